"""CLI subcommands of calibration: ``jwarp calibrate`` and ``jwarp simulate-campaign``.

``calibrate`` parses its options, reserves and writes the output files and prints; the
calibration itself (rows, free groups, initial guess, task weighting, CV, errors,
provenance) is :func:`jwarp.calibration.calibrate_campaign`, which Python users call the
same way (:class:`~jwarp.calibration.CampaignOptions`).

Examples::

    jwarp simulate-campaign --robot justin19 --plugin cartesian --samples 500 --seed 1 --out run/
    jwarp simulate-campaign --samples 500 --unmodeled harmonic:amp=5e-4,kappa_nonlinear --out run/
    jwarp calibrate --robot justin19 --setup run/setup.json --data run/samples.csv \\
        --free theta,d,r,alpha,kappa_theta,kappa_alpha \\
        --calibrate-rows 0:300 --test-rows 300:500 --out run/calibrated.json --json
    jwarp calibrate --setup run/setup.json --data run/samples.csv \\
        --free theta,d,r,alpha,kappa_theta,kappa_alpha,harmonic,coupling \\
        --prior harmonic=1e-3,harmonic:torso_*=5e-3 --order harmonic:torso_*=3 \\
        --loss soft_l1 --loss-scale 3 --fix tracker=run/first.json --diagnostics

``--prior`` sets prior sigmas (SI units: m, rad, rad/(N m); ``inf``: no prior) per group or
per joint/frame pattern (``group:pattern``), or reads them from a JSON file
``{"harmonic:torso_*": 5e-3, ...}``; ``--order`` the harmonic orders of ``harmonic`` and
``coupling``; ``--loss`` a robust loss on each sample's residual norm, ``--loss-scale``
in mm (in the measurement's unit when it is not metres); ``--fix GROUP=RESULT.json``
keeps a measurement group at the values of an earlier ``--params-out``;
``--diagnostics`` prints the residual diagnostics of docs/calibration.md (correlation
between end-effectors, residual against joint angles and torques) on the calibration rows.

``calibrate`` frees the robot groups named by ``--free`` (DH entries, compliances, ``mass``:
the point masses of the robot's mass model that load its compliant joints; ``--out`` then
writes the calibrated masses too) and, always, the measurement's
pose and marker groups (tracker, camera, markers, fixtures; ``--fix`` fixes them); other
measurement groups (intrinsics, radii) are freed by naming them in ``--free``. The table
compares the nominal robot ("before"; measurement parameters from the plugin's initial
guess on the calibration rows, e.g. the tracker pose by rigid alignment) with the
calibrated one ("after"), on the calibration and the test rows. Lengths are reported in mm,
pixels in px.

Safety: option values are checked first (finite, in range; ``--samples`` against an
estimate of the memory it needs), then every output path (``--out``, ``--params-out``,
``--rerun``; the ``simulate-campaign`` folder), all before any computation. ``calibrate``
writes ``--out`` and ``--params-out`` to temporary files (made before the computation) and
renames them back to back at the end (the robot first), after the ``--rerun`` recording; the
``--params-out`` JSON records the SHA-256 of the ``--out`` robot file (``robot_sha256``), so
a pair cut apart by a kill between the renames is recognisable. ``simulate-campaign``
replaces its folder as one set (:class:`jwarp.utils.atomic.AtomicFolder`). Test rows that are
also calibration rows are an error unless ``--allow-overlap``; without
``--calibrate-rows`` the calibration rows are all rows not in ``--test-rows``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import sys
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from jwarp.model import RobotModel

#: robots whose simulated truth is elastic by default, and its mean compliance [rad/(N m)]
ELASTIC_ROBOTS = ("justin19", "arm7")
DEFAULT_TRUE_KAPPA = 6e-5


def _cli_error(msg: str) -> Exception:
    from jwarp.cli.common import CLIError

    return CLIError(msg)


class ProgressBar:
    """The calibration's progress on stderr: a tqdm bar per start whose count is the
    solver iterations (its total the ``--max-nfev`` budget: every iteration costs at
    least one evaluation), with the cost (0.5 |r|^2 of the whitened problem) and the
    step (the relative cost decrease of the last iteration).

    The cost of one least-squares run never rises (only cost-reducing steps are
    accepted); where it does, the solver has begun a new run: an active-set round (the
    compliances that went negative are held at 0 and the rest solved again from there, so
    the cost restarts higher) or the next multi-start. Each is written as its own line,
    so a rising cost is explained. ``restarts`` counts the active-set rounds seen. With a
    robust loss (``robust``) the bar shows 0.5 |r|^2, which is not what the solver
    minimises and may rise within a run: no restart is inferred from it."""

    def __init__(self, label: str, stream: Any = None, enabled: bool = True,
                 total: int | None = None, robust: bool = False):
        self.label, self.stream, self.enabled = label, stream or sys.stderr, enabled
        self.total = total
        #: with a robust loss the solver minimises the robust cost while the callback
        #: reports 0.5 |r|^2, which may rise within a run: no restart is inferred then
        self.robust = robust
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.bar: Any = None
        self.start = -1
        self.cost = math.nan
        self.round = 1
        self.restarts = 0

    def _finish(self) -> None:
        """Close the current bar; a run that ended before its budget (converged, or an
        active-set round/start that stopped early) is drawn complete: 100 %, its count of
        iterations and the budget it did not need."""
        bar = self.bar
        if bar is None:
            return
        if bar.total and bar.n < bar.total:
            budget = bar.total
            bar.total = bar.n
            bar.bar_format = ("{desc}: {percentage:3.0f}%|{bar}| {n_fmt} iterations, done "
                              f"within the --max-nfev budget of {budget}"
                              " [{elapsed}{postfix}]")
            bar.refresh()
        bar.close()
        self.bar = None

    def _new_bar(self, p: Any) -> None:
        from tqdm.auto import tqdm

        self._finish()
        desc = self.label if p.n_starts == 1 else f"{self.label} start {p.start + 1}/{p.n_starts}"
        self.bar = tqdm(total=self.total, desc=desc, unit="it", file=self.stream,
                        dynamic_ncols=True, leave=True, mininterval=0.2 if self.tty else 1.0,
                        bar_format="{desc}: {percentage:3.0f}%|{bar}| {n_fmt}/{total_fmt} "
                                   "iterations (of the --max-nfev budget) [{elapsed}{postfix}]")

    def __call__(self, p: Any) -> None:
        cost = float(p.cost)
        if p.start != self.start:
            self.start, self.round = p.start, 1
            if self.enabled:
                self._new_bar(p)
            step = math.nan
        elif not self.robust and math.isfinite(self.cost) and cost > self.cost * (1 + 1e-12):
            self.round += 1
            self.restarts += 1
            if self.enabled:
                self.bar.write(f"{self.label}: active-set round {self.round} of start "
                               f"{p.start + 1}: compliances that went negative are held at 0 "
                               f"and the fit restarts from there (cost {self.cost:.6g} -> "
                               f"{cost:.6g}; not a divergence)", file=self.stream)
            step = math.nan
        else:
            step = (self.cost - cost) / self.cost if self.cost > 0 else 0.0
        self.cost = cost
        if not self.enabled:
            return
        self.bar.update(1)
        post = f"{'|r|^2/2' if self.robust else 'cost'} {cost:.6g}"
        if math.isfinite(step):
            post += f", step {step:.2e}"
        if self.round > 1:
            post += f", round {self.round}"
        self.bar.set_postfix_str(post, refresh=False)

    def close(self) -> None:
        """Close the bar (complete when the fit ended before its budget)."""
        self._finish()


def _parse_keyed(values: list[str] | None, option: str, kind: type) -> dict[str, Any]:
    """``--prior``/``--order`` values: ``KEY=VALUE[,KEY=VALUE...]`` items or (``--prior``)
    JSON files {key: value}; later ones win."""
    out: dict[str, Any] = {}
    for v in values or []:
        if "=" not in v:
            if kind is int:
                raise _cli_error(f"{option}: expected GROUP[:PATTERN]=K, got '{v}'")
            from jwarp.cli.common import read_small_text

            if not os.path.exists(v):
                raise _cli_error(f"{option}: '{v}' is neither KEY=SIGMA nor a file (no such "
                                 f"file)")
            text = read_small_text(v, option)
            try:
                doc = json.loads(text)
            except ValueError as e:
                raise _cli_error(f"{option}: '{v}' is neither KEY=SIGMA nor a readable JSON "
                                 f"file ({e})") from None
            if not isinstance(doc, dict):
                raise _cli_error(f"{option}: {v}: expected a JSON object {{key: sigma}}")
            items = list(doc.items())
        else:
            items = []
            for item in v.split(","):
                key, eq, val = item.partition("=")
                if not eq or not key.strip():
                    raise _cli_error(f"{option}: expected KEY=VALUE items, got '{item}'")
                items.append((key.strip(), val.strip()))
        for key, val in items:
            try:
                num = kind(val) if not isinstance(val, (int, float)) or kind is float \
                    else val
                if kind is int and (isinstance(val, float) or str(val).strip() != str(num)):
                    raise ValueError
            except (TypeError, ValueError):
                raise _cli_error(f"{option}: {key}: expected "
                                 f"{'an integer' if kind is int else 'a number'}, "
                                 f"got {val!r}") from None
            out[str(key)] = num
    return out


def _parse_fix(fix: str | None) -> tuple[str | None, dict[str, str]]:
    """``--fix`` items ``GROUP`` or ``GROUP=RESULT.json`` -> (the groups, comma-separated,
    {group: result file})."""
    if fix is None or not fix.strip():
        return fix, {}
    groups, at = [], {}
    for item in fix.split(","):
        g, eq, path = item.partition("=")
        g = g.strip()
        if eq:
            if not path.strip():
                raise _cli_error(f"--fix: expected GROUP=RESULT.json, got '{item}'")
            at[g] = path.strip()
        groups.append(g)
    return ",".join(groups), at


def _check_int(option: str, value: int, minimum: int) -> None:
    if value < minimum:
        raise _cli_error(f"{option}: expected an integer >= {minimum}, got {value}")


#: most multi-starts of ``calibrate`` (each a whole fit)
MAX_STARTS = 10_000


def _check_float(option: str, value: float | None, minimum: float = 0.0,
                 maximum: float = math.inf, unit: str = "") -> None:
    """A finite ``value`` in [minimum, maximum] (None: not given, fine)."""
    if value is None:
        return
    if not math.isfinite(value) or not minimum <= value <= maximum:
        upper = "" if maximum == math.inf else f" and <= {maximum:g}"
        raise _cli_error(f"{option}: expected a finite number >= {minimum:g}{upper}{unit}, "
                         f"got {value}")


def _reserve_outputs(args: argparse.Namespace, inputs: dict[str, str | None]) -> dict[str, Any]:
    """Check every output path of ``calibrate`` before any work and hold a temporary file
    beside ``--out`` and ``--params-out`` (:class:`~jwarp.utils.atomic.AtomicFile`; ``--rerun``
    is only probed, its recording writes its own): a missing or unwritable folder, a
    folder given for a file, an output that is an input or another output is an error
    naming the option."""
    from jwarp.cli.common import input_named
    from jwarp.utils.atomic import AtomicFile

    outs = [(opt, p) for opt, p in (("--out", args.out), ("--params-out", args.params_out),
                                     ("--rerun", args.rerun)) if p]
    seen = {os.path.realpath(p): opt for opt, p in inputs.items() if p and os.path.exists(p)}
    for opt, p in outs:
        key = os.path.realpath(p)
        if key in seen:
            raise _cli_error(f"{opt}: {p} is also {seen[key]}; give another file")
        other = input_named(p, opt)   # --prior FILE, --fix GROUP=FILE, ...: inputs too
        if other is not None and other not in ("--out", "--params-out", "--rerun"):
            raise _cli_error(f"{opt}: {p} is also {other}; give another file")
        seen[key] = opt
    if args.rerun:
        from jwarp.viz import rerun_module

        try:
            rerun_module()
        except ImportError as e:
            raise _cli_error(f"--rerun: {e}") from None
    reserved: dict[str, Any] = {}
    try:
        for opt, p in outs:
            reserved[opt] = AtomicFile(p, option=opt)
        if "--rerun" in reserved:
            reserved.pop("--rerun").discard()
    except BaseException:
        for f in reserved.values():
            f.discard()
        raise
    return reserved


def _write_tmp(f: Any, text: str) -> None:
    """Write ``text`` into the temporary file of the AtomicFile ``f``, synced to disk."""
    with open(f.tmp, "w", encoding="utf-8") as fh:
        fh.write(text)
        fh.flush()
        os.fsync(fh.fileno())


def cmd_calibrate(args: argparse.Namespace) -> int:
    from jwarp.cli.common import quiet_warp

    _check_int("--starts", args.starts, 1)
    if args.starts > MAX_STARTS:  # each start is a whole fit: bound the work up front
        raise _cli_error(f"--starts: {args.starts} starts of up to --max-nfev {args.max_nfev} "
                         f"evaluations each (about {args.starts:.3g} x one calibration); at "
                         f"most {MAX_STARTS}")
    _check_int("--max-nfev", args.max_nfev, 1)
    _check_int("--seed", args.seed, 0)
    if args.name is not None and not args.name.strip():
        raise _cli_error("--name: empty robot name")
    quiet_warp()
    inputs = {"--setup": args.setup, "--data": args.data, "--robot": args.robot}
    outputs = _reserve_outputs(args, inputs)
    try:
        return _calibrate(args, outputs)
    finally:
        for f in outputs.values():  # after a commit: nothing left to remove
            f.discard()


#: the CLI spelling of each option of :class:`jwarp.calibration.CampaignOptions` (and of
#: :func:`~jwarp.calibration.load_campaign`'s arguments) in messages
OPTION_NAMES = {
    "robot": "--robot", "setup": "--setup", "data": "--data", "free": "--free",
    "fix": "--fix", "fix_at": "--fix", "sigma": "--prior", "orders": "--order",
    "loss_scale": "--loss-scale", "calibrate_rows": "--calibrate-rows",
    "test_rows": "--test-rows", "allow_overlap": "--allow-overlap", "cv_folds": "--cv",
    "cv_grid": "--cv-grid", "cv_workers": "--cv-workers", "virtual_noise": "--virtual-noise",
    "n_starts": "--starts", "seed": "--seed", "max_nfev": "--max-nfev", "name": "--name",
}


def _option_error(e: ValueError) -> Exception:
    """A library error that names a ``--option`` (:data:`OPTION_NAMES` given as its
    ``names``) as the CLI's error; other errors unchanged."""
    if str(e).startswith(tuple(v + ": " for v in OPTION_NAMES.values())):
        return _cli_error(str(e))
    return e


