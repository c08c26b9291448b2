"""Containment of collision meshes by fitted spheres (issue 42): the default fit holds every
point of every triangle inside the union of the link's spheres (checked here by an
independent numpy sampling with fresh seeds, on closed-form surfaces and on the Panda's
own meshes), the robot records how its spheres relate to its meshes (saved and loaded;
old files load with an unknown relation), and approximate models plan with the measured
poke-out as extra margin per link, with one warning."""

import json
import os
import uuid
import warnings

import numpy as np
import pytest
import trimesh

import jwarp
from jwarp.importers.spheres import (
    contain_fit,
    containment_bound,
    fit_link,
    fit_spheres,
    load_mesh,
    surface_cover,
)
from jwarp.model import RobotModel, RobotModelError, Sphere, SphereRelation
from jwarp.model.sphere_relation import inflated, relation_text

GAP = 0.001


def outside(points, centres, radii):
    """(n,) numpy: how far each point lies outside every sphere (<= 0 inside one)."""
    d = np.linalg.norm(points[:, None, :] - centres[None], axis=-1) - radii[None]
    return d.min(axis=1)


def box_surface(half, n, rng):
    """n uniform points on the surface of the box of half sizes ``half`` (area-weighted
    faces) plus its 8 corners."""
    half = np.asarray(half, float)
    areas = np.array([half[1] * half[2], half[0] * half[2], half[0] * half[1]])
    axis = rng.choice(3, n, p=areas / areas.sum())
    pts = rng.uniform(-1, 1, (n, 3)) * half
    pts[np.arange(n), axis] = rng.choice([-1.0, 1.0], n) * half[axis]
    corners = np.array(np.meshgrid(*[[-h, h] for h in half], indexing="ij")).reshape(3, -1).T
    return np.concatenate([pts, corners])


def test_surface_cover_has_the_stated_covering_radius():
    mesh = trimesh.creation.box(extents=(0.1, 0.04, 0.02))
    P = surface_cover(mesh, 0.002)
    x = box_surface([0.05, 0.02, 0.01], 20000, np.random.default_rng(7))
    from scipy.spatial import cKDTree

    d, _ = cKDTree(P).query(x)
    assert d.max() <= 0.002 + 1e-12
    with pytest.raises(ValueError, match="gap"):
        surface_cover(mesh, 0.0)


def test_box_is_contained_closed_form():
    T = trimesh.transformations.euler_matrix(0.3, -0.2, 0.7)
    T[:3, 3] = [0.1, -0.05, 0.2]
    half = np.array([0.06, 0.025, 0.015])
    fit = fit_link([{"kind": "box", "size": 2 * half, "origin": T}], tolerance=0.01,
                   contain=GAP, seed=3)
    assert fit.contained and fit.poke_out_bound == 0.0
    rng = np.random.default_rng(20261202)  # not the fit's streams
    x = box_surface(half, 200_000, rng) @ T[:3, :3].T + T[:3, 3]
    assert outside(x, fit.centres, fit.radii).max() <= 1e-9
    # protrusion in closed form: a centre's clearance is its distance to the nearest face
    local = (fit.centres - T[:3, 3]) @ T[:3, :3]
    assert np.all(np.abs(local) < half)  # centred inside the box
    prot = fit.radii - np.min(half - np.abs(local), axis=1)
    assert prot.max() == pytest.approx(fit.max_protrusion, abs=1e-6)
    assert GAP < prot.max() <= fit.protrusion + 1e-9
    # the check can fail: the same spheres 2 mm smaller leave the surface outside
    assert outside(x, fit.centres, fit.radii - 0.002).max() > 0
    assert containment_bound(trimesh.creation.box(extents=2 * half).apply_transform(T),
                             fit.centres, fit.radii - 0.002, gap=GAP) > 0


def test_true_cylinder_surface_is_contained():
    """The fit sees a 64-gon; the true cylinder lies outside it by r (1 - cos(pi/64)),
    which the certificate adds."""
    r, length = 0.03, 0.12
    fit = fit_link([{"kind": "cylinder", "size": (r, length)}], tolerance=0.01, contain=GAP)
    rng = np.random.default_rng(99)
    n = 100_000
    side = rng.random(n) < (2 * np.pi * r * length) / (2 * np.pi * r * length + 2 * np.pi * r * r)
    phi = rng.uniform(0, 2 * np.pi, n)
    rad = np.where(side, r, r * np.sqrt(rng.random(n)))
    z = np.where(side, rng.uniform(-length / 2, length / 2, n),
                 rng.choice([-length / 2, length / 2], n))
    x = np.stack([rad * np.cos(phi), rad * np.sin(phi), z], axis=1)
    assert fit.contained
    assert outside(x, fit.centres, fit.radii).max() <= 1e-9


