"""Planner (jwarp/solvers/planning/planner.py): U_path gradient, substep detection, planning, errors."""

import numpy as np
import pytest
from devices import requires_cpu

import jwarp
from jwarp.core.limits import within_limits
from jwarp.solvers import planning as PL
from jwarp.world import collision, path_feasibility, world_from_occupancy

N_CELLS = 64
LIM2 = np.array([[-1.0, 1.0], [-1.0, 1.0]])
H2 = 2.0 / (N_CELLS - 1)


def grid2():
    xs = LIM2[0, 0] + H2 * np.arange(N_CELLS)
    return np.meshgrid(xs, xs, indexing="ij")


@pytest.fixture(scope="module")
def block_world():
    """planar4's workspace with a block in front of the base at x in (0.5, 0.75)."""
    X, Y = grid2()
    return world_from_occupancy((X > 0.5) & (X < 0.75) & (np.abs(Y) < 0.12), LIM2, H2)


@pytest.fixture(scope="module")
def wall_world():
    """A one-voxel wall at x = 0 for sphere2d, open above y = 0.6."""
    X, Y = grid2()
    return world_from_occupancy((np.abs(X) < 0.5 * H2) & (Y < 0.6), LIM2, H2)


def test_upath_gradient_matches_central_fd(device, block_world):
    robot = jwarp.robot("planar4")
    rng = np.random.default_rng(0)
    s, g = np.array([1.2, 0.3, 0.0, 0.0]), np.array([-1.2, -0.2, 0.1, 0.0])
    Q = path_feasibility.initial_paths(s[None], g[None], 6, "straight")
    Q = np.repeat(Q, 2, 0)
    Q[:, 1:-1] += rng.normal(scale=0.3, size=Q[:, 1:-1].shape)
    obj = PL.PathObjective(robot, block_world, 2, 6, 3, weights=PL.PathWeights(1.0, 0.7, 0.05),
                           eps=0.04, device=device, dtype=np.float64)
    u, grad = obj.value_and_grad(Q)
    coll0, length0 = obj.collision.numpy().copy(), obj.length.numpy().copy()
    assert np.all(coll0 > 0)  # the straight-ish paths cross the block
    h = 1e-7
    fd = np.zeros_like(Q)
    for t in range(1, 5):
        for j in range(4):
            Qp, Qm = Q.copy(), Q.copy()
            Qp[:, t, j] += h
            Qm[:, t, j] -= h
            fd[:, t, j] = (obj.value_and_grad(Qp)[0] - obj.value_and_grad(Qm)[0]) / (2 * h)
    np.testing.assert_allclose(grad, fd, atol=1e-5 * np.abs(fd).max(), rtol=1e-4)
    # U_path = collision (independent call on the substeps) + lam_l * length
    qs = path_feasibility.substeps(Q, 3, device=device).reshape(-1, 4)
    c, _ = collision.collision_cost(robot, qs, block_world, w_world=1.0, w_self=0.7, eps=0.04,
                                    grad=False, device=device, dtype=np.float64)
    np.testing.assert_allclose(coll0, c.reshape(2, -1).sum(1), rtol=1e-10)
    np.testing.assert_allclose(u, c.reshape(2, -1).sum(1) + 0.05 * length0, rtol=1e-10)


def test_substeps_catch_a_thin_wall_that_waypoints_miss(device, wall_world):
    robot = jwarp.robot("sphere2d")
    path = np.array([[-0.5, 0.0], [0.5, 0.0]])
    assert collision.is_collision_free(robot, path, wall_world, device=device).all()  # both free
    # the check is continuous: it sees the wall between the waypoints whatever n_substeps
    assert not path_feasibility.path_feasible(robot, wall_world, path, 1, device=device)
    n_sub = path_feasibility.substeps_for_voxel(robot, path, wall_world.voxel_size, device=device)
    assert n_sub >= 31  # 1 m of motion / 0.032 m voxels
    assert not path_feasibility.path_feasible(robot, wall_world, path, n_sub, device=device)
    # ... and says where: the wall at x = 0 is half way
    from jwarp.world.motion import check_paths
    res = check_paths(robot, wall_world, path, device=device)
    assert res.code[0] == 1 and 0.3 < res.where[0] < 0.7 and "grid" in res.reason(0)
    # the planner's own check sees it too: the straight line is never reported feasible
    res = PL.plan(robot, wall_world, path[0], path[1], start_kind="straight", iterations=0,
                  n_waypoints=2, device=device)
    assert not res.feasible[0] and res.collision_cost[0] > 0


