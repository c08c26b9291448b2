#!/usr/bin/env python
"""BPS encoding benchmark: :meth:`jwarp.learn.bps.BasisPointSet.encode` of 1 and 64 worlds
at 1024 and 4096 basis points, beside the per-world :func:`jwarp.world.sdf_query` loop.

    python benchmarks/bench_bps.py                     # CPU
    python benchmarks/bench_bps.py --device cuda       # CUDA
    python benchmarks/bench_bps.py --quick             # smoke-test sizes

Sections (``--only`` picks some):

* ``2d``: planar5, basis points in its reach (:func:`jwarp.learn.bps.basis_points`), worlds
  = simplex worlds on the grid of ``feasible_simplex_world("planar5")`` (63 x 64 cells).
* ``3d``: justin19, worlds = simplex worlds on the grid of the shelf
  (:func:`jwarp.world.scenes.shelf_world`, 41 x 51 x 41 cells, 4 cm), the shelf first.

Rows per (worlds W, points N): ``encode`` (numpy out: the whole call, grids handed to the
device, one launch, result back on the host), ``encode_torch_out`` (into a preallocated torch
tensor on the device, zero-copy) and ``sdf_query_loop`` (the baseline: one
:func:`jwarp.world.sdf_query` per world), timed side by side (:func:`timing.side_by_side`:
interleaved rounds, each round back-to-back calls for ``--min-time`` s closed by a device
sync); figures in ms per call (min/median over the rounds), plus the encoded values per
second of the median and the speedup over the baseline (of the medians).
"""

import argparse
import os
import sys
from typing import Any

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np
import warp as wp

wp.config.quiet = True

from jwarp.core.arrays import init_warp
from jwarp.learn.bps import basis_points
from jwarp.world.feasibility import robot_world_grid
from jwarp.world.scenes import shelf_world
from jwarp.world.sdf import sdf_query
from jwarp.world.simplex import simplex_world

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))  # also when imported by path
import timing


def worlds_2d(n: int) -> list:
    shape, limits, _ = robot_world_grid("planar5")
    return [simplex_world(2, seed=s, shape=shape, limits=limits) for s in range(n)]


def worlds_3d(n: int) -> list:
    shelf = shelf_world()
    return [shelf] + [simplex_world(3, seed=s, shape=shelf.shape, limits=shelf.limits)
                      for s in range(1, n)]


def section(args: argparse.Namespace, robot: str, make_worlds: Any) -> dict:
    import torch

    dev = wp.get_device(args.device)
    tdev = f"cuda:{dev.ordinal}" if dev.is_cuda else "cpu"
    all_worlds = make_worlds(max(args.worlds))
    out: dict = {"robot": robot, "grid": list(all_worlds[0].shape), "rows": []}
    for n in args.points:
        bps = basis_points(robot, n)
        for w in args.worlds:
            ws = all_worlds[:w]
            buf = torch.empty((w, bps.size), dtype=torch.float32, device=tdev)
            fns = [lambda: bps.encode(ws, device=dev),
                   lambda: bps.encode(ws, out=buf),
                   lambda: [sdf_query(x, bps.points, device=dev) for x in ws]]
            if args.no_baseline:
                fns = fns[:2]
            t = timing.side_by_side(fns, dev, args.min_time, args.repeats)
            err = float(np.abs(bps.encode(ws, device=dev)
                               - np.stack([sdf_query(x, bps.points) for x in ws])).max())
            row = {"worlds": w, "points": bps.size, "n_points": n,
                   "encode_ms": t[0].figures(1e3), "encode_torch_out_ms": t[1].figures(1e3),
                   "values_per_s_median": w * bps.size / t[0].median,
                   "max_abs_diff_vs_sdf_query": err}
            if not args.no_baseline:
                row["sdf_query_loop_ms"] = t[2].figures(1e3)
                row["speedup_vs_sdf_query_loop"] = t[2].median / t[0].median
            out["rows"].append(row)
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--device", default="cpu", help="cpu (default) or cuda[:N]")
    p.add_argument("--points", default="1024,4096", help="basis point counts (comma-separated)")
    p.add_argument("--worlds", default="1,64", help="worlds per call (comma-separated)")
    p.add_argument("--min-time", type=float, default=0.2, help="seconds per timed run")
    p.add_argument("--repeats", type=int, default=5, help="interleaved rounds (min/median)")
    p.add_argument("--no-baseline", action="store_true", help="skip the sdf_query loop")
    timing.section_options(p, "2d,3d")
    args = p.parse_args(argv)
    init_warp()
    if args.device == "cuda":
        args.device = "cuda:0"
    if args.quick:
        args.points, args.worlds, args.min_time, args.repeats = "256", "1,4", 0.01, 2
    args.points = [int(v) for v in str(args.points).split(",")]
    args.worlds = [int(v) for v in str(args.worlds).split(",")]
    sections = {"2d": lambda a: section(a, "planar5", worlds_2d),
                "3d": lambda a: section(a, "justin19", worlds_3d)}
    timing.run_sections(p, sections, args, f"{args.repeats} rounds side by side, ms per call "
                        f"(min/median)", repeats=args.repeats)
    return 0


if __name__ == "__main__":
    sys.exit(main())
