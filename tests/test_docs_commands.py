"""Every command quoted in README.md, docs/*.md and examples/README.md (issue 27 item 4).

* Every ``jwarp ...`` command of a fenced block (tests/doc_commands.py extracts them) is
  parsed by the real parser, as :func:`jwarp.cli.main.main` parses it, so a subcommand or
  option that does not exist (or a value it refuses) fails naming ``file:line``. Synopsis
  notation is expanded (:func:`doc_commands.expand`): ``[...]`` optional parts once with and
  once without, ``a|b`` each alternative, ``PLACEHOLDER`` words and ``...`` through the
  explicit tables below.
* ``python X.py`` commands: the script exists and its ``--help`` names the options used.
* Every ``jwarp`` command runs for real in a temporary folder, each with a check of its
  output (README's calibration recipe, the planning and IK examples, design.md's recipe, ...),
  except those of :data:`NOT_RUN` (each with its reason); :data:`SCALED` lists the commands
  run with fewer worlds/paths/epochs than written, and
  :func:`test_every_jwarp_command_is_run_or_listed` keeps the two in step with the docs.
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

import doc_commands as dc  # tests/doc_commands.py
import numpy as np
import pytest

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
        "--setup run/setup.json --data run/samples.csv "
        "--free theta,d,r,alpha,kappa_theta,kappa_alpha,harmonic,coupling "
        "--params-out run/harmonic_params.json",
        "README's recipe's files, the free groups of the Python call above (the priors "
        "and orders are of the harmonic group: it must be free) and a --params-out"),
    "docs/scenes.md: jwarp plan ... --time-limit": (
        "--robot planar4 --world block.npz --start 1.2,0,0,0 --goal -1.2,0,0,0",
        "the plan two lines above"),
    "docs/scenes.md: jwarp plan ... --no-stop-when-solved": (
        "--robot planar4 --world block.npz --start 1.2,0,0,0 --goal -1.2,0,0,0",
        "the plan three lines above"),
    "docs/scenes.md: jwarp plan ... --shorten 0": (
        "--robot planar4 --world block.npz --start 1.2,0,0,0 --goal -1.2,0,0,0",
        "the plan four lines above"),
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
    if len(found) > 1:  # a whole command that starts a longer one names itself
        found = [c for c in found if c.text == prefix] or found
    if len({c.text for c in found}) == 1:  # the same command quoted twice: one command
        found = found[:1]
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


# ------------------------------------------------------------------ docs/ik.md, run
_IK_STATUS = re.compile(
    r"robot (\S+): IK of (\S+)(?: \(([^)]*)\))? is (feasible|NOT feasible) \((\d+) of (\d+) "
    r"starts\); position error (\S+) m, rotation error (\S+) rad \(tolerances (\S+) m, "
    r"(\S+) rad\)")


def _ik_answer(out: str) -> dict:
    """The printed answer of ``jwarp ik``: its status line's fields, the ``why:`` line and
    the joint values (name -> value [rad/m], 6 decimals as printed)."""
    m = _IK_STATUS.search(out)
    assert m, out
    q = dict(re.findall(r"^  (\w+) ([+-][0-9.]+)$", out, re.M))
    why = [ln for ln in out.splitlines() if ln.startswith("why: ")]
    return {"frame": m.group(2), "mode": m.group(3), "feasible": m.group(4) == "feasible",
            "n_ok": int(m.group(5)), "n_starts": int(m.group(6)),
            "pos_err": float(m.group(7)), "rot_err": float(m.group(8)),
            "tol_pos": float(m.group(9)), "tol_rot": float(m.group(10)),
            "why": why[0] if why else None, "q": {k: float(v) for k, v in q.items()}}


def _doc_target(argv: list[str], folder: Path) -> np.ndarray:
    """The 4x4 target pose a doc's ``jwarp ik`` command asks for, built from its words with
    scipy (independently of jwarp's parser): a rotation vector, ``--quat`` (xyzw),
    ``--rpy`` (fixed x, y, z) or ``--target-matrix`` (16 numbers or a file of them)."""
    from scipy.spatial.transform import Rotation

    def opt(name):
        return argv[argv.index(name) + 1] if name in argv else None

    T = np.eye(4)
    if opt("--target-matrix") is not None:
        text = opt("--target-matrix")
        if (folder / text).is_file():
            text = (folder / text).read_text()
        T = np.array([float(v) for v in text.replace(",", " ").split()]).reshape(4, 4)
        u, _, vt = np.linalg.svd(T[:3, :3])
        T[:3, :3] = u @ vt
        return T
    v = [float(x) for x in opt("--target").split(",")]
    T[:3, 3] = v[:3]
    if len(v) == 6:
        T[:3, :3] = Rotation.from_rotvec(v[3:]).as_matrix()
    elif opt("--quat") is not None:
        T[:3, :3] = Rotation.from_quat([float(x) for x in opt("--quat").split(",")]).as_matrix()
    elif opt("--rpy") is not None:
        T[:3, :3] = Rotation.from_euler("xyz", [float(x) for x in opt("--rpy").split(",")]
                                        ).as_matrix()
    return T


def _rot_angle(Ra: np.ndarray, Rb: np.ndarray) -> float:
    """Angle [rad] of Ra^T Rb."""
    return float(np.arccos(np.clip((np.trace(Ra.T @ Rb) - 1) / 2, -1.0, 1.0)))


def _check_ik_pose(robot, answer: dict, T: np.ndarray, orientation: str = "full",
                   axis=None) -> None:
    """The printed joint values put the frame on ``T``: FK of them (rounded to the 6 printed
    decimals: up to ~5 um, 5 urad off) against the printed tolerances."""
    import jwarp

    q = np.array([answer["q"][j] for j in robot.joint_names])
    F = jwarp.fk(robot, q)[robot.frame_index(answer["frame"])]
    slack_pos, slack_rot = 1e-5, 1e-5
    assert np.linalg.norm(F[:3, 3] - T[:3, 3]) <= answer["tol_pos"] + slack_pos, (F, T)
    if orientation == "full":
        assert _rot_angle(F[:3, :3], T[:3, :3]) <= answer["tol_rot"] + slack_rot, (F, T)
    elif orientation == "axis":
        a = np.asarray(axis, float) / np.linalg.norm(axis)
        cos = np.clip(np.dot(F[:3, :3] @ a, T[:3, :3] @ a), -1, 1)
        assert np.arccos(cos) <= answer["tol_rot"] + slack_rot


#: docs/ik.md: "the target of the first ones is the pose of right_tcp at q = (...)"
IK_MD_Q = (0.3, 1.0, 0.2, 1.0, -0.4, 0.5, 0.1)
IK_TARGET_KEYS = [  # key, orientation of the check
    ("docs/ik.md: jwarp ik --robot arm7 --frame right_tcp --target -0.7296,0.1664,0.8123,"
     "-0.1763,-1.238,-0.0875", "full"),
    ("docs/ik.md: jwarp ik --robot arm7 --frame right_tcp --target -0.7296,0.1664,0.8123 "
     "--quat", "full"),
    ("docs/ik.md: jwarp ik --robot arm7 --frame right_tcp --target -0.7296,0.1664,0.8123 "
     "--rpy", "full"),
    ('docs/ik.md: jwarp ik --robot arm7 --frame right_tcp --target-matrix "0 0 -1', "full"),
    ("docs/ik.md: jwarp ik --robot arm7 --frame right_tcp --target-matrix pose.txt", "full"),
    ("docs/ik.md: jwarp ik --robot arm7 --frame right_tcp --target -0.7296,0.1664,0.8123 "
     "--position-only", "none"),
    ("docs/ik.md: jwarp ik --robot arm7 --frame right_tcp --target -0.7296,0.1664,0.8123,"
     "-0.1763,-1.238,-0.0875 --free-axis", "axis"),
    ("docs/ik.md: jwarp ik --robot arm7 --frame right_tcp --target -0.7296,0.1664,0.8123,"
     "-0.1763,-1.238,-0.0875 --initial", "full"),
    ("docs/ik.md: jwarp ik --robot arm7 --frame right_tcp --target -0.7296,0.1664,0.8123,"
     "-0.1763,-1.238,-0.0875 --tol-pos", "full"),
    ("docs/ik.md: jwarp ik --robot arm7 --frame right_tcp --target -0.7296,0.1664,0.8123,"
     "-0.1763,-1.238,-0.0875 --scene examples/scenes/table_shelf.yaml", "full"),
    ("docs/ik.md: jwarp ik --robot arm7 --frame right_tcp --target -0.7296,0.1664,0.8123,"
     "-0.1763,-1.238,-0.0875 --scene examples/scenes/table_shelf.yaml --voxel", "full"),
    ("README.md: jwarp ik --robot arm7 --frame right_tcp --target -0.7296,0.1664,0.8123 "
     "--quat", "full"),
]


def test_ik_md_target_is_the_quoted_pose():
    """docs/ik.md: the first target is right_tcp's pose at q = (0.3, 1.0, ...), and "the
    first three are the same pose (4 digits)" (rotation vector, quaternion xyzw, rpy)."""
    import jwarp

    robot = jwarp.robot("arm7")
    F = jwarp.fk(robot, np.array(IK_MD_Q))[robot.frame_index("right_tcp")]
    for key, _ in IK_TARGET_KEYS[:3]:
        T = _doc_target(argv_of(key), ROOT)
        np.testing.assert_allclose(T[:3, 3], F[:3, 3], atol=1e-4, err_msg=key)
        assert _rot_angle(T[:3, :3], F[:3, :3]) < 3e-4, key
    text = (ROOT / "docs" / "ik.md").read_text()
    assert "q = (0.3, 1.0, 0.2, 1.0, -0.4, 0.5, 0.1)" in text


@pytest.mark.parametrize("key,orientation", IK_TARGET_KEYS,
                         ids=[doc(k).where for k, _ in IK_TARGET_KEYS])
def test_ik_md_commands(key, orientation, in_work, capsys):
    """Each target format, position-only, free axis, initial guess, tolerances and scene
    example of docs/ik.md (and README's): exit 0, feasible, and FK of the printed joint
    values is the target (built independently with scipy) within the printed tolerances."""
    import jwarp

    robot = jwarp.robot("arm7")
    argv = argv_of(key)
    if "pose.txt" in argv:  # "pose.txt holds 16 numbers ... as numpy.savetxt writes them"
        np.savetxt(in_work / "pose.txt",
                   jwarp.fk(robot, np.array(IK_MD_Q))[robot.frame_index("right_tcp")])
    code, out, err = run(capsys, argv)
    ans = _ik_answer(out)
    assert code == 0 and ans["feasible"] and ans["why"] is None, out + err
    assert ans["frame"] == "right_tcp" and list(ans["q"]) == robot.joint_names
    axis = None
    if "--free-axis" in argv:
        axis = [float(v) for v in argv[argv.index("--free-axis") + 1].split(",")]
        assert ans["mode"] == "free rotation about 0,0,1"
    if orientation == "none":
        assert ans["mode"] == "position only" and ans["rot_err"] == 0
    _check_ik_pose(robot, ans, _doc_target(argv, in_work), orientation, axis)
    if "--initial" in argv:  # --starts 1: the initial guess is the only seed
        assert (ans["n_ok"], ans["n_starts"]) == (1, 1)
    if "--tol-pos" in argv:
        assert (ans["tol_pos"], ans["tol_rot"]) == (0.001, 0.01)
    else:  # "defaults 1e-4 m and 1e-3 rad"
        assert (ans["tol_pos"], ans["tol_rot"]) == (1e-4, 1e-3)


def test_ik_md_why_lines(in_work, capsys):
    """docs/ik.md's infeasible examples print the ``why:`` lines it quotes: the target on
    the table top (a collision) and a target out of reach (the pose error, at least the
    distance from the shoulder to the reach sphere: 0.4 + 0.39 + 0.118 m from (0, 0, 0.5))."""
    text = (ROOT / "docs" / "ik.md").read_text()
    key = ("docs/ik.md: jwarp ik --robot arm7 --frame right_tcp --target 0.55,0.4,0.4 "
           "--position-only --scene")
    code, out, err = run(capsys, argv_of(key))
    ans = _ik_answer(out)
    quoted = re.search(r"```text\n(robot arm7: IK .*?); wall time [0-9.]+ s\n(why: [^\n]*?); "
                       r"\.\.\.\n```", text, re.S)
    assert quoted, "docs/ik.md: the quoted output of the table-top example"
    assert code == 1 and not ans["feasible"], out + err
    status = quoted.group(1)
    # the structure and counts of the quoted status line; its errors to the printed digits
    assert re.sub(r"error \S+ m", "", status) == \
        re.sub(r"error \S+ m", "", out.splitlines()[0].split("; wall time")[0])
    assert ans["pos_err"] < ans["tol_pos"]  # the position is reached; the table is hit
    assert ans["why"].startswith(quoted.group(2) + "; "), (quoted.group(2), ans["why"])
    # "a target out of reach, `--target 1.5,0,0.8 --position-only`, prints `why: ...`"
    m = re.search(r"out of reach, `--target ([0-9.,]+) --position-only`, prints\n?`(why: [^`]+)`",
                  text)
    assert m, "docs/ik.md: the out-of-reach example"
    argv = argv_of(key)
    argv = argv[:argv.index("--target") + 1] + [m.group(1), "--position-only"]
    code, out, err = run(capsys, argv)
    ans = _ik_answer(out)
    assert code == 1 and ans["why"] == m.group(2), out + err
    reach = 0.4 + 0.39 + 0.118
    gap = np.linalg.norm(np.array([float(v) for v in m.group(1).split(",")]) - [0, 0, 0.5]) - reach
    assert ans["pos_err"] >= gap - 1e-6, (ans["pos_err"], gap)


def test_ik_md_targets_file(in_work, capsys):
    """docs/ik.md "Many targets": the quoted targets.csv solved in one batch by the quoted
    command; results.csv holds a row per target (joint names, status, errors) whose FK is
    its target, and the printed line starts as quoted."""
    import jwarp
    from jwarp.solvers.ik.objective import pose_from_quaternions

    text = (ROOT / "docs" / "ik.md").read_text()
    block = re.search(r"`targets.csv`.*?```text\n(x,y,z,qx,qy,qz,qw\n.*?)```", text, re.S)
    assert block, "docs/ik.md: the quoted targets.csv"
    (in_work / "targets.csv").write_text(block.group(1))
    code, out, err = run(capsys, argv_of("docs/ik.md: jwarp ik --robot arm7 --frame right_tcp "
                                         "--targets targets.csv --out results.csv"))
    quoted = re.search(r"prints `(robot arm7: IK .*?) \.\.\.`", text, re.S)
    assert quoted and code == 0, out + err
    assert out.startswith(" ".join(quoted.group(1).split())), out
    robot = jwarp.robot("arm7")
    with open(in_work / "results.csv") as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == [*robot.joint_names, "status", "pos_err_m", "rot_err_rad"]
    vals = np.array([[float(v) for v in r[:7]] for r in rows[1:]])
    assert [r[7] for r in rows[1:]] == ["solved"] * 3
    tgt = np.loadtxt(in_work / "targets.csv", delimiter=",", skiprows=1)
    T = pose_from_quaternions(tgt[:, :3], tgt[:, 3:])
    F = jwarp.fk(robot, vals)[:, robot.frame_index("right_tcp")]
    assert np.all(np.linalg.norm(F[:, :3, 3] - T[:, :3, 3], axis=1) <= 1e-4 + 1e-9)
    assert all(_rot_angle(F[k, :3, :3], T[k, :3, :3]) <= 1e-3 + 1e-7 for k in range(3))


# ------------------------------------------------------------------ every command, run
def _path_columns(out: str, joint_names: list[str]) -> np.ndarray:
    """The path table ``jwarp plan`` prints (one row per joint, one column per waypoint,
    5 decimals) as (waypoints, dof)."""
    rows = {}
    for ln in out.split("path [rad/m]", 1)[1].splitlines()[2:]:
        w = ln.split()
        if w and w[0] in joint_names and w[0] not in rows:
            rows[w[0]] = [float(v) for v in w[1:]]
    assert list(rows) == list(joint_names), out[:2000]
    return np.array([rows[j] for j in joint_names]).T


def _starts_of(out: str) -> list[str]:
    """The ``--start`` values ``jwarp free-config`` prints."""
    return [ln.split()[1] for ln in out.splitlines() if ln.startswith("--start ")]


def test_readme_elastic_plan(in_work, capsys):
    """README: ``plan --robot justin19 --world simplex:seed=1 --start ... --goal ...
    --elastic`` with a start and goal from ``free-config`` (README: "A start in collision is
    refused: jwarp free-config ... prints collision-free ... --start values"), drawn with a
    5 cm margin: free-config checks the rigid robot, and the elastic robot sags into the
    world by up to ~15 mm at its margin-0 draws (plan refuses those)."""
    import jwarp

    code, out, err = run(capsys, ["free-config", "--robot", "justin19", "--world",
                                  "simplex:seed=1", "--n", "2", "--seed", "0", "--margin",
                                  "0.05"])
    starts = _starts_of(out)
    assert code == 0 and len(starts) == 2, out + err
    argv = argv_of("README.md: jwarp plan --robot justin19 --world simplex:seed=1")
    argv[argv.index("--start") + 1], argv[argv.index("--goal") + 1] = starts
    code, out, err = run(capsys, argv)
    assert code == 0 and re.search(r"robot justin19: path of \d+ waypoints is feasible", out), \
        out[:600] + err
    path = _path_columns(out, jwarp.robot("justin19").joint_names)
    for i, s in ((0, starts[0]), (-1, starts[1])):
        np.testing.assert_allclose(path[i], [float(v) for v in s.split(",")], atol=6e-5)


def _scene_file(folder: Path) -> Path:
    """``my_scene.yaml`` of docs/scenes.md: a small jwarp scene (a table-top box and a
    ball) beside arm7 and justin19 at the origin."""
    p = folder / "my_scene.yaml"
    p.write_text("objects:\n"
                 "  - {id: table, type: box, size: [0.6, 0.8, 0.04], "
                 "pose: {position: [0.6, 0, 0.3]}}\n"
                 "  - {id: ball, type: sphere, radius: 0.1, pose: {position: [-0.4, 0.4, 1.0]}}\n")
    return p


def test_scenes_md_commands(in_work, capsys):
    """docs/scenes.md's three commands: the Panda (example-robot-data's, as panda.urdf) in
    the table-and-shelf scene from the file's MoveIt start to its goal; arm7 in a small
    scene of ours (my_scene.yaml) over the quoted grid extent; IK in that scene."""
    import yaml
    from robot_data import erd

    import jwarp

    # --start moveit --goal moveit: the file's robot_state and goal joint constraints
    argv = [erd("panda_description/urdf/panda.urdf") if w == "panda.urdf" else w
            for w in argv_of("docs/scenes.md: jwarp plan --robot panda.urdf")]
    code, out, err = run(capsys, argv)
    assert code == 0 and "robot panda: path of" in out and " is feasible" in out, out + err
    scene = yaml.safe_load((ROOT / "examples/scenes/table_shelf.yaml").read_text())
    state = dict(zip(scene["robot_state"]["joint_state"]["name"],
                     scene["robot_state"]["joint_state"]["position"]))
    goal = {c["joint_name"]: c["position"]
            for c in scene["goal_constraints"][0]["joint_constraints"]}
    names = [n for n in re.findall(r"^  (panda_\w+) ", out, re.M)]
    names = list(dict.fromkeys(names))
    path = _path_columns(out, names)
    arm = [n for n in names if n in goal]
    assert len(arm) == 7
    idx = [names.index(n) for n in arm]
    np.testing.assert_allclose(path[0, idx], [state[n] for n in arm], atol=6e-5)
    np.testing.assert_allclose(path[-1, idx], [goal[n] for n in arm], atol=6e-5)

    # my_scene.yaml, --extent -1,1,-1,1,0,1.6 (a grid), --start ... --goal ...
    _scene_file(in_work)
    robot = jwarp.robot("arm7")
    start, goal7 = "0,0,0,0,0,0,0", "0,1.0,0,0.8,0,0,0"
    argv = argv_of("docs/scenes.md: jwarp plan --robot arm7 --scene my_scene.yaml")
    argv[argv.index("--start") + 1], argv[argv.index("--goal") + 1] = start, goal7
    code, out, err = run(capsys, argv)
    assert code == 0 and "robot arm7: path of" in out and " is feasible" in out, out + err
    path = _path_columns(out, robot.joint_names)
    np.testing.assert_allclose(path[0], np.zeros(7), atol=6e-5)
    np.testing.assert_allclose(path[-1], [0, 1.0, 0, 0.8, 0, 0, 0], atol=6e-5)

    # IK in the scene: the pose reached, the TCP outside the box and the ball
    argv = argv_of("docs/scenes.md: jwarp ik --robot arm7 --frame right_tcp --target 0.4,-0.3")
    code, out, err = run(capsys, argv)
    ans = _ik_answer(out)
    assert code == 0 and ans["feasible"], out + err
    T = _doc_target(argv, in_work)
    _check_ik_pose(robot, ans, T)
    assert np.linalg.norm(T[:3, 3] - [-0.4, 0.4, 1.0]) > 0.1
    assert T[2, 3] > 0.32  # above the table top


def test_scenes_md_time_limit_and_no_stop(in_work, capsys):
    """docs/scenes.md: ``plan ... --time-limit 0.5 --fallback none`` ("at most about 0.5 s,
    no fallback"), ``plan ... --no-stop-when-solved`` ("every start optimised") and
    ``plan ... --shorten 0`` (the first feasible path, not shortened), with
    the plan two and three lines above them (README's block world)."""
    _readme_block_world(in_work)
    code, out, err = run(capsys, argv_of("docs/scenes.md: jwarp plan ... --time-limit"))
    assert code in (0, 1), out + err
    m = re.search(r"wall time ([0-9.]+) s", out)
    stop = re.search(r"stopped: (\w+); stage: (\w+)", out)
    assert m and stop, out
    assert float(m.group(1)) < 0.5 + 1.0, out  # 0.5 s, plus a loaded machine's slack
    assert stop.group(2) != "fallback", out
    code, out, err = run(capsys, argv_of("docs/scenes.md: jwarp plan ... --no-stop-when"))
    stop = re.search(r"stopped: (\w+); stage: (\w+)", out)
    assert code in (0, 1) and stop, out + err
    assert stop.group(1) in ("all_done", "iterations"), out  # not "solved": no early stop
    # --shorten 0: the first feasible path as it is (its length line says nothing shortened)
    code, out, err = run(capsys, argv_of("docs/scenes.md: jwarp plan ... --shorten 0"))
    assert code in (0, 1), out + err
    if code == 0:
        assert re.search(r"length: \S+ x the straight line's length cost\n", out), out
        assert "shortened" not in out, out


def test_calibration_md_priors_and_orders(tmp_path, monkeypatch, capsys):
    """docs/calibration.md: ``calibrate ... --prior harmonic=1e-3,harmonic:torso_*=5e-3
    --prior priors.json --order harmonic:torso_*=3,harmonic:right_*=1`` on README's
    campaign: each joint's harmonic order and prior sigma are the ones asked for (K = 2
    elsewhere), in the parameters written by --params-out."""
    monkeypatch.chdir(tmp_path)
    assert main(argv_of("README.md: jwarp simulate-campaign --robot justin19")) == 0
    (tmp_path / "priors.json").write_text('{"harmonic:torso_*": 5e-3}')  # the doc's example
    code, out, err = run(capsys, argv_of("docs/calibration.md: jwarp calibrate ... --prior"))
    assert code == 0, out + err
    params = json.loads((tmp_path / "run" / "harmonic_params.json").read_text())["parameters"]
    orders: dict[str, int] = {}
    for p in params:
        m = re.match(r"(\w+)\.harmonic_a(\d+)$", p["name"])
        if m:
            orders[m.group(1)] = max(orders.get(m.group(1), 0), int(m.group(2)))
            want = 5e-3 if m.group(1).startswith("torso_") else 1e-3
            assert p["sigma"] == pytest.approx(want), p
    assert orders and all(k == (3 if j.startswith("torso_") else 1 if j.startswith("right_")
                                else 2) for j, k in orders.items()), orders


def test_calibration_md_cross_validation(tmp_path, monkeypatch, capsys):
    """docs/calibration.md "Choosing settings": the worked example's campaign and its
    ``calibrate --cv 4``: the prior scale of the truth (0.01) chosen, and every quoted
    line of the table and of the inside / outside report printed as quoted (the timing
    in the first line aside)."""
    monkeypatch.chdir(tmp_path)
    code, out, err = run(capsys, argv_of("docs/calibration.md: jwarp simulate-campaign "
                                         "--samples 140"))
    assert code == 0, out + err
    code, out, err = run(capsys, argv_of("docs/calibration.md: jwarp calibrate --setup "
                                         "cv/setup.json"))
    assert code == 0, out + err
    chosen = [ln for ln in out.splitlines() if ln.endswith("<- chosen")]
    assert len(chosen) == 1 and chosen[0].split()[0] == "scale=0.01", out
    text = (ROOT / "docs" / "calibration.md").read_text()
    quoted = re.search(r"prints \(abridged\)\n\n```\n(.*?)```", text, re.S).group(1)
    lines = quoted.splitlines()
    assert lines[0].startswith("cross-validation: 4 folds of 40 calibration rows, 10 settings")
    for ln in lines[1:]:
        ln = ln.removesuffix(" ...")
        assert any(o.startswith(ln) for o in out.splitlines()), (ln, out)


#: doc commands run with fewer worlds/paths/epochs than written (the replacements are
#: applied to the doc's argv word by word), with the reason
SCALED = {
    "docs/datasets.md: jwarp data generate --robot justin19 --worlds 10000 --paths-per-world "
    "100 --db out.sqlite": (
        {"--worlds": "3", "--paths-per-world": "1"},
        "10000 worlds x 100 paths take hours; 3 worlds x 1 path (worlds 0 and 2 give a hard "
        "path each, which the split by world of train plan needs); run after the cluster "
        "command below has labelled the same 3 worlds into out.sqlite, so it resumes: the "
        "complete worlds are skipped (the documented rerun), saving ~1.5 min of CI"),
    "docs/datasets.md: jwarp data generate --robot justin19 --worlds 10000 --paths-per-world "
    "100 --db /data/justin19.sqlite --ray-address": (
        {"--worlds": "3", "--paths-per-world": "1", "--db": "out.sqlite",
         "--device": "cpu", "--num-gpus": "0", "--chunk": "1"},
        "CI has no GPU and no cluster: 3 worlds of one path on the CPU, in a local Ray "
        "instance of 2 CPUs started by the test (the running cluster --ray-address auto "
        "finds), into the database of the recipe above (out.sqlite in the test's folder); "
        "--chunk 1: 3 worlds are 3 tasks, both CPUs busy (16 would be one task)"),
    "docs/urdf.md: jwarp import-urdf baxter.urdf": (
        {"--spheres": "none"},
        "the sphere fit of Baxter's links takes ~60 s with a cold cache (CI's); the test "
        "checks the planned joints and the locked joint, which the fit does not touch "
        "(Baxter's fit: benchmarks/bench_robots.py)"),
    "docs/datasets.md: jwarp train plan --robot justin19 --data out.sqlite": (
        {"--epochs": "1", "--steps-per-epoch": "2"},
        "10 epochs of 100 steps take ~2.5 min on the CPU; 1 epoch of 2 steps trains the same "
        "network on the same split"),
}
#: doc commands that are parsed but not run, with the reason
NOT_RUN: dict = {}


def scaled_argv(key: str) -> list[str]:
    """:func:`argv_of` with the :data:`SCALED` replacements of ``key`` (an option the doc
    does not give is appended)."""
    argv = argv_of(key)
    for opt, value in SCALED[key][0].items():
        if opt in argv:
            argv[argv.index(opt) + 1] = value
        else:
            argv += [opt, value]
    return argv


def test_datasets_md_recipe(in_work, capsys):
    """docs/datasets.md's cluster command, then its generate / info / export / train plan
    (scaled: :data:`SCALED`), and docs/cli_vocabulary.md's ``data export p.sqlite --npz
    p.npz`` on the same database (its deprecation line and its "p.npz: N paths" line). The
    cluster command runs against a local Ray instance: its chunks run as Ray tasks and their
    worlds land in the driver's database; the plain generate then resumes it."""
    ray = pytest.importorskip("ray", reason="the test extra's ray is not installed")
    if ray.is_initialized():
        ray.shutdown()
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False,
             runtime_env={"env_vars": {"PYTHONPATH": str(ROOT)}})
    try:
        key = ("docs/datasets.md: jwarp data generate --robot justin19 --worlds 10000 "
               "--paths-per-world 100 --db /data/justin19.sqlite --ray-address")
        argv = scaled_argv(key)
        assert argv[argv.index("--ray-address") + 1] == "auto"
        code, out, err = run(capsys, argv)
    finally:
        ray.shutdown()
    assert code == 0 and "out.sqlite: 3 worlds (3 paths) written" in out, out + err
    assert out.rstrip().endswith("(ray)"), out  # the chunks ran as Ray tasks
    key = ("docs/datasets.md: jwarp data generate --robot justin19 --worlds 10000 "
           "--paths-per-world 100 --db out.sqlite")
    code, out, err = run(capsys, scaled_argv(key))
    assert code == 0 and "out.sqlite: 0 worlds (0 paths) written, 3 already there" in out, \
        out + err
    code, out, err = run(capsys, argv_of("docs/datasets.md: jwarp data info out.sqlite"))
    info = json.loads(out)
    assert code == 0 and info["robot"] == "justin19" and info["worlds"] == 3
    assert info["paths"] == 3 and info["n_dof"] == 19
    code, out, err = run(capsys, argv_of("docs/datasets.md: jwarp data export out.sqlite"))
    npz = np.load(in_work / "out.npz")
    assert code == 0 and npz["start"].shape == (3, 19) and npz["goal"].shape == (3, 19), err
    assert sorted(npz["world_id"].tolist()) == [0, 1, 2]
    # the paths run from their start to their goal
    np.testing.assert_allclose(npz["path"][:, 0], npz["start"], atol=1e-5)
    np.testing.assert_allclose(npz["path"][:, -1], npz["goal"], atol=1e-5)
    key = "docs/datasets.md: jwarp train plan --robot justin19 --data out.sqlite"
    code, out, err = run(capsys, scaled_argv(key))
    assert code == 0 and "trained planning network for justin19" in out, out + err
    assert (in_work / argv_of(key)[argv_of(key).index("--out") + 1]).is_file()
    # docs/cli_vocabulary.md: the old spelling still writes the file, with its warning
    (in_work / "p.sqlite").write_bytes((in_work / "out.sqlite").read_bytes())
    cmd = doc("docs/cli_vocabulary.md: jwarp data export p.sqlite --npz p.npz")
    quoted = (ROOT / cmd.file).read_text().splitlines()[cmd.line:cmd.line + 2]
    code, out, err = run(capsys, argv_of("docs/cli_vocabulary.md: jwarp data export p.sqlite"))
    assert code == 0 and quoted[0].strip() in err, (quoted, err)
    n = len(np.load(in_work / "p.npz")["start"])
    assert n == 3 and re.sub(r"\d+", str(n), quoted[1].strip()) in out, (quoted, out)


