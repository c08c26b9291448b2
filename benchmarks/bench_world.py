#!/usr/bin/env python
"""Exact worlds (jwarp.world.shapes, jwarp.kernels.geometry) and the continuous path check
(jwarp.world.motion): what a user's scene costs.

    python benchmarks/bench_world.py                 # CPU, one thread
    python benchmarks/bench_world.py --device cuda   # on a GPU
    python benchmarks/bench_world.py --quick

Printed (min / median over repeats, the machine named):

* build: a 20-object scene (boxes, cylinders, spheres) from scratch through the public API
  (``World.of_shapes`` + ``add``) and its device copy (the BVH), ready for a query;
* move: 50 objects moved in place (``World.move``) and brought to the device (refit);
* query: signed distance + gradient of 100,000 points, exact (BVH broad phase) against the
  grid of the same scene (``scene_world`` at 2 cm), both float32, side by side;
* check: the continuous check of random arm7 paths (20 waypoints) in the scene,
  paths per second.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402
import warp as wp  # noqa: E402

if hasattr(wp.config, "quiet"):
    wp.config.quiet = True

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import timing  # noqa: E402

from jwarp.core.arrays import init_warp  # noqa: E402


def _scene(rng: np.random.Generator, n: int):
    from jwarp.world import World
    w = World.of_shapes()
    kinds = [("box", lambda: rng.uniform(0.05, 0.4, 3)), ("cylinder",
             lambda: [rng.uniform(0.1, 0.5), rng.uniform(0.02, 0.1)]),
             ("sphere", lambda: [rng.uniform(0.03, 0.1)])]
    for i in range(n):
        kind, dims = kinds[i % 3]
        w.add(f"o{i}", kind, dims(), rng.uniform([-1, -1, 0], [1, 1, 1.5]))
    return w


def stats(times: list[float]) -> str:
    t = np.array(times) * 1e3
    return f"{t.min():8.3f} {np.median(t):8.3f}"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--repeats", type=int, default=20)
    ap.add_argument("--points", type=int, default=100_000)
    ap.add_argument("--paths", type=int, default=200)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--json", default=None, help="write the figures here")
    a = ap.parse_args(argv)
    rows: list[dict] = []

    def row(what: str, times: list[float], **extra) -> None:
        rows.append(dict(what=what, min_ms=float(np.min(times) * 1e3),
                         median_ms=float(np.median(times) * 1e3), **extra))
    if a.quick:
        a.repeats, a.points, a.paths = 3, 5000, 10
    init_warp()
    dev = wp.get_device(a.device)
    rng = np.random.default_rng(0)
    print(f"# jwarp exact worlds, {timing.machine()}, warp {wp.config.version}, device {dev}")
    print(f"{'what':<52}{'min ms':>9}{'median':>9}")
    from jwarp.core.device import scalar_type
    from jwarp.world.device_world import DeviceWorld
    f32 = scalar_type(np.float32)
    # build
    times = []
    for r in range(a.repeats):
        t0 = time.perf_counter()
        w = _scene(np.random.default_rng(r), 20)
        dw = DeviceWorld(w, dev, f32)
        wp.synchronize_device(dev)
        times.append(time.perf_counter() - t0)
    print(f"{'build 20 objects + device copy (BVH)':<52}{stats(times)}")
    row("build", times)
    # move
    w = _scene(rng, 60)
    dw = DeviceWorld(w, dev, f32)
    ids = w.object_ids[:50]
    times = []
    for _ in range(a.repeats):
        P = rng.uniform([-1, -1, 0], [1, 1, 1.5], (50, 3))
        t0 = time.perf_counter()
        w.move(ids, P)
        dw.sync()
        w.shapes.device_shapes(dev, f32)
        wp.synchronize_device(dev)
        times.append(time.perf_counter() - t0)
    print(f"{'move 50 objects (pose arrays + BVH refit)':<52}{stats(times)}")
    row("move", times)
    # query: exact vs grid of the table-and-shelf scene
    from jwarp.world import SceneOptions, exact_world, scene_world
    from jwarp.world.collision import CollisionModel  # noqa: F401  (kernels)
    from jwarp.world.scene_file import scene_from_dict, table_shelf_scene
    scene = scene_from_dict(table_shelf_scene())
    ex = exact_world(scene)
    grid = scene_world(scene, SceneOptions(voxel_size=0.02)).astype(np.float32)
    b = scene.bounds()
    pts = rng.uniform(b[:, 0] - 0.1, b[:, 1] + 0.1, (a.points, 3)).astype(np.float32)
    k = DeviceWorld(ex, dev, f32).k
    p_wp = wp.array(pts, dtype=k.vec3, device=dev)
    out = [wp.empty(a.points, dtype=f32, device=dev), wp.empty(a.points, dtype=k.vec3, device=dev),
           wp.empty(a.points, dtype=wp.int32, device=dev)]
    qw = {}
    for name, world, cut in (("exact", ex, 1e30), ("exact, cutoff 5 cm", ex, 0.05),
                             ("grid 2 cm", grid, 1e30)):
        dwq = DeviceWorld(world, dev, f32)
        qw[name] = (dwq, cut)
    res = {n: [] for n in qw}
    for _ in range(a.repeats):
        for name, (dwq, cut) in qw.items():
            t0 = time.perf_counter()
            wp.launch(k.world_query, dim=a.points, inputs=[dwq.struct, p_wp, cut], outputs=out,
                      device=dev)
            wp.synchronize_device(dev)
            res[name].append(time.perf_counter() - t0)
    base = np.median(res["grid 2 cm"])
    for name, t in res.items():
        ns = np.median(t) / a.points * 1e9
        label = f"query {a.points} points, {name} ({len(scene.shapes)} shapes)"
        print(f"{label:<52}{stats(t)}   {ns:7.1f} ns/point, {np.median(t) / base:5.2f} x grid")
        row(f"query {name}", t, ns_per_point=ns)
    # continuous check
    import jwarp
    from jwarp.world.motion import MotionCheck
    robot = jwarp.robot("arm7")
    w = exact_world(scene)
    lim = np.array(robot.joint_limits)
    q = rng.uniform(lim[:, 0], lim[:, 1], (a.paths, 2, robot.n_dof)) * 0.6
    paths = q[:, :1] + np.linspace(0, 1, 20)[None, :, None] * (q[:, 1:] - q[:, :1])
    chk = MotionCheck(robot, w, device=dev)
    pw = wp.array(paths, dtype=wp.float64, device=dev)
    idx = wp.array(np.arange(a.paths, dtype=np.int32), dtype=wp.int32, device=dev)
    chk.launch(pw, idx, a.paths)
    times = []
    for _ in range(a.repeats):
        t0 = time.perf_counter()
        o = chk.launch(pw, idx, a.paths)
        ok = o["ok"].numpy()
        times.append(time.perf_counter() - t0)
    rate = a.paths / np.median(times)
    print(f"{f'check {a.paths} arm7 paths (20 waypoints), {ok[:a.paths].mean():.0%} ok':<52}"
          f"{stats(times)}   {rate:9.0f} paths/s")
    row("check", times, paths_per_s=rate, ok=float(ok[:a.paths].mean()))
    if a.json:
        import json
        with open(a.json, "w") as f:
            json.dump({"device": str(dev), "rows": rows}, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
