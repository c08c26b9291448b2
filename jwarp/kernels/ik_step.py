"""Device-resident IK iteration kernels (math only; thesis 3.3.3 eq. 3.21-3.24).

The solver (:class:`jwarp.solvers.ik.IKSolver`) keeps a batch of ``B = P * S``
configurations (P problems x S starts, configuration ``b = p * S + s``) on the device. Per
iteration, after the cost kernels of :mod:`jwarp.kernels.ik` and the collision kernels:

* ``check`` (launch dim B): the configuration's task error norms ``|e_v|`` and ``|e_w|``
  over the task rows (all 6, or ``[v_x, v_y, w_z]`` of a planar robot: position rows 0, 1
  and rotation row 5), "on target" (``|e_v| < tol_pos``, ``|e_w| < tol_rot`` and, elastic,
  the last DH row change ``delta < tol_rho``) and, for on-target configurations that are
  not done and whose collision cost is below the screen (or on a ``full`` check
  iteration), the exact feasibility check **in float64**: within the box and linear limits
  up to ``limit_tol``, every sphere more than ``margin`` from the world and from every
  sphere it may collide with (the frames recomputed in float64 at the configuration, at its
  compensation rows when elastic). A feasible configuration is *done*: frozen from then on,
  its result row written, the counters ``counts = [done configurations, solved problems,
  near]`` raised atomically.
* ``pose`` (dim B, rigid robot): error and Jacobian of the frame from a walk along its
  chain (no frames stored), the values of FK + :mod:`jwarp.kernels.ik` ``pose_error``.
* ``near`` (dim B): the active configurations whose pose is on target, listed in
  ``idx[:counts[2]]`` (at most ``cap`` of them, the size of the gathered launch; the
  others wait) before the collision costs; only those need U_A and the check (``gather``
  packs them for the collision kernel, ``scatter_aux`` writes their U_A back).
* Per configuration ``done``: 0 active, 1 done (feasible), 2 frozen (``freeze_solved``: an
  active configuration of a solved problem stops in ``step``).
* ``step`` (launch dim B): the damped least-squares step in float64 (eq. 3.21-3.24)
  ``A = J J^T + mu^2 I`` (m x m over the task rows, m = 6 or 3), Cholesky ``A = L L^T``,
  ``dq = J^T A^-1 e`` and, on target, minus ``alpha (g - J^T A^-1 J g)`` (the U_A gradient
  ``g`` projected onto the nullspace), the whole step scaled so that no joint moves more
  than ``max_step``, then projected onto the joint limits (:mod:`jwarp.kernels.path`).
  Joints at a box limit that the step pushes outward are held (columns removed, the step
  recomputed); a start that stalls off target is re-seeded or gives up (``RestartArgs``,
  ``done[b] = 3``).
  Done configurations do not move; once ``counts`` say the solve is over
  (every configuration done, or every problem solved with ``stop_solved``) nothing moves
  and ``halt[0]`` becomes 1, which the next ``check`` obeys.
* ``finalize`` (dim B) writes the result row of the configurations that are not done,
  ``select`` (dim P) picks per problem the feasible start with the lowest U_A, else the
  smallest ``|e_v| + 0.1 |e_w|`` (first index on ties, like ``numpy.argmin``).

Result rows ``out (B, n_dof + 5)`` float64: ``[q (n_dof), |e_v|, |e_w|, U_A, feasible,
iterations]``. ``best (P, 2)`` int32: ``[chosen start, feasible starts]``.
"""


import functools
from types import SimpleNamespace

import warp as wp

from jwarp.kernels import collision as collision_kernels
from jwarp.kernels import fk as fk_kernels
from jwarp.kernels import ik as ik_cost_kernels
from jwarp.kernels import path as path_kernels
from jwarp.kernels.fk import ROWS_NOMINAL

#: result row columns after the n_dof joint values
COL_POS, COL_ROT, COL_AUX, COL_FEASIBLE, COL_ITERATIONS = range(5)
#: number of those columns
N_EXTRA = 5

f64 = wp.float64

#: weight of the squared rotation error [m^2/rad^2] in the restart's progress measure
#: ``|e_v|^2 + W_ROT |e_w|^2`` (the sqrt is applied to the rows)
W_ROT = 0.1
W_ROT_SQRT = W_ROT ** 0.5
#: a joint within this distance [rad or m] of a box limit counts as at the limit
LIMIT_HOLD = 1e-6


@wp.struct
class RestartArgs:
    """Re-seeding of stalled configurations, one kernel argument of ``step``.

    after: steps without progress before a re-seed (0: never); max_restarts: re-seeds per
    configuration before it gives up; progress: the fraction of its best cost a step
    must reach to count as progress; on_cost: the best cost set while on target (the
    tolerances' cost); seed (1,) int32: Warp random seed of the solve (an array, so a
    recorded launch reads each solve's); best (B,) float64, stall (B,)
    and count (B,) int32 per configuration; gave (P,) int32 starts given up per problem.
    """

    after: int
    max_restarts: int
    progress: f64
    on_cost: f64
    seed: wp.array(dtype=wp.int32)
    best: wp.array(dtype=f64)
    stall: wp.array(dtype=wp.int32)
    count: wp.array(dtype=wp.int32)
    gave: wp.array(dtype=wp.int32)


