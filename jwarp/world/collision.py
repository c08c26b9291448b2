"""Collision costs and distances of a sphere robot in a signed-distance world (host API).

Thesis eq. 3.8-3.12: the robot is a set of spheres fixed to its frames
(``RobotModel.sphere_arrays()``), the world a signed distance field
(:class:`jwarp.world.World`), and

* ``U_world(q) = sum_s c(D(x_s(q)) - r_s)``                    (eq. 3.8)
* ``U_self(q)  = sum_(a,b) c(|x_a(q) - x_b(q)| - r_a - r_b)``  (eq. 3.11)

over the sphere pairs whose frames may collide (``RobotModel.allowed_collision_pairs``;
pairs at a constant positive distance are left out, see :func:`rigid_pairs`),
with the smooth clip ``c`` of eq. 3.10 (``-d + eps/2`` below 0, ``(d - eps)^2 / (2 eps)``
up to ``eps``, 0 beyond): a configuration whose spheres all keep ``eps`` from the world
and from each other costs exactly 0. Path costs (eq. 3.9, 3.12) are sums of these over the
substep configurations: pass them flattened as one batch.

2D worlds: robots with ``workspace_dim == 2`` (planar4, planar5, sphere2d) move in the
x-y plane and use the x, y of their spheres; a world of the other dimension is an error.

Fast path for loops (a planner): build a :class:`CollisionModel` once and call
:meth:`CollisionModel.cost` with Warp arrays and a :class:`CollisionData` workspace (or
preallocated outputs); it launches one fused kernel (one thread per configuration, the
gradient by hand in the same launch) or, on CUDA for batches up to
:data:`WIDE_MAX_CONFIGS`, the four wide launches of :mod:`jwarp.kernels.collision_wide`,
and copies nothing to the host. :func:`collision_cost` wraps it for numpy / Warp /
torch input (same kind out).

Model vs Data: the robot's frame and sphere tables are its
:class:`jwarp.core.device.DeviceModel` (``put_model``, shared by every robot of equal
content); a :class:`CollisionModel` adds the world (its SDF on the device) and launches the
kernels. A :class:`CollisionData` holds every intermediate (FK frames, sphere centres,
forces and moments, bounding-sphere centres) and every output (cost, gradient, distances)
of one batch size, reused from call to call. DH rows are :class:`jwarp.core.rows.DHRows`.
"""

from __future__ import annotations

import os
from typing import Any, cast

import numpy as np
import warp as wp

from jwarp.core.arrays import (
    Batch,
    as_batch,
    default_dtype,
    finite_as,
    init_warp,
    real_array,
    real_number,
    resolve_device,
    to_output,
)
from jwarp.core.caches import IdentityCache
from jwarp.core.device import (
    DeviceModel,
    collision_tables,
    numpy_dtype,
    put_model,
    scalar_type,
)
from jwarp.core.rows import DHRows, RowsKind
from jwarp.core.types import ArrayLike, DeviceLike, DTypeLike
from jwarp.kernels import collision as ck
from jwarp.kernels import collision_wide as cwide
from jwarp.kernels.elastic import funcs as elastic_funcs
from jwarp.kernels.fk import kernels as fk_kernels
from jwarp.kinematics.compensation import CompensationRows
from jwarp.model import RobotModel
from jwarp.world.device_world import DeviceWorld
from jwarp.world.sdf import World, sdf_query

__all__ = ["DEFAULT_EPS", "CollisionModel", "CollisionData", "collision_model", "collision_cost",
           "collision_pairs", "rigid_pairs", "sphere_distances", "self_distances", "min_distances",
           "is_collision_free", "sdf_query", "check_world"]

#: default smoothing distance eps of the clip c (eq. 3.10) [m]
DEFAULT_EPS = 0.05
_FAR = 1e30
#: the cost's launch plan where a CollisionModel is not told (``wide=None``): the
#: environment variable ``JWARP_COST_KERNEL`` = ``fused`` (one thread per configuration),
#: ``wide`` (:mod:`jwarp.kernels.collision_wide`) or ``auto`` (the default)
COST_KERNELS = ("auto", "fused", "wide")
#: ``auto``: the wide launches on CUDA up to this many configurations per call. Measured on
#: an H200 (benchmarks/bench_cost_kernel.py, float32): at 400-20 000 configurations the
#: wide launches fill the GPU (1.3-3.3x faster per call); at 1e6 random configurations
#: they gain 1.04-1.2x, and a labelling run, whose ~1.2e6 configurations per call follow
#: smooth paths (coherent warps), ran 15 % slower with them.
WIDE_MAX_CONFIGS = 65536


def default_wide(device: DeviceLike, n: int) -> bool:
    """Whether :meth:`CollisionModel.cost` of ``n`` configurations runs the wide launches on
    ``device`` when the model is not told: ``JWARP_COST_KERNEL`` (``auto``: on CUDA up to
    :data:`WIDE_MAX_CONFIGS`; see :data:`COST_KERNELS`)."""
    v = os.environ.get("JWARP_COST_KERNEL", "auto").strip().lower() or "auto"
    if v not in COST_KERNELS:
        raise ValueError(f"JWARP_COST_KERNEL: expected one of {', '.join(COST_KERNELS)}, "
                         f"got {v!r}")
    return v == "wide" or (v == "auto" and bool(resolve_device(device).is_cuda)
                           and n <= WIDE_MAX_CONFIGS)


def check_world(robot: RobotModel, world: World | None) -> None:
    """ValueError unless ``world`` is None or has the robot's workspace dimension."""
    if world is None:
        return
    if not isinstance(world, World):
        raise TypeError(f"world: expected a jwarp.world.World, got {type(world).__name__}")
    if world.dim != robot.workspace_dim:
        raise ValueError(f"world: a {world.dim}D world does not fit robot '{robot.name}', which "
                         f"moves in {robot.workspace_dim}D (workspace_dim={robot.workspace_dim})")


