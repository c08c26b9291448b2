"""Scene files -> World: the SDF of every primitive against trimesh's exact distances to an
independent mesh of it (grid points and trilinear lookups at random points), MoveIt
planning-scene YAML (MotionBenchMaker's and ROS's spellings), the table-and-shelf example,
MoveIt joint values, and bad scenes."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import trimesh
import yaml
from scipy.spatial.transform import Rotation

import jwarp
from jwarp.world.moveit import joint_vector
from jwarp.world.scene_file import (
    TABLE_SHELF_GOAL,
    TABLE_SHELF_START,
    Scene,
    SceneOptions,
    load_scene,
    robot_frames,
    scene_from_dict,
    scene_world,
    table_shelf_scene,
)

H = 0.02  # voxel [m]
ROOT = Path(__file__).resolve().parents[2]

# a rotated pose for every primitive: position and quaternion (x, y, z, w)
ROT = Rotation.from_euler("xyz", [0.4, -0.7, 1.1])
POS = [0.1, -0.2, 0.3]


def reference_mesh(kind: str, dims: list[float]) -> trimesh.Trimesh:
    """An independent fine mesh of the primitive in its local frame (module conventions)."""
    if kind == "box":
        return trimesh.creation.box(extents=dims)
    if kind == "sphere":
        return trimesh.creation.icosphere(subdivisions=4, radius=dims[0])
    if kind == "cylinder":
        return trimesh.creation.cylinder(radius=dims[1], height=dims[0], sections=256)
    if kind == "capsule":
        return trimesh.creation.capsule(height=dims[0], radius=dims[1], count=[64, 64])
    if kind == "cone":
        m = trimesh.creation.cone(radius=dims[1], height=dims[0], sections=256)
        m.apply_translation([0, 0, -0.5 * dims[0]])  # bounding box centred on the origin
        return m
    raise AssertionError(kind)


#: type -> (jwarp object keys, dims in Shape order)
PRIMS = {
    "box": ({"size": [0.3, 0.16, 0.1]}, [0.3, 0.16, 0.1]),
    "sphere": ({"radius": 0.12}, [0.12]),
    "cylinder": ({"radius": 0.08, "length": 0.3}, [0.3, 0.08]),
    "capsule": ({"radius": 0.06, "length": 0.25}, [0.25, 0.06]),
    "cone": ({"radius": 0.1, "length": 0.25}, [0.25, 0.1]),
}
#: the reference meshes' own error (chords of the tessellation) [m], well below half a voxel
MESH_TOL = 1e-3


def one_object_scene(obj: dict) -> Scene:
    return scene_from_dict({"format": "jwarp.scene", "objects": [obj]})


def reference_distance(mesh: trimesh.Trimesh, points: np.ndarray) -> np.ndarray:
    return -trimesh.proximity.signed_distance(mesh, points)  # trimesh: positive inside


def sample_grid_and_random(world, scene, rng, n: int = 600):
    """n grid cell centres (half of them within 2 voxels of the surface), n random points
    in the grid and n random points within 2 voxels of the surface."""
    centres = world.cell_centres().reshape(-1, 3)
    sdf = world.sdf.reshape(-1)
    near = np.flatnonzero(np.abs(sdf) < 2 * world.voxel_size)
    idx = np.concatenate([rng.choice(near, n // 2, replace=False),
                          rng.choice(len(sdf), n // 2, replace=False)])
    lo, hi = world.limits[:, 0], world.limits[:, 1]
    rand = lo + rng.random((40 * n, 3)) * (hi - lo)
    band = rand[np.abs(scene.distance(rand)) < 2 * world.voxel_size][:n]
    return idx, centres[idx], rand[:n], band


#: the trilinear lookup of a sampled exact SDF: within half a voxel near the surface
#: (|d| < 2 voxels) except at apexes (the cone's tip), everywhere within the bound of a
#: 1-Lipschitz field, sqrt(3)/2 voxel (reached at points: the cone's tip, a sphere's
#: centre). A convex solid's SDF is convex, so the lookup never underestimates it.
LIPSCHITZ = math.sqrt(3) / 2


@pytest.mark.parametrize("kind", list(PRIMS))
@pytest.mark.parametrize("rotated", [False, True])
def test_primitive_sdf_matches_exact_distance(kind, rotated):
    keys, dims = PRIMS[kind]
    q = ROT.as_quat().tolist() if rotated else [0, 0, 0, 1]
    scene = one_object_scene({"id": "thing", "type": kind, **keys,
                              "pose": {"position": POS, "quaternion": q}})
    world = scene_world(scene, SceneOptions(voxel_size=H, pad=0.06))
    mesh = reference_mesh(kind, dims)
    T = np.eye(4)
    T[:3, :3] = Rotation.from_quat(q).as_matrix()
    T[:3, 3] = POS
    mesh.apply_transform(T)
    # the grid covers the shape's bounding box padded by 0.06 m
    assert np.all(world.limits[:, 0] <= mesh.bounds[0] - 0.06 + 1e-9)
    assert np.all(world.limits[:, 1] >= mesh.bounds[1] + 0.06 - H)
    rng = np.random.default_rng(len(kind) + 10 * rotated)
    idx, centres, rand, band = sample_grid_and_random(world, scene, rng)
    ref_c = reference_distance(mesh, centres)
    err_c = np.abs(world.sdf.reshape(-1)[idx] - ref_c)
    assert err_c.max() <= MESH_TOL, (kind, err_c.max())          # exact at the cell centres
    assert np.abs(scene.distance(centres) - ref_c).max() <= MESH_TOL
    for pts, bound in ((rand, LIPSCHITZ), (band, 0.5)):           # the kernels' trilinear lookup
        if kind == "cone" and bound == 0.5:
            tip = T[:3, :3] @ [0, 0, 0.5 * dims[0]] + T[:3, 3]
            pts = pts[np.linalg.norm(pts - tip, axis=1) > 2 * H]
        err = world.distance(pts) - reference_distance(mesh, pts)
        assert np.abs(err).max() <= bound * H + MESH_TOL, (kind, bound, np.abs(err).max() / H)
        assert err.min() >= -MESH_TOL, (kind, err.min())          # convex: never under
    assert world.occupancy.any() and not world.occupancy.all()


def test_mesh_object_sdf_matches_trimesh(tmp_path):
    """A non-convex closed mesh (a torus) from a file, rotated and scaled."""
    torus = trimesh.creation.torus(major_radius=0.15, minor_radius=0.05,
                                   major_sections=64, minor_sections=32)
    torus.export(tmp_path / "torus.stl")
    (tmp_path / "scene.json").write_text(json.dumps({"objects": [
        {"id": "ring", "type": "mesh", "file": "torus.stl", "scale": 1.2,
         "pose": {"position": POS, "rpy": [0.3, 0.5, -0.2]}}]}))
    scene = load_scene(tmp_path / "scene.json")
    world = scene_world(scene, SceneOptions(voxel_size=H, pad=0.06))
    ref = torus.copy()
    ref.apply_scale(1.2)
    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler("xyz", [0.3, 0.5, -0.2]).as_matrix()  # URDF rpy
    T[:3, 3] = POS
    ref.apply_transform(T)
    rng = np.random.default_rng(3)
    idx, centres, rand, band = sample_grid_and_random(world, scene, rng, n=400)
    # the grid: Warp's BVH queries in float32; the reference: trimesh in float64
    assert np.abs(world.sdf.reshape(-1)[idx] - reference_distance(ref, centres)).max() < 1e-5
    assert np.abs(world.distance(band) - reference_distance(ref, band)).max() <= 0.5 * H
    assert np.abs(world.distance(rand) - reference_distance(ref, rand)).max() <= LIPSCHITZ * H
    assert world.sdf.reshape(-1)[np.argmin(np.linalg.norm(
        world.cell_centres().reshape(-1, 3) - POS, axis=1))] > 0  # the hole is free


def test_union_of_shapes_and_grid_options():
    scene = scene_from_dict({"objects": [
        {"id": "a", "type": "box", "size": [0.2, 0.2, 0.2], "pose": {"position": [0, 0, 0]}},
        {"id": "b", "type": "sphere", "radius": 0.1, "pose": {"position": [0.5, 0, 0]}}],
        "grid": {"voxel": 0.05, "pad": 0.1}})
    world = scene_world(scene)
    assert world.voxel_size == 0.05 and world.meta["objects"] == ["a", "b"]
    np.testing.assert_allclose(world.limits[:, 0], [-0.2, -0.2, -0.2])
    assert np.all(world.limits[:, 1] >= [0.7 - 1e-9, 0.2 - 1e-9, 0.2 - 1e-9])
    p = np.array([[0.25, 0.0, 0.0], [0.1, 0.1, 0.1], [0.0, 0.0, 0.0]])
    np.testing.assert_allclose(scene.distance(p), [0.15, 0.0, -0.1], atol=1e-12)
    # options override the file; explicit limits
    w2 = scene_world(scene, SceneOptions(voxel_size=0.1, limits=[[-1, 1], [-1, 1], [-1, 1]]))
    assert w2.shape == (21, 21, 21) and w2.voxel_size == 0.1
    c = w2.cell_centres().reshape(-1, 3)
    np.testing.assert_allclose(w2.sdf.reshape(-1), scene.distance(c), atol=1e-12)
    assert scene_world(scene, SceneOptions(dtype=np.float32)).sdf.dtype == np.float32
    # an empty scene needs limits; then it is free everywhere
    empty = scene_from_dict({"objects": []})
    with pytest.raises(ValueError, match="has no objects"):
        scene_world(empty)
    assert (scene_world(empty, SceneOptions(limits=[[0, 1]] * 3, voxel_size=0.5)).sdf > 1).all()
    for bad, match in ((SceneOptions(voxel_size=0), "voxel_size"),
                       (SceneOptions(voxel_size=float("nan")), "voxel_size"),
                       (SceneOptions(pad=-1), "pad"),
                       (SceneOptions(limits=[[0, 1], [1, 0], [0, 1]]), "limits")):
        with pytest.raises(ValueError, match=match):
            scene_world(scene, bad)


def test_quaternion_and_rpy_agree():
    r = Rotation.from_euler("xyz", [0.2, -0.4, 0.9])  # extrinsic x, y, z = URDF rpy
    a = one_object_scene({"id": "a", "type": "box", "size": [1, 2, 3],
                          "pose": {"position": [1, 2, 3], "quaternion": r.as_quat().tolist()}})
    b = one_object_scene({"id": "a", "type": "box", "size": [1, 2, 3],
                          "pose": {"position": [1, 2, 3], "rpy": [0.2, -0.4, 0.9]}})
    np.testing.assert_allclose(a.shapes[0].pose, b.shapes[0].pose, atol=1e-12)
    np.testing.assert_allclose(a.shapes[0].pose[:3, :3], r.as_matrix(), atol=1e-12)


# ------------------------------------------------------------------ MoveIt YAML
#: a bookshelf as MotionBenchMaker (robowflex) writes it: string types, list positions,
#: quaternions [x, y, z, w], frame panda_link0 defined by fixed_frame_transforms
BOOKSHELF_MBM = """
fixed_frame_transforms:
  - child_frame_id: panda_link0
    header: {frame_id: world}
    transform: {translation: [0, 0, 0], rotation: [0, 0, 0, 1]}
