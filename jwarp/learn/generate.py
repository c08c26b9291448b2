"""Generate motion-planning datasets into a path database (:mod:`jwarp.learn.dataset`),
in-process or on a Ray cluster (docs/datasets.md).

:func:`generate` splits the world seeds ``first_seed .. first_seed + n_worlds - 1`` into
chunks; every chunk is computed by the pure function :func:`label_chunk` (world =
``world_maker(robot, seed)``, labels = ``labeler(robot, world, paths_per_world, seed,
options)``: deterministic per world seed), in this process or as one Ray task per chunk
(``ray=True``; optional extra ``distributed``: ``pip install 'jwarp[distributed]'``). ONE
writer, the calling process, writes every world with its paths in one transaction, so
the file never holds half a world. Worlds already complete in the database are skipped:
an interrupted run (Ctrl-C, a crash, a killed node) is resumed by running the same
command again, without duplicates.

Ray: each task asks for ``num_cpus=1`` and ``num_gpus`` (e.g. 1 or 0.25: several tasks
share a GPU); a task whose worker dies (killed process, lost node) is retried by Ray
(``max_retries``) and a chunk whose task still fails is resubmitted by the driver up to
``max_retries`` times before :func:`generate` raises. ``ray_address``: an existing
cluster (``"auto"``, ``"ray://head:10001"``, ``"head:6379"``); None: the running Ray
instance of this process, or a local one (``num_cpus``).

The default labeller and world maker are :func:`jwarp.learn.plan_data.label_world` and
:func:`jwarp.learn.plan_data.world_for`; both can be injected (tests, other labels).
"""

from __future__ import annotations

import dataclasses
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

from jwarp.learn.dataset import PathDB, WorldRecord, world_record

if TYPE_CHECKING:
    from jwarp.model import RobotModel

__all__ = ["GenerateReport", "check_settings", "default_labeler", "default_options", "default_world_maker",
           "generate", "label_chunk", "options_dict", "ray_module"]

#: world seeds per chunk (one Ray task) when not given
DEFAULT_CHUNK = 8


@dataclass
class GenerateReport:
    """What :func:`generate` did: worlds written now, skipped (already complete), paths
    written, chunks retried by the driver, seconds."""

    db: str
    worlds_written: int = 0
    worlds_skipped: int = 0
    paths_written: int = 0
    retried_chunks: int = 0
    seconds: float = 0.0
    backend: str = "in-process"
    failed: list = field(default_factory=list)

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


# ====================================================================== defaults
def _plan_data() -> Any:
    try:
        from jwarp.learn import plan_data
    except ImportError as e:
        raise ImportError(f"the default labeller jwarp.learn.plan_data is not available "
                          f"({e}); pass labeler= and world_maker=") from None
    return plan_data


def default_labeler() -> Callable:
    """:func:`jwarp.learn.plan_data.label_world`."""
    return _plan_data().label_world


def default_world_maker() -> Callable:
    """``world_for(robot, seed)`` of :mod:`jwarp.learn.plan_data`."""
    return _plan_data().world_for


def default_options(**kw: Any) -> Any:
    """``PlanDataOptions(**kw)`` of :mod:`jwarp.learn.plan_data` (unknown keys dropped)."""
    cls = _plan_data().PlanDataOptions
    names = {f.name for f in dataclasses.fields(cls)} if dataclasses.is_dataclass(cls) else set(kw)
    return cls(**{k: v for k, v in kw.items() if k in names})


def options_dict(options: Any) -> dict:
    """The options as a plain dict (dataclass, ``to_dict()``, dict or None)."""
    if options is None:
        return {}
    if hasattr(options, "to_dict"):
        return dict(options.to_dict())
    if dataclasses.is_dataclass(options):
        return dataclasses.asdict(cast(Any, options))  # an instance (to_dict-less dataclass)
    return dict(options)


def ray_module() -> Any:
    """The ``ray`` module; ImportError naming the extra when it is missing."""
    try:
        import ray
    except ImportError as e:
        raise ImportError(f"Ray is not installed ({e}); install the optional extra: "
                          f"pip install 'jwarp[distributed]'") from None
    return ray


# ====================================================================== the pure part
def _call_world_maker(world_maker: Callable, robot: RobotModel, seed: int, options: Any) -> Any:
    device = getattr(options, "device", None)
    try:
        return world_maker(robot, seed, device=device)
    except TypeError as e:
        if "device" not in str(e):
            raise
        return world_maker(robot, seed)


