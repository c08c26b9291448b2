"""World files (``.npz``) and the world specification strings of the CLI.

File format ``jwarp.world`` version 1 (numpy ``.npz``, compressed, no pickles):

* ``format``     str  "jwarp.world"
* ``version``    int  1
* ``sdf``        (nx, ny[, nz]) float32/float64 [m], negative inside obstacles
* ``limits``     (dim, 2) float64 [m] first and last cell centre per axis
* ``voxel_size`` float64 [m]
* ``occupancy``  bool grid (optional)
* ``meta``       str  JSON object (optional)

World specifications (:func:`parse_world_spec`): ``"simplex:seed=3,threshold=0.4"``
or a path to a ``.npz`` file.
"""

from __future__ import annotations

import json
import os
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from jwarp.atomic import AtomicFile
from jwarp.world.sdf import World

__all__ = ["FORMAT", "VERSION", "save_world", "load_world", "parse_world_spec", "SPEC_KEYS"]

FORMAT = "jwarp.world"
VERSION = 1


def save_world(world: World, path: str | os.PathLike) -> None:
    """Write ``world`` to ``path`` (.npz) via a temporary file in the same folder and a
    rename, so readers never see a partial file."""
    if not isinstance(world, World):
        raise TypeError(f"world: expected a World, got {type(world).__name__}")
    try:
        meta = json.dumps(world.meta)
    except (TypeError, ValueError) as e:
        raise ValueError(f"world.meta: not JSON serialisable: {e}") from e
    arrays: dict[str, np.ndarray] = dict(
        format=np.array(FORMAT), version=np.array(VERSION, np.int64), sdf=world.sdf,
        limits=world.limits, voxel_size=np.array(world.voxel_size, np.float64),
        meta=np.array(meta))
    if world.occupancy is not None:
        arrays["occupancy"] = world.occupancy
    with AtomicFile(path) as f:
        with open(f.tmp, "wb") as fh:
            np.savez_compressed(fh, **arrays)
            fh.flush()
            os.fsync(fh.fileno())


def load_world(path: str | os.PathLike) -> World:
    """Read a world written by :func:`save_world`. Any malformed or unreadable file
    raises ValueError naming the file and the problem."""
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as z:
            data = {k: z[k] for k in z.files}
    except FileNotFoundError as e:
        raise ValueError(f"path: world file '{path}' does not exist") from e
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, KeyError) as e:
        raise ValueError(f"{path}: not a readable .npz world file: {e}") from e
    if not isinstance(data, dict) or "format" not in data:
        raise ValueError(f"{path}: not a jwarp world file (no 'format' entry)")
    if str(data["format"]) != FORMAT:
        raise ValueError(f"{path}: format '{data['format']}' is not '{FORMAT}'")
    try:
        version = int(data.get("version", -1))
    except (TypeError, ValueError) as e:
        raise ValueError(f"{path}: malformed 'version'") from e
    if version != VERSION:
        raise ValueError(f"{path}: unsupported world file version {version} (expected {VERSION})")
    for key in ("sdf", "limits", "voxel_size"):
        if key not in data:
            raise ValueError(f"{path}: missing '{key}'")
    meta: dict = {}
    if "meta" in data:
        try:
            meta = json.loads(str(data["meta"]))
        except json.JSONDecodeError as e:
            raise ValueError(f"{path}: 'meta' is not valid JSON: {e}") from e
        if not isinstance(meta, dict):
            raise ValueError(f"{path}: 'meta' is not a JSON object")
    try:
        if data["voxel_size"].shape != ():
            raise ValueError(f"voxel_size: expected a scalar, got shape {data['voxel_size'].shape}")
        if data["sdf"].dtype not in (np.float32, np.float64):
            raise ValueError(f"sdf: expected float32 or float64, got {data['sdf'].dtype}")
        return World(data["sdf"], data["limits"], float(data["voxel_size"]),
                     data.get("occupancy"), meta)
    except (TypeError, ValueError) as e:
        raise ValueError(f"{path}: {e}") from e


#: keys of a ``simplex:`` specification and their types
SPEC_KEYS = {
    "seed": int, "threshold": float, "frequency": float, "octaves": int,
    "persistence": float, "dim": int, "cells": int, "voxel": float, "feasible": int,
    "samples": int, "tries": int, "clear_base": int,
}


