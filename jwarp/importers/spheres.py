"""Collision spheres fitted to a link's geometry (meshes and primitives): spheres centred
inside the part's solid, each reaching at most ``protrusion`` past its surface, that cover
the surface within a one-sided error ``tolerance``, with an optional count budget.

Method (see ``docs/spheres.md``):

0. **The solid**: inside/outside is the generalised winding number of the triangles (> 1/2
   inside; Warp's BVH query ``mesh_query_point_sign_winding_number`` on the CPU), so open
   meshes (holes, cracks, missing faces) and meshes of several overlapping bodies have a
   solid as a closed mesh does. A mesh whose triangles face inwards (negative signed
   volume) is flipped first. Signed distances to the surface come from the same query.
   Surface samples buried inside the solid (a face of one body inside another) are dropped.
1. **Surface samples** ``S``: ``n_surface`` area-uniform points (default
   ``clip(8 area / tolerance^2, 1500, 4000)``) plus the mesh's vertices (corners).
2. **Candidate centres on the medial axis**, only inside the solid: for 1500 samples ``p``
   (normal ``n``, both sides) the largest ball touching the surface at ``p`` that holds no
   other sample (shrinking-ball iteration: it stops at the opposite wall), and centres at
   1/2 and 1/4 of the way to that ball's centre. Centres the winding number puts outside
   are dropped (**no sphere is centred outside the solid**). A candidate centred at ``c``
   has radius ``clearance(c) + protrusion``, ``clearance`` its exact distance to the
   surface (an open mesh: also bounded by its holes, sampled): **a sphere reaches at most
   ``protrusion`` past the surface** (the ball of radius ``clearance`` lies in the solid,
   so every point of the sphere is within ``radius - clearance`` of it). The default
   protrusion follows the part's thickness ``R`` (its largest clearance):
   ``PROTRUSION_MIN tolerance`` (1/2) up to ``R = 3 tolerance`` (fingers, hands), rising
   linearly to ``PROTRUSION_MAX tolerance`` (2) at ``R = 5 tolerance`` (thick arm links).
3. **Greedy set cover** of ``S``: a sample counts as covered by a sphere when it lies
   within ``eps`` outside it; repeatedly take the candidate covering the most uncovered
   samples, drop spheres whose samples all lie in others, then replace two neighbouring
   spheres by one candidate holding every sample only they held, while possible. Without
   ``max_spheres``: ``eps = 0.85 tolerance`` (the rest is a margin for the gaps between
   samples). With ``max_spheres = K``: that ``eps`` if K spheres suffice, else the smallest
   ``eps`` (doubling, then bisection to 2 %) for which the greedy cover of 2000 of the
   samples needs at most K spheres: the one-sided error then exceeds the tolerance and the
   report says by how much.
   **Large parts** (``8 area / tolerance^2`` > 50 000 samples, e.g. a mobile base or a
   pedestal at 1 cm, and no ``max_spheres``): the dense matrix cannot hold enough samples,
   so the cover is sparse (the pairs within ``radius + eps`` from a k-d tree): up to 60 000
   surface samples (``min(8 area / tolerance^2, 60 000)``), medial candidates from one in
   six of them (on the inward side only when the mesh is closed and consistently wound),
   at most 60 000 candidates (thinned as above), the same greedy cover and
   pruning, no two-for-one step; samples no candidate holds even after their own
   candidates are added stay uncovered (the check reports them).
4. **Check** on at least 20 000 fresh boundary samples (another random stream):
   ``one_sided_error`` is the largest distance of a fresh sample outside every sphere.
   Fresh samples further out than 0.9 tolerance are added to ``S`` and the cover repeated
   with a 5 % smaller ``eps`` (up to ``max_rounds`` times); the round kept is the one
   within 0.9 tolerance (else within tolerance) with the fewest spheres.
5. **Report**: ``max_protrusion``, the largest ``radius - clearance(centre)`` (how far a
   sphere reaches outside the solid), and the **excess volume** (the union of spheres
   outside the solid, Monte Carlo with ``n_volume`` points in the spheres' bounding box,
   inside test by winding number) as a volume and a fraction of the solid's volume
   (``|mesh.volume|`` for a closed single-body mesh, else Monte Carlo by winding number).

Units: metres (whatever unit the mesh is in; tolerance and protrusion in the same unit).
Memory: the cover's dense matrix is at most ``_MAX_PAIRS`` float32 entries (about 50 MB);
the fit of a Panda link takes about a second on one core.
"""

from __future__ import annotations

import functools
import itertools
import os
import weakref
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, cast

import numpy as np
import trimesh
import warp as wp
from scipy import sparse
from scipy.spatial import cKDTree

from jwarp.utils.checks import check_int, check_real
from jwarp.utils.warp_init import init_quietly

__all__ = ["SphereFit", "SphereFitOptions", "fit_spheres", "fit_geometry", "fit_link", "fit_kernels",
           "surface_cover", "containment_bound", "containment_growth", "contain_fit", "link_part", "CONTAIN_CHECK", "CONTAIN_GAP",
           "primitive_mesh", "load_mesh", "one_sided_error", "excess_volume",
           "signed_distance", "inside_solid", "sphere_protrusion", "mesh_memo", "PRIMITIVES"]

#: primitive kinds and the number of size values each takes (URDF order)
PRIMITIVES = {"box": 3, "cylinder": 2, "capsule": 2, "sphere": 1}
_DEPTHS = (1.0, 0.5, 0.25)  # candidate centres at these fractions of the medial radius
_CANDIDATE_POINTS = 1500  # samples whose medial balls give candidates (plus unheld ones)
_FIT_SAMPLES = (1500, 4000)  # clip of the automatic surface sample count
_MAX_PAIRS = 12_000_000  # candidates x samples of the cover's dense slack matrix
#: a part whose automatic sample count ``8 area / tolerance^2`` exceeds this (a mobile base,
#: a pedestal: > 0.6 m^2 at 1 cm) is fitted by the sparse cover (module docstring, step 3)
_SPARSE_FROM = 50_000
_SPARSE_SAMPLES = 60_000  # at most this many fit samples of the sparse cover
_SPARSE_CANDIDATES = 60_000  # at most this many candidates of the sparse cover
_EPS_FIT = 0.85  # the cover's allowed error, as a fraction of the tolerance
_BUDGET_SAMPLES = 2000  # samples of the error search with max_spheres
_HOLE_DIRECTIONS = 64  # directions of the open-mesh clearance test
_CHECK_SAMPLES = 20_000  # fresh surface samples of the check (at least)
_REFIT = 0.9  # refit when a fresh sample lies further out than this x tolerance


@dataclass
class SphereFitOptions:
    """Options of :func:`fit_spheres` (lengths in the mesh's unit, usually m).

    tolerance: > 0, the allowed one-sided error (every surface point within this distance
        of a sphere).
    max_spheres: None (the fewest spheres meeting ``tolerance``) or >= 1 (at most this many
        spheres; the error reached is reported).
    n_surface: surface samples for the fit (the check takes at least 20 000 fresh ones);
        None: ``clip(8 area / tolerance^2, 1500, 4000)``.
    n_volume: Monte Carlo points of the excess-volume estimate.
    seed: random seed (the fit is deterministic for a given seed).
    max_rounds: fit-check rounds (>= 1; with a binding budget one).
    protrusion: > 0, how far a sphere may reach past the surface (each radius is the
        centre's clearance + protrusion); None: by the part's thickness, ``tolerance / 2``
        for thin parts up to ``2 tolerance`` for thick ones (module docstring).
    contain: None (the one-sided error mode above) or > 0, the gap ``g`` [mesh unit] of
        the containment mode: the cover holds every fit sample at least ``g`` inside a
        sphere, and :func:`contain_fit` then grows radii until every point of every
        triangle lies inside the union (certified on a point set of covering radius
        ``g``, module docstring "Containment"); ``tolerance`` then sets the sample density
        and the automatic protrusion only.
    """

    tolerance: float
    max_spheres: int | None = None
    n_surface: int | None = None
    n_volume: int = 100_000
    seed: int = 0
    max_rounds: int = 6
    protrusion: float | None = None
    contain: float | None = None

    def validate(self) -> SphereFitOptions:
        self.tolerance = check_real(self.tolerance, "tolerance", 0, open_lo=True)
        if self.protrusion is not None:
            self.protrusion = check_real(self.protrusion, "protrusion", 0, open_lo=True)
        if self.contain is not None:
            self.contain = check_real(self.contain, "contain", 0, open_lo=True)
        if self.max_spheres is not None:
            self.max_spheres = check_int(self.max_spheres, "max_spheres", 1)
        if self.n_surface is not None:
            self.n_surface = check_int(self.n_surface, "n_surface", 10)
        self.n_volume = check_int(self.n_volume, "n_volume", 100)
        self.seed = check_int(self.seed, "seed", 0)
        self.max_rounds = check_int(self.max_rounds, "max_rounds", 1)
        return self


