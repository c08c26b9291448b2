#!/usr/bin/env python
"""Optimal experimental design (thesis 2.4.2): speed of the batched candidate Jacobians
and of greedy / DETMAX selection (:mod:`jwarp.calibration.design.optimal`).

    python benchmarks/bench_design.py                 # 1e4 candidates, N = 100
    python benchmarks/bench_design.py --pool 100000 --only jacobians
    python benchmarks/bench_design.py --quick         # smoke-test sizes

One CPU core: BLAS threads are set to 1 before numpy loads, and Warp runs CPU kernels on
one thread. Sections (``--only`` picks some):

* ``jacobians``: whitened candidate Jacobians per second (:func:`candidate_jacobians`,
  batches of 4096) for hand4 fingertip contacts (all six pairs, m = 1, 64 DH parameters)
  and justin19 with the external tracker (two markers, m = 6, theta, d, r, alpha + tracker
  + markers).
* ``greedy``, ``detmax``: selection of ``--n`` of ``--pool`` hand4 contact candidates,
  task D-optimal for the relative fingertip task (rank 55 of 64), from the Jacobians of the
  first section (not timed here); acceptance target of issue 16: DETMAX on 1e4 candidates,
  N = 100, <= 10 s on one CPU core. ``detmax_justin`` does the same for justin19's tracker
  (m = 6 rows per candidate: the m x m low-rank updates), plain D-optimality.
"""

from __future__ import annotations

import argparse
import os
import sys

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402
import warp as wp  # noqa: E402

if hasattr(wp.config, "quiet"):
    wp.config.quiet = True

import jwarp  # noqa: E402
from jwarp.calibration.design.optimal import (  # noqa: E402
    DesignOptions,
    candidate_jacobians,
    prior_information,
    select,
    task_information,
)
from jwarp.calibration.files import Setup, make_measurement  # noqa: E402
from jwarp.calibration.pool import draw_configurations  # noqa: E402
from jwarp.calibration.simulate.campaign import justin_tracker_setup, uniform_configurations  # noqa: E402
from jwarp.calibration.simulate.scenarios import HAND_FINGERS, hand_contact_setup  # noqa: E402
from jwarp.core.arrays import init_warp  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import timing  # noqa: E402  (benchmarks/timing.py, beside this script)

HAND_FREE = "theta,d,r,alpha"
JUSTIN_FREE = "theta,d,r,alpha,tracker,markers"
TARGET_S = 10.0
_CACHE: dict = {}


def hand_problem(args: argparse.Namespace) -> dict:
    """hand4 pool, measurement and task (drawn once per process)."""
    if "hand" not in _CACHE:
        robot = jwarp.robot("hand4")
        pairs = tuple((a, b) for i, a in enumerate(HAND_FINGERS) for b in HAND_FINGERS[i + 1:])
        setup = hand_contact_setup(pairs=pairs)
        q, meta = draw_configurations(robot, setup, args.pool, 0)
        task = make_measurement(robot, Setup(plugin="relative", robot="hand4", section={
            "end_effectors": [f"{f}_tip" for f in HAND_FINGERS]}))
        qt = uniform_configurations(robot, np.random.default_rng(1), 300)
        _CACHE["hand"] = {"robot": robot, "meas": make_measurement(robot, setup), "q": q,
                          "meta": meta, "task": task, "q_task": qt}
    return _CACHE["hand"]


def justin_problem(args: argparse.Namespace) -> dict:
    if "justin" not in _CACHE:
        robot = jwarp.robot("justin19")
        meas = make_measurement(robot, justin_tracker_setup())
        q = uniform_configurations(robot, np.random.default_rng(2), args.pool_justin)
        _CACHE["justin"] = {"robot": robot, "meas": meas, "q": q}
    return _CACHE["justin"]


def hand_matrices(args: argparse.Namespace) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    if "hand_U" not in _CACHE:
        h = hand_problem(args)
        U, space = candidate_jacobians(h["robot"], h["meas"], h["q"], HAND_FREE, meta=h["meta"])
        L, _ = task_information(h["robot"], h["task"], h["q_task"], space.names, HAND_FREE)
        _CACHE["hand_U"] = (U, prior_information(space), L)
    return _CACHE["hand_U"]


