"""MoveIt SRDF (jwarp.importers.srdf): the Panda SRDF of example-robot-data read and checked
against counts taken with xml.etree, disable_collisions into the robot's exclude pairs
(``import-urdf --srdf``), export -> import round trip of the pairs (``export-urdf`` writes
the SRDF with the URDF as one set), and malformed SRDFs named by file and element."""

from __future__ import annotations

import json
import os
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

import jwarp
from jwarp.importers.groups import GroupOptions, plan_group
from jwarp.importers.robot import example_robot_urdf, load_urdf
from jwarp.importers.srdf import (
    SrdfError,
    SrdfWarning,
    group_joints,
    parse_srdf,
    read_srdf,
    srdf_path,
)
from jwarp.importers.urdf_export import export_urdf


def _panda() -> tuple[str, str]:
    try:
        urdf = example_robot_urdf("panda_description/urdf/panda.urdf")
        srdf = example_robot_urdf("panda_description/srdf/panda.srdf")
    except ValueError as e:
        pytest.skip(str(e))
    return urdf, srdf


def _pairs(model) -> set[frozenset[str]]:
    """Exclude pairs of ``model`` by frame name."""
    n = model.frame_names
    return {frozenset((n[a], n[b])) for a, b in model.self_collision.exclude_pairs}


def test_read_panda_srdf_matches_etree():
    _, path = _panda()
    root = ET.parse(path).getroot()
    s = read_srdf(path)
    dc = root.findall("disable_collisions")
    assert len(s.disable_collisions) == len(dc) > 0
    assert [(d.link1, d.link2, d.reason) for d in s.disable_collisions] == \
        [(e.get("link1"), e.get("link2"), e.get("reason")) for e in dc]
    assert set(s.groups) == {g.get("name") for g in root.findall("group")}
    arm = root.find("group[@name='arm']")
    assert s.groups["arm"].joints == [j.get("name") for j in arm.findall("joint")]
    st = root.find("group_state")
    assert s.state(st.get("name")) == {
        j.get("name"): float(j.get("value")) for j in st.findall("joint")}
    ee = root.find("end_effector")
    assert [(e.name, e.parent_link) for e in s.end_effectors] == \
        [(ee.get("name"), ee.get("parent_link"))]
    # subgroups resolve to the joints of both groups
    imp = load_urdf(_panda()[0])
    both = group_joints(s, "arm_and_hand", imp.source.urdf_joints)
    assert both == s.groups["arm"].joints + s.groups["hand"].joints


