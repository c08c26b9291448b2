"""Issue 27, items 2 and 5 on the CLI: one vocabulary (``--out`` with deprecated hidden
aliases, ``--device`` wherever work runs on a device, the defaults that differ from the
Python API named in ``--help``), joint names beside printed configurations, float64 JSON
endpoints, ``costs_explained``, ``free-config``; and no lost work: a read-only database,
memory estimates before any labelling, damaged database rows named (and skipped), a
checkpoint whose config does not match its weights refused before any allocation."""

from __future__ import annotations

import inspect
import json
import os
import sqlite3
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from cli_helpers import one_line_error, q_text, run  # tests/cli_helpers.py

import jwarp
from jwarp.cli.main import build_parser
from jwarp.learn import generate as gen

ROOT = Path(__file__).resolve().parents[2]


# ------------------------------------------------------------------ tiny databases
def _world(seed: int):
    from jwarp.world.sdf import world_from_occupancy

    occ = np.random.default_rng(seed).random((8, 8)) < 0.2
    w = world_from_occupancy(occ, np.array([[-1.0, -0.3], [-1.0, -0.3]]), 0.1)
    w.meta = {"seed": seed}
    return w


def _labels(seed: int, n: int = 3, w: int = 4, n_dof: int = 5):
    rng = np.random.default_rng(100 + seed)
    s = rng.uniform(-1, 1, (n, n_dof)).astype(np.float32)
    g = rng.uniform(-1, 1, (n, n_dof)).astype(np.float32)
    return SimpleNamespace(starts=s, goals=g, paths=np.linspace(s, g, w, axis=1),
                           cost=np.ones(n), feasible=np.ones(n, bool),
                           hard=np.zeros(n, bool), settings={})


def _db(path: Path, seeds=(0, 1, 2)) -> Path:
    """A planar5 path database of 3 worlds x 3 paths x 4 waypoints."""
    from jwarp.learn.dataset import PathDB, world_record

    with PathDB(path, jwarp.robot("planar5"), create=True) as db:
        for s in seeds:
            assert db.add_world(world_record(s, _world(s), _labels(s)))
    return path


def _no_labelling(monkeypatch):
    """Any labelling (or world making) fails the test: the checks must come first."""
    def forbidden(*a, **k):
        raise AssertionError("work started before the checks")

    monkeypatch.setattr(gen, "default_labeler", lambda: forbidden)
    monkeypatch.setattr(gen, "default_world_maker", lambda: forbidden)


# ------------------------------------------------------------------ --out and its aliases
@pytest.mark.parametrize("argv, old", [
    (["show", "planar4", "--save", "x.rrd"], "--save"),
    (["data", "export", "d.sqlite", "--npz", "x.npz"], "--npz"),
    (["sensitivity", "--setup", "s.json", "--task-setup", "t.json", "--png", "x.png"], "--png"),
])
def test_old_output_spellings_are_deprecated_aliases_of_out(capsys, argv, old):
    args = build_parser().parse_args(argv)
    err = capsys.readouterr().err
    assert args.out == argv[argv.index(old) + 1]
    assert err.splitlines() == [f"jwarp: warning: {old} is deprecated; use --out"]
    new = [("--out" if a == old else a) for a in argv]
    assert build_parser().parse_args(new).out == args.out
    assert capsys.readouterr().err == ""           # the new spelling: no warning


def test_aliases_are_hidden_and_out_is_listed(capsys):
    for argv, old in ((["show", "--help"], "--save"), (["data", "export", "--help"], "--npz"),
                      (["sensitivity", "--help"], "--png")):
        code, out, _ = run(capsys, argv)
        assert code == 0 and "--out" in out and old not in out, argv


def test_required_out_given_by_neither_spelling(capsys, tmp_path):
    one_line_error(capsys, ["show", "planar4"], "--out")
    one_line_error(capsys, ["data", "export", _db(tmp_path / "d.sqlite")], "--out")