name: bookshelf
robot_model_name: panda
robot_state:
  joint_state:
    name: [panda_joint1, panda_joint2]
    position: [0.1, -0.2]
world:
  collision_objects:
    - id: Shelf
      header: {frame_id: panda_link0}
      primitives:
        - type: box
          dimensions: [0.3, 0.8, 0.02]
        - type: box
          dimensions: [0.3, 0.8, 0.02]
        - type: box
          dimensions: [0.3, 0.02, 0.6]
      primitive_poses:
        - position: [0.7, 0.0, 0.3]
          orientation: [0, 0, 0, 1]
        - position: [0.7, 0.0, 0.6]
          orientation: [0, 0, 0, 1]
        - position: [0.7, 0.41, 0.3]
          orientation: [0, 0, 0, 1]
    - id: Can1
      header: {frame_id: panda_link0}
      primitives:
        - type: cylinder
          dimensions: [0.12, 0.03]
      primitive_poses:
        - position: [0.65, 0.1, 0.37]
          orientation: [0, 0, 0.7071068, 0.7071068]
"""

#: the same as ROS writes messages: type codes, x/y/z(/w) mappings, an object pose
BOOKSHELF_ROS = """
world:
  collision_objects:
    - id: Shelf
      header: {frame_id: world}
      pose: {position: {x: 0.7, y: 0.0, z: 0.0}, orientation: {x: 0, y: 0, z: 0, w: 1}}
      operation: 0
      primitives:
        - {type: 1, dimensions: [0.3, 0.8, 0.02]}
        - {type: 1, dimensions: [0.3, 0.8, 0.02]}
        - {type: 1, dimensions: [0.3, 0.02, 0.6]}
      primitive_poses:
        - {position: {x: 0, y: 0.0, z: 0.3}, orientation: {x: 0, y: 0, z: 0, w: 1}}
        - {position: {x: 0, y: 0.0, z: 0.6}, orientation: {x: 0, y: 0, z: 0, w: 1}}
        - {position: {x: 0, y: 0.41, z: 0.3}, orientation: {x: 0, y: 0, z: 0, w: 1}}
    - id: Can1
      header: {frame_id: world}
      primitives: [{type: 3, dimensions: [0.12, 0.03]}]
      primitive_poses:
        - {position: {x: 0.65, y: 0.1, z: 0.37}, orientation: {x: 0, y: 0, z: 0.7071068, w: 0.7071068}}
