"""Forward-kinematics and Jacobian kernels (math only; no numpy, no host logic).

All kernels are built per scalar type by :func:`kernels` (float32 or float64) and are
batched over configurations: one thread per configuration walks the frames in
topological order.

Frame tables (part of the *Model*, :class:`jwarp.core.device.DeviceModel`):

* ``order``        (n_frames,) int32  frames, parents first
* ``parent``       (n_frames,) int32  parent index, -1 for a root
* ``is_dh``        (n_frames,) int32  1 for a DH frame, 0 for a static frame
* ``prismatic``    (n_frames,) int32  1 if the driving joint(s) are prismatic
* ``fixed_rot``    (n_frames,) mat33  Rot_y(beta0) Rot_x(alpha0) (DH) or the static rotation
* ``fixed_pos``    (n_frames,) vec3   r0 * Rot_y(beta0) e_x (DH) or the static translation
* ``dh0``          (n_frames, 5)      nominal rows [d, theta, r, alpha, beta]
* ``trig``         (n_frames,) vec4   nominal [cos alpha, sin alpha, cos beta, sin beta]
* ``cpl_start``    (n_frames + 1,) int32, ``cpl_joint``/``cpl_coef``: CSR coupling q -> frame
* ``ch_start``     (n_frames + 1,) int32, ``ch_ab`` (n_terms, 2): CSR angle-dependent errors
  of coupled frames (the robot's ``coupling_harmonic``): frame i's terms k = 1 .. K_i are
  rows ``ch_start[i] .. ch_start[i + 1] - 1`` ``[a_k, b_k]``; empty for every frame of a
  robot without them; ``n_ch`` the number of frames with terms (0: the kernels skip them
  on a uniform branch, reading no table)
* ``jh_start``     (n_dof + 1,) int32, ``jh_ab`` (n_terms, 2): CSR transmission errors (the
  robot's ``harmonic``) of the joints that drive a frame with harmonic terms, only to
  recover their commanded values (:func:`commanded`); empty otherwise

The kernels see the links' joint values q' (the host applies transmission errors:
:mod:`jwarp.kinematics.transmission`). A frame's joint value (:func:`joint_value`) is
``sum_j c_j q'_j + sum_k a_k sin(k u) + b_k cos(k u)`` with ``u = sum_j c_j q_j`` of the
commanded values (:func:`harmonic_angle`; ``RobotModel.coupled_frame_delta``); its
derivative w.r.t. q'_j is ``c_j (1 + h'(u) / s_j)`` (:func:`coupling_weight`), the weight
of every analytic Jacobian column and projected gradient of a coupled frame.

DH rows ``rho`` (B_rho, n_frames, 5 or 9) and ``rows_kind`` (the host's typed value is
:class:`jwarp.core.rows.DHRows`); ``rho_stride`` is 1 to use row ``b`` for configuration
``b`` and 0 to share row 0. ``rows_kind`` is one of

* :data:`ROWS_NOMINAL` (0): ignore ``rho`` and use the precomputed nominal tables (fast
  path; ``rho`` is the nominal ``(1, n_frames, 5)`` table, which the torque pass reads);
* :data:`ROWS_DH` (1): rows ``[d, theta, r, alpha, beta]`` (calibration, elastic model),
  differentiable through a Tape w.r.t. every column;
* :data:`ROWS_COMPENSATION` (2): rows of 9 columns ``[d, theta, r, alpha, beta, cos alpha,
  sin alpha, cos beta, sin beta]`` (the compensation buffers of
  :mod:`jwarp.kernels.elastic`, whose update stores the cos/sin with the angles), so FK at
  per-configuration rows costs no more trigonometry than the nominal fast path. Gradients
  through a Tape w.r.t. such rows reach the cos/sin columns, not alpha/beta: use
  :data:`ROWS_DH` to differentiate w.r.t. rho.

DH convention: ``parent_T_child = Rot_y(beta) Rot_x(alpha) Trans_x(r) Rot_z(theta+q) Trans_z(d)``.
"""


import functools
from types import SimpleNamespace
from typing import Any

import warp as wp

#: ``rows_kind`` of the kernels (see the module docstring; :class:`jwarp.core.rows.RowsKind`)
ROWS_NOMINAL = wp.constant(0)
ROWS_DH = wp.constant(1)
ROWS_COMPENSATION = wp.constant(2)


