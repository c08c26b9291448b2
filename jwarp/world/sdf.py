"""Signed distance fields on regular grids: the :class:`World` and its constructors.

Grid convention (used everywhere in jwarp):

* ``sdf[i, j(, k)]`` is the distance [m] at the cell centre
  ``limits[:, 0] + voxel_size * (i, j(, k))``; ``limits`` (dim, 2) holds the first and the
  last cell centre per axis, so ``limits[:, 1] = limits[:, 0] + (shape - 1) * voxel_size``.
* Negative inside obstacles, positive in free space, in metres.
* Between cell centres the field is interpolated (bi/trilinear, see
  :mod:`jwarp.kernels.collision`); outside the grid box the world is free: the distance
  is that at the nearest point of the box plus the distance to that point.

SDF from an occupancy grid (:func:`world_from_occupancy`): an occupied cell is a solid
cube of side ``voxel_size``, so the obstacle surface lies on the faces between occupied
and free cells. With scipy's exact Euclidean distance transform over cell centres,

* free cell:     ``D = min |c - c_occ| - voxel_size / 2``   (c_occ: occupied cell centres)
* occupied cell: ``D = -(min |c - c_free| - voxel_size / 2)``

which is the exact distance to the cube surface along grid axes and overestimates it by
at most ``(sqrt(dim) - 1) / 2`` voxels diagonally. Interpolation puts D = 0 on the
faces between occupied and free cells. A grid without any occupied (free) cell gets
``+`` (``-``) the length of the grid box diagonal plus one voxel everywhere.

File format ``jwarp.world`` version 1 (:func:`save_world`, :func:`load_world`; numpy
``.npz``, compressed, no pickles):

* ``format``     str  "jwarp.world"
* ``version``    int  1
* ``sdf``        (nx, ny[, nz]) float32/float64 [m], negative inside obstacles
* ``limits``     (dim, 2) float64 [m] first and last cell centre per axis
* ``voxel_size`` float64 [m]
* ``occupancy``  bool grid (optional)
* ``meta``       str  JSON object (optional)
"""

from __future__ import annotations

import json
import os
import zipfile
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, cast

import numpy as np
import warp as wp
from scipy import ndimage

from jwarp.core.arrays import finite_as, init_warp, real_array, resolve_device
from jwarp.core.device import scalar_type
from jwarp.core.types import ArrayLike, DeviceLike, DTypeLike, RobotLike
from jwarp.kernels import collision as ck
from jwarp.utils.atomic import AtomicFile

__all__ = ["FORMAT", "MAX_GRID_CELLS", "VERSION", "World", "check_grid_cells", "grid_geometry", "load_world", "save_world", "sdf_query",
           "world_from_occupancy", "world_from_mesh",
           "world_from_points"]

DEFAULT_CELLS = 64
_F32_MAX = float(np.finfo(np.float32).max)


