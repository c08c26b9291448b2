"""Smoke test of benchmarks/bench_plan_data.py: the --quick CPU run exits 0 and reports
both sections (the numbers themselves are not checked)."""

from __future__ import annotations


def test_bench_plan_data_quick_cpu(run_bench):
    stdout, doc = run_bench("bench_plan_data.py", "--quick", "--device", "cpu")
    assert stdout.startswith("machine: "), stdout
    fid = doc["fidelity"]["planar4"]
    assert fid["tasks"] == 3 and fid["thesis_feasible_pct"] == 32.6
    sp = doc["speed"]
    assert sp["robot"] == "planar4" and len(sp["runs"]) == 2
    assert sp["hard_paths_per_s"]["median"] >= 0
