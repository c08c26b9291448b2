"""Geometric primitives of a scene and their exact signed distances (numpy, float64).

A :class:`Shape` is one solid in the scene's world frame: ``kind`` (``box``, ``sphere``,
``cylinder``, ``capsule``, ``cone``, ``mesh``), its dimensions in the local frame and its
pose (4x4, local -> world). Local frames (the conventions of MoveIt's ``SolidPrimitive``):

* ``box``: ``dims = [x, y, z]`` full side lengths [m], centred on the origin;
* ``sphere``: ``dims = [radius]``;
* ``cylinder``: ``dims = [length, radius]``, axis z, centred (z in +-length/2);
* ``capsule``: ``dims = [length, radius]``, the segment z in +-length/2 swept by a ball of
  ``radius`` (total length ``length + 2 radius``);
* ``cone``: ``dims = [length, radius]``, axis z, base disc of ``radius`` at
  z = -length/2, tip at z = +length/2 (the centre of its bounding box at the origin, as
  MoveIt and FCL place it);
* ``mesh``: a triangle mesh, vertices in the local frame (open meshes: inside by the
  generalised winding number in the exact world; a grid needs a closed mesh).

:func:`signed_distance` gives the exact Euclidean signed distance [m] (negative inside) to
one shape by closed forms (the cone through the distance to its triangular cross-section
in the (r, z) half plane); meshes use trimesh's exact point-to-triangle distances.
:func:`pose_matrix` builds poses from a position and a quaternion (x, y, z, w) or roll,
pitch, yaw.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from jwarp.core.types import ArrayLike

__all__ = ["KINDS", "MAX_EXTENT", "N_DIMS", "Shape", "finite_vector", "pose_matrix", "quaternion_matrix", "rpy_matrix",
           "signed_distance", "union_distance"]

#: the shape kinds and their number of dimensions (None: a mesh, no dimensions)
N_DIMS = {"box": 3, "sphere": 1, "cylinder": 2, "capsule": 2, "cone": 2, "mesh": 0}
KINDS = tuple(N_DIMS)
#: [m] the largest dimension, position coordinate or mesh vertex coordinate of a shape (a
#: bigger one is a unit mistake or garbage, and its grid could not be sampled)
MAX_EXTENT = 1e4


@dataclass(eq=False)
class Shape:
    """One solid of a scene.

    Attributes:
        kind: one of :data:`KINDS`.
        dims: (N_DIMS[kind],) [m], module docstring.
        pose: (4, 4) local -> world frame [m].
        object_id: id of the scene object it belongs to (error messages, meta).
        mesh: ``trimesh.Trimesh`` in local coordinates for ``kind == "mesh"``, else None.
    """

    kind: str
    dims: np.ndarray
    pose: np.ndarray
    object_id: str = ""
    mesh: Any = None
    _inv: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        where = f"object '{self.object_id}'"
        if self.kind not in N_DIMS:
            raise ValueError(f"{where}: unknown shape type '{self.kind}'; known: {', '.join(KINDS)}")
        d = np.asarray(self.dims, dtype=np.float64).reshape(-1)
        if len(d) != N_DIMS[self.kind]:
            raise ValueError(f"{where}: a {self.kind} needs {N_DIMS[self.kind]} dimensions, "
                             f"got {len(d)}")
        if not np.all(np.isfinite(d)) or np.any(d <= 0):
            raise ValueError(f"{where}: {self.kind} dimensions must be finite and > 0 [m], "
                             f"got {d.tolist()}")
        _check_extent(d, f"{where}: {self.kind} dimensions")
        self.dims = d
        T = np.asarray(self.pose, dtype=np.float64)
        if T.shape != (4, 4) or not np.all(np.isfinite(T)):
            raise ValueError(f"{where}: pose must be a finite 4x4 transform")
        _check_extent(T[:3, 3], f"{where}: position")
        R = T[:3, :3]
        if not np.allclose(R.T @ R, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
            raise ValueError(f"{where}: pose rotation is not a rotation matrix")
        self.pose = T
        inv = np.eye(4)
        inv[:3, :3] = R.T
        inv[:3, 3] = -R.T @ T[:3, 3]
        self._inv = inv
        if self.kind == "mesh":
            if self.mesh is None:
                raise ValueError(f"{where}: a mesh shape needs its mesh")
            _check_mesh(self.mesh, where)
            # open meshes are accepted: the exact world decides inside by the winding
            # number (jwarp.kernels.geometry); a grid of them (scene_world) needs them closed

    def to_local(self, points: np.ndarray) -> np.ndarray:
        """(..., 3) world points [m] -> (..., 3) in the shape's frame."""
        return points @ self._inv[:3, :3].T + self._inv[:3, 3]

    def bounds(self) -> np.ndarray:
        """(3, 2) [m] axis-aligned bounding box in the world frame."""
        if self.kind == "mesh":
            corners = np.asarray(self.mesh.vertices, np.float64)
        else:
            if self.kind == "box":
                h = 0.5 * self.dims
            elif self.kind == "sphere":
                h = np.full(3, self.dims[0])
            elif self.kind == "capsule":
                h = np.array([self.dims[1], self.dims[1], 0.5 * self.dims[0] + self.dims[1]])
            else:
                h = np.array([self.dims[1], self.dims[1], 0.5 * self.dims[0]])
            corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1)
                                for sz in (-1, 1)]) * h
        w = corners @ self.pose[:3, :3].T + self.pose[:3, 3]
        return np.stack([w.min(0), w.max(0)], axis=1)

    def world_mesh(self) -> Any:
        """The mesh (``kind == "mesh"``) in world coordinates (a trimesh copy)."""
        m = self.mesh.copy()
        m.apply_transform(self.pose)
        return m


