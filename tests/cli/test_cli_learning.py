"""``jwarp train ik``, ``jwarp eval ik`` and ``jwarp ik --warm-start`` (jwarp/cli/learning.py,
jwarp/cli/planning.py): a tiny planar5 training (1 epoch, 3 steps) with its checkpoint and
rerun curves, resuming, the evaluation table (text and JSON), the warm start in ``ik``,
and the option errors (one line naming the option, nothing written)."""

from __future__ import annotations

import json

import pytest
from cli_helpers import one_line_error, run  # noqa: F401  (tests/cli_helpers.py)

from jwarp.cli import main

TINY = ["--robot", "planar5", "--world", "random", "--n-worlds", "2", "--targets-per-world",
        "48", "--val-targets", "12", "--steps-per-epoch", "3", "--batch", "32", "--hidden", "32",
        "--quiet"]


@pytest.fixture(scope="module")
def model_path(tmp_path_factory):
    """One tiny trained planar5 network (its checkpoint and rerun curves)."""
    d = tmp_path_factory.mktemp("train")
    out, rrd = d / "p5.pt", d / "curves.rrd"
    code = main(["train", "ik", *TINY, "--epochs", "1", "--out", str(out), "--rerun", str(rrd)])
    assert code == 0
    return out, rrd


def test_train_writes_checkpoint_and_curves(model_path):
    out, rrd = model_path
    assert out.is_file() and out.stat().st_size > 0
    assert rrd.is_file() and rrd.stat().st_size > 0
    from jwarp.learn.checkpoint import load_checkpoint

    net = load_checkpoint(out, robot="planar5")
    assert net.meta["epoch"] == 1 and net.config.hidden == 32 and net.config.twin
    assert not [p for p in out.parent.iterdir() if ".tmp" in p.name or p.name.startswith(".")]


def test_train_prints_epoch_lines_and_resumes(tmp_path, capsys):
    out = tmp_path / "m.pt"
    argv = ["train", "ik", *[a for a in TINY if a != "--quiet"], "--no-twin",
            "--no-unit-vectors", "--no-boosting", "--out", out]
    code, text, err = run(capsys, argv + ["--epochs", "1"])
    assert code == 0, err
    assert "epoch 1/1" in text and "val_feasible" in text and f"wrote {out}" in text
    code, text, err = run(capsys, argv + ["--epochs", "2", "--resume"])
    assert code == 0, err
    assert "resumed from" in text and "epoch 2/2" in text and "epoch 1/2" not in text
    from jwarp.learn.checkpoint import load_checkpoint

    net = load_checkpoint(out)
    assert net.meta["epoch"] == 2 and not net.config.twin and not net.config.unit_vectors
    assert net.meta["training"]["boosting"] is False


def test_eval_table_and_json(model_path, capsys):
    out, _ = model_path
    base = ["eval", "ik", "--robot", "planar5", "--model", out, "--targets", "6", "--n-worlds",
            "1", "--random-starts", "6", "--iterations", "60"]
    code, text, err = run(capsys, base + ["--ablation"])
    assert code == 0, err
    for col in ("Initial Guess", "Multi-Starts [#]", "Feas. (1) [%]", "Iterations [#]",
                "Length Cost U_1^q", "Training w. Boosting", "Twin-Headed Network"):
        assert col in text
    assert "Random" in text and "p5 (unsupervised)" in text
    code, text, err = run(capsys, base + ["--json"])
    assert code == 0, err
    doc = json.loads(text)
    rows = doc["table_3_5"]
    assert [r["name"] for r in rows] == ["Random", "p5 (unsupervised)"]
    assert doc["world"] == "random" and doc["frame"] == "tcp"
    assert rows[1]["heads"] == 2 and 0 <= rows[1]["feasibility_1"] <= 1
    assert rows[0]["multi_starts"]["cap"] == 6 and rows[1]["multi_starts"]["cap"] == 8
    # random only (no model)
    code, text, err = run(capsys, ["eval", "ik", "--robot", "planar5", "--world", "none",
                                   "--targets", "4", "--random-starts", "3", "--json"])
    assert code == 0, err
    assert [r["name"] for r in json.loads(text)["table_3_5"]] == ["Random"]


def test_ik_warm_start(model_path, capsys):
    out, _ = model_path
    argv = ["ik", "--robot", "planar5", "--frame", "tcp", "--target", "0.5,0.3,0",
            "--warm-start", out, "--json"]
    code, text, err = run(capsys, argv)
    assert code in (0, 1), err
    doc = json.loads(text)
    assert doc["warm_start"] == str(out)
    code, text, err = run(capsys, argv + ["--starts", "8"])
    assert code == 0, err
    assert json.loads(text)["feasible"]
    code, text, err = run(capsys, argv[:-1])
    assert "starts" in text


