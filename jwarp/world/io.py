"""World specification strings of the CLI, and the world files (``.npz``; their format and
:func:`save_world` / :func:`load_world` live beside :class:`~jwarp.world.sdf.World` in
:mod:`jwarp.world.sdf`, re-exported here).

World specifications (:func:`parse_world_spec`): ``"simplex:seed=3,threshold=0.4"``
or a path to a ``.npz`` file.
"""

from __future__ import annotations

import math
import os
from typing import TYPE_CHECKING, Any

import numpy as np

from jwarp.core.types import DeviceLike
from jwarp.world.sdf import FORMAT, VERSION, World, load_world, save_world

if TYPE_CHECKING:
    from jwarp.model import RobotModel

__all__ = ["FORMAT", "VERSION", "save_world", "load_world", "parse_world_spec", "SPEC_KEYS"]

#: keys of a ``simplex:`` specification and their types
SPEC_KEYS = {
    "seed": int, "threshold": float, "frequency": float, "octaves": int,
    "persistence": float, "dim": int, "cells": int, "voxel": float, "feasible": int,
    "samples": int, "tries": int, "clear_base": int,
}


def parse_world_spec(spec: Any, robot: RobotModel | None = None, device: DeviceLike = None) -> World:
    """A world from a specification (the CLI's ``--world``).

    * a :class:`World` passes through;
    * ``"path/to/world.npz"``: :func:`load_world`;
    * ``"simplex"`` or ``"simplex:key=value,..."`` with keys
      ``seed`` (default 0), ``threshold`` (0.6), ``frequency`` (2), ``octaves`` (1),
      ``persistence`` (0.5), ``dim`` (robot's workspace dimension, else 3),
      ``cells`` (64: cells along the longest axis), ``voxel`` [m] (instead of cells),
      ``feasible`` (0: if > 0, search seeds from ``seed`` on until that many of
      ``samples`` (1000) random configurations are collision-free, at most ``tries`` (50)
      seeds), ``clear_base`` (1: keep the robot's fixed spheres free of obstacles);
    * ``"shelf"`` or ``"shelf:voxel=V"``: the shelf scene
      (:func:`jwarp.world.scenes.shelf_world`, voxel size V [m], default 0.04; 3D robots).

    With a ``robot`` the grid covers the robot's reach (:func:`robot_world_grid`),
    otherwise [-1, 1] m per axis. ``feasible`` needs a robot. A world of the wrong
    dimension for the robot raises ValueError.

    ``device``: the Warp device of the robot computations that build a ``simplex`` world
    (its reach, fixed spheres and the ``feasible`` collision checks; None: Warp's default
    device, as before). A world itself is host data (numpy); files and World objects
    need no device.

    Raises:
        ValueError: an unknown or repeated key, a value that is not a number, NaN/inf,
            out of range (``cells`` >= 2, ``voxel`` > 0, ``seed``/``feasible`` >= 0,
            ``samples``/``tries`` >= 1, ``clear_base`` 0 or 1), ``cells`` with ``voxel``,
            ``samples``/``tries`` without ``feasible``; a malformed world file.
        MemoryError: the grid (about :data:`BYTES_PER_CELL` per cell) or the ``feasible``
            samples would need more than the available memory; checked before anything
            is allocated, the message gives the grid and the figure.
    """
    from jwarp.world.collision import check_world

    model = robot
    if isinstance(spec, World):
        world = spec
    elif isinstance(spec, (str, os.PathLike)):
        text = os.fspath(spec).strip()
        head, _, rest = text.partition(":")
        if head.lower() == "simplex":
            world = _simplex_from_spec(rest, model, text, device)
        elif head.lower() == "shelf":
            world = _shelf_from_spec(rest, text)
        else:
            if not text.lower().endswith(".npz"):
                raise ValueError(f"world: expected 'simplex[:key=value,...]', "
                                 f"'shelf[:voxel=V]' or a .npz file, got '{text}'")
            world = load_world(text)
    else:
        raise TypeError(f"world: expected a specification string, path or World, got "
                        f"{type(spec).__name__}")
    if model is not None:
        check_world(model, world)
    return world


def _shelf_from_spec(rest: str, text: str) -> World:
    """The shelf scene of ``shelf[:voxel=V]``."""
    from jwarp.world.scenes import shelf_world

    voxel = 0.04
    if rest.strip():
        key, eq, value = rest.strip().partition("=")
        if key.strip() != "voxel" or not eq:
            raise ValueError(f"world: shelf takes only voxel=V [m], got '{text}'")
        try:
            voxel = float(value)
        except ValueError:
            raise ValueError(f"world: voxel: expected a number [m], got '{value}'") from None
    try:
        return shelf_world(voxel)
    except ValueError as e:
        raise ValueError(f"world: {e}") from None


#: peak memory of a simplex world per grid cell [bytes]: the noise's float64 temporaries,
#: the occupancy, the two distance transforms and the SDF (measured about 250 B in 2D and
#: 340 B in 3D)
BYTES_PER_CELL = 400
#: memory of a ``feasible`` search per sampled configuration [bytes] per robot frame (the
#: collision check's frames, float64 4x4, and their copies)
BYTES_PER_SAMPLE_FRAME = 4 * 128


