"""CLI hardening of ``fk``, ``show``, ``plan``, ``ik`` and the ``--world`` parser: every
error is one line ``jwarp: error: <option>: ...`` with exit status 2 (no traceback, no
usage lines for bad values), sizes are checked against their memory before any work,
output paths are checked before any work and written atomically."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from jwarp.cli import main

P4 = ["--robot", "planar4"]
START, GOAL = "1.2,0,0,0", "-1.2,0,0,0"


def plan_args(block: Path, *extra: str) -> list[str]:
    return ["plan", *P4, "--world", str(block), "--start", START, f"--goal={GOAL}",
            "--starts", "2", "--iterations", "2", "--waypoints", "4", "--substeps", "2", *extra]


IK = ["ik", *P4, "--frame", "tcp", "--target", "0.5,0.5,0", "--starts", "2",
      "--iterations", "2"]


def run(capsys, argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def one_line_error(capsys, argv, option: str) -> str:
    """Run argv; assert exit 2, nothing on stdout and exactly one stderr line
    ``jwarp: error: <option>: ...``; return that line."""
    code, out, err = run(capsys, argv)
    lines = err.splitlines()
    assert code == 2, (code, err)
    assert out == ""
    assert len(lines) == 1, err
    assert lines[0].startswith(f"jwarp: error: {option}: "), lines[0]
    return lines[0]


# ------------------------------------------------------------------ option values
@pytest.mark.parametrize("extra, option", [
    (["--lam", "inf"], "--lam"),
    (["--lam", "-inf"], "--lam"),
    (["--lam", "nan"], "--lam"),
    (["--lam", "0"], "--lam"),
    (["--lam", "2"], "--lam"),
    (["--lam", "abc"], "--lam"),
    (["--max-iter", "-1"], "--max-iter"),
    (["--max-iter", "1.5"], "--max-iter"),
    (["--kappa", "-inf"], "--kappa"),
])
def test_fk_elastic_bad_values(capsys, extra, option):
    one_line_error(capsys, ["fk", "planar4", "--elastic", *extra], option)


@pytest.mark.parametrize("extra, option", [
    (["--q", "1e39,0,0,0"], "--q"),
    (["--elastic", "--kappa", "1e300"], "--kappa"),
])
def test_fk_float32_overflow(capsys, extra, option):
    line = one_line_error(capsys, ["fk", "planar4", "--dtype", "float32", *extra], option)
    assert "overflow float32" in line


@pytest.mark.parametrize("device", ["nodevice", "cuda:99", ""])
def test_fk_unknown_device(capsys, device):
    line = one_line_error(capsys, ["fk", "planar4", "--device", device], "--device")
    assert "device" in line


def test_fk_max_iter_zero_allowed_and_not_converged(capsys):
    code, out, err = run(capsys, ["fk", "justin19", "--elastic", "--max-iter", "0"])
    assert code == 0
    assert "iterations = 0, converged = NO" in out
    assert "did not converge in 0 updates" in err


@pytest.mark.parametrize("extra, option", [
    (["--margin", "nan"], "--margin"),
    (["--margin", "-1"], "--margin"),
    (["--margin", "-inf"], "--margin"),
    (["--step", "-1"], "--step"),
    (["--step", "0"], "--step"),
    (["--step", "inf"], "--step"),
    (["--starts", "0"], "--starts"),
    (["--iterations", "-5"], "--iterations"),
    (["--iterations", str(10**22)], "--iterations"),
    (["--waypoints", "1"], "--waypoints"),
    (["--substeps", "-2"], "--substeps"),
    (["--seed", "-1"], "--seed"),
    (["--device", "cuda:99"], "--device"),
    (["--elastic", "--kappa", "-inf"], "--kappa"),
    # reliability round 3 (items 5): the option the user gave, never an internal name
    (["--margin", "1e308"], "--margin"),
    (["--margin", "1e30"], "--margin"),
    (["--elastic", "--kappa", "1e308"], "--kappa"),
    (["--endpoint-margin", "-1"], "--endpoint-margin"),
    (["--self-margin", "nan"], "--self-margin"),
    (["--time-limit", "-1"], "--time-limit"),
    # reliability round 4, item 8: accepted and ignored (it only relaxes the margin)
    (["--margin", "0.01", "--endpoint-margin", "0.05"], "--endpoint-margin"),
    (["--endpoint-margin", "0.001"], "--endpoint-margin"),       # default --margin 0
])
def test_plan_bad_values(capsys, block, extra, option):
    one_line_error(capsys, plan_args(block, *extra), option)


@pytest.mark.parametrize("start, option, message", [
    ("9,0,0,0", "--start", "outside the joint limits"),
    ("0,0,0,0", "--start", "in collision"),  # planar4 at zeros reaches into the block
])
def test_plan_solver_errors_name_the_option(capsys, block, start, option, message):
    argv = ["plan", *P4, "--world", str(block), "--start", start, f"--goal={GOAL}"]
    assert message in one_line_error(capsys, argv, option)


@pytest.mark.parametrize("extra, option", [
    (["--target", "-nan,0,0"], "--target"),
    (["--target", "1e300,0,0"], "--target"),
    (["--frame", "nope"], "--frame"),
    (["--starts", "0"], "--starts"),
    (["--iterations", "-1"], "--iterations"),
    (["--margin", "inf"], "--margin"),
    (["--elastic", "--kappa", "-inf"], "--kappa"),
    (["--device", "nodevice"], "--device"),
    (["--robot", "nobot"], "--robot"),
    # reliability round 4, item 9: "numeric overflow" named no option
    (["--tol-pos", "1e308"], "--tol-pos"),
    (["--tol-rot", "1e308"], "--tol-rot"),
    (["--tol-rot", "4"], "--tol-rot"),
    (["--seed", "-1"], "--seed"),
])
def test_ik_bad_values(capsys, extra, option):
    one_line_error(capsys, IK + extra, option)


# ------------------------------------------------------------------ memory
@pytest.mark.parametrize("extra, option", [
    (["--starts", str(10**10)], "--starts"),
    (["--waypoints", str(10**10)], "--waypoints"),
    (["--substeps", str(10**10)], "--substeps"),
])
def test_plan_batch_too_large_for_memory(capsys, block, extra, option):
    line = one_line_error(capsys, plan_args(block, *extra), option)
    assert "needs about" in line and "B of memory" in line and "available" in line


def test_ik_starts_too_large_for_memory(capsys):
    line = one_line_error(capsys, IK + ["--starts", str(10**12)], "--starts")
    assert "needs about" in line and "available" in line


@pytest.mark.parametrize("spec, message", [
    ("simplex:cells=1000000", "1000000 grid needs about"),
    ("simplex:cells=99999999999999999999", "grid needs about"),
    ("simplex:voxel=1e-9", "grid needs about"),
    ("simplex:feasible=1,samples=1000000000000", "1000000000000 sampled configurations"),
])
def test_world_too_large_for_memory(capsys, block, spec, message):
    argv = ["plan", *P4, "--world", spec, "--start", START, f"--goal={GOAL}"]
    line = one_line_error(capsys, argv, "--world")
    assert message in line and "available" in line


def test_world_spec_memory_figure_3d():
    from jwarp.world.io import parse_world_spec

    with pytest.raises(MemoryError, match=r"a 100000\^3 grid needs about .* TB of memory"):
        parse_world_spec("simplex:dim=3,cells=100000")


# ------------------------------------------------------------------ world specs and files
@pytest.mark.parametrize("spec, message", [
    ("simplex:seed=1,seed=2", "'seed' given twice"),
    ("simplex:feasible=-1", "feasible: expected an integer >= 0"),
    ("simplex:clear_base=5", "clear_base: expected an integer in [0, 1]"),
    ("simplex:cells=20,voxel=0.1", "'cells' or 'voxel', not both"),
    ("simplex:samples=5", "only meaningful with feasible=N"),
    ("simplex:voxel=-0.1", "voxel: expected a positive size"),
])
def test_world_spec_errors(capsys, spec, message):
    line = one_line_error(capsys, IK + ["--world", spec], "--world")
    assert message in line
    assert "world: world:" not in line


def _npz(path: Path, **arrays) -> Path:
    base = dict(format=np.array("jwarp.world"), version=np.array(1), sdf=np.ones((4, 4)),
                limits=np.array([[0.0, 3.0], [0.0, 3.0]]), voxel_size=np.array(1.0))
    base.update(arrays)
    np.savez(path, **{k: v for k, v in base.items() if v is not None})
    return path


@pytest.mark.parametrize("make, message", [
    (lambda p: p.write_text("not a zip archive at all"), "not a zip archive"),
    (lambda p: _npz(p, voxel_size=np.array("x")), "voxel_size: expected a number"),
    (lambda p: _npz(p, limits=np.array([[0.0, 3e300], [0.0, 3e300]]),
                    voxel_size=np.array(1e300)), "voxel_size"),
    (lambda p: _npz(p, sdf=np.full((4, 4), 1e300)), "sdf: values overflow float32"),
])
def test_bad_world_files(capsys, tmp_path, make, message):
    path = tmp_path / "w.npz"
    make(path)
    line = one_line_error(capsys, IK + ["--world", str(path)], "--world")
    assert str(path) in line and message in line


# ------------------------------------------------------------------ output paths
def _forbid(monkeypatch, module: str, name: str) -> None:
    def fail(*a, **k):
        raise AssertionError(f"{name} ran before the output path was checked")

    monkeypatch.setattr(module + "." + name, fail)


@pytest.mark.parametrize("where", ["missing", "folder", "empty", "under_a_file"])
def test_rerun_and_save_paths_checked_before_any_work(capsys, monkeypatch, tmp_path, block, where):
    pytest.importorskip("rerun")
    target = {"missing": tmp_path / "no" / "x.rrd", "folder": tmp_path,
              "empty": "", "under_a_file": block / "x.rrd"}[where]
    _forbid(monkeypatch, "jwarp.world.io", "parse_world_spec")
    _forbid(monkeypatch, "jwarp.solvers.ik", "ik")
    _forbid(monkeypatch, "jwarp.kinematics", "fk")
    one_line_error(capsys, plan_args(block, "--rerun", target), "--rerun")
    one_line_error(capsys, IK + ["--world", str(block), "--rerun", target], "--rerun")
    one_line_error(capsys, ["show", "planar4", "--elastic", "--out", target], "--out")
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_output_that_is_an_input_is_refused(capsys, tmp_path, block):
    pytest.importorskip("rerun")
    import jwarp

    world = tmp_path / "w.npz"
    world.write_bytes(block.read_bytes())
    line = one_line_error(capsys, plan_args(world, "--rerun", world), "--rerun")
    assert "is also --world" in line
    assert world.read_bytes() == block.read_bytes()
    robot = tmp_path / "r.json"
    jwarp.robot("planar4").save(robot)
    before = robot.read_bytes()
    line = one_line_error(capsys, ["show", robot, "--out", robot], "--out")
    assert "is also robot" in line and robot.read_bytes() == before


def test_plan_error_mid_run_keeps_old_recording(capsys, monkeypatch, tmp_path, block):
    pytest.importorskip("rerun")
    import jwarp.solvers.planning as PL

    target = tmp_path / "plan.rrd"
    target.write_bytes(b"old recording")
    real = PL.plan

    def plan_then_fail(*a, callback=None, **k):
        real(*a, callback=callback, **k)  # the recording gets data
        raise RuntimeError("device lost")

    monkeypatch.setattr(PL, "plan", plan_then_fail)
    code, out, err = run(capsys, plan_args(block, "--rerun", target))
    assert code == 2 and out == ""
    assert err.splitlines() == ["jwarp: error: RuntimeError: device lost (run with "
                                "JWARP_DEBUG=1 for the traceback)"]
    assert target.read_bytes() == b"old recording"
    assert [p.name for p in tmp_path.iterdir()] == ["plan.rrd"]


def test_show_interrupt_keeps_old_file(capsys, monkeypatch, tmp_path):
    pytest.importorskip("rerun")
    import jwarp.viz.robot as viz

    target = tmp_path / "show.rrd"
    target.write_bytes(b"old")
    real, calls = viz.log_robot, []

    def log_then_interrupt(*a, **k):
        calls.append(1)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return real(*a, **k)

    monkeypatch.setattr(viz, "log_robot", log_then_interrupt)
    try:
        code, out, err = run(capsys, ["show", "planar4", "--q", "zeros", "--q", "0.1,0,0,0",
                                      "--out", target])
    except KeyboardInterrupt:
        pytest.fail("KeyboardInterrupt escaped main()")
    assert code == 130 and err.splitlines() == ["jwarp: interrupted"]
    assert target.read_bytes() == b"old"
    assert [p.name for p in tmp_path.iterdir()] == ["show.rrd"]


# ------------------------------------------------------------------ exception policy
@pytest.mark.parametrize("exc, expect", [
    (KeyError("q"), "jwarp: error: KeyError: 'q' (run with JWARP_DEBUG=1 for the traceback)"),
    (IndexError("index 5 is out of bounds"),
     "jwarp: error: IndexError: index 5 is out of bounds (run with JWARP_DEBUG=1 for the "
     "traceback)"),
    (MemoryError("Unable to allocate 3 TiB"),
     "jwarp: error: out of memory: Unable to allocate 3 TiB"),
    (OverflowError("(34, 'Numerical result out of range')"),
     "jwarp: error: numeric overflow: (34, 'Numerical result out of range')"),
])
def test_unexpected_exceptions_one_line_and_debug_traceback(capsys, monkeypatch, exc, expect):
    import jwarp.cli.kinematics as cli

    def boom(args):
        raise exc

    monkeypatch.setattr(cli, "cmd_info", boom)
    code, out, err = run(capsys, ["info", "planar4"])
    assert code == 2 and err.splitlines() == [expect]
    monkeypatch.setenv("JWARP_DEBUG", "1")
    with pytest.raises(type(exc)):
        main(["info", "planar4"])


def test_module_entry_point_subcommand_error_is_one_line():
    """``python -m jwarp.cli plan ...``: the CLIError of a subcommand module is caught too."""
    r = subprocess.run([sys.executable, "-m", "jwarp.cli", "plan", *P4, "--world",
                        "simplex:colour=3", "--start", START, f"--goal={GOAL}"],
                       capture_output=True, text=True, timeout=300,
                       env={**os.environ, "JWARP_DEBUG": ""})
    assert r.returncode == 2, r.stderr
    assert "Traceback" not in r.stderr
    assert r.stderr.splitlines()[-1].startswith("jwarp: error: --world: unknown key 'colour'")
