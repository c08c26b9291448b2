"""Scene input as tools write it (MoveIt frames without headers, full robot states with
gripper joints the model lacks or fixes), bad scenes that fail with a ValueError naming
the object and the problem, and grids whose cell count would overflow."""

from __future__ import annotations

import numpy as np
import pytest

from jwarp.world.scene_file import Scene, SceneOptions, load_scene, scene_world
from jwarp.world.sdf import MAX_GRID_CELLS, grid_geometry

TABLE_SHELF = "examples/scenes/table_shelf.yaml"


# ------------------------------------------------------------------ grid sizes
@pytest.mark.parametrize("voxel", [1e-300, 1e-320, 1e-4])
def test_grid_geometry_refuses_too_many_cells(voxel):
    with pytest.raises(ValueError, match=r"voxel_size: .* needs a grid of .* cells, more than "
                                         r"the 2\*\*31"):
        grid_geometry(3, limits=[[0, 1], [0, 1], [0, 1]], voxel_size=voxel)


def test_grid_geometry_refuses_a_huge_shape():
    with pytest.raises(ValueError, match=r"shape needs a grid of 70000 x 70000 x 1000"):
        grid_geometry(3, shape=(70000, 70000, 1000), voxel_size=0.1)
    s, _, _ = grid_geometry(3, limits=[[0, 1], [0, 1], [0, 1]], voxel_size=0.01)
    assert s == (101, 101, 101)


@pytest.mark.parametrize("voxel", [0.0, -0.01, float("nan"), float("inf")])
def test_grid_geometry_refuses_bad_voxels(voxel):
    with pytest.raises(ValueError, match="voxel_size: expected a positive number"):
        grid_geometry(3, limits=[[0, 1], [0, 1], [0, 1]], voxel_size=voxel)


@pytest.fixture(scope="module")
def table_shelf() -> Scene:
    from pathlib import Path

    return load_scene(Path(__file__).resolve().parents[2] / TABLE_SHELF)


@pytest.mark.parametrize("voxel", [1e-300, 1e-320, 5e-4])
def test_scene_world_refuses_overflowing_voxels(table_shelf, voxel):
    """It used to wrap the int64 cell count around to a 2 x 2 x 2 grid."""
    with pytest.raises(ValueError, match=r"voxel_size: .* needs a grid of .* cells, more than "
                                         r"the 2\*\*31"):
        scene_world(table_shelf, SceneOptions(voxel_size=voxel))


@pytest.mark.parametrize("voxel", [0.0, -1.0, float("nan"), float("inf")])
def test_scene_world_refuses_bad_voxels(table_shelf, voxel):
    with pytest.raises(ValueError, match="voxel_size: expected a positive number"):
        scene_world(table_shelf, SceneOptions(voxel_size=voxel))


def test_scene_world_refuses_grids_beyond_memory(table_shelf, monkeypatch):
    import jwarp.utils.memory

    monkeypatch.setattr(jwarp.utils.memory, "available_memory", lambda: 10 ** 6)
    with pytest.raises(ValueError, match=r"voxel_size: 0.02 m .* needs a grid of 51 x 95 x 66 "
                                         r"= 3.198e\+05 cells, about 10.2 MB of memory, more "
                                         r"than the 1.0 MB available"):
        scene_world(table_shelf, SceneOptions(voxel_size=0.02))
    assert MAX_GRID_CELLS > 51 * 95 * 66


# ------------------------------------------------------------------ MoveIt input as tools write it
def panda_urdf(fingers: str) -> str:
    """A two-joint 'panda' whose finger joints are prismatic (finger 2 mimics finger 1;
    axes +-y as in the Panda's URDF), fixed, or absent."""
    def joint(name, parent, child, jtype="revolute", extra="", axis="0 0 1"):
        lim = '<limit lower="-2" upper="2" effort="1" velocity="1"/>' if jtype == "revolute" \
            else extra
        return (f'<joint name="{name}" type="{jtype}"><parent link="{parent}"/>'
                f'<child link="{child}"/><origin xyz="0 0 0.1" rpy="0 0 0"/>'
                f'<axis xyz="{axis}"/>{lim}</joint>')

    links = ["panda_link0", "panda_link1", "panda_link2", "panda_hand"]
    parts = [joint("panda_joint1", "panda_link0", "panda_link1"),
             joint("panda_joint2", "panda_link1", "panda_link2"),
             joint("panda_hand_joint", "panda_link2", "panda_hand", "fixed")]
    if fingers != "absent":
        links += ["panda_leftfinger", "panda_rightfinger"]
        lim = '<limit lower="0" upper="0.04" effort="1" velocity="1"/>'
        kind = "prismatic" if fingers == "prismatic" else "fixed"
        parts += [joint("panda_finger_joint1", "panda_hand", "panda_leftfinger", kind, lim,
                        "0 1 0"),
                  joint("panda_finger_joint2", "panda_hand", "panda_rightfinger", kind,
                        lim + ('<mimic joint="panda_finger_joint1"/>'
                               if kind == "prismatic" else ""), "0 -1 0")]
    body = "".join(f'<link name="{n}"/>' for n in links) + "".join(parts)
    return f'<?xml version="1.0"?><robot name="panda">{body}</robot>'


