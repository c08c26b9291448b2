"""MoveIt's own Panda SRDF (tests/importers/data/moveit_panda.srdf: moveit_resources'
panda_moveit_config, as MoveIt ships it) on example-robot-data's Panda URDF: what MoveIt
writes is read (``passive_joint`` inside a group, the floating ``virtual_joint``, ...), what
jwarp does not use is named in ONE warning, the file is read and checked before any sphere
fit, MoveIt's allowed-collision semantics (``enable_collisions``,
``disable_default_collisions``), and issue 42's acceptance line: the SRDF's disabled pairs
equal jwarp's skipped pairs plus the ones it reports as adjacent (a cheap sphere fit: the
decision needs spheres on the links and sampled collision rates, not a tight fit)."""

from __future__ import annotations

import json
import time
import warnings
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from jwarp.importers.groups import GroupOptions, plan_group
from jwarp.importers.robot import example_robot_urdf, load_urdf
from jwarp.importers.srdf import (
    USED_ELEMENTS,
    SrdfError,
    SrdfIgnoredWarning,
    disabled_link_pairs,
    parse_srdf,
    read_srdf,
)
from jwarp.model.pair_reasons import moveit_adjacent_pairs, skipped_pairs

MOVEIT_SRDF = str(Path(__file__).parent / "data" / "moveit_panda.srdf")
#: the pairs issue 42 found unchecked by the old import (the Default rule at a bad home)
LINK5_PAIRS = [("panda_link5", "panda_hand"), ("panda_link5", "panda_link7"),
               ("panda_link5", "panda_rightfinger")]
CHEAP = dict(tolerance=0.03, max_spheres=4, refine=False, pair_samples=2000)


def _urdf() -> str:
    try:
        return example_robot_urdf("panda_description/urdf/panda.urdf")
    except ValueError as e:
        pytest.skip(str(e))


