"""``jwarp sensitivity`` and ``jwarp design``: outputs, files, one-line errors."""

import dataclasses
import json
import re

import numpy as np
import pytest
from cli_helpers import one_line_error, run
from pool_helpers import ball_colliding, self_colliding

from jwarp.calibration.files import Setup, make_measurement, write_setup
from jwarp.calibration.pool import draw_pool, parse_configurations, write_configurations
from jwarp.calibration.simulate.campaign import justin_tracker_setup, uniform_configurations
from jwarp.calibration.simulate.scenarios import hand_contact_setup
from jwarp.plugins.registry import robot as get_robot
from jwarp.world import World


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("design")
    write_setup(d / "one.json", hand_contact_setup(pairs=(("thumb", "index"),)))
    write_setup(d / "rel2.json", Setup(plugin="relative", robot="hand4", section={
        "end_effectors": ["thumb_tip", "index_tip"]}))
    write_setup(d / "contact.json", hand_contact_setup())
    write_setup(d / "rel4.json", Setup(plugin="relative", robot="hand4", section={
        "end_effectors": [f"{f}_tip" for f in ("thumb", "index", "middle", "ring")]}))
    write_setup(d / "justin.json", justin_tracker_setup())
    write_setup(d / "jrel.json", Setup(plugin="relative", robot="justin19", section={
        "end_effectors": ["right_tcp", "left_tcp"]}))
    return d


