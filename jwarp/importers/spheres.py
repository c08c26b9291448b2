"""Collision spheres fitted to a link's geometry (meshes and primitives), with a bounded
one-sided error.

Method (see ``docs/spheres.md``):

1. **Surface samples** ``S``: ``n_surface`` area-uniform points of the mesh (default
   ``clip(2 area / tolerance^2, 2000, 20000)``, a spacing of about ``tolerance / 1.4``) plus
   its vertices (the corners, where an uncovered point is most likely).
2. **Candidate spheres**, medial-axis-like: for each sample ``p`` with inward normal ``n`` the
   largest ball touching the surface at ``p`` (shrinking-ball iteration against ``S``: it
   stops at the opposite wall, so a thin plate gives thin balls), and centres at 1/2 and
   1/4 of the way from ``p`` to that ball's centre (smaller balls for small details), for
   2500 of the samples (and later for any sample no candidate holds); centres outside a
   watertight mesh are dropped. Each candidate centre ``c`` gets the radius
   ``d(c) + tolerance``, ``d(c)`` its distance to the mesh (while choosing, an upper bound:
   the distance to its own surface point and to the nearest sample; the chosen spheres get
   the exact distance from ``trimesh.proximity``): a sphere reaches at most ``tolerance``
   past the surface point nearest its centre, so the excess volume stays small.
3. **Greedy set cover** of ``S``: repeatedly take the candidate containing the most
   uncovered samples (a sample is covered by a sphere when it lies inside, or within the
   allowed error ``eps`` of it), then drop spheres whose samples all lie in others.
   Tolerance mode: ``eps = 0`` (every sample inside a sphere), fewest spheres found.
   ``max_spheres`` mode: the smallest ``eps`` (doubling from ``tolerance``, then
   bisection to 2 %) for which the greedy cover of 3000 of the samples needs at most
   ``max_spheres`` spheres; ``eps = 0`` if that is already possible. The spheres keep their
   reach ``d + tolerance``: too few of them leave parts of the surface outside, and the
   report says by how much (``one_sided_error``, ``meets_tolerance``). (For fewer spheres
   that still hold the whole surface, raise ``tolerance`` instead.) Greedy cover is an
   approximation: "smallest" is the smallest the greedy cover finds.
4. **Check** on ``n_surface`` fresh samples (another random stream): the one-sided error is
   the largest distance of a fresh sample outside every sphere. In tolerance mode a fresh
   sample further out than ``tolerance / 2`` (a margin for the gaps between samples) is
   added to ``S`` and the cover repeated (up to ``max_rounds`` times); the report states
   the final value either way.
5. **Excess volume**: the volume of the union of spheres outside the mesh, Monte Carlo
   with ``n_volume`` uniform points in the spheres' bounding box (``mesh.contains`` for a
   watertight mesh; for a mesh that is not watertight the inside is approximated by the
   mesh's convex hull, which underestimates the excess of a non-convex part).

Units: metres (whatever unit the mesh is in; tolerance in the same unit).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import trimesh
from scipy import sparse
from scipy.spatial import cKDTree

__all__ = ["SphereFit", "SphereFitOptions", "fit_spheres", "fit_geometry", "fit_link",
           "primitive_mesh", "load_mesh", "one_sided_error", "excess_volume", "PRIMITIVES"]

#: primitive kinds and the number of size values each takes (URDF order)
PRIMITIVES = {"box": 3, "cylinder": 2, "capsule": 2, "sphere": 1}
_DEPTHS = (1.0, 0.5, 0.25)  # candidate centres at these fractions of the medial radius
_CANDIDATE_POINTS = 2500  # samples whose medial balls give candidates (plus unheld ones)
_MAX_MODE_SAMPLES = 3000  # samples of the error search with max_spheres


@dataclass
class SphereFitOptions:
    """Options of :func:`fit_spheres` (lengths in the mesh's unit, usually m).

    tolerance: > 0, the allowed one-sided error and each sphere's reach past the surface.
    max_spheres: None (fewest spheres meeting ``tolerance``) or >= 1 (smallest error with at
        most this many spheres).
    n_surface: surface samples for the fit, and again (fresh) for the check; None:
        ``clip(2 area / tolerance^2, 2000, 20000)`` (spacing about tolerance / 1.4).
    n_volume: Monte Carlo points of the excess-volume estimate.
    seed: random seed (the fit is deterministic for a given seed).
    max_rounds: fit-check rounds in tolerance mode (>= 1).
    """

    tolerance: float
    max_spheres: int | None = None
    n_surface: int | None = None
    n_volume: int = 200_000
    seed: int = 0
    max_rounds: int = 4

    def validate(self) -> "SphereFitOptions":
        tol = self.tolerance
        if isinstance(tol, bool) or not isinstance(tol, (int, float, np.floating, np.integer)):
            raise TypeError(f"tolerance: expected a number, got {type(tol).__name__}")
        if not np.isfinite(tol) or tol <= 0:
            raise ValueError(f"tolerance: must be finite and > 0, got {tol}")
        self.tolerance = float(tol)
        if self.max_spheres is not None:
            self.max_spheres = _int(self.max_spheres, "max_spheres", 1)
        if self.n_surface is not None:
            self.n_surface = _int(self.n_surface, "n_surface", 10)
        self.n_volume = _int(self.n_volume, "n_volume", 100)
        self.seed = _int(self.seed, "seed", 0)
        self.max_rounds = _int(self.max_rounds, "max_rounds", 1)
        return self


@dataclass
class SphereFit:
    """A sphere set and its report.

    centres (k, 3), radii (k,) [mesh unit]; ``one_sided_error``: max distance of the fresh
    check samples outside every sphere; ``meets_tolerance``: ``one_sided_error <=
    tolerance``; ``fit_error``: the allowed error ``eps`` of the cover (0 in tolerance mode);
    ``excess_volume`` (+- ``excess_volume_stderr``, one standard error of the Monte Carlo
    estimate from ``n_volume`` points) and ``excess_fraction`` = excess / ``mesh_volume``
    (the convex hull's volume for a mesh that is not watertight); ``volume_method`` says how
    inside/outside was decided; ``rounds``: fit-check rounds used.
    """

    centres: np.ndarray
    radii: np.ndarray
    tolerance: float
    one_sided_error: float
    meets_tolerance: bool
    fit_error: float
    excess_volume: float
    excess_volume_stderr: float
    excess_fraction: float
    mesh_volume: float
    n_volume: int
    n_surface: int
    volume_method: str
    rounds: int = 1
    notes: list[str] = field(default_factory=list)

    @property
    def k(self) -> int:
        """Number of spheres."""
        return int(len(self.radii))

    def transformed(self, origin: np.ndarray) -> "SphereFit":
        """The same fit with centres mapped by the rigid 4x4 ``origin`` (radii unchanged)."""
        T = _origin(origin)
        out = SphereFit(**{**self.__dict__, "notes": list(self.notes),
                           "radii": self.radii.copy()})
        out.centres = self.centres @ T[:3, :3].T + T[:3, 3]
        return out


# ----------------------------------------------------------------- helpers
def _int(x: Any, name: str, low: int) -> int:
    if isinstance(x, bool) or not isinstance(x, (int, np.integer)):
        raise TypeError(f"{name}: expected an integer, got {type(x).__name__}")
    if x < low:
        raise ValueError(f"{name}: must be >= {low}, got {x}")
    return int(x)


def _origin(origin: Any) -> np.ndarray:
    T = np.eye(4) if origin is None else np.asarray(origin, np.float64)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise ValueError(f"origin: expected a finite 4x4 transform, got shape {T.shape}")
    R = T[:3, :3]
    if not np.allclose(R @ R.T, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
        raise ValueError("origin: the rotation part is not a rotation matrix")
    return T


def _check_mesh(mesh: Any) -> trimesh.Trimesh:
    if not isinstance(mesh, trimesh.Trimesh):
        raise TypeError(f"mesh: expected a trimesh.Trimesh, got {type(mesh).__name__}")
    if len(mesh.faces) == 0 or len(mesh.vertices) == 0:
        raise ValueError("mesh: empty (no faces)")
    if not np.all(np.isfinite(mesh.vertices)):
        raise ValueError("mesh: vertices contain NaN or inf")
    if not mesh.area > 0:
        raise ValueError("mesh: zero surface area")
    return mesh


def one_sided_error(points: np.ndarray, centres: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """(n,) distance [m] of each point outside every sphere: ``max(0, min_i |p - c_i| - r_i)``
    (0 inside some sphere). ``points`` (n, 3), ``centres`` (k, 3), ``radii`` (k,)."""
    p = np.asarray(points, np.float64).reshape(-1, 3)
    out = np.full(len(p), np.inf)
    for s in range(0, len(p), 4096):
        d = np.linalg.norm(p[s:s + 4096, None, :] - centres[None], axis=-1) - radii[None]
        out[s:s + 4096] = d.min(axis=1) if len(radii) else np.inf
    return np.maximum(out, 0.0)


def _sample(mesh: trimesh.Trimesh, n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    pts, face = trimesh.sample.sample_surface(mesh, n, seed=seed)
    return np.asarray(pts), np.asarray(mesh.face_normals[face])


def _shrinking_ball(points: np.ndarray, inward: np.ndarray, tree: cKDTree, r0: float,
                    iters: int = 40) -> np.ndarray:
    """(n,) radius of the largest ball tangent at each point (normal ``inward``) that holds
    no other sample: the medial ball (shrinking-ball iteration)."""
    r = np.full(len(points), r0)
    active = np.ones(len(points), bool)
    scale = 1e-9 * r0
    for _ in range(iters):
        if not active.any():
            break
        idx = np.flatnonzero(active)
        c = points[idx] + r[idx, None] * inward[idx]
        dist, nn = tree.query(c)
        q = tree.data[nn]
        shrink = dist < r[idx] - scale
        dq = q - points[idx]
        dot = np.einsum("ij,ij->i", dq, inward[idx])
        ok = shrink & (dot > 0)
        r_new = np.where(ok, np.einsum("ij,ij->i", dq, dq) / (2 * np.where(ok, dot, 1.0)), r[idx])
        changed = ok & (r_new < r[idx] - scale)
        r[idx] = np.minimum(r[idx], r_new)
        active[idx[~changed]] = False
    return r


def _candidates(mesh: trimesh.Trimesh, pts: np.ndarray, normals: np.ndarray,
                samples: np.ndarray, tolerance: float,
                watertight: bool) -> tuple[np.ndarray, np.ndarray]:
    """Candidate centres (M, 3) and radii (M,) = ``d + tolerance``, from the medial balls of
    ``pts`` (normals ``normals``) among all ``samples``. ``d`` is an upper bound of the
    centre's distance to the mesh (to its own surface point and to the nearest sample);
    :func:`_exact_radii` replaces it by the exact distance for the spheres chosen."""
    tree = cKDTree(samples)
    r0 = 0.5 * float(np.linalg.norm(mesh.extents))
    sides = (-1.0,) if watertight else (-1.0, 1.0)  # outward face normals: inward = -n
    centres, dists = [], []
    for side in sides:
        inward = side * normals
        r = _shrinking_ball(pts, inward, tree, r0)
        for f in _DEPTHS:
            centres.append(pts + (f * r)[:, None] * inward)
            dists.append(f * r)
    c, d = np.concatenate(centres), np.concatenate(dists)
    _, keep = np.unique(np.round(c / (0.05 * tolerance)).astype(np.int64), axis=0,
                        return_index=True)
    keep = np.sort(keep)
    c, d = c[keep], np.minimum(d[keep], tree.query(c[keep])[0])
    if watertight:  # keep centres inside (a medial centre of a closed mesh is inside)
        inside = mesh.contains(c)
        c, d = c[inside], d[inside]
    return c, d + tolerance


def _exact_radii(mesh: trimesh.Trimesh, c: np.ndarray, tolerance: float) -> np.ndarray:
    """(k,) exact distance of each centre to the mesh + tolerance."""
    _, d, _ = trimesh.proximity.closest_point(mesh, c)
    return np.asarray(d, np.float64) + tolerance


class _Coverage:
    """Which candidate holds which sample, with the slack ``|p - c| - r`` of every pair
    whose slack is <= ``eps_max`` (computed once; a cover at any ``eps <= eps_max`` filters
    it)."""

    def __init__(self, samples: np.ndarray, centres: np.ndarray, radii: np.ndarray,
                 eps_max: float) -> None:
        self.shape = (len(centres), len(samples))
        tree = cKDTree(samples)
        lists = tree.query_ball_point(centres, radii + eps_max, return_sorted=False)
        self.rows = np.repeat(np.arange(len(centres)), [len(x) for x in lists])
        self.cols = (np.concatenate([np.asarray(x, np.int64) for x in lists]) if len(self.rows)
                     else np.zeros(0, np.int64))
        self.slack = (np.linalg.norm(samples[self.cols] - centres[self.rows], axis=1)
                      - radii[self.rows])

    def matrix(self, eps: float) -> sparse.csr_matrix:
        """(M, N) int32 0/1: sample j lies within radius + eps of candidate i."""
        k = self.slack <= eps
        return sparse.csr_matrix((np.ones(int(k.sum()), np.int32), (self.rows[k], self.cols[k])),
                                 shape=self.shape)

    def unheld(self, eps: float) -> np.ndarray:
        """Indices of the samples no candidate holds at ``eps``."""
        held = np.zeros(self.shape[1], bool)
        held[self.cols[self.slack <= eps]] = True
        return np.flatnonzero(~held)


def _greedy_cover(A: sparse.csr_matrix, limit: int | None) -> list[int] | None:
    """Greedy set cover: indices of the chosen rows, None when some column cannot be
    covered or more than ``limit`` rows would be needed. Redundant rows are dropped."""
    n = A.shape[1]
    if A.shape[0] == 0:
        return None
    At = A.T.tocsr()
    if np.any(np.diff(At.indptr) == 0):
        return None
    uncovered = np.ones(n, bool)
    gain = np.asarray(A.sum(axis=1)).ravel().astype(np.int64)
    chosen: list[int] = []
    while uncovered.any():
        if limit is not None and len(chosen) >= limit:
            return None
        j = int(np.argmax(gain))
        cols = A.indices[A.indptr[j]:A.indptr[j + 1]]
        new = cols[uncovered[cols]]
        uncovered[new] = False
        chosen.append(j)
        gain -= np.asarray(At[new].sum(axis=0)).ravel().astype(np.int64)
    counts = np.asarray(A[chosen].sum(axis=0)).ravel()
    for j in reversed(list(chosen)):  # prune spheres whose samples all lie in others
        cols = A.indices[A.indptr[j]:A.indptr[j + 1]]
        if np.all(counts[cols] >= 2):
            counts[cols] -= 1
            chosen.remove(j)
    return chosen


def _cover(samples: np.ndarray, cand_c: np.ndarray, cand_r: np.ndarray,
           max_spheres: int | None, tol: float, eps_max: float) -> tuple[list[int], float]:
    """Chosen candidate indices and the allowed error eps of the cover: 0 when possible,
    else (too many spheres, or samples held by no candidate) the smallest eps found by
    doubling from ``tol`` and then bisection, to ~2 % or 0.05 tolerance."""
    cov = _Coverage(samples, cand_c, cand_r, 0.0)
    chosen = _greedy_cover(cov.matrix(0.0), max_spheres)
    if chosen is not None:
        return chosen, 0.0
    lo, hi = 0.0, tol
    while True:
        cov = _Coverage(samples, cand_c, cand_r, hi)
        best = _greedy_cover(cov.matrix(hi), max_spheres)
        if best is not None:
            break
        if hi >= eps_max:
            raise RuntimeError("sphere cover failed at the largest error (a bug)")
        lo, hi = hi, min(2.0 * hi, eps_max)
    while hi - lo > max(0.02 * hi, 0.05 * tol, 1e-12):
        mid = 0.5 * (lo + hi)
        got = _greedy_cover(cov.matrix(mid), max_spheres)
        if got is None:
            lo = mid
        else:
            hi, best = mid, got
    return best, hi


def _tighten(samples: np.ndarray, c: np.ndarray, r: np.ndarray, tol: float) -> np.ndarray:
    """Radii shrunk to what their samples need: each sample goes to the sphere it is deepest
    in, and a sphere keeps ``max |p - c| + tol / 2`` over its samples (a margin for the gaps
    between samples), never more than before."""
    need = np.zeros(len(r))
    for s in range(0, len(samples), 2048):
        d = np.linalg.norm(samples[s:s + 2048, None, :] - c[None], axis=-1)
        owner = np.argmin(d - r[None], axis=1)
        np.maximum.at(need, owner, d[np.arange(len(d)), owner])
    return np.minimum(r, need + 0.5 * tol)


def excess_volume(mesh: trimesh.Trimesh, centres: np.ndarray, radii: np.ndarray, *,
                  n: int = 200_000, seed: int = 0) -> tuple[float, float, str]:
    """Monte Carlo volume of the union of spheres outside ``mesh``: ``(volume, one standard
    error, method)`` from ``n`` uniform points in the spheres' bounding box. Inside test:
    ``mesh.contains`` for a watertight mesh, else the convex hull (documented
    approximation)."""
    c = np.asarray(centres, np.float64).reshape(-1, 3)
    r = np.asarray(radii, np.float64).reshape(-1)
    if len(r) == 0:
        return 0.0, 0.0, "none"
    lo, hi = (c - r[:, None]).min(0), (c + r[:, None]).max(0)
    box = float(np.prod(hi - lo))
    rng = np.random.default_rng(seed)
    x = lo + rng.random((n, 3)) * (hi - lo)
    in_union = one_sided_error(x, c, r) <= 0.0
    body = mesh if mesh.is_watertight else mesh.convex_hull
    method = "mesh.contains (watertight)" if mesh.is_watertight else \
        "convex hull of the mesh (not watertight: lower bound where the part is non-convex)"
    outside = np.zeros(n, bool)
    idx = np.flatnonzero(in_union)
    if len(idx):
        outside[idx] = ~body.contains(x[idx])
    p = outside.mean()
    return box * p, box * np.sqrt(p * (1 - p) / n), method


#: the largest surface a tolerance-mode fit takes, in cells of tolerance^2 (a Panda link at
#: 1 cm is about 1e3; a 10 m box at 1 cm is 6e6)
MAX_SURFACE_CELLS = 1e6


# ----------------------------------------------------------------- public API
def fit_spheres(mesh: trimesh.Trimesh, *, tolerance: float, max_spheres: int | None = None,
                n_surface: int | None = None, n_volume: int = 200_000, seed: int = 0,
                max_rounds: int = 4) -> SphereFit:
    """Fit spheres to ``mesh`` so that every surface point lies inside a sphere (one-sided
    error <= ``tolerance``), with as few spheres as the greedy cover finds; or, with
    ``max_spheres``, the smallest error reachable with at most that many (reported, with
    ``meets_tolerance`` False when it exceeds ``tolerance``). See the module docstring for
    the method and :class:`SphereFitOptions` for the arguments. Returns a :class:`SphereFit`
    (centres (k, 3), radii (k,), in the mesh's frame and unit)."""
    opt = SphereFitOptions(tolerance, max_spheres, n_surface, n_volume, seed, max_rounds).validate()
    mesh = _check_mesh(mesh)
    tol = opt.tolerance
    # the work before it starts: a cover within ``tolerance`` needs about one sphere per
    # tolerance^2 of surface in the worst case, and the fit's matrices grow with its square
    need = mesh.area / tol ** 2
    if opt.max_spheres is None and need > MAX_SURFACE_CELLS:
        raise ValueError(f"tolerance: a surface of {mesh.area:.4g} (unit^2) at tolerance {tol:g} "
                         f"is about {need:.3g} cells of tolerance^2 (at most "
                         f"{MAX_SURFACE_CELLS:.0e}): the fit would not end in reasonable time "
                         f"or memory; raise the tolerance, give max_spheres, or check the "
                         f"mesh's unit (a URDF in cm or mm needs a scale)")
    n_s = opt.n_surface or int(np.clip(2.0 * mesh.area / tol ** 2, 2000, 20000))
    watertight = bool(mesh.is_watertight)
    pts, nrm = _sample(mesh, n_s, opt.seed)
    used = np.unique(mesh.faces)
    samples = np.concatenate([pts, np.asarray(mesh.vertices)[used]])
    normals = np.concatenate([nrm, np.asarray(mesh.vertex_normals)[used]])
    rng = np.random.default_rng(opt.seed)
    n_cand = _CANDIDATE_POINTS if opt.max_spheres is None else _CANDIDATE_POINTS // 2
    sub = rng.permutation(len(samples))[:n_cand]
    cand_c, cand_r = _candidates(mesh, samples[sub], normals[sub], samples, tol, watertight)
    scale = float(np.linalg.norm(mesh.extents))
    eps_max = 2.0 * scale  # one sphere of any candidate then holds every sample
    check, _ = _sample(mesh, n_s, opt.seed + 7919)  # fresh stream
    notes: list[str] = []
    if opt.max_spheres is not None:  # the error search works on a subset (documented)
        keep = rng.permutation(len(samples))[:_MAX_MODE_SAMPLES]
        samples, normals = samples[keep], normals[keep]
    rounds = 0
    while True:
        rounds += 1
        lost = _Coverage(samples, cand_c, cand_r, 0.0).unheld(0.0)
        if len(lost):  # samples no candidate holds: add their own medial candidates
            c2, r2 = _candidates(mesh, samples[lost], normals[lost], samples, tol, watertight)
            cand_c, cand_r = np.concatenate([cand_c, c2]), np.concatenate([cand_r, r2])
        chosen, eps = _cover(samples, cand_c, cand_r, opt.max_spheres, tol, eps_max)
        c = cand_c[chosen]
        r = np.minimum(cand_r[chosen], _exact_radii(mesh, c, tol))
        if eps == 0.0:
            r = _tighten(samples, c, r, tol)
        err_all = one_sided_error(check, c, r)
        err = float(err_all.max())
        bad = err_all > (0.5 * tol if opt.max_spheres is None else max(eps, tol))
        if not bad.any() or rounds >= opt.max_rounds:
            break
        # fresh samples outside: fit them too, with their own candidates
        new_p = check[bad]
        _, _, tri = trimesh.proximity.closest_point(mesh, new_p)
        new_n = np.asarray(mesh.face_normals[tri])
        samples, normals = np.concatenate([samples, new_p]), np.concatenate([normals, new_n])
        c2, r2 = _candidates(mesh, new_p, new_n, samples, tol, watertight)
        cand_c, cand_r = np.concatenate([cand_c, c2]), np.concatenate([cand_r, r2])
        check, _ = _sample(mesh, n_s, opt.seed + 7919 * (rounds + 1))
    if eps > 0 and opt.max_spheres is None:
        notes.append(f"some samples are held by no candidate sphere; cover error {eps:.3g}")
    vol, se, method = excess_volume(mesh, c, r, n=opt.n_volume, seed=opt.seed + 104729)
    mvol = float(mesh.volume) if watertight else float(mesh.convex_hull.volume)
    return SphereFit(centres=c, radii=r, tolerance=tol, one_sided_error=err,
                     meets_tolerance=err <= tol, fit_error=float(eps), excess_volume=vol,
                     excess_volume_stderr=se, excess_fraction=vol / mvol if mvol > 0 else np.inf,
                     mesh_volume=mvol, n_volume=opt.n_volume, n_surface=n_s,
                     volume_method=method, rounds=rounds, notes=notes)


def primitive_mesh(kind: str, size: Any, *, sections: int = 64) -> trimesh.Trimesh:
    """A trimesh of a URDF-style primitive centred at the origin: ``box`` size (x, y, z),
    ``cylinder`` (radius, length) along z, ``capsule`` (radius, length of the cylindrical
    part) along z, ``sphere`` (radius,). Curved primitives are tessellated with
    ``sections`` segments per circle (their polygon lies inside the true surface by at
    most ``r (1 - cos(pi / sections))``)."""
    if kind not in PRIMITIVES:
        raise ValueError(f"kind: unknown primitive '{kind}', expected one of {sorted(PRIMITIVES)}")
    s = np.asarray(size, np.float64).reshape(-1)
    if s.size != PRIMITIVES[kind]:
        raise ValueError(f"size: a {kind} takes {PRIMITIVES[kind]} values, got {s.size}")
    if not np.all(np.isfinite(s)) or np.any(s <= 0):
        raise ValueError(f"size: must be finite and > 0, got {s.tolist()}")
    if kind == "box":
        return trimesh.creation.box(extents=s)
    if kind == "cylinder":
        return trimesh.creation.cylinder(radius=s[0], height=s[1], sections=sections)
    if kind == "capsule":
        return trimesh.creation.capsule(height=s[1], radius=s[0], count=[sections, sections])
    return trimesh.creation.icosphere(subdivisions=3, radius=s[0])


def load_mesh(path: str | Path, scale: Any = None) -> trimesh.Trimesh:
    """A mesh file (stl, obj, dae with pycollada, ...) as one Trimesh, scaled by ``scale``
    (a number or (3,) per axis)."""
    p = Path(path)
    if not p.is_file():
        raise ValueError(f"mesh: file not found '{p}'")
    try:
        m = trimesh.load(p, force="mesh")
    except Exception as e:  # trimesh raises many types for unreadable files
        raise ValueError(f"mesh: cannot load '{p}': {e}") from e
    if not isinstance(m, trimesh.Trimesh) or len(m.faces) == 0:
        raise ValueError(f"mesh: '{p}' holds no triangles")
    return _scaled(m, scale)


def _scaled(m: trimesh.Trimesh, scale: Any) -> trimesh.Trimesh:
    """A copy of ``m`` scaled per axis (``scale``: None, a number or (3,))."""
    if scale is None:
        return m
    sc = np.asarray(scale, np.float64).reshape(-1)
    if sc.size not in (1, 3) or not np.all(np.isfinite(sc)) or np.any(sc == 0):
        raise ValueError(f"scale: expected 1 or 3 finite non-zero numbers, got {sc.tolist()}")
    m = m.copy()
    m.apply_transform(np.diag([*np.broadcast_to(sc, (3,)), 1.0]))
    return m


def fit_geometry(kind: str, size: Any = None, origin: Any = None, mesh: Any = None, *,
                 scale: Any = None, tolerance: float, **options: Any) -> SphereFit:
    """Spheres for one collision geometry of a link, in the link frame.

    ``kind``: ``box``/``cylinder``/``capsule``/``sphere`` (``size`` as in
    :func:`primitive_mesh`) or ``mesh`` (``mesh``: a Trimesh or a file path, ``scale``
    optional); ``origin``: the geometry's 4x4 pose in the link frame (default identity).
    A sphere gives exactly itself (one sphere, no error, no excess). Other options go to
    :func:`fit_spheres`."""
    T = _origin(origin)
    if kind == "sphere":
        m = primitive_mesh(kind, size)  # validates size
        SphereFitOptions(tolerance, **{k: v for k, v in options.items()
                                       if k in ("max_spheres", "n_surface", "n_volume", "seed",
                                                "max_rounds")}).validate()
        r = float(np.asarray(size, np.float64).reshape(-1)[0])
        vol = 4.0 / 3.0 * np.pi * r ** 3
        fit = SphereFit(centres=np.zeros((1, 3)), radii=np.array([r]), tolerance=float(tolerance),
                        one_sided_error=0.0, meets_tolerance=True, fit_error=0.0,
                        excess_volume=0.0, excess_volume_stderr=0.0, excess_fraction=0.0,
                        mesh_volume=vol, n_volume=0, n_surface=0, volume_method="exact sphere",
                        notes=[f"exact: the geometry is a sphere ({len(m.faces)}-face mesh unused)"])
        return fit.transformed(T)
    if kind == "mesh":
        if mesh is None:
            raise ValueError("mesh: required for kind 'mesh'")
        m = load_mesh(mesh, scale) if isinstance(mesh, (str, Path)) else \
            _scaled(_check_mesh(mesh), scale)
    elif kind in PRIMITIVES:
        m = primitive_mesh(kind, size)
    else:
        raise ValueError(f"kind: unknown geometry '{kind}', expected mesh or one of "
                         f"{sorted(PRIMITIVES)}")
    return fit_spheres(m, tolerance=tolerance, **options).transformed(T)


def fit_link(geometries: Any, *, tolerance: float, **options: Any) -> SphereFit:
    """Spheres of all collision geometries of one link, in the link frame: one
    :func:`fit_geometry` per geometry, concatenated. Each geometry is a mapping or an
    object with ``kind``, ``size``, ``origin`` and, for meshes, ``mesh`` (or
    ``filename``/``path``) and ``scale``. The report: total count, the largest one-sided
    error, summed excess volume (an overestimate of the union's where geometries overlap)
    and mesh volume."""
    fits = []
    for i, g in enumerate(geometries):
        get = (g.get if isinstance(g, dict) else lambda k, d=None, g=g: getattr(g, k, d))
        mesh = get("mesh") if get("mesh") is not None else (get("filename") or get("path"))
        try:
            fits.append(fit_geometry(get("kind"), get("size"), get("origin"), mesh,
                                     scale=get("scale"), tolerance=tolerance, **options))
        except (ValueError, TypeError) as e:
            raise type(e)(f"geometries[{i}]: {e}") from e
    if not fits:
        raise ValueError("geometries: empty")
    err = max(f.one_sided_error for f in fits)
    return SphereFit(
        centres=np.concatenate([f.centres for f in fits]),
        radii=np.concatenate([f.radii for f in fits]), tolerance=float(tolerance),
        one_sided_error=err, meets_tolerance=all(f.meets_tolerance for f in fits),
        fit_error=max(f.fit_error for f in fits),
        excess_volume=sum(f.excess_volume for f in fits),
        excess_volume_stderr=float(np.sqrt(sum(f.excess_volume_stderr ** 2 for f in fits))),
        excess_fraction=(sum(f.excess_volume for f in fits)
                         / max(sum(f.mesh_volume for f in fits), 1e-300)),
        mesh_volume=sum(f.mesh_volume for f in fits), n_volume=max(f.n_volume for f in fits),
        n_surface=max(f.n_surface for f in fits),
        volume_method="; ".join(sorted({f.volume_method for f in fits})),
        rounds=max(f.rounds for f in fits), notes=[n for f in fits for n in f.notes])
