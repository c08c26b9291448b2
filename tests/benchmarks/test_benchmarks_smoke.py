"""Smoke tests of the benchmark scripts' --quick CPU runs (bench_kinematics.py,
bench_planning.py, bench_calibration.py; bench_ik.py in test_bench_ik_smoke.py): exit 0,
rows and the JSON's timing fields present (the numbers themselves are not checked)."""

from __future__ import annotations


def test_bench_kinematics_quick_cpu(run_bench):
    stdout, doc = run_bench("bench_kinematics.py", "--quick", "--device", "cpu", timeout=300)
    lines = stdout.splitlines()
    assert any(line.split()[:2] == ["robot", "op"] for line in lines), stdout
    for robot in ("justin19", "arm7"):
        for op in (["fk"], ["jacobian"], ["elastic_fk(10)"], ["elastic_step"], ["fk", "numpy"]):
            assert any(line.split()[:len(op) + 1] == [robot, *op] for line in lines), \
                f"no '{robot} {' '.join(op)}' row in:\n{stdout}"
    assert ("pinocchio not installed" in stdout
            or any("fk pinocchio" in line for line in lines)), stdout

    rows = doc["rows"]
    fk_rows = [r for r in rows if r["op"] == "fk" and r["device"] == "cpu"]
    assert {r["robot"] for r in fk_rows} == {"justin19", "arm7"}
    assert all(r["configs_per_s"] > 0 and r["time_per_batch_s"] > 0 for r in rows)
    # the numpy FK written in the benchmark agrees with jwarp's
    for robot in ("justin19", "arm7"):
        assert doc["checks"][f"{robot}: |numpy fk - jwarp fk| max"] < 1e-3


def test_bench_planning_quick_cpu(run_bench):
    """bench_planning.py --quick: every section runs; its times are min/median figures
    (benchmarks/timing.py) and its IK section is bench_ik.py's shelf IK (ik() alone)."""
    stdout, doc = run_bench("bench_planning.py", "--quick", timeout=300)
    assert stdout.startswith("machine: "), stdout
    assert doc["machine"] and doc["repeats"] == 3
    for P in (1, 4):
        t = doc["iteration"][f"iteration_ms_{P}_paths"]
        assert 0 < t["min"] <= t["median"]
    ik = doc["ik"]
    assert set(ik) >= {"ik", "targets", "starts"} and "baseline" not in ik
    t = ik["ik"]["time_per_target_ms_median_over_targets"]
    assert 0 < t["min"] <= t["median"] and 0 <= ik["ik"]["solved_rate"] <= 1
    assert doc["feasibility"]["planar4"]["hard_tasks"] >= 0
    comp = doc["compensation"]
    for key in ("path_iteration_1_paths", "path_iteration_4_paths", "ik_iteration_64_configs"):
        c = comp[key]
        assert 0 < c["rigid_best_s"] <= c["rigid_s"] and 0 < c["elastic_best_s"] <= c["elastic_s"]
        assert c["rounds"] == 3
        assert abs(c["overhead"] - (c["elastic_s"] / c["rigid_s"] - 1)) < 1e-12


def test_bench_calibration_quick_cpu(run_bench):
    """bench_calibration.py --quick: the calibration time is min/median over 2 runs."""
    stdout, doc = run_bench("bench_calibration.py", "--quick", "--samples", "40", "--test", "20",
                            "--free", "theta,d,kappa_theta,tracker,markers", timeout=300)
    assert "full calibration:" in stdout and "after test" in stdout
    assert doc["runs"] == 2 and 0 < doc["time_min_s"] <= doc["time_s"] and doc["machine"]
