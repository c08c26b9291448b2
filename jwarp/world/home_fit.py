"""The home configuration of an imported robot free of self-collision, without hiding
real collisions (docs/urdf.md, "Home configuration").

:func:`fit_home` takes the robot being imported (:class:`~jwarp.importers.robot.UrdfRobot`,
for its collision geometry) and its jwarp model (fitted spheres, sampled pairs, SRDF pairs,
planning group) and looks, at the home, at every checked frame pair whose spheres are
closer than ``contact_margin + 2 tolerance`` (farther, the geometry is apart: each link's
surface is within the fit's one-sided error of its spheres). The contact test is jwarp's
own: surface points of one link's geometry (its vertices and ``n_surface`` area-uniform
samples) against the other's solid (signed distance by generalised winding number,
:func:`jwarp.importers.spheres.signed_distance`), both ways, at the home's FK; sampled
points give an upper bound of the true distance, so a pair whose meshes are apart is never
called in contact.

* **Geometry in contact** (closer than ``contact_margin``, overlapping included): the home
  is a self-collision. A home the caller gave is refused (ValueError naming it, the pairs,
  the geometry's overlap and the spheres' depth). The default home (zeros projected into
  the limits) is replaced by the first free one of :func:`home_candidates` (the SRDF's
  group states, ``ready``/``home``/``default`` first; the middle of the limits), else by a
  free random configuration (``n_random`` tries), else refused; the report's ``rejected``
  and a warning say which homes were in collision and which was chosen. MoveIt's setup
  assistant would instead uncheck such pairs (its "Default" rule); jwarp never unchecks a
  pair to free a home: a pair free almost everywhere else would go unchecked on every
  motion (issue 42: the Panda's link5 against its hand).
* **Tightened**: where the geometry is apart but the spheres overlap (spheres reaching
  past the surface, up to the fit's protrusion), the overlapping spheres of the two links
  are shrunk, never below their clearance (the distance of the centre to the link's
  surface: the sphere then still holds the ball inside the solid), each pair by what it
  lacks to ``gap`` split in proportion to the two spheres' protrusion, until the home is
  free. A link whose shrunk spheres would leave its surface further than ``tolerance``
  outside them (the one-sided error on ``n_surface`` samples; None: not bounded) is put
  back as it was and, with ``refit``, fitted again (:func:`jwarp.importers.spheres.
  fit_link`, same tolerance) with a protrusion of half the URDF geometry's distance to its
  partner at the home, less ``gap`` (so the pair is free whatever the partner's spheres do
  within their own protrusion), then tightened again where still needed. A pair still
  overlapping stays checked and is in the report's ``remaining``: no collision is hidden.

The home (:func:`resolve_home`): an SRDF ``<group_state>`` name, joint values, or None
(:func:`jwarp.world.model_check.home_configuration`: zeros projected into the limits);
:func:`fit_home` writes the chosen one to ``notes['home']``, the first configuration of the
solvers' collision-model check (:func:`jwarp.world.model_check.home_configurations`).
"""

from __future__ import annotations

import math
import time
import warnings
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from jwarp.importers.spheres import (
    load_mesh,
    one_sided_error,
    primitive_mesh,
    signed_distance,
)
from jwarp.model import RobotModel, Sphere
from jwarp.utils.checks import check_int

__all__ = ["HomeFitOptions", "HomeFitReport", "HomeFitWarning", "fit_home", "resolve_home",
           "link_mesh", "mesh_distance"]


class HomeFitWarning(UserWarning):
    """A default home replaced (it was a self-collision), spheres tightened, or a pair
    left overlapping at the home."""


