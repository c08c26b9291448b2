"""Batches without lockstep (issue 45): PlanResult.solved_at per stage, a hard problem
does not hold the others of its batch, PlanOptions.stall_iterations hands a stalled
problem to the fallback, problem_time_limit bounds each problem's search; the last
check of a batch gives one start per problem to the mesh certificate."""

import time

import numpy as np
import pytest
from worlds import block_world_2d

import jwarp
from jwarp.solvers import planning as PL
from jwarp.world import path_feasibility as FZ

S4 = np.array([1.2, 0.0, 0.0, 0.0])
G4 = np.array([-1.2, 0.0, 0.0, 0.0])
#: the straight line solves it
S_EASY = np.array([2.0, 1.0, 0.0, 0.0])
G_EASY = np.array([2.0, -1.0, 0.0, 0.0])
#: one problem of each stage: straight line, multi-starts, fallback
STARTS = np.stack([S_EASY, S4, S4 * 0.9])
GOALS = np.stack([G_EASY, G4, G4 * 0.9])
STAGED = dict(n_starts=4, iterations=300, seed=0, n_substeps=8, device="cpu")


@pytest.fixture(scope="module")
def world():
    return block_world_2d()


def certified(robot, world, path):
    n_sub = FZ.substeps_for_voxel(robot, path, world.resolution, safety=2.0,
                                  max_substeps=256)
    return bool(FZ.path_feasible(jwarp.robot(robot), world, path, n_sub)[()])


def test_solved_at_per_stage_and_a_hard_problem_holds_no_other(world):
    robot = jwarp.robot("planar4")
    PL.plan(robot, world, STARTS, GOALS, **STAGED)  # kernels loaded
    t = time.perf_counter()
    res = PL.plan(robot, world, STARTS, GOALS, **STAGED)
    wall = time.perf_counter() - t
    assert list(res.stage) == ["straight", "optimizer", "fallback"]
    assert res.feasible.all() and res.stop_reason == "solved"
    for b in range(3):
        assert certified(robot, world, res.path[b])
    s = res.solved_at
    assert s.shape == (3,) and np.all(np.isfinite(s))
    # stage by stage, each within the call
    assert 0 < s[0] <= s[1] <= s[2] <= res.wall_time <= wall
    # the easy ones were solved before the hard one's RRT began (not at the batch's end)
    assert s[1] <= res.wall_time - res.timings["rrt"]
    assert res.timings["handed_over"] == 1  # its starts stalled: handed over early
    d = res.to_dict(2)
    assert d["stage"] == "fallback" and d["solved_at_s"] == pytest.approx(s[2])


def test_solved_at_nan_where_unsolved_and_the_straight_stage(world):
    res = PL.plan("planar4", world, STARTS, GOALS, n_starts=2, iterations=3, seed=0,
                  fallback=None, device="cpu")
    assert list(res.stage) == ["straight", "none", "none"]
    assert np.isnan(res.solved_at[1:]).all() and 0 < res.solved_at[0] <= res.wall_time
    assert res.to_dict(1)["solved_at_s"] is None
    line = PL.plan("planar4", world, S_EASY, G_EASY, device="cpu")  # the straight result
    assert list(line.stage) == ["straight"]
    assert 0 < line.solved_at[0] <= line.wall_time


def test_stall_iterations_ends_the_multi_starts_early(world):
    # no stalled start drawn again (reseed_iterations 0): those draws solve S4 -> G4
    o = dict(STAGED, n_starts=8, step=0.05, weights=PL.PathWeights(length=0.05),
             reseed_iterations=0)
    starts, goals = np.stack([S_EASY, S4, S4 * 0.9]), np.stack([G_EASY, G4, G4 * 0.9])
    PL.plan("planar4", world, starts, goals, **o)  # kernels loaded
    slow = PL.plan("planar4", world, starts, goals, stall_iterations=None, **o)
    fast = PL.plan("planar4", world, starts, goals, **o)
    for res in (slow, fast):  # the multi-starts solve neither hard problem
        assert list(res.stage) == ["straight", "fallback", "fallback"] and res.feasible.all()
    assert "handed_over" not in slow.timings and fast.timings["handed_over"] == 2
    # without it the multi-starts run their 300 iterations first
    assert fast.timings["optimizer"] < slow.timings["optimizer"]
    assert fast.solved_at[1:].max() < slow.solved_at[1:].max()


def test_problem_time_limit_bounds_each_problem(world):
    # a step too small to move anything: the straight line stays in collision
    o = dict(start_kind="straight", step=1e-9, iterations=10**7, stall_iterations=None,
             device="cpu")
    PL.plan("planar4", world, S4, G4, start_kind="straight", iterations=1, fallback=None)
    t = time.perf_counter()
    res = PL.plan("planar4", world, S4, G4, problem_time_limit=0.3, fallback=None, **o)
    wall = time.perf_counter() - t
    assert res.stop_reason == "time_limit" and list(res.stage) == ["none"]
    assert 0.3 <= res.wall_time <= wall < 3.0
    assert np.isnan(res.solved_at[0])
    # with the fallback: the multi-starts get fallback_after of the problem's budget (of
    # the smaller limit where both are given), then the fallback solves it
    for kw in (dict(problem_time_limit=2.0), dict(problem_time_limit=2.0, time_limit=50.0),
               dict(problem_time_limit=50.0, time_limit=2.0)):
        res = PL.plan("planar4", world, S4, G4, **o, **kw)
        assert res.feasible[0] and list(res.stage) == ["fallback"]
        before = res.timings["endpoints"] + res.timings.get("straight", 0.0)
        assert 0.15 * 2.0 - 0.01 <= res.timings["optimizer"] + before < 0.15 * 50.0
        assert res.solved_at[0] <= res.wall_time
    # without a limit of either kind: 10**7 iterations would not end; a fallback without
    # a budget leaves them their end (here a few iterations)
    res = PL.plan("planar4", world, S4, G4, **dict(o, iterations=5))
    assert res.feasible[0] and list(res.stage) == ["fallback"]


def test_problem_time_limit_sub_options():
    o = PL.PlanOptions(problem_time_limit=1.5, stall_iterations=5)
    o.validate()
    assert PL.PlanOptions().problem_time_limit is None
    assert PL.PlanOptions().stall_iterations == 20


def test_best_of_group_picks_the_largest_score_per_problem():
    from jwarp.solvers.planning.planner import _best_of_group

    group = np.array([0, 0, 0, 1, 1, 2, 3])
    score = np.array([1.0, 3.0, 2.0, 5.0, 4.0, 0.0, 9.0])
    sel = np.array([1, 1, 1, 0, 1, 1, 0], bool)
    assert _best_of_group(group, score, sel, 1).tolist() == [0, 1, 0, 0, 1, 1, 0]
    assert _best_of_group(group, score, sel, 2).tolist() == [0, 1, 1, 0, 1, 1, 0]
    assert not _best_of_group(group, score, np.zeros(7, bool), 1).any()
