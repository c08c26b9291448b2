"""An independent exact path checker for jwarp's planning promise (a helper of the tests
and benchmarks, not a test file).

A path is an array (W, n) of joint waypoints joined by straight lines in joint space. jwarp
calls it *feasible* when every robot collision sphere keeps at least ``margin`` from the
exact scene geometry along the whole continuous motion. :class:`PathVerifier` checks that
without any of jwarp's kinematics or collision code: forward kinematics by **pinocchio**
(the URDF itself), distances by **coal** between exact primitives, numpy for the rest.
jwarp is used by callers only to read a scene file into shapes
(``jwarp.world.load_scene(...).shapes``: ``kind``, ``dims``, ``pose``, ``object_id``,
``mesh``; conventions of jwarp/world/primitives.py, mapped here onto coal's own, which are
the same: Box full sides, Cylinder/Capsule/Cone centred on z with half length +-L/2, the
cone's tip at +z).

Two checks, at samples so dense that no revolute joint moves more than ``max_step_deg``
(and no prismatic joint more than ``max_step_m``) between two of them:

(a) ``mesh``: the URDF collision geometry (pinocchio ``GeometryModel``: meshes as coal BVH
    models, boxes/cylinders/spheres as coal primitives) against every scene shape; the
    signed coal distance (negative: penetrating). Containment without a surface crossing
    (a small object swallowed by a closed link mesh, a link swallowed by a scene mesh) is
    caught by a point-in-mesh test whenever one's world bounding box lies inside the
    other's;
(b) ``sphere`` (when ``spheres`` are given): each robot sphere (frame name, centre in that
    frame, radius), placed by pinocchio FK, against every scene shape (coal sphere vs the
    exact primitive).

Sphere frame names follow jwarp's URDF importer (jwarp/importers/urdf.py, docs/urdf.md):
a URDF link name is that link's frame; a joint name is the URDF joint frame (pinocchio's
frame of that name: the child link's frame); ``<joint>_axis`` is the frame of a moving
joint whose axis is neither +z nor -z: the joint frame turned so that its z is the joint
axis (``R_align``, reimplemented here); ``<joint>_origin`` the same frame at joint value 0.
Mimic joints follow their joint (``multiplier * q + offset``).

(c) ``self`` (when ``self_pairs`` are given): the URDF collision geometries of each listed
    pair of links against each other (coal mesh-mesh distance, negative: penetrating),
    held to ``self_margin`` (default 0). A link swallowed whole by another without a
    surface crossing is not detected by (c).

A sample at the first or last waypoint is held to ``endpoint_margin`` (default
``margin``), every other sample to ``margin``.

Each pair is first bounded below cheaply (bounding spheres, numpy); the exact coal
distance runs only where the bound could still beat the smallest distance found so far or
the threshold, so the reported minimum is exact and every violation is found.
"""

from __future__ import annotations

import math
import os
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import coal
import numpy as np
import pinocchio as pin

__all__ = ["PathVerifier", "Verdict", "Hit", "checked_link_pairs", "coal_shape", "robot_spheres"]


@dataclass
class Hit:
    """One sample-pair distance: ``distance`` [m] between robot part ``link`` (a URDF
    collision geometry's link, or ``frame#k`` for robot sphere k) and scene object
    ``object_id``, at waypoint interval ``interval`` (between waypoints i and i + 1) and
    ``fraction`` in [0, 1] along it; ``check`` is ``"mesh"``, ``"sphere"`` or ``"self"``
    (then ``object_id`` is the other link)."""

    distance: float
    interval: int
    fraction: float
    link: str
    object_id: str
    check: str
    threshold: float = 0.0

    def __str__(self) -> str:
        return (f"{self.check} {self.link} vs {self.object_id}: {self.distance * 1e3:.3f} mm "
                f"(needs {self.threshold * 1e3:.3f} mm) at interval {self.interval} "
                f"+ {self.fraction:.4f}")


