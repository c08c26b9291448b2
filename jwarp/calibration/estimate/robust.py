"""Robust losses of the calibration (``loss`` of :class:`~.options.CalibrationOptions`).

A robust loss replaces a sample's squared whitened residual norm ``|e_s|^2`` by
``f^2 rho(|e_s|^2 / f^2)`` (``f``: the scale in whitened units), so that a sample far off
(an outlier, a mislabelled marker) pulls less. The problem keeps the least-squares form
by scaling each sample's residual vector: ``r_s = w(z_s) e_s`` with
``w(z) = sqrt(rho(z) / z)`` and ``z_s = |e_s|^2 / f^2``, whose Jacobian is exact
(``w J_s + e_s (dw/dz) (2 / f^2) e_s^T J_s``). Unlike scipy's own ``loss``, the loss acts on
the norm of each sample (a 3-D point error counts once, not per coordinate) and the prior
rows stay Gaussian.

* ``soft_l1``: ``rho(z) = 2 (sqrt(1 + z) - 1)`` (quadratic below f, linear above);
* ``huber``: ``rho(z) = z`` for ``z <= 1``, else ``2 sqrt(z) - 1``.
"""

from __future__ import annotations

import numpy as np

#: the losses the calibration accepts
LOSSES = ("linear", "soft_l1", "huber")


def robust_weights(e: np.ndarray, loss: str, f: float) -> tuple[np.ndarray, np.ndarray]:
    """Per-sample residual weights of a robust loss.

    Args:
        e: (S, m) whitened residuals.
        loss: one of :data:`LOSSES`.
        f: the loss scale in whitened units (> 0).

    Returns:
        (w (S,), dw/dz (S,)) with ``z = |e_s|^2 / f^2`` (module docstring); w = 1 and
        dw/dz = 0 for the linear loss.
    """
    e = np.asarray(e, np.float64)
    z = np.sum(e * e, axis=1) / float(f) ** 2
    one = np.ones_like(z)
    if loss == "linear":
        return one, np.zeros_like(z)
    if loss == "soft_l1":
        small = z < 1e-6
        zs = np.where(small, 1.0, z)
        sq = np.sqrt(1.0 + zs)
        rho = 2.0 * (sq - 1.0)
        w = np.sqrt(rho / zs)
        dw = (zs / sq - rho) / (2.0 * w * zs ** 2)
        return (np.where(small, 1.0 - z / 8.0, w), np.where(small, -1.0 / 8.0, dw))
    if loss == "huber":
        big = z > 1.0
        zb = np.where(big, z, 4.0)
        sq = np.sqrt(zb)
        rho = 2.0 * sq - 1.0
        w = np.sqrt(rho / zb)
        dw = (zb / sq - rho) / (2.0 * w * zb ** 2)
        return np.where(big, w, 1.0), np.where(big, dw, 0.0)
    raise ValueError(f"loss: expected one of {', '.join(LOSSES)}, got {loss!r}")
