"""Path kernels for optimization-based motion planning (math only; thesis 3.3.1-3.3.3).

A batch of ``P`` paths with ``W`` waypoints each is an array ``paths (P, W, n_dof)``.
The first and last waypoints (start, goal) are fixed; only the interior ones move.

* Substeps (eq. 3.3): each segment ``t`` is split into ``n_sub`` linear substeps
  ``q_{t,u} = q_t + u / n_sub (q_{t+1} - q_t)``, ``u = 0 .. n_sub - 1``, plus the goal:
  ``S = (W - 1) n_sub + 1`` distinct configurations per path, stored as rows
  ``p * S + s`` of ``q_sub (P * S, n_dof)`` with ``s = t n_sub + u`` (``s = S - 1`` is the goal).
* Length cost (eq. 3.5): ``U_l = (W - 1) / U_1(q_W, q_1) * sum_t U_1(q_{t+1}, q_t)`` with
  ``U_1(a, b) = 1/2 |a - b|^2``; the normaliser ``U_1(q_W, q_1)`` is floored at ``norm_floor``
  (rad^2) so a task with start == goal stays finite.
* Path objective (eq. 3.16): ``U_path = sum_s sub_cost[s] + lam_l U_l`` where ``sub_cost``
  already holds ``lam_w U_w + lam_s U_s`` of each substep (collision kernels).
* Gradient w.r.t. an interior waypoint ``t``: the length term
  ``lam_l K (2 q_t - q_{t-1} - q_{t+1})`` plus the substep gradients scattered with the hat
  weights ``1 - |s - t n_sub| / n_sub`` of the substeps ``s`` in the two adjacent segments.
* Limits (:class:`LimitTables`, one kernel argument ``limits``, part of the robot's
  *Model*): a box ``box (n_dof, 2)`` and linear limits
  ``lower <= sum_k c_k q_{j_k} <= upper`` (CSR tables ``lin_start (L + 1)``, ``lin_joint``,
  ``lin_coef``, ``lin_bounds (L, 2)``), enforced by alternating projections (box, then each linear half-space pair) ending with
  the box (``project_row``); ``within_limits_row`` / ``within_linear_limits`` check them up
  to a tolerance (the IK solver's feasibility check and seed sampling use them).

Shapes are in the docstrings; units rad (m for prismatic joints).
"""


import functools
from types import SimpleNamespace

import warp as wp

#: alternating-projection rounds (box + linear limits); the justin19 torso polygon needs <= 2
PROJECTION_ROUNDS = 6


