"""Issue 38 item 1: settings chosen by K-fold cross-validation on the calibration rows
(``jwarp calibrate --cv K --cv-grid ...``, :mod:`jwarp.calibration.estimate.cv`)."""

from __future__ import annotations

import contextlib
import io
import json
import math
import warnings

import numpy as np
import pytest
from cli_helpers import one_line_error, run  # tests/cli_helpers.py

import jwarp
from jwarp.calibration import CalibrationOptions, calibrate_with, errors
from jwarp.calibration.estimate.cv import (
    CVOptions,
    CVSetting,
    calibrate_cv,
    cross_validate,
    default_grid,
    fold_indices,
    parse_cv_grid,
)
from jwarp.calibration.estimate.params import DEFAULT_SIGMA
from jwarp.calibration.files import make_measurement, parse_samples, read_setup


@pytest.fixture(scope="module")
def small_errors(tmp_path_factory):
    """A rigid justin19 campaign whose true DH errors are 1/50 .. 1/170 of the default
    priors (+-0.1 mm, +-0.03 deg against 5 mm, 5 deg): a known prior scale of ~0.01."""
    from jwarp.cli import main

    d = tmp_path_factory.mktemp("cv38")
    with contextlib.redirect_stdout(io.StringIO()):
        assert main(["simulate-campaign", "--samples", "140", "--seed", "2", "--kappa", "0",
                     "--length-error", "0.1", "--angle-error", "0.03",
                     "--out", str(d / "run")]) == 0
    run_dir = d / "run"
    setup = read_setup(str(run_dir / "setup.json"))
    model = jwarp.robot(setup.robot)
    meas = make_measurement(model, setup)
    data = parse_samples((run_dir / "samples.csv").read_text(), model, meas)
    return run_dir, model, meas, data


def test_cv_choice_recovers_the_known_prior_scale_better_than_the_default(small_errors):
    _, model, meas, data = small_errors
    q, y = data.q[:40], data.y[:40]
    base = CalibrationOptions(free="theta,d,r,alpha", warn=False)
    grid = [CVSetting(prior_scale=s) for s in (0.01, 0.1, 1.0)]
    res, cv = calibrate_cv(model, meas, q, y, base, CVOptions(4, grid, workers=1))
    # the truth's scale is ~0.01 of the default priors: CV picks it, the default is 1
    assert cv.chosen.prior_scale == 0.01
    assert cv.errors[0] < cv.errors[2]
    # ... and the chosen fit predicts the 100 held-out rows better than the default's
    default = calibrate_with(model, meas, q, y, base)
    e_cv = errors(res.robot, meas, res.params, data.q[40:], data.y[40:]).mean()
    e_def = errors(default.robot, meas, default.params, data.q[40:], data.y[40:]).mean()
    assert e_cv < 0.95 * e_def
    # the final fit is the chosen setting's fit on all rows, recorded in the provenance
    again = calibrate_with(model, meas, q, y, grid[0].apply(base))
    np.testing.assert_array_equal(res.x, again.x)
    prov = res.provenance["cv"]
    assert prov["chosen"]["prior_scale"] == 0.01 and prov["folds"] == 4
    assert prov["cv_error"] == pytest.approx(cv.errors[0])
    assert [r["label"] for r in prov["table"]] == ["scale=0.01", "scale=0.1", "base"]
    assert res.to_dict()["provenance"]["cv"]["cv_error"] == prov["cv_error"]
    assert "<- chosen" in cv.table(1e3, "mm").splitlines()[2]


def test_folds_in_processes_give_the_same_numbers(small_errors):
    _, model, meas, data = small_errors
    base = CalibrationOptions(free="theta", warn=False)
    grid = [CVSetting(prior_scale=0.1), CVSetting()]
    one = cross_validate(model, meas, data.q[:24], data.y[:24], base, CVOptions(3, grid, 0, 1))
    two = cross_validate(model, meas, data.q[:24], data.y[:24], base, CVOptions(3, grid, 0, 2))
    assert two.workers == 2
    np.testing.assert_array_equal(one.fold_errors, two.fold_errors)
    # every row held out exactly once, folds of near-equal size
    f = fold_indices(24, 3, 0)
    assert sorted(np.bincount(f)) == [8, 8, 8]
    with pytest.raises(ValueError, match="folds"):
        fold_indices(24, 1)
    for bad, name in ((CVOptions(workers=0), "workers"), (CVOptions(folds=1), "folds"),
                      (CVOptions(seed=-1), "seed")):
        with pytest.raises(ValueError, match=name):
            cross_validate(model, meas, data.q[:24], data.y[:24], base, bad)
    with pytest.raises(TypeError, match="settings"):
        CVOptions(settings=[{"prior_scale": 1}]).validate()
    with pytest.raises(ValueError, match="folds"):   # more folds than rows
        cross_validate(model, meas, data.q[:4], data.y[:4], base, CVOptions(folds=5))


