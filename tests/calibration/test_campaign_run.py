"""``calibrate_campaign``: the library function behind ``jwarp calibrate`` (issue 40)."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

import jwarp
from jwarp.calibration import (
    CampaignCalibration,
    CampaignOptions,
    calibrate_campaign,
    load_campaign,
)
from jwarp.calibration.campaign_run import PROVENANCE_NOTE
from jwarp.calibration.simulate.campaign import simulate_campaign
from jwarp.calibration.simulate.scenarios import scenario
from tests.cli_helpers import run


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    d = tmp_path_factory.mktemp("campaign_run")
    setup, sampler, accept = scenario("justin19", "cartesian")
    camp = simulate_campaign(jwarp.robot("justin19"), setup, 40, seed=5, sampler=sampler,
                             accept=accept)
    return d, camp.write(d / "camp")


def _without_date(robot_doc: dict) -> dict:
    prov = json.loads(robot_doc["notes"][PROVENANCE_NOTE])
    prov.pop("date")
    return dict(robot_doc, notes=dict(robot_doc["notes"], **{PROVENANCE_NOTE: prov}))


def test_same_parameters_as_the_cli(campaign, capsys, tmp_path):
    d, paths = campaign
    out, params = tmp_path / "cal.json", tmp_path / "params.json"
    code, stdout, err = run(capsys, [
        "calibrate", "--setup", paths["setup.json"], "--data", paths["samples.csv"],
        "--free", "theta,d,kappa_theta", "--test-rows", "30:40", "--prior", "theta=2e-3",
        "--max-nfev", "6", "--quiet", "--json", "--out", out, "--params-out", params])
    assert code == 0, err
    cli = json.loads(stdout)
    doc = json.loads(params.read_text())
    c = load_campaign(paths["setup.json"], paths["samples.csv"])
    lib = calibrate_campaign(c, CampaignOptions(
        free="theta,d,kappa_theta", test_rows="30:40", sigma={"theta": 2e-3}, max_nfev=6))
    assert isinstance(lib, CampaignCalibration)
    # bit for bit: every parameter value and posterior std, the errors, the free groups
    assert [p["value"] for p in doc["parameters"]] == [float(v) for v in lib.result.x]
    assert [p["name"] for p in doc["parameters"]] == list(lib.result.names)
    assert doc["measurement_params"] == dict(zip(lib.result.param_names,
                                                 map(float, lib.result.params)))
    assert cli["before"] == lib.before and cli["after"] == lib.after
    assert cli["free"] == lib.free and cli["test_range"] == lib.test_range
    # the same findings; the library names its options by field (test_rows: ...)
    assert cli["warnings"] == [w.replace("test_rows: ", "--test-rows: ", 1)
                               for w in c.warnings + lib.warnings]
    assert cli["calibrated_name"] == lib.robot.name == "justin19-calibrated"
    assert _without_date(json.loads(out.read_text())) == _without_date(lib.robot.to_dict())
    np.testing.assert_array_equal(lib.train_rows, np.arange(30))
    np.testing.assert_array_equal(lib.test_rows, np.arange(30, 40))
    assert lib.unit == "mm" and lib.scale == 1000.0 and lib.overlap == 0


def test_errors_name_the_option(campaign):
    _, paths = campaign
    c = load_campaign(paths["setup.json"], paths["samples.csv"])
    with pytest.raises(ValueError, match="^test_rows: rows 5:10 are also calibration rows "
                                         r"\(calibrate_rows 0:10\).*allow_overlap"):
        calibrate_campaign(c, CampaignOptions(calibrate_rows="0:10", test_rows="5:15"))
    with pytest.raises(ValueError, match="^--test-rows: .*--allow-overlap"):
        calibrate_campaign(c, CampaignOptions(calibrate_rows="0:10", test_rows="5:15"),
                           names={"test_rows": "--test-rows", "allow_overlap": "--allow-overlap"})
    with pytest.raises(ValueError, match=r"^cv_folds: expected an integer in \[2, 40\]"):
        calibrate_campaign(c, CampaignOptions(cv_folds=1))
    with pytest.raises(ValueError, match="^cv_grid: only with cv_folds"):
        calibrate_campaign(c, CampaignOptions(cv_grid=["scale=1|2"]))
    with pytest.raises(ValueError, match="^virtual_noise: expected a finite number >= 0"):
        calibrate_campaign(c, CampaignOptions(virtual_noise=-1.0))
    with pytest.raises(ValueError, match="^calibrate_rows: .*give more rows"):
        calibrate_campaign(c, CampaignOptions(free="theta,d,r,alpha", calibrate_rows="0:3"))
    with pytest.raises(TypeError, match="^options: expected CampaignOptions"):
        calibrate_campaign(c, {"free": "theta"})  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="^name: empty robot name"):
        calibrate_campaign(c, CampaignOptions(name=" "))
    with pytest.raises(ValueError, match="^robot: not given"):
        bare = paths["setup.json"].replace("setup.json", "bare.json")
        with open(paths["setup.json"]) as fh:
            doc = json.load(fh)
        doc.pop("robot")
        with open(bare, "w") as fh:
            json.dump(doc, fh)
        load_campaign(bare, paths["samples.csv"])


def test_problem_takes_options_and_the_old_keywords_warn(campaign):
    """``CalibrationProblem(..., options)`` (issue 40): the former keywords give the same
    problem bit for bit, with a DeprecationWarning, as ``problem_options`` of them."""
    from jwarp.calibration import CalibrationOptions, CalibrationProblem
    from jwarp.calibration.estimate.map import problem_options

    _, paths = campaign
    c = load_campaign(paths["setup.json"], paths["samples.csv"])
    q, y = c.samples.q[:20], c.samples.y[:20]
    kw = dict(free="theta,d,kappa_theta,tracker", sigma={"theta": 2e-3}, max_iter=50,
              noise_sigma=2e-3)
    with pytest.warns(DeprecationWarning, match="CalibrationProblem: the keywords .*free"):
        old = CalibrationProblem(c.robot, c.measurement, q, y, **kw)
    new = CalibrationProblem(c.robot, c.measurement, q, y, problem_options(**kw))
    same = CalibrationProblem(c.robot, c.measurement, q, y, CalibrationOptions(
        free="theta,d,kappa_theta,tracker", free_poses=False, bound_kappa=False,
        sigma={"theta": 2e-3}, equilibrium_iterations=50, noise_sigma=2e-3))
    x = old.initial_x()
    for p in (new, same):
        assert p.space.names == old.space.names and p.max_iter == 50
        np.testing.assert_array_equal(p.initial_x(), x)
        np.testing.assert_array_equal(p.residuals(x), old.residuals(x))
        np.testing.assert_array_equal(p.jacobian(x), old.jacobian(x))
    # free_poses (the options' default) adds the pose and marker groups, as calibrate() does
    posed = CalibrationProblem(c.robot, c.measurement, q, y, CalibrationOptions(free="theta"))
    assert "tracker" in posed.space.free_groups and "markers" in posed.space.free_groups
    with pytest.raises(TypeError, match="got options and the keywords sigma"):
        CalibrationProblem(c.robot, c.measurement, q, y, CalibrationOptions(free="theta"),
                           sigma={})
    with pytest.raises(TypeError, match="unexpected keyword 'n_starts'"):
        CalibrationProblem(c.robot, c.measurement, q, y, free="theta", n_starts=2)
    with pytest.raises(TypeError, match="missing options"):
        CalibrationProblem(c.robot, c.measurement, q, y)
    with pytest.raises(TypeError, match="^options: expected CalibrationOptions"):
        CalibrationProblem(c.robot, c.measurement, q, y, {"free": "theta"})


def test_cv_grid_as_items_or_settings(campaign):
    """``cv_grid`` takes the CLI's items or CVSetting objects: the same choice and fit."""
    from jwarp.calibration import CVSetting

    _, paths = campaign
    c = load_campaign(paths["setup.json"], paths["samples.csv"])
    base = dict(free="theta,d", calibrate_rows="0:30", test_rows="30:40", cv_folds=3,
                cv_workers=1, max_nfev=3)
    a = calibrate_campaign(c, CampaignOptions(cv_grid=["scale=0.1|1"], **base))
    b = calibrate_campaign(c, CampaignOptions(
        cv_grid=[CVSetting(prior_scale=0.1), CVSetting(prior_scale=1.0)], **base))
    assert a.cv is not None and b.cv is not None and a.cv.best == b.cv.best
    np.testing.assert_array_equal(a.cv.errors, b.cv.errors)
    np.testing.assert_array_equal(a.result.x, b.result.x)
    assert json.loads(a.robot.notes[PROVENANCE_NOTE])["cv"]["folds"] == 3


