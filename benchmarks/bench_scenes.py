#!/usr/bin/env python
"""Arm planning on MotionBenchMaker-style scene problems: jwarp's planner on the exact
world, every path it calls feasible re-checked by the independent verifier, and OMPL's
RRT-Connect as a baseline on the same checks (a script printing figures, never a timed
test).

    python benchmarks/bench_scenes.py                          # 7 x 100 problems, CPU
    python benchmarks/bench_scenes.py --per-family 10          # 70 problems
    python benchmarks/bench_scenes.py --problems DIR           # a set of scene_problems.py
    python benchmarks/bench_scenes.py --quick                  # 3 per family
    python benchmarks/bench_scenes.py --device cuda            # per-problem on the GPU
    python benchmarks/bench_scenes.py --json out.json
    python benchmarks/bench_scenes.py --problems DIR --robot ur5.json   # another arm's set

The arm is the Panda (fitted from example-robot-data's URDF, or ``--robot``), or the one a
``--problems`` set was made for (its index's ``robot``: ``scene_problems.py --arm ur5``,
``kinova``, ``xarm7``; then ``--robot`` is its imported model, ``jwarp import-urdf URDF
--srdf SRDF``).

1. Problems: ``benchmarks/scene_problems.py`` (``--per-family N``, ``--seed S``,
   ``--families``) written to ``--out`` (default: a temporary folder), or read with
   ``--problems DIR`` (its ``index.json``).
2. jwarp: for every margin of ``--margins`` (default ``0,0.01``) and every problem, one
   :class:`jwarp.solvers.planning.Planner` on ``jwarp.world.exact_world(scene)`` (no grid)
   with ``PlanOptions(margin, endpoint_margin=0, time_limit=1 s, stop_when_solved=True,
   fallback="rrt")``, device ``cpu`` (one core: Warp runs CPU kernels serially, numpy's
   BLAS is held to one thread) and/or ``cuda``; untimed warm-up calls first (kernel
   compilation): the first problem of every family (with every ``--versus`` variant). The
   time of a problem is the Planner's construction plus its ``plan`` call (wall clock).
3. The verifier (``tests/verifier.py``: pinocchio FK, coal distances of the URDF collision
   meshes and of the robot's spheres to the exact scene primitives, samples <= 0.5 deg
   apart) re-checks every path jwarp calls feasible, with jwarp's own rule: the first and
   the last segment at ``endpoint_margin`` (0), the segments between at ``margin``. A
   *collision* is a verifier distance < 0 anywhere on the path: must be 0. What counts
   follows jwarp's promise for the robot (printed as ``promise:``): a robot with collision
   pieces (every ``jwarp import-urdf``) has the mesh certificate, so its URDF meshes keep
   the margin and its spheres may touch an object where the meshes are proven clear: a
   collision is a mesh distance < 0; a robot without pieces promises its spheres: a mesh
   or a sphere distance < 0. ``m-viol`` counts paths whose promised geometry comes closer
   than the margin on the inner segments (should be 0); ``mesh<margin`` the paths whose
   URDF meshes do (information where the spheres are the promise).
   Self-collision: the URDF meshes of every link pair jwarp checks (its frame pairs with
   spheres, mapped to their links) must not intersect anywhere on the path (coal; counted
   as a collision; ``--no-verify-self`` skips it).
4. Baseline: OMPL (``pip install ompl``, 2.0.1, or ``pip install -e ".[benchmark]"``)
   RRT-Connect in the arm joints (the Panda's 7; its fingers fixed at the start's value), without path simplification, its state validity
   ``jwarp.world.collision.is_collision_free`` and its motion validator jwarp's exact
   continuous check (``MotionCheck.check`` of the 2-waypoint path), both at the margin
   (``endpoint_margin`` at the start and goal states and on motions from or to them),
   the same time limit. Skipped (said so) where ``ompl`` cannot be imported, or with
   ``--no-ompl``. Its paths are not re-verified (``--verify-ompl`` does).

``--no-stop-when-solved`` plans with ``stop_when_solved=False``; ``--option NAME=JSON``
sets another PlanOptions field (repeatable, e.g. ``--option shorten=0``). ``--versus
"NAME=JSON[;NAME=JSON]"`` (repeatable) plans every problem also with these fields over the
others, the variants taking turns problem by problem (order alternating) so that they share
the machine's load, a table each (e.g. ``--versus via_ik=0``: before and after an option).

Printed: the machine, the settings, then per device and margin a table per family
(problems, solved, solved by the straight line / the optimizer / the fallback, verified
collision-free of the solved, collisions, margin violations, median / p95 / max seconds, median / p95 length
ratio: U_l of the solved paths, 1 for the straight line) and the baseline's
line, and at the end a summary table. A path jwarp called feasible that the verifier finds
colliding is saved (scene file, ``path.npy``, the verdict) under ``--save-failures``.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

# one CPU core: numpy's BLAS would otherwise use every core. Set before numpy loads; an
# exported value wins.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402
import warp as wp  # noqa: E402

if hasattr(wp.config, "quiet"):
    wp.config.quiet = True

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
sys.path.insert(0, str(ROOT / "tests"))

import scene_problems as SP  # noqa: E402
import timing  # noqa: E402

try:  # pinocchio + coal: the verifier (a GPU machine may lack them: --no-verify there)
    from verifier import PathVerifier, checked_link_pairs, robot_spheres  # noqa: E402
except ImportError as _e:
    PathVerifier = None  # type: ignore[assignment,misc]
    _VERIFIER_MISSING = f"{type(_e).__name__}: {_e}"

import jwarp
from jwarp.core.arrays import init_warp  # noqa: E402


# ------------------------------------------------------------------ problems
def read_index(args: argparse.Namespace) -> dict | None:
    """The index of ``--problems`` (None: problems are generated)."""
    if not args.problems:
        return None
    file = Path(args.problems) / "index.json"
    if not file.is_file():
        raise SystemExit(f"--problems: no index.json in {args.problems}")
    return json.loads(file.read_text())


def near_goals(index: dict) -> tuple[int, int, int] | None:
    """(goals whose URDF meshes are within 1 cm of an object, goals, within 2 cm) by the
    index's recorded clearance (``clearance_m.goal_mesh``); None without it."""
    d = [p.get("clearance_m", {}).get("goal_mesh") for p in index.get("problems", [])]
    if not d or any(v is None for v in d):
        return None
    a = np.asarray(d, np.float64)
    return int((a <= 0.01).sum()), len(a), int((a <= 0.02).sum())


