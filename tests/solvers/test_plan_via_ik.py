"""Starts through collision-free IK via points (PlanOptions.via_ik, issue 45 item 3): where
the straight line is not proven, some random multi-starts are replaced by paths through
via points of one batched IK call; the via points are collision-free, the starts are
deterministic with the seed, and every path the planner returns is certified as before."""

import numpy as np
import pytest

import jwarp
from jwarp.solvers import planning as PL
from jwarp.solvers.planning import via_ik as VI
from jwarp.world import World
from jwarp.world.collision import min_distances
from jwarp.world.motion import check_paths
from jwarp.world.path_feasibility import initial_paths

MARGIN = 0.01


def _shelf():
    """A shelf of two boards in front of arm7, the goal's tool inside it."""
    w = World.of_shapes()
    w.add("board_lo", "box", np.array([0.3, 0.6, 0.02]), np.array([0.55, 0.0, 0.25]))
    w.add("board_hi", "box", np.array([0.3, 0.6, 0.02]), np.array([0.55, 0.0, 0.55]))
    w.add("back", "box", np.array([0.02, 0.6, 0.32]), np.array([0.72, 0.0, 0.40]))
    return w


def _clear(robot, world, q):
    """World and self clearance (N, 2) [m] of configurations q (N, n_dof), float64."""
    return np.asarray(min_distances(jwarp.robot(robot), np.atleast_2d(q), world, device="cpu",
                                    dtype=np.float64))


@pytest.fixture(scope="module")
def problems():
    """arm7 and pairs (start, goal), both 2 cm clear, whose straight line hits the world."""
    robot = jwarp.robot("arm7")
    world = _shelf()
    rng = np.random.default_rng(11)
    lim = np.array(robot.joint_limits)
    out = []
    while len(out) < 3:
        c = rng.uniform(lim[:, 0], lim[:, 1], (2, robot.n_dof)) * 0.8
        if not (_clear(robot, world, c) > 0.02).all():
            continue
        u = np.linspace(0.0, 1.0, 200)[:, None]
        line = c[0] + u * (c[1] - c[0])
        if _clear(robot, world, line)[:, 0].min() < -0.02:
            out.append(c)
    return robot, world, np.array(out)


def _vias(robot, world, pairs, seed=0, k=7):
    q0, q1 = pairs[:, 0], pairs[:, 1]
    lines = initial_paths(q0, q1, 20, "straight")
    return VI.ik_via_points(robot, world, q0, q1, lines, k, margin=MARGIN, device="cpu",
                            seed=seed)


def test_via_points_are_collision_free_and_found(problems):
    robot, world, pairs = problems
    vias = _vias(robot, world, pairs)
    assert len(vias) == len(pairs)
    assert sum(len(v) for v in vias) > 0  # the IK finds some
    lim = np.array(robot.joint_limits)
    for per in vias:
        assert len(per) <= 7
        for v in per:
            assert v.ndim == 2 and v.shape[1] == robot.n_dof and 1 <= len(v) <= 2
            d = _clear(robot, world, v)
            assert (d[:, 0] > MARGIN - 1e-6).all() and (d[:, 1] > -1e-6).all()
            assert ((v >= lim[:, 0] - 1e-9) & (v <= lim[:, 1] + 1e-9)).all()


def test_via_points_are_deterministic_with_the_seed(problems):
    robot, world, pairs = problems
    a = _vias(robot, world, pairs, seed=4)
    b = _vias(robot, world, pairs, seed=4)
    assert [len(x) for x in a] == [len(x) for x in b]
    for xa, xb in zip(a, b):
        for va, vb in zip(xa, xb):
            np.testing.assert_array_equal(va, vb)


def test_the_planner_starts_from_them_where_the_line_fails(problems):
    """With no iterations the returned starts are the initial paths: the last random
    starts of a problem whose line is not proven are the via-point paths."""
    robot, world, pairs = problems
    q0, q1 = pairs[:, 0], pairs[:, 1]
    # stop_when_solved off: the IK runs even where a kept random start is proven
    o = PL.PlanOptions(margin=MARGIN, n_starts=8, via_ik=3, iterations=0, seed=2,
                       fallback=None, shorten=0, stop_when_solved=False)
    res = PL.Planner(robot, world, len(pairs), o, device="cpu").plan(q0, q1)
    assert (res.stage != "straight").all()
    lines = initial_paths(q0, q1, 20, "straight").astype(np.float32).astype(np.float64)
    want, count = VI.ik_via_paths(robot, world, q0, q1, lines, 3, 20, margin=MARGIN,
                                  device="cpu", seed=2)
    assert count.sum() > 0
    got = res.all_paths
    for b in range(len(pairs)):
        c = int(count[b])
        if c:
            np.testing.assert_allclose(got[b, 8 - c:], want[b, :c].astype(np.float32),
                                       atol=1e-5)
    off = PL.Planner(robot, world, len(pairs), PL.PlanOptions(
        margin=MARGIN, n_starts=8, via_ik=0, iterations=0, seed=2, fallback=None,
        shorten=0, stop_when_solved=False), device="cpu").plan(q0, q1)
    # the other starts are the same random ones
    np.testing.assert_array_equal(got[:, :8 - int(count.max())],
                                  off.all_paths[:, :8 - int(count.max())])