@dataclass(eq=False)
class World:
    """Signed distance field on a regular 2D or 3D grid (see the module docstring).

    Attributes:
        sdf: (nx, ny) or (nx, ny, nz) float32/float64 [m], negative inside obstacles.
        limits: (dim, 2) [m] first and last cell centre per axis.
        voxel_size: cell size [m] (the same on every axis).
        occupancy: bool grid of the same shape when the world came from one, else None.
        meta: free-form description (generator, seed, ...), saved with the world.
    """

    sdf: np.ndarray | None
    limits: np.ndarray | None = None
    voxel_size: float | None = None
    occupancy: np.ndarray | None = None
    meta: dict = field(default_factory=dict)
    shapes: Any = None
    grid_error: float = 0.0

    def __post_init__(self) -> None:
        if self.shapes is not None:
            from jwarp.world.shapes import ShapeSet

            if not isinstance(self.shapes, ShapeSet):
                raise TypeError(f"shapes: expected a jwarp.world.shapes.ShapeSet, got "
                                f"{type(self.shapes).__name__}")
        try:
            ge = float(self.grid_error)
        except (TypeError, ValueError) as e:
            raise TypeError(f"grid_error: expected a number [m], got {self.grid_error!r}") from e
        if not (np.isfinite(ge) and ge >= 0):
            raise ValueError(f"grid_error: expected a finite number >= 0 [m], got {ge!r}")
        self.grid_error = ge
        if self.sdf is None:  # exact objects only
            from jwarp.world.shapes import ShapeSet

            if self.shapes is None:
                self.shapes = ShapeSet()
            if self.limits is not None or self.voxel_size is not None or \
                    self.occupancy is not None:
                raise ValueError("sdf: a world without a grid takes no limits, voxel_size or "
                                 "occupancy")
            if not isinstance(self.meta, dict):
                raise TypeError(f"meta: expected a dict, got {type(self.meta).__name__}")
            return
        sdf = np.asarray(self.sdf)
        if sdf.dtype not in (np.float32, np.float64):
            if not np.issubdtype(sdf.dtype, np.number) or np.issubdtype(sdf.dtype, np.complexfloating):
                raise TypeError(f"sdf: expected a float32/float64 array, got dtype {sdf.dtype}")
            sdf = sdf.astype(np.float64)
        if sdf.ndim not in (2, 3):
            raise ValueError(f"sdf: expected a 2D or 3D grid, got shape {sdf.shape}")
        if min(sdf.shape) < 2:
            raise ValueError(f"sdf: every grid size must be >= 2, got shape {sdf.shape}")
        if not np.all(np.isfinite(sdf)):
            raise ValueError("sdf: contains NaN or inf")
        if sdf.dtype == np.float64 and np.abs(sdf).max() > _F32_MAX:
            raise ValueError(f"sdf: values overflow float32 (largest magnitude {_F32_MAX:.3g}), "
                             f"the dtype of the collision kernels")
        self.sdf = np.ascontiguousarray(sdf)
        try:
            h = float(self.voxel_size)  # type: ignore[arg-type]  # None: TypeError, below
        except (TypeError, ValueError) as e:
            raise TypeError(f"voxel_size: expected a number, got {self.voxel_size!r}") from e
        if not np.isfinite(h) or h <= 0 or h > _F32_MAX:
            raise ValueError(f"voxel_size: expected a positive number [m] (finite in float32), "
                             f"got {self.voxel_size!r}")
        self.voxel_size = h
        try:
            lim = np.asarray(self.limits, dtype=np.float64)
        except (TypeError, ValueError) as e:
            raise TypeError(f"limits: expected ({sdf.ndim}, 2) numbers [m]: {e}") from e
        if lim.shape != (sdf.ndim, 2):
            raise ValueError(f"limits: expected shape ({sdf.ndim}, 2) for a {sdf.ndim}D grid, "
                             f"got {lim.shape}")
        if not np.all(np.isfinite(lim)):
            raise ValueError("limits: contains NaN or inf")
        if np.abs(lim).max() > _F32_MAX:
            raise ValueError(f"limits: values overflow float32 (largest magnitude "
                             f"{_F32_MAX:.3g}), the dtype of the collision kernels")
        expect = lim[:, 0] + (np.array(sdf.shape) - 1) * h
        if not np.allclose(lim[:, 1], expect, rtol=0.0, atol=1e-6 * h + 1e-9):
            raise ValueError(f"limits: upper cell centres {lim[:, 1].tolist()} do not match "
                             f"lower + (shape - 1) * voxel_size = {expect.tolist()}")
        self.limits = lim
        if self.occupancy is not None:
            occ = np.asarray(self.occupancy)
            if occ.shape != sdf.shape:
                raise ValueError(f"occupancy: shape {occ.shape} does not match sdf {sdf.shape}")
            if occ.dtype != bool:
                raise TypeError(f"occupancy: expected a bool array, got dtype {occ.dtype}")
            self.occupancy = occ
        if not isinstance(self.meta, dict):
            raise TypeError(f"meta: expected a dict, got {type(self.meta).__name__}")

    # ------------------------------------------------------------------ sizes
    @classmethod
    def of_shapes(cls, shapes: Any = None, meta: dict | None = None) -> World:
        """A 3D world of exact objects only (a :class:`jwarp.world.shapes.ShapeSet`; None:
        empty, fill it with :meth:`add`)."""
        return cls(None, shapes=shapes, meta=dict(meta or {}))

    @classmethod
    def batch(cls, worlds: Sequence[World]) -> World:
        """One world holding a batch of worlds of exact objects, world i's objects as group
        i (ids ``"<i>/<id>"``): a :class:`jwarp.solvers.planning.Planner` with one problem
        per world plans each problem in its own world in one batch."""
        from jwarp.world.shapes import ShapeSet

        ws = list(worlds)
        if not ws:
            raise ValueError("worlds: expected at least one world")
        out = ShapeSet()
        for i, w in enumerate(ws):
            if not isinstance(w, World):
                raise TypeError(f"worlds[{i}]: expected a World, got {type(w).__name__}")
            if w.sdf is not None:
                raise ValueError(f"worlds[{i}]: a batch takes worlds of exact objects only "
                                 f"(this one has a grid)")
            if w.shapes is None:
                continue
            for oid in w.shapes.ids:
                kind, dims, mesh = w.shapes.spec(oid)
                out.add(f"{i}/{oid}", kind, [] if dims is None else dims, w.shapes.pose(oid),
                        mesh=mesh, group=i)
        out.n_worlds = len(ws)
        return cls.of_shapes(out, {"n_worlds": len(ws)})

    def content_hash(self) -> str:
        """SHA-256 (hex) of the grid's content: shape, limits, voxel size and the occupancy
        (or, without one, the SDF as float32). Equal grids give equal hashes whatever their
        meta; datasets use it to refuse duplicate worlds and to split by world. The exact
        objects (``shapes``) are not part of it; a world without a grid raises ValueError."""
        import hashlib

        if self.sdf is None:
            raise ValueError("world: has no grid (exact objects only): no content hash")
        sdf = np.asarray(self.sdf)
        h = hashlib.sha256()
        h.update(json.dumps([list(map(int, sdf.shape)), float(cast(float, self.voxel_size))]).encode())
        h.update(np.ascontiguousarray(np.asarray(self.limits, np.float64)).tobytes())
        if self.occupancy is not None:
            h.update(b"occ")
            h.update(np.packbits(np.asarray(self.occupancy, bool).ravel()).tobytes())
        else:
            h.update(b"sdf")
            h.update(np.ascontiguousarray(sdf, np.float32).tobytes())
        return h.hexdigest()

    @property
    def n_worlds(self) -> int:
        """Worlds of a batch (:meth:`batch`); 1 for a single world."""
        return int(self.meta.get("n_worlds", 1)) if self.sdf is None else 1

    def select(self, i: int) -> World:
        """World ``i`` (an integer) of a batch as a world of its own (a copy of its
        objects); a single world is its own world ``i`` for any ``i``."""
        from jwarp.world.shapes import ShapeSet

        if isinstance(i, (bool, np.bool_)) or not isinstance(i, (int, np.integer)):
            raise TypeError(f"i: expected an integer index of a world of the batch, got {i!r}")
        if self.n_worlds == 1:  # one world serves every problem
            return self
        if not 0 <= int(i) < self.n_worlds:
            raise ValueError(f"i: expected a world of the batch in [0, {self.n_worlds}), got {i}")
        out = ShapeSet()
        groups = self.shapes.groups()
        for oid, g in zip(self.shapes.ids, groups):
            if g == i:
                kind, dims, mesh = self.shapes.spec(oid)
                out.add(oid.split("/", 1)[1], kind, [] if dims is None else dims,
                        self.shapes.pose(oid), mesh=mesh)
        return World.of_shapes(out, {"batch_of": self.n_worlds, "index": int(i)})

    @property
    def has_grid(self) -> bool:
        """Whether the world holds a signed distance grid."""
        return self.sdf is not None

    @property
    def resolution(self) -> float:
        """The length [m] below which the world's distances are not resolved: the voxel
        size of a grid, 0.02 m for exact objects only (the planner's default smoothing
        width and its initial substep sizing use it)."""
        return float(cast(float, self.voxel_size)) if self.sdf is not None else 0.02

    def add(self, id: str, kind: str, dims: ArrayLike = (), pose: ArrayLike | None = None, *,
            mesh: Any = None) -> int:
        """Add an exact object (:meth:`jwarp.world.shapes.ShapeSet.add`)."""
        self._require_3d("add")
        if self.shapes is None:
            from jwarp.world.shapes import ShapeSet

            self.shapes = ShapeSet()
        return self.shapes.add(id, kind, dims, pose, mesh=mesh)

    def remove(self, id: str) -> None:
        """Remove exact object ``id``."""
        if self.shapes is None:
            raise KeyError(f"object '{id}': this world has no objects")
        self.shapes.remove(id)

    def move(self, ids: str | Sequence[str], poses: ArrayLike) -> None:
        """Move exact objects in place (:meth:`jwarp.world.shapes.ShapeSet.move`)."""
        if self.shapes is None:
            raise KeyError(f"objects {ids!r}: this world has no objects")
        self.shapes.move(ids, poses)

    def attach(self, id: str, robot: RobotLike, frame: int | str, q: ArrayLike, *,
               max_spheres: int = 32) -> Any:
        """Attach exact object ``id`` to ``frame`` of ``robot`` at its configuration ``q``
        (n_dof,): the object leaves the world and the returned robot (a copy) carries
        spheres covering it (:mod:`jwarp.world.attach`), so planning and IK with that
        robot move it with the frame. :meth:`detach` puts it back."""
        from jwarp.kinematics.fk import fk
        from jwarp.plugins.registry import robot as get_robot
        from jwarp.world.attach import Attachment, attach_object, sphere_table

        model = get_robot(robot)
        fi = model.frame_index(frame)
        if self.shapes is None or id not in self.shapes.ids:
            raise KeyError(f"object '{id}': not in this world (objects: "
                           f"{', '.join(self.object_ids) or 'none'})")
        kind, dims, mesh = self.shapes.spec(id)
        if kind == "plane":
            raise ValueError(f"object '{id}': a plane cannot be attached")
        T = np.asarray(fk(model, np.asarray(q, np.float64).reshape(1, -1),
                          dtype=np.float64))[0, fi]
        rel = np.linalg.inv(T) @ self.shapes.pose(id)
        carried, rng = attach_object(model, fi, rel, kind, dims, mesh, max_spheres)
        self.shapes.remove(id)
        self.attached[id] = Attachment(id, kind, dims, mesh, fi, rel, rng,
                                       sphere_table(carried.spheres[rng[0]:rng[1]]))
        return carried

    def detach(self, id: str, robot: RobotLike, q: ArrayLike) -> Any:
        """Put attached object ``id`` back into the world where ``robot`` (the one
        :meth:`attach` returned) holds it at ``q``; returns the robot without its spheres."""
        from jwarp.kinematics.fk import fk
        from jwarp.plugins.registry import robot as get_robot

        a = self.attached.get(id)
        if a is None:
            raise KeyError(f"object '{id}': not attached (attached: "
                           f"{', '.join(self.attached) or 'none'})")
        model = get_robot(robot)
        if not a.carried_by(model):
            raise ValueError(f"robot: not a robot that carries object '{id}' (its spheres "
                             f"{a.spheres[0]}..{a.spheres[1] - 1} are not the ones attach "
                             f"added); pass the robot attach returned (or one a later attach "
                             f"returned)")
        T = np.asarray(fk(model, np.asarray(q, np.float64).reshape(1, -1),
                          dtype=np.float64))[0, a.frame]
        self.add(id, a.kind, [] if a.dims is None else a.dims, T @ a.frame_T_object,
                 mesh=a.mesh)
        del self.attached[id]
        s0, s1 = a.spheres
        for b in self.attached.values():  # later attachments' spheres move down
            if b.spheres[0] >= s1:
                b.spheres = (b.spheres[0] - (s1 - s0), b.spheres[1] - (s1 - s0))
        spheres = list(model.spheres[:s0]) + list(model.spheres[s1:])
        name = model.name.removesuffix("+attached") if not self.attached else model.name
        return model.copy(spheres=spheres, name=name)

    @property
    def attached(self) -> dict:
        """Objects attached to a robot (:meth:`attach`), by id."""
        return self.__dict__.setdefault("_attached", {})

    @property
    def object_ids(self) -> list[str]:
        """Ids of the exact objects (index order of the kernels' object numbers)."""
        return [] if self.shapes is None else self.shapes.ids

    def object_name(self, k: int) -> str:
        """The name of what a kernel reported as object ``k`` (-2: the grid)."""
        if k == -2:
            return "grid"
        ids = self.object_ids
        return ids[k] if 0 <= k < len(ids) else "none"

    def _require_3d(self, what: str) -> None:
        if self.sdf is not None and self.sdf.ndim != 3:
            raise ValueError(f"{what}: exact objects need a 3D world, this grid is 2D")

    def _require_grid(self, what: str) -> None:
        if self.sdf is None:
            raise ValueError(f"{what}: this world has no grid (exact objects only)")

    @property
    def dim(self) -> int:
        """2 or 3."""
        return 3 if self.sdf is None else self.sdf.ndim

    @property
    def shape(self) -> tuple[int, ...]:
        self._require_grid("shape")
        return tuple(cast(np.ndarray, self.sdf).shape)

    @property
    def origin(self) -> np.ndarray:
        """(dim,) [m] centre of cell 0."""
        return cast(np.ndarray, self.limits)[:, 0].copy()

    @property
    def extent(self) -> np.ndarray:
        """(dim, 2) [m] outer faces of the grid's cells (limits -/+ half a voxel)."""
        return cast(np.ndarray, self.limits) + np.array([-0.5, 0.5]) * cast(float, self.voxel_size)

    def cell_centres(self) -> np.ndarray:
        """(*shape, dim) [m] coordinates of every cell centre."""
        lim, h = cast(np.ndarray, self.limits), cast(float, self.voxel_size)
        axes = [lim[d, 0] + h * np.arange(n) for d, n in enumerate(self.shape)]
        return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)

    def astype(self, dtype: DTypeLike) -> World:
        """The same world with the SDF stored as ``dtype`` (float32 or float64); exact
        objects are shared."""
        if self.sdf is None:
            return World(None, meta=dict(self.meta), shapes=self.shapes)
        return World(self.sdf.astype(dtype), cast(np.ndarray, self.limits).copy(), self.voxel_size,
                     None if self.occupancy is None else self.occupancy.copy(), dict(self.meta),
                     self.shapes, self.grid_error)

    # ----------------------------------------------------------------- queries
    def distance(self, points: ArrayLike, *, grad: bool = False,
                 device: DeviceLike = None) -> Any:
        """Signed distance [m] at ``points`` (..., dim) [m]: the grid's interpolated value
        (with the kernel the cost functions use; its spatial gradient (..., dim) if
        ``grad``), and with exact objects the minimum with their exact distances (float64;
        their gradient: :func:`jwarp.world.device_world.world_query`)."""
        has_objects = self.shapes is not None and len(self.shapes) > 0
        if self.sdf is None or has_objects:
            if grad:
                raise ValueError("grad: a world with exact objects gives its gradient through "
                                 "jwarp.world.device_world.world_query(world, points)")
            exact = self.shapes.distance(points)
            if self.sdf is None:
                return exact
            return np.minimum(sdf_query(self, points, device=device), exact)
        return sdf_query(self, points, grad=grad, device=device)

    # --------------------------------------------------------------------- I/O
    def save(self, path: str | os.PathLike) -> None:
        """Write the world as ``.npz`` atomically (format: module docstring)."""
        self._require_grid("save")
        if self.shapes is not None and len(self.shapes):
            raise ValueError("save: a world file holds a grid only; save the exact objects "
                             "as a scene file")
        save_world(self, path)

    @classmethod
    def load(cls, path: str | os.PathLike) -> World:
        """Read a world written by :meth:`save`; a malformed file raises ValueError."""
        return load_world(path)

    def __repr__(self) -> str:
        if self.sdf is None:
            return f"World(objects={self.object_ids}, meta={self.meta})"
        return (f"World(dim={self.dim}, shape={self.shape}, voxel_size={self.voxel_size:g} m, "
                f"limits={np.round(self.limits, 4).tolist()}, meta={self.meta})")


