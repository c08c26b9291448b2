"""Basis point sets (BPS, thesis 3.4.1, eqs. 3.25-3.27): a world encoded as the signed
distances at a fixed set of points.

The points (eq. 3.25) lie on a hexagonal close packing (:func:`hcp_points`) inside a ball
around the robot's reach (:func:`basis_points`), so that every part of the workspace is
covered evenly (thesis Fig. 3.9). The feature vector of a world (eq. 3.27) is its SDF
looked up at the points, ``W_B = [D(b_1), ..., D(b_N)]`` [m], negative inside obstacles,
with the very lookup of the collision costs (:func:`jwarp.kernels.collision.kernels`'
``world_sample``: bi/trilinear inside the grid box, distance to the box added outside).

Packings (nearest-neighbour distance ``s``, a lattice point on the ball's centre):

* 2D hexagonal lattice: ``(i + j/2, j sqrt(3)/2) s``; one point per ``sqrt(3)/2 s^2``.
* 3D hexagonal close packing, ABAB layers ``sqrt(2/3) s`` apart: even layers the 2D
  lattice, odd layers shifted by ``(1/2, 1/(2 sqrt(3))) s``; one point per ``s^3 / sqrt(2)``.

Encoding (:func:`bps_encode`): one Warp launch over (worlds x points) for a whole batch;
the worlds travel as a Warp array of ``WorldGrid`` structs, each holding its own grid, so
worlds of any grid shapes share the launch. The grids are handed over per call (on the CPU
as zero-copy views of float32 ``World.sdf``; on CUDA as one upload of all grids); nothing is
cached. Float32 (the dtype of the collision kernels).
"""

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from types import SimpleNamespace
from typing import Any, cast

import numpy as np
import warp as wp

from jwarp.core.arrays import (
    init_warp,
    is_torch,
    real_array,
    real_number,
    resolve_device,
)
from jwarp.core.types import ArrayLike, DeviceLike, RobotLike
from jwarp.kernels import collision as ck
from jwarp.model import RobotModel
from jwarp.plugins.registry import robot as get_robot
from jwarp.utils.checks import check_int
from jwarp.world.feasibility import random_configurations
from jwarp.world.sdf import World

__all__ = ["BasisPointSet", "basis_points", "bps_encode", "hcp_density", "hcp_points", "kernels",
           "robot_reach_ball"]

#: relative tolerance of the ball test: points on the sphere count as inside
_EDGE = 1e-12


@functools.cache
def kernels() -> SimpleNamespace:
    """The encoding kernel (float32), built once (``jwarp warmup --families learn``)."""
    k = ck.kernels(wp.float32)
    WorldGrid = k.WorldGrid
    vec3 = k.vec3
    world_sample = k.world_sample

    @wp.kernel(module="unique", enable_backward=False)
    def bps_kernel(
        # Model:
        worlds: wp.array(dtype=WorldGrid),  # type: ignore[valid-type]
        points: wp.array(dtype=vec3),  # type: ignore[valid-type]
        # Data out:
        out: wp.array2d(dtype=wp.float32),  # type: ignore[valid-type]
    ):
        """out[w, p] = D_w(points[p]) [m] (the collision kernels' lookup)."""
        w, p = wp.tid()  # type: ignore[misc]
        d, g = world_sample(worlds[w], points[p])
        out[w, p] = d

    return SimpleNamespace(WorldGrid=WorldGrid, vec3=vec3, encode=bps_kernel)


# ===================================================================== packing
def hcp_density(dim: int, spacing: float) -> float:
    """Points per unit area (dim 2) or volume (dim 3) of the packing of :func:`hcp_points`:
    ``2 / (sqrt(3) s^2)`` and ``sqrt(2) / s^3``."""
    if dim == 2:
        return 2.0 / (math.sqrt(3.0) * spacing ** 2)
    if dim == 3:
        return math.sqrt(2.0) / spacing ** 3
    raise ValueError(f"dim: expected 2 or 3, got {dim!r}")


