"""Relative-position task function (thesis eq. 2.46): end-effector positions relative to
the first one, in base coordinates.

``y_k = x_{E_k} - x_{E_1}`` for k = 2..N with ``x_E = T_E(q) . o_E`` (``o_E`` an optional
offset in the end-effector frame, default its origin). Observations per sample:
``<name>_x, _y, _z`` [m] for every end-effector but the first. It is a task measurement
(what in-hand manipulation needs), blind to a common shift of all end-effectors.

Setup section (JSON)::

    {"plugin": "relative",
     "end_effectors": ["thumb_tip", {"name": "index", "frame": "index_tip",
                                     "position": [0, 0, 0], "sigma": 0.01}, ...],
     "free_offsets": false,
     "noise": 0.001}

An entry is a frame (or end-effector) name, or an object with ``frame`` and optional
``name`` (default: the frame name), ``position`` (offset [m], default 0) and ``sigma``
(prior [m] of the offset, default 0.01). Parameters: none, or with ``"free_offsets": true``
``offset_<name>_x, _y, _z`` per end-effector (group ``markers``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from jwarp.model import RobotModel
from jwarp.model import geometry as g
from jwarp.model.measurement import Measurement, ParamBlock
from jwarp.plugins.registry import hookimpl


class RelativeMeasurement(Measurement):
    """End-effector positions [m] relative to the first one (eq. 2.46)."""

    name = "relative"
    unit = "m"
    DEFAULT_NOISE = 0.001         # m
    DEFAULT_OFFSET_SIGMA = 0.01   # m

    def __init__(self, robot: RobotModel, setup: dict) -> None:
        super().__init__(robot, setup)
        g.check_keys(setup, {"plugin", "end_effectors", "free_offsets", "noise"}, "setup")
        ees = g.section(setup, "end_effectors", "setup")
        if not isinstance(ees, list) or len(ees) < 2:
            raise ValueError("setup.end_effectors: expected a list of at least two end-effectors")
        free = setup.get("free_offsets", False)
        if not isinstance(free, bool):
            raise ValueError(f"setup.free_offsets: expected true or false, got {free!r}")
        self.free_offsets = free
        self.ee_names: list[str] = []
        frames: list[int] = []
        offsets: list[np.ndarray] = []
        sigmas: list[float] = []
        for k, e in enumerate(ees):
            where = f"setup.end_effectors[{k}]"
            if isinstance(e, str):
                e = {"frame": e}
            g.check_keys(e, {"name", "frame", "position", "sigma"}, where)
            fr = g.section(e, "frame", where)
            fi = g.robot_frame(robot, fr, f"{where}.frame")
            nm = g.valid_name(e.get("name", fr if isinstance(fr, str) else robot.frames[fi].name),
                              f"{where}.name")
            if nm in self.ee_names:
                raise ValueError(f"{where}.name: duplicate end-effector name '{nm}'")
            self.ee_names.append(nm)
            frames.append(fi)
            offsets.append(g.finite_array(e.get("position", [0.0, 0.0, 0.0]),
                                          f"{where}.position", (3,)))
            sigmas.append(g.positive(e.get("sigma", self.DEFAULT_OFFSET_SIGMA), f"{where}.sigma",
                                     allow_inf=True))
        self.noise = g.positive(setup.get("noise", self.DEFAULT_NOISE), "setup.noise")
        self.ee_frames = np.array(frames, dtype=np.int64)
        self.offsets = np.array(offsets)               # (N, 3) setup values
        self.frames = sorted(set(frames))
        self.ee_slot = [self.frames.index(f) for f in frames]
        self.obs_names = [f"{nm}_{a}" for nm in self.ee_names[1:] for a in "xyz"]
        self.meta_names = []
        if free:
            self.params = ParamBlock([f"offset_{nm}_{a}" for nm in self.ee_names for a in "xyz"],
                                     self.offsets.ravel(), np.repeat(sigmas, 3),
                                     ["markers"] * (3 * len(frames)))
        else:
            self.params = ParamBlock()

    def _points(self, f: np.ndarray, p: np.ndarray) -> tuple[np.ndarray, ...]:
        T = f[:, self.ee_frames]
        R, o = T[..., :3, :3], T[..., :3, 3]
        off = p.reshape(-1, 3) if self.free_offsets else self.offsets
        return np.einsum("skij,kj->ski", R, off) + o, R, o   # (S, N, 3)

    def predict(self, frames: np.ndarray, p: np.ndarray, meta: dict | None = None) -> np.ndarray:
        f, p, _ = self.check_inputs(frames, p, meta)
        x = self._points(f, p)[0]
        return (x[:, 1:] - x[:, :1]).reshape(f.shape[0], -1)

    def jacobians(self, frames: np.ndarray, p: np.ndarray, meta: dict | None = None
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        f, p, _ = self.check_inputs(frames, p, meta)
        S, N = f.shape[0], len(self.ee_names)
        x, R, o = self._points(f, p)
        y = (x[:, 1:] - x[:, :1]).reshape(S, -1)
        # a point x fixed in frame E: dx = [I | -[x - o]x] (v; w)
        blk = np.concatenate([np.broadcast_to(np.eye(3), (S, N, 3, 3)), -g.skew(x - o)], axis=-1)
        jf = np.zeros((S, N - 1, 3, len(self.frames), 6))
        jp = np.zeros((S, N - 1, 3, self.params.size))
        for k in range(1, N):
            jf[:, k - 1, :, self.ee_slot[k]] += blk[:, k]
            jf[:, k - 1, :, self.ee_slot[0]] -= blk[:, 0]
            if self.free_offsets:
                jp[:, k - 1, :, 3 * k:3 * k + 3] = R[:, k]
                jp[:, k - 1, :, 0:3] = -R[:, 0]
        return y, jf.reshape(S, 3 * (N - 1), len(self.frames), 6), jp.reshape(S, 3 * (N - 1), -1)


@hookimpl
def jwarp_measurements() -> dict[str, Any]:
    return {"relative": RelativeMeasurement}
