"""URDF import (jwarp.importers): FK and Jacobians against pinocchio on the arms of
example-robot-data, mimic joints, axes in every direction, JSON round trip, elastic FK on
the imported Panda, collision geometry, malformed URDFs, and ``jwarp import-urdf``."""

from __future__ import annotations

import json
import math
from importlib import metadata
from pathlib import Path

import numpy as np
import pytest

import jwarp
from jwarp.importers.robot import load_urdf
from jwarp.importers.urdf import dh_matrix, dh_of, rpy_matrix

pin = pytest.importorskip("pinocchio")


def _robots_dir() -> Path:
    """example-robot-data's robots folder (the cmeel wheel ships the URDFs, no module)."""
    try:
        dist = metadata.distribution("example-robot-data")
    except metadata.PackageNotFoundError:
        pytest.skip("example-robot-data is not installed")
    folder = Path(dist.locate_file("cmeel.prefix/share/example-robot-data/robots"))
    if not folder.is_dir():
        pytest.skip(f"example-robot-data robots folder not found ({folder})")
    return folder


ARMS = {
    "panda": "panda_description/urdf/panda.urdf",      # 7 + finger, finger 2 mimics finger 1
    "ur5": "ur_description/urdf/ur5_robot.urdf",
    "kinova": "kinova_description/robots/kinova.urdf",  # continuous joints
    "xarm7": "xarm_description/urdf/xarm7.urdf",
    "z1": "z1_description/urdf/z1.urdf",
    "so100": "so_arm_description/urdf/so100.urdf",      # axes along x
    "double_pendulum": "double_pendulum_description/urdf/double_pendulum_continuous.urdf",
}


def pin_config(pm, m, Q: np.ndarray) -> np.ndarray:
    """jwarp configurations (n, n_dof) -> pinocchio's (n, nq), joints matched by name
    (continuous joints are [cos, sin] in pinocchio; mimic joints have nq = 0)."""
    out = np.tile(pin.neutral(pm), (len(Q), 1))
    for i in range(1, pm.njoints):
        j, name = pm.joints[i], pm.names[i]
        if j.nq == 0:
            continue
        assert name in m.joint_names, name
        v = Q[:, m.joint_index(name)]
        if j.nq == 1:
            out[:, j.idx_q] = v
        else:
            assert j.nq == 2
            out[:, j.idx_q] = np.cos(v)
            out[:, j.idx_q + 1] = np.sin(v)
    return out


def jac_columns(pm, m, Jp: np.ndarray) -> np.ndarray:
    """pinocchio's (6, nv) Jacobian in jwarp's joint order (6, n_dof)."""
    out = np.zeros((6, m.n_dof))
    for i in range(1, pm.njoints):
        j, name = pm.joints[i], pm.names[i]
        if j.nv == 1:
            out[:, m.joint_index(name)] = Jp[:, j.idx_v]
    return out


def compare_with_pinocchio(path: str, m, n: int, seed: int = 0) -> tuple[float, float, int]:
    """Largest |FK - pinocchio| over every link frame and |J - pinocchio| over every
    end-effector at ``n`` random configurations within the limits; number of link frames."""
    pm = pin.buildModelFromUrdf(str(path), mimic=True)
    pd = pm.createData()
    rng = np.random.default_rng(seed)
    lim = m.joint_limits
    Q = rng.uniform(lim[:, 0], lim[:, 1], (n, m.n_dof))
    F = np.asarray(jwarp.fk(m, Q, device="cpu"))
    eff = sorted(set(m.end_effectors.values()))
    J = {fi: np.asarray(jwarp.jacobian(m, Q, fi, device="cpu")) for fi in eff}
    links = [(f, m.frame_index(fr.name)) for f, fr in enumerate(pm.frames)
             if fr.type == pin.FrameType.BODY and fr.name in m.frame_names]
    pin_id = {fi: pm.getFrameId(m.frame_names[fi], pin.FrameType.BODY) for fi in eff}
    e_fk = e_jac = 0.0
    for k, qp in enumerate(pin_config(pm, m, Q)):
        pin.framesForwardKinematics(pm, pd, qp)
        ours = F[k, [i for _, i in links]]
        theirs = np.array([pd.oMf[f].homogeneous for f, _ in links])
        e_fk = max(e_fk, float(np.abs(ours - theirs).max()))
        pin.computeJointJacobians(pm, pd, qp)
        for fi in eff:
            Jp = pin.getFrameJacobian(pm, pd, pin_id[fi], pin.LOCAL_WORLD_ALIGNED)
            e_jac = max(e_jac, float(np.abs(J[fi][k] - jac_columns(pm, m, Jp)).max()))
    return e_fk, e_jac, len(links)


