"""The kinematics kernels honour ``coupling_harmonic`` (issue 29): the joint value of a
coupled frame is ``u + sum_k a_k sin(k u) + b_k cos(k u)``, ``u = sum_j c_j q_j``.

References: the numpy FK of tests/reference.py with the coupled frame's theta shifted per
configuration by a numpy harmonic sum (checked against ``RobotModel.coupled_frame_delta``),
central finite differences of that FK for the Jacobians, and the calibration's per-sample
DH rows for the elastic model."""

import numpy as np
import pytest
from reference import central_difference_grad, ref_fk
from scipy.spatial.transform import Rotation

import jwarp
from jwarp import kinematics as K
from jwarp.calibration.estimate.result import model_frames
from jwarp.core.limits import sample_within_limits
from jwarp.solvers import ik as IK
from jwarp.world import collision

#: (K = 2, 2) [a_k, b_k] of torso_4 [rad]: a few mrad
H = np.array([[4.0e-3, -3.0e-3], [2.5e-3, 5.0e-3]])


def _robot():
    base = jwarp.robot("justin19")
    ch = np.zeros((base.n_frames, 2, 2))
    ch[base.frame_index("torso_4")] = H
    return base, base.copy(coupling_harmonic=ch)


def _sample(model, n, seed):
    q = sample_within_limits(model, n, np.random.default_rng(seed))
    return q


def _delta(model, q):
    """(B, n_frames) numpy harmonic sum of each frame at q (independent of the model's)."""
    i = model.frame_index("torso_4")
    u = sum(c * q[:, j] for j, c in model.frames[i].coupling)
    d = np.zeros((len(q), model.n_frames))
    d[:, i] = sum(H[k, 0] * np.sin((k + 1) * u) + H[k, 1] * np.cos((k + 1) * u)
                  for k in range(len(H)))
    return d


def _ref_fk(base, q):
    """numpy FK of the robot with harmonics: theta of torso_4 shifted per configuration."""
    dh = np.broadcast_to(base.dh_table, (len(q),) + base.dh_table.shape).copy()
    dh[:, :, 1] += _delta(base, q)
    return ref_fk(base, q, dh=dh)


def test_delta_matches_model_definition():
    base, robot = _robot()
    q = _sample(base, 16, 0)
    np.testing.assert_allclose(robot.coupled_frame_delta(q), _delta(base, q), atol=1e-15)
    assert robot.has_coupling_harmonic and not base.has_coupling_harmonic


def test_fk_matches_numpy_reference(device):
    base, robot = _robot()
    q = _sample(base, 200, 1)
    ref = _ref_fk(base, q)
    got = K.fk(robot, q, device=device, dtype=np.float64)
    np.testing.assert_allclose(got, ref, atol=1e-12, rtol=0)
    got32 = K.fk(robot, q.astype(np.float32), device=device, dtype=np.float32)
    np.testing.assert_allclose(got32, ref, atol=2e-5, rtol=0)
    # the effect is there: the torso and hands move by about the harmonic amplitude
    tcp = base.frame_index("right_tcp")
    moved = np.linalg.norm(got[:, tcp, :3, 3] - K.fk(base, q, device=device, dtype=np.float64)
                           [:, tcp, :3, 3], axis=-1)
    assert moved.max() > 2e-3


def _fd_jacobian(base, q, frame, eps=1e-6):
    """(B, 6, n_dof) central differences of the numpy FK: [linear; angular]."""
    B, n = q.shape
    J = np.zeros((B, 6, n))
    for j in range(n):
        e = np.zeros(n)
        e[j] = eps
        Fp = _ref_fk(base, q + e)[:, frame]
        Fm = _ref_fk(base, q - e)[:, frame]
        J[:, :3, j] = (Fp[:, :3, 3] - Fm[:, :3, 3]) / (2 * eps)
        dR = Fp[:, :3, :3] @ np.swapaxes(Fm[:, :3, :3], -1, -2)
        J[:, 3:, j] = Rotation.from_matrix(dR).as_rotvec() / (2 * eps)
    return J


@pytest.mark.parametrize("frame", ["right_tcp", "torso_4"])
def test_jacobian_matches_finite_differences(device, frame):
    base, robot = _robot()
    q = _sample(base, 6, 2)
    fi = base.frame_index(frame)
    fd = _fd_jacobian(base, q, fi)
    got = K.jacobian(robot, q, frame, device=device, dtype=np.float64)
    scale = np.abs(fd).max()
    np.testing.assert_allclose(got, fd, atol=1e-6 * scale, rtol=0)
    # without the chain-rule factor the torso columns would differ by ~h'(u)
    plain = K.jacobian(base, q, frame, device=device, dtype=np.float64)
    assert np.abs(got - plain)[:, :, 1:3].max() > 1e-3 * scale


