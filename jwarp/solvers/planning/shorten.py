"""Shortening of certified paths (:attr:`PlanOptions.shorten`): shortcuts between the
corners of a feasible path, each straight shortcut proven by the exact continuous check,
then the path's waypoints respaced along the shortened polyline in proportion to its
segments' lengths (which lowers the length cost U_l, eq. 3.5, without moving the path).

The planner calls :func:`shortcut_paths` with its own check
(:meth:`jwarp.solvers.planning.Planner.motion_check`) and re-checks every shortened path
as a whole with its own rule (margins, endpoint margin) before keeping it."""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from jwarp.solvers.planning.objective import NORM_FLOOR

__all__ = ["MAX_LIST", "MIN_ROUND_GAIN", "Pace", "corners", "length_cost", "respace",
           "shortcut_paths"]

#: most shortcuts in a path's list of one check call (:func:`shortcut_paths`): the
#: candidates from the current point and, while they fit, from the points after it
MAX_LIST = 48

#: a round that shortens no path by more than this share of its length ends the rounds
MIN_ROUND_GAIN = 1e-3


def length_cost(paths: np.ndarray) -> np.ndarray:
    """U_l (thesis eq. 3.5, as the kernels and :attr:`PlanResult.length_cost`) of paths
    (..., W, n_dof): ``(W - 1) sum_t |q_{t+1} - q_t|^2 / |q_W - q_1|^2`` (its normaliser
    floored as the kernels do), 1 for the straight line at evenly spaced waypoints."""
    p = np.asarray(paths, np.float64)
    d2 = np.maximum(np.sum((p[..., -1, :] - p[..., 0, :]) ** 2, axis=-1), 2.0 * NORM_FLOOR)
    seg = np.sum(np.diff(p, axis=-2) ** 2, axis=(-2, -1))
    return (p.shape[-2] - 1) * seg / d2


def corners(path: np.ndarray, tol: float = 1e-9) -> np.ndarray:
    """The nodes (k, n_dof) of a polyline (W, n_dof) where it turns: repeated waypoints and
    waypoints on the straight line between their neighbours dropped (the polyline is the
    same); the first and last are kept (:func:`corners_many` of one path)."""
    return corners_many(np.asarray(path, np.float64)[None], tol)[0]


def corners_many(paths: np.ndarray, tol: float = 1e-9) -> list[np.ndarray]:
    """:func:`corners` of every path of ``paths`` (K, W, n_dof) at once (one pass over the
    waypoints for all paths): per path its nodes (k_i, n_dof)."""
    p = np.asarray(paths, np.float64)
    K, W = p.shape[:2]
    keep = np.zeros((K, W), bool)
    keep[:, 0] = keep[:, -1] = True
    last = np.zeros(K, np.int64)              # each path's last kept waypoint
    r = np.arange(K)
    for t in range(1, W - 1):
        a, b, c = p[r, last], p[:, t], p[:, t + 1]
        ab = np.linalg.norm(b - a, axis=1)
        bc = np.linalg.norm(c - b, axis=1)
        turn = (ab > tol) & (ab + bc - np.linalg.norm(c - a, axis=1)
                             > tol * np.maximum(1.0, ab + bc))
        keep[turn, t] = True
        last[turn] = t
    return [p[k][keep[k]] for k in range(K)]


def corners_ragged(polylines: list[np.ndarray], tol: float = 1e-9) -> list[np.ndarray]:
    """:func:`corners` of polylines (k_i, n_dof) of different lengths at once: each padded
    to the longest with its last point repeated (a repeated point is no corner, so the
    padding adds none), then :func:`corners_many`."""
    if not polylines:
        return []
    L = max(len(x) for x in polylines)
    n = polylines[0].shape[-1]
    pad = np.empty((len(polylines), L, n))
    for k, x in enumerate(polylines):
        pad[k, :len(x)] = x
        pad[k, len(x):] = x[-1]
    return corners_many(pad, tol)


def respace(nodes: np.ndarray, n_waypoints: int) -> np.ndarray:
    """``n_waypoints`` waypoints on the polyline ``nodes`` (k <= n_waypoints): every node a
    waypoint, the others spread over the segments in proportion to their lengths (the same
    polyline, so nothing between the waypoints moves)."""
    from jwarp.solvers.planning.rrt import resample_path

    return resample_path(nodes, n_waypoints)


#: :meth:`Pace.chunks`: the first call's share of a chunk, before any call has been timed
FIRST_CHUNK_SHARE = 0.125