def parse_world_spec(spec: Any, robot: Any = None) -> World:
    """A world from a specification (the CLI's ``--world``).

    * a :class:`World` passes through;
    * ``"path/to/world.npz"``: :func:`load_world`;
    * ``"simplex"`` or ``"simplex:key=value,..."`` with keys
      ``seed`` (default 0), ``threshold`` (0.6), ``frequency`` (2), ``octaves`` (1),
      ``persistence`` (0.5), ``dim`` (robot's workspace dimension, else 3),
      ``cells`` (64: cells along the longest axis), ``voxel`` [m] (instead of cells),
      ``feasible`` (0: if > 0, search seeds from ``seed`` on until that many of
      ``samples`` (1000) random configurations are collision-free, at most ``tries`` (50)
      seeds), ``clear_base`` (1: keep the robot's fixed spheres free of obstacles).

    With a ``robot`` the grid covers the robot's reach (:func:`robot_world_grid`),
    otherwise [-1, 1] m per axis. ``feasible`` needs a robot. A world of the wrong
    dimension for the robot raises ValueError.
    """
    from jwarp.collision import check_world
    from jwarp.registry import robot as get_robot

    model = None if robot is None else get_robot(robot)
    if isinstance(spec, World):
        world = spec
    elif isinstance(spec, (str, os.PathLike)):
        text = os.fspath(spec).strip()
        head, _, rest = text.partition(":")
        if head.lower() == "simplex":
            world = _simplex_from_spec(rest, model, text)
        else:
            if not text.lower().endswith(".npz"):
                raise ValueError(f"world: expected 'simplex[:key=value,...]' or a .npz file, "
                                 f"got '{text}'")
            world = load_world(text)
    else:
        raise TypeError(f"world: expected a specification string, path or World, got "
                        f"{type(spec).__name__}")
    if model is not None:
        check_world(model, world)
    return world


def _simplex_from_spec(rest: str, model: Any, text: str) -> World:
    from jwarp.world.feasibility import feasible_simplex_world, fixed_spheres, robot_world_grid
    from jwarp.world.simplex import simplex_world

    opts: dict[str, Any] = {}
    for item in filter(None, (s.strip() for s in rest.split(","))):
        key, eq, value = item.partition("=")
        key = key.strip().lower()
        if not eq:
            raise ValueError(f"world: '{item}' in '{text}' is not key=value")
        if key not in SPEC_KEYS:
            raise ValueError(f"world: unknown key '{key}' in '{text}'; known: {', '.join(SPEC_KEYS)}")
        try:
            opts[key] = SPEC_KEYS[key](value.strip())
        except ValueError as e:
            raise ValueError(f"world: bad value for '{key}' in '{text}': {value!r}") from e
    dim = opts.pop("dim", model.workspace_dim if model is not None else 3)
    if dim not in (2, 3):
        raise ValueError(f"world: dim must be 2 or 3, got {dim}")
    cells = opts.pop("cells", 64)
    voxel = opts.pop("voxel", None)
    feasible = opts.pop("feasible", 0)
    samples = opts.pop("samples", 1000)
    tries = opts.pop("tries", 50)
    clear_base = bool(opts.pop("clear_base", 1))
    seed = opts.pop("seed", 0)
    noise = opts  # threshold, frequency, octaves, persistence
    if feasible > 0:
        if model is None:
            raise ValueError(f"world: 'feasible' in '{text}' needs a robot")
        world = feasible_simplex_world(model, seed=seed, min_feasible=feasible, n=samples,
                                       max_tries=tries, cells=cells, voxel_size=voxel,
                                       clear_base=clear_base, dim=dim, **noise)
    else:
        if model is not None and dim == model.workspace_dim:
            shape, limits, h = robot_world_grid(model, cells=cells, voxel_size=voxel)
            keep = fixed_spheres(model, pad=2 * h) if clear_base else []
            world = simplex_world(dim, seed=seed, shape=shape, limits=limits, keep_free=keep,
                                  **noise)
        else:
            shape = None if voxel is not None else (cells,) * dim
            world = simplex_world(dim, seed=seed, shape=shape,
                                  limits=np.array([[-1.0, 1.0]] * dim), voxel_size=voxel,
                                  **noise)
    world.meta["spec"] = text
    return world
