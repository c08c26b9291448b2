"""Reliability round 3, items 5 and 6: errors name the option the user gave, not an
internal name (``plan --margin 1e308`` said "eps: ...", ``simulate-campaign --kappa 1e308``
"frames: contains NaN or inf"), and ``simulate-campaign --noise 1e308`` no longer writes
non-finite samples that ``calibrate`` then refuses (nothing is written)."""

from __future__ import annotations

from cli_helpers import one_line_error

PLAN = ["plan", "--robot", "planar4", "--world", "simplex:seed=0", "--start", "1.2,0,0,0",
        "--goal", "-1.2,0,0,0"]


def test_plan_margin_names_margin(capsys):
    line = one_line_error(capsys, PLAN + ["--margin", "1e308"], "--margin")
    assert "eps" not in line


def test_simulate_campaign_kappa_names_kappa(capsys, tmp_path):
    out = tmp_path / "c"
    line = one_line_error(capsys, ["simulate-campaign", "--robot", "justin19", "--kappa",
                                   "1e308", "--out", str(out)], "--kappa")
    assert "frames" not in line and not out.exists()


def test_simulate_campaign_noise_writes_nothing_non_finite(capsys, tmp_path):
    out = tmp_path / "c"
    one_line_error(capsys, ["simulate-campaign", "--robot", "justin19", "--noise", "1e308",
                            "--out", str(out)], "--noise")
    assert not out.exists()
