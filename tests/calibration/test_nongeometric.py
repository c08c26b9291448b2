"""Non-geometric extras (docs/nongeometric.md): joint transmission errors (``harmonic``)
and torque-dependent joint compliance (``kappa_nonlinear``): robot file round trip, the
kinematics against an independent numpy reference, and the calibration groups' analytic
Jacobian columns against central finite differences."""

from __future__ import annotations

import numpy as np
import pytest
from calibration.test_calibration import (
    FramePositions,
    _assert_jacobian_close,
    _cartesian,
    _fd_jacobian,
    _q,
)
from devices import requires_cpu
from reference import THETA, nominal_dh, ref_fk, ref_torques

import jwarp
from jwarp.calibration import CalibrationProblem, ParameterSpace
from jwarp.calibration.estimate.map import problem_options
from jwarp.model import RobotModel, RobotModelError

KAPPA = 1e-4


def _nongeo(robot, seed=0, amp=2e-3, knl=2e-9):
    """robot with compliances on [alpha, theta], two harmonics on every joint, and a
    nonlinear compliance on every DH frame."""
    rng = np.random.default_rng(seed)
    kap = np.zeros((robot.n_frames, 3))
    kap[:, [0, 2]] = rng.uniform(0.5 * KAPPA, 1.5 * KAPPA, (robot.n_frames, 2))
    h = rng.uniform(-amp, amp, (robot.n_dof, 2, 2))
    k2 = rng.uniform(-knl, knl, robot.n_frames) * robot.is_dh
    return robot.copy(kappa=kap * robot.is_dh[:, None], harmonic=h, kappa_nonlinear=k2)


def _ref_transmission(h, q):
    """numpy q + sum_k a sin(k q) + b cos(k q), independent of RobotModel's code."""
    out = q.copy()
    for j in range(q.shape[1]):
        for k in range(h.shape[1]):
            out[:, j] += h[j, k, 0] * np.sin((k + 1) * q[:, j]) + h[j, k, 1] * np.cos((k + 1) * q[:, j])
    return out


def _ref_elastic(model, q, n_iter=200):
    """Reference equilibrium rho = rho0 + kappa tau + [0, 0, kappa_nl tau_theta^3] at the
    transmitted joint values (tests/reference.py FK and torques)."""
    qe = _ref_transmission(model.harmonic, q)
    rho0 = np.broadcast_to(nominal_dh(model), (len(q), model.n_frames, 5)).copy()
    rho = rho0.copy()
    for _ in range(n_iter):
        F = ref_fk(model, qe, rho)
        tau = ref_torques(model, F, rho)
        new = rho0.copy()
        new[..., 3] += model.kappa[:, 0] * tau[..., 0]
        new[..., 4] += model.kappa[:, 1] * tau[..., 1]
        new[..., THETA] += model.kappa[:, 2] * tau[..., 2] + model.kappa_nonlinear * tau[..., 2] ** 3
        rho = new
    return ref_fk(model, qe, rho), rho


