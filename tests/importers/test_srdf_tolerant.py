"""SRDF entries naming links or joints the URDF lacks are skipped with one warning, as
MoveIt's loader does (jwarp.importers.srdf.prune_srdf via groups.load_srdf); an error only
where the group or state asked for is broken. Synthetic SRDFs on the Panda URDF, and the
real Baxter and Z1 SRDFs of example-robot-data (which the strict check refused), each
compared with counts taken with xml.etree from the SRDF and the URDF."""

from __future__ import annotations

import warnings
import xml.etree.ElementTree as ET

import pytest

from jwarp.importers.groups import GroupOptions, plan_group
from jwarp.importers.robot import example_robot_urdf, load_urdf
from jwarp.importers.srdf import SrdfError, SrdfWarning


def _erd(path: str) -> str:
    try:
        return example_robot_urdf(path)
    except ValueError as e:
        pytest.skip(str(e))


def _urdf_names(urdf: str) -> tuple[set[str], set[str]]:
    """(links, joints) of a URDF file, read with xml.etree."""
    root = ET.parse(urdf).getroot()
    return ({e.get("name") for e in root.findall("link")},
            {e.get("name") for e in root.findall("joint")})


def _expected_skips(srdf: str, links: set[str], joints: set[str]) -> dict[str, int]:
    """Per element, how many names of ``srdf`` (xml.etree) the URDF lacks."""
    root = ET.parse(srdf).getroot()
    out = {"group": 0, "group_state": 0, "end_effector": 0, "disable_collisions": 0}
    for g in root.findall("group"):
        out["group"] += sum(j.get("name") not in joints for j in g.findall("joint"))
        out["group"] += sum(k.get("name") not in links for k in g.findall("link"))
        out["group"] += sum(c.get("base_link") not in links or c.get("tip_link") not in links
                            for c in g.findall("chain"))
    for st in root.findall("group_state"):
        out["group_state"] += sum(j.get("name") not in joints for j in st.findall("joint"))
    for e in root.findall("end_effector"):
        out["end_effector"] += e.get("parent_link") not in links
    for d in root.findall("disable_collisions"):
        out["disable_collisions"] += d.get("link1") not in links or d.get("link2") not in links
    return out


def _load(urdf: str, srdf, **options):
    """plan_group with the SRDF: (result, the warnings it gave)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = plan_group(load_urdf(urdf), GroupOptions(srdf=srdf, **options))
    return res, [w for w in caught if issubclass(w.category, SrdfWarning)]


SYNTH = """<robot name="panda">
  <group name="arm"><joint name="panda_joint1"/><joint name="ghost_joint"/>
    <joint name="panda_joint2"/></group>
  <group name="hand"><joint name="ghost_finger"/><link name="ghost_link"/></group>
  <group name="both"><group name="arm"/><group name="hand"/></group>
  <group name="wrist"><chain base_link="panda_link5" tip_link="panda_link7"/></group>
  <group_state name="home" group="arm"><joint name="panda_joint2" value="-0.5"/>
    <joint name="ghost_joint" value="1"/></group_state>
  <group_state name="gone" group="wrist"><joint name="ghost_joint" value="1"/></group_state>
  <end_effector name="tool" parent_link="ghost_link" group="wrist"/>
  <end_effector name="flange" parent_link="panda_link7" group="wrist"/>
  <disable_collisions link1="panda_link0" link2="ghost_link" reason="Never"/>
  <disable_collisions link1="panda_link0" link2="panda_link5" reason="Never"/>
