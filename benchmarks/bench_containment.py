#!/usr/bin/env python
"""Do a robot file's spheres contain its URDF collision meshes? (a script printing figures,
never a timed test; issue 42)

    python benchmarks/bench_containment.py panda_old.json panda_new.json
    python benchmarks/bench_containment.py --urdf example-robot-data:panda --samples 200000 x.json

For every robot JSON and every link with collision geometry (the URDF's, posed in the
link frame by ``jwarp.importers.spheres.link_part``): ``--samples`` fresh area-uniform
surface points (trimesh, ``--seed``, a stream the fit never used) plus the mesh's vertices,
and numpy's distance of each outside the link's spheres (``min_i |x - c_i| - r_i``). Printed
per link: spheres, the largest poke-out found, the relation's recorded poke-out bound and
protrusion, and the totals. Independent of the fit's own certificate (which tests
``jwarp.importers.spheres.surface_cover`` points held ``gap`` deep).
"""

from __future__ import annotations

import argparse
import sys

import numpy as np


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("robots", nargs="+", metavar="ROBOT.json")
    ap.add_argument("--urdf", default="example-robot-data:panda",
                    help="the URDF the robots were imported from (example-robot-data:panda)")
    ap.add_argument("--samples", type=int, default=200_000,
                    help="fresh surface samples per link (200000)")
    ap.add_argument("--seed", type=int, default=20261202, help="sample seed")
    args = ap.parse_args(argv)

    import trimesh

    import jwarp
    from jwarp.importers.robot import load_urdf, package_robot_path
    from jwarp.importers.spheres import link_part
    from jwarp.world.spherize import _geometry

    urdf = package_robot_path(args.urdf) or args.urdf
    imported = load_urdf(urdf)
    by_link: dict[str, list] = {}
    for g in imported.geometries:
        if g.kind != "sphere":
            by_link.setdefault(g.link, []).append(g)
    parts = {k: link_part([_geometry(g) for g in v])[0] for k, v in by_link.items()}
    for path in args.robots:
        model = jwarp.robot(path)
        rel = model.sphere_relation
        f, p, r = model.sphere_arrays()
        print(f"\n{path}: {len(model.spheres)} spheres; relation "
              f"{'unknown' if rel is None else rel.kind}")
        print(f"{'link':20s} {'spheres':>7s} {'poke-out found [mm]':>20s} "
              f"{'recorded bound [mm]':>20s} {'protrusion [mm]':>16s}")
        worst = 0.0
        for k, mesh in parts.items():
            if mesh is None:
                continue
            sel = f == model.frame_index(k)
            x, _ = trimesh.sample.sample_surface(mesh, args.samples, seed=args.seed)
            x = np.concatenate([np.asarray(x), np.asarray(mesh.vertices)])
            out = np.full(len(x), np.inf)
            for s in range(0, len(x), 20000):
                d = np.linalg.norm(x[s:s + 20000, None] - p[sel][None], axis=-1) - r[sel][None]
                out[s:s + 20000] = d.min(axis=1)
            found = max(float(out.max()), 0.0)
            worst = max(worst, found)
            rec = "-" if rel is None else f"{rel.link_poke_out(k) * 1e3:.2f}"
            prot = "-" if rel is None else f"{rel.protrusion.get(k, float('nan')) * 1e3:.2f}"
            print(f"{k:20s} {int(sel.sum()):7d} {found * 1e3:20.2f} {rec:>20s} {prot:>16s}")
        print(f"{'all':20s} {len(model.spheres):7d} {worst * 1e3:20.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
