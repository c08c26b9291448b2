"""Every command quoted in README.md, docs/*.md and examples/README.md (issue 27 item 4).

* Every ``jwarp ...`` command of a fenced block (tests/doc_commands.py extracts them) is
  parsed by the real parser, as :func:`jwarp.cli.main.main` parses it, so a subcommand or
  option that does not exist (or a value it refuses) fails naming ``file:line``. Synopsis
  notation is expanded (:func:`doc_commands.expand`): ``[...]`` optional parts once with and
  once without, ``a|b`` each alternative, ``PLACEHOLDER`` words and ``...`` through the
  explicit tables below.
* ``python X.py`` commands: the script exists and its ``--help`` names the options used.
* A curated list of commands runs for real in a temporary folder, each with a check of its
  output (README's calibration recipe, the planning and IK examples, design.md's recipe, ...).
* Figures the docs quote are checked where that is cheap: defaults quoted in synopses
  against the parser's defaults, quoted output lines against the run's output.
"""

from __future__ import annotations

import csv
import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import doc_commands as dc  # tests/doc_commands.py
from jwarp.cli.common import CLIError, fix_negative_values, value_options
from jwarp.cli.main import build_parser, main

ROOT = dc.ROOT
COMMANDS = dc.all_commands()
JWARP = [c for c in COMMANDS if c.program == "jwarp"]
PYTHON = [c for c in COMMANDS if c.program == "python"]

# ------------------------------------------------------------------ synopsis tables
#: placeholder words of synopses -> a value of the option's type (parse only)
PLACEHOLDERS = {
    "N": "10", "K": "1", "S": "1", "M": "0.01", "R": "justin19", "RAD": "3.14",
    "DIR": "pkgs", "NAME": "arm", "NAME=BODY": "tcp=panda_hand", "SPEC": "shelf",
    "CSV": "samples.csv", "ADDR": "auto", "NAME=VALUE": "panda_finger_joint1=0.04",
    "J1,J2,...": "panda_joint1,panda_joint2", "STATE": "default", "Q1,Q2,...": "0,0,0,0,0,0,0",
}
#: ``--start ...`` / ``--goal ...``: "some configuration"; README names `--start zeros`
VALUE_ELLIPSIS = {"--start": "zeros", "--goal": "zeros"}
#: ``jwarp CMD ... --more``: ``...`` stands for the options of a command nearby
COMMAND_ELLIPSIS = {
    "docs/calibration.md: jwarp calibrate ... --prior": (
        "--setup run/setup.json --data run/samples.csv",
        "the calibrate options of README's recipe"),
    "docs/scenes.md: jwarp plan ... --time-limit": (
        "--robot planar4 --world block.npz --start 1.2,0,0,0 --goal -1.2,0,0,0",
        "the plan two lines above"),
    "docs/scenes.md: jwarp plan ... --no-stop-when-solved": (
        "--robot planar4 --world block.npz --start 1.2,0,0,0 --goal -1.2,0,0,0",
        "the plan three lines above"),
}


def _ellipsis_of(cmd: dc.DocCommand) -> str:
    """The :data:`COMMAND_ELLIPSIS` options of ``cmd`` ("" if none)."""
    for key, (options, _reason) in COMMAND_ELLIPSIS.items():
        file, prefix = key.split(": ", 1)
        if cmd.file == file and cmd.text.startswith(prefix):
            return options
    return ""


def variants(cmd: dc.DocCommand) -> list[list[str]]:
    """The concrete argv lists (after ``jwarp``) of a doc command: synopsis expanded and
    placeholders replaced through the tables above. AssertionError naming the line for a
    ``...`` the tables do not explain."""
    out = []
    for v in dc.expand(dc.words(cmd.text)[1:]):
        argv: list[str] = []
        for k, (w, optional) in enumerate(v):
            if w == "...":
                prev = argv[-1] if argv else ""
                if prev in VALUE_ELLIPSIS:
                    argv.append(VALUE_ELLIPSIS[prev])
                elif _ellipsis_of(cmd) and not prev.startswith("-") and k <= 2:
                    argv += _ellipsis_of(cmd).split()
                elif optional:
                    pass  # "[--opt X ...]": the option may repeat
                else:
                    raise AssertionError(f"{cmd.where}: '...' not explained by the tables: "
                                         f"{cmd.text}")
                continue
            argv.append(PLACEHOLDERS.get(w, w))
        out.append(argv)
    return out


@pytest.fixture(scope="module")
def parser():
    return build_parser()


def parse(parser, argv: list[str]):
    return parser.parse_args(fix_negative_values(argv, value_options(parser)))


