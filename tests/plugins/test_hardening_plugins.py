"""Hardening of the plugin registry: one broken plugin never disables the others.

Entry points are tested with fake distributions (``<name>.dist-info`` with METADATA and
entry_points.txt plus modules in a temporary folder on PYTHONPATH), each in a fresh Python
process so that the process-wide plugin manager starts anew. Run-time plugins
(``register_plugin``), robot files given by path, and model-level input checks
(duplicate names referred to by name, bool vs numbers, numpy scalars, 0-DoF robots) are
tested in this process.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import textwrap
import warnings
from pathlib import Path

import numpy as np
import pytest

import jwarp
from jwarp.cli import main
from jwarp.model import Mass, RobotModel, RobotModelError, Sphere
from jwarp.plugins import registry
from jwarp.plugins.registry import PluginError, PluginWarning

ROOT = Path(__file__).resolve().parents[2]
BUILTIN_ROBOTS = {"arm7", "hand4", "justin19", "planar4", "planar5", "sphere2d"}
BUILTIN_MEASUREMENTS = {"cartesian", "contact", "image", "relative"}

# ------------------------------------------------------------------ fake distributions
GOOD = {
    "goodplug_robots": """
        import jwarp

        class ExtMeasurement:
            def __init__(self, robot, setup):
                self.robot = robot

        class SharedMeasurement(ExtMeasurement):
            pass

        @jwarp.hookimpl
        def jwarp_robots():
            return {"ext_arm": lambda: jwarp.robot("planar4").copy(name="ext_arm"),
                    "shared": lambda: jwarp.robot("planar4").copy(name="shared")}

        @jwarp.hookimpl
        def jwarp_measurements():
            return {"ext_meas": ExtMeasurement, "shared_meas": SharedMeasurement}
    """,
}
BAD = {
    "badplug_importerr": """
        raise ImportError("badplug needs libfoo")
    """,
    "badplug_attr": """
        import jwarp

        @jwarp.hookimpl
        def jwarp_robots():
            return {"attr_arm": lambda: jwarp.robot("planar4")}
    """,
    "badplug_hookraises": """
        import jwarp

        @jwarp.hookimpl
        def jwarp_robots():
            raise RuntimeError("robots boom")

        @jwarp.hookimpl
        def jwarp_measurements():
            raise KeyError("measurements boom")
    """,
    "badplug_factory": """
        import jwarp

        def boom():
            raise RuntimeError("factory boom")

        @jwarp.hookimpl
        def jwarp_robots():
            return {"boom_arm": boom}
    """,
    "badplug_shared": """
        import jwarp

        @jwarp.hookimpl
        def jwarp_robots():
            return {"shared": lambda: jwarp.robot("planar5").copy(name="shared")}

        @jwarp.hookimpl
        def jwarp_measurements():
            return {"shared_meas": object}
    """,
    "badplug_misspelled": """
        import jwarp

        @jwarp.hookimpl
        def jwarp_robot():
            return {"never_arm": None}

        @jwarp.hookimpl
        def jwarp_measurement():
            return {"never_meas": None}

        @jwarp.hookimpl
        def jwarp_robots():
            return {"spelled_arm": lambda: jwarp.robot("planar4").copy(name="spelled_arm")}
    """,
    "badplug_unmarked": """
        def jwarp_robots():
            return {"unmarked_arm": None}
    """,
    "badplug_notdict": """
        import jwarp

        @jwarp.hookimpl
        def jwarp_robots():
            return ["not", "a", "dict"]
    """,
}
BAD_EPS = {
    "missing": "no_such_module_jwarp_test",
    "importerr": "badplug_importerr",
    "wrongattr": "badplug_attr:missing_attr",
    "hookraises": "badplug_hookraises",
    "factoryraises": "badplug_factory",
    "shared": "badplug_shared",
    "misspelled": "badplug_misspelled",
    "unmarked": "badplug_unmarked",
    "notdict": "badplug_notdict",
}


def _write_dist(site: Path, name: str, version: str, eps: dict[str, str],
                modules: dict[str, str]) -> None:
    info = site / f"{name}-{version}.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {name}\nVersion: {version}\n")
    lines = ["[jwarp]"] + [f"{k} = {v}" for k, v in eps.items()]
    (info / "entry_points.txt").write_text("\n".join(lines) + "\n")
    for mod, src in modules.items():
        (site / f"{mod}.py").write_text(textwrap.dedent(src))


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    site = tmp_path_factory.mktemp("site")
    _write_dist(site, "goodplug", "1.0", {"good": "goodplug_robots"}, GOOD)
    _write_dist(site, "badplug", "2.0", BAD_EPS, BAD)
    return site


def _run(site: Path, args: list[str], no_entry_points: bool = False):
    env = dict(os.environ)
    env.pop("JWARP_NO_ENTRY_POINTS", None)
    if no_entry_points:
        env["JWARP_NO_ENTRY_POINTS"] = "1"
    env["PYTHONPATH"] = os.pathsep.join([str(site), str(ROOT)])
    return subprocess.run([sys.executable, *args], env=env, capture_output=True, text=True,
                          timeout=300, cwd=str(site))


PROBE = """
import json, warnings
warnings.simplefilter("always")
with warnings.catch_warnings(record=True) as caught:
    warnings.simplefilter("always")
    import jwarp
    from jwarp.plugins import registry
    out = {"file": jwarp.__file__, "robots": jwarp.robots(), "robots2": jwarp.robots(),
           "measurements": jwarp.measurements(), "problems": registry.plugin_problems()}
    def attempt(f, *a):
        try:
            r = f(*a)
            return {"ok": getattr(r, "name", None) or getattr(r, "__name__", repr(r))}
        except Exception as e:
            return {"error": type(e).__name__, "message": str(e)}
    out["calls"] = {
        "robot ext_arm": attempt(jwarp.robot, "ext_arm"),
        "robot spelled_arm": attempt(jwarp.robot, "spelled_arm"),
        "robot arm7": attempt(jwarp.robot, "arm7"),
        "robot shared": attempt(jwarp.robot, "shared"),
        "robot boom_arm": attempt(jwarp.robot, "boom_arm"),
        "robot boom_arm again": attempt(jwarp.robot, "boom_arm"),
        "robot nope": attempt(jwarp.robot, "nope"),
        "measurement ext_meas": attempt(registry.measurement, "ext_meas"),
        "measurement cartesian": attempt(registry.measurement, "cartesian"),
        "measurement shared_meas": attempt(registry.measurement, "shared_meas"),
    }
