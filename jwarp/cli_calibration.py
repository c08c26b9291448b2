"""CLI subcommands of calibration: ``jwarp calibrate`` and ``jwarp simulate-campaign``.

Examples::

    jwarp simulate-campaign --robot justin19 --plugin cartesian --samples 500 --seed 1 --out run/
    jwarp calibrate --robot justin19 --setup run/setup.json --data run/samples.csv \\
        --free theta,d,r,alpha,kappa_theta,kappa_alpha \\
        --calibrate-rows 0:300 --test-rows 300:500 --out run/calibrated.json --json

``calibrate`` frees the robot groups named by ``--free`` (DH entries, compliances, ``mass``:
the point masses of the robot's mass model that load its compliant joints; ``--out`` then
writes the calibrated masses too) and, always, the measurement's
pose and marker groups (tracker, camera, markers, fixtures; ``--fix`` fixes them); other
measurement groups (intrinsics, radii) are freed by naming them in ``--free``. The table
compares the nominal robot ("before"; measurement parameters from the plugin's initial
guess on the calibration rows, e.g. the tracker pose by rigid alignment) with the
calibrated one ("after"), on the calibration and the test rows. Lengths are reported in mm,
pixels in px.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
import warnings
from typing import Any

import numpy as np

#: measurement groups that are free unless --fix names them (poses of sensors, markers)
ALWAYS_FREE_MEASUREMENT_GROUPS = ("tracker", "camera", "markers", "fixtures")
#: robots whose simulated truth is elastic by default, and its mean compliance [rad/(N m)]
ELASTIC_ROBOTS = ("justin19", "arm7")
DEFAULT_TRUE_KAPPA = 1e-4


def _cli_error(msg: str) -> Exception:
    from jwarp.cli import CLIError

    return CLIError(msg)


class ProgressBar:
    """One self-overwriting status line on stderr (plain lines when stderr is no TTY)."""

    def __init__(self, label: str, stream: Any = None, enabled: bool = True):
        self.label, self.stream, self.enabled = label, stream or sys.stderr, enabled
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.t0 = time.perf_counter()
        self.last = 0.0

    def __call__(self, p: Any) -> None:
        if not self.enabled:
            return
        now = time.perf_counter()
        if not self.tty and now - self.last < 1.0 and p.iteration > 1:
            return  # a line per second in logs
        self.last = now
        width = 20
        done = int(width * (p.start + 1) / max(p.n_starts, 1))
        bar = "#" * done + "-" * (width - done)
        line = (f"{self.label} [{bar}] start {p.start + 1}/{p.n_starts} iteration "
                f"{p.iteration:4d} cost {p.cost:11.5g}  {now - self.t0:6.1f} s")
        if self.tty:
            self.stream.write("\r" + line)
        else:
            self.stream.write(line + "\n")
        self.stream.flush()

    def close(self) -> None:
        if self.enabled and self.tty:
            self.stream.write("\n")
            self.stream.flush()


def _stats(err: np.ndarray, scale: float) -> dict[str, float]:
    from jwarp.solvers.calibration import error_stats

    return {k: v * scale for k, v in error_stats(err).items()}


def _free_groups(free: str, meas: Any, fix: str | None) -> list[str]:
    from jwarp.solvers.calibration import parse_groups

    groups = parse_groups(free) if free else []
    fixed = set(parse_groups(fix)) if fix else set()
    meas_groups = meas.params.group_names()
    unknown_fix = sorted(fixed - set(meas_groups))
    if unknown_fix:
        raise _cli_error(f"--fix: {unknown_fix} are not groups of the '{meas.name}' "
                         f"measurement (its groups: {', '.join(meas_groups) or 'none'})")
    for g in meas_groups:
        if g in ALWAYS_FREE_MEASUREMENT_GROUPS and g not in fixed and g not in groups:
            groups.append(g)
    return groups


def cmd_calibrate(args: argparse.Namespace) -> int:
    from jwarp.cli import _quiet_warp, dumps
    from jwarp.registry import robot as get_robot
    from jwarp.solvers.calibration import calibrate, errors
    from jwarp.solvers.calibration.files import (make_measurement, parse_rows, read_samples,
                                                 read_setup)

    _quiet_warp()
    setup = read_setup(args.setup)
    robot_name = args.robot or setup.robot
    if not robot_name:
        raise _cli_error("--robot: not given and the setup file names no robot")
    model = get_robot(robot_name)
    meas = make_measurement(model, setup)
    data = read_samples(args.data, model, meas)
    S = len(data)
    train = data.select(parse_rows(args.calibrate_rows, S, "--calibrate-rows"))
    test = data.select(parse_rows(args.test_rows, S, "--test-rows")) if args.test_rows else None
    free = _free_groups(args.free, meas, args.fix)
    if args.out and os.path.isdir(args.out):
        raise _cli_error(f"--out: {args.out} is a folder; give a file name (calibrated.json)")
    scale, unit = (1000.0, "mm") if meas.unit == "m" else (1.0, meas.unit)

    def table_rows(robot: Any, p: np.ndarray) -> dict[str, dict[str, float]]:
        out = {"train": _stats(errors(robot, meas, p, train.q, train.y, train.meta or None), scale)}
        if test is not None:
            out["test"] = _stats(errors(robot, meas, p, test.q, test.y, test.meta or None), scale)
        return out

    from jwarp.solvers.calibration.result import model_frames

    p_start = meas.initial_guess(model_frames(model, train.q, elastic=False), train.y,
                                 meas.params.nominal, train.meta or None)
    before = table_rows(model, p_start)
    bar = ProgressBar("calibrate", enabled=not args.quiet)
    t0 = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            res = calibrate(model, meas, train.q, train.y, free=free, meta=train.meta or None,
                            n_starts=args.starts, seed=args.seed, max_nfev=args.max_nfev,
                            callback=bar)
        finally:
            bar.close()
    wall = time.perf_counter() - t0
    after = table_rows(res.robot, res.params)
    if args.out:
        res.robot.save(args.out)  # atomic
    if args.params_out:
        from jwarp.atomic import atomic_write_text

        atomic_write_text(args.params_out, dumps(res.to_dict(), indent=1) + "\n")
    if args.rerun:
        from jwarp.viz import save_calibration_rrd

        save_calibration_rrd(args.rerun, res.robot, meas, res.params, data.q, data.y,
                             data.meta or None, p_before=p_start, robot_before=model)
    summary = {
        "robot": model.name, "plugin": meas.name, "unit": unit, "free": free,
        "samples": {"train": len(train), "test": 0 if test is None else len(test)},
        "before": before, "after": after, "time_s": wall, "iterations": res.iterations,
        "nfev": res.nfev, "success": bool(res.success), "elastic": bool(res.elastic),
        "warnings": list(res.warnings) + [str(w.message) for w in caught
                                          if str(w.message) not in res.warnings],
        "out": args.out,
    }
    if args.json:
        print(dumps(summary, indent=1))
        return 0
    print(f"calibrated '{model.name}' with '{meas.name}': {len(train)} calibration rows, "
          f"{0 if test is None else len(test)} test rows; free: {', '.join(free)}")
    print(f"{res.iterations} iterations, {res.nfev} evaluations, {wall:.1f} s"
          f"{', elastic model' if res.elastic else ''}")
    print(f"\n{'rows':<8}{'':8}{'mean':>10}{'std':>10}{'max':>10}   [{unit}]")
    for rows in ("train", "test"):
        if rows not in before:
            continue
        for label, d in (("before", before), ("after", after)):
            s = d[rows]
            print(f"{rows:<8}{label:<8}{s['mean']:>10.3f}{s['std']:>10.3f}{s['max']:>10.3f}")
    for w in summary["warnings"]:
        print(f"warning: {w}")
    if args.out:
        print(f"wrote {args.out}")
    return 0


def cmd_simulate_campaign(args: argparse.Namespace) -> int:
    from jwarp.cli import _quiet_warp
    from jwarp.registry import robot as get_robot
    from jwarp.solvers.calibration.campaign import simulate_campaign
    from jwarp.solvers.calibration.files import read_setup

    _quiet_warp()
    if args.setup:
        setup = read_setup(args.setup)
        robot_name = args.robot or setup.robot
        sampler = accept = None
    else:
        from jwarp.solvers.calibration.scenarios import scenario

        robot_name = args.robot or "justin19"
        setup, sampler, accept = scenario(robot_name, args.plugin)
    if not robot_name:
        raise _cli_error("--robot: not given and the setup file names no robot")
    model = get_robot(robot_name)
    k = args.kappa if args.kappa is not None else (
        DEFAULT_TRUE_KAPPA if model.name in ELASTIC_ROBOTS else 0.0)
    kappa = None if k == 0 else (0.5 * k, 1.5 * k)
    camp = simulate_campaign(model, setup, args.samples, seed=args.seed, noise=args.noise,
                             length_error=args.length_error * 1e-3,
                             angle_error=math.radians(args.angle_error), kappa=kappa,
                             sampler=sampler, accept=accept)
    paths = camp.write(args.out)
    if args.json:
        print(json.dumps({"robot": model.name, "plugin": setup.plugin, "samples": args.samples,
                          "noise": camp.noise, **paths}, indent=1))
    else:
        print(f"simulated {args.samples} '{setup.plugin}' samples of '{model.name}' "
              f"(noise {camp.noise:g}): {paths['samples.csv']}, {paths['setup.json']} "
              f"(rough setup), {paths['truth.json']} (true robot)")
    return 0


def add_subcommands(sub: Any) -> None:
    """Register ``calibrate`` and ``simulate-campaign`` on the CLI's subparsers."""
    s = sub.add_parser("calibrate", help="MAP calibration from a setup file and samples CSV")
    s.add_argument("--robot", default=None, help="robot name or .json (default: the setup's)")
    s.add_argument("--setup", required=True, metavar="SETUP.json",
                   help="measurement setup (plugin, markers, rough tracker/camera pose, sigmas)")
    s.add_argument("--data", required=True, metavar="SAMPLES.csv", help="measured samples")
    s.add_argument("--free", default="theta", metavar="GROUPS",
                   help="parameter groups to calibrate: theta,d,r,alpha,beta,kappa_theta,"
                        "kappa_alpha,kappa_beta,mass (point masses loading compliant joints; "
                        "prior 10%% of each mass) (+ measurement groups such as intrinsics)")
    s.add_argument("--fix", default=None, metavar="GROUPS",
                   help="measurement groups to keep at their setup values (e.g. markers)")
    s.add_argument("--calibrate-rows", default=None, metavar="A:B",
                   help="rows used for calibration (default all)")
    s.add_argument("--test-rows", default=None, metavar="A:B", help="rows for testing only")
    s.add_argument("--out", default=None, metavar="CALIBRATED.json",
                   help="write the calibrated robot (atomically)")
    s.add_argument("--params-out", default=None, metavar="RESULT.json",
                   help="write parameters, posterior std and findings as JSON")
    s.add_argument("--starts", type=int, default=1, help="multi-start: number of starts")
    s.add_argument("--seed", type=int, default=0, help="seed of the multi-start draws")
    s.add_argument("--max-nfev", type=int, default=200, help="most residual evaluations")
    s.add_argument("--rerun", default=None, metavar="FILE.rrd",
                   help="write measured vs predicted markers and residuals per sample")
    s.add_argument("--quiet", action="store_true", help="no progress bar")
    s.add_argument("--json", action="store_true",
                   help="print the summary as JSON (lengths in mm)")
    s.set_defaults(func=cmd_calibrate)

    s = sub.add_parser("simulate-campaign",
                       help="write a synthetic samples CSV + rough setup + true robot")
    s.add_argument("--robot", default=None, help="robot name (default justin19)")
    s.add_argument("--plugin", default="cartesian",
                   help="built-in scenario: cartesian, image, relative (justin19); contact (hand4)")
    s.add_argument("--setup", default=None, metavar="SETUP.json",
                   help="simulate this exact setup instead of a built-in scenario")
    s.add_argument("--samples", type=int, default=500, help="number of samples")
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("--noise", type=float, default=None,
                   help="noise sigma (unit of the measurement; default the setup's)")
    s.add_argument("--length-error", type=float, default=5.0, metavar="MM",
                   help="uniform DH length errors +- MM (default 5)")
    s.add_argument("--angle-error", type=float, default=5.0, metavar="DEG",
                   help="uniform DH angle errors +- DEG (default 5)")
    s.add_argument("--kappa", type=float, default=None, metavar="K",
                   help="mean true compliance of joint and lateral axes [rad/(N m)] (0: rigid; "
                        f"default {DEFAULT_TRUE_KAPPA:g} for {', '.join(ELASTIC_ROBOTS)}, else 0)")
    s.add_argument("--out", required=True, metavar="FOLDER",
                   help="folder for samples.csv, setup.json and truth.json")
    s.add_argument("--json", action="store_true")
    s.set_defaults(func=cmd_simulate_campaign)
