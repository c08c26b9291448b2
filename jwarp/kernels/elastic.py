"""Elastic kinematics kernels: gravity torques and the damped torque-equilibrium update.

Model (thesis eq. 2.31-2.35, paper eq. 5-10): ``rho = rho0 + kappa * tau(F(q, rho))``
with the gravity torques of all masses in the subtree of frame i about

* ``beta``  : the y-axis of the parent frame, through the parent origin,
* ``alpha`` : the x-axis of ``parent * Rot_y(beta)``, through the parent origin,
* ``theta`` : the z-axis of frame i, through the origin of frame i.

(For beta = 0 these are the axes of the papers' eq. 7.) One update is
``rho_n = (1 - lam) rho_{n-1} + lam (rho0 + kappa tau(F(q, rho_{n-1})))``.

Extra model tables (see :mod:`jwarp.kernels.fk` for the frame tables):

* ``mass``      (n_frames,) total point mass attached to each frame [kg]
* ``mass_com``  (n_frames,) vec3 its centre of mass in frame coordinates [m]
* ``child_start`` (n_frames + 1,) int32, ``child_idx``: CSR list of each frame's children

``kappa`` has shape (B_kappa, n_frames, 3) in rad/(N m), axes [alpha, beta, theta];
``kappa_stride`` 0 shares row 0. ``rho0`` likewise with ``rho0_stride``.
"""


import functools
from types import SimpleNamespace

import warp as wp

from jwarp.kernels.fk import kernels as fk_kernels


