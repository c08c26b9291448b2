#!/usr/bin/env python
"""The overhead of :func:`jwarp.fk` on one configuration against the Model/Data path.

The reference is :func:`jwarp.kinematics.forward_kinematics` with a reused
:class:`~jwarp.kinematics.KinematicsData` (the buffers and the recorded launch made once,
q copied in, the launch replayed). Each row times ``jwarp.fk(robot, q, device=...)`` of one
configuration in one array kind (numpy, a Warp CPU array, a CPU torch tensor) and device
argument (None, "cpu"), side by side with the reference in one run (interleaved rounds, see
:func:`timing.side_by_side`), and prints the ratio fk / reference of the min and of the
median over the rounds. Issue 28's acceptance line: every ratio within 1.5x.

    python benchmarks/bench_fk_overhead.py                  # justin19 and the UR5 URDF
    python benchmarks/bench_fk_overhead.py --dtype float64 --rounds 9 --json out.json
    python benchmarks/bench_fk_overhead.py --quick              # smoke-test sizes

The URDF robot is example-robot-data's UR5 (skipped where that package is not installed).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import warp as wp

sys.path.insert(0, str(Path(__file__).resolve().parent))
from timing import machine, side_by_side  # noqa: E402  (benchmarks/timing.py)

import jwarp  # noqa: E402
from jwarp.core.arrays import init_warp  # noqa: E402
from jwarp.core.device import put_model  # noqa: E402
from jwarp.kinematics import KinematicsData, forward_kinematics  # noqa: E402

#: example-robot-data's UR5, relative to its robots folder
UR5 = "ur_description/urdf/ur5_robot.urdf"


def ur5_path() -> str | None:
    """The UR5 URDF of example-robot-data, or None where it is not installed."""
    from jwarp.importers.robot import example_robot_urdf

    try:
        return example_robot_urdf(UR5)
    except ValueError:
        return None


def inputs(q: np.ndarray) -> dict:
    """One configuration (n_dof,) in every array kind fk takes on the CPU."""
    kinds = {"numpy": q, "warp": wp.array(q[None], device="cpu")}
    try:
        import torch

        kinds["torch"] = torch.from_numpy(q.copy())
    except ImportError:
        pass
    return kinds


def rows(name: str, robot, dtype, min_time: float, rounds: int) -> list[dict]:
    """The ratios fk / forward_kinematics of ``robot`` for every array kind and device."""
    rng = np.random.default_rng(0)
    lim = robot.joint_limits
    q = rng.uniform(lim[:, 0], lim[:, 1], robot.n_dof).astype(dtype)
    m = put_model(jwarp.robot(robot), "cpu", dtype)
    d = KinematicsData(m, 1)
    q1 = q[None]
    out = []
    for kind, x in inputs(q).items():
        for device in (None, "cpu"):
            def ref() -> None:
                forward_kinematics(m, d, q1)

            def call(x=x, device=device) -> None:
                jwarp.fk(robot, x, device=device)

            base, fk = side_by_side([ref, call], "cpu", min_time, rounds)
            out.append({"robot": name, "kind": kind, "device": device,
                        "ref_us": base.best * 1e6, "fk_us": fk.best * 1e6,
                        "ratio_min": fk.best / base.best,
                        "ratio_median": fk.median / base.median})
    return out


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--dtype", default="float32", choices=["float32", "float64"])
    parser.add_argument("--rounds", type=int, default=7, help="interleaved rounds per row")
    parser.add_argument("--min-time", type=float, default=0.05,
                        help="seconds of back-to-back calls per timed run")
    parser.add_argument("--quick", action="store_true", help="smoke-test sizes")
    parser.add_argument("--json", help="write the figures to this file")
    args = parser.parse_args(argv)
    if args.quick:
        args.rounds, args.min_time = 2, 0.005
    dtype = np.dtype(args.dtype).type
    init_warp()
    robots = {"justin19": jwarp.robot("justin19")}
    path = ur5_path()
    if path is not None:
        robots["ur5 (URDF)"] = jwarp.robot(path)
    table = []
    for name, robot in robots.items():
        table += rows(name, robot, dtype, args.min_time, args.rounds)
    print(f"fk of one configuration / forward_kinematics with a reused KinematicsData "
          f"({args.dtype}, {machine('cpu')}, {args.rounds} rounds)")
    print(f"{'robot':<12} {'kind':<6} {'device':<6} {'ref us':>8} {'fk us':>8} "
          f"{'min':>6} {'median':>7}")
    for r in table:
        print(f"{r['robot']:<12} {r['kind']:<6} {str(r['device']):<6} {r['ref_us']:8.2f} "
              f"{r['fk_us']:8.2f} {r['ratio_min']:6.2f} {r['ratio_median']:7.2f}")
    doc = {"dtype": args.dtype, "machine": machine("cpu"), "rows": table}
    if args.json:
        Path(args.json).write_text(json.dumps(doc, indent=1))
    return doc


if __name__ == "__main__":
    main()
