"""Collision kernels: SDF lookup, world and self-collision costs, sphere distances.

Math only; the host side is :mod:`jwarp.world.collision`. Built per scalar type by
:func:`kernels` (float32 or float64) and batched over configurations (N = paths x
substeps flattened): one thread per configuration.

World grid (the *Model* of the world; the fused ``cost`` and ``distance`` kernels take it as
one :class:`WorldGrid` struct, the plain Tape kernels as separate arrays):

* ``grid``   (nx, ny, nz) signed distances [m] at cell centres; a 2D world is stored
  with nz = 1 and looked up with ``dim = 2`` (bilinear in x, y; z ignored).
* ``origin`` vec3 [m] centre of cell (0, 0, 0); ``inv_h`` 1 / voxel size [1/m].
* ``cellmin`` same shape: ``cellmin[i, j, k]`` = smallest grid value over the corners
  (i..i+1, j..j+1, k..k+1) of the cell spanned from there, a lower bound of the
  interpolated D inside it (and outside the box, where D only grows); the cost kernel
  skips the interpolation where this bound already keeps a sphere ``eps`` away.

Lookup (:func:`sdf_sample`): trilinear (bilinear) interpolation of the cell-centre values;
outside the box of cell centres the point is clamped onto the box and the distance to the
box is added, ``D(x) = D(clamp(x)) + |x - clamp(x)|``, so the world is free out there and
the distance grows away from the grid (continuous at the box faces).

Robot tables (``DeviceModel.spheres`` of :mod:`jwarp.core.device`; see :mod:`jwarp.kernels.fk`
for the frame tables):

* ``sph_frame`` (S,) int32, ``sph_pos`` (S,) vec3 [m] in frame coordinates, ``sph_rad`` (S,) [m]
* ``bound_pos`` (n_frames,) vec3, ``bound_rad`` (n_frames,): a sphere per frame enclosing
  all its collision spheres (broad phase of the self-collision check)
* ``fpair_a``, ``fpair_b`` (P_f,) int32 frame pairs allowed to collide (that carry spheres);
  ``fpair_start`` (P_f + 1,) int32 CSR into the entries: one entry per sphere of frame a
  with pairs in it, ``ent_sphere`` (E,) int32 that sphere, ``ent_start`` (E + 1,) int32 CSR
  into ``pair_b`` (P,) int32, its partner spheres on frame b. Sphere pair p is
  (ent_sphere[e], pair_b[p]) for the entry e holding p.

Self-collision culling (exact): frame pairs whose bounding spheres keep ``eps`` apart are
skipped, then spheres of frame a whose surface keeps ``eps`` from the bounding sphere of b.

Costs (thesis eq. 3.8-3.12) with the smooth clip ``c`` of eq. 3.10 (:func:`smooth_clip`):

* world: ``U_w(q) = sum_s c(D(x_s(q)) - r_s)``
* self:  ``U_s(q) = sum_(a, b) c(|x_a(q) - x_b(q)| - r_a - r_b)`` over the allowed pairs

The fused ``cost`` and ``distance`` kernels carry no adjoint (``enable_backward=False``);
``world_cost_spheres`` and ``self_cost_pairs`` are the plain versions for ``wp.Tape``.

Hand-written gradient (:data:`cost` kernel): each sphere gets a force ``f = dU/dx``;
per frame the kernel sums ``F_i = sum f`` and ``M_i = sum x x f`` (world coordinates),
adds every subtree into its root (leaves first), and then for every driven frame i
``dU/dq_i = z_i . (M_i - o_i x F_i)`` (revolute) or ``z_i . F_i`` (prismatic), spread
onto the driving joints through the coupling tables. DH rows ``rho`` are held fixed.
"""


import functools
from types import SimpleNamespace

import warp as wp

from jwarp.kernels import geometry as geometry_kernels
from jwarp.kernels.elastic import funcs as elastic_funcs
from jwarp.kernels.fk import ROWS_NOMINAL
from jwarp.kernels.fk import funcs as fk_funcs

#: :func:`funcs` ``objects_near``: no exact object (nor plane) near the ball
NEAR_NONE = wp.constant(-2)