@functools.cache
def funcs(scalar: type) -> SimpleNamespace:
    """The limit tables and ``@wp.func`` helpers the path kernels share, for one scalar
    type (``wp.float32``/``wp.float64``); built once per type (issue 40 item 5: the kernels
    are built one each, by :func:`substeps`, :func:`path_cost`, :func:`path_grad`,
    :func:`path_step`, :func:`project`, :func:`gather`, :func:`keep` and :func:`select`,
    from these)."""
    zero = scalar(0.0)
    one = scalar(1.0)
    half = scalar(0.5)
    n_rounds = PROJECTION_ROUNDS

    @wp.struct
    class LimitTables:
        """The joint limits of one robot (see the module docstring), one kernel argument:
        the box ``box`` (n_dof, 2) [rad or m] and the linear limits as CSR rows
        ``lin_start`` (L + 1,), ``lin_joint``/``lin_coef`` (max(nnz, 1),), ``lin_bounds``
        (L, 2)."""

        box: wp.array2d(dtype=scalar)
        lin_start: wp.array(dtype=wp.int32)
        lin_joint: wp.array(dtype=wp.int32)
        lin_coef: wp.array(dtype=scalar)
        lin_bounds: wp.array2d(dtype=scalar)

    @wp.func
    def length_scale(paths: wp.array3d(dtype=scalar), p: int, norm_floor: scalar) -> scalar:
        """K = (W - 1) / max(1/2 |q_W - q_1|^2, norm_floor) of path p."""
        W = paths.shape[1]
        d2 = zero
        for j in range(paths.shape[2]):
            d = paths[p, W - 1, j] - paths[p, 0, j]
            d2 += d * d
        return scalar(W - 1) / wp.max(half * d2, norm_floor)

    @wp.func
    def waypoint_grad(paths: wp.array3d(dtype=scalar), sub_grad: wp.array2d(dtype=scalar),
                      p: int, t: int, j: int, n_sub: int, lam_l: scalar, k_len: scalar) -> scalar:
        """dU_path / dQ[p, t, j] for an interior waypoint t (1 <= t <= W - 2)."""
        W = paths.shape[1]
        S = (W - 1) * n_sub + 1
        g = lam_l * k_len * (scalar(2.0) * paths[p, t, j] - paths[p, t - 1, j] - paths[p, t + 1, j])
        centre = t * n_sub
        inv = one / scalar(n_sub)
        for s in range(centre - n_sub + 1, centre + n_sub):
            w = one - scalar(wp.abs(s - centre)) * inv
            g += w * sub_grad[p * S + s, j]
        return g

    @wp.func
    def linear_value(x: wp.array2d(dtype=scalar), row: int, l: int, lim: LimitTables):
        """(v, c2): the value ``v = sum_k c_k x[row, j_k]`` of linear limit l and
        ``c2 = sum_k c_k^2`` (the squared norm of its row, for the projection)."""
        v = zero
        c2 = zero
        for k in range(lim.lin_start[l], lim.lin_start[l + 1]):
            c = lim.lin_coef[k]
            v += c * x[row, lim.lin_joint[k]]
            c2 += c * c
        return v, c2

    @wp.func
    def within_linear_limits(x: wp.array2d(dtype=scalar), row: int, lim: LimitTables,
                             tol: scalar) -> int:
        """1 if x[row] violates no linear limit by more than ``tol`` (``tol`` = 0: every
        ``lower <= v <= upper``), else 0."""
        for l in range(lim.lin_bounds.shape[0]):
            v, c2 = linear_value(x, row, l, lim)
            if lim.lin_bounds[l, 0] - v > tol or v - lim.lin_bounds[l, 1] > tol:
                return 0
        return 1

    @wp.func
    def within_limits_row(x: wp.array2d(dtype=scalar), row: int, lim: LimitTables,
                          tol: scalar) -> int:
        """1 if x[row] violates no box or linear limit by more than ``tol``
        (:func:`jwarp.core.limits.within_limits`), else 0."""
        for j in range(x.shape[1]):
            if lim.box[j, 0] - x[row, j] > tol or x[row, j] - lim.box[j, 1] > tol:
                return 0
        return within_linear_limits(x, row, lim, tol)

    @wp.func
    def project_row(x: wp.array2d(dtype=scalar), row: int, lim: LimitTables):
        """Project x[row, :] onto the box and the linear limits (alternating projections)."""
        n = x.shape[1]
        n_lin = lim.lin_bounds.shape[0]
        rounds = 1
        if n_lin > 0:
            rounds = n_rounds
        for _r in range(rounds):
            for j in range(n):
                x[row, j] = wp.clamp(x[row, j], lim.box[j, 0], lim.box[j, 1])
            for l in range(n_lin):
                v, c2 = linear_value(x, row, l, lim)
                excess = zero
                if v < lim.lin_bounds[l, 0]:
                    excess = v - lim.lin_bounds[l, 0]
                if v > lim.lin_bounds[l, 1]:
                    excess = v - lim.lin_bounds[l, 1]
                if excess != zero and c2 > zero:
                    for k in range(lim.lin_start[l], lim.lin_start[l + 1]):
                        jj = lim.lin_joint[k]
                        x[row, jj] = x[row, jj] - lim.lin_coef[k] * excess / c2
        if n_lin > 0:
            for j in range(n):
                x[row, j] = wp.clamp(x[row, j], lim.box[j, 0], lim.box[j, 1])

    return SimpleNamespace(
        scalar=scalar,
        zero=zero, one=one, half=half, n_rounds=n_rounds, LimitTables=LimitTables,
        length_scale=length_scale, waypoint_grad=waypoint_grad, linear_value=linear_value,
        within_linear_limits=within_linear_limits, within_limits_row=within_limits_row,
        project_row=project_row,
    )


