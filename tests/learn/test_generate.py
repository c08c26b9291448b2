"""Dataset generation (jwarp/learn/generate.py) with a fast fake labeller: in-process
runs, resuming an interrupted run without duplicates, determinism per world seed; on a
local Ray instance (2 CPUs; skipped without the extra ``distributed``): the same rows as
in-process, and nothing lost when a worker process dies mid-chunk. One integration test
with the real labeller (jwarp.learn.plan_data), skipped while that module is missing."""

from __future__ import annotations

import importlib.util
import os
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

import jwarp
from jwarp.learn.dataset import PathDB
from jwarp.learn.generate import generate, label_chunk
from jwarp.world.sdf import world_from_occupancy

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]


def fake_world_maker(robot, seed, device=None):
    rng = np.random.default_rng(seed)
    occ = rng.random((10, 8)) < 0.25
    return world_from_occupancy(occ, np.array([[-1.0, -0.1], [-1.0, -0.3]]), 0.1)


def fake_labeler(robot, world, n_tasks, seed, options=None):
    rng = np.random.default_rng([seed, int(world.occupancy.sum())])
    n = robot.n_dof
    starts = rng.uniform(-1, 1, (n_tasks, n)).astype(np.float32)
    goals = rng.uniform(-1, 1, (n_tasks, n)).astype(np.float32)
    paths = np.linspace(starts, goals, 6, axis=1).astype(np.float32)
    cost = np.linalg.norm(goals - starts, axis=1)
    return SimpleNamespace(starts=starts, goals=goals, paths=paths, cost=cost,
                           feasible=cost < 2.0, hard=cost > 2.5, settings={"fake": 1})


class FailAfter:
    """A labeller that raises on world seed ``bad`` (an interrupted run)."""

    def __init__(self, bad):
        self.bad = bad

    def __call__(self, robot, world, n_tasks, seed, options=None):
        if seed == self.bad:
            raise KeyboardInterrupt
        return fake_labeler(robot, world, n_tasks, seed, options)


class DieOnce:
    """A labeller whose worker process dies (os._exit) the first time it labels world
    ``bad``: the marker file tells the retried attempt that it already died once."""

    def __init__(self, bad, marker):
        self.bad, self.marker = bad, str(marker)

    def __call__(self, robot, world, n_tasks, seed, options=None):
        if seed == self.bad and not os.path.exists(self.marker):
            Path(self.marker).write_text(str(os.getpid()))
            os._exit(1)
        return fake_labeler(robot, world, n_tasks, seed, options)


FAKE = dict(labeler=fake_labeler, world_maker=fake_world_maker, progress=False,
            options={"n_waypoints": 6})


def test_in_process(tmp_path):
    rep = generate(jwarp.robot("planar5"), 5, 7, tmp_path / "a.sqlite", first_seed=3, chunk=2, **FAKE)
    assert rep.worlds_written == 5 and rep.paths_written == 35 and rep.worlds_skipped == 0
    with PathDB(tmp_path / "a.sqlite", jwarp.robot("planar5")) as db:
        assert db.complete_worlds() == {3, 4, 5, 6, 7} and db.n_paths() == 35
        assert db.settings() == [{"options": {"n_waypoints": 6}, "paths_per_world": 7,
                                  "labels": {"fake": 1}}]
        a = db.paths_of([5])
        model = __import__("jwarp").robot("planar5")
        lab = fake_labeler(model, fake_world_maker(model, 5), 7, 5)
        np.testing.assert_array_equal(a["path"], lab.paths)
        np.testing.assert_array_equal(db.world(5).occupancy, fake_world_maker(model, 5).occupancy)
    # deterministic per world seed: other chunking, other order of runs -> same rows
    generate(jwarp.robot("planar5"), 2, 7, tmp_path / "b.sqlite", first_seed=6, chunk=5, **FAKE)
    generate(jwarp.robot("planar5"), 5, 7, tmp_path / "b.sqlite", first_seed=3, chunk=1, **FAKE)
    with PathDB(tmp_path / "a.sqlite") as a, PathDB(tmp_path / "b.sqlite") as b:
        assert a.rows() == b.rows()