@functools.cache
def dls_funcs(scalar: type, planar: bool, n_dof: int) -> SimpleNamespace:
    """The local matrix types and ``@wp.func`` helpers of the damped least-squares step, for
    one scalar type, task and number of joints; built once per (scalar, planar, n_dof)
    (issue 40 item 5: the kernels are built one each, by :func:`dls`, :func:`step` and
    :func:`sample`, from these)."""
    M = 3 if planar else 6
    N = int(n_dof)
    PLANAR = int(planar)
    matm = wp.types.matrix((M, M), f64)
    vecm = wp.types.vector(M, f64)
    matmn = wp.types.matrix((M, N), f64)
    vecn = wp.types.vector(N, f64)
    zero = f64(0.0)
    one = f64(1.0)
    pk = path_kernels.funcs(scalar)

    @wp.func
    def task_row(r: int) -> int:
        """Row of the 6D Jacobian/error for task row r ([0, 1, 5] for a planar robot)."""
        if PLANAR != 0 and r == 2:
            return 5
        return r

    @wp.func
    def cholesky_solve(A: matm, e: vecm, f: vecm, mu2: f64):
        """(A^-1 e, A^-1 f) for the SPD A by Cholesky A = L L^T (the pivot floor
        ``1e-12 mu2`` only guards round-off)."""
        L = matm()
        for i in range(M):
            for j in range(i + 1):
                s = A[i, j]
                for k in range(j):
                    s -= L[i, k] * L[j, k]
                if i == j:
                    L[i, i] = wp.sqrt(wp.max(s, mu2 * f64(1e-12)))
                else:
                    L[i, j] = s / L[j, j]
        x = vecm()
        y = vecm()
        for i in range(M):  # L z = rhs
            sx = e[i]
            sy = f[i]
            for k in range(i):
                sx -= L[i, k] * x[k]
                sy -= L[i, k] * y[k]
            x[i] = sx / L[i, i]
            y[i] = sy / L[i, i]
        for ii in range(M):  # L^T x = z
            i = M - 1 - ii
            sx = x[i]
            sy = y[i]
            for k in range(i + 1, M):
                sx -= L[k, i] * x[k]
                sy -= L[k, i] * y[k]
            x[i] = sx / L[i, i]
            y[i] = sy / L[i, i]
        return x, y

    @wp.func
    def dls_step(jac: wp.array3d(dtype=scalar), err: wp.array2d(dtype=scalar),
                 grad: wp.array2d(dtype=scalar), b: int, use_ns: int, mu2: f64, alpha: f64,
                 max_step: f64) -> vecn:
        """The scaled step of configuration b (float64): ``J^T A^-1 e`` minus, if
        ``use_ns``, ``alpha (g - J^T A^-1 J g)``, with ``A = J J^T + mu2 I`` over the task
        rows, times ``min(1, max_step / max_j |dq_j|)``."""
        free = vecn()
        for j in range(N):
            free[j] = one
        return dls_step_masked(jac, err, grad, b, use_ns, mu2, alpha, max_step, free)

    @wp.func
    def dls_step_masked(jac: wp.array3d(dtype=scalar), err: wp.array2d(dtype=scalar),
                        grad: wp.array2d(dtype=scalar), b: int, use_ns: int, mu2: f64,
                        alpha: f64, max_step: f64, free: vecn) -> vecn:
        """:func:`dls_step` over the joints with ``free[j] = 1`` only (the columns of J and
        the entries of g of the others are zero, so they do not move)."""
        J = matmn()
        e = vecm()
        g = vecn()
        for r in range(M):
            rr = task_row(r)
            e[r] = f64(err[b, rr])
            for j in range(N):
                J[r, j] = f64(jac[b, rr, j]) * free[j]
        for j in range(N):
            g[j] = f64(grad[b, j]) * free[j]
        A = J * wp.transpose(J)
        for i in range(M):
            A[i, i] = A[i, i] + mu2
        x, y = cholesky_solve(A, e, J * g, mu2)
        Jt = wp.transpose(J)
        d = Jt * x
        if use_ns != 0:
            d = d - alpha * (g - Jt * y)
        big = zero
        for j in range(N):
            big = wp.max(big, wp.abs(d[j]))
        return d * wp.min(one, max_step / wp.max(big, f64(1e-300)))

    @wp.func
    def task_cost(err: wp.array2d(dtype=scalar), b: int) -> f64:
        """The progress measure of a configuration: ``|e_v|^2 + W_ROT |e_w|^2`` over the
        task rows [m^2]."""
        c = zero
        for r in range(M):
            rr = task_row(r)
            v = f64(err[b, rr])
            if rr >= 3:
                v = v * f64(W_ROT_SQRT)
            c += v * v
        return c

    @wp.func
    def sample_row(q: wp.array2d(dtype=scalar), b: int, state: wp.uint32,
                   limits: pk.LimitTables):
        """q[b] uniform in the box, redrawn (up to 20 times) until it meets the linear
        limits, else projected onto them."""
        for attempt in range(20):
            for j in range(N):
                lo = limits.box[j, 0]
                q[b, j] = lo + scalar(wp.randf(state)) * (limits.box[j, 1] - lo)
            if pk.within_linear_limits(q, b, limits, scalar(0.0)) != 0:
                return
        pk.project_row(q, b, limits)

    return SimpleNamespace(
        scalar=scalar,
        planar=planar, n_dof=n_dof, M=M, N=N, PLANAR=PLANAR, matm=matm, vecm=vecm,
        matmn=matmn, vecn=vecn, zero=zero, one=one, pk=pk, task_row=task_row,
        cholesky_solve=cholesky_solve, dls_step=dls_step, dls_step_masked=dls_step_masked,
        task_cost=task_cost, sample_row=sample_row,
    )


