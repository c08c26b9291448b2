"""jwarp.learn.plan_data: Table 3.2 worlds and hard-task labels (thesis 3.5.1)."""

import numpy as np
import pytest

import jwarp
from jwarp.learn.plan_data import PlanDataOptions, WorldLabels, label_world, world_for
from jwarp.solvers import planning as PL
from jwarp.world import path_feasibility, world_from_occupancy

N = 64
LIM = np.array([[-1.0, 1.0], [-1.0, 1.0]])
H = 2.0 / (N - 1)
FAST = PlanDataOptions(n_waypoints=12, max_starts=6, iterations=150, step=0.05,
                       n_substeps=6)


@pytest.fixture(scope="module")
def world():
    """planar4's workspace with two blocks: some straight lines cross them."""
    xs = LIM[0, 0] + H * np.arange(N)
    X, Y = np.meshgrid(xs, xs, indexing="ij")
    occ = ((X > 0.5) & (X < 0.75) & (np.abs(Y) < 0.3)) | ((Y > 0.45) & (Y < 0.6) & (X < 0.2))
    return world_from_occupancy(occ, LIM, H)


@pytest.fixture(scope="module")
def labels(world):
    return label_world(jwarp.robot("planar4"), world, 12, 5, FAST)


def independent_feasible(robot, world, path):
    n_sub = path_feasibility.substeps_for_voxel(robot, path, world.voxel_size, safety=2.0, max_substeps=256)
    return bool(path_feasibility.path_feasible(jwarp.robot(robot), world, path, n_sub)[()])


def test_shapes_and_settings(labels):
    L = labels
    assert isinstance(L, WorldLabels) and len(L) == 12
    assert L.starts.shape == L.goals.shape == (12, 4) and L.starts.dtype == np.float32
    assert L.paths.shape == (12, 12, 4) and L.paths.dtype == np.float32
    for a in (L.cost, L.feasible, L.hard, L.length_cost):
        assert a.shape == (12,)
    assert L.feasible.dtype == bool and L.hard.dtype == bool
    np.testing.assert_allclose(L.paths[:, 0], L.starts, atol=1e-6)
    np.testing.assert_allclose(L.paths[:, -1], L.goals, atol=1e-6)
    import json
    json.dumps(L.settings)
    assert L.settings["options"]["max_starts"] == 6 and L.settings["seed"] == 5
    assert L.hard.any() and (~L.hard).any()  # both kinds in this world


def test_deterministic(world, labels):
    again = label_world(jwarp.robot("planar4"), world, 12, 5, FAST)
    for k in ("starts", "goals", "paths", "cost", "feasible", "hard"):
        np.testing.assert_array_equal(getattr(again, k), getattr(labels, k))
    other = label_world(jwarp.robot("planar4"), world, 12, 6, FAST)
    assert not np.array_equal(other.starts, labels.starts)


def test_labels_feasible_by_independent_check(world, labels):
    robot = jwarp.robot("planar4")
    assert labels.feasible.any()
    for i in np.nonzero(labels.feasible)[0]:
        assert independent_feasible(robot, world, labels.paths[i].astype(np.float64)), i


def test_easy_hard_consistent_with_straight_line(world, labels):
    o = FAST.plan_options("straight", 1, 0)
    line = PL.Planner("planar4", world, len(labels), o, device="cpu").plan(
        labels.starts.astype(np.float64), labels.goals.astype(np.float64))
    np.testing.assert_array_equal(labels.hard, ~line.feasible)
    easy = ~labels.hard
    assert labels.feasible[easy].all() and np.all(labels.n_starts[easy] == 0)
    assert np.all(labels.n_starts[labels.hard] == 6)
    assert np.all(labels.n_feasible_starts[labels.hard & ~labels.feasible] == 0)


def test_converged_labels_shorter(world, labels):
    from dataclasses import replace

    early = label_world(jwarp.robot("planar4"), world, 12, 5, replace(FAST, converge=False))
    both = labels.feasible & early.feasible
    assert both.any()
    # per task another start may win (the lowest U_path), so compare the hard labels' mean
    h = both & labels.hard
    assert h.any()
    assert labels.length_cost[h].mean() < early.length_cost[h].mean()


def test_world_for_table_3_2():
    w = world_for(jwarp.robot("planar4"), 3)
    assert w.shape == (64, 64)
    side = (np.asarray(w.limits)[:, 1] - np.asarray(w.limits)[:, 0] + w.voxel_size)
    np.testing.assert_allclose(side, [1.0, 1.0], rtol=1e-9)
    assert w.meta["feasible_fraction"] >= 0.2 and w.meta["requested_seed"] == 3
    w2 = world_for(jwarp.robot("planar4"), 3)
    np.testing.assert_array_equal(w.occupancy, w2.occupancy)