def test_import_adds_srdf_pairs(tmp_path, capsys):
    urdf, srdf = _panda()
    root = ET.parse(srdf).getroot()
    want = {frozenset((e.get("link1"), e.get("link2"))) for e in root.findall("disable_collisions")}
    robot = load_urdf(urdf)
    before = jwarp.robot("arm7")     # any model: the API checks that frames match
    with pytest.raises(ValueError, match="model: its frames"):
        plan_group(robot, GroupOptions(srdf=srdf), model=before)
    # a robot with exclude pairs of its own (as sampled ones): SRDF pairs are added to them
    own = robot.model.copy()
    own.self_collision.exclude_pairs = [(0, 14)]      # panda_link0 - panda_rightfinger
    res = plan_group(robot, GroupOptions(srdf=srdf), model=own)
    names = robot.model.frame_names
    assert _pairs(res.model) == want | {frozenset((names[0], names[14]))}
    assert res.srdf_pairs == len(want) and res.pairs_added == len(want)
    res = plan_group(robot, GroupOptions(srdf=srdf, srdf_collisions="replace"), model=own)
    assert _pairs(res.model) == want
    # end-effectors: the SRDF's <end_effector> parent link
    ee = root.find("end_effector")
    assert res.model.end_effectors == {ee.get("name"): names.index(ee.get("parent_link"))}
    # the CLI says where the pairs came from
    from jwarp.cli.main import main

    out = tmp_path / "panda.json"
    assert main(["import-urdf", urdf, "--out", str(out), "--spheres", "none", "--srdf", srdf,
                 "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["srdf"]["disable_collisions"] == len(want)
    assert _pairs(jwarp.robot(str(out))) == want


def test_export_import_round_trip(tmp_path):
    urdf, srdf = _panda()
    model = plan_group(load_urdf(urdf), GroupOptions(srdf=srdf)).model
    out = tmp_path / "exported.urdf"
    export_urdf(model, out)
    written = srdf_path(out)
    assert written == tmp_path / "exported.srdf" and written.is_file()
    # reasons: the source SRDF's own for its pairs (recorded at import); for the others
    # (frames without geometry) Adjacent exactly where a URDF joint of the exported file
    # joins the links, else Never
    joints = {frozenset((j.find("parent").get("link"), j.find("child").get("link")))
              for j in ET.parse(out).getroot().findall("joint")}
    source = {frozenset((e.get("link1"), e.get("link2"))): e.get("reason")
              for e in ET.parse(srdf).getroot().findall("disable_collisions")}
    for e in ET.parse(written).getroot().findall("disable_collisions"):
        pair = frozenset((e.get("link1"), e.get("link2")))
        assert e.get("reason") == source.get(pair, "Adjacent" if pair in joints else "Never")
    assert {e.get("reason") for e in ET.parse(written).getroot().findall(
        "disable_collisions")} >= {"Default", "Never", "Adjacent"}
    back = plan_group(load_urdf(out), GroupOptions(srdf=written, srdf_collisions="replace"))
    assert _pairs(back.model) == _pairs(model) and len(_pairs(model)) > 0
    # the CLI: export-urdf writes the SRDF beside the URDF; --no-srdf does not
    from jwarp.cli.main import main

    src = tmp_path / "m.json"
    model.save(src)
    assert main(["export-urdf", str(src), "--out", str(tmp_path / "cli.urdf")]) == 0
    assert (tmp_path / "cli.srdf").read_text() == written.read_text().replace(
        "exported", "cli")  # same robot, same pairs
    assert main(["export-urdf", str(src), "--out", str(tmp_path / "none.urdf"),
                 "--no-srdf"]) == 0
    assert not (tmp_path / "none.srdf").exists()


def test_export_failure_leaves_no_srdf(tmp_path, monkeypatch):
    import jwarp.importers.urdf_export as ue

    def boom(*a, **k):
        raise RuntimeError("boom")
    monkeypatch.setattr(ue, "urdf_text", boom)
    with pytest.raises(RuntimeError):
        export_urdf(jwarp.robot("arm7"), tmp_path / "r.urdf")
    assert os.listdir(tmp_path) == []


# (names the URDF lacks are skipped, as MoveIt does: tests/importers/test_srdf_tolerant.py)
BAD = [
    ("<robot name='p'><group name='a'><group name='b'/></group><group name='b'>"
     "<group name='a'/></group></robot>", "subgroups form a cycle"),
    ("<robot name='p'><group_state name='s' group='arm'/></robot>", "unknown group 'arm'"),
    ("<robot name='p'><group name='g'><joint name='panda_joint1'/></group>"
     "<group_state name='s' group='g'><joint name='panda_joint1' value='x'/></group_state>"
     "</robot>", "value 'x' is not finite numbers"),
    ("<robot name='p'><end_effector name='e' parent_link='panda_link7' group='g'/></robot>",
     "unknown group 'g'"),
    ("<robot name='p'><disable_collisions link1='panda_link0'/></robot>",
     "has no 'link2' attribute"),
    ("<robot name='p'><group name='g'><joint name='panda_joint1'/><chain/></group></robot>",
     "<chain> .* has no 'base_link'"),
    ("<robot name='p'><group name='g'", "not valid XML"),
    ("<srdf/>", "root element is <srdf>, expected <robot>"),
]


@pytest.mark.parametrize("text,match", BAD, ids=[str(k) for k in range(len(BAD))])
def test_bad_srdf_names_file_and_element(tmp_path, text, match):
    urdf, _ = _panda()
    path = tmp_path / "bad.srdf"
    path.write_text(text)
    with pytest.raises(ValueError, match=match) as e:
        plan_group(load_urdf(urdf), GroupOptions(srdf=path, joints=["panda_joint1"], state="s"))
    assert str(path) in str(e.value)
    assert isinstance(e.value, SrdfError)


def test_bad_chain_and_missing_group():
    urdf, _ = _panda()
    s = parse_srdf("<robot name='p'><group name='g'><chain base_link='panda_link5' "
                   "tip_link='panda_link2'/></group></robot>", "x.srdf")
    imp = load_urdf(urdf)
    with pytest.raises(ValueError, match=r"x.srdf: <group name=\"g\"> \(line 1\) <chain>: "
                                         r"tip_link 'panda_link2' is not below base_link"):
        plan_group(imp, GroupOptions(srdf=s, group="g"))
    with pytest.raises(ValueError, match=r"group: x.srdf has no <group name=\"h\"> \(its groups: g\)"):
        plan_group(imp, GroupOptions(srdf=s, group="h"))
    with pytest.raises(ValueError, match="state: x.srdf has no <group_state name=\"s\">"):
        plan_group(imp, GroupOptions(srdf=s, joints=["panda_joint1"], state="s"))


def test_srdf_path():
    assert srdf_path("a/b.urdf") == Path("a/b.srdf")
    assert srdf_path("a/b.URDF") == Path("a/b.srdf")
    assert srdf_path("a/b.xml") == Path("a/b.xml.srdf")


@pytest.mark.filterwarnings("ignore::jwarp.importers.srdf.SrdfWarning")
def test_group_states_as_moveit_and_pinocchio_write_them(tmp_path):
    """States of one name in several groups are merged (MoveIt names states per group);
    pinocchio's SRDFs leave out ``group`` and give the floating base 7 numbers; a state
    is checked when it is used."""
    urdf, _ = _panda()
    path = tmp_path / "s.srdf"
    path.write_text("""<robot name="panda">
      <group name="arm"><joint name="panda_joint1"/><joint name="panda_joint2"/></group>
      <group name="hand"><joint name="panda_finger_joint1"/></group>
      <group_state name="home" group="arm"><joint name="panda_joint2" value="-0.5"/></group_state>
      <group_state name="home" group="hand"><joint name="panda_finger_joint1" value="0.02"/>
      </group_state>
      <group_state name="pin"><joint name="root_joint" value="0 0 1 0 0 0 1"/>
        <joint name="panda_joint2" value="0.25"/></group_state>
      <group_state name="other" group="arm"><joint name="nope" value="1"/></group_state>
    </robot>""")
    s = read_srdf(path)
    assert s.state("home") == {"panda_joint2": -0.5, "panda_finger_joint1": 0.02}
    assert s.state("pin") == {"panda_joint2": 0.25}
    imp = load_urdf(urdf)
    with pytest.warns(SrdfWarning, match="1 entries name links or joints the URDF lacks.*'nope'"):
        res = plan_group(imp, GroupOptions(srdf=path, joints=["panda_joint1"], state="home"))
    assert res.frozen["panda_joint2"] == -0.5 and res.frozen["panda_finger_joint1"] == 0.02
    assert res.source["panda_joint3"] == "default" and res.frozen["panda_joint3"] == 0.0
    res = plan_group(imp, GroupOptions(srdf=path, joints=["panda_joint1"], state="pin"))
    assert res.frozen["panda_joint2"] == 0.25
    with pytest.raises(ValueError, match=r"<group_state name=\"other\"> \(line 9\): unknown "
                                         r"joint 'nope'"):
        plan_group(imp, GroupOptions(srdf=path, joints=["panda_joint1"], state="other"))


# ------------------------------------------------ reliability 4, item 2: the export's set
USER_SRDF = ("<?xml version='1.0'?>\n<robot name='mine'><group name='arm'>"
             "<chain base_link='a' tip_link='b'/></group></robot>\n")


def test_export_never_overwrites_a_users_srdf(tmp_path, capsys):
    """``import-urdf robot.urdf --srdf robot.srdf`` then ``export-urdf --out robot.urdf``:
    the user's SRDF beside --out is refused before any work, not overwritten; --no-srdf
    writes the URDF and says the SRDF there is not this export's; an SRDF an earlier export
    of the same URDF wrote is replaced (and removed, with a warning, under --no-srdf)."""
    from jwarp.cli.main import main

    robot = jwarp.robot("arm7")
    out = tmp_path / "robot.urdf"
    mine = tmp_path / "robot.srdf"
    mine.write_text(USER_SRDF)
    with pytest.raises(ValueError, match=r"path: .*robot.srdf exists and is not an SRDF "
                                         r"that export-urdf wrote for robot.urdf"):
        export_urdf(robot, out)
    assert sorted(os.listdir(tmp_path)) == ["robot.srdf"] and mine.read_text() == USER_SRDF
    assert main(["export-urdf", "arm7", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "--out: " in err and "robot.srdf" in err and "--no-srdf" in err
    assert sorted(os.listdir(tmp_path)) == ["robot.srdf"] and mine.read_text() == USER_SRDF
    assert main(["export-urdf", "arm7", "--out", str(out), "--no-srdf"]) == 0
    err = capsys.readouterr().err
    assert f"left {mine} alone" in err and "may not describe this URDF" in err
    assert out.is_file() and mine.read_text() == USER_SRDF
    # an SRDF written by an export of this URDF is the export's to replace or remove
    mine.unlink()
    export_urdf(robot, out)
    first = mine.read_text()
    assert export_urdf(robot.copy(name="other"), out) == [] and mine.read_text() != first
    w = export_urdf(robot, out, options=jwarp.importers.urdf_export.UrdfExportOptions(
        srdf=False))
    assert not mine.exists() and len(w) == 1 and "removed the SRDF" in w[0]
    # an export SRDF of another URDF of the same stem ("robot.urdf" vs "robot.xml" -> no
    # clash; a renamed copy) is not this export's either
    other = tmp_path / "robot.srdf"
    export_urdf(robot, tmp_path / "copy.urdf")
    (tmp_path / "copy.srdf").rename(other)
    with pytest.raises(ValueError, match="not an SRDF that export-urdf wrote for robot.urdf"):
        export_urdf(robot, out)


class _Killed(BaseException):
    """A kill between two renames: no clean-up runs."""


def _kill_after(monkeypatch, k):
    """export_urdf's commit: the first ``k`` renames happen, then the process "dies" (the
    others' temporary files are dropped here: after a real SIGKILL the next write of the
    target removes those of the dead process, jwarp.utils.atomic.clean_stale)."""
    import jwarp.importers.urdf_export as ue

    def commit_all(files):
        files = list(files)
        for f in files[:k]:
            f.commit()
        for f in files[k:]:
            f.discard()
        raise _Killed()
    monkeypatch.setattr(ue, "commit_all", commit_all)


@pytest.mark.parametrize("k", [0, 1, 2, 3])
def test_export_killed_between_renames_leaves_a_detected_set(tmp_path, monkeypatch, capsys, k):
    """export-urdf writes the side file, the SRDF and the URDF (in that order, the URDF
    last). Killed after ``k`` renames over an earlier export: every mixed set (a new side
    file or SRDF beside the old URDF) is reported by export_set_problems and by
    import-urdf; the whole old (k=0) and whole new (k=3) sets report nothing."""
    from jwarp.importers.urdf_export import export_set_problems, side_file_path

    base = jwarp.robot("arm7")
    kappa = np.zeros((base.n_frames, 3))
    kappa[base.is_dh, 2] = 1e-4
    old, new = base.copy(kappa=kappa), base.copy(kappa=2 * kappa, name="new")
    out = tmp_path / "robot.urdf"
    export_urdf(old, out)
    assert export_set_problems(out) == []
    _kill_after(monkeypatch, k)
    with pytest.raises(_Killed):
        export_urdf(new, out)
    monkeypatch.undo()
    new_side = "'new'" in side_file_path(out).read_text() or '"new"' in side_file_path(
        out).read_text()
    new_srdf = "robot 'new'" in srdf_path(out).read_text()
    new_urdf = "robot 'new'" in out.read_text()
    assert (new_side, new_srdf, new_urdf) == (k >= 1, k >= 2, k >= 3)
    problems = export_set_problems(out)
    assert len(problems) == {0: 0, 1: 1, 2: 2, 3: 0}[k], problems
    if k == 1:
        assert problems[0].startswith(f"side file {side_file_path(out)} was written by "
                                      f"export-urdf with another version of {out}")
    if k == 2:
        assert problems[1].startswith(f"SRDF {srdf_path(out)} was written")
    # import-urdf of that URDF says so
    from jwarp.cli.main import main

    assert main(["import-urdf", str(out), "--out", str(tmp_path / "back.json"), "--spheres",
                 "none", "--no-home-fit"]) == 0
    err = capsys.readouterr().err
    assert err.count("jwarp: warning: ") == len(problems)
    for p in problems:
        assert p in " ".join(err.split())
    # the next export makes the set whole again (and removes the killed one's files)
    export_urdf(new, out)
    assert export_set_problems(out) == []
    assert sorted(os.listdir(tmp_path)) == ["back.json", "robot.srdf", "robot.urdf",
                                            "robot.urdf.jwarp.json"]


def test_export_killed_before_removing_a_stale_side_file_or_on_a_first_export(tmp_path,
                                                                              monkeypatch):
    from jwarp.importers.urdf_export import export_set_problems, side_file_path

    base = jwarp.robot("arm7")
    kappa = np.zeros((base.n_frames, 3))
    kappa[base.is_dh, 2] = 1e-4
    out = tmp_path / "robot.urdf"
    # a first export killed after the side file: no URDF, the side file says whose it is
    _kill_after(monkeypatch, 1)
    with pytest.raises(_Killed):
        export_urdf(base.copy(kappa=kappa), out)
    monkeypatch.undo()
    p = export_set_problems(out)
    assert len(p) == 1 and "which does not exist" in p[0]
    export_urdf(base.copy(kappa=kappa), out)
    assert export_set_problems(out) == []
    # the rigid robot needs no side file: killed after its renames, before the old side
    # file is removed -> the old side file records another URDF
    import jwarp.importers.urdf_export as ue
    real = ue.commit_all

    def commit_then_die(files):
        real(files)
        raise _Killed()
    monkeypatch.setattr(ue, "commit_all", commit_then_die)
    with pytest.raises(_Killed):
        export_urdf(base.copy(name="rigid"), out)
    monkeypatch.undo()
    assert side_file_path(out).is_file()
    p = export_set_problems(out)
    assert len(p) == 1 and p[0].startswith(f"side file {side_file_path(out)}")


def test_srdf_collisions_without_an_srdf_is_refused(tmp_path, capsys):
    """Reliability round 4, item 8: ``--srdf-collisions`` without ``--srdf`` was accepted
    and ignored."""
    from jwarp.cli.main import main

    with pytest.raises(ValueError, match="srdf_collisions: 'replace' only with an SRDF"):
        GroupOptions(srdf_collisions="replace").validate()
    GroupOptions().validate()                 # the default "add" says nothing
    urdf = tmp_path / "r.urdf"
    export_urdf(jwarp.robot("planar4"), urdf, options=jwarp.importers.urdf_export.UrdfExportOptions(
        srdf=False))
    for how in ("add", "replace"):
        assert main(["import-urdf", str(urdf), "--out", str(tmp_path / "r.json"), "--spheres",
                     "none", "--srdf-collisions", how]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert err[-1].startswith("jwarp: error: --srdf-collisions: only with --srdf")
    assert not (tmp_path / "r.json").exists()
