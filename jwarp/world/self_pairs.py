"""Self-collision pairs to exclude, found as MoveIt's setup assistant does: adjacent links
(parent and child of a joint, also through fixed joints), pairs never in collision over
``n_samples`` random configurations within the joint limits, and pairs in collision in
every one of them (a check that always fails is no check).

A frame pair collides in a configuration when some sphere of one frame and some sphere of
the other are closer than ``margin`` (surface distance ``|x_a - x_b| - r_a - r_b <
margin``). Only pairs whose frames both carry spheres are tested; pairs involving a frame
without spheres are left as they are (they cost nothing in the planner). Random sampling
cannot prove that a pair never collides: a pair colliding in a small part of the joint
space may be missed, more likely with fewer samples (MoveIt's default is 10000); a
positive ``margin`` keeps pairs that come close.

:func:`with_self_pairs` writes the result into a robot's ``self_collision`` section
(``exclude_pairs``), which the planner's self-collision check reads
(``RobotModel.allowed_collision_pairs``); :func:`write_self_pairs` saves it as robot JSON.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from jwarp.kinematics.fk import fk
from jwarp.model import RobotModel, SelfCollision
from jwarp.registry import robot as get_robot

__all__ = ["SelfPairs", "never_colliding_pairs", "adjacent_pairs", "rigid_groups",
           "with_self_pairs", "write_self_pairs"]


@dataclass
class SelfPairs:
    """Result of :func:`never_colliding_pairs` (frame indices, ``a < b``).

    adjacent: pairs linked by a joint or rigidly attached (excluded).
    never_colliding: tested pairs closer than ``margin`` in no sample (excluded).
    always_colliding: tested pairs closer than ``margin`` in every sample (excluded, as
        MoveIt does: such a pair would make every configuration a collision; usually
        overlapping spheres of neighbouring links).
    min_distance: (n_frames, n_frames) smallest sphere surface distance [m] over the
        samples (inf where a frame has no spheres, and on the diagonal).
    collision_rate: (n_frames, n_frames) fraction of samples in collision.
    samples: (n_samples, n_dof) the configurations [rad or m].
    """

    adjacent: list[tuple[int, int]]
    never_colliding: list[tuple[int, int]]
    always_colliding: list[tuple[int, int]]
    min_distance: np.ndarray
    collision_rate: np.ndarray
    samples: np.ndarray
    seed: int
    margin: float

    @property
    def exclude_pairs(self) -> list[tuple[int, int]]:
        """Sorted union of ``adjacent``, ``never_colliding`` and ``always_colliding``."""
        return sorted(set(self.adjacent) | set(self.never_colliding) | set(self.always_colliding))


def rigid_groups(robot: RobotModel) -> np.ndarray:
    """(n_frames,) group id per frame: frames joined by fixed joints (static frames, DH
    frames driven by no joint) share an id (the id of the group's root frame)."""
    parents = robot.parents
    group = np.arange(robot.n_frames)
    for f in robot.topological_order:
        fr = robot.frames[f]
        if parents[f] >= 0 and (fr.kind == "static" or not fr.coupling):
            group[f] = group[parents[f]]
    return group


def adjacent_pairs(robot: RobotModel) -> list[tuple[int, int]]:
    """Sorted frame pairs ``(a, b)``, ``a < b``, that are adjacent: in one rigid group, or
    in the groups of a moving frame and of its parent."""
    group = rigid_groups(robot)
    parents = robot.parents
    members: dict[int, list[int]] = {}
    for f, g in enumerate(group):
        members.setdefault(int(g), []).append(f)
    out: set[tuple[int, int]] = set()
    linked = [(int(g), int(g)) for g in members]
    linked += [(int(group[f]), int(group[parents[f]])) for f in range(robot.n_frames)
               if parents[f] >= 0 and group[f] != group[parents[f]]]
    for ga, gb in linked:
        for a in members[ga]:
            for b in members[gb]:
                if a != b:
                    out.add((min(a, b), max(a, b)))
    return sorted(out)


def _int(x: Any, name: str, low: int) -> int:
    if isinstance(x, bool) or not isinstance(x, (int, np.integer)):
        raise TypeError(f"{name}: expected an integer, got {type(x).__name__}")
    if x < low:
        raise ValueError(f"{name}: must be >= {low}, got {x}")
    return int(x)


def never_colliding_pairs(robot: Any, n_samples: int = 10000, seed: int = 0,
                          margin: float = 0.0, *, batch: int = 1024) -> SelfPairs:
    """Adjacent and never-colliding frame pairs of ``robot`` (name or RobotModel) over
    ``n_samples`` configurations drawn uniformly within the joint limits with
    ``numpy.random.default_rng(seed)`` (FK on the CPU in float64, ``batch`` at a time).
    ``margin`` [m]: a pair counts as colliding when its spheres come closer than this."""
    model = get_robot(robot)
    n_samples = _int(n_samples, "n_samples", 1)
    seed = _int(seed, "seed", 0)
    batch = _int(batch, "batch", 1)
    if isinstance(margin, bool) or not isinstance(margin, (int, float, np.floating, np.integer)) \
            or not np.isfinite(margin):
        raise ValueError(f"margin: expected a finite distance [m], got {margin!r}")
    sf, sp, sr = model.sphere_arrays()
    if len(sr) == 0:
        raise ValueError(f"robot: '{model.name}' has no collision spheres")
    lim = model.joint_limits
    if not np.all(np.isfinite(lim)):
        raise ValueError(f"robot: '{model.name}' has infinite joint limits; cannot sample")
    rng = np.random.default_rng(seed)
    q = lim[:, 0] + rng.random((n_samples, model.n_dof)) * (lim[:, 1] - lim[:, 0])

    order = np.argsort(sf, kind="stable")
    sf, sp, sr = sf[order], sp[order], sr[order]
    frames, starts = np.unique(sf, return_index=True)
    nb = len(frames)
    dmin = np.full((nb, nb), np.inf)
    hits = np.zeros((nb, nb), np.int64)
    for s in range(0, n_samples, batch):
        T = fk(model, q[s:s + batch], device="cpu", dtype=np.float64)  # (B, nf, 4, 4)
        Tf = T[:, sf]
        x = np.einsum("bsij,sj->bsi", Tf[..., :3, :3], sp) + Tf[..., :3, 3]
        d = np.linalg.norm(x[:, :, None] - x[:, None], axis=-1) - sr[:, None] - sr[None]
        fd = np.minimum.reduceat(np.minimum.reduceat(d, starts, axis=1), starts, axis=2)
        dmin = np.minimum(dmin, fd.min(axis=0))
        hits += (fd < margin).sum(axis=0)

    nf = model.n_frames
    min_distance = np.full((nf, nf), np.inf)
    rate = np.zeros((nf, nf))
    ix = np.ix_(frames, frames)
    min_distance[ix] = dmin
    rate[ix] = hits / n_samples
    np.fill_diagonal(min_distance, np.inf)
    np.fill_diagonal(rate, 0.0)
    adjacent = adjacent_pairs(model)
    adj = set(adjacent)
    tested = [(int(a), int(b)) for i, a in enumerate(frames) for b in frames[i + 1:]
              if (int(a), int(b)) not in adj]
    never = [p for p in tested if rate[p] == 0.0]
    always = [p for p in tested if rate[p] == 1.0]
    return SelfPairs(adjacent=adjacent, never_colliding=never, always_colliding=always,
                     min_distance=min_distance, collision_rate=rate, samples=q, seed=seed,
                     margin=float(margin))


def with_self_pairs(robot: Any, pairs: SelfPairs, *, replace: bool = True) -> RobotModel:
    """A copy of ``robot`` whose ``self_collision`` excludes ``pairs.exclude_pairs``.

    ``replace=True``: the section becomes exactly these exclusions (no groups, no include
    pairs: every other frame pair is checked); ``replace=False``: they are added to the
    existing ``exclude_pairs`` (groups and includes kept; exclusion wins)."""
    model = get_robot(robot)
    if not isinstance(pairs, SelfPairs):
        raise TypeError(f"pairs: expected a SelfPairs, got {type(pairs).__name__}")
    nf = model.n_frames
    for a, b in pairs.exclude_pairs:
        if not (0 <= a < nf and 0 <= b < nf):
            raise ValueError(f"pairs: frame pair ({a}, {b}) out of range for robot "
                             f"'{model.name}' ({nf} frames)")
    old = model.self_collision
    if replace:
        sc = SelfCollision(groups={}, include_pairs=[], exclude_pairs=list(pairs.exclude_pairs))
    else:
        have = {tuple(sorted(p)) for p in old.exclude_pairs}
        sc = SelfCollision(groups={k: list(v) for k, v in old.groups.items()},
                           include_pairs=list(old.include_pairs),
                           exclude_pairs=list(old.exclude_pairs)
                           + [p for p in pairs.exclude_pairs if p not in have])
    notes = dict(model.notes)
    notes["self_collision"] = (
        f"exclude_pairs: {len(pairs.adjacent)} adjacent + {len(pairs.never_colliding)} never "
        f"+ {len(pairs.always_colliding)} always colliding in {len(pairs.samples)} random "
        f"configurations (seed {pairs.seed}, margin "
        f"{pairs.margin} m; jwarp.world.self_pairs)" + ("" if replace else ", added to the "
                                                          "hand-written section"))
    return model.copy(self_collision=sc, notes=notes)


def write_self_pairs(robot: Any, out: str | os.PathLike, pairs: SelfPairs | None = None, *,
                     replace: bool = True, **options: Any) -> RobotModel:
    """Compute the pairs (``options`` go to :func:`never_colliding_pairs`) unless given, and
    save the robot with them as JSON to ``out`` (atomically). Returns the new model."""
    out = Path(out)
    if not out.parent.is_dir():
        raise ValueError(f"out: folder '{out.parent}' does not exist")
    if pairs is None:
        pairs = never_colliding_pairs(robot, **options)
    elif options:
        raise TypeError(f"options {sorted(options)} given with precomputed pairs")
    model = with_self_pairs(robot, pairs, replace=replace)
    model.save(out)
    return model
