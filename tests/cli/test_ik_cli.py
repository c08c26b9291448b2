"""``jwarp ik`` options (issue 26 item 3): ``--scene``, ``--initial``, ``--tol-pos``/``--tol-rot``,
the target formats (``--quat``, ``--rpy``, ``--target-matrix``), ``--position-only`` and
``--free-axis``, the reason of an infeasible answer, ``--elastic``'s own help, and the errors
(one line naming the option). arm7 in-process; every answer is checked against the host FK
(:func:`jwarp.core.device.host_frames`, numpy, not the solver's kernels)."""

from __future__ import annotations

import json
import math
import re

import numpy as np
import pytest
import yaml
from cli_helpers import one_line_error, q_text, run
from scipy.spatial.transform import Rotation

import jwarp
from jwarp.core.device import host_frames
from jwarp.viz import world_spheres

ARM = jwarp.robot("arm7")
FRAME = "right_tcp"
FI = ARM.frame_index(FRAME)
Q0 = np.array([0.3, 1.0, 0.2, 1.0, -0.4, 0.5, 0.1])
BASE = ["ik", "--robot", "arm7", "--frame", FRAME]



def pose(q):
    return host_frames(ARM, np.asarray(q)[None])[0, FI]


def target_text(T) -> str:
    """x,y,z,rx,ry,rz of a pose (scipy rotation vector)."""
    return q_text(np.r_[T[:3, 3], Rotation.from_matrix(T[:3, :3]).as_rotvec()])


def solve(capsys, argv, code=None):
    c, out, err = run(capsys, BASE + [str(a) for a in argv] + ["--json"])
    assert c in (0, 1), err
    if code is not None:
        assert c == code, (out, err)
    res = json.loads(out)
    assert c == (0 if res["feasible"] else 1)
    return res


def pose_error(q, T):
    X = pose(q)
    rot = Rotation.from_matrix(T[:3, :3] @ X[:3, :3].T).magnitude()
    return float(np.linalg.norm(T[:3, 3] - X[:3, 3])), float(rot)


# ------------------------------------------------------------------ target formats
def test_every_target_format_gives_the_same_pose(capsys):
    """--target with a rotation vector, --quat, --rpy and --target-matrix (16 numbers and a
    file): the same target matrix in the JSON and a solution on it."""
    T = pose(Q0)
    r = Rotation.from_matrix(T[:3, :3])
    xyz = q_text(T[:3, 3])
    forms = [["--target", target_text(T)],
             ["--target", xyz, "--quat", q_text(r.as_quat())],
             ["--target", xyz, "--rpy", q_text(r.as_euler("xyz"))],
             ["--target-matrix", " ".join(repr(float(v)) for v in T.ravel())]]
    for form in forms:
        res = solve(capsys, form + ["--starts", 4], code=0)
        np.testing.assert_allclose(res["target"], T, atol=1e-12)
        pos, rot = pose_error(res["q"], T)
        assert pos < 1e-4 and rot < 1e-3 and res["reason"] == "feasible"


def test_target_matrix_file(capsys, tmp_path):
    T = pose(Q0)
    f = tmp_path / "T.txt"
    np.savetxt(f, T)
    res = solve(capsys, ["--target-matrix", f, "--starts", 4], code=0)
    np.testing.assert_allclose(res["target"], T, atol=1e-12)


def test_target_errors(capsys):
    T = pose(Q0)
    xyz = q_text(T[:3, 3])
    one_line_error(capsys, BASE + ["--target", xyz, "--quat", "0,0,0,0"], "--quat")
    line = one_line_error(capsys, BASE + ["--target", target_text(T), "--quat", "0,0,0,1"],
                          "--quat")
    assert "--target" in line
    line = one_line_error(capsys, BASE + ["--target", target_text(T), "--rpy", "0,0,1"], "--rpy")
    assert "--target" in line
    one_line_error(capsys, BASE + ["--target", xyz, "--quat", "0,0,0,1", "--rpy", "0,0,1"],
                   "--quat")
    eye = " ".join(map(str, np.eye(4).ravel()))
    line = one_line_error(capsys, BASE + ["--target", xyz, "--target-matrix", eye],
                          "--target-matrix")
    assert "--target" in line
    S = np.eye(4)
    S[:3, :3] *= 1.001
    one_line_error(capsys, BASE + ["--target-matrix", " ".join(map(str, S.ravel()))],
                   "--target-matrix")
    one_line_error(capsys, BASE, "--target")
    one_line_error(capsys, BASE + ["--target", "1,2"], "--target")