@pytest.fixture(scope="module")
def panda_meshes():
    from jwarp.importers.robot import example_robot_urdf

    try:
        urdf = example_robot_urdf("panda_description/urdf/panda.urdf")
    except (ImportError, FileNotFoundError, ValueError):
        pytest.skip("example-robot-data is not installed")
    root = os.path.join(os.path.dirname(os.path.dirname(urdf)), "meshes", "collision")
    return {k: load_mesh(os.path.join(root, f"{k}.stl")) for k in ("finger", "link5")}


@pytest.mark.parametrize("name,protrusion", [("finger", 0.0075), ("link5", None)])
def test_panda_meshes_are_contained(panda_meshes, name, protrusion):
    mesh = panda_meshes[name]
    fit = fit_spheres(mesh, tolerance=0.01, protrusion=protrusion, contain=GAP,
                      n_volume=2000)
    assert fit.contained and fit.one_sided_error == 0.0
    x, _ = trimesh.sample.sample_surface(mesh, 200_000, seed=424242)  # fresh seed
    x = np.concatenate([np.asarray(x), np.asarray(mesh.vertices)])
    assert outside(x, fit.centres, fit.radii).max() <= 1e-9
    # the price: how far the spheres reach past the surface, reported and bounded
    assert 0 < fit.max_protrusion <= (protrusion or 0.02) + GAP + fit.grown + 1e-9


def test_approximate_fit_pokes_out_within_its_certified_bound(panda_meshes):
    mesh = panda_meshes["finger"]
    fit = fit_spheres(mesh, tolerance=0.01, protrusion=0.0075, n_volume=2000)
    assert not fit.contained
    bound = containment_bound(mesh, fit.centres, fit.radii, gap=GAP)
    x, _ = trimesh.sample.sample_surface(mesh, 200_000, seed=31337)
    measured = outside(np.asarray(x), fit.centres, fit.radii).max()
    assert 0.001 < measured <= bound <= measured + 2 * GAP
    grown = contain_fit(mesh, fit, GAP)
    assert grown.contained and grown.k == fit.k
    assert np.all(grown.radii >= fit.radii) and grown.grown <= bound + 1e-9
    assert outside(np.asarray(x), grown.centres, grown.radii).max() <= 1e-9


# ------------------------------------------------------------------ the model's relation
def unique(name="justin19"):
    return jwarp.robot(name).copy(name=f"h42-{uuid.uuid4().hex[:8]}")


def approximate(model, poke):
    rel = SphereRelation(kind="approximate", bound=max(poke.values()), poke_out=poke,
                         protrusion={k: 0.01 for k in poke}, gap=GAP, method="test")
    return model.copy(sphere_relation=rel)


def test_relation_round_trip_and_old_files(tmp_path):
    base = unique()
    links = sorted({base.frames[s.frame].name for s in base.spheres})
    model = approximate(base, {links[0]: 0.004, links[1]: 0.002})
    model.save(tmp_path / "r.json")
    back = RobotModel.load(tmp_path / "r.json")
    assert back.sphere_relation == model.sphere_relation
    assert back.sphere_relation.link_poke_out(links[0]) == 0.004
    contained = base.copy(sphere_relation=SphereRelation(kind="contained", gap=GAP))
    contained.save(tmp_path / "c.json")
    assert RobotModel.load(tmp_path / "c.json").sphere_relation.kind == "contained"
    # a file written before the field: loads, relation unknown, and said so
    doc = model.to_dict()
    del doc["sphere_relation"]
    (tmp_path / "old.json").write_text(json.dumps(doc))
    old = RobotModel.load(tmp_path / "old.json")
    assert old.sphere_relation is None and "unknown" in relation_text(old)
    doc["sphere_relation"] = {"kind": "roughly"}
    with pytest.raises(RobotModelError, match="sphere_relation.kind"):
        RobotModel.from_dict(doc)
    doc["sphere_relation"] = {"kind": "approximate", "poke_out": {links[0]: -1.0}}
    with pytest.raises(RobotModelError, match="sphere_relation.poke_out"):
        RobotModel.from_dict(doc)


def test_relation_follows_shrunk_spheres():
    base = unique()
    model = base.copy(sphere_relation=SphereRelation(kind="contained", gap=GAP))
    spheres = list(model.spheres)
    s0 = spheres[0]
    spheres[0] = Sphere(frame=s0.frame, position=s0.position.copy(), radius=s0.radius - 0.003)
    edited = model.copy(spheres=spheres)
    rel = edited.sphere_relation
    link = model.frames[s0.frame].name
    assert rel.kind == "approximate" and rel.link_poke_out(link) == pytest.approx(0.003)
    # the planner's margin grows back only the shrunk sphere (per-sphere margin)
    assert rel.sphere_margin[0] == pytest.approx(0.003) and not any(rel.sphere_margin[1:])
    np.testing.assert_allclose(inflated(edited).sphere_arrays()[2], model.sphere_arrays()[2],
                               atol=1e-12)
    again = RobotModel.from_dict(edited.to_dict()).sphere_relation
    assert again.sphere_margin == rel.sphere_margin
    moved = list(model.spheres)
    moved[0] = Sphere(frame=s0.frame, position=s0.position + 0.01, radius=s0.radius)
    assert model.copy(spheres=moved).sphere_relation is None  # no promise left


