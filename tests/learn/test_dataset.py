"""The SQLite path database (jwarp/learn/dataset.py): round trip of worlds and paths,
append-only writes without duplicates, the robot/BPS checks, a locked and a corrupt file
(clear error naming the file, nothing already written lost), the torch reader and the
.npz export."""

from __future__ import annotations

import sqlite3
from types import SimpleNamespace

import numpy as np
import pytest
import torch

import jwarp
from jwarp.learn.dataset import PathDataset, PathDB, PathDBError, export_npz, world_record
from jwarp.world.sdf import world_from_occupancy

N_DOF = 5  # planar5


def fake_world(seed: int, shape=(12, 10)):
    rng = np.random.default_rng(seed)
    occ = rng.random(shape) < 0.2
    lim = np.array([[-1.0, -1.0 + (shape[0] - 1) * 0.1], [-0.5, -0.5 + (shape[1] - 1) * 0.1]])
    w = world_from_occupancy(occ, lim, 0.1)
    w.meta = {"kind": "fake", "seed": seed}
    return w


def fake_labels(seed: int, n: int, w: int = 4):
    rng = np.random.default_rng(1000 + seed)
    starts = rng.standard_normal((n, N_DOF)).astype(np.float32)
    goals = rng.standard_normal((n, N_DOF)).astype(np.float32)
    paths = np.linspace(starts, goals, w, axis=1).astype(np.float32)
    return SimpleNamespace(starts=starts, goals=goals, paths=paths,
                           cost=rng.random(n), feasible=rng.random(n) < 0.7,
                           hard=rng.random(n) < 0.3, settings={"labeler": "fake", "w": w})


def record(seed: int, n: int = 5):
    return world_record(seed, fake_world(seed), fake_labels(seed, n))


def filled(path, seeds=(0, 1, 2), n=5):
    with PathDB(path, jwarp.robot("planar5"), create=True) as db:
        for s in seeds:
            assert db.add_world(record(s, n))
    return path


def test_round_trip(tmp_path):
    p = filled(tmp_path / "d.sqlite")
    with PathDB(p) as db:
        assert db.robot == "planar5" and db.meta["format"] == "jwarp-path-db"
        assert db.complete_worlds() == {0, 1, 2} and db.n_paths() == 15 and db.n_dof() == N_DOF
        a = db.paths_of([1])
        lab = fake_labels(1, 5)
        np.testing.assert_array_equal(a["start"], lab.starts)
        np.testing.assert_array_equal(a["path"], lab.paths)
        np.testing.assert_array_equal(a["feasible"], lab.feasible)
        np.testing.assert_allclose(a["cost"], lab.cost)
        w, ref = db.world(2), fake_world(2)
        np.testing.assert_array_equal(w.occupancy, ref.occupancy)
        np.testing.assert_array_equal(w.sdf, ref.sdf)
        np.testing.assert_array_equal(w.limits, ref.limits)
        assert w.voxel_size == ref.voxel_size and w.meta == ref.meta
        assert db.settings() == [{"labeler": "fake", "w": 4}]
        info = db.info()
        assert info["worlds"] == 3 and info["paths"] == 15
    # the world index exists
    con = sqlite3.connect(p)
    assert "paths_by_world" in {r[0] for r in con.execute(
        "SELECT name FROM sqlite_master WHERE type='index'")}
    con.close()


def test_append_only_no_duplicates(tmp_path):
    p = filled(tmp_path / "d.sqlite")
    with PathDB(p, jwarp.robot("planar5"), create=True) as db:
        before = db.rows()
        assert not db.add_world(record(1))  # again: ignored
        assert db.add_world(record(3))
        assert db.rows()[:len(before)] == before and db.n_paths() == 20


def test_world_without_occupancy(tmp_path):
    w = fake_world(4)
    w.occupancy = None
    with PathDB(tmp_path / "d.sqlite", jwarp.robot("planar5"), create=True) as db:
        db.add_world(world_record(4, w, fake_labels(4, 2)))
        np.testing.assert_allclose(db.world(4).sdf, w.sdf.astype(np.float32))


