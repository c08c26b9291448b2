"""Virtual noise for the systematic error (thesis 2.3.2, eqs. 2.6-2.8).

A model that cannot represent the truth leaves ``Delta h = min_Theta |h(q) - h(q, Theta)|``
(eq. 2.6). MAP with the true noise covariance then trusts the certain samples too much; the
systematic error is modelled as an added, *virtual* covariance (eq. 2.7)::

    hat Lambda_a(q) = Lambda_a(q) + bar Lambda_a^e

Four ways to set ``bar Lambda^e`` (a variance, per observed value, unit^2):

(a) by the user: :func:`virtual_covariance` / :func:`add_virtual_noise` (a std, one per
    value, or a covariance);
(b) the approximation ``(Delta h)^2 sqrt(N)`` (:func:`approximate_virtual_variance`);
(c) from an ensemble of simulated data sets drawn from the prior (eq. 2.8,
    :func:`ensemble_virtual_variance`): each member is calibrated without and with the
    virtual variance ``v``; ``v`` is chosen so that the predicted measurements' variance of
    the calibrated model grows by exactly ``(Delta h)^2``, averaged over truths, data sets
    and query points. The predicted variance is the Laplace (linearized) one,
    ``J_q Cov(Theta*) J_q^T`` with ``Cov(Theta*) = (sum_n J_n^T hat Lambda_n^-1 J_n +
    Lambda_Theta^-1)^-1`` at the member's fit, averaged over the m values (trace / m);
    the difference grows monotonically with ``v`` and is solved by bisection in log v;
(d) from a validation set (:func:`validation_virtual_variance`): the candidate with the
    lowest validation error of the calibrated model.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from jwarp.calibration.design.tow import virtual_covariance
from jwarp.utils.checks import check_int


def add_virtual_noise(covariance: Any, virtual: Any) -> np.ndarray:
    """Eq. 2.7: covariance (..., m, m) plus the virtual covariance (a std: scalar or (m,),
    or an (m, m) covariance) -> (..., m, m)."""
    C = np.asarray(covariance, np.float64)
    if C.ndim < 2 or C.shape[-1] != C.shape[-2]:
        raise ValueError(f"covariance: expected (..., m, m), got {C.shape}")
    return C + virtual_covariance(virtual, C.shape[-1], "virtual")


def approximate_virtual_variance(delta_h: float, n_samples: int) -> float:
    """(b) ``(Delta h)^2 sqrt(N)`` [unit^2]: the virtual variance that keeps the systematic
    error ``delta_h`` [unit] from being averaged away by N samples."""
    if not (isinstance(delta_h, (int, float, np.floating)) and math.isfinite(delta_h)
            and delta_h >= 0):
        raise ValueError(f"delta_h: expected a number >= 0, got {delta_h!r}")
    check_int(n_samples, "n_samples", 1)
    return float(delta_h) ** 2 * math.sqrt(int(n_samples))


@dataclass
class EnsembleMember:
    """One simulated data set of (c): a truth drawn from the prior and its samples.

    fit(v) -> (J_train (N, m, P), J_query (Q, m, P)): calibrate this data set with the
        virtual variance ``v`` (0: plain MAP) added to ``covariance`` and return the model
        Jacobians dh/dTheta at the fit on the calibration and on the query configurations.
    covariance: (N, m, m) measurement covariance of the calibration samples [unit^2].
    delta_h2: the member's squared systematic error (eq. 2.6, mean over the values)
        [unit^2], e.g. the mean squared residual of the best fit to the noise-free truth.
    prior_cov: (P, P) prior covariance Lambda_Theta, or None (no prior).
    """

    fit: Callable[[float], tuple[np.ndarray, np.ndarray]]
    covariance: Any
    delta_h2: float
    prior_cov: Any = None


def predicted_variance(J_train: Any, covariance: Any, J_query: Any, prior_cov: Any = None
                       ) -> float:
    """Mean (over query points and values) Laplace variance of the predicted measurements,
    ``trace(J_q Cov(Theta) J_q^T) / m`` with ``Cov(Theta) = (sum J^T Lambda^-1 J +
    Lambda_Theta^-1)^-1``; J_train (N, m, P), covariance (N, m, m), J_query (Q, m, P)."""
    Jt = np.asarray(J_train, np.float64)
    C = np.asarray(covariance, np.float64)
    Jq = np.asarray(J_query, np.float64)
    info = np.einsum("nip,nij,njq->pq", Jt, np.linalg.inv(C), Jt)
    if prior_cov is not None:
        info = info + np.linalg.inv(np.asarray(prior_cov, np.float64))
    cov = np.linalg.pinv(info, hermitian=True)
    return float(np.einsum("qip,pr,qir->", Jq, cov, Jq) / (Jq.shape[0] * Jq.shape[1]))


@dataclass
class VirtualNoiseEstimate:
    """Result of :func:`ensemble_virtual_variance`: ``variance`` [unit^2], the target
    ``delta_h2`` (mean over the members), the achieved mean ``delta_v`` (eq. 2.8's left
    side) and the bisection ``iterations``."""

    variance: float
    delta_h2: float
    delta_v: float
    iterations: int


def ensemble_virtual_variance(members: Sequence[EnsembleMember], *, lo: float = 1e-12,
                              hi: float = 1e6, rtol: float = 1e-3, max_iter: int = 100
                              ) -> VirtualNoiseEstimate:
    """(c) Eq. 2.8: the scalar virtual variance ``v`` with ``E[Delta V(v)] = E[(Delta h)^2]``
    over the ``members`` (:class:`EnsembleMember`), where ``Delta V(v)`` is the predicted
    variance of the fit with ``v`` minus that of the plain fit (:func:`predicted_variance`).
    Bisection in log v inside [lo, hi]; ValueError when the target lies outside."""
    members = list(members)
    if not members:
        raise ValueError("members: empty ensemble")
    for k, mb in enumerate(members):
        if not isinstance(mb, EnsembleMember):
            raise TypeError(f"members[{k}]: expected EnsembleMember, got {type(mb).__name__}")
    if not (0 < lo < hi and math.isfinite(hi)):
        raise ValueError(f"lo, hi: expected 0 < lo < hi < inf, got {lo!r}, {hi!r}")
    target = float(np.mean([m.delta_h2 for m in members]))
    base = []
    for mb in members:
        Jt, Jq = mb.fit(0.0)
        base.append(predicted_variance(Jt, mb.covariance, Jq, mb.prior_cov))

    def delta_v(v: float) -> float:
        out = 0.0
        for mb, b in zip(members, base):
            Jt, Jq = mb.fit(v)
            C = np.asarray(mb.covariance, np.float64)
            Cv = C + v * np.eye(C.shape[-1])
            out += predicted_variance(Jt, Cv, Jq, mb.prior_cov) - b
        return out / len(members)

    f_lo, f_hi = delta_v(lo), delta_v(hi)
    if not f_lo <= target <= f_hi:
        raise ValueError(f"lo, hi: the predicted variance grows by {f_lo:.3g}..{f_hi:.3g} in "
                         f"[{lo:g}, {hi:g}], the target (Delta h)^2 is {target:.3g}")
    a, b = math.log(lo), math.log(hi)
    it, f = 0, f_lo
    for it in range(1, max_iter + 1):  # noqa: B007 (the count is returned)
        mid = 0.5 * (a + b)
        f = delta_v(math.exp(mid))
        if f < target:
            a = mid
        else:
            b = mid
        if b - a < rtol:
            break
    v = math.exp(0.5 * (a + b))
    return VirtualNoiseEstimate(variance=v, delta_h2=target, delta_v=delta_v(v), iterations=it)


def validation_virtual_variance(candidates: Sequence[float],
                                validation_error: Callable[[float], float]
                                ) -> tuple[float, np.ndarray]:
    """(d) The candidate virtual variance [unit^2] whose calibrated model has the lowest
    ``validation_error(v)`` (calibrate with ``v``, evaluate on held-out samples, e.g. in
    the task space); returns (best, errors (len(candidates),))."""
    c = np.asarray(candidates, np.float64).reshape(-1)
    if c.size == 0 or not np.all(np.isfinite(c)) or np.any(c < 0):
        raise ValueError(f"candidates: expected finite variances >= 0, got {candidates!r}")
    errs = np.array([float(validation_error(float(v))) for v in c])
    if not np.all(np.isfinite(errs)):
        raise ValueError("validation_error: returned NaN or inf")
    return float(c[int(np.argmin(errs))]), errs
