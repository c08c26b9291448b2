"""Bit-for-bit snapshot of calibration results, for refactors that must not change any
(issue 40): run a fixed campaign and calibration through the CLI and the Python API,
keep every output, and compare two such snapshots byte for byte.

Usage (PYTHONPATH at the tree under test)::

    python tools/snapshot_calibrate.py run /tmp/before      # on the old tree
    python tools/snapshot_calibrate.py run /tmp/after       # on the new tree
    python tools/snapshot_calibrate.py compare /tmp/before /tmp/after

``run`` simulates a small campaign (``jwarp simulate-campaign``, justin19, cartesian, 60
samples, seed 3) into ``OUT/campaign`` and calibrates, with several option sets (plain;
``--test-rows``; text output; ``--cv`` with a small grid; the setup's ``tow`` section with
``--virtual-noise``; a robust loss with priors, orders, ``--fix``, multi-start and
``--diagnostics``; ``--fix GROUP=RESULT.json``), from a frozen copy of the first run's
campaign in ``--work`` (default /tmp/jwarp_snapshot_calibrate): a new campaign draws a new
campaign id, and the calibrated robot's provenance records the id and the input paths, so
every run calibrates the same files at the same paths. The CLI runs in this process
(``jwarp.cli.main``), one command after the other; ``--cv-workers 1``. The Python API part
writes the ``calibrate_with`` result, the residuals and Jacobian of a
``CalibrationProblem`` and the sensitivity's stacked Jacobians as .npy/.json.

The date the calibrated robots' provenance records is frozen (2026-01-01), so the robot
files compare byte for byte. Each output also gets a normalized copy under
``OUT/normalized/``: the values that differ from run to run by design (``time_s``: wall
times, also in the ``--cv`` provenance and hence in ``robot_sha256``; the campaign id a
fresh campaign draws; the snapshot folder's path; the seconds ``calibrate`` prints)
replaced by placeholders. ``compare`` cmps every file of BEFORE with AFTER
and, where the raw bytes differ, the normalized copies; it exits 1 when any file differs
after normalizing or is missing.
"""

from __future__ import annotations

import argparse
import contextlib
import filecmp
import io
import json
import os
import re
import shutil
import sys

import numpy as np

#: keys whose values differ from run to run by design (wall times, dates, file hashes of
#: files holding a date, the id a new campaign draws), or from release to release (the
#: jwarp version the provenance records)
VOLATILE = {"date", "time_s", "robot_sha256", "campaign_id", "wall_s", "jwarp_version"}

TASK = {"plugin": "cartesian", "tracker": {"position": [0, 0, 0]},
        "markers": [{"name": "right", "frame": "right_tcp", "position": [0, 0, 0.05]},
                    {"name": "left", "frame": "left_tcp", "position": [0, 0, 0.05]}],
        "noise": 1e-4}


def cli(argv: list[str], stdout_path: str) -> int:
    """``jwarp ARGV`` in this process; stdout into ``stdout_path``, the exit code returned."""
    from jwarp.cli import main

    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        code = main([str(a) for a in argv])
    with open(stdout_path, "w", encoding="utf-8") as fh:
        fh.write(buf.getvalue())
    if code != 0:
        raise SystemExit(f"jwarp {' '.join(map(str, argv))}: exit {code}")
    return code


def calibrations(inp: str, work: str) -> dict[str, list[str]]:
    """{run name: the calibrate arguments} (``--out``/``--params-out`` added per run)."""
    setup, data = os.path.join(inp, "setup.json"), os.path.join(inp, "samples.csv")
    base = ["calibrate", "--setup", setup, "--data", data, "--quiet"]
    return {
        "plain": base + ["--free", "theta,d", "--max-nfev", "10", "--json"],
        "test_rows": base + ["--free", "theta,d,r,alpha,kappa_theta,kappa_alpha",
                             "--test-rows", "45:60", "--max-nfev", "10", "--json"],
        "text": base + ["--free", "theta,d,kappa_theta", "--calibrate-rows", "0:45",
                        "--test-rows", "40:60", "--allow-overlap", "--max-nfev", "10",
                        "--name", "snap-robot"],
        "cv": base + ["--free", "theta,d", "--calibrate-rows", "0:45", "--test-rows", "45:60",
                      "--cv", "3", "--cv-grid", "scale=0.1|1", "--cv-workers", "1",
                      "--max-nfev", "5", "--json"],
        "tow": ["calibrate", "--setup", os.path.join(inp, "tow.json"), "--data", data,
                "--quiet", "--free", "theta,d", "--virtual-noise", "1e-4", "--max-nfev", "10",
                "--json"],
        "robust": base + ["--free", "theta,harmonic", "--prior", "theta=1e-3",
                          "--order", "harmonic=1", "--loss", "soft_l1", "--loss-scale", "3",
                          "--fix", "markers,tracker=" + os.path.join(work, "run", "plain",
                                                                     "params.json"),
                          "--starts", "2", "--seed", "1", "--diagnostics",
                          "--max-nfev", "8", "--json"],
    }


