"""URDF export against pinocchio (an independent URDF parser and FK) at 1000 random
configurations: every jwarp frame is a URDF link of the same name, every jwarp joint a
URDF joint of the same name; coupled frames are mimic joints (pinocchio >= 3 reads them)."""

from __future__ import annotations

import math
import os
import xml.etree.ElementTree as ET

import numpy as np
import pytest

import jwarp
from jwarp.calibration.estimate.params import perturb_robot
from jwarp.importers.urdf_export import (
    UrdfExportOptions,
    dh_origin,
    export_urdf,
    rpy_of,
    side_file_path,
)

pin = pytest.importorskip("pinocchio")

N_CONFIGS = 1000


def random_q(robot, n, seed=0):
    lim = robot.joint_limits
    return np.random.default_rng(seed).uniform(lim[:, 0], lim[:, 1], (n, robot.n_dof))


def pinocchio_fk(urdf_path, robot, q):
    """(B, n_frames, 4, 4) world transforms of the links named like jwarp's frames."""
    model = pin.buildModelFromUrdf(str(urdf_path), mimic=True)
    assert model.nq == robot.n_dof          # mimic joints add no coordinate
    data = model.createData()
    idx_q = [model.joints[model.getJointId(n)].idx_q for n in robot.joint_names]
    fids = [model.getFrameId(n, pin.BODY) for n in robot.frame_names]
    assert all(f < model.nframes for f in fids)
    out = np.empty((len(q), robot.n_frames, 4, 4))
    for b, qb in enumerate(q):
        qp = pin.neutral(model)
        qp[idx_q] = qb
        pin.framesForwardKinematics(model, data, qp)
        for k, f in enumerate(fids):
            out[b, k] = data.oMf[f].homogeneous
    return out


def jwarp_fk(robot, q):
    return np.asarray(jwarp.fk(robot, q, device="cpu", dtype=np.float64))


def calibrated_robot():
    return perturb_robot(jwarp.robot("arm7"), np.random.default_rng(3),
                         groups=("theta", "d", "r", "alpha", "beta"))


@pytest.mark.parametrize("make", [lambda: jwarp.robot("arm7"), lambda: jwarp.robot("justin19"),
                                  calibrated_robot], ids=["arm7", "justin19", "calibrated"])
def test_fk_equals_pinocchio(tmp_path, make):
    robot = make()
    path = tmp_path / "robot.urdf"
    export_urdf(robot, path)
    q = random_q(robot, N_CONFIGS)
    err = np.abs(pinocchio_fk(path, robot, q) - jwarp_fk(robot, q)).max()
    assert err < 1e-9, err


def test_justin_coupled_frame_is_a_mimic_chain(tmp_path):
    robot = jwarp.robot("justin19")
    path = tmp_path / "justin.urdf"
    export_urdf(robot, path)
    joints = {j.get("name"): j for j in ET.parse(path).getroot().iter("joint")}
    i = robot.frame_names.index("torso_4")
    coupling = robot.frames[i].coupling
    assert len(coupling) == 2          # sum of two joints: two mimic joints about one axis
    mimics = [(j.find("mimic").get("joint"), float(j.find("mimic").get("multiplier")))
              for j in joints.values() if j.find("mimic") is not None]
    assert mimics == [(robot.joint_names[j], c) for j, c in coupling]
    # the jwarp joints are exactly the URDF's actuated (non-mimic, non-fixed) joints
    actuated = {n for n, j in joints.items() if j.get("type") != "fixed"
                and j.find("mimic") is None}
    assert actuated == set(robot.joint_names)


def test_coupling_without_unit_driver(tmp_path):
    """A joint that drives frames only with coefficients != 1 gets a driver joint on a leaf
    link; the frames mimic it."""
    doc = jwarp.robot("arm7").to_dict()
    doc["frames"][2].pop("joint", None)
    doc["frames"][2]["coupled"] = {"joints": [1], "coefficients": [-0.5]}
    robot = jwarp.RobotModel.from_dict(doc)
    path = tmp_path / "r.urdf"
    export_urdf(robot, path)
    q = random_q(robot, 200, seed=1)
    assert np.abs(pinocchio_fk(path, robot, q) - jwarp_fk(robot, q)).max() < 1e-9


