"""Continuous refinement of a sphere fit: the same number of spheres (or a few more),
centres moved and radii reset so that the spheres reach as little as possible past the
part's surface while every surface point stays within the one-sided error bound.

Method (lengths in the mesh's unit; ``e = error_fraction * tolerance``):

1. **The problem.** For a centre ``c`` inside the solid with clearance ``s(c)`` (its
   distance to the surface), a sphere of radius ``s(c) + p`` reaches at most ``p`` past
   the surface (its protrusion). A surface point ``x`` lies within ``e`` of that sphere
   when ``g(x, c) = |x - c| - s(c) <= p + e``. With ``k`` centres ``C``, the smallest
   common protrusion that covers every surface sample within ``e`` is
   ``P(C) = max_x min_i g(x, c_i) - e``.
2. **Centres**: ``P`` is minimised over the centres from the given fit's (a smooth
   max/min with temperatures of ``0.05 tolerance``, Adam steps, the exact gradient of the
   clearance from the closest surface point, Warp's mesh query; centres kept inside the
   solid).
3. **Radii**: each sample goes to the sphere of smallest ``g``; a sphere's protrusion is
   the largest ``g - e`` of its samples (it may be negative: a sphere smaller than its
   inscribed ball), then each sphere in turn is shrunk as far as every sample stays
   within ``e`` of some sphere. Spheres holding no sample are dropped.
4. **Check** on fresh surface samples (``n_check``, another random stream): samples
   further out than ``check_fraction * tolerance`` join the fit samples and step 3
   repeats (up to 4 times). The report (``one_sided_error``, ``max_protrusion``,
   excess) is recomputed with :mod:`jwarp.importers.spheres`.

:func:`fit_refined` runs :func:`~jwarp.importers.spheres.fit_spheres` at a ladder of
protrusions and refines each (several starting points); :func:`link_protrusions` gives
per-link starts and bounds that spend a sphere budget on the wrist and the hand, where
grasping brings an arm near objects, and save it on the fixed base.

Measured (Panda of example-robot-data, 1 cm, shared 2-core VM; grasp configurations of
``benchmarks/bench_grasp_endpoints.py``, 4 x 10 scenes per family, 1150 configurations
whose URDF meshes are free): the default fit, 61 spheres, largest protrusion 20 mm,
refuses 60 (5.2 %); :func:`refine_fit` of every link (300 iterations, same 61 spheres)
38 (3.3 %), fingers 4.1 mm; :func:`fit_refined` with :func:`link_protrusions` (seed 0),
68 spheres, 16 (1.4 %), one-sided error <= 9.5 mm on 50 000 fresh samples per link, hand
3.9 mm, fingers 0.9 mm, import 27 s instead of 6 s; the count and the figures vary with
the seed (seed 1: 71 spheres, 2.0 %).
"""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING, Any

import numpy as np
import trimesh
import warp as wp

from jwarp.importers.spheres import (
    SphereFit,
    contain_fit,
    excess_volume,
    fit_spheres,
    mesh_memo,
    one_sided_error,
    sphere_protrusion,
)
from jwarp.utils.checks import check_int
from jwarp.utils.warp_init import init_quietly

if TYPE_CHECKING:
    from jwarp.model import RobotModel

__all__ = ["refine_fit", "fit_refined", "coverage_protrusion", "link_protrusions", "fit_kernels",
           "MAX_SPHERES", "MAX_SPHERES_CONTAINED", "LADDER", "CONTAIN_PROTRUSIONS", "WRIST_JOINTS", "WRIST_PROTRUSION", "BASE_PROTRUSION",
           "HAND_PROTRUSION"]

