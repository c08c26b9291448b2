"""The options of an inverse-kinematics solve: :class:`IKOptions`, :class:`IKWeights`,
the orientation modes."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from jwarp.core.arrays import real_array, real_number
from jwarp.kernels import ik as ik_kernels
from jwarp.model import RobotModel
from jwarp.solvers.options import SolverOptions
from jwarp.solvers.overrides import renamed_options
from jwarp.utils.checks import check_int

if TYPE_CHECKING:
    from jwarp.world.sdf import World

#: the largest accepted position tolerance [m] (IKOptions.tol_pos): larger means nothing
MAX_TOL_POS = 1e3


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


@renamed_options(max_iterations="iterations")
@dataclass
class IKOptions(SolverOptions):
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
        cuda_graphs: on CUDA, replay the rigid robot's iterations between two counter
            reads as one CUDA graph each (captured on first use; fewer launches from the
            host). False launches every kernel from Python (the same arithmetic).
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
        mesh_margin: a robot whose spheres only approximate its meshes (relation
            "approximate") solves with each link's spheres grown by its measured poke-out
            (as ``PlanOptions.mesh_margin``; a warning once per robot); False: as they are.

    ``validate()`` (also run on construction) raises ValueError/TypeError naming the field.
    """

    # the fields of SolverOptions with the IK's defaults (the others as there)
    n_starts: int = 16
    iterations: int = 200
    step: float = 1.0
    max_step: float = 0.5
    seed: int | None = 0
    # the IK's own
    tol_pos: float = 1e-4
    tol_rot: float = 1e-3
    damping: float = 1e-3
    tol_rho: float = 1e-6
    check_every: int = 5
    read_every: int | None = None
    cuda_graphs: bool = True
    weights: IKWeights | None = None
    q_default: Any = None
    freeze_solved: bool = True
    n_random_with_warm_start: int = 0
    restart_after: int | None = 5
    max_restarts: int = 10
    orientation: str = "full"
    free_axis: Any = (0.0, 0.0, 1.0)

    def __post_init__(self) -> None:
        self.validate()

    def validate(self) -> None:
        """Check every field (ValueError/TypeError naming it); numbers become floats."""
        for name, lo in (("n_starts", 1), ("iterations", 0), ("check_every", 1),
                         ("n_random_with_warm_start", 0)):
            setattr(self, name, check_int(getattr(self, name), name, lo))
        if self.read_every is not None:
            self.read_every = check_int(self.read_every, "read_every", 1)
        if self.restart_after is not None:
            self.restart_after = check_int(self.restart_after, "restart_after", 1)
        self.max_restarts = check_int(self.max_restarts, "max_restarts", 0)
        _, self.free_axis = orientation_args(self.orientation, self.free_axis)
        for name in ("tol_pos", "tol_rot", "step", "max_step", "damping", "tol_rho"):
            v = getattr(self, name)
            if not (math.isfinite(real_number(v, name)) and v > 0):
                raise ValueError(f"{name}: expected a number > 0, got {v!r}")
            setattr(self, name, float(v))
        # beyond these a tolerance means nothing (and its square overflows the solver's)
        if self.tol_pos > MAX_TOL_POS:
            raise ValueError(f"tol_pos: {self.tol_pos:g} m is not a position tolerance (at "
                             f"most {MAX_TOL_POS:g} m)")
        if self.tol_rot > math.pi:
            raise ValueError(f"tol_rot: {self.tol_rot:g} rad is more than pi, the largest "
                             f"rotation error there is")
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
        for name in ("stop_when_solved", "freeze_solved", "allow_no_collision", "cuda_graphs",
                     "mesh_margin"):
            v = getattr(self, name)
            if not isinstance(v, (bool, np.bool_)):
                raise TypeError(f"{name}: expected a bool, got {v!r}")
            setattr(self, name, bool(v))
        check_int(self.seed, "seed", 0, 2 ** 63 - 1, none=True)
        if self.weights is not None:
            if not isinstance(self.weights, IKWeights):
                raise TypeError(f"weights: expected IKWeights, got {type(self.weights).__name__}")
            self.weights.validate()

    def eps_for(self, world: World | None) -> float:
        """The smoothing width in use: ``eps`` or the default for ``world``."""
        if self.eps is not None:
            return self.eps
        return max(float(world.resolution) if world is not None else 0.0, 0.01, self.margin)
