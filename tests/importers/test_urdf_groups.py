"""Planning groups, frozen joints and default end-effectors of imported URDFs
(jwarp.importers.groups, jwarp.model.freeze_joints, jwarp.importers.tips): FK of the
reduced robot against pinocchio's FK of the full URDF with the other joints at their
locked values; frozen fingers; MoveIt states naming frozen joints; default end-effectors
of Panda, Baxter, UR10; CLI errors naming the option."""

from __future__ import annotations

import json
import math
import warnings

import numpy as np
import pytest

import jwarp
from jwarp.importers.groups import GroupOptions, default_end_effectors, plan_group
from jwarp.importers.robot import example_robot_urdf, load_urdf
from jwarp.model import freeze_joints, frozen_joint_values

pin = pytest.importorskip("pinocchio")


def _erd(rel: str) -> str:
    try:
        return example_robot_urdf(rel)
    except ValueError as e:
        pytest.skip(str(e))


PANDA = "panda_description/urdf/panda.urdf"
PANDA_SRDF = "panda_description/srdf/panda.srdf"
BAXTER = "baxter_description/urdf/baxter.urdf"


def fk_error(path: str, model, values: dict[str, float], n: int = 30, seed: int = 0) -> float:
    """Largest |FK - pinocchio FK| over every link frame of ``model`` at ``n`` random
    configurations of its joints, pinocchio's other joints at ``values`` (by name); mimic
    joints as the URDF says (``multiplier * value + offset``, read here with xml.etree;
    pinocchio loads them as free joints: its ``mimic=True`` refuses TALOS)."""
    import xml.etree.ElementTree as ET

    mimic = {}
    for j in ET.parse(path).getroot().findall("joint"):
        el = j.find("mimic")
        if el is not None:
            mimic[j.get("name")] = (el.get("joint"), float(el.get("multiplier", 1.0)),
                                    float(el.get("offset", 0.0)))
    pm = pin.buildModelFromUrdf(path)
    pd = pm.createData()
    rng = np.random.default_rng(seed)
    lim = model.joint_limits
    Q = rng.uniform(lim[:, 0], lim[:, 1], (n, model.n_dof))
    F = np.asarray(jwarp.fk(model, Q, device="cpu"))
    links = [(f, model.frame_index(fr.name)) for f, fr in enumerate(pm.frames)
             if fr.type == pin.FrameType.BODY and fr.name in model.frame_names]
    assert len(links) > 10
    err = 0.0
    for k in range(n):
        def value(name: str, k: int = k) -> float:  # k bound now (B023)
            if name in model.joint_names:
                return Q[k, model.joint_index(name)]
            if name in mimic:
                src, mult, off = mimic[name]
                return mult * value(src) + off
            return values[name]
        q = pin.neutral(pm)
        for i in range(1, pm.njoints):
            j, name = pm.joints[i], pm.names[i]
            v = value(name)
            if j.nq == 1:
                q[j.idx_q] = v
            else:
                q[j.idx_q:j.idx_q + 2] = [math.cos(v), math.sin(v)]
        pin.framesForwardKinematics(pm, pd, q)
        ours = F[k, [i for _, i in links]]
        theirs = np.array([pd.oMf[f].homogeneous for f, _ in links])
        err = max(err, float(np.abs(ours - theirs).max()))
    return err


def test_group_from_srdf_equals_pinocchio():
    urdf, srdf = _erd(PANDA), _erd(PANDA_SRDF)
    res = plan_group(load_urdf(urdf), GroupOptions(srdf=srdf, group="arm", state="default"))
    m = res.model
    import xml.etree.ElementTree as ET

    root = ET.parse(srdf).getroot()
    arm = [j.get("name") for j in root.find("group[@name='arm']").findall("joint")]
    state = {j.get("name"): float(j.get("value"))
             for j in root.find("group_state[@name='default']").findall("joint")}
    assert m.joint_names == arm and m.n_dof == 7
    assert res.frozen == {"panda_finger_joint1": state["panda_finger_joint1"]}
    assert fk_error(urdf, m, state) < 1e-12
    # end-effector: the SRDF's end_effector parent link
    ee = root.find("end_effector")
    assert m.end_effectors == {ee.get("name"): m.frame_index(ee.get("parent_link"))}
    assert json.loads(m.notes["frozen_joints"]) == res.frozen
    assert m.notes["planning_group"] == "arm"


