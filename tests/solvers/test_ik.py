"""Two-stage IK (jwarp/solvers/ik/solver.py, jwarp/kernels/ik.py): costs vs numpy and finite
differences, targets reached to tolerance, collision-free solutions, clear errors."""

import numpy as np
import pytest
from reference import central_difference_grad  # tests/reference.py
from scipy.spatial.transform import Rotation

import jwarp
from jwarp.core.limits import sample_within_limits, within_limits
from jwarp.solvers import ik as IK
from jwarp.world import collision, shelf_world


def ref_costs(F, T, lam_p, lam_r):
    dp = F[:3, 3] - T[:3, 3]
    return 0.5 * lam_p * dp @ dp + 0.5 * lam_r * (3 - np.trace(F[:3, :3] @ T[:3, :3].T))


def test_pose_error_and_uik_gradient_match_numpy_and_fd(device):
    robot = jwarp.robot("arm7")
    world = shelf_world()
    rng = np.random.default_rng(0)
    q = sample_within_limits(robot, 4, rng)
    qt = sample_within_limits(robot, 4, rng)
    T = jwarp.fk(robot, qt, device=device)[:, robot.frame_index("tcp")]
    w = IK.IKWeights(position=2.0, rotation=0.5, world=1.0, self=0.5, default=0.1)
    qd = rng.uniform(-0.5, 0.5, robot.n_dof)
    obj = IK.IKObjective(robot, "tcp", 4, world=world, weights=w, eps=0.05, q_default=qd,
                         device=device, dtype=np.float64)
    u, g = obj.value_and_grad(q, T)
    F = jwarp.fk(robot, q, device=device)[:, robot.frame_index("tcp")]
    err = obj.err.numpy()
    for b in range(4):
        np.testing.assert_allclose(err[b, :3], T[b, :3, 3] - F[b, :3, 3], atol=1e-12)
        rv = Rotation.from_matrix(T[b, :3, :3] @ F[b, :3, :3].T).as_rotvec()
        np.testing.assert_allclose(err[b, 3:], rv, atol=1e-9)
    c, _ = collision.collision_cost(robot, q, world, w_world=1.0, w_self=0.5, eps=0.05,
                                    device=device, dtype=np.float64)
    ref = [ref_costs(F[b], T[b], 2.0, 0.5) for b in range(4)]
    ref = np.array(ref) + c + 0.05 * np.sum((q - qd) ** 2, axis=1)
    np.testing.assert_allclose(u, ref, rtol=1e-10)
    fd = central_difference_grad(lambda x: obj.value_and_grad(x, T)[0], q)
    np.testing.assert_allclose(g, fd, rtol=1e-5, atol=1e-6)


def _check_reached(robot, frame, q, T, device, tol_p=1e-4, tol_r=1e-3):
    F = jwarp.fk(robot, q, device=device)[..., robot.frame_index(frame), :, :]
    pos = np.linalg.norm(F[..., :3, 3] - T[..., :3, 3], axis=-1)
    ang = Rotation.from_matrix((F[..., :3, :3] @ np.swapaxes(T[..., :3, :3], -1, -2))
                               .reshape(-1, 3, 3)).magnitude()
    assert np.all(pos < tol_p) and np.all(ang < tol_r), (pos, ang)


@pytest.mark.parametrize("name,frame", [("arm7", "tcp"), ("justin19", "right_tcp"),
                                        ("justin19", "left_tcp")])
def test_ik_reaches_targets_to_tolerance(device, name, frame):
    robot = jwarp.robot(name)
    rng = np.random.default_rng(1)
    qt = sample_within_limits(robot, 6, rng)
    free = collision.is_collision_free(robot, qt, device=device)  # reachable without self-collision
    qt = qt[free][:4]
    T = jwarp.fk(robot, qt, device=device)[:, robot.frame_index(frame)]
    res = IK.ik(robot, frame, T, n_starts=8, seed=2, device=device)
    assert res.q.shape == (len(qt), robot.n_dof) and res.feasible.all()
    assert np.all(res.pos_err < 1e-4) and np.all(res.rot_err < 1e-3)
    _check_reached(robot, frame, res.q, T, device)
    assert within_limits(robot, res.q).all()
    assert collision.is_collision_free(robot, res.q, device=device).all()


def test_planar_ik_uses_x_y_and_yaw(device):
    robot = jwarp.robot("planar4")
    q = np.array([[0.3, -0.4, 0.8, 0.2]])
    T = jwarp.fk(robot, q, device=device)[:, robot.frame_index("tcp")]
    res = IK.ik(robot, "tcp", T, n_starts=4, device=device)
    assert res.feasible.all()
    _check_reached(robot, "tcp", res.q, T, device)