@pytest.mark.parametrize("arm", sorted(ARMS))
def test_fk_and_jacobians_equal_pinocchio(arm):
    path = _robots_dir() / ARMS[arm]
    from lxml import etree

    m = jwarp.robot(str(path))
    e_fk, e_jac, n = compare_with_pinocchio(path, m, 1000)
    assert n == len(etree.parse(str(path)).getroot().findall("link"))   # every link compared
    # acceptance: 1e-9; measured about 2e-15 (the import is exact up to roundoff)
    assert e_fk < 1e-12, f"{arm}: FK differs from pinocchio by {e_fk:.2e}"
    assert e_jac < 1e-12, f"{arm}: Jacobian differs from pinocchio by {e_jac:.2e}"


def test_every_link_is_a_frame_and_panda_finger_mimics():
    path = _robots_dir() / ARMS["panda"]
    imp = load_urdf(path)
    m = imp.model
    from lxml import etree

    links = [el.get("name") for el in etree.parse(str(path)).getroot().findall("link")]
    assert set(links) <= set(m.frame_names)
    assert "panda_finger_joint2" not in m.joint_names       # mimic: not actuated
    f2 = m.frames[m.frame_index(imp.source.joint_frames["panda_finger_joint2"])]
    assert f2.coupling == [(m.joint_index("panda_finger_joint1"), 1.0)]
    # default end-effector: the tool of the arm, not every leaf link (docs/urdf.md)
    assert set(m.end_effectors) == {"panda_hand_tcp"}
    # the fingers slide apart by q each: prismatic limits from the URDF
    assert m.joints[m.joint_index("panda_finger_joint1")].type == "prismatic"


#: a robot with axes along z (UR5: also +-y), one with axes along x (SO-100, with a joint named
#: after a link), continuous joints and non-foldable origins (Kinova), a mimic finger (Panda)
JOINT_FRAME_ARMS = ("panda", "ur5", "so100", "kinova")


@pytest.mark.parametrize("arm", JOINT_FRAME_ARMS)
def test_every_link_and_joint_frame_equals_pinocchio(arm):
    """FK of every URDF link AND joint name equals pinocchio's ``oMf`` of that name (a joint
    name is the URDF joint frame after the motion, the child link's frame; jwarp's axis frame
    is ``<joint>_axis``; docs/urdf.md). A joint named like a link is that link (SO-100's
    ``gripper``): pinocchio's frame of the same name and type BODY is compared."""
    path = _robots_dir() / ARMS[arm]
    m = jwarp.robot(str(path))
    pm = pin.buildModelFromUrdf(str(path), mimic=True)
    pd = pm.createData()
    from lxml import etree

    root = etree.parse(str(path)).getroot()
    links = {el.get("name") for el in root.findall("link")}
    joints = {el.get("name") for el in root.findall("joint")}
    kinds = (pin.FrameType.BODY, pin.FrameType.JOINT, pin.FrameType.FIXED_JOINT)
    pairs = [(f, m.frame_index(fr.name)) for f, fr in enumerate(pm.frames)
             if fr.type in kinds and fr.name != "universe"
             and not (fr.name in links and fr.type != pin.FrameType.BODY)]
    compared = {pm.frames[f].name for f, _ in pairs}
    assert compared == links | joints, "every link and joint compared"
    rng = np.random.default_rng(7)
    Q = rng.uniform(m.joint_limits[:, 0], m.joint_limits[:, 1], (200, m.n_dof))
    F = np.asarray(jwarp.fk(m, Q, device="cpu", dtype=np.float64))
    ours = F[:, [i for _, i in pairs]]
    err = 0.0
    for k, qp in enumerate(pin_config(pm, m, Q)):
        pin.framesForwardKinematics(pm, pd, qp)
        theirs = np.array([pd.oMf[f].homogeneous for f, _ in pairs])
        err = max(err, float(np.abs(ours[k] - theirs).max()))
    assert err < 1e-9, f"{arm}: a link or joint frame differs from pinocchio by {err:.2e}"


