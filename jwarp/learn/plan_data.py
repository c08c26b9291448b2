"""Hard-task motion-planning labels (thesis 3.5.1, "Motion Planning Dataset", Table 3.2).

Per world: random collision-free start/goal pairs. The straight line in joint space is
optimized first (:class:`jwarp.solvers.planning.Planner`, gradient descent on U_path with a
fixed step); a task is *easy* when it converges to a feasible path and *hard* otherwise.
A hard task gets up to ``max_starts`` multi-starts through 1-3 random via points, all
optimized in one batch, and its label is the best (lowest U_path, so in practice the
shortest) feasible one. Labels are *converged* paths (:attr:`PlanOptions.converge`):
feasible paths keep being optimized, staying feasible, until their length cost settles.
Easy tasks keep their straight-line result as a separate set (Table 3.3's first row);
tasks no start solves are reported with ``feasible = False``.

:func:`world_for` builds the simplex world of Table 3.2 for a robot and a seed (planar
robots: 64 x 64 cells over 1 x 1 m; 3D arms: 64^3 over 1.2^3 m; justin19: 64^3 over 3^3 m;
each box centred on the robot's reach), kept only when >= 200 of 1000 random
configurations are collision-free (:func:`jwarp.world.feasibility.feasible_simplex_world`).

Fidelity (measured 2026-11-24 on a 2-core VM, CPU, small samples: ``bench_plan_data.py``):
the single-start feasibility of the random multi-starts over solved hard tasks depends
mostly on the world, then on the iteration budget. With Table 3.2's boxes *literally*
(planar4: 1 x 1 m around an arm reaching 1 m, so the obstacles crowd the base; arm7:
1.2^3 m) planar4 gets 5-12 % (thesis 32.6 %) and most tasks are hard and unsolved; on
grids fitted to the robot's reach with coarser noise (``extent="reach"``, ``frequency=1``)
planar4 gets 26-32 % (200 iterations) to 59 % (300), arm7 (``threshold=0.45``) 10-44 %
(thesis 54.5 %) on 1-6 solved tasks. :func:`world_for` keeps the Table 3.2 geometry.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from jwarp.core.arrays import real_number
from jwarp.core.device import numpy_dtype, scalar_type
from jwarp.core.limits import sample_within_limits
from jwarp.core.types import DeviceLike, DTypeLike
from jwarp.model import RobotModel
from jwarp.solvers.planning import PathWeights, Planner, PlanOptions
from jwarp.utils.checks import check_int
from jwarp.world.feasibility import feasible_simplex_world
from jwarp.world.path_feasibility import check_world, collision_free

if TYPE_CHECKING:
    from jwarp.world.sdf import World

__all__ = ["PlanDataOptions", "WorldLabels", "world_for", "label_world", "world_extent"]

#: side of the cubic (square) world of Table 3.2 [m] per robot; other robots: by their
#: workspace dimension (2D: 1 m, 3D: 1.2 m)
WORLD_EXTENT = {"planar4": 1.0, "planar5": 1.0, "arm7": 1.2, "justin19": 3.0}
#: cells per axis of the worlds of Table 3.2
WORLD_CELLS = 64


@dataclass
class PlanDataOptions:
    """Options of :func:`label_world`; :meth:`validate` raises ValueError/TypeError naming
    the field.

    Attributes:
        n_waypoints: W, waypoints per path (20 in the thesis), >= 3.
        max_starts: random multi-starts (1-3 via points) per hard task, >= 1 (thesis: 100).
        iterations: most gradient steps per path, >= 1.
        step, max_step: step size (eq. 3.18) and the largest change of one joint of one
            waypoint per step [rad], > 0.
        n_substeps: substeps per segment (None: sized to the world's voxel per call).
        substep_voxels: with ``n_substeps`` None: the most a sphere centre travels between
            two cost substeps of the multi-start search and the convergence, in voxels
            (:attr:`PlanOptions.substep_voxels`), > 0. The straight-line stage, which tells
            easy from hard tasks, keeps the thesis' 1. 3 (default), with ``stats_tasks``
            32, measured on an H200 (justin19, Table 3.2 world 0, 256 tasks, 20 starts,
            300 iterations, 2 runs): 7.2-7.3 labelled hard paths/s against 5.4-5.5 with 1
            and every start run, labelling 79 of 84 and 82 of 97 hard tasks (78 and 86
            before); single-start feasibility on 2 worlds x 48 tasks 20.5 % (19.7 % before).
            The exact continuous check certifies every label either way.
        check_all_every: exact feasibility checks every this many iterations, >= 1.
        length_weight: lam_l of eq. 3.16 while converging the feasible paths (world and
            self-collision weights are 1), >= 0; the search uses the planner's 0.01. 0.1:
            with 0.01 converging hardly shortens the paths (planar4: hard labels' U_l
            1.84/2.54/3.16 early-stopped vs 1.80/2.53/3.18 converged; with 0.1:
            1.60/2.16/2.36), and searching with 0.1 finds far fewer feasible paths.
        margin: required clearance [m] of the labels, >= 0.
        converge: converge the feasible paths (the best ``refine`` of each task) until
            the length cost settles; False: the labels are the early-stopped paths.
        refine: feasible multi-starts per hard task converged for its label, >= 1.
        stats_tasks: the first this many hard tasks of a call run every multi-start (the
            single-start statistics of Table 3.2 are measured on them); every other hard
            task stops its starts once ``refine`` of them are feasible (one without
            ``converge``), so starts that would never be needed cost nothing. None: every
            hard task runs every start (the statistics over all of them).
        converge_tol: relative change of U_l between checks that counts as converged.
        device: Warp device of the optimisation ("cpu", "cuda", "cuda:0", ...; None:
            Warp's default device, docs/api.md "Devices").
        dtype: "float32" or "float64", the optimisation's float type.
    """

    n_waypoints: int = 20
    max_starts: int = 100
    iterations: int = 300
    step: float = 0.01
    max_step: float = 0.1
    n_substeps: int | None = None
    substep_voxels: float = 3.0
    check_all_every: int = 10
    length_weight: float = 0.1
    margin: float = 0.0
    converge: bool = True
    refine: int = 4
    stats_tasks: int | None = 32
    converge_tol: float = 1e-4
    device: str | None = None
    dtype: str = "float32"

    def validate(self) -> None:
        for name, lo in (("n_waypoints", 3), ("max_starts", 1), ("iterations", 1),
                         ("check_all_every", 1), ("refine", 1)):
            v = getattr(self, name)
            check_int(v, name, lo)
        if self.stats_tasks is not None:
            v = self.stats_tasks
            check_int(v, "stats_tasks", 0)
        if self.n_substeps is not None:
            v = self.n_substeps
            check_int(v, "n_substeps", 1)
        for name, strict in (("step", True), ("max_step", True), ("converge_tol", True),
                             ("substep_voxels", True),
                             ("length_weight", False), ("margin", False)):
            v = getattr(self, name)
            x = real_number(v, name)
            if not math.isfinite(x) or x < 0 or (strict and x == 0):
                raise ValueError(f"{name}: expected a finite number {'>' if strict else '>='} 0, "
                                 f"got {v!r}")
        if not isinstance(self.converge, (bool, np.bool_)):
            raise TypeError(f"converge: expected True or False, got {self.converge!r}")
        if self.device is not None and not isinstance(self.device, str):
            raise TypeError(f"device: expected a device name (str), got "
                            f"{type(self.device).__name__}")
        if self.dtype not in ("float32", "float64"):
            raise ValueError(f"dtype: expected 'float32' or 'float64', got {self.dtype!r}")

    def plan_options(self, start_kind: str, n_starts: int, seed: int,
                     refine: bool = False, enough: int | None = None) -> PlanOptions:
        """The :class:`PlanOptions` of one stage: the search (straight line or
        multi-starts: the planner's length weight, each path stopping once feasible, a
        problem's starts once ``enough`` of them are) or, with ``refine``, the convergence
        of feasible seeds (``length_weight``, ``converge``)."""
        w = PathWeights(length=float(self.length_weight)) if refine else PathWeights()
        return PlanOptions(n_starts=n_starts, start_kind=start_kind, n_waypoints=self.n_waypoints,
                           n_substeps=self.n_substeps, iterations=self.iterations,
                           substep_voxels=1.0 if start_kind == "straight"
                           else float(self.substep_voxels),
                           step=self.step, max_step=self.max_step, weights=w,
                           margin=float(self.margin), check_all_every=self.check_all_every,
                           converge=bool(refine), converge_tol=float(self.converge_tol),
                           seed=int(seed), stop_when_solved=False, fallback=None,
                           enough_feasible=None if refine else enough)


@dataclass
class WorldLabels:
    """Labels of one world for N tasks (:func:`label_world`).

    starts, goals (N, n_dof) float32 [rad or m]; paths (N, W, n_dof) float32: the label
    (the converged best feasible multi-start path of a hard task, the straight-line
    result of an easy one; the lowest-cost infeasible path when nothing was feasible);
    cost (N,) U_path (eq. 3.16) of the label; feasible (N,) bool; hard (N,) bool (False:
    an easy task, kept separately); settings: the options that made them (JSON-able);
    length_cost (N,) U_l (eq. 3.5, 1 for the straight line) of the label; n_feasible_starts
    (N,) feasible multi-starts of a hard task (0 for easy ones); n_starts (N,) multi-starts
    run to the end (0 for easy tasks); stats (N,) bool: the hard tasks whose multi-starts
    all ran (``PlanDataOptions.stats_tasks``), the subset the single-start statistics are
    measured on (elsewhere a task's starts stopped once enough were feasible, and
    ``n_feasible_starts`` counts those).
    """

    starts: np.ndarray
    goals: np.ndarray
    paths: np.ndarray
    cost: np.ndarray
    feasible: np.ndarray
    hard: np.ndarray
    settings: dict
    length_cost: np.ndarray | None = field(default=None, repr=False)
    n_feasible_starts: np.ndarray | None = field(default=None, repr=False)
    n_starts: np.ndarray | None = field(default=None, repr=False)
    stats: np.ndarray | None = field(default=None, repr=False)

    def __len__(self) -> int:
        return len(self.starts)

    @property
    def single_start_rate(self) -> float:
        """Fraction of feasible multi-starts over the hard tasks some start solved (the
        thesis' "Avg. Feas." of Table 3.2: its dataset holds only solved tasks), on the
        tasks whose starts all ran (:attr:`stats`); NaN if none."""
        m = self.hard & self.feasible
        if self.stats is not None:
            m = m & self.stats
        if not m.any():
            return float("nan")
        # set with the statistics
        n_ok, n_all = cast(np.ndarray, self.n_feasible_starts), cast(np.ndarray, self.n_starts)
        return float(n_ok[m].sum() / n_all[m].sum())


def world_extent(model: RobotModel) -> float:
    """Side [m] of the Table 3.2 world of the robot ``model`` (:func:`world_for` resolves
    a name)."""
    return float(WORLD_EXTENT.get(model.name, 1.0 if model.workspace_dim == 2 else 1.2))


def world_for(robot: RobotModel, world_seed: int, *, device: DeviceLike = None, extent: Any = None,
              **noise: Any) -> Any:
    """The Table 3.2 simplex world of ``world_seed`` for ``robot``: ``WORLD_CELLS`` cells
    per axis over a cube (square) of :func:`world_extent` [m] centred on the robot's
    reach, the first seed from ``world_seed`` on with >= 200 of 1000 random
    configurations collision-free (:func:`jwarp.world.feasibility.feasible_simplex_world`).
    Deterministic in the seed. ``extent``: another side [m], or "reach" for the grid
    fitted to the robot's reach (the longest side ``WORLD_CELLS`` cells). ``noise``:
    threshold, frequency, ... of the simplex noise (defaults of
    :func:`jwarp.world.simplex.simplex_world`)."""
    model = robot
    check_int(world_seed, "world_seed", 0)
    if isinstance(extent, str):
        if extent != "reach":
            raise ValueError(f"extent: expected a side [m], None or 'reach', got {extent!r}")
        extent = None
    else:
        extent = world_extent(model) if extent is None else extent
    return feasible_simplex_world(model, seed=int(world_seed), cells=WORLD_CELLS,
                                  extent=extent, device=device, **noise)


def _task_pairs(model: RobotModel, world: World, n: int, margin: float,
                rng: np.random.Generator, device: DeviceLike) -> tuple[np.ndarray, np.ndarray]:
    """n collision-free (start, goal) pairs, drawn uniformly within the limits."""
    out: list[np.ndarray] = []
    have = 0
    for _ in range(200):
        q = sample_within_limits(model, max(64, 4 * (2 * n - have)), rng)
        q = q[collision_free(model, world, q, margin, device=device)]
        out.append(q)
        have += len(q)
        if have >= 2 * n:
            q = np.concatenate(out)[:2 * n]
            return q[0::2], q[1::2]
    raise ValueError(f"world: fewer than {2 * n} collision-free configurations of "
                     f"'{model.name}' found")


def label_world(robot: RobotModel, world: World, n_tasks: int, seed: int,
                options: PlanDataOptions | None = None) -> WorldLabels:
    """Label ``n_tasks`` random tasks of one world (module docstring).

    Args:
        robot: RobotModel.
        world: a :class:`jwarp.world.World` of the robot (e.g. :func:`world_for`).
        n_tasks: N, start/goal pairs (>= 1).
        seed: integer >= 0; the tasks and the multi-starts follow from it, so the labels
            are deterministic for (robot, world, n_tasks, seed, options) on one device.
        options: :class:`PlanDataOptions` (None: the defaults).

    Returns:
        :class:`WorldLabels`.
    """
    model = robot
    check_world(model, world)
    check_int(n_tasks, "n_tasks", 1)
    check_int(seed, "seed", 0)
    if options is None:
        options = PlanDataOptions()
    if not isinstance(options, PlanDataOptions):
        raise TypeError(f"options: expected a PlanDataOptions, got {type(options).__name__}")
    options.validate()
    o = options
    n_tasks = int(n_tasks)
    dtype = numpy_dtype(scalar_type(o.dtype))
    rng = np.random.default_rng([int(seed), 0x6A77])
    q0, q1 = _task_pairs(model, world, n_tasks, float(o.margin), rng, o.device)
    start_seed = int(rng.integers(0, 2**31 - 1))

    line = Planner(model, world, n_tasks, o.plan_options("straight", 1, 0), device=o.device,
                   dtype=dtype).plan(q0, q1)
    W, n = o.n_waypoints, model.n_dof
    paths = line.path.copy()
    cost = line.cost.copy()
    length = line.length_cost.copy()
    feasible = line.feasible.copy()
    hard = ~line.feasible
    n_feasible = np.zeros(n_tasks, np.int64)
    n_starts = np.zeros(n_tasks, np.int64)
    seeds = [paths[i:i + 1] for i in range(n_tasks)]  # feasible paths to converge
    stats = np.zeros(n_tasks, bool)
    hard_idx = np.nonzero(hard)[0]
    n_stats = len(hard_idx) if o.stats_tasks is None else min(int(o.stats_tasks), len(hard_idx))
    enough = o.refine if o.converge else 1
    # the statistics' subset runs every start; the others stop once enough are feasible
    for h, stop, sd in ((hard_idx[:n_stats], None, start_seed),
                        (hard_idx[n_stats:], enough, start_seed + 1)):
        if not len(h):
            continue
        res = Planner(model, world, len(h),
                      o.plan_options("random", o.max_starts, sd, enough=stop),
                      device=o.device, dtype=dtype).plan(q0[h], q1[h])
        paths[h] = res.path
        cost[h] = res.cost
        length[h] = res.length_cost
        feasible[h] = res.feasible
        n_feasible[h] = res.n_feasible
        if stop is None:
            n_starts[h] = o.max_starts
            stats[h] = True
        if o.converge and res.feasible.any():
            allp, fz = res.all_paths, res.all_feasible
            for k, i in enumerate(h):
                f = np.nonzero(fz[k])[0]
                if len(f):  # the shortest feasible starts (joint-space U_l)
                    lk = 0.5 * (np.diff(allp[k, f], axis=1) ** 2).sum((1, 2))
                    seeds[i] = allp[k, f[np.argsort(lk, kind="stable")[:o.refine]]]
    if o.converge:
        _refine(model, world, o, dtype, q0, q1, seeds, feasible, paths, cost, length)
    settings = {"robot": model.name, "n_tasks": n_tasks, "seed": int(seed),
                "world": {k: v for k, v in world.meta.items()
                          if isinstance(v, (int, float, str, bool))},
                "options": asdict(o)}
    return WorldLabels(starts=q0.astype(np.float32), goals=q1.astype(np.float32),
                       paths=paths.reshape(n_tasks, W, n).astype(np.float32),
                       cost=cost.astype(np.float64), feasible=feasible.astype(bool),
                       hard=hard.astype(bool), settings=settings,
                       length_cost=length.astype(np.float64), n_feasible_starts=n_feasible,
                       n_starts=n_starts, stats=stats)


def _refine(model: RobotModel, world: World, o: PlanDataOptions, dtype: DTypeLike, q0: np.ndarray,
            q1: np.ndarray, seeds: list, feasible: np.ndarray, paths: np.ndarray,
            cost: np.ndarray, length: np.ndarray) -> None:
    """Converge the feasible seeds of every solved task (one batch, ``o.refine`` seeds a
    task, fewer repeated) and keep per task the best converged feasible path (lowest
    U_path with ``length_weight``, i.e. about the shortest) where its U_l is below the
    search's. ``cost`` becomes its U_path with the search's weights (arrays updated in
    place)."""
    idx = np.nonzero(feasible)[0]
    if not len(idx):
        return
    K = o.refine
    batch = np.stack([np.concatenate([seeds[i]] * K)[:K] for i in idx])  # (B, K, W, n)
    res = Planner(model, world, len(idx), o.plan_options("random", K, 0, refine=True),
                  device=o.device, dtype=dtype).plan(q0[idx], q1[idx], seeds=batch)
    lam = PathWeights().length
    better = res.feasible & (res.length_cost <= length[idx])
    i = idx[better]
    paths[i] = res.path[better]
    length[i] = res.length_cost[better]
    cost[i] = res.collision_cost[better] + lam * res.length_cost[better]