@functools.cache
def dls(scalar: type, planar: bool, n_dof: int) -> wp.Kernel:
    """The kernel of the scaled step alone (for tests), for ``scalar``, the task and
    ``n_dof``."""
    sh = dls_funcs(scalar, planar, n_dof)
    N, dls_step = sh.N, sh.dls_step

    @wp.kernel(module="unique", enable_backward=False)
    def dls_kernel(
        # Data in:
        jac: wp.array3d(dtype=scalar),
        err: wp.array2d(dtype=scalar),
        grad: wp.array2d(dtype=scalar),
        on: wp.array(dtype=wp.int32),
        mu2: f64,
        alpha: f64,
        max_step: f64,
        # Data out:
        dq: wp.array2d(dtype=f64),
    ):
        """The scaled step dq (B, n_dof) alone (no limits, no state): for tests."""
        b = wp.tid()
        d = dls_step(jac, err, grad, b, on[b], mu2, alpha, max_step)
        for j in range(N):
            dq[b, j] = d[j]

    return dls_kernel


@functools.cache
def step(scalar: type, planar: bool, n_dof: int) -> wp.Kernel:
    """The projected DLS step kernel, for ``scalar``, the task and ``n_dof``."""
    sh = dls_funcs(scalar, planar, n_dof)
    N, vecn, zero, one, pk = sh.N, sh.vecn, sh.zero, sh.one, sh.pk
    dls_step_masked, task_cost, sample_row = sh.dls_step_masked, sh.task_cost, sh.sample_row

    @wp.kernel(module="unique", enable_backward=False)
    def step_kernel(
        # Model:
        limits: pk.LimitTables,
        # Data in:
        jac: wp.array3d(dtype=scalar),
        err: wp.array2d(dtype=scalar),
        grad: wp.array2d(dtype=scalar),
        on: wp.array(dtype=wp.int32),
        solved: wp.array(dtype=wp.int32),
        n_starts: int,
        freeze_solved: int,
        stop_solved: int,
        n_problems: int,
        mu2: f64,
        alpha: f64,
        max_step: f64,
        # Data in/out:
        q: wp.array2d(dtype=scalar),
        done: wp.array(dtype=wp.int32),
        counts: wp.array(dtype=wp.int32),
        iterations: wp.array(dtype=wp.int32),
        halt: wp.array(dtype=wp.int32),
        restart: RestartArgs,
    ):
        """One projected DLS step of every active configuration (module docstring);
        ``iterations[b]`` counts the steps. With ``freeze_solved`` an active configuration
        of a solved problem is frozen instead (``done[b] = 2``, counted in ``counts[0]``).
        Joints at a box limit that the step would push outward are held (their columns
        removed, the step recomputed). A configuration off target whose
        :func:`task_cost` has not fallen below ``restart.progress`` times its best for
        ``restart.after`` steps is re-seeded (uniform in the limits, Warp's random stream
        from ``restart.seed``); after ``restart.max_restarts`` re-seeds it gives up
        (``done[b] = 3``, counted in ``counts[0]``; a problem all of whose starts gave up
        is counted in ``counts[3]``). Launch dim B."""
        b = wp.tid()
        stop = int(0)
        if counts[0] >= q.shape[0]:
            stop = 1
        if stop_solved != 0 and counts[1] + counts[3] >= n_problems:
            stop = 1
        if b == 0:
            halt[0] = stop
            counts[2] = 0  # the next iteration's near-target count
        if stop != 0 or done[b] != 0:
            return
        p = b // n_starts
        if freeze_solved != 0 and solved[p] != 0:
            done[b] = 2
            wp.atomic_add(counts, 0, 1)
            return
        if restart.after > 0:
            c = task_cost(err, b)
            if on[b] != 0:  # on target: progress is measured from the tolerance on
                restart.best[b] = restart.on_cost
                restart.stall[b] = 0
            elif c < restart.progress * restart.best[b]:
                restart.best[b] = c
                restart.stall[b] = 0
            else:
                restart.stall[b] = restart.stall[b] + 1
                if restart.stall[b] >= restart.after:
                    k = restart.count[b]
                    if k >= restart.max_restarts:
                        done[b] = 3
                        wp.atomic_add(counts, 0, 1)
                        if wp.atomic_add(restart.gave, p, 1) == n_starts - 1:
                            wp.atomic_add(counts, 3, 1)
                        return
                    restart.count[b] = k + 1
                    restart.stall[b] = 0
                    restart.best[b] = f64(1.0e300)
                    state = wp.rand_init(restart.seed[0] + 7919 * (k + 1), b)
                    sample_row(q, b, state, limits)
                    iterations[b] = iterations[b] + 1
                    return
        free = vecn()
        for j in range(N):
            free[j] = one
        d = dls_step_masked(jac, err, grad, b, on[b], mu2, alpha, max_step, free)
        held = int(0)
        for j in range(N):
            lo = f64(limits.box[j, 0])
            hi = f64(limits.box[j, 1])
            qj = f64(q[b, j])
            tol = f64(LIMIT_HOLD)
            if (d[j] < zero and qj <= lo + tol) or (d[j] > zero and qj >= hi - tol):
                free[j] = zero
                held = 1
        if held != 0:
            d = dls_step_masked(jac, err, grad, b, on[b], mu2, alpha, max_step, free)
        for j in range(N):
            q[b, j] = scalar(f64(q[b, j]) + d[j])
        pk.project_row(q, b, limits)
        iterations[b] = iterations[b] + 1

    return step_kernel


