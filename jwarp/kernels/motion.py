"""Continuous feasibility of paths on the device (math only; host: :mod:`jwarp.world.motion`).

A path (W, n_dof) moves linearly in joint space between its waypoints. The check proves,
for every segment, that every collision sphere keeps at least the required clearance ``m``
from the world (exact objects, and grids lowered by their declared error) and from every
sphere it may collide with, along the whole continuous motion, and that every waypoint is
within the joint limits (the box and the linear limits are convex, so the segments between
waypoints are then within them too).

Travel bound: while the joints move by ``dq`` the centre of sphere s moves along a curve of
length at most ``L_s = sum_i |dtheta_i| R[s, i]`` (``dtheta_i``: the change of the angle
(or offset) of frame i, through the couplings; ``R[s, i]`` a bound of the distance of the
sphere centre from frame i's joint axis over all configurations, 1 for prismatic frames;
host: :func:`jwarp.world.motion.sphere_reach`). A segment is split into ``n`` equal substeps
so that every point of the motion lies within ``l_s / 2 = L_s / (2 n)`` of a substep along
the sphere's path. Hence a sphere whose clearance at every substep is ``>= m + l_s / 2``
keeps ``m`` in between; a pair of spheres needs ``m + (l_a + l_b) / 2``. A clearance
``< m`` at a substep is a proven violation; one between the two is *uncertain*, and the
segment is checked again with 4 times the substeps, up to ``levels`` times; a segment still
uncertain then is reported as such (not feasible).

Result codes per segment and per path: :data:`OK` 0, :data:`WORLD` 1 (sphere ``a`` vs
object ``b``; -2 the grid), :data:`SELF` 2 (spheres ``a`` and ``b``), :data:`UNCERTIFIED` 3
(sphere ``a``, object/sphere ``b``), :data:`LIMITS` 4 (waypoint outside the limits).
"""

import functools
from types import SimpleNamespace

import warp as wp

from jwarp.kernels import collision as collision_kernels
from jwarp.kernels import fk as fk_kernels
from jwarp.kernels import path as path_kernels

OK = wp.constant(0)
WORLD = wp.constant(1)
SELF = wp.constant(2)
UNCERTIFIED = wp.constant(3)
LIMITS = wp.constant(4)

#: names of the result codes
CODE_NAMES = ("ok", "world collision", "self collision", "uncertified", "joint limits")


