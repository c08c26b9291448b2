"""Calibration data files (setup JSON, samples CSV), simulated campaigns, the calibrate CLI."""

import json
import math
import os

import numpy as np
import pytest

import jwarp
from jwarp.calibration.files import (
    Samples,
    make_measurement,
    parse_rows,
    parse_samples,
    read_samples,
    read_setup,
    setup_from_dict,
    write_samples,
    write_setup,
)
from jwarp.calibration.simulate.campaign import (
    justin_tracker_setup,
    rough_setup,
    simulate_campaign,
    uniform_configurations,
)
from jwarp.cli import main


@pytest.fixture(scope="module")
def justin():
    return jwarp.robot("justin19")


@pytest.fixture(scope="module")
def meas(justin):
    return make_measurement(justin, justin_tracker_setup())


def _csv(robot, meas, rows):
    head = ",".join([j.name for j in robot.joints] + meas.obs_names)
    return head + "\n" + "\n".join(",".join(str(v) for v in r) for r in rows) + "\n"


def test_setup_round_trip(tmp_path):
    s = justin_tracker_setup()
    write_setup(tmp_path / "setup.json", s)
    doc = json.loads((tmp_path / "setup.json").read_text())
    assert doc["schema"] == "jwarp.calibration_setup" and doc["plugin"] == "cartesian"
    back = read_setup(tmp_path / "setup.json")
    assert back.plugin == "cartesian" and back.robot == "justin19"
    assert back.section["markers"] == s.section["markers"]
    assert oct(os.stat(tmp_path / "setup.json").st_mode & 0o777) != "0o600"


@pytest.mark.parametrize("doc, match", [
    ([], "expected a JSON object"),
    ({"markers": []}, "plugin: missing"),
    ({"plugin": "cartesian", "schema": "other"}, "schema: expected"),
    ({"plugin": "cartesian", "version": 7}, "version: 7 not supported"),
    ({"plugin": "cartesian", "robot": 3}, "robot: expected a robot name"),
])
def test_setup_errors(doc, match):
    with pytest.raises(ValueError, match=match):
        setup_from_dict(doc)


def test_malformed_setup_json_names_file_and_line(tmp_path):
    p = tmp_path / "bad.json"
    p.write_text('{"plugin": "cartesian",\n  "markers": [,]}')
    with pytest.raises(ValueError, match=r"bad\.json: malformed JSON at line 2"):
        read_setup(p)


def test_unknown_plugin_and_marker_frame(justin):
    s = justin_tracker_setup()
    s.plugin = "laser"
    with pytest.raises(ValueError, match="unknown measurement 'laser'"):
        make_measurement(justin, s)
    s = justin_tracker_setup()
    s.section["markers"][0]["frame"] = "right_hand"
    with pytest.raises(ValueError, match="right_hand"):
        make_measurement(justin, s)


def test_samples_round_trip_exact(tmp_path, justin, meas):
    rng = np.random.default_rng(0)
    q = uniform_configurations(justin, rng, 7)
    y = rng.normal(size=(7, meas.n_obs))
    write_samples(tmp_path / "s.csv", justin, meas, Samples(q, y))
    back = read_samples(tmp_path / "s.csv", justin, meas)
    np.testing.assert_array_equal(back.q, q)
    np.testing.assert_array_equal(back.y, y)
    assert list(back.lines) == list(range(2, 9))


@pytest.mark.filterwarnings("ignore::jwarp.calibration.files.DataWarning")  # values 0, 1, 2, ...: far outside the limits, on purpose
def test_samples_column_order_is_free(justin, meas):
    cols = [j.name for j in justin.joints] + meas.obs_names
    vals = list(np.arange(len(cols), dtype=float))
    perm = np.random.default_rng(1).permutation(len(cols))
    text = ",".join(cols[k] for k in perm) + "\n" + ",".join(str(vals[k]) for k in perm) + "\n"
    s = parse_samples(text, justin, meas)
    np.testing.assert_array_equal(s.q[0], vals[:justin.n_dof])
    np.testing.assert_array_equal(s.y[0], vals[justin.n_dof:])


