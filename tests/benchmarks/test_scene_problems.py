"""Smoke test of benchmarks/scene_problems.py: one problem of two families generated into
a temporary folder through the CLI, loaded back with jwarp.world.load_scene (start and
goal by joint name, as ``--start moveit --goal moveit``), and its start and goal re-checked
from the file by the independent checker tests/verifier.py."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tests"))

from verifier import PathVerifier  # noqa: E402


def test_scene_problems_generate_and_load(tmp_path):
    import jwarp
    from jwarp.importers.robot import example_robot_urdf
    from jwarp.world.moveit import joint_vector
    from jwarp.world.scene_file import load_scene, robot_frames

    try:
        urdf = example_robot_urdf("panda_description/urdf/panda.urdf")
    except ValueError as e:
        pytest.skip(str(e))
    out = tmp_path / "problems"
    proc = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "scene_problems.py"), "--out", str(out),
         "--per-family", "1", "--seed", "3", "--families", "table_pick,bookshelf_small"],
        cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, f"stdout:\n{proc.stdout}\nstderr:\n{proc.stderr}"
    index = json.loads((out / "index.json").read_text())
    assert [p["family"] for p in index["problems"]] == ["table_pick", "bookshelf_small"]
    assert index["failed"] == []
    robot = jwarp.robot(urdf)
    for p in index["problems"]:
        scene = load_scene(out / p["file"], robot_frames(robot))
        assert scene.format == "moveit" and len(scene.shapes) >= 3
        assert p["target_object"] in scene.object_ids
        start = joint_vector(robot, scene.start, "start")
        goal = joint_vector(robot, scene.goal, "goal", start)
        np.testing.assert_allclose(start, p["start"], atol=1e-12)
        np.testing.assert_allclose(goal, p["goal"], atol=1e-12)
        assert np.abs(goal - start).max() > 0.05
        # the goal puts the TCP where the index says
        T = np.asarray(jwarp.fk(robot, goal[None], device="cpu", dtype="float64"))[0]
        tcp = T[robot.frame_index("panda_hand_tcp")]
        np.testing.assert_allclose(tcp, p["goal_tcp"], atol=2e-3)
        # start and goal clear of the exact scene (URDF meshes), read back from the file
        v = PathVerifier(urdf, None, scene.shapes, joint_names=robot.joint_names)
        for q in (start, goal):
            got = v.check_path(q[None])
            assert got.ok and got.min_distance > 0


def test_arm_specs_frame_offset_and_errors():
    """The zoo arms' specs (``--arm``): the frame offset puts the arm's own frame
    ``standoff`` behind the pre-grasp point with its ``approach`` axis along tcp_pose's z;
    unknown arms and a missing model are refused naming the argument."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    import scene_problems as SP

    site = SP.Site(0.5, 0.3)
    rng = np.random.default_rng(0)
    T = SP.side_grasp(site, rng, np.array([0.2, 0.0, 0.4]), 0.03)
    for name, spec in SP.ARMS.items():
        F = T @ spec.frame_offset()
        axis = F[:3, 0] if spec.approach == "x" else F[:3, 2]
        np.testing.assert_allclose(axis, T[:3, 2], atol=1e-12, err_msg=name)
        np.testing.assert_allclose(F[:3, :3] @ F[:3, :3].T, np.eye(3), atol=1e-12)
        assert abs(np.linalg.det(F[:3, :3]) - 1.0) < 1e-12
        # the frame stands `standoff` behind the pre-grasp point, along the approach
        np.testing.assert_allclose(F[:3, 3] + spec.standoff * axis, T[:3, 3], atol=1e-12)
        assert set(spec.fixed) <= set(spec.ready) | set(spec.fixed)
    assert np.array_equal(SP.ARMS["panda"].frame_offset(), np.eye(4))
    with pytest.raises(ValueError, match="arm: unknown 'ur42'"):
        SP.arm_spec("ur42")
    with pytest.raises(ValueError, match="robot: the ur5 needs its imported model"):
        SP.load_robot(None, "ur5")
    y = SP.scene_yaml("p", {"start": np.array([0.1, 0.2]), "goal": np.array([0.3, 0.4]),
                            "objects": []}, ["panda_joint1", "panda_finger_joint1"])
    names = y["robot_state"]["joint_state"]["name"]
    assert names == ["panda_joint1", "panda_finger_joint1", "panda_finger_joint2"]
    assert y["robot_state"]["joint_state"]["position"][2] == 0.2
    assert [c["joint_name"] for c in y["goal_constraints"][0]["joint_constraints"]] == \
        ["panda_joint1"]
