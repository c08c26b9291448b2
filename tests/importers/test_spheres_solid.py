"""The sphere fit's solid (jwarp.importers.spheres): inside/outside by generalised winding
number against trimesh.contains (closed mesh) and analytic boxes (a box with a face
removed, two overlapping boxes); no sphere centred outside the solid; the reported
protrusion and excess against analytic box distances; the per-link budget; the imported
Panda with default settings (<= 70 spheres, one-sided error <= 1 cm, finger and hand
spheres reaching <= 5 mm past the geometry), checked with numpy/trimesh distances."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import trimesh

from jwarp.importers.spheres import (
    fit_link,
    fit_spheres,
    inside_solid,
    one_sided_error,
    primitive_mesh,
    signed_distance,
    sphere_protrusion,
)

HALF = np.array([0.05, 0.03, 0.02])  # the open box: half sides [m]


def box_sdf(x: np.ndarray, half: np.ndarray, R: np.ndarray | None = None,
            t: np.ndarray | None = None) -> np.ndarray:
    """Analytic signed distance to a box (half sides ``half``, pose R, t), < 0 inside."""
    p = np.asarray(x, float)
    if R is not None:
        p = (p - t) @ R
    q = np.abs(p) - half
    return np.linalg.norm(np.maximum(q, 0), axis=1) + np.minimum(q.max(axis=1), 0)


def open_box() -> trimesh.Trimesh:
    """A box with its whole -x face (both triangles) removed."""
    m = primitive_mesh("box", 2 * HALF)
    keep = m.face_normals[:, 0] > -0.5
    assert (~keep).sum() == 2
    m.update_faces(keep)
    assert not m.is_watertight
    return m


def two_boxes() -> tuple[trimesh.Trimesh, list]:
    """Two overlapping boxes as one mesh (faces of each inside the other): the union."""
    a, b = primitive_mesh("box", (0.12, 0.04, 0.04)), primitive_mesh("box", (0.04, 0.04, 0.10))
    b.apply_translation([0.03, 0.0, 0.02])
    boxes = [(np.array([0.06, 0.02, 0.02]), np.zeros(3)), (np.array([0.02, 0.02, 0.05]),
                                                           np.array([0.03, 0.0, 0.02]))]
    return trimesh.util.concatenate([a, b]), boxes


def union_sdf(x: np.ndarray, boxes) -> np.ndarray:
    """Signed distance to a union of axis-aligned boxes: exact outside (min of the
    distances), inside a lower bound of the depth (enough for inside tests)."""
    return np.min([box_sdf(x - t, h) for h, t in boxes], axis=0)


def away(x: np.ndarray, sdf: np.ndarray, gap: float = 1e-4) -> np.ndarray:
    return np.abs(sdf) > gap


def test_winding_inside_equals_contains_on_a_closed_mesh():
    mesh = trimesh.creation.annulus(r_min=0.02, r_max=0.05, height=0.04)  # non-convex
    assert mesh.is_watertight
    x = np.random.default_rng(1).uniform(-0.06, 0.06, (20000, 3))
    ins = inside_solid(mesh, x)
    ref = mesh.contains(x)
    d = signed_distance(mesh, x)
    far = np.abs(d) > 1e-5
    assert ins.sum() > 1000
    np.testing.assert_array_equal(ins[far], ref[far])
    # the distance magnitude is trimesh's (Warp computes in float32: ~1e-5 m here)
    _, dt, _ = trimesh.proximity.closest_point(mesh, x[:500])
    np.testing.assert_allclose(np.abs(d[:500]), dt, atol=1e-5)


def test_open_box_has_the_box_as_solid_and_centres_inside():
    mesh = open_box()
    x = np.random.default_rng(2).uniform(-0.07, 0.07, (20000, 3))
    ref = box_sdf(x, HALF)
    ok = away(x, ref)
    np.testing.assert_array_equal(inside_solid(mesh, x)[ok], (ref < 0)[ok])
    tol = 0.01
    fit = fit_spheres(mesh, tolerance=tol, n_volume=100_000)
    assert not fit.watertight
    # never centred outside the solid (analytic box), and every sphere hugs it
    assert np.all(box_sdf(fit.centres, HALF) < 0)
    # the reach through the missing face counts too (the open mesh's clearance is sampled
    # in 64 directions: within a few % of the clearance)
    analytic = float((fit.radii + box_sdf(fit.centres, HALF)).max())
    assert fit.max_protrusion == pytest.approx(analytic, abs=1e-3)
    assert analytic <= fit.protrusion + 1e-3
    # covered: fresh samples of the open box's surface (its walls) and of the missing face
    walls, _ = trimesh.sample.sample_surface(mesh, 20000, seed=11)
    assert one_sided_error(walls, fit.centres, fit.radii).max() <= tol
    # excess against the analytic box, an independent Monte Carlo estimate
    ref_vol, ref_se = analytic_excess(fit.centres, fit.radii, lambda p: box_sdf(p, HALF) < 0)
    assert abs(fit.excess_volume - ref_vol) <= 4 * np.hypot(ref_se, fit.excess_volume_stderr)
    assert fit.mesh_volume == pytest.approx(np.prod(2 * HALF), rel=0.05)  # Monte Carlo


def analytic_excess(c, r, inside, n: int = 300_000, seed: int = 77):
    """Union of spheres outside ``inside``: Monte Carlo over the spheres' bounding box."""
    lo, hi = (c - r[:, None]).min(0), (c + r[:, None]).max(0)
    x = lo + np.random.default_rng(seed).random((n, 3)) * (hi - lo)
    hit = (one_sided_error(x, c, r) <= 0) & ~inside(x)
    p = hit.mean()
    box = np.prod(hi - lo)
    return box * p, box * np.sqrt(p * (1 - p) / n)


