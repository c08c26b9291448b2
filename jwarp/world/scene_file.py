"""Scene files -> :class:`~jwarp.world.sdf.World`: jwarp's own scene format (YAML or JSON)
and MoveIt planning scenes (:mod:`jwarp.world.moveit`), with the signed distance field
sampled from the shapes' exact distances. Format, options and accuracy: docs/scenes.md.

jwarp scene format (``format: jwarp.scene``; YAML or JSON; lengths in m, angles in rad)::

    format: jwarp.scene
    frame: world                   # the frame of every pose (default world; optional)
    grid: {voxel: 0.02, pad: 0.2}  # optional defaults; or limits: [[x0, x1], [y0, y1], [z0, z1]]
    objects:
      - id: table
        type: box                  # box | sphere | cylinder | capsule | cone | mesh
        size: [1.0, 0.8, 0.04]     # box: full side lengths
        pose: {position: [0.6, 0, 0.38], quaternion: [0, 0, 0, 1]}   # (x, y, z, w)
      - id: can
        type: cylinder             # cylinder, capsule, cone: radius and length (axis z)
        radius: 0.04
        length: 0.12
        pose: {position: [0.5, 0.2, 0.46], rpy: [0, 0, 0]}           # or roll, pitch, yaw
      - {id: ball, type: sphere, radius: 0.05, pose: {position: [0.4, -0.3, 0.45]}}
      - id: mug
        type: mesh                 # a closed mesh file (relative to this file), any
        file: meshes/mug.stl       # format trimesh reads; optional scale: s or [sx, sy, sz]
        pose: {position: [0.7, 0.1, 0.42], rpy: [0, 0, 1.57]}

A file with ``world``/``collision_objects`` or ``robot_state`` at the top level is read
as a MoveIt planning scene. :func:`load_scene` reads either into a :class:`Scene`;
:func:`scene_world` samples its SDF on a grid (:class:`SceneOptions`).

SDF: every cell centre gets the minimum over the shapes of the exact signed distance
(:mod:`jwarp.world.primitives`; meshes: Warp's BVH queries, float32). That is exact at
the cell centres outside the shapes (and inside any one shape that overlaps no other);
between centres the collision kernels interpolate trilinearly, which for these fields
errs by at most half a voxel (measured and tested; docs/scenes.md).
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from jwarp.core.types import ArrayLike, DTypeLike
from jwarp.utils.roots import one_warning_per_file
from jwarp.world.moveit import (
    RobotFrames,
    goal_joint_values,
    load_mesh,
    moveit_frames,
    moveit_shapes,
    parse_pose,
    start_joint_values,
    unknown_frame,
)
from jwarp.world.primitives import (
    N_DIMS,
    Shape,
    finite_vector,
    pose_matrix,
    quaternion_matrix,
    rpy_matrix,
    signed_distance,
)
from jwarp.world.sdf import World, check_grid_cells, world_from_mesh

if TYPE_CHECKING:
    from jwarp.model import RobotModel

__all__ = ["DEFAULT_PAD", "DEFAULT_VOXEL", "FORMAT", "TABLE_SHELF_GOAL", "TABLE_SHELF_START",
           "DuplicateKeyError", "Scene", "SceneOptions", "load_scene", "load_yaml",
           "robot_frames", "scene_from_dict", "scene_world", "table_shelf_scene"]

FORMAT = "jwarp.scene"
#: default voxel size [m] and padding of the automatic extent [m]
DEFAULT_VOXEL = 0.02
DEFAULT_PAD = 0.2
#: peak memory per grid cell [bytes] of :func:`scene_world` (the float64 SDF, the
#: occupancy and a mesh's float32 grid; the temporaries are chunked)
BYTES_PER_CELL = 32
#: points per chunk of the exact-distance evaluation
_CHUNK = 1 << 18
#: keys of an object of the jwarp format, per type (besides id, type, pose, frame)
_OBJECT_KEYS = {"box": ("size",), "sphere": ("radius",), "cylinder": ("radius", "length"),
                "capsule": ("radius", "length"), "cone": ("radius", "length"),
                "mesh": ("file", "scale")}


@dataclass
class Scene:
    """Shapes of a scene file, in the world frame, and what else the file gave.

    Attributes:
        shapes: the solids (:class:`~jwarp.world.primitives.Shape`).
        format: ``"jwarp"`` or ``"moveit"``.
        grid: the file's grid defaults (keys ``voxel``, ``pad``, ``limits``; may be empty).
        start: ``{joint: value}`` of a MoveIt robot state, or None.
        goal: ``{joint: value}`` of MoveIt goal joint constraints, or None.
        source: the file path (or ``"<dict>"``).
    """

    shapes: list[Shape]
    format: str = "jwarp"
    grid: dict = field(default_factory=dict)
    start: dict | None = None
    goal: dict | None = None
    source: str = "<dict>"

    @property
    def object_ids(self) -> list[str]:
        """Ids of the objects, in file order, each once."""
        return list(dict.fromkeys(s.object_id for s in self.shapes))

    def bounds(self) -> np.ndarray:
        """(3, 2) [m] bounding box of every shape (ValueError for an empty scene)."""
        if not self.shapes:
            raise ValueError(f"scene {self.source}: has no objects")
        b = np.stack([s.bounds() for s in self.shapes])
        return np.stack([b[:, :, 0].min(0), b[:, :, 1].max(0)], axis=1)

    def distance(self, points: ArrayLike) -> np.ndarray:
        """Exact signed distance [m] of ``points`` (..., 3) to the union of the shapes
        (minimum over the shapes; +inf for an empty scene)."""
        p = np.asarray(points, dtype=np.float64)
        out = np.full(p.shape[:-1], np.inf)
        for s in self.shapes:
            out = np.minimum(out, signed_distance(s, p))
        return out


@dataclass
class SceneOptions:
    """The grid of :func:`scene_world`.

    Attributes:
        voxel_size: cell size [m] (None: the file's ``grid.voxel``, else
            :data:`DEFAULT_VOXEL`).
        limits: (3, 2) [m] first/last cell centre per axis (None: the file's
            ``grid.limits``, else the shapes' bounding box padded by ``pad``).
        pad: [m] padding of the automatic extent (None: the file's ``grid.pad``, else
            :data:`DEFAULT_PAD`). Outside the grid the collision kernels extrapolate, so
            keep ``pad`` above the largest robot sphere radius plus the margin.
        dtype: float64 or float32 SDF.
    """

    voxel_size: float | None = None
    limits: Any = None
    pad: float | None = None
    dtype: DTypeLike = np.float64

    def validate(self) -> None:
        if self.voxel_size is not None:
            v = self.voxel_size
            if isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer)) \
                    or not (math.isfinite(v) and v > 0):
                raise ValueError(f"voxel_size: expected a positive number [m], got {v!r}")
        if self.pad is not None:
            p = self.pad
            if isinstance(p, bool) or not isinstance(p, (int, float, np.floating, np.integer)) \
                    or not (math.isfinite(p) and p >= 0):
                raise ValueError(f"pad: expected a number >= 0 [m], got {p!r}")
        if self.limits is not None:
            lim = np.asarray(self.limits, dtype=np.float64)
            if lim.shape != (3, 2) or not np.all(np.isfinite(lim)) or np.any(lim[:, 1] <= lim[:, 0]):
                raise ValueError(f"limits: expected finite [[x0, x1], [y0, y1], [z0, z1]] [m] "
                                 f"with x0 < x1 etc., got {np.asarray(self.limits).tolist()}")
        if np.dtype(self.dtype) not in (np.float32, np.float64):
            raise TypeError(f"dtype: expected float32 or float64, got {self.dtype!r}")


# ------------------------------------------------------------------ reading
def load_scene(path: str | os.PathLike, frames: dict[str, np.ndarray] | None = None) -> Scene:
    """Read a scene file (``.yaml``/``.yml``/``.json``; jwarp or MoveIt format, told
    apart by its keys). ``frames``: extra frame ids -> (4, 4) transforms into the world
    frame (e.g. :func:`robot_frames`); ``world`` is always the identity. Every problem
    is a ValueError naming the file and the object."""
    p = Path(path)
    if not p.is_file():
        raise ValueError(f"scene: file '{p}' does not exist" if not p.exists()
                         else f"scene: '{p}' is not a file")
    text = _scene_text(p)
    try:
        if p.suffix.lower() == ".json":
            data = json.loads(text, object_pairs_hook=_unique_json_keys)
        else:
            data = load_yaml(text)
    except DuplicateKeyError as e:
        raise ValueError(f"scene {p}: {e}") from None
    except (json.JSONDecodeError, ValueError) as e:
        raise ValueError(f"scene {p}: not valid JSON: {e}") from None
    except Exception as e:  # yaml.YAMLError
        raise ValueError(f"scene {p}: not valid YAML: {' '.join(str(e).split())}") from None
    if data is None:
        raise ValueError(f"scene {p}: the file is empty")
    return scene_from_dict(data, frames=frames, base_dir=p.parent, source=str(p))


class DuplicateKeyError(ValueError):
    """A key given twice in one mapping of a YAML or JSON document (the later value would
    silently replace the earlier one: a second ``objects:`` list drops the first)."""


def _unique_json_keys(pairs: list[tuple[str, Any]]) -> dict:
    out: dict = {}
    for k, v in pairs:
        if k in out:
            raise DuplicateKeyError(f"key {k!r} is given twice in one JSON object; keep one")
        out[k] = v
    return out


def load_yaml(text: str) -> Any:
    """``yaml.safe_load(text)``, but a key given twice in one mapping is a
    :class:`DuplicateKeyError` naming the key and both lines (PyYAML keeps the last value
    without a word). Every YAML jwarp reads goes through it."""
    import yaml

    class UniqueKeyLoader(yaml.SafeLoader):
        def construct_mapping(self, node: Any, deep: bool = False) -> Any:
            if isinstance(node, yaml.MappingNode):
                seen: dict = {}
                for key_node, _ in node.value:
                    if key_node.tag == "tag:yaml.org,2002:merge":
                        continue
                    key = self.construct_object(key_node, deep=True)
                    try:
                        first = seen.get(key)
                    except TypeError:  # an unhashable key: PyYAML reports it
                        continue
                    line = key_node.start_mark.line + 1
                    if first is not None:
                        raise DuplicateKeyError(f"key {key!r} is given twice in one mapping "
                                                f"(lines {first} and {line}); keep one")
                    seen[key] = line
            return super().construct_mapping(node, deep=deep)

    return yaml.load(text, Loader=UniqueKeyLoader)  # noqa: S506 - a SafeLoader


def _scene_text(path: Path) -> str:
    """The text of a scene file: UTF-8 (with or without a byte order mark) or UTF-16 with
    a byte order mark; ValueError naming the file and the first bad byte otherwise."""
    import codecs

    raw = path.read_bytes()
    if raw.startswith((codecs.BOM_UTF16_LE, codecs.BOM_UTF16_BE)):
        try:
            return raw.decode("utf-16")
        except UnicodeDecodeError as e:
            raise ValueError(f"scene {path}: not valid UTF-16 text ({e.reason} at byte "
                             f"{e.start}); save the file as UTF-8") from None
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        line = raw.count(b"\n", 0, e.start) + 1
        col = e.start - (raw.rfind(b"\n", 0, e.start) + 1) + 1
        raise ValueError(f"scene {path}: not UTF-8 text (byte 0x{raw[e.start]:02x} at line "
                         f"{line}, column {col}); save the file as UTF-8") from None


def scene_from_dict(data: Any, frames: dict[str, np.ndarray] | None = None,
                    base_dir: str | os.PathLike | None = None, source: str = "<dict>") -> Scene:
    """A :class:`Scene` from the parsed contents of a scene file (see :func:`load_scene`)."""
    if not isinstance(data, dict):
        raise ValueError(f"scene {source}: expected a mapping at the top level, got "
                         f"{type(data).__name__}")
    known = RobotFrames({"world": np.eye(4)}, getattr(frames, "moving", ()))
    for name, T in (frames or {}).items():
        known[str(name)] = np.asarray(T, dtype=np.float64)
    base = Path(base_dir) if base_dir is not None else None
    try:
        with one_warning_per_file():  # a mesh outside the scene's folder: said once
            return _scene_of(data, known, base, source)
    except ValueError as e:
        raise ValueError(f"scene {source}: {e}") from None


def _scene_of(data: dict, known: dict, base: Path | None, source: str) -> Scene:
    if "objects" in data or data.get("format") == FORMAT:
        return _jwarp_scene(data, known, base, source)
    if any(k in data for k in ("world", "collision_objects", "robot_state", "start_state",
                               "goal_constraints", "joint_constraints")):
        known = moveit_frames(data, known)
        return Scene(moveit_shapes(data, known, base), "moveit", {},
                     start_joint_values(data), goal_joint_values(data), source)
    raise ValueError("neither a jwarp scene ('objects') nor a MoveIt planning scene "
                     "('world: collision_objects')")


def _jwarp_scene(data: dict, frames: dict, base: Path | None, source: str) -> Scene:
    fmt = data.get("format", FORMAT)
    if fmt != FORMAT:
        raise ValueError(f"format '{fmt}' is not '{FORMAT}'")
    unknown = set(data) - {"format", "version", "frame", "frames", "grid", "objects"}
    if unknown:
        raise ValueError(f"unknown top-level key(s) {sorted(unknown)}")
    for name, pose in (data.get("frames") or {}).items():
        frames[str(name)] = _jwarp_pose(pose, f"frames: '{name}'")
    scene_frame = str(data.get("frame", "world"))
    grid = data.get("grid") or {}
    if not isinstance(grid, dict) or set(grid) - {"voxel", "pad", "limits"}:
        raise ValueError("grid: expected a mapping of voxel, pad and/or limits")
    objs = data.get("objects") or []
    if not isinstance(objs, list):
        raise ValueError("objects: expected a list")
    shapes, seen = [], set()
    for k, obj in enumerate(objs):
        if not isinstance(obj, dict):
            raise ValueError(f"objects[{k}]: expected a mapping, got {obj!r}")
        if not str(obj.get("id", "")).strip():
            raise ValueError(f"objects[{k}]: missing 'id'")
        oid = str(obj["id"])
        where = f"object '{oid}'"
        if oid in seen:
            raise ValueError(f"{where}: id given twice")
        seen.add(oid)
        kind = str(obj.get("type", "")).lower()
        if kind not in N_DIMS:
            raise ValueError(f"{where}: unknown type {obj.get('type')!r}; known: "
                             f"{', '.join(N_DIMS)}")
        extra = set(obj) - {"id", "type", "pose", "frame", *_OBJECT_KEYS[kind]}
        if extra:
            raise ValueError(f"{where}: unknown key(s) {sorted(extra)} for a {kind}; "
                             f"expected {', '.join(_OBJECT_KEYS[kind])}")
        frame = str(obj.get("frame", scene_frame))
        if frame not in frames:
            raise unknown_frame(frames, frame, where, "frame")
        if "pose" not in obj:
            raise ValueError(f"{where}: missing pose")
        T = frames[frame] @ _jwarp_pose(obj["pose"], f"{where}: pose")
        need = [key for key in _OBJECT_KEYS[kind] if key != "scale" and key not in obj]
        if need:
            raise ValueError(f"{where}: a {kind} needs {', '.join(need)}")
        if kind == "mesh":
            spec = {"file": obj["file"], **({"scale": obj["scale"]} if "scale" in obj else {})}
            shapes.append(Shape("mesh", [], T, oid, load_mesh(spec, where, base)))
            continue
        if kind == "box":
            dims = finite_vector(obj["size"], None, f"{where}: size")
        elif kind == "sphere":
            dims = finite_vector([obj["radius"]], 1, f"{where}: radius")
        else:
            dims = finite_vector([obj["length"], obj["radius"]], 2, f"{where}: length, radius")
        shapes.append(Shape(kind, dims, T, oid))
    return Scene(shapes, "jwarp", dict(grid), None, None, source)


def _jwarp_pose(pose: Any, where: str) -> np.ndarray:
    if not isinstance(pose, dict) or "position" not in pose:
        raise ValueError(f"{where}: expected {{position: [x, y, z], quaternion: [x, y, z, w] "
                         f"or rpy: [r, p, y]}}, got {pose!r}")
    extra = set(pose) - {"position", "quaternion", "rpy", "orientation"}
    if extra or ("rpy" in pose and ("quaternion" in pose or "orientation" in pose)):
        raise ValueError(f"{where}: expected position and one of quaternion/rpy, got keys "
                         f"{sorted(pose)}")
    if "rpy" in pose:
        p = finite_vector(pose["position"], 3, f"{where} position")
        return pose_matrix(p, rpy_matrix(finite_vector(pose["rpy"], 3, f"{where} rpy")))
    if "quaternion" in pose:
        p = finite_vector(pose["position"], 3, f"{where} position")
        q = finite_vector(pose["quaternion"], 4, f"{where} quaternion (x, y, z, w)")
        try:
            return pose_matrix(p, quaternion_matrix(q))
        except ValueError as e:
            raise ValueError(f"{where}: {e}") from None
    return parse_pose(pose, where)


def robot_frames(model: RobotModel) -> dict[str, np.ndarray]:
    """Frame ids a scene of ``model`` may use: ``base`` and every frame of the robot
    fixed to its base (static frames and uncoupled DH frames from a root), each with its
    transform in the robot's base coordinates."""
    from jwarp.core.device import host_frames

    T = host_frames(model, np.zeros(model.n_dof))[0]
    out = RobotFrames({"base": np.eye(4)})
    fixed: list[bool] = []
    moving = []
    for i, f in enumerate(model.frames):
        ok = not f.coupling and (f.parent is None or fixed[f.parent])
        fixed.append(ok)
        if ok:
            out[f.name] = T[i]
        else:
            moving.append(f.name)
    out.moving = tuple(moving)
    return out


# ------------------------------------------------------------------ the grid
def _grid_cells(span: np.ndarray, h: float, source: str) -> np.ndarray:
    """(3,) int64 cells per axis covering ``span`` (3,) [m] at voxel ``h`` [m] (>= 2);
    ValueError naming voxel_size and the cell count if there are more than 2**31 cells
    or they need more than the available memory (:data:`BYTES_PER_CELL` each)."""
    from jwarp.utils.memory import available_memory, format_bytes

    with np.errstate(over="ignore", invalid="ignore"):
        nf = np.maximum(np.ceil(span / h - 1e-9) + 1, 2)
    what = f"voxel_size: {h:g} m over the {' x '.join(f'{v:.4g}' for v in span)} m extent of " \
           f"scene {source}"
    hint = "raise voxel_size (--voxel) or shrink the extent"
    check_grid_cells(nf, what, hint)
    need = float(np.prod(nf)) * BYTES_PER_CELL
    have = available_memory()
    if have is not None and need > have:
        raise ValueError(f"{what} needs a grid of {' x '.join(f'{v:.0f}' for v in nf)} = "
                         f"{np.prod(nf):.4g} cells, about {format_bytes(need)} of memory, more "
                         f"than the {format_bytes(have)} available; {hint}")
    return nf.astype(np.int64)


def exact_world(scene: Scene) -> World:
    """The exact 3D :class:`World` of ``scene``: its shapes as exact objects
    (:class:`jwarp.world.shapes.ShapeSet`; no grid), one object per shape (ids of objects
    with several shapes get ``#k`` suffixes). Objects can then be added, moved and
    removed in place (:meth:`World.add`, :meth:`World.move`, :meth:`World.remove`)."""
    from jwarp.world.shapes import ShapeSet

    if not isinstance(scene, Scene):
        raise TypeError(f"scene: expected a Scene, got {type(scene).__name__}")
    meta = {"source": "scene", "scene": scene.source, "format": scene.format,
            "objects": scene.object_ids, "exact": True}
    return World.of_shapes(ShapeSet.from_shapes(scene.shapes), meta)


def scene_world(scene: Scene, options: SceneOptions | None = None) -> World:
    """The 3D grid :class:`World` of ``scene``: at every cell centre the minimum over the
    shapes of their exact signed distances (module docstring); it declares
    ``grid_error = sqrt(3)/2 voxel_size``, the most the interpolation can overestimate, and
    the collision checks subtract it. Prefer :func:`exact_world` (no grid, exact). ``meta`` records the source, the
    object ids and the grid. ValueError naming ``voxel_size`` (before any allocation) if
    the grid would have more than 2**31 cells or not fit in the available memory."""
    opts = options or SceneOptions()
    opts.validate()
    if not isinstance(scene, Scene):
        raise TypeError(f"scene: expected a Scene, got {type(scene).__name__}")
    g = SceneOptions(scene.grid.get("voxel"), scene.grid.get("limits"), scene.grid.get("pad"))
    try:
        g.validate()
    except ValueError as e:
        raise ValueError(f"scene {scene.source}: grid: {e}") from None
    h = float(opts.voxel_size if opts.voxel_size is not None else
              g.voxel_size if g.voxel_size is not None else DEFAULT_VOXEL)
    pad = float(opts.pad if opts.pad is not None else g.pad if g.pad is not None else DEFAULT_PAD)
    limits = opts.limits if opts.limits is not None else g.limits
    if limits is None:
        if not scene.shapes:
            raise ValueError(f"scene {scene.source}: has no objects; give the grid's limits")
        b = scene.bounds()
        lo, span = b[:, 0] - pad, b[:, 1] - b[:, 0] + 2 * pad
    else:
        lim = np.asarray(limits, dtype=np.float64)
        lo, span = lim[:, 0], lim[:, 1] - lim[:, 0]
    n = _grid_cells(span, h, scene.source)
    lim = np.stack([lo, lo + (n - 1) * h], axis=1)
    shape = tuple(int(v) for v in n)
    sdf = np.full(shape, np.inf)
    prims = [s for s in scene.shapes if s.kind != "mesh"]
    axes = [lo[d] + h * np.arange(n[d]) for d in range(3)]
    per_x = max(1, _CHUNK // (shape[1] * shape[2]))
    for i0 in range(0, shape[0], per_x):
        if not prims:
            break
        pts = np.stack(np.meshgrid(axes[0][i0:i0 + per_x], axes[1], axes[2], indexing="ij"), -1)
        block = sdf[i0:i0 + per_x]
        for s in prims:
            np.minimum(block, signed_distance(s, pts), out=block)
    for s in scene.shapes:
        if s.kind == "mesh":
            try:
                m = world_from_mesh(s.world_mesh(), lim, h, shape=shape)
            except ValueError as e:
                raise ValueError(f"object '{s.object_id}': {e}") from None
            np.minimum(sdf, m.sdf, out=sdf)
    if not np.isfinite(sdf).all():  # no shapes
        sdf[:] = float(np.linalg.norm(lim[:, 1] - lim[:, 0])) + h
    meta = {"source": "scene", "scene": scene.source, "format": scene.format,
            "objects": scene.object_ids, "pad": pad if limits is None else None}
    # trilinear interpolation of exact (1-Lipschitz) distances at cell centres is off by at
    # most the distance to the cell's corners weighted: sqrt(3) / 2 voxels
    return World(sdf.astype(opts.dtype), lim, h, sdf < 0, meta,
                 grid_error=float(np.sqrt(3.0) / 2.0 * h))


# ------------------------------------------------------------------ a scene for a Panda
_PANDA_JOINTS = [f"panda_joint{i}" for i in range(1, 8)]
#: the start (Panda's "ready" pose, fingers open 3.5 cm each, as MoveIt writes a full robot
#: state) and goal (the arm's 7 joints: the hand in front of the shelf's lower
#: compartment) of examples/scenes/table_shelf.yaml [rad, m]
TABLE_SHELF_START = {**dict(zip(_PANDA_JOINTS, [0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785])),
                     "panda_finger_joint1": 0.035, "panda_finger_joint2": 0.035}
TABLE_SHELF_GOAL = dict(zip(_PANDA_JOINTS, [-1.0, 0.3, 0.0, -1.9, 0.0, 2.2, 0.785]))


def table_shelf_scene(frame_id: str = "world", robot_state: dict | None = None,
                      goal: dict | None = None) -> dict:
    """A tabletop-and-shelf planning scene for a Panda at the origin, as MoveIt YAML data
    (a dict; ``yaml.safe_dump`` it to write examples/scenes/table_shelf.yaml).

    * table: top 0.6 x 0.6 m, 3 cm thick, upper face at z = 0.40 m, centred at
      (0.55, 0.40), on four cylinder legs (radius 2 cm); a can (cylinder r 4 cm, 12 cm
      tall) and a box on it;
    * shelf: x 0.50..0.80 m (boards 30 cm deep, 2 cm thick at z = 0.20, 0.50, 0.80 m),
      y -0.75..-0.15 m, side walls and a back wall up to 0.90 m, a box on the middle board.

    ``robot_state`` / ``goal``: ``{joint: value}`` written as ``robot_state.joint_state``
    and ``goal_constraints[0].joint_constraints`` (omitted when None).
    """
    def pose(x: float, y: float, z: float, q: tuple = (0.0, 0.0, 0.0, 1.0)) -> dict:
        return {"position": [round(v, 9) for v in (x, y, z)],
                "orientation": [round(v, 12) for v in q]}

    def obj(oid: str, prims: list) -> dict:
        return {"id": oid, "header": {"frame_id": frame_id}, "operation": "add",
                "primitives": [{"type": t, "dimensions": [round(v, 9) for v in d]}
                               for t, d, _ in prims],
                "primitive_poses": [p for _, _, p in prims]}

    tx, ty, top, th = 0.55, 0.40, 0.40, 0.03
    legs = [("cylinder", (top - th, 0.02), pose(tx + sx * 0.26, ty + sy * 0.26, 0.5 * (top - th)))
            for sx in (-1, 1) for sy in (-1, 1)]
    x0, x1, y0, y1, zt, t = 0.50, 0.80, -0.75, -0.15, 0.90, 0.02
    xc, yc = 0.5 * (x0 + x1), 0.5 * (y0 + y1)
    boards = [("box", (x1 - x0, y1 - y0, t), pose(xc, yc, z)) for z in (0.20, 0.50, 0.80)]
    walls = [("box", (x1 - x0, t, zt), pose(xc, y, 0.5 * zt)) for y in (y0 - 0.5 * t, y1 + 0.5 * t)]
    back = [("box", (t, y1 - y0 + 2 * t, zt), pose(x1 + 0.5 * t, yc, 0.5 * zt))]
    yaw45 = (0.0, 0.0, math.sin(math.pi / 8), math.cos(math.pi / 8))
    objects = [
        obj("table", [("box", (0.6, 0.6, th), pose(tx, ty, top - 0.5 * th))] + legs),
        obj("can", [("cylinder", (0.12, 0.04), pose(0.50, 0.30, top + 0.06))]),
        obj("box_on_table", [("box", (0.08, 0.12, 0.10), pose(0.62, 0.52, top + 0.05, yaw45))]),
        obj("shelf", boards + walls + back),
        obj("box_in_shelf", [("box", (0.10, 0.10, 0.12), pose(0.68, -0.55, 0.51 + 0.06))]),
    ]
    data: dict = {"name": "table_shelf", "robot_model_name": "panda",
                  "world": {"collision_objects": objects}, "is_diff": True}
    if robot_state is not None:
        data["robot_state"] = {"joint_state": {"name": list(robot_state),
                                               "position": [float(v) for v in robot_state.values()]}}
    if goal is not None:
        data["goal_constraints"] = [{"joint_constraints": [
            {"joint_name": k, "position": float(v), "tolerance_above": 1e-4,
             "tolerance_below": 1e-4, "weight": 1.0} for k, v in goal.items()]}]
    return data
