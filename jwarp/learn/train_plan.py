"""Supervised training of the motion-planning network (thesis 3.4.3, Algorithm 1; 3.5.2,
Table 3.3).

Data are plain arrays (:class:`PlanSamples`): ``starts (N, n_dof)``, ``goals (N, n_dof)``,
``paths (N, W, n_dof)`` (the labels), ``world_index (N,)`` into a list of worlds, and
optionally the labels' costs U_path. :func:`make_plan_data` labels random tasks with the
planner's multi-starts (a small stand-in for the hard-task labels of
``jwarp.learn.plan_data``).

:func:`train_plan`: mean squared error of the network's deviation from the straight line
(:func:`jwarp.learn.plan_net.encode_paths`) against the label's, with (switches of
:class:`TrainPlanOptions`):

- ``time_reversal``: the reversed label is a label of the reversed task (goal -> start);
- ``axis_symmetry``: every declared symmetry of the robot
  (:func:`jwarp.learn.plan_net.axis_symmetries`) maps the task and label by
  ``joint_sign`` and the world's BPS by the workspace map (:func:`symmetric_bps`);
- ``boosting``: every epoch after the first, the samples whose predicted cost exceeds the
  label's by more than the ``boost_percentile`` quantile of those excesses keep weight 1,
  all others get ``1 - boost_ratio`` (Algorithm 1's BoostDataset, as sampling weights
  instead of removals; augmented copies share their sample's weight).

Algorithm 1's other steps work between training rounds: :func:`clean` (plan from the
network's prediction; a cheaper feasible path replaces the label) and :func:`extend`
(sample new tasks, keep those whose predicted path costs most, label them with a
caller-supplied labeler, default :func:`label_tasks`). :func:`improve` runs the loop.

Data at scale come from a path database (:class:`jwarp.learn.dataset.PathDB`, written by
``jwarp data generate``): :func:`samples_from_db` reads its labels (worlds rebuilt from the
stored occupancy) and :func:`split_by_world` keeps unseen worlds for validation.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import torch

from jwarp.core.arrays import device_name
from jwarp.core.threads import ThreadFollower, torch_threads
from jwarp.core.types import RobotLike
from jwarp.learn.plan_net import (
    PlanNet,
    PlanNetConfig,
    axis_symmetries,
    encode_paths,
    symmetric_bps,
)
from jwarp.model import RobotModel
from jwarp.plugins.registry import robot as get_robot
from jwarp.solvers.planning import Planner, PlanOptions
from jwarp.utils.checks import check_int
from jwarp.world.path_feasibility import collision_free

if TYPE_CHECKING:
    from jwarp.world.sdf import World

__all__ = ["PlanSamples", "TrainPlanOptions", "make_plan_data", "label_tasks", "sample_tasks",
           "hard_tasks",
           "path_costs", "prediction_costs", "augment", "boost_weights", "train_plan",
           "validation_mse", "clean", "extend", "improve", "samples_from_db",
           "split_by_world", "data_description"]


# ====================================================================== data
@dataclass
class PlanSamples:
    """Training samples of the planning network (plain arrays): starts, goals (N, n_dof),
    paths (N, W, n_dof) labels, world_index (N,) into ``worlds``, cost (N,) the labels'
    U_path (None: not computed yet); optionally ``world_ids`` (one per world: the ids of
    a path database) and ``source`` (a dict saying where the labels come from, e.g. the
    database; recorded in the checkpoint)."""

    starts: np.ndarray
    goals: np.ndarray
    paths: np.ndarray
    world_index: np.ndarray
    worlds: list
    cost: np.ndarray | None = None
    world_ids: list | None = None
    source: dict | None = None

    def __post_init__(self) -> None:
        self.starts = np.asarray(self.starts, np.float64)
        self.goals = np.asarray(self.goals, np.float64)
        self.paths = np.asarray(self.paths, np.float64)
        self.world_index = np.asarray(self.world_index, np.int64)
        self.worlds = list(self.worlds)
        N = len(self.starts)
        if self.paths.ndim != 3 or len(self.paths) != N or self.goals.shape != self.starts.shape \
                or self.world_index.shape != (N,) or self.paths.shape[2] != self.starts.shape[1]:
            raise ValueError(f"samples: expected starts/goals (N, n), paths (N, W, n), "
                             f"world_index (N,), got {self.starts.shape}, {self.goals.shape}, "
                             f"{self.paths.shape}, {self.world_index.shape}")
        if N and (self.world_index.min() < 0 or self.world_index.max() >= len(self.worlds)):
            raise ValueError(f"world_index: expected indices into {len(self.worlds)} worlds")
        if self.cost is not None:
            self.cost = np.asarray(self.cost, np.float64)
        if self.world_ids is not None:
            self.world_ids = [int(i) for i in self.world_ids]
            if len(self.world_ids) != len(self.worlds):
                raise ValueError(f"world_ids: expected one per world ({len(self.worlds)}), "
                                 f"got {len(self.world_ids)}")

    def __len__(self) -> int:
        return len(self.starts)

    def subset(self, idx: Any) -> PlanSamples:
        return PlanSamples(self.starts[idx], self.goals[idx], self.paths[idx],
                           self.world_index[idx], self.worlds,
                           None if self.cost is None else self.cost[idx], self.world_ids,
                           self.source)

    def compact(self) -> PlanSamples:
        """The same samples with only the worlds they use (in order of first use by world
        index; ``world_index`` renumbered)."""
        used = np.unique(self.world_index)
        remap = np.full(max(len(self.worlds), 1), -1, np.int64)
        remap[used] = np.arange(len(used))
        return PlanSamples(self.starts, self.goals, self.paths, remap[self.world_index],
                           [self.worlds[i] for i in used], self.cost,
                           None if self.world_ids is None else
                           [self.world_ids[i] for i in used], self.source)

    def append(self, other: PlanSamples) -> PlanSamples:
        """This set and ``other`` (same worlds list or its extension)."""
        if other.worlds[:len(self.worlds)] != self.worlds:
            raise ValueError("other: its worlds must extend this set's worlds")
        cost = None
        if self.cost is not None and other.cost is not None:
            cost = np.concatenate([self.cost, other.cost])
        ids = self.world_ids if len(other.worlds) == len(self.worlds) else other.world_ids
        return PlanSamples(np.concatenate([self.starts, other.starts]),
                           np.concatenate([self.goals, other.goals]),
                           np.concatenate([self.paths, other.paths]),
                           np.concatenate([self.world_index, other.world_index]),
                           other.worlds, cost, ids, self.source)


def sample_tasks(model: RobotModel, world: World, n: int, rng: np.random.Generator,
                 min_distance: float = 0.5) -> tuple[np.ndarray, np.ndarray]:
    """``n`` random collision-free start/goal pairs (at least ``min_distance`` apart in
    joint space, as far as the pool allows) of the robot ``model``."""
    from jwarp.core.limits import sample_within_limits

    pool = np.empty((0, model.n_dof))
    for _ in range(50):
        q = sample_within_limits(model, max(64, 8 * n), rng)
        pool = np.concatenate([pool, q[collision_free(model, world, q, 0.0, device="cpu")]])
        if len(pool) >= 2 * n:
            break
    if len(pool) < 2:
        raise ValueError("world: too few collision-free configurations to sample tasks")
    a = rng.integers(0, len(pool), n)
    b = rng.integers(0, len(pool), n)
    far = np.linalg.norm(pool[a] - pool[b], axis=1) >= min_distance
    for _ in range(20):  # redraw goals too close to their start
        if far.all():
            break
        b[~far] = rng.integers(0, len(pool), int((~far).sum()))
        far = np.linalg.norm(pool[a] - pool[b], axis=1) >= min_distance
    return pool[a], pool[b]


def hard_tasks(model: RobotModel, world: World, n: int, rng: np.random.Generator, *,
               iterations: int = 200, n_waypoints: int = 20, n_substeps: int = 4,
               rounds: int = 20) -> tuple[np.ndarray, np.ndarray]:
    """Up to ``n`` random tasks whose straight line does not become feasible within
    ``iterations`` planner steps (the thesis' hard tasks; 3 n candidates per round, at
    most ``rounds`` rounds) of the robot ``model``."""
    S, G, got = [], [], 0
    for _ in range(rounds):
        q0, q1 = sample_tasks(model, world, 3 * (n - got), rng)
        opts = PlanOptions(n_starts=1, start_kind="straight", n_waypoints=n_waypoints,
                           n_substeps=n_substeps, iterations=iterations, fallback=None)
        easy = Planner(model, world, len(q0), opts, device="cpu").plan(q0, q1).feasible
        S.append(q0[~easy][:n - got])
        G.append(q1[~easy][:n - got])
        got += len(S[-1])
        if got >= n:
            break
    return np.concatenate(S), np.concatenate(G)


def label_tasks(robot: RobotModel, world: World, starts: np.ndarray, goals: np.ndarray, *,
                n_waypoints: int = 20, n_starts: int = 16, iterations: int = 200,
                n_substeps: int = 4, seed: int = 0
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The default labeler: the planner's multi-starts (the straight line and
    ``n_starts - 1`` random ones, thesis 3.5.1), best feasible path per task. Returns
    paths (N, W, n_dof), feasible (N,), cost (N,)."""
    opts = PlanOptions(n_starts=n_starts, start_kind="mixed", n_waypoints=n_waypoints,
                       n_substeps=n_substeps, iterations=iterations, seed=seed,
                       stop_when_solved=False, fallback=None)
    res = Planner(robot, world, len(starts), opts, device="cpu").plan(starts, goals)
    return res.path, res.feasible, res.cost


