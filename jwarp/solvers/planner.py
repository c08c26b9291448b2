"""Optimization-based motion planning (OMP): batched gradient descent on U_path.

Thesis 3.3.1-3.3.3 and the IROS'22 paper, section II. A path is ``W`` waypoints
``Q = [q_1 .. q_W]`` with fixed start ``q_1`` and goal ``q_W``; linear substeps (eq. 3.3)
between the waypoints make the swept volume explicit. The objective (eq. 3.16)

    U_path(Q) = lam_w U_w(Q) + lam_s U_s(Q) + lam_l U_l(Q)

sums the world and self-collision costs (eq. 3.8-3.12, :mod:`jwarp.world.collision`) over all
substeps and adds the normalised length cost (eq. 3.5). Gradient descent with a fixed
step (eq. 3.18), a per-joint step clamp and a projection onto the joint limits (box plus
linear limits such as justin19's coupled torso) runs for many paths in one launch per
stage: substeps -> collision cost + gradient -> path cost -> step.

A path is *feasible* when every substep is collision-free with ``margin`` (world and self)
and every waypoint is within the limits. Each path stops on its own as soon as it is
feasible (early stop); :class:`Planner` (a persistent solver: device buffers reused across
calls, options in :class:`PlanOptions`, seeds from the caller) and its one-call wrapper
:func:`plan` return per problem the best (lowest U_path) feasible path of its multi-starts,
chosen on the device, or the lowest-cost infeasible one with ``feasible = False``.

With ``kappa`` (elastic compensation, elastic paper section V, Fig. 2.11) the robot is the
elastic model (:mod:`jwarp.kinematics.compensation`): the collision kernel computes the frames
at the DH rows kept from the previous iteration, one torque update at every waypoint from
those frames gives the rows of the next iteration (substeps take their nearest
waypoint's), and the collision gradient is taken with the rows fixed.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from types import SimpleNamespace
from typing import Any, Callable

import numpy as np
import warp as wp

from jwarp.core.arrays import finite_as, init_warp, real_array, real_number, resolve_device
from jwarp.core.device import numpy_dtype, put_model, scalar_type
from jwarp.world import collision
from jwarp.world.model_check import check_collision_model
from jwarp.kernels import path as path_kernels
from jwarp.model import RobotModel
from jwarp.registry import robot as get_robot
from jwarp.kinematics.compensation import CompensationRows
from jwarp.kinematics.transmission import transmitted, untransmitted
from jwarp.kinematics.launch import kappa_array
from jwarp.solvers.feasibility import (ELASTIC_CHECK, MAX_CHECK_SUBSTEPS, SWEEP_SAFETY,  # noqa: F401
                                       certify_check, check_endpoints, check_substeps,
                                       check_world,
                                       collision_free, elastic_equilibrium, initial_paths,
                                       path_feasible, polyline_path, sphere_centres,
                                       substeps, substeps_for_voxel, substeps_per_path)
from jwarp.core.limits import project_numpy, within_limits
from jwarp.solvers.overrides import renamed_options, translate, with_overrides

#: floor of the length-cost normaliser 1/2 |q_goal - q_start|^2 [rad^2]
NORM_FLOOR = 1e-4


@dataclass
class PathWeights:
    """Weights of eq. 3.16: world collision, self-collision and length (joint space, eq.
    3.5); ``cartesian``: the Cartesian length cost (eqs. 3.6-3.7, the motion of every
    collision sphere between waypoints, normalised by the direct start-goal motion; rigid
    kinematics), 0 (default) leaves it out."""

    world: float = 1.0
    self: float = 1.0
    length: float = 0.01
    cartesian: float = 0.0

    def validate(self) -> None:
        for k in ("world", "self", "length", "cartesian"):
            v = getattr(self, k)
            if not (math.isfinite(real_number(v, f"weights.{k}")) and v >= 0):
                raise ValueError(f"weights.{k}: expected a finite number >= 0, got {v!r}")


@dataclass
class PlanResult:
    """Result of :func:`plan` / :meth:`Planner.plan` for B problems.

    path (B, W, n_dof) best path per problem; feasible (B,) bool; cost (B,) U_path;
    length_cost (B,) U_l (eq. 3.5, 1 for the straight line); collision_cost (B,) weighted
    world + self cost summed over substeps; iterations (B,) gradient steps until the chosen
    path was feasible (or the iteration budget); start_index (B,) which multi-start (seed)
    won; n_feasible (B,) feasible multi-starts; wall_time [s] of the whole call;
    n_substeps substeps per segment; all_feasible (B, n_starts); all_iterations
    (B, n_starts); all_paths (B, n_starts, W, n_dof) final paths of every start, read from
    the device on first use (the best paths are chosen on the device, so a caller that
    needs only ``path`` never copies the others to the host).

    Budgets and fallback (:attr:`PlanOptions.time_limit`, ``stop_when_solved``,
    ``fallback``): ``stop_reason`` why the call ended, one of :data:`STOP_REASONS`:
    "solved" (every problem has a feasible path: ``stop_when_solved``, or the fallback
    solved the rest), "all_done" (every start finished on its own: feasible with
    ``freeze_feasible``, converged with ``converge``), "time_limit" (the time ran out first)
    or "iterations" (the iterations, and the fallback's samples, ran out first);
    ``stage`` (B,) which stage gave the path: "optimizer" (the multi-starts),
    "fallback" (the gradient optimisation seeded with the RRT-Connect path,
    :mod:`jwarp.solvers.rrt`) or "none" (no feasible path). A fallback path is none of
    the multi-starts: its ``start_index`` is -1, its ``iterations`` those of the seeded
    optimisation (0: the RRT path itself, certified as it is); ``n_feasible``, ``all_*``
    stay the multi-starts'. ``fallback_notes``: what the fallback did. ``timings`` [s]:
    "optimizer" (the multi-starts) and, where it ran, "rrt" and "fallback_optimizer".
    """

    path: np.ndarray
    feasible: np.ndarray
    cost: np.ndarray
    length_cost: np.ndarray
    collision_cost: np.ndarray
    iterations: np.ndarray
    start_index: np.ndarray
    n_feasible: np.ndarray
    wall_time: float
    n_substeps: int
    all_feasible: np.ndarray = field(repr=False)
    all_iterations: np.ndarray = field(repr=False)
    #: every start's final path: a numpy (B, n_starts, W, n_dof) array, or a Warp array
    #: (B * n_starts, W, n_dof) on the planner's device (its own copy) until first read
    paths_source: Any = field(default=None, repr=False)
    #: why the call ended (:data:`STOP_REASONS`)
    stop_reason: str = "iterations"
    #: (B,) "optimizer", "fallback" or "none" (None: filled by the planner)
    stage: Any = None
    #: seconds per stage: "optimizer", "rrt", "fallback_optimizer"
    timings: dict = field(default_factory=dict, repr=False)
    #: (B,) "feasible" or why the problem's path is not (:meth:`Planner.explain`)
    reasons: Any = None
    #: (B,) str: what the RRT fallback did for each problem ("" where it did not run):
    #: no tree connection (and why), or its path certified / not certified (and why);
    #: appended to ``reasons`` of a problem without a plan
    fallback_notes: Any = None

    @property
    def all_paths(self) -> np.ndarray:
        """(B, n_starts, W, n_dof) float64: the final path of every start."""
        src = self.paths_source
        if isinstance(src, wp.array):
            B, n_starts = self.all_feasible.shape
            src = src.numpy().astype(np.float64).reshape((B, n_starts) + self.path.shape[1:])
            self.paths_source = src
        return src

    def to_dict(self, index: int = 0) -> dict:
        """JSON-ready summary of problem ``index``."""
        return {"path": self.path[index].tolist(), "feasible": bool(self.feasible[index]),
                "costs": {"total": float(self.cost[index]),
                          "length": float(self.length_cost[index]),
                          "collision": float(self.collision_cost[index])},
                "iterations": int(self.iterations[index]),
                "start_index": int(self.start_index[index]),
                "n_feasible_starts": int(self.n_feasible[index]),
                "n_substeps": int(self.n_substeps),
                "wall_time_s": float(self.wall_time),
                "stop_reason": str(self.stop_reason),
                "reason": (str(self.reasons[index]) if self.reasons is not None
                           else None),
                "stage": None if self.stage is None else str(self.stage[index])}


# ====================================================================== helpers
def _configs(x: Any, robot: RobotModel, name: str) -> np.ndarray:
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

    def __init__(self, robot: Any, world: Any, n_paths: int, n_waypoints: int, n_substeps: int,
                 *, weights: PathWeights | None = None, eps: float | None = None,
                 kappa: Any = None, lam: float = 0.7, device: Any = None, dtype: Any = np.float32):
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
        lam = self.scalar(self.weights.cartesian)
        floor = self.scalar(NORM_FLOOR * 1e-2)  # [m^2]
        wp.launch(c.k.fk.fk, dim=PW, inputs=[self.paths.reshape((PW, self.n)), *c.rows.args,
                                             self.cm.model.frame_struct],
                  outputs=[c.frames], device=dev)
        wp.launch(c.k.centres, dim=(PW, self.cm.n_spheres),
                  inputs=[c.frames, self.cm.sph_frame, self.cm.sph_pos], outputs=[c.xs],
                  device=dev)
        wp.launch(c.k.cost, dim=self.P, inputs=[c.xs, self.W, lam, floor],
                  outputs=[self.cartesian, self.total], device=dev)
        if grad:
            wp.launch(c.k.grad, dim=(self.P, self.W),
                      inputs=[c.frames, self.paths.reshape((PW, self.n)), c.xs, self.W,
                              self.n_sub, lam, floor,
                              self.cm.model.frame_struct, self.cm.sph_frame, c.force, c.moment],
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
                  inputs=[self.paths, self.sub_grad, self.n_sub, self.scalar(self.weights.length),
                          self.scalar(NORM_FLOOR), self.scalar(step), self.scalar(max_step),
                          self.active, self.limits],
                  outputs=[self._paths_next.reshape((self.P * self.W, self.n))], device=self.device)
        self.paths, self._paths_next = self._paths_next, self.paths

    def value_and_grad(self, paths: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Host convenience: U_path (P,) and dU/dQ (P, W, n_dof) as numpy."""
        self.set_paths(paths)
        self.evaluate(grad=True)
        return self.total.numpy().astype(np.float64), self.gradient().numpy().astype(np.float64)


# ====================================================================== options
#: the kinds of multi-starts drawn when no seeds are given (:attr:`PlanOptions.start_kind`)
INITIAL_KINDS = ("straight", "random", "mixed")
#: substep length [m] of the cost in a world of exact objects only (sphere travel per
#: substep): the continuous check proves feasibility, the cost only guides the descent
EXACT_SUBSTEP = 0.25
#: evaluations per segment of the planner's continuous check (MotionOptions.max_evals)
PLANNER_CHECK_EVALS = 256
#: the same on a GPU, after 8 rounds of parallel evaluations (H200, 700 Panda problems in one
#: batch: 64 gave 667 solved in 4.0 s, 256 gave 691 in 15 s)
PLANNER_CHECK_EVALS_GPU = 64
#: why a plan call ended (:attr:`PlanResult.stop_reason`)
STOP_REASONS = ("solved", "time_limit", "iterations", "all_done")
#: the fallbacks of :attr:`PlanOptions.fallback` (besides None)
FALLBACKS = ("rrt",)
#: the stages of :attr:`PlanResult.stage`
STAGES = ("optimizer", "fallback", "none")


def _check_int(v: Any, name: str, lo: int) -> None:
    if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < lo:
        raise ValueError(f"{name}: expected an integer >= {lo}, got {v!r}")


def _check_flag(v: Any, name: str) -> None:
    if not (isinstance(v, (bool, np.bool_)) or (isinstance(v, (int, np.integer)) and v in (0, 1))):
        raise TypeError(f"{name}: expected True or False, got {v!r}")


@renamed_options(initial="start_kind", early_stop="freeze_feasible")
@dataclass
class PlanOptions:
    """Options of the planner: of :class:`Planner`, and the keyword options of :func:`plan`
    (documented here once). :meth:`validate` raises ValueError/TypeError naming the field.

    Attributes:
        n_starts: multi-starts per problem when no seeds are given ("straight": one).
        start_kind: the multi-starts without seeds: "straight" (the line in joint space),
            "random" (1-3 random via points inside the limits, thesis 3.5.1) or "mixed"
            (the line plus ``n_starts - 1`` random ones).
        n_waypoints: W, >= 2 (20 in the thesis); seeds given as paths bring their own W.
        n_substeps: substeps per segment, >= 1; None sizes them to the world's voxel size
            on the initial paths of each call (:func:`substeps_for_voxel`).
        iterations: most gradient steps per path, >= 0.
        step, max_step: step size alpha (eq. 3.18) and the largest change of one joint of
            one waypoint per step [rad], both > 0.
        weights: :class:`PathWeights` (lam_w, lam_s, lam_l); None: the defaults.
        eps: smoothing width of the clipped cost c (eq. 3.10) [m], > 0 and >= ``margin``
            (a path of zero collision cost is then feasible); None: max(voxel, 1 cm, margin).
        margin: required clearance [m] (>= 0) of every sphere along the whole continuous
            motion (:mod:`jwarp.world.motion`).
        self_margin: clearance [m] (>= 0) required between the robot's own spheres
            (self collision; MoveIt's default padding is 0 too).
        endpoint_margin: clearance [m] required of the start and goal and on the first
            and last segment, where it is below ``margin`` (None: ``margin``), so grasp
            poses closer to an object than the path margin can be planned.
        freeze_feasible: freeze each path once it is feasible.
        stop_when_solved: end as soon as every problem has one feasible path (default);
            False optimises every start until it is feasible (or converged, or out of
            iterations): for labels (``converge``), per-start statistics.
        time_limit: seconds for the whole call (None: no limit), > 0: checked before
            every iteration (wall clock since the call started); when it is reached the
            current paths get their exact check and the call ends (the endpoint checks,
            one evaluation and that check always run, so a call can overrun a tiny limit).
        fallback: "rrt" (default): problems the multi-starts have not solved after
            their iterations, or after ``fallback_after`` of ``time_limit``, get an
            RRT-Connect path in joint space (:mod:`jwarp.solvers.rrt`) as the seed of
            one more gradient optimisation (exact check as always); None: no fallback.
        fallback_after: the share of ``time_limit`` the multi-starts may use before the
            fallback, in (0, 1) (without a time limit: after the iterations).
        rrt: :class:`jwarp.solvers.rrt.RRTOptions` of the fallback (None: its defaults).
        check_all_every: exact feasibility check of every unfinished path every this many
            iterations (>= 1; paths whose largest substep cost is below ``w c(margin)`` are
            checked every iteration) and after the last one; None: 1 in a world of exact
            objects only (its check costs about one evaluation), 10 with a grid.
        free_via: draw the random via points from collision-free configurations.
        kappa: elastic compensation with these compliances [rad/(N m)] (any form of
            :func:`jwarp.kinematics.kappa_array`); None plans on the rigid model.
        lam: damping of the torque update in (0, 1] (elastic only).
        seed: random seed of the random multi-starts (an integer >= 0, a numpy Generator
            or None for fresh entropy); every call draws from ``default_rng(seed)``.
        converge: keep optimizing feasible paths until their length cost converges
            (labels of thesis 3.5.1): a feasible path is re-checked every
            ``check_all_every`` iterations; each feasible iterate is kept (so the result
            is the last feasible one), and the path stops when the relative change of
            U_l between two kept iterates is <= ``converge_tol`` (or the iterations run
            out). ``iterations`` of the result is then the iteration of the kept iterate.
            False (default): ``freeze_feasible`` decides.
        converge_tol: relative change of U_l that counts as converged, > 0.
        callback: called as ``callback(iteration, paths (P, W, n_dof))`` after every
            evaluation (e.g. rerun streaming; it reads every path to the host).
        allow_no_collision: plan without a collision model: a robot without collision
            spheres (every path is then collision-free) or in self-collision at its home
            configurations is accepted; False (default): either is a ValueError naming the
            robot and the link pairs (:func:`jwarp.world.model_check.check_collision_model`;
            CLI ``--no-collision``).
    """

    n_starts: int = 8
    start_kind: str = "mixed"
    n_waypoints: int = 20
    n_substeps: int | None = None
    iterations: int = 100
    step: float = 0.01
    max_step: float = 0.1
    weights: PathWeights | None = None
    eps: float | None = None
    margin: float = 0.0
    endpoint_margin: float | None = None
    self_margin: float = 0.0
    freeze_feasible: bool = True
    stop_when_solved: bool = True
    check_all_every: int | None = None
    free_via: bool = True
    kappa: Any = None
    lam: float = 0.7
    seed: Any = 0
    callback: Callable[[int, np.ndarray], None] | None = None
    converge: bool = False
    converge_tol: float = 1e-3
    time_limit: float | None = None
    fallback: str | None = "rrt"
    fallback_after: float = 0.15
    rrt: Any = None
    allow_no_collision: bool = False

    def validate(self, dtype: Any = np.float32) -> None:
        """ValueError/TypeError naming the first bad field; numbers must be finite in the
        computing ``dtype``."""
        npdt = numpy_dtype(scalar_type(dtype))
        for name, lo in (("iterations", 0), ("n_waypoints", 2), ("n_starts", 1)):
            _check_int(getattr(self, name), name, lo)
        if self.check_all_every is not None:
            _check_int(self.check_all_every, "check_all_every", 1)
        for name in ("step", "max_step"):
            v = getattr(self, name)
            if not (math.isfinite(real_number(v, name, npdt)) and v > 0):
                raise ValueError(f"{name}: expected a number > 0, got {v!r}")
        margin = real_number(self.margin, "margin")
        if not (math.isfinite(margin) and margin >= 0):
            raise ValueError(f"margin: expected a number >= 0 [m], got {self.margin!r}")
        real_number(self.margin, "margin", npdt)  # finite in the computing dtype too
        if margin > 1e3:
            raise ValueError(f"margin: {margin:g} m is not a clearance a robot can keep")
        sm = real_number(self.self_margin, "self_margin")
        if not (math.isfinite(sm) and sm >= 0):
            raise ValueError(f"self_margin: expected a number >= 0 [m], got {self.self_margin!r}")
        if self.endpoint_margin is not None:
            em = real_number(self.endpoint_margin, "endpoint_margin")
            if not (math.isfinite(em) and em >= 0):
                raise ValueError(f"endpoint_margin: expected a number >= 0 [m] or None, got "
                                 f"{self.endpoint_margin!r}")
        if self.eps is not None:
            eps = real_number(self.eps, "eps")
            if not (math.isfinite(eps) and eps > 0):
                raise ValueError(f"eps: expected a number > 0 [m], got {self.eps!r}")
            if eps < margin:
                raise ValueError(f"eps: must be >= margin ({margin:g} m), got {eps:g}")
            real_number(self.eps, "eps", npdt)
        if not isinstance(self.start_kind, str):
            raise TypeError(f"start_kind: expected one of "
                            f"{', '.join(map(repr, INITIAL_KINDS))}, got "
                            f"{type(self.start_kind).__name__} (give initial paths as seeds)")
        if self.start_kind not in INITIAL_KINDS:
            raise ValueError(f"start_kind: unknown kind '{self.start_kind}' (expected "
                             f"'straight', 'random' or 'mixed'; paths are seeds)")
        if self.n_substeps is not None:
            check_substeps(self.n_substeps)
        if self.weights is not None:
            if not isinstance(self.weights, PathWeights):
                raise TypeError(f"weights: expected a PathWeights, got "
                                f"{type(self.weights).__name__}")
            self.weights.validate()
        tol = real_number(self.converge_tol, "converge_tol")
        if not (math.isfinite(tol) and tol > 0):
            raise ValueError(f"converge_tol: expected a number > 0, got {self.converge_tol!r}")
        for name in ("freeze_feasible", "stop_when_solved", "free_via", "converge",
                     "allow_no_collision"):
            _check_flag(getattr(self, name), name)
        seed = self.seed
        if not (seed is None or isinstance(seed, (np.random.Generator, np.random.SeedSequence))):
            _check_int(seed, "seed", 0)
        if self.kappa is not None and not 0.0 < real_number(self.lam, "lam") <= 1.0:
            raise ValueError(f"lam: expected a damping factor in (0, 1], got {self.lam!r}")
        if self.callback is not None and not callable(self.callback):
            raise TypeError(f"callback: expected a callable (iteration, paths), got "
                            f"{type(self.callback).__name__}")
        _check_budget(self)


def _check_budget(o: "PlanOptions") -> None:
    """:meth:`PlanOptions.validate` of ``time_limit``, ``fallback``, ``fallback_after``
    and ``rrt``."""
    if o.time_limit is not None:
        if isinstance(o.time_limit, (bool, np.bool_)):
            raise TypeError(f"time_limit: expected a number of seconds > 0 or None, got "
                            f"{o.time_limit!r}")
        t = real_number(o.time_limit, "time_limit")
        if not (math.isfinite(t) and t > 0):
            raise ValueError(f"time_limit: expected a number > 0 [s] or None, got "
                             f"{o.time_limit!r}")
    if o.fallback is not None and (not isinstance(o.fallback, str)
                                   or o.fallback not in FALLBACKS):
        raise ValueError(f"fallback: expected 'rrt' or None, got {o.fallback!r}")
    f = real_number(o.fallback_after, "fallback_after")
    if not 0.0 < f < 1.0:
        raise ValueError(f"fallback_after: expected a number in (0, 1), got "
                         f"{o.fallback_after!r}")
    if o.rrt is not None:
        from jwarp.solvers.rrt import RRTOptions

        if not isinstance(o.rrt, RRTOptions):
            raise TypeError(f"rrt: expected a jwarp.solvers.rrt.RRTOptions, got "
                            f"{type(o.rrt).__name__}")
        o.rrt.validate()


@dataclass(frozen=True)
class ViaPoints:
    """Seeds of :meth:`Planner.plan` given as via points: ``points`` (k, n_dof),
    (n_seeds, k, n_dof) or (n_problems, n_seeds, k, n_dof) (k >= 0). Each seed is the
    path start -> via points -> goal of ``n_waypoints`` waypoints spread evenly along its
    joint-space length (as the random multi-starts), projected onto the limits."""

    points: Any


# ====================================================================== planner
class _Buffers:
    """The device buffers of one shape (P paths of W waypoints, n_sub substeps)."""

    def __init__(self, obj: PathObjective, B: int, gather: bool) -> None:
        P, W, n, S = obj.P, obj.W, obj.n, obj.S
        dev, sc = obj.device, obj.scalar
        self.key = (P, W, obj.n_sub)
        self.objective = obj
        self.used = False
        # every buffer is written before it is read
        self.idx = wp.empty(P, dtype=wp.int32, device=dev)             # path indices
        self.final = wp.empty((P, W, n), dtype=sc, device=dev)          # kept paths
        self.final_cost = wp.empty((P, 3), dtype=sc, device=dev)        # U_path, U_l, coll.
        self.feasible = wp.empty(P, dtype=wp.int32, device=dev)
        self.best = wp.empty(B, dtype=wp.int32, device=dev)
        self.best_path = wp.empty((B, W, n), dtype=sc, device=dev)
        self.best_cost = wp.empty((B, 3), dtype=sc, device=dev)
        #: candidates of the exact checks gathered on the device (``gather``; else None:
        #: on the CPU the host reads the arrays in place)
        self.cand_paths = self.cand_sub = None
        if gather:
            self.cand_paths = wp.empty((P, W, n), dtype=sc, device=dev)
            self.cand_sub = wp.empty((P * S, n), dtype=sc, device=dev)


class Planner:
    """A persistent batched planner (thesis 3.3, gradient descent on U_path eq. 3.16) for
    ``n_problems`` start/goal pairs at a time on one device.

    Args:
        robot: robot name or RobotModel.
        world: a :class:`jwarp.world.World` of the robot's workspace dimension.
        n_problems: B, the start/goal pairs of every :meth:`plan` call.
        options: :class:`PlanOptions` (None: the defaults); validated here, and copied.
        device: Warp device of the optimisation and of every check (collision, limits,
            elastic equilibrium, substep sizing); None: Warp's default device (docs/api.md
            "Devices").
        dtype: float type of the optimisation (None: float32); the exact feasibility
            checks run in float64.
        warm_start: optional learned warm start (thesis 3.4.3): any object with a callable
            ``paths(starts (B, n_dof), goals (B, n_dof), world) -> (B, H, W, n_dof)``
            (e.g. ``jwarp.learn.plan_net.PlanNet``). A :meth:`plan` call without seeds then
            starts from its H paths per problem, followed by ``options.n_starts - H``
            multi-starts of kind ``options.start_kind`` (none if ``n_starts <= H``) of the
            network's W waypoints; explicit seeds win. TypeError naming ``warm_start`` if
            it has no callable ``paths``.

    The device buffers (paths, substeps, costs, gradients, the kept paths and the
    per-problem selection) are allocated by the first :meth:`plan` call and reused by
    every later call of the same shapes (seeds per problem, waypoints, substeps: give
    ``options.n_substeps`` to keep the shapes fixed; sized substeps follow each call's
    initial paths). The best start of every problem is chosen on the device; only the
    per-path screen, the candidates of the exact checks and the chosen paths are read.

    Example::

        planner = Planner("planar4", world, 64, PlanOptions(n_starts=8, n_substeps=8))
        res = planner.plan(starts, goals)                 # random multi-starts
        res = planner.plan(starts, goals, seeds=guesses)  # e.g. learned warm starts
    """

    def __init__(self, robot: Any, world: Any, n_problems: int,
                 options: PlanOptions | None = None, device: Any = None,
                 dtype: Any = None, warm_start: Any = None) -> None:
        init_warp()
        if warm_start is not None and not callable(getattr(warm_start, "paths", None)):
            raise TypeError(f"warm_start: expected an object with a callable paths(starts, "
                            f"goals, world) (e.g. a loaded planning network), got "
                            f"{type(warm_start).__name__}")
        self.warm_start = warm_start
        self.robot = get_robot(robot)
        check_world(self.robot, world)
        self.world = world
        _check_int(n_problems, "n_problems", 1)
        self.n_problems = int(n_problems)
        if options is None:
            options = PlanOptions()
        if not isinstance(options, PlanOptions):
            raise TypeError(f"options: expected a PlanOptions, got {type(options).__name__}")
        self.scalar = scalar_type(np.float32 if dtype is None else dtype)
        self.npdt = numpy_dtype(self.scalar)
        options.validate(self.npdt)
        o = replace(options, step=float(options.step), max_step=float(options.max_step),
                    margin=real_number(options.margin, "margin"))
        self.device = resolve_device(device)
        if not o.allow_no_collision:
            check_collision_model(self.robot, need_spheres=True, what="planning",
                                  device=self.device)
        self.options = o
        #: gather the candidates and keep the final paths with kernels (on a GPU); on the
        #: CPU the host indexes the device arrays in place (the same numbers, no launches)
        self._kernel_copies = not self.device.is_cpu
        #: smoothing width of the collision cost [m] (options.eps or its default)
        self.eps = (real_number(o.eps, "eps") if o.eps is not None
                    else max(float(world.resolution), 0.01, o.margin))
        real_number(self.eps, "eps", self.npdt)
        if o.kappa is not None:
            kappa_array(self.robot, o.kappa)  # validates, naming kappa
        self._buffers: _Buffers | None = None
        self._motion = None  # the continuous path check (motion_check())
        #: a batch of worlds (World.batch): problem b plans in world b
        self.batched = world.n_worlds > 1
        if self.batched and world.n_worlds != self.n_problems:
            raise ValueError(f"world: a batch of {world.n_worlds} worlds needs as many "
                             f"problems, got n_problems={self.n_problems}")
        if self.batched and o.kappa is not None:
            raise ValueError("kappa: a batch of worlds plans on the rigid model only")
        self._reach = None   # sphere_reach of the robot (substeps in exact worlds)

    # ------------------------------------------------------------------ public
    def plan(self, start: Any, goal: Any, seeds: Any = None) -> PlanResult:
        """Plan the ``n_problems`` paths from ``start`` to ``goal``.

        Args:
            start, goal: (n_problems, n_dof) or (n_dof,) joint values [rad or m] (a single
                configuration is used for every problem). Checked: within the limits,
                collision-free with ``options.margin`` (and a converged equilibrium on the
                elastic model).
            seeds: the initial paths: None draws ``options.n_starts`` multi-starts of kind
                ``options.start_kind`` (with a ``warm_start``: its paths first); an array
                of paths (W, n_dof), (n_seeds, W, n_dof) or
                (n_problems, n_seeds, W, n_dof) (their first/last rows are replaced by
                start/goal, they are projected onto the limits, and W is theirs), e.g.
                learned warm starts; or :class:`ViaPoints`.

        Returns:
            :class:`PlanResult` (``wall_time``: this call).
        """
        if seeds is None and self.warm_start is not None:
            seeds = self._warm_seeds(start, goal)
        model = self.robot
        if not model.has_harmonic:
            return self._plan(start, goal, seeds, "seeds")
        # transmission errors: the kernels and checks work in the links' joint space; the
        # endpoints and seeds go in through q' = q + dq(q), the paths come back through its
        # inverse (waypoints exact; between them the links follow the straight segment in
        # q', which differs from the one in q by the change of dq along it)
        q0 = transmitted(model, self._problems(start, "start"))
        q1 = transmitted(model, self._problems(goal, "goal"))
        if seeds is not None and not isinstance(seeds, (str, ViaPoints)):
            seeds = transmitted(model, real_array(seeds, "seeds"))
        elif isinstance(seeds, ViaPoints):
            seeds = ViaPoints(transmitted(model, real_array(seeds.points, "seeds")))
        res = self._plan(q0, q1, seeds, "seeds")
        res.path = untransmitted(model, res.path)
        res.paths_source = untransmitted(model, res.all_paths)
        return res

    def _warm_seeds(self, start: Any, goal: Any) -> np.ndarray:
        """The warm start's paths (B, H, W, n_dof), then ``n_starts - H`` multi-starts."""
        q0, q1 = self._problems(start, "start"), self._problems(goal, "goal")
        raw = self.warm_start.paths(q0.copy(), q1.copy(), self.world)
        if hasattr(raw, "detach") and hasattr(raw, "cpu"):  # a torch tensor
            raw = raw.detach().cpu().numpy()
        g = np.asarray(raw, dtype=np.float64)
        if g.ndim != 4 or g.shape[0] != len(q0) or g.shape[3] != self.robot.n_dof \
                or g.shape[1] == 0 or g.shape[2] < 2 or not np.all(np.isfinite(g)):
            raise ValueError(f"warm_start: paths() returned shape {g.shape}, expected "
                             f"({len(q0)}, H, W, {self.robot.n_dof}) finite values")
        o = self.options
        extra = o.n_starts - g.shape[1]
        if extra > 0:
            r = _initial(self.robot, q0, q1, o.start_kind, extra, g.shape[2], o.seed, self.world,
                         o.free_via, device=self.device)
            g = np.concatenate([g, r], axis=1)
        return g

    @property
    def objective(self) -> PathObjective | None:
        """The :class:`PathObjective` (device buffers) of the last call's shapes; None
        before the first call."""
        return None if self._buffers is None else self._buffers.objective

    # ------------------------------------------------------------------ steps
    def _plan(self, start: Any, goal: Any, seeds: Any, seeds_name: str,
              t_start: float | None = None) -> PlanResult:
        """The multi-start optimisation, then (``options.fallback``) the fallback for the
        problems it has not solved; ``t_start``: the ``time.perf_counter()`` at which the
        call started (the clock of ``time_limit``; None: now)."""
        t0 = time.perf_counter() if t_start is None else t_start
        model, o, dev = self.robot, self.options, self.device
        deadline = None if o.time_limit is None else t0 + float(o.time_limit)
        opt_deadline = deadline
        if deadline is not None and o.fallback is not None:
            opt_deadline = t0 + float(o.fallback_after) * float(o.time_limit)
        q0 = self._problems(start, "start")
        q1 = self._problems(goal, "goal")
        finite_as(q0, self.npdt, "start")  # also finite in the optimisation's dtype
        finite_as(q1, self.npdt, "goal")
        em = o.margin if o.endpoint_margin is None else min(o.margin, o.endpoint_margin)
        sem = min(o.self_margin, em)
        pw = 1 if self.batched else 0
        check_endpoints(model, self.world, q0, "start", em, o.kappa, device=dev,
                        self_margin=sem, per_world=pw)
        check_endpoints(model, self.world, q1, "goal", em, o.kappa, device=dev,
                        self_margin=sem, per_world=pw)
        if isinstance(seeds, ViaPoints):
            Q = _via_seeds(model, q0, q1, seeds.points, o.n_waypoints)
        else:
            Q = _initial(model, q0, q1, o.start_kind if seeds is None else seeds, o.n_starts,
                         o.n_waypoints, o.seed, self.world, o.free_via, device=dev,
                         name=seeds_name)  # (B, n_starts, W, n)
        B, n_starts, W = Q.shape[:3]
        P = B * n_starts
        Qf = Q.reshape(P, W, model.n_dof)
        n_sub = o.n_substeps
        if n_sub is None and self.world.has_grid:
            n_sub = substeps_for_voxel(model, Qf, float(self.world.resolution), device=dev)
        elif n_sub is None:  # exact objects only: the check is continuous, the cost a guide
            from jwarp.world.motion import travel_bound

            if self._reach is None:
                from jwarp.world.motion import sphere_reach
                self._reach = sphere_reach(model)
            n_sub = int(np.clip(np.ceil(travel_bound(model, Qf, self._reach).max(initial=0.0)
                                        / EXACT_SUBSTEP), 1, 16))
        buf = self._prepare(P, W, n_sub)
        obj = buf.objective
        obj.set_paths(Qf)
        if buf.used:  # the last call left paths inactive
            obj.set_active(np.ones(P, bool))
        buf.used = True

        # screen: a substep whose (weighted, clipped) cost is below w_min c(margin) has no
        # sphere within margin; such paths get the exact check every iteration, all others
        # every check_all_every iterations and after the last one
        check_every = o.check_all_every if o.check_all_every is not None else (
            10 if self.world.has_grid else 1)
        w = obj.weights
        w_min = min([v for v in (w.world, w.self) if v > 0] or [0.0])
        screen = w_min * (self.eps - o.margin) ** 2 / (2.0 * self.eps)
        done = np.zeros(P, bool)
        feasible = np.zeros(P, bool)
        iters = np.full(P, o.iterations, np.int64)
        kept_len = np.full(P, np.inf)  # converge: U_l of the last kept feasible iterate
        reason = "iterations"
        for it in range(o.iterations + 1):
            # the time limit: checked before the evaluation; the current paths still get
            # their exact check below
            out_of_time = opt_deadline is not None and time.perf_counter() >= opt_deadline
            obj.evaluate(grad=it < o.iterations and not out_of_time)
            if o.callback is not None:
                o.callback(it, obj.paths.numpy())
            smax = obj.sub_max.numpy()
            last = it == o.iterations or out_of_time or (it + 1) % check_every == 0
            if o.converge:
                self._converge_check(buf, it, last, smax < screen, done, feasible, iters,
                                     kept_len)
                solved = done & feasible
            else:
                cand = np.nonzero(~done & ((smax < screen) | last))[0]
                if len(cand):
                    newly = cand[self._confirm(buf, cand)]
                    if len(newly):
                        feasible[newly] = True
                        iters[newly] = it
                        if o.freeze_feasible:
                            self._keep(buf, newly)
                            done[newly] = True
                solved = feasible
                if o.stop_when_solved and o.freeze_feasible and B > 1:
                    # a solved problem needs nothing more: its other starts stop here
                    # (kept as they are), so they cost no evaluation or check from now on
                    fin = np.repeat(solved.reshape(B, n_starts).any(1), n_starts) & ~done
                    if fin.any():
                        self._keep(buf, np.nonzero(fin)[0])
                        done[fin] = True
            if o.stop_when_solved and solved.reshape(B, n_starts).any(1).all():
                reason = "solved"
                break
            if done.all():
                reason = "all_done"
                break
            if it == o.iterations:
                break
            if out_of_time:
                reason = "time_limit"
                iters[~feasible] = it
                break
            if o.freeze_feasible:
                obj.set_active(~done)
            obj.step(o.step, o.max_step)
        # converge: a feasible path's final is its last feasible iterate, already kept
        rest = np.nonzero(~done & ~feasible)[0] if o.converge else np.nonzero(~done)[0]
        if len(rest):
            self._keep(buf, rest)
        res = self._result(buf, feasible, iters, B, n_starts, time.perf_counter() - t0)
        res.stop_reason = reason
        res.stage = np.where(res.feasible, "optimizer", "none")
        res.timings = {"optimizer": time.perf_counter() - t0}
        if o.fallback is not None and not res.feasible.all():
            _fallback(self, res, q0, q1, t0, deadline)
        res.reasons = self.explain(res)
        res.wall_time = time.perf_counter() - t0
        return res

    def explain(self, res: PlanResult) -> list[str]:
        """Per problem of ``res``: "feasible", or why its best path is not: the first
        colliding link and object (or link pair), an uncertified approach, or the joint
        limits (one check of the infeasible problems' paths on the device), then what the
        RRT fallback did ("; fallback: ...", :attr:`PlanResult.fallback_notes`)."""
        out = self._explain(res)
        notes = res.fallback_notes
        if notes is not None:
            for i in np.nonzero(~np.asarray(res.feasible, bool))[0]:
                if notes[i]:
                    out[i] = f"{out[i]}; fallback: {notes[i]}"
        return out

    def _explain(self, res: PlanResult) -> list[str]:
        """:meth:`explain` without the fallback's notes."""
        out = ["feasible"] * len(res.feasible)
        bad = np.nonzero(~np.asarray(res.feasible, bool))[0]
        if not len(bad):
            return out
        o = self.options
        if o.kappa is not None:
            for i in bad:
                out[i] = "not feasible on the elastic model (collision or limits at a substep)"
            return out
        paths = np.asarray(res.path)
        if self.batched:  # the paths of every problem, so path b is in world b
            chk = self.motion_check().check(paths, margin=o.margin,
                                            endpoint_margin=o.endpoint_margin,
                                            self_margin=o.self_margin, world_group=1)
            for i in bad:
                out[i] = chk.reason(i) if not chk.ok[i] else \
                    "not feasible: the optimisation ran out of iterations or time"
            return out
        chk = self.motion_check().check(paths[bad], margin=o.margin,
                                        endpoint_margin=o.endpoint_margin,
                                        self_margin=o.self_margin)
        for k, i in enumerate(bad):
            out[i] = chk.reason(k) if not chk.ok[k] else \
                "not feasible: the optimisation ran out of iterations or time"
        return out

    def _converge_check(self, buf: _Buffers, it: int, last: bool, screened: np.ndarray,
                        done: np.ndarray, feasible: np.ndarray, iters: np.ndarray,
                        kept_len: np.ndarray) -> None:
        """One iteration's checks of :attr:`PlanOptions.converge` (arrays (P,) updated in
        place): paths not yet feasible are checked as without ``converge``; feasible ones
        every ``check_all_every`` iterations. Every confirmed iterate is kept; a feasible
        path whose U_l changed by <= ``converge_tol`` (relative) since its last kept
        iterate is done. A feasible path that left feasibility goes on; its last feasible
        iterate stays kept."""
        last = last or it == 0  # converge: every path is checked once at the start
        cand = np.nonzero(~done & np.where(feasible, last, screened | last))[0]
        if not len(cand):
            return
        good = cand[self._confirm(buf, cand)]
        if not len(good):
            return
        length = buf.objective.length.numpy().astype(np.float64)[good]
        again = feasible[good]
        change = np.abs(length - kept_len[good])
        stop = good[again & (change <= self.options.converge_tol * np.abs(kept_len[good]))]
        feasible[good] = True
        iters[good] = it
        kept_len[good] = length
        self._keep(buf, good)
        done[stop] = True

    def _problems(self, x: Any, name: str) -> np.ndarray:
        q = _configs(x, self.robot, name)
        if len(q) == 1 and self.n_problems > 1:
            q = np.repeat(q, self.n_problems, 0)
        if len(q) != self.n_problems:
            raise ValueError(f"{name}: expected {self.n_problems} configurations (n_problems) "
                             f"or one, got {len(q)}")
        return q

    def _prepare(self, P: int, W: int, n_sub: int) -> _Buffers:
        """The buffers of this shape: the last call's, else new ones."""
        buf = self._buffers
        if buf is not None and buf.key == (P, W, n_sub):
            return buf
        self._buffers = None  # free the old ones first
        o = self.options
        obj = PathObjective(self.robot, self.world, P, W, n_sub, weights=o.weights,
                            eps=self.eps, kappa=o.kappa, lam=o.lam, device=self.device,
                            dtype=self.npdt)
        if self.batched:  # substep rows of problem b's paths are in world b
            obj.group_div = obj.S * (P // self.n_problems)
        obj.skip_inactive = bool(o.freeze_feasible)  # frozen paths cost no collision queries
        self._buffers = _Buffers(obj, self.n_problems, self._kernel_copies)
        return self._buffers

    def _upload_idx(self, buf: _Buffers, idx: np.ndarray) -> None:
        host: wp.array = wp.array(np.ascontiguousarray(idx, np.int32), dtype=wp.int32, device="cpu")
        wp.copy(buf.idx, host, count=len(idx))

    def motion_check(self) -> Any:
        """The planner's :class:`jwarp.world.motion.MotionCheck` (made on first use)."""
        if self._motion is None:
            from jwarp.world.motion import MotionCheck, MotionOptions

            # a bounded proof per segment: a path grazing the margin for longer than the
            # budget stays "not yet feasible" and the descent goes on moving it
            # on a GPU one thread would advance a grazing segment alone (the launch waits
            # for it): more parallel rounds, fewer sequential evaluations
            opts = (MotionOptions(max_evals=PLANNER_CHECK_EVALS_GPU, rounds=8)
                    if self.device.is_cuda else MotionOptions(max_evals=PLANNER_CHECK_EVALS))
            self._motion = MotionCheck(self.robot, self.world, device=self.device,
                                       options=opts)
        return self._motion

    def _confirm(self, buf: _Buffers, cand: np.ndarray) -> np.ndarray:
        """Exact feasibility of the candidate paths: rigid model: the continuous check on
        the device (:mod:`jwarp.world.motion`), one launch over the candidates' segments,
        one flag per candidate read back; elastic model: every substep at its converged
        torque equilibrium (host loop)."""
        o = self.options
        if o.kappa is None:
            obj = buf.objective
            self._upload_idx(buf, cand)
            # stop when solved: one proven path per problem is enough (the others of
            # that problem are skipped inside the launch)
            group = obj.P // self.n_problems if (o.stop_when_solved and not o.converge) else 0
            out = self.motion_check().launch(obj.paths, buf.idx, len(cand), margin=o.margin,
                                             endpoint_margin=o.endpoint_margin, group=group,
                                             self_margin=o.self_margin,
                                             world_group=obj.P // self.n_problems
                                             if self.batched else 0)
            return out["ok"].numpy()[:len(cand)].astype(bool)
        return self._confirm_elastic(buf, cand)

    def _confirm_elastic(self, buf: _Buffers, cand: np.ndarray) -> np.ndarray:
        """Exact feasibility of the candidate paths (zero collision cost): every substep
        collision-free with ``margin`` and every waypoint within the limits. Only the
        candidates' paths and substeps are read (gathered on the device)."""
        obj, o, dev = buf.objective, self.options, self.device
        S, n, K = obj.S, obj.n, len(cand)
        if self._kernel_copies:
            self._upload_idx(buf, cand)
            wp.launch(obj.k.gather, dim=(K, S),
                      inputs=[obj.paths, obj.q_sub, buf.idx, obj.n_sub],
                      outputs=[buf.cand_paths, buf.cand_sub], device=dev)
            q = buf.cand_sub[:K * S].numpy().astype(np.float64)
            paths = buf.cand_paths[:K].numpy().astype(np.float64)
        else:  # CPU: the arrays are host memory
            q = obj.q_sub.numpy().reshape(obj.P, S, n)[cand].reshape(K * S, n).astype(np.float64)
            paths = obj.paths.numpy()[cand].astype(np.float64)
        # elastic: the converged torque equilibrium at every substep, not the kept rows
        free = collision_free(self.robot, self.world, q, o.margin, kappa=o.kappa, device=dev)
        ok = free.reshape(K, S).all(axis=1) & within_limits(self.robot, paths).all(axis=1)
        # the paths moved since n_substeps was chosen: re-check the survivors at substeps
        # sized to their own segments (no sphere centre moves more than half a voxel per
        # substep)
        surv = np.nonzero(ok)[0]
        if len(surv):  # every survivor's own count, checked in one call per count
            need = substeps_per_path(self.robot, paths[surv], float(self.world.resolution),
                                     safety=SWEEP_SAFETY, max_substeps=MAX_CHECK_SUBSTEPS,
                                     device=dev)
            for k in np.unique(need[need > obj.n_sub]):
                sel = surv[need == k]
                ok[sel] = path_feasible(self.robot, self.world, paths[sel], int(k),
                                        margin=o.margin, kappa=o.kappa, device=dev)
        return ok

    def _keep(self, buf: _Buffers, idx: np.ndarray) -> None:
        """Keep the current paths ``idx`` and their costs as final (on the device)."""
        obj = buf.objective
        if not self._kernel_copies:  # CPU: the arrays are host memory
            buf.final.numpy()[idx] = obj.paths.numpy()[idx]
            cost = buf.final_cost.numpy()
            for c, a in enumerate((obj.total, obj.length, obj.collision)):
                cost[idx, c] = a.numpy()[idx]
            return
        self._upload_idx(buf, idx)
        wp.launch(obj.k.keep, dim=(len(idx), obj.W),
                  inputs=[obj.paths, obj.total, obj.length, obj.collision, buf.idx],
                  outputs=[buf.final, buf.final_cost], device=self.device)

    def _result(self, buf: _Buffers, feasible: np.ndarray, iters: np.ndarray, B: int,
                n_starts: int, wall: float) -> PlanResult:
        """Per problem the best start (feasible first, then the lowest U_path), chosen on
        the device; reads the chosen paths and costs only."""
        obj = buf.objective
        host: wp.array = wp.array(feasible.astype(np.int32), dtype=wp.int32, device="cpu")
        wp.copy(buf.feasible, host)
        wp.launch(obj.k.select, dim=B, inputs=[buf.final, buf.final_cost, buf.feasible,
                                               n_starts],
                  outputs=[buf.best, buf.best_path, buf.best_cost], device=self.device)
        best = buf.best.numpy().astype(np.int64)
        cost = buf.best_cost.numpy().astype(np.float64)
        rows = np.arange(B)
        fz = feasible.reshape(B, n_starts)
        it = iters.reshape(B, n_starts)
        return PlanResult(path=buf.best_path.numpy().astype(np.float64), feasible=fz[rows, best],
                          cost=np.ascontiguousarray(cost[:, 0]),
                          length_cost=np.ascontiguousarray(cost[:, 1]),
                          collision_cost=np.ascontiguousarray(cost[:, 2]),
                          iterations=it[rows, best], start_index=best, n_feasible=fz.sum(1),
                          wall_time=wall, n_substeps=obj.n_sub, all_feasible=fz,
                          all_iterations=it, paths_source=wp.clone(buf.final))


def _fallback(planner: "Planner", res: PlanResult, q0: np.ndarray, q1: np.ndarray, t0: float,
              deadline: float | None) -> None:
    """:attr:`PlanOptions.fallback` for the problems of ``res`` without a feasible path:
    RRT-Connect (:func:`jwarp.solvers.rrt.rrt_connect`, with the planner's margins, kappa
    and device) for each in turn, each path found resampled to the W waypoints
    (:func:`jwarp.solvers.rrt.resample_path`: its nodes kept where it has at most W) as
    the one seed of a gradient optimisation of the same options (no fallback,
    ``stop_when_solved``) of all of them at once. On the rigid model that optimisation's
    exact check is the RRT's own (:func:`jwarp.solvers.feasibility.certify_check`: the
    same pairs, margins and evaluation budget), so a seed the trees proved is certified as
    it is at iteration 0 and returned (the trees' shortcuts were checked by it too); a
    seed that is not (more than W nodes, so its corners were cut) is optimised and kept
    only if that ends certified. Its feasible paths replace those problems' results in
    ``res`` (stage "fallback", ``start_index`` -1); ``fallback_notes``, ``stop_reason``
    and ``timings`` updated. With a ``deadline`` the trees get 80 % of the time left, the
    optimisation the rest."""
    from jwarp.solvers.rrt import RRTOptions, resample_path, rrt_connect

    o = planner.options
    t_rrt = time.perf_counter()
    ro = o.rrt if o.rrt is not None else RRTOptions()
    rng = ro.seed if isinstance(ro.seed, np.random.Generator) else np.random.default_rng(ro.seed)
    ropt = replace(ro, seed=rng)
    rrt_stop = None if deadline is None else t_rrt + 0.8 * max(0.0, deadline - t_rrt)
    W = res.path.shape[1]
    notes = res.fallback_notes = np.full(len(res.feasible), "", dtype=object)
    found, seeds, nodes = [], [], []
    timed_out = False
    for b in np.nonzero(~res.feasible)[0]:
        if rrt_stop is not None and time.perf_counter() >= rrt_stop:
            timed_out = True
            notes[b] = "RRT-Connect not run: no time left"
            continue
        r = rrt_connect(planner.robot, planner.world.select(int(b)), q0[b], q1[b], ropt,
                        margin=o.margin,
                        kappa=o.kappa, device=planner.device, deadline=rrt_stop,
                        endpoint_margin=o.endpoint_margin, self_margin=o.self_margin)
        if r.success:
            found.append(int(b))
            seeds.append(resample_path(r.path, W))
            nodes.append(len(r.path))
        else:
            why = {"max_samples": "rrt.max_samples used up",
                   "time_limit": "out of time",
                   "check_mismatch": "its path failed the edge-by-edge re-check"}.get(
                       r.stop_reason, r.stop_reason)
            notes[b] = (f"RRT-Connect found no path ({why}; {r.n_samples} samples, "
                        f"{r.n_nodes} nodes, {r.wall_time:.2f} s)")
        timed_out |= r.stop_reason == "time_limit"
    res.timings["rrt"] = time.perf_counter() - t_rrt
    if found:
        t_opt = time.perf_counter()
        left = None if deadline is None else max(deadline - t_opt, 1e-6)
        # every iteration checked (the first before any step: the seed as it is)
        sub_o = replace(o, n_starts=1, fallback=None, time_limit=left, stop_when_solved=True,
                        callback=None, check_all_every=1)
        sub_world = planner.world
        if planner.batched:  # the found problems' own worlds, as a batch of their own
            from jwarp.world.sdf import World
            sub_world = World.batch([planner.world.select(int(b)) for b in found])
        sub = Planner(planner.robot, sub_world, len(found), sub_o, device=planner.device,
                      dtype=planner.npdt)
        if o.kappa is None:  # certify with the check that proved the RRT's edges
            sub._motion = certify_check(planner.robot, sub_world, device=planner.device)
        idx = np.array(found)
        r2 = sub._plan(q0[idx], q1[idx], np.stack(seeds)[:, None], "seeds")
        timed_out |= r2.stop_reason == "time_limit"
        ok = r2.feasible
        b = idx[ok]
        res.path[b] = r2.path[ok]
        res.feasible[b] = True
        res.cost[b] = r2.cost[ok]
        res.length_cost[b] = r2.length_cost[ok]
        res.collision_cost[b] = r2.collision_cost[ok]
        res.iterations[b] = r2.iterations[ok]
        res.start_index[b] = -1
        res.stage[b] = "fallback"
        res.timings["fallback_optimizer"] = time.perf_counter() - t_opt
        for k, bb in enumerate(found):
            cut = (f", resampled to {W} waypoints (corners cut)" if nodes[k] > W
                   else f" as {W} waypoints")
            if ok[k]:
                how = ("certified as it is" if r2.iterations[k] == 0 else
                       f"certified after {int(r2.iterations[k])} optimisation steps")
                notes[bb] = f"RRT-Connect path of {nodes[k]} nodes{cut}: {how}"
            else:
                notes[bb] = (f"RRT-Connect path of {nodes[k]} nodes{cut} not certified "
                             f"({_seed_reason(planner, sub, seeds[k], bb)}) and its "
                             f"optimisation ended infeasible")
    if res.feasible.all():
        res.stop_reason = "solved"
    elif deadline is not None and (timed_out or time.perf_counter() >= deadline):
        res.stop_reason = "time_limit"
    else:
        res.stop_reason = "iterations"


def _seed_reason(planner: "Planner", sub: "Planner", seed: np.ndarray, b: int) -> str:
    """Why the fallback seed (W, n_dof) of problem ``b`` is not certified, in words (the
    fallback optimisation's check, in the problem's own world)."""
    o = planner.options
    if o.kappa is not None:
        ok = path_feasible(planner.robot, planner.world.select(int(b)), seed[None],
                           sub.objective.n_sub if sub.objective is not None else 1,
                           margin=o.margin, kappa=o.kappa, device=planner.device,
                           self_margin=o.self_margin)[0]
        return "certified now" if ok else "not feasible on the elastic model"
    chk = certify_check(planner.robot, planner.world.select(int(b)), device=planner.device)
    c = chk.check(seed[None].astype(planner.npdt).astype(np.float64), margin=o.margin,
                  endpoint_margin=o.endpoint_margin, self_margin=o.self_margin)
    return c.reason(0)


def plan(robot: Any, world: Any, start: Any, goal: Any, *, seeds: Any = None,
         device: Any = None, dtype: Any = np.float32, options: PlanOptions | None = None,
         **overrides: Any) -> PlanResult:
    """Plan collision-free paths from ``start`` to ``goal`` by gradient descent on U_path:
    one call of a :class:`Planner` made for it.

    Args:
        robot: robot name or RobotModel.
        world: a :class:`jwarp.world.World` of the robot's workspace dimension.
        start, goal: (n_dof,) or (B, n_dof) joint values [rad or m] (B problems).
        seeds: optional user guesses (W, n_dof), (n_starts, W, n_dof) or
            (B, n_starts, W, n_dof) (the ``seeds`` of :meth:`Planner.plan`; ``n_starts``
            and ``n_waypoints`` are then theirs, and ``start_kind`` is unused).
        device, dtype: Warp device of the optimisation and of every check, and its float
            type (default: Warp's default device, as :class:`Planner`; float32).
        options: :class:`PlanOptions` (None: its defaults); not modified.
        **overrides: any field of :class:`PlanOptions` as a keyword (``n_starts=16``,
            ``iterations=300``, ``callback=f``, ...): the options are
            ``dataclasses.replace(options, **overrides)``, so an override wins over the same
            field of ``options`` (``stop_when_solved`` True and ``fallback`` "rrt" by
            default: pass False / None to optimise every start until it is feasible
            without a fallback). ``time_limit`` counts from the start of this call.
            The old ``initial`` (one release, with a DeprecationWarning) is
            ``start_kind`` when a string, else ``seeds``.

    Returns:
        :class:`PlanResult` (``wall_time``: the whole call).

    Raises:
        ValueError: bad shapes, NaN, start/goal outside the limits or in collision, world
            and robot dimensions differ, bad options.
        TypeError: an override that is not a field of :class:`PlanOptions` (named, with
            the list of fields), ``options`` not a :class:`PlanOptions`.
    """
    t0 = time.perf_counter()
    if not isinstance(overrides.get("initial", ""), str):  # the old name of seeds
        given = {"initial": overrides.pop("initial")}
        if seeds is not None:
            given["seeds"] = seeds
        seeds = translate("plan()", {"initial": "seeds"}, given)["seeds"]
    init_warp()
    model = get_robot(robot)
    check_world(model, world)
    q0 = _configs(start, model, "start")
    q1 = _configs(goal, model, "goal")
    if len(q0) != len(q1):
        if len(q0) == 1:
            q0 = np.repeat(q0, len(q1), 0)
        elif len(q1) == 1:
            q1 = np.repeat(q1, len(q0), 0)
        else:
            raise ValueError(f"start, goal: batch sizes differ ({len(q0)} vs {len(q1)})")
    options = with_overrides("plan", PlanOptions, options, overrides)
    planner = Planner(model, world, len(q0), options, device=device, dtype=dtype)
    res = planner._plan(q0, q1, seeds, "seeds", t_start=t0)
    res.wall_time = time.perf_counter() - t0
    return res


def _initial(model: RobotModel, q0: np.ndarray, q1: np.ndarray, initial: Any, n_starts: int,
             W: int, seed: Any, world: Any = None, free_via: bool = True, device: Any = None,
             name: str = "initial") -> np.ndarray:
    """Initial paths (B, n_starts, W, n_dof): of a kind (:data:`INITIAL_KINDS`) or from
    the caller's guesses ``initial`` (errors name ``name``)."""
    B, n = q0.shape
    if isinstance(initial, str):
        rng = np.random.default_rng(seed)
        if initial == "straight":
            return initial_paths(q0, q1, W, "straight")[:, None]
        if initial in ("random", "mixed"):
            k = n_starts if initial == "random" else n_starts - 1
            parts = []
            if initial == "mixed":
                parts.append(initial_paths(q0, q1, W, "straight")[:, None])
            if k > 0:
                r = initial_paths(np.repeat(q0, k, 0), np.repeat(q1, k, 0), W, "random",
                                  robot=model, rng=rng, world=world if free_via else None,
                                  device=device)
                parts.append(r.reshape(B, k, W, n))
            return np.concatenate(parts, axis=1)
        raise ValueError(f"{name}: unknown kind '{initial}' (expected 'straight', 'random', "
                         f"'mixed' or an array of paths)")
    g = _seed_array(initial, name, q0.shape, "W", 2)
    g[:, :, 0] = q0[:, None]
    g[:, :, -1] = q1[:, None]
    return project_numpy(model, g)


def _seed_array(x: Any, name: str, shape: tuple[int, int], rows: str, min_rows: int
                ) -> np.ndarray:
    """Seeds (rows, n), (n_seeds, rows, n) or (B, n_seeds, rows, n) with rows >= min_rows
    -> (B, n_seeds, rows, n) float64, a copy; errors name ``name``."""
    B, n = shape
    g = real_array(x, name)
    if g.ndim == 2:
        g = g[None, None]
    elif g.ndim == 3:
        g = g[None]
    if (g.ndim != 4 or g.shape[-1] != n or g.shape[-2] < min_rows
            or g.shape[0] not in (1, B)):
        what = "paths" if rows == "W" else "via points"
        raise ValueError(f"{name}: expected {what} ({rows}, {n}), (n_starts, {rows}, {n}) or "
                         f"({B}, n_starts, {rows}, {n}), got {np.shape(x)}")
    if not np.all(np.isfinite(g)):
        raise ValueError(f"{name}: contains NaN or inf")
    return np.array(np.broadcast_to(g, (B,) + g.shape[1:]), np.float64)


def _via_seeds(model: RobotModel, q0: np.ndarray, q1: np.ndarray, points: Any, W: int
               ) -> np.ndarray:
    """Seed paths (B, n_seeds, W, n_dof) through the via points of :class:`ViaPoints`."""
    v = _seed_array(points, "seeds", q0.shape, "k", 0)
    B, K = v.shape[:2]
    out = np.empty((B, K, W, q0.shape[1]))
    for b in range(B):
        for i in range(K):
            out[b, i] = polyline_path(q0[b], v[b, i], q1[b], W)
    return project_numpy(model, out)
