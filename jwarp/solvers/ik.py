"""Collision-free inverse kinematics: the two-stage solver of thesis 3.3.3 (eq. 3.21-3.24).

Stage 1 (projection, eq. 3.21-3.23): ``q <- q + J^+ e`` with the 6D error
``e = [p_T - p; log(R_T R^T)]`` of the end-effector frame and the damped pseudo-inverse
``J^+ = J^T (J J^T + mu^2 I)^-1`` of the geometric Jacobian (planar robots use the rows
``v_x, v_y, w_z`` only). Stage 2 (eq. 3.24): once a configuration is on the target
(``|e_v| < tol_pos``, ``|e_w| < tol_rot``) it descends ``U_A`` (world + self collision +
closeness to a default pose, eq. 3.19) inside the Jacobian's nullspace,
``q <- q + J^+ e - alpha (I - J^+ J) dU_A/dq``, the ``J^+ e`` term pulling it back onto the
target manifold. Every step is clamped per joint and projected onto the joint limits.

A configuration is *feasible* when it is on the target, collision-free with ``margin``
(world and self) and within the limits; each multi-start stops when feasible. The batch
holds ``T`` targets x ``n_starts`` random seeds; :func:`ik` returns per target the
feasible solution with the lowest U_A (or the best infeasible one, flagged).

With ``kappa`` the robot is the elastic model (elastic paper section V): one torque update
per iteration from the DH rows kept from the previous iteration; frames and Jacobians at
those rows, gradients with the rows fixed; "on target" also requires the torque update to
have converged (largest DH change < ``tol_rho``).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np
import warp as wp

from jwarp.core.arrays import finite_as, init_warp, real_array, real_number, resolve_device
from jwarp.core.device import numpy_dtype, scalar_type, tables
from jwarp.kernels import fk as fk_kernels
from jwarp.kernels import ik as ik_kernels
from jwarp.kernels import path as path_kernels
from jwarp.model import RobotModel
from jwarp.registry import robot as get_robot
from jwarp.kinematics.compensation import CompensationRows
from jwarp.core.limits import limit_tables, sample_within_limits, within_limits
from jwarp.solvers.planner import collision_free
from jwarp.world import collision


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
    (projection + nullspace); start_index (T,); n_feasible (T,) feasible starts;
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
    if not np.allclose(R @ np.swapaxes(R, 1, 2), np.eye(3), atol=1e-6) or \
            not np.allclose(np.linalg.det(R), 1.0, atol=1e-6):
        raise ValueError("target: rotation part is not a rotation matrix")
    if not np.allclose(T[:, 3], [0, 0, 0, 1]):
        raise ValueError("target: last row must be [0, 0, 0, 1]")
    return T, lead


class IKObjective:
    """Pose error, U_f (eq. 3.15) and U_A (eq. 3.19) with gradients for B configurations.

    Owns the device buffers of one batch; ``q`` (B, n_dof) is the current batch. Arrays are
    Warp arrays on ``device``.
    """

    def __init__(self, robot: Any, frame: int | str, n: int, *, world: Any = None,
                 weights: IKWeights | None = None, eps: float | None = None,
                 q_default: Any = None, kappa: Any = None, lam: float = 0.7,
                 device: Any = None, dtype: Any = np.float64):
        init_warp()
        self.robot = get_robot(robot)
        self.frame = self.robot.frame_index(frame)
        collision.check_world(self.robot, world)
        self.world = world
        self.weights = weights or IKWeights()
        self.weights.validate()
        self.device = resolve_device(device)
        self.scalar = scalar_type(dtype)
        self.npdt = numpy_dtype(self.scalar)
        self.B, self.n = int(n), self.robot.n_dof
        self.t = tables(self.robot, self.device, self.npdt)
        self.fk = fk_kernels.kernels(self.scalar)
        self.kk = ik_kernels.kernels(self.scalar)
        self.pk = path_kernels.kernels(self.scalar)
        self.limits = limit_tables(self.robot, self.device, self.scalar)
        self.eps = real_number(eps, "eps", self.npdt) if eps is not None else (
            float(max(world.voxel_size, 0.01)) if world is not None else 0.01)
        dev, sc, B, n = self.device, self.scalar, self.B, self.n
        self.q = wp.zeros((B, n), dtype=sc, device=dev)
        self.frames = wp.zeros((B, self.robot.n_frames), dtype=self.fk.mat44, device=dev)
        self.jac = wp.zeros((B, 6, n), dtype=sc, device=dev)
        self.target = wp.zeros(B, dtype=self.fk.mat44, device=dev)
        self.err = wp.zeros((B, 6), dtype=sc, device=dev)
        self.pos_err = wp.zeros(B, dtype=sc, device=dev)
        self.rot_err = wp.zeros(B, dtype=sc, device=dev)
        self.cost_f = wp.zeros(B, dtype=sc, device=dev)
        self.grad_f = wp.zeros((B, n), dtype=sc, device=dev)
        self.cost_a = wp.zeros(B, dtype=sc, device=dev)
        self.grad_a = wp.zeros((B, n), dtype=sc, device=dev)
        self.coll_cost = wp.zeros(B, dtype=sc, device=dev)
        self.coll_grad = wp.zeros((B, n), dtype=sc, device=dev)
        self.cm = collision.collision_model(self.robot, world, device=dev, dtype=self.npdt)
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
        self.q_default = wp.array(a, dtype=self.scalar, device=self.device)

    def set_q(self, q: np.ndarray, keep_rho: bool = False) -> None:
        """Copy q (B, n_dof) into the batch; ``keep_rho`` keeps the elastic DH rows of the
        last iteration (compensation: one torque update per iteration)."""
        q = np.ascontiguousarray(q, dtype=self.npdt).reshape(self.B, self.n)
        if self.device.is_cpu:
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
                     [self.frames, self.target, self.scalar(w.position),
                      self.scalar(w.rotation), t.frame_struct, t.chain(self.frame)],
                     [self.jac, self.err, self.pos_err, self.rot_err, self.cost_f, self.grad_f])

    def evaluate_aux(self) -> None:
        """U_A (world + self collision + closeness to the default pose) and its gradient at
        the frames of the last :meth:`evaluate_pose` (elastic: the same DH rows, followed
        by the iteration's one torque update of the rows)."""
        w = self.weights
        use = int(w.world > 0 or w.self > 0)
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

    def project_limits(self) -> None:
        self._launch(("project",), self.pk.project, [*self.limits.args], [self.q])

    def value_and_grad(self, q: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Host convenience: U_ik = U_f + U_A (eq. 3.19) (B,) and its gradient (B, n_dof)."""
        self.set_q(q)
        self.set_target(target)
        self.evaluate_pose()
        self.evaluate_aux()
        u = self.cost_f.numpy() + self.cost_a.numpy()
        g = self.grad_f.numpy() + self.grad_a.numpy()
        return u.astype(np.float64), g.astype(np.float64)


def _task_rows(robot: RobotModel) -> np.ndarray:
    return np.array([0, 1, 5]) if robot.workspace_dim == 2 else np.arange(6)


def ik(robot: Any, frame: int | str, target: Any, *, world: Any = None, n_starts: int = 16,
       initial: Any = None, q_default: Any = None, weights: IKWeights | None = None,
       tol_pos: float = 1e-4, tol_rot: float = 1e-3, margin: float = 0.0,
       eps: float | None = None, max_iterations: int = 200, step: float = 1.0,
       max_step: float = 0.5, damping: float = 1e-3, kappa: Any = None, lam: float = 0.7,
       tol_rho: float = 1e-6, stop_when_solved: bool = True, check_every: int = 5,
       seed: int | None = 0,
       device: Any = "cpu", dtype: Any = np.float64,
       callback: Callable[[int, np.ndarray], None] | None = None) -> IKResult:
    """Collision-free IK of ``frame`` onto ``target`` with random multi-starts.

    Args:
        robot: robot name or RobotModel.
        frame: end-effector frame (name, end-effector alias or index).
        target: pose(s) (4, 4) or (T, 4, 4) in the base frame [m]; planar robots use x, y
            and the rotation about z.
        world: optional :class:`jwarp.world.World` (None: self-collision only).
        n_starts: random seeds per target (uniform inside the limits).
        initial: seeds (n_dof,), (n_starts, n_dof) or (T, n_starts, n_dof) instead of random.
        q_default: default pose for the closeness term (default: the middle of the limits).
        weights: :class:`IKWeights`.
        tol_pos, tol_rot: target tolerance [m] and [rad] (thesis: 1e-4 m, 1e-3 rad).
        margin: required clearance [m] (world and self); eps (>= margin) smoothing width.
        max_iterations: iterations per start (projection + nullspace).
        step, max_step: nullspace step alpha and the largest change of one joint per
            iteration [rad].
        damping: mu of the damped pseudo-inverse.
        kappa, lam, tol_rho: elastic compensation (see the module docstring).
        stop_when_solved: end once every target has a feasible start (else run every start
            until it is feasible or out of iterations).
        check_every: exact collision check of every on-target start every this many
            iterations (starts whose collision cost is below ``w c(margin)`` are checked at
            once).
        seed: random seed of the starts.
        device, dtype: Warp device and float type.
        callback: ``callback(iteration, q (B, n_dof))`` after every evaluation.

    Raises:
        ValueError: unknown frame, bad target/seed shapes, world dimension mismatch, bad
            options.
    """
    t0 = time.perf_counter()
    init_warp()
    model = get_robot(robot)
    fi = model.frame_index(frame)
    collision.check_world(model, world)
    T, lead = _targets(target)
    for name, v, lo in (("n_starts", n_starts, 1), ("max_iterations", max_iterations, 0),
                        ("check_every", check_every, 1)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < lo:
            raise ValueError(f"{name}: expected an integer >= {lo}, got {v!r}")
    for name, v in (("tol_pos", tol_pos), ("tol_rot", tol_rot), ("step", step),
                    ("max_step", max_step), ("damping", damping), ("tol_rho", tol_rho)):
        if not (math.isfinite(real_number(v, name)) and v > 0):
            raise ValueError(f"{name}: expected a number > 0, got {v!r}")
    tol_pos, tol_rot, step, max_step, damping, tol_rho = (
        float(v) for v in (tol_pos, tol_rot, step, max_step, damping, tol_rho))
    margin = real_number(margin, "margin")
    if not (math.isfinite(margin) and margin >= 0):
        raise ValueError(f"margin: expected a number >= 0 [m], got {margin!r}")
    finite_as(T, numpy_dtype(scalar_type(dtype)), "target")  # finite in the solver's dtype
    eps_v = real_number(eps, "eps") if eps is not None else max(
        float(world.voxel_size) if world is not None else 0.0, 0.01, margin)
    if not eps_v >= margin or not eps_v > 0:
        raise ValueError(f"eps: must be > 0 and >= margin ({margin:g} m), got {eps_v:g}")
    nT = len(T)
    rng = np.random.default_rng(seed)
    if initial is None:
        q0 = sample_within_limits(model, nT * n_starts, rng).reshape(nT, n_starts, model.n_dof)
    else:
        q0 = _seeds(model, initial, nT)
        finite_as(q0, numpy_dtype(scalar_type(dtype)), "initial")
        n_starts = q0.shape[1]
    B = nT * n_starts
    obj = IKObjective(model, fi, B, world=world, weights=weights, eps=eps_v, q_default=q_default,
                      kappa=kappa, lam=lam, device=device, dtype=dtype)
    obj.set_q(q0.reshape(B, -1))
    obj.project_limits()
    obj.set_target(np.repeat(T, n_starts, axis=0))
    # screen: a collision cost below w_min c(margin) means no sphere is within margin
    # (every term is >= 0); those get the exact check at once, the others every
    # check_every iterations
    wts = obj.weights
    w_min = min([v for v in (wts.world, wts.self) if v > 0] or [0.0])
    screen = w_min * (eps_v - margin) ** 2 / (2.0 * eps_v)
    rows = _task_rows(model)
    npos = 2 if model.workspace_dim == 2 else 3
    done = np.zeros(B, bool)
    feasible = np.zeros(B, bool)
    iters = np.full(B, max_iterations, np.int64)
    q_out = np.zeros((B, model.n_dof))
    errs = np.zeros((B, 3))  # pos, rot, U_A
    mu2 = damping ** 2
    for it in range(max_iterations + 1):
        obj.evaluate_pose()
        obj.evaluate_aux()
        q = obj.q.numpy().astype(np.float64)
        if callback is not None:
            callback(it, q)
        err = obj.err.numpy().astype(np.float64)[:, rows]
        pe = np.linalg.norm(err[:, :npos], axis=1)
        re = np.linalg.norm(err[:, npos:], axis=1)
        on = (pe < tol_pos) & (re < tol_rot)
        if obj.compensation is not None:
            on &= obj.delta.numpy() < tol_rho
        cost_a = obj.cost_a.numpy().astype(np.float64)
        coll = obj.coll_cost.numpy()
        full = it % check_every == 0 or it == max_iterations
        cand = np.nonzero(~done & on & ((coll < screen) | full))[0]
        if len(cand):
            ok = within_limits(model, q[cand]) & _free(obj, q[cand], cand, margin)
            newly = cand[ok]
            feasible[newly] = True
            done[newly] = True
            iters[newly] = it
            q_out[newly] = q[newly]
            errs[newly] = np.stack([pe[newly], re[newly], cost_a[newly]], 1)
        if done.all() or it == max_iterations:
            break
        if stop_when_solved and feasible.reshape(nT, n_starts).any(1).all():
            break
        J = obj.jac.numpy().astype(np.float64)[:, rows]         # (B, m, n)
        JJt = J @ np.swapaxes(J, 1, 2) + mu2 * np.eye(len(rows))
        dq = np.einsum("bmn,bm->bn", J, np.linalg.solve(JJt, err[..., None])[..., 0])
        ga = obj.grad_a.numpy().astype(np.float64)
        ns = ga - np.einsum("bmn,bm->bn", J, np.linalg.solve(JJt, (J @ ga[..., None]))[..., 0])
        dq = np.where(on[:, None], dq - step * ns, dq)
        # scale the whole step (keeps the Newton direction) so no joint moves > max_step
        big = np.abs(dq).max(axis=1, keepdims=True)
        dq *= np.minimum(1.0, max_step / np.maximum(big, 1e-300))
        dq[done] = 0.0
        obj.set_q(q + dq, keep_rho=True)
        obj.project_limits()
    rest = np.nonzero(~done)[0]
    if len(rest):
        q_out[rest] = q[rest]
        errs[rest] = np.stack([pe[rest], re[rest], cost_a[rest]], 1)
    return _result(q_out, feasible, errs, iters, nT, n_starts, lead, time.perf_counter() - t0)


def _free(obj: IKObjective, q: np.ndarray, idx: np.ndarray, margin: float) -> np.ndarray:
    """Exact check (world and self, ``margin``) of the configurations ``q`` = rows ``idx``."""
    rho = None
    if obj.compensation is not None:
        rho = obj.compensation.rho()[idx]
    return collision_free(obj.robot, obj.world, q, margin, rho=rho)


def _seeds(model: RobotModel, initial: Any, nT: int) -> np.ndarray:
    a = real_array(initial, "initial")
    n = model.n_dof
    if a.ndim == 1:
        a = a[None, None]
    elif a.ndim == 2:
        a = a[None]
    if a.ndim != 3 or a.shape[-1] != n or a.shape[0] not in (1, nT) or a.shape[1] == 0:
        raise ValueError(f"initial: expected seeds ({n},), (n_starts, {n}) or ({nT}, n_starts, "
                         f"{n}), got {np.shape(initial)}")
    if not np.all(np.isfinite(a)):
        raise ValueError("initial: contains NaN or inf")
    return np.array(np.broadcast_to(a, (nT,) + a.shape[1:]))


def _result(q: np.ndarray, feasible: np.ndarray, errs: np.ndarray, iters: np.ndarray, nT: int,
            S: int, lead: tuple, wall: float) -> IKResult:
    n = q.shape[1]
    fz = feasible.reshape(nT, S)
    e = errs.reshape(nT, S, 3)
    # feasible first (lowest U_A), else the smallest pose error
    key_f = np.where(fz, e[..., 2], np.inf)
    key_i = e[..., 0] + e[..., 1] * 0.1
    best = np.where(fz.any(1), np.argmin(key_f, axis=1), np.argmin(key_i, axis=1))
    r = np.arange(nT)
    qa = q.reshape(nT, S, n)
    it = iters.reshape(nT, S)

    def shp(x: np.ndarray, tail: tuple = ()) -> np.ndarray:
        return x.reshape(lead + tail)

    return IKResult(q=shp(qa[r, best], (n,)), feasible=shp(fz[r, best]),
                    pos_err=shp(e[r, best, 0]), rot_err=shp(e[r, best, 1]),
                    cost=shp(e[r, best, 2]), iterations=shp(it[r, best]),
                    start_index=shp(best), n_feasible=shp(fz.sum(1)), wall_time=wall,
                    all_q=shp(qa, (S, n)), all_feasible=shp(fz, (S,)), all_iterations=shp(it, (S,)))
