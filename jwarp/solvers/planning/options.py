"""The options of a motion plan: :class:`PlanOptions`, :class:`PathWeights`, :class:`ViaPoints`
and their checks."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from jwarp.core.arrays import real_number
from jwarp.core.device import numpy_dtype, scalar_type
from jwarp.core.types import DTypeLike
from jwarp.solvers.options import SolverOptions
from jwarp.solvers.overrides import renamed_options
from jwarp.utils.checks import check_int
from jwarp.world.path_feasibility import check_substeps


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


# ====================================================================== options
#: the kinds of multi-starts drawn when no seeds are given (:attr:`PlanOptions.start_kind`)
INITIAL_KINDS = ("straight", "random", "mixed")


#: why a plan call ended (:attr:`PlanResult.stop_reason`)
STOP_REASONS = ("solved", "time_limit", "iterations", "all_done")


#: the fallbacks of :attr:`PlanOptions.fallback` (besides None)
FALLBACKS = ("rrt",)
#: ``PlanOptions.fallback_after=None`` per device kind: the share of ``time_limit`` the
#: multi-starts use before the fallback (measured on the scene benchmark's 700 problems).
FALLBACK_AFTER = {"cpu": 0.15, "cuda": 0.08}
#: the same for a planner of more than one problem on a CUDA device (a batch moves in
#: lockstep: with 0.08 of a 2 s limit the 700-problem batch's setup used up the share
#: before its first step, and the fallback got 73 problems; with 0.5, 6 of them, and
#: 699/700 were solved in 2.05 s on an H200, benchmarks/README.md "issue 45")
BATCH_FALLBACK_AFTER = {"cpu": 0.15, "cuda": 0.5}


#: ``PlanOptions.n_starts=None`` per device kind. On an H200 (700 distinct scene problems,
#: margin 0, one at a time): 8 starts solved 99.1 % (34 by the fallback), mean 66 ms, p98
#: 415 ms; 32 starts 99.6 % (6 by the fallback), mean 39 ms, p98 170 ms; 96 starts 99.9 %,
#: mean 40 ms, p98 150 ms (benchmarks/README.md, issue 45)
N_STARTS = {"cpu": 8, "cuda": 32}


#: ``PlanOptions.shorten=None`` per device kind: rounds of shortcuts. One CPU core: one round
#: (a median U_l within 1.05x of ``stop_when_solved=False``'s at +12 % CPU time over the
#: first feasible path; four rounds +26-61 %, docs/scenes.md "Short paths"). CUDA: four
#: (700 problems one at a time on an H200: U_l median / p95 1.19 / 4.02 at a mean of 26 ms,
#: against 1.49 / 9.68 at 23 ms with one round; benchmarks/README.md, issue 45)
SHORTEN = {"cpu": 1, "cuda": 4}


def _per_device(value: Any, table: dict, device: str) -> Any:
    """``value``, or where it is None the ``table``'s entry for ``device``'s kind."""
    return table["cuda" if str(device).startswith("cuda") else "cpu"] if value is None \
        else value


def shorten_for(o: PlanOptions, device: str) -> int:
    """``o.shorten``, or its default on ``device`` (:data:`SHORTEN`)."""
    return int(_per_device(o.shorten, SHORTEN, device))


#: ``PlanOptions.reseed_iterations=None`` per device kind (0: off). One CPU core,
#: interleaved A/B in one process (2026-12-03, 140 distinct scene problems per set, 1 s
#: each): off / 5 / 10 iterations, seed 5 mean 37.0 / 30.2 / 32.0 ms, p95 130 / 105 /
#: 107, median 22.1 / 20.0 / 22.7; seed 7 mean 46.6 / 39.0 / 42.7, p95 156 / 138 / 143,
#: median 26.8 / 24.0 / 25.1. Off on CUDA: a draw copies every path of the batch to
#: the host and back
RESEED = {"cpu": 5, "cuda": 0}


def reseed_for(o: PlanOptions, device: str) -> int | None:
    """``o.reseed_iterations``, or its default on ``device`` (:data:`RESEED`); None:
    off (0)."""
    v = int(_per_device(o.reseed_iterations, RESEED, device))
    return v if v > 0 else None


def n_starts_for(o: PlanOptions, device: str) -> int:
    """``o.n_starts``, or its default on ``device`` (:data:`N_STARTS`)."""
    return int(_per_device(o.n_starts, N_STARTS, device))


def fallback_share(o: PlanOptions, device: str, n_problems: int = 1) -> float:
    """``o.fallback_after``, or its default on ``device`` for ``n_problems``
    (:data:`FALLBACK_AFTER`; more than one: :data:`BATCH_FALLBACK_AFTER`)."""
    table = FALLBACK_AFTER if int(n_problems) <= 1 else BATCH_FALLBACK_AFTER
    return float(_per_device(o.fallback_after, table, device))


#: the stages of :attr:`PlanResult.stage`
STAGES = ("straight", "optimizer", "fallback", "none")


def _check_flag(v: Any, name: str) -> None:
    if not (isinstance(v, (bool, np.bool_)) or (isinstance(v, (int, np.integer)) and v in (0, 1))):
        raise TypeError(f"{name}: expected True or False, got {v!r}")


@renamed_options(initial="start_kind", early_stop="freeze_feasible")
@dataclass
class PlanOptions(SolverOptions):
    """Options of the planner: of :class:`Planner`, and the keyword options of :func:`plan`
    (documented here once). :meth:`validate` raises ValueError/TypeError naming the field.

    Attributes:
        n_starts: multi-starts per problem when no seeds are given ("straight": one);
            None (default): :data:`N_STARTS` of the device (8 on the CPU, 32 on a CUDA
            device, where more starts cost little and leave fewer problems to the
            fallback).
        start_kind: the multi-starts without seeds: "straight" (the line in joint space),
            "random" (1-3 random via points inside the limits, thesis 3.5.1) or "mixed"
            (the line plus ``n_starts - 1`` random ones).
        n_waypoints: W, >= 2 (20 in the thesis); seeds given as paths bring their own W.
        n_substeps: substeps per segment, >= 1; None sizes them to the world's voxel size
            on the initial paths of each call (:func:`substeps_for_voxel`).
        substep_voxels: with ``n_substeps`` None in a grid world: the most a sphere centre
            may travel between two substeps of the cost, in voxels (> 0; 1: the thesis'
            rule). The cost only guides the paths (the exact continuous check certifies
            them), so a coarser cost (2-3) trades some guidance for fewer configurations.
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
            poses closer to an object than the path margin can be planned; at most
            ``margin`` (a larger one would be ignored: ValueError).
        freeze_feasible: freeze each path once it is feasible.
        stop_when_solved: end as soon as every problem has one feasible path (default);
            False optimises every start until it is feasible (or converged, or out of
            iterations): for labels (``converge``), per-start statistics.
        enough_feasible: with ``stop_when_solved`` False (and ``freeze_feasible``, not
            ``converge``): a problem's other starts stop once this many of its starts are
            feasible (>= 1; labels need only the few they converge); None: every start runs
            until it is feasible or out of iterations.
        time_limit: seconds for the whole call (None: no limit), > 0: checked before
            every iteration (wall clock since the call started); when it is reached the
            current paths get their exact check and the call ends (the endpoint checks,
            one evaluation and that check always run, so a call can overrun a tiny limit).
        problem_time_limit: seconds of each problem's own search (None: no limit), > 0,
            counted from the call's start like ``time_limit`` but independent of it: a
            problem not solved within it leaves the batch unsolved (stage "none"); its
            multi-starts get ``fallback_after`` of it (of the smaller of the two limits
            where both are given), then the fallback searches until it is spent. The
            call's ``time_limit`` also bounds the shortening of solved paths; this one
            bounds the search only (a batch of many problems: the solved ones are
            shortened after it).
        stall_iterations: with the ``fallback`` (and ``stop_when_solved``,
            ``freeze_feasible``, without ``converge``): a problem whose best start has not
            lowered its cost U_path by more than 1 % for this many iterations (>= 1)
            leaves the multi-starts at once (its starts frozen, costing no evaluation or
            check from then on) and is handed to the fallback; the multi-starts end as
            soon as every problem is solved or handed over, instead of running to the
            end of their share of the time or iterations. In a batch the handed problems'
            RRT-Connect trees grow between the other problems' steps (at most
            ``planner.FALLBACK_LOOP_SHARE`` of the loop's time), and a path found there
            is certified at once (``PlanResult.solved_at``). None: off (every unsolved
            problem waits for the multi-starts' end).
        reseed_iterations: a start (one multi-start path) whose own cost U_path has not
            fallen by more than 1 % for this many iterations (>= 1) while its problem is
            unsolved is drawn again (with ``stop_when_solved``): a new random path (1-3 random via points within the
            limits, not checked against the world, as the IK re-seeds a stalled seed), at
            most ``planner.RESEED_MAX`` times per start. 0: off; None (default): by the
            device (:data:`RESEED`: 5 on the CPU, off on a CUDA device).
        fallback: "rrt" (default): problems the multi-starts have not solved after
            their iterations, or after ``fallback_after`` of ``time_limit``, get an
            RRT-Connect path in joint space (:mod:`jwarp.solvers.planning.rrt`) as the seed of
            one more gradient optimisation (exact check as always); None or "none" (the
            CLI's ``--fallback none``; stored as None): no fallback.
        fallback_after: the share of ``time_limit`` the multi-starts may use before the
            fallback, in (0, 1) (without a time limit: after the iterations); None
            (default): :data:`FALLBACK_AFTER` of the planner's device kind (0.15 on the
            CPU, 0.08 on CUDA, where the fallback's share of the tail is largest:
            benchmarks/README.md, ``bench_scenes.py``); for more than one problem
            :data:`BATCH_FALLBACK_AFTER` (0.5 on CUDA, where the batch's steps are cheap
            per problem: ``bench_batch.py``).
        rrt: :class:`jwarp.solvers.planning.rrt.RRTOptions` of the fallback (None: its defaults).
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
        shorten: rounds of shortcuts of every solved problem's path once the call has
            its paths (>= 0; 0: off, the first feasible path as it is): with
            ``stop_when_solved`` (the default) on the rigid model, without ``converge``
            (:mod:`jwarp.solvers.planning.shorten`). Each round pulls the path straight:
            from the start, the straight segments to the later corners (and midpoints
            between them) are proven by the exact continuous check, with the clearance
            ``eps`` from the world (the cost's smoothing width, >= ``margin``: a shortcut
            keeps as far from objects as the descent's cost asks), and the path jumps
            to the farthest proven one; the waypoints
            are then respaced along the shortened polyline (every corner a waypoint: each
            new segment lies on a proven shortcut or on a segment of the certified path,
            so where the endpoint margins are not below ``margin`` and ``self_margin``
            the path is proven as built, kept in float64; else the whole path is checked
            again with the planner's rule); it replaces the path only if proven and of
            a lower length cost U_l. ``time_limit`` bounds it too. The multi-starts stop
            at the first feasible one, which may be a long detour (a random via point):
            this makes the default path short at little extra time. A round that
            shortens no path by more than 0.1 % ends the rounds, and a path whose U_l is
            at most 1.05 (:data:`jwarp.solvers.planning.planner.NEAR_STRAIGHT`) is left
            as it is; a path whose shortened polyline reaches that (its length at most
            sqrt(1.05) times the straight line's) takes no further round. None
            (default): :data:`SHORTEN` of the planner's device kind (1 on the CPU, where
            each round's checks cost most; 4 on CUDA).
        shorten_budget: the work of the rounds after their first check call, as a share
            of the optimisation's (> 0; default 0.5): they stop once their checks have
            evaluated that share of the configurations whose collision cost the
            multi-starts evaluated (iterations x paths x substeps; the fallback's work not
            counted). None: only ``shorten`` and ``time_limit`` bound them. Counted in
            evaluations, not seconds: the same path on every machine. The first check
            call (the first jumps of every path), the final check of the shortened path
            and its costs are outside it.
        allow_no_collision: plan without a collision model: a robot without collision
            spheres (every path is then collision-free) or in self-collision at its home
            configurations is accepted; False (default): either is a ValueError naming the
            robot and the link pairs (:func:`jwarp.world.model_check.check_collision_model`;
            CLI ``--no-collision``).
        straight_first: before any initial path is drawn or the optimiser is set up,
            the straight line of ``n_waypoints`` waypoints (the first multi-start of
            "mixed" and "straight") is proven by the planner's continuous check (the same
            margins, and the mesh certificate where the start or goal needs it); a problem
            whose line is proven is solved by it (stage "straight", no cost evaluated
            until its costs are read). Used where the multi-starts include the line (no
            seeds, no ``warm_start``, ``start_kind`` "mixed" or "straight"), with
            ``stop_when_solved`` and ``freeze_feasible``, without ``converge``,
            ``callback`` or ``kappa``; False: the line is checked with the other starts
            after the first cost evaluation, as before. Under the same conditions the
            other multi-starts of a problem whose line is not proven are checked as drawn
            next (the random ones, then the ``via_ik`` ones; a problem's first proven
            start ends its search, ``timings["starts"]``): where every problem has one,
            the optimiser is not set up at all (stage "optimizer", iteration 0, costs
            evaluated on first read), else those problems are kept as they are and the
            others optimised.
        mesh_margin: a robot whose spheres only approximate its meshes
            (``RobotModel.sphere_relation`` "approximate": the meshes poke out of them by a
            measured amount per link) plans with each link's spheres grown by that link's
            poke-out (:func:`jwarp.world.model_check.mesh_margin_model`; a warning once per
            robot); False: the spheres as they are (the meshes may then enter objects by
            up to the poke-out; warned once too). Contained and unknown relations: no
            change.
        via_ik: where the straight line is not proven (by the ``straight_first`` stage,
            else by one check of the lines before the starts are optimised), this many of
            a problem's random multi-starts (``start_kind`` "mixed", no seeds, at most
            ``n_starts - 1``; >= 0, 0: off) are replaced by paths through via points of
            one collision-free batched IK call (:mod:`jwarp.solvers.planning.via_ik`):
            the goal's tool pose pulled back along its approach axis (out of a shelf, a
            cage or a box), and the tool at the line's first colliding waypoint lifted or
            moved sideways; every via point is collision-free at the planner's margins
            and the paths are optimised and certified as every start. Deterministic with
            ``seed``; the rigid model (in a batch of worlds each problem's via points
            are checked in its own world). With ``stop_when_solved`` (``freeze_feasible``,
            no ``converge``) a problem one of whose kept random starts the spheres
            already prove gets no IK (its first check ends it). Default 5: on 84 scene problems (seed 5,
            CPU) it took the problems left to the RRT fallback from 5 to 0 and the p95
            time from 0.27 to 0.13 s (benchmarks/README.md, issue 45).
        via_frame: the tool frame of ``via_ik`` (a frame name or index; its z axis is the
            approach axis); None: the robot's first end effector, else its last frame.
    """

    # the fields of SolverOptions with the planner's defaults (the others as there)
    n_starts: int | None = None
    iterations: int = 100
    step: float = 0.01
    max_step: float = 0.1
    # the planner's own
    start_kind: str = "mixed"
    n_waypoints: int = 20
    n_substeps: int | None = None
    substep_voxels: float = 1.0
    weights: PathWeights | None = None
    endpoint_margin: float | None = None
    self_margin: float = 0.0
    freeze_feasible: bool = True
    enough_feasible: int | None = None
    check_all_every: int | None = None
    free_via: bool = True
    callback: Callable[[int, np.ndarray], None] | None = None
    converge: bool = False
    converge_tol: float = 1e-3
    time_limit: float | None = None
    problem_time_limit: float | None = None
    stall_iterations: int | None = 20
    reseed_iterations: int | None = None
    fallback: str | None = "rrt"
    fallback_after: float | None = None
    rrt: Any = None
    shorten: int | None = None
    shorten_budget: float | None = 0.5
    straight_first: bool = True
    via_ik: int = 5
    via_frame: int | str | None = None

    def __post_init__(self) -> None:
        self.fallback = fallback_word(self.fallback)

    def validate(self, dtype: DTypeLike = np.float32) -> None:
        """ValueError/TypeError naming the first bad field; numbers must be finite in the
        computing ``dtype``."""
        npdt = numpy_dtype(scalar_type(dtype))
        for name, lo in (("iterations", 0), ("n_waypoints", 2), ("via_ik", 0)):
            check_int(getattr(self, name), name, lo)
        if self.shorten is not None:
            check_int(self.shorten, "shorten", 0)
        if self.n_starts is not None:
            check_int(self.n_starts, "n_starts", 1)
        if self.check_all_every is not None:
            check_int(self.check_all_every, "check_all_every", 1)
        if self.enough_feasible is not None:
            check_int(self.enough_feasible, "enough_feasible", 1)
        for name in ("step", "max_step", "substep_voxels"):
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
            if em > margin:
                raise ValueError(f"endpoint_margin: {em:g} m is larger than the margin "
                                 f"({margin:g} m): it only relaxes the margin near the start "
                                 f"and goal, so it would be ignored; give a margin of at least "
                                 f"{em:g} m, or an endpoint margin <= {margin:g} m")
        if self.shorten_budget is not None:
            sb = real_number(self.shorten_budget, "shorten_budget")
            if not (math.isfinite(sb) and sb > 0):
                raise ValueError(f"shorten_budget: expected a share > 0 of the optimisation's "
                                 f"work, or None, got {self.shorten_budget!r}")
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
                     "allow_no_collision", "mesh_margin", "straight_first"):
            _check_flag(getattr(self, name), name)
        if self.via_frame is not None:
            if isinstance(self.via_frame, (bool, np.bool_)) or not isinstance(
                    self.via_frame, (str, int, np.integer)):
                raise TypeError(f"via_frame: expected a frame name or index, or None, got "
                                f"{self.via_frame!r}")
            if not isinstance(self.via_frame, str):
                check_int(self.via_frame, "via_frame", 0)
        seed = self.seed
        if not (seed is None or isinstance(seed, (np.random.Generator, np.random.SeedSequence))):
            check_int(seed, "seed", 0)
        if self.kappa is not None and not 0.0 < real_number(self.lam, "lam") <= 1.0:
            raise ValueError(f"lam: expected a damping factor in (0, 1], got {self.lam!r}")
        if self.callback is not None and not callable(self.callback):
            raise TypeError(f"callback: expected a callable (iteration, paths), got "
                            f"{type(self.callback).__name__}")
        _check_budget(self)


def fallback_word(value: Any) -> Any:
    """:attr:`PlanOptions.fallback` in one vocabulary with the CLI's ``--fallback rrt|none``:
    ``"none"`` (any case, spaces around) is None, ``"RRT"`` is ``"rrt"``; anything else is
    returned as it is (checked by :meth:`PlanOptions.validate`)."""
    if isinstance(value, str) and value.strip().lower() in (*FALLBACKS, "none"):
        v = value.strip().lower()
        return None if v == "none" else v
    return value


def _check_budget(o: PlanOptions) -> None:
    """:meth:`PlanOptions.validate` of ``time_limit``, ``problem_time_limit``,
    ``stall_iterations``, ``fallback``, ``fallback_after`` and ``rrt``."""
    for name in ("time_limit", "problem_time_limit"):
        v = getattr(o, name)
        if v is None:
            continue
        if isinstance(v, (bool, np.bool_)):
            raise TypeError(f"{name}: expected a number of seconds > 0 or None, got {v!r}")
        t = real_number(v, name)
        if not (math.isfinite(t) and t > 0):
            raise ValueError(f"{name}: expected a number > 0 [s] or None, got {v!r}")
    if o.stall_iterations is not None:
        check_int(o.stall_iterations, "stall_iterations", 1)
    if o.reseed_iterations is not None:
        check_int(o.reseed_iterations, "reseed_iterations", 0)
    o.fallback = fallback_word(o.fallback)
    if o.fallback is not None and (not isinstance(o.fallback, str)
                                   or o.fallback not in FALLBACKS):
        raise ValueError(f"fallback: expected 'rrt', 'none' or None, got {o.fallback!r}")
    f = 0.5 if o.fallback_after is None else real_number(o.fallback_after, "fallback_after")
    if not 0.0 < f < 1.0:
        raise ValueError(f"fallback_after: expected a number in (0, 1), got "
                         f"{o.fallback_after!r}")
    if o.rrt is not None:
        from jwarp.solvers.planning.rrt import RRTOptions

        if not isinstance(o.rrt, RRTOptions):
            raise TypeError(f"rrt: expected a jwarp.solvers.planning.rrt.RRTOptions, got "
                            f"{type(o.rrt).__name__}")
        o.rrt.validate()


@dataclass(frozen=True)
class ViaPoints:
    """Seeds of :meth:`Planner.plan` given as via points: ``points`` (k, n_dof),
    (n_seeds, k, n_dof) or (n_problems, n_seeds, k, n_dof) (k >= 0). Each seed is the
    path start -> via points -> goal of ``n_waypoints`` waypoints spread evenly along its
    joint-space length (as the random multi-starts), projected onto the limits."""

    points: Any
