"""CLI subcommand ``jwarp import-mjcf``: a MuJoCo MJCF file -> a jwarp robot JSON
(docs/urdf.md, MJCF; needs ``pip install jwarp[mjcf]``)::

    jwarp import-mjcf panda.xml --out panda.json --end-effector tcp=attachment_site

``--out`` is checked before the import; the file is written atomically. The summary line
gives the joints, frames, masses and collision geometry found (``--json``: as JSON).
"""

from __future__ import annotations

import argparse
import math
import os
from typing import Any

from jwarp.cli.common import CLIError, check_output, real_arg
from jwarp.cli.urdf import end_effectors_arg, import_error, import_summary


def cmd_import_mjcf(args: argparse.Namespace) -> int:
    from jwarp.importers.robot import load_mjcf

    check_output(args.out, "--out", inputs={"MJCF": args.mjcf})
    if not os.path.isfile(args.mjcf):
        raise CLIError(f"MJCF: file not found: '{args.mjcf}'")
    eff = end_effectors_arg(args.end_effector, "BODY")
    try:
        imported = load_mjcf(args.mjcf, end_effectors=eff, continuous_limit=args.continuous_limit,
                             name=args.name, sites=not args.no_sites)
    except ImportError as e:
        raise CLIError(f"MJCF: {e}") from None
    except ValueError as e:
        raise import_error(e, "MJCF") from None
    model = imported.model
    if args.no_spheres:
        model = model.copy(spheres=[])
    model.save(args.out)
    import_summary(model, imported.geometries, args.out, args.json)
    return 0


def add_subcommands(sub: Any) -> None:
    """Register ``import-mjcf`` on the CLI's subparsers."""
    s = sub.add_parser("import-mjcf", help="import a MuJoCo MJCF robot into a jwarp robot JSON "
                                           "(bodies and sites as frames; needs jwarp[mjcf])")
    s.add_argument("mjcf", metavar="MJCF", help="the MJCF (.xml) file")
    s.add_argument("--out", required=True, metavar="ROBOT.json", help="robot file to write")
    s.add_argument("--end-effector", action="append", metavar="NAME=BODY",
                   help="named end-effector: a body or site (repeatable; default: every tip "
                        "body and every site)")
    s.add_argument("--continuous-limit", type=real_arg("--continuous-limit", 0.0, lo_open=True,
                                                        unit=" rad"), default=math.pi,
                   metavar="RAD", help="limits [-x, x] of hinge joints without a range (pi)")
    s.add_argument("--name", default=None, help="robot name (default: the model's)")
    s.add_argument("--no-sites", action="store_true", help="do not add sites as frames")
    s.add_argument("--no-spheres", action="store_true",
                   help="drop the sphere geoms from the robot's collision spheres")
    s.add_argument("--json", action="store_true", help="print the summary as JSON")
    s.set_defaults(func=cmd_import_mjcf)
