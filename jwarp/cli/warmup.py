"""``jwarp warmup``: compile every jwarp kernel family ahead of time into Warp's kernel
cache, so that no later command or script waits for a compiler (docs/install.md,
"Kernel cache").

Kernel families (``--families``; each in float32 and float64 unless ``--dtype``):

* ``fk``: forward kinematics, frame Jacobians and DH-parameter Jacobians;
* ``elastic``: elastic FK (equilibrium iteration, compensation);
* ``geometry``: world shapes (signed distances of boxes, spheres, meshes, ...);
* ``collision``: self- and world-collision costs and checks;
* ``path``: the planner's path cost, gradient and projection (and its Cartesian terms);
* ``motion``: the continuous motion checks;
* ``ik``: the IK cost and the damped-least-squares step (the step is built per robot:
  its degrees of freedom and whether it is planar, hence ``--robots``);
* ``calibration``: the visibility kernels of measurement-pose sampling (calibration
  itself runs on ``fk`` and ``elastic``).

A kernel's binary is found again by the hash of its source and options, so a warm cache
stays valid until jwarp or Warp changes; ``WARP_CACHE_PATH`` moves the cache.

Python: :func:`warmup` (also ``jwarp.warmup``).
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Iterable
from dataclasses import dataclass, field
from types import SimpleNamespace
from typing import TYPE_CHECKING, Any

from jwarp.cli.common import CLIError, check_device, int_arg
from jwarp.utils.checks import check_int

if TYPE_CHECKING:
    from jwarp.core.types import DeviceLike
    from jwarp.model import RobotModel

__all__ = ["DTYPES", "FAMILIES", "WarmupReport", "add_subcommands", "kernel_modules", "warmup"]

#: the kernel families, in the order they are compiled
FAMILIES = ("fk", "elastic", "geometry", "collision", "path", "motion", "ik", "calibration",
            "learn", "spherize")
#: the float types every family is built in (the public API follows its input's dtype)
DTYPES = ("float32", "float64")


@dataclass
class WarmupReport:
    """What :func:`warmup` did: ``modules`` Warp modules loaded on ``device``, of which
    ``compiled`` were compiled now (the rest came from the cache), in ``seconds`` [s];
    ``cache_dir`` the kernel cache; ``families``, ``dtypes`` and ``robots`` as resolved."""

    device: str
    cache_dir: str
    families: list[str]
    dtypes: list[str]
    robots: list[str]
    modules: int
    compiled: int
    seconds: float
    compiled_names: list[str] = field(default_factory=list)


def _kernels_of(obj: Any) -> list[Any]:
    """The ``wp.Kernel`` objects of a kernel namespace (attributes, also inside dicts,
    lists and tuples)."""
    import warp as wp

    found: list[Any] = []
    values = list(vars(obj).values()) if hasattr(obj, "__dict__") else []
    while values:
        v = values.pop(0)
        if isinstance(v, wp.Kernel):
            found.append(v)
        elif isinstance(v, dict):
            values.extend(v.values())
        elif isinstance(v, (list, tuple)):
            values.extend(v)
    return found


def _check_names(values: Iterable[str], allowed: Iterable[str], option: str) -> list[str]:
    allowed = list(allowed)
    out: list[str] = []
    for v in values:
        if v not in allowed:
            raise ValueError(f"{option}: unknown value {v!r}; expected some of "
                             f"{', '.join(allowed)}")
        if v not in out:
            out.append(v)
    if not out:
        raise ValueError(f"{option}: expected at least one of {', '.join(allowed)}")
    return out


def kernel_modules(families: Iterable[str] = FAMILIES, dtypes: Iterable[str] = DTYPES,
                   robots: Iterable[Any] = ()) -> list[Any]:
    """The Warp modules (one per kernel) of the kernel ``families`` in ``dtypes``; the IK
    step's for each robot of ``robots`` (names or RobotModels). Defining them compiles
    nothing. Raises ValueError naming ``families``/``dtypes`` for an unknown entry."""
    import warp as wp

    from jwarp.kernels import (
        collision,
        collision_wide,
        elastic,
        fk,
        geometry,
        ik,
        ik_step,
        motion,
        path,
        visibility,
    )
    from jwarp.plugins.registry import robot as get_robot

    families = _check_names(families, FAMILIES, "families")
    dtypes = _check_names(dtypes, DTYPES, "dtypes")
    models = [r if not isinstance(r, str) else get_robot(r) for r in robots]
    spaces: list[Any] = []
    for name in dtypes:
        sc = wp.float32 if name == "float32" else wp.float64
        for fam in families:
            if fam == "fk":
                spaces.append(fk.kernels(sc))
            elif fam == "elastic":
                spaces.append(elastic.kernels(sc))
            elif fam == "geometry":
                spaces.append(geometry.kernels(sc))
            elif fam == "collision":
                spaces += [collision.kernels(sc), collision_wide.kernels(sc)]
            elif fam == "path":
                spaces += [path.kernels(sc), path.cartesian_kernels(sc)]
            elif fam == "motion":
                spaces.append(motion.kernels(sc))
            elif fam == "ik":
                spaces.append(ik.kernels(sc))
                shapes = sorted({(m.workspace_dim == 2, int(m.n_dof)) for m in models})
                for planar in sorted({p for p, _ in shapes}):
                    spaces.append(ik_step.check_kernels(sc, planar))
                for planar, n_dof in shapes:
                    spaces.append(ik_step.dls_kernels(sc, planar, n_dof))
            elif fam == "calibration":
                spaces.append(visibility.kernels(sc))
            elif fam == "learn":  # the basis point set encoding of jwarp train (float32)
                from jwarp.learn import bps

                spaces.append(bps.kernels())
            elif fam == "spherize":  # the sphere fit of URDF imports (fixed types)
                from jwarp.importers import sphere_refine, spheres

                spaces.append(SimpleNamespace(
                    fit=list(spheres.fit_kernels()) + list(sphere_refine.fit_kernels())))
    modules: dict[int, Any] = {}
    for space in spaces:
        for k in _kernels_of(space):
            modules.setdefault(id(k.module), k.module)
    return list(modules.values())


def warmup(device: DeviceLike = None, robots: Iterable[str | RobotModel] | None = None,
           dtypes: Iterable[str] = DTYPES, families: Iterable[str] = FAMILIES, *,
           jobs: int | None = None, progress: bool = True) -> WarmupReport:
    """Compile (or load from the kernel cache) every kernel of ``families`` in ``dtypes``
    on ``device`` (default: CUDA if present, else the CPU), the IK step for each of
    ``robots`` (default: every registered robot), ``jobs`` modules at a time (default
    ``min(jwarp.core.threads.cpu_threads(), 4)``). ``progress``: a tqdm bar on stderr
    (terminal only).

    Returns:
        :class:`WarmupReport` (the cache folder, modules loaded and compiled, seconds).
    Raises:
        ValueError: an unknown family, dtype, robot or device (naming the argument).
    """
    import warp as wp

    from jwarp.core.arrays import resolve_device
    from jwarp.core.kernel_cache import cache_dir, compile_progress, compiled_modules
    from jwarp.plugins.registry import robots as robot_names

    t0 = time.perf_counter()
    dev = resolve_device(device)
    names = list(robot_names()) if robots is None else list(robots)
    if jobs is None:
        from jwarp.core.threads import cpu_threads

        jobs = min(cpu_threads(), 4)
    check_int(jobs, "jobs", 1)
    mods = kernel_modules(families, dtypes, names)
    before = len(compiled_modules())
    with compile_progress(len(mods), f"jwarp warmup ({dev.alias})", bar=progress) as p:
        wp.force_load(device=dev, modules=mods, max_workers=jobs if jobs > 1 else 0)
        p.update(max(len(mods) - p.n, 0))  # modules already loaded in this process
    done = compiled_modules()[before:]
    return WarmupReport(
        device=str(dev.alias), cache_dir=cache_dir(),
        families=_check_names(families, FAMILIES, "families"),
        dtypes=_check_names(dtypes, DTYPES, "dtypes"),
        robots=[n if isinstance(n, str) else n.name for n in names], modules=len(mods),
        compiled=len(done), seconds=time.perf_counter() - t0, compiled_names=done)


def _list_arg(option: str) -> Any:
    def parse(text: str) -> list[str]:
        items = [t.strip() for t in text.split(",") if t.strip()]
        if not items:
            raise CLIError(f"{option}: expected a comma-separated list, got {text!r}")
        return items

    return parse


def cmd_warmup(args: argparse.Namespace) -> int:
    from jwarp.cli.common import robot_option

    check_device(args.device)
    robots = None
    if args.robots is not None:
        robots = [robot_option(r, "--robots") for r in args.robots]
    try:
        families = _check_names(args.families, FAMILIES, "--families")
        dtypes = _check_names(args.dtype, DTYPES, "--dtype")
    except ValueError as e:
        raise CLIError(str(e)) from None
    from jwarp.core.kernel_cache import cache_dir

    print(f"jwarp warmup: compiling {', '.join(families)} ({', '.join(dtypes)}) for "
          f"{args.device or 'the default device'} into the kernel cache {cache_dir()}",
          file=sys.stderr, flush=True)
    rep = warmup(args.device, robots, dtypes, families, jobs=args.jobs)
    print(f"{rep.modules} kernel modules on {rep.device}: {rep.compiled} compiled, "
          f"{rep.modules - rep.compiled} already cached ({rep.seconds:.1f} s)")
    print(f"kernel cache: {rep.cache_dir}")
    print("  (WARP_CACHE_PATH=<dir> puts it in <dir>/<warp version>; copy that folder into "
          "an image or CI cache to skip compiling: docs/install.md)")
    return 0


def add_subcommands(sub: Any) -> None:
    """Register ``warmup`` on the CLI's subparsers."""
    s = sub.add_parser("warmup", help="compile every kernel ahead of time into Warp's kernel "
                                      "cache (first run only)",
                       description="Compile every jwarp kernel family ahead of time (into "
                                   "Warp's kernel cache; WARP_CACHE_PATH moves it) and print "
                                   "where the cache is.")
    s.add_argument("--device", default=None,
                   help="Warp device (default: cuda:0 if present, else cpu)")
    s.add_argument("--robots", type=_list_arg("--robots"), default=None, metavar="R,...",
                   help="robots whose IK step is compiled (names or robot .json/.urdf "
                        "paths; default: every registered robot)")
    s.add_argument("--dtype", type=_list_arg("--dtype"), default=list(DTYPES),
                   metavar="T,...", help="float32, float64 or both (default both)")
    s.add_argument("--families", type=_list_arg("--families"), default=list(FAMILIES),
                   metavar="F,...", help=f"kernel families (default all: {', '.join(FAMILIES)})")
    s.add_argument("--jobs", type=int_arg("--jobs", 1, 64), default=None,
                   metavar="N", help="modules compiled at a time (default min(free cores, 4): "
                                     "$JWARP_THREADS, else the cores this process may use "
                                     "less the load of others)")
    s.set_defaults(func=cmd_warmup)
