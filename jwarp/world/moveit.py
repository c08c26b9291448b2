"""MoveIt planning scenes and motion-plan requests in YAML (as MoveIt, robowflex and
MotionBenchMaker write them): collision objects -> :class:`~jwarp.world.primitives.Shape`,
the robot state's joint values -> a start, goal joint constraints -> a goal.

Read (everything else is ignored: octomaps, attached objects, object colours,
``multi_dof_joint_state``, constraint tolerances and weights)::

    fixed_frame_transforms:            # optional: more frame ids (child in frame_id)
      - header: {frame_id: world}      # optional (no header or '': world)
        child_frame_id: panda_link0
        transform: {translation: [0, 0, 0], rotation: [0, 0, 0, 1]}
    robot_state:                       # or start_state (a MotionPlanRequest)
      joint_state:
        name: [panda_joint1, ...]
        position: [0.0, ...]
    world:                             # or collision_objects at the top level
      collision_objects:
        - id: table
          header: {frame_id: world}
          pose: {position: [0.5, 0, 0.2], orientation: [0, 0, 0, 1]}    # optional
          primitives:
            - type: box                # box|sphere|cylinder|cone or 1|2|3|4 (SolidPrimitive)
              dimensions: [0.6, 1.0, 0.4]
          primitive_poses:             # one per primitive, relative to pose
            - position: {x: 0, y: 0, z: 0}
              orientation: {x: 0, y: 0, z: 0, w: 1}
          meshes:                      # optional: inline shape_msgs/Mesh or a file
            - vertices: [[x, y, z], ...]      # or {x:, y:, z:}
              triangles: [[0, 1, 2], ...]     # or {vertex_indices: [...]}
            - resource: meshes/mug.stl        # relative to the YAML file (or file://)
          mesh_poses: [...]
    goal_constraints:                  # a MotionPlanRequest's goal (the first set)
      - joint_constraints:
          - {joint_name: panda_joint1, position: 0.3}
    joint_constraints: [...]           # or directly at the top level

Positions are lists ``[x, y, z]`` or mappings ``{x, y, z}``; orientations quaternions
``[x, y, z, w]`` (ROS order) or ``{x, y, z, w}``. Dimensions follow
``shape_msgs/SolidPrimitive``: BOX ``[x, y, z]``, SPHERE ``[radius]``, CYLINDER and CONE
``[height, radius]``. An object's ``operation`` may be absent, ``add`` (0) or ``append``
(2). Every error is a ValueError naming the object id (or the joint names) and the problem.
Joint values are matched to a robot by :func:`joint_vector`: joints the robot model lacks
or fixes (a gripper's fingers in a full MoveIt state) are ignored with one warning.
"""

from __future__ import annotations

import math
import re
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from jwarp.model import RobotModel, frozen_joint_values
from jwarp.world.primitives import Shape, finite_vector, pose_matrix, quaternion_matrix

__all__ = ["PRIMITIVE_TYPES", "collision_objects", "goal_joint_values", "ignored_joint_names",
           "joint_vector", "moveit_frames", "moveit_shapes", "parse_pose", "start_joint_values"]

#: shape_msgs/SolidPrimitive type codes -> shape kinds
PRIMITIVE_TYPES = {1: "box", 2: "sphere", 3: "cylinder", 4: "cone"}
_OPERATIONS = {None: True, 0: True, 2: True, "add": True, "append": True}


def parse_pose(value: Any, where: str) -> np.ndarray:
    """A (4, 4) transform from a geometry_msgs/Pose mapping (``position`` and optional
    ``orientation``, each a list or an x/y/z(/w) mapping; also ``translation``/``rotation``
    of a Transform)."""
    if not isinstance(value, dict):
        raise ValueError(f"{where}: expected a pose mapping with position and orientation, "
                         f"got {value!r}")
    pos = value.get("position", value.get("translation"))
    if pos is None:
        raise ValueError(f"{where}: missing position")
    rot = value.get("orientation", value.get("rotation"))
    p = finite_vector(_xyz(pos, "xyz"), 3, f"{where} position")
    if rot is None:
        return pose_matrix(p)
    q = finite_vector(_xyz(rot, "xyzw"), 4, f"{where} orientation")
    try:
        return pose_matrix(p, quaternion_matrix(q))
    except ValueError as e:
        raise ValueError(f"{where} orientation: {e}") from None


def _xyz(value: Any, keys: str) -> Any:
    if isinstance(value, dict):
        missing = [k for k in keys if k not in value]
        if missing:
            return [value.get(k) for k in keys]  # finite_vector names the None
        return [value[k] for k in keys]
    return value