class Pace:
    """The seconds per checked row of the calls timed so far (:meth:`run`): whether a call
    of ``n`` rows still ends before a deadline (:meth:`fits`), so that the calls of a
    stage in chunks stop before the chunk that would overrun it, not after."""

    def __init__(self) -> None:
        self.seconds = 0.0
        self.rows = 0
        self.stopped = False  # a call did not fit: the stage ends

    def fits(self, n: int, deadline: float | None) -> bool:
        """True without a deadline; False once it has passed; else whether ``n`` rows at
        the pace so far end before it (True before any call: nothing to go by)."""
        if deadline is None:
            return True
        now = time.perf_counter()
        if now >= deadline:
            return False
        return self.rows == 0 or now + self.seconds * n / self.rows <= deadline

    def chunks(self, n: int, size: int, deadline: float | None) -> list[tuple[int, int]]:
        """The (start, end) of calls over ``n`` items in chunks of ``size``; with a
        ``deadline``, before any call has been timed, the first is
        :data:`FIRST_CHUNK_SHARE` of ``size`` (it sets the pace: one call of a full chunk
        may itself overrun the deadline)."""
        size = max(1, int(size))
        step = size if self.rows or deadline is None else max(1, int(size * FIRST_CHUNK_SHARE))
        out, at = [], 0
        while at < n:
            out.append((at, min(n, at + step)))
            at, step = at + step, size
        return out

    def run(self, f: Callable[[np.ndarray], np.ndarray], rows: np.ndarray) -> np.ndarray:
        """``f(rows)``, timed."""
        t = time.perf_counter()
        out = f(rows)
        self.seconds += time.perf_counter() - t
        self.rows += len(rows)
        return out


