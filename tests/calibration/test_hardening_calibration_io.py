"""Hardening of the calibration commands and their files: outputs checked before any work,
atomic multi-file sets (campaign folder; --out + --params-out) that survive SIGKILL at any
moment, row selection, file encodings, and one-line CLI errors for bad option values."""

from __future__ import annotations

import json
import os
import random
import re
import shutil
import signal
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import pytest

import jwarp
from jwarp.calibration.files import (
    DataWarning,
    make_measurement,
    parse_samples,
    read_samples,
    read_setup,
    sha256_hex,
)
from jwarp.calibration.simulate.campaign import (
    justin_tracker_setup,
    read_campaign,
    simulate_campaign,
)
from jwarp.cli import main
from jwarp.utils import atomic
from jwarp.utils.atomic import AtomicFolder, atomic_write_text, clean_stale

ROOT = Path(__file__).resolve().parents[2]
ENV = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
SIM = ["simulate-campaign", "--robot", "justin19", "--samples", "30"]


def _err_line(capsys) -> str:
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1, err
    assert lines[0].startswith("jwarp: error: "), err
    return lines[0]


def _temp_entries(folder: Path) -> list[str]:
    """jwarp temporary entries (files or folders) anywhere under ``folder``."""
    pat = re.compile(r"^\..+\.(tmp|old)-[0-9a-f]{6}-\d+-\w+$|^\..+\.[0-9a-f]{6}-\d+-\w+\.tmp$")
    return [os.path.join(d, n) for d, dirs, files in os.walk(folder) for n in dirs + files
            if pat.match(n)]


@pytest.fixture(scope="module")
def camp_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("camp") / "run"
    assert main(SIM + ["--seed", "1", "--out", str(d)]) == 0
    return d


# ---------------------------------------------------------------- 1. no lost work
@pytest.mark.parametrize("option", ["--out", "--params-out", "--rerun"])
def test_calibrate_checks_outputs_before_reading_or_computing(tmp_path, capsys, option):
    """A missing folder (or a file where the folder should be) is an error naming the
    option, before the inputs are even read (here: --data does not exist)."""
    blocker = tmp_path / "a_file"
    blocker.write_text("x")
    for bad, why in ((tmp_path / "missing" / "x.out", "does not exist"),
                     (blocker / "x.out", "is not a folder")):
        rc = main(["calibrate", "--setup", str(tmp_path / "none.json"), "--data",
                   str(tmp_path / "none.csv"), option, str(bad)])
        line = _err_line(capsys)
        assert rc == 2 and line.startswith(f"jwarp: error: {option}: ") and why in line
    assert sorted(os.listdir(tmp_path)) == ["a_file"]


def test_calibrate_refuses_output_that_is_an_input_or_another_output(camp_dir, tmp_path, capsys):
    before = (camp_dir / "samples.csv").read_bytes()
    base = ["calibrate", "--setup", str(camp_dir / "setup.json"), "--data",
            str(camp_dir / "samples.csv"), "--quiet"]
    assert main(base + ["--out", str(camp_dir / "samples.csv")]) == 2
    assert "--out:" in _err_line(capsys) and (camp_dir / "samples.csv").read_bytes() == before
    assert main(base + ["--out", str(tmp_path / "a.json"), "--params-out",
                        str(tmp_path / "a.json")]) == 2
    assert "--params-out:" in _err_line(capsys)


def test_simulate_campaign_checks_out_before_work(tmp_path, capsys, monkeypatch):
    rc = main(["simulate-campaign", "--setup", str(tmp_path / "none.json"),
               "--out", str(tmp_path / "missing" / "run")])
    line = _err_line(capsys)
    assert rc == 2 and line.startswith("jwarp: error: --out: ") and "does not exist" in line
    (tmp_path / "f").write_text("x")
    assert main(SIM + ["--out", str(tmp_path / "f")]) == 2
    assert "--out:" in _err_line(capsys) and (tmp_path / "f").read_text() == "x"
    (tmp_path / "run").mkdir()
    monkeypatch.chdir(tmp_path / "run")  # replacing the current folder: refused
    assert main(SIM + ["--out", "."]) == 2
    assert "--out: '.' holds the current folder" in _err_line(capsys)
    assert os.listdir(tmp_path / "run") == []


