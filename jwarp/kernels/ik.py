"""Inverse-kinematics cost kernels (math only; thesis eq. 3.13-3.15, 3.19, 3.21-3.24).

Per configuration ``b`` with the frames ``F = f(q_b)`` (FK output), the geometric Jacobian
``J (6, n_dof)`` of the end-effector frame ``e`` (rows [linear; angular] in the base frame)
and a target pose ``T_b`` (4x4):

* ``U_p = 1/2 |Pos(F_e) - Pos(T)|^2``                           (eq. 3.13) [m^2]
* ``U_r = 1/2 (3 - trace(Rot(F_e) Rot(T)^T))``                   (eq. 3.14)
* ``U_f = lam_p U_p + lam_r U_r``                                 (eq. 3.15)
* its gradient ``lam_p J_v^T (p - p_T) - lam_r / 2 J_w^T vee(M - M^T)`` with
  ``M = Rot(F_e) Rot(T)^T`` and ``vee(A) = (A_21, A_02, A_10)``,
* the 6D error for the projection step (eq. 3.21-3.23):
  ``e = [p_T - p; log(Rot(T) Rot(F_e)^T)]`` (rotation vector in the base frame), so that
  ``q += J^+ e`` moves the frame onto the target; ``pos_err = |e_v|`` [m],
  ``rot_err = |e_w|`` [rad].
* ``U_A = lam_l 1/2 |q - q_default|^2 + sum`` of the already weighted collision costs
  (eq. 3.19) and its gradient.
"""


import functools
from types import SimpleNamespace

import warp as wp

from jwarp.kernels.fk import funcs as fk_funcs

#: orientation modes of a target: the full pose, position only, the rotation about one
#: axis of the frame free (:func:`kernels` ``apply_orientation``)
ORIENT_FULL, ORIENT_NONE, ORIENT_AXIS = 0, 1, 2


