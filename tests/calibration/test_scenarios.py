"""Built-in calibration campaigns (jwarp.calibration.simulate.scenarios) and the examples'
--quick runs. Observations are checked against plain-numpy re-computations (pinhole
projection, brute-force capsule distance, end-effector differences) on the true robot."""

from __future__ import annotations

import math
import os
import subprocess
import sys

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import jwarp
from jwarp.calibration.estimate.result import model_frames
from jwarp.calibration.files import make_measurement, read_samples, read_setup
from jwarp.calibration.simulate.campaign import simulate_campaign
from jwarp.calibration.simulate.scenarios import (
    available,
    contact_sampler,
    hand_contact_setup,
    look_at_head_joints,
    scenario,
)

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def test_available_and_unknown_combination():
    assert set(available()) == {("justin19", "cartesian"), ("justin19", "image"),
                                ("justin19", "relative"), ("hand4", "contact")}
    with pytest.raises(ValueError, match=r"justin19/cartesian.*hand4/contact"):
        scenario("hand4", "image")
    with pytest.raises(ValueError, match="robot, plugin"):
        scenario("justin19", "laser")


def test_cartesian_scenario_simulates():
    setup, sampler, accept = scenario("justin19", "cartesian")
    assert setup.plugin == "cartesian" and sampler is None and accept is None
    camp = simulate_campaign(jwarp.robot("justin19"), setup, 5, seed=0)
    assert camp.samples.y.shape == (5, 6) and np.all(np.isfinite(camp.samples.y))


def test_relative_scenario_is_tcp_difference_on_the_truth():
    robot = jwarp.robot("justin19")
    setup, sampler, accept = scenario("justin19", "relative")
    camp = simulate_campaign(robot, setup, 6, seed=2, noise=0.0, kappa=None)
    F = jwarp.fk(camp.true_robot, camp.samples.q, device="cpu", dtype="float64")
    d = F[:, robot.frame_index("right_tcp"), :3, 3] - F[:, robot.frame_index("left_tcp"), :3, 3]
    np.testing.assert_allclose(camp.samples.y, d, atol=1e-12)


def test_look_at_points_the_head_x_axis_at_the_target():
    robot = jwarp.robot("justin19")
    rng = np.random.default_rng(3)
    from jwarp.calibration.simulate.campaign import uniform_configurations

    q = uniform_configurations(robot, rng, 200)
    target = np.array([1.1, 0.0, 1.0]) + rng.uniform(-0.3, 0.3, (200, 3))
    hj = look_at_head_joints(robot, q, target, clip=False)
    lim = robot.joint_limits[[robot.joint_index("head_pan"), robot.joint_index("head_tilt")]]
    inside = np.all((hj > lim[:, 0]) & (hj < lim[:, 1]), axis=1)
    assert inside.sum() >= 10
    q = q[inside]
    q[:, [robot.joint_index("head_pan"), robot.joint_index("head_tilt")]] = hj[inside]
    F = jwarp.fk(robot, q, device="cpu", dtype="float64")
    T = F[:, robot.frame_index("head_tcp")]
    v = target[inside] - T[:, :3, 3]
    cos = np.einsum("si,si->s", T[:, :3, 0], v) / np.linalg.norm(v, axis=1)
    np.testing.assert_allclose(cos, 1.0, atol=1e-12)


def _project(section: dict, robot, frames: np.ndarray) -> np.ndarray:
    """Plain pinhole + distortion of eq. 2.40-2.41 from the setup dict: (S, K, 2) px and
    (S, K) depth."""
    cam = section["camera"]
    Tm = np.eye(4)
    Tm[:3, :3] = Rotation.from_rotvec(cam["rotvec"]).as_matrix()
    Tm[:3, 3] = cam["position"]
    Tc = frames[:, robot.frame_index(cam["frame"])] @ Tm
    intr = section["intrinsics"]
    f, c, xi = np.array(intr["focal"]), np.array(intr["center"]), intr["xi"]
    uv, z = [], []
    for mk in section["markers"]:
        x = np.append(mk["position"], 1.0)
        xw = x if mk["frame"] is None else frames[:, robot.frame_index(mk["frame"])] @ x
        xc = np.linalg.solve(Tc, np.broadcast_to(xw, (len(frames), 4))[..., None])[..., 0]
        n = xc[:, :2] / xc[:, 2:3]
        uv.append(c + f * n / (1 + xi * np.sum(n * n, axis=1, keepdims=True)))
        z.append(xc[:, 2])
    return np.stack(uv, axis=1), np.stack(z, axis=1)


