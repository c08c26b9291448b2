"""Settings of a calibration chosen by K-fold cross-validation (issue 38 item 1).

Prior strengths, harmonic orders and free groups decide how well a calibration predicts
poses it was not fitted on; trying them against the test rows is fitting the test rows.
:func:`cross_validate` scores a grid of :class:`CVSetting` on the calibration rows alone:
the rows are split into K folds (a seeded permutation), every setting is fitted on K - 1
folds and its errors measured on the fold left out, for all K folds; the CV error of a
setting is the mean of the per-marker error norms over all held-out rows (every row
held out once). :func:`calibrate_cv` then fits the best setting on all rows and records
the choice and the table in ``result.provenance['cv']``.

The fits run in parallel worker processes (``workers``; default: one per core, at most
one per fit), each with its BLAS pool held to one thread (small dense solves gain nothing
from BLAS threads and oversubscribe the cores: :mod:`jwarp.core.threads`); ``workers=1``
runs them in this process. The numbers do not depend on ``workers``.

``jwarp calibrate --cv K [--cv-grid ...]`` is the CLI (:func:`parse_cv_grid`).
"""

from __future__ import annotations

import dataclasses
import itertools
import json
import math
import os
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from jwarp.calibration.estimate.options import CalibrationOptions
from jwarp.calibration.estimate.params import DEFAULT_SIGMA, ROBOT_GROUPS, parse_groups
from jwarp.core.types import ArrayLike, RobotLike
from jwarp.utils.checks import check_int

if TYPE_CHECKING:
    from jwarp.model.measurement import Measurement

#: the prior scales of the default grid (:func:`default_grid`): factors on the prior sigma
#: of every free robot group
DEFAULT_SCALES = (0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0)


@dataclass(frozen=True)
class CVSetting:
    """One setting of the grid: changes to the base :class:`CalibrationOptions`.

    Attributes:
        label: the setting's name in the table (default: made from the changes).
        prior_scale: factor (> 0) on the prior sigma of every free robot group (the
            group's own sigma and its pattern keys; from ``options.sigma`` or
            :data:`~jwarp.calibration.estimate.params.DEFAULT_SIGMA`); measurement
            groups keep theirs.
        sigma: prior sigma overrides ``{group[:pattern]: sigma}`` [SI] merged over the
            base options' (after ``prior_scale``).
        orders: harmonic orders ``{group[:pattern]: K}`` merged over the base's.
        free: the free groups instead of the base's (None: the base's).
    """

    label: str = ""
    prior_scale: float = 1.0
    sigma: Mapping[str, float] | None = None
    orders: Mapping[str, int] | None = None
    free: str | None = None

    def name(self) -> str:
        """``label``, or a description of the changes (``"base"`` for none)."""
        if self.label:
            return self.label
        parts = []
        if self.prior_scale != 1.0:
            parts.append(f"scale={self.prior_scale:g}")
        parts += [f"prior:{k}={v:g}" for k, v in (self.sigma or {}).items()]
        parts += [f"order:{k}={v}" for k, v in (self.orders or {}).items()]
        if self.free is not None:
            parts.append(f"free={self.free}")
        return " ".join(parts) or "base"

    def to_dict(self) -> dict[str, Any]:
        """JSON document of the setting."""
        d: dict[str, Any] = {"label": self.name(), "prior_scale": float(self.prior_scale)}
        if self.sigma:
            d["sigma"] = {str(k): float(v) for k, v in self.sigma.items()}
        if self.orders:
            d["orders"] = {str(k): int(v) for k, v in self.orders.items()}
        if self.free is not None:
            d["free"] = self.free
        return d

    def apply(self, options: CalibrationOptions) -> CalibrationOptions:
        """The base ``options`` with this setting's changes (no callback, no warnings)."""
        s = self.prior_scale
        if isinstance(s, bool) or not isinstance(s, (int, float)) or not (
                math.isfinite(s) and s > 0):
            raise ValueError(f"prior_scale: expected a finite number > 0, got {s!r}")
        free = options.free if self.free is None else self.free
        sigma: dict[str, float] = dict(options.sigma or {})
        if s != 1.0:
            robot_free = [g for g in parse_groups(free) if g in ROBOT_GROUPS]
            for g in robot_free:
                sigma[g] = float(sigma.get(g, DEFAULT_SIGMA[g])) * s
            for k in list(sigma):
                g, sep, _ = k.partition(":")
                if sep and g in robot_free:
                    sigma[k] = float(sigma[k]) * s
        sigma.update(self.sigma or {})
        orders: dict[str, int] = dict(options.orders or {})
        orders.update(self.orders or {})
        return dataclasses.replace(options, free=free, sigma=sigma or None,
                                   orders=orders or None, callback=None, warn=False)