def test_collision_free_ik_in_a_shelf(device):
    robot = jwarp.robot("justin19")
    world = shelf_world()
    # a grasp pose between the two boards, hand (0.35 m of spheres) pointing forward (+x)
    T = IK.pose_matrix([0.6, -0.25, 0.8], Rotation.from_euler("y", 90, degrees=True).as_rotvec())
    res = IK.ik(robot, "right_tcp", T, world=world, n_starts=16, margin=0.01, seed=0,
                device=device)
    assert res.feasible and res.pos_err < 1e-4 and res.rot_err < 1e-3
    assert res.q.shape == (robot.n_dof,)
    _check_reached(robot, "right_tcp", res.q, T, device)
    assert collision.is_collision_free(robot, res.q[None], world, margin=0.01, device=device).all()
    d = res.to_dict()
    assert d["feasible"] and len(d["q"]) == 19


def test_bad_inputs():
    robot = jwarp.robot("arm7")
    T = np.eye(4)
    with pytest.raises(ValueError, match="frame"):
        IK.ik(robot, "no_such_frame", T)
    with pytest.raises(ValueError, match="target"):
        IK.ik(robot, "tcp", np.eye(3))
    bad = np.eye(4)
    bad[:3, :3] *= 2
    with pytest.raises(ValueError, match="target: rotation"):
        IK.ik(robot, "tcp", bad)
    with pytest.raises(ValueError, match="world"):
        IK.ik("planar4", "tcp", T, world=shelf_world())
    with pytest.raises(ValueError, match="seeds"):
        IK.ik(robot, "tcp", T, seeds=np.zeros((2, 3)))
    with pytest.raises(ValueError, match="n_starts"):
        IK.ik(robot, "tcp", T, n_starts=0)


def test_torch_uik_matches_numpy_gradient(device):
    torch = pytest.importorskip("torch")
    from jwarp.learn.torch_costs import u_ik

    robot = jwarp.robot("arm7")
    world = shelf_world()
    rng = np.random.default_rng(4)
    q = sample_within_limits(robot, 3, rng)
    T = jwarp.fk(robot, sample_within_limits(robot, 3, rng), device=device)[:, 8]
    w = IK.IKWeights(default=0.2)
    obj = IK.IKObjective(robot, "tcp", 3, world=world, weights=w, device=device, dtype=np.float64)
    u_ref, g_ref = obj.value_and_grad(q, T)
    qt = torch.tensor(q, requires_grad=True, device=device)  # u_ik runs on q's device
    u = u_ik(qt, torch.tensor(T, device=device), robot, "tcp", world=world, weights=w)
    np.testing.assert_allclose(u.detach().cpu().numpy(), u_ref, rtol=1e-12)
    u.sum().backward()
    np.testing.assert_allclose(qt.grad.cpu().numpy(), g_ref, rtol=1e-12)
    with pytest.raises(ValueError, match="target"):
        u_ik(qt, torch.tensor(T[:2], device=device), robot, "tcp")


def test_compensated_ik_reaches_the_target_on_the_elastic_model(device):
    from jwarp.solvers import compensation as C

    robot = jwarp.robot("justin19")
    rng = np.random.default_rng(6)
    qt = sample_within_limits(robot, 10, rng)
    qt = qt[collision.is_collision_free(robot, qt, device=device)][:3]
    T = jwarp.fk(robot, qt, device=device)[:, robot.frame_index("right_tcp")]
    kappa = C.JUSTIN_KAPPA
    res = C.compensated_ik(robot, "right_tcp", T, kappa=kappa, n_starts=8, seed=1, device=device)
    assert res.feasible.all()
    # independent check: the converged elastic model (fk_elastic from rho0) at the solution
    pos, ang = C.equilibrium_pose_error(robot, "right_tcp", res.q, T, kappa, device=device)
    assert np.all(pos < 1.1e-4) and np.all(ang < 1.1e-3), (pos, ang)
    # the rigid model at the same q misses the target by the sag (mm to cm)
    F = jwarp.fk(robot, res.q, device=device)[:, robot.frame_index("right_tcp")]
    assert np.all(np.linalg.norm(F[:, :3, 3] - T[:, :3, 3], axis=1) > 1e-3)
    with pytest.raises(ValueError, match="kappa"):
        C.compensated_ik(robot, "right_tcp", T, device=device)  # justin19 ships without compliances