@dataclass
class HomeFitOptions:
    """Options of :func:`fit_home` (module docstring).

    Attributes:
        contact_margin: URDF geometry closer than this at the home [m] is in contact (a
            self-collision); overlapping geometry always is.
        gap: surface distance [m] left between the tightened spheres of a pair.
        tolerance: largest one-sided error [m] of a tightened link's surface (None: not
            bounded); the import passes its fit tolerance.
        n_surface: area-uniform surface samples per link (contact test and coverage).
        seed: seed of the samples (and of a refit).
        refit: a link whose shrunk spheres would exceed ``tolerance`` is fitted again
            with a protrusion that fits the home (False: left as it was).
        n_random: random configurations tried for a default home when none of
            :func:`home_candidates` is free.
    """

    contact_margin: float = 0.0005
    gap: float = 1e-4
    tolerance: float | None = None
    n_surface: int = 4000
    seed: int = 0
    refit: bool = True
    n_random: int = 2000

    def validate(self) -> HomeFitOptions:
        for key in ("contact_margin", "gap", "tolerance"):
            v = getattr(self, key)
            if v is None and key == "tolerance":
                continue
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) \
                    or v < 0:
                raise ValueError(f"{key}: expected a finite distance >= 0 [m], got {v!r}")
        check_int(self.n_surface, "n_surface", 100)
        check_int(self.seed, "seed")
        check_int(self.n_random, "n_random", 0)
        return self


@dataclass
class HomeFitReport:
    """What :func:`fit_home` did. ``home``: (n_dof,) values [rad or m] and ``home_from``
    (where they came from); ``default_pairs``: ``{"links": [a, b], "sphere_depth_m",
    "mesh_distance_m"}`` excluded (reason Default); ``tightened``: per link ``{"link",
    "spheres" (count shrunk), "largest_cut_m", "one_sided_error_m": [before, after]}``;
    ``remaining``: pairs still overlapping at the home ``{"links", "sphere_depth_m",
    "mesh_distance_m", "why"}``; ``warnings``: the lines warned; ``seconds``: wall time."""

    home: list[float]
    home_from: str
    #: always empty since issue 42 (no pair is unchecked to free a home); kept for readers
    default_pairs: list[dict] = field(default_factory=list)
    #: default homes tried and found in self-collision: ``{"home_from", "pairs": [{"links",
    #: "sphere_distance_m" (negative: overlapping), "mesh_distance_m"}]}``
    rejected: list[dict] = field(default_factory=list)
    tightened: list[dict] = field(default_factory=list)
    remaining: list[dict] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    seconds: float = 0.0

    @property
    def home_free(self) -> bool:
        """No checked pair overlaps at the home any more."""
        return not self.remaining

    def to_dict(self) -> dict:
        return {**asdict(self), "home_free": self.home_free}

    def summary(self) -> str:
        """One line for the import's summary."""
        t = ", ".join(
            f"{r['link']} (fitted again: protrusion {1e3 * r['protrusion_m']:.1f} mm, "
            f"{r['spheres']} spheres)" if r.get("refit") else
            f"{r['link']} ({r['spheres']} spheres, up to {1e3 * r['largest_cut_m']:.1f} mm)"
            for r in self.tightened if not r.get("reverted")) or "none"
        state = "free" if self.home_free else (
            "IN COLLISION: " + ", ".join("/".join(p["links"]) for p in self.remaining))
        why = ("; replaced " + ", ".join(
            f"{r['home_from']} (self-collision: "
            + ", ".join("/".join(p["links"]) for p in r["pairs"]) + ")"
            for r in self.rejected)) if self.rejected else ""
        return f"home ({self.home_from}): {state}{why}; spheres tightened: {t}"