def load_problems(args: argparse.Namespace) -> tuple[Path, dict]:
    """(folder, index) of the problem set: read (``--problems``) or generated."""
    if args.problems:
        folder = Path(args.problems)
        index = read_index(args)
        assert index is not None
        if args.families:
            fams = args.families.split(",")
            index["problems"] = [p for p in index["problems"] if p["family"] in fams]
        return folder, index
    folder = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="bench_scenes_"))
    fams = args.families.split(",") if args.families else None
    elapsed = timing.stopwatch()
    index = SP.generate(folder, args.per_family, args.seed, fams, log=lambda s: None)
    print(f"generated {len(index['problems'])} problems ({len(index['failed'])} failed) "
          f"into {folder} in {elapsed():.1f} s", flush=True)
    return folder, index


class Problem:
    """One problem: the scene, its exact world, start and goal (the model's joints)."""

    def __init__(self, folder: Path, entry: dict, robot: Any) -> None:
        from jwarp.world import exact_world, load_scene
        from jwarp.world.moveit import joint_vector
        from jwarp.world.scene_file import robot_frames

        self.file = folder / entry["file"]
        self.name = Path(entry["file"]).stem
        self.family = entry["family"]
        self.scene = load_scene(self.file, robot_frames(robot))
        self.world = exact_world(self.scene)
        self.start = joint_vector(robot, self.scene.start, "start")
        self.goal = joint_vector(robot, self.scene.goal, "goal", self.start)
        self._verifier = None

    def verifier(self, urdf: str, spheres: list, names: list) -> Any:
        if self._verifier is None:
            self._verifier = PathVerifier(urdf, None, self.scene.shapes, spheres=spheres,
                                          joint_names=names, self_pairs=SELF_PAIRS or None)
        return self._verifier


#: the arm joints OMPL plans in (``scene_problems.ArmSpec.joints``; set in main)
ARM_JOINTS: list[str] = list(SP.ARM)
#: URDF link pairs the verifier checks mesh against mesh (``self_link_pairs``; set in main)
SELF_PAIRS: list[tuple[str, str]] = []
#: what jwarp promises for the robot (set in main): "meshes" where it records its collision
#: pieces (the mesh certificate proves what its spheres cannot: its spheres may touch an
#: object where the meshes keep clear), else "spheres" (its spheres keep the margin)
PROMISE = ["spheres"]


def self_link_pairs(robot: Any, urdf: str) -> list[tuple[str, str]]:
    """The URDF link pairs of the frame pairs jwarp checks for self-collision
    (``verifier.checked_link_pairs``): the meshes of these pairs must stay apart."""
    return checked_link_pairs(robot, PathVerifier(urdf, None, []))


# ------------------------------------------------------------------ jwarp
def plan_one(robot: Any, prob: Problem, margin: float, args: argparse.Namespace,
             device: str, variant: dict | None = None) -> tuple[float, Any]:
    from jwarp.solvers.planning import Planner, PlanOptions

    o = PlanOptions(margin=margin, endpoint_margin=args.endpoint_margin,
                    time_limit=args.time_limit, stop_when_solved=not args.no_stop_when_solved,
                    fallback="rrt", **{**extra_options(args), **(variant or {})})
    wp.synchronize_device(device)
    t0 = time.perf_counter()
    try:
        res = Planner(robot, prob.world, 1, o, device=device).plan(prob.start, prob.goal)
    except Exception as e:  # noqa: BLE001 - a planner error is a failed problem, kept
        res = e
    wp.synchronize_device(device)
    return time.perf_counter() - t0, res


