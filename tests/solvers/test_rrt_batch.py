"""RRT-Connect for a batch of problems at once (jwarp.solvers.planning.rrt.rrt_connect_batch):
paths feasible in each problem's own world, the same trees as the per-problem loop with the
same generators, determinism, one world for all, bad shapes, and the planner's fallback."""

import numpy as np
import pytest
from worlds import block_world_2d

import jwarp
from jwarp.solvers import planning as PL
from jwarp.solvers.planning import rrt as R
from jwarp.world import World
from jwarp.world import path_feasibility as FZ
from jwarp.world.collision import min_distances

S4 = np.array([1.2, 0.0, 0.0, 0.0])
G4 = np.array([-1.2, 0.0, 0.0, 0.0])


@pytest.fixture(scope="module")
def walls():
    """arm7 problems in a batch of worlds, each a wall (a thin box) the straight line from
    its start to its goal crosses: (robot, own worlds, batch world, starts, goals)."""
    robot = jwarp.robot("arm7")
    rng = np.random.default_rng(5)
    lim = np.array(robot.joint_limits)
    worlds, starts, goals = [], [], []
    while len(worlds) < 3:
        w = World.of_shapes()
        w.add("wall", "box", [0.04, 0.5, 0.5], rng.uniform([0.3, -0.3, 0.3], [0.6, 0.3, 0.7]))
        q = rng.uniform(lim[:, 0], lim[:, 1], (64, robot.n_dof)) * 0.7
        free = q[min_distances(robot, q, w, dtype=np.float64).min(axis=1) > 0.02]
        for i in range(len(free) - 1):
            a, b = free[i], free[i + 1]
            if not FZ.path_feasible(robot, w, np.stack([a, b])[None], 1)[0]:
                worlds.append(w)
                starts.append(a)
                goals.append(b)
                break
    return robot, worlds, World.batch(worlds), np.array(starts), np.array(goals)


def own_world_feasible(robot, world, path):
    """Every edge by the continuous check in the problem's own world, and dense samples of
    the polyline clear of it by the spheres' distances."""
    edges = np.stack([path[:-1], path[1:]], axis=1)
    ok = FZ.certify_check(robot, world, device="cpu").check(edges, meshes=False).ok.all()
    u = np.linspace(0, 1, 50)[None, :, None]
    dense = (path[:-1, None] + u * (path[1:] - path[:-1])[:, None]).reshape(-1, robot.n_dof)
    return bool(ok) and min_distances(jwarp.robot(robot), dense, world, dtype=np.float64)[:, 0].min() > 0


def test_batch_of_worlds_paths_feasible_around_walls(walls):
    robot, worlds, batch, q0, q1 = walls
    res = R.rrt_connect_batch(robot, batch, q0, q1, R.RRTOptions(seed=2), device="cpu")
    assert len(res) == 3
    for b, r in enumerate(res):
        assert r.success and r.stop_reason == "connected"
        np.testing.assert_array_equal(r.path[0], q0[b])
        np.testing.assert_array_equal(r.path[-1], q1[b])
        assert len(r.path) >= 3  # the wall: not the straight line
        assert own_world_feasible(robot, worlds[b], r.path)
    again = R.rrt_connect_batch(robot, batch, q0, q1, R.RRTOptions(seed=2), device="cpu")
    for r, s in zip(res, again):
        np.testing.assert_array_equal(r.path, s.path)


def test_batch_grows_the_loops_trees(walls):
    """Problem b draws from its own generator (problem_rngs): the per-problem loop with
    those generators grows the same trees and returns the same paths."""
    robot, worlds, batch, q0, q1 = walls
    res = R.rrt_connect_batch(robot, batch, q0, q1, R.RRTOptions(seed=4), device="cpu")
    rngs = R.problem_rngs(4, 3)
    for b in range(3):
        one = R.rrt_connect(robot, worlds[b], q0[b], q1[b], R.RRTOptions(seed=rngs[b]),
                            device="cpu")
        assert one.success == res[b].success
        assert one.n_samples == res[b].n_samples and one.n_nodes == res[b].n_nodes
        np.testing.assert_array_equal(one.path, res[b].path)


def test_world_index_picks_the_problems_worlds(walls):
    robot, worlds, batch, q0, q1 = walls
    res = R.rrt_connect_batch(robot, batch, q0[[2, 0]], q1[[2, 0]], R.RRTOptions(seed=1),
                              world_index=[2, 0], device="cpu")
    for r, b in zip(res, (2, 0)):
        assert r.success and own_world_feasible(robot, worlds[b], r.path)