@dataclass
class Verdict:
    """Result of :meth:`PathVerifier.check_path`.

    ok: every sample keeps its threshold in every check; ``min_distance`` [m] the smallest
    distance found (checks a and b), ``closest`` where (a :class:`Hit`); ``mesh`` /
    ``sphere`` / ``self_mesh``: the smallest per check (None when not run); ``first_violation``: the first
    sample (path order) below its threshold, None when ok; ``n_samples`` configurations
    checked; ``n_exact`` exact coal distance queries run."""

    ok: bool
    min_distance: float
    closest: Hit | None
    mesh: Hit | None
    sphere: Hit | None
    first_violation: Hit | None
    n_samples: int
    n_exact: int = 0
    self_mesh: Hit | None = None

    @property
    def interval(self) -> int | None:
        return None if self.closest is None else self.closest.interval

    @property
    def fraction(self) -> float | None:
        return None if self.closest is None else self.closest.fraction

    @property
    def link(self) -> str | None:
        return None if self.closest is None else self.closest.link

    @property
    def object_id(self) -> str | None:
        return None if self.closest is None else self.closest.object_id

    def __str__(self) -> str:
        head = "ok" if self.ok else f"VIOLATION: {self.first_violation}"
        return f"{head}; closest {self.closest}; {self.n_samples} samples"


# ------------------------------------------------------------------ scene shapes -> coal
def coal_shape(shape: Any) -> tuple[Any, Any]:
    """(coal geometry, trimesh or None) of a jwarp scene shape (``kind``, ``dims``,
    ``mesh``), in the shape's local frame."""
    kind, d = shape.kind, np.asarray(shape.dims, np.float64)
    if kind == "box":
        return coal.Box(float(d[0]), float(d[1]), float(d[2])), None
    if kind == "sphere":
        return coal.Sphere(float(d[0])), None
    if kind == "cylinder":              # dims [length, radius]; coal: (radius, length)
        return coal.Cylinder(float(d[1]), float(d[0])), None
    if kind == "capsule":               # segment length; coal: (radius, segment length)
        return coal.Capsule(float(d[1]), float(d[0])), None
    if kind == "cone":
        return coal.Cone(float(d[1]), float(d[0])), None
    if kind == "mesh":
        m = shape.mesh
        return _bvh(np.asarray(m.vertices, np.float64), np.asarray(m.faces, np.int64)), m
    raise ValueError(f"object '{getattr(shape, 'object_id', '?')}': unknown shape kind {kind!r}")


def _bvh(vertices: np.ndarray, faces: np.ndarray) -> Any:
    b = coal.BVHModelOBBRSS()
    b.beginModel(len(faces), len(vertices))
    b.addVertices(np.ascontiguousarray(vertices, np.float64))
    b.addTriangles(np.ascontiguousarray(faces, np.int64))
    b.endModel()
    b.computeLocalAABB()
    return b


def _local_bound(geom: Any, mesh: Any) -> tuple[np.ndarray, float, np.ndarray]:
    """(centre (3,), radius, local AABB corners (8, 3)) of a coal geometry (local frame)."""
    if mesh is not None:
        v = np.asarray(mesh.vertices, np.float64)
        lo, hi = v.min(0), v.max(0)
    else:
        if isinstance(geom, coal.Box):
            h = np.asarray(geom.halfSide, np.float64)
        elif isinstance(geom, coal.Sphere):
            h = np.full(3, geom.radius)
        elif isinstance(geom, coal.Capsule):
            h = np.array([geom.radius, geom.radius, geom.halfLength + geom.radius])
        elif isinstance(geom, (coal.Cylinder, coal.Cone)):
            h = np.array([geom.radius, geom.radius, geom.halfLength])
        else:
            geom.computeLocalAABB()
            lo = np.asarray(geom.aabb_local.min_, np.float64)
            hi = np.asarray(geom.aabb_local.max_, np.float64)
            h = None
        if h is not None:
            lo, hi = -h, h
    c = 0.5 * (lo + hi)
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                        for z in (lo[2], hi[2])])
    if mesh is not None:
        r = float(np.linalg.norm(np.asarray(mesh.vertices) - c, axis=1).max())
    else:
        r = float(np.linalg.norm(hi - c))
    return c, r, corners


def _world_aabb(corners: np.ndarray, T: np.ndarray) -> np.ndarray:
    w = corners @ T[:3, :3].T + T[:3, 3]
    return np.stack([w.min(0), w.max(0)])


def _inside(a: np.ndarray, b: np.ndarray) -> bool:
    """AABB a (2, 3) within AABB b."""
    return bool(np.all(a[0] >= b[0]) and np.all(a[1] <= b[1]))


def _contains(mesh: Any, T: np.ndarray, point: np.ndarray) -> bool:
    """Whether the world point lies inside the closed trimesh posed by T."""
    R, t = T[:3, :3], T[:3, 3]
    local = (np.asarray(point) - t) @ R
    return bool(mesh.contains(local[None])[0])