out["warnings"] = [[w.category.__name__, str(w.message)] for w in caught]
print("PROBE" + json.dumps(out))
"""


@pytest.fixture(scope="module")
def probe(site) -> dict:
    res = _run(site, ["-c", PROBE])
    assert res.returncode == 0, res.stderr
    line = [s for s in res.stdout.splitlines() if s.startswith("PROBE")][-1]
    out = json.loads(line[len("PROBE"):])
    assert Path(out["file"]).resolve().is_relative_to(ROOT / "jwarp")
    return out


def _the(problems: list[str], *words: str) -> str:
    hits = [p for p in problems if all(w in p for w in words)]
    assert len(hits) == 1, (words, problems)
    return hits[0]


def test_broken_entry_points_leave_the_others_working(probe):
    assert set(probe["robots"]) == BUILTIN_ROBOTS | {"ext_arm", "spelled_arm", "boom_arm"}
    assert probe["robots2"] == probe["robots"]
    assert set(probe["measurements"]) == BUILTIN_MEASUREMENTS | {"ext_meas"}
    calls = probe["calls"]
    for key in ("robot ext_arm", "robot spelled_arm", "robot arm7", "measurement ext_meas",
                "measurement cartesian"):
        assert "ok" in calls[key], (key, calls[key])
    assert calls["robot ext_arm"]["ok"] == "ext_arm"
    assert calls["measurement ext_meas"]["ok"] == "ExtMeasurement"


def test_load_failures_name_entry_point_distribution_and_exception(probe):
    problems = probe["problems"]
    assert all("\n" not in p for p in problems)
    p = _the(problems, "'missing = no_such_module_jwarp_test'")
    assert "badplug 2.0" in p and "ModuleNotFoundError" in p and "failed to load" in p
    p = _the(problems, "'importerr = badplug_importerr'")
    assert "ImportError: badplug needs libfoo" in p
    p = _the(problems, "'wrongattr = badplug_attr:missing_attr'")
    assert "AttributeError" in p and "missing_attr" in p
    for p in problems:  # every problem of an entry point says how to skip them
        assert "JWARP_NO_ENTRY_POINTS=1" in p, p


def test_hooks_that_raise_or_misbehave_are_reported(probe):
    problems = probe["problems"]
    p = _the(problems, "hookraises", "jwarp_robots() raised")
    assert "RuntimeError: robots boom" in p and "badplug 2.0" in p
    p = _the(problems, "hookraises", "jwarp_measurements() raised")
    assert "KeyError" in p and "measurements boom" in p
    p = _the(problems, "notdict", "jwarp_robots() returned list")
    assert "expected a dict" in p


def test_misspelled_and_unmarked_hooks_are_reported(probe):
    problems = probe["problems"]
    _the(problems, "'misspelled = badplug_misspelled'", "hook 'jwarp_robot' is not a jwarp hook")
    _the(problems, "'misspelled = badplug_misspelled'", "hook 'jwarp_measurement' is not")
    _the(problems, "'unmarked = badplug_unmarked'", "not marked with @jwarp.hookimpl")
    assert "never_arm" not in probe["robots"] and "unmarked_arm" not in probe["robots"]


def test_name_claimed_by_two_plugins_is_an_error_only_when_asked_for(probe):
    assert "shared" not in probe["robots"] and "shared_meas" not in probe["measurements"]
    for key, what in (("robot shared", "robot 'shared'"),
                      ("measurement shared_meas", "measurement 'shared_meas'")):
        call = probe["calls"][key]
        assert call["error"] == "PluginError", call
        msg = call["message"]
        assert what in msg and "two plugins" in msg
        assert "'good = goodplug_robots' (distribution goodplug 1.0)" in msg
        assert "'shared = badplug_shared' (distribution badplug 2.0)" in msg
        assert "JWARP_NO_ENTRY_POINTS=1" in msg
    _the(probe["problems"], "robot 'shared' is claimed by two plugins")


def test_factory_that_raises_is_an_error_of_that_robot_only(probe):
    for key in ("robot boom_arm", "robot boom_arm again"):
        call = probe["calls"][key]
        assert call["error"] == "PluginError", call
        assert "'factoryraises = badplug_factory'" in call["message"]
        assert "boom_arm" in call["message"] and "RuntimeError: factory boom" in call["message"]
    nope = probe["calls"]["robot nope"]
    assert nope["error"] == "ValueError" and "unknown robot 'nope'" in nope["message"]
    assert "ext_arm" in nope["message"] and "plugin problems" in nope["message"]


def test_each_problem_is_one_plugin_warning_once(probe):
    caught = probe["warnings"]
    assert all(cat == "PluginWarning" for cat, _ in caught), caught
    messages = [m for _, m in caught]
    assert sorted(messages) == sorted(probe["problems"])  # each once, none twice
    assert all("\n" not in m for m in messages)


def test_cli_robots_lists_the_good_and_warns_one_line_each(site, probe):
    res = _run(site, ["-m", "jwarp", "robots"])
    assert res.returncode == 0, res.stderr
    listed = {line.split()[0] for line in res.stdout.splitlines()[1:]}
    assert listed == BUILTIN_ROBOTS | {"ext_arm", "spelled_arm"}
    err = [line for line in res.stderr.splitlines() if not line.startswith("Warp ")]
    assert "Traceback" not in res.stderr
    assert all(line.startswith("jwarp: warning: ") for line in err), err
    assert len(err) == len(probe["problems"]) + 1  # + the failing factory
    _the(err, "boom_arm", "RuntimeError: factory boom")
    _the(err, "'missing = no_such_module_jwarp_test'", "ModuleNotFoundError")

    res = _run(site, ["-m", "jwarp", "robots", "--json"])
    assert res.returncode == 0, res.stderr
    rows = json.loads(res.stdout)
    assert isinstance(rows, list)
    assert {r["name"] for r in rows} == BUILTIN_ROBOTS | {"ext_arm", "spelled_arm"}
    assert all(line.startswith(("jwarp: warning: ", "Warp "))
               for line in res.stderr.splitlines()), res.stderr


def test_cli_conflicting_robot_is_one_error_line(site):
    res = _run(site, ["-m", "jwarp", "info", "shared"])
    assert res.returncode == 2
    err = [line for line in res.stderr.splitlines() if not line.startswith("Warp ")]
    assert "Traceback" not in res.stderr
    assert all(line.startswith("jwarp: ") for line in err), err
    assert err[-1].startswith("jwarp: error: robot: robot 'shared' is claimed by two plugins")
    assert "goodplug 1.0" in err[-1] and "badplug 2.0" in err[-1]
    res = _run(site, ["-m", "jwarp", "info", "ext_arm"])
    assert res.returncode == 0 and "robot ext_arm" in res.stdout


def test_no_entry_points_skips_them(site):
    probe = PROBE.replace('print("PROBE"', 'out.pop("calls"); print("PROBE"')
    res = _run(site, ["-c", probe], no_entry_points=True)
    assert res.returncode == 0, res.stderr
    out = json.loads([s for s in res.stdout.splitlines() if s.startswith("PROBE")][-1][5:])
    assert set(out["robots"]) == BUILTIN_ROBOTS
    assert set(out["measurements"]) == BUILTIN_MEASUREMENTS
    assert out["problems"] == [] and out["warnings"] == []


# ------------------------------------------------------------------ register_plugin
@pytest.fixture
def registered():
    plugins = []
    yield plugins
    for p in plugins:
        if registry.plugin_manager().is_registered(p):
            registry.unregister_plugin(p)


def _robots_plugin(table):
    class P:
        @jwarp.hookimpl
        def jwarp_robots(self):
            return table() if callable(table) else table
    return P()


def test_register_plugin_refuses_misspelled_hooks():
    class Misspelled:
        @jwarp.hookimpl
        def jwarp_robot(self):
            return {}

    class Unmarked:
        def jwarp_robots(self):
            return {}

    class Measurement:
        @jwarp.hookimpl
        def jwarp_measurement(self):
            return {}

    for obj, words in ((Misspelled(), "hook 'jwarp_robot' is not a jwarp hook"),
                       (Unmarked(), "'jwarp_robots' is not marked with @jwarp.hookimpl"),
                       (Measurement(), "hook 'jwarp_measurement' is not a jwarp hook")):
        with pytest.raises(PluginError, match="register_plugin: plugin 'hard_x'") as e:
            jwarp.register_plugin(obj, name="hard_x")
        assert words in str(e.value)
        assert not registry.plugin_manager().has_plugin("hard_x")  # nothing half-registered
    with pytest.raises(PluginError, match="defines no @jwarp.hookimpl hook"):
        jwarp.register_plugin(object(), name="hard_x")
    with pytest.raises(TypeError, match="name: expected a string"):
        jwarp.register_plugin(_robots_plugin({}), name=3)
    with pytest.raises(ValueError, match="not registered"):
        registry.unregister_plugin(object())


def test_register_plugin_twice_is_a_clear_error(registered):
    p = _robots_plugin({})
    jwarp.register_plugin(p, name="hard_twice")
    registered.append(p)
    with pytest.raises(PluginError, match="register_plugin: .*already registered"):
        jwarp.register_plugin(p, name="hard_twice_2")
    with pytest.raises(PluginError, match="register_plugin: .*already registered"):
        jwarp.register_plugin(_robots_plugin({}), name="hard_twice")


def test_run_time_plugin_that_raises_or_conflicts(registered):
    def boom():
        raise RuntimeError("hard boom")

    raising = _robots_plugin(lambda: 1 / 0)
    a = _robots_plugin({"hard_dup": lambda: jwarp.robot("planar4"),
                        "hard_a": jwarp.robot("planar4")})
    b = _robots_plugin({"hard_dup": lambda: jwarp.robot("planar5"), "hard_boom": boom})
    for p, n in ((raising, "hard_raising"), (a, "hard_a_plugin"), (b, "hard_b_plugin")):
        jwarp.register_plugin(p, name=n)
        registered.append(p)
    with pytest.warns(PluginWarning) as rec:
        names = jwarp.robots()
    messages = [str(w.message) for w in rec]
    assert set(names) >= BUILTIN_ROBOTS | {"hard_a", "hard_boom"} and "hard_dup" not in names
    _the(messages, "plugin 'hard_raising'", "ZeroDivisionError")
    _the(messages, "robot 'hard_dup'", "'hard_a_plugin' and plugin 'hard_b_plugin'")
    assert jwarp.robot("hard_a").n_dof == 4 and jwarp.robot("arm7").n_dof == 7
    with pytest.raises(PluginError, match="robot 'hard_dup' is claimed by two plugins: "
                                          "plugin 'hard_a_plugin' and plugin 'hard_b_plugin'"):
        jwarp.robot("hard_dup")
    with pytest.raises(PluginError, match="plugin 'hard_b_plugin': the factory of robot "
                                          "'hard_boom' raised RuntimeError: hard boom"):
        jwarp.robot("hard_boom")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # each problem is warned once, not at every call
        jwarp.robots()
    registry.unregister_plugin("hard_b_plugin")
    assert jwarp.robot("hard_dup").n_dof == 4  # the conflict is gone with one of them


def test_cli_robots_reports_a_failing_factory(registered, capsys):
    p = _robots_plugin({"hard_cli_boom": lambda: jwarp.robot("no_such_robot_x")})
    jwarp.register_plugin(p, name="hard_cli")
    registered.append(p)
    assert main(["robots", "--json"]) == 0
    out, err = capsys.readouterr()
    names = {r["name"] for r in json.loads(out)}
    assert names == set(jwarp.robots()) - {"hard_cli_boom"} and names >= BUILTIN_ROBOTS
    line = _the(err.splitlines(), "hard_cli_boom")
    assert line.startswith("jwarp: warning: robot: plugin 'hard_cli': the factory of robot")
    assert "unknown robot 'no_such_robot_x'" in line


# ------------------------------------------------------------------ robot files by path
def test_missing_robot_file_says_file_not_found(tmp_path, capsys):
    for path in ("nope/robot.json", str(tmp_path / "nope.json"), tmp_path / "x" / "r.json"):
        with pytest.raises(ValueError, match="file not found"):
            jwarp.robot(path)
    assert main(["info", "nope.json"]) == 2
    out, err = capsys.readouterr()
    assert err.strip() == ("jwarp: error: robot: file not found: 'nope.json' (read as a path "
                           "to a robot file; no robot is registered under that name either)")
    with pytest.raises(ValueError, match="unknown robot 'nope'"):
        jwarp.robot("nope")
    path = tmp_path / "sub" / "mine.json"
    path.parent.mkdir()
    jwarp.robot("planar4").save(path)
    assert jwarp.robot(path).n_dof == 4 and jwarp.robot(str(path)).n_dof == 4


# ------------------------------------------------------------------ model input checks
def _two_link() -> dict:
    return {
        "name": "two_link",
        "joints": [{"name": "j1", "limits": [-3.0, 3.0]}, {"name": "j2", "limits": [-3.0, 3.0]}],
        "frames": [
            {"name": "base", "kind": "static", "transform": np.eye(4).tolist()},
            {"name": "link_1", "parent": "base", "kind": "dh", "dh": [0, 0, 0, 0], "joint": "j1"},
            {"name": "link_2", "parent": "link_1", "kind": "dh", "dh": [0, 0, 0.5, 0],
             "joint": "j2"},
        ],
        "masses": [{"frame": "link_2", "mass": 1.0, "com": [0.1, 0, 0]}],
        "spheres": [{"frame": "link_2", "position": [0, 0, 0], "radius": 0.05}],
        "end_effectors": {"tcp": "link_2"},
    }


def test_duplicate_frame_name_referred_to_by_name(tmp_path):
    # link_2 renamed to link_1 by a copy-paste slip: masses, spheres and end-effectors still
    # say "link_2"; the duplicate is the cause and is reported, not "unknown frame 'link_2'"
    doc = _two_link()
    doc["frames"][2]["name"] = "link_1"
    with pytest.raises(RobotModelError, match=r"^frames\[2\]\.name: duplicate frame name "
                                              r"'link_1' \(also frames\[1\]\)$"):
        RobotModel.from_dict(doc)
    path = tmp_path / "dup.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(RobotModelError, match=r"dup\.json: frames\[2\]\.name: duplicate frame"):
        RobotModel.load(path)


def test_duplicate_joint_name_referred_to_by_name():
    doc = _two_link()
    doc["joints"][1]["name"] = "j1"   # frames[2] still refers to "j2"
    with pytest.raises(RobotModelError, match=r"^joints\[1\]\.name: duplicate joint name 'j1' "
                                              r"\(also joints\[0\]\)$"):
        RobotModel.from_dict(doc)


@pytest.mark.parametrize("name", [None, 3, "", ["a"]])
def test_frame_and_joint_names_must_be_strings(name):
    for key in ("frames", "joints"):
        doc = _two_link()
        doc[key][1]["name"] = name
        with pytest.raises(RobotModelError, match=rf"{key}\[1\]\.name: expected a non-empty "
                                                  r"string"):
            RobotModel.from_dict(doc)


def test_end_effector_must_not_shadow_another_frame():
    doc = _two_link()
    doc["end_effectors"] = {"link_1": "link_2"}
    with pytest.raises(RobotModelError, match=r"end_effectors\.link_1: the name of frame 1 "
                                              r"'link_1', but points at frame 2"):
        RobotModel.from_dict(doc)
    doc["end_effectors"] = {"link_2": "link_2", "tcp": 2}
    assert RobotModel.from_dict(doc).frame_index("link_2") == 2


def test_zero_dof_robot_is_refused_at_load():
    doc = _two_link()
    doc["joints"] = []
    for f in doc["frames"]:
        f.pop("joint", None)
    with pytest.raises(RobotModelError, match="joints: a robot needs at least one joint"):
        RobotModel.from_dict(doc)


BOOL_FIELDS = [
    (("masses", 0, "mass"), r"masses\[0\]\.mass"),
    (("masses", 0, "com", 0), r"masses\[0\]\.com"),
    (("spheres", 0, "radius"), r"spheres\[0\]\.radius"),
    (("joints", 0, "limits", 1), r"joints\[0\]\.limits"),
    (("frames", 1, "dh", 2), r"frames\[1\]\.dh"),
    (("frames", 0, "transform", 0, 0), r"frames\[0\]\.transform"),
    (("gravity",), "gravity"),
    (("kappa", 1, 0), "kappa"),
    (("workspace_dim",), "workspace_dim"),
    (("frames", 1, "parent"), r"frames\[1\]\.parent"),
    (("masses", 0, "frame"), r"masses\[0\]\.frame"),
    (("linear_limits", 0, "coefficients", 0), r"linear_limits\[0\]\.coefficients"),
    (("linear_limits", 0, "limits", 0), r"linear_limits\[0\]\.limits"),
]


def _set(doc, path, value):
    for k in path[:-1]:
        doc = doc[k]
    doc[path[-1]] = value


def _full_doc() -> dict:
    doc = _two_link()
    doc["gravity"] = [0.0, 0.0, -9.81]
    doc["kappa"] = [[0, 0, 0], [1e-4, 1e-4, 1e-4], [1e-4, 1e-4, 1e-4]]
    doc["workspace_dim"] = 3
    doc["linear_limits"] = [{"joints": ["j1", "j2"], "coefficients": [1.0, 1.0],
                             "limits": [-1.0, 1.0]}]
    return doc


@pytest.mark.parametrize("path,where", BOOL_FIELDS,
                         ids=[".".join(map(str, p)) for p, _ in BOOL_FIELDS])
def test_bool_is_refused_where_a_number_is_meant(path, where):
    RobotModel.from_dict(_full_doc())  # the document itself is fine
    for value in (True, np.bool_(False)):
        doc = _full_doc()
        if path == ("gravity",):
            value = [0.0, 0.0, value]
        _set(doc, path, value)
        with pytest.raises(RobotModelError, match=where + ".*(bool|True|False)"):
            RobotModel.from_dict(doc)


def test_bool_is_refused_in_python_built_models():
    m = jwarp.robot("planar4")
    with pytest.raises(RobotModelError, match=r"masses\[0\]\.mass"):
        m.copy(masses=[Mass(frame=1, mass=True, com=np.zeros(3))])
    with pytest.raises(RobotModelError, match="kappa.*bool"):
        m.copy(kappa=np.zeros((m.n_frames, 3), bool))


def test_numpy_scalars_are_accepted_and_saved_as_plain_numbers(tmp_path):
    doc = _full_doc()
    doc["masses"][0]["mass"] = np.float32(0.5)
    doc["masses"][0]["frame"] = np.int64(2)
    doc["spheres"][0]["radius"] = np.float16(0.25)
    doc["joints"][0]["limits"] = [np.float32(-1.5), np.float64(1.5)]
    doc["frames"][2]["parent"] = np.int32(1)
    doc["frames"][2]["joint"] = np.int64(1)
    doc["workspace_dim"] = np.int64(3)
    doc["kappa"][1][0] = np.float32(2e-4)
    doc["end_effectors"] = {"tcp": np.int64(2)}
    doc["linear_limits"][0]["limits"] = [np.float32(-1), np.float32(1)]
    doc["linear_limits"][0]["joints"] = [np.int64(0), "j2"]
    m = RobotModel.from_dict(doc)
    assert m.masses[0].mass == 0.5 and m.masses[0].frame == 2 and m.spheres[0].radius == 0.25
    assert m.joints[0].lower == -1.5 and m.frame_index("tcp") == 2 and m.workspace_dim == 3
    assert math.isclose(m.kappa[1, 0], 2e-4, rel_tol=1e-6)
    path = tmp_path / "np.json"
    m.save(path)  # json cannot write numpy scalars: the model holds plain numbers
    back = RobotModel.load(path)
    assert back.to_dict() == m.to_dict()
    # Python-built models too: validation turns numpy scalars into plain numbers
    m2 = m.copy(workspace_dim=np.int64(3),
                masses=[Mass(frame=np.int64(1), mass=np.float32(0.25), com=np.zeros(3))],
                spheres=[Sphere(frame=np.int32(2), position=[0, 0, 0], radius=np.float32(0.5))])
    doc2 = json.loads(json.dumps(m2.to_dict()))
    assert doc2["workspace_dim"] == 3 and doc2["masses"][0] == {"frame": 1, "mass": 0.25,
                                                                 "com": [0.0, 0.0, 0.0]}
    assert doc2["spheres"][0]["frame"] == 2 and doc2["spheres"][0]["radius"] == 0.5
