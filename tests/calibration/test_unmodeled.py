"""Systematic error in simulated campaigns: effects in the truth outside the calibration
model (``simulate_campaign(unmodeled=...)``, ``jwarp simulate-campaign --unmodeled``),
their spec parsing, the true robot file carrying them, and the calibration's response
(noise level without them, a systematic residual with them)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from cli_helpers import one_line_error, run
from devices import requires_cpu

import jwarp
from jwarp.calibration import calibrate, error_stats
from jwarp.calibration.estimate.result import model_frames, predict
from jwarp.calibration.files import make_measurement
from jwarp.calibration.simulate.campaign import (
    justin_tracker_setup,
    read_campaign,
    simulate_campaign,
)
from jwarp.calibration.simulate.unmodeled import EFFECTS, parse_unmodeled
from jwarp.model import RobotModel


def test_spec_parsing_forms_and_defaults():
    u = parse_unmodeled("harmonic:amp=1e-3,k=3,kappa_nonlinear,kappa_beta:max=5e-5,min=0")
    assert u.effects == {"harmonic": {"amp": 1e-3, "k": 3.0}, "kappa_nonlinear": {},
                         "kappa_beta": {"max": 5e-5, "min": 0.0}}
    assert u.get("kappa_nonlinear", "rel") == EFFECTS["kappa_nonlinear"]["rel"]
    # 'all' is the effects of issue 16; 'coupling' (issue 29) and 'backlash' (issue 38)
    # only by name, so that campaigns with 'all' keep their data
    assert set(parse_unmodeled("all").effects) == set(EFFECTS) - {"coupling", "backlash"}
    assert parse_unmodeled("coupling:amp=5e-3").get("coupling", "amp") == 5e-3
    assert not parse_unmodeled("none") and not parse_unmodeled(None) and not parse_unmodeled("")
    assert parse_unmodeled(["harmonic", "kappa_beta"]).effects == {"harmonic": {}, "kappa_beta": {}}
    assert parse_unmodeled({"harmonic": {"amp": 2e-4}}).get("harmonic", "amp") == 2e-4


@pytest.mark.parametrize("spec, match", [
    ("wobble", "unknown effect 'wobble'"),
    ("harmonic:size=1", "harmonic: unknown option 'size'"),
    ("harmonic:amp=x", "harmonic:amp: expected a number"),
    ("harmonic:amp=-1", "harmonic:amp must be a finite number >= 0"),
    ("harmonic:k=1.5", "harmonic:k must be an integer"),
    ("amp=1,harmonic", "option 'amp=1' before any effect"),
    ("harmonic,,kappa_beta", "empty item"),
    ("harmonic,harmonic", "given twice"),
    ("kappa_beta:min=5e-5,max=1e-5", "kappa_beta: min > max"),
    ("harmonic:amp", "expected key=value"),
])
def test_spec_errors_name_the_option(spec, match):
    with pytest.raises(ValueError, match=match) as e:
        parse_unmodeled(spec, option="--unmodeled")
    assert str(e.value).startswith("--unmodeled: ")
    with pytest.raises(TypeError, match="unmodeled: expected a spec string"):
        parse_unmodeled(3.0)


@requires_cpu
def test_truth_carries_the_effects_and_reproduces_the_data(tmp_path):
    robot = jwarp.robot("justin19")
    setup = justin_tracker_setup(noise=1e-4)
    plain = simulate_campaign(robot, setup, 40, seed=3)
    camp = simulate_campaign(robot, setup, 40, seed=3, unmodeled="all")
    t = camp.true_robot
    # the other draws do not change: same geometric truth, same configurations
    np.testing.assert_array_equal(t.dh_table, plain.true_robot.dh_table)
    np.testing.assert_array_equal(camp.samples.q, plain.samples.q)
    np.testing.assert_array_equal(t.kappa[:, [0, 2]], plain.true_robot.kappa[:, [0, 2]])
    assert t.harmonic.shape == (robot.n_dof, 2, 2)
    assert 0 < np.abs(t.harmonic).max() <= EFFECTS["harmonic"]["amp"]
    assert np.all(t.kappa[t.is_dh, 1] >= 1e-5) and np.all(t.kappa[t.is_dh, 1] <= 3e-5)
    assert not np.any(plain.true_robot.kappa[:, 1])
    # kappa_nonlinear: +-rel of kappa_theta at each joint's reference torque; none on the
    # vertical torso pan axis (no torque)
    k = t.kappa_nonlinear
    assert np.any(k > 0) and np.any(k < 0) and k[robot.frame_index("torso_1")] == 0
    # the written truth reproduces the data to the noise
    camp.write(tmp_path / "c")
    back = read_campaign(tmp_path / "c")
    np.testing.assert_array_equal(back.truth.harmonic, t.harmonic)
    np.testing.assert_array_equal(back.truth.kappa_nonlinear, t.kappa_nonlinear)
    meas = make_measurement(back.truth, camp.true_setup)
    y = predict(back.truth, meas, camp.true_params, back.samples.q)
    res = (y - back.samples.y).reshape(-1)
    assert np.std(res) < 1.5e-4
    # ... and the effects are of the documented size: without them the data move by mm
    y0 = predict(plain.true_robot, meas, camp.true_params, back.samples.q)
    assert 5e-4 < np.abs(y0 - y).mean() < 2e-2


@requires_cpu
def test_default_truth_is_sized_like_agile_justin():
    """simulate_campaign's default errors: nominal model ~20 mm off at the TCPs (paper: 21
    mm mean, 63 mm max) in the robot's base frame; the former +-5 mm / +-5 deg gave >100."""
    robot = jwarp.robot("justin19")
    camp = simulate_campaign(robot, justin_tracker_setup(), 300, seed=0)
    q = camp.samples.q
    tcp = [robot.frame_index("right_tcp"), robot.frame_index("left_tcp")]
    d = np.linalg.norm(model_frames(camp.true_robot, q)[:, tcp, :3, 3]
                       - model_frames(robot, q)[:, tcp, :3, 3], axis=-1) * 1e3
    assert 10 < d.mean() < 35 and 35 < d.max() < 120