def test_campaign_folder_is_one_set_and_keeps_other_files(tmp_path, capsys):
    run = tmp_path / "run"
    assert main(SIM + ["--seed", "1", "--out", str(run), "--json"]) == 0
    first = json.loads(capsys.readouterr().out)["campaign_id"]
    (run / "calibrated.json").write_text("mine")  # a file of the user's in the folder
    (run / "plots").mkdir()
    (run / "plots" / "a.txt").write_text("plot")
    assert main(SIM + ["--seed", "2", "--out", str(run), "--json"]) == 0
    second = json.loads(capsys.readouterr().out)["campaign_id"]
    assert first != second
    c = read_campaign(run)
    assert c.campaign_id == second and len(c.samples) == 30
    assert c.truth.notes["campaign_id"] == second
    assert c.setup.samples_sha256 == sha256_hex((run / "samples.csv").read_bytes())
    assert (run / "calibrated.json").read_text() == "mine"
    assert (run / "plots" / "a.txt").read_text() == "plot"
    assert sorted(os.listdir(tmp_path)) == ["run"] and not _temp_entries(tmp_path)


def test_read_campaign_refuses_files_of_two_campaigns(tmp_path):
    robot = jwarp.robot("justin19")
    setup = justin_tracker_setup()
    for name, seed in (("a", 1), ("b", 2)):
        simulate_campaign(robot, setup, 10, seed=seed).write(tmp_path / name)
    mixed = tmp_path / "mixed"
    shutil.copytree(tmp_path / "a", mixed)
    shutil.copy(tmp_path / "b" / "setup.json", mixed / "setup.json")
    with pytest.raises(ValueError, match=r"setup\.json \(campaign \w+\) and truth\.json "
                                         r"\(campaign \w+\) are not of one campaign"):
        read_campaign(mixed)
    shutil.copy(tmp_path / "a" / "setup.json", mixed / "setup.json")
    shutil.copy(tmp_path / "b" / "samples.csv", mixed / "samples.csv")
    with pytest.raises(ValueError, match=r"samples\.csv is not the samples file of campaign"):
        read_campaign(mixed)
    shutil.copy(tmp_path / "a" / "samples.csv", mixed / "samples.csv")
    assert read_campaign(mixed).campaign_id == read_setup(mixed / "setup.json").campaign_id


def test_calibrate_warns_when_data_is_not_the_setups_campaign(tmp_path, capsys):
    robot = jwarp.robot("justin19")
    for name, seed in (("a", 1), ("b", 2)):
        simulate_campaign(robot, justin_tracker_setup(), 40, seed=seed).write(tmp_path / name)
    rc = main(["calibrate", "--setup", str(tmp_path / "a" / "setup.json"), "--data",
               str(tmp_path / "b" / "samples.csv"), "--quiet", "--json"])
    cap = capsys.readouterr()
    assert rc == 0
    assert "jwarp: warning: --data:" in cap.err and "not the samples file" in cap.err
    assert any("not the samples file" in w for w in json.loads(cap.out)["warnings"])


def test_atomic_file_removes_stale_temporaries_of_ended_processes(tmp_path):
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    host = atomic._HOST
    stale = tmp_path / f".x.json.{host}-{dead.pid}-ab12.tmp"
    live = tmp_path / f".x.json.{host}-{os.getppid()}-cd34.tmp"  # a running process
    other = tmp_path / f".y.json.{host}-{dead.pid}-ef56.tmp"      # another target's
    for p in (stale, live, other):
        p.write_text("partial")
    atomic_write_text(tmp_path / "x.json", "{}")
    assert not stale.exists() and live.exists() and other.exists()
    assert (tmp_path / "x.json").read_text() == "{}"


def _run_and_crash_at(k: int, work) -> tuple[int, list[str]]:
    """Run ``work()`` in a forked child that dies (os._exit, like SIGKILL: no clean-up)
    before its k-th file system step; returns (exit status, step names)."""
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:  # child
        os.close(r)
        steps = []
        count = [0]

        def wrap(mod, name):
            f = getattr(mod, name)

            def g(*a, **kw):
                steps.append(name)
                if count[0] == k:
                    os.write(w, ",".join(steps).encode())
                    os._exit(9)
                count[0] += 1
                return f(*a, **kw)
            setattr(mod, name, g)

        try:
            for mod, name in ((os, "rename"), (os, "replace"), (os, "mkdir"), (os, "link"),
                              (os, "open"), (atomic, "_exchange"), (atomic, "_remove")):
                wrap(mod, name)
            work()
            os.write(w, ",".join(steps).encode())
            os._exit(0)
        except BaseException:
            os._exit(3)
    os.close(w)
    _, status = os.waitpid(pid, 0)
    with os.fdopen(r, "rb") as f:
        steps = f.read().decode().split(",")
    return os.waitstatus_to_exitcode(status), steps