@functools.cache
def substeps(scalar: type) -> wp.Kernel:
    """The linear substeps kernel (eq. 3.3), for ``scalar``."""

    @wp.kernel(module="unique")
    def substeps_kernel(
        # Data in:
        paths: wp.array3d(dtype=scalar),
        n_sub: int,
        # Data out:
        q_sub: wp.array2d(dtype=scalar),
    ):
        """Linear substeps (eq. 3.3). Launch dim (P, S); q_sub (P * S, n_dof)."""
        p, s = wp.tid()
        W = paths.shape[1]
        S = (W - 1) * n_sub + 1
        t = s // n_sub
        u = s - t * n_sub
        row = p * S + s
        if t >= W - 1:  # the goal, exactly
            for j in range(paths.shape[2]):
                q_sub[row, j] = paths[p, W - 1, j]
            return
        a = scalar(u) / scalar(n_sub)
        for j in range(paths.shape[2]):
            q0 = paths[p, t, j]
            q_sub[row, j] = q0 + a * (paths[p, t + 1, j] - q0)

    return substeps_kernel


@functools.cache
def path_cost(scalar: type) -> wp.Kernel:
    """The per-path cost kernel (length, collision, U_path), for ``scalar``."""
    sh = funcs(scalar)
    zero, half, length_scale = sh.zero, sh.half, sh.length_scale

    @wp.kernel(module="unique")
    def path_cost_kernel(
        # Data in:
        paths: wp.array3d(dtype=scalar),
        sub_cost: wp.array(dtype=scalar),
        n_sub: int,
        lam_l: scalar,
        norm_floor: scalar,
        # Data out:
        length: wp.array(dtype=scalar),
        collision: wp.array(dtype=scalar),
        total: wp.array(dtype=scalar),
        sub_max: wp.array(dtype=scalar),
    ):
        """Per path (launch dim P): length cost U_l (eq. 3.5, unweighted), summed substep
        cost sum_s sub_cost (eq. 3.9 + 3.12, weighted as given), U_path (eq. 3.16) and the
        largest substep cost max_s sub_cost (a feasibility screen: every term of a substep
        cost is >= 0, so max_s sub_cost < w c(margin) means no sphere is within margin)."""
        p = wp.tid()
        W = paths.shape[1]
        S = (W - 1) * n_sub + 1
        k_len = length_scale(paths, p, norm_floor)
        l = zero
        for t in range(W - 1):
            for j in range(paths.shape[2]):
                d = paths[p, t + 1, j] - paths[p, t, j]
                l += half * d * d
        c = zero
        m = zero
        for s in range(S):
            v = sub_cost[p * S + s]
            c += v
            m = wp.max(m, v)
        sub_max[p] = m
        length[p] = k_len * l
        collision[p] = c
        total[p] = c + lam_l * k_len * l

    return path_cost_kernel


@functools.cache
def path_grad(scalar: type) -> wp.Kernel:
    """The path gradient kernel (dU_path/dQ), for ``scalar``."""
    sh = funcs(scalar)
    zero, length_scale, waypoint_grad = sh.zero, sh.length_scale, sh.waypoint_grad

    @wp.kernel(module="unique")
    def path_grad_kernel(
        # Data in:
        paths: wp.array3d(dtype=scalar),
        sub_grad: wp.array2d(dtype=scalar),
        n_sub: int,
        lam_l: scalar,
        norm_floor: scalar,
        # Data out:
        grad: wp.array3d(dtype=scalar),
    ):
        """dU_path/dQ (P, W, n_dof), zero at start and goal. Launch dim (P, W)."""
        p, t = wp.tid()
        W = paths.shape[1]
        if t == 0 or t == W - 1:
            for j in range(paths.shape[2]):
                grad[p, t, j] = zero
            return
        k_len = length_scale(paths, p, norm_floor)
        for j in range(paths.shape[2]):
            grad[p, t, j] = waypoint_grad(paths, sub_grad, p, t, j, n_sub, lam_l, k_len)

    return path_grad_kernel


