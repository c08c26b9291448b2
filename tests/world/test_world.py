"""Worlds: simplex noise, SDFs (occupancy, mesh, points), lookup, files, feasibility.

Every check compares against an independent plain-numpy/scipy computation written here.
"""

import math
import os

import numpy as np
import pytest
import trimesh
from reference import ref_fk
from scipy.interpolate import RegularGridInterpolator

import jwarp
from jwarp.world import (
    World,
    feasible_fraction,
    feasible_simplex_world,
    fixed_spheres,
    load_world,
    noise_grid,
    parse_world_spec,
    random_configurations,
    save_world,
    simplex_noise,
    simplex_occupancy,
    simplex_world,
    world_from_mesh,
    world_from_occupancy,
    world_from_points,
)

# ================================================================ simplex noise
_GRAD3 = [(1, 1, 0), (-1, 1, 0), (1, -1, 0), (-1, -1, 0), (1, 0, 1), (-1, 0, 1), (1, 0, -1),
          (-1, 0, -1), (0, 1, 1), (0, -1, 1), (0, 1, -1), (0, -1, -1)]


def _perm(seed):
    p = np.random.default_rng(seed).permutation(256).tolist()
    return p + p


def ref_noise2(x, y, perm):
    """Gustavson's SimplexNoise.noise(x, y), transcribed scalar by scalar."""
    F2 = 0.5 * (math.sqrt(3.0) - 1.0)
    G2 = (3.0 - math.sqrt(3.0)) / 6.0
    s = (x + y) * F2
    i, j = math.floor(x + s), math.floor(y + s)
    t = (i + j) * G2
    x0, y0 = x - (i - t), y - (j - t)
    i1, j1 = (1, 0) if x0 > y0 else (0, 1)
    x1, y1 = x0 - i1 + G2, y0 - j1 + G2
    x2, y2 = x0 - 1.0 + 2.0 * G2, y0 - 1.0 + 2.0 * G2
    ii, jj = i & 255, j & 255
    n = 0.0
    for (cx, cy, gi) in ((x0, y0, perm[ii + perm[jj]] % 12),
                         (x1, y1, perm[ii + i1 + perm[jj + j1]] % 12),
                         (x2, y2, perm[ii + 1 + perm[jj + 1]] % 12)):
        t0 = 0.5 - cx * cx - cy * cy
        if t0 >= 0:
            g = _GRAD3[gi]
            n += t0 ** 4 * (g[0] * cx + g[1] * cy)
    return 70.0 * n


def ref_noise3(x, y, z, perm):
    """Gustavson's SimplexNoise.noise(x, y, z), transcribed scalar by scalar."""
    F3, G3 = 1.0 / 3.0, 1.0 / 6.0
    s = (x + y + z) * F3
    i, j, k = math.floor(x + s), math.floor(y + s), math.floor(z + s)
    t = (i + j + k) * G3
    x0, y0, z0 = x - (i - t), y - (j - t), z - (k - t)
    if x0 >= y0:
        if y0 >= z0:
            o1, o2 = (1, 0, 0), (1, 1, 0)
        elif x0 >= z0:
            o1, o2 = (1, 0, 0), (1, 0, 1)
        else:
            o1, o2 = (0, 0, 1), (1, 0, 1)
    else:
        if y0 < z0:
            o1, o2 = (0, 0, 1), (0, 1, 1)
        elif x0 < z0:
            o1, o2 = (0, 1, 0), (0, 1, 1)
        else:
            o1, o2 = (0, 1, 0), (1, 1, 0)
    ii, jj, kk = i & 255, j & 255, k & 255
    n = 0.0
    for c, o in enumerate(((0, 0, 0), o1, o2, (1, 1, 1))):
        cx, cy, cz = x0 - o[0] + c * G3, y0 - o[1] + c * G3, z0 - o[2] + c * G3
        gi = perm[ii + o[0] + perm[jj + o[1] + perm[kk + o[2]]]] % 12
        t0 = 0.6 - cx * cx - cy * cy - cz * cz
        if t0 >= 0:
            g = _GRAD3[gi]
            n += t0 ** 4 * (g[0] * cx + g[1] * cy + g[2] * cz)
    return 32.0 * n