# ====================================================================== geometry
#: the most cells a grid may have (index arithmetic of the kernels is 32-bit)
MAX_GRID_CELLS = 2 ** 31


def check_grid_cells(counts: Any, argument: str, hint: str = "") -> None:
    """ValueError naming ``argument`` (e.g. ``"voxel_size: 1e-12 m"``) if a grid of
    ``counts`` cells per axis (floats: may be huge or inf) has more than
    :data:`MAX_GRID_CELLS` cells."""
    n = np.asarray(counts, dtype=np.float64)
    with np.errstate(over="ignore"):
        total = float(np.prod(n))
    if np.all(np.isfinite(n)) and total <= MAX_GRID_CELLS:
        return
    sizes = " x ".join(f"{v:.6g}" for v in n)
    raise ValueError(f"{argument} needs a grid of {sizes} = {total:.4g} cells, more than "
                     f"the 2**31 = {MAX_GRID_CELLS} cells a grid may have"
                     + (f"; {hint}" if hint else ""))


def grid_geometry(dim: int, *, shape: Sequence[int] | None = None, limits: Any = None,
                  voxel_size: float | None = None) -> tuple[tuple[int, ...], np.ndarray, float]:
    """Complete a grid from any of ``shape``, ``limits`` (dim, 2) [m] (first/last cell
    centre) or (dim,) [m] (first cell centre), and ``voxel_size`` [m].

    * shape + limits (dim, 2): voxel from the limits (must be the same on every axis);
    * limits (dim, 2) + voxel_size: shape = cells that fit (upper limit rounded down);
    * limits (dim,) + shape + voxel_size: box starting there;
    * shape + voxel_size: box centred on the origin;
    * shape alone: the longest side spans [-1, 1] m, centred on the origin;
    * nothing: ``64`` cells per axis over [-1, 1] m.

    Returns ``(shape, limits (dim, 2), voxel_size)``.
    """
    if shape is not None:
        try:
            s = tuple(int(v) for v in shape)
        except (TypeError, ValueError) as e:
            raise TypeError(f"shape: expected a sequence of integers, got {shape!r}") from e
        if len(s) != dim:
            raise ValueError(f"shape: expected {dim} grid sizes, got {s}")
        if min(s) < 2:
            raise ValueError(f"shape: every grid size must be >= 2, got {s}")
        check_grid_cells(s, "shape")
    else:
        s = None
    h = None
    if voxel_size is not None:
        try:
            h = float(voxel_size)
        except (TypeError, ValueError) as e:
            raise TypeError(f"voxel_size: expected a number, got {voxel_size!r}") from e
        if not np.isfinite(h) or h <= 0:
            raise ValueError(f"voxel_size: expected a positive number [m], got {voxel_size!r}")
    lim = None
    if limits is not None:
        lim = np.asarray(limits, dtype=np.float64)
        if lim.shape not in ((dim, 2), (dim,)):
            raise ValueError(f"limits: expected shape ({dim}, 2) or ({dim},), got {lim.shape}")
        if not np.all(np.isfinite(lim)):
            raise ValueError("limits: contains NaN or inf")
        if lim.ndim == 2 and np.any(lim[:, 1] <= lim[:, 0]):
            raise ValueError(f"limits: every upper limit must exceed the lower one, got {lim.tolist()}")
    if lim is not None and lim.ndim == 2:
        span = lim[:, 1] - lim[:, 0]
        if s is not None:
            hs = span / (np.array(s) - 1)
            if not np.allclose(hs, hs[0], rtol=1e-6):
                raise ValueError(f"limits: with shape {s} the voxel sizes per axis {hs.tolist()} "
                                 f"differ; the grid must be isotropic")
            if h is not None and not np.isclose(h, hs[0], rtol=1e-6):
                raise ValueError(f"voxel_size: {h} does not match limits and shape ({hs[0]})")
            return s, lim, float(hs[0])
        if h is None:
            h = float(span.max()) / (DEFAULT_CELLS - 1)
        with np.errstate(over="ignore"):
            nf = np.floor(span / h + 1e-6) + 1
        check_grid_cells(nf, f"voxel_size: {h:g} m over limits {lim.tolist()}",
                         "raise voxel_size or shrink the limits")
        n = nf.astype(np.int64)
        if np.any(n < 2):
            raise ValueError(f"voxel_size: {h} m leaves fewer than 2 cells on an axis of "
                             f"limits {lim.tolist()}")
        lim = np.stack([lim[:, 0], lim[:, 0] + (n - 1) * h], axis=1)
        return tuple(int(v) for v in n), lim, h
    if s is None:
        s = (DEFAULT_CELLS,) * dim
    if h is None:
        if lim is not None:
            raise ValueError("voxel_size: required when limits gives only the lower corner")
        h = 2.0 / (max(s) - 1)
    lower = lim if lim is not None else -0.5 * (np.array(s) - 1) * h
    lim = np.stack([lower, lower + (np.array(s) - 1) * h], axis=1)
    return s, lim, h


