"""Ordering measurement poses by a travelling-salesman heuristic in joint space (thesis
2.4.3; elastic paper IV-C: ordering halved the collection time).

The poses form an open path (the robot starts at the first and stops at the last; no
return). The path is found by LKH (Lin-Kernighan-Helsgaun, through ``elkai``) on the
distance matrix with one extra dummy node at distance 0 from every pose (optionally only
from a given start pose), which turns the open path into a tour; the tour is cut at the
dummy. LKH works on integer weights: distances are scaled to integers up to
:data:`SCALE`. The result is never longer than the input order (that order is kept if LKH
does not beat it).

Metrics: ``euclidean`` ``|q_a - q_b|`` [rad] and ``max`` ``max_j |q_a,j - q_b,j|`` (the
travel of the joint that moves most: the time of a synchronized move at equal joint
speeds).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from jwarp.utils.checks import check_int

__all__ = ["SCALE", "Ordering", "distance_matrix", "path_length", "order_poses"]

#: the largest distance as an integer weight handed to LKH
SCALE = 1_000_000
METRICS = ("euclidean", "max")


def distance_matrix(q: np.ndarray, metric: str = "euclidean") -> np.ndarray:
    """(n, n) joint-space distances of configurations q (n, n_dof) [rad or m]."""
    if metric not in METRICS:
        raise ValueError(f"metric: expected one of {', '.join(METRICS)}, got {metric!r}")
    q = np.asarray(q, np.float64)
    d = np.abs(q[:, None, :] - q[None, :, :])
    return np.sqrt((d * d).sum(-1)) if metric == "euclidean" else d.max(-1, initial=0.0)


def path_length(q: np.ndarray, order: np.ndarray | None = None, metric: str = "euclidean"
                ) -> float:
    """Sum of the joint-space distances along q[order] (open path) [rad or m]."""
    q = np.asarray(q, np.float64)
    if order is not None:
        q = q[np.asarray(order)]
    if len(q) < 2:
        return 0.0
    d = np.abs(np.diff(q, axis=0))
    if metric not in METRICS:
        raise ValueError(f"metric: expected one of {', '.join(METRICS)}, got {metric!r}")
    step = np.sqrt((d * d).sum(-1)) if metric == "euclidean" else d.max(-1)
    return float(step.sum())


@dataclass
class Ordering:
    """An execution order of poses: ``order`` (n,) indices into the input; path lengths
    of the input order (``before``) and of ``order`` (``after``) per metric
    {"euclidean": rad, "max": rad}; ``solver`` "lkh", "input" (kept: LKH was not shorter)
    or "trivial" (n <= 2)."""

    order: np.ndarray
    before: dict[str, float]
    after: dict[str, float]
    solver: str

    def summary(self) -> str:
        """One line per metric: before -> after (ratio)."""
        out = []
        for m in METRICS:
            b, a = self.before[m], self.after[m]
            out.append(f"path length ({m}): {b:.3f} -> {a:.3f} rad "
                       f"({a / b if b > 0 else 1.0:.2f}x)")
        return "\n".join(out)


def order_poses(q: np.ndarray, *, metric: str = "euclidean", start: int | None = None,
                runs: int = 1) -> Ordering:
    """The shortest open path through the poses q (n, n_dof) that LKH finds.

    Args:
        metric: distance minimized (``euclidean`` or ``max``).
        start: index of the pose to start from (None: free).
        runs: LKH runs (more: closer to optimal, slower); LKH's own seed is fixed, so
            the result is reproducible.

    Raises:
        ValueError: q not (n, n_dof) finite, a bad metric, start or runs.
    """
    q = np.asarray(q, np.float64)
    if q.ndim != 2 or not np.all(np.isfinite(q)):
        raise ValueError(f"q: expected a finite (n, n_dof) array, got shape {q.shape}")
    if metric not in METRICS:
        raise ValueError(f"metric: expected one of {', '.join(METRICS)}, got {metric!r}")
    n = len(q)
    if start is not None and not (0 <= int(start) < max(n, 1)):
        raise ValueError(f"start: expected an index in [0, {n}), got {start}")
    check_int(runs, "runs", 1)
    ident = np.arange(n)
    lengths = {m: path_length(q, None, m) for m in METRICS}
    if n <= 2:
        order = ident if start is None or start == 0 else ident[::-1]
        return Ordering(order, lengths, {m: path_length(q, order, m) for m in METRICS},
                        "trivial")
    order = _lkh_path(distance_matrix(q, metric), start, runs)
    after = {m: path_length(q, order, m) for m in METRICS}
    solver = "lkh"
    keep_input = start is None or start == 0
    if after[metric] > lengths[metric] and keep_input:
        order, after, solver = ident, dict(lengths), "input"
    return Ordering(order, lengths, after, solver)


def _lkh_path(D: np.ndarray, start: int | None, runs: int) -> np.ndarray:
    """Open path through D (n, n) by LKH on the tour with a dummy node."""
    import elkai

    n = len(D)
    big = float(D.max()) if D.size else 0.0
    scale = SCALE / big if big > 0 else 1.0
    W = np.zeros((n + 1, n + 1), np.int64)
    W[:n, :n] = np.rint(D * scale).astype(np.int64)
    if start is not None:   # the dummy reaches only the start for free
        far = int(n * SCALE + 1)
        W[n, :n] = far
        W[:n, n] = far
        W[n, start] = W[start, n] = 0
    tour = elkai.DistanceMatrix(W.tolist()).solve_tsp(runs=runs)[:-1]
    k = tour.index(n)
    path = tour[k + 1:] + tour[:k]
    if start is not None and path[0] != start:
        path = path[::-1]
    return np.asarray(path, np.int64)
