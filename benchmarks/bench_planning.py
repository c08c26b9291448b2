#!/usr/bin/env python
"""Planning benchmark: OMP iteration time, IK time to a feasible solution, feasibility of
random multi-starts on hard tasks, and the cost of elastic compensation.

    python benchmarks/bench_planning.py                        # CPU, default sizes
    python benchmarks/bench_planning.py --device cuda --paths 1000
    python benchmarks/bench_planning.py --tasks 100 --json out.json   # the full figure
    python benchmarks/bench_planning.py --quick                # smoke-test sizes

Sections (``--only`` picks some):

* ``iteration``: one gradient iteration (substeps -> collision cost + gradient -> path
  cost -> projected step, plus the host read of the per-path screen) of one justin19 path
  of 20 waypoints with substeps sized to the voxel size, and of ``--paths`` paths at once.
  Warp runs CPU kernels on one thread and the script limits numpy's BLAS to one thread,
  so the CPU figure is one core.
* ``ik``: wall time of :func:`jwarp.solvers.ik.ik` (random multi-start, stop at the
  first feasible start) for justin19's right hand in a shelf-like world, per target:
  ``bench_ik.py``'s :func:`shelf_ik` (its section c) for ik() alone, imported from there.
* ``feasibility``: per robot (planar4, arm7, justin19) ``--tasks`` hard tasks (random
  collision-free start/goal in a random simplex world where the straight line is still
  infeasible after 50 iterations), then ``--starts`` random multi-starts (1-3 via points)
  for 50 iterations: fraction of tasks solved and of single starts feasible, over all hard
  tasks and over the tasks some start solved (the thesis' 50 % is of the latter kind: its
  dataset kept only solved tasks). Every task world is a distinct simplex world.
* ``compensation``: time per iteration rigid vs elastic (one torque update) for the
  justin19 path and an IK batch (its kernels, timed side by side here; and the whole
  ``ik()`` iteration with the host step, timed by
  :func:`jwarp.solvers.compensation.ik_iteration_overhead` from the solver's per-iteration
  callbacks); iterations to converge of compensated IK for kappa = 1e-4 and 20x softer
  (2e-3) rad/(N m) vs rigid, from the same seeds.

Times go through ``benchmarks/timing.py``: min and median over ``--repeats`` runs of at
least ``--min-time`` seconds each (:func:`timing.measure`), rigid and elastic interleaved
(:func:`timing.side_by_side`, the overhead a ratio of their medians and of their bests);
the machine is printed first.
"""

from __future__ import annotations

import argparse
import os
import sys
from typing import Any

# one CPU core: numpy's BLAS (the IK's host step) would otherwise use every core. Set
# before numpy loads; an exported value wins.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402
import warp as wp  # noqa: E402

if hasattr(wp.config, "quiet"):
    wp.config.quiet = True

import jwarp  # noqa: E402
from jwarp.core.arrays import init_warp  # noqa: E402
from jwarp.core.limits import sample_within_limits  # noqa: E402
from jwarp.solvers import compensation as comp  # noqa: E402
from jwarp.solvers import ik as IK  # noqa: E402
from jwarp.solvers import planning as PL  # noqa: E402
from jwarp.world import (
    collision,  # noqa: E402
    path_feasibility,
)
from jwarp.world.io import parse_world_spec  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import timing  # noqa: E402  (benchmarks/timing.py, beside this script)
from bench_ik import shelf_ik  # noqa: E402  (bench_ik.py owns the IK benchmark)

ROBOTS = ("planar4", "arm7", "justin19")
SIMPLEX = "simplex:seed={seed},feasible=200"  # >= 200 of 1000 random configs free


def free_configs(robot: Any, world: Any, n: int, rng: np.random.Generator) -> np.ndarray:
    out = []
    for _ in range(100):
        q = sample_within_limits(robot, 4 * n, rng)
        out.append(q[collision.is_collision_free(jwarp.robot(robot), q, world)])
        if sum(map(len, out)) >= n:
            return np.concatenate(out)[:n]
    raise RuntimeError(f"fewer than {n} collision-free configurations of {robot.name} found")