def collision_pairs(robot: RobotModel) -> np.ndarray:
    """(P, 2) int32 sphere index pairs checked for self-collision, in kernel order:
    pairs of spheres whose frames are allowed to collide
    (``RobotModel.allowed_collision_pairs``), grouped by frame pair (sorted), the sphere on
    the lower frame index first, except the rigid pairs of :func:`rigid_pairs`."""
    return collision_tables(robot)["pairs"].copy()


def rigid_pairs(robot: RobotModel) -> tuple[np.ndarray, np.ndarray]:
    """Allowed sphere pairs left out of the self-collision check because their surface
    distance is the same in every configuration and positive: ``(pairs (R, 2) int32,
    distance (R,) [m])``. (A constant distance <= 0 stays in the check: such a pair
    always collides, which says the model or its allowed pairs are wrong.)"""
    rt = collision_tables(robot)
    return rt["rigid_pairs"].copy(), rt["rigid_distance"].copy()


class CollisionData:
    """The workspace of :meth:`CollisionModel.cost` and :meth:`CollisionModel.distances` for
    ``n`` configurations (the *Data*): scratch ``frames`` (n, n_frames) mat44, ``xs``
    (n, n_spheres) sphere centres, ``force``/``moment``/``bc`` (n, n_frames) vec3, and the
    outputs ``cost`` (n,), ``grad`` (n, n_dof), ``sphere_dist`` (n, n_spheres),
    ``pair_dist`` (n, n_pairs), ``min_dist`` (n, 2), each made on first use and reused by
    every later call (so the arrays a call returns are overwritten by the next call with
    the same data). Make it with :meth:`CollisionModel.make_data`; one data must not be
    used from two threads at once.

    Scratch layout: CUDA frame-major in memory (coalesced). CPU: Warp runs the
    configurations of a launch one after another, so every configuration reuses one row (a
    stride-0 view of a single row, which stays in L1) instead of streaming about 3 KB of
    scratch per configuration through the caches."""

    def __init__(self, cm: CollisionModel, n: int) -> None:
        n = int(n)
        if n < 1:
            raise ValueError(f"n: expected >= 1 configurations, got {n}")
        self.n = n
        self.device, self.scalar, self.n_dof = cm.device, cm.scalar, cm.robot.n_dof
        self.n_spheres, self.n_pairs = cm.n_spheres, cm.n_pairs
        self.key = cm.model.key  # the robot content these buffers are sized for
        k = fk_kernels(self.scalar)
        vec3 = cm.k.vec3
        nf, ns = cm.robot.n_frames, max(cm.n_spheres, 1)
        self._rows: list = []  # CPU: the single rows behind the stride-0 views
        self.frames = self._scratch(nf, k.mat44)
        self.xs = self._scratch(ns, vec3)
        self.force = self._scratch(nf, vec3)
        self.moment = self._scratch(nf, vec3)
        self.bc = self._scratch(nf, vec3)
        self._out: dict = {}
        self._wide: tuple | None = None

    def _scratch(self, m: int, dt: Any) -> wp.array:
        if self.device.is_cuda:
            return wp.empty((m, self.n), dtype=dt, device=self.device).transpose()
        row = wp.empty((1, m), dtype=dt, device=self.device)
        self._rows.append(row)  # owns the memory of the view
        return wp.array(ptr=row.ptr, shape=(self.n, m), strides=(0, row.strides[1]),
                        dtype=dt, device=self.device)

    @property
    def scratch(self) -> tuple[wp.array, ...]:
        """(frames, xs, force, moment, bc)."""
        return self.frames, self.xs, self.force, self.moment, self.bc

    @property
    def wide_scratch(self) -> tuple[wp.array, ...]:
        """(frames, xs, force, moment, bc) with a real row per configuration, as the wide
        launches need (they hand rows to each other): the scratch itself on CUDA, full
        arrays made on first use on the CPU."""
        if self.device.is_cuda:
            return self.scratch
        if self._wide is None:
            k = fk_kernels(self.scalar)
            vec3 = ck.kernels(self.scalar).vec3
            nf, ns = self.frames.shape[1], self.xs.shape[1]
            self._wide = tuple(wp.empty((self.n, m), dtype=dt, device=self.device)
                               for m, dt in ((nf, k.mat44), (ns, vec3), (nf, vec3), (nf, vec3),
                                             (nf, vec3)))
        return self._wide

    def output(self, name: str) -> wp.array:
        """The output ``name`` (cost, grad, sphere_dist, pair_dist, min_dist), made once."""
        a = self._out.get(name)
        if a is None:
            shape = {"cost": (self.n,), "grad": (self.n, self.n_dof),
                     "sphere_dist": (self.n, self.n_spheres), "pair_dist": (self.n, self.n_pairs),
                     "min_dist": (self.n, 2)}[name]
            a = self._out[name] = wp.empty(shape, dtype=self.scalar, device=self.device)
        return a

    cost = property(lambda self: self.output("cost"), doc="(n,) collision cost")
    grad = property(lambda self: self.output("grad"), doc="(n, n_dof) d cost / d q")
    sphere_dist = property(lambda self: self.output("sphere_dist"), doc="(n, n_spheres) [m]")
    pair_dist = property(lambda self: self.output("pair_dist"), doc="(n, n_pairs) [m]")
    min_dist = property(lambda self: self.output("min_dist"), doc="(n, 2) [m]")