@pytest.mark.parametrize("dim", [2, 3])
def test_noise_matches_scalar_reference(dim):
    rng = np.random.default_rng(5)
    pts = rng.uniform(-30, 30, (400, dim))
    perm = _perm(7)
    ref = [ref_noise2(*p, perm) if dim == 2 else ref_noise3(*p, perm) for p in pts]
    np.testing.assert_allclose(simplex_noise(pts, seed=7), ref, rtol=0, atol=1e-12)


@pytest.mark.parametrize("dim", [2, 3])
def test_noise_reproducible_range_and_continuous(dim):
    rng = np.random.default_rng(0)
    pts = rng.uniform(0, 50, (20000, dim))
    a = simplex_noise(pts, seed=3)
    np.testing.assert_array_equal(a, simplex_noise(pts, seed=3))
    b = simplex_noise(pts, seed=4)
    assert np.abs(a - b).mean() > 0.1  # another seed, another function
    assert np.abs(a).max() <= 1.05 and a.std() > 0.15
    assert abs(a.mean()) < 0.05
    # continuity: tiny steps in random directions change the value by O(step)
    step = 1e-6 * rng.normal(size=pts.shape)
    assert np.abs(simplex_noise(pts + step, seed=3) - a).max() < 1e-3


def test_noise_grid_and_occupancy_knobs():
    g1 = noise_grid((32, 24), seed=1)
    assert g1.shape == (32, 24)
    np.testing.assert_array_equal(g1, noise_grid((32, 24), seed=1))
    assert not np.array_equal(g1, noise_grid((32, 24), seed=2))
    fill = [simplex_occupancy((48, 48, 48), seed=2, threshold=t).mean() for t in (0.2, 0.4, 0.6)]
    assert fill[0] > fill[1] > fill[2] > 0
    # higher frequency: more, smaller blobs -> more occupied/free transitions along x
    lo = simplex_occupancy((128, 128), seed=2, threshold=0.3, frequency=2.0)
    hi = simplex_occupancy((128, 128), seed=2, threshold=0.3, frequency=8.0)
    assert np.abs(np.diff(hi.astype(int), axis=0)).sum() > 2 * np.abs(np.diff(lo.astype(int), axis=0)).sum()
    oct3 = noise_grid((64, 64), seed=1, octaves=3)
    assert np.abs(oct3).max() <= 1.05
    with pytest.raises(ValueError, match="frequency"):
        noise_grid((8, 8), seed=0, frequency=0)
    with pytest.raises(ValueError, match="octaves"):
        noise_grid((8, 8), seed=0, octaves=0)
    with pytest.raises(TypeError, match="seed"):
        noise_grid((8, 8), seed=1.5)
    with pytest.raises(ValueError, match="shape"):
        noise_grid((8,), seed=0)


def test_simplex_world_reproducible_and_keep_free():
    w1 = simplex_world(2, seed=11, shape=(40, 40), threshold=0.1)
    w2 = simplex_world(2, seed=11, shape=(40, 40), threshold=0.1)
    np.testing.assert_array_equal(w1.sdf, w2.sdf)
    assert w1.meta["seed"] == 11 and w1.occupancy.any()
    centre = w1.cell_centres()[w1.occupancy][0]
    w3 = simplex_world(2, seed=11, shape=(40, 40), threshold=0.1, keep_free=[(centre, 0.2)])
    near = np.linalg.norm(w3.cell_centres() - centre, axis=-1) <= 0.2
    assert not w3.occupancy[near].any()
    np.testing.assert_array_equal(w3.occupancy[~near], w1.occupancy[~near])
    with pytest.raises(ValueError, match="dim"):
        simplex_world(4, seed=0)


# ==================================================================== SDF
def brute_sdf(occ, h):
    """Distance of every cell centre to the nearest cell centre of the other kind, minus
    half a voxel, negative inside (the documented convention), by brute force."""
    idx = np.stack(np.meshgrid(*[np.arange(n) for n in occ.shape], indexing="ij"), -1).reshape(-1, occ.ndim)
    flat = occ.reshape(-1)
    d = np.linalg.norm(idx[:, None, :] - idx[None, :, :], axis=-1) * h
    to_occ = np.where(flat[None, :], d, np.inf).min(1)
    to_free = np.where(~flat[None, :], d, np.inf).min(1)
    out = np.where(flat, -(to_free - h / 2), to_occ - h / 2)
    return out.reshape(occ.shape)


