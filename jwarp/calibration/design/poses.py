"""Measurement-pose sampling (thesis 2.4.3, Fig. 2.9; elastic paper IV-C).

Rejection sampling of configurations under a measurement setup's constraints, evaluated in
batches by Warp kernels (:mod:`jwarp.kernels.visibility`) on the CPU or a CUDA device:

* joint limits (box and linear, the box optionally shrunk by ``joint_margin``),
* self-collision of the robot's sphere model with a safety ``margin`` [m],
* markers seen by tracker cameras (the setup's ``cameras``): in range, inside the view
  cone, facing the camera within ``max_angle`` and not occluded by the robot's spheres,
  for at least ``k_of_n`` cameras; at least one marker (``require="any"``) or all of them;
  with ``single_marker`` no second marker visible to any camera,
* contact setups: configurations on the contact manifold of the nominal model from a
  contact search passed as ``draw`` (:func:`jwarp.calibration.simulate.scenarios.contact_sampler`),
  then limits and self-collision with the contact bodies' own frame pairs left out.

Camera entries (file-level ``cameras`` list of a setup file, docs/pose_sampling.md)::

    {"name": "c1", "pose": {"position": [x, y, z], "rotvec": [rx, ry, rz]}
                   | {"position": [...], "look_at": [x, y, z]},
     "fov": 60.0, "range": [0.5, 6.0]}

position [m] in the robot's base frame, optical axis = the camera's z axis, ``fov`` the
full opening angle of the view cone [deg] in (0, 180), ``range`` [near, far] [m].
Marker normals: file-level ``marker_normals`` ``{marker: [x, y, z]}`` in the marker's frame
(default: the frame's z axis; the base frame's z for fixed markers).

:func:`write_plan` writes the (ordered, :mod:`jwarp.calibration.design.tour`) plan as CSV.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import warp as wp

from jwarp.calibration.files import Setup, make_measurement
from jwarp.core.arrays import init_warp, resolve_device
from jwarp.core.device import make_struct, put_model, scalar_type
from jwarp.core.types import ArrayLike, DTypeLike, RobotLike
from jwarp.kernels import path as path_kernels
from jwarp.kernels import visibility as vk
from jwarp.model import RobotModel
from jwarp.model.geometry import parse_markers, rotvec_matrix
from jwarp.plugins.registry import robot as get_robot
from jwarp.utils.atomic import atomic_write_text
from jwarp.utils.checks import check_int

__all__ = ["Camera", "PoseOptions", "PoseSampler", "PoseSample", "CODE_NAMES", "parse_cameras",
           "marker_table", "sample_poses", "plan_text", "write_plan"]

#: names of the verdict codes of :mod:`jwarp.kernels.visibility`
CODE_NAMES = ("ok", "limits", "not_seen", "many_markers", "self_collision")
#: a sphere whose centre is closer than radius + this to a marker holds it [m]
CONTAIN_TOL = 1e-4


@dataclass(frozen=True)
class Camera:
    """A fixed tracker camera: ``position`` (3,) [m] in the base frame, ``axis`` (3,) unit
    optical axis, ``fov`` full cone angle [deg], ``near``/``far`` [m]."""

    name: str
    position: np.ndarray
    axis: np.ndarray
    fov: float
    near: float
    far: float


def _vec3(x: ArrayLike, where: str) -> np.ndarray:
    try:
        a = np.asarray(x, np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{where}: expected 3 numbers, got {x!r}") from None
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise ValueError(f"{where}: expected 3 finite numbers, got {x!r}")
    return a


def parse_cameras(cameras: Any, where: str = "cameras") -> list[Camera]:
    """Check a setup's ``cameras`` list (module docstring) and return :class:`Camera` s.

    Raises:
        ValueError: naming the key, e.g. ``cameras[2].pose: missing`` or
            ``cameras[0].fov: expected an angle in (0, 180) deg``.
    """
    if not isinstance(cameras, list) or not cameras:
        raise ValueError(f"{where}: expected a non-empty list of cameras, got {cameras!r}")
    out: list[Camera] = []
    for i, c in enumerate(cameras):
        w = f"{where}[{i}]"
        if not isinstance(c, dict):
            raise ValueError(f"{w}: expected an object, got {c!r}")
        extra = sorted(set(c) - {"name", "pose", "fov", "range"})
        if extra:
            raise ValueError(f"{w}: unknown key(s) {extra}; allowed: fov, name, pose, range")
        name = str(c.get("name", f"camera{i + 1}"))
        pose = c.get("pose")
        if pose is None:
            raise ValueError(f"{w}.pose: missing; give {{\"position\": [x, y, z], \"rotvec\": "
                             f"[..]}} or {{\"position\": .., \"look_at\": [x, y, z]}}")
        if not isinstance(pose, dict):
            raise ValueError(f"{w}.pose: expected an object, got {pose!r}")
        extra = sorted(set(pose) - {"position", "rotvec", "look_at"})
        if extra:
            raise ValueError(f"{w}.pose: unknown key(s) {extra}; allowed: look_at, position, "
                             f"rotvec")
        if "position" not in pose:
            raise ValueError(f"{w}.pose.position: missing")
        pos = _vec3(pose["position"], f"{w}.pose.position")
        if ("rotvec" in pose) == ("look_at" in pose):
            raise ValueError(f"{w}.pose: give exactly one of rotvec, look_at")
        if "rotvec" in pose:
            axis = rotvec_matrix(_vec3(pose["rotvec"], f"{w}.pose.rotvec"))[:, 2]
        else:
            d = _vec3(pose["look_at"], f"{w}.pose.look_at") - pos
            if np.linalg.norm(d) < 1e-9:
                raise ValueError(f"{w}.pose.look_at: equals the position")
            axis = d
        fov = c.get("fov")
        if isinstance(fov, bool) or not isinstance(fov, (int, float)) \
                or not (0.0 < float(fov) < 180.0):
            raise ValueError(f"{w}.fov: expected an angle in (0, 180) deg, got {fov!r}")
        rng = c.get("range", [0.0, math.inf])
        if not isinstance(rng, (list, tuple)) or len(rng) != 2 \
                or any(isinstance(v, bool) or not isinstance(v, (int, float)) for v in rng) \
                or not (0.0 <= float(rng[0]) < float(rng[1])):
            raise ValueError(f"{w}.range: expected [near, far] with 0 <= near < far [m], "
                             f"got {rng!r}")
        out.append(Camera(name=name, position=pos, axis=axis / np.linalg.norm(axis),
                          fov=float(fov), near=float(rng[0]), far=float(rng[1])))
    return out


def marker_table(robot: RobotModel, setup: Setup) -> tuple[list[str], np.ndarray, np.ndarray,
                                                           np.ndarray]:
    """The setup's markers as (names, frame (M,) int (-1: fixed), position (M, 3) [m],
    unit normal (M, 3)) in their frame's coordinates (normals: ``marker_normals`` or z)."""
    names, frames, (_, nominal, _, _) = parse_markers(
        setup.section, robot, default_sigma=1.0, frame_optional=True, position_required=False)
    pos = np.asarray(nominal, np.float64).reshape(-1, 3)
    normal = np.tile([0.0, 0.0, 1.0], (len(names), 1))
    given = setup.marker_normals or {}
    if not isinstance(given, dict):
        raise ValueError(f"marker_normals: expected an object {{marker: [x, y, z]}}, got {given!r}")
    for k, v in given.items():
        if k not in names:
            raise ValueError(f"marker_normals.{k}: unknown marker; markers: {', '.join(names)}")
        n = _vec3(v, f"marker_normals.{k}")
        if np.linalg.norm(n) < 1e-9:
            raise ValueError(f"marker_normals.{k}: zero vector")
        normal[names.index(k)] = n / np.linalg.norm(n)
    fr = np.array([-1 if f is None else int(f) for f in frames], np.int64)
    return names, fr, pos, normal