@pytest.mark.parametrize("exchange", [True, False], ids=["exchange", "two-renames"])
def test_atomic_folder_survives_a_crash_at_every_step(tmp_path, monkeypatch, exchange):
    """Crash the folder write before each of its file system steps: the folder is all old
    or all new (after the next writer's recovery where the swap had to rename twice), and
    the next write leaves no temporary entry."""
    if not exchange:
        monkeypatch.setattr(atomic, "_exchange", lambda a, b: False)
    target = tmp_path / "set"

    def write(tag):
        def work():
            with AtomicFolder(target) as f:
                for name in ("a.csv", "b.json", "c.json"):
                    atomic_write_text(f.file(name), f"{tag} {name}")
        return work

    def state():
        if not target.exists():
            return None
        return {n: (target / n).read_text() for n in ("a.csv", "b.json", "c.json")}

    old = {n: f"old {n}" for n in ("a.csv", "b.json", "c.json")}
    new = {n: f"new {n}" for n in ("a.csv", "b.json", "c.json")}
    k, seen_missing = 0, 0
    while True:
        write("old")()
        (target / "user.txt").write_text("keep")
        code, steps = _run_and_crash_at(k, write("new"))
        assert code in (0, 9), (k, code)
        s = state()
        if s is None:  # only between the two renames of the fallback
            assert not exchange and steps[-1] == "rename", steps
            seen_missing += 1
            clean_stale(target)
            s = state()
        assert s in (old, new), (k, steps, s)
        assert (target / "user.txt").read_text() == "keep"
        write("newer")()  # the next run cleans up whatever the crash left
        assert state() == {n: f"newer {n}" for n in old} and not _temp_entries(tmp_path), k
        if code == 0:
            break
        k += 1
    assert k > 10  # every step of the write was crashed at
    assert seen_missing == (0 if exchange else 1)


def _campaign_state(folder: Path, refs: dict[bytes, dict]) -> str | None:
    """Check the campaign folder without touching it: one campaign id in setup.json and
    truth.json, the samples' SHA-256 they record, and all three equal to a complete run's
    output (``refs``: samples bytes -> {setup section, truth notes-free dict}); returns
    the campaign id (None: no folder yet)."""
    if not folder.exists():
        return None
    raw = (folder / "samples.csv").read_bytes()
    setup = json.loads((folder / "setup.json").read_text())
    truth = json.loads((folder / "truth.json").read_text())
    cid = setup["campaign_id"]
    assert truth["notes"]["campaign_id"] == cid
    assert setup["samples_sha256"] == truth["notes"]["samples_sha256"] == sha256_hex(raw)
    assert raw in refs, "samples.csv of no complete run"
    ref = refs[raw]
    for k in ("campaign_id", "samples_sha256"):
        setup.pop(k)
        truth["notes"].pop(k)
    assert setup == ref["setup"] and truth == ref["truth"]
    return cid


