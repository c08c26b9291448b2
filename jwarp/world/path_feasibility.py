"""Feasibility of configurations and paths (the checks every planner here shares).

``collision_free`` (configurations), ``path_feasible`` (paths: continuous on the rigid
model, :mod:`jwarp.world.motion`; substeps at their torque equilibria on the elastic one),
``check_endpoints`` (errors naming the row and the clearance), substeps and their sizing,
and the path shapes (``initial_paths``, ``polyline_path``). :mod:`jwarp.solvers.planning`
and :mod:`jwarp.solvers.planning.rrt` use them; they use neither.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any, cast

import numpy as np
import warp as wp

from jwarp.core.arrays import (
    finite_as,
    init_warp,
    real_array,
    real_number,
    resolve_device,
)
from jwarp.core.device import numpy_dtype, put_model, scalar_type
from jwarp.core.limits import describe_violation, sample_within_limits, within_limits
from jwarp.core.types import ArrayLike, DeviceLike, DTypeLike
from jwarp.kernels import path as path_kernels
from jwarp.kinematics.transmission import untransmitted, without_transmission
from jwarp.model import RobotModel
from jwarp.utils.checks import check_int
from jwarp.world import collision

if TYPE_CHECKING:
    from jwarp.world.sdf import World

#: feasibility checks use substeps with sphere motion <= voxel / SWEEP_SAFETY
SWEEP_SAFETY = 2.0
#: most substeps per segment of the final feasibility check
MAX_CHECK_SUBSTEPS = 256
#: the elastic equilibrium of the feasibility checks (:func:`elastic_equilibrium`):
#: damped updates (lam), most updates, tolerance [rad] (0.1 um at 1 m)
ELASTIC_CHECK: dict[str, Any] = {"lam": 0.7, "max_iter": 30, "tol": 1e-7}


def check_world(robot: RobotModel, world: World) -> None:
    """TypeError/ValueError unless ``world`` is a World of the robot's workspace dimension."""
    if world is None:
        raise ValueError("world: required (a jwarp.world.World)")
    collision.check_world(robot, world)


def check_endpoints(robot: RobotModel, world: World, q: np.ndarray, name: str, margin: float,
                    rho_kappa: Any = None, device: DeviceLike = None,
                    self_margin: float = 0.0, per_world: int = 0) -> np.ndarray:
    """ValueError naming ``name`` (and the row) if a configuration is outside the limits or
    in collision (closer than ``margin`` to an obstacle or to itself: the message names the
    link and the object, or the two links, and their distance), or, on the elastic
    model (``rho_kappa``: compliances), if its torque equilibrium does not converge
    (:data:`ELASTIC_CHECK`): then nothing can be said about its collisions. The checks run
    on ``device`` (None: Warp's default device).
    Returns (N,) bool: the configurations the spheres alone keep free (the others were
    proven free by the mesh certificate, :mod:`jwarp.world.mesh_check`)."""
    ok = within_limits(robot, q)
    if not ok.all():
        i = int(np.nonzero(~ok)[0][0])
        where = f"{name}[{i}]" if len(q) > 1 else name
        raise ValueError(f"{where}: outside the joint limits: {describe_violation(robot, q[i])}")
    rho = None
    if rho_kappa is not None:
        rho, conv = elastic_equilibrium(robot, q, rho_kappa, device=device)
        if not conv.all():
            i = int(np.nonzero(~conv)[0][0])
            where = f"{name}[{i}]" if len(q) > 1 else name
            c = ELASTIC_CHECK
            raise ValueError(f"kappa: the elastic equilibrium at {where} does not converge in "
                             f"{c['max_iter']} torque updates (lam {c['lam']:g}) to {c['tol']:g} "
                             f"rad, so its collisions cannot be checked; lower kappa")
    spheres = collision_free(robot, world, q, margin, rho=rho, device=device,
                             self_margin=self_margin, per_world=per_world, meshes=False)
    free = spheres
    if not spheres.all() and rho is None:
        from jwarp.world.collision import mesh_certified

        free = mesh_certified(robot, q, world, spheres, margin, self_margin, device, per_world)
    if not free.all():
        i = int(np.nonzero(~free)[0][0])
        where = f"{name}[{i}]" if len(q) > 1 else name
        from jwarp.world.collision import closest_pair_text, min_distances
        w_i = world.select(i) if per_world and world.n_worlds > 1 else world
        rho_i = None if rho is None else rho[i:i + 1]
        md = np.asarray(min_distances(robot, q[i:i + 1], w_i, rho=rho_i, device=device,
                                      dtype=np.float64))[0]
        hit_world = bool(md[0] <= margin)
        pair = closest_pair_text(robot, q[i], w_i, self_collision=not hit_world,
                                 rho=None if rho_i is None else rho_i[0], device=device)
        what = (f"{pair} (margin {margin:g} m)" if hit_world else
                f"{pair} (self margin {self_margin:g} m)")
        raise ValueError(f"{where}: configuration is in collision: {what}")
    return spheres


