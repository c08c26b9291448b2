"""Budgets and fallback of the planner (PlanOptions.time_limit, stop_when_solved on by
default, fallback "rrt"): PlanResult.stop_reason per call and stage per problem; the
RRT-Connect fallback solves a planar4 problem the straight line and the multi-starts do
not solve in a few iterations."""

import inspect
import time

import numpy as np
import pytest
from worlds import block_world_2d

import jwarp
from jwarp.solvers import planning as PL
from jwarp.solvers.planning.rrt import RRTOptions
from jwarp.world import path_feasibility

S4 = np.array([1.2, 0.0, 0.0, 0.0])
G4 = np.array([-1.2, 0.0, 0.0, 0.0])
#: an easy problem: the straight line is feasible at once
S_EASY = np.array([2.0, 1.0, 0.0, 0.0])
G_EASY = np.array([2.0, -1.0, 0.0, 0.0])


@pytest.fixture(scope="module")
def world():
    return block_world_2d()


def independent_feasible(robot, world, path):
    n_sub = path_feasibility.substeps_for_voxel(robot, path, world.resolution, safety=2.0, max_substeps=256)
    return bool(path_feasibility.path_feasible(jwarp.robot(robot), world, path, n_sub)[()])


def test_defaults():
    o = PL.PlanOptions()
    assert o.stop_when_solved is True and o.fallback == "rrt" and o.time_limit is None
    assert o.fallback_after is None and o.rrt is None
    assert PL.options.fallback_share(o, "cpu") == 0.15
    assert PL.options.fallback_share(o, "cuda:0") == 0.08
    assert PL.options.fallback_share(PL.PlanOptions(fallback_after=0.3), "cuda:0") == 0.3
    # a batch on CUDA: the optimizer's lockstep steps get half the limit
    assert PL.options.fallback_share(o, "cuda:0", 700) == 0.5
    assert PL.options.fallback_share(o, "cpu", 700) == 0.15
    assert PL.options.fallback_share(PL.PlanOptions(fallback_after=0.3), "cuda:0", 700) == 0.3
    assert "options" in inspect.signature(PL.plan).parameters  # plan()'s options: PlanOptions


def test_stop_when_solved_ends_at_the_first_feasible_start(world):
    o = dict(n_starts=8, iterations=300, step=0.05, seed=0, n_substeps=8,
             weights=PL.PathWeights(length=0.05), fallback=None)
    first = PL.plan("planar4", world, S4, G4, **o)
    every = PL.plan("planar4", world, S4, G4, stop_when_solved=False, **o)
    assert first.feasible[0] and first.stop_reason == "solved"
    assert list(first.stage) == ["optimizer"]
    # without it every start runs on: more feasible starts, the iterations used up
    assert every.feasible[0] and every.stop_reason == "iterations"
    assert every.n_feasible[0] > first.n_feasible[0] == 1
    # the start that solved it first is the same, at the same iteration
    k = int(first.start_index[0])
    assert every.all_feasible[0, k]
    assert every.all_iterations[0, k] == first.all_iterations[0, k] == first.iterations[0]


def test_all_done_when_every_start_finishes(world):
    res = PL.plan("planar4", world, S_EASY, G_EASY, start_kind="straight", n_starts=1,
                  stop_when_solved=False, fallback=None)
    assert res.feasible[0] and res.stop_reason == "all_done"


def test_time_limit_ends_the_optimisation(world):
    # a step too small to move anything: the straight line stays in collision
    PL.plan("planar4", world, S4, G4, start_kind="straight", iterations=1, fallback=None)  # load
    t = time.perf_counter()
    res = PL.plan("planar4", world, S4, G4, start_kind="straight", step=1e-9,
                  iterations=10**7, time_limit=0.3, fallback=None)
    wall = time.perf_counter() - t
    assert res.stop_reason == "time_limit" and not res.feasible[0]
    assert list(res.stage) == ["none"]
    assert 0.3 <= res.wall_time <= wall
    assert wall < 3.0  # one iteration and the exact check after the limit (shared CPU)
    assert 0 < res.iterations[0] < 10**7  # the iteration it stopped at
    # with the fallback: the multi-starts get fallback_after (0.15) of the time, then RRT
    # (stall_iterations off: the start that cannot move is not handed over early)
    res = PL.plan("planar4", world, S4, G4, start_kind="straight", step=1e-9,
                  iterations=10**7, time_limit=5.0, stall_iterations=None)
    assert res.feasible[0] and list(res.stage) == ["fallback"]
    assert res.stop_reason == "solved"
    before = res.timings["endpoints"] + res.timings.get("straight", 0.0)
    assert res.timings["optimizer"] + before >= 0.15 * 5.0 - 0.01 and res.wall_time < 10.0
    assert "handed_over" not in res.timings
    # by default the stalled start (its cost cannot fall) goes to the fallback at once
    res = PL.plan("planar4", world, S4, G4, start_kind="straight", step=1e-9,
                  iterations=10**7, time_limit=5.0)
    assert res.feasible[0] and list(res.stage) == ["fallback"]
    assert res.timings["handed_over"] == 1
    assert res.iterations[0] >= 0 and res.timings["optimizer"] < 0.15 * 5.0
    assert res.solved_at[0] <= res.wall_time


