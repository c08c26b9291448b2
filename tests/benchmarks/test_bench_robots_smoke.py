"""Smoke test of benchmarks/bench_robots.py (the robot zoo): a robot whose import fails is
a row with the import's error, never the end of the benchmark (every import is given an
invalid ``--tolerance``, so this runs in seconds; the whole zoo's figures are the script's,
and tests/importers/test_zoo.py checks FK, home and IK of a CI-sized zoo)."""


def test_bench_robots_failed_imports_are_rows(run_bench):
    stdout, doc = run_bench("bench_robots.py", "--robots", "panda,ur5e_mjcf", "--quick",
                            "--import-arg=--tolerance", "--import-arg=-1", timeout=300)
    assert stdout.startswith("machine: "), stdout
    assert doc["settings"]["quick"] and doc["settings"]["ik_poses"] == 20
    rows = doc["rows"]
    assert [r["robot"] for r in rows] == ["panda", "ur5e_mjcf"]
    for r in rows:
        assert r["error"].startswith("import failed (exit 2)") and "--tolerance" in r["error"], r
        assert r["import_s"] > 0 and r["peak_gb"] > 0
        assert "--tolerance -1" in r["import_cmd"]
    # the Panda is imported with the SRDF example-robot-data ships, and its default state
    # as the home, as a MoveIt user would; the MJCF arm has none
    assert "panda.srdf --home default" in rows[0]["import_cmd"]
    assert "--srdf" not in rows[1]["import_cmd"]
    assert "| robot | dof | spheres |" in stdout and "ERROR import failed" in stdout
    assert doc["meets_acceptance"] == []
