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
host: :func:`jwarp.world.motion.sphere_reach`). Along a segment q(u) = q_t + u dq, a sphere
with clearance ``d_s`` at u therefore keeps ``>= m`` for every u' with
``|u' - u| L_s <= d_s - m``; a pair of spheres likewise with their relative travel, which
only the joints below their frames' common ancestor cause
(:func:`jwarp.world.motion.pair_travel_tables`). The check is
*conservative advancement*: from u = 0, each evaluation (FK, exact world distances,
self pairs) proves the motion up to ``u + min_s (d_s - m) / L_s`` and the next evaluation
starts there, until u = 1. A clearance ``< m`` is a proven violation; a step below
``min_step`` (the motion grazes the margin) or too many evaluations is *uncertified* (not
feasible). Far from obstacles a few evaluations prove a whole segment.

The same bound proves an interval from its midpoint: an evaluation at u_m with every
clearance ``d_s >= m + w L_s`` (pairs likewise) proves [u_m - w, u_m + w]. The *levels*
(:func:`level_kernel`, the GPU's default; the host: :class:`jwarp.world.motion.MotionCheck`)
split every segment into n0 intervals (level 0) and evaluate every interval of a level in
parallel, at its midpoint with ``reach`` = its half width: a clearance below the margin is
a proven violation, a step >= the half width proves the interval, a step below
``min_step`` leaves the segment uncertified (as the advancement does); of any other
interval the two parts the step does not prove, [u0, u_m - step] and [u_m + step, u1]
(each at most half of it: the widths at least halve per level), are appended to the next
level's work list (compacted with an atomic counter; a fixed capacity). A segment is
proven when all its intervals are. What
the levels leave (the capacity, the level cap) goes on with the advancement from its
proven prefix, or is uncertified: nothing is proven that the bound does not prove.

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
#: a segment not finished because another segment of its path failed first
SKIPPED = wp.constant(5)
#: uncertified where the motion grazes the self-collision margin (spheres a, b)
UNCERTIFIED_SELF = wp.constant(6)
#: internal: proven step limited by a self pair
OK_SELF_LIMITED = wp.constant(7)

#: names of the result codes
CODE_NAMES = ("ok", "world collision", "self collision", "uncertified", "joint limits",
              "skipped", "uncertified (self)")


@functools.cache
def funcs() -> SimpleNamespace:
    """The structs and ``@wp.func`` helpers the check kernels share (every check computes in
    float64, whatever the paths' type); built once (issue 40 item 5: the kernels are built
    one each, by :func:`prep`, :func:`points`, :func:`cover`, :func:`segment`,
    :func:`level_init`, :func:`level`, :func:`level_end` and :func:`reduce`, from these;
    those that read the paths once per path type)."""
    f64 = wp.float64
    fk = fk_kernels.funcs(f64)
    ck = collision_kernels.funcs(f64)
    pk = path_kernels.funcs(f64)
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
        bound_skip: int
        reach: wp.array2d(dtype=f64)
        fp_start: wp.array(dtype=wp.int32)
        fp_frame: wp.array(dtype=wp.int32)
        fp_weight: wp.array(dtype=f64)
        limits: pk.LimitTables
        limit_tol: f64

    @wp.struct
    class CheckScratch:
        """Rows: per segment (K (W - 1), m) dq (n_dof), dtheta (n_frames), travel (S),
        fptravel (frame pairs); per evaluating thread q (n_dof), frames (n_frames), xs (S)
        (on the CPU stride-0 views of one row)."""

        q: wp.array2d(dtype=f64)
        dq: wp.array2d(dtype=f64)
        dth: wp.array2d(dtype=f64)
        travel: wp.array2d(dtype=f64)
        fptravel: wp.array2d(dtype=f64)
        frames: wp.array2d(dtype=mat44)
        xs: wp.array2d(dtype=vec3)

    @wp.struct
    class Segments:
        """Per segment (K, W - 1) of a launch: result ``code``, where (``u``, a fraction of
        the segment), what (``a``, ``b``), the clearance ``d`` [m], the evaluations ``n``,
        and the proven prefix ``cov`` of the parallel rounds (of the levels: the start of
        the first interval they left unresolved, 1 if none); the levels' intervals not
        resolved yet ``left`` and the first result written (``claim``, 0: none)."""

        code: wp.array2d(dtype=wp.int32)
        u: wp.array2d(dtype=f64)
        a: wp.array2d(dtype=wp.int32)
        b: wp.array2d(dtype=wp.int32)
        d: wp.array2d(dtype=f64)
        n: wp.array2d(dtype=wp.int32)
        cov: wp.array2d(dtype=f64)
        left: wp.array2d(dtype=wp.int32)
        claim: wp.array2d(dtype=wp.int32)

    @wp.struct
    class Points:
        """Per parallel evaluation (K, W - 1, M): code, proven radius ``h`` (in u), what
        (``a``, ``b``) and clearance ``d``."""

        code: wp.array3d(dtype=wp.int32)
        h: wp.array3d(dtype=f64)
        a: wp.array3d(dtype=wp.int32)
        b: wp.array3d(dtype=wp.int32)
        d: wp.array3d(dtype=f64)

    @wp.func
    def point_u(c0: f64, j: int, M: int, dense: int) -> f64:
        """Point j of M over [c0, 1] (``dense``: denser near c0)."""
        f = (f64(j) + half) / f64(M)
        if dense != 0:
            f = f * f
        return c0 + (one - c0) * f

    @wp.func
    def advance(cm: CheckModel, sc: CheckScratch, r: int, rt: int, m_req: f64, m_self: f64,
                reach: f64, grp: int):
        """FK of sc.q[r] and how far the motion is proven from there: returns (code, a, b,
        d, step) with code WORLD/SELF (and the sphere(s)/object, clearance d) if a
        clearance is below ``m_req`` (world; ``m_self`` between the robot's own spheres)
        here, else OK and ``step`` = min over spheres of (clearance - required) / travel
        (pairs: / their relative travel), in units of the
        segment's parameter u, capped at ``reach`` (objects farther than the whole
        remaining motion are not visited); (a, b, d) then name the limiting pair. Rows:
        ``r`` of the evaluation scratch (q, frames, xs), ``rt`` of the segment's travel."""
        model = cm.model
        spheres = cm.spheres
        nf = model.order.shape[0]
        for kk in range(nf):
            fk.write_frame(model, r, model.order[kk], sc.q, cm.rho, 0, fk_kernels.ROWS_NOMINAL,
                           sc.frames, r)
        step = reach
        la = int(-1)
        lb = int(-1)
        ld = f64(1e30)
        lself = int(0)
        S = spheres.sph_frame.shape[0]
        cur = int(-1)  # the frame of the run of spheres whose bound was tested last
        near_n = int(-1)  # its objects (objects_near; -1: every sphere queries them all)
        near = ck.geometry.near_ids()
        for s in range(S):
            fr = spheres.sph_frame[s]
            x = ck.sphere_centre(sc.frames, r, fr, spheres.sph_pos[s])
            sc.xs[r, s] = x
            L = sc.travel[rt, s]
            if cm.use_world != 0:
                if cm.bound_skip != 0 and fr != cur:
                    # the objects within the largest cutoff of this run of the frame's
                    # spheres from its bounding sphere, in one query: the spheres look at
                    # those only (the same result with fewer queries; exact objects, no
                    # meshes)
                    cur = fr
                    near_n = -1
                    if spheres.bound_rad[fr] >= zero:
                        lf = zero
                        s2 = s
                        while s2 < S:
                            if spheres.sph_frame[s2] != fr:
                                break
                            lf = wp.max(lf, sc.travel[rt, s2])
                            s2 += 1
                        near_n, near = ck.objects_near(
                            cm.world, ck.sphere_centre(sc.frames, r, fr, spheres.bound_pos[fr]),
                            spheres.bound_rad[fr], m_req + lf * reach + f64(1e-9), grp)
                rs = spheres.sph_rad[s]
                d, g, obj = ck.world_distance_near(cm.world, x,
                                                   rs + m_req + L * reach + f64(1e-9), grp,
                                                   near_n, near)
                if obj != -1:
                    dd = d - rs
                    if dd < m_req:
                        return WORLD, s, obj, dd, zero
                    if L > zero:
                        h = (dd - m_req) / L
                        if h < step:
                            step = h
                            la = s
                            lb = obj
                            ld = dd
        if cm.use_self != 0:
            for fp in range(spheres.fpair_a.shape[0]):
                fa = spheres.fpair_a[fp]
                fb = spheres.fpair_b[fp]
                ca = ck.sphere_centre(sc.frames, r, fa, spheres.bound_pos[fa])
                cb = ck.sphere_centre(sc.frames, r, fb, spheres.bound_pos[fb])
                Lab = sc.fptravel[rt, fp]  # the pair's relative travel (module docstring)
                rfb = spheres.bound_rad[fb]
                if wp.length(ca - cb) - spheres.bound_rad[fa] - rfb \
                        < m_self + Lab * step + f64(1e-9):
                    for e in range(spheres.fpair_start[fp], spheres.fpair_start[fp + 1]):
                        sa = spheres.ent_sphere[e]
                        xa = sc.xs[r, sa]
                        ra = spheres.sph_rad[sa]
                        # frame b's bounding sphere encloses its spheres: a sphere of frame a
                        # that keeps the bound from it keeps it from each of them (the same
                        # code and step: no pair skipped here could lower the step)
                        if wp.length(xa - cb) - ra - rfb >= m_self + Lab * step + f64(1e-9):
                            continue
                        for p in range(spheres.ent_start[e], spheres.ent_start[e + 1]):
                            sb = spheres.pair_b[p]
                            dd = wp.length(xa - sc.xs[r, sb]) - ra - spheres.sph_rad[sb]
                            if dd < m_self:
                                return SELF, sa, sb, dd, zero
                            if Lab > zero:
                                h = (dd - m_self) / Lab
                                if h < step:
                                    step = h
                                    la = sa
                                    lb = sb
                                    ld = dd
                                    lself = 1
        if lself != 0:  # the limiting constraint is a self pair (for the report)
            return OK_SELF_LIMITED, la, lb, ld, step
        return OK, la, lb, ld, step

    @wp.func
    def required(margin: f64, end_margin: f64, self_margin: f64, t: int, W: int):
        """(world, self) clearance required on segment t of W - 1."""
        if t == 0 or t == W - 2:
            return wp.min(margin, end_margin), wp.min(self_margin, end_margin)
        return margin, self_margin

    @wp.func
    def claim_result(seg: Segments, k: int, t: int, code: int, u: f64, a: int, b: int,
                     d: f64):
        """Write the segment's result once: the first interval that decides it (a
        violation, or an unproven interval at the finest width) writes code, where and
        what; later ones leave it."""
        if wp.atomic_add(seg.claim, k, t, 1) == 0:
            seg.u[k, t] = u
            seg.a[k, t] = a
            seg.b[k, t] = b
            seg.d[k, t] = d
            seg.code[k, t] = code

    return SimpleNamespace(
        f64=f64, fk=fk, ck=ck, pk=pk, vec3=vec3, mat44=mat44, zero=zero, half=half, one=one,
        CheckModel=CheckModel, CheckScratch=CheckScratch, Segments=Segments, Points=Points,
        point_u=point_u, advance=advance, required=required, claim_result=claim_result,
    )


@functools.cache
def prep(path_scalar: type) -> wp.Kernel:
    """The segments' preparation kernel (limits, travel) for paths stored in
    ``path_scalar``."""
    sh = funcs()
    f64, fk, pk, zero = sh.f64, sh.fk, sh.pk, sh.zero
    CheckModel, CheckScratch, Segments = sh.CheckModel, sh.CheckScratch, sh.Segments

    @wp.kernel(module="unique", enable_backward=False)
    def prep_kernel(
        # Model:
        cm: CheckModel,
        # Data in:
        paths: wp.array3d(dtype=path_scalar),
        idx: wp.array(dtype=wp.int32),
        # Scratch:
        sc: CheckScratch,
        bad: wp.array(dtype=wp.int32),
        # Data out:
        seg: Segments,
    ):
        """Segment t of path idx[k] (launch dim (K, W - 1)): its waypoints within the limits
        (else code LIMITS), else code OK and the travel of every sphere and frame pair over
        the segment (segment row k (W - 1) + t)."""
        k, t = wp.tid()
        W = paths.shape[1]
        n_dof = paths.shape[2]
        r = k * (W - 1) + t
        p = idx[k]
        model = cm.model
        seg.code[k, t] = OK
        seg.cov[k, t] = zero
        seg.u[k, t] = zero
        seg.a[k, t] = -1
        seg.b[k, t] = -1
        seg.d[k, t] = zero
        seg.n[k, t] = 0
        # waypoints within the limits (the last segment also checks the goal)
        last = t + 1
        if t < W - 2:
            last = t
        for wi in range(t, last + 1):
            for j in range(n_dof):
                sc.dq[r, j] = f64(paths[p, wi, j])
            if pk.within_limits_row(sc.dq, r, cm.limits, cm.limit_tol) == 0:
                seg.code[k, t] = LIMITS
                seg.u[k, t] = f64(wi - t)
                bad[k] = 1
                return
        for j in range(n_dof):
            sc.dq[r, j] = f64(paths[p, t + 1, j]) - f64(paths[p, t, j])
        nf = model.order.shape[0]
        for i in range(nf):
            v = zero
            for c in range(model.cpl_start[i], model.cpl_start[i + 1]):
                v += model.cpl_coef[c] * sc.dq[r, model.cpl_joint[c]]
            sc.dth[r, i] = wp.abs(v) + fk.harmonic_travel(model, i, r, sc.dq)
        for s in range(cm.reach.shape[0]):  # travel of each centre over the whole segment
            l = zero
            for i in range(nf):
                l += sc.dth[r, i] * cm.reach[s, i]
            sc.travel[r, s] = l
        for fp in range(cm.fp_start.shape[0] - 1):  # relative travel of each frame pair
            l = zero
            for e in range(cm.fp_start[fp], cm.fp_start[fp + 1]):
                l += sc.dth[r, cm.fp_frame[e]] * cm.fp_weight[e]
            sc.fptravel[r, fp] = l

    return prep_kernel


@functools.cache
def points(path_scalar: type) -> wp.Kernel:
    """The parallel evaluations' kernel (a point round) for paths stored in
    ``path_scalar``."""
    sh = funcs()
    f64, one = sh.f64, sh.one
    CheckModel, CheckScratch = sh.CheckModel, sh.CheckScratch
    Segments, Points = sh.Segments, sh.Points
    point_u, advance, required = sh.point_u, sh.advance, sh.required

    @wp.kernel(module="unique", enable_backward=False)
    def point_kernel(
        # Model:
        cm: CheckModel,
        # Data in:
        paths: wp.array3d(dtype=path_scalar),
        idx: wp.array(dtype=wp.int32),
        margin: f64,
        end_margin: f64,
        self_margin: f64,
        world_group: int,
        seg: Segments,
        dense_start: int,
        # Scratch:
        sc: CheckScratch,
        # Data out:
        pts: Points,
    ):
        """The evaluations of a segment in parallel (GPU; launch dim (K, W - 1, M)): point j
        of the part not proven yet, [c, 1] with c = ``seg.cov`` (uniform, or with
        ``dense_start`` denser near c: u = c + (1 - c) ((j + 1/2) / M)^2), its code and
        proven radius h (in u) of :func:`advance`."""
        k, t, j = wp.tid()
        W = paths.shape[1]
        M = pts.code.shape[2]
        c0 = seg.cov[k, t]
        if seg.code[k, t] != OK or c0 >= one:
            pts.code[k, t, j] = SKIPPED
            return
        rt = k * (W - 1) + t
        r = rt * M + j
        p = idx[k]
        wg = int(-1)
        if world_group > 0:
            wg = p // world_group
        m_req, m_self = required(margin, end_margin, self_margin, t, W)
        u = point_u(c0, j, M, dense_start)
        for jj in range(paths.shape[2]):
            sc.q[r, jj] = f64(paths[p, t, jj]) + u * sc.dq[rt, jj]
        c, a, b, d, h = advance(cm, sc, r, rt, m_req, m_self, one, wg)
        pts.code[k, t, j] = c
        pts.h[k, t, j] = h
        pts.a[k, t, j] = a
        pts.b[k, t, j] = b
        pts.d[k, t, j] = d

    return point_kernel


@functools.cache
def cover() -> wp.Kernel:
    """The kernel that grows the proven prefix after a point round (reads no paths)."""
    sh = funcs()
    one, Segments, Points, point_u = sh.one, sh.Segments, sh.Points, sh.point_u

    @wp.kernel(module="unique", enable_backward=False)
    def cover_kernel(
        # Data in:
        pts: Points,
        dense_start: int,
        # Data in/out:
        bad: wp.array(dtype=wp.int32),
        seg: Segments,
    ):
        """After a :func:`point_kernel` round (launch dim (K, W - 1)): a point below the
        margin fails the segment there (proven); else the proven prefix [0, c] grows over
        the points whose intervals join it."""
        k, t = wp.tid()
        M = pts.code.shape[2]
        c0 = seg.cov[k, t]
        if seg.code[k, t] != OK or c0 >= one:
            return
        cov = c0
        gap = int(0)
        for j in range(M):
            uj = point_u(c0, j, M, dense_start)
            c = pts.code[k, t, j]
            seg.n[k, t] = seg.n[k, t] + 1
            if c == WORLD or c == SELF:
                seg.code[k, t] = c
                seg.u[k, t] = uj
                seg.a[k, t] = pts.a[k, t, j]
                seg.b[k, t] = pts.b[k, t, j]
                seg.d[k, t] = pts.d[k, t, j]
                bad[k] = 1
                return
            if gap == 0:
                if uj - pts.h[k, t, j] <= cov:
                    cov = wp.max(cov, uj + pts.h[k, t, j])
                else:
                    gap = 1
        seg.cov[k, t] = wp.min(cov, one)

    return cover_kernel


@functools.cache
def segment(path_scalar: type) -> wp.Kernel:
    """The conservative advancement kernel for paths stored in ``path_scalar``."""
    sh = funcs()
    f64, zero, one = sh.f64, sh.zero, sh.one
    CheckModel, CheckScratch, Segments = sh.CheckModel, sh.CheckScratch, sh.Segments
    advance, required = sh.advance, sh.required

    @wp.kernel(module="unique", enable_backward=False)
    def segment_kernel(
        # Model:
        cm: CheckModel,
        # Data in:
        paths: wp.array3d(dtype=path_scalar),
        idx: wp.array(dtype=wp.int32),
        margin: f64,
        end_margin: f64,
        self_margin: f64,
        min_step: f64,
        max_evals: int,
        probe_len: f64,
        group: int,
        world_group: int,
        use_points: int,
        # Scratch:
        sc: CheckScratch,
        bad: wp.array(dtype=wp.int32),
        ok_segments: wp.array(dtype=wp.int32),
        solved: wp.array(dtype=wp.int32),
        # Data in/out:
        seg: Segments,
    ):
        """Segment t of path idx[k] (launch dim (K, W - 1)) by conservative advancement:
        from u = 0, each evaluation proves the motion up to u + step (module docstring:
        every sphere moves at most ``travel * step``); the evaluations continue from
        there until u = 1 (OK), a clearance below the margin (WORLD/SELF), or a step
        below ``min_step`` or more than ``max_evals`` evaluations (UNCERTIFIED: the motion
        grazes the margin). Out: the code, where (u), what (a, b), the clearance d [m] and
        the number of evaluations. ``use_points``: 0 from u = 0 (a coarse probe pass
        first), 1 from ``seg.cov`` (the point rounds), 2 from ``seg.cov`` where the levels
        left the segment unresolved (a segment they decided, ``cov`` = 1, is left as it
        is)."""
        k, t = wp.tid()
        W = paths.shape[1]
        n_dof = paths.shape[2]
        r = k * (W - 1) + t
        p = idx[k]
        wg = int(-1)  # a batch of worlds: path p plans in world p // world_group
        if world_group > 0:
            wg = p // world_group
        g = int(-1)  # ``group`` > 0: paths p of one problem p // group need one feasible
        if use_points == 2 and seg.cov[k, t] >= one:
            return  # proven (and counted) by the levels (or failed there)
        if group > 0:
            g = p // group
            if solved[g] != 0:
                seg.code[k, t] = SKIPPED
                seg.n[k, t] = 0
                return
        if seg.code[k, t] != OK:  # outside the limits (prep_kernel)
            return
        rt = r  # the segment's travel row (prep_kernel); evaluations use row r too
        m_req, m_self = required(margin, end_margin, self_margin, t, W)
        code = int(OK)
        u = zero
        ca = int(-1)
        cb = int(-1)
        cd = zero
        n = int(0)
        lmax = zero
        for s in range(cm.reach.shape[0]):
            lmax = wp.max(lmax, sc.travel[rt, s])
        if use_points != 0:  # the parallel rounds or the levels proved [0, cov]
            u = seg.cov[k, t]
            n = seg.n[k, t]
        # a coarse pass first (one probe per ``probe_len`` of travel, at most 16): most
        # colliding segments show a clearance below the margin at one of them
        n_probe = wp.min(int(wp.ceil(lmax / probe_len)), 16)
        if use_points != 0:
            n_probe = 0
        for kp in range(1, n_probe):
            if bad[k] != 0:  # another segment of this path failed: nothing to prove
                break
            up = f64(kp) / f64(n_probe)
            for j in range(n_dof):
                sc.q[r, j] = f64(paths[p, t, j]) + up * sc.dq[r, j]
            c, a, b, d, step = advance(cm, sc, r, rt, m_req, m_self, zero, wg)
            n += 1
            if c != OK and c != OK_SELF_LIMITED:
                code = c
                u = up
                ca = a
                cb = b
                cd = d
                break
        while u < one and code == OK:
            if bad[k] != 0:
                code = SKIPPED
                break
            if g >= 0:
                if solved[g] != 0:
                    code = SKIPPED
                    break
            for j in range(n_dof):
                sc.q[r, j] = f64(paths[p, t, j]) + u * sc.dq[r, j]
            c, a, b, d, step = advance(cm, sc, r, rt, m_req, m_self, one - u, wg)
            n += 1
            if c != OK and c != OK_SELF_LIMITED:
                code = c
                ca = a
                cb = b
                cd = d
                break
            if step >= one - u:
                u = one
            elif step < min_step or n >= max_evals:
                # stalled against the margin: a probe a little ahead that is below it
                # proves a violation, else the segment stays unproven
                code = UNCERTIFIED
                if c == OK_SELF_LIMITED:
                    code = UNCERTIFIED_SELF
                ca = a
                cb = b
                cd = d
                probe = f64(1e-4)
                for _pr in range(3):
                    up = wp.min(u + probe, one)
                    for j in range(n_dof):
                        sc.q[r, j] = f64(paths[p, t, j]) + up * sc.dq[r, j]
                    c2, a2, b2, d2, s2 = advance(cm, sc, r, rt, m_req, m_self, one - up, wg)
                    n += 1
                    if c2 != OK and c2 != OK_SELF_LIMITED:
                        code = c2
                        u = up
                        ca = a2
                        cb = b2
                        cd = d2
                        break
                    probe = probe * f64(10.0)
                break
            else:
                u = u + step
        if code == OK:  # the goal of the segment itself (the advancement proved up to it)
            u = one
            if wp.atomic_add(ok_segments, k, 1) == W - 2 and g >= 0:
                solved[g] = 1  # the path's last segment proven: its problem is solved
        elif code != SKIPPED:
            bad[k] = 1
        seg.code[k, t] = code
        seg.u[k, t] = u
        seg.a[k, t] = ca
        seg.b[k, t] = cb
        seg.d[k, t] = cd
        seg.n[k, t] = n

    return segment_kernel


@functools.cache
def level_init() -> wp.Kernel:
    """The levels' level 0 kernel (reads no paths)."""
    sh = funcs()
    f64, one, Segments = sh.f64, sh.one, sh.Segments

    @wp.kernel(module="unique", enable_backward=False)
    def level_init_kernel(
        # Model:
        n0: int,
        # Data in:
        bad: wp.array(dtype=wp.int32),
        # Data in/out:
        count: wp.array(dtype=wp.int32),
        seg: Segments,
        # Data out:
        list_seg: wp.array(dtype=wp.int32),
        list_u0: wp.array(dtype=f64),
        list_u1: wp.array(dtype=f64),
    ):
        """Level 0 of the interval refinement (launch dim (K, W - 1), after
        :func:`prep_kernel`): segment t of path k, within the limits, is split into ``n0``
        equal intervals [j / n0, (j + 1) / n0], appended to the work list (``list_seg``:
        the segment row k (W - 1) + t, ``list_u0``, ``list_u1``: the interval's ends in
        the segment's parameter u; ``count[0]`` their number). An
        interval beyond the list's capacity is left to the sequential advancement
        (``seg.cov`` = its start). A segment of a path outside the limits is skipped."""
        k, t = wp.tid()
        W1 = seg.code.shape[1]
        if seg.code[k, t] != OK:
            return
        if bad[k] != 0:
            seg.code[k, t] = SKIPPED
            return
        seg.cov[k, t] = one
        seg.left[k, t] = n0
        seg.claim[k, t] = 0
        cap = list_seg.shape[0]
        base = wp.atomic_add(count, 0, n0)
        for j in range(n0):
            pos = base + j
            if pos < cap:
                list_seg[pos] = k * W1 + t
                list_u0[pos] = f64(j) / f64(n0)
                list_u1[pos] = f64(j + 1) / f64(n0)
            else:
                wp.atomic_min(seg.cov, k, t, f64(j) / f64(n0))

    return level_init_kernel


@functools.cache
def level(path_scalar: type) -> wp.Kernel:
    """The kernel of one level of the interval refinement for paths stored in
    ``path_scalar``."""
    sh = funcs()
    f64, zero, half = sh.f64, sh.zero, sh.half
    CheckModel, CheckScratch, Segments = sh.CheckModel, sh.CheckScratch, sh.Segments
    advance, required, claim_result = sh.advance, sh.required, sh.claim_result

    @wp.kernel(module="unique", enable_backward=False)
    def level_kernel(
        # Model:
        cm: CheckModel,
        # Data in:
        paths: wp.array3d(dtype=path_scalar),
        idx: wp.array(dtype=wp.int32),
        margin: f64,
        end_margin: f64,
        self_margin: f64,
        min_step: f64,
        group: int,
        world_group: int,
        level: int,
        last: int,
        list_seg: wp.array(dtype=wp.int32),
        list_u0: wp.array(dtype=f64),
        list_u1: wp.array(dtype=f64),
        # Scratch:
        sc: CheckScratch,
        # Data in/out:
        count: wp.array(dtype=wp.int32),
        bad: wp.array(dtype=wp.int32),
        ok_segments: wp.array(dtype=wp.int32),
        solved: wp.array(dtype=wp.int32),
        seg: Segments,
        # Data out:
        next_seg: wp.array(dtype=wp.int32),
        next_u0: wp.array(dtype=f64),
        next_u1: wp.array(dtype=f64),
    ):
        """One level of the interval refinement (launch dim: the list's capacity on a GPU,
        threads past ``count[level]`` return; its size on the CPU). Interval i of the list
        is [u0, u1] = [``list_u0[i]``, ``list_u1[i]``] of segment row r = ``list_seg[i]``.
        One :func:`advance` at its midpoint u_m with ``reach`` = its half width w (objects
        farther than the interval's whole motion are not visited; scratch row i):

        * a clearance below the margin: the segment fails there (WORLD/SELF, proven);
        * step >= w: the interval is proven (every sphere moves at most ``travel * w``
          from u_m); the segment's last one proves the segment (``ok_segments``,
          ``solved`` as :func:`segment_kernel`);
        * else, where step < ``min_step``: the segment is UNCERTIFIED there (the motion
          grazes the margin; an interval narrower than ``min_step`` is never split: it is
          proven or this); where ``last``: the interval is left to the sequential
          advancement (``seg.cov`` = min of its start); else the parts the evaluation does
          not prove, [u0, u_m - step] and [u_m + step, u1] (each at most half of it), are
          appended to the next level's list (``next_*``, counter ``count[level + 1]``; a
          part beyond the capacity is left like ``last``). The ends are rounded outwards
          (by 1e-15: what an interval leaves out is proven).

        A segment already decided, of a failed path (``bad``) or of a solved problem
        (``group``) is not evaluated further."""
        i = wp.tid()
        if i >= count[level] or i >= list_seg.shape[0]:
            return
        W = paths.shape[1]
        r = list_seg[i]
        k = r // (W - 1)
        t = r - k * (W - 1)
        if seg.code[k, t] != OK or bad[k] != 0:
            return
        p = idx[k]
        g = int(-1)
        if group > 0:
            g = p // group
            if solved[g] != 0:
                return
        wg = int(-1)
        if world_group > 0:
            wg = p // world_group
        m_req, m_self = required(margin, end_margin, self_margin, t, W)
        u0 = list_u0[i]
        u1 = list_u1[i]
        um = half * (u0 + u1)
        w = wp.max(um - u0, u1 - um) + f64(1e-15)  # covers [u0, u1] despite rounding
        for jj in range(paths.shape[2]):
            sc.q[i, jj] = f64(paths[p, t, jj]) + um * sc.dq[r, jj]
        c, a, b, d, step = advance(cm, sc, i, r, m_req, m_self, w, wg)
        wp.atomic_add(seg.n, k, t, 1)
        if c != OK and c != OK_SELF_LIMITED:  # below the margin here: proven
            claim_result(seg, k, t, c, um, a, b, d)
            bad[k] = 1
            return
        if step >= w:  # the interval is proven
            if wp.atomic_add(seg.left, k, t, -1) == 1:  # its segment's last one
                if wp.atomic_add(ok_segments, k, 1) == W - 2 and g >= 0:
                    solved[g] = 1
            return
        if step < min_step:  # stalled against the margin (as segment_kernel)
            code = int(UNCERTIFIED)
            if c == OK_SELF_LIMITED:
                code = UNCERTIFIED_SELF
            claim_result(seg, k, t, code, um, a, b, d)
            bad[k] = 1
            return
        if last != 0:
            wp.atomic_min(seg.cov, k, t, u0)
            return
        if seg.code[k, t] != OK or bad[k] != 0:  # decided meanwhile: no parts
            return
        # the parts not proven: [u0, um - s], [um + s, u1] with s = step less a guard, so
        # that the rounded ends lie within the proven [um - step, um + step]; an empty
        # part (its end before its start) lies within it whole
        sg = wp.max(step - f64(1e-15), zero)
        a_end = um - sg
        b_start = um + sg
        n_parts = int(0)
        if a_end > u0:
            n_parts += 1
        if u1 > b_start:
            n_parts += 1
        wp.atomic_add(seg.left, k, t, n_parts - 1)  # one interval out, its parts in
        cap = next_seg.shape[0]
        for h in range(2):
            lo = u0
            hi = a_end
            if h == 1:
                lo = b_start
                hi = u1
            if hi > lo:
                pos = wp.atomic_add(count, level + 1, 1)
                if pos < cap:
                    next_seg[pos] = r
                    next_u0[pos] = lo
                    next_u1[pos] = hi
                else:
                    wp.atomic_min(seg.cov, k, t, lo)

    return level_kernel


@functools.cache
def level_end() -> wp.Kernel:
    """The levels' end kernel (reads no paths)."""
    sh = funcs()
    zero, one, Segments = sh.zero, sh.one, sh.Segments

    @wp.kernel(module="unique", enable_backward=False)
    def level_end_kernel(
        # Model:
        group: int,
        fallback: int,
        # Data in:
        idx: wp.array(dtype=wp.int32),
        solved: wp.array(dtype=wp.int32),
        # Data in/out:
        bad: wp.array(dtype=wp.int32),
        count: wp.array(dtype=wp.int32),
        seg: Segments,
    ):
        """After the last level (launch dim (K, W - 1)): a segment whose intervals were all
        proven is OK (``cov`` = 1); one of a failed path or a solved problem is SKIPPED;
        one with intervals left unresolved (the capacity or the level cap) keeps code OK
        and its proven prefix [0, cov] for :func:`segment_kernel` (``fallback``; counted in
        the last entry of ``count``), or is UNCERTIFIED at ``cov`` (no fallback)."""
        k, t = wp.tid()
        if seg.code[k, t] != OK:
            return
        if seg.left[k, t] == 0:
            seg.u[k, t] = one
            seg.cov[k, t] = one
            return
        skip = bad[k]
        if group > 0:
            if solved[idx[k] // group] != 0:
                skip = 1
        if skip != 0:
            seg.code[k, t] = SKIPPED
            return
        if seg.cov[k, t] >= one:  # (unreachable: an unresolved interval lowers it)
            seg.cov[k, t] = zero
        if fallback != 0:
            wp.atomic_add(count, count.shape[0] - 1, 1)
            return
        seg.code[k, t] = UNCERTIFIED
        seg.u[k, t] = seg.cov[k, t]
        seg.a[k, t] = -1
        seg.b[k, t] = -1
        seg.d[k, t] = zero
        bad[k] = 1

    return level_end_kernel


@functools.cache
def reduce() -> wp.Kernel:
    """The per-path reduction kernel (reads no paths)."""
    sh = funcs()
    f64, zero, Segments = sh.f64, sh.zero, sh.Segments

    @wp.kernel(module="unique", enable_backward=False)
    def reduce_kernel(
        # Data in:
        seg: Segments,
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
        skipped = int(0)
        for t in range(seg.code.shape[1]):
            c = seg.code[k, t]
            if c == SKIPPED:
                skipped = 1
            if c != OK and c != SKIPPED:
                ok[k] = 0
                code[k] = c
                where[k] = f64(t) + seg.u[k, t]
                what[k, 0] = seg.a[k, t]
                what[k, 1] = seg.b[k, t]
                dist[k] = seg.d[k, t]
                return
        if skipped != 0:  # not failed, not proven either (its problem was solved)
            ok[k] = 0
            code[k] = SKIPPED

    return reduce_kernel


@functools.cache
def kernels(path_scalar: type) -> SimpleNamespace:
    """Check kernels for paths stored in ``path_scalar`` (float32/float64); every check
    computes in float64: :func:`funcs`' structs and functions and every kernel of the
    builders (a facade: the builders build only the kernel asked for)."""
    sh = funcs()
    return SimpleNamespace(Segments=sh.Segments, Points=sh.Points, prep=prep(path_scalar),
                           points=points(path_scalar), cover=cover(),
                           required=sh.required,
                           CheckModel=sh.CheckModel, CheckScratch=sh.CheckScratch,
                           advance=sh.advance, segment=segment(path_scalar), reduce=reduce(),
                           level_init=level_init(), level=level(path_scalar),
                           level_end=level_end(),
                           fk=sh.fk, ck=sh.ck)