def warm_check(robot: Any, prob: Problem, device: str) -> None:
    """The rest of the warm-up: the float64 continuous check of 2-waypoint paths (the
    shortcuts of ``PlanOptions.shorten`` and the RRT fallback's edges) and, for a robot
    with collision pieces, the mesh certificate's kernels, which the first problem's plan
    may not have loaded (its path needs no shortcut, its endpoints no meshes), so that no
    timed problem pays for loading them."""
    from jwarp.solvers.planning import Planner
    from jwarp.world.mesh_check import mesh_check

    pl = Planner(robot, prob.world, 1, device=device)
    pl.motion_check().check(np.stack([prob.start, prob.start])[None], group=1)
    mc = mesh_check(robot, prob.world, device)  # the certificate's kernels too
    if mc is not None:
        mc.paths_free(np.stack([prob.start, prob.goal])[None])
    wp.synchronize_device(device)


def extra_options(args: argparse.Namespace) -> dict:
    """PlanOptions fields given on the command line (``--option NAME=VALUE``)."""
    return parse_options(args.option)


def parse_options(texts: list[str] | None) -> dict:
    """``NAME=JSON`` texts as a dict of PlanOptions fields."""
    out = {}
    for text in texts or []:
        k, _, v = text.partition("=")
        out[k.strip()] = json.loads(v)
    return out


def variants(args: argparse.Namespace) -> list[tuple[str, dict]]:
    """The option sets planned side by side: ``("", {})`` (the options as given) and one
    per ``--versus "NAME=JSON[,NAME=JSON]"`` (its fields over them)."""
    out: list[tuple[str, dict]] = [("", {})]
    for text in args.versus or []:
        out.append((text, parse_options([t for t in text.split(";") if t.strip()])))
    return out


def length_ratio(path: np.ndarray) -> float:
    """The length cost U_l of a path (W, n) (thesis eq. 3.5, as ``PlanResult.length_cost``):
    1 for the straight line at evenly spaced waypoints, > 1 for any detour."""
    path = np.asarray(path, np.float64)
    d2 = float(np.sum((path[-1] - path[0]) ** 2))
    seg = float(np.sum(np.diff(path, axis=0) ** 2))
    return (len(path) - 1) * seg / max(d2, 1e-12)


def verify(v: Any, path: np.ndarray, margin: float, end_margin: float) -> dict:
    """jwarp's rule (module docstring): first/last segments at min(margin, end_margin),
    the inner ones at margin. Returns the figures of the row."""
    em = min(margin, end_margin)
    W = len(path)
    parts = ([(path, em)] if W <= 2 else
             [(path[:2], em), (path[1:-1], margin), (path[-2:], em)])
    t0 = time.perf_counter()
    verdicts = [(v.check_path(p, margin=m, endpoint_margin=m), m) for p, m in parts]
    out: dict = {"verify_s": time.perf_counter() - t0}
    selfm = [x.self_mesh for x, _ in verdicts if x.self_mesh is not None]
    self_min = min(selfm, key=lambda h: h.distance) if selfm else None
    out["self_min_m"] = None if self_min is None else self_min.distance
    out["self_collision"] = bool(self_min is not None and self_min.distance < 0)
    mesh = [x.mesh for x, _ in verdicts if x.mesh is not None]
    sph = [x.sphere for x, _ in verdicts if x.sphere is not None]
    mesh_min = min(mesh, key=lambda h: h.distance) if mesh else None
    sph_min = min(sph, key=lambda h: h.distance) if sph else None
    out["mesh_min_m"] = None if mesh_min is None else mesh_min.distance
    out["sphere_min_m"] = None if sph_min is None else sph_min.distance
    meshes = PROMISE[0] == "meshes"
    # the meshes always count; the spheres where they are the promise
    hits = [h for h in ((mesh_min,) if meshes else (mesh_min, sph_min)) if h is not None]
    worst = min(hits, key=lambda h: h.distance) if hits else None
    out["collision"] = bool(worst is not None and worst.distance < 0) or out["self_collision"]
    out["closest"] = None if worst is None else str(worst)
    # inner segments at the margin (the promised geometry: meshes or spheres)
    inner = verdicts[1][0] if len(verdicts) == 3 else verdicts[0][0]
    m_inner = verdicts[1][1] if len(verdicts) == 3 else em
    kept = inner.mesh if meshes else inner.sphere
    out["sphere_margin_violation"] = bool(kept is not None and kept.distance < m_inner)
    out["mesh_below_margin"] = bool(inner.mesh is not None and inner.mesh.distance < m_inner)
    out["first_violation"] = next((str(x.first_violation) for x, _ in verdicts
                                   if x.first_violation is not None), None)
    return out


def save_failure(args: argparse.Namespace, prob: Problem, path: np.ndarray, tag: str,
                 row: dict) -> str:
    d = Path(args.save_failures) / f"{prob.name}_{tag}"
    d.mkdir(parents=True, exist_ok=True)
    shutil.copy(prob.file, d / prob.file.name)
    np.save(d / "path.npy", path)
    (d / "verdict.json").write_text(json.dumps(row, indent=1, default=str))
    return str(d)


