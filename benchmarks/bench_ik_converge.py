#!/usr/bin/env python
"""IK convergence and per-target stopping (issue "IK that converges"): solve rate and
solved targets per second of :class:`jwarp.solvers.ik.IKSolver` on the Panda of
example-robot-data, with and without re-seeding stalled starts, timed side by side.

    python benchmarks/bench_ik_converge.py                      # CPU, both sections
    python benchmarks/bench_ik_converge.py --device cuda        # the H100 figures
    python benchmarks/bench_ik_converge.py --quick              # smoke-test sizes

Sections (``--only`` picks some):

* ``reach``: reachable targets (FK of uniform configurations inside the limits) of the
  frame ``panda_hand_tcp``, no collision model (pose and limits, as the peers compare),
  ``--seeds`` numpy seeds per target (the same for every variant), ``--iterations``,
  1 mm / 0.01 rad; for each of ``--targets``: ``restart_after=None`` (no re-seeding, the
  solver before this issue apart from the held limits), the default re-seeding, and the
  same with ``freeze_solved``; then :class:`IKOptions`' defaults (16 seeds, 200
  iterations, 1e-4 m / 1e-3 rad); ``--dtype`` the iteration's float type. "solved" is
  one float64 check of every returned configuration (jwarp's float64 FK: position and
  rotation error, box limits), not the solver's own flag. Solved targets per second = solved / (min or median seconds of one
  ``solve`` of a persistent solver, ``--repeats`` runs interleaved, each reseeded).
* ``scene``: collision-free IK of the fitted Panda sphere model
  (``benchmarks/scene_problems.py``'s, ``SpherizeOptions(tolerance=0.02)``) in a table
  and bookshelf scene (the ``bookshelf_small`` family's objects plus a table, exact
  primitives, ``jwarp.world.exact_world``), margin 0: ``--scene-targets`` targets = FK of
  configurations found collision-free there, 4 seeds each, one batch (the time of
  ``solve``) and one target at a time (median per target; on the CPU: one core).
"""

from __future__ import annotations

import argparse
import os
import sys

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402
import warp as wp  # noqa: E402

wp.config.quiet = True

import jwarp  # noqa: E402
from jwarp.core.arrays import init_warp  # noqa: E402
from jwarp.core.limits import sample_within_limits  # noqa: E402
from jwarp.solvers.ik import IKOptions, IKSolver

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import timing  # noqa: E402  (benchmarks/timing.py, beside this script)

URDF = "panda_description/urdf/panda.urdf"
TCP = "panda_hand_tcp"
#: the Warp device of every kernel here (FK included: a GPU machine may have no CPU
#: compiler for Warp)
DEVICE = "cpu"


def panda() -> object:
    """The Panda's kinematic model (no spheres), end effector ``tcp``."""
    from jwarp.importers.robot import example_robot_urdf, load_urdf

    return load_urdf(example_robot_urdf(URDF), end_effectors={"tcp": TCP}).model


def common_check(model: object, q: np.ndarray, T: np.ndarray, tol_pos: float,
                 tol_rot: float) -> np.ndarray:
    """(P,) bool: q (P, n_dof) puts ``tcp`` on T (P, 4, 4) within the tolerances (float64
    FK) and lies within the box limits."""
    F = jwarp.fk(model, np.asarray(q, np.float64), device=DEVICE)[:, model.frame_index("tcp")]
    pos = np.linalg.norm(F[:, :3, 3] - T[:, :3, 3], axis=1)
    c = (np.einsum("bij,bij->b", F[:, :3, :3], T[:, :3, :3]) - 1.0) / 2.0
    rot = np.arccos(np.clip(c, -1.0, 1.0))
    lo, hi = model.joint_limits.T
    inside = ((q >= lo - 1e-9) & (q <= hi + 1e-9)).all(1)
    return (pos < tol_pos) & (rot < tol_rot) & inside


def section_reach(args: argparse.Namespace) -> dict:
    model = panda()
    out = {}
    for P in args.targets:
        rng = np.random.default_rng(P)
        T = jwarp.fk(model, sample_within_limits(model, P, rng),
                     device=DEVICE)[:, model.frame_index("tcp")]
        S = args.seeds
        seeds = sample_within_limits(model, P * S, rng).reshape(P, S, -1)
        base = dict(n_starts=S, iterations=args.iterations, tol_pos=1e-3, tol_rot=1e-2)
        variants = {"no re-seeding": IKOptions(restart_after=None, **base),
                    "re-seeding (default)": IKOptions(**base),
                    "re-seeding + freeze_solved": IKOptions(freeze_solved=True, **base)}
        solvers = {k: IKSolver(model, "tcp", P, o, device=args.device, dtype=args.dtype)
                   for k, o in variants.items()}

        def make(s: IKSolver, seeds_: np.ndarray) -> object:
            def prepare(r: int) -> object:
                s.reseed(r)
                return lambda: s.solve(T, seeds_)
            return prepare

        runs = timing.each_run([make(s, seeds) for s in solvers.values()], args.repeats,
                               device=args.device)
        rows = {}
        for name, run in zip(solvers, runs):
            res = run.results[-1]
            ok = common_check(model, res.q, T, 1e-3, 1e-2)
            t = run.timing
            rows[name] = {"solved_pct": 100 * ok.mean(), "solver_says_pct": 100 * res.feasible.mean(),
                          "seconds": t.figures(), "solved_per_s": {"min_time": ok.sum() / t.best,
                                                                   "median_time": ok.sum() / t.median},
                          "median_iterations_chosen": float(np.median(res.iterations))}
            print(f"  {P:>6} targets  {name:28s} solved {rows[name]['solved_pct']:6.2f} %  "
                  f"{ok.sum() / t.best:10.0f} solved/s (min time {t.best * 1e3:.2f} ms, "
                  f"median {t.median * 1e3:.2f} ms)", flush=True)
        # the defaults: 16 random seeds (drawn by the solver), 200 iterations, 1e-4 / 1e-3
        d = IKSolver(model, "tcp", P, IKOptions(), device=args.device, dtype=args.dtype)
        run = timing.each_run([lambda r: (d.reseed(r), lambda: d.solve(T))[1]], args.repeats,
                              device=args.device)[0]
        res = run.results[-1]
        ok = common_check(model, res.q, T, 1e-4, 1e-3)
        rows["defaults (16 seeds, 200 it, 1e-4 m / 1e-3 rad)"] = {
            "solved_pct": 100 * ok.mean(), "seconds": run.timing.figures(),
            "solved_per_s": {"min_time": ok.sum() / run.timing.best}}
        print(f"  {P:>6} targets  defaults (16 seeds, 200 it)   solved {100 * ok.mean():6.2f} %  "
              f"{ok.sum() / run.timing.best:10.0f} solved/s", flush=True)
        out[str(P)] = rows
    return {"seeds": args.seeds, "iterations": args.iterations, "tol": "1 mm / 0.01 rad",
            "dtype": args.dtype,
            "by_targets": out}