def test_joint_names_are_frame_aliases(tmp_path):
    """The joint names are ``frame_aliases`` of the child links' frames, kept by JSON; the
    axis-aligned dh frame of a joint whose axis is not +-z is ``<joint>_axis``; a document
    without ``frame_aliases`` (saved before) loads; an alias may not shadow another frame."""
    path = _robots_dir() / ARMS["ur5"]
    imp = load_urdf(path, end_effectors={"elbow": "elbow_joint"})
    m = imp.model
    assert m.frame_index("elbow_joint") == m.frame_index("forearm_link")
    assert m.frame_index("elbow") == m.frame_index("forearm_link")   # end_effectors may name a joint
    assert imp.source.joint_frames["elbow_joint"] == "elbow_joint_axis"
    assert "elbow_joint" not in m.frame_names
    assert m.frame_index("world_joint") == m.frame_index("base_link")  # fixed joints too
    from jwarp.importers.groups import GroupOptions, plan_group

    grouped = plan_group(imp, GroupOptions(end_effectors={"wrist": "wrist_2_joint"})).model
    assert grouped.end_effectors == {"wrist": m.frame_index("wrist_2_link")}
    doc = m.to_dict()
    assert doc["frame_aliases"]["elbow_joint"] == m.frame_index("forearm_link")
    m2 = jwarp.RobotModel.from_dict(json.loads(json.dumps(doc)))
    assert m2.frame_aliases == m.frame_aliases
    old = dict(doc)
    del old["frame_aliases"]
    assert jwarp.RobotModel.from_dict(old).frame_aliases == {}
    bad = dict(doc, frame_aliases={"tool0": "forearm_link"})
    with pytest.raises(ValueError, match="frame_aliases.tool0"):
        jwarp.RobotModel.from_dict(bad)
    with pytest.raises(ValueError, match="frame_aliases.x"):
        jwarp.RobotModel.from_dict(dict(doc, frame_aliases={"x": 99}))


# ------------------------------------------------------------------ small URDFs
def write(tmp_path, text: str, name: str = "robot.urdf") -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


LINK = '<link name="{0}"><inertial><origin xyz="0.01 0.02 0.03"/><mass value="{1}"/>' \
       '<inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link>'


def joint(name, parent, child, jtype="revolute", xyz="0 0 0.1", rpy="0 0 0", axis="0 0 1",
          extra='<limit lower="-2" upper="2" effort="1" velocity="1"/>'):
    ax = "" if axis is None else f'<axis xyz="{axis}"/>'
    return (f'<joint name="{name}" type="{jtype}"><parent link="{parent}"/>'
            f'<child link="{child}"/><origin xyz="{xyz}" rpy="{rpy}"/>{ax}{extra}</joint>')


def urdf(*parts, links=None):
    links = links if links is not None else []
    return '<?xml version="1.0"?><robot name="t">' + "".join(links) + "".join(parts) + "</robot>"


AXES = ["0 0 1", "0 0 -1", "1 0 0", "-1 0 0", "0 1 0", "0 -1 0", "0.3 -0.4 1.2", "1 1 0",
        "0 0.6 -0.8"]


def chain_urdf(prismatic_every: int = 3) -> str:
    """A chain with every axis direction, odd origins, prismatic and continuous joints and
    a fixed joint."""
    names = [f"l{k}" for k in range(len(AXES) + 2)]
    links = [LINK.format(n, 0.5 + 0.1 * k) for k, n in enumerate(names)]
    parts = []
    rng = np.random.default_rng(3)
    for k, ax in enumerate(AXES):
        xyz = " ".join(f"{v:.6f}" for v in rng.uniform(-0.2, 0.2, 3))
        rpy = " ".join(f"{v:.6f}" for v in rng.uniform(-3, 3, 3))
        jt = "prismatic" if k % prismatic_every == 2 else ("continuous" if k == 4 else "revolute")
        extra = ('<limit effort="1" velocity="1"/>' if jt == "continuous"
                 else '<limit lower="-1.5" upper="1.5" effort="1" velocity="1"/>')
        parts.append(joint(f"j{k}", names[k], names[k + 1], jt, xyz, rpy, ax, extra))
    parts.append(joint("tool", names[-2], names[-1], "fixed", "0.1 0 0.05", "0.3 0.2 0.1", None, ""))
    return urdf(*parts, links=links)


