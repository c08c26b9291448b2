"""Evaluation of IK warm starts: the analogues of the thesis' Table 3.5 (feasibility and
convergence of the IK solver from random / supervised / unsupervised initial guesses) and
Table 3.4 (ablation: feasibility after 10 solver iterations), thesis 3.5.3.

A *warm start* is any object with ``seeds(targets (P, 4, 4) numpy, world) -> (P, H,
n_dof)`` (:func:`jwarp.solvers.ik.check_warm_start`; a loaded
``jwarp.learn.ik_net.IKNet``, H = 2 for twin heads); ``None`` is the random baseline.

:func:`evaluate_ik` runs the two-stage solver (:class:`jwarp.solvers.ik.IKSolver`, every
seed on its own until it is feasible or out of iterations: ``stop_when_solved``,
``freeze_solved`` and re-seeding (``restart_after``) off, the thesis' multi-start) from
the seeds *in order*: a network's H heads first, then ``n_random`` random seeds (uniform
inside the limits, numpy stream of ``seed``: the same random seeds for every warm start
evaluated with the same ``seed``); the random baseline uses the random seeds only. Seeds
are independent, so they run in blocks and a target stops getting new blocks once one of
its seeds is feasible (the figures equal those of running every seed). The columns:

* ``feasibility_1`` ("Feas. (1)"): fraction of the targets solved from the first seed alone
  (a twin network: head 1); ``feasibility_heads`` ("best of the H heads"): solved by any
  head (None for the random baseline).
* ``multi_starts`` ("Multi-Starts [#]"): mean and std of the number of seeds tried, in
  order, until the first feasible one; a target with none feasible among the ``cap`` seeds
  counts as ``cap`` (``n_capped`` says how many did; the mean is then a lower bound).
* ``iterations`` ("Iterations [#]"): mean and std of the solver iterations of that first
  feasible seed, over the solved targets.
* ``length_cost`` ("Length Cost U_1^q"): mean and std over the solved targets of
  U_1^q(q, q_default) = 1/2 |q - q_default|^2 (thesis eq. 3.4) of that solution, with the
  solver's default pose (:meth:`jwarp.solvers.ik.IKObjective.set_default`: the middle of
  the limits projected onto the linear limits, unless ``q_default`` is given) - the
  closeness term of U_A without its weight [rad^2].

:func:`ablation_table` evaluates several networks after ``iterations`` (10) solver
iterations from their heads alone; :func:`format_table_35` and :func:`format_table_34`
print the tables with the thesis' column names.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from jwarp.core.limits import project_numpy, sample_within_limits
from jwarp.core.types import ArrayLike, DeviceLike, DTypeLike
from jwarp.solvers.ik import IKOptions, IKSolver, check_warm_start, warm_start_seeds
from jwarp.solvers.overrides import renamed_argument
from jwarp.utils.checks import check_int

if TYPE_CHECKING:
    from jwarp.model import RobotModel

#: seeds per target and block after the first (a target stops once one is feasible)
BLOCK = 8
#: the default number of random seeds tried one after the other (the cap of multi_starts)
N_RANDOM = 50


def _groups(world: Any, targets: ArrayLike) -> list[tuple[Any, np.ndarray]]:
    """[(world, targets (P, 4, 4))] from one world (or None) and (N, 4, 4) targets, or a
    sequence of W worlds with (W, P, 4, 4) targets or a sequence of W (P_w, 4, 4)."""
    def poses(t: Any, what: str) -> np.ndarray:
        from jwarp.solvers.ik.objective import as_poses

        a = np.asarray(as_poses(t), np.float64)  # also (positions, quaternions)
        if a.ndim == 2:
            a = a[None]
        if a.ndim != 3 or a.shape[1:] != (4, 4) or len(a) == 0:
            raise ValueError(f"{what}: expected poses (N, 4, 4), got shape {a.shape}")
        if not np.all(np.isfinite(a)):
            raise ValueError(f"{what}: contains NaN or inf")
        return a

    if isinstance(world, (list, tuple)):
        if len(world) == 0:
            raise ValueError("world: expected a world, None or a non-empty sequence of worlds")
        if isinstance(targets, np.ndarray) and targets.ndim == 4:
            targets = list(targets)
        if not isinstance(targets, (list, tuple)) or len(targets) != len(world):
            n = len(targets) if isinstance(targets, (list, tuple)) else np.shape(targets)
            raise ValueError(f"targets: expected one array of poses per world ({len(world)} "
                             f"worlds), got {n}")
        return [(w, poses(t, f"targets[{i}]")) for i, (w, t) in enumerate(zip(world, targets))]
    return [(world, poses(targets, "targets"))]


def _mean_std(x: Sequence[float] | np.ndarray) -> dict:
    a = np.asarray(x, np.float64)
    if a.size == 0:
        return {"mean": math.nan, "std": math.nan, "n": 0}
    return {"mean": float(a.mean()), "std": float(a.std()), "n": int(a.size)}


def _solve_block(model: RobotModel, frame: int | str, world: Any, T: np.ndarray, seeds: np.ndarray,
                 opts: IKOptions, device: DeviceLike, dtype: DTypeLike) -> tuple[np.ndarray, ...]:
    """Every seed (P, S, n) on its own: (feasible (P, S), iterations (P, S), q (P, S, n))."""
    solver = IKSolver(model, frame, len(T), opts, world=world, device=device, dtype=dtype)
    res = solver.solve(T, seeds)
    return (np.asarray(res.all_feasible).reshape(seeds.shape[:2]),
            np.asarray(res.all_iterations).reshape(seeds.shape[:2]),
            np.asarray(res.all_q).reshape(seeds.shape))


def evaluate_ik(robot: RobotModel, frame: int | str, world: Any, targets: ArrayLike, *, warm_start: Any = None,
                n_random: int = N_RANDOM, iterations: int | None = None, margin: float = 0.0,
                tol_pos: float = 1e-4, tol_rot: float = 1e-3, q_default: Any = None,
                seed: int = 0, device: DeviceLike = None, dtype: DTypeLike = np.float64,
                name: str | None = None, **old_names: Any) -> dict:
    """The Table 3.5 columns of one initial guess (module docstring).

    Args:
        robot: robot name or RobotModel; frame: the end-effector frame.
        world: a :class:`jwarp.world.World`, None (self-collision only) or a sequence of
            worlds; targets: poses (N, 4, 4) (one world), or per world (W, P, 4, 4) or a
            sequence of W arrays (P_w, 4, 4); a pose array may also be a tuple
            ``(positions (N, 3), quaternions (N, 4) xyzw)`` (as :func:`jwarp.ik`).
        warm_start: None (random initial guesses) or an object with a callable ``seeds``.
        n_random: random seeds tried one after the other (after a network's heads), >= 0
            (>= 1 without a warm start); the cap of the multi-starts is H + n_random.
        iterations: solver iterations per seed (None: 200; ``max_iterations``: the name
            before issue 28, deprecated); margin, tol_pos, tol_rot, q_default:
            the solver's options (:class:`jwarp.solvers.ik.IKOptions`).
        seed: numpy seed of the random seeds; device, dtype: where the solver runs.
        name: the row's name (default "Random" or the warm start's class name).

    Returns:
        dict: ``name``, ``robot``, ``dof``, ``frame``, ``n_targets``, ``n_worlds``,
        ``heads`` (H; 0 random), ``feasibility_1``, ``feasibility_heads`` (None when
        H < 2), ``multi_starts`` {mean, std, cap, n_capped}, ``solved_rate`` (within the
        cap), ``iterations`` and ``length_cost`` {mean, std, n}, ``max_iterations``,
        ``n_random``, ``wall_s``.
    """
    t0 = time.perf_counter()
    check_warm_start(warm_start)
    model = robot
    fi = model.frame_index(frame)
    n_random = check_int(n_random, "n_random", 0 if warm_start is not None else 1)
    unknown = sorted(set(old_names) - {"max_iterations"})
    if unknown:
        raise TypeError(f"evaluate_ik() got an unexpected keyword argument {unknown[0]!r}")
    iterations = renamed_argument("evaluate_ik()", "max_iterations", "iterations", old_names,
                                  iterations)   # the name before issue 28, for one release
    max_iterations = check_int(200 if iterations is None else iterations, "iterations", 0)
    opts = IKOptions(n_starts=1, iterations=max_iterations, margin=margin, tol_pos=tol_pos,
                     tol_rot=tol_rot, stop_when_solved=False, q_default=q_default, seed=seed,
                     restart_after=None, freeze_solved=False)  # every seed on its own
    qd = (project_numpy(model, model.joint_limits.mean(axis=1)) if q_default is None
          else np.asarray(q_default, np.float64).reshape(model.n_dof))
    rng = np.random.default_rng(seed)
    first, heads_ok, counts, iters, lengths = [], [], [], [], []
    H = 0
    n_capped = 0
    groups = _groups(world, targets)
    for w, T in groups:
        P, n = len(T), model.n_dof
        rand = sample_within_limits(model, P * n_random, rng).reshape(P, n_random, n) \
            if n_random else np.zeros((P, 0, n))
        if warm_start is not None:
            ws = warm_start_seeds(model, warm_start, T, w)
            if H and ws.shape[1] != H:
                raise ValueError(f"warm_start: returned {ws.shape[1]} seeds per target for one "
                                 f"world and {H} for another")
            H = ws.shape[1]
            seeds = np.concatenate([ws, rand], axis=1)
        else:
            seeds = rand
        cap = seeds.shape[1]
        lead = max(H, 1)
        # the first block: every target's heads (or its first random seed)
        fz, it, q = _solve_block(model, fi, w, T, seeds[:, :lead], opts, device, dtype)
        found = np.full(P, -1)
        f_it = np.zeros(P, np.int64)
        f_q = np.zeros((P, n))

        def record(rows: np.ndarray, offset: int, fz: np.ndarray, it: np.ndarray,
                   q: np.ndarray) -> None:
            for r, row in enumerate(rows):
                k = np.flatnonzero(fz[r])
                if len(k) and found[row] < 0:  # noqa: B023 (record runs in this iteration)
                    found[row] = offset + k[0]  # noqa: B023
                    f_it[row] = it[r, k[0]]  # noqa: B023
                    f_q[row] = q[r, k[0]]  # noqa: B023

        record(np.arange(P), 0, fz, it, q)
        first.append(fz[:, 0])
        if H >= 2:
            heads_ok.append(fz.any(axis=1))
        start = lead
        while start < cap:
            rows = np.flatnonzero(found < 0)
            if len(rows) == 0:
                break
            stop = min(cap, start + BLOCK)
            fz, it, q = _solve_block(model, fi, w, T[rows], seeds[rows, start:stop], opts,
                                     device, dtype)
            record(rows, start, fz, it, q)
            start = stop
        ok = found >= 0
        n_capped += int((~ok).sum())
        counts.append(np.where(ok, found + 1, cap))
        iters.append(f_it[ok])
        lengths.append(0.5 * np.sum((f_q[ok] - qd) ** 2, axis=1))
    counts_a = np.concatenate(counts)
    N = len(counts_a)
    ms = _mean_std(counts_a)
    cap = max(H, 0) + n_random
    return {
        "name": name or ("Random" if warm_start is None else type(warm_start).__name__),
        "robot": model.name, "dof": model.n_dof, "frame": str(frame), "n_targets": N,
        "n_worlds": len(groups), "heads": H,
        "feasibility_1": float(np.concatenate(first).mean()),
        "feasibility_heads": float(np.concatenate(heads_ok).mean()) if heads_ok else None,
        "multi_starts": {"mean": ms["mean"], "std": ms["std"], "cap": cap,
                         "n_capped": n_capped},
        "solved_rate": float(1.0 - n_capped / N),
        "iterations": _mean_std(np.concatenate(iters)),
        "length_cost": _mean_std(np.concatenate(lengths)),
        "max_iterations": max_iterations, "n_random": n_random,
        "wall_s": time.perf_counter() - t0,
    }


def _config_value(net: Any, key: str) -> Any:
    """``key`` of the network's ``config`` (attribute or key), else of its training
    settings ``meta["training"]`` (boosting is a training setting); None where missing."""
    for src in (getattr(net, "config", None),
                (getattr(net, "meta", None) or {}).get("training")
                if isinstance(getattr(net, "meta", None), Mapping) else None):
        if src is None:
            continue
        v = src.get(key) if isinstance(src, Mapping) else getattr(src, key, None)
        if v is not None:
            return v
    return None


def ablation_table(robot: RobotModel, frame: int | str, world: Any, targets: ArrayLike,
                   nets: Mapping[str, Any] | Sequence[tuple[str, Any]], *,
                   iterations: int = 10, device: DeviceLike = None, **options: Any) -> list[dict]:
    """Table 3.4: per network (``{name: net}`` or ``[(name, net)]``) the feasibility after
    ``iterations`` solver iterations from its heads alone (head 1: ``feasibility``; any
    head: ``feasibility_heads``), with its ``boosting``, ``twin`` and ``unit_vectors``
    settings read from ``net.config`` (attribute or key) or ``net.meta["training"]``
    (None where missing). Further
    ``options`` go to :func:`evaluate_ik` (margin, seed, ...)."""
    items = list(nets.items()) if isinstance(nets, Mapping) else list(nets)
    if not items:
        raise ValueError("nets: expected at least one network")
    rows = []
    for label, net in items:
        if net is None:
            raise TypeError(f"nets[{label!r}]: expected a warm start, got None")
        check_warm_start(net, f"nets[{label!r}]")
        r = evaluate_ik(robot, frame, world, targets, warm_start=net, n_random=0,
                        iterations=iterations, device=device, name=str(label), **options)
        rows.append({"name": str(label), "boosting": _config_value(net, "boosting"),
                     "twin": _config_value(net, "twin"),
                     "unit_vectors": _config_value(net, "unit_vectors"),
                     "feasibility": r["feasibility_1"],
                     "feasibility_heads": r["feasibility_heads"], "iterations": iterations,
                     "n_targets": r["n_targets"]})
    return rows


# ------------------------------------------------------------------ printing
def _pm(d: dict, fmt: str = ".2f") -> str:
    if not d or d.get("n", 1) == 0 or not math.isfinite(d["mean"]):
        return "-"
    return f"{d['mean']:{fmt}} ± {d['std']:{fmt}}"


def _table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    widths = [max(len(h), *(len(r[i]) for r in rows)) if rows else len(h)
              for i, h in enumerate(header)]
    line = "  ".join(h.ljust(w) for h, w in zip(header, widths)).rstrip()
    out = [line, "-" * len(line)]
    out += ["  ".join(c.ljust(w) for c, w in zip(r, widths)).rstrip() for r in rows]
    return "\n".join(out)


TABLE_35_COLUMNS = ("Robot", "DoF", "Initial Guess", "Multi-Starts [#]", "Feas. (1) [%]",
                    "Feas. (heads) [%]", "Iterations [#]", "Length Cost U_1^q [rad^2]",
                    "Solved [%]")
TABLE_34_COLUMNS = ("Network", "Training w. Boosting", "Twin-Headed Network",
                    "Unit Vector Output", "Feasibility", "Feasibility (heads)")


def format_table_35(rows: Sequence[dict], title: str | None = None) -> str:
    """Table 3.5 analogue of :func:`evaluate_ik` results (one row each); the robot and DoF
    are printed on the first row of each robot. A capped multi-start mean is marked
    ``>=`` (cap and capped count in a note below)."""
    lines = []
    body = []
    prev = None
    for r in rows:
        ms = r["multi_starts"]
        m = _pm({"mean": ms["mean"], "std": ms["std"]})
        if ms["n_capped"]:
            m = ">=" + m
        same = prev == r["robot"]
        prev = r["robot"]
        heads = r.get("feasibility_heads")
        body.append(["" if same else r["robot"], "" if same else str(r["dof"]), r["name"], m,
                     f"{100 * r['feasibility_1']:.1f}",
                     "-" if heads is None else f"{100 * heads:.1f}",
                     _pm(r["iterations"]), _pm(r["length_cost"]),
                     f"{100 * r['solved_rate']:.1f}"])
    if title:
        lines.append(title)
    lines.append(_table(TABLE_35_COLUMNS, body))
    notes = [f"{r['name']}: {r['multi_starts']['n_capped']} of {r['n_targets']} targets not "
             f"solved within the cap of {r['multi_starts']['cap']} seeds"
             for r in rows if r["multi_starts"]["n_capped"]]
    if rows:
        r0 = rows[0]
        lines.append(f"{r0['n_targets']} targets in {r0['n_worlds']} world(s); at most "
                     f"{r0['max_iterations']} iterations per seed; random seeds tried one "
                     f"after the other up to the cap (heads first for a network)")
    lines += notes
    return "\n".join(lines)


def format_table_34(rows: Sequence[dict], title: str | None = None) -> str:
    """Table 3.4 analogue of :func:`ablation_table` rows."""
    def yn(v: Any) -> str:
        return "-" if v is None else ("Yes" if v else "No")

    body = [[r["name"], yn(r["boosting"]), yn(r["twin"]), yn(r["unit_vectors"]),
             f"{r['feasibility']:.3f}",
             "-" if r["feasibility_heads"] is None else f"{r['feasibility_heads']:.3f}"]
            for r in rows]
    lines = [title] if title else []
    lines.append(_table(TABLE_34_COLUMNS, body))
    if rows:
        lines.append(f"feasibility after {rows[0]['iterations']} solver iterations from the "
                     f"network's prediction alone ({rows[0]['n_targets']} targets)")
    return "\n".join(lines)