def test_load_campaign_takes_a_robot_model(campaign):
    _, paths = campaign
    c = load_campaign(paths["setup.json"], paths["samples.csv"], robot=jwarp.robot("justin19"))
    assert c.robot_source is None and c.robot.name == "justin19" and c.warnings == []
    run = calibrate_campaign(c, CampaignOptions(free="theta", max_nfev=2, name="mine"))
    prov = json.loads(run.robot.notes[PROVENANCE_NOTE])
    assert run.robot.name == "mine" and prov["nominal_robot"] == "justin19"
    assert prov["data_sha256"] == c.data_sha256 and prov["test_rows"] is None


def test_diagnostics_from_python_as_the_cli(campaign, capsys):
    d, paths = campaign
    code, stdout, err = run(capsys, [
        "calibrate", "--setup", paths["setup.json"], "--data", paths["samples.csv"],
        "--free", "theta,d", "--test-rows", "30:40", "--max-nfev", "4", "--quiet", "--json",
        "--diagnostics"])
    assert code == 0, err
    cli = json.loads(stdout)["diagnostics"]
    c = load_campaign(paths["setup.json"], paths["samples.csv"])
    lib = calibrate_campaign(c, CampaignOptions(free="theta,d", test_rows="30:40",
                                                max_nfev=4))
    assert lib.measurement is c.measurement
    diag = lib.diagnostics()
    # the calibration rows (30 of them), in the report unit as the CLI prints them
    assert json.loads(json.dumps(diag.to_dict(lib.scale))) == cli
    with pytest.raises(ValueError, match="bins"):
        lib.diagnostics(bins=31)
    hand = dataclasses.replace(lib, measurement=None)
    with pytest.raises(ValueError, match="measurement: not recorded"):
        hand.diagnostics()
