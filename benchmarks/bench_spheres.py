#!/usr/bin/env python
"""Collision spheres of imported robots (example-robot-data: Panda, UR10, TALOS left arm)
and self-collision pairs: spheres, one-sided error, excess, largest protrusion, fit time
and peak memory per robot.

    python benchmarks/bench_spheres.py                 # panda, ur10, talos arm; pairs
    python benchmarks/bench_spheres.py --quick         # the Panda only, few pair samples,
                                                       # 10 000 / 50 000 check samples

Sections (``--only`` picks some):

* ``robots``: :func:`jwarp.world.spherize.spherize` (the default
  :class:`~jwarp.world.spherize.SpherizeOptions` unless ``--tolerance``/``--protrusion``/
  ``--max-spheres`` are given; no disk cache) of each URDF in ``--robots``, each in its
  own process (one core: BLAS threads 1), timed (fit + self pairs) with its peak resident
  memory (``ru_maxrss`` of that process). Per link, measured here independently of the
  fit's own report: the one-sided error on 50 000 fresh samples of the link's geometry
  (posed in the link frame, union of all its geometries; samples buried inside another
  body dropped), the largest protrusion (:func:`~jwarp.importers.spheres.sphere_protrusion`
  against the link's solid) and the excess volume / solid volume
  (:func:`~jwarp.importers.spheres.excess_volume`, 200 000 points). Rows are grouped
  (Panda: arm links, hand, fingers); the fit's own warnings are printed.
* ``pairs``: :func:`jwarp.world.self_pairs.never_colliding_pairs` on justin19 with
  ``--pair-samples`` configurations: seconds (min/median), and the counts of adjacent,
  never-, always-colliding and kept frame pairs.
"""

import argparse
import multiprocessing as mp
import os
import resource
import sys
import time
import warnings

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np
import trimesh
import warp as wp

wp.config.quiet = True

from jwarp.core.arrays import init_warp
from jwarp.plugins.registry import robot as get_robot
from jwarp.world.self_pairs import never_colliding_pairs

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))  # also when imported by path
import timing

ROBOTS = {"panda": "panda_description/urdf/panda.urdf",
          "ur10": "ur_description/urdf/ur10_robot.urdf",
          "talos_arm": "talos_data/robots/talos_left_arm.urdf"}


def group(robot: str, link: str) -> str:
    if robot == "panda":
        return "fingers" if "finger" in link else "hand" if "hand" in link else "arm"
    if robot == "talos_arm":
        return "gripper" if "gripper" in link else "arm"
    return "arm"


def link_mesh(geoms) -> trimesh.Trimesh:
    """The union (as one mesh) of a link's non-sphere geometries, posed in the link frame."""
    from jwarp.importers.spheres import load_mesh, primitive_mesh

    parts = []
    for g in geoms:
        m = (load_mesh(g.mesh_file(), g.scale) if g.kind == "mesh"
             else primitive_mesh(g.kind, g.size)).copy()
        m.apply_transform(np.asarray(g.origin, float))
        parts.append(m)
    return parts[0] if len(parts) == 1 else trimesh.util.concatenate(parts)


#: fresh surface samples of the one-sided error and points of the volumes per link (the
#: module docstring's 50 000 and 200 000); ``--quick``: QUICK_SAMPLES
SAMPLES = (50_000, 200_000)
QUICK_SAMPLES = (10_000, 50_000)


def measure_links(name: str, path: str, model, fit_rows: dict,
                  samples: tuple = SAMPLES) -> list[dict]:
    """Independent per-link figures of a fitted model (module docstring); ``samples``:
    (surface samples, volume points) per link."""
    from jwarp.importers.robot import load_urdf
    from jwarp.importers.spheres import (
        excess_volume,
        one_sided_error,
        signed_distance,
        sphere_protrusion,
    )

    by_link: dict = {}
    for g in load_urdf(path).geometries:
        if g.kind != "sphere":
            by_link.setdefault(g.link, []).append(g)
    rows = []
    for link, geoms in by_link.items():
        mesh = link_mesh(geoms)
        f = model.frame_index(link)
        c = np.array([s.position for s in model.spheres if s.frame == f]).reshape(-1, 3)
        r = np.array([s.radius for s in model.spheres if s.frame == f])
        pts, face = trimesh.sample.sample_surface(mesh, samples[0], seed=424242)
        nrm = mesh.face_normals[face]
        h = 1e-3 * float(np.linalg.norm(mesh.extents))
        buried = (signed_distance(mesh, pts + h * nrm) < 0) & (signed_distance(mesh, pts - h * nrm) < 0)
        err = float(one_sided_error(pts[~buried], c, r).max()) if len(r) else float("inf")
        prot = float(sphere_protrusion(mesh, c, r).max()) if len(r) else 0.0
        exc, _, _ = excess_volume(mesh, c, r, n=samples[1], seed=7)
        lo, hi = mesh.bounds
        x = lo + np.random.default_rng(8).random((samples[1], 3)) * (hi - lo)
        vol = float(np.prod(hi - lo)) * float((signed_distance(mesh, x) < 0).mean())
        rows.append({"robot": name, "link": link, "group": group(name, link), "spheres": len(r),
                     "one_sided_error_mm": err * 1e3, "max_protrusion_mm": prot * 1e3,
                     "excess_cm3": exc * 1e6, "solid_volume_cm3": vol * 1e6,
                     "excess_fraction": exc / vol if vol > 0 else float("inf"),
                     "watertight": bool(mesh.is_watertight),
                     "fit_report": fit_rows.get(link, {})})
    return rows


