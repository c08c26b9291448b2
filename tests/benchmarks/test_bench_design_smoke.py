"""Smoke test of benchmarks/bench_design.py: the --quick run exits 0 and reports every
section (the numbers themselves are not checked)."""

from __future__ import annotations


def test_bench_design_quick(run_bench):
    stdout, doc = run_bench("bench_design.py", "--quick")
    assert stdout.startswith("machine: "), stdout
    jac = doc["jacobians"]
    assert jac["hand4_contact"]["candidates"] == 400
    assert jac["justin19_tracker"]["rows_per_candidate"] == 6
    for name in ("greedy", "detmax", "detmax_justin"):
        fig = doc[name]
        assert fig["n"] == 20 and fig["criterion"] > fig["prior_criterion"]
        assert fig["seconds"]["min"] > 0
    assert doc["greedy"]["task_rank"] == 55 and "meets_target" in doc["detmax"]