def _read(path_or_text: str):
    """(Srdf, the SrdfIgnoredWarnings it gave)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        s = (read_srdf(path_or_text) if not path_or_text.lstrip().startswith("<")
             else parse_srdf(path_or_text))
    return s, [w for w in caught if w.category is SrdfIgnoredWarning]


def _not_used(path: str) -> list[tuple[str, int]]:
    """The elements of the SRDF jwarp does not read, by xml.etree (lines by lxml's count:
    the file's own text, 1-based)."""
    text = Path(path).read_text()
    root = ET.fromstring(text)
    out = [el.tag for el in root if el.tag not in USED_ELEMENTS]
    out += [f"group/{sub.tag}" for g in root.findall("group") for sub in g
            if sub.tag not in ("joint", "link", "chain", "group")]
    return sorted(out)


def test_moveit_panda_srdf_reads_with_one_warning():
    s, warned = _read(MOVEIT_SRDF)
    root = ET.parse(MOVEIT_SRDF).getroot()
    assert len(warned) == 1
    msg = str(warned[0].message)
    assert "<passive_joint> in a <group>" in msg and MOVEIT_SRDF in msg
    assert sorted(t for t, _ in s.ignored) == _not_used(MOVEIT_SRDF) == ["group/passive_joint"]
    line = next(k for k, t in enumerate(Path(MOVEIT_SRDF).read_text().splitlines(), 1)
                if t.strip().startswith("<passive_joint"))
    assert s.ignored == [("group/passive_joint", line)] and f"(line {line})" in msg
    assert s.virtual_joints == ["virtual_joint"]
    assert [(d.link1, d.link2, d.reason) for d in s.disable_collisions] == [
        (e.get("link1"), e.get("link2"), e.get("reason"))
        for e in root.findall("disable_collisions")]
    assert s.state_names == ["ready", "extended", "transport", "open", "close"]
    assert s.groups["hand"].joints == ["panda_finger_joint1"]       # not the passive joint
    # the whole import path: group, state and end-effector of the MoveIt file
    res = plan_group(load_urdf(_urdf()), GroupOptions(srdf=s, group="panda_arm",
                                                      state="ready"))
    assert res.model.n_dof == 7 and res.end_effectors_from == "srdf end_effector"
    assert res.model.end_effectors == {"hand": res.model.frame_index("panda_link8")}


def test_unused_elements_one_warning_listing_all():
    text = """<robot name="panda">
  <virtual_joint name="world_joint" type="fixed" parent_frame="world" child_link="panda_link0"/>
  <passive_joint name="panda_finger_joint2"/>
  <passive_joint name="panda_finger_joint1"/>
  <group name="arm"><joint name="panda_joint1"/><passive_joint name="x"/></group>
  <link_sphere_approximation link="panda_link0"><sphere center="0 0 0" radius="0.1"/>
  </link_sphere_approximation>
  <joint_property joint_name="panda_joint1" property_name="angular_distance_weight" value="1"/>
  <something_new/>
  <disable_collisions link1="panda_link0" link2="panda_link1" reason="Adjacent"/>
</robot>"""
    s, warned = _read(text)
    assert len(warned) == 1
    msg = str(warned[0].message)
    assert msg.startswith("<srdf>: 6 elements jwarp does not use are ignored")
    for part in ("<passive_joint> x2 (line 3)", "<passive_joint> in a <group> (line 5)",
                 "<link_sphere_approximation> (line 6)", "<joint_property> (line 8)",
                 "<something_new> (line 9)"):
        assert part in msg, part
    assert len(s.disable_collisions) == 1 and s.virtual_joints == ["world_joint"]
    _, none = _read("<robot name='p'><group name='g'><joint name='j'/></group></robot>")
    assert none == []


def test_moveit_collision_matrix_semantics():
    """MoveIt's ACM: disable_collisions pairs, every pair of a disable_default_collisions
    link, less the enable_collisions pairs (checked whatever else says)."""
    s, _ = _read("""<robot name="p">
  <disable_default_collisions link="panda_hand"/>
  <enable_collisions link1="panda_hand" link2="panda_link5" reason="keep"/>
  <enable_collisions link1="panda_link2" link2="panda_link3"/>
  <disable_collisions link1="panda_link0" link2="panda_link1" reason="Adjacent"/>
  <disable_collisions link1="panda_link2" link2="panda_link3" reason="Adjacent"/>
</robot>""")
    links = ["panda_link0", "panda_link1", "panda_link2", "panda_link3", "panda_link5",
             "panda_hand", "panda_leftfinger"]
    got = disabled_link_pairs(s, links)
    want = {frozenset(("panda_hand", x)) for x in links if x not in ("panda_hand",
                                                                        "panda_link5")}
    want |= {frozenset(("panda_link0", "panda_link1"))}
    assert set(got) == want
    assert got[frozenset(("panda_link0", "panda_link1"))] == \
        "disable_collisions line 5, reason Adjacent"
    assert "disable_default_collisions line 2" in got[frozenset(("panda_hand", "panda_link0"))]
    # names the URDF lacks: checked strictly, pruned with the others
    bad = parse_srdf("<robot name='p'><enable_collisions link1='panda_link0' link2='ghost'/>"
                     "</robot>", source="bad.srdf")
    from jwarp.importers.srdf import check_srdf, prune_srdf
    imp = load_urdf(_urdf())
    names, joints = set(imp.source.link_frames), set(imp.source.urdf_joints)
    with pytest.raises(SrdfError, match=r"bad.srdf: <enable_collisions> \(line 1\) link2: "
                                        r"unknown link 'ghost'"):
        check_srdf(bad, names, joints)
    assert prune_srdf(bad, names, joints).enable_collisions == []
    # the import: the hand unchecked against all but link5
    res = plan_group(imp, GroupOptions(srdf=s))
    m = res.model
    A = m.allowed_collision_pairs
    assert A[m.frame_index("panda_hand"), m.frame_index("panda_link5")]
    assert not A[m.frame_index("panda_hand"), m.frame_index("panda_link0")]
    assert A[m.frame_index("panda_link2"), m.frame_index("panda_link3")]


@pytest.fixture(scope="module")
def cheap_panda():
    """example-robot-data's Panda with a cheap sphere fit (about 4 s; 2000 pair samples)."""
    from jwarp.world.spherize import SpherizeOptions, spherize

    imp = load_urdf(_urdf())
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model, rep = spherize(imp, SpherizeOptions(**CHEAP))
    return imp, model, rep


def test_adjacency_rule_is_moveits_on_the_panda(cheap_panda):
    """jwarp's Adjacent rule (links joined directly or through links without geometry)
    gives exactly the pairs MoveIt's setup assistant wrote as reason="Adjacent"."""
    imp, model, rep = cheap_panda
    n = model.frame_names
    mine = {frozenset((n[a], n[b])) for a, b in moveit_adjacent_pairs(model)}
    root = ET.parse(MOVEIT_SRDF).getroot()
    moveit = {frozenset((d.get("link1"), d.get("link2")))
              for d in root.findall("disable_collisions") if d.get("reason") == "Adjacent"}
    assert mine == moveit and len(mine) == 10
    assert frozenset(("panda_link7", "panda_hand")) in mine     # through panda_link8
    assert frozenset(("panda_link6", "panda_hand")) not in mine  # rigid, but not adjacent


def test_acceptance_moveit_srdf_pairs_equal_skipped_plus_adjacent(cheap_panda):
    """Issue 42: MoveIt's Panda SRDF imports, and its disabled pairs equal jwarp's skipped
    pairs plus the ones jwarp reports as adjacent; the link5 pairs stay checked, and every
    skipped pair says why."""
    imp, model, rep = cheap_panda
    s, _ = _read(MOVEIT_SRDF)
    res = plan_group(imp, GroupOptions(srdf=s), model=model)
    rows = skipped_pairs(res.model)
    skipped = {frozenset(r["links"]) for r in rows}
    adjacent = {frozenset(r["links"]) for r in rows if r["reason"] == "Adjacent"}
    srdf = {frozenset((d.link1, d.link2)) for d in s.disable_collisions}
    assert srdf | adjacent == skipped
    assert {r["reason"] for r in rows} <= {"SRDF", "Adjacent"}
    for r in rows:
        assert r["why"], r
        if r["reason"] == "SRDF":
            assert r["why"].startswith("disable_collisions line ")
    A = res.model.allowed_collision_pairs
    for a, b in LINK5_PAIRS:
        assert A[res.model.frame_index(a), res.model.frame_index(b)], (a, b)
    # without the SRDF: Adjacent, Always and Never (MoveIt's sampled rules) only, and the
    # link5 pairs checked too (the old import unchecked them at its home)
    own = skipped_pairs(model)
    assert {r["reason"] for r in own} <= {"Adjacent", "Always", "Never"}
    A = model.allowed_collision_pairs
    for a, b in LINK5_PAIRS:
        assert A[model.frame_index(a), model.frame_index(b)], (a, b)
    # "add": the sampled never pairs stay unchecked too; each pair keeps its reason
    res = plan_group(imp, GroupOptions(srdf=s, srdf_collisions="add"), model=model)
    got = {frozenset(r["links"]): r["reason"] for r in skipped_pairs(res.model)}
    assert set(got) == srdf | {frozenset(r["links"]) for r in own}


def test_group_resampled_keeps_the_srdf_decision(cheap_panda):
    """A planning group (``--group panda_arm``: the fingers frozen): the pairs sampled again
    over the 7 arm joints add no never-colliding pair (``never=False``, the SRDF decides
    those); the skipped pairs are the SRDF's plus adjacent, always-colliding and frozen
    ones, and the link5 pairs stay checked."""
    from jwarp.world.spherize import SpherizeOptions, resample_pairs

    imp, model, rep = cheap_panda
    s, _ = _read(MOVEIT_SRDF)
    g = plan_group(imp, GroupOptions(srdf=s, group="panda_arm"), model=model)
    out, pairs = resample_pairs(g.model, model.self_collision.exclude_pairs,
                                SpherizeOptions(**CHEAP), never=False)
    assert out.n_dof == 7 and pairs.never_colliding == []
    rows = skipped_pairs(out)
    srdf = {frozenset((d.link1, d.link2)) for d in s.disable_collisions}
    other = {frozenset(r["links"]) for r in rows if r["reason"] != "SRDF"}
    assert {frozenset(r["links"]) for r in rows} == srdf | other
    assert {r["reason"] for r in rows if frozenset(r["links"]) in other} <= {
        "Adjacent", "Always", "Frozen"}
    A = out.allowed_collision_pairs
    for a, b in LINK5_PAIRS:
        assert A[out.frame_index(a), out.frame_index(b)], (a, b)
    # with never=True (--srdf-collisions add) the sampled never pairs are unchecked too
    # (here all of them are the SRDF's as well: the SRDF's reason is the one recorded)
    out2, pairs2 = resample_pairs(g.model, model.self_collision.exclude_pairs,
                                  SpherizeOptions(**CHEAP))
    A2 = out2.allowed_collision_pairs
    assert pairs2.never_colliding and not any(A2[a, b] for a, b in pairs2.never_colliding)


def test_cli_srdf_parsed_before_the_fit(tmp_path, capsys, monkeypatch):
    """A bad --srdf (or a --home state it lacks) fails before any sphere fit (the fit is
    replaced by one that fails the test), in well under a second of the import's work."""
    import jwarp.world.spherize as spherize_mod
    from jwarp.cli.main import main

    def no_fit(*a, **k):
        raise AssertionError("the sphere fit ran before the SRDF was checked")

    monkeypatch.setattr(spherize_mod, "spherized_robot", no_fit)
    monkeypatch.setattr(spherize_mod, "spherize", no_fit)
    urdf = _urdf()
    load_urdf(urdf)                               # imports warm, as the import's own
    bad = tmp_path / "bad.srdf"
    cases = [("<robot name='p'><disable_collisions link1='panda_link0' link2='ghost'/>"
              "<group name='arm'><joint name='ghost_joint'/></group></robot>",
              ["--group", "arm"], "--group: "),
             ("<robot name='p'><group name='g'", [], "--srdf: "),
             ("<robot name='p'><group_state name='s' group='nope'/></robot>",
              ["--state", "s", "--joints", "panda_joint1"], "unknown group 'nope'"),
             (Path(MOVEIT_SRDF).read_text(), ["--home", "nowhere"],
              "--home: ")]
    for text, extra, match in cases:
        bad.write_text(text)
        t0 = time.perf_counter()
        code = main(["import-urdf", urdf, "--out", str(tmp_path / "p.json"), "--srdf",
                     str(bad)] + extra)
        took = time.perf_counter() - t0
        err = capsys.readouterr().err
        assert code == 2 and match in err, (extra, err)
        assert took < 1.0, took
    assert "state" in err and "ready" in err        # the known states named


def test_cli_moveit_srdf_import(tmp_path, capsys, monkeypatch):
    """``import-urdf --srdf`` with MoveIt's file: one warning line for the passive joint,
    every unchecked pair listed with its reason (the SRDF's and the adjacent ones), the
    default home (a self-collision: link5 in the hand) replaced by the SRDF's 'ready'."""
    from jwarp.cli.main import main

    monkeypatch.setenv("JWARP_CACHE", str(tmp_path / "cache"))
    out = tmp_path / "panda.json"
    args = ["import-urdf", _urdf(), "--out", str(out), "--srdf", MOVEIT_SRDF,
            "--tolerance", str(CHEAP["tolerance"]), "--max-spheres",
            str(CHEAP["max_spheres"]), "--no-refine", "--pair-samples",
            str(CHEAP["pair_samples"])]
    assert main(args) == 0
    text = capsys.readouterr().out
    assert text.count("jwarp does not use") == 1 and "<passive_joint> in a <group>" in text
    assert "self-collision pairs not checked: 34 (SRDF 34)" in text
    assert "home (SRDF group_state 'ready'): free; replaced zeros projected into the limits " \
           "(self-collision: panda_link5/panda_hand" in text
    assert main(args + ["--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    s, _ = _read(MOVEIT_SRDF)
    srdf = {frozenset((d.link1, d.link2)) for d in s.disable_collisions}
    rows = doc["skipped_pairs"]
    adjacent = {frozenset(r["links"]) for r in rows if r["reason"] == "Adjacent"}
    assert {frozenset(r["links"]) for r in rows} == srdf | adjacent
    assert doc["srdf"]["ignored"] == [f"group/passive_joint (line {s.ignored[0][1]})"]
    ready = s.state("ready")
    import jwarp
    m = jwarp.robot(str(out))
    home = json.loads(m.notes["home"])
    assert [home[m.joint_index(j)] for j in ready] == pytest.approx(list(ready.values()))
    for a, b in LINK5_PAIRS:
        assert m.allowed_collision_pairs[m.frame_index(a), m.frame_index(b)]
    # coal on the URDF meshes (pinocchio, not jwarp): the chosen home keeps every checked
    # pair apart; at the default home link5 touches the hand
    pytest.importorskip("pinocchio")
    at_home = _coal_distances(m, home)
    assert min(at_home.values()) > 0.005, min(at_home.items(), key=lambda t: t[1])
    zeros = _coal_distances(m, [min(max(0.0, lo), hi) for lo, hi in m.joint_limits])
    assert zeros[frozenset(("panda_link5", "panda_hand"))] <= 0.0


def _coal_distances(m, q) -> dict:
    """{frozenset(links): coal's smallest distance [m]} of the URDF collision geometry
    (pinocchio) of every pair ``m`` checks, at ``q`` (the finger mimic follows)."""
    import numpy as np
    import pinocchio as pin

    urdf = _urdf()
    pm = pin.buildModelFromUrdf(urdf)
    gm = pin.buildGeomFromUrdf(pm, urdf, pin.GeometryType.COLLISION,
                               package_dirs=[str(Path(urdf).parents[4])])
    names = [pm.frames[g.parentFrame].name for g in gm.geometryObjects]
    qp = pin.neutral(pm)
    for i in range(1, pm.njoints):
        n = "panda_finger_joint1" if pm.names[i] == "panda_finger_joint2" else pm.names[i]
        qp[pm.joints[i].idx_q] = q[m.joint_index(n)]
    A = m.allowed_collision_pairs
    pairs = [(a, b) for a in range(len(names)) for b in range(a + 1, len(names))
             if names[a] != names[b] and A[m.frame_index(names[a]), m.frame_index(names[b])]]
    for a, b in pairs:
        gm.addCollisionPair(pin.CollisionPair(a, b))
    pd, gd = pm.createData(), pin.GeometryData(gm)
    pin.computeDistances(pm, pd, gm, gd, np.asarray(qp))
    out: dict = {}
    for (a, b), r in zip(pairs, gd.distanceResults):
        key = frozenset((names[a], names[b]))
        out[key] = min(out.get(key, np.inf), r.min_distance)
    return out