def test_simulate_campaign_sigkill_at_random_moments_leaves_one_complete_set(tmp_path):
    """SIGKILL `jwarp simulate-campaign` into one folder at random moments of its run (at
    least 20 kills, seeds alternating): after every kill the folder holds the three files
    of one complete run; the next successful run leaves no temporary entries."""
    seeds = (1, 2, 3)
    refs = {}
    for s in seeds:  # the complete runs, in-process (the same code as the subprocess)
        ref = tmp_path / f"ref{s}"
        assert main(SIM + ["--seed", str(s), "--out", str(ref)]) == 0
        setup = json.loads((ref / "setup.json").read_text())
        truth = json.loads((ref / "truth.json").read_text())
        for k in ("campaign_id", "samples_sha256"):
            setup.pop(k)
            truth["notes"].pop(k)
        refs[(ref / "samples.csv").read_bytes()] = {"setup": setup, "truth": truth}
    target = tmp_path / "camp"

    def cmd(seed):
        return [sys.executable, "-m", "jwarp", *SIM, "--seed", str(seed), "--out", str(target)]

    # the run's length as the kills will meet it: the first run may compile kernels
    # (a cold cache), the later ones do not, so the shorter of two runs
    durations = []
    for _ in range(2):
        t0 = time.perf_counter()
        subprocess.run(cmd(seeds[0]), env=ENV, check=True, capture_output=True)
        durations.append(time.perf_counter() - t0)
    duration = min(durations)
    first_id = _campaign_state(target, refs)
    rng = random.Random(20240611)
    ids, kills, i = {first_id}, 0, 0
    while kills < 20 and i < 40:
        # half spread over the whole run, half over its last third (where it writes)
        t = rng.uniform(0.0, 1.0) if i % 2 else rng.uniform(0.65, 1.0)
        p = subprocess.Popen(cmd(seeds[(i + 1) % len(seeds)]), env=ENV,
                             stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        time.sleep(t * duration)
        if p.poll() is None:
            p.send_signal(signal.SIGKILL)
            kills += 1
        p.wait()
        cid = _campaign_state(target, refs)  # raises unless one complete set
        assert cid is not None
        ids.add(cid)
        i += 1
    assert kills >= 20, (kills, i, duration)
    subprocess.run(cmd(seeds[0]), env=ENV, check=True, capture_output=True)
    _campaign_state(target, refs)
    assert not _temp_entries(tmp_path), _temp_entries(tmp_path)
    assert sorted(os.listdir(target)) == ["samples.csv", "setup.json", "truth.json"]


def test_calibrate_pair_and_killed_run_leaves_nothing_behind(camp_dir, tmp_path, capsys):
    """--out and --params-out: the params record the SHA-256 of the robot file written
    with them; a calibration killed while computing leaves the old outputs as they were,
    and its reserved temporary files are removed by the next run."""
    out, params = tmp_path / "cal.json", tmp_path / "res.json"
    args = ["calibrate", "--setup", str(camp_dir / "setup.json"), "--data",
            str(camp_dir / "samples.csv"), "--calibrate-rows", "0:20", "--test-rows", "20:30",
            "--out", str(out), "--params-out", str(params), "--quiet"]
    assert main(args) == 0
    capsys.readouterr()
    doc = json.loads(params.read_text())
    assert doc["robot_sha256"] == sha256_hex(out.read_bytes())
    old = (out.read_bytes(), params.read_bytes())
    p = subprocess.Popen([sys.executable, "-m", "jwarp", *args, "--starts", "1000",
                          "--max-nfev", "100000"], env=ENV,
                         stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.time() + 60
    while len(_temp_entries(tmp_path)) < 2 and time.time() < deadline and p.poll() is None:
        time.sleep(0.02)
    time.sleep(0.2)
    p.send_signal(signal.SIGKILL)
    p.wait()
    assert len(_temp_entries(tmp_path)) == 2  # reserved before the work, orphaned by the kill
    assert (out.read_bytes(), params.read_bytes()) == old
    assert main(args + ["--seed", "1", "--starts", "2"]) == 0
    assert not _temp_entries(tmp_path)
    assert json.loads(params.read_text())["robot_sha256"] == sha256_hex(out.read_bytes())


def test_calibrate_renames_the_robot_before_its_params(camp_dir, tmp_path, capsys,
                                                      monkeypatch):
    """Reliability round 3, item 11: --params-out was renamed first, so a kill between the
    renames left new params beside the old robot. The robot now goes first: a kill there
    (simulated: the second rename fails) leaves the new robot and the old params, whose
    robot_sha256 names the old robot."""
    from jwarp.utils.atomic import AtomicFile
    out, params = tmp_path / "cal.json", tmp_path / "res.json"
    args = ["calibrate", "--setup", str(camp_dir / "setup.json"), "--data",
            str(camp_dir / "samples.csv"), "--calibrate-rows", "0:20", "--test-rows", "20:30",
            "--out", str(out), "--params-out", str(params), "--quiet"]
    assert main(args) == 0
    old_robot, old_params = out.read_bytes(), params.read_bytes()
    order = []
    commit = AtomicFile.commit

    def killed_after_first(self):
        order.append(Path(self.target).name)
        if len(order) == 2:
            raise KeyboardInterrupt  # the kill between the two renames
        return commit(self)

    monkeypatch.setattr(AtomicFile, "commit", killed_after_first)
    other = [a if a != "0:20" else "4:20" for a in args]   # another result
    assert main(other) == 130   # interrupted
    assert order == ["cal.json", "res.json"]
    assert params.read_bytes() == old_params and out.read_bytes() != old_robot
    assert json.loads(old_params)["robot_sha256"] == sha256_hex(old_robot)


# ---------------------------------------------------------------- 5. calibration inputs
def test_overlapping_rows_are_an_error_unless_allowed(camp_dir, capsys):
    base = ["calibrate", "--setup", str(camp_dir / "setup.json"), "--data",
            str(camp_dir / "samples.csv"), "--quiet", "--json"]
    rc = main(base + ["--calibrate-rows", "0:20", "--test-rows", "15:30"])
    line = _err_line(capsys)
    assert rc == 2 and line.startswith("jwarp: error: --test-rows: rows 15:20 are also")
    assert "--allow-overlap" in line
    rc = main(base + ["--calibrate-rows", "0:20", "--test-rows", "15:30", "--allow-overlap"])
    res = json.loads(capsys.readouterr().out)
    assert rc == 0 and res["samples"] == {"train": 20, "test": 15, "test_fitted": 5}
    assert any("5 of the 15 test rows were also calibration rows" in w for w in res["warnings"])
    # without --calibrate-rows the calibration rows are the rows that are not test rows
    assert main(base + ["--test-rows", "10:20"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert res["samples"] == {"train": 20, "test": 10, "test_fitted": 0}


def test_too_few_rows_is_an_error_about_rows(camp_dir, capsys):
    base = ["calibrate", "--setup", str(camp_dir / "setup.json"), "--data",
            str(camp_dir / "samples.csv"), "--quiet"]
    for rows in ("0:1", "0:2"):
        assert main(base + ["--calibrate-rows", rows]) == 2
        line = _err_line(capsys)
        assert line.startswith("jwarp: error: --calibrate-rows: "), line
        assert "rows" in line.split(":", 3)[-1]


def test_non_utf8_files_name_file_and_line_and_bom_is_accepted(camp_dir, tmp_path):
    robot = jwarp.robot("justin19")
    setup = read_setup(camp_dir / "setup.json")
    meas = make_measurement(robot, setup)
    text = (camp_dir / "samples.csv").read_text()
    bom = tmp_path / "bom.csv"
    bom.write_bytes(b"\xef\xbb\xbf" + text.replace("\n", "\r\n").encode())  # as Excel saves
    s = read_samples(bom, robot, meas)
    np.testing.assert_array_equal(s.q, read_samples(camp_dir / "samples.csv", robot, meas).q)
    lines = text.splitlines(keepends=True)
    latin = tmp_path / "latin1.csv"
    latin.write_bytes("".join(lines[:3]).encode() + "0.5,Gr\xfc\xdfe\n".encode("latin-1"))
    with pytest.raises(ValueError, match=r"latin1\.csv: line 4, column 7: not UTF-8"):
        read_samples(latin, robot, meas)
    sj = tmp_path / "setup.json"
    sj.write_bytes(b"\xef\xbb\xbf" + (camp_dir / "setup.json").read_bytes())
    assert read_setup(sj).plugin == "cartesian"
    sj.write_bytes(b'{"plugin": "cartesian",\n "description": "M\xfcller"}')
    with pytest.raises(ValueError, match=r"setup\.json: line 2, column 19: not UTF-8"):
        read_setup(sj)


def test_joint_far_outside_limits_warns_naming_the_row(camp_dir, tmp_path, capsys):
    robot = jwarp.robot("justin19")
    meas = make_measurement(robot, read_setup(camp_dir / "setup.json"))
    lines = (camp_dir / "samples.csv").read_text().splitlines()
    col = lines[0].split(",").index("right_2")
    fields = lines[5].split(",")
    fields[col] = "95.0"  # degrees written into a radian column
    lines[5] = ",".join(fields)
    text = "\n".join(lines) + "\n"
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        parse_samples(text, robot, meas, where="deg.csv")
    msgs = [str(w.message) for w in caught if issubclass(w.category, DataWarning)]
    assert len(msgs) == 1
    assert re.match(r"deg\.csv: line 6 \(sample 4\): joint 'right_2' = 95 is far outside "
                    r"its limits .*degrees instead of radians", msgs[0]), msgs
    with warnings.catch_warnings(record=True) as caught:  # slightly outside: no warning
        warnings.simplefilter("always")
        lo = robot.joint_limits[robot.joint_names.index("right_2")][0]
        fields[col] = repr(float(lo) - 0.01)
        lines[5] = ",".join(fields)
        parse_samples("\n".join(lines) + "\n", robot, meas)
    assert not [w for w in caught if issubclass(w.category, DataWarning)]
    data = tmp_path / "deg.csv"
    data.write_text(text)
    assert main(["calibrate", "--setup", str(camp_dir / "setup.json"), "--data", str(data),
                 "--quiet", "--calibrate-rows", "0:30"]) == 0
    err = capsys.readouterr().err
    assert "jwarp: warning: " in err and "line 6 (sample 4): joint 'right_2'" in err


# ---------------------------------------------------------------- 6. one-line CLI errors
@pytest.mark.parametrize("extra, option", [
    (["--kappa", "inf"], "--kappa"), (["--kappa", "nan"], "--kappa"),
    (["--kappa=-1e-4"], "--kappa"), (["--angle-error", "nan"], "--angle-error"),
    (["--angle-error", "inf"], "--angle-error"), (["--angle-error", "400"], "--angle-error"),
    (["--length-error=-5"], "--length-error"), (["--length-error", "inf"], "--length-error"),
    (["--noise", "nan"], "--noise"), (["--noise=-1"], "--noise"), (["--noise", "inf"], "--noise"),
    (["--samples", "0"], "--samples"), (["--samples=-3"], "--samples"),
    (["--seed=-1"], "--seed"),
])
def test_simulate_campaign_bad_values_one_line(tmp_path, capsys, extra, option):
    rc = main(["simulate-campaign", "--robot", "justin19", "--samples", "5", *extra,
               "--out", str(tmp_path / "run")])
    line = _err_line(capsys)
    assert rc == 2 and line.startswith(f"jwarp: error: {option}: "), line
    assert not (tmp_path / "run").exists() and not os.listdir(tmp_path)


def test_simulate_campaign_refuses_samples_beyond_memory(tmp_path, capsys):
    t0 = time.perf_counter()
    rc = main(SIM[:3] + ["--samples", "100000000", "--out", str(tmp_path / "run")])
    line = _err_line(capsys)
    assert rc == 2 and time.perf_counter() - t0 < 5
    assert re.match(r"jwarp: error: --samples: 100000000 samples \([\d.]+ kB per sample for "
                    r"'justin19'\) needs about [\d.]+ [TG]B of memory, more than the", line), line
    assert not os.listdir(tmp_path)


@pytest.mark.parametrize("extra, option", [
    (["--starts", "0"], "--starts"), (["--max-nfev=-1"], "--max-nfev"),
    (["--max-nfev", "0"], "--max-nfev"), (["--seed=-2"], "--seed"),
    (["--calibrate-rows", "0:99"], "--calibrate-rows"), (["--test-rows", "a:b"], "--test-rows"),
    (["--test-rows", "0:30"], "--test-rows"),
    # reliability round 4 (items 7-9): ignored options, overflows, unbounded reads
    (["--loss-scale", "3"], "--loss-scale"),
    (["--loss", "huber", "--loss-scale", "1e308"], "--loss-scale"),
    (["--virtual-noise", "1e308"], "--virtual-noise"),
])
def test_calibrate_bad_values_one_line(camp_dir, capsys, extra, option):
    rc = main(["calibrate", "--setup", str(camp_dir / "setup.json"), "--data",
               str(camp_dir / "samples.csv"), "--quiet", *extra])
    line = _err_line(capsys)
    assert rc == 2 and line.startswith(f"jwarp: error: {option}: "), line


def test_cli_error_is_one_line_without_traceback_in_a_process(tmp_path):
    r = subprocess.run([sys.executable, "-m", "jwarp", *SIM[:3], "--samples", "5", "--kappa",
                        "inf", "--out", str(tmp_path / "run")], env=ENV, capture_output=True,
                       text=True)
    err = [ln for ln in r.stderr.splitlines() if ln.strip() and "CUDA" not in ln]
    assert r.returncode == 2 and err == [err[0]] and err[0].startswith("jwarp: error: --kappa: ")
    assert "Traceback" not in r.stderr
