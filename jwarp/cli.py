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
``--q`` directly (``--q -0.5,0,...``). The CLI computes in float64 on the CPU unless told
otherwise. Errors print ``jwarp: error: ...`` on stderr and exit with status 2.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from typing import Any, Sequence

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
        raise CLIError(message, usage=self.format_usage())


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


def _fix_negative_values(argv: list[str]) -> list[str]:
    """Let ``--q -0.5,0,...`` mean ``--q=-0.5,0,...`` (argparse would take it for an option)."""
    out: list[str] = []
    i = 0
    while i < len(argv):
        a = argv[i]
        if a in ("--q", "--kappa", "--start", "--goal", "--target") and i + 1 < len(argv):
            nxt = argv[i + 1]
            if nxt.startswith("-") and len(nxt) > 1 and (nxt[1].isdigit() or nxt[1] == "."):
                out.append(f"{a}={nxt}")
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
def cmd_robots(args: argparse.Namespace) -> int:
    from jwarp.registry import robots

    rows = []
    for name in robots():
        m = _robot(name)
        rows.append({"name": name, "dof": m.n_dof, "frames": m.n_frames,
                     "end_effectors": list(m.end_effectors), "spheres": len(m.spheres),
                     "capsules": len(m.capsules), "masses": len(m.masses),
                     "description": m.description})
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
    _warn_limits(model, q)
    _quiet_warp()
    from jwarp import kinematics

    dtype = _dtype(args.dtype)
    rigid = np.asarray(kinematics.fk(model, q.astype(dtype), device=args.device, dtype=dtype),
                       np.float64)
    out: dict[str, Any] = {"robot": model.name, "q": q.tolist(), "device": args.device,
                           "dtype": args.dtype, "elastic": bool(args.elastic)}
    frames = rigid
    sags: dict[str, np.ndarray] = {}
    if args.elastic:
        kappa, source = parse_kappa(args.kappa, model)
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
    for q in qs:
        _warn_limits(model, q)
    _elastic_options(args)
    kappa = None
    if args.elastic:
        kappa, _ = parse_kappa(args.kappa, model)
        if kappa is None:
            kappa = model.kappa
    _quiet_warp()
    from jwarp.viz import save_robot_rrd

    try:
        path = save_robot_rrd(model, np.stack(qs), args.save, elastic_kappa=kappa, lam=args.lam,
                              max_iter=args.max_iter)
    except ImportError as e:
        raise CLIError(f"show: {e}") from None
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
        s.add_argument("--lam", type=float, default=None, metavar="L",
                       help="damping of the fixed-point iteration, in (0, 1] (default 1)")
        s.add_argument("--max-iter", type=int, default=None, metavar="N",
                       help=f"most torque updates (default {DEFAULT_MAX_ITER}; the iteration "
                            "stops once no DH angle changes by more than 1e-9 rad)")

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


def main(argv: Sequence[str] | None = None) -> int:
    """Run the CLI; returns the exit status (0 ok, 2 usage or input error)."""
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser()
    try:
        args = parser.parse_args(_fix_negative_values(argv))
        return args.func(args)
    except CLIError as e:
        if e.usage:
            sys.stderr.write(e.usage)
        print(f"jwarp: error: {e}", file=sys.stderr)
        return 2
    except SystemExit as e:  # --help / --version
        return e.code if isinstance(e.code, int) else (0 if e.code is None else 2)
    except BrokenPipeError:  # pragma: no cover - e.g. `jwarp fk ... | head`
        try:
            sys.stdout = open(os.devnull, "w")
        except OSError:
            pass
        return 0
    except (ValueError, TypeError, OSError) as e:
        # jwarp's own validation errors (unknown robot, bad kappa, unknown device, ...)
        print(f"jwarp: error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