@dataclass
class SphereFit:
    """A sphere set and its report.

    centres (k, 3), radii (k,) [mesh unit]; ``one_sided_error``: max distance of the fresh
    check samples outside every sphere; ``meets_tolerance``: ``one_sided_error <=
    tolerance``; ``fit_error``: the allowed error ``eps`` of the cover; ``protrusion``: the
    allowed reach past the surface; ``max_protrusion``: the largest reach of a sphere
    outside the solid (module docstring, step 5); ``excess_volume`` (+-
    ``excess_volume_stderr``, one standard error of the Monte Carlo estimate from
    ``n_volume`` points) and ``excess_fraction`` = excess / ``mesh_volume`` (the solid's
    volume); ``volume_method`` says how inside/outside was decided; ``rounds``: fit-check
    rounds used; ``watertight``: whether the mesh was closed.
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
    protrusion: float = 0.0
    max_protrusion: float = 0.0
    watertight: bool = True
    #: containment (:func:`contain_fit`): every point of every triangle inside the union
    #: of the spheres, certified with the covering gap ``contain_gap`` [mesh unit] on
    #: ``n_certify`` points; ``poke_out_bound`` [mesh unit]: an upper bound of how far a
    #: surface point can lie outside the spheres (0 when contained; else the largest
    #: deficit of the certificate's points + the gap, :func:`containment_bound`);
    #: ``grown``: the largest radius increase the containment took
    contained: bool = False
    #: fresh samples of the last containment check (0: certified, not sampled yet)
    n_fresh: int = 0
    contain_gap: float = 0.0
    poke_out_bound: float = float("nan")
    n_certify: int = 0
    grown: float = 0.0

    @property
    def k(self) -> int:
        """Number of spheres."""
        return int(len(self.radii))

    def transformed(self, origin: np.ndarray) -> SphereFit:
        """The same fit with centres mapped by the rigid 4x4 ``origin`` (radii unchanged)."""
        T = _origin(origin)
        out = SphereFit(**{**self.__dict__, "notes": list(self.notes),
                           "radii": self.radii.copy()})
        out.centres = self.centres @ T[:3, :3].T + T[:3, 3]
        return out


# ----------------------------------------------------------------- helpers
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
    c = np.asarray(centres, np.float64).reshape(-1, 3)
    r = np.asarray(radii, np.float64).reshape(-1)
    out = np.full(len(p), np.inf)
    if len(r) == 0:
        return out
    if len(r) * len(p) > 1_000_000:  # many: Warp's CPU loop (float64, the same figures)
        _init_warp()
        res = wp.zeros(len(p), dtype=wp.float64, device="cpu")
        wp.launch(_outside_kernel, len(p), device="cpu", inputs=[
            wp.array(p, dtype=wp.vec3d, device="cpu"), wp.array(c, dtype=wp.vec3d, device="cpu"),
            wp.array(r, dtype=wp.float64, device="cpu"), res])
        return np.maximum(res.numpy(), 0.0)
    step = max(1, 4_000_000 // max(len(r), 1))  # bounded memory at any sphere count
    for s in range(0, len(p), step):
        d = np.linalg.norm(p[s:s + step, None, :] - c[None], axis=-1) - r[None]
        out[s:s + step] = d.min(axis=1)
    return np.maximum(out, 0.0)


# ----------------------------------------------------------------- the solid (Warp)
def _init_warp() -> None:
    # importers sit below jwarp.core: Warp directly (init is a no-op once done)
    wp.config.quiet = True  # type: ignore[attr-defined]
    if hasattr(wp, "LOG_WARNING"):
        wp.config.log_level = max(wp.config.log_level, wp.LOG_WARNING)
    init_quietly()  # without Warp's "CUDA driver not found" line on a CPU machine


@wp.kernel(enable_backward=False)
def _outside_kernel(
    # Data in:
    points: wp.array(dtype=wp.vec3d),  # type: ignore[valid-type]
    centres: wp.array(dtype=wp.vec3d),  # type: ignore[valid-type]
    radii: wp.array(dtype=wp.float64),  # type: ignore[valid-type]
    # Data out:
    out: wp.array(dtype=wp.float64),  # type: ignore[valid-type]
):
    i = wp.tid()
    p = points[i]
    best = wp.float64(1.0e300)
    for j in range(centres.shape[0]):
        best = wp.min(best, wp.length(p - centres[j]) - radii[j])
    out[i] = best


@wp.kernel(enable_backward=False)
def _signed_distance_kernel(
    # Model:
    mesh: wp.uint64,
    # Data in:
    points: wp.array(dtype=wp.vec3),  # type: ignore[valid-type]
    max_dist: float,
    # Data out:
    out: wp.array(dtype=float),  # type: ignore[valid-type]
):
    i = wp.tid()
    p = points[i]
    q = wp.mesh_query_point_sign_winding_number(mesh, p, max_dist)
    if q.result:  # type: ignore[attr-defined]
        c = wp.mesh_eval_position(mesh, q.face, q.u, q.v)  # type: ignore[attr-defined]
        out[i] = q.sign * wp.length(p - c)  # type: ignore[attr-defined]
    else:
        out[i] = max_dist


def fit_kernels() -> tuple:
    """The Warp kernels of the sphere fit (``jwarp warmup --families spherize``)."""
    return (_outside_kernel, _signed_distance_kernel, _nearest_kernel)


class _Solid:
    """A mesh's solid for point queries: generalised winding number > 1/2 inside (Warp's
    BVH query on the CPU), signed distance to the surface (negative inside). Coordinates are
    taken relative to the bounding-box centre (float32 in Warp)."""

    def __init__(self, mesh: trimesh.Trimesh) -> None:
        _init_warp()
        V = np.asarray(mesh.vertices, np.float64)
        F = np.asarray(mesh.faces, np.int64)
        a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
        self.centre = 0.5 * (V.min(0) + V.max(0))
        signed = float(np.einsum("ij,ij->i", a - self.centre,
                                 np.cross(b - self.centre, c - self.centre)).sum() / 6.0)
        self.flipped = signed < 0  # triangles facing inwards: flip them
        if self.flipped:
            F = F[:, ::-1]
        self.faces = F
        self.simple = False  # a closed single-body mesh (set by the fit): nothing buried
        self.closed = bool(mesh.is_watertight)  # no holes: the triangles bound the solid
        self.extent = float(np.linalg.norm(V.max(0) - V.min(0)))
        self._pts: wp.array = wp.array((V - self.centre).astype(np.float32), dtype=wp.vec3,
                                       device="cpu")
        self._idx: wp.array = wp.array(F.astype(np.int32).ravel(), dtype=wp.int32, device="cpu")
        self.mesh = wp.Mesh(points=self._pts, indices=self._idx, support_winding_number=True)

    def signed_distance(self, x: np.ndarray) -> np.ndarray:
        """(n,) signed distance of the points ``x`` (n, 3) to the surface, < 0 inside."""
        x = np.asarray(x, np.float64).reshape(-1, 3)
        if len(x) == 0:
            return np.zeros(0)
        maxd = 2.0 * self.extent + float(np.linalg.norm(x - self.centre, axis=1).max()) + 1.0
        out = wp.zeros(len(x), dtype=float, device="cpu")
        pts: wp.array = wp.array((x - self.centre).astype(np.float32), dtype=wp.vec3, device="cpu")
        wp.launch(_signed_distance_kernel, len(x), inputs=[self.mesh.id, pts, maxd, out],
                  device="cpu")
        return out.numpy().astype(np.float64)


def signed_distance(mesh: trimesh.Trimesh, points: np.ndarray) -> np.ndarray:
    """(n,) signed distance [mesh unit] of ``points`` (n, 3) to the surface of ``mesh``,
    negative inside its solid (generalised winding number > 1/2: defined for open and
    multi-body meshes too). Float32 precision relative to the mesh's bounding-box centre."""
    return _Solid(_check_mesh(mesh)).signed_distance(points)