@pytest.mark.parametrize("shape", [(9, 11), (7, 8, 6)])
def test_sdf_from_occupancy_equals_brute_force(shape):
    rng = np.random.default_rng(1)
    occ = rng.random(shape) < 0.3
    h = 0.05
    lower = np.array([-0.2, 0.1, 0.3][:len(shape)])
    w = world_from_occupancy(occ, lower, h)
    np.testing.assert_allclose(w.sdf, brute_sdf(occ, h), rtol=0, atol=1e-12)
    np.testing.assert_allclose(w.limits[:, 0], lower)
    np.testing.assert_allclose(w.limits[:, 1], lower + (np.array(shape) - 1) * h)
    assert w.dim == len(shape) and w.shape == shape and w.occupancy.dtype == bool
    # the same grid from limits (dim, 2) alone
    w2 = world_from_occupancy(occ, w.limits)
    np.testing.assert_allclose(w2.sdf, w.sdf, rtol=0, atol=1e-15)
    assert np.isclose(w2.voxel_size, h)


def test_sdf_single_voxel_surface_on_faces_and_empty_grids(device):
    occ = np.zeros((9, 9, 9), bool)
    occ[4, 4, 4] = True
    w = world_from_occupancy(occ, np.zeros(3), 0.1)
    np.testing.assert_allclose(w.sdf[4, 4, 4], -0.05)
    np.testing.assert_allclose(w.sdf[4 + np.arange(1, 5), 4, 4], 0.1 * np.arange(1, 5) - 0.05)
    # interpolation puts the surface on the cube's face, half a voxel from the centre
    assert abs(w.distance(np.array([0.45, 0.4, 0.4]), device=device)) < 1e-12
    empty = world_from_occupancy(np.zeros((5, 6), bool), np.zeros(2), 0.1)
    full = world_from_occupancy(np.ones((5, 6), bool), np.zeros(2), 0.1)
    assert np.all(empty.sdf > 0.6) and np.all(full.sdf < -0.6)


def box_sdf(p, centre, half):
    q = np.abs(p - centre) - half
    return np.linalg.norm(np.maximum(q, 0), axis=-1) + np.minimum(q.max(-1), 0)


def test_mesh_sdf_box_and_sphere_closed_form(device):
    lim = np.array([[-0.5, 0.5], [-0.5, 0.5], [-0.4, 0.6]])
    box = trimesh.creation.box(extents=(0.4, 0.3, 0.5))
    box.apply_translation((0.05, -0.02, 0.1))
    w = world_from_mesh(box, lim, 0.05, device=device)
    assert w.shape == (21, 21, 21)
    ref = box_sdf(w.cell_centres(), np.array([0.05, -0.02, 0.1]), np.array([0.2, 0.15, 0.25]))
    np.testing.assert_allclose(w.sdf, ref, atol=2e-6)
    assert (w.sdf < 0).sum() > 0 and np.array_equal(w.occupancy, w.sdf < 0)
    ball = trimesh.creation.icosphere(subdivisions=4, radius=0.3)
    w = world_from_mesh((ball.vertices, ball.faces), lim, shape=(21, 21, 21), device=device)
    ref = np.linalg.norm(w.cell_centres(), axis=-1) - 0.3
    np.testing.assert_allclose(w.sdf, ref, atol=2.5e-3)  # facets vs the true sphere
    np.testing.assert_array_equal(np.sign(w.sdf[np.abs(ref) > 3e-3]), np.sign(ref[np.abs(ref) > 3e-3]))
    with pytest.raises(ValueError, match="mesh"):
        world_from_mesh((ball.vertices, ball.faces + 10_000), lim, 0.05, device=device)
    with pytest.raises(ValueError, match="watertight"):
        world_from_mesh((ball.vertices, ball.faces[1:]), lim, 0.05, device=device)