@pytest.fixture(scope="module")
def pandas(tmp_path_factory) -> dict:
    from jwarp.importers.robot import load_urdf

    folder = tmp_path_factory.mktemp("urdf")
    out = {}
    for fingers in ("prismatic", "fixed", "absent"):
        path = folder / f"panda_{fingers}.urdf"
        path.write_text(panda_urdf(fingers))
        out[fingers] = load_urdf(path).model
    return out


FULL_STATE = {"panda_joint1": 0.1, "panda_joint2": -0.2, "panda_finger_joint1": 0.035,
              "panda_finger_joint2": 0.035}


def write_yaml(path, data) -> str:
    import yaml

    path.write_text(yaml.safe_dump(data))
    return str(path)


def moveit_state(start: dict | None = None, goal: dict | None = None, **more) -> dict:
    data = {"world": {"collision_objects": []}, **more}
    if start is not None:
        data["robot_state"] = {"joint_state": {"name": list(start),
                                               "position": list(start.values())}}
    if goal is not None:
        data["goal_constraints"] = [{"joint_constraints": [
            {"joint_name": k, "position": v, "weight": 1.0} for k, v in goal.items()]}]
    return data


@pytest.mark.parametrize("fingers", ["fixed", "absent"])
def test_finger_joints_the_model_fixes_or_lacks_warn_once(pandas, fingers, tmp_path):
    from jwarp.world.moveit import joint_vector

    m = pandas[fingers]
    assert m.joint_names == ["panda_joint1", "panda_joint2"]
    scene = load_scene(write_yaml(tmp_path / "s.yaml", moveit_state(FULL_STATE)))
    with pytest.warns(UserWarning) as rec:
        q = joint_vector(m, scene.start, "start")
    assert len(rec) == 1
    msg = str(rec[0].message)
    assert "start: ignoring joint(s) 'panda_finger_joint1' = 0.035, 'panda_finger_joint2' = " \
           "0.035" in msg and "robot 'panda'" in msg
    np.testing.assert_allclose(q, [0.1, -0.2])


def test_finger_values_out_of_range_or_nan_only_warn(pandas, tmp_path):
    from jwarp.world.moveit import joint_vector

    state = {**FULL_STATE, "panda_finger_joint1": 0.3, "panda_finger_joint2": float("nan")}
    scene = load_scene(write_yaml(tmp_path / "s.yaml", moveit_state(state, goal=state)))
    for what, values in (("start", scene.start), ("goal", scene.goal)):
        with pytest.warns(UserWarning, match=rf"{what}: ignoring joint\(s\) 'panda_finger_joint1'"
                                             r" = 0.3, 'panda_finger_joint2' = nan"):
            q = joint_vector(pandas["fixed"], values, what, fallback=np.zeros(2))
        np.testing.assert_allclose(q, [0.1, -0.2])


def test_goal_constraints_on_missing_fingers_warn(pandas, tmp_path):
    from jwarp.world.moveit import joint_vector

    goal = {"panda_joint2": 0.5, "panda_finger_joint1": 0.04}
    scene = load_scene(write_yaml(tmp_path / "g.yaml", moveit_state(goal=goal)))
    with pytest.warns(UserWarning, match=r"goal: ignoring joint\(s\) 'panda_finger_joint1'"):
        q = joint_vector(pandas["absent"], scene.goal, "goal", fallback=np.array([1.0, 1.0]))
    np.testing.assert_allclose(q, [1.0, 0.5])


def test_movable_fingers_and_mimics_are_used_without_warning(pandas, recwarn):
    from jwarp.world.moveit import joint_vector

    m = pandas["prismatic"]
    assert m.joint_names == ["panda_joint1", "panda_joint2", "panda_finger_joint1"]
    np.testing.assert_allclose(joint_vector(m, FULL_STATE, "start"), [0.1, -0.2, 0.035])
    assert not [w for w in recwarn if issubclass(w.category, UserWarning)]


