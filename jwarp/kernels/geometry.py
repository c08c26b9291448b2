"""Exact signed distances of points to world objects (math only; host: :mod:`jwarp.world.shapes`).

Built per scalar type by :func:`kernels` (float32 or float64). Every function returns the
signed distance ``d`` [m] of a point (negative inside the solid) and its gradient ``g``
(unit length where defined) in the frame the point was given in.

Shape kinds (:data:`SPHERE` ... :data:`MESH`) and their ``size`` (local frame, the
conventions of :mod:`jwarp.world.primitives`):

* sphere   ``size = (radius, 0, 0)``
* box      ``size = half side lengths (hx, hy, hz)``, centred
* cylinder ``size = (radius, half length, 0)``, axis z, centred
* capsule  ``size = (radius, half segment length, 0)``: the segment z in +-half length
* cone     ``size = (base radius, half length, 0)``: base disc at z = -half length, tip at +
* plane    half-space z <= 0 of its local frame (normal +z); ``size`` unused
* mesh     a ``wp.Mesh`` (local vertices, built with ``support_winding_number=True``): the
           sign comes from the generalised winding number, so open and multi-part meshes
           have a well-defined inside; ``size`` holds the half extents of its local
           bounding box, ``centre`` its centre

World objects (:class:`WorldShapes`, one kernel argument): per object ``kind``, pose
``rot`` (local -> world rotation) and ``pos`` [m], ``size``, ``centre``, ``mesh`` id; a
``wp.Bvh`` over the world bounding boxes of every object except planes (broad phase: a
query returns only the objects whose box lies within the cutoff of a point), and the
indices of the planes (always visited). :func:`shapes_distance` gives the smallest
signed distance over the objects within ``cutoff`` of a point, its gradient and the
object index (-1: none within the cutoff; the distance is then ``cutoff``, a lower bound).
"""

import functools
from types import SimpleNamespace

import warp as wp

SPHERE = wp.constant(0)
BOX = wp.constant(1)
CYLINDER = wp.constant(2)
CAPSULE = wp.constant(3)
CONE = wp.constant(4)
PLANE = wp.constant(5)
MESH = wp.constant(6)

#: the most objects a ball's candidate list holds (:func:`kernels` ``shapes_near``: one
#: BVH query for all the spheres of a link instead of one per sphere); a ball near more
#: objects has its points query the BVH each
NEAR_MAX = wp.constant(16)

#: kind names in index order (host tables use these indices)
KIND_NAMES = ("sphere", "box", "cylinder", "capsule", "cone", "plane", "mesh")