def test_sphere2d_plans_through_the_opening(device):
    X, Y = grid2()
    world = world_from_occupancy((np.abs(X) < 1.5 * H2) & (Y < 0.3), LIM2, H2)
    robot = jwarp.robot("sphere2d")
    s, g = np.array([-0.5, 0.0]), np.array([0.5, 0.0])
    res = PL.plan(robot, world, s, g, start_kind="mixed", n_starts=8, iterations=200,
                  step=0.05, n_waypoints=10, seed=1, device=device)
    assert res.feasible[0] and not res.all_feasible[0, 0]  # the straight start failed
    p = res.path[0]
    np.testing.assert_array_equal(p[0], s)
    np.testing.assert_array_equal(p[-1], g)
    assert p[:, 1].max() > 0.3  # it went over the top of the wall
    assert path_feasibility.path_feasible(robot, world, p, 64, device=device)  # independent fine check


def test_planar4_plans_around_a_known_obstacle(device, block_world):
    robot = jwarp.robot("planar4")
    s, g = np.array([1.2, 0.0, 0.0, 0.0]), np.array([-1.2, 0.0, 0.0, 0.0])
    straight = path_feasibility.initial_paths(s[None], g[None], 20, "straight")[0]
    assert not path_feasibility.path_feasible(robot, block_world, straight, 16, device=device)
    res = PL.plan(robot, block_world, s, g, start_kind="mixed", n_starts=16, n_substeps=8,
                  iterations=300, step=0.05, seed=0, device=device)
    assert res.feasible[0] and res.n_feasible[0] >= 1
    p = res.path[0]
    assert p.shape == (20, 4)
    np.testing.assert_allclose(p[[0, -1]], [s, g], atol=1e-6)
    assert within_limits(robot, p).all()
    # checked at substeps sized to the final path (sphere motion <= voxel / 2), not only at
    # the 8 substeps the optimisation used
    n_chk = path_feasibility.substeps_for_voxel(robot, p, block_world.voxel_size, safety=path_feasibility.SWEEP_SAFETY,
                                  device=device)
    assert n_chk > 8 and path_feasibility.path_feasible(robot, block_world, p, n_chk, device=device)
    assert res.length_cost[0] > 1.0 and res.collision_cost[0] >= 0
    assert 0 < res.iterations[0] <= 300 and res.wall_time > 0
    d = res.to_dict()
    assert d["feasible"] and len(d["path"]) == 20 and "length" in d["costs"]


def test_substep_voxels_coarsens_the_cost_not_the_check(device, block_world):
    """``substep_voxels``: fewer cost substeps in a grid world (the cost guides, the
    continuous check certifies): the paths still go around the block, verified densely."""
    robot = jwarp.robot("planar4")
    s, g = np.array([1.2, 0.0, 0.0, 0.0]), np.array([-1.2, 0.0, 0.0, 0.0])
    kw = dict(start_kind="mixed", n_starts=16, iterations=300, step=0.05, seed=0,
              fallback=None, device=device)
    fine = PL.plan(robot, block_world, s, g, **kw)
    coarse = PL.plan(robot, block_world, s, g, substep_voxels=3.0, **kw)
    assert coarse.n_substeps < fine.n_substeps
    assert coarse.n_substeps <= np.ceil(fine.n_substeps / 3) + 1
    assert coarse.feasible[0] and fine.feasible[0]
    p = coarse.path[0]
    n_chk = path_feasibility.substeps_for_voxel(robot, p, block_world.voxel_size,
                                                safety=path_feasibility.SWEEP_SAFETY,
                                                device=device)
    assert path_feasibility.path_feasible(robot, block_world, p, n_chk, device=device)
    with pytest.raises(ValueError, match="substep_voxels"):
        PL.plan(robot, block_world, s, g, substep_voxels=0.0, device=device)


