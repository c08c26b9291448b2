"""Basis point sets (jwarp.learn.bps): the points are a valid close packing inside the robot's
reach, and the encoding equals jwarp's own SDF lookup (issue 14, item 1)."""

import json
import math

import numpy as np
import pytest
import torch
from scipy.spatial import cKDTree

import jwarp
from jwarp.learn.bps import (
    BasisPointSet,
    basis_points,
    bps_encode,
    hcp_density,
    hcp_points,
    robot_reach_ball,
)
from jwarp.world.feasibility import feasible_simplex_world
from jwarp.world.scenes import shelf_world
from jwarp.world.sdf import World, sdf_query
from jwarp.world.simplex import simplex_world


def min_distance(p: np.ndarray) -> float:
    d, _ = cKDTree(p).query(p, k=2)
    return float(d[:, 1].min())


# ------------------------------------------------------------------- packing
@pytest.mark.parametrize("dim", [2, 3])
def test_hcp_is_a_close_packing(dim):
    s, r = 0.1, 1.0
    c = np.array([0.3, -0.2, 0.5][:dim])
    p = hcp_points(dim, s, c, r)
    assert p.shape[1] == dim and p.dtype == np.float64
    assert abs(min_distance(p) - s) < 1e-9
    assert np.all(np.linalg.norm(p - c, axis=1) <= r * (1 + 1e-12))
    assert np.any(np.all(np.abs(p - c) < 1e-12, axis=1))  # a lattice point on the centre
    # every point has the kissing number of neighbours at distance s (6 / 12) deep inside
    tree = cKDTree(p)
    inner = p[np.linalg.norm(p - c, axis=1) < r - 2 * s]
    counts = [len(n) - 1 for n in tree.query_ball_point(inner, s * (1 + 1e-9))]
    assert set(counts) == {6 if dim == 2 else 12}


@pytest.mark.parametrize("dim", [2, 3])
def test_hcp_count_matches_the_packing_density(dim):
    s, r = 0.05, 1.0
    p = hcp_points(dim, s, np.zeros(dim), r)
    vol = math.pi * r ** 2 if dim == 2 else 4 / 3 * math.pi * r ** 3
    expect = vol * hcp_density(dim, s)
    assert abs(len(p) - expect) / expect < 0.02, (len(p), expect)
    # the density itself: hexagonal 2/(sqrt(3) s^2) = pi/(2 sqrt 3) packing fraction of discs,
    # hcp sqrt(2)/s^3 = pi/(3 sqrt 2) of spheres of diameter s
    frac = hcp_density(dim, s) * (math.pi * (s / 2) ** 2 if dim == 2 else 4 / 3 * math.pi * (s / 2) ** 3)
    assert frac == pytest.approx(math.pi / (2 * math.sqrt(3)) if dim == 2 else math.pi / (3 * math.sqrt(2)))


def test_hcp_3d_is_abab():
    s = 1.0
    p = hcp_points(3, s, np.zeros(3), 3.0)
    dz = s * math.sqrt(2 / 3)
    layer = np.round(p[:, 2] / dz).astype(int)
    assert np.allclose(p[:, 2], layer * dz)
    xy = {k: p[layer == k, :2] for k in (-2, -1, 0, 1, 2)}
    for a, b in ((0, 2), (-1, 1)):  # layers two apart coincide in x-y (A B A B)
        assert cKDTree(xy[a]).query(xy[b])[0].max() < 1e-9 or cKDTree(xy[b]).query(xy[a])[0].max() < 1e-9
    assert cKDTree(xy[0]).query(xy[1])[0].min() > 0.5  # B sits over the A triangles


def test_hcp_errors():
    with pytest.raises(ValueError, match="dim"):
        hcp_points(4, 0.1, np.zeros(4), 1.0)
    with pytest.raises(ValueError, match="spacing"):
        hcp_points(2, 0.0, np.zeros(2), 1.0)
    with pytest.raises(ValueError, match="radius"):
        hcp_points(2, 0.1, np.zeros(2), -1.0)
    with pytest.raises(ValueError, match="centre"):
        hcp_points(3, 0.1, np.zeros(2), 1.0)
    with pytest.raises(ValueError, match="centre"):
        hcp_points(2, 0.1, [np.nan, 0.0], 1.0)