def collision_objects(data: Any) -> list:
    """The collision object list of a planning scene mapping (``world.collision_objects``
    or top-level ``collision_objects``); [] when there is none."""
    if not isinstance(data, dict):
        raise ValueError(f"scene: expected a mapping at the top level, got {type(data).__name__}")
    world = data.get("world") or {}
    if not isinstance(world, dict):
        raise ValueError("scene: 'world' must be a mapping")
    objs = world.get("collision_objects", data.get("collision_objects")) or []
    if not isinstance(objs, list):
        raise ValueError("scene: 'collision_objects' must be a list")
    return objs


class RobotFrames(dict):
    """Frame name -> 4x4 transform in the world of the frames a scene may use, and
    ``moving``: the robot's frames that move with its joints (named in errors: a scene
    object cannot be fixed to one)."""

    def __init__(self, frames: Any = (), moving: Any = ()) -> None:
        super().__init__(frames)
        self.moving = tuple(moving) if moving else tuple(getattr(frames, "moving", ()))


def unknown_frame(frames: dict, frame: str, where: str, key: str = "frame_id") -> ValueError:
    """The error for a ``key`` naming ``frame``, which ``frames`` lacks: a robot link that
    moves with its joints is said to be one; else the known frames are listed."""
    if frame in getattr(frames, "moving", ()):
        return ValueError(f"{where}: {key} '{frame}' is a link of the robot that moves with "
                          f"its joints; a scene object must be given in a fixed frame (world, "
                          f"base, or a frame fixed to the base: {', '.join(sorted(frames))}); "
                          f"an object held by the robot: World.attach")
    return ValueError(f"{where}: unknown {key} '{frame}'; known frames: "
                      f"{', '.join(sorted(frames))}")


def moveit_frames(data: dict, frames: dict[str, np.ndarray],
                  world_frame: str = "world") -> dict[str, np.ndarray]:
    """``frames`` (name -> 4x4 in the world) plus the scene's ``fixed_frame_transforms``:
    each the pose of ``child_frame_id`` in its header's frame (no header or an empty
    ``frame_id``: ``world_frame``), which must be known or defined before; where only the
    child is known, the entry defines its header's frame instead."""
    out = RobotFrames(frames)
    entries = data.get("fixed_frame_transforms") or []
    if not isinstance(entries, list):
        raise ValueError("fixed_frame_transforms: expected a list")
    for k, t in enumerate(entries):
        where = f"fixed_frame_transforms[{k}]"
        if not isinstance(t, dict) or not str(t.get("child_frame_id") or "").strip("/ "):
            raise ValueError(f"{where}: expected a mapping with child_frame_id and transform")
        parent = _frame_id(t, where) or world_frame
        child = str(t["child_frame_id"]).strip().lstrip("/")
        T = parse_pose(t.get("transform"), f"{where} transform")
        if parent not in out and child in out:
            out[parent] = out[child] @ np.linalg.inv(T)
            continue
        if parent not in out:
            raise unknown_frame(out, parent, where)
        T = out[parent] @ T
        if child in out and not np.allclose(out[child], T, atol=1e-9):
            raise ValueError(f"{where}: frame '{child}' is already defined with another transform")
        out[child] = T
    return out


def _frame_id(obj: dict, where: str) -> str:
    header = obj.get("header") or {}
    if not isinstance(header, dict):
        raise ValueError(f"{where}: header must be a mapping")
    return str(header.get("frame_id", "") or "").strip().lstrip("/")


def moveit_shapes(data: Any, frames: dict[str, np.ndarray], base_dir: Path | None = None,
                  world_frame: str = "world") -> list[Shape]:
    """Shapes of every collision object of a planning scene mapping, in the frame
    ``world_frame`` of ``frames`` (name -> 4x4 world transform; an empty ``frame_id``
    means ``world_frame``). ``base_dir``: folder of relative mesh files."""
    shapes: list[Shape] = []
    seen: set[str] = set()
    for k, obj in enumerate(collision_objects(data)):
        if not isinstance(obj, dict):
            raise ValueError(f"collision_objects[{k}]: expected a mapping, got {obj!r}")
        if "id" not in obj or not str(obj["id"]).strip():
            raise ValueError(f"collision_objects[{k}]: missing 'id'")
        oid = str(obj["id"])
        where = f"object '{oid}'"
        if oid in seen:
            raise ValueError(f"{where}: id given twice")
        seen.add(oid)
        op = obj.get("operation")
        if isinstance(op, str):
            op = op.lower()
        if op not in _OPERATIONS:
            raise ValueError(f"{where}: operation {op!r} is not add (0) or append (2)")
        frame = _frame_id(obj, where) or world_frame
        if frame not in frames:
            raise unknown_frame(frames, frame, where)
        T = frames[frame]
        if obj.get("pose") is not None:
            T = T @ parse_pose(obj["pose"], f"{where}: pose")
        if obj.get("planes"):
            raise ValueError(f"{where}: planes (infinite half spaces) are not supported; "
                             f"use a large box")
        shapes += _primitives(obj, T, where, oid)
        shapes += _meshes(obj, T, where, oid, base_dir)
    return shapes