@dataclass
class PoseOptions:
    """Options of :class:`PoseSampler`.

    margin: self-collision safety margin [m] between sphere surfaces (>= 0).
    joint_margin: distance kept from the box joint limits [rad or m] (>= 0).
    k_of_n: cameras that must see a marker (1 .. number of cameras).
    max_angle: largest angle between marker normal and the ray to the camera [deg] in
        (0, 180]; None: no facing test.
    single_marker: reject configurations where a second marker is visible to any camera.
    require: "any" (at least one marker seen) or "all" (every marker seen).
    self_collision: check self-collision (False: only limits and visibility).
    batch_size: candidates per kernel launch (CPU ~1e5, CUDA ~1e7).
    max_tries: candidates drawn at most before giving up.
    seed: random seed; device: Warp device ("cpu", "cuda", "cuda:0"; None: Warp's default
    device, docs/api.md "Devices"); dtype: float32/float64.
    """

    margin: float = 0.02
    joint_margin: float = 0.0
    k_of_n: int = 1
    max_angle: float | None = 60.0
    single_marker: bool = False
    require: str = "any"
    self_collision: bool = True
    batch_size: int = 1 << 16
    max_tries: int = 50_000_000
    seed: int = 0
    device: str | None = None
    dtype: str = "float32"

    def validate(self) -> PoseOptions:
        """Check every field; ValueError/TypeError naming the field. Returns self."""
        def real(name: str, lo: float, hi: float = math.inf, lo_open: bool = False) -> None:
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer)):
                raise TypeError(f"{name}: expected a number, got {v!r}")
            if not math.isfinite(float(v)) or float(v) < lo or (lo_open and float(v) == lo) \
                    or float(v) > hi:
                raise ValueError(f"{name}: expected a finite value in {'(' if lo_open else '['}"
                                 f"{lo:g}, {hi:g}], got {v!r}")

        def integer(name: str, lo: int) -> None:
            v = getattr(self, name)
            check_int(v, name, lo)

        real("margin", 0.0, 1.0)
        real("joint_margin", 0.0, math.pi)
        integer("k_of_n", 1)
        if self.max_angle is not None:
            real("max_angle", 0.0, 180.0, lo_open=True)
        if self.require not in ("any", "all"):
            raise ValueError(f"require: expected 'any' or 'all', got {self.require!r}")
        integer("batch_size", 1)
        integer("max_tries", 1)
        integer("seed", 0)
        if self.dtype not in ("float32", "float64"):
            raise ValueError(f"dtype: expected 'float32' or 'float64', got {self.dtype!r}")
        for name in ("single_marker", "self_collision"):
            if not isinstance(getattr(self, name), bool):
                raise TypeError(f"{name}: expected True or False, got {getattr(self, name)!r}")
        return self


