#!/usr/bin/env python
"""Many distinct problems in one batch (issue 45: "700 distinct problems in one batch,
>= 99 % solved in <= 2 s total"): every problem of a ``scene_problems.py`` set in one
:meth:`jwarp.world.World.batch` and one :class:`jwarp.solvers.planning.Planner` call, each
problem in its own world (a script printing figures, never a timed test).

    python benchmarks/bench_batch.py --problems DIR [--device cuda] [--time-limit 2]
        [--limit N] [--margin 0] [--option NAME=JSON ...] [--no-verify]
        [--save-paths DIR] [--json FILE]

What is timed: the ``Planner``'s construction plus its ``plan`` call over the whole batch
(wall clock, the device synchronised before and after), with ``PlanOptions(margin,
endpoint_margin=0, time_limit=--time-limit, fallback="rrt")`` and the other defaults
(``--option`` sets another field), after one untimed warm-up call on the first 8
problems (kernel compilation). ``time_limit`` is the whole call's budget.

Printed: the machine and settings; per family the problems, solved, which stage solved
them (straight line, optimizer, fallback), and at the end the stop reason, the
planner's stage timings and the total; then (unless ``--no-verify``, which a GPU machine
without pinocchio/coal needs) every feasible path re-checked by the independent verifier
(``tests/verifier.py``: pinocchio FK + coal distances of the URDF meshes, <= 0.5 deg
steps, jwarp's endpoint rule; see ``bench_scenes.py``): collisions must be 0.
``--save-paths DIR``: the feasible paths as ``DIR/batch_m<margin>/<problem>.npy``, which
``bench_scenes.py --problems SET --verify-saved DIR`` verifies on another machine.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from collections import Counter
from pathlib import Path

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402
import warp as wp  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
sys.path.insert(0, str(ROOT / "tests"))

import bench_scenes as BS  # noqa: E402
import scene_problems as SP  # noqa: E402
import timing  # noqa: E402

STAGES = ("straight", "optimizer", "fallback", "none")


def plan_batch(robot, probs: list, o, device: str):
    """(seconds, PlanResult) of one Planner over ``probs`` in one batch world
    (``res.timings["construction"]``: the Planner's construction, seconds)."""
    from jwarp.solvers.planning import Planner
    from jwarp.world import World

    world = World.batch([p.world for p in probs])
    q0 = np.stack([p.start for p in probs])
    q1 = np.stack([p.goal for p in probs])
    wp.synchronize_device(device)
    t0 = time.perf_counter()
    planner = Planner(robot, world, len(probs), o, device=device)
    t1 = time.perf_counter()
    res = planner.plan(q0, q1)
    wp.synchronize_device(device)
    res.timings["construction"] = t1 - t0
    return time.perf_counter() - t0, res


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--problems", required=True, metavar="DIR",
                    help="a problem set of scene_problems.py (its index.json)")
    ap.add_argument("--robot", default=None, metavar="JSON",
                    help="the arm's robot file (default, Panda only: fitted from the URDF)")
    ap.add_argument("--device", default="cpu", help="cpu or cuda (cpu)")
    ap.add_argument("--time-limit", type=float, default=2.0,
                    help="seconds for the whole batch (2)")
    ap.add_argument("--limit", type=int, default=None, help="the first N problems only")
    ap.add_argument("--margin", type=float, default=0.0)
    ap.add_argument("--option", action="append", metavar="NAME=JSON",
                    help="another PlanOptions field (repeatable)")
    ap.add_argument("--repeat", type=int, default=1, help="timed calls (1)")
    ap.add_argument("--no-verify", action="store_true", help="skip the verifier")
    ap.add_argument("--save-paths", default=None, metavar="DIR")
    ap.add_argument("--json", default=None, metavar="FILE")
    args = ap.parse_args(argv)
    if args.time_limit <= 0:
        ap.error("--time-limit: expected > 0")
    if args.limit is not None and args.limit < 1:
        ap.error("--limit: expected >= 1")
    if args.repeat < 1:
        ap.error("--repeat: expected >= 1")
    from jwarp.core.arrays import init_warp
    from jwarp.solvers.planning import PlanOptions

    init_warp()
    device = "cuda:0" if args.device == "cuda" else args.device
    folder = Path(args.problems)
    index_file = folder / "index.json"
    if not index_file.is_file():
        ap.error(f"--problems: no index.json in {folder}")
    index = json.loads(index_file.read_text())
    arm = index.get("robot", "panda")
    try:
        robot, urdf = SP.load_robot(args.robot, arm)
    except ValueError as e:
        ap.error(f"--robot: {e}")
    verify = not args.no_verify and urdf is not None and BS.PathVerifier is not None
    if not args.no_verify and not verify:
        ap.error("the verifier needs pinocchio, coal and example-robot-data: add --no-verify "
                 "(and --save-paths to verify elsewhere)")
    entries = index["problems"][:args.limit]
    probs = [BS.Problem(folder, e, robot) for e in entries]
    try:
        opts = BS.extra_options(args)
        o = PlanOptions(margin=args.margin, endpoint_margin=0.0, time_limit=args.time_limit,
                        fallback="rrt", **opts)
    except (TypeError, ValueError) as e:
        ap.error(f"--option: {e}")
    print(f"machine: {timing.machine('cpu')}"
          + ("" if device == "cpu" else f"; {timing.machine(device)}")
          + f"; warp {wp.config.version}; jwarp at git {BS.git_head()}; load average "
            f"{os.getloadavg()[0]:.2f}")
    print(f"problems: {len(probs)} distinct ({arm}, {len(robot.spheres)} spheres) from {folder}, "
          f"one World.batch, one Planner on {device}; PlanOptions(margin={args.margin:g}, "
          f"endpoint_margin=0, time_limit={args.time_limit:g} s for the batch, fallback='rrt', "
          f"{opts}); timed: construction + plan(), after an untimed warm-up on 8 problems",
          flush=True)
    plan_batch(robot, probs[:min(8, len(probs))], o, device)   # warm-up: compilation
    runs = []
    for _ in range(args.repeat):
        runs.append(plan_batch(robot, probs, o, device))
    secs = [t for t, _ in runs]
    total, res = runs[-1]
    stage = np.asarray(res.stage).astype(str)
    fams = [p.family for p in probs]
    print(f"{'family':<18} {'n':>4} {'solved':>7} " + " ".join(f"{s:>9}" for s in STAGES))
    for fam in [f for f in SP.FAMILIES if f in fams] + ["all"]:
        sel = np.array([fam in ("all", f) for f in fams])
        c = Counter(stage[sel])
        n = int(sel.sum())
        ok = int(np.asarray(res.feasible)[sel].sum())
        print(f"{fam:<18} {n:>4} {100 * ok / n:>6.1f}% " + " ".join(f"{c.get(s, 0):>9}" for s in STAGES))
    tm = {k: round(float(v), 3) for k, v in (res.timings or {}).items()}
    print(f"batch of {len(probs)}: {int(np.sum(res.feasible))} solved in {total:.2f} s "
          f"(calls: {', '.join(f'{t:.2f}' for t in secs)} s); stop reason {res.stop_reason}; "
          f"stage seconds {tm}", flush=True)
    at = np.asarray(res.solved_at, np.float64)
    at = np.sort(np.where(np.isfinite(at), at, np.inf))
    n99 = int(np.ceil(0.99 * len(at))) - 1
    print(f"plan() clock (construction not counted): wall {res.wall_time:.3f} s; solved_at "
          f"(seconds from the call's start at which each problem's path was found): median "
          f"{np.median(at):.3f}, 99 % of the problems by {at[n99]:.3f} s, last solved "
          f"{at[np.isfinite(at)].max() if np.isfinite(at).any() else float('nan'):.3f} s",
          flush=True)
    out: dict = {"machine": timing.machine(device), "n": len(probs), "seconds": secs,
                 "solved": int(np.sum(res.feasible)), "stage": stage.tolist(),
                 "timings": tm, "options": opts, "time_limit": args.time_limit,
                 "margin": args.margin, "problems": [p.name for p in probs]}
    paths = np.asarray(res.path)
    if args.save_paths:
        d = Path(args.save_paths) / f"batch_m{args.margin:g}"
        d.mkdir(parents=True, exist_ok=True)
        for i in np.nonzero(res.feasible)[0]:
            np.save(d / f"{probs[i].name}.npy", paths[i])
    if verify:
        BS.PROMISE[0] = "meshes" if getattr(robot, "collision_pieces", None) is not None \
            else "spheres"
        BS.SELF_PAIRS[:] = BS.self_link_pairs(robot, urdf)
        spheres = BS.robot_spheres(robot)
        coll = 0
        for i in np.nonzero(res.feasible)[0]:
            row = BS.verify(probs[i].verifier(urdf, spheres, robot.joint_names), paths[i],
                            args.margin, 0.0)
            if row["collision"]:
                coll += 1
                print(f"  !! {probs[i].name}: {row['first_violation'] or row['closest']}")
        print(f"verifier: {int(np.sum(res.feasible))} feasible paths, {coll} collisions "
              f"(URDF meshes, world or self; must be 0)")
        out["collisions"] = coll
    if args.json:
        from jwarp.utils.atomic import atomic_write_text

        atomic_write_text(args.json, json.dumps(out, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
