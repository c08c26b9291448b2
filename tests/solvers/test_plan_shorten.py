"""Short paths by default (issue 39, item 1): PlanOptions.shorten shortens the path of
every solved problem (stop_when_solved, rigid model) with shortcuts proven by the exact
continuous check, then respaces its waypoints; the shortened path is certified again and
kept only when its length cost U_l is lower. Non-default modes (stop_when_solved False,
converge, shorten=0) return what they returned before. Panda scene problems: every
shortened path is re-checked by the independent verifier (tests/verifier.py)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from worlds import block_world_2d

import jwarp
from jwarp.solvers import planning as PL
from jwarp.solvers.planning.shorten import (
    corners,
    corners_many,
    corners_ragged,
    length_cost,
    respace,
    shortcut_paths,
)
from jwarp.world import path_feasibility

S4 = np.array([1.2, 0.0, 0.0, 0.0])
G4 = np.array([-1.2, 0.0, 0.0, 0.0])
#: the multi-starts of test_plan_budget: the first feasible one is a detour
OPTS = dict(n_starts=8, iterations=300, step=0.05, seed=0, n_substeps=8,
            weights=PL.PathWeights(length=0.05), fallback=None)


@pytest.fixture(scope="module")
def world():
    return block_world_2d()


def independent_feasible(robot, world, path):
    n_sub = path_feasibility.substeps_for_voxel(robot, path, world.resolution, safety=2.0,
                                                max_substeps=256)
    return bool(path_feasibility.path_feasible(jwarp.robot(robot), world, path, n_sub)[()])


# ------------------------------------------------------------------ the pieces
def test_length_cost_is_the_planners(world):
    res = PL.plan("planar4", world, S4, G4, shorten=0, **OPTS)
    assert length_cost(res.path[0]) == pytest.approx(res.length_cost[0], rel=1e-4)
    line = np.linspace(S4, G4, 20)
    assert length_cost(line) == pytest.approx(1.0)


def test_corners_of_many_paths_are_each_paths_corners():
    """corners_many (all paths in one pass) gives each path's corners exactly, repeated
    and collinear waypoints included."""
    rng = np.random.default_rng(4)
    for _ in range(100):
        K, W, n = rng.integers(1, 5), rng.integers(2, 10), rng.integers(1, 7)
        P = rng.normal(size=(K, W, n))
        for k in range(K):
            for t in range(1, W - 1):
                u = rng.random()
                if u < 0.25:
                    P[k, t] = P[k, t - 1]
                elif u < 0.5:
                    P[k, t] = 0.5 * (P[k, t - 1] + P[k, t + 1])
        for one, many in zip((corners(p) for p in P), corners_many(P)):
            np.testing.assert_array_equal(one, many)


def test_corners_of_ragged_polylines_are_each_ones_corners():
    """corners_ragged (polylines of different lengths padded in one pass) gives each
    polyline's corners exactly, repeated and collinear points (also at the end)
    included; no polylines: none."""
    rng = np.random.default_rng(7)
    assert corners_ragged([]) == []
    for _ in range(100):
        n = int(rng.integers(1, 7))
        lines = []
        for _ in range(int(rng.integers(1, 6))):
            P = rng.normal(size=(int(rng.integers(2, 12)), n))
            for t in range(1, len(P)):
                u = rng.random()
                if u < 0.25:
                    P[t] = P[t - 1]
                elif u < 0.4 and t + 1 < len(P):
                    P[t] = 0.5 * (P[t - 1] + P[t + 1])
            lines.append(P)
        for one, many in zip((corners(p) for p in lines), corners_ragged(lines)):
            np.testing.assert_array_equal(one, many)


def test_corners_and_respace_keep_the_polyline():
    a, b, c = np.zeros(2), np.array([1.0, 0.0]), np.array([1.0, 2.0])
    path = np.concatenate([np.linspace(a, b, 5), np.linspace(b, c, 9)[1:], [c]])  # c twice
    k = corners(path)
    np.testing.assert_allclose(k, [a, b, c])
    r = respace(k, 12)
    assert r.shape == (12, 2)
    np.testing.assert_allclose(r[[0, -1]], [a, c])
    assert any(np.allclose(q, b) for q in r)  # the corner stays a waypoint
    on_first = np.isclose(r[:, 1], 0.0) & (r[:, 0] <= 1.0 + 1e-12)
    on_second = np.isclose(r[:, 0], 1.0)
    assert np.all(on_first | on_second)  # every waypoint on the polyline
    seg = np.linalg.norm(np.diff(r, axis=0), axis=1)
    assert seg.max() <= 1.5 * seg.min()  # spread in proportion to the lengths
    assert length_cost(r) < length_cost(path)


def test_shortcut_paths_uses_only_proven_segments():
    path = np.array([[0.0, 0.0], [1.0, 1.0], [2.0, 0.0], [3.0, 1.0], [4.0, 0.0]])
    calls = []

    def accept_all(segs, per):
        calls.append((segs.shape, per))
        return np.ones(len(segs), bool)

    out = shortcut_paths(path[None], accept_all, rounds=3)
    np.testing.assert_allclose(out[0], path[[0, -1]])
    assert calls and all(s[1:] == (2, 2) and s[0] % per == 0 for s, per in calls)
    # nothing proven: the path stays as it is
    out = shortcut_paths(path[None], lambda s, p: np.zeros(len(s), bool), rounds=3)
    np.testing.assert_allclose(out[0], path)
    # no rounds, or not active: unchanged
    np.testing.assert_allclose(shortcut_paths(path[None], accept_all, rounds=0)[0], path)
    np.testing.assert_allclose(
        shortcut_paths(path[None], accept_all, 3, active=np.array([False]))[0], path)

    # only the segments that avoid x in (1.5, 2.5) above y 0.25 are proven
    def wall(segs, per):
        u = np.linspace(0, 1, 201)[None, :, None]
        q = segs[:, :1] + u * (segs[:, 1:] - segs[:, :1])
        hit = (np.abs(q[..., 0] - 2.0) < 0.5) & (q[..., 1] < 0.25)
        return ~hit.any(axis=1)

    out = shortcut_paths(path[None], wall, rounds=4)[0]
    assert np.linalg.norm(np.diff(out, axis=0), axis=1).sum() < \
        np.linalg.norm(np.diff(path, axis=0), axis=1).sum() - 0.5
    assert wall(np.stack([out[:-1], out[1:]], 1), 1).all()


def _zigzag(n=9):
    x = np.arange(n, dtype=float)
    return np.stack([x, np.where(np.arange(n) % 2 == 1, 1.0, 0.0)], axis=1)


def _first_only(check):
    """``check`` as MotionCheck.check(group=per) answers it on the CPU: per list only its
    first proven entry is ok (the rest skipped)."""
    def f(segs, per):
        ok = np.asarray(check(segs, per), bool).reshape(-1, per)
        out = np.zeros_like(ok)
        rows = np.nonzero(ok.any(1))[0]
        out[rows, ok[rows].argmax(1)] = True
        return out.reshape(-1)
    return f


def test_shortcut_lists_farthest_first_and_one_call_walks():
    """A path whose first points see nothing: one call covers the walk past them and the
    jump after (its list holds the later points' shortcuts too), farthest first; a check
    that answers only a list's first proven entry gives the same path."""
    path = _zigzag(9)

    def from_four(segs, per):  # only shortcuts starting at x >= 4 are proven
        return segs[:, 0, 0] >= 4.0 - 1e-9

    lists = []

    def rec(segs, per):
        lists.append(segs.copy())
        return from_four(segs, per)

    out = shortcut_paths(path[None], rec, rounds=1, max_points=0)[0]
    assert len(lists) == 1  # the walk from 0 to 4 and the jump from 4: one call
    s = lists[0]
    real = np.linalg.norm(s[:, 1] - s[:, 0], axis=1) > 0
    starts, ends = s[real, 0, 0], s[real, 1, 0]
    assert np.all(np.diff(starts) >= 0)  # from the current point first, then the next
    for x in np.unique(starts):
        assert np.all(np.diff(ends[starts == x]) < 0)  # the farthest first
    np.testing.assert_allclose(out, path[[0, 1, 2, 3, 4, 8]])
    np.testing.assert_allclose(
        shortcut_paths(path[None], _first_only(from_four), rounds=1, max_points=0)[0], out)
    # a short list (max_list): the walk takes more calls, the same path
    calls = []

    def count(segs, per):
        calls.append(per)
        return from_four(segs, per)

    np.testing.assert_allclose(
        shortcut_paths(path[None], count, rounds=1, max_points=0, max_list=2)[0], out)
    assert len(calls) > 1 and max(calls) <= 7
    # a list shorter than the first start's shortcuts still holds them all (never none)
    calls.clear()
    np.testing.assert_allclose(
        shortcut_paths(path[None], count, rounds=1, max_points=0, max_list=1)[0], out)
    assert calls[0] == 7  # the 7 shortcuts from point 0


def test_shortcut_budget_and_min_gain():
    path = _zigzag(9)
    calls = []

    def accept(segs, per):
        calls.append(per)
        return np.ones(len(segs), bool)

    import time
    # a budget already spent: the first call is still made (and takes the jump)
    out = shortcut_paths(path[None], accept, rounds=4, budget=lambda: True)[0]
    assert len(calls) == 1
    np.testing.assert_allclose(out, path[[0, -1]])
    # spent after two calls: the second round's call is not made
    calls.clear()
    shortcut_paths(path[None], lambda s, p: calls.append(p) or (np.arange(len(s)) % p == 1),
                   rounds=4, budget=lambda: len(calls) >= 2)
    assert len(calls) == 2
    # a deadline already passed: nothing
    calls.clear()
    out = shortcut_paths(path[None], accept, rounds=4, deadline=time.perf_counter() - 1.0)[0]
    assert not calls
    np.testing.assert_allclose(out, corners(path))
    # a round gaining less than min_gain (relative) ends the rounds
    def short_only(segs, per):  # only short shortcuts: every round cuts a little more
        return np.linalg.norm(segs[:, 1] - segs[:, 0], axis=1) <= 1.2

    def rounds_of(min_gain):
        starts = []

        def rec(segs, per):
            starts.append(bool(np.allclose(segs[0, 0], path[0])))
            return short_only(segs, per)

        out = shortcut_paths(path[None], rec, rounds=6, min_gain=min_gain)[0]
        return sum(starts), np.linalg.norm(np.diff(out, axis=0), axis=1).sum()

    n0, len0 = rounds_of(0.0)
    n1, len1 = rounds_of(0.5)
    assert n0 >= 2 and n1 == 1  # round 1 gains < 50 %: no second round
    assert len0 <= len1 < np.linalg.norm(np.diff(path, axis=0), axis=1).sum()


def test_rounds_end_near_the_straight_line():
    """``near_straight``: a path whose polyline is within that length ratio of its straight
    line after a round takes no further round (a check call saved where little is left
    to gain); bad values are a ValueError naming the argument. A detour around a disc
    (radius 1 at the origin): each round pulls the string tighter around it."""
    path = np.array([[-2.0, 0.0], [-2.0, 2.0], [-1.0, 2.0], [0.0, 2.0], [1.0, 2.0],
                     [2.0, 2.0], [2.0, 0.0]])
    straight = 4.0

    def clear_of_disc(segs):
        a, b = segs[:, 0], segs[:, 1]
        d = b - a
        t = np.clip(-np.sum(a * d, 1) / np.maximum(np.sum(d * d, 1), 1e-12), 0.0, 1.0)
        return np.linalg.norm(a + t[:, None] * d, axis=1) >= 1.0

    def run(near):
        lengths = []

        def rec(segs, per):
            return clear_of_disc(segs)

        out = path
        for rounds in range(1, 7):  # the length after each number of rounds
            out = shortcut_paths(path[None], rec, rounds=rounds, min_gain=0.0,
                                 near_straight=near)[0]
            lengths.append(np.linalg.norm(np.diff(out, axis=0), axis=1).sum() / straight)
        return lengths

    free = run(None)
    assert free[0] > free[1] > np.pi / 4, free  # the second round gains too
    # a bound just above the first round's ratio: no second round
    near = run(free[0] * 1.001)
    assert near == pytest.approx([free[0]] * 6), near
    # a bound never reached: as without it
    assert run(1.0) == pytest.approx(free)
    for bad in (0.5, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="^near_straight: expected a length ratio >= 1"):
            shortcut_paths(path[None], clear_of_disc, rounds=2, near_straight=bad)


# ------------------------------------------------------------------ the planner
def test_default_path_is_shortened_and_feasible(world):
    first = PL.plan("planar4", world, S4, G4, shorten=0, **OPTS)
    short = PL.plan("planar4", world, S4, G4, **OPTS)
    full = PL.plan("planar4", world, S4, G4, shorten=4, shorten_budget=None, **OPTS)
    assert PL.PlanOptions().shorten is None and PL.PlanOptions().shorten_budget == 0.5
    assert first.feasible[0] and short.feasible[0] and full.feasible[0]
    assert first.length_before is None  # shortening off
    assert short.length_before[0] == pytest.approx(first.length_cost[0])
    # the detour of the first feasible start is cut: shorter with the default (one round
    # on the CPU, within the budget), much shorter in four rounds without a budget
    assert PL.options.shorten_for(PL.PlanOptions(), "cpu") == 1
    assert PL.options.shorten_for(PL.PlanOptions(), "cuda:0") == 4
    assert PL.options.shorten_for(PL.PlanOptions(shorten=3), "cpu") == 3
    assert short.length_cost[0] < 0.95 * first.length_cost[0]  # one round on the CPU
    assert full.length_cost[0] <= short.length_cost[0] + 1e-6
    assert full.length_cost[0] < 0.8 * first.length_cost[0]
    assert length_cost(short.path[0]) == pytest.approx(short.length_cost[0], rel=1e-4)
    assert "shorten" in short.timings
    # same start, goal, waypoints; the same start won at the same iteration
    np.testing.assert_allclose(short.path[0, [0, -1]], first.path[0, [0, -1]])
    assert short.path.shape == first.path.shape
    assert short.start_index[0] == first.start_index[0]
    assert short.iterations[0] == first.iterations[0]
    # certified again by the planner's check and by an independent one
    robot = PL.Planner("planar4", world, 1).robot
    assert independent_feasible(robot, world, short.path[0])
    # its costs are the objective's at the new path (U_path = collision + w U_l)
    assert short.cost[0] == pytest.approx(short.collision_cost[0]
                                          + 0.05 * short.length_cost[0], rel=1e-4)
    d = short.to_dict(0)
    assert d["length_before_shortening"] == pytest.approx(first.length_cost[0])


def test_non_default_modes_unchanged(world):
    for extra in (dict(stop_when_solved=False), dict(converge=True, stop_when_solved=False,
                                                      iterations=60)):
        a = PL.plan("planar4", world, S4, G4, shorten=0, **{**OPTS, **extra})
        b = PL.plan("planar4", world, S4, G4, **{**OPTS, **extra})
        np.testing.assert_array_equal(a.path, b.path)
        np.testing.assert_array_equal(a.length_cost, b.length_cost)
        assert b.length_before is None


def test_a_batch_is_shortened_per_problem(world):
    starts = np.stack([S4, np.array([2.0, 1.0, 0.0, 0.0])])
    goals = np.stack([G4, np.array([2.0, -1.0, 0.0, 0.0])])
    o = {**OPTS, "fallback": "rrt"}
    first = PL.plan("planar4", world, starts, goals, shorten=0, **o)
    short = PL.plan("planar4", world, starts, goals, **o)
    assert short.feasible.all() and first.feasible.all()
    assert np.all(short.length_cost <= first.length_cost * (1 + 1e-6))
    # length_before: U_l of the same paths (on the host in float64 where the costs wait
    # for their first read; the float32 kernel's in ``first``)
    np.testing.assert_allclose(short.length_before, first.length_cost, rtol=1e-6)
    robot = PL.Planner("planar4", world, 1).robot
    for p in short.path:
        assert independent_feasible(robot, world, p)


def test_batch_of_worlds():
    """World.batch: each problem's shortcuts are proven in its own world (re-checked in
    that world alone)."""
    import jwarp
    from jwarp.world import World
    from jwarp.world.collision import min_distances
    from jwarp.world.path_feasibility import certify_check

    robot = jwarp.robot("arm7")
    rng = np.random.default_rng(13)
    worlds = []
    for _ in range(3):
        w = World.of_shapes()
        for j in range(3):
            w.add(f"b{j}", "box", rng.uniform(0.05, 0.2, 3),
                  rng.uniform([-0.7, -0.7, 0.0], [0.7, 0.7, 1.0]))
        worlds.append(w)
    batch = World.batch(worlds)
    lim = np.array(robot.joint_limits)
    free = []
    while len(free) < 6:
        c = rng.uniform(lim[:, 0], lim[:, 1], (64, robot.n_dof)) * 0.6
        ok = np.ones(64, bool)
        for w in worlds:
            ok &= min_distances(robot, c, w, dtype=np.float64).min(axis=1) > 0.02
        free.extend(c[ok])
    starts, goals = np.array(free[:3]), np.array(free[3:6])
    o = dict(n_starts=4, iterations=60, start_kind="random", seed=1, device="cpu")
    first = PL.plan(robot, batch, starts, goals, shorten=0, **o)
    short = PL.plan(robot, batch, starts, goals, **o)
    np.testing.assert_array_equal(short.feasible, first.feasible)
    assert short.feasible.sum() >= 2
    for b in np.nonzero(short.feasible)[0]:
        assert short.length_cost[b] <= first.length_cost[b] * (1 + 1e-6)
        assert certify_check(robot, worlds[b], device="cpu").check(short.path[b]).ok[0]
    assert np.sum(short.length_cost[short.feasible]) < np.sum(first.length_cost[first.feasible])


@pytest.mark.parametrize("bad", [-1, 1.5, True, "4"])
def test_bad_shorten(bad):
    with pytest.raises((ValueError, TypeError), match="shorten"):
        PL.PlanOptions(shorten=bad).validate()


@pytest.mark.parametrize("bad", [0, -0.5, float("nan"), float("inf"), "x"])
def test_bad_shorten_budget(bad):
    with pytest.raises((ValueError, TypeError), match="shorten_budget"):
        PL.PlanOptions(shorten_budget=bad).validate()


def test_budget_counts_evaluations_not_seconds(world, monkeypatch):
    """The default budget is deterministic (the same path twice); a smaller one makes
    fewer check evaluations, never fewer than the first call's; None spends the most."""
    from jwarp.world.motion import MotionCheck

    spent: list[int] = []
    original = MotionCheck.check

    def counting(self, *args, **kwargs):
        r = original(self, *args, **kwargs)
        if kwargs.get("group"):  # the shortcuts' calls
            spent[-1] += r.evaluations
        return r

    monkeypatch.setattr(MotionCheck, "check", counting)
    runs = {}
    for budget in (1e-6, 0.5, 0.5, None):
        spent.append(0)
        runs.setdefault(budget, []).append(
            (PL.plan("planar4", world, S4, G4, shorten_budget=budget, **OPTS), spent[-1]))
    (a, ea), (b, eb) = runs[0.5]
    np.testing.assert_array_equal(a.path, b.path)
    assert ea == eb > 0
    (tiny, et), = runs[1e-6]
    (free, ef), = runs[None]
    assert 0 < et <= ea <= ef
    assert tiny.length_cost[0] <= tiny.length_before[0]  # never longer
    assert a.length_cost[0] < a.length_before[0]
    assert free.length_cost[0] <= a.length_cost[0] + 1e-6


def test_near_straight_paths_are_left_alone(world, monkeypatch):
    import jwarp.solvers.planning.shorten as SH
    from jwarp.solvers.planning.planner import NEAR_STRAIGHT

    pl = PL.Planner("planar4", world, 1, PL.PlanOptions(shorten=0, **OPTS))
    res = pl.plan(S4, G4)
    assert res.length_cost[0] > 1.5
    calls = []
    original = SH.shortcut_paths
    monkeypatch.setattr(SH, "shortcut_paths",
                        lambda *a, **k: calls.append(1) or original(*a, **k))
    pl.options.shorten = 4
    path = res.path.copy()
    res.length_cost[0] = NEAR_STRAIGHT  # as if the first feasible path were nearly straight
    pl._shorten(pl._buffers.objective.n_sub, res, None)
    assert not calls and np.array_equal(res.path, path)
    res.length_cost[0] = NEAR_STRAIGHT + 0.01
    pl._shorten(pl._buffers.objective.n_sub, res, None)
    assert calls


def test_time_limit_bounds_it(world):
    # the time is up before the shortening: the path stays the first feasible one
    import time

    pl = PL.Planner("planar4", world, 1, PL.PlanOptions(shorten=0, **OPTS))
    res = pl.plan(S4, G4)
    path = res.path.copy()
    pl.options.shorten = 4
    pl._shorten(pl._buffers.objective.n_sub, res, deadline=time.perf_counter() - 1.0)
    np.testing.assert_array_equal(res.path, path)
    assert res.timings["shorten"] < 0.01  # nothing tried
    # with time left it shortens
    pl._shorten(pl._buffers.objective.n_sub, res, deadline=time.perf_counter() + 100.0)
    assert res.length_cost[0] < 0.8 * res.length_before[0]


# ------------------------------------------------------------------ panda scenes
def test_panda_scene_paths_short_and_verified(tmp_path):
    """Three table_under_pick problems of benchmarks/scene_problems.py: the default paths
    are no longer than the first feasible ones (much shorter together), and every one is
    collision-free by the independent verifier (URDF meshes and spheres, coal)."""
    from jwarp.importers.robot import example_robot_urdf

    try:
        example_robot_urdf("panda_description/urdf/panda.urdf")
    except ValueError as e:
        pytest.skip(str(e))
    pytest.importorskip("coal")
    root = Path(__file__).resolve().parents[2]
    sys.path.insert(0, str(root / "benchmarks"))
    import scene_problems as SP
    from verifier import PathVerifier, robot_spheres

    from jwarp.world import exact_world, load_scene
    from jwarp.world.moveit import joint_vector
    from jwarp.world.scene_file import robot_frames

    robot, urdf = SP.load_robot()
    index = SP.generate(tmp_path, 3, 1, ["table_under_pick"], log=lambda s: None)
    before, after = [], []
    for e in index["problems"]:
        scene = load_scene(tmp_path / e["file"], robot_frames(robot))
        world = exact_world(scene)
        q0 = joint_vector(robot, scene.start, "start")
        q1 = joint_vector(robot, scene.goal, "goal", q0)
        o = dict(margin=0.0, endpoint_margin=0.0, fallback=None, device="cpu")
        first = PL.plan(robot, world, q0, q1, shorten=0, **o)
        res = PL.plan(robot, world, q0, q1, **o)
        assert res.feasible[0] == first.feasible[0]
        if not res.feasible[0]:
            continue
        assert res.length_cost[0] <= first.length_cost[0] * (1 + 1e-6)
        before.append(first.length_cost[0])
        after.append(res.length_cost[0])
        v = PathVerifier(urdf, None, scene.shapes, spheres=robot_spheres(robot),
                         joint_names=robot.joint_names)
        got = v.check_path(res.path[0], margin=0.0, endpoint_margin=0.0)
        assert got.min_distance >= 0, str(got)
    assert len(after) >= 2
    assert sum(after) < 0.7 * sum(before)


def test_shortened_costs_are_evaluated_when_read(world):
    """The shortened rows' costs are left to their first read (a PathObjective of their
    own): read after the Planner's next call, they are those of a call read at once."""
    pl = PL.Planner("planar4", world, 1, PL.PlanOptions(**OPTS))
    late = pl.plan(S4, G4)
    assert late.__dict__.get("_cost") is None  # deferred (set by the first read)
    pl.plan(np.array([2.0, 1.0, 0.0, 0.0]), np.array([2.0, -1.0, 0.0, 0.0]))  # reuses buffers
    now = pl.plan(S4, G4)
    np.testing.assert_array_equal(late.path, now.path)
    for name in ("cost", "length_cost", "collision_cost"):
        np.testing.assert_allclose(getattr(late, name), getattr(now, name), rtol=1e-6)
    assert late.length_cost[0] == pytest.approx(length_cost(late.path[0]), rel=1e-4)
    assert late.length_cost[0] < late.length_before[0]
    assert late.cost[0] == pytest.approx(late.collision_cost[0] + 0.05 * late.length_cost[0],
                                         rel=1e-4)
