"""``jwarp train plan``, ``jwarp eval plan`` and ``jwarp plan --warm-start``
(jwarp/cli/learning.py, jwarp/cli/planning.py): a tiny planar4 training with its checkpoint,
the evaluation table (text and JSON), the warm-started plan, and the option errors (one
line naming the option)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from cli_helpers import one_line_error, run  # noqa: F401  (tests/cli_helpers.py)

import jwarp
from jwarp.cli import main

TINY = ["--robot", "planar4", "--n-worlds", "1", "--tasks-per-world", "6", "--val-worlds", "1",
        "--val-tasks", "3", "--label-starts", "2", "--label-iterations", "30", "--n-bps", "16",
        "--hidden", "16", "--blocks", "1", "--steps-per-epoch", "3", "--batch", "8", "--quiet"]
START, GOAL = "1.2,0,0,0", "-1.2,0,0,0"


@pytest.fixture(scope="module")
def model_path(tmp_path_factory):
    out = tmp_path_factory.mktemp("train") / "p4.pt"
    assert main(["train", "plan", *TINY, "--epochs", "1", "--boosting", "--out", str(out)]) == 0
    return out


def test_train_plan_writes_a_checkpoint(model_path):
    from jwarp.learn.checkpoint import load_plan_checkpoint

    net = load_plan_checkpoint(model_path)
    assert net.config.n_bps == 16 and net.meta["epoch"] == 1
    assert net.meta["training"]["boosting"] is True


def test_eval_plan_table_and_json(model_path, capsys):
    argv = ["eval", "plan", "--robot", "planar4", "--model", model_path, "--n-worlds", "1",
            "--tasks", "3", "--ks", "0,5", "--random-starts", "2"]
    code, out, err = run(capsys, argv)
    assert code == 0, err
    assert "k=5" in out and "p4" in out and "random (best of 2)" in out
    code, out, err = run(capsys, [*argv, "--json"])
    doc = json.loads(out)
    assert [r["name"] for r in doc["rows"]][0] == "p4" and doc["ks"] == [0, 5]


def test_plan_warm_start(model_path, block, capsys):
    argv = ["plan", "--robot", "planar4", "--world", block, "--start", START, f"--goal={GOAL}",
            "--iterations", "5", "--substeps", "2", "--warm-start", model_path, "--json"]
    code, out, err = run(capsys, argv)
    assert code in (0, 1), err
    doc = json.loads(out)
    assert len(doc["path"]) == 20
    code, out, err = run(capsys, [*argv[:-1], "--starts", "3"])
    assert "of 3 starts" in out


def test_plan_warm_start_errors(model_path, block, capsys, tmp_path):
    import torch

    from jwarp.learn.checkpoint import save_checkpoint
    from jwarp.learn.plan_net import PlanNet, PlanNetConfig

    torch.manual_seed(0)
    other = save_checkpoint(tmp_path / "p5.pt", PlanNet(PlanNetConfig(robot="planar5", n_bps=0,
                                                                       hidden=8)))
    base = ["plan", "--robot", "planar4", "--world", block, "--start", START, f"--goal={GOAL}"]
    msg = one_line_error(capsys, [*base, "--warm-start", other], "--warm-start")
    assert "planar5" in msg
    one_line_error(capsys, [*base, "--warm-start", tmp_path / "missing.pt"], "--warm-start")
    one_line_error(capsys, [*base, "--warm-start", model_path, "--waypoints", "7"],
                   "--waypoints")


@pytest.mark.parametrize("extra, option", [
    (["--epochs", "0"], "--epochs"),
    (["--epochs", "1", "--waypoints", "2"], "--waypoints"),
    (["--epochs", "1", "--lr", "-1"], "--lr"),
    (["--epochs", "1", "--extend", "nan"], "--extend"),
    (["--epochs", "1", "--device", "tpu"], "--device"),
])
def test_train_plan_option_errors(capsys, tmp_path, extra, option):
    one_line_error(capsys, ["train", "plan", *TINY, "--out", tmp_path / "m.pt", *extra], option)
    assert not (tmp_path / "m.pt").exists()


def test_train_plan_out_is_checked_first(capsys, tmp_path):
    one_line_error(capsys, ["train", "plan", *TINY, "--epochs", "1", "--out", tmp_path], "--out")


def test_eval_plan_option_errors(capsys, tmp_path, model_path):
    base = ["eval", "plan", "--robot", "planar4", "--n-worlds", "1", "--tasks", "2"]
    one_line_error(capsys, [*base, "--model", tmp_path / "none.pt"], "--model")
    one_line_error(capsys, [*base, "--model", model_path, "--robot", "planar5"], "--model")
    one_line_error(capsys, [*base, "--ks", "a,b"], "--ks")
    one_line_error(capsys, [*base, "--ks", "-1"], "--ks")


# ------------------------------------------------------------------ --data DB.sqlite
DB_TINY = ["--robot", "planar4", "--n-bps", "8", "--hidden", "8", "--blocks", "1",
           "--steps-per-epoch", "2", "--batch", "4", "--epochs", "1", "--quiet"]


def _db_world(robot, seed, device=None):
    from jwarp.world import world_from_occupancy

    occ = np.random.default_rng(seed).random((16, 16)) < 0.08
    return world_from_occupancy(occ, np.array([[-1.0, 1.0], [-1.0, 1.0]]), 2.0 / 15)


def _db_labeler(robot, world, n_tasks, seed, options=None):
    from types import SimpleNamespace

    rng = np.random.default_rng(seed)
    s = rng.uniform(-1, 1, (n_tasks, robot.n_dof)).astype(np.float32)
    g = rng.uniform(-1, 1, (n_tasks, robot.n_dof)).astype(np.float32)
    c = np.linalg.norm(g - s, axis=1)
    return SimpleNamespace(starts=s, goals=g, paths=np.linspace(s, g, 6, axis=1), cost=c,
                           feasible=np.ones(n_tasks, bool), hard=np.ones(n_tasks, bool),
                           settings={})


def _make_db(path, robot="planar4"):
    from jwarp.learn.generate import generate

    generate(jwarp.robot(robot), 4, 5, path, labeler=_db_labeler, world_maker=_db_world, progress=False,
             options={"n_waypoints": 6})
    return path


def test_train_plan_from_a_database(tmp_path, capsys):
    from jwarp.learn.checkpoint import load_plan_checkpoint

    db = _make_db(tmp_path / "p4.sqlite")
    out = tmp_path / "m.pt"
    code, stdout, err = run(capsys, ["train", "plan", *DB_TINY, "--data", db,
                                     "--val-fraction", "0.25", "--out", out])
    assert code == 0, err
    assert "15 tasks" in stdout
    net = load_plan_checkpoint(out)
    assert net.n_waypoints == 6  # the database's waypoints by default
    src = net.meta["world_distribution"]
    assert src["source"] == "path-db" and src["path"] == str(db.resolve())
    assert src["robot"] == "planar4" and src["worlds"] == 3 and src["paths"] == 15


def test_train_plan_data_errors(tmp_path, capsys):
    db = _make_db(tmp_path / "p4.sqlite")
    other = _make_db(tmp_path / "p5.sqlite", robot="planar5")
    junk = tmp_path / "junk.sqlite"
    junk.write_bytes(b"not a database at all" * 100)
    base = ["train", "plan", *DB_TINY, "--out", tmp_path / "m.pt"]
    for path, words in ((tmp_path / "none.sqlite", "does not exist"), (other, "planar5"),
                        (junk, "junk.sqlite")):
        msg = one_line_error(capsys, [*base, "--data", path], "--data")
        assert words in msg
    msg = one_line_error(capsys, [*base, "--data", db, "--waypoints", "20"], "--waypoints")
    assert "6 waypoints" in msg
    one_line_error(capsys, [*base, "--data", db, "--val-fraction", "1"], "--val-fraction")
    assert not (tmp_path / "m.pt").exists()
