"""Smoke test of benchmarks/bench_scenes.py: ``--quick`` on one problem of two families
(generated, planned at both margins on the CPU, verified, and the OMPL baseline where it
is installed) exits 0 and the independent verifier finds no collision on any path jwarp
called feasible (the timings are not checked)."""

from __future__ import annotations

import pytest


def test_bench_scenes_quick(run_bench):
    from jwarp.importers.robot import example_robot_urdf

    try:
        example_robot_urdf("panda_description/urdf/panda.urdf")
    except ValueError as e:
        pytest.skip(str(e))
    stdout, doc = run_bench("bench_scenes.py", "--quick", "--per-family", "1",
                            "--families", "table_pick,bookshelf_small", "--device", "cpu",
                            timeout=300)
    assert stdout.startswith("machine: "), stdout
    assert doc["n_problems"] == 2 and doc["margins"] == [0.0, 0.01]
    assert doc["endpoint_margin"] == 0.0
    jw = [r for r in doc["rows"] if r["planner"] == "jwarp"]
    assert len(jw) == 4
    solved = [r for r in jw if r["solved"]]
    assert solved, stdout
    for r in solved:   # every feasible path was re-checked: no collision, no margin broken
        assert r["length_ratio"] >= 1.0 - 1e-6, r  # U_l: 1 for the straight line
        assert "collision" in r, r
        assert not r["collision"], r
        assert not r["sphere_margin_violation"], r
    assert doc["jwarp_collisions"] == 0
    for s in doc["summary"]:
        assert s["problems"] == 2 and 0 <= s["solved"] <= 2
        assert s["median_s"] <= s["p95_s"] <= s["max_s"]
        if s["solved"] and s["planner"] == "jwarp":
            assert 1.0 - 1e-6 <= s["median_length_ratio"] <= s["p95_length_ratio"]


def test_versus_variants_are_parsed():
    """``--versus "a=1;b=null"``: the plain options first, then each variant's fields."""
    import argparse
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
    import bench_scenes

    args = argparse.Namespace(versus=["via_ik=0", "via_ik=2;via_frame=\"tcp\""], option=None)
    assert bench_scenes.variants(args) == [
        ("", {}), ("via_ik=0", {"via_ik": 0}),
        ('via_ik=2;via_frame="tcp"', {"via_ik": 2, "via_frame": "tcp"})]
    assert bench_scenes.variants(argparse.Namespace(versus=None, option=None)) == [("", {})]


def test_near_goals_counts_the_index_clearances():
    """Goals near an object, by the index's mesh clearance: <= 1 cm and <= 2 cm; None
    where a problem lacks it."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
    import bench_scenes

    index = {"problems": [{"clearance_m": {"goal_mesh": v}} for v in (0.004, 0.01, 0.015, 0.3)]}
    assert bench_scenes.near_goals(index) == (2, 4, 3)
    index["problems"].append({})
    assert bench_scenes.near_goals(index) is None
