"""Collision-free inverse kinematics: the two-stage solver of thesis 3.3.3 (eq. 3.21-3.24).

Stage 1 (projection, eq. 3.21-3.23): ``q <- q + J^+ e`` with the 6D error
``e = [p_T - p; log(R_T R^T)]`` of the end-effector frame and the damped pseudo-inverse
``J^+ = J^T (J J^T + mu^2 I)^-1`` of the geometric Jacobian (planar robots use the rows
``v_x, v_y, w_z`` only). Stage 2 (eq. 3.24): once a configuration is on the target
(``|e_v| < tol_pos``, ``|e_w| < tol_rot``) it descends ``U_A`` (world + self collision +
closeness to a default pose, eq. 3.19) inside the Jacobian's nullspace,
``q <- q + J^+ e - alpha (I - J^+ J) dU_A/dq``, the ``J^+ e`` term pulling it back onto the
target manifold. Every step is scaled so that no joint moves more than ``max_step`` and
projected onto the joint limits.

Convergence (beyond the thesis): a joint at a box limit that the step would push further
out is held (its Jacobian column removed, the step recomputed), and a start whose pose
error stops falling while off target (``restart_after`` steps without a 10 % gain) is
re-seeded uniformly inside the limits, up to ``max_restarts`` times; then it gives up. A
problem is done when solved or when all its starts gave up; with ``stop_when_solved`` the
batch ends when every problem is done. Panda, 4 starts, 50 iterations, 1 mm / 0.01 rad:
85 % of reachable targets solved before, 99 % with both (benchmarks/README.md). Targets may
constrain the full pose, the position only (``orientation="none"``) or one axis of the
frame (``orientation="axis"``, ``free_axis``: a grasp symmetric about the tool axis).

A configuration is *feasible* when it is on the target, collision-free with ``margin``
(world and self) and within the limits; each multi-start stops when feasible. The batch
holds ``P`` problems (targets) x ``S`` seeds; the solver returns per problem the feasible
seed with the lowest U_A (or the best infeasible one, flagged).

:class:`IKSolver` keeps everything on the device (:mod:`jwarp.kernels.ik_step`): the damped
least-squares step, the exact feasibility check of the candidates (float64: limits, world
and self collision with ``margin``), freezing the solved seeds and the best-seed selection
run in kernels; the host only reads three counters now and then to decide when to stop
(every iteration on the CPU, where that is free; every ``check_every`` iterations on CUDA)
and copies the results once at the end. :func:`ik` is a thin wrapper that builds one.

With ``kappa`` the robot is the elastic model (elastic paper section V): one torque update
per iteration from the DH rows kept from the previous iteration; frames and Jacobians at
those rows, gradients with the rows fixed; "on target" also requires the torque update to
have converged (largest DH change < ``tol_rho``).
"""

from __future__ import annotations

import dataclasses
import math
import numbers
import time
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np
import warp as wp

from jwarp.core.arrays import finite_as, init_warp, real_array, real_number, resolve_device
from jwarp.core.device import numpy_dtype, put_model, scalar_type
from jwarp.core.limits import LIMIT_TOL, sample_within_limits
from jwarp.kernels import fk as fk_kernels
from jwarp.kernels import ik as ik_kernels
from jwarp.kernels import ik_step as step_kernels
from jwarp.kernels import path as path_kernels
from jwarp.kinematics.compensation import CompensationRows
from jwarp.kinematics.transmission import transmitted, untransmitted
from jwarp.model import RobotModel
from jwarp.registry import robot as get_robot
from jwarp.solvers.overrides import renamed_options, translate, with_overrides
from jwarp.world import collision
from jwarp.world.model_check import check_collision_model


@dataclass
class IKWeights:
    """Weights of eq. 3.15/3.19: position, rotation, world, self-collision, default pose."""

    position: float = 1.0
    rotation: float = 1.0
    world: float = 1.0
    self: float = 1.0
    default: float = 0.01

    def validate(self) -> None:
        for k in ("position", "rotation", "world", "self", "default"):
            v = getattr(self, k)
            if not (math.isfinite(real_number(v, f"weights.{k}")) and v >= 0):
                raise ValueError(f"weights.{k}: expected a finite number >= 0, got {v!r}")


@dataclass
class IKResult:
    """Result of :func:`ik` for T targets (leading dims of ``target``).

    q (T, n_dof) chosen solution; feasible (T,) bool; pos_err (T,) [m]; rot_err (T,) [rad];
    cost (T,) U_A at the solution; iterations (T,) iterations the chosen start needed
    (projection + nullspace, re-seeds included; an infeasible start: ``iterations``, or
    its own count if it gave up); start_index (T,); n_feasible (T,) feasible starts;
    wall_time [s]; all_q (T, n_starts, n_dof); all_feasible (T, n_starts).
    """

    q: np.ndarray
    feasible: np.ndarray
    pos_err: np.ndarray
    rot_err: np.ndarray
    cost: np.ndarray
    iterations: np.ndarray
    start_index: np.ndarray
    n_feasible: np.ndarray
    wall_time: float
    all_q: np.ndarray = field(repr=False)
    all_feasible: np.ndarray = field(repr=False)
    all_iterations: np.ndarray = field(repr=False)

    def to_dict(self, index: int = 0) -> dict:
        """JSON-ready summary of target ``index`` (flat index over the target dims)."""
        def pick(a: np.ndarray, tail: int = 0) -> np.ndarray:
            a = np.asarray(a)
            return a.reshape((-1,) + a.shape[a.ndim - tail:])[index]

        return {"q": pick(self.q, 1).tolist(), "feasible": bool(pick(self.feasible)),
                "pos_err_m": float(pick(self.pos_err)), "rot_err_rad": float(pick(self.rot_err)),
                "costs": {"aux": float(pick(self.cost))},
                "iterations": int(pick(self.iterations)),
                "start_index": int(pick(self.start_index)),
                "n_feasible_starts": int(pick(self.n_feasible)),
                "wall_time_s": float(self.wall_time)}

    @classmethod
    def from_rows(cls, out: np.ndarray, best: np.ndarray, n_dof: int, P: int, S: int,
                  wall: float) -> "IKResult":
        """The result of P problems x S seeds from the solver's result rows ``out``
        (P * S, n_dof + 5) ``[q, |e_v|, |e_w|, U_A, feasible, iterations]`` and its choice
        ``best`` (P, 2) ``[chosen seed, feasible seeds]`` (:mod:`jwarp.kernels.ik_step`)."""
        n, E = n_dof, step_kernels
        qa = out[:, :n].reshape(P, S, n)
        e = out[:, n + E.COL_POS:n + E.COL_AUX + 1].reshape(P, S, 3)
        fz = (out[:, n + E.COL_FEASIBLE] != 0).reshape(P, S)
        it = out[:, n + E.COL_ITERATIONS].astype(np.int64).reshape(P, S)
        b = best[:, 0].astype(np.int64)
        r = np.arange(P)
        return cls(q=qa[r, b], feasible=fz[r, b], pos_err=e[r, b, 0], rot_err=e[r, b, 1],
                   cost=e[r, b, 2], iterations=it[r, b], start_index=b,
                   n_feasible=best[:, 1].astype(np.int64), wall_time=wall, all_q=qa,
                   all_feasible=fz, all_iterations=it)

    def reshaped(self, lead: tuple, wall: float | None = None) -> "IKResult":
        """This result of P flat problems with the leading dims ``lead`` (prod = P)
        instead, and the wall time ``wall`` (None: unchanged)."""
        def shp(x: np.ndarray) -> np.ndarray:
            x = np.asarray(x)
            return x.reshape(tuple(lead) + x.shape[1:])

        return dataclasses.replace(
            self, wall_time=self.wall_time if wall is None else wall,
            **{f.name: shp(getattr(self, f.name)) for f in dataclasses.fields(self)
               if f.name != "wall_time"})