def test_talos_arm_chain_group_with_half_sitting_state():
    """A real SRDF chain group (TALOS ``l_arm``: torso_2_link -> wrist_left_ft_tool_link) with
    the ``half_sitting`` state (which also holds the 7 values of the floating
    ``root_joint``, left out): FK of the 7-joint arm equals pinocchio's FK of the full URDF
    with every other joint at its state value."""
    urdf = _erd("talos_data/robots/talos_full_v2.urdf")
    srdf = _erd("talos_data/srdf/talos.srdf")
    import xml.etree.ElementTree as ET

    root = ET.parse(srdf).getroot()
    state = {j.get("name"): [float(x) for x in j.get("value").split()]
             for j in root.find("group_state[@name='half_sitting']").findall("joint")}
    res = plan_group(load_urdf(urdf), GroupOptions(srdf=srdf, group="l_arm",
                                                   state="half_sitting"))
    m = res.model
    assert m.joint_names == [f"arm_left_{k}_joint" for k in range(1, 8)]
    for name, v in res.frozen.items():       # the state's value where it has one, else 0
        if res.source[name] == "state":
            assert state[name] == [v]
        else:
            assert name not in state and v == 0.0
    assert sum(s == "state" for s in res.source.values()) >= 20
    assert m.end_effectors == {"wrist_left_ft_tool_link": m.frame_index("wrist_left_ft_tool_link")}
    assert fk_error(urdf, m, res.frozen, n=10) < 1e-12


def test_chain_group_tip_is_the_end_effector(tmp_path):
    urdf = _erd(PANDA)
    srdf = tmp_path / "chain.srdf"
    srdf.write_text("<robot name='panda'><group name='arm'><chain base_link='panda_link0' "
                    "tip_link='panda_link8'/></group></robot>")
    res = plan_group(load_urdf(urdf), GroupOptions(srdf=srdf, group="arm",
                                                   lock={"panda_finger_joint1": 0.02}))
    assert res.model.n_dof == 7 and res.source == {"panda_finger_joint1": "lock"}
    assert res.model.end_effectors == {"panda_link8": res.model.frame_index("panda_link8")}
    assert res.end_effectors_from == "group chain tips"
    assert fk_error(urdf, res.model, {"panda_finger_joint1": 0.02}) < 1e-12


def test_joint_subset_of_baxter_equals_pinocchio():
    urdf = _erd(BAXTER)
    robot = load_urdf(urdf)
    left = [f"left_{j}" for j in ("s0", "s1", "e0", "e1", "w0", "w1", "w2")]
    lock = {"right_s0": 0.3, "right_e1": 1.0, "head_pan": -0.4}
    res = plan_group(robot, GroupOptions(joints=left, lock=lock))
    m = res.model
    assert m.joint_names == left
    full = robot.model
    # the others: the lock values, else 0 clipped into the limits
    values = {n: lock.get(n, min(max(0.0, lo), hi))
              for n, (lo, hi) in zip(full.joint_names, full.joint_limits) if n not in left}
    assert res.frozen == values
    assert fk_error(urdf, m, values) < 1e-12
    # default end-effector of the left arm only: the right arm is now fixed
    assert list(m.end_effectors) == ["left_gripper"]


