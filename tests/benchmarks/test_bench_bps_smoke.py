"""Smoke test of benchmarks/bench_bps.py: the --quick CPU run exits 0 and reports both sections
with every row (the numbers themselves are not checked, except that the encoding agrees with
the SDF lookup)."""


def test_bench_bps_quick_cpu(run_bench):
    stdout, doc = run_bench("bench_bps.py", "--quick", "--device", "cpu")
    assert stdout.startswith("machine: "), stdout
    assert doc["machine"] and doc["repeats"] == 2
    for name, dim in (("2d", 2), ("3d", 3)):
        sec = doc[name]
        assert len(sec["grid"]) == dim
        assert [r["worlds"] for r in sec["rows"]] == [1, 4]
        for r in sec["rows"]:
            for k in ("encode_ms", "encode_torch_out_ms", "sdf_query_loop_ms"):
                assert 0 < r[k]["min"] <= r[k]["median"], r
            assert r["values_per_s_median"] > 0 and r["speedup_vs_sdf_query_loop"] > 0
            assert r["max_abs_diff_vs_sdf_query"] < 1e-6