def _check_dim(dim: Any) -> int:
    if isinstance(dim, (bool, np.bool_)) or not isinstance(dim, (int, np.integer)):
        raise TypeError(f"dim: expected the integer 2 or 3, got {dim!r}")
    if dim not in (2, 3):
        raise ValueError(f"dim: expected 2 or 3, got {dim!r}")
    return int(dim)


def _positive(v: Any, name: str) -> float:
    f = real_number(v, name)
    if not (np.isfinite(f) and f > 0):
        raise ValueError(f"{name}: expected a positive finite length [m], got {v!r}")
    return f


def _centre(centre: Any, dim: int) -> np.ndarray:
    c = np.array(real_array(centre, "centre"), dtype=np.float64)
    if c.shape != (dim,):
        raise ValueError(f"centre: expected shape ({dim},), got {c.shape}")
    if not np.all(np.isfinite(c)):
        raise ValueError("centre: contains NaN or inf")
    return c


def hcp_points(dim: int, spacing: float, centre: Any, radius: float) -> np.ndarray:
    """Hexagonal lattice (dim 2) or hexagonal close packing (dim 3, ABAB layers) points with
    nearest-neighbour distance ``spacing`` [m] inside the ball (``centre`` (dim,), ``radius``)
    [m] (module docstring); a lattice point sits on the centre. Returns (N, dim) float64,
    ordered by layer, row, column; about ``hcp_density(dim, spacing)`` times the ball's
    volume of them."""
    dim = _check_dim(dim)
    s = _positive(spacing, "spacing")
    r = _positive(radius, "radius")
    c = _centre(centre, dim)
    if (r / s) ** dim > 1e8:
        raise ValueError(f"spacing: {s:g} m in a ball of radius {r:g} m gives more than "
                         f"~1e8 points")
    row = s * math.sqrt(3.0) / 2.0
    nj = int(math.ceil(r / row)) + 1
    if dim == 2:
        layers = [(0, 0.0, 0.0, 0.0)]
    else:
        dz = s * math.sqrt(2.0 / 3.0)
        nk = int(math.ceil(r / dz)) + 1
        layers = [(k, (k % 2) * s / 2.0, (k % 2) * s / (2.0 * math.sqrt(3.0)), k * dz)
                  for k in range(-nk, nk + 1)]
    out = []
    j = np.arange(-nj, nj + 1)
    lim = r * r * (1.0 + _EDGE)
    for _, ox, oy, z in layers:
        if abs(z) > r:
            continue
        ni = int(math.ceil(r / s)) + nj // 2 + 2
        i = np.arange(-ni, ni + 1)
        J, I = np.meshgrid(j, i, indexing="ij")
        x = (I + 0.5 * J) * s + ox
        y = J * row + oy
        keep = x * x + y * y + z * z <= lim
        pts = [x[keep], y[keep]] + ([np.full(int(keep.sum()), z)] if dim == 3 else [])
        out.append(np.stack(pts, axis=1))
    p = np.concatenate(out, axis=0) if out else np.zeros((0, dim))
    return p + c