def test_frozen_fingers_panda():
    urdf = _erd(PANDA)
    full = load_urdf(urdf).model
    m = full.freeze({"panda_finger_joint1": 0.03})
    assert m.n_dof == 7 and "panda_finger_joint1" not in m.joint_names
    assert m.frame_names == full.frame_names              # frames and indices kept
    # finger 2 mimics finger 1: both at 0.03
    assert fk_error(urdf, m, {"panda_finger_joint1": 0.03}) < 1e-12
    assert frozen_joint_values(m) == {"panda_finger_joint1": 0.03}
    # on import: --freeze NAME (no value: 0 clipped into [0, 0.04])
    res = plan_group(load_urdf(urdf), GroupOptions(freeze={"panda_finger_joint1": None}))
    assert res.model.n_dof == 7 and res.frozen == {"panda_finger_joint1": 0.0}
    assert res.model.end_effectors == {"panda_hand_tcp": full.frame_index("panda_hand_tcp")}


def test_freeze_rigid_pairs_and_coupled_joints():
    # collision spheres on the hand and both fingers: freezing joins them rigidly -> excluded
    urdf = _erd(PANDA)
    full = load_urdf(urdf).model
    idx = [full.frame_index(n) for n in ("panda_hand", "panda_leftfinger", "panda_rightfinger",
                                         "panda_link5")]
    spheres = [jwarp.model.Sphere(frame=i, position=np.zeros(3), radius=0.01) for i in idx]
    m = full.copy(spheres=spheres).freeze({"panda_finger_joint1": 0.0})
    pairs = {tuple(sorted(p)) for p in m.self_collision.exclude_pairs}
    assert pairs == {tuple(sorted((a, b))) for a in idx[:3] for b in idx[:3] if a < b}
    # a coupled robot (justin19's torso): freezing one of the coupled joints keeps the FK
    # of the full model with that joint at its value (and its linear limits shifted)
    robot = jwarp.robot("justin19")
    coupled = next(f for f in robot.frames if len(f.coupling) > 1)
    j = coupled.coupling[0][0]
    name = robot.joint_names[j]
    v = 0.5 * (robot.joints[j].lower + robot.joints[j].upper) + 0.1
    small = freeze_joints(robot, {name: v})
    rng = np.random.default_rng(1)
    lim = small.joint_limits
    Q = rng.uniform(lim[:, 0], lim[:, 1], (20, small.n_dof))
    Qf = np.insert(Q, j, v, axis=1)
    a = np.asarray(jwarp.fk(small, Q, device="cpu"), np.float64)
    b = np.asarray(jwarp.fk(robot, Qf, device="cpu"), np.float64)
    assert np.abs(a - b).max() < 1e-5                      # float32 kernels
    for old in robot.linear_limits:
        if j in old.joints:
            c = old.coefficients[old.joints.index(j)]
            assert any(math.isclose(n.lower, old.lower - c * v) for n in small.linear_limits)


def test_freeze_folds_transmission_errors():
    """A frozen joint with a harmonic transmission error: its frames see value + dq(value);
    reference: the full robot's FK (with its transmission error) at that value."""
    robot = jwarp.robot("arm7")
    h = np.zeros((robot.n_dof, 2, 2))
    h[2] = [[0.01, -0.02], [0.005, 0.003]]
    rh = robot.copy(harmonic=h)
    v = 0.4
    small = freeze_joints(rh, {robot.joint_names[2]: v})
    assert small.harmonic.shape == (robot.n_dof - 1, 2, 2) and not small.has_harmonic
    Q = np.random.default_rng(0).uniform(-1, 1, (10, small.n_dof))
    Qf = np.insert(Q, 2, v, axis=1)
    a = np.asarray(jwarp.fk(small, Q, device="cpu"), np.float64)
    b = np.asarray(jwarp.fk(rh, Qf, device="cpu"), np.float64)
    c = np.asarray(jwarp.fk(robot, Qf, device="cpu"), np.float64)
    assert np.abs(b - c).max() > 1e-3            # the error matters ...
    assert np.abs(a - b).max() < 1e-6            # ... and is kept


