"""benchmarks/bench_world.py --quick runs and reports every figure."""


def test_bench_world_quick(run_bench):
    out, fig = run_bench("bench_world.py", "--quick")
    whats = [r["what"] for r in fig["rows"]]
    assert whats[:2] == ["build", "move"] and "check" in whats
    assert any(w.startswith("query exact") for w in whats) and "query grid 2 cm" in whats
    assert all(r["min_ms"] > 0 for r in fig["rows"])
    assert "ns/point" in out and "paths/s" in out
