"""Reliability round 3, item 1: no command writes an output over one of its own input
files, whichever options name them (``train plan --data DB --out DB`` replaced the path
database with a checkpoint and exited 0); refused before any work, the input untouched."""

from __future__ import annotations

import hashlib

from cli_helpers import one_line_error


def digest(path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_train_plan_refuses_its_database_as_out(capsys, tmp_path):
    db = tmp_path / "paths.sqlite"
    db.write_bytes(b"SQLite format 3\x00" + b"\x00" * 100)   # any existing file
    before = digest(db)
    line = one_line_error(capsys, ["train", "plan", "--robot", "planar4", "--data", str(db),
                                   "--epochs", "1", "--out", str(db)], "--out")
    assert "is also --data" in line
    assert digest(db) == before


def test_calibrate_refuses_its_fix_and_prior_files_as_outputs(capsys, tmp_path):
    """Reliability round 4, item 3: ``--fix GROUP=FILE`` names an input inside a KEY=FILE
    item and ``--prior FILE`` (given twice: two files of one option) were not protected:
    ``--params-out``/``--out`` overwrote them. Refused before any work, files untouched."""
    from jwarp.cli import main

    run_dir = tmp_path / "run"
    assert main(["simulate-campaign", "--samples", "20", "--seed", "1",
                 "--out", str(run_dir)]) == 0
    capsys.readouterr()
    fx, pr, pr2 = tmp_path / "fx.json", tmp_path / "pr.json", tmp_path / "pr2.json"
    fx.write_text('{"any": "result"}')
    pr.write_text('{"theta": 1e-3}')
    pr2.write_text('{"d": 1e-3}')
    before = {p: digest(p) for p in (fx, pr, pr2)}
    base = ["calibrate", "--setup", run_dir / "setup.json", "--data", run_dir / "samples.csv",
            "--free", "theta", "--max-nfev", "2"]
    line = one_line_error(capsys, [*base, "--fix", f"tracker={fx}", "--params-out", fx,
                                   "--out", tmp_path / "out.json"], "--params-out")
    assert "is also --fix" in line
    line = one_line_error(capsys, [*base, "--prior", pr, "--out", pr], "--out")
    assert "is also --prior" in line
    line = one_line_error(capsys, [*base, "--prior", pr, "--prior", pr2, "--out", pr],
                          "--out")
    assert "is also --prior" in line
    assert {p: digest(p) for p in (fx, pr, pr2)} == before
    assert not (tmp_path / "out.json").exists()


def test_command_files_hold_every_file_of_an_option_and_key_file_items(tmp_path):
    import argparse

    from jwarp.cli.common import input_named, set_command_files

    a, b, c = (tmp_path / n for n in ("a.json", "b.json", "c.json"))
    for p in (a, b, c):
        p.write_text("{}")
    set_command_files(argparse.Namespace(prior=[str(a), str(b)], fix=f"tracker={c},camera",
                                         out=str(tmp_path / "new.json"), func=None))
    assert input_named(str(a), "--out") == "--prior"
    assert input_named(str(b), "--out") == "--prior"
    assert input_named(str(c), "--out") == "--fix"
    assert input_named(str(tmp_path / "new.json"), "--out") is None
