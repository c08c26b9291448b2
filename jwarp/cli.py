"""Command line interface: ``jwarp robots | info | fk | show`` (kinematics, here), and
``calibrate | simulate-campaign`` (:mod:`jwarp.cli_calibration`).

Examples::

    jwarp robots
    jwarp info justin19 --json
    jwarp fk justin19 --q zeros --elastic
    jwarp fk arm7 --q 0,30,0,-60,0,45,0 --deg --json
    jwarp show justin19 --q zeros --q 0,0,45,... --elastic --save justin.rrd

Joint values ``--q`` are comma-separated, in rad (m for prismatic joints), or ``zeros``;
``--deg`` reads revolute joints in degrees. A value starting with a minus sign may follow
``--q`` directly (``--q -0.5,0,...``; any option's negative number, ``-inf`` and ``-nan``
too). The CLI computes in float64 on the CPU unless told otherwise.

Errors and exit status (:func:`main`):

* 0 success; 1 ``plan``/``ik`` found no feasible path/solution; 2 any error; 130
  interrupted (Ctrl-C: ``jwarp: interrupted``, no traceback, no partial output file).
* An error is ONE line ``jwarp: error: <option>: <what is wrong>`` on stderr (argparse's
  own usage errors, e.g. a missing required option, print the usage lines before it).
  Option values are checked before any work: numbers must be finite and in range
  (``--lam`` in (0, 1], counts >= 1, ``--max-iter`` >= 0, ...), sizes are checked against
  an estimate of the memory they need (:mod:`jwarp.memory`; the error gives the figure),
  ``--device`` must exist, and every output path (``--save``, ``--rerun``) must be
  writable (its folder exists, it is not a folder) before the computation starts. Files
  are written atomically (:class:`jwarp.atomic.AtomicFile`): an error or interrupt leaves
  no temporary file and the old file as it was.
* Exceptions reach :func:`main` as one line: :class:`CLIError`, ValueError, TypeError,
  OSError (files), ``zipfile.BadZipFile`` are input errors and print their message;
  OverflowError prints ``numeric overflow: ...``, MemoryError (and Warp's RuntimeError
  "Failed to allocate ...") ``out of memory: ...``. Any other exception (KeyError,
  IndexError, other RuntimeErrors, ...) is unexpected, possibly a bug: it prints
  ``jwarp: error: <Type>: <message> (run with JWARP_DEBUG=1 for the traceback)``, also with
  status 2. With the environment variable ``JWARP_DEBUG=1`` every exception other than
  CLIError (and --help/--version's exit) is raised with its traceback.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import sys
import zipfile
from typing import Any, Callable, Sequence

import numpy as np

#: default compliance of ``fk --elastic`` for a robot without its own kappa [rad/(N m)]
DEFAULT_KAPPA = 1e-4
#: default most torque updates of ``--elastic`` (stops earlier once converged)
DEFAULT_MAX_ITER = 50
#: modules with an ``add_subcommands(subparsers)`` function
SUBCOMMAND_MODULES = ("jwarp.cli_calibration", "jwarp.cli_planning")


class CLIError(Exception):
    """A usage or input error: reported as ``jwarp: error: ...``, exit status 2."""

    def __init__(self, message: str, usage: str = ""):
        super().__init__(message)
        self.usage = usage


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # type: ignore[override]
        # "argument --lam: invalid float value: 'x'" -> "--lam: invalid float value: 'x'"
        message = re.sub(r"^argument ([^:\s]+?)(?:/[^:\s]+)?: ", r"\1: ", message)
        raise CLIError(message, usage=self.format_usage())


# ------------------------------------------------------------------ option types
def int_arg(option: str, lo: int, hi: int | None = None) -> Callable[[str], int]:
    """An argparse ``type`` for an integer option in [lo, hi] (hi None: no upper bound);
    anything else is a :class:`CLIError` naming ``option`` (one line, no usage)."""
    def parse(text: str) -> int:
        try:
            v = int(text.strip())
        except ValueError:
            v = None
        if v is None or v < lo or (hi is not None and v > hi):
            rng = f">= {lo}" if hi is None else f"in [{lo}, {hi}]"
            raise CLIError(f"{option}: expected an integer {rng}, got {text!r}")
        return v

    parse.__name__ = "integer"  # argparse names the type in some messages
    return parse


def real_arg(option: str, lo: float = -math.inf, hi: float = math.inf, *,
             lo_open: bool = False, hi_open: bool = False,
             unit: str = "") -> Callable[[str], float]:
    """An argparse ``type`` for a finite real option in the interval from ``lo`` to ``hi``
    (``lo_open``/``hi_open``: excluding the bound); NaN, inf or out of range is a
    :class:`CLIError` naming ``option``."""
    if math.isinf(lo) and math.isinf(hi):
        what = "a finite number"
    elif math.isinf(hi):
        what = f"a number {'>' if lo_open else '>='} {lo:g}"
    elif math.isinf(lo):
        what = f"a number {'<' if hi_open else '<='} {hi:g}"
    else:
        what = f"a number in {'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"

    def parse(text: str) -> float:
        try:
            v = float(text.strip())
        except ValueError:
            v = math.nan
        above = v > lo if lo_open else v >= lo
        below = v < hi if hi_open else v <= hi
        if not (math.isfinite(v) and above and below):
            raise CLIError(f"{option}: expected {what}{unit}, got {text!r}")
        return v

    parse.__name__ = "number"
    return parse


def check_dtype_range(values: Any, dtype: Any, option: str) -> None:
    """CLIError naming ``option`` if finite ``values`` overflow the computing ``dtype``
    (1e39 is finite in float64, inf in float32)."""
    a = np.asarray(values, np.float64)
    with np.errstate(over="ignore", invalid="ignore"):
        ok = bool(np.all(np.isfinite(a.astype(dtype))))
    if not ok:
        raise CLIError(f"{option}: values overflow {np.dtype(dtype).name} (largest magnitude "
                       f"{float(np.finfo(dtype).max):.3g}); use --dtype float64")


def check_device(name: str, option: str = "--device") -> None:
    """CLIError naming ``option`` unless Warp has the device ``name`` (checked before any
    work; e.g. ``cuda:0`` on a machine without a GPU)."""
    from jwarp.arrays import resolve_device

    try:
        resolve_device(name)
    except (ValueError, TypeError, RuntimeError) as e:
        msg = " ".join(str(e).split())
        raise CLIError(f"{option}: {msg.removeprefix('device: ')}") from None


def check_output(path: str, option: str, rerun: bool = False,
                 inputs: dict[str, str | None] | None = None) -> None:
    """Check an output path before any work: CLIError naming ``option`` if it is empty, a
    folder, in a missing or unwritable folder (a temporary file is made there and removed:
    :class:`jwarp.atomic.AtomicFile`), one of the existing input files ``inputs``
    ({option: path}), or, with ``rerun``, if rerun-sdk is missing."""
    from jwarp.atomic import AtomicFile

    if not path or not path.strip():
        raise CLIError(f"{option}: empty file name")
    for opt, src in (inputs or {}).items():
        if src and os.path.isfile(src) and os.path.realpath(src) == os.path.realpath(path):
            raise CLIError(f"{option}: {path} is also {opt}; give another file")
    if rerun:
        from jwarp.viz import _rerun

        try:
            _rerun()
        except ImportError as e:
            raise CLIError(f"{option}: {e}") from None
    try:
        AtomicFile(path, option=option).discard()
    except ValueError as e:
        raise CLIError(str(e)) from None


# ------------------------------------------------------------------ parsing helpers
def _robot(name: str):
    from jwarp.registry import robot

    return robot(name)


def parse_q(text: str, model: Any, deg: bool = False, option: str = "--q") -> np.ndarray:
    """Parse ``v1,v2,...`` or ``zeros`` into (n_dof,) joint values [rad or m]."""
    text = text.strip()
    n = model.n_dof
    if text.lower() in ("zeros", "zero", "0"):
        return np.zeros(n)
    parts = [p.strip() for p in text.split(",")]
    if parts and parts[-1] == "":
        parts = parts[:-1]  # tolerate a trailing comma
    values = []
    for k, p in enumerate(parts):
        try:
            v = float(p)
        except ValueError:
            raise CLIError(f"{option}: value {k + 1} ({p!r}) is not a number") from None
        if not math.isfinite(v):
            raise CLIError(f"{option}: value {k + 1} is {p}; joint values must be finite")
        values.append(v)
    if len(values) != n:
        raise CLIError(f"{option}: robot '{model.name}' has {n} joints "
                       f"({', '.join(model.joint_names)}), got {len(values)} values")
    q = np.array(values, np.float64)
    if deg:
        revolute = np.array([j.type == "revolute" for j in model.joints])
        q = np.where(revolute, np.deg2rad(q), q)
    return q


def parse_kappa(text: str | None, model: Any) -> tuple[Any, str]:
    """The kappa for fk_elastic and where it came from ('--kappa', 'robot' or 'default')."""
    if text is not None:
        parts = [p.strip() for p in text.split(",") if p.strip()]
        try:
            vals = [float(p) for p in parts]
        except ValueError:
            raise CLIError(f"--kappa: expected a number or 3 numbers [alpha,beta,theta] "
                           f"in rad/(N m), got {text!r}") from None
        if len(vals) not in (1, 3):
            raise CLIError(f"--kappa: expected 1 or 3 values [alpha,beta,theta], got {len(vals)}")
        if not all(math.isfinite(v) and v >= 0 for v in vals):
            raise CLIError(f"--kappa: compliances must be finite and >= 0, got {text!r}")
        return (vals[0] if len(vals) == 1 else vals), "--kappa"
    if np.any(model.kappa):
        return None, "robot"
    return DEFAULT_KAPPA, "default"


_NEGATIVE = re.compile(r"^-(\d|\.\d|inf|nan)", re.IGNORECASE)


def _value_options(parser: argparse.ArgumentParser) -> set[str]:
    """The option strings (``--q``, ``--lam``, ...) of ``parser`` and its subcommands that
    take a value."""
    found: set[str] = set()
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                found |= _value_options(sub)
        elif action.option_strings and action.nargs != 0:
            found.update(action.option_strings)
    return found


def _fix_negative_values(argv: list[str], options: set[str] | None = None) -> list[str]:
    """Let ``--q -0.5,0,...`` mean ``--q=-0.5,0,...`` (argparse would take it for an
    option), for every option in ``options`` (default: the joint value options) and
    values that start like a negative number, ``-inf`` or ``-nan``."""
    if options is None:
        options = {"--q", "--kappa", "--start", "--goal", "--target"}
    out: list[str] = []
    i = 0
    while i < len(argv):
        a = argv[i]
        if a in options and i + 1 < len(argv) and _NEGATIVE.match(argv[i + 1]):
            out.append(f"{a}={argv[i + 1]}")
            i += 2
            continue
        out.append(a)
        i += 1
    return out


def _quiet_warp() -> None:
    """Keep Warp's greeting and module-load messages off stdout (JSON output)."""
    import warp as wp

    if hasattr(wp.config, "quiet"):
        wp.config.quiet = True
    if hasattr(wp, "LOG_WARNING") and hasattr(wp.config, "log_level"):
        wp.config.log_level = max(wp.config.log_level, wp.LOG_WARNING)


