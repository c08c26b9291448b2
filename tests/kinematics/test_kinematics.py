"""Kinematics kernels against the independent numpy reference and finite differences."""

import numpy as np
import pytest
import warp as wp
from devices import requires_cpu, requires_cuda
from reference import kappa_uniform, ref_fk, ref_fk_elastic, ref_jacobian_fd, ref_torques, sample_q

import jwarp
from jwarp import kinematics as K
from jwarp.kinematics.autodiff import tape_jacobian

ROBOTS = ["justin19", "arm7", "planar4", "planar5", "sphere2d", "hand4"]
KAPPA = 1e-4  # 0.1 rad/kNm


def _sample(model, n, seed):
    q = sample_q(model, n, seed=seed)
    if model.name == "justin19":  # respect the coupled torso limit 0 <= q1 + q2 <= 135 deg
        q[:, 2] = np.clip(q[:, 2], np.maximum(0, -q[:, 1]), np.deg2rad(135) - np.maximum(q[:, 1], 0))
    return q


@pytest.mark.parametrize("name", ROBOTS)
def test_fk_matches_reference_float64_and_float32(device, name):
    model = jwarp.robot(name)
    q = _sample(model, 1000, seed=1)
    expected = ref_fk(model, q)
    got64 = K.fk(name, q, device=device)
    assert got64.shape == (1000, model.n_frames, 4, 4) and got64.dtype == np.float64
    np.testing.assert_allclose(got64, expected, atol=1e-9, rtol=0)
    got32 = K.fk(name, q.astype(np.float32), device=device)
    assert got32.dtype == np.float32
    np.testing.assert_allclose(got32, expected, atol=1e-5, rtol=0)


def test_fk_per_configuration_dh_rows(device):
    model = jwarp.robot("justin19")
    q = _sample(model, 20, seed=2)
    rng = np.random.default_rng(3)
    dh = model.dh_table + rng.normal(0, 0.01, (20, model.n_frames, 5)) * model.is_dh[None, :, None]
    np.testing.assert_allclose(K.fk(model, q, dh=dh, device=device), ref_fk(model, q, dh=dh),
                               atol=1e-12)
    shared = dh[0]
    np.testing.assert_allclose(K.fk(model, q, dh=shared, device=device), ref_fk(model, q, dh=shared),
                               atol=1e-12)


def test_leading_batch_dims_and_single_configuration(device):
    model = jwarp.robot("planar4")
    q = _sample(model, 6, seed=4).reshape(2, 3, 4)
    frames = K.fk(model, q, device=device)
    assert frames.shape == (2, 3, model.n_frames, 4, 4)
    single = K.fk(model, q[1, 2], device=device)
    assert single.shape == (model.n_frames, 4, 4)
    np.testing.assert_allclose(single, frames[1, 2])


def test_coupled_torso_moves_frame4_by_minus_q1_plus_q2(device):
    model = jwarp.robot("justin19")
    q = np.zeros((3, 19))
    q[:, 1] = [0.3, -0.2, 0.5]
    q[:, 2] = [0.4, 0.7, 0.1]
    frames = K.fk(model, q, device=device)
    rel = np.linalg.inv(frames[:, 3]) @ frames[:, 4]
    angle = np.arctan2(rel[:, 1, 0], rel[:, 0, 0])
    np.testing.assert_allclose(angle, -(q[:, 1] + q[:, 2]), atol=1e-12)
    # the coupled joint keeps the chest orientation independent of q1, q2 (parallel axes)
    np.testing.assert_allclose(frames[:, 4, :3, :3], frames[:1, 4, :3, :3].repeat(3, 0), atol=1e-12)
    jac = K.jacobian(model, q, "torso_4", device=device)
    np.testing.assert_allclose(jac[:, 3:, 1] + jac[:, 3:, 2], 0.0, atol=1e-12)


@pytest.mark.parametrize("name,frame", [("justin19", "right_tcp"), ("justin19", "left_tcp"),
                                        ("justin19", "head_tcp"), ("justin19", "torso_4"),
                                        ("arm7", "right_tcp"), ("planar5", "tcp"),
                                        ("sphere2d", "point"), ("hand4", "index_tip")])
