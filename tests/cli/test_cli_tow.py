"""``jwarp calibrate`` with the setup's ``tow`` section and ``--virtual-noise``."""

from __future__ import annotations

import json

import pytest

import jwarp
from jwarp.calibration.files import read_setup, write_setup
from jwarp.calibration.simulate.campaign import simulate_campaign
from jwarp.calibration.simulate.scenarios import scenario
from tests.cli_helpers import one_line_error, run

TASK = {"plugin": "cartesian", "tracker": {"position": [0, 0, 0]},
        "markers": [{"name": "right", "frame": "right_tcp", "position": [0, 0, 0.05]},
                    {"name": "left", "frame": "left_tcp", "position": [0, 0, 0.05]}],
        "noise": 1e-4}


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    d = tmp_path_factory.mktemp("tow")
    setup, sampler, accept = scenario("justin19", "image")
    camp = simulate_campaign(jwarp.robot("justin19"), setup, 40, seed=2, sampler=sampler,
                             accept=accept, kappa=None)
    paths = camp.write(d / "camp")
    return d, paths


def calib(capsys, paths, setup, *more):
    return run(capsys, ["calibrate", "--setup", setup, "--data", paths["samples.csv"],
                        "--free", "theta,camera,markers", "--max-nfev", "5", "--quiet",
                        "--json", *more])


def test_tow_section_changes_the_fit(campaign, capsys):
    d, paths = campaign
    code, out, err = calib(capsys, paths, paths["setup.json"])
    assert code == 0, err
    plain = json.loads(out)
    s = read_setup(paths["setup.json"])
    s.tow = {"task": TASK, "virtual_noise": 0.005}
    write_setup(d / "tow.json", s)
    assert read_setup(d / "tow.json").tow == s.tow        # round trip
    code, out, err = calib(capsys, paths, d / "tow.json")
    assert code == 0, err
    tow = json.loads(out)
    code, out, err = calib(capsys, paths, paths["setup.json"], "--virtual-noise", "3")
    assert code == 0, err
    vn = json.loads(out)
    a = plain["after"]["train"]["mean"]
    assert tow["after"]["train"]["mean"] != pytest.approx(a, rel=1e-6)
    assert vn["after"]["train"]["mean"] != pytest.approx(a, rel=1e-6)


def test_tow_errors(campaign, capsys):
    d, paths = campaign
    s = read_setup(paths["setup.json"])
    s.tow = {"task": dict(TASK, markers=[{"name": "x", "frame": "nope"}]), "virtual_noise": 0.01}
    write_setup(d / "bad.json", s)
    code, out, err = calib(capsys, paths, d / "bad.json")
    assert code != 0 and "tow.task.markers[0].frame" in err
    one_line_error(capsys, ["calibrate", "--setup", paths["setup.json"], "--data",
                            paths["samples.csv"], "--virtual-noise", "-1", "--quiet"],
                   "--virtual-noise")
