"""Exact world objects: a :class:`ShapeSet` of primitives, planes and triangle meshes.

The host table behind the exact collision kernels (:mod:`jwarp.kernels.geometry`). Objects
can be added, removed and moved in place; their device copy (per Warp device and float
type) follows on the next query: moved objects update their pose arrays and refit the
bounding-volume hierarchy, added or removed ones rebuild it.

Conventions (local frames as :mod:`jwarp.world.primitives` and MoveIt's SolidPrimitive):

* ``box``: ``dims = [x, y, z]`` full side lengths, centred;
* ``sphere``: ``[radius]``;
* ``cylinder``, ``capsule``, ``cone``: ``[length, radius]``, axis z, centred (the cone's
  base at -length/2, its tip at +length/2; a capsule's segment is z in +-length/2);
* ``plane``: the half-space z <= 0 of its pose (solid below, normal +z); no dims;
* ``mesh``: a ``trimesh.Trimesh`` in local coordinates (need not be closed: inside is
  decided by the generalised winding number).

Poses are 4x4 local -> world [m].
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np
import warp as wp

from jwarp.core.arrays import init_warp, resolve_device
from jwarp.core.types import ArrayLike
from jwarp.kernels import geometry as gk
from jwarp.utils.checks import check_int

__all__ = ["KINDS", "ShapeSet", "DeviceShapes", "LIMIT_EXTENT", "mesh_arrays"]

#: kinds a ShapeSet holds
KINDS = ("sphere", "box", "cylinder", "capsule", "cone", "plane", "mesh")
_N_DIMS = {"sphere": 1, "box": 3, "cylinder": 2, "capsule": 2, "cone": 2, "plane": 0, "mesh": 0}
#: largest accepted size or position [m]
LIMIT_EXTENT = 1e4


_LAST_ROW = np.array([0.0, 0.0, 0.0, 1.0])
_EYE3 = np.eye(3)
_ORTHO_TOL = 1e-6 + 1e-5 * _EYE3


def _det3(R: np.ndarray) -> float:
    return float(R[0, 0] * (R[1, 1] * R[2, 2] - R[1, 2] * R[2, 1])
                 - R[0, 1] * (R[1, 0] * R[2, 2] - R[1, 2] * R[2, 0])
                 + R[0, 2] * (R[1, 0] * R[2, 1] - R[1, 1] * R[2, 0]))


def _pose(pose: Any, where: str) -> np.ndarray:
    try:
        T = np.asarray(pose, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise TypeError(f"{where}: pose must be a 4x4 transform of numbers: {e}") from None
    if T.shape == (3,):
        p = T
        T = np.eye(4)
        T[:3, 3] = p
    if T.shape != (4, 4):
        raise ValueError(f"{where}: pose must be a 4x4 transform (or a position (3,)), "
                         f"got shape {T.shape}")
    if not np.isfinite(T).all():
        raise ValueError(f"{where}: pose contains NaN or inf")
    if np.abs(T[3] - _LAST_ROW).max() > 1e-9:
        raise ValueError(f"{where}: pose's last row is {T[3].tolist()}, not [0, 0, 0, 1] "
                         f"(a transposed transform?)")
    R = T[:3, :3]
    # np.allclose(R^T R, I, atol=1e-6) (its rtol 1e-5 on the diagonal), and det(R) > 0
    if (np.abs(R.T @ R - _EYE3) > _ORTHO_TOL).any() or _det3(R) < 0:
        raise ValueError(f"{where}: pose rotation is not a rotation matrix")
    if np.abs(T[:3, 3]).max() > LIMIT_EXTENT:
        raise ValueError(f"{where}: position {T[:3, 3].tolist()} is beyond "
                         f"{LIMIT_EXTENT:g} m")
    return T


def mesh_arrays(mesh: Any, where: str) -> tuple[np.ndarray, np.ndarray]:
    """``(vertices (V, 3) float64, faces (F, 3) int32)`` of a mesh-like object (anything
    with ``vertices`` and ``faces``, e.g. a ``trimesh.Trimesh``, or a ``(vertices, faces)``
    pair), checked before any kernel sees it: finite vertices, integer face indices in
    ``[0, V)`` (an index past the vertices would make Warp's mesh queries read outside
    the vertex array). Raises TypeError/ValueError starting with ``where``."""
    if hasattr(mesh, "vertices") and hasattr(mesh, "faces"):
        verts, faces = mesh.vertices, mesh.faces
    elif isinstance(mesh, (tuple, list)) and len(mesh) == 2:
        verts, faces = mesh
    else:
        raise TypeError(f"{where}: a mesh needs a trimesh.Trimesh (vertices, faces), got "
                        f"{type(mesh).__name__}")
    try:
        v = np.asarray(verts, dtype=np.float64)
        f = np.asarray(faces)
    except (TypeError, ValueError) as e:
        raise TypeError(f"{where}: mesh vertices and faces must be arrays of numbers: "
                        f"{e}") from None
    if v.ndim != 2 or v.shape[1] != 3 or len(v) == 0 or f.ndim != 2 or len(f) == 0:
        raise ValueError(f"{where}: empty mesh ({len(v)} vertices, {len(f)} faces)"
                         if v.size == 0 or f.size == 0 else
                         f"{where}: mesh vertices must have shape (V, 3) and faces (F, 3), "
                         f"got {v.shape} and {f.shape}")
    if f.shape[1] != 3:
        raise ValueError(f"{where}: mesh faces must be triangles (F, 3), got shape {f.shape}")
    if f.dtype == bool or not np.issubdtype(f.dtype, np.integer):
        raise TypeError(f"{where}: mesh face indices must be integers, got dtype {f.dtype}")
    if not np.all(np.isfinite(v)):
        raise ValueError(f"{where}: mesh vertices contain NaN or inf")
    bad = np.nonzero((f < 0).any(axis=1) | (f >= len(v)).any(axis=1))[0]
    if len(bad):
        j = int(bad[0])
        raise ValueError(f"{where}: mesh face {j} has vertex indices {f[j].tolist()} outside "
                         f"[0, {len(v)}) ({len(bad)} such faces)")
    return v, f.astype(np.int32)


@dataclass
class _Object:
    id: str
    kind: str
    size: np.ndarray      # kernel size (module docstring of jwarp.kernels.geometry)
    centre: np.ndarray    # local bounding-box centre
    half: np.ndarray      # local bounding-box half extents (planes: unused)
    mesh: Any = None      # (vertices, faces) (mesh kind)
    dims: Any = None      # the dimensions as given (add)
    source: Any = None    # the mesh as given (add)
    group: int = 0        # its world in a batch of worlds


class ShapeSet:
    """Exact objects of a world (module docstring), each with a unique ``id``.

    Example::

        s = ShapeSet()
        s.add("table", "box", [1.0, 0.8, 0.04], pose)
        s.add("floor", "plane", pose=np.eye(4))
        s.move(["table"], [new_pose])
        s.remove("table")
    """

    def __init__(self) -> None:
        self._objects: list[_Object] = []
        self._index: dict[str, int] = {}
        #: the poses (K, 4, 4) are the first K rows of a buffer grown by doubling, so that
        #: adding objects one by one is amortised O(1) (a copy per add made n adds O(n^2))
        self._pose_buf = np.zeros((0, 4, 4))
        #: bumped by add/remove (device tables rebuilt) and by move (poses refreshed)
        self.structure_version = 0
        self.pose_version = 0
        #: worlds of a batch (World.batch), also those without objects
        self.n_worlds = 1
        self._device: dict = {}

    # ------------------------------------------------------------------ build
    @classmethod
    def from_shapes(cls, shapes: Iterable[Any]) -> ShapeSet:
        """A ShapeSet of :class:`jwarp.world.primitives.Shape` objects (ids made unique
        by a ``#k`` suffix where one object has several shapes)."""
        s = cls()
        seen: dict[str, int] = {}
        for sh in shapes:
            base = sh.object_id or sh.kind
            k = seen.get(base, 0)
            seen[base] = k + 1
            oid = base if k == 0 else f"{base}#{k}"
            dims = [] if sh.kind == "mesh" else sh.dims
            s.add(oid, sh.kind, dims, sh.pose, mesh=sh.mesh)
        return s

    def add(self, id: str, kind: str, dims: Any = (), pose: Any = None, *,
            mesh: Any = None, group: int = 0) -> int:
        """Add object ``id`` (a new name) of ``kind`` (:data:`KINDS`) with ``dims`` [m]
        and ``pose`` (4x4 or a position; None: identity); ``group``: its world in a batch
        of worlds (>= 0). Returns its index."""
        check_int(group, "group", 0)
        if not isinstance(id, str) or not id:
            raise TypeError(f"id: expected a non-empty string, got {id!r}")
        where = f"object '{id}'"
        if id in self._index:
            raise ValueError(f"{where}: an object of that id exists (remove it first)")
        if kind not in _N_DIMS:
            raise ValueError(f"{where}: unknown shape type {kind!r}; known: {', '.join(KINDS)}")
        T = np.eye(4) if pose is None else _pose(pose, where)
        obj = self._make(id, kind, dims, mesh, where)
        obj.dims = None if kind in ("mesh", "plane") else np.asarray(dims, np.float64).reshape(-1)
        obj.source = mesh
        obj.group = int(group)
        k = len(self._objects)
        if k == len(self._pose_buf):
            grown = np.zeros((max(8, 2 * k), 4, 4))
            grown[:k] = self._pose_buf[:k]
            self._pose_buf = grown
        self._pose_buf[k] = T
        self._objects.append(obj)
        self._index[id] = k
        self.structure_version += 1
        return k

    @property
    def _poses(self) -> np.ndarray:
        """(K, 4, 4) the objects' poses (a view of the buffer)."""
        return self._pose_buf[:len(self._objects)]

    @_poses.setter
    def _poses(self, value: np.ndarray) -> None:
        self._pose_buf = np.array(value, np.float64).reshape(-1, 4, 4)

    def _make(self, id: str, kind: str, dims: Any, mesh: Any, where: str) -> _Object:
        if kind == "mesh":
            return self._make_mesh(id, mesh, where)
        from jwarp.core.arrays import real_array

        # numbers only: numpy would take True as 1.0 and the text "0.1" as 0.1
        items = dims if isinstance(dims, (list, tuple)) else [dims]
        if any(isinstance(x, (bool, np.bool_, str, bytes)) for x in items):
            raise ValueError(f"{where}: {kind} dimensions must be numbers [m], got {dims!r}")
        try:
            d = real_array(dims, f"{where}: dims").reshape(-1)
        except TypeError:
            raise ValueError(f"{where}: {kind} dimensions must be numbers [m], "
                             f"got {dims!r}") from None
        if len(d) != _N_DIMS[kind]:
            raise ValueError(f"{where}: a {kind} needs {_N_DIMS[kind]} dimensions, got {len(d)}")
        if not np.all(np.isfinite(d)) or np.any(d <= 0):
            raise ValueError(f"{where}: {kind} dimensions must be finite and > 0 [m], "
                             f"got {d.tolist()}")
        if len(d) and d.max() > LIMIT_EXTENT:
            raise ValueError(f"{where}: {kind} dimensions {d.tolist()} exceed "
                             f"{LIMIT_EXTENT:g} m")
        z = np.zeros(3)
        if kind == "sphere":
            size, half = np.array([d[0], 0, 0]), np.full(3, d[0])
        elif kind == "box":
            size = half = 0.5 * d
        elif kind == "plane":
            size, half = z, z
        else:
            length, radius = d
            size = np.array([radius, 0.5 * length, 0.0])
            hz = 0.5 * length + (radius if kind == "capsule" else 0.0)
            half = np.array([radius, radius, hz])
        return _Object(id, kind, size, z.copy(), half)

    def _make_mesh(self, id: str, mesh: Any, where: str) -> _Object:
        v, f = mesh_arrays(mesh, where)
        if np.abs(v).max() > LIMIT_EXTENT:
            raise ValueError(f"{where}: mesh vertices beyond {LIMIT_EXTENT:g} m")
        lo, hi = v.min(0), v.max(0)
        return _Object(id, "mesh", 0.5 * (hi - lo), 0.5 * (hi + lo), 0.5 * (hi - lo),
                       mesh=(v, f))

    def remove(self, id: str) -> None:
        """Remove object ``id`` (KeyError naming it if absent)."""
        k = self._find(id)
        poses = np.delete(self._poses, k, axis=0)
        del self._objects[k]
        self._poses = poses
        self._index = {o.id: i for i, o in enumerate(self._objects)}
        self.structure_version += 1

    def move(self, ids: Any, poses: Any) -> None:
        """Set the poses (n, 4, 4) (or positions (n, 3)) of objects ``ids`` (n names)."""
        if isinstance(ids, str):
            ids = [ids]
            poses = [poses]
        idx = np.array([self._find(i) for i in ids], dtype=np.int64)
        P = np.asarray(poses, dtype=np.float64)
        if P.shape == (len(idx), 3):
            T = self._poses[idx].copy()
            T[:, :3, 3] = P
        elif P.shape == (len(idx), 4, 4):
            T = P
        else:
            raise ValueError(f"poses: expected ({len(idx)}, 4, 4) transforms or ({len(idx)}, 3) "
                             f"positions, got {P.shape}")
        if not np.all(np.isfinite(T)):
            bad = int(np.nonzero(~np.isfinite(T).reshape(len(idx), -1).all(1))[0][0])
            raise ValueError(f"object '{ids[bad]}': pose contains NaN or inf")
        # the checks of add (_pose), vectorised; the first bad object is named
        last = np.abs(T[:, 3] - _LAST_ROW).max(axis=1, initial=0.0)
        R = T[:, :3, :3]
        ortho = (np.abs(np.einsum("nji,njk->nik", R, R) - _EYE3) > _ORTHO_TOL).any(axis=(1, 2))
        rows = np.nonzero((last > 1e-9) | ortho | (np.linalg.det(R) < 0))[0]
        if len(rows):
            _pose(T[int(rows[0])], f"object '{ids[int(rows[0])]}'")
        if np.abs(T[:, :3, 3]).max(initial=0.0) > LIMIT_EXTENT:
            raise ValueError(f"poses: a position is beyond {LIMIT_EXTENT:g} m")
        self._poses[idx] = T
        self.pose_version += 1

    def _find(self, id: str) -> int:
        k = self._index.get(id)
        if k is None:
            raise KeyError(f"object '{id}': not in this world (objects: "
                           f"{', '.join(self.ids) or 'none'})")
        return k

    # ------------------------------------------------------------------ read
    @property
    def ids(self) -> list[str]:
        return [o.id for o in self._objects]

    @property
    def n_groups(self) -> int:
        """Worlds of the batch: 1 + the largest group (1 without objects), at least
        :attr:`n_worlds` when a batch set it."""
        return max(1 + max((o.group for o in self._objects), default=0), self.n_worlds)

    def groups(self) -> np.ndarray:
        """(K,) int: each object's world in the batch."""
        return np.array([o.group for o in self._objects], np.int64)

    def __len__(self) -> int:
        return len(self._objects)

    def kind(self, id: str) -> str:
        return self._objects[self._find(id)].kind

    def spec(self, id: str) -> tuple[str, Any, Any]:
        """(kind, dims as given, mesh as given) of object ``id``."""
        o = self._objects[self._find(id)]
        return o.kind, o.dims, o.source

    def pose(self, id: str) -> np.ndarray:
        return self._poses[self._find(id)].copy()

    def poses(self) -> np.ndarray:
        """(K, 4, 4) every object's pose, in the order of :attr:`ids` (a copy)."""
        return self._poses.copy()

    def specs(self) -> list[tuple[str, Any, Any]]:
        """``(kind, dims as given, mesh as given)`` of every object, in the order of
        :attr:`ids` (:meth:`spec` of each)."""
        return [(o.kind, o.dims, o.source) for o in self._objects]

    def bounds(self) -> np.ndarray:
        """(K, 3, 2) [m] world bounding boxes (planes: infinite)."""
        K = len(self._objects)
        out = np.empty((K, 3, 2))
        if K == 0:
            return out
        half = np.stack([o.half for o in self._objects])
        cen = np.stack([o.centre for o in self._objects])
        R = self._poses[:, :3, :3]
        c = np.einsum("nij,nj->ni", R, cen) + self._poses[:, :3, 3]
        e = np.einsum("nij,nj->ni", np.abs(R), half)
        out[:, :, 0], out[:, :, 1] = c - e, c + e
        planes = np.array([o.kind == "plane" for o in self._objects])
        out[planes, :, 0], out[planes, :, 1] = -np.inf, np.inf
        return out

    def distance(self, points: ArrayLike) -> np.ndarray:
        """Exact signed distance [m] of ``points`` (..., 3) to the union (numpy, float64,
        through the float64 kernel on Warp's default device); +inf without objects."""
        from jwarp.core.arrays import real_array

        p = real_array(points, "points")
        if p.ndim < 1 or p.shape[-1] != 3:
            raise ValueError(f"points: expected shape (..., 3), got {p.shape}")
        if not np.all(np.isfinite(p)):
            bad = np.argwhere(~np.isfinite(p.reshape(-1, 3)).all(axis=-1))[0, 0]
            at = np.unravel_index(int(bad), p.shape[:-1]) if p.ndim > 1 else ()
            raise ValueError(f"points: point {list(map(int, at))} contains NaN or inf (a "
                             f"distance of an unknown point is no answer)")
        init_warp()
        flat = np.ascontiguousarray(p.reshape(-1, 3))
        if len(self) == 0:
            return np.full(p.shape[:-1], np.inf)
        k = gk.kernels(wp.float64)
        dev = resolve_device(None)
        ds = self.device_shapes(dev, wp.float64)
        n = len(flat)
        d = wp.empty(n, dtype=wp.float64, device=dev)
        g = wp.empty(n, dtype=k.vec3, device=dev)
        o = wp.empty(n, dtype=wp.int32, device=dev)
        wp.launch(k.distance, dim=n, inputs=[ds.struct, wp.array(flat, dtype=k.vec3, device=dev),
                                             1e30], outputs=[d, g, o], device=dev)
        return d.numpy().reshape(p.shape[:-1])

    # ---------------------------------------------------------------- device
    def device_shapes(self, device: wp.Device, scalar: type) -> DeviceShapes:
        """The device copy for (device, scalar type), brought up to date."""
        key = (str(device), scalar.__name__)
        ds = self._device.get(key)
        if ds is None or ds.structure_version != self.structure_version:
            ds = self._device[key] = DeviceShapes(self, resolve_device(device), scalar)
        elif ds.pose_version != self.pose_version:
            ds.update_poses(self)
        return ds


class DeviceShapes:
    """The device arrays of a :class:`ShapeSet` (one device, one float type) and the
    kernel struct :attr:`struct` (``WorldShapes``); the struct is replaced when objects
    are added or removed (``structure_version``), updated in place when they move."""

    def __init__(self, shapes: ShapeSet, device: wp.Device, scalar: type) -> None:
        init_warp()
        self.device, self.scalar = device, scalar
        k = gk.kernels(scalar)
        objs = shapes._objects
        K = len(objs)
        kinds = np.array([KINDS.index(o.kind) for o in objs], np.int32)
        self.meshes = []  # keep the wp.Mesh objects alive
        mesh_ids = np.zeros(K, np.uint64)
        for i, o in enumerate(objs):
            if o.kind == "mesh":
                v, f = o.mesh
                m = wp.Mesh(points=wp.array(v.astype(np.float32), dtype=wp.vec3, device=device),
                            indices=wp.array(f.reshape(-1), dtype=wp.int32, device=device),
                            support_winding_number=True)
                self.meshes.append(m)
                mesh_ids[i] = m.id
        npdt = np.float64 if scalar == wp.float64 else np.float32
        s = k.WorldShapes()
        s.kind = wp.array(kinds, dtype=wp.int32, device=device)
        s.size = wp.array(np.stack([o.size for o in objs]).astype(npdt) if K else
                          np.zeros((0, 3), npdt), dtype=k.vec3, device=device)
        s.centre = wp.array(np.stack([o.centre for o in objs]).astype(npdt) if K else
                            np.zeros((0, 3), npdt), dtype=k.vec3, device=device)
        s.mesh = wp.array(mesh_ids, dtype=wp.uint64, device=device)
        s.rot = wp.zeros(K, dtype=k.mat33, device=device)
        s.pos = wp.zeros(K, dtype=k.vec3, device=device)
        planes = np.nonzero(kinds == KINDS.index("plane"))[0].astype(np.int32)
        s.planes = wp.array(planes, dtype=wp.int32, device=device)
        self._npdt = npdt
        self._in_bvh = kinds != KINDS.index("plane")
        self.bvh = None
        self.struct = s
        self.structure_version = shapes.structure_version
        groups = shapes.groups().astype(np.int32)
        n_groups = shapes.n_groups
        s.group = wp.array(groups, dtype=wp.int32, device=device)
        s.use_groups = int(n_groups > 1)
        self._write_poses(shapes)
        roots = np.full(n_groups, -2, np.int32)  # -2: no object of that world in the BVH
        if self._in_bvh.any():
            lo, hi = self._boxes(shapes)
            self._lo: wp.array = wp.array(lo, dtype=wp.vec3, device=device)
            self._hi: wp.array = wp.array(hi, dtype=wp.vec3, device=device)
            if n_groups > 1:
                self._groups: wp.array = wp.array(groups, dtype=wp.int32, device=device)
                self.bvh = wp.Bvh(self._lo, self._hi, groups=self._groups)
            else:
                self.bvh = wp.Bvh(self._lo, self._hi)
            s.bvh = self.bvh.id
            s.use_bvh = 1
            if n_groups > 1:
                r = wp.empty(n_groups, dtype=wp.int32, device=device)
                wp.launch(k.group_roots, dim=n_groups, inputs=[self.bvh.id], outputs=[r],
                          device=device)
                has = np.zeros(n_groups, bool)
                has[groups[self._in_bvh]] = True
                roots = np.where(has, r.numpy(), -2).astype(np.int32)
        else:
            s.bvh = 0
            s.use_bvh = 0
        s.group_root = wp.array(roots, dtype=wp.int32, device=device)
        self.pose_version = shapes.pose_version

    def _write_poses(self, shapes: ShapeSet) -> None:
        P = shapes._poses
        self.struct.rot.assign(np.ascontiguousarray(P[:, :3, :3], self._npdt))
        self.struct.pos.assign(np.ascontiguousarray(P[:, :3, 3], self._npdt))

    def _boxes(self, shapes: ShapeSet) -> tuple[np.ndarray, np.ndarray]:
        """float32 world boxes of the objects in the BVH (planes: a point at the origin,
        never queried since they are not in the BVH's index order... they are kept as
        degenerate boxes far away so indices stay object indices)."""
        b = shapes.bounds()
        lo = b[:, :, 0].astype(np.float32)
        hi = b[:, :, 1].astype(np.float32)
        # round outwards: the float32 box must contain the float64 one
        lo = np.nextafter(lo, np.float32(-np.inf))
        hi = np.nextafter(hi, np.float32(np.inf))
        far = np.float32(1e30)
        lo[~self._in_bvh] = far
        hi[~self._in_bvh] = far
        return np.ascontiguousarray(lo), np.ascontiguousarray(hi)

    def update_poses(self, shapes: ShapeSet) -> None:
        """Moved objects: new pose arrays and a refit of the BVH (no rebuild)."""
        self._write_poses(shapes)
        if self.bvh is not None:
            lo, hi = self._boxes(shapes)
            self._lo.assign(lo)
            self._hi.assign(hi)
            self.bvh.refit()
        self.pose_version = shapes.pose_version
