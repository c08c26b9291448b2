"""Issue 38 item 3: the range a calibration is valid in. The calibrated robot records the
range of its calibration poses per joint and per coupled angle (notes['valid_range']);
IK, the planner, ``jwarp fk`` and ``calibrate --test-rows`` warn once outside it, with how
far; the test report splits its error inside / outside."""

from __future__ import annotations

import contextlib
import io
import json
import math
import warnings

import numpy as np
import pytest
from cli_helpers import run  # tests/cli_helpers.py

import jwarp
from jwarp.model.valid_range import (
    VALID_RANGE_NOTE,
    ValidRangeWarning,
    check_valid_range,
    record_valid_range,
    valid_range,
)


def _ranged(name: str, q: np.ndarray):
    return record_valid_range(jwarp.robot(name), q)


def test_records_joint_and_coupled_ranges_and_measures_how_far():
    robot = jwarp.robot("justin19")
    rng = np.random.default_rng(0)
    lo, hi = robot.joint_limits[:, 0], robot.joint_limits[:, 1]
    q = lo + (hi - lo) * (0.25 + 0.5 * rng.random((30, robot.n_dof)))
    cal = record_valid_range(robot, q)
    vr = valid_range(cal)
    assert vr is not None and vr.samples == 30
    np.testing.assert_allclose(vr.lower, q.min(0))
    np.testing.assert_allclose(vr.upper, q.max(0))
    assert vr.coupled == ("torso_4",)            # -(q1 + q2)
    u = q @ robot.coupling_matrix[robot.frame_index("torso_4")]
    np.testing.assert_allclose([vr.coupled_lower[0], vr.coupled_upper[0]], [u.min(), u.max()])
    # saved and loaded: the same range
    again = jwarp.model.RobotModel.from_dict(json.loads(json.dumps(cal.to_dict())))
    np.testing.assert_allclose(valid_range(again).upper, vr.upper)
    # inside: every joint inside and the coupled angle inside
    assert not vr.outside(q).any()
    # each joint in range but the coupled angle past its maximum: only the coupled entry
    j1, j2 = robot.joint_names.index("torso_tilt_1"), robot.joint_names.index("torso_tilt_2")
    k = int(np.argmin(u))                         # the largest q1 + q2
    q_c = q[k].copy()
    i1, i2 = int(np.argmax(q[:, j1])), int(np.argmax(q[:, j2]))
    q_c[j1], q_c[j2] = q[i1, j1], q[i2, j2]      # both at their own maxima
    ex = vr.excess(q_c)
    extra = u.min() - q_c @ robot.coupling_matrix[robot.frame_index("torso_4")]
    assert extra > 0
    assert np.allclose(ex[0, :robot.n_dof], 0.0)
    assert ex[0, -1] == pytest.approx(extra)
    # a joint past its maximum by 0.1 rad
    q_j = q[0].copy()
    q_j[5] = vr.upper[5] + 0.1
    assert vr.excess(q_j)[0, 5] == pytest.approx(0.1)
    assert f"up to {math.degrees(0.1):.2f} deg" in vr.describe(vr.excess(q_j))


def test_check_warns_once_per_entry_point_with_how_far():
    robot = jwarp.robot("planar4")
    q = np.array([[0.0, 0.0, 0.0, 0.0], [0.5, 0.5, 0.5, 0.5]])
    cal = _ranged("planar4", q)
    inside = np.array([[0.2, 0.3, 0.1, 0.4]])
    outside = np.array([[0.2, 0.3, 0.1, 0.7]])
    with warnings.catch_warnings(record=True) as got:
        warnings.simplefilter("always")
        assert check_valid_range(cal, inside, "here") is None
        m1 = check_valid_range(cal, outside, "here")
        m2 = check_valid_range(cal, outside, "here")      # the same entry point: no repeat
        check_valid_range(cal, outside, "there")          # another entry point: its own
        assert check_valid_range(robot, outside, "here") is None   # no recorded range
    assert m1 == m2 and "q4 up to 11.46 deg past [0.00, 28.65] deg" in m1.replace(
        robot.joint_names[3], "q4")
    assert [type(w.message) for w in got] == [ValidRangeWarning] * 2
    assert "1 of 1 configuration" in str(got[0].message)


def test_bad_note_is_an_error_naming_it():
    cal = _ranged("planar4", np.zeros((2, 4)))
    cal.notes[VALID_RANGE_NOTE] = "{not json"
    with pytest.raises(ValueError, match="notes.valid_range"):
        valid_range(cal)