def _warn_limits(model: Any, q: np.ndarray) -> None:
    for j, (lo, hi) in enumerate(model.joint_limits):
        if not lo - 1e-12 <= q[j] <= hi + 1e-12:
            print(f"jwarp: warning: {model.joint_names[j]} = {q[j]:+.6g} outside its limits "
                  f"[{lo:+.6g}, {hi:+.6g}]", file=sys.stderr)
    for lim in model.linear_limits:
        v = sum(c * q[j] for j, c in zip(lim.joints, lim.coefficients))
        if not lim.lower - 1e-12 <= v <= lim.upper + 1e-12:
            terms = " + ".join(f"{c:g}*{model.joint_names[j]}"
                               for j, c in zip(lim.joints, lim.coefficients))
            print(f"jwarp: warning: {terms} = {v:+.6g} outside [{lim.lower:+.6g}, "
                  f"{lim.upper:+.6g}]", file=sys.stderr)


def dumps(obj: Any, indent: int = 0) -> str:
    """JSON with one line per object key and lists of numbers kept on one line."""
    pad = " " * (indent + 1)
    if isinstance(obj, dict) and obj:
        items = [f"{pad}{json.dumps(str(k))}: {dumps(v, indent + 1)}" for k, v in obj.items()]
        return "{\n" + ",\n".join(items) + "\n" + " " * indent + "}"
    if isinstance(obj, list) and any(isinstance(v, (dict, list)) for v in obj):
        items = [pad + dumps(v, indent + 1) for v in obj]
        return "[\n" + ",\n".join(items) + "\n" + " " * indent + "]"
    return json.dumps(obj)


