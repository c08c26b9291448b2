#!/usr/bin/env python
"""Collision spheres of the Panda (example-robot-data's collision meshes) and self-collision
pairs: spheres per link, one-sided error, excess volume, fit time.

    python benchmarks/bench_spheres.py                 # all Panda links, 3 tolerances
    python benchmarks/bench_spheres.py --quick         # smoke-test sizes

Sections (``--only`` picks some):

* ``panda``: :func:`jwarp.importers.spheres.fit_spheres` on each collision mesh
  (``meshes/collision/*.stl`` of ``panda_description``) at each of ``--tolerances`` [m]
  (default options: automatic sample count, 200k Monte Carlo points for the excess volume).
  Per link: spheres k, the fit's own one-sided error and an independent check on 50 000
  fresh surface samples (another seed) [mm], the excess volume [cm^3] +- one standard error
  and as a fraction of the mesh volume, the fit time [s] (min/median over ``--repeats``
  fits with seeds 0, 1, ...; k and the errors are those of seed 0). Also printed as a
  table.
* ``pairs``: :func:`jwarp.world.self_pairs.never_colliding_pairs` on justin19 with
  ``--pair-samples`` configurations: seconds (min/median), and the counts of adjacent,
  never-, always-colliding and kept frame pairs.
"""

import argparse
import importlib.metadata
import os
import sys
from pathlib import Path

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np
import trimesh
import warp as wp

wp.config.quiet = True

from jwarp.core.arrays import init_warp
from jwarp.importers.spheres import fit_spheres, load_mesh, one_sided_error
from jwarp.registry import robot as get_robot
from jwarp.world.self_pairs import never_colliding_pairs

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))  # also when imported by path
import timing


def panda_meshes() -> list[Path]:
    """The Panda's collision STL files of example-robot-data (empty if not installed)."""
    try:
        dist = importlib.metadata.distribution("example-robot-data")
    except importlib.metadata.PackageNotFoundError:
        return []
    root = Path(dist.locate_file("cmeel.prefix/share/example-robot-data/robots/panda_description"))
    return sorted((root / "meshes" / "collision").glob("*.stl"))


def panda(args) -> dict:
    files = panda_meshes()
    if args.quick:
        files = [f for f in files if f.stem in ("link0", "finger")]
    if not files:
        return {"skipped": "example-robot-data (Panda meshes) not installed"}
    out: dict = {"tolerances_m": args.tolerances, "repeats": args.repeats, "links": []}
    for tol in args.tolerances:
        for path in files:
            mesh = load_mesh(path)
            runs = timing.each_run([lambda r: (lambda: fit_spheres(mesh, tolerance=tol,
                                                                   seed=max(r - 1, 0)))],
                                   args.repeats)[0]
            fit = runs.results[0]
            check, _ = trimesh.sample.sample_surface(mesh, 50_000, seed=424242)
            err = float(one_sided_error(check, fit.centres, fit.radii).max())
            t = timing.summarize(runs.seconds)
            out["links"].append({
                "link": path.stem, "tolerance_mm": tol * 1e3, "spheres": fit.k,
                "one_sided_error_mm": fit.one_sided_error * 1e3,
                "fresh_check_error_mm": err * 1e3, "meets_tolerance": bool(err <= tol),
                "excess_cm3": fit.excess_volume * 1e6,
                "excess_stderr_cm3": fit.excess_volume_stderr * 1e6,
                "excess_fraction": fit.excess_fraction, "mesh_volume_cm3": fit.mesh_volume * 1e6,
                "surface_samples": fit.n_surface, "fit_s": t.figures()})
    print("| tol [mm] | link | spheres | error [mm] (fit / fresh 50k) | excess [cm^3] | "
          "excess / volume | fit [s] min / median |")
    print("|---|---|---|---|---|---|---|")
    for r in out["links"]:
        print(f"| {r['tolerance_mm']:.0f} | {r['link']} | {r['spheres']} | "
              f"{r['one_sided_error_mm']:.2f} / {r['fresh_check_error_mm']:.2f} | "
              f"{r['excess_cm3']:.1f} +- {r['excess_stderr_cm3']:.1f} | "
              f"{r['excess_fraction']:.2f} | {r['fit_s']['min']:.2f} / {r['fit_s']['median']:.2f} |")
    for tol in args.tolerances:
        rows = [r for r in out["links"] if r["tolerance_mm"] == tol * 1e3]
        print(f"tolerance {tol * 1e3:.0f} mm: {sum(r['spheres'] for r in rows)} spheres on "
              f"{len(rows)} links, all covered: {all(r['meets_tolerance'] for r in rows)}")
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
    p.add_argument("--tolerances", default="0.005,0.01,0.02", help="metres, comma-separated")
    p.add_argument("--pair-samples", type=int, default=10000, help="configurations (pairs)")
    p.add_argument("--repeats", type=int, default=3, help="runs (min/median)")
    timing.section_options(p, "panda,pairs")
    args = p.parse_args(argv)
    init_warp()
    if args.quick:
        args.tolerances, args.pair_samples, args.repeats = "0.02", 200, 2
    args.tolerances = [float(v) for v in str(args.tolerances).split(",")]
    timing.run_sections(p, {"panda": panda, "pairs": pairs}, args,
                        f"{args.repeats} runs, min/median", repeats=args.repeats)
    return 0


if __name__ == "__main__":
    sys.exit(main())