@functools.cache
def funcs(scalar: type) -> SimpleNamespace:
    """The frame tables, vector types and ``@wp.func`` helpers of the kinematics, for one
    scalar type (``wp.float32``/``wp.float64``); built once per type (issue 40 item 5: the
    kernels are built one each, by :func:`fk`, :func:`fk_components`, :func:`jacobian` and
    :func:`jacobian_dh`, from these)."""
    vec3 = wp.types.vector(3, scalar)
    mat33 = wp.types.matrix((3, 3), scalar)
    mat44 = wp.types.matrix((4, 4), scalar)
    vec4 = wp.types.vector(4, scalar)
    zero = scalar(0.0)
    one = scalar(1.0)

    @wp.struct
    class FrameTables:
        """The frame tables of one robot (see the module docstring), one kernel argument."""

        order: wp.array(dtype=wp.int32)
        parent: wp.array(dtype=wp.int32)
        is_dh: wp.array(dtype=wp.int32)
        prismatic: wp.array(dtype=wp.int32)
        fixed_rot: wp.array(dtype=mat33)
        fixed_pos: wp.array(dtype=vec3)
        dh0: wp.array2d(dtype=scalar)
        trig: wp.array(dtype=vec4)
        cpl_start: wp.array(dtype=wp.int32)
        cpl_joint: wp.array(dtype=wp.int32)
        cpl_coef: wp.array(dtype=scalar)
        ch_start: wp.array(dtype=wp.int32)
        ch_ab: wp.array2d(dtype=scalar)
        jh_start: wp.array(dtype=wp.int32)
        jh_ab: wp.array2d(dtype=scalar)
        n_ch: wp.int32

    @wp.func
    def dh_fixed_rot(alpha: scalar, beta: scalar) -> mat33:
        ca = wp.cos(alpha)
        sa = wp.sin(alpha)
        cb = wp.cos(beta)
        sb = wp.sin(beta)
        return mat33(cb, sb * sa, sb * ca,
                     zero, ca, -sa,
                     -sb, cb * sa, cb * ca)

    if scalar == wp.float32:

        @wp.func
        def cos_sin(x: scalar):
            """(cos x, sin x) in float32: Cody-Waite reduction by pi/2 and the minimax
            polynomials of Cephes' sinf/cosf (error below 3e-7, tested for |x| <= 60 rad);
            about twice as fast as two libm calls on the CPU."""
            # round to nearest by the 1.5 * 2^23 shifter (no libm call; |x| < 1e6)
            k = (x * scalar(0.63661977236758134) + scalar(12582912.0)) - scalar(12582912.0)
            # pi/2 in three parts; k * part is exact for the first two (|k| < 2^11)
            r = ((x - k * scalar(1.5703125)) - k * scalar(4.837512969970703125e-4)) - k * scalar(7.54978995489188216e-8)
            z = r * r
            s = r + r * z * (scalar(-1.6666654611e-1) + z * (scalar(8.3321608736e-3)
                                                            + z * scalar(-1.9515295891e-4)))
            c = one - scalar(0.5) * z + z * z * (scalar(4.166664568298827e-2) + z * (
                scalar(-1.388731625493765e-3) + z * scalar(2.443315711809948e-5)))
            quadrant = int(k) & 3  # branch-free quadrant fix-up (random angles mispredict)
            odd = scalar(quadrant & 1)
            cos_base = c + odd * (s - c)
            sin_base = s + odd * (c - s)
            cos_sign = one - scalar(2 * (((quadrant + 1) >> 1) & 1))
            sin_sign = one - scalar(2 * (quadrant >> 1))
            return cos_sign * cos_base, sin_sign * sin_base

    else:

        @wp.func
        def cos_sin(x: scalar):
            """(cos x, sin x) from libm (float64)."""
            return wp.cos(x), wp.sin(x)

    if scalar == wp.float32:

        @wp.func
        def cos_sin_near(x: scalar, x0: scalar, c0: scalar, s0: scalar):
            """(cos x, sin x) given cos/sin of a nearby x0: for |x - x0| < 0.1 rad the angle
            sum with a Taylor series of the difference (truncation < 2e-9, below float32
            resolution), else :func:`cos_sin`."""
            dx = x - x0
            if wp.abs(dx) < scalar(0.1):
                d2 = dx * dx
                sd = dx * (one - d2 * scalar(1.0 / 6.0) * (one - d2 * scalar(1.0 / 20.0)))
                cd = one - d2 * scalar(0.5) * (one - d2 * scalar(1.0 / 12.0))
                return c0 * cd - s0 * sd, s0 * cd + c0 * sd
            return cos_sin(x)

        @wp.func
        def cos_sin_step(x: scalar, dx: scalar, c0: scalar, s0: scalar, x0: scalar,
                         cn: scalar, sn: scalar):
            """float32: always :func:`cos_sin_near` from the nominal angle x0 (chained steps
            would accumulate float32 rounding over the iterations)."""
            return cos_sin_near(x, x0, cn, sn)

    else:
        # float64 constants must be made here: Warp evaluates a float expression inside a
        # kernel, e.g. ``scalar(1.0 / 6.0)``, in float32 (a 1e-8 relative error)
        i3, i6, i12, i20, i30, i42, i56 = (scalar(1.0 / n) for n in (3, 6, 12, 20, 30, 42, 56))
        near_max = scalar(0.1)
        step_max = scalar(2e-4)

        @wp.func
        def cos_sin_near(x: scalar, x0: scalar, c0: scalar, s0: scalar):
            """(cos x, sin x) given cos/sin of a nearby x0: for |x - x0| < 0.1 rad the angle
            sum with a Taylor series of the difference (truncation < 3e-15), else libm."""
            dx = x - x0
            if wp.abs(dx) < near_max:
                d2 = dx * dx
                # reciprocal constants: a division costs ~10x a multiplication on the CPU
                sd = dx * (one - d2 * i6 * (one - d2 * i20 * (one - d2 * i42)))
                cd = one - d2 * scalar(0.5) * (one - d2 * i12 * (one - d2 * i30 * (one - d2 * i56)))
                return c0 * cd - s0 * sd, s0 * cd + c0 * sd
            return cos_sin(x)

        @wp.func
        def cos_sin_step(x: scalar, dx: scalar, c0: scalar, s0: scalar, x0: scalar,
                         cn: scalar, sn: scalar):
            """(cos x, sin x) for x = x_prev + dx, given (c0, s0) = cos/sin of x_prev and
            (cn, sn) = cos/sin of the nominal angle x0. For |dx| < 2e-4 rad the angle sum
            with a two-term series of dx (truncation dx^4/24 < 7e-17; a short dependency
            chain, where :func:`cos_sin_near`'s longer series was the torque update's hot
            spot); rounding adds ~1e-16 per step. Else :func:`cos_sin_near` from x0."""
            if wp.abs(dx) < step_max:
                h = scalar(0.5) * dx * dx
                cd = one - h
                sd = dx - i3 * h * dx
                return c0 * cd - s0 * sd, s0 * cd + c0 * sd
            return cos_sin_near(x, x0, cn, sn)

    @wp.func
    def coupled_angle(model: FrameTables, i: int, b: int, q: wp.array2d(dtype=scalar)) -> scalar:
        """``sum_j c_j q[b, j]`` of frame i (its coupling, without harmonic terms)."""
        v = zero
        for k in range(model.cpl_start[i], model.cpl_start[i + 1]):
            v += model.cpl_coef[k] * q[b, model.cpl_joint[k]]
        return v

    @wp.func
    def commanded(model: FrameTables, j: int, x: scalar):
        """(q_j, dq'_j/dq_j): the commanded value of joint j whose links see x (the inverse
        of its transmission error ``x = q + sum_k a_k sin(k q) + b_k cos(k q)``, by Newton's
        method, and the error's slope there); (x, 1) where ``jh`` holds no terms."""
        y = x
        s = one
        h0 = model.jh_start[j]
        h1 = model.jh_start[j + 1]
        if h1 > h0:
            for it in range(6):
                f = y - x
                s = one
                for k in range(h0, h1):
                    kk = scalar(k - h0 + 1)
                    ck, sk = cos_sin(kk * y)
                    f += model.jh_ab[k, 0] * sk + model.jh_ab[k, 1] * ck
                    s += kk * (model.jh_ab[k, 0] * ck - model.jh_ab[k, 1] * sk)
                y = y - f / s
        return y, s

    @wp.func
    def harmonic_angle(model: FrameTables, i: int, b: int, q: wp.array2d(dtype=scalar)) -> scalar:
        """The angle of frame i's harmonic terms, ``u = sum_j c_j q_j`` of the commanded
        joint values (:func:`commanded` of the values q the kernels see)."""
        v = zero
        for k in range(model.cpl_start[i], model.cpl_start[i + 1]):
            j = model.cpl_joint[k]
            y, s = commanded(model, j, q[b, j])
            v += model.cpl_coef[k] * y
        return v

    @wp.func
    def joint_value(model: FrameTables, i: int, b: int, q: wp.array2d(dtype=scalar)) -> scalar:
        """Joint value of frame i at configuration b: ``sum_j c_j q[b, j] + sum_k a_k sin(k u)
        + b_k cos(k u)`` (``u`` :func:`harmonic_angle`; no terms without ``coupling_harmonic``)."""
        v = coupled_angle(model, i, b, q)
        if model.n_ch != 0:  # a uniform branch on a kernel argument: free without terms
            h0 = model.ch_start[i]
            h1 = model.ch_start[i + 1]
            if h1 > h0:
                u = harmonic_angle(model, i, b, q)
                e = zero
                for k in range(h0, h1):
                    ck, sk = cos_sin(scalar(k - h0 + 1) * u)
                    e += model.ch_ab[k, 0] * sk + model.ch_ab[k, 1] * ck
                v += e
        return v

    @wp.func
    def coupling_harmonic_slope(model: FrameTables, i: int, b: int,
                                q: wp.array2d(dtype=scalar)) -> scalar:
        """``h'(u) = sum_k k (a_k cos(k u) - b_k sin(k u))`` of frame i's harmonic terms (zero
        without them): pass it to :func:`coupling_weight`."""
        g = zero
        if model.n_ch != 0:
            h0 = model.ch_start[i]
            h1 = model.ch_start[i + 1]
            if h1 > h0:
                u = harmonic_angle(model, i, b, q)
                for k in range(h0, h1):
                    kk = scalar(k - h0 + 1)
                    ck, sk = cos_sin(kk * u)
                    g += kk * (model.ch_ab[k, 0] * ck - model.ch_ab[k, 1] * sk)
        return g

    @wp.func
    def coupling_weight(model: FrameTables, c: int, b: int, q: wp.array2d(dtype=scalar),
                        hp: scalar) -> scalar:
        """d joint_value / dq_j of coupling entry c (joint j = ``cpl_joint[c]``) at
        configuration b: ``c_j (1 + h'(u) / s_j)``, ``hp`` = h'(u) of the frame
        (:func:`coupling_harmonic_slope`), s_j the slope of joint j's transmission error
        (1 without); exactly ``cpl_coef[c]`` where hp is zero."""
        w = model.cpl_coef[c]
        if hp != zero:
            j = model.cpl_joint[c]
            y, s = commanded(model, j, q[b, j])
            w = w * (one + hp / s)
        return w

    @wp.func
    def harmonic_travel(model: FrameTables, i: int, r: int, dq: wp.array2d(dtype=scalar)) -> scalar:
        """A bound of how much frame i's harmonic terms can change over the joint motion
        dq[r] (zero without them): ``L sum_j |c_j dq_j| / s_min_j`` with L = sum_k k (|a_k| +
        |b_k|) and s_min_j the least slope of joint j's transmission (1 without)."""
        t = zero
        h0 = int(0)
        h1 = int(0)
        if model.n_ch != 0:
            h0 = model.ch_start[i]
            h1 = model.ch_start[i + 1]
        if h1 > h0:
            lip = zero
            for k in range(h0, h1):
                lip += scalar(k - h0 + 1) * (wp.abs(model.ch_ab[k, 0]) + wp.abs(model.ch_ab[k, 1]))
            for c in range(model.cpl_start[i], model.cpl_start[i + 1]):
                j = model.cpl_joint[c]
                smin = one
                for k in range(model.jh_start[j], model.jh_start[j + 1]):
                    smin -= scalar(k - model.jh_start[j] + 1) * (wp.abs(model.jh_ab[k, 0])
                                                                 + wp.abs(model.jh_ab[k, 1]))
                t += wp.abs(model.cpl_coef[c] * dq[r, j]) / smin
            t = t * lip
        return t

    @wp.func
    def child_frame(model: FrameTables, Rp: mat33, pp: vec3, i: int, rb: int, qi: scalar,
                    rows_kind: int, rho: wp.array3d(dtype=scalar)):
        """World rotation and position of frame i from its parent's (Rp, pp), and the
        direction of its ``r`` translation (= its alpha axis, ``Rp Rot_y(beta) e_x``; zero
        for a static frame).

        DH frames are composed column by column (Rot_y, Rot_x, Trans_x, Rot_z, Trans_z),
        which costs about half the multiplications of a full 4x4 product."""
        if model.is_dh[i] == 0:
            return Rp * model.fixed_rot[i], Rp * model.fixed_pos[i] + pp, vec3(zero, zero, zero)
        d = model.dh0[i, 0]
        theta = model.dh0[i, 1]
        r = model.dh0[i, 2]
        cs = model.trig[i]
        ca = cs[0]
        sa = cs[1]
        cb = cs[2]
        sb = cs[3]
        if rows_kind != ROWS_NOMINAL:
            d = rho[rb, i, 0]
            theta = rho[rb, i, 1]
            r = rho[rb, i, 2]
            if rows_kind == ROWS_COMPENSATION:  # rows carry their cos/sin (compensation buffers)
                ca = rho[rb, i, 5]
                sa = rho[rb, i, 6]
                cb = rho[rb, i, 7]
                sb = rho[rb, i, 8]
            else:
                ca, sa = cos_sin_near(rho[rb, i, 3], model.dh0[i, 3], cs[0], cs[1])
                cb, sb = cos_sin_near(rho[rb, i, 4], model.dh0[i, 4], cs[2], cs[3])
        if model.prismatic[i] != 0:
            d = d + qi
        else:
            theta = theta + qi
        c0 = vec3(Rp[0, 0], Rp[1, 0], Rp[2, 0])
        c1 = vec3(Rp[0, 1], Rp[1, 1], Rp[2, 1])
        c2 = vec3(Rp[0, 2], Rp[1, 2], Rp[2, 2])
        if sb != zero or rows_kind == ROWS_DH:  # Rot_y(beta); always when differentiable in beta
            t0 = cb * c0 - sb * c2
            c2 = sb * c0 + cb * c2
            c0 = t0
        n1 = ca * c1 + sa * c2  # Rot_x(alpha)
        n2 = ca * c2 - sa * c1
        p = pp + r * c0  # Trans_x(r)
        ct, st = cos_sin(theta)
        m0 = ct * c0 + st * n1  # Rot_z(theta + q)
        m1 = ct * n1 - st * c0
        return wp.matrix_from_cols(m0, m1, n2), p + d * n2, c0  # Trans_z(d)

    @wp.func
    def child_rot_pos(model: FrameTables, Rp: mat33, pp: vec3, i: int, rb: int, qi: scalar,
                      rows_kind: int, rho: wp.array3d(dtype=scalar)):
        """World rotation and position of frame i from its parent's (:func:`child_frame`)."""
        R, p, ax = child_frame(model, Rp, pp, i, rb, qi, rows_kind, rho)
        return R, p

    @wp.func
    def chain_link(model: FrameTables, chain: wp.array(dtype=wp.int32), k: int, b: int,
                   q: wp.array2d(dtype=scalar), rows_kind: int, rho: wp.array3d(dtype=scalar),
                   rb: int, Rp: mat33, pp: vec3):
        """One step of a walk along ``chain`` (the frames from the root to its last one) at
        configuration b: the index i = chain[k] and the world rotation and position of
        frame i from (Rp, pp), those of chain[k - 1] (identity and origin for k = 0)."""
        i = chain[k]
        R, p = child_rot_pos(model, Rp, pp, i, rb, joint_value(model, i, b, q), rows_kind, rho)
        return i, R, p

    @wp.func
    def chain_pose(model: FrameTables, chain: wp.array(dtype=wp.int32), b: int,
                   q: wp.array2d(dtype=scalar), rows_kind: int, rho: wp.array3d(dtype=scalar),
                   rb: int):
        """World rotation and position of the last frame of ``chain`` (the frames from the
        root to it) at configuration b, walking only that chain (no frames stored)."""
        R = wp.identity(3, dtype=scalar)
        p = vec3(zero, zero, zero)
        for k in range(chain.shape[0]):
            i, R, p = chain_link(model, chain, k, b, q, rows_kind, rho, rb, R, p)
        return R, p

    @wp.func
    def chain_point(model: FrameTables, chain: wp.array(dtype=wp.int32), b: int,
                    q: wp.array2d(dtype=scalar), rows_kind: int, rho: wp.array3d(dtype=scalar),
                    rb: int, point: vec3) -> vec3:
        """World position of ``point`` (coordinates of the last frame of ``chain``, the
        frames from the root to it), walking only that chain (:func:`chain_pose`)."""
        R, p = chain_pose(model, chain, b, q, rows_kind, rho, rb)
        return R * point + p

    @wp.func
    def waypoint_thread(t: int, layout: wp.vec4i):
        """(configuration b, its row, on_waypoint) of thread t where rows are kept per
        waypoint. ``layout`` = (S configurations per path, n_sub substeps per segment,
        W waypoints, P paths or 0), S = (W - 1) n_sub + 1, configuration ``p * S + s``;
        a substep reads its nearest waypoint's row (ties: the later one), on_waypoint is 1
        where b is that waypoint.

        P > 0 (CUDA): threads 0 .. P W - 1 take the waypoints (row t), the rest the
        substeps in path order, so the torque update that only waypoints run does not
        diverge the warps of the substeps. P = 0 (the CPU): b = t, so the configurations
        of a path run one after another and its rows stay in cache.
        Layout (1, 1, 1, 0) gives (t, t, 1)."""
        S = layout[0]
        if S == 1:
            return t, t, 1
        n_sub = layout[1]
        W = layout[2]
        n_wp = W * layout[3]
        if n_wp == 0:
            p = t // S
            s = t - p * S
            w = (s + (n_sub >> 1)) // n_sub
            return t, p * W + w, int(w * n_sub == s)
        if t < n_wp:
            p = t // W
            return p * S + (t - p * W) * n_sub, t, 1
        k = t - n_wp
        m = S - W  # substeps per path (n_sub >= 2 here)
        p = k // m
        r = k - p * m
        seg = r // (n_sub - 1)
        j = r - seg * (n_sub - 1) + 1  # 1 .. n_sub - 1 within the segment
        return p * S + seg * n_sub + j, p * W + seg + (j + (n_sub >> 1)) // n_sub, 0

    @wp.func
    def pack(R: mat33, p: vec3) -> mat44:
        return mat44(R[0, 0], R[0, 1], R[0, 2], p[0],
                     R[1, 0], R[1, 1], R[1, 2], p[1],
                     R[2, 0], R[2, 1], R[2, 2], p[2],
                     zero, zero, zero, one)

    @wp.func
    def unpack_rot(T: mat44) -> mat33:
        return mat33(T[0, 0], T[0, 1], T[0, 2], T[1, 0], T[1, 1], T[1, 2], T[2, 0], T[2, 1], T[2, 2])

    @wp.func
    def unpack_pos(T: mat44) -> vec3:
        return vec3(T[0, 3], T[1, 3], T[2, 3])

    @wp.func
    def parent_pose(frames: wp.array2d(dtype=mat44), b: int, pi: int):
        """World rotation and position of frame pi from batch-major frames."""
        Tp = frames[b, pi]
        return unpack_rot(Tp), unpack_pos(Tp)

    @wp.func
    def parent_pose(frames: wp.array4d(dtype=scalar), b: int, pi: int):  # noqa: F811 (overload)
        """World rotation and position of frame pi from scalar frames (any strides)."""
        return (mat33(frames[b, pi, 0, 0], frames[b, pi, 0, 1], frames[b, pi, 0, 2],
                      frames[b, pi, 1, 0], frames[b, pi, 1, 1], frames[b, pi, 1, 2],
                      frames[b, pi, 2, 0], frames[b, pi, 2, 1], frames[b, pi, 2, 2]),
                vec3(frames[b, pi, 0, 3], frames[b, pi, 1, 3], frames[b, pi, 2, 3]))

    @wp.func
    def store_pose(frames: wp.array2d(dtype=mat44), b: int, i: int, R: mat33, p: vec3):
        frames[b, i] = pack(R, p)

    @wp.func
    def store_pose(frames: wp.array4d(dtype=scalar), b: int, i: int, R: mat33,  # noqa: F811
                   p: vec3):  # (a Warp overload)
        for r in range(3):
            for c in range(3):
                frames[b, i, r, c] = R[r, c]
            frames[b, i, r, 3] = p[r]
            frames[b, i, 3, r] = zero
        frames[b, i, 3, 3] = one

    @wp.func
    def write_frame(model: FrameTables, b: int, i: int, q: wp.array2d(dtype=scalar),
                    rho: wp.array3d(dtype=scalar), rb: int, rows_kind: int, frames: Any, fb: int):
        """frames[fb, i] from its parent's transform (already written to row fb) and the
        joint values of configuration b; returns the frame's world rotation, position and
        alpha axis (:func:`child_frame`). ``frames``: batch-major mat44 (B, n_frames) or
        scalar (B, n_frames, 4, 4); ``fb`` is b, or a scratch row of the calling thread."""
        qi = joint_value(model, i, b, q)
        Rp = wp.identity(3, dtype=scalar)
        pp = vec3(zero, zero, zero)
        pi = model.parent[i]
        if pi >= 0:
            Rp, pp = parent_pose(frames, fb, pi)
        R, p, ax = child_frame(model, Rp, pp, i, rb, qi, rows_kind, rho)
        store_pose(frames, fb, i, R, p)
        return R, p, ax

    @wp.func
    def add_axis_columns(model: FrameTables, i: int, z: vec3, p: vec3, target: vec3, b: int,
                         q: wp.array2d(dtype=scalar), jac: wp.array3d(dtype=scalar)):
        """Adds the velocity of ``target`` due to the joint(s) driving frame i (axis z
        through p) to the columns of jac[b] (rows [linear; angular]; coupled joints add
        :func:`coupling_weight` ``*`` the column, q[b] the configuration)."""
        if model.cpl_start[i + 1] > model.cpl_start[i]:
            lin = wp.cross(z, target - p)
            ang = z
            if model.prismatic[i] != 0:
                lin = z
                ang = vec3(zero, zero, zero)
            if model.n_ch == 0:  # no harmonic terms anywhere (uniform branch): plain weights
                for c in range(model.cpl_start[i], model.cpl_start[i + 1]):
                    j = model.cpl_joint[c]
                    w = model.cpl_coef[c]
                    for r in range(3):
                        jac[b, r, j] = jac[b, r, j] + w * lin[r]
                        jac[b, r + 3, j] = jac[b, r + 3, j] + w * ang[r]
            else:
                hp = coupling_harmonic_slope(model, i, b, q)
                for c in range(model.cpl_start[i], model.cpl_start[i + 1]):
                    j = model.cpl_joint[c]
                    w = coupling_weight(model, c, b, q, hp)
                    for r in range(3):
                        jac[b, r, j] = jac[b, r, j] + w * lin[r]
                        jac[b, r + 3, j] = jac[b, r + 3, j] + w * ang[r]

    @wp.func
    def clear_jacobian(jac: wp.array3d(dtype=scalar), b: int):
        """jac[b] (6, n_dof) = 0."""
        for j in range(jac.shape[2]):
            for r in range(6):
                jac[b, r, j] = zero

    @wp.func
    def chain_jacobian(model: FrameTables, chain: wp.array(dtype=wp.int32), b: int,
                       q: wp.array2d(dtype=scalar), rows_kind: int,
                       rho: wp.array3d(dtype=scalar), rb: int, target: vec3,
                       jac: wp.array3d(dtype=scalar)):
        """Geometric Jacobian jac[b] (6, n_dof) of the world point ``target`` moving with
        the last frame of ``chain``: the chain walked again (as :func:`chain_pose`), each
        frame adding its joint axis (z through its origin, :func:`add_axis_columns`)."""
        clear_jacobian(jac, b)
        R = wp.identity(3, dtype=scalar)
        p = vec3(zero, zero, zero)
        for k in range(chain.shape[0]):
            i, R, p = chain_link(model, chain, k, b, q, rows_kind, rho, rb, R, p)
            add_axis_columns(model, i, vec3(R[0, 2], R[1, 2], R[2, 2]), p, target, b, q, jac)

    @wp.func
    def frames_jacobian(model: FrameTables, chain: wp.array(dtype=wp.int32),
                        frames: wp.array2d(dtype=mat44), b: int, q: wp.array2d(dtype=scalar),
                        target: vec3, jac: wp.array3d(dtype=scalar)):
        """Geometric Jacobian jac[b] (6, n_dof) of the world point ``target`` moving with
        the last frame of ``chain``, from frames an FK pass has already computed at q[b]
        (no kinematics of its own; q only for :func:`coupling_weight`)."""
        clear_jacobian(jac, b)
        for k in range(chain.shape[0]):
            T = frames[b, chain[k]]
            add_axis_columns(model, chain[k], vec3(T[0, 2], T[1, 2], T[2, 2]),
                             vec3(T[0, 3], T[1, 3], T[2, 3]), target, b, q, jac)

    return SimpleNamespace(
        scalar=scalar,
        vec3=vec3, mat33=mat33, mat44=mat44, vec4=vec4, zero=zero, one=one,
        FrameTables=FrameTables, dh_fixed_rot=dh_fixed_rot, cos_sin=cos_sin,
        cos_sin_near=cos_sin_near, cos_sin_step=cos_sin_step,
        coupled_angle=coupled_angle, commanded=commanded, harmonic_angle=harmonic_angle,
        joint_value=joint_value, coupling_harmonic_slope=coupling_harmonic_slope,
        coupling_weight=coupling_weight, harmonic_travel=harmonic_travel,
        child_frame=child_frame, child_rot_pos=child_rot_pos, chain_link=chain_link,
        chain_pose=chain_pose, chain_point=chain_point, waypoint_thread=waypoint_thread,
        pack=pack, unpack_rot=unpack_rot, unpack_pos=unpack_pos, parent_pose=parent_pose,
        store_pose=store_pose, write_frame=write_frame, add_axis_columns=add_axis_columns,
        clear_jacobian=clear_jacobian, chain_jacobian=chain_jacobian,
        frames_jacobian=frames_jacobian,
    )