def test_sensitivity_text_json_png_rerun(capsys, files):
    d = files
    code, out, err = run(capsys, ["sensitivity", "--setup", d / "one.json", "--task-setup",
                                  d / "rel2.json", "--n", 80, "--out", d / "s.png",
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
    assert len(pool) == 150 and "collision check (self, margin 0 m): dropped" in out
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


def test_design_justin_pool_and_plans_are_free(capsys, files):
    d = files
    robot = get_robot("justin19")
    meas = make_measurement(robot, justin_tracker_setup())
    code, out, err = run(capsys, ["design", "--setup", d / "justin.json", "--write-candidates",
                                  120, "--seed", 4, "--out", d / "jpool.csv"])
    assert code == 0, err
    m = re.search(r"collision check \(self, margin 0 m\): dropped (\d+) of (\d+) draws", out)
    assert m, out
    ref = draw_pool(robot, justin_tracker_setup(), 120, seed=4)   # the same draws
    raw = np.concatenate([ref.q, ref.rejected_q])
    assert int(m.group(1)) == int(self_colliding(robot, raw).sum()) > 0
    assert int(m.group(2)) == len(raw)
    pool = parse_configurations((d / "jpool.csv").read_text(), robot, meas)
    assert len(pool) == 120 and not self_colliding(robot, pool.q).any()
    code, out, err = run(capsys, ["design", "--setup", d / "justin.json", "--task-setup",
                                  d / "jrel.json", "--task-n", 40, "--candidates",
                                  d / "jpool.csv", "--n", 10, "--out", d / "jplan.csv",
                                  "--quiet"])
    assert code == 0, err
    assert "all 120 rows of --candidates pass the collision check (self, margin 0 m)" in out
    plan = parse_configurations((d / "jplan.csv").read_text(), robot, meas)
    assert len(plan) == 10 and not self_colliding(robot, plan.q).any()
    # a pool made elsewhere, unchecked: its colliding rows are left out of the selection
    q_raw = uniform_configurations(robot, np.random.default_rng(7), 100)
    write_configurations(d / "raw.csv", robot, meas, q_raw)
    bad = self_colliding(robot, q_raw)
    code, out, err = run(capsys, ["design", "--setup", d / "justin.json", "--candidates",
                                  d / "raw.csv", "--n", 10, "--out", d / "rplan.csv", "--json",
                                  "--quiet"])
    assert code == 0, err
    doc = json.loads(out)
    cc = doc["collision_check"]
    assert cc["excluded"]["self_collision"] == int(bad.sum()) > 0
    assert cc["excluded_lines"] == [int(i) + 2 for i in np.flatnonzero(bad)]
    assert not bad[doc["indices"]].any() and doc["n_candidates"] == 100
    plan = parse_configurations((d / "rplan.csv").read_text(), robot, meas)
    assert np.array_equal(plan.q, q_raw[doc["indices"]])
    line = one_line_error(capsys, ["design", "--setup", d / "justin.json", "--candidates",
                                   d / "raw.csv", "--n", int((~bad).sum()) + 1, "--out",
                                   d / "x.csv"], "--n")
    assert "pass the collision check" in line


def test_design_pool_world_and_bare_robot(capsys, files, tmp_path):
    d = files
    code, out, err = run(capsys, ["design", "--setup", d / "justin.json", "--write-candidates",
                                  40, "--world", "shelf", "--margin", 0.02, "--out",
                                  tmp_path / "w.csv", "--json"])
    assert code == 0, err
    doc = json.loads(out)
    assert doc["kept"] == 40 and doc["world_checked"] and doc["margin"] == 0.02
    assert doc["drawn"] == 40 + sum(doc["dropped"].values())
    bare = dataclasses.replace(get_robot("arm7"), spheres=[], name="arm7_bare")
    bare.save(tmp_path / "bare.json")
    write_setup(tmp_path / "bare_rel.json", Setup(plugin="relative", robot=str(
        tmp_path / "bare.json"), section={"end_effectors": ["right_tcp", "right_4"]}))
    code, out, err = run(capsys, ["design", "--setup", tmp_path / "bare_rel.json",
                                  "--write-candidates", 30, "--out", tmp_path / "b.csv"])
    assert code == 0, err
    assert "warning: robot 'arm7_bare' has no collision spheres: the pool is NOT checked" in err
    assert "collision check: NONE" in out


def test_design_pool_scene_counts(capsys, files, tmp_path):
    d = files
    centre, radius = [0.55, 0.0, 1.0], 0.3
    (tmp_path / "ball.yaml").write_text(
        f"objects:\n  - {{id: ball, type: sphere, radius: {radius}, "
        f"pose: {{position: {centre}}}}}\n")
    code, out, err = run(capsys, ["design", "--setup", d / "justin.json", "--write-candidates",
                                  60, "--seed", 2, "--scene", tmp_path / "ball.yaml", "--out",
                                  tmp_path / "s.csv", "--json"])
    assert code == 0, err
    doc = json.loads(out)
    robot = get_robot("justin19")
    world = World.of_shapes()
    world.add("ball", "sphere", [radius], centre)
    ref = draw_pool(robot, justin_tracker_setup(), 60, seed=2, world=world)   # same draws
    raw = np.concatenate([ref.q, ref.rejected_q])
    s_bad = self_colliding(robot, raw)
    w_bad = ball_colliding(robot, raw, centre, radius) & ~s_bad
    assert doc["world_checked"] and doc["drawn"] == len(raw)
    assert doc["dropped"]["self_collision"] == int(s_bad.sum())
    assert doc["dropped"]["world_collision"] == int(w_bad.sum()) > 0
    q = parse_configurations((tmp_path / "s.csv").read_text(), robot,
                             make_measurement(robot, justin_tracker_setup())).q
    assert len(q) == 60 and not (self_colliding(robot, q)
                                 | ball_colliding(robot, q, centre, radius)).any()


def test_design_collision_option_errors(capsys, files, tmp_path):
    d = files
    base = ["design", "--setup", d / "justin.json", "--write-candidates", 10, "--out",
            tmp_path / "p.csv"]
    one_line_error(capsys, base + ["--margin", -1], "--margin")
    one_line_error(capsys, base + ["--world", "simplex:bogus=1"], "--world")
    one_line_error(capsys, base + ["--scene", tmp_path / "none.yaml"], "--scene")
    one_line_error(capsys, base + ["--world", "shelf", "--scene", tmp_path / "none.yaml"],
                   "--scene")
    assert not (tmp_path / "p.csv").exists()
