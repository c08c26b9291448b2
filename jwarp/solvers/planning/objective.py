"""The path objective (thesis eq. 3.3): length, collision and limit costs of a batch of
paths and their gradients, on the device."""

from __future__ import annotations

from types import SimpleNamespace
from typing import TYPE_CHECKING

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
from jwarp.kernels import path as path_kernels
from jwarp.kinematics.compensation import CompensationRows
from jwarp.model import RobotModel
from jwarp.plugins.registry import robot as get_robot
from jwarp.solvers.planning.options import PathWeights
from jwarp.world import collision
from jwarp.world.path_feasibility import check_substeps, check_world

if TYPE_CHECKING:
    from jwarp.world.sdf import World

#: floor of the length-cost normaliser 1/2 |q_goal - q_start|^2 [rad^2]
NORM_FLOOR = 1e-4


# ====================================================================== helpers
def path_configs(x: ArrayLike, robot: RobotModel, name: str) -> np.ndarray:
    """(..., n_dof) -> (B, n_dof) float64 with shape/NaN checks naming ``name``."""
    a = real_array(x, name)
    if a.ndim == 0 or a.shape[-1] != robot.n_dof or a.size == 0:
        raise ValueError(f"{name}: expected shape (..., {robot.n_dof}) for robot "
                         f"'{robot.name}', got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name}: contains NaN or inf")
    return a.reshape(-1, robot.n_dof)