def test_geometric_jacobian_matches_finite_differences(device, name, frame):
    model = jwarp.robot(name)
    q = _sample(model, 40, seed=5)
    fi = model.frame_index(frame)
    jac = K.jacobian(model, q, frame, device=device)
    assert jac.shape == (40, 6, model.n_dof)
    np.testing.assert_allclose(jac, ref_jacobian_fd(model, q, fi), atol=1e-7)


def test_jacobian_of_a_point_and_float32(device):
    model = jwarp.robot("justin19")
    q = _sample(model, 10, seed=6)
    point = np.array([0.02, -0.01, 0.05])
    jac = K.jacobian(model, q, "left_tcp", point=point, device=device)
    eps = 1e-6
    fd = np.zeros((10, 3, 19))
    for j in range(19):
        dq = np.zeros(19)
        dq[j] = eps
        plus, minus = ref_fk(model, q + dq)[:, 22], ref_fk(model, q - dq)[:, 22]
        fd[:, :, j] = ((plus - minus)[:, :3, :3] @ point + (plus - minus)[:, :3, 3]) / (2 * eps)
    np.testing.assert_allclose(jac[:, :3], fd, atol=1e-7)
    jac32 = K.jacobian(model, q.astype(np.float32), "left_tcp", point=point, device=device)
    np.testing.assert_allclose(jac32, jac, atol=2e-5)


def _pose_fd(fn, x, eps=1e-6):
    """Central differences of a pose function -> (B, 6, P) twist columns."""
    base = fn(x)
    cols = []
    for p in range(x.size):
        dx = np.zeros_like(x)
        dx.flat[p] = eps
        dT = (fn(x + dx) - fn(x - dx)) / (2 * eps)
        A = dT[:, :3, :3] @ base[:, :3, :3].transpose(0, 2, 1)
        ang = 0.5 * np.stack([A[:, 2, 1] - A[:, 1, 2], A[:, 0, 2] - A[:, 2, 0], A[:, 1, 0] - A[:, 0, 1]], 1)
        cols.append(np.concatenate([dT[:, :3, 3], ang], 1))
    return np.stack(cols, -1)


@pytest.mark.parametrize("name,frame", [("justin19", "right_tcp"), ("hand4", "thumb_tip")])
def test_dh_jacobian_matches_finite_differences(device, name, frame):
    model = jwarp.robot(name)
    q = _sample(model, 5, seed=7)
    fi = model.frame_index(frame)
    rng = np.random.default_rng(8)
    dh = model.dh_table + rng.normal(0, 0.02, model.dh_table.shape) * model.is_dh[:, None]
    jac = K.jacobian_dh(model, q, frame, dh=dh, device=device)
    assert jac.shape == (5, 6, model.n_frames, 5)
    fd = _pose_fd(lambda x: ref_fk(model, q, dh=x.reshape(dh.shape))[:, fi], dh.copy())
    np.testing.assert_allclose(jac.reshape(5, 6, -1), fd, atol=1e-7)
    tape = tape_jacobian(model, q, frame, dh=dh, wrt=("q", "dh"), device=device)
    np.testing.assert_allclose(tape["dh"], jac, atol=1e-10)
    np.testing.assert_allclose(tape["q"], K.jacobian(model, q, frame, dh=dh, device=device), atol=1e-10)
    nominal = tape_jacobian(model, q, frame, wrt=("dh",), device=device)  # beta = 0: d/d beta must not vanish
    np.testing.assert_allclose(nominal["dh"], K.jacobian_dh(model, q, frame, device=device), atol=1e-10)