def pose_matrix(xyz: Any, rotvec: Any = (0.0, 0.0, 0.0)) -> np.ndarray:
    """4x4 pose from a position [m] and a rotation vector (axis * angle) [rad]."""
    from scipy.spatial.transform import Rotation

    p = np.asarray(xyz, np.float64).reshape(3)
    r = np.asarray(rotvec, np.float64).reshape(3)
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(r).as_matrix()
    T[:3, 3] = p
    return T


def _targets(target: Any) -> tuple[np.ndarray, tuple]:
    T = real_array(target, "target")
    if T.ndim < 2 or T.shape[-2:] != (4, 4) or T.size == 0:
        raise ValueError(f"target: expected shape (..., 4, 4), got {T.shape}")
    if not np.all(np.isfinite(T)):
        raise ValueError("target: contains NaN or inf")
    lead = T.shape[:-2]
    T = T.reshape(-1, 4, 4)
    R = T[:, :3, :3]
    # np.allclose(x, y, atol=1e-6) with its default rtol=1e-5, written out (faster)
    if np.any(np.abs(R @ np.swapaxes(R, 1, 2) - np.eye(3)) > 1e-6 + 1e-5 * np.eye(3)) or \
            np.any(np.abs(np.linalg.det(R) - 1.0) > 1e-6 + 1e-5):
        raise ValueError("target: rotation part is not a rotation matrix")
    if np.any(np.abs(T[:, 3] - [0, 0, 0, 1]) > 1e-8 + 1e-5 * np.array([0, 0, 0, 1])):
        raise ValueError("target: last row must be [0, 0, 0, 1]")
    return T, lead


def batch_array(B: int, tail: tuple, dtype: Any, device: Any, batch_fastest: bool) -> wp.array:
    """A zeroed Warp array of shape (B, *tail); with ``batch_fastest`` the first index is
    the fastest in memory (a transposed view), which coalesces a CUDA warp's accesses of
    ``a[b, ...]`` over consecutive ``b``."""
    shape = (int(B),) + tuple(int(t) for t in tail)
    if not batch_fastest or len(shape) == 1:
        return wp.zeros(shape, dtype=dtype, device=device)
    return wp.zeros(shape[::-1], dtype=dtype, device=device).transpose()


