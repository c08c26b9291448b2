"""Shared helpers of the calibration examples (calibrate_*.py): the common command-line
options, the train/test split of a simulated campaign, one calibration per table row, error
statistics against the measured and the noise-free test data, table printing and the
acceptance checks (printed as ``check: ... PASS|FAIL``; the example exits with
``report_checks``' status, 1 when any check fails).

Not a library module: the examples import it from their own folder.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
import warnings
from dataclasses import dataclass, field
from typing import Any, Callable, Sequence

import numpy as np

import jwarp
from jwarp.calibration import CalibrationWarning, calibrate, error_stats, errors
from jwarp.calibration.files import Samples, make_measurement
from jwarp.calibration.estimate.result import model_frames


def example_parser(doc: str, *, noise: float, noise_help: str, quick_help: str
                   ) -> argparse.ArgumentParser:
    """The options every example has: --samples, --test, --seed, --noise (default ``noise``),
    --starts, --max-nfev, --quick; the example adds its own and calls ``parse_example``."""
    ap = argparse.ArgumentParser(description=doc.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--samples", type=int, default=300, help="calibration rows (default 300)")
    ap.add_argument("--test", type=int, default=200, help="test rows (default 200)")
    ap.add_argument("--seed", type=int, default=1, help="seed of truth, samples and noise")
    ap.add_argument("--noise", type=float, default=noise,
                    help=f"{noise_help} (default {noise:g})")
    ap.add_argument("--starts", type=int, default=1, help="multi-start count per row")
    ap.add_argument("--max-nfev", type=int, default=200, help="solver evaluations per row")
    ap.add_argument("--quick", action="store_true", help=f"smoke run: {quick_help}")
    return ap


def parse_example(ap: argparse.ArgumentParser, argv: list[str] | None,
                  quick: dict[str, Any], positive: Sequence[str] = ("samples", "test")
                  ) -> argparse.Namespace:
    """Parse; with --quick set the options ``quick``; the options ``positive`` must be >= 1
    and --noise > 0."""
    args = ap.parse_args(argv)
    if args.quick:
        for k, v in quick.items():
            setattr(args, k, v)
    if any(getattr(args, k) < 1 for k in positive):
        ap.error(" and ".join("--" + k.replace("_", "-") for k in positive) + " must be >= 1")
    if not args.noise > 0:
        ap.error("--noise must be > 0")
    return args


def start(robot_name: str) -> tuple[Any, float]:
    """The robot and the start time of the run (the plugin registry and Warp are brought up
    by a first call before the clock starts)."""
    jwarp.robot(robot_name)
    t0 = time.perf_counter()
    return jwarp.robot(robot_name), t0


@dataclass
class Data:
    """A simulated campaign split into calibration and test rows."""

    train: Samples
    test: Samples
    y_clean: np.ndarray       # the truth's noise-free observations of the test rows
    truth: Any                # the measurement with the true setup


def split_campaign(camp: Any, n_train: int, n_test: int) -> Data:
    """The first ``n_train`` rows of ``camp.samples`` for calibration, the next ``n_test``
    for the test, and the true model's noise-free predictions of the test rows."""
    truth = make_measurement(camp.true_robot, camp.true_setup)
    train = camp.samples.select(slice(0, n_train))
    test = camp.samples.select(slice(n_train, n_train + n_test))
    y_clean = truth.predict(model_frames(camp.true_robot, test.q), camp.true_params,
                            test.meta or None)
    return Data(train, test, y_clean, truth)


def noise_floor(dim: int, sigma: float) -> float:
    """Mean norm of a ``dim``-dimensional Gaussian noise vector of per-coordinate std
    ``sigma``: the mean test error a perfect model reaches on measured data
    (sigma * sqrt(2) Gamma((dim+1)/2) / Gamma(dim/2): 0.80, 1.25, 1.60 sigma for 1, 2, 3)."""
    return sigma * math.sqrt(2.0) * math.exp(math.lgamma((dim + 1) / 2) - math.lgamma(dim / 2))