goal_constraints:
  - joint_constraints:
      - {joint_name: panda_joint1, position: 0.5, tolerance_above: 0.01, tolerance_below: 0.01, weight: 1}
"""


def test_moveit_yaml_boxes_and_cylinders(tmp_path):
    (tmp_path / "mbm.yaml").write_text(BOOKSHELF_MBM)
    (tmp_path / "ros.yaml").write_text(BOOKSHELF_ROS)
    a, b = load_scene(tmp_path / "mbm.yaml"), load_scene(tmp_path / "ros.yaml")
    assert a.format == b.format == "moveit"
    assert a.object_ids == b.object_ids == ["Shelf", "Can1"]
    assert [s.kind for s in a.shapes] == ["box", "box", "box", "cylinder"]
    for s, t in zip(a.shapes, b.shapes):
        assert s.kind == t.kind
        np.testing.assert_allclose(s.dims, t.dims)
        np.testing.assert_allclose(s.pose, t.pose, atol=1e-7)
    assert a.start == {"panda_joint1": 0.1, "panda_joint2": -0.2} and a.goal is None
    assert b.goal == {"panda_joint1": 0.5} and b.start is None
    world = scene_world(a, SceneOptions(voxel_size=0.01))
    # inside the lower board: -1 cm at its mid plane; the can: its axis is z, radius 3 cm
    d = world.distance(np.array([[0.7, 0.0, 0.3], [0.65, 0.1, 0.37], [0.65, 0.18, 0.37],
                                 [0.7, -0.2, 0.45]]))
    np.testing.assert_allclose(d, [-0.01, -0.03, 0.05, 0.15 - 0.01], atol=0.005)


def test_table_shelf_example_file_is_the_generators():
    path = ROOT / "examples" / "scenes" / "table_shelf.yaml"
    from_file = load_scene(path)
    gen = scene_from_dict(table_shelf_scene(robot_state=TABLE_SHELF_START, goal=TABLE_SHELF_GOAL))
    assert from_file.object_ids == gen.object_ids == ["table", "can", "box_on_table", "shelf",
                                                      "box_in_shelf"]
    assert len(from_file.shapes) == len(gen.shapes) == 14
    for s, t in zip(from_file.shapes, gen.shapes):
        assert s.kind == t.kind
        np.testing.assert_allclose(s.dims, t.dims, atol=1e-12)
        np.testing.assert_allclose(s.pose, t.pose, atol=1e-12)
    assert from_file.start == TABLE_SHELF_START and from_file.goal == TABLE_SHELF_GOAL
    # sized for a Panda at the origin: table top at z = 0.40 m in front, shelf boards at
    # x 0.5..0.8 m, the base (|x|, |y| < 0.15 m, z < 0.3 m) free with room to spare
    np.testing.assert_allclose(gen.distance(np.array([[0.55, 0.40, 0.45]])), [0.05], atol=1e-12)
    for z in (0.2, 0.5, 0.8):
        assert gen.distance(np.array([[0.65, -0.45, z]]))[0] == pytest.approx(-0.01)
    base = np.stack(np.meshgrid(*[np.linspace(-0.15, 0.15, 7)] * 2, np.linspace(0, 0.3, 7),
                                indexing="ij"), -1).reshape(-1, 3)
    assert gen.distance(base).min() > 0.05
    world = scene_world(gen)
    assert world.meta["format"] == "moveit" and world.occupancy.sum() > 0


def test_moveit_joint_values_to_robot_order():
    m = jwarp.robot("arm7")
    vals = {f"right_{i}": 0.1 * i for i in range(7, 0, -1)}  # any order
    np.testing.assert_allclose(joint_vector(m, vals, "start"), 0.1 * np.arange(1, 8))
    with pytest.raises(ValueError, match=r"start: unknown joint\(s\) 'panda_joint1', 'x'"):
        joint_vector(m, {**vals, "panda_joint1": 0.0, "x": 1.0}, "start")
    with pytest.raises(ValueError, match=r"no value for joint\(s\) 'right_3'"):
        joint_vector(m, {k: v for k, v in vals.items() if k != "right_3"}, "start")
    q = joint_vector(m, {"right_2": 0.5}, "goal", fallback=np.full(7, -1.0))
    np.testing.assert_allclose(q, [-1, 0.5, -1, -1, -1, -1, -1])


def test_robot_frames_are_the_fixed_ones():
    m = jwarp.robot("arm7")
    f = robot_frames(m)
    assert set(f) == {"base", "right_base"}  # right_1 on is moved by joints
    np.testing.assert_allclose(f["base"], np.eye(4))


# ------------------------------------------------------------------ bad scenes
def moveit_object(**over):
    obj = {"id": "Can1", "header": {"frame_id": "world"},
           "primitives": [{"type": "cylinder", "dimensions": [0.12, 0.03]}],
           "primitive_poses": [{"position": [0.6, 0.1, 0.4], "orientation": [0, 0, 0, 1]}]}
    obj.update(over)
    return {"world": {"collision_objects": [obj]}}


@pytest.mark.parametrize("data, match", [
    (moveit_object(primitives=[{"type": "torus", "dimensions": [1, 2]}]),
     "object 'Can1': primitive 0: unknown primitive type 'torus'"),
    (moveit_object(primitives=[{"type": 7, "dimensions": [1, 2]}]),
     "object 'Can1': primitive 0: unknown primitive type 7"),
    (moveit_object(primitives=[{"type": "box", "dimensions": [0.1, 0.2]}]),
     "object 'Can1': a box needs 3 dimensions, got 2"),
    (moveit_object(primitives=[{"type": "sphere", "dimensions": [-0.1]}]),
     "object 'Can1': sphere dimensions must be finite and > 0"),
    (moveit_object(primitive_poses=[{"position": [0.6, float("nan"), 0.4],
                                     "orientation": [0, 0, 0, 1]}]),
     "object 'Can1': primitive 0 pose position: contains NaN"),
    (moveit_object(primitive_poses=[{"position": [0.6, 0.1, 0.4],
                                     "orientation": [0, 0, 0, float("nan")]}]),
     "object 'Can1': primitive 0 pose orientation: contains NaN"),
    (moveit_object(primitive_poses=[]), r"object 'Can1': 1 primitives but 0 primitive_poses "
                                        r"\(missing pose\)"),
    (moveit_object(header={"frame_id": "table_link"}),
     "object 'Can1': unknown frame_id 'table_link'; known frames: world"),
    (moveit_object(meshes=[{"resource": "no/such.stl"}], mesh_poses=[{"position": [0, 0, 0]}]),
     "object 'Can1': mesh 0: mesh file '.*no/such.stl' does not exist"),
    (moveit_object(primitive_poses=[{"position": [0, 0, 0], "orientation": [0, 0, 0, 0]}]),
     "object 'Can1': primitive 0 pose orientation: .*not unit length"),
    (moveit_object(planes=[{"coef": [0, 0, 1, 0]}]), "object 'Can1': planes"),
    (moveit_object(operation="remove"), "object 'Can1': operation 'remove'"),
    ({"world": {"collision_objects": [{"primitives": []}]}}, r"collision_objects\[0\]: missing 'id'"),
])
def test_bad_moveit_scenes(data, match, tmp_path):
    with pytest.raises(ValueError, match=match):
        scene_from_dict(data, base_dir=tmp_path)


def jwarp_object(**over):
    obj = {"id": "ball", "type": "sphere", "radius": 0.1, "pose": {"position": [0, 0, 0.5]}}
    obj.update(over)
    return {"objects": [{k: v for k, v in obj.items() if v is not None}]}


@pytest.mark.parametrize("data, match", [
    (jwarp_object(type="blob"), "object 'ball': unknown type 'blob'"),
    (jwarp_object(type="box", radius=None, size=[1, 2]), "object 'ball': a box needs 3 dimensions"),
    (jwarp_object(pose={"position": [0, math.nan, 0]}), "object 'ball': pose position: contains NaN"),
    (jwarp_object(pose={"position": [0, 0, 0], "rpy": [0, math.inf, 0]}),
     "object 'ball': pose rpy: contains NaN or inf"),
    (jwarp_object(pose=None), "object 'ball': missing pose"),
    (jwarp_object(frame="camera"), "object 'ball': unknown frame 'camera'"),
    (jwarp_object(type="mesh", radius=None, file="gone.obj"),
     "object 'ball': mesh file '.*gone.obj' does not exist"),
    (jwarp_object(type="cylinder"), "object 'ball': a cylinder needs length"),
    (jwarp_object(colour="red"), r"object 'ball': unknown key\(s\) \['colour'\]"),
    ({"objects": [{"id": "a", "type": "sphere", "radius": 1, "pose": {"position": [0, 0, 0]}}] * 2},
     "object 'a': id given twice"),
    ({"stuff": 1}, "neither a jwarp scene"),
])
def test_bad_jwarp_scenes(data, match, tmp_path):
    with pytest.raises(ValueError, match=match):
        scene_from_dict(data, base_dir=tmp_path)


def test_bad_files(tmp_path):
    with pytest.raises(ValueError, match="does not exist"):
        load_scene(tmp_path / "none.yaml")
    (tmp_path / "bad.yaml").write_text("objects: [\n")
    with pytest.raises(ValueError, match="not valid YAML"):
        load_scene(tmp_path / "bad.yaml")
    (tmp_path / "bad.json").write_text("{")
    with pytest.raises(ValueError, match="not valid JSON"):
        load_scene(tmp_path / "bad.json")
    open_mesh = trimesh.creation.box().slice_plane([0, 0, 0], [0, 0, 1])  # no lid: open
    open_mesh.export(tmp_path / "open.stl")
    # an open mesh loads (the exact world decides inside by the winding number) ...
    cup = scene_from_dict({"objects": [{"id": "cup", "type": "mesh", "file": "open.stl",
                                        "pose": {"position": [0, 0, 0]}}]}, base_dir=tmp_path)
    from jwarp.world import exact_world
    d = exact_world(cup).shapes.distance([[0.0, 0.0, 0.25], [0.0, 0.0, 2.0]])
    assert d[0] < 0 < d[1]
    # ... but a grid of it needs it closed
    with pytest.raises(ValueError, match="object 'cup': mesh: not watertight"):
        scene_world(cup, SceneOptions(voxel_size=0.1))
    (tmp_path / "s.yaml").write_text(yaml.safe_dump(moveit_object(
        primitives=[{"type": "cone", "dimensions": [0.1]}])))
    with pytest.raises(ValueError, match=r"s.yaml: object 'Can1': a cone needs 2 dimensions"):
        load_scene(tmp_path / "s.yaml")


def test_keys_given_twice_and_nan_mesh_vertices_are_errors(tmp_path):
    """Reliability round 4, item 4: a second top-level ``objects:`` dropped the first list
    (a plan through the lost wall was "feasible"), a key given twice in an object took the
    last value, and an STL with a NaN vertex loaded with its faces dropped."""
    wall = ("objects:\n  - id: wall\n    type: box\n    size: [0.1, 1, 1]\n"
            "    pose: {position: [0.5, 0, 0.5]}\n")
    ball = ("objects:\n  - id: ball\n    type: sphere\n    radius: 0.1\n"
            "    pose: {position: [0, 0, 2]}\n")
    (tmp_path / "two.yaml").write_text(wall + ball)
    with pytest.raises(ValueError, match=r"two.yaml: key 'objects' is given twice in one "
                                         r"mapping \(lines 1 and 6\)"):
        load_scene(tmp_path / "two.yaml")
    (tmp_path / "twice.yaml").write_text(wall.replace("size: [0.1, 1, 1]\n",
                                                      "size: [0.1, 1, 1]\n    size: [0.01, 0.01, 0.01]\n"))
    with pytest.raises(ValueError, match=r"twice.yaml: key 'size' is given twice .*lines 4 and 5"):
        load_scene(tmp_path / "twice.yaml")
    (tmp_path / "twice.json").write_text('{"objects": [], "objects": []}')
    with pytest.raises(ValueError, match=r"twice.json: key 'objects' is given twice"):
        load_scene(tmp_path / "twice.json")
    # MoveIt scenes go through the same reader
    (tmp_path / "m.yaml").write_text("name: a\nname: b\nworld: {collision_objects: []}\n")
    with pytest.raises(ValueError, match=r"m.yaml: key 'name' is given twice"):
        load_scene(tmp_path / "m.yaml")
    (tmp_path / "one.yaml").write_text(wall)
    assert [s.object_id for s in load_scene(tmp_path / "one.yaml").shapes] == ["wall"]
    # a NaN vertex in an STL file: an error naming the file, no face dropped
    box = trimesh.creation.box()
    v = box.vertices.copy()
    v[0, 0] = np.nan
    trimesh.Trimesh(v, box.faces, process=False).export(tmp_path / "nan.stl")
    (tmp_path / "mesh.yaml").write_text("objects:\n  - id: m\n    type: mesh\n"
                                        "    file: nan.stl\n    pose: {position: [0, 0, 0]}\n")
    with pytest.raises(ValueError, match=r"object 'm': .*nan.stl' has \d+ vertices that are "
                                         r"NaN or inf"):
        load_scene(tmp_path / "mesh.yaml")


def test_mimic_joint_names_are_accepted_and_ignored():
    """justin19's torso_4 frame follows -(torso_tilt_1 + torso_tilt_2) (a coupled, mimic
    joint): a MoveIt state listing it maps to the 19 joints; a fixed frame's name is not a
    joint."""
    m = jwarp.robot("justin19")
    vals = {n: 0.01 * i for i, n in enumerate(m.joint_names)}
    q = joint_vector(m, {**vals, "torso_4": 0.3}, "start")
    np.testing.assert_allclose(q, 0.01 * np.arange(19))
    with pytest.raises(ValueError, match=r"unknown joint\(s\) 'torso_base'"):
        joint_vector(m, {**vals, "torso_base": 0.0}, "start")


def test_messages_name_the_culprit(tmp_path):
    """Reliability round 4, item 9: a folder or /dev/zero as a mesh was "does not exist";
    ``scale: 1.0e6`` (text to YAML) and box dims of text or booleans were taken or refused
    without the reason; a frame_id of a moving link was only "unknown"."""
    import os

    from jwarp.world import World
    mesh = {"resource": str(tmp_path)}
    with pytest.raises(ValueError, match=r"mesh file '.*' is a folder, not a file"):
        scene_from_dict(moveit_object(meshes=[mesh], mesh_poses=[{"position": [0, 0, 0]}]),
                        base_dir=tmp_path)
    if os.path.exists("/dev/zero"):
        with pytest.raises(ValueError, match=r"mesh file '/dev/zero' is a device, not a "
                                             r"regular file"):
            scene_from_dict(jwarp_object(type="mesh", radius=None, file="/dev/zero"),
                            base_dir=tmp_path)
    trimesh.creation.box().export(tmp_path / "box.stl")
    (tmp_path / "s.yaml").write_text(
        "world:\n  collision_objects:\n    - id: m\n      header: {frame_id: world}\n"
        "      meshes: [{resource: box.stl, scale: 1.0e6}]\n"
        "      mesh_poses: [{position: [0, 0, 0], orientation: [0, 0, 0, 1]}]\n")
    with pytest.raises(ValueError, match=r"scale: '1.0e6' is text, not a number .*1.0e\+6"):
        load_scene(tmp_path / "s.yaml")
    for size, match in ((["0.1", 0.1, 0.1], r"size: '0.1' is text, not a number"),
                        ([True, 0.1, 0.1], r"size: expected numbers, got True")):
        with pytest.raises(ValueError, match=match):
            scene_from_dict(jwarp_object(type="box", radius=None, size=size), base_dir=tmp_path)
        with pytest.raises(ValueError, match="object 'b': box dimensions must be numbers"):
            World.of_shapes().add("b", "box", size)
    robot = jwarp.robot("arm7")
    frames = robot_frames(robot)
    moving = frames.moving[2]
    with pytest.raises(ValueError, match=f"frame_id '{moving}' is a link of the robot that "
                                         f"moves with its joints"):
        scene_from_dict(moveit_object(header={"frame_id": moving}), frames=frames)
    with pytest.raises(ValueError, match=f"frame '{moving}' is a link of the robot that moves"):
        scene_from_dict(jwarp_object(frame=moving), frames=frames)
    with pytest.raises(ValueError, match="unknown frame_id 'nowhere'; known frames"):
        scene_from_dict(moveit_object(header={"frame_id": "nowhere"}), frames=frames)


def test_meshes_outside_the_scene_folder_warn_once_per_file(tmp_path, monkeypatch, capsys):
    """Reliability round 4, item 10: a mesh named with ``../``, an absolute path or
    ``file://`` was read without a word. One warning per file outside the scene's folder;
    JWARP_ALLOWED_ROOTS lists folders whose files need none."""
    import warnings

    from jwarp.utils.roots import ROOTS_ENV, OutsideFolderWarning

    lib = tmp_path / "lib"
    lib.mkdir()
    trimesh.creation.box().export(lib / "box.stl")
    trimesh.creation.box().export(lib / "other.stl")
    scenes = tmp_path / "scenes"
    scenes.mkdir()
    trimesh.creation.box().export(scenes / "own.stl")
    objs = [{"id": f"m{k}", "type": "mesh", "file": f, "pose": {"position": [k, 0, 0]}}
            for k, f in enumerate(["../lib/box.stl", str(lib / "box.stl"),
                                   f"file://{lib / 'box.stl'}", "own.stl", "../lib/other.stl"])]
    (scenes / "s.yaml").write_text(yaml.safe_dump({"objects": objs}))
    monkeypatch.delenv(ROOTS_ENV, raising=False)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        scene = load_scene(scenes / "s.yaml")
    assert len(scene.shapes) == 5                # read anyway
    out = [str(w.message) for w in caught if issubclass(w.category, OutsideFolderWarning)]
    # box.stl named three ways: one warning; other.stl: one
    assert len(out) == 2 and all(f"is outside {scenes.resolve()}" in m for m in out), out
    assert "object 'm0'" in out[0] and "other.stl" in out[1]
    monkeypatch.setenv(ROOTS_ENV, str(lib))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        load_scene(scenes / "s.yaml")
    assert not [w for w in caught if issubclass(w.category, OutsideFolderWarning)]
    # the CLI prints it as one line
    from jwarp.cli.common import plugin_warnings_one_line
    monkeypatch.delenv(ROOTS_ENV)
    plugin_warnings_one_line()
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        load_scene(scenes / "s.yaml")
    err = capsys.readouterr().err
    assert err.count("jwarp: warning: object 'm0': mesh file") == 1