def test_setting_scales_free_robot_groups_and_their_patterns_only():
    base = CalibrationOptions(free="theta,d,harmonic,tracker",
                              sigma={"d": 1e-3, "harmonic:torso_*": 5e-3, "tracker": 1.0},
                              orders={"harmonic": 3})
    o = CVSetting(prior_scale=0.5, orders={"harmonic:torso_*": 1}).apply(base)
    assert o.sigma == {"d": 5e-4, "harmonic:torso_*": 2.5e-3, "tracker": 1.0,
                       "theta": 0.5 * DEFAULT_SIGMA["theta"],
                       "harmonic": 0.5 * DEFAULT_SIGMA["harmonic"]}
    assert o.orders == {"harmonic": 3, "harmonic:torso_*": 1}
    assert o.callback is None and o.warn is False
    assert CVSetting().apply(base).sigma == base.sigma      # scale 1: the base unchanged
    with pytest.raises(ValueError, match="prior_scale"):
        CVSetting(prior_scale=0.0).apply(base)


def test_grid_parsing(tmp_path):
    assert [s.prior_scale for s in parse_cv_grid(None)] == [s.prior_scale for s in default_grid()]
    assert len(default_grid()) == 10 and 1.0 in [s.prior_scale for s in default_grid()]
    g = parse_cv_grid(["scale=0.1|1", "prior:harmonic:torso_*=1e-3|2e-2", "order:coupling=1|2"])
    assert len(g) == 8
    assert g[-1].name() == "prior:harmonic:torso_*=0.02 order:coupling=2"
    assert parse_cv_grid(["free=theta,d|theta,d,harmonic"])[1].free == "theta,d,harmonic"
    f = tmp_path / "grid.json"
    f.write_text(json.dumps([{"label": "wide", "prior_scale": 2}, {"sigma": {"d": 1e-4}}]))
    assert [s.name() for s in parse_cv_grid([str(f)])] == ["wide", "prior:d=0.0001"]
    for bad, why in ((["scale=0|1"], "bad value '0'"), (["what=1"], "unknown axis 'what'"),
                     (["scale="], "expected AXIS"), (["order:harmonic=1.5"], "bad value"),
                     (["nofile"], "neither")):
        with pytest.raises(ValueError, match=f"--cv-grid: .*{why}"):
            parse_cv_grid(bad)


def test_cli_cv_prints_the_table_and_records_the_choice(small_errors, capsys, tmp_path):
    run_dir = small_errors[0]
    out = tmp_path / "cal.json"
    argv = ["calibrate", "--setup", run_dir / "setup.json", "--data", run_dir / "samples.csv",
            "--free", "theta", "--calibrate-rows", "0:24", "--quiet"]
    code, text, err = run(capsys, [*argv, "--cv", "3", "--cv-grid", "scale=0.1|1",
                                   "--cv-workers", "1", "--out", out])
    assert code == 0, err
    assert "cross-validation: 3 folds of 24 calibration rows, 2 settings" in text
    prov = json.loads(jwarp.robot(str(out)).notes["calibration"])["cv"]
    assert prov["folds"] == 3 and len(prov["table"]) == 2
    assert prov["chosen"]["label"] in ("scale=0.1", "base")
    assert math.isfinite(prov["cv_error"])
    code, text, _ = run(capsys, [*argv, "--cv", "3", "--cv-grid", "scale=0.1|1",
                                 "--cv-workers", "1", "--json"])
    assert json.loads(text)["cv"]["cv_error"] == pytest.approx(prov["cv_error"])
    one_line_error(capsys, [*argv, "--cv-grid", "scale=1"], "--cv-grid")
    one_line_error(capsys, [*argv, "--cv", "1"], "--cv")
    one_line_error(capsys, [*argv, "--cv", "3", "--cv-grid", "scale=-1"], "--cv-grid")
    one_line_error(capsys, [*argv, "--cv", "3", "--cv-workers", "0"], "--cv-workers")


def test_without_cv_the_result_is_unchanged(small_errors):
    """No --cv: calibrate_with is what it was (no provenance, the same fit)."""
    _, model, meas, data = small_errors
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = calibrate_with(model, meas, data.q[:24], data.y[:24],
                             CalibrationOptions(free="theta"))
    assert res.provenance == {} and "provenance" not in res.to_dict()