@functools.cache
def kernels(path_scalar: type) -> SimpleNamespace:
    """Check kernels for paths stored in ``path_scalar`` (float32/float64); every check
    computes in float64."""
    f64 = wp.float64
    fk = fk_kernels.kernels(f64)
    ck = collision_kernels.kernels(f64)
    pk = path_kernels.kernels(f64)
    vec3, mat44 = fk.vec3, fk.mat44
    zero = f64(0.0)
    half = f64(0.5)
    one = f64(1.0)

    @wp.struct
    class CheckModel:
        """Everything the check reads besides the paths (one kernel argument)."""

        model: fk.FrameTables
        rho: wp.array3d(dtype=f64)
        spheres: ck.SphereTables
        world: ck.WorldModel
        use_world: int
        use_self: int
        reach: wp.array2d(dtype=f64)
        limits: wp.array2d(dtype=f64)
        lin_start: wp.array(dtype=wp.int32)
        lin_joint: wp.array(dtype=wp.int32)
        lin_coef: wp.array(dtype=f64)
        lin_bounds: wp.array2d(dtype=f64)
        limit_tol: f64

    @wp.struct
    class CheckScratch:
        """Per-thread rows (threads, m): q, dq (n_dof), dtheta (n_frames), travel (S),
        frames (n_frames), xs (S). On the CPU stride-0 views of one row."""

        q: wp.array2d(dtype=f64)
        dq: wp.array2d(dtype=f64)
        dth: wp.array2d(dtype=f64)
        travel: wp.array2d(dtype=f64)
        frames: wp.array2d(dtype=mat44)
        xs: wp.array2d(dtype=vec3)

    @wp.func
    def clearances(cm: CheckModel, sc: CheckScratch, r: int, m_req: f64, inv_n: f64):
        """FK of sc.q[r] and the clearances of its spheres: (code, a, b, d) of the first
        violation (code WORLD/SELF), else (UNCERTIFIED, a, b, d) of the first uncertain
        sphere/pair, else (OK, -1, -1, 0)."""
        model = cm.model
        spheres = cm.spheres
        nf = model.order.shape[0]
        for kk in range(nf):
            fk.write_frame(model, r, model.order[kk], sc.q, cm.rho, 0, fk_kernels.ROWS_NOMINAL,
                           sc.frames, r)
        unc = int(0)
        ua = int(-1)
        ub = int(-1)
        ud = zero
        lmax = zero
        for s in range(spheres.sph_frame.shape[0]):
            x = ck.sphere_centre(sc.frames, r, spheres.sph_frame[s], spheres.sph_pos[s])
            sc.xs[r, s] = x
            l = sc.travel[r, s] * inv_n
            lmax = wp.max(lmax, l)
            if cm.use_world != 0:
                rs = spheres.sph_rad[s]
                band = m_req + half * l
                d, g, obj = ck.world_distance(cm.world, x, rs + band + f64(1e-9))
                if obj != -1:
                    dd = d - rs
                    if dd < m_req:
                        return WORLD, s, obj, dd
                    if dd < band and unc == 0:
                        unc = 1
                        ua = s
                        ub = obj
                        ud = dd
        if cm.use_self != 0:
            for fp in range(spheres.fpair_a.shape[0]):
                fa = spheres.fpair_a[fp]
                fb = spheres.fpair_b[fp]
                ca = ck.sphere_centre(sc.frames, r, fa, spheres.bound_pos[fa])
                cb = ck.sphere_centre(sc.frames, r, fb, spheres.bound_pos[fb])
                if wp.length(ca - cb) - spheres.bound_rad[fa] - spheres.bound_rad[fb] \
                        < m_req + lmax + f64(1e-9):
                    for e in range(spheres.fpair_start[fp], spheres.fpair_start[fp + 1]):
                        sa = spheres.ent_sphere[e]
                        xa = sc.xs[r, sa]
                        ra = spheres.sph_rad[sa]
                        la = sc.travel[r, sa] * inv_n
                        for p in range(spheres.ent_start[e], spheres.ent_start[e + 1]):
                            sb = spheres.pair_b[p]
                            dd = wp.length(xa - sc.xs[r, sb]) - ra - spheres.sph_rad[sb]
                            if dd < m_req:
                                return SELF, sa, sb, dd
                            if dd < m_req + half * (la + sc.travel[r, sb] * inv_n) and unc == 0:
                                unc = 1
                                ua = sa
                                ub = sb
                                ud = dd
        if unc != 0:
            return UNCERTIFIED, ua, ub, ud
        return OK, -1, -1, zero

    @wp.kernel(module="unique", enable_backward=False)
    def segment_kernel(
        # Data in:
        paths: wp.array3d(dtype=path_scalar),
        idx: wp.array(dtype=wp.int32),
        margin: f64,
        end_margin: f64,
        delta: f64,
        max_sub: int,
        levels: int,
        # Model:
        cm: CheckModel,
        # Scratch:
        sc: CheckScratch,
        # Data out:
        seg_code: wp.array2d(dtype=wp.int32),
        seg_u: wp.array2d(dtype=f64),
        seg_a: wp.array2d(dtype=wp.int32),
        seg_b: wp.array2d(dtype=wp.int32),
        seg_d: wp.array2d(dtype=f64),
        seg_n: wp.array2d(dtype=wp.int32),
    ):
        """Segment t of path idx[k] (launch dim (K, W - 1)): its result code, where
        (fraction u of the segment), what (a, b), the clearance d [m] and the substeps n
        of the last level."""
        k, t = wp.tid()
        W = paths.shape[1]
        n_dof = paths.shape[2]
        r = k * (W - 1) + t
        p = idx[k]
        model = cm.model
        # waypoints within the limits (the last segment also checks the goal)
        last = t + 1
        if t < W - 2:
            last = t
        for wi in range(t, last + 1):
            for j in range(n_dof):
                sc.q[r, j] = f64(paths[p, wi, j])
            if pk.within_limits_row(sc.q, r, cm.limits, cm.lin_start, cm.lin_joint,
                                    cm.lin_coef, cm.lin_bounds, cm.limit_tol) == 0:
                seg_code[k, t] = LIMITS
                seg_u[k, t] = f64(wi - t)
                seg_a[k, t] = -1
                seg_b[k, t] = -1
                seg_d[k, t] = zero
                seg_n[k, t] = 0
                return
        for j in range(n_dof):
            sc.dq[r, j] = f64(paths[p, t + 1, j]) - f64(paths[p, t, j])
        nf = model.order.shape[0]
        for i in range(nf):
            v = zero
            for c in range(model.cpl_start[i], model.cpl_start[i + 1]):
                v += model.cpl_coef[c] * sc.dq[r, model.cpl_joint[c]]
            sc.dth[r, i] = wp.abs(v)
        lmax = zero
        for s in range(cm.reach.shape[0]):
            l = zero
            for i in range(nf):
                l += sc.dth[r, i] * cm.reach[s, i]
            sc.travel[r, s] = l
            lmax = wp.max(lmax, l)
        m_req = margin
        if t == 0 or t == W - 2:
            m_req = wp.min(margin, end_margin)
        n = wp.clamp(int(wp.ceil(lmax / delta)), 1, max_sub)
        code = int(OK)
        cu = zero
        ca = int(-1)
        cb = int(-1)
        cd = zero
        for lev in range(levels):
            inv_n = one / f64(n)
            code = OK
            unc = int(0)
            for kk in range(n + 1):
                u = f64(kk) * inv_n
                for j in range(n_dof):
                    if kk == n:
                        sc.q[r, j] = f64(paths[p, t + 1, j])
                    else:
                        sc.q[r, j] = f64(paths[p, t, j]) + u * sc.dq[r, j]
                c, a, b, d = clearances(cm, sc, r, m_req, inv_n)
                if c == WORLD or c == SELF:
                    code = c
                    cu = u
                    ca = a
                    cb = b
                    cd = d
                    break
                if c == UNCERTIFIED and unc == 0:
                    unc = 1
                    cu = u
                    ca = a
                    cb = b
                    cd = d
            if code != OK:
                break
            if unc == 0:
                break
            code = UNCERTIFIED
            if lev < levels - 1:
                n = n * 4
        seg_code[k, t] = code
        seg_u[k, t] = cu
        seg_a[k, t] = ca
        seg_b[k, t] = cb
        seg_d[k, t] = cd
        seg_n[k, t] = n

    @wp.kernel(module="unique", enable_backward=False)
    def reduce_kernel(
        # Data in:
        seg_code: wp.array2d(dtype=wp.int32),
        seg_u: wp.array2d(dtype=f64),
        seg_a: wp.array2d(dtype=wp.int32),
        seg_b: wp.array2d(dtype=wp.int32),
        seg_d: wp.array2d(dtype=f64),
        # Data out:
        ok: wp.array(dtype=wp.int32),
        code: wp.array(dtype=wp.int32),
        where: wp.array(dtype=f64),
        what: wp.array2d(dtype=wp.int32),
        dist: wp.array(dtype=f64),
    ):
        """Per path k (launch dim K): the first failing segment's result (``where`` in
        waypoint units, t + u), ok = 1 if none failed."""
        k = wp.tid()
        ok[k] = 1
        code[k] = OK
        where[k] = zero
        what[k, 0] = -1
        what[k, 1] = -1
        dist[k] = zero
        for t in range(seg_code.shape[1]):
            c = seg_code[k, t]
            if c != OK:
                ok[k] = 0
                code[k] = c
                where[k] = f64(t) + seg_u[k, t]
                what[k, 0] = seg_a[k, t]
                what[k, 1] = seg_b[k, t]
                dist[k] = seg_d[k, t]
                return

    return SimpleNamespace(CheckModel=CheckModel, CheckScratch=CheckScratch,
                           clearances=clearances, segment=segment_kernel, reduce=reduce_kernel,
                           fk=fk, ck=ck)