@functools.cache
def path_step(scalar: type) -> wp.Kernel:
    """The gradient step kernel (clamped, projected onto the limits), for
    ``scalar``."""
    sh = funcs(scalar)
    LimitTables, length_scale, waypoint_grad = sh.LimitTables, sh.length_scale, sh.waypoint_grad
    project_row = sh.project_row

    @wp.kernel(module="unique")
    def path_step_kernel(
        # Model:
        limits: LimitTables,
        # Data in:
        paths: wp.array3d(dtype=scalar),
        sub_grad: wp.array2d(dtype=scalar),
        n_sub: int,
        lam_l: scalar,
        norm_floor: scalar,
        step: scalar,
        max_step: scalar,
        active: wp.array(dtype=wp.int32),
        # Data out:
        paths_out: wp.array2d(dtype=scalar),
    ):
        """One gradient-descent step (eq. 3.18) with per-joint step clamp and projection
        onto the limits. Launch dim (P, W); paths_out is (P * W, n_dof) (a different buffer
        than ``paths``). Start, goal and paths with ``active[p] == 0`` are copied."""
        p, t = wp.tid()
        W = paths.shape[1]
        row = p * W + t
        n = paths.shape[2]
        if t == 0 or t == W - 1 or active[p] == 0:
            for j in range(n):
                paths_out[row, j] = paths[p, t, j]
            return
        k_len = length_scale(paths, p, norm_floor)
        for j in range(n):
            g = waypoint_grad(paths, sub_grad, p, t, j, n_sub, lam_l, k_len)
            d = wp.clamp(step * g, -max_step, max_step)
            paths_out[row, j] = paths[p, t, j] - d
        project_row(paths_out, row, limits)

    return path_step_kernel


@functools.cache
def project(scalar: type) -> wp.Kernel:
    """The kernel projecting rows onto the joint limits, for ``scalar``."""
    sh = funcs(scalar)
    LimitTables, project_row = sh.LimitTables, sh.project_row

    @wp.kernel(module="unique")
    def project_kernel(
        # Model:
        limits: LimitTables,
        # Data in/out:
        q: wp.array2d(dtype=scalar),
    ):
        """Project every row of q (B, n_dof) onto the joint limits, in place. Launch dim B."""
        b = wp.tid()
        project_row(q, b, limits)

    return project_kernel


@functools.cache
def gather(scalar: type) -> wp.Kernel:
    """The kernel packing chosen paths and their substeps, for ``scalar``."""

    @wp.kernel(module="unique")
    def gather_kernel(
        # Data in:
        paths: wp.array3d(dtype=scalar),
        q_sub: wp.array2d(dtype=scalar),
        idx: wp.array(dtype=wp.int32),
        n_sub: int,
        # Data out:
        paths_out: wp.array3d(dtype=scalar),
        q_sub_out: wp.array2d(dtype=scalar),
    ):
        """The paths ``idx[k]`` and their substeps, packed: ``paths_out[k] = paths[idx[k]]``
        (K, W, n_dof) and rows ``k * S + s`` of ``q_sub_out`` (K * S, n_dof). Launch dim
        (K, S); S >= W."""
        k, s = wp.tid()
        p = idx[k]
        W = paths.shape[1]
        S = (W - 1) * n_sub + 1
        for j in range(paths.shape[2]):
            q_sub_out[k * S + s, j] = q_sub[p * S + s, j]
        if s < W:
            for j in range(paths.shape[2]):
                paths_out[k, s, j] = paths[p, s, j]

    return gather_kernel


@functools.cache
def keep(scalar: type) -> wp.Kernel:
    """The kernel keeping paths as the final ones, for ``scalar``."""

    @wp.kernel(module="unique")
    def keep_kernel(
        # Data in:
        paths: wp.array3d(dtype=scalar),
        total: wp.array(dtype=scalar),
        length: wp.array(dtype=scalar),
        collision: wp.array(dtype=scalar),
        idx: wp.array(dtype=wp.int32),
        # Data out:
        final: wp.array3d(dtype=scalar),
        final_cost: wp.array2d(dtype=scalar),
    ):
        """Keep the current paths ``idx[k]`` as their final ones: ``final[p] = paths[p]`` and
        ``final_cost[p] = (U_path, U_l, collision)``. Launch dim (K, W)."""
        k, t = wp.tid()
        p = idx[k]
        for j in range(paths.shape[2]):
            final[p, t, j] = paths[p, t, j]
        if t == 0:
            final_cost[p, 0] = total[p]
            final_cost[p, 1] = length[p]
            final_cost[p, 2] = collision[p]

    return keep_kernel


