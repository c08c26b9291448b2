"""The device-resident IK solver (jwarp/solvers/ik/solver.py IKSolver, jwarp/kernels/ik_step.py):
the damped least-squares kernel against numpy, the solver against the host loop it
replaced (benchmarks/bench_ik.py legacy_ik), the device's feasibility check and best-seed
choice against the host's, reuse across calls, caller seeds and option checks. CPU always;
CUDA where present."""

import importlib.util
from pathlib import Path

import numpy as np
import pytest
import warp as wp
from devices import requires_cpu, requires_cuda

import jwarp
from jwarp.core.limits import project_numpy, sample_within_limits, within_limits
from jwarp.kernels import ik_step
from jwarp.solvers import ik as IK
from jwarp.world import collision, shelf_world

ROOT = Path(__file__).resolve().parents[2]


def _bench():
    spec = importlib.util.spec_from_file_location("bench_ik", ROOT / "benchmarks" / "bench_ik.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _free_targets(robot, frame, n, seed, world=None, margin=0.0, device="cpu"):
    """n collision-free configurations and their frame poses (host checks on ``device``:
    the CUDA test machine has no CPU compiler)."""
    rng = np.random.default_rng(seed)
    qt = sample_within_limits(robot, 8 * n, rng)
    qt = qt[collision.is_collision_free(jwarp.robot(robot), qt, world, margin, device=device,
                                        dtype=np.float64)][:n]
    return qt, jwarp.fk(robot, qt, device=device, dtype=np.float64)[:, robot.frame_index(frame)]


# ------------------------------------------------------------------ the DLS kernel
def _dls_numpy(J, err, g, on, mu2, alpha, max_step, rows):
    J = J.astype(np.float64)[:, rows]
    e = err.astype(np.float64)[:, rows]
    g = g.astype(np.float64)
    A = J @ np.swapaxes(J, 1, 2) + mu2 * np.eye(len(rows))
    d = np.einsum("bmn,bm->bn", J, np.linalg.solve(A, e[..., None])[..., 0])
    ns = g - np.einsum("bmn,bm->bn", J, np.linalg.solve(A, J @ g[..., None])[..., 0])
    d = np.where(on[:, None] != 0, d - alpha * ns, d)
    return d * np.minimum(1.0, max_step / np.maximum(np.abs(d).max(1, keepdims=True), 1e-300))


@pytest.mark.parametrize("planar", [False, True])
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_dls_kernel_matches_numpy_solve(device, planar, dtype):
    """The in-kernel Cholesky step equals numpy's solve, also for (nearly) singular J:
    rank-deficient, two equal rows, all zero; steps large enough to be scaled and small."""
    rng = np.random.default_rng(3)
    B, n = 48, 9
    J = rng.normal(size=(B, 6, n))
    J[:8, :, 3:] = 0.0                      # rank 3
    J[8:16, 1] = J[8:16, 0] * (1 + 1e-9)    # two (almost) equal rows
    J[16:20] = 0.0                          # no Jacobian at all
    J[20:24] *= 1e-4                        # tiny: the damping dominates
    err = rng.normal(size=(B, 6)) * np.where(np.arange(B) % 2, 1.0, 1e-3)[:, None]
    g = rng.normal(size=(B, n))
    on = rng.integers(0, 2, B).astype(np.int32)
    J, err, g = (a.astype(dtype) for a in (J, err, g))
    scalar = wp.float64 if dtype == np.float64 else wp.float32
    k = ik_step.dls_kernels(scalar, planar, n)
    out = wp.zeros((B, n), dtype=wp.float64, device=device)
    mu2, alpha, max_step = 1e-6, 0.7, 0.5
    wp.launch(k.dls, dim=B, inputs=[wp.array(J, dtype=scalar, device=device),
                                    wp.array(err, dtype=scalar, device=device),
                                    wp.array(g, dtype=scalar, device=device),
                                    wp.array(on, dtype=wp.int32, device=device),
                                    mu2, alpha, max_step], outputs=[out], device=device)
    rows = np.array([0, 1, 5]) if planar else np.arange(6)
    want = _dls_numpy(J, err, g, on, mu2, alpha, max_step, rows)
    got = out.numpy()
    # well-conditioned rows to round-off; (nearly) singular ones to cond(A) * eps
    np.testing.assert_allclose(got[24:], want[24:], rtol=0, atol=1e-12)
    np.testing.assert_allclose(got[:24], want[:24], rtol=0, atol=1e-8)
    assert np.abs(got).max(1).max() <= max_step * (1 + 1e-12)


# ------------------------------------------------------------ the solver vs the host loop
@pytest.mark.parametrize("name,frame,kw", [
    ("arm7", "tcp", {}),
    ("arm7", "tcp", {"stop_when_solved": False}),
    ("justin19", "right_tcp", {}),
    ("justin19", "right_tcp", {"kappa": 1e-4}),
    ("planar4", "tcp", {"check_every": 3}),
])
def test_solver_matches_the_host_loop_float64(name, frame, kw):
    legacy = _bench().legacy_ik
    robot = jwarp.robot(name)
    _, T = _free_targets(robot, frame, 3, seed=1)
    new = IK.ik(robot, frame, T, n_starts=6, seed=2, restart_after=None, freeze_solved=False,
                **kw)
    old = legacy(robot, frame, T, n_starts=6, seed=2, hold_limits=True, **kw)
    np.testing.assert_array_equal(new.all_feasible, old.all_feasible)
    np.testing.assert_array_equal(new.all_iterations, old.all_iterations)
    np.testing.assert_array_equal(new.start_index, old.start_index)
    np.testing.assert_array_equal(new.n_feasible, old.n_feasible)
    np.testing.assert_allclose(new.q, old.q, rtol=0, atol=1e-9)
    f = old.all_feasible
    np.testing.assert_allclose(new.all_q[f], old.all_q[f], rtol=0, atol=1e-9)
    for k in ("pos_err", "rot_err", "cost"):
        np.testing.assert_allclose(getattr(new, k), getattr(old, k), rtol=1e-6, atol=1e-12)
    assert new.feasible.all()


def test_solver_matches_the_host_loop_in_the_shelf():
    legacy = _bench().legacy_ik
    robot = jwarp.robot("justin19")
    world = shelf_world()
    from scipy.spatial.transform import Rotation

    T = IK.pose_matrix([0.6, -0.25, 0.8], Rotation.from_euler("y", 90, degrees=True).as_rotvec())
    kw = dict(world=world, n_starts=16, margin=0.01, seed=0)
    new = IK.ik(robot, "right_tcp", T, restart_after=None, freeze_solved=False, **kw)
    old = legacy(robot, "right_tcp", T, hold_limits=True, **kw)
    assert new.feasible and old.feasible
    np.testing.assert_array_equal(new.all_feasible, old.all_feasible)
    np.testing.assert_array_equal(new.all_iterations, old.all_iterations)
    assert new.start_index == old.start_index
    np.testing.assert_allclose(new.q, old.q, rtol=0, atol=1e-9)


@requires_cpu
@requires_cuda
def test_cuda_solver_matches_the_cpu_solver_float64():
    robot = jwarp.robot("justin19")
    world = shelf_world()
    _, T = _free_targets(robot, "right_tcp", 4, seed=5, world=world, margin=0.01)
    seeds = sample_within_limits(robot, 32, np.random.default_rng(3)).reshape(4, 8, -1)
    opts = IK.IKOptions(n_starts=8, margin=0.01, read_every=1)  # CUDA's default is sparser
    res = [IK.IKSolver(robot, "right_tcp", len(T), opts, world=world, device=d,
                       dtype=np.float64).solve(T, seeds) for d in ("cpu", "cuda:0")]
    np.testing.assert_array_equal(res[0].all_feasible, res[1].all_feasible)
    np.testing.assert_array_equal(res[0].all_iterations, res[1].all_iterations)
    np.testing.assert_array_equal(res[0].start_index, res[1].start_index)
    np.testing.assert_allclose(res[0].q, res[1].q, rtol=0, atol=1e-8)


@requires_cuda
def test_cuda_graphs_replay_the_launches():
    """IKOptions.cuda_graphs: the iterations between counter reads replayed as CUDA graphs
    give the results of launching every kernel (fused cost: no atomics, bit for bit), also
    on a second solve that replays the captured graphs."""
    robot = jwarp.robot("justin19")
    world = shelf_world()
    _, T = _free_targets(robot, "right_tcp", 6, seed=7, world=world, margin=0.01,
                         device="cuda:0")
    seeds = sample_within_limits(robot, 48, np.random.default_rng(4)).reshape(6, 8, -1)
    res = {}
    for graphs in (False, True):
        opts = IK.IKOptions(n_starts=8, margin=0.01, cuda_graphs=graphs)
        solver = IK.IKSolver(robot, "right_tcp", len(T), opts, world=world, device="cuda:0",
                             dtype=np.float64)
        cm = solver.objective.cm  # shared by robot and world: restored below
        cm.wide = False  # the fused cost: the same sums in every run
        try:
            res[graphs] = [solver.solve(T, seeds) for _ in range(2)]
        finally:
            cm.wide = None
    for a, b in zip(res[False], res[True]):
        np.testing.assert_array_equal(a.all_feasible, b.all_feasible)
        np.testing.assert_array_equal(a.all_iterations, b.all_iterations)
        np.testing.assert_allclose(a.q, b.q, rtol=0, atol=1e-12)
    assert res[True][0].feasible.all()
    with pytest.raises(TypeError, match="cuda_graphs"):
        IK.IKOptions(cuda_graphs=1)


# ------------------------------------------------------------ the device's checks
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_device_feasibility_check_matches_the_host_check(device, dtype):
    """Seeds that sit on their targets are checked at iteration 0: feasible exactly where
    the host says within the limits and collision-free with the margin (world and self)."""
    robot = jwarp.robot("justin19")
    world = shelf_world()
    rng = np.random.default_rng(11)
    q = sample_within_limits(robot, 64, rng)
    q = q.astype(dtype).astype(np.float64)  # exactly representable in the solver's dtype
    T = jwarp.fk(robot, q, device=device, dtype=np.float64)[:, robot.frame_index("right_tcp")]
    margin = 0.02
    opts = IK.IKOptions(iterations=0, margin=margin, tol_pos=1e-3, tol_rot=1e-2)
    res = IK.IKSolver(robot, "right_tcp", len(q), opts, world=world, device=device,
                      dtype=dtype).solve(T, q[:, None])
    want = within_limits(robot, q) & collision.is_collision_free(
        robot, q, world, margin, device=device, dtype=np.float64)
    assert 5 < want.sum() < len(q) - 5  # both kinds are there
    np.testing.assert_array_equal(res.feasible, want)
    assert np.all(res.iterations[res.feasible] == 0)


def test_best_seed_selection_on_the_device_matches_numpy(device):
    rng = np.random.default_rng(4)
    P, S, n = 40, 7, 5
    out = np.zeros((P * S, n + ik_step.N_EXTRA))
    out[:, n:n + 3] = rng.integers(0, 4, (P * S, 3)) * 0.25  # ties on purpose
    feas = rng.random(P * S) < 0.2
    feas[:S] = False        # problem 0: nothing feasible
    feas[S:2 * S] = True    # problem 1: everything feasible
    out[:, n + ik_step.COL_FEASIBLE] = feas
    best = wp.zeros((P, 2), dtype=wp.int32, device=device)
    ck = ik_step.check_kernels(wp.float64, False)
    wp.launch(ck.select, dim=P, inputs=[wp.array(out, dtype=wp.float64, device=device), S, n],
              outputs=[best], device=device)
    got = best.numpy()
    errs = out[:, n:n + 3].reshape(P, S, 3)
    np.testing.assert_array_equal(got[:, 0], IK.select_best(feas.reshape(P, S), errs))
    np.testing.assert_array_equal(got[:, 1], feas.reshape(P, S).sum(1))


# ------------------------------------------------------------ reuse, seeds, options
def test_solver_is_reused_without_reallocation(device):
    robot = jwarp.robot("arm7")
    _, T = _free_targets(robot, "tcp", 3, seed=7, device=device)
    solver = IK.IKSolver(robot, "tcp", 3, IK.IKOptions(n_starts=4, seed=1), device=device)
    first = solver.solve(T)
    bufs = (solver.objective, solver.objective.q.ptr, solver.out.ptr, solver.done.ptr)
    again = solver.solve(T[::-1])
    assert (solver.objective, solver.objective.q.ptr, solver.out.ptr, solver.done.ptr) == bufs
    assert first.feasible.all() and again.feasible.all()
    solver.reseed(1)  # the same seeds as the first call: the same answer
    third = solver.solve(T)
    np.testing.assert_array_equal(third.q, first.q)
    np.testing.assert_array_equal(third.all_iterations, first.all_iterations)
    fresh = IK.IKSolver(robot, "tcp", 3, IK.IKOptions(n_starts=4, seed=1), device=device)
    np.testing.assert_array_equal(fresh.solve(T).q, first.q)
    # another seed count reallocates, then works the same way
    res = solver.solve(T, np.zeros((2, robot.n_dof)))
    assert solver.n_seeds == 2 and res.all_q.shape == (3, 2, robot.n_dof)


def test_caller_seeds_are_used(device):
    robot = jwarp.robot("justin19")
    qt, T = _free_targets(robot, "right_tcp", 2, seed=9, device=device)
    solver = IK.IKSolver(robot, "right_tcp", 2, IK.IKOptions(n_starts=3), device=device)
    # a seed that is already a solution: feasible at iteration 0, unchanged
    seeds = sample_within_limits(robot, 6, np.random.default_rng(0)).reshape(2, 3, -1)
    seeds[:, 1] = qt
    res = solver.solve(T, seeds)
    assert res.feasible.all() and np.all(res.iterations == 0)
    np.testing.assert_array_equal(res.start_index, [1, 1])
    np.testing.assert_allclose(res.q, qt, rtol=0, atol=1e-12)
    # both problems were solved at iteration 0: the other seeds never moved (projected only)
    np.testing.assert_allclose(res.all_q[:, [0, 2]], project_numpy(robot, seeds[:, [0, 2]]),
                               rtol=0, atol=1e-12)
    # one seed set for every problem, and one target for every problem
    res = solver.solve(T[0], qt[0][None])
    assert res.q.shape == (2, robot.n_dof) and res.feasible.all()
    assert np.all(res.iterations == 0)


def test_options_are_checked_by_name():
    with pytest.raises(ValueError, match="^n_starts"):
        IK.IKOptions(n_starts=0)
    with pytest.raises(ValueError, match="^iterations"):
        IK.IKOptions(iterations=-1)
    with pytest.raises(ValueError, match="^check_every"):
        IK.IKOptions(check_every=True)
    with pytest.raises(ValueError, match="^tol_pos"):
        IK.IKOptions(tol_pos=0.0)
    with pytest.raises(TypeError, match="^damping"):
        IK.IKOptions(damping="1e-3")
    with pytest.raises(ValueError, match="^margin"):
        IK.IKOptions(margin=-0.01)
    with pytest.raises(ValueError, match="^eps"):
        IK.IKOptions(margin=0.05, eps=0.01)
    with pytest.raises(ValueError, match="^lam"):
        IK.IKOptions(lam=1.5)
    with pytest.raises(TypeError, match="^stop_when_solved"):
        IK.IKOptions(stop_when_solved=1)
    with pytest.raises(TypeError, match="^seed"):
        IK.IKOptions(seed=1.5)
    with pytest.raises(ValueError, match="^weights.world"):
        IK.IKOptions(weights=IK.IKWeights(world=-1.0))
    opts = IK.IKOptions()
    opts.step = -1.0
    with pytest.raises(ValueError, match="^step"):
        opts.validate()
    with pytest.raises(ValueError, match="^n_problems"):
        IK.IKSolver("arm7", "tcp", 0)
    with pytest.raises(TypeError, match="^options"):
        IK.IKSolver("arm7", "tcp", 1, options={"n_starts": 2})
    with pytest.raises(ValueError, match="^kappa"):
        IK.IKSolver("arm7", "tcp", 1, IK.IKOptions(kappa=-1.0), device="cpu")
    solver = IK.IKSolver("arm7", "tcp", 2, IK.IKOptions(n_starts=2), device="cpu")
    with pytest.raises(ValueError, match="^target"):
        solver.solve(np.repeat(np.eye(4)[None], 3, axis=0))
    with pytest.raises(ValueError, match="^seeds"):
        solver.solve(np.eye(4), np.zeros((3, 2, 7)))


def test_ik_reuses_a_cached_solver_with_the_same_answer():
    robot = jwarp.robot("arm7")
    _, T = _free_targets(robot, "tcp", 2, seed=12)
    seeds = sample_within_limits(robot, 8, np.random.default_rng(5)).reshape(2, 4, -1)
    cold = IK.IKSolver(robot, "tcp", 2, IK.IKOptions(n_starts=4, seed=5), device="cpu",
                       dtype=np.float64).solve(T, seeds)  # the seeds and re-seeds of ik()
    for seed in (8, 5):  # the second call reseeds the solver the first one left cached
        warm = IK.ik(robot, "tcp", T, n_starts=4, seed=seed)
    np.testing.assert_array_equal(warm.all_q, cold.all_q)
    np.testing.assert_array_equal(warm.all_iterations, cold.all_iterations)


def test_random_seeds_are_drawn_on_the_device_within_the_limits(device):
    robot = jwarp.robot("justin19")  # box and linear (torso) limits
    far = np.eye(4)
    far[:3, 3] = 10.0  # out of reach: the seeds are the result rows
    solver = IK.IKSolver(robot, "right_tcp", 2, IK.IKOptions(n_starts=200, iterations=0,
                                                             seed=4), device=device)
    q = solver.solve(far).all_q.reshape(-1, robot.n_dof)
    assert within_limits(robot, q).all()
    lo, hi = robot.joint_limits.T
    span = (q.max(0) - q.min(0)) / (hi - lo)
    assert np.all(span > 0.8)  # spread over the box
    assert len(np.unique(q[:, 0])) == len(q)
    solver.reseed(4)
    np.testing.assert_array_equal(solver.solve(far).all_q.reshape(-1, robot.n_dof), q)


def test_freeze_solved_stops_the_other_seeds(device):
    robot = jwarp.robot("arm7")
    _, T = _free_targets(robot, "tcp", 6, seed=13, device=device)
    seeds = sample_within_limits(robot, 6 * 5, np.random.default_rng(2)).reshape(6, 5, -1)
    opts = dict(n_starts=5, stop_when_solved=False, iterations=60)
    full = IK.IKSolver(robot, "tcp", 6, IK.IKOptions(freeze_solved=False, **opts),
                       device=device).solve(T, seeds)
    frozen = IK.IKSolver(robot, "tcp", 6, IK.IKOptions(freeze_solved=True, **opts),
                         device=device).solve(T, seeds)
    assert frozen.feasible.all() and full.feasible.all()
    np.testing.assert_allclose(frozen.pos_err, 0, atol=1e-4)
    # a problem's feasible seeds are those that became feasible at its first success
    first = np.where(full.all_feasible, full.all_iterations, 10**9).min(1)
    for p in range(6):
        f = frozen.all_feasible[p]
        assert np.all(frozen.all_iterations[p][f] == first[p])
        assert np.all(full.all_feasible[p][f])  # the same seeds, the same iterations
    assert frozen.n_feasible.sum() <= full.n_feasible.sum()


def test_elastic_solver_reaches_the_equilibrium_target(device):
    from jwarp.solvers import compensation as C

    robot = jwarp.robot("justin19")
    _, T = _free_targets(robot, "right_tcp", 2, seed=6, device=device)
    res = IK.ik(robot, "right_tcp", T, kappa=C.JUSTIN_KAPPA, n_starts=6, seed=1,
                device=device, dtype=np.float64)
    assert res.feasible.all()
    pos, ang = C.equilibrium_pose_error(robot, "right_tcp", res.q, T, C.JUSTIN_KAPPA,
                                        device=device)
    assert np.all(pos < 1.1e-4) and np.all(ang < 1.1e-3), (pos, ang)


# ------------------------------------------------------ sparse counter reads (CUDA default)
def test_near_kernel_defers_the_seeds_beyond_its_cap(device):
    """``near`` lists at most ``cap`` on-target seeds; the others are counted, their U_A and
    gradient zeroed and their collision cost set above any screen; off-target seeds are
    switched off."""
    B, n, cap = 8, 3, 2
    k = ik_step.check_kernels(wp.float64, False)
    err = np.zeros((B, 6))
    err[[1, 5], 0] = 0.5                       # off target
    done = np.zeros(B, np.int32)
    done[2] = 1                                # done: untouched
    arr = lambda a, dt=wp.float64: wp.array(a, dtype=dt, device=device)  # noqa: E731
    on = arr(np.ones(B, np.int32), wp.int32)
    counts = arr(np.zeros(3, np.int32), wp.int32)
    idx = arr(np.full(B, -1, np.int32), wp.int32)
    coll, cost, grad = arr(np.full(B, 0.25)), arr(np.full(B, 0.5)), arr(np.ones((B, n)))
    wp.launch(k.near, dim=B, inputs=[arr(err), 1e-4, 1e-3, cap,
                                     arr(np.zeros(1, np.int32), wp.int32),
                                     arr(done, wp.int32)],
              outputs=[on, counts, idx, coll, cost, grad], device=device)
    on_target = [0, 3, 4, 6, 7]
    assert counts.numpy()[2] == len(on_target)
    listed = idx.numpy()[:cap]
    assert set(listed) <= set(on_target) and len(set(listed)) == cap
    assert np.all(idx.numpy()[cap:] == -1)
    deferred = sorted(set(on_target) - set(listed))
    np.testing.assert_array_equal(coll.numpy()[deferred], 1e30)
    np.testing.assert_array_equal(cost.numpy()[deferred], 0.0)
    np.testing.assert_array_equal(grad.numpy()[deferred], 0.0)
    kept = sorted(set(range(B)) - set(deferred))
    np.testing.assert_array_equal(coll.numpy()[kept], 0.25)
    np.testing.assert_array_equal(grad.numpy()[kept], 1.0)
    np.testing.assert_array_equal(on.numpy(), [1, 0, 1, 1, 1, 0, 1, 1])


@pytest.mark.parametrize("read_every", [4, 7])
def test_sparse_counter_reads_still_solve_and_check_everything(device, read_every):
    """Reading the counters every k iterations (CUDA's default) with a gathered U_A launch
    too small for the on-target seeds between reads (arm7 in the shelf world, 48 x 8 seeds
    near the solutions: ~384 seeds reach the target at once, the launch starts at 64): the
    seeds beyond it wait, every problem is still solved, and every reported solution is on
    target, within the limits and collision-free by the independent host checks."""
    robot = jwarp.robot("arm7")
    world = shelf_world()
    qt, T = _free_targets(robot, "tcp", 48, seed=5, world=world, margin=0.01, device=device)
    rng = np.random.default_rng(4)
    seeds = qt[:, None] + rng.normal(scale=2e-3, size=(len(T), 8, robot.n_dof))
    # cuda_graphs off: the spy below reads the counters at every near pass, which a graph
    # replay (the same launches) does not call back into
    kw = dict(margin=0.01, stop_when_solved=False, seed=3, cuda_graphs=False)
    dense = IK.IKSolver(robot, "tcp", len(T), IK.IKOptions(read_every=1, **kw), world=world,
                        device=device, dtype=np.float64).solve(T, seeds)
    solver = IK.IKSolver(robot, "tcp", len(T), IK.IKOptions(read_every=read_every, **kw),
                         world=world, device=device, dtype=np.float64)
    seen = []  # (launch size, seeds on target) of every near pass
    near = solver._near

    def spy(cap):
        near(cap)
        seen.append((cap, int(solver.counts.numpy()[2])))
    solver._near = spy
    sparse = solver.solve(T, seeds)
    assert any(n > cap for cap, n in seen), seen  # the deferral did happen
    assert dense.feasible.all() and sparse.feasible.all()
    assert sparse.all_feasible.sum() == dense.all_feasible.sum() == len(T) * 8
    q = sparse.all_q[sparse.all_feasible]
    tcp = jwarp.fk(robot, q, device=device, dtype=np.float64)[:, robot.frame_index("tcp")]
    want = np.repeat(T, 8, axis=0)[sparse.all_feasible.reshape(-1)]
    assert np.abs(tcp[:, :3, 3] - want[:, :3, 3]).max() < 1e-4
    assert within_limits(robot, q, tol=1e-9).all()
    assert collision.is_collision_free(robot, q, world, 0.01, device=device,
                                       dtype=np.float64).all()
    with pytest.raises(ValueError, match="^read_every"):
        IK.IKOptions(read_every=0)


def test_seed_and_tolerances_out_of_range_name_the_option():
    """Reliability round 4, item 9: ik(seed=-1) failed inside numpy without naming seed;
    tol_pos/tol_rot of 1e308 overflowed ("numeric overflow") in the solver's setup."""
    from jwarp.solvers.ik import IKOptions, IKSolver, ik

    T = np.eye(4)
    T[:3, 3] = [0.5, 0.5, 0.0]
    for kw, match in ((dict(seed=-1), r"seed: expected an integer in \[0, 9223372036854775807\]"),
                      (dict(tol_pos=1e308), "tol_pos: 1e\\+308 m is not a position tolerance"),
                      (dict(tol_rot=1e308), "tol_rot: 1e\\+308 rad is more than pi")):
        with pytest.raises(ValueError, match=match):
            ik("planar4", "tcp", T, n_starts=2, iterations=2, **kw)
    solver = IKSolver(jwarp.robot("planar4"), "tcp", 1, IKOptions(n_starts=2, iterations=2))
    with pytest.raises(ValueError, match="seed: expected an integer >= 0"):
        solver.reseed(-1)