def test_data_export_with_the_old_spelling_writes_the_file(capsys, tmp_path):
    db = _db(tmp_path / "d.sqlite")
    code, out, err = run(capsys, ["data", "export", db, "--npz", tmp_path / "d.npz"])
    assert code == 0 and "9 paths" in out
    assert "jwarp: warning: --npz is deprecated; use --out" in err
    with np.load(tmp_path / "d.npz") as z:
        assert z["path"].shape == (9, 4, 5)


# ------------------------------------------------------------------ help and defaults
def _subparsers(parser=None, prefix=()):
    import argparse

    parser = parser or build_parser()
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                kids = list(_subparsers(sub, prefix + (name,)))
                yield from kids or [(" ".join(prefix + (name,)), sub)]


#: commands whose work runs on a Warp or torch device
COMPUTING = ("fk", "ik", "plan", "free-config", "data generate", "sample-poses", "eval ik",
             "eval plan", "train ik", "train plan")


def test_device_on_every_computing_command():
    cmds = dict(_subparsers())
    assert set(COMPUTING) <= set(cmds)
    for name in COMPUTING:
        opts = {o for a in cmds[name]._actions for o in a.option_strings}
        assert "--device" in opts, name


def test_top_level_help_lists_every_train_and_eval_command(capsys):
    code, out, _ = run(capsys, ["--help"])
    assert code == 0
    for text in ("train ik", "train plan", "eval ik", "eval plan"):
        assert text in " ".join(out.split()), text


def _help_of(command: list[str], option: str, capsys) -> str:
    code, out, _ = run(capsys, command + ["--help"])
    assert code == 0
    text = " ".join(out.split())
    text = text[text.index("options:"):]             # past the usage lines
    return text[text.index(option):]


def test_defaults_that_differ_from_the_python_api_are_named_in_help(capsys):
    from jwarp.cli.common import DEFAULT_MAX_ITER
    from jwarp.kinematics.equilibrium import fk_elastic
    from jwarp.solvers.planning import PlanOptions

    api = inspect.signature(fk_elastic).parameters["max_iter"].default
    assert api != DEFAULT_MAX_ITER  # the difference the help must name
    h = _help_of(["fk"], "--max-iter", capsys)
    assert f"default {DEFAULT_MAX_ITER}" in h and f"default is {api}" in h[:300]
    api = PlanOptions.iterations  # plan()'s options are PlanOptions' fields
    parser = dict(_subparsers())["plan"]
    cli = next(a.default for a in parser._actions if "--iterations" in a.option_strings)
    assert cli != api
    h = _help_of(["plan"], "--iterations", capsys)
    assert f"default {cli}" in h[:200] and f"default is {api}" in h[:200]


def _defaults(command: str) -> dict:
    return {a.dest: a.default for a in dict(_subparsers())[command]._actions
            if a.option_strings}


@pytest.mark.parametrize("command, api, names", [
    ("plan", "jwarp.solvers.planning:PlanOptions",
     {"step": "step", "margin": "margin", "seed": "seed", "self_margin": "self_margin",
      "fallback": "fallback", "stop_when_solved": "stop_when_solved"}),
    ("ik", "jwarp.solvers.ik:IKOptions",
     {"iterations": "iterations", "margin": "margin", "seed": "seed"}),
    ("train ik", "jwarp.learn.train_ik:TrainIKOptions",
     {"targets_per_world": "n_targets", "val_targets": "n_val", "hidden": "hidden",
      "n_bps": "n_bps", "batch": "batch_size", "steps_per_epoch": "steps_per_epoch",
      "lr": "lr", "mix": "mix", "seed": "seed"}),
    ("train plan", "jwarp.learn.train_plan:TrainPlanOptions",
     {"n_bps": "n_bps", "hidden": "hidden", "blocks": "n_blocks", "heads": "n_heads",
      "batch": "batch_size", "steps_per_epoch": "steps_per_epoch", "lr": "lr"}),
    ("calibrate", "jwarp.calibration:CalibrationOptions",
     {"max_nfev": "max_nfev", "starts": "n_starts", "seed": "seed"}),
])
def test_cli_defaults_equal_the_python_api(command, api, names):
    """Every other default the CLI shares with the Python API is the API's own."""
    import dataclasses
    import importlib

    mod, name = api.split(":")
    obj = getattr(importlib.import_module(mod), name)
    if dataclasses.is_dataclass(obj):
        ref = {f.name: f.default for f in dataclasses.fields(obj)}
    else:
        ref = {k: p.default for k, p in inspect.signature(obj).parameters.items()}
    cli = _defaults(command)
    for opt, param in names.items():
        assert cli[opt] == ref[param], (command, opt, cli[opt], ref[param])


