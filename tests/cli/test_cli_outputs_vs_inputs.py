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
