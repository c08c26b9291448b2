"""CLI subcommand ``jwarp import-mjcf``: a MuJoCo MJCF file -> a jwarp robot JSON
(docs/urdf.md, MJCF; needs ``pip install jwarp[mjcf]``)::

    jwarp import-mjcf panda.xml --out panda.json --end-effector tcp=attachment_site

``--out`` is checked before the import; the file is written atomically. The summary line
gives the joints, frames, masses and collision geometry found (``--json``: as JSON).
"""

from __future__ import annotations

import argparse
import json
import math
import os
from typing import Any

from jwarp.cli.common import CLIError, check_output, real_arg


def end_effectors_arg(items: list[str] | None) -> dict[str, str] | None:
    """``--end-effector NAME=BODY`` values -> ``{NAME: BODY}`` (None when none given)."""
    if not items:
        return None
    out = {}
    for item in items:
        alias, sep, body = item.partition("=")
        if not sep or not alias.strip() or not body.strip():
            raise CLIError(f"--end-effector: expected NAME=BODY, got '{item}'")
        if alias.strip() in out:
            raise CLIError(f"--end-effector: '{alias.strip()}' given twice")
        out[alias.strip()] = body.strip()
    return out


def cmd_import_mjcf(args: argparse.Namespace) -> int:
    from jwarp.importers.robot import load_mjcf

    check_output(args.out, "--out", inputs={"MJCF": args.mjcf})
    if not os.path.isfile(args.mjcf):
        raise CLIError(f"MJCF: file not found: '{args.mjcf}'")
    eff = end_effectors_arg(args.end_effector)
    try:
        imported = load_mjcf(args.mjcf, end_effectors=eff, continuous_limit=args.continuous_limit,
                             name=args.name, sites=not args.no_sites)
    except ImportError as e:
        raise CLIError(f"MJCF: {e}") from None
    except ValueError as e:
        msg = " ".join(str(e).split())
        if msg.startswith("end_effectors."):
            raise CLIError(f"--end-effector: {msg.partition(': ')[2]}") from None
        raise CLIError(f"MJCF: {msg}") from None
    model = imported.model
    if args.no_spheres:
        model = model.copy(spheres=[])
    model.save(args.out)
    kinds: dict[str, int] = {}
    for g in imported.geometries:
        kinds[g.kind] = kinds.get(g.kind, 0) + 1
    summary: dict[str, Any] = {
        "robot": model.name, "dof": model.n_dof, "frames": model.n_frames,
        "masses": len(model.masses), "mass_kg": sum(m.mass for m in model.masses),
        "spheres": len(model.spheres), "collision_geometry": kinds,
        "end_effectors": sorted(model.end_effectors), "out": args.out}
    if args.json:
        print(json.dumps(summary, indent=1))
    else:
        print(f"{model.name}: {model.n_dof} joints, {model.n_frames} frames, "
              f"{len(model.masses)} masses ({summary['mass_kg']:.3f} kg), "
              f"{len(model.spheres)} spheres; collision geometry "
              f"{', '.join(f'{k} {v}' for k, v in sorted(kinds.items())) or 'none'}")
        print(f"end-effectors: {', '.join(sorted(model.end_effectors))}")
        print(f"robot: {args.out}")
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
