"""Feasible candidate pools of experimental design (jwarp.calibration.pool):
the kept configurations are free of self- and world collision, and the dropped counts
equal an independent count (numpy sphere distances from jwarp's FK) on the raw draws."""

import dataclasses
import warnings

import numpy as np
import pytest
from pool_helpers import ball_colliding, in_limits, self_colliding

from jwarp.calibration.design.optimal import DesignOptions, design
from jwarp.calibration.files import Setup, make_measurement
from jwarp.calibration.pool import REASONS, check_configurations, draw_configurations, draw_pool
from jwarp.calibration.simulate.campaign import justin_tracker_setup
from jwarp.calibration.simulate.scenarios import hand_contact_setup
from jwarp.plugins.registry import robot as get_robot
from jwarp.world import World

SELF, WORLD = REASONS.index("self_collision"), REASONS.index("world_collision")


@pytest.fixture(scope="module")
def justin():
    return get_robot("justin19")


def test_justin_pool_is_free_and_counts_its_drops(justin):
    setup = justin_tracker_setup()
    pool = draw_pool(justin, setup, 150, seed=3)
    assert pool.complete and len(pool) == 150 and pool.self_checked and not pool.world_checked
    assert not self_colliding(justin, pool.q).any() and in_limits(justin, pool.q).all()
    raw = np.concatenate([pool.q, pool.rejected_q])
    assert pool.drawn == len(raw)
    coll = self_colliding(justin, raw)
    assert pool.dropped["self_collision"] == int(coll.sum()) > 0
    assert np.all(pool.rejected_reason == SELF) and self_colliding(justin, pool.rejected_q).all()
    assert sum(pool.dropped.values()) == pool.drawn - len(pool)
    # the same seed draws the same pool; a design chosen from it is free by construction
    again = draw_pool(justin, setup, 150, seed=3)
    assert np.array_equal(again.q, pool.q)
    res = design(justin, make_measurement(justin, setup), pool.q,
                 DesignOptions(n=12, method="detmax"), free="theta,d,r,alpha")
    plan = pool.q[res.indices]
    assert len(plan) == 12 and not self_colliding(justin, plan).any()


def test_margin_and_world(justin):
    centre, radius, margin = (0.55, 0.0, 1.0), 0.3, 0.02
    world = World.of_shapes()
    world.add("ball", "sphere", [radius], centre)
    pool = draw_pool(justin, justin_tracker_setup(), 80, seed=5, world=world, margin=margin)
    assert pool.complete and pool.world_checked
    assert not self_colliding(justin, pool.q, margin).any()
    assert not ball_colliding(justin, pool.q, centre, radius, margin).any()
    raw = np.concatenate([pool.q, pool.rejected_q])
    s = self_colliding(justin, raw, margin)
    w = ball_colliding(justin, raw, centre, radius, margin) & ~s
    assert pool.dropped["self_collision"] == int(s.sum()) > 0
    assert pool.dropped["world_collision"] == int(w.sum()) > 0
    assert np.array_equal(pool.rejected_reason == WORLD, w[len(pool):])
    # check_configurations on the raw draws gives the same verdicts
    chk = check_configurations(justin, raw, justin_tracker_setup(), world=world, margin=margin)
    assert np.array_equal(chk.keep, ~(s | w))


def test_contact_pool_leaves_the_contact_bodies_out():
    hand = get_robot("hand4")
    setup = hand_contact_setup()
    pool = draw_pool(hand, setup, 60, seed=0)
    assert pool.complete and set(pool.meta) == {"pair"} and len(pool.meta["pair"]) == 60
    frames = [b.frame for b in make_measurement(hand, setup).bodies.values()]
    assert not self_colliding(hand, pool.q, skip_frames=frames).any()
    raw = np.concatenate([pool.q, pool.rejected_q])
    assert pool.dropped["self_collision"] == int(self_colliding(hand, raw,
                                                                skip_frames=frames).sum())
    assert len(pool.rejected_meta["pair"]) == len(pool.rejected_q)


def test_robot_without_spheres_warns():
    bare = dataclasses.replace(get_robot("arm7"), spheres=[], name="arm7_bare")
    setup = Setup(plugin="relative", robot=None,
                  section={"end_effectors": ["right_tcp", "right_4"]})
    pool = draw_pool(bare, setup, 20, seed=0)
    assert len(pool) == 20 and pool.drawn == 20 and not pool.self_checked
    assert any("NOT checked" in w for w in pool.warnings)
    assert "NONE" in pool.summary()
    with pytest.warns(UserWarning, match="no collision spheres"):
        q, meta = draw_configurations(bare, setup, 20, seed=0)
    assert np.array_equal(q, pool.q) and meta == {}


def test_short_pool_says_so(justin):
    pool = draw_pool(justin, justin_tracker_setup(), 30, seed=0, margin=0.5, max_draws=60)
    assert not pool.complete and len(pool) < 30 and pool.drawn == 60
    assert any(w.startswith(f"only {len(pool)} of 30") for w in pool.warnings)
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        draw_configurations(justin, justin_tracker_setup(), 5, seed=0, margin=0.0)
    assert not rec      # a complete, checked pool warns nothing


@pytest.mark.parametrize("kw, err, match", [
    ({"margin": -0.1}, ValueError, "margin: expected a distance in"),
    ({"margin": "x"}, TypeError, "margin: expected a distance"),
    ({"max_draws": 3}, ValueError, "max_draws: expected an integer >= n"),
    ({"world": "shelf"}, TypeError, "world: expected a jwarp.world.World"),
])
def test_pool_errors(justin, kw, err, match):
    with pytest.raises(err, match=match):
        draw_pool(justin, justin_tracker_setup(), 10, seed=0, **kw)
    with pytest.raises(ValueError, match="n: expected an integer >= 1"):
        draw_pool(justin, justin_tracker_setup(), 0, seed=0)