# ------------------------------------------------------------------ the home
def resolve_home(model: RobotModel, home: Any = None, srdf: Any = None) -> tuple[np.ndarray, str]:
    """(q (n_dof,) [rad or m], where it came from) of ``home``: None (zeros projected into
    the limits), the name of an SRDF ``<group_state>`` of ``srdf`` (its joints of
    ``model``; the others as for None), or ``n_dof`` numbers. A revolute joint's value
    outside its limits is moved by a multiple of 2 pi into them where it fits (the same
    pose: SRDFs write angles in (-pi, pi]). ValueError naming ``home`` for an unknown
    state, a wrong count, a value outside the joint's limits."""
    from jwarp.world.model_check import home_configuration

    q = home_configuration(model)
    lim = model.joint_limits
    if home is None:
        return q, "zeros projected into the limits"
    if isinstance(home, str):
        if srdf is None:
            raise ValueError(f"home: state '{home}' needs an SRDF (srdf / --srdf); or give "
                             f"{model.n_dof} joint values")
        values = srdf.state(home)   # SrdfError naming the file and the states
        used = [j for j in values if j in model.joint_names]
        if not used:
            raise ValueError(f"home: SRDF state '{home}' sets none of the joints of robot "
                             f"'{model.name}' ({', '.join(model.joint_names)})")
        for j in used:
            q[model.joint_index(j)] = values[j]
        what = f"SRDF group_state '{home}'"
    else:
        if isinstance(home, (bytes, dict)) or not isinstance(home, (Sequence, np.ndarray)):
            raise TypeError(f"home: expected a state name or joint values, got "
                            f"{type(home).__name__}")
        v = np.asarray(home, np.float64).reshape(-1)
        if v.shape != (model.n_dof,) or not np.all(np.isfinite(v)):
            raise ValueError(f"home: expected {model.n_dof} finite joint values (joints "
                             f"{', '.join(model.joint_names)}), got {len(v)}")
        q = v.copy()
        what = "given joint values"
    tol = 1e-9 * np.maximum(1.0, np.abs(lim).max(axis=1))
    for j, jt in enumerate(model.joints):   # a revolute joint's value + 2 pi k: same pose
        if jt.type != "prismatic" and not lim[j, 0] - tol[j] <= q[j] <= lim[j, 1] + tol[j]:
            k = math.ceil((lim[j, 0] - tol[j] - q[j]) / (2 * math.pi))
            if q[j] + 2 * math.pi * k <= lim[j, 1] + tol[j]:
                q[j] += 2 * math.pi * k
    bad = np.flatnonzero((q < lim[:, 0] - tol) | (q > lim[:, 1] + tol))
    if len(bad):
        j = int(bad[0])
        raise ValueError(f"home: {model.joint_names[j]}={q[j]:g} is outside the joint's "
                         f"limits [{lim[j, 0]:g}, {lim[j, 1]:g}] ({what})")
    return np.clip(q, lim[:, 0], lim[:, 1]), what


# ------------------------------------------------------------------ geometry
def link_mesh(robot: Any, link: str) -> Any:
    """The collision geometry of ``link`` of an imported URDF (``robot``: a
    :class:`~jwarp.importers.robot.UrdfRobot`) as one trimesh in the link frame [m]
    (primitives tessellated), or None when it has none or a mesh file is missing."""
    import trimesh

    parts = []
    for g in robot.geometries:
        if g.link != link:
            continue
        if g.kind == "mesh":
            if getattr(g, "mesh", None) is not None:
                m = g.mesh.copy()
            elif g.mesh_path is None:
                return None
            else:
                m = load_mesh(g.mesh_path, g.scale)
        else:
            m = primitive_mesh(g.kind, g.size)
        m = m.copy()
        m.apply_transform(np.asarray(g.origin, np.float64))
        parts.append(m)
    if not parts:
        return None
    return parts[0] if len(parts) == 1 else trimesh.util.concatenate(parts)


def _surface_points(mesh: Any, n: int, seed: int) -> np.ndarray:
    """(m, 3) the mesh's vertices (at most ``n``) and ``n`` area-uniform samples."""
    import trimesh

    v = np.asarray(mesh.vertices, np.float64)
    if len(v) > n:
        v = v[np.random.default_rng(seed).permutation(len(v))[:n]]
    pts, _ = trimesh.sample.sample_surface(mesh, n, seed=seed)
    return np.concatenate([v, np.asarray(pts, np.float64)])


