"""CLI subcommands of experimental design: ``jwarp sensitivity`` and ``jwarp design``.

Examples::

    # eigenvalue spectra of hand4 contacts vs the relative task (thesis Fig. 2.8)
    jwarp sensitivity --setup contact.json --task-setup relative.json --n 300 --seed 0 \\
        --out spectra.png --rerun spectra.rrd
    # a pool of 10000 collision-free contact configurations, then the 100 task D-optimal ones
    jwarp design --setup contact.json --write-candidates 10000 --seed 0 --out pool.csv
    jwarp design --setup contact.json --task-setup relative.json --candidates pool.csv \\
        --n 100 --method detmax --out plan.csv

``sensitivity``: the actual measurement (``--setup``) at ``--samples`` (a samples, pool or
plan CSV: joint + per-sample columns, observed columns ignored) or at ``--n`` configurations
drawn with ``--seed`` (contact setups: in contact on the nominal robot; others: uniform),
and the task measurement (``--task-setup``) at ``--task-samples`` or ``--n`` uniform
configurations. Prints the identifiable counts, the kernel-inclusion verdict of eq. 2.24
and the directions that break it (:mod:`jwarp.calibration.design.sensitivity`); ``--out``
(old spelling ``--png``, deprecated) draws both spectra on a log scale, ``--rerun`` logs them as bar charts (log10 of the
eigenvalues) under ``sensitivity/<actual|task>``.

``design``: selects ``--n`` rows of ``--candidates`` (task D-optimality with
``--task-setup``, else plain D-optimality; :mod:`jwarp.calibration.design.optimal`) and
writes them, in the order chosen, to ``--out`` in the pool format. With
``--write-candidates N`` it instead writes a pool of N drawn configurations to ``--out``.
Pools are feasible (:func:`jwarp.calibration.pool.draw_pool`): draws outside the
joint limits, in self-collision (sphere surfaces closer than ``--margin``, as
``jwarp sample-poses`` checks them) or, with ``--world`` / ``--scene``, in collision with
the world are dropped and replaced by more draws; a summary line says how many were
dropped and why. Rows of ``--candidates`` are checked the same way and the failing ones
left out of the selection (their line numbers are printed). A robot without collision
spheres gets a ``warning:`` line on stderr: its pool is not checked.
Option values and ``--out`` are checked before any work; files are written atomically.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from jwarp.cli.common import (
    CLIError,
    check_output,
    dumps,
    int_arg,
    quiet_warp,
    real_arg,
    rerun_recording,
)
from jwarp.cli.vocabulary import add_out

if TYPE_CHECKING:
    from jwarp.model import RobotModel

DEFAULT_FREE = "theta,d,r,alpha"


def _setup_and_measurement(path: str, option: str, robot_name: str | None) -> tuple[Any, Any, Any]:
    from jwarp.calibration.files import make_measurement, read_setup
    from jwarp.plugins.registry import robot as get_robot

    try:
        setup = read_setup(path)
    except ValueError as e:
        raise CLIError(f"{option}: {' '.join(str(e).split())}") from None
    name = robot_name or setup.robot
    if not name:
        raise CLIError("--robot: not given and the setup file names no robot")
    model = get_robot(name)
    try:
        meas = make_measurement(model, setup)
    except ValueError as e:
        raise CLIError(f"{option}: {' '.join(str(e).split())}") from None
    return setup, model, meas


def _configurations(model: RobotModel, setup: Any, meas: Any, path: str | None, option: str,
                    n: int, seed: int, uniform: bool) -> tuple[np.ndarray, dict | None]:
    from jwarp.calibration.pool import draw_configurations, read_configurations
    from jwarp.calibration.simulate.campaign import uniform_configurations

    if path:
        s = read_configurations(path, model, meas, option)
        return s.q, (s.meta or None)
    if uniform and not meas.meta_names:
        return uniform_configurations(model, np.random.default_rng(seed), n), None
    q, meta = draw_configurations(model, setup, n, seed)
    return q, (meta or None)


# ------------------------------------------------------------------ plots
_COLORS = {"actual": (40, 40, 220), "task": (200, 90, 30)}   # BGR: red, blue (Fig. 2.8)


def spectra_png(path: str, spectra: list[tuple[str, np.ndarray]], threshold: float | None,
                title: str, option: str = "--out") -> None:
    """A log-scale plot of eigenvalue spectra (descending, one polyline + markers each)
    written atomically as PNG (OpenCV; matplotlib is not a dependency)."""
    import cv2

    from jwarp.utils.atomic import AtomicFile

    W, H, left, right, top, bottom = 900, 560, 90, 30, 50, 60
    img = np.full((H, W, 3), 255, np.uint8)
    allv = np.concatenate([v[v > 0] for _, v in spectra if np.any(v > 0)] or [np.ones(1)])
    lo = math.floor(math.log10(max(allv.min(), 1e-300)))
    hi = math.ceil(math.log10(allv.max()))
    lo = max(lo, hi - 24)
    if hi == lo:
        hi = lo + 1
    P = max(len(v) for _, v in spectra)

    def xy(i: int, v: float) -> tuple[int, int]:
        lv = math.log10(v) if v > 0 else lo
        lv = min(max(lv, lo), hi)
        x = left + (W - left - right) * (i / max(P - 1, 1))
        y = top + (H - top - bottom) * (hi - lv) / (hi - lo)
        return int(round(x)), int(round(y))

    font = cv2.FONT_HERSHEY_SIMPLEX
    step = max(1, (hi - lo) // 12)
    for e in range(lo, hi + 1, step):
        _, y = xy(0, 10.0 ** e)
        cv2.line(img, (left, y), (W - right, y), (225, 225, 225), 1)
        cv2.putText(img, f"1e{e}", (8, y + 5), font, 0.45, (60, 60, 60), 1, cv2.LINE_AA)
    cv2.rectangle(img, (left, top), (W - right, H - bottom), (0, 0, 0), 1)
    if threshold and threshold > 0:
        _, y = xy(0, threshold)
        cv2.line(img, (left, y), (W - right, y), (120, 120, 120), 1, cv2.LINE_AA)
    for k, (name, v) in enumerate(spectra):
        color = _COLORS.get(name, (60, 160, 60))
        pts = np.array([xy(i, float(x)) for i, x in enumerate(v)], np.int32)
        cv2.polylines(img, [pts], False, color, 1, cv2.LINE_AA)
        for p in pts:
            cv2.circle(img, (int(p[0]), int(p[1])), 3, color, -1, cv2.LINE_AA)
        cv2.putText(img, name, (W - right - 160, top + 22 + 20 * k), font, 0.55, color, 1,
                    cv2.LINE_AA)
    cv2.putText(img, title, (left, 30), font, 0.55, (0, 0, 0), 1, cv2.LINE_AA)
    cv2.putText(img, "eigenvalue index", (W // 2 - 60, H - 20), font, 0.5, (0, 0, 0), 1,
                cv2.LINE_AA)
    ok, buf = cv2.imencode(".png", img)
    if not ok:  # pragma: no cover - OpenCV failure
        raise OSError(f"{option}: PNG encoding failed")
    f = AtomicFile(path, option=option)
    try:
        with open(f.tmp, "wb") as fh:
            fh.write(buf.tobytes())
        f.commit()
    except BaseException:
        f.discard()
        raise


# ------------------------------------------------------------- sensitivity
def cmd_sensitivity(args: argparse.Namespace) -> int:
    from jwarp.calibration.design.sensitivity import sensitivity

    quiet_warp()
    inputs = {"--setup": args.setup, "--task-setup": args.task_setup,
              "--samples": args.samples, "--task-samples": args.task_samples}
    for opt, p in (("--out", args.out), ("--rerun", args.rerun)):
        if p:
            check_output(p, opt, rerun=opt == "--rerun", inputs=inputs)
    if args.out and args.rerun and args.out == args.rerun:
        raise CLIError(f"--rerun: {args.rerun} is also --out; give another file")
    setup, model, meas = _setup_and_measurement(args.setup, "--setup", args.robot)
    tsetup, tmodel, task = _setup_and_measurement(args.task_setup, "--task-setup",
                                                  args.robot or setup.robot)
    if tmodel.name != model.name:
        raise CLIError(f"--task-setup: robot '{tmodel.name}' differs from the --setup robot "
                       f"'{model.name}'; give --robot")
    qa, ma = _configurations(model, setup, meas, args.samples, "--samples", args.n, args.seed,
                             uniform=False)
    qt, mt = _configurations(model, tsetup, task, args.task_samples, "--task-samples", args.n,
                             args.seed + 1, uniform=True)
    t0 = time.perf_counter()
    try:
        res = sensitivity(model, meas, qa, task, qt, args.free, meta_actual=ma, meta_task=mt,
                          whiten=args.whiten, rtol=args.rtol, atol=args.atol)
    except ValueError as e:
        msg = " ".join(str(e).split())
        for prefix, opt in (("free: ", "--free"), ("rtol, atol: ", "--rtol, --atol")):
            if msg.startswith(prefix):
                raise CLIError(f"{opt}: {msg.removeprefix(prefix)}") from None
        raise
    wall = time.perf_counter() - t0
    labels = (f"actual ({meas.name})", f"task ({task.name})")
    spectra = [("actual", res.actual.eigenvalues), ("task", res.task.eigenvalues)]
    if args.out:
        spectra_png(args.out, spectra, res.actual.threshold,
                    f"{model.name}: eigenvalues of J^T J, {meas.name} (red) vs {task.name} "
                    f"(blue)")
    if args.rerun:
        from jwarp.viz.spectra import SpectraRecording

        rec = rerun_recording(SpectraRecording, args.rerun)
        rec.save(spectra)
    if args.json:
        doc = dict(res.to_dict(), robot=model.name, free=args.free,
                   configurations={"actual": int(len(qa)), "task": int(len(qt))},
                   time_s=wall, out=args.out, png=args.out, rerun=args.rerun)
        print(dumps(doc, indent=1))
        return 0
    unit = "whitened" if args.whiten else f"{meas.unit} / parameter unit"
    print(f"sensitivity of '{model.name}': {labels[0]} at {len(qa)} configurations vs "
          f"{labels[1]} at {len(qt)}; free: {args.free}; {len(res.names)} parameters; "
          f"J {unit}; {wall:.1f} s")
    print(f"identifiable: eigenvalue of J^T J > max(rtol {res.rtol:g} x largest, atol "
          f"{res.atol:g})")
    print(f"\n{'measurement':<24}{'identifiable':>14}{'of':>6}{'largest':>12}{'threshold':>12}")
    for lab, sp in zip(labels, (res.actual, res.task)):
        print(f"{lab:<24}{sp.n_identifiable:>14d}{sp.n_params:>6d}{sp.eigenvalues[0]:>12.3e}"
              f"{sp.threshold:>12.3e}")
    verdict = "holds" if res.kernel_included else \
        f"FAILS by {len(res.breaking)} direction{'s' if len(res.breaking) != 1 else ''}"
    print(f"\nkernel inclusion Kernel(Ja^T Ja) in Kernel(Jt^T Jt) (eq. 2.24): {verdict}")
    for k, d in enumerate(res.breaking):
        top = ", ".join(f"{n} {w:+.2f}" for n, w in d.top)
        print(f"  direction {k + 1} (task gain {d.task_gain:.2e}): {top}")
    for path in (args.out, args.rerun):
        if path:
            print(f"wrote {path}")
    return 0


# ------------------------------------------------------------------ design
def _design_world(args: argparse.Namespace, model: RobotModel) -> Any:
    """The World of ``--world`` SPEC or ``--scene`` FILE (its exact objects), or None."""
    if args.world is not None:
        from jwarp.world.io import parse_world_spec

        try:
            return parse_world_spec(args.world, robot=model)
        except (ValueError, TypeError, OSError, MemoryError, OverflowError) as e:
            msg = " ".join(str(e).split())
            for prefix in ("world: ", "path: "):
                msg = msg.removeprefix(prefix)
            raise CLIError(f"--world: {msg}") from None
    if args.scene is not None:
        from jwarp.world.collision import check_world
        from jwarp.world.scene_file import exact_world, load_scene, robot_frames

        try:
            world = exact_world(load_scene(args.scene, frames=robot_frames(model)))
            check_world(model, world)
        except (ValueError, TypeError, OSError) as e:
            raise CLIError(f"--scene: {' '.join(str(e).split()).removeprefix('scene: ')}") \
                from None
        return world
    return None


def _warn(lines: list[str]) -> None:
    for w in lines:
        print(f"warning: {w}", file=sys.stderr)


def cmd_design(args: argparse.Namespace) -> int:
    from jwarp.calibration.design.optimal import DesignOptions, design
    from jwarp.calibration.pool import (
        PoolChecker,
        configurations_text,
        draw_pool,
        read_configurations,
    )
    from jwarp.utils.atomic import AtomicFile

    quiet_warp()
    if args.write_candidates is not None and args.candidates:
        raise CLIError("--write-candidates: writes a pool; do not give --candidates with it")
    if args.write_candidates is None and not args.candidates:
        raise CLIError("--candidates: required (or --write-candidates N to make a pool)")
    inputs = {"--setup": args.setup, "--task-setup": args.task_setup,
              "--candidates": args.candidates, "--task-samples": args.task_samples,
              "--scene": args.scene}
    check_output(args.out, "--out", inputs=inputs)
    setup, model, meas = _setup_and_measurement(args.setup, "--setup", args.robot)
    if args.write_candidates is not None:   # the pool's memory, before any draw
        from jwarp.cli.common import check_option_memory
        from jwarp.cli.planning import config_bytes

        n = args.write_candidates
        check_option_memory(2.0 * n * config_bytes(model), f"a pool of {n} configurations "
                            f"of '{model.name}' (with the draws its checks drop)",
                            "--write-candidates")
    world = _design_world(args, model)
    if args.write_candidates is not None:
        try:
            drawn = draw_pool(model, setup, args.write_candidates, args.seed, world=world,
                              margin=args.margin)
        except ValueError as e:
            raise CLIError(f"--setup: {' '.join(str(e).split()).removeprefix('setup: ')}") \
                from None
        if len(drawn) == 0:
            _warn(drawn.warnings)
            why = ", ".join(f"{k.replace('_', ' ')} {v}" for k, v in drawn.dropped.items() if v)
            raise CLIError(f"--write-candidates: no configuration of {drawn.drawn} draws passed "
                           f"the collision check (margin {args.margin:g} m; {why}); lower "
                           f"--margin or check the world")
        text = configurations_text(model, meas, drawn.q, drawn.meta)
        with AtomicFile(args.out, option="--out") as f, open(f.tmp, "w", encoding="utf-8") as fh:
            fh.write(text)
        _warn(drawn.warnings)
        if args.json:
            print(dumps(dict(drawn.to_dict(), robot=model.name, plugin=meas.name,
                             out=args.out), indent=1))
            return 0
        print(f"wrote {len(drawn)} candidate configurations of '{meas.name}' on "
              f"'{model.name}' to {args.out}"
              f"{'' if drawn.complete else f' (SHORT of the {drawn.requested} asked for)'}")
        print(drawn.summary())
        return 0
    pool = read_configurations(args.candidates, model, meas, "--candidates")
    checker = PoolChecker(model, setup, world=world, margin=args.margin)
    _warn(checker.warnings)
    chk = checker(pool.q)
    feasible = np.flatnonzero(chk.keep)
    excluded = np.flatnonzero(~chk.keep)
    if args.n > len(feasible):
        raise CLIError(f"--n: {args.n} configurations asked from the {len(feasible)} rows of "
                       f"--candidates that pass the collision check (of {len(pool)}; margin "
                       f"{args.margin:g} m)")
    task = qt = mt = None
    if args.task_setup:
        tsetup, tmodel, task = _setup_and_measurement(args.task_setup, "--task-setup",
                                                      args.robot or setup.robot)
        if tmodel.name != model.name:
            raise CLIError(f"--task-setup: robot '{tmodel.name}' differs from the --setup "
                           f"robot '{model.name}'; give --robot")
        qt, mt = _configurations(model, tsetup, task, args.task_samples, "--task-samples",
                                 args.task_n, args.seed + 1, uniform=True)
    elif args.task_samples:
        raise CLIError("--task-samples: only with --task-setup")
    options = DesignOptions(n=args.n, method=args.method, seed=args.seed)
    last = [0.0]

    def progress(done: int, total: int) -> None:
        now = time.perf_counter()
        if args.quiet or now - last[0] < 1.0:
            return
        last[0] = now
        what = f"step {done}/{total}" if total else f"excursion {done}"
        print(f"design: {what}", file=sys.stderr)

    meta_ok = {k: np.asarray(v)[feasible] for k, v in pool.meta.items()}
    try:
        res = design(model, meas, pool.q[feasible], options, free=args.free,
                     meta_pool=meta_ok or None, task=task, q_task=qt, meta_task=mt,
                     progress=progress)
    except ValueError as e:
        msg = " ".join(str(e).split())
        for prefix, opt in (("free: ", "--free"), ("sigma: ", "--free")):
            if msg.startswith(prefix):
                raise CLIError(f"{opt}: {msg.removeprefix(prefix)}") from None
        raise
    idx = feasible[res.indices]            # rows of --candidates
    row_lines = cast(np.ndarray, pool.lines)  # read from a file: its line numbers
    res.indices = idx
    res.n_candidates = len(pool)
    meta = {k: np.asarray(v)[idx] for k, v in pool.meta.items()}
    text = configurations_text(model, meas, pool.q[idx], meta)
    with AtomicFile(args.out, option="--out") as f, open(f.tmp, "w", encoding="utf-8") as fh:
        fh.write(text)
    if args.json:
        doc = dict(res.to_dict(), robot=model.name, plugin=meas.name,
                   task=None if task is None else task.name, free=args.free,
                   candidates=args.candidates, out=args.out,
                   lines=[int(v) for v in row_lines[idx]],
                   collision_check={"self_checked": chk.self_checked,
                                    "world_checked": chk.world_checked, "margin": args.margin,
                                    "excluded": dict(chk.dropped),
                                    "excluded_lines": [int(v) for v in row_lines[excluded]],
                                    "warnings": chk.warnings})
        print(dumps(doc, indent=1))
        return 0
    crit = "task D-optimality" if task is not None else "D-optimality"
    if excluded.size:
        why = ", ".join(f"{k.replace('_', ' ')} {v}" for k, v in chk.dropped.items() if v)
        shown = ", ".join(str(int(v)) for v in row_lines[excluded[:10]])
        print(f"excluded {excluded.size} of {len(pool)} rows of --candidates that fail the "
              f"collision check (margin {args.margin:g} m; {why}): lines {shown}"
              f"{', ...' if excluded.size > 10 else ''}")
    elif chk.self_checked or chk.world_checked:
        what = " + ".join(w for w, on in (("self", chk.self_checked),
                                          ("world", chk.world_checked)) if on)
        print(f"all {len(pool)} rows of --candidates pass the collision check ({what}, "
              f"margin {args.margin:g} m)")
    print(f"selected {len(idx)} of {len(pool)} candidates ({args.method}, {crit}, task rank "
          f"{res.rank}) in {res.time_s:.2f} s; criterion -log det(L^T Cov L): prior "
          f"{res.prior_criterion:.3f} -> {res.criterion:.3f}"
          f"{f', {res.iterations} detmax excursions' if args.method == 'detmax' else ''}")
    if res.notes:
        for k, v in res.notes.items():
            print(f"note: {k}: {v}")
    print(f"wrote {args.out}")
    return 0


def add_subcommands(sub: Any) -> None:
    """Register ``sensitivity`` and ``design`` on the CLI's subparsers."""
    s = sub.add_parser("sensitivity", help="eigenvalue spectra and kernel inclusion of an "
                       "actual vs a task measurement (thesis eqs. 2.23-2.24)")
    s.add_argument("--robot", default=None, help="robot name or .json (default: the setup's)")
    s.add_argument("--setup", required=True, metavar="S.json", help="actual measurement setup")
    s.add_argument("--task-setup", required=True, metavar="T.json",
                   help="task measurement setup (e.g. plugin relative)")
    s.add_argument("--samples", default=None, metavar="CSV",
                   help="configurations of the actual measurement (samples, pool or plan CSV)")
    s.add_argument("--task-samples", default=None, metavar="CSV",
                   help="configurations of the task (default: --n uniform ones)")
    s.add_argument("--n", type=int_arg("--n", 1), default=100,
                   help="configurations drawn where no file is given (default 100)")
    s.add_argument("--seed", type=int_arg("--seed", 0), default=0, help="seed of the draws")
    s.add_argument("--free", default=DEFAULT_FREE, metavar="GROUPS",
                   help=f"parameter groups (default {DEFAULT_FREE})")
    s.add_argument("--rtol", type=real_arg("--rtol", 0.0), default=1e-12,
                   help="identifiable: eigenvalue > rtol x largest (default 1e-12)")
    s.add_argument("--atol", type=real_arg("--atol", 0.0), default=0.0,
                   help="... and > atol (the thesis uses 1e-6; default 0)")
    s.add_argument("--whiten", action="store_true",
                   help="divide the Jacobian rows by the measurement noise")
    add_out(s, "--png", metavar="OUT.png",
            help="plot both spectra (log scale) to this PNG")
    s.add_argument("--rerun", default=None, metavar="OUT.rrd",
                   help="log both spectra as rerun bar charts")
    s.add_argument("--json", action="store_true", help="print the result as JSON")
    s.set_defaults(func=cmd_sensitivity)

    s = sub.add_parser("design", help="task D-optimal selection of measurement "
                       "configurations from a candidate pool (greedy / DETMAX)")
    s.add_argument("--robot", default=None, help="robot name or .json (default: the setup's)")
    s.add_argument("--setup", required=True, metavar="S.json", help="actual measurement setup")
    s.add_argument("--task-setup", default=None, metavar="T.json",
                   help="task measurement setup (default: plain D-optimality)")
    s.add_argument("--candidates", default=None, metavar="POOL.csv",
                   help="candidate pool: the robot's joint columns + per-sample columns")
    s.add_argument("--write-candidates", type=int_arg("--write-candidates", 1), default=None,
                   metavar="N", help="instead: draw N collision-free candidates (--seed) and "
                                     "write them to --out")
    s.add_argument("--margin", type=real_arg("--margin", 0.0, 1.0, unit=" m"), default=0.0,
                   help="least distance [m] between collision-sphere surfaces (self and "
                        "world) of a kept candidate (default 0; sample-poses uses 0.02)")
    where = s.add_mutually_exclusive_group()
    where.add_argument("--world", default=None, metavar="SPEC",
                       help="drop candidates in collision with this world: simplex:seed=S[,...], "
                            "shelf or a world .npz file")
    where.add_argument("--scene", default=None, metavar="FILE.yaml",
                       help="drop candidates in collision with this scene's objects (jwarp or "
                            "MoveIt scene file, docs/scenes.md)")
    s.add_argument("--n", type=int_arg("--n", 1), default=100,
                   help="configurations to select (default 100)")
    s.add_argument("--method", choices=("greedy", "detmax"), default="detmax")
    s.add_argument("--task-samples", default=None, metavar="CSV",
                   help="task configurations (default: --task-n uniform ones)")
    s.add_argument("--task-n", type=int_arg("--task-n", 1), default=500,
                   help="uniform task configurations (default 500)")
    s.add_argument("--seed", type=int_arg("--seed", 0), default=0, help="seed of the draws")
    s.add_argument("--free", default=DEFAULT_FREE, metavar="GROUPS",
                   help=f"parameter groups to be calibrated (default {DEFAULT_FREE})")
    s.add_argument("--out", required=True, metavar="PLAN.csv",
                   help="the selected configurations (pool format, order of selection)")
    s.add_argument("--quiet", action="store_true", help="no progress lines")
    s.add_argument("--json", action="store_true", help="print the result as JSON")
    s.set_defaults(func=cmd_design)
