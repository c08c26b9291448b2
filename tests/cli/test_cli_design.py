"""``jwarp sensitivity`` and ``jwarp design``: outputs, files, one-line errors."""

import json

import numpy as np
import pytest

from cli_helpers import one_line_error, run
from jwarp.registry import robot as get_robot
from jwarp.solvers.calibration.files import Setup, make_measurement, write_setup
from jwarp.solvers.calibration.pool import parse_configurations
from jwarp.solvers.calibration.scenarios import hand_contact_setup


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("design")
    write_setup(d / "one.json", hand_contact_setup(pairs=(("thumb", "index"),)))
    write_setup(d / "rel2.json", Setup(plugin="relative", robot="hand4", section={
        "end_effectors": ["thumb_tip", "index_tip"]}))
    write_setup(d / "contact.json", hand_contact_setup())
    write_setup(d / "rel4.json", Setup(plugin="relative", robot="hand4", section={
        "end_effectors": [f"{f}_tip" for f in ("thumb", "index", "middle", "ring")]}))
    return d


def test_sensitivity_text_json_png_rerun(capsys, files):
    d = files
    code, out, err = run(capsys, ["sensitivity", "--setup", d / "one.json", "--task-setup",
                                  d / "rel2.json", "--n", 80, "--png", d / "s.png",
                                  "--rerun", d / "s.rrd"])
    assert code == 0, err
    assert "actual (contact)" in out and "FAILS by 1 direction" in out
    png = (d / "s.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and (d / "s.rrd").stat().st_size > 0
    code, out, err = run(capsys, ["sensitivity", "--setup", d / "one.json", "--task-setup",
                                  d / "rel2.json", "--n", 80, "--json"])
    doc = json.loads(out)
    assert code == 0 and doc["actual"]["n_identifiable"] == 26
    assert doc["task"]["n_identifiable"] == 27 and doc["kernel_included"] is False
    assert len(doc["breaking"]) == 1 and doc["breaking"][0]["top"]


def test_design_pool_and_plan(capsys, files):
    d = files
    code, out, err = run(capsys, ["design", "--setup", d / "contact.json",
                                  "--write-candidates", 150, "--seed", 1, "--out", d / "pool.csv"])
    assert code == 0, err
    robot = get_robot("hand4")
    meas = make_measurement(robot, hand_contact_setup())
    pool = parse_configurations((d / "pool.csv").read_text(), robot, meas)
    assert len(pool) == 150
    for method in ("greedy", "detmax"):
        code, out, err = run(capsys, ["design", "--setup", d / "contact.json", "--task-setup",
                                      d / "rel4.json", "--task-n", 50, "--candidates",
                                      d / "pool.csv", "--n", 12, "--method", method,
                                      "--out", d / f"plan_{method}.csv", "--json", "--quiet"])
        assert code == 0, err
        doc = json.loads(out)
        plan = parse_configurations((d / f"plan_{method}.csv").read_text(), robot, meas)
        assert len(plan) == 12 and doc["method"] == method
        assert np.array_equal(plan.q, pool.q[doc["indices"]])
        assert np.array_equal(plan.meta["pair"], pool.meta["pair"][doc["indices"]])
        assert doc["criterion"] > doc["prior_criterion"]


def test_design_errors(capsys, files, tmp_path):
    d = files
    bad = tmp_path / "bad.csv"
    bad.write_text("thumb_abd,pair\n0,0\n")
    line = one_line_error(capsys, ["design", "--setup", d / "contact.json", "--candidates", bad,
                                   "--out", tmp_path / "p.csv"], "--candidates")
    assert "missing column 'thumb_flex_1'" in line
    one_line_error(capsys, ["design", "--setup", d / "contact.json", "--candidates", bad,
                            "--out", tmp_path / "missing" / "p.csv"], "--out")
    one_line_error(capsys, ["design", "--setup", d / "contact.json", "--out", tmp_path / "p.csv"],
                   "--candidates")
    one_line_error(capsys, ["design", "--setup", d / "contact.json", "--write-candidates", 0,
                            "--out", tmp_path / "p.csv"], "--write-candidates")
    one_line_error(capsys, ["sensitivity", "--setup", d / "one.json", "--task-setup",
                            d / "rel2.json", "--n", 30, "--free", "theta,bogus"], "--free")
    one_line_error(capsys, ["sensitivity", "--setup", d / "one.json", "--task-setup",
                            d / "rel2.json", "--n", 30, "--rtol", 0], "--rtol, --atol")
    one_line_error(capsys, ["sensitivity", "--setup", tmp_path / "none.json", "--task-setup",
                            d / "rel2.json"], "--setup")
    assert not (tmp_path / "p.csv").exists()