def test_ik_and_planner_warn_once_outside_the_range():
    robot = jwarp.robot("planar4")
    q_cal = np.array([[0.0, 0.0, 0.0, 0.0], [0.3, 0.3, 0.3, 0.3]])
    cal = _ranged("planar4", q_cal)
    q_far = np.array([[1.2, -0.6, 0.9, 0.4]])
    T = jwarp.fk(robot, q_far, device="cpu")[:, robot.frame_index("tcp")]
    with warnings.catch_warnings(record=True) as got:
        warnings.simplefilter("always")
        res = jwarp.ik(cal, "tcp", T, n_starts=4, seed=1, device="cpu")
        jwarp.ik(cal, "tcp", T, n_starts=4, seed=1, device="cpu")
    rw = [w for w in got if issubclass(w.category, ValidRangeWarning)]
    assert res.feasible.all() and len(rw) == 1 and str(rw[0].message).startswith("ik: ")
    assert rw[0].filename == __file__                  # attributed to the caller's line
    from jwarp.solvers import planning as PL
    from jwarp.world import world_from_occupancy

    world = world_from_occupancy(np.zeros((8, 8), bool), [[-2.0, 1.5], [-2.0, 1.5]])
    start, goal = np.array([0.1, 0.1, 0.1, 0.1]), np.array([0.2, 0.2, 0.2, 0.2])
    with warnings.catch_warnings(record=True) as got:
        warnings.simplefilter("always")
        PL.plan(cal, world, start, goal, device="cpu", n_starts=2, iterations=5)
    assert not [w for w in got if issubclass(w.category, ValidRangeWarning)]
    with warnings.catch_warnings(record=True) as got:
        warnings.simplefilter("always")
        PL.plan(cal, world, start, goal + 0.5, device="cpu", n_starts=2, iterations=5)
        PL.plan(cal, world, start, goal + 0.5, device="cpu", n_starts=2, iterations=5)
    rw = [w for w in got if issubclass(w.category, ValidRangeWarning)]
    assert len(rw) == 1 and str(rw[0].message).startswith("plan: ")


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    from jwarp.cli import main

    d = tmp_path_factory.mktemp("campaign38")
    with contextlib.redirect_stdout(io.StringIO()):
        assert main(["simulate-campaign", "--samples", "60", "--seed", "1", "--kappa", "0",
                     "--out", str(d / "run")]) == 0
    return d / "run"


def test_calibrate_records_the_range_and_splits_the_test_report(campaign, capsys, tmp_path):
    from jwarp.calibration import calibrate
    from jwarp.calibration.files import make_measurement, parse_samples, read_setup

    out = tmp_path / "cal.json"
    code, text, err = run(capsys, [
        "calibrate", "--setup", campaign / "setup.json", "--data", campaign / "samples.csv",
        "--free", "theta", "--calibrate-rows", "0:40", "--test-rows", "40:60", "--out", out,
        "--quiet", "--json"])
    assert code == 0, err
    doc = json.loads(text)
    cal = jwarp.robot(str(out))
    vr = valid_range(cal)
    setup = read_setup(str(campaign / "setup.json"))
    model = jwarp.robot(setup.robot)
    meas = make_measurement(model, setup)
    data = parse_samples((campaign / "samples.csv").read_text(), model, meas)
    q = data.q
    np.testing.assert_allclose(vr.lower, q[:40].min(0))
    np.testing.assert_allclose(vr.upper, q[:40].max(0))
    n_out = int(vr.outside(q[40:60]).sum())
    assert 0 < n_out < 20
    tr = doc["test_range"]
    assert tr["outside"]["rows"] == n_out and tr["inside"]["rows"] == 20 - n_out
    # the two parts make up the test row's mean
    mean = (tr["inside"]["mean"] * tr["inside"]["rows"]
            + tr["outside"]["mean"] * tr["outside"]["rows"]) / 20
    assert mean == pytest.approx(doc["after"]["test"]["mean"], rel=1e-9)
    w = [x for x in doc["warnings"] if x.startswith("--test-rows: ")]
    assert len(w) == 1 and f"{n_out} of 20 configuration(s)" in w[0] and "deg past" in w[0]
    # the API result carries the range too
    res = calibrate(model, meas, q[:40], data.y[:40], free="theta", max_nfev=3, warn=False)
    np.testing.assert_allclose(res.valid_range.upper, q[:40].max(0))
    assert res.to_dict()["valid_range"]["samples"] == 40
    # jwarp fk warns with a configuration outside, not inside
    inside = ",".join(str(v) for v in q[0])
    code, _, err = run(capsys, ["fk", out, "--q", inside, "--json"])
    assert code == 0 and "outside the range" not in err
    far = q[0].copy()
    far[0] = vr.upper[0] + 0.2
    code, _, err = run(capsys, ["fk", out, "--q", ",".join(str(v) for v in far), "--json"])
    assert code == 0 and "outside the range of the 40 calibration poses" in err
    assert f"{robot_joint(cal, 0)} up to {math.degrees(0.2):.2f} deg" in err


def robot_joint(robot, j: int) -> str:
    return robot.joint_names[j]
