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
import sys
from typing import TYPE_CHECKING, Any

from jwarp.cli.common import CLIError, check_output, int_arg, real_arg

if TYPE_CHECKING:
    from jwarp.model import RobotModel


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
    if msg.startswith("protrusion: "):  # the sphere fit's bound on the option
        return CLIError(f"--{msg}")
    return CLIError(f"{what}: {msg}")


def joint_values_arg(items: list[str] | None, option: str, value_required: bool = True
                     ) -> dict[str, float | None] | None:
    """``--lock``/``--freeze`` values ``NAME=VALUE`` (``NAME`` alone when not
    ``value_required``: None, the default value) -> ``{NAME: value}`` (None when none)."""
    if not items:
        return None
    out: dict[str, float | None] = {}
    for item in items:
        name, sep, text = item.partition("=")
        name = name.strip()
        if not name or (sep and not text.strip()) or (value_required and not sep):
            form = "NAME=VALUE" if value_required else "NAME[=VALUE]"
            raise CLIError(f"{option}: expected {form}, got '{item}'")
        if name in out:
            raise CLIError(f"{option}: joint '{name}' given twice")
        if not sep:
            out[name] = None
            continue
        try:
            v = float(text)
        except ValueError:
            raise CLIError(f"{option}: {name}: expected a number [rad or m], got '{text}'") from None
        if not math.isfinite(v):
            raise CLIError(f"{option}: {name}: expected a finite number, got '{text}'")
        out[name] = v
    return out


#: GroupOptions fields -> the import-urdf options that set them (error messages)
GROUP_OPTIONS = {"group": "--group", "joints": "--joints", "lock": "--lock", "state": "--state",
                 "freeze": "--freeze", "srdf": "--srdf", "srdf_collisions": "--srdf-collisions"}


def early_srdf(args: argparse.Namespace, imported: Any) -> tuple[Any, list[str]]:
    """``--srdf`` read and checked against the URDF before any sphere fit (a bad file
    fails in well under a second, naming ``--srdf``, ``--group``, ``--state`` or
    ``--home``): (the pruned :class:`~jwarp.importers.srdf.Srdf` or None, the warning lines:
    elements jwarp does not use, names the URDF lacks)."""
    import warnings

    from jwarp.importers.groups import load_srdf
    from jwarp.importers.srdf import SrdfIgnoredWarning, SrdfWarning

    if args.srdf is None:
        return None, []
    if not os.path.isfile(args.srdf):
        raise CLIError(f"--srdf: file not found: '{args.srdf}'")
    home = home_arg(args.home)
    states = [x for x in (args.state, home if isinstance(home, str) else None) if x]
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            srdf = load_srdf(args.srdf, imported, states,
                             [args.group] if args.group else [])
            for name in states:
                srdf.state(name)     # an unknown state: SrdfError naming the states
    except ValueError as e:
        msg = " ".join(str(e).split())
        if isinstance(home, str) and args.state != home and f'"{home}"' in msg:
            raise CLIError(f"--home: {msg.removeprefix('state: ')}") from None
        raise group_error(e, args.srdf) from None
    lines = [" ".join(str(w.message).split()) for w in caught
             if issubclass(w.category, (SrdfWarning, SrdfIgnoredWarning))]
    return srdf, lines


def group_options(args: argparse.Namespace, eff: dict[str, str] | None,
                  srdf: Any = None) -> Any:
    """The :class:`~jwarp.importers.groups.GroupOptions` of ``import-urdf``'s options
    (``srdf``: the SRDF already read by :func:`early_srdf`, else ``--srdf``'s file)."""
    from jwarp.importers.groups import GroupOptions

    if args.srdf is not None and not os.path.isfile(args.srdf):
        raise CLIError(f"--srdf: file not found: '{args.srdf}'")
    if args.srdf_collisions is not None and args.srdf is None:
        raise CLIError("--srdf-collisions: only with --srdf (it says what becomes of the SRDF's "
                       "disable_collisions); without one it would be ignored")
    joints = None
    if args.joints is not None:
        joints = [j.strip() for j in args.joints.split(",") if j.strip()]
        if not joints:
            raise CLIError("--joints: expected joint names j1,j2,...")
    return GroupOptions(srdf=args.srdf if srdf is None else srdf, group=args.group,
                        joints=joints, lock=joint_values_arg(args.lock, "--lock"),
                        state=args.state,
                        freeze=joint_values_arg(args.freeze, "--freeze", value_required=False),
                        srdf_collisions=args.srdf_collisions or "srdf", end_effectors=eff)


