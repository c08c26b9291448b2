"""The Warp functions the kernels share (one definition, called from every kernel that
needs them), each called from a probe kernel here and checked against an independent
result, float32 and float64:

* jwarp.kernels.fk ``chain_pose`` / ``chain_jacobian`` (the chain walk of the Jacobian
  kernels and of the IK solver's pose kernel): the frame of the full FK, and the Jacobian
  kernel's columns;
* jwarp.kernels.path ``within_limits_row`` / ``within_linear_limits`` (beside
  ``project_row``; the IK solver's check and seed sampling): numpy's limit check;
* jwarp.kernels.ik ``aux_row`` (U_A of ``aux_cost`` and of the IK solver's
  ``scatter_aux``): U_A in numpy.
"""

import functools

import numpy as np
import pytest
import warp as wp

import jwarp
from jwarp.core.device import put_model
from jwarp.core.limits import project_numpy
from jwarp.kernels import fk as fk_kernels
from jwarp.kernels import ik as ik_kernels
from jwarp.kernels import path as path_kernels
from jwarp.kernels.fk import ROWS_NOMINAL

DTYPES = [(np.float32, wp.float32), (np.float64, wp.float64)]


@functools.cache
def _probes(scalar):
    fk = fk_kernels.kernels(scalar)
    pk = path_kernels.kernels(scalar)
    ik = ik_kernels.kernels(scalar)

    @wp.kernel(module="unique", enable_backward=False)
    def chain_probe(q: wp.array2d(dtype=scalar), model: fk.FrameTables,
                    chain: wp.array(dtype=wp.int32), nominal: wp.array3d(dtype=scalar),
                    pose: wp.array(dtype=fk.mat44), jac: wp.array3d(dtype=scalar)):
        b = wp.tid()
        R, p = fk.chain_pose(model, chain, b, q, ROWS_NOMINAL, nominal, 0)
        pose[b] = fk.pack(R, p)
        fk.chain_jacobian(model, chain, b, q, ROWS_NOMINAL, nominal, 0, p, jac)

    @wp.kernel(module="unique", enable_backward=False)
    def limits_probe(q: wp.array2d(dtype=scalar), tol: scalar, limits: pk.LimitTables,
                     out: wp.array2d(dtype=wp.int32)):
        b = wp.tid()
        out[b, 0] = pk.within_limits_row(q, b, limits, tol)
        out[b, 1] = pk.within_linear_limits(q, b, limits, tol)

    @wp.kernel(module="unique", enable_backward=False)
    def aux_probe(q: wp.array2d(dtype=scalar), q_default: wp.array2d(dtype=scalar),
                  coll_cost: wp.array(dtype=scalar), coll_grad: wp.array2d(dtype=scalar),
                  use_collision: int, lam_l: scalar, cost: wp.array(dtype=scalar),
                  grad: wp.array2d(dtype=scalar)):
        b = wp.tid()
        c = scalar(0.0)
        if use_collision != 0:
            c = coll_cost[b]
        k = q.shape[0] - 1 - b  # the collision rows in another order (the gathered batch)
        cost[b] = ik.aux_row(q, b, q_default, 0, c, coll_grad, k, use_collision, lam_l, grad)

    return chain_probe, limits_probe, aux_probe


@pytest.mark.parametrize("name,frame", [("justin19", "left_tcp"), ("arm7", "tcp"),
                                        ("planar4", "tcp")])
@pytest.mark.parametrize("npdt,scalar", DTYPES)
def test_chain_walk_gives_the_fk_frame_and_the_jacobian_kernels_columns(name, frame, npdt,
                                                                       scalar):
    robot = jwarp.robot(name)
    rng = np.random.default_rng(1)
    lim = robot.joint_limits
    q = rng.uniform(lim[:, 0], lim[:, 1], (17, robot.n_dof)).astype(npdt)
    t = put_model(robot, "cpu", npdt)
    fi = robot.frame_index(frame)
    pose = wp.zeros(len(q), dtype=fk_kernels.kernels(scalar).mat44, device="cpu")
    jac = wp.full((len(q), 6, robot.n_dof), 7.0, dtype=scalar, device="cpu")  # cleared
    chain_probe = _probes(scalar)[0]
    wp.launch(chain_probe, dim=len(q), inputs=[wp.array(q, dtype=scalar, device="cpu"),
                                               t.frame_struct, t.chain(fi), t.dh0_3d],
              outputs=[pose, jac], device="cpu")
    frames = jwarp.fk(robot, q, device="cpu", dtype=npdt)[:, fi]
    np.testing.assert_array_equal(pose.numpy(), frames)
    np.testing.assert_array_equal(jac.numpy(), jwarp.jacobian(robot, q, frame, device="cpu",
                                                              dtype=npdt))