def test_implicit_defaults_of_plan_and_ik_equal_the_api(capsys):
    """--starts/--waypoints of plan and --starts of ik are filled in at run time (a warm
    start changes them): the help names the API's values."""
    import re

    from jwarp.solvers.ik import IKOptions
    from jwarp.solvers.planning import PlanOptions
    from jwarp.solvers.planning.options import N_STARTS

    assert PlanOptions.n_starts is None  # the device's: the help names the CPU's first
    for cmd, opt, n in ((["plan"], "--starts", N_STARTS["cpu"]),
                        (["plan"], "--waypoints", PlanOptions.n_waypoints),
                        (["ik"], "--starts", IKOptions.n_starts)):
        assert re.search(rf"\(default {n}\b", _help_of(cmd, opt, capsys)[:250]), (cmd, opt)


# ------------------------------------------------------------------ configurations
@pytest.fixture(scope="module")
def free_pair():
    """Two collision-free planar4 configurations in simplex:seed=3 from free-config."""
    import contextlib
    import io

    from jwarp.cli import main

    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        code = main(["free-config", "--robot", "planar4", "--world", "simplex:seed=3",
                     "--n", "2", "--seed", "4", "--json"])
    assert code == 0
    return json.loads(buf.getvalue())


def test_free_config_configurations_are_free_and_within_limits(free_pair):
    import jwarp
    from jwarp.world.collision import min_distances
    from jwarp.world.io import parse_world_spec

    model = jwarp.robot("planar4")
    q = np.array(free_pair["configurations"])
    assert q.shape == (2, 4) and free_pair["joint_names"] == list(model.joint_names)
    lim = model.joint_limits
    assert np.all((q >= lim[:, 0]) & (q <= lim[:, 1]))
    md = min_distances(model, q, parse_world_spec("simplex:seed=3", robot=model))
    assert np.all(md > 0)


def test_free_config_text_names_joints_and_seed_matters(capsys):
    import jwarp

    code, out, _ = run(capsys, ["free-config", "--robot", "planar4", "--world",
                                "simplex:seed=3", "--seed", "1"])
    assert code == 0
    for name in jwarp.robot("planar4").joint_names:
        assert any(line.split()[:1] == [name] for line in out.splitlines()), name
    start = [ln for ln in out.splitlines() if ln.startswith("--start ")]
    code, out2, _ = run(capsys, ["free-config", "--robot", "planar4", "--world",
                                 "simplex:seed=3", "--seed", "2"])
    assert len(start) == 1 and start[0] not in out2


def test_plan_json_float64_endpoints_names_and_costs(capsys, free_pair):
    q0, q1 = free_pair["configurations"]
    code, out, err = run(capsys, ["plan", "--robot", "planar4", "--world", "simplex:seed=3",
                                  "--start", q_text(q0), "--goal", q_text(q1), "--json"])
    assert code in (0, 1), err
    d = json.loads(out)
    assert d["start"] == q0 and d["goal"] == q1      # float64, not float32-rounded
    assert d["path"][0] == q0 and d["path"][-1] == q1
    assert any(float(np.float32(v)) != v for v in q0)  # the check can fail
    assert d["joint_names"] == ["joint_1", "joint_2", "joint_3", "joint_4"]
    c, e = d["costs"], d["costs_explained"]
    assert set(c) == {"total", "length", "collision"}
    w = e["weights"]["length"]
    assert c["total"] == pytest.approx(c["collision"] + w * c["length"], rel=1e-5, abs=1e-6)
    assert f"collision + {w:g} x length" in e["explained"]