def test_mesh_margin_inflates_radii_per_link_and_warns_once():
    from worlds import block_world

    from jwarp.core.device import put_model
    from jwarp.solvers.planning import Planner, PlanOptions
    from jwarp.world.model_check import MeshMarginWarning, mesh_margin_model

    base = unique()
    links = sorted({base.frames[s.frame].name for s in base.spheres})
    poke = {links[0]: 0.004, links[1]: 0.0015}
    for k in links[2:]:
        poke[k] = 0.0
    model = approximate(base, poke)
    with pytest.warns(MeshMarginWarning, match="poke out by up to 4.0 mm"):
        grown = mesh_margin_model(model, True, what="planning")
    with warnings.catch_warnings():
        warnings.simplefilter("error", MeshMarginWarning)  # once: no second warning
        again = mesh_margin_model(model, True, what="planning")
    f, _, r0 = model.sphere_arrays()
    names = np.array([model.frames[i].name for i in f])
    want = r0 + np.array([poke[n] for n in names])
    np.testing.assert_allclose(grown.sphere_arrays()[2], want, atol=1e-12)
    np.testing.assert_allclose(again.sphere_arrays()[2], want, atol=1e-12)
    assert grown.sphere_relation.kind == "contained" and grown.sphere_relation.inflated
    assert inflated(grown) is grown  # not grown twice
    # the device collision model of the planner carries the grown radii
    planner = Planner(model, block_world(), 1, PlanOptions(), device="cpu")
    rad = put_model(planner.robot, "cpu", np.float64).spheres.sph_rad.numpy()
    np.testing.assert_allclose(rad, want, atol=1e-12)
    # switched off: the spheres as they are, with its own warning once
    with pytest.warns(MeshMarginWarning, match="mesh_margin is off"):
        off = Planner(model, block_world(), 1, PlanOptions(mesh_margin=False), device="cpu")
    np.testing.assert_allclose(put_model(off.robot, "cpu", np.float64).spheres.sph_rad.numpy(),
                               r0, atol=1e-12)
    # contained and unknown relations: nothing added, no warning
    with warnings.catch_warnings():
        warnings.simplefilter("error", MeshMarginWarning)
        assert mesh_margin_model(base) is not None
        np.testing.assert_allclose(mesh_margin_model(base).sphere_arrays()[2], r0)
    with pytest.raises(TypeError, match="mesh_margin"):
        PlanOptions(mesh_margin="yes").validate(np.float32)


def test_an_edited_contained_fit_is_grown_back_without_a_warning():
    """The import's home fit shrinks contained spheres that overlap at the home: the
    relation is "approximate" by what they lost, and planning grows them back (they contain
    the meshes again) without a warning, as the user imported with the defaults; with
    mesh_margin off it still warns."""
    import dataclasses

    from jwarp.world.model_check import CONTAIN_METHOD, MeshMarginWarning, mesh_margin_model

    base = unique()
    links = sorted({base.frames[s.frame].name for s in base.spheres})
    model = approximate(base, {links[0]: 0.003, **{k: 0.0 for k in links[1:]}})
    model = model.copy(sphere_relation=dataclasses.replace(
        model.sphere_relation, method=f"{CONTAIN_METHOD}: ...; spheres shrunk afterwards"))
    with warnings.catch_warnings():
        warnings.simplefilter("error", MeshMarginWarning)
        grown = mesh_margin_model(model, True)
    f, _, r0 = model.sphere_arrays()
    first = np.array([model.frames[i].name == links[0] for i in f])
    np.testing.assert_allclose(grown.sphere_arrays()[2], r0 + 0.003 * first, atol=1e-12)
    with pytest.warns(MeshMarginWarning, match="mesh_margin is off"):
        mesh_margin_model(model, False)


TWO_LINKS = """<?xml version="1.0"?>
<robot name="two_link">
  <link name="base"><collision><geometry><box size="0.1 0.1 0.04"/></geometry></collision></link>
  <link name="arm"><collision><origin xyz="0.12 0 0"/>
    <geometry><box size="0.24 0.04 0.03"/></geometry></collision></link>
  <joint name="j1" type="revolute"><parent link="base"/><child link="arm"/>
    <origin xyz="0 0 0.1"/><axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
</robot>
"""


