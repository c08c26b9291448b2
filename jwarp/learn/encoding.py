"""Network-side encodings of joint configurations and target frames (thesis 3.4.2).

:class:`JointCodec` maps a network output onto joint values inside the joint limits:

- unit-vector mode (``unit_vectors=True``, the thesis' singularity-free output): every
  revolute joint gets a pair ``(sin, cos)``; the pair is put on the unit circle, its angle
  ``atan2(sin, cos)`` in (-pi, pi] is mapped linearly onto [lower, upper]
  (``q = lower + (angle + pi) / (2 pi) * (upper - lower)``). Prismatic joints get one value
  ``lower + (upper - lower) * sigmoid(y)``.
- plain mode: one value per joint, ``lower + (upper - lower) * sigmoid(y)``.

Either way every decoded ``q`` lies inside the box limits. Joint limits that couple joints
(``RobotModel.linear_limits``, e.g. justin19's torso ``q1 + q2`` polygon) are not enforced
here: the solver projects every seed onto them first, and the training cost U_ik carries
the distance to the default pose only (not the coupled limits), so a network may predict a
configuration slightly outside the coupled polygon.

:func:`frame_features` is the network input of a target frame: 3D robots use the position
and the first two rotation columns (the continuous 6D rotation encoding), planar robots
(``workspace_dim == 2``) use ``x, y, cos(yaw), sin(yaw)``.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from jwarp.core.types import RobotLike
from jwarp.plugins.registry import robot as get_robot

__all__ = ["JointCodec", "frame_features", "frame_features_numpy", "feature_size"]


def feature_size(dim: int) -> int:
    """Width of :func:`frame_features` for a ``dim``-D workspace (2: 4, 3: 9)."""
    if dim == 2:
        return 4
    if dim == 3:
        return 9
    raise ValueError(f"dim: expected 2 or 3, got {dim!r}")


def frame_features(T: torch.Tensor, dim: int) -> torch.Tensor:
    """(B, 4, 4) target frames -> (B, F) network features (F = :func:`feature_size`):
    3D: ``[p (3), R[:, 0] (3), R[:, 1] (3)]``; 2D: ``[x, y, cos yaw, sin yaw]``."""
    if T.ndim != 3 or tuple(T.shape[1:]) != (4, 4):
        raise ValueError(f"T: expected (B, 4, 4), got {tuple(T.shape)}")
    if dim == 2:
        return torch.stack([T[:, 0, 3], T[:, 1, 3], T[:, 0, 0], T[:, 1, 0]], dim=1)
    if dim == 3:
        return torch.cat([T[:, :3, 3], T[:, :3, 0], T[:, :3, 1]], dim=1)
    raise ValueError(f"dim: expected 2 or 3, got {dim!r}")


def frame_features_numpy(T: np.ndarray, dim: int, out: np.ndarray | None = None) -> np.ndarray:
    """:func:`frame_features` on numpy (P, 4, 4), written into ``out`` (P, F) if given."""
    P = T.shape[0]
    if out is None:
        out = np.empty((P, feature_size(dim)), np.float32)
    if dim == 2:
        out[:, 0] = T[:, 0, 3]
        out[:, 1] = T[:, 1, 3]
        out[:, 2] = T[:, 0, 0]
        out[:, 3] = T[:, 1, 0]
    else:
        out[:, 0:3] = T[:, :3, 3]
        out[:, 3:6] = T[:, :3, 0]
        out[:, 6:9] = T[:, :3, 1]
    return out


class JointCodec:
    """Joint values <-> network outputs (module docstring).

    Args:
        robot: robot name or RobotModel.
        unit_vectors: (sin, cos) pairs for revolute joints (else one sigmoid value each).

    Attributes:
        size: output width (2 per revolute joint and 1 per prismatic joint with unit
            vectors; else 1 per joint).
        n_dof, lower, upper (n_dof,) float64 numpy.
    """

    def __init__(self, robot: RobotLike, unit_vectors: bool = True):
        model = get_robot(robot)
        self.robot = model
        self.unit_vectors = bool(unit_vectors)
        self.n_dof = model.n_dof
        lim = np.asarray(model.joint_limits, np.float64)
        self.lower, self.upper = lim[:, 0].copy(), lim[:, 1].copy()
        rev = np.array([j.type == "revolute" for j in model.joints], bool)
        if not self.unit_vectors:
            rev[:] = False
        self.revolute = rev
        self.rev_idx = np.flatnonzero(rev)
        self.lin_idx = np.flatnonzero(~rev)
        nr, nl = len(self.rev_idx), len(self.lin_idx)
        self.size = 2 * nr + nl
        # output layout: joint by joint, 2 slots (sin, cos) for a unit-vector joint, else 1
        slots, col = [], 0
        sin_cols, cos_cols, lin_cols = [], [], []
        for j in range(self.n_dof):
            if rev[j]:
                sin_cols.append(col)
                cos_cols.append(col + 1)
                col += 2
            else:
                lin_cols.append(col)
                col += 1
            slots.append(col)
        self.sin_cols = np.array(sin_cols, np.int64)
        self.cos_cols = np.array(cos_cols, np.int64)
        self.lin_cols = np.array(lin_cols, np.int64)
        # decode builds [rev joints..., lin joints...] and permutes back to joint order
        order = np.concatenate([self.rev_idx, self.lin_idx])
        self.inverse = np.argsort(order)
        self._cache: dict = {}

    def _t(self, device: torch.device | str | None, dtype: torch.dtype) -> dict:
        key = (str(device), dtype)
        c = self._cache.get(key)
        if c is None:
            def f(a: np.ndarray) -> torch.Tensor:
                return torch.as_tensor(a, dtype=dtype, device=device)

            def i(a: np.ndarray) -> torch.Tensor:
                return torch.as_tensor(a, dtype=torch.long, device=device)

            c = {"lo_r": f(self.lower[self.rev_idx]), "rng_r": f((self.upper - self.lower)[self.rev_idx]),
                 "lo_l": f(self.lower[self.lin_idx]), "rng_l": f((self.upper - self.lower)[self.lin_idx]),
                 "rev": i(self.rev_idx), "lin": i(self.lin_idx), "sin": i(self.sin_cols),
                 "cos": i(self.cos_cols), "lcol": i(self.lin_cols), "inv": i(self.inverse)}
            self._cache[key] = c
        return c

    def encode(self, q: torch.Tensor) -> torch.Tensor:
        """(..., n_dof) joint values inside the limits -> (..., size) outputs that
        :meth:`decode` maps back to them."""
        if q.shape[-1] != self.n_dof:
            raise ValueError(f"q: expected (..., {self.n_dof}), got {tuple(q.shape)}")
        c = self._t(q.device, q.dtype)
        out = q.new_zeros(q.shape[:-1] + (self.size,))
        if len(self.rev_idx):
            u = (q[..., c["rev"]] - c["lo_r"]) / c["rng_r"]
            a = (2.0 * u - 1.0) * math.pi
            out[..., c["sin"]] = torch.sin(a)
            out[..., c["cos"]] = torch.cos(a)
        if len(self.lin_idx):
            u = ((q[..., c["lin"]] - c["lo_l"]) / c["rng_l"]).clamp(1e-6, 1.0 - 1e-6)
            out[..., c["lcol"]] = torch.logit(u)
        return out

    def decode(self, y: torch.Tensor) -> torch.Tensor:
        """(..., size) network outputs -> (..., n_dof) joint values inside the box limits
        (differentiable)."""
        if y.shape[-1] != self.size:
            raise ValueError(f"y: expected (..., {self.size}), got {tuple(y.shape)}")
        c = self._t(y.device, y.dtype)
        parts = []
        if len(self.rev_idx):
            s, co = y[..., c["sin"]], y[..., c["cos"]]
            # the pair on the unit circle (atan2 is scale-free; the norm guards (0, 0))
            r = torch.sqrt(s * s + co * co + 1e-12)
            a = torch.atan2(s / r, co / r)
            parts.append(c["lo_r"] + (a + math.pi) * (1.0 / (2.0 * math.pi)) * c["rng_r"])
        if len(self.lin_idx):
            parts.append(c["lo_l"] + c["rng_l"] * torch.sigmoid(y[..., c["lcol"]]))
        q = parts[0] if len(parts) == 1 else torch.cat(parts, dim=-1)
        if len(self.lin_idx) and len(self.rev_idx):
            q = q[..., c["inv"]]
        return q
