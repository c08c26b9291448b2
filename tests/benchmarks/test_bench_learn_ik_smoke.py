"""Smoke test of benchmarks/bench_learn_ik.py: the --quick CPU run (a tiny network trained
first, no --model) exits 0 and reports every section (the numbers are not checked)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "benchmarks" / "bench_learn_ik.py"


def test_bench_learn_ik_quick_cpu(tmp_path):
    out = tmp_path / "bench.json"
    proc = subprocess.run([sys.executable, str(SCRIPT), "--quick", "--json", str(out)],
                          cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, f"stdout:\n{proc.stdout}\nstderr:\n{proc.stderr}"
    assert "no --model given: trained a tiny network first" in proc.stdout
    doc = json.loads(out.read_text())
    assert doc["machine"] and doc["repeats"] == 2 and doc["model"] is None
    ik = doc["ik"]
    for k in ("learned", "random"):
        t = ik[k]["time_per_target_ms_median_over_targets"]
        assert 0 < t["min"] <= t["median"]
        assert 0 <= ik[k]["solved_rate"] <= 1
    assert ik["speedup_learned_vs_random"]["of_medians"] > 0 and ik["heads"] in (1, 2)
    assert doc["inference"]["ms_per_target"]["median"] > 0
    assert doc["train"]["samples_per_s_median_after_first"] > 0