def test_masses_as_inertials(tmp_path):
    """Total mass and the centre of mass (pinocchio's, from the inertials) equal jwarp's
    point masses."""
    robot = jwarp.robot("justin19")
    path = tmp_path / "justin.urdf"
    export_urdf(robot, path)
    model = pin.buildModelFromUrdf(str(path), mimic=True)
    data = model.createData()
    fr, m, com = robot.mass_arrays()
    assert math.isclose(pin.computeTotalMass(model), m.sum(), rel_tol=1e-12)
    q = random_q(robot, 20, seed=2)
    F = jwarp_fk(robot, q)
    for b in range(len(q)):
        qp = pin.neutral(model)
        qp[[model.joints[model.getJointId(n)].idx_q for n in robot.joint_names]] = q[b]
        c_pin = pin.centerOfMass(model, data, qp)
        pts = np.einsum("kij,kj->ki", F[b, fr, :3, :3], com) + F[b, fr, :3, 3]
        assert np.abs(c_pin - (m[:, None] * pts).sum(0) / m.sum()).max() < 1e-12


def test_spheres_as_collision_geometry(tmp_path):
    robot = jwarp.robot("arm7")
    path = tmp_path / "arm.urdf"
    export_urdf(robot, path)
    root = ET.parse(path).getroot()
    got = []
    for link in root.iter("link"):
        for c in link.iter("collision"):
            s = c.find("geometry/sphere")
            xyz = [float(v) for v in c.find("origin").get("xyz").split()]
            got.append((link.get("name"), tuple(xyz), float(s.get("radius"))))
    want = [(robot.frame_names[s.frame], tuple(s.position), s.radius) for s in robot.spheres]
    assert sorted(got) == sorted(want)


def test_capsule_is_cylinder_and_two_spheres(tmp_path):
    doc = jwarp.robot("arm7").to_dict()
    p0, p1, r = [0.01, 0.02, 0.0], [0.1, -0.05, 0.2], 0.03
    doc["capsules"] = [{"frame": 3, "p0": p0, "p1": p1, "radius": r}]
    doc["spheres"] = []
    robot = jwarp.RobotModel.from_dict(doc)
    path = tmp_path / "c.urdf"
    export_urdf(robot, path)
    link = [l for l in ET.parse(path).getroot().iter("link")
            if l.get("name") == robot.frame_names[3]][0]
    cols = link.findall("collision")
    assert len(cols) == 3
    cyl = [c for c in cols if c.find("geometry/cylinder") is not None][0]
    length = float(cyl.find("geometry/cylinder").get("length"))
    assert math.isclose(length, np.linalg.norm(np.subtract(p1, p0)), rel_tol=1e-14)
    xyz = np.array(cyl.find("origin").get("xyz").split(), float)
    rpy = np.array(cyl.find("origin").get("rpy").split(), float)
    R = pin.rpy.rpyToMatrix(*rpy)               # pinocchio's own URDF rpy convention
    assert np.allclose(xyz, np.add(p0, p1) / 2, atol=1e-15)
    assert np.allclose(R[:, 2], np.subtract(p1, p0) / length, atol=1e-14)
    centres = sorted(tuple(float(v) for v in c.find("origin").get("xyz").split())
                     for c in cols if c.find("geometry/sphere") is not None)
    assert centres == sorted([tuple(p0), tuple(p1)])


def test_rpy_round_trip_and_gimbal_lock():
    rng = np.random.default_rng(4)
    rows = [[0.1, math.pi / 2, 0.2, math.pi / 2, 0.0], [0, math.pi / 2, 0, -math.pi / 2, 0],
            [0, 0, 0, 0, math.pi / 2], [0, -math.pi / 2, 0, math.pi / 2, 0]]
    rows += rng.uniform(-math.pi, math.pi, (200, 5)).tolist()
    for row in rows:
        R = dh_origin(np.array(row))[:3, :3]
        assert np.abs(pin.rpy.rpyToMatrix(*rpy_of(R)) - R).max() < 1e-15 * 8