def _check_extent(values: np.ndarray, where: str) -> None:
    """ValueError naming ``where`` if any of ``values`` [m] exceeds :data:`MAX_EXTENT`."""
    big = np.abs(values).max(initial=0.0)
    if big > MAX_EXTENT:
        raise ValueError(f"{where}: {np.asarray(values).tolist()} [m] exceed {MAX_EXTENT:g} m "
                         f"(a unit mistake? lengths are in m)")


def _check_mesh(mesh: Any, where: str) -> None:
    """ValueError naming ``where`` for an empty mesh (no vertices or no faces), non-finite
    or enormous vertices."""
    v = np.asarray(mesh.vertices, np.float64).reshape(-1, 3)
    nf = len(np.asarray(mesh.faces).reshape(-1, 3))
    if len(v) == 0 or nf == 0:
        raise ValueError(f"{where}: mesh is empty ({len(v)} vertices, {nf} faces)")
    if not np.all(np.isfinite(v)):
        raise ValueError(f"{where}: mesh vertices contain NaN or inf")
    big = float(np.abs(v).max())
    if big > MAX_EXTENT:
        raise ValueError(f"{where}: mesh vertices reach {big:g} m, beyond {MAX_EXTENT:g} m (a "
                         f"unit mistake? lengths are in m; give a scale)")


# ------------------------------------------------------------------ distances
def _box(p: np.ndarray, size: np.ndarray) -> np.ndarray:
    q = np.abs(p) - 0.5 * size
    outside = np.linalg.norm(np.maximum(q, 0.0), axis=-1)
    inside = np.minimum(q.max(axis=-1), 0.0)
    return outside + inside


def _cylinder(p: np.ndarray, length: float, radius: float) -> np.ndarray:
    dr = np.hypot(p[..., 0], p[..., 1]) - radius
    dz = np.abs(p[..., 2]) - 0.5 * length
    outside = np.hypot(np.maximum(dr, 0.0), np.maximum(dz, 0.0))
    return outside + np.minimum(np.maximum(dr, dz), 0.0)


def _capsule(p: np.ndarray, length: float, radius: float) -> np.ndarray:
    z = np.clip(p[..., 2], -0.5 * length, 0.5 * length)
    return np.sqrt(p[..., 0] ** 2 + p[..., 1] ** 2 + (p[..., 2] - z) ** 2) - radius


def _cone(p: np.ndarray, length: float, radius: float) -> np.ndarray:
    """Distance to the triangle (-R, -L/2), (R, -L/2), (0, L/2) of the (r, z) plane: the
    cone is its solid of revolution, and for r >= 0 the nearest point of the symmetric
    convex triangle is the nearest point of the solid in that half plane."""
    r = np.hypot(p[..., 0], p[..., 1])
    z = p[..., 2]
    pts = np.stack([r, z], axis=-1)
    verts = np.array([[-radius, -0.5 * length], [radius, -0.5 * length], [0.0, 0.5 * length]])
    d2 = np.full(r.shape, np.inf)
    inside = np.ones(r.shape, bool)
    for k in range(3):
        a, b = verts[k], verts[(k + 1) % 3]
        e = b - a
        w = pts - a
        t = np.clip((w @ e) / (e @ e), 0.0, 1.0)
        d2 = np.minimum(d2, np.sum((w - t[..., None] * e) ** 2, axis=-1))
        inside &= (e[0] * w[..., 1] - e[1] * w[..., 0]) >= 0.0   # counter-clockwise: left
    d = np.sqrt(d2)
    return np.where(inside, -d, d)


