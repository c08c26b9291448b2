"""The planner: a persistent :class:`Planner` holding its device buffers, the one-call
:func:`plan`, initial paths and the RRT fallback."""

from __future__ import annotations

import math
import time
from dataclasses import replace
from typing import Any

import numpy as np
import warp as wp

from jwarp.core.arrays import finite_as, init_warp, real_array, real_number, resolve_device
from jwarp.core.device import numpy_dtype, scalar_type
from jwarp.core.limits import project_numpy, within_limits
from jwarp.kinematics.launch import kappa_array
from jwarp.kinematics.transmission import transmitted, untransmitted
from jwarp.model import RobotModel
from jwarp.model.valid_range import check_valid_range
from jwarp.plugins.registry import robot as get_robot
from jwarp.solvers.overrides import renamed_argument, with_overrides
from jwarp.solvers.planning.objective import PathObjective, path_configs
from jwarp.solvers.planning.options import (
    PlanOptions,
    ViaPoints,
    check_int,
    fallback_share,
    n_starts_for,
    reseed_for,
    shorten_for,
)
from jwarp.solvers.planning.result import PlanResult
from jwarp.world.model_check import check_collision_model, mesh_margin_model
from jwarp.world.path_feasibility import (
    MAX_CHECK_SUBSTEPS,
    SWEEP_SAFETY,
    certify_check,
    check_endpoints,
    check_world,
    collision_free,
    initial_paths,
    path_feasible,
    polyline_path,
    substeps_for_voxel,
    substeps_per_path,
)

#: substep length [m] of the cost in a world of exact objects only (sphere travel per
#: substep): the continuous check proves feasibility, the cost only guides the descent
EXACT_SUBSTEP = 0.25

#: on the CPU, the optimiser's checks before its last take this many candidates per
#: problem, the clearest (None: every one): in a world of exact objects every iteration
#: checks, and the starts that still collide cost most of it. 280 interleaved plans of
#: 140 seed-7 Panda problems on one core (load 2): every candidate mean 61 ms, p95 218,
#: p98 541; two 43 / 134 / 241; one 42 / 132 / 181 (seed 5: 47 / 184 / 247, 35 / 128 /
#: 155, 37 / 125 / 150; fallbacks 3, 1, 0)
CPU_CHECK_PER_PROBLEM: int | None = 1

#: points per segment the straight stage's check evaluates first on the CPU (0: none)
LINE_CHECK_POINTS = 2
#: the same for the check of the starts as drawn (:meth:`Planner._proven_starts`), CPU: a
#: random or via-point start that collides is mostly found at a point, before the
#: advancement proves its segments up to the collision. Interleaved A/B, one process, one
#: core (2026-12-03): 280 seed-5 plans 0 / 1 point: mean 34.0 / 29.5 ms, median 21.8 /
#: 21.4, p95 120 / 100; 140 seed-7 plans 0 / 1 / 2: mean 47 / 38 / 44, median 25.7 / 22.7
#: / 26.1
START_CHECK_POINTS = 1


#: the most clearance [m] from the world that :attr:`PlanOptions.shorten` asks of a
#: shortcut beyond ``margin`` (it asks ``eps``, the cost's smoothing width, up to this):
#: on the Panda scene benchmark (margin 0, 70 problems) shortcuts at the margin alone left
#: 22 paths whose URDF meshes touch an object (the spheres approximate the meshes), 1 cm 15,
#: the first feasible paths 18
SHORTCUT_CLEARANCE = 0.01

#: :attr:`PlanOptions.shorten` leaves a path alone whose length cost U_l is at most this
#: (the straight line's is 1; U_l 1.05 is a path about 2.5 % longer than the line, and
#: the median of ``stop_when_solved=False`` on the Panda scene benchmark is 1.09): a
#: shortcut would gain little for a check's time
NEAR_STRAIGHT = 1.05

#: the rounds of :attr:`PlanOptions.shorten` end for a path once the U_l of its polyline
#: (its length over the straight line's, squared; at most its respaced path's U_l) is at
#: most this
STOP_NEAR_STRAIGHT: float | None = NEAR_STRAIGHT

#: :meth:`Planner.explain`'s reason for an unsolved problem once the call's deadline has
#: passed (no diagnosis check after the time limit)
NOT_DIAGNOSED = "not feasible: out of time (no path proven within the time limit; not diagnosed)"

#: :attr:`PlanOptions.shorten` is skipped when less than this share of
#: :attr:`PlanOptions.time_limit` is left of the call (its checks would not fit)
SHORTEN_MIN_LEFT = 0.05

#: the paths whose shortcuts (and whose shortened paths' certification) go in one check
#: call of :attr:`PlanOptions.shorten` under a time limit: the deadline is asked before
#: every call, so the shortening overruns it by at most one such call
SHORTEN_CHUNK = 128

#: the share of the time left at the start of :attr:`PlanOptions.shorten` kept for the
#: certification of the shortened paths (the shortcut rounds end before it)
SHORTEN_CHECK_SHARE = 0.2


#: evaluations per segment of the planner's continuous check (MotionOptions.max_evals)
PLANNER_CHECK_EVALS = 256