def save_path(folder: str, prob: Problem, path: np.ndarray, tag: str) -> None:
    """One feasible path as ``folder/tag/problem.npy`` (for ``--verify-saved`` elsewhere)."""
    d = Path(folder) / tag
    d.mkdir(parents=True, exist_ok=True)
    np.save(d / f"{prob.name}.npy", path)


def verify_saved(args: argparse.Namespace, robot: Any, urdf: str | None, spheres: list,
                 probs: list[Problem], margins: list[float]) -> int:
    """``--verify-saved DIR``: the verifier on paths another machine planned and saved with
    ``--save-paths`` (a GPU machine without pinocchio/coal). Prints per folder the paths
    checked and the collisions; returns the number of collisions."""
    if urdf is None:
        raise SystemExit("--verify-saved: needs example-robot-data (the arm's URDF)")
    by_name = {p.name: p for p in probs}
    total = 0
    for d in sorted(Path(args.verify_saved).iterdir()):
        if not d.is_dir():
            continue
        m = float(d.name.rsplit("_m", 1)[1])
        files = sorted(d.glob("*.npy"))
        coll = viol = mesh = sphere = 0
        for f in files:
            p = by_name.get(f.stem)
            if p is None:
                raise SystemExit(f"--verify-saved: {f} names no problem of the set")
            row = verify(p.verifier(urdf, spheres, robot.joint_names), np.load(f), m,
                         args.endpoint_margin)
            coll += row["collision"]
            viol += row["sphere_margin_violation"]
            mesh += (row["mesh_min_m"] is not None and row["mesh_min_m"] < 0) or row["self_collision"]
            sphere += row["sphere_min_m"] is not None and row["sphere_min_m"] < 0
            if row["collision"]:
                print(f"  !! {d.name}/{f.stem}: {row['first_violation']}", flush=True)
        print(f"{d.name}: {len(files)} feasible paths verified, {coll} collisions ({mesh} of "
              f"the URDF meshes, world or self, {sphere} of the spheres), {viol} sphere margin violations",
              flush=True)
        total += coll
    print(f"verifier collisions among the saved feasible paths: {total} (must be 0)")
    return total


def run_jwarp(robot: Any, urdf: str, spheres: list, probs: list[Problem], margin: float,
              args: argparse.Namespace, device: str) -> tuple[list[dict], float]:
    """Every problem planned on ``device`` at ``margin``; (rows, wall time of all)."""
    vs = variants(args)
    # warm-up, untimed: the first problem of every family with every variant, so that the
    # kernels of the stages a straight first problem skips are loaded too
    firsts = list({p.family: p for p in reversed(probs)}.values())
    for p in firsts:
        for _, extra in vs:
            plan_one(robot, p, margin, args, device, extra)
    warm_check(robot, probs[0], device)
    rows = []
    total = timing.stopwatch()
    # every problem planned with every variant in turn (the order alternating), so the
    # variants share the machine's load
    jobs = [(k, p, vs[(k + j) % len(vs)]) for k, p in enumerate(probs) for j in range(len(vs))]
    for k, p, (vname, extra) in jobs:
        t, res = plan_one(robot, p, margin, args, device, extra)
        if isinstance(res, Exception):
            ok = False
            row = {"planner": "jwarp", "device": device, "margin": margin, "problem": p.name,
                   "family": p.family, "solved": False, "time_s": t, "stage": "error",
                   "stop_reason": "error", "reason": f"{type(res).__name__}: {res}"}
            print(f"  {p.name} margin {margin:g}: planner error: {row['reason']}", flush=True)
        else:
            ok = bool(res.feasible[0])
            row = {"planner": "jwarp", "device": device, "margin": margin, "problem": p.name,
                   "family": p.family, "solved": ok, "time_s": t, "stage": str(res.stage[0]),
                   "stop_reason": str(res.stop_reason), "reason": str(res.reasons[0]),
                   "timings": {k2: float(v) for k2, v in res.timings.items()}}
            if ok:
                row["length_ratio"] = length_ratio(res.path[0])
                if args.save_paths:
                    save_path(args.save_paths, p, np.asarray(res.path[0], np.float64),
                              f"{device.split(':')[0]}_m{margin:g}")
        if ok and not args.no_verify:
            path = np.asarray(res.path[0], np.float64)
            row.update(verify(p.verifier(urdf, spheres, robot.joint_names), path, margin,
                              args.endpoint_margin))
            if row["collision"] or row["sphere_margin_violation"]:
                row["saved"] = save_failure(args, p, path, f"{device}_m{margin:g}", row)
                print(f"  !! {p.name} margin {margin:g}: jwarp feasible, verifier: "
                      f"{row['first_violation']} (saved to {row['saved']})", flush=True)
        row["variant"] = vname
        rows.append(row)
        if args.progress:
            print(f"  [{k + 1}/{len(probs)}] {p.name}{' ' + vname if vname else ''}: "
                  f"{'solved' if ok else 'failed'} ({row['stage']}) {t:.3f} s",
                  file=sys.stderr, flush=True)
    return rows, total()


