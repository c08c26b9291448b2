"""Shared set-up of the benchmark scripts' smoke tests: the ``run_bench`` fixture runs a
script of benchmarks/ with ``--json`` into a temporary file and returns what it printed and
its figures."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture
def run_bench(tmp_path):
    """``run_bench(script, *args, timeout=600) -> (stdout, figures)``: runs
    ``benchmarks/<script> *args --json FILE`` from the repository root, asserts that it
    exits 0 (its output in the message otherwise) and reads FILE."""
    def run(script: str, *args: str, timeout: float = 600) -> tuple[str, dict]:
        out = tmp_path / f"{Path(script).stem}.json"
        proc = subprocess.run(
            [sys.executable, str(ROOT / "benchmarks" / script), *args, "--json", str(out)],
            cwd=ROOT, capture_output=True, text=True, timeout=timeout)
        assert proc.returncode == 0, f"stdout:\n{proc.stdout}\nstderr:\n{proc.stderr}"
        return proc.stdout, json.loads(out.read_text())

    return run
