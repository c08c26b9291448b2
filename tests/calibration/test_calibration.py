"""MAP calibration (jwarp.calibration): torque derivatives, the analytic residual
Jacobian through the elastic equilibrium, recovery of a simulated truth, identifiability
warnings, result I/O and input validation. All float64, small sample counts. The solver
evaluates its model on the CPU (it takes no device): those tests need Warp's CPU backend
(``requires_cpu``); the torque derivatives are checked against the kernels on every device."""

from __future__ import annotations

import json
import math
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
from devices import requires_cpu

import jwarp
from jwarp.calibration import (
    CalibrationProblem,
    CalibrationWarning,
    ParameterSpace,
    calibrate,
    error_stats,
    errors,
    observation_groups,
    predict,
)
from jwarp.calibration.estimate import elastic as E
from jwarp.calibration.estimate.map import problem_options
from jwarp.calibration.estimate.params import perturb_robot
from jwarp.calibration.estimate.result import model_frames
from jwarp.model.measurement import Measurement, ParamBlock

ROOT = Path(__file__).resolve().parents[2]
KAPPA = 1e-4  # rad/(N m), Agile Justin's order of magnitude


class FramePositions(Measurement):
    """Test-local measurement: origins of some robot frames in base coordinates [m];
    no own parameters. J_frames: a twist (v, w) moves a frame origin by v."""

    name = "positions"
    unit = "m"

    def __init__(self, robot, frames):
        super().__init__(robot, {"plugin": "positions"})
        self.frames = [robot.frame_index(f) for f in frames]
        names = [robot.frames[i].name for i in self.frames]
        self.obs_names = [f"{n}_{a}" for n in names for a in "xyz"]
        self.params = ParamBlock()
        self.noise = 1e-4

    def jacobians(self, frames, p, meta=None):
        f, _, _ = self.check_inputs(frames, p, meta)
        S, K = f.shape[0], len(self.frames)
        y = f[:, self.frames][:, :, :3, 3].reshape(S, 3 * K)
        jf = np.zeros((S, K, 3, K, 6))
        for k in range(K):
            jf[:, k, :, k, :3] = np.eye(3)
        return y, jf.reshape(S, 3 * K, K, 6), np.zeros((S, 3 * K, 0))


# tracker 3 m in front of the robot, looking back (rotation angle below pi: a rotation
# vector near |r| = pi has a second representation, see the report on initial_guess)
def _cartesian(robot, tracker=((3.0, 0.2, 1.0), (0.0, 0.0, 2.6)), marker=(0.0, 0.02, 0.05),
               noise=1e-4, sigma_marker=0.05):
    from jwarp.plugins.measurements.cartesian import CartesianMeasurement

    setup = {"plugin": "cartesian",
             "tracker": {"position": list(tracker[0]), "rotvec": list(tracker[1])},
             "markers": [{"name": "right", "frame": "right_tcp", "position": list(marker),
                          "sigma": sigma_marker},
                         {"name": "left", "frame": "left_tcp", "position": list(marker),
                          "sigma": sigma_marker}],
             "noise": noise}
    return CartesianMeasurement(robot, setup)


def _q(robot, n, rng):
    lim = robot.joint_limits
    return rng.uniform(lim[:, 0], lim[:, 1], (n, robot.n_dof))


def _fd_jacobian(prob, x, rel_step=1e-4):
    """Central differences (step rel_step * prior sigma); columns whose data part is tiny
    (parameters that act only through small torque changes) are redone with a 100x larger
    step so that the residuals' rounding does not dominate."""
    scale = prob.space.scale

    def column(i, step):
        h = step * scale[i]
        xp, xm = x.copy(), x.copy()
        xp[i] += h
        xm[i] -= h
        return (prob.residuals(xp) - prob.residuals(xm)) / (2 * h)

    J = np.stack([column(i, rel_step) for i in range(x.size)], axis=1)
    norms = np.linalg.norm(J[:prob.n_data], axis=0)
    for i in np.nonzero(norms < 1e-2 * np.median(norms))[0]:
        J[:, i] = column(i, 100 * rel_step)
    return J


def _torque_state(robot, rng, S, device):
    """S random configurations of ``robot`` with DH rows 3 cm/rad off the nominal ones,
    their frames (Warp FK on ``device``) and torque state: (q, rho, frames, state)."""
    q = _q(robot, S, rng)
    rho = robot.dh_table + 0.03 * rng.standard_normal((S, robot.n_frames, 5)) * robot.is_dh[None, :, None]
    frames = jwarp.fk(robot, q, dh=rho, device=device)
    return q, rho, frames, E.torque_state(robot, frames, rho)


def _assert_jacobian_matches_fd(prob, rng, col_rtol, total_rtol=1e-7):
    """The analytic residual Jacobian of ``prob`` equals central differences at a random
    point about its prior (compliances in [0.5, 1.5] KAPPA); returns that point."""
    sp = prob.space
    x = sp.nominal + 0.5 * sp.scale * rng.standard_normal(sp.size)
    kap = sp.kind == 1
    x[kap] = rng.uniform(0.5, 1.5, kap.sum()) * KAPPA
    J = prob.jacobian(x)
    Jfd = _fd_jacobian(prob, x)
    _assert_jacobian_close(J, Jfd, prob.n_data, col_rtol=col_rtol, total_rtol=total_rtol)
    return x


