"""Evaluation of motion-planning networks (thesis 3.5.2, Fig. 3.24, Table 3.3): the
feasibility of the network's paths alone, of the planner started from them after k
iterations, and of random multi-starts (one, and the best of ``n_random``), on unseen
tasks and worlds.

One planner run per initial-guess kind and world with ``max(ks)`` iterations and an exact
feasibility check after every iteration (``check_all_every=1``): a task counts as feasible
after k iterations when one of its starts was feasible at iteration <= k (early stop
freezes a feasible path, so the count is that of a run of exactly k iterations). k = 0 is
the initial guess itself ("network alone").
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from jwarp.core.types import DeviceLike, RobotLike
from jwarp.plugins.registry import robot as get_robot
from jwarp.solvers.planning import Planner, PlanOptions

if TYPE_CHECKING:
    from jwarp.model import RobotModel
    from jwarp.world.sdf import World

__all__ = ["evaluate_plan", "format_plan_table"]


def _run(model: RobotModel, world: World, q0: np.ndarray, q1: np.ndarray, K: int, *, seeds: Any = None,
         n_starts: int = 1, start_kind: str = "random", n_waypoints: int = 20,
         n_substeps: int = 4, seed: int = 0, device: DeviceLike = None
         ) -> tuple[np.ndarray, np.ndarray]:
    """(B, n_starts) first feasible iteration (K + 1: never) and (B,) best cost."""
    opts = PlanOptions(n_starts=n_starts, start_kind=start_kind, n_waypoints=n_waypoints,
                       n_substeps=n_substeps, iterations=K, check_all_every=1, seed=seed,
                       stop_when_solved=False, fallback=None)
    res = Planner(model, world, len(q0), opts, device=device).plan(q0, q1, seeds=seeds)
    it = np.where(res.all_feasible, res.all_iterations, K + 1)
    return it, np.where(res.feasible, res.cost, np.nan)


def evaluate_plan(robot: RobotLike, worlds: list, starts: np.ndarray, goals: np.ndarray,
                  world_index: np.ndarray, *, nets: list | tuple = (), ks: tuple = (0, 10, 50),
                  n_random: int = 10, n_waypoints: int = 20, n_substeps: int = 4,
                  seed: int = 0, baselines: bool = True, device: DeviceLike = None) -> list[dict]:
    """Rows of the table: per ``(name, net)`` in ``nets`` (a network's heads as the
    starts; "network alone" is the k = 0 column), then "random (1)" (one random multi-start:
    1-3 random via points), "random (best of n_random)" and "straight line". Each row:
    ``name``, ``feasible`` {k: fraction of tasks feasible after k iterations}, ``cost``
    (mean U_path of the feasible ones after max(ks)), ``n_tasks``. ``baselines=False``:
    the networks' rows only. ``device``: the planner's Warp device (the networks predict
    on their own device)."""
    model = get_robot(robot)
    starts = np.asarray(starts, np.float64)
    goals = np.asarray(goals, np.float64)
    world_index = np.asarray(world_index, np.int64)
    ks = tuple(sorted(int(k) for k in ks))
    K = ks[-1]
    kinds: list[tuple[str, dict]] = [(name, {"net": net}) for name, net in nets]
    kinds += [] if not baselines else [("random (1)", {"n_starts": 1, "start_kind": "random"}),
              (f"random (best of {n_random})", {"n_starts": n_random, "start_kind": "random"}),
              ("straight line", {"n_starts": 1, "start_kind": "straight"})]
    rows = []
    for name, how in kinds:
        first = np.empty(len(starts))
        cost = np.empty(len(starts))
        for wi in np.unique(world_index):
            idx = np.flatnonzero(world_index == wi)
            world = worlds[wi]
            q0, q1 = starts[idx], goals[idx]
            if "net" in how:
                seeds = how["net"].paths(q0, q1, world)
                it, c = _run(model, world, q0, q1, K, seeds=seeds, n_starts=seeds.shape[1],
                             n_waypoints=seeds.shape[2], n_substeps=n_substeps, seed=seed,
                             device=device)
            else:
                it, c = _run(model, world, q0, q1, K, n_starts=how["n_starts"],
                             start_kind=how["start_kind"], n_waypoints=n_waypoints,
                             n_substeps=n_substeps, seed=seed + int(wi), device=device)
            first[idx] = it.min(axis=1)
            cost[idx] = c
        feas = {k: float(np.mean(first <= k)) for k in ks}
        ok = np.isfinite(cost)
        rows.append({"name": name, "feasible": feas, "n_tasks": int(len(starts)),
                     "cost": float(cost[ok].mean()) if ok.any() else math.nan})
    return rows


def format_plan_table(rows: list[dict], title: str = "") -> str:
    """The rows of :func:`evaluate_plan` as a text table (feasibility per k, cost)."""
    ks = list(rows[0]["feasible"]) if rows else []
    w = max([len(r["name"]) for r in rows] + [12])
    head = f"{'initial guess':<{w}}  " + "  ".join(f"{'k=' + str(k):>7}" for k in ks) \
        + f"  {'U_path':>8}"
    lines = [title] if title else []
    lines += [head, "-" * len(head)]
    for r in rows:
        lines.append(f"{r['name']:<{w}}  " + "  ".join(f"{100 * r['feasible'][k]:6.1f}%"
                                                     for k in ks) + f"  {r['cost']:8.4f}")
    if rows:
        lines.append(f"(feasibility after k planner iterations, {rows[0]['n_tasks']} tasks; "
                     f"k=0: the initial guess alone)")
    return "\n".join(lines)