def make_plan_data(robot: RobotLike, worlds: list, n_per_world: int, *, seed: int = 0,
                   n_waypoints: int = 20, n_starts: int = 16, iterations: int = 200,
                   n_substeps: int = 4, hard: bool = False, rounds: int = 3,
                   labeler: Callable | None = None) -> PlanSamples:
    """Random tasks in every world labelled by ``labeler(robot, world, starts, goals)
    -> (paths, feasible, cost)`` (default :func:`label_tasks`); only feasible labels are
    kept, so a world may give fewer than ``n_per_world`` (with ``hard``, new tasks are
    drawn for the missing ones up to ``rounds`` times). ``hard``: keep only tasks whose
    straight line does not become feasible within ``iterations`` (the thesis' hard
    dataset)."""
    model = get_robot(robot)
    rng = np.random.default_rng(seed)
    parts = []
    for wi, world in enumerate(worlds):
        got, done = 0, 0
        while got < n_per_world and done < (rounds if hard else 1):
            done += 1
            need = n_per_world - got
            if hard:
                q0, q1 = hard_tasks(model, world, need, rng, iterations=iterations,
                                    n_waypoints=n_waypoints, n_substeps=n_substeps, rounds=1)
                if not len(q0):
                    continue
            else:
                q0, q1 = sample_tasks(model, world, need, rng)
            if labeler is None:
                P, ok, c = label_tasks(model, world, q0, q1, n_waypoints=n_waypoints,
                                       n_starts=n_starts, iterations=iterations,
                                       n_substeps=n_substeps, seed=int(rng.integers(2**31)))
            else:
                P, ok, c = labeler(model, world, q0, q1)
            ok = np.asarray(ok, bool)
            parts.append((q0[ok], q1[ok], np.asarray(P)[ok], np.full(int(ok.sum()), wi),
                          np.asarray(c, np.float64)[ok]))
            got += int(ok.sum())
    n = model.n_dof
    if not parts:
        return PlanSamples(np.empty((0, n)), np.empty((0, n)), np.empty((0, n_waypoints, n)),
                           np.empty(0, np.int64), worlds, np.empty(0))
    q0, q1, paths, ids = [np.concatenate([p[k] for p in parts]) for k in range(4)]
    return PlanSamples(q0, q1, paths, ids, worlds=worlds,
                       cost=np.concatenate([p[4] for p in parts]))