def test_any_axis_origin_and_type_equal_pinocchio(tmp_path):
    path = write(tmp_path, chain_urdf())
    for merge in (True, False):
        m = load_urdf(path, merge_static=merge).model
        e_fk, e_jac, n = compare_with_pinocchio(path, m, 300, seed=1)
        assert n == len(AXES) + 2
        assert e_fk < 1e-9 and e_jac < 1e-9, (merge, e_fk, e_jac)
    assert m.joints[4].lower == -math.pi and m.joints[4].upper == math.pi   # continuous
    assert m.joints[2].type == "prismatic"
    assert load_urdf(path, continuous_limit=2 * math.pi).model.joints[4].upper \
        == 2 * math.pi


def test_jacobian_matches_finite_differences(tmp_path):
    """Independent of pinocchio: the imported tip Jacobian against central differences."""
    m = load_urdf(write(tmp_path, chain_urdf())).model
    tip = m.frame_index("l10")
    q = np.random.default_rng(5).uniform(-1, 1, m.n_dof)
    J = np.asarray(jwarp.jacobian(m, q, tip, device="cpu"))
    h = 1e-6
    for j in range(m.n_dof):
        dq = np.zeros(m.n_dof)
        dq[j] = h
        Tp = np.asarray(jwarp.fk(m, q + dq, device="cpu"))[tip]
        Tm = np.asarray(jwarp.fk(m, q - dq, device="cpu"))[tip]
        dp = (Tp[:3, 3] - Tm[:3, 3]) / (2 * h)
        dR = (Tp[:3, :3] - Tm[:3, :3]) / (2 * h) @ Tp[:3, :3].T
        w = np.array([dR[2, 1], dR[0, 2], dR[1, 0]])
        assert np.allclose(J[:3, j], dp, atol=1e-7) and np.allclose(J[3:, j], w, atol=1e-6)


def mimic_urdf(mult=2.0, offset=0.3, pmult=-0.5, poffset=0.02) -> str:
    links = [LINK.format(n, 1.0) for n in ("base", "a", "b", "c", "d")]
    return urdf(
        joint("ja", "base", "a", axis="0 1 0"),
        joint("jb", "a", "b", xyz="0.2 0 0", rpy="0.1 0.2 0.3", axis="1 0 0",
              extra=f'<limit lower="-9" upper="9" effort="1" velocity="1"/><mimic joint="ja" multiplier="{mult}" '
                    f'offset="{offset}"/>'),
        joint("jc", "a", "c", "prismatic", xyz="0 0.1 0", axis="0 0 1",
              extra='<limit lower="0" upper="0.1" effort="1" velocity="1"/>'),
        joint("jd", "c", "d", "prismatic", xyz="0 0 0.1", axis="0.6 0.8 0",
              extra=f'<limit lower="-1" upper="1" effort="1" velocity="1"/><mimic joint="jc" multiplier="{pmult}" '
                    f'offset="{poffset}"/>'),
        links=links)


def axis_angle(axis, angle):
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K


def test_mimic_joints_move_as_declared(tmp_path):
    path = write(tmp_path, mimic_urdf())
    m = jwarp.robot(str(path))
    assert m.joint_names == ["ja", "jc"]
    Q = np.random.default_rng(2).uniform(m.joint_limits[:, 0], m.joint_limits[:, 1], (50, 2))
    F = np.asarray(jwarp.fk(m, Q, device="cpu"))
    ia, ib, ic, idd = (m.frame_index(n) for n in "abcd")
    origin_b = np.eye(4)
    origin_b[:3, :3] = rpy_matrix([0.1, 0.2, 0.3])
    origin_b[:3, 3] = [0.2, 0, 0]
    for k, (qa, qc) in enumerate(Q):
        rel = np.linalg.inv(F[k, ia]) @ F[k, ib]       # numpy reference of URDF's mimic
        want = origin_b.copy()
        want[:3, :3] = origin_b[:3, :3] @ axis_angle([1, 0, 0], 2.0 * qa + 0.3)
        assert np.allclose(rel, want, atol=1e-12)
        rel = np.linalg.inv(F[k, ic]) @ F[k, idd]
        assert np.allclose(rel[:3, 3], [0, 0, 0.1] + (-0.5 * qc + 0.02) * np.array([0.6, 0.8, 0]),
                           atol=1e-12)
        assert np.allclose(rel[:3, :3], np.eye(3), atol=1e-12)
    e_fk, e_jac, _ = compare_with_pinocchio(path, m, 200)
    assert e_fk < 1e-9 and e_jac < 1e-9, (e_fk, e_jac)


