"""Smoke test of benchmarks/bench_poses.py: the --quick CPU run exits 0 and reports both
sections (the numbers are not checked, only that they are consistent)."""


def test_bench_poses_quick_cpu(run_bench):
    stdout, doc = run_bench("bench_poses.py", "--quick", "--device", "cpu")
    assert stdout.startswith("machine: "), stdout
    chk = doc["checks"]
    assert chk["batch"] == 2048 and sum(chk["counts"].values()) == 2048
    assert 0 < chk["ms_per_call"]["min"] <= chk["ms_per_call"]["median"]
    assert chk["candidates_per_s_best"] >= chk["candidates_per_s_median"] > 0
    (row,) = doc["tsp"]["rows"]
    assert row["poses"] == 20 and row["ratio_euclidean"] <= 1.0
    assert 0 < row["s"]["min"] <= row["s"]["median"]