def test_image_campaign_sees_every_marker_on_the_truth():
    robot = jwarp.robot("justin19")
    setup, sampler, accept = scenario("justin19", "image")
    assert setup.section["camera"]["frame"] == "head_tcp"
    assert len([m for m in setup.section["markers"] if m["frame"] is None]) >= 1
    camp = simulate_campaign(robot, setup, 12, seed=5, noise=0.0, sampler=sampler,
                             accept=accept)
    frames = model_frames(camp.true_robot, camp.samples.q)
    uv, z = _project(camp.true_setup.section, robot, frames)
    w, h = setup.section["intrinsics"]["size"]
    assert np.all(z > 0.2)
    assert np.all((uv[..., 0] >= 0) & (uv[..., 0] <= w) & (uv[..., 1] >= 0) & (uv[..., 1] <= h))
    np.testing.assert_allclose(camp.samples.y, uv.reshape(12, -1), atol=1e-7)
    truth = make_measurement(camp.true_robot, camp.true_setup)
    assert truth.visible(frames, camp.true_params).all()
    # the sampler alone (nominal robot): hands in front, head looking near them
    q, meta = sampler(np.random.default_rng(1), 40)
    assert meta == {} and 0 < len(q) <= 40
    lim = robot.joint_limits
    assert np.all((q >= lim[:, 0] - 1e-12) & (q <= lim[:, 1] + 1e-12))
    nom = make_measurement(robot, setup)
    vis = nom.visible(model_frames(robot, q, elastic=False), nom.params.nominal)
    assert vis.all(axis=1).mean() > 0.8


def _capsule_distance_brute(frames, robot, a: str, b: str, n: int = 401) -> np.ndarray:
    caps = {robot.frames[c.frame].name: c for c in robot.capsules}
    out = []
    pts = []
    for name in (a, b):
        c = caps[f"{name}_distal"]
        t = np.linspace(0, 1, n)[:, None]
        local = np.asarray(c.p0) + t * (np.asarray(c.p1) - np.asarray(c.p0))
        F = frames[:, c.frame]
        pts.append(np.einsum("sij,nj->sni", F[:, :3, :3], local) + F[:, None, :3, 3])
        out.append(c.radius)
    d = np.linalg.norm(pts[0][:, :, None] - pts[1][:, None], axis=-1).min(axis=(1, 2))
    return d - out[0] - out[1]


def test_contact_sampler_finds_nominal_contacts():
    robot = jwarp.robot("hand4")
    setup, sampler, accept = scenario("hand4", "contact")
    assert accept is None
    pairs = [tuple(p) for p in setup.section["pairs"]]
    assert pairs == [("thumb", "index"), ("thumb", "middle"), ("thumb", "ring")]
    q, meta = sampler(np.random.default_rng(0), 15)
    assert 10 <= len(q) <= 15 and set(np.unique(meta["pair"])) == {0, 1, 2}
    lim = robot.joint_limits
    assert np.all((q >= lim[:, 0] - 1e-12) & (q <= lim[:, 1] + 1e-12))
    F = jwarp.fk(robot, q, device="cpu", dtype="float64")
    for k, (a, b) in enumerate(pairs):
        m = meta["pair"] == k
        d = _capsule_distance_brute(F[m], robot, a, b)
        np.testing.assert_allclose(d, 0.0, atol=2e-6)


def test_contact_campaign_measures_the_true_distance():
    robot = jwarp.robot("hand4")
    setup = hand_contact_setup(pairs=(("thumb", "index"), ("index", "middle")))
    camp = simulate_campaign(robot, setup, 8, seed=3, noise=0.0, kappa=None,
                             sampler=contact_sampler(robot, setup))
    F = jwarp.fk(camp.true_robot, camp.samples.q, device="cpu", dtype="float64")
    pair = camp.samples.meta["pair"]
    d = np.empty(len(pair))
    for k, (a, b) in enumerate([("thumb", "index"), ("index", "middle")]):
        d[pair == k] = _capsule_distance_brute(F[pair == k], robot, a, b)
    np.testing.assert_allclose(camp.samples.y[:, 0], d, atol=2e-6)
    assert np.abs(d).max() > 1e-4      # the truth is not in contact where the nominal is
    with pytest.raises(ValueError, match="pairs: unknown finger 'pinky'"):
        hand_contact_setup(pairs=(("thumb", "pinky"),))