def _assert_jacobian_close(J, Jfd, n_data, col_rtol, total_rtol):
    """Per column: |J - Jfd| / max(|Jfd|, 1e-3 median column norm) < col_rtol; overall
    Frobenius relative error < total_rtol; prior rows exact."""
    d = J[:n_data] - Jfd[:n_data]
    norms = np.linalg.norm(Jfd[:n_data], axis=0)
    assert np.all(norms > 0), "a free parameter has no effect on the data"
    col = np.linalg.norm(d, axis=0) / np.maximum(norms, 1e-3 * np.median(norms))
    assert col.max() < col_rtol, f"worst column rel error {col.max():.2e} (column {col.argmax()})"
    assert np.linalg.norm(d) / np.linalg.norm(Jfd[:n_data]) < total_rtol
    np.testing.assert_allclose(J[n_data:], Jfd[n_data:], rtol=1e-6, atol=1e-6 * np.abs(Jfd[n_data:]).max())


# ------------------------------------------------------------ torque derivatives
def test_torques_twists_and_torque_jacobian_match_kernels_and_finite_differences(device):
    robot = jwarp.robot("justin19")
    rng = np.random.default_rng(1)
    q, rho, frames, st = _torque_state(robot, rng, 3, device)
    tk = jwarp.gravity_torques(robot, q, dh=rho, device=device)
    np.testing.assert_allclose(st.tau, tk, rtol=1e-9, atol=1e-9 * np.abs(tk).max())
    # the twist of DH entry (j, c) moves frame j's origin like jacobian_dh of frame j says
    a, w = E.dh_twists(robot, st)
    for j in (1, 2, 4, 8, 12, 17, 25):
        jac = jwarp.jacobian_dh(robot, q, j, dh=rho, device=device)     # (S, 6, n, 5)
        v = a[:, j] + np.cross(w[:, j], frames[:, j, None, :3, 3])
        np.testing.assert_allclose(v, jac[:, :3, j, :].transpose(0, 2, 1), atol=1e-12)
        np.testing.assert_allclose(w[:, j], jac[:, 3:, j, :].transpose(0, 2, 1), atol=1e-12)
    # d tau / d rho against central differences of the Warp torque kernel
    D = E.torque_jacobian(robot, st)
    eps = 1e-6
    for j in np.nonzero(robot.is_dh)[0]:
        for c in range(5):
            rp, rm = rho.copy(), rho.copy()
            rp[:, j, c] += eps
            rm[:, j, c] -= eps
            fd = (jwarp.gravity_torques(robot, q, dh=rp, device=device)
                  - jwarp.gravity_torques(robot, q, dh=rm, device=device)) / (2 * eps)
            np.testing.assert_allclose(D[:, :, :, j, c], fd, atol=1e-6 * max(1.0, np.abs(fd).max()),
                                       err_msg=f"frame {j} column {c}")


# ----------------------------------------------------------- residual Jacobian
@requires_cpu
def test_elastic_residual_jacobian_matches_finite_differences():
    """All DH groups, all three compliance axes, tracker and markers on the tree-shaped
    justin19 (torques couple both arms through the torso)."""
    robot = jwarp.robot("justin19")
    meas = _cartesian(robot)
    rng = np.random.default_rng(2)
    S = 30
    q = _q(robot, S, rng)
    y = rng.normal(0, 0.3, (S, 6))
    prob = CalibrationProblem(robot, meas, q, y,
                              problem_options(noise_sigma=1e-4, tol=1e-15, max_iter=300,
                                              free="theta,d,r,alpha,beta,kappa_theta,"
                                                   "kappa_alpha,kappa_beta,tracker,markers"))
    assert prob.elastic
    _assert_jacobian_matches_fd(prob, rng, col_rtol=2e-6)


@requires_cpu
def test_rigid_residual_jacobian_matches_finite_differences():
    robot = jwarp.robot("arm7")
    meas = FramePositions(robot, ["right_tcp", 5])
    rng = np.random.default_rng(3)
    S = 12
    q = _q(robot, S, rng)
    y = rng.normal(0, 0.3, (S, 6))
    prob = CalibrationProblem(robot, meas, q, y,
                              problem_options(free=["theta", "d", "r", "alpha", "beta"]))
    assert not prob.elastic and prob.space.size == 7 * 5
    x = prob.space.nominal + 0.3 * prob.space.scale * rng.standard_normal(prob.space.size)
    _assert_jacobian_close(prob.jacobian(x), _fd_jacobian(prob, x), prob.n_data,
                           col_rtol=1e-6, total_rtol=1e-7)


@requires_cpu
def test_diverged_equilibrium_gives_infinite_residuals_not_an_error():
    robot = jwarp.robot("arm7")
    meas = FramePositions(robot, ["right_tcp"])
    rng = np.random.default_rng(11)
    q = _q(robot, 10, rng)
    prob = CalibrationProblem(robot, meas, q, np.zeros((10, 3)),
                              problem_options(free="kappa_alpha", max_iter=200))
    x = np.full(prob.space.size, 5.0)         # 5 rad/(N m): no equilibrium near rho0
    r = prob.residuals(x)
    assert r.shape == (prob.n_residuals,) and np.all(np.isinf(r))
    assert np.all(np.isfinite(prob.residuals(np.full(prob.space.size, KAPPA))))


