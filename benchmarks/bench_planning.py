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
  first feasible start) for justin19's right hand in a shelf-like world, per target.
* ``feasibility``: per robot (planar4, arm7, justin19) ``--tasks`` hard tasks (random
  collision-free start/goal in a random simplex world where the straight line is still
  infeasible after 50 iterations), then ``--starts`` random multi-starts (1-3 via points)
  for 50 iterations: fraction of tasks solved and of single starts feasible, over all hard
  tasks and over the tasks some start solved (the thesis' 50 % is of the latter kind: its
  dataset kept only solved tasks). Every task world is a distinct simplex world.
* ``compensation``: time per iteration rigid vs elastic (one torque update) for the
  justin19 path and an IK batch (its kernels, and the whole ``ik()`` iteration with the
  host step); iterations to converge of compensated IK for kappa =
  1e-4 and 20x softer (2e-3) rad/(N m) vs rigid, from the same seeds.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import sys
import time
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
from jwarp.world import collision  # noqa: E402
from jwarp.core.arrays import init_warp  # noqa: E402
from jwarp.solvers import compensation as comp  # noqa: E402
from jwarp.solvers import ik as IK  # noqa: E402
from jwarp.solvers import planner as PL  # noqa: E402
from jwarp.core.limits import sample_within_limits  # noqa: E402
from jwarp.world import shelf_world  # noqa: E402
from jwarp.world.io import parse_world_spec  # noqa: E402

ROBOTS = ("planar4", "arm7", "justin19")
FRAMES = {"planar4": "tcp", "arm7": "tcp", "justin19": "right_tcp"}
SIMPLEX = "simplex:seed={seed},feasible=200"  # >= 200 of 1000 random configs free


def timed(fn: Any, min_time: float, repeats: int = 3) -> float:
    """Best-of-``repeats`` mean seconds per call over runs of at least ``min_time``."""
    fn()
    best = math.inf
    for _ in range(repeats):
        n, t0 = 0, time.perf_counter()
        while True:
            fn()
            n += 1
            dt = time.perf_counter() - t0
            if dt >= min_time:
                break
        best = min(best, dt / n)
    return best


def free_configs(robot: Any, world: Any, n: int, rng: np.random.Generator) -> np.ndarray:
    out = []
    for _ in range(100):
        q = sample_within_limits(robot, 4 * n, rng)
        out.append(q[collision.is_collision_free(robot, q, world)])
        if sum(map(len, out)) >= n:
            return np.concatenate(out)[:n]
    raise RuntimeError(f"fewer than {n} collision-free configurations of {robot.name} found")


# ====================================================================== sections
def bench_iteration(args: argparse.Namespace) -> dict:
    robot = jwarp.robot("justin19")
    world = parse_world_spec(SIMPLEX.format(seed=1), robot)
    rng = np.random.default_rng(0)
    q = free_configs(robot, world, 2 * max(args.paths, 1), rng)
    Q = PL.initial_paths(q[0::2], q[1::2], 20, "straight")
    n_sub = PL.substeps_for_voxel(robot, Q[:1], world.voxel_size)
    out = {"world_voxel_m": world.voxel_size, "n_substeps": n_sub, "waypoints": 20}
    for P in (1, args.paths):
        sync = (lambda: wp.synchronize_device(args.device))
        obj = PL.PathObjective(robot, world, P, 20, n_sub, device=args.device, dtype=np.float32)
        obj.set_paths(Q[:P])

        def one() -> None:
            obj.evaluate()
            obj.sub_max.numpy()  # the host read of the feasibility screen (a sync)
            obj.step(1e-4, 1e-3)

        def many() -> None:
            for _ in range(10):
                one()
            sync()

        t = timed(many, args.min_time) / 10
        out[f"iteration_ms_{P}_paths"] = 1e3 * t
        out[f"substep_configs_{P}_paths"] = obj.N
    return out


def bench_ik(args: argparse.Namespace) -> dict:
    from scipy.spatial.transform import Rotation

    robot = jwarp.robot("justin19")
    world = shelf_world()
    rng = np.random.default_rng(1)
    times, iters, ok = [], [], []
    for k in range(args.ik_targets):
        # grasp poses between the boards, hand pointing into the shelf (+x) with noise
        p = [rng.uniform(0.5, 0.62), rng.uniform(-0.5, 0.1), rng.uniform(0.72, 0.88)]
        r = (Rotation.from_euler("y", 90, degrees=True)
             * Rotation.from_rotvec(rng.normal(scale=0.15, size=3))).as_rotvec()
        T = IK.pose_matrix(p, r)
        if k == 0:  # warm-up (kernel compiles)
            IK.ik(robot, "right_tcp", T, world=world, n_starts=args.ik_starts, margin=0.01)
        res = IK.ik(robot, "right_tcp", T, world=world, n_starts=args.ik_starts, margin=0.01,
                    seed=k)
        times.append(res.wall_time)
        iters.append(int(res.iterations))
        ok.append(bool(res.feasible))
    t = np.array(times)
    ok = np.array(ok)
    return {"targets": len(t), "starts": args.ik_starts, "feasible_rate": float(ok.mean()),
            "time_ms_median": 1e3 * float(np.median(t)), "time_ms_mean": 1e3 * float(t.mean()),
            "time_ms_median_feasible": 1e3 * float(np.median(t[ok])) if ok.any() else None,
            "iterations_median": float(np.median(iters))}