# ---------------------------------------------------------------- basis points
@pytest.mark.parametrize("robot, dim", [("planar5", 2), ("justin19", 3)])
@pytest.mark.parametrize("n", [1024, 4096])
def test_basis_points_size_and_reach(robot, dim, n):
    bps = basis_points(robot, n)
    assert bps.dim == dim and bps.size == len(bps.points)
    assert bps.size == n, bps  # exactly: the outermost shell of the packing is cut
    full = hcp_points(dim, bps.spacing, bps.centre, bps.radius)
    assert n <= len(full) < 1.03 * n  # ... which is a few % of the points
    assert cKDTree(full).query(bps.points)[0].max() < 1e-12  # a subset of that packing
    centre, radius = robot_reach_ball(jwarp.robot(robot))
    assert np.allclose(bps.centre, centre) and bps.radius == pytest.approx(radius)
    assert np.all(np.linalg.norm(bps.points - bps.centre, axis=1) <= bps.radius * (1 + 1e-12))
    assert abs(min_distance(bps.points) - bps.spacing) < 1e-9
    wider = basis_points(robot, n, margin=0.1)
    assert wider.radius == pytest.approx(radius + 0.1) and wider.spacing > bps.spacing


def test_reach_ball_holds_the_reach_box():
    from jwarp.world.feasibility import robot_reach

    centre, radius = robot_reach_ball(jwarp.robot("justin19"))
    box = robot_reach("justin19")
    assert np.allclose(centre, [0.0, 0.0, 0.5884], atol=1e-3)  # the base of justin19
    # the box of the same configurations' spheres touches the ball from inside
    assert np.all(box[:, 1] - centre <= radius + 1e-9) and np.all(centre - box[:, 0] <= radius + 1e-9)


def test_basis_points_tiny():
    assert basis_points("planar5", 1).size == 1
    two = basis_points("justin19", 2)
    assert two.size == 2 and abs(min_distance(two.points) - two.spacing) < 1e-9


def test_basis_points_errors():
    with pytest.raises(TypeError, match="n_points"):
        basis_points("planar5", 10.5)
    with pytest.raises(ValueError, match="n_points"):
        basis_points("planar5", 0)
    with pytest.raises(ValueError, match="margin"):
        basis_points("planar5", 100, margin=-1.0)


def test_dict_round_trip():
    bps = basis_points("planar5", 300)
    d = json.loads(json.dumps(bps.to_dict()))
    back = BasisPointSet.from_dict(d)
    assert back == bps
    assert np.array_equal(back.points, bps.points) and back.spacing == bps.spacing
    assert np.array_equal(back.centre, bps.centre) and back.radius == bps.radius
    with pytest.raises(ValueError, match="radius"):
        BasisPointSet.from_dict({k: v for k, v in d.items() if k != "radius"})
    with pytest.raises(ValueError, match="dim"):
        BasisPointSet.from_dict({**d, "dim": 3})
    with pytest.raises(ValueError, match="points"):
        BasisPointSet.from_dict({**d, "points": []})


# -------------------------------------------------------------------- encoding
@pytest.fixture(scope="module")
def worlds_2d():
    """Three 2D worlds with three different grids: planar5's feasible simplex world, a
    coarser simplex world, and one whose grid covers only part of the reach."""
    return [feasible_simplex_world("planar5", seed=0),
            simplex_world(2, seed=3, shape=(40, 50)),
            simplex_world(2, seed=4, shape=(30, 30), limits=np.array([[-0.5, 0.3], [-0.2, 0.6]]))]


@pytest.fixture(scope="module")
def worlds_3d():
    """The shelf at two voxel sizes and a 3D simplex world (three grid shapes)."""
    return [shelf_world(), shelf_world(0.05).astype(np.float32),
            simplex_world(3, seed=1, shape=(20, 30, 25))]


def reference(worlds, points, device):
    """SDF lookups of the points in every world, on ``device`` (the CUDA test machine has
    no CPU compiler)."""
    return np.stack([sdf_query(w, points, device=device) for w in worlds])