# ------------------------------------------------------------------ OMPL baseline
def ompl_modules() -> tuple[Any, Any, Any] | str:
    try:
        from ompl import base as ob
        from ompl import geometric as og
        from ompl import util as ou
    except Exception as e:  # noqa: BLE001 - any import failure skips the baseline
        return f"{type(e).__name__}: {e}"
    return ob, og, ou


def ompl_plan(mods: tuple, robot: Any, prob: Problem, margin: float,
              args: argparse.Namespace) -> dict:
    """RRT-Connect in the arm joints with jwarp's exact checks (module docstring)."""
    from jwarp.world.collision import is_collision_free
    from jwarp.world.motion import MotionCheck

    ob, og, _ = mods
    em = min(margin, args.endpoint_margin)
    names = robot.joint_names
    arm = [i for i, n in enumerate(names) if n in ARM_JOINTS]
    lim = np.asarray(robot.joint_limits, np.float64)
    q0, q1 = prob.start, prob.goal
    full = q0.copy()
    ends = (q0[arm].copy(), q1[arm].copy())
    counts = {"states": 0, "motions": 0}
    t0 = time.perf_counter()
    chk = MotionCheck(jwarp.robot(robot), prob.world, device="cpu")

    def vec(s: Any) -> np.ndarray:
        q = full.copy()
        q[arm] = [s[i] for i in range(len(arm))]
        return q

    def at_end(qa: np.ndarray) -> bool:
        return any(np.array_equal(qa[arm], e) for e in ends)

    def valid(s: Any) -> bool:
        counts["states"] += 1
        q = vec(s)
        return bool(is_collision_free(jwarp.robot(robot), q[None], prob.world, em if at_end(q) else margin,
                                      device="cpu", validate=False)[0])

    class Motion(ob.MotionValidator):
        def checkMotion(self, a: Any, b: Any, *rest: Any) -> bool:
            counts["motions"] += 1
            qa, qb = vec(a), vec(b)
            m = em if (at_end(qa) or at_end(qb)) else margin
            return bool(chk.check(np.stack([qa, qb]), margin=m, endpoint_margin=m).ok[0])

    space = ob.RealVectorStateSpace(len(arm))
    bounds = ob.RealVectorBounds(len(arm))
    for i, j in enumerate(arm):
        bounds.setLow(i, float(lim[j, 0]))
        bounds.setHigh(i, float(lim[j, 1]))
    space.setBounds(bounds)
    si = ob.SpaceInformation(space)
    si.setStateValidityChecker(valid)
    mv = Motion(si)
    si.setMotionValidator(mv)
    si.setup()
    ss = og.SimpleSetup(si)
    sts = []
    for q in (q0, q1):
        s = space.allocState()
        for i, j in enumerate(arm):
            s[i] = float(q[j])
        sts.append(s)
    ss.setStartAndGoalStates(sts[0], sts[1])
    ss.setPlanner(og.RRTConnect(si))
    left = max(1e-3, args.time_limit - (time.perf_counter() - t0))
    ss.solve(left)
    ok = bool(ss.haveExactSolutionPath())
    t = time.perf_counter() - t0
    row = {"planner": "ompl_rrtconnect", "device": "cpu", "margin": margin,
           "problem": prob.name, "family": prob.family, "solved": ok, "time_s": t,
           "state_checks": counts["states"], "motion_checks": counts["motions"]}
    if ok:
        p = ss.getSolutionPath()
        path = np.array([vec(p.getState(i)) for i in range(p.getStateCount())])
        row["waypoints"] = len(path)
        row["_path"] = path
    return row


def run_ompl(mods: tuple, robot: Any, urdf: str, spheres: list, probs: list[Problem],
             margin: float, args: argparse.Namespace) -> list[dict]:
    rows = []
    for p in probs:
        row = ompl_plan(mods, robot, p, margin, args)
        path = row.pop("_path", None)
        if path is not None and args.verify_ompl:
            row.update(verify(p.verifier(urdf, spheres, robot.joint_names), path, margin,
                              args.endpoint_margin))
        rows.append(row)
    return rows


# ------------------------------------------------------------------ printing
def pct(a: float, b: float) -> str:
    return f"{100.0 * a / b:5.1f}%" if b else "    -"