def bench_feasibility(args: argparse.Namespace) -> dict:
    out = {}
    for name in args.robots:
        robot = jwarp.robot(name)
        rng = np.random.default_rng(2)
        hard, solved, single, tried, seed = 0, 0, [], 0, 0
        t0 = time.perf_counter()
        while hard < args.tasks and tried < 20 * args.tasks:
            world = parse_world_spec(SIMPLEX.format(seed=seed), robot)
            seed = world.meta["seed"] + 1  # the next distinct world (the spec searches up)
            q = free_configs(robot, world, 2 * 8, rng)
            for a, b in zip(q[0::2], q[1::2]):
                if hard >= args.tasks:
                    break
                tried += 1
                line = PL.plan(robot, world, a, b, initial="straight", iterations=50,
                               step=args.step, seed=None)
                if line.feasible[0]:
                    continue  # easy task
                hard += 1
                res = PL.plan(robot, world, a, b, initial="random", n_starts=args.starts,
                              iterations=50, step=args.step, seed=hard,
                              n_substeps=line.n_substeps)
                solved += bool(res.feasible[0])
                single.append(res.all_feasible[0].mean())
        on_solved = [r for r in single if r > 0]
        out[name] = {"hard_tasks": hard, "tasks_tried": tried,
                     "solved_rate_multistart": solved / max(hard, 1),
                     "single_start_rate": float(np.mean(single)) if single else None,
                     # the thesis' figure: its dataset holds only tasks some start solved
                     "single_start_rate_solved_tasks": float(np.mean(on_solved))
                     if on_solved else None,
                     "starts": args.starts, "seconds": time.perf_counter() - t0}
    return out


def bench_compensation(args: argparse.Namespace) -> dict:
    robot = jwarp.robot("justin19")
    world = parse_world_spec(SIMPLEX.format(seed=1), robot)
    rng = np.random.default_rng(3)
    q = free_configs(robot, world, 2 * args.paths, rng)
    Q = PL.initial_paths(q[0::2], q[1::2], 20, "straight")
    n_sub = PL.substeps_for_voxel(robot, Q[:1], world.voxel_size)
    out: dict = {}
    for P in (1, args.paths):
        objs = [PL.PathObjective(robot, world, P, 20, n_sub, kappa=k, device=args.device)
                for k in (None, comp.JUSTIN_KAPPA)]
        for o in objs:
            o.set_paths(Q[:P])
        out[f"path_iteration_{P}_paths"] = comp.iteration_overhead(*objs, repeats=args.repeats)
    B = 64
    objs = [IK.IKObjective(robot, "right_tcp", B, world=world, kappa=k, device=args.device)
            for k in (None, comp.JUSTIN_KAPPA)]
    qs = sample_within_limits(robot, B, rng)
    T = jwarp.fk(robot, qs)[:, robot.frame_index("right_tcp")]
    for o in objs:
        o.set_q(qs)
        o.set_target(T)
    out[f"ik_iteration_{B}_configs"] = comp.iteration_overhead(*objs, repeats=args.repeats)
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
                                                         max_iterations=400, device=args.device)
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
    p.add_argument("--min-time", type=float, default=0.3)
    p.add_argument("--repeats", type=int, default=100)
    p.add_argument("--only", default="iteration,ik,feasibility,compensation")
    p.add_argument("--quick", action="store_true", help="tiny sizes (smoke test)")
    p.add_argument("--json", default=None, metavar="FILE", help="also write the figures as JSON")
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
    sections = {"iteration": bench_iteration, "ik": bench_ik,
                "feasibility": bench_feasibility, "compensation": bench_compensation}
    result: dict = {"device": str(args.device), "machine": platform.processor() or platform.machine(),
                    "warp": wp.config.version}
    for name in [s.strip() for s in args.only.split(",") if s.strip()]:
        if name not in sections:
            p.error(f"--only: unknown section '{name}' (known: {', '.join(sections)})")
        t0 = time.perf_counter()
        result[name] = sections[name](args)
        print(f"== {name} ({time.perf_counter() - t0:.1f} s)")
        print(json.dumps(result[name], indent=1, default=float))
        sys.stdout.flush()
    if args.json:
        from jwarp.atomic import atomic_write_text

        atomic_write_text(args.json, json.dumps(result, indent=1, default=float) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