def default_grid(scales: Iterable[float] = DEFAULT_SCALES) -> list[CVSetting]:
    """The grid without ``--cv-grid``: the prior of every free robot group scaled by each
    factor of :data:`DEFAULT_SCALES` (1 is the base settings)."""
    return [CVSetting(prior_scale=float(s)) for s in scales]


def parse_cv_grid(items: Sequence[str] | None, option: str = "--cv-grid") -> list[CVSetting]:
    """The grid of ``--cv-grid`` items (their product; None or empty: :func:`default_grid`).

    Each item is ``AXIS=V1|V2|...``: ``scale`` (prior scale factors), ``prior:KEY``
    (sigmas of a group or ``group:pattern`` key [SI]), ``order:KEY`` (harmonic orders),
    ``free`` (free-group lists, e.g. ``free=theta,d|theta,d,harmonic``); or the path of a
    JSON file holding a list of settings ``{"label", "prior_scale", "sigma", "orders",
    "free"}``. ValueError naming ``option`` on bad input.
    """
    if not items:
        return default_grid()
    axes: list[list[dict[str, Any]]] = []
    out: list[CVSetting] = []
    for item in items:
        if "=" not in item:
            out += _grid_file(item, option)
            continue
        key, _, vals = item.partition("=")
        key = key.strip()
        alts = [v.strip() for v in vals.split("|")]
        if not key or not all(alts):
            raise ValueError(f"{option}: expected AXIS=V1|V2|..., got '{item}'")
        axis: list[dict[str, Any]] = []
        for v in alts:
            try:
                if key == "scale":
                    f = float(v)
                    if not (math.isfinite(f) and f > 0):
                        raise ValueError
                    axis.append({"prior_scale": f})
                elif key.startswith("prior:") and key[6:]:
                    f = float(v)
                    if not f > 0:
                        raise ValueError
                    axis.append({"sigma": {key[6:]: f}})
                elif key.startswith("order:") and key[6:]:
                    k = int(v)
                    if k < 0:
                        raise ValueError
                    axis.append({"orders": {key[6:]: k}})
                elif key == "free":
                    parse_groups(v)
                    axis.append({"free": v})
                else:
                    raise KeyError(key)
            except KeyError:
                raise ValueError(f"{option}: unknown axis '{key}' (scale, prior:KEY, order:KEY "
                                 f"or free)") from None
            except (TypeError, ValueError):
                raise ValueError(f"{option}: {key}: bad value '{v}' (scale: a number > 0; "
                                 f"prior: a sigma > 0; order: an integer >= 0)") from None
        axes.append(axis)
    for combo in itertools.product(*axes) if axes else ():
        merged: dict[str, Any] = {"sigma": {}, "orders": {}}
        for part in combo:
            for name, val in part.items():
                if name in ("sigma", "orders"):
                    merged[name].update(val)
                else:
                    merged[name] = val
        out.append(CVSetting(prior_scale=merged.get("prior_scale", 1.0),
                             sigma=merged["sigma"] or None, orders=merged["orders"] or None,
                             free=merged.get("free")))
    return out


