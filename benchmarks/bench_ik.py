#!/usr/bin/env python
"""IK benchmark: the device-resident :class:`jwarp.solvers.ik.IKSolver` against the host
loop it replaced (kept here as :func:`legacy_ik`, the baseline), timed side by side.

    python benchmarks/bench_ik.py                      # CPU: section c (+ a, b at CPU sizes)
    python benchmarks/bench_ik.py --device cuda        # CUDA: sections a, b (+ c on the CPU)
    python benchmarks/bench_ik.py --quick              # smoke-test sizes

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
* ``c``: one justin19 collision-free IK on one CPU core (16 random seeds, the shelf world
  and grasp poses of ``bench_planning.py``'s IK figure): median time per target, solved
  rate; a persistent solver and :func:`jwarp.solvers.ik.ik` beside the baseline, all three
  from the same numpy seeds (so with the same solutions; drawing them is timed).

In a and b the persistent solver draws its seeds on the device (Warp's random stream),
:func:`ik` and the baseline on the host (numpy's); the solved rates are printed beside
the rates.

Every figure is the min and median over ``--repeats`` runs; the baseline runs in the same
process, interleaved with the new solver, and the ratio is baseline time / new time (per
run, and of the medians). The script prints the machine (CPU model, GPU name) and limits
numpy's BLAS to one thread (set before numpy loads; an exported value wins).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import platform
import sys
import time
from typing import Any, Callable

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402
import warp as wp  # noqa: E402

wp.config.quiet = True

import jwarp  # noqa: E402
from jwarp.core.arrays import init_warp  # noqa: E402
from jwarp.core.limits import sample_within_limits, within_limits  # noqa: E402
from jwarp.solvers import ik as IK  # noqa: E402
from jwarp.solvers.planner import collision_free  # noqa: E402
from jwarp.world import collision  # noqa: E402


# ====================================================================== the baseline
def legacy_ik(robot: Any, frame: Any, target: Any, *, world: Any = None, n_starts: int = 16,
              initial: Any = None, q_default: Any = None, weights: Any = None,
              tol_pos: float = 1e-4, tol_rot: float = 1e-3, margin: float = 0.0,
              eps: float | None = None, max_iterations: int = 200, step: float = 1.0,
              max_step: float = 0.5, damping: float = 1e-3, kappa: Any = None,
              lam: float = 0.7, tol_rho: float = 1e-6, stop_when_solved: bool = True,
              check_every: int = 5, seed: int | None = 0, device: Any = "cpu",
              dtype: Any = np.float64, callback: Callable | None = None) -> IK.IKResult:
    """The IK solver before :class:`IKSolver` (jwarp 634a275): kernels for the costs, then
    per iteration a host read of q, the errors, J and dU_A/dq, the damped least-squares
    step in numpy (float64) and the feasibility check of the candidates on the host
    (``collision_free``, float64). Inputs are not validated (the benchmark's own)."""
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
        JJt = J @ np.swapaxes(J, 1, 2) + mu2 * np.eye(len(rows))
        dq = np.einsum("bmn,bm->bn", J, np.linalg.solve(JJt, err[..., None])[..., 0])
        ga = obj.grad_a.numpy().astype(np.float64)
        ns = ga - np.einsum("bmn,bm->bn", J, np.linalg.solve(JJt, (J @ ga[..., None]))[..., 0])
        dq = np.where(on[:, None], dq - step * ns, dq)
        big = np.abs(dq).max(axis=1, keepdims=True)
        dq *= np.minimum(1.0, max_step / np.maximum(big, 1e-300))
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
        out.append(q[collision.is_collision_free(robot, q, world, margin, device=device,
                                                 dtype=np.float64)])
        if sum(map(len, out)) >= n:
            return np.concatenate(out)[:n]
    raise RuntimeError(f"fewer than {n} collision-free configurations of {robot.name}")


def stats(values: list[float]) -> dict:
    v = np.asarray(values, float)
    return {"min": float(v.min()), "median": float(np.median(v))}


def sync(device: Any) -> None:
    wp.synchronize_device(device)


def batched(args: argparse.Namespace, name: str, robot_name: str, frame: str, world: Any,
            margin: float, batch: int, starts: int) -> dict:
    """Solved targets per second of one batched solve, new solver vs baseline, interleaved."""
    robot = jwarp.robot(robot_name)
    rng = np.random.default_rng(0)
    q = free_configs(robot, world, batch, margin, rng, args.device)
    T = np.asarray(jwarp.fk(robot, q, device=args.device, dtype=np.float64)
                   )[:, robot.frame_index(frame)]
    dev, dt = args.device, args.dtype
    opts = IK.IKOptions(n_starts=starts, margin=margin, max_iterations=args.max_iterations)
    kw = dict(world=world, n_starts=starts, margin=margin, max_iterations=args.max_iterations,
              device=dev, dtype=dt)
    solver = IK.IKSolver(robot, frame, batch, opts, world=world, device=dev, dtype=dt)
    frozen = IK.IKSolver(robot, frame, batch, dataclasses.replace(opts, freeze_solved=True),
                         world=world, device=dev, dtype=dt)

    def run_new(seed: int, s: Any = solver) -> tuple[float, Any]:
        s.reseed(seed)
        sync(dev)
        t0 = time.perf_counter()
        r = s.solve(T)
        return time.perf_counter() - t0, r

    def run_frozen(seed: int) -> tuple[float, Any]:
        return run_new(seed, frozen)

    def run_ik(seed: int) -> tuple[float, Any]:
        sync(dev)
        t0 = time.perf_counter()
        r = IK.ik(robot, frame, T, seed=seed, **kw)
        return time.perf_counter() - t0, r

    def run_old(seed: int) -> tuple[float, Any]:
        sync(dev)
        t0 = time.perf_counter()
        r = legacy_ik(robot, frame, T, seed=seed, **kw)
        return time.perf_counter() - t0, r

    runs = {"solver": run_new, "solver_freeze_solved": run_frozen, "ik": run_ik,
            "baseline": run_old}
    if args.no_baseline:
        runs.pop("baseline")
    for fn in runs.values():  # warm-up: kernel compiles, first touch
        fn(0)
    rate: dict = {k: [] for k in runs}
    solved: dict = {k: [] for k in runs}
    secs: dict = {k: [] for k in runs}
    iters: dict = {k: [] for k in runs}
    for r in range(args.repeats):
        for k, fn in runs.items():
            t, res = fn(r + 1)
            secs[k].append(t)
            solved[k].append(float(np.mean(res.feasible)))
            rate[k].append(float(np.sum(res.feasible)) / t)
            iters[k].append(float(np.max(res.all_iterations)))
    out: dict = {"robot": robot_name, "frame": frame, "targets": batch, "starts": starts,
                 "margin_m": margin, "world": "shelf" if world is not None else None,
                 "max_iterations": args.max_iterations, "dtype": np.dtype(dt).name}
    for k in runs:
        out[k] = {"solved_targets_per_s": stats(rate[k]), "seconds": stats(secs[k]),
                  "solved_rate": stats(solved[k]), "iterations_run_max": stats(iters[k])}
    if "baseline" in runs:
        for k in ("solver", "solver_freeze_solved"):
            per = [n / b for b, n in zip(rate["baseline"], rate[k])]
            out[f"speedup_{k}_vs_baseline"] = {
                "per_run": per,
                "of_medians": float(np.median(rate[k]) / np.median(rate["baseline"]))}
    return out


# ====================================================================== sections
def section_a(args: argparse.Namespace) -> dict:
    return batched(args, "a", "arm7", "right_tcp", None, 0.0, args.batch, args.starts_a)


def section_b(args: argparse.Namespace) -> dict:
    from jwarp.world.scenes import shelf_world

    return batched(args, "b", "justin19", "right_tcp", shelf_world(), 0.01, args.batch_b,
                   args.starts_b)


def grasp_targets(n: int, seed: int = 1) -> list[np.ndarray]:
    """bench_planning.py's IK figure: grasp poses between the shelf's boards, hand pointing
    into the shelf (+x) with noise."""
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        p = [rng.uniform(0.5, 0.62), rng.uniform(-0.5, 0.1), rng.uniform(0.72, 0.88)]
        r = (Rotation.from_euler("y", 90, degrees=True)
             * Rotation.from_rotvec(rng.normal(scale=0.15, size=3))).as_rotvec()
        out.append(IK.pose_matrix(p, r))
    return out


def section_c(args: argparse.Namespace) -> dict:
    """One target at a time on one CPU core (Warp runs CPU kernels on one thread; numpy's
    BLAS is limited to one thread above)."""
    from jwarp.world.scenes import shelf_world

    robot = jwarp.robot("justin19")
    world = shelf_world()
    targets = grasp_targets(args.targets_c)
    kw = dict(world=world, n_starts=16, margin=0.01, device="cpu", dtype=np.float64)
    solver = IK.IKSolver(robot, "right_tcp", 1, IK.IKOptions(n_starts=16, margin=0.01),
                         world=world, device="cpu", dtype=np.float64)

    def run_new(T: np.ndarray, seed: int) -> Any:  # ik()'s seeds (numpy), drawn in the timing
        seeds = sample_within_limits(robot, 16, np.random.default_rng(seed))
        return solver.solve(T, seeds)

    runs = {"solver": run_new,
            "ik": lambda T, seed: IK.ik(robot, "right_tcp", T, seed=seed, **kw),
            "baseline": lambda T, seed: legacy_ik(robot, "right_tcp", T, seed=seed, **kw)}
    if args.no_baseline:
        runs.pop("baseline")
    for fn in runs.values():
        fn(targets[0], 0)
    med: dict = {k: [] for k in runs}
    solved: dict = {k: [] for k in runs}
    iters: dict = {k: [] for k in runs}
    for _ in range(args.repeats):
        per: dict = {k: [] for k in runs}
        for i, T in enumerate(targets):
            for k, fn in runs.items():  # interleaved per target
                t0 = time.perf_counter()
                res = fn(T, i)
                per[k].append(time.perf_counter() - t0)
                if len(solved[k]) < len(targets):
                    solved[k].append(bool(res.feasible))
                    iters[k].append(int(res.iterations))
        for k in runs:
            med[k].append(float(np.median(per[k])))
    out: dict = {"robot": "justin19", "frame": "right_tcp", "world": "shelf", "starts": 16,
                 "margin_m": 0.01, "targets": len(targets), "dtype": "float64"}
    for k in runs:
        out[k] = {"time_per_target_ms_median_over_targets": {
            s: 1e3 * v for s, v in stats(med[k]).items()},
            "solved_rate": float(np.mean(solved[k])),
            "iterations_median": float(np.median(iters[k]))}
    if "baseline" in runs:
        per_run = [b / n for b, n in zip(med["baseline"], med["solver"])]
        out["speedup_solver_vs_baseline"] = {
            "per_run": per_run, "of_medians": float(np.median(med["baseline"]) /
                                                    np.median(med["solver"]))}
        out["speedup_ik_vs_baseline"] = float(np.median(med["baseline"]) / np.median(med["ik"]))
    return out


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
    p.add_argument("--only", default="a,b,c")
    p.add_argument("--no-baseline", action="store_true", help="skip the baseline (legacy_ik)")
    p.add_argument("--quick", action="store_true", help="tiny sizes (smoke test)")
    p.add_argument("--json", default=None, metavar="FILE", help="also write the figures as JSON")
    args = p.parse_args(argv)
    init_warp()
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    from timing import machine

    cuda = str(args.device).startswith("cuda")
    args.dtype = np.dtype(args.dtype or ("float32" if cuda else "float64")).type
    if args.batch is None:
        args.batch = 10000 if cuda else 200
    if args.batch_b is None:
        args.batch_b = 10000 if cuda else 100
    if args.quick:
        args.batch, args.batch_b, args.targets_c, args.repeats = 8, 4, 3, 2
        args.max_iterations = min(args.max_iterations, 30)
    sections = {"a": section_a, "b": section_b, "c": section_c}
    result: dict = {"device": str(args.device), "machine": machine(args.device),
                    "cpu": machine("cpu"), "warp": wp.config.version,
                    "repeats": args.repeats}
    print(f"machine: {result['machine']}; CPU {result['cpu']}; warp {result['warp']}; "
          f"repeats {args.repeats} (min/median)")
    for name in [s.strip() for s in args.only.split(",") if s.strip()]:
        if name not in sections:
            p.error(f"--only: unknown section '{name}' (known: {', '.join(sections)})")
        t0 = time.perf_counter()
        result[name] = sections[name](args)
        print(f"== {name} ({time.perf_counter() - t0:.1f} s)")
        print(json.dumps(result[name], indent=1, default=float))
        sys.stdout.flush()
    if args.json:
        from jwarp.atomic import atomic_write_text

        atomic_write_text(args.json, json.dumps(result, indent=1, default=float) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