@functools.cache
def sample(scalar: type, planar: bool, n_dof: int) -> wp.Kernel:
    """The random seeds kernel, for ``scalar``, the task and ``n_dof``."""
    sh = dls_funcs(scalar, planar, n_dof)
    pk, sample_row = sh.pk, sh.sample_row

    @wp.kernel(module="unique", enable_backward=False)
    def sample_kernel(
        # Model:
        limits: pk.LimitTables,
        # Data in:
        seed: int,
        # Data out:
        q: wp.array2d(dtype=scalar),
    ):
        """Random seeds: q[b] uniform in the box, redrawn (up to 20 times) until it meets
        the linear limits, else projected onto them (the device twin of
        :func:`jwarp.core.limits.sample_within_limits`; Warp's random stream). Launch dim B."""
        b = wp.tid()
        sample_row(q, b, wp.rand_init(seed, b), limits)

    return sample_kernel


@functools.cache
def dls_kernels(scalar: type, planar: bool, n_dof: int) -> SimpleNamespace:
    """The damped least-squares step for one scalar type, task (6 rows, or the 3 rows
    [v_x, v_y, w_z] of a planar robot) and number of joints (the sizes of the local
    matrices). The linear algebra runs in float64 either way. A facade: :func:`dls_funcs`'
    types and functions and every kernel of the builders (which build only the kernel
    asked for)."""
    sh = dls_funcs(scalar, planar, n_dof)
    return SimpleNamespace(
        scalar=scalar, planar=planar, rows=sh.M, n_dof=sh.N, task_row=sh.task_row,
        cholesky_solve=sh.cholesky_solve, dls_step=sh.dls_step,
        dls_step_masked=sh.dls_step_masked, task_cost=sh.task_cost,
        dls=dls(scalar, planar, n_dof), step=step(scalar, planar, n_dof),
        sample=sample(scalar, planar, n_dof),
    )