def _spec_int(key: str, v: Any, lo: int, hi: int | None = None) -> int:
    if v < lo or (hi is not None and v > hi):
        rng = f">= {lo}" if hi is None else f"in [{lo}, {hi}]"
        raise ValueError(f"world: {key}: expected an integer {rng}, got {v}")
    return int(v)


def _grid_size(model: RobotModel | None, dim: int, cells: int | None, voxel: float | None,
               device: DeviceLike = None) -> list[float]:
    """The grid sizes (per axis, as floats: nothing is allocated) a simplex spec makes."""
    if model is not None and dim == model.workspace_dim:
        from jwarp.world.feasibility import robot_reach

        span = np.diff(robot_reach(model, device=device), axis=1)[:, 0]
        h = voxel if voxel is not None else float(span.max()) / (cells - 1)
        return [math.ceil(s / h - 1e-9) + 1.0 for s in span.tolist()]
    if voxel is not None:
        return [math.floor(2.0 / voxel + 1e-6) + 1.0] * dim
    return [float(cells)] * dim


def _grid_text(sizes: list[float]) -> str:
    fmt = [f"{s:.0f}" if s < 1e15 else f"{s:.3g}" for s in sizes]
    return f"{fmt[0]}^{len(fmt)}" if len(set(fmt)) == 1 else " x ".join(fmt)


def _simplex_from_spec(rest: str, model: RobotModel, text: str, device: DeviceLike = None) -> World:
    from jwarp.utils.memory import check_memory
    from jwarp.world.feasibility import (
        feasible_simplex_world,
        fixed_spheres,
        robot_world_grid,
    )
    from jwarp.world.simplex import simplex_world

    opts: dict[str, Any] = {}
    for item in filter(None, (s.strip() for s in rest.split(","))):
        key, eq, value = item.partition("=")
        key = key.strip().lower()
        if not eq:
            raise ValueError(f"world: '{item}' in '{text}' is not key=value")
        if key not in SPEC_KEYS:
            raise ValueError(f"world: unknown key '{key}' in '{text}'; known: {', '.join(SPEC_KEYS)}")
        if key in opts:
            raise ValueError(f"world: key '{key}' given twice in '{text}'")
        try:
            opts[key] = SPEC_KEYS[key](value.strip())
        except ValueError as e:
            raise ValueError(f"world: bad value for '{key}' in '{text}': {value!r}") from e
        if isinstance(opts[key], float) and not math.isfinite(opts[key]):
            raise ValueError(f"world: {key}: expected a finite number, got {value.strip()}")
    dim = opts.pop("dim", model.workspace_dim if model is not None else 3)
    if dim not in (2, 3):
        raise ValueError(f"world: dim must be 2 or 3, got {dim}")
    if "cells" in opts and "voxel" in opts:
        raise ValueError(f"world: give 'cells' or 'voxel', not both, in '{text}'")
    cells = _spec_int("cells", opts.pop("cells", 64), 2)
    voxel = opts.pop("voxel", None)
    if voxel is not None and not voxel > 0:
        raise ValueError(f"world: voxel: expected a positive size [m], got {voxel:g}")
    feasible = _spec_int("feasible", opts.pop("feasible", 0), 0)
    for key in ("samples", "tries"):
        if key in opts and feasible == 0:
            raise ValueError(f"world: '{key}' in '{text}' is only meaningful with feasible=N")
    samples = _spec_int("samples", opts.pop("samples", 1000), 1)
    tries = _spec_int("tries", opts.pop("tries", 50), 1)
    if feasible > samples:
        raise ValueError(f"world: feasible: expected at most samples={samples} "
                         f"collision-free configurations, got {feasible}")
    clear_base = bool(_spec_int("clear_base", opts.pop("clear_base", 1), 0, 1))
    seed = _spec_int("seed", opts.pop("seed", 0), 0)
    noise = opts  # threshold, frequency, octaves, persistence
    if feasible > 0 and model is None:
        raise ValueError(f"world: 'feasible' in '{text}' needs a robot")
    sizes = _grid_size(model, dim, None if voxel is not None else cells, voxel, device)
    n_cells = math.prod(sizes)
    check_memory(n_cells * BYTES_PER_CELL, f"world: '{text}': a {_grid_text(sizes)} grid",
                 "lower 'cells' (or raise 'voxel')")
    if feasible > 0:
        check_memory(samples * model.n_frames * BYTES_PER_SAMPLE_FRAME,
                     f"world: '{text}': checking {samples} sampled configurations",
                     "lower 'samples'")
        world = feasible_simplex_world(model, seed=seed, min_feasible=feasible, n=samples,
                                       max_tries=tries, cells=cells, voxel_size=voxel,
                                       clear_base=clear_base, dim=dim, device=device, **noise)
    else:
        shape: tuple[int, ...] | None
        if model is not None and dim == model.workspace_dim:
            shape, limits, h = robot_world_grid(model, cells=cells, voxel_size=voxel,
                                                device=device)
            keep = fixed_spheres(model, pad=2 * h, device=device) if clear_base else []
            world = simplex_world(dim, seed=seed, shape=shape, limits=limits, keep_free=keep,
                                  **noise)
        else:
            shape = None if voxel is not None else (cells,) * dim
            world = simplex_world(dim, seed=seed, shape=shape,
                                  limits=np.array([[-1.0, 1.0]] * dim), voxel_size=voxel,
                                  **noise)
    world.meta["spec"] = text
    return world