def test_world_from_points():
    rng = np.random.default_rng(2)
    dirs = rng.normal(size=(3000, 3))
    pts = 0.3 * dirs / np.linalg.norm(dirs, axis=1, keepdims=True)
    pts = np.concatenate([pts, [[5.0, 5.0, 5.0]]])  # one point outside the grid
    w = world_from_points(pts, np.array([[-0.5, 0.5]] * 3), 0.05)
    occ = np.zeros(w.shape, bool)
    idx = np.rint((pts[:-1] + 0.5) / 0.05).astype(int)
    occ[tuple(idx.T)] = True
    np.testing.assert_array_equal(w.occupancy, occ)
    np.testing.assert_allclose(w.sdf, world_from_occupancy(occ, w.limits).sdf)
    assert w.meta["points_outside"] == 1
    with pytest.raises(ValueError, match="points"):
        world_from_points(np.zeros((3, 4)), np.zeros((3, 2)), 0.1)


# ================================================================ lookup
def ref_lookup(world, x):
    """RegularGridInterpolator inside the cell-centre box, plus the documented outside
    rule D(clamp(x)) + |x - clamp(x)|."""
    axes = [world.limits[d, 0] + world.voxel_size * np.arange(n) for d, n in enumerate(world.shape)]
    xc = np.clip(x, world.limits[:, 0], world.limits[:, 1])
    interp = RegularGridInterpolator(axes, world.sdf, bounds_error=False, fill_value=None)
    return interp(xc) + np.linalg.norm(x - xc, axis=-1)


@pytest.mark.parametrize("dim", [2, 3])
def test_lookup_matches_scipy_interpolation_and_fd_gradient(device, dim):
    w = simplex_world(dim, seed=4, shape=(13, 11, 9)[:dim], limits=np.array([[-1, 1.4], [0, 2], [0.5, 2.1]][:dim]),
                      threshold=0.2)
    rng = np.random.default_rng(3)
    lo, hi = w.limits[:, 0] - 0.5, w.limits[:, 1] + 0.5  # also outside the grid
    x = rng.uniform(lo, hi, (500, dim))
    d, g = w.distance(x, grad=True, device=device)
    np.testing.assert_allclose(d, ref_lookup(w, x), rtol=0, atol=1e-12)
    h = 1e-7
    fd = np.stack([(ref_lookup(w, x + h * e) - ref_lookup(w, x - h * e)) / (2 * h)
                   for e in np.eye(dim)], -1)
    # skip points within h of a cell boundary (kinks of the piecewise-linear field)
    u = (x - w.limits[:, 0]) / w.voxel_size
    smooth = np.all(np.abs(u - np.round(u)) > 1e-4, axis=1)
    np.testing.assert_allclose(g[smooth], fd[smooth], rtol=0, atol=1e-6)
    # float32 field: the same within float32 precision
    d32 = w.astype(np.float32).distance(x, device=device)
    np.testing.assert_allclose(d32, d, atol=1e-5)


def test_lookup_far_outside_grows(device):
    w = simplex_world(2, seed=1, shape=(16, 16))
    far = np.array([[10.0, 0.0], [20.0, 0.0]])
    d = w.distance(far, device=device)
    assert d[1] - d[0] == pytest.approx(10.0, abs=1e-9)
    with pytest.raises(ValueError, match="points"):
        w.distance(np.zeros((4, 3)), device=device)


# ================================================================ files
def test_npz_round_trip(tmp_path, device):
    w = simplex_world(3, seed=2, shape=(10, 12, 8)).astype(np.float32)
    w.meta["note"] = "hello"
    path = tmp_path / "w.npz"
    w.save(path)
    assert sorted(os.listdir(tmp_path)) == ["w.npz"]  # no temporary files left behind
    r = World.load(path)
    assert r.sdf.dtype == np.float32
    np.testing.assert_array_equal(r.sdf, w.sdf)
    np.testing.assert_array_equal(r.occupancy, w.occupancy)
    np.testing.assert_array_equal(r.limits, w.limits)
    assert r.voxel_size == w.voxel_size and r.meta == w.meta
    m = world_from_mesh(trimesh.creation.box(extents=(0.2, 0.2, 0.2)), np.array([[-0.3, 0.3]] * 3), 0.1,
                        device=device)
    m.occupancy = None
    save_world(m, tmp_path / "m.npz")
    assert load_world(tmp_path / "m.npz").occupancy is None