def _elastic_options(args: argparse.Namespace) -> None:
    """Reject elastic options without --elastic; fill in their defaults."""
    if not args.elastic:
        for opt, val in (("--kappa", args.kappa), ("--lam", args.lam),
                         ("--max-iter", args.max_iter)):
            if val is not None:
                raise CLIError(f"{opt}: only meaningful with --elastic")
    args.lam = 1.0 if args.lam is None else args.lam
    args.max_iter = DEFAULT_MAX_ITER if args.max_iter is None else args.max_iter


def _dtype(name: str) -> Any:
    return {"float64": np.float64, "float32": np.float32}[name]


# ------------------------------------------------------------------ commands
def _plugin_warnings_one_line() -> None:
    """Show :class:`~jwarp.registry.PluginWarning` as one ``jwarp: warning: ...`` line on
    stderr (a broken plugin is reported, never a traceback); other warnings as before."""
    import warnings

    show = warnings.showwarning
    if getattr(show, "_jwarp_plugin_lines", False):
        return

    def showwarning(message, category, filename, lineno, file=None, line=None):  # noqa: ANN001
        from jwarp.registry import PluginWarning

        if isinstance(category, type) and issubclass(category, PluginWarning):
            print(f"jwarp: warning: {message}", file=sys.stderr if file is None else file)
        else:
            show(message, category, filename, lineno, file, line)

    showwarning._jwarp_plugin_lines = True  # type: ignore[attr-defined]
    warnings.showwarning = showwarning