def collision_free(robot: RobotModel, world: World, q: np.ndarray, margin: float,
                   kappa: ArrayLike | None = None, rho: ArrayLike | None = None, device: DeviceLike = None,
                   self_margin: float = 0.0, per_world: int = 0,
                   meshes: bool = True) -> np.ndarray:
    """(N,) bool: q (N, n_dof) collision-free: more than ``margin`` [m] from the world and
    more than ``self_margin`` [m] between the robot's own spheres. A thin call of
    :func:`jwarp.world.collision.is_collision_free` (the one check; here in the planners'
    argument order, float64, ``self_margin`` 0 by default) that adds the elastic model.

    With ``rho`` (N, n_frames, 5) the frames are those DH rows; with ``kappa`` (and no
    rho) the elastic model in its torque equilibrium (:func:`elastic_equilibrium`, to
    1e-7 rad: 0.1 um at 1 m). A configuration whose equilibrium does not converge is not
    collision-free (its frames are unknown). ``meshes``: as
    :func:`jwarp.world.collision.is_collision_free` (the mesh certificate proves what the
    spheres refuse, rigid model only)."""
    col = collision
    q = np.ascontiguousarray(real_array(q, "q"))
    converged = None
    if rho is None and kappa is not None:
        rho, converged = elastic_equilibrium(robot, q, kappa, device=device)
        conv = converged.reshape(-1)
        if not conv.all():  # unknown frames (NaN rows): checked as zeros, reported not free
            rho = np.where(conv[:, None, None], rho, 0.0)
    free = np.asarray(col.is_collision_free(robot, q, world, margin=margin, rho=rho,
                                            device=device, dtype=np.float64,
                                            self_margin=self_margin, per_world=per_world,
                                            meshes=meshes),
                      bool).reshape(-1)
    return free if converged is None else free & converged.reshape(-1)


def elastic_equilibrium(robot: RobotModel, q: np.ndarray, kappa: ArrayLike, device: DeviceLike = None
                        ) -> tuple[np.ndarray, np.ndarray]:
    """The elastic model's equilibrium at q (N, n_dof) as the feasibility checks solve it
    (:data:`ELASTIC_CHECK`, float64): ``(rho (N, n_frames, 5), converged (N,) bool)``."""
    from jwarp.kinematics.equilibrium import fk_elastic

    # the checks see the links' joint values (transmission errors already applied)
    model = robot
    q = np.asarray(q, np.float64)
    if model.has_harmonic and model.has_coupling_harmonic:
        # the coupled frames' harmonic terms need the commanded values: the robot's own tables
        q = untransmitted(model, q)
    else:
        model = without_transmission(model)
    res = fk_elastic(model, q, kappa, device=device, dtype=np.float64, **ELASTIC_CHECK)
    return np.asarray(res.rho), np.asarray(res.converged, bool)