@functools.cache
def fk(scalar: type) -> wp.Kernel:
    """The forward kinematics kernel (every frame's world transform), for ``scalar``."""
    sh = funcs(scalar)
    mat44, FrameTables, write_frame = sh.mat44, sh.FrameTables, sh.write_frame

    @wp.kernel(module="unique")
    def fk_kernel(
        # Model:
        model: FrameTables,
        # Data in:
        q: wp.array2d(dtype=scalar),
        rho: wp.array3d(dtype=scalar),
        rho_stride: int,
        rows_kind: int,
        # Data out:
        frames: wp.array2d(dtype=mat44),
    ):
        """World transform of every frame: frames[b, i] (4x4)."""
        b = wp.tid()
        for k in range(model.order.shape[0]):
            i = model.order[k]
            write_frame(model, b, i, q, rho, b * rho_stride, rows_kind, frames, b)

    return fk_kernel


@functools.cache
def fk_components(scalar: type) -> wp.Kernel:
    """The forward kinematics kernel writing the transforms' components, for
    ``scalar``."""
    sh = funcs(scalar)
    FrameTables, write_frame = sh.FrameTables, sh.write_frame

    @wp.kernel(module="unique", enable_backward=False)
    def fk_components_kernel(
        # Model:
        model: FrameTables,
        # Data in:
        q: wp.array2d(dtype=scalar),
        rho: wp.array3d(dtype=scalar),
        rho_stride: int,
        rows_kind: int,
        # Data out:
        frames: wp.array4d(dtype=scalar),
    ):
        """:func:`fk_kernel` writing scalars ``frames[b, i, r, c]`` (B, n_frames, 4, 4) of any
        strides: with the batch index fastest in memory (a component-major view) every
        store of a warp is one coalesced 128-byte line on CUDA. Forward only (no Tape):
        gradients go through :func:`fk_kernel`."""
        b = wp.tid()
        for k in range(model.order.shape[0]):
            write_frame(model, b, model.order[k], q, rho, b * rho_stride, rows_kind, frames, b)

    return fk_components_kernel


