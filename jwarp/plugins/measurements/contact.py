"""Contact measurement (thesis eq. 2.43-2.44): signed distance between two bodies.

Each sample measures one pair of bodies (per-sample input column ``pair`` = index into the
setup's pair list); the observation is the signed distance ``distance`` [m] (> 0 apart,
< 0 in penetration; a measured contact is 0). The distance depends only on the relative
pose of the two bodies' frames. Bodies:

* ``sphere`` and ``capsule`` (segment ``p0``-``p1`` swept by a radius): exact analytic
  distance (closest points of two segments, minus the radii); a sphere is a capsule with
  ``p0 = p1``. ``robot_capsule`` / ``robot_sphere`` take the geometry from the RobotModel
  (e.g. hand4's capsule fingertips).
* ``mesh`` (trimesh, watertight): distance of a sphere/capsule to the mesh surface, from
  the closest points on the triangles (:func:`trimesh.triangles.closest_point`) signed by
  the generalized winding number (:func:`mesh_signed_distance`, outside positive; note
  that ``trimesh.proximity.signed_distance`` is positive INSIDE), minimized along the
  capsule's segment. Mesh-mesh pairs are not supported.

A body sits on a robot frame (``"frame": "<name>"``) or is a fixture linked to the base
(``"frame": null``) with a pose (position + rotation vector) in the base frame.

Setup section (JSON)::

    {"plugin": "contact",
     "bodies": [
       {"name": "thumb", "robot_capsule": "thumb_distal", "sigma_radius": 0.001},
       {"name": "index", "robot_capsule": 1},
       {"name": "ball", "type": "sphere", "frame": "palm", "center": [0.05, 0, 0.03],
        "radius": 0.01},
       {"name": "tip", "type": "capsule", "frame": "ring_distal", "p0": [0, 0, 0],
        "p1": [0.011, 0, 0], "radius": 0.009},
       {"name": "table", "type": "mesh", "frame": null, "box": [0.3, 0.3, 0.02],
        "position": [0.08, 0, -0.05], "rotvec": [0, 0, 0],
        "sigma_position": 0.01, "sigma_rotation": 0.1}],
     "pairs": [["thumb", "index"], ["index", "table"]],
     "noise": 0.0005}

Mesh geometry: ``"box": [ex, ey, ez]`` (extents, centred), ``"vertices"`` + ``"faces"``,
or ``"file"`` (any format trimesh loads; relative paths are taken from the working
directory). Parameters: ``<body>_radius`` for every sphere/capsule body (group ``radii``),
``<body>_px, _py, _pz, _rx, _ry, _rz`` for every fixture (group ``fixtures``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, cast

import numpy as np

from jwarp.model import RobotModel
from jwarp.model import geometry as g
from jwarp.model.measurement import Measurement, ParamBlock
from jwarp.plugins.registry import hookimpl

BODY_KEYS = {"name", "type", "frame", "center", "p0", "p1", "radius", "sigma_radius",
             "robot_capsule", "robot_sphere", "box", "vertices", "faces", "file",
             "position", "rotvec", "sigma_position", "sigma_rotation"}


@dataclass
class Body:
    name: str
    kind: str                      # "capsule" (spheres too) or "mesh"
    frame: int | None              # robot frame, None = fixture on the base
    p0: np.ndarray | None = None   # (3,) segment in the body's frame [m]
    p1: np.ndarray | None = None
    i_radius: int = -1             # parameter index of the radius
    i_pose: int = -1               # parameter index of the fixture pose (6 entries)
    mesh: Any = None               # trimesh.Trimesh in the body's frame
    slot: int = -1                 # index in Measurement.frames (robot frames only)


def closest_segments(a0: np.ndarray, a1: np.ndarray, b0: np.ndarray, b1: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Closest points of segments a0-a1 and b0-b1 (points allowed), vectorized.

    All inputs (N, 3) [m]. Returns (ca, cb) (N, 3). Ericson, Real-Time Collision
    Detection, 5.1.9.
    """
    d1, d2, r = a1 - a0, b1 - b0, a0 - b0
    a = np.einsum("ij,ij->i", d1, d1)
    e = np.einsum("ij,ij->i", d2, d2)
    f = np.einsum("ij,ij->i", d2, r)
    c = np.einsum("ij,ij->i", d1, r)
    b = np.einsum("ij,ij->i", d1, d2)
    tiny = 1e-18
    a_pt, e_pt = a <= tiny, e <= tiny
    sa, se = np.where(a_pt, 1.0, a), np.where(e_pt, 1.0, e)
    denom = a * e - b * b
    s = np.where(denom > 1e-12 * np.maximum(a * e, tiny),
                 np.clip((b * f - c * e) / np.where(denom > 0, denom, 1.0), 0.0, 1.0), 0.0)
    t = (b * s + f) / se
    s = np.where(t < 0, np.clip(-c / sa, 0.0, 1.0), np.where(t > 1, np.clip((b - c) / sa, 0.0, 1.0), s))
    t = np.clip(t, 0.0, 1.0)
    # degenerate segments
    s = np.where(e_pt, np.clip(-c / sa, 0.0, 1.0), s)
    t = np.where(e_pt, 0.0, t)
    t = np.where(a_pt, np.clip(f / se, 0.0, 1.0), t)
    s = np.where(a_pt, 0.0, s)
    return a0 + s[:, None] * d1, b0 + t[:, None] * d2


