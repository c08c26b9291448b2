"""The continuous check's interval refinement (``MotionOptions(method="levels")``,
jwarp.kernels.motion level kernels) against the conservative advancement
(``method="advance"``, the CPU's default) and against dense sampling: free and colliding
paths, paths that pass an object within a millimetre of the margin (a batch of worlds,
``world_group``), self-collision, ``group`` batches, the work list's overflow and the
level cap. A path the levels call feasible must be feasible by dense sampling, and by the
advancement wherever that proves something (it may leave uncertified what the levels
prove, and the other way round: both counts are printed)."""

import numpy as np
import pytest
import warp as wp
from worlds import ball_worlds, box_pole_scene, grazing_paths

import jwarp
from jwarp.world.collision import min_distances
from jwarp.world.motion import MotionCheck, MotionOptions
from jwarp.world.primitives import Shape, pose_matrix

LEVELS = MotionOptions(method="levels")
ADVANCE = MotionOptions(method="advance")
WORLD, SELF, UNCERTIFIED = 1, 2, 3


@pytest.fixture(scope="module")
def arm():
    return jwarp.robot("arm7")


@pytest.fixture(scope="module")
def scene():
    return box_pole_scene(floor=True)


def _random_paths(robot, n, W, seed, scale=0.6):
    rng = np.random.default_rng(seed)
    lim = np.array(robot.joint_limits)
    mid = lim.mean(1)
    q = mid + scale * (rng.uniform(lim[:, 0], lim[:, 1], size=(n, 2, robot.n_dof)) - mid)
    return q[:, :1] + np.linspace(0, 1, W)[None, :, None] * (q[:, 1:] - q[:, :1])


def _dense(robot, world, paths, n=1500):
    """(world, self) smallest clearance [m] per path over ``n`` samples a segment."""
    P, W, nd = paths.shape
    u = np.linspace(0, 1, n)
    seg = paths[:, :-1, None] + u[None, None, :, None] * np.diff(paths, axis=1)[:, :, None]
    md = min_distances(jwarp.robot(robot), seg.reshape(-1, nd), world, dtype=np.float64)
    return md.reshape(P, -1, 2).min(axis=1)


def _compare(name, old, new, dense_ok):
    """The levels' verdicts against the advancement's and dense sampling's; returns
    (levels prove, advancement uncertified) and the reverse count."""
    assert not (new.ok & ~dense_ok).any(), f"{name}: feasible by the levels, not dense"
    assert not (old.ok & ~dense_ok).any(), f"{name}: feasible by the advancement, not dense"
    # a violation the advancement proves is a violation: the levels never call it feasible
    proven_bad = np.isin(old.code, (WORLD, SELF))
    assert not (new.ok & proven_bad).any(), name
    assert not (new.ok & ~old.ok & (old.code != UNCERTIFIED)).any(), name
    gained = int((new.ok & ~old.ok).sum())
    lost = int((old.ok & ~new.ok).sum())
    print(f"{name}: {len(new.ok)} paths, advancement {int(old.ok.sum())} feasible, levels "
          f"{int(new.ok.sum())}; levels prove {gained} the advancement leaves uncertified, "
          f"leave {lost} uncertified it proves")
    return gained, lost


def test_levels_agree_on_free_and_colliding_paths(device, arm, scene):
    paths = _random_paths(arm, 150, 6, seed=6)
    old = MotionCheck(arm, scene, device=device, options=ADVANCE).check(paths)
    chk = MotionCheck(arm, scene, device=device, options=LEVELS)
    new = chk.check(paths)
    d = _dense(arm, scene, paths)
    _compare("free/colliding", old, new, (d[:, 0] >= 0) & (d[:, 1] >= 0))
    assert 20 < (~new.ok).sum() < 130                 # both kinds present
    assert new.ok[(d[:, 0] > 2e-3) & (d[:, 1] > 2e-3)].all()    # clearly free: proven
    np.testing.assert_array_equal(new.ok, old.ok)
    bad = ~new.ok
    assert set(new.code[bad]) <= {WORLD, SELF}
    if device == "cpu":  # (on a GPU the first segment to fail stops the others: any)
        np.testing.assert_array_equal(new.code[bad], old.code[bad])
    # the place reported is a place of the violation: a configuration there collides
    for i in np.nonzero(new.code == WORLD)[0][:10]:
        t = int(new.where[i])
        u = new.where[i] - t
        q = paths[i, t] + u * (paths[i, t + 1] - paths[i, t])
        assert min_distances(arm, q[None], scene, dtype=np.float64)[0, 0] < 1e-9
        assert "vs object" in new.reason(i)
    # prep, level 0, the levels, their end, (the advancement of what is left,) reduce
    assert chk.last_launches <= 5 + chk.options.n_levels()