@functools.cache
def select(scalar: type) -> wp.Kernel:
    """The kernel picking each problem's best start, for ``scalar``."""
    sh = funcs(scalar)
    zero = sh.zero

    @wp.kernel(module="unique")
    def select_kernel(
        # Data in:
        final: wp.array3d(dtype=scalar),
        final_cost: wp.array2d(dtype=scalar),
        feasible: wp.array(dtype=wp.int32),
        n_starts: int,
        # Data out:
        best: wp.array(dtype=wp.int32),
        best_path: wp.array3d(dtype=scalar),
        best_cost: wp.array2d(dtype=scalar),
    ):
        """Per problem b (launch dim B; its starts are paths b * n_starts ...): the best
        start, feasible ones first, then the lowest U_path (``final_cost[:, 0]``), as numpy's
        argmin picks it (the first minimum; the first NaN if there is one), its path and
        costs."""
        b = wp.tid()
        p0 = b * n_starts
        any_feasible = int(0)
        for i in range(n_starts):
            if feasible[p0 + i] != 0:
                any_feasible = 1
        bi = int(0)
        bv = zero
        nan = int(0)
        for i in range(n_starts):
            v = final_cost[p0 + i, 0]
            if any_feasible != 0 and feasible[p0 + i] == 0:
                v = scalar(wp.inf)
            if nan == 0:
                if wp.isnan(v):
                    bi = i
                    nan = 1
                elif i == 0 or v < bv:
                    bi = i
                    bv = v
        best[b] = bi
        p = p0 + bi
        for t in range(final.shape[1]):
            for j in range(final.shape[2]):
                best_path[b, t, j] = final[p, t, j]
        for c in range(3):
            best_cost[b, c] = final_cost[p, c]

    return select_kernel


@functools.cache
def kernels(scalar: type) -> SimpleNamespace:
    """Path kernels for one scalar type (``wp.float32`` or ``wp.float64``):
    :func:`funcs`' tables and functions and every kernel of the builders (a facade: the
    builders build only the kernel asked for)."""
    sh = funcs(scalar)
    return SimpleNamespace(
        scalar=scalar, LimitTables=sh.LimitTables, length_scale=sh.length_scale,
        waypoint_grad=sh.waypoint_grad, linear_value=sh.linear_value,
        within_linear_limits=sh.within_linear_limits,
        within_limits_row=sh.within_limits_row, project_row=sh.project_row,
        substeps=substeps(scalar), path_cost=path_cost(scalar),
        path_grad=path_grad(scalar), path_step=path_step(scalar), project=project(scalar),
        gather=gather(scalar), keep=keep(scalar), select=select(scalar),
    )


@functools.cache
def cartesian_funcs(scalar: type) -> SimpleNamespace:
    """The ``@wp.func`` helpers the Cartesian length cost's kernels share, for one scalar
    type; built once per type (issue 40 item 5: the kernels are built one each, by
    :func:`cartesian_centres`, :func:`cartesian_cost`, :func:`cartesian_grad` and
    :func:`cartesian_arcs`, from these)."""
    from jwarp.kernels import fk as fk_kernels

    fk = fk_kernels.kernels(scalar)
    vec3, mat44, FrameTables = fk.vec3, fk.mat44, fk.FrameTables
    zero = scalar(0.0)
    half = scalar(0.5)

    @wp.func
    def centre(frames: wp.array2d(dtype=mat44), row: int, f: int, pos: vec3) -> vec3:
        T = frames[row, f]
        return vec3(T[0, 0] * pos[0] + T[0, 1] * pos[1] + T[0, 2] * pos[2] + T[0, 3],
                    T[1, 0] * pos[0] + T[1, 1] * pos[1] + T[1, 2] * pos[2] + T[1, 3],
                    T[2, 0] * pos[0] + T[2, 1] * pos[1] + T[2, 2] * pos[2] + T[2, 3])

    @wp.func
    def scale(xs: wp.array2d(dtype=vec3), p: int, W: int, norm_floor: scalar) -> scalar:
        """K = (W - 1) / max(U_c1(q_W, q_1), norm_floor) of path p."""
        d2 = zero
        for s in range(xs.shape[1]):
            d = xs[p * W + W - 1, s] - xs[p * W, s]
            d2 += wp.dot(d, d)
        return scalar(W - 1) / wp.max(half * d2, norm_floor)

    return SimpleNamespace(
        scalar=scalar,
        fk=fk, vec3=vec3, mat44=mat44, FrameTables=FrameTables, zero=zero, half=half,
        centre=centre, scale=scale,
    )


