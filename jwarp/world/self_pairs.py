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

The URDF import follows MoveIt's setup assistant (moveit_setup_assistant
``computeDefaultCollisions``) with ``adjacency="moveit"`` and ``always_fraction=0.95``:
**Adjacent** is a parent and child link, or two links joined through links without
collision geometry (:func:`moveit_adjacent_pairs`; jwarp's frames without spheres, such as
a joint's ``_axis`` or ``_origin`` frame or a flange, count as such links); **Always** a
pair in collision in at least 95 % of the samples (MoveIt: more than 95 % of rounds of 200
random states); **Never** a pair in collision in none of them (MoveIt's setup assistant
disables these by default, ``include_never_colliding = true``, over 10000 states by
default). The reason of every excluded pair is recorded in
``notes['self_collision_pairs']`` (:data:`PAIRS_NOTE`; :func:`skipped_pairs` lists them).
MoveIt's fourth rule, **Default** (pairs in collision at the default configuration), is
not applied by the import: a home in self-collision is refused or replaced
(:mod:`jwarp.world.home_fit`), never freed by unchecking a pair.

:func:`default_pairs` splits the pairs whose spheres overlap at a configuration by
whether the robot's own geometry is in contact there (a ``contact`` test the caller gives,
e.g. the URDF's collision meshes): spheres that overlap where the meshes do not are a fit
to correct. :func:`with_default_pairs` (MoveIt's "Default" rule, which the import no longer
applies) adds pairs to ``exclude_pairs`` and lists them in
``notes['self_collision_default']`` (an exported SRDF writes them with reason="Default").
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from jwarp.core.types import RobotLike
from jwarp.kinematics.fk import fk
from jwarp.model import RobotModel, SelfCollision
from jwarp.model.pair_reasons import (
    PAIRS_NOTE,
    moveit_adjacent_pairs,
    pair_reasons,
    skipped_pairs,
    with_pair_reasons,
)
from jwarp.plugins.registry import robot as get_robot
from jwarp.utils.checks import check_int
from jwarp.utils.memory import check_memory, format_bytes

__all__ = ["SelfPairs", "PairSamplingCost", "never_colliding_pairs", "pair_sampling_cost",
           "adjacent_pairs", "moveit_adjacent_pairs", "rigid_groups", "default_pairs",
           "with_default_pairs", "DEFAULT_NOTE", "PAIRS_NOTE", "ALWAYS_FRACTION",
           "with_self_pairs", "write_self_pairs", "pair_reasons", "with_pair_reasons",
           "skipped_pairs", "sampled_reasons"]

#: MoveIt setup assistant's share of random states in collision above which a pair is
#: "always" colliding (its ``min_collision_fraction``, 95 %)
ALWAYS_FRACTION = 0.95


#: ``RobotModel.notes`` key listing the "Default" pairs (JSON ``[[frame a, frame b], ...]``;
#: the same key as :data:`jwarp.importers.srdf.DEFAULT_NOTE`)
DEFAULT_NOTE = "self_collision_default"


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
    #: the adjacency rule ("rigid": :func:`adjacent_pairs`; "moveit":
    #: :func:`moveit_adjacent_pairs`) and the always rule's share of samples
    adjacency: str = "rigid"
    always_fraction: float = 1.0

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


#: default working-set target of the pair sampling [bytes] (:func:`never_colliding_pairs`)
MAX_MEMORY = 256_000_000
#: most spheres of one bounding-sphere cluster of a frame (the culling of sphere blocks)
CLUSTER = 48
#: bytes per sphere-pair distance and configuration while a block is computed: the squared
#: distance (then the surface distance) and one coordinate's difference (float64), with room
_PAIR_BYTES = 8 * 4
#: bytes per sphere and configuration of a batch: its world centre and the FK of its frame
_SPHERE_BYTES = 8 * (3 + 3)


@dataclass
class PairSamplingCost:
    """What :func:`never_colliding_pairs` will do (:func:`pair_sampling_cost`).

    spheres: collision spheres; frames: frames with spheres; frame_pairs: frame pairs
    computed (both frames with spheres: the tested ones and the adjacent ones, whose distances
    are reported too); sphere_pairs: sphere pairs of those frame pairs; evaluations:
    ``sphere_pairs * n_samples`` distances at most (frame pairs whose bounding spheres are
    farther apart than the current minimum and ``margin`` are skipped, so usually fewer);
    batch: configurations per FK batch; memory: working set [bytes] (at most about
    ``max_memory``, plus the samples and the result matrices).
    """

    spheres: int
    frames: int
    frame_pairs: int
    sphere_pairs: int
    evaluations: int
    batch: int
    memory: int

    def __str__(self) -> str:
        return (f"self-pair sampling: {self.spheres} spheres on {self.frames} frames, "
                f"{self.frame_pairs} frame pairs ({self.sphere_pairs} sphere pairs), at most "
                f"{self.evaluations:.3g} distances, about {format_bytes(self.memory)} of memory")


def _memory_arg(max_memory: Any) -> int:
    max_memory = check_int(max_memory, "max_memory", 1)
    if max_memory < 1_000_000:
        raise ValueError(f"max_memory: expected at least 1000000 bytes, got {max_memory}")
    return max_memory


def _plan(model: RobotModel, n_samples: int, batch: int, max_memory: int
          ) -> tuple[PairSamplingCost, int]:
    """The cost of the sampling and the tile size [spheres] of a frame-pair block."""
    sf = model.sphere_arrays()[0]
    frames, counts = np.unique(sf, return_counts=True)
    S, nf = int(len(sf)), int(model.n_frames)
    # a batch's centres and frame transforms take at most a quarter of the budget
    per_cfg = S * _SPHERE_BYTES + nf * 8 * 16 * 4
    batch = max(1, min(batch, n_samples, (max_memory // 4) // max(per_cfg, 1)))
    # a block of tile x tile sphere pairs for one configuration fits in half the budget
    tile = max(1, int(math.isqrt(max(1, (max_memory // 2) // _PAIR_BYTES))))
    c = counts.astype(np.int64)
    sphere_pairs = int((c.sum() ** 2 - (c ** 2).sum()) // 2)
    nb = len(frames)
    cost = PairSamplingCost(
        spheres=S, frames=nb, frame_pairs=nb * (nb - 1) // 2, sphere_pairs=sphere_pairs,
        evaluations=sphere_pairs * n_samples, batch=batch,
        memory=int(batch * per_cfg + nf * nf * 16 + min(
            max_memory // 2, _PAIR_BYTES * batch * min(CLUSTER, int(np.max(c, initial=1))) ** 2)))
    return cost, tile


def pair_sampling_cost(robot: RobotModel, n_samples: int = 10000, *, batch: int = 1024,
                       max_memory: int = MAX_MEMORY) -> PairSamplingCost:
    """The work and memory of :func:`never_colliding_pairs` with these arguments, without
    doing it (sizes only)."""
    model = robot
    n_samples = check_int(n_samples, "n_samples", 1)
    batch = check_int(batch, "batch", 1)
    return _plan(model, n_samples, batch, _memory_arg(max_memory))[0]


def never_colliding_pairs(robot: RobotLike, n_samples: int = 10000, seed: int = 0,
                          margin: float = 0.0, *, batch: int = 1024,
                          max_memory: int = MAX_MEMORY, verbose: bool = False,
                          adjacency: str = "rigid", always_fraction: float = 1.0) -> SelfPairs:
    """Adjacent and never-colliding frame pairs of ``robot`` (name or RobotModel) over
    ``n_samples`` configurations drawn uniformly within the joint limits with
    ``numpy.random.default_rng(seed)`` (FK on the CPU in float64, at most ``batch`` at a
    time). ``margin`` [m]: a pair counts as colliding when its spheres come closer than this.
    ``adjacency``: ``"rigid"`` (:func:`adjacent_pairs`) or ``"moveit"``
    (:func:`moveit_adjacent_pairs`); ``always_fraction``: a tested pair colliding in at
    least this share of the samples is "always" colliding (in (0, 1]; MoveIt's setup
    assistant: :data:`ALWAYS_FRACTION`).

    Memory is bounded by ``max_memory`` [bytes] (default 256 MB) at any sphere count: the
    FK batch shrinks with the number of spheres, and every frame pair's sphere-pair distances
    are computed in blocks of configurations and tiles of spheres. A frame pair is computed in
    a configuration only where the distance of the two frames' bounding spheres is below
    ``margin`` and below the pair's smallest distance so far (otherwise neither the collision
    count nor the minimum can change), so the results are exact; frames of more than
    :data:`CLUSTER` spheres are culled per cluster of spheres. ``verbose`` prints
    :func:`pair_sampling_cost` before the work. A MemoryError is raised before the work when
    the estimate exceeds the available memory."""
    model = get_robot(robot)
    n_samples = check_int(n_samples, "n_samples", 1)
    seed = check_int(seed, "seed", 0)
    batch = check_int(batch, "batch", 1)
    max_memory = _memory_arg(max_memory)
    if isinstance(margin, bool) or not isinstance(margin, (int, float, np.floating, np.integer)) \
            or not np.isfinite(margin):
        raise ValueError(f"margin: expected a finite distance [m], got {margin!r}")
    margin = float(margin)
    if adjacency not in ("rigid", "moveit"):
        raise ValueError(f"adjacency: expected 'rigid' or 'moveit', got {adjacency!r}")
    if isinstance(always_fraction, bool) or not isinstance(always_fraction, (int, float)) \
            or not 0.0 < always_fraction <= 1.0:
        raise ValueError(f"always_fraction: expected a share in (0, 1], got {always_fraction!r}")
    sf, sp, sr = model.sphere_arrays()
    if len(sr) == 0:
        raise ValueError(f"robot: '{model.name}' has no collision spheres")
    lim = model.joint_limits
    if not np.all(np.isfinite(lim)):
        raise ValueError(f"robot: '{model.name}' has infinite joint limits; cannot sample")
    cost, tile = _plan(model, n_samples, batch, max_memory)
    if verbose:
        print(cost, flush=True)
    check_memory(cost.memory + n_samples * model.n_dof * 8, "self-pair sampling",
                 "pass a smaller max_memory")
    batch = cost.batch
    rng = np.random.default_rng(seed)
    q = lim[:, 0] + rng.random((n_samples, model.n_dof)) * (lim[:, 1] - lim[:, 0])

    order = np.argsort(sf, kind="stable")
    sf, sp, sr = sf[order], sp[order], sr[order]
    frames, starts = np.unique(sf, return_index=True)
    ends = np.append(starts[1:], len(sf))
    nb = len(frames)
    # each frame's spheres in clusters of at most CLUSTER (sorted along the frame's principal
    # axis; the order within a frame changes no minimum), each with a bounding sphere (frame
    # coordinates, a little inflated so that rounding never makes a bound exceed a distance)
    groups: list[list[int]] = []        # per frame: its cluster indices
    g0: list[int] = []
    g1: list[int] = []
    gc: list[np.ndarray] = []
    gr: list[float] = []
    for i, (a, e) in enumerate(zip(starts, ends)):
        p = sp[a:e]
        if e - a > CLUSTER:
            u = np.linalg.svd(p - p.mean(axis=0), full_matrices=False)[2][0]
            o = a + np.argsort(p @ u, kind="stable")
            sp[a:e], sr[a:e] = sp[o], sr[o]
        groups.append([])
        for c in range(a, e, CLUSTER):
            ce = min(c + CLUSTER, e)
            mid = sp[c:ce].mean(axis=0)
            reach = float(np.max(np.linalg.norm(sp[c:ce] - mid, axis=1) + sr[c:ce]))
            groups[i].append(len(g0))
            g0.append(c)
            g1.append(ce)
            gc.append(mid)
            gr.append(reach + 1e-9 * (1.0 + reach))
    gframe = np.repeat(frames, [len(g) for g in groups])
    gc_arr, gr_arr = np.array(gc), np.array(gr)
    dmin = np.full((nb, nb), np.inf)
    hits = np.zeros((nb, nb), np.int64)
    pairs = [(i, j) for i in range(nb) for j in range(i + 1, nb)]
    # frames of one rigid group (fixed or locked joints between them) keep their distance in
    # every configuration: computed in the first sample only, counted for all
    gid = rigid_groups(model)
    rigid = {(i, j) for i, j in pairs if gid[frames[i]] == gid[frames[j]]}
    for s in range(0, n_samples, batch):
        T = fk(model, q[s:s + batch], device="cpu", dtype=np.float64)  # (B, nf, 4, 4)
        B = T.shape[0]
        x = np.empty((B, len(sf), 3))
        for i, f in enumerate(frames):
            Tf = T[:, f]
            x[:, starts[i]:ends[i]] = (np.einsum("bij,sj->bsi", Tf[:, :3, :3],
                                                 sp[starts[i]:ends[i]]) + Tf[:, None, :3, 3])
        Tg = T[:, gframe]
        C = np.einsum("bgij,gj->bgi", Tg[..., :3, :3], gc_arr) + Tg[..., :3, 3]
        del T, Tg
        for i, j in pairs:
            one = (i, j) in rigid
            if one and s > 0:
                continue
            fd = None           # (B,) the pair's smallest distance per sample (inf: > bound)
            for ga in groups[i]:
                for gb in groups[j]:
                    bound = np.linalg.norm(C[:, ga] - C[:, gb], axis=-1) - gr_arr[ga] - gr_arr[gb]
                    if one:
                        bound = bound[:1]
                    todo = np.flatnonzero(bound < max(margin, dmin[i, j]))
                    if not len(todo):
                        continue
                    d = _frame_pair_min(x, sr, todo, g0[ga], g1[ga], g0[gb], g1[gb], tile)
                    if fd is None:
                        fd = np.full(B, np.inf)
                    fd[todo] = np.minimum(fd[todo], d)
                    dmin[i, j] = min(dmin[i, j], float(d.min()))
            if fd is not None:
                hits[i, j] += (n_samples * int(fd[0] < margin) if one
                               else int(np.count_nonzero(fd < margin)))
        del x, C
    dmin = np.minimum(dmin, dmin.T)
    hits = hits + hits.T

    nf = model.n_frames
    min_distance = np.full((nf, nf), np.inf)
    rate = np.zeros((nf, nf))
    ix = np.ix_(frames, frames)
    min_distance[ix] = dmin
    rate[ix] = hits / n_samples
    np.fill_diagonal(min_distance, np.inf)
    np.fill_diagonal(rate, 0.0)
    adjacent = moveit_adjacent_pairs(model) if adjacency == "moveit" else adjacent_pairs(model)
    adj = set(adjacent)
    tested = [(int(a), int(b)) for i, a in enumerate(frames) for b in frames[i + 1:]
              if (int(a), int(b)) not in adj]
    never = [p for p in tested if rate[p] == 0.0]
    # hits / n_samples >= fraction, in integers (no rounding at 100 %)
    need = math.ceil(float(always_fraction) * n_samples - 1e-9)
    always = [p for p in tested if rate[p] * n_samples >= need - 1e-6]
    return SelfPairs(adjacent=adjacent, never_colliding=never, always_colliding=always,
                     min_distance=min_distance, collision_rate=rate, samples=q, seed=seed,
                     margin=margin, adjacency=adjacency, always_fraction=float(always_fraction))


def _frame_pair_min(x: np.ndarray, r: np.ndarray, todo: np.ndarray, a0: int, a1: int,
                    b0: int, b1: int, tile: int) -> np.ndarray:
    """(len(todo),) smallest surface distance [m] between spheres ``a0:a1`` and ``b0:b1`` in
    the configurations ``todo`` of the batch's centres ``x`` (B, S, 3), computed in tiles of
    at most ``tile`` x ``tile`` spheres and as many configurations as fit in
    ``tile**2`` sphere pairs."""
    out = np.full(len(todo), np.inf)
    for ta in range(a0, a1, tile):
        ea = min(ta + tile, a1)
        for tb in range(b0, b1, tile):
            eb = min(tb + tile, b1)
            step = max(1, (tile * tile) // ((ea - ta) * (eb - tb)))
            for k in range(0, len(todo), step):
                sel = todo[k:k + step]
                d2 = None
                for c in range(3):   # |xa - xb|^2 summed as numpy's norm does: x, +y, +z
                    e = x[sel, ta:ea, c][:, :, None] - x[sel, tb:eb, c][:, None]
                    e *= e
                    d2 = e if d2 is None else np.add(d2, e, out=d2)
                d = np.sqrt(d2, out=d2)
                d -= r[ta:ea, None]
                d -= r[None, tb:eb]
                out[k:k + step] = np.minimum(out[k:k + step], d.min(axis=(1, 2)))
    return out



def default_pairs(robot: RobotModel, home: Any, contact: Any
                  ) -> tuple[list[tuple[int, int, float]], list[tuple[int, int, float]]]:
    """MoveIt's "Default" rule, checked against the robot's own geometry: the checked frame
    pairs (``RobotModel.allowed_collision_pairs``) whose spheres overlap at ``home``
    ((n_dof,) [rad or m]), split into ``(default, fit)``, each ``[(a, b, depth [m] < 0)]``
    (frame indices ``a < b``, deepest first): ``default`` where ``contact(a, b)`` is true
    (the pair's geometry touches at ``home``: excluded, as MoveIt does), ``fit`` where it
    is false (the spheres reach too far: a fit to correct, never an exclusion). ``contact``:
    a callable ``(frame a, frame b) -> bool``."""
    from jwarp.world.model_check import home_self_collisions

    model = robot
    q = np.asarray(home, np.float64).reshape(-1)
    if q.shape != (model.n_dof,) or not np.all(np.isfinite(q)):
        raise ValueError(f"home: expected {model.n_dof} finite joint values, got shape "
                         f"{q.shape}")
    if not callable(contact):
        raise TypeError(f"contact: expected a callable (frame a, frame b) -> bool, got "
                        f"{type(contact).__name__}")
    default: list[tuple[int, int, float]] = []
    fit: list[tuple[int, int, float]] = []
    for na, nb, depth in home_self_collisions(model, q):
        a, b = sorted((model.frame_index(na), model.frame_index(nb)))
        (default if contact(a, b) else fit).append((a, b, depth))
    return default, fit


def with_default_pairs(robot: RobotModel, pairs: Any) -> RobotModel:
    """A copy of ``robot`` whose ``exclude_pairs`` also hold ``pairs`` (frame index pairs,
    e.g. the ``default`` of :func:`default_pairs`; extra items are ignored), listed by name
    in ``notes['self_collision_default']`` (added to those listed already)."""
    import json

    model = robot
    nf = model.n_frames
    new = []
    for p in pairs:
        a, b = int(p[0]), int(p[1])
        if not (0 <= a < nf and 0 <= b < nf) or a == b:
            raise ValueError(f"pairs: frame pair ({a}, {b}) out of range for robot "
                             f"'{model.name}' ({nf} frames)")
        new.append((min(a, b), max(a, b)))
    if not new:
        return model
    sc = model.self_collision
    have = {tuple(sorted(p)) for p in sc.exclude_pairs}
    names = model.frame_names
    notes = dict(model.notes)
    listed = json.loads(notes.get(DEFAULT_NOTE) or "[]")
    listed += [[names[a], names[b]] for a, b in new if [names[a], names[b]] not in listed]
    notes[DEFAULT_NOTE] = json.dumps(listed)
    new_sc = SelfCollision(groups={k: list(v) for k, v in sc.groups.items()},
                           include_pairs=list(sc.include_pairs),   # exclusion wins
                           exclude_pairs=list(sc.exclude_pairs)
                           + sorted(set(new) - have))
    return model.copy(self_collision=new_sc, notes=notes)


def with_self_pairs(robot: RobotLike, pairs: SelfPairs, *, replace: bool = True) -> RobotModel:
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
    out = model.copy(self_collision=sc, notes=notes)
    old_reasons = {} if replace else pair_reasons(model)
    return with_pair_reasons(out, {**sampled_reasons(model, pairs), **old_reasons})


def sampled_reasons(robot: RobotModel, pairs: SelfPairs) -> dict[tuple[int, int], tuple[str, str]]:
    """``{(a, b): (reason, why)}`` of the exclusions of the sampled ``pairs``: Adjacent,
    Always (with its share of the samples), Never (with the closest distance seen)."""
    model = robot
    n = len(pairs.samples)
    out: dict[tuple[int, int], tuple[str, str]] = {}
    for a, b in pairs.adjacent:
        if pairs.adjacency == "moveit":
            p = model.parents
            why = ("parent and child" if p[a] == b or p[b] == a else
                   "joined through frames without collision geometry")
        else:
            why = "joined by a joint or rigidly attached"
        out[(a, b)] = ("Adjacent", why)
    for a, b in pairs.always_colliding:
        out[(a, b)] = ("Always", f"in collision in {100 * pairs.collision_rate[a, b]:.1f} % of "
                                 f"{n} random configurations (>= "
                                 f"{100 * pairs.always_fraction:g} %)")
    for a, b in pairs.never_colliding:
        d = pairs.min_distance[a, b]
        out[(a, b)] = ("Never", f"in collision in none of {n} random configurations "
                                f"(closest {1e3 * d:.1f} mm)" if math.isfinite(d) else
                       f"in collision in none of {n} random configurations")
    return out


def write_self_pairs(robot: RobotLike, out: str | os.PathLike, pairs: SelfPairs | None = None, *,
                     replace: bool = True, **options: Any) -> RobotModel:
    """Compute the pairs (``options`` go to :func:`never_colliding_pairs`) unless given, and
    save the robot with them as JSON to ``out`` (atomically). Returns the new model."""
    out = Path(out)
    if not out.parent.is_dir():
        raise ValueError(f"out: folder '{out.parent}' does not exist")
    if pairs is not None and options:
        raise TypeError(f"options {sorted(options)} given with precomputed pairs")
    model = get_robot(robot)
    if pairs is None:
        pairs = never_colliding_pairs(model, **options)
    model = with_self_pairs(model, pairs, replace=replace)
    model.save(out)
    return model
