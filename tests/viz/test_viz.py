"""Rerun recordings: world-coordinate collision bodies and atomic .rrd files."""

from __future__ import annotations

import numpy as np
import pytest

import jwarp
from jwarp import kinematics
from jwarp.viz import robot as viz


def test_world_spheres_follow_their_frames():
    model = jwarp.robot("justin19")
    q = np.linspace(-0.3, 0.3, 19)
    frames = kinematics.fk(model, q, device="cpu", dtype=np.float64)
    centres, radii = viz.world_spheres(model, frames)
    idx, pos, rad = model.sphere_arrays()
    assert centres.shape == (53, 3) and np.array_equal(radii, rad)
    for k in (0, 17, 52):
        T = frames[idx[k]]
        np.testing.assert_allclose(centres[k], T[:3, :3] @ pos[k] + T[:3, 3], atol=1e-12)


def test_world_capsules():
    model = jwarp.robot("hand4")
    frames = kinematics.fk(model, np.zeros(model.n_dof), device="cpu", dtype=np.float64)
    p0, p1, r = viz.world_capsules(model, frames)
    assert p0.shape == p1.shape == (len(model.capsules), 3) and len(r) == len(model.capsules)
    c = model.capsules[0]
    T = frames[c.frame]
    np.testing.assert_allclose(p1[0], T[:3, :3] @ c.p1 + T[:3, 3], atol=1e-12)


def test_capsule_orientation_quaternions():
    rng = np.random.default_rng(0)
    d = rng.normal(size=(8, 3))
    d = np.vstack([d / np.linalg.norm(d, axis=1, keepdims=True), [[0, 0, 1], [0, 0, -1]]])
    q = viz._z_to(d)
    x, y, z, w = q.T
    # third column of the rotation matrix of (x, y, z, w) = image of +z
    col = np.stack([2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)], axis=1)
    np.testing.assert_allclose(col, d, atol=1e-12)


def test_frames_shape_is_checked():
    with pytest.raises(ValueError, match="frames: expected shape"):
        viz.world_spheres(jwarp.robot("justin19"), np.zeros((3, 4, 4)))


def test_save_robot_rrd(tmp_path):
    pytest.importorskip("rerun")
    target = tmp_path / "justin.rrd"
    q = np.zeros((3, 19))
    q[1, 3] = 0.5
    out = viz.save_robot_rrd("justin19", q, target, elastic_kappa=1e-4)
    assert out == target
    assert target.stat().st_size > 1000
    assert target.read_bytes()[:4] == b"RRF2"  # rerun's file magic
    assert [p.name for p in tmp_path.iterdir()] == ["justin.rrd"]  # no temp file left


def test_save_robot_rrd_overwrites_and_handles_capsules(tmp_path):
    pytest.importorskip("rerun")
    target = tmp_path / "hand.rrd"
    target.write_bytes(b"old")
    viz.save_robot_rrd("hand4", np.zeros(12), target)
    assert target.stat().st_size > 100
    assert [p.name for p in tmp_path.iterdir()] == ["hand.rrd"]


@pytest.mark.parametrize("q, message", [
    (np.zeros((2, 5)), "q_list: expected shape"),
    (np.full((1, 19), np.nan), "NaN"),
])
def test_save_robot_rrd_bad_input_leaves_nothing(tmp_path, q, message):
    pytest.importorskip("rerun")
    with pytest.raises(ValueError, match=message):
        viz.save_robot_rrd("justin19", q, tmp_path / "x.rrd")
    assert list(tmp_path.iterdir()) == []


def test_save_robot_rrd_missing_folder(tmp_path):
    pytest.importorskip("rerun")
    with pytest.raises(ValueError, match="does not exist"):
        viz.save_robot_rrd("justin19", np.zeros(19), tmp_path / "missing" / "x.rrd")
