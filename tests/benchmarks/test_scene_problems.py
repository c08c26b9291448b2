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