def test_samples_reject_bad_rows_with_line_numbers(justin, meas):
    n = justin.n_dof + meas.n_obs
    good = [0.1] * n
    with pytest.raises(ValueError, match=r"line 3, column 'right_y'.*NaN"):
        bad = list(good)
        bad[justin.n_dof + 1] = float("nan")
        parse_samples(_csv(justin, meas, [good, bad]), justin, meas)
    with pytest.raises(ValueError, match=rf"line 2: {n - 1} fields"):
        parse_samples(_csv(justin, meas, [good[:-1]]), justin, meas)
    with pytest.raises(ValueError, match="line 2, column 'torso_pan': not a number"):
        parse_samples(_csv(justin, meas, [["x"] + good[1:]]), justin, meas)
    with pytest.raises(ValueError, match=r"missing column\(s\) \['left_z'\]"):
        head = ",".join([j.name for j in justin.joints] + meas.obs_names[:-1])
        parse_samples(head + "\n" + ",".join(["0"] * (n - 1)), justin, meas)
    with pytest.raises(ValueError, match=r"unknown column\(s\) \['extra'\]"):
        head = ",".join([j.name for j in justin.joints] + meas.obs_names + ["extra"])
        parse_samples(head + "\n" + ",".join(["0"] * (n + 1)), justin, meas)
    with pytest.raises(ValueError, match="no sample rows"):
        parse_samples(_csv(justin, meas, []), justin, meas)
    with pytest.raises(ValueError, match="empty file"):
        parse_samples("", justin, meas)


def test_parse_rows():
    assert parse_rows("0:300", 500) == slice(0, 300)
    assert parse_rows("300:", 500) == slice(300, 500)
    assert parse_rows(None, 10) == slice(0, 10)
    for bad in ("0:600", "5:5", "a:b", "1:2:3"):
        with pytest.raises(ValueError, match="--rows"):
            parse_rows(bad, 500, "--rows")


def test_uniform_configurations_respect_linear_limits(justin):
    q = uniform_configurations(justin, np.random.default_rng(2), 500)
    lim = justin.joint_limits
    assert np.all(q >= lim[:, 0]) and np.all(q <= lim[:, 1])
    s = q[:, 1] + q[:, 2]
    assert np.all(s >= 0) and np.all(s <= 2.356 + 1e-12)


def test_simulated_campaign_is_the_true_model_plus_noise(justin):
    setup = justin_tracker_setup()
    c = simulate_campaign(justin, setup, 20, seed=3, noise=0.0, rough_position=0.0, rough_rotation=0.0,
                          rough_marker=0.0)
    # independent check: true robot's elastic frames -> markers in tracker coordinates
    truth = c.true_robot
    fr = jwarp.fk_elastic(truth, c.samples.q, truth.kappa, max_iter=100, tol=1e-13,
                          device="cpu", dtype=np.float64).frames
    tr = setup.section["tracker"]
    from scipy.spatial.transform import Rotation
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(tr["rotvec"]).as_matrix()
    T[:3, 3] = tr["position"]
    Tinv = np.linalg.inv(T)
    for k, mk in enumerate(setup.section["markers"]):
        f = justin.frame_index(mk["frame"])
        x = fr[:, f] @ np.append(mk["position"], 1.0)
        np.testing.assert_allclose((x @ Tinv.T)[:, :3], c.samples.y[:, 3 * k:3 * k + 3], atol=1e-9)
    # the truth differs from nominal by at most 5 mm / 5 deg in d, r, theta, alpha
    diff = truth.dh_table - justin.dh_table
    assert np.abs(diff[:, [0, 2]]).max() <= 0.005 and np.abs(diff[:, [1, 3]]).max() <= math.radians(5)
    assert np.abs(diff).max() > 0


def test_rough_setup_moves_the_tracker_by_the_asked_amount():
    s = justin_tracker_setup()
    r = rough_setup(s, np.random.default_rng(0), rough_position=0.2, rough_rotation=math.radians(20))
    d = np.subtract(r.section["tracker"]["position"], s.section["tracker"]["position"])
    assert np.linalg.norm(d) == pytest.approx(0.2)
    from scipy.spatial.transform import Rotation
    a = Rotation.from_rotvec(r.section["tracker"]["rotvec"]) * Rotation.from_rotvec(
        s.section["tracker"]["rotvec"]).inv()
    assert a.magnitude() == pytest.approx(math.radians(20))