def test_ik_and_plan_text_print_joint_names(capsys, free_pair):
    import jwarp

    names = jwarp.robot("planar4").joint_names
    code, out, _ = run(capsys, ["ik", "--robot", "planar4", "--frame", "tcp", "--target",
                                "0.5,0.5,0", "--starts", "4"])
    rows = {ln.split()[0]: float(ln.split()[1]) for ln in out.splitlines()
            if ln.strip() and ln.split()[0] in names}
    assert code == 0 and list(rows) == list(names)
    # the printed solution reaches the target (numpy FK of the model, not the solver's)
    q = np.array([rows[n] for n in names])
    F = jwarp.fk("planar4", q, device="cpu")
    tcp = F[jwarp.robot("planar4").frame_index("tcp")]
    assert np.allclose(tcp[:2, 3], [0.5, 0.5], atol=1e-3)
    q0, q1 = free_pair["configurations"]
    code, out, _ = run(capsys, ["plan", "--robot", "planar4", "--world", "simplex:seed=3",
                                "--start", q_text(q0), "--goal", q_text(q1)])
    table = [ln.split() for ln in out.splitlines() if ln.strip().split()[:1] and
             ln.split()[0] in names]
    assert [r[0] for r in table] == list(names)
    assert all(len(r) == 21 for r in table)          # name + 20 waypoints
    assert "= collision" in out and "x length" in out
    code, out, _ = run(capsys, ["fk", "planar4", "--q", "0.1,0.2,0.3,0.4"])
    qline = next(ln for ln in out.splitlines() if ln.startswith("q [rad/m]"))
    assert code == 0 and qline.endswith(
        ", ".join(f"{n}={v:g}" for n, v in zip(names, (0.1, 0.2, 0.3, 0.4))))


# ------------------------------------------------------------------ no lost work
def test_read_only_database_or_folder_refused_before_labelling(capsys, tmp_path, monkeypatch):
    """os.access is patched: the tests may run as root, whom chmod does not stop."""
    db = _db(tmp_path / "d.sqlite")
    before = db.read_bytes()
    _no_labelling(monkeypatch)
    real = os.access
    argv = ["data", "generate", "--robot", "planar5", "--worlds", 5, "--paths-per-world", 3,
            "--db", db, "--quiet"]
    monkeypatch.setattr(os, "access", lambda p, m, **k: False if Path(p) == db
                        else real(p, m, **k))
    line = one_line_error(capsys, argv, "--db")
    assert "read-only" in line and str(db) in line
    monkeypatch.setattr(os, "access", lambda p, m, **k: False if Path(p) == tmp_path
                        else real(p, m, **k))
    line = one_line_error(capsys, argv, "--db")
    assert "folder" in line and "journal" in line
    assert db.read_bytes() == before


def test_memory_estimates_refuse_before_labelling(capsys, tmp_path, monkeypatch):
    _no_labelling(monkeypatch)
    base = ["data", "generate", "--robot", "planar4", "--worlds", 1, "--db",
            tmp_path / "d.sqlite", "--quiet"]
    line = one_line_error(capsys, base + ["--paths-per-world", 10**7], "--paths-per-world")
    assert "needs about" in line and "TB" in line
    line = one_line_error(capsys, base + ["--paths-per-world", 10, "--n-waypoints", 10**5],
                          "--n-waypoints")
    assert "needs about" in line
    assert not (tmp_path / "d.sqlite").exists()


