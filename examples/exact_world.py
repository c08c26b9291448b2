#!/usr/bin/env python
"""An exact world in a few lines: objects added, planned around, moved, attached to the hand.

    python examples/exact_world.py            # arm7, one CPU core, a few seconds

1. A world of exact objects (a table, a box on it, a pole, a floor plane): no grid.
2. A plan from one side of the box to the other: the straight line would hit the box, so
   the planner goes around; every sphere keeps the margin along the whole continuous motion
   (jwarp.world.motion), re-checked here by dense sampling of the exact distances.
3. The same straight line alone: "NOT feasible" and why (link and object).
4. The box moves in place; the planner (and its device copy of the world) sees it.
5. A part is attached to the hand: the robot now carries it, and planning keeps it clear too.

Prints one line per step and the checks; exit status 1 if a check fails.
"""

from __future__ import annotations

import os
import sys

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402

import jwarp  # noqa: E402
from jwarp.solvers.planning import plan
from jwarp.world import World  # noqa: E402
from jwarp.world.collision import min_distances  # noqa: E402
from jwarp.world.primitives import pose_matrix  # noqa: E402


def dense_clearance(robot, world, path: np.ndarray, n: int = 400) -> float:
    """Smallest sphere clearance [m] over ``n`` samples per segment (an independent look)."""
    u = np.linspace(0.0, 1.0, n)
    q = (path[:-1, None] + u[None, :, None] * np.diff(path, axis=0)[:, None]).reshape(
        -1, robot.n_dof)
    return float(min_distances(jwarp.robot(robot), q, world, dtype=np.float64).min())


def plan_kept_clear(robot, world, start, goal, margin: float = 0.01) -> tuple[str, bool]:
    """Plan with ``margin``; (a line saying how it went, whether it is feasible and keeps
    the margin by dense sampling)."""
    res = plan(robot, world, start, goal, margin=margin)
    c = dense_clearance(robot, world, res.path[0])
    state = "feasible" if res.feasible[0] else "NOT feasible"
    text = (f"{state} ({res.stage[0]}, {res.wall_time * 1e3:.0f} ms); densely sampled "
            f"clearance {c * 1e3:.1f} mm")
    return text, bool(res.feasible[0]) and c >= margin - 1e-6


def main() -> int:
    robot = jwarp.robot("arm7")
    world = World.of_shapes()
    # the hand swings from (-0.23, -0.67, 0.86) to (-0.71, -0.03, 0.86) m: a box in the middle
    world.add("table", "box", [0.6, 0.6, 0.05], [-0.6, -0.45, 0.2])
    world.add("box", "box", [0.12, 0.12, 0.3], [-0.57, -0.42, 0.86])
    world.add("pole", "cylinder", [1.2, 0.03], [0.4, 0.5, 0.6])
    world.add("floor", "plane", pose=pose_matrix([0.0, 0.0, -0.02]))
    start = np.array([0.6, 1.0, 0.0, -0.9, 0.0, 0.4, 0.0])
    goal = np.array([-0.6, 1.0, 0.0, -0.9, 0.0, 0.4, 0.0])
    checks = []

    text, ok = plan_kept_clear(robot, world, start, goal)
    print(f"1-2. plan around the box: {text}")
    checks.append(("the plan keeps the 1 cm margin (dense re-check)", ok))

    line = plan(robot, world, start, goal, start_kind="straight", iterations=0, fallback=None)
    print(f"3. the straight line: {line.reasons[0]}")
    checks.append(("the straight line is refused, naming the box",
                   not line.feasible[0] and "'box'" in line.reasons[0]))

    world.move("box", [-0.57, -0.42, 2.5])       # lifted far above: the line is free now
    moved = plan(robot, world, start, goal, start_kind="straight", iterations=0, fallback=None)
    print(f"4. box moved away: the straight line is "
          f"{'feasible' if moved.feasible[0] else 'NOT feasible: ' + moved.reasons[0]}")
    checks.append(("the moved box is seen at once", bool(moved.feasible[0])))
    world.move("box", [-0.57, -0.42, 0.86])

    tcp = list(robot.end_effectors)[0]
    T = jwarp.fk(robot, start[None], dtype=np.float64)[0, robot.frame_index(tcp)]
    part = T.copy()
    part[:3, 3] = T[:3, 3] + 0.08 * T[:3, 2]
    world.add("part", "cylinder", [0.12, 0.025], part)
    carried = world.attach("part", robot, tcp, start)
    text, ok = plan_kept_clear(carried, world, start, goal)
    print(f"5. with the part in the hand ({len(carried.spheres) - len(robot.spheres)} spheres "
          f"cover it): {text}")
    checks.append(("the part is carried clear of the world too", ok))

    print()
    for text, ok in checks:
        print(f"check: {text}: {'PASS' if ok else 'FAIL'}")
    n_ok = sum(ok for _, ok in checks)
    print(f"checks: {n_ok} of {len(checks)} passed")
    return 0 if n_ok == len(checks) else 1


if __name__ == "__main__":
    sys.exit(main())