def _box_geometry(limits: Any, voxel_size: Any, shape: tuple[int, ...]) -> tuple[np.ndarray, float]:
    """limits (dim, 2) and voxel_size of a grid of known ``shape``."""
    _, lim, h = grid_geometry(len(shape), shape=shape, limits=limits, voxel_size=voxel_size)
    return lim, h


# ================================================================ constructors
def world_from_occupancy(occupancy: Any, limits: Any, voxel_size: float | None = None, *,
                         dtype: DTypeLike = np.float64) -> World:
    """Signed distance field of a boolean occupancy grid (module docstring convention).

    Args:
        occupancy: (nx, ny) or (nx, ny, nz) bool (or 0/1 integer) grid, True = obstacle.
        limits: (dim, 2) [m] first/last cell centre, or (dim,) first cell centre.
        voxel_size: [m]; may be omitted when ``limits`` is (dim, 2).
        dtype: float32 or float64 of the SDF.
    """
    occ = np.asarray(occupancy)
    if occ.dtype != bool:
        if not np.issubdtype(occ.dtype, np.integer) or not np.isin(occ, (0, 1)).all():
            raise TypeError(f"occupancy: expected a bool (or 0/1 integer) grid, got dtype {occ.dtype}")
        occ = occ.astype(bool)
    if occ.ndim not in (2, 3) or min(occ.shape) < 2:
        raise ValueError(f"occupancy: expected a 2D or 3D grid with sizes >= 2, got shape {occ.shape}")
    lim, h = _box_geometry(limits, voxel_size, occ.shape)
    if dtype not in (np.float32, np.float64, "float32", "float64"):
        raise TypeError(f"dtype: expected float32 or float64, got {dtype!r}")
    if not occ.any() or occ.all():
        big = float(np.linalg.norm(lim[:, 1] - lim[:, 0])) + h
        sdf = np.full(occ.shape, big if not occ.any() else -big)
    else:
        d_free = ndimage.distance_transform_edt(~occ, sampling=h)  # free cells -> nearest occupied
        d_occ = ndimage.distance_transform_edt(occ, sampling=h)    # occupied -> nearest free
        sdf = np.where(occ, -(d_occ - 0.5 * h), d_free - 0.5 * h)
    return World(sdf.astype(dtype), lim, h, occ.copy(), {"source": "occupancy"})


