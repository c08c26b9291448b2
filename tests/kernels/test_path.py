"""Path kernels (jwarp/kernels/path.py) against plain numpy and central finite differences."""

import numpy as np
import pytest
import warp as wp

import jwarp
from jwarp.core.arrays import init_warp
from jwarp.core.device import put_model
from jwarp.core.limits import limit_violation, project_numpy, within_limits
from jwarp.kernels import path as PK
from jwarp.solvers import planning as planner
from jwarp.world import path_feasibility

init_warp()
F64 = wp.float64
K64 = PK.kernels(F64)
FLOOR = planner.NORM_FLOOR


# ------------------------------------------------------------------ numpy references
def ref_substeps(Q, n_sub):
    P, W, n = Q.shape
    out = []
    for t in range(W - 1):
        for u in range(n_sub):
            out.append(Q[:, t] + u / n_sub * (Q[:, t + 1] - Q[:, t]))
    out.append(Q[:, -1])
    return np.stack(out, axis=1)  # (P, S, n)


def ref_length(Q):
    W = Q.shape[1]
    norm = np.maximum(0.5 * np.sum((Q[:, -1] - Q[:, 0]) ** 2, axis=-1), FLOOR)
    return (W - 1) / norm * 0.5 * np.sum(np.diff(Q, axis=1) ** 2, axis=(1, 2))


# a smooth stand-in for the per-substep collision cost with a known gradient
A = np.random.default_rng(0).normal(size=(3, 3))


def f_sub(q):  # (N, 3) -> (N,)
    return np.sum(np.sin(q @ A.T), axis=-1) + 0.5 * np.sum(q ** 2, axis=-1)


def df_sub(q):
    return np.cos(q @ A.T) @ A + q


def ref_upath(Q, n_sub, lam_l):
    qs = ref_substeps(Q, n_sub)
    return f_sub(qs.reshape(-1, Q.shape[2])).reshape(qs.shape[:2]).sum(1) + lam_l * ref_length(Q)


def _w(a, dt=F64, device="cpu"):
    return wp.array(np.ascontiguousarray(a), dtype=dt, device=device)


def _sub_arrays(Q, n_sub, device="cpu"):
    P, W, n = Q.shape
    S = (W - 1) * n_sub + 1
    q_sub = wp.empty((P * S, n), dtype=F64, device=device)
    wp.launch(K64.substeps, dim=(P, S), inputs=[_w(Q, device=device), n_sub], outputs=[q_sub],
              device=device)
    return q_sub.numpy()


# ------------------------------------------------------------------ tests
@pytest.mark.parametrize("n_sub", [1, 3, 5])
def test_substeps_match_numpy(device, n_sub):
    Q = np.random.default_rng(1).normal(size=(4, 6, 3))
    got = _sub_arrays(Q, n_sub, device).reshape(4, -1, 3)
    np.testing.assert_allclose(got, ref_substeps(Q, n_sub), atol=1e-14)
    # waypoints are exactly the substeps s = t n_sub
    np.testing.assert_array_equal(got[:, ::n_sub], Q)
    # the host wrapper agrees and keeps leading dims
    np.testing.assert_allclose(path_feasibility.substeps(Q, n_sub, device=device), ref_substeps(Q, n_sub), atol=1e-14)


def test_path_cost_matches_numpy(device):
    rng = np.random.default_rng(2)
    Q = rng.normal(size=(5, 7, 3))
    Q[4, -1] = Q[4, 0]  # start == goal: the normaliser floor keeps it finite
    n_sub, lam_l = 4, 0.3
    qs = _sub_arrays(Q, n_sub, device)
    sub_cost = f_sub(qs)
    P = len(Q)
    out = [wp.empty(P, dtype=F64, device=device) for _ in range(4)]
    wp.launch(K64.path_cost, dim=P, inputs=[_w(Q, device=device), _w(sub_cost, device=device), n_sub, lam_l, FLOOR],
              outputs=out, device=device)
    length, coll, total, smax = (o.numpy() for o in out)
    np.testing.assert_allclose(smax, np.maximum(sub_cost.reshape(P, -1).max(1), 0), rtol=1e-12)
    np.testing.assert_allclose(length, ref_length(Q), rtol=1e-12)
    np.testing.assert_allclose(coll, sub_cost.reshape(P, -1).sum(1), rtol=1e-12)
    np.testing.assert_allclose(total, ref_upath(Q, n_sub, lam_l), rtol=1e-12)
    # the straight line has length cost exactly 1 (thesis 3.3.2)
    line = np.linspace(0, 1, 7)[None, :, None] * np.array([1.0, -2.0, 0.5])
    wp.launch(K64.path_cost, dim=1, inputs=[_w(line, device=device), _w(np.zeros(25), device=device), n_sub, lam_l, FLOOR],
              outputs=out[:1] + [wp.empty(1, dtype=F64, device=device) for _ in range(3)], device=device)
    np.testing.assert_allclose(out[0].numpy()[0], 1.0, rtol=1e-12)