# =============================================================== the point set
@dataclass(frozen=True)
class BasisPointSet:
    """A fixed set of basis points (eq. 3.25) and the packing it came from.

    Attributes:
        points: (N, dim) float64 [m], world coordinates.
        spacing: nearest-neighbour distance of the packing [m].
        centre: (dim,) [m] centre of the ball the points lie in.
        radius: radius of that ball [m].
    """

    points: np.ndarray
    spacing: float
    centre: np.ndarray
    radius: float

    def __post_init__(self) -> None:
        p = np.array(real_array(self.points, "points"), dtype=np.float64)
        if p.ndim != 2 or p.shape[1] not in (2, 3) or len(p) == 0:
            raise ValueError(f"points: expected shape (N >= 1, 2 or 3), got {p.shape}")
        if not np.all(np.isfinite(p)):
            raise ValueError("points: contains NaN or inf")
        p.setflags(write=False)
        c = _centre(self.centre, p.shape[1])
        c.setflags(write=False)
        object.__setattr__(self, "points", p)
        object.__setattr__(self, "centre", c)
        object.__setattr__(self, "spacing", _positive(self.spacing, "spacing"))
        object.__setattr__(self, "radius", _positive(self.radius, "radius"))

    @property
    def dim(self) -> int:
        """2 or 3."""
        return int(self.points.shape[1])

    @property
    def size(self) -> int:
        """Number of points N."""
        return int(self.points.shape[0])

    def encode(self, worlds: Any, *, device: DeviceLike = None, out: Any = None) -> Any:
        """``worlds``: one World or a sequence of Worlds (same dim) -> (W, N) SDF values [m]
        at the points (negative inside obstacles); see :func:`bps_encode`."""
        return bps_encode(worlds, self.points, device=device, out=out)

    def to_dict(self) -> dict:
        """JSON-able description (lists of floats); :meth:`from_dict` restores it exactly."""
        return {"format": "jwarp.bps", "version": 1, "dim": self.dim,
                "points": self.points.tolist(), "spacing": float(self.spacing),
                "centre": self.centre.tolist(), "radius": float(self.radius)}

    @classmethod
    def from_dict(cls, d: Any) -> "BasisPointSet":
        """The set written by :meth:`to_dict`; ValueError/TypeError naming a bad key."""
        if not isinstance(d, dict):
            raise TypeError(f"d: expected a dict, got {type(d).__name__}")
        if d.get("format", "jwarp.bps") != "jwarp.bps":
            raise ValueError(f"format: expected 'jwarp.bps', got {d.get('format')!r}")
        for key in ("points", "spacing", "centre", "radius"):
            if key not in d:
                raise ValueError(f"{key}: missing from the BPS dict")
        bps = cls(np.asarray(d["points"], dtype=np.float64), d["spacing"],
                  np.asarray(d["centre"], dtype=np.float64), d["radius"])
        if "dim" in d and d["dim"] != bps.dim:
            raise ValueError(f"dim: {d['dim']} does not match the points' {bps.dim}")
        return bps

    def __repr__(self) -> str:
        return (f"BasisPointSet(dim={self.dim}, size={self.size}, spacing={self.spacing:.4g} m, "
                f"centre={np.round(self.centre, 4).tolist()}, radius={self.radius:.4g} m)")

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, BasisPointSet):
            return NotImplemented
        return (self.spacing == other.spacing and self.radius == other.radius
                and np.array_equal(self.centre, other.centre)
                and np.array_equal(self.points, other.points))

    __hash__ = None  # type: ignore[assignment]


def robot_reach_ball(robot: RobotModel, n: int = 2000, seed: int = 0, device: DeviceLike = None
                     ) -> tuple[np.ndarray, float]:
    """``(centre (workspace_dim,), radius)`` [m]: the ball around the robot's base (origin of
    its root frame) holding every collision sphere (centre distance + radius) over ``n``
    random configurations (:func:`jwarp.world.feasibility.random_configurations`, ``seed``)."""
    from jwarp.kinematics.fk import fk

    model = robot
    f, pos, rad = model.sphere_arrays()
    if len(f) == 0:
        raise ValueError(f"robot: '{model.name}' has no collision spheres")
    d = model.workspace_dim
    q = random_configurations(model, n, seed)
    T = fk(model, q, device=device, dtype=np.float64)
    root = int(model.topological_order[0])
    centre = T[:, root, :d, 3].mean(axis=0)
    Ts = T[:, f]
    x = np.einsum("bsij,sj->bsi", Ts[..., :3, :3], pos) + Ts[..., :3, 3]
    r = np.linalg.norm(x[..., :d] - centre, axis=-1) + rad[None, :]
    return centre, float(r.max())