def _poses(obj: dict, key: str, n: int, where: str) -> list:
    poses = obj.get(key) or []
    if not isinstance(poses, list):
        raise ValueError(f"{where}: '{key}' must be a list")
    if len(poses) != n:
        what = "primitives" if key == "primitive_poses" else "meshes"
        hint = " (missing pose)" if len(poses) < n else ""
        raise ValueError(f"{where}: {n} {what} but {len(poses)} {key}{hint}")
    return poses


def _primitives(obj: dict, T: np.ndarray, where: str, oid: str) -> list[Shape]:
    prims = obj.get("primitives") or []
    if not isinstance(prims, list):
        raise ValueError(f"{where}: 'primitives' must be a list")
    poses = _poses(obj, "primitive_poses", len(prims), where)
    out = []
    for i, (prim, pose) in enumerate(zip(prims, poses)):
        w = f"{where}: primitive {i}"
        if not isinstance(prim, dict) or "type" not in prim:
            raise ValueError(f"{w}: expected a mapping with type and dimensions")
        t = prim["type"]
        kind = _primitive_kind(t)
        if kind is None:
            raise ValueError(f"{w}: unknown primitive type {t!r}; known: BOX, SPHERE, "
                             f"CYLINDER, CONE (or 1-4)")
        dims = finite_vector(prim.get("dimensions", []), None, f"{w} ({kind}) dimensions")
        Tp = T @ parse_pose(pose, f"{w} pose")
        out.append(Shape(kind, dims, Tp, object_id=oid))
    return out


def _primitive_kind(t: Any) -> str | None:
    """The shape kind of a SolidPrimitive type (a code 1-4, also as a string, or a name in
    any case); None if unknown."""
    if isinstance(t, bool):
        return None
    text = str(t).strip().lower()
    if isinstance(t, int) or text.isdigit():
        return PRIMITIVE_TYPES.get(int(text))
    return text if text in PRIMITIVE_TYPES.values() else None


def _meshes(obj: dict, T: np.ndarray, where: str, oid: str, base_dir: Path | None) -> list[Shape]:
    meshes = obj.get("meshes") or []
    if not isinstance(meshes, list):
        raise ValueError(f"{where}: 'meshes' must be a list")
    poses = _poses(obj, "mesh_poses", len(meshes), where)
    out = []
    for i, (mesh, pose) in enumerate(zip(meshes, poses)):
        w = f"{where}: mesh {i}"
        out.append(Shape("mesh", [], T @ parse_pose(pose, f"{w} pose"), object_id=oid,
                         mesh=load_mesh(mesh, w, base_dir)))
    return out


