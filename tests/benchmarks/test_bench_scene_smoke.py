"""Smoke test of benchmarks/bench_scene.py --quick: both sections run, the exact kernel of
the benchmark agrees with numpy's Scene.distance, the grid lookup with the exact distances
to within the trilinear error (the timings themselves are not checked)."""

from __future__ import annotations


def test_bench_scene_quick(run_bench):
    stdout, doc = run_bench("bench_scene.py", "--quick", timeout=300)
    assert stdout.startswith("machine: ")
    assert doc["build"]["shapes"] == 14
    q = doc["query"]
    assert q["check_exact_kernel_vs_numpy_max_abs_m"] < 1e-5
    assert q["grid_lookup_vs_exact_max_abs_m"] < 0.87 * q["voxel"]  # sqrt(3)/2 voxel: Lipschitz
    for t in q["ns_per_point"].values():
        assert 0 < t["min"] <= t["median"]
