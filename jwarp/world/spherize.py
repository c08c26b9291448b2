"""Collision model of an imported URDF robot: spheres fitted to every link's collision
geometry and the self-collision pairs sampled as MoveIt's setup assistant does
(docs/urdf.md, "Collision model").

:func:`spherize` takes a :class:`~jwarp.importers.robot.UrdfRobot` (the kinematic import:
links as frames, URDF sphere geometry already as spheres) and

1. fits spheres (:func:`jwarp.importers.spheres.fit_link`, one-sided error <= ``tolerance``
   on fresh surface samples) to every link's other collision geometry (boxes, cylinders,
   capsules, meshes); links whose geometry is all spheres ("spherized" URDFs) keep them
   as they are;
2. excludes the self-collision pairs that are adjacent (through fixed joints too) or never /
   always in collision over ``pair_samples`` random configurations
   (:func:`jwarp.world.self_pairs.never_colliding_pairs`).

:func:`spherized_robot` does it for a URDF file, cached on disk by the URDF's text, its mesh
files' bytes and the options (``$JWARP_CACHE`` or ``~/.cache/jwarp``), since fitting a
Panda takes seconds. ``jwarp import-urdf --spheres fit`` and ``--robot x.urdf`` on the
planning commands use it.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from jwarp.atomic import atomic_write_text
from jwarp.model import RobotModel, Sphere
from jwarp.world.self_pairs import SelfPairs, never_colliding_pairs, with_self_pairs

__all__ = ["SpherizeOptions", "SpherizeReport", "spherize", "spherized_robot"]

#: bump when the fitted result of the same inputs changes
CACHE_VERSION = 1


@dataclass
class SpherizeOptions:
    """Options of :func:`spherize`; :meth:`validate` raises ValueError/TypeError naming the
    field.

    tolerance: one-sided error [m] of the fitted spheres (every surface point within this
        distance of a sphere) and each sphere's reach past the surface, > 0.
    max_spheres: None (the fewest spheres meeting ``tolerance``) or the most spheres per
        collision geometry (the fit then reports the error it reached).
    pair_samples: random configurations of the self-collision pair sampling, >= 1.
    pair_margin: distance [m] below which a sampled pair counts as colliding, >= 0.
    seed: seed of the fit and of the pair sampling.
    """

    tolerance: float = 0.01
    max_spheres: int | None = None
    pair_samples: int = 10000
    pair_margin: float = 0.0
    seed: int = 0

    def validate(self) -> None:
        for name, strict in (("tolerance", True), ("pair_margin", False)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer)):
                raise TypeError(f"{name}: expected a number [m], got {type(v).__name__}")
            if not math.isfinite(v) or v < 0 or (strict and v == 0):
                raise ValueError(f"{name}: expected a finite distance {'>' if strict else '>='} "
                                 f"0 [m], got {v!r}")
        for name, lo, none in (("max_spheres", 1, True), ("pair_samples", 1, False),
                               ("seed", 0, False)):
            v = getattr(self, name)
            if v is None and none:
                continue
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < lo:
                raise ValueError(f"{name}: expected an integer >= {lo}"
                                 f"{' or None' if none else ''}, got {v!r}")


@dataclass
class SpherizeReport:
    """What :func:`spherize` did. ``links``: one row per link with collision geometry:
    ``{link, geometries, spheres, one_sided_error [m], meets_tolerance, excess_fraction,
    kept (URDF spheres taken as they are)}``; ``pairs``: the sampled self pairs (None when
    read from the cache); ``cached``: the model came from the disk cache."""

    links: list[dict] = field(default_factory=list)
    pairs: SelfPairs | None = None
    cached: bool = False

    @property
    def n_spheres(self) -> int:
        return int(sum(r["spheres"] for r in self.links))

    def to_dict(self) -> dict:
        out: dict[str, Any] = {"links": self.links, "spheres": self.n_spheres,
                               "cached": self.cached}
        if self.pairs is not None:
            out["excluded_pairs"] = len(self.pairs.exclude_pairs)
        return out


def _geometry(g: Any) -> dict:
    mesh = None
    if g.kind == "mesh":
        # an in-memory mesh (MJCF import) or the file (ValueError naming the link when missing)
        mesh = g.mesh if getattr(g, "mesh", None) is not None else g.mesh_file()
    return {"kind": g.kind, "size": g.size, "origin": g.origin, "mesh": mesh,
            "scale": g.scale if g.kind == "mesh" else None}


def spherize(urdf_robot: Any, options: SpherizeOptions | None = None
             ) -> tuple[RobotModel, SpherizeReport]:
    """The collision model of an imported URDF (module docstring): a copy of
    ``urdf_robot.model`` with fitted spheres and sampled self-collision exclusions, and the
    report."""
    from jwarp.importers.spheres import fit_link

    o = SpherizeOptions() if options is None else options
    if not isinstance(o, SpherizeOptions):
        raise TypeError(f"options: expected a SpherizeOptions, got {type(o).__name__}")
    o.validate()
    model: RobotModel = urdf_robot.model
    by_link: dict[str, list] = {}
    for g in urdf_robot.geometries:
        by_link.setdefault(g.link, []).append(g)
    spheres = list(model.spheres)
    report = SpherizeReport()
    fit_opts = {"seed": int(o.seed)}
    if o.max_spheres is not None:
        fit_opts["max_spheres"] = int(o.max_spheres)
    for link, geoms in by_link.items():
        frame = model.frame_index(link)
        todo = [g for g in geoms if g.kind != "sphere"]
        if not todo:  # a spherized link: its spheres are already the model's
            report.links.append({"link": link, "geometries": len(geoms), "spheres": len(geoms),
                                 "one_sided_error": 0.0, "meets_tolerance": True,
                                 "excess_fraction": 0.0, "kept": True})
            continue
        try:
            fit = fit_link([_geometry(g) for g in todo], tolerance=float(o.tolerance),
                           **fit_opts)
        except (ValueError, TypeError) as e:
            raise type(e)(f"link '{link}': {e}") from e
        spheres += [Sphere(frame=frame, position=np.asarray(c, np.float64), radius=float(r))
                    for c, r in zip(fit.centres, fit.radii)]
        report.links.append({"link": link, "geometries": len(geoms),
                             "spheres": int(len(fit.radii)) + len(geoms) - len(todo),
                             "one_sided_error": float(fit.one_sided_error),
                             "meets_tolerance": bool(fit.meets_tolerance),
                             "excess_fraction": float(fit.excess_fraction), "kept": False})
    fitted = model.copy(spheres=spheres)
    if len(spheres):
        pairs = never_colliding_pairs(fitted, n_samples=int(o.pair_samples), seed=int(o.seed),
                                      margin=float(o.pair_margin))
        fitted = with_self_pairs(fitted, pairs)
        report.pairs = pairs
    return fitted, report


def _cache_dir() -> Path:
    root = os.environ.get("JWARP_CACHE")
    return Path(root) if root else Path.home() / ".cache" / "jwarp"


def _cache_key(urdf_robot: Any, path: str, options: SpherizeOptions, urdf_options: dict) -> str:
    h = hashlib.sha256()
    h.update(f"jwarp-spherize-{CACHE_VERSION}".encode())
    h.update(Path(path).read_bytes())
    for g in urdf_robot.geometries:
        if g.kind == "mesh" and g.mesh_path is not None and os.path.isfile(g.mesh_path):
            h.update(Path(g.mesh_path).read_bytes())
    h.update(json.dumps(asdict(options), sort_keys=True).encode())
    h.update(json.dumps(urdf_options, sort_keys=True, default=str).encode())
    return h.hexdigest()[:32]


def spherized_robot(path: str | os.PathLike, options: SpherizeOptions | None = None, *,
                    cache: bool = True, **urdf_options: Any) -> tuple[RobotModel, SpherizeReport]:
    """:func:`spherize` of the URDF file ``path`` (``urdf_options``: the fields of
    :class:`~jwarp.importers.urdf.UrdfOptions`, e.g. ``package_dirs``, ``end_effectors``).
    With ``cache`` the result is read from / written to the disk cache (module docstring;
    a cache file that does not load is recomputed and replaced)."""
    from jwarp.importers.robot import load_urdf

    o = SpherizeOptions() if options is None else options
    if not isinstance(o, SpherizeOptions):
        raise TypeError(f"options: expected a SpherizeOptions, got {type(o).__name__}")
    o.validate()
    imported = load_urdf(path, **urdf_options)
    file = None
    if cache:
        file = _cache_dir() / "urdf" / f"{_cache_key(imported, os.fspath(path), o, urdf_options)}.json"
        if file.is_file():
            try:
                doc = json.loads(file.read_text())
                model = RobotModel.from_dict(doc["robot"])
                return model, SpherizeReport(links=doc["links"], cached=True)
            except (OSError, ValueError, KeyError, TypeError):
                pass  # a damaged cache entry: recompute
    model, report = spherize(imported, o)
    if file is not None:
        try:
            file.parent.mkdir(parents=True, exist_ok=True)
            atomic_write_text(file, json.dumps({"robot": model.to_dict(), "links": report.links}))
        except OSError:
            pass  # a read-only home: no cache, same result
    return model, report
