"""The collision cost at GPU width: the fused cost of :mod:`jwarp.kernels.collision` split
into four launches, each parallel over its widest index.

The fused ``cost`` kernel runs one thread per configuration: FK of every frame, every
sphere against the world and every self pair, in sequence. That suits the CPU (Warp runs
a launch's threads one after another there) but leaves a GPU with long, divergent threads.
Here (N configurations, S spheres, P_f frame pairs of the self-collision tables):

1. :data:`frames` (N,): FK into ``frames[t]``, the bounding-sphere centres ``bc[t]``,
   zeroed outputs, and the compensation torque update of the waypoint threads (it reads
   the frames only);
2. :data:`world` (S, N): sphere centre ``xs[t, s]`` and its world cost term; the term and
   its force ``f = w_world c'(d) dD/dx`` (and moment ``x x f``) are added atomically into
   ``cost[b]`` and the sphere's frame row of ``force``/``moment``;
3. :data:`self_pairs` (P_f, N): one frame pair (broad phase on the bounding spheres, then
   its sphere pairs), its cost and forces added atomically once per thread;
4. :data:`gradient` (N,): subtree sums of the forces and moments (leaves to root) and
   ``dU/dq`` through the couplings, as the fused kernel does.

The terms are those of the fused kernel; only the order of the sums differs (atomic adds),
so results agree to float rounding. Scratch (frames, xs, force, moment, bc) must hold a
real row per configuration (no stride-0 CPU views): the launches hand data to each other.
Thread t, configuration b and DH row follow :func:`jwarp.kernels.fk.waypoint_thread` as in
the fused kernel, and frozen rows (``active``) cost nothing.
"""

import functools
from types import SimpleNamespace

import warp as wp

from jwarp.kernels import collision as collision_kernels
from jwarp.kernels.elastic import funcs as elastic_funcs
from jwarp.kernels.fk import ROWS_NOMINAL
from jwarp.kernels.fk import funcs as fk_funcs