def test_mimic_of_a_mimic_is_resolved(tmp_path):
    links = [LINK.format(n, 1.0) for n in ("base", "a", "b", "c")]
    path = write(tmp_path, urdf(
        joint("ja", "base", "a"),
        joint("jb", "a", "b", extra='<limit lower="-9" upper="9" effort="1" velocity="1"/><mimic joint="ja" '
                                    'multiplier="2" offset="0.1"/>'),
        joint("jc", "b", "c", extra='<limit lower="-9" upper="9" effort="1" velocity="1"/><mimic joint="jb" '
                                    'multiplier="3" offset="0.2"/>'), links=links))
    m = jwarp.robot(str(path))
    fc = m.frames[m.frame_index("c")]
    assert fc.coupling == [(0, 6.0)] and math.isclose(fc.dh[1], 3 * 0.1 + 0.2)


def test_json_round_trip_gives_identical_fk(tmp_path):
    m = jwarp.robot(str(_robots_dir() / ARMS["panda"]))
    m.save(tmp_path / "panda.json")
    m2 = jwarp.RobotModel.load(tmp_path / "panda.json")
    Q = np.random.default_rng(0).uniform(m.joint_limits[:, 0], m.joint_limits[:, 1], (100, m.n_dof))
    assert np.array_equal(np.asarray(jwarp.fk(m, Q, device="cpu")),
                          np.asarray(jwarp.fk(m2, Q, device="cpu")))
    assert m2.frame_names == m.frame_names and len(m2.masses) == len(m.masses)


def test_fk_elastic_runs_on_imported_panda():
    m = jwarp.robot(str(_robots_dir() / ARMS["panda"]))
    assert sum(x.mass for x in m.masses) > 10.0             # the URDF's inertials
    q = np.array([0.0, -0.5, 0.0, -2.0, 0.0, 1.5, 0.7, 0.02])
    rigid = np.asarray(jwarp.fk(m, q, device="cpu"))
    res = jwarp.fk_elastic(m, q, kappa=[0.0, 0.0, 1e-4], device="cpu", dtype=np.float64)
    assert bool(np.all(res.converged))
    tcp = m.frame_index("panda_hand_tcp")
    sag = np.asarray(res.frames)[tcp, :3, 3] - rigid[tcp, :3, 3]
    assert 1e-5 < np.linalg.norm(sag) < 1e-1               # gravity bends the joints
    zero = jwarp.fk_elastic(m, q, kappa=0.0, device="cpu", dtype=np.float64)
    assert np.allclose(np.asarray(zero.frames), rigid, atol=1e-12)


def test_dh_folding_is_exact():
    rng = np.random.default_rng(0)
    for _ in range(200):
        row = rng.uniform(-3, 3, 5)
        row[[0, 2]] *= 0.1
        T = dh_matrix(row)
        assert np.allclose(dh_matrix(dh_of(T)), T, atol=1e-12)
    T = np.eye(4)
    T[:3, 3] = [0.0, 0.1, 0.0]            # a pure offset along y: not a DH row
    assert dh_of(T) is None


