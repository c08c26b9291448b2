"""Compensation rows (jwarp/elastic_rows.py, kernels/elastic.py compensation_update)
against the numpy reference of the damped torque iteration."""

import dataclasses

import numpy as np
import pytest
import warp as wp
from devices import requires_cuda
from reference import kappa_uniform, nominal_dh, ref_fk, ref_fk_elastic, ref_torques
from worlds import block_world

import jwarp
from jwarp.core.device import put_model
from jwarp.core.limits import sample_within_limits
from jwarp.kernels import fk as fk_kernels
from jwarp.kinematics.compensation import CompensationRows
from jwarp.solvers import planning as PL
from jwarp.world import collision, path_feasibility

LAM = 0.6


def _frames(model, F, device="cpu"):
    """(N, nf, 4, 4) numpy -> warp mat44 array (N, nf) float64 on ``device``."""
    return wp.array(np.ascontiguousarray(F), dtype=fk_kernels.kernels(wp.float64).mat44,
                    device=device)


def _expected(model, F, prev, kappa):
    """One damped update of the rows ``prev`` (B, nf, 5) from frames F at those rows."""
    rho0 = nominal_dh(model)
    tau = ref_torques(model, F, prev)
    target = rho0 + np.stack([np.zeros_like(tau[..., 0]), kappa[..., 2] * tau[..., 2],
                              np.zeros_like(tau[..., 0]), kappa[..., 0] * tau[..., 0],
                              kappa[..., 1] * tau[..., 1]], axis=-1)
    return (1 - LAM) * prev + LAM * target


@pytest.mark.parametrize("name, gravity, per_waypoint, per_frame", [
    ("justin19", None, False, False), ("arm7", None, False, False),
    ("justin19", [1.5, -2.0, -9.5], False, False),  # gravity off the z-axis: general torques
    ("arm7", None, True, False),  # a compliance table per waypoint
    ("justin19", None, True, True)])  # one thread per (waypoint, DH frame), CUDA's default
def test_update_from_given_frames_matches_reference_and_maps_substeps(name, gravity,
                                                                      per_waypoint, per_frame):
    model = jwarp.robot(name)
    if gravity is not None:
        model = dataclasses.replace(model, gravity=np.array(gravity))
    kappa = kappa_uniform(model, 2e-3)
    P, W, n_sub = 2, 3, 3
    S = (W - 1) * n_sub + 1
    if per_waypoint:
        kappa = kappa * np.linspace(0.5, 2.0, P * W)[:, None, None]
    q = sample_within_limits(model, P * S, np.random.default_rng(1))
    rows = CompensationRows(put_model(model, "cpu", np.float64), P, W, n_sub, kappa, LAM)
    assert rows.rows.shape == (P * W, model.n_frames, 9)
    np.testing.assert_array_equal(rows.delta.numpy(), 1e30)  # nothing converged yet
    # substep s of a path reads waypoint round(s / n_sub), ties to the later one
    np.testing.assert_array_equal(rows.config_rows(), [0, 0, 1, 1, 1, 2, 2, 3, 3, 4, 4, 4, 5, 5])
    wpt = np.array([p * S + w * n_sub for p in range(P) for w in range(W)])
    prev = np.broadcast_to(nominal_dh(model), (P * W, model.n_frames, 5)).copy()
    for _ in range(3):  # the second and third start from bent rows (beta != 0)
        F = ref_fk(model, q, rows.rho())  # frames of every configuration at its rows
        delta = rows.update(_frames(model, F), per_frame=per_frame).numpy()
        want = _expected(model, F[wpt], prev, kappa)
        got = rows.rows.numpy()
        np.testing.assert_allclose(got[..., :5], want, atol=1e-12)
        np.testing.assert_allclose(got[..., 5:], np.stack(
            [np.cos(want[..., 3]), np.sin(want[..., 3]), np.cos(want[..., 4]),
             np.sin(want[..., 4])], -1), atol=1e-12)
        np.testing.assert_allclose(delta, np.abs(want - prev).max(axis=(1, 2)), atol=1e-12)
        prev = want
    assert np.abs(prev - nominal_dh(model)).max() > 1e-3  # the robot does bend
    with pytest.raises(ValueError, match="frames"):
        rows.update(_frames(model, F[:3]))