def test_fallback_solves_what_the_multi_starts_do_not(world):
    robot = jwarp.robot("planar4")
    o = dict(n_starts=2, iterations=3, seed=0)
    plain = PL.plan(robot, world, S4, G4, fallback=None, **o)
    assert not plain.feasible[0]  # the straight line and a random start, 3 iterations
    assert plain.stop_reason == "iterations" and list(plain.stage) == ["none"]
    res = PL.plan(robot, world, S4, G4, **o)
    assert res.feasible[0] and list(res.stage) == ["fallback"]
    assert res.stop_reason == "solved" and res.start_index[0] == -1
    assert independent_feasible(robot, world, res.path[0])
    np.testing.assert_allclose(res.path[0, 0], S4)
    np.testing.assert_allclose(res.path[0, -1], G4)
    assert res.path.shape == (1, 20, 4)
    # the multi-starts' own results stay as they were
    np.testing.assert_array_equal(res.all_feasible, plain.all_feasible)
    assert res.n_feasible[0] == 0
    # the straight line was tried first (it collides), then the endpoints checked and
    # the random start as drawn; the RRT's path (at most 20 nodes) certified as it is by
    # the trees' own check, in one call (no optimisation of it)
    assert set(res.timings) == {"straight", "endpoints", "starts", "optimizer", "rrt",
                                "fallback_certify", "shorten"}
    assert res.iterations[0] == 0 and "certified as it is" in res.fallback_notes[0]
    d = res.to_dict(0)
    assert d["stop_reason"] == "solved" and d["stage"] == "fallback" and d["feasible"]


def test_fallback_only_for_the_unsolved_problems(world):
    starts, goals = np.array([S4, S_EASY]), np.array([G4, G_EASY])
    # the easy problem's straight line is free: the straight stage solves it, the other
    # goes on to the multi-starts (and the fallback)
    for fb, stages in ((None, ["none", "straight"]), ("rrt", ["fallback", "straight"])):
        opts = PL.PlanOptions(n_starts=4, iterations=3, seed=0, fallback=fb)
        res = PL.Planner("planar4", world, 2, opts, device="cpu").plan(starts, goals)
        assert list(res.stage) == stages
        assert res.feasible[1] and res.start_index[1] >= 0
        assert res.feasible[0] == (fb == "rrt")
        assert res.stop_reason == ("solved" if fb else "iterations")


def test_fallback_none_is_the_clis_word(world):
    """Issue 39 item 5: ``fallback="none"`` (the CLI's ``--fallback none``) is None in
    Python too: stored as None, and the same plan."""
    for word in ("none", "None", " NONE "):
        assert PL.PlanOptions(fallback=word).fallback is None
    assert PL.PlanOptions(fallback="RRT").fallback == "rrt"
    o = dict(n_starts=2, iterations=3, seed=0)
    plain = PL.plan("planar4", world, S4, G4, fallback=None, **o)
    word = PL.plan("planar4", world, S4, G4, fallback="none", **o)
    assert list(word.stage) == list(plain.stage) == ["none"]
    np.testing.assert_array_equal(word.path, plain.path)
    assert "rrt" not in word.timings


def test_fallback_with_its_options(world):
    # too few samples to connect the trees: the fallback fails, the result is the
    # optimiser's
    rrt = RRTOptions(max_samples=1, batch=1, goal_bias=0.0)
    res = PL.plan("planar4", world, S4, G4, n_starts=2, iterations=3, seed=0, rrt=rrt)
    assert not res.feasible[0] and list(res.stage) == ["none"]
    assert res.stop_reason == "iterations" and "rrt" in res.timings