#: :func:`link_protrusions`: links with at most this many moving joints between them and an
#: end effector form its wrist; their spheres may reach ``WRIST_PROTRUSION x tolerance``
#: past the surface, the fixed root link's ``BASE_PROTRUSION x tolerance``
WRIST_JOINTS, WRIST_PROTRUSION, BASE_PROTRUSION = 2, 0.75, 3.0
#: :func:`link_protrusions`: the bound on the hand's spheres (links rigid with an end
#: effector), x tolerance: the thin-part protrusion of the fit (spheres that hug a gripper)
HAND_PROTRUSION = 0.5

#: :func:`fit_refined` also refines fits at these fractions of the first fit's protrusion
#: (kept when they need no more spheres): the refinement finds a local optimum, so several
#: starting points give a lower protrusion more often
LADDER = (0.8, 0.6)

#: fits of more spheres than this are returned unrefined (the steps are dense in N x k)
MAX_SPHERES = 32
#: the same in the containment mode (``contain``: more spheres hold the same part)
MAX_SPHERES_CONTAINED = 64
_SAMPLES = (2000, 6000)  # clip of the automatic fit-sample count 8 area / tolerance^2


@wp.kernel(enable_backward=False)
def _closest_kernel(
    # Model:
    mesh: wp.uint64,
    # Data in:
    points: wp.array(dtype=wp.vec3),  # type: ignore[valid-type]
    max_dist: float,
    # Data out:
    sd: wp.array(dtype=float),  # type: ignore[valid-type]
    closest: wp.array(dtype=wp.vec3),  # type: ignore[valid-type]
):
    i = wp.tid()
    p = points[i]
    q = wp.mesh_query_point_sign_winding_number(mesh, p, max_dist)
    if q.result:  # type: ignore[attr-defined]
        c = wp.mesh_eval_position(mesh, q.face, q.u, q.v)  # type: ignore[attr-defined]
        sd[i] = q.sign * wp.length(p - c)  # type: ignore[attr-defined]
        closest[i] = c
    else:
        sd[i] = max_dist
        closest[i] = p


def fit_kernels() -> tuple:
    """The Warp kernels of the refined sphere fit (``jwarp warmup --families spherize``)."""
    return (_closest_kernel,)


