"""MotionCheck.check's ``group`` (the shortcuts of PlanOptions.shorten: a list in the order
of preference whose first proven entry is taken) and its output buffers kept per number
of waypoints (a planner checks its W-waypoint paths and 2-waypoint shortcuts in turn)."""

import numpy as np
import pytest
from worlds import box_pole_scene

import jwarp
from jwarp.world.motion import MotionCheck


@pytest.fixture(scope="module")
def arm():
    return jwarp.robot("arm7")


@pytest.fixture(scope="module")
def scene():
    return box_pole_scene(floor=False)


def _segments(robot, n, seed):
    rng = np.random.default_rng(seed)
    lim = np.array(robot.joint_limits)
    mid = lim.mean(1)
    return mid + 0.6 * (rng.uniform(lim[:, 0], lim[:, 1], size=(n, 2, robot.n_dof)) - mid)


def test_group_proves_the_first_feasible_entry_of_each_list(arm, scene):
    """On the CPU the entries are checked in order: in every group of G the first entry
    that is feasible alone is proven, the earlier ones fail, the later ones are skipped."""
    segs = _segments(arm, 120, seed=3)
    chk = MotionCheck(arm, scene, device="cpu")
    solo = chk.check(segs, margin=0.01).ok
    assert 0 < solo.sum() < len(solo)
    G = 6
    got = chk.check(segs, margin=0.01, group=G)
    ok = got.ok.reshape(-1, G)
    for g, row in enumerate(solo.reshape(-1, G)):
        want = np.zeros(G, bool)
        if row.any():
            want[np.argmax(row)] = True
        np.testing.assert_array_equal(ok[g], want, err_msg=f"group {g}")
    c = solo.reshape(-1, G).cumsum(1)
    after = (c >= 1) & ~((c == 1) & solo.reshape(-1, G))  # after the first feasible
    skipped = got.code.reshape(-1, G)[after]
    assert len(skipped) and (skipped == 5).all()  # SKIPPED, whatever they are alone
    # group 1: every path alone, as without a group
    np.testing.assert_array_equal(chk.check(segs, margin=0.01, group=1).ok, solo)


@pytest.mark.parametrize("bad", [-1, 1.5, True, "2"])
def test_bad_group(arm, scene, bad):
    with pytest.raises(ValueError, match="group"):
        MotionCheck(arm, scene, device="cpu").check(_segments(arm, 2, 0), group=bad)


def test_alternating_waypoints_reuse_the_buffers(arm, scene):
    """Paths of 2 and of 5 waypoints in turn: the same verdicts as a fresh check each time,
    and no new output buffers after the first of each."""
    segs = _segments(arm, 16, seed=5)
    paths = segs[:, :1] + np.linspace(0, 1, 5)[None, :, None] * (segs[:, 1:] - segs[:, :1])
    want2 = MotionCheck(arm, scene, device="cpu").check(segs)
    want5 = MotionCheck(arm, scene, device="cpu").check(paths)
    chk = MotionCheck(arm, scene, device="cpu")
    first: dict = {}
    for _ in range(3):
        for W, p, want in ((2, segs, want2), (5, paths, want5)):
            got = chk.check(p)
            np.testing.assert_array_equal(got.ok, want.ok)
            np.testing.assert_array_equal(got.code, want.code)
            buf = chk._outputs(len(p), W)["ok"]
            assert first.setdefault(W, buf) is buf