@pytest.mark.parametrize("field, value, error, match", [
    ("time_limit", -1.0, ValueError, "^time_limit: expected a number > 0"),
    ("time_limit", 0, ValueError, "^time_limit: expected a number > 0"),
    ("time_limit", float("nan"), ValueError, "^time_limit"),
    ("time_limit", float("inf"), ValueError, "^time_limit"),
    ("time_limit", True, TypeError, "^time_limit"),
    ("time_limit", "1", TypeError, "^time_limit"),
    ("problem_time_limit", -1.0, ValueError, "^problem_time_limit: expected a number > 0"),
    ("problem_time_limit", 0, ValueError, "^problem_time_limit: expected a number > 0"),
    ("problem_time_limit", float("nan"), ValueError, "^problem_time_limit"),
    ("problem_time_limit", True, TypeError, "^problem_time_limit"),
    ("problem_time_limit", "1", TypeError, "^problem_time_limit"),
    ("stall_iterations", 0, ValueError, "^stall_iterations"),
    ("stall_iterations", 2.5, ValueError, "^stall_iterations"),
    ("reseed_iterations", -1, ValueError, "^reseed_iterations"),
    ("reseed_iterations", 1.5, ValueError, "^reseed_iterations"),
    ("fallback", "rrt*", ValueError, "^fallback: expected 'rrt', 'none' or None"),
    ("fallback", "", ValueError, "^fallback"),
    ("fallback", 0, ValueError, "^fallback"),
    ("fallback_after", 0.0, ValueError, "^fallback_after"),
    ("fallback_after", 1.0, ValueError, "^fallback_after"),
    ("stop_when_solved", "yes", TypeError, "^stop_when_solved"),
])
def test_budget_options_are_validated(world, field, value, error, match):
    with pytest.raises(error, match=match):
        PL.PlanOptions(**{field: value}).validate()
    with pytest.raises(error, match=match):
        PL.plan("planar4", world, S4, G4, **{field: value})


def test_fallback_starts_new_trees_while_time_is_left(world, monkeypatch):
    """rrt.max_samples used up without a path: with a time limit the trees start again
    (the generator's next samples) until a path or the limit; without one, one try."""
    from jwarp.solvers.planning import rrt as R

    robot = jwarp.robot("planar4")
    tries = []
    original = R.rrt_connect

    def counting(*args, **kwargs):
        r = original(*args, **kwargs)
        tries.append(r.stop_reason)
        return r

    monkeypatch.setattr(R, "rrt_connect", counting)
    o = dict(n_starts=2, iterations=3, seed=0, rrt=RRTOptions(max_samples=150, batch=1))
    once = PL.plan(robot, world, S4, G4, **o)
    assert tries == ["max_samples"] and not once.feasible[0]
    assert "rrt.max_samples used up" in once.reasons[0]
    tries.clear()
    res = PL.plan(robot, world, S4, G4, time_limit=20.0, **o)
    assert len(tries) > 1 and set(tries[:-1]) == {"max_samples"}
    assert res.feasible[0] and list(res.stage) == ["fallback"] and tries[-1] == "connected"
    assert independent_feasible(robot, world, res.path[0])


def test_stalled_starts_are_drawn_again(world):
    """reseed_iterations: a start whose cost stopped falling gets a new random path (a
    jump far beyond max_step between two iterations), each start at most RESEED_MAX
    times, counted in timings["reseeded"]; off (0): no jump; the default by device. Feasible results
    independently certified."""
    from jwarp.solvers.planning import planner as PM

    out = {}
    assert PL.options.reseed_for(PL.PlanOptions(), "cpu") == 5
    assert PL.options.reseed_for(PL.PlanOptions(), "cuda:0") is None
    assert PL.options.reseed_for(PL.PlanOptions(reseed_iterations=0), "cpu") is None
    for reseed in (3, 0):
        snaps = []
        o = dict(n_starts=3, iterations=150, step=0.05, max_step=0.05, seed=1,
                 n_substeps=8, fallback=None, stall_iterations=None, straight_first=False,
                 reseed_iterations=reseed, callback=lambda it, p, s=snaps: s.append(p.copy()))
        res = PL.plan("planar4", world, S4, G4, **o)
        jumps = sum(int((np.abs(b - a).max(axis=(1, 2)) > 0.3).sum())
                    for a, b in zip(snaps, snaps[1:]))
        out[reseed] = (res, jumps)
        if res.feasible[0]:
            assert independent_feasible("planar4", world, res.path[0])
    res, jumps = out[3]
    assert 1 <= res.timings["reseeded"] <= PM.RESEED_MAX * 3
    assert jumps == res.timings["reseeded"]
    res, jumps = out[0]
    assert "reseeded" not in res.timings and jumps == 0
    # stop_when_solved=False (the best of the multi-starts, e.g. learning labels): none
    keep = PL.plan("planar4", world, S4, G4, n_starts=3, iterations=150, step=0.05,
                   max_step=0.05, seed=1, n_substeps=8, fallback=None, stall_iterations=None,
                   straight_first=False, reseed_iterations=3, stop_when_solved=False)
    assert "reseeded" not in keep.timings
