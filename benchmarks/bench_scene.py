#!/usr/bin/env python
"""Scenes: the cost of building a scene's SDF grid, and exact primitive distances against
the grid's trilinear lookup per query point (the question of docs/scenes.md: are the
primitives' exact distances cheaper than the grid in the collision check?).

    python benchmarks/bench_scene.py                 # CPU (one thread: Warp CPU kernels)
    python benchmarks/bench_scene.py --device cuda
    python benchmarks/bench_scene.py --quick         # smoke-test sizes

Sections:

* ``build``: :func:`jwarp.world.scene_file.scene_world` of the table-and-shelf scene
  (examples/scenes/table_shelf.yaml, 14 boxes and cylinders) at 2 cm and 1 cm voxels
  (numpy, float64; one call per run).
* ``query``: distance of N random points in the scene's grid box, float32, one Warp launch
  on preallocated arrays: the collision kernels' grid lookup (``sdf_query``: 8 reads and
  trilinear weights, with the gradient) against an exact kernel written here (a loop over
  the K shapes: box, sphere, cylinder, capsule closed forms, distance only), and the
  exact kernel on the scene repeated to 2K and 4K shapes (the exact cost grows with K,
  the grid's does not). The exact kernel is checked against numpy's
  :meth:`Scene.distance` (max abs difference printed).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import warp as wp

wp.config.quiet = True
sys.path.insert(0, str(Path(__file__).resolve().parent))

import timing  # noqa: E402

from jwarp.core.arrays import init_warp, resolve_device  # noqa: E402
from jwarp.kernels import collision as ck  # noqa: E402
from jwarp.world.scene_file import SceneOptions, scene_from_dict, scene_world, table_shelf_scene  # noqa: E402

KIND = {"box": 0, "sphere": 1, "cylinder": 2, "capsule": 3}


@wp.kernel
def exact_distance_kernel(points: wp.array(dtype=wp.vec3), kind: wp.array(dtype=int),
                          rot_t: wp.array(dtype=wp.mat33), trans: wp.array(dtype=wp.vec3),
                          dims: wp.array(dtype=wp.vec3), dist: wp.array(dtype=float)):
    """dist[p] = min over shapes of the exact signed distance of points[p] [m]."""
    p = wp.tid()
    x = points[p]
    best = float(1.0e30)
    for s in range(kind.shape[0]):
        q = rot_t[s] * (x - trans[s])          # into the shape's frame
        a = dims[s]
        k = kind[s]
        d = float(0.0)
        if k == 0:                              # box: a = half sizes
            e = wp.vec3(wp.abs(q[0]) - a[0], wp.abs(q[1]) - a[1], wp.abs(q[2]) - a[2])
            o = wp.vec3(wp.max(e[0], 0.0), wp.max(e[1], 0.0), wp.max(e[2], 0.0))
            d = wp.length(o) + wp.min(wp.max(e[0], wp.max(e[1], e[2])), 0.0)
        elif k == 1:                            # sphere: a[0] = radius
            d = wp.length(q) - a[0]
        elif k == 2:                            # cylinder: a = (half length, radius)
            dr = wp.sqrt(q[0] * q[0] + q[1] * q[1]) - a[1]
            dz = wp.abs(q[2]) - a[0]
            mr = wp.max(dr, 0.0)
            mz = wp.max(dz, 0.0)
            d = wp.sqrt(mr * mr + mz * mz) + wp.min(wp.max(dr, dz), 0.0)
        else:                                   # capsule: a = (half length, radius)
            z = wp.clamp(q[2], -a[0], a[0])
            d = wp.length(wp.vec3(q[0], q[1], q[2] - z)) - a[1]
        best = wp.min(best, d)
    dist[p] = best


def shape_tables(scene, device):
    kind, rt, tr, dims = [], [], [], []
    for s in scene.shapes:
        kind.append(KIND[s.kind])
        rt.append(s.pose[:3, :3].T)
        tr.append(s.pose[:3, 3])
        a = s.dims
        dims.append(0.5 * a if s.kind == "box" else (a[0], 0, 0) if s.kind == "sphere"
                    else (0.5 * a[0], a[1], 0))
    return (wp.array(np.array(kind, np.int32), dtype=int, device=device),
            wp.array(np.array(rt, np.float32), dtype=wp.mat33, device=device),
            wp.array(np.array(tr, np.float32), dtype=wp.vec3, device=device),
            wp.array(np.array(dims, np.float32), dtype=wp.vec3, device=device))


def build(args):
    scene = scene_from_dict(table_shelf_scene())
    out = {"shapes": len(scene.shapes)}
    for h in ((0.04,) if args.quick else (0.02, 0.01)):
        runs = timing.each_run([lambda r, h=h: (lambda: scene_world(scene, SceneOptions(h)))],
                               rounds=args.repeats)
        w = runs[0].results[-1]
        out[f"voxel_{h:g}"] = {"grid": list(w.shape), "cells": int(w.sdf.size),
                               "build_s": runs[0].timing.figures()}
    return out


def query(args):
    dev = resolve_device(args.device)
    init_warp()
    scene = scene_from_dict(table_shelf_scene())
    world = scene_world(scene, SceneOptions(0.02)).astype(np.float32)
    n = 2_000 if args.quick else (100_000 if dev.is_cpu else 4_000_000)
    rng = np.random.default_rng(0)
    lo, hi = world.limits[:, 0], world.limits[:, 1]
    pts_np = (lo + rng.random((n, 3)) * (hi - lo)).astype(np.float32)
    pts = wp.array(pts_np, dtype=wp.vec3, device=dev)
    k = ck.kernels(wp.float32)
    grid = wp.array(np.ascontiguousarray(world.sdf), dtype=wp.float32, device=dev)
    dist = wp.empty(n, dtype=wp.float32, device=dev)
    grad = wp.empty(n, dtype=wp.vec3, device=dev)
    origin = wp.vec3(*lo.astype(np.float32))
    inv_h = 1.0 / world.voxel_size

    def grid_lookup():
        wp.launch(k.sdf_query, dim=n, inputs=[pts, grid, origin, inv_h, 3],
                  outputs=[dist, grad], device=dev)

    tables = {}
    for rep in (1, 2, 4):
        big = scene_from_dict(table_shelf_scene())
        big.shapes = scene.shapes * rep
        tables[rep] = shape_tables(big, dev)
    exact_out = wp.empty(n, dtype=float, device=dev)

    def exact(rep):
        return lambda: wp.launch(exact_distance_kernel, dim=n, inputs=[pts, *tables[rep]],
                                 outputs=[exact_out], device=dev)

    exact(1)()
    check = float(np.abs(exact_out.numpy() - scene.distance(pts_np.astype(np.float64))).max())
    grid_lookup()
    gap = float(np.abs(dist.numpy() - scene.distance(pts_np.astype(np.float64))).max())
    fns = [grid_lookup, exact(1), exact(2), exact(4)]
    t = timing.side_by_side(fns, device=dev, min_time=0.02 if args.quick else 0.2,
                            rounds=args.repeats)
    K = len(scene.shapes)
    names = ["grid_trilinear", f"exact_{K}_shapes", f"exact_{2 * K}_shapes",
             f"exact_{4 * K}_shapes"]
    per_point = {name: ti.figures(1e9 / n) for name, ti in zip(names, t)}
    return {"points": n, "shapes": K, "voxel": world.voxel_size,
            "ns_per_point": per_point,
            "exact_over_grid_median": {name: per_point[name]["median"] /
                                       per_point["grid_trilinear"]["median"] for name in names[1:]},
            "check_exact_kernel_vs_numpy_max_abs_m": check,
            "grid_lookup_vs_exact_max_abs_m": gap}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--device", default="cpu")
    p.add_argument("--repeats", type=int, default=5)
    timing.section_options(p, "build,query")
    args = p.parse_args()
    if args.quick:
        args.repeats = 2
    timing.run_sections(p, {"build": build, "query": query}, args,
                        "scene SDF build and exact-vs-grid distance queries")


if __name__ == "__main__":
    main()