# ------------------------------------------------------------------ URDF helpers
def _align_z(axis: np.ndarray) -> np.ndarray:
    """The rotation taking z onto the unit ``axis``, with jwarp's URDF importer convention
    (exact Rot_y(+-pi/2) for +-x, Rot_x(-+pi/2) for +-y, Rodrigues otherwise)."""
    a = np.asarray(axis, np.float64)
    exact = {(1, 0, 0): [[0, 0, 1], [0, 1, 0], [-1, 0, 0]],
             (0, 1, 0): [[1, 0, 0], [0, 0, 1], [0, -1, 0]]}
    for e, m in exact.items():
        m = np.array(m, np.float64)
        if np.all(np.abs(a - e) <= 1e-12):
            return m
        if np.all(np.abs(a + np.array(e)) <= 1e-12):
            return m.T
    z = np.array([0.0, 0.0, 1.0])
    v = np.cross(z, a)
    vx = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + vx + vx @ vx / (1.0 + float(a[2]))


@dataclass
class _UrdfJoint:
    name: str
    type: str
    axis: np.ndarray
    mimic: tuple[str, float, float] | None


def _read_joints(urdf_path: str) -> list[_UrdfJoint]:
    root = ET.parse(urdf_path).getroot()
    out = []
    for j in root.findall("joint"):
        ax = j.find("axis")
        axis = np.array([1.0, 0.0, 0.0]) if ax is None else np.array(
            [float(x) for x in ax.get("xyz", "1 0 0").split()])
        axis = axis / np.linalg.norm(axis)
        mm = j.find("mimic")
        mimic = None
        if mm is not None:
            mimic = (mm.get("joint"), float(mm.get("multiplier", 1.0)),
                     float(mm.get("offset", 0.0)))
        out.append(_UrdfJoint(j.get("name"), j.get("type"), axis, mimic))
    return out


def _default_package_dirs(urdf_path: str) -> list[str]:
    return [str(p) for p in Path(urdf_path).resolve().parents]


def checked_link_pairs(robot: Any, verifier: PathVerifier) -> list[tuple[str, str]]:
    """The URDF link pairs of the frame pairs jwarp checks for self-collision (frames with
    spheres, ``robot.allowed_collision_pairs``), each frame mapped to its link by
    :meth:`PathVerifier.link_of`: the pairs whose meshes must stay apart (check c)."""
    allowed = robot.allowed_collision_pairs
    frames = sorted({s.frame for s in robot.spheres})
    names = robot.frame_names
    out = set()
    for i, a in enumerate(frames):
        for b in frames[i + 1:]:
            if allowed[a, b]:
                la, lb = verifier.link_of(names[a]), verifier.link_of(names[b])
                if la and lb and la != lb:
                    out.add((min(la, lb), max(la, lb)))
    return sorted(out)


def robot_spheres(robot: Any) -> list[tuple[str, np.ndarray, float]]:
    """``[(frame name, centre (3,) in that frame [m], radius [m])]`` of a jwarp
    RobotModel's spheres (reads only ``sphere_arrays()`` and ``frame_names``)."""
    f, p, r = robot.sphere_arrays()
    names = robot.frame_names
    return [(names[int(fi)], np.asarray(pi, np.float64), float(ri)) for fi, pi, ri in zip(f, p, r)]


