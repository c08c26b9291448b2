"""Shortening of certified paths (:attr:`PlanOptions.shorten`): shortcuts between the
corners of a feasible path, each straight shortcut proven by the exact continuous check,
then the path's waypoints respaced along the shortened polyline in proportion to its
segments' lengths (which lowers the length cost U_l, eq. 3.5, without moving the path).

The planner calls :func:`shortcut_paths` with its own check
(:meth:`jwarp.solvers.planning.Planner.motion_check`) and re-checks every shortened path
as a whole with its own rule (margins, endpoint margin) before keeping it."""

from __future__ import annotations

import time
from typing import Callable

import numpy as np

from jwarp.solvers.planning.objective import NORM_FLOOR

__all__ = ["corners", "length_cost", "respace", "shortcut_paths"]


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
    same); the first and last are kept."""
    p = np.asarray(path, np.float64)
    keep = [0]
    for t in range(1, len(p) - 1):
        a, b, c = p[keep[-1]], p[t], p[t + 1]
        ab, bc = np.linalg.norm(b - a), np.linalg.norm(c - b)
        if ab <= tol:
            continue  # a repeat of the last kept node
        if ab + bc - np.linalg.norm(c - a) > tol * max(1.0, ab + bc):
            keep.append(t)
    keep.append(len(p) - 1)
    return p[keep]


def respace(nodes: np.ndarray, n_waypoints: int) -> np.ndarray:
    """``n_waypoints`` waypoints on the polyline ``nodes`` (k <= n_waypoints): every node a
    waypoint, the others spread over the segments in proportion to their lengths (the same
    polyline, so nothing between the waypoints moves)."""
    from jwarp.solvers.planning.rrt import resample_path

    return resample_path(nodes, n_waypoints)


def shortcut_paths(paths: np.ndarray, check: Callable[[np.ndarray, int], np.ndarray],
                   rounds: int, deadline: float | None = None,
                   active: np.ndarray | None = None, max_points: int = 21
                   ) -> list[np.ndarray]:
    """Shortcuts of feasible paths (K, W, n_dof), all at once (greedy string pulling).

    Each round takes every path's corners (:func:`corners`) and, where that makes at most
    ``max_points`` points, the midpoints of the segments between them. From the start,
    the straight segments to every later point that save length are checked at once and
    the path jumps to the farthest proven one (the next point where none is), until the
    goal. The segments of all paths go to ``check(segments (E, 2, n_dof), per_path)`` in
    one call per jump (``per_path``: segments per path, the paths' lists padded to it
    with zero-length segments at their start, whose answers are ignored), which returns
    (E,) bool: proven feasible. A path's new corners replace the old where they still fit
    its W waypoints and are shorter. Ends after ``rounds`` rounds, when no path gained, or
    at ``deadline`` (``time.perf_counter()``). ``active`` (K,) bool: the paths to shorten
    (None: all); the others are returned as their corners.

    Returns:
        per path its corners (k_i, n_dof) after the shortcuts (the start and goal kept).
    """
    paths = np.asarray(paths, np.float64)
    K, W, n = paths.shape
    nodes = [corners(p) for p in paths]
    active = (np.ones(K, bool) if active is None else np.array(active, bool).reshape(K))
    for _ in range(int(rounds)):
        if not active.any() or (deadline is not None and time.perf_counter() >= deadline):
            break
        pts = [_refined(nd) if 2 * len(nd) - 1 <= max_points else nd for nd in nodes]
        cums = [np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])
                for p in pts]
        at = np.zeros(K, np.int64)              # the current point of each path
        kept: list[list[int]] = [[0] for _ in range(K)]
        going = active & np.array([len(p) >= 3 for p in pts])
        while going.any():
            cand: list[np.ndarray] = []
            for k in range(K):
                if not going[k]:
                    cand.append(np.zeros(0, np.int64))
                    continue
                p, c, a = pts[k], cums[k], at[k]
                j = np.arange(a + 2, len(p))
                gain = c[j] - c[a] - np.linalg.norm(p[j] - p[a], axis=1)
                cand.append(j[gain > 1e-6 * max(1.0, c[-1])])
            per = max(len(c) for c in cand)
            ok = np.zeros((K, 0), bool)
            if per:
                segs = np.empty((K, per, 2, n))
                for k in range(K):
                    segs[k] = pts[k][0]  # padding: zero-length segments at the start
                    if len(cand[k]):
                        segs[k, :len(cand[k]), 0] = pts[k][at[k]]
                        segs[k, :len(cand[k]), 1] = pts[k][cand[k]]
                ok = np.asarray(check(segs.reshape(-1, 2, n), per), bool).reshape(K, per)
            for k in map(int, np.nonzero(going)[0]):
                good = cand[k][ok[k, :len(cand[k])]] if per else cand[k][:0]
                at[k] = good.max() if len(good) else at[k] + 1
                kept[k].append(int(at[k]))
                if at[k] >= len(pts[k]) - 1:
                    going[k] = False
        for k in map(int, np.nonzero(active)[0]):
            new = corners(pts[k][kept[k]])
            old_len = np.linalg.norm(np.diff(nodes[k], axis=0), axis=1).sum()
            new_len = np.linalg.norm(np.diff(new, axis=0), axis=1).sum()
            if len(new) <= W and new_len < old_len * (1.0 - 1e-6):
                nodes[k] = new
            else:
                active[k] = False
    return nodes


def _refined(nodes: np.ndarray) -> np.ndarray:
    """The corners (k, n) with the midpoint of every segment between them (2k - 1, n):
    the ends of the shortcuts tried (a shortcut may start halfway along a segment)."""
    out = np.empty((2 * len(nodes) - 1, nodes.shape[1]))
    out[0::2] = nodes
    out[1::2] = 0.5 * (nodes[:-1] + nodes[1:])
    return out
