"""Transmission errors (the robot's ``harmonic`` field) in the IK solver and the planner:
both work in the links' joint space and return commanded joint values, checked here with
the numpy reference FK of the links' joint values (an independent numpy transmission)."""

import dataclasses

import numpy as np
import pytest
from reference import ref_fk
from worlds import block_world_2d

import jwarp
from jwarp.kinematics.transmission import transmitted, untransmitted
from jwarp.solvers import planning as PL
from jwarp.solvers.ik import IKOptions, IKSolver
from jwarp.world import path_feasibility

AMP = 0.03  # rad: large, so that ignoring it would miss the targets by centimetres


def with_harmonic(robot, seed=0, amp=AMP):
    rng = np.random.default_rng(seed)
    h = rng.uniform(-amp, amp, (robot.n_dof, 2, 2)) / np.array([1.0, 2.0])[None, :, None]
    return robot.copy(harmonic=h)


def ref_transmission(robot, q):
    h = robot.harmonic
    k = np.arange(1, h.shape[1] + 1)
    kq = q[..., :, None] * k
    return q + (h[:, :, 0] * np.sin(kq) + h[:, :, 1] * np.cos(kq)).sum(-1)


def test_untransmitted_inverts_the_transmission():
    robot = with_harmonic(jwarp.robot("arm7"))
    rng = np.random.default_rng(1)
    q = rng.uniform(-2.5, 2.5, (500, robot.n_dof))
    q_link = ref_transmission(robot, q)
    np.testing.assert_allclose(transmitted(robot, q), q_link, atol=1e-15)
    np.testing.assert_allclose(untransmitted(robot, q_link), q, atol=1e-12)
    plain = jwarp.robot("arm7")
    assert np.array_equal(untransmitted(plain, q), q)


def test_untransmitted_refuses_a_non_invertible_transmission():
    robot = with_harmonic(jwarp.robot("arm7"), amp=3.0)
    with pytest.raises(ValueError, match="harmonic"):
        untransmitted(robot, np.linspace(-3, 3, 7 * 50).reshape(50, 7))


def test_ik_solutions_reach_the_target_with_the_transmission(device):
    plain = jwarp.robot("arm7")
    robot = with_harmonic(plain)
    rng = np.random.default_rng(2)
    q_true = rng.uniform(-1.5, 1.5, (16, robot.n_dof))
    T = ref_fk(plain, ref_transmission(robot, q_true))[:, -1]
    frame = robot.n_frames - 1
    opts = IKOptions(n_starts=8, iterations=200)
    res = IKSolver(robot, frame, 16, opts, device=device, dtype=np.float64).solve(T)
    assert res.feasible.sum() >= 8  # (some random targets self-collide)
    ok = res.feasible
    # FK with the transmission applied (numpy transmission, then the plain robot's FK)
    got = ref_fk(plain, ref_transmission(robot, res.q[ok]))[:, frame]
    assert np.abs(got[:, :3, 3] - T[ok, :3, 3]).max() < 1e-3
    # the commanded values differ from the links' (the errors matter at this size)
    wrong = ref_fk(plain, res.q[ok])[:, frame]
    assert np.abs(wrong[:, :3, 3] - T[ok, :3, 3]).max() > 5e-3
    np.testing.assert_allclose(res.all_q[ok, res.start_index[ok]], res.q[ok])


def test_planner_paths_are_commanded_values(device):
    plain = jwarp.robot("planar4")
    robot = with_harmonic(plain)
    world = block_world_2d()
    start = np.array([1.2, 0.0, 0.0, 0.0])
    goal = np.array([-1.2, 0.0, 0.0, 0.0])
    opts = PL.PlanOptions(n_starts=4, iterations=150)
    res = PL.Planner(robot, world, 1, opts, device=device).plan(start, goal)
    assert res.feasible[0]
    np.testing.assert_allclose(res.path[0, 0], start, atol=1e-6)  # float32 paths
    np.testing.assert_allclose(res.path[0, -1], goal, atol=1e-6)
    # the links' path is collision-free (checked on the plain robot at the links' values)
    link = ref_transmission(robot, res.path[0])
    assert path_feasibility.path_feasible(plain, world, link[None], 8, device=device)[0]
    # the chosen start's path as it ended (shorten=0: not pulled straight afterwards)
    raw = PL.Planner(robot, world, 1, dataclasses.replace(opts, shorten=0),
                     device=device).plan(start, goal)
    np.testing.assert_allclose(raw.all_paths[0, raw.start_index[0]], raw.path[0])