def test_kappa_jacobian_through_the_equilibrium_matches_finite_differences():
    model = jwarp.robot("justin19")
    q = _sample(model, 3, seed=9)
    kappa = kappa_uniform(model, KAPPA)
    point = np.array([0.0, 0.0, 0.1])
    tape = tape_jacobian(model, q, "right_tcp", point=point, kappa=kappa, iterations=6,
                         wrt=("q", "kappa"))
    picks = [(1, 0), (2, 1), (4, 2), (7, 2), (9, 0), (12, 2)]

    def pose(k):
        T = ref_fk_elastic(model, q, k, n_iter=6)[0][:, 13].copy()
        T[:, :3, 3] += T[:, :3, :3] @ point
        return T

    for i, a in picks:
        def fn(x, i=i, a=a):
            k = kappa.copy()
            k[i, a] = x[0]
            return pose(k)

        fd = _pose_fd(fn, np.array([kappa[i, a]]), eps=1e-7)[..., 0]
        np.testing.assert_allclose(tape["kappa"][:, :, i, a], fd, rtol=1e-5, atol=1e-6)
    fdq = _pose_fd(lambda x: _shift(ref_fk_elastic(model, x.reshape(q.shape), kappa, n_iter=6)[0][:, 13],
                                    point), q.copy())
    # columns of the FD over all q entries: pick each sample's own joints
    B = q.shape[0]
    fdq = fdq.reshape(B, 6, B, 19)[np.arange(B), :, np.arange(B)]
    np.testing.assert_allclose(tape["q"], fdq, atol=1e-6)


def _shift(T, point):
    T = T.copy()
    T[:, :3, 3] += T[:, :3, :3] @ point
    return T


@pytest.mark.parametrize("name", ["justin19", "arm7", "hand4"])
def test_gravity_torques_and_elastic_fk_match_reference(device, name):
    model = jwarp.robot(name)
    q = _sample(model, 50, seed=10)
    np.testing.assert_allclose(K.gravity_torques(model, q, device=device),
                               ref_torques(model, ref_fk(model, q)), atol=1e-9)
    kappa = kappa_uniform(model, KAPPA * 3)
    frames, rho = ref_fk_elastic(model, q, kappa, n_iter=4, lam=0.7)[:2]
    res = K.fk_elastic(model, q, kappa, lam=0.7, max_iter=4, tol=0.0, device=device)
    np.testing.assert_allclose(res.frames, frames, atol=1e-10)
    np.testing.assert_allclose(res.rho, rho, atol=1e-12)
    assert (res.iterations == 4).all()


def test_justin_elastic_sag_converges_in_three_iterations(device, capsys):
    model = jwarp.robot("justin19")
    q = np.vstack([np.zeros(19), _sample(model, 200, seed=11)])
    kappa = kappa_uniform(model, KAPPA)
    rigid = K.fk(model, q, device=device)
    exact = K.fk_elastic(model, q, kappa, max_iter=50, tol=1e-12, device=device)
    assert exact.converged.all()
    tcp = [model.frame_index("right_tcp"), model.frame_index("left_tcp")]
    sag = np.linalg.norm(exact.frames[:, tcp][..., :3, 3] - rigid[:, tcp][..., :3, 3], axis=-1) * 1e3
    residual = []
    for n in range(5):
        it = K.fk_elastic(model, q, kappa, max_iter=n, tol=0.0, device=device)
        residual.append(np.linalg.norm(it.frames[:, tcp][..., :3, 3] - exact.frames[:, tcp][..., :3, 3],
                                       axis=-1).max() * 1e3)
    print(f"\njustin19 kappa=0.1 rad/kNm: TCP sag at q=0 right {sag[0, 0]:.2f} mm, "
          f"left {sag[0, 1]:.2f} mm; over 200 random q mean {sag[1:].mean():.1f} mm, "
          f"min {sag[1:].min():.1f} mm, max {sag[1:].max():.1f} mm")
    print("max TCP distance to the equilibrium after 0..4 updates [mm]: "
          + ", ".join(f"{r:.4f}" for r in residual))
    assert sag[0].min() > 2.0 and sag[0].max() < 60.0          # a few mm to cm at q = 0
    assert sag.min() > 1.0 and sag.max() < 300.0  # up to ~0.2 m with the torso tilted
    # contraction by > 5x per update; after 3 updates every TCP is within 0.5 mm
    assert all(residual[k + 1] < 0.2 * residual[k] for k in range(4))
    assert residual[3] < 0.5
    coarse = K.fk_elastic(model, q, kappa, tol=1e-4, device=device)  # 0.1 mm per metre
    print(f"updates to tol 1e-4 rad: median {np.median(coarse.iterations):.0f}, "
          f"max {coarse.iterations.max()}")
    assert coarse.converged.all() and np.median(coarse.iterations) <= 3