# ------------------------------------------------------------------ collision geometry
def test_collision_geometry_and_spheres(tmp_path):
    (tmp_path / "pkgs" / "my_pkg" / "meshes").mkdir(parents=True)
    (tmp_path / "pkgs" / "my_pkg" / "meshes" / "a.stl").write_text("solid x\nendsolid x\n")
    (tmp_path / "rel.stl").write_text("solid x\nendsolid x\n")
    col = ('<collision><origin xyz="0 0 0.1"/><geometry><sphere radius="0.05"/></geometry></collision>'
           '<collision><origin xyz="0 0 0.2" rpy="0 1.5707963267948966 0"/><geometry>'
           '<box size="0.1 0.2 0.3"/></geometry></collision>'
           '<collision><geometry><cylinder radius="0.04" length="0.3"/></geometry></collision>'
           '<collision><geometry><capsule radius="0.03" length="0.2"/></geometry></collision>'
           '<collision><geometry><mesh filename="package://my_pkg/meshes/a.stl" scale="2 2 2"/>'
           '</geometry></collision>'
           '<collision><geometry><mesh filename="rel.stl"/></geometry></collision>'
           '<collision><geometry><mesh filename="package://other/none.stl"/></geometry></collision>')
    links = ['<link name="base"/>', f'<link name="arm">{col}</link>']
    path = write(tmp_path, urdf(joint("j", "base", "arm"), links=links))
    imp = load_urdf(path, package_dirs=[tmp_path / "pkgs"])
    g = imp.geometries_of("arm")
    assert [x.kind for x in g] == ["sphere", "box", "cylinder", "capsule", "mesh", "mesh", "mesh"]
    assert g[1].size.tolist() == [0.1, 0.2, 0.3] and np.allclose(g[1].origin[:3, 3], [0, 0, 0.2])
    assert g[2].size.tolist() == [0.04, 0.3] and g[3].size.tolist() == [0.03, 0.2]
    assert g[4].mesh_path == str(tmp_path / "pkgs" / "my_pkg" / "meshes" / "a.stl")
    assert g[4].scale.tolist() == [2, 2, 2]
    assert g[5].mesh_path == str(tmp_path / "rel.stl")
    assert g[6].mesh_path is None
    with pytest.raises(ValueError, match="link 'arm'.*package://other/none.stl"):
        g[6].mesh_file()
    m = imp.model
    assert len(m.spheres) == 1 and m.spheres[0].frame == m.frame_index("arm")
    assert m.spheres[0].radius == 0.05 and m.spheres[0].position.tolist() == [0, 0, 0.1]
    assert m.end_effectors == {"arm": m.frame_index("arm")}
    assert imp.model.masses == []          # no inertials: massless
    with pytest.raises(ValueError, match=r"link 'arm' <collision> 7: mesh file not found: "
                                         r"'package://other/none.stl'"):
        load_urdf(path, package_dirs=[tmp_path / "pkgs"], require_meshes=True)


def test_panda_meshes_resolve_from_the_package_folder():
    imp = load_urdf(_robots_dir() / ARMS["panda"], require_meshes=True)
    meshes = [x for x in imp.geometries if x.kind == "mesh"]
    assert len(meshes) >= 8 and all(Path(x.mesh_file()).is_file() for x in meshes)


def test_masses_and_given_end_effectors(tmp_path):
    links = [LINK.format("base", 2.0), LINK.format("a", 1.5)]
    path = write(tmp_path, urdf(joint("j", "base", "a", axis="1 0 0"), links=links))
    m = load_urdf(path, end_effectors={"tcp": "a", "origin": "base"}).model
    assert m.end_effectors == {"tcp": m.frame_index("a"), "origin": m.frame_index("base")}
    assert [(m.frame_names[x.frame], x.mass, x.com.tolist()) for x in m.masses] == \
        [("base", 2.0, [0.01, 0.02, 0.03]), ("a", 1.5, [0.01, 0.02, 0.03])]
    with pytest.raises(ValueError, match="end_effectors.tcp: unknown link or frame 'nope'"):
        load_urdf(path, end_effectors={"tcp": "nope"})


# ------------------------------------------------------------------ malformed URDFs
LINKS3 = ['<link name="base"/>', '<link name="a"/>', '<link name="b"/>']