def test_other_robot_or_bps_refused(tmp_path):
    p = filled(tmp_path / "d.sqlite")
    with pytest.raises(PathDBError, match=r"robot 'planar5'.*not of robot 'planar4'") as e:
        PathDB(p, jwarp.robot("planar4"))
    assert str(p) in str(e.value)
    with pytest.raises(PathDBError, match="BPS"):
        PathDB(p, jwarp.robot("planar5"), bps={"points": [[0.0, 0.0]]})
    q = tmp_path / "b.sqlite"
    PathDB(q, jwarp.robot("planar5"), bps={"points": [[0.0, 0.0]]}, create=True).close()
    PathDB(q, jwarp.robot("planar5"), bps={"points": [[0.0, 0.0]]}).close()
    with pytest.raises(PathDBError, match="another BPS"):
        PathDB(q, bps={"points": [[1.0, 0.0]]})
    with PathDB(p) as db:  # nothing changed
        assert db.n_paths() == 15


def test_missing_garbage_and_foreign_files(tmp_path):
    with pytest.raises(PathDBError, match="does not exist"):
        PathDB(tmp_path / "none.sqlite")
    g = tmp_path / "garbage.sqlite"
    junk = b"this is not a database at all " * 200
    g.write_bytes(junk)
    for create in (False, True):
        with pytest.raises(PathDBError, match=r"garbage.sqlite.*not a readable SQLite database"):
            PathDB(g, jwarp.robot("planar5"), create=create)
    assert g.read_bytes() == junk  # left as it was
    f = tmp_path / "foreign.sqlite"
    con = sqlite3.connect(f)
    con.execute("CREATE TABLE t (x)")
    con.commit()
    con.close()
    with pytest.raises(PathDBError, match="not a jwarp path database"):
        PathDB(f, jwarp.robot("planar5"), create=True)


def test_corrupt_pages_clear_error(tmp_path):
    p = filled(tmp_path / "d.sqlite", seeds=range(8), n=40)
    data = bytearray(p.read_bytes())
    data[4096:] = b"\xff" * (len(data) - 4096)  # every page after the first destroyed
    p.write_bytes(bytes(data))
    with pytest.raises(PathDBError, match="d.sqlite"), PathDB(p) as db:
        db.paths_of(db.world_ids())


def test_locked_database_loses_nothing(tmp_path):
    p = filled(tmp_path / "d.sqlite")
    other = sqlite3.connect(p, isolation_level=None)
    other.execute("BEGIN IMMEDIATE")  # another writer holds the write lock
    try:
        with (PathDB(p, jwarp.robot("planar5"), timeout=0.2) as db,
              pytest.raises(PathDBError, match=r"d.sqlite' is locked by another process "
                                               r"while writing world 7")):
            db.add_world(record(7))
    finally:
        other.execute("ROLLBACK")
        other.close()
    with PathDB(p, jwarp.robot("planar5")) as db:
        assert db.complete_worlds() == {0, 1, 2} and db.n_paths() == 15
        assert db.add_world(record(7))  # once the lock is gone
        assert db.complete_worlds() == {0, 1, 2, 7}


def test_torch_reader(tmp_path):
    p = filled(tmp_path / "d.sqlite", seeds=range(4), n=5)
    ds = PathDataset(p, batch_size=6, occupancy=True)
    batches = list(ds)
    assert [len(b["task"] if "task" in b else b["cost"]) for b in batches] == [6, 6, 6, 2]
    b = batches[0]
    assert b["start"].shape == (6, N_DOF) and b["path"].shape == (6, 4, N_DOF)
    assert b["path"].dtype == torch.float32 and b["occupancy"].shape == (2, 12, 10)
    assert b["world_id"].tolist() == [0] * 5 + [1] and b["world_index"].tolist() == [0] * 5 + [1]
    np.testing.assert_array_equal(b["occupancy"][b["world_index"][5]].numpy(),
                                  fake_world(1).occupancy)
    starts = torch.cat([x["start"] for x in batches])
    with PathDB(p) as db:
        np.testing.assert_array_equal(starts.numpy(), db.paths_of(range(4))["start"])
    # shuffled, feasible only, through a DataLoader with 2 workers: the same paths
    ds2 = PathDataset(p, batch_size=4, shuffle=True, seed=3, feasible_only=True)
    loader = torch.utils.data.DataLoader(ds2, batch_size=None, num_workers=2)
    got = torch.cat([x["start"] for x in loader])
    with PathDB(p) as db:
        a = db.paths_of(range(4))
    want = a["start"][a["feasible"]]
    assert got.shape == want.shape
    assert sorted(map(tuple, got.numpy().tolist())) == sorted(map(tuple, want.tolist()))
    with pytest.raises(PathDBError, match="planar4"):
        PathDataset(p, robot=jwarp.robot("planar4"))