def test_batched_problems_and_user_guess(device, block_world):
    robot = jwarp.robot("planar4")
    s = np.array([[2.0, 1.0, 0.0, 0.0], [2.0, 0.0, 0.5, 0.0]])
    g = np.array([[2.0, -1.0, 0.0, 0.0], [2.5, 0.3, 0.0, 0.0]])
    guess = path_feasibility.initial_paths(s, g, 8, "straight")[:, None]  # (B, 1, W, n)
    res = PL.plan(robot, block_world, s, g, seeds=guess, iterations=50, device=device)
    assert res.path.shape == (2, 8, 4) and res.feasible.shape == (2,)
    assert res.feasible.all() and np.all(res.iterations == 0)  # both lines are free already
    np.testing.assert_allclose(res.path, guess[:, 0], atol=1e-6)
    np.testing.assert_allclose(res.length_cost, 1.0, rtol=1e-5)


def test_bad_inputs_give_clear_errors(device, block_world, wall_world):
    """Some are found by the endpoint checks' collision kernels: on the device."""
    robot = jwarp.robot("planar4")
    ok = np.array([1.2, 0.0, 0.0, 0.0])
    inside = np.array([0.0, 0.0, 0.0, 0.0])  # arm along +x through the block
    with pytest.raises(ValueError, match="start.*collision"):
        PL.plan(robot, block_world, inside, ok, device=device)
    with pytest.raises(ValueError, match="goal.*limits"):
        PL.plan(robot, block_world, ok, np.array([-1.2, 0.0, 0.0, 3.1]), device=device)
    with pytest.raises(ValueError, match="start: expected shape"):
        PL.plan(robot, block_world, ok[:3], ok, device=device)
    with pytest.raises(ValueError, match="goal: contains NaN"):
        PL.plan(robot, block_world, ok, np.full(4, np.nan), device=device)
    with pytest.raises(ValueError, match="world"):
        PL.plan("arm7", block_world, np.zeros(7), np.zeros(7), device=device)
    with pytest.raises(ValueError, match="seeds"):
        PL.plan(robot, block_world, ok, -ok, seeds=np.zeros((5, 3)), device=device)
    with pytest.raises(ValueError, match="start_kind"):
        PL.plan(robot, block_world, ok, -ok, start_kind="zigzag", device=device)
    with pytest.raises(ValueError, match="eps"):
        PL.plan(robot, block_world, ok, -ok, eps=0.01, margin=0.02, device=device)
    with pytest.raises(ValueError, match="iterations"):
        PL.plan(robot, block_world, ok, -ok, iterations=-1, device=device)
    with pytest.raises(ValueError, match="start, goal"):
        PL.plan(robot, block_world, np.stack([ok, ok]), np.stack([-ok, -ok, -ok]), device=device)


def test_torch_upath_matches_numpy_gradient(device, block_world):
    torch = pytest.importorskip("torch")
    from jwarp.learn.torch_costs import u_path

    robot = jwarp.robot("planar4")
    rng = np.random.default_rng(3)
    s, g = np.array([1.2, 0.3, 0.0, 0.0]), np.array([-1.2, -0.2, 0.1, 0.0])
    Q = np.repeat(path_feasibility.initial_paths(s[None], g[None], 6, "straight"), 3, 0)
    Q[:, 1:-1] += rng.normal(scale=0.3, size=Q[:, 1:-1].shape)
    w = PL.PathWeights(1.0, 0.5, 0.1)
    obj = PL.PathObjective(robot, block_world, 3, 6, 3, weights=w, eps=0.04, device=device,
                           dtype=np.float64)
    u_ref, g_ref = obj.value_and_grad(Q)
    # u_path runs on the paths' device
    qt = torch.tensor(Q, dtype=torch.float64, requires_grad=True, device=device)
    u = u_path(qt, robot, block_world, 3, weights=w, eps=0.04)
    np.testing.assert_allclose(u.detach().cpu().numpy(), u_ref, rtol=1e-12)
    scale = torch.tensor([1.0, -2.0, 0.5], dtype=torch.float64, device=device)
    (u * scale).sum().backward()
    np.testing.assert_allclose(qt.grad.cpu().numpy(), g_ref * scale.cpu().numpy()[:, None, None],
                               rtol=1e-12)
    with pytest.raises(ValueError, match="paths"):
        u_path(torch.zeros(2, 5, device=device), robot, block_world, 3)


