"""Feasibility of worlds for a robot (thesis 3.5.1) and robot-fitted world grids.

A world is kept for a robot when at least 200 of 1000 random configurations within the
joint limits are collision-free (world and self-collision, sphere model):
:func:`feasible_fraction` measures it, :func:`feasible_simplex_world` searches seeds from
a start seed until a simplex world passes.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Sequence
from typing import Any

import numpy as np

from jwarp.core.arrays import real_number
from jwarp.core.device import content_key
from jwarp.core.types import DeviceLike, RobotLike
from jwarp.model import RobotModel
from jwarp.plugins.registry import robot as get_robot
from jwarp.utils.checks import check_int
from jwarp.world.sdf import World, grid_geometry

__all__ = ["random_configurations", "feasible_fraction", "feasible_simplex_world",
           "fixed_spheres", "robot_reach", "robot_world_grid"]


def random_configurations(robot: RobotLike, n: int, seed: int | Sequence[int] = 0) -> np.ndarray:
    """(n, n_dof) configurations drawn uniformly within the joint limits and the linear
    joint limits (rejection sampling), reproducible by ``seed``."""
    model = get_robot(robot)
    check_int(n, "n", 1)
    rng = np.random.default_rng(seed)
    lim = model.joint_limits
    out = np.empty((0, model.n_dof))
    for _ in range(1000):
        q = rng.uniform(lim[:, 0], lim[:, 1], (max(2 * (n - len(out)), 16), model.n_dof))
        ok = np.ones(len(q), bool)
        for ll in model.linear_limits:
            v = q[:, ll.joints] @ np.asarray(ll.coefficients, np.float64)
            ok &= (v >= ll.lower) & (v <= ll.upper)
        out = np.concatenate([out, q[ok]])
        if len(out) >= n:
            return out[:n]
    raise ValueError(f"robot: cannot sample configurations of '{model.name}' within its "
                     f"linear joint limits (acceptance too low)")


def feasible_fraction(robot: RobotLike, world: World | None, n: int = 1000, seed: int = 0, *,
                      margin: float = 0.0, device: DeviceLike = None) -> float:
    """Fraction of ``n`` random configurations (:func:`random_configurations`) whose
    spheres keep more than ``margin`` [m] from the world and from each other."""
    from jwarp.world.collision import is_collision_free

    model = get_robot(robot)
    q = random_configurations(model, n, seed)
    free = is_collision_free(model, q, world, margin, device=device, dtype=np.float64)
    return float(np.mean(free))


def fixed_spheres(robot: RobotLike, pad: float = 0.0, device: DeviceLike = None) -> list[tuple[np.ndarray, float]]:
    """Collision spheres on frames that no joint moves (the robot's fixed base), as
    ``(centre (workspace_dim,) [m], radius + pad [m])`` in the base frame."""
    from jwarp.kinematics.fk import fk

    model = get_robot(robot)
    pad = real_number(pad, "pad")
    if not np.isfinite(pad):
        raise ValueError(f"pad: expected a finite distance [m], got {pad!r}")
    moving = np.zeros(model.n_frames, bool)
    for i in model.topological_order:
        p = model.parents[i]
        moving[i] = bool(model.frames[i].coupling) or (p >= 0 and moving[p])
    f, pos, rad = model.sphere_arrays()
    if len(f) == 0:
        return []
    T = fk(model, np.zeros((1, model.n_dof)), device=device, dtype=np.float64)[0]
    out = []
    for s in range(len(f)):
        if not moving[f[s]]:
            c = T[f[s], :3, :3] @ pos[s] + T[f[s], :3, 3]
            out.append((c[:model.workspace_dim], float(rad[s]) + float(pad)))
    return out


#: reach boxes by (robot content key, n, seed): equal robots share one, an edited copy
#: (other limits, DH rows, spheres) has another key; the most recently used are kept
_REACH: OrderedDict[tuple, np.ndarray] = OrderedDict()
_REACH_MAX = 64
_REACH_LOCK = threading.Lock()


def robot_reach(robot: RobotLike, n: int = 2000, seed: int = 0, device: DeviceLike = None) -> np.ndarray:
    """(workspace_dim, 2) [m] box around every collision sphere of ``n`` random
    configurations (centres -/+ radii): the space a world for this robot must cover.
    Cached per robot content (:func:`jwarp.core.device.content_key`), ``n`` and ``seed``
    (the last 64 of them)."""
    from jwarp.kinematics.fk import fk

    model = get_robot(robot)
    key = (content_key(model), n, seed)
    with _REACH_LOCK:
        box = _REACH.get(key)
        if box is not None:
            _REACH.move_to_end(key)
            return box.copy()
    f, pos, rad = model.sphere_arrays()
    if len(f) == 0:
        raise ValueError(f"robot: '{model.name}' has no collision spheres")
    q = random_configurations(model, n, seed)
    T = fk(model, q, device=device, dtype=np.float64)[:, f]
    x = np.einsum("bsij,sj->bsi", T[..., :3, :3], pos) + T[..., :3, 3]
    lo = (x - rad[:, None]).min(axis=(0, 1))
    hi = (x + rad[:, None]).max(axis=(0, 1))
    d = model.workspace_dim
    box = np.stack([lo[:d], hi[:d]], axis=1)
    with _REACH_LOCK:
        _REACH[key] = box
        while len(_REACH) > _REACH_MAX:
            _REACH.popitem(last=False)
    return box.copy()


def robot_world_grid(robot: RobotLike, cells: int = 64, voxel_size: float | None = None,
                     pad: float = 0.0, device: DeviceLike = None
                     ) -> tuple[tuple[int, ...], np.ndarray, float]:
    """A grid covering the robot's reach (:func:`robot_reach`, plus ``pad`` [m]; its FK on
    ``device``): the longest side gets ``cells`` cells (or the given ``voxel_size``), the
    others as many cells of the same size as cover them, centred on the reach box.
    Returns ``(shape, limits (dim, 2), voxel_size)``."""
    check_int(cells, "cells", 2)
    pad = real_number(pad, "pad")
    if not np.isfinite(pad):
        raise ValueError(f"pad: expected a finite distance [m], got {pad!r}")
    box = robot_reach(robot, device=device)
    box = box + np.array([-pad, pad])
    span = box[:, 1] - box[:, 0]
    h = real_number(voxel_size, "voxel_size") if voxel_size is not None else \
        float(span.max()) / (cells - 1)
    if not np.isfinite(h) or h <= 0:
        raise ValueError(f"voxel_size: expected a positive number [m], got {voxel_size!r}")
    n = np.ceil(span / h - 1e-9).astype(int) + 1
    centre = box.mean(axis=1)
    lower = centre - 0.5 * (n - 1) * h
    return grid_geometry(len(n), shape=tuple(int(v) for v in n), limits=lower, voxel_size=h)


#: candidate simplex seeds drawn from a requested seed's own stream lie at and above this
#: offset, away from the small seeds users request
STREAM_SEED_OFFSET = 2 ** 32


def world_seed_candidates(seed: int, n: int) -> list[int]:
    """The simplex seeds :func:`feasible_simplex_world` tries for the requested ``seed``:
    ``seed`` itself, then ``n - 1`` seeds of its own stream
    (``numpy.random.SeedSequence(seed)``, offset by :data:`STREAM_SEED_OFFSET`). Distinct
    requested seeds therefore fall back onto distinct candidates: the old rule (``seed``,
    ``seed + 1``, ...) made consecutive seeds collapse onto one world (seeds 1-7 of
    justin19 all became world 11)."""
    for name, v, lo in (("seed", seed, 0), ("n", n, 1)):
        check_int(v, name, lo)
    seed = int(seed)
    extra = np.random.SeedSequence(seed).generate_state(int(n) - 1, dtype=np.uint64)
    return [seed] + [STREAM_SEED_OFFSET + int(x % (2 ** 62)) for x in extra]


def feasible_simplex_world(robot: RobotLike, *, seed: int = 0, min_feasible: int = 200,
                           n: int = 1000, max_tries: int = 50, cells: int = 64,
                           voxel_size: float | None = None, clear_base: bool = True,
                           margin: float = 0.0, dim: int | None = None, device: DeviceLike = None,
                           extent: float | None = None, **noise: Any) -> World:
    """The first simplex world of the candidates of ``seed`` (:func:`world_seed_candidates`:
    ``seed`` itself, then seeds of its own stream, so distinct seeds give distinct worlds) in
    which at least ``min_feasible`` of ``n`` random configurations are collision-free
    (thesis: 200 of 1000).

    The grid covers the robot's reach (:func:`robot_world_grid`), or, with ``extent`` [m],
    a cube (square) of that side with ``cells`` cells per axis centred on the reach box
    (the worlds of thesis Table 3.2: e.g. 64 x 64 over 1 x 1 m); with ``clear_base`` the
    robot's fixed spheres (plus two voxels) are kept free of obstacles. ``noise``:
    threshold, frequency, octaves, persistence (see :func:`simplex_world`). The result's
    ``meta`` records the seed used, the requested seed, the candidate's index and the
    feasible fraction. Raises ValueError when no candidate of ``max_tries`` passes (lower
    the obstacle density: raise ``threshold``).
    """
    from jwarp.world.simplex import simplex_world

    model: RobotModel = get_robot(robot)
    dim = model.workspace_dim if dim is None else dim
    if dim != model.workspace_dim:
        raise ValueError(f"dim: robot '{model.name}' needs {model.workspace_dim}D worlds, got {dim}")
    check_int(min_feasible, "min_feasible", 1, n)
    check_int(max_tries, "max_tries", 1)
    if extent is None:
        shape, limits, h = robot_world_grid(model, cells=cells, voxel_size=voxel_size,
                                            device=device)
    else:
        side = real_number(extent, "extent")
        if not (np.isfinite(side) and side > 0):
            raise ValueError(f"extent: expected a side length > 0 [m], got {extent!r}")
        if voxel_size is not None:
            raise ValueError("voxel_size: give cells or voxel_size with extent, not both")
        check_int(cells, "cells", 2)
        h = side / cells  # cells of h fill the side; limits are the first/last centres
        centre = robot_reach(model, device=device).mean(axis=1)
        lower = centre - 0.5 * (cells - 1) * h
        shape, limits, h = grid_geometry(dim, shape=(int(cells),) * dim, limits=lower,
                                         voxel_size=h)
    keep = fixed_spheres(model, pad=2 * h, device=device) if clear_base else []
    fractions = []
    check_int(seed, "seed", 0)
    for k, s in enumerate(world_seed_candidates(int(seed), int(max_tries))):
        world = simplex_world(dim, seed=s, shape=shape, limits=limits, keep_free=keep, **noise)
        frac = feasible_fraction(model, world, n, seed=s % 2 ** 32, margin=margin,
                                 device=device)
        fractions.append(frac)
        if frac * n >= min_feasible:
            world.meta.update(robot=model.name, requested_seed=int(seed), candidate=k,
                              feasible_fraction=frac, feasible_samples=int(n))
            return world
    raise ValueError(f"no simplex world among {max_tries} candidates of seed {seed} has "
                     f"{min_feasible}/{n} collision-free configurations for '{model.name}' "
                     f"(best {max(fractions) * n:.0f}); raise 'threshold' for fewer obstacles")