def stats(rows: list[dict]) -> dict:
    t = np.array([r["time_s"] for r in rows]) if rows else np.zeros(0)
    solved = [r for r in rows if r["solved"]]
    checked = [r for r in solved if "collision" in r]
    lr = np.array([r["length_ratio"] for r in solved if "length_ratio" in r])
    return {
        "problems": len(rows), "solved": len(solved),
        "solved_pct": 100.0 * len(solved) / len(rows) if rows else math.nan,
        "straight": sum(r.get("stage") == "straight" for r in rows),
        "optimizer": sum(r.get("stage") == "optimizer" for r in rows),
        "fallback": sum(r.get("stage") == "fallback" for r in rows),
        "errors": sum(r.get("stage") == "error" for r in rows),
        "verified": len(checked),
        "verified_free": sum(not r["collision"] for r in checked),
        "collisions": sum(r["collision"] for r in checked),
        "sphere_margin_violations": sum(r["sphere_margin_violation"] for r in checked),
        "mesh_below_margin": sum(r["mesh_below_margin"] for r in checked),
        "median_s": float(np.median(t)) if len(t) else math.nan,
        "p95_s": float(np.percentile(t, 95)) if len(t) else math.nan,
        "p98_s": float(np.percentile(t, 98)) if len(t) else math.nan,
        "mean_s": float(np.mean(t)) if len(t) else math.nan,
        "max_s": float(t.max()) if len(t) else math.nan,
        "median_solved_s": (float(np.median([r["time_s"] for r in solved]))
                            if solved else math.nan),
        "median_length_ratio": (float(np.median(lr)) if len(lr) else math.nan),
        "p95_length_ratio": (float(np.percentile(lr, 95)) if len(lr) else math.nan),
    }


HEAD = (f"{'family':<17} {'n':>4} {'solved':>7} {'line':>5} {'optim':>5} {'fallb':>5} "
        f"{'verif.free':>10} "
        f"{'coll':>4} {'m-viol':>6} {'mesh<m':>6} {'error':>5} {'mean_s':>6} {'median_s':>8} {'p95_s':>6} "
        f"{'p98_s':>6} {'max_s':>6} "
        f"{'len_med':>7} {'len_p95':>7}")


def line(name: str, s: dict) -> str:
    vf = (f"{s['verified_free']}/{s['verified']}" if s["verified"] else "-")
    return (f"{name:<17} {s['problems']:>4} {pct(s['solved'], s['problems']):>7} "
            f"{s['straight']:>5} {s['optimizer']:>5} {s['fallback']:>5} {vf:>10} "
            f"{s['collisions']:>4} "
            f"{s['sphere_margin_violations']:>6} {s['mesh_below_margin']:>6} {s['errors']:>5} "
            f"{s['mean_s']:>6.3f} {s['median_s']:>8.3f} {s['p95_s']:>6.3f} {s['p98_s']:>6.3f} "
            f"{s['max_s']:>6.3f} {s['median_length_ratio']:>7.2f} {s['p95_length_ratio']:>7.2f}")


def print_table(rows: list[dict], families: list[str]) -> dict:
    print(HEAD)
    per = {}
    for f in families:
        fr = [r for r in rows if r["family"] == f]
        if fr:
            per[f] = stats(fr)
            print(line(f, per[f]))
    per["all"] = stats(rows)
    print(line("all", per["all"]), flush=True)
    return per


def report_jwarp(rows: list[dict], families: list[str], robot: Any, dev: str, gpu: str,
                 m: float, n: int, total: float, args: argparse.Namespace, vname: str) -> dict:
    """The table of one device, margin and variant; returns its per-family figures."""
    with_v = f" [{vname}]" if vname else ""
    print(f"== jwarp{with_v} on {dev}{gpu}, margin {m:g} m, endpoint_margin "
          f"{args.endpoint_margin:g} m: {n} problems one after the other "
          f"in {total:.1f} s (incl. verification{', all variants' if args.versus else ''})")
    per = print_table(rows, families)
    mesh_s = sum(r.get("timings", {}).get("mesh_check", 0.0) for r in rows)
    plan_s = sum(r["time_s"] for r in rows)
    errors = sum(r["stage"] == "error" for r in rows)
    print(f"   {len(robot.spheres)} spheres; mesh certificate "
          f"{'on' if getattr(robot, 'collision_pieces', None) is not None else 'off'}: "
          f"{mesh_s:.2f} s of {plan_s:.2f} s planning ({100 * mesh_s / max(plan_s, 1e-9):.1f} %)"
          f"; planner errors (e.g. endpoints refused) {errors}")
    return per