@functools.cache
def jacobian(scalar: type) -> wp.Kernel:
    """The geometric Jacobian kernel, for ``scalar``."""
    sh = funcs(scalar)
    vec3, FrameTables, chain_point = sh.vec3, sh.FrameTables, sh.chain_point
    chain_jacobian = sh.chain_jacobian

    @wp.kernel(module="unique")
    def jacobian_kernel(
        # Model:
        model: FrameTables,
        chain: wp.array(dtype=wp.int32),
        # Data in:
        q: wp.array2d(dtype=scalar),
        rho: wp.array3d(dtype=scalar),
        rho_stride: int,
        rows_kind: int,
        point: vec3,
        # Data out:
        jac: wp.array3d(dtype=scalar),
    ):
        """Geometric Jacobian (B, 6, n_dof) of ``point`` (in the last chain frame's
        coordinates) w.r.t. q: rows [linear; angular] velocity in the base frame.
        ``chain`` lists the frames from the root to the target. Coupled joints add
        ``coef * column`` to each driving joint."""
        b = wp.tid()
        rb = b * rho_stride
        target = chain_point(model, chain, b, q, rows_kind, rho, rb, point)  # pass 1
        chain_jacobian(model, chain, b, q, rows_kind, rho, rb, target, jac)  # pass 2: axes

    return jacobian_kernel


