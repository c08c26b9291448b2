#!/usr/bin/env python
"""The collision cost per launch: the fused kernel (one thread per configuration) against
the wide launches (:mod:`jwarp.kernels.collision_wide`), side by side in one run.

    python benchmarks/bench_cost_kernel.py                       # CPU, small sizes
    python benchmarks/bench_cost_kernel.py --device cuda         # the sizes of the issue
    python benchmarks/bench_cost_kernel.py --quick               # smoke test

Cases (``--cases`` picks some):

* ``justin19``: Agile Justin in its Table 3.2 world (:func:`jwarp.learn.plan_data.world_for`,
  seed 0: a simplex grid), at the batch sizes of ``--justin-batches`` (labelling launches
  hold 1e5-1e6 substep configurations);
* ``arm7``: the 7-DoF arm in its Table 3.2 world;
* ``panda``: the fitted Panda sphere model (``--panda``: a robot JSON; else the fit of
  ``benchmarks/scene_problems.py``, which needs example-robot-data and trimesh) in the
  table-and-bookshelf scene of exact primitives of ``bench_ik_converge.py``, at 400
  configurations (an IK batch of 100 targets x 4 seeds).

Configurations: ``random`` uniform within the limits (most touch something: the expensive
case) and ``near`` = random configurations pulled half way to a collision-free one (the
mix a planner's substeps see). Each row: the cost and gradient of
:meth:`jwarp.world.collision.CollisionModel.cost` on preallocated outputs (the planner's
call), the two variants interleaved (:func:`timing.side_by_side`), min and median ms per
launch, the ratio fused / wide, and the largest difference of cost and gradient relative to
their largest magnitude.
"""

from __future__ import annotations

import argparse
import os
import sys
from typing import Any

import numpy as np
import warp as wp

wp.config.quiet = True

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import timing  # noqa: E402  (benchmarks/timing.py, beside this script)

import jwarp
from jwarp.core.arrays import init_warp  # noqa: E402
from jwarp.plugins.registry import robot as get_robot  # noqa: E402
from jwarp.world import random_configurations  # noqa: E402
from jwarp.world.collision import CollisionModel, is_collision_free  # noqa: E402


def configurations(robot: Any, world: Any, n: int, kind: str, seed: int,
                   device: Any) -> np.ndarray:
    q = random_configurations(robot, n, seed)
    if kind == "random":
        return q
    pool = random_configurations(robot, 4000, seed + 1)
    free = pool[is_collision_free(jwarp.robot(robot), pool, world, device=device)]
    if not len(free):
        return q
    pick = free[np.random.default_rng(seed).integers(0, len(free), n)]
    return 0.5 * (q + pick)


def panda_case(path: str | None) -> tuple[Any, Any]:
    import scene_problems as sp

    from jwarp.world.scene_file import exact_world, scene_from_dict

    robot = get_robot(path) if path else sp.load_robot()[0]
    objects, _, _ = sp.FAMILIES["bookshelf_small"](np.random.default_rng(7))
    table, _, _ = sp.FAMILIES["table_pick"](np.random.default_rng(8))
    table = [dict(o, id=f"t_{o['id']}") for o in table]
    scene = scene_from_dict({"world": {"collision_objects": objects + table}}, source="bench")
    return robot, exact_world(scene)