def test_malformed_world_files(tmp_path):
    good = simplex_world(2, seed=0, shape=(6, 6))
    arrays = dict(format=np.array("jwarp.world"), version=np.array(1), sdf=good.sdf,
                  limits=good.limits, voxel_size=np.array(good.voxel_size))

    def write(name, **change):
        a = {**arrays, **change}
        a = {k: v for k, v in a.items() if v is not None}
        np.savez(tmp_path / name, **a)
        return tmp_path / name

    (tmp_path / "junk.npz").write_bytes(b"not a zip file at all")
    cases = {
        tmp_path / "junk.npz": "not a readable",
        tmp_path / "missing.npz": "does not exist",
        write("nofmt.npz", format=None): "format",
        write("other.npz", format=np.array("something")): "format",
        write("ver.npz", version=np.array(7)): "version",
        write("nosdf.npz", sdf=None): "sdf",
        write("lim.npz", limits=np.zeros(3)): "limits",
        write("limfit.npz", limits=good.limits + 1.0 * np.array([[0, 1], [0, 0]])): "limits",
        write("nan.npz", sdf=np.full((6, 6), np.nan)): "NaN",
        write("vox.npz", voxel_size=np.array(-1.0)): "voxel_size",
        write("int.npz", sdf=np.zeros((6, 6), np.int64)): "sdf",
        write("meta.npz", meta=np.array("{not json")): "meta",
        write("occ.npz", occupancy=np.zeros((5, 5), bool)): "occupancy",
    }
    for path, msg in cases.items():
        with pytest.raises(ValueError, match=msg):
            load_world(path)
    with pytest.raises(ValueError, match="folder"):
        save_world(good, tmp_path / "nope" / "w.npz")


def test_world_validation():
    sdf = np.zeros((4, 5))
    with pytest.raises(ValueError, match="limits"):
        World(sdf, np.zeros((3, 2)), 0.1)
    with pytest.raises(ValueError, match="limits"):
        World(sdf, np.array([[0, 0.3], [0, 0.5]]), 0.1)  # y: 5 cells of 0.1 end at 0.4
    with pytest.raises(ValueError, match="voxel_size"):
        World(sdf, np.array([[0, 0.3], [0, 0.4]]), 0.0)
    with pytest.raises(ValueError, match="sdf"):
        World(np.zeros(5), np.zeros((1, 2)), 0.1)
    with pytest.raises(TypeError, match="occupancy"):
        World(sdf, np.array([[0, 0.3], [0, 0.4]]), 0.1, np.zeros((4, 5)))
    with pytest.raises(ValueError, match="limits"):  # anisotropic grid
        world_from_occupancy(np.zeros((4, 5), bool), np.array([[0, 0.3], [0, 0.3]]))


def test_parse_world_spec(tmp_path, device):
    w = parse_world_spec("simplex:seed=3,threshold=0.5,dim=2,cells=20")
    assert w.dim == 2 and w.shape == (20, 20) and w.meta["seed"] == 3
    np.testing.assert_array_equal(w.sdf, simplex_world(2, seed=3, shape=(20, 20), threshold=0.5).sdf)
    w.save(tmp_path / "a.npz")
    np.testing.assert_array_equal(parse_world_spec(str(tmp_path / "a.npz")).sdf, w.sdf)
    assert parse_world_spec(w) is w
    r = parse_world_spec("simplex:seed=1,cells=24", robot=jwarp.robot("planar4"), device=device)  # its reach: FK
    assert r.dim == 2 and max(r.shape) == 24
    assert np.all(r.limits[:, 0] < -0.9) and np.all(r.limits[:, 1] > 0.9)  # covers the reach
    with pytest.raises(ValueError, match="unknown key 'colour'"):
        parse_world_spec("simplex:colour=3")
    with pytest.raises(ValueError, match="bad value for 'seed'"):
        parse_world_spec("simplex:seed=x")
    with pytest.raises(ValueError, match="not key=value"):
        parse_world_spec("simplex:seed")
    with pytest.raises(ValueError, match="needs a robot"):
        parse_world_spec("simplex:feasible=200")
    with pytest.raises(ValueError, match="world"):
        parse_world_spec("blocks:seed=1")
    with pytest.raises(ValueError, match="2D world"):
        parse_world_spec(w, robot=jwarp.robot("justin19"))
    with pytest.raises(ValueError, match="3D world"):
        parse_world_spec("simplex:dim=3,cells=8", robot=jwarp.robot("planar4"))
    # the shelf scene by name
    from jwarp.world.scenes import shelf_world
    np.testing.assert_array_equal(parse_world_spec("shelf", robot=jwarp.robot("justin19")).sdf,
                                  shelf_world().sdf)
    assert parse_world_spec("shelf:voxel=0.05").voxel_size == pytest.approx(0.05)
    for bad in ("shelf:cells=3", "shelf:voxel=x", "shelf:voxel=-1"):
        with pytest.raises(ValueError, match="^world"):
            parse_world_spec(bad)
    with pytest.raises(ValueError, match="3D world"):
        parse_world_spec("shelf", robot=jwarp.robot("planar4"))