def world_from_points(points: ArrayLike, limits: Any, voxel_size: float | None = None, *,
                      shape: Sequence[int] | None = None, dtype: DTypeLike = np.float64) -> World:
    """World from a point cloud on obstacle surfaces (e.g. a depth camera).

    Each point marks the cell whose centre is nearest as occupied; the SDF follows as for
    :func:`world_from_occupancy`. Points outside the grid are dropped (their count is in
    ``meta["points_outside"]``).

    Args:
        points: (M, dim) [m].
        limits, voxel_size, shape: the grid, see :func:`grid_geometry`.
    """
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] not in (2, 3) or p.shape[0] == 0:
        raise ValueError(f"points: expected shape (M, 2) or (M, 3) with M >= 1, got {p.shape}")
    if not np.all(np.isfinite(p)):
        raise ValueError("points: contains NaN or inf")
    dim = p.shape[1]
    s, lim, h = grid_geometry(dim, shape=shape, limits=limits, voxel_size=voxel_size)
    idx = np.rint((p - lim[:, 0]) / h).astype(np.int64)
    inside = np.all((idx >= 0) & (idx < np.array(s)), axis=1)
    occ = np.zeros(s, bool)
    occ[tuple(idx[inside].T)] = True
    world = world_from_occupancy(occ, lim, h, dtype=dtype)
    world.meta.update(source="points", points=int(len(p)), points_outside=int((~inside).sum()))
    return world