def test_rows_converge_to_the_equilibrium_under_a_fixed_path(device):
    """With the path held still, each evaluate is one damped iteration at every waypoint:
    after k evaluates the rows equal the reference iteration's k-th iterate."""
    model = jwarp.robot("justin19")
    kappa = kappa_uniform(model, 1e-4)
    q = sample_within_limits(model, 4, np.random.default_rng(2))
    Q = path_feasibility.initial_paths(q[:2], q[2:], 5, "straight")
    obj = PL.PathObjective(model, block_world(), 2, 5, 4, kappa=kappa, lam=LAM, dtype=np.float64,
                           device=device)
    obj.set_paths(Q)
    k = 12
    for _ in range(k):
        obj.evaluate()
    _, rho_ref = ref_fk_elastic(model, Q.reshape(-1, model.n_dof), kappa, n_iter=k, lam=LAM)
    rows_all = obj.compensation.rows.numpy()
    rows = rows_all[..., :5]
    np.testing.assert_allclose(rows, rho_ref, atol=1e-10)
    # the last updates are small steps (cos/sin chained from the previous rows'): the
    # cos/sin columns must still match their angles
    assert np.abs(obj.compensation.delta.numpy()).max() < 2e-4
    np.testing.assert_allclose(rows_all[..., 5:], np.stack(
        [np.cos(rows[..., 3]), np.sin(rows[..., 3]), np.cos(rows[..., 4]),
         np.sin(rows[..., 4])], -1), rtol=0, atol=1e-14)
    _, rho_eq = ref_fk_elastic(model, Q.reshape(-1, model.n_dof), kappa, n_iter=40, lam=LAM)
    assert np.abs(rows - rho_eq).max() < 1e-5
    obj.set_paths(Q)  # new paths start again from the rigid robot
    np.testing.assert_array_equal(obj.compensation.rows.numpy()[..., :5],
                                  np.broadcast_to(nominal_dh(model), rows.shape))