def group_error(e: ValueError, srdf: str | None) -> CLIError:
    """An error of :func:`~jwarp.importers.groups.plan_group` naming its CLI option."""
    msg = " ".join(str(e).split())
    key, sep, rest = msg.partition(": ")
    if sep and key in GROUP_OPTIONS:
        return CLIError(f"{GROUP_OPTIONS[key]}: {rest}")
    if srdf is not None and msg.startswith(srdf):
        return CLIError(f"--srdf: {msg}")
    return import_error(e, "URDF")


def group_lines(res: Any, sampled: bool) -> tuple[list[str], dict[str, Any]]:
    """Summary lines and JSON fields of a :class:`~jwarp.importers.groups.GroupResult`
    (``sampled``: the self-collision pairs were sampled, ``--spheres fit``)."""
    lines, extra = [], {"planned_joints": res.planned, "frozen_joints": res.frozen,
                        "end_effectors_from": res.end_effectors_from}
    if res.srdf is not None:
        how = ("the SRDF's only (--srdf-collisions replace)" if res.srdf_collisions == "replace"
               else "the sampled pairs plus the SRDF's (--srdf-collisions add)"
               if res.srdf_collisions == "add" and sampled
               else "the SRDF's, the adjacent and the always colliding ones (sampled "
                    "never-colliding pairs the SRDF keeps checked are checked)"
               if sampled else "the SRDF's (no pairs sampled without --spheres fit)")
        lines.append(f"SRDF {res.srdf.path}: {res.srdf_pairs} disable_collisions; "
                     f"self-collision exclude pairs: {how} ({res.pairs_added} from the SRDF"
                     + (f", {res.pairs_dropped} sampled never-colliding pairs checked again"
                        if res.pairs_dropped else "") + ")")
        extra["srdf"] = {"path": res.srdf.path, "disable_collisions": res.srdf_pairs,
                         "pairs_added": res.pairs_added, "pairs_dropped": res.pairs_dropped,
                         "collisions": res.srdf_collisions,
                         "groups": list(res.srdf.groups),
                         "skipped": [str(k) for k in res.srdf.skipped],
                         "ignored": [f"{t} (line {n})" for t, n in res.srdf.ignored]}
    if res.frozen:
        lines.append(f"planning with {len(res.planned)} joints ({', '.join(res.planned)}); "
                     f"frozen: " + ", ".join(f"{k}={v:g} ({res.source[k]})"
                                             for k, v in res.frozen.items()))
    lines.append(f"end-effectors from: {res.end_effectors_from}")
    return lines, extra


def sphere_fit_line(fit: Any, model: RobotModel, tolerance: float, parts: str) -> str:
    """The summary line of a sphere fit (``fit``: a SpherizeReport) of an import: parts
    fitted (``parts``: "links", "bodies"), tolerance, largest one-sided error, checked
    frame pairs of the written ``model``."""
    worst = max((r["one_sided_error"] for r in fit.links), default=0.0)
    from jwarp.model.sphere_relation import relation_text

    return (f"spheres fitted to {len(fit.links)} {parts} (tolerance {tolerance} m, "
            f"{relation_text(model)}; largest one-sided error on fresh samples "
            f"{worst:.4f} m"
            f"{', from the cache' if fit.cached else ''}); "
            f"{int(model.allowed_collision_pairs.sum()) // 2} self-collision frame "
            f"pairs checked")