class IKObjective:
    """Pose error, U_f (eq. 3.15) and U_A (eq. 3.19) with gradients for B configurations.

    Owns the device buffers of one batch; ``q`` (B, n_dof) is the current batch. Arrays are
    Warp arrays on ``device``.
    """

    def __init__(self, robot: Any, frame: int | str, n: int, *, world: Any = None,
                 weights: IKWeights | None = None, eps: float | None = None,
                 q_default: Any = None, kappa: Any = None, lam: float = 0.7,
                 device: Any = None, dtype: Any = np.float64, batch_fastest: bool = False,
                 orientation: str = "full", free_axis: Any = (0.0, 0.0, 1.0)):
        init_warp()
        self.robot = get_robot(robot)
        self.frame = self.robot.frame_index(frame)
        collision.check_world(self.robot, world)
        self.world = world
        self.weights = weights or IKWeights()
        self.weights.validate()
        #: the kernels' orientation mode and free axis (:attr:`IKOptions.orientation`)
        self.orient, free_axis = orientation_args(orientation, free_axis)
        self.device = resolve_device(device)
        self.scalar = scalar_type(dtype)
        self.npdt = numpy_dtype(self.scalar)
        self.B, self.n = int(n), self.robot.n_dof
        self.t = put_model(self.robot, self.device, self.npdt)
        self.fk = fk_kernels.kernels(self.scalar)
        self.axis = self.fk.vec3(*(float(v) for v in free_axis))
        self.kk = ik_kernels.kernels(self.scalar)
        self.pk = path_kernels.kernels(self.scalar)
        self.limits = self.t.limits
        self.eps = real_number(eps, "eps", self.npdt) if eps is not None else (
            float(max(world.resolution, 0.01)) if world is not None else 0.01)
        dev, sc, B, n = self.device, self.scalar, self.B, self.n
        #: per-configuration arrays with the configuration index fastest in memory (CUDA:
        #: a warp's loads and stores coalesce); the kernels index them [b, ...] either way
        self.batch_fastest = bool(batch_fastest)

        def batch(tail: tuple, dt: Any) -> wp.array:
            return batch_array(B, tail, dt, dev, self.batch_fastest)

        self.q = batch((n,), sc)
        self.frames = batch((self.robot.n_frames,), self.fk.mat44)
        self.jac = batch((6, n), sc)
        self.target = wp.zeros(B, dtype=self.fk.mat44, device=dev)
        self.err = batch((6,), sc)
        self.pos_err = wp.zeros(B, dtype=sc, device=dev)
        self.rot_err = wp.zeros(B, dtype=sc, device=dev)
        self.cost_f = wp.zeros(B, dtype=sc, device=dev)
        self.grad_f = batch((n,), sc)
        self.cost_a = wp.zeros(B, dtype=sc, device=dev)
        self.grad_a = batch((n,), sc)
        self.coll_cost = wp.zeros(B, dtype=sc, device=dev)
        self.coll_grad = batch((n,), sc)
        self.cm = collision.collision_model(self.robot, world, device=dev, dtype=self.npdt)
        w = self.weights
        #: whether U_A has a collision term: spheres, and a world (weighted) or self pairs
        #: (weighted); without one the collision kernels are not launched (their cost is 0)
        self.collides = bool(self.cm.n_spheres > 0 and (
            (world is not None and w.world > 0) or (self.cm.n_pairs > 0 and w.self > 0)))
        self._launches: dict = {}
        self.set_default(q_default)
        #: elastic compensation rows (None: the rigid robot)
        self.compensation: CompensationRows | None = None
        if kappa is not None:
            self.compensation = CompensationRows(self.t, B, 1, 1, kappa, lam)
        #: (B,) largest DH row change of the last torque update [rad] (elastic only)
        self.delta = self.compensation.delta if self.compensation is not None else None

    def _launch(self, key: tuple, kernel: Any, inputs: list, outputs: list) -> None:
        """Launch with a recorded command (cuts Warp's per-launch argument packing);
        ``key`` names every argument that may change between calls."""
        launch = self._launches.get(key)
        if launch is None:
            if len(self._launches) > 32:
                self._launches.clear()
            launch = wp.launch(kernel, dim=self.B, inputs=inputs, outputs=outputs,
                               device=self.device, record_cmd=True)
            self._launches[key] = launch
        launch.launch()

    def set_default(self, q_default: Any) -> None:
        """Default pose (n_dof,) or per configuration (B, n_dof); None: mid of the limits
        (projected onto the linear limits)."""
        from jwarp.core.limits import project_numpy

        if q_default is None:
            q_default = project_numpy(self.robot, self.robot.joint_limits.mean(axis=1))
        a = real_array(q_default, "q_default")
        if a.shape not in ((self.n,), (self.B, self.n)) or not np.all(np.isfinite(a)):
            raise ValueError(f"q_default: expected finite values of shape ({self.n},) or "
                             f"({self.B}, {self.n}), got {a.shape}")
        a = finite_as(a.reshape(-1, self.n), self.npdt, "q_default")
        self.default_stride = int(len(a) > 1)
        self.q_default: wp.array = wp.array(a, dtype=self.scalar, device=self.device)

    def set_q(self, q: np.ndarray, keep_rho: bool = False) -> None:
        """Copy q (B, n_dof) into the batch; ``keep_rho`` keeps the elastic DH rows of the
        last iteration (compensation: one torque update per iteration)."""
        q = np.ascontiguousarray(q, dtype=self.npdt).reshape(self.B, self.n)
        if self.device.is_cpu and self.q.is_contiguous:
            self.q.numpy()[...] = q  # CPU arrays share memory with numpy
        else:
            wp.copy(self.q, wp.array(q, dtype=self.scalar, device=self.device))
        if not keep_rho and self.compensation is not None:
            self.compensation.reset()

    def set_target(self, target: np.ndarray) -> None:
        """target (B, 4, 4) poses of the frame."""
        wp.copy(self.target, wp.array(np.ascontiguousarray(target, dtype=self.npdt),
                                      dtype=self.fk.mat44, device=self.device))

    # ------------------------------------------------------------------ stages
    def evaluate_pose(self) -> None:
        """FK (elastic: at the compensation rows), then from those frames the Jacobian of
        the frame and the pose error/costs."""
        t = self.t
        comp = self.compensation
        rho = (comp.rows, 1, 2) if comp is not None else (t.dh0_3d, 0, 0)
        self._launch(("fk", id(rho[0])), self.fk.fk, [self.q, *rho, t.frame_struct],
                     [self.frames])
        w = self.weights
        self._launch(("pose", w.position, w.rotation), self.kk.pose_error,
                     [self.frames, self.q, self.target, self.scalar(w.position),
                      self.scalar(w.rotation), self.orient, self.axis, t.frame_struct,
                      t.chain(self.frame)],
                     [self.jac, self.err, self.pos_err, self.rot_err, self.cost_f, self.grad_f])

    def evaluate_aux(self) -> None:
        """U_A (world + self collision + closeness to the default pose) and its gradient at
        the frames of the last :meth:`evaluate_pose` (elastic: the same DH rows, followed
        by the iteration's one torque update of the rows)."""
        w = self.weights
        use = int(self.collides)
        comp = self.compensation
        # elastic: at the rows of evaluate_pose, then one torque update from them: inside
        # the collision launch on the CPU; on CUDA from evaluate_pose's frames, one thread
        # per (configuration, DH frame) (H100, 64 configurations: the fused update's serial
        # walk over the robot cost more than a second launch)
        fused = comp is not None and self.device.is_cpu
        if use:
            self.cm.cost(self.q, rho=comp, w_world=w.world, w_self=w.self, eps=self.eps,
                         grad=True, out_cost=self.coll_cost, out_grad=self.coll_grad,
                         update_rows=fused)
        if comp is not None and not (use and fused):
            comp.update(self.frames)
        self._launch(("aux", id(self.q_default), use, w.default), self.kk.aux_cost,
                     [self.q, self.q_default, self.default_stride, self.coll_cost,
                      self.coll_grad, use, self.scalar(w.default)],
                     [self.cost_a, self.grad_a])

    def reset_rows(self) -> None:
        """Elastic only: back to the nominal DH rows (a new solve)."""
        if self.compensation is not None:
            self.compensation.reset()

    def update_rows(self) -> None:
        """Elastic only: the iteration's torque update of the rows from the frames of the
        last :meth:`evaluate_pose`, without U_A (what :meth:`evaluate_aux` would do with
        it)."""
        if self.compensation is not None:
            self.compensation.update(self.frames)

    def project_limits(self) -> None:
        self._launch(("project",), self.pk.project, [self.limits], [self.q])

    def value_and_grad(self, q: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Host convenience: U_ik = U_f + U_A (eq. 3.19) (B,) and its gradient (B, n_dof)."""
        self.set_q(q)
        self.set_target(target)
        self.evaluate_pose()
        self.evaluate_aux()
        u = self.cost_f.numpy() + self.cost_a.numpy()
        g = self.grad_f.numpy() + self.grad_a.numpy()
        return u.astype(np.float64), g.astype(np.float64)


#: values of :attr:`IKOptions.orientation` -> the kernels' mode
ORIENTATIONS = {"full": ik_kernels.ORIENT_FULL, "none": ik_kernels.ORIENT_NONE,
                "axis": ik_kernels.ORIENT_AXIS}


def _task_rows(robot: RobotModel) -> np.ndarray:
    return np.array([0, 1, 5]) if robot.workspace_dim == 2 else np.arange(6)


def orientation_args(orientation: str, free_axis: Any) -> tuple[int, tuple]:
    """(the kernels' mode of ``orientation``, ``free_axis`` normalised (3,)); ValueError
    naming ``orientation`` (not a key of :data:`ORIENTATIONS`) or ``free_axis`` (not a
    finite nonzero 3-vector)."""
    if orientation not in ORIENTATIONS:
        raise ValueError(f"orientation: expected one of {', '.join(map(repr, ORIENTATIONS))}, "
                         f"got {orientation!r}")
    axis = real_array(free_axis, "free_axis").astype(np.float64)
    norm = float(np.linalg.norm(axis)) if axis.shape == (3,) else 0.0
    if axis.shape != (3,) or not np.all(np.isfinite(axis)) or norm < 1e-9:
        raise ValueError(f"free_axis: expected a finite nonzero vector (3,), got {free_axis!r}")
    return ORIENTATIONS[orientation], tuple(float(v) for v in axis / norm)


def check_single_world(world: Any) -> None:
    """ValueError naming ``world`` for a batch of worlds (:meth:`World.batch`): IK checks
    every target against one world (a batch would be checked as the union of its worlds);
    solve each world's targets with that world (``world.select(i)``)."""
    n = getattr(world, "n_worlds", 1) if world is not None else 1
    if n > 1:
        raise ValueError(f"world: a batch of {n} worlds; IK solves in one world (its "
                         f"targets would be checked against all {n}): solve per world, "
                         f"world.select(i)")


def _positive_int(v: Any, name: str, lo: int) -> int:
    if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, np.integer)) or v < lo:
        raise ValueError(f"{name}: expected an integer >= {lo}, got {v!r}")
    return int(v)