def samples_from_db(db: Any, robot: RobotModel, *, world_ids: Any = None, hard_only: bool = True,
                    feasible_only: bool = True, n_waypoints: int | None = None,
                    skip_damaged: bool = False, skipped: list | None = None) -> PlanSamples:
    """The stored labels of a path database (a path or an open
    :class:`jwarp.learn.dataset.PathDB`) as :class:`PlanSamples`: starts, goals, paths (the
    stored float32 values) of the worlds ``world_ids`` (None: all; in that order, tasks in
    order), each world rebuilt from its stored occupancy (:meth:`PathDB.world`); only the
    worlds with a selected path are in ``worlds`` (``world_ids`` their database ids).
    ``hard_only``/``feasible_only``: only the rows flagged hard / feasible. ``cost`` is left
    None (recomputed with the trainer's settings when needed). ``source`` names the file,
    robot and kinematics hash.

    Errors (ValueError): a database of another robot (:class:`PathDBError` naming the
    file), a world id not in it, stored paths whose waypoint count is not ``n_waypoints``
    (None: not checked), no selected row (naming the database), a damaged world or path
    row (:class:`jwarp.learn.dataset.DamagedRowError`, naming the file, the world and the
    row). ``skip_damaged``: damaged worlds and rows are left out instead and described in
    the list ``skipped`` (as :func:`jwarp.learn.dataset.export_npz`)."""
    from jwarp.core.device import content_key
    from jwarp.learn.dataset import DamagedRowError, PathDB, PathDBError

    model = robot
    own = not isinstance(db, PathDB)
    d = PathDB(db, model) if own else db
    try:
        if not own and (d.robot != model.name or d.kinematics_hash != content_key(model)):
            raise PathDBError(f"database: '{d.path}' holds paths of robot '{d.robot}' "
                              f"(kinematics hash {d.kinematics_hash}), not of robot "
                              f"'{model.name}' (kinematics hash {content_key(model)})")
        stored = d.world_ids()
        ids = stored if world_ids is None else [int(i) for i in world_ids]
        missing = sorted(set(ids) - set(stored))
        if missing:
            raise ValueError(f"world_ids: database '{d.path}' has no world "
                             f"{', '.join(map(str, missing[:5]))}"
                             f"{' ...' if len(missing) > 5 else ''}")
        if skip_damaged:
            good = []
            for i in ids:
                try:
                    d.world_row(i)
                    good.append(i)
                except DamagedRowError as e:
                    if skipped is not None:
                        skipped.append({"what": f"world {i} and its paths: {e}",
                                        "world_id": i, "task": None})
            ids = good
        try:
            a = d.paths_of(ids, skip_damaged=skip_damaged, skipped=skipped)
        except DamagedRowError:
            raise
        except ValueError as e:
            if "waypoints" not in str(e):
                raise
            raise ValueError(f"n_waypoints: database '{d.path}' mixes paths with different "
                             f"numbers of waypoints; select worlds of one setting "
                             f"(world_ids)") from None
        keep = np.ones(len(a["task"]), bool)
        if feasible_only:
            keep &= a["feasible"]
        if hard_only:
            keep &= a["hard"]
        if not keep.any():
            what = " and ".join(w for w, on in (("hard", hard_only), ("feasible", feasible_only))
                                if on) or "any"
            raise ValueError(f"database: '{d.path}' has no {what} path in the "
                             f"{len(ids)} selected worlds ({len(a['task'])} paths in all)")
        a = {k: v[keep] for k, v in a.items()}
        W = a["path"].shape[1]
        if n_waypoints is not None and int(n_waypoints) != W:
            raise ValueError(f"n_waypoints: database '{d.path}' stores paths of {W} "
                             f"waypoints, the network is configured for {n_waypoints}")
        # worlds in order of first appearance (the order of ``world_ids``)
        order = {w: i for i, w in enumerate(dict.fromkeys(a["world_id"].tolist()))}
        first = [int(w) for w in order]
        index = np.array([order[w] for w in a["world_id"].tolist()], np.int64)
        worlds = [d.world(w) for w in first]
        source = {"source": "path-db", "path": str(Path(d.path).resolve()),
                  "robot": d.robot, "kinematics_hash": d.kinematics_hash,
                  "hard_only": bool(hard_only), "feasible_only": bool(feasible_only)}
    finally:
        if own:
            d.close()
    return PlanSamples(a["start"], a["goal"], a["path"], index, worlds, None, first, source)