def test_elastic_fk_matches_per_sample_rows(device):
    """fk_elastic of the robot with harmonics = fk_elastic of the robot without them at the
    per-configuration DH rows that carry the shift (the calibration's model)."""
    base, robot = _robot()
    q = _sample(base, 20, 3)
    kappa = K.kappa_array(base, None)
    if not np.any(kappa):
        kappa = np.zeros((base.n_frames, 3))
        kappa[base.is_dh.astype(bool)] = 2e-4
    dh = np.broadcast_to(base.dh_table, (len(q),) + base.dh_table.shape).copy()
    dh[:, :, 1] += _delta(base, q)
    opt = dict(tol=1e-13, max_iter=200, device=device, dtype=np.float64)
    ref = K.fk_elastic(base, q, kappa, dh=dh, **opt).frames
    got = K.fk_elastic(robot, q, kappa, **opt).frames
    np.testing.assert_allclose(np.asarray(got), np.asarray(ref), atol=1e-12)
    rigid = K.fk_elastic(base, q, kappa, device=device, dtype=np.float64).frames
    assert np.abs(np.asarray(got) - np.asarray(rigid)).max() > 1e-3
    # the calibration's host path (rows from coupled_frame_delta) gives the same frames
    if device == "cpu":
        np.testing.assert_allclose(model_frames(robot, q, kappa=kappa, elastic=True, tol=1e-13,
                                                max_iter=200),
                                   np.asarray(got), atol=1e-12)
        np.testing.assert_allclose(model_frames(robot, q, elastic=False), _ref_fk(base, q),
                                   atol=1e-12)


def test_without_harmonics_unchanged(device):
    """A robot whose coupling_harmonic is all zero (K = 2) or absent (K = 0) gives the
    very same frames and Jacobians as the numpy reference of the plain robot."""
    base, _ = _robot()
    zero = base.copy(coupling_harmonic=np.zeros((base.n_frames, 2, 2)))
    q = _sample(base, 50, 4)
    for dt in (np.float32, np.float64):
        a = K.fk(base, q.astype(dt), device=device, dtype=dt)
        b = K.fk(zero, q.astype(dt), device=device, dtype=dt)
        assert np.array_equal(a, b)
        ja = K.jacobian(base, q.astype(dt), "right_tcp", device=device, dtype=dt)
        jb = K.jacobian(zero, q.astype(dt), "right_tcp", device=device, dtype=dt)
        assert np.array_equal(ja, jb)
    np.testing.assert_allclose(K.fk(base, q, device=device, dtype=np.float64), ref_fk(base, q),
                               atol=1e-12)


def test_round_trip_keeps_coupling_harmonic(tmp_path):
    _, robot = _robot()
    path = tmp_path / "r.json"
    robot.save(path)
    back = jwarp.robot(str(path))
    np.testing.assert_array_equal(back.coupling_harmonic[:, :2], robot.coupling_harmonic)
    q = _sample(robot, 5, 5)
    np.testing.assert_array_equal(K.fk(back, q, device="cpu", dtype=np.float64),
                                  K.fk(robot, q, device="cpu", dtype=np.float64))


def test_ik_objective_gradient_and_ik_reach_targets(device):
    base, robot = _robot()
    rng = np.random.default_rng(6)
    qt = sample_within_limits(robot, 8, rng)
    qt = qt[collision.is_collision_free(robot, qt, device=device)][:3]
    assert len(qt) == 3
    fi = robot.frame_index("right_tcp")
    T = _ref_fk(base, qt)[:, fi]
    # analytic gradient of the IK objective (pose error + collision) vs finite differences
    obj = IK.IKObjective(robot, "right_tcp", 3, weights=IK.IKWeights(default=0.0),
                         device=device, dtype=np.float64)
    q = qt + rng.normal(0, 0.05, qt.shape)
    u, g = obj.value_and_grad(q, T)
    fd = central_difference_grad(lambda x: obj.value_and_grad(x, T)[0], q)
    np.testing.assert_allclose(g, fd, rtol=1e-5, atol=1e-7)
    # IK converges on the robot with harmonics, to the targets of its numpy FK
    res = IK.ik(robot, "right_tcp", T, n_starts=8, seed=2, device=device)
    assert res.feasible.all() and np.all(res.pos_err < 1e-4) and np.all(res.rot_err < 1e-3)
    F = _ref_fk(base, res.q)[:, fi]
    assert np.all(np.linalg.norm(F[:, :3, 3] - T[:, :3, 3], axis=-1) < 1e-4)