def world_from_mesh(mesh: Any, limits: Any, voxel_size: float | None = None, *,
                    shape: Sequence[int] | None = None, device: DeviceLike = None,
                    dtype: DTypeLike = np.float64) -> World:
    """World from a closed triangle mesh: exact distance of every cell centre to the mesh
    surface, negative inside (ray-casting parity), via Warp's BVH mesh queries.

    Args:
        mesh: watertight ``trimesh.Trimesh`` (or a ``(vertices (V, 3), faces (F, 3))``
            pair) [m]; several closed bodies may be concatenated into one mesh.
        limits, voxel_size, shape: the 3D grid, see :func:`grid_geometry`.
        device: Warp device of the queries.

    The distances are computed in float32 (Warp meshes are float32): about 1e-7 relative
    to the grid size. ``occupancy`` is ``sdf < 0``.
    """
    import warp as wp

    from jwarp.core.arrays import init_warp, resolve_device
    from jwarp.kernels.collision import mesh_sdf_kernel
    from jwarp.world.shapes import mesh_arrays

    v, f = mesh_arrays(mesh, "mesh")
    if len(v) < 3:
        raise ValueError(f"mesh: vertices must have shape (V >= 3, 3), got {v.shape}")
    import trimesh

    if not trimesh.Trimesh(v, f, process=True).is_watertight:
        raise ValueError("mesh: not watertight (closed), so its inside is undefined")
    s, lim, h = grid_geometry(3, shape=shape, limits=limits, voxel_size=voxel_size)
    init_warp()
    dev = resolve_device(device)
    wmesh = wp.Mesh(points=wp.array(v.astype(np.float32), dtype=wp.vec3, device=dev),
                    indices=wp.array(f.astype(np.int32).reshape(-1), dtype=wp.int32, device=dev))
    out = wp.empty(s, dtype=wp.float32, device=dev)
    max_dist = float(np.linalg.norm(lim[:, 1] - lim[:, 0]) + np.abs(v - lim.mean(1)).max() * 2 + 1.0)
    wp.launch(mesh_sdf_kernel, dim=s, inputs=[wmesh.id, wp.vec3(*lim[:, 0]), float(h), max_dist],
              outputs=[out], device=dev)
    sdf = out.numpy().astype(dtype)
    return World(sdf, lim, h, sdf < 0, {"source": "mesh", "faces": int(len(f))})


