"""The sphere fit's fast paths (issue 24: every zoo robot imports in a minute on one core):
COLLADA triangle soups merged into the closed solid they draw, the sparse cover of a large
part (checked against the box's exact geometry and numpy), the Warp one-sided error
against numpy, links of the same geometry fitted once, and the pair sampling left to the
caller (``sample_pairs=False``)."""

import numpy as np
import pytest
import trimesh

from jwarp.importers import spheres as S


def test_collada_triangle_soup_is_merged_into_its_solid():
    from jwarp.importers.robot import example_robot_urdf

    urdf = example_robot_urdf("tiago_description/robots/tiago.urdf")
    root = urdf.split("tiago_description")[0]
    path = f"{root}tiago_description/meshes/arm/arm_1_collision.dae"
    raw = trimesh.load(path, force="mesh")       # as trimesh gives it: one body per triangle
    assert not raw.is_watertight and raw.body_count > 10
    m = S.load_mesh(path)
    assert m.is_watertight and m.body_count == 1
    assert len(m.faces) == len(raw.faces)
    assert abs(m.volume - raw.volume) <= 1e-9 * max(1.0, abs(raw.volume))
    assert np.allclose(m.bounds, raw.bounds)


def test_sparse_cover_of_a_large_plate():
    """A 1.2 m x 1.2 m x 4 cm plate at 2 cm: 8 area / tol^2 > 50 000, the sparse cover."""
    tol = 0.02
    half = np.array([0.6, 0.6, 0.02])
    box = trimesh.creation.box(extents=2 * half)
    assert 8 * box.area / tol ** 2 > S._SPARSE_FROM
    fit = S.fit_spheres(box, tolerance=tol, max_rounds=3)
    # independent: fresh samples of the box surface (numpy distances), exact box clearance
    p, _ = trimesh.sample.sample_surface(box, 30_000, seed=123)
    err = max(float(np.maximum((np.linalg.norm(q[:, None] - fit.centres[None], axis=-1)
                                - fit.radii).min(axis=1), 0.0).max())
              for q in np.array_split(p, 30))
    assert err <= tol
    assert np.all(np.abs(fit.centres) <= half + 1e-12)          # centres inside the solid
    clearance = (half - np.abs(fit.centres)).min(axis=1)
    assert np.all(fit.radii - clearance <= 2 * tol + 1e-9)      # reach past the surface
    assert fit.max_protrusion == pytest.approx(float((fit.radii - clearance).max()), abs=1e-4)


def test_one_sided_error_many_spheres_matches_numpy():
    rng = np.random.default_rng(3)
    c = rng.uniform(-1, 1, (700, 3))
    r = rng.uniform(0.01, 0.1, 700)
    p = rng.uniform(-1.2, 1.2, (3000, 3))
    ref = np.maximum((np.linalg.norm(p[:, None] - c[None], axis=-1) - r).min(axis=1), 0.0)
    got = S.one_sided_error(p, c, r)
    assert len(p) * len(r) > 1_000_000            # the Warp path
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-12)
    assert np.any(got == 0) and np.any(got > 0)


URDF = """<robot name="twins">
  <link name="base"/>
  <link name="a"><collision><geometry><box size="0.1 0.06 0.04"/></geometry></collision></link>
  <link name="b"><collision><geometry><box size="0.1 0.06 0.04"/></geometry></collision></link>
  <link name="c"><collision><geometry><cylinder radius="0.03" length="0.1"/></geometry>
  </collision></link>
  <joint name="j1" type="revolute"><parent link="base"/><child link="a"/>
    <axis xyz="0 0 1"/><limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="j2" type="revolute"><parent link="a"/><child link="b"/>
    <origin xyz="0.15 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="j3" type="revolute"><parent link="b"/><child link="c"/>
    <origin xyz="0.15 0 0"/><axis xyz="0 1 0"/>
    <limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
</robot>
"""


def test_same_geometry_fitted_once_and_pairs_left_to_the_caller(tmp_path, monkeypatch):
    from jwarp.importers.robot import load_urdf
    from jwarp.world.self_pairs import never_colliding_pairs
    from jwarp.world.spherize import MOVEIT_RULES, SpherizeOptions, spherize

    path = tmp_path / "twins.urdf"
    path.write_text(URDF)
    calls = []
    real = S.fit_link
    monkeypatch.setattr(S, "fit_link", lambda *a, **k: calls.append(1) or real(*a, **k))
    opts = SpherizeOptions(tolerance=0.02, pair_samples=200, refine=False,
                           contain=False)  # the plain one-sided fit
    model, report = spherize(load_urdf(str(path)), opts)
    assert len(calls) == 2                          # a and b share one fit, c its own
    rows = {r["link"]: r for r in report.links}
    assert rows["a"]["spheres"] == rows["b"]["spheres"] > 0
    # the shared fit, in each link's frame, as fitted alone
    alone = S.fit_link([{"kind": "box", "size": [0.1, 0.06, 0.04]}], tolerance=0.02, seed=0)
    for link in ("a", "b"):
        f = model.frame_index(link)
        got = np.array([s.position for s in model.spheres if s.frame == f])
        np.testing.assert_allclose(got, alone.centres)
    assert report.pairs is not None
    ref = never_colliding_pairs(model, n_samples=200, seed=0, **MOVEIT_RULES)
    assert set(map(tuple, model.self_collision.exclude_pairs)) == set(ref.exclude_pairs)

    bare, rep2 = spherize(load_urdf(str(path)), opts, sample_pairs=False)
    assert rep2.pairs is None and not bare.self_collision.exclude_pairs
    assert [s.radius for s in bare.spheres] == [s.radius for s in model.spheres]