def test_robot_file_round_trip_and_backward_compatibility(tmp_path):
    base = jwarp.robot("justin19")
    assert base.harmonic.shape == (19, 0, 2) and not base.has_harmonic
    assert "harmonic" not in base.to_dict() and "kappa_nonlinear" not in base.to_dict()
    model = _nongeo(base)
    path = tmp_path / "r.json"
    model.save(path)
    back = RobotModel.load(path)
    np.testing.assert_array_equal(back.harmonic, model.harmonic)
    np.testing.assert_array_equal(back.kappa_nonlinear, model.kappa_nonlinear)
    # joints left out of the file are zero; lists of different lengths are padded
    doc = base.to_dict()
    doc["harmonic"] = {"right_2": [[1e-3, 0.0]], "left_1": [[0.0, 1e-3], [2e-3, 0.0]]}
    m = RobotModel.from_dict(doc)
    assert m.harmonic.shape == (19, 2, 2)
    assert m.harmonic[base.joint_index("right_2"), 1].tolist() == [0.0, 0.0]
    assert m.harmonic[base.joint_index("left_1"), 1, 0] == 2e-3
    with pytest.raises(RobotModelError, match="harmonic: unknown joint 'nope'"):
        RobotModel.from_dict({**doc, "harmonic": {"nope": [[0.0, 0.0]]}})
    with pytest.raises(RobotModelError, match=r"harmonic.right_2: expected"):
        RobotModel.from_dict({**doc, "harmonic": {"right_2": [1e-3, 0.0]}})
    with pytest.raises(RobotModelError, match="kappa_nonlinear"):
        RobotModel.from_dict({**doc, "kappa_nonlinear": [1.0, 2.0]})
    k = np.zeros(base.n_frames)
    k[0] = 1e-9                                    # torso_base is static
    assert not base.is_dh[0]
    with pytest.raises(RobotModelError, match="kappa_nonlinear: must be 0 on static"):
        base.copy(kappa_nonlinear=k)


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_fk_elastic_and_fk_match_numpy_reference_with_the_new_terms(dtype, device):
    """One kernel source for float32 and float64: both dtypes against the numpy reference
    (float32 to its resolution)."""
    model = _nongeo(jwarp.robot("justin19"), knl=5e-9)
    rng = np.random.default_rng(1)
    q = _q(model, 6, rng)
    F_ref, rho_ref = _ref_elastic(model, q)
    res = jwarp.fk_elastic(model, q.astype(dtype), max_iter=200, device=device, dtype=dtype)
    tol = 1e-10 if dtype == np.float64 else 2e-5
    assert res.converged.all()
    np.testing.assert_allclose(res.frames, F_ref, atol=tol)
    np.testing.assert_allclose(res.rho[..., 1], rho_ref[..., 1], atol=tol)
    # the new terms matter at this size: without them the frames differ by millimetres
    plain = model.copy(harmonic=None, kappa_nonlinear=None)
    other = jwarp.fk_elastic(plain, q.astype(dtype), max_iter=200, device=device, dtype=dtype)
    assert np.abs(other.frames[..., :3, 3] - F_ref[..., :3, 3]).max() > 1e-3
    # rigid FK sees the transmission errors; the joint Jacobian has the chain-rule factor
    np.testing.assert_allclose(jwarp.fk(model, q, device=device, dtype=np.float64),
                               ref_fk(model, _ref_transmission(model.harmonic, q)), atol=1e-12)
    J = jwarp.jacobian(model, q, "right_tcp", device=device, dtype=np.float64)
    tcp = model.frame_index("right_tcp")
    eps = 1e-6
    for j in (3, 6):
        dq = np.zeros(model.n_dof)
        dq[j] = eps
        d = (ref_fk(model, _ref_transmission(model.harmonic, q + dq))[:, tcp, :3, 3]
             - ref_fk(model, _ref_transmission(model.harmonic, q - dq))[:, tcp, :3, 3]) / (2 * eps)
        np.testing.assert_allclose(J[:, :3, j], d, atol=1e-8)


@requires_cpu
def test_compensation_rows_see_the_nonlinear_compliance():
    """The optimizers' one-update-per-iteration compensation (elastic_step) converges to
    the same equilibrium as fk_elastic with kappa_nonlinear."""
    model = _nongeo(jwarp.robot("justin19"), knl=5e-9).copy(harmonic=None)
    q = _q(model, 4, np.random.default_rng(5))
    ref = jwarp.fk_elastic(model, q, max_iter=200, device="cpu", dtype=np.float64)
    rho = None
    for _ in range(60):
        rho = jwarp.elastic_step(model, q, rho, device="cpu", dtype=np.float64).rho
    np.testing.assert_allclose(rho, ref.rho, atol=1e-10)


@requires_cpu
@pytest.mark.parametrize("free", ["harmonic", "kappa_nonlinear",
                                  "theta,kappa_theta,kappa_alpha,harmonic,kappa_nonlinear,"
                                  "tracker,markers"])
def test_new_jacobian_columns_match_finite_differences(free):
    """Every new column (harmonic through the equilibrium's joint columns, kappa_nonlinear
    through the implicit-function Jacobian with the local compliance kappa + 3 k tau^2),
    at a robot that already has nonzero extras (so the fixed ones act too)."""
    robot = _nongeo(jwarp.robot("justin19"), seed=3)
    meas = _cartesian(robot)
    rng = np.random.default_rng(4)
    S = 30
    q = _q(robot, S, rng)
    y = rng.normal(0, 0.3, (S, 6))
    prob = CalibrationProblem(robot, meas, q, y,
                              problem_options(noise_sigma=1e-4, tol=1e-15, max_iter=400, free=free))
    sp = prob.space
    assert prob.elastic
    x = sp.nominal + 0.5 * sp.scale * rng.standard_normal(sp.size)
    J = prob.jacobian(x)
    Jfd = _fd_jacobian(prob, x)
    # the residuals are nearly linear in a nonlinear compliance of prior size, but their
    # rounding swamps a step of 1e-4 sigma for the weakly loaded joints, and a step of one
    # sigma is far from linear at the torso (300 N m): a step of median/norm sigmas,
    # clipped to [1e-4, 1e3]
    norms = np.linalg.norm(J[:prob.n_data], axis=0)
    med = np.median(norms)
    for i in np.nonzero(sp.kind == 5)[0]:
        h = sp.sigma[i] * float(np.clip(med / max(norms[i], 1e-300), 1e-4, 1e3))
        xp, xm = x.copy(), x.copy()
        xp[i] += h
        xm[i] -= h
        Jfd[:, i] = (prob.residuals(xp) - prob.residuals(xm)) / (2 * h)
    _assert_jacobian_close(J, Jfd, prob.n_data, col_rtol=2e-5, total_rtol=1e-6)
    assert np.sum(np.array(sp.groups) == "kappa_nonlinear") in (0, 20)


