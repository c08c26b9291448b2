"""Planning-network samples from a path database (jwarp.learn.train_plan.samples_from_db,
split_by_world): exactly the stored rows, worlds rebuilt from the stored occupancy, a
split with disjoint worlds, the errors (another robot, waypoint count, nothing selected),
and a short training whose checkpoint names the database. A tiny planar4 database written
by jwarp.learn.generate with a fast fake labeller."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

import jwarp
from jwarp.learn.dataset import PathDB, PathDBError
from jwarp.learn.generate import generate
from jwarp.learn.train_plan import (
    PlanSamples,
    TrainPlanOptions,
    samples_from_db,
    split_by_world,
    train_plan,
)
from jwarp.world.sdf import world_from_occupancy

ROBOT = "planar4"
W = 6


def world_maker(robot, seed, device=None):
    rng = np.random.default_rng(seed)
    occ = rng.random((16, 16)) < 0.08
    return world_from_occupancy(occ, np.array([[-1.0, 1.0], [-1.0, 1.0]]), 2.0 / 15)


def labeler(robot, world, n_tasks, seed, options=None):
    rng = np.random.default_rng(seed)
    n = robot.n_dof
    starts = rng.uniform(-1, 1, (n_tasks, n)).astype(np.float32)
    goals = rng.uniform(-1, 1, (n_tasks, n)).astype(np.float32)
    paths = np.linspace(starts, goals, W, axis=1).astype(np.float32)
    cost = np.linalg.norm(goals - starts, axis=1)
    return SimpleNamespace(starts=starts, goals=goals, paths=paths, cost=cost,
                           feasible=cost < 2.6, hard=cost > 1.2, settings={"fake": 1})


def make_db(path, robot=ROBOT, n_worlds=5, per_world=8):
    generate(jwarp.robot(robot), n_worlds, per_world, path, labeler=labeler, world_maker=world_maker,
             progress=False, options={"n_waypoints": W})
    return path


@pytest.fixture(scope="module")
def db(tmp_path_factory):
    return make_db(tmp_path_factory.mktemp("db") / "p4.sqlite")


@pytest.mark.parametrize("hard_only, feasible_only", [(True, True), (False, True),
                                                       (False, False)])
def test_samples_are_exactly_the_stored_rows(db, hard_only, feasible_only):
    s = samples_from_db(db, jwarp.robot(ROBOT), hard_only=hard_only, feasible_only=feasible_only)
    with PathDB(db, jwarp.robot(ROBOT)) as d:
        rows = [r for r in d.rows() if (r[6] or not feasible_only) and (r[7] or not hard_only)]
        assert len(s) == len(rows) > 0
        n = 4
        for i, r in enumerate(rows):
            assert s.world_ids[s.world_index[i]] == r[0]
            assert np.array_equal(s.starts[i], np.frombuffer(r[2], np.float32))
            assert np.array_equal(s.goals[i], np.frombuffer(r[3], np.float32))
            assert np.array_equal(s.paths[i], np.frombuffer(r[4], np.float32).reshape(-1, n))
        for wid, world in zip(s.world_ids, s.worlds):  # rebuilt from the stored occupancy
            ref = world_maker(None, wid)
            assert np.array_equal(world.occupancy, ref.occupancy)
            assert np.allclose(world.sdf, ref.sdf)
    assert s.cost is None and s.source["robot"] == ROBOT and s.source["path"].endswith("p4.sqlite")


def test_world_ids_subset_and_open_db(db):
    with PathDB(db) as d:
        s = samples_from_db(d, jwarp.robot(ROBOT), world_ids=[3, 1])
        assert s.world_ids == [3, 1] and set(s.world_index) == {0, 1}
        assert s.world_index[0] == 0  # in the order asked for
        with pytest.raises(ValueError, match="world_ids: .* no world 99"):
            samples_from_db(d, jwarp.robot(ROBOT), world_ids=[1, 99])
        with pytest.raises(PathDBError, match="planar5"):
            samples_from_db(d, jwarp.robot("planar5"))


def test_split_keeps_worlds_disjoint(db):
    s = samples_from_db(db, jwarp.robot(ROBOT), hard_only=False)
    train, val = split_by_world(s, 0.4, seed=1)
    assert len(train) + len(val) == len(s) and len(val.worlds) == 2
    assert not set(train.world_ids) & set(val.world_ids)
    assert set(train.world_ids) | set(val.world_ids) == set(s.world_ids)
    for part in (train, val):  # compacted: only its own worlds
        assert sorted(set(part.world_index.tolist())) == list(range(len(part.worlds)))
    key = {tuple(np.r_[a, b]) for a, b in zip(s.starts, s.goals)}
    assert {tuple(np.r_[a, b]) for a, b in zip(train.starts, train.goals)} | \
        {tuple(np.r_[a, b]) for a, b in zip(val.starts, val.goals)} == key
    t2, _ = split_by_world(s, 0.4, seed=1)
    assert t2.world_ids == train.world_ids  # deterministic per seed
    t0, v0 = split_by_world(s, 0.0)
    assert len(t0) == len(s) and len(v0) == 0
    with pytest.raises(ValueError, match="val_fraction"):
        split_by_world(s, 1.0)
    with pytest.raises(ValueError, match="val_fraction"):
        split_by_world(s.subset(np.flatnonzero(s.world_index == 0)), 0.5)


def test_errors_name_the_cause(db, tmp_path):
    with pytest.raises(ValueError, match="n_waypoints: .*6 waypoints.* 20"):
        samples_from_db(db, jwarp.robot(ROBOT), n_waypoints=20)
    assert len(samples_from_db(db, jwarp.robot(ROBOT), n_waypoints=W))
    with pytest.raises(PathDBError, match="p4.sqlite.*planar4"):
        samples_from_db(db, jwarp.robot("planar5"))
    empty = tmp_path / "empty.sqlite"
    PathDB(empty, jwarp.robot(ROBOT), create=True).close()
    with pytest.raises(ValueError, match="empty.sqlite.*no hard and feasible path"):
        samples_from_db(empty, jwarp.robot(ROBOT))


def test_training_checkpoint_names_the_database(db, tmp_path):
    from jwarp.learn.checkpoint import load_plan_checkpoint

    train, val = split_by_world(samples_from_db(db, jwarp.robot(ROBOT), hard_only=False), 0.25)
    out = tmp_path / "m.pt"
    opts = TrainPlanOptions(robot=ROBOT, n_bps=8, n_waypoints=W, hidden=8, n_blocks=1,
                            epochs=1, steps_per_epoch=2, batch_size=4, checkpoint=str(out))
    train_plan(opts, train, val)
    src = load_plan_checkpoint(out).meta["world_distribution"]
    assert src["source"] == "path-db" and src["path"] == train.source["path"]
    assert src["robot"] == ROBOT and src["worlds"] == len(train.worlds)
    assert src["paths"] == len(train) and src["world_ids"] == train.world_ids


def test_plain_samples_keep_the_old_description():
    from jwarp.learn.train_plan import data_description

    s = PlanSamples(np.zeros((1, 4)), np.ones((1, 4)), np.zeros((1, 3, 4)), [0], [None])
    assert data_description(s) == "samples"