@functools.cache
def cartesian_centres(scalar: type) -> wp.Kernel:
    """The sphere centres kernel of the Cartesian length cost, for ``scalar``."""
    sh = cartesian_funcs(scalar)
    vec3, mat44, centre = sh.vec3, sh.mat44, sh.centre

    @wp.kernel(module="unique")
    def centres_kernel(
        # Model:
        sph_frame: wp.array(dtype=wp.int32),
        sph_pos: wp.array(dtype=vec3),
        # Data in:
        frames: wp.array2d(dtype=mat44),
        # Data out:
        xs: wp.array2d(dtype=vec3),
    ):
        """Sphere centres xs (P * W, n_spheres) [m]. Launch dim (P * W, n_spheres)."""
        r, s = wp.tid()
        xs[r, s] = centre(frames, r, sph_frame[s], sph_pos[s])

    return centres_kernel


@functools.cache
def cartesian_cost(scalar: type) -> wp.Kernel:
    """The Cartesian length cost kernel, for ``scalar``."""
    sh = cartesian_funcs(scalar)
    vec3, zero, half, scale = sh.vec3, sh.zero, sh.half, sh.scale

    @wp.kernel(module="unique")
    def cost_kernel(
        # Data in:
        xs: wp.array2d(dtype=vec3),
        W: int,
        lam_c: scalar,
        norm_floor: scalar,
        # Data out:
        cart: wp.array(dtype=scalar),
        total: wp.array(dtype=scalar),
    ):
        """cart[p] = U_c (unweighted) and total[p] += lam_c U_c. Launch dim P."""
        p = wp.tid()
        k = scale(xs, p, W, norm_floor)
        u = zero
        for t in range(W - 1):
            for s in range(xs.shape[1]):
                d = xs[p * W + t + 1, s] - xs[p * W + t, s]
                u += half * wp.dot(d, d)
        cart[p] = k * u
        total[p] = total[p] + lam_c * k * u

    return cost_kernel


@functools.cache
def cartesian_grad(scalar: type) -> wp.Kernel:
    """The Cartesian length cost's gradient kernel, for ``scalar``."""
    sh = cartesian_funcs(scalar)
    fk, vec3, mat44, FrameTables, zero = sh.fk, sh.vec3, sh.mat44, sh.FrameTables, sh.zero
    scale = sh.scale

    @wp.kernel(module="unique")
    def grad_kernel(
        # Model:
        model: FrameTables,
        sph_frame: wp.array(dtype=wp.int32),
        # Data in:
        frames: wp.array2d(dtype=mat44),
        q: wp.array2d(dtype=scalar),
        xs: wp.array2d(dtype=vec3),
        W: int,
        n_sub: int,
        lam_c: scalar,
        norm_floor: scalar,
        # Data out:
        force: wp.array2d(dtype=vec3),
        moment: wp.array2d(dtype=vec3),
        sub_grad: wp.array2d(dtype=scalar),
    ):
        """Adds lam_c dU_c/dq_t to the substep gradient row ``p * S + t * n_sub`` of every
        interior waypoint t (that row enters waypoint t's gradient with weight 1 and no
        other waypoint's). Launch dim (P, W); scratch force, moment (P * W, n_frames);
        ``frames`` were computed at the waypoints ``q`` (P * W, n_dof)."""
        p, t = wp.tid()
        if t == 0 or t == W - 1:
            return
        r = p * W + t
        nf = model.order.shape[0]
        for i in range(nf):
            force[r, i] = vec3(zero, zero, zero)
            moment[r, i] = vec3(zero, zero, zero)
        k = lam_c * scale(xs, p, W, norm_floor)
        for s in range(xs.shape[1]):
            x = xs[r, s]
            f = k * (scalar(2.0) * x - xs[r - 1, s] - xs[r + 1, s])
            fr = sph_frame[s]
            force[r, fr] = force[r, fr] + f
            moment[r, fr] = moment[r, fr] + wp.cross(x, f)
        for kk in range(nf):  # subtree sums, leaves to root
            i = model.order[nf - 1 - kk]
            pi = model.parent[i]
            if pi >= 0:
                force[r, pi] = force[r, pi] + force[r, i]
                moment[r, pi] = moment[r, pi] + moment[r, i]
        S = (W - 1) * n_sub + 1
        row = p * S + t * n_sub
        for i in range(nf):
            m0 = model.cpl_start[i]
            m1 = model.cpl_start[i + 1]
            if m1 > m0:
                T = frames[r, i]
                z = vec3(T[0, 2], T[1, 2], T[2, 2])
                F = force[r, i]
                gi = wp.dot(z, F)
                if model.prismatic[i] == 0:
                    gi = wp.dot(z, moment[r, i] - wp.cross(vec3(T[0, 3], T[1, 3], T[2, 3]), F))
                hp = fk.coupling_harmonic_slope(model, i, r, q)
                for m in range(m0, m1):
                    jm = model.cpl_joint[m]
                    sub_grad[row, jm] = sub_grad[row, jm] + fk.coupling_weight(model, m, r, q, hp) * gi

    return grad_kernel


