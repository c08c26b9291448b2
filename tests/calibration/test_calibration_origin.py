"""The ``origin`` calibration group (a 6-parameter pose error per joint origin): analytic
Jacobian against central differences, selection and errors, recovery of perturbed origins
from simulated cartesian data, and the URDF export of the calibrated robot (pinocchio FK)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from devices import requires_cpu

import jwarp
from jwarp.calibration import CalibrationProblem, ParameterSpace, calibrate
from jwarp.calibration.estimate.map import problem_options
from jwarp.calibration.estimate.origin import (
    delta_transform,
    left_jacobian,
    rotation,
    with_static_transforms,
)
from jwarp.calibration.estimate.params import KIND_ORIGIN
from jwarp.importers.urdf_export import dh_origin, export_urdf
from jwarp.plugins.measurements.cartesian import CartesianMeasurement

pytestmark = requires_cpu


def origin_arm(base_offset=(0.0, 0.0, 0.0)):
    """arm7 in the layout of an imported URDF: per joint a static frame ``<joint>_origin``
    (the fixed part of its DH transform) and a DH frame with zero DH rows driven by it."""
    src = jwarp.robot("arm7")
    names = src.frame_names
    frames = []
    for f in src.frames:
        parent = None if f.parent is None else names[f.parent]
        if f.kind == "static":
            T = np.array(f.transform)
            if f.parent is None:
                T[:3, 3] += base_offset
            frames.append({"name": f.name, "parent": parent, "kind": "static",
                           "transform": T.tolist()})
            continue
        frames.append({"name": f.name + "_origin", "parent": parent, "kind": "static",
                       "transform": dh_origin(f.dh).tolist()})
        d = {"name": f.name, "parent": f.name + "_origin", "kind": "dh", "dh": [0.0] * 5}
        d["joint"] = src.joint_names[f.coupling[0][0]]
        frames.append(d)
    doc = {"name": "arm7_origins", "joints": [{"name": j.name, "type": j.type,
                                               "limits": [j.lower, j.upper]} for j in src.joints],
           "frames": frames, "end_effectors": {"tcp": "right_tcp"}}
    return jwarp.RobotModel.from_dict(doc)


def cartesian(robot, noise=1e-5):
    return CartesianMeasurement(robot, {
        "plugin": "cartesian",
        "tracker": {"position": [2.5, 0.3, 0.8], "rotvec": [0.1, -0.2, 2.4]},
        "markers": [{"name": "m", "frame": "right_tcp", "position": [0.02, 0.01, 0.05],
                     "sigma": 0.01}],
        "noise": noise})


def random_q(robot, n, seed):
    lim = robot.joint_limits
    return np.random.default_rng(seed).uniform(lim[:, 0], lim[:, 1], (n, robot.n_dof))


def test_same_fk_as_arm7():
    q = random_q(jwarp.robot("arm7"), 50, 0)
    a = jwarp.fk("arm7", q, device="cpu", dtype=np.float64)
    robot = origin_arm()
    b = jwarp.fk(robot, q, device="cpu", dtype=np.float64)
    for name in jwarp.robot("arm7").frame_names:
        i, j = jwarp.robot("arm7").frame_index(name), robot.frame_index(name)
        assert np.abs(np.asarray(a)[:, i] - np.asarray(b)[:, j]).max() < 1e-12


def test_so3_helpers_against_differences():
    rng = np.random.default_rng(1)
    for w in [np.zeros(3), 1e-8 * rng.standard_normal(3), rng.standard_normal(3)]:
        R = rotation(w)
        assert np.allclose(R @ R.T, np.eye(3), atol=1e-15)
        for k in range(3):
            h = 1e-6
            e = np.eye(3)[k]
            dR = (rotation(w + h * e) - rotation(w - h * e)) / (2 * h)
            W = dR @ R.T                               # [J_l e_k]x
            assert np.allclose([W[2, 1], W[0, 2], W[1, 0]], left_jacobian(w)[:, k], atol=1e-9)


def test_space_selects_joint_origins():
    robot = origin_arm()
    meas = cartesian(robot)
    sp = ParameterSpace.build(robot, meas, "origin")
    frames = sorted(set(sp.frame.tolist()))
    assert [robot.frame_names[i] for i in frames] == [f"right_{k}_origin" for k in range(1, 8)]
    assert sp.names[:6] == [f"right_1_origin.origin_{a}" for a in ("x", "y", "z", "rx", "ry", "rz")]
    assert np.all(sp.sigma == 1e-3) and np.all(sp.nominal == 0)
    # any static frame by name with frames=
    sp2 = ParameterSpace.build(robot, meas, "origin", frames=["right_base", "right_tcp"])
    assert sorted(set(sp2.frame.tolist())) == [robot.frame_index("right_base"),
                                              robot.frame_index("right_tcp")]
    with pytest.raises(ValueError, match="static; only DH frames"):
        ParameterSpace.build(robot, meas, "theta", frames=["right_base"])
    arm7 = jwarp.robot("arm7")     # DH robot: its base frame is the one joint origin
    sp3 = ParameterSpace.build(arm7, cartesian(arm7), "origin")
    assert set(sp3.frame.tolist()) == {arm7.frame_index("right_base")}
    doc = arm7.to_dict()                # without a static base frame: nothing to select
    doc["frames"][1]["parent"] = None
    doc["frames"] = doc["frames"][1:]
    for f in doc["frames"]:
        if isinstance(f["parent"], int):
            f["parent"] -= 1
        if "joint" in f:
            pass
    doc.update(masses=[], spheres=[], self_collision={}, end_effectors={})
    bare = jwarp.RobotModel.from_dict(doc)
    with pytest.raises(ValueError, match="group 'origin' selects no frames"):
        ParameterSpace.build(bare, cartesian(bare), "origin")


def test_origin_group_with_the_elastic_model_matches_central_differences():
    """The origin group on a compliant robot (issue 29): the columns include the shift of
    the torque equilibrium (leaving it out is visibly wrong), against central differences."""
    robot = origin_arm()
    kappa = np.zeros((robot.n_frames, 3))
    kappa[robot.is_dh, 2] = 3e-4
    doc = robot.to_dict()
    doc["masses"] = [{"frame": i, "mass": 2.0, "com": [0.01, 0.0, 0.05]}
                     for i in np.nonzero(robot.is_dh)[0].tolist()]
    doc["kappa"] = kappa.tolist()
    soft = jwarp.RobotModel.from_dict(doc)
    meas = cartesian(soft)
    q = random_q(soft, 20, 2)
    y = np.random.default_rng(5).normal(0.0, 0.3, (20, 3))
    prob = CalibrationProblem(soft, meas, q, y,
                              problem_options(free="origin,kappa_theta", tol=1e-15, max_iter=300))
    assert prob.elastic
    sp = prob.space
    rng = np.random.default_rng(6)
    x = sp.nominal + 5 * sp.scale * rng.standard_normal(sp.size)
    x[sp.kind != KIND_ORIGIN] = 3e-4 * rng.uniform(0.5, 1.5, int((sp.kind != KIND_ORIGIN).sum()))
    J = prob.jacobian(x)
    org = np.nonzero(sp.kind == KIND_ORIGIN)[0]
    Jfd = np.empty((J.shape[0], org.size))
    for n, i in enumerate(org):
        h = 1e-5
        xp, xm = x.copy(), x.copy()
        xp[i] += h
        xm[i] -= h
        Jfd[:, n] = (prob.residuals(xp) - prob.residuals(xm)) / (2 * h)
    norms = np.linalg.norm(Jfd[:prob.n_data], axis=0)
    rel = np.linalg.norm(J[:, org] - Jfd, axis=0) / np.maximum(norms, 1e-6 * np.median(norms))
    assert rel.max() < 1e-6, (rel.max(), sp.names[org[int(rel.argmax())]])
    # the equilibrium's share is not negligible: the rigid model's columns differ by far
    # more than the tolerance above
    rig = CalibrationProblem(soft, meas, q, y,
                             problem_options(free="origin,kappa_theta", elastic=False))
    Jr = rig.jacobian(x)[:prob.n_data, org]
    off = np.linalg.norm(Jr - Jfd[:prob.n_data], axis=0) / norms
    assert off.max() > 1e-3


@pytest.mark.parametrize("extra", ["", ",theta,d,tracker,markers"])
def test_jacobian_matches_central_differences(extra):
    robot = origin_arm()
    meas = cartesian(robot)
    q = random_q(robot, 25, 3)
    y = meas.predict(np.asarray(jwarp.fk(robot, q, device="cpu", dtype=np.float64)),
                     meas.params.nominal)
    prob = CalibrationProblem(robot, meas, q, y, problem_options(free="origin" + extra))
    sp = prob.space
    rng = np.random.default_rng(4)
    x = sp.nominal + 20 * sp.scale * rng.standard_normal(sp.size)   # ~2 cm / 20 mrad off
    x[sp.kind != KIND_ORIGIN] = (sp.nominal + 0.3 * sp.scale * rng.standard_normal(sp.size)
                                 )[sp.kind != KIND_ORIGIN]
    J = prob.jacobian(x)
    Jfd = np.empty_like(J)
    for i in range(sp.size):
        h = 1e-5                                   # [m] or [rad]
        xp, xm = x.copy(), x.copy()
        xp[i] += h
        xm[i] -= h
        Jfd[:, i] = (prob.residuals(xp) - prob.residuals(xm)) / (2 * h)
    d = np.linalg.norm(J - Jfd, axis=0)
    norms = np.linalg.norm(Jfd[:prob.n_data], axis=0)
    assert np.all(norms[sp.kind == KIND_ORIGIN] > 0)
    rel = d / np.maximum(norms, 1e-6 * np.median(norms))
    assert rel.max() < 1e-7, (rel.max(), sp.names[int(rel.argmax())])


def test_calibrate_origins_and_export(tmp_path):
    pin = pytest.importorskip("pinocchio")
    nominal = origin_arm()
    rng = np.random.default_rng(5)
    truth_T = {}
    for i, f in enumerate(nominal.frames):
        if f.name.endswith("_origin"):
            delta = np.concatenate([2e-3 * rng.standard_normal(3), 2e-3 * rng.standard_normal(3)])
            truth_T[i] = f.transform @ delta_transform(delta)
    truth = with_static_transforms(nominal, truth_T)
    meas = cartesian(nominal)
    p = meas.params.nominal
    q = random_q(nominal, 150, 6)
    y = meas.predict(np.asarray(jwarp.fk(truth, q, device="cpu", dtype=np.float64)), p)
    y = y + 1e-5 * rng.standard_normal(y.shape)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = calibrate(nominal, meas, q, y, free="origin", warn=False)
    q_test = random_q(nominal, 200, 7)

    def tcp_error(robot):   # marker error in tracker coordinates [m] at new configurations
        pred = meas.predict(np.asarray(jwarp.fk(robot, q_test, device="cpu",
                                                dtype=np.float64)),
                            p if robot is nominal else res.params)
        ref = meas.predict(np.asarray(jwarp.fk(truth, q_test, device="cpu",
                                               dtype=np.float64)), p)
        return np.sqrt(np.mean(np.sum((pred - ref).reshape(-1, 3) ** 2, axis=1)))

    before, after = tcp_error(nominal), tcp_error(res.robot)
    assert before > 5e-3 and after < 2e-5, (before, after)
    # the calibrated robot carries the new origins, and its URDF reproduces them
    for i in truth_T:
        assert not np.array_equal(res.robot.frames[i].transform, nominal.frames[i].transform)
    path = tmp_path / "calibrated.urdf"
    assert export_urdf(res.robot, path) == []
    model = pin.buildModelFromUrdf(str(path), mimic=True)
    data = model.createData()
    qs = random_q(nominal, 1000, 8)
    F = np.asarray(jwarp.fk(res.robot, qs, device="cpu", dtype=np.float64))
    idx_q = [model.joints[model.getJointId(n)].idx_q for n in res.robot.joint_names]
    fids = [model.getFrameId(n, pin.BODY) for n in res.robot.frame_names]
    err = 0.0
    for b, qb in enumerate(qs):
        qp = pin.neutral(model)
        qp[idx_q] = qb
        pin.framesForwardKinematics(model, data, qp)
        for k, f in enumerate(fids):
            err = max(err, np.abs(data.oMf[f].homogeneous - F[b, k]).max())
    assert err < 1e-9, err
