"""Issue 38 item 2: direction-dependent joint errors (the ``backlash`` group): the
direction from the previous pose, the analytic Jacobian against central differences,
``simulate-campaign --unmodeled backlash``, recovery on simulation and the diagnostics'
direction correlation."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

import jwarp
from jwarp.calibration import CalibrationProblem, calibrate, errors
from jwarp.calibration.estimate.backlash import check_directions, motion_directions
from jwarp.calibration.estimate.diagnostics import residual_diagnostics
from jwarp.calibration.estimate.map import problem_options
from jwarp.calibration.estimate.params import (
    DEFAULT_SIGMA,
    KIND_BACKLASH,
    KIND_KAPPA,
    robot_backlash,
    with_backlash,
)
from jwarp.calibration.estimate.result import model_frames
from jwarp.calibration.files import make_measurement
from jwarp.calibration.simulate.campaign import simulate_campaign
from jwarp.calibration.simulate.scenarios import scenario
from jwarp.calibration.simulate.unmodeled import parse_unmodeled


def test_motion_directions_from_the_previous_pose():
    q = np.array([[0.0, 1.0], [0.5, 1.0], [0.5, 0.2], [0.1, 0.2], [0.1, 0.9]])
    d = motion_directions(q)
    np.testing.assert_array_equal(d, [[0, 0], [1, 0], [1, -1], [-1, -1], [-1, 1]])
    with pytest.raises(ValueError, match="directions"):
        check_directions(np.full((5, 2), 0.5), 5, 2)
    with pytest.raises(ValueError, match="directions: expected shape"):
        check_directions(d[:4], 5, 2)


def _campaign(n, seed, unmodeled=None, kappa=None):
    robot = jwarp.robot("justin19")
    setup, sampler, accept = scenario("justin19", "cartesian")
    camp = simulate_campaign(robot, setup, n, seed=seed, sampler=sampler, accept=accept,
                             unmodeled=unmodeled, kappa=kappa)
    return robot, make_measurement(robot, camp.setup), camp


@pytest.mark.parametrize("elastic", [False, True])
def test_backlash_jacobian_matches_central_differences(elastic):
    kappa = {"kappa_theta": (3e-5, 9e-5)} if elastic else None
    robot, meas, camp = _campaign(30, 3, "backlash", kappa)
    free = "theta,backlash,harmonic,coupling" + (",kappa_theta" if elastic else "")
    prob = CalibrationProblem(robot, meas, camp.samples.q, camp.samples.y,
                              problem_options(free=free))
    sp = prob.space
    bl = np.nonzero(sp.kind == KIND_BACKLASH)[0]
    assert len(bl) >= 17 and sp.names[bl[0]] == "torso_pan.backlash"
    assert sp.sigma[bl[0]] == DEFAULT_SIGMA["backlash"]
    rng = np.random.default_rng(0)
    x = prob.initial_x() + rng.normal(0, 1e-3, sp.size) * (sp.kind != 2)
    x[sp.kind == KIND_KAPPA] = 5e-5
    J = prob.jacobian(x)
    h = 1e-6
    for i in list(bl[::4]) + [int(bl[-1])]:
        e = np.zeros_like(x)
        e[i] = h
        fd = (prob.residuals(x + e) - prob.residuals(x - e)) / (2 * h)
        assert np.abs(fd).max() > 0
        np.testing.assert_allclose(J[:, i], fd, atol=1e-6 * np.abs(fd).max(),
                                   err_msg=sp.names[i])


def test_simulated_backlash_recorded_and_applied_with_the_directions():
    robot, meas, camp = _campaign(40, 1, "backlash:min=1e-3,max=3e-3")
    b = robot_backlash(camp.true_robot)
    moved = b != 0
    assert moved.sum() == robot.n_dof and np.all((b[moved] >= 1e-3) & (b[moved] <= 3e-3))
    assert json.loads(camp.true_robot.notes["backlash"])["torso_pan"] == b[0]
    q = camp.samples.q
    d = motion_directions(q)
    # the truth's frames: the links at q + b s (the nominal directions of the order)
    with_dir = model_frames(camp.true_robot, q, directions=d)
    plain = model_frames(camp.true_robot, q)
    shifted = model_frames(camp.true_robot.copy(notes={}), q + d * b)
    np.testing.assert_allclose(with_dir, shifted, atol=1e-12)
    assert np.abs(with_dir - plain).max() > 1e-4
    with pytest.raises(ValueError, match="backlash: min > max"):
        parse_unmodeled("backlash:min=3e-3,max=1e-3")


def test_group_recovers_backlash_and_reaches_the_noise_only_error():
    """Acceptance (issue 38): with backlash of 1-3 mrad the standard groups' test error is
    well above the noise-only campaign's; with the group within 10 % of it, and the
    torso's b recovered."""
    N, T = 120, 200
    free = "theta,d,r,alpha,kappa_theta,kappa_alpha"
    out = {}
    fits = {}
    for unm in (None, "backlash"):
        robot, meas, camp = _campaign(T, 3, unm)
        q, y = camp.samples.q, camp.samples.y
        d = motion_directions(q)
        for f in (free, free + ",backlash"):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                res = calibrate(robot, meas, q[:N], y[:N], free=f, directions=d[:N])
            out[unm, f] = errors(res.robot, meas, res.params, q[N:], y[N:],
                                 directions=d[N:]).mean()
            fits[unm, f] = (res, camp, meas, q[:N], y[:N], d[:N])
    ref = out[None, free]
    assert out["backlash", free] > 1.5 * ref
    assert out["backlash", free + ",backlash"] < 1.10 * ref
    res, camp, meas, q, y, d = fits["backlash", free + ",backlash"]
    bt, bf = robot_backlash(camp.true_robot), robot_backlash(res.robot)
    np.testing.assert_allclose(bf[:3], bt[:3], atol=0.7e-3)      # the torso, 1-3 mrad
    # over the arms and torso (the head's two joints carry no marker): within a third
    assert np.mean(np.abs(bf[:17] - bt[:17])) < np.mean(bt[:17]) / 3
    # diagnostics: before, the torso's per-sample errors follow the direction of motion
    res0 = fits["backlash", free][0]
    before = residual_diagnostics(res0.robot, meas, res0.params, q, y, directions=d)
    after = residual_diagnostics(res.robot, meas, res.params, q, y, directions=d)
    top0 = max(abs(j.direction_corr) for j in before.joints)
    top1 = max(abs(j.direction_corr) for j in after.joints)
    assert top0 > 0.3 and top1 < 0.5 * top0, (top0, top1)
    assert "direction_corr" in before.to_dict()["joints"][0]


