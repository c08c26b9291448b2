"""Self-collision pairs from random configurations (jwarp.world.self_pairs), checked against
the collision kernel's own sphere-pair distances (jwarp.world.collision.self_distances) on
a copy of the robot with every frame pair allowed."""

from __future__ import annotations

import numpy as np
import pytest

import jwarp
from jwarp.model import RobotModel, SelfCollision
from jwarp.world.collision import collision_pairs, self_distances
from jwarp.world.self_pairs import (
    adjacent_pairs,
    never_colliding_pairs,
    rigid_groups,
    with_self_pairs,
    write_self_pairs,
)


@pytest.fixture(scope="module")
def justin():
    robot = jwarp.robot("justin19")
    return robot, never_colliding_pairs(robot, n_samples=400, seed=5, margin=0.01)


def test_adjacent_pairs_arm7():
    robot = jwarp.robot("arm7")
    adj = set(adjacent_pairs(robot))
    parents = robot.parents
    for f in range(robot.n_frames):  # every joint's parent and child
        if parents[f] >= 0:
            assert (int(parents[f]), f) in adj
    # right_tcp is fixed to right_7: one rigid body, so right_6 is adjacent to both
    g = rigid_groups(robot)
    tcp, l7, l6 = (robot.frame_index(n) for n in ("right_tcp", "right_7", "right_6"))
    assert g[tcp] == g[l7] and g[l6] != g[l7]
    assert (l6, tcp) in adj and (l6, l7) in adj
    assert (0, 2) not in adj and (0, tcp) not in adj
    pairs = never_colliding_pairs(robot, n_samples=200, seed=1)
    assert set(pairs.adjacent) <= set(pairs.exclude_pairs)


def test_pairs_agree_with_collision_kernel(justin):
    robot, pairs = justin
    margin = pairs.margin
    everything = robot.copy(self_collision=SelfCollision())
    d = np.asarray(self_distances(everything, pairs.samples, device="cpu", dtype=np.float64))
    sf = robot.sphere_arrays()[0]
    sp = collision_pairs(everything)
    fa, fb = np.minimum(sf[sp[:, 0]], sf[sp[:, 1]]), np.maximum(sf[sp[:, 0]], sf[sp[:, 1]])
    checked = kept = never = 0
    adjacent = set(pairs.adjacent)
    for a, b in sorted(set(zip(fa.tolist(), fb.tolist()))):
        sel = (fa == a) & (fb == b)
        per_sample = d[:, sel].min(axis=1)
        np.testing.assert_allclose(pairs.min_distance[a, b], per_sample.min(), atol=1e-9)
        rate = np.mean(per_sample < margin)
        assert pairs.collision_rate[a, b] == pytest.approx(rate)
        if (a, b) in adjacent:
            continue
        checked += 1
        if (a, b) in pairs.never_colliding:
            assert np.all(per_sample >= margin)
            never += 1
        elif (a, b) in pairs.always_colliding:
            assert np.all(per_sample < margin)
        else:  # kept: it does collide in some sampled configuration
            assert (a, b) not in pairs.exclude_pairs and np.any(per_sample < margin)
            kept += 1
    assert checked > 20 and kept > 10 and never >= 1


def test_reproducible_by_seed(justin):
    robot, pairs = justin
    again = never_colliding_pairs(robot, n_samples=400, seed=5, margin=0.01, batch=97)
    assert again.exclude_pairs == pairs.exclude_pairs
    np.testing.assert_array_equal(again.samples, pairs.samples)
    np.testing.assert_allclose(again.min_distance, pairs.min_distance, atol=1e-12)
    other = never_colliding_pairs(robot, n_samples=400, seed=6, margin=0.01)
    assert not np.array_equal(other.samples, pairs.samples)
    lim = robot.joint_limits
    assert np.all((pairs.samples >= lim[:, 0]) & (pairs.samples <= lim[:, 1]))


def test_written_into_self_collision(justin, tmp_path):
    robot, pairs = justin
    out = tmp_path / "justin_pairs.json"
    model = write_self_pairs(robot, out, pairs)
    loaded = RobotModel.load(out)
    excluded = np.zeros((robot.n_frames,) * 2, bool)
    for a, b in pairs.exclude_pairs:
        excluded[a, b] = excluded[b, a] = True
    np.fill_diagonal(excluded, True)
    np.testing.assert_array_equal(loaded.allowed_collision_pairs, ~excluded)
    np.testing.assert_array_equal(model.allowed_collision_pairs, ~excluded)
    assert "never" in loaded.notes["self_collision"]
    # the planner's self-collision pairs are those of the kept frame pairs only
    sf = robot.sphere_arrays()[0]
    for i, j in collision_pairs(loaded):
        assert not excluded[sf[i], sf[j]]
    # merge mode keeps the hand-written groups and adds the exclusions
    merged = with_self_pairs(robot, pairs, replace=False)
    assert merged.self_collision.groups == robot.self_collision.groups
    assert not np.any(merged.allowed_collision_pairs & excluded)


def test_bad_arguments(tmp_path):
    with pytest.raises(ValueError, match="n_samples"):
        never_colliding_pairs("arm7", n_samples=0)
    with pytest.raises(ValueError, match="margin"):
        never_colliding_pairs("arm7", n_samples=10, margin=float("nan"))
    with pytest.raises(TypeError, match="seed"):
        never_colliding_pairs("arm7", n_samples=10, seed=1.5)
    bare = jwarp.robot("arm7").copy(spheres=[])
    with pytest.raises(ValueError, match="spheres"):
        never_colliding_pairs(bare, n_samples=10)
    with pytest.raises(ValueError, match="out"):
        write_self_pairs("arm7", tmp_path / "missing" / "x.json", n_samples=10)
    with pytest.raises(TypeError, match="pairs"):
        with_self_pairs("arm7", [(0, 1)])