def shortcut_paths(paths: np.ndarray, check: Callable[..., np.ndarray],
                   rounds: int, deadline: float | None = None,
                   active: np.ndarray | None = None, max_points: int = 21,
                   max_list: int | None = None, min_gain: float | None = None,
                   budget: Callable[[], bool] | None = None,
                   near_straight: float | None = None,
                   chunk: int | None = None) -> list[np.ndarray]:
    """Shortcuts of feasible paths (K, W, n_dof), all at once (greedy string pulling).

    Each round takes every path's corners (:func:`corners`) and, where that makes at most
    ``max_points`` points, the midpoints of the segments between them. From the start,
    the path jumps along the straight segment to the farthest later point proven
    reachable, and from there on, to the goal; from a point without any proven shortcut
    it follows the path to the next point. One call of ``check(segments (E, 2, n_dof),
    per_path)`` finds every path's next jump: per path a list of ``per_path`` segments
    in the order of preference (from the current point the shortcuts that save length,
    the farthest first, then those from the next point, and so on while the list holds
    at most ``max_list`` (None: :data:`MAX_LIST`); padded with zero-length segments at the path's start, whose
    answers are ignored); it returns (E,) bool: proven feasible. The first proven entry
    of a path's list is its jump (the path followed up to that entry's start), so
    ``check`` may skip the rest of a list once one entry is proven
    (:meth:`jwarp.world.motion.MotionCheck.check` with ``group=per_path`` does: on the
    CPU the entries are checked in order and the work stops at the first proven, so the
    walk over points without a shortcut costs no call of its own). A path's new corners
    replace the old where they still fit its W waypoints and are shorter.

    Ends after ``rounds`` rounds, when no path's round shortened it by more than
    ``min_gain`` (relative; None: :data:`MIN_ROUND_GAIN`), or at ``deadline`` (``time.perf_counter()``; checked
    before every call: a round cut short keeps its jumps so far and the path after
    them). ``chunk`` (paths): with a ``deadline``, each step's check is made in calls of
    the lists of at most ``chunk`` paths, ``check(segments, per_path, rows)`` with ``rows``
    (E_c,) the rows of ``segments`` to check (those paths' lists, no padding; the others
    are not read) returning (E_c,) bool, and the deadline is asked before every call: a
    call that would end after it at the pace of the calls so far (:class:`Pace`) is not
    made, so a step overruns the deadline by at most one chunk's call; the paths whose
    lists were not checked keep the rest of the path as it is (every jump taken was
    proven by a call that completed). None (or no ``deadline``): the two-argument call
    over every path at once. ``budget``: a function, True once the budget is spent (e.g. the evaluations
    of the checks so far against a share of the planner's: deterministic), asked before
    every call but the first (the first jumps of every path are always tried); a round
    cut short by it ends as by ``deadline``.
    ``active`` (K,) bool: the paths to shorten (None: all); the others are
    returned as their corners. ``near_straight``: a path whose length after a round is at
    most this multiple of the straight line's (its start to its goal) takes no further
    round (None: no such end): the rounds after it would gain little for their checks.

    Returns:
        per path its corners (k_i, n_dof) after the shortcuts (the start and goal kept).
    """
    max_list = MAX_LIST if max_list is None else int(max_list)
    min_gain = MIN_ROUND_GAIN if min_gain is None else float(min_gain)
    paths = np.asarray(paths, np.float64)
    K, W, n = paths.shape
    nodes = corners_many(paths)
    straight = np.linalg.norm(paths[:, -1] - paths[:, 0], axis=1)
    if near_straight is not None:
        near_straight = float(near_straight)
        if not np.isfinite(near_straight) or near_straight < 1.0:
            raise ValueError(f"near_straight: expected a length ratio >= 1, got {near_straight!r}")
    active = (np.ones(K, bool) if active is None else np.array(active, bool).reshape(K))
    calls = 0
    pace = Pace()
    step = 0.0  # seconds of the last step's host work (lists, jumps): the next must fit too
    for _ in range(int(rounds)):
        if not active.any() or _late(deadline, step) or pace.stopped or _spent(calls, budget):
            break
        # per active path its points, their cumulative lengths and the gain of every
        # shortcut (s, j) of them (once per round: the steps' lists, _entries, read it),
        # path by path with the deadline asked every SETUP_CHUNK paths: a path not
        # reached takes no part in this round (kept as it is)
        t_setup = time.perf_counter()
        pts, cums, gains = _round_setup(nodes, active, max_points, deadline)
        if step == 0.0:  # the first step's host work (its lists) is of the set-up's order
            step = time.perf_counter() - t_setup
        at = np.zeros(K, np.int64)              # the current point of each path
        kept: list[list[int]] = [[0] for _ in range(K)]
        going = active & np.array([len(p) >= 3 for p in pts])
        while going.any():
            t_step, paced = time.perf_counter(), pace.seconds
            if _late(deadline, step) or pace.stopped or _spent(calls, budget):
                for k in map(int, np.nonzero(going)[0]):  # the rest of the path as it is
                    kept[k].extend(range(int(at[k]) + 1, len(pts[k])))
                break
            lists = [_entries(pts[k], cums[k], int(at[k]), max_list, gains[k]) if going[k]
                     else np.zeros((0, 2), np.int64) for k in range(K)]
            per = max(len(e) for e in lists)
            ok = np.zeros((K, per), bool)
            late = np.zeros(K, bool)  # lists not checked: out of time
            if per:
                segs = np.empty((K, per, 2, n))
                for k in range(K):
                    segs[k] = pts[k][0]  # padding: zero-length segments at the start
                    e = lists[k]
                    if len(e):
                        segs[k, :len(e), 0] = pts[k][e[:, 0]]
                        segs[k, :len(e), 1] = pts[k][e[:, 1]]
                if chunk is None or deadline is None:
                    ok = np.asarray(check(segs.reshape(-1, 2, n), per), bool).reshape(K, per)
                else:
                    late = _check_chunks(check, segs.reshape(-1, 2, n), per, lists, ok,
                                         int(chunk), deadline, pace)
                calls += 1
            for k in map(int, np.nonzero(going & late)[0]):  # the rest as it is
                kept[k].extend(range(int(at[k]) + 1, len(pts[k])))
                going[k] = False
            for k in map(int, np.nonzero(going)[0]):
                e = lists[k]
                hit = np.nonzero(ok[k, :len(e)])[0]
                if len(hit):  # follow the path to the entry's start, then jump
                    s, j = map(int, e[hit[0]])
                elif len(e):  # none proven: follow the path past the last start listed
                    s = j = int(e[-1, 0]) + 1
                else:  # no shortcut saves length from here on: follow it to the goal
                    s = j = len(pts[k]) - 1
                kept[k].extend(range(int(at[k]) + 1, s + 1))
                if j != s:
                    kept[k].append(j)
                at[k] = j
                if at[k] >= len(pts[k]) - 1:
                    going[k] = False
            # the step's host work (its checks are paced by Pace)
            step = time.perf_counter() - t_step - (pace.seconds - paced)
        act = list(map(int, np.nonzero(active)[0]))
        news = corners_ragged([pts[k][kept[k]] for k in act])
        for k, new in zip(act, news):
            old_len = np.linalg.norm(np.diff(nodes[k], axis=0), axis=1).sum()
            new_len = np.linalg.norm(np.diff(new, axis=0), axis=1).sum()
            if len(new) <= W and new_len < old_len * (1.0 - 1e-6):
                nodes[k] = new
            if not (len(new) <= W and new_len < old_len * (1.0 - min_gain)):
                active[k] = False  # this round gained (almost) nothing: the next would not
            elif near_straight is not None and min(new_len, old_len) <= near_straight * straight[k]:
                active[k] = False  # near the straight line: the next would gain little
    return nodes