class CollisionModel:
    """Device tables of one robot and one world (or none) for the collision kernels,
    with scratch buffers reused across calls (so one model must not be called from two
    threads at once).

    Args:
        robot: name or RobotModel.
        world: :class:`World` of the robot's workspace dimension, or None (self-collision only).
            Its SDF is copied to the device once: treat the world as immutable afterwards.
        device: Warp device (None: Warp's default device, docs/api.md "Devices").
        dtype: float32 (default) or float64.
        wide: run :meth:`cost` as the wide launches of :mod:`jwarp.kernels.collision_wide`
            (parallel over configuration x sphere and configuration x frame pair) instead
            of the fused one-thread-per-configuration kernel; None: per call,
            :func:`default_wide` (on CUDA for batches up to :data:`WIDE_MAX_CONFIGS`). The
            two agree to float rounding.
    """

    def __init__(self, robot: RobotModel, world: World | None = None, *, device: DeviceLike = None,
                 dtype: DTypeLike = np.float32, wide: bool | None = None) -> None:
        init_warp()
        self.robot = robot
        check_world(self.robot, world)
        self.world = world
        self.device = resolve_device(device)
        self.scalar = scalar_type(dtype)
        self.dtype = numpy_dtype(self.scalar)
        #: the robot's device model (frame, mass and sphere tables; shared by content)
        self.model: DeviceModel = put_model(self.robot, self.device, self.scalar)
        self.k = ck.kernels(self.scalar)
        if wide is not None and not isinstance(wide, (bool, np.bool_)):
            raise TypeError(f"wide: expected True, False or None, got {wide!r}")
        #: whether :meth:`cost` runs the wide launches (else the fused kernel); None: by
        #: the batch size (:func:`default_wide`)
        self.wide: bool | None = None if wide is None else bool(wide)
        sp = self.model.spheres
        dev = self.device
        self.n_spheres, self.n_pairs, self.pairs = sp.n_spheres, sp.n_pairs, sp.pairs
        #: the world on the device (grid + exact objects), one struct argument
        self.device_world = DeviceWorld(world, dev, self.scalar)
        dw = self.device_world
        self.grid, self.cellmin = dw.grid, dw.cellmin
        self.origin, self.inv_h, self.dim = dw.origin, dw.inv_h, dw.dim
        self._work: CollisionData | None = None  # scratch of calls without a data
        self._launches: dict = {}
        self._dummy = wp.empty((1, 1), dtype=self.scalar, device=dev)
        self._no_active = wp.ones(1, dtype=wp.int32, device=dev)
        self._no_update = elastic_funcs(self.scalar).CompensationArgs()  # enabled = 0

    # ------------------------------------------------------------ plumbing
    @property
    def world_struct(self) -> Any:
        """The world as the fused kernels' argument (exact objects brought up to date:
        moved objects in place, added/removed ones in a new struct)."""
        if self.device_world.sync():
            self._launches.clear()  # recorded launches hold the old struct
        return self.device_world.struct

    @property
    def model_args(self) -> list:
        """Frame and sphere tables in kernel argument order."""
        return [self.model.frame_struct, self.model.spheres.struct]

    def make_data(self, n: int) -> CollisionData:
        """A :class:`CollisionData` workspace for ``n`` configurations."""
        return CollisionData(self, n)

    def scratch(self, n: int) -> tuple[wp.array, ...]:
        """Scratch (frames, xs, force, moment, bc), shape (>= n, m) each, kept between calls
        without a data (the internal workspace, grown on demand)."""
        return self._workspace(n).scratch

    def _workspace(self, n: int) -> CollisionData:
        w = self._work
        if w is None or n > w.n:
            cap = max(n, int(w.n * 1.5) if w is not None else 1, 1)
            w = self._work = CollisionData(self, cap)
            self._launches.clear()
        return w

    def _data(self, data: CollisionData | None, n: int) -> CollisionData:
        """``data`` checked for n configurations on this model, or the internal workspace."""
        if data is None:
            return self._workspace(n)
        if not isinstance(data, CollisionData):
            raise TypeError(f"data: expected a CollisionData (CollisionModel.make_data), got "
                            f"{type(data).__name__}")
        if data.n != n or data.device != self.device or data.scalar != self.scalar \
                or data.key != self.model.key:
            raise ValueError(f"data: a workspace for {data.n} configurations on {data.device}, "
                             f"q has {n} on {self.device} (make it with make_data(n) of this "
                             f"model)")
        return data

    def _check_rows(self, rows: CompensationRows, n: int) -> None:
        if n != rows.N or rows.t.key != self.model.key or rows.rows.dtype != self.scalar \
                or rows.rows.device != self.device:
            raise ValueError(f"rho: compensation rows for {rows.N} configurations of "
                             f"'{rows.t.robot.name}' on {rows.rows.device}, expected {n} of "
                             f"'{self.robot.name}' on {self.device} in this dtype")

    def dh_rows(self, rho: Any, n: int, expand: bool = False) -> DHRows:
        """``rho`` as :class:`jwarp.core.rows.DHRows` for ``n`` configurations: None (the
        nominal rows), DH rows (n_frames, 5) or (n, n_frames, 5) (numpy, torch or Warp),
        :class:`DHRows`, or compensation rows
        (:class:`jwarp.kinematics.compensation.CompensationRows`, kept per waypoint;
        ``expand``: as their per-configuration 5-column rows, for kernels without a row
        layout)."""
        if rho is None:
            return self.model.nominal_rows
        nf = self.robot.n_frames
        if isinstance(rho, CompensationRows):
            self._check_rows(rho, n)
            if not expand:
                return rho.dh_rows
            rho = rho.rho()
        if isinstance(rho, DHRows):
            if expand and rho.kind == RowsKind.COMPENSATION:
                raise ValueError("rho: compensation DHRows need their CompensationRows here "
                                 "(expanded to per-configuration rows)")
            return rho.check(nf, n, self.scalar, self.device)
        if isinstance(rho, wp.array):
            if rho.dtype != self.scalar:
                raise TypeError(f"rho: warp array dtype {rho.dtype.__name__} does not match "
                                f"the kernels' {np.dtype(self.dtype).name}")
            if rho.ndim == 2 and tuple(rho.shape) == (nf, 5):
                return DHRows.shared(rho if rho.device == self.device else rho.to(self.device))
            if rho.ndim == 3 and tuple(rho.shape) == (n, nf, 5):
                return DHRows.per_config(rho if rho.device == self.device else rho.to(self.device))
            raise ValueError(f"rho: expected shape ({nf}, 5) or ({n}, {nf}, 5), got {tuple(rho.shape)}")
        a = real_array(rho, "rho")
        if a.shape not in ((nf, 5), (n, nf, 5)):
            raise ValueError(f"rho: expected shape ({nf}, 5) or ({n}, {nf}, 5) (DH rows "
                             f"[d, theta, r, alpha, beta] per frame), got {a.shape}")
        if not np.all(np.isfinite(a)):
            raise ValueError("rho: contains NaN or inf")
        arr: wp.array = wp.array(finite_as(a.reshape(-1, nf, 5), self.dtype, "rho"),
                                 dtype=self.scalar, device=self.device)
        return DHRows.per_config(arr) if a.ndim == 3 else DHRows.shared(arr)

    def _cost_args(self, q: Any, eps: Any, w_world: Any, w_self: Any
                   ) -> tuple[int, float, float, float]:
        """Checked arguments of :meth:`cost` and :meth:`cost_tape`: batch size, eps > 0 [m]
        and the two weights, each a real number in the computing dtype."""
        self._check_q(q)
        eps = real_number(eps, "eps", self.dtype)
        if eps <= 0:
            raise ValueError(f"eps: expected a positive distance [m], got {eps}")
        return (q.shape[0], eps, real_number(w_world, "w_world", self.dtype),
                real_number(w_self, "w_self", self.dtype))

    def _check_q(self, q: wp.array) -> None:
        if not isinstance(q, wp.array):
            raise TypeError(f"q: expected a warp array (use collision_cost for numpy/torch), "
                            f"got {type(q).__name__}")
        if q.ndim != 2 or q.shape[1] != self.robot.n_dof:
            raise ValueError(f"q: expected shape (N, {self.robot.n_dof}), got {tuple(q.shape)}")
        if q.dtype != self.scalar:
            raise TypeError(f"q: warp array dtype {q.dtype.__name__} does not match the "
                            f"kernels' {np.dtype(self.dtype).name}")
        if q.device != self.device:
            raise ValueError(f"q: on device {q.device}, the collision model on {self.device}")

    def _out(self, out: wp.array | None, shape: tuple, name: str) -> wp.array:
        if out is None:
            return wp.empty(shape, dtype=self.scalar, device=self.device)
        if not isinstance(out, wp.array) or tuple(out.shape) != shape or out.dtype != self.scalar \
                or out.device != self.device:
            raise ValueError(f"{name}: expected a warp {np.dtype(self.dtype).name} array of shape "
                             f"{shape} on {self.device}")
        return out

    # --------------------------------------------------------------- costs
    def cost(self, q: wp.array, *, rho: Any = None, w_world: float = 1.0, w_self: float = 1.0,
             eps: float = DEFAULT_EPS, grad: bool = True, out_cost: wp.array | None = None,
             out_grad: wp.array | None = None, update_rows: bool = False,
             data: CollisionData | None = None, group_div: int = 0,
             active: wp.array | None = None,
             active_div: int = 0) -> tuple[wp.array, wp.array | None]:
        """Collision cost and its hand-written gradient in one launch.

        Args:
            q: (N, n_dof) Warp array on this device and dtype [rad or m].
            rho: DH rows (n_frames, 5) or per configuration (N, n_frames, 5), a
                :class:`jwarp.core.rows.DHRows`, or
                :class:`jwarp.kinematics.compensation.CompensationRows` (elastic compensation:
                frames at those rows, gradient with the rows fixed); None = nominal.
            w_world, w_self: weights of U_world and U_self (eq. 3.16); a zero weight skips
                that term. Without a world U_world is 0.
            eps: smoothing distance of the clip c [m], > 0.
            grad: also compute d cost / d q.
            out_cost: optional preallocated (N,) output; out_grad: (N, n_dof).
            update_rows: with compensation rows as ``rho``, also make their torque update
                from this launch's frames, inside the same launch (elastic paper section V).
                On the H100 this beat a second launch over the waypoints at 1 to 1000 paths.
            data: a :class:`CollisionData` for N configurations (:meth:`make_data`): its
                scratch, and its ``cost``/``grad`` as outputs unless ``out_cost``/``out_grad``
                are given. Without it the model's own scratch and new outputs are used.
            group_div: a batch of worlds (:meth:`jwarp.world.sdf.World.batch`): row b of
                q is in world ``b // group_div``; 0: every object counts.
            active, active_div: rows b with ``active[b // active_div] == 0`` are skipped
                (cost and gradient 0; a planner's frozen paths); ``active_div`` 0: none.

        Returns:
            ``(cost (N,), grad (N, n_dof) or None)`` as Warp arrays (no host copies).
        """
        n, eps, w_world, w_self = self._cost_args(q, eps, w_world, w_self)
        d = self._work
        if data is not None or d is None or n > d.n:
            d = self._data(data, n)
        if data is not None:
            out_cost = d.cost if out_cost is None else out_cost
            out_grad = d.grad if out_grad is None and grad else out_grad
        cost = self._out(out_cost, (n,), "out_cost")
        g = self._out(out_grad, (n, self.robot.n_dof), "out_grad") if grad else None
        rows = self.dh_rows(rho, n)
        if update_rows and not isinstance(rho, CompensationRows):
            raise ValueError("update_rows: needs compensation rows as rho "
                             "(jwarp.kinematics.compensation.CompensationRows)")
        comp = rho.args() if update_rows else self._no_update
        ww = float(w_world) if self.world is not None and self.n_spheres else 0.0
        ws = float(w_self) if self.n_pairs else 0.0
        gout = g if g is not None else self._dummy
        if self.wide if self.wide is not None else default_wide(self.device, n):
            self._cost_wide(q, rows, ww, ws, float(eps), grad, group_div, active, active_div,
                            d, cost, gout, comp, record=out_cost is not None)
            if update_rows:
                rho.commit()
            return cost, g
        frames, xs, force, moment, bc = d.frames, d.xs, d.force, d.moment, d.bc

        def inputs() -> list:
            return [*self.model_args,
                    q, rows.array, rows.stride, rows.layout_vec, int(rows.kind), world_struct,
                    ww, ws, float(eps), int(grad), int(group_div),
                    active if active is not None else self._no_active, int(active_div),
                    int(ww != 0.0 and self.device_world.bound_skip),
                    frames, xs, force, moment, bc]

        world_struct = self.world_struct  # syncs moved/added objects first
        # caller-owned buffers (a planner's loop): replay a recorded launch (cheaper on the host)
        reuse = out_cost is not None and (rho is None or isinstance(rho, (wp.array, DHRows,
                                                                           CompensationRows)))
        if not reuse:
            wp.launch(self.k.cost, dim=n, inputs=inputs(), outputs=[cost, gout, comp],
                      device=self.device)
        else:
            key = (id(q), id(rows.array), rows.stride, int(rows.kind), rows.layout, id(cost),
                   id(g), ww, ws, float(eps), n, id(comp), id(frames), int(group_div),
                   id(active), int(active_div))
            hit = self._launches.get(key)
            if hit is None:
                if len(self._launches) > 32:
                    self._launches.clear()
                launch = wp.launch(self.k.cost, dim=n, inputs=inputs(),
                                   outputs=[cost, gout, comp], device=self.device,
                                   record_cmd=True)
                hit = (launch, q, rows, cost, g, comp, frames, active)
                self._launches[key] = hit
            hit[0].launch()
        if update_rows:
            rho.commit()
        return cost, g

    def cost_kernels(self, n: int) -> list:
        """The kernels :meth:`cost` launches for ``n`` configurations (the fused one, or the
        wide launches), e.g. to load their modules before a CUDA graph capture."""
        if self.wide if self.wide is not None else default_wide(self.device, n):
            kw = cwide.kernels(self.scalar)
            return [kw.frames, kw.world, kw.self_pairs, kw.gradient]
        return [self.k.cost]

    def _cost_wide(self, q: wp.array, rows: DHRows, ww: float, ws: float, eps: float,
                   grad: bool, group_div: int, active: wp.array | None, active_div: int,
                   d: CollisionData, cost: wp.array, gout: wp.array, comp: Any,
                   record: bool) -> None:
        """:meth:`cost` as the four launches of :mod:`jwarp.kernels.collision_wide`
        (``record``: replay launches recorded for the same buffers, a planner's loop)."""
        n = q.shape[0]
        frames, xs, force, moment, bc = d.wide_scratch
        world_struct = self.world_struct  # syncs moved/added objects (drops the records)
        kind, want_grad = int(rows.kind), int(grad)
        key = ("wide", id(q), id(rows.array), rows.stride, kind, rows.layout, id(cost),
               id(gout), ww, ws, eps, n, id(comp), id(frames), int(group_div), id(active),
               int(active_div), want_grad)
        hit = self._launches.get(key) if record else None
        if hit is not None:  # a planner's loop: the recorded launches, no argument packing
            for launch in hit[0]:
                launch.launch()
            return
        kw = cwide.kernels(self.scalar)
        act = active if active is not None else self._no_active
        sp = self.model.spheres.struct
        layout = rows.layout_vec
        plan = [(kw.frames, n, [self.model.frame_struct, sp, q, rows.array, rows.stride, layout,
                                kind, want_grad, int(ws != 0.0), act, int(active_div),
                                frames, force, moment, bc], [cost, gout, comp])]
        if self.n_spheres:
            plan.append((kw.world, (self.n_spheres, n),
                         [sp, world_struct, kind, layout, ww, eps, want_grad, int(group_div), act,
                          int(active_div), frames, xs, force, moment], [cost]))
        n_fp = int(self.model.spheres.struct.fpair_a.shape[0])
        if ws != 0.0 and n_fp:
            plan.append((kw.self_pairs, (n_fp, n),
                         [sp, kind, layout, ws, eps, want_grad, act, int(active_div), xs, bc,
                          force, moment], [cost]))
        if grad:
            plan.append((kw.gradient, n, [self.model.frame_struct, q, kind, layout, act,
                                          int(active_div), frames, force, moment], [gout]))
        if not record:
            for kern, dim, inputs, outputs in plan:
                wp.launch(kern, dim=dim, inputs=inputs, outputs=outputs, device=self.device)
            return
        if len(self._launches) > 32:
            self._launches.clear()
        launches = [wp.launch(kern, dim=dim, inputs=inputs, outputs=outputs,
                              device=self.device, record_cmd=True)
                    for kern, dim, inputs, outputs in plan]
        # the recorded launches hold these arrays: keep them alive with the record
        self._launches[key] = (launches, q, rows, cost, gout, comp, frames, active)
        for launch in launches:
            launch.launch()

    def cost_tape(self, q: wp.array, *, rho: ArrayLike | None = None, w_world: float = 1.0,
                  w_self: float = 1.0, eps: float = DEFAULT_EPS) -> tuple[wp.array, wp.array]:
        """The same cost, its gradient w.r.t. q by ``wp.Tape`` (FK kernel + one thread per
        sphere and per sphere pair, atomic sums). Slower; a cross-check of the
        hand-written gradient and the route for derivatives w.r.t. other inputs.
        Returns ``(cost (N,), grad (N, n_dof))`` Warp arrays."""
        n, eps, w_world, w_self = self._cost_args(q, eps, w_world, w_self)
        if self.device_world.has_objects and w_world != 0:
            raise ValueError("tape: the Tape route takes grids only; this world has exact "
                             "objects (use the hand-written gradient, tape=False)")
        rows = self.dh_rows(rho, n, expand=True)
        qg = wp.clone(q)
        qg.requires_grad = True
        k = fk_kernels(self.scalar)
        frames = wp.zeros((n, self.robot.n_frames), dtype=k.mat44, device=self.device,
                          requires_grad=True)
        cost = wp.zeros(n, dtype=self.scalar, device=self.device, requires_grad=True)
        sp = self.model.spheres
        tape = wp.Tape()
        with tape:
            wp.launch(k.fk, dim=n, inputs=[self.model.frame_struct, qg, *rows.args],
                      outputs=[frames], device=self.device)
            if self.world is not None and self.n_spheres and w_world != 0:
                wp.launch(self.k.world_cost_spheres, dim=(n, self.n_spheres),
                          inputs=[sp.sph_frame, sp.sph_pos, sp.sph_rad, frames, self.grid,
                                  self.origin, self.inv_h, self.dim, float(w_world), float(eps)],
                          outputs=[cost], device=self.device)
            if self.n_pairs and w_self != 0:
                wp.launch(self.k.self_cost_pairs, dim=(n, self.n_pairs),
                          inputs=[sp.sph_frame, sp.sph_pos, sp.sph_rad, sp.pair_a, sp.pair_b,
                                  frames, float(w_self), float(eps)],
                          outputs=[cost], device=self.device)
        tape.backward(grads={cost: wp.ones(n, dtype=self.scalar, device=self.device)})
        grad = wp.clone(qg.grad)
        tape.zero()
        return cost, grad

    # ----------------------------------------------------------- distances
    def distances(self, q: wp.array, *, rho: ArrayLike | None = None, spheres: bool = False,
                  pairs: bool = False, use_world: bool = True, use_self: bool = True,
                  data: CollisionData | None = None, group_div: int = 0
                  ) -> tuple[wp.array | None, wp.array | None, wp.array]:
        """Signed surface distances [m] (Warp arrays).

        Returns ``(sphere_dist (N, S) or None, pair_dist (N, P) or None, min_dist (N, 2))``:
        ``sphere_dist[b, s] = D(x_s) - r_s``; ``pair_dist[b, p] = |x_a - x_b| - r_a - r_b``
        for the pairs of :func:`collision_pairs`; ``min_dist[b] = [min world, min self]``
        (1e30 where there is nothing to measure). ``data``: a :class:`CollisionData` for N
        configurations whose scratch and outputs are used (else new outputs)."""
        self._check_q(q)
        n = q.shape[0]
        rows = self.dh_rows(rho, n, expand=True)
        uw = int(use_world and self.world is not None and self.n_spheres > 0)
        us = int(use_self and self.n_pairs > 0)
        d = self._data(data, n)
        if data is not None:
            sd = d.sphere_dist if spheres and uw else None
            pd = d.pair_dist if pairs and us else None
            md = d.min_dist
        else:
            sd = wp.empty((n, self.n_spheres), dtype=self.scalar, device=self.device) \
                if spheres and uw else None
            pd = wp.empty((n, self.n_pairs), dtype=self.scalar, device=self.device) \
                if pairs and us else None
            md = wp.empty((n, 2), dtype=self.scalar, device=self.device)
        dummy = self._dummy
        wp.launch(self.k.distance, dim=n,
                  inputs=[*self.model_args, _FAR, q, *rows.args, self.world_struct, uw, us,
                          int(sd is not None), int(pd is not None), int(group_div),
                          d.frames, d.xs],
                  outputs=[sd if sd is not None else dummy, pd if pd is not None else dummy, md],
                  device=self.device)
        return sd, pd, md


