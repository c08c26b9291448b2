"""The convex pieces of imported collision geometry (jwarp.importers.collision_pieces):
every primitive's piece holds 2000 points of the exact primitive (surface and volume,
numpy), a mesh's piece is its hull (holds every vertex, made of vertices), an MJCF
ellipsoid's piece holds the ellipsoid; the Panda imported through ``spherized_robot`` has
one piece per collision geometry on its link's frame, equal to pinocchio's URDF collision
geometry's hull in the world at random configurations; ``jwarp import-urdf`` writes pieces
standing for its final spheres (after the home fit tightened them)."""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np
import pytest
import trimesh
from cli_helpers import run
from scipy.spatial import ConvexHull

from jwarp.importers.collision_pieces import (
    CYLINDER_SIDES,
    METHOD,
    geometry_piece,
    hull_vertices,
    pieces_from_geometries,
)
from jwarp.importers.robot import example_robot_urdf, load_urdf
from jwarp.importers.urdf import CollisionGeometry
from jwarp.model import RobotModel
from jwarp.world.spherize import SpherizeOptions, spherize, spherized_robot

N = 1000   # surface points, and as many volume points, of each primitive


def random_pose(rng: np.random.Generator) -> np.ndarray:
    """A random (4, 4) rigid transform (rotation by a random unit quaternion)."""
    w, x, y, z = (q := rng.normal(size=4)) / np.linalg.norm(q)
    T = np.eye(4)
    T[:3, :3] = [[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                 [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                 [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]]
    T[:3, 3] = rng.uniform(-0.3, 0.3, 3)
    return T


def posed(T: np.ndarray, p: np.ndarray) -> np.ndarray:
    return p @ T[:3, :3].T + T[:3, 3]


def unit_vectors(rng: np.random.Generator, n: int) -> np.ndarray:
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def box_points(size, rng):
    """N surface and N volume points of a box of full edges ``size`` centred at 0."""
    h = np.asarray(size, float) / 2
    surf = rng.uniform(-1, 1, (N, 3)) * h
    axis = rng.integers(0, 3, N)
    surf[np.arange(N), axis] = np.sign(rng.uniform(-1, 1, N)) * h[axis]
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]) * h
    return np.concatenate([surf, corners, rng.uniform(-1, 1, (N, 3)) * h])