def classify(cmd: dc.DocCommand) -> str:
    """How the test covers ``cmd``: ``parsed`` (a jwarp command: every synopsis variant
    parsed), ``python`` (each ``&&`` step a script that exists, ``python -m pytest`` or an
    :data:`INSTALL_STEPS` entry); AssertionError for anything else."""
    w = dc.words(cmd.text)
    if w[0] == "jwarp":
        assert variants(cmd), cmd.where
        return "parsed"
    for step in cmd.text.split("&&"):
        sw = dc.words(step)
        ok = (" ".join(sw) in INSTALL_STEPS
              or (sw[0] in ("python", "python3") and len(sw) > 1
                  and (sw[1:3] == ["-m", "pytest"] or sw[1].endswith(".py"))))
        assert ok, f"{cmd.where}: no check covers the step {step.strip()!r}"
    return "python"


def test_every_command_is_classified():
    """No silent skipping: every extracted command is covered by a check (parsed, or a
    python command checked below), and the extraction finds the commands it must."""
    kinds = [classify(c) for c in COMMANDS]
    assert kinds.count("parsed") == len(JWARP) and kinds.count("python") == len(PYTHON)
    assert len(kinds) == len(COMMANDS)
    assert len(COMMANDS) >= 50, len(COMMANDS)
    files = {c.file for c in COMMANDS}
    assert {"README.md", "docs/install.md", "docs/design.md", "docs/urdf.md"} <= files
    # the README's source tree (``jwarp/__init__.py  facade ...``) and printed messages
    # (``jwarp: warning: ...``) are not commands
    assert not [c.where for c in COMMANDS if not re.match(r"(jwarp|python3?)\s", c.text)]
    # every synopsis-table entry names exactly one extracted command
    for key in COMMAND_ELLIPSIS:
        doc(key)


@pytest.mark.parametrize("cmd", JWARP, ids=[c.where for c in JWARP])
def test_jwarp_command_parses(cmd, parser, capsys):
    for argv in variants(cmd):
        try:
            parse(parser, argv)
        except (CLIError, SystemExit) as e:
            pytest.fail(f"{cmd.where}: `jwarp {' '.join(argv)}` does not parse: {e}")
    capsys.readouterr()


def _optional_defaults(cmd: dc.DocCommand) -> list[tuple[str, str]]:
    """``[--opt VALUE]`` groups of a synopsis whose VALUE is a number literal."""
    return re.findall(r"\[(--[a-z-]+) (-?[0-9][0-9.e+-]*)\]", cmd.text)


SYNOPSES_WITH_DEFAULTS = [c for c in JWARP if _optional_defaults(c)]


@pytest.mark.parametrize("cmd", SYNOPSES_WITH_DEFAULTS,
                         ids=[c.where for c in SYNOPSES_WITH_DEFAULTS])
def test_synopsis_values_are_the_defaults(cmd, parser):
    """A ``[--opt 0.02]`` in a synopsis quotes the default: leaving it out gives the same."""
    minimal = parse(parser, variants(cmd)[-1])
    for opt, text in _optional_defaults(cmd):
        given = parse(parser, variants(cmd)[-1] + [opt, text])
        dest = opt.lstrip("-").replace("-", "_")
        assert getattr(minimal, dest) == getattr(given, dest), \
            f"{cmd.where}: {opt} {text} is not the default ({getattr(minimal, dest)!r})"


def test_deprecated_spelling_prints_the_documented_warning(parser, capsys):
    """docs/cli_vocabulary.md quotes the warning of an old spelling on the line after it."""
    cmd = next(c for c in JWARP if c.where.startswith("docs/cli_vocabulary.md"))
    lines = (ROOT / cmd.file).read_text().splitlines()
    parse(parser, variants(cmd)[0])
    assert lines[cmd.line].strip() in capsys.readouterr().err


# ------------------------------------------------------------------ python commands
def _python_steps() -> list[tuple[dc.DocCommand, list[str]]]:
    """Every ``&&`` step of the python commands, as words."""
    return [(c, dc.words(step)) for c in PYTHON for step in c.text.split("&&")]


#: steps of the README's install one-liners that are not run (with the reason) -> check
INSTALL_STEPS = {
    "python3 -m venv .venv": "creates a virtual environment (the test runs inside one)",
    ". .venv/bin/activate": "activates it",
    "pip install torch==2.13.0": "the pinned torch (checked: pyproject accepts it)",
    "pip install -e .": "installs jwarp (checked: pyproject's project)",
    'pip install -e .[test]': "with the test extra (checked: the extra exists)",
}


