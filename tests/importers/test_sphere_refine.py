"""Refinement of a sphere fit (jwarp.importers.sphere_refine.refine_fit): closed-form
optima (a ball, a short capsule), the one-sided error on fresh samples drawn by trimesh
and measured with numpy, centres inside (trimesh's inside test), the reach past the
surface from points on the spheres and the analytic distance to a box, and a Panda link."""

from __future__ import annotations

import importlib.metadata
from pathlib import Path

import numpy as np
import pytest
import trimesh

from jwarp.importers.sphere_refine import refine_fit
from jwarp.importers.spheres import SphereFit, fit_spheres, load_mesh, sphere_protrusion

TOL = 0.01


def fresh_error(mesh: trimesh.Trimesh, c: np.ndarray, r: np.ndarray, n: int = 50_000,
                seed: int = 1234) -> float:
    """Largest distance of fresh surface samples outside every sphere (numpy, dense)."""
    p, _ = trimesh.sample.sample_surface(mesh, n, seed=seed)
    d = np.linalg.norm(np.asarray(p)[:, None, :] - c[None], axis=-1) - r[None]
    return float(max(d.min(axis=1).max(), 0.0))


def one_sphere_fit(mesh: trimesh.Trimesh, c: list, r: float) -> SphereFit:
    """A hand-made one-sphere fit of ``mesh`` (the starting point of the refinement)."""
    c = np.asarray([c], float)
    rr = np.array([r])
    err = fresh_error(mesh, c, rr, n=5000)
    prot = float(sphere_protrusion(mesh, c, rr)[0])
    return SphereFit(centres=c, radii=rr, tolerance=TOL, one_sided_error=err,
                     meets_tolerance=err <= TOL, fit_error=TOL, excess_volume=0.0,
                     excess_volume_stderr=0.0, excess_fraction=0.0,
                     mesh_volume=float(mesh.volume), n_volume=0, n_surface=0,
                     volume_method="test", protrusion=prot, max_protrusion=prot)


def test_ball_goes_to_its_centre_and_shrinks_by_the_error():
    """One sphere for a ball of radius R: the optimum is the ball's centre and radius
    R - e (every surface point exactly e outside), so it reaches nowhere past the surface."""
    R = 0.05
    ball = trimesh.creation.icosphere(subdivisions=4, radius=R)
    fit = one_sphere_fit(ball, [0.012, -0.008, 0.005], 0.07)
    out = refine_fit(ball, fit, iters=200)
    assert out.k == 1
    assert np.linalg.norm(out.centres[0]) < 1.5e-3
    e = R - out.radii[0]
    assert 0.8 * TOL <= e <= 0.95 * TOL, e
    assert out.max_protrusion < 0 < fit.max_protrusion
    assert fresh_error(ball, out.centres, out.radii) <= 0.95 * TOL + 1e-4


def test_short_capsule_one_sphere_min_max_optimum():
    """One sphere for a capsule (radius a, cylinder length L along z): by symmetry the
    optimum centre is the capsule's centre, radius a + L/2 - e (the two tips exactly e
    outside), so the sphere reaches L/2 - e past the side."""
    a, L = 0.03, 0.04
    cap = trimesh.creation.capsule(height=L, radius=a, count=[48, 48])
    fit = one_sphere_fit(cap, [0.004, 0.0, 0.012], 0.065)
    out = refine_fit(cap, fit, iters=300)
    assert out.k == 1
    assert np.linalg.norm(out.centres[0]) < 2e-3, out.centres
    e = a + L / 2 - out.radii[0]
    assert 0.8 * TOL <= e <= 0.95 * TOL, e
    assert out.max_protrusion == pytest.approx(L / 2 - e, abs=1.5e-3)
    assert fresh_error(cap, out.centres, out.radii) <= 0.95 * TOL + 1e-4


def box_outside(p: np.ndarray, half: np.ndarray) -> np.ndarray:
    """(n,) analytic distance of points outside the axis-aligned box (0 inside)."""
    return np.linalg.norm(np.maximum(np.abs(p) - half, 0.0), axis=1)