def _check_chunks(check: Callable[..., np.ndarray], segs: np.ndarray, per: int,
                  lists: list[np.ndarray], ok: np.ndarray, chunk: int, deadline: float,
                  pace: Pace) -> np.ndarray:
    """The lists (``lists[k]`` of path k, rows ``k per ..``) checked in calls of at most
    ``chunk`` paths' lists until a call would end after ``deadline`` (:meth:`Pace.fits`);
    ``ok`` (K, per) filled. Returns (K,) bool: the paths with a list left unchecked."""
    K = len(lists)
    todo = np.array([k for k in range(K) if len(lists[k])], np.int64)
    late = np.zeros(K, bool)
    flat = ok.reshape(-1)
    for c, e in pace.chunks(len(todo), chunk, deadline):
        part = todo[c:e]
        rows = np.concatenate([k * per + np.arange(len(lists[k])) for k in part])
        if not pace.fits(len(rows), deadline):
            late[todo[c:]] = True
            pace.stopped = True
            break
        flat[rows] = np.asarray(pace.run(lambda r: check(segs, per, r), rows),
                                bool).reshape(len(rows))
    return late


#: :func:`shortcut_paths`: the paths whose round set-up (points, lengths, gains: host work
#: of about 0.1-0.7 ms a path) is made between two looks at the deadline; before, a
#: 700-path GPU batch's round set-up alone overran its deadline by 0.1-0.5 s
SETUP_CHUNK = 32


def _round_setup(nodes: list, active: np.ndarray, max_points: int, deadline: float | None
                 ) -> tuple[list, list, list]:
    """(points, cumulative lengths, gains) per path for a round of :func:`shortcut_paths`;
    the inactive paths' are their corners, an empty array and None; with a ``deadline``,
    the paths not reached before it are made inactive in ``active`` (in place)."""
    none = np.zeros(0)  # an inactive path's cumulative lengths (not read)
    pts, cums = list(nodes), [none] * len(nodes)
    gains: list = [None] * len(nodes)
    for i, k in enumerate(map(int, np.nonzero(active)[0])):
        if i % SETUP_CHUNK == 0 and _late(deadline):
            active[k:] = False
            break
        nd = nodes[k]
        p = _refined(nd) if 2 * len(nd) - 1 <= max_points else nd
        c = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])
        pts[k], cums[k], gains[k] = p, c, _gains(p, c)
    return pts, cums, gains


def _late(deadline: float | None, step: float = 0.0) -> bool:
    """Whether a step of ``step`` seconds started now would end after ``deadline``."""
    return deadline is not None and time.perf_counter() + step >= deadline


def _spent(calls: int, budget: Callable[[], bool] | None) -> bool:
    return calls > 0 and budget is not None and bool(budget())


def _gains(p: np.ndarray, cum: np.ndarray) -> np.ndarray:
    """(m, m) the length a shortcut from point s to point j of the points ``p`` (m, n)
    saves over the path between them (cumulative lengths ``cum``): ``cum[j] - cum[s] -
    |p[j] - p[s]|``."""
    d = np.linalg.norm(p[None, :, :] - p[:, None, :], axis=-1)
    return cum[None, :] - cum[:, None] - d


def _entries(p: np.ndarray, cum: np.ndarray, a: int, max_list: int,
             gains: np.ndarray | None = None) -> np.ndarray:
    """The shortcuts (m, 2) (start, end point) tried from point ``a`` of the points ``p``
    (cumulative lengths ``cum``): from ``a`` those to later points that save length, the
    farthest first, then from ``a + 1``, ... (each start's whole list) while the list
    holds at most ``max_list`` (the first start's always). ``gains``: :func:`_gains` of
    the points (None: computed here)."""
    out: list[np.ndarray] = []
    size = 0
    tol = 1e-6 * max(1.0, float(cum[-1]))
    g = _gains(p, cum) if gains is None else gains
    for s in range(a, len(p) - 2):
        j = np.arange(s + 2, len(p))
        j = j[g[s, s + 2:] > tol][::-1]
        if size and size + len(j) > max_list:
            break
        out.append(np.stack([np.full(len(j), s), j], axis=1))
        size += len(j)
    return np.concatenate(out) if out else np.zeros((0, 2), np.int64)


def _refined(nodes: np.ndarray) -> np.ndarray:
    """The corners (k, n) with the midpoint of every segment between them (2k - 1, n):
    the ends of the shortcuts tried (a shortcut may start halfway along a segment)."""
    out = np.empty((2 * len(nodes) - 1, nodes.shape[1]))
    out[0::2] = nodes
    out[1::2] = 0.5 * (nodes[:-1] + nodes[1:])
    return out
