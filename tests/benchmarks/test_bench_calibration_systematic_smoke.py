"""Smoke test of bench_calibration.py's systematic-error section (issue 16 speed
acceptance): it runs, times min/median over the repeats and calibrates (the timings
themselves are not checked: never a timed test)."""


def test_bench_calibration_systematic_quick(run_bench):
    stdout, doc = run_bench("bench_calibration.py", "--case", "systematic", "--quick",
                            "--samples", "40", "--test", "20",
                            "--free", "theta,d,kappa_theta,kappa_alpha,tracker,markers",
                            timeout=300)
    assert "[systematic:" in stdout and "target <= 10 s on one core" in stdout
    fig = doc["systematic"]
    assert fig["runs"] == 2 and 0 < fig["time_min_s"] <= fig["time_s"] and doc["machine"]
    assert fig["held_at_bound"] >= 0 and fig["iterations"] >= 1
    assert fig["after"]["test"]["mean"] < 0.02   # [m]; the nominal robot is off by ~50 mm
    assert "time_s" not in doc  # the clean section did not run