def _moved(T: np.ndarray, p: np.ndarray) -> np.ndarray:
    return p @ T[:3, :3].T + T[:3, 3]


def mesh_distance(mesh_a: Any, T_a: np.ndarray, mesh_b: Any, T_b: np.ndarray, *,
                  n_surface: int = 4000, seed: int = 0) -> float:
    """Smallest distance [m] between the solids of ``mesh_a`` posed at ``T_a`` (4, 4) and
    ``mesh_b`` at ``T_b``, negative when they overlap (as deep as the deepest sampled point
    of one inside the other): surface points of each (vertices and ``n_surface``
    samples) against the other's signed distance (winding number). An upper bound of the
    true distance (the sampled points of the nearest spot may miss it by their spacing)."""
    Ta, Tb = np.asarray(T_a, np.float64), np.asarray(T_b, np.float64)
    pa = _surface_points(mesh_a, n_surface, seed)
    pb = _surface_points(mesh_b, n_surface, seed + 1)
    inv_b, inv_a = np.linalg.inv(Tb), np.linalg.inv(Ta)
    d_ab = signed_distance(mesh_b, _moved(inv_b @ Ta, pa))
    d_ba = signed_distance(mesh_a, _moved(inv_a @ Tb, pb))
    return float(min(d_ab.min(), d_ba.min()))


# ------------------------------------------------------------------ the fit
#: group_state names tried first for a default home (MoveIt configs' usual names)
HOME_STATE_NAMES = ("ready", "home", "default")


def home_candidates(model: RobotModel, srdf: Any = None) -> list[tuple[Any, str]]:
    """``[(home, what)]`` tried in order for the default home (``fit_home(home=None)``):
    zeros projected into the limits; the SRDF's ``<group_state>`` names (``ready``,
    ``home``, ``default`` first, then the others in document order) that set a joint of
    ``model``; the middle of the limits. (The sampled free configuration is the last
    resort: :func:`fit_home`.)"""
    out: list[tuple[Any, str]] = [(None, "zeros projected into the limits")]
    if srdf is not None:
        names = srdf.state_names
        names = [n for n in HOME_STATE_NAMES if n in names] + \
            [n for n in names if n not in HOME_STATE_NAMES]
        for n in names:
            try:
                values = srdf.state(n)
            except ValueError:
                continue
            if any(j in model.joint_names for j in values):
                out.append((n, f"SRDF group_state '{n}'"))
    lim = np.asarray(model.joint_limits, np.float64)
    out.append((list(0.5 * (lim[:, 0] + lim[:, 1])), "the middle of the joint limits"))
    return out