def test_one_world_for_all():
    world = block_world_2d()
    starts = np.stack([S4, S4 * 0.9, np.array([2.0, 1.0, 0.0, 0.0])])
    goals = np.stack([G4, G4 * 0.9, np.array([2.0, -1.0, 0.0, 0.0])])
    res = R.rrt_connect_batch(jwarp.robot("planar4"), world, starts, goals, R.RRTOptions(seed=1),
                              device="cpu")
    rngs = R.problem_rngs(1, 3)
    for b, r in enumerate(res):
        assert r.success
        edges = np.stack([r.path[:-1], r.path[1:]], axis=1)
        assert FZ.path_feasible(jwarp.robot("planar4"), world, edges, 1).all()
        one = R.rrt_connect(jwarp.robot("planar4"), world, starts[b], goals[b], R.RRTOptions(seed=rngs[b]),
                            device="cpu")
        np.testing.assert_array_equal(one.path, r.path)
    assert len(res[0].path) >= 3  # the block is between


def test_budget_ends_each_problem():
    world = block_world_2d()
    res = R.rrt_connect_batch(jwarp.robot("planar4"), world, np.stack([S4, S4]), np.stack([G4, G4]),
                              R.RRTOptions(seed=0, max_samples=8, batch=4), device="cpu")
    for r in res:
        assert r.n_samples <= 8
        assert r.success or r.stop_reason == "max_samples"


@pytest.mark.parametrize("kw, match", [
    ({"starts": np.zeros((2, 5))}, "starts"),
    ({"starts": np.zeros(4)}, "starts"),
    ({"goals": np.zeros((3, 4))}, "goals"),
    ({"goals": np.full((2, 4), np.nan)}, "goals"),
    ({"meshes": [True, False, True]}, "meshes"),
    ({"world_index": [0, 0]}, "world_index"),
])
def test_bad_arguments_name_themselves(walls, kw, match):
    robot, worlds, batch, q0, q1 = walls
    args = {"starts": np.stack([S4, S4]), "goals": np.stack([G4, G4]), "meshes": True,
            "world_index": None}
    world = block_world_2d()
    if "world_index" in kw:  # distinct worlds of a batch of worlds
        robot, world = jwarp.robot("arm7"), batch
        args.update(starts=q0[:2], goals=q1[:2])
    else:
        robot = jwarp.robot("planar4")
    args.update(kw)
    with pytest.raises(ValueError, match=match):
        R.rrt_connect_batch(robot, world, args["starts"], args["goals"], device="cpu",
                            meshes=args["meshes"], world_index=args["world_index"])


def test_a_batch_of_worlds_needs_one_world_per_problem(walls):
    robot, worlds, batch, q0, q1 = walls
    with pytest.raises(ValueError, match="world"):
        R.rrt_connect_batch(robot, batch, q0[:2], q1[:2], device="cpu")


def test_start_in_collision_is_named(walls):
    robot, worlds, batch, q0, q1 = walls
    bad = q1.copy()
    # a configuration in problem 1's wall as its goal
    lim = np.array(robot.joint_limits)
    q = np.random.default_rng(0).uniform(lim[:, 0], lim[:, 1], (256, robot.n_dof))
    hit = q[min_distances(robot, q, worlds[1], dtype=np.float64)[:, 0] < 0]
    assert len(hit)
    bad[1] = hit[0]
    with pytest.raises(ValueError, match=r"goals\[1\]"):
        R.rrt_connect_batch(robot, batch, q0, bad, device="cpu")


def test_planner_fallback_runs_the_batch(monkeypatch):
    """The planner's fallback with more than one unsolved problem: one RRTBatch for all;
    its paths certified (stage "fallback"); one problem: rrt_connect as before."""
    from jwarp.solvers.planning import planner as PM

    world = block_world_2d()
    calls = {"batch": 0, "one": 0}
    orig_1 = R.rrt_connect

    class Batch(R.RRTBatch):
        def __init__(self, *a, **k):
            calls["batch"] += 1
            super().__init__(*a, **k)

    def one(*a, **k):
        calls["one"] += 1
        return orig_1(*a, **k)

    monkeypatch.setattr(R, "RRTBatch", Batch)
    monkeypatch.setattr(R, "rrt_connect", one)
    starts = np.stack([S4, S4 * 0.95])
    goals = np.stack([G4, G4 * 0.95])
    o = dict(n_starts=1, iterations=1, fallback="rrt", device="cpu", n_substeps=8, step=0.05)
    res = PL.plan("planar4", world, starts, goals, **o)
    assert calls == {"batch": 1, "one": 0}
    assert res.feasible.all() and (res.stage == "fallback").all()
    calls.update(batch=0, one=0)
    res1 = PL.plan("planar4", world, S4, G4, **o)
    assert calls == {"batch": 0, "one": 1} and res1.feasible.all()
    monkeypatch.setattr(PM, "FALLBACK_BATCH", False)
    calls.update(batch=0, one=0)
    res2 = PL.plan("planar4", world, starts, goals, **o)
    assert calls == {"batch": 0, "one": 2} and res2.feasible.all()