def label_chunk(robot: RobotModel, seeds: Sequence[int], paths_per_world: int, options: Any = None,
                labeler: Callable | None = None, world_maker: Callable | None = None
                ) -> list[WorldRecord]:
    """The records (:func:`jwarp.learn.dataset.world_record`) of the worlds ``seeds``: a
    pure function of its arguments (what a Ray task runs)."""
    model = robot
    labeler = default_labeler() if labeler is None else labeler
    world_maker = default_world_maker() if world_maker is None else world_maker
    out = []
    for seed in seeds:
        world = _call_world_maker(world_maker, model, int(seed), options)
        labels = labeler(model, world, int(paths_per_world), int(seed), options)
        rec = world_record(int(seed), world, labels)
        rec["settings"] = {"options": options_dict(options),
                           "paths_per_world": int(paths_per_world),
                           "labels": rec["settings"]}
        out.append(rec)
    return out


def _plain_json(v: Any) -> Any:
    import json

    return json.loads(json.dumps(v, default=lambda o: o.tolist() if hasattr(o, "tolist")
                                 else str(o)))


#: settings that may differ between the runs filling one database (not the labels' meaning)
NEUTRAL_SETTINGS = ("device",)


def check_settings(db: PathDB, options: Any, paths_per_world: int) -> None:
    """ValueError if ``db`` holds paths made with other options or another number of
    paths per world than this run (resuming would mix them); option keys absent on either
    side and :data:`NEUTRAL_SETTINGS` are not compared."""
    want = _plain_json(options_dict(options))
    for stored in db.settings():
        diff = []
        if stored.get("paths_per_world", paths_per_world) != paths_per_world:
            diff.append(f"paths_per_world: {stored['paths_per_world']!r} in the file, "
                        f"{paths_per_world!r} now")
        old = stored.get("options", {})
        diff += [f"{k}: {old[k]!r} in the file, {v!r} now" for k, v in want.items()
                 if k in old and k not in NEUTRAL_SETTINGS and old[k] != v]
        if diff:
            raise ValueError(f"generate: '{db.path}' holds paths made with other settings "
                             f"({'; '.join(diff)}); resuming would mix them: use the same "
                             f"options or another database")


# ====================================================================== driver
def _progress(total: int, done: int, enabled: bool) -> Any:
    from tqdm.auto import tqdm

    return tqdm(total=total, initial=done, unit="path", unit_scale=True, disable=not enabled,
                dynamic_ncols=True, desc="paths", smoothing=0.1)