def inside_solid(mesh: trimesh.Trimesh, points: np.ndarray) -> np.ndarray:
    """(n,) bool: ``points`` (n, 3) inside the solid of ``mesh`` (generalised winding
    number > 1/2; for a closed mesh the same as ``mesh.contains``)."""
    return signed_distance(mesh, points) < 0.0


def _fibonacci(n: int) -> np.ndarray:
    i = np.arange(n) + 0.5
    z = 1.0 - 2.0 * i / n
    t = np.pi * (1.0 + 5 ** 0.5) * i
    s = np.sqrt(1.0 - z * z)
    return np.stack([s * np.cos(t), s * np.sin(t), z], axis=1)


def _clearance(solid: _Solid, c: np.ndarray, d: np.ndarray) -> np.ndarray:
    """(M,) clearance of centres ``c`` inside the solid: their distance ``d`` to the
    triangles, and for an open mesh at most the radius of a ball around ``c`` whose 64
    sampled points at 0.99 x that radius all lie inside the solid (a hole is no triangle:
    a ball reaching through it is shrunk by bisection, 6 steps)."""
    d = np.asarray(d, np.float64).copy()
    if solid.closed or len(d) == 0:
        return d
    u = _fibonacci(_HOLE_DIRECTIONS)

    def all_inside(idx: np.ndarray, rad: np.ndarray) -> np.ndarray:
        x = (c[idx, None, :] + 0.99 * rad[:, None, None] * u[None]).reshape(-1, 3)
        return cast(np.ndarray, (solid.signed_distance(x).reshape(len(idx), -1) < 0).all(axis=1))

    idx = np.flatnonzero(~all_inside(np.arange(len(d)), d))
    if len(idx):
        lo, hi = np.zeros(len(idx)), d[idx].copy()
        for _ in range(6):
            mid = 0.5 * (lo + hi)
            ok = all_inside(idx, mid)
            lo, hi = np.where(ok, mid, lo), np.where(ok, hi, mid)
        d[idx] = 0.99 * lo
    return d