def test_interrupted_run_resumes_without_duplicates(tmp_path):
    db = tmp_path / "r.sqlite"
    fake = dict(FAKE, labeler=FailAfter(bad=4))
    with pytest.raises(KeyboardInterrupt):
        generate(jwarp.robot("planar5"), 6, 5, db, chunk=4, **fake)
    with PathDB(db) as d:
        assert d.complete_worlds() == {0, 1, 2, 3} and d.n_paths() == 20  # nothing lost
    rep = generate(jwarp.robot("planar5"), 6, 5, db, chunk=4, **FAKE)
    assert rep.worlds_skipped == 4 and rep.worlds_written == 2
    rep = generate(jwarp.robot("planar5"), 6, 5, db, chunk=4, **FAKE)  # complete: nothing to do
    assert rep.worlds_written == 0 and rep.worlds_skipped == 6
    generate(jwarp.robot("planar5"), 6, 5, tmp_path / "ref.sqlite", **FAKE)
    with PathDB(db) as d, PathDB(tmp_path / "ref.sqlite") as ref:
        assert d.rows() == ref.rows() and d.n_paths() == 30


def test_resume_with_other_settings_refused(tmp_path):
    db = tmp_path / "s.sqlite"
    generate(jwarp.robot("planar5"), 2, 5, db, **FAKE)
    with pytest.raises(ValueError, match=r"paths_per_world: 5 in the file, 7 now"):
        generate(jwarp.robot("planar5"), 4, 7, db, **FAKE)
    with pytest.raises(ValueError, match=r"n_waypoints: 6 in the file, 8 now"):
        generate(jwarp.robot("planar5"), 4, 5, db, **dict(FAKE, options={"n_waypoints": 8}))
    # the device is not a setting of the labels; more worlds with the same settings are fine
    rep = generate(jwarp.robot("planar5"), 4, 5, db, **dict(FAKE, options={"n_waypoints": 6,
                                                               "device": "cuda"}))
    assert rep.worlds_written == 2 and rep.worlds_skipped == 2


def test_bad_arguments(tmp_path):
    with pytest.raises(ValueError, match="n_worlds"):
        generate(jwarp.robot("planar5"), 0, 5, tmp_path / "x.sqlite", **FAKE)
    generate(jwarp.robot("planar5"), 1, 2, tmp_path / "x.sqlite", **FAKE)
    with pytest.raises(ValueError, match="not of robot 'planar4'"):
        generate(jwarp.robot("planar4"), 1, 2, tmp_path / "x.sqlite", **FAKE)


def test_label_chunk_is_pure():
    a = label_chunk(jwarp.robot("planar5"), [1, 2], 3, None, fake_labeler, fake_world_maker)
    b = label_chunk(jwarp.robot("planar5"), [1, 2], 3, None, fake_labeler, fake_world_maker)
    assert [r["world_id"] for r in a] == [1, 2]
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x["paths"], y["paths"])


# ---------------------------------------------------------------------- Ray
def test_ray_started_and_stopped_by_generate(tmp_path, monkeypatch):
    """``ray=True`` without a running instance: generate starts a local one (2 CPUs, its
    workers import this jwarp and, through PYTHONPATH, this test module) and stops it."""
    ray = pytest.importorskip("ray", reason="the optional extra 'distributed' (ray) is absent")
    if ray.is_initialized():
        pytest.skip("a Ray instance of another test is running")
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([str(HERE), os.environ.get("PYTHONPATH",
                                                                                "")]))
    t = time.perf_counter()
    rep = generate(jwarp.robot("planar5"), 4, 3, tmp_path / "own.sqlite", chunk=2, ray=True, num_cpus=2,
                   **FAKE)
    print(f"ray own instance {time.perf_counter() - t:.1f} s")
    assert rep.worlds_written == 4 and not ray.is_initialized()
    generate(jwarp.robot("planar5"), 4, 3, tmp_path / "ref.sqlite", **FAKE)
    with PathDB(tmp_path / "own.sqlite") as a, PathDB(tmp_path / "ref.sqlite") as b:
        assert a.rows() == b.rows()


@pytest.fixture(scope="module")
def ray_local():
    ray = pytest.importorskip("ray", reason="the optional extra 'distributed' (ray) is absent")
    pp = os.pathsep.join([str(ROOT), str(HERE), os.environ.get("PYTHONPATH", "")])
    t = time.perf_counter()
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False,
             runtime_env={"env_vars": {"PYTHONPATH": pp}})
    print(f"ray start {time.perf_counter() - t:.1f} s")
    yield ray
    ray.shutdown()