@pytest.mark.parametrize("margin", [0.0, 0.01])
def test_levels_prove_grazing_paths_in_a_batch_of_worlds(device, arm, margin):
    """Paths passing a ball (each in its own world of a batch, ``world_group`` 1) at
    margin + 1 mm, + 0.2 mm (feasible), and 0.2 mm into the margin (infeasible)."""
    for delta in (1e-3, 2e-4, -2e-4):
        paths, dense, balls = grazing_paths(arm, 12, delta, margin=margin,
                                          seed=int(1e4 * delta) + 7)
        wb = ball_worlds(balls)
        old = MotionCheck(arm, wb, device=device, options=ADVANCE).check(
            paths, margin=margin, world_group=1)
        new = MotionCheck(arm, wb, device=device, options=LEVELS).check(
            paths, margin=margin, world_group=1)
        _compare(f"graze {delta * 1e3:+.1f} mm, margin {margin}", old, new, dense >= margin)
        if delta < 0:
            assert not new.ok.any() and (new.code == WORLD).sum() >= 10
            assert all("ball" in r for r in new.reasons())
        else:
            assert (np.abs(dense - margin - delta) < 1e-5).all()   # they do graze
            assert new.ok.all(), new.reasons()


def test_levels_uncertify_below_min_step(arm):
    """A graze the smallest step cannot resolve is uncertified (not feasible), as by the
    advancement; a coarser ``min_step`` uncertifies earlier."""
    paths, dense, balls = grazing_paths(arm, 6, 2e-5, seed=3)
    wb = ball_worlds(balls)
    for ms in (1e-5, 1e-3):
        old = MotionCheck(arm, wb, options=MotionOptions(method="advance", min_step=ms)).check(
            paths, world_group=1)
        chk = MotionCheck(arm, wb, options=MotionOptions(method="levels", min_step=ms))
        new = chk.check(paths, world_group=1)
        _compare(f"graze 0.02 mm, min_step {ms}", old, new, dense >= 0)
        if ms == 1e-3:
            assert not new.ok.any() and set(new.code) == {UNCERTIFIED}
            assert all("ball' at waypoint" in r and "grazes" in r for r in new.reasons())
            # the last level's intervals narrower than min_step: proven or uncertified
            assert 1 / (2 * 16 * 2 ** (chk.options.n_levels() - 1)) < ms


def test_levels_never_prove_a_shallow_collision(arm):
    """Spheres that dip 20 um and 1 um into a ball for a moment (a small part of one
    interval): never feasible (an interval left out of the proof would show here)."""
    for delta, seed in ((-2e-5, 51), (-1e-6, 52)):
        paths, dense, balls = grazing_paths(arm, 16, delta, seed=seed)
        assert (dense < 0).all()
        wb = ball_worlds(balls)
        new = MotionCheck(arm, wb, options=LEVELS).check(paths, world_group=1)
        old = MotionCheck(arm, wb, options=ADVANCE).check(paths, world_group=1)
        _compare(f"graze {delta * 1e3:+.3f} mm", old, new, dense >= 0)
        assert not new.ok.any()
        assert set(new.code) <= {WORLD, UNCERTIFIED}