FORMAT = "jwarp.world"
VERSION = 1


def save_world(world: World, path: str | os.PathLike) -> None:
    """Write ``world`` to ``path`` (.npz) via a temporary file in the same folder and a
    rename, so readers never see a partial file."""
    if not isinstance(world, World):
        raise TypeError(f"world: expected a World, got {type(world).__name__}")
    try:
        meta = json.dumps(world.meta)
    except (TypeError, ValueError) as e:
        raise ValueError(f"world.meta: not JSON serialisable: {e}") from e
    arrays: dict[str, Any] = dict(
        format=np.array(FORMAT), version=np.array(VERSION, np.int64), sdf=world.sdf,
        limits=world.limits, voxel_size=np.array(world.voxel_size, np.float64),
        meta=np.array(meta))
    if world.occupancy is not None:
        arrays["occupancy"] = world.occupancy
    with AtomicFile(path) as f, open(f.tmp, "wb") as fh:
        np.savez_compressed(fh, **arrays)
        fh.flush()
        os.fsync(fh.fileno())


def load_world(path: str | os.PathLike) -> World:
    """Read a world written by :func:`save_world`. Any malformed or unreadable file
    raises ValueError naming the file and the problem."""
    path = Path(path)
    if not path.exists():
        raise ValueError(f"path: world file '{path}' does not exist")
    if path.is_dir():
        raise ValueError(f"{path}: is a folder, not a .npz world file")
    try:
        with open(path, "rb") as fh:  # OSError if unreadable
            is_zip = zipfile.is_zipfile(fh)
        if not is_zip:  # np.load would try .npy and pickles next
            raise ValueError(f"{path}: not a readable .npz world file (not a zip archive, "
                             f"or truncated)")
        with np.load(path, allow_pickle=False) as z:
            data = {k: z[k] for k in z.files}
    except ValueError as e:
        if str(e).startswith(f"{path}: "):
            raise
        raise ValueError(f"{path}: not a readable .npz world file: {e}") from e
    except (OSError, EOFError, zipfile.BadZipFile, KeyError, MemoryError,
            NotImplementedError, RuntimeError) as e:
        raise ValueError(f"{path}: not a readable .npz world file: "
                         f"{' '.join(str(e).split()) or type(e).__name__}") from e
    if not isinstance(data, dict) or "format" not in data:
        raise ValueError(f"{path}: not a jwarp world file (no 'format' entry)")
    if str(data["format"]) != FORMAT:
        raise ValueError(f"{path}: format '{data['format']}' is not '{FORMAT}'")
    try:
        version = int(data.get("version", -1))
    except (TypeError, ValueError) as e:
        raise ValueError(f"{path}: malformed 'version'") from e
    if version != VERSION:
        raise ValueError(f"{path}: unsupported world file version {version} (expected {VERSION})")
    for key in ("sdf", "limits", "voxel_size"):
        if key not in data:
            raise ValueError(f"{path}: missing '{key}'")
    meta: dict = {}
    if "meta" in data:
        try:
            meta = json.loads(str(data["meta"]))
        except json.JSONDecodeError as e:
            raise ValueError(f"{path}: 'meta' is not valid JSON: {e}") from e
        if not isinstance(meta, dict):
            raise ValueError(f"{path}: 'meta' is not a JSON object")
    try:
        if data["voxel_size"].shape != ():
            raise ValueError(f"voxel_size: expected a scalar, got shape {data['voxel_size'].shape}")
        if data["sdf"].dtype not in (np.float32, np.float64):
            raise ValueError(f"sdf: expected float32 or float64, got {data['sdf'].dtype}")
        if data["voxel_size"].dtype.kind not in "iuf":
            raise ValueError(f"voxel_size: expected a number [m], got {data['voxel_size']!r}")
        return World(data["sdf"], data["limits"], float(data["voxel_size"]),
                     data.get("occupancy"), meta)
    except (TypeError, ValueError, OverflowError) as e:
        raise ValueError(f"{path}: {e}") from e