@functools.cache
def check_funcs(scalar: type, planar: bool) -> SimpleNamespace:
    """The tables, scratch and ``@wp.func`` helpers the check kernels share, for a solver
    of one scalar type (the exact check itself in float64, module docstring); built once per
    (scalar, planar) (issue 40 item 5: the kernels are built one each, by :func:`check`,
    :func:`near`, :func:`gather`, :func:`scatter_aux`, :func:`pose`, :func:`reset`,
    :func:`repeat_targets`, :func:`finalize` and :func:`select`, from these)."""
    fk64 = fk_kernels.funcs(f64)
    ck64 = collision_kernels.funcs(f64)
    pk64 = path_kernels.funcs(f64)
    fk = fk_kernels.funcs(scalar)
    ikk = ik_cost_kernels.kernels(scalar)
    PLANAR = int(planar)
    NPOS = 2 if planar else 3
    zero = f64(0.0)

    @wp.func
    def task_errors(err: wp.array2d(dtype=scalar), b: int):
        """(|e_v|, |e_w|) over the task rows (float64)."""
        pe = zero
        for r in range(NPOS):
            v = f64(err[b, r])
            pe += v * v
        re = zero
        if PLANAR != 0:
            v = f64(err[b, 5])
            re = v * v
        else:
            for r in range(3):
                v = f64(err[b, r + 3])
                re += v * v
        return wp.sqrt(pe), wp.sqrt(re)

    @wp.func
    def write_result(out: wp.array2d(dtype=f64), b: int, q: wp.array2d(dtype=scalar),
                     pe: f64, re: f64, aux: f64, feasible: f64, iterations: f64):
        """Result row out[b] (module docstring): q[b] (in float64), |e_v|, |e_w|, U_A,
        feasible (1 or 0) and the iterations."""
        n = q.shape[1]
        for j in range(n):
            out[b, j] = f64(q[b, j])
        out[b, n + COL_POS] = pe
        out[b, n + COL_ROT] = re
        out[b, n + COL_AUX] = aux
        out[b, n + COL_FEASIBLE] = feasible
        out[b, n + COL_ITERATIONS] = iterations

    @wp.func
    def collision_free_row(q: wp.array2d(dtype=f64), b: int, rho: wp.array3d(dtype=f64),
                           use_rho: int, model: fk64.FrameTables, spheres: ck64.SphereTables,
                           world: ck64.WorldModel, use_world: int, use_self: int, margin: f64,
                           frames: wp.array2d(dtype=fk64.mat44),
                           xs: wp.array2d(dtype=fk64.vec3)) -> int:
        """1 if every sphere of q[b] keeps more than ``margin`` [m] from the world and from
        every sphere it may collide with (the decision of
        :func:`jwarp.world.collision.is_collision_free`, which takes the minimum distance;
        here the first distance <= margin ends the check). Frames at the rows ``rho[b]``
        when ``use_rho`` (= 1), else the nominal ones."""
        nf = model.order.shape[0]
        for k in range(nf):
            fk64.write_frame(model, b, model.order[k], q, rho, b, use_rho, frames, b)
        for s in range(spheres.sph_frame.shape[0]):
            x = ck64.sphere_centre(frames, b, spheres.sph_frame[s], spheres.sph_pos[s])
            xs[b, s] = x
            if use_world != 0:
                r = spheres.sph_rad[s]
                d, g, obj = ck64.world_distance(world, x, r + margin + f64(1e-9), -1)
                if obj != -1 and d - r <= margin:
                    return 0
        if use_self != 0:
            for fp in range(spheres.fpair_a.shape[0]):
                fa = spheres.fpair_a[fp]
                fb = spheres.fpair_b[fp]
                ca = ck64.sphere_centre(frames, b, fa, spheres.bound_pos[fa])
                cb = ck64.sphere_centre(frames, b, fb, spheres.bound_pos[fb])
                rfb = spheres.bound_rad[fb]
                if wp.length(ca - cb) - spheres.bound_rad[fa] - rfb <= margin:
                    for e in range(spheres.fpair_start[fp], spheres.fpair_start[fp + 1]):
                        sa = spheres.ent_sphere[e]
                        xa = xs[b, sa]
                        ra = spheres.sph_rad[sa]
                        if wp.length(xa - cb) - ra - rfb <= margin:
                            for p in range(spheres.ent_start[e], spheres.ent_start[e + 1]):
                                sb = spheres.pair_b[p]
                                if wp.length(xa - xs[b, sb]) - ra - spheres.sph_rad[sb] <= margin:
                                    return 0
        return 1

    @wp.struct
    class CheckTables:
        """Float64 tables of the exact check, one kernel argument."""

        model: fk64.FrameTables
        spheres: ck64.SphereTables
        world: ck64.WorldModel
        use_world: int
        use_self: int
        limits: pk64.LimitTables
        limit_tol: f64

    @wp.struct
    class CheckScratch:
        """Float64 per-configuration scratch of the exact check, one kernel argument:
        q64 (B, n_dof), rho64 (B or 1, n_frames, 5), frames (>= B, n_frames), xs (>= B, S)."""

        q64: wp.array2d(dtype=f64)
        rho64: wp.array3d(dtype=f64)
        frames: wp.array2d(dtype=fk64.mat44)
        xs: wp.array2d(dtype=fk64.vec3)

    return SimpleNamespace(
        scalar=scalar,
        planar=planar, fk64=fk64, fk=fk, ck64=ck64, pk64=pk64, ikk=ikk, PLANAR=PLANAR,
        NPOS=NPOS, zero=zero, task_errors=task_errors, write_result=write_result,
        collision_free_row=collision_free_row, CheckTables=CheckTables,
        CheckScratch=CheckScratch,
    )


