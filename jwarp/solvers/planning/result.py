"""What a motion plan returns: :class:`PlanResult`."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import warp as wp


class _Filled:
    """A field of :class:`PlanResult` that the planner may leave to be filled on its
    first read (``PlanResult._fill``: the costs of the straight stage, evaluated only when
    asked for): set on the class after the dataclass is made, so the generated
    ``__init__`` stores through it (``default``: what the class itself reads)."""

    _NONE = object()

    def __init__(self, default: Any = _NONE) -> None:
        self.default = default

    def __set_name__(self, owner: type, name: str) -> None:
        self.slot = "_" + name

    def __get__(self, obj: Any, owner: Any = None) -> Any:
        if obj is None:  # the dataclass asks for the default
            if self.default is _Filled._NONE:
                raise AttributeError(self.slot)
            return self.default
        d = obj.__dict__
        if d.get(self.slot, None) is None and d.get("_fill") is not None:
            fill, d["_fill"] = d["_fill"], None
            fill(obj)
        return d.get(self.slot)

    def __set__(self, obj: Any, value: Any) -> None:
        obj.__dict__[self.slot] = value


@dataclass
class PlanResult:
    """Result of :func:`plan` / :meth:`Planner.plan` for B problems.

    path (B, W, n_dof) the chosen path per problem (shortened by
    :attr:`PlanOptions.shorten` where that was shorter and certified: then it differs from
    ``all_paths[b, start_index[b]]``, see ``length_before``); feasible (B,) bool; cost (B,) U_path;
    length_cost (B,) U_l (eq. 3.5, 1 for the straight line); collision_cost (B,) weighted
    world + self cost summed over substeps; iterations (B,) gradient steps until the chosen
    path was feasible (or the iteration budget); start_index (B,) which multi-start (seed)
    won; n_feasible (B,) feasible multi-starts; wall_time [s] of the whole call;
    n_substeps substeps per segment; all_feasible (B, n_starts); all_iterations
    (B, n_starts); all_paths (B, n_starts, W, n_dof) final paths of every start, read from
    the device on first use (the best paths are chosen on the device, so a caller that
    needs only ``path`` never copies the others to the host).

    Budgets and fallback (:attr:`PlanOptions.time_limit`, ``stop_when_solved``,
    ``fallback``): ``stop_reason`` why the call ended, one of :data:`STOP_REASONS`:
    "solved" (every problem has a feasible path: ``stop_when_solved``, or the fallback
    solved the rest), "all_done" (every start finished on its own: feasible with
    ``freeze_feasible``, converged with ``converge``), "time_limit" (the time ran out first)
    or "iterations" (the iterations, and the fallback's samples, ran out first);
    ``stage`` (B,) which stage gave the path: "straight" (the straight line of the W
    waypoints, proven before any other start was drawn: :attr:`PlanOptions.straight_first`;
    ``iterations`` 0, ``start_index`` 0 and, where every problem was solved so, the
    line is the one start: ``all_*`` (B, 1); its ``cost``, ``length_cost``,
    ``collision_cost`` and ``length_before`` are evaluated when first read, at
    ``n_substeps`` sized to the line), "optimizer" (the multi-starts),
    "fallback" (the gradient optimisation seeded with the RRT-Connect path,
    :mod:`jwarp.solvers.planning.rrt`) or "none" (no feasible path). A fallback path is none of
    the multi-starts: its ``start_index`` is -1, its ``iterations`` those of the seeded
    optimisation (0: the RRT path itself, certified as it is); ``n_feasible``, ``all_*``
    stay the multi-starts'. ``solved_at`` (B,) float: seconds from the call's start at
    which the stage of ``stage`` had the problem's feasible path (its straight line
    proven; its start kept feasible by the multi-starts' exact check; its fallback path
    certified), NaN where the problem has none; the shortening of a solved path comes
    later (see ``timings["shorten"]``), so ``solved_at`` <= ``wall_time``, and a problem
    of a batch is solved at its own time, not at the end of the batch.
    ``fallback_notes``: what the fallback did. ``timings`` [s]:
    "optimizer" (the multi-starts) and, where it ran, "via_ik" (the IK via points of
    :attr:`PlanOptions.via_ik`, inside "optimizer"), "rrt", "fallback_certify" (the
    RRT paths that kept every node checked as they are, in one call), "fallback_optimizer"
    (the others optimised) and "shorten"; for a robot with collision pieces "mesh_check" (the mesh certificate's
    share, :mod:`jwarp.world.mesh_check`). ``length_before``: the length cost before the shortening
    (:attr:`PlanOptions.shorten`).
    """

    path: np.ndarray
    feasible: np.ndarray
    cost: np.ndarray
    length_cost: np.ndarray
    collision_cost: np.ndarray
    iterations: np.ndarray
    start_index: np.ndarray
    n_feasible: np.ndarray
    wall_time: float
    n_substeps: int
    all_feasible: np.ndarray = field(repr=False)
    all_iterations: np.ndarray = field(repr=False)
    #: every start's final path: a numpy (B, n_starts, W, n_dof) array, or a Warp array
    #: (B * n_starts, W, n_dof) on the planner's device (its own copy) until first read
    paths_source: Any = field(default=None, repr=False)
    #: why the call ended (:data:`STOP_REASONS`)
    stop_reason: str = "iterations"
    #: (B,) "straight", "optimizer", "fallback" or "none" (None: filled by the planner)
    stage: Any = None
    #: (B,) float: seconds from the call's start at which each problem's feasible path
    #: was found by its ``stage`` (NaN: none; None: not recorded)
    solved_at: Any = None
    #: seconds per stage: "endpoints", "straight", "starts" (the multi-starts checked as
    #: drawn before the optimiser: where each problem has one proven, no optimiser runs),
    #: "via_ik", "optimizer", "rrt", "fallback_certify",
    #: "fallback_optimizer" (and "handed_over": the problems :attr:`PlanOptions.stall_iterations` handed to the
    #: fallback before the multi-starts' end, a count)
    timings: dict = field(default_factory=dict, repr=False)
    #: (B,) "feasible" or why the problem's path is not (:meth:`Planner.explain`)
    reasons: Any = None
    #: (B,) str: what the RRT fallback did for each problem ("" where it did not run):
    #: no tree connection (and why), or its path certified / not certified (and why);
    #: appended to ``reasons`` of a problem without a plan
    fallback_notes: Any = None
    #: (B,) float: U_l of each problem's feasible path before :attr:`PlanOptions.shorten`
    #: shortened it (equal to ``length_cost`` where nothing was shorter; NaN where the
    #: problem has no feasible path or nothing was tried); None: shortening off
    length_before: Any = None
    #: fills the fields left to their first read (``_fill(result)``; None: nothing left)
    _fill: Any = field(default=None, init=False, repr=False, compare=False)

    @property
    def all_paths(self) -> np.ndarray:
        """(B, n_starts, W, n_dof) float64: the final path of every start."""
        src = self.paths_source
        if isinstance(src, wp.array):
            B, n_starts = self.all_feasible.shape
            src = src.numpy().astype(np.float64).reshape((B, n_starts) + self.path.shape[1:])
            self.paths_source = src
        return src

    def to_dict(self, index: int = 0) -> dict:
        """JSON-ready summary of problem ``index``."""
        return {"path": self.path[index].tolist(), "feasible": bool(self.feasible[index]),
                "costs": {"total": float(self.cost[index]),
                          "length": float(self.length_cost[index]),
                          "collision": float(self.collision_cost[index])},
                "iterations": int(self.iterations[index]),
                "start_index": int(self.start_index[index]),
                "n_feasible_starts": int(self.n_feasible[index]),
                "n_substeps": int(self.n_substeps),
                "wall_time_s": float(self.wall_time),
                "stop_reason": str(self.stop_reason),
                "reason": (str(self.reasons[index]) if self.reasons is not None
                           else None),
                "stage": None if self.stage is None else str(self.stage[index]),
                "solved_at_s": (None if self.solved_at is None
                                or not np.isfinite(self.solved_at[index])
                                else float(self.solved_at[index])),
                "length_before_shortening": (
                    None if self.length_before is None
                    or not np.isfinite(self.length_before[index])
                    else float(self.length_before[index]))}


# the fields the straight stage leaves to their first read (PlanResult._fill)
for _name, _default in (("cost", _Filled._NONE), ("length_cost", _Filled._NONE),
                        ("collision_cost", _Filled._NONE), ("length_before", None)):
    _field = _Filled(_default)
    _field.__set_name__(PlanResult, _name)
    setattr(PlanResult, _name, _field)
