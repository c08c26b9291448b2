#!/usr/bin/env python
"""The continuous path check side by side: today's conservative advancement
(``MotionOptions(method="advance")``: on a GPU 4 rounds of 16 parallel points per segment
first, then one thread per segment advancing from the proven prefix; on the CPU the
advancement alone) against the interval refinement (``method="levels"``: 16 intervals per
segment, each proven from its midpoint or cut to the parts it leaves unproven, at most
half of it each, level by level, every interval of a level in parallel), on the same
paths in the same process.

    python benchmarks/bench_motion_check.py                    # CPU
    python benchmarks/bench_motion_check.py --device cuda      # a GPU
    python benchmarks/bench_motion_check.py --quick            # smoke-test sizes
    python benchmarks/bench_motion_check.py --device cuda --advance-evals 64 \
        --advance-rounds 8                                     # the planner's GPU settings

Cases per robot (arm7, justin19, and the fitted-sphere Panda of benchmarks/scene_problems.py
when its URDF is installed):

* ``ordinary``: random straight paths (8 waypoints) in a small scene of boxes (free and
  colliding ones);
* ``graze 1mm`` / ``graze 0.1mm``: free paths (3 waypoints), each passing a ball of its own
  world (a batch of worlds, ``world_group`` 1) at 1 mm / 0.1 mm clearance: the hard case
  (a segment proven only in small steps near the ball);
* ``graze -0.1mm``: the same 0.1 mm into the ball (a collision to find).

Columns: ``ms`` the time of one check (``MotionCheck.launch`` on device arrays, closed by
a device sync; median of interleaved runs, :func:`timing.side_by_side`), ``launches``
kernel launches of one check (memsets not counted), ``evals`` evaluations (FK + distances)
summed over the segments, ``ok`` paths proven feasible; ``agree`` paths with the same
verdict by both, ``+lv`` proven only by the levels (the advancement leaves them
uncertified), ``+adv`` proven only by the advancement. A script printing figures, never a
timed test.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np
import warp as wp

wp.config.quiet = True

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

import timing  # noqa: E402
from worlds import ball_worlds, grazing_paths  # noqa: E402

import jwarp
from jwarp.core.arrays import init_warp  # noqa: E402
from jwarp.world import World  # noqa: E402
from jwarp.world.motion import MotionCheck, MotionOptions  # noqa: E402
from jwarp.world.primitives import pose_matrix  # noqa: E402


def scene(name: str) -> World:
    """A few boxes around the robot (free and colliding random paths)."""
    w = World.of_shapes()
    if name == "justin19":
        w.add("block", "box", [0.3, 1.0, 0.6], [0.75, 0.0, 0.3])
        w.add("shelf", "box", [0.4, 0.3, 0.05], [0.7, 0.6, 1.4])
    elif name == "panda":
        w.add("table", "box", [0.6, 1.0, 0.05], [0.55, 0.0, 0.2])
        w.add("wall", "box", [0.05, 0.6, 0.6], [0.0, -0.6, 0.5])
        w.add("post", "cylinder", [0.8, 0.03], pose_matrix([0.45, 0.35, 0.6]))
    else:
        w.add("box", "box", [0.2, 0.2, 0.2], [0.45, 0.0, 0.5])
        w.add("pole", "cylinder", [0.6, 0.03], pose_matrix([0.0, 0.45, 0.5]))
        w.add("floor", "plane", pose=pose_matrix([0, 0, -0.05]))
    return w


def random_paths(robot: Any, n: int, W: int, seed: int) -> np.ndarray:
    """``n`` straight paths of W waypoints within the joint limits."""
    from jwarp.core.limits import within_limits

    rng = np.random.default_rng(seed)
    lim = np.asarray(robot.joint_limits)
    mid = lim.mean(1)
    q = mid + 0.6 * (rng.uniform(lim[:, 0], lim[:, 1], size=(4 * n, 2, robot.n_dof)) - mid)
    q = q[within_limits(robot, q.reshape(-1, robot.n_dof)).reshape(-1, 2).all(1)][:n]
    return q[:, :1] + np.linspace(0, 1, W)[None, :, None] * (q[:, 1:] - q[:, :1])


def load(name: str) -> Any:
    import jwarp

    if name == "panda":
        import scene_problems as SP  # noqa: E402  (benchmarks/)

        return SP.load_robot()[0]
    return jwarp.robot(name)


def run_case(robot: Any, world: World, paths: np.ndarray, world_group: int, device: Any,
             args: argparse.Namespace) -> dict:
    adv = MotionOptions(method="advance", max_evals=args.advance_evals,
                        rounds=args.advance_rounds)
    checks = [MotionCheck(jwarp.robot(robot), world, device=device, options=o)
              for o in (adv, MotionOptions(method="levels"))]
    P = wp.array(np.ascontiguousarray(paths, np.float64), dtype=wp.float64, device=device)
    idx = wp.array(np.arange(len(paths), dtype=np.int32), device=device)
    res = []
    for chk in checks:
        out = chk.launch(P, idx, len(paths), world_group=world_group)
        res.append(dict(ok=out["ok"].numpy()[:len(paths)].astype(bool),
                        evals=int(out["seg"].n.numpy()[:len(paths)].sum()),
                        launches=chk.last_launches))
    fns = [lambda c=c: c.launch(P, idx, len(paths), world_group=world_group) for c in checks]
    t = timing.side_by_side(fns, device, args.min_time, args.rounds)
    old, new = res
    return {"paths": len(paths), "segments": len(paths) * (paths.shape[1] - 1),
            "advance": {"ms": t[0].median * 1e3, "launches": old["launches"],
                        "evals": old["evals"], "ok": int(old["ok"].sum())},
            "levels": {"ms": t[1].median * 1e3, "launches": new["launches"],
                       "evals": new["evals"], "ok": int(new["ok"].sum())},
            "agree": int((old["ok"] == new["ok"]).sum()),
            "levels_only": int((new["ok"] & ~old["ok"]).sum()),
            "advance_only": int((old["ok"] & ~new["ok"]).sum())}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--robots", default="arm7,justin19,panda")
    ap.add_argument("--paths", type=int, default=None, help="ordinary paths per robot")
    ap.add_argument("--graze", type=int, default=None, help="grazing paths per case")
    ap.add_argument("--advance-evals", type=int, default=MotionOptions.max_evals,
                    help="the advancement's max_evals (the planner's on a GPU: "
                         "PLANNER_CHECK_EVALS_GPU = 64)")
    ap.add_argument("--advance-rounds", type=int, default=MotionOptions.rounds,
                    help="the advancement's parallel rounds on a GPU (the planner's: 8)")
    ap.add_argument("--min-time", type=float, default=0.2)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv)
    init_warp()
    device = wp.get_device(args.device)
    gpu = device.is_cuda
    n_ord = args.paths or (8 if args.quick else (2048 if gpu else 200))
    n_graze = args.graze or (4 if args.quick else (256 if gpu else 24))
    if args.quick:
        args.min_time, args.rounds = 0.01, 1
    print(f"machine: {timing.machine(device)}")
    print(f"{'robot':9s} {'case':13s} {'paths':>6s} | {'advance ms':>10s} {'launch':>6s} "
          f"{'evals':>8s} {'ok':>5s} | {'levels ms':>10s} {'launch':>6s} {'evals':>8s} "
          f"{'ok':>5s} | {'speedup':>7s} {'agree':>6s} {'+lv':>4s} {'+adv':>4s}")
    rows = []
    for name in args.robots.split(","):
        try:
            robot = load(name)
        except Exception as e:  # noqa: BLE001  (the Panda's URDF may be missing)
            print(f"{name}: skipped ({e})")
            continue
        cases = [("ordinary", scene(name), random_paths(robot, n_ord, 8, seed=1), 0)]
        for label, delta in (("graze 1mm", 1e-3), ("graze 0.1mm", 1e-4),
                             ("graze -0.1mm", -1e-4)):
            paths, _, balls = grazing_paths(robot, n_graze, delta, seed=5)
            cases.append((label, ball_worlds(balls), paths, 1))
        for label, world, paths, wg in cases:
            r = run_case(robot, world, paths, wg, device, args)
            a, b = r["advance"], r["levels"]
            print(f"{name:9s} {label:13s} {r['paths']:6d} | {a['ms']:10.2f} {a['launches']:6d} "
                  f"{a['evals']:8d} {a['ok']:5d} | {b['ms']:10.2f} {b['launches']:6d} "
                  f"{b['evals']:8d} {b['ok']:5d} | {a['ms'] / b['ms']:6.2f}x "
                  f"{r['agree']:6d} {r['levels_only']:4d} {r['advance_only']:4d}", flush=True)
            rows.append({"robot": name, "case": label, **r})
    if args.json:
        Path(args.json).write_text(json.dumps({"machine": timing.machine(device),
                                               "device": str(device), "rows": rows}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
