#!/usr/bin/env python
"""Throughput of the collision kernels (configurations per second).

Times :meth:`jwarp.world.collision.CollisionModel.cost` (world + self-collision cost, with and
without the hand-written gradient, one launch on preallocated Warp arrays, the way a
planner calls it in its loop), the ``wp.Tape`` gradient for comparison, and the
minimum-distance kernel of the feasibility checks, and prints one fixed-width table.

    python benchmarks/bench_collision.py                     # CPU
    python benchmarks/bench_collision.py --device cuda       # CUDA (or --device all)
    python benchmarks/bench_collision.py --quick             # smoke-test sizes

Worlds: the default feasible simplex world of each robot (``feasible_simplex_world(robot,
seed=0)``: at least 200 of 1000 random configurations collision-free, 64 cells along
the longest axis). Configurations: ``random`` = uniform within the joint limits (most of
them touch the world or the robot itself: the expensive case), ``free`` = only those
whose spheres all keep eps = 5 cm from the world and from each other (every sphere is
checked, nothing contributes: cost 0).
Each row warms up (compiles), then repeats back-to-back calls for at least ``--min-time``
seconds, closed by a device sync, ``--repeats`` times; the median is shown. The
``us/config`` column is the time per call divided by the batch size; ``path ms`` is the
time for a batch of ``--path-configs`` configurations (one 20-waypoint path with its
substeps) at that rate. CPU runs use one thread (Warp runs CPU kernels serially).
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable
from typing import Any

import numpy as np
import warp as wp

wp.config.quiet = True
if hasattr(wp, "LOG_WARNING") and hasattr(wp.config, "log_level"):
    wp.config.log_level = max(wp.config.log_level, wp.LOG_WARNING)

import timing  # noqa: E402

from jwarp.core.arrays import init_warp  # noqa: E402
from jwarp.plugins.registry import robot as get_robot  # noqa: E402
from jwarp.world import feasible_simplex_world, random_configurations  # noqa: E402
from jwarp.world.collision import DEFAULT_EPS, CollisionModel, is_collision_free  # noqa: E402

FULL = dict(cpu=(200, 10_000), cuda=(1_000, 200_000), min_time=0.3, repeats=5, tape_batch=1_000)
QUICK = dict(cpu=(50,), cuda=(1_000,), min_time=0.01, repeats=2, tape_batch=50)


def measure(fn: Callable[[], Any], device: Any, min_time: float, repeats: int) -> tuple[float, float]:
    """(median, best) seconds per call (:func:`timing.measure`)."""
    t = timing.measure(fn, device, min_time, repeats)
    return t.median, t.best


def configurations(model: Any, world: Any, n: int, kind: str, device: Any, seed: int = 0) -> np.ndarray:
    if kind == "random":
        return random_configurations(model, n, seed)
    pool = random_configurations(model, max(4 * n, 2000), seed)
    # margin eps: every sphere beyond the clip's reach, so the cost is exactly 0
    free = pool[is_collision_free(model, pool, world, DEFAULT_EPS, device=device, dtype=np.float64)]
    if len(free) == 0:
        raise RuntimeError("no collision-free configuration found")
    return free[np.arange(n) % len(free)]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--device", default="cpu", choices=["cpu", "cuda", "all"])
    ap.add_argument("--dtype", default="float32", choices=["float32", "float64"])
    ap.add_argument("--robots", default="justin19,arm7,planar4")
    ap.add_argument("--batches", default=None, help="comma-separated batch sizes (all devices)")
    ap.add_argument("--path-configs", type=int, default=200,
                    help="configurations of one path (20 waypoints with substeps) for 'path ms'")
    ap.add_argument("--min-time", type=float, default=None)
    ap.add_argument("--repeats", type=int, default=None)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--no-tape", action="store_true")
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv)
    cfg = dict(QUICK if args.quick else FULL)
    if args.min_time is not None:
        cfg["min_time"] = args.min_time
    if args.repeats is not None:
        cfg["repeats"] = args.repeats
    init_warp()
    devices = ["cpu", "cuda"] if args.device == "all" else [args.device]
    if "cuda" in devices and not wp.is_cuda_available():
        if args.device == "cuda":
            print("CUDA not available", file=sys.stderr)
            return 2
        devices.remove("cuda")
    dtype = np.float32 if args.dtype == "float32" else np.float64
    rows: list[dict] = []
    print(f"# jwarp collision kernels, {args.dtype}, {timing.machine()}, "
          f"warp {wp.config.version}")
    header = f"{'device':<7}{'robot':<10}{'S':>4}{'P':>5}{'configs':<8}{'op':<11}{'batch':>8}" \
             f"{'ms/call':>10}{'us/config':>11}{'Mconfig/s':>11}{'path ms':>9}"
    print(header)
    print("-" * len(header))
    for dev_name in devices:
        dev = wp.get_device(dev_name)
        batches = [int(b) for b in args.batches.split(",")] if args.batches else cfg[dev_name]
        for name in args.robots.split(","):
            model = get_robot(name)
            world = feasible_simplex_world(model, seed=0, device=dev)
            cm = CollisionModel(model, world, device=dev, dtype=dtype)
            for kind in ("random", "free"):
                for n in batches:
                    qn = configurations(model, world, n, kind, dev)
                    q = wp.array(qn.astype(dtype), dtype=cm.scalar, device=dev)
                    cost = wp.empty(n, dtype=cm.scalar, device=dev)
                    grad = wp.empty((n, model.n_dof), dtype=cm.scalar, device=dev)
                    ops: dict[str, Callable[[], Any]] = {
                        "cost": lambda: cm.cost(q, grad=False, out_cost=cost),
                        "cost+grad": lambda: cm.cost(q, out_cost=cost, out_grad=grad),
                        "min dist": lambda: cm.distances(q),
                    }
                    if not args.no_tape and n <= cfg["tape_batch"]:
                        ops["tape grad"] = lambda: cm.cost_tape(q)
                    for op, fn in ops.items():
                        med, best = measure(fn, dev, cfg["min_time"], cfg["repeats"])
                        per = med / n
                        row = dict(device=dev_name, robot=name, spheres=cm.n_spheres,
                                   pairs=cm.n_pairs, configs=kind, op=op, batch=n,
                                   ms_per_call=med * 1e3, best_ms_per_call=best * 1e3,
                                   us_per_config=per * 1e6, configs_per_s=1.0 / per,
                                   path_ms=per * args.path_configs * 1e3,
                                   colliding=float((cost.numpy()[:n] > 0).mean()) if op.startswith("cost") else None)
                        rows.append(row)
                        print(f"{dev_name:<7}{name:<10}{cm.n_spheres:>4}{cm.n_pairs:>5} {kind:<7}{op:<11}"
                              f"{n:>8}{med * 1e3:>10.3f}{per * 1e6:>11.3f}{1e-6 / per:>11.3f}"
                              f"{per * args.path_configs * 1e3:>9.3f}", flush=True)
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(dict(rows=rows, settings=vars(args), config=cfg), fh, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