class _MeshSolid:
    """The solid of a mesh for point queries (generalised winding number > 1/2 inside, as
    :func:`jwarp.importers.spheres.signed_distance`): signed distance and closest surface
    point. Coordinates relative to the bounding-box centre (float32 in Warp)."""

    def __init__(self, mesh: trimesh.Trimesh) -> None:
        wp.config.quiet = True  # type: ignore[attr-defined]
        init_quietly()
        V = np.asarray(mesh.vertices, np.float64)
        F = np.asarray(mesh.faces, np.int64)
        self.centre = 0.5 * (V.min(0) + V.max(0))
        a, b, c = (V[F[:, i]] - self.centre for i in range(3))
        if float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum()) < 0:
            F = F[:, ::-1]  # triangles facing inwards
        self.extent = float(np.linalg.norm(V.max(0) - V.min(0)))
        self._pts: wp.array = wp.array((V - self.centre).astype(np.float32), dtype=wp.vec3,
                                       device="cpu")
        self._idx: wp.array = wp.array(F.astype(np.int32).ravel(), dtype=wp.int32, device="cpu")
        self.mesh = wp.Mesh(points=self._pts, indices=self._idx, support_winding_number=True)

    def query(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(n,) signed distance (< 0 inside) and (n, 3) closest surface point of ``p``."""
        x = (np.asarray(p, np.float64).reshape(-1, 3) - self.centre).astype(np.float32)
        if len(x) == 0:
            return np.zeros(0), np.zeros((0, 3))
        maxd = 2.0 * self.extent + float(np.linalg.norm(x, axis=1).max()) + 1.0
        sd = wp.zeros(len(x), dtype=float, device="cpu")
        cl = wp.zeros(len(x), dtype=wp.vec3, device="cpu")
        wp.launch(_closest_kernel, len(x), inputs=[self.mesh.id, wp.array(
            x, dtype=wp.vec3, device="cpu"), maxd], outputs=[sd, cl], device="cpu")
        return sd.numpy().astype(np.float64), cl.numpy().astype(np.float64) + self.centre


def _check_mesh(mesh: Any) -> trimesh.Trimesh:
    if not isinstance(mesh, trimesh.Trimesh):
        raise TypeError(f"mesh: expected a trimesh.Trimesh, got {type(mesh).__name__}")
    if len(mesh.faces) == 0 or not np.all(np.isfinite(mesh.vertices)) or not mesh.area > 0:
        raise ValueError("mesh: empty, zero-area or not finite")
    return mesh


def _mesh_solid(mesh: trimesh.Trimesh) -> _MeshSolid:
    return mesh_memo(mesh, "refine solid", lambda: _MeshSolid(mesh))


def _boundary_sample(mesh: trimesh.Trimesh, solid: _MeshSolid, n: int, seed: int
                     ) -> tuple[np.ndarray, np.ndarray]:
    """About ``n`` area-uniform surface samples and their normals on the solid's boundary
    (a face of one body buried inside another, inside on both sides, dropped); the same
    (n, seed) of the same mesh object is sampled once."""
    p, nrm = mesh_memo(mesh, ("refine samples", n, seed),
                       lambda: _boundary_sample_new(mesh, solid, n, seed))
    return p.copy(), nrm.copy()


def _boundary_sample_new(mesh: trimesh.Trimesh, solid: _MeshSolid, n: int, seed: int
                         ) -> tuple[np.ndarray, np.ndarray]:
    p, face = trimesh.sample.sample_surface(mesh, n, seed=seed)
    p, nrm = np.asarray(p), np.asarray(mesh.face_normals[face])
    if mesh.is_watertight and mesh.body_count == 1:
        return p, nrm
    h = 1e-3 * solid.extent
    both = (solid.query(p + h * nrm)[0] < 0) & (solid.query(p - h * nrm)[0] < 0)
    return p[~both], nrm[~both]


def _clearance_grad(solid: _MeshSolid, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(k,) clearance ``-signed_distance`` of centres ``c`` (k, 3) and (k, 3) its gradient
    (the unit vector from the closest surface point, sign-corrected)."""
    sd, cl = solid.query(c)
    s = -sd
    d = np.asarray(c, np.float64) - cl
    n = np.linalg.norm(d, axis=1, keepdims=True)
    u = np.where(n > 0, d / np.maximum(n, 1e-300), 0.0)
    return s, np.where(s[:, None] >= 0, u, -u)


def _g(x: np.ndarray, c: np.ndarray, s: np.ndarray) -> np.ndarray:
    """(N, k) ``|x_j - c_i| - s_i``."""
    return np.linalg.norm(x[:, None, :] - c[None], axis=-1) - s[None]


def _optimise(solid: _MeshSolid, x: np.ndarray, c: np.ndarray, tol: float, iters: int,
              lr: float) -> np.ndarray:
    """Centres (k, 3) minimising a smooth ``max_j min_i g(x_j, c_i)`` (Adam)."""
    c = c.copy()
    t1, t2 = 0.05 * tol, 0.05 * tol
    m, v = np.zeros_like(c), np.zeros_like(c)
    best, best_c = np.inf, c.copy()
    b1, b2 = 0.9, 0.999
    for it in range(1, iters + 1):
        s, u = _clearance_grad(solid, c)
        diff = x[:, None, :] - c[None]  # (N, k, 3)
        dist = np.linalg.norm(diff, axis=-1)
        g = dist - s[None]
        hard = float(g.min(axis=1).max())
        if hard < best and np.all(s > 0):
            best, best_c = hard, c.copy()
        a = -g / t1
        amax = a.max(axis=1, keepdims=True)
        w = np.exp(a - amax)
        ws = w.sum(axis=1, keepdims=True)
        mj = -t1 * (amax[:, 0] + np.log(ws[:, 0]))  # softmin over spheres
        w /= ws
        b = mj / t2
        b -= b.max()
        vj = np.exp(b)
        vj /= vj.sum()  # softmax weights over samples
        coef = vj[:, None] * w  # (N, k)
        dg_dc = -diff / np.maximum(dist, 1e-12)[..., None] - u[None]  # d g / d c_i
        grad = np.einsum("jk,jkd->kd", coef, dg_dc)
        grad += 10.0 * np.where(s < 0.1 * tol, 1.0, 0.0)[:, None] * -u  # stay inside
        m = b1 * m + (1 - b1) * grad
        v = b2 * v + (1 - b2) * grad * grad
        step = lr * (0.1 + 0.9 * (1 - it / iters))
        c -= step * (m / (1 - b1 ** it)) / (np.sqrt(v / (1 - b2 ** it)) + 1e-12)
    return best_c


def _radii(x: np.ndarray, c: np.ndarray, s: np.ndarray, e: float) -> np.ndarray:
    """(k,) radii: per-sphere protrusion from the assignment to the smallest ``g``, then
    each sphere shrunk while every sample stays within ``e`` (NaN: sphere not needed)."""
    g = _g(x, c, s)
    own = g.argmin(axis=1)
    k = len(c)
    p = np.full(k, -np.inf)
    np.maximum.at(p, own, g[np.arange(len(x)), own] - e)
    for i in np.argsort(-p):  # the largest first
        if not np.isfinite(p[i]):
            continue
        others = np.delete(np.arange(k), i)
        held_else = (g[:, others] - e <= p[None, others]).any(axis=1) if len(others) \
            else np.zeros(len(x), bool)
        need = ~held_else
        p[i] = float((g[need, i] - e).max()) if need.any() else -np.inf
    r = s + p
    r[~np.isfinite(p) | (r <= 0)] = np.nan
    return r


def coverage_protrusion(mesh: trimesh.Trimesh, centres: np.ndarray, tolerance: float,
                        *, n: int = 20_000, seed: int = 0) -> float:
    """The smallest common protrusion [mesh unit] with which spheres at ``centres`` (k, 3)
    (radius = clearance + protrusion) hold ``n`` surface samples within ``tolerance``:
    ``max_x min_i (|x - c_i| - clearance(c_i)) - tolerance``."""
    solid = _MeshSolid(_check_mesh(mesh))
    x, _ = _boundary_sample(mesh, solid, n, seed)
    s, _ = _clearance_grad(solid, np.asarray(centres, np.float64).reshape(-1, 3))
    return float(_g(x, np.asarray(centres, np.float64).reshape(-1, 3), s).min(1).max()
                 - tolerance)


def refine_fit(mesh: trimesh.Trimesh, fit: SphereFit, *, error_fraction: float = 0.88,
               check_fraction: float = 0.95, n_surface: int | None = None,
               n_check: int = 50_000, iters: int = 150, seed: int = 0,
               n_volume: int = 100_000, contain: float | None = None) -> SphereFit:
    """``fit`` (a :func:`~jwarp.importers.spheres.fit_spheres` result for ``mesh``, same
    frame) with its centres moved and radii reset so that the spheres reach as little as
    possible past the surface while the one-sided error stays within ``check_fraction x
    tolerance`` on ``n_check`` fresh samples (module docstring).
    ``contain`` (a gap > 0 [mesh unit]): the containment mode, every sample held at least
    ``contain`` inside a sphere (``error_fraction`` and ``check_fraction`` unused), a fresh
    sample outside every sphere a miss, and the result contained by
    :func:`~jwarp.importers.spheres.contain_fit` (``fit`` is taken contained too).
    Returns a new :class:`SphereFit`
    (the input's when the refinement does not lower the largest protrusion)."""
    mesh = _check_mesh(mesh)
    if not isinstance(fit, SphereFit):
        raise TypeError(f"fit: expected a SphereFit, got {type(fit).__name__}")
    if not 0 < error_fraction <= check_fraction <= 1:
        raise ValueError(f"error_fraction, check_fraction: expected 0 < error_fraction <= "
                         f"check_fraction <= 1, got {error_fraction}, {check_fraction}")
    for name, v, lo in (("iters", iters, 1), ("n_check", n_check, 100), ("seed", seed, 0),
                        ("n_volume", n_volume, 100)):
        check_int(v, name, lo)
    check_int(n_surface, "n_surface", 10, none=True)
    tol = float(fit.tolerance)
    if fit.k == 0 or fit.k > (MAX_SPHERES_CONTAINED if contain is not None else MAX_SPHERES):
        return fit  # nothing to move, or too many spheres for the dense (N, k) steps
    n_surface = n_surface or int(np.clip(8.0 * mesh.area / tol ** 2, *_SAMPLES))
    solid = _mesh_solid(mesh)
    x, _ = _boundary_sample(mesh, solid, n_surface, seed + 31)
    c0 = np.asarray(fit.centres, np.float64)
    s0, _ = _clearance_grad(solid, c0)
    c0 = c0[s0 > 0]  # the fit centres its spheres inside (guard)
    if len(c0) == 0:
        return fit
    if contain is not None:
        if isinstance(contain, bool) or not np.isfinite(contain) or contain <= 0:
            raise ValueError(f"contain: expected None or a gap > 0, got {contain!r}")
        fit = contain_fit(mesh, fit, float(contain), seed=seed, n_check=0)
    c = _optimise(solid, x, c0, tol, iters, 0.05 * tol)
    e = -float(contain) if contain is not None else error_fraction * tol
    miss = 0.0 if contain is not None else check_fraction * tol
    s, _ = _clearance_grad(solid, c)
    for rnd in range(5):
        r = _radii(x, c, s, e)
        keep = np.isfinite(r)
        cc, rr = c[keep], r[keep]
        if len(rr) == 0:  # no sphere holds any sample (a part below the tolerance)
            return fit
        check, _ = _boundary_sample(mesh, solid, n_check, seed + 7919 * (rnd + 3))
        err_all = one_sided_error(check, cc, rr)
        bad = err_all > miss
        if not bad.any():
            break
        x = np.concatenate([x, check[bad]])
        if contain is None:
            e *= 0.97
    err = float(err_all.max())
    if contain is not None:  # grown to containment first: then compared with the fit
        got = contain_fit(mesh, replace(fit, centres=cc, radii=rr, contained=False, grown=0.0),
                          float(contain), seed=seed, n_check=0)
        if got.max_protrusion >= fit.max_protrusion:
            return fit
        return replace(got, notes=list(fit.notes) + [
            f"refined: largest protrusion {fit.max_protrusion:.4g} -> "
            f"{got.max_protrusion:.4g}"])
    prot = sphere_protrusion(mesh, cc, rr)
    if float(prot.max()) >= fit.max_protrusion or (err > check_fraction * tol
                                                    and err > fit.one_sided_error):
        return fit  # no better than the fit (a binding budget, a hard part)
    vol, se, _ = excess_volume(mesh, cc, rr, n=n_volume, seed=seed + 104729)
    out = replace(fit, centres=cc, radii=rr, one_sided_error=err, meets_tolerance=err <= tol,
                  fit_error=e, excess_volume=vol, excess_volume_stderr=se,
                  excess_fraction=vol / fit.mesh_volume if fit.mesh_volume > 0 else np.inf,
                  protrusion=float(prot.max()), max_protrusion=float(prot.max()),
                  notes=list(fit.notes) + [f"refined: largest protrusion "
                                           f"{fit.max_protrusion:.4g} -> {prot.max():.4g}"])
    return out


def fit_refined(mesh: trimesh.Trimesh, *, tolerance: float, protrusion: float | None = None,
                max_protrusion: float | None = None, ladder: tuple = LADDER,
                refine: dict | None = None, **fit_options: Any) -> SphereFit:
    """:func:`~jwarp.importers.spheres.fit_spheres` of ``mesh`` followed by
    :func:`refine_fit`, from several starting points: the fit with ``protrusion`` (None:
    automatic) and fits at ``ladder`` fractions of its protrusion (only with
    ``max_protrusion`` or when the first fit's protrusion is below ``tolerance``, a thin
    part: for a thick one they need more spheres, and time; with ``max_protrusion`` the
    ladder stops at the first start whose refined fit is within the bound). The refinement finds a local
    optimum, so several starts find lower protrusions more often.

    Which refined fit is returned: with ``max_protrusion`` None, the one of the lowest
    largest protrusion among those of no more spheres than the first fit; with
    ``max_protrusion`` [m], the one of the fewest spheres among those reaching at most that
    far past the surface (then the lowest protrusion; none: the lowest protrusion, with a
    note). Every candidate's one-sided error is within ``check_fraction x tolerance`` on
    fresh samples (else the plain fit is the candidate). ``refine``: keyword arguments of
    :func:`refine_fit`; ``fit_options``: of ``fit_spheres`` (``max_spheres``, ``seed``,
    ...)."""
    ropt = dict(refine or {})
    if fit_options.get("contain") is not None:  # the containment mode: refined too
        ropt.setdefault("contain", fit_options["contain"])
    ok_err = 0.0 if fit_options.get("contain") is not None else tolerance
    if max_protrusion is not None and (isinstance(max_protrusion, bool) or not isinstance(
            max_protrusion, (int, float, np.floating)) or not max_protrusion > 0):
        raise ValueError(f"max_protrusion: expected None or a distance > 0, got "
                         f"{max_protrusion!r}")
    for f in ladder:
        if isinstance(f, bool) or not isinstance(f, (int, float, np.floating)) \
                or not 0 < float(f) <= 2 or float(f) == 1:
            raise ValueError(f"ladder: expected factors in (0, 2] other than 1, got {f!r}")
    base = fit_spheres(mesh, tolerance=tolerance, protrusion=protrusion, **fit_options)
    if base.k > (MAX_SPHERES if fit_options.get("contain") is None else MAX_SPHERES_CONTAINED):
        return base  # too many spheres to refine (time): the plain fit
    cands = [refine_fit(mesh, base, **ropt)]
    if max_protrusion is None and base.protrusion >= tolerance:
        ladder = ()  # a thick part: lower protrusions need more spheres (and time)
    for f in ladder:
        if max_protrusion is not None and cands[-1].max_protrusion <= max_protrusion:
            break  # within the bound: lower starts only add spheres (and time)
        fit = fit_spheres(mesh, tolerance=tolerance, protrusion=float(f) * base.protrusion,
                          **fit_options)
        if max_protrusion is None and fit.k > base.k:
            continue  # more spheres than the first fit: not a candidate
        got = refine_fit(mesh, fit, **ropt)
        if got.one_sided_error <= ok_err:
            cands.append(got)
    if max_protrusion is None:
        ok = [c for c in cands if c.k <= base.k]
        return min(ok, key=lambda c: (c.max_protrusion, c.k))
    ok = [c for c in cands if c.max_protrusion <= max_protrusion]
    if ok:
        return min(ok, key=lambda c: (c.k, c.max_protrusion))
    best = min(cands, key=lambda c: (c.max_protrusion, c.k))
    best.notes.append(f"no refined fit reaches at most {max_protrusion:.4g} past the surface "
                      f"(lowest {best.max_protrusion:.4g})")
    return best


def link_protrusions(model: RobotModel, tolerance: float, *, wrist_joints: int = WRIST_JOINTS,
                     wrist: float = WRIST_PROTRUSION, base: float = BASE_PROTRUSION,
                     hand: float = HAND_PROTRUSION, hand_start: float | None = None,
                     gripper: bool = False) -> dict[str, dict[str, float]]:
    """Per-link options of :func:`fit_refined` that spend a sphere budget where grasping
    brings a robot near objects: ``{link: {"protrusion": start [m], "max_protrusion": bound
    [m]}}`` for

    * the **wrist**: links on the path from the root to an end effector of ``model`` (a
      :class:`~jwarp.model.RobotModel`) with at most ``wrist_joints`` moving joints between
      them and it: start and bound ``wrist x tolerance`` (a Panda's link5, link6, link7);
    * the **hand**: the links rigidly attached to the end effector (no moving joint
      between): start ``wrist x tolerance``, bound ``hand x tolerance`` (a Panda's link8,
      hand and TCP frame: the gripper's spheres hug it);
    * the **base**: the root link when it is fixed, start ``base x tolerance``, no bound
      (it moves with nothing).

    ``hand_start``: the hand's start factor (None: ``wrist``); ``gripper``: the links
    below the hand that are off the path to the end effector (a gripper's fingers) get
    the hand's settings too (the containment mode, :data:`CONTAIN_PROTRUSIONS`).

    Other links are not listed (the automatic protrusion). Measured on the Panda at 1 cm
    (module docstring): 68 spheres, one-sided error <= 1 cm, 1.4 % of mesh-free grasp
    configurations refused instead of 5.2 %."""
    tol = float(tolerance)
    if not np.isfinite(tol) or tol <= 0:
        raise ValueError(f"tolerance: expected a finite distance > 0 [m], got {tolerance!r}")
    check_int(wrist_joints, "wrist_joints", 0)
    for name, v in (("wrist", wrist), ("base", base), ("hand", hand)):
        if isinstance(v, bool) or not isinstance(v, (int, float, np.floating)) \
                or not np.isfinite(v) or v <= 0:
            raise ValueError(f"{name}: expected a finite factor > 0, got {v!r}")
    frames = model.frames
    out: dict[str, dict[str, float]] = {}
    h0 = wrist if hand_start is None else float(hand_start)
    hands: set[int] = set()
    if frames and frames[0].parent is None and frames[0].kind == "static":
        out[frames[0].name] = {"protrusion": base * tol}
    for ee in model.end_effectors:
        path = model.ancestors(ee)
        moving = 0
        for i in reversed(path):
            if moving > wrist_joints:
                break
            if frames[i].kind != "static":
                moving += 1
            if i != path[0]:
                cap = (hand if moving == 0 else wrist) * tol
                out[frames[i].name] = {"protrusion": (h0 if moving == 0 else wrist) * tol,
                                       "max_protrusion": cap}
                if moving == 0:
                    hands.add(i)
    if gripper and hands:
        for i, f in enumerate(frames):
            if f.name in out:
                continue
            if any(a in hands for a in model.ancestors(i)):
                out[f.name] = {"protrusion": h0 * tol, "max_protrusion": hand * tol}
    return out


#: :func:`link_protrusions` settings of the containment mode (``SpherizeOptions.contain``):
#: containing spheres that reach only ``0.5 tolerance`` past a wrist need three times the
#: spheres (Panda link5 at 1 cm: 113 spheres at 5 mm, 33 at 10 mm, 18 at 15 mm); the wrist
#: gets ``1.5 tolerance``, the hand and the gripper's fingers ``1.0 tolerance``. The Panda:
#: 125 spheres (1.25 / 0.75 gave 191). Grasps the spheres touch and the meshes clear are
#: not refused for it: the mesh certificate proves them (jwarp.world.mesh_check); fewer
#: spheres plan faster (issue 42: 1.35x the one-sided fit's time per problem on one CPU
#: core against 1.62x with 191, 1.21x against 1.35x on an H200; benchmarks/README.md)
CONTAIN_PROTRUSIONS: dict[str, Any] = {"wrist": 1.5, "hand": 1.0, "hand_start": 1.0,
                                       "gripper": True}