@renamed_options(max_iterations="iterations")
@dataclass
class IKOptions:
    """Options of :class:`IKSolver` and :func:`ik` (thesis 3.3.3).

    Attributes:
        n_starts: random seeds per target when :meth:`IKSolver.solve` gets none (uniform
            inside the limits).
        tol_pos, tol_rot: target tolerance [m] and [rad] (thesis: 1e-4 m, 1e-3 rad).
        margin: required clearance [m] (world and self), >= 0.
        eps: smoothing width of the collision clip [m], > 0 and >= margin (None: the
            world's voxel size, at least 0.01 and ``margin``).
        iterations: iterations per seed (projection + nullspace), >= 0.
        step: nullspace step alpha.
        max_step: the largest change of one joint per iteration [rad or m]; the whole step
            is scaled down to it.
        damping: mu of the damped pseudo-inverse.
        kappa, lam, tol_rho: elastic compensation (compliances [rad/(N m)] or None for the
            rigid robot, damping of the torque update in (0, 1], and the largest DH row
            change [rad] of the last update for a solution to count; module docstring).
        stop_when_solved: end once every target has a feasible seed (else run every seed
            until it is feasible or out of iterations).
        check_every: exact collision check of every on-target seed every this many
            iterations (seeds whose collision cost is below ``w c(margin)`` are checked at
            once).
        read_every: how often the host reads the solver's counters (to stop, and to size
            the gathered U_A launch), >= 1; None: every iteration on the CPU (a view, free),
            every ``check_every`` iterations on CUDA (a copy and a sync). Between reads
            the rigid robot's gathered launch keeps the last size with headroom (seeds
            beyond it take pose-only steps for an iteration), the elastic robot evaluates U_A
            of every seed; results may differ slightly, every returned solution is checked.
        seed: random seed of the starts (None: fresh entropy).
        weights: :class:`IKWeights` of U_f and U_A (None: the defaults).
        q_default: default pose of the closeness term, (n_dof,) or per seed
            (n_problems * n_seeds, n_dof) (None: the middle of the limits).
        freeze_solved: once a problem has a feasible seed, stop its other seeds (they keep
            their last state, infeasible): a problem is done when solved, and solved
            problems cost nothing more (default). A problem gets the first feasible seeds
            found instead of the lowest U_A among those found by the time every problem
            is solved (False: the thesis' multi-start; about half the solved targets per
            second on the Panda, benchmarks/bench_ik_converge.py).
        n_random_with_warm_start: random seeds per target (uniform inside the limits, from
            the solver's :attr:`IKSolver.rng`) added after a warm start's seeds, >= 0
            (:class:`IKSolver` ``warm_start``; unused without one).
        restart_after: re-seed a start whose pose error has not improved (by 10 %,
            measured as ``|e_v|^2 + 0.1 |e_w|^2``) for this many steps while off target,
            >= 1 (uniform inside the limits, Warp's random stream); None: never (a start
            then runs until feasible or out of iterations, the thesis' multi-start).
        max_restarts: re-seeds per start before it gives up, >= 0; a problem whose
            starts all gave up is done (with ``stop_when_solved`` the batch ends once every
            problem is solved or given up).
        orientation: what of the target's orientation counts: "full" (the pose),
            "none" (position only: ``rot_err`` is 0) or "axis" (the frame's
            ``free_axis`` must point along the target's; the rotation about it is free:
            ``rot_err`` is the angle between the axes).
        free_axis: (3,) the free axis of ``orientation="axis"`` in the frame's coordinates
            (normalised; default the tool axis z).
        allow_no_collision: solve without a collision model: a robot without collision
            spheres in a world (every solution is then world-collision-free) or in
            self-collision at its home configurations is accepted; False (default): either
            is a ValueError naming the robot and the link pairs
            (:func:`jwarp.world.model_check.check_collision_model`; CLI ``--no-collision``).
            Without a world a robot without spheres is plain kinematic IK, no error.

    ``validate()`` (also run on construction) raises ValueError/TypeError naming the field.
    """

    n_starts: int = 16
    tol_pos: float = 1e-4
    tol_rot: float = 1e-3
    margin: float = 0.0
    eps: float | None = None
    iterations: int = 200
    step: float = 1.0
    max_step: float = 0.5
    damping: float = 1e-3
    kappa: Any = None
    lam: float = 0.7
    tol_rho: float = 1e-6
    stop_when_solved: bool = True
    check_every: int = 5
    read_every: int | None = None
    seed: int | None = 0
    weights: IKWeights | None = None
    q_default: Any = None
    freeze_solved: bool = True
    n_random_with_warm_start: int = 0
    restart_after: int | None = 5
    max_restarts: int = 10
    orientation: str = "full"
    free_axis: Any = (0.0, 0.0, 1.0)
    allow_no_collision: bool = False

    def __post_init__(self) -> None:
        self.validate()

    def validate(self) -> None:
        """Check every field (ValueError/TypeError naming it); numbers become floats."""
        for name, lo in (("n_starts", 1), ("iterations", 0), ("check_every", 1),
                         ("n_random_with_warm_start", 0)):
            setattr(self, name, _positive_int(getattr(self, name), name, lo))
        if self.read_every is not None:
            self.read_every = _positive_int(self.read_every, "read_every", 1)
        if self.restart_after is not None:
            self.restart_after = _positive_int(self.restart_after, "restart_after", 1)
        self.max_restarts = _positive_int(self.max_restarts, "max_restarts", 0)
        _, self.free_axis = orientation_args(self.orientation, self.free_axis)
        for name in ("tol_pos", "tol_rot", "step", "max_step", "damping", "tol_rho"):
            v = getattr(self, name)
            if not (math.isfinite(real_number(v, name)) and v > 0):
                raise ValueError(f"{name}: expected a number > 0, got {v!r}")
            setattr(self, name, float(v))
        margin = real_number(self.margin, "margin")
        if not (math.isfinite(margin) and margin >= 0):
            raise ValueError(f"margin: expected a number >= 0 [m], got {margin!r}")
        self.margin = margin
        if self.eps is not None:
            eps = real_number(self.eps, "eps")
            if not (math.isfinite(eps) and eps > 0 and eps >= margin):
                raise ValueError(f"eps: must be > 0 and >= margin ({margin:g} m), got {eps:g}")
            self.eps = eps
        lam = real_number(self.lam, "lam")
        if not 0.0 < lam <= 1.0:
            raise ValueError(f"lam: expected a damping factor in (0, 1], got {self.lam!r}")
        self.lam = lam
        for name in ("stop_when_solved", "freeze_solved", "allow_no_collision"):
            v = getattr(self, name)
            if not isinstance(v, (bool, np.bool_)):
                raise TypeError(f"{name}: expected a bool, got {v!r}")
            setattr(self, name, bool(v))
        if self.seed is not None and (isinstance(self.seed, (bool, np.bool_))
                                      or not isinstance(self.seed, numbers.Integral)):
            raise TypeError(f"seed: expected an integer or None, got {self.seed!r}")
        if self.weights is not None:
            if not isinstance(self.weights, IKWeights):
                raise TypeError(f"weights: expected IKWeights, got {type(self.weights).__name__}")
            self.weights.validate()

    def eps_for(self, world: Any) -> float:
        """The smoothing width in use: ``eps`` or the default for ``world``."""
        if self.eps is not None:
            return self.eps
        return max(float(world.resolution) if world is not None else 0.0, 0.01, self.margin)


