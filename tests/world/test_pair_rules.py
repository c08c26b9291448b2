"""MoveIt setup assistant's pair rules as the URDF import applies them
(jwarp.world.self_pairs with ``adjacency="moveit"``, ``always_fraction=0.95``;
jwarp.model.pair_reasons): small synthetic URDFs whose collision rates are known in closed
form (spheres on prismatic joints, uniform samples), so the Adjacent / Always / Never /
checked split is predicted, not read back."""

from __future__ import annotations

import numpy as np
import pytest

from jwarp.importers.robot import load_urdf
from jwarp.model.pair_reasons import moveit_adjacent_pairs, skipped_pairs
from jwarp.world.self_pairs import (
    ALWAYS_FRACTION,
    adjacent_pairs,
    never_colliding_pairs,
    with_self_pairs,
)
from jwarp.world.spherize import SpherizeOptions, spherize

R = 0.1          # sphere radius [m]
A_HI = 2 * R / 0.97   # a/s collide for x < 2R: 97 % of [0, A_HI]


def _sphere_link(name: str, r: float = R, z: float = 0.0) -> str:
    return (f'<link name="{name}"><collision><origin xyz="0 0 {z}"/><geometry>'
            f'<sphere radius="{r}"/></geometry></collision></link>')


def _prismatic(name, parent, child, lo, hi, xyz="0 0 0"):
    return (f'<joint name="{name}" type="prismatic"><parent link="{parent}"/>'
            f'<child link="{child}"/><origin xyz="{xyz}"/><axis xyz="1 0 0"/>'
            f'<limit lower="{lo}" upper="{hi}" effort="1" velocity="1"/></joint>')


@pytest.fixture()
def sliders(tmp_path):
    """base (a sphere 1 m below) with four children: s fixed at the origin; a sliding on x
    in [0, 2R/0.97] (meets s 97 % of the time); c on x in [-2R, 0] shifted by -R (meets s
    in half); b on x, 0.5 m aside (never meets anything)."""
    text = ('<robot name="sliders">' + _sphere_link("base", 0.05, -1.0) + _sphere_link("s")
            + _sphere_link("a") + _sphere_link("b") + _sphere_link("c")
            + '<joint name="fs" type="fixed"><parent link="base"/><child link="s"/></joint>'
            + _prismatic("ja", "base", "a", 0.0, A_HI)
            + _prismatic("jb", "base", "b", -0.5, 0.5, "0 0.5 0")
            + _prismatic("jc", "base", "c", -2 * R, 0.0, f"{-R} 0 0")
            + "</robot>")
    path = tmp_path / "sliders.urdf"
    path.write_text(text)
    return str(path)


def _rows(model):
    return {tuple(r["links"]): r for r in skipped_pairs(model)}


def test_always_rule_at_95_percent(sliders):
    imp = load_urdf(sliders)
    model, rep = spherize(imp, SpherizeOptions(pair_samples=4000, seed=3))
    m = model
    p = rep.pairs
    i = m.frame_index
    # the rates are those of the geometry: a/s 97 %, c/s: x_c + R - ... (|x| < 2R) half
    assert p.collision_rate[i("s"), i("a")] == pytest.approx(0.97, abs=0.015)
    assert p.collision_rate[i("s"), i("c")] == pytest.approx(0.5, abs=0.04)
    rows = _rows(m)
    assert rows[("s", "a")]["reason"] == "Always"
    assert "% of 4000 random configurations (>= 95 %)" in rows[("s", "a")]["why"]
    for pair in (("s", "b"), ("a", "b"), ("b", "c")):
        assert rows[pair]["reason"] == "Never", pair
    assert {k for k, r in rows.items() if r["reason"] == "Adjacent"} == {
        ("base", "s"), ("base", "a"), ("base", "b"), ("base", "c")}
    # a and c meet sometimes, s and c half the time: both checked
    A = m.allowed_collision_pairs
    assert A[i("s"), i("c")] and A[i("a"), i("c")]
    assert ("s", "c") not in rows and ("a", "c") not in rows
    # the old rule (every sample) keeps a/s checked: the 95 % rule is what excludes it
    old = never_colliding_pairs(m, n_samples=4000, seed=3)
    assert (i("s"), i("a")) not in old.always_colliding
    assert ALWAYS_FRACTION == 0.95