# ---------------------------------------------------------------- recovery
@requires_cpu
def test_full_elastic_calibration_recovers_simulated_truth_with_cartesian_plugin():
    """Truth inside the model: +-5 mm / +-5 deg errors on theta, d, r, alpha of every DH
    frame, kappa_theta and kappa_alpha; rough tracker (0.4 m, 20 deg off) and markers."""
    nominal = jwarp.robot("justin19")
    rng = np.random.default_rng(4)
    truth = perturb_robot(nominal, rng, kappa=(0.5 * KAPPA, 1.5 * KAPPA))
    noise = 1e-4
    m_true = _cartesian(truth, noise=noise)
    meas = _cartesian(nominal, tracker=((2.7, 0.5, 1.2), (0.1, -0.1, 2.6 - 0.35)),
                      marker=(0.0, 0.0, 0.03), noise=noise)
    q = _q(nominal, 140, rng)
    y_clean = m_true.predict(model_frames(truth, q), m_true.params.nominal)
    y = y_clean + rng.normal(0, noise, y_clean.shape)
    tr, te = slice(0, 100), slice(100, None)
    progress = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", CalibrationWarning)
        res = calibrate(nominal, meas, q[tr], y[tr], callback=progress.append,
                        free="theta,d,r,alpha,kappa_theta,kappa_alpha,tracker,markers")
    assert res.success and res.elastic
    before = error_stats(errors(nominal, meas, meas.params.nominal, q[te], y[te]))
    after_clean = error_stats(errors(res.robot, meas, res.params, q[te], y_clean[te]))
    after = error_stats(errors(res.robot, meas, res.params, q[te], y[te]))
    assert before["mean"] > 0.02                      # tens of mm before
    assert after_clean["mean"] <= 1.5 * noise         # the acceptance line (vs the truth)
    # against noisy test data the error is about the noise's own mean norm (1.6 sigma in 3D)
    assert after["mean"] <= 1.5 * 1.596 * noise
    assert error_stats(res.errors)["mean"] <= 1.5 * 1.596 * noise
    # the tracker pose is recovered within its posterior uncertainty
    sp = res.space
    truth_x = sp.pack(truth.dh_table, truth.kappa, m_true.params.nominal)
    for name in ("tracker_px", "tracker_py", "tracker_rz"):
        i = sp.index(name)
        assert abs(res.x[i] - truth_x[i]) < 6 * res.std[i] + 1e-3, name
    # progress callback: one call per iteration of the single start, costs decreasing
    assert [p.iteration for p in progress] == list(range(1, len(progress) + 1))
    assert len(progress) == res.iterations >= 1
    assert progress[-1].cost <= progress[0].cost and progress[-1].n_starts == 1
    assert np.all(np.isfinite(res.std)) and np.all(res.std > 0)


@requires_cpu
def test_position_measurement_recovers_subset_errors_and_joint_compliance():
    nominal = jwarp.robot("arm7")
    rng = np.random.default_rng(5)
    truth = perturb_robot(nominal, rng, groups="theta,d", frames=[1, 2, 3, 4, 5],
                          kappa=(2 * KAPPA, 4 * KAPPA), kappa_groups="kappa_theta")
    meas = FramePositions(nominal, ["right_tcp", 4])
    noise = 1e-4
    q = _q(nominal, 90, rng)
    y_clean = meas.predict(model_frames(truth, q), np.zeros(0))
    y = y_clean + rng.normal(0, noise, y_clean.shape)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", CalibrationWarning)
        res = calibrate(nominal, meas, q[:60], y[:60], free="theta,d,kappa_theta",
                        noise_sigma=noise, n_starts=2, seed=1)
    test = error_stats(errors(res.robot, meas, res.params, q[60:], y_clean[60:]))
    assert test["mean"] <= 1.5 * noise
    assert len(res.starts) == 2 and res.cost == min(s["cost"] for s in res.starts)
    # a rigid fit cannot explain the compliance: clearly worse
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", CalibrationWarning)
        rigid = calibrate(nominal, meas, q[:60], y[:60], free="theta,d", noise_sigma=noise)
    assert error_stats(errors(rigid.robot, meas, rigid.params, q[60:], y_clean[60:]))["mean"] > 3 * test["mean"]