def cmd_robots(args: argparse.Namespace) -> int:
    """List the robots; broken plugins and robots whose factory fails are reported as
    ``jwarp: warning: ...`` lines on stderr (the list itself, also ``--json``, stays a list)."""
    import warnings

    from jwarp.registry import PluginWarning, plugin_problems, robots

    rows = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PluginWarning)  # printed below, each once
        names = robots()
        problems = plugin_problems()
        for name in names:
            try:
                m = _robot(name)
            except Exception as e:  # noqa: BLE001 - a plugin's factory may fail in any way
                problems.append(" ".join(str(e).split()) + "; not listed")
                continue
            rows.append({"name": name, "dof": m.n_dof, "frames": m.n_frames,
                         "end_effectors": list(m.end_effectors), "spheres": len(m.spheres),
                         "capsules": len(m.capsules), "masses": len(m.masses),
                         "description": m.description})
    for message in problems:
        print(f"jwarp: warning: {message}", file=sys.stderr)
    if args.json:
        print(dumps(rows))
        return 0
    print(f"{'robot':<12} {'DoF':>4} {'frames':>7}  end-effectors")
    for r in rows:
        print(f"{r['name']:<12} {r['dof']:>4} {r['frames']:>7}  {', '.join(r['end_effectors'])}")
    return 0