def test_twenty_times_softer_converges_with_damping(device, capsys):
    """20x the compliance: lam = 0.5 converges where lam = 1 oscillates. With 20x on the
    torso's lateral axes too, a few configurations approach buckling (kappa * M g h near 1
    for the upright torso carrying ~40 kg) and converge slowly or not at all."""
    model = jwarp.robot("justin19")
    q = _sample(model, 100, seed=12)
    soft_limbs = kappa_uniform(model, 20 * KAPPA)
    soft_limbs[:5] = KAPPA  # torso frames at the nominal compliance
    undamped = K.fk_elastic(model, q, soft_limbs, lam=1.0, max_iter=300, tol=1e-9, device=device)
    res = K.fk_elastic(model, q, soft_limbs, lam=0.5, max_iter=300, tol=1e-9, device=device)
    everything = K.fk_elastic(model, q, kappa_uniform(model, 20 * KAPPA), lam=0.5, max_iter=300,
                              tol=1e-6, device=device)
    rigid = K.fk(model, q, device=device)
    sag = np.linalg.norm(res.frames[:, [13, 22]][..., :3, 3] - rigid[:, [13, 22]][..., :3, 3], axis=-1)
    print(f"\n20x softer limbs, lam=0.5: converged {res.converged.mean():.0%}, iterations median "
          f"{np.median(res.iterations):.0f} max {res.iterations.max()}; lam=1: converged "
          f"{undamped.converged.mean():.0%}; TCP sag mean {sag.mean() * 1e3:.1f} mm, max "
          f"{sag.max() * 1e3:.1f} mm")
    print(f"20x everything (torso too), lam=0.5, tol 1e-6: converged "
          f"{everything.converged.mean():.0%}, iterations median {np.median(everything.iterations):.0f}")
    assert res.converged.all()
    tau = ref_torques(model, res.frames, dh=res.rho)
    rho_fixed = model.dh_table.copy()[None].repeat(100, 0)
    rho_fixed[..., 3] += soft_limbs[:, 0] * tau[..., 0]
    rho_fixed[..., 4] += soft_limbs[:, 1] * tau[..., 1]
    rho_fixed[..., 1] += soft_limbs[:, 2] * tau[..., 2]
    np.testing.assert_allclose(res.rho, rho_fixed, atol=1e-8)  # a true fixed point
    assert everything.converged.mean() >= 0.9


def test_elastic_step_is_one_update_of_the_iteration(device):
    model = jwarp.robot("justin19")
    q = _sample(model, 8, seed=13)
    kappa = kappa_uniform(model, KAPPA)
    first = K.elastic_step(model, q, None, kappa, device=device)
    np.testing.assert_allclose(first.frames, ref_fk(model, q), atol=1e-12)
    second = K.elastic_step(model, q, first.rho, kappa, device=device)
    two = K.fk_elastic(model, q, kappa, max_iter=2, tol=0.0, device=device)
    np.testing.assert_allclose(second.rho, two.rho, atol=1e-14)
    assert second.delta.shape == (8,) and (second.delta < first.delta).all()


def test_torch_autograd_matches_jacobian(device):
    torch = pytest.importorskip("torch")
    model = jwarp.robot("justin19")
    q_np = _sample(model, 4, seed=14)
    q = torch.tensor(q_np, requires_grad=True)
    frames = K.fk(model, q, device=device)
    assert isinstance(frames, torch.Tensor) and frames.shape == (4, 27, 4, 4)
    frames[:, 13, :3, 3].sum().backward()
    jac = K.jacobian(model, q_np, "right_tcp", device=device)
    np.testing.assert_allclose(q.grad.numpy(), jac[:, :3].sum(1), atol=1e-12)
    q2 = torch.tensor(q_np, requires_grad=True)
    res = K.fk_elastic(model, q2, KAPPA, max_iter=4, tol=0.0, device=device)
    res.frames[:, 22, 2, 3].sum().backward()
    kappa = kappa_uniform(model, KAPPA)
    fd = np.zeros_like(q_np)
    for j in range(19):
        dq = np.zeros(19)
        dq[j] = 1e-6
        fd[:, j] = (ref_fk_elastic(model, q_np + dq, kappa, n_iter=4)[0][:, 22, 2, 3]
                    - ref_fk_elastic(model, q_np - dq, kappa, n_iter=4)[0][:, 22, 2, 3]) / 2e-6
    np.testing.assert_allclose(q2.grad.numpy(), fd, atol=1e-7)
    q32 = torch.tensor(q_np, dtype=torch.float32)
    out = K.fk(model, q32, device=device)
    assert out.dtype == torch.float32
    np.testing.assert_allclose(out.numpy(), ref_fk(model, q_np), atol=1e-5)