class PathObjective:
    """U_path (eq. 3.16) and its gradient for a batch of P paths on one device.

    Owns the device buffers of one batch shape (P, W, n_dof) and ``n_substeps``; each call
    launches: substeps -> collision cost + gradient [-> elastic torque update at the
    waypoints] -> path cost (-> gradient or step). Arrays are Warp arrays on ``device``.
    """

    def __init__(self, robot: RobotLike, world: World, n_paths: int, n_waypoints: int, n_substeps: int,
                 *, weights: PathWeights | None = None, eps: float | None = None,
                 kappa: ArrayLike | None = None, lam: float = 0.7, device: DeviceLike = None, dtype: DTypeLike = np.float32):
        init_warp()
        self.robot = get_robot(robot)
        check_world(self.robot, world)
        self.world = world
        self.weights = weights or PathWeights()
        self.weights.validate()
        if n_waypoints < 2:
            raise ValueError(f"n_waypoints: expected >= 2, got {n_waypoints}")
        self.n_sub = check_substeps(n_substeps)
        self.device = resolve_device(device)
        self.scalar = scalar_type(dtype)
        self.npdt = numpy_dtype(self.scalar)
        self.k = path_kernels.kernels(self.scalar)
        self.P, self.W, self.n = int(n_paths), int(n_waypoints), self.robot.n_dof
        self.S = (self.W - 1) * self.n_sub + 1
        self.N = self.P * self.S
        #: a batch of worlds: substep row b is in world b // group_div (0: one world)
        self.group_div = 0
        #: skip the collision cost of frozen paths (``active`` 0; the planner with
        #: ``freeze_feasible``): their costs are kept, nothing reads them again
        self.skip_inactive = False
        #: configurations whose collision cost :meth:`evaluate` computed so far (its work;
        #: every substep row, skipped ones included)
        self.evaluations = 0
        self.eps = real_number(eps, "eps", self.npdt) if eps is not None else float(
            max(world.resolution, 0.01))
        if not self.eps > 0:
            raise ValueError(f"eps: expected > 0 [m], got {eps!r}")
        self.limits = put_model(self.robot, self.device, self.scalar).limits
        dev, sc = self.device, self.scalar
        self.paths = wp.zeros((self.P, self.W, self.n), dtype=sc, device=dev)
        self._paths_next = wp.zeros((self.P, self.W, self.n), dtype=sc, device=dev)
        self.q_sub = wp.zeros((self.N, self.n), dtype=sc, device=dev)
        self.length = wp.zeros(self.P, dtype=sc, device=dev)
        self.collision = wp.zeros(self.P, dtype=sc, device=dev)
        self.total = wp.zeros(self.P, dtype=sc, device=dev)
        self.sub_max = wp.zeros(self.P, dtype=sc, device=dev)
        self.grad = wp.zeros((self.P, self.W, self.n), dtype=sc, device=dev)
        self.active = wp.ones(self.P, dtype=wp.int32, device=dev)
        self.sub_cost = wp.zeros(self.N, dtype=sc, device=dev)
        self.sub_grad = wp.zeros((self.N, self.n), dtype=sc, device=dev)
        self.cm = collision.collision_model(self.robot, world, device=dev, dtype=self.npdt)
        #: elastic compensation rows (None: the rigid robot)
        self.compensation: CompensationRows | None = None
        if kappa is not None:
            self.compensation = CompensationRows(put_model(self.robot, dev, self.npdt), self.P,
                                                 self.W, self.n_sub, kappa, lam)
        #: Cartesian length cost U_c (P,) (eq. 3.7, unweighted; zeros without it)
        self.cartesian = wp.zeros(self.P, dtype=sc, device=dev)
        self._cart = None
        if self.weights.cartesian > 0 and self.cm.n_spheres:
            ck = path_kernels.cartesian_kernels(sc)
            nf, PW = self.robot.n_frames, self.P * self.W
            self._cart = SimpleNamespace(
                k=ck, frames=wp.zeros((PW, nf), dtype=ck.fk.mat44, device=dev),
                xs=wp.zeros((PW, self.cm.n_spheres), dtype=ck.fk.vec3, device=dev),
                force=wp.zeros((PW, nf), dtype=ck.fk.vec3, device=dev),
                moment=wp.zeros((PW, nf), dtype=ck.fk.vec3, device=dev),
                rows=self.cm.dh_rows(None, PW))

    # ------------------------------------------------------------------ state
    def set_paths(self, paths: np.ndarray) -> None:
        """Copy paths (P, W, n_dof) into the device buffer."""
        a = real_array(paths, "paths")
        if a.size != self.P * self.W * self.n:
            raise ValueError(f"paths: expected {self.P} paths of {self.W} waypoints of "
                             f"{self.n} joints, got shape {a.shape}")
        a = finite_as(a.reshape(self.P, self.W, self.n), self.npdt, "paths")
        wp.copy(self.paths, wp.array(a, dtype=self.scalar, device=self.device))
        self.reset_compensation()

    def reset_compensation(self) -> None:
        """Start the elastic rows again from the rigid robot (no-op without kappa)."""
        if self.compensation is not None:
            self.compensation.reset()

    def set_active(self, active: np.ndarray) -> None:
        wp.copy(self.active, wp.array(np.asarray(active, np.int32), dtype=wp.int32,
                                      device=self.device))

    # ------------------------------------------------------------------ stages
    def evaluate(self, grad: bool = True) -> None:
        """Substeps, (elastic update,) collision cost/gradient and per-path costs of the
        current paths; fills ``sub_cost`` (N,), ``sub_grad`` (N, n_dof), ``length``,
        ``collision``, ``total`` (P,)."""
        k, dev = self.k, self.device
        self.evaluations += self.N
        wp.launch(k.substeps, dim=(self.P, self.S), inputs=[self.paths, self.n_sub],
                  outputs=[self.q_sub], device=dev)
        comp = self.compensation
        w = self.weights
        # elastic: frames at the kept rows, and from them one torque update for next time
        self.cm.cost(self.q_sub, rho=comp, w_world=w.world, w_self=w.self, eps=self.eps,
                     grad=grad, out_cost=self.sub_cost, out_grad=self.sub_grad,
                     update_rows=comp is not None, group_div=self.group_div,
                     active=self.active, active_div=self.S if self.skip_inactive else 0)
        wp.launch(k.path_cost, dim=self.P,
                  inputs=[self.paths, self.sub_cost, self.n_sub, self.scalar(w.length),
                          self.scalar(NORM_FLOOR)],
                  outputs=[self.length, self.collision, self.total, self.sub_max], device=dev)
        if self._cart is not None:
            self._cartesian_length(grad)

    def _cartesian_length(self, grad: bool) -> None:
        """U_c (eq. 3.7) into ``cartesian`` and ``total``; with ``grad`` its gradient into
        the waypoint rows of ``sub_grad`` (rigid frames at the waypoints)."""
        c, dev, PW = self._cart, self.device, self.P * self.W
        assert c is not None  # called when the Cartesian term is on
        lam = self.scalar(self.weights.cartesian)
        floor = self.scalar(NORM_FLOOR * 1e-2)  # [m^2]
        wp.launch(c.k.fk.fk, dim=PW, inputs=[self.cm.model.frame_struct,
                                             self.paths.reshape((PW, self.n)), *c.rows.args],
                  outputs=[c.frames], device=dev)
        sp = self.cm.model.spheres
        wp.launch(c.k.centres, dim=(PW, self.cm.n_spheres),
                  inputs=[sp.sph_frame, sp.sph_pos, c.frames], outputs=[c.xs], device=dev)
        wp.launch(c.k.cost, dim=self.P, inputs=[c.xs, self.W, lam, floor],
                  outputs=[self.cartesian, self.total], device=dev)
        if grad:
            wp.launch(c.k.grad, dim=(self.P, self.W),
                      inputs=[self.cm.model.frame_struct, sp.sph_frame, c.frames,
                              self.paths.reshape((PW, self.n)), c.xs, self.W, self.n_sub, lam,
                              floor, c.force, c.moment],
                      outputs=[self.sub_grad], device=dev)

    def gradient(self) -> wp.array:
        """dU_path/dQ (P, W, n_dof) of the last :meth:`evaluate` (zero at start/goal)."""
        wp.launch(self.k.path_grad, dim=(self.P, self.W),
                  inputs=[self.paths, self.sub_grad, self.n_sub, self.scalar(self.weights.length),
                          self.scalar(NORM_FLOOR)],
                  outputs=[self.grad], device=self.device)
        return self.grad

    def step(self, step: float, max_step: float) -> None:
        """One projected gradient step on the active paths (uses the last evaluate)."""
        wp.launch(self.k.path_step, dim=(self.P, self.W),
                  inputs=[self.limits, self.paths, self.sub_grad, self.n_sub,
                          self.scalar(self.weights.length), self.scalar(NORM_FLOOR),
                          self.scalar(step), self.scalar(max_step), self.active],
                  outputs=[self._paths_next.reshape((self.P * self.W, self.n))], device=self.device)
        self.paths, self._paths_next = self._paths_next, self.paths

    def value_and_grad(self, paths: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Host convenience: U_path (P,) and dU/dQ (P, W, n_dof) as numpy."""
        self.set_paths(paths)
        self.evaluate(grad=True)
        return self.total.numpy().astype(np.float64), self.gradient().numpy().astype(np.float64)