def row(robot: Any, world: Any, n: int, kind: str, args: argparse.Namespace) -> dict:
    dt = np.float32 if args.dtype == "float32" else np.float64
    scalar = wp.float32 if dt == np.float32 else wp.float64
    q = configurations(robot, world, n, kind, seed=n, device=args.device)
    qa = wp.array(q.astype(dt), dtype=scalar, device=args.device)
    out = {}
    calls = []
    for wide in (False, True):
        cm = CollisionModel(jwarp.robot(robot), world, device=args.device, dtype=dt, wide=wide)
        data = cm.make_data(n)
        c, g = cm.cost(qa, data=data, out_cost=data.cost, out_grad=data.grad)
        out[wide] = (c.numpy().copy(), g.numpy().copy())
        calls.append(lambda cm=cm, data=data: cm.cost(qa, data=data, out_cost=data.cost,
                                                      out_grad=data.grad))
    t_fused, t_wide = timing.side_by_side(calls, args.device, args.min_time, args.rounds)
    (c0, g0), (c1, g1) = out[False], out[True]
    fig = {"robot": robot.name, "configurations": n, "kind": kind,
           "spheres": int(CollisionModel(jwarp.robot(robot), world, device=args.device, dtype=dt).n_spheres),
           "touching_pct": 100.0 * float((c0 > 0).mean()),
           "fused_ms": {"min": 1e3 * t_fused.best, "median": 1e3 * t_fused.median},
           "wide_ms": {"min": 1e3 * t_wide.best, "median": 1e3 * t_wide.median},
           "speedup_min": t_fused.best / t_wide.best,
           "speedup_median": t_fused.median / t_wide.median,
           "cost_diff_rel": float(np.abs(c0 - c1).max() / max(np.abs(c0).max(), 1e-30)),
           "grad_diff_rel": float(np.abs(g0 - g1).max() / max(np.abs(g0).max(), 1e-30))}
    print(f"  {robot.name:>9} {kind:>6} N={n:>8}: fused {fig['fused_ms']['min']:9.3f} / "
          f"{fig['fused_ms']['median']:9.3f} ms, wide {fig['wide_ms']['min']:9.3f} / "
          f"{fig['wide_ms']['median']:9.3f} ms, x{fig['speedup_min']:.1f} (min) "
          f"x{fig['speedup_median']:.1f} (median); diff cost {fig['cost_diff_rel']:.1e} grad "
          f"{fig['grad_diff_rel']:.1e}", flush=True)
    return fig


def bench(args: argparse.Namespace) -> dict:
    from jwarp.learn.plan_data import world_for

    rows = []
    for case in args.cases:
        if case == "panda":
            robot, world = panda_case(args.panda)
            sizes = args.panda_batches
        else:
            robot, world = get_robot(case), world_for(jwarp.robot(case), 0, device=args.device)
            sizes = args.justin_batches if case == "justin19" else args.arm_batches
        for n in sizes:
            for kind in ("random", "near"):
                rows.append(row(robot, world, n, kind, args))
    return {"dtype": args.dtype, "rows": rows}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--device", default="cpu", help="cpu (default) or cuda[:N]")
    p.add_argument("--dtype", choices=("float32", "float64"), default="float32")
    p.add_argument("--cases", default="justin19,arm7,panda")
    p.add_argument("--panda", default=None, metavar="JSON", help="the fitted Panda robot file")
    p.add_argument("--justin-batches", default=None, help="comma-separated batch sizes")
    p.add_argument("--arm-batches", default=None)
    p.add_argument("--panda-batches", default="400")
    p.add_argument("--min-time", type=float, default=0.2)
    p.add_argument("--rounds", type=int, default=5)
    timing.section_options(p, "cost")
    args = p.parse_args(argv)
    init_warp()
    cuda = str(args.device).startswith("cuda")
    defaults = ("2000,20000,200000,1000000", "20000,200000") if cuda else ("200,2000", "2000")
    ints = lambda s: [int(x) for x in s.split(",") if x.strip()]  # noqa: E731
    args.justin_batches = ints(args.justin_batches or defaults[0])
    args.arm_batches = ints(args.arm_batches or defaults[1])
    args.panda_batches = ints(args.panda_batches)
    args.cases = [c.strip() for c in args.cases.split(",") if c.strip()]
    if args.quick:
        args.justin_batches, args.arm_batches, args.panda_batches = [64], [64], [64]
        args.cases = [c for c in args.cases if c != "panda"]
        args.min_time, args.rounds = 0.01, 2
    timing.run_sections(p, {"cost": bench}, args, f"{args.rounds} interleaved rounds")
    return 0


if __name__ == "__main__":
    sys.exit(main())