def _grid_file(path: str, option: str) -> list[CVSetting]:
    if not os.path.isfile(path):
        raise ValueError(f"{option}: '{path}' is neither AXIS=V1|V2|... nor a file")
    try:
        with open(path, encoding="utf-8") as fh:
            doc = json.load(fh)
    except (OSError, ValueError) as e:
        raise ValueError(f"{option}: {path}: not a readable JSON file ({e})") from None
    if not isinstance(doc, list) or not doc:
        raise ValueError(f"{option}: {path}: expected a non-empty JSON list of settings")
    out = []
    for k, d in enumerate(doc):
        if not isinstance(d, dict):
            raise ValueError(f"{option}: {path}: entry {k} is not an object")
        extra = set(d) - {"label", "prior_scale", "sigma", "orders", "free"}
        if extra:
            raise ValueError(f"{option}: {path}: entry {k}: unknown key '{sorted(extra)[0]}'")
        try:
            out.append(CVSetting(label=str(d.get("label", "")),
                                 prior_scale=float(d.get("prior_scale", 1.0)),
                                 sigma=d.get("sigma"), orders=d.get("orders"),
                                 free=d.get("free")))
        except (TypeError, ValueError) as e:
            raise ValueError(f"{option}: {path}: entry {k}: {e}") from None
    return out


@dataclass
class CVOptions:
    """Options of a cross-validation (:func:`cross_validate`, :func:`calibrate_cv`);
    :meth:`validate` raises ValueError/TypeError naming the field.

    Attributes:
        folds: K, the number of folds (2 <= K <= the calibration rows).
        settings: the grid (:class:`CVSetting`); None: :func:`default_grid`.
        seed: the seed of the fold permutation (an integer >= 0).
        workers: processes running the fits (None: :func:`default_workers`, one per
            core; 1: in this process).
    """

    folds: int = 5
    settings: Sequence[CVSetting] | None = None
    seed: int = 0
    workers: int | None = None

    def validate(self) -> None:
        """ValueError/TypeError naming the first bad field (``folds`` against the rows:
        :func:`fold_indices`)."""
        check_int(self.folds, "folds", 2)
        check_int(self.seed, "seed", 0)
        check_int(self.workers, "workers", 1, none=True)
        if self.settings is not None and (
                isinstance(self.settings, (str, bytes)) or not len(self.settings)
                or not all(isinstance(x, CVSetting) for x in self.settings)):
            raise TypeError("settings: expected a non-empty sequence of CVSetting or None")


@dataclass
class CVResult:
    """The cross-validation table.

    Attributes:
        settings: (G,) the settings scored.
        errors: (G,) CV error of each: mean per-marker error norm over all held-out rows
            [measurement unit].
        fold_errors: (G, K) mean error per held-out fold.
        best: index of the chosen setting (lowest CV error).
        folds: K; seed: the seed of the fold permutation; rows: calibration rows;
        time_s: wall time of all fits [s]; workers: processes used.
    """

    settings: list[CVSetting]
    errors: np.ndarray
    fold_errors: np.ndarray
    best: int
    folds: int
    seed: int
    rows: int
    time_s: float
    workers: int
    unit: str = "m"
    fold_of: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))

    @property
    def chosen(self) -> CVSetting:
        """The setting with the lowest CV error."""
        return self.settings[self.best]

    def table(self, scale: float = 1.0, unit: str | None = None) -> str:
        """The table as text (errors times ``scale``, e.g. 1e3 for mm), the choice marked."""
        u = unit or self.unit
        w = max(12, *(len(s.name()) for s in self.settings))
        rows = [f"cross-validation: {self.folds} folds of {self.rows} calibration rows, "
                f"{len(self.settings)} settings ({self.time_s:.1f} s, {self.workers} "
                f"process{'es' if self.workers != 1 else ''})",
                f"  {'setting':<{w}} {'CV mean':>10} {'fold std':>10}   [{u}]"]
        for g, s in enumerate(self.settings):
            mark = "  <- chosen" if g == self.best else ""
            rows.append(f"  {s.name():<{w}} {self.errors[g] * scale:>10.4f} "
                        f"{np.std(self.fold_errors[g]) * scale:>10.4f}{mark}")
        return "\n".join(rows)

    def to_dict(self, scale: float = 1.0, unit: str | None = None) -> dict[str, Any]:
        """JSON document: folds, seed, the chosen setting and its CV error, the table."""
        return {"folds": int(self.folds), "seed": int(self.seed), "rows": int(self.rows),
                "unit": unit or self.unit, "chosen": self.chosen.to_dict(),
                "cv_error": float(self.errors[self.best] * scale),
                "time_s": float(self.time_s), "workers": int(self.workers),
                "table": [{**s.to_dict(), "cv_error": float(e * scale),
                           "fold_errors": [float(v * scale) for v in fe]}
                          for s, e, fe in zip(self.settings, self.errors, self.fold_errors)]}