def test_widths_by_device():
    """RRTOptions.batch and n_connect None: by the device (wider rounds on a CUDA device);
    a value set is kept on either."""
    assert R.RRTOptions().batch is None and R.RRTOptions().n_connect is None
    assert R.rrt_widths(R.RRTOptions(), True) == (R.CPU_BATCH, R.CPU_CONNECT) == (32, 4)
    assert R.rrt_widths(R.RRTOptions(), False) == (R.CUDA_BATCH, R.CUDA_CONNECT) == (128, 16)
    assert R.rrt_widths(R.RRTOptions(batch=8), False) == (8, R.CUDA_CONNECT)
    assert R.rrt_widths(R.RRTOptions(n_connect=2), True) == (R.CPU_BATCH, 2)
    assert R.rrt_widths(R.RRTOptions(batch=5, n_connect=3), False) == (5, 3)
    R.RRTOptions(batch=None, n_connect=None).validate()
    for field in ("batch", "n_connect"):
        with pytest.raises(ValueError, match=f"^rrt.{field}"):
            R.RRTOptions(**{field: 0}).validate()


class _Cuda:
    is_cuda = True


@pytest.mark.parametrize("cuda", [False, True])
def test_rounds_are_as_wide_as_the_device(monkeypatch, cuda):
    """Each round draws the device's samples per problem (the checks still on the CPU:
    only the width's device rule is faked), in the batch and in the one-problem search."""
    world = block_world_2d()
    drawn: list[int] = []
    orig = R.sample_within_limits
    monkeypatch.setattr(R, "sample_within_limits",
                        lambda m, K, rng: drawn.append(K) or orig(m, K, rng))
    if cuda:
        monkeypatch.setattr(R, "resolve_device", lambda d: _Cuda())
    want = R.CUDA_BATCH if cuda else R.CPU_BATCH
    o = R.RRTOptions(seed=0, max_samples=1000)
    res = R.rrt_connect_batch(jwarp.robot("planar4"), world, np.stack([S4, S4 * 0.95]),
                              np.stack([G4, G4 * 0.95]), o, device="cpu")
    assert drawn and all(k == want for k in drawn[:-2])
    assert all(r.n_samples % want == 0 or r.n_samples == 1000 for r in res)
    drawn.clear()
    R.rrt_connect(jwarp.robot("planar4"), world, S4, G4, o, device="cpu")
    assert drawn and drawn[0] == want
    drawn.clear()
    R.rrt_connect_batch(jwarp.robot("planar4"), world, np.stack([S4, S4 * 0.95]),
                        np.stack([G4, G4 * 0.95]), R.RRTOptions(seed=0, batch=8), device="cpu")
    assert drawn and set(drawn) == {8}


def test_batch_problems_join_late_with_the_same_result(walls):
    """RRTBatch: a problem that joins after others searched for rounds finds the path it
    finds in rrt_connect_batch (its own generator: the others and the time it joined do
    not change its trees)."""
    robot, worlds, batch, q0, q1 = walls
    o = R.RRTOptions(seed=4)
    ref = R.rrt_connect_batch(robot, batch, q0, q1, o, device="cpu")
    rb = R.RRTBatch(robot, batch, q0, q1, o, device="cpu")
    rb.start([0, 2])
    for _ in range(3):
        rb.round()
    assert 1 not in rb.problems and 1 not in set(rb.active.tolist())
    rb.start([1])
    with pytest.raises(ValueError, match="rows: 1"):
        rb.start([1])
    rb.run()
    rb.finish(rb.connected())
    for b in range(3):
        r = rb.result(b)
        assert r.success and r.n_samples == ref[b].n_samples
        np.testing.assert_array_equal(r.path, ref[b].path)
        assert own_world_feasible(robot, worlds[b], r.path)