def test_cli_simulate_campaign_with_a_scenario(tmp_path, capsys):
    from jwarp.cli import main

    out = tmp_path / "img"
    assert main(["simulate-campaign", "--robot", "justin19", "--plugin", "image", "--samples",
                 "6", "--seed", "1", "--out", str(out)]) == 0
    capsys.readouterr()
    setup = read_setup(out / "setup.json")
    robot = jwarp.robot("justin19")
    s = read_samples(out / "samples.csv", robot, make_measurement(robot, setup))
    assert s.y.shape == (6, 10)


def _run_example(script, *args):
    env = dict(os.environ, PYTHONWARNINGS="ignore")
    return subprocess.run([sys.executable, os.path.join(ROOT, "examples", script), *args],
                          capture_output=True, text=True, timeout=120, env=env, cwd=ROOT)


@pytest.mark.parametrize("script, expect", [
    ("calibrate_justin_tracker.py", ["Table I ladder", "+kappa_alpha (full)",
                                     "check: ladder falls monotonically",
                                     "check: mean test error vs noise-free truth",
                                     "check: mean test error vs measured rows",
                                     "noise floor = mean norm of 3-D Gaussian noise"]),
    ("calibrate_justin_camera.py", ["Table 2.3 (simulated)", "full + intrinsics",
                                    "check: freeing the intrinsics lowers the test error",
                                    "check: mean test error vs noise-free truth",
                                    "check: mean test error vs measured rows",
                                    "noise floor = mean norm of 2-D Gaussian noise"]),
    ("calibrate_hand_contact.py", ["contact paper Table I (simulated)", "full DH",
                                   "check: nominal > joint offsets > full DH",
                                   "check: mean test error vs noise-free truth",
                                   "check: mean test error vs measured rows",
                                   "noise floor = mean norm of 1-D Gaussian noise"]),
])
def test_example_quick(script, expect):
    """--quick: exit status 0, the table, the floor line and every check line PASS."""
    r = _run_example(script, "--quick")
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    for text in expect:
        assert text in r.stdout, r.stdout
    checks = [ln for ln in r.stdout.splitlines() if ln.startswith("check: ")]
    assert len(checks) == 3 and all(ln.endswith("  PASS") for ln in checks), r.stdout
    assert "checks: 3 of 3 passed" in r.stdout
    assert "mean" in r.stdout and "paper" in r.stdout
    assert not math.isnan(float(r.stdout.split("total ")[-1].split(" s")[0]))


def test_example_failed_check_exits_1():
    """One solver evaluation per row leaves the full DH model at the nominal one: the
    accuracy checks fail, are printed as FAIL and the example exits with status 1."""
    r = _run_example("calibrate_hand_contact.py", "--quick", "--max-nfev", "1")
    assert r.returncode == 1, r.stdout[-2000:] + r.stderr[-2000:]
    fails = [ln for ln in r.stdout.splitlines()
             if ln.startswith("check: ") and ln.endswith("  FAIL")]
    assert any("vs noise-free truth" in ln for ln in fails), r.stdout
    assert "FAILED, exit status 1" in r.stdout


def test_report_checks_status(capsys):
    sys.path.insert(0, os.path.join(ROOT, "examples"))
    try:
        from calib_common import Check, noise_floor, report_checks
    finally:
        sys.path.remove(os.path.join(ROOT, "examples"))
    assert report_checks([Check("a 1 <= 2", True), Check("b 3 <= 2", False)]) == 1
    out = capsys.readouterr().out
    assert "check: a 1 <= 2  PASS" in out and "check: b 3 <= 2  FAIL" in out
    assert report_checks([Check("a", True)]) == 0
    # E|noise| of d-dim Gaussian noise vs a Monte-Carlo estimate
    rng = np.random.default_rng(0)
    for d, expect in ((1, 0.798), (2, 1.253), (3, 1.596)):
        assert noise_floor(d, 2.0) == pytest.approx(2 * expect, rel=1e-3)
        mc = np.linalg.norm(rng.standard_normal((200000, d)), axis=1).mean()
        assert noise_floor(d, 1.0) == pytest.approx(mc, rel=1e-2)