</robot>"""


def test_unknown_names_skipped_with_one_warning(tmp_path):
    urdf = _erd("panda_description/urdf/panda.urdf")
    path = tmp_path / "s.srdf"
    path.write_text(SYNTH)
    links, joints = _urdf_names(urdf)
    want = _expected_skips(str(path), links, joints)
    res, warned = _load(urdf, path)
    assert len(warned) == 1, [str(w.message) for w in warned]
    msg = str(warned[0].message)
    assert str(path) in msg and "'ghost_joint'" in msg and "MoveIt" in msg
    s = res.srdf
    # per element, the entries naming unknown names (whole drops are extra rows)
    got = {k: sum(1 for x in s.skipped if x.element == k and not x.whole) for k in want}
    want["end_effector"] = 1      # the tool's unknown link
    assert got == want, s.skipped
    assert set(s.groups) == {"arm", "both", "wrist"}          # "hand" lost every member
    assert s.groups["arm"].joints == ["panda_joint1", "panda_joint2"]
    assert s.groups["both"].subgroups == ["arm"]
    assert [e.name for e in s.end_effectors] == ["flange"]
    assert [(d.link1, d.link2) for d in s.disable_collisions] == [("panda_link0", "panda_link5")]
    assert res.srdf_pairs == 1
    n = res.model.frame_names
    assert (n.index("panda_link0"), n.index("panda_link5")) in {
        tuple(sorted(p)) for p in res.model.self_collision.exclude_pairs}
    # a state keeps its known joints
    assert s.state("home") == {"panda_joint2": -0.5}
    res, _ = _load(urdf, path, joints=["panda_joint1"], state="home")
    assert res.frozen["panda_joint2"] == -0.5
    # a group that kept every member can be planned with
    res, _ = _load(urdf, path, group="wrist")
    assert res.planned == ["panda_joint6", "panda_joint7"]


def test_broken_group_or_state_asked_for_is_an_error(tmp_path):
    urdf = _erd("panda_description/urdf/panda.urdf")
    path = tmp_path / "s.srdf"
    path.write_text(SYNTH)
    for group in ("arm", "hand", "both"):
        with pytest.raises(SrdfError, match=rf"group: {path}: <group name=\"{group}\"> \(line "
                                            rf"\d+\) names what the URDF lacks: .*ghost_"):
            _load(urdf, path, group=group)
    with pytest.raises(SrdfError, match=r"state: .*<group_state name=\"gone\"> \(line 9\): "
                                        r"unknown joint 'ghost_joint'"):
        _load(urdf, path, joints=["panda_joint1"], state="gone")


def test_baxter_srdf_loads(tmp_path):
    """baxter_manipulation.srdf names joints 'baxter/...': its groups and state are dropped,
    its disable_collisions between the URDF's links are kept."""
    urdf = _erd("baxter_description/urdf/baxter.urdf")
    srdf = _erd("baxter_description/srdf/baxter_manipulation.srdf")
    links, joints = _urdf_names(urdf)
    want = _expected_skips(srdf, links, joints)
    res, warned = _load(urdf, srdf)
    assert len(warned) == 1 and "'baxter/head_pan'" in str(warned[0].message)
    s = res.srdf
    got = {k: sum(1 for x in s.skipped if x.element == k and not x.whole) for k in want}
    assert got == want
    root = ET.parse(srdf).getroot()
    kept = [(d.get("link1"), d.get("link2")) for d in root.findall("disable_collisions")
            if d.get("link1") in links and d.get("link2") in links]
    assert len(kept) > 300
    assert [(d.link1, d.link2) for d in s.disable_collisions] == kept
    assert s.groups == {} and s.group_states == []
    n = res.model.frame_names
    excl = {tuple(sorted(p)) for p in res.model.self_collision.exclude_pairs}
    assert excl == {tuple(sorted((n.index(a), n.index(b)))) for a, b in kept if a != b}
    with pytest.raises(SrdfError, match="neutral.*unknown joint 'baxter/head_pan'.*nothing of "
                                        "the state"):
        s.state("neutral")


def test_z1_srdf_loads():
    """z1.srdf's chain starts at 'base', which z1.urdf lacks: the chain is skipped, the
    group keeps its six joints; its states load."""
    urdf = _erd("z1_description/urdf/z1.urdf")
    srdf = _erd("z1_description/srdf/z1.srdf")
    links, joints = _urdf_names(urdf)
    want = _expected_skips(srdf, links, joints)
    assert want["group"] == 1
    res, warned = _load(urdf, srdf)
    assert len(warned) == 1 and "'base'" in str(warned[0].message)
    s = res.srdf
    assert [(x.element, x.owner) for x in s.skipped] == [("group", "end_effector")]
    root = ET.parse(srdf).getroot()
    g = root.find("group[@name='end_effector']")
    assert s.groups["end_effector"].joints == [j.get("name") for j in g.findall("joint")]
    assert s.groups["end_effector"].chains == []
    st = root.find("group_state[@name='home']")
    assert s.state("home") == {j.get("name"): float(j.get("value")) for j in st.findall("joint")}
    # the group lost its chain: asking for it is an error, asking for its joints is not
    with pytest.raises(SrdfError, match="group: .*end_effector.*chain base -> gripperMover"):
        _load(urdf, srdf, group="end_effector")
    res, _ = _load(urdf, srdf, joints=[j.get("name") for j in g.findall("joint")],
                   state="arm_up")
    assert res.planned == [j.get("name") for j in g.findall("joint")]