def world_content_key(world: World, index: int) -> str:
    """The content hash of a world (:meth:`jwarp.world.sdf.World.content_hash`), or
    ``"index:<i>"`` for an entry without a grid."""
    try:
        return world.content_hash()
    except (AttributeError, ValueError):
        return f"index:{index}"


def split_by_world(samples: PlanSamples, val_fraction: float = 0.1, seed: int = 0
                   ) -> tuple[PlanSamples, PlanSamples]:
    """(train, val): a random ``val_fraction`` of the worlds (rounded, at least one when
    ``val_fraction`` > 0) and all their samples go to validation, so validation worlds are
    unseen in training; worlds of equal content (:meth:`jwarp.world.sdf.World.content_hash`,
    e.g. the same grid stored twice) are one world for the split, so none is on both sides;
    each part keeps only its worlds (:meth:`PlanSamples.compact`).
    ``val_fraction`` 0: val is empty. ValueError for a fraction outside [0, 1) or fewer
    than two worlds to split."""
    if not (isinstance(val_fraction, (int, float)) and 0.0 <= val_fraction < 1.0):
        raise ValueError(f"val_fraction: expected a number in [0, 1), got {val_fraction!r}")
    used = np.unique(samples.world_index)
    if val_fraction == 0:
        return samples.compact(), samples.subset(np.zeros(0, np.int64)).compact()
    if len(used) < 2:
        raise ValueError(f"val_fraction: the samples have {len(used)} world(s); a split by "
                         f"world needs at least 2 (or val_fraction 0)")
    # split by content: worlds with equal grids (world_content_key) fall on one side
    keys = [world_content_key(samples.worlds[int(i)], int(i)) for i in used]
    groups: dict[str, list[int]] = {}
    for i, k in zip(used, keys):
        groups.setdefault(k, []).append(int(i))
    if len(groups) < 2:
        raise ValueError(f"val_fraction: the samples' {len(used)} world(s) have "
                         f"{len(groups)} distinct grid(s); a split by world needs at least 2 "
                         f"(or val_fraction 0)")
    order = sorted(groups)
    n_val = min(max(1, round(val_fraction * len(order))), len(order) - 1)
    rng = np.random.default_rng(seed)
    val_keys = [order[j] for j in rng.permutation(len(order))[:n_val]]
    val_worlds = [i for k in val_keys for i in groups[k]]
    is_val = np.isin(samples.world_index, val_worlds)
    return (samples.subset(np.flatnonzero(~is_val)).compact(),
            samples.subset(np.flatnonzero(is_val)).compact())