@functools.cache
def jacobian_dh(scalar: type) -> wp.Kernel:
    """The DH-row Jacobian kernel, for ``scalar``."""
    sh = funcs(scalar)
    vec3, zero, FrameTables, chain_link = sh.vec3, sh.zero, sh.FrameTables, sh.chain_link
    chain_point = sh.chain_point

    @wp.kernel(module="unique")
    def jacobian_dh_kernel(
        # Model:
        model: FrameTables,
        chain: wp.array(dtype=wp.int32),
        # Data in:
        q: wp.array2d(dtype=scalar),
        rho: wp.array3d(dtype=scalar),
        rho_stride: int,
        rows_kind: int,
        point: vec3,
        # Data out:
        jac: wp.array4d(dtype=scalar),
    ):
        """Jacobian (B, 6, n_frames, 5) of ``point`` on the chain's last frame w.r.t. the
        DH rows [d, theta, r, alpha, beta] of every frame (zero off the chain): rows
        [linear; angular] in the base frame. Caller zero-fills ``jac``."""
        b = wp.tid()
        rb = b * rho_stride
        target = chain_point(model, chain, b, q, rows_kind, rho, rb, point)
        R = wp.identity(3, dtype=scalar)
        p = vec3(zero, zero, zero)
        for k in range(chain.shape[0]):
            Rp = R
            pp = p
            i, R, p = chain_link(model, chain, k, b, q, rows_kind, rho, rb, Rp, pp)
            if model.is_dh[i] != 0:
                beta = model.dh0[i, 4]
                if rows_kind != ROWS_NOMINAL:
                    beta = rho[rb, i, 4]
                z = vec3(R[0, 2], R[1, 2], R[2, 2])
                ax_beta = vec3(Rp[0, 1], Rp[1, 1], Rp[2, 1])
                ax_alpha = Rp * vec3(wp.cos(beta), zero, -wp.sin(beta))
                # x axis of Rot_y(beta) Rot_x(alpha) = ax_alpha: direction of r
                lin_d = z
                lin_theta = wp.cross(z, target - p)
                lin_r = ax_alpha
                lin_alpha = wp.cross(ax_alpha, target - pp)
                lin_beta = wp.cross(ax_beta, target - pp)
                for r in range(3):
                    jac[b, r, i, 0] = lin_d[r]
                    jac[b, r, i, 1] = lin_theta[r]
                    jac[b, r + 3, i, 1] = z[r]
                    jac[b, r, i, 2] = lin_r[r]
                    jac[b, r, i, 3] = lin_alpha[r]
                    jac[b, r + 3, i, 3] = ax_alpha[r]
                    jac[b, r, i, 4] = lin_beta[r]
                    jac[b, r + 3, i, 4] = ax_beta[r]

    return jacobian_dh_kernel


