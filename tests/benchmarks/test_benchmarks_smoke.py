"""Smoke test of benchmarks/bench_kinematics.py: the --quick CPU run exits 0 and prints
the FK rows of both robots (the numbers themselves are not checked)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "benchmarks" / "bench_kinematics.py"


def test_bench_kinematics_quick_cpu(tmp_path):
    out = tmp_path / "bench.json"
    proc = subprocess.run(
        [sys.executable, str(SCRIPT), "--quick", "--device", "cpu", "--json", str(out)],
        cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, f"stdout:\n{proc.stdout}\nstderr:\n{proc.stderr}"
    lines = proc.stdout.splitlines()
    assert any(line.split()[:2] == ["robot", "op"] for line in lines), proc.stdout
    for robot in ("justin19", "arm7"):
        for op in (["fk"], ["jacobian"], ["elastic_fk(10)"], ["elastic_step"], ["fk", "numpy"]):
            assert any(line.split()[:len(op) + 1] == [robot, *op] for line in lines), \
                f"no '{robot} {' '.join(op)}' row in:\n{proc.stdout}"
    assert ("pinocchio not installed" in proc.stdout
            or any("fk pinocchio" in line for line in lines)), proc.stdout

    doc = json.loads(out.read_text())
    rows = doc["rows"]
    fk_rows = [r for r in rows if r["op"] == "fk" and r["device"] == "cpu"]
    assert {r["robot"] for r in fk_rows} == {"justin19", "arm7"}
    assert all(r["configs_per_s"] > 0 and r["time_per_batch_s"] > 0 for r in rows)
    # the numpy FK written in the benchmark agrees with jwarp's
    for robot in ("justin19", "arm7"):
        assert doc["checks"][f"{robot}: |numpy fk - jwarp fk| max"] < 1e-3