class IKSolver:
    """Batched collision-free IK of one frame, resident on one device.

    Holds ``n_problems`` targets x ``n_seeds`` seeds (``options.n_starts`` unless the seeds
    given to :meth:`solve` say otherwise): the cost buffers (:class:`IKObjective`), the
    per-seed state and result rows, and the recorded kernel launches. :meth:`solve` reuses
    all of them while the number of seeds stays the same (a different count reallocates).
    Options are read once, at construction.

    Per iteration (:mod:`jwarp.kernels.ik_step`): the pose error and Jacobian (rigid robot:
    one kernel walking the frame's chain; elastic: FK at the compensation rows), the list
    of active seeds whose pose is on target, U_A of those only (their collision costs in a
    gathered batch), the exact check of the candidates, and the projected DLS step of the
    active seeds. The host reads three counters (done seeds, solved problems, seeds on
    target) every iteration on the CPU (a view, free) and every ``check_every`` iterations
    on CUDA (a small copy and a sync): between two reads the rigid robot's gathered U_A
    launch keeps the size of the last read count with headroom (seeds beyond it wait an
    iteration), the elastic model evaluates U_A of every seed. The result rows are copied
    once at the end.

    Args:
        robot: robot name or RobotModel.
        frame: end-effector frame (name, end-effector alias or index).
        n_problems: targets per :meth:`solve` (>= 1).
        options: :class:`IKOptions` (None: the defaults).
        world: optional :class:`jwarp.world.World` (None: self-collision only).
        device: Warp device (None: Warp's default device, docs/api.md "Devices"); every
            kernel and check of the solve runs there.
        dtype: float type of the iteration (None: float64); the step's linear algebra and
            the feasibility check are float64 either way.
        warm_start: optional learned warm start (thesis 3.4): any object with a callable
            ``seeds(targets (P, 4, 4) numpy, world) -> (P, H, n_dof)`` (e.g. a loaded
            ``jwarp.learn`` IK network: H = 2 for twin heads). :meth:`solve` without
            ``seeds`` then starts from its H seeds per target followed by
            ``options.n_random_with_warm_start`` random ones (from :attr:`rng`); seeds given
            to :meth:`solve` win. A TypeError (no callable ``seeds``) or ValueError (its
            output is not (P, H, n_dof) finite values) names ``warm_start``.
    """

    def __init__(self, robot: Any, frame: int | str, n_problems: int,
                 options: IKOptions | None = None, world: Any = None, device: Any = None,
                 dtype: Any = None, warm_start: Any = None):
        init_warp()
        #: the warm start (None: random seeds); see the class docstring
        self.warm_start = check_warm_start(warm_start)
        self.robot = get_robot(robot)
        self.frame = self.robot.frame_index(frame)
        collision.check_world(self.robot, world)
        check_single_world(world)
        self.world = world
        self.n_problems = _positive_int(n_problems, "n_problems", 1)
        if options is None:
            options = IKOptions()
        elif not isinstance(options, IKOptions):
            raise TypeError(f"options: expected IKOptions, got {type(options).__name__}")
        options = dataclasses.replace(options)  # a copy (validated): later edits do not leak
        self.device = resolve_device(device)
        if not options.allow_no_collision:
            check_collision_model(self.robot, need_spheres=world is not None,
                                  what="IK in a world", device=self.device)
        self.options = options
        self.scalar = scalar_type(np.float64 if dtype is None else dtype)
        self.npdt = numpy_dtype(self.scalar)
        self.eps = options.eps_for(world)
        #: random generator of the seeds (from ``options.seed``); :meth:`reseed` resets it
        self.rng = np.random.default_rng(options.seed)
        self.planar = self.robot.workspace_dim == 2
        self.dk = step_kernels.dls_kernels(self.scalar, self.planar, self.robot.n_dof)
        self.ck = step_kernels.check_kernels(self.scalar, self.planar)
        self.limits = put_model(self.robot, self.device, self.scalar).limits
        self.limits64 = put_model(self.robot, self.device, np.float64).limits
        self.cm64 = collision.collision_model(self.robot, world, device=self.device,
                                              dtype=np.float64)
        w = options.weights or IKWeights()
        self.weights = w
        w_min = min([v for v in (w.world, w.self) if v > 0] or [0.0])
        # screen: a collision cost below w_min c(margin) means no sphere is within margin
        # (every term is >= 0); those get the exact check at once, the others every
        # check_every iterations
        self.screen = w_min * (self.eps - options.margin) ** 2 / (2.0 * self.eps)
        dev = self.device
        mat44 = fk_kernels.kernels(self.scalar).mat44
        self.targets = wp.zeros(self.n_problems, dtype=mat44, device=dev)
        self.best = wp.zeros((self.n_problems, 2), dtype=wp.int32, device=dev)
        self.solved = wp.zeros(self.n_problems, dtype=wp.int32, device=dev)
        #: [done, frozen or given-up seeds, solved problems, seeds on target this
        #: iteration, problems whose seeds all gave up]
        self.counts = wp.zeros(4, dtype=wp.int32, device=dev)
        self._counts_host = (self.counts if dev.is_cpu else
                             wp.zeros(4, dtype=wp.int32, device="cpu", pinned=True))
        self.halt = wp.zeros(1, dtype=wp.int32, device=dev)
        self.n_seeds = 0
        self.objective: IKObjective | None = None
        self._allocate(options.n_starts)

    # ------------------------------------------------------------------ buffers
    def _allocate(self, n_seeds: int) -> None:
        """Buffers and recorded launches for ``n_seeds`` seeds per problem."""
        o, dev = self.options, self.device
        P, S, n = self.n_problems, int(n_seeds), self.robot.n_dof
        B = P * S
        self.n_seeds, self.B = S, B
        fast = dev.is_cuda  # configuration index fastest in memory (coalesced)
        obj = IKObjective(self.robot, self.frame, B, world=self.world, weights=o.weights,
                          eps=self.eps, q_default=o.q_default, kappa=o.kappa, lam=o.lam,
                          device=dev, dtype=self.scalar, batch_fastest=fast,
                          orientation=o.orientation, free_axis=o.free_axis)
        self.objective = obj
        i32 = wp.int32
        self.on = wp.zeros(B, dtype=i32, device=dev)
        #: per seed: 0 active, 1 done (feasible), 2 frozen (``freeze_solved``)
        self.done = wp.zeros(B, dtype=i32, device=dev)
        self.iterations = wp.zeros(B, dtype=i32, device=dev)
        rs = step_kernels.RestartArgs()
        rs.after = int(o.restart_after or 0)
        rs.max_restarts = int(o.max_restarts)
        rs.progress = wp.float64(RESTART_PROGRESS)
        rs.on_cost = wp.float64(o.tol_pos ** 2 + step_kernels.W_ROT * o.tol_rot ** 2)
        rs.seed = wp.zeros(1, dtype=i32, device=dev)
        # the solve's seed is staged here (CUDA: pinned, copied without a sync)
        self._seed_host = (rs.seed if dev.is_cpu else
                           wp.zeros(1, dtype=i32, device="cpu", pinned=True))
        rs.best = wp.zeros(B, dtype=wp.float64, device=dev)
        rs.stall = wp.zeros(B, dtype=i32, device=dev)
        rs.count = wp.zeros(B, dtype=i32, device=dev)
        rs.gave = wp.zeros(P, dtype=i32, device=dev)
        #: the re-seeding state (:class:`jwarp.kernels.ik_step.RestartArgs`)
        self.restart = rs
        self.out = batch_array(B, (n + step_kernels.N_EXTRA,), wp.float64, dev, fast)
        # the seeds whose pose is on target, gathered for their collision costs
        self.idx = wp.zeros(B, dtype=i32, device=dev)
        self.q_near = batch_array(B, (n,), self.scalar, dev, fast)
        self.near_cost = wp.zeros(B, dtype=self.scalar, device=dev)
        self.near_grad = batch_array(B, (n,), self.scalar, dev, fast)
        self._near_views: dict = {}
        comp = obj.compensation
        nf = self.robot.n_frames
        self._rows = comp.rows if comp is not None else wp.zeros((1, nf, 9), dtype=self.scalar,
                                                                  device=dev)
        self._delta = obj.delta if comp is not None else wp.zeros(1, dtype=self.scalar,
                                                                  device=dev)
        ck, cm = self.ck, self.cm64
        tab = ck.CheckTables()
        tab.model, tab.spheres = cm.model_args
        tab.world = cm.world_struct
        tab.use_world = int(self.world is not None and cm.n_spheres > 0)
        tab.use_self = int(cm.n_pairs > 0)
        tab.limits = self.limits64
        tab.limit_tol = wp.float64(LIMIT_TOL)
        self._check_tables = tab
        sc = ck.CheckScratch()
        k64 = fk_kernels.kernels(wp.float64)
        sc.q64 = batch_array(B, (n,), wp.float64, dev, fast)
        sc.rho64 = (batch_array(B, (nf, 5), wp.float64, dev, fast) if comp is not None else
                    wp.zeros((1, nf, 5), dtype=wp.float64, device=dev))
        self._scratch_owner: list = []
        sc.frames = self._scratch(B, nf, k64.mat44)
        sc.xs = self._scratch(B, max(cm.n_spheres, 1), k64.vec3)
        self._check_scratch = sc
        self._launches: dict = {}

    def _scratch(self, B: int, m: int, dtype: Any) -> wp.array:
        """(B, m) scratch of the check: on CUDA frame-major (coalesced); on the CPU, whose
        threads run one after another, one row seen by every configuration (stride 0)."""
        if self.device.is_cuda:
            return wp.zeros((m, B), dtype=dtype, device=self.device).transpose()
        row = wp.zeros((1, m), dtype=dtype, device=self.device)
        self._scratch_owner.append(row)  # owns the memory of the view
        return wp.array(ptr=row.ptr, shape=(B, m), strides=(0, row.strides[1]), dtype=dtype,
                        device=self.device)

    def _sync_world(self) -> None:
        """Objects added to or removed from the world since the last solve: the new world
        struct in the check tables and the cost (recorded launches re-recorded); moved
        objects need nothing (updated in place)."""
        ws = self.cm64.world_struct
        if self._check_tables.world is not ws:
            self._check_tables.world = ws
            self._launches.clear()

    def _launch(self, key: Any, kernel: Any, dim: int, inputs: list) -> None:
        launch = self._launches.get(key)
        if launch is None:
            launch = wp.launch(kernel, dim=dim, inputs=inputs, device=self.device,
                               record_cmd=True)
            self._launches[key] = launch
        launch.launch()

    def _read_counts(self) -> np.ndarray:
        """The counters on the host (CPU: a view; CUDA: a copy, which waits for the
        device)."""
        if self.device.is_cpu:
            return self._counts_host.numpy()
        wp.copy(self._counts_host, self.counts)
        wp.synchronize_device(self.device)
        return self._counts_host.numpy()

    def _pose(self) -> None:
        """Rigid robot: error and Jacobian of every active seed (one kernel)."""
        obj = self.objective
        t = obj.t
        self._launch("pose", self.ck.pose, self.B, [
            obj.q, obj.target, self.halt, self.done, t.frame_struct, t.chain(self.frame),
            t.dh0_3d, obj.orient, obj.axis, obj.jac, obj.err])

    def _near(self, cap: int) -> None:
        """List the on-target seeds, at most ``cap`` of them (the others wait)."""
        o, obj = self.options, self.objective
        self._launch(("near", cap), self.ck.near, self.B, [
            obj.err, o.tol_pos, o.tol_rot, cap, self.halt, self.done, self.on, self.counts,
            self.idx, obj.coll_cost, obj.cost_a, obj.grad_a])

    def _gather_size(self, n_near: int) -> int:
        """Size of the gathered U_A launch for ``n_near`` seeds: a power of two above 32
        seeds (so a few recorded launches serve every count), at most B."""
        n_near = max(int(n_near), 1)
        return min(self.B, n_near if self.B <= 32 else 1 << (n_near - 1).bit_length())

    def _near_aux(self, n_near: int) -> None:
        """U_A and its gradient of the ``n_near`` listed seeds (at most :meth:`_gather_size`
        of them): their collision costs in a gathered batch."""
        obj, w = self.objective, self.weights
        K = self._gather_size(n_near)
        views = self._near_views.get(K)
        if views is None:
            views = self._near_views[K] = (self.q_near[:K], self.near_cost[:K],
                                           self.near_grad[:K])
        qk, ck, gk = views
        use = int(obj.collides)
        if use:
            self._launch(("gather", K), self.ck.gather, K, [obj.q, self.idx, self.counts, qk])
            obj.cm.cost(qk, w_world=w.world, w_self=w.self, eps=obj.eps, grad=True,
                        out_cost=ck, out_grad=gk)
        self._launch(("scatter", K), self.ck.scatter_aux, K, [
            obj.q, obj.q_default, obj.default_stride, self.idx, self.counts, ck, gk, use,
            self.scalar(w.default), obj.coll_cost, obj.cost_a, obj.grad_a])

    def _check(self, full: bool) -> None:
        o, obj = self.options, self.objective
        self._launch(("check", bool(full)), self.ck.check, self.B, [
            obj.q, obj.err, obj.cost_a, obj.coll_cost, self._delta, self._rows,
            int(obj.compensation is not None), o.tol_pos, o.tol_rot, o.tol_rho, self.screen,
            int(full), o.margin, self.n_seeds, self.halt, self.iterations,
            self._check_tables, self._check_scratch,
            self.on, self.done, self.solved, self.counts, self.out])

    def _step(self) -> None:
        o, obj = self.options, self.objective
        self._launch("step", self.dk.step, self.B, [
            obj.jac, obj.err, obj.grad_a, self.on, self.solved, self.n_seeds,
            int(o.freeze_solved), int(o.stop_when_solved), self.n_problems, o.damping ** 2,
            o.step, o.max_step, self.limits, obj.q, self.done, self.counts,
            self.iterations, self.halt, self.restart])

    # ------------------------------------------------------------------ solve
    def reseed(self, seed: int | None) -> None:
        """Restart the random seeds' generator from ``seed``."""
        self.rng = np.random.default_rng(seed)

    def solve(self, targets: Any, seeds: Any = None, *,
              callback: Callable[[int, np.ndarray], None] | None = None) -> IKResult:
        """Solve the ``n_problems`` targets.

        Args:
            targets: poses (n_problems, 4, 4) in the base frame [m], or one pose (4, 4)
                for every problem; planar robots use x, y and the rotation about z.
            seeds: initial configurations (n_problems, n_seeds, n_dof) or the same for every
                problem (n_seeds, n_dof) or (n_dof,); None: with a ``warm_start``, its H
                seeds per problem and ``options.n_random_with_warm_start`` random ones
                (numpy, from :attr:`rng`); without, ``options.n_starts`` random seeds per
                problem, drawn on the device (uniform in the box, redrawn for the linear
                limits; Warp's random stream, seeded from :attr:`rng`). Every seed is
                projected onto the joint limits first.
            callback: ``callback(iteration, q (B, n_dof))`` after every evaluation (reads q
                back every iteration).

        Returns:
            :class:`IKResult` with the leading dims of ``targets`` (a (4, 4) target with
            ``n_problems == 1``: no leading dim).
        """
        t0 = time.perf_counter()
        self._sync_world()
        T, lead = _targets(targets)
        P, model = self.n_problems, self.robot
        if len(T) != P:
            if len(T) != 1:
                raise ValueError(f"target: expected {P} poses (the solver's n_problems) or "
                                 f"one, got {len(T)}")
            T = np.broadcast_to(T, (P, 4, 4))
            lead = (P,)
        T = finite_as(T, self.npdt, "target")  # finite in the solver's dtype
        q0 = None
        S = self.options.n_starts
        if seeds is not None:
            q0 = finite_as(_seeds(model, seeds, P, "seeds"), self.npdt, "seeds")
            S = q0.shape[1]
        elif self.warm_start is not None:
            q0 = finite_as(warm_start_seeds(model, self.warm_start, T, self.world,
                                            self.options.n_random_with_warm_start, self.rng),
                           self.npdt, "warm_start")
            S = q0.shape[1]
        if q0 is not None and model.has_harmonic:  # the kernels work in the links' joint space
            q0 = transmitted(model, q0)
        if S != self.n_seeds:
            self._allocate(S)
        obj, dev, B = self.objective, self.device, self.B
        if q0 is None:  # random seeds, drawn on the device
            obj.reset_rows()
            wp.launch(self.dk.sample, dim=B, inputs=[int(self.rng.integers(1 << 31)),
                                                     self.limits],
                      outputs=[obj.q], device=dev)
        else:
            obj.set_q(q0.reshape(B, -1))
        obj.project_limits()
        if dev.is_cpu:
            self.targets.numpy()[...] = T  # CPU arrays share memory with numpy
        else:
            wp.copy(self.targets, wp.array(T, dtype=self.targets.dtype, device=dev))
        self._launch("repeat", self.ck.repeat_targets, B, [self.targets, S, obj.target])
        self._seed_host.numpy()[0] = int(self.rng.integers(1 << 31))  # this solve's re-seeds
        if not dev.is_cpu:
            wp.copy(self.restart.seed, self._seed_host)
        self._launch("reset", self.ck.reset, B, [P, self.done, self.on, self.iterations,
                                                self.solved, self.counts, self.halt,
                                                self.restart])
        o = self.options
        rigid = obj.compensation is None
        # the counters are read every iteration on the CPU (a view: free) and on CUDA every
        # check_every iterations (a copy that waits for the device). Between two reads the
        # rigid robot gathers the on-target seeds into a launch sized from the last read
        # count with headroom (seeds beyond it wait an iteration); the elastic robot
        # evaluates U_A of every seed
        k_read = o.read_every or (1 if dev.is_cpu else o.check_every)
        every = k_read == 1 or (rigid and callback is not None)
        cap = self.B if every else self._gather_size(2 * 32)

        def over(c: np.ndarray) -> bool:
            return bool(c[0] >= B or (o.stop_when_solved and c[1] + c[3] >= P))

        for it in range(o.iterations + 1):
            last = it == o.iterations
            read = every or it % k_read == 0
            if rigid:
                self._pose()
            else:
                obj.evaluate_pose()
            near = True
            if last:  # U_A of every seed: the result rows of the unsolved ones carry it
                obj.evaluate_aux()
            elif rigid:
                self._near(self.B if read else cap)
                if read:
                    c = self._read_counts()
                    if not every and over(c):  # solved at the last check (device halted)
                        break
                    near = c[2] > 0
                    if near:
                        self._near_aux(int(c[2]))
                    cap = self._gather_size(2 * max(int(c[2]), 32))
                else:
                    self._near_aux(cap)
            elif every:
                self._near(self.B)
                c = self._read_counts()
                near = c[2] > 0
                if near:
                    obj.evaluate_aux()
                else:
                    obj.update_rows()
            else:
                obj.evaluate_aux()
            if callback is not None:
                callback(it, obj.q.numpy().astype(np.float64))
            if near:
                self._check(it % o.check_every == 0 or last)
            if last:
                break
            if every or callback is not None or (not rigid and read):
                if over(self._read_counts()):
                    break
            self._step()
        self._launch("finalize", self.ck.finalize, B, [obj.q, obj.err, obj.cost_a, self.done,
                                                       self.iterations, o.iterations,
                                                       self.out])
        self._launch("select", self.ck.select, P, [self.out, S, model.n_dof, self.best])
        out = self.out.numpy().copy() if dev.is_cpu else self.out.numpy()
        if self.npdt != np.float64:  # a float32 value clamped to a limit may lie outside
            lo, hi = model.joint_limits[:, 0], model.joint_limits[:, 1]  # the float64 one
            np.clip(out[:, :model.n_dof], lo, hi, out=out[:, :model.n_dof])
        best = self.best.numpy().copy() if dev.is_cpu else self.best.numpy()
        res = IKResult.from_rows(out, best, model.n_dof, P, S, time.perf_counter() - t0)
        if model.has_harmonic:  # back to the commanded joint values
            res = dataclasses.replace(res, q=untransmitted(model, res.q),
                                      all_q=untransmitted(model, res.all_q))
        return res.reshaped(lead)


