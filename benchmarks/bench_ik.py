#!/usr/bin/env python
"""IK benchmark: the device-resident :class:`jwarp.solvers.ik.IKSolver` against the host
loop it replaced (kept here as :func:`legacy_ik`, the baseline), timed side by side.

    python benchmarks/bench_ik.py                      # CPU: section c (+ a, b at CPU sizes)
    python benchmarks/bench_ik.py --device cuda        # CUDA: sections a, b (+ c on the CPU)
    python benchmarks/bench_ik.py --quick              # smoke-test sizes
    PYTHONPATH=/tmp/peers python benchmarks/bench_ik.py --peers   # vs Newton, pytorch_kinematics

Sections (``--only`` picks some):

* ``a``: batched IK of arm7's ``tcp`` (position and orientation to 1e-4 m / 1e-3 rad, joint
  limits, self-collision free); targets = FK of random collision-free configurations;
  solved targets per second at ``--batch`` targets (``--starts-a`` seeds each), for the
  solver with :func:`ik`'s semantics (``solver``), with ``freeze_solved`` (a problem's
  other seeds stop at its first feasible one), :func:`ik` itself and the baseline; the
  speedups are ratios of solved targets per second (per run and of the medians).
* ``b``: justin19 ``right_tcp`` collision-free IK in the shelf world
  (:func:`jwarp.world.scenes.shelf_world`, margin 1 cm): targets = FK of random
  configurations that are collision-free with that margin; solved targets per second.
* ``c``: one justin19 collision-free IK on one CPU core (16 random seeds, grasp poses in
  the shelf world; :func:`shelf_ik`, which ``bench_planning.py``'s ``ik`` section calls
  too): median time per target, solved rate; a persistent solver and
  :func:`jwarp.solvers.ik.ik` beside the baseline, all three from the same numpy seeds (so
  with the same solutions; drawing them is timed).

* ``peers`` (``--peers``, or ``--only peers``): jwarp's IKSolver beside Newton's ``newton.ik``
  IKSolver (Levenberg-Marquardt; at each of ``--newton-iterations``) and pytorch_kinematics'
  PseudoInverseIK on the Panda of example-robot-data (TCP ``panda_hand_tcp``): the same
  reachable targets (FK of random configurations), the same ``--peer-seeds`` numpy seeds per
  target, 1 mm / 0.01 rad, and one float64 check of every returned configuration (pinocchio,
  else jwarp's float64 FK: pose errors and joint limits; ``benchmarks/ik_peers.py``); printed
  as a table ``| targets | library | solved targets/s | solved |``. A peer that is not
  installed is printed as "not installed". Newton runs on the Warp device, pytorch_kinematics
  on the torch device of ``--device``.

In a and b the persistent solver draws its seeds on the device (Warp's random stream),
:func:`ik` and the baseline on the host (numpy's); the solved rates are printed beside
the rates.

Every figure is the min and median over ``--repeats`` runs, timed one solve per run by
``benchmarks/timing.py`` (:func:`timing.each_run`: an untimed warm-up first, every call
closed by a device sync); the baseline runs in the same process, interleaved with the new
solver, and the speedup is baseline time / new time (per run, of the medians and of the
bests). The script prints the machine (CPU model, GPU name) and limits numpy's BLAS to one
thread (set before numpy loads; an exported value wins).
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import io
import math
import os
import sys
import time
from collections.abc import Callable, Sequence
from typing import Any

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402
import warp as wp  # noqa: E402

wp.config.quiet = True

import jwarp  # noqa: E402
from jwarp.core.arrays import init_warp  # noqa: E402
from jwarp.core.limits import sample_within_limits, within_limits  # noqa: E402
from jwarp.kernels.ik_step import LIMIT_HOLD  # noqa: E402
from jwarp.solvers import ik as IK  # noqa: E402
from jwarp.world import collision  # noqa: E402
from jwarp.world.path_feasibility import collision_free

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))  # also when imported by path
import timing  # noqa: E402  (benchmarks/timing.py, beside this script)


# ====================================================================== the baseline
def legacy_ik(robot: Any, frame: Any, target: Any, *, world: Any = None, n_starts: int = 16,
              initial: Any = None, q_default: Any = None, weights: Any = None,
              tol_pos: float = 1e-4, tol_rot: float = 1e-3, margin: float = 0.0,
              eps: float | None = None, iterations: int = 200, step: float = 1.0,
              max_step: float = 0.5, damping: float = 1e-3, kappa: Any = None,
              lam: float = 0.7, tol_rho: float = 1e-6, stop_when_solved: bool = True,
              check_every: int = 5, seed: int | None = 0, device: Any = "cpu",
              dtype: Any = np.float64, callback: Callable | None = None,
              hold_limits: bool = False) -> IK.IKResult:
    """The IK solver before :class:`IKSolver` (jwarp 634a275): kernels for the costs, then
    per iteration a host read of q, the errors, J and dU_A/dq, the damped least-squares
    step in numpy (float64) and the feasibility check of the candidates on the host
    (``collision_free``, float64). Inputs are not validated (the benchmark's own).
    ``hold_limits``: the solver's rule since: joints at a box limit (within
    ``ik_step.LIMIT_HOLD``) that the step pushes outward are held (their Jacobian columns
    and gradient entries zeroed, the step recomputed); the tests' reference of it."""
    t0 = time.perf_counter()
    init_warp()
    model = jwarp.robot(robot)
    fi = model.frame_index(frame)
    T = np.asarray(target, np.float64)
    lead = T.shape[:-2]
    T = T.reshape(-1, 4, 4)
    eps_v = eps if eps is not None else max(
        float(world.voxel_size) if world is not None else 0.0, 0.01, margin)
    nT = len(T)
    rng = np.random.default_rng(seed)
    if initial is None:
        q0 = sample_within_limits(model, nT * n_starts, rng).reshape(nT, n_starts, model.n_dof)
    else:
        q0 = np.array(np.broadcast_to(np.asarray(initial, np.float64).reshape(
            (-1,) + np.shape(initial)[-2:]), (nT,) + np.shape(initial)[-2:]))
        n_starts = q0.shape[1]
    B = nT * n_starts
    obj = IK.IKObjective(model, fi, B, world=world, weights=weights, eps=eps_v,
                         q_default=q_default, kappa=kappa, lam=lam, device=device, dtype=dtype)
    obj.set_q(q0.reshape(B, -1))
    obj.project_limits()
    obj.set_target(np.repeat(T, n_starts, axis=0))
    wts = obj.weights
    w_min = min([v for v in (wts.world, wts.self) if v > 0] or [0.0])
    screen = w_min * (eps_v - margin) ** 2 / (2.0 * eps_v)
    rows = np.array([0, 1, 5]) if model.workspace_dim == 2 else np.arange(6)
    npos = 2 if model.workspace_dim == 2 else 3
    done = np.zeros(B, bool)
    feasible = np.zeros(B, bool)
    max_iterations = iterations
    iters = np.full(B, max_iterations, np.int64)
    q_out = np.zeros((B, model.n_dof))
    errs = np.zeros((B, 3))  # pos, rot, U_A
    mu2 = damping ** 2
    for it in range(max_iterations + 1):
        obj.evaluate_pose()
        obj.evaluate_aux()
        q = obj.q.numpy().astype(np.float64)
        if callback is not None:
            callback(it, q)
        err = obj.err.numpy().astype(np.float64)[:, rows]
        pe = np.linalg.norm(err[:, :npos], axis=1)
        re = np.linalg.norm(err[:, npos:], axis=1)
        on = (pe < tol_pos) & (re < tol_rot)
        if obj.compensation is not None:
            on &= obj.delta.numpy() < tol_rho
        cost_a = obj.cost_a.numpy().astype(np.float64)
        coll = obj.coll_cost.numpy()
        full = it % check_every == 0 or it == max_iterations
        cand = np.nonzero(~done & on & ((coll < screen) | full))[0]
        if len(cand):
            rho = obj.compensation.rho()[cand] if obj.compensation is not None else None
            ok = within_limits(model, q[cand]) & collision_free(model, world, q[cand], margin,
                                                                rho=rho)
            newly = cand[ok]
            feasible[newly] = True
            done[newly] = True
            iters[newly] = it
            q_out[newly] = q[newly]
            errs[newly] = np.stack([pe[newly], re[newly], cost_a[newly]], 1)
        if done.all() or it == max_iterations:
            break
        if stop_when_solved and feasible.reshape(nT, n_starts).any(1).all():
            break
        J = obj.jac.numpy().astype(np.float64)[:, rows]         # (B, m, n)
        ga = obj.grad_a.numpy().astype(np.float64)

        def dls(J: np.ndarray, ga: np.ndarray) -> np.ndarray:
            JJt = J @ np.swapaxes(J, 1, 2) + mu2 * np.eye(len(rows))
            dq = np.einsum("bmn,bm->bn", J, np.linalg.solve(JJt, err[..., None])[..., 0])
            ns = ga - np.einsum("bmn,bm->bn", J,
                                np.linalg.solve(JJt, (J @ ga[..., None]))[..., 0])
            dq = np.where(on[:, None], dq - step * ns, dq)
            big = np.abs(dq).max(axis=1, keepdims=True)
            return dq * np.minimum(1.0, max_step / np.maximum(big, 1e-300))

        dq = dls(J, ga)
        if hold_limits:
            lim = obj.limits.box.numpy().astype(np.float64)
            held = (((dq < 0) & (q <= lim[:, 0] + LIMIT_HOLD))
                    | ((dq > 0) & (q >= lim[:, 1] - LIMIT_HOLD)))
            rows_h = held.any(1)
            if rows_h.any():
                free = (~held).astype(np.float64)
                dq[rows_h] = dls(J * free[:, None, :], ga * free)[rows_h]
        dq[done] = 0.0
        obj.set_q(q + dq, keep_rho=True)
        obj.project_limits()
    rest = np.nonzero(~done)[0]
    if len(rest):
        q_out[rest] = q[rest]
        errs[rest] = np.stack([pe[rest], re[rest], cost_a[rest]], 1)
    S = n_starts
    out = np.concatenate([q_out, errs, feasible[:, None], iters[:, None]], axis=1)
    fz, e = feasible.reshape(nT, S), errs.reshape(nT, S, 3)
    best = np.stack([IK.select_best(fz, e), fz.sum(1)], axis=1)
    res = IK.IKResult.from_rows(out, best, model.n_dof, nT, S, time.perf_counter() - t0)
    return res.reshaped(lead)


