"""Distance lower bounds between convex pieces by GJK (math only; host:
:mod:`jwarp.world.mesh_check`).

Built per scalar type by :func:`kernels` (float32 or float64). A *piece* is a sphere-swept
convex polytope: the convex hull of its vertices grown by ``radius`` (a sphere is one
vertex, a capsule two, a box eight, a URDF mesh its convex hull). A world object may also
be a *half-space* (a plane: the solid ``n . x <= offset``).

The certificate (:func:`gjk_lower`): GJK on the Minkowski difference ``D = A - B`` of two
hulls. Whatever direction ``v`` the iteration has reached, ``w = argmin_{d in D} v . d``
(one support query per hull) gives the separating-axis bound ``dist(A, B) >= v . w / |v|``,
which holds for *any* ``v``: the simplex sub-algorithm (Ericson's closest points on a
segment, triangle, tetrahedron) only makes ``v`` good, never the bound wrong. The best
bound over the iterations is returned, minus both radii and a rounding allowance ``slack``
[m] (the host sets it per scalar type). A bound <= 0 means "maybe touching": not certified.

Tables (the *Model*; ``vstart`` is CSR into ``verts``):

* robot pieces: ``frame`` (K,) int32, ``vstart`` (K + 1,), ``verts`` (V,) vec3 [m] in the
  frame's coordinates, ``rad`` (K,), ``centre`` (K,) vec3 and ``bound`` (K,): a sphere
  enclosing the piece with its radius (the broad phase);
* world objects: the same in world coordinates (``frame`` unused), ``kind`` (O,) int32
  (:data:`HULL`, :data:`HALFSPACE`: normal in ``centre``, offset in ``bound``), ``group``
  (O,) int32: the world of a batch it belongs to, and a box holding the vertices (the
  broad phase): ``rot`` (O,) mat33 its axes (columns), ``half`` (O,) vec3 its half
  extents about ``centre``;
* self pairs: ``pair_a``, ``pair_b`` (Q,) int32 robot piece indices.

Kernels (one thread per (configuration, piece, object) or (configuration, pair); the
frames ``X`` (N, n_frames) mat44 come from :func:`jwarp.kinematics.fk`):

* ``world_lower``: ``out[c, k] = min_o`` bound of piece ``k`` to object ``o`` (atomic min:
  the host fills ``out`` with a large value first); a pair whose piece's enclosing sphere
  keeps ``cap[c]`` (per configuration: what its caller needs) from the object's box is
  not refined (that distance is its bound), and GJK stops once its bound reaches
  ``cap[c]`` (a bound >= ``cap[c]`` says only that: enough). ``use_groups``: 0 every
  object counts; 1 only objects whose ``group`` is the configuration's ``cfg_group[c]``;
  2 the same for objects sorted by group, ``o_first`` (G + 1,) int32 the first object of
  each group: the launch's third dimension is then the largest group's object count, not
  every object of every world.
* ``self_lower``: ``out[c, q]`` the bound of pair ``q`` (likewise with the two pieces'
  enclosing spheres).
"""

import functools
from types import SimpleNamespace

import warp as wp

#: world object kinds
HULL = wp.constant(0)
HALFSPACE = wp.constant(1)
#: GJK iterations at most (a bound is kept from every one; polytopes of a few hundred
#: vertices converge to 1e-6 m in well under this)
MAX_ITER = wp.constant(48)