@pytest.mark.parametrize("n_sub", [1, 3])
def test_path_gradient_matches_central_fd(device, n_sub):
    rng = np.random.default_rng(3)
    Q = rng.normal(size=(3, 6, 3))
    lam_l = 0.7
    P, W, n = Q.shape
    grad = wp.empty((P, W, n), dtype=F64, device=device)
    sub_grad = df_sub(_sub_arrays(Q, n_sub, device))
    wp.launch(K64.path_grad, dim=(P, W), inputs=[_w(Q, device=device), _w(sub_grad, device=device), n_sub, lam_l, FLOOR],
              outputs=[grad], device=device)
    g = grad.numpy()
    fd = np.zeros_like(Q)
    h = 1e-6
    for t in range(1, W - 1):
        for j in range(n):
            Qp, Qm = Q.copy(), Q.copy()
            Qp[:, t, j] += h
            Qm[:, t, j] -= h
            fd[:, t, j] = (ref_upath(Qp, n_sub, lam_l) - ref_upath(Qm, n_sub, lam_l)) / (2 * h)
    np.testing.assert_allclose(g, fd, atol=1e-7, rtol=1e-7)
    assert np.all(g[:, 0] == 0) and np.all(g[:, -1] == 0)


def test_step_kernel_clamps_projects_and_freezes(device):
    robot = jwarp.robot("justin19")
    rng = np.random.default_rng(4)
    P, W, n, n_sub = 3, 5, robot.n_dof, 2
    Q = rng.uniform(-1, 1, size=(P, W, n))
    Q[..., 1:3] = [1.2, 1.1]
    S = (W - 1) * n_sub + 1
    sub_grad = rng.normal(scale=50.0, size=(P * S, n))
    sub_grad[:, 2] = -400.0  # pushes q2 up: the torso sum q1 + q2 must be projected
    step, max_step, lam_l = 0.01, 0.3, 0.2
    lim = put_model(robot, device, np.float64).limits
    active = np.array([1, 0, 1], np.int32)
    out = wp.empty((P * W, n), dtype=F64, device=device)
    wp.launch(K64.path_step, dim=(P, W),
              inputs=[lim, _w(Q, device=device), _w(sub_grad, device=device), n_sub, lam_l, FLOOR, step,
                      max_step, wp.array(active, dtype=wp.int32, device=device)], outputs=[out],
              device=device)
    got = out.numpy().reshape(P, W, n)
    # numpy: gradient with hat weights + length term, clamp, projection
    g = np.zeros_like(Q)
    sg = sub_grad.reshape(P, S, n)
    norm = np.maximum(0.5 * np.sum((Q[:, -1] - Q[:, 0]) ** 2, -1), FLOOR)
    for t in range(1, W - 1):
        for s in range(t * n_sub - n_sub + 1, t * n_sub + n_sub):
            g[:, t] += (1 - abs(s - t * n_sub) / n_sub) * sg[:, s]
        g[:, t] += lam_l * (W - 1) / norm[:, None] * (2 * Q[:, t] - Q[:, t - 1] - Q[:, t + 1])
    expect = Q - np.clip(step * g, -max_step, max_step)
    expect[:, 1:-1] = project_numpy(robot, expect[:, 1:-1])
    expect[:, 0], expect[:, -1] = Q[:, 0], Q[:, -1]
    expect[1] = Q[1]  # inactive path unchanged
    np.testing.assert_allclose(got, expect, atol=1e-12)
    assert np.all(within_limits(robot, got[[0, 2], 1:-1]))
    assert np.any(np.abs(got[0, 1:-1, 1] + got[0, 1:-1, 2] - 2.356194490192345) < 1e-9)


def test_projection_justin_torso_polygon(device):
    robot = jwarp.robot("justin19")
    rng = np.random.default_rng(5)
    q = rng.uniform(-4, 4, size=(2000, robot.n_dof))
    lim = put_model(robot, device, np.float64).limits
    arr = _w(q, device=device)
    wp.launch(K64.project, dim=len(q), inputs=[lim], outputs=[arr], device=device)
    got = arr.numpy()
    assert limit_violation(robot, got).max() < 1e-12
    np.testing.assert_allclose(got, project_numpy(robot, q), atol=1e-12)
    # points inside the limits are left alone
    inside = project_numpy(robot, q)
    arr = _w(inside, device=device)
    wp.launch(K64.project, dim=len(q), inputs=[lim], outputs=[arr], device=device)
    np.testing.assert_array_equal(arr.numpy(), inside)


def test_substeps_bad_input():
    with pytest.raises(ValueError, match="paths"):
        path_feasibility.substeps(np.zeros((1, 3)), 2)
    with pytest.raises(ValueError, match="n_substeps"):
        path_feasibility.substeps(np.zeros((2, 3)), 0)
    with pytest.raises(ValueError, match="paths"):
        path_feasibility.substeps(np.full((2, 3), np.nan), 2)