# ====================================================================== helpers
def free_configs(robot: Any, world: Any, n: int, margin: float, rng: np.random.Generator,
                 device: Any = "cpu") -> np.ndarray:
    """n random configurations within the limits, collision-free with ``margin``."""
    out: list = []
    for _ in range(200):
        q = sample_within_limits(robot, 4 * n, rng)
        out.append(q[collision.is_collision_free(jwarp.robot(robot), q, world, margin, device=device,
                                                 dtype=np.float64)])
        if sum(map(len, out)) >= n:
            return np.concatenate(out)[:n]
    raise RuntimeError(f"fewer than {n} collision-free configurations of {robot.name}")


def stats(values: list[float]) -> dict:
    """min and median of per-run figures that are not times (rates, solved shares)."""
    v = np.asarray(values, float)
    return {"min": float(v.min()), "median": float(np.median(v))}


def batched(args: argparse.Namespace, name: str, robot_name: str, frame: str, world: Any,
            margin: float, batch: int, starts: int) -> dict:
    """Solved targets per second of one batched solve, new solver vs baseline, interleaved
    (:func:`timing.each_run`: one solve per variant and run, seeds 1..``--repeats``)."""
    robot = jwarp.robot(robot_name)
    rng = np.random.default_rng(0)
    q = free_configs(robot, world, batch, margin, rng, args.device)
    T = np.asarray(jwarp.fk(robot, q, device=args.device, dtype=np.float64)
                   )[:, robot.frame_index(frame)]
    dev, dt = args.device, args.dtype
    opts = IK.IKOptions(n_starts=starts, margin=margin, iterations=args.max_iterations,
                        freeze_solved=False)  # ik()'s semantics before freezing was default
    kw = dict(world=world, n_starts=starts, margin=margin, iterations=args.max_iterations,
              device=dev, dtype=dt)

    def persistent(s: IK.IKSolver) -> Callable[[int], Callable[[], Any]]:
        def make(seed: int) -> Callable[[], Any]:
            s.reseed(seed)  # untimed: the solver's device seeds of this run
            return lambda: s.solve(T)
        return make

    makes: dict = {
        "solver": persistent(IK.IKSolver(robot, frame, batch, opts, world=world, device=dev,
                                         dtype=dt)),
        "solver_freeze_solved": persistent(IK.IKSolver(
            robot, frame, batch, dataclasses.replace(opts, freeze_solved=True), world=world,
            device=dev, dtype=dt)),
        "ik": lambda seed: lambda: IK.ik(robot, frame, T, seed=seed, **kw),
        "baseline": lambda seed: lambda: legacy_ik(robot, frame, T, seed=seed, **kw)}
    if args.no_baseline:
        makes.pop("baseline")
    runs = dict(zip(makes, timing.each_run(list(makes.values()), args.repeats, dev)))
    out: dict = {"robot": robot_name, "frame": frame, "targets": batch, "starts": starts,
                 "margin_m": margin, "world": "shelf" if world is not None else None,
                 "max_iterations": args.max_iterations, "dtype": np.dtype(dt).name}
    per_solved: dict = {}  # seconds per solved target, run by run
    for k, r in runs.items():
        n_solved = [float(np.sum(res.feasible)) for res in r.results]
        per_solved[k] = [t / n if n else math.inf for t, n in zip(r.seconds, n_solved)]
        out[k] = {"solved_targets_per_s": stats([n / t for t, n in zip(r.seconds, n_solved)]),
                  "seconds": r.timing.figures(),
                  "solved_rate": stats([float(np.mean(res.feasible)) for res in r.results]),
                  "iterations_run_max": stats([float(np.max(res.all_iterations))
                                               for res in r.results])}
    if "baseline" in runs:
        for k in ("solver", "solver_freeze_solved"):
            out[f"speedup_{k}_vs_baseline"] = timing.speedup(per_solved["baseline"],
                                                             per_solved[k])
    return out