def test_plans_are_deterministic_and_certified(problems):
    robot, world, pairs = problems
    q0, q1 = pairs[:, 0], pairs[:, 1]
    o = PL.PlanOptions(margin=MARGIN, seed=7, fallback=None, time_limit=None)
    r1 = PL.plan(robot, world, q0, q1, options=o, device="cpu")
    r2 = PL.plan(robot, world, q0, q1, options=o, device="cpu")
    np.testing.assert_array_equal(r1.path, r2.path)
    np.testing.assert_array_equal(r1.feasible, r2.feasible)
    assert r1.feasible.any()
    ok = check_paths(robot, world, r1.path[r1.feasible], margin=MARGIN, device="cpu").ok
    assert ok.all()


@pytest.mark.parametrize("value, err", [(-1, ValueError), (1.5, ValueError),
                                        (True, (TypeError, ValueError)),
                                        ("3", (TypeError, ValueError))])
def test_via_ik_is_validated(value, err):
    with pytest.raises(err, match="via_ik"):
        PL.PlanOptions(via_ik=value).validate()


@pytest.mark.parametrize("value", [1.5, -1, True, [1]])
def test_via_frame_is_validated(value):
    with pytest.raises((TypeError, ValueError), match="via_frame"):
        PL.PlanOptions(via_frame=value).validate()


def test_via_frame_must_be_a_frame_of_the_robot():
    with pytest.raises(ValueError, match="via_frame"):
        PL.Planner("arm7", _shelf(), 1, PL.PlanOptions(via_frame="no_such_frame"),
                   device="cpu")
    PL.Planner("arm7", _shelf(), 1, PL.PlanOptions(via_frame="tcp"), device="cpu")
    assert VI.via_frame(jwarp.robot("arm7"), None) == jwarp.robot("arm7").frame_index("tcp")


# ---------------------------------------------------------------- a batch of worlds
_SHELF_BOXES = [([0.3, 0.6, 0.02], [0.55, 0.0, 0.25]), ([0.3, 0.6, 0.02], [0.55, 0.0, 0.55]),
                ([0.02, 0.6, 0.32], [0.72, 0.0, 0.40])]


def _box_clearance(robot, q, boxes):
    """(N,) smallest sphere-to-box surface distance [m] of q (N, n_dof) to axis-aligned
    boxes [(full sizes, centre)], in numpy from jwarp's FK (independent of its kernels)."""
    from tests.pool_helpers import sphere_centres

    x, r = sphere_centres(robot, np.atleast_2d(q))
    out = np.full(len(x), np.inf)
    for size, centre in boxes:
        d = np.abs(x - np.asarray(centre)) - 0.5 * np.asarray(size)
        sd = np.linalg.norm(np.maximum(d, 0.0), axis=-1) + np.minimum(d.max(-1), 0.0) - r
        out = np.minimum(out, sd.min(-1))
    return out


def _batch(boxes):
    worlds = []
    for bx in boxes:
        w = World.of_shapes()
        for i, (size, centre) in enumerate(bx):
            w.add(f"box{i}", "box", np.array(size), np.array(centre))
        worlds.append(w)
    return World.batch(worlds)


@pytest.fixture(scope="module")
def batch_problems(problems):
    """One start/goal (a line through the shelf) in three worlds: the shelf, and the shelf
    with a small block in the arm of the first via point problem 1 (2) gets when all
    three worlds are the shelf (so that point collides in its own world, not in world 0;
    the start and the goal stay 2 cm clear)."""
    robot, world, pairs = problems
    q0, q1 = np.repeat(pairs[:1, 0], 3, 0), np.repeat(pairs[:1, 1], 3, 0)
    lines = initial_paths(q0, q1, 20, "straight")
    same = VI.ik_via_points(robot, _batch([_SHELF_BOXES] * 3), q0, q1, lines, 7,
                            margin=MARGIN, device="cpu", seed=0)
    from tests.pool_helpers import sphere_centres

    xe, re_ = sphere_centres(robot, np.stack([q0[0], q1[0]]))
    xe = xe.reshape(-1, 3)
    re_ = np.tile(re_, 2)
    boxes = [list(_SHELF_BOXES)]
    for b in (1, 2):
        # a 4 cm block at the sphere of problem b's first via point farthest from the
        # start's and the goal's spheres
        v = same[b][0]
        xv = sphere_centres(robot, v)[0].reshape(-1, 3)
        room = (np.linalg.norm(xv[:, None] - xe[None], axis=-1) - re_).min(1)
        blk = [([0.04, 0.04, 0.04], list(xv[np.argmax(room)]))]
        assert (_box_clearance(robot, np.stack([q0[0], q1[0]]), blk) > 0.02).all()
        assert (_box_clearance(robot, v, blk) <= MARGIN).any()
        boxes.append(list(_SHELF_BOXES) + blk)
    return robot, _batch(boxes), boxes, q0, q1