@functools.cache
def kernels(scalar: type) -> SimpleNamespace:
    """IK kernels for one scalar type (``wp.float32`` or ``wp.float64``)."""
    fk = fk_funcs(scalar)
    vec3, mat33, mat44 = fk.vec3, fk.mat33, fk.mat44
    zero = scalar(0.0)
    half = scalar(0.5)
    two = scalar(2.0)

    @wp.func
    def rotation_log(M: mat33) -> vec3:
        """Rotation vector (axis * angle, angle in [0, pi]) of the rotation matrix M."""
        qt = wp.quat_from_matrix(M)
        v = vec3(qt[0], qt[1], qt[2])
        w = qt[3]
        if w < zero:
            v = -v
            w = -w
        s = wp.length(v)
        if s < scalar(1e-12):
            return two * v
        return v * (two * wp.atan2(s, w) / s)

    @wp.func
    def pose_error_row(R: mat33, p: vec3, T: mat44, b: int, err: wp.array2d(dtype=scalar)):
        """The 6D error of the frame (R, p) to the target T, written to err[b] (6,):
        ``e = [Pos(T) - p; log(Rot(T) R^T)]``; returns ``(M, e_v, e_w)`` with
        ``M = R Rot(T)^T``. Shared by ``pose_error`` and the IK solver's pose kernel."""
        M = R * wp.transpose(fk.unpack_rot(T))
        ev = fk.unpack_pos(T) - p
        ew = rotation_log(wp.transpose(M))  # log(Rt R^T)
        for r in range(3):
            err[b, r] = ev[r]
            err[b, r + 3] = ew[r]
        return M, ev, ew

    @wp.func
    def apply_orientation(mode: int, axis: vec3, R: mat33, T: mat44, b: int,
                          err: wp.array2d(dtype=scalar), jac: wp.array3d(dtype=scalar)):
        """Restrict the rotation rows of err[b] (6,) and jac[b] (6, n_dof) to the target's
        orientation mode: ``ORIENT_FULL`` leaves them; ``ORIENT_NONE`` (position only)
        zeroes them; ``ORIENT_AXIS`` (the rotation about the frame's ``axis`` (3,), in the
        frame's coordinates, is free) makes the error the rotation taking the current axis
        ``a = R axis`` onto the target's ``Rot(T) axis`` (angle in [0, pi] times the unit
        normal of both) and removes the rotation about ``a`` from the angular rows
        (``J_w <- (I - a a^T) J_w``)."""
        if mode == ORIENT_NONE:
            for r in range(3):
                err[b, r + 3] = zero
                for j in range(jac.shape[2]):
                    jac[b, r + 3, j] = zero
        elif mode == ORIENT_AXIS:
            a = R * axis
            at = fk.unpack_rot(T) * axis
            c = wp.cross(a, at)
            s = wp.length(c)
            ang = wp.atan2(s, wp.dot(a, at))
            e = c
            if s > scalar(1e-12):
                e = c * (ang / s)
            elif wp.dot(a, at) < zero:  # opposite axes: any normal of a
                n = wp.cross(a, vec3(scalar(1.0), zero, zero))
                if wp.length(n) < scalar(0.5):
                    n = wp.cross(a, vec3(zero, scalar(1.0), zero))
                e = wp.normalize(n) * ang
            for r in range(3):
                err[b, r + 3] = e[r]
            for j in range(jac.shape[2]):
                jw = vec3(jac[b, 3, j], jac[b, 4, j], jac[b, 5, j])
                jw = jw - a * wp.dot(a, jw)
                for r in range(3):
                    jac[b, r + 3, j] = jw[r]

    @wp.kernel(module="unique")
    def pose_error_kernel(
        # Model:
        model: fk.FrameTables,
        chain: wp.array(dtype=wp.int32),
        # Data in:
        frames: wp.array2d(dtype=mat44),
        q: wp.array2d(dtype=scalar),
        target: wp.array(dtype=mat44),
        lam_p: scalar,
        lam_r: scalar,
        orient: int,
        axis: vec3,
        # Data out:
        jac: wp.array3d(dtype=scalar),
        err: wp.array2d(dtype=scalar),
        pos_err: wp.array(dtype=scalar),
        rot_err: wp.array(dtype=scalar),
        cost: wp.array(dtype=scalar),
        grad: wp.array2d(dtype=scalar),
    ):
        """Jacobian (B, 6, n_dof) of the frame ``chain[-1]`` (from ``frames``, no FK of
        its own; ``frames`` were computed at ``q`` (B, n_dof)), 6D error (B, 6) restricted
        to the orientation mode ``orient`` (:func:`apply_orientation`; U_f and its
        gradient stay the full eq. 3.15), its norms (B,), U_f (B,) and dU_f/dq (B, n_dof).
        Launch dim B."""
        b = wp.tid()
        F = frames[b, chain[chain.shape[0] - 1]]
        fk.frames_jacobian(model, chain, frames, b, q, fk.unpack_pos(F), jac)
        T = target[b]
        dp = fk.unpack_pos(F) - fk.unpack_pos(T)
        M, ev, ew = pose_error_row(fk.unpack_rot(F), fk.unpack_pos(F), T, b, err)
        apply_orientation(orient, axis, fk.unpack_rot(F), T, b, err, jac)
        pos_err[b] = wp.length(ev)
        rot_err[b] = wp.length(vec3(err[b, 3], err[b, 4], err[b, 5]))
        tr = M[0, 0] + M[1, 1] + M[2, 2]
        cost[b] = lam_p * half * wp.dot(dp, dp) + lam_r * half * (scalar(3.0) - tr)
        vee = vec3(M[1, 2] - M[2, 1], M[2, 0] - M[0, 2], M[0, 1] - M[1, 0])
        for j in range(jac.shape[2]):
            gv = zero
            gw = zero
            for r in range(3):
                gv += jac[b, r, j] * dp[r]
                gw += jac[b, r + 3, j] * vee[r]
            grad[b, j] = lam_p * gv - lam_r * half * gw

    @wp.func
    def aux_row(q: wp.array2d(dtype=scalar), b: int, q_default: wp.array2d(dtype=scalar),
                bd: int, c0: scalar, coll_grad: wp.array2d(dtype=scalar), gk: int,
                use_collision: int, lam_l: scalar, grad: wp.array2d(dtype=scalar)) -> scalar:
        """U_A of configuration b: ``c0`` (its collision cost, or 0) + lam_l/2
        |q[b] - q_default[bd]|^2, returned; dU_A/dq written to grad[b] (with the collision
        gradient of row gk of ``coll_grad`` when ``use_collision``)."""
        c = c0
        for j in range(q.shape[1]):
            d = q[b, j] - q_default[bd, j]
            c += lam_l * half * d * d
            g = lam_l * d
            if use_collision != 0:
                g += coll_grad[gk, j]
            grad[b, j] = g
        return c

    @wp.kernel(module="unique")
    def aux_cost_kernel(
        # Data in:
        q: wp.array2d(dtype=scalar),
        q_default: wp.array2d(dtype=scalar),
        default_stride: int,
        coll_cost: wp.array(dtype=scalar),
        coll_grad: wp.array2d(dtype=scalar),
        use_collision: int,
        lam_l: scalar,
        # Data out:
        cost: wp.array(dtype=scalar),
        grad: wp.array2d(dtype=scalar),
    ):
        """U_A = collision + lam_l/2 |q - q_default|^2 (B,) and dU_A/dq (B, n_dof).
        ``q_default`` (B or 1, n_dof) with ``default_stride`` 1 or 0. Launch dim B."""
        b = wp.tid()
        c = zero
        if use_collision != 0:
            c = coll_cost[b]
        cost[b] = aux_row(q, b, q_default, b * default_stride, c, coll_grad, b, use_collision,
                          lam_l, grad)

    return SimpleNamespace(scalar=scalar, rotation_log=rotation_log,
                           pose_error_row=pose_error_row, apply_orientation=apply_orientation,
                           aux_row=aux_row,
                           pose_error=pose_error_kernel, aux_cost=aux_cost_kernel)