# ============================================================ feasibility
def ref_feasible(model, q, world):
    """Collision-free per configuration with numpy: ref_fk, scipy interpolation for the
    world, all allowed sphere pairs for self-collision."""
    f, p, r = model.sphere_arrays()
    F = ref_fk(model, q)[:, f]
    x = np.einsum("bsij,sj->bsi", F[..., :3, :3], p) + F[..., :3, 3]
    dw = ref_lookup(world, x[..., :world.dim].reshape(-1, world.dim)).reshape(x.shape[:2]) - r
    ok = (dw > 0).all(1)
    allowed = model.allowed_collision_pairs
    a, b = np.triu_indices(len(f), 1)
    keep = allowed[f[a], f[b]]
    a, b = a[keep], b[keep]
    ds = np.linalg.norm(x[:, a] - x[:, b], axis=-1) - r[a] - r[b]
    return ok & (ds > 0).all(1)


@pytest.mark.parametrize("name", ["planar4", "justin19"])
def test_feasibility_filter_default_world(device, name):
    model = jwarp.robot(name)
    w = feasible_simplex_world(model, seed=0, device=device)
    assert w.dim == model.workspace_dim
    q = random_configurations(model, 1000, seed=w.meta["seed"])
    free = ref_feasible(model, q, w)
    assert free.sum() >= 200
    assert feasible_fraction(model, w, 1000, seed=w.meta["seed"],
                             device=device) == pytest.approx(free.mean(), abs=2e-3)
    for centre, radius in fixed_spheres(model, device=device):  # the fixed base stays free
        assert w.distance(centre, device=device) >= radius
    assert feasible_fraction(model, None, device=device) > 0.3  # self-collision alone


def test_feasibility_filter_gives_up_and_samples_linear_limits(device):
    model = jwarp.robot("justin19")
    q = random_configurations(model, 500, seed=1)
    s = q[:, 1] + q[:, 2]
    assert np.all((s >= 0) & (s <= np.deg2rad(135) + 1e-12))
    assert np.all((q >= model.joint_limits[:, 0]) & (q <= model.joint_limits[:, 1]))
    with pytest.raises(ValueError, match="no simplex world"):
        feasible_simplex_world("planar4", seed=0, threshold=-0.5, max_tries=2, n=100, min_feasible=50,
                               device=device)


def test_shelf_world_boards_and_back_wall(device):
    from jwarp.world import shelf_world

    w = shelf_world()
    assert w.voxel_size == pytest.approx(0.04)
    from jwarp.world.collision import sdf_query

    d = np.asarray(sdf_query(w, np.array([[0.9, 0.0, 0.55], [0.9, 0.0, 0.8], [1.12, 0.0, 0.3],
                                          [0.0, 0.0, 0.8]]), device=device))
    assert d[0] < 0 and d[2] < 0  # inside a board and the back wall
    assert d[1] > 0.15 and d[3] > 0.5  # between the boards, far in front of the shelf
    with pytest.raises(ValueError, match="voxel_size"):
        shelf_world(0.0)