@requires_cpu
def test_cli_plan_and_ik_json(block_world, tmp_path, capsys):
    """The CLI on its default device, the CPU."""
    import json

    from jwarp.cli import main
    from jwarp.world.io import save_world

    wfile = tmp_path / "block.npz"
    save_world(block_world, wfile)
    rrd = tmp_path / "plan.rrd"
    rc = main(["plan", "--robot", "planar4", "--world", str(wfile), "--start", "1.2,0,0,0",
               "--goal", "-1.2,0,0,0", "--starts", "16", "--substeps", "8", "--step", "0.05",
               "--iterations", "300", "--json", "--rerun", str(rrd)])
    out = json.loads(capsys.readouterr().out)
    assert rc == 0 and out["feasible"] and len(out["path"]) == 20
    assert set(out["costs"]) == {"total", "length", "collision"}
    assert out["iterations"] > 0 and out["wall_time_s"] > 0
    assert rrd.stat().st_size > 1000
    assert path_feasibility.path_feasible(jwarp.robot("planar4"), block_world, np.array(out["path"]), 32)
    from scipy.spatial.transform import Rotation

    F = jwarp.fk("arm7", np.array([0.3, 0.6, 0.0, -1.0, 0.2, 0.5, 0.0]), device="cpu")[8]
    tgt = np.concatenate([F[:3, 3], Rotation.from_matrix(F[:3, :3]).as_rotvec()])
    rc = main(["ik", "--robot", "arm7", "--frame", "tcp", "--target",
               ",".join(f"{v:.12f}" for v in tgt), "--json"])
    out = json.loads(capsys.readouterr().out)
    assert rc == 0 and out["feasible"] and out["pos_err_m"] < 1e-4 and len(out["q"]) == 7
    assert main(["plan", "--robot", "planar4", "--world", str(wfile), "--start", "0,0,0,0",
                 "--goal", "1,0,0,0"]) == 2
    assert "start: configuration is in collision" in capsys.readouterr().err
    assert main(["ik", "--robot", "arm7", "--frame", "nope", "--target", "0,0,1"]) == 2
    assert "unknown frame" in capsys.readouterr().err


@pytest.mark.parametrize("name", ["planar4", "arm7", "justin19"])
def test_substeps_per_path_equals_a_numpy_sweep(device, name):
    """The per-path substep counts (longest sphere arc of a segment, computed on the
    device) equal a numpy sweep over the same fine interpolation (sphere_centres)."""
    from jwarp.core.limits import sample_within_limits

    robot = jwarp.robot(name)
    rng = np.random.default_rng(4)
    Q = sample_within_limits(robot, 12 * 6, rng).reshape(12, 6, -1) * 0.5
    fine, P, W, n = 16, 12, 6, robot.n_dof
    u = np.arange(fine)[:, None] / fine
    q = (Q[:, :-1, None] + u * np.diff(Q, axis=1)[:, :, None]).reshape(P, -1, n)
    q = np.concatenate([q, Q[:, -1:]], axis=1)
    x = path_feasibility.sphere_centres(robot, q.reshape(-1, n), device=device).reshape(P, q.shape[1], -1, 3)
    arc = np.linalg.norm(np.diff(x, axis=1), axis=-1).reshape(P, W - 1, fine, -1).sum(2)
    want = np.clip(np.ceil(arc.max(axis=(1, 2)) * 2.0 / 0.01), 1, 512).astype(np.int64)
    got = path_feasibility.substeps_per_path(robot, Q, 0.01, safety=2.0, max_substeps=512, device=device)
    np.testing.assert_array_equal(got, want)
    assert len(np.unique(got)) > 3   # a real spread of counts, not one clamped value