def test_warp_arrays_in_warp_arrays_out(device):
    model = jwarp.robot("arm7")
    q_np = _sample(model, 16, seed=15)
    q = wp.array(q_np, dtype=wp.float64, device=device)
    frames = K.fk(model, q)
    assert isinstance(frames, wp.array) and frames.shape == (16, model.n_frames)
    np.testing.assert_allclose(frames.numpy(), ref_fk(model, q_np), atol=1e-12)


@pytest.mark.parametrize("call,match", [
    (lambda: K.fk("justin19", np.zeros(7)), r"q: expected shape \(\.\.\., 19\)"),
    (lambda: K.fk("justin19", np.full(19, np.nan)), "q: contains NaN"),
    (lambda: K.fk("no_such_robot", np.zeros(19)), "unknown robot 'no_such_robot'"),
    (lambda: K.fk("justin19", np.zeros((0, 19))), "q: empty batch"),
    (lambda: K.fk("justin19", np.zeros(19), dh=np.zeros((27, 4))), r"dh: expected shape"),
    (lambda: K.jacobian("justin19", np.zeros(19), "nose"), "unknown frame 'nose'"),
    (lambda: K.jacobian("justin19", np.zeros(19), 99), "frame index 99 out of range"),
    (lambda: K.jacobian("justin19", np.zeros(19), 13, point=[1, 2]), "point"),
    (lambda: K.fk_elastic("justin19", np.zeros(19), -1.0), "kappa: compliances must be >= 0"),
    (lambda: K.fk_elastic("justin19", np.zeros(19), np.ones((5, 3))), "kappa: expected"),
    (lambda: K.fk_elastic("justin19", np.zeros(19), 1e-4, lam=1.5), "lam"),
    (lambda: K.fk_elastic("justin19", np.zeros(19), 1e-4, max_iter=-1), "max_iter"),
    (lambda: K.fk("justin19", np.zeros(19), device="cuda:7"), "device"),
])
def test_bad_inputs_raise_clear_errors(call, match):
    with pytest.raises(ValueError, match=match):
        call()


def test_bad_types_raise_type_errors():
    with pytest.raises(TypeError, match="q"):
        K.fk("justin19", "zeros")
    with pytest.raises(TypeError, match="dtype"):
        K.fk("justin19", np.zeros(19), dtype=np.int32)