# ====================================================================== functional API
#: CollisionModels by (robot content key, device, dtype) and the world (by identity, held
#: weakly), the 32 used last
_MODELS: IdentityCache[CollisionModel] = IdentityCache(32, owner=0)


def collision_model(robot: RobotModel, world: World | None = None, *, device: DeviceLike = None,
                    dtype: DTypeLike = np.float32) -> CollisionModel:
    """A cached :class:`CollisionModel` for (robot, world, device, dtype): robots of equal
    content share one (their device model is one, :func:`jwarp.core.device.put_model`);
    worlds are told apart by identity (held weakly; treat a world as immutable)."""
    init_warp()
    model = robot
    check_world(model, world)
    dev = resolve_device(device)
    scalar = scalar_type(dtype)
    key = (put_model(model, dev, scalar).key, str(dev), scalar.__name__)
    hit = _MODELS.get(key, (world,))
    if hit is not None:
        return hit
    return _MODELS.put(key, (world,), CollisionModel(model, world, device=dev, dtype=scalar))


def _prepare(robot: RobotModel, q: ArrayLike, world: World | None, device: DeviceLike, dtype: DTypeLike,
             validate: bool) -> tuple[RobotModel, Batch, CollisionModel]:
    init_warp()
    model = robot
    check_world(model, world)
    dev = resolve_device(device, like=q)
    dt = default_dtype(q) if dtype is None else dtype
    batch = as_batch(q, model.n_dof, "q", device=dev, dtype=dt,
                     what=f"robot '{model.name}' has {model.n_dof} joints", validate=validate)
    return model, batch, collision_model(model, world, device=dev, dtype=dt)


