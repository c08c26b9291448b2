"""benchmarks/bench_motion_check.py --quick runs, compares both checks on every case and
reports their figures."""


def test_bench_motion_check_quick(run_bench):
    out, fig = run_bench("bench_motion_check.py", "--quick", "--robots", "arm7")
    rows = fig["rows"]
    assert [r["case"] for r in rows] == ["ordinary", "graze 1mm", "graze 0.1mm",
                                         "graze -0.1mm"]
    for r in rows:
        assert r["advance"]["ms"] > 0 and r["levels"]["ms"] > 0
        assert r["levels"]["launches"] > r["advance"]["launches"] >= 3
        assert r["levels"]["evals"] > 0 and r["agree"] + r["levels_only"] + r["advance_only"] \
            == r["paths"]
    assert rows[-1]["levels"]["ok"] == rows[-1]["advance"]["ok"] == 0   # collisions
    assert rows[1]["levels"]["ok"] == rows[1]["paths"]                 # 1 mm: proven
    assert "machine:" in out and "speedup" in out
