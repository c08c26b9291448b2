"""Bit-for-bit snapshot of IK and planning results, for refactors that must not change any
(issue 40): a fixed set of ``plan`` and ``ik`` calls (README's examples, with and without
elastic compensation and a margin) on the CPU, each result's arrays saved as .npy.

Usage (PYTHONPATH at the tree under test)::

    python tools/snapshot_solvers.py run /tmp/before
    python tools/snapshot_solvers.py run /tmp/after
    python tools/snapshot_solvers.py compare /tmp/before /tmp/after

``compare`` exits 1 when any file differs byte for byte or is missing.
"""

from __future__ import annotations

import argparse
import filecmp
import os
import sys

import numpy as np


def _save(out: str, name: str, res: object) -> None:
    for k in ("feasible", "q", "path", "iterations", "cost", "pos_err", "rot_err", "solved",
              "length"):
        v = getattr(res, k, None)
        if v is None or callable(v):
            continue
        np.save(os.path.join(out, f"{name}.{k}.npy"), np.asarray(v), allow_pickle=False)


def run(out: str) -> None:
    import jwarp
    from jwarp.solvers.ik import ik
    from jwarp.solvers.planning import plan
    from jwarp.world import world_from_occupancy

    os.makedirs(out, exist_ok=True)
    lim = np.array([[-1.0, 1.0], [-1.0, 1.0]])
    h = 2.0 / 63
    X, Y = np.meshgrid(*[lim[d, 0] + h * np.arange(64) for d in range(2)], indexing="ij")
    world = world_from_occupancy((X > 0.5) & (X < 0.75) & (np.abs(Y) < 0.12), lim, h)
    for name, kw in (("plan", {}), ("plan_margin", {"margin": 0.02}),
                     ("plan_f64", {"dtype": np.float64}),
                     ("plan_elastic", {"kappa": 1e-3})):
        res = plan("planar4", world, [1.2, 0, 0, 0], [-1.2, 0, 0, 0], n_starts=16,
                   n_substeps=8, step=0.05, iterations=300, device="cpu", **kw)
        _save(out, name, res)
    robot = jwarp.robot("justin19")
    T = jwarp.fk(robot, np.full(19, 0.3))[robot.frame_index("right_tcp")]
    for name, kw in (("ik", {}), ("ik_margin", {"margin": 0.01}),
                     ("ik_elastic", {"kappa": 1e-4}),
                     ("ik_f32", {"dtype": np.float32, "seed": 3})):
        sol = ik(robot, "right_tcp", T, n_starts=16, device="cpu", **kw)
        _save(out, name, sol)
    print(f"snapshot of {os.path.dirname(jwarp.__file__)} into {out}: "
          f"{len(os.listdir(out))} files")


def compare(a: str, b: str) -> int:
    bad = 0
    names = sorted(set(os.listdir(a)) | set(os.listdir(b)))
    for n in names:
        pa, pb = os.path.join(a, n), os.path.join(b, n)
        if not (os.path.exists(pa) and os.path.exists(pb)) or not filecmp.cmp(pa, pb, False):
            print(f"DIFFERENT {n}")
            bad += 1
    print(f"{len(names) - bad} of {len(names)} files the same; {bad} different or missing")
    return 1 if bad else 0


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = p.add_subparsers(dest="cmd", required=True)
    sub.add_parser("run").add_argument("out")
    c = sub.add_parser("compare")
    c.add_argument("before")
    c.add_argument("after")
    args = p.parse_args()
    if args.cmd == "run":
        run(args.out)
        return 0
    return compare(args.before, args.after)


if __name__ == "__main__":
    sys.exit(main())