@requires_cpu
def test_rough_tracker_near_half_turn_converges_without_biasing_the_robot():
    """A tracker looking back at the robot (rotation ~ pi, where the rotation vector has two
    representations): the initial alignment must keep the representation next to the rough
    setup, else the tracker prior pulls the joint offsets along the flat directions."""
    robot = jwarp.robot("justin19")
    m_true = _cartesian(robot, tracker=((2.5, 0.0, 1.2), (0.0, 0.0, -math.pi + 0.05)))
    meas = _cartesian(robot, tracker=((2.2, 0.3, 1.0), (0.15, -0.1, math.pi - 0.15)))
    rng = np.random.default_rng(12)
    q = _q(robot, 40, rng)
    y = m_true.predict(model_frames(robot, q), m_true.params.nominal) + rng.normal(0, 1e-4, (40, 6))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", CalibrationWarning)
        res = calibrate(robot, meas, q, y, free="theta,tracker", fix="markers")
    assert not any(n.startswith("tracker") for n, _ in res.moved), res.moved
    assert np.linalg.norm(res.x_start[-3:] - meas.params.nominal[3:6]) < 0.5
    # MAP: the rough prior mean itself pulls a few mrad along the flat direction; a wrong
    # rotation-vector branch (2 pi away) would pull ~50 mrad
    assert abs(res.value("torso_1.theta")) < 1e-2
    assert error_stats(res.errors)["mean"] < 3e-4


def test_nearest_rotvec_picks_the_representation_next_to_the_reference():
    from scipy.spatial.transform import Rotation

    from jwarp.model.geometry import nearest_rotvec

    for r_true, ref in (([0, 0, -math.pi + 0.05], [0, 0, math.pi - 0.1]),
                        ([0.1, 0.2, 0.3], [0.1, 0.2, 0.3]),
                        ([0, 0, 1e-14], [0, 0, 2 * math.pi])):
        R = Rotation.from_rotvec(r_true).as_matrix()
        r = nearest_rotvec(R, np.array(ref))
        np.testing.assert_allclose(Rotation.from_rotvec(r).as_matrix(), R, atol=1e-12)
        ks = np.arange(-3, 4)
        th = np.linalg.norm(r)
        axis = r / th if th > 0 else np.array([0, 0, 1.0])
        best = min(np.linalg.norm((th + 2 * math.pi * k) * axis - ref) for k in ks)
        assert np.linalg.norm(r - ref) <= best + 1e-12
    assert np.linalg.norm(nearest_rotvec(np.eye(3), np.array([0, 0, 6.2])) - [0, 0, 2 * math.pi]) < 1e-12


# ------------------------------------------------------------ identifiability
@requires_cpu
def test_identifiability_warning_names_tracker_redundant_with_first_joint_offset():
    robot = jwarp.robot("justin19")
    meas = _cartesian(robot)
    rng = np.random.default_rng(6)
    q = _q(robot, 20, rng)
    y = meas.predict(model_frames(robot, q), meas.params.nominal) + rng.normal(0, 1e-4, (20, 6))
    with pytest.warns(CalibrationWarning, match=r"not identifiable.*torso_1\.theta"):
        res = calibrate(robot, meas, q, y, free="theta,tracker", frames=["torso_1", "right_1"])
    (d,) = [d for d in res.unidentifiable if d.parameters[0][0] == "torso_1.theta"]
    assert d.eigenvalue < 1e-4          # numerically zero (well-determined ones are > 1e3)
    assert any(n.startswith("tracker_") for n, _ in d.parameters)
    # the flat direction is held by the prior: the offset stays near nominal
    assert abs(res.value("torso_1.theta")) < 1e-3


@requires_cpu
def test_identifiability_warning_for_d_of_consecutive_parallel_axes():
    robot = jwarp.robot("justin19")
    meas = FramePositions(robot, ["right_tcp", "left_tcp"])
    rng = np.random.default_rng(7)
    q = _q(robot, 20, rng)
    y = meas.predict(model_frames(robot, q), np.zeros(0))
    with pytest.warns(CalibrationWarning, match="not identifiable"):
        res = calibrate(robot, meas, q, y, free="d", frames=["torso_3", "torso_4"])
    assert len(res.unidentifiable) == 1
    names = {n for n, _ in res.unidentifiable[0].parameters}
    assert names == {"torso_3.d", "torso_4.d"}
    # no warning where the data determine everything
    with warnings.catch_warnings():
        warnings.simplefilter("error", CalibrationWarning)
        ok = calibrate(robot, meas, q, y, free="d", frames=["torso_3", "right_3"])
    assert ok.unidentifiable == [] and ok.warnings == []


@requires_cpu
def test_moved_parameters_are_reported():
    robot = jwarp.robot("arm7")
    truth = robot.with_dh(robot.dh_table + np.where(np.arange(robot.n_frames)[:, None] == 3,
                                                    [0, 0.03, 0, 0, 0], 0.0))
    meas = FramePositions(robot, ["right_tcp"])
    rng = np.random.default_rng(8)
    q = _q(robot, 20, rng)
    y = meas.predict(model_frames(truth, q), np.zeros(0))
    with pytest.warns(CalibrationWarning, match="moved"):
        res = calibrate(robot, meas, q, y, free="theta", sigma={"theta": 0.005})
    name = f"{robot.frames[3].name}.theta"
    assert name in dict(res.moved) and dict(res.moved)[name] > 3
    assert res.value(name) == pytest.approx(robot.dh_table[3, 1] + 0.03, abs=1e-4)  # MAP: prior pulls a little


