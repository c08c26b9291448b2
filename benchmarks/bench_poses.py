#!/usr/bin/env python
"""Measurement-pose sampling benchmark (thesis 2.4.3, elastic paper IV-C): candidates per
second of the constraint checks and the TSP ordering time.

    python benchmarks/bench_poses.py                          # CPU (one core: Warp's CPU
                                                              #   kernels run one thread)
    python benchmarks/bench_poses.py --device cuda            # CUDA, batch 1e7
    python benchmarks/bench_poses.py --quick                  # smoke-test sizes

Sections (``--only`` picks some):

* ``checks``: justin19 with the paper's tracker set-up: 6 tracker cameras in a ring
  2.5 m around the robot looking at it (70 deg cone, 0.5-6 m), a marker on each TCP,
  ``k_of_n`` 4, facing limit 60 deg, self-collision margin 2 cm (float32). One call =
  :meth:`PoseSampler.run_batch`: one launch drawing ``--batch`` candidates uniformly in the
  joint box on the device (Warp RNG), checking limits, visibility with occlusion rays
  against the 53 spheres and self-collision (early exit: cheap checks first), appending
  the accepted ones; the accepted rows and the verdict counts come back to the host.
  Figures: ms per call (min/median over ``--repeats`` runs), candidates/s of the median and
  of the best run, candidates inside the joint limits per second (the ones that reach FK
  and the visibility tests; justin19's coupled torso limit rejects about a third of the
  box), the acceptance and the verdict counts of one call (which check
  rejected how many).
* ``tsp``: :func:`order_poses` of ``--tsp-sizes`` poses sampled by the same sampler
  (LKH via elkai, 1 run): seconds (min/median) and the path length before/after (sum of
  the Euclidean joint distances and of the largest joint travel per move).
"""

import argparse
import math
import os
import sys
import time

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np
import warp as wp

wp.config.quiet = True

from jwarp.calibration.design.poses import CODE_NAMES, PoseOptions, PoseSampler
from jwarp.calibration.design.tour import order_poses
from jwarp.calibration.simulate.campaign import justin_tracker_setup
from jwarp.core.arrays import init_warp
from jwarp.plugins.registry import robot as get_robot

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))  # also when imported by path
import timing


def tracker_setup(n_cameras: int = 6):
    s = justin_tracker_setup()
    s.cameras = [{"name": f"c{i}", "pose": {"position": [2.5 * math.cos(a), 2.5 * math.sin(a),
                                                         2.2], "look_at": [0.3, 0.0, 1.0]},
                  "fov": 70.0, "range": [0.5, 6.0]}
                 for i, a in enumerate(np.linspace(-1.2, 1.2, n_cameras))]
    return s


def make_sampler(args: argparse.Namespace) -> PoseSampler:
    opt = PoseOptions(k_of_n=4, max_angle=60.0, margin=0.02, batch_size=args.batch,
                      device=args.device, seed=0)
    return PoseSampler(get_robot("justin19"), tracker_setup(), opt)


def checks(args: argparse.Namespace) -> dict:
    ps = make_sampler(args)
    seeds = iter(range(1, 1 << 30))
    t = timing.measure(lambda: ps.run_batch(args.batch, next(seeds)), args.device,
                       args.min_time, args.repeats)
    _, counts = ps.run_batch(args.batch, 12345)
    return {"batch": args.batch, "cameras": 6, "spheres": int(ps.model.spheres.n_spheres),
            "ms_per_call": t.figures(1e3),
            "candidates_per_s_median": args.batch / t.median,
            "candidates_per_s_best": args.batch / t.best,
            "inside_limits_per_s_median": (args.batch - int(counts[1])) / t.median,
            "acceptance": float(counts[0]) / args.batch,
            "counts": {nm: int(c) for nm, c in zip(CODE_NAMES, counts)}}


def tsp(args: argparse.Namespace) -> dict:
    ps = make_sampler(args)
    rows = []
    for n in args.tsp_sizes:
        q = ps.sample(n).q
        secs, res = [], None
        for _ in range(args.repeats):
            t0 = time.perf_counter()
            res = order_poses(q)
            secs.append(time.perf_counter() - t0)
        tm = timing.summarize(secs)
        rows.append({"poses": n, "s": tm.figures(), "solver": res.solver,
                     "length_before": res.before, "length_after": res.after,
                     "ratio_euclidean": res.after["euclidean"] / res.before["euclidean"],
                     "ratio_max": res.after["max"] / res.before["max"]})
    return {"rows": rows}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--device", default="cpu", help="cpu (default) or cuda[:N]")
    p.add_argument("--batch", type=int, default=None,
                   help="candidates per launch (CPU 65536, CUDA 10 000 000)")
    p.add_argument("--tsp-sizes", default="100,300", help="poses ordered (comma-separated)")
    p.add_argument("--min-time", type=float, default=0.5, help="seconds per timed run")
    p.add_argument("--repeats", type=int, default=5, help="runs (min/median)")
    timing.section_options(p, "checks,tsp")
    args = p.parse_args(argv)
    init_warp()
    if args.device == "cuda":
        args.device = "cuda:0"
    if args.batch is None:
        args.batch = 10_000_000 if str(args.device).startswith("cuda") else 1 << 16
    if args.quick:
        args.batch, args.tsp_sizes, args.min_time, args.repeats = 2048, "20", 0.01, 2
    args.tsp_sizes = [int(v) for v in str(args.tsp_sizes).split(",")]
    timing.run_sections(p, {"checks": checks, "tsp": tsp}, args,
                        f"{args.repeats} runs, min/median", repeats=args.repeats)
    return 0


if __name__ == "__main__":
    sys.exit(main())
