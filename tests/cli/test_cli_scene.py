"""``jwarp plan --scene``: a scene file end to end on arm7 (the straight line collides with
a ball, the plan goes around it: checked against the scene's exact distances), MoveIt
robot states and goal joint constraints as --start/--goal, and the errors."""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml
from cli_helpers import one_line_error, q_text, run

import jwarp
from jwarp.core.device import host_frames
from jwarp.viz import world_spheres
from jwarp.world.scene_file import load_scene

START = [-1.2, 1.0, 0.0, 1.0, 0.0, 0.0, 0.0]
GOAL = [1.2, 1.0, 0.0, 1.0, 0.0, 0.0, 0.0]
VOXEL = 0.03
#: a ball in the way of arm7's straight swing from START to GOAL, and a rotated floor
SCENE = {"format": "jwarp.scene", "objects": [
    {"id": "ball", "type": "sphere", "radius": 0.1, "pose": {"position": [-0.57, 0.43, 0.86]}},
    {"id": "floor", "type": "box", "size": [2, 2, 0.05],
     "pose": {"position": [0, 0, -0.025], "rpy": [0, 0, 0.3]}}]}


@pytest.fixture(scope="module")
def scene_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("scene") / "ball.yaml"
    path.write_text(yaml.safe_dump(SCENE))
    return path


def clearance(q: np.ndarray, scene_path) -> float:
    """min over arm7's spheres of (exact distance to the scene - radius) [m] at q (W, 7)."""
    model = jwarp.robot("arm7")
    scene = load_scene(scene_path)
    out = np.inf
    for f in host_frames(model, np.atleast_2d(q)):
        c, r = world_spheres(model, f)
        out = min(out, float((scene.distance(c) - r).min()))
    return out


def test_plan_with_scene_goes_around_the_obstacle(capsys, scene_file):
    base = ["plan", "--robot", "arm7", "--scene", scene_file, "--voxel", VOXEL, "--start",
            q_text(START), "--goal", q_text(GOAL), "--waypoints", 12, "--json"]
    # the straight line (no iterations, no fallback) collides with the ball ...
    code, out, _ = run(capsys, base + ["--starts", 1, "--iterations", 0, "--fallback", "none"])
    line = np.array(json.loads(out)["path"])
    assert code == 1 and not json.loads(out)["feasible"]
    dense = START + np.linspace(0, 1, 200)[:, None] * (np.array(GOAL) - START)
    assert clearance(dense, scene_file) < -0.02
    np.testing.assert_allclose(line[[0, -1]], [START, GOAL])
    # ... the planned path does not: its waypoints clear the exact scene (the grid's
    # lookup may overestimate by up to half a voxel)
    code, out, _ = run(capsys, base + ["--starts", 4, "--iterations", 200])
    res = json.loads(out)
    assert code == 0 and res["feasible"] and res["world"] == str(scene_file)
    path = np.array(res["path"])
    np.testing.assert_allclose(path[[0, -1]], [START, GOAL], atol=1e-6)
    assert clearance(path, scene_file) > -0.5 * VOXEL