def _rho_arg(rho: Any, batch: Batch, nf: int) -> Any:
    """Per-configuration rho with the caller's leading dims -> (N, n_frames, 5)."""
    if rho is None or isinstance(rho, wp.array):
        if isinstance(rho, wp.array) and rho.ndim > 3:
            return rho.reshape((-1, nf, 5))
        return rho
    a = real_array(rho, "rho")
    if a.ndim > 2:
        if a.shape[:-2] != tuple(batch.lead_shape):
            raise ValueError(f"rho: batch dims {a.shape[:-2]} do not match q's {tuple(batch.lead_shape)}")
        a = a.reshape(-1, *a.shape[-2:])
    return a


def collision_cost(robot: RobotModel, q: ArrayLike, world: World | None, *, w_world: float = 1.0,
                   w_self: float = 1.0, eps: float = DEFAULT_EPS, rho: ArrayLike | None = None,
                   grad: bool = True, device: DeviceLike = None, dtype: DTypeLike = None,
                   tape: bool = False, validate: bool = True) -> tuple[Any, Any]:
    """Collision cost ``w_world U_world + w_self U_self`` (eq. 3.8, 3.10, 3.11) per
    configuration and its gradient w.r.t. q.

    Args:
        robot: name or RobotModel.
        q: (..., n_dof) joint values (numpy, Warp or torch) [rad or m].
        world: :class:`World` of the robot's workspace dimension, or None (self only).
        w_world, w_self: weights; eps: smoothing distance of c [m].
        rho: optional DH rows (n_frames, 5) or (..., n_frames, 5) (elastic compensation:
            FK at rho, gradient with rho held fixed).
        grad: also return the gradient.
        device, dtype: as in :func:`jwarp.fk` (default float32 unless q is float64).
        tape: gradient by ``wp.Tape`` instead of the hand-written kernel (slower).
        validate: check q for NaN/inf (copies Warp/torch input to the host; in a loop pass
            False, or call :meth:`CollisionModel.cost` directly).

    Returns:
        ``(cost (...,), grad (..., n_dof) or None)`` in the kind of ``q`` (Warp in, Warp out).
    """
    model, batch, cm = _prepare(robot, q, world, device, dtype, validate)
    rho_b = _rho_arg(rho, batch, model.n_frames)
    g: wp.array | None
    if tape:
        cost, g = cm.cost_tape(batch.array, rho=rho_b, w_world=w_world, w_self=w_self, eps=eps)
        if not grad:
            g = None
    else:
        cost, g = cm.cost(batch.array, rho=rho_b, w_world=w_world, w_self=w_self, eps=eps,
                          grad=grad)
    out_c = to_output(cost, batch)
    out_g = None if g is None else to_output(g, batch, (model.n_dof,))
    return out_c, out_g