def test_missing_movable_joints_and_foreign_names_stay_errors(pandas):
    from jwarp.world.moveit import joint_vector

    m = pandas["fixed"]
    with pytest.raises(ValueError, match=r"start: no value for joint\(s\) 'panda_joint2' of "
                                         r"robot 'panda'"), pytest.warns(UserWarning):
        joint_vector(m, {"panda_joint1": 0.0, "panda_finger_joint1": 0.0}, "start")
    with pytest.raises(ValueError, match=r"unknown joint\(s\) 'right_1', 'x'"):
        joint_vector(m, {"panda_joint1": 0.0, "panda_joint2": 0.0, "right_1": 0.0, "x": 1.0},
                     "start")
    with pytest.raises(ValueError, match=r"unknown joint\(s\) 'panda_hand'"):  # a link
        joint_vector(m, {"panda_joint1": 0.0, "panda_joint2": 0.0, "panda_hand": 0.0}, "start")
    with pytest.raises(ValueError, match=r"start: joint\(s\) 'panda_joint2' = nan of robot "
                                         r"'panda' not finite"):
        joint_vector(m, {"panda_joint1": 0.0, "panda_joint2": float("nan")}, "start")


def test_gripper_joints_of_another_naming_warn():
    """A UR arm's MoveIt state lists its Robotiq gripper's joints (other first words)."""
    import jwarp
    from jwarp.world.moveit import ignored_joint_names

    m = jwarp.robot("arm7")
    assert ignored_joint_names(m, ["finger_joint", "left_inner_knuckle_joint", "right_9",
                                   "panda_joint1", "right_base", "x"]) == \
        ["finger_joint", "left_inner_knuckle_joint", "right_9"]


def box_in(frame: str) -> dict:
    return {"id": "box", "header": {"frame_id": frame},
            "primitives": [{"type": "box", "dimensions": [0.1, 0.1, 0.1]}],
            "primitive_poses": [{"position": [0, 0, 0], "orientation": [0, 0, 0, 1]}]}


@pytest.mark.parametrize("header", [None, {}, {"frame_id": ""}, {"frame_id": "world"},
                                    {"frame_id": "/world"}])
def test_fixed_frame_transforms_without_header_are_in_the_world(header, tmp_path):
    t = {"child_frame_id": "table", "transform": {"translation": [1, 2, 3],
                                                   "rotation": [0, 0, 0, 1]}}
    if header is not None:
        t["header"] = header
    data = {"fixed_frame_transforms": [t], "world": {"collision_objects": [box_in("table")]}}
    scene = load_scene(write_yaml(tmp_path / "s.yaml", data))
    np.testing.assert_allclose(scene.shapes[0].pose[:3, 3], [1, 2, 3])


def test_fixed_frame_transforms_with_robot_frames(pandas, tmp_path):
    from jwarp.world.scene_file import robot_frames

    frames = robot_frames(pandas["fixed"])
    assert "panda_link0" in frames and "panda_hand" not in frames
    ident = {"translation": [0, 0, 0], "rotation": [0, 0, 0, 1]}
    data = {"fixed_frame_transforms": [
        {"header": {"frame_id": "world"}, "child_frame_id": "panda_link0", "transform": ident},
        {"header": {"frame_id": "panda_link0"}, "child_frame_id": "panda_link0", "transform": ident},
        # only the child known: the entry defines its header's frame
        {"header": {"frame_id": "odom"}, "child_frame_id": "base",
         "transform": {"translation": [0.5, 0, 0], "rotation": [0, 0, 0, 1]}}],
        "world": {"collision_objects": [box_in("odom")]}}
    scene = load_scene(write_yaml(tmp_path / "s.yaml", data), frames=frames)
    np.testing.assert_allclose(scene.shapes[0].pose[:3, 3], [-0.5, 0, 0])


# ------------------------------------------------------------------ bad scenes
def moveit_object(**over) -> dict:
    obj = {"id": "Can1", "header": {"frame_id": "world"},
           "primitives": [{"type": "cylinder", "dimensions": [0.12, 0.03]}],
           "primitive_poses": [{"position": [0.6, 0.1, 0.4], "orientation": [0, 0, 0, 1]}]}
    obj.update(over)
    return {"world": {"collision_objects": [obj]}}