def _protrusion(solid: _Solid, centres: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """(k,) how far each sphere reaches outside the solid: ``radius - clearance(centre)``
    (the ball of radius ``clearance`` lies inside, so every point of the sphere is within
    that distance of the solid; a centre outside has a negative clearance)."""
    c = np.asarray(centres, np.float64).reshape(-1, 3)
    r = np.asarray(radii, np.float64).reshape(-1)
    if len(r) == 0:
        return np.zeros(0)
    sd = solid.signed_distance(c)
    inside = sd < 0
    clear = sd * -1.0
    clear[inside] = _clearance(solid, c[inside], -sd[inside])
    return r - clear


def sphere_protrusion(mesh: trimesh.Trimesh, centres: np.ndarray,
                      radii: np.ndarray) -> np.ndarray:
    """(k,) how far [mesh unit] each sphere (``centres`` (k, 3), ``radii`` (k,)) reaches
    outside the solid of ``mesh``: ``radius + signed_distance(centre)`` (an upper bound,
    exact for a convex part: the ball of radius ``-signed_distance`` lies inside); for an
    open mesh the clearance is also bounded by the solid's holes (sampled, see the module
    docstring)."""
    return _protrusion(_Solid(_check_mesh(mesh)), centres, radii)


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


def _candidates(solid: _Solid, pts: np.ndarray, normals: np.ndarray, samples: np.ndarray,
                grid: float, sides: tuple = (-1.0, 1.0)) -> tuple[np.ndarray, np.ndarray]:
    """Candidate centres (M, 3) inside the solid and their clearance (M,): the medial balls
    of ``pts`` (normals ``normals``, both ``sides``: inward is -normal for a well-oriented
    mesh) among ``samples``, and centres at 1/2 and 1/4 of the way to them; duplicates
    within ``grid`` merged."""
    tree = cKDTree(samples)
    r0 = 0.5 * solid.extent
    centres = []
    for side in sides:
        inward = side * normals
        r = _shrinking_ball(pts, inward, tree, r0)
        for f in _DEPTHS:
            centres.append(pts + (f * r)[:, None] * inward)
    c = np.concatenate(centres)
    _, keep = np.unique(np.round(c / grid).astype(np.int64), axis=0, return_index=True)
    c = c[np.sort(keep)]
    sd = solid.signed_distance(c)
    inside = sd < -1e-9 * max(solid.extent, 1e-300)
    c = c[inside]
    return c, _clearance(solid, c, -sd[inside])


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
        if len(new):  # the rows of the newly covered samples, gathered (= At[new].sum(0))
            lo, hi = At.indptr[new], At.indptr[new + 1]
            ln = hi - lo
            pos = np.repeat(lo - np.cumsum(ln) + ln, ln) + np.arange(int(ln.sum()))
            gain -= np.bincount(At.indices[pos], weights=At.data[pos],
                                minlength=len(gain)).astype(np.int64)
    counts = np.asarray(A[chosen].sum(axis=0)).ravel()
    for j in reversed(list(chosen)):  # prune spheres whose samples all lie in others
        cols = A.indices[A.indptr[j]:A.indptr[j + 1]]
        if np.all(counts[cols] >= 2):
            counts[cols] -= 1
            chosen.remove(j)
    return chosen


class _Slack:
    """Dense (M, N) float32 ``|p_j - c_i| - r_i`` of candidates and samples (at most
    ``_MAX_PAIRS`` entries: the caller subsamples candidates; ``eps`` unused, the signature
    of :class:`_Holds`)."""

    def __init__(self, samples: np.ndarray, centres: np.ndarray, radii: np.ndarray,
                 eps: float = 0.0) -> None:
        self.c, self.r = centres, radii
        self.s = np.empty((len(centres), len(samples)), np.float32)
        step = max(1, 4_000_000 // max(len(samples), 1))
        o = samples.mean(axis=0) if len(samples) else np.zeros(3)
        p = samples - o
        pp = np.einsum("ij,ij->i", p, p)
        for a in range(0, len(centres), step):
            c = centres[a:a + step] - o
            d2 = np.einsum("ij,ij->i", c, c)[:, None] + pp[None] - 2.0 * (c @ p.T)
            self.s[a:a + step] = np.sqrt(np.maximum(d2, 0.0)) - radii[a:a + step, None]

    def matrix(self, eps: float) -> sparse.csr_matrix:
        """(M, N) int32 0/1: sample j lies within radius + eps of candidate i."""
        return sparse.csr_matrix(self.s <= eps, dtype=np.int32)

    def unheld(self, eps: float) -> np.ndarray:
        """Indices of the samples no candidate holds at ``eps``."""
        return np.flatnonzero(~(self.s <= eps).any(axis=0)) if len(self.s) else \
            np.arange(self.s.shape[1])


class _Holds:
    """Sparse (M, N) 0/1 "candidate i holds sample j at ``eps``" (``|p_j - c_i| - r_i <=
    eps``) of a large part, from a k-d tree of the samples (module docstring, step 3)."""

    def __init__(self, samples: np.ndarray, centres: np.ndarray, radii: np.ndarray,
                 eps: float) -> None:
        tree = cKDTree(samples)
        rows = tree.query_ball_point(centres, radii + eps, return_sorted=False) \
            if len(centres) else []
        n = np.fromiter((len(x) for x in rows), np.int64, len(rows))
        indptr = np.concatenate([[0], np.cumsum(n)])
        indices = np.fromiter(itertools.chain.from_iterable(rows), np.int32, int(indptr[-1]))
        self.A = sparse.csr_matrix((np.ones(len(indices), np.int32), indices, indptr),
                                   shape=(len(centres), len(samples)))
        self.A.sort_indices()

    def unheld(self, eps: float) -> np.ndarray:
        """Indices of the samples no candidate holds (at the ``eps`` of the construction;
        the argument is the signature of :class:`_Slack`)."""
        return np.flatnonzero(np.diff(self.A.tocsc().indptr) == 0)

    def cover(self) -> list[int]:
        """Greedy cover of the samples some candidate holds (the others stay uncovered)."""
        held = np.flatnonzero(np.diff(self.A.tocsc().indptr) > 0)
        if len(held) == 0:
            return [int(np.argmax(np.diff(self.A.indptr)))] if self.A.shape[0] else []
        got = _greedy_cover(self.A[:, held].tocsr(), None)
        return [] if got is None else got


def _two_for_one(B: np.ndarray, chosen: list[int], centres: np.ndarray,
                 reach: np.ndarray) -> list[int]:
    """Local search after the greedy cover (``B`` (M, N) bool: candidate i holds sample j;
    ``reach`` (M,): radius + eps): replace two chosen spheres that hold a common region
    (centres closer than their summed reach) by one candidate that holds every sample only
    they held, while such a pair exists."""
    chosen = list(chosen)
    tried: set = set()
    improved = True
    while improved and len(chosen) > 1:
        improved = False
        cnt = B[chosen].sum(axis=0, dtype=np.int32)
        ch = np.asarray(chosen)
        dist = np.linalg.norm(centres[ch, None] - centres[None, ch], axis=-1)
        near = dist <= reach[ch, None] + reach[None, ch]
        for a, b in zip(*np.nonzero(np.triu(near, 1))):
            i, j = int(ch[a]), int(ch[b])
            if (i, j) in tried:
                continue
            tried.add((i, j))
            only = np.flatnonzero((B[i] | B[j]) & (cnt - B[i] - B[j] <= 0))
            ok = np.flatnonzero(B[:, only].all(axis=1)) if len(only) else np.arange(len(B))
            if len(ok):
                m = int(ok[np.argmax(B[ok].sum(axis=1))])
                chosen = [x for x in chosen if x not in (i, j)] + [m]
                improved = True
                break
    return chosen


def _cover(slack: _Slack, max_spheres: int | None, eps0: float,
           eps_max: float) -> tuple[list[int], float]:
    """Chosen candidate indices and the allowed error eps of the cover: ``eps0`` when
    possible, else (too many spheres, or samples held by no candidate) the smallest eps
    found by doubling from ``eps0`` and then bisection, to ~2 %."""
    chosen = _greedy_cover(slack.matrix(eps0), max_spheres)
    if chosen is not None:
        return _two_for_one(slack.s <= eps0, chosen, slack.c, slack.r + eps0), eps0
    # (a negative eps0, the containment mode: widened by steps of |eps0|, doubling)
    step = abs(eps0) if eps0 != 0 else 1e-12
    lo, hi = eps0, eps0 + step
    while True:
        best = _greedy_cover(slack.matrix(hi), max_spheres)
        if best is not None:
            break
        if hi >= eps_max:
            raise RuntimeError("sphere cover failed at the largest error (a bug)")
        step *= 2.0
        lo, hi = hi, min(eps0 + step, eps_max)
    while hi - lo > max(0.02 * abs(hi), 0.02 * abs(eps0), 1e-12):
        mid = 0.5 * (lo + hi)
        got = _greedy_cover(slack.matrix(mid), max_spheres)
        if got is None:
            lo = mid
        else:
            hi, best = mid, got
    return _two_for_one(slack.s <= hi, best, slack.c, slack.r + hi), hi


#: per mesh object: what the fits of one link compute more than once (its solid, solid
#: volumes, boundary samples); weak keys, so nothing outlives the mesh
_MESH_CACHE: weakref.WeakKeyDictionary[trimesh.Trimesh, tuple[int, dict]] = weakref.WeakKeyDictionary()


def mesh_memo(mesh: trimesh.Trimesh, key: Any, make: Any) -> Any:
    """``make()`` computed once per mesh object and ``key`` (a hashable) and remembered
    while the mesh lives (the fits of one link at several protrusions, its refinements);
    a mesh whose face count changed starts afresh."""
    got = _MESH_CACHE.get(mesh)
    if got is None or got[0] != len(mesh.faces):
        got = _MESH_CACHE[mesh] = (len(mesh.faces), {})
    if key not in got[1]:
        got[1][key] = make()
    return got[1][key]


def _solid_of(mesh: trimesh.Trimesh) -> _Solid:
    return mesh_memo(mesh, "solid", lambda: _Solid(mesh))


def _solid_volume(mesh: trimesh.Trimesh, solid: _Solid, n: int, seed: int
                  ) -> tuple[float, str]:
    """The solid's volume: ``|mesh.volume|`` of a closed single-body mesh, else Monte Carlo
    by winding number with ``n`` points in the bounding box (once per mesh object, n and
    seed)."""
    return mesh_memo(mesh, ("volume", n, seed),
                     lambda: _solid_volume_new(mesh, solid, n, seed))


def _solid_volume_new(mesh: trimesh.Trimesh, solid: _Solid, n: int, seed: int
                      ) -> tuple[float, str]:
    if mesh.is_watertight and mesh.body_count == 1:
        return abs(float(mesh.volume)), "closed mesh"
    lo, hi = mesh.bounds
    x = lo + np.random.default_rng(seed).random((n, 3)) * (hi - lo)
    return float(np.prod(hi - lo)) * float((solid.signed_distance(x) < 0).mean()), \
        "Monte Carlo by winding number"


def _excess(solid: _Solid, centres: np.ndarray, radii: np.ndarray, n: int,
            seed: int) -> tuple[float, float]:
    c = np.asarray(centres, np.float64).reshape(-1, 3)
    r = np.asarray(radii, np.float64).reshape(-1)
    if len(r) == 0:
        return 0.0, 0.0
    lo, hi = (c - r[:, None]).min(0), (c + r[:, None]).max(0)
    box = float(np.prod(hi - lo))
    x = lo + np.random.default_rng(seed).random((n, 3)) * (hi - lo)
    in_union = one_sided_error(x, c, r) <= 0.0
    outside = np.zeros(n, bool)
    idx = np.flatnonzero(in_union)
    if len(idx):
        outside[idx] = solid.signed_distance(x[idx]) >= 0.0
    p = outside.mean()
    return box * p, box * np.sqrt(p * (1 - p) / n)


def excess_volume(mesh: trimesh.Trimesh, centres: np.ndarray, radii: np.ndarray, *,
                  n: int = 200_000, seed: int = 0) -> tuple[float, float, str]:
    """Monte Carlo volume of the union of spheres outside the solid of ``mesh``: ``(volume,
    one standard error, method)`` from ``n`` uniform points in the spheres' bounding box.
    Inside test: generalised winding number > 1/2 (open and multi-body meshes too)."""
    vol, se = _excess(_Solid(_check_mesh(mesh)), centres, radii, n, seed)
    return vol, se, "winding number"


# ----------------------------------------------------------------- containment
#: fresh area-uniform surface samples (plus the mesh's vertices) of the check after
#: :func:`contain_fit` (another random stream than the fit's and the certificate's)
CONTAIN_CHECK = 100_000
#: radii grown this much [mesh unit] beyond the certificate's need (float64 rounding)
_ROUNDING = 1e-9
#: default gap [m] of the containment certificate (:func:`surface_cover`)
CONTAIN_GAP = 0.001
#: the most certificate points of one part (:func:`surface_cover`); beyond: ValueError
MAX_COVER_POINTS = 20_000_000


def surface_cover(mesh: trimesh.Trimesh, gap: float) -> np.ndarray:
    """(n, 3) points on the triangles of ``mesh`` such that **every point of every
    triangle lies within** ``gap`` **of one of them** [mesh unit]: each triangle of longest
    edge ``e`` is cut into ``m^2`` similar triangles, ``m = ceil(e / (sqrt(3) gap))``, and
    their corners are taken. A point of a triangle of longest edge ``a`` lies within
    ``a / sqrt(3)`` of one of its corners (the circumradius ``a / (2 sin A)``, ``A >= 60``
    deg, for an acute triangle; half an edge on the boundary of an obtuse one), here
    ``<= gap``. Deterministic (no sampling). Buried faces (a body inside another) are kept:
    a mesh checker such as coal tests every triangle."""
    mesh = _check_mesh(mesh)
    g = check_real(gap, "gap", 0, open_lo=True)
    V = np.asarray(mesh.vertices, np.float64)
    F = np.asarray(mesh.faces, np.int64)
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    e = np.max(np.stack([np.linalg.norm(b - a, axis=1), np.linalg.norm(c - b, axis=1),
                         np.linalg.norm(a - c, axis=1)]), axis=0)
    m = np.maximum(np.ceil(e / (np.sqrt(3.0) * g)), 1).astype(np.int64)
    total = int(((m + 1) * (m + 2) // 2).sum())
    if total > MAX_COVER_POINTS:
        raise ValueError(f"gap: {g:g} needs {total} certificate points on a surface of "
                         f"{mesh.area:.4g} (at most {MAX_COVER_POINTS}); raise the gap")
    out = [V[np.unique(F)]]
    for k in np.unique(m):
        if k == 1:
            continue  # the corners: the vertices above
        sel = m == k
        i, j = np.meshgrid(np.arange(k + 1), np.arange(k + 1), indexing="ij")
        keep = i + j <= k
        u, v = i[keep] / k, j[keep] / k  # barycentric grid (corners included)
        pa, pb, pc = a[sel], b[sel], c[sel]
        pts = (pa[:, None] * (1 - u - v)[None, :, None] + pb[:, None] * u[None, :, None]
               + pc[:, None] * v[None, :, None])
        out.append(pts.reshape(-1, 3))
    return np.concatenate(out)


@wp.kernel(enable_backward=False)
def _nearest_kernel(
    # Data in:
    points: wp.array(dtype=wp.vec3d),  # type: ignore[valid-type]
    centres: wp.array(dtype=wp.vec3d),  # type: ignore[valid-type]
    radii: wp.array(dtype=wp.float64),  # type: ignore[valid-type]
    # Data out:
    out: wp.array(dtype=wp.float64),  # type: ignore[valid-type]
    arg: wp.array(dtype=wp.int32),  # type: ignore[valid-type]
):
    i = wp.tid()
    p = points[i]
    best = wp.float64(1.0e300)
    k = int(0)
    for j in range(centres.shape[0]):
        d = wp.length(p - centres[j]) - radii[j]
        if d < best:
            best = d
            k = j
    out[i] = best
    arg[i] = k


def _nearest_deficit(points: np.ndarray, centres: np.ndarray, radii: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray]:
    """(n,) ``min_i |p - c_i| - r_i`` and (n,) its argmin (float64; Warp's CPU loop)."""
    p = np.asarray(points, np.float64).reshape(-1, 3)
    c = np.asarray(centres, np.float64).reshape(-1, 3)
    r = np.asarray(radii, np.float64).reshape(-1)
    if len(p) == 0 or len(r) == 0:
        return np.full(len(p), np.inf), np.zeros(len(p), np.int64)
    _init_warp()
    out = wp.zeros(len(p), dtype=wp.float64, device="cpu")
    arg = wp.zeros(len(p), dtype=wp.int32, device="cpu")
    wp.launch(_nearest_kernel, len(p), device="cpu", inputs=[
        wp.array(p, dtype=wp.vec3d, device="cpu"), wp.array(c, dtype=wp.vec3d, device="cpu"),
        wp.array(r, dtype=wp.float64, device="cpu"), out, arg])
    return out.numpy(), arg.numpy().astype(np.int64)


def _cover_of(mesh: trimesh.Trimesh, gap: float) -> np.ndarray:
    return mesh_memo(mesh, ("cover", float(gap)), lambda: surface_cover(mesh, gap))


def containment_bound(mesh: trimesh.Trimesh, centres: np.ndarray, radii: np.ndarray, *,
                      gap: float = CONTAIN_GAP, surface_error: float = 0.0) -> float:
    """An upper bound [mesh unit] of how far a point of the triangles of ``mesh`` lies
    outside the union of the spheres (``centres`` (k, 3), ``radii`` (k,)): the largest
    ``min_i |p - c_i| - r_i`` over the points ``p`` of :func:`surface_cover` (``gap``)
    plus ``gap`` (that function is 1-Lipschitz in p, and every surface point is within
    ``gap`` of some ``p``), plus ``surface_error`` (how far the true surface may lie
    outside the triangles: a tessellated cylinder), clipped at 0. 0 means every surface
    point is inside (up to float64 rounding)."""
    if len(np.asarray(radii).reshape(-1)) == 0:
        return float("inf")
    d, _ = _nearest_deficit(_cover_of(_check_mesh(mesh), gap), centres, radii)
    return max(0.0, float(d.max()) + float(gap) + float(surface_error))


def containment_growth(mesh: trimesh.Trimesh, centres: np.ndarray, radii: np.ndarray, *,
                       gap: float = CONTAIN_GAP, surface_error: float = 0.0) -> np.ndarray:
    """(k,) how much [mesh unit] each sphere's radius must grow for the spheres
    (``centres`` (k, 3), ``radii`` (k,)) to contain every point of the triangles of ``mesh``
    (step 2 of :func:`contain_fit`: each cover point not ``gap + surface_error`` deep goes to
    the sphere it is deepest in); all 0 when they contain it already."""
    c = np.asarray(centres, np.float64).reshape(-1, 3)
    r = np.asarray(radii, np.float64).reshape(-1)
    P = _cover_of(_check_mesh(mesh), check_real(gap, "gap", 0, open_lo=True))
    depth = float(gap) + float(surface_error)
    d, arg = _nearest_deficit(P, c, r)
    need = d + depth > 0
    grown = r.copy()
    if need.any():
        want = np.linalg.norm(P[need] - c[arg[need]], axis=1) + depth + _ROUNDING
        np.maximum.at(grown, arg[need], want)
    return grown - r


def contain_fit(mesh: trimesh.Trimesh, fit: SphereFit, gap: float = CONTAIN_GAP, *,
                surface_error: float = 0.0, n_check: int = CONTAIN_CHECK,
                seed: int = 0) -> SphereFit:
    """``fit`` (spheres of ``mesh``, same frame) with radii grown so that **every point of
    every triangle lies inside the union of the spheres**:

    1. the points ``P`` of :func:`surface_cover` (covering radius ``gap``);
    2. each ``p`` of ``P`` less than ``gap + surface_error`` deep inside every sphere is
       given to the sphere it is deepest in (the smallest ``|p - c_i| - r_i``: the least
       growth), and that sphere's radius grows to ``|p - c_i| + gap + surface_error``
       (radii only grow, so points already deep enough stay so);
    3. then every ``p`` lies ``gap + surface_error`` deep, and a surface point ``x``
       within ``gap`` of ``p`` (the true surface within ``surface_error`` of the triangles)
       has ``|x - c_i| - r_i <= 0``: contained (the certificate; checked again by
       :func:`containment_bound`, and on ``n_check`` fresh area-uniform samples and the
       vertices: ``one_sided_error`` must be 0).

    Returns a new :class:`SphereFit` with ``contained``, ``contain_gap``, ``n_certify``,
    ``grown`` (largest radius increase), ``poke_out_bound`` (0), the measured
    ``max_protrusion`` and excess volume; ``protrusion`` is the larger of the allowed one
    and the measured one. ``n_check`` 0: the certificate only (no fresh samples, the
    excess volume not measured again: the steps of a fit; ``n_fresh`` 0). ``fit`` already
    contained with this gap and checked on at least ``n_check`` samples is returned as
    is."""
    mesh = _check_mesh(mesh)
    if not isinstance(fit, SphereFit):
        raise TypeError(f"fit: expected a SphereFit, got {type(fit).__name__}")
    g = check_real(gap, "gap", 0, open_lo=True)
    if isinstance(surface_error, bool) or not np.isfinite(surface_error) or surface_error < 0:
        raise ValueError(f"surface_error: expected a finite distance >= 0, got "
                         f"{surface_error!r}")
    if n_check != 0:
        check_int(n_check, "n_check", 100)
    if fit.contained and fit.contain_gap == g and surface_error == 0 \
            and fit.n_fresh >= n_check:
        return fit
    c = np.asarray(fit.centres, np.float64).reshape(-1, 3)
    r = np.asarray(fit.radii, np.float64).reshape(-1).copy()
    if len(r) == 0:
        raise ValueError("fit: no spheres to contain the mesh with")
    P = _cover_of(mesh, g)
    depth = g + float(surface_error)
    d, arg = _nearest_deficit(P, c, r)
    before = max(0.0, float(d.max()) + depth)
    need = d + depth > 0
    r0 = r.copy()
    if need.any():
        want = np.linalg.norm(P[need] - c[arg[need]], axis=1) + depth + _ROUNDING
        np.maximum.at(r, arg[need], want)
    after = containment_bound(mesh, c, r, gap=g, surface_error=float(surface_error))
    if after > 0:  # cannot happen (radii only grew past every deficit): a bug
        raise RuntimeError(f"containment failed: bound {after:g} after growing the radii")
    solid = _solid_of(mesh)
    prot = _protrusion(solid, c, r)
    from dataclasses import replace

    if n_check == 0:  # a step of a fit: the certificate only
        return replace(fit, radii=r, one_sided_error=0.0, meets_tolerance=True,
                       protrusion=max(float(fit.protrusion), float(prot.max())),
                       max_protrusion=float(prot.max()), contained=True, contain_gap=g,
                       poke_out_bound=0.0, n_certify=int(len(P)), n_fresh=0,
                       grown=max(float((r - r0).max()), float(fit.grown)))
    x, _ = _sample(mesh, int(n_check), seed + 611953)  # fresh stream
    x = np.concatenate([x, np.asarray(mesh.vertices, np.float64)])
    err = float(one_sided_error(x, c, r).max())
    vol, se = _excess(solid, c, r, fit.n_volume, seed + 104729)
    return replace(fit, radii=r, one_sided_error=err, meets_tolerance=err <= fit.tolerance,
                   excess_volume=vol, excess_volume_stderr=se,
                   excess_fraction=vol / fit.mesh_volume if fit.mesh_volume > 0 else np.inf,
                   protrusion=max(float(fit.protrusion), float(prot.max())),
                   max_protrusion=float(prot.max()), contained=True, contain_gap=g,
                   poke_out_bound=0.0, n_certify=int(len(P)), n_fresh=int(len(x)),
                   grown=max(float((r - r0).max()), float(fit.grown)),
                   notes=list(fit.notes) + [f"contained: certified poke-out bound "
                                            f"{before:.4g} -> 0 on {len(P)} points (gap "
                                            f"{g:g}), radii grown by up to "
                                            f"{(r - r0).max():.4g}"])


#: the largest surface a tolerance-mode fit takes, in cells of tolerance^2 (a Panda link at
#: 1 cm is about 1e3; a 10 m box at 1 cm is 6e6)
MAX_SURFACE_CELLS = 1e6


# ----------------------------------------------------------------- public API
#: the automatic protrusion: ``PROTRUSION_MIN * tolerance`` for spheres of clearance up to
#: ``PROTRUSION_KNEE[0] * tolerance``, rising linearly to ``PROTRUSION_MAX * tolerance`` at
#: ``PROTRUSION_KNEE[1] * tolerance`` and beyond
PROTRUSION_MIN, PROTRUSION_MAX, PROTRUSION_KNEE = 0.5, 2.0, (3.0, 5.0)


def _reach(clearance: np.ndarray, *, tol: float, fixed: float | None,
           part: float | None) -> np.ndarray:
    """(M,) allowed protrusion of spheres of the given clearance (module docstring)."""
    if fixed is not None:
        return np.full(np.shape(clearance), fixed)
    a, b = PROTRUSION_KNEE
    x = np.asarray(clearance) if part is None else np.full(np.shape(clearance), part)
    t = np.clip((x / tol - a) / (b - a), 0.0, 1.0)
    return tol * (PROTRUSION_MIN + (PROTRUSION_MAX - PROTRUSION_MIN) * t)


def fit_spheres(mesh: trimesh.Trimesh, *, tolerance: float, max_spheres: int | None = None,
                n_surface: int | None = None, n_volume: int = 100_000, seed: int = 0,
                max_rounds: int = 6, protrusion: float | None = None,
                contain: float | None = None, contain_check: int = CONTAIN_CHECK) -> SphereFit:
    """Fit spheres to ``mesh``: centres inside its solid, radii = clearance + ``protrusion``
    (default ``tolerance / 2``), every surface point within ``tolerance`` of a sphere with as
    few spheres as the greedy cover finds; or, with ``max_spheres``, at most that many and
    the smallest error the cover finds (reported, ``meets_tolerance`` False when it exceeds
    ``tolerance``). See the module docstring for the method and :class:`SphereFitOptions`
    for the arguments; ``contain`` (a gap > 0): the containment mode (the cover holds the
    samples ``contain`` inside the spheres, then :func:`contain_fit` with
    ``n_check=contain_check``: 0 certifies without the fresh-sample check). Returns a
    :class:`SphereFit` (centres (k, 3), radii (k,), in the mesh's frame and unit)."""
    opt = SphereFitOptions(tolerance, max_spheres, n_surface, n_volume, seed, max_rounds,
                           protrusion, contain).validate()
    mesh = _check_mesh(mesh)
    tol = opt.tolerance
    part = None  # the automatic protrusion follows the part's largest clearance
    need = mesh.area / tol ** 2
    if opt.max_spheres is None and need > MAX_SURFACE_CELLS:
        raise ValueError(f"tolerance: a surface of {mesh.area:.4g} (unit^2) at tolerance {tol:g} "
                         f"is about {need:.3g} cells of tolerance^2 (at most "
                         f"{MAX_SURFACE_CELLS:.0e}): the fit would not end in reasonable time "
                         f"or memory; raise the tolerance, give max_spheres, or check the "
                         f"mesh's unit (a URDF in cm or mm needs a scale)")
    solid = _solid_of(mesh)
    watertight = bool(mesh.is_watertight)
    sparse = opt.max_spheres is None and opt.n_surface is None and \
        8.0 * mesh.area / tol ** 2 > _SPARSE_FROM
    n_s = opt.n_surface or (min(int(8.0 * mesh.area / tol ** 2), _SPARSE_SAMPLES) if sparse
                            else int(np.clip(8.0 * mesh.area / tol ** 2, *_FIT_SAMPLES)))
    pts, nrm = _sample(mesh, n_s, opt.seed)
    used = np.unique(mesh.faces)
    verts = np.asarray(mesh.vertices)[used]
    if len(verts) > n_s // 2:  # a fine mesh: its vertices add nothing over the samples
        verts = verts[np.random.default_rng(opt.seed + 1).permutation(len(verts))[:n_s // 2]]
    samples = np.concatenate([pts, verts])
    normals = np.concatenate([nrm, np.asarray(mesh.vertex_normals)[used][:len(verts)]
                              if len(verts) == len(used) else
                              _closest_normals(mesh, verts)])
    solid.simple = watertight and mesh.body_count == 1  # then no face is buried
    if sparse and watertight and mesh.is_winding_consistent:  # the inward side is known
        grid_sides: tuple = (1.0,) if solid.flipped else (-1.0,)
    else:
        grid_sides = (-1.0, 1.0)
    medial = functools.partial(_candidates, sides=grid_sides)
    on = _on_boundary(solid, samples, normals)
    samples, normals = samples[on], normals[on]
    rng = np.random.default_rng(opt.seed)
    grid = 0.2 * min(tol, opt.protrusion or tol)
    sub = rng.permutation(len(samples))[:max(_CANDIDATE_POINTS, len(samples) // 6)
                                        if sparse else _CANDIDATE_POINTS]
    cand_c, cand_d = medial(solid, samples[sub], normals[sub], samples, grid)
    if opt.max_spheres is not None and len(samples) > _BUDGET_SAMPLES:
        # the error search repeats the cover: on a subset of the samples (documented)
        keep = np.sort(rng.permutation(len(samples))[:_BUDGET_SAMPLES])
        samples, normals = samples[keep], normals[keep]
    if opt.protrusion is None and len(cand_d):
        part = float(cand_d.max())
    reach = functools.partial(_reach, tol=tol, fixed=opt.protrusion, part=part)
    notes: list[str] = []
    if solid.flipped:
        notes.append("the mesh's triangles face inwards: flipped")
    if len(cand_c) == 0:  # no solid (a sheet, a single open surface): spheres on the surface
        notes.append("the mesh encloses no solid (winding number <= 1/2 everywhere): "
                      "spheres centred on the surface")
        cand_c, cand_d = samples[sub].copy(), np.zeros(len(sub))
    eps_max = 2.0 * solid.extent + tol  # one sphere of any candidate then holds every sample
    # the cover's allowed error; containment: every sample at least the gap inside, and a
    # fresh sample outside any sphere is a miss (then fitted in the next round)
    eps0 = -opt.contain if opt.contain else _EPS_FIT * tol
    ok_at = 0.0 if opt.contain else tol
    refit_at = 0.0 if opt.contain else _REFIT * tol
    n_check = int(np.clip(20.0 * mesh.area / tol ** 2, _CHECK_SAMPLES, 2.5 * _CHECK_SAMPLES))
    check = _boundary_sample(mesh, solid, n_check, opt.seed + 7919)  # fresh stream
    rounds, best = 0, None
    while True:
        rounds += 1
        cap = _SPARSE_CANDIDATES if sparse else max(1, _MAX_PAIRS // len(samples))
        kind = _Holds if sparse else _Slack
        cand_c, cand_d = _thin(cand_c, cand_d, cap, grid)
        slack = kind(samples, cand_c, cand_d + reach(cand_d), eps0)
        lost = slack.unheld(eps0)
        if len(lost):  # samples no candidate holds: add their own medial candidates
            c2, d2 = medial(solid, samples[lost], normals[lost], samples, grid)
            cand_c, cand_d = np.concatenate([cand_c, c2]), np.concatenate([cand_d, d2])
            cand_c, cand_d = _thin(cand_c, cand_d, cap, grid)
            slack = kind(samples, cand_c, cand_d + reach(cand_d), eps0)
        if sparse:
            chosen, eps = slack.cover(), eps0
        else:
            chosen, eps = _cover(slack, opt.max_spheres, eps0, eps_max)
        c, r = cand_c[chosen], cand_d[chosen] + reach(cand_d[chosen])
        err_all = one_sided_error(check, c, r)
        err = float(err_all.max())
        key = (err > ok_at, err > refit_at, len(c) if err <= ok_at else err, err)
        if best is None or key < best[0]:
            best = (key, c, r, err, eps, float(reach(cand_d[chosen]).max()), eps > eps0)
        bad = err_all > refit_at
        if (opt.max_spheres is not None and eps > eps0) or not bad.any() \
                or rounds >= opt.max_rounds:  # (eps > eps0 with a budget: it binds)
            break
        if not opt.contain:
            eps0 *= 0.95  # the next round's cover a little tighter
        # fresh samples outside: fit them too, with their own candidates
        new_p = check[bad]
        new_n = _closest_normals(mesh, new_p)
        samples, normals = np.concatenate([samples, new_p]), np.concatenate([normals, new_n])
        c2, d2 = medial(solid, new_p, new_n, samples, grid)
        cand_c, cand_d = np.concatenate([cand_c, c2]), np.concatenate([cand_d, d2])
        check = _boundary_sample(mesh, solid, n_check, opt.seed + 7919 * (rounds + 1))
    _, c, r, err, eps, allowed, widened = best  # of the rounds: covered with margin, fewest
    if widened and opt.max_spheres is None:
        notes.append(f"some samples are held by no candidate sphere; cover error {eps:.3g}")
    prot = _protrusion(solid, c, r)
    vol, se = _excess(solid, c, r, opt.n_volume, opt.seed + 104729)
    mvol, how = _solid_volume(mesh, solid, opt.n_volume, opt.seed + 15485863)
    out = SphereFit(centres=c, radii=r, tolerance=tol, one_sided_error=err,
                     meets_tolerance=err <= tol, fit_error=float(eps), excess_volume=vol,
                     excess_volume_stderr=se, excess_fraction=vol / mvol if mvol > 0 else np.inf,
                     mesh_volume=mvol, n_volume=opt.n_volume, n_surface=n_s,
                     volume_method=f"winding number (solid volume: {how})", rounds=rounds,
                     notes=notes, protrusion=allowed,
                     max_protrusion=float(prot.max()) if len(prot) else 0.0,
                     watertight=watertight)
    return contain_fit(mesh, out, opt.contain, seed=opt.seed, n_check=contain_check) \
        if opt.contain else out


def _thin(c: np.ndarray, d: np.ndarray, cap: int, grid: float
          ) -> tuple[np.ndarray, np.ndarray]:
    """At most ``cap`` candidates (bounded memory): one per cell of a grid coarsened by
    1.25 until they fit (the deepest of each cell, so the spread and the big balls stay)."""
    order = np.argsort(-d, kind="stable")
    c, d = c[order], d[order]
    while len(c) > cap:
        grid *= 1.25
        _, keep = np.unique(np.floor(c / grid).astype(np.int64), axis=0, return_index=True)
        keep = np.sort(keep)
        c, d = c[keep], d[keep]
    return c, d


def _on_boundary(solid: _Solid, p: np.ndarray, n: np.ndarray) -> np.ndarray:
    """(n,) bool: surface points ``p`` (normals ``n``) on the solid's boundary, i.e. not
    buried inside it (a face of one body inside another: inside on both sides)."""
    if solid.simple:
        return np.ones(len(p), bool)
    h = 1e-3 * solid.extent
    both = (solid.signed_distance(p + h * n) < 0) & (solid.signed_distance(p - h * n) < 0)
    return ~both


def _boundary_sample(mesh: trimesh.Trimesh, solid: _Solid, n: int, seed: int) -> np.ndarray:
    """About ``n`` area-uniform samples of the solid's boundary (buried ones dropped)."""
    p, nrm = _sample(mesh, n, seed)
    return p[_on_boundary(solid, p, nrm)]


def _closest_normals(mesh: trimesh.Trimesh, p: np.ndarray) -> np.ndarray:
    """(n, 3) face normal of the triangle nearest each point."""
    _, _, tri = trimesh.proximity.closest_point(mesh, p)
    return np.asarray(mesh.face_normals[tri])


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


def file_problem(path: str | os.PathLike) -> str | None:
    """Why ``path`` cannot be read as a file (``"does not exist"``, ``"is a folder, not a
    file"``, ``"is a device, not a regular file"``, ...), or None for a regular file."""
    import stat

    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        return ("is a symbolic link to a file that does not exist"
                if os.path.islink(path) else "does not exist")
    except OSError as e:
        return f"cannot be read ({e.strerror or e})"
    if stat.S_ISREG(mode):
        return None
    if stat.S_ISDIR(mode):
        return "is a folder, not a file"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "is a device, not a regular file"
    return "is not a regular file (a pipe or socket)"


def load_mesh(path: str | Path, scale: Any = None) -> trimesh.Trimesh:
    """A mesh file (stl, obj, dae with pycollada, ...) as one Trimesh, scaled by ``scale``
    (a number or (3,) per axis); vertices at the same position are merged (whatever their
    normals or texture coordinates)."""
    p = Path(path)
    why = file_problem(p)
    if why is not None:
        raise ValueError(f"mesh: '{p}' {why}")
    try:  # unprocessed first: processing drops the faces of a NaN vertex without a word
        m = trimesh.load(p, force="mesh", process=False)
    except Exception as e:  # trimesh raises many types for unreadable files
        raise ValueError(f"mesh: cannot load '{p}': {e}") from e
    if not isinstance(m, trimesh.Trimesh) or len(m.faces) == 0:
        raise ValueError(f"mesh: '{p}' holds no triangles")
    bad = ~np.isfinite(np.asarray(m.vertices, np.float64)).all(axis=1)
    if bad.any():
        raise ValueError(f"mesh: '{p}' has {int(bad.sum())} vertices that are NaN or inf "
                         f"(the first: vertex {int(np.argmax(bad))})")
    m.process()  # what trimesh.load(p) does by default
    # one vertex per position (COLLADA files often give each triangle its own corners, for
    # their normals/UVs: a triangle soup, open and of one body per face, takes the slow
    # open-mesh clearance test; merged it is the closed solid it draws)
    m.merge_vertices(merge_tex=True, merge_norm=True)
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


def _geometry_mesh(kind: str | None, size: Any, mesh: Any, scale: Any) -> trimesh.Trimesh:
    """The mesh of one URDF-style geometry in its own frame (``sphere`` as an icosphere)."""
    if kind == "mesh":
        if mesh is None:
            raise ValueError("mesh: required for kind 'mesh'")
        return load_mesh(mesh, scale) if isinstance(mesh, (str, Path)) else \
            _scaled(_check_mesh(mesh), scale)
    if kind in PRIMITIVES:
        return primitive_mesh(kind, size)
    raise ValueError(f"kind: unknown geometry '{kind}', expected mesh or one of "
                     f"{sorted(PRIMITIVES)}")


def _exact_sphere(size: Any, tolerance: float, T: np.ndarray) -> SphereFit:
    r = float(np.asarray(size, np.float64).reshape(-1)[0])
    vol = 4.0 / 3.0 * np.pi * r ** 3
    fit = SphereFit(centres=np.zeros((1, 3)), radii=np.array([r]), tolerance=float(tolerance),
                    one_sided_error=0.0, meets_tolerance=True, fit_error=0.0,
                    excess_volume=0.0, excess_volume_stderr=0.0, excess_fraction=0.0,
                    mesh_volume=vol, n_volume=0, n_surface=0, volume_method="exact sphere",
                    notes=["exact: the geometry is a sphere"])
    return fit.transformed(T)


_FIT_KEYS = ("max_spheres", "n_surface", "n_volume", "seed", "max_rounds", "protrusion",
             "contain")


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
        primitive_mesh(kind, size)  # validates size
        SphereFitOptions(tolerance, **{k: v for k, v in options.items()
                                       if k in _FIT_KEYS}).validate()
        return _exact_sphere(size, tolerance, T)
    m = _geometry_mesh(kind, size, mesh, scale)
    return fit_spheres(m, tolerance=tolerance, **options).transformed(T)


def geometry_bounds(geometries: Any) -> np.ndarray:
    """(2, 3) [m] lower and upper corner of the box holding a link's collision
    ``geometries`` (as :func:`fit_link` takes them) in the link frame."""
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    for i, g in enumerate(geometries):
        get = (g.get if isinstance(g, dict) else lambda k, d=None, g=g: getattr(g, k, d))
        mesh = get("mesh") if get("mesh") is not None else (
            get("filename") or get("path") or get("mesh_path"))
        try:
            T = _origin(get("origin"))
            if get("kind") == "sphere":
                r = float(np.asarray(get("size"), np.float64).reshape(-1)[0])
                b = T[:3, 3] + np.array([[-r], [r]])
            else:
                b = _geometry_mesh(get("kind"), get("size"), mesh, get("scale")).bounds
                corners = np.array(np.meshgrid(*b.T, indexing="ij")).reshape(3, -1).T
                c = corners @ T[:3, :3].T + T[:3, 3]
                b = np.stack([c.min(0), c.max(0)])
        except (ValueError, TypeError) as e:
            raise type(e)(f"geometries[{i}]: {e}") from e
        lo, hi = np.minimum(lo, b[0]), np.maximum(hi, b[1])
    return np.stack([lo, hi])


def link_part(geometries: Any) -> tuple[trimesh.Trimesh | None, float]:
    """The union (one Trimesh, link frame) of a link's collision ``geometries`` (as
    :func:`fit_link` takes them) other than spheres, and how far [m] a tessellated curved
    primitive among them may lie inside its true surface (0 for meshes and boxes); None
    when the link has only spheres."""
    parts, sagitta = [], 0.0
    for i, g in enumerate(geometries):
        get = (g.get if isinstance(g, dict) else lambda k, d=None, g=g: getattr(g, k, d))
        if get("kind") == "sphere":
            continue
        mesh = get("mesh") if get("mesh") is not None else (
            get("filename") or get("path") or get("mesh_path"))
        try:
            m = _geometry_mesh(get("kind"), get("size"), mesh, get("scale")).copy()
            m.apply_transform(_origin(get("origin")))
        except (ValueError, TypeError) as e:
            raise type(e)(f"geometries[{i}]: {e}") from e
        parts.append(m)
        if get("kind") in ("cylinder", "capsule"):
            rad = float(np.asarray(get("size"), np.float64).reshape(-1)[0])
            sagitta = max(sagitta, rad * (1.0 - np.cos(np.pi / 64)))
    if not parts:
        return None, 0.0
    return (parts[0] if len(parts) == 1 else
            cast(trimesh.Trimesh, trimesh.util.concatenate(parts))), sagitta


def fit_link(geometries: Any, *, tolerance: float, fit: Any = None,
             **options: Any) -> SphereFit:
    """Spheres of all collision geometries of one link, in the link frame. Each geometry is
    a mapping or an object with ``kind``, ``size``, ``origin`` and, for meshes, ``mesh``
    (or ``filename``/``path``/``mesh_path``: the importer's ``CollisionGeometry``) and
    ``scale``. Spheres are taken as they are; every other
    geometry is posed in the link frame and the union fitted as **one** part
    (:func:`fit_spheres`: the solid of overlapping bodies by winding number, so
    ``max_spheres`` is the budget of the whole link). ``fit``: the function fitting that
    part (default :func:`fit_spheres`; :func:`jwarp.world.spherize.spherize` passes
    :func:`jwarp.importers.sphere_refine.fit_refined` for a robot's wrist, hand and base,
    with its ``max_protrusion``; other options are passed on). The
    report: total count, the fit's one-sided error, excess and protrusion (URDF spheres add
    none)."""
    exact, parts = [], []
    sagitta = 0.0  # how far a tessellated curved primitive lies inside its true surface
    for i, g in enumerate(geometries):
        get = (g.get if isinstance(g, dict) else lambda k, d=None, g=g: getattr(g, k, d))
        mesh = get("mesh") if get("mesh") is not None else (
            get("filename") or get("path") or get("mesh_path"))  # the importer's geometries
        try:
            kind = get("kind")
            T = _origin(get("origin"))
            if kind == "sphere":
                primitive_mesh(kind, get("size"))
                exact.append(_exact_sphere(get("size"), tolerance, T))
            else:
                m = _geometry_mesh(kind, get("size"), mesh, get("scale")).copy()
                m.apply_transform(T)
                parts.append(m)
                if kind in ("cylinder", "capsule"):
                    rad = float(np.asarray(get("size"), np.float64).reshape(-1)[0])
                    sagitta = max(sagitta, rad * (1.0 - np.cos(np.pi / 64)))
        except (ValueError, TypeError) as e:
            raise type(e)(f"geometries[{i}]: {e}") from e
    if not exact and not parts:
        raise ValueError("geometries: empty")
    SphereFitOptions(tolerance, **{k: v for k, v in options.items() if k in _FIT_KEYS}
                     ).validate()
    budget = options.get("max_spheres")
    fits = list(exact)
    if parts:
        if budget is not None:
            if budget <= len(exact):
                raise ValueError(f"max_spheres: {budget} is no more than the link's "
                                 f"{len(exact)} sphere geometries")
            options = {**options, "max_spheres": budget - len(exact)}
        whole = (parts[0] if len(parts) == 1 else
                 cast(trimesh.Trimesh, trimesh.util.concatenate(parts)))  # meshes in: a mesh
        step = {"contain_check": 0} if options.get("contain") else {}  # checked below
        got = (fit or fit_spheres)(whole, tolerance=tolerance, **options, **step)
        if options.get("contain"):  # contained, certified and checked on fresh samples
            got = contain_fit(whole, got, float(options["contain"]), surface_error=sagitta,
                              seed=int(options.get("seed", 0)))
        elif not options.get("contain"):  # the approximate fit: its certified poke-out
            from dataclasses import replace

            got = replace(got, poke_out_bound=containment_bound(
                whole, got.centres, got.radii, gap=CONTAIN_GAP, surface_error=sagitta))
        fits.append(got)
    return SphereFit(
        centres=np.concatenate([f.centres for f in fits]),
        radii=np.concatenate([f.radii for f in fits]), tolerance=float(tolerance),
        one_sided_error=max(f.one_sided_error for f in fits),
        meets_tolerance=all(f.meets_tolerance for f in fits),
        fit_error=max(f.fit_error for f in fits),
        excess_volume=sum(f.excess_volume for f in fits),
        excess_volume_stderr=float(np.sqrt(sum(f.excess_volume_stderr ** 2 for f in fits))),
        excess_fraction=(sum(f.excess_volume for f in fits)
                         / max(sum(f.mesh_volume for f in fits), 1e-300)),
        mesh_volume=sum(f.mesh_volume for f in fits), n_volume=max(f.n_volume for f in fits),
        n_surface=max(f.n_surface for f in fits),
        volume_method="; ".join(sorted({f.volume_method for f in fits})),
        rounds=max(f.rounds for f in fits), notes=[n for f in fits for n in f.notes],
        protrusion=max(f.protrusion for f in fits),
        max_protrusion=max(f.max_protrusion for f in fits),
        watertight=all(f.watertight for f in fits),
        contained=all(f.contained or f.volume_method == "exact sphere" for f in fits),
        contain_gap=max(f.contain_gap for f in fits),
        poke_out_bound=max((0.0 if f.volume_method == "exact sphere" else f.poke_out_bound)
                           for f in fits),
        n_certify=sum(f.n_certify for f in fits), grown=max(f.grown for f in fits))