def test_ik_iteration_overhead_times_whole_solver_iterations(device):
    from jwarp.solvers import compensation as C

    out = C.ik_iteration_overhead(jwarp.robot("arm7"), "tcp", 1e-3, n_starts=4, iterations=8, rounds=2,
                                  device=device)
    assert out["rigid_s"] > 0 and out["elastic_s"] > 0
    assert out["overhead"] == pytest.approx(out["elastic_s"] / out["rigid_s"] - 1)
    assert len(out["overhead_per_round"]) == 2
    assert out["rigid_setup_s"] > 0 and out["elastic_setup_s"] > 0
    with pytest.raises(ValueError, match="iterations"):
        C.ik_iteration_overhead(jwarp.robot("arm7"), "tcp", 1e-3, n_starts=2, iterations=1, device=device)
    with pytest.raises(ValueError, match="frame"):
        C.ik_iteration_overhead(jwarp.robot("arm7"), "no_such_frame", 1e-3, n_starts=2, iterations=2,
                                device=device)


@pytest.mark.parametrize("kappa", [None, 1e-3])
def test_ik_jacobian_from_fk_frames_matches_the_jacobian_kernel(device, kappa):
    """The pose-error kernel builds J from the FK frames (coupled torso included); it equals
    jwarp.jacobian at the same q and DH rows (the compensation rows when elastic)."""
    from jwarp.kinematics import jacobian

    robot = jwarp.robot("justin19")
    q = sample_within_limits(robot, 5, np.random.default_rng(8))
    obj = IK.IKObjective(robot, "right_tcp", 5, kappa=kappa, device=device, dtype=np.float64)
    obj.set_q(q)
    obj.set_target(np.repeat(np.eye(4)[None], 5, axis=0))
    for _ in range(2 if kappa else 1):  # elastic: a second pass at bent rows
        obj.evaluate_pose()
        obj.evaluate_aux()
    obj.evaluate_pose()
    dh = obj.compensation.rho() if kappa else None
    want = jacobian(robot, q, "right_tcp", dh=dh, device=device, dtype=np.float64)
    np.testing.assert_allclose(obj.jac.numpy(), want, atol=1e-12)
    assert np.abs(want[:, :, :3]).max() > 0.1  # the torso columns are there


def _same_result(a, b):
    for name in ("q", "pos_err", "rot_err", "feasible", "iterations"):
        np.testing.assert_array_equal(np.asarray(getattr(a, name)), np.asarray(getattr(b, name)),
                                      err_msg=name)


def test_ik_takes_options_and_overrides():
    """ik(options=..., **overrides): the options are dataclasses.replace(options,
    **overrides); an override wins over the options' field; the results equal the keyword
    call bit for bit; the options object is not modified."""
    robot = jwarp.robot("arm7")
    q = sample_within_limits(robot, 4, np.random.default_rng(11))
    T = np.asarray(jwarp.fk(robot, q, device="cpu"))[:, robot.frame_index("right_tcp")]
    kw = IK.ik(robot, "right_tcp", T, n_starts=3, seed=5, iterations=120, tol_pos=2e-4,
               freeze_solved=False, orientation="axis", free_axis=(0.0, 1.0, 1.0))
    opts = IK.IKOptions(n_starts=7, seed=1, iterations=120, orientation="axis",
                        free_axis=(0.0, 1.0, 1.0))
    a = IK.ik(robot, "right_tcp", T, options=opts, n_starts=3, seed=5, tol_pos=2e-4,
              freeze_solved=False)
    b = IK.ik(robot, "right_tcp", T, options=IK.IKOptions(
        n_starts=3, seed=5, iterations=120, tol_pos=2e-4, freeze_solved=False,
        orientation="axis", free_axis=(0.0, 1.0, 1.0)))
    _same_result(a, kw)
    _same_result(b, kw)
    assert np.asarray(kw.feasible).any()
    assert (opts.n_starts, opts.seed, opts.tol_pos) == (7, 1, 1e-4)  # not modified
    other = IK.ik(robot, "right_tcp", T, options=opts)  # the options' own seed and starts
    assert not np.array_equal(np.asarray(other.q), np.asarray(kw.q))


def test_ik_rejects_unknown_options_naming_them():
    robot = jwarp.robot("arm7")
    with pytest.raises(TypeError, match=r"ik\(\) got an unexpected option 'n_seeds'; "
                                        r"options are the fields of IKOptions: .*\bn_starts\b"):
        IK.ik(robot, "tcp", np.eye(4), n_seeds=4)
    with pytest.raises(TypeError, match="^options: expected IKOptions or None"):
        IK.ik(robot, "tcp", np.eye(4), options={"n_starts": 4})
    with pytest.raises(ValueError, match="^n_starts"):  # values: validated as before
        IK.ik(robot, "tcp", np.eye(4), options=IK.IKOptions(), n_starts=0)