def test_overlapping_bodies_fit_as_their_union():
    mesh, boxes = two_boxes()
    x = np.random.default_rng(3).uniform(-0.08, 0.08, (20000, 3))
    ref = union_sdf(x, boxes)
    ok = away(x, ref)
    np.testing.assert_array_equal(inside_solid(mesh, x)[ok], (ref < 0)[ok])
    tol = 0.01
    fit = fit_spheres(mesh, tolerance=tol)
    assert np.all(union_sdf(fit.centres, boxes) < 0)
    # the union's boundary (the faces buried in the other box need no cover) is covered
    pts, _ = trimesh.sample.sample_surface(mesh, 40000, seed=12)
    boundary = pts[union_sdf(pts, boxes) > -1e-9]
    assert one_sided_error(boundary, fit.centres, fit.radii).max() <= tol
    ref_vol, ref_se = analytic_excess(fit.centres, fit.radii,
                                      lambda p: union_sdf(p, boxes) < 0)
    assert abs(fit.excess_volume - ref_vol) <= 4 * np.hypot(ref_se, fit.excess_volume_stderr)


def test_protrusion_report_against_a_box():
    """sphere_protrusion of arbitrary spheres (centres in and out of a box) equals the
    analytic largest distance of the sphere from the box: r + sdf(c) for a convex box
    (attained towards the nearest face or away from it)."""
    half = np.array([0.04, 0.03, 0.05])
    mesh = primitive_mesh("box", 2 * half)
    rng = np.random.default_rng(4)
    c = rng.uniform(-0.03, 0.03, (50, 3))
    r = rng.uniform(0.005, 0.04, 50)
    got = sphere_protrusion(mesh, c, r)
    np.testing.assert_allclose(got, r + box_sdf(c, half), atol=2e-6)
    # the fit's own figure: at most the allowed protrusion, and what the box says
    fit = fit_spheres(mesh, tolerance=0.01, protrusion=0.003)
    assert fit.protrusion == 0.003
    np.testing.assert_allclose(fit.max_protrusion, (fit.radii + box_sdf(fit.centres, half)).max(),
                               atol=2e-6)
    assert fit.max_protrusion <= 0.003 + 2e-6


def test_per_link_budget_is_respected():
    T = np.eye(4)
    T[:3, 3] = [0.0, 0.0, 0.15]
    geoms = [{"kind": "box", "size": (0.06, 0.06, 0.2), "origin": np.eye(4)},
             {"kind": "cylinder", "size": (0.04, 0.12), "origin": T},
             {"kind": "sphere", "size": [0.02], "origin": T}]
    free = fit_link(geoms, tolerance=0.01)
    assert free.k > 4
    for k in (2, 4):
        fit = fit_link(geoms, tolerance=0.01, max_spheres=k)
        assert fit.k <= k  # the URDF sphere counts against the budget
        assert fit.one_sided_error >= free.one_sided_error - 1e-9
    with pytest.raises(ValueError, match="max_spheres"):
        fit_link(geoms, tolerance=0.01, max_spheres=1)


URDF = """<?xml version="1.0"?>
<robot name="two_links">
  <link name="base"><collision><geometry><box size="0.1 0.1 0.05"/></geometry></collision></link>
  <link name="arm"><collision><origin xyz="0.15 0 0"/>
    <geometry><box size="0.3 0.08 0.08"/></geometry></collision></link>
  <joint name="j1" type="revolute"><parent link="base"/><child link="arm"/>
    <origin xyz="0 0 0.1"/><axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
</robot>
"""