def _calibrate(args: argparse.Namespace, outputs: dict[str, Any]) -> int:
    from jwarp.calibration.campaign_run import (
        CampaignOptions,
        calibrate_campaign,
        load_campaign,
        report_unit,
    )
    from jwarp.calibration.files import sha256_hex
    from jwarp.cli.common import dumps
    from jwarp.utils.atomic import commit_all

    try:
        campaign = load_campaign(args.setup, args.data, robot=args.robot)
    except ValueError as e:
        if str(e).startswith("robot: "):
            raise _cli_error(f"--{e}") from None
        raise
    mixed = f"data: {args.data} is not the samples file"   # named as the option
    input_warnings = ["--" + w if w.startswith(mixed) else w for w in campaign.warnings]
    for w in input_warnings:
        print(f"jwarp: warning: {w}", file=sys.stderr)
    model, meas, data = campaign.robot, campaign.measurement, campaign.samples
    fix_groups, fix_at = _parse_fix(args.fix)
    scale, unit = report_unit(meas)
    priors = _parse_keyed(args.prior, "--prior", float)
    orders = _parse_keyed(args.order, "--order", int)
    if args.loss != "linear":
        if args.loss_scale is None:
            raise _cli_error(f"--loss-scale: required with --loss {args.loss} (the residual "
                             f"norm where the loss turns robust, {unit})")
        _check_float("--loss-scale", args.loss_scale, unit=f" {unit}")
        if not args.loss_scale > 0:
            raise _cli_error(f"--loss-scale: expected a number > 0 {unit}, got {args.loss_scale}")
        loss_scale: float | None = float(args.loss_scale) / scale   # in the measurement's unit
    elif args.loss_scale is not None:
        raise _cli_error("--loss-scale: only with a robust --loss (soft_l1 or huber); with "
                         "the default linear loss it would be ignored")
    else:
        loss_scale = None
    options = CampaignOptions(
        free=args.free, fix=fix_groups, fix_at=fix_at or None, sigma=priors or None,
        orders=orders or None, loss=args.loss, loss_scale=loss_scale,
        calibrate_rows=args.calibrate_rows, test_rows=args.test_rows,
        allow_overlap=args.allow_overlap, cv_folds=args.cv, cv_grid=args.cv_grid,
        cv_workers=args.cv_workers, virtual_noise=args.virtual_noise, n_starts=args.starts,
        seed=args.seed, max_nfev=args.max_nfev, name=args.name)
    bar = ProgressBar("calibrate", enabled=not args.quiet, total=args.max_nfev,
                      robust=args.loss != "linear")
    try:
        run = calibrate_campaign(campaign, options, callback=bar, names=OPTION_NAMES)
    except ValueError as e:
        raise _option_error(e) from None
    finally:
        bar.close()
    res, calibrated, train, test = run.result, run.robot, run.train, run.test
    free, before, after, both, cv_result = run.free, run.before, run.after, run.overlap, run.cv
    # --out and --params-out into their temporary files, renamed back to back at the end
    robot_text = json.dumps(calibrated.to_dict(), indent=1) + "\n"
    if "--out" in outputs:
        _write_tmp(outputs["--out"], robot_text)
    if "--params-out" in outputs:
        doc = dict(res.to_dict(), robot_file=args.out, robot_sha256=sha256_hex(robot_text))
        _write_tmp(outputs["--params-out"], dumps(doc, indent=1) + "\n")
    if args.rerun:  # atomic on its own; an error here leaves --out and --params-out old
        from jwarp.viz import save_calibration_rrd

        save_calibration_rrd(args.rerun, res.robot, meas, res.params, data.q, data.y,
                             data.meta or None, p_before=run.p_start, robot_before=model)
    # the robot first: a kill between the renames leaves the new robot beside the old
    # params, whose robot_sha256 then names the old robot (the new one is never lost)
    commit_all(outputs[k] for k in ("--out", "--params-out") if k in outputs)
    fit_warnings = run.warnings
    test_range = run.test_range
    summary = {
        "robot": model.name, "plugin": meas.name, "unit": unit, "free": free,
        "samples": {"train": len(train), "test": 0 if test is None else len(test),
                    "test_fitted": both},
        "before": before, "after": after, "time_s": run.time_s, "iterations": res.iterations,
        "nfev": res.nfev, "success": bool(res.success), "elastic": bool(res.elastic),
        "warnings": input_warnings + fit_warnings,
        "out": args.out, "params_out": args.params_out, "rerun": args.rerun,
        "calibrated_name": calibrated.name, "active_set_rounds": bar.restarts,
    }
    if test_range is not None:
        summary["test_range"] = test_range
    if cv_result is not None:
        summary["cv"] = cv_result.to_dict(scale, unit)
    diag = None
    if args.diagnostics:
        from jwarp.calibration.estimate.diagnostics import format_diagnostics

        diag = run.diagnostics()
        summary["diagnostics"] = diag.to_dict(scale)
    if args.json:
        print(dumps(summary, indent=1))
        return 0
    if cv_result is not None:
        print(cv_result.table(scale, unit))
        print()
    if diag is not None:
        print(format_diagnostics(diag, scale, unit))
        print()
    print(f"calibrated '{model.name}' with '{meas.name}': {len(train)} calibration rows, "
          f"{0 if test is None else len(test)} test rows"
          f"{f' ({both} of them fitted too)' if both else ''}; free: {', '.join(free)}")
    print(f"{res.iterations} iterations, {res.nfev} evaluations, {run.time_s:.1f} s"
          f"{', elastic model' if res.elastic else ''}"
          f"{f'; {bar.restarts} active-set restart(s) (compliances held at 0)' if bar.restarts else ''}")
    print(f"\n{'rows':<8}{'':8}{'mean':>10}{'std':>10}{'max':>10}   [{unit}]")
    for rows in ("train", "test"):
        if rows not in before:
            continue
        for label, d in (("before", before), ("after", after)):
            s = d[rows]
            print(f"{rows:<8}{label:<8}{s['mean']:>10.3f}{s['std']:>10.3f}{s['max']:>10.3f}")
    if test_range is not None and test_range["outside"] is not None:
        for label in ("inside", "outside"):
            part = test_range[label]
            if part is not None:
                print(f"{'test':<8}{label:<8}{part['mean']:>10.3f}{part['std']:>10.3f}"
                      f"{part['max']:>10.3f}   ({part['rows']} rows {label} the calibration "
                      f"poses' range)")
    for w in fit_warnings:
        print(f"warning: {w}")
    for path in (args.out, args.params_out, args.rerun):
        if path:
            print(f"wrote {path}" + (f" (robot '{calibrated.name}', provenance in its notes."
                                     f"calibration)" if path == args.out else ""))
    return 0