def test_without_backlash_the_directions_change_nothing():
    robot, meas, camp = _campaign(30, 2)
    q, y = camp.samples.q, camp.samples.y
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        a = calibrate(robot, meas, q, y, free="theta", max_nfev=5)
        b = calibrate(robot, meas, q, y, free="theta", max_nfev=5,
                      directions=motion_directions(q)[::-1].copy())
    np.testing.assert_array_equal(a.x, b.x)
    assert "backlash" not in a.robot.notes
    assert with_backlash(robot, np.zeros(robot.n_dof)).notes.get("backlash") is None


def test_cli_simulates_and_calibrates_backlash(tmp_path, capsys):
    from cli_helpers import run  # tests/cli_helpers.py

    out = tmp_path / "run"
    code, _, err = run(capsys, ["simulate-campaign", "--samples", "80", "--seed", "1",
                                "--kappa", "0", "--unmodeled", "backlash:min=2e-3,max=3e-3",
                                "--out", out])
    assert code == 0, err
    truth = jwarp.robot(str(out / "truth.json"))
    b = robot_backlash(truth)
    assert np.all((b >= 2e-3) & (b <= 3e-3))
    argv = ["calibrate", "--setup", out / "setup.json", "--data", out / "samples.csv",
            "--calibrate-rows", "0:60", "--test-rows", "60:80", "--quiet", "--json",
            "--diagnostics"]
    code, text, err = run(capsys, [*argv, "--free", "theta,d,r,alpha"])
    assert code == 0, err
    without = json.loads(text)
    code, text, err = run(capsys, [*argv, "--free", "theta,d,r,alpha,backlash",
                                   "--params-out", tmp_path / "p.json"])
    assert code == 0, err
    with_bl = json.loads(text)
    assert with_bl["after"]["test"]["mean"] < 0.8 * without["after"]["test"]["mean"]
    params = json.loads((tmp_path / "p.json").read_text())["parameters"]
    assert sum(p["group"] == "backlash" for p in params) == 17
    corr = [j["direction_corr"] for j in without["diagnostics"]["joints"]]
    assert max(abs(c) for c in corr if c is not None) > 0.3