def signed_distance(shape: Shape, points: ArrayLike) -> np.ndarray:
    """Exact signed distance [m] of ``points`` (..., 3) [m, world frame] to ``shape``,
    negative inside; returns (...,)."""
    p = np.asarray(points, dtype=np.float64)
    if p.shape[-1:] != (3,):
        raise ValueError(f"points: expected shape (..., 3), got {p.shape}")
    if shape.kind == "mesh":
        import trimesh

        flat = p.reshape(-1, 3)
        # trimesh: positive inside; exact closest points on the triangles
        d = -trimesh.proximity.signed_distance(shape.world_mesh(), flat)
        return np.asarray(d, np.float64).reshape(p.shape[:-1])
    q = shape.to_local(p)
    a = shape.dims
    if shape.kind == "box":
        return _box(q, a)
    if shape.kind == "sphere":
        return np.linalg.norm(q, axis=-1) - a[0]
    if shape.kind == "cylinder":
        return _cylinder(q, a[0], a[1])
    if shape.kind == "capsule":
        return _capsule(q, a[0], a[1])
    return _cone(q, a[0], a[1])


def union_distance(shapes: list[Shape], points: ArrayLike) -> np.ndarray:
    """min over ``shapes`` of :func:`signed_distance`: exact outside the shapes; inside
    where shapes overlap it is minus the deepest single penetration (the sign is right,
    the magnitude a lower bound of the depth). +inf for no shapes."""
    p = np.asarray(points, dtype=np.float64)
    out = np.full(p.shape[:-1], np.inf)
    for s in shapes:
        out = np.minimum(out, signed_distance(s, p))
    return out


# ------------------------------------------------------------------ poses
def quaternion_matrix(q: Any) -> np.ndarray:
    """(3, 3) rotation of a unit quaternion ``(x, y, z, w)`` (ROS order); normalised,
    ValueError if its norm is not within 1e-3 of 1 (or zero)."""
    x, y, z, w = np.asarray(q, dtype=np.float64)
    n = np.sqrt(x * x + y * y + z * z + w * w)
    if not abs(n - 1.0) < 1e-3:
        raise ValueError(f"quaternion (x, y, z, w) {list(map(float, q))} is not unit length "
                         f"(norm {n:.6g})")
    x, y, z, w = x / n, y / n, z / n, w / n
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def rpy_matrix(rpy: Any) -> np.ndarray:
    """(3, 3) rotation of roll, pitch, yaw [rad] about the fixed x, y, z axes (URDF):
    ``Rz(yaw) @ Ry(pitch) @ Rx(roll)``."""
    r, p, y = np.asarray(rpy, dtype=np.float64)
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


def pose_matrix(position: Any, rotation: np.ndarray | None = None) -> np.ndarray:
    """(4, 4) transform of a position (3,) [m] and a rotation matrix (identity if None)."""
    T = np.eye(4)
    T[:3, 3] = np.asarray(position, dtype=np.float64)
    if rotation is not None:
        T[:3, :3] = rotation
    return T


def _not_text(text: str, where: str) -> None:
    """ValueError for a number given as text, with YAML's reason when it reads as one."""
    try:
        float(text)
    except ValueError:
        raise ValueError(f"{where}: expected numbers, got the text {text!r}") from None
    raise ValueError(f"{where}: {text!r} is text, not a number (YAML reads a number such as "
                     f"1.0e6, without a sign in its exponent, or a quoted one as text: write "
                     f"1.0e+6, or drop the quotes)")


def finite_vector(value: Any, n: int | None, where: str) -> np.ndarray:
    """``value`` as a (n,) float64 vector of finite numbers (any length if ``n`` is None);
    ValueError naming ``where`` (e.g. ``"object 'table': pose position"``) otherwise."""
    if isinstance(value, str):
        _not_text(value, where)
    if isinstance(value, (str, bytes, dict)) or not hasattr(value, "__len__"):
        raise ValueError(f"{where}: expected a list of {n or 'some'} numbers, got {value!r}")
    for x in value:  # float() would take True as 1.0 and the text "0.5" as 0.5
        if isinstance(x, str):
            _not_text(x, where)
        if isinstance(x, (bool, np.bool_, bytes)):
            raise ValueError(f"{where}: expected numbers, got {x!r} in {value!r}")
    try:
        v = np.array([float(x) for x in value], dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{where}: expected numbers, got {value!r}") from None
    if n is not None and len(v) != n:
        raise ValueError(f"{where}: expected {n} numbers, got {len(v)}")
    if not np.all(np.isfinite(v)):
        raise ValueError(f"{where}: contains NaN or inf: {v.tolist()}")
    return v
