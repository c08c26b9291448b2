"""``jwarp plan`` budgets: --stop-when-solved (default) / --no-stop-when-solved,
--time-limit, --fallback rrt|none; the stop reason and the solving stage in the text and
JSON output; bad values are one-line errors naming the option."""

from __future__ import annotations

import json

import pytest
from cli_helpers import one_line_error, run

START, GOAL = "1.2,0,0,0", "-1.2,0,0,0"


def plan_args(block, *extra):
    return ["plan", "--robot", "planar4", "--world", str(block), "--start", START,
            f"--goal={GOAL}", *extra]


def plan_json(capsys, block, *extra):
    code, out, err = run(capsys, plan_args(block, *extra, "--json"))
    doc = json.loads(out)
    assert code == (0 if doc["feasible"] else 1), err
    return doc


def test_defaults_stop_when_solved_and_fall_back(capsys, block):
    # 3 iterations of 2 starts do not solve it; the RRT-Connect fallback does
    doc = plan_json(capsys, block, "--starts", "2", "--iterations", "3")
    assert doc["feasible"] and doc["stage"] == "fallback" and doc["stop_reason"] == "solved"
    assert doc["start_index"] == -1
    doc = plan_json(capsys, block, "--starts", "2", "--iterations", "3", "--fallback", "none")
    assert not doc["feasible"] and doc["stage"] == "none"
    assert doc["stop_reason"] == "iterations"


def test_stop_when_solved_flags(capsys, block):
    common = ("--starts", "8", "--iterations", "300", "--step", "0.05", "--substeps", "8",
              "--fallback", "NONE")
    first = plan_json(capsys, block, *common)
    again = plan_json(capsys, block, *common, "--stop-when-solved")
    every = plan_json(capsys, block, *common, "--no-stop-when-solved")
    assert first["stop_reason"] == again["stop_reason"] == "solved"
    assert first["stage"] == "optimizer" and first["path"] == again["path"]
    assert every["stop_reason"] in ("iterations", "all_done")
    assert every["n_feasible_starts"] > first["n_feasible_starts"]


def test_time_limit(capsys, block):
    doc = plan_json(capsys, block, "--starts", "1", "--step", "1e-9", "--iterations",
                    "1000000000", "--time-limit", "0.3", "--fallback", "none")
    assert doc["stop_reason"] == "time_limit" and not doc["feasible"]
    assert 0.3 <= doc["wall_time_s"] < 3.0


def test_text_output_names_the_stop_reason_and_stage(capsys, block):
    code, out, err = run(capsys, plan_args(block, "--starts", "2", "--iterations", "3"))
    assert code == 0, err
    assert "stopped: solved; stage: fallback (solved by the fallback" in out
    code, out, err = run(capsys, plan_args(block, "--starts", "2", "--iterations", "3",
                                           "--fallback", "none"))
    assert code == 1
    assert "stopped: iterations; stage: none (not solved)" in out


@pytest.mark.parametrize("extra, option", [
    (["--time-limit", "-1"], "--time-limit"),
    (["--time-limit", "0"], "--time-limit"),
    (["--time-limit", "nan"], "--time-limit"),
    (["--time-limit", "inf"], "--time-limit"),
    (["--time-limit", "1s"], "--time-limit"),
    (["--fallback", "prm"], "--fallback"),
    (["--fallback", ""], "--fallback"),
    (["--shorten-budget", "0"], "--shorten-budget"),
    (["--shorten-budget", "-1"], "--shorten-budget"),
    (["--shorten-budget", "nan"], "--shorten-budget"),
    (["--shorten-budget", "all"], "--shorten-budget"),
])
def test_bad_values_name_the_option(capsys, block, extra, option):
    line = one_line_error(capsys, plan_args(block, *extra), option)
    if option == "--time-limit":
        assert "expected a number > 0 [s]" in line
    elif option == "--shorten-budget":
        assert "expected a number > 0" in line
    else:
        assert "expected 'rrt' or 'none'" in line


def test_shorten_budget_values(capsys, block):
    """--shorten-budget SHARE|none reaches PlanOptions.shorten_budget (default 0.5)."""
    from jwarp.cli.main import build_parser

    p = build_parser()
    base = plan_args(block)
    assert p.parse_args(base).shorten_budget == 0.5
    assert p.parse_args(base + ["--shorten-budget", "none"]).shorten_budget is None
    assert p.parse_args(base + ["--shorten-budget", "0.5"]).shorten_budget == 0.5
    common = ("--starts", "8", "--iterations", "300", "--step", "0.05", "--substeps", "8",
              "--fallback", "none")
    free = plan_json(capsys, block, *common, "--shorten-budget", "none")
    default = plan_json(capsys, block, *common)
    assert free["costs"]["length"] <= default["costs"]["length"] + 1e-6
    assert default["length_before_shortening"] >= default["costs"]["length"]