def test_freeze_errors():
    m = jwarp.robot("arm7")
    with pytest.raises(ValueError, match="values: unknown joint 'nope'"):
        freeze_joints(m, {"nope": 0.0})
    lo, hi = m.joint_limits[0]
    with pytest.raises(ValueError, match=rf"values\['{m.joint_names[0]}'\]: .* outside the "
                                         rf"joint's limits"):
        freeze_joints(m, {m.joint_names[0]: hi + 0.1})
    with pytest.raises(ValueError, match="freezes every joint"):
        freeze_joints(m, {n: 0.0 for n in m.joint_names})
    with pytest.raises(TypeError, match="values: expected a mapping"):
        freeze_joints(m, 3)


def test_moveit_states_may_name_frozen_joints(tmp_path):
    # joint names that no other rule of moveit.joint_vector would ignore
    urdf = tmp_path / "r.urdf"
    urdf.write_text("""<robot name="r">
      <link name="base"/><link name="upper"/><link name="fore"/>
      <joint name="shoulder" type="revolute"><parent link="base"/><child link="upper"/>
        <axis xyz="0 0 1"/><limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
      <joint name="elbow" type="revolute"><parent link="upper"/><child link="fore"/>
        <origin xyz="0.3 0 0"/><axis xyz="0 0 1"/><limit lower="-2" upper="2" effort="1"
        velocity="1"/></joint></robot>""")
    from jwarp.world.moveit import joint_vector

    full = load_urdf(urdf).model
    with pytest.raises(ValueError, match="unknown joint"):
        joint_vector(full.copy(joints=full.joints), {"shoulder": 0.1, "elbow": 0.2, "wrist": 0},
                     "start")
    m = full.freeze({"elbow": 0.5})
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        q = joint_vector(m, {"shoulder": 0.1, "elbow": 0.2}, "start")
    assert q.tolist() == [0.1]
    assert len(w) == 1 and "'elbow' = 0.2" in str(w[0].message)



def test_joint_vector_needs_no_name_for_errors(tmp_path):
    """Issue 39 (the first hour): ``joint_vector(model, values)`` works without the name
    its errors use (default "joint values"); a name that is not a string is a TypeError
    naming ``what``."""
    from jwarp.world.moveit import joint_vector

    arm = jwarp.robot("arm7")
    values = {n: 0.1 * i for i, n in enumerate(arm.joint_names)}
    assert joint_vector(arm, values).tolist() == pytest.approx(list(values.values()))
    with pytest.raises(ValueError, match=r"^joint values: no value for joint\(s\) "):
        joint_vector(arm, dict(list(values.items())[1:]))
    with pytest.raises(ValueError, match=r"^goal: no value for joint\(s\) "):
        joint_vector(arm, dict(list(values.items())[1:]), "goal")
    fallback = np.full(arm.n_dof, 0.5)
    q = joint_vector(arm, dict(list(values.items())[1:]), fallback=fallback)
    assert q[0] == 0.5 and q[1:].tolist() == pytest.approx(list(values.values())[1:])
    with pytest.raises(TypeError, match="^what: expected the name"):
        joint_vector(arm, values, 3)

def test_default_end_effectors():
    panda = load_urdf(_erd(PANDA)).model
    assert list(panda.end_effectors) == ["panda_hand_tcp"]
    assert list(default_end_effectors(panda.freeze({"panda_finger_joint1": 0.04}))) == \
        ["panda_hand_tcp"]
    baxter = load_urdf(_erd(BAXTER)).model
    from lxml import etree

    root = etree.parse(_erd(BAXTER)).getroot()
    parents = {j.find("parent").get("link") for j in root.findall("joint")}
    leaves = [link.get("name") for link in root.findall("link") if link.get("name") not in parents]
    assert len(leaves) > 20                     # every leaf link: what the import used to give
    assert sorted(baxter.end_effectors) == ["left_gripper", "right_gripper"]
    ur = load_urdf(_erd("ur_description/urdf/ur10_robot.urdf")).model
    assert list(ur.end_effectors) == ["tool0"]


