"""Smoke test of benchmarks/bench_learn_ik.py: the --quick CPU run (a tiny network trained
first, no --model) exits 0 and reports every section (the numbers are not checked)."""

from __future__ import annotations


def test_bench_learn_ik_quick_cpu(run_bench):
    stdout, doc = run_bench("bench_learn_ik.py", "--quick")
    assert "no --model given: trained a tiny network first" in stdout
    assert doc["machine"] and doc["repeats"] == 2 and doc["model"] is None
    ik = doc["ik"]
    for k in ("learned", "random"):
        t = ik[k]["time_per_target_ms_median_over_targets"]
        assert 0 < t["min"] <= t["median"]
        assert 0 <= ik[k]["solved_rate"] <= 1
    assert ik["speedup_learned_vs_random"]["of_medians"] > 0 and ik["heads"] in (1, 2)
    assert doc["inference"]["ms_per_target"]["median"] > 0
    assert doc["train"]["samples_per_s_median_after_first"] > 0