def scene_setup(n_targets: int, device: str, robot_file: str | None = None) -> tuple:
    """(sphere model, exact world, targets (n, 4, 4)) of the table-and-bookshelf scene
    (``robot_file``: the fitted Panda as a robot JSON, else fitted here)."""
    import scene_problems as sp

    from jwarp.world.path_feasibility import collision_free
    from jwarp.world.scene_file import exact_world, scene_from_dict

    robot, _ = sp.load_robot(robot_file)
    rng = np.random.default_rng(7)
    objects, _, _ = sp.FAMILIES["bookshelf_small"](rng)
    table, _, _ = sp.FAMILIES["table_pick"](np.random.default_rng(8))
    table = [dict(o, id=f"t_{o['id']}") for o in table]  # ids unique across both
    scene = scene_from_dict({"world": {"collision_objects": objects + table}}, source="bench")
    world = exact_world(scene)
    fi = robot.frame_index(TCP)
    found = []
    while sum(len(f) for f in found) < n_targets:
        q = sample_within_limits(robot, 2000, rng)
        ok = collision_free(robot, world, q, 0.0, device=device)
        F = jwarp.fk(robot, q[ok], device=device)[:, fi]
        reach = (F[:, 0, 3] > 0.2) & (F[:, 2, 3] > 0.1)  # in front, above the floor
        found.append(F[reach])
    return robot, world, np.concatenate(found)[:n_targets]


def section_scene(args: argparse.Namespace) -> dict:
    robot, world, T = scene_setup(args.scene_targets, args.device, args.panda)
    P = len(T)
    o = IKOptions(n_starts=4, seed=0, cuda_graphs=not args.no_cuda_graphs)
    batch = IKSolver(robot, TCP, P, o, world=world, device=args.device)
    one = IKSolver(robot, TCP, 1, o, world=world, device=args.device)
    run = timing.each_run([lambda r: (batch.reseed(r), lambda: batch.solve(T))[1]],
                          args.repeats, device=args.device)[0]
    res = run.results[-1]
    per = []
    solved_one = 0
    for k in range(P):
        r1 = timing.each_run([lambda r, k=k: (one.reseed(r), lambda: one.solve(T[k]))[1]], 1,
                             device=args.device)[0]
        per.append(r1.seconds[0])
        solved_one += int(r1.results[0].feasible)
    fig = {"targets": P, "batch_seconds": run.timing.figures(),
           "batch_solved_pct": 100 * res.feasible.mean(),
           "one_target_ms": {"min": 1e3 * min(per), "median": 1e3 * float(np.median(per)),
                             "p95": 1e3 * float(np.percentile(per, 95))},
           "one_target_solved_pct": 100 * solved_one / P,
           "spheres": int(robot.n_spheres) if hasattr(robot, "n_spheres") else None}
    print(f"  batch of {P}: {run.timing.best * 1e3:.2f} ms (median {run.timing.median * 1e3:.2f}),"
          f" solved {fig['batch_solved_pct']:.1f} %; one target median "
          f"{fig['one_target_ms']['median']:.3f} ms, solved {fig['one_target_solved_pct']:.1f} %",
          flush=True)
    return fig


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--device", default="cpu", help="cpu (default) or cuda[:N]")
    p.add_argument("--targets", default="1000,10000", help="batch sizes of the reach section")
    p.add_argument("--seeds", type=int, default=4, help="seeds per target (reach)")
    p.add_argument("--iterations", type=int, default=50, help="iterations (reach)")
    p.add_argument("--scene-targets", type=int, default=100)
    p.add_argument("--no-cuda-graphs", action="store_true",
                   help="scene: launch every kernel from Python (IKOptions.cuda_graphs=False)")
    p.add_argument("--panda", default=None, metavar="JSON",
                   help="scene: the fitted Panda robot file (default: fit it here)")
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--dtype", choices=("float64", "float32"), default="float64",
                   help="the solver's float type (reach; its feasibility check is float64)")
    timing.section_options(p, "reach,scene")
    args = p.parse_args(argv)
    global DEVICE
    DEVICE = args.device
    init_warp()
    args.targets = [int(x) for x in str(args.targets).split(",") if x.strip()]
    if args.quick:
        args.targets, args.scene_targets, args.repeats = [50], 5, 2
    timing.run_sections(p, {"reach": section_reach, "scene": section_scene}, args,
                        f"{args.repeats} runs each")
    return 0


if __name__ == "__main__":
    sys.exit(main())
