"""A small planar4 run of the motion-planning network (docs/learning.md, "Motion-planning
network"): hard tasks in random simplex worlds labelled by the planner's multi-starts, the
Table 3.3 ladder (augmentation, boosting, cleaning, extension) and the Fig. 3.24 analogue
on unseen worlds. CPU; sizes by the flags (defaults: the documented run).

    python examples/train_plan_planar4.py --out plan_planar4.json
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from jwarp.learn.evaluate_plan import evaluate_plan, format_plan_table
from jwarp.learn.train_plan import (TrainPlanOptions, clean, extend, make_plan_data,
                                    train_plan)
from jwarp.world.feasibility import feasible_simplex_world


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--worlds", type=int, default=8)
    ap.add_argument("--tasks", type=int, default=40)
    ap.add_argument("--test-worlds", type=int, default=3)
    ap.add_argument("--test-tasks", type=int, default=25)
    ap.add_argument("--epochs", type=int, default=10)
    ap.add_argument("--steps", type=int, default=100)
    ap.add_argument("--out", default="plan_planar4.json")
    a = ap.parse_args()
    t0 = time.time()
    worlds = [feasible_simplex_world("planar4", seed=1000 + 7 * i) for i in range(a.worlds)]
    test_worlds = [feasible_simplex_world("planar4", seed=900000 + 7 * i)
                   for i in range(a.test_worlds)]
    data = make_plan_data("planar4", worlds, a.tasks, seed=0, hard=True)
    test = make_plan_data("planar4", test_worlds, a.test_tasks, seed=1, hard=True)
    print(f"data: {len(data)} train, {len(test)} test samples ({time.time() - t0:.0f} s)",
          flush=True)
    base = dict(robot="planar4", n_bps=128, hidden=128, n_blocks=3, epochs=a.epochs,
                steps_per_epoch=a.steps, batch_size=128)
    ladder = [("hard, no aug.", dict(time_reversal=False, axis_symmetry=False)),
              ("hard, axis", dict(time_reversal=False, axis_symmetry=True)),
              ("hard, time", dict(time_reversal=True, axis_symmetry=False)),
              ("hard, both", dict()),
              ("hard, both, boost", dict(boosting=True))]
    out = {"sizes": vars(a), "n_train": len(data), "n_test": len(test), "ladder": []}
    ks = (0, 10, 50)
    net = None
    for name, sw in ladder:
        t = time.time()
        net, hist = train_plan(TrainPlanOptions(**base, **sw), data, test)
        rows = evaluate_plan("planar4", test.worlds, test.starts, test.goals, test.world_index,
                             nets=[(name, net)], ks=ks, baselines=False)
        out["ladder"].append({"name": name, "val_mse_before": hist[0]["val_mse"],
                              "val_mse_after": hist[-1]["val_mse"], "rows": rows,
                              "seconds": time.time() - t})
        print(f"{name}: val_mse {hist[0]['val_mse']:.5f} -> {hist[-1]['val_mse']:.5f}; "
              f"feasible {rows[0]['feasible']} ({time.time() - t:.0f} s)", flush=True)
    # Algorithm 1 rounds on top of the last (both + boost) network
    opts = TrainPlanOptions(**base, boosting=True)
    d = data
    for r in (1, 2):
        d, n_rep = clean(net, d, seed=r)
        net, hist = train_plan(opts, d, test, net=net)
        rows = evaluate_plan("planar4", test.worlds, test.starts, test.goals, test.world_index,
                             nets=[(f"{r} clean", net)], ks=ks, baselines=False)
        out["ladder"].append({"name": f"{r} clean(s), both, boost", "replaced": n_rep,
                              "val_mse_after": hist[-1]["val_mse"], "rows": rows})
        print(f"clean {r}: replaced {n_rep}; val_mse {hist[-1]['val_mse']:.5f}; feasible "
              f"{rows[0]['feasible']}", flush=True)
    d, n_add = extend(net, d, max(1, len(d) // 4))
    net, hist = train_plan(opts, d, test, net=net)
    rows = evaluate_plan("planar4", test.worlds, test.starts, test.goals, test.world_index,
                         nets=[("+ ext.", net)], ks=ks)
    out["ladder"].append({"name": "2 cleans, + ext., both, boost", "added": n_add,
                          "val_mse_after": hist[-1]["val_mse"], "rows": rows})
    print(f"extend: added {n_add}; val_mse {hist[-1]['val_mse']:.5f}; feasible "
          f"{rows[0]['feasible']}", flush=True)
    print(format_plan_table(rows, f"planar4, {len(test)} hard tasks in {a.test_worlds} unseen "
                                  f"worlds"))
    out["final_table"] = rows
    out["seconds"] = time.time() - t0
    with open(a.out, "w") as f:
        json.dump(out, f, indent=1, default=float)


if __name__ == "__main__":
    main()