def test_ray_same_rows_as_in_process(tmp_path, ray_local):
    generate(jwarp.robot("planar5"), 6, 4, tmp_path / "local.sqlite", first_seed=10, chunk=2, **FAKE)
    t = time.perf_counter()
    rep = generate(jwarp.robot("planar5"), 6, 4, tmp_path / "ray.sqlite", first_seed=10, chunk=2, ray=True,
                   **FAKE)
    print(f"ray run {time.perf_counter() - t:.1f} s")
    assert rep.backend == "ray" and rep.worlds_written == 6
    with PathDB(tmp_path / "local.sqlite") as a, PathDB(tmp_path / "ray.sqlite") as b:
        assert a.rows() == b.rows() and len(a.rows()) == 24
        assert a.settings() == b.settings()


def test_ray_worker_killed_mid_chunk(tmp_path, ray_local):
    marker = tmp_path / "died"
    fake = dict(FAKE, labeler=DieOnce(bad=2, marker=marker))
    t = time.perf_counter()
    rep = generate(jwarp.robot("planar5"), 5, 4, tmp_path / "k.sqlite", chunk=3, ray=True, max_retries=2,
                   **fake)
    print(f"ray kill run {time.perf_counter() - t:.1f} s")
    assert marker.exists(), "the worker was never killed"
    assert int(marker.read_text()) != os.getpid()
    assert rep.worlds_written == 5
    generate(jwarp.robot("planar5"), 5, 4, tmp_path / "ref.sqlite", **FAKE)
    with PathDB(tmp_path / "k.sqlite") as k, PathDB(tmp_path / "ref.sqlite") as ref:
        assert k.rows() == ref.rows() and k.n_paths() == 20  # all rows, no duplicates


class AlwaysFails:
    def __init__(self, bad):
        self.bad = bad

    def __call__(self, robot, world, n_tasks, seed, options=None):
        if seed == self.bad:
            raise ValueError(f"cannot label world {seed}")
        return fake_labeler(robot, world, n_tasks, seed, options)


def test_ray_chunk_failing_for_good(tmp_path, ray_local):
    fake = dict(FAKE, labeler=AlwaysFails(bad=3))
    with pytest.raises(RuntimeError, match=r"world seeds 2\.\.3 failed 2 times.*rerun"):
        generate(jwarp.robot("planar5"), 4, 2, tmp_path / "f.sqlite", chunk=2, ray=True, max_retries=1,
                 **fake)
    with PathDB(tmp_path / "f.sqlite") as d:  # the good chunk is kept
        assert d.complete_worlds() == {0, 1}


# ---------------------------------------------------------------------- real labeller
@pytest.mark.skipif(importlib.util.find_spec("jwarp.learn.plan_data") is None,
                    reason="jwarp.learn.plan_data (the real labeller, issue 15 item 1) is not "
                           "in this tree yet")
def test_real_labeler_integration(tmp_path):
    from jwarp.learn import plan_data

    opts = plan_data.PlanDataOptions(n_waypoints=8, max_starts=4)
    rep = generate(jwarp.robot("planar5"), 2, 3, tmp_path / "real.sqlite", options=opts, progress=False)
    assert rep.worlds_written == 2
    with PathDB(tmp_path / "real.sqlite", jwarp.robot("planar5")) as db:
        a = db.paths_of([0, 1])
        assert a["path"].shape == (6, 8, 5) and np.isfinite(a["path"]).all()
        w = db.world(1)
        ref = plan_data.world_for(__import__("jwarp").robot("planar5"), 1, device="cpu")
        np.testing.assert_array_equal(w.occupancy, ref.occupancy)
        np.testing.assert_array_equal(w.sdf, ref.sdf)  # recomputed exactly from the grid
        assert db.settings()[0]["options"]["n_waypoints"] == 8


def test_ray_missing_names_the_extra(tmp_path, monkeypatch):
    import sys

    monkeypatch.setitem(sys.modules, "ray", None)  # as if the extra were not installed
    with pytest.raises(ImportError, match=r"jwarp\[distributed\]"):
        generate(jwarp.robot("planar5"), 1, 1, tmp_path / "n.sqlite", ray=True, **FAKE)
    assert not (tmp_path / "n.sqlite").exists()  # refused before any work
