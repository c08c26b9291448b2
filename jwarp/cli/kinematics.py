"""CLI commands of kinematics: ``jwarp robots | info | fk | show``.

Examples::

    jwarp robots
    jwarp info justin19 --json
    jwarp fk justin19 --q zeros --elastic
    jwarp fk arm7 --q 0,30,0,-60,0,45,0 --deg --json
    jwarp show justin19 --q zeros --q 0,0,45,... --elastic --out justin.rrd

Joint values ``--q`` are comma-separated, in rad (m for prismatic joints), or ``zeros``;
``--deg`` reads revolute joints in degrees. A value starting with a minus sign may follow
``--q`` directly (``--q -0.5,0,...``; any option's negative number, ``-inf`` and ``-nan``
too). The CLI computes in float64 on the CPU unless told otherwise.
"""

from __future__ import annotations

import argparse
import sys
from typing import TYPE_CHECKING, Any

import numpy as np

from jwarp.cli.common import (
    DEFAULT_KAPPA,
    DEFAULT_MAX_ITER,
    CLIError,
    check_device,
    check_dtype_range,
    check_output,
    dtype_of,
    dumps,
    elastic_options,
    int_arg,
    load_robot,
    parse_kappa,
    parse_q,
    quiet_warp,
    real_arg,
    warn_limits,
)
from jwarp.cli.vocabulary import add_out, require_out

if TYPE_CHECKING:
    from jwarp.model import RobotModel

#: fk_elastic's own default of max_iter (jwarp.kinematics.equilibrium; the CLI's differs)
API_MAX_ITER = 10


def cmd_robots(args: argparse.Namespace) -> int:
    """List the robots; broken plugins and robots whose factory fails are reported as
    ``jwarp: warning: ...`` lines on stderr (the list itself, also ``--json``, stays a list)."""
    import warnings

    from jwarp.plugins.registry import PluginWarning, plugin_problems, robots

    rows = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PluginWarning)  # printed below, each once
        names = robots()
        problems = plugin_problems()
        for name in names:
            try:
                m = load_robot(name)
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


def device_line() -> str:
    """One line on the devices Warp computes on: ``devices: cpu, cuda:0 (NAME)``, or, on a
    machine without CUDA, that there is none and why (no NVIDIA driver, or a driver that
    found no GPU): Warp's own "CUDA driver not found" line is not printed
    (:mod:`jwarp.utils.warp_init`)."""
    import warp as wp

    from jwarp.core.arrays import init_warp
    from jwarp.utils.warp_init import cuda_driver_found

    init_warp()
    cuda = list(wp.get_cuda_devices())
    if cuda:
        return "devices: cpu, " + ", ".join(f"{d} ({d.name})" for d in cuda)
    why = "the NVIDIA driver found no GPU" if cuda_driver_found() else \
        "no NVIDIA CUDA driver found"
    return f"devices: cpu only (no CUDA: {why}; jwarp computes on the CPU)"


def cmd_info(args: argparse.Namespace) -> int:
    m = load_robot(args.robot)
    if args.json:
        print(dumps(m.to_dict()))
    else:
        print(m.summary())
        print(device_line())
    return 0


def _positions(model: RobotModel, frames: np.ndarray) -> dict[str, list[float]]:
    return {name: frames[i, :3, 3].tolist() for i, name in enumerate(model.frame_names)}


def cmd_fk(args: argparse.Namespace) -> int:
    model = load_robot(args.robot)
    elastic_options(args)
    q = parse_q(args.q, model, args.deg)
    kappa, source = parse_kappa(args.kappa, model) if args.elastic else (None, "")
    dtype = dtype_of(args.dtype)
    check_dtype_range(q, dtype, "--q")
    if kappa is not None:
        check_dtype_range(kappa, dtype, "--kappa")
    quiet_warp()
    check_device(args.device)
    warn_limits(model, q)
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
            "diverged": bool(np.asarray(res.diverged).any()),
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
    print(f"q [rad/m]: {', '.join(f'{n}={v:.6g}' for n, v in zip(model.joint_names, q))}")
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
        if not out["converged"] and out.get("diverged"):
            print("jwarp: warning: the elastic iteration diverged (non-finite frames); lower "
                  "--kappa or --lam", file=sys.stderr)
        elif not out["converged"]:
            print(f"jwarp: warning: the elastic iteration did not converge in {args.max_iter} "
                  f"updates; raise --max-iter or lower --lam", file=sys.stderr)
        print(f"{'end-effector':<16} {'dx [mm]':>9} {'dy [mm]':>9} {'dz [mm]':>9} {'|sag| [mm]':>11}")
        for ee, s in sags.items():
            print(f"{ee:<16} {s[0]:>9.3f} {s[1]:>9.3f} {s[2]:>9.3f} {np.linalg.norm(s):>11.3f}")
    return 0


def cmd_show(args: argparse.Namespace) -> int:
    model = load_robot(args.robot)
    qs = [parse_q(t, model, args.deg, option=f"--q #{k + 1}")
          for k, t in enumerate(args.q or ["zeros"])]
    elastic_options(args)
    kappa = None
    if args.elastic:
        kappa, _ = parse_kappa(args.kappa, model)
        if kappa is None:
            kappa = model.kappa
    # the output path before any work
    require_out(args)
    check_output(args.out, "--out", rerun=True, inputs={"robot": args.robot})
    for q in qs:
        warn_limits(model, q)
    quiet_warp()
    from jwarp.viz import save_robot_rrd

    try:
        path = save_robot_rrd(model, np.stack(qs), args.out, elastic_kappa=kappa, lam=args.lam,
                              max_iter=args.max_iter, option="--out")
    except ImportError as e:
        raise CLIError(f"--out: {e}") from None
    print(f"wrote {path} ({len(qs)} configuration{'s' if len(qs) != 1 else ''} of "
          f"'{model.name}'{', rigid and elastic' if args.elastic else ''}); "
          f"view with: rerun {path}")
    return 0



def add_subcommands(sub: Any) -> None:
    """Register ``robots``, ``info``, ``fk`` and ``show`` on the CLI's subparsers."""
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
                       help=f"most torque updates, >= 0 (default {DEFAULT_MAX_ITER}, the Python "
                            f"API's fk_elastic(max_iter=...) default is {API_MAX_ITER}: the CLI "
                            "allows more because it stops once no DH angle changes by more "
                            "than 1e-9 rad; 0: the rigid frames, converged only if they are "
                            "the equilibrium)")

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
    add_out(s, "--save", required=True, metavar="FILE.rrd",
            help="the rerun recording to write")
    s.set_defaults(func=cmd_show)