@requires_cpu
def test_rigid_harmonic_columns_and_group_names():
    robot = jwarp.robot("arm7")
    meas = FramePositions(robot, ["right_tcp"])
    rng = np.random.default_rng(6)
    q = _q(robot, 15, rng)
    prob = CalibrationProblem(robot, meas, q, rng.normal(0, 0.3, (15, 3)),
                              problem_options(free="theta,harmonic"))
    sp = prob.space
    assert not prob.elastic
    assert sp.size == 7 + 7 * 2 * 2
    assert f"{robot.joint_names[0]}.harmonic_a1" in sp.names
    assert f"{robot.joint_names[6]}.harmonic_b2" in sp.names
    x = sp.nominal + 0.5 * sp.scale * rng.standard_normal(sp.size)
    _assert_jacobian_close(prob.jacobian(x), _fd_jacobian(prob, x), prob.n_data,
                           col_rtol=1e-6, total_rtol=1e-7)
    # the calibrated robot carries the coefficients and reproduces the model's frames
    cal = sp.robot_at(x)
    np.testing.assert_array_equal(cal.harmonic, sp.harmonic_at(x))
    np.testing.assert_allclose(jwarp.fk(cal, q, device="cpu", dtype=np.float64),
                               prob.frames(x), atol=1e-12)


@requires_cpu
def test_calibrated_robot_with_nonlinear_compliance_reproduces_predictions(tmp_path):
    robot = _nongeo(jwarp.robot("justin19"), seed=8)
    meas = _cartesian(robot)
    q = _q(robot, 20, np.random.default_rng(9))
    prob = CalibrationProblem(robot, meas, q, np.zeros((20, 6)),
                              problem_options(noise_sigma=1e-4, free="kappa_nonlinear,harmonic",
                                              tol=1e-14, max_iter=300))
    sp = prob.space
    x = sp.nominal + sp.scale * np.random.default_rng(10).standard_normal(sp.size)
    cal = sp.robot_at(x)
    cal.save(tmp_path / "cal.json")
    back = RobotModel.load(tmp_path / "cal.json")
    F = jwarp.fk_elastic(back, q, max_iter=300, tol=1e-14, device="cpu", dtype=np.float64).frames
    np.testing.assert_allclose(F, prob.frames(x), atol=1e-10)


def test_parameter_space_sigma_and_validation():
    robot = jwarp.robot("justin19")
    sp = ParameterSpace.build(robot, None, "kappa_nonlinear,harmonic",
                              sigma={"harmonic": 5e-4})
    h = np.array(sp.groups) == "harmonic"
    assert np.all(sp.sigma[h] == 5e-4)
    assert np.all(sp.sigma[~h] == 1e-9)
    with pytest.raises(ValueError, match=r"sigma\['kappa_nonlinear'\]"):
        ParameterSpace.build(robot, None, "kappa_nonlinear", sigma={"kappa_nonlinear": -1})


@requires_cpu
def test_optimizer_compensation_rows_see_the_nonlinear_compliance():
    """The rows IK and the planner keep across iterations (CompensationRows: one torque
    update per iteration from frames at the rows) converge to fk_elastic's equilibrium
    with kappa_nonlinear; the same robot without it converges elsewhere."""
    from jwarp.core.device import put_model
    from jwarp.kinematics.compensation import CompensationRows

    model = _nongeo(jwarp.robot("justin19"), knl=5e-9).copy(harmonic=None)
    q = _q(model, 3, np.random.default_rng(7))
    ref = jwarp.fk_elastic(model, q, max_iter=200, device="cpu", dtype=np.float64)
    t = put_model(model, "cpu", np.float64)
    rows = CompensationRows(t, 3, 1, 1, None, lam=1.0)
    for _ in range(60):
        frames = jwarp.fk(model, wp_q(q), dh=rows.rho(), device="cpu", dtype=np.float64)
        rows.update(frames)
    np.testing.assert_allclose(rows.rho(), ref.rho, atol=1e-9)
    plain = jwarp.fk_elastic(model.copy(kappa_nonlinear=None), q, max_iter=200, device="cpu",
                             dtype=np.float64)
    assert np.abs(plain.rho - ref.rho).max() > 1e-4


def wp_q(q):
    import warp as wp

    return wp.array(np.ascontiguousarray(q, np.float64), dtype=wp.float64, device="cpu")