def load_mesh(spec: Any, where: str, base_dir: Path | None = None) -> Any:
    """A trimesh.Trimesh from an inline shape_msgs/Mesh mapping (``vertices``,
    ``triangles``) or a file (``resource``/``file``: a path, relative to ``base_dir``, or
    ``file://``; optional ``scale``: a number or 3). A file outside ``base_dir`` (and the
    folders of ``JWARP_ALLOWED_ROOTS``) is read with an
    :class:`~jwarp.utils.roots.OutsideFolderWarning`."""
    import trimesh

    from jwarp.importers.spheres import file_problem
    from jwarp.importers.spheres import load_mesh as load_mesh_file

    if not isinstance(spec, dict):
        raise ValueError(f"{where}: expected a mapping (vertices/triangles or resource)")
    src = spec.get("resource", spec.get("file"))
    if src is not None:
        src = str(src)
        if src.startswith("package://"):
            raise ValueError(f"{where}: cannot resolve '{src}' (package:// needs ROS); give "
                             f"a file path")
        path = Path(src.removeprefix("file://"))
        if not path.is_absolute() and base_dir is not None:
            path = base_dir / path
        why = file_problem(path)
        if why is not None:
            raise ValueError(f"{where}: mesh file '{path}' {why}")
        if base_dir is not None:  # ../, absolute, file://: said once (jwarp.utils.roots)
            from jwarp.utils.roots import warn_if_outside

            warn_if_outside(path, base_dir, f"{where}: mesh file", stacklevel=2)
        scale = None
        if "scale" in spec:
            s = spec["scale"]
            scale = finite_vector([s] * 3 if isinstance(s, (int, float)) else s, 3,
                                  f"{where} scale")
            if np.any(scale <= 0):
                raise ValueError(f"{where} scale: expected numbers > 0, got {scale.tolist()}")
        try:
            return load_mesh_file(path, scale)
        except ValueError as e:
            raise ValueError(f"{where}: {e}") from None
    verts = spec.get("vertices")
    tris = spec.get("triangles")
    if verts is None or tris is None:
        raise ValueError(f"{where}: needs 'vertices' and 'triangles', or a 'resource' file")
    v = np.array([finite_vector(_xyz(p, "xyz"), 3, f"{where} vertex {j}")
                  for j, p in enumerate(verts)]).reshape(-1, 3)
    f = []
    for j, t in enumerate(tris):
        idx = t.get("vertex_indices") if isinstance(t, dict) else t
        try:
            ids = [int(x) for x in idx]
        except (TypeError, ValueError):
            raise ValueError(f"{where}: triangle {j}: expected 3 vertex indices, got {t!r}") from None
        if len(ids) != 3 or min(ids) < 0 or max(ids) >= len(v):
            raise ValueError(f"{where}: triangle {j}: expected 3 vertex indices in "
                             f"[0, {len(v)}), got {ids}")
        f.append(ids)
    if len(v) < 4 or not f:
        raise ValueError(f"{where}: a closed mesh needs >= 4 vertices and some triangles")
    return trimesh.Trimesh(v, np.array(f), process=True)


# ------------------------------------------------------------------ joint values
def start_joint_values(data: Any) -> dict[str, float] | None:
    """``{joint name: value}`` of ``robot_state.joint_state`` (a planning scene) or
    ``start_state.joint_state`` (a MotionPlanRequest); None if there is none."""
    if not isinstance(data, dict):
        return None
    state = data.get("robot_state") or data.get("start_state")
    if not state:
        return None
    js = state.get("joint_state") if isinstance(state, dict) else None
    if not js:
        return None
    if not isinstance(js, dict):
        raise ValueError("robot_state: joint_state must be a mapping with name and position")
    names = js.get("name") or []
    pos = js.get("position") or []
    if not isinstance(names, list) or len(names) != len(pos):
        raise ValueError(f"robot_state: joint_state has {len(names) if isinstance(names, list) else '?'} "
                         f"names but {len(pos) if hasattr(pos, '__len__') else '?'} positions")
    if not names:
        return None
    vals = [_number(v, f"robot_state: joint_state position of '{n}'") for n, v in zip(names, pos)]
    return _unique(names, np.array(vals), "robot_state: joint_state")


def goal_joint_values(data: Any) -> dict[str, float] | None:
    """``{joint name: value}`` of the goal joint constraints: the first entry of
    ``goal_constraints`` with ``joint_constraints`` (a MotionPlanRequest), or top-level
    ``joint_constraints``; None if there are none."""
    if not isinstance(data, dict):
        return None
    cons = data.get("joint_constraints")
    if cons is None:
        for g in data.get("goal_constraints") or []:
            if isinstance(g, dict) and g.get("joint_constraints"):
                cons = g["joint_constraints"]
                break
    if not cons:
        return None
    if not isinstance(cons, list):
        raise ValueError("joint_constraints: expected a list of {joint_name, position}")
    names, vals = [], []
    for k, c in enumerate(cons):
        if not isinstance(c, dict) or "joint_name" not in c or "position" not in c:
            raise ValueError(f"joint_constraints[{k}]: expected joint_name and position, got {c!r}")
        names.append(str(c["joint_name"]))
        vals.append(_number(c["position"], f"joint_constraints[{k}] ('{c['joint_name']}') "
                                           f"position"))
    return _unique(names, np.array(vals), "joint_constraints")


def _number(value: Any, where: str) -> float:
    """``value`` as a float (NaN and inf pass: :func:`joint_vector` refuses them only for
    the joints it uses, so a bad value of an ignored joint does not refuse the file)."""
    if isinstance(value, (bool, str, bytes)) or value is None:
        raise ValueError(f"{where}: expected a number, got {value!r}")
    try:
        return float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{where}: expected a number, got {value!r}") from None


def _unique(names: list, vals: np.ndarray, where: str) -> dict[str, float]:
    out: dict[str, float] = {}
    for n, v in zip(names, vals):
        n = str(n)
        if n in out:
            raise ValueError(f"{where}: joint '{n}' given twice")
        out[n] = float(v)
    return out