def test_box_reaches_less_past_the_surface_within_the_error():
    """A fitted bar: after the refinement every fresh surface sample is within the
    tolerance, the centres are inside, and the spheres' largest reach past the box (points
    on the spheres, analytic box distance) is lower than the fit's and below the reported
    bound."""
    ext = np.array([0.2, 0.05, 0.04])
    box = trimesh.creation.box(extents=ext)
    fit = fit_spheres(box, tolerance=TOL, protrusion=0.02)
    out = refine_fit(box, fit)
    assert out is not fit and out.k <= fit.k
    assert fresh_error(box, out.centres, out.radii) <= TOL
    assert out.one_sided_error <= TOL and out.meets_tolerance
    assert np.all(box.contains(out.centres))
    u = np.random.default_rng(0).normal(size=(4000, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)

    def reach(c: np.ndarray, r: np.ndarray) -> float:
        return max(float(box_outside(ci + ri * u, ext / 2).max()) for ci, ri in zip(c, r))

    before, after = reach(fit.centres, fit.radii), reach(out.centres, out.radii)
    assert after < before - 2e-3, (before, after)
    assert after <= out.max_protrusion + 1e-4


def test_panda_link_refined():
    """A Panda arm link at 1 cm: same sphere count, error within 1 cm on fresh samples,
    centres inside, the largest protrusion lowered by at least 2 mm."""
    try:
        dist = importlib.metadata.distribution("example-robot-data")
    except importlib.metadata.PackageNotFoundError:
        pytest.skip("example-robot-data is not installed")
    root = Path(dist.locate_file(
        "cmeel.prefix/share/example-robot-data/robots/panda_description"))
    path = root / "meshes" / "collision" / "link4.stl"
    if not path.is_file():
        pytest.skip(f"no Panda collision mesh {path}")
    mesh = load_mesh(path)
    fit = fit_spheres(mesh, tolerance=TOL)
    out = refine_fit(mesh, fit, iters=200)
    assert out.k <= fit.k
    assert fresh_error(mesh, out.centres, out.radii) <= TOL
    assert np.all(mesh.contains(out.centres))
    assert out.max_protrusion <= fit.max_protrusion - 2e-3
    got = sphere_protrusion(mesh, out.centres, out.radii)
    assert float(got.max()) == pytest.approx(out.max_protrusion, abs=1e-6)


@pytest.mark.parametrize("kwargs,exc,name", [
    ({"error_fraction": 0.0}, ValueError, "error_fraction"),
    ({"error_fraction": 0.9, "check_fraction": 0.8}, ValueError, "check_fraction"),
    ({"iters": 0}, ValueError, "iters"),
])
def test_bad_arguments_name_themselves(kwargs, exc, name):
    box = trimesh.creation.box(extents=[0.1, 0.05, 0.05])
    fit = one_sphere_fit(box, [0, 0, 0], 0.08)
    with pytest.raises(exc, match=name):
        refine_fit(box, fit, **kwargs)
    with pytest.raises(TypeError, match="fit"):
        refine_fit(box, {"centres": []})
    with pytest.raises(TypeError, match="mesh"):
        refine_fit("box.stl", fit)


def test_fit_refined_is_no_worse_than_one_refinement():
    """The multi-start fit: no more spheres than the plain fit, a largest protrusion no
    higher than the refinement of the plain fit alone, the error within the tolerance on
    fresh samples."""
    from jwarp.importers.sphere_refine import fit_refined

    cap = trimesh.creation.capsule(height=0.12, radius=0.025, count=[32, 32])
    base = fit_spheres(cap, tolerance=TOL)
    one = refine_fit(cap, base, iters=150)
    got = fit_refined(cap, tolerance=TOL, refine={"iters": 150})
    assert got.k <= base.k
    assert got.max_protrusion <= one.max_protrusion + 1e-9
    assert fresh_error(cap, got.centres, got.radii) <= TOL
    with pytest.raises(ValueError, match="ladder"):
        fit_refined(cap, tolerance=TOL, ladder=(2.5,), refine={"iters": 5})


URDF = """<robot name="toy">
  <link name="base"/>
  {links}
</robot>"""


def toy_chain(tmp_path: Path) -> Path:
    """base -(j1..j4 revolute)- l1..l4 -(fixed)- hand -(fixed)- tcp."""
    parts, parent = [], "base"
    for i in range(1, 5):
        parts.append(f'<link name="l{i}"/><joint name="j{i}" type="revolute"><parent '
                     f'link="{parent}"/><child link="l{i}"/><origin xyz="0 0 0.1"/><axis '
                     f'xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/>'
                     f'</joint>')
        parent = f"l{i}"
    parts.append('<link name="hand"/><joint name="jh" type="fixed"><parent link="l4"/>'
                 '<child link="hand"/><origin xyz="0 0 0.1"/></joint>')
    parts.append('<link name="tcp"/><joint name="jt" type="fixed"><parent link="hand"/>'
                 '<child link="tcp"/><origin xyz="0 0 0.1"/></joint>')
    p = tmp_path / "toy.urdf"
    p.write_text(URDF.format(links="\n".join(parts)))
    return p


def test_link_protrusions_wrist_and_base(tmp_path):
    """The wrist: the links with at most 2 moving joints between them and the end
    effector (l2: j3, j4; l1 has 3); the fixed root gets the base factor."""
    from jwarp.importers.robot import load_urdf
    from jwarp.importers.sphere_refine import link_protrusions

    model = load_urdf(toy_chain(tmp_path), end_effectors={"tcp": "tcp"}).model
    got = link_protrusions(model, 0.02)
    assert got["base"] == {"protrusion": pytest.approx(0.06)}
    for name in ("l2", "l3", "l4"):
        assert got[name] == {"protrusion": pytest.approx(0.015),
                             "max_protrusion": pytest.approx(0.015)}, name
    for name in ("hand", "tcp"):  # rigid with the end effector: the spheres hug it
        assert got[name] == {"protrusion": pytest.approx(0.015),
                             "max_protrusion": pytest.approx(0.01)}, name
    assert "l1" not in got
    got1 = link_protrusions(model, 0.02, wrist_joints=0, wrist=0.5, base=1.0)
    assert got1["l4"]["protrusion"] == pytest.approx(0.01) and "l3" not in got1
    assert got1["base"]["protrusion"] == pytest.approx(0.02)
    with pytest.raises(ValueError, match="tolerance"):
        link_protrusions(model, 0.0)
    with pytest.raises(ValueError, match="wrist_joints"):
        link_protrusions(model, 0.01, wrist_joints=-1)


def test_refine_fit_of_a_part_below_the_tolerance_returns_the_fit():
    """A 5 mm cylinder (TIAGo's arm_tool_link) at a 1 cm tolerance: the refinement has no
    sphere to keep and returns the plain fit (it raised on an empty reduction)."""
    from jwarp.importers.sphere_refine import fit_refined
    from jwarp.importers.spheres import fit_spheres, primitive_mesh

    mesh = primitive_mesh("cylinder", [0.005, 0.005])
    fit = fit_refined(mesh, tolerance=0.01, protrusion=0.0075, max_protrusion=0.005)
    plain = fit_spheres(mesh, tolerance=0.01, protrusion=0.0075)
    assert fit.k >= 1 and fit.one_sided_error <= 0.01
    assert fit.k <= plain.k