def cmd_info(args: argparse.Namespace) -> int:
    m = _robot(args.robot)
    if args.json:
        print(dumps(m.to_dict()))
    else:
        print(m.summary())
    return 0


def _positions(model: Any, frames: np.ndarray) -> dict[str, list[float]]:
    return {name: frames[i, :3, 3].tolist() for i, name in enumerate(model.frame_names)}


def cmd_fk(args: argparse.Namespace) -> int:
    model = _robot(args.robot)
    _elastic_options(args)
    q = parse_q(args.q, model, args.deg)
    kappa, source = parse_kappa(args.kappa, model) if args.elastic else (None, "")
    dtype = _dtype(args.dtype)
    check_dtype_range(q, dtype, "--q")
    if kappa is not None:
        check_dtype_range(kappa, dtype, "--kappa")
    _quiet_warp()
    check_device(args.device)
    _warn_limits(model, q)
    from jwarp import kinematics

    rigid = np.asarray(kinematics.fk(model, q.astype(dtype), device=args.device, dtype=dtype),
                       np.float64)
    out: dict[str, Any] = {"robot": model.name, "q": q.tolist(), "device": args.device,
                           "dtype": args.dtype, "elastic": bool(args.elastic)}
    frames = rigid
    sags: dict[str, np.ndarray] = {}
    if args.elastic:
        res = kinematics.fk_elastic(model, q.astype(dtype), kappa, lam=args.lam,
                                    max_iter=args.max_iter, device=args.device, dtype=dtype)
        frames = np.asarray(res.frames, np.float64)
        sags = {ee: 1e3 * (frames[fi, :3, 3] - rigid[fi, :3, 3])
                for ee, fi in model.end_effectors.items()}
        out.update({
            "kappa": kappa, "kappa_source": source, "lam": args.lam, "max_iter": args.max_iter,
            "iterations": int(np.asarray(res.iterations)),
            "converged": bool(np.asarray(res.converged)),
        })
    out["frames"] = _positions(model, frames)
    out["end_effectors"] = {ee: frames[fi, :3, 3].tolist() for ee, fi in model.end_effectors.items()}
    if args.elastic:
        out["rigid_frames"] = _positions(model, rigid)
        out["sag_mm"] = {ee: {"dx": float(s[0]), "dy": float(s[1]), "dz": float(s[2]),
                              "norm": float(np.linalg.norm(s))} for ee, s in sags.items()}
    if args.json:
        print(dumps(out))
        return 0

    kind = "elastic" if args.elastic else "rigid"
    print(f"robot {model.name}: {kind} FK, {args.dtype} on {args.device}")
    print(f"q [rad/m] = [{', '.join(f'{v:.6g}' for v in q)}]")
    eff_of: dict[int, list[str]] = {}
    for ee, fi in model.end_effectors.items():
        eff_of.setdefault(fi, []).append(ee)
    head = f"{'frame':<16} {'x [m]':>10} {'y [m]':>10} {'z [m]':>10}"
    print(head + ("  sag [mm]" if args.elastic else ""))
    for i, name in enumerate(model.frame_names):
        p = frames[i, :3, 3]
        line = f"{name:<16} {p[0]:>10.6f} {p[1]:>10.6f} {p[2]:>10.6f}"
        if args.elastic:
            line += f"  {1e3 * np.linalg.norm(p - rigid[i, :3, 3]):8.3f}"
        if i in eff_of:
            line += "  <- end-effector" + "".join(f" {e}" for e in eff_of[i] if e != name)
        print(line)
    if args.elastic:
        ksrc = {"robot": "the robot's own kappa",
                "default": f"{DEFAULT_KAPPA:g} rad/(N m) on all axes (default)",
                "--kappa": f"{out['kappa']} rad/(N m)"}[out["kappa_source"]]
        print(f"elastic: kappa = {ksrc}, lambda = {args.lam:g}, iterations = "
              f"{out['iterations']}, converged = {'yes' if out['converged'] else 'NO'}")
        if not out["converged"]:
            print(f"jwarp: warning: the elastic iteration did not converge in {args.max_iter} "
                  f"updates; raise --max-iter or lower --lam", file=sys.stderr)
        print(f"{'end-effector':<16} {'dx [mm]':>9} {'dy [mm]':>9} {'dz [mm]':>9} {'|sag| [mm]':>11}")
        for ee, s in sags.items():
            print(f"{ee:<16} {s[0]:>9.3f} {s[1]:>9.3f} {s[2]:>9.3f} {np.linalg.norm(s):>11.3f}")
    return 0