def test_cli_simulate_and_calibrate(tmp_path, capsys):
    setup = tmp_path / "tracker.json"
    write_setup(setup, justin_tracker_setup(noise=0.0005))
    run = tmp_path / "run"
    assert main(["simulate-campaign", "--setup", str(setup), "--samples", "120", "--seed", "4",
                 "--kappa", "0", "--angle-error", "1", "--length-error", "1",
                 "--out", str(run)]) == 0
    capsys.readouterr()
    out = tmp_path / "cal.json"
    rrd = tmp_path / "cal.rrd"
    rc = main(["calibrate", "--setup", str(run / "setup.json"), "--data", str(run / "samples.csv"),
               "--free", "theta", "--calibrate-rows", "0:80", "--test-rows", "80:120",
               "--out", str(out), "--rerun", str(rrd), "--json", "--quiet"])
    res = json.loads(capsys.readouterr().out)
    assert rc == 0
    assert res["unit"] == "mm" and "tracker" in res["free"] and "markers" in res["free"]
    for rows in ("train", "test"):
        assert set(res["after"][rows]) == {"mean", "std", "max"}
        assert res["after"][rows]["mean"] < res["before"][rows]["mean"]
    calibrated = jwarp.RobotModel.load(out)
    assert calibrated.n_frames == 27
    assert rrd.stat().st_size > 0


def test_cli_calibrate_errors(tmp_path, capsys):
    setup = tmp_path / "tracker.json"
    write_setup(setup, justin_tracker_setup())
    data = tmp_path / "s.csv"
    data.write_text("torso_pan\n0\n")
    rc = main(["calibrate", "--setup", str(setup), "--data", str(data), "--out",
               str(tmp_path / "c.json")])
    assert rc == 2 and "missing column" in capsys.readouterr().err
    assert not (tmp_path / "c.json").exists()
    rc = main(["calibrate", "--setup", str(tmp_path / "nope.json"), "--data", str(data)])
    assert rc == 2 and "file not found" in capsys.readouterr().err


def test_cli_calibrate_mass_group_writes_calibrated_masses(tmp_path, capsys):
    """--free mass on a compliant robot file: the saved robot carries the calibrated masses
    (closer to the heavier truth), DH rows and compliances untouched; a robot without
    masses or without compliance is an error naming `free`."""
    nominal = jwarp.robot("justin19")
    kap = np.zeros((nominal.n_frames, 3))
    kap[:, [0, 2]] = 1e-4
    nominal = nominal.with_dh(nominal.dh_table, kappa=kap * nominal.is_dh[:, None])
    robot_file = tmp_path / "justin_elastic.json"
    nominal.save(robot_file)
    m0 = np.array([m.mass for m in nominal.masses])
    truth = nominal.with_masses(1.15 * m0)
    camp = simulate_campaign(nominal, justin_tracker_setup(noise=1e-4), 100, seed=6,
                             true_robot=truth)
    run = tmp_path / "run"
    camp.write(run)
    out = tmp_path / "cal.json"
    args = ["calibrate", "--robot", str(robot_file), "--setup", str(run / "setup.json"),
            "--data", str(run / "samples.csv"), "--calibrate-rows", "0:70",
            "--test-rows", "70:100", "--json", "--quiet"]
    rc = main(args + ["--free", "mass", "--out", str(out)])
    res = json.loads(capsys.readouterr().out)
    assert rc == 0, res
    assert res["free"][0] == "mass" and res["elastic"]
    assert res["after"]["test"]["mean"] < 0.5 * res["before"]["test"]["mean"]
    cal = jwarp.RobotModel.load(out)
    m_cal = np.array([m.mass for m in cal.masses])
    assert np.any(m_cal != m0)
    assert abs(m_cal.sum() - 1.15 * m0.sum()) < 0.5 * abs(m0.sum() - 1.15 * m0.sum())
    np.testing.assert_allclose(cal.kappa, nominal.kappa)
    np.testing.assert_allclose(cal.dh_table, nominal.dh_table)
    # errors name `free`
    massless = tmp_path / "massless.json"
    nominal.copy(masses=[]).save(massless)
    rc = main(args[:1] + ["--robot", str(massless)] + args[3:] + ["--free", "mass"])
    assert rc == 2 and "free: group 'mass' selects nothing" in capsys.readouterr().err
    rc = main(args[:1] + ["--robot", "justin19"] + args[3:] + ["--free", "theta,mass"])
    assert rc == 2 and "free: group 'mass' selects no masses" in capsys.readouterr().err