def freeze_date() -> None:
    """``datetime.datetime.now()`` at 2026-01-01 00:00:00 (UTC): the calibrated robot's
    provenance records the date, imported at call time, so its files compare byte for byte."""
    import datetime

    class Frozen(datetime.datetime):
        @classmethod
        def now(cls, tz: object = None) -> Frozen:  # type: ignore[override]
            return cls(2026, 1, 1, tzinfo=tz)  # type: ignore[arg-type]

    datetime.datetime = Frozen  # type: ignore[misc]


def run(out: str, work: str) -> None:
    import jwarp
    from jwarp.calibration.files import read_setup, write_setup

    print(f"snapshot of {os.path.dirname(jwarp.__file__)} into {out}", file=sys.stderr)
    freeze_date()
    out = os.path.abspath(out)
    os.makedirs(out, exist_ok=True)
    # 1. the campaign, simulated fresh (compared with its campaign id normalized)
    cli(["simulate-campaign", "--robot", "justin19", "--plugin", "cartesian", "--samples", "60",
         "--seed", "3", "--out", os.path.join(out, "campaign"), "--json"],
        os.path.join(out, "simulate.stdout"))
    # 2. the frozen inputs of the calibrations: the first run's campaign, kept
    inp = os.path.join(work, "inputs")
    if not os.path.isdir(inp):
        os.makedirs(work, exist_ok=True)
        shutil.copytree(os.path.join(out, "campaign"), inp)
        s = read_setup(os.path.join(inp, "setup.json"))
        s.tow = {"task": TASK, "virtual_noise": 0.005}
        write_setup(os.path.join(inp, "tow.json"), s)
    # 3. the CLI calibrations, written in the work folder (same paths in every run)
    runs = calibrations(inp, work)  # robust: --fix tracker=<plain's params>
    for name, argv in runs.items():
        d = os.path.join(work, "run", name)
        shutil.rmtree(d, ignore_errors=True)
        os.makedirs(d)
        argv = argv + ["--out", os.path.join(d, "calibrated.json"),
                       "--params-out", os.path.join(d, "params.json")]
        cli(argv, os.path.join(d, "stdout.txt"))
        shutil.copytree(d, os.path.join(out, name))
    # 4. the Python API on the same inputs
    api(inp, os.path.join(out, "api"))
    normalize_all(out)


def api(inp: str, out: str) -> None:
    import warnings

    import jwarp
    from jwarp.calibration import CalibrationOptions, CalibrationProblem, calibrate_with
    from jwarp.calibration.files import make_measurement, read_samples, read_setup

    os.makedirs(out, exist_ok=True)
    setup = read_setup(os.path.join(inp, "setup.json"))
    model = jwarp.robot(setup.robot)
    meas = make_measurement(model, setup)
    data = read_samples(os.path.join(inp, "samples.csv"), model, meas)
    q, y = data.q[:45], data.y[:45]
    res = calibrate_with(model, meas, q, y, CalibrationOptions(
        free="theta,d,kappa_theta", max_nfev=10, warn=False))
    np.save(os.path.join(out, "calibrate_with_x.npy"), res.x)
    np.save(os.path.join(out, "calibrate_with_params.npy"), res.params)
    with open(os.path.join(out, "calibrate_with_robot.json"), "w", encoding="utf-8") as fh:
        fh.write(json.dumps(res.robot.to_dict(), indent=1) + "\n")
    with open(os.path.join(out, "calibrate_with_result.json"), "w", encoding="utf-8") as fh:
        fh.write(json.dumps(res.to_dict(), indent=1) + "\n")
    # the problem with the keywords of before issue 40 (deprecated, still working)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        prob = CalibrationProblem(model, meas, q, y, free=["theta", "d", "tracker", "markers"])
    x = prob.initial_x()
    np.save(os.path.join(out, "problem_x0.npy"), x)
    np.save(os.path.join(out, "problem_residuals.npy"), prob.residuals(x))
    np.save(os.path.join(out, "problem_jacobian.npy"), prob.jacobian(x))
    # the sensitivity's stacked Jacobian (a CalibrationProblem inside)
    from jwarp.calibration.design.sensitivity import stacked_jacobian

    for whiten in (False, True):
        J, names = stacked_jacobian(model, meas, q[:10], "theta,d,kappa_theta,tracker",
                                    whiten=whiten, sigma={"theta": 2e-3})
        np.save(os.path.join(out, f"stacked_jacobian_{'white' if whiten else 'raw'}.npy"), J)
    with open(os.path.join(out, "stacked_jacobian_names.json"), "w", encoding="utf-8") as fh:
        fh.write(json.dumps(names) + "\n")