# ---------------------------------------------------------------- results
@requires_cpu
def test_result_robot_saves_and_loads_and_errors_match_numpy(tmp_path):
    robot = jwarp.robot("arm7")
    meas = FramePositions(robot, ["right_tcp"])
    rng = np.random.default_rng(9)
    truth = perturb_robot(robot, rng, groups="theta", kappa=(KAPPA, 2 * KAPPA),
                          kappa_groups="kappa_theta")
    q = _q(robot, 25, rng)
    y = meas.predict(model_frames(truth, q), np.zeros(0))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", CalibrationWarning)
        res = calibrate(robot, meas, q, y, free="theta,kappa_theta", noise_sigma=1e-4)
    path = tmp_path / "calibrated.json"
    res.robot.save(path)
    loaded = jwarp.robot(str(path))
    np.testing.assert_allclose(loaded.dh_table, res.robot.dh_table)
    np.testing.assert_allclose(loaded.kappa, res.robot.kappa)
    assert np.any(loaded.kappa[:, 2] > 0)
    # errors(): norm of (elastic prediction - y) per frame, against plain numpy
    e = errors(loaded, meas, np.zeros(0), q, y)
    fr = jwarp.fk_elastic(loaded, q, loaded.kappa, max_iter=100, tol=1e-13, device="cpu").frames
    ref = np.linalg.norm(fr[:, 8, :3, 3] - y, axis=1)[:, None]
    np.testing.assert_allclose(e, ref, atol=1e-12)
    np.testing.assert_allclose(e, res.errors, atol=1e-9)
    np.testing.assert_allclose(predict(loaded, meas, np.zeros(0), q), fr[:, 8, :3, 3], atol=1e-12)
    st = error_stats([[1.0, 2.0], [3.0, 6.0]])
    assert st == {"mean": 3.0, "std": pytest.approx(np.std([1, 2, 3, 6])), "max": 6.0}
    doc = json.loads(json.dumps(res.to_dict()))
    assert doc["errors"]["mean"] == pytest.approx(error_stats(res.errors)["mean"])
    assert [p["name"] for p in doc["parameters"]] == res.names
    assert "parameter" in res.table()


def test_observation_groups():
    robot = jwarp.robot("justin19")
    groups = observation_groups(_cartesian(robot))
    assert [n for n, _ in groups] == ["right", "left"]
    assert [ix.tolist() for _, ix in groups] == [[0, 1, 2], [3, 4, 5]]

    class Dist:
        obs_names = ["distance"]
    assert [(n, ix.tolist()) for n, ix in observation_groups(Dist())] == [("distance", [0])]


def test_parameter_space_pack_unpack_and_robot_at():
    robot = jwarp.robot("justin19")
    meas = _cartesian(robot)
    chain = {i for f in meas.frames for i in robot.ancestors(f) if robot.is_dh[i]}
    # rigid: the DH frames on the measured chains only
    rigid = ParameterSpace.build(robot, meas, "alpha")
    assert set(rigid.frame) == chain and "head_1.alpha" not in rigid.names
    # elastic: plus the head, whose weight loads the torso
    sp = ParameterSpace.build(robot, meas, "alpha,kappa_alpha,markers", sigma={"alpha": 0.01})
    used = chain | {robot.frame_index("head_1"), robot.frame_index("head_2")}
    assert sp.size == 2 * len(used) + 6
    assert sp.names[0] == "torso_1.alpha" and "right_7.kappa_alpha" in sp.names
    assert "head_2.kappa_alpha" in sp.names
    assert np.all(sp.sigma[:len(used)] == 0.01)
    np.testing.assert_array_equal(sp.sigma[-6:], meas.params.sigma[6:])
    x = sp.nominal + np.arange(sp.size) * 1e-5
    dh, kap, p, mass = sp.unpack(x)
    np.testing.assert_allclose(sp.pack(dh, kap, p, mass), x)
    np.testing.assert_array_equal(mass, [m.mass for m in robot.masses])   # mass not free
    assert np.all(p[:6] == meas.params.nominal[:6])          # tracker not free: nominal
    rob = sp.robot_at(x)
    np.testing.assert_allclose(rob.dh_table, dh)
    np.testing.assert_allclose(rob.kappa, kap)
    assert not np.any(kap[~robot.is_dh])


# ------------------------------------------------------------------- masses
def _extra_mass(robot, frame="right_7", mass=0.4, com=(0.02, -0.01, 0.05)):
    """robot with a second point mass on ``frame`` (names become <frame>.mass0/.mass1)."""
    doc = robot.to_dict()
    doc["masses"].append({"frame": robot.frame_index(frame), "mass": mass, "com": list(com)})
    return jwarp.RobotModel.from_dict(doc)


def _elastic(robot, kappa, axes=(0, 2), seed=0):
    """robot with compliances U(0.5, 1.5) * kappa on ``axes`` of every DH frame."""
    rng = np.random.default_rng(seed)
    kap = np.zeros((robot.n_frames, 3))
    kap[:, list(axes)] = rng.uniform(0.5 * kappa, 1.5 * kappa, (robot.n_frames, len(axes)))
    return robot.with_dh(robot.dh_table, kappa=kap * robot.is_dh[:, None])


def _masses(robot):
    return np.array([m.mass for m in robot.masses])


