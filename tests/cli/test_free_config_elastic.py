"""``jwarp free-config --elastic``: configurations collision-free on the deflected robot,
the check ``plan``/``ik --elastic`` apply to their start and goal (README's elastic plan
sends readers to free-config)."""

from __future__ import annotations

import json

import numpy as np
from cli_helpers import run

import jwarp
from jwarp.cli.common import DEFAULT_KAPPA
from jwarp.world import parse_world_spec
from jwarp.world.path_feasibility import collision_free


def _configs(capsys, *extra):
    code, out, err = run(capsys, ["free-config", "--robot", "justin19", "--world",
                                  "simplex:seed=1", "--n", "4", "--seed", "0", "--json", *extra])
    assert code == 0, err
    doc = json.loads(out)
    return doc, np.array(doc["configurations"])


def test_elastic_configurations_are_free_on_the_deflected_robot(capsys):
    """justin19's own compliances are zero (uncalibrated): --elastic takes the CLI's
    default kappa, as plan --elastic does."""
    robot = jwarp.robot("justin19")
    world = parse_world_spec("simplex:seed=1", robot)
    doc, q = _configs(capsys, "--elastic")
    assert doc["elastic"] is True and q.shape == (4, robot.n_dof)
    assert collision_free(robot, world, q, 0.0, kappa=DEFAULT_KAPPA, device="cpu").all()
    rigid_doc, rigid = _configs(capsys)
    assert rigid_doc["elastic"] is False
    assert collision_free(robot, world, rigid, 0.0, device="cpu").all()
    # the rigid draws are not all free once the robot sags (README's case: -14.5 mm)
    assert not collision_free(robot, world, rigid, 0.0, kappa=DEFAULT_KAPPA, device="cpu").all()


def test_kappa_without_elastic_is_refused(capsys):
    code, out, err = run(capsys, ["free-config", "--robot", "justin19", "--kappa", "1e-4"])
    assert code != 0 and "--kappa" in err


def test_absurd_kappa_names_the_option_and_collision_free_reports_not_free(capsys):
    """Reliability round 4, item 9: ``--elastic --kappa 1e308`` failed with "free-config:
    rho: contains NaN or inf"; collision_free of configurations whose equilibrium does not
    converge raised instead of calling them not free (its docstring)."""
    code, out, err = run(capsys, ["free-config", "--robot", "planar4", "--world",
                                  "simplex:seed=3", "--n", "2", "--seed", "0", "--elastic",
                                  "--kappa", "1e308"])
    assert code == 2 and out == ""
    assert err.strip().splitlines()[-1].startswith(
        "jwarp: error: --kappa: the elastic equilibrium converges at none of")
    robot = jwarp.robot("planar4")
    world = parse_world_spec("simplex:seed=3", robot)
    q = np.zeros((3, robot.n_dof))
    assert not collision_free(robot, world, q, 0.0, kappa=1e308, device="cpu").any()
