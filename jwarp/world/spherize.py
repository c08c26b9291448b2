"""Collision model of an imported URDF robot: spheres fitted to every link's collision
geometry and the self-collision pairs sampled as MoveIt's setup assistant does
(docs/urdf.md, "Collision model").

:func:`spherize` takes a :class:`~jwarp.importers.robot.UrdfRobot` (the kinematic import:
links as frames, URDF sphere geometry already as spheres) and

1. fits spheres (:func:`jwarp.importers.spheres.fit_link`: centres inside the solid by
   winding number, so open and multi-body meshes work; one-sided error <= ``tolerance``
   on fresh surface samples; each sphere reaching at most ``protrusion`` past the surface;
   at most ``max_spheres`` per link when given) to every link's other collision geometry
   (boxes, cylinders, capsules, meshes, fitted together as one part); links whose geometry
   is all spheres ("spherized" URDFs) keep them as they are; links of the same geometry
   (mesh file, scale, pose; a hand's fingers) are fitted once. A link whose fit passes a
   bound (one-sided error > ``tolerance``, largest protrusion > ``warn_protrusion``,
   excess volume > ``warn_excess`` x the part's volume) is named in
   ``SpherizeReport.warnings`` and a :class:`SphereFitWarning` is issued;
2. excludes the self-collision pairs that are adjacent (through fixed joints too) or never /
   always in collision over ``pair_samples`` random configurations
   (:func:`jwarp.world.self_pairs.never_colliding_pairs`);
3. records the convex pieces of every collision geometry beside the spheres
   (``RobotModel.collision_pieces``:
   :func:`jwarp.importers.collision_pieces.pieces_from_geometries`; hulls of the meshes,
   the primitives' corners), which a mesh certificate checks against the world.

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
import sys
import warnings
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from jwarp.model import RobotModel, Sphere, SphereRelation
from jwarp.utils.atomic import atomic_write_text
from jwarp.utils.checks import check_int
from jwarp.world.self_pairs import (
    ALWAYS_FRACTION,
    SelfPairs,
    never_colliding_pairs,
    pair_reasons,
    sampled_reasons,
    with_pair_reasons,
    with_self_pairs,
)

__all__ = ["SpherizeOptions", "SpherizeReport", "SphereFitWarning", "spherize", "certify_relation",
           "fit_relation",
           "spherized_robot", "resample_pairs"]

#: bump when the fitted result of the same inputs changes
#: Monte Carlo points of a link's excess volume at import (:func:`spherize`)
EXCESS_SAMPLES = 50_000
CACHE_VERSION = 9  # 3: mesh vertices merged, sparse cover of large parts; 4: refined fits;
#                   5: URDF axis frames named <joint>_axis, joint names frame aliases;
#                   6: MoveIt's pair rules (adjacency, always >= 95 %), reasons in notes
#                   7: containment (contain, contain_gap), sphere_relation
#                   8: collision_pieces (the geometry's convex pieces)
#                   9: containment protrusions wrist 1.5, hand 1.0 (was 1.25, 0.75)


#: the pair sampling of an import: MoveIt setup assistant's Adjacent and Always rules
#: (jwarp.world.self_pairs module docstring)
MOVEIT_RULES: dict[str, Any] = {"adjacency": "moveit", "always_fraction": ALWAYS_FRACTION}


class SphereFitWarning(UserWarning):
    """A link's fitted spheres pass a bound (error, protrusion or excess): the collision
    model may miss collisions or refuse free configurations."""


@dataclass
class SpherizeOptions:
    """Options of :func:`spherize`; :meth:`validate` raises ValueError/TypeError naming the
    field.

    tolerance: one-sided error [m] of the fitted spheres (every surface point within this
        distance of a sphere), > 0.
    protrusion: None (automatic: ``tolerance / 2`` for thin parts such as fingers and
        hands, up to ``2 tolerance`` for thick links; docs/spheres.md) or how far [m] a
        sphere may reach past the surface, > 0.
    max_spheres: None (the fewest spheres meeting ``tolerance``) or the most spheres per
        link (the fit then reports the error it reached).
    warn_protrusion: bound [m] on a link's largest protrusion; None: ``2.5 tolerance`` (or
        ``1.25 protrusion`` when larger).
    warn_excess: bound on a link's excess volume as a fraction of its volume, > 0 (a link
        whose excess is below ``(2 tolerance)^3`` is not named: a tiny part's shell).
    pair_samples: random configurations of the self-collision pair sampling, >= 1.
    pair_margin: distance [m] below which a sampled pair counts as colliding, >= 0.
    seed: seed of the fit and of the pair sampling.
    refine: with the automatic protrusion, fit the wrist, hand and fixed base by
        :func:`jwarp.importers.sphere_refine.fit_refined` with the per-link protrusions of
        :func:`~jwarp.importers.sphere_refine.link_protrusions` (spheres that hug the parts
        that come near grasped objects; docs/spheres.md); False: the plain fit everywhere.
    contain: True (default): the spheres contain every collision mesh
        (:func:`jwarp.importers.spheres.contain_fit`: every point of every triangle inside
        the union of the link's spheres, certified; ``tolerance`` then sets the sample
        density and the protrusion scale, not an error); the model's relation is
        ``"contained"``. False: the one-sided-error fit (fewer spheres; a mesh point may
        lie up to about ``tolerance`` outside them); the relation is ``"approximate"``
        with each link's certified poke-out, which the planner and IK add as margin.
        With ``max_spheres`` the budget wins: the one-sided-error fit within it, and the
        relation ``"approximate"`` with the poke-out it leaves.
    contain_gap: covering radius [m] of the containment certificate's point set, and how
        deep the cover holds its samples, > 0 (1 mm).
    contain_factors: with ``contain`` and ``refine``, the protrusion factors (x
        ``tolerance``) of the refined links: ``{"wrist": w, "hand": h}`` (either may be
        left out); None: :data:`jwarp.importers.sphere_refine.CONTAIN_PROTRUSIONS` (wrist
        1.5, hand and fingers 1.0: the Panda gets 125 spheres). Larger factors: fewer
        spheres and faster planning, more grasps the spheres touch (the mesh certificate
        proves them, at its cost; docs/spheres.md, "Containment": wrist 2, hand 1 gave the
        Panda 102 spheres, wrist 1.25, hand 0.75 191).
    """

    tolerance: float = 0.01
    max_spheres: int | None = None
    pair_samples: int = 10000
    pair_margin: float = 0.0
    seed: int = 0
    protrusion: float | None = None
    warn_protrusion: float | None = None
    warn_excess: float = 1.0
    refine: bool = True
    contain: bool = True
    contain_gap: float = 0.001
    contain_factors: dict | None = None

    def validate(self) -> None:
        for name, strict in (("tolerance", True), ("pair_margin", False), ("protrusion", True),
                             ("warn_protrusion", True), ("warn_excess", True),
                             ("contain_gap", True)):
            v = getattr(self, name)
            if v is None and name in ("protrusion", "warn_protrusion"):
                continue
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
            check_int(v, name, lo)
        f = self.contain_factors
        if f is not None:
            if not isinstance(f, dict):
                raise TypeError(f"contain_factors: expected None or a dict {{'wrist': w, "
                                f"'hand': h}}, got {type(f).__name__}")
            bad = set(f) - {"wrist", "hand"}
            if bad:
                raise ValueError(f"contain_factors: unknown keys {sorted(bad)} (wrist, hand)")
            for k, v in f.items():
                if isinstance(v, bool) or not isinstance(v, (int, float)) \
                        or not math.isfinite(v) or v <= 0:
                    raise ValueError(f"contain_factors: '{k}' must be a number > 0, got {v!r}")
        for name in ("refine", "contain"):
            if not isinstance(getattr(self, name), (bool, np.bool_)):
                raise TypeError(f"{name}: expected True or False, got "
                                f"{type(getattr(self, name)).__name__}")


@dataclass
class SpherizeReport:
    """What :func:`spherize` did. ``links``: one row per link with collision geometry:
    ``{link, geometries, spheres, one_sided_error [m], meets_tolerance, protrusion (the
    allowed reach [m]), max_protrusion [m], excess_volume [m^3], excess_fraction,
    watertight, kept (URDF spheres taken as they are)}``; ``warnings``: one line per link
    that passes a bound (module docstring); ``pairs``: the sampled self pairs (None when
    read from the cache); ``cached``: the model came from the disk cache."""

    links: list[dict] = field(default_factory=list)
    pairs: SelfPairs | None = None
    cached: bool = False
    warnings: list[str] = field(default_factory=list)

    @property
    def n_spheres(self) -> int:
        return int(sum(r["spheres"] for r in self.links))

    def link_lines(self) -> list[str]:
        """Per link: spheres, the poke-out bound (how far a mesh point may lie outside the
        link's spheres; 0 contained) and the protrusion (how far they reach past the
        surface) [mm], then the totals (the import report, ``jwarp import-urdf``)."""
        out = []
        for r in self.links:
            poke = 0.0 if r.get("kept") else float(r.get("poke_out_bound", float("nan")))
            how = ("URDF spheres" if r.get("kept") else "contained" if r.get("contained")
                   else "approximate")
            out.append(f"  {r['link']}: {r['spheres']} spheres, {how}, poke-out <= "
                       f"{poke * 1e3:.2f} mm, protrusion {r['max_protrusion'] * 1e3:.2f} mm"
                       + (f" (radii grown up to {r['grown'] * 1e3:.2f} mm, "
                          f"{r['certify_points']} certificate points)"
                          if r.get("contained") and not r.get("kept") else ""))
        pokes = [0.0 if r.get("kept") else float(r.get("poke_out_bound", float("nan")))
                 for r in self.links]
        prots = [float(r["max_protrusion"]) for r in self.links]
        out.append(f"  total: {self.n_spheres} spheres on {len(self.links)} links, poke-out "
                   f"<= {max(pokes, default=0.0) * 1e3:.2f} mm, protrusion <= "
                   f"{max(prots, default=0.0) * 1e3:.2f} mm")
        return out

    def to_dict(self) -> dict:
        out: dict[str, Any] = {"links": self.links, "spheres": self.n_spheres,
                               "cached": self.cached, "warnings": list(self.warnings)}
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


def fit_progress(total: int, enabled: bool | None) -> Any:
    """The sphere fit's progress bar on stderr (tqdm; one step per link to fit, and one for
    the self-collision pair sampling): ``enabled`` None shows it when stderr is a terminal,
    False never (a disabled bar: its calls do nothing)."""
    from tqdm.auto import tqdm

    if enabled is None:
        enabled = bool(getattr(sys.stderr, "isatty", lambda: False)())
    return tqdm(total=total, desc="sphere fit", unit="link", file=sys.stderr,
                disable=not enabled, leave=True, dynamic_ncols=True,
                bar_format="{desc}: {percentage:3.0f}%|{bar}| {n_fmt}/{total_fmt} steps "
                           "[{elapsed}<{remaining}{postfix}]")


def spherize(urdf_robot: Any, options: SpherizeOptions | None = None, *,
             sample_pairs: bool = True, progress: bool | None = False
             ) -> tuple[RobotModel, SpherizeReport]:
    """The collision model of an imported URDF (module docstring): a copy of
    ``urdf_robot.model`` with fitted spheres, sampled self-collision exclusions and the
    convex pieces of its collision geometry (``collision_pieces``, standing for the fitted
    spheres), and the report. ``sample_pairs`` False: no pair sampling (the caller samples the pairs of a
    planning group with :func:`resample_pairs`; the model keeps its own exclusions).
    ``progress``: a progress bar on stderr (:func:`fit_progress`: a step per link, the
    link's name beside it, then the pair sampling); None: when stderr is a terminal.
    The fit's results do not depend on it."""
    from jwarp.importers.collision_pieces import pieces_from_geometries
    from jwarp.importers.sphere_refine import CONTAIN_PROTRUSIONS, link_protrusions

    o = SpherizeOptions() if options is None else options
    if not isinstance(o, SpherizeOptions):
        raise TypeError(f"options: expected a SpherizeOptions, got {type(o).__name__}")
    o.validate()
    model: RobotModel = urdf_robot.model
    by_link: dict[str, list] = {}
    for g in urdf_robot.geometries:
        by_link.setdefault(g.link, []).append(g)
    if o.protrusion is not None and by_link:
        size = robot_size(model, by_link)
        if o.protrusion > size:
            raise ValueError(f"protrusion: {o.protrusion:g} m is more than the robot's size "
                             f"(its collision geometry spans {size:.4g} m): spheres reaching "
                             f"that far past the surface would touch every other link")
    spheres = list(model.spheres)
    report = SpherizeReport()
    # the excess volume (a reported figure, not the spheres) by 50 000 Monte Carlo points a
    # link (its standard error is reported): half the default, for the import's time
    fit_opts: dict[str, Any] = {"seed": int(o.seed), "n_volume": EXCESS_SAMPLES}
    if o.contain and o.max_spheres is None:  # a budget: approximate, its poke-out recorded
        fit_opts["contain"] = float(o.contain_gap)
    if o.max_spheres is not None:
        fit_opts["max_spheres"] = int(o.max_spheres)
    if o.protrusion is not None:
        fit_opts["protrusion"] = float(o.protrusion)
    # the wrist, hand and base: refined fits (jwarp.importers.sphere_refine)
    factors = dict(CONTAIN_PROTRUSIONS)
    if o.contain_factors:
        factors.update({k: float(v) for k, v in o.contain_factors.items()})
        if "hand" in o.contain_factors:
            factors["hand_start"] = float(o.contain_factors["hand"])
    contained = o.contain and o.max_spheres is None
    per_link = link_protrusions(model, float(o.tolerance), **(factors if contained else {})) \
        if o.protrusion is None and o.refine else {}
    n_fit = sum(any(g.kind != "sphere" for g in geoms) for geoms in by_link.values())
    bar = fit_progress(n_fit + int(bool(sample_pairs)), progress)
    try:
        fitted = _fit_links(model, by_link, o, fit_opts, per_link, spheres, report, bar)
        for w in report.warnings:
            warnings.warn(w, SphereFitWarning, stacklevel=2)
        if len(spheres) and sample_pairs:
            bar.set_postfix_str("self-collision pairs", refresh=True)
            pairs = never_colliding_pairs(fitted, n_samples=int(o.pair_samples),
                                          seed=int(o.seed), margin=float(o.pair_margin),
                                          **MOVEIT_RULES)
            # the model's own exclusions (e.g. MJCF <contact><exclude>) are kept and the
            # sampled ones added; a model without any (an imported URDF) gets exactly these
            sc = model.self_collision
            own = bool(sc.exclude_pairs or sc.include_pairs or sc.groups)
            fitted = with_self_pairs(fitted, pairs, replace=not own)
            report.pairs = pairs
            check_not_all_in_contact(pairs, o)
        if sample_pairs:
            bar.update(1)
    finally:
        bar.close()
    # the geometry's convex pieces, beside the fitted spheres (a mesh certificate's input)
    pieces = pieces_from_geometries(fitted, urdf_robot.geometries)
    return fitted.copy(collision_pieces=pieces), report


def _fit_links(model: RobotModel, by_link: dict[str, list], o: SpherizeOptions,
               fit_opts: dict[str, Any], per_link: dict, spheres: list, report: Any,
               bar: Any) -> RobotModel:
    """The links' fits of :func:`spherize` (spheres and report rows appended to
    ``spheres`` and ``report``; one ``bar`` step per fitted link); the model with them."""
    from jwarp.importers.sphere_refine import fit_refined
    from jwarp.importers.spheres import fit_link

    fitted_once: dict = {}  # links of the same geometry (a hand's fingers) are fitted once
    for link, geoms in by_link.items():
        frame = model.frame_index(link)
        todo = [g for g in geoms if g.kind != "sphere"]
        if not todo:  # a spherized link: its spheres are already the model's
            report.links.append({"link": link, "geometries": len(geoms), "spheres": len(geoms),
                                 "one_sided_error": 0.0, "meets_tolerance": True,
                                 "protrusion": 0.0, "max_protrusion": 0.0,
                                 "excess_volume": 0.0, "excess_fraction": 0.0,
                                 "watertight": True, "kept": True})
            continue
        link_opts = dict(fit_opts)
        if link in per_link:
            link_opts.update(per_link[link], fit=fit_refined)
        if o.max_spheres is not None:  # the link's URDF spheres count against its budget
            link_opts["max_spheres"] = max(int(o.max_spheres) - (len(geoms) - len(todo)), 1)
        bar.set_postfix_str(link, refresh=False)
        parts = [_geometry(g) for g in todo]
        key = _fit_key(parts, link_opts)
        try:
            fit = fitted_once.get(key)
            if fit is None:
                fit = fitted_once[key] = fit_link(parts, tolerance=float(o.tolerance),
                                                  **link_opts)
        except (ValueError, TypeError) as e:
            raise type(e)(f"link '{link}': {e}") from e
        spheres += [Sphere(frame=frame, position=np.asarray(c, np.float64), radius=float(r))
                    for c, r in zip(fit.centres, fit.radii)]
        row = {"link": link, "geometries": len(geoms),
               "spheres": int(len(fit.radii)) + len(geoms) - len(todo),
               "one_sided_error": float(fit.one_sided_error),
               "meets_tolerance": bool(fit.meets_tolerance),
               "protrusion": float(fit.protrusion), "max_protrusion": float(fit.max_protrusion),
               "excess_volume": float(fit.excess_volume),
               "excess_fraction": float(fit.excess_fraction),
               "watertight": bool(fit.watertight), "kept": False,
               "requested_protrusion": float(link_opts.get("protrusion", 0.0)),
               "refined": link in per_link, "contained": bool(fit.contained),
               "poke_out_bound": float(fit.poke_out_bound),
               "contain_gap": float(fit.contain_gap or o.contain_gap),
               "certify_points": int(fit.n_certify), "grown": float(fit.grown)}
        report.links.append(row)
        report.warnings += link_warnings(row, o)
        bar.update(1)
    return model.copy(spheres=spheres, sphere_relation=fit_relation(report.links, o))


def fit_relation(rows: list[dict], options: SpherizeOptions) -> SphereRelation:
    """The :class:`~jwarp.model.SphereRelation` of a fit from its report rows
    (:class:`SpherizeReport` ``links``): ``"contained"`` when every fitted link is
    (bound 0), else ``"approximate"`` with each link's certified poke-out [m]."""
    poke = {r["link"]: (0.0 if r.get("kept") or r.get("contained")
                        else float(r.get("poke_out_bound", float("nan"))))
            for r in rows}
    if any(not math.isfinite(v) for v in poke.values()):
        raise ValueError("options: a link's poke-out was not measured (a bug)")
    prot = {r["link"]: float(r.get("max_protrusion", 0.0)) for r in rows}
    gap = float(options.contain_gap)
    if all(v == 0.0 for v in poke.values()):
        return SphereRelation(kind="contained", bound=0.0, poke_out=poke, protrusion=prot,
                              gap=gap, method=f"jwarp.importers.spheres.contain_fit: every "
                                              f"triangle point within {gap:g} m of a point "
                                              f"held {gap:g} m deep")
    budget = f", max_spheres {options.max_spheres}" if options.max_spheres else ""
    return SphereRelation(kind="approximate", bound=max(poke.values(), default=0.0),
                          poke_out=poke, protrusion=prot, gap=gap,
                          method=f"one-sided-error fit (tolerance {options.tolerance:g} m"
                                 f"{budget}); poke-out: jwarp.importers.spheres."
                                 f"containment_bound (gap {gap:g} m)")


def robot_size(model: RobotModel, by_link: dict[str, list]) -> float:
    """Diagonal [m] of the box holding every link's collision geometry (``by_link``: link
    name -> its geometries) at the configuration of zeros clipped to the joint limits."""
    from jwarp.importers.spheres import geometry_bounds
    from jwarp.kinematics.fk import fk

    lim = np.asarray(model.joint_limits, np.float64)
    q = np.clip(np.zeros(model.n_dof), lim[:, 0], lim[:, 1])
    T = np.asarray(fk(model, q[None], device="cpu", dtype=np.float64))[0]
    pts = []
    for link, geoms in by_link.items():
        b = geometry_bounds([_geometry(g) for g in geoms])
        corners = np.array(np.meshgrid(*b.T, indexing="ij")).reshape(3, -1).T
        Tf = T[model.frame_index(link)]
        pts.append(corners @ Tf[:3, :3].T + Tf[:3, 3])
    p = np.concatenate(pts)
    return float(np.linalg.norm(p.max(0) - p.min(0)))


def check_not_all_in_contact(pairs: SelfPairs, options: SpherizeOptions) -> None:
    """ValueError when every tested self pair (frames with spheres, not adjacent) of the
    sampled ``pairs`` collided in every sample: all of them are excluded as "always
    colliding", so the model would check no self pair at all and call every
    configuration free (spheres far too large: ``protrusion``, ``tolerance``)."""
    always = set(pairs.always_colliding)
    tested = (always | set(pairs.never_colliding) | {
        (int(a), int(b)) for a, b in zip(*np.nonzero(np.triu(pairs.collision_rate > 0, 1)))}
              ) - set(pairs.adjacent)
    if always and tested == always:
        raise ValueError(f"protrusion: the fitted spheres of all {len(always)} link pairs "
                         f"that are not adjacent are in contact in every one of "
                         f"{len(pairs.samples)} samples, so every pair would be excluded as "
                         f"always colliding and no self-collision checked; the spheres are "
                         f"far too large (protrusion {options.protrusion} m, tolerance "
                         f"{options.tolerance:g} m)")


def _fit_key(parts: list[dict], options: dict) -> tuple:
    """A hashable key of a link's geometries (kind, size, pose, mesh file or object, scale)
    and fit options: links with equal keys get the same fit (it is deterministic)."""
    key: list = [tuple(sorted((k, repr(v)) for k, v in options.items()))]
    for g in parts:
        mesh = g["mesh"]
        if mesh is not None and not isinstance(mesh, (str, os.PathLike)):
            mesh = ("object", id(mesh))
        key.append((g["kind"], None if g["size"] is None else
                    tuple(np.asarray(g["size"], np.float64).ravel().tolist()),
                    None if g["origin"] is None else
                    tuple(np.asarray(g["origin"], np.float64).ravel().tolist()),
                    None if mesh is None else str(mesh) if isinstance(mesh, (str, os.PathLike))
                    else mesh,
                    None if g["scale"] is None else
                    tuple(np.asarray(g["scale"], np.float64).ravel().tolist())))
    return tuple(key)


def link_warnings(row: dict, options: SpherizeOptions) -> list[str]:
    """The bounds a link's fit row (:class:`SpherizeReport` ``links``) passes, as lines
    naming the link and the figures (empty when none)."""
    tol = float(options.tolerance)
    bound = options.warn_protrusion
    if bound is None:
        bound = max(2.5 * tol, 1.25 * float(options.protrusion or 0.0),
                    1.25 * float(row.get("requested_protrusion", 0.0)))
    out = []
    name = row["link"]
    if row.get("one_sided_error", 0.0) > tol:
        out.append(f"link '{name}': one-sided error {row['one_sided_error']:.4f} m > tolerance "
                   f"{tol:g} m (surface outside the spheres: collisions may be missed)")
    if row.get("max_protrusion", 0.0) > bound:
        out.append(f"link '{name}': a sphere reaches {row['max_protrusion']:.4f} m outside the "
                   f"part (bound {bound:g} m): free configurations may be refused")
    if row.get("excess_fraction", 0.0) > options.warn_excess and \
            row.get("excess_volume", 0.0) > (2.0 * tol) ** 3:  # not for a 1 cm^3 part
        out.append(f"link '{name}': spheres' volume outside the part is "
                   f"{row['excess_fraction']:.2f} x the part's volume (bound "
                   f"{options.warn_excess:g})")
    return out


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
                    cache: bool = True, sample_pairs: bool = True,
                    progress: bool | None = False,
                    **urdf_options: Any) -> tuple[RobotModel, SpherizeReport]:
    """:func:`spherize` of the URDF file ``path`` (``urdf_options``: the fields of
    :class:`~jwarp.importers.urdf.UrdfOptions`, e.g. ``package_dirs``, ``end_effectors``;
    ``sample_pairs`` and ``progress`` (a bar on stderr while fitting; None: on a terminal)
    as in :func:`spherize`).
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
        key = _cache_key(imported, os.fspath(path), o, urdf_options)
        if not sample_pairs:
            key = hashlib.sha256(f"{key}-no-pairs".encode()).hexdigest()[:32]
        file = _cache_dir() / "urdf" / f"{key}.json"
        if file.is_file():
            try:
                doc = json.loads(file.read_text())
                model = RobotModel.from_dict(doc["robot"])
                report = SpherizeReport(links=doc["links"], cached=True,
                                        warnings=list(doc.get("warnings", [])))
                for w in report.warnings:
                    warnings.warn(w, SphereFitWarning, stacklevel=2)
                return model, report
            except (OSError, ValueError, KeyError, TypeError):
                pass  # a damaged cache entry: recompute
    model, report = spherize(imported, o, sample_pairs=sample_pairs, progress=progress)
    if file is not None:
        try:
            file.parent.mkdir(parents=True, exist_ok=True)
            atomic_write_text(file, json.dumps({"robot": model.to_dict(), "links": report.links,
                                                "warnings": report.warnings}))
        except OSError:
            pass  # a read-only home: no cache, same result
    return model, report


def resample_pairs(model: RobotModel, sampled: Any, options: SpherizeOptions, *,
                   never: bool = True) -> tuple[RobotModel, SelfPairs]:
    """The self-collision exclusions of ``model`` sampled again over its own joints: for a
    model whose joints were locked or frozen after the fit (a planning group), whose
    ``sampled`` pairs came from the whole robot's joint ranges (a pair that collides only
    where a locked joint goes no more is excluded now; one that collides at every value of
    the planned joints, e.g. an arm link resting on a locked torso, is excluded as MoveIt
    does). Exclusions of ``model`` that are not among the ``sampled`` ones (SRDF pairs,
    links that freezing joined rigidly) are kept; so are those whose recorded reason
    (``notes['self_collision_pairs']``) is not one of the sampled rules. ``never`` False:
    the never-colliding pairs are not excluded (an SRDF decides those: the import's
    ``--srdf-collisions srdf``). Returns (model, the new pairs)."""
    o = options
    o.validate()
    pairs = never_colliding_pairs(model, n_samples=int(o.pair_samples), seed=int(o.seed),
                                  margin=float(o.pair_margin), **MOVEIT_RULES)
    if not never:
        pairs.never_colliding = []
    sc = model.self_collision
    old = {tuple(sorted(int(i) for i in p)) for p in sampled}
    why = pair_reasons(model)
    sampled_kinds = ("Adjacent", "Always", "Never")
    keep = [tuple(sorted(p)) for p in sc.exclude_pairs
            if (tuple(sorted(p)) not in old and tuple(sorted(p)) not in why)
            or why.get(tuple(sorted(p)), ("",))[0] not in ("",) + sampled_kinds]
    out = with_self_pairs(model, pairs, replace=True)
    merged = sorted(set(out.self_collision.exclude_pairs) | set(keep))
    notes = dict(out.notes)
    notes["self_collision"] += (f"; sampled over the {model.n_dof} planned joints (others "
                                f"locked), {len(keep)} earlier exclusions kept")
    from jwarp.model import SelfCollision

    new_sc = SelfCollision(groups={k: list(v) for k, v in sc.groups.items()},
                           include_pairs=list(sc.include_pairs), exclude_pairs=merged)
    reasons = {**sampled_reasons(model, pairs), **{p: why[p] for p in keep if p in why}}
    return with_pair_reasons(out.copy(self_collision=new_sc, notes=notes), reasons), pairs


def certify_relation(model: RobotModel, urdf_robot: Any, gap: float | None = None
                     ) -> RobotModel:
    """``model`` (spheres fitted to ``urdf_robot``'s collision geometry, then edited, e.g.
    tightened at the home by :mod:`jwarp.world.home_fit`) with the poke-out of every link
    its relation lists above 0 measured again, certified
    (:func:`jwarp.importers.spheres.containment_bound` of the link's spheres against its
    geometry, covering radius ``gap`` [m]; None: the relation's): the relation becomes
    ``"contained"`` again when every link is. Models of no or a contained relation are
    returned as they are."""
    from jwarp.importers.spheres import containment_bound, containment_growth, link_part

    rel = model.sphere_relation
    if rel is None or rel.kind == "contained":
        return model
    g = float(gap if gap is not None else (rel.gap or 0.001))
    by_link: dict[str, list] = {}
    for geo in urdf_robot.geometries:
        by_link.setdefault(geo.link, []).append(geo)
    f, p, r = model.sphere_arrays()
    poke = dict(rel.poke_out)
    names = [fr.name for fr in model.frames]
    margin = np.asarray(rel.sphere_margin if rel.sphere_margin is not None
                        and len(rel.sphere_margin) == len(r)
                        else [rel.link_poke_out(names[i]) for i in f], np.float64)
    for link, v in rel.poke_out.items():
        if v <= 0 or link not in by_link:
            continue
        mesh, sag = link_part([_geometry(x) for x in by_link[link]])
        sel = f == model.frame_index(link)
        if mesh is None or not sel.any():
            continue
        poke[link] = containment_bound(mesh, p[sel], r[sel], gap=g, surface_error=sag)
        # the least growth per sphere that contains the link (the planner's margin)
        margin[sel] = containment_growth(mesh, p[sel], r[sel], gap=g, surface_error=sag)
    bound = max(poke.values(), default=0.0)
    new = SphereRelation(kind="contained" if bound == 0.0 else "approximate", bound=bound,
                         poke_out=poke, protrusion=dict(rel.protrusion), gap=g,
                         method=f"{rel.method}; poke-out certified again after the edit "
                                f"(gap {g:g} m)",
                         sphere_margin=None if bound == 0.0 else margin.tolist())
    return model.copy(sphere_relation=new)