# ====================================================================== sections
def section_a(args: argparse.Namespace) -> dict:
    return batched(args, "a", "arm7", "right_tcp", None, 0.0, args.batch, args.starts_a)


def section_b(args: argparse.Namespace) -> dict:
    from jwarp.world.scenes import shelf_world

    return batched(args, "b", "justin19", "right_tcp", shelf_world(), 0.01, args.batch_b,
                   args.starts_b)


def grasp_targets(n: int, seed: int = 1) -> list[np.ndarray]:
    """Grasp poses between the shelf's boards, hand pointing into the shelf (+x) with noise
    (:func:`jwarp.world.scenes.shelf_grasp_poses`; the targets of :func:`shelf_ik`)."""
    from jwarp.world.scenes import shelf_grasp_poses

    return list(shelf_grasp_poses(n, seed))


SHELF_VARIANTS = ("solver", "ik", "baseline")


def shelf_ik(n_targets: int, repeats: int, starts: int = 16,
             variants: Sequence[str] = SHELF_VARIANTS) -> dict:
    """One justin19 collision-free IK at a time on one CPU core (Warp runs CPU kernels on
    one thread; numpy's BLAS is limited to one thread above): ``n_targets`` grasp targets
    (:func:`grasp_targets`) in the shelf world, margin 1 cm, ``starts`` random seeds drawn
    by numpy from seed = the target's index. Variants (``variants`` picks): ``solver`` (a
    persistent :class:`IKSolver` given those seeds; drawing them is timed), ``ik``
    (:func:`jwarp.solvers.ik.ik`) and ``baseline`` (:func:`legacy_ik`), interleaved target
    by target (:func:`timing.each_run`). Per variant: the median time per target of each
    of the ``repeats`` passes over the targets, min and median over the passes [ms]; the
    solved rate and median iterations (first pass); the speedups of the solver and ik()
    over the baseline. Section c, and bench_planning.py's ``ik`` section."""
    from jwarp.world.scenes import shelf_world

    robot = jwarp.robot("justin19")
    world = shelf_world()
    targets = grasp_targets(n_targets)
    n = len(targets)
    kw = dict(world=world, n_starts=starts, margin=0.01, device="cpu", dtype=np.float64)
    solver = IK.IKSolver(robot, "right_tcp", 1, IK.IKOptions(n_starts=starts, margin=0.01),
                         world=world, device="cpu", dtype=np.float64)

    def solve_new(T: np.ndarray, seed: int) -> Any:  # ik()'s seeds (numpy), drawn in the timing
        solver.reseed(seed)  # and ik()'s re-seeds
        return solver.solve(T, sample_within_limits(robot, starts, np.random.default_rng(seed)))

    solves = {"solver": solve_new,
              "ik": lambda T, seed: IK.ik(robot, "right_tcp", T, seed=seed, **kw),
              "baseline": lambda T, seed: legacy_ik(robot, "right_tcp", T, seed=seed, **kw)}
    solves = {k: solves[k] for k in variants}

    def per_target(solve: Callable) -> Callable[[int], Callable[[], Any]]:
        def make(r: int) -> Callable[[], Any]:  # run r >= 1: target (r - 1) % n, seed = index
            i = (r - 1) % n if r else 0
            return lambda: solve(targets[i], i)
        return make

    runs = dict(zip(solves, timing.each_run([per_target(f) for f in solves.values()],
                                            repeats * n)))
    out: dict = {"robot": "justin19", "frame": "right_tcp", "world": "shelf", "starts": starts,
                 "margin_m": 0.01, "targets": n, "dtype": "float64"}
    med: dict = {}  # per pass over the targets: the median seconds per target
    for k, r in runs.items():
        med[k] = [float(np.median(r.seconds[j * n:(j + 1) * n])) for j in range(repeats)]
        first = r.results[:n]
        out[k] = {"time_per_target_ms_median_over_targets": timing.summarize(med[k]).figures(1e3),
                  "solved_rate": float(np.mean([bool(res.feasible) for res in first])),
                  "iterations_median": float(np.median([int(res.iterations) for res in first]))}
    if "baseline" in runs:
        for k in ("solver", "ik"):
            if k in runs:
                out[f"speedup_{k}_vs_baseline"] = timing.speedup(med["baseline"], med[k])
    return out