def _campaigns(folder: Path, capsys) -> None:
    """docs/design.md's two campaigns (tracker/, relative/) in ``folder``."""
    for key in ("docs/design.md: jwarp simulate-campaign --plugin cartesian",
                "docs/design.md: jwarp simulate-campaign --plugin relative"):
        code, out, err = run(capsys, argv_of(key))
        assert code == 0, out + err


def _synopsis_argv(key: str, variant: int, values: dict[str, str]) -> list[str]:
    """A synopsis variant (:func:`argv_of`) with its placeholder words replaced by
    ``values`` (word -> value, or ``"--opt"`` -> the value after the option)."""
    argv = argv_of(key, variant)
    for k, v in values.items():
        if k.startswith("--"):
            if k in argv:
                argv[argv.index(k) + 1] = v
        else:
            argv = [v if w == k else w for w in argv]
    return argv


def test_design_md_synopses(in_work, capsys):
    """docs/design.md's ``sensitivity`` and ``design`` synopses, expanded (each optional
    group with and without; ``a|b`` each), on the recipe's campaigns: the identifiable
    counts are the eigenvalues above the threshold, the pool holds N collision-checked
    rows (drawn = kept + dropped), the selection is N distinct pool rows written in order."""
    _campaigns(in_work, capsys)
    # FILE.yaml: a ball in front of justin19 (my_scene.yaml's table cuts its mobile base)
    (in_work / "ball.yaml").write_text(
        "objects:\n  - {id: ball, type: sphere, radius: 0.1, pose: {position: [1.2, 0, 1.0]}}\n")
    values = {"S.json": "tracker/setup.json", "T.json": "relative/setup.json",
              "groups": "theta,d,r,alpha", "FILE.yaml": "ball.yaml",
              "samples.csv": "tracker/samples.csv", "--task-samples": "relative/samples.csv"}
    key = "docs/design.md: jwarp sensitivity --setup S.json"
    for variant in range(len(variants(doc(key)))):
        argv = _synopsis_argv(key, variant, values)
        code, out, err = run(capsys, argv)
        assert code == 0, (argv, out + err)
        if "--json" in argv:
            res = json.loads(out)
            for part in ("actual", "task"):
                ev = np.array(res[part]["eigenvalues"])
                assert res[part]["n_identifiable"] == int(np.sum(ev > res[part]["threshold"]))
                assert res[part]["threshold"] == pytest.approx(1e-12 * ev.max())
            assert (in_work / "out.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
            assert (in_work / "out.rrd").stat().st_size > 0
        else:
            assert re.search(r"kernel inclusion .*: (holds|fails|does not hold)", out), out
    key = "docs/design.md: jwarp design --setup S.json --write-candidates"
    for variant in range(len(variants(doc(key)))):
        argv = _synopsis_argv(key, variant, {**values, "--write-candidates": "200"})
        code, out, err = run(capsys, argv)
        assert code == 0, (argv, out + err)
        rows = [ln for ln in (in_work / "pool.csv").read_text().splitlines()
                if re.match(r"^-?[0-9.]", ln)]
        assert len(rows) == 200
        if "--json" in argv:
            res = json.loads(out)
            assert res["kept"] == 200 and res["drawn"] == 200 + sum(res["dropped"].values())
            assert res["world_checked"] and res["margin"] == 0.01
    pool = [ln for ln in (in_work / "pool.csv").read_text().splitlines()
            if re.match(r"^-?[0-9.]", ln)]
    key = "docs/design.md: jwarp design --setup S.json [--task-setup"
    for variant in range(len(variants(doc(key)))):
        argv = _synopsis_argv(key, variant, values)
        code, out, err = run(capsys, argv)
        assert code == 0, (argv, out + err)
        plan = [ln for ln in (in_work / "plan.csv").read_text().splitlines()
                if re.match(r"^-?[0-9.]", ln)]
        assert len(plan) == 100 and len(set(plan)) == 100 and set(plan) <= set(pool)
        if "--json" in argv:
            res = json.loads(out)
            assert [pool[i] for i in res["indices"]] == plan  # written in the order chosen
            if res["method"] == "greedy":  # each greedy step raises the criterion
                assert np.all(np.diff(res["history"]) >= 0)


def _doc_cameras() -> dict:
    """The ``cameras`` and ``marker_normals`` of docs/pose_sampling.md's setup example."""
    text = (ROOT / "docs" / "pose_sampling.md").read_text()
    cams = re.search(r'"cameras": (\[.*?\n \])', text, re.S)
    normals = re.search(r'"marker_normals": (\{[^}]*\})', text)
    assert cams and normals
    return {"cameras": json.loads(cams.group(1)), "marker_normals": json.loads(normals.group(1))}


def test_pose_sampling_md_synopsis(in_work, capsys):
    """docs/pose_sampling.md's synopsis on design.md's tracker setup (plus the doc's two
    cameras and a marker normal, which ``--single-marker`` needs): 300 rows within the joint
    limits, ordered (the printed path length is the file's), verdict counts that add up,
    and with cameras each pose has a marker inside a camera's view cone and range (a
    necessary condition of "seen"; occlusion is not re-checked)."""
    from scipy.spatial.transform import Rotation

    import jwarp

    _campaigns(in_work, capsys)
    setup = json.loads((in_work / "tracker" / "setup.json").read_text())
    (in_work / "setup.json").write_text(json.dumps({**setup, **_doc_cameras()}))
    robot = jwarp.robot("justin19")
    lo, hi = np.asarray(robot.joint_limits).T
    key = "docs/pose_sampling.md: jwarp sample-poses"
    for variant in range(len(variants(doc(key)))):
        argv = argv_of(key, variant)
        if "cuda" in argv:
            continue  # --device cuda: the same options on the CPU are variant 0
        if variant == len(variants(doc(key))) - 1:  # the minimal one: no cameras
            argv = ["tracker/setup.json" if w == "setup.json" else w for w in argv]
        code, out, err = run(capsys, argv)
        assert code == 0, (argv, out + err)
        with open(in_work / "plan.csv") as f:
            rows = list(csv.reader(f))
        assert rows[0][:19] == robot.joint_names
        q = np.array([[float(v) for v in r[:19]] for r in rows[1:]])
        assert q.shape == (300, 19)
        assert np.all(q >= lo - 1e-6) and np.all(q <= hi + 1e-6)
        length = float(np.linalg.norm(np.diff(q, axis=0), axis=1).sum())
        if "--json" in argv:
            res = json.loads(out)
            assert sum(res["counts"].values()) == res["tried"]
            assert res["length_after"]["euclidean"] == pytest.approx(length, rel=1e-5)
            assert res["length_after"]["euclidean"] < res["length_before"]["euclidean"]
            cams = _doc_cameras()["cameras"]
            F = jwarp.fk(robot, q)
            seen = np.zeros(len(q), bool)
            for m in setup["markers"]:
                T = F[:, robot.frame_index(m["frame"])]
                x = T[:, :3, :3] @ np.array(m["position"]) + T[:, :3, 3]
                for c in cams:
                    o = np.array(c["pose"]["position"])
                    if "look_at" in c["pose"]:
                        axis = np.array(c["pose"]["look_at"]) - o
                    else:
                        axis = Rotation.from_rotvec(c["pose"]["rotvec"]).as_matrix()[:, 2]
                    ray = x - o
                    d = np.linalg.norm(ray, axis=1)
                    cos = ray @ axis / (d * np.linalg.norm(axis))
                    near, far = c.get("range", [0, np.inf])
                    seen |= (cos >= np.cos(np.radians(c["fov"] / 2)) - 1e-6) & \
                        (d >= near - 1e-6) & (d <= far + 1e-6)
            assert seen.all(), np.flatnonzero(~seen)
        else:
            m = re.search(r"path length \(euclidean\): [0-9.]+ -> ([0-9.]+) rad", out)
            assert m and float(m.group(1)) == pytest.approx(length, abs=2e-3), out


def _urdf_joint(urdf: str, name: str) -> tuple[np.ndarray, np.ndarray]:
    """``(origin 4x4, axis)`` of a URDF joint, read with ElementTree."""
    import xml.etree.ElementTree as ET

    from scipy.spatial.transform import Rotation

    j = next(e for e in ET.parse(urdf).getroot().iter("joint") if e.get("name") == name)
    o = j.find("origin")
    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler("xyz", [float(v) for v in o.get("rpy").split()]).as_matrix()
    T[:3, 3] = [float(v) for v in o.get("xyz").split()]
    return T, np.array([float(v) for v in j.find("axis").get("xyz").split()])


def _child_in_parent(robot, parent: str, child: str) -> np.ndarray:
    """Pose of link ``child`` in link ``parent`` by the imported robot's FK (home)."""
    import jwarp

    F = jwarp.fk(robot, np.zeros(robot.n_dof))
    return np.linalg.inv(F[robot.frame_index(parent)]) @ F[robot.frame_index(child)]


def test_urdf_md_srdf_group_and_freeze(in_work, capsys):
    """docs/urdf.md's SRDF-group and --freeze imports of example-robot-data's Panda: the
    planned joints are the SRDF group's, and the frozen finger sits where the URDF puts it
    at the state's value (SRDF ``default``: 0.001 m) or the --freeze value (0.04 m)."""
    import xml.etree.ElementTree as ET

    from robot_data import erd

    import jwarp

    urdf, srdf = erd("panda_description/urdf/panda.urdf"), erd("panda_description/srdf/panda.srdf")
    group = [j.get("name") for g in ET.parse(srdf).getroot().iter("group")
             if g.get("name") == "arm" for j in g.iter("joint")]
    state = {j.get("name"): float(j.get("value")) for s in ET.parse(srdf).getroot().iter(
        "group_state") if s.get("name") == "default" for j in s.iter("joint")}
    origin, axis = _urdf_joint(urdf, "panda_finger_joint1")
    for key, finger in (("docs/urdf.md: jwarp import-urdf panda.urdf --out arm.json --srdf",
                         state["panda_finger_joint1"]),
                        ("docs/urdf.md: jwarp import-urdf panda.urdf --out arm.json --freeze",
                         0.04)):
        argv = [{"panda.urdf": urdf, "panda.srdf": srdf}.get(w, w) for w in argv_of(key)]
        code, out, err = run(capsys, argv)
        assert code == 0, out + err
        robot = jwarp.robot(str(in_work / "arm.json"))
        assert robot.joint_names == group, robot.joint_names
        T = _child_in_parent(robot, "panda_hand", "panda_leftfinger")
        np.testing.assert_allclose(T[:3, 3], origin[:3, 3] + finger * axis, atol=1e-9)


def test_urdf_md_baxter_left_arm(in_work, capsys):
    """docs/urdf.md's Baxter import (example-robot-data): the planned joints are the 7
    given, and the locked right_s0 = 0.3 turns right_upper_shoulder as the URDF's joint
    does at 0.3 rad. Scaled (:data:`SCALED`): no sphere fit."""
    from robot_data import erd
    from scipy.spatial.transform import Rotation

    import jwarp

    urdf = erd("baxter_description/urdf/baxter.urdf")
    key = "docs/urdf.md: jwarp import-urdf baxter.urdf"
    argv = [urdf if w == "baxter.urdf" else w for w in scaled_argv(key)]
    code, out, err = run(capsys, argv)
    assert code == 0, out + err
    robot = jwarp.robot(str(in_work / "left.json"))
    assert robot.joint_names == argv[argv.index("--joints") + 1].split(",")
    origin, axis = _urdf_joint(urdf, "right_s0")
    want = origin.copy()
    want[:3, :3] = origin[:3, :3] @ Rotation.from_rotvec(0.3 * axis).as_matrix()
    np.testing.assert_allclose(_child_in_parent(robot, "right_arm_mount",
                                                "right_upper_shoulder"), want, atol=1e-9)


#: a small MJCF arm for docs/urdf.md's ``import-mjcf panda.xml`` (the doc's file name: a
#: Panda MJCF such as MuJoCo Menagerie's is not installed here); one capsule to fit spheres
#: to (the spheres are kept as they are), so that ``--spheres fit`` takes seconds
MJCF_ARM = """<mujoco model="arm3">
  <compiler angle="radian"/>
  <worldbody>
    <body name="base" pos="0 0 0.1">
      <geom type="sphere" size="0.05"/>
      <joint name="j1" type="hinge" axis="0 0 1" range="-2 2"/>
      <body name="upper" pos="0 0 0.2">
        <joint name="j2" type="hinge" axis="0 1 0" range="-1.5 1.5"/>
        <geom type="capsule" fromto="0 0 0 0 0 0.3" size="0.04"/>
        <body name="fore" pos="0 0 0.3" euler="0.2 -0.4 0.9">
          <joint name="j3" type="hinge" axis="1 0 0" range="-2 2"/>
          <geom type="sphere" size="0.03" pos="0 0 0.1"/>
          <body name="hand" pos="0 0 0.25">
            <geom type="sphere" size="0.03"/>
            <site name="attachment_site" pos="0 0 0.05"/>
          </body>
        </body>
      </body>
    </body>
  </worldbody>
</mujoco>
"""


def test_urdf_md_import_mjcf(in_work, capsys):
    """docs/urdf.md's ``import-mjcf`` synopsis (each variant) on a small MJCF arm written as
    panda.xml: the robot file loads, and its FK of the end-effector body is MuJoCo's own
    (mj_kinematics) at random joint values."""
    mujoco = pytest.importorskip("mujoco")
    import jwarp

    (in_work / "panda.xml").write_text(MJCF_ARM)
    m = mujoco.MjModel.from_xml_path(str(in_work / "panda.xml"))
    d = mujoco.MjData(m)
    key = "docs/urdf.md: jwarp import-mjcf panda.xml"
    for variant in range(len(variants(doc(key)))):
        argv = _synopsis_argv(key, variant, {"tcp=panda_hand": "tcp=hand", "arm": "arm3",
                                              "--max-spheres": "8"})
        code, out, err = run(capsys, argv)
        assert code == 0, (argv, out + err)
        robot = jwarp.robot(str(in_work / "panda.json"))
        assert robot.joint_names == ["j1", "j2", "j3"]
        q = np.random.default_rng(variant).uniform(-1, 1, 3)
        d.qpos[:] = q
        mujoco.mj_kinematics(m, d)
        b = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "hand")
        F = jwarp.fk(robot, q)[robot.frame_index("hand")]
        np.testing.assert_allclose(F[:3, 3], d.xpos[b], atol=1e-9)
        np.testing.assert_allclose(F[:3, :3], d.xmat[b].reshape(3, 3), atol=1e-9)