def test_default_end_effector_of_unnamed_parallel_jaws(tmp_path):
    """Two prismatic leaf joints under one body are a gripper: the tool is that body's
    unbranched end (no tool-like names anywhere)."""
    def joint(name, kind, parent, child, xyz="0 0 0", axis="0 0 1"):
        lim = '<limit lower="-1" upper="1" effort="1" velocity="1"/>'
        return (f'<joint name="{name}" type="{kind}"><parent link="{parent}"/>'
                f'<child link="{child}"/><origin xyz="{xyz}"/><axis xyz="{axis}"/>{lim}</joint>')
    links = ["base", "l1", "l2", "palm", "a", "b"]
    text = ("<robot name='r'>" + "".join(f"<link name='{n}'/>" for n in links)
            + joint("j1", "revolute", "base", "l1") + joint("j2", "revolute", "l1", "l2", "0.3 0 0")
            + joint("p", "fixed", "l2", "palm", "0.1 0 0")
            + joint("s1", "prismatic", "palm", "a", axis="0 1 0")
            + joint("s2", "prismatic", "palm", "b", axis="0 -1 0") + "</robot>")
    path = tmp_path / "jaw.urdf"
    path.write_text(text)
    assert list(load_urdf(path).model.end_effectors) == ["palm"]


def test_cli_group_and_errors(tmp_path, capsys):
    from jwarp.cli.main import main

    urdf, srdf = _erd(PANDA), _erd(PANDA_SRDF)
    out = tmp_path / "arm.json"
    base = ["import-urdf", urdf, "--out", str(out), "--spheres", "none"]
    assert main(base + ["--srdf", srdf, "--group", "arm", "--state", "default", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["dof"] == 7 and summary["end_effectors"] == ["end_effector"]
    assert summary["frozen_joints"] == {"panda_finger_joint1": 0.001}
    assert jwarp.robot(str(out)).n_dof == 7
    assert main(base + ["--freeze", "panda_finger_joint1=0.02"]) == 0
    assert "frozen: panda_finger_joint1=0.02 (freeze)" in capsys.readouterr().out
    bad = [
        (["--group", "arm"], "--group: needs an SRDF"),
        (["--srdf", srdf, "--group", "nope"], "--group: .*has no <group name=\"nope\">"),
        (["--joints", "panda_joint1,nope"], "--joints: unknown joint 'nope'"),
        (["--joints", "panda_joint1", "--group", "arm", "--srdf", srdf], "--group: give either"),
        (["--joints", "panda_joint1", "--lock", "panda_joint1=0"], "--lock: joint 'panda_joint1' "
                                                                   "is one of the planned"),
        (["--lock", "panda_joint1=0"], "--lock: only with a group or joints"),
        (["--srdf", srdf, "--state", "default"], "--state: only with a group, joints or freeze"),
        (["--joints", "panda_joint1", "--lock", "panda_joint2"], "--lock: expected NAME=VALUE"),
        (["--joints", "panda_joint1", "--lock", "panda_joint2=x"], "--lock: panda_joint2: expected"),
        (["--freeze", "panda_finger_joint1=0.5"], "--freeze: panda_finger_joint1=0.5 m is outside"),
        (["--freeze", "panda_finger_joint2=0.01"], "--freeze: 'panda_finger_joint2' mimics "
                                                   "'panda_finger_joint1'"),
        (["--srdf", srdf, "--joints", "panda_joint1", "--state", "nope"],
         "--state: .*has no <group_state name=\"nope\">"),
        (["--srdf", str(tmp_path / "missing.srdf")], "--srdf: file not found"),
    ]
    bad_xml = tmp_path / "bad.srdf"
    bad_xml.write_text("<robot name='p'>")
    bad.append((["--srdf", str(bad_xml)], f"--srdf: {bad_xml}: not valid XML"))
    out.unlink()
    for extra, match in bad:
        assert main(base + extra) == 2, extra
        err = capsys.readouterr().err
        assert __import__("re").search(match, err), (extra, err)
        assert not out.exists()
