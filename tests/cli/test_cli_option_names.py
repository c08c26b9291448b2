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


def test_calibrate_starts_without_end_is_refused_up_front(capsys, tmp_path):
    """Reliability round 3, item 4: ``calibrate --starts 1000000000`` ran for minutes with
    no bound or estimate: refused before any work, naming --starts and the figure."""
    setup, data = tmp_path / "s.json", tmp_path / "d.csv"
    setup.write_text("{}")
    data.write_text("")
    line = one_line_error(capsys, ["calibrate", "--setup", str(setup), "--data", str(data),
                                   "--starts", "1000000000"], "--starts")
    assert "1000000000" in line and "at most" in line


def test_plan_elastic_kappa_names_kappa(capsys):
    """``plan --elastic --kappa 1e308`` said "rho: contains NaN or inf"."""
    line = one_line_error(capsys, PLAN + ["--elastic", "--kappa", "1e308"], "--kappa")
    assert "rho" not in line and "does not converge" in line


def test_import_urdf_of_a_huge_link_ends_at_once(capsys, tmp_path):
    """Reliability round 3, items 4 and 9, shown by the command that failed: ``jwarp
    import-urdf --spheres fit`` of a link with a 10 m box (a URDF in cm), and of a normal
    link at --tolerance 1e-7, ran for minutes; now one line naming the tolerance at once."""
    import time
    template = (
        '<robot name="big"><link name="base"><collision><geometry><box size="{s} {s} {s}"/>'
        '</geometry></collision></link><link name="l1"/><joint name="j1" type="revolute">'
        '<parent link="base"/><child link="l1"/><axis xyz="0 0 1"/>'
        '<limit lower="-1" upper="1" effort="1" velocity="1"/></joint></robot>')
    for size, extra in (("10", []), ("1000", []), ("0.1", ["--tolerance", "1e-7"])):
        path = tmp_path / f"b{size}.urdf"
        path.write_text(template.format(s=size))
        t = time.perf_counter()
        line = one_line_error(capsys, ["import-urdf", str(path), "--out",
                                       str(tmp_path / "o.json"), "--spheres", "fit", *extra],
                              "URDF")
        assert "tolerance" in line and "cells" in line and time.perf_counter() - t < 30