def _one_robot(name: str, options: dict, queue, samples: tuple = SAMPLES) -> None:
    """Fit one robot in this (fresh) process: time, peak memory, per-link figures."""
    init_warp()
    from jwarp.importers.robot import example_robot_urdf, load_urdf
    from jwarp.world.spherize import SpherizeOptions, spherize

    path = example_robot_urdf(ROBOTS[name])
    imported = load_urdf(path)
    base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    t = time.perf_counter()
    with warnings.catch_warnings(record=True):
        warnings.simplefilter("always")
        model, rep = spherize(imported, SpherizeOptions(**options))
    seconds = time.perf_counter() - t
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    rows = measure_links(name, str(path), model, {r["link"]: r for r in rep.links}, samples)
    queue.put({"robot": name, "spheres": len(model.spheres), "seconds": seconds,
               "peak_rss_mb": peak / 1024, "rss_before_fit_mb": base / 1024,
               "warnings": rep.warnings, "links": rows,
               "fit_rows": rep.links})


def robots(args) -> dict:
    try:
        from jwarp.importers.robot import example_robot_urdf
        example_robot_urdf(ROBOTS["panda"])
    except ValueError as e:
        return {"skipped": f"example-robot-data not installed ({e})"}
    options = {"pair_samples": args.pair_samples}
    for key in ("tolerance", "protrusion", "max_spheres"):
        if getattr(args, key) is not None:
            options[key] = getattr(args, key)
    names = ["panda"] if args.quick else [n.strip() for n in args.robots.split(",")]
    out: dict = {"options": options, "robots": []}
    ctx = mp.get_context("spawn")
    for name in names:
        q = ctx.Queue()
        p = ctx.Process(target=_one_robot, args=(name, options, q,
                                                 QUICK_SAMPLES if args.quick else SAMPLES))
        p.start()
        res = q.get()
        p.join()
        out["robots"].append(res)
    print("| robot | group | links | spheres | one-sided error max [mm] | protrusion max [mm] "
          "| excess / volume (max) |")
    print("|---|---|---|---|---|---|---|")
    for res in out["robots"]:
        groups: dict = {}
        for r in res["links"]:
            groups.setdefault(r["group"], []).append(r)
        for g, rows in groups.items():
            print(f"| {res['robot']} | {g} | {len(rows)} | {sum(r['spheres'] for r in rows)} | "
                  f"{max(r['one_sided_error_mm'] for r in rows):.2f} | "
                  f"{max(r['max_protrusion_mm'] for r in rows):.2f} | "
                  f"{max(r['excess_fraction'] for r in rows):.2f} |")
    for res in out["robots"]:
        print(f"{res['robot']}: {res['spheres']} spheres, fit + self pairs "
              f"{res['seconds']:.1f} s, peak memory {res['peak_rss_mb']:.0f} MB"
              + "".join(f"\n  warning: {w}" for w in res["warnings"]))
        for r in res["links"]:
            print(f"  {r['link']:32s} {r['spheres']:3d} spheres  err {r['one_sided_error_mm']:5.2f} mm"
                  f"  protrusion {r['max_protrusion_mm']:5.2f} mm  excess {r['excess_fraction']:.2f}"
                  f"{'' if r['watertight'] else '  (open mesh)'}")
    return out


def pairs(args) -> dict:
    robot = get_robot("justin19")
    runs = timing.each_run([lambda r: (lambda: never_colliding_pairs(robot, args.pair_samples,
                                                                     seed=r))], args.repeats)[0]
    p = runs.results[0]
    tested = {(a, b) for a in range(robot.n_frames) for b in range(a + 1, robot.n_frames)
              if np.isfinite(p.min_distance[a, b])}
    return {"robot": "justin19", "samples": args.pair_samples,
            "seconds": timing.summarize(runs.seconds).figures(),
            "adjacent": len(p.adjacent), "never_colliding": len(p.never_colliding),
            "always_colliding": len(p.always_colliding),
            "kept": len(tested - set(p.exclude_pairs))}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--device", default="cpu", help="cpu only (the fit runs on the host)")
    p.add_argument("--robots", default=",".join(ROBOTS), help="comma-separated: "
                   + ", ".join(ROBOTS))
    p.add_argument("--tolerance", type=float, default=None, help="[m] (default 0.01)")
    p.add_argument("--protrusion", type=float, default=None, help="[m] (default automatic)")
    p.add_argument("--max-spheres", type=int, default=None, help="per link (default none)")
    p.add_argument("--pair-samples", type=int, default=10000, help="configurations (pairs)")
    p.add_argument("--repeats", type=int, default=3, help="runs of the pairs section")
    timing.section_options(p, "robots,pairs")
    args = p.parse_args(argv)
    init_warp()
    if args.quick:
        args.pair_samples, args.repeats = 200, 2
    timing.run_sections(p, {"robots": robots, "pairs": pairs}, args,
                        "robots: one run each in its own process; pairs: "
                        f"{args.repeats} runs, min/median", repeats=args.repeats)
    return 0


if __name__ == "__main__":
    sys.exit(main())