def cmd_show(args: argparse.Namespace) -> int:
    model = _robot(args.robot)
    qs = [parse_q(t, model, args.deg, option=f"--q #{k + 1}")
          for k, t in enumerate(args.q or ["zeros"])]
    _elastic_options(args)
    kappa = None
    if args.elastic:
        kappa, _ = parse_kappa(args.kappa, model)
        if kappa is None:
            kappa = model.kappa
    # the output path before any work
    check_output(args.save, "--save", rerun=True, inputs={"robot": args.robot})
    for q in qs:
        _warn_limits(model, q)
    _quiet_warp()
    from jwarp.viz import save_robot_rrd

    try:
        path = save_robot_rrd(model, np.stack(qs), args.save, elastic_kappa=kappa, lam=args.lam,
                              max_iter=args.max_iter, option="--save")
    except ImportError as e:
        raise CLIError(f"--save: {e}") from None
    print(f"wrote {path} ({len(qs)} configuration{'s' if len(qs) != 1 else ''} of "
          f"'{model.name}'{', rigid and elastic' if args.elastic else ''}); "
          f"view with: rerun {path}")
    return 0


# ------------------------------------------------------------------ parser
def build_parser() -> argparse.ArgumentParser:
    from jwarp import __version__

    p = _Parser(prog="jwarp", description="jwarp: fast batched (elastic) robot kinematics "
                "on NVIDIA Warp. Units: m, rad, N m.")
    p.add_argument("--version", action="version", version=f"jwarp {__version__}")
    sub = p.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True

    s = sub.add_parser("robots", help="list the registered robots")
    s.add_argument("--json", action="store_true", help="print a JSON list")
    s.set_defaults(func=cmd_robots)

    s = sub.add_parser("info", help="describe a robot (joints, frames, bodies)")
    s.add_argument("robot", help="robot name (see 'jwarp robots') or path to a robot .json")
    s.add_argument("--json", action="store_true", help="print the robot's JSON document")
    s.set_defaults(func=cmd_info)

    def elastic_opts(s: argparse.ArgumentParser) -> None:
        s.add_argument("--deg", action="store_true", help="revolute joint values in degrees")
        s.add_argument("--elastic", action="store_true",
                       help="elastic FK: frames in the gravity torque equilibrium")
        s.add_argument("--kappa", default=None, metavar="K",
                       help="compliance in rad/(N m): one value for all axes or alpha,beta,theta "
                            f"(default: the robot's own kappa, else {DEFAULT_KAPPA:g})")
        s.add_argument("--lam", type=real_arg("--lam", 0.0, 1.0, lo_open=True), default=None,
                       metavar="L", help="damping of the fixed-point iteration, in (0, 1] "
                                         "(default 1)")
        s.add_argument("--max-iter", type=int_arg("--max-iter", 0), default=None, metavar="N",
                       help=f"most torque updates, >= 0 (default {DEFAULT_MAX_ITER}; the "
                            "iteration stops once no DH angle changes by more than 1e-9 rad; "
                            "0: the rigid frames, converged only if they are the equilibrium)")

    s = sub.add_parser("fk", help="forward kinematics: every frame's position")
    s.add_argument("robot", help="robot name or path to a robot .json")
    s.add_argument("--q", default="zeros", metavar="Q",
                   help="joint values v1,v2,... in rad (m for prismatic) or 'zeros' (default)")
    elastic_opts(s)
    s.add_argument("--json", action="store_true", help="print JSON")
    s.add_argument("--device", default="cpu", help="Warp device (default cpu; e.g. cuda:0)")
    s.add_argument("--dtype", default="float64", choices=("float64", "float32"))
    s.set_defaults(func=cmd_fk)

    s = sub.add_parser("show", help="write a rerun recording (.rrd) of frames and spheres")
    s.add_argument("robot", help="robot name or path to a robot .json")
    s.add_argument("--q", action="append", metavar="Q",
                   help="a configuration (v1,v2,... or 'zeros'); repeat for several time steps")
    elastic_opts(s)
    s.add_argument("--save", required=True, metavar="FILE.rrd", help="the recording to write")
    s.set_defaults(func=cmd_show)

    import importlib

    for module in SUBCOMMAND_MODULES:  # calibration, planning: each adds its subcommands
        importlib.import_module(module).add_subcommands(sub)
    return p


