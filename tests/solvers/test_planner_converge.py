"""PlanOptions.converge: feasible paths keep being optimized (staying feasible) until the
length cost settles; the default early stop is unchanged."""

import numpy as np
import pytest

import jwarp
from jwarp.solvers import planning as PL
from jwarp.world import path_feasibility, world_from_occupancy

N = 64
LIM = np.array([[-1.0, 1.0], [-1.0, 1.0]])
H = 2.0 / (N - 1)
START = np.array([1.2, 0.0, 0.0, 0.0])
GOAL = np.array([-1.2, 0.0, 0.0, 0.0])


@pytest.fixture(scope="module")
def block_world():
    xs = LIM[0, 0] + H * np.arange(N)
    X, Y = np.meshgrid(xs, xs, indexing="ij")
    return world_from_occupancy((X > 0.5) & (X < 0.75) & (np.abs(Y) < 0.12), LIM, H)


def independent_feasible(robot, world, path):
    """path_feasible at substeps sized so no sphere moves more than half a voxel."""
    n_sub = path_feasibility.substeps_for_voxel(robot, path, world.voxel_size, safety=2.0, max_substeps=256)
    return bool(path_feasibility.path_feasible(jwarp.robot(robot), world, path, n_sub)[()])


def run(world, converge, **kw):
    robot = jwarp.robot("planar4")
    o = PL.PlanOptions(start_kind="mixed", n_starts=8, iterations=300, step=0.05, seed=0,
                       n_substeps=8, converge=converge, weights=PL.PathWeights(length=0.05), **kw)
    return PL.Planner(robot, world, 1, o, device="cpu").plan(START, GOAL)


def test_converged_paths_are_feasible_and_shorter(block_world):
    robot = jwarp.robot("planar4")
    early = run(block_world, False)
    conv = run(block_world, True)
    assert early.feasible[0] and conv.feasible[0]
    assert independent_feasible(robot, block_world, conv.path[0])
    # every feasible start of the converged run is feasible by the independent check
    for k in np.nonzero(conv.all_feasible[0])[0]:
        assert independent_feasible(robot, block_world, conv.all_paths[0, k])
    assert conv.length_cost[0] < early.length_cost[0]
    # the same starts: each feasible start got shorter (or stayed) by converging
    both = early.all_feasible[0] & conv.all_feasible[0]
    assert both.any()
    lu = lambda p: 0.5 * (np.diff(p, axis=-2) ** 2).sum((-1, -2))
    assert np.all(lu(conv.all_paths[0, both]) <= lu(early.all_paths[0, both]) * (1 + 1e-6))
    # the reported length cost is eq. 3.5 of the returned path (numpy reference)
    p = conv.path[0]
    ref = (p.shape[0] - 1) * lu(p) / (0.5 * ((p[-1] - p[0]) ** 2).sum())
    np.testing.assert_allclose(conv.length_cost[0], ref, rtol=1e-4)


def test_converge_tolerance_stops_earlier(block_world):
    loose = run(block_world, True, converge_tol=0.2)
    tight = run(block_world, True, converge_tol=1e-6)
    f = loose.all_feasible[0] & tight.all_feasible[0]
    assert f.any()
    assert np.all(loose.all_iterations[0, f] <= tight.all_iterations[0, f])


def test_default_unchanged(block_world):
    """Without converge, plan() keeps its early stop: the same paths as before."""
    a = run(block_world, False)
    b = PL.plan("planar4", block_world, START, GOAL, start_kind="mixed", n_starts=8,
                iterations=300, step=0.05, seed=0, n_substeps=8,
                weights=PL.PathWeights(length=0.05))
    np.testing.assert_array_equal(a.path, b.path)
    np.testing.assert_array_equal(a.all_iterations, b.all_iterations)


@pytest.mark.parametrize("field,value,exc", [("converge_tol", 0.0, ValueError),
                                             ("converge_tol", float("nan"), ValueError),
                                             ("converge", "yes", TypeError)])
def test_option_errors_name_the_field(field, value, exc):
    with pytest.raises(exc, match=field):
        PL.PlanOptions(**{field: value}).validate()


# ---------------------------------------------------------------- Cartesian length cost
def cartesian_reference(robot, Q):
    """Eq. 3.7 summed over every collision sphere, in numpy (host FK)."""
    P, W, n = Q.shape
    x = path_feasibility.sphere_centres(robot, Q.reshape(-1, n)).reshape(P, W, -1, 3)
    step = 0.5 * (np.diff(x, axis=1) ** 2).sum((-1, -2, -3))
    direct = 0.5 * ((x[:, -1] - x[:, 0]) ** 2).sum((-1, -2))
    return (W - 1) * step / direct


@pytest.mark.parametrize("name", ["planar4", "arm7", "justin19"])
def test_cartesian_length_value_and_gradient(name):
    robot = jwarp.robot(name)
    rng = np.random.default_rng(1)
    lim = robot.joint_limits
    s = rng.uniform(lim[:, 0], lim[:, 1]) * 0.5
    g = rng.uniform(lim[:, 0], lim[:, 1]) * 0.5
    Q = np.repeat(path_feasibility.initial_paths(s[None], g[None], 5, "straight"), 2, 0)
    Q[:, 1:-1] += rng.normal(scale=0.1, size=Q[:, 1:-1].shape)
    d = robot.workspace_dim
    occ = np.zeros((8,) * d, bool)  # an empty world: only the length terms
    from jwarp.world import world_from_occupancy
    world = world_from_occupancy(occ, np.array([[-3.0, 3.0]] * d), 6.0 / 7)
    w = PL.PathWeights(world=0.0, self=0.0, length=0.0, cartesian=0.7)
    obj = PL.PathObjective(robot, world, 2, 5, 2, weights=w, device="cpu", dtype=np.float64)
    u, grad = obj.value_and_grad(Q)
    ref = cartesian_reference(robot, Q)
    np.testing.assert_allclose(obj.cartesian.numpy(), ref, rtol=1e-10)
    np.testing.assert_allclose(u, 0.7 * ref, rtol=1e-10)
    h = 1e-6
    fd = np.zeros_like(Q)
    for t in range(1, 4):
        for j in range(robot.n_dof):
            Qp, Qm = Q.copy(), Q.copy()
            Qp[:, t, j] += h
            Qm[:, t, j] -= h
            fd[:, t, j] = (obj.value_and_grad(Qp)[0] - obj.value_and_grad(Qm)[0]) / (2 * h)
    np.testing.assert_allclose(grad, fd, atol=1e-6 * np.abs(fd).max(), rtol=1e-5)
    assert np.all(grad[:, [0, -1]] == 0)


def test_cartesian_weight_default_zero(block_world):
    assert PL.PathWeights().cartesian == 0.0
    with pytest.raises(ValueError, match="weights.cartesian"):
        PL.PathWeights(cartesian=-1.0).validate()


def test_cartesian_length_shortens_workspace_motion(block_world):
    """Planning with the Cartesian term gives paths whose spheres move less."""
    robot = jwarp.robot("planar4")
    plain = run(block_world, True)
    cart = PL.Planner(robot, block_world, 1, PL.PlanOptions(
        start_kind="mixed", n_starts=8, iterations=300, step=0.05, seed=0, n_substeps=8,
        converge=True, weights=PL.PathWeights(length=0.05, cartesian=0.05)),
        device="cpu").plan(START, GOAL)
    assert cart.feasible[0]
    assert independent_feasible(robot, block_world, cart.path[0])
    assert cartesian_reference(robot, cart.path) < cartesian_reference(robot, plain.path)