def test_always_rule_threshold_is_inclusive_and_bounded(sliders):
    m = spherize(load_urdf(sliders), SpherizeOptions(pair_samples=200), sample_pairs=False)[0]
    i = m.frame_index
    p = never_colliding_pairs(m, n_samples=2000, seed=0, adjacency="moveit",
                              always_fraction=0.95)
    rate = p.collision_rate[i("s"), i("a")]
    q = never_colliding_pairs(m, n_samples=2000, seed=0, adjacency="moveit",
                              always_fraction=float(rate))          # exactly the rate
    assert (i("s"), i("a")) in q.always_colliding
    r = never_colliding_pairs(m, n_samples=2000, seed=0, adjacency="moveit",
                              always_fraction=float(rate) + 1e-3)
    assert (i("s"), i("a")) not in r.always_colliding
    for bad in (0.0, 1.5, True):
        with pytest.raises(ValueError, match="always_fraction: expected a share in"):
            never_colliding_pairs(m, n_samples=10, always_fraction=bad)
    with pytest.raises(ValueError, match="adjacency: expected 'rigid' or 'moveit'"):
        never_colliding_pairs(m, n_samples=10, adjacency="tree")


def test_adjacency_through_links_without_geometry(tmp_path):
    """base -(revolute)- l1 -(fixed)- flange (no geometry) -(fixed)- tool, and a camera
    fixed on l1: MoveIt's rule makes l1/tool adjacent (through the flange) but not
    base/tool or tool/cam (l1 between them has geometry); jwarp's rigid rule would join
    all of l1, tool and cam to base."""
    def fixed(name, parent, child, xyz="0 0 0"):
        return (f'<joint name="{name}" type="fixed"><parent link="{parent}"/>'
                f'<child link="{child}"/><origin xyz="{xyz}"/></joint>')
    text = ('<robot name="t">' + _sphere_link("base") + _sphere_link("l1", z=0.5)
            + '<link name="flange"/>' + _sphere_link("tool", z=0.2) + _sphere_link("cam")
            + '<joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>'
              '<axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/>'
              '</joint>'
            + fixed("f1", "l1", "flange", "0 0 1") + fixed("f2", "flange", "tool")
            + fixed("f3", "l1", "cam", "0.5 0 0.5") + "</robot>")
    path = tmp_path / "t.urdf"
    path.write_text(text)
    m = load_urdf(str(path)).model
    n = m.frame_names
    def fs(pairs):
        return {frozenset(p) for p in pairs}

    got = fs((n[a], n[b]) for a, b in moveit_adjacent_pairs(m))
    assert got == fs([("base", "l1"), ("l1", "tool"), ("l1", "cam")])
    rigid = fs((n[a], n[b]) for a, b in adjacent_pairs(m) if "flange" not in (n[a], n[b]))
    assert rigid == fs([("base", "l1"), ("base", "tool"), ("base", "cam"), ("l1", "tool"),
                        ("l1", "cam"), ("tool", "cam")])
    # through the import: tool/cam is sampled (fixed relative pose: never or always)
    model, rep = spherize(load_urdf(str(path)), SpherizeOptions(pair_samples=300))
    rows = {frozenset(k): r for k, r in _rows(model).items()}
    assert rows[frozenset(("l1", "tool"))]["reason"] == "Adjacent"
    assert "without collision geometry" in rows[frozenset(("l1", "tool"))]["why"]
    assert rows[frozenset(("base", "l1"))]["why"] == "parent and child"
    assert rows[frozenset(("tool", "cam"))]["reason"] in ("Never", "Always")
    assert frozenset(("base", "tool")) not in rows or \
        rows[frozenset(("base", "tool"))]["reason"] in ("Never", "Always")
    # pairs never appear without a reason, and the reasons survive a save and load
    import jwarp
    out = tmp_path / "t.json"
    model.save(out)
    again = jwarp.robot(str(out))
    assert skipped_pairs(again) == skipped_pairs(model)
    solid = sorted({sph.frame for sph in model.spheres})
    blocked = ~model.allowed_collision_pairs[np.ix_(solid, solid)]
    assert len(skipped_pairs(model)) == (int(blocked.sum()) - len(solid)) // 2


def test_reasons_recorded_by_with_self_pairs():
    import jwarp
    robot = jwarp.robot("arm7")
    pairs = never_colliding_pairs(robot, n_samples=200, seed=1, adjacency="moveit",
                                  always_fraction=ALWAYS_FRACTION)
    m = with_self_pairs(robot, pairs)
    rows = skipped_pairs(m)
    got = {r["reason"] for r in rows}
    assert got <= {"Adjacent", "Always", "Never"}
    n = m.frame_names
    assert {tuple(r["links"]) for r in rows if r["reason"] == "Never"} == {
        (n[a], n[b]) for a, b in pairs.never_colliding}
