"""What an inverse-kinematics solve returns: :class:`IKResult`."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from jwarp.kernels import ik_step as step_kernels


@dataclass
class IKResult:
    """Result of :func:`ik` for T targets (leading dims of ``target``).

    q (T, n_dof) chosen solution; feasible (T,) bool; pos_err (T,) [m]; rot_err (T,) [rad];
    cost (T,) U_A at the solution; iterations (T,) iterations the chosen start needed
    (projection + nullspace, re-seeds included; an infeasible start: ``iterations``, or
    its own count if it gave up); start_index (T,); n_feasible (T,) feasible starts;
    wall_time [s]; all_q (T, n_starts, n_dof); all_feasible (T, n_starts).
    """

    q: np.ndarray
    feasible: np.ndarray
    pos_err: np.ndarray
    rot_err: np.ndarray
    cost: np.ndarray
    iterations: np.ndarray
    start_index: np.ndarray
    n_feasible: np.ndarray
    wall_time: float
    all_q: np.ndarray = field(repr=False)
    all_feasible: np.ndarray = field(repr=False)
    all_iterations: np.ndarray = field(repr=False)

    def to_dict(self, index: int = 0) -> dict:
        """JSON-ready summary of target ``index`` (flat index over the target dims)."""
        def pick(a: np.ndarray, tail: int = 0) -> np.ndarray:
            a = np.asarray(a)
            return a.reshape((-1,) + a.shape[a.ndim - tail:])[index]

        return {"q": pick(self.q, 1).tolist(), "feasible": bool(pick(self.feasible)),
                "pos_err_m": float(pick(self.pos_err)), "rot_err_rad": float(pick(self.rot_err)),
                "costs": {"aux": float(pick(self.cost))},
                "iterations": int(pick(self.iterations)),
                "start_index": int(pick(self.start_index)),
                "n_feasible_starts": int(pick(self.n_feasible)),
                "wall_time_s": float(self.wall_time)}

    @classmethod
    def from_rows(cls, out: np.ndarray, best: np.ndarray, n_dof: int, P: int, S: int,
                  wall: float) -> IKResult:
        """The result of P problems x S seeds from the solver's result rows ``out``
        (P * S, n_dof + 5) ``[q, |e_v|, |e_w|, U_A, feasible, iterations]`` and its choice
        ``best`` (P, 2) ``[chosen seed, feasible seeds]`` (:mod:`jwarp.kernels.ik_step`)."""
        n, E = n_dof, step_kernels
        qa = out[:, :n].reshape(P, S, n)
        e = out[:, n + E.COL_POS:n + E.COL_AUX + 1].reshape(P, S, 3)
        fz = (out[:, n + E.COL_FEASIBLE] != 0).reshape(P, S)
        it = out[:, n + E.COL_ITERATIONS].astype(np.int64).reshape(P, S)
        b = best[:, 0].astype(np.int64)
        r = np.arange(P)
        return cls(q=qa[r, b], feasible=fz[r, b], pos_err=e[r, b, 0], rot_err=e[r, b, 1],
                   cost=e[r, b, 2], iterations=it[r, b], start_index=b,
                   n_feasible=best[:, 1].astype(np.int64), wall_time=wall, all_q=qa,
                   all_feasible=fz, all_iterations=it)

    def reshaped(self, lead: tuple, wall: float | None = None) -> IKResult:
        """This result of P flat problems with the leading dims ``lead`` (prod = P)
        instead, and the wall time ``wall`` (None: unchanged)."""
        def shp(x: np.ndarray) -> np.ndarray:
            x = np.asarray(x)
            return x.reshape(tuple(lead) + x.shape[1:])

        return dataclasses.replace(
            self, wall_time=self.wall_time if wall is None else wall,
            **{f.name: shp(getattr(self, f.name)) for f in dataclasses.fields(self)
               if f.name != "wall_time"})