def test_network_memory_refused_before_any_data(capsys, tmp_path, monkeypatch):
    """--hidden 65536: ~26e9 parameters (counted on torch's meta device), hundreds of GB
    to train; refused before any world or target is made."""
    import importlib

    def forbidden(*a, **k):
        raise AssertionError("data made before the memory check")

    # (jwarp.learn re-exports functions named like these modules: import them by name)
    tik = importlib.import_module("jwarp.learn.train_ik")
    tp = importlib.import_module("jwarp.learn.train_plan")
    monkeypatch.setattr(tik, "make_ik_data", forbidden)
    monkeypatch.setattr(tp, "make_plan_data", forbidden)
    for cmd in (["train", "ik"], ["train", "plan"]):
        line = one_line_error(capsys, cmd + ["--robot", "planar4", "--epochs", 1, "--hidden",
                                             65536, "--out", tmp_path / "m.pt"], "--hidden")
        assert "needs about" in line and "GB" in line
    line = one_line_error(capsys, ["train", "plan", "--robot", "planar4", "--epochs", 1,
                                   "--tasks-per-world", 10**7, "--out", tmp_path / "m.pt"],
                          "--tasks-per-world")
    assert "needs about" in line
    assert not (tmp_path / "m.pt").exists()


def test_sampling_sizes_refused_before_sampling(capsys, tmp_path):
    """sample-poses --batch-size and design --write-candidates: refused by the memory
    estimate before any draw (a simulated campaign's setup)."""
    from jwarp.calibration.simulate.scenarios import scenario

    setup, _, _ = scenario("justin19", "cartesian")
    path = tmp_path / "setup.json"
    from jwarp.calibration.files import write_setup

    write_setup(path, setup)
    line = one_line_error(capsys, ["sample-poses", "--setup", path, "--n", 10, "--batch-size",
                                   10**9, "--out", tmp_path / "p.csv"], "--batch-size")
    assert "needs about" in line
    line = one_line_error(capsys, ["design", "--setup", path, "--write-candidates", 10**9,
                                   "--out", tmp_path / "p.csv"], "--write-candidates")
    assert "needs about" in line and not (tmp_path / "p.csv").exists()


def test_damaged_world_blob_named_and_skipped(capsys, tmp_path):
    db = _db(tmp_path / "d.sqlite")
    con = sqlite3.connect(db)
    con.execute("UPDATE worlds SET occupancy = ? WHERE world_id = 1", (b"not zlib at all",))
    con.execute("UPDATE paths SET waypoints = substr(waypoints, 1, 8) "
                "WHERE world_id = 2 AND task = 1")
    con.commit()
    con.close()
    line = one_line_error(capsys, ["data", "export", db, "--out", tmp_path / "x.npz"], "DB")
    assert str(db) in line and "world 1" in line and "world_id=1" in line
    assert "occupancy" in line and "--skip-damaged" in line
    assert not (tmp_path / "x.npz").exists()
    code, out, err = run(capsys, ["data", "export", db, "--out", tmp_path / "x.npz",
                                  "--skip-damaged"])
    assert code == 0, err
    warn = [ln for ln in err.splitlines() if ln.startswith("jwarp: warning: skipped")]
    assert len(warn) == 2 and "world 1" in warn[0] and "task=1" in warn[1]
    with np.load(tmp_path / "x.npz") as z:
        assert list(z["worlds"]) == [0, 2]
        assert sorted(zip(z["world_id"], z["task"])) == [(0, 0), (0, 1), (0, 2), (2, 0), (2, 2)]
        np.testing.assert_array_equal(z["path"][0], _labels(0).paths[0].astype(np.float32))
    assert "5 paths" in out


