"""Distinct world seeds give distinct worlds (issue "Learning, part 2 again", item 0).

The old rule tried seed, seed + 1, ... until a world passed the 200/1000 filter, so
consecutive seeds collapsed onto one world (planar4 seeds 0..11: 3 distinct worlds). Now
each requested seed falls back onto candidates of its own stream; path databases refuse a
world whose grid is already stored, and the train/validation split is by content."""

from __future__ import annotations

import numpy as np
import pytest

import jwarp
from jwarp.learn.dataset import DuplicateWorldError, PathDB, record_hash, world_record
from jwarp.learn.plan_data import world_for
from jwarp.learn.train_plan import PlanSamples, split_by_world
from jwarp.world.feasibility import world_seed_candidates
from jwarp.world.sdf import World


def test_consecutive_seeds_give_distinct_worlds():
    worlds = [world_for(jwarp.robot("planar4"), s) for s in range(12)]
    hashes = {w.content_hash() for w in worlds}
    assert len(hashes) == 12  # was 3
    assert [w.meta["requested_seed"] for w in worlds] == list(range(12))
    # deterministic: the same seed gives the same world
    assert world_for(jwarp.robot("planar4"), 5).content_hash() == worlds[5].content_hash()


def test_a_passing_seed_keeps_its_world():
    """A seed whose own world passes the filter is that world (as before the fix)."""
    w = world_for(jwarp.robot("planar4"), 2)
    assert w.meta["candidate"] == 0 and w.meta["seed"] == 2
    again = world_for(jwarp.robot("planar4"), 2)
    assert np.array_equal(again.occupancy, w.occupancy)


def test_candidates_of_distinct_seeds_are_disjoint():
    a = world_seed_candidates(1, 50)
    b = world_seed_candidates(2, 50)
    assert a[0] == 1 and b[0] == 2
    assert not set(a) & set(b)
    assert len(set(a)) == 50
    assert world_seed_candidates(1, 50) == a  # deterministic
    for bad, name in (((-1, 5), "seed"), ((1.5, 5), "seed"), ((True, 5), "seed"),
                      ((1, 0), "n"), ((1, "5"), "n")):
        with pytest.raises(ValueError, match=f"^{name}: expected an integer"):
            world_seed_candidates(*bad)


def test_content_hash_of_a_world_without_a_grid_is_refused():
    with pytest.raises(ValueError, match="no grid"):
        World.of_shapes().content_hash()


def test_content_hash_ignores_meta_and_sees_the_grid():
    w = world_for(jwarp.robot("planar4"), 0)
    v = World(w.sdf.copy(), w.limits.copy(), w.voxel_size, w.occupancy.copy(), {"other": 1})
    assert v.content_hash() == w.content_hash()
    occ = w.occupancy.copy()
    occ.flat[0] = not occ.flat[0]
    u = World(w.sdf.copy(), w.limits.copy(), w.voxel_size, occ, {})
    assert u.content_hash() != w.content_hash()


class _Labels:
    def __init__(self, n_dof: int, n: int = 2, w: int = 4):
        rng = np.random.default_rng(0)
        self.starts = rng.normal(size=(n, n_dof))
        self.goals = rng.normal(size=(n, n_dof))
        self.paths = rng.normal(size=(n, w, n_dof))
        self.cost = np.ones(n)
        self.feasible = np.ones(n, bool)
        self.hard = np.zeros(n, bool)
        self.settings = {"test": 1}


def test_path_db_refuses_a_duplicate_world(tmp_path):
    w0, w1 = world_for(jwarp.robot("planar4"), 0), world_for(jwarp.robot("planar4"), 1)
    db = PathDB(tmp_path / "p.sqlite", jwarp.robot("planar4"), create=True)
    assert db.add_world(world_record(0, w0, _Labels(4)))
    assert db.add_world(world_record(1, w1, _Labels(4)))
    with pytest.raises(DuplicateWorldError, match="world 2 has the same grid as world 0"):
        db.add_world(world_record(2, w0, _Labels(4)))
    assert db.world_ids() == [0, 1]  # nothing written
    info = db.info()
    assert info["distinct_worlds"] == 2 and info["duplicate_worlds"] == []
    assert record_hash(db.world_row(0)) == w0.content_hash()
    db.close()


def test_path_db_of_before_the_hash_table(tmp_path):
    """Worlds stored without hashes (an older database) are hashed before the next write,
    so a duplicate of one of them is refused too; info counts distinct grids."""
    w0 = world_for(jwarp.robot("planar4"), 0)
    path = tmp_path / "old.sqlite"
    db = PathDB(path, jwarp.robot("planar4"), create=True)
    db.add_world(world_record(0, w0, _Labels(4)))
    db.con.execute("DROP TABLE world_hashes")
    db.close()
    db = PathDB(path)  # adds the table back, empty
    with pytest.raises(DuplicateWorldError, match="world 1 has the same grid as world 0"):
        db.add_world(world_record(1, w0, _Labels(4)))
    assert db.info()["distinct_worlds"] == 1
    db.close()


def test_split_by_world_keeps_equal_grids_on_one_side():
    a, b, c = (world_for(jwarp.robot("planar4"), s) for s in (0, 1, 2))
    a2 = World(a.sdf.copy(), a.limits.copy(), a.voxel_size, a.occupancy.copy(), {"copy": 1})
    worlds = [a, b, c, a2]
    n = 16
    idx = np.arange(n) % 4
    s = PlanSamples(np.zeros((n, 4)), np.zeros((n, 4)), np.zeros((n, 3, 4)), idx, worlds)
    for seed in range(8):
        train, val = split_by_world(s, 0.34, seed=seed)
        tr = {w.content_hash() for w in train.worlds}
        va = {w.content_hash() for w in val.worlds}
        assert not tr & va
        assert len(tr) + len(va) == 3
