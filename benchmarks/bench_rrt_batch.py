#!/usr/bin/env python
"""The RRT-Connect fallback for a whole batch (issue 45 item 2): one problem after another
(``rrt_connect`` per problem in its own world) against all at once (``rrt_connect_batch``
over one ``World.batch`` of the problems' exact worlds), side by side in one run; then,
optionally, a :class:`jwarp.solvers.planning.Planner` over the whole batch with
``fallback="rrt"`` before (``planner.FALLBACK_BATCH = False``) and after. A script
printing figures, never a timed test.

    python benchmarks/scene_problems.py --out /tmp/p45b --per-family 10 --seed 7
    python benchmarks/bench_rrt_batch.py --problems /tmp/p45b
    python benchmarks/bench_rrt_batch.py --problems /tmp/p45b --planner --time-limit 5

Both runs give problem b the same generator (``rrt.problem_rngs``), so the loop and the
batch grow the same trees: their paths are identical (printed: ``same paths``) and the
difference is the time alone. Every path is re-checked edge by edge by ``path_feasible``
in the problem's own world. One untimed warm-up of both first (kernel compilation).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402
import warp as wp  # noqa: E402

if hasattr(wp.config, "quiet"):
    wp.config.quiet = True

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
sys.path.insert(0, str(ROOT / "tests"))

import scene_problems as SP  # noqa: E402
import timing  # noqa: E402
from bench_scenes import Problem, git_head  # noqa: E402


def main() -> int:
    import json
    from dataclasses import replace

    from jwarp.solvers.planning import rrt as R
    from jwarp.world import World
    from jwarp.world import path_feasibility as FZ

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--problems", required=True, help="a scene_problems.py set (index.json)")
    ap.add_argument("--n", type=int, default=0, help="the first N problems only (0: all)")
    ap.add_argument("--margin", type=float, default=0.0)
    ap.add_argument("--endpoint-margin", type=float, default=0.0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--max-samples", type=int, default=4000)
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--planner", action="store_true",
                    help="also a Planner over the whole batch, fallback before/after")
    ap.add_argument("--time-limit", type=float, default=10.0, help="the Planner's [s]")
    args = ap.parse_args()

    index = json.loads((Path(args.problems) / "index.json").read_text())
    arm = index.get("robot", "panda")
    robot, _ = SP.load_robot(None, arm)
    entries = index["problems"][:args.n or None]
    probs = [Problem(Path(args.problems), e, robot) for e in entries]
    B = len(probs)
    world = World.batch([p.world for p in probs])
    q0 = np.stack([p.start for p in probs])
    q1 = np.stack([p.goal for p in probs])
    em = args.endpoint_margin
    kw = dict(margin=args.margin, endpoint_margin=em, device=args.device)
    o = R.RRTOptions(seed=args.seed, max_samples=args.max_samples)
    print(f"machine: {timing.machine(args.device)}; device {args.device}; warp "
          f"{wp.config.version}; load average {os.getloadavg()[0]:.2f}; jwarp at git "
          f"{git_head()}")
    print(f"problems: {B} from {args.problems} ({arm}, {len(robot.spheres)} spheres; exact "
          f"worlds, one World.batch); margin {args.margin:g} m, endpoint_margin {em:g} m; "
          f"RRTOptions(seed={args.seed}, max_samples={args.max_samples}, step {o.step}, "
          f"batch {o.batch})")

    def loop(sel: list[int]) -> tuple[float, list]:
        rngs = R.problem_rngs(args.seed, B)
        t = time.perf_counter()
        out = [R.rrt_connect(robot, world.select(b), q0[b], q1[b], replace(o, seed=rngs[b]),
                             **kw) for b in sel]
        return time.perf_counter() - t, out

    def batch(sel: list[int]) -> tuple[float, list]:
        t = time.perf_counter()
        out = R.rrt_connect_batch(robot, world, q0[sel], q1[sel], o, world_index=sel, **kw)
        return time.perf_counter() - t, out

    warm = [0, 1] if B > 1 else [0]
    loop(warm)
    batch(warm)
    t_loop, r_loop = loop(list(range(B)))
    t_batch, r_batch = batch(list(range(B)))

    def feasible(res: list) -> int:
        n = 0
        for b, r in enumerate(res):
            if r.path is None:
                continue
            e = np.stack([r.path[:-1], r.path[1:]], axis=1)
            n += bool(FZ.path_feasible(robot, world.select(b), e, 1, margin=args.margin,
                                       device=args.device).all())
        return n

    same = sum(int((a.path is None and b.path is None) or (
        a.path is not None and b.path is not None and np.array_equal(a.path, b.path)))
        for a, b in zip(r_loop, r_batch))
    tm = r_batch[0].timings
    print(f"\n{'RRT-Connect':<24} {'wall [s]':>9} {'solved':>7} {'re-checked':>10} "
          f"{'samples':>8} {'straight':>8}")
    for name, t, res in (("per-problem loop", t_loop, r_loop), ("batch", t_batch, r_batch)):
        ok = sum(r.success for r in res)
        print(f"{name:<24} {t:9.2f} {ok:>4}/{B:<3} {feasible(res):>10} "
              f"{sum(r.n_samples for r in res):>8} {sum(r.n_samples == 0 and r.success for r in res):>8}")
    print(f"speed-up {t_loop / t_batch:.2f}x; same paths {same}/{B}; batch: "
          f"{int(tm.get('states_calls', 0))} state calls ({tm['states']:.2f} s), "
          f"{int(tm.get('edges_calls', 0))} edge calls ({tm['edges']:.2f} s), shortcut "
          f"{tm.get('shortcut', 0.0):.2f} s")

    if args.planner:
        from jwarp.solvers.planning import Planner, PlanOptions
        from jwarp.solvers.planning import planner as PM

        po = PlanOptions(margin=args.margin, endpoint_margin=em, time_limit=args.time_limit,
                         fallback="rrt")
        print(f"\nPlanner over the batch (B = {B}): PlanOptions(margin {args.margin:g}, "
              f"endpoint_margin {em:g}, time_limit {args.time_limit:g} s, fallback rrt)")
        print(f"{'fallback':<24} {'wall [s]':>9} {'solved':>7} {'by fallback':>11} "
              f"{'rrt [s]':>8}")
        Planner(robot, world, B, po, device=args.device).plan(q0, q1)  # warm-up
        for flag in (False, True):
            PM.FALLBACK_BATCH = flag
            t = time.perf_counter()
            res = Planner(robot, world, B, po, device=args.device).plan(q0, q1)
            t = time.perf_counter() - t
            fb = int((res.stage == "fallback").sum())
            print(f"{'batch' if flag else 'per-problem loop':<24} {t:9.2f} "
                  f"{int(res.feasible.sum()):>4}/{B:<3} {fb:>11} "
                  f"{res.timings.get('rrt', 0.0):8.2f}")
        PM.FALLBACK_BATCH = True
    return 0


if __name__ == "__main__":
    sys.exit(main())