def ik(robot: Any, frame: int | str, target: Any, *, world: Any = None, seeds: Any = None,
       device: Any = None, dtype: Any = np.float64,
       callback: Callable[[int, np.ndarray], None] | None = None, warm_start: Any = None,
       options: IKOptions | None = None, **overrides: Any) -> IKResult:
    """Collision-free IK of ``frame`` onto ``target`` with random multi-starts: one
    :class:`IKSolver` solve.

    Args:
        robot: robot name or RobotModel.
        frame: end-effector frame (name, end-effector alias or index).
        target: pose(s) (4, 4) or (..., 4, 4) in the base frame [m].
        world: optional :class:`jwarp.world.World` (None: self-collision only).
        seeds: start configurations (n_dof,), (n_starts, n_dof) or (T, n_starts, n_dof)
            instead of random ones (the old name ``initial`` warns, for one release).
        device, dtype: Warp device (None: Warp's default device, as :class:`IKSolver`;
            docs/api.md "Devices") and float type.
        callback: ``callback(iteration, q (B, n_dof))`` after every evaluation.
        warm_start: optional learned warm start (:class:`IKSolver`'s ``warm_start``: an
            object with ``seeds(targets (T, 4, 4), world) -> (T, H, n_dof)``): the seeds
            are its H per target followed by ``n_random_with_warm_start`` random ones
            (numpy, from ``seed``) instead of ``n_starts`` random ones; ``seeds`` win.
        options: :class:`IKOptions` (None: its defaults); not modified.
        **overrides: any field of :class:`IKOptions` as a keyword (``n_starts=32``,
            ``tol_pos=1e-5``, ``seed=1``, ...): the options are
            ``dataclasses.replace(options, **overrides)``, so an override wins over the same
            field of ``options``; ``ik(r, f, T, n_starts=8)`` equals
            ``ik(r, f, T, options=IKOptions(n_starts=8))``.

    Raises:
        ValueError: unknown frame, bad target/seed shapes, world dimension mismatch, bad
            options, a warm start's output that is not (T, H, n_dof) finite values.
        TypeError: an override that is not a field of :class:`IKOptions` (named, with the
            list of fields), ``options`` not an :class:`IKOptions`, a ``warm_start``
            without a callable ``seeds``.
    """
    t0 = time.perf_counter()
    if "initial" in overrides:   # the old name of seeds (one release)
        given = {"initial": overrides.pop("initial")}
        if seeds is not None:
            given["seeds"] = seeds
        seeds = translate("ik()", {"initial": "seeds"}, given)["seeds"]
    init_warp()
    check_warm_start(warm_start)
    model = get_robot(robot)
    fi = model.frame_index(frame)
    collision.check_world(model, world)
    check_single_world(world)
    T, lead = _targets(target)
    opts = with_overrides("ik", IKOptions, options, overrides)
    seed = opts.seed
    finite_as(T, numpy_dtype(scalar_type(dtype)), "target")  # before the seeds' check
    n_seeds = opts.n_starts
    if seeds is not None:
        q0 = _seeds(model, seeds, len(T), "seeds")
        finite_as(q0, numpy_dtype(scalar_type(dtype)), "seeds")
        n_seeds = q0.shape[1]
    elif warm_start is not None:  # its seeds, then random ones from numpy's stream
        q0 = warm_start_seeds(model, warm_start, T, world, opts.n_random_with_warm_start,
                              np.random.default_rng(seed))
        finite_as(q0, numpy_dtype(scalar_type(dtype)), "warm_start")
        n_seeds = q0.shape[1]
    else:  # numpy's random stream (the seeds ik() has always drawn)
        q0 = sample_within_limits(model, len(T) * n_seeds,
                                  np.random.default_rng(seed)).reshape(len(T), n_seeds, -1)
    opts.n_starts = n_seeds
    key = _solver_key(model, fi, len(T), opts, world, device, dtype)
    solver = _SOLVERS.pop(key, None) if key is not None else None  # in use: not shared
    if solver is None:
        solver = IKSolver(model, fi, len(T), opts, world=world, device=device, dtype=dtype)
    solver.reseed(seed)  # a cached solver: the same re-seeds as a new one
    res = solver.solve(T, q0, callback=callback)
    if key is not None:
        _SOLVERS[key] = solver
        while len(_SOLVERS) > SOLVER_CACHE_SIZE:
            _SOLVERS.pop(next(iter(_SOLVERS)))
    return res.reshaped(lead, time.perf_counter() - t0)