def fold_indices(n: int, folds: int, seed: int = 0) -> np.ndarray:
    """(n,) fold index of each row: a seeded permutation cut into ``folds`` near-equal
    parts (ValueError naming ``folds`` unless 2 <= folds <= n)."""
    if isinstance(folds, bool) or not isinstance(folds, (int, np.integer)) or not (
            2 <= folds <= n):
        raise ValueError(f"folds: expected an integer in [2, {n}] (the calibration rows), "
                         f"got {folds!r}")
    perm = np.random.default_rng(seed).permutation(n)
    out = np.empty(n, np.int64)
    out[perm] = np.arange(n) % folds
    return out


def _slice_meta(meta: Mapping[str, Any] | None, rows: np.ndarray) -> dict[str, Any] | None:
    if not meta:
        return None
    return {k: np.asarray(v)[rows] for k, v in meta.items()}


def _fold_options(options: CalibrationOptions, rows: np.ndarray) -> CalibrationOptions:
    """``options`` for the fit on ``rows``: a per-sample covariance (S, m, m) and the
    directions of motion (S, n_dof) sliced."""
    cov = options.covariance
    if cov is not None and np.ndim(cov) == 3:
        options = dataclasses.replace(options, covariance=np.asarray(cov)[rows])
    if options.directions is not None:
        options = dataclasses.replace(options, directions=np.asarray(options.directions)[rows])
    return options


def _fit_fold(task: tuple) -> tuple[int, int, np.ndarray]:
    """One fit on the training folds and its per-marker errors (R, G) on the held-out
    fold (a worker process's task)."""
    from jwarp.calibration.estimate.map import calibrate_with
    from jwarp.calibration.estimate.result import errors

    g, k, robot, meas, q, y, meta, options, train, test = task
    res = calibrate_with(robot, meas, q[train], y[train], _fold_options(options, train),
                         meta=_slice_meta(meta, train))
    dirs = None if options.directions is None else np.asarray(options.directions)[test]
    err = errors(res.robot, meas, res.params, q[test], y[test], _slice_meta(meta, test),
                 directions=dirs)
    return g, k, err


def _init_worker() -> None:
    """A worker process: one BLAS thread (the folds are the parallelism)."""
    from threadpoolctl import threadpool_limits

    threadpool_limits(1)


def default_workers(tasks: int) -> int:
    """Worker processes for ``tasks`` fits: the cores this process may use, at most one
    per fit."""
    try:
        cores = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        cores = os.cpu_count() or 1
    return max(1, min(cores, tasks))