def section_c(args: argparse.Namespace) -> dict:
    variants = [v for v in SHELF_VARIANTS if not (args.no_baseline and v == "baseline")]
    return shelf_ik(args.targets_c, args.repeats, variants=variants)


# ====================================================================== peers
def _ints(p: argparse.ArgumentParser, option: str, text: str) -> list[int]:
    """Comma-separated positive integers of ``option`` (a parser error naming it otherwise)."""
    try:
        vals = [int(v) for v in str(text).split(",") if v.strip()]
    except ValueError:
        vals = []
    if not vals or min(vals) < 1:
        p.error(f"{option}: expected comma-separated positive integers, got {text!r}")
    return vals


def _count(n: int) -> str:
    """A target count as the issue's tables print it (1e3, or the number)."""
    e = int(round(math.log10(n)))
    return f"1e{e}" if 10 ** e == n and e >= 2 else str(n)


def _k(v: float) -> str:
    """A rate as the issue's tables print it (121 k)."""
    return f"{v / 1e3:.3g} k"


def section_peers(args: argparse.Namespace) -> dict:
    """jwarp vs Newton's ik and pytorch_kinematics (module docstring, ``benchmarks/ik_peers.py``):
    per ``--peer-targets`` size and library, solved targets per second (min and median over
    ``--repeats`` runs, one solve each, interleaved after an untimed warm-up,
    :func:`timing.each_run`) and the solved share of the common check; a library whose
    warm-up solve predicts more than ``--peer-budget`` seconds for the runs at a size is
    skipped there. Prints the table, returns the figures."""
    import importlib.metadata as md

    import ik_peers as K

    dev, dt = args.device, args.dtype
    tol_p, tol_r = args.peer_tol_pos, args.peer_tol_rot
    S, it = args.peer_seeds, args.peer_iterations
    try:
        urdf, model = K.panda(args.peer_urdf, args.peer_model)
    except ValueError as e:
        raise SystemExit(f"bench_ik.py: {e}") from None
    check = K.PoseCheck(urdf, model, tol_p, tol_r, device=dev)
    libs = args.peer_libraries
    newton = K.import_newton() if "newton" in libs else None
    pk = K.import_pytorch_kinematics() if "pytorch_kinematics" in libs else None

    def version(dist: str) -> str | None:
        try:
            return md.version(dist)
        except md.PackageNotFoundError:
            return None

    out: dict = {"robot": model.name, "urdf": urdf, "frame": K.TCP, "seeds": S,
                 "iterations": it, "newton_iterations": args.newton_iterations,
                 "tol_pos_m": tol_p, "tol_rot_rad": tol_r, "check": check.reference,
                 "limit_slack_rad": K.LIMIT_SLACK, "dtype_jwarp_pytorch_kinematics":
                 np.dtype(dt).name, "dtype_newton": "float32",
                 "jwarp_commit": _git_commit(),
                 "newton": (newton.__version__ if newton is not None else "not installed")
                 if "newton" in libs else "not run",
                 "pytorch_kinematics": (version("pytorch-kinematics") or "installed")
                 if pk is not None else ("not installed" if "pytorch_kinematics" in libs
                                         else "not run"),
                 "stand_ins": list(K.STAND_INS), "rows": []}
    try:
        import torch
        out["torch"] = torch.__version__
    except ImportError:
        out["torch"] = "not installed"

    # the frames agree: each library's own FK of the TCP against the reference (float64)
    rng = np.random.default_rng(123)
    q5 = sample_within_limits(model, 5, rng)[:, K.arm_columns(model)]
    ref = check.fk(q5)
    frame_check: dict = {}

    def frame_diff(name: str, T: np.ndarray) -> None:
        d = float(np.abs(np.asarray(T) - ref).max())
        frame_check[name] = d
        if d > 1e-5:  # float32 FK agrees to ~1e-6; more is another frame or offset
            raise RuntimeError(f"peers: {name}'s TCP frame differs from the reference by {d:g}")

    q_full = np.tile(np.mean(model.joint_limits, axis=1), (5, 1))
    q_full[:, K.arm_columns(model)] = q5
    frame_diff("jwarp", np.asarray(jwarp.fk(model, q_full, device=dev, dtype=np.float64)
                                   )[:, model.frame_index(K.TCP)])
    out["frame_check_max_abs_diff"] = frame_check

    for P in args.peer_targets:
        T, _, seeds = K.problem(model, P, S, seed=0, device=dev)
        runners: dict = {}
        if "jwarp" in libs:
            jw = K.Jwarp(model, P, S, it, tol_p, tol_r, dev, dt)
            runners[f"jwarp IKSolver, max {it} it"] = (jw, lambda jw=jw: jw.solve(T, seeds))
        if newton is not None:
            nw = K.Newton(newton, urdf, P, S, max(args.newton_iterations), dev)
            if "newton" not in frame_check:
                frame_diff("newton", nw.fk(q5))
            for n_it in args.newton_iterations:
                runners[f"Newton {newton.__version__} ik LM, {n_it} it"] = (
                    nw, lambda nw=nw, n_it=n_it: nw.solve(T, seeds, n_it))
        if pk is not None:
            with contextlib.redirect_stderr(io.StringIO()):  # its URDF parser's warnings
                pr = K.PytorchKinematics(pk, urdf, P, S, it, tol_p, tol_r, dev, dt)
            if "pytorch_kinematics" not in frame_check:
                frame_diff("pytorch_kinematics", pr.fk(q5))
            runners[f"pytorch_kinematics, {it} it"] = (pr, lambda pr=pr: pr.solve(T, seeds))
        # untimed first call of each (compiles); skip what would exceed the budget
        kept: dict = {}
        for name, (runner, call) in runners.items():
            t0 = time.perf_counter()
            call()
            wp.synchronize_device(dev)
            first = time.perf_counter() - t0
            if first * args.repeats > args.peer_budget:
                out["rows"].append({"targets": P, "library": name, "skipped":
                                    f"first solve {first:.1f} s x {args.repeats} runs > "
                                    f"--peer-budget {args.peer_budget:g} s"})
            else:
                kept[name] = (runner, call)
        runs = timing.each_run([lambda r, c=c: c for _, c in kept.values()], args.repeats, dev)
        for (name, (runner, _)), r in zip(kept.items(), runs):
            solved, rates, pose_ok, over = [], [], [], 0.0
            for q, t in zip(r.results, r.seconds):
                q_best = K.pick_best(check, q, T) if runner.returns_all_seeds else q
                n = int(check(q_best, T).solved.sum())
                solved.append(n / P)
                rates.append(n / t)
                c = check(q, T)  # every seed returned: on target ignoring the limits
                ok = (c.pos_err <= tol_p) & (c.rot_err <= tol_r)
                pose_ok.append(float(np.mean(ok.reshape(P, -1).any(1))))
                over = max(over, float(np.max(np.maximum(q - check.hi, check.lo - q))))
            row = {"targets": P, "library": name, "solved_targets_per_s": stats(rates),
                   "solved_rate": stats(solved), "pose_only_rate": stats(pose_ok),
                   "max_limit_violation_rad": max(over, 0.0), "seconds": r.timing.figures()}
            if isinstance(runner, K.Jwarp):
                row["jwarp_own_feasible_rate"] = float(np.mean(runner.last.feasible))
                row["iterations_run_max"] = int(np.max(runner.last.all_iterations))
            out["rows"].append(row)
    print(peers_table(out))
    return out