def basis_points(robot: RobotLike, n_points: int, *, margin: float = 0.0, device: DeviceLike = None
                 ) -> BasisPointSet:
    """Exactly ``n_points`` hcp points (:func:`hcp_points`, dim = ``robot.workspace_dim``) in
    the ball of the robot's reach (:func:`robot_reach_ball`: the base and the farthest
    collision sphere surface over 2000 random configurations) grown by ``margin`` [m].

    Rule: the count of :func:`hcp_points` is a step function of the spacing (whole symmetric
    shells of the lattice enter the ball at once), so the spacing is bisected (60 steps,
    from half and twice the estimate of the packing density) to the largest one whose ball
    holds at least ``n_points`` points, and of those the ``n_points`` nearest the centre are
    kept (ties in lattice order): only the outermost, partly filled shell is cut, which is
    under 3 % of the points for ``n_points`` >= 500 in 3D (>= 100 in 2D). The result is still
    a subset of one packing (nearest-neighbour distance ``spacing``) inside the ball.
    ``device``: where the FK of the reach runs."""
    check_int(n_points, "n_points", 1, 10_000_000)
    n_points = int(n_points)
    m = real_number(margin, "margin")
    if not (np.isfinite(m) and m >= 0):
        raise ValueError(f"margin: expected a finite distance >= 0 [m], got {margin!r}")
    model = get_robot(robot)
    dim = model.workspace_dim
    centre, radius = robot_reach_ball(model, device=device)
    radius += m
    vol = math.pi * radius ** 2 if dim == 2 else 4.0 / 3.0 * math.pi * radius ** 3
    est = (vol * hcp_density(dim, 1.0) / n_points) ** (1.0 / dim)
    lo, hi = 0.5 * est, 2.0 * est
    while len(hcp_points(dim, lo, centre, radius)) < n_points:  # count(lo) >= n_points
        lo *= 0.5
    while hi < 4.0 * radius and len(hcp_points(dim, hi, centre, radius)) >= n_points:
        lo, hi = hi, 2.0 * hi  # count(hi) < n_points (beyond 2 radius: the centre alone)
    for _ in range(60):
        s = 0.5 * (lo + hi)
        if len(hcp_points(dim, s, centre, radius)) >= n_points:
            lo = s
        else:
            hi = s
    p = hcp_points(dim, lo, centre, radius)
    order = np.argsort(np.linalg.norm(p - centre, axis=1), kind="stable")
    keep = np.sort(order[:n_points])
    return BasisPointSet(p[keep], lo, centre, radius)


# =================================================================== encoding
def _worlds(worlds: Any) -> list[World]:
    if isinstance(worlds, World):
        return [worlds]
    if isinstance(worlds, (str, bytes)) or not isinstance(worlds, Sequence):
        raise TypeError(f"worlds: expected a World or a sequence of Worlds, got "
                        f"{type(worlds).__name__}")
    out = list(worlds)
    if not out:
        raise ValueError("worlds: empty sequence")
    for i, w in enumerate(out):
        if not isinstance(w, World):
            raise TypeError(f"worlds[{i}]: expected a jwarp.world.World, got {type(w).__name__}")
    dims = {w.dim for w in out}
    if len(dims) > 1:
        raise ValueError(f"worlds: mixed dimensions {sorted(dims)}; one batch is all 2D or all 3D")
    return out


def _points(points: ArrayLike, dim: int) -> np.ndarray:
    if isinstance(points, BasisPointSet):
        points = points.points
    p = real_array(points, "points")
    if p.ndim != 2 or p.shape[0] == 0 or p.shape[1] != dim:
        raise ValueError(f"points: expected shape (N >= 1, {dim}) for {dim}D worlds, got {p.shape}")
    if not np.all(np.isfinite(p)):
        raise ValueError("points: contains NaN or inf")
    p3 = np.zeros((len(p), 3), np.float32)
    with np.errstate(over="ignore"):
        p3[:, :dim] = p
    if not np.all(np.isfinite(p3)):
        raise ValueError("points: values overflow float32")
    return p3


def _grid32(w: World) -> np.ndarray:
    sdf = cast(np.ndarray, w.sdf)  # a world with a grid
    g = sdf if sdf.dtype == np.float32 else sdf.astype(np.float32)
    return np.ascontiguousarray(g if w.dim == 3 else g[:, :, None])


