"""The independent exact path checker tests/verifier.py (pinocchio + coal) on the Panda of
example-robot-data: it finds a known penetration of the hand (at a waypoint, between
waypoints, and a small object swallowed by the closed hand mesh), passes a clearly free
path, agrees with closed forms (sphere vs box) and with jwarp's shape conventions
(cylinder, capsule, cone), and its frames (links, joint-named frames, the mimic finger)
agree with jwarp's FK."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from verifier import PathVerifier, robot_spheres  # noqa: E402

import jwarp  # noqa: E402
from jwarp.importers.robot import example_robot_urdf  # noqa: E402
from jwarp.model import Sphere  # noqa: E402
from jwarp.world.primitives import Shape, pose_matrix, rpy_matrix, signed_distance  # noqa: E402

READY = np.array([0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785, 0.035])


@pytest.fixture(scope="module")
def urdf() -> str:
    try:
        return example_robot_urdf("panda_description/urdf/panda.urdf")
    except ValueError as e:
        pytest.skip(str(e))


@pytest.fixture(scope="module")
def panda(urdf):
    return jwarp.robot(urdf)


def hand_origin(urdf: str, q: np.ndarray) -> np.ndarray:
    return PathVerifier(urdf, None, []).frame_placements(q, ["panda_hand"])[0][:3, 3]


def test_joint_order_matches_jwarp(urdf, panda):
    v = PathVerifier(urdf, None, [])
    assert v.joint_names == panda.joint_names


def test_frames_agree_with_jwarp_fk(urdf, panda):
    """Every jwarp frame (links, the joint-named finger frames with R_align, the mimic
    right finger) placed by pinocchio equals jwarp's FK, and so do sphere centres."""
    rng = np.random.default_rng(3)
    lim = panda.joint_limits
    q = np.vstack([READY, rng.uniform(lim[:, 0], lim[:, 1], (3, panda.n_dof))])
    T = np.asarray(jwarp.fk(panda, q, device="cpu", dtype="float64"))
    v = PathVerifier(urdf, None, [])
    for i in range(len(q)):
        P = v.frame_placements(q[i], panda.frame_names)
        assert np.abs(P - T[i]).max() < 1e-12, panda.frame_names
    # spheres on every frame, read from a jwarp model the way benchmarks do
    model = jwarp.robot(urdf)
    centres = rng.uniform(-0.05, 0.05, (panda.n_frames, 3))
    model.spheres = [Sphere(frame=k, position=centres[k], radius=0.01) for k in range(panda.n_frames)]
    vs = PathVerifier(urdf, None, [], spheres=robot_spheres(model))
    for i in range(len(q)):
        want = np.einsum("fij,fj->fi", T[i, :, :3, :3], centres) + T[i, :, :3, 3]
        assert np.abs(vs.sphere_centres(q[i]) - want).max() < 1e-12


def test_sphere_vs_box_closed_form(urdf):
    """A sphere on the fixed base frame against a rotated box: coal's signed distance is
    the closed form (outside: Euclidean distance to the box minus the radius; inside:
    minus the distance to the nearest face minus the radius)."""
    R = rpy_matrix([0.3, -0.2, 0.7])
    size = np.array([0.4, 0.2, 0.1])
    box = Shape("box", size, pose_matrix([0.8, 0.3, 0.5], R), object_id="box")
    r = 0.03
    for local in ([0.35, 0.0, 0.0], [0.3, 0.2, 0.1], [0.0, 0.0, 0.051], [0.05, 0.02, 0.0],
                  [0.21, 0.11, 0.0]):
        local = np.array(local)
        c = R @ local + box.pose[:3, 3]
        q_ = np.abs(local) - 0.5 * size
        want = (np.linalg.norm(np.maximum(q_, 0)) + min(q_.max(), 0.0)) - r
        v = PathVerifier(urdf, None, [box], spheres=[("panda_link0", c, r)], mesh_check=False)
        got = v.check_path(READY[None])
        assert got.sphere is not None and got.sphere.object_id == "box"
        assert abs(got.min_distance - want) < 1e-9, (local, got.min_distance, want)
        assert got.ok == (want >= 0)