# ------------------------------------------------------------------ --initial
def test_initial_is_the_first_seed(capsys):
    """With no iterations the answer is the first seed as given: --initial itself (also in
    degrees with --deg); from it the solver needs no other seed."""
    T = pose(Q0)
    res = solve(capsys, ["--target", target_text(T), "--initial", q_text(Q0), "--starts", 1,
                         "--iterations", 0], code=0)
    np.testing.assert_allclose(res["q"], Q0, atol=1e-12)
    np.testing.assert_allclose(res["initial"], Q0)
    assert res["start_index"] == 0 and res["iterations"] == 0
    res = solve(capsys, ["--target", target_text(T), "--initial", q_text(np.degrees(Q0)),
                         "--deg", "--starts", 1, "--iterations", 0], code=0)
    np.testing.assert_allclose(res["q"], Q0, atol=1e-12)
    # a nearby initial guess and random seeds after it: the first seed wins in few steps
    q1 = Q0 + 0.05
    res = solve(capsys, ["--target", target_text(T), "--initial", q_text(q1), "--starts", 3],
                code=0)
    assert res["start_index"] == 0
    assert np.abs(np.array(res["q"]) - Q0).max() < 0.2


def test_initial_errors(capsys):
    T = target_text(pose(Q0))
    line = one_line_error(capsys, BASE + ["--target", T, "--initial", "0,0,0"], "--initial")
    assert "7 joints" in line
    one_line_error(capsys, BASE + ["--target", T, "--initial", "0,0,0,x,0,0,0"], "--initial")
    one_line_error(capsys, BASE + ["--target", T, "--initial", "0,0,0,nan,0,0,0"], "--initial")
    q = Q0.copy()
    q[1] = ARM.joint_limits[1, 1] + 0.1
    line = one_line_error(capsys, BASE + ["--target", T, "--initial", q_text(q)], "--initial")
    assert "right_2" in line and "limits" in line


# ------------------------------------------------------------------ tolerances and reasons
def test_tolerances_reach_the_solver_and_the_reason(capsys):
    """From --initial exactly 5 mm / 0.6 deg off the target, no iterations: feasible only
    within the given tolerances; otherwise the reason quotes the closed-form errors."""
    T = pose(Q0)
    off = T.copy()
    off[:3, 3] += [0.0, 0.003, 0.004]                     # 5 mm
    argv = ["--target", target_text(off), "--initial", q_text(Q0), "--starts", 1,
            "--iterations", 0]
    res = solve(capsys, argv, code=1)
    m = re.search(r"position error ([0-9.]+) mm \(>= tol 0.1 mm\)", res["reason"])
    assert m and float(m.group(1)) == pytest.approx(5.0, rel=1e-5), res["reason"]
    res = solve(capsys, argv + ["--tol-pos", 0.0051], code=0)
    assert res["tol_pos_m"] == 0.0051
    # rotation: 0.6 deg about x
    rot = T.copy()
    rot[:3, :3] = Rotation.from_rotvec([math.radians(0.6), 0, 0]).as_matrix() @ T[:3, :3]
    argv = ["--target", target_text(rot), "--initial", q_text(Q0), "--starts", 1,
            "--iterations", 0]
    res = solve(capsys, argv, code=1)
    m = re.search(r"rotation error ([0-9.]+) deg", res["reason"])
    assert m and float(m.group(1)) == pytest.approx(0.6, rel=1e-4), res["reason"]
    solve(capsys, argv + ["--tol-rot", math.radians(0.61)], code=0)
    # the text output says why
    code, out, _ = run(capsys, BASE + argv)
    assert code == 1 and re.search(r"^why: pose not reached: ", out, re.M), out


def test_tolerance_errors(capsys):
    T = target_text(pose(Q0))
    for bad in ("0", "-1e-3", "nan", "inf", "x"):
        one_line_error(capsys, BASE + ["--target", T, f"--tol-pos={bad}"], "--tol-pos")
        one_line_error(capsys, BASE + ["--target", T, f"--tol-rot={bad}"], "--tol-rot")


# ------------------------------------------------------------------ scenes
SCENE_FAR = {"format": "jwarp.scene", "objects": [
    {"id": "post", "type": "box", "size": [0.1, 0.1, 0.5], "pose": {"position": [2, 2, 0.25]}}]}


def scene_at_sphere(tmp_path, q, s=6, half=0.08):
    """A scene with a box of half size ``half`` centred at sphere s of arm7 at q."""
    c, r = world_spheres(ARM, host_frames(ARM, q[None])[0])
    data = {"format": "jwarp.scene", "objects": [
        {"id": "crate", "type": "box", "size": [2 * half] * 3,
         "pose": {"position": c[s].tolist()}}]}
    path = tmp_path / "crate.yaml"
    path.write_text(yaml.safe_dump(data))
    return path, r[s]