@functools.cache
def kernels(scalar: type) -> SimpleNamespace:
    """Elastic kernels for one scalar type."""
    fk = fk_kernels(scalar)
    vec3, vec4, mat33, mat44 = fk.vec3, fk.vec4, fk.mat33, fk.mat44
    zero = scalar(0.0)
    one = scalar(1.0)
    unpack_rot, unpack_pos = fk.unpack_rot, fk.unpack_pos

    @wp.func
    def torque_update(
        b: int,
        frames: wp.array2d(dtype=mat44),
        rho: wp.array3d(dtype=scalar), rho_stride: int, use_rho: int,
        rho0: wp.array3d(dtype=scalar), rho0_stride: int,
        kappa: wp.array3d(dtype=scalar), kappa_stride: int,
        lam: scalar, gravity: vec3,
        order: wp.array(dtype=wp.int32), parent: wp.array(dtype=wp.int32),
        is_dh: wp.array(dtype=wp.int32), dh0: wp.array2d(dtype=scalar),
        trig: wp.array(dtype=vec4),
        mass: wp.array(dtype=scalar), mass_com: wp.array(dtype=vec3),
        child_start: wp.array(dtype=wp.int32), child_idx: wp.array(dtype=wp.int32),
        moments: wp.array2d(dtype=vec4),
        rho_out: wp.array3d(dtype=scalar), tau_out: wp.array3d(dtype=scalar), write_tau: int,
    ) -> scalar:
        n = order.shape[0]
        # subtree first moments [sum m w; sum m] (world), leaves to root; each written once
        for kk in range(n):
            i = order[n - 1 - kk]
            T = frames[b, i]
            w = unpack_rot(T) * mass_com[i] + unpack_pos(T)
            m = mass[i]
            acc = vec4(m * w[0], m * w[1], m * w[2], m)
            for c in range(child_start[i], child_start[i + 1]):
                acc = acc + moments[b, child_idx[c]]
            moments[b, i] = acc
        delta = zero
        rb = b * rho_stride
        r0 = b * rho0_stride
        kb = b * kappa_stride
        for i in range(n):
            if is_dh[i] != 0:
                mo = moments[b, i]
                s = vec3(mo[0], mo[1], mo[2])
                mtot = mo[3]
                T = frames[b, i]
                p_i = unpack_pos(T)
                z = vec3(T[0, 2], T[1, 2], T[2, 2])
                pp = vec3(zero, zero, zero)
                Rp = wp.identity(3, dtype=scalar)
                pi = parent[i]
                if pi >= 0:
                    Tp = frames[b, pi]
                    pp = unpack_pos(Tp)
                    Rp = unpack_rot(Tp)
                prev_d = dh0[i, 0]
                prev_t = dh0[i, 1]
                prev_r = dh0[i, 2]
                prev_a = dh0[i, 3]
                prev_b = dh0[i, 4]
                if use_rho != 0:
                    prev_d = rho[rb, i, 0]
                    prev_t = rho[rb, i, 1]
                    prev_r = rho[rb, i, 2]
                    prev_a = rho[rb, i, 3]
                    prev_b = rho[rb, i, 4]
                cs = trig[i]
                cb, sb = fk.cos_sin_near(prev_b, dh0[i, 4], cs[2], cs[3])
                ax_alpha = Rp * vec3(cb, zero, -sb)
                ax_beta = vec3(Rp[0, 1], Rp[1, 1], Rp[2, 1])
                arm_p = wp.cross(s - mtot * pp, gravity)
                tau_a = wp.dot(arm_p, ax_alpha)
                tau_b = wp.dot(arm_p, ax_beta)
                tau_t = wp.dot(wp.cross(s - mtot * p_i, gravity), z)
                if write_tau != 0:
                    tau_out[b, i, 0] = tau_a
                    tau_out[b, i, 1] = tau_b
                    tau_out[b, i, 2] = tau_t
                new_a = (one - lam) * prev_a + lam * (rho0[r0, i, 3] + kappa[kb, i, 0] * tau_a)
                new_b = (one - lam) * prev_b + lam * (rho0[r0, i, 4] + kappa[kb, i, 1] * tau_b)
                new_t = (one - lam) * prev_t + lam * (rho0[r0, i, 1] + kappa[kb, i, 2] * tau_t)
                delta = wp.max(delta, wp.max(wp.abs(new_a - prev_a),
                                             wp.max(wp.abs(new_b - prev_b), wp.abs(new_t - prev_t))))
                rho_out[b, i, 0] = prev_d
                rho_out[b, i, 1] = new_t
                rho_out[b, i, 2] = prev_r
                rho_out[b, i, 3] = new_a
                rho_out[b, i, 4] = new_b
            else:
                for c in range(5):
                    rho_out[b, i, c] = dh0[i, c]
                if write_tau != 0:
                    for c in range(3):
                        tau_out[b, i, c] = zero
        return delta

    @wp.kernel(module="unique")
    def elastic_step_kernel(
        # Data in:
        q: wp.array2d(dtype=scalar),
        rho: wp.array3d(dtype=scalar),
        rho_stride: int,
        use_rho: int,
        rho0: wp.array3d(dtype=scalar),
        rho0_stride: int,
        kappa: wp.array3d(dtype=scalar),
        kappa_stride: int,
        lam: scalar,
        gravity: vec3,
        write_tau: int,
        # Model:
        order: wp.array(dtype=wp.int32),
        parent: wp.array(dtype=wp.int32),
        is_dh: wp.array(dtype=wp.int32),
        prismatic: wp.array(dtype=wp.int32),
        fixed_rot: wp.array(dtype=mat33),
        fixed_pos: wp.array(dtype=vec3),
        dh0: wp.array2d(dtype=scalar),
        trig: wp.array(dtype=fk.vec4),
        cpl_start: wp.array(dtype=wp.int32),
        cpl_joint: wp.array(dtype=wp.int32),
        cpl_coef: wp.array(dtype=scalar),
        mass: wp.array(dtype=scalar),
        mass_com: wp.array(dtype=vec3),
        child_start: wp.array(dtype=wp.int32),
        child_idx: wp.array(dtype=wp.int32),
        # Data out:
        frames: wp.array2d(dtype=mat44),
        moments: wp.array2d(dtype=vec4),
        rho_out: wp.array3d(dtype=scalar),
        tau_out: wp.array3d(dtype=scalar),
        delta: wp.array(dtype=scalar),
    ):
        """One torque update: frames = F(q, rho); rho_out = damped update from the
        gravity torques of those frames; delta[b] = max |rho_out - rho| (rad)."""
        b = wp.tid()
        for k in range(order.shape[0]):
            i = order[k]
            fk.write_frame(b, i, q, rho, rho_stride, use_rho, parent, is_dh, prismatic, fixed_rot,
                           fixed_pos, dh0, trig, cpl_start, cpl_joint, cpl_coef, frames)
        delta[b] = torque_update(b, frames, rho, rho_stride, use_rho, rho0, rho0_stride,
                                 kappa, kappa_stride, lam, gravity, order, parent, is_dh, dh0,
                                 trig, mass, mass_com, child_start, child_idx, moments, rho_out,
                                 tau_out, write_tau)

    return SimpleNamespace(vec4=vec4, elastic_step=elastic_step_kernel)