def test_mass_torques_are_linear_in_the_masses_and_match_the_kernel(device):
    """d tau / d m against the Warp torque kernel of robots with other masses (tau is
    linear in the masses at fixed frames), two entries on one frame included."""
    robot = _extra_mass(jwarp.robot("justin19"))
    rng = np.random.default_rng(13)
    S = 3
    q, rho, frames, st = _torque_state(robot, rng, S, device)
    D = E.mass_torque_jacobian(robot, frames, st, np.arange(len(robot.masses)))
    assert D.shape == (S, robot.n_frames, 3, len(robot.masses))
    m = _masses(robot) * rng.uniform(0.5, 1.5, len(robot.masses))
    other = robot.with_masses(m)
    tk = jwarp.gravity_torques(other, q, dh=rho, device=device)
    np.testing.assert_allclose(np.einsum("snkp,p->snk", D, m), tk, rtol=1e-9,
                               atol=1e-9 * np.abs(tk).max())
    # one unit mass: only the frames above it feel it
    e = len(robot.masses) - 1                       # the extra entry on right_7
    unit = robot.with_masses(np.eye(len(robot.masses))[e])
    tu = jwarp.gravity_torques(unit, q, dh=rho, device=device)
    np.testing.assert_allclose(D[..., e], tu, atol=1e-12)
    assert np.abs(D[:, robot.frame_index("left_2"), :, e]).max() == 0
    assert np.abs(D[:, robot.frame_index("right_2"), :, e]).max() > 1
    # the per-entry values override the robot's own in torque_state
    st2 = E.torque_state(robot, frames, rho, E.frame_masses(robot, m))
    np.testing.assert_allclose(st2.tau, tk, rtol=1e-9, atol=1e-9 * np.abs(tk).max())


@requires_cpu
def test_mass_residual_jacobian_matches_finite_differences():
    """mass columns through the implicit function theorem, with theta and free compliances
    on the tree-shaped justin19 (two entries on right_7)."""
    robot = _extra_mass(jwarp.robot("justin19"))
    meas = FramePositions(robot, ["right_tcp", "left_tcp"])
    rng = np.random.default_rng(14)
    S = 15
    q = _q(robot, S, rng)
    y = rng.normal(0, 0.3, (S, 6))
    prob = CalibrationProblem(robot, meas, q, y,
                              problem_options(noise_sigma=1e-4, tol=1e-15, max_iter=300,
                                              free="theta,kappa_theta,kappa_alpha,mass"))
    sp = prob.space
    masses = [n for n in sp.names if ".mass" in n]
    assert len(masses) == len(robot.masses) == 22        # the root torso_1 carries everything
    assert "right_7.mass0" in masses and "right_7.mass1" in masses and "head_2.mass" in masses
    x = _assert_jacobian_matches_fd(prob, rng, col_rtol=5e-6)
    # the masses of x reach the equilibrium: predictions change with them
    xm = x.copy()
    xm[sp.index("right_tcp.mass")] *= 1.5
    assert np.abs(prob.predict(xm) - prob.predict(x)).max() > 1e-5


def test_mass_group_selection_names_bounds_and_calibrated_robot():
    nominal = jwarp.robot("justin19")
    meas = FramePositions(nominal, ["right_tcp"])
    right = [i for i in range(nominal.n_frames) if nominal.frames[i].name.startswith("right_")]
    # compliance only in the right arm: the masses hanging below its compliant frames
    kap = np.zeros((nominal.n_frames, 3))
    kap[right, 2] = KAPPA
    robot = nominal.with_dh(nominal.dh_table, kappa=kap * nominal.is_dh[:, None])
    sp = ParameterSpace.build(robot, meas, "mass,theta")
    arm = [f"right_{k}.mass" for k in range(1, 8)] + ["right_tcp.mass"]
    assert [n for n in sp.names if n.endswith(".mass")] == arm
    i = sp.index("right_4.mass")
    m0 = robot.masses[sp.column[i]].mass
    assert sp.nominal[i] == m0 and sp.sigma[i] == pytest.approx(0.1 * m0)   # relative prior
    assert sp.lower[i] == 0 and np.all(sp.lower[sp.kind == 0] == -np.inf)
    # a free kappa group makes the whole chain compliant: torso, left arm and head load it
    sp_k = ParameterSpace.build(nominal, meas, "kappa_alpha,mass", sigma={"mass": 0.2})
    assert sum(n.endswith(".mass") for n in sp_k.names) == len(nominal.masses)
    j = sp_k.index("head_2.mass")
    assert sp_k.sigma[j] == pytest.approx(0.2 * 3.0)
    # pack / unpack / robot_at carry the masses
    x = sp.nominal.copy()
    x[sp.kind == 3] *= 1.2
    dh, kp, p, mass = sp.unpack(x)
    np.testing.assert_allclose(sp.pack(dh, kp, p, mass), x)
    assert mass[sp.column[i]] == pytest.approx(1.2 * m0)
    assert nominal.frames[nominal.masses[-1].frame].name == "head_2"
    assert mass[-1] == nominal.masses[-1].mass                     # not free: nominal
    cal = sp.robot_at(x)
    np.testing.assert_allclose(_masses(cal), mass)
    np.testing.assert_allclose(cal.kappa, robot.kappa)
    assert _masses(robot)[sp.column[i]] == m0                     # the nominal is untouched
    # with_masses validates
    with pytest.raises(ValueError, match=r"masses: expected shape \(21,\)"):
        robot.with_masses(np.ones(3))
    with pytest.raises(ValueError, match=r"masses\[2\]: must be finite and >= 0"):
        robot.with_masses(np.where(np.arange(21) == 2, -1.0, 1.0))
    # bad input names `free`
    massless = robot.copy(masses=[])
    with pytest.raises(ValueError, match="free: group 'mass' selects nothing: robot 'justin19' "
                                         "has no point masses"):
        ParameterSpace.build(massless, FramePositions(massless, ["right_tcp"]), "theta,mass")
    with pytest.raises(ValueError, match="free: group 'mass' selects no masses.*compliant"):
        ParameterSpace.build(nominal, meas, "mass")              # rigid robot
    with pytest.raises(ValueError, match="free: group 'mass' selects no masses.*compliant"):
        ParameterSpace.build(robot, FramePositions(robot, ["left_tcp"]), "mass")  # rigid chain
    rng = np.random.default_rng(15)
    q = _q(robot, 10, rng)
    with pytest.raises(ValueError, match="free: the 'mass' group acts only through the elastic"):
        CalibrationProblem(robot, meas, q, np.zeros((10, 3)),
                           problem_options(free="mass", elastic=False))
    with pytest.raises(ValueError, match=r"sigma\['mass'\]: must be > 0"):
        ParameterSpace.build(robot, meas, "mass", sigma={"mass": 0})