@dataclass
class Row:
    """One calibrated model of a table."""

    label: str
    free: list[str]
    test: dict[str, float]                 # vs measured test data [display unit]
    clean: dict[str, float]                # vs noise-free test data of the truth
    train: dict[str, float]
    time_s: float
    iterations: int
    nfev: int
    result: Any = None
    findings: list[str] = field(default_factory=list)
    extra: dict[str, dict[str, float]] = field(default_factory=dict)

    @property
    def n_unidentifiable(self) -> int:
        return sum("not identifiable" in w for w in self.findings)


def scaled(stats: dict[str, float], scale: float) -> dict[str, float]:
    return {k: v * scale for k, v in stats.items()}


def distance_stats_mm(x: np.ndarray, x_true: np.ndarray) -> dict[str, float]:
    """error_stats [mm] of the point distances |x - x_true| (arrays (..., 3) in m)."""
    return scaled(error_stats(np.linalg.norm(x - x_true, axis=-1)), 1000.0)


def calibrate_row(label: str, robot: Any, meas: Any, train: Samples, test: Samples,
                  y_clean: np.ndarray, free: Sequence[str], *, scale: float = 1.0,
                  n_starts: int = 1, seed: int = 0, max_nfev: int = 200,
                  fit: bool = True) -> Row:
    """Calibrate the groups ``free`` on ``train`` and evaluate on ``test`` (measured y and
    the truth's noise-free ``y_clean``); errors times ``scale`` (1000: m -> mm).
    ``fit=False``: no calibration, the nominal robot and measurement parameters."""
    t0 = time.perf_counter()
    meta_tr = train.meta or None
    meta_te = test.meta or None
    if fit:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", CalibrationWarning)
            res = calibrate(robot, meas, train.q, train.y, free=list(free), meta=meta_tr,
                            n_starts=n_starts, seed=seed, max_nfev=max_nfev)
        model, p = res.robot, res.params
        findings = list(res.warnings)
        iters, nfev = res.iterations, res.nfev
        tr = error_stats(res.errors)
        del caught
    else:
        res, model, p, findings, iters, nfev = None, robot, meas.params.nominal, [], 0, 0
        tr = error_stats(errors(model, meas, p, train.q, train.y, meta_tr))
    wall = time.perf_counter() - t0
    te = error_stats(errors(model, meas, p, test.q, test.y, meta_te))
    cl = error_stats(errors(model, meas, p, test.q, y_clean, meta_te))
    return Row(label, list(free), scaled(te, scale), scaled(cl, scale), scaled(tr, scale),
               wall, iters, nfev, res, findings)


def run_rows(plan: Sequence[tuple[str, Sequence[str] | None]], robot: Any, meas: Any,
             data: Data, args: argparse.Namespace, unit: str, *, scale: float = 1.0,
             extra: dict[str, Callable[[Row], dict[str, float]]] | None = None) -> list[Row]:
    """One ``calibrate_row`` per (label, free groups) of ``plan`` (free ``None``: no fit),
    with --starts, --seed, --max-nfev of ``args``; ``extra[name](row)`` fills
    ``row.extra[name]``. Progress per row on stderr."""
    rows = []
    for label, free in plan:
        r = calibrate_row(label, robot, meas, data.train, data.test, data.y_clean, free or [],
                          scale=scale, n_starts=args.starts, seed=args.seed,
                          max_nfev=args.max_nfev, fit=free is not None)
        for name, fn in (extra or {}).items():
            r.extra[name] = fn(r)
        rows.append(r)
        print(f"  {label}: {r.test['mean']:.3f} {unit} ({r.time_s:.1f} s)", file=sys.stderr,
              flush=True)
    return rows


