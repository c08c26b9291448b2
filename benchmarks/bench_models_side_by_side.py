"""Two robot files of one robot planned side by side on the same scene problems (issue 42).

``python benchmarks/bench_models_side_by_side.py OLD.json NEW.json --problems DIR
[--margin M] [--time-limit S] [--device cpu|cuda] [--json FILE]``: one process; every
problem is planned with OLD and with NEW in turn, the order alternating, ``Planner``
defaults (as ``bench_scenes.py`` plans: ``fallback="rrt"``, ``stop_when_solved``), so the
load of a shared machine falls on both alike. Prints the solved counts, the per-problem
time ratio NEW / OLD (median and p95 over the problems both solve), the ratio of the sums,
both medians and p95s, and NEW's share of time in the mesh certificate
(``PlanResult.timings["mesh_check"]``). Problems: a folder written by
``scene_problems.generate`` (``bench_scenes.py --out``).
"""

from __future__ import annotations

import argparse
import json
import sys
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import bench_scenes as BS  # noqa: E402
import timing  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("old", help="robot file (the reference)")
    ap.add_argument("new", help="robot file (compared with it)")
    ap.add_argument("--problems", required=True, help="problem folder (index.json)")
    ap.add_argument("--margin", type=float, default=0.0, help="clearance [m] (0)")
    ap.add_argument("--time-limit", type=float, default=1.0, help="seconds per problem (1)")
    ap.add_argument("--device", default="cpu", help="cpu (default) or cuda")
    ap.add_argument("--json", help="write every row here")
    args = ap.parse_args(argv)
    from jwarp.core.arrays import init_warp
    from jwarp.model.robot import RobotModel

    for name in ("old", "new"):
        if not Path(getattr(args, name)).is_file():
            raise SystemExit(f"{name}: no such robot file: {getattr(args, name)}")
    folder = Path(args.problems)
    if not (folder / "index.json").is_file():
        raise SystemExit(f"--problems: no index.json in {folder}")
    if args.json and not Path(args.json).resolve().parent.is_dir():
        raise SystemExit(f"--json: the folder of {args.json} does not exist")
    init_warp()
    warnings.simplefilter("ignore")  # the robots' fit warnings, once per process anyway
    robots = [RobotModel.load(args.old), RobotModel.load(args.new)]
    entries = json.loads((folder / "index.json").read_text())["problems"]
    ns = argparse.Namespace(endpoint_margin=0.0, time_limit=args.time_limit,
                            no_stop_when_solved=False, option=[])
    probs = [[BS.Problem(folder, e, r) for e in entries] for r in robots]
    for i, r in enumerate(robots):  # warm-up: every kernel loaded before the timed runs
        BS.plan_one(r, probs[i][0], args.margin, ns, args.device)
        BS.warm_check(r, probs[i][0], args.device)
    rows = []
    for j in range(len(entries)):
        rec: dict = {"problem": probs[0][j].name, "family": probs[0][j].family}
        for i in ((0, 1) if j % 2 == 0 else (1, 0)):
            t, res = BS.plan_one(robots[i], probs[i][j], args.margin, ns, args.device)
            ok = not isinstance(res, Exception) and bool(np.asarray(res.feasible).all())
            rec[("old", "new")[i]] = {"time_s": t, "solved": ok,
                                      "timings": dict(getattr(res, "timings", {}) or {})}
        rows.append(rec)
    both = [r for r in rows if r["old"]["solved"] and r["new"]["solved"]]
    print(f"machine: {timing.machine()}; device {args.device}; margin {args.margin:g} m; "
          f"{len(rows)} problems from {folder}")
    for k, f in (("old", args.old), ("new", args.new)):
        t = np.array([r[k]["time_s"] for r in rows if r[k]["solved"]])
        print(f"{k} {f}: {len(robots[k == 'new'].spheres)} spheres, solved "
              f"{sum(r[k]['solved'] for r in rows)}/{len(rows)}, median "
              f"{np.median(t) * 1e3 if len(t) else float('nan'):.1f} ms, p95 "
              f"{np.percentile(t, 95) * 1e3 if len(t) else float('nan'):.0f} ms")
    if both:
        ta = np.array([r["old"]["time_s"] for r in both])
        tb = np.array([r["new"]["time_s"] for r in both])
        ra = tb / ta
        print(f"new / old over the {len(both)} problems both solve: per problem median "
              f"{np.median(ra):.2f} (p95 {np.percentile(ra, 95):.2f}), sums {tb.sum() / ta.sum():.2f}")
    mesh = sum(r["new"]["timings"].get("mesh_check", 0.0) for r in rows)
    total = sum(r["new"]["time_s"] for r in rows)
    print(f"new: mesh certificate {mesh:.2f} s of {total:.2f} s ({100 * mesh / max(total, 1e-12):.1f} %)")
    if args.json:
        from jwarp.utils.atomic import atomic_write_text

        atomic_write_text(args.json, json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
