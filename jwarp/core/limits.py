"""Joint limits of a robot as device tables and host-side checks (box + linear limits).

The box is ``RobotModel.joint_limits (n_dof, 2)``; linear limits are
``RobotModel.linear_limits`` (``lower <= sum_k c_k q_{j_k} <= upper``, e.g. justin19's
coupled torso ``0 <= q1 + q2 <= 2.356``). :mod:`jwarp.kernels.path` projects onto both; the
device tables it reads (the ``kernels.path.LimitTables`` struct) are the ``limits`` of the
robot's device model (:func:`jwarp.core.device.put_model`).
"""

from __future__ import annotations

import numpy as np

from jwarp.model import RobotModel

__all__ = ["LIMIT_TOL", "limit_violation", "within_limits",
           "describe_violation", "sample_within_limits", "project_numpy"]

#: slack when checking limits [rad or m] (float32 round-off of a projected value)
LIMIT_TOL = 1e-6


def limit_violation(robot: RobotModel, q: np.ndarray) -> np.ndarray:
    """Largest violation of the box and linear limits per configuration.

    q (..., n_dof) -> (...,) [rad or m], 0 inside the limits.
    """
    q = np.asarray(q, np.float64)
    lo, hi = robot.joint_limits[:, 0], robot.joint_limits[:, 1]
    v = np.maximum(np.maximum(lo - q, q - hi), 0.0).max(axis=-1, initial=0.0)
    for lim in robot.linear_limits:
        s = q[..., lim.joints] @ np.asarray(lim.coefficients, np.float64)
        v = np.maximum(v, np.maximum(np.maximum(lim.lower - s, s - lim.upper), 0.0))
    return v


def within_limits(robot: RobotModel, q: np.ndarray, tol: float = LIMIT_TOL) -> np.ndarray:
    """(...,) bool: q (..., n_dof) satisfies the box and linear limits up to ``tol``."""
    return limit_violation(robot, q) <= tol


def describe_violation(robot: RobotModel, q: np.ndarray) -> str:
    """A human-readable list of the limits one configuration q (n_dof,) violates."""
    q = np.asarray(q, np.float64)
    out = []
    for j, (lo, hi) in enumerate(robot.joint_limits):
        if not lo - LIMIT_TOL <= q[j] <= hi + LIMIT_TOL:
            out.append(f"{robot.joint_names[j]}={q[j]:+.4g} not in [{lo:+.4g}, {hi:+.4g}]")
    for lim in robot.linear_limits:
        s = float(q[lim.joints] @ np.asarray(lim.coefficients))
        if not lim.lower - LIMIT_TOL <= s <= lim.upper + LIMIT_TOL:
            terms = " + ".join(f"{c:g}*{robot.joint_names[j]}"
                               for j, c in zip(lim.joints, lim.coefficients))
            out.append(f"{terms}={s:+.4g} not in [{lim.lower:+.4g}, {lim.upper:+.4g}]")
    return "; ".join(out)


def sample_within_limits(robot: RobotModel, n: int, rng: np.random.Generator) -> np.ndarray:
    """n uniform random configurations (n, n_dof) inside the box, rejection-sampled for the
    linear limits (falls back to projection for rows still outside after 20 rounds)."""
    lo, hi = robot.joint_limits[:, 0], robot.joint_limits[:, 1]
    q = rng.uniform(lo, hi, size=(n, robot.n_dof))
    for _ in range(20):
        bad = ~within_limits(robot, q)
        if not bad.any():
            return q
        q[bad] = rng.uniform(lo, hi, size=(int(bad.sum()), robot.n_dof))
    return project_numpy(robot, q)


def project_numpy(robot: RobotModel, q: np.ndarray, rounds: int = 6) -> np.ndarray:
    """Host version of the kernels' projection (alternating box / linear projections)."""
    q = np.array(q, np.float64, copy=True)
    lo, hi = robot.joint_limits[:, 0], robot.joint_limits[:, 1]
    if not robot.linear_limits:
        return np.clip(q, lo, hi)
    for _ in range(rounds):
        q = np.clip(q, lo, hi)
        for lim in robot.linear_limits:
            c = np.asarray(lim.coefficients, np.float64)
            s = q[..., lim.joints] @ c
            excess = np.where(s < lim.lower, s - lim.lower, np.where(s > lim.upper, s - lim.upper, 0.0))
            q[..., lim.joints] -= excess[..., None] * c / (c @ c)
    return np.clip(q, lo, hi)