def sdf_query(world: World, points: ArrayLike, *, grad: bool = False, device: DeviceLike = None
              ) -> Any:
    """Interpolated signed distance [m] of ``world`` at ``points`` (..., dim) [m] (numpy),
    with the lookup of the cost kernels. Returns (...,) or, with ``grad``, a tuple
    ``(dist (...,), gradient (..., dim))``."""
    if not isinstance(world, World):
        raise TypeError(f"world: expected a jwarp.world.World, got {type(world).__name__}")
    p = real_array(points, "points")
    if p.ndim < 1 or p.shape[-1] != world.dim:
        raise ValueError(f"points: expected shape (..., {world.dim}) for a {world.dim}D world, "
                         f"got {p.shape}")
    if not np.all(np.isfinite(p)):
        raise ValueError("points: contains NaN or inf")
    init_warp()
    dev = resolve_device(device)
    sdf, limits = cast(np.ndarray, world.sdf), cast(np.ndarray, world.limits)
    dt = sdf.dtype
    scalar = scalar_type(dt)
    k = ck.kernels(scalar)
    lead = p.shape[:-1]
    flat = p.reshape(-1, world.dim)
    p3 = np.zeros((len(flat), 3), dt)
    p3[:, :world.dim] = finite_as(flat, dt, "points")
    grid = sdf if world.dim == 3 else sdf[:, :, None]
    o = np.zeros(3)
    o[:world.dim] = limits[:, 0]
    n = max(len(flat), 1)
    dist = wp.empty(n, dtype=scalar, device=dev)
    g = wp.empty(n, dtype=k.vec3, device=dev)
    if len(flat):
        wp.launch(k.sdf_query, dim=len(flat),
                  inputs=[wp.array(p3, dtype=k.vec3, device=dev),
                          wp.array(np.ascontiguousarray(grid), dtype=scalar, device=dev),
                          k.vec3(*o), 1.0 / cast(float, world.voxel_size), world.dim],
                  outputs=[dist, g], device=dev)
    d = dist.numpy()[:len(flat)].reshape(lead)
    if not grad:
        return d
    return d, g.numpy()[:len(flat), :world.dim].reshape(lead + (world.dim,))
