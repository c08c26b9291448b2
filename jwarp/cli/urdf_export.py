"""CLI command ``jwarp export-urdf``: a jwarp robot (e.g. a calibrated one) as URDF.

Example::

    jwarp export-urdf calibrated.json --out calibrated.urdf

Writes ``calibrated.urdf`` and, when the robot has fields URDF cannot hold (``kappa``,
``kappa_nonlinear``, ``harmonic``, ``linear_limits``), the side file
``calibrated.urdf.jwarp.json`` (the full jwarp robot), and the SRDF ``calibrated.srdf``
with the frame pairs never checked for self-collision (``--no-srdf``: none; an SRDF there
that no export of ``--out`` wrote is never overwritten). Each warning is one line
``jwarp: warning: ...`` on stderr. See ``docs/urdf_export.md``.
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

from jwarp.cli.common import CLIError, check_output, real_arg, robot_option


def cmd_export_urdf(args: argparse.Namespace) -> int:
    from jwarp.importers.urdf_export import (
        UrdfExportOptions,
        check_srdf_target,
        export_urdf,
        side_file_path,
    )

    check_output(args.out, "--out", inputs={"ROBOT": args.robot})
    side = str(side_file_path(args.out))
    check_output(side, "--out", inputs={"ROBOT": args.robot})
    if not args.no_srdf:
        from jwarp.importers.srdf import srdf_path

        check_output(str(srdf_path(args.out)), "--out", inputs={"ROBOT": args.robot})
        try:  # a user's SRDF beside --out is not overwritten
            check_srdf_target(args.out, option="--out")
        except ValueError as e:
            raise CLIError(str(e)) from None
    robot = robot_option(args.robot, "ROBOT")
    if args.name is not None and not args.name.strip():
        raise CLIError("--name: empty robot name")
    opts = UrdfExportOptions(effort=args.effort, velocity=args.velocity,
                             side_file={"auto": None, "always": True, "never": False}[args.side_file],
                             srdf=not args.no_srdf)
    for line in export_urdf(robot, args.out, name=args.name, options=opts):
        print(f"jwarp: warning: {' '.join(line.split())}", file=sys.stderr)
    print(args.out)
    return 0


def add_subcommands(sub: Any) -> None:
    """Register ``export-urdf`` on the CLI's subparsers."""
    s = sub.add_parser("export-urdf", help="write a jwarp robot (e.g. calibrated) as URDF; "
                       "elastic fields go to <out>.jwarp.json")
    s.add_argument("robot", metavar="ROBOT", help="robot name or .json (e.g. a calibration's "
                   "robot)")
    s.add_argument("--out", required=True, metavar="ROBOT.urdf", help="URDF file to write")
    s.add_argument("--name", default=None, help="URDF robot name (default: the robot's)")
    s.add_argument("--effort", type=real_arg("--effort", 0.0), default=0.0,
                   help="URDF <limit effort> of every joint [N m or N] (0: unknown)")
    s.add_argument("--velocity", type=real_arg("--velocity", 0.0), default=0.0,
                   help="URDF <limit velocity> of every joint [rad/s or m/s] (0: unknown)")
    s.add_argument("--side-file", choices=("auto", "always", "never"), default="auto",
                   help="write <out>.jwarp.json: when URDF cannot hold a field (auto), "
                        "always, never")
    s.add_argument("--no-srdf", action="store_true",
                   help="do not write <out stem>.srdf (the self-collision exclusions as "
                        "MoveIt disable_collisions)")
    s.set_defaults(func=cmd_export_urdf)
