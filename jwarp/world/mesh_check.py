"""The mesh certificate: a robot's own collision geometry, not only its spheres, proven free.

A robot imported from a URDF records the convex pieces of its collision geometry
(``RobotModel.collision_pieces``: a mesh's convex hull, a box's corners, a sphere or a
capsule as a point or a segment with a radius, a cylinder as a circumscribed 32-gon
prism; :mod:`jwarp.model.collision_pieces`). :class:`MeshCheck` proves configurations
and straight joint-space segments free for those pieces against the exact objects of a
world (their convex pieces: a box's corners, a cylinder's or cone's circumscribed
polygons, a mesh's convex hull; planes as half-spaces) and against each other on every
frame pair the robot checks, by GJK lower bounds (:mod:`jwarp.kernels.convex`). Every
bound is a separating-axis bound, so it is never above the true distance: what the
certificate calls free is free for the URDF geometry.

Continuous segments: a piece moves at most ``T_k = sum_i reach_k,i |dtheta_i|`` along a
segment (``reach``: :func:`jwarp.world.reach.point_reach` of its enclosing sphere, the
bound the sphere check uses), so a segment [a, b] whose bounds ``d_a``, ``d_b`` satisfy
``d_a + d_b - 2 margin > T_k`` for every piece (and the pair travel for every self pair)
keeps the clearance all along; other segments are halved until they pass, a
configuration fails, or the budget runs out (not certified).

The spheres stay the planner's guide (and its first check): the certificate is asked only
where the spheres cannot prove a configuration or a path (e.g. a grasp pose whose
contained spheres reach past the fingers into the object the fingers clear by 3 mm).
Pieces cover what the spheres were fitted to; spheres added later (an attached object)
are certified as spheres (pieces of one vertex). A model whose fitted spheres were
edited (``CollisionPieces.extra_spheres`` is None), a world with a voxel grid, or an
elastic model get no certificate (:func:`mesh_check` returns None): the spheres decide.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import warp as wp

from jwarp.core.arrays import init_warp, real_array, resolve_device
from jwarp.core.caches import IdentityCache
from jwarp.core.types import ArrayLike, DeviceLike
from jwarp.kernels import convex as ck
from jwarp.model import RobotModel

if TYPE_CHECKING:
    from jwarp.world.sdf import World

__all__ = ["MeshCheck", "MeshCheckStats", "cached_mesh_check", "mesh_check", "sphere_reach_past",
           "world_pieces"]

#: sides of the circumscribed polygons of world cylinders and cones
POLY_SIDES = 32
#: [m] rounding allowance subtracted from every float64 bound
SLACK = 1e-9
#: [m] GJK stops when its bound is this close to its distance estimate
GJK_TOL = 1e-7
#: [m] what :meth:`MeshCheck.paths_free` asks a point to clear beyond what its intervals'
#: proofs need (the bounds stop there: a cap, :meth:`MeshCheck.lower_bounds`)
CAP_PAD = 1e-3
#: most halvings of a segment (2^MAX_DEPTH sub-intervals) before it is "not certified"
MAX_DEPTH = 14
#: most configurations one :meth:`MeshCheck.paths_free` call evaluates per path segment
#: on average before the rest is "not certified"
EVALS_PER_SEGMENT = 64


@dataclass
class MeshCheckStats:
    """Work of a :class:`MeshCheck` (cumulative): calls, configurations evaluated, seconds."""

    calls: int = 0
    configurations: int = 0
    seconds: float = 0.0


def _poly(r: float, n: int = POLY_SIDES) -> np.ndarray:
    """(n, 2) vertices of a regular n-gon circumscribing the circle of radius r."""
    a = 2 * np.pi * np.arange(n) / n
    R = r / np.cos(np.pi / n)
    return np.stack([R * np.cos(a), R * np.sin(a)], axis=1)


#: the corners of a box, in the order x outer, z inner (signs of its half extents)
_BOX_SIGNS = np.array([[x, y, z] for x in (-1.0, 1.0) for y in (-1.0, 1.0)
                       for z in (-1.0, 1.0)])


@dataclass
class PieceTable:
    """The convex pieces of a :class:`jwarp.world.shapes.ShapeSet` in world coordinates,
    one per object, as flat arrays (``O`` objects, ``V`` vertices in all):

    - ``kind`` (O,) int32: :data:`jwarp.kernels.convex.HULL` or ``HALFSPACE``;
    - ``vertices`` (V, 3) [m]: object ``o``'s are rows ``vstart[o]:vstart[o + 1]`` (a
      half-space: ``[normal, (offset, 0, 0)]``);
    - ``vstart`` (O + 1,) int: the first row of each object's vertices;
    - ``radius`` (O,) [m]: the hull grown by it (a sphere's point, a capsule's segment);
    - ``group`` (O,) int: each object's world in a batch;
    - ``rot`` (O, 3, 3): each object's orientation (the broad phase's box axes)."""

    kind: np.ndarray
    vertices: np.ndarray
    vstart: np.ndarray
    radius: np.ndarray
    group: np.ndarray
    rot: np.ndarray


def piece_table(shapes: Any) -> PieceTable:
    """The :class:`PieceTable` of ``shapes``, built per kind with array operations (a
    batch of 700 worlds holds about 9000 objects: one Python step per object was a
    second of the batch's plan)."""
    O = len(shapes)
    T = np.asarray(shapes.poses(), np.float64).reshape(O, 4, 4)
    R, t = T[:, :3, :3], T[:, :3, 3]
    specs = shapes.specs()
    kinds = np.array([k for k, _, _ in specs], dtype=object)
    group = shapes.groups() if O else np.zeros(0, np.int64)
    kind = np.full(O, int(ck.HULL), np.int32)
    radius = np.zeros(O)
    local: list = [None] * O  # (n_o, 3) local vertices of each hull
    world_v: list = [None] * O

    def dims_of(idx: np.ndarray, n: int) -> np.ndarray:
        return np.array([np.asarray(specs[i][1], np.float64).reshape(-1)[:n] for i in idx]
                        ).reshape(len(idx), n)

    idx = np.nonzero(kinds == "plane")[0]
    if len(idx):
        kind[idx] = int(ck.HALFSPACE)
        n = R[idx, :, 2]
        off = np.einsum("ki,ki->k", n, t[idx])
        for j, i in enumerate(idx):
            world_v[i] = np.array([n[j], [off[j], 0.0, 0.0]])
    idx = np.nonzero(kinds == "sphere")[0]
    if len(idx):
        radius[idx] = dims_of(idx, 1)[:, 0]
        for i in idx:
            local[i] = np.zeros((1, 3))
    idx = np.nonzero(kinds == "box")[0]
    if len(idx):
        h = dims_of(idx, 3) / 2
        corners = _BOX_SIGNS[None] * h[:, None, :]
        for j, i in enumerate(idx):
            local[i] = corners[j]
    idx = np.nonzero(kinds == "capsule")[0]
    if len(idx):
        d = dims_of(idx, 2)
        radius[idx] = d[:, 1]
        for j, i in enumerate(idx):
            local[i] = np.array([[0, 0, -d[j, 0] / 2], [0, 0, d[j, 0] / 2]])
    a = 2 * np.pi * np.arange(POLY_SIDES) / POLY_SIDES
    for name in ("cylinder", "cone"):
        idx = np.nonzero(kinds == name)[0]
        if not len(idx):
            continue
        d = dims_of(idx, 2)
        Rr = d[:, 1] / np.cos(np.pi / POLY_SIDES)  # circumscribing the circle (_poly)
        px, py = Rr[:, None] * np.cos(a), Rr[:, None] * np.sin(a)
        for j, i in enumerate(idx):
            p = np.stack([px[j], py[j]], axis=1)
            lo = np.c_[p, np.full(POLY_SIDES, -d[j, 0] / 2)]
            hi = (np.c_[p, np.full(POLY_SIDES, d[j, 0] / 2)] if name == "cylinder"
                  else np.array([[0.0, 0.0, d[j, 0] / 2]]))
            local[i] = np.concatenate([lo, hi])
    for i in np.nonzero(kinds == "mesh")[0]:
        local[i] = _hull_vertices(specs[i][2])
    for k in range(O):
        if world_v[k] is None and local[k] is None:  # pragma: no cover - kinds validated
            raise ValueError(f"world: object {k} of unknown kind '{kinds[k]}'")
    # world coordinates, per object ``local @ R.T + t``: stacked by vertex count, so
    # each object's product is the same BLAS call as on its own (the same bits)
    for rows in _same_count(local, np.nonzero(kind == int(ck.HULL))[0]):
        Lk = np.stack([local[i] for i in rows])
        Wk = np.matmul(Lk, R[rows].transpose(0, 2, 1)) + t[rows][:, None, :]
        for j, i in enumerate(rows):
            world_v[i] = Wk[j]
    counts = np.array([len(world_v[i]) for i in range(O)], np.int64)
    vstart = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    V = np.concatenate(world_v) if O else np.zeros((0, 3))
    return PieceTable(kind, V, vstart, radius, np.asarray(group, np.int64), R.copy())


def _same_count(arrays: list, rows: np.ndarray) -> list[np.ndarray]:
    """``rows`` split into groups whose ``arrays[i]`` have the same length."""
    if not len(rows):
        return []
    n = np.array([len(arrays[i]) for i in rows])
    return [rows[n == k] for k in np.unique(n)]


def world_pieces(shapes: Any) -> list[tuple[int, np.ndarray, float, int]]:
    """The convex pieces of a :class:`jwarp.world.shapes.ShapeSet` in world coordinates,
    one per object: ``(kind, vertices (V, 3) [m], radius [m], group)`` with kind
    :data:`jwarp.kernels.convex.HULL` (the set: the vertices' hull grown by radius), or
    :data:`~jwarp.kernels.convex.HALFSPACE` (a plane: vertices = [normal, (offset, 0, 0)]).
    Every piece contains its object (a mesh: its convex hull, which for a non-convex mesh
    is more than the object: conservative). The rows of :func:`piece_table`."""
    tab = piece_table(shapes)
    return [(int(tab.kind[i]), tab.vertices[tab.vstart[i]:tab.vstart[i + 1]],
             float(tab.radius[i]), int(tab.group[i])) for i in range(len(tab.kind))]


def _hull_vertices(src: Any) -> np.ndarray:
    """(V, 3) the convex hull's vertices of a mesh object given as ``src`` (a trimesh or
    ``(vertices, faces)``; local coordinates)."""
    import trimesh

    v = np.asarray(src.vertices if hasattr(src, "vertices") else src[0], np.float64)
    try:
        hull = trimesh.convex.convex_hull(v)
        return np.asarray(hull.vertices, np.float64)
    except Exception:  # noqa: BLE001 - a flat or degenerate mesh: its vertices span the hull
        return v


class MeshCheck:
    """The mesh certificate of one robot in one world (module docstring), kept on a
    device: the piece tables, the world's pieces (rebuilt when objects move), the travel
    tables. Float64 throughout (a certificate, not a cost).

    Args:
        robot: a RobotModel with ``collision_pieces``.
        world: a :class:`jwarp.world.sdf.World` of exact objects (no voxel grid), or None
            (self pairs only).
        device: Warp device (None: Warp's default).
    """

    def __init__(self, robot: RobotModel, world: World | None, device: DeviceLike = None) -> None:
        init_warp()
        self.device = resolve_device(device)
        self.robot = robot
        self.world = world
        cp = robot.collision_pieces
        if cp is None:
            raise ValueError(f"robot: '{robot.name}' has no collision_pieces (import it from "
                             f"its URDF: docs/spheres.md, 'The mesh certificate')")
        extra = cp.extra_spheres(robot)
        if extra is None:
            raise ValueError(f"robot: the spheres of '{robot.name}' were edited after its "
                             f"collision pieces were made; the pieces cannot stand for them")
        rp = _robot_part(robot, extra, self.device)
        self.sources, self.n_pieces, self.frame = rp.sources, rp.n_pieces, rp.frame
        self._tab, self.reach, self._coupling = rp.tab, rp.reach, rp.coupling
        self.pair_a, self.pair_b, self.pair_weight, self._ptab = (rp.pair_a, rp.pair_b,
                                                                  rp.pair_weight, rp.ptab)
        self._world_key: Any = None
        self._wtab: tuple = ()
        self.stats = MeshCheckStats()
        self._lock = threading.Lock()

    # ------------------------------------------------------------------ tables
    def _world_tables(self) -> tuple:
        """The world's piece tables on the device (rebuilt when objects move or change)."""
        sh = None if self.world is None else self.world.shapes
        key = None if sh is None else (id(sh), sh.structure_version, sh.pose_version)
        if key == self._world_key and self._wtab:
            return self._wtab
        O = len(sh) if sh is not None else 0
        centre = np.zeros((O, 3))
        bound = np.zeros(O)
        rot = np.tile(np.eye(3), (O, 1, 1))
        half = np.zeros((O, 3))
        if O:
            tab = piece_table(sh)
            kind, V, vstart, radius, grp = (tab.kind, tab.vertices, tab.vstart, tab.radius,
                                            tab.group)
            hull = kind == int(ck.HULL)
            plane = np.nonzero(~hull)[0]
            centre[plane] = V[vstart[plane]]
            bound[plane] = V[vstart[plane] + 1, 0]
            h = np.nonzero(hull)[0]
            # the broad phase's box: the vertices' extent along the object's axes (per
            # object as ``v @ R``, stacked by vertex count: the same bits)
            verts = [V[vstart[i]:vstart[i + 1]] for i in range(O)]
            for rows in _same_count(verts, h):
                Vk, Rk = np.stack([verts[i] for i in rows]), tab.rot[rows]
                lv = np.matmul(Vk, Rk)
                lo, hi = lv.min(1), lv.max(1)
                c = np.matmul(Rk, ((lo + hi) / 2)[:, :, None])[:, :, 0]
                rot[rows], half[rows], centre[rows] = Rk, (hi - lo) / 2, c
                bound[rows] = np.linalg.norm(Vk - c[:, None, :], axis=2).max(1) + radius[rows]
        else:
            kind, V, vstart = np.zeros(0, np.int32), np.zeros((1, 3)), np.zeros(1, np.int64)
            radius, grp = np.zeros(0), np.zeros(0, np.int64)
        dev = self.device
        f64, v3 = wp.float64, wp.types.vector(3, wp.float64)
        # objects sorted by world (World.batch): each configuration's launch row covers
        # its own world's objects only
        n_groups = max(int(getattr(self.world, "n_worlds", 1) or 1),
                       int(grp.max(initial=-1)) + 1)
        sorted_groups = bool(O) and bool(np.all(np.diff(grp) >= 0)) and grp.min() >= 0
        first = np.searchsorted(grp, np.arange(n_groups + 1)).astype(np.int32) \
            if sorted_groups else np.zeros(1, np.int32)
        self._group_span = int(np.diff(first).max(initial=0)) if sorted_groups else 0
        self._o_first: wp.array = wp.array(first, dtype=wp.int32, device=dev)
        self._wtab = (wp.array(kind, dtype=wp.int32, device=dev),
                      wp.array(vstart.astype(np.int32), dtype=wp.int32, device=dev),
                      wp.array(V if len(V) else np.zeros((1, 3)), dtype=v3, device=dev),
                      wp.array(radius, dtype=f64, device=dev),
                      wp.array(centre, dtype=v3, device=dev),
                      wp.array(bound, dtype=f64, device=dev),
                      wp.array(grp.astype(np.int32), dtype=wp.int32, device=dev),
                      wp.array(rot, dtype=wp.types.matrix((3, 3), f64), device=dev),
                      wp.array(half, dtype=v3, device=dev))
        self.n_objects = O
        self._world_key = key
        return self._wtab

    # ------------------------------------------------------------------ bounds
    def lower_bounds(self, q: np.ndarray, groups: np.ndarray | None = None,
                     cap: float | np.ndarray = 0.05) -> tuple[np.ndarray, np.ndarray]:
        """Lower bounds [m] of the pieces' distances at configurations ``q`` (N, n_dof):
        ``(world (N, K), self (N, Q))``, per piece its smallest over the world's objects
        and per self pair (``self.pair_a``, ``self.pair_b``); bounds <= 0: maybe touching.
        ``cap`` [m] (a number or (N,) per configuration): what the caller needs to know; a
        bound at or above it may be less than the distance (the broad phase's, or GJK
        stopped there). ``groups`` (N,) int: the world of a batch each configuration is
        in."""
        import time

        from jwarp.kinematics import fk

        t0 = time.perf_counter()
        kern = ck.kernels(wp.float64)
        q = real_array(q, "q")
        if q.ndim not in (1, 2) or q.shape[-1] != self.robot.n_dof or not np.isfinite(q).all():
            raise ValueError(f"q: expected finite configurations (N, {self.robot.n_dof}) of "
                             f"'{self.robot.name}', got shape {q.shape}")
        q = np.ascontiguousarray(q.reshape(-1, self.robot.n_dof))
        N, K, Q = len(q), self.n_pieces, len(self.pair_a)
        caps = np.broadcast_to(np.asarray(cap, np.float64), (N,))
        dev = self.device
        wl = np.full((N, K), np.inf)
        sl = np.full((N, Q), np.inf)
        if N == 0 or K == 0:
            return wl, sl
        with self._lock:
            X: wp.array = wp.array(np.asarray(fk(self.robot, q, device=dev, dtype=np.float64)),
                         dtype=kern.mat44, device=dev)
            wt = self._world_tables()
            cap_d: wp.array = wp.array(np.ascontiguousarray(caps), dtype=wp.float64, device=dev)
            if self.n_objects:
                out = wp.full((N, K), 1e30, dtype=wp.float64, device=dev)
                g = np.zeros(N, np.int32) if groups is None else np.asarray(groups, np.int32)
                mode, span = 0, self.n_objects
                if groups is not None:
                    mode = 1
                    if self._group_span and g.min(initial=0) >= 0 \
                            and g.max(initial=0) < len(self._o_first) - 1:
                        mode, span = 2, self._group_span
                if span:
                    wp.launch(kern.world_lower, dim=(N, K, span),
                              inputs=[*self._tab, *wt, self._o_first, X,
                                      wp.array(g, dtype=wp.int32, device=dev), mode, cap_d,
                                  wp.float64(GJK_TOL), wp.float64(SLACK)],
                          outputs=[out], device=dev)
                wl = out.numpy()
            if Q:
                out2 = wp.empty((N, Q), dtype=wp.float64, device=dev)
                wp.launch(kern.self_lower, dim=(N, Q),
                          inputs=[*self._tab, *self._ptab, X, cap_d,
                                  wp.float64(GJK_TOL), wp.float64(SLACK)],
                          outputs=[out2], device=dev)
                sl = out2.numpy()
            self.stats.calls += 1
            self.stats.configurations += N
            self.stats.seconds += time.perf_counter() - t0
        return wl, sl

    def free(self, q: Any, margin: float = 0.0, self_margin: float = 0.0,
             groups: np.ndarray | None = None) -> np.ndarray:
        """(N,) bool: the pieces at ``q`` (N, n_dof) keep more than ``margin`` [m] from
        the world and more than ``self_margin`` from each other (certified)."""
        wl, sl = self.lower_bounds(q, groups, cap=max(margin, self_margin) + 0.05)
        return np.asarray((wl > margin).all(axis=1) & (sl > self_margin).all(axis=1), bool)

    def paths_free(self, paths: Any, margin: float = 0.0, self_margin: float = 0.0, *,
                   endpoint_margin: float | None = None, groups: np.ndarray | None = None,
                   evals_per_segment: int = EVALS_PER_SEGMENT) -> np.ndarray:
        """(P,) bool: every path of ``paths`` (P, W, n_dof), the straight joint-space
        segments between its waypoints, certified free for the pieces (module docstring)
        with ``margin`` from the world and ``self_margin`` between pieces; the first and
        last segment with ``endpoint_margin`` (None: ``margin``) instead, so a grasp pose
        closer than ``margin`` can be left and reached. ``groups`` (P,): the world of a
        batch each path is in. A path whose segments need more than ``evals_per_segment``
        configurations on average, or a halving below 2^-:data:`MAX_DEPTH`, is not
        certified (False)."""
        P_ = np.asarray(paths, np.float64)
        if P_.ndim != 3 or P_.shape[2] != self.robot.n_dof:
            raise ValueError(f"paths: expected shape (P, W, {self.robot.n_dof}), got "
                             f"{P_.shape}")
        P, W, n = P_.shape
        ok = np.ones(P, bool)
        if P == 0:
            return ok
        if W == 1:
            em = margin if endpoint_margin is None else min(margin, endpoint_margin)
            g = None if groups is None else np.asarray(groups)
            return self.free(P_[:, 0], em, min(self_margin, em), g)
        S = W - 1
        # per segment: the margins, the travel per piece (K) and per self pair (Q)
        seg_path = np.repeat(np.arange(P), S)
        qa = P_[:, :-1].reshape(-1, n)
        qb = P_[:, 1:].reshape(-1, n)
        dth = np.abs((qb - qa) @ self._coupling.T)          # (P S, n_frames)
        Tk = dth @ self.reach.T                              # (P S, K)
        Tq = dth @ self.pair_weight.T                        # (P S, Q)
        mw = np.full(P * S, float(margin))
        ms = np.full(P * S, float(self_margin))
        if endpoint_margin is not None:
            em = min(float(margin), float(endpoint_margin))
            ends = np.zeros((P, S), bool)
            ends[:, 0] = ends[:, -1] = True
            mw[ends.reshape(-1)] = em
            ms[ends.reshape(-1)] = np.minimum(ms[ends.reshape(-1)], em)
        g = None if groups is None else np.asarray(groups, np.int64)
        # what a point must be known to clear: an interval of width w of a segment is
        # proven when its two ends clear the margin by more than w T / 2 each (T: the
        # segment's largest travel); a waypoint ends intervals of width 1, a midpoint of
        # an interval of width w ends intervals of width w / 2 (its other ends were asked
        # for more)
        tk_max = Tk.max(axis=1, initial=0.0)
        tq_max = Tq.max(axis=1, initial=0.0)

        def need(rows: np.ndarray, width: np.ndarray) -> np.ndarray:
            return np.maximum(mw[rows] + width * tk_max[rows] / 2,
                              ms[rows] + width * tq_max[rows] / 2) + CAP_PAD

        seg_need = need(np.arange(P * S), np.ones(P * S)).reshape(P, S)
        way_cap = np.empty((P, W))
        way_cap[:, :-1] = seg_need
        way_cap[:, -1] = seg_need[:, -1]
        way_cap[:, 1:-1] = np.maximum(seg_need[:, :-1], seg_need[:, 1:])
        wl, sl = self.lower_bounds(P_.reshape(-1, n), None if g is None else np.repeat(g, W),
                                   cap=way_cap.reshape(-1))
        wl = wl.reshape(P, W, -1)
        sl = sl.reshape(P, W, -1)
        # intervals: (segment row, t0, t1, bounds at both ends)
        seg = np.arange(P * S)
        t0 = np.zeros(P * S)
        t1 = np.ones(P * S)
        wa, wb = wl[:, :-1].reshape(P * S, -1), wl[:, 1:].reshape(P * S, -1)
        sa, sb = sl[:, :-1].reshape(P * S, -1), sl[:, 1:].reshape(P * S, -1)
        budget = int(evals_per_segment) * P * S
        used = 0
        for _depth in range(MAX_DEPTH + 1):
            if not len(seg):
                break
            live = ok[seg_path[seg]]
            seg, t0, t1, wa, wb, sa, sb = (x[live] for x in (seg, t0, t1, wa, wb, sa, sb))
            if not len(seg):
                break
            span = (t1 - t0)[:, None]
            mwi, msi = mw[seg][:, None], ms[seg][:, None]
            hit = ((wa <= mwi) | (wb <= mwi)).any(1) | ((sa <= msi) | (sb <= msi)).any(1)
            ok[seg_path[seg[hit]]] = False
            proven = ((wa + wb - 2 * mwi > span * Tk[seg]).all(1)
                      & (sa + sb - 2 * msi > span * Tq[seg]).all(1))
            todo = ~hit & ~proven & ok[seg_path[seg]]
            if not todo.any():
                break
            if _depth == MAX_DEPTH or used + int(todo.sum()) > budget:
                ok[seg_path[seg[todo]]] = False
                break
            seg, t0, t1, wa, wb, sa, sb = (x[todo] for x in (seg, t0, t1, wa, wb, sa, sb))
            tm = (t0 + t1) / 2
            qm = qa[seg] + (qb[seg] - qa[seg]) * tm[:, None]
            wm, sm = self.lower_bounds(qm, None if g is None else g[seg_path[seg]],
                                       cap=need(seg, (t1 - t0) / 2))
            used += len(seg)
            seg = np.concatenate([seg, seg])
            t0, t1 = np.concatenate([t0, tm]), np.concatenate([tm, t1])
            wa, wb = np.concatenate([wa, wm]), np.concatenate([wm, wb])
            sa, sb = np.concatenate([sa, sm]), np.concatenate([sm, sb])
        return ok


def sphere_reach_past(robot: RobotModel) -> float:
    """[m] how deep a sphere collision may be while the meshes are still free: the largest
    protrusion of the spheres past the meshes (``sphere_relation``; 2 cm when unknown),
    plus 2 mm. Checks try the certificate only where the spheres collide less deeply."""
    rel = getattr(robot, "sphere_relation", None)
    return (max(rel.protrusion.values(), default=0.0) if rel is not None else 0.02) + 2e-3


#: MeshChecks by device and (robot, world) (by identity, held weakly), the 8 used last
_CACHE: IdentityCache[MeshCheck] = IdentityCache(8, owner=1)

#: the robot sides of MeshChecks (:func:`_robot_part`) by (extra spheres, device) and the
#: robot (by identity, held weakly), the 8 made last
_ROBOT_PARTS: IdentityCache[Any] = IdentityCache(8)


def _robot_part(robot: RobotModel, extra: list[int], device: wp.Device) -> Any:
    """The robot's side of a :class:`MeshCheck` on ``device`` (piece tables, travel
    reaches, self pairs), made once per robot (and spheres appended after the fit) and
    device: planners of one robot in many worlds share it."""
    from types import SimpleNamespace

    from jwarp.world.reach import point_reach

    key = (tuple(extra), str(device))
    hit = _ROBOT_PARTS.get(key, (robot,))
    if hit is not None:
        return hit
    cp = robot.collision_pieces
    assert cp is not None  # mesh_check() makes none without pieces
    frames = [int(p.frame) for p in cp.pieces]
    verts = [np.asarray(p.vertices, np.float64).reshape(-1, 3) for p in cp.pieces]
    rads = [float(p.radius) for p in cp.pieces]
    sources = [p.source for p in cp.pieces]
    for s in extra:  # spheres added after the fit (an attached object): as spheres
        sph = robot.spheres[s]
        frames.append(int(sph.frame))
        verts.append(np.asarray(sph.position, np.float64).reshape(1, 3))
        rads.append(float(sph.radius))
        sources.append(f"sphere {s}")
    K = len(frames)
    frame = np.asarray(frames, np.int32)
    vstart = np.concatenate([[0], np.cumsum([len(v) for v in verts])]).astype(np.int32)
    V = np.concatenate(verts) if K else np.zeros((0, 3))
    lo = np.array([v.min(0) for v in verts]).reshape(K, 3)
    hi = np.array([v.max(0) for v in verts]).reshape(K, 3)
    centre = (lo + hi) / 2
    bound = np.array([np.linalg.norm(v - c, axis=1).max() + r
                      for v, c, r in zip(verts, centre, rads)]).reshape(K)
    f64, v3 = wp.float64, wp.types.vector(3, wp.float64)
    tab: tuple = (wp.array(frame, dtype=wp.int32, device=device),
           wp.array(vstart, dtype=wp.int32, device=device),
           wp.array(V.reshape(-1, 3), dtype=v3, device=device),
           wp.array(np.asarray(rads, np.float64), dtype=f64, device=device),
           wp.array(centre, dtype=v3, device=device),
           wp.array(bound, dtype=f64, device=device))
    # travel: per piece and frame the reach of its enclosing sphere
    reach = point_reach(robot, frame, centre, bound)   # (K, n_frames)
    pair_a, pair_b, pair_weight = _pair_tables(robot, frame, reach)
    coupling = np.zeros((robot.n_frames, robot.n_dof))
    for i, f in enumerate(robot.frames):
        for j, c in f.coupling:
            coupling[i, j] += c
    part = SimpleNamespace(sources=sources, n_pieces=K, frame=frame, tab=tab, reach=reach,
                           coupling=coupling, pair_a=pair_a, pair_b=pair_b,
                           pair_weight=pair_weight,
                           ptab=(wp.array(pair_a, dtype=wp.int32, device=device),
                                 wp.array(pair_b, dtype=wp.int32, device=device)))
    return _ROBOT_PARTS.put(key, (robot,), part)


def _pair_tables(robot: RobotModel, f: np.ndarray, reach: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Self pairs: pieces on two frames the robot checks against each other (``f`` (K,)
    each piece's frame), and per pair the travel weights (Q, n_frames) of the frames
    between them and their common ancestor (``reach`` (K, n_frames))."""
    allowed = np.asarray(robot.allowed_collision_pairs, bool)
    ia, ib = np.nonzero((f[:, None] != f[None, :]) & allowed[f[:, None], f[None, :]]
                        & (np.arange(len(f))[:, None] < np.arange(len(f))[None, :]))
    parents = robot.parents

    def chain(x: int) -> list[int]:
        out = []
        while x >= 0:
            out.append(x)
            x = int(parents[x])
        return out

    W = np.zeros((len(ia), robot.n_frames))
    for q, (a, b) in enumerate(zip(ia, ib)):
        ca, cb = chain(int(f[a])), chain(int(f[b]))
        common = set(ca) & set(cb)
        for k, c in ((a, ca), (b, cb)):
            for i in c:
                if i in common:
                    break
                W[q, i] += reach[k, i]
    return ia.astype(np.int32), ib.astype(np.int32), W



def cached_mesh_check(robot: RobotModel, world: World | None, device: DeviceLike = None) -> MeshCheck | None:
    """The :class:`MeshCheck` :func:`mesh_check` has made for these, or None (makes none)."""
    return _CACHE.get(str(resolve_device(device)), (robot, world))


def mesh_check(robot: RobotModel, world: World | None, device: DeviceLike = None, *, rho: ArrayLike | None = None
               ) -> MeshCheck | None:
    """The :class:`MeshCheck` of ``robot`` in ``world`` on ``device`` (kept per robot,
    world and device: a few are cached), or None where there is none: no
    ``collision_pieces``, spheres edited since the pieces were made, a world with a voxel
    grid, or an elastic model (``rho`` given)."""
    if rho is not None:
        return None
    model = robot
    cp = getattr(model, "collision_pieces", None)
    if cp is None or cp.extra_spheres(model) is None:
        return None
    if world is not None and getattr(world, "has_grid", False):
        return None
    dev = resolve_device(device)
    hit = _CACHE.get(str(dev), (model, world))
    if hit is not None:
        return hit
    return _CACHE.put(str(dev), (model, world), MeshCheck(model, world, dev))