# ------------------------------------------------------------------ main
def git_head() -> str:
    """The checkout's commit (and '+changes' where jwarp/ has uncommitted edits)."""
    import subprocess

    try:
        head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT,
                              capture_output=True, text=True, timeout=10).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--", "jwarp"], cwd=ROOT,
                               capture_output=True, text=True, timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return (head or "unknown") + ("+changes" if dirty else "")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--problems", default=None, metavar="DIR",
                    help="read this problem set (index.json) instead of generating one")
    ap.add_argument("--per-family", type=int, default=None,
                    help="problems per family to generate (100; --quick: 3)")
    ap.add_argument("--seed", type=int, default=0, help="generator seed (0)")
    ap.add_argument("--families", default=None,
                    help=f"comma-separated subset ({','.join(SP.FAMILIES)})")
    ap.add_argument("--out", default=None, metavar="DIR",
                    help="keep the generated problems here (default: a temporary folder)")
    ap.add_argument("--quick", action="store_true", help="3 problems per family (smoke test)")
    ap.add_argument("--device", default="cpu", choices=["cpu", "cuda", "all"],
                    help="cpu (one core; default), cuda (where present) or all")
    ap.add_argument("--margins", default="0,0.01", help="comma-separated margins [m] (0,0.01)")
    ap.add_argument("--endpoint-margin", type=float, default=0.0,
                    help="clearance [m] of the first/last segment (0: grasp poses stay plannable)")
    ap.add_argument("--time-limit", type=float, default=1.0, help="seconds per problem (1)")
    ap.add_argument("--no-stop-when-solved", action="store_true",
                    help="PlanOptions(stop_when_solved=False): every start optimised")
    ap.add_argument("--option", action="append", metavar="NAME=JSON",
                    help="another PlanOptions field, e.g. --option shorten=0 (repeatable)")
    ap.add_argument("--versus", action="append", metavar="NAME=JSON[;NAME=JSON]",
                    help="also plan every problem with these PlanOptions fields over the "
                         "others, in turn with the plain options (a table each; repeatable)")
    ap.add_argument("--no-ompl", action="store_true", help="skip the OMPL baseline")
    ap.add_argument("--verify-ompl", action="store_true",
                    help="also re-check OMPL's paths with the verifier")
    ap.add_argument("--no-verify", action="store_true", help="skip the verifier")
    ap.add_argument("--save-failures", default=os.path.join(tempfile.gettempdir(),
                                                            "bench_scenes_failures"),
                    metavar="DIR", help="where verifier-refuted paths are saved")
    ap.add_argument("--progress", action="store_true", help="a line per problem on stderr")
    ap.add_argument("--json", default=None, metavar="FILE", help="also write every row as JSON")
    ap.add_argument("--no-verify-self", action="store_true",
                    help="the verifier skips the self pairs' URDF meshes")
    ap.add_argument("--robot", default=None, metavar="JSON",
                    help="the arm's robot file (default, Panda only: fitted from the URDF)")
    ap.add_argument("--save-paths", default=None, metavar="DIR",
                    help="save every feasible path (DIR/<device>_m<margin>/<problem>.npy)")
    ap.add_argument("--verify-saved", default=None, metavar="DIR",
                    help="only verify the paths saved by --save-paths (needs --problems)")
    args = ap.parse_args(argv)
    if args.per_family is None:
        args.per_family = 3 if args.quick else 100
    if args.per_family < 1:
        ap.error("--per-family: expected >= 1")
    margins = [float(m) for m in args.margins.split(",") if m.strip()]

    init_warp()
    devices = []
    if args.device in ("cpu", "all"):
        devices.append("cpu")
    cuda_note = None
    if args.device in ("cuda", "all"):
        if wp.get_cuda_device_count() > 0:
            devices.append("cuda:0")
        else:
            cuda_note = "CUDA not available: the GPU part is skipped"
    elapsed = timing.stopwatch()
    print(f"machine: {timing.machine('cpu')}; warp {wp.config.version}; "
          f"BLAS threads {os.environ.get('OPENBLAS_NUM_THREADS')}; load average "
          f"{os.getloadavg()[0]:.2f}; jwarp at git {git_head()}")
    given = read_index(args)
    arm = given.get("robot", "panda") if given is not None else "panda"
    try:
        spec = SP.arm_spec(arm)
        robot, urdf = SP.load_robot(args.robot, arm)
    except ValueError as e:
        raise SystemExit(f"--robot: {e}") from None
    missing = [n for n in spec.joints if n not in robot.joint_names]
    if missing:
        raise SystemExit(f"--robot: {args.robot} is no {arm} (the problem set's robot): "
                         f"it lacks the joints {missing}")
    ARM_JOINTS[:] = spec.joints
    if (urdf is None or PathVerifier is None) and not (args.no_verify and args.no_ompl):
        raise SystemExit("--robot without example-robot-data: add --no-verify --no-ompl "
                         "(and verify elsewhere with --save-paths / --verify-saved)")
    spheres = robot_spheres(robot) if PathVerifier is not None else []
    cp = getattr(robot, "collision_pieces", None)
    PROMISE[0] = "meshes" if cp is not None and cp.extra_spheres(robot) is not None else "spheres"
    print(f"promise: the {PROMISE[0]} keep the margin ('coll' counts URDF-mesh collisions"
          + (", and sphere collisions" if PROMISE[0] == "spheres" else
             "; the spheres may touch where the mesh certificate proves the meshes clear")
          + "; 'm-viol' the promised geometry below the margin)")
    if PathVerifier is not None and urdf is not None and not args.no_verify_self:
        SELF_PAIRS[:] = self_link_pairs(robot, urdf)
    folder, index = load_problems(args)
    probs = [Problem(folder, e, robot) for e in index["problems"]]
    if not probs:
        print("no problems", file=sys.stderr)
        return 1
    families = [f for f in SP.FAMILIES if any(p.family == f for p in probs)]
    if args.verify_saved:
        return 1 if verify_saved(args, robot, urdf, spheres, probs, margins) else 0
    mods = None if args.no_ompl else ompl_modules()
    if isinstance(mods, tuple):
        try:
            mods[2].setLogLevel(mods[2].LOG_WARN)
        except Exception:  # noqa: BLE001 - quieter logs only
            pass

    print(f"problems: {len(probs)} ({', '.join(families)}) from {folder}; robot {arm}, "
          f"{len(robot.spheres)} spheres; world: exact primitives (no grid)")
    near = near_goals(index)
    if near is not None:
        print(f"goals near an object (the URDF meshes within 1 cm, the index's clearance): "
              f"{near[0]} of {near[1]}; within 2 cm: {near[2]}")
    print(f"jwarp PlanOptions: margins {margins} m, endpoint_margin {args.endpoint_margin:g} m, "
          f"time_limit {args.time_limit:g} s, stop_when_solved={not args.no_stop_when_solved}, "
          f"fallback rrt, {extra_options(args)}; time = "
          f"Planner construction + plan(), after one untimed warm-up call")
    print("verifier: URDF meshes + robot spheres vs exact primitives (coal), <= 0.5 deg "
          "steps; first/last segment at endpoint_margin, inner at margin")
    if cuda_note:
        print(cuda_note)
    if isinstance(mods, str):
        print(f"OMPL baseline skipped: cannot import ompl ({mods}); pip install ompl")
    print(flush=True)

    result: dict = {"machine": timing.machine("cpu"), "warp": wp.config.version, "robot": arm,
                    "git": git_head(),
                    "problems_dir": str(folder), "n_problems": len(probs),
                    "families": families, "margins": margins,
                    "endpoint_margin": args.endpoint_margin, "time_limit_s": args.time_limit,
                    "seed": index.get("seed"), "summary": [], "rows": []}
    summary = []
    for dev in devices:
        gpu = "" if dev == "cpu" else f" ({timing.machine(dev)})"
        for m in margins:
            all_rows, total = run_jwarp(robot, urdf, spheres, probs, m, args, dev)
            result["rows"] += all_rows
            for vname, _ in variants(args):
                rows = [r for r in all_rows if r["variant"] == vname]
                per = report_jwarp(rows, families, robot, dev, gpu, m, len(probs), total,
                                   args, vname)
                summary.append({"planner": "jwarp" + (f" [{vname}]" if vname else ""),
                                "device": dev, "margin": m, "total_wall_s": total,
                                "per_family": per, **per["all"]})
                print()
    if isinstance(mods, tuple):
        for m in margins:
            rows = run_ompl(mods, robot, urdf, spheres, probs, m, args)
            s = stats(rows)
            print(f"== OMPL RRT-Connect (jwarp exact checks, cpu), margin {m:g} m: solved "
                  f"{s['solved']}/{s['problems']} ({pct(s['solved'], s['problems']).strip()}), "
                  f"time median {s['median_s']:.3f} s, p95 {s['p95_s']:.3f} s, max "
                  f"{s['max_s']:.3f} s; median of the solved {s['median_solved_s']:.3f} s; "
                  f"checks per problem (median): "
                  f"{np.median([r['state_checks'] for r in rows]):.0f} states, "
                  f"{np.median([r['motion_checks'] for r in rows]):.0f} motions", flush=True)
            if args.verify_ompl:
                print(f"   verified collision-free {s['verified_free']}/{s['verified']}, "
                      f"collisions {s['collisions']}")
            result["rows"] += rows
            summary.append({"planner": "ompl_rrtconnect", "device": "cpu", "margin": m, **s})
        print()
    print("summary")
    print(f"{'planner':<16} {'device':<7} {'margin':>6} {'problems':>8} {'solved':>7} "
          f"{'verif.free':>10} {'coll':>4} {'median_s':>8} {'p95_s':>6} {'max_s':>6} "
          f"{'len_med':>7} {'len_p95':>7}")
    for s in summary:
        vf = f"{s['verified_free']}/{s['verified']}" if s["verified"] else "-"
        print(f"{s['planner']:<16} {s['device']:<7} {s['margin']:>6g} {s['problems']:>8} "
              f"{pct(s['solved'], s['problems']):>7} {vf:>10} {s['collisions']:>4} "
              f"{s['median_s']:>8.3f} {s['p95_s']:>6.3f} {s['max_s']:>6.3f} "
              f"{s.get('median_length_ratio', math.nan):>7.2f} "
              f"{s.get('p95_length_ratio', math.nan):>7.2f}")
    coll = sum(s["collisions"] for s in summary if s["planner"] == "jwarp")
    print(f"verifier collisions among jwarp's feasible paths: {coll} (must be 0); "
          f"wall time {elapsed():.0f} s; load average {os.getloadavg()[0]:.2f}", flush=True)
    result["summary"] = summary
    result["jwarp_collisions"] = coll
    if args.json:
        from jwarp.utils.atomic import atomic_write_text

        atomic_write_text(args.json, json.dumps(result, indent=1, default=str) + "\n")
    sys.stdout.flush()
    sys.stderr.flush()
    if isinstance(mods, tuple):
        # nanobind (OMPL) prints reference-leak reports at interpreter exit: skip that
        # teardown (everything is written and flushed)
        os._exit(0)
    return 0


if __name__ == "__main__":
    sys.exit(main())
