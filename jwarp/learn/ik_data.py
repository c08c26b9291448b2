"""Training data of the IK networks, without labels (thesis 3.4.4, 3.5.1).

Targets are FK poses of random configurations that are collision-free in their world
(world and self-collision, sphere model; inside the joint limits, coupled limits
included), so every target is reachable. :func:`sample_targets` mixes up to four kinds
(fractions ``mix``, default 60/20/20/0 %):

- ``uniform``: random collision-free configurations;
- ``near obstacles``: of a pool of ``pool`` x as many collision-free configurations, those
  whose smallest sphere-to-world distance is smallest (the hard regions next to
  obstacles; without a world: the smallest self distance);
- ``border``: of the pool, those whose end-effector is farthest from the base frame's
  origin (the border of the workspace, reached only stretched out);
- ``scene tasks``: poses drawn from the scene's task distribution (the shelf:
  :func:`jwarp.world.scenes.shelf_grasp_poses`, tool poses between its boards, hand into the
  shelf), for a network that serves that task. Not every such pose is reachable (the
  unsupervised loss needs no label; their ``q`` rows are NaN).

Worlds (:func:`make_worlds`): ``"random"``: simplex worlds fitted to the robot
(:func:`jwarp.world.feasibility.feasible_simplex_world`, seeds ``seed + 100 i``, each with
at least 200 of 1000 random configurations collision-free); ``"shelf"``: the fixed shelf
scene (3D robots); ``"none"``: no world (self-collision only). The validation set
(:func:`make_ik_data`) uses its own worlds (random: seeds from ``seed + 100000``, unseen in
training) and targets, fixed by the seed.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from jwarp.core.types import DeviceLike, RobotLike
from jwarp.kinematics.fk import fk
from jwarp.plugins.registry import robot as get_robot
from jwarp.world.collision import is_collision_free, min_distances
from jwarp.world.feasibility import feasible_simplex_world, random_configurations
from jwarp.world.scenes import shelf_grasp_poses, shelf_world

if TYPE_CHECKING:
    from jwarp.model import RobotModel
    from jwarp.world.sdf import World

__all__ = ["sample_targets", "make_worlds", "IKData", "make_ik_data", "DEFAULT_MIX",
           "SCENE_TASKS", "check_mix"]

DEFAULT_MIX = (0.6, 0.2, 0.2, 0.0)  # uniform, near obstacles, workspace border, scene tasks
#: the task distribution of a world kind (:func:`make_worlds`), if it has one
SCENE_TASKS = {"shelf": shelf_grasp_poses}


def _free_configurations(model: RobotModel, n: int, world: World | None, rng: np.random.Generator,
                         device: DeviceLike) -> np.ndarray:
    out = np.empty((0, model.n_dof))
    for _ in range(200):
        q = random_configurations(model, max(2 * (n - len(out)), 64),
                                  seed=int(rng.integers(1 << 31)))
        free = is_collision_free(model, q, world, 0.0, device=device, dtype=np.float64)
        out = np.concatenate([out, q[free]])
        if len(out) >= n:
            return out[:n]
    raise ValueError(f"world: too few collision-free configurations of '{model.name}' "
                     f"({len(out)} of {n} found)")


def sample_targets(robot: RobotLike, frame: int | str, n: int, world: World | None = None, *, seed: int = 0,
                   mix: tuple | np.ndarray = DEFAULT_MIX, pool: int = 4, device: DeviceLike = None,
                   tasks: Callable[[int, np.random.Generator], np.ndarray] | None = None
                   ) -> tuple[np.ndarray, np.ndarray]:
    """``n`` targets (module docstring): returns ``(targets (n, 4, 4), q (n, n_dof))``
    float64, q the collision-free configuration each target came from (NaN for scene
    tasks). ``mix``: 3 or 4 fractions >= 0 (uniform, near obstacles, border[, scene
    tasks]); ``tasks(k, rng) -> (k, 4, 4)``: the scene's task poses (needed when the
    fourth fraction is > 0)."""
    model = get_robot(robot)
    f = model.frame_index(frame)
    mix = check_mix(mix)
    if mix[3] > 0 and tasks is None:
        raise ValueError("mix: a scene-task fraction needs a world with a task distribution "
                         f"(world kinds: {', '.join(SCENE_TASKS)})")
    rng = np.random.default_rng(seed)
    n_near = int(round(n * mix[1]))
    n_border = int(round(n * mix[2]))
    n_task = int(round(n * mix[3]))
    n_uni = n - n_near - n_border - n_task
    parts = [_free_configurations(model, n_uni, world, rng, device)] if n_uni > 0 else []
    if n_near + n_border > 0:
        cand = _free_configurations(model, max(pool * (n_near + n_border), 16), world, rng,
                                    device)
        used = np.zeros(len(cand), bool)
        if n_near:
            md = min_distances(model, cand, world, device=device, dtype=np.float64)
            d = md[:, 0] if world is not None else md[:, 1]
            pick = np.argsort(d, kind="stable")[:n_near]
            used[pick] = True
            parts.append(cand[pick])
        if n_border:
            T = fk(model, cand, device=device, dtype=np.float64)[:, f]
            r = np.linalg.norm(T[:, :model.workspace_dim, 3], axis=1)
            r[used] = -np.inf
            parts.append(cand[np.argsort(-r, kind="stable")[:n_border]])
    q = np.concatenate(parts) if parts else np.empty((0, model.n_dof))
    T = fk(model, q, device=device, dtype=np.float64)[:, f] if len(q) else np.empty((0, 4, 4))
    if n_task:
        assert tasks is not None  # checked with the mix above
        Tt = np.asarray(tasks(n_task, rng), np.float64)
        if Tt.shape != (n_task, 4, 4) or not np.all(np.isfinite(Tt)):
            raise ValueError(f"tasks: expected {n_task} finite poses (k, 4, 4), got shape "
                             f"{Tt.shape}")
        T = np.concatenate([T, Tt])
        q = np.concatenate([q, np.full((n_task, model.n_dof), np.nan)])
    order = rng.permutation(n)
    return np.ascontiguousarray(T[order]), q[order]


def check_mix(mix: Any) -> np.ndarray:
    """``mix`` as 4 fractions summing to 1 (a 3-entry mix has no scene tasks); ValueError
    naming ``mix`` unless 3 or 4 finite numbers >= 0 with a positive sum."""
    m = np.asarray(mix, np.float64).reshape(-1)
    if m.shape not in ((3,), (4,)) or not np.all(np.isfinite(m)) or (m < 0).any() \
            or m.sum() <= 0:
        raise ValueError(f"mix: expected 3 or 4 fractions >= 0 (uniform, near obstacles, "
                         f"border, scene tasks), got {mix!r}")
    if len(m) == 3:
        m = np.append(m, 0.0)
    return m / m.sum()


def make_worlds(robot: RobotLike, kind: str, n: int, *, seed: int = 0, device: DeviceLike = None) -> list:
    """``n`` worlds of ``kind`` ("random", "shelf", "none"; module docstring); "shelf" and
    "none" give one world (or None) whatever ``n``."""
    model = get_robot(robot)
    if kind == "random":
        return [feasible_simplex_world(model, seed=int(seed) + 100 * i, device=device)
                for i in range(int(n))]
    if kind == "shelf":
        if model.workspace_dim != 3:
            raise ValueError(f"world: the shelf is a 3D scene; '{model.name}' is planar "
                             f"(use 'random' or 'none')")
        return [shelf_world()]
    if kind == "none":
        return [None]
    raise ValueError(f"world: expected 'random', 'shelf' or 'none', got {kind!r}")


@dataclass
class IKData:
    """Training and validation targets, grouped by world.

    worlds / val_worlds: lists of World (or [None]); targets[i] (N, 4, 4) and q[i] (N, n_dof)
    of worlds[i]; val_targets[j] (M, 4, 4), val_q[j] of val_worlds[j]; distribution: a
    description of the world distribution (saved in checkpoints)."""

    worlds: list
    targets: list
    q: list
    val_worlds: list
    val_targets: list
    val_q: list
    distribution: dict


def make_ik_data(robot: RobotLike, frame: int | str, world: str = "random", *, n_worlds: int = 8,
                 n_targets: int = 1000, n_val_worlds: int = 2, n_val: int = 128,
                 seed: int = 0, mix: tuple = DEFAULT_MIX, device: DeviceLike = None) -> IKData:
    """Worlds and targets for training (``n_targets`` per world) and a validation set
    (``n_val`` targets per validation world), reproducible by ``seed``. With "shelf" and
    "none" the validation worlds are the training world (unseen targets)."""
    model = get_robot(robot)
    worlds = make_worlds(model, world, n_worlds, seed=seed, device=device)
    val_worlds = (make_worlds(model, world, n_val_worlds, seed=seed + 100000, device=device)
                  if world == "random" else list(worlds))
    m = check_mix(mix)
    tasks = SCENE_TASKS.get(world)
    tr = [sample_targets(model, frame, n_targets, w, seed=seed * 7919 + i, mix=m,
                         device=device, tasks=tasks) for i, w in enumerate(worlds)]
    va = [sample_targets(model, frame, n_val, w, seed=seed * 7919 + 50000 + j, mix=m,
                         device=device, tasks=tasks) for j, w in enumerate(val_worlds)]
    dist: dict = {"kind": world, "mix": {"uniform": m[0], "near_obstacles": m[1],
                                         "border": m[2], "scene_tasks": m[3]}}
    if m[3] > 0:
        dist["scene_tasks"] = tasks.__name__
    if world == "random":
        dist.update(generator="feasible_simplex_world", n_worlds=int(n_worlds),
                    seeds=[int(w.meta.get("seed", -1)) for w in worlds],
                    grid_shape=list(worlds[0].shape), voxel_size=float(worlds[0].voxel_size))
    elif world == "shelf":
        dist.update(scene="shelf_world", voxel_size=float(worlds[0].voxel_size))
    return IKData(worlds=worlds, targets=[t for t, _ in tr], q=[q for _, q in tr],
                  val_worlds=val_worlds, val_targets=[t for t, _ in va],
                  val_q=[q for _, q in va], distribution=dist)
