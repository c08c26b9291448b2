#!/usr/bin/env python
"""Hard-task label generation (thesis 3.5.1, Table 3.2): fidelity and speed of
:func:`jwarp.learn.plan_data.label_world`.

    python benchmarks/bench_plan_data.py                          # CPU, default sizes
    python benchmarks/bench_plan_data.py --device cuda --only speed --tasks 256
    python benchmarks/bench_plan_data.py --quick                  # smoke-test sizes

Sections (``--only`` picks some):

* ``fidelity``: per robot (planar4, arm7, justin19) ``--worlds`` Table 3.2 worlds
  (:func:`world_for`, or the robot-reach grid with ``--world reach``), ``--tasks`` random
  tasks each, labelled with ``--starts`` multi-starts: the single-start feasibility of
  the random multi-starts on hard tasks (over the tasks some start solved: the thesis'
  dataset holds only those; and over every hard task), the hard/solved counts and the
  average U_l (eq. 3.5) of the labels, side by side with Table 3.2 (32.6 / 54.5 / 44.1 %,
  U_path 1.71 / 1.55 / 1.48).
* ``speed``: labelled (feasible) hard paths per second of ``label_world`` for
  ``--speed-robot`` (default justin19) on ``--device`` (the whole call: task sampling,
  straight lines, multi-starts, checks). Warp runs CPU kernels on one thread, so the CPU
  figure is one core (thesis: 8.4 s per justin19 path per core).
"""

from __future__ import annotations

import argparse
import os
import sys

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402
import warp as wp  # noqa: E402

if hasattr(wp.config, "quiet"):
    wp.config.quiet = True

import jwarp
from jwarp.core.arrays import init_warp  # noqa: E402
from jwarp.learn.plan_data import PlanDataOptions, label_world, world_for  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import timing  # noqa: E402  (benchmarks/timing.py, beside this script)

ROBOTS = ("planar4", "arm7", "justin19")
#: Table 3.2: Avg. Feas. phi [%] and Avg. U_path of the labels
THESIS = {"planar4": (32.6, 1.7136), "arm7": (54.5, 1.551), "justin19": (44.1, 1.483)}


def options(args: argparse.Namespace) -> PlanDataOptions:
    return PlanDataOptions(max_starts=args.starts, iterations=args.iterations, step=args.step,
                           device=args.device,
                           stats_tasks=None if args.stats_tasks < 0 else args.stats_tasks,
                           substep_voxels=args.substep_voxels)


def make_world(robot: str, seed: int, args: argparse.Namespace):
    return world_for(jwarp.robot(robot), seed, device=args.device,
                     extent=None if args.world == "table" else "reach",
                     frequency=args.frequency, threshold=args.threshold)


def bench_fidelity(args: argparse.Namespace) -> dict:
    out = {}
    o = options(args)
    for name in args.robots:
        elapsed = timing.stopwatch()
        tasks = hard = solved = stats_tasks = 0
        rates_solved, rates_all, lengths = [], [], []
        for k in range(args.worlds):
            world = make_world(name, 1000 * k, args)
            lab = label_world(jwarp.robot(name), world, args.tasks, k, o)
            tasks += len(lab)
            h = lab.hard
            hard += int(h.sum())
            solved += int((h & lab.feasible).sum())
            st = h & lab.stats  # the tasks whose multi-starts all ran (stats_tasks)
            stats_tasks += int(st.sum())
            r = lab.n_feasible_starts[st] / np.maximum(lab.n_starts[st], 1)
            rates_all += list(r)
            rates_solved += list(r[lab.feasible[st]])
            lengths += list(lab.length_cost[h & lab.feasible])
        phi, u = THESIS.get(name, (None, None))
        fig = {"worlds": args.worlds, "world": args.world, "frequency": args.frequency,
               "threshold": args.threshold,
               "tasks": tasks, "hard": hard,
               "hard_solved": solved, "starts": args.starts,
               "statistics_tasks": stats_tasks,
               "single_start_rate_solved_pct": 100 * float(np.mean(rates_solved))
               if rates_solved else None,
               "single_start_rate_all_hard_pct": 100 * float(np.mean(rates_all))
               if rates_all else None,
               "avg_label_length_cost": float(np.mean(lengths)) if lengths else None,
               "thesis_feasible_pct": phi, "thesis_avg_upath": u, "seconds": elapsed()}
        out[name] = fig
        print(f"  {name}: single-start feasible {fig['single_start_rate_solved_pct']} % "
              f"(thesis {phi} %), avg U_l {fig['avg_label_length_cost']} (thesis {u}); "
              f"hard {hard}/{tasks}, solved {solved}", flush=True)
    return out