#: a step counts as progress (resets a start's stall count) when it brings the pose cost
#: below this fraction of the start's best (:attr:`IKOptions.restart_after`)
RESTART_PROGRESS = 0.9

#: :func:`ik` keeps this many small solvers (<= :data:`SOLVER_CACHE_MAX_BATCH` seeds) for
#: calls with the same robot, frame, sizes, world, device, dtype and options (a solver's
#: set-up costs about as much as a small solve on the CPU)
SOLVER_CACHE_SIZE = 8
SOLVER_CACHE_MAX_BATCH = 4096
_SOLVERS: "dict[tuple, IKSolver]" = {}


def _solver_key(model: RobotModel, frame: int, n_problems: int, opts: IKOptions, world: Any,
                device: Any, dtype: Any) -> tuple | None:
    """Cache key of a solver for these arguments (None: do not cache). The cached solver
    holds the robot and the world, so their ids stay theirs while it is cached."""
    if n_problems * opts.n_starts > SOLVER_CACHE_MAX_BATCH:
        return None

    def arr(a: Any) -> Any:
        if a is None:
            return None
        a = np.asarray(a, np.float64)
        return a.shape, a.tobytes()

    w = opts.weights
    fields = tuple(getattr(opts, f.name) for f in dataclasses.fields(opts)
                   if f.name not in ("seed", "weights", "kappa", "q_default"))
    return (id(model), frame, n_problems, fields, id(world), str(resolve_device(device)),
            scalar_type(dtype).__name__, None if w is None else dataclasses.astuple(w),
            arr(opts.kappa), arr(opts.q_default))


