"""Joint limits of a robot as device tables and host-side checks (box + linear limits).

The box is ``RobotModel.joint_limits (n_dof, 2)``; linear limits are
``RobotModel.linear_limits`` (``lower <= sum_k c_k q_{j_k} <= upper``, e.g. justin19's
coupled torso ``0 <= q1 + q2 <= 2.356``). :mod:`jwarp.kernels.path` projects onto both.
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass

import numpy as np
import warp as wp

from jwarp.core.device import numpy_dtype, scalar_type
from jwarp.model import RobotModel

#: slack when checking limits [rad or m] (float32 round-off of a projected value)
LIMIT_TOL = 1e-6


@dataclass
class LimitTables:
    """Device tables read by the path kernels' projection (see kernels/path.py)."""

    limits: wp.array      # (n_dof, 2)
    lin_start: wp.array   # (L + 1,) int32
    lin_joint: wp.array   # (max(nnz, 1),) int32
    lin_coef: wp.array    # (max(nnz, 1),)
    lin_bounds: wp.array  # (L, 2)

    @property
    def args(self) -> list:
        return [self.limits, self.lin_start, self.lin_joint, self.lin_coef, self.lin_bounds]


_CACHE: "weakref.WeakKeyDictionary[RobotModel, dict]" = weakref.WeakKeyDictionary()


def limit_tables(robot: RobotModel, device: object, dtype: object) -> LimitTables:
    """Limit tables of ``robot`` on ``device`` in ``dtype`` (cached per robot object)."""
    scalar = scalar_type(dtype)
    dev = wp.get_device(device)
    key = (str(dev), scalar.__name__)
    per = _CACHE.setdefault(robot, {})
    if key in per:
        return per[key]
    npdt = numpy_dtype(scalar)
    start, joint, coef, bounds = [0], [], [], []
    for lim in robot.linear_limits:
        joint += list(lim.joints)
        coef += list(lim.coefficients)
        start.append(len(joint))
        bounds.append([lim.lower, lim.upper])
    t = LimitTables(
        limits=wp.array(robot.joint_limits.astype(npdt), dtype=scalar, device=dev),
        lin_start=wp.array(np.array(start, np.int32), dtype=wp.int32, device=dev),
        lin_joint=wp.array(np.array(joint or [0], np.int32), dtype=wp.int32, device=dev),
        lin_coef=wp.array(np.array(coef or [0.0], npdt), dtype=scalar, device=dev),
        lin_bounds=wp.array(np.array(bounds, npdt).reshape(-1, 2), dtype=scalar, device=dev),
    )
    per[key] = t
    return t


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