#: words of gripper joint names (a MoveIt state of an arm lists its gripper's joints)
_GRIPPER_WORDS = re.compile(r"finger|gripper|knuckle|jaw|claw|(^|_)hand(_|$)", re.IGNORECASE)


def ignored_joint_names(model: RobotModel, names: Any) -> list[str]:
    """Those of ``names`` that are joints of the robot which ``model`` lacks or fixes, so a
    MoveIt state or goal may list them and :func:`joint_vector` ignores them (with a
    warning): joints frozen by :func:`jwarp.model.freeze_joints` (``notes['frozen_joints']``),
    names of fixed (uncoupled) DH frames of the model, and names of no frame of
    the model that share the first ``_``-separated word of one of its joint or frame
    names or of its name (``panda_finger_joint1`` for a Panda arm without fingers) or name
    a gripper part (finger, gripper, knuckle, jaw, claw, hand). A static frame's (a
    link's) name is not a joint name, so it is not ignored."""
    frames = {f.name: f for f in model.frames}
    words = {_first_word(n) for n in [*model.joint_names, *frames, model.name]}
    frozen = set(frozen_joint_values(model)) if isinstance(model, RobotModel) else set()
    out = []
    for n in names:
        if n in model.joint_names:
            continue
        if n in frozen:             # jwarp.model.freeze_joints: fixed at a value
            out.append(n)
            continue
        f = frames.get(n)
        if f is not None:
            if f.kind == "dh" and not f.coupling:
                out.append(n)
        elif _first_word(n) in words or _GRIPPER_WORDS.search(n):
            out.append(n)
    return out


def _first_word(name: str) -> str:
    return str(name).lower().split("_", 1)[0]


def joint_vector(model: RobotModel, values: dict[str, float], what: str = "joint values",
                 fallback: np.ndarray | None = None) -> np.ndarray:
    """(n_dof,) joint values of ``model`` from ``{name: value}`` (a MoveIt state or goal).

    * names of coupled (mimic) frames of the model are accepted and ignored (their values
      follow from the joints they mimic);
    * names of joints the model lacks or fixes (:func:`ignored_joint_names`, e.g. gripper
      fingers) are ignored with one warning naming them and their values (whatever the
      values: NaN or out of any range);
    * any other unknown name is a ValueError naming it;
    * every movable joint of the model needs a finite value unless ``fallback`` (n_dof,)
      supplies it (ValueError naming the missing or non-finite ones).

    ``what`` names the source in errors (e.g. ``"start"``; default ``"joint values"``);
    not a string: TypeError naming it."""
    if not isinstance(what, str):
        raise TypeError(f"what: expected the name of the values (a string) for errors, got "
                        f"{type(what).__name__}")
    names = model.joint_names
    frames = model.frames
    mimic = {f.name for f in frames if f.coupling and f.name not in names}
    # an imported URDF's joint names are aliases of their child links' frames: a mimic
    # joint's is its coupled frame, or the fixed frame after its coupled "<joint>_axis"
    for a, i in model.frame_aliases.items():
        p = frames[i].parent
        if a not in names and (frames[i].coupling or (
                p is not None and frames[p].coupling and frames[p].name == a + "_axis")):
            mimic.add(a)
    extra = [n for n in values if n not in names and n not in mimic]
    ignored = ignored_joint_names(model, extra)
    unknown = [n for n in extra if n not in ignored]
    if unknown:
        raise ValueError(f"{what}: unknown joint(s) {', '.join(repr(n) for n in unknown)} for "
                         f"robot '{model.name}'; its joints: {', '.join(names)}")
    if ignored:
        listed = ", ".join(f"'{n}' = {values[n]:g}" for n in ignored)
        warnings.warn(f"{what}: ignoring joint(s) {listed}: not movable joints of robot "
                      f"'{model.name}' (fixed or not in the model)", stacklevel=2)
    missing = [n for n in names if n not in values]
    if missing and fallback is None:
        raise ValueError(f"{what}: no value for joint(s) {', '.join(repr(n) for n in missing)} "
                         f"of robot '{model.name}'")
    bad = [n for n in names if n in values and not math.isfinite(values[n])]
    if bad:
        raise ValueError(f"{what}: joint(s) {', '.join(f'{n!r} = {values[n]}' for n in bad)} "
                         f"of robot '{model.name}' not finite (NaN or inf)")
    q = np.array([values[n] if n in values else float(fallback[i])
                  for i, n in enumerate(names)], np.float64)
    return q