def cross_validate(robot: RobotLike, measurement: Measurement, q: ArrayLike, y: Any, options: CalibrationOptions,
                   cv: CVOptions | None = None, *,
                   meta: Mapping[str, Any] | None = None) -> CVResult:
    """Score the settings of ``cv`` (:class:`CVOptions`; default 5 folds of
    :func:`default_grid`) by K-fold cross-validation on the rows q (S, n_dof), y (S, m)
    (module docstring).

    Args:
        robot, measurement, meta: as :func:`~jwarp.calibration.calibrate`.
        options: the base :class:`CalibrationOptions` each setting changes.
        cv: folds, grid, seed of the fold permutation, worker processes.

    Returns:
        :class:`CVResult` (the best setting: lowest CV error; ties: the first).
    """
    import time

    from jwarp.calibration.estimate.samples import check_samples
    from jwarp.plugins.registry import robot as get_robot

    t0 = time.perf_counter()
    if not isinstance(options, CalibrationOptions):
        raise TypeError(f"options: expected a CalibrationOptions, got {type(options).__name__}")
    options.validate()
    cv = CVOptions() if cv is None else cv
    if not isinstance(cv, CVOptions):
        raise TypeError(f"cv: expected a CVOptions, got {type(cv).__name__}")
    cv.validate()
    folds, seed, workers = int(cv.folds), int(cv.seed), cv.workers
    grid = list(default_grid() if cv.settings is None else cv.settings)
    model = get_robot(robot)
    qa, ya, md = check_samples(model, measurement, q, y, meta)
    fold = fold_indices(len(qa), folds, seed)
    if options.directions is None:   # the direction of motion: from all rows' order
        from jwarp.calibration.estimate.backlash import motion_directions

        options = dataclasses.replace(options, directions=motion_directions(qa))
    opts = [x.apply(options) for x in grid]
    for o in opts:
        o.validate()
    tasks = [(g, k, model, measurement, qa, ya, md or None, opts[g],
              np.flatnonzero(fold != k), np.flatnonzero(fold == k))
             for g in range(len(grid)) for k in range(folds)]
    n_workers = default_workers(len(tasks)) if workers is None else min(int(workers), len(tasks))
    results: list[tuple[int, int, np.ndarray]]
    if n_workers == 1:
        results = [_fit_fold(t) for t in tasks]
    else:
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        with ProcessPoolExecutor(max_workers=n_workers,
                                 mp_context=multiprocessing.get_context("spawn"),
                                 initializer=_init_worker) as ex:
            results = list(ex.map(_fit_fold, tasks))
    G = len(grid)
    held = [np.zeros(0)] * (G * folds)
    for g, k, err in results:
        held[g * folds + k] = err
    fold_err = np.array([[float(np.mean(held[g * folds + k])) for k in range(folds)]
                         for g in range(G)])
    cv_err = np.array([float(np.mean(np.concatenate([held[g * folds + k].reshape(-1)
                                                     for k in range(folds)])))
                       for g in range(G)])
    return CVResult(settings=grid, errors=cv_err, fold_errors=fold_err,
                    best=int(np.argmin(cv_err)),
                    folds=int(folds), seed=int(seed), rows=len(qa),
                    time_s=time.perf_counter() - t0, workers=n_workers,
                    unit=str(getattr(measurement, "unit", "m")), fold_of=fold)


def calibrate_cv(robot: RobotLike, measurement: Measurement, q: ArrayLike, y: Any, options: CalibrationOptions,
                 cv: CVOptions | None = None, *, meta: Mapping[str, Any] | None = None
                 ) -> tuple[Any, CVResult]:
    """:func:`cross_validate`, then the calibration with the chosen setting on all rows
    (with ``options``' callback and warnings). Returns (the
    :class:`~jwarp.calibration.estimate.result.CalibrationResult`, whose
    ``provenance['cv']`` records the choice, its CV error and the table; the
    :class:`CVResult`)."""
    from jwarp.calibration.estimate.map import calibrate_with
    from jwarp.plugins.registry import robot as get_robot

    model = get_robot(robot)   # resolved once here; both steps take the model
    table = cross_validate(model, measurement, q, y, options, cv, meta=meta)
    final = dataclasses.replace(table.chosen.apply(options), callback=options.callback,
                                warn=options.warn)
    res = calibrate_with(model, measurement, q, y, final, meta=meta)
    res.provenance = dict(res.provenance, cv=table.to_dict())
    return res, table