def fit_home(robot: Any, model: RobotModel | None = None, home: Any = None,
             options: HomeFitOptions | None = None, *, srdf: Any = None
             ) -> tuple[RobotModel, HomeFitReport]:
    """``model`` (default ``robot.model``; its frames those of the imported ``robot``, e.g.
    fitted and reduced to a planning group) with a home free of self-collision (module
    docstring); ``home`` as in :func:`resolve_home` (``srdf``: a parsed
    :class:`~jwarp.importers.srdf.Srdf` for a state name, and the default home's
    candidates). A checked pair whose URDF collision geometry is in contact at the home
    (closer than ``contact_margin``) is a self-collision: a given ``home`` is refused
    (ValueError naming it, the pairs and their distances); the default home (None) is
    replaced by the first free one of :func:`home_candidates`, else by a free random
    configuration (``n_random`` tries, seeded), else refused. No pair is ever unchecked to
    free a home. Spheres overlapping where the geometry is apart are tightened or fitted
    again. Returns (model, report); warns (:class:`HomeFitWarning`) naming a replaced home,
    every tightened link and pair left overlapping."""
    o = (HomeFitOptions() if options is None else options)
    if not isinstance(o, HomeFitOptions):
        raise TypeError(f"options: expected HomeFitOptions, got {type(o).__name__}")
    o.validate()
    t0 = time.perf_counter()
    model = robot.model if model is None else model
    if not isinstance(model, RobotModel):
        raise TypeError(f"model: expected a RobotModel, got {type(model).__name__}")
    if model.frame_names[:len(robot.model.frame_names)] != robot.model.frame_names:
        raise ValueError("model: its frames are not those of the imported robot")
    q, where = resolve_home(model, home, srdf)   # a given home's errors first
    report = HomeFitReport(home=q.tolist(), home_from=where)
    if not model.spheres:
        return model, report
    names = model.frame_names
    meshes: dict[int, Any] = {}

    def mesh_of(f: int) -> Any:
        if f not in meshes:
            meshes[f] = link_mesh(robot, names[f])
        return meshes[f]

    # spheres farther apart than this have geometry apart (each link's surface is within
    # the fit's one-sided error, at most ``tolerance``, of its spheres)
    reach = o.contact_margin + 2.0 * (o.tolerance or 0.0)

    def contacts(qc: np.ndarray) -> tuple[list, list, Any]:
        """(pairs in contact [(a, b, sphere distance, mesh distance)], pairs to tighten
        [(a, b, depth)], (FK, the distance function)) at ``qc``: the URDF geometry of every
        checked pair whose spheres are closer than ``reach`` is tested."""
        from jwarp.kinematics.fk import fk

        T = fk(model, qc[None], device="cpu", dtype=np.float64)[0]
        dist: dict[tuple[int, int], float] = {}

        def distance(a: int, b: int) -> float:
            if (a, b) not in dist:
                ma, mb = mesh_of(a), mesh_of(b)
                dist[a, b] = (math.nan if ma is None or mb is None else
                              mesh_distance(ma, T[a], mb, T[b], n_surface=o.n_surface,
                                            seed=o.seed))
            return dist[a, b]

        hit, fit = [], []
        for (a, b), d in _near_pairs(model, T, reach):
            if distance(a, b) <= o.contact_margin:
                hit.append((a, b, d, distance(a, b)))
            elif d < 0:
                fit.append((a, b, d))
        return hit, fit, (T, distance)

    def words(rows: list) -> str:
        return ", ".join(f"{names[a]}/{names[b]} (URDF collision geometry "
                         f"{_contact_words(dm)}, spheres "
                         + (f"{-1e3 * d:.1f} mm deep)" if d < 0 else f"{1e3 * d:.1f} mm apart)")
                         for a, b, d, dm in rows)

    hit, fit, (T, distance) = contacts(q)
    if hit and home is not None:
        raise ValueError(
            f"home: {where} is a self-collision of robot '{model.name}': {words(hit)}; "
            f"give a home where these links are apart, or, if they may touch, disable the "
            f"pair in the SRDF (<disable_collisions>); jwarp does not uncheck a pair to "
            f"free a home")
    if hit:   # the default home: replaced by a free one
        rejected = [(where, hit)]
        found = None
        for cand, what in home_candidates(model, srdf)[1:]:
            try:
                qc, _ = resolve_home(model, cand, srdf)
            except ValueError:
                continue      # a state outside the limits
            h, f2, td = contacts(qc)
            if not h:
                found = (qc, what, f2, td)
                break
            rejected.append((what, h))
        if found is None:
            found = _random_free_home(model, o, contacts, reach)
        if found is None:
            raise ValueError(
                f"home: no home free of self-collision found for robot '{model.name}': "
                + "; ".join(f"{w}: {words(h)}" for w, h in rejected if w)
                + f"; nor among {o.n_random} random configurations; give one (--home)")
        q, where, fit, (T, distance) = found
        report.home, report.home_from = q.tolist(), where
        report.rejected = [{"home_from": w, "pairs": [
            {"links": [names[a], names[b]], "sphere_distance_m": d, "mesh_distance_m": dm}
            for a, b, d, dm in h]} for w, h in rejected]
        report.warnings.append(
            f"the default home ({rejected[0][0]}) is a self-collision: {words(rejected[0][1])}"
            + "".join(f"; so is {w}: {words(h)}" for w, h in rejected[1:])
            + f"; the home is {where} instead (no pair is unchecked to free a home)")
    from jwarp.world.model_check import home_self_collisions

    if fit:
        pairs = [(a, b) for a, b, _ in fit]
        model = _tighten(robot, model, T, pairs, o, report, mesh_of)
        back = [r["frame"] for r in report.tightened if r.get("reverted")]
        if back and o.refit:
            model = _refit(robot, model, back, pairs, o, report, distance)
            left = {tuple(sorted((names.index(na), names.index(nb))))
                    for na, nb, _ in home_self_collisions(model, q, device="cpu")}
            again = [p for p in pairs if p in left]
            if again:
                model = _tighten(robot, model, T, again, o, report, mesh_of)
    # what is left (pairs without geometry, or tightening that would uncover a surface)
    for na, nb, depth in home_self_collisions(model, q, device="cpu"):
        a, b = sorted((names.index(na), names.index(nb)))
        d = distance(a, b)
        why = ("no URDF collision geometry to compare" if math.isnan(d) else
               "tightening would uncover a surface beyond the tolerance"
               if any(r["link"] in (na, nb) for r in report.tightened if r.get("reverted"))
               else "spheres at their clearance still overlap")
        report.remaining.append({"links": [names[a], names[b]], "sphere_depth_m": depth,
                                 "mesh_distance_m": d, "why": why})
        report.warnings.append(f"links '{names[a]}' and '{names[b]}' remain in collision at "
                               f"the home ({where}): spheres {-1e3 * depth:.1f} mm deep, URDF "
                               f"geometry {_contact_words(d)} ({why})")
    for w in report.warnings:
        warnings.warn(w, HomeFitWarning, stacklevel=2)
    import json

    from jwarp.world.model_check import HOME_NOTE

    notes = dict(model.notes)
    notes[HOME_NOTE] = json.dumps([float(v) for v in q])   # the solvers' check starts here
    report.seconds = time.perf_counter() - t0
    return model.copy(notes=notes), report


