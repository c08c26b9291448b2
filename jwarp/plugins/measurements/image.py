"""Image measurement (thesis eq. 2.40-2.41): pixels of markers seen by a pinhole camera.

``u = c + f * D(P(x_c), xi)`` with ``x_c = inv(T_cam) x_w`` the marker in camera
coordinates (z along the optical axis), ``P(x) = (x_x / x_z, x_y / x_z)`` and the radial
distortion ``D(n, xi) = n / (1 + xi |n|^2)``; ``f = (fx, fy)``, ``c = (cx, cy)`` [px].
The camera pose is ``T_cam = T_F(q) . T_mount`` for a camera on robot frame ``F``
(closed loop, e.g. justin19's ``head_tcp``) or ``T_mount`` in the base frame for a fixed
camera (``"frame": null``). Markers sit on robot frames or on a fixed pole (``"frame":
null`` = base frame). Observations per sample: ``<marker>_u, _v`` [px].

Setup section (JSON)::

    {"plugin": "image",
     "camera": {"frame": "head_tcp", "position": [x, y, z], "rotvec": [rx, ry, rz],
                "sigma_position": 0.05, "sigma_rotation": 0.2},
     "intrinsics": {"focal": [fx, fy], "center": [cx, cy], "xi": 0.0,
                    "sigma_focal": 10.0, "sigma_center": 10.0, "sigma_xi": 0.1,
                    "size": [width, height]},
     "markers": [{"name": "right", "frame": "right_tcp", "position": [0, 0, 0.05],
                  "sigma": 0.02}, {"name": "pole", "frame": null, "position": [...]}],
     "noise": 1.0}

Parameters: ``camera_px, _py, _pz, _rx, _ry, _rz`` (group ``camera``: the mount pose in
frame ``F`` or in the base), ``marker_<name>_x, _y, _z`` (group ``markers``), then
``intrinsics_fx, _fy, _cx, _cy, _xi`` (group ``intrinsics``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from jwarp.model import RobotModel
from jwarp.model import geometry as g
from jwarp.model.measurement import Measurement, ParamBlock
from jwarp.plugins.registry import hookimpl

INTRINSIC_NAMES = ("fx", "fy", "cx", "cy", "xi")


class ImageMeasurement(Measurement):
    """Marker pixels [px] through a pinhole camera with radial distortion (eq. 2.40-2.41)."""

    name = "image"
    unit = "px"
    DEFAULT_NOISE = 1.0                 # px
    DEFAULT_CAMERA_SIGMA = (0.05, 0.2)  # m, rad
    DEFAULT_MARKER_SIGMA = 0.02         # m
    DEFAULT_INTRINSIC_SIGMA = {"focal": 10.0, "center": 10.0, "xi": 0.1}  # px, px, 1

    def __init__(self, robot: RobotModel, setup: dict) -> None:
        super().__init__(robot, setup)
        g.check_keys(setup, {"plugin", "camera", "intrinsics", "markers", "noise"}, "setup")
        cam = g.section(setup, "camera", "setup")
        g.check_keys(cam, {"frame", "position", "rotvec", "sigma_position", "sigma_rotation"},
                     "setup.camera")
        cf = g.section(cam, "frame", "setup.camera")
        self.camera_frame: int | None = (None if cf is None else
                                         g.robot_frame(robot, cf, "setup.camera.frame"))
        pos, rv, sp, sr = g.parse_pose(cam, "setup.camera",
                                       default_sigma_position=self.DEFAULT_CAMERA_SIGMA[0],
                                       default_sigma_rotation=self.DEFAULT_CAMERA_SIGMA[1])
        names, nominal, sigma, groups = g.pose_param_entries("camera", pos, rv, sp, sr, "camera")

        self.marker_names, mframes, entries = g.parse_markers(
            setup, robot, default_sigma=self.DEFAULT_MARKER_SIGMA, frame_optional=True,
            position_required=True)
        accs: tuple[list[Any], ...] = (names, nominal, sigma, groups)
        mores: tuple[list[Any], ...] = entries
        for acc, more in zip(accs, mores):
            acc += more

        intr = g.section(setup, "intrinsics", "setup")
        g.check_keys(intr, {"focal", "center", "xi", "sigma_focal", "sigma_center", "sigma_xi",
                            "size"}, "setup.intrinsics")
        foc = g.finite_array(g.section(intr, "focal", "setup.intrinsics"),
                             "setup.intrinsics.focal", (2,))
        if np.any(foc <= 0):
            raise ValueError(f"setup.intrinsics.focal: must be > 0 px, got {foc.tolist()}")
        cen = g.finite_array(g.section(intr, "center", "setup.intrinsics"),
                             "setup.intrinsics.center", (2,))
        xi = float(g.finite_array(intr.get("xi", 0.0), "setup.intrinsics.xi", ()))
        sf, sc, sx = (g.positive(intr.get(f"sigma_{k}", v), f"setup.intrinsics.sigma_{k}",
                                 allow_inf=True)
                      for k, v in self.DEFAULT_INTRINSIC_SIGMA.items())
        self.image_size: np.ndarray | None = None
        if intr.get("size") is not None:
            self.image_size = g.finite_array(intr["size"], "setup.intrinsics.size", (2,))
            if np.any(self.image_size <= 0):
                raise ValueError("setup.intrinsics.size: width and height must be > 0 px")
        names += [f"intrinsics_{k}" for k in INTRINSIC_NAMES]
        nominal += [*map(float, foc), *map(float, cen), xi]
        sigma += [sf, sf, sc, sc, sx]
        groups += ["intrinsics"] * 5

        self.noise = g.positive(setup.get("noise", self.DEFAULT_NOISE), "setup.noise")
        used = {f for f in mframes if f is not None}
        if self.camera_frame is not None:
            used.add(self.camera_frame)
        self.frames = sorted(used)
        nf = robot.n_frames  # index nf = the base frame (identity) in the extended frames
        self.marker_frames = np.array([nf if f is None else f for f in mframes], dtype=np.int64)
        self.marker_slot = [None if f is None else self.frames.index(f) for f in mframes]
        self.camera_slot = None if self.camera_frame is None else self.frames.index(self.camera_frame)
        self.obs_names = [f"{nm}_{a}" for nm in self.marker_names for a in "uv"]
        self.meta_names = []
        self.params = ParamBlock(names, np.array(nominal), np.array(sigma), groups)
        self._i_markers = 6
        self._i_intr = 6 + 3 * self.n_markers

    @property
    def n_markers(self) -> int:
        return len(self.marker_names)

    # ------------------------------------------------------------- geometry
    def _geometry(self, f: np.ndarray, p: np.ndarray) -> dict[str, np.ndarray]:
        S, K = f.shape[0], self.n_markers
        ext = np.concatenate([f, np.broadcast_to(np.eye(4), (S, 1, 4, 4))], axis=1)
        TM = ext[:, self.marker_frames]                        # (S, K, 4, 4)
        RM, pM = TM[..., :3, :3], TM[..., :3, 3]
        xm = p[6:self._i_intr].reshape(K, 3)
        xw = np.einsum("skij,kj->ski", RM, xm) + pM            # (S, K, 3)
        if self.camera_frame is None:
            RF, pF = np.broadcast_to(np.eye(3), (S, 3, 3)), np.zeros((S, 3))
        else:
            RF, pF = f[:, self.camera_frame, :3, :3], f[:, self.camera_frame, :3, 3]
        Rm, tm = g.rotvec_matrix(p[3:6]), p[:3]
        Rc = RF @ Rm                                           # (S, 3, 3)
        pc = RF @ tm + pF                                      # (S, 3)
        d = xw - pc[:, None]
        xc = np.einsum("sji,skj->ski", Rc, d)                  # Rc^T (xw - pc)
        return dict(RM=RM, pM=pM, xw=xw, RF=RF, pF=pF, Rm=Rm, Rc=Rc, pc=pc, d=d, xc=xc)

    def _intrinsics(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
        i = self._i_intr
        return p[i:i + 2], p[i + 2:i + 4], float(p[i + 4])

    def _project(self, xc: np.ndarray, p: np.ndarray) -> np.ndarray:
        foc, cen, xi = self._intrinsics(p)
        n = xc[..., :2] / xc[..., 2:3]
        gfac = 1.0 / (1.0 + xi * np.sum(n * n, axis=-1, keepdims=True))
        return cen + foc * n * gfac

    # ------------------------------------------------------------ interface
    def predict(self, frames: np.ndarray, p: np.ndarray, meta: dict | None = None) -> np.ndarray:
        f, p, _ = self.check_inputs(frames, p, meta)
        return self._project(self._geometry(f, p)["xc"], p).reshape(f.shape[0], -1)

    def jacobians(self, frames: np.ndarray, p: np.ndarray, meta: dict | None = None
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        f, p, _ = self.check_inputs(frames, p, meta)
        S, K = f.shape[0], self.n_markers
        G = self._geometry(f, p)
        foc, cen, xi = self._intrinsics(p)
        xc = G["xc"]
        z = xc[..., 2]
        n = xc[..., :2] / z[..., None]                         # (S, K, 2)
        r2 = np.sum(n * n, axis=-1)
        gfac = 1.0 / (1.0 + xi * r2)
        D = n * gfac[..., None]
        y = (cen + foc * D).reshape(S, -1)
        # chain: du/dxc = diag(f) dD/dn dn/dxc
        dDdn = (gfac[..., None, None] * np.eye(2)
                - 2.0 * xi * (gfac ** 2)[..., None, None] * n[..., :, None] * n[..., None, :])
        dndx = np.zeros((S, K, 2, 3))
        dndx[..., 0, 0] = dndx[..., 1, 1] = 1.0 / z
        dndx[..., :, 2] = -n / z[..., None]
        A = foc[:, None] * (dDdn @ dndx)                       # (S, K, 2, 3)
        B = A @ np.swapaxes(G["Rc"], -1, -2)[:, None]          # d u / d xw  (S, K, 2, 3)
        xw = G["xw"]
        jf = np.zeros((S, K, 2, len(self.frames), 6))
        for k in range(K):
            slot = self.marker_slot[k]
            if slot is not None:   # marker frame twist: dxw = v + w x (xw - pM)
                jf[:, k, :, slot, :3] += B[:, k]
                jf[:, k, :, slot, 3:] += -B[:, k] @ g.skew(xw[:, k] - G["pM"][:, k])
            if self.camera_slot is not None:  # camera frame twist: dxc = -Rc^T(v + w x (xw - pF))
                jf[:, k, :, self.camera_slot, :3] -= B[:, k]
                jf[:, k, :, self.camera_slot, 3:] -= -B[:, k] @ g.skew(xw[:, k] - G["pF"])
        jp = np.zeros((S, K, 2, self.params.size))
        jp[..., 0:3] = -A @ G["Rm"].T                          # mount position
        rot = g.skew(G["d"]) @ (G["RF"] @ g.left_jacobian(p[3:6]))[:, None]
        jp[..., 3:6] = B @ rot                                 # mount rotation vector
        for k in range(K):
            i = self._i_markers + 3 * k
            jp[:, k, :, i:i + 3] = B[:, k] @ G["RM"][:, k]
        i = self._i_intr
        jp[..., 0, i] = D[..., 0]
        jp[..., 1, i + 1] = D[..., 1]
        jp[..., 0, i + 2] = 1.0
        jp[..., 1, i + 3] = 1.0
        jp[..., :, i + 4] = -foc * (gfac ** 2 * r2)[..., None] * n
        return y, jf.reshape(S, 2 * K, len(self.frames), 6), jp.reshape(S, 2 * K, -1)

    def visible(self, frames: np.ndarray, p: np.ndarray) -> np.ndarray:
        """(S, K) bool: marker in front of the camera (z > 0), inside the monotone range of
        the distortion (xi |n|^2 < 1 for xi > 0) and, when the setup gives
        ``intrinsics.size``, inside the image."""
        f, p, _ = self.check_inputs(frames, p)
        xc = self._geometry(f, p)["xc"]
        ok = xc[..., 2] > 1e-9
        xi = self._intrinsics(p)[2]
        if xi > 0:  # beyond |n| = 1/sqrt(xi) the distortion folds back: outside the lens
            with np.errstate(divide="ignore", invalid="ignore"):
                n = xc[..., :2] / xc[..., 2:3]
            ok &= xi * np.sum(n * n, axis=-1) < 1.0
        if self.image_size is not None:
            with np.errstate(divide="ignore", invalid="ignore"):
                u = self._project(xc, p)
            ok &= np.all((u >= 0) & (u <= self.image_size), axis=-1)
        return ok

    def initial_guess(self, frames: np.ndarray, y: np.ndarray, p: np.ndarray,
                      meta: dict | None = None) -> np.ndarray:
        """Camera mount pose from all samples by PnP (OpenCV ``solvePnP``) on the predicted
        marker positions in the mount frame's coordinates and the undistorted measured
        pixels (current intrinsics; SQPnP, then Levenberg-Marquardt refinement); markers and
        intrinsics are kept."""
        f, p, _ = self.check_inputs(frames, p, meta)
        S, K = f.shape[0], self.n_markers
        uv = self.check_obs(y, S).reshape(S, K, 2)
        G = self._geometry(f, p)
        # marker positions in the coordinates of the frame carrying the camera mount
        obj = np.einsum("sji,skj->ski", G["RF"], G["xw"] - G["pF"][:, None]).reshape(-1, 3)
        foc, cen, xi = self._intrinsics(p)
        dn = ((uv - cen) / foc).reshape(-1, 2)                 # distorted normalized coords
        rho = np.linalg.norm(dn, axis=-1)
        if abs(xi) > 1e-12:   # invert rho = r / (1 + xi r^2) on the branch through r = rho
            disc = 1.0 - 4.0 * xi * rho ** 2
            if np.any(disc < 0):
                raise ValueError("initial_guess: pixels outside the distortion model's range")
            with np.errstate(divide="ignore", invalid="ignore"):
                r = np.where(rho > 1e-12, (1.0 - np.sqrt(disc)) / (2.0 * xi * rho), rho)
        else:
            r = rho
        undist = dn * (1.0 + xi * r ** 2)[:, None]
        if obj.shape[0] < 6:
            raise ValueError(f"initial_guess: PnP needs >= 6 marker observations, got {obj.shape[0]}")
        obj = np.ascontiguousarray(obj, dtype=np.float64)
        undist = np.ascontiguousarray(undist, dtype=np.float64)
        # SQPnP is globally optimal (no initial guess needed); LM refines the reprojection
        import cv2  # lazily: importing jwarp (and its plugin registry) needs no OpenCV

        ok, rvec, tvec = cv2.solvePnP(obj, undist, np.eye(3), None, flags=cv2.SOLVEPNP_SQPNP)
        if not ok or not np.all(np.isfinite(rvec)) or not np.all(np.isfinite(tvec)):
            raise ValueError("initial_guess: PnP failed (degenerate marker positions)")
        rvec, tvec = cv2.solvePnPRefineLM(obj, undist, np.eye(3), None, rvec, tvec)
        from scipy.spatial.transform import Rotation  # lazy: 0.3 s at import

        Rcf = Rotation.from_rotvec(rvec.ravel()).as_matrix()   # x_cam = Rcf x_F + t
        out = p.copy()
        out[3:6] = g.nearest_rotvec(Rcf.T, p[3:6])   # the representation next to the prior
        out[:3] = -Rcf.T @ tvec.ravel()
        return out


@hookimpl
def jwarp_measurements() -> dict[str, Any]:
    return {"image": ImageMeasurement}