def _with_transmission(base, robot):
    """The robot with transmission errors on the torso joints that drive torso_4, too."""
    hj = np.zeros((base.n_dof, 1, 2))
    for j, _ in base.frames[base.frame_index("torso_4")].coupling:
        hj[j, 0] = [8.0e-3, -6.0e-3]
    return robot.copy(harmonic=hj)


def _ref_fk_both(base, both, q):
    """numpy FK of a robot with transmission errors and coupled-frame harmonics: the links
    see q' = q + dq(q) (numpy); torso_4's terms are of the commanded q."""
    q_link = q + both.harmonic[:, 0, 0] * np.sin(q) + both.harmonic[:, 0, 1] * np.cos(q)
    dh = np.broadcast_to(base.dh_table, (len(q),) + base.dh_table.shape).copy()
    dh[:, :, 1] += _delta(base, q)
    return ref_fk(base, q_link, dh=dh)


def test_with_transmission_errors_fk_and_jacobian(device):
    """With transmission errors on the coupled joints as well, the harmonic terms are of
    the commanded joint values (``coupled_frame_delta``), the rest of the links' values."""
    base, robot = _robot()
    both = _with_transmission(base, robot)
    q = _sample(base, 8, 7)
    ref = _ref_fk_both(base, both, q)
    np.testing.assert_allclose(K.fk(both, q, device=device, dtype=np.float64), ref, atol=1e-12)
    i = base.frame_index("torso_4")
    dh = np.broadcast_to(base.dh_table, (len(q),) + base.dh_table.shape).copy()
    dh[:, :, 1] += both.coupled_frame_delta(q)
    np.testing.assert_allclose(ref[:, i], ref_fk(base, both.joint_transmission(q), dh=dh)[:, i],
                               atol=1e-14)
    np.testing.assert_allclose(K.fk(both, q.astype(np.float32), device=device,
                                    dtype=np.float32), ref, atol=2e-5)
    fi = base.frame_index("right_tcp")
    eps = 1e-6
    fd = np.zeros((len(q), 6, base.n_dof))
    for j in range(base.n_dof):
        e = np.zeros(base.n_dof)
        e[j] = eps
        Fp, Fm = _ref_fk_both(base, both, q + e)[:, fi], _ref_fk_both(base, both, q - e)[:, fi]
        fd[:, :3, j] = (Fp[:, :3, 3] - Fm[:, :3, 3]) / (2 * eps)
        fd[:, 3:, j] = Rotation.from_matrix(Fp[:, :3, :3] @ np.swapaxes(Fm[:, :3, :3], -1, -2)
                                            ).as_rotvec() / (2 * eps)
    got = K.jacobian(both, q, "right_tcp", device=device, dtype=np.float64)
    np.testing.assert_allclose(got, fd, atol=1e-6 * np.abs(fd).max(), rtol=0)
    # elastic FK: the robot's kernels against the per-sample rows of the plain robot
    kappa = 2e-4
    opt = dict(tol=1e-13, max_iter=200, device=device, dtype=np.float64)
    ref_el = K.fk_elastic(base, both.joint_transmission(q), kappa, dh=dh, **opt).frames
    np.testing.assert_allclose(np.asarray(K.fk_elastic(both, q, kappa, **opt).frames),
                               np.asarray(ref_el), atol=1e-12)


def test_ik_with_transmission_errors(device):
    base, robot = _robot()
    both = _with_transmission(base, robot)
    rng = np.random.default_rng(8)
    qt = sample_within_limits(both, 8, rng)
    qt = qt[collision.is_collision_free(both, qt, device=device)][:3]
    fi = base.frame_index("right_tcp")
    T = _ref_fk_both(base, both, qt)[:, fi]
    res = IK.ik(both, "right_tcp", T, n_starts=8, seed=3, device=device)
    assert res.feasible.all() and np.all(res.pos_err < 1e-4) and np.all(res.rot_err < 1e-3)
    F = _ref_fk_both(base, both, res.q)[:, fi]
    assert np.all(np.linalg.norm(F[:, :3, 3] - T[:, :3, 3], axis=-1) < 1e-4)