# ====================================================================== sections
def bench_iteration(args: argparse.Namespace) -> dict:
    robot = jwarp.robot("justin19")
    world = parse_world_spec(SIMPLEX.format(seed=1), robot)
    rng = np.random.default_rng(0)
    q = free_configs(robot, world, 2 * max(args.paths, 1), rng)
    Q = path_feasibility.initial_paths(q[0::2], q[1::2], 20, "straight")
    n_sub = path_feasibility.substeps_for_voxel(robot, Q[:1], world.voxel_size)
    out = {"world_voxel_m": world.voxel_size, "n_substeps": n_sub, "waypoints": 20}
    for P in (1, args.paths):
        obj = PL.PathObjective(robot, world, P, 20, n_sub, device=args.device, dtype=np.float32)
        obj.set_paths(Q[:P])

        def one() -> None:
            obj.evaluate()
            obj.sub_max.numpy()  # the host read of the feasibility screen (a sync)
            obj.step(1e-4, 1e-3)

        t = timing.measure(one, args.device, args.min_time, args.repeats)
        out[f"iteration_ms_{P}_paths"] = t.figures(1e3)
        out[f"substep_configs_{P}_paths"] = obj.N
    return out


def bench_shelf_ik(args: argparse.Namespace) -> dict:
    """bench_ik.py's section c for :func:`jwarp.solvers.ik.ik` alone (CPU, float64)."""
    return shelf_ik(args.ik_targets, args.repeats, args.ik_starts, variants=("ik",))


def bench_feasibility(args: argparse.Namespace) -> dict:
    out = {}
    for name in args.robots:
        robot = jwarp.robot(name)
        rng = np.random.default_rng(2)
        hard, solved, single, tried, seed = 0, 0, [], 0, 0
        elapsed = timing.stopwatch()  # the study's duration, not a timed figure
        while hard < args.tasks and tried < 20 * args.tasks:
            world = parse_world_spec(SIMPLEX.format(seed=seed), robot)
            seed = world.meta["seed"] + 1  # the next distinct world (the spec searches up)
            q = free_configs(robot, world, 2 * 8, rng)
            for a, b in zip(q[0::2], q[1::2]):
                if hard >= args.tasks:
                    break
                tried += 1
                line = PL.plan(robot, world, a, b, start_kind="straight", iterations=50,
                               step=args.step, seed=None, fallback=None)
                if line.feasible[0]:
                    continue  # easy task
                hard += 1
                res = PL.plan(robot, world, a, b, start_kind="random", n_starts=args.starts,
                              iterations=50, step=args.step, seed=hard,
                              n_substeps=line.n_substeps, stop_when_solved=False,
                              fallback=None)
                solved += bool(res.feasible[0])
                single.append(res.all_feasible[0].mean())
        on_solved = [r for r in single if r > 0]
        out[name] = {"hard_tasks": hard, "tasks_tried": tried,
                     "solved_rate_multistart": solved / max(hard, 1),
                     "single_start_rate": float(np.mean(single)) if single else None,
                     # the thesis' figure: its dataset holds only tasks some start solved
                     "single_start_rate_solved_tasks": float(np.mean(on_solved))
                     if on_solved else None,
                     "starts": args.starts, "seconds": elapsed()}
    return out


def iteration(obj: Any) -> None:
    """One iteration of a filled objective's kernels: evaluate (+ a tiny step of a path)."""
    if isinstance(obj, PL.PathObjective):
        obj.evaluate()
        obj.step(1e-6, 1e-6)
    else:
        obj.evaluate_pose()
        obj.evaluate_aux()


def rigid_vs_elastic(args: argparse.Namespace, rigid: Any, elastic: Any) -> dict:
    """Seconds per :func:`iteration` of the rigid and the elastic objective, side by side
    (``--repeats`` rounds of >= ``--min-time`` s each): medians (``*_s``), bests
    (``*_best_s``) and the overhead of the torque update (elastic / rigid - 1) of both."""
    r, e = timing.side_by_side([lambda: iteration(rigid), lambda: iteration(elastic)],
                               args.device, args.min_time, rounds=args.repeats)
    return {"rigid_s": r.median, "elastic_s": e.median, "overhead": e.median / r.median - 1.0,
            "rigid_best_s": r.best, "elastic_best_s": e.best,
            "overhead_of_bests": e.best / r.best - 1.0, "rounds": r.runs}