@functools.cache
def kernels(scalar: type) -> SimpleNamespace:
    """GJK functions and kernels for one scalar type (``wp.float32``/``wp.float64``)."""
    vec3 = wp.types.vector(3, scalar)
    mat44 = wp.types.matrix((4, 4), scalar)
    mat33 = wp.types.matrix((3, 3), scalar)
    zero = scalar(0.0)
    one = scalar(1.0)
    tiny = scalar(1e-20)
    big = scalar(1e30)

    @wp.func
    def rot_of(T: mat44) -> mat33:
        return mat33(T[0, 0], T[0, 1], T[0, 2], T[1, 0], T[1, 1], T[1, 2], T[2, 0], T[2, 1], T[2, 2])

    @wp.func
    def pos_of(T: mat44) -> vec3:
        return vec3(T[0, 3], T[1, 3], T[2, 3])

    @wp.func
    def support(verts: wp.array(dtype=vec3), s: int, e: int, R: mat33, t: vec3, u: vec3) -> vec3:
        """The vertex of ``R verts[s:e] + t`` farthest along ``u`` (world coordinates)."""
        ul = wp.transpose(R) * u
        best = verts[s]
        bd = wp.dot(ul, best)
        for i in range(s + 1, e):
            p = verts[i]
            d = wp.dot(ul, p)
            if d > bd:
                bd = d
                best = p
        return R * best + t

    @wp.func
    def closest_segment(a: vec3, b: vec3):
        """Closest point to the origin on segment ab and the vertices it uses (bits)."""
        ab = b - a
        den = wp.dot(ab, ab)
        tt = zero
        if den > tiny:
            tt = -wp.dot(a, ab) / den
        if tt <= zero:
            return a, 1
        if tt >= one:
            return b, 2
        return a + ab * tt, 3

    @wp.func
    def closest_triangle(a: vec3, b: vec3, c: vec3):
        """Closest point to the origin on triangle abc (Ericson 5.1.5) and its vertex bits."""
        ab = b - a
        ac = c - a
        ap = -a
        d1 = wp.dot(ab, ap)
        d2 = wp.dot(ac, ap)
        if d1 <= zero and d2 <= zero:
            return a, 1
        bp = -b
        d3 = wp.dot(ab, bp)
        d4 = wp.dot(ac, bp)
        if d3 >= zero and d4 <= d3:
            return b, 2
        vc = d1 * d4 - d3 * d2
        if vc <= zero and d1 >= zero and d3 <= zero:
            den = d1 - d3
            v = zero
            if den > tiny:
                v = d1 / den
            return a + ab * v, 3
        cp = -c
        d5 = wp.dot(ab, cp)
        d6 = wp.dot(ac, cp)
        if d6 >= zero and d5 <= d6:
            return c, 4
        vb = d5 * d2 - d1 * d6
        if vb <= zero and d2 >= zero and d6 <= zero:
            den = d2 - d6
            w = zero
            if den > tiny:
                w = d2 / den
            return a + ac * w, 5
        va = d3 * d6 - d5 * d4
        if va <= zero and (d4 - d3) >= zero and (d5 - d6) >= zero:
            den = (d4 - d3) + (d5 - d6)
            w = zero
            if den > tiny:
                w = (d4 - d3) / den
            return b + (c - b) * w, 6
        den = va + vb + vc
        if wp.abs(den) <= tiny:  # degenerate: the best edge
            p0, m0 = closest_segment(a, b)
            p1, m1 = closest_segment(a, c)
            p2, m2 = closest_segment(b, c)
            best = p0
            mb = m0
            if wp.dot(p1, p1) < wp.dot(best, best):
                best = p1
                mb = (m1 & 1) | ((m1 & 2) << 1)
            if wp.dot(p2, p2) < wp.dot(best, best):
                best = p2
                mb = m2 << 1
            return best, mb
        inv = one / den
        v = vb * inv
        w = vc * inv
        return a + ab * v + ac * w, 7

    @wp.func
    def outside(a: vec3, b: vec3, c: vec3, d: vec3) -> bool:
        """True unless the origin and d are strictly on the same side of plane abc (a
        flat tetrahedron counts every face as outside)."""
        n = wp.cross(b - a, c - a)
        sp = -wp.dot(a, n)
        sd = wp.dot(d - a, n)
        return sp * sd <= zero

    @wp.func
    def remap3(m: int, i0: int, i1: int, i2: int) -> int:
        """Triangle bits (of its vertices 0, 1, 2) as tetrahedron bits of i0, i1, i2."""
        out = 0
        if (m & 1) != 0:
            out = out | (1 << i0)
        if (m & 2) != 0:
            out = out | (1 << i1)
        if (m & 4) != 0:
            out = out | (1 << i2)
        return out

    @wp.func
    def closest_tetra(a: vec3, b: vec3, c: vec3, d: vec3):
        """Closest point to the origin on tetrahedron abcd and its vertex bits (15 and the
        origin when it lies inside)."""
        best = vec3(zero, zero, zero)
        bd = big
        mb = 15
        if outside(a, b, c, d):
            p, m = closest_triangle(a, b, c)
            if wp.dot(p, p) < bd:
                bd = wp.dot(p, p)
                best = p
                mb = remap3(m, 0, 1, 2)
        if outside(a, c, d, b):
            p, m = closest_triangle(a, c, d)
            if wp.dot(p, p) < bd:
                bd = wp.dot(p, p)
                best = p
                mb = remap3(m, 0, 2, 3)
        if outside(a, d, b, c):
            p, m = closest_triangle(a, d, b)
            if wp.dot(p, p) < bd:
                bd = wp.dot(p, p)
                best = p
                mb = remap3(m, 0, 3, 1)
        if outside(b, d, c, a):
            p, m = closest_triangle(b, d, c)
            if wp.dot(p, p) < bd:
                bd = wp.dot(p, p)
                best = p
                mb = remap3(m, 1, 3, 2)
        return best, mb

    @wp.func
    def gjk_lower(va: wp.array(dtype=vec3), sa: int, ea: int, Ra: mat33, ta: vec3,
                  vb: wp.array(dtype=vec3), sb: int, eb: int, Rb: mat33, tb: vec3,
                  tol: scalar, enough: scalar) -> scalar:
        """A lower bound [m] of the distance between the hulls ``Ra va[sa:ea] + ta`` and
        ``Rb vb[sb:eb] + tb`` (module docstring; <= 0: maybe overlapping). Stops when the
        bound is within ``tol`` of the current distance estimate, or once it reaches
        ``enough`` (the caller needs no more)."""
        u0 = vec3(one, zero, zero)
        v = support(va, sa, ea, Ra, ta, u0) - support(vb, sb, eb, Rb, tb, -u0)
        p0 = v
        p1 = v
        p2 = v
        p3 = v
        n = int(1)
        lb = scalar(-big)
        for _it in range(MAX_ITER):
            vv = wp.dot(v, v)
            if vv <= tiny:
                break
            nv = wp.sqrt(vv)
            w = support(va, sa, ea, Ra, ta, -v) - support(vb, sb, eb, Rb, tb, v)
            lb = wp.max(lb, wp.dot(v, w) / nv)
            if nv - lb <= tol or lb >= enough:
                break
            # the simplex with w, its closest point to the origin, the vertices kept
            if n == 1:
                p1 = w
                v, m = closest_segment(p0, p1)
                q0 = p0
                q1 = p1
                n = int(0)
                if (m & 1) != 0:
                    p0 = q0
                    n = 1
                if (m & 2) != 0:
                    if n == 0:
                        p0 = q1
                    else:
                        p1 = q1
                    n = n + 1
            elif n == 2:
                p2 = w
                v, m = closest_triangle(p0, p1, p2)
                q0 = p0
                q1 = p1
                q2 = p2
                n = int(0)
                for i in range(3):
                    if (m & (1 << i)) != 0:
                        q = q0
                        if i == 1:
                            q = q1
                        if i == 2:
                            q = q2
                        if n == 0:
                            p0 = q
                        elif n == 1:
                            p1 = q
                        else:
                            p2 = q
                        n = n + 1
            else:
                p3 = w
                v, m = closest_tetra(p0, p1, p2, p3)
                if m == 15:  # the origin inside: the hulls overlap
                    break
                q0 = p0
                q1 = p1
                q2 = p2
                q3 = p3
                n = int(0)
                for i in range(4):
                    if (m & (1 << i)) != 0:
                        q = q0
                        if i == 1:
                            q = q1
                        if i == 2:
                            q = q2
                        if i == 3:
                            q = q3
                        if n == 0:
                            p0 = q
                        elif n == 1:
                            p1 = q
                        else:
                            p2 = q
                        n = n + 1
            if wp.dot(v, v) >= vv:  # no progress (rounding): keep the bound found
                break
        return lb

    @wp.func
    def halfspace_lower(va: wp.array(dtype=vec3), sa: int, ea: int, Ra: mat33, ta: vec3,
                        nrm: vec3, offset: scalar) -> scalar:
        """The exact distance [m] of hull ``Ra va[sa:ea] + ta`` from the half-space
        ``nrm . x <= offset`` (<= 0: touching or inside)."""
        p = support(va, sa, ea, Ra, ta, -nrm)
        return wp.dot(nrm, p) - offset

    @wp.kernel(enable_backward=False)
    def world_lower(
        # Model:
        frame: wp.array(dtype=wp.int32),
        vstart: wp.array(dtype=wp.int32),
        verts: wp.array(dtype=vec3),
        rad: wp.array(dtype=scalar),
        centre: wp.array(dtype=vec3),
        bound: wp.array(dtype=scalar),
        o_kind: wp.array(dtype=wp.int32),
        o_vstart: wp.array(dtype=wp.int32),
        o_verts: wp.array(dtype=vec3),
        o_rad: wp.array(dtype=scalar),
        o_centre: wp.array(dtype=vec3),
        o_bound: wp.array(dtype=scalar),
        o_group: wp.array(dtype=wp.int32),
        o_rot: wp.array(dtype=mat33),
        o_half: wp.array(dtype=vec3),
        o_first: wp.array(dtype=wp.int32),
        # Data in:
        X: wp.array2d(dtype=mat44),
        cfg_group: wp.array(dtype=wp.int32),
        use_groups: int,
        cap: wp.array(dtype=scalar),
        tol: scalar,
        slack: scalar,
        # Data out:
        out: wp.array2d(dtype=scalar),
    ):
        c, k, o = wp.tid()
        if use_groups == 2:
            # objects sorted by group: the launch's third index counts within the
            # configuration's own world, o_first[g] .. o_first[g + 1]
            grp = cfg_group[c]
            o = o_first[grp] + o
            if o >= o_first[grp + 1]:
                return
        elif use_groups != 0:
            if o_group[o] != cfg_group[c]:
                return
        T = X[c, frame[k]]
        R = rot_of(T)
        t = pos_of(T)
        eye = mat33(one, zero, zero, zero, one, zero, zero, zero, one)
        origin = vec3(zero, zero, zero)
        lb = zero
        if o_kind[o] == HALFSPACE:
            lb = halfspace_lower(verts, vstart[k], vstart[k + 1], R, t, o_centre[o],
                                 o_bound[o]) - rad[k] - slack
        else:
            cw = R * centre[k] + t
            # broad phase: the piece's enclosing sphere against the object's box (o_rot,
            # o_half about o_centre: it holds the object's vertices; a thin shelf is far
            # from most pieces by its box, not by its enclosing sphere)
            lc = wp.transpose(o_rot[o]) * (cw - o_centre[o])
            h = o_half[o]
            ex = vec3(wp.max(wp.abs(lc[0]) - h[0], zero), wp.max(wp.abs(lc[1]) - h[1], zero),
                      wp.max(wp.abs(lc[2]) - h[2], zero))
            lb = wp.length(ex) - bound[k] - o_rad[o] - slack
            if lb < cap[c]:
                g = gjk_lower(verts, vstart[k], vstart[k + 1], R, t,
                              o_verts, o_vstart[o], o_vstart[o + 1], eye, origin, tol,
                              cap[c] + rad[k] + o_rad[o] + slack)
                lb = wp.max(lb, g - rad[k] - o_rad[o] - slack)
        wp.atomic_min(out, c, k, lb)

    @wp.kernel(enable_backward=False)
    def self_lower(
        # Model:
        frame: wp.array(dtype=wp.int32),
        vstart: wp.array(dtype=wp.int32),
        verts: wp.array(dtype=vec3),
        rad: wp.array(dtype=scalar),
        centre: wp.array(dtype=vec3),
        bound: wp.array(dtype=scalar),
        pair_a: wp.array(dtype=wp.int32),
        pair_b: wp.array(dtype=wp.int32),
        # Data in:
        X: wp.array2d(dtype=mat44),
        cap: wp.array(dtype=scalar),
        tol: scalar,
        slack: scalar,
        # Data out:
        out: wp.array2d(dtype=scalar),
    ):
        c, q = wp.tid()
        a = pair_a[q]
        b = pair_b[q]
        Ta = X[c, frame[a]]
        Tb = X[c, frame[b]]
        Ra = rot_of(Ta)
        ta = pos_of(Ta)
        Rb = rot_of(Tb)
        tb = pos_of(Tb)
        lb = wp.length((Ra * centre[a] + ta) - (Rb * centre[b] + tb)) - bound[a] - bound[b]
        if lb < cap[c]:
            g = gjk_lower(verts, vstart[a], vstart[a + 1], Ra, ta,
                          verts, vstart[b], vstart[b + 1], Rb, tb, tol,
                          cap[c] + rad[a] + rad[b] + slack)
            lb = wp.max(lb, g - rad[a] - rad[b] - slack)
        out[c, q] = lb

    return SimpleNamespace(vec3=vec3, mat44=mat44, support=support, gjk_lower=gjk_lower,
                           world_lower=world_lower, self_lower=self_lower)