def test_export_npz(tmp_path):
    p = filled(tmp_path / "d.sqlite")
    out = export_npz(p, tmp_path / "d.npz")
    with np.load(out) as z:
        assert z["start"].shape == (15, N_DOF) and z["path"].shape == (15, 4, N_DOF)
        assert z["worlds"].tolist() == [0, 1, 2] and z["world_occupancy"].shape == (3, 12, 10)
        assert '"robot":"planar5"' in str(z["meta"])
    assert [x.name for x in tmp_path.iterdir() if x.name.startswith(".")] == []


def test_reader_pickles_without_its_connection(tmp_path):
    import pickle

    p = filled(tmp_path / "d.sqlite", seeds=(0, 1), n=3)
    ds = PathDataset(p, batch_size=4, occupancy=True)
    first = [b["start"] for b in ds]
    again = pickle.loads(pickle.dumps(ds))  # after use: it holds a connection and a cache
    assert all(torch.equal(x, y["start"]) for x, y in zip(first, again))


def test_writer_killed_mid_transaction(tmp_path):
    """A writer killed (os._exit) in the middle of a world's transaction: the next open
    rolls the half world back (SQLite's journal); the complete worlds are all there."""
    import subprocess
    import sys

    p = filled(tmp_path / "d.sqlite")
    code = (f"import os, sqlite3; con = sqlite3.connect({str(p)!r}, isolation_level=None); "
            "con.execute('BEGIN IMMEDIATE'); "
            "con.execute(\"INSERT INTO worlds(world_id, dim, shape, limits, voxel_size, "
            "sdf_dtype, meta, n_paths) VALUES (9, 2, '[2,2]', x'00', 0.1, 'float64', '{}', 5)\"); "
            "con.execute(\"INSERT INTO paths(world_id, task, start, goal, waypoints, "
            "n_waypoints, cost, feasible, hard) VALUES (9, 0, x'00', x'00', x'00', 1, 0, 0, 0)\"); "
            "os._exit(1)")
    assert subprocess.run([sys.executable, "-c", code]).returncode == 1
    with PathDB(p, jwarp.robot("planar5")) as db:
        assert db.complete_worlds() == {0, 1, 2} and db.n_paths() == 15
        assert db.add_world(record(9))
        assert db.complete_worlds() == {0, 1, 2, 9}


def test_info_reports_worlds_whose_paths_are_missing(tmp_path, capsys):
    """Reliability round 3, item 10: a world whose paths were removed from the database was
    never reported; ``info()`` lists it and ``jwarp data info`` warns."""
    import sqlite3

    from cli_helpers import run
    p = filled(tmp_path / "d.sqlite")
    with PathDB(p) as db:
        assert db.info()["worlds_missing_paths"] == []
    con = sqlite3.connect(str(p))
    con.execute("DELETE FROM paths WHERE world_id = 1 AND task >= 2")
    con.commit()
    con.close()
    with PathDB(p) as db:
        assert db.info()["worlds_missing_paths"] == [{"world_id": 1, "expected": 5, "stored": 2}]
    code, out, err = run(capsys, ["data", "info", str(p)])
    assert code == 0 and "1 world(s) miss paths (e.g. world 1: 2 of 5 stored)" in err