#: memory of simulate-campaign per sample and robot frame [bytes] (a few 4x4 float64
#: frame arrays: candidates, kept frames, the elastic solve's copies; measured ~3)
_BYTES_PER_SAMPLE_FRAME = 4 * 128
#: ... and per sample and CSV column (the text and its row lists) [bytes]
_BYTES_PER_SAMPLE_COLUMN = 64


def _check_campaign_memory(model: RobotModel, meas: Any, n: int) -> None:
    """Refuse ``--samples`` whose estimated memory exceeds the available memory."""
    from jwarp.calibration.files import columns
    from jwarp.utils.memory import check_memory, format_bytes

    per = (_BYTES_PER_SAMPLE_FRAME * model.n_frames
           + _BYTES_PER_SAMPLE_COLUMN * len(columns(model, meas)))
    try:
        check_memory(n * per, f"{n} samples ({format_bytes(per)} per sample for "
                              f"'{model.name}')", "simulate fewer samples (or several "
                     "campaigns with different --seed)")
    except MemoryError as e:
        raise _cli_error(f"--samples: {e}") from None


def cmd_simulate_campaign(args: argparse.Namespace) -> int:
    from jwarp.calibration.files import make_measurement, read_setup
    from jwarp.calibration.simulate.campaign import simulate_campaign
    from jwarp.cli.common import quiet_warp
    from jwarp.plugins.registry import robot as get_robot
    from jwarp.utils.atomic import AtomicFolder

    _check_int("--samples", args.samples, 1)
    _check_int("--seed", args.seed, 0)
    _check_float("--noise", args.noise, unit=" (unit of the measurement)")
    _check_float("--length-error", args.length_error, unit=" mm")
    _check_float("--angle-error", args.angle_error, maximum=180.0, unit=" deg")
    _check_float("--kappa", args.kappa, unit=" rad/(N m)")
    from jwarp.calibration.simulate.unmodeled import parse_unmodeled

    try:
        unmodeled = parse_unmodeled(args.unmodeled, option="--unmodeled")
    except (ValueError, TypeError) as e:
        raise _cli_error(str(e)) from None
    AtomicFolder(args.out, option="--out").discard()  # the folder can be written: checked
    quiet_warp()
    if args.setup:
        setup = read_setup(args.setup)
        robot_name = args.robot or setup.robot
        sampler = accept = None
    else:
        from jwarp.calibration.simulate.scenarios import scenario

        robot_name = args.robot or "justin19"
        setup, sampler, accept = scenario(robot_name, args.plugin)
    if not robot_name:
        raise _cli_error("--robot: not given and the setup file names no robot")
    model = get_robot(robot_name)
    # the written setup.json names the robot, so calibrate needs no --robot again (a file
    # by its absolute path: calibrate may run from another folder)
    recorded = os.path.abspath(robot_name) if os.path.isfile(robot_name) else robot_name
    setup = dataclasses.replace(setup, robot=recorded)
    _check_campaign_memory(model, make_measurement(model, setup), args.samples)
    k = args.kappa if args.kappa is not None else (
        DEFAULT_TRUE_KAPPA if model.name in ELASTIC_ROBOTS else 0.0)
    # joint compliance U(0.5, 1.5) K, lateral (alpha) a third of it (as DEFAULT_KAPPA)
    kappa = None if k == 0 else {"kappa_theta": (0.5 * k, 1.5 * k),
                                 "kappa_alpha": (k / 6, k / 2)}
    try:
        camp = simulate_campaign(model, setup, args.samples, seed=args.seed, noise=args.noise,
                                 length_error=args.length_error * 1e-3,
                                 angle_error=math.radians(args.angle_error), kappa=kappa,
                                 sampler=sampler, accept=accept, unmodeled=unmodeled)
    except ValueError as e:
        if "NaN or inf" in str(e) and args.kappa is not None:  # the robot sagged to infinity
            raise _cli_error(f"--kappa: {args.kappa:g} rad/(N m) makes the true robot's "
                             f"equilibrium non-finite; give a compliance a robot can have "
                             f"(e.g. <= 1e-2)") from None
        raise
    # refuse what calibrate would refuse, before anything is written
    bad = [o for o, v in (("--noise", camp.samples.y), ("--kappa", camp.samples.q))
           if not np.all(np.isfinite(v))]
    if bad:
        raise _cli_error(f"{bad[0]}: {getattr(args, bad[0][2:])} gives non-finite samples; "
                         f"nothing was written")
    paths = camp.write(args.out, option="--out")
    if args.json:
        print(json.dumps({"robot": model.name, "plugin": setup.plugin, "samples": args.samples,
                          "noise": camp.noise, "unmodeled": unmodeled.effects, "campaign_id": camp.campaign_id, **paths},
                         indent=1))
    else:
        print(f"simulated {args.samples} '{setup.plugin}' samples of '{model.name}' "
              f"(noise {camp.noise:g}): {paths['samples.csv']}, {paths['setup.json']} "
              f"(rough setup), {paths['truth.json']} (true robot); campaign "
              f"{camp.campaign_id}")
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
                        "prior 10%% of each mass), harmonic, kappa_nonlinear, origin, "
                        "coupling (coupled frames: coefficients, offset, harmonics of the "
                        "coupled angle), backlash (direction-dependent joint errors; the "
                        "direction from the previous row) (+ measurement groups such as "
                        "intrinsics)")
    s.add_argument("--fix", default=None, metavar="GROUPS",
                   help="measurement groups to keep at their setup values (e.g. markers), "
                        "or GROUP=RESULT.json at the values of an earlier --params-out "
                        "(e.g. tracker=cal.json)")
    s.add_argument("--prior", action="append", default=None, metavar="KEY=SIGMA|FILE.json",
                   help="prior sigmas [m, rad, rad/(N m); inf: none] per group or per "
                        "joint/frame pattern (harmonic=1e-3,harmonic:torso_*=5e-3), or a "
                        "JSON file of them; repeatable")
    s.add_argument("--order", action="append", default=None, metavar="KEY=K",
                   help="harmonic orders of the harmonic and coupling groups, per group or "
                        "pattern (harmonic:torso_*=3,coupling=2); repeatable")
    s.add_argument("--loss", default="linear", choices=("linear", "soft_l1", "huber"),
                   help="robust loss on each sample's residual norm (default linear)")
    s.add_argument("--loss-scale", type=float, default=None, metavar="MM",
                   help="where the robust loss turns robust [mm; the measurement's unit "
                        "when not metres], e.g. 3 noise sigmas")
    s.add_argument("--diagnostics", action="store_true",
                   help="print residual diagnostics of the calibrated model (correlation "
                        "between end-effectors, residual vs joint angle and torque)")
    s.add_argument("--cv", type=int, default=None, metavar="K",
                   help="choose prior strengths, harmonic orders or groups by K-fold "
                        "cross-validation on the calibration rows (the grid: --cv-grid), "
                        "then fit the best on all of them; the table is printed and the "
                        "choice recorded in the provenance")
    s.add_argument("--cv-grid", action="append", default=None, metavar="AXIS=V1|V2|...",
                   help="settings of --cv, the product of the items: scale=0.1|1 (factor "
                        "on every free robot group's prior), prior:KEY=S1|S2, order:KEY=K1|K2, "
                        "free=G1|G2 (group lists), or a JSON file listing settings; default "
                        "scale=0.01|0.02|0.05|0.1|0.2|0.5|1|2|5|10; repeatable")
    s.add_argument("--cv-workers", type=int, default=None, metavar="N",
                   help="processes for the --cv fits (default: one per core)")
    s.add_argument("--calibrate-rows", default=None, metavar="A:B",
                   help="rows used for calibration (default: all rows not in --test-rows)")
    s.add_argument("--test-rows", default=None, metavar="A:B",
                   help="rows for testing only (must not overlap --calibrate-rows)")
    s.add_argument("--allow-overlap", action="store_true",
                   help="allow test rows that are also calibration rows (the report counts "
                        "them; their errors are not independent of the fit)")
    s.add_argument("--out", default=None, metavar="CALIBRATED.json",
                   help="write the calibrated robot (atomically), named --name, with its "
                        "provenance (campaign, input files, free groups, errors, date) in "
                        "its notes")
    s.add_argument("--name", default=None, metavar="NAME",
                   help="name of the calibrated robot (default: <robot>-calibrated)")
    s.add_argument("--params-out", default=None, metavar="RESULT.json",
                   help="write parameters, posterior std and findings as JSON (with the "
                        "SHA-256 of the --out robot file: robot_sha256)")
    s.add_argument("--virtual-noise", type=float, default=None, metavar="SIGMA",
                   help="virtual noise std [measurement unit] added to every observation "
                        "for the systematic error (thesis eq. 2.7; the setup's tow section "
                        "adds task-oriented weighting)")
    s.add_argument("--starts", type=int, default=1, help="multi-start: number of starts (>= 1)")
    s.add_argument("--seed", type=int, default=0, help="seed of the multi-start draws (>= 0)")
    s.add_argument("--max-nfev", type=int, default=200,
                   help="most residual evaluations (>= 1)")
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
    s.add_argument("--samples", type=int, default=500,
                   help="number of samples (refused when the memory estimate exceeds the "
                        "available memory)")
    s.add_argument("--seed", type=int, default=0, help="random seed (>= 0)")
    s.add_argument("--noise", type=float, default=None,
                   help="noise sigma (unit of the measurement; default the setup's)")
    s.add_argument("--length-error", type=float, default=1.0, metavar="MM",
                   help="uniform DH length errors +- MM (default 1; with the default angle "
                        "errors and compliances justin19's nominal model is ~20 mm off at "
                        "the TCPs, as Agile Justin's)")
    s.add_argument("--angle-error", type=float, default=0.3, metavar="DEG",
                   help="uniform DH angle errors +- DEG (default 0.3)")
    s.add_argument("--kappa", type=float, default=None, metavar="K",
                   help="mean true joint compliance [rad/(N m)], U(0.5 K, 1.5 K); the lateral "
                        "(alpha) axes get a third of it (0: rigid; "
                        f"default {DEFAULT_TRUE_KAPPA:g} for {', '.join(ELASTIC_ROBOTS)}, else 0)")
    s.add_argument("--unmodeled", default=None, metavar="EFFECTS",
                   help="effects in the truth outside the calibration model: "
                        "harmonic[:amp=RAD,k=K] (joint transmission errors), "
                        "kappa_nonlinear[:rel=R] (torque-dependent stiffness), "
                        "kappa_beta[:min=K,max=K] (lateral compliance), "
                        "coupling[:amp=RAD,k=K] (error of coupled frames), "
                        "backlash[:min=RAD,max=RAD] (direction-dependent joint errors), "
                        "comma-separated, "
                        "or 'all' (the first three; defaults: docs/nongeometric.md); "
                        "truth.json carries them")
    s.add_argument("--out", required=True, metavar="FOLDER",
                   help="folder for samples.csv, setup.json and truth.json, replaced as one "
                        "set (its parent folder must exist; its other files are kept)")
    s.add_argument("--json", action="store_true")
    s.set_defaults(func=cmd_simulate_campaign)