@functools.cache
def kernels(scalar: type) -> SimpleNamespace:
    """Kernels and functions for one scalar type (``wp.float32`` or ``wp.float64``):
    :func:`funcs`' tables and functions and every kernel of the builders (a facade: the
    builders build only the kernel asked for)."""
    sh = funcs(scalar)
    return SimpleNamespace(
        scalar=scalar, FrameTables=sh.FrameTables, vec3=sh.vec3, mat33=sh.mat33,
        mat44=sh.mat44, vec4=sh.vec4, cos_sin=sh.cos_sin, cos_sin_near=sh.cos_sin_near,
        cos_sin_step=sh.cos_sin_step, joint_value=sh.joint_value,
        coupled_angle=sh.coupled_angle, commanded=sh.commanded,
        harmonic_angle=sh.harmonic_angle,
        coupling_harmonic_slope=sh.coupling_harmonic_slope,
        coupling_weight=sh.coupling_weight, harmonic_travel=sh.harmonic_travel,
        waypoint_thread=sh.waypoint_thread, write_frame=sh.write_frame,
        child_frame=sh.child_frame, child_rot_pos=sh.child_rot_pos,
        chain_link=sh.chain_link, chain_pose=sh.chain_pose, chain_point=sh.chain_point,
        add_axis_columns=sh.add_axis_columns, clear_jacobian=sh.clear_jacobian,
        chain_jacobian=sh.chain_jacobian, frames_jacobian=sh.frames_jacobian, pack=sh.pack,
        unpack_rot=sh.unpack_rot, unpack_pos=sh.unpack_pos, fk=fk(scalar),
        fk_components=fk_components(scalar), jacobian=jacobian(scalar),
        jacobian_dh=jacobian_dh(scalar),
    )
