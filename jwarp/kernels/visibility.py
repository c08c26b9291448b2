"""Measurement-pose checks (thesis 2.4.3, elastic paper IV-C): limits, marker visibility
from fixed cameras with occlusion by the robot's spheres, self-collision with a margin.

Math only; the host side is :mod:`jwarp.calibration.design.poses`. Built per scalar type
by :func:`kernels` (float32 or float64); one thread per candidate configuration.

Sensor tables (:class:`Sensors`, part of the *Model*):

* cameras ``cam_pos`` (C,) vec3 [m] and ``cam_axis`` (C,) vec3 (unit optical axis) in the
  robot's base frame, ``cam_cos_fov`` (C,) cos of the half opening angle of the view cone,
  ``cam_near``/``cam_far`` (C,) [m] the range of distances it measures;
* markers ``mk_frame`` (M,) int32 (-1: fixed in the base frame), ``mk_pos`` (M,) vec3 [m]
  and ``mk_normal`` (M,) unit vec3, both in the coordinates of that frame;
* ``fs_start`` (n_frames + 1,) int32 CSR into ``fs_sphere`` (S,) int32: the collision
  spheres of each frame (the occlusion test's broad phase uses the frame's bounding sphere
  from :class:`jwarp.kernels.collision.SphereTables`).

Camera c sees marker m at world point x with world normal n when (:func:`sees`)

* ``near <= |x - o_c| <= far`` (range),
* ``axis_c . (x - o_c) >= cos_fov |x - o_c|`` (inside the view cone),
* ``n . (o_c - x) >= cos_max_angle |x - o_c|`` (the marker faces the camera),
* no collision sphere meets the segment o_c -> x (closest point of the segment to the
  centre closer than the radius), except the spheres that hold the marker itself (centre
  closer than ``radius + contain_tol`` to x: the body it is mounted on; whether it faces
  away is the facing test's job).

A marker is *seen* when at least ``k_of_n`` cameras see it; *visible* when one does. The
visibility verdict: at least one marker seen (``need_all`` = 0) or every marker seen (1);
with ``single_marker`` exactly one marker is visible to any camera at all. Self-collision:
an allowed sphere pair (:func:`jwarp.world.collision.collision_pairs`) closer than
``margin`` [m] (surface distance), frame pairs flagged in ``skip_fpair`` left out.

Codes (:data:`OK` ... :data:`SELF_COLLISION`): the first failed check in the order
limits, visibility, single marker, self-collision (cheap tests first).
"""

import functools
from types import SimpleNamespace

import warp as wp

from jwarp.kernels.collision import funcs as collision_funcs
from jwarp.kernels.fk import ROWS_NOMINAL
from jwarp.kernels.fk import funcs as fk_funcs
from jwarp.kernels.path import kernels as path_kernels

#: verdicts written to ``code``
OK = wp.constant(0)
LIMITS = wp.constant(1)
NOT_SEEN = wp.constant(2)
MANY_MARKERS = wp.constant(3)
SELF_COLLISION = wp.constant(4)
#: number of codes (the ``counts`` table's width)
N_CODES = 5
#: rows of the ``counts`` table (threads add to row tid % COUNT_ROWS: less contention)
COUNT_ROWS = 64