def sphere_distances(robot: RobotModel, q: ArrayLike, world: World | None, *, rho: ArrayLike | None = None, device: DeviceLike = None,
                     dtype: DTypeLike = None, validate: bool = True) -> Any:
    """(..., n_spheres) signed distance [m] of each sphere's surface to the world:
    ``D(x_s) - r_s`` (negative = penetration)."""
    if world is None:
        raise ValueError("world: required for sphere distances")
    model, batch, cm = _prepare(robot, q, world, device, dtype, validate)
    if cm.n_spheres == 0:
        raise ValueError(f"robot: '{model.name}' has no collision spheres")
    sd, _, _ = cm.distances(batch.array, rho=_rho_arg(rho, batch, model.n_frames), spheres=True,
                            use_self=False)
    return to_output(cast(wp.array, sd), batch, (cm.n_spheres,))  # spheres=True


def self_distances(robot: RobotModel, q: ArrayLike, *, rho: ArrayLike | None = None, device: DeviceLike = None,
                   dtype: DTypeLike = None, validate: bool = True) -> Any:
    """(..., n_pairs) signed distance [m] between the surfaces of the sphere pairs of
    :func:`collision_pairs` (negative = penetration)."""
    model, batch, cm = _prepare(robot, q, None, device, dtype, validate)
    if cm.n_pairs == 0:
        raise ValueError(f"robot: '{model.name}' has no self-collision sphere pairs")
    _, pd, _ = cm.distances(batch.array, rho=_rho_arg(rho, batch, model.n_frames), pairs=True,
                            use_world=False)
    return to_output(cast(wp.array, pd), batch, (cm.n_pairs,))  # pairs=True