def test_spherize_budget_and_warnings(tmp_path, monkeypatch):
    from jwarp.importers.robot import load_urdf
    from jwarp.world.spherize import SphereFitWarning, SpherizeOptions, spherize

    monkeypatch.setenv("JWARP_CACHE", str(tmp_path / "cache"))
    path = tmp_path / "r.urdf"
    path.write_text(URDF)
    imported = load_urdf(path)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the one-sided fit's bounds: no warning here
        model, rep = spherize(imported, SpherizeOptions(pair_samples=50, contain=False))
    assert rep.warnings == []
    rows = {r["link"]: r for r in rep.links}
    assert rows["arm"]["max_protrusion"] <= rows["arm"]["protrusion"] + 1e-6
    # a budget of 2 per link: counts, and the error it costs is named
    with pytest.warns(SphereFitWarning) as caught:
        model, rep = spherize(imported, SpherizeOptions(pair_samples=50, max_spheres=2))
    assert any("link 'arm': one-sided error" in str(w.message) for w in caught)
    arm = model.frame_index("arm")
    assert sum(s.frame == arm for s in model.spheres) <= 2
    assert any("'arm'" in w for w in rep.warnings)
    # a protrusion bound below the allowed reach: named with the figures
    with pytest.warns(SphereFitWarning, match="reaches .* outside the part"):
        spherize(imported, SpherizeOptions(pair_samples=50, protrusion=0.01,
                                           warn_protrusion=0.005))
    with pytest.raises(ValueError, match="protrusion"):
        SpherizeOptions(protrusion=-1.0).validate()
    with pytest.raises(ValueError, match="warn_excess"):
        SpherizeOptions(warn_excess=0.0).validate()


# ----------------------------------------------------------------- the Panda, default fit
def link_parts(geoms) -> list:
    """(inside test, distance-to-surface, surface sampler) of each geometry, posed in the
    link frame (boxes analytic; meshes by trimesh)."""
    from jwarp.importers.spheres import load_mesh

    parts = []
    for g in geoms:
        T = np.asarray(g.origin, float)
        if g.kind == "box":
            half = np.asarray(g.size, float) / 2
            R, t = T[:3, :3], T[:3, 3]
            mesh = primitive_mesh("box", 2 * half)
            mesh.apply_transform(T)
            parts.append((lambda p, h=half, R=R, t=t: box_sdf(p, h, R, t), mesh))
        else:
            assert g.kind == "mesh"
            mesh = load_mesh(g.mesh_file(), g.scale).copy()
            mesh.apply_transform(T)
            assert mesh.is_watertight

            def sdf(p, m=mesh):
                return -trimesh.proximity.signed_distance(m, p)  # trimesh: > 0 inside
            parts.append((sdf, mesh))
    return parts


def test_panda_default_fit_is_small_covering_and_tight(tmp_path, monkeypatch):
    from jwarp.importers.robot import example_robot_urdf, load_urdf
    from jwarp.world.spherize import SpherizeOptions, spherized_robot

    try:
        path = example_robot_urdf("panda_description/urdf/panda.urdf")
    except ValueError as e:
        pytest.skip(str(e))
    monkeypatch.setenv("JWARP_CACHE", str(tmp_path / "cache"))
    # the one-sided fit (``contain=False``; the contained default is tested in
    # test_sphere_containment.py): few spheres, covering within the tolerance, tight
    model, rep = spherized_robot(path, SpherizeOptions(pair_samples=200, contain=False))
    assert len(model.spheres) <= 70
    imported = load_urdf(path)
    by_link: dict = {}
    for g in imported.geometries:
        by_link.setdefault(g.link, []).append(g)
    assert {"panda_hand", "panda_leftfinger", "panda_rightfinger"} <= set(by_link)
    u = np.random.default_rng(5).normal(size=(400, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    for link, geoms in by_link.items():
        f = model.frame_index(link)
        c = np.array([s.position for s in model.spheres if s.frame == f])
        r = np.array([s.radius for s in model.spheres if s.frame == f])
        parts = link_parts(geoms)
        # one-sided error: fresh samples of the union's boundary (not inside another part)
        pts = np.concatenate([trimesh.sample.sample_surface(m, 8000, seed=21)[0]
                              for _, m in parts])
        depth = np.min([sdf(pts) for sdf, _ in parts], axis=0)
        boundary = pts[depth > -1e-6]
        err = one_sided_error(boundary, c, r).max()
        assert err <= 0.01, (link, err)
        # centres inside the union
        assert np.all(np.min([sdf(c) for sdf, _ in parts], axis=0) < 0), link
        if link in ("panda_hand", "panda_leftfinger", "panda_rightfinger"):
            # protrusion: points on each sphere outside every part, their distance to the
            # union (the smallest distance to a part) at most 5 mm
            x = (c[:, None, :] + r[:, None, None] * u[None]).reshape(-1, 3)
            dist = np.min([sdf(x) for sdf, _ in parts], axis=0)
            assert dist.max() <= 0.005 + 1e-5, (link, dist.max())
    rows = {r["link"]: r for r in rep.links}
    for name in ("panda_hand", "panda_leftfinger", "panda_rightfinger"):
        assert rows[name]["max_protrusion"] <= 0.005 + 1e-6
