"""Joint transmission errors (the robot's ``harmonic`` field) on the host side.

A transmission error only changes which joint value the links see: joint j acts as
``q'_j = q_j + sum_k a_jk sin(k q_j) + b_jk cos(k q_j)`` (:meth:`RobotModel.joint_transmission`).
Feeding ``q'`` into the unchanged FK / elastic kernels is therefore exact; the joint
Jacobian gains the diagonal chain-rule factor ``dq'_j/dq_j``
(:meth:`RobotModel.joint_transmission_slope`). The public kinematics functions
(:func:`~jwarp.kinematics.fk.fk`, :func:`~jwarp.kinematics.equilibrium.fk_elastic`,
:func:`~jwarp.kinematics.equilibrium.elastic_step`,
:func:`~jwarp.kinematics.jacobians.jacobian`, ``jacobian_dh``) call :func:`transmitted`
first; robots without transmission errors pass through untouched (one attribute check).
The IK and planner kernels read joint values on the device directly; the solvers
(:class:`~jwarp.solvers.ik.IKSolver`, :class:`~jwarp.solvers.planning.Planner`) therefore
work in the links' joint space: their inputs (seeds, start, goal, warm starts) go through
:func:`transmitted` and their results come back through :func:`untransmitted`, so a
solution is exact for the commanded joint values (see ``docs/nongeometric.md``).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import warp as wp

from jwarp.core.arrays import is_torch
from jwarp.model import RobotModel


def transmitted(model: RobotModel, q: Any) -> Any:
    """``q + dq(q)`` in the kind of ``q`` (numpy, torch (differentiable) or Warp, same
    device and dtype), or ``q`` itself when the robot has no transmission errors. Shapes
    are not checked here beyond the last axis (the kinematics functions check them)."""
    if not model.has_harmonic:
        return q
    h = model.harmonic
    if is_torch(q):
        import torch

        if q.shape[-1] != model.n_dof or not q.is_floating_point():
            return q   # the caller's validation reports it
        k = torch.arange(1, h.shape[1] + 1, dtype=q.dtype, device=q.device)
        ht = torch.as_tensor(h, dtype=q.dtype, device=q.device)
        kq = q[..., :, None] * k
        return q + torch.sum(ht[:, :, 0] * torch.sin(kq) + ht[:, :, 1] * torch.cos(kq), dim=-1)
    if isinstance(q, wp.array):
        a = q.numpy()
        if a.shape[-1] != model.n_dof:
            return q
        out = model.joint_transmission(a).astype(a.dtype)
        return wp.array(out, dtype=q.dtype, device=q.device)
    try:
        a = np.asarray(q)
    except (TypeError, ValueError):
        return q
    if a.ndim == 0 or a.shape[-1] != model.n_dof or a.dtype.kind not in "fiu":
        return q
    out = model.joint_transmission(a)
    return out.astype(a.dtype) if a.dtype.kind == "f" else out


def transmission_slope(model: RobotModel, q: Any) -> np.ndarray | None:
    """(..., n_dof) numpy ``dq'/dq`` at ``q`` (numpy/torch/Warp), None without errors."""
    if not model.has_harmonic:
        return None
    if is_torch(q):
        a = q.detach().cpu().numpy()
    elif isinstance(q, wp.array):
        a = q.numpy()
    else:
        a = np.asarray(q, np.float64)
    return model.joint_transmission_slope(a)


def without_transmission(model: RobotModel) -> RobotModel:
    """The robot without its transmission errors (a copy, cached on ``model``; models are
    treated as immutable once used)."""
    return _cached_copy(model, model.has_harmonic, "_without_transmission", harmonic=None)


def _cached_copy(model: RobotModel, needed: bool, key: str, **changes: object) -> RobotModel:
    """``model`` itself when not ``needed``, else ``model.copy(**changes)``, cached on the
    model under ``key``."""
    if not needed:
        return model
    out = model.__dict__.get(key)
    if out is None:
        out = model.__dict__[key] = model.copy(**changes)
    return out


def without_coupling_harmonic(model: RobotModel) -> RobotModel:
    """The robot without the angle-dependent errors of its coupled frames
    (``coupling_harmonic``; a copy, cached on ``model``), for callers that add them to
    per-configuration DH rows themselves (the calibration). The kinematics kernels
    otherwise apply them (:mod:`jwarp.kernels.fk` ``joint_value``)."""
    return _cached_copy(model, model.has_coupling_harmonic, "_without_coupling_harmonic",
                        coupling_harmonic=None)


def untransmitted(model: RobotModel, q_link: np.ndarray, *, tol: float = 1e-13,
                  max_iter: int = 30) -> np.ndarray:
    """The joint values ``q`` whose links see ``q_link`` (..., n_dof): the inverse of
    :func:`transmitted` by Newton's method per joint (float64 numpy; ``q_link`` itself
    without transmission errors). Converges when ``dq'/dq > 0`` (a transmission error
    smaller than the joint's own motion: |sum k (|a_k| + |b_k|)| < 1); raises ValueError
    naming ``harmonic`` when it does not."""
    a = np.asarray(q_link, np.float64)
    if not model.has_harmonic:
        return a.copy()
    q = a.copy()
    for _ in range(max_iter):
        r = model.joint_transmission(q) - a
        if np.all(np.abs(r) <= tol * (1.0 + np.abs(a))):
            return q
        q = q - r / model.joint_transmission_slope(q)
    r = model.joint_transmission(q) - a
    if np.all(np.abs(r) <= 1e-9 * (1.0 + np.abs(a))):
        return q
    raise ValueError(f"harmonic: the transmission errors of '{model.name}' are not invertible "
                     f"at some joint values (residual {np.abs(r).max():.3g} rad)")