@wp.kernel(module="unique")
def mesh_sdf_kernel(
    # Model:
    mesh: wp.uint64,
    origin: wp.vec3,
    h: float,
    max_dist: float,
    # Data out:
    sdf: wp.array3d(dtype=float),
):
    """Signed distance [m] of every cell centre ``origin + h * (i, j, k)`` to a closed
    (watertight) triangle mesh: negative inside (ray-casting parity)."""
    i, j, k = wp.tid()
    p = origin + wp.vec3(float(i), float(j), float(k)) * h
    query = wp.mesh_query_point_sign_parity(mesh, p, max_dist)
    d = max_dist
    if query.result:
        c = wp.mesh_eval_position(mesh, query.face, query.u, query.v)
        d = query.sign * wp.length(p - c)
    sdf[i, j, k] = d

@functools.cache
def funcs(scalar: type) -> SimpleNamespace:
    """The structs and ``@wp.func`` helpers the collision kernels share, for one scalar type
    (``wp.float32``/``wp.float64``); built once per type (issue 40 item 5: the kernels are
    built one each, by :func:`cost`, :func:`distance`, :func:`world_cost_spheres`,
    :func:`self_cost_pairs`, :func:`sdf_query` and :func:`world_query`, from these)."""
    fk = fk_funcs(scalar)
    el = elastic_funcs(scalar)
    vec3, mat44 = fk.vec3, fk.mat44
    zero = scalar(0.0)
    one = scalar(1.0)
    half = scalar(0.5)
    unpack_rot, unpack_pos = fk.unpack_rot, fk.unpack_pos

    @wp.struct
    class SphereTables:
        """The collision tables of one robot (see the module docstring), one kernel argument."""

        sph_frame: wp.array(dtype=wp.int32)
        sph_pos: wp.array(dtype=vec3)
        sph_rad: wp.array(dtype=scalar)
        bound_pos: wp.array(dtype=vec3)
        bound_rad: wp.array(dtype=scalar)
        fpair_a: wp.array(dtype=wp.int32)
        fpair_b: wp.array(dtype=wp.int32)
        fpair_start: wp.array(dtype=wp.int32)
        ent_sphere: wp.array(dtype=wp.int32)
        ent_start: wp.array(dtype=wp.int32)
        pair_b: wp.array(dtype=wp.int32)

    @wp.struct
    class WorldGrid:
        """The world of the fused kernels (see the module docstring), one kernel argument:
        ``grid`` and ``cellmin`` (nx, ny, nz), ``origin``, ``inv_h`` and ``dim``."""

        grid: wp.array3d(dtype=scalar)
        cellmin: wp.array3d(dtype=scalar)
        origin: vec3
        inv_h: scalar
        dim: int

    gk = geometry_kernels.kernels(scalar)

    @wp.struct
    class WorldModel:
        """The whole world of the fused kernels, one kernel argument: a grid (``use_grid``;
        its values are lowered by the declared ``grid_error`` [m], so a grid's distance is
        a lower bound of the true one) and exact objects (:mod:`jwarp.kernels.geometry`)."""

        grid: WorldGrid
        use_grid: int
        grid_error: scalar
        shapes: gk.WorldShapes

    @wp.func
    def smooth_clip(d: scalar, eps: scalar):
        """Smooth clip c(d) of eq. 3.10 and its derivative c'(d):
        ``-d + eps/2`` for d < 0, ``(d - eps)^2 / (2 eps)`` for 0 <= d <= eps, 0 beyond."""
        if d < zero:
            return -d + half * eps, -one
        if d < eps:
            t = d - eps
            return half * t * t / eps, t / eps
        return zero, zero

    @wp.func
    def sdf_sample(grid: wp.array3d(dtype=scalar), origin: vec3, inv_h: scalar, dim: int,
                   x: vec3):
        """Signed distance D(x) [m] and its gradient dD/dx (vec3; z = 0 in 2D) at a
        world point x [m] (module docstring: interpolation and the outside rule)."""
        nx = grid.shape[0]
        ny = grid.shape[1]
        nz = grid.shape[2]
        h = one / inv_h
        u = (x - origin) * inv_h
        cx = wp.clamp(u[0], zero, scalar(nx - 1))
        cy = wp.clamp(u[1], zero, scalar(ny - 1))
        cz = zero
        if dim == 3:
            cz = wp.clamp(u[2], zero, scalar(nz - 1))
        ox = (u[0] - cx) * h
        oy = (u[1] - cy) * h
        oz = zero
        if dim == 3:
            oz = (u[2] - cz) * h
        i = wp.min(int(cx), nx - 2)
        j = wp.min(int(cy), ny - 2)
        fx = cx - scalar(i)
        fy = cy - scalar(j)
        gx = zero
        gy = zero
        gz = zero
        v = zero
        if dim == 3:
            k = wp.min(int(cz), nz - 2)
            fz = cz - scalar(k)
            c000 = grid[i, j, k]
            c100 = grid[i + 1, j, k]
            c010 = grid[i, j + 1, k]
            c110 = grid[i + 1, j + 1, k]
            c001 = grid[i, j, k + 1]
            c101 = grid[i + 1, j, k + 1]
            c011 = grid[i, j + 1, k + 1]
            c111 = grid[i + 1, j + 1, k + 1]
            # along x
            c00 = c000 + fx * (c100 - c000)
            c10 = c010 + fx * (c110 - c010)
            c01 = c001 + fx * (c101 - c001)
            c11 = c011 + fx * (c111 - c011)
            # along y
            c0 = c00 + fy * (c10 - c00)
            c1 = c01 + fy * (c11 - c01)
            v = c0 + fz * (c1 - c0)
            gz = c1 - c0
            gy = (one - fz) * (c10 - c00) + fz * (c11 - c01)
            d0 = (one - fy) * (c100 - c000) + fy * (c110 - c010)
            d1 = (one - fy) * (c101 - c001) + fy * (c111 - c011)
            gx = (one - fz) * d0 + fz * d1
            if oz != zero:
                gz = zero
        else:
            c00 = grid[i, j, 0]
            c10 = grid[i + 1, j, 0]
            c01 = grid[i, j + 1, 0]
            c11 = grid[i + 1, j + 1, 0]
            c0 = c00 + fx * (c10 - c00)
            c1 = c01 + fx * (c11 - c01)
            v = c0 + fy * (c1 - c0)
            gy = c1 - c0
            gx = (one - fy) * (c10 - c00) + fy * (c11 - c01)
        if ox != zero:
            gx = zero
        if oy != zero:
            gy = zero
        g = vec3(gx, gy, gz) * inv_h
        osq = ox * ox + oy * oy + oz * oz
        if osq > zero:
            on = wp.sqrt(osq)
            v = v + on
            g = g + vec3(ox, oy, oz) / on
        return v, g

    @wp.func
    def sdf_lower_bound(cellmin: wp.array3d(dtype=scalar), origin: vec3, inv_h: scalar,
                        dim: int, x: vec3) -> scalar:
        """A lower bound of D(x): the smallest of the corner values of the grid cell that
        holds x (``cellmin``, see module docstring), exact for the interpolation."""
        nx = cellmin.shape[0]
        ny = cellmin.shape[1]
        nz = cellmin.shape[2]
        u = (x - origin) * inv_h
        i = wp.min(int(wp.clamp(u[0], zero, scalar(nx - 1))), nx - 2)
        j = wp.min(int(wp.clamp(u[1], zero, scalar(ny - 1))), ny - 2)
        k = 0
        if dim == 3:
            k = wp.min(int(wp.clamp(u[2], zero, scalar(nz - 1))), nz - 2)
        return cellmin[i, j, k]

    @wp.func
    def world_sample(world: WorldGrid, x: vec3):
        """:func:`sdf_sample` of a :class:`WorldGrid`."""
        return sdf_sample(world.grid, world.origin, world.inv_h, world.dim, x)

    @wp.func
    def world_lower_bound(world: WorldGrid, x: vec3) -> scalar:
        """:func:`sdf_lower_bound` of a :class:`WorldGrid`."""
        return sdf_lower_bound(world.cellmin, world.origin, world.inv_h, world.dim, x)

    @wp.func
    def world_distance(world: WorldModel, x: vec3, cutoff: scalar, grp: int):
        """(d, g, k): the smallest signed distance [m] of the point x to the world where it
        is below ``cutoff``, its gradient and what gave it (object index k >= 0, -2 the
        grid); (cutoff, +z, -1) where nothing is closer than the cutoff. Grid cells whose
        corners keep the cutoff and objects whose boxes keep it are skipped. ``grp``: the
        world of a batch of worlds (-1: all objects; :mod:`jwarp.kernels.geometry`)."""
        return world_distance_skip(world, x, cutoff, grp, 0)

    @wp.func
    def grid_distance(world: WorldModel, x: vec3, cutoff: scalar):
        """(d, g, k) of :func:`world_distance` from the grid alone (k -2; (cutoff, +z, -1)
        without a grid or where its cell keeps the cutoff)."""
        best = cutoff
        bg = vec3(zero, zero, one)
        bk = int(-1)
        if world.use_grid != 0:
            gr = world.grid
            if sdf_lower_bound(gr.cellmin, gr.origin, gr.inv_h, gr.dim, x) - world.grid_error \
                    < cutoff:
                d, g = sdf_sample(gr.grid, gr.origin, gr.inv_h, gr.dim, x)
                d = d - world.grid_error
                if d < best:
                    best = d
                    bg = g
                    bk = -2
        return best, bg, bk

    @wp.func
    def objects_near(world: WorldModel, c: vec3, r: scalar, eps: scalar, grp: int):
        """(n, ids): the exact objects that may come within ``eps`` of a sphere inside
        the ball (c, r) (:func:`jwarp.kernels.geometry` ``shapes_near``, with the rounding
        a rounding slack): the BVH objects ``ids[:n]`` and the planes; n =
        :data:`NEAR_NONE`: none at all; n = -1: too many for
        the list. Callers pass this only for worlds without meshes (``bound_skip``)."""
        rr = r + eps + scalar(1e-4) * (one + wp.abs(c[0]) + wp.abs(c[1]) + wp.abs(c[2]))
        n, ids = gk.shapes_near(world.shapes, c, rr, grp)
        if n == 0:  # no BVH object: the planes' distances from the ball decide
            d, g, k = gk.shapes_distance_near(world.shapes, c, rr, grp, 0, ids)
            if k == -1:
                n = NEAR_NONE
        return n, ids

    @wp.func
    def world_distance_near(world: WorldModel, x: vec3, cutoff: scalar, grp: int, n: int,
                            ids: gk.near_ids):
        """:func:`world_distance` with the exact objects ``ids[:n]`` of
        :func:`objects_near` for a ball holding the sphere at x (its cutoff within the
        ball's eps): n = :data:`NEAR_NONE` leaves the objects out, n = -1 queries them
        all."""
        best, bg, bk = grid_distance(world, x, cutoff)
        if world.shapes.kind.shape[0] > 0 and n != NEAR_NONE:
            d2, g2, k2 = gk.shapes_distance_near(world.shapes, x, best, grp, n, ids)
            if k2 >= 0:
                best = d2
                bg = g2
                bk = k2
        return best, bg, bk

    @wp.func
    def world_distance_skip(world: WorldModel, x: vec3, cutoff: scalar, grp: int,
                            skip_objects: int):
        """:func:`world_distance`; ``skip_objects`` = 1 leaves the exact objects out (the
        caller proved them farther than the cutoff)."""
        best, bg, bk = grid_distance(world, x, cutoff)
        if world.shapes.kind.shape[0] > 0 and skip_objects == 0:  # a grid-only world never
            d2, g2, k2 = gk.shapes_distance(world.shapes, x, best, grp)  # enters the objects
            if k2 >= 0:
                best = d2
                bg = g2
                bk = k2
        return best, bg, bk

    @wp.func
    def sphere_centre(frames: wp.array2d(dtype=mat44), b: int, f: int, p: vec3) -> vec3:
        T = frames[b, f]
        return unpack_rot(T) * p + unpack_pos(T)

    @wp.func
    def forces_to_gradient(model: fk.FrameTables, frames: wp.array2d(dtype=mat44),
                           force: wp.array2d(dtype=vec3), moment: wp.array2d(dtype=vec3),
                           t: int, b: int, q: wp.array2d(dtype=scalar),
                           grad: wp.array2d(dtype=scalar)):
        """``grad[b] += d cost / d q_b`` from the per-frame force and moment sums of row t
        (world coordinates, module docstring): subtrees summed into their roots (leaves
        first; ``force``/``moment`` are overwritten with the sums), then each driven
        frame's ``z . (M - o x F)`` (revolute) or ``z . F`` (prismatic) spread onto its
        joints through the couplings."""
        nf = model.order.shape[0]
        # subtree sums, leaves to root (children follow parents in ``order``)
        for kk in range(nf):
            i = model.order[nf - 1 - kk]
            pi = model.parent[i]
            if pi >= 0:
                force[t, pi] = force[t, pi] + force[t, i]
                moment[t, pi] = moment[t, pi] + moment[t, i]
        for i in range(nf):
            m0 = model.cpl_start[i]
            m1 = model.cpl_start[i + 1]
            if m1 > m0:
                T = frames[t, i]
                z = vec3(T[0, 2], T[1, 2], T[2, 2])
                F = force[t, i]
                gi = wp.dot(z, F)
                if model.prismatic[i] == 0:
                    gi = wp.dot(z, moment[t, i] - wp.cross(unpack_pos(T), F))
                hp = fk.coupling_harmonic_slope(model, i, b, q)
                for m in range(m0, m1):
                    jm = model.cpl_joint[m]
                    grad[b, jm] = grad[b, jm] + fk.coupling_weight(model, m, b, q, hp) * gi

    return SimpleNamespace(
        scalar=scalar, fk=fk, el=el, vec3=vec3, mat44=mat44, zero=zero, one=one, half=half,
        unpack_rot=unpack_rot, unpack_pos=unpack_pos, geometry=gk,
        SphereTables=SphereTables, WorldGrid=WorldGrid, WorldModel=WorldModel,
        smooth_clip=smooth_clip, sdf_sample=sdf_sample, sdf_lower_bound=sdf_lower_bound,
        world_sample=world_sample, world_lower_bound=world_lower_bound,
        world_distance=world_distance,
        world_distance_skip=world_distance_skip, sphere_centre=sphere_centre,
        objects_near=objects_near, world_distance_near=world_distance_near,
        forces_to_gradient=forces_to_gradient,
    )


