"""A :class:`jwarp.world.sdf.World` on a Warp device: the ``WorldModel`` struct of the
collision kernels (:mod:`jwarp.kernels.collision`), built in one place.

The grid part (its values, the per-cell minimum of the corners, origin, 1/voxel,
dimension and declared ``grid_error``) is copied once; the exact objects come from their
:class:`jwarp.world.shapes.ShapeSet`, whose device copy follows moves in place and is
rebuilt after adds/removes (:meth:`DeviceWorld.sync` returns whether the struct changed).
"""

from __future__ import annotations

from typing import Any, cast

import numpy as np
import warp as wp

from jwarp.core.device import numpy_dtype
from jwarp.core.types import ArrayLike, DeviceLike, DTypeLike
from jwarp.kernels import collision as ck
from jwarp.world.sdf import World

__all__ = ["DeviceWorld", "cell_minimum", "empty_shapes", "world_query"]


def cell_minimum(grid: np.ndarray) -> np.ndarray:
    """``out[i, j, k]`` = min of ``grid`` over the corners ``(i..i+1, j..j+1, k..k+1)``
    (last index clamped; size-1 axes use their single layer): a lower bound of the
    interpolated field in the cell spanned from (i, j, k)."""
    g = np.asarray(grid)
    out = g.copy()
    for axis in range(g.ndim):
        if g.shape[axis] > 1:
            nxt = np.concatenate([np.take(out, np.arange(1, g.shape[axis]), axis=axis),
                                  np.take(out, [g.shape[axis] - 1], axis=axis)], axis=axis)
            out = np.minimum(out, nxt)
    return np.ascontiguousarray(out)


_EMPTY: dict = {}
#: the dummy grid of worlds without one, per (device, type): (grid, cellmin, struct)
_NO_GRID: dict = {}


def empty_shapes(device: wp.Device, scalar: type) -> Any:
    """A ``WorldShapes`` struct with no objects (cached per device and type)."""
    key = (str(device), scalar.__name__)
    s = _EMPTY.get(key)
    if s is None:
        gk = ck.kernels(scalar).geometry
        s = gk.WorldShapes()
        s.kind = wp.zeros(0, dtype=wp.int32, device=device)
        s.rot = wp.zeros(0, dtype=gk.mat33, device=device)
        s.pos = wp.zeros(0, dtype=gk.vec3, device=device)
        s.size = wp.zeros(0, dtype=gk.vec3, device=device)
        s.centre = wp.zeros(0, dtype=gk.vec3, device=device)
        s.mesh = wp.zeros(0, dtype=wp.uint64, device=device)
        s.planes = wp.zeros(0, dtype=wp.int32, device=device)
        s.group = wp.zeros(0, dtype=wp.int32, device=device)
        s.group_root = wp.zeros(1, dtype=wp.int32, device=device)
        s.use_groups = 0
        s.bvh = 0
        s.use_bvh = 0
        _EMPTY[key] = s
    return s


