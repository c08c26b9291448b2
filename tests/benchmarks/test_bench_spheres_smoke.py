"""Smoke test of benchmarks/bench_spheres.py: the --quick run exits 0 and reports both
sections; where the Panda meshes are installed, every fitted link meets the tolerance on
the fresh check samples (the numbers are otherwise not checked)."""


def test_bench_spheres_quick(run_bench):
    stdout, doc = run_bench("bench_spheres.py", "--quick")
    assert stdout.startswith("machine: "), stdout
    assert doc["repeats"] == 2
    pairs = doc["pairs"]
    assert pairs["samples"] == 200 and 0 < pairs["seconds"]["min"] <= pairs["seconds"]["median"]
    assert pairs["adjacent"] > 0 and pairs["kept"] > 0
    if "skipped" not in doc["panda"]:
        rows = doc["panda"]["links"]
        assert [r["link"] for r in rows] == ["finger", "link0"]
        for r in rows:
            assert r["spheres"] >= 1 and r["meets_tolerance"], r
            assert 0 < r["fit_s"]["min"] <= r["fit_s"]["median"]
            assert r["excess_cm3"] >= 0
        assert "| link |" in stdout
