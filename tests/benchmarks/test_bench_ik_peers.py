"""benchmarks/ik_peers.py (the peers of ``bench_ik.py --peers``): its common float64 check
against known pose offsets and joint-limit violations, its rotation-to-quaternion conversion
against scipy's, its choice of seed; and the ``--only peers --quick`` run (the peers that are
not installed print "not installed"; the numbers themselves are not checked)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))

import ik_peers as K  # noqa: E402


def _rot(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rodrigues' rotation (the test's own)."""
    k = np.asarray(axis, float) / np.linalg.norm(axis)
    Kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * Kx + (1 - np.cos(angle)) * Kx @ Kx


@pytest.fixture(scope="module")
def panda():
    try:
        return K.panda()
    except ValueError as e:  # example-robot-data missing
        pytest.skip(str(e))


@pytest.mark.parametrize("use_pinocchio", [True, False])
def test_check_measures_known_offsets(panda, use_pinocchio):
    urdf, model = panda
    check = K.PoseCheck(urdf, model, 1e-3, 1e-2, use_pinocchio=use_pinocchio)
    T, q, _ = K.problem(model, 6, 1, seed=3)
    q7 = q[:, K.arm_columns(model)]
    exact = check(q7, T)
    assert exact.solved.all() and exact.pos_err.max() < 1e-12 and exact.rot_err.max() < 1e-7
    rng = np.random.default_rng(0)
    d = rng.uniform(1e-4, 5e-3, len(T))           # position offsets [m]
    a = rng.uniform(1e-3, 3.0, len(T))            # rotation offsets [rad]
    Tm = T.copy()
    for i in range(len(T)):
        u = rng.normal(size=3)
        Tm[i, :3, 3] += d[i] * u / np.linalg.norm(u)
        Tm[i, :3, :3] = T[i, :3, :3] @ _rot(rng.normal(size=3), a[i])
    c = check(q7, Tm)
    np.testing.assert_allclose(c.pos_err, d, rtol=1e-9)
    np.testing.assert_allclose(c.rot_err, a, rtol=1e-7)
    np.testing.assert_array_equal(c.solved, (d <= 1e-3) & (a <= 1e-2))


def test_check_joint_limits_and_nan(panda):
    urdf, model = panda
    check = K.PoseCheck(urdf, model, 1e-3, 1e-2)
    lo, hi = model.joint_limits[K.arm_columns(model)].T
    q7 = np.stack([lo, hi, lo - 1e-10, hi + 1e-6, np.full(7, np.nan)])
    q7[2, 1:] = (lo[1:] + hi[1:]) / 2
    T = check.fk(np.where(np.isfinite(q7), q7, 0.0))
    c = check(q7, T)
    np.testing.assert_array_equal(c.in_limits, [True, True, True, False, False])
    np.testing.assert_array_equal(c.solved, [True, True, True, False, False])


def test_pick_best_prefers_a_solved_seed(panda):
    urdf, model = panda
    check = K.PoseCheck(urdf, model, 1e-3, 1e-2)
    T, q, _ = K.problem(model, 2, 1, seed=5)
    q7 = q[:, K.arm_columns(model)]
    out = q7.copy()
    out[:, 0] += 2 * np.pi  # the exact pose, outside joint 1's limits (+-2.9): not solved
    near = q7 + 1e-5          # within tolerance, solved
    far = q7 + 0.3
    both = np.stack([np.stack([out[0], far[0], near[0]]), np.stack([far[1], out[1], far[1]])])
    best = K.pick_best(check, both, T)
    np.testing.assert_array_equal(best[0], near[0])  # solved beats the smaller error
    np.testing.assert_array_equal(best[1], out[1])   # no solved seed: the smallest error


def test_quaternion_matches_scipy():
    Rotation = pytest.importorskip("scipy.spatial.transform").Rotation
    R = Rotation.random(200, random_state=2).as_matrix()
    R[:4] = [np.eye(3), _rot([1, 0, 0], np.pi), _rot([0, 1, 0], np.pi), _rot([0, 0, 1], np.pi)]
    q = K.matrix_to_quat_xyzw(R)
    ref = Rotation.from_matrix(R).as_quat()  # x, y, z, w
    np.testing.assert_allclose(np.abs(np.sum(q * ref, 1)), 1.0, atol=1e-12)


def test_bench_ik_peers_quick_cpu(run_bench):
    stdout, doc = run_bench("bench_ik.py", "--only", "peers", "--quick", "--device", "cpu")
    sec = doc["peers"]
    assert "| targets | library | solved targets/s | solved |" in stdout
    assert sec["frame_check_max_abs_diff"]["jwarp"] < 1e-9
    libs = [r["library"] for r in sec["rows"]]
    assert libs[0].startswith("jwarp IKSolver") and all(r["targets"] == 8 for r in sec["rows"])
    for r in sec["rows"]:
        assert r["solved_targets_per_s"]["median"] >= 0 and 0 <= r["solved_rate"]["median"] <= 1
        assert r["solved_rate"]["median"] <= r["pose_only_rate"]["median"] <= 1
    assert sec["rows"][0]["solved_rate"]["median"] > 0
    for lib, prefix in (("newton", "Newton"), ("pytorch_kinematics", "pytorch_kinematics")):
        if sec[lib] == "not installed":
            assert f"| | {lib} | not installed |" in stdout
        else:
            assert any(n.startswith(prefix) for n in libs), libs
