"""Smoke test of benchmarks/bench_ik.py: the --quick CPU run exits 0 and reports every
section with the new solver beside the baseline (the numbers themselves are not checked)."""

from __future__ import annotations


def test_bench_ik_quick_cpu(run_bench):
    stdout, doc = run_bench("bench_ik.py", "--quick", "--device", "cpu")
    assert stdout.startswith("machine: "), stdout
    assert doc["machine"] and doc["repeats"] == 2
    for name in ("a", "b"):
        sec = doc[name]
        for k in ("solver", "solver_freeze_solved", "ik", "baseline"):
            assert sec[k]["solved_targets_per_s"]["median"] > 0, sec
            assert 0 < sec[k]["solved_rate"]["median"] <= 1
        assert len(sec["speedup_solver_vs_baseline"]["per_run"]) == 2
        assert sec["speedup_solver_freeze_solved_vs_baseline"]["of_medians"] > 0
    c = doc["c"]
    for k in ("solver", "ik", "baseline"):
        t = c[k]["time_per_target_ms_median_over_targets"]
        assert 0 < t["min"] <= t["median"]
    # the same seeds and re-seeds: the same solutions, so the same iterations (the
    # baseline, the solver before held limits and re-seeding, differs)
    assert c["solver"]["iterations_median"] == c["ik"]["iterations_median"]
    for k in ("solver", "ik"):  # timing.speedup: per run, of the medians, of the bests
        sp = c[f"speedup_{k}_vs_baseline"]
        assert len(sp["per_run"]) == 2 and sp["of_medians"] > 0 and sp["of_bests"] > 0