@functools.cache
def funcs(scalar: type) -> SimpleNamespace:
    """The ``@wp.func`` helpers the wide cost's kernels share, for one scalar type; built
    once per type (issue 40 item 5: the kernels are built one each, by :func:`frames`,
    :func:`world`, :func:`self_pairs` and :func:`gradient`, from these)."""
    fk = fk_funcs(scalar)
    el = elastic_funcs(scalar)
    ck = collision_kernels.funcs(scalar)
    vec3, mat44 = fk.vec3, fk.mat44
    zero = scalar(0.0)

    @wp.func
    def thread_rows(t: int, rows_kind: int, rho_layout: wp.vec4i, rho_stride: int):
        """(configuration b, its DH row offset, on_waypoint) of thread t (fused kernel's rule)."""
        if rows_kind == ROWS_NOMINAL:
            return t, 0, 0
        b, row, on_waypoint = fk.waypoint_thread(t, rho_layout)
        return b, rho_stride * row, on_waypoint

    @wp.func
    def frozen(b: int, active: wp.array(dtype=wp.int32), active_div: int) -> int:
        """1 where configuration b belongs to a frozen path (``active[b // active_div] == 0``)."""
        if active_div > 0:
            if active[b // active_div] == 0:
                return 1
        return 0

    return SimpleNamespace(
        scalar=scalar,
        fk=fk, el=el, ck=ck, vec3=vec3, mat44=mat44, zero=zero, thread_rows=thread_rows,
        frozen=frozen,
    )


@functools.cache
def frames(scalar: type) -> wp.Kernel:
    """The wide cost's FK kernel (launch 1), for ``scalar``."""
    sh = funcs(scalar)
    fk, el, ck, vec3, mat44, zero = sh.fk, sh.el, sh.ck, sh.vec3, sh.mat44, sh.zero
    thread_rows, frozen = sh.thread_rows, sh.frozen

    @wp.kernel(module="unique", enable_backward=False)
    def frames_kernel(
        # Model:
        model: fk.FrameTables,
        spheres: ck.SphereTables,
        # Data in:
        q: wp.array2d(dtype=scalar),
        rho: wp.array3d(dtype=scalar),
        rho_stride: int,
        rho_layout: wp.vec4i,
        rows_kind: int,
        want_grad: int,
        want_self: int,
        active: wp.array(dtype=wp.int32),
        active_div: int,
        # Scratch:
        frames: wp.array2d(dtype=mat44),
        force: wp.array2d(dtype=vec3),
        moment: wp.array2d(dtype=vec3),
        bc: wp.array2d(dtype=vec3),
        # Data out:
        cost: wp.array(dtype=scalar),
        grad: wp.array2d(dtype=scalar),
        comp: el.CompensationArgs,
    ):
        """Launch dim N: FK of thread t's configuration into ``frames[t]`` (n_frames mat44),
        bounding-sphere centres ``bc[t]`` (if ``want_self``), ``cost[b] = 0``, zero forces,
        moments and gradient row, and the waypoint threads' compensation update."""
        t = wp.tid()
        b, rb, on_waypoint = thread_rows(t, rows_kind, rho_layout, rho_stride)
        cost[b] = zero
        if want_grad != 0:
            for j in range(grad.shape[1]):
                grad[b, j] = zero
        if frozen(b, active, active_div) != 0:
            return
        nf = model.order.shape[0]
        for k in range(nf):
            i = model.order[k]
            fk.write_frame(model, b, i, q, rho, rb, rows_kind, frames, t)
            if want_grad != 0:
                force[t, i] = vec3(zero, zero, zero)
                moment[t, i] = vec3(zero, zero, zero)
        if want_self != 0:
            for i in range(nf):
                if spheres.bound_rad[i] >= zero:
                    bc[t, i] = ck.sphere_centre(frames, t, i, spheres.bound_pos[i])
        if comp.enabled != 0 and on_waypoint != 0:
            el.compensation_update_at(model, frames, t, rho, rb, comp)

    return frames_kernel


@functools.cache
def world(scalar: type) -> wp.Kernel:
    """The wide cost's world kernel (launch 2: spheres against the world), for
    ``scalar``."""
    sh = funcs(scalar)
    ck, vec3, mat44, zero, thread_rows = sh.ck, sh.vec3, sh.mat44, sh.zero, sh.thread_rows
    frozen = sh.frozen

    @wp.kernel(module="unique", enable_backward=False)
    def world_kernel(
        # Model:
        spheres: ck.SphereTables,
        world: ck.WorldModel,
        # Data in:
        rows_kind: int,
        rho_layout: wp.vec4i,
        w_world: scalar,
        eps: scalar,
        want_grad: int,
        group_div: int,
        active: wp.array(dtype=wp.int32),
        active_div: int,
        frames: wp.array2d(dtype=mat44),
        # Scratch:
        xs: wp.array2d(dtype=vec3),
        force: wp.array2d(dtype=vec3),
        moment: wp.array2d(dtype=vec3),
        # Data out:
        cost: wp.array(dtype=scalar),
    ):
        """Launch dim (S, N) (t fastest: a warp reads one sphere of consecutive
        configurations, coalesced in the frame-major CUDA scratch): centre ``xs[t, s]`` of sphere s and, with ``w_world``, its term
        ``w_world c(D(x) - r)`` added into ``cost[b]`` and its force/moment into its frame's
        row (atomic adds)."""
        s, t = wp.tid()
        b, rb, on_waypoint = thread_rows(t, rows_kind, rho_layout, 0)
        if frozen(b, active, active_div) != 0:
            return
        fr = spheres.sph_frame[s]
        x = ck.sphere_centre(frames, t, fr, spheres.sph_pos[s])
        xs[t, s] = x
        if w_world == zero:
            return
        grp = int(-1)
        if group_div > 0:
            grp = b // group_div
        rs = spheres.sph_rad[s]
        d, g, obj = ck.world_distance(world, x, rs + eps, grp)
        if obj != -1 and d - rs < eps:
            c, dc = ck.smooth_clip(d - rs, eps)
            wp.atomic_add(cost, b, w_world * c)
            if want_grad != 0 and dc != zero:
                f = (w_world * dc) * g
                wp.atomic_add(force, t, fr, f)
                wp.atomic_add(moment, t, fr, wp.cross(x, f))

    return world_kernel


@functools.cache
def self_pairs(scalar: type) -> wp.Kernel:
    """The wide cost's self-collision kernel (launch 3: frame pairs), for ``scalar``."""
    sh = funcs(scalar)
    ck, vec3, zero, thread_rows, frozen = sh.ck, sh.vec3, sh.zero, sh.thread_rows, sh.frozen

    @wp.kernel(module="unique", enable_backward=False)
    def self_kernel(
        # Model:
        spheres: ck.SphereTables,
        # Data in:
        rows_kind: int,
        rho_layout: wp.vec4i,
        w_self: scalar,
        eps: scalar,
        want_grad: int,
        active: wp.array(dtype=wp.int32),
        active_div: int,
        xs: wp.array2d(dtype=vec3),
        bc: wp.array2d(dtype=vec3),
        # Scratch:
        force: wp.array2d(dtype=vec3),
        moment: wp.array2d(dtype=vec3),
        # Data out:
        cost: wp.array(dtype=scalar),
    ):
        """Launch dim (P_f, N) (t fastest: a warp walks one frame pair's tables for
        consecutive configurations): frame pair fp of configuration t: the fused kernel's broad
        phase (bounding spheres, then each sphere of frame a against b's bound) and the
        terms ``w_self c(|x_a - x_b| - r_a - r_b)`` of its sphere pairs, summed in the
        thread and added once into ``cost[b]`` and the two frames' force/moment rows."""
        fp, t = wp.tid()
        b, rb, on_waypoint = thread_rows(t, rows_kind, rho_layout, 0)
        if frozen(b, active, active_div) != 0:
            return
        fa = spheres.fpair_a[fp]
        fb = spheres.fpair_b[fp]
        ca = bc[t, fa]
        cb = bc[t, fb]
        rb_eps = spheres.bound_rad[fb] + eps
        reach = spheres.bound_rad[fa] + rb_eps
        if wp.length_sq(ca - cb) >= reach * reach:
            return
        u = zero
        fa_f = vec3(zero, zero, zero)
        fa_m = vec3(zero, zero, zero)
        fb_f = vec3(zero, zero, zero)
        fb_m = vec3(zero, zero, zero)
        hit = int(0)
        for e in range(spheres.fpair_start[fp], spheres.fpair_start[fp + 1]):
            sa = spheres.ent_sphere[e]
            xa = xs[t, sa]
            ra = spheres.sph_rad[sa]
            ra_reach = ra + rb_eps
            if wp.length_sq(xa - cb) < ra_reach * ra_reach:
                for p in range(spheres.ent_start[e], spheres.ent_start[e + 1]):
                    sb = spheres.pair_b[p]
                    xb = xs[t, sb]
                    diff = xa - xb
                    rsum = ra + spheres.sph_rad[sb]
                    lim = rsum + eps
                    dsq = wp.length_sq(diff)
                    if dsq < lim * lim:
                        dist = wp.sqrt(dsq)
                        c, dc = ck.smooth_clip(dist - rsum, eps)
                        u += c
                        if want_grad != 0 and dist > zero:
                            f = (w_self * dc / dist) * diff
                            fa_f = fa_f + f
                            fa_m = fa_m + wp.cross(xa, f)
                            fb_f = fb_f - f
                            fb_m = fb_m - wp.cross(xb, f)
                            hit = 1
        if u != zero:
            wp.atomic_add(cost, b, w_self * u)
        if hit != 0:
            wp.atomic_add(force, t, fa, fa_f)
            wp.atomic_add(moment, t, fa, fa_m)
            wp.atomic_add(force, t, fb, fb_f)
            wp.atomic_add(moment, t, fb, fb_m)

    return self_kernel


@functools.cache
def gradient(scalar: type) -> wp.Kernel:
    """The wide cost's gradient kernel (launch 4), for ``scalar``."""
    sh = funcs(scalar)
    fk, ck, vec3, mat44, thread_rows = sh.fk, sh.ck, sh.vec3, sh.mat44, sh.thread_rows
    frozen = sh.frozen

    @wp.kernel(module="unique", enable_backward=False)
    def gradient_kernel(
        # Model:
        model: fk.FrameTables,
        # Data in:
        q: wp.array2d(dtype=scalar),
        rows_kind: int,
        rho_layout: wp.vec4i,
        active: wp.array(dtype=wp.int32),
        active_div: int,
        frames: wp.array2d(dtype=mat44),
        # Scratch:
        force: wp.array2d(dtype=vec3),
        moment: wp.array2d(dtype=vec3),
        # Data out:
        grad: wp.array2d(dtype=scalar),
    ):
        """Launch dim N: ``grad[b] = d cost / d q_b`` from the frames' force and moment
        sums (subtrees summed leaves to root; the fused kernel's projection)."""
        t = wp.tid()
        b, rb, on_waypoint = thread_rows(t, rows_kind, rho_layout, 0)
        if frozen(b, active, active_div) != 0:
            return
        ck.forces_to_gradient(model, frames, force, moment, t, b, q, grad)

    return gradient_kernel


@functools.cache
def kernels(scalar: type) -> SimpleNamespace:
    """The four launches of the wide cost for one scalar type (``wp.float32``/``wp.float64``)
    (a facade over the builders, which build only the kernel asked for)."""
    return SimpleNamespace(
        frames=frames(scalar), world=world(scalar), self_pairs=self_pairs(scalar),
        gradient=gradient(scalar), scalar=scalar,
    )