def cylinder_points(r, length, rng):
    """Surface (side, cap rims and discs) and volume points of a cylinder along z."""
    a = rng.uniform(0, 2 * np.pi, N)
    z = rng.uniform(-length / 2, length / 2, N)
    side = np.column_stack([r * np.cos(a), r * np.sin(a), z])
    cap = np.sqrt(rng.uniform(0, 1, N)) * r
    caps = np.column_stack([cap * np.cos(a), cap * np.sin(a),
                            np.sign(rng.uniform(-1, 1, N)) * length / 2])
    ring = np.linspace(0, 2 * np.pi, 721)   # the rims, where a polygon would cut first
    rims = np.concatenate([np.column_stack([r * np.cos(ring), r * np.sin(ring),
                                            np.full(721, s * length / 2)]) for s in (-1, 1)])
    u = np.sqrt(rng.uniform(0, 1, N)) * r
    vol = np.column_stack([u * np.cos(a), u * np.sin(a), rng.uniform(-length / 2, length / 2, N)])
    return np.concatenate([side[: N // 2], caps[: N // 2], rims, vol])


def ball_points(r, rng):
    return np.concatenate([r * unit_vectors(rng, N),
                           r * unit_vectors(rng, N) * rng.uniform(0, 1, (N, 1)) ** (1 / 3)])


def capsule_points(r, length, rng):
    """Surface (side and hemispheres) and volume points of a capsule along z."""
    a = rng.uniform(0, 2 * np.pi, N)
    side = np.column_stack([r * np.cos(a), r * np.sin(a), rng.uniform(-length / 2, length / 2, N)])
    cap = r * unit_vectors(rng, N)
    cap[:, 2] = np.abs(cap[:, 2]) * np.sign(rng.uniform(-1, 1, N))
    cap[:, 2] += np.sign(cap[:, 2]) * length / 2
    vol = ball_points(r, rng)[N:]
    vol[:, 2] += rng.uniform(-length / 2, length / 2, N)
    return np.concatenate([side[: N // 2], cap[: N // 2], vol])


def outside_polytope(vertices: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(P,) how far [m] each point lies outside the hull of ``vertices`` (<= 0 inside), by
    its half-space inequalities."""
    eq = ConvexHull(vertices).equations
    return (points @ eq[:, :3].T + eq[:, 3]).max(axis=1)


def segment_distance(points, a, b):
    ab = b - a
    t = np.clip((points - a) @ ab / max(float(ab @ ab), 1e-300), 0.0, 1.0)
    return np.linalg.norm(points - (a + t[:, None] * ab), axis=1)


# ------------------------------------------------------------------ primitives
def test_box_piece_is_its_corners_and_holds_the_box():
    rng = np.random.default_rng(1)
    T, size = random_pose(rng), [0.3, 0.04, 0.02]
    v, r = geometry_piece("box", size, T)
    assert r == 0.0 and v.shape == (8, 3)
    h = np.array(size) / 2
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]) * h
    np.testing.assert_allclose(np.sort(v, axis=0), np.sort(posed(T, corners), axis=0),
                               atol=1e-15)
    assert outside_polytope(v, posed(T, box_points(size, rng))).max() <= 1e-9


def test_cylinder_piece_circumscribes_the_circles():
    rng = np.random.default_rng(2)
    T, rad, length = random_pose(rng), 0.05, 0.2
    v, r = geometry_piece("cylinder", [rad, length], T)
    assert r == 0.0 and v.shape == (2 * CYLINDER_SIDES, 3)
    local = posed(np.linalg.inv(T), v)
    np.testing.assert_allclose(np.hypot(local[:, 0], local[:, 1]),
                               rad / math.cos(math.pi / CYLINDER_SIDES), rtol=1e-12)
    np.testing.assert_allclose(np.sort(np.unique(np.round(local[:, 2], 12))),
                               [-length / 2, length / 2])
    out = outside_polytope(v, posed(T, cylinder_points(rad, length, rng)))
    assert out.max() <= 1e-9
    # tight: the polygon's edges touch the circle (a rim point on an edge's middle)
    assert out.max() >= -1e-6


def test_sphere_and_capsule_pieces_hold_them():
    rng = np.random.default_rng(3)
    T = random_pose(rng)
    v, r = geometry_piece("sphere", [0.07], T)
    assert r == 0.07 and v.shape == (1, 3)
    np.testing.assert_allclose(v[0], T[:3, 3], atol=1e-15)
    pts = posed(T, ball_points(0.07, rng))
    assert (np.linalg.norm(pts - v[0], axis=1) - r).max() <= 1e-12
    v, r = geometry_piece("capsule", [0.03, 0.25], T)
    assert r == 0.03 and v.shape == (2, 3)
    np.testing.assert_allclose(v, posed(T, np.array([[0, 0, -0.125], [0, 0, 0.125]])),
                               atol=1e-15)
    pts = posed(T, capsule_points(0.03, 0.25, rng))
    assert (segment_distance(pts, v[0], v[1]) - r).max() <= 1e-12


def test_unknown_kind_and_bad_size_are_refused():
    with pytest.raises(ValueError, match="kind: unknown geometry 'cone'"):
        geometry_piece("cone", [1, 2])
    with pytest.raises(ValueError, match="size: a box takes 3"):
        geometry_piece("box", [1, 2])
    with pytest.raises(ValueError, match="origin"):
        geometry_piece("box", [1, 2, 3], np.zeros((4, 4)))


# ------------------------------------------------------------------ meshes
def test_mesh_piece_is_the_hull_of_the_scaled_posed_mesh(tmp_path):
    rng = np.random.default_rng(4)
    # not convex: a ring and a box beside it
    ring = trimesh.creation.annulus(r_min=0.02, r_max=0.05, height=0.03, sections=40)
    block = trimesh.creation.box(extents=[0.02, 0.03, 0.04])
    block.apply_translation([0.09, 0.0, 0.01])
    mesh = trimesh.util.concatenate([ring, block])
    path = tmp_path / "part.stl"
    mesh.export(path)
    T, scale = random_pose(rng), np.array([1.5, 0.5, 2.0])
    g = CollisionGeometry(link="arm", kind="mesh", size=np.zeros(0), origin=T,
                          mesh_uri="part.stl", mesh_path=str(path), scale=scale)
    m = RobotModel.from_dict(ROBOT)
    piece = pieces_from_geometries(m, [g]).pieces[0]
    stored = trimesh.load(path, force="mesh")     # the file's float32 vertices
    ref = posed(T, np.asarray(stored.vertices, float) * scale)
    assert piece.radius == 0.0 and piece.frame == m.frame_index("arm")
    assert outside_polytope(piece.vertices, ref).max() <= 1e-9       # holds every vertex
    d = np.linalg.norm(piece.vertices[:, None] - ref[None], axis=2).min(axis=1)
    assert d.max() <= 1e-12                                          # made of vertices
    assert len(piece.vertices) < len(np.unique(ref, axis=0))         # inner ones dropped
    assert len(piece.vertices) == len(ConvexHull(ref).vertices)
    # surface samples of the mesh too
    pts = posed(T, np.asarray(stored.sample(2000, seed=5), float) * scale)
    assert outside_polytope(piece.vertices, pts).max() <= 1e-9
    assert piece.source == "arm <collision> 1 mesh hull"


def test_flat_mesh_piece_is_its_vertices():
    square = trimesh.Trimesh(vertices=[[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]],
                             faces=[[0, 1, 2], [0, 2, 3]], process=False)
    T = random_pose(np.random.default_rng(6))
    v, r = geometry_piece("mesh", None, T, square, 0.1)
    assert r == 0.0 and len(v) == 4
    np.testing.assert_allclose(np.sort(v, axis=0),
                               np.sort(posed(T, np.asarray(square.vertices) * 0.1), axis=0),
                               atol=1e-15)
    assert len(hull_vertices(np.zeros((5, 3)))) == 1


# ------------------------------------------------------------------ a URDF of every kind
ROBOT = {
    "name": "two", "joints": [{"name": "j1", "limits": [-3, 3]}],
    "frames": [{"name": "base", "parent": None, "kind": "static",
                "transform": np.eye(4).tolist()},
               {"name": "arm", "parent": "base", "kind": "dh", "dh": [0.1, 0, 0, 0, 0],
                "joint": "j1"}],
    "spheres": [{"frame": "arm", "position": [0, 0, 0], "radius": 0.1}],
}

URDF = """<?xml version="1.0"?>
<robot name="kinds">
  <link name="base"><collision><geometry><sphere radius="0.05"/></geometry></collision>
    <collision><origin xyz="0 0 -0.05"/><geometry><box size="0.3 0.3 0.02"/></geometry></collision></link>
  <link name="arm"><collision><origin xyz="0.15 0 0" rpy="0 0 0.3"/>
    <geometry><box size="0.3 0.04 0.02"/></geometry></collision>
    <collision><origin xyz="0.3 0 0" rpy="1.5707963 0 0"/>
    <geometry><capsule radius="0.02" length="0.1"/></geometry></collision></link>
  <link name="tip"><collision><origin xyz="0.05 0 0" rpy="0 1.5707963 0"/>
    <geometry><cylinder radius="0.02" length="0.1"/></geometry></collision></link>
  <joint name="j1" type="revolute"><parent link="base"/><child link="arm"/>
    <origin xyz="0 0 0.1"/><axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="j2" type="revolute"><parent link="arm"/><child link="tip"/>
    <origin xyz="0.3 0 0"/><axis xyz="0 1 0"/><limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
</robot>
"""


@pytest.fixture
def urdf(tmp_path, monkeypatch):
    monkeypatch.setenv("JWARP_CACHE", str(tmp_path / "cache"))
    p = tmp_path / "kinds.urdf"
    p.write_text(URDF)
    return p


def test_one_piece_per_geometry_on_its_links_frame(urdf):
    imp = load_urdf(urdf)
    cp = pieces_from_geometries(imp.model, imp.geometries)
    names = imp.model.frame_names
    assert [names[p.frame] for p in cp.pieces] == [g.link for g in imp.geometries]
    assert [p.source for p in cp.pieces] == [
        "base <collision> 1 sphere", "base <collision> 2 box", "arm <collision> 1 box",
        "arm <collision> 2 capsule", "tip <collision> 1 cylinder"]
    assert [len(p.vertices) for p in cp.pieces] == [1, 8, 8, 2, 2 * CYLINDER_SIDES]
    assert cp.method == METHOD and cp.sphere_count == len(imp.model.spheres) == 1
    assert cp.extra_spheres(imp.model) == []
    # the capsule along the link's y (rpy 90 deg about x): ends at y = -+0.05
    np.testing.assert_allclose(cp.pieces[3].vertices, [[0.3, 0.05, 0], [0.3, -0.05, 0]],
                               atol=1e-8)
    with pytest.raises(ValueError, match=r"geometries\[1\] \(link 'nope'\): link: unknown "
                                         r"frame 'nope'"):
        pieces_from_geometries(imp.model, [imp.geometries[0],
                                           {"link": "nope", "kind": "box", "size": [1, 1, 1]}])


def test_spherized_robot_records_pieces_for_its_spheres(urdf):
    opts = SpherizeOptions(tolerance=0.03, max_spheres=2, refine=False, pair_samples=100)
    with warnings.catch_warnings():   # the coarse fit's bounds: not what is tested
        warnings.simplefilter("ignore")
        model, _ = spherized_robot(urdf, opts)
    cp = model.collision_pieces
    assert cp is not None and len(cp.pieces) == 5 and cp.method == METHOD
    assert cp.sphere_count == len(model.spheres) > 1 and cp.extra_spheres(model) == []


H = 0.05   # half edge of the cubes [m]


def _cube(name, x):
    return (f'<link name="{name}"><collision><origin xyz="{x} 0 0"/><geometry>'
            f'<box size="{2 * H} {2 * H} {2 * H}"/></geometry></collision></link>')


def _slider(name, parent, child, axis):
    return (f'<joint name="{name}" type="prismatic"><parent link="{parent}"/>'
            f'<child link="{child}"/><axis xyz="{axis}"/>'
            f'<limit lower="-0.5" upper="0.5" effort="1" velocity="1"/></joint>')


def test_import_urdf_stamps_the_pieces_after_the_home_fit(tmp_path, capsys, monkeypatch):
    """The cubes of tests/world/test_home_fit.py: at the home 'b' is 4 mm from 'base', so
    the home fit tightens their spheres after the fit made the pieces; the written model's
    pieces stand for the tightened spheres."""
    text = ('<robot name="boxes">' + _cube("base", 0.0)
            + '<link name="m1"><collision><origin xyz="0 0 1"/><geometry><box size="0.01 0.01 '
              '0.01"/></geometry></collision></link>' + _cube("a", 2 * H - 0.002)
            + '<link name="m2"><collision><origin xyz="0 0 -1"/><geometry><box size="0.01 0.01 '
              '0.01"/></geometry></collision></link>' + _cube("b", -2 * H - 0.004)
            + _slider("j1", "base", "m1", "0 0 1") + _slider("j2", "m1", "a", "0 1 0")
            + _slider("j3", "base", "m2", "0 0 1") + _slider("j4", "m2", "b", "0 1 0")
            + "</robot>")
    boxes = tmp_path / "boxes.urdf"
    boxes.write_text(text)
    monkeypatch.setenv("JWARP_CACHE", str(tmp_path / "cache"))   # one fit for both
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fitted, _ = spherized_robot(boxes, SpherizeOptions(tolerance=0.03, pair_samples=200))
    out = tmp_path / "boxes.json"
    code, _, err = run(capsys, ["import-urdf", boxes, "--out", out, "--pair-samples", "200",
                                "--tolerance", "0.03", "--home", "0,0.3,0,0"])
    assert code == 0, err
    saved = RobotModel.load(out)
    cp = saved.collision_pieces
    assert cp is not None and len(cp.pieces) == 5
    assert fitted.collision_pieces.extra_spheres(saved) is None      # spheres tightened
    assert cp.sphere_digest != fitted.collision_pieces.sphere_digest
    assert cp.extra_spheres(saved) == [] and cp.sphere_count == len(saved.spheres)
    code, _, err = run(capsys, ["import-urdf", boxes, "--out", out, "--spheres", "none"])
    assert code == 0 and RobotModel.load(out).collision_pieces is None


# ------------------------------------------------------------------ MJCF
MJCF = """
<mujoco model="kinds">
  <worldbody>
    <body name="base" pos="0.1 -0.2 0.3" quat="0.9 0.1 -0.3 0.2">
      <geom type="cylinder" size="0.05 0.1" pos="0.01 0 0" euler="0.3 0.2 0.1"/>
      <joint name="j1" type="hinge" axis="0.3 -0.5 0.8" range="-2 2"/>
      <body name="upper" pos="0 0.1 0.4" quat="0.7 0 0.7 0">
        <joint name="j2" type="hinge" axis="1 0 0" range="-1.5 1.5"/>
        <geom type="capsule" fromto="0 0 0 0.1 0 0.3" size="0.04"/>
        <geom type="box" size="0.02 0.03 0.1" pos="0 0 0.1" euler="0.5 0 0"/>
        <geom type="ellipsoid" size="0.02 0.03 0.04" pos="0 0.05 0.2" euler="0.1 0.7 0"/>
      </body>
    </body>
  </worldbody>
</mujoco>
"""


def test_mjcf_pieces_hold_mujocos_geoms(tmp_path):
    """Each piece, in its body's frame, holds 2000 points of the exact geom placed by
    MuJoCo's own kinematics (geom pose relative to its body)."""
    mujoco = pytest.importorskip("mujoco")
    from jwarp.importers.robot import load_mjcf

    path = tmp_path / "kinds.xml"
    path.write_text(MJCF)
    imp = load_mjcf(path)
    cp = pieces_from_geometries(imp.model, imp.geometries)
    mm = mujoco.MjModel.from_xml_path(str(path))
    md = mujoco.MjData(mm)
    mujoco.mj_kinematics(mm, md)
    rng = np.random.default_rng(7)
    assert len(cp.pieces) == mm.ngeom == 4
    for g, piece in zip(range(mm.ngeom), cp.pieces):
        body = mujoco.mj_id2name(mm, mujoco.mjtObj.mjOBJ_BODY, int(mm.geom_bodyid[g]))
        assert imp.model.frame_names[piece.frame] == body
        Tb, Tg = np.eye(4), np.eye(4)
        Tb[:3, :3], Tb[:3, 3] = md.xmat[mm.geom_bodyid[g]].reshape(3, 3), md.xpos[mm.geom_bodyid[g]]
        Tg[:3, :3], Tg[:3, 3] = md.geom_xmat[g].reshape(3, 3), md.geom_xpos[g]
        T = np.linalg.inv(Tb) @ Tg
        s = mm.geom_size[g]
        kind = int(mm.geom_type[g])
        if kind == mujoco.mjtGeom.mjGEOM_CYLINDER:
            out = outside_polytope(piece.vertices, posed(T, cylinder_points(s[0], 2 * s[1], rng)))
        elif kind == mujoco.mjtGeom.mjGEOM_BOX:
            out = outside_polytope(piece.vertices, posed(T, box_points(2 * s[:3], rng)))
        elif kind == mujoco.mjtGeom.mjGEOM_ELLIPSOID:
            pts = np.concatenate([unit_vectors(rng, 5000), ball_points(1.0, rng)]) * s[:3]
            out = outside_polytope(piece.vertices, posed(T, pts))
            assert "ellipsoid" in piece.source
        else:
            assert kind == mujoco.mjtGeom.mjGEOM_CAPSULE
            out = segment_distance(posed(T, capsule_points(s[0], 2 * s[1], rng)),
                                   piece.vertices[0], piece.vertices[1]) - piece.radius
        assert out.max() <= 1e-9, (g, out.max())
    with warnings.catch_warnings():   # a coarse fit's bounds: not what is tested
        warnings.simplefilter("ignore")
        fitted, _ = spherize(imp, SpherizeOptions(tolerance=0.03, max_spheres=2, refine=False,
                                                  pair_samples=10))
    assert len(fitted.collision_pieces.pieces) == 4
    assert fitted.collision_pieces.extra_spheres(fitted) == []


# ------------------------------------------------------------------ the Panda
@pytest.fixture(scope="module")
def panda(tmp_path_factory):
    try:
        path = example_robot_urdf("panda")
    except ValueError as e:
        pytest.skip(str(e))
    mp = pytest.MonkeyPatch()
    mp.setenv("JWARP_CACHE", str(tmp_path_factory.mktemp("cache")))
    try:   # a coarse fit (the pieces do not depend on it)
        opts = SpherizeOptions(tolerance=0.03, max_spheres=2, pair_samples=50, refine=False)
        with warnings.catch_warnings():   # the coarse fit's bounds: not what is tested
            warnings.simplefilter("ignore")
            model, _ = spherized_robot(path, opts)
            cached, report = spherized_robot(path, opts)
    finally:
        mp.undo()
    assert report.cached
    return path, model, cached


def test_panda_has_one_piece_per_collision_geometry(panda):
    path, model, cached = panda
    imp = load_urdf(path)
    cp = model.collision_pieces
    assert cp is not None and len(cp.pieces) == len(imp.geometries) == 17
    assert [model.frame_names[p.frame] for p in cp.pieces] == [g.link for g in imp.geometries]
    assert cp.sphere_count == len(model.spheres) and cp.extra_spheres(model) == []
    counts = [len(p.vertices) for p in cp.pieces]
    assert sum(counts) == 1232 and max(counts) == 152      # 9 mesh hulls, 8 finger boxes
    assert all(p.radius == 0.0 for p in cp.pieces)
    assert cached.collision_pieces is not None and cached.collision_pieces.extra_spheres(cached) == []
    for p, q in zip(cp.pieces, cached.collision_pieces.pieces):   # the cache keeps them
        assert p.frame == q.frame and np.array_equal(p.vertices, q.vertices)


def test_panda_pieces_are_pinocchios_collision_hulls(panda):
    """At 3 random configurations, each piece placed by pinocchio's FK of its link and the
    hull of the URDF collision geometry placed by pinocchio hold each other within 1e-6 m."""
    pin = pytest.importorskip("pinocchio")
    coal = pytest.importorskip("coal")
    path, model, _ = panda
    pm = pin.buildModelFromUrdf(path)
    pd = pm.createData()
    dirs = [str(p) for p in Path(path).resolve().parents]
    gm = pin.buildGeomFromUrdf(pm, path, pin.GeometryType.COLLISION, package_dirs=dirs)
    gd = pin.GeometryData(gm)
    local = []   # each geometry's points in its own frame
    for go in gm.geometryObjects:
        if isinstance(go.geometry, coal.Box):
            h = np.asarray(go.geometry.halfSide, float)
            local.append(np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1)
                                   for z in (-1, 1)]) * h)
        else:
            m = trimesh.load(go.meshPath, force="mesh")
            local.append(np.asarray(m.vertices, float) * np.asarray(go.meshScale, float))
    links = [pm.frames[go.parentFrame].name for go in gm.geometryObjects]
    pieces = model.collision_pieces.pieces
    assert sorted(links) == sorted(model.frame_names[p.frame] for p in pieces)
    by_link: dict[str, list[int]] = {}
    for k, p in enumerate(pieces):
        by_link.setdefault(model.frame_names[p.frame], []).append(k)
    order = [by_link[ln].pop(0) for ln in links]   # the geometries' order within a link
    rng = np.random.default_rng(11)
    lo, hi = pm.lowerPositionLimit, pm.upperPositionLimit
    for _ in range(3):
        q = rng.uniform(lo, hi)
        pin.framesForwardKinematics(pm, pd, q)
        pin.updateGeometryPlacements(pm, pd, gm, gd, q)
        for gi, k in enumerate(order):
            piece = pieces[k]
            Tf = pd.oMf[pm.getFrameId(model.frame_names[piece.frame], pin.BODY)].homogeneous
            world_piece = posed(Tf, piece.vertices)
            world_geom = posed(gd.oMg[gi].homogeneous, local[gi])
            assert outside_polytope(world_geom, world_piece).max() <= 1e-6, piece.source
            assert outside_polytope(world_piece, world_geom).max() <= 1e-6, piece.source