def test_install_md_full_warmup(in_work, capsys):
    """docs/install.md's ``jwarp warmup`` and ``jwarp warmup --device cpu`` (the Docker and
    CI recipes): every module of every family and registered robot, compiled or found in
    Warp's kernel cache, which it names. Fast with a warm cache (~3 s); a cold one compiles
    131 modules (minutes)."""
    import warp as wp

    import jwarp
    from jwarp.cli.warmup import kernel_modules

    n = len(kernel_modules(robots=jwarp.robots()))
    for key in ("docs/install.md: jwarp warmup", "docs/install.md: jwarp warmup --device cpu"):
        code, out, err = run(capsys, argv_of(key))
        m = re.search(r"(\d+) kernel modules on cpu: (\d+) compiled, (\d+) already cached", out)
        assert code == 0 and m, out + err
        assert int(m.group(1)) == n == int(m.group(2)) + int(m.group(3))
        cache = re.search(r"^kernel cache: (\S+)$", out, re.M)
        assert cache and Path(cache.group(1)).is_dir(), out
        assert cache.group(1) == str(wp.config.kernel_cache_dir), out


#: tables whose keys name commands without running them
TABLES = ("NOT_RUN", "SCALED", "COMMAND_ELLIPSIS", "PLACEHOLDERS")