def _world_structs(ws: list[World], dev: wp.Device, kn: SimpleNamespace) -> tuple[wp.array, list]:
    """The worlds as a Warp array of WorldGrid structs on ``dev``, and what keeps their grids
    alive until the launch is done."""
    grids = [_grid32(w) for w in ws]
    if dev.is_cpu:  # zero-copy views of the host grids
        arrays: list[wp.array] = [wp.array(g, dtype=wp.float32, device=dev, copy=False)
                                  for g in grids]
        keep: list = [grids, arrays]
    else:  # one upload of all grids, then views into it
        sizes = [g.size for g in grids]
        flat: wp.array = wp.array(np.concatenate([g.ravel() for g in grids]), dtype=wp.float32,
                                  device=dev)
        arrays, off = [], 0
        for g, n in zip(grids, sizes):
            arrays.append(wp.array(ptr=flat.ptr + 4 * off, shape=g.shape, dtype=wp.float32,
                                   device=dev))
            off += n
        keep = [flat, arrays]
    structs = []
    for w, a in zip(ws, arrays):
        s = kn.WorldGrid()
        s.grid = a
        s.cellmin = a  # not read by world_sample
        o = np.zeros(3)
        o[:w.dim] = cast(np.ndarray, w.limits)[:, 0]
        s.origin = kn.vec3(*o)
        s.inv_h = 1.0 / cast(float, w.voxel_size)
        s.dim = w.dim
        structs.append(s)
    return wp.array(structs, dtype=kn.WorldGrid, device=dev), keep


def _check_out(out: Any, shape: tuple[int, int], device: DeviceLike) -> tuple[wp.array, wp.Device]:
    if not is_torch(out):
        raise TypeError(f"out: expected a torch tensor, got {type(out).__name__}")
    import torch

    if out.dtype != torch.float32:
        raise TypeError(f"out: expected a float32 tensor, got {out.dtype}")
    if tuple(out.shape) != shape:
        raise ValueError(f"out: expected shape {shape} (worlds, points), got {tuple(out.shape)}")
    if not out.is_contiguous():
        raise ValueError("out: expected a contiguous tensor")
    if out.requires_grad:
        raise ValueError("out: must not require grad (it is written in place)")
    tdev = wp.device_from_torch(out.device)
    dev = resolve_device(device, like=out)
    if dev != tdev:
        raise ValueError(f"out: tensor on {tdev}, but device={device!r} ({dev})")
    return cast(wp.array, wp.from_torch(out, dtype=wp.float32)), dev


def bps_encode(worlds: Any, points: ArrayLike, *, device: DeviceLike = None, out: Any = None) -> Any:
    """The BPS feature vectors (eq. 3.27) of ``worlds`` (one World or a sequence of Worlds of
    one dim) at ``points`` ((N, dim) [m] or a :class:`BasisPointSet`): (W, N) signed
    distances [m], negative inside obstacles, float32, equal to
    :func:`jwarp.world.sdf_query` of each world at the points.

    Returns a numpy array, or, where ``out`` is a torch float32 tensor (W, N) (contiguous,
    CPU or CUDA), fills it in place (zero-copy, ``wp.from_torch``; on CUDA the launch goes
    on the current Warp stream of that device) and returns it. ``device``: where the kernel
    runs (default: that of ``out``, else Warp's preferred device); ValueError if it is not
    ``out``'s device."""
    ws = _worlds(worlds)
    p3 = _points(points, ws[0].dim)
    init_warp()
    shape = (len(ws), len(p3))
    if out is not None:
        dest, dev = _check_out(out, shape, device)
    else:
        dev = resolve_device(device)
        dest = wp.empty(shape, dtype=wp.float32, device=dev)
    kn = kernels()
    structs, keep = _world_structs(ws, dev, kn)
    wp.launch(kn.encode, dim=shape,
              inputs=[structs, wp.array(p3, dtype=kn.vec3, device=dev)],
              outputs=[dest], device=dev)
    if out is not None:
        # CUDA frees of the grids' buffer are stream-ordered (Warp's memory pool), so the
        # launch may still run when it is released here
        del keep
        return out
    res = dest.numpy()
    del keep
    return res