def test_encode_equals_sdf_lookup_2d(device, worlds_2d):
    bps = basis_points("planar5", 1024)
    e = bps.encode(worlds_2d, device=device)
    assert isinstance(e, np.ndarray) and e.dtype == np.float32 and e.shape == (3, bps.size)
    ref = reference(worlds_2d, bps.points, device)
    assert np.abs(e - ref).max() < 1e-6
    assert (e < 0).any() and (e > 0).any()  # obstacles and free space among the points
    one = bps.encode(worlds_2d[1], device=device)  # a single world
    assert one.shape == (1, bps.size) and np.abs(one[0] - ref[1]).max() < 1e-6


def test_encode_equals_sdf_lookup_3d(device, worlds_3d):
    bps = basis_points("justin19", 1024)
    e = bps_encode(worlds_3d, bps, device=device)
    ref = reference(worlds_3d, bps.points, device)
    assert e.shape == (3, bps.size) and np.abs(e - ref).max() < 1e-6
    assert (e[0] < 0).any()  # some points inside the shelf's boards
    assert np.allclose(e[0], worlds_3d[0].distance(bps.points, device=device), atol=1e-6)


def test_encode_into_torch_zero_copy(device, worlds_3d):
    bps = basis_points("justin19", 512)
    dev = "cuda:0" if device.startswith("cuda") else "cpu"
    out = torch.full((3, bps.size), float("nan"), dtype=torch.float32, device=dev)
    ptr = out.data_ptr()
    r = bps.encode(worlds_3d, out=out)
    assert r is out and out.data_ptr() == ptr
    assert np.abs(out.cpu().numpy() - reference(worlds_3d, bps.points, device)).max() < 1e-6
    r = bps.encode(worlds_3d, out=out, device=device)  # the same device named: fine
    assert r is out


def test_encode_errors(worlds_2d, worlds_3d):
    bps2 = basis_points("planar5", 100)
    bps3 = basis_points("justin19", 100)
    with pytest.raises(ValueError, match="worlds"):
        bps3.encode([], device="cpu")
    with pytest.raises(ValueError, match="worlds"):  # mixed dims
        bps3.encode([worlds_3d[0], worlds_2d[0]], device="cpu")
    with pytest.raises(TypeError, match=r"worlds\[1\]"):
        bps3.encode([worlds_3d[0], "shelf"], device="cpu")
    with pytest.raises(TypeError, match="worlds"):
        bps3.encode(42, device="cpu")
    with pytest.raises(ValueError, match="points"):  # 2D points, 3D world
        bps2.encode(worlds_3d[0], device="cpu")
    with pytest.raises(ValueError, match="points"):
        bps_encode(worlds_3d[0], np.zeros((0, 3)), device="cpu")
    with pytest.raises(ValueError, match="points"):
        bps_encode(worlds_3d[0], np.array([[0.0, np.inf, 0.0]]), device="cpu")
    with pytest.raises(ValueError, match="out"):
        bps3.encode(worlds_3d, out=torch.empty(2, bps3.size), device="cpu")
    with pytest.raises(TypeError, match="out"):
        bps3.encode(worlds_3d, out=torch.empty(3, bps3.size, dtype=torch.float64), device="cpu")
    with pytest.raises(TypeError, match="out"):
        bps3.encode(worlds_3d, out=np.empty((3, bps3.size), np.float32), device="cpu")
    with pytest.raises(ValueError, match="out"):
        bps3.encode(worlds_3d, out=torch.empty(bps3.size, 3).T, device="cpu")
    with pytest.raises(ValueError, match="out|device"):
        bps3.encode(worlds_3d, out=torch.empty(3, bps3.size), device="cuda:0")
    with pytest.raises(ValueError, match="device"):
        bps3.encode(worlds_3d, device="tpu:7")
    with pytest.raises(ValueError, match="points"):
        BasisPointSet(np.array([[np.nan, 0.0]]), 0.1, np.zeros(2), 1.0)
    with pytest.raises(ValueError, match="centre"):
        BasisPointSet(np.zeros((1, 2)), 0.1, np.zeros(3), 1.0)
    assert isinstance(worlds_3d[0], World)