@requires_cuda
def test_cuda_matches_cpu_and_torch_autograd_on_cuda():
    model = jwarp.robot("justin19")
    q = _sample(model, 256, seed=16)
    kappa = kappa_uniform(model, KAPPA)
    np.testing.assert_allclose(K.fk(model, q, device="cuda:0"), ref_fk(model, q), atol=1e-9)
    np.testing.assert_allclose(K.fk(model, q.astype(np.float32), device="cuda:0"), ref_fk(model, q),
                               atol=2e-5)
    # compared with references only: the trimmed Warp of the GPU machine has no CPU compiler
    jac = K.jacobian(model, q, "right_tcp", device="cuda:0")
    np.testing.assert_allclose(jac, ref_jacobian_fd(model, q, 13), atol=1e-7)
    tape = tape_jacobian(model, q[:8], "left_tcp", wrt=("dh",), device="cuda:0")
    np.testing.assert_allclose(K.jacobian_dh(model, q[:8], "left_tcp", device="cuda:0"), tape["dh"],
                               atol=1e-10)
    gpu = K.fk_elastic(model, q, kappa, max_iter=4, tol=0.0, device="cuda:0")
    np.testing.assert_allclose(gpu.frames, ref_fk_elastic(model, q, kappa, n_iter=4)[0], atol=1e-9)
    torch = pytest.importorskip("torch")
    qt = torch.tensor(q, device="cuda", requires_grad=True)
    frames = K.fk(model, qt)
    assert frames.is_cuda and frames.shape == (256, 27, 4, 4)
    frames[:, 13, :3, 3].sum().backward()
    np.testing.assert_allclose(qt.grad.cpu().numpy(), jac[:, :3].sum(1), atol=1e-9)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_kernel_cos_sin_matches_numpy(device, dtype):
    """The kernels' cos/sin (a polynomial in float32) against numpy over +-60 rad,
    including the quadrant boundaries k pi/4 where the fix-up switches branches."""
    from jwarp.core.device import scalar_type
    from jwarp.kernels import fk as fk_kernels

    scalar = scalar_type(dtype)
    k = fk_kernels.kernels(scalar)

    @wp.kernel(module="unique")
    def eval_cos_sin(x: wp.array(dtype=scalar), c: wp.array(dtype=scalar), s: wp.array(dtype=scalar)):
        i = wp.tid()
        ci, si = k.cos_sin(x[i])
        c[i] = ci
        s[i] = si

    rng = np.random.default_rng(5)
    quarter = np.arange(-80, 81) * (np.pi / 4)
    x = np.concatenate([rng.uniform(-60, 60, 20000), quarter, quarter + 1e-6, quarter - 1e-6,
                        [0.0, 1e-30, -1e-30]]).astype(dtype)
    xs = wp.array(x, dtype=scalar, device=device)
    c = wp.empty_like(xs)
    s = wp.empty_like(xs)
    wp.launch(eval_cos_sin, dim=len(x), inputs=[xs], outputs=[c, s], device=device)
    x64 = x.astype(np.float64)
    tol = 3e-7 if dtype == np.float32 else 1e-15
    np.testing.assert_allclose(c.numpy(), np.cos(x64), rtol=0, atol=tol)
    np.testing.assert_allclose(s.numpy(), np.sin(x64), rtol=0, atol=tol)


def test_kernel_cos_sin_step_follows_a_chain_of_steps(device):
    """cos_sin_step (the compensation rows' cos/sin after one update) against numpy along
    2000 chained steps: small steps (the two-term series from the previous cos/sin) must not
    drift; every 100th step is large (the exact path from the nominal angle)."""
    from jwarp.kernels import fk as fk_kernels

    k = fk_kernels.kernels(wp.float64)

    @wp.kernel(module="unique")
    def chain(dx: wp.array(dtype=wp.float64), x0: wp.float64,
              out: wp.array2d(dtype=wp.float64)):
        c0 = wp.cos(x0)
        s0 = wp.sin(x0)
        cn = c0
        sn = s0
        x = x0
        for j in range(dx.shape[0]):
            x = x + dx[j]
            c0, s0 = k.cos_sin_step(x, dx[j], c0, s0, x0, cn, sn)
            out[j, 0] = x
            out[j, 1] = c0
            out[j, 2] = s0

    rng = np.random.default_rng(8)
    dx = rng.uniform(-1.9e-4, 1.9e-4, 2000)
    dx[::100] = rng.uniform(-0.05, 0.05, 20)  # larger than the series' range
    out = wp.zeros((len(dx), 3), dtype=wp.float64, device=device)
    wp.launch(chain, dim=1, inputs=[wp.array(dx, dtype=wp.float64, device=device), 0.7],
              outputs=[out], device=device)
    x, c, s = out.numpy().T
    # a series with the wrong sign or order would be off by >= dx^3/6 ~ 1e-12 per step
    np.testing.assert_allclose(c, np.cos(x), rtol=0, atol=1e-14)
    np.testing.assert_allclose(s, np.sin(x), rtol=0, atol=1e-14)