def _seeds(model: RobotModel, initial: Any, nT: int, name: str = "initial") -> np.ndarray:
    a = real_array(initial, name)
    n = model.n_dof
    if a.ndim == 1:
        a = a[None, None]
    elif a.ndim == 2:
        a = a[None]
    if a.ndim != 3 or a.shape[-1] != n or a.shape[0] not in (1, nT) or a.shape[1] == 0:
        raise ValueError(f"{name}: expected seeds ({n},), (n_starts, {n}) or ({nT}, n_starts, "
                         f"{n}), got {np.shape(initial)}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name}: contains NaN or inf")
    return np.array(np.broadcast_to(a, (nT,) + a.shape[1:]))


# ------------------------------------------------------------------ warm starts
def check_warm_start(warm_start: Any, name: str = "warm_start") -> Any:
    """``warm_start`` itself if it is None or has a callable ``seeds``, else a TypeError
    naming ``name``. A warm start (duck-typed; e.g. ``jwarp.learn.ik_net.IKNet``) is any
    object with ``seeds(targets (P, 4, 4) numpy float64, world) -> (P, H, n_dof)``: H
    initial configurations per target (a twin-headed network: 2)."""
    if warm_start is not None and not callable(getattr(warm_start, "seeds", None)):
        raise TypeError(f"{name}: expected an object with a callable seeds(targets, world) "
                        f"(e.g. a loaded IK network), got {type(warm_start).__name__}")
    return warm_start


def warm_start_seeds(model: RobotModel, warm_start: Any, targets: np.ndarray, world: Any,
                     n_random: int = 0, rng: np.random.Generator | None = None,
                     name: str = "warm_start") -> np.ndarray:
    """Seeds (P, H + n_random, n_dof) for the targets (P, 4, 4): the warm start's H per
    target (checked: shape (P, H, n_dof), H >= 1, finite; a ValueError naming ``name``
    otherwise), then ``n_random`` uniform ones inside the limits drawn from ``rng``."""
    check_warm_start(warm_start, name)
    T = np.ascontiguousarray(targets, dtype=np.float64).reshape(-1, 4, 4)
    P, n = len(T), model.n_dof
    raw = warm_start.seeds(T.copy(), world)
    if hasattr(raw, "detach") and hasattr(raw, "cpu"):  # a torch tensor
        raw = raw.detach().cpu().numpy()
    try:
        a = np.asarray(raw, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise ValueError(f"{name}: seeds() returned {type(raw).__name__}, not an array of "
                         f"numbers ({e})") from None
    if a.ndim == 2 and a.shape == (P, n):  # one seed per target
        a = a[:, None]
    if a.ndim != 3 or a.shape[0] != P or a.shape[2] != n or a.shape[1] == 0:
        raise ValueError(f"{name}: seeds() must return ({P}, H, {n}) joint values for {P} "
                         f"targets of '{model.name}', got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name}: seeds() returned NaN or inf")
    if n_random:
        rng = np.random.default_rng() if rng is None else rng
        extra = sample_within_limits(model, P * int(n_random), rng).reshape(P, int(n_random), n)
        a = np.concatenate([a, extra], axis=1)
    return np.ascontiguousarray(a)


def select_best(feasible: np.ndarray, errs: np.ndarray) -> np.ndarray:
    """Host twin of the device selection (:mod:`jwarp.kernels.ik_step` ``select``):
    feasible (P, S) bool, errs (P, S, 3) [|e_v|, |e_w|, U_A] -> (P,) chosen seed: the
    feasible one with the lowest U_A, else the smallest |e_v| + 0.1 |e_w|."""
    key_f = np.where(feasible, errs[..., 2], np.inf)
    key_i = errs[..., 0] + errs[..., 1] * 0.1
    return np.where(feasible.any(1), np.argmin(key_f, axis=1), np.argmin(key_i, axis=1))