def bench_compensation(args: argparse.Namespace) -> dict:
    robot = jwarp.robot("justin19")
    world = parse_world_spec(SIMPLEX.format(seed=1), robot)
    rng = np.random.default_rng(3)
    q = free_configs(robot, world, 2 * args.paths, rng)
    Q = path_feasibility.initial_paths(q[0::2], q[1::2], 20, "straight")
    n_sub = path_feasibility.substeps_for_voxel(robot, Q[:1], world.voxel_size)
    out: dict = {}
    for P in (1, args.paths):
        objs = [PL.PathObjective(robot, world, P, 20, n_sub, kappa=k, device=args.device)
                for k in (None, comp.JUSTIN_KAPPA)]
        for o in objs:
            o.set_paths(Q[:P])
        out[f"path_iteration_{P}_paths"] = rigid_vs_elastic(args, *objs)
    B = 64
    objs = [IK.IKObjective(robot, "right_tcp", B, world=world, kappa=k, device=args.device)
            for k in (None, comp.JUSTIN_KAPPA)]
    qs = sample_within_limits(robot, B, rng)
    T = jwarp.fk(robot, qs)[:, robot.frame_index("right_tcp")]
    for o in objs:
        o.set_q(qs)
        o.set_target(T)
    out[f"ik_iteration_{B}_configs"] = rigid_vs_elastic(args, *objs)
    # the whole solver iteration (kernels + host step), the figure a user of ik() sees
    out[f"ik_solver_iteration_{B}_starts"] = comp.ik_iteration_overhead(
        robot, "right_tcp", comp.JUSTIN_KAPPA, world=world, n_starts=B,
        rounds=3 if args.quick else 9, device=args.device)
    qt = sample_within_limits(robot, 4 * args.comp_targets, rng)
    qt = qt[collision.is_collision_free(robot, qt)][:args.comp_targets]
    T = jwarp.fk(robot, qt)[:, robot.frame_index("right_tcp")]
    limbs = np.full((robot.n_frames, 3), 20 * comp.JUSTIN_KAPPA) * robot.is_dh[:, None]
    torso = [i for i, f in enumerate(robot.frames) if f.name.startswith("torso")]
    limbs[torso] = comp.JUSTIN_KAPPA * robot.is_dh[torso, None]
    for label, kappa, lam in (("justin_1e-4", comp.JUSTIN_KAPPA, 0.7),
                              ("soft20x_2e-3_all_axes", 20 * comp.JUSTIN_KAPPA, 0.5),
                              ("soft20x_2e-3_limbs_only", limbs, 0.7),
                              ("soft20x_2e-3_theta_only", [0.0, 0.0, 20 * comp.JUSTIN_KAPPA], 0.7)):
        out[f"ik_convergence_{label}"] = comp.compare_ik(robot, "right_tcp", T, kappa, lam=lam,
                                                         n_starts=8, check_every=1,
                                                         iterations=400, device=args.device)
    return out


# ====================================================================== main
def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--device", default="cpu", help="cpu (default) or cuda[:N]")
    p.add_argument("--paths", type=int, default=None, help="paths at once (default 1000 on "
                   "CUDA, 100 on CPU)")
    p.add_argument("--tasks", type=int, default=None,
                   help="hard tasks per robot for the feasibility rate (100 = the full figure; "
                        "default 20)")
    p.add_argument("--starts", type=int, default=10, help="random multi-starts per hard task")
    p.add_argument("--step", type=float, default=0.2, help="OMP step size")
    p.add_argument("--robots", default=",".join(ROBOTS), help="robots of the feasibility study")
    p.add_argument("--ik-targets", type=int, default=20)
    p.add_argument("--ik-starts", type=int, default=16)
    p.add_argument("--comp-targets", type=int, default=10)
    p.add_argument("--min-time", type=float, default=0.3,
                   help="seconds of work per timed run (default 0.3; --quick 0.01)")
    p.add_argument("--repeats", type=int, default=5,
                   help="timed runs per figure, min/median (default 5; --quick 3)")
    timing.section_options(p, "iteration,ik,feasibility,compensation")
    args = p.parse_args(argv)
    init_warp()
    cuda = str(args.device).startswith("cuda")
    if args.paths is None:
        args.paths = 1000 if cuda else 100
    if args.tasks is None:
        args.tasks = 20
    args.robots = [r.strip() for r in args.robots.split(",") if r.strip()]
    if args.quick:
        args.paths, args.tasks, args.starts = min(args.paths, 4), 1, 3
        args.ik_targets, args.comp_targets, args.min_time, args.repeats = 2, 2, 0.01, 3
        args.robots = ["planar4"]
    sections = {"iteration": bench_iteration, "ik": bench_shelf_ik,
                "feasibility": bench_feasibility, "compensation": bench_compensation}
    timing.run_sections(p, sections, args,
                        f"min/median of {args.repeats} runs of >= {args.min_time:g} s",
                        min_time_s=args.min_time, repeats=args.repeats)
    return 0


if __name__ == "__main__":
    sys.exit(main())