def test_train_plan_data_damaged_named_and_skipped(capsys, tmp_path):
    from jwarp.learn.dataset import DamagedRowError
    from jwarp.learn.train_plan import samples_from_db

    db = _db(tmp_path / "d.sqlite")
    con = sqlite3.connect(db)
    con.execute("UPDATE worlds SET occupancy = x'0102' WHERE world_id = 1")
    con.execute("UPDATE paths SET waypoints = x'00' WHERE world_id = 2 AND task = 0")
    con.commit()
    con.close()
    line = one_line_error(capsys, ["train", "plan", "--robot", "planar5", "--data", db,
                                   "--all-paths", "--epochs", 1, "--out",
                                   tmp_path / "m.pt"], "--data")
    assert "world 2" in line and "task=0" in line and str(db) in line
    assert "--skip-damaged" in line and not (tmp_path / "m.pt").exists()
    skipped: list = []
    s = samples_from_db(db, jwarp.robot("planar5"), hard_only=False, skip_damaged=True, skipped=skipped)
    assert s.world_ids == [0, 2] and len(s.starts) == 5
    assert [(k["world_id"], k["task"]) for k in skipped] == [(1, None), (2, 0)]
    with pytest.raises(DamagedRowError) as e:    # the row, not "mixed waypoint counts"
        samples_from_db(db, jwarp.robot("planar5"), hard_only=False, world_ids=[2])
    assert "task=0" in str(e.value) and "mixes" not in str(e.value)
    one_line_error(capsys, ["train", "plan", "--robot", "planar5", "--skip-damaged",
                            "--epochs", 1, "--out", tmp_path / "m.pt"], "--skip-damaged")


def test_damaged_path_row_named_without_skip(tmp_path):
    from jwarp.learn.dataset import DamagedRowError, PathDB

    db = _db(tmp_path / "d.sqlite")
    con = sqlite3.connect(db)
    con.execute("UPDATE paths SET start = x'00' WHERE world_id = 0 AND task = 2")
    con.commit()
    con.close()
    with PathDB(db) as d, pytest.raises(DamagedRowError) as e:
        d.paths_of([0])
    assert e.value.world_id == 0 and e.value.task == 2
    assert str(db) in str(e.value) and "task=2" in str(e.value)


def test_checkpoint_config_checked_before_any_allocation(tmp_path):
    """A 5 kB checkpoint whose config says hidden=40000 (6.4 GB of weights): one line
    naming --model, and the process never grows by gigabytes (a subprocess: its own
    peak RSS)."""
    torch = pytest.importorskip("torch")
    import jwarp
    from jwarp.learn.checkpoint import save_checkpoint
    from jwarp.learn.ik_net import IKNet, IKNetConfig

    net = IKNet(IKNetConfig(robot="planar4", frame="tcp", hidden=8, n_blocks=1))
    net.robot = jwarp.robot("planar4")
    small = tmp_path / "small.pt"
    save_checkpoint(small, net)
    doc = torch.load(small, weights_only=True)
    doc["config"]["hidden"] = 40000
    forged = tmp_path / "forged.pt"
    torch.save(doc, forged)
    assert forged.stat().st_size < 20_000
    code = ("import resource, sys; from jwarp.cli import main; "
            f"rc = main(['eval', 'ik', '--robot', 'planar4', '--world', 'none', "
            f"'--model', {str(forged)!r}]); "
            "print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss); sys.exit(rc)")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       cwd=ROOT, timeout=300)
    lines = [ln for ln in p.stderr.splitlines() if not ln.startswith("Warp CUDA")]
    assert p.returncode == 2 and len(lines) == 1, p.stderr
    assert lines[0].startswith(f"jwarp: error: --model: '{forged}'")
    assert "hidden=40000" in lines[0] and "does not match its weights" in lines[0]
    assert int(p.stdout.split()[-1]) < 3_000_000   # kB: far below the 6.4 GB of weights


def test_checkpoint_matching_config_still_loads(tmp_path):
    pytest.importorskip("torch")
    import jwarp
    from jwarp.learn.checkpoint import load_checkpoint, save_checkpoint
    from jwarp.learn.ik_net import IKNet, IKNetConfig

    net = IKNet(IKNetConfig(robot="planar4", frame="tcp", hidden=8, n_blocks=1))
    net.robot = jwarp.robot("planar4")
    save_checkpoint(tmp_path / "a.pt", net)
    back = load_checkpoint(tmp_path / "a.pt")
    for (k, v), (k2, v2) in zip(net.state_dict().items(), back.state_dict().items()):
        assert k == k2 and bool((v == v2).all())