@pytest.mark.parametrize("kind,dims", [("cylinder", [0.3, 0.08]), ("capsule", [0.2, 0.05]),
                                       ("cone", [0.25, 0.1]), ("sphere", [0.07])])
def test_shape_conventions_match_jwarp(urdf, kind, dims):
    """The coal shape of each jwarp kind is the same solid: sphere-to-shape distances
    equal jwarp's exact signed distance of the centre minus the radius."""
    shape = Shape(kind, dims, pose_matrix([0.6, -0.2, 0.4], rpy_matrix([0.4, 0.9, -0.3])), "s")
    rng = np.random.default_rng(5)
    pts = shape.pose[:3, 3] + rng.uniform(-0.25, 0.25, (12, 3))
    r = 0.02
    want = signed_distance(shape, pts) - r
    for p, w in zip(pts, want):
        v = PathVerifier(urdf, None, [shape], spheres=[("panda_link0", p, r)], mesh_check=False)
        got = v.check_path(READY[None]).min_distance
        if w > -r:    # coal's penetration depth of a deep sphere is the EPA depth, same
            assert abs(got - w) < 2e-6, (kind, p, got, w)
        else:
            assert got < 0


def test_finds_hand_pushed_into_box(urdf):
    """The hand lowered into a box: the waypoint inside is a violation on the hand or a
    finger against the box; the same box 10 cm lower is clear."""
    h = hand_origin(urdf, READY)
    down = READY.copy()
    down[3] -= 0.3   # joint 4 folds: the hand goes down
    hd = hand_origin(urdf, down)
    assert hd[2] < h[2] - 0.05
    top = hd[2] - 0.02   # the box top 2 cm below the lowered hand's flange
    box = Shape("box", [0.3, 0.3, 0.2], pose_matrix([hd[0], hd[1], top - 0.1]), object_id="block")
    v = PathVerifier(urdf, None, [box])
    got = v.check_path(np.array([READY, down]))
    assert not got.ok
    assert got.first_violation.object_id == "block"
    assert got.first_violation.link in ("panda_hand", "panda_leftfinger", "panda_rightfinger")
    assert got.closest.interval == 0 and got.closest.fraction == 1.0
    assert got.min_distance < -0.05    # the fingers reach ~10 cm below the flange
    assert not got.first_violation.distance >= 0
    low = Shape("box", [0.3, 0.3, 0.2], pose_matrix([hd[0], hd[1], top - 0.25]), object_id="block")
    ok = PathVerifier(urdf, None, [low]).check_path(np.array([READY, down]))
    assert ok.ok and ok.min_distance > 0.0


def test_finds_collision_between_waypoints(urdf):
    """Both waypoints free, the straight line between them sweeps the hand through a
    pillar: found inside the interval (at 0.5 deg steps), with the mesh and the spheres."""
    a, b = READY.copy(), READY.copy()
    a[0], b[0] = -0.8, 0.8
    h = hand_origin(urdf, READY)
    pillar = Shape("cylinder", [0.3, 0.03], pose_matrix([h[0], h[1], h[2] - 0.05]), "pillar")
    spheres = [("panda_hand", np.array([0.0, 0.0, 0.05]), 0.06)]
    v = PathVerifier(urdf, None, [pillar], spheres=spheres)
    assert v.check_path(a[None]).ok and v.check_path(b[None]).ok
    got = v.check_path(np.array([a, b]))
    assert not got.ok and got.n_samples >= 180    # 1.6 rad / 0.5 deg + 1
    assert 0.1 < got.first_violation.fraction < 0.5
    assert abs(got.closest.fraction - 0.5) < 0.1 and got.closest.object_id == "pillar"
    assert got.mesh.distance < 0 and got.sphere.distance < 0
    # a coarse check (only the waypoints) would miss it
    assert v.check_path(a[None]).ok