def _scrub(v: object) -> object:
    if isinstance(v, dict):
        out = {}
        for k, x in v.items():
            if k in VOLATILE:
                out[k] = f"<{k}>"
            elif isinstance(x, str) and x.startswith("{"):
                try:
                    out[k] = _scrub(json.loads(x))   # notes.calibration: JSON in a string
                except ValueError:
                    out[k] = x
            else:
                out[k] = _scrub(x)
        return out
    if isinstance(v, list):
        return [_scrub(x) for x in v]
    return v


def normalize(path: str, root: str) -> bytes:
    """The file's bytes with the run-dependent values replaced (see the module doc) and
    the snapshot folder ``root`` written ``<out>``."""
    with open(path, "rb") as fh:
        raw = fh.read()
    if path.endswith(".npy"):
        return raw
    text = raw.decode("utf-8").replace(root, "<out>")
    try:
        doc = json.loads(text)
    except ValueError:
        # text output: the wall time of the fit and a campaign id
        text = re.sub(r"evaluations, [0-9.]+ s", "evaluations, <t> s", text)
        text = re.sub(r"\([0-9.]+ s, ", "(<t> s, ", text)
        text = re.sub(r"campaign [0-9a-f-]{8,}", "campaign <id>", text)
        return text.encode("utf-8")
    return (json.dumps(_scrub(doc), indent=1, sort_keys=False) + "\n").encode("utf-8")


def _files(root: str) -> list[str]:
    out = []
    for d, dirs, files in os.walk(root):
        dirs[:] = sorted(x for x in dirs if not (d == root and x == "normalized"))
        out += sorted(os.path.relpath(os.path.join(d, f), root) for f in files)
    return out


def normalize_all(out: str) -> None:
    for rel in _files(out):
        dst = os.path.join(out, "normalized", rel)
        os.makedirs(os.path.dirname(dst), exist_ok=True)
        with open(dst, "wb") as fh:
            fh.write(normalize(os.path.join(out, rel), out))


def compare(before: str, after: str) -> int:
    bad = 0
    rels = _files(before)
    missing = sorted(set(_files(after)) - set(rels))
    for rel in rels:
        a, b = os.path.join(before, rel), os.path.join(after, rel)
        if not os.path.exists(b):
            print(f"MISSING   {rel}")
            bad += 1
        elif filecmp.cmp(a, b, shallow=False):
            print(f"identical {rel}")
        elif filecmp.cmp(os.path.join(before, "normalized", rel),
                         os.path.join(after, "normalized", rel), shallow=False):
            print(f"identical {rel} (after normalizing {', '.join(sorted(VOLATILE))}, the "
                  f"snapshot folder)")
        else:
            print(f"DIFFERENT {rel}")
            bad += 1
    for rel in missing:
        print(f"NEW       {rel} (only in {after})")
    print(f"{len(rels) - bad} of {len(rels)} files the same; {bad} different or missing")
    return 1 if bad else 0


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = p.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run")
    r.add_argument("out")
    r.add_argument("--work", default="/tmp/jwarp_snapshot_calibrate")
    c = sub.add_parser("compare")
    c.add_argument("before")
    c.add_argument("after")
    a = p.parse_args()
    if a.cmd == "run":
        run(a.out, a.work)
        return 0
    return compare(a.before, a.after)


if __name__ == "__main__":
    sys.exit(main())