def test_ik_warm_start_errors(model_path, capsys, tmp_path):
    out, _ = model_path
    ik = ["ik", "--robot", "planar5", "--frame", "tcp", "--target", "0.5,0.3,0"]
    one_line_error(capsys, ik + ["--warm-start", tmp_path / "none.pt"], "--warm-start")
    bad = tmp_path / "bad.pt"
    bad.write_text("not a checkpoint")
    one_line_error(capsys, ik + ["--warm-start", bad], "--warm-start")
    line = one_line_error(capsys, ["ik", "--robot", "arm7", "--frame", "tcp", "--target",
                                   "0.5,0.3,0.4", "--warm-start", out], "--warm-start")
    assert "planar5" in line and "arm7" in line
    line = one_line_error(capsys, ["ik", "--robot", "planar5", "--frame", "link_3", "--target",
                                   "0.5,0.3,0", "--warm-start", out], "--warm-start")
    assert "frame" in line
    one_line_error(capsys, ik + ["--starts", "0"], "--starts")
    one_line_error(capsys, ik + ["--warm-start", out, "--starts", "-1"], "--starts")


@pytest.mark.parametrize("extra, option", [
    (["--epochs", "0"], "--epochs"),
    (["--epochs", "x"], "--epochs"),
    (["--epochs", "1", "--batch", "0"], "--batch"),
    (["--epochs", "1", "--lr", "-1"], "--lr"),
    (["--epochs", "1", "--lr", "nan"], "--lr"),
    (["--epochs", "1", "--n-bps", "-3"], "--n-bps"),
    (["--epochs", "1", "--steps-per-epoch", "0"], "--steps-per-epoch"),
    (["--epochs", "1", "--seed", "-1"], "--seed"),
    (["--epochs", "1", "--device", "cuda:7"], "--device"),
    (["--epochs", "1", "--device", "tpu"], "--device"),
    (["--epochs", "1", "--world", "moon"], "--world"),
    (["--epochs", "1", "--frame", "nope"], "--frame"),
    (["--epochs", "1", "--mix", "1,x,0"], "--mix"),
    (["--epochs", "1", "--mix", "1,-1,0"], "--mix"),
    (["--epochs", "1", "--mix", "1,0"], "--mix"),
    (["--epochs", "1", "--mix", "0.5,0,0,0.5"], "--mix"),  # random worlds: no scene tasks
])
def test_train_option_errors(capsys, tmp_path, extra, option):
    argv = ["train", "ik", "--robot", "planar5", "--out", tmp_path / "m.pt", *extra]
    one_line_error(capsys, argv, option)
    assert not (tmp_path / "m.pt").exists()


def test_train_errors_before_any_work(capsys, tmp_path):
    base = ["train", "ik", "--robot", "planar5", "--epochs", "1"]
    one_line_error(capsys, base + ["--out", tmp_path], "--out")  # a folder
    one_line_error(capsys, base + ["--out", tmp_path / "no" / "m.pt"], "--out")
    one_line_error(capsys, base + ["--out", tmp_path / "m.pt", "--resume"], "--resume")
    one_line_error(capsys, base + ["--out", tmp_path / "m.pt", "--rerun", tmp_path / "m.pt"],
                   "--rerun")
    one_line_error(capsys, base + ["--out", tmp_path / "m.pt", "--rerun", tmp_path / "x" / "c.rrd"],
                   "--rerun")
    one_line_error(capsys, base + ["--robot", "nobody", "--out", tmp_path / "m.pt"], "--robot")
    one_line_error(capsys, ["train", "ik", "--robot", "planar5", "--epochs", "1", "--world",
                            "shelf"], "--world")
    one_line_error(capsys, ["train", "ik", "--robot", "justin19", "--epochs", "1", "--world",
                            "shelf", "--n-worlds", "3", "--out", tmp_path / "m.pt"], "--n-worlds")
    one_line_error(capsys, base + ["--supervised", "--no-boosting"], "--no-boosting")
    assert list(tmp_path.iterdir()) == []


def test_eval_option_errors(capsys, tmp_path, model_path):
    out, _ = model_path
    base = ["eval", "ik", "--robot", "planar5"]
    one_line_error(capsys, base + ["--model", tmp_path / "none.pt"], "--model")
    one_line_error(capsys, ["eval", "ik", "--robot", "arm7", "--model", out], "--model")
    one_line_error(capsys, base + ["--model", out, "--frame", "link_2"], "--model")
    one_line_error(capsys, base + ["--targets", "0"], "--targets")
    one_line_error(capsys, base + ["--random-starts", "0"], "--random-starts")
    one_line_error(capsys, base + ["--ablation"], "--ablation")
    one_line_error(capsys, base + ["--world", "shelf"], "--world")
    one_line_error(capsys, base + ["--device", "cuda:9"], "--device")
    one_line_error(capsys, base + ["--mix", "0,0,0,1"], "--mix")


def test_train_and_eval_need_a_subcommand(capsys):
    code, _, err = run(capsys, ["train"])
    assert code == 2 and "jwarp: error:" in err
    code, _, err = run(capsys, ["eval", "ik"])
    assert code == 2 and "--robot" in err