class ContactMeasurement(Measurement):
    """Signed distance [m] between the two bodies of each sample's pair (eq. 2.43-2.44)."""

    name = "contact"
    unit = "m"
    DEFAULT_NOISE = 0.0005                 # m
    DEFAULT_RADIUS_SIGMA = 0.001           # m
    DEFAULT_FIXTURE_SIGMA = (0.01, 0.1)    # m, rad
    MESH_SAMPLES = 11                      # coarse samples along a capsule against a mesh
    MESH_GOLDEN_ITERS = 40                 # golden-section refinement steps

    def __init__(self, robot: RobotModel, setup: dict) -> None:
        super().__init__(robot, setup)
        g.check_keys(setup, {"plugin", "bodies", "pairs", "noise"}, "setup")
        bodies = g.section(setup, "bodies", "setup")
        if not isinstance(bodies, list) or not bodies:
            raise ValueError("setup.bodies: expected a non-empty list of bodies")
        names: list[str] = []
        nominal: list[float] = []
        sigma: list[float] = []
        groups: list[str] = []
        self.bodies: dict[str, Body] = {}
        for k, bd in enumerate(bodies):
            where = f"setup.bodies[{k}]"
            g.check_keys(bd, BODY_KEYS, where)
            nm = g.valid_name(g.section(bd, "name", where), f"{where}.name")
            if nm in self.bodies:
                raise ValueError(f"{where}.name: duplicate body name '{nm}'")
            body, radius = self._parse_body(robot, bd, nm, where)
            if radius is not None:
                body.i_radius = len(names)
                names.append(f"{nm}_radius")
                nominal.append(radius)
                sigma.append(g.positive(bd.get("sigma_radius", self.DEFAULT_RADIUS_SIGMA),
                                        f"{where}.sigma_radius", allow_inf=True))
                groups.append("radii")
            if body.frame is None:
                pos, rv, sp, sr = g.parse_pose(
                    bd, where, default_sigma_position=self.DEFAULT_FIXTURE_SIGMA[0],
                    default_sigma_rotation=self.DEFAULT_FIXTURE_SIGMA[1], required=False)
                body.i_pose = len(names)
                n6, v6, s6, g6 = g.pose_param_entries(nm, pos, rv, sp, sr, "fixtures")
                names += n6
                nominal += v6
                sigma += s6
                groups += g6
            else:
                for key in ("position", "rotvec", "sigma_position", "sigma_rotation"):
                    if key in bd:
                        raise ValueError(f"{where}.{key}: only fixtures (\"frame\": null) have "
                                         f"a pose; a body on a robot frame is given in that "
                                         f"frame's coordinates")
            self.bodies[nm] = body

        pairs = g.section(setup, "pairs", "setup")
        if not isinstance(pairs, list) or not pairs:
            raise ValueError("setup.pairs: expected a non-empty list of [body, body] pairs")
        self.pairs: list[tuple[str, str]] = []
        for k, pr in enumerate(pairs):
            where = f"setup.pairs[{k}]"
            if not isinstance(pr, (list, tuple)) or len(pr) != 2:
                raise ValueError(f"{where}: expected two body names, got {pr!r}")
            for b in pr:
                if b not in self.bodies:
                    raise ValueError(f"{where}: unknown body '{b}'; bodies: "
                                     f"{', '.join(self.bodies)}")
            if pr[0] == pr[1]:
                raise ValueError(f"{where}: a body cannot touch itself ('{pr[0]}')")
            if self.bodies[pr[0]].kind == "mesh" and self.bodies[pr[1]].kind == "mesh":
                raise ValueError(f"{where}: mesh-mesh pairs are not supported "
                                 f"('{pr[0]}', '{pr[1]}')")
            if self.bodies[pr[0]].frame is None and self.bodies[pr[1]].frame is None:
                raise ValueError(f"{where}: both bodies are fixtures; the distance does not "
                                 f"depend on the robot")
            self.pairs.append((str(pr[0]), str(pr[1])))

        self.noise = g.positive(setup.get("noise", self.DEFAULT_NOISE), "setup.noise")
        used = sorted({self.bodies[b].frame for pr in self.pairs for b in pr
                       if self.bodies[b].frame is not None})
        self.frames = used
        for body in self.bodies.values():
            if body.frame is not None and body.frame in used:
                body.slot = used.index(body.frame)
        self.obs_names = ["distance"]
        self.meta_names = ["pair"]
        self.params = ParamBlock(names, np.array(nominal), np.array(sigma), groups)

    # ----------------------------------------------------------------- setup
    @staticmethod
    def _parse_body(robot: RobotModel, bd: dict, nm: str, where: str
                    ) -> tuple[Body, float | None]:
        if "robot_capsule" in bd or "robot_sphere" in bd:
            key = "robot_capsule" if "robot_capsule" in bd else "robot_sphere"
            extra = set(bd) - {"name", key, "sigma_radius"}
            if extra:
                raise ValueError(f"{where}: key(s) {sorted(extra)} cannot be combined with "
                                 f"'{key}' (the geometry comes from the robot)")
            items = robot.capsules if key == "robot_capsule" else robot.spheres
            ref = bd[key]
            if isinstance(ref, bool) or not isinstance(ref, (str, int)):
                raise ValueError(f"{where}.{key}: expected a frame name or an index")
            if isinstance(ref, int):
                if not 0 <= ref < len(items):
                    raise ValueError(f"{where}.{key}: index {ref} out of range [0, {len(items)}) "
                                     f"for robot '{robot.name}'")
                item = items[ref]
            else:
                fi = g.robot_frame(robot, ref, f"{where}.{key}")
                found = [it for it in items if it.frame == fi]
                if len(found) != 1:
                    raise ValueError(f"{where}.{key}: robot '{robot.name}' has {len(found)} "
                                     f"{key[6:]}s on frame '{ref}'; give an index instead")
                item = found[0]
            if key == "robot_capsule":
                p0, p1 = np.asarray(item.p0, float), np.asarray(item.p1, float)
            else:
                p0 = p1 = np.asarray(item.position, float)
            return Body(nm, "capsule", item.frame, p0.copy(), p1.copy()), float(item.radius)
        kind = g.section(bd, "type", where)
        fr = g.section(bd, "frame", where)
        frame = None if fr is None else g.robot_frame(robot, fr, f"{where}.frame")
        allowed = {"sphere": {"center", "radius"}, "capsule": {"p0", "p1", "radius"},
                   "mesh": {"box", "vertices", "faces", "file"}}
        if kind not in allowed:
            raise ValueError(f"{where}.type: unknown body type {kind!r}; known: "
                             f"sphere, capsule, mesh (or robot_capsule / robot_sphere)")
        geo_keys = set().union(*allowed.values()) | {"sigma_radius"}
        wrong = sorted((set(bd) & geo_keys) - allowed[kind] - ({"sigma_radius"} if kind != "mesh" else set()))
        if wrong:
            raise ValueError(f"{where}: key(s) {wrong} do not apply to a {kind}")
        if kind in ("sphere", "capsule"):
            radius = g.positive(g.section(bd, "radius", where), f"{where}.radius", allow_zero=True)
            if kind == "sphere":
                c = g.finite_array(g.section(bd, "center", where), f"{where}.center", (3,))
                return Body(nm, "capsule", frame, c.copy(), c.copy()), radius
            p0 = g.finite_array(g.section(bd, "p0", where), f"{where}.p0", (3,))
            p1 = g.finite_array(g.section(bd, "p1", where), f"{where}.p1", (3,))
            return Body(nm, "capsule", frame, p0, p1), radius
        return Body(nm, "mesh", frame, mesh=_load_mesh(bd, where)), None

    # ------------------------------------------------------------ evaluation
    def _pair_index(self, meta: dict[str, np.ndarray]) -> np.ndarray:
        a = np.asarray(meta["pair"], dtype=np.float64)
        if not np.all(np.isfinite(a)) or np.any(a != np.round(a)):
            raise ValueError("meta['pair']: expected integer pair indices")
        idx = a.astype(np.int64)
        if np.any((idx < 0) | (idx >= len(self.pairs))):
            bad = idx[(idx < 0) | (idx >= len(self.pairs))][0]
            raise ValueError(f"meta['pair']: index {bad} out of range [0, {len(self.pairs)})")
        return idx

    def _pose(self, body: Body, f: np.ndarray, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Rotation (S, 3, 3) and origin (S, 3) of the body's frame in the base."""
        S = f.shape[0]
        if body.frame is not None:
            return f[:, body.frame, :3, :3], f[:, body.frame, :3, 3]
        i = body.i_pose
        return (np.broadcast_to(g.rotvec_matrix(p[i + 3:i + 6]), (S, 3, 3)),
                np.broadcast_to(p[i:i + 3], (S, 3)))

    def _evaluate(self, f: np.ndarray, p: np.ndarray, meta: dict, grad: bool):
        S = f.shape[0]
        pair = self._pair_index(meta)
        y = np.zeros((S, 1))
        jf = np.zeros((S, 1, len(self.frames), 6)) if grad else None
        jp = np.zeros((S, 1, self.params.size)) if grad else None
        for k, (na, nb) in enumerate(self.pairs):
            sel = np.nonzero(pair == k)[0]
            if sel.size == 0:
                continue
            A, B = self.bodies[na], self.bodies[nb]
            if A.kind == "mesh":
                A, B = B, A  # the segment body first; the distance is symmetric
            RA, oA = self._pose(A, f[sel], p)
            RB, oB = self._pose(B, f[sel], p)
            # segment bodies (capsules) have their end points
            a0 = np.einsum("sij,j->si", RA, cast(np.ndarray, A.p0)) + oA
            a1 = np.einsum("sij,j->si", RA, cast(np.ndarray, A.p1)) + oA
            if B.kind == "capsule":
                b0 = np.einsum("sij,j->si", RB, cast(np.ndarray, B.p0)) + oB
                b1 = np.einsum("sij,j->si", RB, cast(np.ndarray, B.p1)) + oB
                ca, cb = closest_segments(a0, a1, b0, b1)
                diff = ca - cb
                dist = np.linalg.norm(diff, axis=1)
                n = diff / np.where(dist > 0, dist, 1.0)[:, None]
                d = dist - p[A.i_radius] - p[B.i_radius]
            else:
                ca, cb, sd, n = self._segment_mesh(a0, a1, RB, oB, B.mesh)
                d = sd - p[A.i_radius]
            y[sel, 0] = d
            if not grad:
                continue
            assert jf is not None and jp is not None  # allocated with grad
            for body, c, sign in ((A, ca, 1.0), (B, cb, -1.0)):
                if body.frame is not None:
                    jf[sel, 0, body.slot, :] += sign * g.point_twist_rows(n, c, f[sel, body.frame, :3, 3])
                else:
                    i = body.i_pose
                    t = p[i:i + 3]
                    jp[sel, 0, i:i + 3] += sign * n
                    jp[sel, 0, i + 3:i + 6] += sign * np.cross(c - t, n) @ g.left_jacobian(p[i + 3:i + 6])
                if body.i_radius >= 0:
                    jp[sel, 0, body.i_radius] -= 1.0
        return y, jf, jp

    def _segment_mesh(self, a0: np.ndarray, a1: np.ndarray, RB: np.ndarray, oB: np.ndarray,
                      mesh: Any) -> tuple[np.ndarray, ...]:
        """Minimum over the segment a0-a1 (S, 3) of the outside-positive signed distance to
        ``mesh`` (pose RB, oB). Returns (point on segment, closest mesh point (world),
        distance (S,), unit gradient n (S, 3) in the base)."""
        la0 = np.einsum("sji,sj->si", RB, a0 - oB)   # segment in mesh coordinates
        la1 = np.einsum("sji,sj->si", RB, a1 - oB)

        def sd(t: np.ndarray) -> np.ndarray:       # outside-positive signed distance
            return mesh_signed_distance(mesh, la0 + t[:, None] * (la1 - la0))[0]

        S = a0.shape[0]
        degenerate = np.linalg.norm(la1 - la0, axis=1) < 1e-12
        grid = np.linspace(0.0, 1.0, self.MESH_SAMPLES)
        vals = np.stack([sd(np.full(S, t)) for t in grid], axis=1)   # (S, n)
        best = np.argmin(vals, axis=1)
        t_best = grid[best]
        if not np.all(degenerate):
            h = grid[1]
            lo, hi = np.clip(t_best - h, 0, 1), np.clip(t_best + h, 0, 1)
            gr = (np.sqrt(5.0) - 1.0) / 2.0
            c, d = hi - gr * (hi - lo), lo + gr * (hi - lo)
            fc, fd = sd(c), sd(d)
            for _ in range(self.MESH_GOLDEN_ITERS):
                left = fc < fd          # minimum in [lo, d]: drop (d, hi]; else drop [lo, c)
                hi = np.where(left, d, hi)
                lo = np.where(left, lo, c)
                c_new = np.where(left, hi - gr * (hi - lo), d)
                d_new = np.where(left, c, lo + gr * (hi - lo))
                f_new = sd(np.where(left, c_new, d_new))   # one new evaluation per step
                fc, fd = np.where(left, f_new, fd), np.where(left, fc, f_new)
                c, d = c_new, d_new
            t_gs = 0.5 * (lo + hi)
            f_gs = sd(t_gs)
            t_best = np.where((f_gs < vals[np.arange(S), best]) & ~degenerate, t_gs, t_best)
        P = la0 + t_best[:, None] * (la1 - la0)
        sdist, closest, tri = mesh_signed_distance(mesh, P)
        diff = P - closest
        nl = np.where((np.abs(sdist) > 1e-12)[:, None], diff / np.where(sdist == 0, 1.0, sdist)[:, None],
                      mesh.face_normals[tri])
        nl /= np.linalg.norm(nl, axis=1, keepdims=True)
        pw = np.einsum("sij,sj->si", RB, P) + oB
        cw = np.einsum("sij,sj->si", RB, closest) + oB
        return pw, cw, sdist, np.einsum("sij,sj->si", RB, nl)

    # ------------------------------------------------------------- interface
    def predict(self, frames: np.ndarray, p: np.ndarray, meta: dict | None = None) -> np.ndarray:
        f, p, m = self.check_inputs(frames, p, meta)
        return self._evaluate(f, p, m, grad=False)[0]

    def jacobians(self, frames: np.ndarray, p: np.ndarray, meta: dict | None = None
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        f, p, m = self.check_inputs(frames, p, meta)
        return self._evaluate(f, p, m, grad=True)


def mesh_signed_distance(mesh: Any, points: np.ndarray, chunk: int = 1 << 18
                         ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Outside-positive signed distance of points to a watertight triangle mesh.

    points (N, 3) [m] in the mesh's coordinates. Returns (distance (N,) [m] (> 0 outside,
    < 0 inside), closest surface point (N, 3), index of the closest triangle (N,)).
    Exhaustive over the triangles (closest points by :func:`trimesh.triangles.closest_point`,
    inside/outside by the generalized winding number), so it needs no spatial index; cost
    O(N x triangles), meant for the small meshes of fixtures and fingertips. (trimesh's own
    ``proximity.signed_distance`` is positive INSIDE and needs the optional ``rtree``.)
    """
    import trimesh

    tri = np.asarray(mesh.triangles, dtype=np.float64)          # (M, 3, 3)
    M, N = tri.shape[0], points.shape[0]
    best_d = np.full(N, np.inf)
    best_c = np.zeros((N, 3))
    best_i = np.zeros(N, dtype=np.int64)
    winding = np.zeros(N)
    step = max(1, chunk // M)
    for lo in range(0, N, step):
        pts = points[lo:lo + step]
        n = pts.shape[0]
        c = trimesh.triangles.closest_point(np.broadcast_to(tri, (n, M, 3, 3)).reshape(-1, 3, 3),
                                            np.repeat(pts, M, axis=0)).reshape(n, M, 3)
        d2 = np.sum((c - pts[:, None]) ** 2, axis=-1)
        i = np.argmin(d2, axis=1)
        best_i[lo:lo + n] = i
        best_c[lo:lo + n] = c[np.arange(n), i]
        best_d[lo:lo + n] = np.sqrt(d2[np.arange(n), i])
        # solid angle of every triangle seen from each point (Van Oosterom & Strackee)
        a, b, cc = (tri[None, :, k] - pts[:, None] for k in range(3))
        la, lb, lc = (np.linalg.norm(x, axis=-1) for x in (a, b, cc))
        num = np.einsum("nmi,nmi->nm", a, np.cross(b, cc))
        den = (la * lb * lc + np.einsum("nmi,nmi->nm", a, b) * lc
               + np.einsum("nmi,nmi->nm", a, cc) * lb + np.einsum("nmi,nmi->nm", b, cc) * la)
        winding[lo:lo + n] = np.sum(np.arctan2(num, den), axis=1) / (2.0 * np.pi)
    inside = winding > 0.5
    return np.where(inside, -best_d, best_d), best_c, best_i


def _load_mesh(bd: dict, where: str) -> Any:
    import trimesh

    given = [k for k in ("box", "vertices", "file") if k in bd]
    if len(given) != 1:
        raise ValueError(f"{where}: a mesh needs exactly one of 'box', 'vertices' + 'faces' "
                         f"or 'file', got {given or 'none'}")
    if "box" in bd:
        ext = g.finite_array(bd["box"], f"{where}.box", (3,))
        if np.any(ext <= 0):
            raise ValueError(f"{where}.box: extents must be > 0 m, got {ext.tolist()}")
        mesh = trimesh.creation.box(extents=ext)
    elif "vertices" in bd:
        v = g.finite_array(bd["vertices"], f"{where}.vertices")
        if v.ndim != 2 or v.shape[1] != 3:
            raise ValueError(f"{where}.vertices: expected (N, 3) numbers, got shape {v.shape}")
        fc = np.asarray(g.section(bd, "faces", where))
        if fc.ndim != 2 or fc.shape[1] != 3 or fc.dtype.kind not in "iu":
            raise ValueError(f"{where}.faces: expected (M, 3) integer vertex indices")
        if fc.size and (fc.min() < 0 or fc.max() >= len(v)):
            raise ValueError(f"{where}.faces: vertex index out of range [0, {len(v)})")
        mesh = trimesh.Trimesh(vertices=v, faces=fc, process=True)
    else:
        try:
            mesh = trimesh.load(bd["file"], force="mesh")
        except Exception as e:  # trimesh raises many kinds for unreadable files
            raise ValueError(f"{where}.file: cannot load mesh '{bd['file']}': {e}") from e
    if not mesh.is_watertight:
        raise ValueError(f"{where}: the mesh must be watertight (closed) for a signed distance")
    return mesh


@hookimpl
def jwarp_measurements() -> dict[str, Any]:
    return {"contact": ContactMeasurement}
