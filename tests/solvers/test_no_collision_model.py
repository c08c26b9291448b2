"""No silent empty models (jwarp.world.model_check): planning, or IK in a world, with a robot
without collision spheres is an error naming the robot and how to get spheres; a robot in
self-collision at its home configurations is an error naming the link pairs; both unless
``allow_no_collision`` (CLI ``--no-collision``)."""

from __future__ import annotations

import numpy as np
import pytest
from cli_helpers import one_line_error, run
from worlds import block_world_2d

import jwarp
from jwarp.model import Sphere
from jwarp.solvers.ik import IKOptions, IKSolver, ik
from jwarp.solvers.planning import Planner, PlanOptions, plan
from jwarp.world.model_check import check_collision_model, home_configurations, home_self_collisions

START, GOAL = np.array([1.2, 0, 0, 0]), np.array([-1.2, 0, 0, 0])


@pytest.fixture(scope="module")
def world():
    return block_world_2d()


@pytest.fixture(scope="module")
def bare():
    return jwarp.robot("planar4").copy(spheres=[], name="bare4")


def test_planning_without_spheres_is_an_error(world, bare):
    with pytest.raises(ValueError, match=r"robot: 'bare4' has no collision spheres.*"
                                         r"import-urdf ROBOT.urdf --spheres fit.*"
                                         r"import-mjcf ROBOT.xml --spheres fit"):
        plan(bare, world, START, GOAL, iterations=5)
    with pytest.raises(ValueError, match="'bare4' has no collision spheres"):
        Planner(bare, world, 1, PlanOptions())
    # opted out: the straight line through the block is "feasible" (nothing is checked)
    res = plan(bare, world, START, GOAL, iterations=5, n_starts=1, start_kind="straight",
               allow_no_collision=True)
    assert res.feasible[0]
    with_spheres = plan("planar4", world, START, GOAL, iterations=0, n_starts=1,
                        start_kind="straight", fallback=None)
    assert not with_spheres.feasible[0]   # the same line collides when spheres are checked
    with pytest.raises(TypeError, match="allow_no_collision"):
        PlanOptions(allow_no_collision="yes").validate()


def test_ik_in_a_world_without_spheres_is_an_error(world, bare):
    T = jwarp.fk("planar4", np.array([0.3, 0.2, -0.1, 0.4]))[-1]
    frame = bare.n_frames - 1
    with pytest.raises(ValueError, match="'bare4' has no collision spheres.*--spheres fit"):
        ik(bare, frame, T, world=world)
    with pytest.raises(ValueError, match="'bare4' has no collision spheres"):
        IKSolver(bare, frame, 1, IKOptions(), world=world)
    assert ik(bare, frame, T).feasible                  # no world: plain kinematic IK
    assert ik(bare, frame, T, world=world, allow_no_collision=True).pos_err < 1e-3


def inflated(name: str, frame: str, radius: float):
    """``name`` with one more sphere of ``radius`` at the origin of ``frame``."""
    robot = jwarp.robot(name)
    f = robot.frame_index(frame)
    return robot.copy(spheres=list(robot.spheres) + [Sphere(frame=f, position=np.zeros(3),
                                                            radius=radius)])


def test_self_collision_at_home_names_the_link_pairs(world):
    robot = inflated("arm7", "right_7", 0.5)        # the wrist swallows the upper arm
    want = set()                                      # independent: numpy FK per sphere pair
    allowed = robot.allowed_collision_pairs
    sf, sp, sr = robot.sphere_arrays()
    for _, q in home_configurations(robot):
        T = jwarp.fk(robot, q, device="cpu", dtype=np.float64)
        x = np.array([T[f, :3, :3] @ p + T[f, :3, 3] for f, p in zip(sf, sp)])
        d = np.linalg.norm(x[:, None] - x[None], axis=-1) - sr[:, None] - sr[None]
        pairs = {tuple(sorted((robot.frames[sf[i]].name, robot.frames[sf[j]].name)))
                 for i, j in zip(*np.nonzero(d < 0)) if allowed[sf[i], sf[j]]}
        want.add(frozenset(pairs))
        got = {tuple(sorted(p[:2])) for p in home_self_collisions(robot, q)}
        assert got == pairs and got
    with pytest.raises(ValueError) as e:
        check_collision_model(robot, need_spheres=False, what="IK")
    msg = str(e.value)
    assert "'arm7' is in self-collision at both of its home configurations" in msg
    a, b = home_self_collisions(robot)[0][:2]
    assert f"'{a}'-'{b}'" in msg and "allow_no_collision=True" in msg
    T = jwarp.fk("arm7", np.full(7, 0.3))[robot.frame_index("right_7")]
    with pytest.raises(ValueError, match="self-collision at both"):
        ik(robot, "right_7", T)
    ik(robot, "right_7", T, allow_no_collision=True, iterations=2)
    # a collision at one home configuration only (the middle of the limits is free) is fine
    panda_like = inflated("arm7", "right_7", 0.01)
    assert not home_self_collisions(panda_like, home_configurations(panda_like)[1][1])
    check_collision_model(panda_like, need_spheres=True, what="planning")


@pytest.mark.parametrize("name", ["arm7", "hand4", "justin19", "planar4", "planar5",
                                  "sphere2d"])
def test_builtin_robots_pass(name):
    check_collision_model(jwarp.robot(name), need_spheres=True, what="planning")


def test_cli_plan_and_ik_no_collision(capsys, tmp_path, world, bare):
    from jwarp.world import save_world

    path, wpath = tmp_path / "bare4.json", tmp_path / "block.npz"
    bare.save(path)
    save_world(world, wpath)
    args = ["plan", "--robot", path, "--world", wpath, "--start", "1.2,0,0,0",
            "--goal", "-1.2,0,0,0", "--starts", "1", "--iterations", "2"]
    line = one_line_error(capsys, args, "--robot")
    assert "'bare4' has no collision spheres" in line and "--no-collision" in line
    assert "--spheres fit" in line
    code, out, err = run(capsys, args + ["--no-collision"])
    assert code == 0 and "is feasible" in out, (out, err)
    args = ["ik", "--robot", path, "--world", wpath, "--frame", str(bare.frames[-1].name),
            "--target", "0.5,0.5,0"]
    assert "--no-collision" in one_line_error(capsys, args, "--robot")
    code, out, err = run(capsys, args + ["--no-collision", "--iterations", "3"])
    assert code in (0, 1) and "robot bare4: IK" in out, (out, err)