def path_costs(robot: RobotModel, world: World, paths: np.ndarray, n_substeps: int = 4) -> np.ndarray:
    """U_path (eq. 3.16, the planner's weights; float32 on the CPU) of paths (P, W, n_dof)."""
    from jwarp.learn.torch_costs import path_objective

    paths = np.asarray(paths, np.float64)
    if not len(paths):
        return np.empty(0)
    obj = path_objective(robot, world, len(paths), paths.shape[1], n_substeps, device="cpu",
                         dtype=np.float32)
    obj.set_paths(paths)
    obj.evaluate(grad=False)
    return obj.total.numpy().astype(np.float64)


def _by_world(data: PlanSamples) -> list[tuple[int, np.ndarray]]:
    return [(int(w), np.flatnonzero(data.world_index == w)) for w in np.unique(data.world_index)]


def label_costs(data: PlanSamples, robot: RobotModel, n_substeps: int = 4) -> np.ndarray:
    """The labels' U_path (computed once, stored in ``data.cost``)."""
    if data.cost is None:
        c = np.empty(len(data))
        for wi, idx in _by_world(data):
            c[idx] = path_costs(robot, data.worlds[wi], data.paths[idx], n_substeps)
        data.cost = c
    return data.cost


def prediction_costs(net: PlanNet, data: PlanSamples, n_substeps: int = 4) -> np.ndarray:
    """U_path (N,) of the network's (first head's) predictions."""
    c = np.empty(len(data))
    for wi, idx in _by_world(data):
        world = data.worlds[wi]
        P = net.paths(data.starts[idx], data.goals[idx], world)[:, 0]
        c[idx] = path_costs(net.robot, world, P, n_substeps)
    return c


def boost_weights(net: PlanNet, data: PlanSamples, percentile: float = 0.8,
                  ratio: float = 0.9, n_substeps: int = 4) -> np.ndarray:
    """Sampling weights (N,) of Algorithm 1's BoostDataset: samples whose excess
    ``U(prediction) - U(label)`` is at or above its ``percentile`` quantile get 1, the
    others ``1 - ratio``."""
    excess = prediction_costs(net, data, n_substeps) - label_costs(data, net.robot, n_substeps)
    v = np.quantile(excess, percentile)
    return np.where(excess >= v, 1.0, 1.0 - ratio)


# ====================================================================== augmentation
def augment(net: PlanNet, data: PlanSamples, *, time_reversal: bool = True,
            axis_symmetry: bool = True) -> dict:
    """The training arrays of ``data`` and its augmented copies: ``starts``, ``goals``
    (M, n_dof), ``labels`` (M, W - 2, n_dof) deviation encodings, ``bps`` (M, n_bps) or
    None, ``source`` (M,) the original sample of each row, ``kind`` (M,) 0 original,
    1 reversed, 2 + 2 s mapped by symmetry s, 3 + 2 s mapped and reversed."""
    lo, hi = net.lower, net.upper
    syms = axis_symmetries(net.robot) if axis_symmetry else ()
    idx = np.arange(len(data))
    bps_tables = None
    if net.bps is not None:
        base = np.stack([net.world_bps(w) for w in data.worlds])
        bps_tables = [base] + [symmetric_bps(net.bps, data.worlds, s) for s in syms]
    S, G, P, B, src, kind = [], [], [], [], [], []

    def add(q0: np.ndarray, q1: np.ndarray, paths: np.ndarray, table: int, k: int) -> None:
        S.append(q0)
        G.append(q1)
        P.append(paths)
        src.append(idx)
        kind.append(np.full(len(idx), k))
        if bps_tables is not None:
            B.append(bps_tables[table][data.world_index])

    variants = [(None, 0)] + [(s, i + 1) for i, s in enumerate(syms)]
    for s, table in variants:
        m = (lambda q: q) if s is None else s.map_q
        q0, q1, paths = m(data.starts), m(data.goals), m(data.paths)
        base_kind = 0 if s is None else 2 * table
        add(q0, q1, paths, table, base_kind)
        if time_reversal:
            add(q1, q0, paths[:, ::-1], table, base_kind + 1)
    out = {"starts": np.concatenate(S), "goals": np.concatenate(G),
           "labels": encode_paths(np.concatenate(P), lo, hi),
           "bps": np.concatenate(B).astype(np.float32) if B else None,
           "source": np.concatenate(src), "kind": np.concatenate(kind)}
    if data.paths.shape[1] != net.n_waypoints:
        raise ValueError(f"paths: the labels have {data.paths.shape[1]} waypoints, the network "
                         f"{net.n_waypoints}")
    return out


