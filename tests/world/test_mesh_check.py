"""The mesh certificate (jwarp.world.mesh_check) against the independent verifier: the
Panda's URDF meshes placed by pinocchio, distances by coal (tests/verifier.py)."""

import os
import sys

import numpy as np
import pytest

sys.path.insert(0, os.path.dirname(os.path.dirname(__file__)))

pytest.importorskip("pinocchio")
pytest.importorskip("coal")

from panda_graze import coarse_panda, grasp_q, graze_box  # noqa: E402
from verifier import PathVerifier, checked_link_pairs  # noqa: E402

from jwarp.world.collision import is_collision_free  # noqa: E402
from jwarp.world.feasibility import random_configurations  # noqa: E402
from jwarp.world.mesh_check import MeshCheck, mesh_check, world_pieces  # noqa: E402
from jwarp.world.primitives import Shape, pose_matrix, rpy_matrix  # noqa: E402
from jwarp.world.scene_file import Scene, exact_world  # noqa: E402


@pytest.fixture(scope="module")
def panda(tmp_path_factory):
    """The Panda with a coarse contained fit (79 spheres reaching up to 7 cm past the
    meshes: many configurations the spheres refuse are free for the meshes)."""
    return coarse_panda(tmp_path_factory)


def _scene(rng):
    shapes = [Shape("box", np.array([0.6, 0.8, 0.04]), pose_matrix([0.5, 0.0, 0.2]), "table"),
              Shape("cylinder", np.array([0.3, 0.05]), pose_matrix([0.4, 0.3, 0.5]), "can"),
              Shape("sphere", np.array([0.08]), pose_matrix([0.3, -0.3, 0.6]), "ball"),
              Shape("capsule", np.array([0.3, 0.04]),
                    pose_matrix([0.0, 0.45, 0.5], rpy_matrix([1.2, 0.0, 0.3])), "pole"),
              Shape("cone", np.array([0.2, 0.1]), pose_matrix([-0.3, -0.3, 0.4]), "cone"),
              Shape("box", np.array([0.1, 0.2, 0.3]),
                    pose_matrix(rng.uniform(-0.5, 0.5, 3) + [0, 0, 0.5],
                                rpy_matrix(rng.uniform(-1, 1, 3))), "crate")]
    return Scene(shapes=shapes, source="test_mesh_check")


def _verifier(path, model, scene):
    v = PathVerifier(path, None, scene.shapes)
    v2 = PathVerifier(path, None, scene.shapes, self_pairs=checked_link_pairs(model, v))
    return v2


def test_world_pieces_contain_their_objects():
    rng = np.random.default_rng(0)
    scene = _scene(rng)
    world = exact_world(scene)
    pieces = world_pieces(world.shapes)
    from scipy.spatial import Delaunay

    for shape, (_kind, verts, rad, _) in zip(scene.shapes, pieces):
        # points of the exact object (rejection sampling in its bounding box)
        lo, hi = verts.min(0) - rad, verts.max(0) + rad
        pts = rng.uniform(lo, hi, (20000, 3))
        from jwarp.world.primitives import signed_distance

        inside = pts[signed_distance(shape, pts) < 0]
        assert len(inside) > 100
        if rad == 0:
            assert (Delaunay(verts).find_simplex(inside, tol=1e-12) >= 0).all(), shape.object_id
        else:  # a point or a segment grown by rad
            a, b = verts[0], verts[-1]
            ab = b - a
            t = np.clip(((inside - a) @ ab) / max(ab @ ab, 1e-30), 0, 1)
            d = np.linalg.norm(inside - (a + t[:, None] * ab), axis=1)
            assert (d <= rad + 1e-12).all(), shape.object_id


def test_certified_configurations_are_free_for_the_meshes(panda):
    """No configuration the certificate calls free collides for coal (world and self);
    most the meshes keep free are certified, including many the spheres refuse."""
    path, model = panda
    rng = np.random.default_rng(1)
    scene = _scene(rng)
    world = exact_world(scene)
    v = _verifier(path, model, scene)
    q = random_configurations(model, 300, seed=2)
    mc = MeshCheck(model, world, "cpu")
    cert = mc.free(q)
    ref = v.check_configurations(q)
    assert not (cert & ~ref).any(), np.nonzero(cert & ~ref)[0]
    assert cert.sum() >= 0.8 * ref.sum(), (cert.sum(), ref.sum())
    spheres = is_collision_free(model, q, world, meshes=False, device="cpu")
    gained = cert & ~spheres
    assert gained.sum() >= 5                       # the certificate matters here
    both = is_collision_free(model, q, world, device="cpu")
    assert np.array_equal(both, spheres | cert)


