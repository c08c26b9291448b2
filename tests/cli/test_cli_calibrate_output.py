"""Issue 27, item 3: what ``jwarp calibrate`` prints and writes. A progress bar of solver
iterations with cost and step, active-set restarts labelled (a rising cost explained),
every finding once, the Python API's findings attributed to the caller's line, and the
calibrated robot renamed with its provenance in its notes."""

from __future__ import annotations

import io
import json
import warnings
from types import SimpleNamespace

import numpy as np
import pytest
from cli_helpers import one_line_error, run  # tests/cli_helpers.py

from jwarp.calibration.campaign_run import PROVENANCE_NOTE
from jwarp.cli.calibration import ProgressBar


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    import contextlib

    from jwarp.cli import main

    d = tmp_path_factory.mktemp("campaign")
    with contextlib.redirect_stdout(io.StringIO()):
        assert main(["simulate-campaign", "--samples", "120", "--seed", "1",
                     "--out", str(d / "run")]) == 0
    return d / "run"


def _cal(campaign, *extra):
    return ["calibrate", "--setup", campaign / "setup.json", "--data", campaign / "samples.csv",
            "--free", "theta,d,r,alpha,kappa_theta,kappa_alpha", "--calibrate-rows", "0:90",
            "--test-rows", "90:120", "--max-nfev", "40", *extra]


def test_progress_bar_labels_restarts_and_counts_iterations():
    """A cost that rises within one start is a new least-squares run: labelled once."""
    stream = io.StringIO()
    bar = ProgressBar("calibrate", stream=stream, total=10)
    costs = [10.0, 8.0, 9.0, 7.0, 6.5]       # 8 -> 9: an active-set round
    for k, c in enumerate(costs):
        bar(SimpleNamespace(start=0, n_starts=1, iteration=k + 1, cost=c))
    bar.close()
    text = stream.getvalue()
    assert bar.restarts == 1
    assert text.count("active-set round 2") == 1 and "cost 8 -> 9" in text
    assert "5 iterations, done within the --max-nfev budget of 10" in text  # complete
    assert "cost 6.5" in text and "step" in text
    # a new start is not a restart, even at a higher cost
    bar = ProgressBar("calibrate", stream=io.StringIO(), total=10)
    for s, c in ((0, 5.0), (0, 4.0), (1, 50.0), (1, 40.0)):
        bar(SimpleNamespace(start=s, n_starts=2, iteration=1, cost=c))
    assert bar.restarts == 0
    # a robust loss: 0.5 |r|^2 may rise within a run, no restart is inferred
    bar = ProgressBar("calibrate", stream=io.StringIO(), total=10, robust=True)
    for k, c in enumerate(costs):
        bar(SimpleNamespace(start=0, n_starts=1, iteration=k + 1, cost=c))
    assert bar.restarts == 0


def test_calibrated_robot_renamed_with_provenance_findings_once(campaign, capsys, tmp_path):
    out_json = tmp_path / "cal.json"
    code, out, err = run(capsys, _cal(campaign, "--out", out_json))
    assert code == 0, err
    assert "iterations (of the --max-nfev budget)" in err and "cost" in err
    assert "finding(s)" not in err and "finding(s)" not in out   # no second, joined copy
    warns = [ln for ln in out.splitlines() if ln.startswith("warning: ")]
    assert len(warns) == len(set(warns))
    doc = json.loads(out_json.read_text())
    assert doc["name"] == "justin19-calibrated"
    prov = json.loads(doc["notes"][PROVENANCE_NOTE])
    setup = json.loads((campaign / "setup.json").read_text())
    assert prov["campaign_id"] == setup["campaign_id"] and prov["nominal_robot"] == "justin19"
    assert prov["free"][:6] == ["theta", "d", "r", "alpha", "kappa_theta", "kappa_alpha"]
    import hashlib

    assert prov["data_sha256"] == hashlib.sha256(
        (campaign / "samples.csv").read_bytes()).hexdigest()
    assert prov["samples"] == {"train": 90, "test": 30} and prov["date"].endswith("Z")
    import jwarp

    cal = jwarp.robot(str(out_json))
    assert cal.name == "justin19-calibrated"
    after = prov["errors"]["after"]["test"]["mean"]
    assert 0 < after < prov["errors"]["before"]["test"]["mean"]
    assert "justin19-calibrated" in out
    # the robot loads and computes like any other: its FK differs from the nominal one
    q = np.zeros(cal.n_dof)
    assert not np.allclose(jwarp.fk(cal, q, device="cpu"), jwarp.fk("justin19", q, device="cpu"))


