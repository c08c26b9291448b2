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
* ``dh_info``   (n_dh,) vec4i per DH frame: [its position k in ``order``, the frame i,
  ``end``, its parent]; ``order`` is a depth-first preorder, so the subtree of i is
  ``order[k:end]``
* ``static_idx`` (n_static,) int32 the static frames (rows the step never writes)

Subtree first moments come from prefix sums over that order: the FK pass writes
``prefix[k] = sum_{k' < k} [m w; m]`` of the frames before position k (w: centre of mass
in world coordinates), so the subtree at k sums to ``prefix[end] - prefix[k]``: two loads
per frame, no per-child loop and no read-back of values just written.

``rho`` rows: only the elastic columns [theta, alpha, beta] of DH frames are updated; ``d`` and
``r`` are copied; static-frame rows of ``rho_out`` are not written (:func:`fill_static_rows`
fills them once per buffer). With ``rows_kind`` ``ROWS_NOMINAL`` (:mod:`jwarp.kernels.fk`),
``rho`` must hold the nominal rows (the shared ``(1, n_frames, 5)`` table with stride 0): the
torque pass reads it either way.

``kappa`` has shape (B_kappa, n_frames, 3) in rad/(N m), axes [alpha, beta, theta];
``kappa_stride`` 0 shares row 0. ``rho0`` likewise with ``rho0_stride``. ``kappa_nl``
(n_frames,) [rad/(N m)^3] is the torque-dependent part of the joint compliance: the theta
target is ``rho0 + kappa tau + kappa_nl tau^3`` (compliance ``kappa + kappa_nl tau^2``).
"""


import functools
from types import SimpleNamespace

import warp as wp

from jwarp.kernels.fk import funcs as fk_funcs


@functools.cache
def funcs(scalar: type) -> SimpleNamespace:
    """The compensation arguments and ``@wp.func`` helpers the elastic kernels share, for
    one scalar type; built once per type (issue 40 item 5: the kernels are built one each,
    by :func:`elastic_step`, :func:`compensation_update`,
    :func:`compensation_update_per_frame`, :func:`fill_rows` and :func:`fill_static_rows`,
    from these)."""
    fk = fk_funcs(scalar)
    vec3, vec4, mat44 = fk.vec3, fk.vec4, fk.mat44
    zero = scalar(0.0)
    unpack_rot, unpack_pos = fk.unpack_rot, fk.unpack_pos

    @wp.func
    def gravity_torques(mo: vec4, p_i: vec3, z: vec3, pp: vec3, ax_alpha: vec3, ax_beta: vec3,
                        gravity: vec3) -> vec3:
        """Gravity torques [N m] (alpha, beta, theta) of a subtree with first moments
        ``mo`` = [sum m w; sum m] (w: centres of mass in world coordinates): about
        ``ax_alpha`` and ``ax_beta`` through the parent origin ``pp``, and about the frame's
        own z-axis ``z`` through its origin ``p_i``."""
        mtot = mo[3]
        if gravity[0] == zero and gravity[1] == zero:
            # gravity along z (a fixed branch per robot): only x and y of the arms matter,
            # dot(cross(a, g), x) = g_z (a_y x_x - a_x x_y)
            ax = mo[0] - mtot * pp[0]
            ay = mo[1] - mtot * pp[1]
            ix = mo[0] - mtot * p_i[0]
            iy = mo[1] - mtot * p_i[1]
            return gravity[2] * vec3(ay * ax_alpha[0] - ax * ax_alpha[1],
                                     ay * ax_beta[0] - ax * ax_beta[1], iy * z[0] - ix * z[1])
        s = vec3(mo[0], mo[1], mo[2])
        arm_p = wp.cross(s - mtot * pp, gravity)
        return vec3(wp.dot(arm_p, ax_alpha), wp.dot(arm_p, ax_beta),
                    wp.dot(wp.cross(s - mtot * p_i, gravity), z))

    @wp.func
    def damped_step(rho0: wp.array3d(dtype=scalar), r0: int, kappa: wp.array3d(dtype=scalar),
                    kb: int, i: int, tau: vec3, prev: vec3, lam: scalar, knl: scalar) -> vec3:
        """Change of (alpha, beta, theta) of frame i in one damped update:
        ``lam (rho0 + kappa tau + [0, 0, knl tau_theta^3] - prev)`` with tau and prev in
        (alpha, beta, theta) order (``knl``: the frame's ``kappa_nl``)."""
        tt = tau[2]
        return lam * (vec3(rho0[r0, i, 3], rho0[r0, i, 4], rho0[r0, i, 1] + knl * tt * tt * tt)
                      + wp.cw_mul(vec3(kappa[kb, i, 0], kappa[kb, i, 1], kappa[kb, i, 2]), tau)
                      - prev)

    @wp.func
    def subtree_prefix(model: fk.FrameTables, frames: wp.array2d(dtype=mat44), b: int,
                       mass: wp.array(dtype=scalar), mass_com: wp.array(dtype=vec3),
                       prefix: wp.array2d(dtype=vec4), sb: int):
        """prefix[k, sb] = sum over the frames before position k of ``order`` of
        [m w; m], from frames already computed."""
        acc = vec4(zero, zero, zero, zero)
        prefix[0, sb] = acc
        for k in range(model.order.shape[0]):
            # branch-free (massless frames add zeros): a branch makes the accumulator a
            # merge of two values, which the CPU code then keeps on the stack (~25% slower)
            i = model.order[k]
            m = mass[i]
            T = frames[b, i]
            w = unpack_rot(T) * mass_com[i] + unpack_pos(T)
            acc = acc + vec4(m * w[0], m * w[1], m * w[2], m)
            prefix[k + 1, sb] = acc

    @wp.func
    def torque_update(
        b: int,
        frames: wp.array2d(dtype=mat44),
        rho: wp.array3d(dtype=scalar), rho_stride: int,
        rho0: wp.array3d(dtype=scalar), rho0_stride: int,
        kappa: wp.array3d(dtype=scalar), kappa_stride: int,
        kappa_nl: wp.array(dtype=scalar),
        lam: scalar, gravity: vec3,
        dh_info: wp.array(dtype=wp.vec4i),
        prefix: wp.array2d(dtype=vec4), axes: wp.array2d(dtype=vec3), sb: int,
        rho_out: wp.array3d(dtype=scalar), tau_out: wp.array3d(dtype=scalar), write_tau: int,
    ) -> scalar:
        """Gravity torques of every DH frame from the frames and the moment prefix sums,
        and the damped update of its rows; returns max |rho_out - rho| [rad]. Rows of
        static frames in ``rho_out`` and ``tau_out`` are left as they are (the launcher
        fills them once: :func:`fill_static_rows`)."""
        delta = zero
        rb = b * rho_stride
        r0 = b * rho0_stride
        kb = b * kappa_stride
        for j in range(dh_info.shape[0]):  # static rows of rho_out are not written
            info = dh_info[j]
            i = info[1]
            mo = prefix[info[2], sb] - prefix[info[0], sb]
            T = frames[b, i]
            p_i = unpack_pos(T)
            z = vec3(T[0, 2], T[1, 2], T[2, 2])
            pp = vec3(zero, zero, zero)
            Rp = wp.identity(3, dtype=scalar)
            pi = info[3]
            if pi >= 0:
                Tp = frames[b, pi]
                pp = unpack_pos(Tp)
                Rp = unpack_rot(Tp)
            # rho holds the nominal rows (stride 0) for ROWS_NOMINAL: read it either way
            prev_d = rho[rb, i, 0]
            prev_t = rho[rb, i, 1]
            prev_r = rho[rb, i, 2]
            prev_a = rho[rb, i, 3]
            prev_b = rho[rb, i, 4]
            tau = gravity_torques(mo, p_i, z, pp, axes[i, sb],
                                  vec3(Rp[0, 1], Rp[1, 1], Rp[2, 1]), gravity)
            tau_a = tau[0]
            tau_b = tau[1]
            tau_t = tau[2]
            if write_tau != 0:
                tau_out[b, i, 0] = tau_a
                tau_out[b, i, 1] = tau_b
                tau_out[b, i, 2] = tau_t
            # damped update: new = (1 - lam) prev + lam (rho0 + kappa tau)
            dr = damped_step(rho0, r0, kappa, kb, i, tau, vec3(prev_a, prev_b, prev_t), lam,
                             kappa_nl[i])
            d_a = dr[0]
            d_b = dr[1]
            d_t = dr[2]
            delta = wp.max(delta, wp.max(wp.abs(d_a), wp.max(wp.abs(d_b), wp.abs(d_t))))
            rho_out[b, i, 0] = prev_d
            rho_out[b, i, 1] = prev_t + d_t
            rho_out[b, i, 2] = prev_r
            rho_out[b, i, 3] = prev_a + d_a
            rho_out[b, i, 4] = prev_b + d_b
        return delta

    @wp.struct
    class CompensationArgs:
        """Everything one torque update of compensation rows needs besides the frames and
        the current rows (one kernel argument; see :func:`compensation_update`).
        ``enabled`` = 0 makes a kernel that takes it skip the update."""

        enabled: int
        n_waypoints: int
        n_sub: int
        rho0: wp.array3d(dtype=scalar)
        rho0_stride: int
        kappa: wp.array3d(dtype=scalar)
        kappa_stride: int
        kappa_nl: wp.array(dtype=scalar)
        lam: scalar
        gravity: vec3
        mass: wp.array(dtype=scalar)
        mass_com: wp.array(dtype=vec3)
        dh_info: wp.array(dtype=wp.vec4i)
        prefix: wp.array2d(dtype=vec4)
        scratch_stride: int
        rows_out: wp.array3d(dtype=scalar)
        delta: wp.array(dtype=scalar)

    @wp.func
    def frame_update(model: fk.FrameTables, frames: wp.array2d(dtype=mat44), b: int,
                     rows: wp.array3d(dtype=scalar), u: int, c: CompensationArgs,
                     info: wp.vec4i, mo: vec4) -> scalar:
        """The damped update of DH frame ``info[1]`` in compensation row ``u`` from
        ``frames[b]`` and the first moments ``mo`` of its subtree: writes its entries of
        ``c.rows_out[u]`` and returns max |new - old| [rad]."""
        i = info[1]
        T = frames[b, i]
        pp = vec3(zero, zero, zero)
        Rp = wp.identity(3, dtype=scalar)
        if info[3] >= 0:
            Tp = frames[b, info[3]]
            pp = unpack_pos(Tp)
            Rp = unpack_rot(Tp)
        tau = gravity_torques(mo, unpack_pos(T), vec3(T[0, 2], T[1, 2], T[2, 2]), pp,
                              Rp * vec3(rows[u, i, 7], zero, -rows[u, i, 8]),
                              vec3(Rp[0, 1], Rp[1, 1], Rp[2, 1]), c.gravity)
        prev_t = rows[u, i, 1]
        prev_a = rows[u, i, 3]
        prev_b = rows[u, i, 4]
        dr = damped_step(c.rho0, u * c.rho0_stride, c.kappa, u * c.kappa_stride, i, tau,
                         vec3(prev_a, prev_b, prev_t), c.lam, c.kappa_nl[i])
        new_a = prev_a + dr[0]
        new_b = prev_b + dr[1]
        cs = model.trig[i]
        ca, sa = fk.cos_sin_step(new_a, dr[0], rows[u, i, 5], rows[u, i, 6], model.dh0[i, 3],
                                 cs[0], cs[1])
        cb, sb = fk.cos_sin_step(new_b, dr[1], rows[u, i, 7], rows[u, i, 8], model.dh0[i, 4],
                                 cs[2], cs[3])
        # d and r never change: both buffers hold them from fill_rows
        c.rows_out[u, i, 1] = prev_t + dr[2]
        c.rows_out[u, i, 3] = new_a
        c.rows_out[u, i, 4] = new_b
        c.rows_out[u, i, 5] = ca
        c.rows_out[u, i, 6] = sa
        c.rows_out[u, i, 7] = cb
        c.rows_out[u, i, 8] = sb
        return wp.max(wp.abs(dr[0]), wp.max(wp.abs(dr[1]), wp.abs(dr[2])))

    @wp.func
    def compensation_update(model: fk.FrameTables, frames: wp.array2d(dtype=mat44), b: int,
                            rows: wp.array3d(dtype=scalar), u: int, c: CompensationArgs):
        """One torque update of compensation row ``u`` (9 columns) from ``frames[b]``, the
        frames of its configuration computed at that row (b: the row of ``frames`` that
        holds them, e.g. a thread's scratch row): ``c.rows_out[u]`` (DH frames only) and
        ``c.delta[u]`` = max |new - old| [rad]. Scratch column ``u * c.scratch_stride``."""
        sc = u * c.scratch_stride
        subtree_prefix(model, frames, b, c.mass, c.mass_com, c.prefix, sc)
        dmax = zero
        for j in range(c.dh_info.shape[0]):
            info = c.dh_info[j]
            mo = c.prefix[info[2], sc] - c.prefix[info[0], sc]
            dmax = wp.max(dmax, frame_update(model, frames, b, rows, u, c, info, mo))
        c.delta[u] = dmax

    @wp.func
    def waypoint_config(u: int, c: CompensationArgs) -> int:
        """Configuration index of waypoint u (P paths of ``c.n_waypoints`` waypoints with
        ``c.n_sub`` substeps per segment)."""
        p = u // c.n_waypoints
        return p * ((c.n_waypoints - 1) * c.n_sub + 1) + (u - p * c.n_waypoints) * c.n_sub

    return SimpleNamespace(
        scalar=scalar,
        fk=fk, vec3=vec3, vec4=vec4, mat44=mat44, zero=zero, unpack_rot=unpack_rot,
        unpack_pos=unpack_pos, gravity_torques=gravity_torques, damped_step=damped_step,
        subtree_prefix=subtree_prefix, torque_update=torque_update,
        CompensationArgs=CompensationArgs, compensation_update=compensation_update,
        compensation_update_at=compensation_update,  # (the facade's name for it)
        frame_update=frame_update, waypoint_config=waypoint_config,
    )


@functools.cache
def elastic_step(scalar: type) -> wp.Kernel:
    """The torque update kernel (frames and damped DH rows), for ``scalar``."""
    sh = funcs(scalar)
    fk, vec3, vec4, mat44, zero = sh.fk, sh.vec3, sh.vec4, sh.mat44, sh.zero
    torque_update = sh.torque_update

    @wp.kernel(module="unique")
    def elastic_step_kernel(
        # Model:
        model: fk.FrameTables,
        mass: wp.array(dtype=scalar),
        mass_com: wp.array(dtype=vec3),
        dh_info: wp.array(dtype=wp.vec4i),
        kappa_nl: wp.array(dtype=scalar),
        # Data in:
        q: wp.array2d(dtype=scalar),
        rho: wp.array3d(dtype=scalar),
        rho_stride: int,
        rows_kind: int,
        rho0: wp.array3d(dtype=scalar),
        rho0_stride: int,
        kappa: wp.array3d(dtype=scalar),
        kappa_stride: int,
        lam: scalar,
        gravity: vec3,
        write_tau: int,
        scratch_stride: int,
        # Data out:
        frames: wp.array2d(dtype=mat44),
        prefix: wp.array2d(dtype=vec4),
        axes: wp.array2d(dtype=vec3),
        rho_out: wp.array3d(dtype=scalar),
        tau_out: wp.array3d(dtype=scalar),
        delta: wp.array(dtype=scalar),
    ):
        """One torque update: frames = F(q, rho); rho_out = damped update from the
        gravity torques of those frames; delta[b] = max |rho_out - rho| (rad).
        ``prefix`` (n_frames + 1, S) and ``axes`` (n_frames, S) are scratch (moment prefix
        sums; alpha axes from the FK pass), column ``b * scratch_stride``: stride 0 (S = 1)
        on the CPU, where configurations run one after another and the column stays in L1;
        stride 1 (S = B) on CUDA (frame-major: neighbouring threads touch neighbouring
        entries) and under a Tape (every entry written once)."""
        b = wp.tid()
        sb = b * scratch_stride
        acc = vec4(zero, zero, zero, zero)
        prefix[0, sb] = acc
        for k in range(model.order.shape[0]):
            i = model.order[k]
            R, p, ax = fk.write_frame(model, b, i, q, rho, b * rho_stride, rows_kind, frames, b)
            axes[i, sb] = ax
            m = mass[i]
            if m != zero:  # a fixed pattern per robot: predicted
                w = R * mass_com[i] + p
                acc = acc + vec4(m * w[0], m * w[1], m * w[2], m)
            prefix[k + 1, sb] = acc
        delta[b] = torque_update(b, frames, rho, rho_stride, rho0, rho0_stride, kappa,
                                 kappa_stride, kappa_nl, lam, gravity, dh_info, prefix, axes, sb, rho_out,
                                 tau_out, write_tau)

    return elastic_step_kernel


@functools.cache
def compensation_update(scalar: type) -> wp.Kernel:
    """The compensation rows' update kernel (from an optimizer's frames), for
    ``scalar``."""
    sh = funcs(scalar)
    fk, mat44, CompensationArgs = sh.fk, sh.mat44, sh.CompensationArgs
    compensation_update, waypoint_config = sh.compensation_update, sh.waypoint_config

    @wp.kernel(module="unique", enable_backward=False)
    def compensation_update_kernel(
        # Model:
        model: fk.FrameTables,
        # Data in:
        frames: wp.array2d(dtype=mat44),
        rows: wp.array3d(dtype=scalar),
        # Data out:
        c: CompensationArgs,
    ):
        """One torque update of compensation rows from frames an optimizer has already
        computed (elastic paper section V: no extra forward kinematics).

        ``frames`` (N, n_frames) are F(q, rows) of N = P * S configurations, P paths of
        ``c.n_waypoints`` waypoints with ``c.n_sub`` substeps each (S = (W - 1) n_sub + 1;
        configuration ``p * S + s``; IK: W = n_sub = 1). ``rows`` (P * W, n_frames, 9):
        one row per waypoint (``ROWS_COMPENSATION`` and :func:`jwarp.kernels.fk.waypoint_thread`:
        substeps read their nearest waypoint's). Launch dim P * W: thread u updates the
        torques at its waypoint and writes ``c.rows_out[u]`` and ``c.delta[u]``."""
        u = wp.tid()
        compensation_update(model, frames, waypoint_config(u, c), rows, u, c)

    return compensation_update_kernel


@functools.cache
def compensation_update_per_frame(scalar: type) -> wp.Kernel:
    """The compensation rows' update kernel, one thread per row and frame, for
    ``scalar``."""
    sh = funcs(scalar)
    fk, vec4, mat44, zero, unpack_rot = sh.fk, sh.vec4, sh.mat44, sh.zero, sh.unpack_rot
    unpack_pos, CompensationArgs, frame_update = sh.unpack_pos, sh.CompensationArgs, sh.frame_update
    waypoint_config = sh.waypoint_config

    @wp.kernel(module="unique", enable_backward=False)
    def compensation_update_per_frame_kernel(
        # Model:
        model: fk.FrameTables,
        # Data in:
        frames: wp.array2d(dtype=mat44),
        rows: wp.array3d(dtype=scalar),
        # Data out:
        c: CompensationArgs,
    ):
        """:func:`compensation_update_kernel` with one thread per (waypoint u, DH frame j)
        (launch dim (P * W, n_dh)): each thread sums the first moments of its own subtree
        from the frames, so no thread walks the whole robot one frame after another. For
        small batches on CUDA, where that serial walk sets the launch's duration.
        ``c.delta`` must be zero before the launch (atomic max over the frames)."""
        u, j = wp.tid()
        b = waypoint_config(u, c)
        info = c.dh_info[j]
        mo = vec4(zero, zero, zero, zero)
        for k in range(info[0], info[2]):
            f = model.order[k]
            m = c.mass[f]
            if m != zero:
                T = frames[b, f]
                w = unpack_rot(T) * c.mass_com[f] + unpack_pos(T)
                mo = mo + vec4(m * w[0], m * w[1], m * w[2], m)
        wp.atomic_max(c.delta, u, frame_update(model, frames, b, rows, u, c, info, mo))

    return compensation_update_per_frame_kernel


@functools.cache
def fill_rows(scalar: type) -> wp.Kernel:
    """The kernel filling compensation rows with the nominal ones, for ``scalar``."""
    sh = funcs(scalar)
    fk = sh.fk

    @wp.kernel(module="unique", enable_backward=False)
    def fill_rows_kernel(
        # Model:
        model: fk.FrameTables,
        # Data out:
        rows: wp.array3d(dtype=scalar),
    ):
        """rows[b, i] = nominal [dh0 row, cos alpha, sin alpha, cos beta, sin beta] (launch
        dim (B, n_frames)): compensation rows before the first torque update."""
        b, i = wp.tid()
        for c in range(5):
            rows[b, i, c] = model.dh0[i, c]
        cs = model.trig[i]
        for c in range(4):
            rows[b, i, 5 + c] = cs[c]

    return fill_rows_kernel


@functools.cache
def fill_static_rows(scalar: type) -> wp.Kernel:
    """The kernel writing the nominal rows of the static frames, for ``scalar``."""

    @wp.kernel(module="unique")
    def fill_static_rows(
        # Model:
        dh0: wp.array2d(dtype=scalar),
        static_idx: wp.array(dtype=wp.int32),
        # Data out:
        rho_out: wp.array3d(dtype=scalar),
    ):
        """rho_out[b, i] = dh0[i] for the static frames i (launch dim (B, n_static)): the
        elastic step never writes those rows."""
        b, j = wp.tid()
        i = static_idx[j]
        for c in range(5):
            rho_out[b, i, c] = dh0[i, c]

    return fill_static_rows


@functools.cache
def kernels(scalar: type) -> SimpleNamespace:
    """Elastic kernels for one scalar type: :func:`funcs`' arguments and functions and
    every kernel of the builders (a facade: the builders build only the kernel asked for)."""
    sh = funcs(scalar)
    return SimpleNamespace(
        vec4=sh.vec4, elastic_step=elastic_step(scalar),
        fill_static_rows=fill_static_rows(scalar), CompensationArgs=sh.CompensationArgs,
        compensation_update_at=sh.compensation_update,
        compensation_update=compensation_update(scalar),
        compensation_update_per_frame=compensation_update_per_frame(scalar),
        fill_rows=fill_rows(scalar),
    )