def prim(kind, dims, position=(0, 0, 0)) -> dict:
    return {"primitives": [{"type": kind, "dimensions": dims}],
            "primitive_poses": [{"position": list(position), "orientation": [0, 0, 0, 1]}]}


INF, NAN = float("inf"), float("nan")


@pytest.mark.parametrize("over, match", [
    ({"pose": {"position": [NAN, 0, 0]}}, r"object 'Can1': pose position: contains NaN"),
    ({"pose": {"position": [0, 0, 0], "orientation": [0, INF, 0, 1]}},
     r"object 'Can1': pose orientation: contains NaN or inf"),
    (prim("box", [0.1, 0.1, 0.1], (0, INF, 0)), r"object 'Can1': primitive 0 pose position"),
    (prim("box", [0.1, 0.0, 0.1]), r"object 'Can1': box dimensions must be finite and > 0"),
    (prim("sphere", [-0.1]), r"object 'Can1': sphere dimensions must be finite and > 0"),
    (prim("cylinder", [NAN, 0.1]), r"object 'Can1': primitive 0 \(cylinder\) dimensions: "
                                   r"contains NaN"),
    (prim("box", [2e4, 1, 1]), r"object 'Can1': box dimensions: \[20000.0, 1.0, 1.0\] \[m\] "
                               r"exceed 10000 m"),
    (prim("sphere", [1e300]), r"object 'Can1': sphere dimensions: .* exceed 10000 m"),
    (prim("sphere", [0.1], (0, 0, -1.5e4)), r"object 'Can1': position: .* exceed 10000 m"),
    ({"pose": {"position": [1e6, 0, 0]}}, r"object 'Can1': position: .* exceed 10000 m"),
    (prim("torus", [1, 2]), r"object 'Can1': primitive 0: unknown primitive type 'torus'"),
    (prim(None, [1]), r"object 'Can1': primitive 0: unknown primitive type None"),
    (prim("5", [1]), r"object 'Can1': primitive 0: unknown primitive type '5'"),
    ({"meshes": [{"vertices": [], "triangles": []}], "mesh_poses": [{"position": [0, 0, 0]}]},
     r"object 'Can1': mesh 0: a closed mesh needs >= 4 vertices and some triangles"),
])
def test_bad_moveit_objects_name_the_object(over, match):
    from jwarp.world.scene_file import scene_from_dict

    with pytest.raises(ValueError, match=match):
        scene_from_dict(moveit_object(**over))


def test_primitive_type_codes_as_strings():
    from jwarp.world.scene_file import scene_from_dict

    scene = scene_from_dict(moveit_object(**prim("2", [0.1])))
    assert [s.kind for s in scene.shapes] == ["sphere"]


def jwarp_object(**over) -> dict:
    obj = {"id": "ball", "type": "sphere", "radius": 0.1, "pose": {"position": [0, 0, 0.5]}}
    obj.update(over)
    return {"objects": [{k: v for k, v in obj.items() if v is not None}]}


@pytest.mark.parametrize("data, match", [
    (jwarp_object(radius=0), r"object 'ball': sphere dimensions must be finite and > 0"),
    (jwarp_object(radius=-1), r"object 'ball': sphere dimensions must be finite and > 0"),
    (jwarp_object(radius=INF), r"object 'ball': radius: contains NaN or inf"),
    (jwarp_object(radius=5e4), r"object 'ball': sphere dimensions: \[50000.0\] \[m\] exceed"),
    (jwarp_object(type="box", radius=None, size=[1, 1, 1e5]), r"object 'ball': box dimensions"),
    (jwarp_object(pose={"position": [0, 0, 2e4]}), r"object 'ball': position: .* exceed"),
    ({**jwarp_object(frame="far"), "frames": {"far": {"position": [9e3, 0, 0]}},
      "objects": [{"id": "ball", "type": "sphere", "radius": 0.1, "frame": "far",
                   "pose": {"position": [2e3, 0, 0]}}]}, r"object 'ball': position: .* exceed"),
    (jwarp_object(pose={"position": [0, 0, 0], "quaternion": [NAN, 0, 0, 1]}),
     r"object 'ball': pose quaternion .*: contains NaN"),
    (jwarp_object(type="torus"), r"object 'ball': unknown type 'torus'"),
])
def test_bad_jwarp_objects_name_the_object(data, match):
    from jwarp.world.scene_file import scene_from_dict

    with pytest.raises(ValueError, match=match):
        scene_from_dict(data)


