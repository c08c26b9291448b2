"""CLI subcommands ``jwarp data generate | info | export``: motion-planning datasets in an
SQLite path database (:mod:`jwarp.learn.dataset`, :mod:`jwarp.learn.generate`;
docs/datasets.md).

Examples::

    jwarp data generate --robot justin19 --worlds 10000 --paths-per-world 100 --db out.sqlite
    jwarp data generate --robot justin19 --worlds 10000 --paths-per-world 100 --db out.sqlite \\
        --ray --num-gpus 0.25 --device cuda        # local Ray, 4 tasks per GPU
    jwarp data generate ... --ray-address auto     # an existing Ray cluster (ray start --head)
    jwarp data info out.sqlite
    jwarp data export out.sqlite --out out.npz [--skip-damaged]

``generate`` labels the worlds of seeds ``--first-seed`` .. ``--first-seed + --worlds - 1``
(one world per seed, deterministic) with ``--paths-per-world`` paths each, ``--chunk``
worlds per task, and writes them into ``--db`` (created if missing). Running the same
command again resumes an interrupted run: complete worlds are skipped, nothing is written
twice. Without ``--ray``/``--ray-address`` it runs in this process. A progress bar on
stderr shows paths, paths/s and the ETA (``--quiet``: none); the summary goes to stdout
(``--json``: as JSON).

Every option is checked before any work: counts in range, ``--device``, ``--db`` (a
writable file in an existing folder; an existing database must be one of ``--robot``),
Ray installed for ``--ray`` (the optional extra ``distributed``), ``--num-gpus`` only with
Ray, the default labeller available, the memory the labeller needs for one world
(``--paths-per-world`` x ``--n-waypoints`` x the multi-starts, :mod:`jwarp.utils.memory`);
``export --out`` writable and not the database. Errors are one line naming the option.
An existing database must be writable and so must its folder (SQLite writes its journal
beside it): a read-only one is refused before the first world is labelled.

``--db`` keeps its name (it is not ``--out``): the database is read as well as written
(``generate`` resumes into it). A damaged stored world (a blob that does not decompress,
or a path row of the wrong size) is an error naming the file, the world and the row;
``data export --skip-damaged`` leaves such worlds and rows out and says how many.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from typing import TYPE_CHECKING, Any

from jwarp.cli.common import (
    CLIError,
    check_device,
    check_option_memory,
    check_output,
    dumps,
    int_arg,
    quiet_warp,
    real_arg,
    robot_option,
)
from jwarp.cli.vocabulary import add_out, require_out

if TYPE_CHECKING:
    from jwarp.model import RobotModel


def _check_db(path: str, robot: RobotModel, timeout: float) -> None:
    """``--db``: an existing, writable database of ``robot`` in a writable folder (SQLite
    writes its journal beside the file), or a new file in a writable folder."""
    from jwarp.learn.dataset import PathDB, PathDBError

    if os.path.isdir(path):
        raise CLIError(f"--db: {path} is a folder")
    if os.path.islink(path) and not os.path.exists(path):  # SQLite would open the target
        raise CLIError(f"--db: {path} is a symbolic link to {os.readlink(path)}, which does "
                       f"not exist (a dangling link); give the database file itself")
    if os.path.isfile(path) and os.path.getsize(path) > 0:
        folder = os.path.dirname(os.path.abspath(path))
        if not os.access(path, os.W_OK):
            raise CLIError(f"--db: {path} is read-only; nothing can be added to it (make it "
                           f"writable or give another --db)")
        if not os.access(folder, os.W_OK | os.X_OK):
            raise CLIError(f"--db: the folder {folder} is read-only; SQLite writes its "
                           f"journal beside {os.path.basename(path)} (make the folder "
                           f"writable or give another --db)")
        try:
            PathDB(path, robot, timeout=timeout).close()
        except PathDBError as e:
            raise CLIError(f"--db: {' '.join(str(e).split()).removeprefix('database: ')}") \
                from None
    else:
        check_output(path, "--db")


#: the planner's substeps per segment when the labeller sizes them (an estimate)
_SIZED_SUBSTEPS = 16


def labeller_memory(model: RobotModel, options: Any, paths_per_world: int, chunk: int) -> float:
    """Estimated peak memory [bytes] of labelling one world with ``paths_per_world`` paths
    (:func:`jwarp.learn.plan_data.label_world`: every task's multi-starts in one planner
    batch, all of them kept as ``all_paths``) plus the finished records of a chunk."""
    n, F, S = model.n_dof, model.n_frames, len(model.spheres)
    W = int(getattr(options, "n_waypoints", 20))
    starts = int(getattr(options, "max_starts", 100))
    sub = getattr(options, "n_substeps", None) or _SIZED_SUBSTEPS
    item = 8 if str(getattr(options, "dtype", "float32")) == "float64" else 4
    per_sub = item * (3 * n + 52 * F + 3 * S + 4) + 24 * n     # as jwarp plan's estimate
    batch = float(paths_per_world) * starts
    need = batch * ((W - 1) * sub + 1) * per_sub + batch * W * n * (item + 8)
    need += float(chunk) * paths_per_world * W * n * 4 * 3     # records waiting for the DB
    return need


def _check_generate_memory(model: RobotModel, options: Any, args: argparse.Namespace) -> None:
    from jwarp.learn.generate import DEFAULT_CHUNK

    need = labeller_memory(model, options, args.paths_per_world,
                           1 if not (args.ray or args.ray_address) else
                           (args.chunk or DEFAULT_CHUNK))
    W = getattr(options, "n_waypoints", 20)
    option = "--n-waypoints" if args.n_waypoints is not None and W > 200 else "--paths-per-world"
    check_option_memory(need, f"labelling one world ({args.paths_per_world} paths x {W} "
                        f"waypoints x {getattr(options, 'max_starts', '?')} multi-starts of "
                        f"'{model.name}')", option)


def cmd_generate(args: argparse.Namespace) -> int:
    from jwarp.learn import generate as gen

    quiet_warp()
    model = robot_option(args.robot)
    check_device(args.device)
    use_ray = bool(args.ray or args.ray_address)
    if args.num_gpus and not use_ray:
        raise CLIError("--num-gpus: only with --ray or --ray-address (one GPU share per task)")
    if args.num_cpus is not None and (not args.ray or args.ray_address):
        raise CLIError("--num-cpus: only with --ray (the CPUs of a local Ray instance)")
    if use_ray:
        try:
            gen.ray_module()
        except ImportError as e:
            raise CLIError(f"{'--ray' if args.ray else '--ray-address'}: {e}") from None
    _check_db(args.db, model, args.timeout)
    try:
        labeler, world_maker = gen.default_labeler(), gen.default_world_maker()
        kw: dict[str, Any] = {"device": args.device}
        if args.n_waypoints is not None:
            kw["n_waypoints"] = args.n_waypoints
        if args.margin is not None:
            kw["margin"] = args.margin
        options = gen.default_options(**kw)
    except ImportError as e:
        raise CLIError(f"data generate: {e}") from None
    _check_generate_memory(model, options, args)
    if os.path.isfile(args.db) and os.path.getsize(args.db) > 0:
        from jwarp.learn.dataset import PathDB

        with PathDB(args.db, model, timeout=args.timeout) as db:
            try:
                gen.check_settings(db, options, args.paths_per_world)
            except ValueError as e:
                raise CLIError(f"--db: {' '.join(str(e).split()).removeprefix('generate: ')}") \
                    from None
    report = gen.generate(model, args.worlds, args.paths_per_world, args.db,
                          first_seed=args.first_seed, chunk=args.chunk, options=options,
                          ray=args.ray, ray_address=args.ray_address, num_gpus=args.num_gpus,
                          num_cpus=args.num_cpus, labeler=labeler, world_maker=world_maker,
                          progress=not args.quiet, timeout=args.timeout)
    summary = report.to_dict()
    if args.json:
        print(dumps(summary))
    else:
        rate = report.paths_written / report.seconds if report.seconds > 0 else 0.0
        print(f"{report.db}: {report.worlds_written} worlds ({report.paths_written} paths) "
              f"written, {report.worlds_skipped} already there; {report.seconds:.1f} s, "
              f"{rate:.1f} paths/s ({report.backend})")
    return 0


def cmd_info(args: argparse.Namespace) -> int:
    from jwarp.learn.dataset import PathDB

    with PathDB(args.db, timeout=args.timeout) as db:
        info = db.info()
    if args.json:
        print(json.dumps(info))
    else:
        print(dumps(info))
    short = info["worlds_missing_paths"]
    if short:
        w = short[0]
        print(f"jwarp: warning: {len(short)} world(s) miss paths (e.g. world {w['world_id']}: "
              f"{w['stored']} of {w['expected']} stored)", file=sys.stderr)
    return 0


def cmd_export(args: argparse.Namespace) -> int:
    from jwarp.learn.dataset import PathDB, export_npz

    require_out(args)
    check_output(args.out, "--out", inputs={"DB": args.db})
    skipped: list = []
    with PathDB(args.db, timeout=args.timeout) as db:
        try:
            out = export_npz(db, args.out, skip_damaged=args.skip_damaged, skipped=skipped)
        except ValueError as e:
            msg = " ".join(str(e).split()).removeprefix("database: ")
            if "damaged" in msg:
                msg += " (--skip-damaged leaves damaged worlds and rows out)"
            raise CLIError(f"DB: {msg}") from None
        n = db.n_paths() - sum(d.get("paths", 0) for d in skipped)
    for d in skipped:
        print(f"jwarp: warning: skipped {d['what']}", file=sys.stderr)
    print(f"{out}: {n} paths" + (f" ({len(skipped)} damaged item(s) skipped)" if skipped else ""))
    return 0


def add_subcommands(sub: Any) -> None:
    """Add ``data generate | info | export`` to the ``jwarp`` subparsers."""
    from jwarp.cli.common import Parser

    def timeout(p: argparse.ArgumentParser) -> None:
        p.add_argument("--timeout", type=real_arg("--timeout", 0.0, 86400.0, unit=" [s]"),
                       default=30.0, metavar="S", help="seconds to wait while another process "
                       "holds the database's lock (default 30)")

    data = sub.add_parser("data", help="motion-planning datasets (generate, info, export)")
    dsub = data.add_subparsers(dest="what", metavar="WHAT", parser_class=Parser)
    dsub.required = True

    g = dsub.add_parser("generate", help="label worlds with paths into an SQLite database")
    g.add_argument("--robot", required=True, help="robot name or path to a robot .json")
    g.add_argument("--worlds", type=int_arg("--worlds", 1, 10**9), required=True, metavar="N",
                   help="number of worlds (seeds --first-seed ...)")
    g.add_argument("--paths-per-world", type=int_arg("--paths-per-world", 1, 10**7),
                   required=True, metavar="N", help="labelled paths per world")
    g.add_argument("--db", required=True, metavar="FILE",
                   help="the SQLite database (created if missing; resumed if present)")
    g.add_argument("--first-seed", type=int_arg("--first-seed", 0, 2**62), default=0,
                   metavar="S", help="seed of the first world (default 0)")
    g.add_argument("--chunk", type=int_arg("--chunk", 1, 10**6), default=None, metavar="N",
                   help="worlds per task (default 8)")
    g.add_argument("--n-waypoints", type=int_arg("--n-waypoints", 2, 10**5), default=None,
                   metavar="W", help="waypoints per path (default: the labeller's)")
    g.add_argument("--margin", type=real_arg("--margin", 0.0, unit=" [m]"), default=None,
                   metavar="M", help="required clearance [m] (default: the labeller's)")
    g.add_argument("--device", default="cpu", help="Warp device of the labeller (default cpu)")
    g.add_argument("--ray", action="store_true", help="run the chunks on a local Ray "
                                                      "instance (extra 'distributed')")
    g.add_argument("--ray-address", default=None, metavar="ADDR",
                   help="run on an existing Ray cluster (auto, HOST:6379, ray://HOST:10001)")
    g.add_argument("--num-gpus", type=real_arg("--num-gpus", 0.0, 64.0), default=0.0,
                   metavar="X", help="GPUs per Ray task (e.g. 1, 0.25; default 0)")
    g.add_argument("--num-cpus", type=int_arg("--num-cpus", 1, 1 << 16), default=None,
                   metavar="N", help="CPUs of the local Ray instance (default: all)")
    g.add_argument("--quiet", action="store_true", help="no progress bar")
    g.add_argument("--json", action="store_true", help="print the summary as JSON")
    timeout(g)
    g.set_defaults(func=cmd_generate)

    i = dsub.add_parser("info", help="summary of a path database")
    i.add_argument("db", metavar="DB", help="the SQLite database")
    i.add_argument("--json", action="store_true", help="one line of JSON")
    timeout(i)
    i.set_defaults(func=cmd_info)

    e = dsub.add_parser("export", help="export a path database to .npz")
    e.add_argument("db", metavar="DB", help="the SQLite database")
    add_out(e, "--npz", required=True, metavar="FILE.npz", help="the .npz file to write")
    e.add_argument("--skip-damaged", action="store_true",
                   help="leave out worlds and path rows whose stored data is damaged (each "
                        "named on stderr) instead of stopping at the first")
    timeout(e)
    e.set_defaults(func=cmd_export)