def test_early_stopped_starts_and_the_statistics_subset(world, labels):
    """stats_tasks: the first hard tasks run every start (``stats``), the others stop
    their starts once ``refine`` are feasible: their non-feasible starts end before the
    iteration budget, and the labels stay feasible by the independent check."""
    from dataclasses import replace

    robot = jwarp.robot("planar4")
    h = np.nonzero(labels.hard)[0]
    assert len(h) >= 3
    np.testing.assert_array_equal(labels.stats, labels.hard)  # FAST: every hard task (< 32)
    part = label_world(jwarp.robot("planar4"), world, 12, 5, replace(FAST, stats_tasks=1, refine=1))
    assert part.stats.sum() == 1 and part.stats[h[0]] and not part.stats[h[1:]].any()
    assert np.all(part.n_starts[h[1:]] == 0) and part.n_starts[h[0]] == 6
    np.testing.assert_array_equal(part.hard, labels.hard)
    assert part.feasible[h].sum() >= labels.feasible[h].sum() - 1
    for i in np.nonzero(part.feasible)[0]:
        assert independent_feasible(robot, world, part.paths[i].astype(np.float64)), i
    assert np.isfinite(part.single_start_rate) or not part.feasible[h[0]]
    # the planner option behind it: a problem's starts stop once enough are feasible
    o = replace(FAST.plan_options("random", 6, 3), enough_feasible=1)
    full = PL.Planner("planar4", world, len(h), FAST.plan_options("random", 6, 3),
                      device="cpu").plan(labels.starts[h].astype(np.float64),
                                         labels.goals[h].astype(np.float64))
    stop = PL.Planner("planar4", world, len(h), o, device="cpu").plan(
        labels.starts[h].astype(np.float64), labels.goals[h].astype(np.float64))
    np.testing.assert_array_equal(stop.feasible, full.feasible)
    solved = stop.feasible
    assert solved.any()
    # the unsolved starts of a solved problem stopped at its first feasible iteration
    for b in np.nonzero(solved)[0]:
        first = stop.all_iterations[b][stop.all_feasible[b]].min()
        assert np.all(stop.all_iterations[b][~stop.all_feasible[b]] <= first)
    assert stop.n_feasible.sum() <= full.n_feasible.sum()
    with pytest.raises(ValueError, match="enough_feasible"):
        replace(o, enough_feasible=0).validate()


@pytest.mark.parametrize("field,value,exc", [
    ("stats_tasks", -1, ValueError), ("stats_tasks", 1.0, ValueError),
    ("n_waypoints", 2, ValueError), ("max_starts", 0, ValueError), ("iterations", 1.5, ValueError),
    ("step", 0.0, ValueError), ("max_step", -1.0, ValueError), ("margin", float("nan"), ValueError),
    ("converge_tol", 0.0, ValueError), ("converge", 1, TypeError), ("dtype", "int8", ValueError),
    ("device", 3, TypeError), ("n_substeps", 0, ValueError), ("length_weight", -1.0, ValueError)])
def test_option_errors_name_the_field(field, value, exc):
    with pytest.raises(exc, match=field):
        PlanDataOptions(**{field: value}).validate()


def test_argument_errors(world):
    with pytest.raises(ValueError, match="n_tasks"):
        label_world(jwarp.robot("planar4"), world, 0, 0, FAST)
    with pytest.raises(ValueError, match="seed"):
        label_world(jwarp.robot("planar4"), world, 2, -1, FAST)
    with pytest.raises(TypeError, match="options"):
        label_world(jwarp.robot("planar4"), world, 2, 0, {"max_starts": 2})
    with pytest.raises(ValueError, match="world_seed"):
        world_for(jwarp.robot("planar4"), -1)


def test_world_for_reach_grid_and_extent_errors():
    w = world_for(jwarp.robot("planar4"), 3, extent="reach", frequency=1.0)
    assert max(w.shape) == 64 and w.meta["frequency"] == 1.0
    side = np.asarray(w.limits)[:, 1] - np.asarray(w.limits)[:, 0]
    assert side.max() > 1.5  # planar4 reaches 1 m: the fitted grid is about 2 m wide
    with pytest.raises(ValueError, match="extent"):
        world_for(jwarp.robot("planar4"), 3, extent="table")
    with pytest.raises(ValueError, match="extent"):
        world_for(jwarp.robot("planar4"), 3, extent=-1.0)
