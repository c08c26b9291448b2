"""Shared helpers of the calibration examples (calibrate_*.py): one calibration per table
row, error statistics against the measured and the noise-free test data, table printing.

Not a library module: the examples import it from their own folder.
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np

from jwarp.solvers.calibration import CalibrationWarning, calibrate, error_stats, errors
from jwarp.solvers.calibration.files import Samples


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


def monotone(values: Sequence[float], tol: float = 0.0) -> bool:
    """True when every value is <= the one before (+ tol)."""
    return all(b <= a + tol for a, b in zip(values, values[1:]))


def verdict(ok: bool) -> str:
    return "PASS" if ok else "FAIL"