@functools.cache
def check(scalar: type, planar: bool) -> wp.Kernel:
    """The exact feasibility check kernel (float64), for a solver of ``scalar``."""
    sh = check_funcs(scalar, planar)
    pk64, task_errors, write_result = sh.pk64, sh.task_errors, sh.write_result
    collision_free_row, CheckTables = sh.collision_free_row, sh.CheckTables
    CheckScratch = sh.CheckScratch

    @wp.kernel(module="unique", enable_backward=False)
    def check_kernel(
        # Model:
        tables: CheckTables,
        # Data in:
        q: wp.array2d(dtype=scalar),
        err: wp.array2d(dtype=scalar),
        cost_a: wp.array(dtype=scalar),
        coll_cost: wp.array(dtype=scalar),
        delta: wp.array(dtype=scalar),
        rows: wp.array3d(dtype=scalar),
        use_rows: int,
        tol_pos: f64,
        tol_rot: f64,
        tol_rho: f64,
        screen: f64,
        full: int,
        margin: f64,
        n_starts: int,
        halt: wp.array(dtype=wp.int32),
        iterations: wp.array(dtype=wp.int32),
        # Scratch:
        scratch: CheckScratch,
        # Data out:
        on: wp.array(dtype=wp.int32),
        done: wp.array(dtype=wp.int32),
        solved: wp.array(dtype=wp.int32),
        counts: wp.array(dtype=wp.int32),
        out: wp.array2d(dtype=f64),
    ):
        """On-target flags and the exact check of the candidates (module docstring).
        ``use_rows``: elastic (``delta`` and the compensation ``rows`` (B, n_frames, 9)
        take part). Launch dim B."""
        b = wp.tid()
        if halt[0] != 0 or done[b] != 0:
            return
        pe, re = task_errors(err, b)
        ok = int(0)
        if pe < tol_pos and re < tol_rot:
            ok = 1
        if use_rows != 0:
            if not (f64(delta[b]) < tol_rho):
                ok = 0
        on[b] = ok
        if ok == 0:
            return
        if full == 0 and not (f64(coll_cost[b]) < screen):
            return
        n = q.shape[1]
        q64 = scratch.q64
        for j in range(n):
            q64[b, j] = f64(q[b, j])
        if pk64.within_limits_row(q64, b, tables.limits, tables.limit_tol) == 0:
            return
        if use_rows != 0:
            for i in range(rows.shape[1]):
                for c in range(5):
                    scratch.rho64[b, i, c] = f64(rows[b, i, c])
        if collision_free_row(q64, b, scratch.rho64, use_rows, tables.model, tables.spheres,
                              tables.world, tables.use_world, tables.use_self, margin,
                              scratch.frames, scratch.xs) == 0:
            return
        done[b] = 1
        write_result(out, b, q, pe, re, f64(cost_a[b]), f64(1.0), f64(iterations[b]))
        wp.atomic_add(counts, 0, 1)
        if wp.atomic_max(solved, b // n_starts, 1) == 0:
            wp.atomic_add(counts, 1, 1)

    return check_kernel


@functools.cache
def near(scalar: type, planar: bool) -> wp.Kernel:
    """The kernel listing the on-target configurations, for a solver of ``scalar``."""
    sh = check_funcs(scalar, planar)
    task_errors = sh.task_errors

    @wp.kernel(module="unique", enable_backward=False)
    def near_kernel(
        # Data in:
        err: wp.array2d(dtype=scalar),
        tol_pos: f64,
        tol_rot: f64,
        cap: int,
        halt: wp.array(dtype=wp.int32),
        done: wp.array(dtype=wp.int32),
        # Data out:
        on: wp.array(dtype=wp.int32),
        counts: wp.array(dtype=wp.int32),
        idx: wp.array(dtype=wp.int32),
        coll_cost: wp.array(dtype=scalar),
        cost: wp.array(dtype=scalar),
        grad: wp.array2d(dtype=scalar),
    ):
        """Before the collision costs: the active configurations whose pose is on target
        (``|e_v| < tol_pos``, ``|e_w| < tol_rot``; the elastic condition comes later, in
        ``check``) are listed in ``idx[:min(counts[2], cap)]`` (in no particular order),
        ``on[b] = 0`` for the others: only the listed ones need U_A and the check this
        iteration. ``cap``: the size of the gathered U_A launch; an on-target configuration
        beyond it (``counts[2]`` still counts it) is deferred to a later iteration: its U_A
        and gradient are zeroed (a pose-only step) and its collision cost set above any
        screen (no exact check before a ``full`` one). Launch dim B."""
        b = wp.tid()
        if halt[0] != 0 or done[b] != 0:
            return
        pe, re = task_errors(err, b)
        if pe < tol_pos and re < tol_rot:
            k = wp.atomic_add(counts, 2, 1)
            if k < cap:
                idx[k] = b
            else:
                coll_cost[b] = scalar(1.0e30)
                cost[b] = scalar(0.0)
                for j in range(grad.shape[1]):
                    grad[b, j] = scalar(0.0)
        else:
            on[b] = 0

    return near_kernel


@functools.cache
def gather(scalar: type, planar: bool) -> wp.Kernel:
    """The kernel gathering the configurations to check, for a solver of ``scalar``."""

    @wp.kernel(module="unique", enable_backward=False)
    def gather_kernel(
        # Data in:
        q: wp.array2d(dtype=scalar),
        idx: wp.array(dtype=wp.int32),
        counts: wp.array(dtype=wp.int32),
        # Data out:
        q_near: wp.array2d(dtype=scalar),
    ):
        """q_near[k] = q[idx[k]] for the ``counts[2]`` listed configurations; the rows
        after them (padding up to the launch size) repeat the first. Launch dim K."""
        k = wp.tid()
        kk = k
        if k >= counts[2]:
            kk = 0
        b = idx[kk]
        for j in range(q.shape[1]):
            q_near[k, j] = q[b, j]

    return gather_kernel


@functools.cache
def scatter_aux(scalar: type, planar: bool) -> wp.Kernel:
    """The kernel writing U_A and its gradient to the listed rows, for a solver of
    ``scalar``."""
    sh = check_funcs(scalar, planar)
    ikk = sh.ikk

    @wp.kernel(module="unique", enable_backward=False)
    def scatter_aux_kernel(
        # Data in:
        q: wp.array2d(dtype=scalar),
        q_default: wp.array2d(dtype=scalar),
        default_stride: int,
        idx: wp.array(dtype=wp.int32),
        counts: wp.array(dtype=wp.int32),
        near_cost: wp.array(dtype=scalar),
        near_grad: wp.array2d(dtype=scalar),
        use_collision: int,
        lam_l: scalar,
        # Data out:
        coll_cost: wp.array(dtype=scalar),
        cost: wp.array(dtype=scalar),
        grad: wp.array2d(dtype=scalar),
    ):
        """U_A and dU_A/dq (:mod:`jwarp.kernels.ik` ``aux_row``, as ``aux_cost``) of the
        listed configurations from their collision costs ``near_cost``/``near_grad``
        (row k of the gathered batch), written to their own rows. Launch dim K."""
        k = wp.tid()
        if k >= counts[2]:
            return
        b = idx[k]
        c = scalar(0.0)
        if use_collision != 0:
            c = near_cost[k]
            coll_cost[b] = c
        cost[b] = ikk.aux_row(q, b, q_default, b * default_stride, c, near_grad, k,
                              use_collision, lam_l, grad)

    return scatter_aux_kernel


@functools.cache
def pose(scalar: type, planar: bool) -> wp.Kernel:
    """The rigid robot's pose error and Jacobian kernel, for a solver of ``scalar``."""
    sh = check_funcs(scalar, planar)
    fk, ikk = sh.fk, sh.ikk

    @wp.kernel(module="unique", enable_backward=False)
    def pose_kernel(
        # Model:
        model: fk.FrameTables,
        chain: wp.array(dtype=wp.int32),
        nominal: wp.array3d(dtype=scalar),
        orient: int,
        axis: fk.vec3,
        # Data in:
        q: wp.array2d(dtype=scalar),
        target: wp.array(dtype=fk.mat44),
        halt: wp.array(dtype=wp.int32),
        done: wp.array(dtype=wp.int32),
        # Data out:
        jac: wp.array3d(dtype=scalar),
        err: wp.array2d(dtype=scalar),
    ):
        """The rigid robot's 6D error (B, 6) and Jacobian (B, 6, n_dof) of the frame
        ``chain[-1]``, walking only its chain (twice: the frame, then the joint axes,
        :mod:`jwarp.kernels.fk` ``chain_pose`` and ``chain_jacobian``) with no frames
        stored: the values of FK + :mod:`jwarp.kernels.ik` ``pose_error`` (the same
        functions, ``pose_error_row`` and ``apply_orientation`` included). Configurations
        that are done keep theirs. Launch dim B."""
        b = wp.tid()
        if halt[0] != 0 or done[b] != 0:
            return
        R, p = fk.chain_pose(model, chain, b, q, ROWS_NOMINAL, nominal, 0)
        ikk.pose_error_row(R, p, target[b], b, err)
        fk.chain_jacobian(model, chain, b, q, ROWS_NOMINAL, nominal, 0, p, jac)
        ikk.apply_orientation(orient, axis, R, target[b], b, err, jac)

    return pose_kernel


@functools.cache
def reset(scalar: type, planar: bool) -> wp.Kernel:
    """The kernel zeroing the solver state, for a solver of ``scalar``."""

    @wp.kernel(module="unique", enable_backward=False)
    def reset_kernel(
        # Data in:
        n_problems: int,
        # Data out:
        done: wp.array(dtype=wp.int32),
        on: wp.array(dtype=wp.int32),
        iterations: wp.array(dtype=wp.int32),
        solved: wp.array(dtype=wp.int32),
        counts: wp.array(dtype=wp.int32),
        halt: wp.array(dtype=wp.int32),
        restart: RestartArgs,
    ):
        """Zero the solver state of a new solve. Launch dim B (>= n_problems)."""
        b = wp.tid()
        done[b] = 0
        on[b] = 0
        iterations[b] = 0
        restart.best[b] = f64(1.0e300)
        restart.stall[b] = 0
        restart.count[b] = 0
        if b < n_problems:
            solved[b] = 0
            restart.gave[b] = 0
        if b == 0:
            counts[0] = 0
            counts[1] = 0
            counts[2] = 0
            counts[3] = 0
            halt[0] = 0

    return reset_kernel


@functools.cache
def repeat_targets(scalar: type, planar: bool) -> wp.Kernel:
    """The kernel repeating each problem's target over its starts, for a solver of
    ``scalar``."""

    @wp.kernel(module="unique", enable_backward=False)
    def repeat_targets_kernel(
        # Data in:
        targets: wp.array(dtype=fk_kernels.funcs(scalar).mat44),
        n_starts: int,
        # Data out:
        out: wp.array(dtype=fk_kernels.funcs(scalar).mat44),
    ):
        """out[b] = targets[b // n_starts]. Launch dim B."""
        b = wp.tid()
        out[b] = targets[b // n_starts]

    return repeat_targets_kernel


@functools.cache
def finalize(scalar: type, planar: bool) -> wp.Kernel:
    """The kernel writing the result rows of the unfinished configurations, for a
    solver of ``scalar``."""
    sh = check_funcs(scalar, planar)
    zero, task_errors, write_result = sh.zero, sh.task_errors, sh.write_result

    @wp.kernel(module="unique", enable_backward=False)
    def finalize_kernel(
        # Data in:
        q: wp.array2d(dtype=scalar),
        err: wp.array2d(dtype=scalar),
        cost_a: wp.array(dtype=scalar),
        done: wp.array(dtype=wp.int32),
        iterations: wp.array(dtype=wp.int32),
        max_iterations: int,
        # Data out:
        out: wp.array2d(dtype=f64),
    ):
        """Result rows of the configurations that are not done (feasible): their last q,
        task error norms and U_A, infeasible, ``max_iterations`` (a start that gave up:
        its own step count). Launch dim B."""
        b = wp.tid()
        if done[b] == 1:
            return
        pe, re = task_errors(err, b)
        its = f64(max_iterations)
        if done[b] == 3:
            its = f64(iterations[b])
        write_result(out, b, q, pe, re, f64(cost_a[b]), zero, its)

    return finalize_kernel


@functools.cache
def select(scalar: type, planar: bool) -> wp.Kernel:
    """The best-start selection kernel, for a solver of ``scalar``."""
    sh = check_funcs(scalar, planar)
    zero = sh.zero

    @wp.kernel(module="unique", enable_backward=False)
    def select_kernel(
        # Data in:
        out: wp.array2d(dtype=f64),
        n_starts: int,
        n_dof: int,
        # Data out:
        best: wp.array2d(dtype=wp.int32),
    ):
        """best[p] = [chosen start, feasible starts] of problem p: the feasible start with
        the lowest U_A, else the smallest |e_v| + 0.1 |e_w| (first on ties). Launch dim P."""
        p = wp.tid()
        n_feas = int(0)
        best_f = int(-1)
        val_f = zero
        best_i = int(0)
        val_i = zero
        for s in range(n_starts):
            b = p * n_starts + s
            if out[b, n_dof + COL_FEASIBLE] != zero:
                v = out[b, n_dof + COL_AUX]
                if n_feas == 0 or v < val_f:
                    best_f = s
                    val_f = v
                n_feas += 1
            k = out[b, n_dof + COL_POS] + out[b, n_dof + COL_ROT] * f64(0.1)
            if s == 0 or k < val_i:
                best_i = s
                val_i = k
        if n_feas > 0:
            best[p, 0] = best_f
        else:
            best[p, 0] = best_i
        best[p, 1] = n_feas

    return select_kernel


@functools.cache
def check_kernels(scalar: type, planar: bool) -> SimpleNamespace:
    """Feasibility check, result rows and best-start selection for a solver of one scalar
    type; the exact check itself runs in float64 (module docstring): :func:`check_funcs`'
    tables and functions and every kernel of the builders (a facade: the builders build
    only the kernel asked for)."""
    sh = check_funcs(scalar, planar)
    return SimpleNamespace(
        scalar=scalar, planar=planar, task_errors=sh.task_errors,
        write_result=sh.write_result, within_limits_row=sh.pk64.within_limits_row,
        collision_free_row=sh.collision_free_row, CheckTables=sh.CheckTables,
        CheckScratch=sh.CheckScratch, check=check(scalar, planar),
        near=near(scalar, planar), gather=gather(scalar, planar),
        scatter_aux=scatter_aux(scalar, planar), pose=pose(scalar, planar),
        reset=reset(scalar, planar), repeat_targets=repeat_targets(scalar, planar),
        finalize=finalize(scalar, planar), select=select(scalar, planar),
    )