def test_name_option_and_empty_name(campaign, capsys, tmp_path):
    out_json = tmp_path / "mine.json"
    code, out, err = run(capsys, _cal(campaign, "--out", out_json, "--name", "lab-justin",
                                      "--quiet", "--json"))
    assert code == 0, err
    summary = json.loads(out)
    assert summary["calibrated_name"] == "lab-justin" and "active_set_rounds" in summary
    assert json.loads(out_json.read_text())["name"] == "lab-justin"
    assert "iterations" not in err                    # --quiet: no bar
    one_line_error(capsys, _cal(campaign, "--out", tmp_path / "x.json", "--name", " "), "--name")
    assert not (tmp_path / "x.json").exists()


def test_python_findings_attributed_to_the_callers_line(campaign):
    import jwarp
    from jwarp.calibration import CalibrationWarning, calibrate
    from jwarp.calibration.files import make_measurement, parse_samples, read_setup, read_text

    model = jwarp.robot("justin19")
    meas = make_measurement(model, read_setup(str(campaign / "setup.json")))
    data = parse_samples(read_text(str(campaign / "samples.csv"), "data")[0], model, meas)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        calibrate(model, meas, data.q[:60], data.y[:60], free="theta,d,r,alpha,kappa_theta",
                  max_nfev=15)
        line = __import__("inspect").currentframe().f_lineno - 2
    found = [w for w in caught if issubclass(w.category, CalibrationWarning)]
    assert found, "the fit reported no finding (a free compliance without excitation is one)"
    assert all(w.filename == __file__ and w.lineno == line for w in found)


def test_progress_bar_completes_when_the_fit_ends_early():
    """Issue 39 item 5: a fit that converges within 3 of its 100-evaluation budget ends at
    100 % (not 3 %), saying how many iterations it took and the budget; a run that used
    its whole budget is unchanged."""
    stream = io.StringIO()
    bar = ProgressBar("calibrate", stream=stream, total=100)
    for k, c in enumerate([10.0, 5.0, 2.0]):
        bar(SimpleNamespace(start=0, n_starts=1, iteration=k + 1, cost=c))
    bar.close()
    last = stream.getvalue().replace("\r", "\n").strip().splitlines()[-1]
    assert last.startswith("calibrate: 100%"), last
    assert "3 iterations, done within the --max-nfev budget of 100" in last
    # two starts: the first one's bar is completed when the second begins
    stream = io.StringIO()
    bar = ProgressBar("calibrate", stream=stream, total=50)
    for s, c in ((0, 5.0), (0, 4.0), (1, 50.0)):
        bar(SimpleNamespace(start=s, n_starts=2, iteration=1, cost=c))
    bar.close()
    text = stream.getvalue()
    assert "start 1/2: 100%" in text and "2 iterations, done within" in text
    assert "start 2/2: 100%" in text
    # the whole budget used: the usual bar, at 100 %
    stream = io.StringIO()
    bar = ProgressBar("calibrate", stream=stream, total=2)
    for k in range(2):
        bar(SimpleNamespace(start=0, n_starts=1, iteration=k + 1, cost=1.0 / (k + 1)))
    bar.close()
    assert "2/2 iterations (of the --max-nfev budget)" in stream.getvalue()


def test_calibrate_bar_on_the_cli_ends_complete(campaign, capsys):
    code, out, err = run(capsys, _cal(campaign))
    assert code == 0, err
    last = [ln for ln in err.replace("\r", "\n").splitlines() if ln.startswith("calibrate")][-1]
    assert last.startswith("calibrate: 100%"), last


def test_simulated_setup_records_the_robot(campaign, capsys, tmp_path, monkeypatch):
    """Issue 39 item 5: simulate-campaign --robot R --setup S (S naming no robot) writes a
    setup.json naming R, so calibrate needs no --robot."""
    doc = json.loads((campaign / "setup.json").read_text())
    doc.pop("robot", None)
    for key in ("campaign_id", "samples_sha256"):
        doc.pop(key, None)
    rough = tmp_path / "rough.json"
    rough.write_text(json.dumps(doc))
    run2 = tmp_path / "run2"
    code, out, err = run(capsys, ["simulate-campaign", "--robot", "justin19", "--setup", rough,
                                  "--samples", "120", "--seed", "2", "--out", run2])
    assert code == 0, err
    assert json.loads((run2 / "setup.json").read_text())["robot"] == "justin19"
    code, out, err = run(capsys, ["calibrate", "--setup", run2 / "setup.json", "--data",
                                  run2 / "samples.csv", "--free", "theta,d", "--max-nfev", "20",
                                  "--quiet", "--json"])
    assert code == 0, err
    # a robot file is recorded by its absolute path (calibrate may run elsewhere)
    import jwarp

    robot_file = tmp_path / "j19.json"
    jwarp.robot("justin19").save(robot_file)
    run3 = tmp_path / "run3"
    monkeypatch.chdir(tmp_path)
    code, out, err = run(capsys, ["simulate-campaign", "--robot", "j19.json", "--setup",
                                  rough, "--samples", "60", "--out", run3])
    assert code == 0, err
    assert json.loads((run3 / "setup.json").read_text())["robot"] == str(robot_file)