def peers_table(out: dict) -> str:
    """The peers section's figures as the issue's table (solved targets/s: median over the
    runs, min in brackets; solved: the common check), then: pose only (a returned seed on
    target when the limits are ignored), the largest joint-limit violation of any returned
    seed [rad] (0: none) and the seconds per solve."""
    lines = ["| targets | library | solved targets/s | solved | pose only | largest limit "
             "violation [rad] | s per solve (min / median) |", "|---|---|---|---|---|---|---|"]
    for r in out["rows"]:
        if "skipped" in r:
            lines.append(f"| {_count(r['targets'])} | {r['library']} | skipped: {r['skipped']} "
                         "| | | | |")
            continue
        rate, sec = r["solved_targets_per_s"], r["seconds"]
        lines.append(f"| {_count(r['targets'])} | {r['library']} | {_k(rate['median'])} "
                     f"(min {_k(rate['min'])}) | {100 * r['solved_rate']['median']:.1f}% | "
                     f"{100 * r['pose_only_rate']['median']:.1f}% | "
                     f"{r['max_limit_violation_rad']:.2g} | "
                     f"{sec['min']:.3g} / {sec['median']:.3g} |")
    for lib in ("newton", "pytorch_kinematics"):
        if out[lib] == "not installed":
            lines.append(f"| | {lib} | not installed | | | | |")
    return "\n".join(lines)