def _same_plan(a, b):
    for name in ("path", "feasible", "iterations", "length_cost", "collision_cost"):
        np.testing.assert_array_equal(np.asarray(getattr(a, name)), np.asarray(getattr(b, name)),
                                      err_msg=name)


def test_plan_takes_options_and_overrides(block_world):
    """plan(options=..., **overrides): the options are dataclasses.replace(options,
    **overrides); an override wins over the options' field; the results equal the keyword
    call bit for bit; the options object is not modified; ``initial`` is a kind or seeds."""
    robot = jwarp.robot("planar4")
    s, g = np.array([1.2, 0.0, 0.0, 0.0]), np.array([-1.2, 0.0, 0.0, 0.0])
    o = dict(n_starts=6, n_substeps=8, iterations=120, step=0.05, seed=2, fallback=None,
             stop_when_solved=False)
    kw = PL.plan(robot, block_world, s, g, start_kind="random", **o)
    opts = PL.PlanOptions(start_kind="straight", n_starts=6, n_substeps=8, iterations=120,
                          step=0.05, seed=9, fallback=None)
    a = PL.plan(robot, block_world, s, g, options=opts, start_kind="random", seed=2,
                stop_when_solved=False)
    b = PL.plan(robot, block_world, s, g, options=PL.PlanOptions(start_kind="random", **o))
    _same_plan(a, kw)
    _same_plan(b, kw)
    assert (opts.start_kind, opts.seed, opts.stop_when_solved) == ("straight", 9, True)
    # user guesses (not a kind) are seeds, with or without options
    guess = path_feasibility.initial_paths(s[None], g[None], 12, "straight")[0]
    kw = PL.plan(robot, block_world, s, g, seeds=guess, iterations=30, fallback=None,
                 n_substeps=8, step=0.05, seed=9)
    a = PL.plan(robot, block_world, s, g, options=opts, seeds=guess, iterations=30)
    _same_plan(a, kw)
    assert a.path.shape == (1, 12, 4)


def test_plan_rejects_unknown_options_naming_them(block_world):
    s, g = np.array([1.2, 0.0, 0.0, 0.0]), np.array([-1.2, 0.0, 0.0, 0.0])
    with pytest.raises(TypeError, match=r"plan\(\) got an unexpected option 'max_iterations'; "
                                        r"options are the fields of PlanOptions: .*\bn_starts\b"):
        PL.plan("planar4", block_world, s, g, max_iterations=10)
    with pytest.raises(TypeError, match="^options: expected PlanOptions or None"):
        PL.plan("planar4", block_world, s, g, options={"n_starts": 2})
    with pytest.raises(ValueError, match="^n_starts"):  # values: validated as before
        PL.plan("planar4", block_world, s, g, options=PL.PlanOptions(), n_starts=0)


def test_n_starts_default_follows_the_device():
    """PlanOptions.n_starts None: 8 starts on the CPU, 32 on a CUDA device (where they cost
    little); a given count wins; a count below 1 names the field."""
    from jwarp.solvers.planning.options import N_STARTS, PlanOptions, n_starts_for

    assert PlanOptions().n_starts is None
    assert n_starts_for(PlanOptions(), "cpu") == N_STARTS["cpu"] == 8
    assert n_starts_for(PlanOptions(), "cuda:0") == N_STARTS["cuda"] == 32
    assert n_starts_for(PlanOptions(n_starts=3), "cuda:0") == 3
    with pytest.raises(ValueError, match="^n_starts"):
        PlanOptions(n_starts=0).validate()


def test_default_starts_are_planned_on_the_cpu(block_world):
    """A plan with the default options on the CPU optimises N_STARTS["cpu"] starts (the
    straight line collides in this world)."""
    res = PL.plan("planar4", block_world, np.array([1.2, 0.3, 0.0, 0.0]),
                  np.array([-1.2, -0.3, 0.0, 0.0]), device="cpu", straight_first=False)
    assert res.all_paths.shape[1] == 8