def mesh_object(path, **spec) -> dict:
    return moveit_object(primitives=[], primitive_poses=[], meshes=[{"resource": str(path), **spec}],
                         mesh_poses=[{"position": [0, 0, 0], "orientation": [0, 0, 0, 1]}])


def test_empty_and_enormous_meshes(tmp_path):
    import trimesh

    from jwarp.world.primitives import Shape
    from jwarp.world.scene_file import scene_from_dict

    (tmp_path / "empty.stl").write_bytes(b"")
    (tmp_path / "points.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\n")
    for name in ("empty.stl", "points.obj"):
        with pytest.raises(ValueError, match=rf"object 'Can1': mesh 0: .*{name}"):
            scene_from_dict(mesh_object(tmp_path / name))
    trimesh.creation.box().export(tmp_path / "box.stl")
    assert len(scene_from_dict(mesh_object(tmp_path / "box.stl")).shapes) == 1
    with pytest.raises(ValueError, match=r"object 'Can1': mesh vertices reach 50000 m, beyond "
                                         r"10000 m"):
        scene_from_dict(mesh_object(tmp_path / "box.stl", scale=1e5))
    with pytest.raises(ValueError, match=r"object 'Can1': mesh 0 scale: expected numbers > 0"):
        scene_from_dict(mesh_object(tmp_path / "box.stl", scale=[1, -1, 1]))
    with pytest.raises(ValueError, match=r"object 'lid': mesh is empty \(0 vertices, 0 faces\)"):
        Shape("mesh", [], np.eye(4), "lid", trimesh.Trimesh())


def test_file_encodings(tmp_path):
    text = "objects:\n  - {id: tisch\u00e9, type: sphere, radius: 1, pose: {position: [0, 0, 0]}}\n"
    (tmp_path / "latin1.yaml").write_bytes(text.encode("latin-1"))
    with pytest.raises(ValueError, match=r"scene .*latin1.yaml: not UTF-8 text \(byte 0xe9 at "
                                         r"line 2, column 15\)"):
        load_scene(tmp_path / "latin1.yaml")
    for enc in ("utf-8", "utf-8-sig", "utf-16"):
        (tmp_path / f"{enc}.yaml").write_bytes(text.encode(enc))
        assert load_scene(tmp_path / f"{enc}.yaml").object_ids == ["tisch\u00e9"]
    (tmp_path / "empty.yaml").write_text("")
    with pytest.raises(ValueError, match=r"scene .*empty.yaml: the file is empty"):
        load_scene(tmp_path / "empty.yaml")
    (tmp_path / "bad.json").write_bytes(b'{"objects": [\xff]}')
    with pytest.raises(ValueError, match=r"scene .*bad.json: not UTF-8 text \(byte 0xff"):
        load_scene(tmp_path / "bad.json")


@pytest.mark.parametrize("axis", ["0 0 1", "1 0 0"])
def test_mimic_joint_names_are_accepted_whatever_their_axis(tmp_path, axis, recwarn):
    """A MoveIt state naming a URDF mimic joint: accepted silently whether the importer
    named its coupled frame after the child link (z axis) or "<joint>_axis" (other axes);
    a fixed joint after it still warns."""
    from jwarp.importers.robot import load_urdf
    from jwarp.world.moveit import joint_vector

    lim = '<limit lower="-1" upper="1" effort="1" velocity="1"/>'
    (tmp_path / "m.urdf").write_text(
        '<robot name="rr"><link name="base"/><link name="l1"/><link name="l2"/>'
        '<link name="tip"/>'
        '<joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>'
        f'<origin xyz="0 0 0.1"/><axis xyz="0 0 1"/>{lim}</joint>'
        '<joint name="jm" type="revolute"><parent link="l1"/><child link="l2"/>'
        f'<origin xyz="0 0 0.1"/><axis xyz="{axis}"/>{lim}<mimic joint="j1"/></joint>'
        '<joint name="tip_joint" type="fixed"><parent link="l2"/><child link="tip"/>'
        '<origin xyz="0 0 0.05"/></joint></robot>')
    m = load_urdf(tmp_path / "m.urdf").model
    assert m.joint_names == ["j1"] and "jm" in m.frame_aliases
    np.testing.assert_allclose(joint_vector(m, {"j1": 0.2, "jm": 0.2}, "start"), [0.2])
    assert not [w for w in recwarn if issubclass(w.category, UserWarning)]
    with pytest.warns(UserWarning, match="ignoring joint.*'tip_joint'"):
        joint_vector(m, {"j1": 0.2, "tip_joint": 0.0}, "start")