@functools.cache
def cost(scalar: type) -> wp.Kernel:
    """The fused world and self-collision cost kernel (with its hand-written gradient), for
    ``scalar``."""
    sh = funcs(scalar)
    fk, el, vec3 = sh.fk, sh.el, sh.vec3
    mat44, zero, SphereTables = sh.mat44, sh.zero, sh.SphereTables
    WorldModel, smooth_clip, objects_near = sh.WorldModel, sh.smooth_clip, sh.objects_near
    world_distance_near, sphere_centre = sh.world_distance_near, sh.sphere_centre
    forces_to_gradient = sh.forces_to_gradient

    @wp.kernel(module="unique", enable_backward=False)
    def cost_kernel(
        # Model:
        model: fk.FrameTables,
        spheres: SphereTables,
        # Data in:
        q: wp.array2d(dtype=scalar),
        rho: wp.array3d(dtype=scalar),
        rho_stride: int,
        rho_layout: wp.vec4i,
        rows_kind: int,
        world: WorldModel,
        w_world: scalar,
        w_self: scalar,
        eps: scalar,
        want_grad: int,
        group_div: int,
        active: wp.array(dtype=wp.int32),
        active_div: int,
        bound_skip: int,
        # Scratch:
        frames: wp.array2d(dtype=mat44),
        xs: wp.array2d(dtype=vec3),
        force: wp.array2d(dtype=vec3),
        moment: wp.array2d(dtype=vec3),
        bc: wp.array2d(dtype=vec3),
        # Data out:
        cost: wp.array(dtype=scalar),
        grad: wp.array2d(dtype=scalar),
        comp: el.CompensationArgs,
    ):
        """cost[b] = w_world U_w(q_b) + w_self U_s(q_b) and, if ``want_grad``,
        grad[b, :] = d cost / d q_b (rho fixed). Thread t handles configuration b and DH
        row ``rho_stride * row`` of :func:`jwarp.kernels.fk.waypoint_thread` (t,
        rho_layout) (b = row = t for the layout (1, 1, 1, N)). Scratch (row t): frames
        (N, n_frames), xs (N, S), force, moment and bounding-sphere centres bc
        (N, n_frames). With ``comp.enabled`` (and compensation rows, ``ROWS_COMPENSATION``) the
        waypoint threads end with one torque update of their row from the frames just
        computed (:func:`jwarp.kernels.elastic` ``compensation_update_at``).
        ``bound_skip`` (exact objects, no meshes): where a frame's bounding sphere keeps
        eps from every object, its spheres skip the object queries, else they visit only
        the objects near it (:func:`objects_near`, one query per frame; the same cost)"""
        t = wp.tid()
        b = t
        rb = int(0)
        on_waypoint = int(0)
        if rows_kind != ROWS_NOMINAL:
            b, row, on_waypoint = fk.waypoint_thread(t, rho_layout)
            rb = rho_stride * row
        grp = int(-1)  # a batch of worlds: configuration b plans in world b // group_div
        if group_div > 0:
            grp = b // group_div
        if active_div > 0:  # rows of frozen paths (active[b // active_div] == 0) cost nothing
            if active[b // active_div] == 0:
                cost[b] = zero
                if want_grad != 0:
                    for j in range(grad.shape[1]):
                        grad[b, j] = zero
                return
        nf = model.order.shape[0]
        for k in range(nf):
            i = model.order[k]
            fk.write_frame(model, b, i, q, rho, rb, rows_kind, frames, t)
            if want_grad != 0:
                force[t, i] = vec3(zero, zero, zero)
                moment[t, i] = vec3(zero, zero, zero)
        hit = int(0)
        u_world = zero
        cur = int(-1)  # the frame whose bounding sphere was tested last (bound_skip)
        near_n = int(-1)  # the objects near it (objects_near; -1: each sphere queries all)
        near = sh.geometry.near_ids()
        for s in range(spheres.sph_frame.shape[0]):
            fr = spheres.sph_frame[s]
            x = sphere_centre(frames, t, fr, spheres.sph_pos[s])
            xs[t, s] = x
            if w_world != zero:
                if bound_skip != 0 and fr != cur:
                    cur = fr
                    near_n = -1
                    if spheres.bound_rad[fr] >= zero:
                        near_n, near = objects_near(world, sphere_centre(
                            frames, t, fr, spheres.bound_pos[fr]), spheres.bound_rad[fr],
                            eps, grp)
                # what keeps eps from the sphere costs nothing: cells and objects skipped
                rs = spheres.sph_rad[s]
                d, g, obj = world_distance_near(world, x, rs + eps, grp, near_n, near)
                if obj != -1 and d - rs < eps:
                    c, dc = smooth_clip(d - rs, eps)
                    u_world += c
                    if want_grad != 0 and dc != zero:
                        f = (w_world * dc) * g
                        force[t, fr] = force[t, fr] + f
                        moment[t, fr] = moment[t, fr] + wp.cross(x, f)
                        hit = 1
        u_self = zero
        if w_self != zero:
            for i in range(nf):
                if spheres.bound_rad[i] >= zero:
                    bc[t, i] = sphere_centre(frames, t, i, spheres.bound_pos[i])
            for fp in range(spheres.fpair_a.shape[0]):
                fa = spheres.fpair_a[fp]
                fb = spheres.fpair_b[fp]
                ca = bc[t, fa]
                cb = bc[t, fb]
                rb_eps = spheres.bound_rad[fb] + eps
                reach = spheres.bound_rad[fa] + rb_eps
                if wp.length_sq(ca - cb) < reach * reach:
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
                                    c, dc = smooth_clip(dist - rsum, eps)
                                    u_self += c
                                    if want_grad != 0 and dist > zero:
                                        f = (w_self * dc / dist) * diff
                                        force[t, fa] = force[t, fa] + f
                                        moment[t, fa] = moment[t, fa] + wp.cross(xa, f)
                                        force[t, fb] = force[t, fb] - f
                                        moment[t, fb] = moment[t, fb] - wp.cross(xb, f)
                                        hit = 1
        cost[b] = w_world * u_world + w_self * u_self
        if want_grad != 0:
            for j in range(grad.shape[1]):
                grad[b, j] = zero
            if hit != 0:
                forces_to_gradient(model, frames, force, moment, t, b, q, grad)
        if comp.enabled != 0 and on_waypoint != 0:
            el.compensation_update_at(model, frames, t, rho, rb, comp)

    return cost_kernel


@functools.cache
def distance(scalar: type) -> wp.Kernel:
    """The fused signed-distance kernel (spheres to the world, sphere pairs), for ``scalar``."""
    sh = funcs(scalar)
    fk, vec3, mat44 = sh.fk, sh.vec3, sh.mat44
    SphereTables, WorldModel, world_distance = sh.SphereTables, sh.WorldModel, sh.world_distance
    sphere_centre = sh.sphere_centre

    @wp.kernel(module="unique", enable_backward=False)
    def distance_kernel(
        # Model:
        model: fk.FrameTables,
        spheres: SphereTables,
        far: scalar,
        # Data in:
        q: wp.array2d(dtype=scalar),
        rho: wp.array3d(dtype=scalar),
        rho_stride: int,
        rows_kind: int,
        world: WorldModel,
        use_world: int,
        use_self: int,
        write_spheres: int,
        write_pairs: int,
        group_div: int,
        # Scratch:
        frames: wp.array2d(dtype=mat44),
        xs: wp.array2d(dtype=vec3),
        # Data out:
        sphere_dist: wp.array2d(dtype=scalar),
        pair_dist: wp.array2d(dtype=scalar),
        min_dist: wp.array2d(dtype=scalar),
    ):
        """Signed surface distances [m]: sphere_dist[b, s] = D(x_s) - r_s (if
        ``write_spheres``), pair_dist[b, p] = |x_a - x_b| - r_a - r_b (if ``write_pairs``),
        min_dist[b] = [min over spheres, min over pairs] (``far`` where none)."""
        b = wp.tid()
        grp = int(-1)
        if group_div > 0:
            grp = b // group_div
        nf = model.order.shape[0]
        for k in range(nf):
            fk.write_frame(model, b, model.order[k], q, rho, b * rho_stride, rows_kind, frames, b)
        dmin_w = far
        for s in range(spheres.sph_frame.shape[0]):
            x = sphere_centre(frames, b, spheres.sph_frame[s], spheres.sph_pos[s])
            xs[b, s] = x
            if use_world != 0:
                rs = spheres.sph_rad[s]
                cut = dmin_w + rs  # only the minimum: skip what cannot lower it
                if write_spheres != 0:
                    cut = far
                d, g, obj = world_distance(world, x, cut, grp)
                d = d - rs
                if obj != -1:  # nothing within the cutoff: the minimum stays as it is
                    dmin_w = wp.min(dmin_w, d)
                if write_spheres != 0:
                    sphere_dist[b, s] = d
        dmin_s = far
        if use_self != 0:
            for fp in range(spheres.fpair_a.shape[0]):
                fa = spheres.fpair_a[fp]
                fb = spheres.fpair_b[fp]
                check = write_pairs
                if check == 0:  # broad phase: skip if the bounding spheres are farther apart
                    ca = sphere_centre(frames, b, fa, spheres.bound_pos[fa])
                    cb = sphere_centre(frames, b, fb, spheres.bound_pos[fb])
                    if wp.length(ca - cb) - spheres.bound_rad[fa] - spheres.bound_rad[fb] < dmin_s:
                        check = 1
                if check != 0:
                    cb = sphere_centre(frames, b, fb, spheres.bound_pos[fb])
                    for e in range(spheres.fpair_start[fp], spheres.fpair_start[fp + 1]):
                        sa = spheres.ent_sphere[e]
                        xa = xs[b, sa]
                        ra = spheres.sph_rad[sa]
                        look = write_pairs
                        if look == 0:  # skip spheres whose distance to b's bound cannot lower it
                            if wp.length(xa - cb) - ra - spheres.bound_rad[fb] < dmin_s:
                                look = 1
                        if look != 0:
                            for p in range(spheres.ent_start[e], spheres.ent_start[e + 1]):
                                sb = spheres.pair_b[p]
                                d = wp.length(xa - xs[b, sb]) - ra - spheres.sph_rad[sb]
                                dmin_s = wp.min(dmin_s, d)
                                if write_pairs != 0:
                                    pair_dist[b, p] = d
        min_dist[b, 0] = dmin_w
        min_dist[b, 1] = dmin_s

    return distance_kernel


@functools.cache
def world_cost_spheres(scalar: type) -> wp.Kernel:
    """The plain world cost kernel for ``wp.Tape``, for ``scalar``."""
    sh = funcs(scalar)
    vec3, mat44, smooth_clip = sh.vec3, sh.mat44, sh.smooth_clip
    sdf_sample, sphere_centre = sh.sdf_sample, sh.sphere_centre

    @wp.kernel(module="unique")
    def world_cost_spheres(
        # Model:
        sph_frame: wp.array(dtype=wp.int32),
        sph_pos: wp.array(dtype=vec3),
        sph_rad: wp.array(dtype=scalar),
        # Data in:
        frames: wp.array2d(dtype=mat44),
        grid: wp.array3d(dtype=scalar),
        origin: vec3,
        inv_h: scalar,
        dim: int,
        w: scalar,
        eps: scalar,
        # Data out:
        cost: wp.array(dtype=scalar),
    ):
        """cost[b] += w c(D(x_s) - r_s), one thread per (configuration b, sphere s).
        Plain code for ``wp.Tape`` (differentiable w.r.t. frames and grid)."""
        b, s = wp.tid()
        x = sphere_centre(frames, b, sph_frame[s], sph_pos[s])
        d, g = sdf_sample(grid, origin, inv_h, dim, x)
        c, dc = smooth_clip(d - sph_rad[s], eps)
        wp.atomic_add(cost, b, w * c)

    return world_cost_spheres


@functools.cache
def self_cost_pairs(scalar: type) -> wp.Kernel:
    """The plain self-collision cost kernel for ``wp.Tape``, for ``scalar``."""
    sh = funcs(scalar)
    vec3, mat44, smooth_clip = sh.vec3, sh.mat44, sh.smooth_clip
    sphere_centre = sh.sphere_centre

    @wp.kernel(module="unique")
    def self_cost_pairs(
        # Model:
        sph_frame: wp.array(dtype=wp.int32),
        sph_pos: wp.array(dtype=vec3),
        sph_rad: wp.array(dtype=scalar),
        pair_a: wp.array(dtype=wp.int32),
        pair_b: wp.array(dtype=wp.int32),
        # Data in:
        frames: wp.array2d(dtype=mat44),
        w: scalar,
        eps: scalar,
        # Data out:
        cost: wp.array(dtype=scalar),
    ):
        """cost[b] += w c(|x_a - x_b| - r_a - r_b), one thread per (configuration, pair).
        Plain code for ``wp.Tape``."""
        b, p = wp.tid()
        sa = pair_a[p]
        sb = pair_b[p]
        xa = sphere_centre(frames, b, sph_frame[sa], sph_pos[sa])
        xb = sphere_centre(frames, b, sph_frame[sb], sph_pos[sb])
        diff = xa - xb
        rsum = sph_rad[sa] + sph_rad[sb]
        lim = rsum + eps
        if wp.length_sq(diff) < lim * lim:  # also keeps length() away from 0 in the adjoint
            c, dc = smooth_clip(wp.length(diff) - rsum, eps)
            wp.atomic_add(cost, b, w * c)

    return self_cost_pairs


@functools.cache
def sdf_query(scalar: type) -> wp.Kernel:
    """The grid lookup kernel (distance and gradient at points), for ``scalar``."""
    sh = funcs(scalar)
    vec3, sdf_sample = sh.vec3, sh.sdf_sample

    @wp.kernel(module="unique", enable_backward=False)
    def sdf_query_kernel(
        # Data in:
        points: wp.array(dtype=vec3),
        grid: wp.array3d(dtype=scalar),
        origin: vec3,
        inv_h: scalar,
        dim: int,
        # Data out:
        dist: wp.array(dtype=scalar),
        grad: wp.array(dtype=vec3),
    ):
        """dist[p] = D(points[p]) [m], grad[p] = dD/dx (z = 0 in 2D)."""
        p = wp.tid()
        d, g = sdf_sample(grid, origin, inv_h, dim, points[p])
        dist[p] = d
        grad[p] = g

    return sdf_query_kernel


@functools.cache
def world_query(scalar: type) -> wp.Kernel:
    """The world distance kernel (:func:`world_distance` at points), for ``scalar``."""
    sh = funcs(scalar)
    vec3, WorldModel, world_distance = sh.vec3, sh.WorldModel, sh.world_distance

    @wp.kernel(module="unique", enable_backward=False)
    def world_query_kernel(
        # Model:
        world: WorldModel,
        # Data in:
        points: wp.array(dtype=vec3),
        cutoff: scalar,
        # Data out:
        dist: wp.array(dtype=scalar),
        grad: wp.array(dtype=vec3),
        obj: wp.array(dtype=wp.int32),
    ):
        """dist[p], grad[p], obj[p] of :func:`world_distance` at points[p]."""
        p = wp.tid()
        d, g, k = world_distance(world, points[p], cutoff, -1)
        dist[p] = d
        grad[p] = g
        obj[p] = k

    return world_query_kernel


@functools.cache
def kernels(scalar: type) -> SimpleNamespace:
    """Collision kernels and functions for one scalar type (``wp.float32``/``wp.float64``):
    :func:`funcs`' structs and functions and every kernel of the builders (a facade: the
    builders build only the kernel asked for)."""
    sh = funcs(scalar)
    return SimpleNamespace(
        world_query=world_query(scalar),
        scalar=scalar, SphereTables=sh.SphereTables, WorldGrid=sh.WorldGrid,
        WorldModel=sh.WorldModel, world_distance=sh.world_distance,
        world_distance_skip=sh.world_distance_skip, forces_to_gradient=sh.forces_to_gradient,
        objects_near=sh.objects_near, geometry=sh.geometry, vec3=sh.vec3, mat44=sh.mat44,
        smooth_clip=sh.smooth_clip, sdf_sample=sh.sdf_sample,
        sdf_lower_bound=sh.sdf_lower_bound, world_sample=sh.world_sample,
        world_lower_bound=sh.world_lower_bound, sphere_centre=sh.sphere_centre,
        cost=cost(scalar), distance=distance(scalar),
        world_cost_spheres=world_cost_spheres(scalar), self_cost_pairs=self_cost_pairs(scalar),
        sdf_query=sdf_query(scalar),
    )