def test_cost_at_compensation_rows_equals_cost_at_expanded_rows(device):
    """use_rho = 2 (rows with cos/sin, one per waypoint) == use_rho = 1 (per configuration)."""
    model = jwarp.robot("justin19")
    world = block_world()
    P, W, n_sub = 3, 4, 5
    S = (W - 1) * n_sub + 1
    q = sample_within_limits(model, P * S, np.random.default_rng(3))
    rows = CompensationRows(put_model(model, device, np.float64), P, W, n_sub, 3e-3, LAM)
    for _ in range(2):
        rows.update(_frames(model, ref_fk(model, q, rows.rho()), device))
    cm = collision.collision_model(model, world, device=device, dtype=np.float64)
    qw = wp.array(q, dtype=wp.float64, device=device)
    c2, g2 = (a.numpy() for a in cm.cost(qw, rho=rows, eps=0.05))
    c1, g1 = (a.numpy() for a in cm.cost(qw, rho=rows.rho(), eps=0.05))
    c0, _ = cm.cost(qw, eps=0.05)
    assert np.any(c1 > 0) and np.abs(c1 - c0.numpy()).max() > 1e-6  # the rows matter
    np.testing.assert_allclose(c2, c1, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(g2, g1, rtol=1e-9, atol=1e-10)
    # the gradient holds the rows fixed: central differences in q at the same rows
    hit = np.nonzero(c2 > 1e-6)[0][:4]
    assert len(hit)
    h = 1e-6
    for j in range(0, model.n_dof, 3):
        qp, qm = q.copy(), q.copy()
        qp[:, j] += h
        qm[:, j] -= h
        cp = cm.cost(wp.array(qp, dtype=wp.float64, device=device), rho=rows, eps=0.05,
                     grad=False)[0].numpy()
        cmn = cm.cost(wp.array(qm, dtype=wp.float64, device=device), rho=rows, eps=0.05,
                      grad=False)[0].numpy()
        np.testing.assert_allclose(g2[hit, j], ((cp - cmn) / (2 * h))[hit], rtol=1e-4,
                                   atol=1e-6)
    # the update fused into the cost launch equals the update from reference frames
    twin = CompensationRows(put_model(model, device, np.float64), P, W, n_sub, 3e-3, LAM)
    for _ in range(2):
        twin.update(_frames(model, ref_fk(model, q, twin.rho()), device))
    F = ref_fk(model, q, rows.rho())
    cm.cost(qw, rho=rows, eps=0.05, update_rows=True)
    twin.update(_frames(model, F, device))
    np.testing.assert_allclose(rows.rows.numpy(), twin.rows.numpy(), atol=1e-12)
    np.testing.assert_allclose(rows.delta.numpy(), twin.delta.numpy(), atol=1e-12)
    assert rows.iterations == 3
    with pytest.raises(ValueError, match="rho"):
        cm.cost(qw[:5], rho=rows, eps=0.05)
    with pytest.raises(ValueError, match="update_rows"):
        cm.cost(qw, rho=rows.rho(), eps=0.05, update_rows=True)


def test_bad_compensation_arguments():
    t = put_model(jwarp.robot("arm7"), "cpu", np.float64)
    with pytest.raises(ValueError, match="lam"):
        CompensationRows(t, 1, 3, 2, 1e-4, 0.0)
    with pytest.raises(ValueError, match="kappa"):
        CompensationRows(t, 1, 3, 2, -1e-4, 0.5)
    with pytest.raises(ValueError, match="kappa"):
        CompensationRows(t, 2, 3, 2, np.full((5, t.robot.n_frames, 3), 1e-4), 0.5)


@requires_cuda
def test_cuda_fused_update_matches_the_reference_iteration():
    """On CUDA (frame-major scratch, one prefix column per waypoint) after k evaluates the
    rows are the reference's k-th iterate, with the threads in path order and with the
    waypoints first, which also give the same substep costs and gradients."""
    model = jwarp.robot("justin19")
    kappa = kappa_uniform(model, 1e-3)
    q = sample_within_limits(model, 6, np.random.default_rng(4))
    Q = path_feasibility.initial_paths(q[:3], q[3:], 6, "straight")
    _, rho_ref = ref_fk_elastic(model, Q.reshape(-1, model.n_dof), kappa, n_iter=3, lam=LAM)
    objs = []
    for first in (False, True):
        obj = PL.PathObjective(model, block_world(), 3, 6, 4, kappa=kappa, lam=LAM,
                               dtype=np.float64, device="cuda:0")
        obj.compensation.waypoints_first = first
        obj.set_paths(Q)
        for _ in range(3):
            obj.evaluate()
        np.testing.assert_allclose(obj.compensation.rows.numpy()[..., :5], rho_ref, atol=1e-10)
        objs.append(obj)
    assert np.any(objs[0].sub_cost.numpy() > 0)
    for name in ("sub_cost", "sub_grad"):
        np.testing.assert_allclose(getattr(objs[1], name).numpy(), getattr(objs[0], name).numpy(),
                                   rtol=1e-9, atol=1e-11)


_waypoint_thread = fk_kernels.kernels(wp.float32).waypoint_thread


@wp.kernel
def _thread_map(layout: wp.vec4i, out: wp.array2d(dtype=wp.int32)):
    t = wp.tid()
    b, row, on = _waypoint_thread(t, layout)
    out[t, 0] = b
    out[t, 1] = row
    out[t, 2] = on


@pytest.mark.parametrize("P, W, n_sub", [(3, 4, 5), (2, 3, 2), (2, 5, 1), (1, 2, 4)])
@pytest.mark.parametrize("waypoints_first", [False, True])
def test_waypoint_thread_maps_threads_to_configurations_and_rows(device, P, W, n_sub, waypoints_first):
    """CPU layout: thread b is configuration b. CUDA layout (P given): a permutation with
    the waypoints first. Either way each configuration reads its nearest waypoint's row."""
    model = jwarp.robot("planar4")
    rows = CompensationRows(put_model(model, device, np.float32), P, W, n_sub, 1e-3, LAM)
    layout = rows.layout
    assert layout[:3] == (rows.S, n_sub, W)
    layout = layout[:3] + (0,)  # the CPU's
    if waypoints_first:
        layout = layout[:3] + (P,)  # the CUDA layout
    out = wp.zeros((rows.N, 3), dtype=wp.int32, device=device)
    wp.launch(_thread_map, dim=rows.N, inputs=[wp.vec4i(*layout)], outputs=[out],
              device=device)
    b, row, on = out.numpy().T
    np.testing.assert_array_equal(np.sort(b), np.arange(rows.N))  # every configuration once
    np.testing.assert_array_equal(row, rows.config_rows()[b])      # its nearest waypoint's row
    np.testing.assert_array_equal(on, (b % rows.S) % n_sub == 0)   # the waypoints
    if waypoints_first:
        assert on[:P * W].all() and not on[P * W:].any()
        np.testing.assert_array_equal(row[:P * W], np.arange(P * W))
    else:
        np.testing.assert_array_equal(b, np.arange(rows.N))


@requires_cuda
def test_cuda_ik_update_per_frame_matches_the_reference_iteration():
    """IK on CUDA updates its rows from its FK frames, one thread per (configuration, DH
    frame): after k evaluations at fixed q the rows are the reference's k-th iterate."""
    from jwarp.solvers.ik import IKObjective

    model = jwarp.robot("justin19")
    kappa = kappa_uniform(model, 1e-3)
    q = sample_within_limits(model, 5, np.random.default_rng(5))
    obj = IKObjective(model, "right_tcp", 5, world=block_world(), kappa=kappa, lam=LAM,
                      dtype=np.float64, device="cuda:0")
    obj.set_q(q)
    obj.set_target(np.repeat(np.eye(4)[None], 5, axis=0))
    for _ in range(3):
        obj.evaluate_pose()
        obj.evaluate_aux()
    _, rho_ref = ref_fk_elastic(model, q, kappa, n_iter=3, lam=LAM)
    np.testing.assert_allclose(obj.compensation.rows.numpy()[..., :5], rho_ref, atol=1e-10)
    _, rho_prev = ref_fk_elastic(model, q, kappa, n_iter=2, lam=LAM)
    np.testing.assert_allclose(obj.delta.numpy(), np.abs(rho_ref - rho_prev).max(axis=(1, 2)),
                               atol=1e-10)