# ====================================================================== training
@dataclass
class TrainPlanOptions:
    """Options of :func:`train_plan` (the network: robot, n_bps, n_waypoints, hidden,
    n_blocks, n_heads; training: epochs x steps_per_epoch Adam steps of batch_size samples,
    lr; the switches time_reversal, axis_symmetry, boosting (boost_percentile,
    boost_ratio); n_substeps of the costs; device (None: Warp's default device); seed;
    checkpoint (written after every epoch when given))."""

    robot: str = "planar4"
    n_bps: int = 128
    n_waypoints: int = 20
    hidden: int = 256
    n_blocks: int = 3
    n_heads: int = 1
    epochs: int = 10
    steps_per_epoch: int = 100
    batch_size: int = 128
    lr: float = 1e-3
    time_reversal: bool = True
    axis_symmetry: bool = True
    boosting: bool = False
    boost_percentile: float = 0.8
    boost_ratio: float = 0.9
    n_substeps: int = 4
    device: str | None = None
    seed: int = 0
    checkpoint: str | None = None

    def validate(self) -> None:
        for name, lo in (("epochs", 0), ("steps_per_epoch", 1), ("batch_size", 1),
                         ("n_substeps", 1), ("seed", 0)):
            v = getattr(self, name)
            check_int(v, name, lo)
        if not (isinstance(self.lr, (int, float)) and math.isfinite(self.lr) and self.lr > 0):
            raise ValueError(f"lr: expected a number > 0, got {self.lr!r}")
        for name in ("boost_percentile", "boost_ratio"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and 0.0 <= v <= 1.0):
                raise ValueError(f"{name}: expected a number in [0, 1], got {v!r}")
        self.net_config().validate()

    def net_config(self) -> PlanNetConfig:
        return PlanNetConfig(robot=self.robot, n_bps=self.n_bps, n_waypoints=self.n_waypoints,
                             hidden=self.hidden, n_blocks=self.n_blocks, n_heads=self.n_heads)

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


def _tensors(net: PlanNet, arr: dict, idx: np.ndarray) -> tuple:
    p = net.out.weight

    def t(a: np.ndarray | None) -> torch.Tensor | None:
        return None if a is None else torch.as_tensor(np.ascontiguousarray(a[idx]),
                                                      dtype=p.dtype, device=p.device)
    return t(arr["starts"]), t(arr["goals"]), t(arr["bps"]), t(arr["labels"])


def plan_loss(net: PlanNet, starts: torch.Tensor, goals: torch.Tensor,
              bps: torch.Tensor | None, labels: torch.Tensor) -> torch.Tensor:
    """MSE of the deviation encodings (several heads: the best head per sample)."""
    y = net(starts, goals, bps)
    err = ((y - labels[:, None]) ** 2).mean(dim=(2, 3))  # (B, H)
    return err.min(dim=1).values.mean()


def validation_mse(net: PlanNet, data: PlanSamples) -> float:
    """Mean squared deviation error of ``data`` (no augmentation)."""
    if not len(data):
        return math.nan
    arr = augment(net, data, time_reversal=False, axis_symmetry=False)
    was = net.training
    net.eval()
    with torch.no_grad():
        loss = plan_loss(net, *_tensors(net, arr, np.arange(len(data))))
    net.train(was)
    return float(loss)


def train_plan(options: TrainPlanOptions, data: PlanSamples, val: PlanSamples | None = None,
               *, net: PlanNet | None = None, progress: bool = False,
               callback: Callable | None = None) -> tuple[PlanNet, list]:
    """Train (or continue training ``net``) on ``data``; validation MSE on ``val`` (None:
    none). Returns the network (eval mode) and the history: one record per epoch, epoch 0
    the untrained (or given) network's validation MSE."""
    with torch_threads():  # a thread count that does not oversubscribe the CPUs
        return _train_plan(options, data, val, net, progress, callback)


