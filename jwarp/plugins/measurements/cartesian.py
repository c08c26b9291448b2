"""Cartesian measurement (thesis eq. 2.38): markers on robot frames seen by a tracker.

``y_k = inv(T_tracker) . T_{E_k}(q) . x_k`` with ``T_tracker`` the tracker's pose in the
robot base frame (position + rotation vector) and ``x_k`` the marker position in the
coordinates of its robot frame ``E_k``. Observations per sample: ``<marker>_x, _y, _z`` [m].

Setup section (JSON)::

    {"plugin": "cartesian",
     "tracker": {"position": [x, y, z], "rotvec": [rx, ry, rz],
                 "sigma_position": 1.0, "sigma_rotation": 1.0},
     "markers": [{"name": "right", "frame": "right_tcp", "position": [0, 0, 0.05],
                  "sigma": 0.05}, ...],
     "noise": 0.001}

Parameters: ``tracker_px, _py, _pz, _rx, _ry, _rz`` (group ``tracker``), then
``marker_<name>_x, _y, _z`` per marker (group ``markers``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from jwarp.model import RobotModel
from jwarp.model import geometry as g
from jwarp.model.measurement import Measurement, ParamBlock
from jwarp.plugins.registry import hookimpl


class CartesianMeasurement(Measurement):
    """Marker positions [m] in tracker coordinates (eq. 2.38), vectorized over samples."""

    name = "cartesian"
    unit = "m"
    DEFAULT_NOISE = 0.001          # m
    DEFAULT_MARKER_SIGMA = 0.05    # m
    DEFAULT_TRACKER_SIGMA = (1.0, 1.0)  # m, rad

    def __init__(self, robot: RobotModel, setup: dict) -> None:
        super().__init__(robot, setup)
        g.check_keys(setup, {"plugin", "tracker", "markers", "noise"}, "setup")
        pos, rv, sp, sr = g.parse_pose(g.section(setup, "tracker", "setup"), "setup.tracker",
                                       default_sigma_position=self.DEFAULT_TRACKER_SIGMA[0],
                                       default_sigma_rotation=self.DEFAULT_TRACKER_SIGMA[1])
        g.check_keys(setup["tracker"], {"position", "rotvec", "sigma_position",
                                        "sigma_rotation"}, "setup.tracker")
        names, nominal, sigma, groups = g.pose_param_entries("tracker", pos, rv, sp, sr,
                                                             "tracker")
        self.marker_names, marker_frames, entries = g.parse_markers(
            setup, robot, default_sigma=self.DEFAULT_MARKER_SIGMA, frame_optional=False,
            position_required=False)
        accs: tuple[list[Any], ...] = (names, nominal, sigma, groups)
        mores: tuple[list[Any], ...] = entries
        for acc, more in zip(accs, mores):
            acc += more
        self.noise = g.positive(setup.get("noise", self.DEFAULT_NOISE), "setup.noise")
        self.marker_frames = np.array(marker_frames, dtype=np.int64)     # (K,)
        self.frames = sorted(set(marker_frames))
        self.marker_slot = np.array([self.frames.index(f) for f in marker_frames])  # (K,)
        self.obs_names = [f"{nm}_{a}" for nm in self.marker_names for a in "xyz"]
        self.meta_names = []
        self.params = ParamBlock(names, np.array(nominal), np.array(sigma), groups)

    # ------------------------------------------------------------ helpers
    @property
    def n_markers(self) -> int:
        return len(self.marker_names)

    def _world(self, f: np.ndarray, p: np.ndarray) -> tuple[np.ndarray, ...]:
        """Marker world positions xw (S, K, 3), frame rotations Rf (S, K, 3, 3), origins
        pf (S, K, 3), tracker R (3, 3), t (3,)."""
        T = f[:, self.marker_frames]
        Rf, pf = T[..., :3, :3], T[..., :3, 3]
        xm = p[6:].reshape(self.n_markers, 3)
        xw = np.einsum("skij,kj->ski", Rf, xm) + pf
        return xw, Rf, pf, g.rotvec_matrix(p[3:6]), p[:3]

    # ---------------------------------------------------------- interface
    def predict(self, frames: np.ndarray, p: np.ndarray, meta: dict | None = None) -> np.ndarray:
        f, p, _ = self.check_inputs(frames, p, meta)
        xw, _, _, R, t = self._world(f, p)
        return ((xw - t) @ R).reshape(f.shape[0], -1)   # row-vector form of R^T (x - t)

    def jacobians(self, frames: np.ndarray, p: np.ndarray, meta: dict | None = None
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        f, p, _ = self.check_inputs(frames, p, meta)
        S, K = f.shape[0], self.n_markers
        xw, Rf, pf, R, t = self._world(f, p)
        y = ((xw - t) @ R).reshape(S, -1)
        RT = R.T
        # frames: dy = R^T (v + w x (xw - pf)) = R^T [I | -[xw - pf]x] (v; w)
        jf = np.zeros((S, K, 3, len(self.frames), 6))
        blk = np.concatenate([np.broadcast_to(RT, (S, K, 3, 3)),
                              -RT @ g.skew(xw - pf)], axis=-1)           # (S, K, 3, 6)
        jf[:, np.arange(K), :, self.marker_slot, :] = blk.transpose(1, 0, 2, 3)
        # params
        jp = np.zeros((S, K, 3, self.params.size))
        jp[..., 0:3] = -RT
        jp[..., 3:6] = RT @ g.skew(xw - t) @ g.left_jacobian(p[3:6])
        for k in range(K):
            jp[:, k, :, 6 + 3 * k:9 + 3 * k] = RT @ Rf[:, k]
        return y, jf.reshape(S, 3 * K, len(self.frames), 6), jp.reshape(S, 3 * K, -1)

    def initial_guess(self, frames: np.ndarray, y: np.ndarray, p: np.ndarray,
                      meta: dict | None = None) -> np.ndarray:
        """Tracker pose by closed-form rigid alignment (Kabsch) of the measured marker
        positions (tracker coordinates) onto the predicted ones (base coordinates, with the
        current marker offsets); the marker offsets are kept."""
        f, p, _ = self.check_inputs(frames, p, meta)
        yy = self.check_obs(y, f.shape[0]).reshape(-1, 3)
        xw = self._world(f, p)[0].reshape(-1, 3)
        try:
            R, t = g.rigid_align(yy, xw)
        except ValueError as e:
            raise ValueError(f"initial_guess: {e} (too few distinct marker positions)") from None
        out = p.copy()
        out[:3] = t
        out[3:6] = g.nearest_rotvec(R, p[3:6])   # the representation next to the prior
        return out


@hookimpl
def jwarp_measurements() -> dict[str, Any]:
    return {"cartesian": CartesianMeasurement}
