"""The ``origin`` calibration group: a 6-parameter pose error per static frame (the
URDF-native parametrisation of a joint origin).

A static frame ``s`` with nominal transform ``T0`` (parent -> s) gets the parameters
``delta = (v, w)``: a translation ``v`` [m] and a rotation vector ``w`` [rad], applied in the
frame's own coordinates (right-multiplied)::

    T_s(delta) = T0 @ Trans(v) @ Rot(w)          Rot(w) = exp([w]x)  (Rodrigues)

Default frames (:func:`origin_frames`): the static frames on the measured chains that
precede a joint frame (a ``dh`` frame driven by a joint is their child) - in an imported
URDF, the joint origins. Default prior sigma ``1e-3`` for all six (1 mm, 1 mrad).

Jacobian (:func:`origin_twists`): with ``Ra`` the world rotation of ``F_parent @ T0`` and
``p_s`` the world origin of ``s`` (at delta), ``d/dv_k`` translates ``s`` and everything
below it by ``Ra e_k``; ``d/dw_k`` rotates it about ``p_s`` with angular velocity
``Ra J_l(w) e_k`` (``J_l``: the left Jacobian of SO(3)). A frame ``f`` below ``s`` thus
has the twist ``(v + omega x (p_f - p_s), omega)`` in base coordinates, the twist
convention of the measurements' ``J_frames``.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from jwarp.model import RobotModel

ORIGIN_GROUP = "origin"
#: parameter name suffixes, in column order: translation [m], rotation vector [rad]
ORIGIN_AXES = ("x", "y", "z", "rx", "ry", "rz")


def skew(w: np.ndarray) -> np.ndarray:
    """(..., 3, 3) cross-product matrices of w (..., 3)."""
    w = np.asarray(w, np.float64)
    out = np.zeros(w.shape[:-1] + (3, 3))
    out[..., 0, 1], out[..., 0, 2] = -w[..., 2], w[..., 1]
    out[..., 1, 0], out[..., 1, 2] = w[..., 2], -w[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -w[..., 1], w[..., 0]
    return out


def rotation(w: np.ndarray) -> np.ndarray:
    """(3, 3) ``exp([w]x)`` of a rotation vector w (3,) [rad] (Rodrigues; series near 0)."""
    w = np.asarray(w, np.float64)
    t2 = float(w @ w)
    W = skew(w)
    if t2 < 1e-12:
        a, b = 1.0 - t2 / 6.0, 0.5 - t2 / 24.0
    else:
        t = np.sqrt(t2)
        a, b = np.sin(t) / t, (1.0 - np.cos(t)) / t2
    return np.eye(3) + a * W + b * (W @ W)


def left_jacobian(w: np.ndarray) -> np.ndarray:
    """(3, 3) left Jacobian of SO(3): ``d exp([w]x) = [J_l(w) dw]x exp([w]x)``."""
    w = np.asarray(w, np.float64)
    t2 = float(w @ w)
    W = skew(w)
    if t2 < 1e-12:
        b, c = 0.5 - t2 / 24.0, 1.0 / 6.0 - t2 / 120.0
    else:
        t = np.sqrt(t2)
        b, c = (1.0 - np.cos(t)) / t2, (t - np.sin(t)) / (t2 * t)
    return np.eye(3) + b * W + c * (W @ W)


def delta_transform(delta: np.ndarray) -> np.ndarray:
    """(4, 4) ``Trans(v) @ Rot(w)`` of ``delta = (v, w)`` (6,)."""
    delta = np.asarray(delta, np.float64)
    T = np.eye(4)
    T[:3, :3] = rotation(delta[3:6])
    T[:3, 3] = delta[:3]
    return T


def origin_frames(robot: RobotModel, chain: Iterable[int] | None = None) -> list[int]:
    """Static frames (sorted) with a joint-driven ``dh`` child: the joint origins; only
    those in ``chain`` (frame indices) when given."""
    keep = None if chain is None else set(int(i) for i in chain)
    out = set()
    for f in robot.frames:
        if f.kind == "dh" and f.coupling and f.parent is not None:
            p = f.parent
            if robot.frames[p].kind == "static" and (keep is None or p in keep):
                out.add(int(p))
    return sorted(out)


def with_static_transforms(robot: RobotModel, transforms: dict[int, np.ndarray]
                           ) -> RobotModel:
    """A copy of ``robot`` whose static frames ``transforms`` {frame: (4, 4)} are replaced."""
    out = robot.copy()
    for i, T in transforms.items():
        if out.frames[i].kind != "static":
            raise ValueError(f"transforms: frame '{out.frames[i].name}' is not static")
        out.frames[i].transform = np.array(T, np.float64)
    out.__dict__.pop("static_transforms", None)
    return out.copy()     # validated again, no derived data left from before


def origin_twists(frames: np.ndarray, parent_frames: np.ndarray, T0: np.ndarray,
                  delta: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """Twists of the frames ``targets`` per origin parameter of one static frame.

    Args:
        frames: (S, 4, 4) world transform of the static frame at ``delta``.
        parent_frames: (S, 4, 4) world transform of its parent (identity for a root).
        T0: (4, 4) its nominal transform.
        delta: (6,) its parameters (v [m], w [rad]).
        targets: (S, K, 3) world origins of the frames moved (its descendants).

    Returns:
        (S, K, 6, 6): ``[s, k, :, c]`` the twist ``(v, omega)`` (base coordinates) of
        target k per unit of parameter c.
    """
    Ra = (parent_frames @ T0)[:, :3, :3]                     # (S, 3, 3)
    p_s = frames[:, :3, 3]                                   # (S, 3)
    S, K = targets.shape[:2]
    out = np.zeros((S, K, 6, 6))
    out[:, :, :3, :3] = Ra[:, None]                          # translations
    omega = Ra @ left_jacobian(delta[3:6])                   # (S, 3, 3): columns rx, ry, rz
    out[:, :, 3:, 3:] = omega[:, None]
    r = targets - p_s[:, None, :]                            # (S, K, 3)
    out[:, :, :3, 3:] = -skew(r) @ omega[:, None]            # omega x r = -[r]x omega
    return out
