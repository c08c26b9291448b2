"""``jwarp data generate | info | export`` (jwarp/cli/data.py) with a fast fake labeller
patched in for the default one: a run, resuming it, info and export, and the option errors
(one line naming the option, checked before any work, nothing written)."""

from __future__ import annotations

import json
import sqlite3
import sys
from types import SimpleNamespace

import numpy as np
import pytest
from cli_helpers import one_line_error, run  # noqa: F401  (tests/cli_helpers.py)

from jwarp.learn import generate as gen
from jwarp.learn.dataset import PathDB
from jwarp.world.sdf import world_from_occupancy


def fake_world_maker(robot, seed, device=None):
    occ = np.random.default_rng(seed).random((8, 8)) < 0.2
    return world_from_occupancy(occ, np.array([[-1.0, -0.3], [-1.0, -0.3]]), 0.1)


def fake_labeler(robot, world, n_tasks, seed, options=None):
    rng = np.random.default_rng(seed)
    s = rng.uniform(-1, 1, (n_tasks, robot.n_dof)).astype(np.float32)
    g = rng.uniform(-1, 1, (n_tasks, robot.n_dof)).astype(np.float32)
    w = options["n_waypoints"]
    return SimpleNamespace(starts=s, goals=g, paths=np.linspace(s, g, w, axis=1),
                           cost=np.ones(n_tasks), feasible=np.ones(n_tasks, bool),
                           hard=np.zeros(n_tasks, bool), settings={})


@pytest.fixture
def fake(monkeypatch):
    monkeypatch.setattr(gen, "default_labeler", lambda: fake_labeler)
    monkeypatch.setattr(gen, "default_world_maker", lambda: fake_world_maker)
    monkeypatch.setattr(gen, "default_options",
                        lambda **kw: {"n_waypoints": 5, "device": "cpu", **kw})


GEN = ["data", "generate", "--robot", "planar5", "--paths-per-world", 3, "--quiet"]


def test_generate_info_export(capsys, tmp_path, fake):
    db = tmp_path / "d.sqlite"
    code, out, err = run(capsys, GEN + ["--worlds", 3, "--db", db, "--n-waypoints", 4])
    assert code == 0, err
    assert "3 worlds (9 paths) written, 0 already there" in out
    code, out, _ = run(capsys, GEN + ["--worlds", 5, "--db", db, "--n-waypoints", 4, "--json"])
    rep = json.loads(out)
    assert code == 0 and rep["worlds_written"] == 2 and rep["worlds_skipped"] == 3
    code, out, _ = run(capsys, ["data", "info", db, "--json"])
    info = json.loads(out)
    assert code == 0 and info["worlds"] == 5 and info["paths"] == 15 and info["robot"] == "planar5"
    assert info["settings"][0]["options"]["n_waypoints"] == 4
    code, out, _ = run(capsys, ["data", "export", db, "--out", tmp_path / "d.npz"])
    assert code == 0 and "15 paths" in out
    with np.load(tmp_path / "d.npz") as z:
        assert z["path"].shape == (15, 4, 5)


def test_generate_option_errors(capsys, tmp_path, fake, monkeypatch):
    db = tmp_path / "d.sqlite"
    base = GEN + ["--worlds", 2]
    one_line_error(capsys, base + ["--db", db, "--robot", "nope"], "--robot")
    one_line_error(capsys, GEN + ["--worlds", 0, "--db", db], "--worlds")
    one_line_error(capsys, base + ["--db", db, "--chunk", "-1"], "--chunk")
    one_line_error(capsys, base + ["--db", db, "--device", "cuda:9"], "--device")
    one_line_error(capsys, base + ["--db", tmp_path], "--db")
    one_line_error(capsys, base + ["--db", tmp_path / "no" / "d.sqlite"], "--db")
    # round 4, item 9: a dangling symbolic link gave SQLite's "unable to open database file"
    dangling = tmp_path / "link.sqlite"
    dangling.symlink_to(tmp_path / "gone" / "d.sqlite")
    line = one_line_error(capsys, base + ["--db", dangling], "--db")
    assert "is a symbolic link to" in line and "dangling" in line
    one_line_error(capsys, base + ["--db", db, "--num-gpus", 1], "--num-gpus")
    one_line_error(capsys, base + ["--db", db, "--timeout", "nan"], "--timeout")
    monkeypatch.setitem(sys.modules, "ray", None)
    line = one_line_error(capsys, base + ["--db", db, "--ray"], "--ray")
    assert "jwarp[distributed]" in line
    assert not db.exists()  # nothing written by any of them
    # a database of another robot
    assert run(capsys, base + ["--db", db])[0] == 0
    line = one_line_error(capsys, ["data", "generate", "--robot", "planar4", "--worlds", 2,
                                   "--paths-per-world", 3, "--db", db], "--db")
    assert "planar5" in line and "planar4" in line
    line = one_line_error(capsys, base + ["--db", db, "--n-waypoints", 9], "--db")
    assert "n_waypoints: 5 in the file, 9 now" in line
    with PathDB(db) as d:
        assert d.n_paths() == 6


def test_default_labeller_missing(capsys, tmp_path, monkeypatch):
    def missing():
        raise ImportError("the default labeller jwarp.learn.plan_data is not available")

    monkeypatch.setattr(gen, "default_labeler", missing)
    one_line_error(capsys, GEN + ["--worlds", 1, "--db", tmp_path / "d.sqlite"], "data generate")
    assert not (tmp_path / "d.sqlite").exists()


def test_info_export_errors(capsys, tmp_path, fake):
    bad = tmp_path / "bad.sqlite"
    bad.write_bytes(b"garbage" * 1000)
    code, out, err = run(capsys, ["data", "info", bad])
    assert code == 2 and "bad.sqlite" in err and "not a readable SQLite database" in err
    assert len(err.strip().splitlines()) == 1
    db = tmp_path / "d.sqlite"
    assert run(capsys, GEN + ["--worlds", 1, "--db", db])[0] == 0
    one_line_error(capsys, ["data", "export", db, "--out", db], "--out")
    one_line_error(capsys, ["data", "export", db, "--out", tmp_path / "no" / "x.npz"], "--out")
    con = sqlite3.connect(db, isolation_level=None)
    con.execute("BEGIN EXCLUSIVE")  # a writer holding the file: readers wait, then fail
    try:
        code, out, err = run(capsys, ["data", "info", db, "--timeout", 0.2])
    finally:
        con.execute("ROLLBACK")
        con.close()
    assert code == 2 and "locked" in err and "d.sqlite" in err
    with PathDB(db) as d:
        assert d.n_paths() == 3


def test_interrupted_generate_keeps_worlds_and_resumes(capsys, tmp_path, fake, monkeypatch):
    def interrupted(robot, world, n_tasks, seed, options=None):
        if seed == 2:
            raise KeyboardInterrupt  # Ctrl-C while labelling world 2
        return fake_labeler(robot, world, n_tasks, seed, options)

    db = tmp_path / "d.sqlite"
    monkeypatch.setattr(gen, "default_labeler", lambda: interrupted)
    code, out, err = run(capsys, GEN + ["--worlds", 4, "--db", db])
    assert code == 130 and "jwarp: interrupted" in err
    with PathDB(db) as d:
        assert d.complete_worlds() == {0, 1}
    monkeypatch.setattr(gen, "default_labeler", lambda: fake_labeler)
    code, out, err = run(capsys, GEN + ["--worlds", 4, "--db", db])
    assert code == 0 and "2 worlds (6 paths) written, 2 already there" in out