def test_levels_self_collision(device, arm):
    """Self-collision only (no world), with a self margin: verdicts of the advancement."""
    paths = _random_paths(arm, 200, 4, seed=21, scale=1.0)
    d = _dense(arm, None, paths)[:, 1]
    for sm in (0.0, 0.01):
        old = MotionCheck(arm, None, device=device, options=ADVANCE).check(
            paths, self_margin=sm, endpoint_margin=sm)
        new = MotionCheck(arm, None, device=device, options=LEVELS).check(
            paths, self_margin=sm, endpoint_margin=sm)
        _compare(f"self, self_margin {sm}", old, new, d >= sm)
        assert (new.code == SELF).sum() >= 5 and new.ok.sum() >= 20
        assert new.ok[d > sm + 2e-3].all()
        assert all(r.startswith("self collision") for r, c in zip(new.reasons(), new.code)
                   if c == SELF)


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_levels_group_stops_a_solved_problem(device, arm, scene, dtype):
    """``group`` (the planner's launch): once a path of a problem is proven the others
    stop (skipped); every problem with a feasible path has one proven, every path called
    feasible is feasible."""
    paths = _random_paths(arm, 96, 5, seed=31)
    G = 8
    solo = MotionCheck(arm, scene, device=device, options=LEVELS).check(paths)
    paths = paths[np.argsort(solo.ok, kind="stable")]   # the first problems: none feasible
    solo = MotionCheck(arm, scene, device=device, options=LEVELS).check(paths)
    d = _dense(arm, scene, paths)
    dense_ok = (d[:, 0] >= 0) & (d[:, 1] >= 0)
    chk = MotionCheck(arm, scene, device=device, options=LEVELS)
    P = wp.array(paths.astype(dtype), device=chk.device)
    idx = wp.array(np.arange(len(paths), dtype=np.int32), device=chk.device)
    out = chk.launch(P, idx, len(paths), group=G)
    ok = out["ok"].numpy()[:len(paths)].astype(bool)
    code = out["code"].numpy()[:len(paths)]
    assert not (ok & ~dense_ok).any()
    has = solo.ok.reshape(-1, G).any(1)
    assert 0 < has.sum() < len(has)                # solved and unsolved problems
    np.testing.assert_array_equal(ok.reshape(-1, G).any(1), has)
    if device == "cpu":  # (a GPU may prove every path of a problem in one level)
        assert (code == 5).sum() > 0                # some skipped
    assert not (ok & ~solo.ok).any()


def test_levels_overflow_never_certifies(arm, scene):
    """A work list too small for the segments: without the fallback what does not fit is
    uncertified; with it (the advancement from the proven prefix) the verdicts are the
    full check's. The level cap likewise."""
    paths, dense, balls = grazing_paths(arm, 8, 2e-4, W=4, seed=41)
    wb = ball_worlds(balls)
    full = MotionCheck(arm, wb, options=LEVELS).check(paths, world_group=1)
    assert full.ok.all()
    for cap in (1, 7, 40, 200):
        tiny = MotionCheck(arm, wb, options=MotionOptions(method="levels", capacity=cap,
                                                           fallback=False))
        r = tiny.check(paths, world_group=1)
        assert not (r.ok & ~full.ok).any()
        assert (~r.ok).sum() >= 1, cap
        assert set(r.code[~r.ok]) == {UNCERTIFIED}
        assert any("work budget" in s for s in r.reasons())
        fb = MotionCheck(arm, wb, options=MotionOptions(method="levels", capacity=cap))
        rf = fb.check(paths, world_group=1)
        assert not (rf.ok & (dense < 0)).any()
        np.testing.assert_array_equal(rf.ok, full.ok)
    for fallback in (False, True):
        capped = MotionCheck(arm, wb, options=MotionOptions(method="levels", levels=3,
                                                             fallback=fallback))
        r = capped.check(paths, world_group=1)
        assert capped.options.n_levels() == 3
        if fallback:
            np.testing.assert_array_equal(r.ok, full.ok)
        else:
            assert not r.ok.any() and set(r.code) == {UNCERTIFIED}
    # free and colliding paths with a tiny list and the fallback: the full check's verdicts
    p2 = _random_paths(arm, 60, 5, seed=43)
    a = MotionCheck(arm, scene, options=LEVELS).check(p2)
    b = MotionCheck(arm, scene, options=MotionOptions(method="levels", capacity=16)).check(p2)
    np.testing.assert_array_equal(a.ok, b.ok)


def test_levels_is_the_gpu_default_and_options_are_validated(arm, scene):
    assert MotionOptions().resolved_method(wp.get_device("cpu")) == "advance"
    assert MotionOptions().n_levels() == 13           # 16 intervals down to 1e-5
    assert MotionOptions(intervals=1, min_step=0.1).n_levels() == 4   # w 0.5 .. 0.0625
    assert MotionOptions(levels=4).n_levels() == 4
    for kw, name in ((dict(method="bisect"), "method"), (dict(intervals=0), "intervals"),
                     (dict(intervals=5000), "intervals"), (dict(levels=0), "levels"),
                     (dict(capacity=0), "capacity"), (dict(capacity=2.5), "capacity"),
                     (dict(fallback="yes"), "fallback")):
        with pytest.raises(ValueError, match=name):
            MotionCheck(arm, scene, options=MotionOptions(**kw))


