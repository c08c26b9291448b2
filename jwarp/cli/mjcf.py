"""CLI subcommand ``jwarp import-mjcf``: a MuJoCo MJCF file -> a jwarp robot JSON
(docs/urdf.md, MJCF; needs ``pip install jwarp[mjcf]``)::

    jwarp import-mjcf panda.xml --out panda.json --end-effector tcp=attachment_site

``--spheres fit`` (the default) fits spheres to every body's collision geoms and samples the
self-collision pairs, as ``import-urdf`` does (:func:`jwarp.world.spherize.spherize`);
``mjcf`` keeps only the file's own sphere geoms, ``none`` writes no spheres (``--no-spheres``
is a deprecated alias of ``--spheres none``). Equality constraints the import cannot hold
(``<connect>``, ``<weld>``, ...) are warned about on stderr, naming them.

``--out`` is checked before the import; the file is written atomically. The summary line
gives the joints, frames, masses and collision geometry found (``--json``: as JSON).
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import warnings
from typing import Any

from jwarp.cli.common import CLIError, check_output, int_arg, real_arg
from jwarp.cli.urdf import (
    end_effectors_arg,
    import_error,
    import_summary,
    sphere_fit_line,
)


def _spheres_choice(args: argparse.Namespace) -> str:
    """``--spheres``, with the deprecated ``--no-spheres`` mapped to ``none``."""
    if not args.no_spheres:
        return args.spheres or "fit"
    if args.spheres not in (None, "none"):
        raise CLIError(f"--no-spheres: contradicts --spheres {args.spheres} (--no-spheres is "
                       f"the deprecated spelling of --spheres none)")
    print("jwarp: warning: --no-spheres is deprecated; use --spheres none", file=sys.stderr)
    return "none"


def cmd_import_mjcf(args: argparse.Namespace) -> int:
    from jwarp.importers.mjcf import MjcfWarning
    from jwarp.importers.robot import load_mjcf

    spheres = _spheres_choice(args)
    check_output(args.out, "--out", inputs={"MJCF": args.mjcf})
    if not os.path.isfile(args.mjcf):
        raise CLIError(f"MJCF: file not found: '{args.mjcf}'")
    eff = end_effectors_arg(args.end_effector, "BODY")
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", MjcfWarning)
            imported = load_mjcf(args.mjcf, end_effectors=eff,
                                 continuous_limit=args.continuous_limit, name=args.name,
                                 sites=not args.no_sites)
    except ImportError as e:
        raise CLIError(f"MJCF: {e}") from None
    except ValueError as e:
        raise import_error(e, "MJCF") from None
    notes = [" ".join(str(w.message).split()) for w in caught
             if issubclass(w.category, MjcfWarning)]
    for w in caught:
        if not issubclass(w.category, MjcfWarning):
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    for note in notes:
        print(f"jwarp: warning: {note}", file=sys.stderr)
    model, fit = imported.model, None
    if spheres == "fit" and any(g.kind != "sphere" for g in imported.geometries):
        from jwarp.world.spherize import SpherizeOptions, spherize

        opts = SpherizeOptions(tolerance=args.tolerance, max_spheres=args.max_spheres,
                               pair_samples=args.pair_samples)
        try:
            model, fit = spherize(imported, opts, progress=None)
        except ValueError as e:
            raise import_error(e, "MJCF") from None
    elif spheres == "none":
        model = model.copy(spheres=[])
    model.save(args.out)
    extra: dict[str, Any] = {"warnings": notes, "spheres_from": spheres}
    lines = []
    if fit is not None:
        extra["sphere_fit"] = fit.to_dict()
        lines.append(sphere_fit_line(fit, model, args.tolerance, "bodies"))
    if not model.spheres:
        lines.append("no collision spheres: plan and ik in a world refuse this robot unless "
                     "--no-collision is given")
    import_summary(model, imported.geometries, args.out, args.json, extra, lines)
    return 0


def add_subcommands(sub: Any) -> None:
    """Register ``import-mjcf`` on the CLI's subparsers."""
    s = sub.add_parser("import-mjcf", help="import a MuJoCo MJCF robot into a jwarp robot JSON "
                                           "(bodies and sites as frames, spheres fitted to the "
                                           "collision geoms; needs jwarp[mjcf])")
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
    s.add_argument("--spheres", choices=("fit", "mjcf", "none"), default=None,
                   help="collision model: fit spheres to every body's collision geoms and "
                        "sample the self-collision pairs (fit, default), only the file's own "
                        "sphere geoms (mjcf), or no spheres (none)")
    s.add_argument("--no-spheres", action="store_true",
                   help="deprecated: the same as --spheres none")
    s.add_argument("--tolerance", type=real_arg("--tolerance", 0.0, lo_open=True, unit=" m"),
                   default=0.01, metavar="M",
                   help="one-sided error of the fitted spheres [m] (0.01)")
    s.add_argument("--max-spheres", type=int_arg("--max-spheres", 1), default=None,
                   metavar="K", help="most spheres per collision geom (default: as many as "
                                     "the tolerance needs)")
    s.add_argument("--pair-samples", type=int_arg("--pair-samples", 1), default=10000,
                   metavar="N", help="random configurations of the self-collision pair "
                                     "sampling (10000)")
    s.add_argument("--json", action="store_true", help="print the summary as JSON")
    s.set_defaults(func=cmd_import_mjcf)