def _signed_violation(robot, q, box):
    """Largest violation of the (box and) linear limits, negative inside: the distance to
    the nearest bound."""
    q = np.asarray(q, np.float64)
    v = np.full(len(q), -np.inf)
    if box:
        lo, hi = robot.joint_limits[:, 0], robot.joint_limits[:, 1]
        v = np.maximum(lo - q, q - hi).max(axis=1)
    for ll in robot.linear_limits:
        s = q[:, ll.joints] @ np.asarray(ll.coefficients, np.float64)
        v = np.maximum(v, np.maximum(ll.lower - s, s - ll.upper))
    return v


@pytest.mark.parametrize("npdt,scalar", DTYPES)
def test_limit_checks_match_numpy(npdt, scalar):
    robot = jwarp.robot("justin19")  # box limits and the torso's linear limits
    assert robot.linear_limits
    rng = np.random.default_rng(2)
    lim = robot.joint_limits
    q = rng.uniform(lim[:, 0] - 0.05, lim[:, 1] + 0.05, (400, robot.n_dof))
    q[:100] = project_numpy(robot, q[:100])      # inside (on the boundary, some)
    q[100:200, 3:] = project_numpy(robot, q[100:200])[:, 3:]   # torso may break its polygon
    q = q.astype(npdt)
    lt = put_model(robot, "cpu", npdt).limits
    out = wp.zeros((len(q), 2), dtype=wp.int32, device="cpu")
    limits_probe = _probes(scalar)[1]
    for tol in (0.0, 1e-3):
        wp.launch(limits_probe, dim=len(q), inputs=[wp.array(q, dtype=scalar, device="cpu"),
                                                    scalar(tol), lt],
                  outputs=[out], device="cpu")
        got = out.numpy().astype(bool)
        # numpy's verdict, where the kernel's round-off cannot flip it
        for col, box in ((0, True), (1, False)):
            v = _signed_violation(robot, q, box)
            clear = np.abs(v - tol) > 1e-4
            assert clear.sum() > 250
            np.testing.assert_array_equal(got[clear, col], v[clear] <= tol)
        assert 0 < got[:, 1].sum() < len(q) and got[:, 0].sum() < got[:, 1].sum()


@pytest.mark.parametrize("npdt,scalar", DTYPES)
def test_aux_row_is_u_a(npdt, scalar):
    rng = np.random.default_rng(3)
    B, n, lam = 11, 6, 0.3
    q, q0 = rng.normal(size=(B, n)).astype(npdt), rng.normal(size=(1, n)).astype(npdt)
    cc, cg = rng.random(B).astype(npdt), rng.normal(size=(B, n)).astype(npdt)
    aux_probe = _probes(scalar)[2]
    for use in (0, 1):
        cost = wp.zeros(B, dtype=scalar, device="cpu")
        grad = wp.zeros((B, n), dtype=scalar, device="cpu")
        wp.launch(aux_probe, dim=B, inputs=[wp.array(a, dtype=scalar, device="cpu")
                                            for a in (q, q0, cc, cg)] + [use, scalar(lam)],
                  outputs=[cost, grad], device="cpu")
        d = q.astype(np.float64) - q0
        want_c = 0.5 * lam * (d * d).sum(1) + use * cc
        want_g = lam * d + use * cg[::-1]
        rtol = 1e-5 if npdt == np.float32 else 1e-12
        np.testing.assert_allclose(cost.numpy(), want_c, rtol=rtol)
        np.testing.assert_allclose(grad.numpy(), want_g, rtol=rtol, atol=rtol)