def test_python_commands():
    import tomllib

    pyproject = tomllib.loads((ROOT / "pyproject.toml").read_text())
    seen = 0
    for cmd, w in _python_steps():
        text = " ".join(w)
        if text in INSTALL_STEPS:
            seen += 1
            continue
        assert w[0] in ("python", "python3"), f"{cmd.where}: unclassified step {text!r}"
        if w[1:3] == ["-m", "pytest"]:
            assert all((ROOT / p).exists() for p in w[3:]), cmd.where
        else:
            assert w[1].endswith(".py") and (ROOT / w[1]).is_file(), \
                f"{cmd.where}: {w[1]} does not exist"
        seen += 1
    assert seen == len(_python_steps())
    # README: "`pyproject.toml` accepts `torch>=2.3`"; the pin 2.13.0 satisfies it
    assert "torch>=2.3" in pyproject["project"]["dependencies"]
    assert "test" in pyproject["project"]["optional-dependencies"]
    readme = (ROOT / "README.md").read_text()
    assert "`pyproject.toml` accepts\n`torch>=2.3`" in readme or \
        "`pyproject.toml` accepts `torch>=2.3`" in readme


SCRIPTS = sorted({w[1] for _, w in _python_steps() if w[0].startswith("python")
                  and w[1].endswith(".py")})


@pytest.mark.parametrize("script", SCRIPTS)
def test_python_script_help_names_the_documented_options(script):
    """``python X.py --help`` works and lists every option the docs pass to X.py."""
    r = subprocess.run([sys.executable, str(ROOT / script), "--help"], capture_output=True,
                       text=True, timeout=120, cwd=ROOT)
    assert r.returncode == 0, r.stderr
    used = {o for _, w in _python_steps() if len(w) > 1 and w[1] == script
            for o in w[2:] if o.startswith("--")}
    missing = [o for o in used if o not in r.stdout]
    assert not missing, f"{script} --help lacks {missing}"


# ------------------------------------------------------------------ commands run for real
def doc(key: str) -> dc.DocCommand:
    """The one command of ``key`` = ``"FILE: the start of its text"`` (keys by text, not by
    line number, so that an edit above a command does not break the test)."""
    file, prefix = key.split(": ", 1)
    found = [c for c in COMMANDS if c.file == file and c.text.startswith(prefix)]
    assert len(found) == 1, f"{key!r} names {len(found)} commands"
    return found[0]


def argv_of(key: str, variant: int = 0) -> list[str]:
    """The doc command's argv; words naming a file of the repository (the shipped models,
    example scenes) become absolute paths, the rest run in the temporary folder."""
    out = []
    for w in variants(doc(key))[variant]:
        out.append(str(ROOT / w) if "/" in w and (ROOT / w).is_file() else w)
    return out