def _git_commit() -> str:
    """The commit of the jwarp that runs (the git checkout holding the imported package),
    with ``+uncommitted jwarp/ changes`` where its jwarp/ differs from that commit."""
    import subprocess

    pkg = os.path.dirname(os.path.abspath(jwarp.__file__))
    try:
        c = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=pkg,
                           capture_output=True, text=True, timeout=10).stdout.strip()
        d = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no", "--", "."],
                           cwd=pkg, capture_output=True, text=True, timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        c = d = ""
    if not c:
        return f"unknown (jwarp from {pkg}, not a git checkout)"
    return c + (" +uncommitted jwarp/ changes" if d else "")


# ====================================================================== main
def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--device", default="cpu", help="cpu (default) or cuda[:N] (sections a, b; "
                   "c always runs on the CPU)")
    p.add_argument("--dtype", default=None, help="float32 or float64 of sections a, b "
                   "(default: float32 on CUDA, float64 on the CPU)")
    p.add_argument("--batch", type=int, default=None,
                   help="targets of section a (default 10000 on CUDA, 200 on the CPU)")
    p.add_argument("--batch-b", type=int, default=None,
                   help="targets of section b (default 10000 on CUDA, 100 on the CPU)")
    p.add_argument("--starts-a", type=int, default=4, help="seeds per target, section a")
    p.add_argument("--starts-b", type=int, default=4, help="seeds per target, section b")
    p.add_argument("--max-iterations", type=int, default=50,
                   help="iterations per seed, sections a and b")
    p.add_argument("--targets-c", type=int, default=40, help="targets of section c")
    p.add_argument("--repeats", type=int, default=5, help="timed runs (min/median)")
    p.add_argument("--no-baseline", action="store_true", help="skip the baseline (legacy_ik)")
    p.add_argument("--peers", action="store_true",
                   help="run the peers section (jwarp vs Newton's ik and pytorch_kinematics); "
                   "alone unless --only names other sections too")
    p.add_argument("--peer-targets", default=None,
                   help="comma-separated target counts of the peers section (default 1000 on "
                   "the CPU, 1000,10000 on CUDA; --quick 8)")
    p.add_argument("--peer-seeds", type=int, default=4, help="seeds per target, peers")
    p.add_argument("--peer-iterations", type=int, default=50,
                   help="iterations of jwarp (its maximum) and pytorch_kinematics, peers")
    p.add_argument("--newton-iterations", default="10,20,50",
                   help="comma-separated iteration counts of Newton's LM, peers")
    p.add_argument("--peer-libraries", default="jwarp,newton,pytorch_kinematics",
                   help="comma-separated libraries of the peers section")
    p.add_argument("--peer-tol-pos", type=float, default=1e-3, help="peers: tolerance [m]")
    p.add_argument("--peer-tol-rot", type=float, default=1e-2, help="peers: tolerance [rad]")
    p.add_argument("--peer-urdf", default=None,
                   help="peers: the Panda URDF (default: example-robot-data's)")
    p.add_argument("--peer-model", default=None,
                   help="peers: jwarp's robot JSON of that URDF (default: imported from it; "
                   "write both with: python benchmarks/ik_peers.py DIR)")
    p.add_argument("--peer-budget", type=float, default=120.0,
                   help="peers: skip a library at a size where its first solve times "
                   "--repeats exceeds this [s]")
    timing.section_options(p, "a,b,c")
    args = p.parse_args(argv)
    if args.peers and "peers" not in args.only.split(","):
        args.only = "peers" if args.only == "a,b,c" else args.only + ",peers"
    args.newton_iterations = _ints(p, "--newton-iterations", args.newton_iterations)
    for opt in ("peer_seeds", "peer_iterations"):
        if getattr(args, opt) < 1:
            p.error(f"--{opt.replace('_', '-')}: expected >= 1, got {getattr(args, opt)}")
    for opt in ("peer_tol_pos", "peer_tol_rot", "peer_budget"):
        if not getattr(args, opt) > 0:
            p.error(f"--{opt.replace('_', '-')}: expected > 0, got {getattr(args, opt)}")
    known = ("jwarp", "newton", "pytorch_kinematics")
    args.peer_libraries = [v.strip() for v in args.peer_libraries.split(",") if v.strip()]
    if not args.peer_libraries or set(args.peer_libraries) - set(known):
        p.error(f"--peer-libraries: expected some of {', '.join(known)}, got "
                f"{','.join(args.peer_libraries)!r}")
    init_warp()
    cuda = str(args.device).startswith("cuda")
    args.dtype = np.dtype(args.dtype or ("float32" if cuda else "float64")).type
    if args.batch is None:
        args.batch = 10000 if cuda else 200
    if args.batch_b is None:
        args.batch_b = 10000 if cuda else 100
    if args.peer_targets is None:
        args.peer_targets = "8" if args.quick else ("1000,10000" if cuda else "1000")
    args.peer_targets = _ints(p, "--peer-targets", args.peer_targets)
    if args.quick:
        args.batch, args.batch_b, args.targets_c, args.repeats = 8, 4, 3, 2
        args.max_iterations = min(args.max_iterations, 30)
    sections = {"a": section_a, "b": section_b, "c": section_c, "peers": section_peers}
    timing.run_sections(p, sections, args, f"repeats {args.repeats} (min/median)",
                        repeats=args.repeats)
    return 0


if __name__ == "__main__":
    sys.exit(main())
