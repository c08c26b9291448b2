"""Elastic DH rows kept across the iterations of an optimizer (elastic paper section V).

Inside a planner or IK loop the torque equilibrium ``rho* = rho0 + kappa tau(F(q, rho*))``
is not solved to convergence. Each configuration keeps its rows from the previous
iteration. The optimizer computes its frames at those rows anyway, for its costs. From
those same frames, one damped torque update per iteration gives the rows for the next
iteration. No extra forward kinematics is run, and gradients hold the rows fixed
(d rho / dq = 0). As the optimizer converges, so do the rows.

The rows have 9 columns ``[d, theta, r, alpha, beta, cos alpha, sin alpha, cos beta,
sin beta]``. The FK, Jacobian and collision kernels read them as
:attr:`jwarp.core.rows.RowsKind.COMPENSATION` rows (:attr:`CompensationRows.dh_rows`), so
forward kinematics at these rows costs what the rigid fast path costs.

Model vs Data: the robot's tables (frames, masses, gravity, default compliances) come from
its :class:`jwarp.core.device.DeviceModel`; a :class:`CompensationRows` is the Data of the
update (the row buffers, the moment scratch, ``delta``), reused from one iteration to the
next.

Paths: rows are kept per waypoint, and only the waypoints get a torque update. A substep
reads the rows of its nearest waypoint (:func:`jwarp.kernels.fk.waypoint_thread`).
Deflections change slowly along a segment, and the final feasibility check solves the
full equilibrium at every substep anyway.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import warp as wp

from jwarp.core.arrays import finite_as, real_number
from jwarp.core.device import DeviceModel, numpy_dtype
from jwarp.core.rows import DHRows
from jwarp.core.types import ArrayLike
from jwarp.kernels import elastic as elastic_kernels
from jwarp.kinematics.launch import kappa_array

#: columns of a compensation row (see the module docstring)
ROW_COLUMNS = 9
#: waypoints run first on CUDA once they fill this many warps per multiprocessor (see
#: ``CompensationRows.waypoints_first``; H100, 20 waypoints: slower up to 256 paths, faster
#: at 1000)
WAYPOINT_WARPS_PER_SM = 4


class CompensationRows:
    """Ping-pong buffers of compensation rows, one per waypoint, for N = P * S
    configurations.

    Args:
        t: the robot's :class:`~jwarp.core.device.DeviceModel` on the optimizer's device and
            dtype (:func:`~jwarp.core.device.put_model`).
        n_paths, n_waypoints, n_substeps: layout of the configurations: P paths of
            W waypoints, S = (W - 1) * n_substeps + 1 configurations per path, configuration
            ``p * S + s``. For IK pass ``n_paths=B``, ``n_waypoints=1``, ``n_substeps=1``.
        kappa: compliances [rad/(N m)]. Any form :func:`jwarp.kinematics.kappa_array`
            accepts: shared ``(n_frames, 3)``, or per waypoint ``(P * W, n_frames, 3)``;
            None: the robot's own (``t.kappa``).
        lam: damping of the update in (0, 1].
    """

    def __init__(self, t: DeviceModel, n_paths: int, n_waypoints: int, n_substeps: int,
                 kappa: ArrayLike, lam: float):
        if not 0.0 < real_number(lam, "lam") <= 1.0:
            raise ValueError(f"lam: expected a damping factor in (0, 1], got {lam!r}")
        robot = t.robot
        self.t = t
        self.P, self.W, self.n_sub = int(n_paths), int(n_waypoints), int(n_substeps)
        self.S = (self.W - 1) * self.n_sub + 1
        self.N = self.P * self.S
        self.n_updates = self.P * self.W
        self.lam = t.scalar(float(lam))
        self.k = elastic_kernels.kernels(t.scalar)
        nf = robot.n_frames
        dev = t.device
        self.kappa: wp.array
        self.kappa_stride: int
        if kappa is None:  # the model's default compliances
            self.kappa, self.kappa_stride = t.kappa, 0
        else:
            kap = kappa_array(robot, kappa)  # validates shape and values
            if kap.ndim == 2:
                kap, self.kappa_stride = kap[None], 0
            else:
                kap = kap.reshape(-1, nf, 3)
                if len(kap) != self.n_updates:
                    raise ValueError(f"kappa: per-waypoint tables need {self.n_updates} rows "
                                     f"(paths x waypoints), got {len(kap)}")
                self.kappa_stride = 1
            self.kappa = wp.array(finite_as(kap, numpy_dtype(t.scalar), "kappa"),
                                  dtype=t.scalar, device=dev)
        self.gravity = t.gravity
        self._bufs = [wp.empty((self.n_updates, nf, ROW_COLUMNS), dtype=t.scalar, device=dev)
                      for _ in range(2)]
        # CPU threads run one configuration after another: one scratch column stays in L1
        S = 1 if dev.is_cpu else self.n_updates
        self._prefix = wp.empty((nf + 1, S), dtype=self.k.vec4, device=dev)
        self.delta = wp.zeros(self.n_updates, dtype=t.scalar, device=dev)
        self.iterations = 0
        #: run the waypoints' threads first (:func:`jwarp.kernels.fk.waypoint_thread`).
        #: On CUDA this keeps the torque update, which only waypoints run, from diverging
        #: the warps of the substeps; but the waypoint warps then carry the longest
        #: threads, which only pays once they fill the GPU several times over. The CPU
        #: keeps the path order (the rows of a path stay in cache).
        self.waypoints_first = bool(
            dev.is_cuda and self.n_updates >= WAYPOINT_WARPS_PER_SM * 32 * dev.sm_count)
        self._launches: dict = {}
        self._args: dict = {}
        self._dh_rows: dict = {}
        self.reset()

    @property
    def rows(self) -> wp.array:
        """The current rows (P * W, n_frames, 9) (as kernel arguments: :attr:`dh_rows`)."""
        return self._bufs[0]

    @property
    def dh_rows(self) -> DHRows:
        """The current rows as :class:`jwarp.core.rows.DHRows` (kind ``COMPENSATION``, with
        :attr:`layout`); one value per buffer, made once."""
        buf = self._bufs[0]
        r = self._dh_rows.get(id(buf))
        if r is None or r.layout != self.layout:
            r = self._dh_rows[id(buf)] = DHRows.compensation(buf, self.layout)
        return r

    @property
    def layout(self) -> tuple[int, int, int, int]:
        """(configurations per path S, substeps per segment, waypoints W, P or 0): the
        ``layout`` of :func:`jwarp.kernels.fk.waypoint_thread`, which maps a kernel's
        threads to configurations and their rows; P (waypoints first) where
        :attr:`waypoints_first`."""
        return self.S, self.n_sub, self.W, self.P if self.waypoints_first else 0

    def config_rows(self) -> np.ndarray:
        """(N,) int: the row each configuration reads (numpy twin of ``waypoint_thread``)."""
        b = np.arange(self.N)
        p, s = np.divmod(b, self.S)
        return p * self.W + (s + self.n_sub // 2) // self.n_sub

    def reset(self) -> None:
        """Back to the nominal rows (the rigid robot) in both buffers."""
        for buf in self._bufs:
            wp.launch(self.k.fill_rows, dim=(self.n_updates, self.t.robot.n_frames),
                      inputs=[self.t.frame_struct], outputs=[buf], device=self.t.device)
        self.delta.fill_(1e30)  # no update yet: nothing has converged
        self.iterations = 0

    def args(self) -> Any:
        """The kernel argument (``kernels.elastic.CompensationArgs``) of the next update:
        from :attr:`rows` into the other buffer. A kernel that takes it and runs the update
        must be followed by :meth:`commit`."""
        key = id(self._bufs[1])
        c = self._args.get(key)
        if c is None:
            t = self.t
            c = self.k.CompensationArgs()
            c.enabled = 1
            c.n_waypoints, c.n_sub = self.W, self.n_sub
            c.rho0, c.rho0_stride = t.dh0_3d, 0
            c.kappa, c.kappa_stride = self.kappa, self.kappa_stride
            c.kappa_nl = t.kappa_nl
            c.lam, c.gravity = self.lam, self.gravity
            c.mass, c.mass_com, c.dh_info = t.mass, t.mass_com, t.dh_info
            c.prefix, c.scratch_stride = self._prefix, int(self._prefix.shape[1] > 1)
            c.rows_out, c.delta = self._bufs[1], self.delta
            self._args[key] = c
        return c

    def commit(self) -> None:
        """The rows a kernel has just written through :meth:`args` become :attr:`rows`."""
        self._bufs.reverse()
        self.iterations += 1

    def update(self, frames: wp.array, per_frame: bool | None = None) -> wp.array:
        """One torque update from ``frames`` (N, n_frames) computed at :attr:`rows` (its own
        launch); the new rows become :attr:`rows`. Returns delta (P * W,): the largest row
        change at each waypoint [rad].

        ``per_frame``: one thread per (waypoint, DH frame) instead of one per waypoint.
        Default: on CUDA, where a thread walking the whole robot sets the duration of a
        small launch (an IK batch); the CPU runs threads one after another and prefers
        one per waypoint (no atomics, one pass over the frames)."""
        t = self.t
        if tuple(frames.shape[:2]) != (self.N, t.robot.n_frames):
            raise ValueError(f"frames: expected shape ({self.N}, {t.robot.n_frames}), got "
                             f"{tuple(frames.shape)}")
        if per_frame is None:
            per_frame = t.device.is_cuda
        # a recorded launch per (frames, direction, kind): Warp's argument packing costs
        # microseconds per launch on the host, as much as the update of a whole path
        key = (id(frames), id(self.rows), bool(per_frame))
        hit = self._launches.get(key)
        if hit is None:
            if len(self._launches) > 8:
                self._launches.clear()
            dim: int | tuple[int, int]
            kernel, dim = self.k.compensation_update, self.n_updates
            if per_frame:
                kernel, dim = self.k.compensation_update_per_frame, (self.n_updates,
                                                                     t.dh_info.shape[0])
            launch = wp.launch(kernel, dim=dim, inputs=[t.frame_struct, frames, self.rows],
                               outputs=[self.args()], device=t.device, record_cmd=True)
            hit = self._launches[key] = (launch, frames)  # keeps frames alive for the id
        if per_frame:
            self.delta.zero_()  # the kernel takes the max over the frames atomically
        hit[0].launch()
        self.commit()
        return self.delta

    def rho(self, rows: wp.array | None = None) -> np.ndarray:
        """The DH rows of every configuration (N, n_frames, 5) float64 from ``rows``
        (default: :attr:`rows`)."""
        a = (self.rows if rows is None else rows).numpy()
        return a[self.config_rows(), :, :5].astype(np.float64)