def _train_plan(options: TrainPlanOptions, data: PlanSamples, val: PlanSamples | None,
                net: PlanNet | None, progress: bool, callback: Callable | None
                ) -> tuple[PlanNet, list]:
    options.validate()
    if not len(data):
        raise ValueError("data: no samples")
    torch.manual_seed(options.seed)
    rng = np.random.default_rng(options.seed)
    if net is None:
        net = PlanNet(options.net_config())
    net.to(device_name(options.device))
    arr = augment(net, data, time_reversal=options.time_reversal,
                  axis_symmetry=options.axis_symmetry)
    M = len(arr["source"])
    opt = torch.optim.Adam(net.parameters(), lr=options.lr)
    history = [{"epoch": 0, "val_mse": validation_mse(net, val) if val is not None else math.nan,
                "train_rows": M}]
    if progress:
        print(f"epoch 0: val_mse {history[0]['val_mse']:.5g} ({M} training rows from "
              f"{len(data)} samples)")
    weights = None
    follow = ThreadFollower()  # a job started beside the training: fewer threads
    for e in range(1, options.epochs + 1):
        follow(force=True)
        t0 = time.perf_counter()
        n_hard = 0
        if options.boosting and e > 1:
            net.eval()
            w = boost_weights(net, data, options.boost_percentile, options.boost_ratio,
                              options.n_substeps)
            n_hard = int((w == 1.0).sum())
            weights = w[arr["source"]]
            weights = weights / weights.sum()
        net.train()
        total = 0.0
        for _ in range(options.steps_per_epoch):
            follow()  # within the epoch too, at most every second
            idx = rng.choice(M, size=min(options.batch_size, M), replace=options.batch_size > M,
                             p=weights) if weights is not None else \
                rng.integers(0, M, size=options.batch_size)
            loss = plan_loss(net, *_tensors(net, arr, idx))
            opt.zero_grad()
            loss.backward()
            opt.step()
            total += float(loss.detach())
        net.eval()
        rec = {"epoch": e, "loss": total / options.steps_per_epoch,
               "val_mse": validation_mse(net, val) if val is not None else math.nan,
               "boost_hard": n_hard, "seconds": time.perf_counter() - t0, "train_rows": M}
        history.append(rec)
        if progress:
            print(f"epoch {e}/{options.epochs}: loss {rec['loss']:.5g} val_mse "
                  f"{rec['val_mse']:.5g} hard {n_hard} ({rec['seconds']:.1f} s)")
        if options.checkpoint:
            _save(net, options, history, data)
        if callback is not None:
            callback(rec, net)
    net.eval()
    return net, history


def data_description(data: PlanSamples) -> Any:
    """What a network trained on ``data`` is valid for (the checkpoint's
    ``world_distribution``): ``"samples"``, or for labels of a path database its source
    (path, robot, kinematics hash) with the numbers of worlds and paths trained on and the
    world ids."""
    if data.source is None:
        return "samples"
    used = np.unique(data.world_index)
    out = {**data.source, "worlds": int(len(used)), "paths": int(len(data))}
    if data.world_ids is not None:
        out["world_ids"] = [data.world_ids[i] for i in used]
    return out


def _save(net: PlanNet, options: TrainPlanOptions, history: list, data: PlanSamples) -> None:
    from jwarp.learn.checkpoint import save_checkpoint

    save_checkpoint(options.checkpoint, net, world_distribution=data_description(data),
                    training=options.to_dict(), metrics={**history[-1], "history": history},
                    epoch=int(history[-1]["epoch"]))


# ====================================================================== Algorithm 1
def clean(net: PlanNet, data: PlanSamples, *, iterations: int = 100, n_substeps: int = 4,
          seed: int = 0) -> tuple[PlanSamples, int]:
    """Algorithm 1's CleanDataset: plan every task from the network's prediction (all
    heads, ``iterations`` planner steps); where the result is feasible and at most the
    label's U_path it replaces the label. Returns the cleaned copy and the number of
    replaced labels."""
    cost = label_costs(data, net.robot, n_substeps).copy()
    paths = data.paths.copy()
    n_rep = 0
    for wi, idx in _by_world(data):
        world = data.worlds[wi]
        seeds = net.paths(data.starts[idx], data.goals[idx], world)
        opts = PlanOptions(n_starts=seeds.shape[1], n_waypoints=seeds.shape[2],
                           n_substeps=n_substeps, iterations=iterations, seed=seed,
                           stop_when_solved=False, fallback=None)
        res = Planner(net.robot, world, len(idx), opts, device="cpu").plan(
            data.starts[idx], data.goals[idx], seeds=seeds)
        c = path_costs(net.robot, world, res.path, n_substeps)
        better = res.feasible & (c <= cost[idx])
        better &= np.any(np.abs(res.path - paths[idx]) > 1e-9, axis=(1, 2))
        paths[idx[better]] = res.path[better]
        cost[idx[better]] = c[better]
        n_rep += int(better.sum())
    out = PlanSamples(data.starts, data.goals, paths, data.world_index, data.worlds, cost,
                      data.world_ids, data.source)
    return out, n_rep