def bench_speed(args: argparse.Namespace) -> dict:
    o = options(args)
    name = args.speed_robot
    world = make_world(name, 0, args)
    label_world(jwarp.robot(name), world, 2, 99, PlanDataOptions(max_starts=2, iterations=2,
                                                    device=args.device))  # compile, warm up
    wp.synchronize_device(args.device)
    runs = []
    for r in range(args.repeats):
        elapsed = timing.stopwatch()
        lab = label_world(jwarp.robot(name), world, args.tasks, r, o)
        wp.synchronize_device(args.device)
        t = elapsed()
        n = int((lab.hard & lab.feasible).sum())
        runs.append({"seconds": t, "labelled_hard": n, "hard": int(lab.hard.sum()),
                     "tasks": len(lab), "hard_paths_per_s": n / t})
    rates = [x["hard_paths_per_s"] for x in runs]
    return {"robot": name, "device": str(args.device), "tasks": args.tasks,
            "starts": args.starts, "iterations": args.iterations, "runs": runs,
            "hard_paths_per_s": {"min": min(rates), "median": float(np.median(rates))},
            "thesis_s_per_path_per_core": 8.4 if name == "justin19" else None}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--device", default="cpu", help="cpu (default) or cuda[:N]")
    p.add_argument("--robots", default=",".join(ROBOTS), help="robots of the fidelity study")
    p.add_argument("--worlds", type=int, default=4, help="worlds per robot (fidelity)")
    p.add_argument("--tasks", type=int, default=16, help="tasks per world")
    p.add_argument("--starts", type=int, default=20, help="multi-starts per hard task")
    p.add_argument("--iterations", type=int, default=300)
    p.add_argument("--step", type=float, default=0.01)
    p.add_argument("--world", choices=("table", "reach"), default="table",
                   help="Table 3.2 worlds (world_for) or grids fitted to the robot's reach")
    p.add_argument("--frequency", type=float, default=2.0,
                   help="simplex noise periods across the world (2: the simplex default)")
    p.add_argument("--threshold", type=float, default=0.6,
                   help="simplex occupancy threshold (lower: more obstacles; 0.6 the default)")
    p.add_argument("--stats-tasks", type=int, default=32,
                   help="hard tasks per call that run every start (the single-start "
                        "statistics); the others stop once `refine` starts are feasible; "
                        "-1: all (every start of every task runs)")
    p.add_argument("--substep-voxels", type=float, default=3.0,
                   help="the most a sphere travels between cost substeps, in voxels")
    p.add_argument("--speed-robot", default="justin19")
    p.add_argument("--repeats", type=int, default=3, help="timed runs of the speed section")
    timing.section_options(p, "fidelity,speed")
    args = p.parse_args(argv)
    init_warp()
    args.robots = [r.strip() for r in args.robots.split(",") if r.strip()]
    if args.quick:
        args.worlds, args.tasks, args.starts, args.iterations = 1, 3, 3, 20
        args.robots, args.speed_robot, args.repeats = ["planar4"], "planar4", 2
    sections = {"fidelity": bench_fidelity, "speed": bench_speed}
    timing.run_sections(p, sections, args, f"{args.repeats} speed runs", repeats=args.repeats)
    return 0


if __name__ == "__main__":
    sys.exit(main())