@functools.cache
def cartesian_arcs(scalar: type) -> wp.Kernel:
    """The kernel of the spheres' arc lengths along the paths, for ``scalar``."""
    sh = cartesian_funcs(scalar)
    vec3, zero = sh.vec3, sh.zero

    @wp.kernel(module="unique")
    def arcs_kernel(
        # Data in:
        xs: wp.array2d(dtype=vec3),
        S: int,
        fine: int,
        # Data out:
        arc: wp.array(dtype=scalar),
    ):
        """The longest sphere arc of each path (the sweep check's substep count):
        ``arc[p] = max over segments t and spheres s of sum_k |x_s(row k+1) - x_s(row k)|``
        over the ``fine`` rows of segment t, rows ``p * S + t * fine + k`` of ``xs`` (S rows
        per path: W - 1 segments of ``fine`` rows and the last waypoint). ``arc`` must be
        zero before. Launch dim (P, W - 1, n_spheres)."""
        p, t, s = wp.tid()
        base = p * S + t * fine
        a = zero
        for k in range(fine):
            a += wp.length(xs[base + k + 1, s] - xs[base + k, s])
        wp.atomic_max(arc, p, a)

    return arcs_kernel


@functools.cache
def cartesian_kernels(scalar: type) -> SimpleNamespace:
    """Kernels of the Cartesian length cost (thesis eqs. 3.6-3.7) summed over every
    collision sphere ("the motion of all body parts") at the waypoints:

    ``U_c(Q) = (W - 1) / max(U_c1(q_W, q_1), norm_floor) * sum_t U_c1(q_{t+1}, q_t)`` with
    ``U_c1(a, b) = 1/2 sum_s |x_s(a) - x_s(b)|^2`` [m^2] (x_s: sphere centres). Its gradient
    w.r.t. an interior waypoint t is ``J_s(q_t)^T f_s`` summed over the spheres with the
    force ``f_s = K (2 x_s(q_t) - x_s(q_{t-1}) - x_s(q_{t+1}))``, mapped onto the joints as
    the collision kernels map their forces (subtree sums of force and moment, projected
    on each joint axis). Waypoint frames ``frames (P * W, n_frames)`` come from the FK
    kernel on the paths as rows ``p * W + t``.

    A facade: :func:`cartesian_funcs`' ``fk`` and the kernels of the builders (which build
    only the kernel asked for).
    """
    sh = cartesian_funcs(scalar)
    return SimpleNamespace(
        fk=sh.fk, centres=cartesian_centres(scalar), cost=cartesian_cost(scalar),
        grad=cartesian_grad(scalar), arcs=cartesian_arcs(scalar),
    )