# ------------------------------------------------------------------ the verifier
class PathVerifier:
    """Exact path checker (module docstring).

    Args:
        urdf_path: the robot's URDF.
        package_dirs: folders searched for ``package://`` meshes (default: the URDF's
            ancestors).
        scene_shapes: jwarp scene shapes (``load_scene(...).shapes``), world = robot base.
        spheres: robot spheres ``[(frame name, centre, radius)]`` (:func:`robot_spheres`),
            or None to skip check (b).
        joint_names: the order of the path's columns (default: the URDF's actuated joints,
            non-fixed and non-mimic, in file order: jwarp's order).
        mesh_check: run check (a).
        self_pairs: URDF link-name pairs whose collision geometries are checked against
            each other (check c); None: no self check.
        self_margin: the least distance [m] of check (c).
    """

    def __init__(self, urdf_path: str | os.PathLike, package_dirs: Sequence[str] | None,
                 scene_shapes: Sequence[Any], *, spheres: Sequence[tuple] | None = None,
                 joint_names: Sequence[str] | None = None, mesh_check: bool = True,
                 self_pairs: Sequence[tuple[str, str]] | None = None,
                 self_margin: float = 0.0):
        self.urdf_path = str(urdf_path)
        dirs = list(package_dirs) if package_dirs else []
        dirs += _default_package_dirs(self.urdf_path)
        self.model = pin.buildModelFromUrdf(self.urdf_path)
        self.data = self.model.createData()
        self.geom_model = pin.buildGeomFromUrdf(self.model, self.urdf_path,
                                                pin.GeometryType.COLLISION, package_dirs=dirs)
        self.geom_data = pin.GeometryData(self.geom_model)
        self.mesh_check = mesh_check

        # ---- joints: path column order -> pinocchio q
        ujoints = {j.name: j for j in _read_joints(self.urdf_path)}
        actuated = [j.name for j in ujoints.values() if j.type != "fixed" and j.mimic is None]
        self.joint_names = list(joint_names) if joint_names is not None else actuated
        for n in self.joint_names:
            if n not in ujoints or ujoints[n].type == "fixed" or not self.model.existJointName(n):
                raise ValueError(f"joint_names: '{n}' is not a moving joint of {self.urdf_path}")
        self.prismatic = np.array([ujoints[n].type == "prismatic" for n in self.joint_names])
        col = {n: i for i, n in enumerate(self.joint_names)}

        def drive(name: str, seen: tuple = ()) -> tuple[int, float, float]:
            if name in col:
                return col[name], 1.0, 0.0
            j = ujoints[name]
            if j.mimic is None or name in seen:
                raise ValueError(f"joint '{name}' of the URDF is neither in joint_names nor a mimic")
            c, m0, o0 = drive(j.mimic[0], seen + (name,))
            return c, j.mimic[1] * m0, j.mimic[1] * o0 + j.mimic[2]

        self._qmap = []   # (idx_q, nq, column, multiplier, offset)
        for jid in range(1, self.model.njoints):
            name = self.model.names[jid]
            jm = self.model.joints[jid]
            c, m, o = drive(name)
            self._qmap.append((jm.idx_q, jm.nq, c, m, o))

        # ---- robot collision geometry (check a)
        self._robot = []   # (geometry, link name, local centre, radius, corners, trimesh|None)
        for go in self.geom_model.geometryObjects:
            g = go.geometry
            tm = None
            if isinstance(g, coal.BVHModelBase):
                import trimesh
                tm = trimesh.load(go.meshPath, force="mesh")
                tm.apply_scale(np.asarray(go.meshScale, np.float64))
                if not tm.is_watertight:
                    tm = None    # no inside to test
            mesh_for_bound = tm
            if mesh_for_bound is None and isinstance(g, coal.BVHModelBase):
                mesh_for_bound = _BoundMesh(g)
            c, r, corners = _local_bound(g, mesh_for_bound)
            link = self.model.frames[go.parentFrame].name
            # a point of the solid (a vertex of a mesh, the centre of a primitive)
            ref = np.asarray(mesh_for_bound.vertices[0], np.float64) if mesh_for_bound is not None else c
            self._robot.append((g, link, c, r, (corners, ref), tm))

        # ---- self pairs (check c): pairs of geometry indices of the listed link pairs
        self.self_margin = float(self_margin)
        self._self_pairs: list[tuple[int, int]] = []
        if self_pairs is not None:
            by_link: dict[str, list[int]] = {}
            for gi, part in enumerate(self._robot):
                by_link.setdefault(part[1], []).append(gi)
            for a, b in self_pairs:
                for name in (a, b):
                    if not self.model.existFrame(str(name)):
                        raise ValueError(f"self_pairs: '{name}' is not a link of {self.urdf_path}")
                self._self_pairs += [(i, j) for i in by_link.get(str(a), [])
                                     for j in by_link.get(str(b), [])]

        # ---- scene
        self._scene = []   # (geometry, pose, object_id, world centre, radius, world aabb, trimesh|None, ref)
        for s in scene_shapes:
            g, tm = coal_shape(s)
            T = np.asarray(s.pose, np.float64)
            c, r, corners = _local_bound(g, tm)
            ref = np.asarray(tm.vertices[0], np.float64) if tm is not None else np.zeros(3)
            self._scene.append((g, T, str(s.object_id), T[:3, :3] @ c + T[:3, 3], r,
                                _world_aabb(corners, T), tm, T[:3, :3] @ ref + T[:3, 3]))
        self._scene_c = np.array([x[3] for x in self._scene]).reshape(-1, 3)
        self._scene_r = np.array([x[4] for x in self._scene])
        self._scene_tf = [coal.Transform3s(x[1][:3, :3].copy(), x[1][:3, 3].copy()) for x in self._scene]

        # ---- robot spheres (check b)
        self._spheres = []
        if spheres is not None:
            for k, (fname, centre, radius) in enumerate(spheres):
                self._spheres.append((self._frame_fn(str(fname), ujoints),
                                      np.asarray(centre, np.float64), float(radius),
                                      f"{fname}#{k}", coal.Sphere(max(float(radius), 0.0))))

    # -------------------------------------------------------------- frames
    def link_of(self, name: str) -> str | None:
        """The URDF link a jwarp frame name belongs to (module docstring: a link is
        itself; a joint name, ``<joint>_axis`` and ``<joint>_origin`` are the joint's
        child link); None when the URDF has no such link or joint."""
        if not hasattr(self, "_joint_child"):
            root = ET.parse(self.urdf_path).getroot()
            self._joint_child = {j.get("name"): j.find("child").get("link")
                                 for j in root.findall("joint")}
            self._links = {ln.get("name") for ln in root.findall("link")}
        if name in self._links:
            return name
        for suffix in ("_axis", "_origin", ""):
            base = name[: len(name) - len(suffix)] if suffix and name.endswith(suffix) else name
            if (not suffix or name.endswith(suffix)) and base in self._joint_child:
                return self._joint_child[base]
        return None

    def _frame_fn(self, name: str, ujoints: dict) -> Any:
        """A function of the pinocchio data -> (4, 4) world placement of jwarp frame
        ``name`` (module docstring: links, joints, ``<joint>_axis``, ``<joint>_origin``)."""
        m = self.model
        for kind in (pin.BODY, pin.JOINT, pin.FIXED_JOINT):
            if m.existFrame(name, kind):
                fid = m.getFrameId(name, kind)
                return lambda d: d.oMf[fid].homogeneous
        base = name
        for suffix in ("_origin", "_axis"):
            if name.endswith(suffix):
                base = name[:-len(suffix)]
        if base != name and base in ujoints and ujoints[base].type != "fixed" \
                and m.existJointName(base):
            j = ujoints[base]
            R = np.eye(4)
            if not (np.all(np.abs(j.axis - [0, 0, 1]) <= 1e-12)
                    or np.all(np.abs(j.axis + [0, 0, 1]) <= 1e-12)):
                R[:3, :3] = _align_z(j.axis)
            jid = m.getJointId(base)
            if name.endswith("_axis"):
                return lambda d: d.oMi[jid].homogeneous @ R
            parent, place = m.parents[jid], m.jointPlacements[jid].homogeneous.copy()
            return lambda d: d.oMi[parent].homogeneous @ place @ R
        raise ValueError(f"sphere frame '{name}': neither a link nor a moving joint of "
                         f"{self.urdf_path}")

    def pin_q(self, q: Any) -> np.ndarray:
        """pinocchio's configuration vector of one row of joint values (path column order)."""
        q = np.asarray(q, np.float64)
        out = pin.neutral(self.model)
        for idx, nq, c, mult, off in self._qmap:
            v = mult * q[c] + off
            if nq == 2:     # continuous joint: (cos, sin)
                out[idx:idx + 2] = (math.cos(v), math.sin(v))
            else:
                out[idx] = v
        return out

    def frame_placements(self, q: Any, names: Sequence[str]) -> np.ndarray:
        """(len(names), 4, 4) world placements of jwarp frame names at one configuration."""
        ujoints = {j.name: j for j in _read_joints(self.urdf_path)}
        fns = [self._frame_fn(n, ujoints) for n in names]
        pin.framesForwardKinematics(self.model, self.data, self.pin_q(q))
        return np.array([f(self.data) for f in fns])

    def sphere_centres(self, q: Any) -> np.ndarray:
        """(n_spheres, 3) world centres of the robot spheres at one configuration."""
        pin.framesForwardKinematics(self.model, self.data, self.pin_q(q))
        out = [fn(self.data) for fn, *_ in self._spheres]
        return np.array([T[:3, :3] @ c + T[:3, 3] for T, (_, c, *_) in zip(out, self._spheres)]
                        ).reshape(-1, 3)

    # -------------------------------------------------------------- sampling
    def samples(self, path: Any, max_step_deg: float = 0.5, max_step_m: float = 0.002
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(configurations (K, n), interval (K,), fraction (K,)) of the linear
        interpolation of ``path`` (W, n): no revolute joint moves more than
        ``max_step_deg`` and no prismatic one more than ``max_step_m`` between samples;
        every waypoint is a sample."""
        P = np.asarray(path, np.float64)
        if P.ndim == 1:
            P = P[None]
        if P.ndim != 2 or P.shape[1] != len(self.joint_names):
            raise ValueError(f"path: expected (W, {len(self.joint_names)}) joint values "
                             f"({', '.join(self.joint_names)}), got {P.shape}")
        if not np.all(np.isfinite(P)):
            raise ValueError("path: contains NaN or inf")
        step = np.where(self.prismatic, max_step_m, math.radians(max_step_deg))
        qs, iv, fr = [], [], []
        for i in range(len(P) - 1):
            n = max(1, int(math.ceil(float(np.max(np.abs(P[i + 1] - P[i]) / step)) - 1e-9)))
            t = np.arange(n) / n
            qs.append(P[i] + t[:, None] * (P[i + 1] - P[i]))
            iv.append(np.full(n, i))
            fr.append(t)
        qs.append(P[-1:])
        iv.append(np.array([max(len(P) - 2, 0)]))
        fr.append(np.array([1.0 if len(P) > 1 else 0.0]))
        return np.concatenate(qs), np.concatenate(iv), np.concatenate(fr)

    # -------------------------------------------------------------- the check
    def check_path(self, path: Any, margin: float = 0.0, endpoint_margin: float | None = None,
                   max_step_deg: float = 0.5, max_step_m: float = 0.002) -> Verdict:
        """Check the linearly interpolated ``path`` (W, n) (module docstring)."""
        qs, iv, fr = self.samples(path, max_step_deg, max_step_m)
        end_m = margin if endpoint_margin is None else endpoint_margin
        thr = np.full(len(qs), float(margin))
        thr[0] = thr[-1] = end_m
        req = coal.DistanceRequest()
        res = coal.DistanceResult()
        best = {"mesh": None, "sphere": None, "self": None}
        first: Hit | None = None
        n_exact = 0
        S = len(self._scene)
        for k, q in enumerate(qs):
            pin.forwardKinematics(self.model, self.data, self.pin_q(q))
            pin.updateFramePlacements(self.model, self.data)
            t = float(thr[k])
            parts = []
            if self.mesh_check and S:
                pin.updateGeometryPlacements(self.model, self.data, self.geom_model, self.geom_data)
                for gi, (g, link, c, r, corners, tm) in enumerate(self._robot):
                    M = self.geom_data.oMg[gi]
                    parts.append(("mesh", g, link, M.rotation @ c + M.translation, r, M, corners, tm))
            if self._spheres and S:
                for fn, centre, radius, label, sph in self._spheres:
                    T = fn(self.data)
                    w = T[:3, :3] @ centre + T[:3, 3]
                    parts.append(("sphere", sph, label, w, radius, w, None, None))
            if self._self_pairs:
                if not (self.mesh_check and S):
                    pin.updateGeometryPlacements(self.model, self.data, self.geom_model,
                                                 self.geom_data)
                n_exact, first = self._self_check(k, iv, fr, best, first, req, res, n_exact)
            for check, g, label, wc, r, M, corners, tm in parts:
                lb = np.linalg.norm(self._scene_c - wc, axis=1) - self._scene_r - r
                cur = best[check].distance if best[check] is not None else np.inf
                need = max(cur, t)
                for si in np.nonzero(lb < need)[0]:
                    sg, ST, oid, _, _, saabb, stm, sref = self._scene[si]
                    if check == "mesh":
                        tf = coal.Transform3s(M.rotation, M.translation)
                    else:
                        tf = coal.Transform3s(np.eye(3), M)
                    res.clear()
                    d = float(coal.distance(g, tf, sg, self._scene_tf[si], req, res))
                    n_exact += 1
                    if d > 0:
                        d = self._containment(d, check, M, corners, tm, wc, r, ST, saabb, stm, sref)
                    if d < cur:
                        cur = d
                        best[check] = Hit(d, int(iv[k]), float(fr[k]), label, oid, check, t)
                    if d < t and first is None:
                        first = Hit(d, int(iv[k]), float(fr[k]), label, oid, check, t)
                    need = max(cur, t)
        hits = [h for c, h in best.items() if h is not None and c != "self"]
        closest = min(hits, key=lambda h: h.distance) if hits else None
        return Verdict(ok=first is None,
                       min_distance=closest.distance if closest else math.inf,
                       closest=closest, mesh=best["mesh"] if self.mesh_check else None,
                       sphere=best["sphere"] if self._spheres else None,
                       first_violation=first, n_samples=len(qs), n_exact=n_exact,
                       self_mesh=best["self"])

    def _self_check(self, k: int, iv: np.ndarray, fr: np.ndarray, best: dict,
                    first: Hit | None, req: Any, res: Any, n_exact: int
                    ) -> tuple[int, Hit | None]:
        """Check (c) at sample ``k`` (geometry placements already updated)."""
        t = self.self_margin
        cur = best["self"].distance if best["self"] is not None else np.inf
        for i, j in self._self_pairs:
            gi, li, ci, ri = self._robot[i][:4]
            gj, lj, cj, rj = self._robot[j][:4]
            Mi, Mj = self.geom_data.oMg[i], self.geom_data.oMg[j]
            lb = float(np.linalg.norm(Mi.rotation @ ci + Mi.translation
                                      - (Mj.rotation @ cj + Mj.translation))) - ri - rj
            if lb >= max(cur, t):
                continue
            res.clear()
            Ti = coal.Transform3s(Mi.rotation, Mi.translation)
            Tj = coal.Transform3s(Mj.rotation, Mj.translation)
            d = float(coal.distance(gi, Ti, gj, Tj, req, res))
            n_exact += 1
            if d <= 0.0:
                # coal's distance of two meshes stops at 0 when they intersect: the
                # collision query gives the contacts' penetration depth (or an intersection
                # without one: counted as a contact 1 nm deep)
                creq = coal.CollisionRequest()
                creq.enable_contact = True
                creq.num_max_contacts = 64
                cres = coal.CollisionResult()
                if coal.collide(gi, Ti, gj, Tj, creq, cres):
                    depth = max((abs(float(c.penetration_depth)) for c in cres.getContacts()),
                                default=0.0)
                    d = -max(depth, 1e-9)
            if d < cur:
                cur = d
                best["self"] = Hit(d, int(iv[k]), float(fr[k]), li, lj, "self", t)
            if d < t and first is None:
                first = Hit(d, int(iv[k]), float(fr[k]), li, lj, "self", t)
        return n_exact, first

    def _containment(self, d: float, check: str, M: Any, bound: Any, tm: Any,
                     wc: np.ndarray, r: float, ST: np.ndarray, saabb: np.ndarray,
                     stm: Any, sref: np.ndarray) -> float:
        """``-d`` (penetrating at least that deep) when one part lies wholly inside the
        other's closed mesh without any surface crossing (coal's mesh distances see
        surfaces only, so they report the positive gap ``d`` to the enclosing surface);
        else ``d``. A reference point of the inner solid decides it, only when the inner
        part's world bounding box lies inside the outer one's."""
        if check == "mesh":
            corners, ref = bound
            T = M.homogeneous
            aabb = _world_aabb(corners, T)
            if tm is not None and _inside(saabb, aabb) and _contains(tm, T, sref):
                return -d
            if (stm is not None and _inside(aabb, saabb)
                    and _contains(stm, ST, T[:3, :3] @ ref + T[:3, 3])):
                return -d
        elif stm is not None:
            aabb = np.stack([wc - r, wc + r])
            if _inside(aabb, saabb) and _contains(stm, ST, wc):
                return -d
        return d

    def check_configurations(self, q: Any, margin: float = 0.0) -> np.ndarray:
        """(N,) bool: each configuration (N, n) passes both checks with ``margin``."""
        Q = np.atleast_2d(np.asarray(q, np.float64))
        return np.array([self.check_path(row[None], margin).ok for row in Q])


class _BoundMesh:
    """Vertices of a coal BVH (for its bounds when its file is not a closed mesh)."""

    def __init__(self, bvh: Any):
        v = bvh.vertices
        self.vertices = np.asarray(v() if callable(v) else v, np.float64).reshape(-1, 3)