def min_distances(robot: RobotModel, q: ArrayLike, world: World | None = None, *, rho: ArrayLike | None = None,
                  device: DeviceLike = None, dtype: DTypeLike = None, validate: bool = True,
                  per_world: int = 0) -> Any:
    """(..., 2) [smallest sphere-to-world, smallest sphere-to-sphere] surface distance [m]
    per configuration (``inf`` where there is nothing to measure). ``per_world`` > 0 with a
    batch of worlds (:meth:`World.batch`): configuration b is in world ``b // per_world``
    (0: all objects count)."""
    model, batch, cm = _prepare(robot, q, world, device, dtype, validate)
    _, _, md = cm.distances(batch.array, rho=_rho_arg(rho, batch, model.n_frames),
                            group_div=per_world)
    out = to_output(md, batch, (2,))
    if isinstance(out, np.ndarray):
        out = np.where(out >= 0.5 * _FAR, np.inf, out)
    return out


def mm_text(metres: float) -> str:
    """A distance [m] as millimetres with 2 decimals, never ``-0.00``: a value that rounds
    to zero but is not zero keeps two significant digits (``-0.0031``), an exact zero is
    ``0.00``."""
    v = float(metres) * 1e3
    text = f"{v:.2f}"
    if float(text) == 0.0:
        return "0.00" if v == 0.0 or not np.isfinite(v) else f"{v:.2g}"
    return text


def sphere_link(robot: RobotModel, s: int) -> str:
    """The name of the frame (link) collision sphere ``s`` of ``robot`` is fixed to."""
    model = robot
    return model.frames[model.spheres[int(s)].frame].name


def nearest_objects(robot: RobotModel, q: ArrayLike, world: World, spheres: Any, rho: ArrayLike | None = None,
                    device: DeviceLike = None) -> list[str]:
    """What each of the collision ``spheres`` (indices) of one configuration q (n_dof,) is
    nearest to, in words: ``"object 'NAME'"`` (the world's exact objects) or ``"the world
    grid"`` (a grid, and every 2D world). ``rho`` (n_frames, 5): the frames' DH rows (an
    elastic equilibrium) instead of q's rigid ones. Computed in float64 on ``device`` (None:
    the CPU where Warp has its CPU backend, else Warp's default device: a GPU-only install
    has no CPU kernels)."""
    from jwarp.core.device import host_device
    from jwarp.kinematics.fk import fk
    from jwarp.world.device_world import world_query

    model = robot
    spheres = np.asarray(spheres, np.int64).reshape(-1)
    if world.dim != 3:
        return ["the world grid"] * len(spheres)
    q1 = np.asarray(q, np.float64).reshape(1, model.n_dof)
    if device is None:
        device = host_device()
    F = np.asarray(fk(model, q1, dh=None if rho is None else np.asarray(rho)[None],
                      dtype=np.float64, device=device))[0]
    idx, pos, _ = model.sphere_arrays()            # sphere frames and centres in them
    c = np.einsum("nij,nj->ni", F[idx, :3, :3], pos) + F[idx, :3, 3]
    _, _, obj = world_query(world, c[spheres], device=device)
    return ["the world grid" if int(o) == -2 else f"object '{world.object_name(int(o))}'"
            for o in obj]