def _near_pairs(model: RobotModel, T: np.ndarray, reach: float
                ) -> list[tuple[tuple[int, int], float]]:
    """``[((a, b), smallest sphere surface distance [m])]`` of the checked frame pairs
    (``allowed_collision_pairs``) closer than ``reach`` at the FK ``T``, closest first."""
    from jwarp.world.collision import collision_pairs

    pairs = collision_pairs(model)
    if len(pairs) == 0:
        return []
    sf, sp, sr = model.sphere_arrays()
    x = np.einsum("sij,sj->si", T[sf, :3, :3], sp) + T[sf, :3, 3]
    i, j = pairs[:, 0], pairs[:, 1]
    d = np.linalg.norm(x[i] - x[j], axis=1) - sr[i] - sr[j]
    best: dict[tuple[int, int], float] = {}
    for k in np.flatnonzero(d < reach):
        key = (int(min(sf[i[k]], sf[j[k]])), int(max(sf[i[k]], sf[j[k]])))
        best[key] = min(best.get(key, math.inf), float(d[k]))
    return sorted(best.items(), key=lambda t: t[1])


def _random_free_home(model: RobotModel, o: HomeFitOptions, contacts: Any, reach: float
                      ) -> Any:
    """The first of ``o.n_random`` random configurations (seed ``o.seed``) whose checked
    spheres are all farther apart than ``reach`` (then no URDF geometry needs a test), or,
    among the first ten that are not, one whose geometry is apart: ``(q, what, pairs to
    tighten, (FK, distance))``, or None."""
    from jwarp.kinematics.fk import fk

    lim = np.asarray(model.joint_limits, np.float64)
    rng = np.random.default_rng(o.seed)
    tested = 0
    for k in range(o.n_random):
        qc = lim[:, 0] + rng.random(model.n_dof) * (lim[:, 1] - lim[:, 0])
        if _near_pairs(model, fk(model, qc[None], device="cpu", dtype=np.float64)[0], reach):
            if tested >= 10:
                continue      # URDF geometry tests for the first few only (their cost)
            tested += 1
        h, fit, td = contacts(qc)
        if not h:
            return qc, (f"a random configuration free of self-collision (try {k + 1}, seed "
                        f"{o.seed})"), fit, td
    return None


