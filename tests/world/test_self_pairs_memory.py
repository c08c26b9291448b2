"""Self-pair sampling in bounded memory (jwarp.world.self_pairs): the blocked, culled
computation against a brute-force numpy reference (every sphere pair of every sample), and
its peak memory measured with tracemalloc (numpy reports its buffers to it)."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

import jwarp
from jwarp.kinematics.fk import fk
from jwarp.model import Sphere
from jwarp.world.self_pairs import adjacent_pairs, never_colliding_pairs, pair_sampling_cost


def crowded(name: str, copies: int, seed: int = 0):
    """``name`` with every sphere replaced by ``copies`` jittered smaller ones."""
    robot = jwarp.robot(name)
    rng = np.random.default_rng(seed)
    spheres = [Sphere(frame=s.frame, radius=0.7 * s.radius,
                      position=np.asarray(s.position) + rng.normal(0, 0.3 * s.radius, 3))
               for s in robot.spheres for _ in range(copies)]
    return robot.copy(spheres=spheres)


def brute_force(robot, q, margin):
    """(min_distance, collision_rate) over all frame pairs with spheres: every sphere pair
    of every sample."""
    sf, sp, sr = robot.sphere_arrays()
    T = fk(robot, q, device="cpu", dtype=np.float64)
    nf = robot.n_frames
    per = np.full((len(q), nf, nf), np.inf)
    frames = np.unique(sf)
    for k in range(len(q)):
        Ts = T[k, sf]
        x = np.einsum("sij,sj->si", Ts[:, :3, :3], sp) + Ts[:, :3, 3]
        d = np.linalg.norm(x[:, None] - x[None], axis=-1) - sr[:, None] - sr[None]
        for a in frames:
            for b in frames:
                if a != b:
                    per[k, a, b] = d[sf == a][:, sf == b].min()
    rate = np.mean(per < margin, axis=0)
    np.fill_diagonal(rate, 0.0)
    return per.min(axis=0), rate


@pytest.mark.parametrize("name,copies,margin,max_memory", [
    ("arm7", 40, 0.0, 1_000_000),       # 560 spheres, up to 240 a frame: 1 MB gives tiles of
                                        # 125 spheres and FK batches of ~5
    ("justin19", 3, 0.02, 256_000_000),  # the default budget
])
def test_equals_brute_force(name, copies, margin, max_memory):
    robot = crowded(name, copies)
    got = never_colliding_pairs(robot, n_samples=60, seed=4, margin=margin, batch=25,
                                max_memory=max_memory)
    dmin, rate = brute_force(robot, got.samples, margin)
    if max_memory == 1_000_000:
        assert np.bincount(robot.sphere_arrays()[0]).max() > 125
    np.testing.assert_allclose(got.min_distance, dmin, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(got.collision_rate, rate)
    adj = set(adjacent_pairs(robot))
    frames = np.unique(robot.sphere_arrays()[0])
    tested = [(int(a), int(b)) for a in frames for b in frames if a < b and (a, b) not in adj]
    assert got.never_colliding == [p for p in tested if rate[p] == 0.0]
    assert got.always_colliding == [p for p in tested if rate[p] == 1.0]
    assert 0 < len(got.never_colliding) < len(tested)   # both kinds occur: a real check


def test_memory_is_bounded_at_many_spheres():
    robot = crowded("justin19", 14)          # 742 spheres: 742^2 x 3 doubles = 13 MB a sample
    cost = pair_sampling_cost(robot, 64, max_memory=16_000_000)
    assert cost.spheres == 742 and cost.memory <= 16_000_000
    counts = np.bincount(robot.sphere_arrays()[0])
    assert cost.sphere_pairs == (counts.sum() ** 2 - (counts ** 2).sum()) // 2
    assert cost.evaluations == cost.sphere_pairs * 64
    never_colliding_pairs(robot, n_samples=4, max_memory=16_000_000)   # warm (kernels)
    tracemalloc.start()
    try:
        got = never_colliding_pairs(robot, n_samples=64, seed=1, max_memory=16_000_000)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    # all sphere pairs of one 64-sample batch at once would take 64 x 13 MB = 845 MB
    assert peak < 24_000_000, peak
    assert len(got.never_colliding) > 0


def test_estimate_printed_and_bad_budget(capsys):
    never_colliding_pairs("arm7", n_samples=10, verbose=True)
    out = capsys.readouterr().out
    assert "self-pair sampling: 14 spheres" in out and "of memory" in out
    with pytest.raises(ValueError, match="max_memory"):
        never_colliding_pairs("arm7", n_samples=10, max_memory=1000)
    with pytest.raises(TypeError, match="max_memory"):
        pair_sampling_cost(jwarp.robot("arm7"), 10, max_memory=1e9)