def print_table(title: str, rows: list[Row], unit: str,
                paper: dict[str, tuple[float, float, float]] | None = None,
                extra: Sequence[str] = (), paper_unit: str | None = None) -> None:
    """Rows: test mean/std/max vs measured data, mean vs noise-free truth, train mean,
    optional extra columns (``row.extra[name]`` mean/std/max) and the paper's numbers."""
    print(f"\n{title}")
    head = (f"{'model':<26}{'mean':>8}{'std':>8}{'max':>8}{'clean':>8}{'train':>8}")
    for name in extra:
        head += f"{name + ' mean':>14}{'max':>8}"
    head += f"{'time':>7}{'iter':>5}{'weak':>5}"
    if paper:
        head += f"   | paper{'mean':>7}{'std':>7}{'max':>7}"
    print(head)
    print(f"{'':<26}{'test vs measured [' + unit + ']':>24}{'mean':>8}{'mean':>8}"
          + "".join(f"{'':>14}{'':>8}" for _ in extra)
          + f"{'[s]':>7}" + (f"{'':>10}   | [{paper_unit or unit}]" if paper else ""))
    for r in rows:
        line = (f"{r.label:<26}{r.test['mean']:>8.3f}{r.test['std']:>8.3f}{r.test['max']:>8.3f}"
                f"{r.clean['mean']:>8.3f}{r.train['mean']:>8.3f}")
        for name in extra:
            e = r.extra.get(name)
            line += (f"{e['mean']:>14.3f}{e['max']:>8.3f}" if e else f"{'-':>14}{'-':>8}")
        line += f"{r.time_s:>7.1f}{r.iterations:>5d}{r.n_unidentifiable:>5d}"
        if paper:
            pv = paper.get(r.label)
            line += ("   |     " + "".join(f"{v:>7.2f}" for v in pv)) if pv else "   |"
        print(line)


def floor_line(dim: int, sigma: float, unit: str) -> str:
    """One line saying what the perfect-model floor ``noise_floor(dim, sigma)`` is."""
    return (f"noise floor = mean norm of {dim}-D Gaussian noise of sigma {sigma:g} {unit} per "
            f"coordinate = {noise_floor(dim, sigma):.3f} {unit} "
            f"({noise_floor(dim, 1.0):.2f} sigma): the mean test error of a perfect model on "
            f"the measured rows; against the noise-free rows ('clean') it is 0")


@dataclass
class Check:
    """One acceptance check: what was compared (with the run's numbers) and the outcome."""

    text: str
    ok: bool


def accuracy_checks(row: Row, dim: int, sigma: float, unit: str) -> list[Check]:
    """The acceptance of a model whose truth is inside it: mean test error against the
    noise-free truth <= 1.5 sigma, and against the measured rows <= 1.5 x the noise floor
    (the 1.5 sigma of the acceptance, measured from what a perfect model scores there)."""
    floor = noise_floor(dim, sigma)
    c, m = row.clean["mean"], row.test["mean"]
    return [Check(f"mean test error vs noise-free truth {c:.3f} {unit} <= 1.5 sigma = "
                  f"{1.5 * sigma:.3g} {unit}", c <= 1.5 * sigma),
            Check(f"mean test error vs measured rows {m:.3f} {unit} <= 1.5 x perfect-model "
                  f"floor {floor:.3f} {unit} = {1.5 * floor:.3f} {unit}", m <= 1.5 * floor)]


def falls_check(text: str, rows: Sequence[Row]) -> Check:
    """``text`` + the rows' mean test errors: each strictly below the one before."""
    v = [r.test["mean"] for r in rows]
    return Check(f"{text} {' > '.join(f'{x:.3f}' for x in v)}",
                 all(b < a for a, b in zip(v, v[1:])))


def report_checks(checks: Sequence[Check], t0: float | None = None, title: str = "acceptance"
                  ) -> int:
    """Print ``title``, one ``check: <text>  PASS|FAIL`` line per check (and the total time
    since ``t0``); return the exit status: 0 when all pass, else 1."""
    print(f"\n{title}")
    for c in checks:
        print(f"check: {c.text}  {'PASS' if c.ok else 'FAIL'}")
    failed = sum(not c.ok for c in checks)
    print(f"checks: {len(checks) - failed} of {len(checks)} passed"
          + (f"; {failed} FAILED, exit status 1" if failed else ""))
    if t0 is not None:
        print(f"\ntotal {time.perf_counter() - t0:.1f} s")
    return 1 if failed else 0