def run(capsys, argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    return tmp_path_factory.mktemp("docs")


@pytest.fixture
def in_work(work, monkeypatch):
    monkeypatch.chdir(work)
    return work


def _readme_block_world(folder: Path) -> None:
    """Run README's Python lines up to ``save_world(world, "block.npz")`` (its own recipe
    for the world of the plan command) in ``folder``."""
    text = (ROOT / "README.md").read_text()
    block = next(b for b in re.findall(r"```python\n(.*?)```", text, re.S)
                 if 'save_world(world, "block.npz")' in b)
    head = block[:block.index('save_world(world, "block.npz")')] + \
        'save_world(world, "block.npz")\n'
    head = "\n".join(ln for ln in head.splitlines() if not ln.startswith("from jwarp.solvers"))
    exec(compile(head, "README.md (block world)", "exec"), {})
    assert (folder / "block.npz").is_file()


def _tcp_sag(out: str) -> float:
    """|sag| [mm] of right_tcp in the end-effector table of ``fk --elastic``."""
    return float([ln for ln in out.splitlines() if ln.startswith("right_tcp")][-1].split()[-1])


def test_readme_cli_examples(in_work, capsys):
    import jwarp

    # jwarp robots [--json]
    code, out, _ = run(capsys, argv_of("README.md: jwarp robots", 0))
    assert code == 0 and sorted(r["name"] for r in json.loads(out)) == sorted(jwarp.robots())
    code, out, _ = run(capsys, argv_of("README.md: jwarp robots", 1))
    assert code == 0 and all(name in out for name in jwarp.robots())
    # jwarp info justin19 [--json]: joints, frames, bodies (or the robot's JSON)
    code, out, _ = run(capsys, argv_of("README.md: jwarp info justin19", 0))
    info = json.loads(out)
    assert code == 0 and info["name"] == "justin19" and len(info["joints"]) == 19
    code, out, _ = run(capsys, argv_of("README.md: jwarp info justin19", 1))
    assert code == 0 and "right_tcp" in out
    # jwarp fk justin19 --q 0,...,0 --json: the frames of jwarp.fk
    code, out, _ = run(capsys, argv_of("README.md: jwarp fk justin19 --q 0,0"))
    robot = jwarp.robot("justin19")
    T = jwarp.fk(robot, np.zeros(19))
    frames = json.loads(out)["frames"]
    i = robot.frame_index("right_tcp")
    assert code == 0
    np.testing.assert_allclose(np.ravel(frames["right_tcp"])[:3], T[i, :3, 3], atol=1e-9)
    # --elastic: "+ iterations and TCP sag [mm]"
    code, out, _ = run(capsys, argv_of("README.md: jwarp fk justin19 --q zeros --elastic"))
    assert code == 0 and "iteration" in out
    sag = _tcp_sag(out)
    assert 0 < sag < 100, out
    # --deg: the same frames as the radians
    code, out_deg, _ = run(capsys, argv_of("README.md: jwarp fk arm7 --q 0,30"))
    q = ",".join(str(np.radians(v)) for v in (0, 30, 0, -60, 0, 45, 0))
    code_rad, out_rad, _ = run(capsys, ["fk", "arm7", "--q", q])
    assert code == code_rad == 0
    assert [ln for ln in out_deg.splitlines() if "tcp" in ln] == \
        [ln for ln in out_rad.splitlines() if "tcp" in ln]
    # explicit compliances: a bigger sag than the default's
    code, out, _ = run(capsys, argv_of("README.md: jwarp fk justin19 --elastic --kappa"))
    sag2 = _tcp_sag(out)
    assert code == 0 and sag2 > 0
    # jwarp show ... --out justin.rrd (rerun-sdk is a dependency)
    code, out, _ = run(capsys, argv_of("README.md: jwarp show justin19"))
    assert code == 0 and (in_work / "justin.rrd").stat().st_size > 1000, out


def test_readme_calibration_recipe(in_work, capsys):
    """README's recipe as written: simulate 500 samples, calibrate on 300, test on 200,
    the calibrated robot used by fk."""
    code, out, _ = run(capsys, argv_of("README.md: jwarp simulate-campaign --robot justin19"))
    assert code == 0
    with open(in_work / "run" / "samples.csv") as f:
        assert sum(1 for _ in csv.reader(f)) == 1 + 500
    # with [--json] [--rerun run/cal.rrd]
    code, out, _ = run(capsys, argv_of("README.md: jwarp calibrate --setup run/setup.json", 0))
    assert code == 0, out
    res = json.loads(out)
    # the keys README quotes for --json
    assert {"before", "after", "free", "time_s", "warnings"} <= set(res)
    assert {"train", "test"} <= set(res["before"])
    before, after = res["before"]["test"]["mean"], res["after"]["test"]["mean"]
    assert after < 0.2 * before and after < 3.0, (before, after)  # mm, 1 mm noise
    assert (in_work / "run" / "cal.rrd").is_file()
    # "as a robot named <robot>-calibrated whose notes.calibration records the campaign id,
    # the input files, the free groups, the errors before/after and the date"
    saved = json.loads((in_work / "run" / "calibrated.json").read_text())
    assert saved["name"] == "justin19-calibrated"
    assert saved["notes"]["calibration"]
    code, out, _ = run(capsys, argv_of("README.md: jwarp fk run/calibrated.json"))
    assert code == 0 and "right_tcp" in out


def test_readme_simulate_campaign_defaults(parser):
    """README: "DH errors (+-1 mm, +-0.3 deg by default: --length-error MM, --angle-error
    DEG)"."""
    assert "+-1 mm, +-0.3 deg by default" in (ROOT / "README.md").read_text()
    args = parse(parser, argv_of("README.md: jwarp simulate-campaign --robot justin19"))
    assert (args.length_error, args.angle_error) == (1.0, 0.3)


def test_readme_planning_and_ik(in_work, capsys):
    _readme_block_world(in_work)
    code, out, _ = run(capsys, argv_of("README.md: jwarp plan --robot planar4 --world block.npz"))
    res = json.loads(out)
    assert code == 0 and res["feasible"] in (True, [True]), out[:400]
    # "its JSON start, goal and path endpoints are the float64 inputs"
    assert res["start"] == [1.2, 0, 0, 0] and res["goal"] == [-1.2, 0, 0, 0]
    assert (in_work / "plan.rrd").is_file()
    # docs/scenes.md:356 and its quoted status line (the command's comment)
    key = "docs/scenes.md: jwarp plan --robot planar4 --world block.npz"
    cmd = doc(key)
    code, out, _ = run(capsys, argv_of(key))
    assert code == 0 and cmd.comment and cmd.comment in out, (cmd.comment, out)
    # IK: exit 0 = a feasible solution, joint names beside the values
    code, out, _ = run(capsys, argv_of("README.md: jwarp ik --robot justin19 --frame right_tcp "
                                       "--target 0.6,"))
    assert code == 0 and "right_1" in out and "head_tilt" in out, out
    # warm start from the shipped network
    code, out, _ = run(capsys, argv_of("README.md: jwarp ik --robot justin19 --frame right_tcp "
                                       "--target 0.56,"))
    assert code == 0 and "head_tilt" in out, out
    # README (prose): `jwarp free-config --robot planar4 --world simplex:seed=3 [--n 2]`
    code, out, _ = run(capsys, ["free-config", "--robot", "planar4", "--world",
                                "simplex:seed=3", "--n", "2", "--seed", "0"])
    starts = [ln.split()[1] for ln in out.splitlines() if ln.startswith("--start ")]
    assert code == 0 and len(starts) == 2
    for s in starts:  # each is a start that plan accepts (not refused as in collision)
        code, out, err = run(capsys, ["plan", "--robot", "planar4", "--world",
                                      "simplex:seed=3", "--start", s, "--goal", starts[0],
                                      "--starts", "2", "--iterations", "3"])
        assert code in (0, 1), err  # 2 would be a refused (e.g. colliding) start


def test_readme_eval_ik_shipped_model(in_work, capsys):
    code, out, _ = run(capsys, argv_of("README.md: jwarp eval ik --robot justin19"))
    assert code == 0 and "justin19_shelf" in out and "100 targets" in out, out


def test_readme_learning_recipes(in_work, capsys):
    """The README's two learning blocks, run as written (smoke-sized): train ik; data
    generate, info, export, train plan, eval plan, free-config, plan with the warm start."""
    code, out, err = run(capsys, argv_of("README.md: jwarp train ik --robot planar5"))
    assert code == 0 and Path("p5.pt").is_file(), err
    code, out, err = run(capsys, argv_of("README.md: jwarp data generate --robot planar4"))
    assert code == 0 and Path("planar4.sqlite").is_file(), err
    code, out, err = run(capsys, argv_of("README.md: jwarp data info planar4.sqlite"))
    info = json.loads(out)
    assert code == 0 and info["worlds"] == info["distinct_worlds"] == 2 and info["paths"] == 2
    code, out, err = run(capsys, argv_of("README.md: jwarp data export planar4.sqlite"))
    assert code == 0 and len(np.load("planar4.npz")["start"]) == 2, err
    code, out, err = run(capsys, argv_of("README.md: jwarp train plan --robot planar4 --hard"))
    assert code == 0 and "trained planning network for planar4" in out and \
        Path("plan4.pt").is_file(), err
    code, out, err = run(capsys, argv_of("README.md: jwarp eval plan --robot planar4"))
    assert code == 0 and "feasibility after k planner iterations" in out, out + err
    code, out, err = run(capsys, argv_of("README.md: jwarp free-config --robot planar4"))
    starts = [ln.split()[1] for ln in out.splitlines() if ln.startswith("--start ")]
    assert code == 0 and len(starts) == 2, out + err
    argv = argv_of("README.md: jwarp plan --robot planar4 --world simplex:seed=3")
    argv[argv.index("--start") + 1] = starts[0]
    argv[argv.index("--goal") + 1] = starts[1]
    code, out, err = run(capsys, argv)
    # the network's path is the only start (no random starts beside a warm start; 16 without)
    assert code in (0, 1) and "of 1 starts" in out, out + err  # 1: not feasible


def test_design_recipe(in_work, capsys):
    """docs/design.md's recipe: the campaigns and the pool exactly; the DETMAX selection
    from the first 300 pool rows (over the 10000 it takes about a minute)."""
    for key in ("docs/design.md: jwarp simulate-campaign --plugin cartesian",
                "docs/design.md: jwarp simulate-campaign --plugin relative"):
        code, out, _ = run(capsys, argv_of(key))
        assert code == 0, out
    code, out, _ = run(capsys, argv_of("docs/design.md: jwarp design --setup tracker/setup.json "
                                       "--write-candidates"))
    assert code == 0
    text = (ROOT / "docs" / "design.md").read_text()
    quoted = re.search(r"(collision check \(self, margin 0 m\): dropped \d+ of \d+ draws)",
                       text).group(1)
    assert quoted in out, (quoted, out)
    assert re.search(r"wrote 10000 candidate configurations of 'cartesian' on 'justin19'",
                     out)
    pool = (in_work / "pool.csv").read_text().splitlines()
    header = [ln for ln in pool if not re.match(r"^-?[0-9.]", ln)]
    rows = [ln for ln in pool if re.match(r"^-?[0-9.]", ln)]
    assert len(rows) == 10000
    (in_work / "pool.csv").write_text("\n".join(header + rows[:300]) + "\n")
    code, out, _ = run(capsys, argv_of("docs/design.md: jwarp design --setup tracker/setup.json "
                                       "--task-setup"))
    assert code == 0 and "selected 100 of 300 candidates (detmax" in out, out
    assert (in_work / "plan.csv").is_file()


def test_urdf_import_of_the_panda(in_work, capsys):
    """docs/urdf.md:21 with example-robot-data's Panda as panda.urdf and a coarse fit
    (--tolerance 0.05 --pair-samples 500: the fit at the default tolerance takes longer)."""
    import jwarp
    from jwarp.importers.robot import example_robot_urdf

    urdf = example_robot_urdf("panda_description/urdf/panda.urdf")
    key = "docs/urdf.md: jwarp import-urdf panda.urdf --out panda.json --end-effector"
    argv = [urdf if w == "panda.urdf" else w for w in argv_of(key, -1)]
    code, out, err = run(capsys, argv + ["--tolerance", "0.05", "--pair-samples", "500",
                                         "--no-cache"])
    assert code == 0, err
    saved = json.loads((in_work / "panda.json").read_text())
    assert saved["frames"][saved["end_effectors"]["tcp"]]["name"] == "panda_hand_tcp"
    robot = jwarp.robot(str(in_work / "panda.json"))  # loads as a robot of 7 arm joints+
    assert robot.n_dof >= 7 and robot.frame_index("tcp") == saved["end_effectors"]["tcp"]


def test_install_warmup(in_work, capsys):
    code, out, _ = run(capsys, argv_of("docs/install.md: jwarp warmup --device cpu --robots"))
    assert code == 0 and re.search(r"\d+ kernel modules on cpu: \d+ compiled", out), out
    assert "kernel cache:" in out


def test_install_md_module_count():
    """docs/install.md quotes the module count of a full ``jwarp warmup`` (every family,
    both dtypes, every registered robot's IK step)."""
    import jwarp
    from jwarp.cli.warmup import kernel_modules

    text = (ROOT / "docs" / "install.md").read_text()
    quoted = {int(n) for n in re.findall(r"(\d+) kernel modules on cpu", text)}
    quoted |= {int(n) for n in re.findall(r"\((\d+) modules on the CPU", text)}
    assert quoted == {len(kernel_modules(robots=jwarp.robots()))}, quoted


# ------------------------------------------------------------------ inline commands
def _subparsers(parser) -> dict:
    import argparse

    for a in parser._actions:
        if isinstance(a, argparse._SubParsersAction):
            return a.choices
    return {}


def _inline_commands() -> list[tuple[str, str]]:
    """``(file:line, text)`` of inline code spans of prose that start with ``jwarp <word>``."""
    found = []
    for f in dc.doc_files():
        text = f.read_text(encoding="utf-8")
        prose = re.sub(r"```.*?```", lambda m: "\n" * m.group(0).count("\n"), text, flags=re.S)
        for m in re.finditer(r"`(jwarp\s+[a-z-][^`]*)`", prose):
            line = prose.count("\n", 0, m.start()) + 1
            found.append((f"{f.relative_to(ROOT).as_posix()}:{line}", " ".join(m.group(1).split())))
    return found


INLINE = _inline_commands()


def test_inline_commands_name_real_options(parser):
    """Every `jwarp SUB ... --opt` span in prose names an existing subcommand and only
    options of it (a fragment need not be a complete command)."""
    assert len(INLINE) >= 20, len(INLINE)
    bad = []
    for where, text in INLINE:
        w = text.split()[1:]
        opts = re.findall(r"(?<![\w-])--[a-z0-9][a-z0-9-]*", text)  # `--a/--b` names both
        if w[0].startswith("-"):  # `jwarp --help`, `jwarp --version`
            known = {o for a in parser._actions for o in a.option_strings}
            bad += [f"{where}: {o}" for o in opts if o not in known]
            continue
        for name in w[0].split("|"):  # `jwarp import-urdf|import-mjcf --spheres fit`
            p = _subparsers(parser).get(name)
            if p is None:
                bad.append(f"{where}: no subcommand {name!r} in `{text}`")
                continue
            if len(w) > 1 and w[1] in _subparsers(p):
                p = _subparsers(p)[w[1]]
            known = {o for a in p._actions for o in a.option_strings}
            bad += [f"{where}: `{text}`: {o} is not an option of `jwarp {name}`"
                    for o in opts if o not in known]
    assert not bad, "\n".join(bad)


# ------------------------------------------------------------------ README's Python
#: README python blocks that need a CUDA device: on a machine without one they run with
#: "cuda:0" replaced by "cpu" (the code path is the same; the device is the point)
CUDA_SNIPPETS = {'kin.fk("justin19", q, device="cuda:0")'}


def _expected(comment: str) -> re.Pattern | None:
    """The output a ``print(...)  # comment`` quotes, as a pattern (``...`` matches
    anything), or None for a prose comment (``# metres``)."""
    if not re.match(r"^([\[\(\d-]|True\b|False\b|None\b)", comment):
        return None
    return re.compile(".*".join(re.escape(p) for p in comment.split("...")) + r"\Z")


# README's calibration block warns about the directions its data cannot determine (its text
# says so): expected
@pytest.mark.filterwarnings("ignore::jwarp.solvers.calibration.result.CalibrationWarning")
def test_readme_python_snippets(work, tmp_path, monkeypatch, capsys):
    """Every ```python block of README.md runs, in order, in one namespace (later blocks
    use earlier names, as a reader's session would), in a folder holding README's
    simulated campaign (run/, the calibration block reads it); every ``print(...)  #
    output`` line prints the output its comment quotes."""
    import builtins
    import warp as wp

    monkeypatch.chdir(tmp_path)
    assert main(argv_of("README.md: jwarp simulate-campaign --robot justin19")) == 0
    capsys.readouterr()
    text = (ROOT / "README.md").read_text()
    blocks = [(text.count("\n", 0, m.start()) + 2, m.group(1))
              for m in re.finditer(r"```python\n(.*?)```", text, re.S)]
    assert len(blocks) >= 8
    assert all(sum(key in code for _, code in blocks) == 1 for key in CUDA_SNIPPETS)
    printed: dict[tuple[str, int], list[str]] = {}
    real_print = builtins.print

    def recording_print(*args, **kwargs):
        frame = sys._getframe(1)
        if frame.f_code.co_filename.startswith("README.md") and "file" not in kwargs:
            key = (frame.f_code.co_filename, frame.f_lineno)
            printed.setdefault(key, []).append(" ".join(str(a) for a in args))
        real_print(*args, **kwargs)

    monkeypatch.setattr(builtins, "print", recording_print)
    ns: dict = {"__name__": "__readme__"}
    checked = 0
    for first, code in blocks:
        where = f"README.md:{first - 1}"
        if any(key in code for key in CUDA_SNIPPETS) and not wp.is_cuda_available():
            code = code.replace('"cuda:0"', '"cpu"')
        try:
            exec(compile(code, where, "exec"), ns)
        except Exception as e:
            pytest.fail(f"{where}: the README's Python block fails: {type(e).__name__}: {e}")
        for k, src in enumerate(code.splitlines(), 1):
            m = re.match(r"\s*print\(.*\)\s+#\s*(.*)$", src)
            pattern = m and _expected(m.group(1).strip())
            if pattern:
                out = printed.get((where, k), [])
                assert out and pattern.match(out[-1]), \
                    f"README.md:{first + k - 1}: prints {out!r}, the README says {m.group(1)!r}"
                checked += 1
    assert checked >= 5, checked


# ------------------------------------------------------------------ docs' Python blocks
def _python_blocks() -> list[tuple[str, str]]:
    """``(file:line, code)`` of every ```python block of the docs."""
    out = []
    for f in dc.doc_files():
        text = f.read_text(encoding="utf-8")
        for m in re.finditer(r"```python\n(.*?)```", text, re.S):
            out.append((f"{f.relative_to(ROOT).as_posix()}:{text.count(chr(10), 0, m.start()) + 1}",
                        m.group(1)))
    return out


def _jwarp_names(code: str) -> list[tuple[str, str | None]]:
    """``(module, name)`` of every ``from jwarp... import a, b`` / ``import jwarp.x`` of a
    block (name None for a module import), and ``("jwarp", attr)`` of every ``jwarp.attr``."""
    found: list[tuple[str, str | None]] = []
    flat = re.sub(r"\(\s*([^)]*?)\s*\)", lambda m: " ".join(m.group(1).split()), code)
    for mod, names in re.findall(r"^\s*from (jwarp(?:\.\w+)*) import ([^#\n]+)", flat, re.M):
        for n in names.split(","):
            n = n.strip().split(" as ")[0].strip()
            if n:
                found.append((mod, n))
    for mod in re.findall(r"^\s*import (jwarp(?:\.\w+)*)", flat, re.M):
        found.append((mod, None))
    for attr in re.findall(r"(?<![\w.])jwarp\.([A-Za-z_]\w*)", code):
        found.append(("jwarp", attr))
    return found


def test_docs_python_blocks_name_real_jwarp_api():
    """The Python blocks of README.md and docs/*.md are fragments (``robot``, ``setup``,
    ``panda.urdf`` come from the text around them; README's are run whole above): every
    jwarp module, function and class they import or use exists."""
    import importlib

    blocks = _python_blocks()
    assert len(blocks) >= 30, len(blocks)
    bad, n = [], 0
    for where, code in blocks:
        for mod, name in _jwarp_names(code):
            n += 1
            try:
                m = importlib.import_module(mod)
            except ImportError as e:
                bad.append(f"{where}: import {mod}: {e}")
                continue
            if name is not None and not hasattr(m, name):
                try:
                    importlib.import_module(f"{mod}.{name}")
                except ImportError:
                    bad.append(f"{where}: {mod} has no {name!r}")
    assert n >= 100, n
    assert not bad, "\n".join(bad)


# ------------------------------------------------------------------ files the docs name
#: paths the docs name that are not meant to exist in the repository
EXAMPLE_PATHS = {"jwarp/plugins/robots/my_arm.py": "the module a reader writes (robot_schema.md)"}


def test_files_named_by_the_docs_exist():
    """Every ``jwarp/...``, ``tests/...``, ``examples/...``, ``benchmarks/...``, ``docs/...``
    path the docs name exists (relative to the repository or to the doc)."""
    bad = []
    for f in dc.doc_files():
        text = f.read_text(encoding="utf-8")
        for m in re.finditer(r"(?<![\w/.-])((?:jwarp|tests|examples|benchmarks|docs)/[\w./-]*\w)",
                             text):
            p = m.group(1)
            if p in EXAMPLE_PATHS:
                continue
            if not ((ROOT / p).exists() or (f.parent / p).exists()):
                bad.append(f"{f.relative_to(ROOT)}:{text.count(chr(10), 0, m.start()) + 1}: {p}")
    assert not bad, "\n".join(bad)


# ------------------------------------------------------------------ option tables
def _command_parser(parser, name: str):
    """The subparser of ``name`` (``"data export"``: nested)."""
    p = parser
    for w in name.split():
        p = _subparsers(p)[w]
    return p


def _options_of(p) -> dict[str, object]:
    """option string -> its action."""
    return {o: a for a in p._actions for o in a.option_strings}


def test_cli_vocabulary_tables(parser, capsys):
    """docs/cli_vocabulary.md: every command of an option's row has that option, and every
    old spelling of the alias table still parses (with its one-line deprecation)."""
    text = (ROOT / "docs" / "cli_vocabulary.md").read_text()
    rows = re.findall(r"^\| `(--[a-z-]+)[^`]*` \| [^|]+ \| (.+) \|$", text, re.M)
    assert len(rows) >= 4, rows
    bad = []
    for opt, commands in rows:
        names = re.findall(r"`([a-z][a-z -]*[a-z])`", re.sub(r"\([^)]*\)", "", commands))
        assert names, commands
        for name in names:
            if opt not in _options_of(_command_parser(parser, name)):
                bad.append(f"`{name}` has no {opt}")
    aliases = re.findall(r"^\| `([a-z][a-z -]*?) (--[a-z-]+) (\S+)` \| `[a-z -]*? (--[a-z-]+) "
                         r"\S+` \|$", text, re.M)
    assert len(aliases) >= 3, aliases
    for name, old, _value, new in aliases:
        opts = _options_of(_command_parser(parser, name))
        if old not in opts or new not in opts:
            bad.append(f"`{name}`: {old} or {new} missing")
    assert not bad, "\n".join(bad)


def test_datasets_option_table(parser):
    """docs/datasets.md's table of ``data generate`` options: each exists, and the
    defaults it quotes are the parser's."""
    text = (ROOT / "docs" / "datasets.md").read_text()
    table = text[text.index("| option | meaning |"):]
    table = table[:table.index("\n\n")]
    opts = _options_of(_command_parser(parser, "data generate"))
    rows = [r for r in re.findall(r"^\| (.+?) \| (.+) \|$", table, re.M)
            if r[0].startswith("`--")]
    assert len(rows) >= 8
    checked = 0
    for names, meaning in rows:
        for opt in re.findall(r"`(--[a-z-]+)", names):
            assert opt in opts, f"datasets.md: `data generate` has no {opt}"
        m = re.search(r"\(default (?:(\w) = )?([0-9.]+)\)", meaning)
        if m:
            given = re.findall(r"`(--[a-z-]+)", names)
            opt = given[0] if not m.group(1) else next(
                o for o in given if re.search(rf"`{o} {m.group(1)}`", names))
            default = opts[opt].default
            if default is None and opt == "--chunk":  # None: generate's DEFAULT_CHUNK
                from jwarp.learn.generate import DEFAULT_CHUNK as default
            assert float(default) == float(m.group(2)), (opt, default)
            checked += 1
    assert checked >= 3, checked