@functools.cache
def kernels(scalar: type) -> SimpleNamespace:
    """Pose-check kernels and functions for one scalar type (``wp.float32``/``wp.float64``)."""
    fk = fk_funcs(scalar)
    ck = collision_funcs(scalar)
    pk = path_kernels(scalar)
    vec3, mat44 = fk.vec3, fk.mat44
    zero = scalar(0.0)
    one = scalar(1.0)

    @wp.struct
    class Sensors:
        """Cameras, markers and the per-frame sphere lists (module docstring)."""

        cam_pos: wp.array(dtype=vec3)
        cam_axis: wp.array(dtype=vec3)
        cam_cos_fov: wp.array(dtype=scalar)
        cam_near: wp.array(dtype=scalar)
        cam_far: wp.array(dtype=scalar)
        mk_frame: wp.array(dtype=wp.int32)
        mk_pos: wp.array(dtype=vec3)
        mk_normal: wp.array(dtype=vec3)
        fs_start: wp.array(dtype=wp.int32)
        fs_sphere: wp.array(dtype=wp.int32)

    @wp.struct
    class Checks:
        """What to check: ``n_cameras``/``n_markers`` (0 cameras: no visibility test),
        ``k_of_n``, ``cos_max_angle`` (-2: no facing test), ``need_all``,
        ``single_marker``, ``check_self``, ``margin`` [m], ``contain_tol`` [m]."""

        n_cameras: int
        n_markers: int
        k_of_n: int
        cos_max_angle: scalar
        need_all: int
        single_marker: int
        check_self: int
        margin: scalar
        contain_tol: scalar

    @wp.func
    def segment_hits_sphere(a: vec3, x: vec3, c: vec3, r: scalar) -> int:
        """1 if the segment a -> x comes closer than r to the centre c."""
        d = x - a
        dd = wp.dot(d, d)
        t = zero
        if dd > zero:
            t = wp.clamp(wp.dot(c - a, d) / dd, zero, one)
        e = a + t * d - c
        if wp.dot(e, e) < r * r:
            return 1
        return 0

    @wp.func
    def occluded(frames: wp.array2d(dtype=mat44), t: int, spheres: ck.SphereTables,
                 sensors: Sensors, xs: wp.array2d(dtype=vec3), a: vec3, x: vec3,
                 tol: scalar) -> int:
        """1 if a sphere (not holding x) meets the segment a -> x (broad phase: the frames'
        bounding spheres)."""
        nf = sensors.fs_start.shape[0] - 1
        for f in range(nf):
            rb = spheres.bound_rad[f]
            if rb >= zero:
                cb = ck.sphere_centre(frames, t, f, spheres.bound_pos[f])
                if segment_hits_sphere(a, x, cb, rb) != 0:
                    for k in range(sensors.fs_start[f], sensors.fs_start[f + 1]):
                        s = sensors.fs_sphere[k]
                        c = xs[t, s]
                        r = spheres.sph_rad[s]
                        hold = r + tol
                        if wp.length_sq(x - c) >= hold * hold:
                            if segment_hits_sphere(a, x, c, r) != 0:
                                return 1
        return 0

    @wp.func
    def self_collides(frames: wp.array2d(dtype=mat44), t: int, spheres: ck.SphereTables,
                      xs: wp.array2d(dtype=vec3), skip_fpair: wp.array(dtype=wp.int32),
                      margin: scalar) -> int:
        """1 if an allowed sphere pair keeps less than ``margin`` between its surfaces
        (early exit; the bounding spheres cull frame pairs and spheres)."""
        for fp in range(spheres.fpair_a.shape[0]):
            if skip_fpair[fp] == 0:
                fa = spheres.fpair_a[fp]
                fb = spheres.fpair_b[fp]
                ca = ck.sphere_centre(frames, t, fa, spheres.bound_pos[fa])
                cb = ck.sphere_centre(frames, t, fb, spheres.bound_pos[fb])
                rb_m = spheres.bound_rad[fb] + margin
                reach = spheres.bound_rad[fa] + rb_m
                if wp.length_sq(ca - cb) < reach * reach:
                    for e in range(spheres.fpair_start[fp], spheres.fpair_start[fp + 1]):
                        sa = spheres.ent_sphere[e]
                        xa = xs[t, sa]
                        ra = spheres.sph_rad[sa]
                        ra_reach = ra + rb_m
                        if wp.length_sq(xa - cb) < ra_reach * ra_reach:
                            for p in range(spheres.ent_start[e], spheres.ent_start[e + 1]):
                                sb = spheres.pair_b[p]
                                lim = ra + spheres.sph_rad[sb] + margin
                                if wp.length_sq(xa - xs[t, sb]) < lim * lim:
                                    return 1
        return 0

    @wp.func
    def marker_world(frames: wp.array2d(dtype=mat44), t: int, sensors: Sensors, m: int):
        """World position and unit normal of marker m."""
        f = sensors.mk_frame[m]
        x = sensors.mk_pos[m]
        n = sensors.mk_normal[m]
        if f >= 0:
            T = frames[t, f]
            R = fk.unpack_rot(T)
            x = R * x + fk.unpack_pos(T)
            n = R * n
        return x, n

    @wp.func
    def in_view(sensors: Sensors, checks: Checks, c: int, x: vec3, n: vec3) -> int:
        """1 if marker point x (normal n) is in range, in the view cone of camera c and
        faces it (the tests before the occlusion test)."""
        v = x - sensors.cam_pos[c]
        dist = wp.length(v)
        if dist < sensors.cam_near[c] or dist > sensors.cam_far[c]:
            return 0
        if wp.dot(sensors.cam_axis[c], v) < sensors.cam_cos_fov[c] * dist:
            return 0
        if -wp.dot(n, v) < checks.cos_max_angle * dist:
            return 0
        return 1

    @wp.func
    def check_row(q: wp.array2d(dtype=scalar), b: int, model: fk.FrameTables,
                  spheres: ck.SphereTables, limits: pk.LimitTables, sensors: Sensors, checks: Checks, skip_fpair: wp.array(dtype=wp.int32),
                  rho: wp.array3d(dtype=scalar), frames: wp.array2d(dtype=mat44),
                  xs: wp.array2d(dtype=vec3), t: int, seen: wp.array2d(dtype=wp.int32),
                  write_seen: int) -> int:
        """The verdict code of configuration q[b] (scratch row t of frames and xs);
        ``seen[b, m]`` = cameras that see marker m when ``write_seen`` (0 after a limit
        violation)."""
        if write_seen != 0:
            for m in range(checks.n_markers):
                seen[b, m] = 0
        if pk.within_limits_row(q, b, limits, zero) == 0:
            return LIMITS
        nf = model.order.shape[0]
        for k in range(nf):
            fk.write_frame(model, b, model.order[k], q, rho, 0, ROWS_NOMINAL, frames, t)
        have_xs = int(0)
        if checks.n_cameras > 0:
            n_seen = int(0)
            n_visible = int(0)
            for m in range(checks.n_markers):
                x, n = marker_world(frames, t, sensors, m)
                cnt = int(0)
                for c in range(checks.n_cameras):
                    if in_view(sensors, checks, c, x, n) != 0:
                        if have_xs == 0:
                            for s in range(spheres.sph_frame.shape[0]):
                                xs[t, s] = ck.sphere_centre(frames, t, spheres.sph_frame[s],
                                                            spheres.sph_pos[s])
                            have_xs = 1
                        if occluded(frames, t, spheres, sensors, xs, sensors.cam_pos[c], x,
                                    checks.contain_tol) == 0:
                            cnt += 1
                if write_seen != 0:
                    seen[b, m] = cnt
                if cnt >= checks.k_of_n:
                    n_seen += 1
                if cnt > 0:
                    n_visible += 1
                if checks.need_all != 0 and cnt < checks.k_of_n and write_seen == 0:
                    return NOT_SEEN
            if n_seen == 0 or (checks.need_all != 0 and n_seen < checks.n_markers):
                return NOT_SEEN
            if checks.single_marker != 0 and n_visible > 1:
                return MANY_MARKERS
        if checks.check_self != 0:
            if have_xs == 0:
                for s in range(spheres.sph_frame.shape[0]):
                    xs[t, s] = ck.sphere_centre(frames, t, spheres.sph_frame[s],
                                                spheres.sph_pos[s])
            if self_collides(frames, t, spheres, xs, skip_fpair, checks.margin) != 0:
                return SELF_COLLISION
        return OK

    @wp.kernel(module="unique", enable_backward=False)
    def check_kernel(
        # Model:
        model: fk.FrameTables,
        spheres: ck.SphereTables,
        limits: pk.LimitTables,
        sensors: Sensors,
        skip_fpair: wp.array(dtype=wp.int32),
        rho0: wp.array3d(dtype=scalar),
        # Data in:
        q: wp.array2d(dtype=scalar),
        checks: Checks,
        # Scratch:
        frames: wp.array2d(dtype=mat44),
        xs: wp.array2d(dtype=vec3),
        # Data out:
        code: wp.array(dtype=wp.int32),
        seen: wp.array2d(dtype=wp.int32),
    ):
        """code[b] = verdict of q[b]; seen[b, m] = cameras seeing marker m (all markers
        evaluated, no early exit between markers)."""
        b = wp.tid()
        code[b] = check_row(q, b, model, spheres, limits, sensors, checks, skip_fpair, rho0,
                            frames, xs, b, seen, 1)

    @wp.kernel(module="unique", enable_backward=False)
    def sample_kernel(
        # Model:
        model: fk.FrameTables,
        spheres: ck.SphereTables,
        limits: pk.LimitTables,
        sensors: Sensors,
        skip_fpair: wp.array(dtype=wp.int32),
        rho0: wp.array3d(dtype=scalar),
        # Data in:
        seed: int,
        lower: wp.array(dtype=scalar),
        upper: wp.array(dtype=scalar),
        checks: Checks,
        # Scratch:
        qbuf: wp.array2d(dtype=scalar),
        frames: wp.array2d(dtype=mat44),
        xs: wp.array2d(dtype=vec3),
        dummy_seen: wp.array2d(dtype=wp.int32),
        # Data out:
        count: wp.array(dtype=wp.int32),
        out_q: wp.array2d(dtype=scalar),
        out_idx: wp.array(dtype=wp.int32),
        counts: wp.array2d(dtype=wp.int32),
    ):
        """Candidate b: q uniform in [lower, upper] (Warp's RNG, stream (seed, b)), checked
        (early exit); accepted ones are appended to out_q / out_idx (slot from ``count[0]``,
        in any order; slots past the capacity are counted but not written); counts[b % 64,
        code] += 1."""
        b = wp.tid()
        state = wp.rand_init(seed, b)
        for j in range(qbuf.shape[1]):
            qbuf[b, j] = lower[j] + scalar(wp.randf(state)) * (upper[j] - lower[j])
        c = check_row(qbuf, b, model, spheres, limits, sensors, checks, skip_fpair, rho0, frames,
                      xs, b, dummy_seen, 0)
        wp.atomic_add(counts, b % 64, c, 1)
        if c == OK:
            slot = wp.atomic_add(count, 0, 1)
            if slot < out_q.shape[0]:
                for j in range(qbuf.shape[1]):
                    out_q[slot, j] = qbuf[b, j]
                out_idx[slot] = b

    return SimpleNamespace(Sensors=Sensors, Checks=Checks, check=check_kernel,
                           sample=sample_kernel, segment_hits_sphere=segment_hits_sphere,
                           vec3=vec3, mat44=mat44)