#: exceptions that report a bad input, file or resource: their message is the error line
INPUT_ERRORS = (ValueError, TypeError, OSError, OverflowError, zipfile.BadZipFile)


def _one_line(e: BaseException) -> str:
    return " ".join(str(e).split())


def _debug() -> bool:
    return os.environ.get("JWARP_DEBUG", "").strip() not in ("", "0")


def main(argv: Sequence[str] | None = None) -> int:
    """Run the CLI; returns the exit status: 0 ok, 1 ``plan``/``ik`` not feasible, 2 any
    error (one line ``jwarp: error: ...`` on stderr), 130 interrupted. See the module
    docstring for which exceptions count as input errors and ``JWARP_DEBUG=1``."""
    argv = list(sys.argv[1:] if argv is None else argv)
    _plugin_warnings_one_line()
    try:
        parser = build_parser()
        args = parser.parse_args(_fix_negative_values(argv, _value_options(parser)))
        return args.func(args)
    except CLIError as e:
        if e.usage:
            sys.stderr.write(e.usage)
        print(f"jwarp: error: {_one_line(e)}", file=sys.stderr)
        return 2
    except SystemExit as e:  # --help / --version
        return e.code if isinstance(e.code, int) else (0 if e.code is None else 2)
    except BrokenPipeError:  # pragma: no cover - e.g. `jwarp fk ... | head`
        try:
            sys.stdout = open(os.devnull, "w")
        except OSError:
            pass
        return 0
    except KeyboardInterrupt:
        if _debug():
            raise
        print("jwarp: interrupted", file=sys.stderr)
        return 130
    except INPUT_ERRORS as e:
        # jwarp's own validation errors (unknown robot, bad kappa, unreadable file, ...)
        if _debug():
            raise
        what = "numeric overflow: " if isinstance(e, OverflowError) else ""
        print(f"jwarp: error: {what}{_one_line(e) or type(e).__name__}", file=sys.stderr)
        return 2
    except (MemoryError, RuntimeError) as e:
        if _debug():
            raise
        msg = _one_line(e)
        if isinstance(e, MemoryError) or "allocate" in msg.lower():  # Warp: "Failed to allocate"
            print(f"jwarp: error: out of memory{': ' + msg if msg else ''}", file=sys.stderr)
        else:
            print(f"jwarp: error: {type(e).__name__}: {msg} (run with JWARP_DEBUG=1 for the "
                  f"traceback)", file=sys.stderr)
        return 2
    except Exception as e:  # unexpected: possibly a bug; one line, the traceback on request
        if _debug():
            raise
        print(f"jwarp: error: {type(e).__name__}: {_one_line(e)} (run with JWARP_DEBUG=1 for "
              f"the traceback)", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    # run the imported module's main: under ``python -m jwarp.cli`` this file is __main__,
    # whose CLIError class is not the one the subcommand modules raise (jwarp.cli.CLIError)
    from jwarp.cli import main as _main

    sys.exit(_main())
