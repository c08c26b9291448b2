#!/usr/bin/env python
"""Learned warm starts for the collision-free IK (thesis 3.5.3, Table 3.5) on planar5 in
random worlds: train a small unsupervised IK network (or load one with ``--model``),
evaluate it against random initial guesses on unseen worlds and targets, print the
table, and check that the network's single-guess feasibility after the solver is above
random's (exit 1 otherwise).

    python examples/learned_ik.py                 # train (about a minute on a CPU), evaluate
    python examples/learned_ik.py --quick         # a smaller network and test set
    python examples/learned_ik.py --model p5.pt   # evaluate a trained checkpoint
    python examples/learned_ik.py --save p5.pt    # keep the trained network

The same from the command line: ``jwarp train ik --robot planar5 --epochs 8 --out p5.pt``
then ``jwarp eval ik --robot planar5 --model p5.pt``.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile

import warp as wp

wp.config.quiet = True

import jwarp  # noqa: E402
from jwarp.core.arrays import init_warp  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--model", default=None, help="a planar5 checkpoint (default: train one)")
    p.add_argument("--save", default=None, help="where to keep the trained network")
    p.add_argument("--epochs", type=int, default=None)
    p.add_argument("--quick", action="store_true", help="smaller sizes")
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args(argv)
    init_warp()
    from jwarp.learn.checkpoint import load_checkpoint
    from jwarp.learn.evaluate import evaluate_ik, format_table_35
    from jwarp.learn.ik_data import make_worlds, sample_targets
    from jwarp.learn.train_ik import TrainIKOptions, train_ik

    robot, frame = "planar5", "tcp"
    if args.model:
        net = load_checkpoint(args.model, robot=robot)
        print(f"loaded {args.model}")
    else:
        path = args.save or os.path.join(tempfile.mkdtemp(prefix="learned_ik_"), "planar5.pt")
        epochs = args.epochs or (4 if args.quick else 10)
        opts = TrainIKOptions(robot=robot, frame=frame, world="random",
                              n_worlds=4 if args.quick else 8,
                              n_targets=500 if args.quick else 2000, n_val=64,
                              epochs=epochs, steps_per_epoch=40 if args.quick else 100,
                              batch_size=128 if args.quick else 256, seed=args.seed,
                              checkpoint=path)
        print(f"training an unsupervised planar5 IK network ({epochs} epochs) -> {path}")
        train_ik(opts, progress=True)
        net = load_checkpoint(path, robot=robot)
    n_worlds, n_targets = (2, 25) if args.quick else (4, 100)
    worlds = make_worlds(robot, "random", n_worlds, seed=args.seed + 200000)
    targets = [sample_targets(robot, frame, n_targets, w, seed=args.seed * 7919 + 200000 + i)[0]
               for i, w in enumerate(worlds)]
    rows = [evaluate_ik(jwarp.robot(robot), frame, worlds, targets, n_random=30, seed=args.seed),
            evaluate_ik(jwarp.robot(robot), frame, worlds, targets, warm_start=net, n_random=30,
                        seed=args.seed, name="Unsupervised")]
    print(format_table_35(rows, "Table 3.5 analogue: planar5, unseen random worlds"))
    rnd, learned = rows[0]["feasibility_1"], rows[1]["feasibility_1"]
    ok = learned > rnd
    print(f"check: single-guess feasibility of the network {100 * learned:.1f}% "
          f"{'>' if ok else '<='} random {100 * rnd:.1f}%: {'OK' if ok else 'FAILED'}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