def bench_jacobians(args: argparse.Namespace) -> dict:
    out = {}
    h = hand_problem(args)
    j = justin_problem(args)
    cases = {
        "hand4_contact": lambda: candidate_jacobians(h["robot"], h["meas"], h["q"], HAND_FREE,
                                                     meta=h["meta"], device=args.device),
        "justin19_tracker": lambda: candidate_jacobians(j["robot"], j["meas"], j["q"],
                                                        JUSTIN_FREE, device=args.device),
    }
    sizes = {"hand4_contact": len(h["q"]), "justin19_tracker": len(j["q"])}
    for name, fn in cases.items():
        runs = timing.each_run([lambda r, fn=fn: fn], args.repeats)[0]
        t = runs.timing
        U = runs.results[0][0]
        n = sizes[name]
        out[name] = {"candidates": n, "rows_per_candidate": int(U.shape[1]),
                     "parameters": int(U.shape[2]), "seconds": t.figures(),
                     "candidates_per_s": {"min": n / t.median, "max": n / t.best}}
        print(f"  {name}: {n} candidates x {U.shape[1]} rows x {U.shape[2]} parameters: "
              f"{n / t.best:.0f} candidates/s (best), {n / t.median:.0f}/s (median)",
              flush=True)
    return out


def _select(args: argparse.Namespace, method: str, U: np.ndarray, prior: np.ndarray,
            L: np.ndarray | None) -> dict:
    opts = DesignOptions(n=args.n, method=method)
    runs = timing.each_run([lambda r: (lambda: select(U, prior, L, opts))], args.repeats)[0]
    res = runs.results[0]
    t = runs.timing
    fig = {"candidates": int(U.shape[0]), "n": args.n, "rows_per_candidate": int(U.shape[1]),
           "parameters": int(U.shape[2]), "task_rank": int(res.rank),
           "seconds": t.figures(), "criterion": res.criterion,
           "prior_criterion": res.prior_criterion}
    if method == "detmax":
        fig["excursions"] = res.iterations
        fig["target_s"] = TARGET_S
        fig["meets_target"] = bool(t.median <= TARGET_S)
    print(f"  {method}: {args.n} of {U.shape[0]} in {t.best:.2f} s (best), {t.median:.2f} s "
          f"(median); criterion {res.prior_criterion:.2f} -> {res.criterion:.2f}"
          + (f", {res.iterations} excursions" if method == "detmax" else ""), flush=True)
    return fig


def bench_greedy(args: argparse.Namespace) -> dict:
    return _select(args, "greedy", *hand_matrices(args))


def bench_detmax(args: argparse.Namespace) -> dict:
    return _select(args, "detmax", *hand_matrices(args))


def bench_detmax_justin(args: argparse.Namespace) -> dict:
    j = justin_problem(args)
    U, space = candidate_jacobians(j["robot"], j["meas"], j["q"], JUSTIN_FREE)
    return _select(args, "detmax", U, prior_information(space), None)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--pool", type=int, default=10000, help="hand4 candidates (default 1e4)")
    p.add_argument("--pool-justin", type=int, default=10000,
                   help="justin19 tracker candidates (default 1e4)")
    p.add_argument("--n", type=int, default=100, help="configurations to select (default 100)")
    p.add_argument("--repeats", type=int, default=3, help="timed runs per figure")
    p.add_argument("--device", default="cpu",
                   help="Warp device of the candidate Jacobians (section jacobians): cpu or "
                        "cuda[:N]")
    timing.section_options(p, "jacobians,greedy,detmax,detmax_justin")
    args = p.parse_args(argv)
    args.device = "cpu"
    init_warp()
    if args.quick:
        args.pool, args.pool_justin, args.n, args.repeats = 400, 200, 20, 1
    if min(args.pool, args.pool_justin, args.n, args.repeats) < 1 or args.n > min(
            args.pool, args.pool_justin):
        p.error("--pool, --pool-justin, --n, --repeats must be >= 1 and --n <= the pools")
    sections = {"jacobians": bench_jacobians, "greedy": bench_greedy, "detmax": bench_detmax,
                "detmax_justin": bench_detmax_justin}
    timing.run_sections(p, sections, args, f"one CPU core; {args.repeats} timed runs",
                        repeats=args.repeats, pool=args.pool, n=args.n)
    return 0


if __name__ == "__main__":
    sys.exit(main())