def closest_pair_text(robot: RobotModel, q: ArrayLike, world: World | None, *, self_collision: bool,
                      rho: ArrayLike | None = None, device: DeviceLike = None) -> str:
    """The closest pair of one configuration q (n_dof,) in words, for a message about a
    configuration in collision: ``link 'L' vs object 'O', -93.27 mm`` (``self_collision``
    False: the sphere nearest to the world and the object nearest to it) or ``link 'A' vs
    link 'B', -1.50 mm`` (True: the closest sphere pair of :func:`collision_pairs`); the
    signed surface distance (negative = penetration). ``rho`` (n_frames, 5): the frames'
    DH rows (an elastic equilibrium)."""
    model = robot
    q1 = np.asarray(q, np.float64).reshape(1, model.n_dof)
    r1 = None if rho is None else np.asarray(rho, np.float64)[None]
    if not self_collision:
        d = np.asarray(sphere_distances(model, q1, world, rho=r1, device=device,
                                        dtype=np.float64))[0]
        s = int(np.argmin(d))
        obj = nearest_objects(model, q1[0], world, [s], None if r1 is None else r1[0],
                              device=device)[0]
        return f"link '{sphere_link(model, s)}' vs {obj}, {mm_text(d[s])} mm"
    d = np.asarray(self_distances(model, q1, rho=r1, device=device, dtype=np.float64))[0]
    p = int(np.argmin(d))
    a, b = (sphere_link(model, int(i)) for i in collision_pairs(model)[p])
    return f"link '{a}' vs link '{b}', {mm_text(d[p])} mm"


def is_collision_free(robot: RobotModel, q: ArrayLike, world: World | None = None, margin: float = 0.0, *,
                      rho: ArrayLike | None = None, device: DeviceLike = None, dtype: DTypeLike = None,
                      validate: bool = True, self_margin: float | None = None,
                      per_world: int = 0, meshes: bool = True) -> np.ndarray:
    """(...,) bool numpy: every sphere keeps more than ``margin`` [m] from the world and
    more than ``self_margin`` (None: ``margin``) from every sphere it may collide with
    (joint limits are not checked here). ``meshes`` (default): where the spheres touch,
    a robot that records its collision pieces (an import from a URDF) is free when the
    mesh certificate proves its URDF geometry keeps those clearances
    (:mod:`jwarp.world.mesh_check`): contained spheres reach past the meshes, and a grasp
    pose the fingers clear by millimetres is not refused for it.

    The one check of "is this configuration collision-free" in jwarp:
    :func:`jwarp.world.path_feasibility.collision_free` (the planners', ``jwarp
    free-config``'s: (N,) rows in float64, the elastic equilibrium with ``kappa``) calls
    it, and the IK's mesh rescue calls its :func:`mesh_certified`."""
    margin = real_number(margin, "margin")
    if not np.isfinite(margin):
        raise ValueError(f"margin: expected a finite distance [m], got {margin}")
    sm = margin if self_margin is None else real_number(self_margin, "self_margin")
    if not np.isfinite(sm):
        raise ValueError(f"self_margin: expected a finite distance [m], got {self_margin}")
    model = robot
    md = min_distances(model, q, world, rho=rho, device=device, dtype=dtype, validate=validate,
                       per_world=per_world)
    if isinstance(md, wp.array):
        md = md.numpy()
    elif hasattr(md, "detach"):
        md = md.detach().cpu().numpy()
    md = np.asarray(md)
    free = (md[..., 0] > margin) & (md[..., 1] > sm)
    if meshes and not free.all() and rho is None:
        free = mesh_certified(model, q, world, free, margin, sm, device, per_world, md)
    return free


def mesh_certified(robot: RobotModel, q: ArrayLike, world: World | None, free: np.ndarray, margin: float,
                   self_margin: float, device: DeviceLike = None, per_world: int = 0,
                   md: np.ndarray | None = None) -> np.ndarray:
    """``free`` (the spheres' verdict on ``q``) with the configurations the spheres refuse
    but the mesh certificate proves free (:func:`jwarp.world.mesh_check.mesh_check`;
    unchanged where it has none). ``md`` (..., 2): the spheres' smallest distances (world,
    self) at ``q``: a configuration whose spheres collide deeper than they reach past the
    meshes (:func:`jwarp.world.mesh_check.sphere_reach_past`) is not tried."""
    from jwarp.world.mesh_check import mesh_check, sphere_reach_past

    model = robot
    if getattr(model, "collision_pieces", None) is None:
        return free
    mc = mesh_check(model, world, device)
    if mc is None:
        return free
    if hasattr(q, "numpy") and not isinstance(q, np.ndarray):
        q = q.detach().cpu().numpy() if hasattr(q, "detach") else q.numpy()
    qs = np.asarray(q, np.float64).reshape(-1, model.n_dof)
    flat = free.reshape(-1).copy()
    try_ = ~flat
    if md is not None:
        depth = sphere_reach_past(model)
        m2 = np.asarray(md, np.float64).reshape(-1, 2)
        try_ &= (m2[:, 0] > -depth) & (m2[:, 1] > -depth)
    bad = np.nonzero(try_)[0]
    if not len(bad):
        return free
    groups = bad // int(per_world) if per_world and world is not None and \
        world.n_worlds > 1 else None
    flat[bad] = mc.free(qs[bad], margin, self_margin, groups=groups)
    return flat.reshape(free.shape)
