"""Inverse-kinematics targets and objective: :class:`IKObjective`, pose matrices and
target batches."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
import warp as wp

from jwarp.core.arrays import (
    finite_as,
    init_warp,
    real_array,
    real_number,
    resolve_device,
)
from jwarp.core.device import numpy_dtype, put_model, scalar_type
from jwarp.core.types import ArrayLike, DeviceLike, DTypeLike, RobotLike
from jwarp.kernels import fk as fk_kernels
from jwarp.kernels import ik as ik_kernels
from jwarp.kernels import path as path_kernels
from jwarp.kinematics.compensation import CompensationRows
from jwarp.plugins.registry import robot as get_robot
from jwarp.solvers.ik.options import IKWeights, orientation_args
from jwarp.world import collision

if TYPE_CHECKING:
    from jwarp.world.sdf import World


def pose_matrix(xyz: Any, rotvec: Any = (0.0, 0.0, 0.0)) -> np.ndarray:
    """4x4 pose from a position [m] and a rotation vector (axis * angle) [rad]."""
    from scipy.spatial.transform import Rotation

    p = np.asarray(xyz, np.float64).reshape(3)
    r = np.asarray(rotvec, np.float64).reshape(3)
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(r).as_matrix()
    T[:3, 3] = p
    return T


def quaternion_matrices(q: ArrayLike, name: str = "quaternions") -> np.ndarray:
    """Rotations (..., 3, 3) of quaternions (..., 4) in ROS/MoveIt/scipy order
    ``(x, y, z, w)`` (scalar last), each normalised; ValueError naming ``name`` (and the
    flat index) for NaN/inf or a zero quaternion."""
    a = real_array(q, name)
    if a.ndim == 0 or a.shape[-1] != 4:
        raise ValueError(f"{name}: expected shape (..., 4) (x, y, z, w), got {a.shape}")
    flat = a.reshape(-1, 4)
    if not np.all(np.isfinite(flat)):
        bad = int(np.flatnonzero(~np.isfinite(flat).all(axis=1))[0])
        raise ValueError(f"{name}: quaternion {bad} contains NaN or inf")
    norm = np.linalg.norm(flat, axis=1)
    if np.any(~(norm > 1e-12)):
        bad = int(np.flatnonzero(~(norm > 1e-12))[0])
        raise ValueError(f"{name}: quaternion {bad} has zero norm")
    x, y, z, w = (flat / norm[:, None]).T
    R = np.empty((len(flat), 3, 3))
    R[:, 0, 0], R[:, 0, 1], R[:, 0, 2] = 1 - 2 * (y * y + z * z), 2 * (x * y - z * w), \
        2 * (x * z + y * w)
    R[:, 1, 0], R[:, 1, 1], R[:, 1, 2] = 2 * (x * y + z * w), 1 - 2 * (x * x + z * z), \
        2 * (y * z - x * w)
    R[:, 2, 0], R[:, 2, 1], R[:, 2, 2] = 2 * (x * z - y * w), 2 * (y * z + x * w), \
        1 - 2 * (x * x + y * y)
    return R.reshape(a.shape[:-1] + (3, 3))


def _is_position_quaternion_pair(target: Any) -> bool:
    """Whether ``target`` is a ``(positions (..., 3), quaternions (..., 4))`` tuple (a tuple
    of two 4x4 poses is not: its first item ends in 4)."""
    if not isinstance(target, tuple) or len(target) != 2:
        return False
    try:
        return np.shape(target[0])[-1:] == (3,) and np.shape(target[1])[-1:] == (4,)
    except (TypeError, ValueError):  # ragged: not this form
        return False


def pose_from_quaternions(positions: Any, quaternions: Any) -> np.ndarray:
    """Poses (..., 4, 4) of positions (..., 3) [m] and quaternions (..., 4) ``(x, y, z,
    w)`` (normalised; equal leading dims). ValueError naming ``target`` otherwise."""
    p = real_array(positions, "target")
    q = real_array(quaternions, "target")
    if p.shape[:-1] != q.shape[:-1]:
        raise ValueError(f"target: positions {p.shape} and quaternions {q.shape} must have "
                         f"the same leading dims ((..., 3) and (..., 4))")
    if not np.all(np.isfinite(p)):
        raise ValueError("target: positions contain NaN or inf")
    R = quaternion_matrices(q, "target")
    T = np.zeros(p.shape[:-1] + (4, 4))
    T[..., :3, :3] = R
    T[..., :3, 3] = p
    T[..., 3, 3] = 1.0
    return T


def as_poses(target: Any) -> Any:
    """``target`` itself, or the poses (..., 4, 4) of a ``(positions (..., 3), quaternions
    (..., 4))`` tuple (:func:`pose_from_quaternions`): the one place where the IK's target
    forms are read."""
    if _is_position_quaternion_pair(target):
        return pose_from_quaternions(*target)
    return target


def target_poses(target: Any) -> tuple[np.ndarray, tuple]:
    """The targets as flat poses (P, 4, 4) and their leading dims: ``target`` is poses
    (..., 4, 4) or a tuple ``(positions (..., 3) [m], quaternions (..., 4))`` with the
    quaternions in ROS/MoveIt/scipy order ``(x, y, z, w)`` (normalised here). ValueError
    naming ``target`` for any other shape, NaN/inf, a zero quaternion or a matrix that is
    not a rigid transform."""
    T = real_array(as_poses(target), "target")
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


def batch_array(B: int, tail: tuple, dtype: type, device: wp.Device, batch_fastest: bool) -> wp.array:
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

    def __init__(self, robot: RobotLike, frame: int | str, n: int, *, world: World | None = None,
                 weights: IKWeights | None = None, eps: float | None = None,
                 q_default: Any = None, kappa: ArrayLike | None = None, lam: float = 0.7,
                 device: DeviceLike = None, dtype: DTypeLike = np.float64, batch_fastest: bool = False,
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
        self._launch(("fk", id(rho[0])), self.fk.fk, [t.frame_struct, self.q, *rho],
                     [self.frames])
        w = self.weights
        self._launch(("pose", w.position, w.rotation), self.kk.pose_error,
                     [t.frame_struct, t.chain(self.frame), self.frames, self.q, self.target,
                      self.scalar(w.position), self.scalar(w.rotation), self.orient, self.axis],
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
        self._launch(("project",), path_kernels.project(self.scalar), [self.limits], [self.q])

    def value_and_grad(self, q: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Host convenience: U_ik = U_f + U_A (eq. 3.19) (B,) and its gradient (B, n_dof)."""
        self.set_q(q)
        self.set_target(target)
        self.evaluate_pose()
        self.evaluate_aux()
        u = self.cost_f.numpy() + self.cost_a.numpy()
        g = self.grad_f.numpy() + self.grad_a.numpy()
        return u.astype(np.float64), g.astype(np.float64)


def check_single_world(world: World | None) -> None:
    """ValueError naming ``world`` for a batch of worlds (:meth:`World.batch`): IK checks
    every target against one world (a batch would be checked as the union of its worlds);
    solve each world's targets with that world (``world.select(i)``)."""
    n = getattr(world, "n_worlds", 1) if world is not None else 1
    if n > 1:
        raise ValueError(f"world: a batch of {n} worlds; IK solves in one world (its "
                         f"targets would be checked against all {n}): solve per world, "
                         f"world.select(i)")
