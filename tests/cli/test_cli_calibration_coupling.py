"""``jwarp simulate-campaign --unmodeled coupling`` and ``jwarp calibrate`` with the
options of issue 29: ``coupling`` in ``--free``, ``--prior``, ``--order``, ``--loss``,
``--loss-scale``, ``--fix GROUP=RESULT.json``, ``--diagnostics``; their errors name the
option."""

from __future__ import annotations

import json
import os

import pytest

from jwarp.model import RobotModel
from tests.cli_helpers import one_line_error, run

BASE = "theta,d,r,alpha"


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    d = tmp_path_factory.mktemp("coupling")
    from jwarp.cli import main

    code = main(["simulate-campaign", "--samples", "120", "--seed", "3", "--kappa", "0",
                 "--unmodeled", "coupling", "--out", str(d / "c")])
    assert code == 0
    return d, d / "c"


def calib(capsys, c, *more):
    return run(capsys, ["calibrate", "--setup", c / "setup.json", "--data", c / "samples.csv",
                        "--test-rows", "60:120", "--quiet", "--json", *more])


def test_coupling_group_prior_order_loss_fix_and_diagnostics(campaign, capsys):
    d, c = campaign
    truth = RobotModel.load(c / "truth.json")
    assert truth.has_coupling_harmonic
    code, out, err = calib(capsys, c, "--free", BASE, "--params-out", d / "first.json")
    assert code == 0, err
    plain = json.loads(out)
    code, out, err = calib(capsys, c, "--free", BASE + ",coupling", "--out", d / "cal.json",
                           "--params-out", d / "second.json",
                           "--prior", "coupling:torso_4=2e-2", "--order", "coupling=3",
                           "--loss", "soft_l1", "--loss-scale", "3",
                           "--fix", f"tracker={d / 'first.json'}", "--diagnostics")
    assert code == 0, err
    res = json.loads(out)
    assert res["after"]["test"]["mean"] < 0.8 * plain["after"]["test"]["mean"]
    assert "tracker" not in res["free"] and "coupling" in res["free"]
    first = json.loads((d / "first.json").read_text())
    second = json.loads((d / "second.json").read_text())
    tr = {k: v for k, v in first["measurement_params"].items() if k.startswith("tracker")}
    assert tr and all(second["measurement_params"][k] == v for k, v in tr.items())
    params = {p["name"]: p for p in second["parameters"]}
    assert params["torso_4.coupling_b3"]["sigma"] == 2e-2
    cal = RobotModel.load(d / "cal.json")
    assert cal.coupling_harmonic.shape[1] == 3
    diag = res["diagnostics"]
    assert diag["joints"][0]["frame"] and diag["chance"] == pytest.approx(1 / 6)
    # the text output prints the diagnostics table
    code, out, err = run(capsys, ["calibrate", "--setup", c / "setup.json", "--data",
                                  c / "samples.csv", "--free", BASE, "--quiet",
                                  "--diagnostics", "--max-nfev", "3"])
    assert code == 0, err
    assert "per-sample joint errors" in out and "right ~ left" in out


def test_errors_name_the_option(campaign, capsys, tmp_path):
    _, c = campaign
    base = ["calibrate", "--setup", c / "setup.json", "--data", c / "samples.csv",
            "--free", BASE, "--quiet"]
    one_line_error(capsys, base + ["--loss", "huber"], "--loss-scale")
    one_line_error(capsys, base + ["--loss", "huber", "--loss-scale", "0"], "--loss-scale")
    # round 4, item 8: a scale without a robust loss was accepted and ignored
    line = one_line_error(capsys, base + ["--loss-scale", "3"], "--loss-scale")
    assert "only with a robust --loss" in line
    # round 4, item 9: 1e308 gave "numeric overflow" naming no option
    line = one_line_error(capsys, base + ["--loss", "huber", "--loss-scale", "1e308"],
                          "--loss-scale")
    assert "times the mean noise sigma" in line
    line = one_line_error(capsys, base + ["--virtual-noise", "1e308"], "--virtual-noise")
    assert "a standard deviation of at most" in line
    # a --fix file with a bad value: the file, the parameter and the value
    for value, shown in (("x", "'x'"), (None, "None"), ([1, 2], "[1, 2]")):
        fx = tmp_path / "fx.json"
        fx.write_text(json.dumps({"measurement_params": {"tracker_px": value}}))
        line = one_line_error(capsys, base + ["--fix", f"tracker={fx}"], "--fix")
        assert f"{fx}: 'tracker_px' is {shown}, not a number" in line, line
    one_line_error(capsys, base + ["--prior", "theta:nope*=1e-3"], "--prior")
    one_line_error(capsys, base + ["--prior", "theta=abc"], "--prior")
    one_line_error(capsys, base + ["--prior", str(tmp_path / "missing.json")], "--prior")
    # a file read for a few numbers: a regular file of bounded size (round 4, item 7)
    line = one_line_error(capsys, base + ["--prior", str(tmp_path)], "--prior")
    assert "is a folder, not a regular file" in line
    if os.path.exists("/dev/zero"):
        line = one_line_error(capsys, base + ["--prior", "/dev/zero"], "--prior")
        assert "/dev/zero is a device, not a regular file" in line
        # the data and setup files: never read without end either
        _, c = campaign
        line = one_line_error(capsys, ["calibrate", "--setup", c / "setup.json", "--data",
                                       "/dev/zero", "--free", BASE], "data")
        assert "/dev/zero is a device, pipe or socket, not a regular file" in line
    one_line_error(capsys, base + ["--order", "harmonic=1.5"], "--order")
    one_line_error(capsys, base + ["--order", "theta=2"], "--order")
    line = one_line_error(capsys, base + ["--fix", f"tracker={tmp_path / 'missing.json'}"],
                          "--fix")
    assert "cannot read" in line
    (tmp_path / "prior.json").write_text(json.dumps({"theta": 1e-3, "coupling": "x"}))
    one_line_error(capsys, base + ["--prior", str(tmp_path / "prior.json")], "--prior")