def test_perturb_robot_mass_error_keeps_the_other_draws():
    robot = jwarp.robot("arm7")
    a = perturb_robot(robot, np.random.default_rng(3), kappa=(KAPPA, 2 * KAPPA))
    b = perturb_robot(robot, np.random.default_rng(3), kappa=(KAPPA, 2 * KAPPA), mass_error=0.15)
    np.testing.assert_array_equal(a.dh_table, b.dh_table)
    np.testing.assert_array_equal(a.kappa, b.kappa)
    np.testing.assert_array_equal(_masses(a), _masses(robot))
    ratio = _masses(b) / _masses(robot)
    assert np.all(np.abs(ratio - 1) <= 0.15) and np.abs(ratio - 1).max() > 0.05
    c = perturb_robot(robot, np.random.default_rng(3), frames=["right_2"], mass_error=0.15)
    changed = _masses(c) != _masses(robot)
    assert changed.tolist() == [m.frame == robot.frame_index("right_2") for m in robot.masses]
    with pytest.raises(ValueError, match=r"mass_error: expected a relative error in \[0, 1\)"):
        perturb_robot(robot, np.random.default_rng(3), mass_error=1.5)


@requires_cpu
def test_mass_calibration_recovers_heavier_truth_with_known_compliance():
    """Truth: every point mass +15 %, compliances known (the nominal robot has them); only
    the masses are free. The test error drops from the model error to far below the noise
    against the noise-free truth, and the masses the data determine are recovered."""
    nominal = _elastic(jwarp.robot("arm7"), 2 * KAPPA, seed=21)
    m0 = _masses(nominal)
    truth = nominal.with_masses(1.15 * m0)
    meas = FramePositions(nominal, ["right_tcp", 5])
    noise = 1e-4
    rng = np.random.default_rng(16)
    q = _q(nominal, 160, rng)
    y_clean = meas.predict(model_frames(truth, q), np.zeros(0))
    y = y_clean + rng.normal(0, noise, y_clean.shape)
    tr, te = slice(0, 100), slice(100, None)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", CalibrationWarning)
        res = calibrate(nominal, meas, q[tr], y[tr], free="mass", noise_sigma=noise)
    assert res.success and res.elastic and len(res.names) == len(m0) == 8
    before = error_stats(errors(nominal, meas, np.zeros(0), q[te], y_clean[te]))
    after = error_stats(errors(res.robot, meas, np.zeros(0), q[te], y_clean[te]))
    assert before["mean"] > 10 * noise                   # the wrong masses: ~1 mm
    assert after["mean"] <= 0.5 * noise                   # vs the noise-free truth
    m_cal = _masses(res.robot)
    np.testing.assert_allclose(m_cal, res.x)              # calibrated robot carries them
    m_true = _masses(truth)
    determined = res.std < 0.5 * res.sigma                # data, not the prior, decide
    assert determined.sum() >= 4
    assert np.all(np.abs(m_cal - m_true)[determined] < 3 * res.std[determined])
    assert np.all(np.abs(m_cal - m_true) < 3 * res.std)   # the MAP posterior covers all
    # the best-determined one (the tcp load) lands within a few percent of the truth, and
    # the total mass error (2.2 kg) shrinks by more than half
    assert abs(res.value("right_tcp.mass") / m_true[-1] - 1) < 0.03
    assert abs(m_cal.sum() - m_true.sum()) < 0.5 * abs(m0.sum() - m_true.sum())
    # nothing else moved: DH rows and compliances are the nominal ones
    np.testing.assert_array_equal(res.robot.dh_table, nominal.dh_table)
    np.testing.assert_array_equal(res.robot.kappa, nominal.kappa)