def generate(robot: RobotModel, n_worlds: int, paths_per_world: int, db: str | os.PathLike | PathDB,
             *, first_seed: int = 0, chunk: int | None = None, options: Any = None,
             ray: bool = False, ray_address: str | None = None, num_gpus: float = 0,
             num_cpus: int | None = None, labeler: Callable | None = None,
             world_maker: Callable | None = None, progress: bool = True,
             max_retries: int = 3, bps: Any = None, timeout: float = 30.0) -> GenerateReport:
    """Label the worlds ``first_seed .. first_seed + n_worlds - 1`` with ``paths_per_world``
    paths each into the database ``db`` (a path: created for ``robot`` if missing, checked
    against ``robot``/``bps`` if present; or an open :class:`PathDB`). Module docstring:
    chunks, resuming, Ray (``ray``, ``ray_address``, ``num_gpus``, ``num_cpus`` of a
    local instance, ``max_retries``). ``options``: the labeller's options (default
    ``PlanDataOptions()`` of the default labeller), stored with every path. ``progress``:
    a tqdm bar (paths, paths/s, ETA). Returns a :class:`GenerateReport`."""
    if n_worlds < 1 or paths_per_world < 1:
        raise ValueError(f"generate: n_worlds and paths_per_world must be >= 1, got "
                         f"{n_worlds}, {paths_per_world}")
    if first_seed < 0:
        raise ValueError(f"generate: first_seed must be >= 0, got {first_seed}")
    chunk = DEFAULT_CHUNK if chunk is None else int(chunk)
    if chunk < 1:
        raise ValueError(f"generate: chunk must be >= 1, got {chunk}")
    if options is None and labeler is None:
        options = default_options()
    rmod = ray_module() if (ray or ray_address) else None  # fail before any work
    t0 = time.perf_counter()
    own = not isinstance(db, PathDB)
    pdb = (db if isinstance(db, PathDB)
           else PathDB(db, robot, bps=bps, create=True, timeout=timeout))
    report = GenerateReport(db=str(pdb.path), backend="ray" if rmod else "in-process")
    try:
        check_settings(pdb, options, paths_per_world)
        done = pdb.complete_worlds()
        seeds = [s for s in range(first_seed, first_seed + n_worlds) if s not in done]
        report.worlds_skipped = n_worlds - len(seeds)
        chunks = [seeds[i:i + chunk] for i in range(0, len(seeds), chunk)]
        bar = _progress(n_worlds * paths_per_world, report.worlds_skipped * paths_per_world,
                        progress)
        try:
            def write(recs: list[WorldRecord]) -> None:
                for rec in recs:
                    if pdb.add_world(rec):
                        report.worlds_written += 1
                        report.paths_written += len(rec["cost"])
                    bar.update(paths_per_world)
                bar.set_postfix(worlds=f"{report.worlds_written + report.worlds_skipped}"
                                       f"/{n_worlds}", refresh=False)

            if rmod is None:
                for c in chunks:
                    for s in c:  # one world at a time: written as soon as it is labelled
                        write(label_chunk(robot, [s], paths_per_world, options, labeler,
                                          world_maker))
            else:
                _run_ray(rmod, chunks, robot, paths_per_world, options, labeler,
                         world_maker, write, report, ray_address=ray_address,
                         num_gpus=num_gpus, num_cpus=num_cpus, max_retries=max_retries)
        finally:
            bar.close()
    finally:
        if own:
            pdb.close()
    report.seconds = time.perf_counter() - t0
    return report


def _run_ray(ray: Any, chunks: list[list[int]], robot: RobotModel, paths_per_world: int,
             options: Any, labeler: Any, world_maker: Any, write: Callable,
             report: GenerateReport, *, ray_address: str | None, num_gpus: float,
             num_cpus: int | None, max_retries: int) -> None:
    started = False
    if not ray.is_initialized():
        kw: dict[str, Any] = {"address": ray_address, "ignore_reinit_error": True,
                              "include_dashboard": False, "log_to_driver": True}
        if ray_address is None and num_cpus is not None:
            kw["num_cpus"] = int(num_cpus)
        if ray_address is None:  # a local instance: its workers import this jwarp
            root = str(Path(__file__).resolve().parents[2])
            pp = os.pathsep.join(p for p in (root, os.environ.get("PYTHONPATH", "")) if p)
            kw["runtime_env"] = {"env_vars": {"PYTHONPATH": pp}}
        ray.init(**kw)
        started = True
    pending: dict[Any, tuple[list[int], int]] = {}
    try:
        task = ray.remote(label_chunk).options(num_cpus=1, num_gpus=num_gpus,
                                               max_retries=max_retries,
                                               retry_exceptions=False)
        # the big, shared arguments once in the object store
        args = [ray.put(robot), ray.put(options), ray.put(labeler), ray.put(world_maker)]

        def submit(c: list[int]) -> Any:
            return task.remote(args[0], c, paths_per_world, args[1], args[2], args[3])

        pending.update({submit(c): (c, 0) for c in chunks})
        while pending:
            ready, _ = ray.wait(list(pending), num_returns=1)
            ref = ready[0]
            c, tries = pending.pop(ref)
            try:
                recs = ray.get(ref)
            except (ray.exceptions.RayTaskError, ray.exceptions.WorkerCrashedError,
                    ray.exceptions.RayError) as e:
                if tries >= max_retries:
                    report.failed.append(c)
                    raise RuntimeError(f"generate: the chunk of world seeds {c[0]}..{c[-1]} "
                                       f"failed {tries + 1} times; the worlds written so far "
                                       f"are kept, rerun to resume ({type(e).__name__}: "
                                       f"{str(e).splitlines()[0] if str(e) else ''})") from e
                report.retried_chunks += 1
                pending[submit(c)] = (c, tries + 1)
                continue
            write(recs)
    finally:
        for ref in list(pending):  # an error left these running
            try:
                ray.cancel(ref, force=True)
            except Exception:  # noqa: BLE001 - already finished or gone
                pass
        if started:
            ray.shutdown()