def test_certified_paths_are_free_for_the_meshes(panda):
    path, model = panda
    rng = np.random.default_rng(3)
    scene = _scene(rng)
    world = exact_world(scene)
    v = _verifier(path, model, scene)
    q = random_configurations(model, 400, seed=4)
    mc = mesh_check(model, world, "cpu")
    free = q[mc.free(q, 0.0)]
    P = min(40, len(free) // 2)
    paths = np.stack([free[:P], free[P:2 * P]], axis=1)            # (P, 2, n)
    paths = np.concatenate([paths[:, :1], paths.mean(1, keepdims=True), paths[:, 1:]], 1)
    ok = mc.paths_free(paths)
    for k in np.nonzero(ok)[0]:
        verdict = v.check_path(paths[k], max_step_deg=0.5)
        assert verdict.ok, (k, str(verdict))
    assert ok.sum() >= 3


def test_a_pose_millimetres_from_an_object_is_not_refused_and_plans(panda):
    """A hand 3 mm from a box: the contained spheres touch it, the meshes do not. The pose
    is accepted (is_collision_free), a plan from it is feasible and the verifier finds
    every configuration of it free for the URDF meshes."""
    import jwarp
    from jwarp.solvers.planning import PlanOptions

    path, model = panda
    q0 = grasp_q(model)
    scene = Scene(shapes=[graze_box(model, q0, 0.003)], source="graze")
    world = exact_world(scene)
    assert not is_collision_free(model, q0[None], world, meshes=False, device="cpu")[0]
    assert is_collision_free(model, q0[None], world, device="cpu")[0]
    q1 = q0.copy()
    q1[0] -= 1.0
    res = jwarp.plan(model, world, q0, q1, options=PlanOptions(time_limit=20.0),
                     device="cpu")
    assert bool(res.feasible[0]), res.reasons
    v = _verifier(path, model, scene)
    verdict = v.check_path(res.path[0])
    assert verdict.ok, str(verdict)


def test_ik_accepts_a_grasp_the_meshes_clear(panda):
    """IK of the hand pose 3 mm from a box: the spheres touch the box at every solution,
    the meshes do not; the solver's mesh rescue returns a feasible solution, verified by
    coal (meshes free), and a robot without pieces finds none there."""
    from jwarp.kinematics import fk
    from jwarp.solvers.ik import IKOptions, IKSolver

    path, model = panda
    q0 = grasp_q(model)
    scene = Scene(shapes=[graze_box(model, q0, 0.003)], source="graze")
    world = exact_world(scene)
    hand = model.frame_index("panda_hand")
    target = np.asarray(fk(model, q0[None], dtype=np.float64))[0, hand]
    opts = IKOptions(n_starts=4, iterations=60)
    seeds = np.stack([q0] * 4)
    res = IKSolver(model, hand, 1, world=world, options=opts, device="cpu").solve(
        target, seeds=seeds)
    assert bool(np.asarray(res.feasible).reshape(-1)[0])
    q = np.asarray(res.q).reshape(-1, model.n_dof)
    assert not is_collision_free(model, q, world, meshes=False, device="cpu")[0]
    v = _verifier(path, model, scene)
    assert v.check_configurations(q)[0]
    bare = model.copy(collision_pieces=None)
    res0 = IKSolver(bare, hand, 1, world=world, options=opts, device="cpu").solve(
        target, seeds=seeds)
    q0b = np.asarray(res0.q).reshape(-1, model.n_dof)
    assert not bool(np.asarray(res0.feasible).reshape(-1)[0]) or is_collision_free(
        bare, q0b, world, device="cpu")[0]


def test_bad_input_names_the_argument(panda):
    path, model = panda
    world = exact_world(_scene(np.random.default_rng(0)))
    mc = MeshCheck(model, world, "cpu")
    with pytest.raises(ValueError, match="q:"):
        mc.free(np.zeros((2, model.n_dof + 1)))
    with pytest.raises(ValueError, match="q:"):
        mc.free(np.full((1, model.n_dof), np.nan))
    with pytest.raises(TypeError, match="q"):
        mc.free("home")
    with pytest.raises(ValueError, match="paths:"):
        mc.paths_free(np.zeros((3, model.n_dof)))
    with pytest.raises(ValueError, match="collision_pieces"):
        MeshCheck(model.copy(collision_pieces=None), world, "cpu")
    assert mesh_check(model.copy(collision_pieces=None), world, "cpu") is None


def test_motion_check_meshes_per_path(panda):
    """MotionCheck.check(meshes=) with one bool per path: a short motion leaving a pose 3 mm
    from a box (the spheres touch it, the meshes do not) is proven where its row allows
    the certificate and refused where it does not; a wrong length names the argument."""
    from jwarp.world.motion import MotionCheck

    path, model = panda
    q0 = grasp_q(model)
    world = exact_world(Scene(shapes=[graze_box(model, q0, 0.003)], source="graze"))
    q1 = q0.copy()
    q1[0] -= 0.3   # away from the box (it lies along +x)
    paths = np.stack([np.stack([q0, q1])] * 2)
    chk = MotionCheck(model, world, device="cpu")
    assert not chk.check(paths, meshes=False).ok.any()
    assert chk.check(paths, meshes=True).ok.all()
    assert list(chk.check(paths, meshes=np.array([True, False])).ok) == [True, False]
    assert list(chk.check(paths, meshes=np.array([False, True])).ok) == [False, True]
    with pytest.raises(ValueError, match="meshes"):
        chk.check(paths, meshes=np.array([True, False, True]))


def test_world_pieces_of_a_batch_are_each_worlds_own():
    """The pieces are built per kind with array operations (piece_table): a batch of
    worlds gives each world's own pieces, bit for bit, as placed by their poses."""
    from jwarp.world import World

    rng = np.random.default_rng(3)
    worlds = [exact_world(_scene(rng)) for _ in range(3)]
    batch = World.batch(worlds)
    got = world_pieces(batch.shapes)
    want = [(k, v, r, w) for w, world in enumerate(worlds)
            for (k, v, r, _) in world_pieces(world.shapes)]
    assert len(got) == len(want)
    for (k, v, r, g), (k2, v2, r2, g2) in zip(got, want):
        assert (k, r, g) == (k2, r2, g2)
        assert np.array_equal(v, v2)
    # and as placed: a box's corners are its pose applied to its half extents
    box = worlds[1].shapes.ids.index("crate")
    T = worlds[1].shapes.pose("crate")
    h = np.array([0.1, 0.2, 0.3]) / 2
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]) * h
    k = len(world_pieces(worlds[0].shapes)) + box
    np.testing.assert_allclose(got[k][1], corners @ T[:3, :3].T + T[:3, 3], atol=1e-15)
