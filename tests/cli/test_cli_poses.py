"""``jwarp sample-poses``: the plan file and one-line errors."""

import json
import math

import numpy as np

from jwarp.calibration.design.poses import PoseOptions, PoseSampler
from jwarp.calibration.design.tour import path_length
from jwarp.calibration.files import write_setup
from jwarp.calibration.simulate.campaign import justin_tracker_setup
from jwarp.plugins.registry import robot as get_robot
from tests.cli_helpers import one_line_error, run


def setup_file(tmp_path, cameras, name="setup.json"):
    s = justin_tracker_setup()
    s.cameras = cameras
    path = tmp_path / name
    write_setup(path, s)
    return path, s


CAMS = [{"name": f"c{i}", "pose": {"position": [2.5 * math.cos(a), 2.5 * math.sin(a), 2.2],
                                   "look_at": [0.3, 0.0, 1.0]}, "fov": 70, "range": [0.5, 6]}
        for i, a in enumerate(np.linspace(-1.2, 1.2, 6))]


def test_sample_poses_writes_an_ordered_feasible_plan(tmp_path, capsys):
    path, setup = setup_file(tmp_path, CAMS)
    out = tmp_path / "plan.csv"
    code, stdout, _ = run(capsys, ["sample-poses", "--setup", path, "--n", 30, "--out", out,
                                   "--k-of-n", 3, "--margin", 0.03, "--quiet", "--json",
                                   "--batch-size", 20000])
    assert code == 0
    summary = json.loads(stdout)
    robot = get_robot("justin19")
    header = out.read_text().splitlines()[0].split(",")
    assert header == list(robot.joint_names)
    q = np.loadtxt(out, delimiter=",", skiprows=1)
    assert q.shape == (30, robot.n_dof)
    ok = PoseSampler(robot, setup, PoseOptions(k_of_n=3, margin=0.03)).ok(q)
    assert ok.all()
    assert summary["poses"] == 30 and summary["order"] in ("lkh", "input")
    assert summary["length_after"]["euclidean"] <= summary["length_before"]["euclidean"]
    assert abs(summary["length_after"]["euclidean"] - path_length(q)) < 1e-6


def test_sample_poses_errors(tmp_path, capsys):
    path, _ = setup_file(tmp_path, CAMS)
    out = tmp_path / "plan.csv"
    line = one_line_error(capsys, ["sample-poses", "--setup", path, "--n", 5, "--out", out,
                                   "--k-of-n", 7], "--k-of-n")
    assert "7 cameras asked, the setup has 6" in line
    bad, _ = setup_file(tmp_path, [{"fov": 60}], "bad1.json")
    line = one_line_error(capsys, ["sample-poses", "--setup", bad, "--n", 5, "--out", out],
                          "--setup")
    assert "cameras[0].pose: missing" in line
    bad, _ = setup_file(tmp_path, [{"pose": {"position": [0, 0, 0], "rotvec": [0, 0, 0]},
                                    "fov": 200}], "bad2.json")
    line = one_line_error(capsys, ["sample-poses", "--setup", bad, "--n", 5, "--out", out],
                          "--setup")
    assert "cameras[0].fov" in line
    one_line_error(capsys, ["sample-poses", "--setup", path, "--n", 0, "--out", out], "--n")
    one_line_error(capsys, ["sample-poses", "--setup", path, "--n", 5, "--out", out,
                            "--margin", "-1"], "--margin")
    one_line_error(capsys, ["sample-poses", "--setup", path, "--n", 5,
                            "--out", tmp_path / "missing" / "p.csv"], "--out")
    line = one_line_error(capsys, ["sample-poses", "--setup", path, "--n", 5, "--out", out,
                                   "--k-of-n", 6, "--max-tries", 100, "--quiet"], "--n")
    assert "only" in line
    assert not out.exists()


def test_sample_poses_contact_plan_has_pairs(tmp_path, capsys):
    from jwarp.calibration.simulate.scenarios import hand_contact_setup

    path = tmp_path / "hand.json"
    write_setup(path, hand_contact_setup())
    out = tmp_path / "plan.csv"
    code, stdout, _ = run(capsys, ["sample-poses", "--setup", path, "--n", 6, "--out", out,
                                   "--margin", 0, "--quiet"])
    assert code == 0, stdout
    lines = out.read_text().splitlines()
    assert lines[0].split(",")[-1] == "pair" and len(lines) == 7
    pairs = [int(ln.split(",")[-1]) for ln in lines[1:]]
    assert set(pairs) <= {0, 1, 2}