def _contact_words(d: float) -> str:
    if math.isnan(d):
        return "missing"
    if d < 0:
        return f"overlapping by {-1e3 * d:.1f} mm"
    return f"{1e3 * d:.1f} mm apart"


def _tighten(robot: Any, model: RobotModel, T: np.ndarray, pairs: list[tuple[int, int]],
             o: HomeFitOptions, report: HomeFitReport, mesh_of: Any) -> RobotModel:
    """Shrink the overlapping spheres of the frame ``pairs`` at the home's FK ``T``
    (n_frames, 4, 4) towards their clearance (module docstring); the report's
    ``tightened`` rows."""
    sf, sp, sr = model.sphere_arrays()
    x = np.einsum("sij,sj->si", T[sf, :3, :3], sp) + T[sf, :3, 3]
    frames = sorted({f for p in pairs for f in p})
    lo = sr.copy()            # no geometry: the sphere stays as it is
    for f in frames:
        m = mesh_of(f)
        idx = np.flatnonzero(sf == f)
        if m is None or not len(idx):
            continue
        clear = -signed_distance(m, sp[idx])
        lo[idx] = np.clip(clear, 0.0, sr[idx])
    r = sr.copy()
    for _ in range(50):
        cut = np.zeros_like(r)
        for a, b in pairs:
            ia, ib = np.flatnonzero(sf == a), np.flatnonzero(sf == b)
            d = (np.linalg.norm(x[ia, None] - x[None, ib], axis=-1) - r[ia, None] - r[None, ib])
            for i, j in zip(*np.nonzero(d < o.gap)):
                need = o.gap - d[i, j]
                si, sj = r[ia[i]] - lo[ia[i]], r[ib[j]] - lo[ib[j]]
                tot = si + sj
                if tot <= 0:
                    continue
                k = min(1.0, need / tot)
                cut[ia[i]] = max(cut[ia[i]], k * si)
                cut[ib[j]] = max(cut[ib[j]], k * sj)
        if cut.max() <= 1e-12:
            break
        r = np.maximum(r - cut, lo)
    changed = np.flatnonzero(r < sr)
    if not len(changed):
        return model
    spheres = list(model.spheres)
    for f in sorted({int(sf[i]) for i in changed}):
        idx = np.flatnonzero(sf == f)
        mine = [i for i in idx if r[i] < sr[i]]
        pts = _surface_points(mesh_of(f), o.n_surface, o.seed + 2)
        before = float(one_sided_error(pts, sp[idx], sr[idx]).max())
        after = float(one_sided_error(pts, sp[idx], r[idx]).max())
        row: dict[str, Any] = {"link": model.frame_names[f], "frame": f, "spheres": len(mine),
               "largest_cut_m": float(max(sr[i] - r[i] for i in mine)),
               "one_sided_error_m": [before, after]}
        if o.tolerance is not None and after > max(o.tolerance, before) + 1e-12:
            row["reverted"] = True
            if o.refit:
                row["why"] = (f"shrinking would leave the surface {1e3 * after:.1f} mm "
                              f"outside the spheres")
                report.tightened.append(row)
                continue
            report.warnings.append(
                f"link '{row['link']}': shrinking {len(mine)} spheres by up to "
                f"{1e3 * row['largest_cut_m']:.1f} mm would leave its surface "
                f"{1e3 * after:.1f} mm outside them (tolerance {1e3 * o.tolerance:.1f} mm): "
                f"not tightened")
        else:
            for i in mine:
                s = spheres[i]
                spheres[i] = Sphere(frame=s.frame, position=np.asarray(s.position),
                                    radius=float(r[i]))
            report.warnings.append(
                f"link '{row['link']}': {len(mine)} spheres shrunk by up to "
                f"{1e3 * row['largest_cut_m']:.1f} mm towards their clearance (they overlapped "
                f"at the home while the URDF geometry does not); one-sided error "
                f"{1e3 * before:.1f} -> {1e3 * after:.1f} mm")
        prev = next((x for x in report.tightened if x.get("frame") == f
                     and not x.get("reverted")), None)
        if prev is not None and prev.get("refit") and not row.get("reverted"):
            prev["then_shrunk"] = row["spheres"]   # a refitted link shrunk after all
            prev["largest_cut_m"] = row["largest_cut_m"]
            prev["one_sided_error_m"][1] = after
        elif prev is not None and not row.get("reverted"):   # a second pass on a link
            prev["spheres"] += row["spheres"]
            prev["largest_cut_m"] = max(prev["largest_cut_m"], row["largest_cut_m"])
            prev["one_sided_error_m"][1] = after
        else:
            report.tightened.append(row)
    return model.copy(spheres=spheres)


