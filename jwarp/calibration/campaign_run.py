"""Calibrate a measurement campaign as ``jwarp calibrate`` does, from Python: the files read
(:func:`load_campaign`), then :func:`calibrate_campaign` with :class:`CampaignOptions`: the
calibration and test rows, the free groups (with the measurement's pose and marker groups),
the measurement's initial guess, task-oriented weighting and virtual noise, the fit (or
the ``cv``-fold cross-validation of a grid of settings, then the fit of the best), the
errors before and after, and the calibrated robot with its provenance in its notes.

Typical use::

    from jwarp.calibration import CampaignOptions, calibrate_campaign, load_campaign
    campaign = load_campaign("run/setup.json", "run/samples.csv")
    run = calibrate_campaign(campaign, CampaignOptions(
        free="theta,d,r,alpha,kappa_theta,kappa_alpha", test_rows="300:500"))
    run.robot.save("run/calibrated.json")
    run.after["test"]["mean"]          # mm for a measurement in metres

Errors are ValueError/TypeError naming the option (the field name, or the name ``names``
gives it: the CLI passes its ``--option`` spellings).
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import time
import warnings
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from jwarp.calibration.estimate.cv import CVOptions, CVResult, CVSetting, calibrate_cv
from jwarp.calibration.estimate.map import (
    CalibrationProblem,
    calibrate_with,
    problem_options,
)
from jwarp.calibration.estimate.options import CalibrationOptions
from jwarp.calibration.estimate.result import CalibrationResult, error_stats, errors
from jwarp.calibration.files import Samples, Setup
from jwarp.core.types import RobotLike
from jwarp.model.robot import RobotModel

if TYPE_CHECKING:
    from jwarp.calibration.estimate.diagnostics import Diagnostics
    from jwarp.model.measurement import Measurement

#: the ``notes`` key of a calibrated robot's provenance (a JSON object)
PROVENANCE_NOTE = "calibration"


@dataclass
class CampaignData:
    """A measured campaign as read by :func:`load_campaign`.

    Attributes:
        robot: the nominal robot (prior means of the calibration).
        measurement: the measurement plugin instance of the setup.
        setup: the measurement setup (plugin, rough poses, sigmas, ``tow`` section).
        samples: all rows of the samples file (q (S, n_dof) [rad, m], y (S, m)
            [measurement unit], meta columns, ``dir_<joint>`` directions).
        setup_path, data_path: the files as given (the provenance records their absolute
            paths; messages name them as given).
        data_sha256: SHA-256 of the samples file's bytes.
        robot_source: the robot as given (name or file; None: the setup's, or a
            RobotModel given), recorded as the provenance's ``nominal_robot`` (None: the
            robot's name).
        warnings: findings of reading the samples (e.g. rows far outside the joint limits,
            a samples file of another campaign).
    """

    robot: RobotModel
    measurement: Any
    setup: Setup
    samples: Samples
    setup_path: str
    data_path: str
    data_sha256: str
    robot_source: str | None = None
    warnings: list[str] = field(default_factory=list)


def load_campaign(setup: str | os.PathLike, data: str | os.PathLike,
                  robot: str | RobotModel | None = None) -> CampaignData:
    """Read a campaign: the setup file, the robot (``robot``, a name, .json file or
    RobotModel; None: the one the setup names), its measurement and the samples CSV.

    The reading's warnings (and a samples file whose SHA-256 is not the one the setup
    records, i.e. of another campaign) are collected in :attr:`CampaignData.warnings`,
    not emitted. ValueError naming ``robot`` when neither names a robot; the readers'
    errors name the file."""
    from jwarp.calibration.files import (
        make_measurement,
        parse_samples,
        read_setup,
        read_text,
        sha256_hex,
    )
    from jwarp.plugins.registry import robot as get_robot

    setup_path, data_path = os.fspath(setup), os.fspath(data)
    s = read_setup(setup_path)
    robot_name = robot or s.robot
    if not robot_name:
        raise ValueError("robot: not given and the setup file names no robot")
    model = get_robot(robot_name)
    meas = make_measurement(model, s)
    text, raw = read_text(data_path, "data")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        samples = parse_samples(text, model, meas, where=data_path)
    found = [str(w.message) for w in caught]
    sha = sha256_hex(raw)
    if s.samples_sha256 and s.samples_sha256 != sha:
        found.append(
            f"data: {data_path} is not the samples file of the campaign that {setup_path} "
            f"belongs to (campaign {s.campaign_id}: the SHA-256 it records differs); "
            f"are the files of two campaigns mixed up?")
    return CampaignData(model, meas, s, samples, setup_path, data_path, sha,
                        robot_source=robot if isinstance(robot, str) else None,
                        warnings=found)


@dataclass
class CampaignOptions:
    """Options of :func:`calibrate_campaign` (those of ``jwarp calibrate``).

    Attributes:
        free: free groups, comma-separated or a list: robot groups (``theta``, ``d``,
            ``r``, ``alpha``, ``beta``, ``kappa_*``, ``mass``, ``harmonic``, ...) and
            measurement groups (e.g. ``intrinsics``); the measurement's pose and marker
            groups (tracker, camera, markers, fixtures) are always freed unless in ``fix``.
        fix: measurement groups kept at their setup values (comma-separated or a list).
        fix_at: {measurement group: an earlier result, its ``to_dict()`` or the path of a
            ``--params-out`` file}: groups kept at values calibrated before.
        sigma: prior sigma overrides {group or "group:pattern": sigma} [m, rad,
            rad/(N m); inf: no prior]; orders: harmonic orders {group or pattern: K}.
        loss: "linear", "soft_l1" or "huber"; loss_scale: where the robust loss turns
            robust [unit of the measurement, e.g. m] (required with a robust loss).
        calibrate_rows, test_rows: row ranges ``"A:B"`` of the samples (None: all rows;
            without ``calibrate_rows`` the calibration rows are all rows not in
            ``test_rows``); allow_overlap: allow test rows that are calibration rows.
        cv_folds: choose the setting by K-fold cross-validation on the calibration rows
            (None: no CV), over ``cv_grid``: ``--cv-grid`` items (``AXIS=V1|V2``, or a JSON
            file) or :class:`~jwarp.calibration.estimate.cv.CVSetting` objects (None: the
            default grid); cv_workers: processes (None: one per core).
        virtual_noise: virtual noise std [unit of the measurement] added to every
            observation (thesis eq. 2.7); the setup's ``tow`` section adds task-oriented
            weighting (eq. 2.11).
        n_starts, seed, max_nfev: multi-start count, the seed of its draws (and of the
            CV folds), most residual evaluations per start.
        name: the calibrated robot's name (None: ``<robot>-calibrated``).
    """

    free: str | Iterable[str] = "theta"
    fix: str | Iterable[str] | None = None
    fix_at: Mapping[str, Any] | None = None
    sigma: Mapping[str, float] | None = None
    orders: Mapping[str, int] | None = None
    loss: str = "linear"
    loss_scale: float | None = None
    calibrate_rows: str | None = None
    test_rows: str | None = None
    allow_overlap: bool = False
    cv_folds: int | None = None
    cv_grid: Sequence[str] | Sequence[CVSetting] | None = None
    cv_workers: int | None = None
    virtual_noise: float | None = None
    n_starts: int = 1
    seed: int = 0
    max_nfev: int = 200
    name: str | None = None


@dataclass
class CampaignCalibration:
    """The result of :func:`calibrate_campaign`. Errors are in the report unit: mm for a
    measurement in metres (``scale`` 1000), else the measurement's unit.

    Attributes:
        result: the fit (:class:`~jwarp.calibration.estimate.result.CalibrationResult`;
            its ``robot`` is the calibrated robot without the provenance).
        robot: the calibrated robot, named ``options.name`` (default
            ``<robot>-calibrated``), with its provenance (JSON) in
            ``notes["calibration"]``.
        free: the free groups (with the pose and marker groups added).
        train, test: the calibration and test samples (test None without test rows);
            train_rows, test_rows: their row indices; overlap: test rows also fitted.
        directions_train, directions_test: (S, n_dof) the direction each joint last moved
            in before each row (from the previous row of the file, or its ``dir_<joint>``
            columns).
        p_start: the measurement parameters of "before": the measurement's initial guess
            on the calibration rows with the nominal robot.
        before, after: {"train"|"test": {"mean", "std", "max"}} errors of the nominal and
            the calibrated robot [unit].
        test_range: the test rows' errors inside and outside the calibration poses' range
            (``{"inside": stats | None, "outside": stats | None}``, stats with ``rows``;
            None without test rows).
        cv: the cross-validation (None without ``cv_folds``).
        warnings: the fit's findings, the overlap and the test rows outside the range.
        unit, scale: the report unit and its factor from the measurement's unit.
        time_s: wall time of the fit [s].
        measurement: the campaign's measurement plugin (that of ``result.params``).
    """

    result: CalibrationResult
    robot: RobotModel
    free: list[str]
    train: Samples
    test: Samples | None
    train_rows: np.ndarray
    test_rows: np.ndarray | None
    overlap: int
    directions_train: np.ndarray
    directions_test: np.ndarray | None
    p_start: np.ndarray
    before: dict[str, dict[str, float]]
    after: dict[str, dict[str, float]]
    test_range: dict[str, Any] | None
    cv: CVResult | None
    warnings: list[str]
    unit: str
    scale: float
    time_s: float
    measurement: Any = None

    def diagnostics(self, bins: int = 5) -> Diagnostics:
        """The residual diagnostics of the calibrated robot on the calibration rows, as
        ``jwarp calibrate --diagnostics`` prints them
        (:func:`~jwarp.calibration.estimate.diagnostics.residual_diagnostics` with the rows'
        motion directions): correlation between end-effectors, residual against joint
        angles and torques, in the measurement's unit (``to_dict(self.scale)`` and
        ``format_diagnostics(d, self.scale, self.unit)`` report them in :attr:`unit`).

        Args:
            bins: equal-count bins of each joint value (>= 2, at most the calibration rows).

        Returns:
            :class:`~jwarp.calibration.estimate.diagnostics.Diagnostics`.
        """
        from jwarp.calibration.estimate.diagnostics import residual_diagnostics

        if self.measurement is None:
            raise ValueError("measurement: not recorded (a CampaignCalibration made by hand; "
                             "calibrate_campaign records it)")
        t = self.train
        return residual_diagnostics(self.result.robot, self.measurement, self.result.params,
                                    t.q, t.y, t.meta or None, bins=bins,
                                    directions=self.directions_train)


class _Names:
    """The name of each option in messages: ``names[field]`` or the field itself."""

    def __init__(self, names: Mapping[str, str] | None):
        self.names = dict(names or {})

    def __call__(self, name: str) -> str:
        return self.names.get(name, name)


def report_unit(measurement: Measurement) -> tuple[float, str]:
    """(factor, unit) of the errors reported: (1000, "mm") for a measurement in metres,
    else (1, the measurement's unit)."""
    return (1000.0, "mm") if measurement.unit == "m" else (1.0, measurement.unit)


def split_rows(n: int, calibrate_rows: str | None, test_rows: str | None,
               allow_overlap: bool = False, names: Mapping[str, str] | None = None
               ) -> tuple[np.ndarray, np.ndarray | None, int]:
    """(calibration row indices, test row indices or None, rows in both) of ``n`` rows
    from the ranges ``"A:B"`` (see :class:`CampaignOptions`). ValueError naming the
    option on a bad range, no calibration row left, or an overlap not allowed."""
    from jwarp.calibration.files import parse_rows

    nm = _Names(names)
    every = np.arange(n)
    test = every[parse_rows(test_rows, n, nm("test_rows"))] if test_rows else None
    if calibrate_rows is None and test is not None:
        train = np.setdiff1d(every, test)  # default: the rows that are not test rows
        if not len(train):
            raise ValueError(f"{nm('test_rows')}: {test_rows} covers all {n} rows; none are "
                             f"left for calibration (give {nm('calibrate_rows')})")
    else:
        train = every[parse_rows(calibrate_rows, n, nm("calibrate_rows"))]
    common = np.intersect1d(train, test) if test is not None else train[:0]
    both = len(common)
    if both and not allow_overlap:
        raise ValueError(f"{nm('test_rows')}: rows {common[0]}:{common[-1] + 1} are also "
                         f"calibration rows ({nm('calibrate_rows')} {calibrate_rows}); test "
                         f"rows must not be fitted: give disjoint ranges, or "
                         f"{nm('allow_overlap')} to test on fitted rows anyway")
    return train, test, both


def free_groups(measurement: Measurement, free: str | Iterable[str],
                fix: str | Iterable[str] | None, names: Mapping[str, str] | None = None
                ) -> list[str]:
    """``free`` plus the measurement's pose and marker groups not in ``fix``
    (:func:`~jwarp.calibration.estimate.params.with_pose_groups`); ValueError naming
    ``free`` or ``fix``."""
    from jwarp.calibration.estimate.params import with_pose_groups

    nm = _Names(names)
    try:
        return with_pose_groups(measurement, free or "", fix)
    except ValueError as e:
        msg = str(e)
        opt = nm("fix") if msg.startswith("fix:") else nm("free")
        raise ValueError(f"{opt}: {msg.split(': ', 1)[1]}") from None


def _cv_settings(o: CampaignOptions, n_train: int, nm: _Names) -> list[CVSetting] | None:
    """The grid of ``cv_folds`` (None without it)."""
    if o.cv_folds is None:
        if o.cv_grid or o.cv_workers is not None:
            raise ValueError(f"{nm('cv_grid') if o.cv_grid else nm('cv_workers')}: only with "
                             f"{nm('cv_folds')} K (cross-validation)")
        return None
    if (isinstance(o.cv_folds, bool) or not isinstance(o.cv_folds, (int, np.integer))
            or not 2 <= o.cv_folds <= n_train):
        raise ValueError(f"{nm('cv_folds')}: expected an integer in [2, {n_train}] (folds of "
                         f"the {n_train} calibration rows), got {o.cv_folds}")
    if o.cv_workers is not None and (isinstance(o.cv_workers, bool) or not isinstance(
            o.cv_workers, (int, np.integer)) or o.cv_workers < 1):
        raise ValueError(f"{nm('cv_workers')}: expected an integer >= 1, got {o.cv_workers}")
    items = list(o.cv_grid or [])
    settings = [s for s in items if isinstance(s, CVSetting)]
    if items and len(settings) == len(items):
        return settings
    from jwarp.calibration.estimate.cv import parse_cv_grid

    return parse_cv_grid([str(s) for s in items], option=nm("cv_grid"))


def _tow_covariance(o: CampaignOptions, campaign: CampaignData, train: Samples,
                    free: list[str], nm: _Names) -> np.ndarray | None:
    """Per-sample covariance of the calibration rows: the setup's ``tow`` section (eq. 2.11,
    linearized at the start: nominal robot, initial guess of the measurement) plus
    ``virtual_noise`` (eq. 2.7); None when neither is given."""
    from jwarp.calibration.design.tow import tow_covariance, tow_from_dict
    from jwarp.calibration.design.virtual_noise import add_virtual_noise

    setup, model, meas = campaign.setup, campaign.robot, campaign.measurement
    if setup.tow is None and o.virtual_noise is None:
        return None
    if o.virtual_noise is not None and not (
            isinstance(o.virtual_noise, (int, float, np.floating))
            and not isinstance(o.virtual_noise, bool)
            and math.isfinite(o.virtual_noise) and o.virtual_noise >= 0):
        raise ValueError(f"{nm('virtual_noise')}: expected a finite number >= 0, got "
                         f"{o.virtual_noise}")
    m = meas.n_obs
    cov = np.broadcast_to(np.diag(np.broadcast_to(np.asarray(meas.noise, float) ** 2, (m,))),
                          (len(train), m, m))
    if setup.tow is not None:
        spec = tow_from_dict(setup.tow, model, where=f"{campaign.setup_path}: tow")
        prob = CalibrationProblem(model, meas, train.q, train.y, problem_options(free=free),
                                  meta=train.meta or None)
        st = prob.state(prob.initial_x())
        cov = tow_covariance(meas, spec, st.frames, st.p, meta=train.meta or None)
    if o.virtual_noise is not None:
        try:
            cov = add_virtual_noise(cov, o.virtual_noise)
        except ValueError as e:
            raise ValueError(f"{nm('virtual_noise')}: "
                             f"{str(e).removeprefix('virtual: ')}") from None
    return cov


def _stats(err: np.ndarray, scale: float) -> dict[str, float]:
    return {k: v * scale for k, v in error_stats(err).items()}


def _test_range(res: CalibrationResult, meas: Any, test: Samples, scale: float,
                directions: Any, where: str) -> tuple[dict[str, Any], str | None]:
    """The test rows' errors of the calibrated robot inside and outside the range of the
    calibration poses and the warning naming how far outside (None: all inside)."""
    from jwarp.model.valid_range import outside_message

    err = errors(res.robot, meas, res.params, test.q, test.y, test.meta or None,
                 directions=directions)
    vr = res.valid_range   # set by every fit: the calibration poses' range
    out = vr.outside(test.q) if vr is not None else np.zeros(len(test), bool)
    doc: dict[str, Any] = {}
    for label, mask in (("inside", ~out), ("outside", out)):
        doc[label] = ({**_stats(err[mask], scale), "rows": int(mask.sum())}
                      if mask.any() else None)
    return doc, outside_message(res.robot, test.q, where)


def with_provenance(robot: RobotModel, campaign: CampaignData, options: CampaignOptions,
                    free: Sequence[str], before: dict, after: dict, unit: str, n_train: int,
                    n_test: int, cv: dict | None = None) -> RobotModel:
    """The calibrated robot renamed (``options.name``, default ``<name>-calibrated``) with
    its provenance in ``notes['calibration']`` (JSON: campaign id, input files and the
    SHA-256 of the samples, rows, free groups, errors before/after [unit], date, jwarp
    version; ``cv``: the cross-validation's choice and table)."""
    from datetime import datetime, timezone

    from jwarp import __version__

    o = options
    base = robot.name.removesuffix("-calibrated")
    name = o.name if o.name is not None else f"{base}-calibrated"
    prov = {
        "date": datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "jwarp_version": str(__version__),
        "nominal_robot": robot.name if campaign.robot_source is None else campaign.robot_source,
        "campaign_id": campaign.setup.campaign_id,
        "setup": os.path.abspath(campaign.setup_path),
        "data": os.path.abspath(campaign.data_path), "data_sha256": campaign.data_sha256,
        "calibrate_rows": o.calibrate_rows, "test_rows": o.test_rows,
        "samples": {"train": n_train, "test": n_test}, "free": list(free),
        "loss": o.loss, "starts": o.n_starts,
        "errors": {"unit": unit, "before": before, "after": after},
    }
    if cv is not None:   # cv_folds: the settings chosen, their CV error and the table
        prov["cv"] = cv
    notes = dict(robot.notes)
    notes[PROVENANCE_NOTE] = json.dumps(prov, sort_keys=False)
    return dataclasses.replace(robot, name=name, notes=notes)


def calibrate_campaign(campaign: CampaignData, options: CampaignOptions | None = None, *,
                       callback: Callable[[Any], Any] | None = None,
                       names: Mapping[str, str] | None = None) -> CampaignCalibration:
    """Calibrate ``campaign`` as ``jwarp calibrate`` does (see the module doc).

    Steps: the calibration and test rows (``calibrate_rows``, ``test_rows``); the joints'
    motion directions (previous row, or the file's ``dir_<joint>`` columns); the free
    groups with the pose and marker groups not fixed; "before": the nominal robot with
    the measurement's initial guess on the calibration rows; the covariance of the
    setup's ``tow`` section and ``virtual_noise``; the MAP fit
    (:func:`~jwarp.calibration.calibrate_with`; with ``cv_folds``
    :func:`~jwarp.calibration.calibrate_cv`) with the findings collected, not warned;
    "after"; the test rows inside and outside the calibration poses' range; the
    calibrated robot with its provenance.

    Args:
        campaign: from :func:`load_campaign`.
        options: :class:`CampaignOptions` (None: the defaults).
        callback: called with :class:`~jwarp.calibration.Progress` after every solver
            iteration (a progress bar).
        names: {option field: the name messages give it} (default: the field names;
            the CLI passes ``{"test_rows": "--test-rows", ...}``).

    Raises:
        ValueError/TypeError naming the option: bad rows, too few calibration rows for the
        free parameters or for the measurement's initial guess, bad groups, sigmas,
        orders, CV settings, virtual noise or loss scale.
    """
    o = CampaignOptions() if options is None else options
    if not isinstance(o, CampaignOptions):
        raise TypeError(f"options: expected CampaignOptions, got {type(o).__name__}")
    nm = _Names(names)
    if o.name is not None and (not isinstance(o.name, str) or not o.name.strip()):
        raise ValueError(f"{nm('name')}: empty robot name")
    from jwarp.calibration.estimate.backlash import motion_directions
    from jwarp.calibration.estimate.result import model_frames

    model, meas, data = campaign.robot, campaign.measurement, campaign.samples
    train_rows, test_rows, both = split_rows(len(data), o.calibrate_rows, o.test_rows,
                                             o.allow_overlap, names)
    train = data.select(train_rows)
    test = data.select(test_rows) if test_rows is not None else None
    # the direction each joint last moved in, from the previous row of the file (the
    # measurement order) or its dir_<joint> columns: the backlash group's, and that of a
    # robot recording backlash
    directions = motion_directions(data.q)
    if data.directions is not None:   # the file's dir_<joint> columns, where given
        directions = np.where(np.isnan(data.directions), directions, data.directions)
    dir_train = directions[train_rows]
    dir_test = directions[test_rows] if test_rows is not None else None
    free = free_groups(meas, o.free, o.fix, names)
    scale, unit = report_unit(meas)
    fix_at = dict(o.fix_at) if o.fix_at else {}
    if fix_at:
        from jwarp.calibration.estimate.result import fixed_params

        try:
            fixed_params(meas, fix_at)
        except ValueError as e:
            raise ValueError(f"{nm('fix_at')}: " + str(e).split(": ", 1)[1]) from None
    cv_settings = _cv_settings(o, len(train), nm)
    cv_result = None

    def table_rows(robot: RobotLike, p: np.ndarray) -> dict[str, dict[str, float]]:
        out = {"train": _stats(errors(robot, meas, p, train.q, train.y, train.meta or None,
                                      directions=dir_train), scale)}
        if test is not None:
            out["test"] = _stats(errors(robot, meas, p, test.q, test.y, test.meta or None,
                                        directions=dir_test), scale)
        return out

    try:
        p_start = meas.initial_guess(model_frames(model, train.q, elastic=False), train.y,
                                     meas.params.nominal, train.meta or None)
    except ValueError as e:
        why = str(e).removeprefix("initial_guess: ")
        raise ValueError(f"{nm('calibrate_rows')}: the initial guess of the '{meas.name}' "
                         f"measurement fails on {len(train)} calibration "
                         f"row{'s' if len(train) != 1 else ''} ({why}); give more (or more "
                         f"varied) rows") from None
    before = table_rows(model, p_start)
    covariance = _tow_covariance(o, campaign, train, free, nm)
    t0 = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            copts = CalibrationOptions(
                free=free, free_poses=False, n_starts=o.n_starts, seed=o.seed,
                max_nfev=o.max_nfev, callback=callback, covariance=covariance,
                sigma=o.sigma or None, orders=o.orders or None, loss=o.loss,
                loss_scale=o.loss_scale,
                fix_at=fix_at or None, warn=False,  # the findings: res.warnings, once
                directions=dir_train)
            if cv_settings is None:
                res = calibrate_with(model, meas, train.q, train.y, copts,
                                     meta=train.meta or None)
            else:
                folds = int(o.cv_folds or 0)   # given: cv_settings is not None
                cvo = CVOptions(folds=folds, settings=cv_settings, seed=o.seed,
                                workers=o.cv_workers)
                res, cv_result = calibrate_cv(model, meas, train.q, train.y, copts, cvo,
                                              meta=train.meta or None)
        except ValueError as e:
            msg = str(e)
            if msg.startswith("q, y: "):  # too few rows for the free parameters
                raise ValueError(f"{nm('calibrate_rows')}: " + msg.removeprefix(
                    "q, y: ").replace("give more samples", "give more rows")) from None
            if cv_settings is not None and msg.startswith(("free:", "sigma", "orders")):
                raise ValueError(f"{nm('cv_grid')}: a setting fails: {e}") from None
            for name in ("sigma", "orders"):
                if msg.startswith(name) and nm(name) != name:
                    raise ValueError(f"{nm(name)}: {e}") from None
            if msg.startswith("loss_scale: "):
                raise ValueError(f"{nm('loss_scale')}: "
                                 f"{msg.removeprefix('loss_scale: ')}") from None
            raise
    wall = time.perf_counter() - t0
    after = table_rows(res.robot, res.params)
    calibrated = with_provenance(res.robot, campaign, o, free, before, after, unit,
                                 len(train), 0 if test is None else len(test),
                                 cv=None if cv_result is None else cv_result.to_dict(scale, unit))
    n_test = 0 if test is None else len(test)
    found = list(res.warnings) + [str(w.message) for w in caught
                                  if str(w.message) not in res.warnings
                                  and w.category.__name__ != "CalibrationWarning"]
    if both:
        found.append(f"{both} of the {n_test} test rows were also calibration rows "
                     f"({nm('allow_overlap')}): their errors are not independent of the fit")
    test_range = None
    if test is not None:
        test_range, rng_msg = _test_range(res, meas, test, scale, dir_test, nm("test_rows"))
        if rng_msg is not None:
            found.append(rng_msg)
    return CampaignCalibration(
        result=res, robot=calibrated, free=free, train=train, test=test,
        train_rows=train_rows, test_rows=test_rows, overlap=both,
        directions_train=dir_train, directions_test=dir_test, p_start=p_start,
        before=before, after=after, test_range=test_range, cv=cv_result, warnings=found,
        unit=unit, scale=scale, time_s=wall, measurement=meas)