def test_via_points_in_a_batch_of_worlds_are_free_in_their_own_world(batch_problems):
    robot, batch, boxes, q0, q1 = batch_problems
    lines = initial_paths(q0, q1, 20, "straight")
    vias = VI.ik_via_points(robot, batch, q0, q1, lines, 7, margin=MARGIN, device="cpu",
                            seed=0)
    assert all(len(v) for v in vias)  # the IK finds some in every world
    crossed = 0
    for b, per in enumerate(vias):
        for v in per:
            assert (_box_clearance(robot, v, boxes[b]) > MARGIN - 1e-6).all(), b
            assert (_clear(robot, None, v)[:, 1] > -1e-6).all()  # no self-collision
            for c in range(3):
                crossed += int((_box_clearance(robot, v, boxes[c]) <= MARGIN).sum())
    # some via point of one problem collides in another problem's world (a check in
    # the wrong world, or in all of them, would give other points)
    assert crossed > 0
    # deterministic; world b of problem b given explicitly is the same
    again = VI.ik_via_points(robot, batch, q0, q1, lines, 7, margin=MARGIN, device="cpu",
                             seed=0, worlds=[0, 1, 2])
    for a, b in zip(vias, again):
        assert len(a) == len(b)
        for va, vb in zip(a, b):
            np.testing.assert_array_equal(va, vb)
    with pytest.raises(ValueError, match="worlds"):
        VI.ik_via_points(robot, batch, q0, q1, lines, 7, device="cpu", worlds=[0, 1, 3])


def test_a_batch_plan_starts_from_them_and_is_certified_in_each_world(batch_problems):
    robot, batch, boxes, q0, q1 = batch_problems
    # stop_when_solved off: the IK runs even where a kept random start is proven
    o = PL.PlanOptions(margin=MARGIN, n_starts=8, via_ik=3, iterations=0, seed=2,
                       fallback=None, shorten=0, stop_when_solved=False)
    res = PL.Planner(robot, batch, 3, o, device="cpu").plan(q0, q1)
    assert "via_ik" in res.timings
    lines = initial_paths(q0, q1, 20, "straight").astype(np.float32).astype(np.float64)
    want, count = VI.ik_via_paths(robot, batch, q0, q1, lines, 3, 20, margin=MARGIN,
                                  device="cpu", seed=2)
    assert (count > 0).all()
    for b in range(3):
        c = int(count[b])
        np.testing.assert_allclose(res.all_paths[b, 8 - c:], want[b, :c].astype(np.float32),
                                   atol=1e-5)
    full = PL.plan(robot, batch, q0, q1, options=PL.PlanOptions(
        margin=MARGIN, seed=7, fallback=None, time_limit=None), device="cpu")
    assert full.feasible.any()
    for b in np.nonzero(full.feasible)[0]:
        w = batch.select(int(b))
        assert check_paths(robot, w, full.path[b][None], margin=MARGIN, device="cpu").ok.all()
        fine = initial_paths(full.path[b][:-1], full.path[b][1:], 30, "straight")
        assert (_box_clearance(robot, fine.reshape(-1, robot.n_dof), boxes[b]) > 0).all()


def test_no_ik_where_a_kept_random_start_is_proven(batch_problems):
    """With stop_when_solved a problem one of whose kept random starts the spheres prove
    ends at the first check: the IK is skipped for it (and the start is really free)."""
    robot, batch, boxes, q0, q1 = batch_problems
    o = PL.PlanOptions(margin=MARGIN, n_starts=8, via_ik=3, iterations=0, seed=2,
                       fallback=None, shorten=0)
    pl = PL.Planner(robot, batch, 3, o, device="cpu")
    Q = PL.planner._initial(robot, q0, q1, "mixed", 8, o.n_waypoints, o.seed, batch,
                            o.free_via, device=pl.device)
    first, evals = pl._proven_starts(Q, np.arange(3), 1, 5)
    proven = first >= 0
    assert evals > 0
    for b in range(3):
        ok = check_paths(robot, batch.select(b), Q[b, 1:5].astype(np.float32),
                         margin=MARGIN, device="cpu").ok
        assert proven[b] == ok.any()
        if proven[b]:  # the first proven start of the problem
            assert first[b] == 1 + int(np.argmax(ok))
    res = pl.plan(q0, q1)
    assert ("via_ik" in res.timings) == (not proven.all())
    assert res.feasible[proven].all()
