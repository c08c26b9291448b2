"""Robots one name away (issue 39 item 4): ``jwarp.robot("example-robot-data:panda")`` and
``"robot_descriptions:NAME"``, :func:`jwarp.importers.robot.example_robot_urdf`'s short
names, the errors naming the package to install, and the CLI's ``--robot`` and
``import-urdf`` taking the same names."""

from __future__ import annotations

import json
import sys
from importlib import metadata
from pathlib import Path

import numpy as np
import pytest
from cli_helpers import one_line_error, run
from robot_data import erd

import jwarp
from jwarp.importers.robot import (
    EXAMPLE_ROBOT_ALIASES,
    example_robot_names,
    example_robot_urdf,
    load_urdf,
    package_robot_path,
)


def test_example_robot_data_panda_by_name():
    path = erd("panda_description/urdf/panda.urdf")
    robot = jwarp.robot("example-robot-data:panda")
    ref = load_urdf(path).model
    assert robot.frame_names == ref.frame_names and robot.joint_names == ref.joint_names
    assert list(robot.end_effectors) == ["panda_hand_tcp"]
    q = np.random.default_rng(0).uniform(-1, 1, (5, robot.n_dof))
    np.testing.assert_array_equal(np.asarray(jwarp.fk(robot, q, dtype=np.float64)),
                                  np.asarray(jwarp.fk(ref, q, dtype=np.float64)))
    assert jwarp.robot("example-robot-data:panda") is robot   # cached as a registered robot


def test_short_names():
    erd("panda_description/urdf/panda.urdf")   # skip without the package
    assert example_robot_urdf("panda") == erd("panda_description/urdf/panda.urdf")
    assert example_robot_urdf("ur5") == erd("ur_description/urdf/ur5_robot.urdf")
    assert example_robot_urdf("xarm7") == erd("xarm_description/urdf/xarm7.urdf")
    assert example_robot_urdf("xarm") == erd("xarm_description/urdf/xarm7.urdf")  # folder
    # the old form, a path under the robots folder, still works
    assert example_robot_urdf("ur_description/urdf/ur10_robot.urdf") == \
        erd("ur_description/urdf/ur10_robot.urdf")
    names = example_robot_names()
    assert {"panda", "ur3", "ur5", "ur10", "xarm7", "z1", "baxter", "tiago", "so100"} <= set(names)
    for alias in EXAMPLE_ROBOT_ALIASES:           # every alias names a shipped file
        assert alias in names, alias
    assert package_robot_path("panda") is None    # no prefix: not a package name
    assert package_robot_path("example-robot-data:ur5") == example_robot_urdf("ur5")


def test_errors_name_the_package():
    erd("panda_description/urdf/panda.urdf")
    with pytest.raises(ValueError, match=r"robot: example-robot-data: no robot 'nope'; known: "
                                         r".*panda.*ur5"):
        jwarp.robot("example-robot-data:nope")
    with pytest.raises(ValueError, match=r"example-robot-data: 'ur' names \d+ URDFs"):
        example_robot_urdf("ur")
    with pytest.raises(ValueError, match="example-robot-data: no file"):
        example_robot_urdf("panda_description/urdf/nope.urdf")


def test_example_robot_data_not_installed(monkeypatch):
    def missing(name):
        raise metadata.PackageNotFoundError(name)

    monkeypatch.setattr(metadata, "distribution", missing)
    with pytest.raises(ValueError, match=r"robot: example-robot-data: not installed \(pip "
                                         r"install example-robot-data"):
        jwarp.robot("example-robot-data:ur10")


def test_robot_descriptions_not_installed(monkeypatch):
    monkeypatch.setitem(sys.modules, "robot_descriptions", None)   # import fails
    with pytest.raises(ValueError, match=r"robot: robot_descriptions: not installed \(pip "
                                         r"install robot_descriptions\)"):
        jwarp.robot("robot_descriptions:panda")


def test_robot_descriptions_by_name(monkeypatch, tmp_path):
    """A stand-in robot_descriptions package (the real one downloads repositories): its
    ``<name>_description`` module's URDF_PATH is loaded; with or without the suffix."""
    path = erd("ur_description/urdf/ur5_robot.urdf")
    pkg = tmp_path / "robot_descriptions"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "ur5_test_description.py").write_text(f"URDF_PATH = {path!r}\n")
    (pkg / "broken_test_description.py").write_text("raise RuntimeError('no network')\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    for mod in [m for m in sys.modules if m.startswith("robot_descriptions")]:
        monkeypatch.delitem(sys.modules, mod)
    robot = jwarp.robot("robot_descriptions:ur5_test")
    assert robot.joint_names == load_urdf(path).model.joint_names
    assert package_robot_path("robot_descriptions:ur5_test_description") == path
    with pytest.raises(ValueError, match=r"robot_descriptions: no description "
                                         r"'nope_description' or 'nope'"):
        jwarp.robot("robot_descriptions:nope")
    with pytest.raises(ValueError, match=r"robot_descriptions: broken_test_description: no "
                                         r"network"):
        jwarp.robot("robot_descriptions:broken_test")


def test_cli_takes_the_names(capsys, tmp_path):
    erd("ur_description/urdf/ur5_robot.urdf")
    out = tmp_path / "ur5.json"
    code, stdout, err = run(capsys, ["import-urdf", "example-robot-data:ur5", "--out", out,
                                     "--spheres", "none", "--json"])
    assert code == 0, err
    saved = json.loads(out.read_text())
    assert saved["name"] == "ur5" and len(saved["joints"]) == 6
    line = one_line_error(capsys, ["import-urdf", "example-robot-data:nope", "--out", out],
                          "URDF")
    assert "example-robot-data: no robot 'nope'" in line
    line = one_line_error(capsys, ["ik", "--robot", "example-robot-data:nope", "--frame",
                                   "tool0", "--target", "0.3,0,0.3"], "--robot")
    assert "example-robot-data: no robot 'nope'" in line


def test_docs_say_where_the_urdfs_lie():
    """docs/urdf.md names the folder example-robot-data's URDFs are installed in (its wheel
    has no Python module to ask): the folder example_robot_urdf reads, under the
    installation's site-packages."""
    import site
    import sysconfig

    text = (Path(__file__).resolve().parents[2] / "docs" / "urdf.md").read_text()
    stated = "<site-packages>/cmeel.prefix/share/example-robot-data/robots"
    assert stated in text and "`import\n  example_robot_data` fails" in text
    panda = Path(example_robot_urdf("panda"))
    roots = {Path(p).resolve() for p in (sysconfig.get_paths()["purelib"],
                                         *site.getsitepackages())}
    folder = next(r for r in roots if r in panda.resolve().parents)
    assert panda.resolve() == (folder / stated.split("/", 1)[1]
                               / "panda_description/urdf/panda.urdf").resolve()