def test_batch_restarts_trees_while_time_is_left(walls):
    """RRTBatch(restart=True): a problem whose samples are spent starts new trees while
    the caller's time is left (its samples those of all its trees); without restart, or
    with no time left, it ends as "max_samples"."""
    import time

    robot, worlds, batch, q0, q1 = walls
    o = R.RRTOptions(seed=1, max_samples=1, goal_bias=0.0, batch=1)
    rb = R.RRTBatch(robot, batch, q0, q1, o, device="cpu")
    rb.start([0])
    rb.run()
    assert rb.result(0).stop_reason == "max_samples" and rb.result(0).n_samples == 1
    rb = R.RRTBatch(robot, batch, q0, q1, o, device="cpu", restart=True)
    rb.start([0])
    stop = time.perf_counter() + 0.5
    for _ in range(5):
        rb.round(stop)
    p = rb.problems[0]
    assert p.restarts >= 3 and rb.result(0).n_samples == p.restarts + p.samples
    if rb.result(0).success:
        return
    rb.run(time.perf_counter())  # no time left: its spent samples end it
    assert rb.active.size == 0 and rb.result(0).stop_reason == "max_samples"


def test_planner_grows_handed_problems_trees_between_steps(monkeypatch):
    """A batch's problem handed over (stall_iterations) grows its trees while the other
    problem is still optimised: its RRT path is certified (``solved_at``) before the
    optimiser's last iteration (timed by the callback), stage "fallback", solved before
    the other; FALLBACK_INTERLEAVED off (or no share of the loop's time for its rounds):
    only after the loop. Both paths independently certified."""
    import time

    from jwarp.solvers.planning import planner as PM

    world = block_world_2d()
    starts = np.stack([S4, [-2.895, 1.2639, 1.2862, 0.8666]])
    goals = np.stack([G4, [0.5338, 1.1644, -2.1568, -1.1121]])
    chk = FZ.certify_check(jwarp.robot("planar4"), world, device="cpu")
    # FALLBACK_LOOP_SHARE 0: its start counts, so no round runs in the loop
    for inter, share in ((True, 1.0), (False, 1.0), (True, 0.0)):
        monkeypatch.setattr(PM, "FALLBACK_INTERLEAVED", inter)
        monkeypatch.setattr(PM, "FALLBACK_LOOP_SHARE", share)
        calls: list = []
        o = PL.PlanOptions(n_starts=2, iterations=400, fallback="rrt", n_substeps=8,
                           step=0.02, stall_iterations=3, straight_first=False,
                           callback=lambda it, paths, calls=calls: calls.append(
                               time.perf_counter()))
        pl = PL.Planner("planar4", world, 2, o, device="cpu")
        t0 = time.perf_counter()
        res = pl.plan(starts, goals)
        assert res.feasible.all() and res.stage[0] == "fallback"
        later = [t for t in calls if t > t0 + res.solved_at[0]]  # iterations after it
        if inter and share:
            assert len(later) >= 5  # found while the loop still ran
            assert "while the optimiser ran" in res.fallback_notes[0]
            assert res.solved_at[0] < res.solved_at[1]
            assert res.timings["rrt"] > 0
        else:
            assert not later
        assert chk.check(res.path, meshes=False).ok.all()


def test_batch_round_not_started_when_it_would_end_late(walls, monkeypatch):
    """RRTBatch.round: a round that would end after ``stop_at`` at the last round's pace
    is not started (its problems leave as "time_limit"): a fake clock, 10 s a round,
    ``stop_at`` 15 s ahead: one round, then none."""
    import time as T

    robot, worlds, batch, q0, q1 = walls
    now = [1000.0]
    monkeypatch.setattr(T, "perf_counter", lambda: now[0])
    grow, seen = R._grow_round, []

    def slow(model, active, chk, o, step, stop_at, *a):
        seen.append(stop_at)
        out = grow(model, active, chk, o, step, stop_at, *a)
        now[0] += 10.0
        return out

    monkeypatch.setattr(R, "_grow_round", slow)
    rb = R.RRTBatch(robot, batch, q0, q1, R.RRTOptions(seed=3, goal_bias=0.0), device="cpu")
    rb.start([0, 1, 2])
    stop = now[0] + 15.0
    rb.round(stop)
    left = rb.active.tolist()
    assert left  # no tree connects in its first round of a walled problem
    rb.round(stop)
    assert seen == [stop, stop - 10.0]
    assert rb.active.size == 0
    assert all(rb.result(b).stop_reason == "time_limit" for b in left)