def import_summary(model: RobotModel, geometries: list, out: str, as_json: bool,
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


def home_arg(text: str | None) -> str | list[float] | None:
    """``--home``: an SRDF group_state name, or joint values ``q1,q2,...`` [rad or m]."""
    if text is None:
        return None
    text = text.strip()
    if not text:
        raise CLIError("--home: expected an SRDF state name or joint values q1,q2,...")
    parts = [t.strip() for t in text.split(",")]
    try:
        values = [float(t) for t in parts]
    except ValueError:
        if len(parts) > 1:
            raise CLIError(f"--home: expected numbers q1,q2,... [rad or m], got '{text}'") from None
        return text
    if not all(math.isfinite(v) for v in values):
        raise CLIError(f"--home: expected finite numbers, got '{text}'")
    return values


def home_fit_step(imported: Any, model: RobotModel, args: argparse.Namespace, srdf: Any
                  ) -> tuple[Any, Any]:
    """The import's home free of self-collision (:func:`jwarp.world.home_fit.fit_home`: a
    given home in collision refused, the default one replaced; spheres tightened), its
    warnings printed from the report."""
    import warnings

    from jwarp.world.home_fit import HomeFitOptions, HomeFitWarning, fit_home

    home = home_arg(args.home)
    try:
        with warnings.catch_warnings():  # printed from the report
            warnings.simplefilter("ignore", HomeFitWarning)
            return fit_home(imported, model, home, HomeFitOptions(tolerance=args.tolerance),
                            srdf=srdf)
    except ValueError as e:
        msg = " ".join(str(e).split())
        raise CLIError(f"--home: {msg.removeprefix('home: ').removeprefix('state: ')}") \
            from None


#: unchecked pairs named per reason in the text summary (``--json`` lists them all)
PAIRS_SHOWN = 40


def pair_lines(model: RobotModel) -> tuple[list[str], list[dict]]:
    """Summary lines naming every unchecked self-collision pair by reason, and the JSON rows
    (:func:`jwarp.model.pair_reasons.skipped_pairs`)."""
    from jwarp.model.pair_reasons import skipped_pairs, skipped_summary

    rows = skipped_pairs(model)
    by: dict[str, list[str]] = {}
    for r in rows:
        by.setdefault(r["reason"], []).append("/".join(r["links"]))
    lines = [skipped_summary(model)]
    lines += [f"  {k}: {', '.join(v[:PAIRS_SHOWN])}"
              + (f" and {len(v) - PAIRS_SHOWN} more (--json lists every pair)"
                 if len(v) > PAIRS_SHOWN else "") for k, v in by.items()]
    return lines, rows


def group_resamples(imported: Any, args: argparse.Namespace, eff: Any,
                    srdf: Any = None) -> bool:
    """Whether the import's planning group has fewer joints than the robot and keeps
    sampled pairs: then its self pairs are sampled over the group only (once, after the
    fit) and not first over every joint (the group of the kinematic model, probed)."""
    import warnings

    from jwarp.importers.groups import plan_group

    try:
        with warnings.catch_warnings():  # the import's own call reports them
            warnings.simplefilter("ignore")
            g = plan_group(imported, group_options(args, eff, srdf), model=imported.model)
    except (ValueError, CLIError):
        return False  # the import's own call reports it
    return g.model.n_dof < imported.model.n_dof and g.srdf_collisions != "replace"


def home_needs_model(args: argparse.Namespace, imported: Any) -> None:
    """``--home`` fits the collision model at a home configuration: CLIError naming it,
    before any work, when the options or the URDF leave no collision model to fit."""
    if args.home is None:
        return
    if args.no_home_fit:
        raise CLIError("--home: needs a collision model fitted at the home, not "
                       "--no-home-fit (--home is the configuration of the home fit)")
    if args.spheres == "none":
        raise CLIError("--home: needs a collision model, and --spheres none gives none to "
                       "fit at the home")
    if args.spheres == "urdf" and not imported.model.spheres:
        raise CLIError(f"--home: needs a collision model, and {args.urdf} has no sphere "
                       f"geometry, so --spheres urdf gives none (use --spheres fit)")
    if args.spheres == "fit" and not imported.model.spheres and not imported.geometries:
        raise CLIError(f"--home: needs a collision model, and {args.urdf} has no collision "
                       f"geometry to fit one to")


def cmd_import_urdf(args: argparse.Namespace) -> int:
    from jwarp.importers.robot import load_urdf, package_robot_path

    try:  # example-robot-data:NAME, robot_descriptions:NAME
        args.urdf = package_robot_path(args.urdf) or args.urdf
    except ValueError as e:
        raise CLIError(f"URDF: {' '.join(str(e).split())}") from None
    check_output(args.out, "--out", inputs={"URDF": args.urdf})
    if not os.path.isfile(args.urdf):
        raise CLIError(f"URDF: file not found: '{args.urdf}'")
    for d in args.package_dir or []:
        if not os.path.isdir(d):
            raise CLIError(f"--package-dir: not a folder: '{d}'")
    eff = end_effectors_arg(args.end_effector)
    home = home_arg(args.home)   # its form checked before the fit
    if isinstance(home, str) and args.srdf is None:
        raise CLIError(f"--home: state '{home}' needs --srdf (or give joint values q1,q2,...)")
    urdf_options = dict(end_effectors=eff, package_dirs=args.package_dir or [],
                        continuous_limit=args.continuous_limit, name=args.name,
                        require_meshes=args.require_meshes)
    try:
        imported = load_urdf(args.urdf, **urdf_options)
        from jwarp.importers.urdf_export import export_set_problems

        for problem in export_set_problems(args.urdf):  # files of an export that differ
            print(f"jwarp: warning: {problem}", file=sys.stderr)
        home_needs_model(args, imported)  # before the sphere fit
        srdf, srdf_warnings = early_srdf(args, imported)   # before the sphere fit too
        model, fit = imported.model, None
        if args.spheres == "fit" and any(g.kind != "sphere" for g in imported.geometries):
            import warnings

            from jwarp.world.spherize import (
                SphereFitWarning,
                SpherizeOptions,
                spherized_robot,
            )

            opts = SpherizeOptions(tolerance=args.tolerance, max_spheres=args.max_spheres,
                                   pair_samples=args.pair_samples, protrusion=args.protrusion,
                                   refine=args.refine, contain=not args.approximate,
                                   contain_gap=args.contain_gap)
            with warnings.catch_warnings():  # printed below from the report, each once
                warnings.simplefilter("ignore", SphereFitWarning)
                model, fit = spherized_robot(args.urdf, opts, cache=not args.no_cache,
                                             sample_pairs=not group_resamples(imported, args,
                                                                              eff, srdf),
                                             progress=None, **urdf_options)
        elif args.spheres == "none":
            model = model.copy(spheres=[])
    except ValueError as e:
        raise import_error(e, "URDF") from None
    from jwarp.importers.groups import plan_group

    try:
        import warnings

        from jwarp.importers.srdf import SrdfWarning

        with warnings.catch_warnings():  # printed from the summary (group_lines)
            warnings.simplefilter("ignore", SrdfWarning)
            grouped = plan_group(imported, group_options(args, eff, srdf), model=model)
    except ValueError as e:
        raise group_error(e, args.srdf) from None
    fitted_pairs = model.self_collision.exclude_pairs  # sampled over every joint
    model = grouped.model
    resampled = None
    if fit is not None and model.n_dof < imported.model.n_dof \
            and grouped.srdf_collisions != "replace":
        from jwarp.world.spherize import resample_pairs

        model, resampled = resample_pairs(model, fitted_pairs, opts,
                                          never=grouped.srdf is None
                                          or grouped.srdf_collisions == "add")
    home = None
    if model.spheres and not args.no_home_fit:
        model, home = home_fit_step(imported, model, args, grouped.srdf)
        if fit is not None:  # tightened spheres: their poke-out certified again
            from jwarp.world.spherize import certify_relation

            model = certify_relation(model, imported, opts.contain_gap)
    elif args.home is not None:
        raise CLIError("--home: needs a collision model (--spheres fit or urdf) and no "
                       "--no-home-fit")
    from jwarp.model.collision_pieces import stamp_pieces

    model = stamp_pieces(model)   # the fit's pieces stand for the final (edited) spheres
    model.save(args.out)
    missing = [g.mesh_uri for g in imported.geometries if g.kind == "mesh" and g.mesh_path is None]
    extra: dict[str, Any] = {"missing_meshes": missing}
    lines = []
    if fit is not None:
        extra["sphere_fit"] = fit.to_dict()
        lines.append(sphere_fit_line(fit, model, args.tolerance, "links"))
        lines += fit.link_lines()
        lines += [f"warning: {w}" for w in fit.warnings]
        if resampled is not None:
            lines.append(f"self-collision pairs sampled again over the {model.n_dof} planned "
                         f"joints (the others locked): {len(resampled.never_colliding)} never, "
                         f"{len(resampled.always_colliding)} always colliding excluded")
            extra["pairs_resampled"] = {"never": len(resampled.never_colliding),
                                        "always": len(resampled.always_colliding)}
    more_lines, more = group_lines(grouped, fit is not None)
    lines += more_lines
    lines += [f"warning: {w}" for w in srdf_warnings]
    extra.update(more)
    plines, extra["skipped_pairs"] = pair_lines(model)
    lines += plines
    if home is not None:
        lines.append(home.summary())
        lines += [f"warning: {w}" for w in home.warnings]
        extra["home_fit"] = home.to_dict()
    import_summary(model, imported.geometries, args.out, args.json, extra, lines,
                   f" ({len(missing)} mesh files not found)" if missing else "")
    return 0


def add_subcommands(sub: Any) -> None:
    """Register ``import-urdf`` on the CLI's subparsers."""
    s = sub.add_parser("import-urdf", help="import a URDF robot into a jwarp robot JSON "
                                           "(links as frames, mimic joints coupled, masses)")
    s.add_argument("urdf", metavar="URDF",
                   help="the URDF file, or example-robot-data:NAME / robot_descriptions:NAME "
                        "(a robot of that package, docs/urdf.md)")
    s.add_argument("--out", required=True, metavar="ROBOT.json", help="robot file to write")
    s.add_argument("--end-effector", action="append", metavar="NAME=LINK",
                   help="named end-effector (repeatable; default: the group's SRDF "
                        "end-effector or chain tip, else one per arm at its tool: docs/urdf.md)")
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
                   help="sample density and protrusion scale of the fitted spheres; with "
                        "--approximate their one-sided error [m] (0.01)")
    s.add_argument("--max-spheres", type=int_arg("--max-spheres", 1), default=None,
                   metavar="K", help="most spheres per link (default: as many as the "
                                     "tolerance needs)")
    s.add_argument("--protrusion", type=real_arg("--protrusion", 0.0, lo_open=True, unit=" m"),
                   default=None, metavar="M",
                   help="how far a fitted sphere may reach past the link's surface [m] "
                        "(default: tolerance/2 for thin parts such as fingers, up to "
                        "2 x tolerance for thick links; the wrist, hand and fixed base "
                        "refined to hug their parts, see --no-refine)")
    s.add_argument("--no-refine", dest="refine", action="store_false",
                   help="fit the wrist, hand and base like every other link (default: "
                        "refined fits there: spheres that reach less past the surface, "
                        "fewer free grasps refused; slower import; docs/spheres.md)")
    s.add_argument("--approximate", action="store_true",
                   help="the one-sided-error fit instead of containment: fewer spheres, but "
                        "the meshes may poke out of them by about the tolerance; the model "
                        "records each link's poke-out and planning and IK add it as margin "
                        "(docs/spheres.md)")
    s.add_argument("--contain-gap", type=real_arg("--contain-gap", 0.0, lo_open=True,
                                                  unit=" m"), default=0.001, metavar="M",
                   help="covering radius of the containment certificate's points [m] (0.001)")
    s.add_argument("--pair-samples", type=int_arg("--pair-samples", 1), default=10000,
                   metavar="N", help="random configurations of the self-collision pair "
                                     "sampling (10000)")
    s.add_argument("--no-cache", action="store_true",
                   help="fit again instead of reading the fit cache ($JWARP_CACHE/urdf, default "
                        "~/.cache/jwarp/urdf)")
    s.add_argument("--srdf", default=None, metavar="ROBOT.srdf",
                   help="MoveIt SRDF: its disable_collisions are excluded from self-collision, "
                        "its groups, group states and end-effectors can be used; read and "
                        "checked before the sphere fit; elements jwarp does not use "
                        "(passive_joint, link_sphere_approximation, ...) are named in one "
                        "warning")
    s.add_argument("--srdf-collisions", choices=("srdf", "add", "replace"), default=None,
                   help="SRDF disable_collisions: with the adjacent and always colliding "
                        "pairs (srdf, default: every pair the SRDF keeps checked is checked), "
                        "added to every sampled exclude pair, never-colliding ones too (add), "
                        "or the only ones (replace)")
    s.add_argument("--group", default=None, metavar="NAME",
                   help="plan with the joints of this SRDF group only (others locked)")
    s.add_argument("--joints", default=None, metavar="J1,J2,...",
                   help="plan with these joints only (others locked)")
    s.add_argument("--lock", action="append", metavar="NAME=VALUE",
                   help="value [rad or m] of a joint outside --group/--joints (repeatable; "
                        "default: --state's value, else 0 clipped into the limits)")
    s.add_argument("--state", default=None, metavar="NAME",
                   help="SRDF group_state giving the values of locked and frozen joints")
    s.add_argument("--freeze", action="append", metavar="NAME[=VALUE]",
                   help="freeze a joint at a value, e.g. a gripper finger (repeatable; mimic "
                        "joints follow; no value: --state's, else 0 clipped into the limits)")
    s.add_argument("--home", default=None, metavar="STATE|Q1,Q2,...",
                   help="home configuration: an SRDF group_state (with --srdf) or joint "
                        "values, refused when the URDF geometry of a checked pair touches "
                        "there (default: zeros projected into the limits, replaced when in "
                        "self-collision by the SRDF's states, the middle of the limits or a "
                        "random free configuration); spheres overlapping where the geometry "
                        "does not are tightened (docs/urdf.md)")
    s.add_argument("--no-home-fit", action="store_true",
                   help="leave the home as fitted (no check, no tightening)")
    s.add_argument("--json", action="store_true", help="print the summary as JSON")
    s.set_defaults(func=cmd_import_urdf)