@requires_cpu
def test_standard_groups_reach_noise_without_and_not_with_unmodeled_effects():
    robot = jwarp.robot("justin19")
    setup = justin_tracker_setup(noise=1e-4)
    free = "theta,kappa_theta,kappa_alpha,tracker,markers"   # the truth's groups
    mean = {}
    for spec in (None, "all"):
        camp = simulate_campaign(robot, setup, 100, seed=2, unmodeled=spec, dh_groups=("theta",))
        meas = make_measurement(robot, camp.setup)
        res = calibrate(robot, meas, camp.samples.q, camp.samples.y, free=free, warn=False)
        assert res.status > 0, res.message          # converged, not cut by max_nfev
        mean[spec] = error_stats(res.errors)["mean"]
    floor = 1e-4 * math.sqrt(2) * math.gamma(2) / math.gamma(1.5)     # 3-D noise: 1.6 sigma
    assert mean[None] < 1.3 * floor
    assert mean["all"] > 3 * floor


def test_cli_unmodeled_errors_name_the_option(capsys, tmp_path):
    line = one_line_error(capsys, ["simulate-campaign", "--unmodeled", "harmonic:amp=x",
                                   "--out", tmp_path / "c"], "--unmodeled")
    assert "expected a number" in line
    one_line_error(capsys, ["simulate-campaign", "--unmodeled", "wobble", "--out",
                            tmp_path / "c"], "--unmodeled")
    assert not (tmp_path / "c").exists()


@requires_cpu
def test_cli_writes_the_unmodeled_truth(capsys, tmp_path):
    code, out, err = run(capsys, ["simulate-campaign", "--samples", 20, "--seed", 1,
                                  "--unmodeled", "harmonic:amp=1e-3,k=1,kappa_nonlinear",
                                  "--out", tmp_path / "c", "--json"])
    assert code == 0, err
    truth = RobotModel.load(tmp_path / "c" / "truth.json")
    assert truth.harmonic.shape == (19, 1, 2) and np.abs(truth.harmonic).max() <= 1e-3
    assert np.any(truth.kappa_nonlinear) and not np.any(truth.kappa[:, 1])