@pytest.mark.parametrize("text, match", [
    ('<robot name="t"><link name="base"/>', "not valid XML"),
    ('<robbot name="t"/>', "root element is <robbot>"),
    (urdf(joint("j", "base", "a"), joint("k", "ghost", "b"), links=LINKS3),
     "joint 'k': parent link 'ghost' is not defined"),
    (urdf(joint("j", "base", "a"), joint("k", "a", "ghost"), links=LINKS3),
     "joint 'k': child link 'ghost' is not defined"),
    (urdf('<joint name="j" type="revolute"><child link="a"/></joint>', links=LINKS3),
     "joint 'j': missing <parent link"),
    (urdf(joint("j", "base", "a"), joint("k", "b", "a"), links=LINKS3),
     "link 'a' has two parents \\(joints 'j' and 'k'\\)"),
    (urdf(joint("j", "base", "a"), joint("k", "a", "b"), joint("l", "b", "a"), links=LINKS3),
     "two parents"),
    (urdf(joint("j", "base", "a"), joint("k", "a", "b"), joint("l", "b", "base"), links=LINKS3),
     "the joints form a cycle"),
    (urdf(joint("j", "base", "a"), joint("k", "a", "b", "planar"), links=LINKS3),
     "joint 'k': type 'planar' is not supported"),
    (urdf(joint("j", "base", "a"), joint("k", "a", "b", "floating"), links=LINKS3),
     "joint 'k': type 'floating' is not supported"),
    (urdf(joint("j", "base", "a"), joint("k", "a", "b", "hinge"), links=LINKS3),
     "joint 'k': unknown joint type 'hinge'"),
    (urdf(joint("j", "base", "a"), joint("k", "a", "b", extra='<limit lower="0" upper="1"/>'
                                         '<mimic joint="nope"/>'), links=LINKS3),
     "joint 'k': <mimic joint=\"nope\"> names an unknown joint"),
    (urdf(joint("j", "base", "a", "fixed"), joint("k", "a", "b", extra='<limit lower="0" '
          'upper="1"/><mimic joint="j"/>'), links=LINKS3), "<mimic> of the fixed joint 'j'"),
    (urdf(joint("j", "base", "a", axis="0 0 0"), links=LINKS3[:2]), "joint 'j': <axis xyz> is zero"),
    (urdf(joint("j", "base", "a", extra=""), links=LINKS3[:2]), "joint 'j': a revolute joint needs a <limit>"),
    (urdf(joint("j", "base", "a"), links=LINKS3), "several root links"),
    (urdf(joint("j", "base", "a", xyz="0 0"), links=LINKS3[:2]), "origin xyz>: expected 3"),
])
def test_malformed_urdf_names_the_element(tmp_path, text, match):
    path = write(tmp_path, text)
    with pytest.raises(ValueError, match=match) as info:
        load_urdf(path)
    assert str(path) in str(info.value)


def test_missing_file_and_bad_options(tmp_path):
    with pytest.raises(ValueError, match="URDF file not found"):
        load_urdf(tmp_path / "none.urdf")
    with pytest.raises(ValueError, match="robot: file not found"):
        jwarp.robot(str(tmp_path / "none.urdf"))
    path = write(tmp_path, urdf(joint("j", "base", "a"), links=LINKS3[:2]))
    with pytest.raises(ValueError, match="continuous_limit"):
        load_urdf(path, continuous_limit=0.0)
    with pytest.raises(ValueError, match="package_dirs: not a folder"):
        load_urdf(path, package_dirs=[tmp_path / "none"])


# ------------------------------------------------------------------ CLI
def test_cli_import_urdf(tmp_path, capsys):
    from cli_helpers import one_line_error, run  # tests/cli_helpers.py

    src = _robots_dir() / ARMS["ur5"]
    out = tmp_path / "ur5.json"
    code, text, _ = run(capsys, ["import-urdf", src, "--out", out, "--end-effector", "tcp=tool0",
                                 "--json"])
    assert code == 0, text
    summary = json.loads(text)
    assert summary["dof"] == 6 and summary["end_effectors"] == ["tcp"]
    m, ref = jwarp.RobotModel.load(out), jwarp.robot(str(src))
    Q = np.random.default_rng(1).uniform(-3, 3, (20, 6))
    assert np.array_equal(np.asarray(jwarp.fk(m, Q, device="cpu")),
                          np.asarray(jwarp.fk(ref, Q, device="cpu")))
    one_line_error(capsys, ["import-urdf", src, "--out", tmp_path / "no" / "x.json"], "--out")
    one_line_error(capsys, ["import-urdf", src, "--out", out, "--end-effector", "tcp"],
                   "--end-effector")
    one_line_error(capsys, ["import-urdf", src, "--out", out, "--continuous-limit", "nan"],
                   "--continuous-limit")
    one_line_error(capsys, ["import-urdf", src, "--out", out, "--package-dir", tmp_path / "no"],
                   "--package-dir")
    one_line_error(capsys, ["import-urdf", tmp_path / "none.urdf", "--out", out], "URDF")
    one_line_error(capsys, ["import-urdf", src, "--out", out, "--end-effector", "tcp=nope"],
                   "--end-effector")
    bad = write(tmp_path, urdf(joint("j", "base", "a", "planar"), links=LINKS3[:2]), "bad.urdf")
    line = one_line_error(capsys, ["import-urdf", bad, "--out", tmp_path / "b.json"], "URDF")
    assert "joint 'j': type 'planar' is not supported" in line
    assert not (tmp_path / "b.json").exists()
