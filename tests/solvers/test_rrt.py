"""RRT-Connect in joint space (jwarp.solvers.planning.rrt): the planner's fallback. Paths whose every
edge passes the planner's path_feasible, the checks used through jwarp.solvers.planning, the
budgets (samples, time), resampling to waypoints and the options' validation."""

import time

import numpy as np
import pytest
from worlds import block_world_2d

import jwarp
from jwarp.core.limits import within_limits
from jwarp.solvers import planning as PL
from jwarp.solvers.planning import rrt as R
from jwarp.world import path_feasibility

S4 = np.array([1.2, 0.0, 0.0, 0.0])
G4 = np.array([-1.2, 0.0, 0.0, 0.0])


@pytest.fixture(scope="module")
def world():
    return block_world_2d()


def edges_feasible(robot, world, path):
    """Every edge (E, 2, n) of ``path`` on its own by the planner's path_feasible (the
    continuous check on the rigid model; substeps sized to half a voxel otherwise)."""
    edges = np.stack([path[:-1], path[1:]], axis=1)
    n_sub = path_feasibility.substeps_for_voxel(robot, edges, world.resolution, safety=2.0, max_substeps=256)
    return path_feasibility.path_feasible(jwarp.robot(robot), world, edges, n_sub)


def test_rrt_connect_finds_a_path_every_edge_feasible(world):
    robot = jwarp.robot("planar4")
    # the straight line is blocked
    assert not path_feasibility.path_feasible(robot, world, path_feasibility.initial_paths(S4[None], G4[None], 20)[0], 32)
    res = R.rrt_connect(robot, world, S4, G4, R.RRTOptions(seed=1), device="cpu")
    assert res.success and res.stop_reason == "connected"
    p = res.path
    np.testing.assert_array_equal(p[0], S4)
    np.testing.assert_array_equal(p[-1], G4)
    assert len(p) >= 3 and res.n_samples > 0 and res.n_nodes > 2
    assert within_limits(robot, p).all()
    ok = edges_feasible(robot, world, p)
    assert ok.shape == (len(p) - 1,) and ok.all()
    # shortcutting kept it short: far fewer nodes than the raw tree path
    assert len(p) <= res.raw_nodes
    # the same seed, the same path
    again = R.rrt_connect(robot, world, S4, G4, R.RRTOptions(seed=1), device="cpu")
    np.testing.assert_array_equal(again.path, p)


def test_rrt_uses_the_planners_checks(world, monkeypatch):
    """The trees check states and edges through the shared checks of
    jwarp.world.path_feasibility (the planner's, re-exported there), so a replaced check is the
    one the fallback uses."""
    from jwarp.world import path_feasibility as FZ
    calls = {"collision_free": 0, "path_feasible": 0}
    for name in calls:
        orig = getattr(FZ, name)

        def wrapped(*a, _orig=orig, _name=name, **k):
            calls[_name] += 1
            return _orig(*a, **k)
        monkeypatch.setattr(FZ, name, wrapped)
    res = R.rrt_connect(jwarp.robot("planar4"), world, S4, G4, R.RRTOptions(seed=0), device="cpu")
    assert res.success
    assert calls["collision_free"] > 0 and calls["path_feasible"] > 0


def test_straight_line_when_free():
    from jwarp.world import world_from_occupancy

    lim = np.array([[-1.0, 1.0], [-1.0, 1.0]])
    empty = world_from_occupancy(np.zeros((16, 16), bool), lim, 2.0 / 15)
    res = R.rrt_connect(jwarp.robot("planar4"), empty, S4, G4, device="cpu")
    assert res.success and res.n_samples == 0
    np.testing.assert_array_equal(res.path, np.stack([S4, G4]))


def test_budgets_end_the_search(world):
    few = R.rrt_connect(jwarp.robot("planar4"), world, S4, G4, R.RRTOptions(max_samples=1, batch=1,
                                                                 goal_bias=0.0), device="cpu")
    assert not few.success and few.path is None and few.stop_reason == "max_samples"
    assert few.n_samples == 1
    late = R.rrt_connect(jwarp.robot("planar4"), world, S4, G4, device="cpu", deadline=time.perf_counter())
    assert not late.success and late.stop_reason == "time_limit" and late.n_samples == 0