@requires_cpu
def test_masses_and_compliances_free_together_report_their_scaling_direction():
    """All masses x c with all compliances / c predict the same: without priors the fit is
    one arbitrary point of that family and the result says so; with priors it is held."""
    robot = jwarp.robot("arm7")
    truth = _elastic(robot, 2 * KAPPA, axes=(2,), seed=22)
    meas = FramePositions(robot, ["right_tcp", 5])
    rng = np.random.default_rng(17)
    q = _q(robot, 40, rng)
    y = meas.predict(model_frames(truth, q), np.zeros(0)) + rng.normal(0, 1e-4, (40, 6))
    with pytest.warns(CalibrationWarning, match=r"masses and compliances are not separately "
                                                r"identifiable.*some of them have no prior"):
        res = calibrate(robot, meas, q, y, free="kappa_theta,mass", noise_sigma=1e-4,
                        sigma={"mass": math.inf, "kappa_theta": math.inf})
    assert error_stats(res.errors)["mean"] < 2 * 1.596 * 1e-4      # still fits the data
    # the flat direction: predictions unchanged when masses x 1.3 and compliances / 1.3
    sp = res.space
    x2 = res.x.copy()
    x2[sp.kind == 3] *= 1.3
    x2[sp.kind == 1] /= 1.3
    prob = CalibrationProblem(robot, meas, q, y,
                              problem_options(free="kappa_theta,mass", noise_sigma=1e-4,
                                              sigma={"mass": math.inf, "kappa_theta": math.inf}))
    np.testing.assert_allclose(prob.predict(x2), prob.predict(res.x), atol=1e-12)
    with pytest.warns(CalibrationWarning, match="not separately identifiable.*held by the priors"):
        held = calibrate(robot, meas, q, y, free="kappa_theta,mass", noise_sigma=1e-4)
    assert np.all(np.isfinite(held.std))
    assert np.all(np.abs(held.x - held.nominal)[sp.kind == 3] < 3 * held.sigma[sp.kind == 3])
    # masses alone (compliances known) are no such case
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        calibrate(truth, meas, q, y, free="mass", noise_sigma=1e-4)
    assert not any("separately identifiable" in str(w.message) for w in caught)


# -------------------------------------------------------------- validation
def test_input_validation_names_the_argument():
    robot = jwarp.robot("justin19")
    meas = _cartesian(robot)
    rng = np.random.default_rng(10)
    q = _q(robot, 30, rng)
    y = rng.normal(size=(30, 6))
    with pytest.raises(ValueError, match=r"free: unknown parameter group\(s\) \['gamma'\].*"
                                         r"theta.*kappa_theta.*tracker, markers"):
        calibrate(robot, meas, q, y, free="theta,gamma")
    with pytest.raises(ValueError, match=r"2 samples x 6 observations = 12 .* fewer than the "
                                         r"\d+ free parameters"):
        calibrate(robot, meas, q[:2], y[:2], free="theta,tracker")
    with pytest.raises(ValueError, match=r"q: expected shape \(S, 19\)"):
        calibrate(robot, meas, q[:, :5], y, free="theta")
    qn = q.copy()
    qn[4, 3] = np.nan
    with pytest.raises(ValueError, match=r"q: NaN or inf in sample\(s\) \[4\]"):
        calibrate(robot, meas, qn, y, free="theta")
    with pytest.raises(ValueError, match=r"y: expected shape \(30, 6\)"):
        calibrate(robot, meas, q, y[:, :3], free="theta")
    yn = y.copy()
    yn[7, 0] = np.inf
    with pytest.raises(ValueError, match=r"y: NaN or inf in sample\(s\) \[7\]"):
        calibrate(robot, meas, q, yn, free="theta")
    with pytest.raises(ValueError, match="free: no parameter group"):
        calibrate(robot, meas, q, y, free=" , ")
    with pytest.raises(ValueError, match="sigma\\['theta'\\]: must be > 0"):
        calibrate(robot, meas, q, y, free="theta", sigma={"theta": -1})
    with pytest.raises(ValueError, match="sigma: unknown parameter group 'thet'"):
        calibrate(robot, meas, q, y, free="theta", sigma={"thet": 1})
    with pytest.raises(ValueError, match="n_starts"):
        calibrate(robot, meas, q, y, free="theta", n_starts=0)
    with pytest.raises(ValueError, match="noise_sigma"):
        calibrate(robot, meas, q, y, free="theta", noise_sigma=[1e-3, 1e-3])
    with pytest.raises(ValueError, match="frames: frame 'right_tcp' is static"):
        calibrate(robot, meas, q, y, free="theta", frames=["right_tcp"])
    with pytest.raises(ValueError, match="x0: expected shape"):
        calibrate(robot, meas, q, y, free="theta", x0=np.zeros(3))


@requires_cpu
def test_benchmark_script_quick_run():
    proc = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_calibration.py"),
                           "--samples", "40", "--test", "20", "--quick",
                           "--free", "theta,d,kappa_theta,tracker,markers"],
                          cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "full calibration:" in proc.stdout and "after test" in proc.stdout