def test_object_inside_closed_hand_mesh(urdf):
    """A small ball wholly inside the closed hand mesh crosses no surface: the
    containment test still reports it."""
    v0 = PathVerifier(urdf, None, [])
    T = v0.frame_placements(READY, ["panda_hand"])[0]
    import trimesh

    go = [g for g in v0.geom_model.geometryObjects if g.name.startswith("panda_hand")][0]
    m = trimesh.load(go.meshPath, force="mesh")
    c_local = m.bounds.mean(0)
    assert m.contains(c_local[None])[0]
    ball = Shape("sphere", [0.004], pose_matrix(T[:3, :3] @ c_local + T[:3, 3]), "marble")
    got = PathVerifier(urdf, None, [ball]).check_path(READY[None])
    assert not got.ok and got.closest.link == "panda_hand" and got.min_distance < 0


def test_clearly_free_path(urdf, panda):
    """A table far from the arm: every sample clear by > 5 cm, and a margin above the
    smallest distance fails."""
    table = Shape("box", [0.6, 1.0, 0.04], pose_matrix([0.9, 0.0, 0.1]), "table")
    shelf = Shape("box", [0.3, 0.3, 0.3], pose_matrix([-0.6, 0.6, 0.3]), "crate")
    goal = READY.copy()
    goal[[0, 2, 5]] = [0.6, 0.3, 1.2]
    v = PathVerifier(urdf, None, [table, shelf], spheres=[("panda_hand", np.zeros(3), 0.05)])
    got = v.check_path(np.array([READY, goal]))
    assert got.ok and got.first_violation is None
    assert got.min_distance > 0.05
    assert not v.check_path(np.array([READY, goal]), margin=got.min_distance + 1e-3).ok
    assert v.check_path(np.array([READY, goal]), margin=got.min_distance - 1e-6).ok


def test_bad_input(urdf):
    v = PathVerifier(urdf, None, [])
    with pytest.raises(ValueError, match="path"):
        v.check_path(np.zeros((2, 3)))
    with pytest.raises(ValueError, match="sphere frame"):
        PathVerifier(urdf, None, [], spheres=[("no_such_link", np.zeros(3), 0.1)])


def test_self_pairs_find_link5_in_the_hand(urdf):
    """Check (c): at zeros the Panda's link5 mesh lies in the hand mesh (a known self
    collision of this URDF); at the ready pose the pair is free, and coal's distance there
    is at most the smallest distance between the two meshes' vertices (an upper bound
    computed here with numpy); a path from ready to zeros is refused between the two."""
    import trimesh

    pairs = [("panda_link5", "panda_hand"), ("panda_link5", "panda_link7")]
    v = PathVerifier(urdf, None, [], self_pairs=pairs)
    bad = v.check_path(np.zeros(8)[None])
    assert not bad.ok and bad.first_violation.check == "self"
    assert bad.self_mesh.distance < -0.01
    assert {bad.self_mesh.link, bad.self_mesh.object_id} == {"panda_link5", "panda_hand"}
    good = v.check_path(READY[None])
    assert good.ok and good.self_mesh.distance > 0.01
    # the vertex bound of the closest pair at ready
    verts = {}
    import pinocchio as pin

    pin.forwardKinematics(v.model, v.data, v.pin_q(READY))
    pin.updateGeometryPlacements(v.model, v.data, v.geom_model, v.geom_data)
    for gi, go in enumerate(v.geom_model.geometryObjects):
        link = v.model.frames[go.parentFrame].name
        if link in (good.self_mesh.link, good.self_mesh.object_id) and go.meshPath:
            tm = trimesh.load(go.meshPath, force="mesh")
            M = v.geom_data.oMg[gi].homogeneous
            verts.setdefault(link, []).append(tm.vertices @ M[:3, :3].T + M[:3, 3])
    a, b = (np.vstack(verts[k]) for k in (good.self_mesh.link, good.self_mesh.object_id))
    vertex_gap = np.sqrt(((a[:, None, :] - b[None, :, :]) ** 2).sum(-1)).min()
    assert good.self_mesh.distance <= vertex_gap + 1e-9
    path = v.check_path(np.stack([READY, np.zeros(8)]))
    assert not path.ok and path.first_violation.interval == 0
    assert 0.0 < path.first_violation.fraction < 1.0
    with pytest.raises(ValueError, match="self_pairs"):
        PathVerifier(urdf, None, [], self_pairs=[("panda_link5", "no_such_link")])