def test_endpoints_are_checked(world):
    with pytest.raises(ValueError, match="^start: outside the joint limits or in collision"):
        R.rrt_connect(jwarp.robot("planar4"), world, np.zeros(4), G4, device="cpu")  # reaches the block
    with pytest.raises(ValueError, match="^goal: expected 4 finite joint values"):
        R.rrt_connect(jwarp.robot("planar4"), world, S4, np.zeros(3), device="cpu")


def test_resample_path_keeps_the_polyline():
    path = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 3.0]])
    out = R.resample_path(path, 7)
    assert out.shape == (7, 2)
    # every node is a waypoint, the others on the segments in proportion to their lengths
    for q in path:
        assert np.any(np.all(out == q, axis=1))
    np.testing.assert_array_equal(out[0], path[0])
    np.testing.assert_array_equal(out[-1], path[-1])
    on_first = np.isclose(out[:, 1], 0.0)
    on_second = np.isclose(out[:, 0], 1.0)
    assert np.all(on_first | on_second)
    # segments of lengths 1 and 3 share the 4 extra waypoints 1 : 3 (the corner on both)
    assert on_first.sum() == 3 and on_second.sum() == 5
    assert R.path_length(out) == pytest.approx(R.path_length(path))
    # more nodes than waypoints: spread evenly along the length
    many = np.stack([np.linspace(0, 1, 30), np.zeros(30)], axis=1)
    out = R.resample_path(many, 5)
    np.testing.assert_allclose(out[:, 0], np.linspace(0, 1, 5))


@pytest.mark.parametrize("field, value, match", [
    ("step", 0.0, "^rrt.step"), ("step", float("nan"), "^rrt.step"),
    ("max_samples", 0, "^rrt.max_samples"), ("batch", 1.5, "^rrt.batch"),
    ("shortcut_iterations", -1, "^rrt.shortcut_iterations"),
    ("goal_bias", 1.5, "^rrt.goal_bias"), ("time_limit", 0.0, "^rrt.time_limit"),
    ("time_limit", float("inf"), "^rrt.time_limit"), ("seed", -1, "^rrt.seed"),
    ("n_substeps", 0, "^rrt.n_substeps"), ("n_connect", 0, "^rrt.n_connect"),
])
def test_options_are_validated(field, value, match):
    with pytest.raises(ValueError, match=match):
        R.RRTOptions(**{field: value}).validate()
    with pytest.raises(ValueError, match=match):
        PL.PlanOptions(rrt=R.RRTOptions(**{field: value})).validate()
    with pytest.raises(TypeError, match="^rrt: expected a jwarp.solvers.planning.rrt.RRTOptions"):
        PL.PlanOptions(rrt={"step": 0.1}).validate()


def test_endpoint_margin(world):
    """A start closer to the block than the path margin: accepted with endpoint_margin,
    whose clearance holds on the edges at start and goal only (PlanOptions.endpoint_margin)."""
    robot = jwarp.robot("planar4")
    near = np.array([0.128, 0.459, 0.0, 0.0])  # about 28 mm from the block
    with pytest.raises(ValueError, match=r"^start: .* in collision \(margin 0.05 m\)"):
        R.rrt_connect(robot, world, near, G4, margin=0.05, device="cpu")
    res = R.rrt_connect(robot, world, near, G4, margin=0.05, endpoint_margin=0.0,
                        device="cpu")
    assert res.success
    p = res.path
    edges = np.stack([p[:-1], p[1:]], axis=1)
    at_margin = path_feasibility.path_feasible(robot, world, edges, 1, margin=0.05)
    assert not at_margin[0] and at_margin[1:-1].all()  # only the first edge needs it
    assert path_feasibility.path_feasible(robot, world, edges[[0, -1]], 1, margin=0.05,
                            endpoint_margin=0.0).all()
    # the planner's fallback passes it on
    for fb, ok in ((None, False), ("rrt", True)):
        opts = PL.PlanOptions(margin=0.05, endpoint_margin=0.0, iterations=3, n_starts=2,
                              fallback=fb)
        out = PL.Planner(robot, world, 1, opts, device="cpu").plan(near, G4)
        assert out.feasible[0] == ok
        assert list(out.stage) == (["fallback"] if ok else ["none"])