def extend(net: PlanNet, data: PlanSamples, n_new: int, *, n_candidates: int | None = None,
           worlds: list | None = None, labeler: Callable | None = None, n_substeps: int = 4,
           seed: int = 0) -> tuple[PlanSamples, int]:
    """Algorithm 1's ExtendDataset: draw ``n_candidates`` (default 4 ``n_new``) random
    tasks in ``worlds`` (default the data's), keep the ``n_new`` whose predicted path has
    the highest U_path, label them with ``labeler(robot, world, starts, goals) -> (paths,
    feasible, cost)`` (default :func:`label_tasks` with the network's waypoints) and append
    the feasible ones. Returns the extended set and the number added."""
    worlds = list(data.worlds) if worlds is None else list(worlds)
    all_worlds = list(data.worlds) + [w for w in worlds if not any(w is v for v in data.worlds)]
    rng = np.random.default_rng(seed)
    n_cand = 4 * n_new if n_candidates is None else int(n_candidates)
    per = np.bincount(rng.integers(0, len(worlds), n_cand), minlength=len(worlds))
    cand = []
    for w, k in zip(worlds, per):
        if k == 0:
            continue
        q0, q1 = sample_tasks(net.robot, w, int(k), rng)
        u = path_costs(net.robot, w, net.paths(q0, q1, w)[:, 0], n_substeps)
        cand += [(u[i], w, q0[i], q1[i]) for i in range(len(q0))]
    cand.sort(key=lambda c: -c[0])
    cand = cand[:n_new]
    parts = []
    for w in worlds:
        mine = [c for c in cand if c[1] is w]
        if not mine:
            continue
        q0 = np.stack([c[2] for c in mine])
        q1 = np.stack([c[3] for c in mine])
        if labeler is None:
            P, ok, c = label_tasks(net.robot, w, q0, q1, n_waypoints=net.n_waypoints,
                                   n_substeps=n_substeps, seed=int(rng.integers(2**31)))
        else:
            P, ok, c = labeler(net.robot, w, q0, q1)
        ok = np.asarray(ok, bool)
        wi = next(i for i, v in enumerate(all_worlds) if v is w)
        parts.append(PlanSamples(q0[ok], q1[ok], np.asarray(P)[ok], np.full(int(ok.sum()), wi),
                                 all_worlds, np.asarray(c, np.float64)[ok]))
    label_costs(data, net.robot, n_substeps)
    out = PlanSamples(data.starts, data.goals, data.paths, data.world_index, all_worlds,
                      data.cost, data.world_ids if len(all_worlds) == len(data.worlds) else None,
                      data.source)
    added = 0
    for p in parts:
        out = out.append(p)
        added += len(p)
    return out, added


def improve(options: TrainPlanOptions, data: PlanSamples, val: PlanSamples | None = None, *,
            rounds: int = 2, n_cleans: int | None = None, extend_fraction: float = 0.05,
            labeler: Callable | None = None, progress: bool = False
            ) -> tuple[PlanNet, PlanSamples, list]:
    """Algorithm 1's main loop: train; then ``rounds`` times clean (the first ``n_cleans``
    rounds; None: all), extend by ``extend_fraction`` of the set (0: never) and train on
    (boosting as ``options.boosting``). Returns the network, the final set and one record
    per round (val_mse, replaced, added)."""
    net, hist = train_plan(options, data, val, progress=progress)
    log = [{"round": 0, "val_mse": hist[-1]["val_mse"], "replaced": 0, "added": 0,
            "samples": len(data)}]
    for r in range(1, rounds + 1):
        replaced = added = 0
        if n_cleans is None or r <= n_cleans:
            data, replaced = clean(net, data, n_substeps=options.n_substeps, seed=r)
        if extend_fraction > 0:
            data, added = extend(net, data, max(1, int(extend_fraction * len(data))),
                                 labeler=labeler, n_substeps=options.n_substeps, seed=r)
        net, hist = train_plan(options, data, val, net=net, progress=progress)
        log.append({"round": r, "val_mse": hist[-1]["val_mse"], "replaced": replaced,
                    "added": added, "samples": len(data)})
        if progress:
            print(f"round {r}: replaced {replaced}, added {added}, val_mse "
                  f"{log[-1]['val_mse']:.5g}")
    return net, data, log