def test_import_urdf_reports_containment_per_link(tmp_path, capsys, monkeypatch):
    """The import prints per link the poke-out bound and the protrusion and the totals, and
    the file records the relation: contained by default; with --approximate the poke-out
    per link, which a planner then adds with one warning."""
    from cli_helpers import run

    from jwarp.world.model_check import MeshMarginWarning, mesh_margin_model

    monkeypatch.setenv("JWARP_CACHE", str(tmp_path / "cache"))
    urdf = tmp_path / "two_link.urdf"
    urdf.write_text(TWO_LINKS)
    out = tmp_path / "r.json"
    fast = ["--pair-samples", "50", "--no-home-fit", "--no-refine", "--tolerance", "0.02"]
    code, stdout, err = run(capsys, ["import-urdf", urdf, "--out", out, *fast])
    assert code == 0, err
    assert "spheres contain the meshes" in stdout
    lines = [x for x in stdout.splitlines() if x.startswith("  ")]
    assert any(x.startswith("  base:") and "contained, poke-out <= 0.00 mm, protrusion" in x
               for x in lines), stdout
    assert any(x.startswith("  total:") for x in lines)
    model = jwarp.robot(str(out))
    assert model.sphere_relation.kind == "contained" and model.sphere_relation.bound == 0
    # independent: the boxes' surfaces lie inside their links' spheres
    f, p, r = model.sphere_arrays()
    rng = np.random.default_rng(5)
    for link, half, shift in (("base", [0.05, 0.05, 0.02], [0, 0, 0]),
                              ("arm", [0.12, 0.02, 0.015], [0.12, 0, 0])):
        sel = f == model.frame_index(link)
        x = box_surface(half, 50_000, rng) + shift
        assert outside(x, p[sel], r[sel]).max() <= 1e-9
    # spheres shrunk after the fit (as the home fit tightens them): certified again, and
    # the planner's per-sphere margin restores containment
    from jwarp.importers.robot import load_urdf
    from jwarp.world.spherize import certify_relation

    arm = model.frame_index("arm")
    sp = list(model.spheres)
    k = next(i for i, x in enumerate(sp) if x.frame == arm)
    sp[k] = Sphere(frame=arm, position=sp[k].position.copy(), radius=sp[k].radius - 0.004)
    tight = certify_relation(model.copy(spheres=sp), load_urdf(str(urdf)), GAP)
    rel = tight.sphere_relation
    assert rel.kind == "approximate" and 0 < rel.link_poke_out("arm") <= 0.004 + GAP
    assert rel.link_poke_out("base") == 0 and rel.sphere_margin[k] > 0
    assert sum(m > 0 for m in rel.sphere_margin) <= sum(x.frame == arm for x in sp)
    f, p, r = tight.sphere_arrays()
    xa = box_surface([0.12, 0.02, 0.015], 50_000, rng) + [0.12, 0, 0]
    assert outside(xa, p[f == arm], r[f == arm]).max() > 0  # the shrunk sphere uncovers
    f, p, r = inflated(tight).sphere_arrays()
    assert outside(xa, p[f == arm], r[f == arm]).max() <= 1e-9
    code, stdout, err = run(capsys, ["import-urdf", urdf, "--out", out, *fast, "--approximate"])
    assert code == 0, err
    approx = jwarp.robot(str(out))
    rel = approx.sphere_relation
    assert rel.kind == "approximate" and rel.bound > 0.001
    assert "approximate spheres" in stdout and "approximate, poke-out <=" in stdout
    # the recorded poke-out bounds what fresh samples find outside
    f, p, r = approx.sphere_arrays()
    sel = f == approx.frame_index("arm")
    found = outside(box_surface([0.12, 0.02, 0.015], 50_000, rng) + [0.12, 0, 0],
                    p[sel], r[sel]).max()
    assert 0 < found <= rel.link_poke_out("arm")
    with pytest.warns(MeshMarginWarning):
        grown = mesh_margin_model(approx.copy(name=f"h42-{uuid.uuid4().hex[:8]}"))
    f2, p2, r2 = grown.sphere_arrays()
    assert outside(box_surface([0.12, 0.02, 0.015], 50_000, rng) + [0.12, 0, 0],
                   p2[f2 == grown.frame_index("arm")], r2[f2 == grown.frame_index("arm")]
                   ).max() <= 1e-9


def test_contain_factors_are_validated():
    from jwarp.world.spherize import SpherizeOptions

    SpherizeOptions(contain_factors={"wrist": 2.0, "hand": 1.0}).validate()
    with pytest.raises(ValueError, match="contain_factors"):
        SpherizeOptions(contain_factors={"elbow": 2.0}).validate()
    with pytest.raises(ValueError, match="contain_factors"):
        SpherizeOptions(contain_factors={"hand": 0.0}).validate()
    with pytest.raises(TypeError, match="contain_factors"):
        SpherizeOptions(contain_factors=[2.0]).validate()
