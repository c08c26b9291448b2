"""CLI subcommand ``jwarp import-urdf``: a URDF file -> a jwarp robot JSON (docs/urdf.md)::

    jwarp import-urdf panda.urdf --out panda.json --end-effector tcp=panda_hand_tcp \\
        --package-dir /opt/ros/share

``--out`` is checked before the import; the file is written atomically. The summary line
gives the joints, frames, masses and collision geometry found (``--json``: as JSON).
"""

from __future__ import annotations

import argparse
import json
import math
import os
from typing import Any

from jwarp.cli.common import CLIError, check_output, int_arg, real_arg


def end_effectors_arg(items: list[str] | None, element: str = "LINK") -> dict[str, str] | None:
    """``--end-effector NAME=<element>`` values -> ``{NAME: element}`` (None when none)."""
    if not items:
        return None
    out = {}
    for item in items:
        alias, sep, target = item.partition("=")
        if not sep or not alias.strip() or not target.strip():
            raise CLIError(f"--end-effector: expected NAME={element}, got '{item}'")
        if alias.strip() in out:
            raise CLIError(f"--end-effector: '{alias.strip()}' given twice")
        out[alias.strip()] = target.strip()
    return out


def import_error(e: ValueError, what: str) -> CLIError:
    """An importer's ValueError as the CLI's one-line error: ``--end-effector`` for the
    end-effector table, else the file (``what``: URDF, MJCF)."""
    msg = " ".join(str(e).split())
    if msg.startswith("end_effectors."):
        return CLIError(f"--end-effector: {msg.partition(': ')[2]}")
    return CLIError(f"{what}: {msg}")


def import_summary(model: Any, geometries: list, out: str, as_json: bool,
                   extra: dict[str, Any] | None = None, lines: list[str] | None = None,
                   note: str = "") -> None:
    """Print what an import wrote: joints, frames, masses, spheres, collision geometry by
    kind, end-effectors (``--json``: as JSON with ``extra``; else text with ``note`` after
    the geometry and ``lines`` before the end-effectors)."""
    kinds: dict[str, int] = {}
    for g in geometries:
        kinds[g.kind] = kinds.get(g.kind, 0) + 1
    summary: dict[str, Any] = {
        "robot": model.name, "dof": model.n_dof, "frames": model.n_frames,
        "masses": len(model.masses), "mass_kg": sum(m.mass for m in model.masses),
        "spheres": len(model.spheres), "collision_geometry": kinds,
        "end_effectors": sorted(model.end_effectors), "out": out, **(extra or {})}
    if as_json:
        print(json.dumps(summary, indent=1))
        return
    print(f"{model.name}: {model.n_dof} joints, {model.n_frames} frames, "
          f"{len(model.masses)} masses ({summary['mass_kg']:.3f} kg), "
          f"{len(model.spheres)} spheres; collision geometry "
          f"{', '.join(f'{k} {v}' for k, v in sorted(kinds.items())) or 'none'}{note}")
    for line in lines or []:
        print(line)
    print(f"end-effectors: {', '.join(sorted(model.end_effectors))}")
    print(f"robot: {out}")


def cmd_import_urdf(args: argparse.Namespace) -> int:
    from jwarp.importers.robot import load_urdf

    check_output(args.out, "--out", inputs={"URDF": args.urdf})
    if not os.path.isfile(args.urdf):
        raise CLIError(f"URDF: file not found: '{args.urdf}'")
    for d in args.package_dir or []:
        if not os.path.isdir(d):
            raise CLIError(f"--package-dir: not a folder: '{d}'")
    eff = end_effectors_arg(args.end_effector)
    urdf_options = dict(end_effectors=eff, package_dirs=args.package_dir or [],
                        continuous_limit=args.continuous_limit, name=args.name,
                        require_meshes=args.require_meshes)
    try:
        imported = load_urdf(args.urdf, **urdf_options)
        model, fit = imported.model, None
        if args.spheres == "fit" and any(g.kind != "sphere" for g in imported.geometries):
            from jwarp.world.spherize import SpherizeOptions, spherized_robot

            opts = SpherizeOptions(tolerance=args.tolerance, max_spheres=args.max_spheres,
                                   pair_samples=args.pair_samples)
            model, fit = spherized_robot(args.urdf, opts, cache=not args.no_cache,
                                         **urdf_options)
        elif args.spheres == "none":
            model = model.copy(spheres=[])
    except ValueError as e:
        raise import_error(e, "URDF") from None
    model.save(args.out)
    missing = [g.mesh_uri for g in imported.geometries if g.kind == "mesh" and g.mesh_path is None]
    extra: dict[str, Any] = {"missing_meshes": missing}
    lines = []
    if fit is not None:
        extra["sphere_fit"] = fit.to_dict()
        worst = max((r["one_sided_error"] for r in fit.links), default=0.0)
        lines.append(f"spheres fitted to {len(fit.links)} links (tolerance {args.tolerance} m, "
                     f"largest one-sided error {worst:.4f} m"
                     f"{', from the cache' if fit.cached else ''}); "
                     f"{int(model.allowed_collision_pairs.sum()) // 2} self-collision frame "
                     f"pairs checked")
    import_summary(model, imported.geometries, args.out, args.json, extra, lines,
                   f" ({len(missing)} mesh files not found)" if missing else "")
    return 0


def add_subcommands(sub: Any) -> None:
    """Register ``import-urdf`` on the CLI's subparsers."""
    s = sub.add_parser("import-urdf", help="import a URDF robot into a jwarp robot JSON "
                                           "(links as frames, mimic joints coupled, masses)")
    s.add_argument("urdf", metavar="URDF", help="the URDF file")
    s.add_argument("--out", required=True, metavar="ROBOT.json", help="robot file to write")
    s.add_argument("--end-effector", action="append", metavar="NAME=LINK",
                   help="named end-effector (repeatable; default: every tip link)")
    s.add_argument("--package-dir", action="append", metavar="DIR",
                   help="folder searched for package:// mesh paths (repeatable)")
    s.add_argument("--continuous-limit", type=real_arg("--continuous-limit", 0.0, lo_open=True,
                                                        unit=" rad"), default=math.pi,
                   metavar="RAD", help="limits [-x, x] of continuous joints (pi)")
    s.add_argument("--name", default=None, help="robot name (default: the URDF's)")
    s.add_argument("--require-meshes", action="store_true",
                   help="fail if a collision mesh file is not found")
    s.add_argument("--spheres", choices=("fit", "urdf", "none"), default="fit",
                   help="collision model: fit spheres to every link's collision geometry and "
                        "sample the self-collision pairs (fit, default), only the URDF's own "
                        "sphere geometry (urdf), or no spheres (none)")
    s.add_argument("--tolerance", type=real_arg("--tolerance", 0.0, lo_open=True, unit=" m"),
                   default=0.01, metavar="M",
                   help="one-sided error of the fitted spheres [m] (0.01)")
    s.add_argument("--max-spheres", type=int_arg("--max-spheres", 1), default=None,
                   metavar="K", help="most spheres per collision geometry (default: as many "
                                     "as the tolerance needs)")
    s.add_argument("--pair-samples", type=int_arg("--pair-samples", 1), default=10000,
                   metavar="N", help="random configurations of the self-collision pair "
                                     "sampling (10000)")
    s.add_argument("--no-cache", action="store_true",
                   help="fit again instead of reading the fit cache ($JWARP_CACHE or "
                        "~/.cache/jwarp)")
    s.add_argument("--json", action="store_true", help="print the summary as JSON")
    s.set_defaults(func=cmd_import_urdf)