@functools.cache
def kernels(scalar: type) -> SimpleNamespace:
    """Exact distance functions and kernels for one scalar type (``wp.float32``/``wp.float64``)."""
    vec3 = wp.types.vector(3, scalar)
    vec2 = wp.types.vector(2, scalar)
    mat33 = wp.types.matrix((3, 3), scalar)
    zero = scalar(0.0)
    one = scalar(1.0)
    tiny = scalar(1e-12)

    @wp.struct
    class WorldShapes:
        """The exact objects of a world (module docstring), one kernel argument."""

        kind: wp.array(dtype=wp.int32)
        rot: wp.array(dtype=mat33)
        pos: wp.array(dtype=vec3)
        size: wp.array(dtype=vec3)
        centre: wp.array(dtype=vec3)
        mesh: wp.array(dtype=wp.uint64)
        bvh: wp.uint64
        use_bvh: int
        planes: wp.array(dtype=wp.int32)
        group: wp.array(dtype=wp.int32)
        group_root: wp.array(dtype=wp.int32)
        use_groups: int

    @wp.func
    def sgn(v: scalar) -> scalar:
        if v < zero:
            return -one
        return one

    @wp.func
    def sphere_sdf(p: vec3, r: scalar):
        n = wp.length(p)
        g = vec3(zero, zero, one)
        if n > tiny:
            g = p / n
        return n - r, g

    @wp.func
    def box_sdf(p: vec3, h: vec3):
        qx = wp.abs(p[0]) - h[0]
        qy = wp.abs(p[1]) - h[1]
        qz = wp.abs(p[2]) - h[2]
        m = wp.max(qx, wp.max(qy, qz))
        if m > zero:
            v = vec3(wp.max(qx, zero), wp.max(qy, zero), wp.max(qz, zero))
            l = wp.length(v)
            return l, vec3(sgn(p[0]) * v[0], sgn(p[1]) * v[1], sgn(p[2]) * v[2]) / l
        if qx >= qy and qx >= qz:
            return qx, vec3(sgn(p[0]), zero, zero)
        if qy >= qz:
            return qy, vec3(zero, sgn(p[1]), zero)
        return qz, vec3(zero, zero, sgn(p[2]))

    @wp.func
    def radial(p: vec3):
        """(|p_xy|, unit radial direction in 3D)."""
        rr = wp.sqrt(p[0] * p[0] + p[1] * p[1])
        u = vec3(one, zero, zero)
        if rr > tiny:
            u = vec3(p[0] / rr, p[1] / rr, zero)
        return rr, u

    @wp.func
    def cylinder_sdf(p: vec3, radius: scalar, half: scalar):
        rr, u = radial(p)
        dx = rr - radius
        dz = wp.abs(p[2]) - half
        ez = vec3(zero, zero, sgn(p[2]))
        if dx > zero and dz > zero:
            l = wp.sqrt(dx * dx + dz * dz)
            return l, (dx * u + dz * ez) / l
        if dx >= dz:
            return dx, u
        return dz, ez

    @wp.func
    def capsule_sdf(p: vec3, radius: scalar, half: scalar):
        c = vec3(zero, zero, wp.clamp(p[2], -half, half))
        return sphere_sdf(p - c, radius)

    @wp.func
    def cone_sdf(p: vec3, radius: scalar, half: scalar):
        """Exact capped cone (base radius at z = -half, tip at +half), after I. Quilez."""
        rr, u = radial(p)
        z = p[2]
        rcap = zero
        if z < zero:
            rcap = radius
        ca = vec2(rr - wp.min(rr, rcap), wp.abs(z) - half)
        k1 = vec2(zero, half)
        k2 = vec2(-radius, scalar(2.0) * half)
        q = vec2(rr, z)
        t = wp.clamp(wp.dot(k1 - q, k2) / wp.dot(k2, k2), zero, one)
        cb = q - k1 + k2 * t
        s = one
        if cb[0] < zero and ca[1] < zero:
            s = -one
        la = wp.dot(ca, ca)
        lb = wp.dot(cb, cb)
        ez = vec3(zero, zero, sgn(z))
        g = vec3(zero, zero, one)
        d = zero
        if la < lb:
            d = wp.sqrt(la)
            if d > tiny:
                g = (ca[0] * u + ca[1] * ez) / d
        else:
            d = wp.sqrt(lb)
            if d > tiny:
                g = (cb[0] * u + cb[1] * vec3(zero, zero, one)) / d
        return s * d, s * g

    @wp.func
    def mesh_sdf(mesh: wp.uint64, p: vec3, centre: vec3, half: vec3, cutoff: scalar):
        """Signed distance to a winding-number mesh; (cutoff, +z) when no face is within
        ``cutoff`` and p lies outside the mesh's (padded) bounding box."""
        rel = p - centre
        inside_box = wp.abs(rel[0]) <= half[0] + tiny and wp.abs(rel[1]) <= half[1] + tiny \
            and wp.abs(rel[2]) <= half[2] + tiny
        maxd = cutoff
        if inside_box:  # the surface may be farther than the cutoff: search it all
            maxd = scalar(2.0) * wp.length(half) + cutoff
        pf = wp.vec3f(wp.float32(p[0]), wp.float32(p[1]), wp.float32(p[2]))
        qr = wp.mesh_query_point_sign_winding_number(mesh, pf, wp.float32(maxd))
        if not qr.result:
            return cutoff, vec3(zero, zero, one)
        cf = wp.mesh_eval_position(mesh, qr.face, qr.u, qr.v)
        v = p - vec3(scalar(cf[0]), scalar(cf[1]), scalar(cf[2]))
        n = wp.length(v)
        s = scalar(qr.sign)
        if s == zero:
            s = one
        g = vec3(zero, zero, one)
        if n > scalar(1e-9):
            g = v / n
        else:
            nf = wp.mesh_eval_face_normal(mesh, qr.face)
            g = vec3(scalar(nf[0]), scalar(nf[1]), scalar(nf[2])) * s
        return s * n, s * g

    @wp.func
    def shape_sdf(ws: WorldShapes, k: int, x: vec3, cutoff: scalar):
        """Signed distance [m] of the world point x to object k and its world gradient."""
        R = ws.rot[k]
        p = wp.transpose(R) * (x - ws.pos[k])
        kind = ws.kind[k]
        sz = ws.size[k]
        d = zero
        g = vec3(zero, zero, one)
        if kind == SPHERE:
            d, g = sphere_sdf(p, sz[0])
        elif kind == BOX:
            d, g = box_sdf(p, sz)
        elif kind == CYLINDER:
            d, g = cylinder_sdf(p, sz[0], sz[1])
        elif kind == CAPSULE:
            d, g = capsule_sdf(p, sz[0], sz[1])
        elif kind == CONE:
            d, g = cone_sdf(p, sz[0], sz[1])
        elif kind == PLANE:
            d = p[2]
        else:
            d, g = mesh_sdf(ws.mesh[k], p, ws.centre[k], sz, cutoff)
        return d, R * g

    @wp.func
    def planes_distance(ws: WorldShapes, x: vec3, cutoff: scalar, grp: int):
        """(d, g, k) of :func:`shapes_distance` over the planes alone (no BVH object)."""
        best = cutoff
        bg = vec3(zero, zero, one)
        bk = int(-1)
        by_group = ws.use_groups != 0 and grp >= 0
        for i in range(ws.planes.shape[0]):
            k = ws.planes[i]
            if by_group and ws.group[k] != grp:
                continue
            d, g = shape_sdf(ws, k, x, cutoff)
            if d < best:
                best = d
                bg = g
                bk = k
        return best, bg, bk

    @wp.func
    def shapes_distance(ws: WorldShapes, x: vec3, cutoff: scalar, grp: int):
        """(d, g, k): the smallest signed distance [m] of x over the objects whose bounding
        box lies within ``cutoff`` of x, its gradient and the object; (cutoff, +z, -1) if
        there is none. Objects farther than the cutoff are never visited. In a batch of
        worlds (``use_groups``) only the objects of world ``grp`` count (``grp`` < 0: all)."""
        best, bg, bk = planes_distance(ws, x, cutoff, grp)
        by_group = ws.use_groups != 0 and grp >= 0
        root = int(-1)
        if by_group:
            root = ws.group_root[grp]  # -2: this world has no objects in the BVH
        if ws.use_bvh != 0 and root != -2:
            # the query box in float32, padded against rounding
            pad = cutoff + scalar(1e-5) * (one + wp.abs(x[0]) + wp.abs(x[1]) + wp.abs(x[2]))
            lo = wp.vec3f(wp.float32(x[0] - pad), wp.float32(x[1] - pad), wp.float32(x[2] - pad))
            hi = wp.vec3f(wp.float32(x[0] + pad), wp.float32(x[1] + pad), wp.float32(x[2] + pad))
            query = wp.bvh_query_aabb(ws.bvh, lo, hi, root)
            k = int(0)
            while wp.bvh_query_next(query, k):
                d, g = shape_sdf(ws, k, x, best)
                if d < best:
                    best = d
                    bg = g
                    bk = k
        return best, bg, bk

    near_ids = wp.types.vector(length=NEAR_MAX, dtype=wp.int32)

    @wp.func
    def shapes_near(ws: WorldShapes, c: vec3, r: scalar, grp: int):
        """(n, ids): the objects of the BVH (every object but the planes) whose bounding
        box lies within ``r`` of the point c, in ``ids[:n]``; n = -1 where more than
        :data:`NEAR_MAX` do (then :func:`shapes_distance_near` queries the BVH itself).
        One query for a ball of points: every object within ``cutoff`` of a point x
        with |x - c| + cutoff <= r is among them."""
        ids = near_ids()
        n = int(0)
        root = int(-1)
        if ws.use_groups != 0 and grp >= 0:
            root = ws.group_root[grp]
        if ws.use_bvh != 0 and root != -2:
            pad = r + scalar(1e-5) * (one + wp.abs(c[0]) + wp.abs(c[1]) + wp.abs(c[2]))
            lo = wp.vec3f(wp.float32(c[0] - pad), wp.float32(c[1] - pad), wp.float32(c[2] - pad))
            hi = wp.vec3f(wp.float32(c[0] + pad), wp.float32(c[1] + pad), wp.float32(c[2] + pad))
            query = wp.bvh_query_aabb(ws.bvh, lo, hi, root)
            k = int(0)
            while wp.bvh_query_next(query, k):
                if n < NEAR_MAX:
                    ids[n] = k
                n += 1
        if n > NEAR_MAX:
            n = -1
        return n, ids

    @wp.func
    def shapes_distance_near(ws: WorldShapes, x: vec3, cutoff: scalar, grp: int, n: int,
                             ids: near_ids):
        """:func:`shapes_distance` over the planes and the objects ``ids[:n]`` of
        :func:`shapes_near` (a superset of the objects within ``cutoff`` of x), without a
        BVH query; n = -1: :func:`shapes_distance` itself."""
        if n < 0:
            return shapes_distance(ws, x, cutoff, grp)
        best, bg, bk = planes_distance(ws, x, cutoff, grp)
        for i in range(n):
            k = ids[i]
            d, g = shape_sdf(ws, k, x, best)
            if d < best:
                best = d
                bg = g
                bk = k
        return best, bg, bk

    @wp.kernel(module="unique", enable_backward=False)
    def distance_kernel(
        # Model:
        ws: WorldShapes,
        # Data in:
        points: wp.array(dtype=vec3),
        cutoff: scalar,
        # Data out:
        dist: wp.array(dtype=scalar),
        grad: wp.array(dtype=vec3),
        obj: wp.array(dtype=wp.int32),
    ):
        """dist[p], grad[p], obj[p] of :func:`shapes_distance` at points[p]."""
        i = wp.tid()
        d, g, k = shapes_distance(ws, points[i], cutoff, -1)
        dist[i] = d
        grad[i] = g
        obj[i] = k

    @wp.kernel(module="unique", enable_backward=False)
    def group_root_kernel(
        # Model:
        bvh: wp.uint64,
        # Data out:
        roots: wp.array(dtype=wp.int32),
    ):
        """roots[g] = the BVH node of group g (launch dim: groups; host marks empty ones)."""
        g = wp.tid()
        roots[g] = wp.bvh_get_group_root(bvh, g)

    return SimpleNamespace(group_roots=group_root_kernel, scalar=scalar, vec3=vec3, mat33=mat33, WorldShapes=WorldShapes,
                           sphere_sdf=sphere_sdf, box_sdf=box_sdf, cylinder_sdf=cylinder_sdf,
                           capsule_sdf=capsule_sdf, cone_sdf=cone_sdf, mesh_sdf=mesh_sdf,
                           shape_sdf=shape_sdf, shapes_distance=shapes_distance,
                           near_ids=near_ids, shapes_near=shapes_near,
                           shapes_distance_near=shapes_distance_near,
                           distance=distance_kernel)