class DeviceWorld:
    """``world`` (or None) on ``device`` in float type ``scalar``: :attr:`struct` is the
    ``WorldModel`` argument of the fused collision kernels."""

    def __init__(self, world: World | None, device: wp.Device, scalar: type) -> None:
        self.world, self.device, self.scalar = world, device, scalar
        self.k = ck.kernels(scalar)
        vec3 = self.k.vec3
        dt = numpy_dtype(scalar)
        use_grid = world is not None and world.sdf is not None
        if not use_grid:  # a dummy grid, never read: one per device and type
            key = (str(device), scalar.__name__)
            hit = _NO_GRID.get(key)
            if hit is None:
                hit = _NO_GRID[key] = self._grid(np.zeros((2, 2, 1), dt), vec3(0.0, 0.0, 0.0),
                                                 1.0, 3)
            self.grid, self.cellmin, self.grid_struct = hit
            self.origin, self.inv_h, self.dim = vec3(0.0, 0.0, 0.0), 1.0, 3
        else:
            assert world is not None  # use_grid; a grid comes with its limits and voxel size
            g = cast(np.ndarray, world.sdf).astype(dt)
            grid = g if world.dim == 3 else g[:, :, None]
            o = np.zeros(3)
            o[:world.dim] = cast(np.ndarray, world.limits)[:, 0]
            origin, inv_h, dim = vec3(*o), 1.0 / cast(float, world.voxel_size), world.dim
            self.origin, self.inv_h, self.dim = origin, inv_h, dim
            self.grid, self.cellmin, self.grid_struct = self._grid(grid, origin, inv_h, dim)
        gs = self.grid_struct
        ws = self.k.WorldModel()
        ws.grid = gs
        ws.use_grid = int(use_grid)
        ws.grid_error = scalar(world.grid_error if world is not None else 0.0)
        self.struct = ws
        self._shapes_key: tuple[Any, ...] | None = None
        self._bound_skip = False
        self.sync()

    def _grid(self, grid: np.ndarray, origin: Any, inv_h: float, dim: int) -> tuple:
        """``(grid, cellmin, WorldGrid struct)`` on the device."""
        sc, dev = self.scalar, self.device
        g: wp.array = wp.array(np.ascontiguousarray(grid), dtype=sc, device=dev)
        cm: wp.array = wp.array(cell_minimum(grid), dtype=sc, device=dev)
        gs = self.k.WorldGrid()
        gs.grid, gs.cellmin, gs.origin = g, cm, origin
        gs.inv_h, gs.dim = sc(inv_h), int(dim)
        return g, cm, gs

    @property
    def bound_skip(self) -> bool:
        """Whether the fused cost may skip the object queries of a frame whose bounding
        sphere keeps eps from every object: exact objects, none a mesh (a mesh's
        winding-number sign need not be 1-Lipschitz, the primitives' distances are)."""
        return self._bound_skip

    @property
    def has_objects(self) -> bool:
        w = self.world
        return w is not None and w.shapes is not None and len(w.shapes) > 0

    def sync(self) -> bool:
        """Bring the exact objects up to date; True if the struct was replaced (objects
        added or removed since the last call), False if unchanged or moved in place."""
        w = self.world
        ds = None
        if w is not None and w.shapes is not None and len(w.shapes) > 0:
            ds = w.shapes.device_shapes(self.device, self.scalar)
        if self._shapes_key is not None and ds is self._shapes_key[0]:
            return False
        self._shapes_key = (ds,)  # also keeps the device copy alive
        self._bound_skip = ds is not None and all(
            w.shapes.kind(i) != "mesh" for i in w.shapes.ids)  # type: ignore[union-attr]  # ds: w.shapes
        self.struct.shapes = ds.struct if ds is not None else empty_shapes(self.device,
                                                                          self.scalar)
        return True


def world_query(world: World, points: ArrayLike, *, cutoff: float = 1e30, device: DeviceLike = None,
                dtype: DTypeLike = np.float64) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Signed distance [m] of the whole world (grid lowered by its ``grid_error``, and
    exact objects) at ``points`` (N, 3): ``(dist (N,), grad (N, 3), obj (N,) int: object
    index, -2 grid, -1 nothing within cutoff)``, computed on ``device`` (None: the
    preferred one)."""
    from jwarp.core.arrays import init_warp, resolve_device
    from jwarp.core.device import scalar_type

    init_warp()
    dev = resolve_device(device)
    scalar = scalar_type(dtype)
    dw = DeviceWorld(world, dev, scalar)
    k = dw.k
    p = np.ascontiguousarray(np.asarray(points, numpy_dtype(scalar)).reshape(-1, 3))
    n = max(len(p), 1)
    d = wp.empty(n, dtype=scalar, device=dev)
    g = wp.empty(n, dtype=k.vec3, device=dev)
    o = wp.empty(n, dtype=wp.int32, device=dev)
    if len(p):
        wp.launch(k.world_query, dim=len(p), inputs=[dw.struct,
                                                     wp.array(p, dtype=k.vec3, device=dev),
                                                     float(cutoff)],
                  outputs=[d, g, o], device=dev)
    return d.numpy()[:len(p)], g.numpy()[:len(p)], o.numpy()[:len(p)]
