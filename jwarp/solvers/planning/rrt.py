"""RRT-Connect in joint space: the planner's fallback (:attr:`PlanOptions.fallback`).

Bidirectional rapidly-exploring random trees (Kuffner and LaValle, ICRA 2000) from the
start and the goal, in numpy on top of jwarp's batched checks. Each round draws ``batch``
configurations within the joint limits (:func:`jwarp.core.limits.sample_within_limits`;
with probability ``goal_bias`` the other tree's root instead), extends one tree from the
nearest node of each sample by at most ``step`` (joint-space Euclidean norm), keeps the
new nodes whose state is collision-free (:func:`jwarp.world.path_feasibility.collision_free`)
and whose edge is feasible (:func:`jwarp.world.path_feasibility.path_feasible` on the batch of
edges ``(E, 2, n_dof)``), then connects the other tree greedily towards every new node:
the straight segment from its nearest node, cut into edges of at most ``step``, is
checked in one batch and its longest feasible prefix added. A complete connection joins
the trees; the trees swap roles every round. The path is then shortcut (random pairs of
its nodes joined by straight segments where feasible, in batches) and can be resampled to
the planner's waypoints (:func:`resample_path`).

The checks are those of :mod:`jwarp.world.path_feasibility` (``collision_free`` and
``path_feasible``): on the rigid model ``path_feasible`` checks the continuous motion of
every edge with :func:`jwarp.world.path_feasibility.certify_check`, the very check (pairs,
margins, evaluation budget) with which the planner certifies an RRT fallback path, so a
path the trees return is certified there as it is; on the elastic model (``kappa``) its
substeps are sized so that no sphere centre moves more than half the world's resolution
between two substeps (:func:`jwarp.world.path_feasibility.substeps_for_voxel`, ``safety``
2), or ``RRTOptions.n_substeps``.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from jwarp.core.arrays import real_array, real_number, resolve_device
from jwarp.core.limits import sample_within_limits, within_limits
from jwarp.core.types import DeviceLike
from jwarp.model import RobotModel
from jwarp.utils.checks import check_int
from jwarp.world import path_feasibility as _fz

#: samples per problem per round (:attr:`RRTOptions.batch` None) on the CPU
CPU_BATCH = 32
#: new nodes per problem per round the other tree connects to (``n_connect`` None), CPU
CPU_CONNECT = 4
#: samples per problem per round on a CUDA device: a round's one launch checks every
#: problem's samples at once, so a wider round costs about as much as a narrow one there
CUDA_BATCH = 128
#: new nodes per problem per round the other tree connects to, on a CUDA device
CUDA_CONNECT = 16


@dataclass
class RRTOptions:
    """Options of :func:`rrt_connect` (ValueError/TypeError naming the field from
    :meth:`validate`).

    Attributes:
        step: the longest extension of a tree in one step and the longest edge checked
            in one piece [rad, m for prismatic joints], joint-space Euclidean norm, > 0.
        max_samples: most random samples per problem, >= 1 (per try: the planner's
            fallback for one problem starts new trees while time is left).
        time_limit: seconds per problem (None: no limit but the caller's deadline), > 0.
        goal_bias: probability that a sample is the other tree's root, in [0, 1].
        seed: random seed (an integer >= 0, a numpy Generator or None: fresh entropy).
        shortcut_iterations: random shortcut pairs tried on the found path, >= 0 (in
            rounds of ``batch`` pairs).
        batch: random samples drawn per problem per round (each extends the tree by at
            most one new node; also the shortcut pairs tried per round), >= 1; None: by
            the checks' device (:func:`rrt_widths`: :data:`CPU_BATCH` on the CPU,
            :data:`CUDA_BATCH` on a CUDA device, whose one launch per round checks every
            problem's samples at once).
        n_connect: the new nodes of a round (those nearest to the other tree) that the
            other tree tries to connect to, per problem, >= 1; None: by the device
            (:data:`CPU_CONNECT`, :data:`CUDA_CONNECT`).
        n_substeps: substeps per edge of the elastic model's checks, >= 1; None sizes them
            to the world's resolution per batch of edges (no sphere centre moves more than
            half of it); the rigid model's edge check is continuous (no substeps).
    """

    step: float = 0.5
    max_samples: int = 4000
    time_limit: float | None = None
    goal_bias: float = 0.1
    seed: Any = 0
    shortcut_iterations: int = 64
    batch: int | None = None
    n_connect: int | None = None
    n_substeps: int | None = None

    def validate(self) -> None:
        step = real_number(self.step, "rrt.step")
        if not (math.isfinite(step) and step > 0):
            raise ValueError(f"rrt.step: expected a number > 0, got {self.step!r}")
        for name, lo in (("max_samples", 1), ("shortcut_iterations", 0), ("batch", 1),
                         ("n_connect", 1)):
            v = getattr(self, name)
            if v is not None or name not in ("batch", "n_connect"):
                check_int(v, f"rrt.{name}", lo)
        if self.n_substeps is not None:
            v = self.n_substeps
            check_int(v, "rrt.n_substeps", 1)
        if self.time_limit is not None:
            t = real_number(self.time_limit, "rrt.time_limit")
            if not (math.isfinite(t) and t > 0):
                raise ValueError(f"rrt.time_limit: expected a number > 0 [s] or None, got "
                                 f"{self.time_limit!r}")
        b = real_number(self.goal_bias, "rrt.goal_bias")
        if not (0.0 <= b <= 1.0):
            raise ValueError(f"rrt.goal_bias: expected a number in [0, 1], got "
                             f"{self.goal_bias!r}")
        seed = self.seed
        if not (seed is None or isinstance(seed, (np.random.Generator, np.random.SeedSequence))) \
                and (isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0):
            raise ValueError(f"rrt.seed: expected an integer >= 0, a Generator or None, "
                             f"got {seed!r}")


def rrt_widths(options: RRTOptions, device_is_cpu: bool) -> tuple[int, int]:
    """``(batch, n_connect)`` of ``options`` (:class:`RRTOptions`): the values set, else
    (None) the device's: :data:`CPU_BATCH` and :data:`CPU_CONNECT` on the CPU,
    :data:`CUDA_BATCH` and :data:`CUDA_CONNECT` on a CUDA device."""
    batch, conn = ((CPU_BATCH, CPU_CONNECT) if device_is_cpu
                   else (CUDA_BATCH, CUDA_CONNECT))
    return (batch if options.batch is None else int(options.batch),
            conn if options.n_connect is None else int(options.n_connect))


@dataclass
class RRTResult:
    """Result of :func:`rrt_connect`.

    path (k, n_dof) start ... goal (every edge checked feasible; shortcut), or None when
    the trees did not connect; success; stop_reason "connected", "max_samples" or
    "time_limit"; n_samples random samples drawn; n_nodes nodes of both trees; raw_nodes
    nodes of the path before shortcutting; n_substeps the substeps per edge of the last
    check; wall_time [s]."""

    path: np.ndarray | None
    success: bool
    stop_reason: str
    n_samples: int
    n_nodes: int
    raw_nodes: int
    n_substeps: int
    wall_time: float
    timings: dict = field(default_factory=dict)


class _Tree:
    """Nodes (N, n) and parents (N,) in growing arrays."""

    def __init__(self, root: np.ndarray) -> None:
        self.q = np.empty((256, len(root)))
        self.parent = np.empty(256, np.int64)
        self.q[0], self.parent[0], self.n = root, -1, 1

    @property
    def nodes(self) -> np.ndarray:
        return self.q[:self.n]

    def add(self, q: np.ndarray, parent: np.ndarray) -> np.ndarray:
        k = len(q)
        while self.n + k > len(self.q):
            self.q = np.concatenate([self.q, np.empty_like(self.q)])
            self.parent = np.concatenate([self.parent, np.empty_like(self.parent)])
        idx = np.arange(self.n, self.n + k)
        self.q[idx], self.parent[idx] = q, parent
        self.n += k
        return idx

    def nearest(self, x: np.ndarray) -> np.ndarray:
        """Index of the nearest node of each row of x (K, n)."""
        nodes = self.nodes
        d = (x * x).sum(1)[:, None] - 2.0 * x @ nodes.T + (nodes * nodes).sum(1)[None]
        return np.argmin(d, axis=1)

    def branch(self, i: int) -> np.ndarray:
        """Nodes from the root to node i, (k, n)."""
        out = []
        while i >= 0:
            out.append(self.q[i])
            i = int(self.parent[i])
        return np.array(out[::-1])


class _Checks:
    """Batched state and edge checks through :mod:`jwarp.world.path_feasibility`. With an
    ``endpoint_margin`` below ``margin`` the segments that start or end at one of the
    ``roots`` (start, goal) are checked at that clearance, every other at ``margin``."""

    def __init__(self, model: Any, world: Any, margin: float, kappa: Any, device: DeviceLike,
                 n_substeps: int | None, endpoint_margin: float | None = None,
                 roots: np.ndarray | None = None, self_margin: float = 0.0,
                 meshes: bool = True) -> None:
        self.model, self.world, self.margin = model, world, margin
        self.meshes = meshes
        self.self_margin = float(self_margin)
        self.kappa, self.device, self.n_sub = kappa, device, n_substeps
        self.em = None
        if endpoint_margin is not None and float(endpoint_margin) < margin:
            self.em = float(endpoint_margin)
        self.roots = roots
        self.last_n_sub = n_substeps or 1
        self.time = {"states": 0.0, "edges": 0.0}

    def states(self, q: np.ndarray, margin: float | None = None,
               meshes: bool = False) -> np.ndarray:
        """(N,) bool: the configurations within the limits and free; ``meshes`` (the
        roots): where the spheres touch, the mesh certificate may prove them free."""
        t = time.perf_counter()
        ok = within_limits(self.model, q)
        if ok.any():
            m = self.margin if margin is None else margin
            ok[ok] = _fz.collision_free(self.model, self.world, q[ok], m,
                                        kappa=self.kappa, device=self.device,
                                        self_margin=min(self.self_margin, m),
                                        meshes=self.meshes and meshes)
        self.time["states"] += time.perf_counter() - t
        return ok

    def _is_root(self, q: np.ndarray) -> np.ndarray:
        return np.any(np.all(q[:, None] == self.roots[None], axis=-1), axis=1)

    def paths(self, paths: np.ndarray) -> np.ndarray:
        """(E,) bool: the paths (E, W, n) feasible."""
        if not len(paths):
            return np.zeros(0, bool)
        t = time.perf_counter()
        n_sub = self.n_sub
        if n_sub is None and self.kappa is None:
            n_sub = 1  # the rigid model's path_feasible checks the continuous motion
        elif n_sub is None:  # elastic: substeps at their equilibria, sized to the world
            n_sub = _fz.substeps_for_voxel(self.model, paths, float(self.world.resolution),
                                           safety=_fz.SWEEP_SAFETY,
                                           max_substeps=_fz.MAX_CHECK_SUBSTEPS,
                                           device=self.device)
        self.last_n_sub = n_sub = int(n_sub)
        ok = np.zeros(len(paths), bool)
        if self.roots is None:
            ok[:] = self._feasible(paths, n_sub)
        else:
            head, tail = self._is_root(paths[:, 0]), self._is_root(paths[:, -1])
            end = head | tail
            # the first and last segment at endpoint_margin where a root is at either end;
            # the mesh certificate only there (the roots may be grasps the spheres touch;
            # the nodes between are free for the spheres, and so are the meshes)
            ok[~end] = self._feasible(paths[~end], n_sub, meshes=False)
            ok[end] = self._feasible(paths[end], n_sub, self.em)
            if self.em is not None and paths.shape[1] > 2:
                # ... but the end away from the root at margin
                for sel, seg in ((end & ~tail, slice(-2, None)), (end & ~head, slice(0, 2))):
                    idx = np.nonzero(sel & ok)[0]
                    if len(idx):
                        ok[idx] = self._feasible(paths[idx, seg], n_sub)
        self.time["edges"] += time.perf_counter() - t
        return ok

    def _feasible(self, paths: np.ndarray, n_sub: int, em: float | None = None,
                  meshes: bool = True) -> np.ndarray:
        if not len(paths):
            return np.zeros(0, bool)
        kw = {} if em is None else {"endpoint_margin": em}
        return np.asarray(_fz.path_feasible(self.model, self.world, paths, n_sub,
                                            margin=self.margin, kappa=self.kappa,
                                            device=self.device, self_margin=self.self_margin,
                                            meshes=self.meshes and meshes, **kw),
                          bool).reshape(len(paths))

    def edges(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        return self.paths(np.stack([a, b], axis=1))


def _vector(x: Any, n: int, name: str) -> np.ndarray:
    a = real_array(x, name)
    if a.shape != (n,) or not np.all(np.isfinite(a)):
        raise ValueError(f"{name}: expected {n} finite joint values, got shape {a.shape}")
    return np.array(a, np.float64)


def rrt_connect(robot: RobotModel, world: Any, start: Any, goal: Any,
                options: RRTOptions | None = None, *, margin: float = 0.0, kappa: Any = None,
                device: DeviceLike = None, deadline: float | None = None,
                endpoint_margin: float | None = None, self_margin: float = 0.0,
                meshes: bool = True) -> RRTResult:
    """A feasible path from ``start`` to ``goal`` (n_dof,) by RRT-Connect (module doc).

    Args:
        robot: robot name or RobotModel; world: a :class:`jwarp.world.World`.
        options: :class:`RRTOptions` (None: the defaults).
        margin: clearance [m] of every check; kappa: the elastic model's compliances.
        endpoint_margin: clearance [m] of start and goal and of the edges at them, where
            it is below ``margin`` (None: ``margin``; :attr:`PlanOptions.endpoint_margin`).
        self_margin: clearance [m] between the robot's own spheres (default 0).
        device: Warp device of the checks (None: Warp's default device).
        deadline: ``time.perf_counter()`` value after which the search stops (besides
            ``options.time_limit``).
        meshes: start and goal, and the edges at them, where the spheres refuse them, may
            be proven by the mesh certificate (:mod:`jwarp.world.mesh_check`; a grasp the
            spheres touch); the other nodes and edges are free for the spheres (start and
            goal may always be proven by it).

    Returns:
        :class:`RRTResult`; ``path`` None when the trees did not connect within
        ``max_samples`` or the time.

    Raises:
        ValueError: start or goal outside the limits or in collision, bad options.
    """
    t0 = time.perf_counter()
    o = options or RRTOptions()
    if not isinstance(o, RRTOptions):
        raise TypeError(f"options: expected an RRTOptions, got {type(o).__name__}")
    o.validate()
    batch, n_connect = rrt_widths(o, not resolve_device(device).is_cuda)
    model = robot
    _fz.check_world(model, world)
    n = model.n_dof
    q0, q1 = _vector(start, n, "start"), _vector(goal, n, "goal")
    stop_at = math.inf if deadline is None else float(deadline)
    if o.time_limit is not None:
        stop_at = min(stop_at, t0 + float(o.time_limit))
    rng = o.seed if isinstance(o.seed, np.random.Generator) else np.random.default_rng(o.seed)
    chk = _Checks(model, world, float(margin), kappa, device, o.n_substeps, endpoint_margin,
                  np.stack([q0, q1]), self_margin=self_margin, meshes=bool(meshes))
    ok = chk.states(np.stack([q0, q1]), margin=chk.em, meshes=True)
    for name, good in zip(("start", "goal"), ok):
        if not good:
            m = float(margin) if chk.em is None else chk.em
            raise ValueError(f"{name}: outside the joint limits or in collision (margin "
                             f"{m:g} m)")
    step = float(o.step)

    def result(path, reason, samples, nodes, raw) -> RRTResult:
        return RRTResult(path=path, success=path is not None, stop_reason=reason,
                         n_samples=samples, n_nodes=nodes, raw_nodes=raw,
                         n_substeps=chk.last_n_sub, wall_time=time.perf_counter() - t0,
                         timings=dict(chk.time))

    # the straight line first
    line = _split(q0[None], q1[None], step)[0]
    if chk.edges(line[:-1], line[1:]).all():
        direct = _verify(np.stack([q0, q1]), chk, step)
        if direct is not None:
            return result(direct, "connected", 0, 2, 2)
    trees = [_Tree(q0), _Tree(q1)]  # trees[0] grows from the start
    a = 0                           # the tree extended towards the samples this round
    samples = 0
    found = None
    reason = "max_samples"
    while samples < o.max_samples:
        if time.perf_counter() >= stop_at:
            reason = "time_limit"
            break
        A, B = trees[a], trees[1 - a]
        K = min(batch, o.max_samples - samples)
        near, qn, new, keep = _extend(model, A, B.q[0], K, rng, o.goal_bias, step)
        samples += K
        keep[keep] = chk.states(new[keep])
        sel = np.nonzero(keep)[0]
        if len(sel):
            sel = sel[chk.edges(qn[sel], new[sel])]
        if len(sel):
            ids = A.add(new[sel], near[sel])
            found = _connect(B, A.q[ids], ids, chk, step, n_connect)
            if found is not None:
                ia, ib = found
                pa, pb = A.branch(ia), B.branch(ib)
                path = np.concatenate([pa, pb[::-1]])
                if a == 1:
                    path = path[::-1]
                path[0], path[-1] = q0, q1
                found = path
                reason = "connected"
                break
        a = 1 - a
    nodes = trees[0].n + trees[1].n
    if found is None:
        return result(None, reason, samples, nodes, 0)
    raw = len(found)
    t = time.perf_counter()
    path = shortcut(found, chk, step, o.shortcut_iterations, batch, rng, stop_at)
    chk.time["shortcut"] = time.perf_counter() - t
    path = _verify(path, chk, step)
    if path is None:
        return result(None, "check_mismatch", samples, nodes, raw)
    return result(path, "connected", samples, nodes, raw)


def _extend(model: Any, A: _Tree, other_root: np.ndarray, K: int, rng: np.random.Generator,
            goal_bias: float, step: float) -> tuple:
    """One extension round of tree ``A``: K samples within the limits (with probability
    ``goal_bias`` the other tree's root), each tree's nearest node moved towards its sample
    by at most ``step``: ``(near (K,) node ids, qn (K, n) those nodes, new (K, n), keep
    (K,) bool: moved at all)``."""
    x = sample_within_limits(model, K, rng)
    x[rng.random(K) < goal_bias] = other_root
    near = A.nearest(x)
    qn = A.q[near]
    d = x - qn
    dist = np.linalg.norm(d, axis=1)
    keep = dist > 1e-12
    new = qn + d * np.minimum(1.0, step / np.maximum(dist, 1e-300))[:, None]
    return near, qn, new, keep


def _verify(path: np.ndarray, chk: _Checks, step: float, rounds: int = 3) -> np.ndarray | None:
    """Every edge of ``path`` checked on its own (one batch, substeps sized to the
    batch); an edge that fails is replaced by its pieces at ``step`` (halved every round).
    None if edges still fail after ``rounds`` rounds (the checks disagree at the edges'
    different substeps: a configuration within a hair of an obstacle)."""
    for r in range(rounds + 1):
        ok = chk.edges(path[:-1], path[1:])
        if ok.all():
            return path
        if r == rounds:
            return None
        out = [path[:1]]
        for e in range(len(ok)):
            if ok[e]:
                out.append(path[e + 1:e + 2])
            else:
                out.append(_split(path[e:e + 1], path[e + 1:e + 2], step / 2 ** r)[0, 1:])
        path = np.concatenate(out)
    return None


def _split(a: np.ndarray, b: np.ndarray, step: float, m: int | None = None) -> np.ndarray:
    """Each segment a -> b (K, n) cut into m pieces (default: the longest's count at
    ``step``): points (K, m + 1, n)."""
    if m is None:
        m = max(1, int(np.ceil(np.linalg.norm(b - a, axis=1).max(initial=0.0) / step)))
    u = np.linspace(0.0, 1.0, m + 1)[None, :, None]
    out = a[:, None] + u * (b - a)[:, None]
    out[:, -1] = b  # the ends exact (the checks recognise start and goal)
    return out


def _connect(B: _Tree, targets: np.ndarray, target_ids: np.ndarray, chk: _Checks,
             step: float, limit: int) -> tuple[int, int] | None:
    """Grow B greedily towards the ``limit`` targets (K, n) nearest to it: the segment from
    its nearest node cut into edges of at most ``step``, all checked in one batch; the
    longest feasible prefix of each is added to B. Returns (target id, B node) of a
    complete connection (the shortest one), else None."""
    prep = _connect_edges(B, targets, target_ids, step, limit)
    return _connect_grow(B, prep, chk.edges(prep[-2], prep[-1]))


def _connect_edges(B: _Tree, targets: np.ndarray, target_ids: np.ndarray, step: float,
                   limit: int) -> tuple:
    """The edges of :func:`_connect` (its first half): ``(target_ids, near, dist, m, ea,
    eb)``, the edges ``ea -> eb`` to check."""
    near = B.nearest(targets)
    qb = B.q[near]
    dist = np.linalg.norm(targets - qb, axis=1)
    if len(targets) > limit:
        keep = np.argsort(dist, kind="stable")[:limit]
        targets, target_ids, near, qb, dist = (targets[keep], target_ids[keep], near[keep],
                                               qb[keep], dist[keep])
    m = np.maximum(1, np.ceil(dist / step).astype(np.int64))
    # every target's edges, each cut into its own m pieces
    rows = np.repeat(np.arange(len(targets)), m)
    k = np.arange(len(rows)) - np.repeat(np.cumsum(m) - m, m)
    frac0, frac1 = (k / m[rows])[:, None], ((k + 1) / m[rows])[:, None]
    d = (targets - qb)[rows]
    ea, eb = qb[rows] + frac0 * d, qb[rows] + frac1 * d
    eb[k + 1 == m[rows]] = targets[rows[k + 1 == m[rows]]]
    return target_ids, near, dist, m, ea, eb


def _connect_grow(B: _Tree, prep: tuple, ok: np.ndarray) -> tuple[int, int] | None:
    """The second half of :func:`_connect`: the edges of :func:`_connect_edges` ``prep``
    checked (``ok``), the feasible prefixes added to B; the connection, else None."""
    target_ids, near, dist, m, _, eb = prep
    best = None
    start = 0
    for i, mi in enumerate(m):
        seg = ok[start:start + mi]
        p = mi if seg.all() else int(np.argmin(seg))  # feasible prefix length
        if p == mi:
            if best is None or dist[i] < best[0]:
                best = (dist[i], int(target_ids[i]), int(near[i]))
        elif p > 0:
            pts = eb[start:start + p]
            parents = np.empty(p, np.int64)
            ids = B.add(pts, parents)  # chained: the first from near[i]
            B.parent[ids[0]] = near[i]
            B.parent[ids[1:]] = ids[:-1]
        start += mi
    return None if best is None else (best[1], best[2])


def path_length(path: np.ndarray) -> float:
    """Joint-space length of a polyline (k, n)."""
    return float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum())


def shortcut(path: np.ndarray, chk: Any, step: float, iterations: int, batch: int,
             rng: np.random.Generator, stop_at: float = math.inf) -> np.ndarray:
    """Random shortcuts of ``path`` (k, n): in rounds of ``batch`` random node pairs
    (i, j > i + 1), each straight segment i -> j (cut at ``step``) checked in one batch;
    the feasible ones that do not overlap are applied, the longest saving first."""
    path = np.array(path, np.float64)
    tried = 0
    while tried < iterations and len(path) > 2 and time.perf_counter() < stop_at:
        K = min(batch, iterations - tried)
        tried += K
        pairs, gain = _shortcut_pairs(path, K, rng)
        if not len(pairs):
            continue
        ok = chk.paths(_split(path[pairs[:, 0]], path[pairs[:, 1]], step))
        path = _shortcut_apply(path, pairs, gain, ok)
    return path


def _shortcut_pairs(path: np.ndarray, K: int, rng: np.random.Generator
                    ) -> tuple[np.ndarray, np.ndarray]:
    """K random node pairs (i, j > i + 1) of ``path`` that would shorten it: the distinct
    ones, (P, 2), and their savings (P,)."""
    k = len(path)
    i = rng.integers(0, k - 2, size=K)
    j = i + 2 + np.floor(rng.random(K) * (k - i - 2)).astype(np.int64)
    pairs = np.unique(np.stack([i, j], 1), axis=0)
    pairs = pairs[pairs[:, 1] > pairs[:, 0] + 1]
    if not len(pairs):
        return pairs, np.zeros(0)
    seg = np.linalg.norm(np.diff(path, axis=0), axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    direct = np.linalg.norm(path[pairs[:, 1]] - path[pairs[:, 0]], axis=1)
    gain = cum[pairs[:, 1]] - cum[pairs[:, 0]] - direct
    return pairs[gain > 1e-9], gain[gain > 1e-9]


def _shortcut_apply(path: np.ndarray, pairs: np.ndarray, gain: np.ndarray, ok: np.ndarray
                    ) -> np.ndarray:
    """``path`` with the feasible (``ok``) shortcuts ``pairs`` that do not overlap applied,
    the longest saving first."""
    k = len(path)
    pairs, gain = pairs[ok], gain[ok]
    drop = np.zeros(k, bool)
    used = np.zeros(k - 1, bool)  # segments replaced by an applied shortcut
    for p in np.argsort(-gain):
        a, b = pairs[p]
        if used[a:b].any():
            continue
        used[a:b] = True
        drop[a + 1:b] = True
    return path[~drop]


def resample_path(path: np.ndarray, n_waypoints: int) -> np.ndarray:
    """A polyline (k, n) as ``n_waypoints`` waypoints on it: with k <= n_waypoints every
    node is a waypoint (the path between the waypoints is the polyline itself), the rest
    spread over its segments in proportion to their lengths; else the waypoints spread
    evenly along its length (:func:`jwarp.world.path_feasibility.polyline_path`)."""
    path = np.asarray(path, np.float64)
    k, W = len(path), int(n_waypoints)
    if W < 2:
        raise ValueError(f"n_waypoints: expected >= 2, got {n_waypoints!r}")
    if k > W:
        return _fz.polyline_path(path[0], path[1:-1], path[-1], W)
    seg = np.linalg.norm(np.diff(path, axis=0), axis=1)
    extra = W - k  # waypoints beyond the nodes, shared by the k - 1 segments
    if seg.sum() > 0 and extra > 0:
        share = extra * seg / seg.sum()
        cnt = np.floor(share).astype(np.int64)
        rest = extra - int(cnt.sum())
        cnt[np.argsort(-(share - cnt))[:rest]] += 1
    else:
        cnt = np.zeros(k - 1, np.int64)
        cnt[0] += extra
    out = [path[:1]]
    for s in range(k - 1):
        u = np.linspace(0.0, 1.0, cnt[s] + 2)[1:, None]
        out.append(path[s] + u * (path[s + 1] - path[s]))
    res = np.concatenate(out)
    assert len(res) == W
    return res


# ====================================================================== a batch of problems
class _BatchChecks:
    """The state and edge checks of :func:`rrt_connect_batch`: every problem's
    configurations (edges) of a round in one call. With a batch of worlds
    (:meth:`jwarp.world.sdf.World.batch`, problem b in world b) problem b's block is
    rows ``b G .. b G + k_b`` of a padded array (G the largest block): the configurations
    through ``collision_free(per_world=G)`` (short blocks padded with the problem's start),
    the edges through the continuous check's ``world_group=G`` and ``rows`` (only the
    blocks' edges are read: no padding checked). Rigid model only."""

    def __init__(self, model: Any, world: Any, margin: float, em: float | None,
                 self_margin: float, meshes: np.ndarray, roots: np.ndarray,
                 device: DeviceLike, slot: np.ndarray) -> None:
        self.model, self.world, self.margin, self.em = model, world, margin, em
        self.slot = slot  # problem b's world of the batch
        self.self_margin, self.meshes, self.roots, self.device = (self_margin, meshes, roots,
                                                                 device)
        self.multi = world.n_worlds > 1
        self.mc = _fz.certify_check(model, world, device=device)
        self.time = {"states": 0.0, "edges": 0.0}
        self.calls = {"states": 0, "edges": 0}

    def _layout(self, blocks: dict[int, np.ndarray]) -> tuple[np.ndarray, int]:
        """(rows (sum k_b,), G) of the blocks in order: problem b's rows w G .. w G + k_b
        of the padded array, w its world (one world: the blocks one after another, G =
        0)."""
        sizes = {b: len(x) for b, x in blocks.items()}
        if not self.multi:
            return np.arange(sum(sizes.values())), 0
        G = max(max(sizes.values()), 1)
        rows = np.concatenate([self.slot[b] * G + np.arange(k) for b, k in sizes.items()])
        return rows, G

    def states(self, blocks: dict[int, np.ndarray]) -> dict[int, np.ndarray]:
        """Per problem (N_b,) bool: its configurations (N_b, n) within the limits and free
        at ``margin`` (the spheres alone: the nodes between start and goal)."""
        t = time.perf_counter()
        out = {b: within_limits(self.model, q) for b, q in blocks.items()}
        todo = {b: q[out[b]] for b, q in blocks.items() if out[b].any()}
        if todo:
            free = self.free(todo, self.margin, meshes=False)
            for b in todo:
                out[b][out[b]] = free[b]
            self.calls["states"] += 1
        self.time["states"] += time.perf_counter() - t
        return out

    def free(self, blocks: dict[int, np.ndarray], margin: float, meshes: bool
             ) -> dict[int, np.ndarray]:
        """Per problem its configurations free at ``margin`` (``collision_free``, one call;
        the padding rows of a batch of worlds are the first problem's start)."""
        rows, G = self._layout(blocks)
        q = np.empty((int(rows.max()) + 1, self.model.n_dof))
        q[:] = self.roots[next(iter(blocks)), 0]
        q[rows] = np.concatenate(list(blocks.values()))
        free = _fz.collision_free(self.model, self.world, q, margin, device=self.device,
                                  self_margin=min(self.self_margin, margin),
                                  per_world=G, meshes=meshes)[rows]
        out, at = {}, 0
        for b, x in blocks.items():
            out[b] = free[at:at + len(x)]
            at += len(x)
        return out

    def _root(self, b: int, q: np.ndarray) -> np.ndarray:
        return np.any(np.all(q[:, None] == self.roots[b][None], axis=-1), axis=1)

    def edges(self, items: dict[int, tuple[np.ndarray, np.ndarray]]) -> dict[int, np.ndarray]:
        """Per problem (E_b,) bool: its edges ``a -> b`` (E_b, n) each feasible (the
        continuous check), those at its start or goal at ``endpoint_margin`` (the mesh
        certificate allowed there where the problem allows it), the others at ``margin``
        (the spheres alone)."""
        t = time.perf_counter()
        out = {b: np.zeros(len(a), bool) for b, (a, _) in items.items()}
        end = {b: self._root(b, a) | self._root(b, e) for b, (a, e) in items.items()}
        if self.em is None:  # one call: every edge at margin
            self._check(items, {b: np.ones(len(a), bool) for b, (a, _) in items.items()},
                        end, None, out)
        else:
            self._check(items, {b: ~e for b, e in end.items()}, end, None, out)
            self._check(items, end, end, self.em, out)
        self.time["edges"] += time.perf_counter() - t
        return out

    def _check(self, items: dict, sel: dict, end: dict, em: float | None, out: dict) -> None:
        blocks = {b: np.stack([a[sel[b]], e[sel[b]]], axis=1) for b, (a, e) in items.items()
                  if sel[b].any()}
        if not blocks:
            return
        rows, G = self._layout(blocks)
        n = self.model.n_dof
        P = np.zeros((int(rows.max()) + 1 if self.multi else len(rows), 2, n))
        P[rows] = np.concatenate(list(blocks.values()))
        mesh = np.concatenate([end[b][sel[b]] & self.meshes[b] for b in blocks])
        res = self.mc.check(P, margin=self.margin, endpoint_margin=em,
                            self_margin=self.self_margin, world_group=G, meshes=mesh,
                            rows=rows)
        ok = np.asarray(res.ok, bool)
        at = 0
        for b, x in blocks.items():
            out[b][sel[b]] = ok[at:at + len(x)]
            at += len(x)
        self.calls["edges"] += 1


class _Problem:
    """One problem's search state in :func:`rrt_connect_batch`."""

    def __init__(self, b: int, q0: np.ndarray, q1: np.ndarray, rng: np.random.Generator
                 ) -> None:
        self.b, self.q0, self.q1, self.rng = b, q0, q1, rng
        self.trees = [_Tree(q0), _Tree(q1)]
        self.a = 0
        self.samples = 0
        self.path: np.ndarray | None = None
        self.raw = 0
        self.reason = "max_samples"
        self.done = False
        self.t_end = 0.0
        self.tried = 0  # shortcut pairs tried
        self.straight = False  # solved by the straight line
        self.t_start = 0.0
        self.spent = 0  # samples of earlier trees (RRTBatch restart)
        self.restarts = 0
        self.stop = math.inf  # its own time limit (RRTOptions.time_limit)


def _problem_rows(x: Any, n: int, name: str) -> np.ndarray:
    a = real_array(x, name)
    if a.ndim != 2 or a.shape[1] != n or not len(a):
        raise ValueError(f"{name}: expected shape (B >= 1, {n}), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name}: contains NaN or inf")
    return np.array(a, np.float64)


def problem_rngs(seed: Any, B: int) -> list[np.random.Generator]:
    """One generator per problem of a batch from ``RRTOptions.seed``: a Generator draws
    the children's seeds; an integer, a SeedSequence or None spawns B children."""
    if isinstance(seed, np.random.Generator):
        return [np.random.default_rng(int(s)) for s in seed.integers(0, 2**63 - 1, size=B)]
    ss = seed if isinstance(seed, np.random.SeedSequence) else np.random.SeedSequence(seed)
    return [np.random.default_rng(c) for c in ss.spawn(B)]


def rrt_connect_batch(robot: RobotModel, world: Any, starts: Any, goals: Any,
                      options: RRTOptions | None = None, *, margin: float = 0.0,
                      endpoint_margin: float | None = None, self_margin: float = 0.0,
                      kappa: Any = None, device: DeviceLike = None,
                      deadline: float | None = None, meshes: Any = True,
                      world_index: Any = None) -> list[RRTResult]:
    """RRT-Connect (:func:`rrt_connect`) for a batch of problems at once: problem b from
    ``starts[b]`` to ``goals[b]`` (B, n_dof) in world b of a batch of worlds
    (:meth:`jwarp.world.sdf.World.batch`, B worlds) or all in one world. Every round
    extends the trees of every problem still searching, and checks all their new states
    in one call and all their edges in one (two with an ``endpoint_margin``: the edges at
    a start or goal at that clearance) over the batch; a problem leaves the round once its
    trees connect or its samples (or ``options.time_limit``, from this call's start) are
    spent. The found paths are shortcut and verified edge by edge the same way, all
    problems' checks in one call per round. Each problem draws from its own generator
    (:func:`problem_rngs`), so its result does not depend on the others. The elastic
    model (``kappa``) runs :func:`rrt_connect` per problem. :class:`RRTBatch` is the same
    search a round at a time, with problems joining while others search.

    Args: as :func:`rrt_connect`; ``meshes`` a bool or (B,) bools, one per problem;
    ``world_index`` (B,) distinct ints: problem b in world ``world_index[b]`` of a batch
    of worlds (None: world b; a planner's unsolved problems in its own batch world).

    Returns:
        B :class:`RRTResult` (``timings`` the batch's, shared; ``wall_time`` until the
        problem's search ended).

    Raises:
        ValueError: bad shapes (naming ``starts``, ``goals``, ``meshes`` or ``world``), a
        start or goal outside the limits or in collision, bad options.
    """
    t0 = time.perf_counter()
    o = options or RRTOptions()
    if not isinstance(o, RRTOptions):
        raise TypeError(f"options: expected an RRTOptions, got {type(o).__name__}")
    o.validate()
    if kappa is not None:
        _fz.check_world(robot, world)
        n = robot.n_dof
        q0, q1 = _problem_rows(starts, n, "starts"), _problem_rows(goals, n, "goals")
        B = len(q0)
        slot = _world_slots(world, B, world_index)
        mesh = _mesh_flags(meshes, B)
        rngs = problem_rngs(o.seed, B)
        return [rrt_connect(robot, world.select(int(slot[b])), q0[b], q1[b],
                            replace(o, seed=rngs[b]), margin=margin, kappa=kappa,
                            device=device, deadline=deadline,
                            endpoint_margin=endpoint_margin, self_margin=self_margin,
                            meshes=bool(mesh[b])) for b in range(B)]
    rb = RRTBatch(robot, world, starts, goals, o, margin=margin,
                  endpoint_margin=endpoint_margin, self_margin=self_margin, device=device,
                  meshes=meshes, world_index=world_index)
    stop_at = math.inf if deadline is None else float(deadline)
    if o.time_limit is not None:
        stop_at = min(stop_at, t0 + float(o.time_limit))
    rb.start(np.arange(rb.n_problems))
    rb.run(stop_at)
    rb.finish(rb.connected(), stop_at)
    return [rb.result(b, t0) for b in range(rb.n_problems)]


def _world_slots(world: Any, B: int, world_index: Any) -> np.ndarray:
    """(B,) problem b's world in a batch of worlds (zeros: one world); ValueError naming
    ``world`` or ``world_index``."""
    nw = world.n_worlds
    if world_index is None:
        if nw not in (1, B):
            raise ValueError(f"world: a batch of {nw} worlds for {B} problems (expected one "
                             f"world or {B}, or a world_index)")
        return np.arange(B) if nw > 1 else np.zeros(B, np.int64)
    slot = np.asarray(world_index)
    if slot.shape != (B,) or not np.issubdtype(slot.dtype, np.integer) or (
            nw > 1 and (slot.min() < 0 or slot.max() >= nw or len(np.unique(slot)) != B)):
        raise ValueError(f"world_index: expected ({B},) distinct worlds in [0, {nw}), "
                         f"got {np.asarray(world_index)!r}")
    return slot.astype(np.int64) if nw > 1 else np.zeros(B, np.int64)


def _mesh_flags(meshes: Any, B: int) -> np.ndarray:
    mesh = np.asarray(meshes)
    if mesh.ndim == 0:
        mesh = np.full(B, bool(mesh))
    if mesh.shape != (B,):
        raise ValueError(f"meshes: expected a bool or ({B},) bools, got shape {mesh.shape}")
    return mesh.astype(bool)


class RRTBatch:
    """RRT-Connect for B problems (rigid model), a round at a time: the search of
    :func:`rrt_connect_batch`, which problems join (:meth:`start`) while others are
    searching. A planner hands a problem over as soon as its optimisation stalls, and its
    trees grow between the other problems' gradient steps (no problem waits for the
    batch).

    Problem b runs from ``starts[b]`` to ``goals[b]`` (B, n_dof) in world
    ``world_index[b]`` of a batch of worlds (None: world b; one world: all), with its own
    generator (:func:`problem_rngs` of ``options.seed``), so its result does not depend on
    when it started or on the others. ``restart``: a problem that used up
    ``options.max_samples`` without a path starts new trees (its generator's next
    samples) while the caller's time is left, instead of ending with most of its time
    unspent.

    Raises:
        ValueError/TypeError: as :func:`rrt_connect_batch`.
    """

    def __init__(self, robot: RobotModel, world: Any, starts: Any, goals: Any,
                 options: RRTOptions | None = None, *, margin: float = 0.0,
                 endpoint_margin: float | None = None, self_margin: float = 0.0,
                 device: DeviceLike = None, meshes: Any = True, world_index: Any = None,
                 restart: bool = False) -> None:
        o = options or RRTOptions()
        if not isinstance(o, RRTOptions):
            raise TypeError(f"options: expected an RRTOptions, got {type(o).__name__}")
        o.validate()
        self.options = o
        self.batch, self.n_connect = rrt_widths(o, not resolve_device(device).is_cuda)
        self.robot, self.world, self.device = robot, world, device
        _fz.check_world(robot, world)
        n = robot.n_dof
        q0, q1 = _problem_rows(starts, n, "starts"), _problem_rows(goals, n, "goals")
        if q1.shape != q0.shape:
            raise ValueError(f"goals: expected shape {q0.shape} (one per start), got "
                             f"{q1.shape}")
        self.q0, self.q1 = q0, q1
        self.n_problems = B = len(q0)
        self.slot = _world_slots(world, B, world_index)
        self.mesh = _mesh_flags(meshes, B)
        self.rngs = problem_rngs(o.seed, B)
        m = float(margin)
        em = None
        if endpoint_margin is not None and float(endpoint_margin) < m:
            em = float(endpoint_margin)
        self.margin, self.endpoint_margin = m, endpoint_margin
        self.self_margin = float(self_margin)
        self.chk = _BatchChecks(robot, world, m, em, self.self_margin, self.mesh,
                                np.stack([q0, q1], 1), device, self.slot)
        self.step = float(o.step)
        self.restart = bool(restart)
        self.problems: dict[int, _Problem] = {}
        self._active: list[_Problem] = []
        self._round_s = 0.0  # seconds of the last round
        self._finished: set[int] = set()

    def start(self, rows: Any) -> None:
        """Problems ``rows`` (ints, not started before) join the search: their start and
        goal checked (ValueError naming ``starts[b]`` / ``goals[b]``), their straight lines
        (in pieces of ``options.step``) tried first, then their trees grown by
        :meth:`round` (each for at most ``options.time_limit`` from now)."""
        rows = [int(b) for b in np.atleast_1d(np.asarray(rows, np.int64))]
        bad = [b for b in rows if b in self.problems or not 0 <= b < self.n_problems]
        if bad:
            raise ValueError(f"rows: {bad[0]} is not a problem of this batch that has not "
                             f"started")
        if not rows:
            return
        q0, q1, chk = self.q0, self.q1, self.chk
        _check_roots(self.robot, self.world, chk, q0, q1, self.device, rows)
        probs = {b: _Problem(b, q0[b], q1[b], self.rngs[b]) for b in rows}
        now = time.perf_counter()
        tl = self.options.time_limit
        for p in probs.values():
            p.t_start = now
            p.stop = math.inf if tl is None else now + float(tl)
        self.problems.update(probs)
        lines = {b: _split(q0[b][None], q1[b][None], self.step)[0] for b in rows}
        ok = chk.edges({b: (x[:-1], x[1:]) for b, x in lines.items()})
        clear = [b for b in rows if ok[b].all()]
        if clear:
            direct = chk.edges({b: (q0[b][None], q1[b][None]) for b in clear})
            for b in clear:
                p = probs[b]
                # the direct edge, else its pieces (checked: _verify's first split)
                p.path = np.stack([q0[b], q1[b]]) if direct[b].all() else lines[b]
                p.raw, p.reason, p.done, p.straight = 2, "connected", True, True
                p.t_end = time.perf_counter()
        self._active += [p for p in probs.values() if not p.done]

    @property
    def active(self) -> np.ndarray:
        """The problems whose trees are still growing (ints)."""
        return np.array([p.b for p in self._active], np.int64)

    def round(self, stop_at: float = math.inf) -> list[int]:
        """One round for every active problem (``batch`` samples each, their states and
        edges checked in one call each over the batch); returns the problems whose trees
        connected in it. A problem whose samples are spent leaves (or starts new trees,
        ``restart``, while ``stop_at`` is ahead); every one leaves when the round would
        end after ``stop_at`` at the last round's pace."""
        before = {p.b for p in self._active if p.path is None}
        t = time.perf_counter()
        # a round that would end after stop_at at the last one's pace is not started
        self._active = _grow_round(self.robot, self._active, self.chk, self.options,
                                   self.step, stop_at - self._round_s, self.batch,
                                   self.n_connect, self.restart)
        self._round_s = time.perf_counter() - t
        return [b for b in sorted(before) if self.problems[b].path is not None]

    def run(self, stop_at: float = math.inf) -> None:
        """Rounds until no problem is active."""
        while self._active:
            self.round(stop_at)

    def connected(self) -> list[int]:
        """The problems whose trees connected (not by their straight line) and whose
        paths :meth:`finish` has not shortcut and verified yet."""
        return [b for b, p in self.problems.items() if p.path is not None
                and not p.straight and b not in self._finished]

    def finish(self, rows: Any, stop_at: float = math.inf) -> None:
        """The paths of ``rows`` (connected problems) shortcut and verified edge by edge,
        all at once (a path that fails its re-check is dropped: ``check_mismatch``)."""
        found = [self.problems[int(b)] for b in rows
                 if int(b) not in self._finished and self.problems[int(b)].path is not None
                 and not self.problems[int(b)].straight]
        if not found:
            return
        t = time.perf_counter()
        _shortcut_batch(found, self.chk, self.step, self.options, stop_at, self.batch)
        self.chk.time["shortcut"] = self.chk.time.get("shortcut", 0.0) + (
            time.perf_counter() - t)
        _verify_batch(self.robot, self.world, found, self.chk, self.step, self.margin,
                      self.endpoint_margin, self.self_margin, self.mesh, self.device)
        self._finished.update(p.b for p in found)

    def result(self, b: int, t0: float | None = None) -> RRTResult:
        """Problem ``b``'s :class:`RRTResult` (``wall_time`` from ``t0``, default its own
        start, until its search ended); "not_started" for a problem that never joined."""
        p = self.problems.get(int(b))
        timings = dict(self.chk.time)
        timings.update({f"{k}_calls": float(v) for k, v in self.chk.calls.items()})
        if p is None:
            return RRTResult(path=None, success=False, stop_reason="not_started",
                             n_samples=0, n_nodes=0, raw_nodes=0, n_substeps=1,
                             wall_time=0.0, timings=timings)
        start = p.t_start if t0 is None else t0
        return RRTResult(path=p.path, success=p.path is not None, stop_reason=p.reason,
                         n_samples=p.samples + p.spent,
                         n_nodes=p.trees[0].n + p.trees[1].n, raw_nodes=p.raw,
                         n_substeps=1, wall_time=(p.t_end or time.perf_counter()) - start,
                         timings=timings)


def _check_roots(model: Any, world: Any, chk: _BatchChecks, q0: np.ndarray, q1: np.ndarray,
                 device: DeviceLike, rows: list[int]) -> None:
    """ValueError naming ``starts[b]`` or ``goals[b]`` (b of ``rows``) outside the limits
    or in collision at the endpoint clearance (the mesh certificate where the problem
    allows it)."""
    mr = chk.margin if chk.em is None else chk.em
    idx = np.asarray(rows, np.int64)
    q = np.stack([q0[idx], q1[idx]], 1).reshape(-1, model.n_dof)
    lim = within_limits(model, q)
    got = chk.free({b: q[2 * k:2 * k + 2] for k, b in enumerate(rows)}, mr, meshes=False)
    free = np.concatenate([got[b] for b in rows]) & lim
    for r in np.nonzero(~free & lim & np.repeat(chk.meshes[idx], 2))[0]:
        w = world.select(int(chk.slot[idx[r // 2]]))
        free[r] = _fz.collision_free(model, w, q[r:r + 1], mr, device=device,
                                     self_margin=min(chk.self_margin, mr), meshes=True)[0]
    for r in range(len(q)):
        if not free[r]:
            name = ("starts", "goals")[r % 2]
            raise ValueError(f"{name}[{idx[r // 2]}]: outside the joint limits or in "
                             f"collision (margin {mr:g} m)")


def _grow_round(model: Any, active: list[_Problem], chk: _BatchChecks, o: RRTOptions,
                step: float, stop_at: float, batch: int, n_connect: int,
                restart: bool = False) -> list[_Problem]:
    """One round of :func:`rrt_connect` for every problem of ``active`` at once; returns
    those still active after it (not connected, samples and time left); ``batch``
    samples and ``n_connect`` connections per problem per round (:func:`rrt_widths`);
    ``restart``: a problem whose samples are spent starts new trees while ``stop_at`` is
    ahead."""
    now = time.perf_counter()
    for p in active:
        if p.samples >= o.max_samples:
            if restart and now < min(stop_at, p.stop):
                p.spent += p.samples
                p.samples = 0
                p.trees = [_Tree(p.q0), _Tree(p.q1)]
                p.a = 0
                p.restarts += 1
            else:
                p.done, p.t_end = True, now
        elif now >= min(stop_at, p.stop):
            p.done, p.reason, p.t_end = True, "time_limit", now
    active = [p for p in active if not p.done]
    if not active:
        return active
    ext: dict[int, tuple] = {}
    for p in active:
        A, Bt = p.trees[p.a], p.trees[1 - p.a]
        K = min(batch, o.max_samples - p.samples)
        ext[p.b] = _extend(model, A, Bt.q[0], K, p.rng, o.goal_bias, step)
        p.samples += K
    states = chk.states({b: e[2][e[3]] for b, e in ext.items() if e[3].any()})
    cand = {}
    for b, e in ext.items():
        keep = e[3]
        if b in states:
            keep[keep] = states[b]
        sel = np.nonzero(keep)[0]
        if len(sel):
            cand[b] = sel
    edge_ok = chk.edges({b: (ext[b][1][sel], ext[b][2][sel]) for b, sel in cand.items()})
    conn: dict[int, tuple] = {}
    byb = {p.b: p for p in active}
    for b, sel in cand.items():
        sel = sel[edge_ok[b]]
        if len(sel):
            p = byb[b]
            near, _, new, _ = ext[b]
            A, Bt = p.trees[p.a], p.trees[1 - p.a]
            ids = A.add(new[sel], near[sel])
            conn[b] = _connect_edges(Bt, A.q[ids], ids, step, n_connect)
    conn_ok = chk.edges({b: (c[-2], c[-1]) for b, c in conn.items()})
    for p in active:
        found = None
        if p.b in conn:
            found = _connect_grow(p.trees[1 - p.a], conn[p.b], conn_ok[p.b])
        if found is not None:
            ia, ib = found
            pa, pb = p.trees[p.a].branch(ia), p.trees[1 - p.a].branch(ib)
            path = np.concatenate([pa, pb[::-1]])
            if p.a == 1:
                path = path[::-1]
            path[0], path[-1] = p.q0, p.q1
            p.path, p.raw, p.reason = path, len(path), "connected"
            p.done, p.t_end = True, time.perf_counter()
        else:
            p.a = 1 - p.a
    return [p for p in active if not p.done]


def _shortcut_batch(found: list[_Problem], chk: _BatchChecks, step: float, o: RRTOptions,
                    stop_at: float, batch: int) -> None:
    """:func:`shortcut` of every found path at once: per round each path's ``batch`` pairs,
    all their pieces (edges at ``step``) checked in one call."""
    for p in found:
        p.path = np.array(p.path, np.float64)
        p.tried = 0
    while time.perf_counter() < stop_at:
        todo = [p for p in found if p.tried < o.shortcut_iterations and len(p.path) > 2]
        if not todo:
            break
        props: dict[int, tuple] = {}
        for p in todo:
            assert p.path is not None
            K = min(batch, o.shortcut_iterations - p.tried)
            p.tried += K
            pairs, gain = _shortcut_pairs(p.path, K, p.rng)
            if len(pairs):
                pts = _split(p.path[pairs[:, 0]], p.path[pairs[:, 1]], step)
                props[p.b] = (pairs, gain, pts)
        if not props:
            continue
        n = props[next(iter(props))][2].shape[-1]
        ok = chk.edges({b: (v[2][:, :-1].reshape(-1, n), v[2][:, 1:].reshape(-1, n))
                        for b, v in props.items()})
        for p in todo:
            if p.b in props:
                pairs, gain, pts = props[p.b]
                good = ok[p.b].reshape(len(pairs), -1).all(axis=1)
                assert p.path is not None
                p.path = _shortcut_apply(p.path, pairs, gain, good)


def _verify_batch(model: Any, world: Any, found: list[_Problem], chk: _BatchChecks,
                  step: float, margin: float, endpoint_margin: float | None,
                  self_margin: float, mesh: np.ndarray, device: DeviceLike) -> None:
    """Every found path's edges checked again, all in one call; a path with a failing
    edge goes to :func:`_verify` on its own (``check_mismatch`` if that fails too)."""
    if not found:
        return
    ok = chk.edges({p.b: (p.path[:-1], p.path[1:]) for p in found if p.path is not None})
    for p in found:
        if p.path is None or ok[p.b].all():
            continue
        one = _Checks(model, world.select(int(chk.slot[p.b])), margin, None, device, None, endpoint_margin,
                      np.stack([p.q0, p.q1]), self_margin=self_margin, meshes=bool(mesh[p.b]))
        p.path = _verify(p.path, one, step)
        if p.path is None:
            p.reason = "check_mismatch"
