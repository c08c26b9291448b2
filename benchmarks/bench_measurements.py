#!/usr/bin/env python
"""Throughput of the measurement plugins' ``jacobians()`` (samples per second).

The plugins are vectorized numpy (float64, host) code; the frames they consume come from
``jwarp.fk`` on ``--device`` (CPU by default) and are copied to the host once, outside the
timing. Rows: cartesian (justin19, tracker + 2 markers), image (justin19 head camera,
3 markers, closed loop), contact (hand4 capsule fingertips, 6 pairs; and a capsule vs a
box mesh fixture), relative (hand4, 4 fingertips).

    python benchmarks/bench_measurements.py                   # S = 300 and 10000, CPU
    python benchmarks/bench_measurements.py --device cuda     # FK on CUDA, plugins on host
    python benchmarks/bench_measurements.py --quick --json out.json
"""

from __future__ import annotations

import argparse
import json
import os
import sys

import numpy as np
from scipy.spatial.transform import Rotation

import jwarp
from jwarp.plugins.registry import measurement

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import timing  # noqa: E402


def setups() -> list[tuple[str, str, str, dict]]:
    """(row label, robot, plugin, setup section)."""
    head = Rotation.from_matrix([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]]).as_rotvec()
    tips = ["thumb", "index", "middle", "ring"]
    caps = [{"name": t, "robot_capsule": f"{t}_distal"} for t in tips]
    return [
        ("cartesian", "justin19", "cartesian", {
            "tracker": {"position": [2.5, 0.3, 1.2], "rotvec": [0.1, -0.2, 2.8]},
            "markers": [{"name": "right", "frame": "right_tcp", "position": [0, 0, 0.05]},
                        {"name": "left", "frame": "left_tcp", "position": [0, 0, 0.05]}]}),
        ("image", "justin19", "image", {
            "camera": {"frame": "head_tcp", "position": [0.05, 0, 0.08], "rotvec": head.tolist()},
            "intrinsics": {"focal": [600, 600], "center": [640, 480], "xi": 0.05},
            "markers": [{"name": "right", "frame": "right_tcp", "position": [0, 0, 0.05]},
                        {"name": "left", "frame": "left_tcp", "position": [0, 0, 0.05]},
                        {"name": "pole", "frame": None, "position": [1.0, 0.2, 1.0]}]}),
        ("contact capsules", "hand4", "contact", {
            "bodies": caps,
            "pairs": [[a, b] for i, a in enumerate(tips) for b in tips[i + 1:]]}),
        ("contact mesh", "hand4", "contact", {
            "bodies": caps[:1] + [{"name": "block", "type": "mesh", "frame": None,
                                   "box": [0.04, 0.06, 0.03], "position": [0.11, 0.01, 0.05]}],
            "pairs": [["thumb", "block"]]}),
        ("relative", "hand4", "relative", {
            "end_effectors": ["thumb_tip", "index_tip", "middle_tip", "ring_tip"]}),
    ]


def sample_q(robot, n: int, rng: np.random.Generator) -> np.ndarray:
    lim = robot.joint_limits
    q = rng.uniform(lim[:, 0], lim[:, 1], size=(n, robot.n_dof))
    if robot.name == "justin19":  # coupled torso: 0 <= q1 + q2 <= 135 deg
        q[:, 2] = np.clip(q[:, 2], np.maximum(0, -q[:, 1]), np.deg2rad(135) - np.maximum(q[:, 1], 0))
    return q


def time_call(fn, min_time: float, repeats: int) -> float:
    """Median seconds per call (:func:`timing.measure`)."""
    return timing.measure(fn, None, min_time, repeats).median


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--device", default="cpu", help="device of the FK producing the frames")
    ap.add_argument("--samples", default="300,10000", help="comma-separated sample counts S")
    ap.add_argument("--min-time", type=float, default=0.3, help="seconds of work per run")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--quick", action="store_true", help="S = 30, 0.01 s runs (smoke test)")
    ap.add_argument("--json", help="also write the rows as JSON to this path")
    args = ap.parse_args(argv)
    sizes = [30] if args.quick else [int(s) for s in args.samples.split(",")]
    min_time = 0.01 if args.quick else args.min_time
    repeats = 2 if args.quick else args.repeats
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"jwarp measurement plugins: jacobians() throughput | {timing.machine()}"
          f" | {os.cpu_count()} CPUs | FK on {args.device} | load {load:.2f}")
    print(f"{'plugin':<18}{'robot':<10}{'S':>7}{'m':>4}{'frames':>7}{'P':>4}"
          f"{'ms/call':>11}{'samples/s':>13}")
    rows = []
    rng = np.random.default_rng(0)
    for label, rname, plugin, setup in setups():
        robot = jwarp.robot(rname)
        m = measurement(plugin)(robot, dict(setup, plugin=plugin))
        for S in sizes:
            q = sample_q(robot, S, rng)
            F = np.asarray(jwarp.fk(robot, q, device=args.device, dtype="float64"))
            meta = {"pair": np.arange(S) % len(m.pairs)} if plugin == "contact" else None
            p = m.params.nominal
            mt = min_time if "mesh" not in label or S <= 1000 else min(min_time, 0.05)
            reps = repeats if "mesh" not in label or S <= 1000 else 1
            t = time_call(lambda: m.jacobians(F, p, meta), mt, reps)
            row = dict(plugin=label, robot=rname, samples=S, m=m.n_obs, frames=len(m.frames),
                       params=m.params.size, time_per_call_s=t, samples_per_s=S / t)
            rows.append(row)
            print(f"{label:<18}{rname:<10}{S:>7}{m.n_obs:>4}{len(m.frames):>7}{m.params.size:>4}"
                  f"{1e3 * t:>11.3f}{S / t:>13.0f}")
            sys.stdout.flush()
    if args.json:
        from jwarp.utils.atomic import atomic_write_text
        atomic_write_text(args.json, json.dumps({"rows": rows, "device": args.device,
                                                 "load": load}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
