#!/usr/bin/env python
"""Learned IK warm starts (issue 14, thesis 3.5.3): speed of the collision-free IK with a
trained network's prediction against random multi-starts, network inference, training
throughput.

    python benchmarks/bench_learn_ik.py --model justin19_shelf.pt   # a trained network
    python benchmarks/bench_learn_ik.py --quick                     # smoke-test sizes
    python benchmarks/bench_learn_ik.py --only train --device cuda  # throughput on a GPU

Sections (``--only`` picks some):

* ``ik``: one justin19 ``right_tcp`` collision-free IK at a time in the shelf world
  (margin 1 cm) on one CPU core (Warp's CPU kernels run on one thread; numpy's BLAS and
  torch are limited to one thread): grasp targets of ``bench_ik.py`` (:func:`grasp_targets`);
  a persistent :class:`jwarp.solvers.ik.IKSolver` with the network as ``warm_start``
  (its heads, plus ``--extra-random`` random seeds; the network's evaluation is timed)
  against the same solver with ``--starts`` random seeds (numpy, drawing them timed),
  interleaved target by target (:func:`timing.each_run`). Median time per target [ms]
  (min and median over ``--repeats`` passes), solved rate, median iterations.
  Targets: median <= 2 ms at >= 95 % solved (thesis: under 10 ms).
* ``inference``: the network's ``seeds`` for one target on the CPU (one torch thread)
  [ms] (:func:`timing.measure`). Target: <= 0.3 ms.
* ``train``: training throughput [samples/s] of :func:`jwarp.learn.train_ik.train_ik`
  on ``--device`` (justin19, shelf, ``--train-steps`` steps of ``--batch`` targets; the
  median over the epochs after the first).

Without ``--model`` a tiny network is trained first (justin19, shelf, a few steps; said so
in the output): its ``ik`` figures time the pipeline, they say nothing about a trained
network's solved rate.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
from typing import Any

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402
import warp as wp  # noqa: E402

wp.config.quiet = True

import jwarp  # noqa: E402
from jwarp.core.arrays import init_warp  # noqa: E402
from jwarp.core.limits import sample_within_limits  # noqa: E402
from jwarp.solvers import ik as IK  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))  # also when imported by path
import timing  # noqa: E402  (benchmarks/timing.py, beside this script)

ROBOT, FRAME, MARGIN = "justin19", "right_tcp", 0.01


def grasp_targets(n: int, seed: int = 1) -> list[np.ndarray]:
    """The grasp targets of bench_ik.py's section c (between the shelf's boards, hand into
    the shelf with noise)."""
    from bench_ik import grasp_targets as targets  # beside this script

    return targets(n, seed)


def _train_options(args: Any, steps: int, epochs: int, checkpoint: str | None) -> Any:
    from jwarp.learn.train_ik import TrainIKOptions

    return TrainIKOptions(robot=ROBOT, frame=FRAME, world="shelf", n_worlds=1,
                          n_targets=args.train_targets, n_val_worlds=1, n_val=16,
                          batch_size=args.batch, epochs=epochs, steps_per_epoch=steps,
                          device=args.device if checkpoint is None else "cpu",
                          seed=0, checkpoint=checkpoint)


def load_or_train(args: Any) -> tuple[Any, str]:
    """The network of ``--model``, or a tiny one trained here (and what it is)."""
    from jwarp.learn.checkpoint import load_checkpoint
    from jwarp.learn.train_ik import train_ik

    if args.model:
        return load_checkpoint(args.model, robot=ROBOT), f"model {args.model}"
    path = os.path.join(tempfile.mkdtemp(prefix="bench_learn_ik_"), "tiny.pt")
    steps = 3 if args.quick else 30
    train_ik(_train_options(args, steps, 1, path), progress=False)
    print(f"note: no --model given: trained a tiny network first ({steps} steps of "
          f"{args.batch} targets on the CPU); the ik figures time the pipeline, not a "
          f"trained network's solved rate", flush=True)
    return load_checkpoint(path, robot=ROBOT), f"tiny network trained here ({steps} steps)"


def section_ik(args: Any) -> dict:
    import torch

    from jwarp.world.scenes import shelf_world

    torch.set_num_threads(1)
    net = args.net
    robot = jwarp.robot(ROBOT)
    world = shelf_world()
    targets = grasp_targets(args.targets)
    n = len(targets)
    opts = IK.IKOptions(n_starts=args.starts, margin=MARGIN,
                        n_random_with_warm_start=args.extra_random)
    learned = IK.IKSolver(robot, FRAME, 1, opts, world=world, device="cpu", dtype=np.float64,
                          warm_start=net)
    rand = IK.IKSolver(robot, FRAME, 1, opts, world=world, device="cpu", dtype=np.float64)

    def solve_learned(T: np.ndarray, seed: int) -> Any:
        learned.reseed(seed)
        return learned.solve(T)

    def solve_random(T: np.ndarray, seed: int) -> Any:
        return rand.solve(T, sample_within_limits(robot, args.starts, np.random.default_rng(seed)))

    solves = {"learned": solve_learned, "random": solve_random}

    def per_target(solve: Any) -> Any:
        def make(r: int) -> Any:
            i = (r - 1) % n if r else 0
            return lambda: solve(targets[i], i)
        return make

    runs = dict(zip(solves, timing.each_run([per_target(f) for f in solves.values()],
                                            args.repeats * n)))
    out: dict = {"robot": ROBOT, "frame": FRAME, "world": "shelf", "margin_m": MARGIN,
                 "targets": n, "random_starts": args.starts,
                 "learned_extra_random": args.extra_random, "network": args.net_what,
                 "heads": int(net.config.twin) + 1}
    for k, r in runs.items():
        per_pass = [statistics.median(r.seconds[p * n:(p + 1) * n]) for p in range(args.repeats)]
        first = r.results[:n]
        out[k] = {"time_per_target_ms_median_over_targets":
                  timing.summarize(per_pass).figures(1e3),
                  "solved_rate": float(np.mean([bool(x.feasible) for x in first])),
                  "iterations_median": float(np.median([int(x.iterations) for x in first]))}
    out["speedup_learned_vs_random"] = timing.speedup(
        [statistics.median(runs["random"].seconds[p * n:(p + 1) * n]) for p in range(args.repeats)],
        [statistics.median(runs["learned"].seconds[p * n:(p + 1) * n]) for p in range(args.repeats)])
    lt = out["learned"]
    out["target_met"] = bool(lt["time_per_target_ms_median_over_targets"]["median"] <= 2.0
                             and lt["solved_rate"] >= 0.95)
    return out


def section_inference(args: Any) -> dict:
    import torch

    torch.set_num_threads(1)
    net = args.net.to("cpu")
    from jwarp.world.scenes import shelf_world

    world = shelf_world()
    T = np.asarray(grasp_targets(1)[0])[None]
    t = timing.measure(lambda: net.seeds(T, world), repeats=args.repeats)
    return {"network": args.net_what, "ms_per_target": t.figures(1e3),
            "hidden": int(net.config.hidden), "n_blocks": int(net.config.n_blocks),
            "n_bps": int(net.config.n_bps), "torch_threads": torch.get_num_threads(),
            "target_met": bool(t.median * 1e3 <= 0.3)}


def section_train(args: Any) -> dict:
    from jwarp.learn.train_ik import train_ik

    steps = 3 if args.quick else args.train_steps
    epochs = 2 if args.quick else 3
    _, history = train_ik(_train_options(args, steps, epochs, None), progress=False)
    rates = [h["samples_per_s"] for h in history if h.get("epoch", 0) >= 1]
    after_first = rates[1:] or rates
    return {"device": args.device, "machine": timing.machine(args.device),
            "batch": args.batch, "steps_per_epoch": steps, "epochs": epochs,
            "samples_per_s_per_epoch": rates,
            "samples_per_s_median_after_first": float(statistics.median(after_first))}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--model", default=None, help="a trained justin19 shelf checkpoint "
                                                 "(default: train a tiny one first)")
    p.add_argument("--device", default="cpu", help="device of the train section (cpu, cuda)")
    p.add_argument("--targets", type=int, default=40, help="targets of the ik section")
    p.add_argument("--starts", type=int, default=16, help="random seeds of the random baseline")
    p.add_argument("--extra-random", type=int, default=0,
                   help="random seeds after the network's heads (default 0)")
    p.add_argument("--batch", type=int, default=256, help="training batch (train section)")
    p.add_argument("--train-steps", type=int, default=50, help="steps per epoch (train)")
    p.add_argument("--train-targets", type=int, default=2000, help="training targets (train)")
    p.add_argument("--repeats", type=int, default=5, help="timed passes (min/median)")
    timing.section_options(p, "ik,inference,train")
    args = p.parse_args(argv)
    if args.quick:
        args.targets, args.repeats = min(args.targets, 4), 2
        args.batch, args.train_targets = min(args.batch, 32), min(args.train_targets, 128)
    init_warp()
    sections = {"ik": section_ik, "inference": section_inference, "train": section_train}
    if any(s.strip() in ("ik", "inference") for s in args.only.split(",")):
        args.net, args.net_what = load_or_train(args)
    timing.run_sections(p, sections, args, f"repeats {args.repeats} (min/median)",
                        repeats=args.repeats, model=args.model, quick=args.quick)
    return 0


if __name__ == "__main__":
    sys.exit(main())