def test_float32_elastic_equilibrium_matches_float64(device):
    """The float32 step sums subtree moments as differences of prefix sums over the whole
    robot: the rows must still agree with float64 to float32 resolution."""
    model = jwarp.robot("justin19")
    q = _sample(model, 200, seed=15)
    kappa = kappa_uniform(model, KAPPA)
    f64 = K.fk_elastic(model, q, kappa, max_iter=4, tol=0.0, device=device)
    f32 = K.fk_elastic(model, q.astype(np.float32), kappa, max_iter=4, tol=0.0, device=device,
                       dtype=np.float32)
    assert f32.rho.dtype == np.float32
    elastic = f64.rho - model.dh_table                 # the deflections, ~1e-3 rad
    assert np.abs(elastic).max() > 1e-3
    np.testing.assert_allclose(f32.rho - model.dh_table, elastic, atol=2e-6)
    np.testing.assert_allclose(f32.frames[..., :3, 3], f64.frames[..., :3, 3], atol=2e-5)
    static = ~model.is_dh.astype(bool)
    np.testing.assert_array_equal(f32.rho[:, static], np.broadcast_to(
        model.dh_table[static].astype(np.float32), f32.rho[:, static].shape))


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_component_major_fk_layout_matches_fk(device, dtype):
    """launch_fk(component_major=True): memory (n_frames, 4, 4, B), viewed (B, n_frames, 4, 4)."""
    from jwarp.core.device import put_model
    model = jwarp.robot("justin19")
    q = _sample(model, 64, seed=16)
    t = put_model(model, device, dtype)
    qa = wp.array(q.astype(dtype), device=device)
    out = K.launch_fk(t, qa, component_major=True)
    assert out.shape == (64, 27, 4, 4) and out.strides[0] == np.dtype(dtype).itemsize
    np.testing.assert_allclose(out.numpy(), ref_fk(model, q), atol=1e-12 if dtype == np.float64 else 1e-5)
    rho = np.repeat(model.dh_table[None], 64, 0) + 1e-3
    dh = (wp.array(rho.astype(dtype), device=device), 1)
    np.testing.assert_array_equal(K.launch_fk(t, qa, dh=dh, component_major=True).numpy(),
                                  K.launch_fk(t, qa, dh=dh).numpy())
    with pytest.raises(ValueError, match="frames: component_major"):
        K.launch_fk(t, qa, frames=wp.empty((64, 27, 4), dtype=t.scalar, device=device),
                    component_major=True)


@requires_cpu
def test_solve_equilibrium_on_a_device_model_is_fk_elastic():
    """``solve_equilibrium(m, q, dh, kappa)`` on the robot's device model gives fk_elastic's
    numbers exactly, takes a Warp q as is, and accepts compliances of either sign."""
    from jwarp.core.device import frame_mass_model, put_model, with_frame_masses

    r = jwarp.robot("justin19")
    rng = np.random.default_rng(7)
    q = rng.uniform(r.joint_limits[:, 0], r.joint_limits[:, 1], (5, r.n_dof))
    kap = kappa_uniform(r, 2e-4)
    m = put_model(r, "cpu", np.float64)
    ref = jwarp.fk_elastic(r, q, kap, dh=r.dh_table, device="cpu", dtype=np.float64,
                           max_iter=30)
    eq = K.solve_equilibrium(m, q, r.dh_table, kap, max_iter=30)
    for a, b in zip(eq, ref):
        np.testing.assert_array_equal(a, b)
    qw = wp.array(q, dtype=wp.float64, device="cpu")
    np.testing.assert_array_equal(K.solve_equilibrium(m, qw, r.dh_table, kap, max_iter=30).frames,
                                  ref.frames)
    neg = K.solve_equilibrium(m, q, r.dh_table, -kap, max_iter=30)
    assert neg.converged.all() and not np.array_equal(neg.frames, ref.frames)
    mass, com = frame_mass_model(r)
    heavy = K.solve_equilibrium(with_frame_masses(m, 2 * mass, com), q, r.dh_table, kap,
                                max_iter=30)
    assert not np.array_equal(heavy.rho, ref.rho)
    with pytest.raises(TypeError, match="m: expected a DeviceModel"):
        K.solve_equilibrium(r, q, r.dh_table, kap)
    for bad in (-1, 2.5, True):   # as fk_elastic: an integer >= 0
        with pytest.raises(ValueError, match="max_iter"):
            K.solve_equilibrium(m, q, r.dh_table, kap, max_iter=bad)
    with pytest.raises(TypeError, match="kappa"):
        K.solve_equilibrium(m, q, r.dh_table, "x")
    with pytest.raises(ValueError, match="kappa: expected shape"):
        K.solve_equilibrium(m, q, r.dh_table, kap[:, :2])
    with pytest.raises(ValueError, match="dh"):
        K.solve_equilibrium(m, q, np.full_like(r.dh_table, np.nan), kap)