def test_scene_solves_and_names_the_colliding_pair(capsys, tmp_path):
    T = pose(Q0)
    far = tmp_path / "far.yaml"
    far.write_text(yaml.safe_dump(SCENE_FAR))
    res = solve(capsys, ["--target", target_text(T), "--scene", far, "--starts", 4], code=0)
    assert res["world"] == str(far)
    # the initial guess inside a box: with no iterations the reason names link and object
    path, r = scene_at_sphere(tmp_path, Q0)
    res = solve(capsys, ["--target", target_text(T), "--scene", path, "--initial", q_text(Q0),
                         "--starts", 1, "--iterations", 0], code=1)
    link = ARM.frames[ARM.spheres[6].frame].name
    m = re.search(rf"collision: link '{link}' vs object 'crate', distance (-?[0-9.]+) mm",
                  res["reason"])
    assert m, res["reason"]
    assert float(m.group(1)) == pytest.approx(-(0.08 + r) * 1e3, abs=0.006)
    # a grid of the scene (--voxel) counts too
    res = solve(capsys, ["--target", target_text(T), "--scene", path, "--voxel", 0.02,
                         "--initial", q_text(Q0), "--starts", 1, "--iterations", 0], code=1)
    assert f"collision: link '{link}' vs " in res["reason"], res["reason"]


def test_scene_errors(capsys, tmp_path):
    T = target_text(pose(Q0))
    far = tmp_path / "far.yaml"
    far.write_text(yaml.safe_dump(SCENE_FAR))
    line = one_line_error(capsys, BASE + ["--target", T, "--scene", far, "--world", "shelf"],
                          "--world")
    assert "--scene" in line
    one_line_error(capsys, BASE + ["--target", T, "--scene", tmp_path / "none.yaml"], "--scene")
    one_line_error(capsys, BASE + ["--target", T, "--world", "shelf", "--voxel", 0.02], "--voxel")


# ------------------------------------------------------------------ orientation modes
def test_orientation_mode_errors(capsys):
    T = pose(Q0)
    line = one_line_error(capsys, BASE + ["--target", target_text(T), "--position-only"],
                          "--position-only")
    assert "--target" in line
    line = one_line_error(capsys, BASE + ["--target", q_text(T[:3, 3]), "--position-only",
                                          "--free-axis", "0,0,1"], "--free-axis")
    assert "--position-only" in line
    one_line_error(capsys, BASE + ["--target", q_text(T[:3, 3]), "--free-axis", "0,0,0"],
                   "--free-axis")
    one_line_error(capsys, BASE + ["--target", q_text(T[:3, 3]), "--free-axis", "1,x,0"],
                   "--free-axis")


def test_position_only(capsys):
    T = pose(Q0)
    res = solve(capsys, ["--target", q_text(T[:3, 3]), "--position-only", "--starts", 4],
                code=0)
    assert res["orientation"] == "none"
    pos, _ = pose_error(res["q"], T)
    assert pos < 1e-4


def test_free_axis(capsys):
    """The target turned 1 rad about the tool's z axis: with --free-axis 0,0,1 the answer
    holds the target's z axis (any rotation about it), not necessarily its x axis."""
    T = pose(Q0)
    spun = T.copy()
    spun[:3, :3] = T[:3, :3] @ Rotation.from_rotvec([0, 0, 1.0]).as_matrix()
    res = solve(capsys, ["--target", target_text(spun), "--free-axis", "0,0,1", "--starts", 4],
                code=0)
    assert res["orientation"] == "axis" and res["free_axis"] == [0.0, 0.0, 1.0]
    X = pose(res["q"])
    assert np.linalg.norm(X[:3, 3] - spun[:3, 3]) < 1e-4
    assert math.acos(min(1.0, float(X[:3, 2] @ spun[:3, 2]))) < 1e-3


# ------------------------------------------------------------------ help
def test_elastic_help_is_the_commands_own(capsys):
    _, ik_help, _ = run(capsys, ["ik", "--help"])
    _, plan_help, _ = run(capsys, ["plan", "--help"])
    flat = " ".join(ik_help.split())
    assert "solve on the elastic model" in flat and "plan on the elastic model" not in flat
    assert "plan on the elastic model" in " ".join(plan_help.split())
    for option in ("--scene", "--initial", "--tol-pos", "--tol-rot", "--quat", "--rpy",
                   "--target-matrix", "--position-only", "--free-axis"):
        assert option in ik_help