def test_side_file_for_elastic_robot(tmp_path):
    robot = jwarp.robot("arm7")
    kappa = np.zeros((robot.n_frames, 3))
    kappa[robot.is_dh, 2] = 1e-4
    elastic = robot.copy(kappa=kappa)
    path = tmp_path / "elastic.urdf"
    warnings = export_urdf(elastic, path)
    side = side_file_path(path)
    assert side == tmp_path / "elastic.urdf.jwarp.json"
    assert side.is_file() and len(warnings) == 1
    assert "kappa" in warnings[0] and str(side) in warnings[0]
    back = jwarp.RobotModel.load(side)
    assert np.array_equal(back.kappa, kappa)
    import hashlib
    assert back.notes["urdf_sha256"] == hashlib.sha256(path.read_bytes()).hexdigest()
    # the rigid robot needs no side file; the stale one of the elastic export goes
    warnings = export_urdf(robot, path)
    assert not side.exists()
    assert len(warnings) == 1 and "removed the side file" in warnings[0]
    assert export_urdf(robot, tmp_path / "rigid.urdf") == []
    assert not side_file_path(tmp_path / "rigid.urdf").exists()
    # a file of the side file's name that no export wrote is left alone (reliability 3,
    # item 3: it was deleted)
    foreign = side_file_path(tmp_path / "mine.urdf")
    foreign.write_text('{"my": "notes"}')
    w = export_urdf(robot, tmp_path / "mine.urdf")
    assert foreign.read_text() == '{"my": "notes"}'
    assert len(w) == 1 and "left" in w[0] and "alone" in w[0]
    # side_file=False: dropped, and said so
    w = export_urdf(elastic, tmp_path / "x.urdf", options=UrdfExportOptions(side_file=False))
    assert "dropped" in w[0] and not side_file_path(tmp_path / "x.urdf").exists()


def test_bad_input(tmp_path):
    robot = jwarp.robot("arm7")
    with pytest.raises(ValueError, match="path: .* is a folder"):
        export_urdf(robot, tmp_path)
    with pytest.raises(ValueError, match="path: folder .* does not exist"):
        export_urdf(robot, tmp_path / "missing" / "r.urdf")
    with pytest.raises(TypeError, match="robot: expected a jwarp RobotModel"):
        export_urdf("arm7", tmp_path / "r.urdf")
    with pytest.raises(ValueError, match="options.velocity"):
        export_urdf(robot, tmp_path / "r.urdf", options=UrdfExportOptions(velocity=-1))
    with pytest.raises(TypeError, match="name"):
        export_urdf(robot, tmp_path / "r.urdf", name=3)
    assert os.listdir(tmp_path) == []       # nothing written, no temporary file left


def test_failure_leaves_no_file(tmp_path, monkeypatch):
    import jwarp.importers.urdf_export as ue

    def boom(*a, **k):
        raise RuntimeError("boom")
    monkeypatch.setattr(ue, "urdf_text", boom)
    kappa = np.full((9, 3), 1e-4) * jwarp.robot("arm7").is_dh[:, None]
    with pytest.raises(RuntimeError):
        export_urdf(jwarp.robot("arm7").copy(kappa=kappa), tmp_path / "r.urdf")
    assert os.listdir(tmp_path) == []


def test_cli(tmp_path, capsys):
    from jwarp.cli.main import main

    robot = jwarp.robot("arm7")
    kappa = np.zeros((robot.n_frames, 3))
    kappa[robot.is_dh, 0] = 2e-4
    src = tmp_path / "calibrated.json"
    robot.copy(kappa=kappa).save(src)
    out = tmp_path / "calibrated.urdf"
    assert main(["export-urdf", str(src), "--out", str(out)]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("jwarp: warning: ") and "kappa" in err[0]
    assert out.is_file() and side_file_path(out).is_file()
    q = random_q(robot, 50)
    assert np.abs(pinocchio_fk(out, robot, q) - jwarp_fk(robot, q)).max() < 1e-9
    assert main(["export-urdf", "arm7", "--out", str(tmp_path)]) == 2
    assert "--out" in capsys.readouterr().err
    assert main(["export-urdf", "no_such_robot", "--out", str(tmp_path / "y.urdf")]) == 2
    assert "robot" in capsys.readouterr().err
    assert not (tmp_path / "y.urdf").exists()


@pytest.mark.parametrize("make", [calibrated_robot, lambda: jwarp.robot("justin19")],
                         ids=["calibrated", "justin19"])
def test_export_then_import_reproduces_fk(tmp_path, make):
    """export_urdf -> jwarp's URDF importer: the imported robot's frames (named after the
    exported links) have the calibrated robot's geometric FK to 1e-9, joints mapped by name
    (justin19: coupled torso through the exported mimic chain)."""
    robot = make()
    path = tmp_path / "robot.urdf"
    export_urdf(robot, path)
    back = jwarp.robot(str(path))
    assert sorted(back.joint_names) == sorted(robot.joint_names)
    q = random_q(robot, N_CONFIGS, seed=5)
    cols = [robot.joint_names.index(n) for n in back.joint_names]
    F = jwarp_fk(robot, q)
    G = jwarp_fk(back, q[:, cols])
    idx = [back.frame_names.index(n) for n in robot.frame_names]
    assert np.abs(G[:, idx] - F).max() < 1e-9