def substeps(paths: Any, n_substeps: int, *, device: DeviceLike = None, dtype: DTypeLike = None) -> np.ndarray:
    """Linear substeps (eq. 3.3) of paths (..., W, n_dof) -> (..., S, n_dof) with
    S = (W - 1) n_substeps + 1 (every waypoint included, the goal last)."""
    init_warp()
    a = real_array(paths, "paths")
    if a.ndim < 2 or a.shape[-2] < 2:
        raise ValueError(f"paths: expected shape (..., W >= 2, n_dof), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError("paths: contains NaN or inf")
    a = finite_as(a, numpy_dtype(scalar_type(np.float64 if dtype is None else dtype)), "paths")
    n_sub = check_substeps(n_substeps)
    scalar = scalar_type(a.dtype)
    W, n = a.shape[-2:]
    flat = a.reshape(-1, W, n)
    S = (W - 1) * n_sub + 1
    dev = resolve_device(device)
    p: wp.array = wp.array(flat, dtype=scalar, device=dev)
    out = wp.empty((flat.shape[0] * S, n), dtype=scalar, device=dev)
    wp.launch(path_kernels.substeps(scalar), dim=(flat.shape[0], S),
              inputs=[p, n_sub], outputs=[out], device=dev)
    return out.numpy().reshape(a.shape[:-2] + (S, n))


def path_feasible(robot: RobotModel, world: World, paths: Any, n_substeps: int, *, margin: float = 0.0,
                  kappa: ArrayLike | None = None, device: DeviceLike = None,
                  endpoint_margin: float | None = None, self_margin: float = 0.0,
                  meshes: bool | None = None) -> np.ndarray:
    """Feasibility of paths (..., W, n_dof): every waypoint within the joint limits and,
    on the rigid model, every sphere at clearance >= ``margin`` [m] along the whole
    continuous motion (:mod:`jwarp.world.motion`; ``min(margin, endpoint_margin)`` on the
    first and last segment; ``n_substeps`` is not used). On the elastic model (``kappa``)
    the ``n_substeps`` linear substeps per segment are checked at their torque equilibria.
    Returns (...,) bool. Runs on ``device`` (None: Warp's default device). ``meshes``:
    the mesh certificate proves what the spheres leave unproven (None: the check's
    :attr:`~jwarp.world.motion.MotionOptions.meshes`; rigid model only)."""
    model = robot
    check_world(model, world)
    a = real_array(paths, "paths")
    if a.ndim < 2 or a.shape[-1] != model.n_dof or a.shape[-2] < 2:
        raise ValueError(f"paths: expected shape (..., W >= 2, {model.n_dof}), got {a.shape}")
    if kappa is None:
        flat = a.reshape(-1, a.shape[-2], a.shape[-1])
        res = certify_check(model, world, device=device).check(
            flat, margin=margin, endpoint_margin=endpoint_margin, self_margin=self_margin,
            meshes=meshes)
        return res.ok.reshape(a.shape[:-2])
    q = substeps(a, n_substeps, device=device)
    free = collision_free(model, world, q.reshape(-1, model.n_dof), margin, kappa=kappa,
                          device=device, self_margin=self_margin)
    free = cast(np.ndarray, free.reshape(q.shape[:-1]).all(axis=-1))
    return free & within_limits(model, a).all(axis=-1)


def certify_check(robot: RobotModel, world: World, device: DeviceLike = None) -> Any:
    """The continuous check (:class:`jwarp.world.motion.MotionCheck`, the default
    :class:`jwarp.world.motion.MotionOptions`: up to 4000 evaluations per segment) that
    :func:`path_feasible` (the rigid model), the RRT-Connect's edges and the planner's
    certificate of an RRT fallback path share: one cached check per (robot, world, device),
    so a path the trees accept is proven by the same pairs, margins and evaluation budget
    when the planner certifies it (the planner's iterations use a smaller budget, which
    leaves a path grazing a self pair for ~0.1 mm "not yet proven")."""
    from jwarp.world.motion import motion_check

    return motion_check(robot, world, device=device)


def check_substeps(n_substeps: Any) -> int:
    return check_int(n_substeps, "n_substeps", 1)
    return int(n_substeps)


def sphere_centres(robot: RobotModel, q: np.ndarray, device: DeviceLike = None) -> np.ndarray:
    """World centres (N, n_spheres, 3) [m] of the collision spheres at q (N, n_dof)."""
    from jwarp.kinematics.fk import fk

    frames = np.asarray(fk(robot, np.asarray(q, np.float64), device=device))
    idx, pos, _ = robot.sphere_arrays()
    f = frames[:, idx]
    return np.einsum("nsij,sj->nsi", f[..., :3, :3], pos) + f[..., :3, 3]


def substeps_for_voxel(robot: RobotModel, paths: Any, voxel_size: float, *,
                       safety: float = 1.0, max_substeps: int = 64, device: DeviceLike = None) -> int:
    """Substeps per segment so that no sphere centre moves more than ``voxel_size / safety``
    between two substeps of ``paths`` (..., W, n_dof) (thesis 3.3.1: N_u adjusted to the
    step length and the voxel size). The motion of each segment is measured on a fine
    (16 per segment) linear interpolation (its FK on ``device``; None: the preferred
    device). Clamped to [1, max_substeps]."""
    voxel_size = real_number(voxel_size, "voxel_size")
    if not (voxel_size > 0 and math.isfinite(voxel_size)):
        raise ValueError(f"voxel_size: expected a number > 0 [m], got {voxel_size!r}")
    return int(substeps_per_path(robot, paths, voxel_size, safety=safety,
                                 max_substeps=max_substeps, device=device).max(initial=1))


def substeps_per_path(robot: RobotModel, paths: Any, voxel_size: float, *,
                      safety: float = 1.0, max_substeps: int = 64, device: DeviceLike = None
                      ) -> np.ndarray:
    """:func:`substeps_for_voxel` of each path of ``paths`` (..., W, n_dof) on its own:
    (P,) int, P the number of paths (one FK call for all of them)."""
    voxel_size = real_number(voxel_size, "voxel_size")
    if not (voxel_size > 0 and math.isfinite(voxel_size)):
        raise ValueError(f"voxel_size: expected a number > 0 [m], got {voxel_size!r}")
    a = real_array(paths, "paths")
    W, n = a.shape[-2:]
    fine = 16
    flat = a.reshape(-1, W, n)
    u = np.arange(fine)[:, None] / fine
    q = (flat[:, :-1, None] + u * np.diff(flat, axis=1)[:, :, None]).reshape(len(flat), -1, n)
    q = np.concatenate([q, flat[:, -1:]], axis=1)            # (P, (W-1)*16+1, n)
    seg = _longest_arcs(robot, q, fine, device)   # per path, on the device
    return np.clip(np.ceil(seg * safety / voxel_size), 1, max_substeps).astype(np.int64)


def _longest_arcs(robot: RobotModel, q: np.ndarray, fine: int, device: DeviceLike) -> np.ndarray:
    """Per path of ``q`` (P, S, n_dof) (S = (W - 1) fine + 1 rows): the longest arc of a
    sphere centre over one segment [m] (float64 FK, sphere centres and the sums in three
    launches on ``device``; no spheres: 0)."""
    P, S, n = q.shape
    init_warp()
    dev = resolve_device(device)
    m = put_model(robot, dev, np.float64)
    sph = m.spheres
    if sph.n_spheres == 0 or S < 2:
        return np.zeros(P)
    from jwarp.kinematics.launch import launch_fk

    k = path_kernels.cartesian_kernels(wp.float64)
    N = P * S
    frames = launch_fk(m, wp.array(np.ascontiguousarray(q.reshape(N, n), np.float64),
                                   dtype=wp.float64, device=dev))
    xs = wp.empty((N, sph.n_spheres), dtype=k.fk.vec3, device=dev)
    wp.launch(k.centres, dim=(N, sph.n_spheres), inputs=[sph.sph_frame, sph.sph_pos, frames],
              outputs=[xs], device=dev)
    arc = wp.zeros(P, dtype=wp.float64, device=dev)
    wp.launch(k.arcs, dim=(P, (S - 1) // fine, sph.n_spheres), inputs=[xs, S, fine],
              outputs=[arc], device=dev)
    return arc.numpy()


def initial_paths(start: np.ndarray, goal: np.ndarray, n_waypoints: int, kind: str = "straight",
                  *, robot: RobotModel | None = None, n_via: tuple[int, int] = (1, 3),
                  rng: np.random.Generator | None = None, world: World | None = None,
                  device: DeviceLike = None, per_world: int = 0) -> np.ndarray:
    """Initial guesses (B, W, n_dof) from start/goal (B, n_dof).

    ``kind``: "straight" (the line in joint space) or "random" (1-3 random via points
    inside the robot's limits, connected linearly with start and goal; the W waypoints are
    spread evenly along the polyline's joint-space length) - thesis 3.5.1. With ``world``
    the via points are drawn from configurations whose spheres are collision-free
    (rejection sampling on ``device``, None: Warp's default device; plain random ones if
    none is found; guesses only: no mesh certificate). ``per_world`` > 0 with a batch of
    worlds (:meth:`jwarp.world.World.batch`): row b is a problem of world
    ``b // per_world``, and its via points are free in that world (0: in every world).
    """
    start = np.asarray(start, np.float64)
    goal = np.asarray(goal, np.float64)
    W = n_waypoints
    s = np.linspace(0.0, 1.0, W)[None, :, None]
    if kind == "straight":
        return start[:, None] + s * (goal - start)[:, None]
    if kind != "random":
        raise ValueError(f"initial: unknown kind '{kind}' (expected 'straight', 'random', "
                         f"'mixed' or an array)")
    if robot is None:
        raise ValueError("robot: needed for random initial paths")
    rng = rng or np.random.default_rng()
    out = np.empty((len(start), W, start.shape[1]))
    ks = rng.integers(n_via[0], n_via[1] + 1, size=len(start))
    pool = sample_within_limits(robot, int(ks.sum()), rng)
    if world is not None and per_world > 0 and getattr(world, "n_worlds", 1) > 1:
        pool = _free_via_per_world(robot, world, ks, pool, rng, device, int(per_world))
    elif world is not None:
        cand = sample_within_limits(robot, max(64, 8 * int(ks.sum())), rng)
        free = cand[collision_free(robot, world, cand, 0.0, device=device, meshes=False)]
        if len(free):
            pool = free[rng.integers(0, len(free), size=int(ks.sum()))]
    first = np.concatenate([[0], np.cumsum(ks)[:-1]])     # each row's first via point
    for k in np.unique(ks):
        rows = np.nonzero(ks == k)[0]
        via = pool[first[rows, None] + np.arange(k)[None]]    # (R, k, n)
        out[rows] = polyline_paths(start[rows], via, goal[rows], W)
    return out


def polyline_paths(start: np.ndarray, via: np.ndarray, goal: np.ndarray, n_waypoints: int
                   ) -> np.ndarray:
    """:func:`polyline_path` of many rows at once: start, goal (R, n_dof), via (R, k,
    n_dof) -> paths (R, W, n_dof)."""
    pts = np.concatenate([start[:, None], via, goal[:, None]], axis=1)   # (R, k + 2, n)
    seg = np.linalg.norm(np.diff(pts, axis=1), axis=2)                  # (R, k + 1)
    cum = np.concatenate([np.zeros((len(pts), 1)), np.cumsum(seg, axis=1)], axis=1)
    tq = np.linspace(0.0, 1.0, n_waypoints)[None] * cum[:, -1:]          # (R, W)
    # the segment of each waypoint: the breakpoints it has passed (interior ones)
    idx = (tq[:, :, None] >= cum[:, None, 1:-1]).sum(axis=2)             # (R, W) in [0, k]
    r = np.arange(len(pts))[:, None]
    c0, length = cum[r, idx], seg[r, idx]
    frac = np.where(length > 0, (tq - c0) / np.where(length > 0, length, 1.0), 0.0)
    frac = np.clip(frac, 0.0, 1.0)[..., None]
    out = pts[r, idx] + frac * (pts[r, idx + 1] - pts[r, idx])
    out[:, 0], out[:, -1] = start, goal
    return out


def _free_via_per_world(robot: RobotModel, world: World, ks: np.ndarray, pool: np.ndarray,
                        rng: np.random.Generator, device: DeviceLike, per_world: int
                        ) -> np.ndarray:
    """Via points (sum ks, n_dof) for rows b of ``per_world`` problems per world of a batch:
    each row's drawn from configurations free in its own world (one check of every
    world's candidates; a world without a free candidate keeps ``pool``'s)."""
    nw = int(world.n_worlds)
    rows = len(ks)
    if rows != nw * per_world:
        raise ValueError(f"per_world: {rows} rows are not {nw} worlds x {per_world}")
    owner = np.repeat(np.arange(rows) // per_world, ks)     # the world of each via point
    need = np.bincount(owner, minlength=nw)
    C = max(8, 8 * int(need.max(initial=0)))                # candidates per world
    cand = sample_within_limits(robot, nw * C, rng)
    free = np.asarray(collision_free(robot, world, cand, 0.0, device=device,
                                     per_world=C, meshes=False), bool).reshape(nw, C)
    n_free = free.sum(1)
    # the k-th free candidate of world w: free rows sorted first per world
    order = np.argsort(~free, axis=1, kind="stable")
    pick = np.floor(rng.random(len(owner)) * np.maximum(n_free[owner], 1)).astype(np.int64)
    out = pool.copy()
    has = n_free[owner] > 0
    idx = owner[has] * C + order[owner[has], pick[has]]
    out[has] = cand[idx]
    return out


def polyline_path(start: np.ndarray, via: np.ndarray, goal: np.ndarray, n_waypoints: int
                  ) -> np.ndarray:
    """A path (W, n_dof) through start (n_dof,), the via points (k, n_dof) and goal: the W
    waypoints spread evenly along the polyline's joint-space length (start and goal exact)."""
    pts = np.vstack([start, via, goal])
    out = np.empty((n_waypoints, len(start)))
    seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    if cum[-1] <= 0:
        out[:] = start
        return out
    tq = np.linspace(0.0, cum[-1], n_waypoints)
    for j in range(len(start)):
        out[:, j] = np.interp(tq, cum, pts[:, j])
    out[0], out[-1] = start, goal
    return out


# ====================================================================== objective