@dataclass
class PoseSample:
    """Sampled measurement poses: ``q`` (n, n_dof) in draw order, ``meta`` per-sample
    columns (contact: ``pair``), ``tried`` candidates drawn, ``counts`` {verdict: candidates}
    (:data:`CODE_NAMES`; for contact setups the candidates of the contact search)."""

    q: np.ndarray
    meta: dict[str, np.ndarray] = field(default_factory=dict)
    tried: int = 0
    counts: dict[str, int] = field(default_factory=dict)

    @property
    def acceptance(self) -> float:
        """Accepted / tried candidates."""
        return float(self.counts.get("ok", 0)) / max(self.tried, 1)


def _scratch(device: wp.Device, n: int, m: int, dtype: DTypeLike) -> tuple[wp.array, Any]:
    """(n, m) per-thread scratch: CUDA frame-major (coalesced), CPU one row seen by every
    thread through a stride-0 view (Warp's CPU launch runs the threads in turn)."""
    if device.is_cuda:
        return wp.empty((m, n), dtype=dtype, device=device).transpose(), None
    row = wp.empty((1, m), dtype=dtype, device=device)
    return wp.array(ptr=row.ptr, shape=(n, m), strides=(0, row.strides[1]), dtype=dtype,
                    device=device), row


class PoseSampler:
    """Rejection sampler of measurement poses for one robot and setup (module docstring).

    Args:
        robot: the nominal robot (planning happens before calibration).
        setup: the measurement setup (its ``cameras`` switch the visibility checks on;
            contact setups search the contact manifold), or None: limits and self-collision.
        options: :class:`PoseOptions` (validated here).
        draw: ``(rng, k) -> (q (<=k, n_dof), meta)`` candidates for setups that are not
            drawn uniformly in the limits; contact setups need one, e.g.
            :func:`~jwarp.calibration.simulate.scenarios.contact_sampler` (the contact
            search), whose candidates :meth:`sample` then checks.

    Raises:
        ValueError: bad options or setup (naming the key), ``k_of_n`` above the number of
            cameras, ``single_marker`` / ``require`` without cameras.
    """

    def __init__(self, robot: RobotLike, setup: Setup | None = None,
                 options: PoseOptions | None = None, draw: Any = None) -> None:
        init_warp()
        self.robot = robot = get_robot(robot)  # the edge: a name, path or RobotModel
        self.draw = draw
        self.setup = setup
        self.options = opt = (options or PoseOptions()).validate()
        self.device = resolve_device(opt.device)
        self.scalar = scalar_type(np.float32 if opt.dtype == "float32" else np.float64)
        self.np_dtype = np.float32 if opt.dtype == "float32" else np.float64
        self.k = vk.kernels(self.scalar)
        self.model = put_model(robot, self.device, self.scalar)
        self.cameras = parse_cameras(setup.cameras) if setup is not None and setup.cameras \
            else []
        self.contact = setup is not None and setup.plugin == "contact"
        if self.cameras and setup is not None and "markers" in setup.section:
            self.marker_names, mk_frame, mk_pos, mk_normal = marker_table(robot, setup)
        elif self.cameras:
            raise ValueError(f"setup: cameras given but the '{setup.plugin}' setup has no markers")
        else:
            self.marker_names, mk_frame = [], np.zeros(0, np.int64)
            mk_pos = mk_normal = np.zeros((0, 3))
        if self.cameras and opt.k_of_n > len(self.cameras):
            raise ValueError(f"k_of_n: {opt.k_of_n} cameras asked, the setup has "
                             f"{len(self.cameras)}")
        if not self.cameras and opt.single_marker:
            raise ValueError("single_marker: needs tracker cameras in the setup (cameras)")
        self.mk_frame, self.mk_pos, self.mk_normal = mk_frame, mk_pos, mk_normal
        self._build_tables(robot)

    # ---------------------------------------------------------------- tables
    def _build_tables(self, robot: RobotModel) -> None:
        opt, dev, sc, dt = self.options, self.device, self.scalar, self.np_dtype
        vec3 = self.k.vec3
        s = self.k.Sensors()
        cams = self.cameras

        def v3(a: np.ndarray | list) -> wp.array:
            a = np.asarray(a, dt).reshape(-1, 3)
            return wp.array(a if len(a) else np.zeros((1, 3), dt), dtype=vec3, device=dev)

        def sa(a: Any, kind: Any = None) -> wp.array:
            a = np.asarray(a, dt if kind is None else np.int32).reshape(-1)
            return wp.array(a if len(a) else np.zeros(1, a.dtype), dtype=kind or sc, device=dev)

        s.cam_pos = v3([c.position for c in cams])
        s.cam_axis = v3([c.axis for c in cams])
        s.cam_cos_fov = sa([math.cos(math.radians(c.fov) / 2) for c in cams])
        s.cam_near = sa([c.near for c in cams])
        s.cam_far = sa([min(c.far, 1e30) for c in cams])
        s.mk_frame = sa(self.mk_frame, wp.int32)
        s.mk_pos = v3(self.mk_pos)
        s.mk_normal = v3(self.mk_normal)
        sph_frame = np.asarray(robot.sphere_arrays()[0], np.int64)
        order = np.argsort(sph_frame, kind="stable")
        start = np.searchsorted(sph_frame[order], np.arange(robot.n_frames + 1))
        s.fs_start = sa(start, wp.int32)
        s.fs_sphere = sa(order, wp.int32)
        self.sensors = s
        c = self.k.Checks()
        c.n_cameras = len(cams)
        c.n_markers = len(self.marker_names) if cams else 0
        c.k_of_n = int(opt.k_of_n)
        c.cos_max_angle = sc(-2.0 if opt.max_angle is None else math.cos(math.radians(
            opt.max_angle)))
        c.need_all = int(opt.require == "all")
        c.single_marker = int(opt.single_marker)
        c.check_self = int(opt.self_collision and self.model.spheres.n_pairs > 0)
        c.margin = sc(opt.margin)
        c.contain_tol = sc(CONTAIN_TOL)
        self.checks = c
        skip = self._skip_frame_pairs()
        self.skip_fpair: wp.array = wp.array(skip, dtype=wp.int32, device=dev)
        lim = np.asarray(robot.joint_limits, np.float64)
        jm = opt.joint_margin
        lo, hi = lim[:, 0] + jm, lim[:, 1] - jm
        if np.any(lo > hi):
            raise ValueError(f"joint_margin: {jm} is more than half the range of joint "
                             f"'{robot.joint_names[int(np.argmax(lo > hi))]}'")
        self.lower, self.upper = lo, hi
        box = np.stack([lo, hi], axis=1)
        #: the robot's limits with the box narrowed by the joint margin (one struct)
        self.limits = make_struct(path_kernels.funcs(sc).LimitTables, self.model.limits,
                                  box=wp.array(box.astype(dt), dtype=sc, device=dev))
        self.lower_w: wp.array = wp.array(lo.astype(dt), dtype=sc, device=dev)
        self.upper_w: wp.array = wp.array(hi.astype(dt), dtype=sc, device=dev)

    def _skip_frame_pairs(self) -> np.ndarray:
        """(P_f,) int32 flags of the frame pairs left out of the self-collision check:
        for contact setups the pairs between the contact bodies' frames."""
        sp = self.model.spheres
        fa = sp.fpair_a.numpy()[:max(len(sp.fpair_a), 1)]
        fb = sp.fpair_b.numpy()[:max(len(sp.fpair_b), 1)]
        skip = np.zeros(max(len(fa), 1), np.int32)
        if self.contact:
            frames = set(self._contact_frames())
            for i in range(len(fa)):
                if int(fa[i]) in frames and int(fb[i]) in frames:
                    skip[i] = 1
        return skip

    def _contact_frames(self) -> list[int]:
        """Robot frames carrying the contact setup's bodies."""
        meas = make_measurement(self.robot, self.setup)
        return [int(b.frame) for b in meas.bodies.values() if b.frame is not None]

    def _model_args(self) -> list:
        return [self.model.frame_struct, self.model.spheres.struct, self.limits,
                self.sensors, self.skip_fpair, self.model.dh0_3d]

    # ---------------------------------------------------------------- checks
    def check(self, q: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Verdicts of given configurations.

        Args:
            q: (N, n_dof) joint values [rad or m].

        Returns:
            (code (N,) int32, :data:`CODE_NAMES` index; seen (N, M) int32: cameras that see
            each marker, 0 for rows outside the limits).
        """
        q = np.asarray(q, np.float64)
        if q.ndim != 2 or q.shape[1] != self.robot.n_dof:
            raise ValueError(f"q: expected shape (N, {self.robot.n_dof}), got {q.shape}")
        if not np.all(np.isfinite(q)):
            raise ValueError("q: contains NaN or inf")
        n = len(q)
        m = max(len(self.marker_names) if self.cameras else 0, 1)
        if n == 0:
            return np.zeros(0, np.int32), np.zeros((0, m - (0 if self.cameras else 1)), np.int32)
        dev = self.device
        qw: wp.array = wp.array(q.astype(self.np_dtype), dtype=self.scalar, device=dev)
        frames, _r1 = _scratch(dev, n, self.robot.n_frames, self.k.mat44)
        xs, _r2 = _scratch(dev, n, max(self.model.spheres.n_spheres, 1), self.k.vec3)
        code = wp.empty(n, dtype=wp.int32, device=dev)
        seen = wp.zeros((n, m), dtype=wp.int32, device=dev)
        wp.launch(self.k.check, dim=n, inputs=[*self._model_args(), qw, self.checks, frames, xs],
                  outputs=[code, seen], device=dev)
        seen_np = seen.numpy()
        return code.numpy(), (seen_np if self.cameras else seen_np[:, :0])

    def ok(self, q: ArrayLike) -> np.ndarray:
        """(N,) bool: configurations that pass every check."""
        return self.check(q)[0] == 0

    # -------------------------------------------------------------- sampling
    def sample(self, n: int, progress: bool = False) -> PoseSample:
        """``n`` accepted configurations (module docstring), drawn uniformly inside the
        (shrunk) box limits on the device in batches of ``batch_size``.

        Raises:
            ValueError: fewer than n accepted within ``max_tries`` candidates (the message
                gives the verdict counts, to tell which constraint rejects).
        """
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
            raise ValueError(f"n: expected a number of poses >= 1, got {n!r}")
        if self.draw is not None:
            return self._sample_drawn(int(n))
        if self.contact:
            raise ValueError("draw: contact setups need a contact search as draw (e.g. "
                             "jwarp.calibration.simulate.scenarios.contact_sampler(robot, setup))")
        opt = self.options
        got_q: list[np.ndarray] = []
        have, tried = 0, 0
        ss = np.random.SeedSequence(opt.seed)
        bar = None
        if progress:
            from tqdm import tqdm
            bar = tqdm(total=n, desc="sample-poses", unit="pose")
        total_counts = np.zeros(vk.N_CODES, np.int64)
        try:
            while have < n and tried < opt.max_tries:
                k = int(min(opt.batch_size, opt.max_tries - tried))
                seed = int(ss.spawn(1)[0].generate_state(1, np.uint32)[0] & 0x7FFFFFFF)
                qq, counts = self.run_batch(k, seed, capacity=n - have)
                total_counts += counts
                tried += k
                if len(qq):
                    got_q.append(qq)
                    have += len(qq)
                    if bar is not None:
                        bar.update(len(qq))
        finally:
            if bar is not None:
                bar.close()
        counts_d = {nm: int(total_counts[i]) for i, nm in enumerate(CODE_NAMES)}
        if have < n:
            raise ValueError(f"n: only {have} of {n} poses accepted in {tried} candidates "
                             f"({_fmt_counts(counts_d)}); relax the constraints (--margin, "
                             f"--k-of-n, --max-angle, cameras) or raise max_tries")
        return PoseSample(q=np.concatenate(got_q)[:n], tried=tried, counts=counts_d)

    def run_batch(self, k: int, seed: int, capacity: int | None = None
                  ) -> tuple[np.ndarray, np.ndarray]:
        """One launch: ``k`` candidates drawn uniformly in the (shrunk) box limits by
        Warp's RNG (stream ``seed``), checked on the device.

        Returns:
            (the accepted configurations (<= capacity, n_dof) float64 in candidate order,
            verdict counts (N_CODES,) int64 of all k candidates). Buffers are kept for
            the next call of the same size. Accepted candidates beyond ``capacity``
            are dropped; on CUDA which ones is not reproducible (threads take the output
            slots in any order), on the CPU the first ones are kept.
        """
        dev, nd = self.device, self.robot.n_dof
        cap = max(int(k if capacity is None else min(capacity, k)), 1)
        ws: dict[str, Any] | None = getattr(self, "_ws", None)
        if ws is None or ws["k"] < k or ws["cap"] < cap:
            ws = {"k": int(k), "cap": cap, "rows": []}
            self._ws = ws
            for name, m, dt in (("qbuf", nd, self.scalar), ("frames", self.robot.n_frames,
                                                           self.k.mat44),
                                ("xs", max(self.model.spheres.n_spheres, 1), self.k.vec3)):
                ws[name], row = _scratch(dev, int(k), m, dt)
                ws["rows"].append(row)
            ws["dummy"] = wp.zeros((1, 1), dtype=wp.int32, device=dev)
            ws["out_q"] = wp.empty((cap, nd), dtype=self.scalar, device=dev)
            ws["out_idx"] = wp.empty(cap, dtype=wp.int32, device=dev)
            ws["count"] = wp.zeros(1, dtype=wp.int32, device=dev)
            ws["counts"] = wp.zeros((vk.COUNT_ROWS, vk.N_CODES), dtype=wp.int32, device=dev)
        ws["count"].zero_()
        ws["counts"].zero_()
        out_q = ws["out_q"][:cap]
        wp.launch(self.k.sample, dim=int(k),
                  inputs=[*self._model_args(), int(seed), self.lower_w, self.upper_w,
                          self.checks, ws["qbuf"], ws["frames"], ws["xs"], ws["dummy"]],
                  outputs=[ws["count"], out_q, ws["out_idx"], ws["counts"]], device=dev)
        c = int(ws["count"].numpy()[0])
        counts = ws["counts"].numpy().sum(axis=0).astype(np.int64)
        if c == 0:
            return np.zeros((0, nd)), counts
        m = min(c, cap)
        idx = ws["out_idx"].numpy()[:m]
        qq = out_q.numpy()[:m].astype(np.float64)
        return qq[np.argsort(idx, kind="stable")], counts

    def _sample_drawn(self, n: int) -> PoseSample:
        """Candidates of ``draw`` (contact: on the contact manifold of the nominal model),
        checked for limits, visibility and self-collision (contact bodies' frame pairs
        left out)."""
        opt = self.options
        rng = np.random.default_rng(opt.seed)
        qs, metas = [], []
        have, tried = 0, 0
        total = np.zeros(vk.N_CODES, np.int64)
        while have < n and tried < opt.max_tries:
            q, meta = self.draw(rng, max(n - have, 8))
            tried += len(q)
            if len(q) == 0:
                continue
            code, _ = self.check(q)
            total += np.bincount(code, minlength=vk.N_CODES)
            ok = code == 0
            qs.append(q[ok])
            metas.append({k: np.asarray(v)[ok] for k, v in meta.items()})
            have += int(ok.sum())
        counts_d = {nm: int(total[i]) for i, nm in enumerate(CODE_NAMES)}
        if have < n:
            raise ValueError(f"n: only {have} of {n} poses accepted in {tried} drawn "
                             f"candidates ({_fmt_counts(counts_d)})")
        meta = {k: np.concatenate([m[k] for m in metas])[:n] for k in metas[0]} if metas else {}
        return PoseSample(q=np.concatenate(qs)[:n], meta=meta, tried=tried, counts=counts_d)


def _fmt_counts(counts: dict[str, int]) -> str:
    return ", ".join(f"{k} {v}" for k, v in counts.items())


def sample_poses(robot: RobotModel, setup: Setup | None, n: int,
                 options: PoseOptions | None = None, progress: bool = False,
                 draw: Any = None) -> PoseSample:
    """``PoseSampler(robot, setup, options, draw).sample(n)``."""
    return PoseSampler(robot, setup, options, draw).sample(n, progress=progress)


def plan_text(robot: RobotModel, q: np.ndarray, meta: dict[str, np.ndarray] | None = None
              ) -> str:
    """CSV text of a measurement plan: one row per pose in execution order, the robot's
    joint columns (as in a samples file, rad or m, 17 significant digits) then the meta
    columns (contact: ``pair``)."""
    q = np.asarray(q, np.float64)
    if q.ndim != 2 or q.shape[1] != robot.n_dof:
        raise ValueError(f"q: expected shape (N, {robot.n_dof}), got {q.shape}")
    meta = meta or {}
    header = list(robot.joint_names) + list(meta)
    lines = [",".join(header)]
    cols = [np.asarray(v) for v in meta.values()]
    for i in range(len(q)):
        row = [repr(float(v)) for v in q[i]] + [str(int(c[i])) for c in cols]
        lines.append(",".join(row))
    return "\n".join(lines) + "\n"


def write_plan(path: str, robot: RobotModel, q: np.ndarray,
               meta: dict[str, np.ndarray] | None = None) -> None:
    """Write :func:`plan_text` to ``path`` atomically."""
    atomic_write_text(path, plan_text(robot, q, meta))