def _refit(robot: Any, model: RobotModel, frames: list[int], pairs: list[tuple[int, int]],
           o: HomeFitOptions, report: HomeFitReport, distance: Any) -> RobotModel:
    """Fit the spheres of ``frames`` again (:func:`jwarp.importers.spheres.fit_link`, the
    import's tolerance) with a protrusion small enough for their ``pairs`` at the home:
    half of the URDF geometry's distance there, less ``gap``. The report's rows of these
    links say so (``refit``); a fit that fails leaves the link as it was."""
    from jwarp.importers.spheres import fit_link

    names = model.frame_names
    spheres = list(model.spheres)
    for f in frames:
        row = next(r for r in report.tightened if r.get("frame") == f and r.get("reverted"))
        gaps = [distance(a, b) for a, b in pairs if f in (a, b)]
        p = 0.5 * (min(gaps) - o.gap) if gaps else math.nan
        geoms = [g for g in robot.geometries if g.link == names[f]]
        if not geoms or not p > 1e-4 or any(g.kind == "mesh" and getattr(g, "mesh", None)
                                            is None and g.mesh_path is None for g in geoms):
            row["why"] += "; no refit (no room between the links' geometry)"
            report.warnings.append(f"link '{names[f]}': {row['why']}: not tightened")
            continue
        items = [{"kind": g.kind, "size": g.size, "origin": g.origin, "scale": g.scale,
                  "mesh": (g.mesh if getattr(g, "mesh", None) is not None else g.mesh_path)
                  if g.kind == "mesh" else None} for g in geoms]
        try:
            fit = fit_link(items, tolerance=float(o.tolerance), protrusion=float(p),
                           seed=o.seed)
        except (ValueError, TypeError) as e:
            row["why"] += f"; refit failed: {e}"
            report.warnings.append(f"link '{names[f]}': {row['why']}: not tightened")
            continue
        old = sum(1 for s in spheres if s.frame == f)
        spheres = [s for s in spheres if s.frame != f] + [
            Sphere(frame=f, position=np.asarray(c, np.float64), radius=float(r))
            for c, r in zip(fit.centres, fit.radii)]
        row.update(reverted=False, refit=True, protrusion_m=float(p), spheres_before=old,
                   spheres=int(len(fit.radii)),
                   one_sided_error_m=[row["one_sided_error_m"][0], float(fit.one_sided_error)])
        report.warnings.append(
            f"link '{names[f]}': {row['why']}; fitted again with protrusion "
            f"{1e3 * p:.1f} mm (half its URDF geometry's distance to its partner at the home): "
            f"{old} -> {len(fit.radii)} spheres, one-sided error "
            f"{1e3 * fit.one_sided_error:.1f} mm")
    return model.copy(spheres=spheres)
