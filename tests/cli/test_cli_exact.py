"""``jwarp plan --scene`` on the exact objects (no grid unless --voxel): the straight line
through a ball is refused with the colliding link and object named ("why:" and the JSON
"reason"), --endpoint-margin lets a goal closer than --margin be planned, and bad values of
the new options name the option."""

from __future__ import annotations

import json

import pytest
import yaml
from cli_helpers import one_line_error, q_text, run

START = [-1.2, 1.0, 0.0, 1.0, 0.0, 0.0, 0.0]
GOAL = [1.2, 1.0, 0.0, 1.0, 0.0, 0.0, 0.0]
SCENE = {"format": "jwarp.scene", "objects": [
    {"id": "ball", "type": "sphere", "radius": 0.1, "pose": {"position": [-0.57, 0.43, 0.86]}}]}


@pytest.fixture(scope="module")
def scene_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("scene") / "ball.yaml"
    path.write_text(yaml.safe_dump(SCENE))
    return path


def test_infeasible_line_names_link_and_object(capsys, scene_file):
    base = ["plan", "--robot", "arm7", "--scene", scene_file, "--start", q_text(START),
            "--goal", q_text(GOAL), "--waypoints", 12, "--starts", 1, "--iterations", 0,
            "--fallback", "none"]
    code, out, _ = run(capsys, base)
    assert code == 1 and "NOT feasible" in out
    why = [line for line in out.splitlines() if line.startswith("why: ")]
    assert len(why) == 1 and "vs object 'ball'" in why[0] and "of link '" in why[0]
    code, out, _ = run(capsys, base + ["--json"])
    doc = json.loads(out)
    assert code == 1 and "vs object 'ball'" in doc["reason"]


def test_plan_goes_around_on_the_exact_world(capsys, scene_file):
    code, out, _ = run(capsys, ["plan", "--robot", "arm7", "--scene", scene_file, "--start",
                                q_text(START), "--goal", q_text(GOAL), "--json"])
    doc = json.loads(out)
    assert code == 0 and doc["feasible"] and doc["reason"] == "feasible"


@pytest.mark.parametrize("opt,value,msg", [("--endpoint-margin", "-1", "--endpoint-margin"),
                                           ("--self-margin", "nan", "--self-margin")])
def test_bad_margins_name_the_option(capsys, scene_file, opt, value, msg):
    one_line_error(capsys, ["plan", "--robot", "arm7", "--scene", scene_file, "--start",
                            q_text(START), "--goal", q_text(GOAL), opt, value], msg)


def test_plan_rerun_records_the_exact_objects(capsys, scene_file, tmp_path):
    pytest.importorskip("rerun")
    rrd = tmp_path / "p.rrd"
    code, out, _ = run(capsys, ["plan", "--robot", "arm7", "--scene", scene_file, "--start",
                                q_text(START), "--goal", q_text(GOAL), "--rerun", str(rrd)])
    assert code == 0 and rrd.is_file() and rrd.stat().st_size > 0