def _run_keys() -> set[str]:
    """The doc-command keys (``"FILE: text"`` string constants, implicit concatenations
    joined) this module names outside the :data:`NOT_RUN` table: the commands run by a
    test above (the :data:`TABLES` only explain or list commands)."""
    import ast

    tree = ast.parse(Path(__file__).read_text())
    skip: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Assign) and any(
                isinstance(t, ast.Name) and t.id in TABLES
                for t in node.targets):
            skip |= {id(n) for n in ast.walk(node.value)}
    pat = re.compile(r"^(README\.md|docs/[\w./]+|examples/README\.md): jwarp ")
    return {n.value for n in ast.walk(tree) if isinstance(n, ast.Constant)
            and isinstance(n.value, str) and pat.match(n.value) and id(n) not in skip}


def _commands_of(key: str) -> list[dc.DocCommand]:
    """The commands :func:`doc` resolves ``key`` to (identical texts: all of them)."""
    file, prefix = key.split(": ", 1)
    found = [c for c in COMMANDS if c.file == file and c.text.startswith(prefix)]
    exact = [c for c in found if c.text == prefix]
    return exact if len(found) > 1 and exact else found


def test_every_jwarp_command_is_run_or_listed():
    """Issue 27 item 4: every ``jwarp`` command of the docs is run by a test above (named by
    its key) or listed in :data:`NOT_RUN` with the reason; the tables name real commands,
    and a scaled command is also run."""
    run_keys = _run_keys()
    covered: dict[str, str] = {}
    for key in run_keys:
        cmds = _commands_of(key)
        assert cmds, f"{key!r} names no command"
        assert len({c.text for c in cmds}) == 1, f"{key!r} names several commands"
        covered.update({c.where: "run" for c in cmds})
    for key in NOT_RUN:
        cmds = _commands_of(key)
        assert len(cmds) == 1, key
        assert cmds[0].where not in covered, f"{key!r} is both run and in NOT_RUN"
        covered[cmds[0].where] = "not run"
    assert set(SCALED) <= run_keys
    missing = [f"{c.where}: {c.text}" for c in JWARP if c.where not in covered]
    assert not missing, "doc commands neither run nor in NOT_RUN:\n" + "\n".join(missing)
    assert len(NOT_RUN) <= 1 and sum(v == "run" for v in covered.values()) >= 65


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
@pytest.mark.filterwarnings("ignore::jwarp.calibration.estimate.result.CalibrationWarning")
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
    ``panda.urdf`` come from the text around them; README's are run whole above, those of
    docs/*.md and examples/README.md after curated preludes in tests/test_docs_snippets.py):
    every jwarp module, function and class they import or use exists."""
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
