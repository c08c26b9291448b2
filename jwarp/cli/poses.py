"""CLI subcommand ``jwarp sample-poses``: a measurement plan of configurations that satisfy
the setup's constraints (thesis 2.4.3, elastic paper IV-C), ordered by a travelling-salesman
heuristic in joint space (docs/pose_sampling.md)::

    jwarp sample-poses --setup setup.json --n 300 --out plan.csv --margin 0.03 \\
        --k-of-n 4 --max-angle 60 --order tsp

The plan CSV has the robot's joint columns (as a samples file, rad or m) in execution
order, plus ``pair`` for contact setups. Every option is checked (and ``--out`` is probed,
``--batch-size`` and ``--n`` against an estimate of their memory) before any sampling; the
file is written atomically.
"""

from __future__ import annotations

import argparse
import json
import math
from typing import TYPE_CHECKING, Any

from jwarp.cli.common import (
    CLIError,
    check_device,
    check_option_memory,
    check_output,
    int_arg,
    quiet_warp,
    real_arg,
    robot_option,
)

if TYPE_CHECKING:
    from jwarp.model import RobotModel


def _check_sampling_memory(robot: RobotModel, args: argparse.Namespace) -> None:
    """Refuse a ``--batch-size`` (candidates per kernel launch) or ``--n`` whose estimated
    memory exceeds the available memory, before any sampling."""
    from jwarp.cli.planning import config_bytes

    per = config_bytes(robot)
    for option, n, what in (("--batch-size", args.batch_size, "candidates per launch"),
                            ("--n", args.n, "poses kept")):
        check_option_memory(float(n) * per, f"{n} {what} of '{robot.name}'", option)


def cmd_sample_poses(args: argparse.Namespace) -> int:
    from jwarp.calibration.design.poses import PoseOptions, PoseSampler, write_plan
    from jwarp.calibration.design.tour import order_poses
    from jwarp.calibration.files import read_setup

    check_output(args.out, "--out", inputs={"--setup": args.setup})
    device = args.device or "cpu"
    check_device(device)
    quiet_warp()
    try:
        setup = read_setup(args.setup)
    except ValueError as e:
        raise CLIError(f"--setup: {' '.join(str(e).split())}") from None
    name = args.robot or setup.robot
    if not name:
        raise CLIError("--robot: not given and the setup file names no robot")
    robot = robot_option(name)
    _check_sampling_memory(robot, args)
    opt = PoseOptions(margin=args.margin, joint_margin=args.joint_margin, k_of_n=args.k_of_n,
                      max_angle=None if args.max_angle == 180.0 else args.max_angle,
                      single_marker=args.single_marker, require=args.require,
                      batch_size=args.batch_size, max_tries=args.max_tries, seed=args.seed,
                      device=device)
    draw = None
    if setup.plugin == "contact":   # configurations on the contact manifold (nominal model)
        from jwarp.calibration.simulate.scenarios import contact_sampler

        draw = contact_sampler(robot, setup)
    try:
        sampler = PoseSampler(robot, setup, opt, draw)
    except ValueError as e:
        msg = " ".join(str(e).split())
        for key, option in (("k_of_n", "--k-of-n"), ("single_marker", "--single-marker"),
                            ("joint_margin", "--joint-margin")):
            if msg.startswith(f"{key}:"):
                raise CLIError(f"{option}:{msg[len(key) + 1:]}") from None
        raise CLIError(f"--setup: {msg}") from None
    try:
        res = sampler.sample(args.n, progress=not args.quiet)
    except ValueError as e:
        raise CLIError(f"--n: {' '.join(str(e).split()).removeprefix('n: ')}") from None
    q, meta = res.q, res.meta
    ordering = None
    if args.order == "tsp":
        ordering = order_poses(q, metric=args.metric, runs=args.tsp_runs)
        q = q[ordering.order]
        meta = {k: v[ordering.order] for k, v in meta.items()}
    write_plan(args.out, robot, q, meta)
    summary: dict[str, Any] = {"robot": robot.name, "plugin": setup.plugin, "poses": len(q),
                               "tried": res.tried, "acceptance": res.acceptance,
                               "counts": res.counts, "out": args.out}
    if ordering is not None:
        summary.update(order=ordering.solver, length_before=ordering.before,
                       length_after=ordering.after)
    if args.json:
        print(json.dumps(summary, indent=1))
    else:
        print(f"{len(q)} poses of '{robot.name}' for '{setup.plugin}' from {res.tried} "
              f"candidates (acceptance {res.acceptance:.3g}; "
              + ", ".join(f"{k} {v}" for k, v in res.counts.items()) + ")")
        if ordering is not None:
            print(f"order: {ordering.solver}\n{ordering.summary()}")
        print(f"plan: {args.out}")
    return 0


def add_subcommands(sub: Any) -> None:
    """Register ``sample-poses`` on the CLI's subparsers."""
    s = sub.add_parser("sample-poses",
                       help="measurement plan: rejection-sampled poses (limits, self-collision, "
                            "camera visibility, contact) ordered by a TSP heuristic")
    s.add_argument("--setup", required=True, metavar="SETUP.json",
                   help="measurement setup (with 'cameras' for tracker visibility checks)")
    s.add_argument("--robot", default=None, help="robot name or .json (default: the setup's)")
    s.add_argument("--n", required=True, type=int_arg("--n", 1), help="number of poses")
    s.add_argument("--out", required=True, metavar="PLAN.csv", help="ordered plan (CSV)")
    s.add_argument("--margin", type=real_arg("--margin", 0.0, 1.0, unit=" m"), default=0.02,
                   help="self-collision safety margin between sphere surfaces [m] (0.02)")
    s.add_argument("--joint-margin", type=real_arg("--joint-margin", 0.0, math.pi),
                   default=0.0, help="distance kept from the joint limits [rad or m] (0)")
    s.add_argument("--k-of-n", type=int_arg("--k-of-n", 1), default=1,
                   help="cameras that must see a marker (1)")
    s.add_argument("--max-angle", type=real_arg("--max-angle", 0.0, 180.0, lo_open=True,
                                                unit=" deg"), default=60.0,
                   help="largest angle between marker normal and the ray to a camera [deg] "
                        "(60; 180: no facing test)")
    s.add_argument("--single-marker", action="store_true",
                   help="reject poses where a second marker is visible to any camera")
    s.add_argument("--require", choices=("any", "all"), default="any",
                   help="at least one marker seen (any) or every marker (all)")
    s.add_argument("--order", choices=("tsp", "none"), default="tsp",
                   help="order the plan by a TSP heuristic in joint space (LKH) or keep the "
                        "draw order")
    s.add_argument("--metric", choices=("euclidean", "max"), default="euclidean",
                   help="joint-space distance the ordering minimizes")
    s.add_argument("--tsp-runs", type=int_arg("--tsp-runs", 1), default=1,
                   help="LKH runs (1)")
    s.add_argument("--batch-size", type=int_arg("--batch-size", 1), default=1 << 16,
                   help="candidates per kernel launch (65536; CUDA: 1e6-1e7)")
    s.add_argument("--max-tries", type=int_arg("--max-tries", 1), default=50_000_000,
                   help="most candidates drawn")
    s.add_argument("--seed", type=int_arg("--seed", 0), default=0, help="random seed")
    s.add_argument("--device", default=None, help="Warp device (cpu default, cuda)")
    s.add_argument("--quiet", action="store_true", help="no progress bar")
    s.add_argument("--json", action="store_true", help="print the summary as JSON")
    s.set_defaults(func=cmd_sample_poses)
