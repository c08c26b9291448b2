"""The ``jwarp`` command line: robots, info, fk (rigid/elastic), show, and its errors."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

import jwarp
from jwarp import kinematics
from jwarp.cli import main

ZEROS19 = ",".join(["0"] * 19)


def run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def run_json(capsys, *argv):
    code, out, err = run(capsys, *argv, "--json")
    assert code == 0, err
    return json.loads(out)


def test_robots_json_lists_justin19(capsys):
    rows = run_json(capsys, "robots")
    by_name = {r["name"]: r for r in rows}
    assert set(jwarp.robots()) == set(by_name)
    assert by_name["justin19"]["dof"] == 19
    assert by_name["justin19"]["frames"] == 27
    assert "right_tcp" in by_name["justin19"]["end_effectors"]


def test_robots_text(capsys):
    code, out, _ = run(capsys, "robots")
    assert code == 0
    assert any(line.split()[:3] == ["justin19", "19", "27"] for line in out.splitlines())


def test_info(capsys):
    code, out, _ = run(capsys, "info", "justin19")
    assert code == 0
    assert "19 DoF, 27 frames" in out
    doc = run_json(capsys, "info", "justin19")
    assert doc["name"] == "justin19" and len(doc["frames"]) == 27
    assert jwarp.RobotModel.from_dict(doc).n_dof == 19


def test_fk_json_zeros_matches_kinematics(capsys):
    d = run_json(capsys, "fk", "justin19", "--q", ZEROS19)
    assert d["robot"] == "justin19"
    assert d["q"] == [0.0] * 19
    assert len(d["frames"]) == 27
    ref = kinematics.fk("justin19", np.zeros(19), device="cpu", dtype=np.float64)
    model = jwarp.robot("justin19")
    i = model.frame_index("right_tcp")
    np.testing.assert_allclose(d["frames"]["right_tcp"], ref[i, :3, 3], rtol=0, atol=1e-12)
    np.testing.assert_allclose(d["end_effectors"]["left_tcp"],
                               ref[model.frame_index("left_tcp"), :3, 3], rtol=0, atol=1e-12)
    assert "iterations" not in d


def test_fk_q_zeros_keyword_and_negative_values(capsys):
    assert run_json(capsys, "fk", "justin19", "--q", "zeros")["frames"] == \
        run_json(capsys, "fk", "justin19", "--q", ZEROS19)["frames"]
    q = np.array([-0.5, 0.2, 0.4] + [-0.3, 0.5, 0.1, -1.0, 0.2, 0.3, 0.1] * 2 + [0.1, 0.2])
    d = run_json(capsys, "fk", "justin19", "--q", ",".join(map(repr, q.tolist())))
    np.testing.assert_allclose(d["q"], q)
    ref = kinematics.fk("justin19", q, device="cpu", dtype=np.float64)
    got = np.array(list(d["frames"].values()))
    np.testing.assert_allclose(got, ref[:, :3, 3], rtol=0, atol=1e-12)


def test_fk_degrees(capsys):
    deg = [10, 20, -30, 40, 0, 45, 90]
    d_deg = run_json(capsys, "fk", "arm7", "--q", ",".join(map(str, deg)), "--deg")
    d_rad = run_json(capsys, "fk", "arm7", "--q", ",".join(repr(v) for v in np.deg2rad(deg).tolist()))
    for name in d_rad["frames"]:
        np.testing.assert_allclose(d_deg["frames"][name], d_rad["frames"][name], atol=1e-12)


def test_fk_text_lists_every_frame(capsys):
    code, out, _ = run(capsys, "fk", "justin19", "--q", "zeros")
    assert code == 0
    for name in jwarp.robot("justin19").frame_names:
        assert f"\n{name} " in out


def test_fk_elastic_json(capsys):
    d = run_json(capsys, "fk", "justin19", "--q", ZEROS19, "--elastic")
    assert d["elastic"] is True
    assert d["kappa"] == pytest.approx(1e-4) and d["kappa_source"] == "default"
    assert d["iterations"] >= 1 and d["converged"] is True
    for tcp in ("right_tcp", "left_tcp"):
        assert d["sag_mm"][tcp]["norm"] > 1.0  # mm
    ref = kinematics.fk_elastic("justin19", np.zeros(19), 1e-4, device="cpu", dtype=np.float64)
    i = jwarp.robot("justin19").frame_index("right_tcp")
    np.testing.assert_allclose(d["frames"]["right_tcp"], ref.frames[i, :3, 3], atol=1e-12)
    assert d["iterations"] == int(ref.iterations)
    rigid = np.array(d["rigid_frames"]["right_tcp"])
    sag = 1e3 * (np.array(d["frames"]["right_tcp"]) - rigid)
    np.testing.assert_allclose([d["sag_mm"]["right_tcp"][k] for k in ("dx", "dy", "dz")], sag,
                               atol=1e-9)


def test_fk_elastic_zero_kappa_has_no_sag(capsys):
    d = run_json(capsys, "fk", "justin19", "--elastic", "--kappa", "0")
    assert d["kappa_source"] == "--kappa"
    assert all(s["norm"] < 1e-9 for s in d["sag_mm"].values())
    assert d["frames"] == d["rigid_frames"]


def test_fk_elastic_not_converged_warns(capsys):
    code, out, err = run(capsys, "fk", "justin19", "--elastic", "--max-iter", "2")
    assert code == 0
    assert "converged = NO" in out and "did not converge in 2 updates" in err


def test_fk_elastic_text(capsys):
    code, out, _ = run(capsys, "fk", "justin19", "--elastic", "--kappa", "1e-4,1e-4,2e-4",
                       "--lam", "0.8")
    assert code == 0
    assert "iterations =" in out and "converged = yes" in out
    assert "right_tcp" in out.split("end-effector ")[-1] and "left_tcp" in out


@pytest.mark.parametrize("argv, message", [
    (["fk", "nobot"], "unknown robot 'nobot'"),
    (["info", "nobot"], "unknown robot 'nobot'"),
    (["fk", "justin19", "--q", "1,2,3"], "has 19 joints"),
    (["fk", "justin19", "--q", ",".join(["0"] * 18 + ["abc"])], "value 19 ('abc') is not a number"),
    (["fk", "justin19", "--q", ",".join(["0"] * 18 + ["nan"])], "must be finite"),
    (["fk", "justin19", "--q", ",".join(["inf"] + ["0"] * 18)], "must be finite"),
    (["fk", "justin19", "--q", ""], "has 19 joints"),
    (["fk", "justin19", "--elastic", "--kappa", "-1"], "--kappa"),
    (["fk", "justin19", "--elastic", "--kappa", "x"], "--kappa"),
    (["fk", "justin19", "--kappa", "1e-4"], "only meaningful with --elastic"),
    (["fk", "justin19", "--elastic", "--lam", "0"], "lam"),
    (["fk", "justin19", "--device", "nodevice"], "device"),
    (["fk"], "required"),
    ([], "required"),
    (["frobnicate"], "invalid choice"),
    (["show", "justin19"], "--out"),
])
def test_bad_input_exit_code_2(capsys, argv, message):
    code, out, err = run(capsys, *argv)
    assert code == 2
    assert "jwarp: error:" in err and message in err
    assert "Traceback" not in err
    assert out == ""


def test_help_exits_0(capsys):
    code, out, _ = run(capsys, "--help")
    assert code == 0 and "fk" in out


def test_show_writes_rrd(capsys, tmp_path):
    pytest.importorskip("rerun")
    target = tmp_path / "j.rrd"
    code, out, err = run(capsys, "show", "justin19", "--q", "zeros", "--q",
                         ",".join(["0.1"] * 19), "--elastic", "--out", str(target))
    assert code == 0, err
    assert target.stat().st_size > 0 and str(target) in out
    assert [p.name for p in tmp_path.iterdir()] == ["j.rrd"]


def test_show_missing_folder(capsys, tmp_path):
    pytest.importorskip("rerun")
    code, _, err = run(capsys, "show", "justin19", "--out", str(tmp_path / "no" / "x.rrd"))
    assert code == 2 and "does not exist" in err


def test_module_entry_point_exit_status():
    """The real process: exit status 2 and a one-line error, no traceback."""
    r = subprocess.run([sys.executable, "-m", "jwarp.cli", "fk", "justin19", "--q", "1,2"],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 2
    assert "jwarp: error: --q: robot 'justin19' has 19 joints" in r.stderr
    assert "Traceback" not in r.stderr