def test_direction_columns_of_the_samples_file(tmp_path, capsys):
    """``dir_<joint>`` columns give the directions (here the reverse of the row order's):
    the fitted backlash changes sign; a bad value names line and column."""
    import csv

    from cli_helpers import run  # tests/cli_helpers.py

    from jwarp.calibration.files import parse_samples, read_setup

    out = tmp_path / "run"
    code, _, err = run(capsys, ["simulate-campaign", "--samples", "80", "--seed", "1",
                                "--kappa", "0", "--unmodeled", "backlash:min=2e-3,max=3e-3",
                                "--out", out])
    assert code == 0, err
    rows = list(csv.reader((out / "samples.csv").read_text().splitlines()))
    robot = jwarp.robot("justin19")
    setup = read_setup(str(out / "setup.json"))
    meas = make_measurement(robot, setup)
    data = parse_samples((out / "samples.csv").read_text(), robot, meas)
    assert data.directions is None
    rev = -motion_directions(data.q)
    names = [f"dir_{j}" for j in robot.joint_names]
    text = "\n".join([",".join(rows[0] + names)] + [
        ",".join(r + [f"{v:g}" for v in rev[k]]) for k, r in enumerate(rows[1:])]) + "\n"
    (tmp_path / "rev.csv").write_text(text)
    back = parse_samples(text, robot, meas)
    np.testing.assert_array_equal(back.directions, rev)
    np.testing.assert_array_equal(back.y, data.y)
    code, _, err = run(capsys, ["calibrate", "--setup", out / "setup.json", "--data",
                                tmp_path / "rev.csv", "--free", "theta,d,r,alpha,backlash",
                                "--quiet", "--json", "--params-out", tmp_path / "p.json"])
    assert code == 0, err
    params = json.loads((tmp_path / "p.json").read_text())["parameters"]
    b = {p["name"].split(".")[0]: p["value"] for p in params if p["group"] == "backlash"}
    bt = robot_backlash(jwarp.robot(str(out / "truth.json")))
    for j in ("torso_pan", "right_1", "left_1"):
        assert b[j] == pytest.approx(-bt[robot.joint_names.index(j)], abs=1e-3), (j, b[j])
    lines = text.splitlines()
    lines[2] = lines[2].rsplit(",", 1)[0] + ",2"          # the last joint's column
    with pytest.raises(ValueError, match=f"line 3, column '{names[-1]}': expected"):
        parse_samples("\n".join(lines) + "\n", robot, meas)


def test_torso_backlash_shared_two_hand_residual_removed():
    """Acceptance (issue 38): backlash of 2-3 mrad on the torso joints only (the case of
    Agile Justin's data): both hands err together (cross-hand correlation of the residuals
    in base coordinates), the test error is ~2x the noise-only campaign's; with the group
    the test error is within 10 % of it and the correlation back at the noise-only one's."""
    from jwarp.calibration.estimate.params import perturb_robot

    robot = jwarp.robot("justin19")
    setup, sampler, accept = scenario("justin19", "cartesian")
    truth = perturb_robot(robot, np.random.default_rng(5), groups=("theta", "d", "r", "alpha"),
                          length_error=1e-3, angle_error=np.radians(0.3), kappa=(3e-5, 9e-5),
                          kappa_groups=("kappa_theta", "kappa_alpha"))
    b = np.zeros(robot.n_dof)
    b[:3] = [3e-3, 2e-3, 3e-3]                     # torso_pan, torso_tilt_1, torso_tilt_2
    free = "theta,d,r,alpha,kappa_theta,kappa_alpha"
    test, corr = {}, {}
    for name, tr in (("noise", truth), ("backlash", with_backlash(truth, b))):
        camp = simulate_campaign(robot, setup, 300, seed=3, sampler=sampler, accept=accept,
                                 true_robot=tr)
        meas = make_measurement(robot, camp.setup)
        q, y = camp.samples.q, camp.samples.y
        d = motion_directions(q)
        for f in (free, free + ",backlash"):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                res = calibrate(robot, meas, q[:200], y[:200], free=f, directions=d[:200])
            test[name, f] = errors(res.robot, meas, res.params, q[200:], y[200:],
                                   directions=d[200:]).mean()
            dg = residual_diagnostics(res.robot, meas, res.params, q[:200], y[:200],
                                      directions=d[:200])
            (_, _, r), = dg.correlations                   # right ~ left, per coordinate
            corr[name, f] = float(np.abs(r).max())
            if name == "backlash" and f == free:
                assert dg.joints[0].frame.startswith("torso_")
                assert dg.joints[0].direction_corr > 0.5
    ref = test["noise", free]
    assert test["backlash", free] > 1.5 * ref
    assert test["backlash", free + ",backlash"] < 1.10 * ref
    assert corr["backlash", free] > 0.2
    assert corr["backlash", free + ",backlash"] < corr["noise", free] + 0.05