def test_planner_with_the_levels_plans_feasible_paths(arm, scene, monkeypatch):
    """The planner's checks (its confirmation launch with ``group``, float32 paths) on the
    levels (the GPU's default) on the CPU: straight lines through an object are planned
    around it, and every path called feasible keeps clear of the world densely sampled."""
    from jwarp.solvers.planning import plan
    monkeypatch.setattr(MotionOptions, "resolved_method", lambda self, device: "levels")
    calls = []
    orig = MotionCheck._launch_levels
    monkeypatch.setattr(MotionCheck, "_launch_levels",
                        lambda self, *a, **kw: calls.append(a[3]) or orig(self, *a, **kw))
    rng = np.random.default_rng(9)
    lim = np.array(arm.joint_limits)
    q = rng.uniform(lim[:, 0], lim[:, 1], size=(400, 2, arm.n_dof)) * 0.6
    free = (min_distances(arm, q.reshape(-1, arm.n_dof), scene, dtype=np.float64)
            .reshape(400, 2, 2).min(axis=(1, 2)) > 0.02)
    lines = q[:, :1] + np.linspace(0, 1, 20)[None, :, None] * (q[:, 1:] - q[:, :1])
    through = _dense(arm, scene, lines, n=50)[:, 0] < 0
    k = np.nonzero(free & through)[0][:3]
    assert len(k) == 3
    res = plan(arm, scene, q[k, 0], q[k, 1], n_starts=4, iterations=80, device="cpu")
    assert res.feasible.all()
    assert (_dense(arm, scene, np.asarray(res.path), n=400) >= 0).all()
    assert calls                                      # the planner's check ran the levels


def test_levels_grazing_verdicts_pass_the_independent_verifier():
    """The one-sided 2 cm Panda fit (``contain=False``: 30 spheres; the contained fit's 147
    make the dense verifier several times slower) grazing a ball at 0.2 mm and dipping
    0.2 mm into one: what the levels call feasible, tests/verifier.py (pinocchio FK, coal
    distances, 0.02 deg samples) finds clear; what they refuse, it finds colliding."""
    import sys
    from pathlib import Path

    pytest.importorskip("coal")
    from jwarp.importers.robot import example_robot_urdf
    from jwarp.world.spherize import SpherizeOptions, spherized_robot
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from verifier import PathVerifier, robot_spheres

    try:
        urdf = example_robot_urdf("panda_description/urdf/panda.urdf")
    except ValueError as e:
        pytest.skip(str(e))
    panda = spherized_robot(urdf, SpherizeOptions(tolerance=0.02, contain=False))[0]
    spheres = robot_spheres(panda)
    for delta in (2e-4, -2e-4):
        paths, dense, balls = grazing_paths(panda, 3, delta, seed=61)
        res = MotionCheck(panda, ball_worlds(balls), options=LEVELS).check(paths, world_group=1)
        assert res.ok.all() == (delta > 0) and res.ok.any() == (delta > 0)
        for path, (c, R), ok in zip(paths, balls, res.ok):
            ball = Shape("sphere", np.array([R]), pose_matrix(c), "ball")
            v = PathVerifier(urdf, None, [ball], spheres=spheres,
                             joint_names=panda.joint_names, mesh_check=False)
            got = v.check_path(path, max_step_deg=0.02, max_step_m=1e-4)
            assert got.ok == ok, (delta, got.min_distance)
            assert abs(got.min_distance - delta) < 5e-5, (delta, got.min_distance)


def test_levels_scratch_budget_starts_with_fewer_intervals(device, arm, scene, monkeypatch):
    """A launch whose level-0 intervals would not fit LEVELS_SCRATCH_BYTES of scratch rows
    starts with fewer (a 700-problem GPU batch asked for 30 GB of one array): the same
    verdicts, every proof confirmed by dense sampling."""
    import jwarp.world.motion as motion

    paths = _random_paths(arm, 150, 6, seed=6)
    full = MotionCheck(arm, scene, device=device, options=LEVELS)
    want = full.check(paths)
    n_seg = paths.shape[0] * (paths.shape[1] - 1)
    row = full._row_bytes()
    assert full._level_options(n_seg).intervals == LEVELS.intervals
    # room for 2 intervals per segment (twice the level 0: the work list's rule)
    monkeypatch.setattr(motion, "LEVELS_SCRATCH_BYTES", 2 * 2 * n_seg * row)
    small = MotionCheck(arm, scene, device=device, options=LEVELS)
    assert small._level_options(n_seg).intervals == 2
    got = small.check(paths)
    assert small._lists[0].shape[0] <= 2 * 2 * n_seg
    d = _dense(arm, scene, paths)
    _compare("budget", want, got, (d[:, 0] >= 0) & (d[:, 1] >= 0))
    np.testing.assert_array_equal(got.ok, want.ok)
    # a capacity set by the user is kept as it is
    o = MotionOptions(method="levels", capacity=4096)
    assert MotionCheck(arm, scene, device=device, options=o)._level_options(n_seg) is o