#: the same on a GPU, after 8 rounds of parallel evaluations (H200, 700 Panda problems in one
#: batch: 64 gave 667 solved in 4.0 s, 256 gave 691 in 15 s); the GPU's default check is now
#: the interval refinement (MotionOptions.method "levels"), which has no per-segment budget
#: (13 levels down to min_step): this bounds only the advancement of what its work list
#: cannot hold
PLANNER_CHECK_EVALS_GPU = 64


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
        check_int(n_problems, "n_problems", 1)
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
        # approximate spheres: the meshes' poke-out as extra margin per link (or a warning)
        self.robot = mesh_margin_model(self.robot, bool(o.mesh_margin), what="planning")
        if not o.allow_no_collision:
            check_collision_model(self.robot, need_spheres=True, what="planning",
                                  device=self.device)
        if o.via_ik > 0 and o.via_frame is not None:  # a frame of this robot
            self.robot.frame_index(o.via_frame, "via_frame")
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
        # explain() diagnoses the unsolved problems by a check (off: the fallback's own
        # optimisation, whose reasons nobody reads)
        self._diagnose = True
        #: a batch of worlds (World.batch): problem b plans in world b
        self.batched = world.n_worlds > 1
        if self.batched and world.n_worlds != self.n_problems:
            raise ValueError(f"world: a batch of {world.n_worlds} worlds needs as many "
                             f"problems, got n_problems={self.n_problems}")
        if self.batched and o.kappa is not None:
            raise ValueError("kappa: a batch of worlds plans on the rigid model only")
        #: per problem of the last plan: its start or goal needs the mesh certificate
        self._mesh_need: np.ndarray | None = None
        self._final = True   # the optimisation's last check (every path may use meshes)
        #: the RRT-Connect batch of the last plan's problems handed to the fallback
        #: (:class:`jwarp.solvers.planning.rrt.RRTBatch`; None: none yet)
        self._rrt: Any = None
        #: problem -> (path (W, n_dof), RRT nodes, seconds from the call's start): the
        #: fallback paths certified while the optimiser still ran
        self._rrt_found: dict[int, tuple] = {}

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
            out = self._plan(start, goal, seeds, "seeds")
            # a calibrated robot: warn once when the paths leave its calibration's range
            check_valid_range(model, out.path, "plan")
            return out
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
        check_valid_range(model, res.path, "plan")
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
        extra = n_starts_for(o, str(self.device)) - g.shape[1]
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
        mesh_s0 = self._mesh_seconds()
        self._rrt, self._rrt_found = None, {}
        deadline = None if o.time_limit is None else t0 + float(o.time_limit)
        # the problems' search (multi-starts, fallback): the call's limit and their own
        budget = [float(v) for v in (o.time_limit, o.problem_time_limit) if v is not None]
        search_end = None if not budget else t0 + min(budget)
        opt_deadline = search_end
        if budget and o.fallback is not None:
            opt_deadline = t0 + fallback_share(o, str(dev), self.n_problems) * min(budget)
        q0 = self._problems(start, "start")
        q1 = self._problems(goal, "goal")
        finite_as(q0, self.npdt, "start")  # also finite in the optimisation's dtype
        finite_as(q1, self.npdt, "goal")
        em = o.margin if o.endpoint_margin is None else min(o.margin, o.endpoint_margin)
        sem = min(o.self_margin, em)
        pw = 1 if self.batched else 0
        timings: dict = {}
        # the straight line first, before any other start is drawn or the optimiser is
        # set up: the continuous check of the line proves its start and goal too (at the
        # endpoint margins, as check_endpoints asks), so where it is proven by the
        # spheres the endpoints need no check of their own (their limits are checked
        # first: a line between configurations within the limits stays within them)
        line = None  # (B,) bool: the problems the straight line solved
        line_at = np.full(len(q0), np.nan)  # seconds from t0 at which the line was proven
        if self._straight_first(seeds) and within_limits(model, q0).all() \
                and within_limits(model, q1).all():
            t_line = time.perf_counter()
            line_paths, line_wp, line, code, dist = self._straight(q0, q1)
            timings["straight"] = time.perf_counter() - t_line
            line_at = np.where(line, time.perf_counter() - t0, np.nan)
            if line.all():
                self._mesh_need = np.zeros(len(q0), bool)
                return self._straight_result(line_paths, t0, timings, mesh_s0, line_at)
        t_end = time.perf_counter()
        s0 = check_endpoints(model, self.world, q0, "start", em, o.kappa, device=dev,
                             self_margin=sem, per_world=pw)
        s1 = check_endpoints(model, self.world, q1, "goal", em, o.kappa, device=dev,
                             self_margin=sem, per_world=pw)
        # problems whose start or goal only the mesh certificate keeps free (a grasp pose
        # the spheres reach past): their unproven paths go to it every check; the others
        # only at the last check (the spheres can prove their paths)
        self._mesh_need = ~(np.asarray(s0, bool) & np.asarray(s1, bool))
        self._final = False
        timings["endpoints"] = time.perf_counter() - t_end
        if line is not None:
            # the optimiser's first check of the line: the mesh certificate for the
            # problems whose start or goal needs it (every problem when that check is
            # its last)
            t_line = time.perf_counter()
            allow = ~line if o.iterations == 0 else ~line & self._mesh_need
            line = self._mesh_proof(self.motion_check(), line_wp, np.arange(len(line)),
                                    line, code, dist, allow, 1 if self.batched else 0)
            timings["straight"] += time.perf_counter() - t_line
            line_at[line & np.isnan(line_at)] = time.perf_counter() - t0
            if line.all():
                return self._straight_result(line_paths, t0, timings, mesh_s0, line_at)
        t_opt = time.perf_counter()
        if isinstance(seeds, ViaPoints):
            Q = _via_seeds(model, q0, q1, seeds.points, o.n_waypoints)
        else:
            Q = _initial(model, q0, q1, o.start_kind if seeds is None else seeds,
                         n_starts_for(o, str(dev)),
                         o.n_waypoints, o.seed, self.world, o.free_via, device=dev,
                         name=seeds_name)  # (B, n_starts, W, n)
        B, n_starts, W = Q.shape[:3]
        # starts proven as drawn (the straight stage's conditions): per problem the index
        # of one (the line is start 0), -1: none; such a problem needs no optimisation,
        # and where every problem has one the optimiser is not set up at all
        first = np.full(B, -1, np.int64)
        first_at = line_at.copy()
        work = 0  # the proofs' evaluations (the shortening's budget base without descent)
        via = seeds is None and o.via_ik > 0 and (line is None or not line.all())
        if line is not None and not line.all():
            first[line] = 0
            k = self._via_count(n_starts) if via else 0
            work += self._prove_starts(Q, np.nonzero(~line)[0], 1, n_starts - k, first,
                                       first_at, t0, timings)
        if via:
            t_via = time.perf_counter()
            ran = self._ik_starts(Q, q0, q1, None if line is None else line_paths, line,
                                  None if line is None else first)
            if ran is not None:
                timings["via_ik"] = time.perf_counter() - t_via
                if line is not None:  # the via-point paths proven as drawn
                    k = self._via_count(n_starts)
                    work += self._prove_starts(Q, ran, n_starts - k, n_starts, first,
                                               first_at, t0, timings)
        if line is not None and ((first >= 0).all() or (
                opt_deadline is not None and time.perf_counter() >= opt_deadline)):
            # every problem has a proven start, or the optimiser's share of the time is
            # spent already (a large batch on the CPU): its first iteration would only
            # check again the starts just checked as drawn
            res = self._starts_result(Q, first, line, t0, timings, first_at)
            return self._finish(res, q0, q1, t0, search_end, deadline, res.n_substeps, work,
                                mesh_s0)
        P = B * n_starts
        Qf = Q.reshape(P, W, model.n_dof)
        n_sub = self._substeps(Qf)
        buf = self._prepare(P, W, n_sub)
        obj = buf.objective
        evals0 = obj.evaluations  # the optimisation's work (PlanOptions.shorten_budget)
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
        found_at = np.full(P, np.nan)  # seconds from t0 at which each path was kept feasible
        reason = "iterations"
        # stall_iterations: a problem whose best cost stopped falling goes to the fallback
        stall = (o.stall_iterations if o.fallback is not None and o.stop_when_solved
                 and o.freeze_feasible and not o.converge else None)
        handed = np.zeros(B, bool)           # problems handed to the fallback early
        # reseed_iterations: a start whose own cost stopped falling is drawn again
        # (the time to a first feasible path: with stop_when_solved, as stall_iterations;
        # the multi-starts of stop_when_solved=False, e.g. the learning labels, are the
        # thesis' as drawn)
        reseed = (reseed_for(o, str(dev)) if o.freeze_feasible and o.stop_when_solved
                  and not o.converge else None)
        row_best = np.full(P, np.inf)        # each start's lowest U_path since drawn
        row_gain_it = np.zeros(P, np.int64)  # the iteration of its last gain (or draw)
        reseeds = np.zeros(P, np.int64)      # its draws after the first
        reseed_rng = np.random.default_rng(o.seed)
        # a batch's handed problems grow their trees between the others' steps
        # (no problem waits for the batch): RRTBatch rounds in this loop
        interleave = (stall is not None and B > 1 and o.kappa is None and FALLBACK_BATCH
                      and FALLBACK_INTERLEAVED)
        t_rrt = 0.0
        best_cost = np.full(B, np.inf)       # their best start's lowest U_path so far
        gain_it = np.zeros(B, np.int64)      # the iteration of its last gain
        last_check = 0.0  # seconds of the last iteration's evaluation and check
        for it in range(o.iterations + 1):
            # the time limit: checked before the evaluation (an iteration that would end
            # past it at the last one's pace counts as past it); the current paths still
            # get their exact check below
            t_it = time.perf_counter()
            out_of_time = opt_deadline is not None and t_it + last_check >= opt_deadline
            self._final = it == o.iterations or out_of_time
            obj.evaluate(grad=it < o.iterations and not out_of_time)
            if o.callback is not None:
                o.callback(it, obj.paths.numpy())
            smax = obj.sub_max.numpy()
            if it == 0 and (first >= 0).any():
                # the problems a start proved as drawn (the straight line: start 0), by
                # the same check: kept as they are, their other starts stop here
                have = np.nonzero(first >= 0)[0]
                rows = np.nonzero(np.repeat(first >= 0, n_starts))[0]
                won = have * n_starts + first[have]
                feasible[won] = True
                iters[won] = 0
                found_at[won] = first_at[have]
                self._keep(buf, rows)
                done[rows] = True
            last = it == o.iterations or out_of_time or (it + 1) % check_every == 0
            if o.converge:
                self._converge_check(buf, it, last, smax < screen, done, feasible, iters,
                                     kept_len)
                found_at[feasible & (iters == it)] = time.perf_counter() - t0
                solved = done & feasible
            else:
                cand = np.nonzero(~done & ((smax < screen) | last))[0]
                # on the CPU, whose threads take the paths in order: per problem the
                # clearest candidates first (the lowest largest substep cost), the
                # likeliest to be proven, which ends its check (the rest are skipped)
                if dev.is_cpu:
                    cand = cand[np.lexsort((smax[cand], cand // n_starts))]
                    if CPU_CHECK_PER_PROBLEM is not None and not self._final:
                        # the clearest few per problem now, the others at the last check
                        g = cand // n_starts
                        first_of = np.searchsorted(g, g)
                        cand = cand[np.arange(len(cand)) - first_of < CPU_CHECK_PER_PROBLEM]
                if len(cand):
                    newly = cand[self._confirm(buf, cand)]
                    if len(newly):
                        feasible[newly] = True
                        iters[newly] = it
                        found_at[newly] = time.perf_counter() - t0
                        if o.freeze_feasible:
                            self._keep(buf, newly)
                            done[newly] = True
                solved = feasible
                enough = 1 if o.stop_when_solved else o.enough_feasible
                if enough is not None and o.freeze_feasible and (B > 1 or enough > 1):
                    # a solved problem needs nothing more (``enough_feasible``: enough of
                    # its starts are feasible): its other starts stop here (kept as they
                    # are), so they cost no evaluation or check from now on
                    fin = np.repeat(solved.reshape(B, n_starts).sum(1) >= enough,
                                    n_starts) & ~done
                    if fin.any():
                        self._keep(buf, np.nonzero(fin)[0])
                        done[fin] = True
                        if not o.stop_when_solved:  # enough_feasible: where they stopped
                            iters[fin] = it
            last_check = time.perf_counter() - t_it
            if o.stop_when_solved and solved.reshape(B, n_starts).any(1).all():
                reason = "solved"
                break
            if stall is not None and it < o.iterations and not out_of_time:
                # each problem's best start not done: its cost this iteration; one that
                # has not fallen by STALL_GAIN for ``stall`` iterations is handed over
                c = np.where(done, np.inf, obj.total.numpy()).reshape(B, n_starts).min(1)
                gain = c < best_cost * (1.0 - STALL_GAIN)
                best_cost[gain] = c[gain]
                gain_it[gain] = it
                open_ = ~done.reshape(B, n_starts).all(1)
                hand = open_ & ~handed & (it - gain_it >= stall)
                if hand.any():
                    rows = np.nonzero(np.repeat(hand, n_starts) & ~done)[0]
                    self._keep(buf, rows)
                    done[rows] = True
                    iters[rows] = it
                    handed |= hand
                    if interleave:
                        t_r = time.perf_counter()
                        self._rrt_start(np.nonzero(hand)[0], q0, q1, t0)
                        t_rrt += time.perf_counter() - t_r
            if reseed is not None and it < o.iterations and not out_of_time \
                    and not done.all():
                n_new = self._reseed(obj, it, reseed, done, row_best, row_gain_it, reseeds,
                                     q0, q1, n_starts, reseed_rng)
                if n_new:
                    timings["reseeded"] = timings.get("reseeded", 0) + n_new
            if self._rrt is not None and len(self._rrt.active) and not out_of_time \
                    and not done.all() \
                    and t_rrt <= FALLBACK_LOOP_SHARE * (time.perf_counter() - t_opt):
                t_r = time.perf_counter()
                self._rrt_round(t0, search_end)
                t_rrt += time.perf_counter() - t_r
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
        res = self._result(buf, feasible, iters, B, n_starts, time.perf_counter() - t0,
                           found_at)
        res.stop_reason = reason
        res.stage = np.where(res.feasible, "optimizer", "none").astype("<U9")
        if line is not None:
            res.stage[line] = "straight"
        timings["optimizer"] = time.perf_counter() - t_opt - t_rrt
        if t_rrt:
            timings["rrt"] = t_rrt
        res.timings = timings
        if self._rrt_found:
            self._rrt_apply(res, obj.n_sub)
        if handed.any():
            timings["handed_over"] = int(handed.sum())
        return self._finish(res, q0, q1, t0, search_end, deadline, obj.n_sub,
                            work + obj.evaluations - evals0, mesh_s0)

    def _reseed(self, obj: PathObjective, it: int, reseed: int, done: np.ndarray,
                row_best: np.ndarray, row_gain_it: np.ndarray, reseeds: np.ndarray,
                q0: np.ndarray, q1: np.ndarray, n_starts: int,
                rng: np.random.Generator) -> int:
        """:attr:`PlanOptions.reseed_iterations`: the starts not done whose cost (this
        iteration's evaluation) has not fallen by ``STALL_GAIN`` for ``reseed`` iterations
        get new random paths (at most :data:`RESEED_MAX` times each; their bookkeeping
        arrays updated in place). Returns how many were drawn."""
        c = np.where(done, np.inf, obj.total.numpy().astype(np.float64))
        gain = c < row_best * (1.0 - STALL_GAIN)
        row_best[gain] = c[gain]
        row_gain_it[gain] = it
        stale = ~done & (it - row_gain_it >= reseed) & (reseeds < RESEED_MAX)
        if not stale.any():
            return 0
        rows = np.nonzero(stale)[0]
        b = rows // n_starts
        new = initial_paths(q0[b], q1[b], obj.W, "random", robot=self.robot, rng=rng)
        paths = obj.paths.numpy().copy()
        paths[rows] = new
        obj.set_paths(paths)
        row_best[rows] = np.inf
        row_gain_it[rows] = it
        reseeds[rows] += 1
        return len(rows)

    def _rrt_batch(self, q0: np.ndarray, q1: np.ndarray) -> Any:
        """The plan's :class:`RRTBatch` over all its problems (made on first use): the
        planner's margins, device and per-problem mesh certificate, ``rrt`` options (their
        seed's generator), new trees while time is left."""
        if self._rrt is None:
            from jwarp.solvers.planning.rrt import RRTBatch

            o = self.options
            need = self._mesh_need
            self._rrt = RRTBatch(self.robot, self.world, q0, q1, _rrt_options(o),
                                 margin=o.margin, endpoint_margin=o.endpoint_margin,
                                 self_margin=o.self_margin, device=self.device,
                                 meshes=True if need is None else np.asarray(need, bool),
                                 restart=True)
        return self._rrt

    def _rrt_start(self, rows: np.ndarray, q0: np.ndarray, q1: np.ndarray, t0: float
                   ) -> None:
        """The problems ``rows`` (handed over) join the plan's RRT batch; those whose
        straight line (in the trees' pieces) is proven there are certified at once."""
        rb = self._rrt_batch(q0, q1)
        rb.start(rows)
        line = [int(b) for b in rows if rb.problems[int(b)].path is not None]
        if line:
            self._rrt_certify(line, t0)

    def _rrt_round(self, t0: float, stop: float | None) -> None:
        """One round of the plan's RRT batch; the paths it connected are shortcut,
        verified and (as :func:`_certified_as_is`) certified as W waypoints at once."""
        rb = self._rrt
        end = math.inf if stop is None else stop
        got = rb.round(end)
        if got:
            rb.finish(got, end)
            self._rrt_certify(got, t0)

    def _rrt_certify(self, rows: list[int], t0: float) -> None:
        """The RRT paths of ``rows`` resampled to W waypoints; those certified as they are
        kept in ``_rrt_found`` (the others go to the fallback's optimisation)."""
        from jwarp.solvers.planning.rrt import resample_path

        rb, W = self._rrt, self.options.n_waypoints
        cand = [b for b in rows if rb.problems[b].path is not None
                and len(rb.problems[b].path) <= W]
        if not cand:
            return
        seeds = [resample_path(rb.problems[b].path, W) for b in cand]
        ok = _certify_rrt_paths(self, np.array(cand), np.stack(seeds), self._mesh_need)
        at = time.perf_counter() - t0
        for k in np.nonzero(ok)[0]:
            b = cand[k]
            self._rrt_found[b] = (seeds[k], len(rb.problems[b].path), at)

    def _rrt_apply(self, res: PlanResult, n_sub: int) -> None:
        """The fallback paths certified during the optimisation (``_rrt_found``) set in
        ``res`` (stage "fallback", iteration 0, start_index -1, their ``solved_at``; costs
        evaluated on first read)."""
        W = res.path.shape[1]
        if res.fallback_notes is None:
            res.fallback_notes = np.full(len(res.feasible), "", dtype=object)
        rows = np.array(sorted(self._rrt_found))
        found = [self._rrt_found[int(b)] for b in rows]
        _set_fallback(res, rows, np.stack([f[0] for f in found]), [f[2] for f in found],
                      [f"RRT-Connect path of {f[1]} nodes as {W} waypoints: certified as it "
                       f"is (its trees grew while the optimiser ran)" for f in found])
        self._costs_on_read(res, rows, n_sub)
        if res.feasible.all():
            res.stop_reason = "solved"

    def _finish(self, res: PlanResult, q0: np.ndarray, q1: np.ndarray, t0: float,
                search_end: float | None, deadline: float | None, n_sub: int, work: int,
                mesh_s0: float) -> PlanResult:
        """The stages after the multi-starts: the fallback for the unsolved problems, the
        shortening of the solved ones (``work``: the evaluations that found them, its
        budget's base; ``n_sub``: the substeps of their costs), the reasons, the wall
        time and the mesh certificate's share."""
        o = self.options
        if o.fallback is not None and not res.feasible.all():
            _fallback(self, res, q0, q1, t0, search_end)
        if shorten_for(o, str(self.device)) > 0 and o.stop_when_solved and not o.converge \
                and o.kappa is None:
            self._shorten(n_sub, res, deadline, work)
        res.reasons = self.explain(res, deadline=deadline)
        res.wall_time = time.perf_counter() - t0
        if getattr(self.robot, "collision_pieces", None) is not None:  # the certificate's share
            res.timings["mesh_check"] = self._mesh_seconds() - mesh_s0
        return res

    def _prove_starts(self, Q: np.ndarray, bad: np.ndarray, lo: int, hi: int,
                      first: np.ndarray, first_at: np.ndarray, t0: float,
                      timings: dict) -> int:
        """:meth:`_proven_starts` of the starts ``lo:hi`` of the problems ``bad`` that have
        none proven yet, recorded in ``first`` and ``first_at`` (seconds from ``t0``) in
        place (``timings["starts"]``); returns the configurations evaluated."""
        t = time.perf_counter()
        bad = bad[first[bad] < 0]
        got, evals = self._proven_starts(Q, bad, lo, hi)
        first[bad] = got
        first_at[bad[got >= 0]] = time.perf_counter() - t0
        timings["starts"] = timings.get("starts", 0.0) + time.perf_counter() - t
        return evals

    def _starts_result(self, Q: np.ndarray, first: np.ndarray, line: np.ndarray, t0: float,
                       timings: dict, first_at: np.ndarray) -> PlanResult:
        """The result of a call without the optimiser: per problem its start proven as
        drawn (``first`` (B,) its index in ``Q`` (B, n_starts, W, n_dof), -1: none, when
        the optimiser's time was spent before it could start; the straight line's
        problems ``line``), as the optimiser's first iteration would return it (stage
        "optimizer", or "straight"; iteration 0; "none": start 0, not feasible, stop
        reason "time_limit"), its costs evaluated on first read."""
        B = len(first)
        have = first >= 0  # else (out of time): start 0, not feasible, stage "none"
        pick = np.where(have, first, 0)
        src = Q.astype(self.npdt).astype(np.float64)
        paths = src[np.arange(B), pick]
        res = self._proven_result(paths, t0, timings, first_at)
        res.paths_source = src
        res.start_index = pick
        res.feasible = have.copy()
        res.n_feasible = have.astype(np.int64)
        res.all_feasible = np.zeros(Q.shape[:2], bool)
        res.all_feasible[np.nonzero(have)[0], first[have]] = True
        res.all_iterations = np.zeros(Q.shape[:2], np.int64)
        res.stage = np.where(line, "straight", np.where(have, "optimizer", "none")).astype("<U9")
        res.solved_at = np.where(have, res.solved_at, np.nan)
        if not have.all():
            res.stop_reason = "time_limit"
        return res

    def _ik_starts(self, Q: np.ndarray, q0: np.ndarray, q1: np.ndarray,
                   line_paths: np.ndarray | None, line: np.ndarray | None,
                   proven: np.ndarray | None = None) -> np.ndarray | None:
        """:attr:`PlanOptions.via_ik`: the last random starts of the problems whose straight
        line is not proven replaced (in place, ``Q`` (B, n_starts, W, n_dof)) by paths
        through collision-free IK via points (:mod:`jwarp.solvers.planning.via_ik`).
        ``line``: which lines the straight stage proved, with their paths; None (no
        straight stage): the lines are checked here (the spheres, the planner's check).
        ``proven`` (B,) ints (:meth:`_proven_starts`, -1: none): the problems with a start
        proven as drawn get no IK. Returns the problems the IK ran for, or None where it
        does not run (not a robot of a 3-D workspace, the elastic model; in a batch of
        worlds each problem's via points and anchor are checked in its own world)."""
        o = self.options
        k = self._via_count(Q.shape[1])
        if k <= 0 or o.kappa is not None or self.robot.workspace_dim != 3:
            return None
        if line is None or line_paths is None:
            line_paths, _, line, _, _ = self._straight(q0, q1)
            if line.all():
                return None
        from jwarp.solvers.planning.via_ik import ik_via_paths

        bad = np.nonzero(~line)[0]
        if proven is not None:  # a start proven as drawn ends its problem: no IK for it
            bad = bad[proven[bad] < 0]
        if not len(bad):
            return None
        n_starts = Q.shape[1]
        V, count = ik_via_paths(self.robot, self.world, q0[bad], q1[bad], line_paths[bad], k,
                                Q.shape[2], frame=o.via_frame, margin=o.margin,
                                self_margin=o.self_margin, device=self.device, dtype=self.npdt,
                                seed=o.seed, worlds=bad if self.batched else None)
        for i, b in enumerate(bad):
            c = int(count[i])
            if c:
                Q[b, n_starts - c:] = V[i, :c]
        return bad

    def _via_count(self, n_starts: int) -> int:
        """The starts per problem that :meth:`_ik_starts` replaces (the last ones)."""
        o = self.options
        return min(int(o.via_ik), n_starts - 1) if o.start_kind == "mixed" else 0

    def _proven_starts(self, Q: np.ndarray, bad: np.ndarray, lo: int, hi: int
                       ) -> tuple[np.ndarray, int]:
        """``(first, evaluations)``: per problem ``bad[i]`` the first of its starts
        ``Q[bad[i], lo:hi]`` that the planner's continuous check proves with the spheres
        alone (its margins, the paths in the optimiser's dtype), as its first check would,
        or -1 (len(bad),) ints; one call for all (a problem's starts after the first
        proven one are skipped inside it), and the configurations it evaluated."""
        first = np.full(len(bad), -1, np.int64)
        g = hi - lo
        if g <= 0 or not len(bad):
            return first, 0
        o = self.options
        W, n = Q.shape[2], Q.shape[3]
        kept = Q[:, lo:hi].astype(self.npdt).astype(np.float64)  # (B, g, W, n)
        rows = (bad[:, None] * g + np.arange(g)[None]).reshape(-1)
        pts = (START_CHECK_POINTS, 1) if self.device.is_cpu and START_CHECK_POINTS else None
        r = self.motion_check().check(kept.reshape(-1, W, n), margin=o.margin,
                                      endpoint_margin=o.endpoint_margin,
                                      self_margin=o.self_margin,
                                      world_group=g if self.batched else 0, group=g,
                                      meshes=False, rows=rows, points=pts)
        ok = np.asarray(r.ok, bool).reshape(len(bad), g)
        first[ok.any(1)] = lo + np.argmax(ok, axis=1)[ok.any(1)]
        return first, int(r.evaluations)

    def _substeps(self, Qf: np.ndarray) -> int:
        """The cost's substeps per segment for the paths ``Qf`` (P, W, n_dof):
        ``options.n_substeps``, else sized to the grid's voxels, or in a world of exact
        objects to :data:`EXACT_SUBSTEP` of sphere travel (at most 16)."""
        o, model = self.options, self.robot
        if o.n_substeps is not None:
            return int(o.n_substeps)
        if self.world.has_grid:
            return substeps_for_voxel(model, Qf, float(self.world.resolution),
                                      safety=1.0 / float(o.substep_voxels), device=self.device)
        # exact objects only: the check is continuous, the cost a guide
        from jwarp.world.motion import travel_bound

        return int(np.clip(np.ceil(travel_bound(model, Qf).max(initial=0.0)
                                   / EXACT_SUBSTEP), 1, 16))

    def _straight_first(self, seeds: Any) -> bool:
        """Whether :attr:`PlanOptions.straight_first` applies to this call: the line is
        the first multi-start (no seeds, start_kind "mixed" or "straight"), a proven path
        ends its problem (``stop_when_solved``, ``freeze_feasible``, not ``converge``),
        the rigid model and no callback to show the iterations to."""
        o = self.options
        kind = o.start_kind if seeds is None else seeds
        return bool(o.straight_first and isinstance(kind, str) and kind in ("mixed", "straight")
                    and o.stop_when_solved and o.freeze_feasible and not o.converge
                    and o.kappa is None and o.callback is None)

    def _straight(self, q0: np.ndarray, q1: np.ndarray) -> tuple:
        """The straight line of every problem as the optimiser would hold it (W waypoints,
        ``initial_paths`` "straight", in the planner's dtype), checked by the planner's
        continuous check (its margins), the spheres alone, as the optimiser's start 0 at
        its first iteration: ``(paths (B, W, n_dof) float64, the same on the device,
        ok (B,) bool, code (B,), clearance (B,))`` (code and clearance for the mesh
        certificate, :meth:`_mesh_proof`)."""
        o, dev = self.options, self.device
        B = len(q0)
        line = initial_paths(q0, q1, o.n_waypoints, "straight").astype(self.npdt)
        p: wp.array = wp.array(line, dtype=self.scalar, device=dev)
        idx: wp.array = wp.array(np.arange(B, dtype=np.int32), dtype=wp.int32, device=dev)
        # on the CPU the line's segments are first evaluated at LINE_CHECK_POINTS points
        # each: a line that collides is found there, before the advancement proves its
        # segments up to the collision (the points prove their neighbourhoods: the same
        # proof)
        pts = (LINE_CHECK_POINTS, 1) if dev.is_cpu and LINE_CHECK_POINTS else None
        out = self.motion_check().launch(p, idx, B, margin=o.margin, points=pts,
                                         endpoint_margin=o.endpoint_margin,
                                         self_margin=o.self_margin,
                                         world_group=1 if self.batched else 0)
        ok = out["ok"].numpy()[:B].astype(bool)
        code = out["code"].numpy()[:B].copy()
        dist = out["dist"].numpy()[:B].copy()
        return line.astype(np.float64), p, ok, code, dist

    def _mesh_proof(self, chk: Any, paths: wp.array, rows: np.ndarray, ok: np.ndarray,
                    code: np.ndarray, dist: np.ndarray, allow: np.ndarray,
                    wg: int) -> np.ndarray:
        """``ok`` (K,) of the paths ``rows`` of ``paths`` checked by ``chk`` (their codes
        and clearances ``code``, ``dist`` (K,)) with those ``allow`` (K,) that the spheres
        left unproven proven by the mesh certificate where it proves them (unchanged
        without one)."""
        if not allow.any() or chk.mesh_check() is None:
            return ok
        o = self.options
        k = np.nonzero(allow)[0]
        ok = ok.copy()
        ok[k] = chk.mesh_recheck(paths, np.asarray(rows)[k], ok[k], code[k], dist[k],
                                 margin=o.margin, endpoint_margin=o.endpoint_margin,
                                 self_margin=o.self_margin, world_group=wg)
        return ok

    def _straight_result(self, paths: np.ndarray, t0: float, timings: dict,
                         mesh_s0: float, line_at: np.ndarray) -> PlanResult:
        """The result of a call the straight lines ``paths`` (B, W, n_dof) solved: one
        start per problem, iteration 0; the costs (and ``length_before``) are evaluated
        when first read (:meth:`_proven_result`)."""
        res = self._proven_result(paths, t0, timings, line_at)
        if getattr(self.robot, "collision_pieces", None) is not None:
            timings["mesh_check"] = self._mesh_seconds() - mesh_s0
        res.wall_time = time.perf_counter() - t0
        return res

    def _proven_result(self, paths: np.ndarray, t0: float, timings: dict,
                       solved_at: np.ndarray) -> PlanResult:
        """A result whose paths (B, W, n_dof) were proven as drawn, one start per
        problem, iteration 0, stage "straight"; the costs (and, with the shortening on
        and not set by it, ``length_before``) are evaluated when first read (a
        :class:`PathObjective` of these paths, at substeps sized to them)."""
        o, B = self.options, len(paths)
        n_sub = self._substeps(paths)
        shortens = (shorten_for(o, str(self.device)) > 0 and o.stop_when_solved
                    and not o.converge and o.kappa is None)
        robot, world, dev, npdt, eps = self.robot, self.world, self.device, self.npdt, self.eps
        batched, own = self.batched, paths.copy()

        def costs(res: PlanResult) -> None:
            obj = _evaluated(robot, world, o, eps, dev, npdt, batched, own, n_sub)
            res.cost = obj.total.numpy().astype(np.float64)
            res.length_cost = obj.length.numpy().astype(np.float64)
            res.collision_cost = obj.collision.numpy().astype(np.float64)
            if shortens and res.__dict__.get("_length_before") is None:
                res.length_before = res.length_cost.copy()  # the line is left as it is

        res = PlanResult(path=paths, feasible=np.ones(B, bool), cost=None, length_cost=None,
                         collision_cost=None, iterations=np.zeros(B, np.int64),
                         start_index=np.zeros(B, np.int64), n_feasible=np.ones(B, np.int64),
                         wall_time=0.0, n_substeps=n_sub, all_feasible=np.ones((B, 1), bool),
                         all_iterations=np.zeros((B, 1), np.int64), paths_source=paths[:, None],
                         stop_reason="solved", stage=np.full(B, "straight", "<U9"),
                         timings=timings, reasons=["feasible"] * B,
                         solved_at=np.asarray(solved_at, np.float64).copy())
        res._fill = costs
        return res

    def _mesh_seconds(self) -> float:
        """Seconds the mesh certificate of this robot and world has worked so far (0
        without one): the share of a plan spent on mesh checks."""
        if getattr(self.robot, "collision_pieces", None) is None or self.options.kappa is not None:
            return 0.0
        from jwarp.world.mesh_check import cached_mesh_check

        mc = cached_mesh_check(self.robot, self.world, self.device)
        return 0.0 if mc is None else mc.stats.seconds

    def _shorten(self, n_sub: int, res: PlanResult, deadline: float | None,
                 work: int | None = None) -> None:
        """:attr:`PlanOptions.shorten` of the feasible paths of ``res`` (in place): their
        shortcuts proven by the planner's continuous check with the clearance ``eps``
        (at most :data:`SHORTCUT_CLEARANCE`, at least ``margin``) from the world (``self_margin`` between the robot's spheres), the waypoints respaced along
        the shortened polyline; a path is replaced where the whole shortened path passes
        that check with the planner's margins and its U_l is lower. ``cost``,
        ``length_cost`` and ``collision_cost`` of the replaced paths are evaluated on
        first read (at ``n_sub`` substeps); ``length_before`` and ``timings["shorten"]``
        set (costs left to their first read stay there: U_l from the paths on the host).
        ``work``: the collision evaluations of the optimisation (the budget's base,
        :attr:`PlanOptions.shorten_budget`; None: no budget).

        ``deadline`` (``time.perf_counter()``): skipped when it has passed or less than
        :data:`SHORTEN_MIN_LEFT` of ``time_limit`` is left; else the shortcut rounds end
        at :data:`SHORTEN_CHECK_SHARE` of the time left before it and the shortened paths'
        certification at it, both in calls of :data:`SHORTEN_CHUNK` paths with the
        deadline asked before each (:func:`jwarp.solvers.planning.shorten.shortcut_paths`):
        a path whose shortcuts or certification were not reached keeps what was proven
        (its certified path as it was, where its certification was not reached)."""
        from jwarp.solvers.planning.shorten import Pace, length_cost, respace, shortcut_paths

        t = time.perf_counter()
        o = self.options
        # U_l: the result's, or where its costs wait for their first read, the paths' own
        # (the kernels' formula on the host)
        ul = (length_cost(np.asarray(res.path, np.float64))
              if res.__dict__.get("_fill") is not None else
              np.asarray(res.length_cost, np.float64))
        res.length_before = np.where(res.feasible, ul, np.nan)
        # a path already near the straight line (U_l <= NEAR_STRAIGHT) is left as it is
        solved = np.asarray(res.feasible, bool) & (ul > NEAR_STRAIGHT)
        short_of_time = deadline is not None and (
            t >= deadline or (o.time_limit is not None
                              and deadline - t < SHORTEN_MIN_LEFT * float(o.time_limit)))
        if not solved.any() or short_of_time:
            res.timings["shorten"] = time.perf_counter() - t
            return
        rounds_end = (None if deadline is None
                      else deadline - SHORTEN_CHECK_SHARE * (deadline - t))
        # a batch of worlds: every problem's row (path b in world b), the unsolved idle
        idx = np.arange(len(solved)) if self.batched else np.nonzero(solved)[0]
        paths = np.asarray(res.path, np.float64)[idx]
        W = paths.shape[1]
        chk = self.motion_check()

        # a shortcut keeps a clearance (the cost's smoothing width eps, at most 1 cm): a
        # straight shortcut may graze an object where a descended path keeps away from
        # it, and the spheres only approximate the meshes
        clear = max(o.margin, min(self.eps, SHORTCUT_CLEARANCE))

        spent = [0]
        # the mesh certificate only where an endpoint needs it (shortcuts fail often)
        need = self._mesh_need
        meshes = bool(need is None or need.any())

        ends = np.concatenate([paths[:, 0], paths[:, -1]])

        on_device: list = [None, None]  # the segments of the last step, and on the device

        def check(segments: np.ndarray, per_path: int, rows: np.ndarray | None = None
                  ) -> np.ndarray:
            # group: a path's list of shortcuts is in the order of preference and the
            # first proven is taken: the rest of the list is skipped. The certificate
            # only for shortcuts from the start or to the goal (a grasp the spheres
            # touch); the waypoints between are free for the spheres. rows: one chunk
            # of the step's lists (the segments on the device once per step)
            seg = segments if rows is None else segments[rows]
            at_end = meshes and ((seg[:, 0, None] == ends[None]).all(-1).any(-1)
                                 | (seg[:, -1, None] == ends[None]).all(-1).any(-1))
            src: Any = segments
            if rows is not None:
                if on_device[0] is not segments:
                    on_device[:] = [segments, wp.array(
                        np.ascontiguousarray(segments, np.float64), dtype=wp.float64,
                        device=chk.device)]
                src = on_device[1]
            r = chk.check(src, margin=clear, self_margin=o.self_margin,
                          world_group=per_path if self.batched else 0, group=per_path,
                          meshes=at_end, rows=rows)
            spent[0] += r.evaluations
            return r.ok

        # the rounds' evaluations: a share of the optimisation's (the first call always)
        allowed = (None if o.shorten_budget is None or work is None
                   else float(o.shorten_budget) * work)
        nodes = shortcut_paths(paths, check, shorten_for(o, str(self.device)), rounds_end,
                               active=solved[idx],
                               budget=None if allowed is None
                               else (lambda: spent[0] >= allowed),
                               near_straight=None if STOP_NEAR_STRAIGHT is None
                               else float(np.sqrt(STOP_NEAR_STRAIGHT)),
                               chunk=SHORTEN_CHUNK)
        # the shortened polylines respaced (the paths not shortened kept as they are);
        # proven as built (_shortcuts_prove), or certified again (in the optimiser's dtype)
        built_proven = self._shortcuts_prove()
        cand = paths.copy()
        for k in np.nonzero(solved[idx])[0]:
            cand[k] = respace(nodes[k], W)
        if not built_proven:
            cand = cand.astype(self.npdt).astype(np.float64)
        cand[:, 0], cand[:, -1] = paths[:, 0], paths[:, -1]
        better = solved[idx] & (length_cost(cand) < length_cost(paths) * (1.0 - 1e-6))
        todo = np.nonzero(better)[0]
        if len(todo) and not built_proven:
            # certified with the planner's rule, in chunks until the deadline: a path
            # whose check was not reached keeps its certified path
            proven = np.zeros(len(better), bool)
            size = len(todo) if deadline is None else SHORTEN_CHUNK
            dev_cand: wp.array = wp.array(np.ascontiguousarray(cand), dtype=wp.float64,
                                          device=chk.device)

            def certify(rows: np.ndarray) -> np.ndarray:
                return chk.check(dev_cand, margin=o.margin, endpoint_margin=o.endpoint_margin,
                                 self_margin=o.self_margin,
                                 world_group=1 if self.batched else 0, meshes=meshes,
                                 rows=rows).ok

            pace = Pace()
            for c, e in pace.chunks(len(todo), size, deadline):
                part = todo[c:e]
                if not pace.fits(len(part), deadline):
                    break
                proven[part] = pace.run(certify, part)
            better &= proven
        if better.any():
            rows, b = np.nonzero(better)[0], idx[better]
            res.path[b] = cand[rows]
            self._costs_on_read(res, b, n_sub)
        res.timings["shorten"] = time.perf_counter() - t

    def _shortcuts_prove(self) -> bool:
        """Whether a shortened path is proven as built: its corners are waypoints, so each
        new segment lies on a proven shortcut (the full margins, or more) or on a segment
        of the certified path; that is the planner's rule wherever the first and last
        segments ask no less than the others (the endpoint margins not below ``margin``
        and ``self_margin``; else a piece of an old end segment, proven at the endpoint
        margin, may become an inner one)."""
        o = self.options
        em = o.margin if o.endpoint_margin is None else min(o.margin, o.endpoint_margin)
        return em >= o.margin and min(o.self_margin, em) >= o.self_margin

    def _costs_on_read(self, res: PlanResult, rows: np.ndarray, n_sub: int) -> None:
        """``cost``, ``length_cost`` and ``collision_cost`` of the problems ``rows`` of
        ``res`` (their paths replaced by the shortening) left to their first read
        (``PlanResult._fill``, as the straight stage's): one evaluation of the paths (B,
        W, n_dof) at ``n_sub`` substeps in a :class:`PathObjective` of their own (the
        planner's buffers are free for the next call), the other problems' costs kept."""
        o = self.options
        robot, world, dev, npdt, eps = self.robot, self.world, self.device, self.npdt, self.eps
        batched, own, rows = self.batched, np.array(res.path, copy=True), np.array(rows)
        # costs still waiting for their first read (a result of proven starts): every
        # path's are evaluated then, the replaced ones as they are now
        pending = res.__dict__.get("_fill") is not None
        kept = {} if pending else {name: np.array(getattr(res, name), np.float64, copy=True)
                                   for name in ("cost", "length_cost", "collision_cost")}

        def costs(r: PlanResult) -> None:
            obj = _evaluated(robot, world, o, eps, dev, npdt, batched, own, n_sub,
                             None if pending else rows)
            for name, arr in (("cost", obj.total), ("length_cost", obj.length),
                              ("collision_cost", obj.collision)):
                if pending:
                    setattr(r, name, arr.numpy().astype(np.float64))
                    continue
                v = kept[name]
                v[rows] = arr.numpy()[rows]
                setattr(r, name, v)

        res.cost = res.length_cost = res.collision_cost = None
        res._fill = costs

    def explain(self, res: PlanResult, deadline: float | None = None) -> list[str]:
        """Per problem of ``res``: "feasible", or why its best path is not: the first
        colliding link and object (or link pair), an uncertified approach, or the joint
        limits (one check of the infeasible problems' paths on the device), then what the
        RRT fallback did ("; fallback: ...", :attr:`PlanResult.fallback_notes`).

        ``deadline`` (``time.perf_counter()``; :meth:`plan` passes its ``time_limit``'s):
        once it has passed, the unsolved problems are not diagnosed by a check (it would
        run after the limit) but said to be out of time (:data:`NOT_DIAGNOSED`), the
        fallback's notes still appended."""
        late = not self._diagnose or (deadline is not None
                                      and time.perf_counter() >= deadline)
        out = self._explain(res, late)
        notes = res.fallback_notes
        if notes is not None:
            for i in np.nonzero(~np.asarray(res.feasible, bool))[0]:
                if notes[i]:
                    out[i] = f"{out[i]}; fallback: {notes[i]}"
        return out

    def _explain(self, res: PlanResult, late: bool = False) -> list[str]:
        """:meth:`explain` without the fallback's notes; ``late``: no check (the deadline
        has passed)."""
        out = ["feasible"] * len(res.feasible)
        bad = np.nonzero(~np.asarray(res.feasible, bool))[0]
        if not len(bad):
            return out
        o = self.options
        if o.kappa is not None:
            for i in bad:
                out[i] = "not feasible on the elastic model (collision or limits at a substep)"
            return out
        if late:
            for i in bad:
                out[i] = NOT_DIAGNOSED
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
        q = path_configs(x, self.robot, name)
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
        """The planner's :class:`jwarp.world.motion.MotionCheck` (made on first use; one
        per robot, world, device and these options is kept and shared by the planners
        of that world: :func:`jwarp.world.motion.motion_check`)."""
        if self._motion is None:
            from jwarp.world.motion import MotionOptions, motion_check

            # a bounded proof per segment: a path grazing the margin for longer than the
            # budget stays "not yet feasible" and the descent goes on moving it
            # on a GPU one thread would advance a grazing segment alone (the launch waits
            # for it): more parallel rounds, fewer sequential evaluations
            opts = (MotionOptions(max_evals=PLANNER_CHECK_EVALS_GPU, rounds=8)
                    if self.device.is_cuda else MotionOptions(max_evals=PLANNER_CHECK_EVALS))
            self._motion = motion_check(self.robot, self.world, device=self.device,
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
            chk = self.motion_check()
            wg = obj.P // self.n_problems if self.batched else 0
            out = chk.launch(obj.paths, buf.idx, len(cand), margin=o.margin,
                             endpoint_margin=o.endpoint_margin, group=group,
                             self_margin=o.self_margin, world_group=wg)
            ok = out["ok"].numpy()[:len(cand)].astype(bool)
            if not ok.all():
                # what the spheres leave unproven, the URDF geometry may prove (a grasp
                # pose the contained spheres reach past): every check for the problems
                # whose endpoints need it, the last check for the others; skipped starts
                # stay skipped
                need = self._mesh_need
                per = obj.P // self.n_problems
                sel = ~ok
                if not self._final and need is not None:
                    sel &= need[np.asarray(cand) // per]
                K = len(cand)
                if self._final and group and sel.any():
                    # the last check: per problem only the unproven start the spheres miss
                    # by least goes to the certificate (one proven path is enough; the
                    # others of an unsolved problem are the fallback's)
                    sel &= _best_of_group(np.asarray(cand) // per, out["dist"].numpy()[:K],
                                          sel, MESH_FINAL_PER_PROBLEM)
                ok = self._mesh_proof(chk, obj.paths, np.asarray(cand), ok,
                                      out["code"].numpy()[:K], out["dist"].numpy()[:K], sel,
                                      wg)
            return ok
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
                n_starts: int, wall: float, found_at: np.ndarray) -> PlanResult:
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
                          all_iterations=it, paths_source=wp.clone(buf.final),
                          solved_at=np.where(fz[rows, best],
                                             found_at.reshape(B, n_starts)[rows, best], np.nan))


#: :attr:`PlanOptions.stall_iterations`: the relative fall of a problem's best cost that
#: counts as progress
STALL_GAIN = 0.01
#: :attr:`PlanOptions.reseed_iterations`: the most new draws of one start
RESEED_MAX = 2


#: the unproven starts per problem that the last check gives to the mesh certificate
#: (those of the largest sphere clearance): on 70 Panda scene problems in one batch (CPU)
#: that check of every start took 1.5 s of a 5 s call; one problem at a time (one CPU
#: core, 60 cage / under-table / thin-shelf problems) it took 120-210 ms of an unsolved
#: problem's plan and proved one path in five calls: with one start the same 58/60
#: solved, mean 270 ms against 293, p95 766 against 923
MESH_FINAL_PER_PROBLEM = 1


def _best_of_group(group: np.ndarray, score: np.ndarray, sel: np.ndarray, k: int
                   ) -> np.ndarray:
    """(K,) bool: of the rows ``sel`` the ``k`` of the largest ``score`` per ``group``."""
    out = np.zeros(len(sel), bool)
    rows = np.nonzero(sel)[0]
    order = rows[np.lexsort((-np.asarray(score, np.float64)[rows], group[rows]))]
    g = group[order]
    first = np.searchsorted(g, g, side="left")
    out[order[np.arange(len(order)) - first < k]] = True
    return out


#: :func:`_fallback` runs the trees of more than one unsolved problem (rigid model) at once
#: (:func:`jwarp.solvers.planning.rrt.rrt_connect_batch`); False: one problem after another
FALLBACK_BATCH = True
#: a batch's problems handed over by :attr:`PlanOptions.stall_iterations` grow their trees
#: between the other problems' gradient steps (:class:`jwarp.solvers.planning.rrt.RRTBatch`),
#: not after the batch's optimisation; False: after it, as one batch
FALLBACK_INTERLEAVED = True
#: the most of the optimiser loop's time that the interleaved RRT rounds take (a round
#: runs only while their seconds so far are at most this share of the loop's): on an
#: H200 a round of a few problems' trees costs several optimiser iterations of the whole
#: 700-problem batch, and with a round every iteration the optimiser reached fewer
#: iterations by its deadline (26 problems it solves in time went to the fallback, the
#: last solved at 1.8 s instead of 1.0 s)
FALLBACK_LOOP_SHARE = 0.25


def _fallback(planner: Planner, res: PlanResult, q0: np.ndarray, q1: np.ndarray, t0: float,
              deadline: float | None) -> None:
    """:attr:`PlanOptions.fallback` for the problems of ``res`` without a feasible path:
    RRT-Connect (:func:`jwarp.solvers.planning.rrt.rrt_connect`, with the planner's margins, kappa
    and device) for each in turn (more than one on the rigid model: all at once,
    :func:`jwarp.solvers.planning.rrt.rrt_connect_batch`, each from its own generator
    drawn from ``rrt.seed``), each path found resampled to the W waypoints
    (:func:`jwarp.solvers.planning.rrt.resample_path`: its nodes kept where it has at most W) as
    the one seed of a gradient optimisation of the same options (no fallback,
    ``stop_when_solved``) of all of them at once. On the rigid model that optimisation's
    exact check is the RRT's own (:func:`jwarp.world.path_feasibility.certify_check`: the
    same pairs, margins and evaluation budget), so a seed the trees proved is certified as
    it is at iteration 0 and returned (the trees' shortcuts were checked by it too); a
    seed that is not (more than W nodes, so its corners were cut) is optimised and kept
    only if that ends certified. Its feasible paths replace those problems' results in
    ``res`` (stage "fallback", ``start_index`` -1); ``fallback_notes``, ``stop_reason``
    and ``timings`` updated. With a ``deadline`` the trees get 80 % of the time left, the
    optimisation the rest; one problem's trees start again while ``rrt.max_samples`` is
    used up with time left (:func:`_rrt_restarts`; in a batch, :class:`RRTBatch`'s
    ``restart``). A batch's problems handed over early (``stall_iterations``) are already
    in the plan's :class:`jwarp.solvers.planning.rrt.RRTBatch` (their trees grew between
    the optimiser's steps, :data:`FALLBACK_INTERLEAVED`): the search goes on with them and
    the rest joins it."""
    from jwarp.solvers.planning.rrt import resample_path

    o = planner.options
    t_rrt = time.perf_counter()
    ropt = _rrt_options(o)
    rrt_stop = None if deadline is None else t_rrt + 0.8 * max(0.0, deadline - t_rrt)
    W = res.path.shape[1]
    if res.fallback_notes is None:
        res.fallback_notes = np.full(len(res.feasible), "", dtype=object)
    notes = res.fallback_notes
    found, seeds, nodes = [], [], []
    timed_out = False
    todo = np.nonzero(~res.feasible)[0]
    need = getattr(planner, "_mesh_need", None)
    batch = None  # more than one problem (rigid): all their trees at once, in one batch
    rb = planner._rrt  # the trees already growing (problems handed over early)
    if (len(todo) > 1 or rb is not None) and o.kappa is None and FALLBACK_BATCH and (
            rrt_stop is None or time.perf_counter() < rrt_stop):
        rb = planner._rrt_batch(q0, q1)
        rb.start([int(b) for b in todo if int(b) not in rb.problems])
        end = math.inf if rrt_stop is None else rrt_stop
        rb.run(end)
        rb.finish(rb.connected(), end)
        batch = [rb.result(int(b)) for b in todo]
    for i, b in enumerate(todo):
        if batch is None and rrt_stop is not None and time.perf_counter() >= rrt_stop:
            timed_out = True
            notes[b] = "RRT-Connect not run: no time left"
            continue
        if batch is not None:
            r = batch[i]
        else:
            r = _rrt_restarts(planner, int(b), q0[b], q1[b], ropt, rrt_stop,
                              True if need is None else bool(need[b]))
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
    res.timings["rrt"] = res.timings.get("rrt", 0.0) + time.perf_counter() - t_rrt
    direct: list[int] = []  # problems whose RRT path is certified as it is, here
    if found and o.kappa is None:
        t_cert = time.perf_counter()
        direct = _certified_as_is(planner, res, found, seeds, nodes, need, t0)
        res.timings["fallback_certify"] = time.perf_counter() - t_cert
        keep = [k for k, b in enumerate(found) if b not in set(direct)]
        found = [found[k] for k in keep]
        seeds = [seeds[k] for k in keep]
        nodes = [nodes[k] for k in keep]
    if found:
        t_opt = time.perf_counter()
        left = None if deadline is None else max(deadline - t_opt, 1e-6)
        # every iteration checked (the first before any step: the seed as it is)
        sub_o = replace(o, n_starts=1, fallback=None, time_limit=left, stop_when_solved=True,
                        callback=None, check_all_every=1, shorten=0, problem_time_limit=None)
        sub_world = planner.world
        if planner.batched:  # the found problems' own worlds, as a batch of their own
            from jwarp.world.sdf import World
            sub_world = World.batch([planner.world.select(int(b)) for b in found])
        sub = Planner(planner.robot, sub_world, len(found), sub_o, device=planner.device,
                      dtype=planner.npdt)
        sub._diagnose = False  # its reasons are not read: the notes below say it
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
        res.solved_at[b] = (t_opt - t0) + r2.solved_at[ok]
        res.timings["fallback_optimizer"] = time.perf_counter() - t_opt
        for k, bb in enumerate(found):
            cut = (f", resampled to {W} waypoints (corners cut)" if nodes[k] > W
                   else f" as {W} waypoints")
            if ok[k]:
                how = ("certified as it is" if r2.iterations[k] == 0 else
                       f"certified after {int(r2.iterations[k])} optimisation steps")
                notes[bb] = f"RRT-Connect path of {nodes[k]} nodes{cut}: {how}"
            elif r2.stop_reason == "time_limit" or (
                    deadline is not None and time.perf_counter() >= deadline):
                # out of time: no per-problem diagnosis (a check per problem in its own
                # world would cost more than the budget that is already spent)
                notes[bb] = (f"RRT-Connect path of {nodes[k]} nodes{cut} not certified as "
                             f"it is, and no time was left to optimise it")
            else:
                notes[bb] = (f"RRT-Connect path of {nodes[k]} nodes{cut} not certified "
                             f"({_seed_reason(planner, sub, seeds[k], bb)}) and its "
                             f"optimisation ended infeasible")
    if direct:  # their costs evaluated when first read
        rows = np.array(direct)
        planner._costs_on_read(res, rows, planner._substeps(np.asarray(res.path)[rows]))
    if res.feasible.all():
        res.stop_reason = "solved"
    elif deadline is not None and (timed_out or time.perf_counter() >= deadline):
        res.stop_reason = "time_limit"
    else:
        res.stop_reason = "iterations"


def _evaluated(robot: RobotModel, world: Any, o: PlanOptions, eps: float, device: Any,
               dtype: Any, batched: bool, paths: np.ndarray, n_sub: int,
               rows: np.ndarray | None = None) -> PathObjective:
    """A :class:`PathObjective` of its own holding ``paths`` (B, W, n_dof), evaluated
    without gradient at ``n_sub`` substeps (a batch of worlds: path b in world b);
    ``rows``: only those paths' collision queries (the others' costs are not read)."""
    B = len(paths)
    obj = PathObjective(robot, world, B, paths.shape[1], n_sub, weights=o.weights, eps=eps,
                        lam=o.lam, device=device, dtype=dtype)
    if batched:
        obj.group_div = obj.S
    obj.set_paths(paths)
    if rows is not None:
        act = np.zeros(B, bool)
        act[rows] = True
        obj.set_active(act)
        obj.skip_inactive = True
    obj.evaluate(grad=False)
    return obj


def _rrt_restarts(planner: Planner, b: int, q0: np.ndarray, q1: np.ndarray, ropt: Any,
                  stop: float | None, meshes: bool) -> Any:
    """RRT-Connect for problem ``b`` (:func:`jwarp.solvers.planning.rrt.rrt_connect`), and
    with a deadline ``stop``, new trees (the generator's next samples) each time
    ``rrt.max_samples`` is used up without a path while time is left: a restart rather
    than an unsolved problem with most of its time unspent. The last result, its samples
    and time those of all the tries."""
    from jwarp.solvers.planning.rrt import rrt_connect

    o = planner.options
    t = time.perf_counter()
    samples = 0
    while True:
        r = rrt_connect(planner.robot, planner.world.select(b), q0, q1, ropt,
                        margin=o.margin, kappa=o.kappa, device=planner.device, deadline=stop,
                        endpoint_margin=o.endpoint_margin, self_margin=o.self_margin,
                        meshes=meshes)
        samples += r.n_samples
        if r.success or r.stop_reason != "max_samples" or stop is None \
                or time.perf_counter() >= stop:
            break
    r.n_samples = samples
    r.wall_time = time.perf_counter() - t
    return r


def _certified_as_is(planner: Planner, res: PlanResult, found: list[int], seeds: list,
                     nodes: list[int], need: np.ndarray | None, t0: float) -> list[int]:
    """The problems ``found`` whose RRT path (``seeds``: resampled to W waypoints; its
    ``nodes``) kept every node (at most W: the resampling only adds points on its
    proven edges) and passes the trees' own check (:func:`certify_check`: the same pairs,
    margins, budget and mesh certificate) as it is, in one call for all of them: their
    results set in ``res`` (stage "fallback", iteration 0; costs left to the caller), the
    rest left to the optimisation (a sub-planner in a batch of their own worlds, which
    cost about 0.5 s of a 700-problem GPU batch). Returns those problems."""
    W = res.path.shape[1]
    cand = [k for k in range(len(found)) if nodes[k] <= W]
    if not cand:
        return []
    rows = np.array([found[k] for k in cand])
    ok = _certify_rrt_paths(planner, rows, np.stack([seeds[k] for k in cand]), need)
    done = rows[ok]
    _set_fallback(res, done, np.stack([seeds[k] for k in cand])[ok],
                  time.perf_counter() - t0,
                  [f"RRT-Connect path of {nodes[cand[k]]} nodes as {W} waypoints: certified "
                   f"as it is" for k in np.nonzero(ok)[0]])
    return [int(b) for b in done]


def _set_fallback(res: PlanResult, rows: np.ndarray, paths: np.ndarray, at: Any,
                  notes: list[str]) -> None:
    """Problems ``rows`` of ``res`` solved by an RRT path certified as it is: ``paths``
    (R, W, n_dof), stage "fallback", iteration 0, start_index -1, ``solved_at`` ``at``
    (seconds; one or per row) and their fallback ``notes`` (costs left to the caller)."""
    res.path[rows] = paths
    res.feasible[rows] = True
    res.iterations[rows] = 0
    res.start_index[rows] = -1
    res.stage[rows] = "fallback"
    res.solved_at[rows] = at
    for b, note in zip(rows, notes):
        res.fallback_notes[b] = note


def _rrt_options(o: PlanOptions) -> Any:
    """The plan's :class:`RRTOptions` (``o.rrt`` or the defaults) with its seed as a
    generator (each problem's own generator drawn from it)."""
    from jwarp.solvers.planning.rrt import RRTOptions

    ro = o.rrt if o.rrt is not None else RRTOptions()
    rng = ro.seed if isinstance(ro.seed, np.random.Generator) else np.random.default_rng(ro.seed)
    return replace(ro, seed=rng)


def _certify_rrt_paths(planner: Planner, rows: np.ndarray, paths: np.ndarray,
                       need: np.ndarray | None) -> np.ndarray:
    """(R,) bool: the paths (R, W, n_dof) of problems ``rows`` within the limits and
    certified by the trees' own check (:func:`certify_check`: the same pairs, margins,
    budget and mesh certificate where ``need`` allows it), in one call."""
    o = planner.options
    W = paths.shape[1]
    full = np.zeros((planner.n_problems,) + paths.shape[1:])
    full[rows] = paths
    chk = certify_check(planner.robot, planner.world, device=planner.device)
    pc = chk.check(full, margin=o.margin, endpoint_margin=o.endpoint_margin,
                   self_margin=o.self_margin, world_group=1 if planner.batched else 0,
                   meshes=np.ones(len(rows), bool) if need is None
                   else np.asarray(need, bool)[rows], rows=rows)
    return np.asarray(pc.ok, bool) & within_limits(planner.robot, paths.reshape(
        -1, paths.shape[2])).reshape(len(rows), W).all(axis=1)


def _seed_reason(planner: Planner, sub: Planner, seed: np.ndarray, b: int) -> str:
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
        seeds = renamed_argument("plan()", "initial", "seeds", overrides, seeds)
    init_warp()
    model = get_robot(robot)
    check_world(model, world)
    q0 = path_configs(start, model, "start")
    q1 = path_configs(goal, model, "goal")
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
    check_valid_range(model, res.path, "plan")   # a calibrated robot: warn once outside
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
                nw = getattr(world, "n_worlds", 1) if world is not None else 1
                r = initial_paths(np.repeat(q0, k, 0), np.repeat(q1, k, 0), W, "random",
                                  robot=model, rng=rng, world=world if free_via else None,
                                  device=device, per_world=k if nw > 1 and nw == B else 0)
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