def moveit_request(tmp_path, start=None, goal=None, objects=True):
    data = {}
    if objects:
        data["world"] = {"collision_objects": [{
            "id": "ball", "header": {"frame_id": "right_base"},
            "primitives": [{"type": "sphere", "dimensions": [0.1]}],
            "primitive_poses": [{"position": [-0.57, 0.43, 0.86], "orientation": [0, 0, 0, 1]}]}]}
    if start is not None:
        data["robot_state"] = {"joint_state": {"name": list(start),
                                               "position": list(start.values())}}
    if goal is not None:
        data["goal_constraints"] = [{"joint_constraints": [
            {"joint_name": k, "position": v, "tolerance_above": 0.01, "tolerance_below": 0.01,
             "weight": 1.0} for k, v in goal.items()]}]
    path = tmp_path / f"moveit{len(list(tmp_path.iterdir()))}.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def test_moveit_start_and_goal(capsys, tmp_path):
    names = [f"right_{i}" for i in range(1, 8)]
    start = dict(reversed(list(zip(names, START))))            # any order
    scene = moveit_request(tmp_path, start=start, goal={"right_1": 1.2, "right_3": 0.3})
    code, out, _ = run(capsys, ["plan", "--robot", "arm7", "--scene", scene, "--start", "moveit",
                                "--goal", "moveit", "--starts", 1, "--iterations", 0,
                                "--waypoints", 3, "--json"])
    res = json.loads(out)
    assert code in (0, 1)
    np.testing.assert_allclose(res["start"], START)
    # unconstrained joints of the goal keep the start's values
    np.testing.assert_allclose(res["goal"], [1.2, 1.0, 0.3, 1.0, 0.0, 0.0, 0.0])
    # a separate MotionPlanRequest file for the goal, joint values with a world spec
    req = moveit_request(tmp_path, goal=dict(zip(names, GOAL)), objects=False)
    code, out, _ = run(capsys, ["plan", "--robot", "arm7", "--world", "shelf", "--start",
                                f"moveit:{scene}", "--goal", f"moveit:{req}", "--starts", 1,
                                "--iterations", 0, "--waypoints", 3, "--json"])
    np.testing.assert_allclose(json.loads(out)["goal"], GOAL)


def test_scene_errors(capsys, tmp_path, scene_file):
    base = ["plan", "--robot", "arm7", "--start", "zeros", "--goal", "zeros"]
    one_line_error(capsys, base + ["--scene", scene_file, "--world", "shelf"], "--world")
    one_line_error(capsys, base + ["--world", "shelf", "--voxel", "0.02"], "--voxel")
    one_line_error(capsys, base + ["--scene", scene_file, "--voxel", "0"], "--voxel")
    one_line_error(capsys, base + ["--scene", scene_file, "--extent", "1,0,0,1,0,1"], "--extent")
    err = one_line_error(capsys, base + ["--scene", tmp_path / "missing.yaml"], "--scene")
    assert "does not exist" in err
    bad = tmp_path / "bad.yaml"
    bad.write_text(yaml.safe_dump({"world": {"collision_objects": [{
        "id": "Can1", "primitives": [{"type": "cylinder", "dimensions": [0.1]}],
        "primitive_poses": [{"position": [0, 0, 0]}]}]}}))
    err = one_line_error(capsys, base + ["--scene", bad], "--scene")
    assert "object 'Can1': a cylinder needs 2 dimensions, got 1" in err
    frame = moveit_request(tmp_path)
    frame.write_text(frame.read_text().replace("right_base", "panda_link0"))
    err = one_line_error(capsys, base + ["--scene", frame], "--scene")
    assert "object 'ball': unknown frame_id 'panda_link0'" in err
    # MoveIt joint values: unknown names, missing joints, no state, no --scene
    panda = moveit_request(tmp_path, start={"panda_joint1": 0.0, "right_1": 0.0})
    err = one_line_error(capsys, ["plan", "--robot", "arm7", "--scene", panda, "--start",
                                  "moveit", "--goal", "zeros"], "--start")
    assert "unknown joint(s) 'panda_joint1'" in err
    partial = moveit_request(tmp_path, start={"right_1": 0.0})
    err = one_line_error(capsys, ["plan", "--robot", "arm7", "--scene", partial, "--start",
                                  "moveit", "--goal", "zeros"], "--start")
    assert "no value for joint(s) 'right_2'" in err
    err = one_line_error(capsys, ["plan", "--robot", "arm7", "--scene", partial, "--start",
                                  "zeros", "--goal", "moveit"], "--goal")
    assert "has no goal joint constraints" in err
    err = one_line_error(capsys, ["plan", "--robot", "arm7", "--world", "shelf", "--start",
                                  "moveit", "--goal", "zeros"], "--start")
    assert "give --scene or moveit:FILE" in err
    one_line_error(capsys, ["plan", "--robot", "planar4", "--scene", scene_file, "--start",
                            "zeros", "--goal", "zeros"], "--scene")
