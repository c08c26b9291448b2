"""Virtual noise (thesis 2.3.2, eqs. 2.6-2.8) on the thesis' 1-D example (Figs. 2.5-2.6):
truth h(q) = q^3 on q ~ U(-1, 1), measurement noise variance q^2 + 0.01, a linear model
a + b q fitted by MAP (weak prior) with three covariances: the true one, a constant one
(= least squares) and the true one plus virtual noise (Delta h)^2 sqrt(N)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from jwarp.calibration.design.virtual_noise import (
    EnsembleMember,
    add_virtual_noise,
    approximate_virtual_variance,
    ensemble_virtual_variance,
    predicted_variance,
    validation_virtual_variance,
)

PRIOR_VAR = 100.0          # weak prior N(0, 10^2) on (a, b)
# the best linear fit of q^3 in L2 on U(-1, 1): b = E[q^4] / E[q^2] = 3/5, a = 0
BEST_B = 0.6
# its squared distance E[(q^3 - 0.6 q)^2] = 1/7 - 1.2/5 + 0.36/3 (eq. 2.6 squared)
DELTA_H2 = 1 / 7 - 1.2 / 5 + 0.36 / 3


def noise_var(q):
    return q ** 2 + 0.01


def distance2(a, b):
    """E_q[(q^3 - a - b q)^2] on U(-1, 1), closed form, per rollout."""
    return 1 / 7 - 2 * b / 5 + b ** 2 / 3 + a ** 2


def fit(q, y, var):
    """Weighted MAP of a + b q per rollout: q, y, var (R, N) -> a, b (R,)."""
    w = 1.0 / var
    s0, s1, s2 = w.sum(1) + 1 / PRIOR_VAR, (w * q).sum(1), (w * q * q).sum(1) + 1 / PRIOR_VAR
    t0, t1 = (w * y).sum(1), (w * q * y).sum(1)
    det = s0 * s2 - s1 * s1
    return (s2 * t0 - s1 * t1) / det, (s0 * t1 - s1 * t0) / det


def rollouts(n, r=4000, seed=0):
    rng = np.random.default_rng(seed)
    q = rng.uniform(-1, 1, (r, n))
    y = q ** 3 + rng.normal(size=(r, n)) * np.sqrt(noise_var(q))
    return q, y


def distances(n, seed=0):
    q, y = rollouts(n, seed=seed)
    v = approximate_virtual_variance(math.sqrt(DELTA_H2), n)
    out = {}
    for name, var in (("true", noise_var(q)), ("constant", np.ones_like(q)),
                      ("virtual", noise_var(q) + v)):
        out[name] = float(np.mean(distance2(*fit(q, y, var))))
    return out


def test_best_linear_fit_closed_form():
    # the exact L2 best fit (independent check of the constants by quadrature)
    qq = np.linspace(-1, 1, 200001)
    b = np.trapezoid(qq ** 4, qq) / np.trapezoid(qq ** 2, qq)
    assert b == pytest.approx(BEST_B, rel=1e-6)
    assert np.trapezoid((qq ** 3 - b * qq) ** 2, qq) / 2 == pytest.approx(DELTA_H2, rel=1e-6)


def test_three_covariances_large_n():
    d = distances(2000, seed=1)
    # true covariance: converges to a suboptimal fit (weighted limit b = E[wq^4]/E[wq^2])
    w_q2 = 1 - 0.01 * 10 * math.atan(10)
    w_q4 = 1 / 3 - 0.01 + 1e-4 * 10 * math.atan(10)
    b_true = w_q4 / w_q2
    assert d["true"] == pytest.approx(distance2(0.0, b_true), rel=0.05)
    assert d["true"] > 1.5 * DELTA_H2
    # constant (least squares) converges to the best linear fit
    assert d["constant"] < 1.05 * DELTA_H2
    # true + virtual: close to least squares, clearly better than the true covariance
    assert d["virtual"] < 1.10 * DELTA_H2
    assert d["virtual"] < 0.75 * d["true"]


def test_three_covariances_small_n():
    d = distances(6, seed=2)
    # least squares wastes the certain samples: worse than the true covariance at small N
    assert d["constant"] > 1.1 * d["true"]
    # the combined covariance keeps the small-N advantage over least squares
    assert d["virtual"] < d["constant"]


def test_virtual_converges_with_n():
    ds = [distances(n, seed=3)["virtual"] for n in (6, 30, 300, 2000)]
    assert all(b < a for a, b in zip(ds, ds[1:]))
    assert ds[-1] - DELTA_H2 < 0.1 * (ds[0] - DELTA_H2)


def _member(n, seed, design_r=1):
    rng = np.random.default_rng(seed)
    q = rng.uniform(-1, 1, n)
    qq = rng.uniform(-1, 1, 200)

    def fit_jac(v):   # linear model: the Jacobian does not depend on the fit
        return (np.stack([np.ones(n), q], 1)[:, None, :],
                np.stack([np.ones(200), qq], 1)[:, None, :])

    return EnsembleMember(fit=fit_jac, covariance=noise_var(q)[:, None, None],
                          delta_h2=DELTA_H2, prior_cov=np.eye(2) * PRIOR_VAR)


def test_ensemble_eq_2_8():
    members = [_member(100, s) for s in range(8)]
    est = ensemble_virtual_variance(members)
    assert est.delta_h2 == pytest.approx(DELTA_H2)
    assert est.delta_v == pytest.approx(DELTA_H2, rel=0.01)
    # independent recomputation of the left side of eq. 2.8 at the estimate
    dv = []
    for m in members:
        Jt, Jq = m.fit(0.0)
        c = np.asarray(m.covariance)
        lam = np.linalg.inv(np.eye(2) / PRIOR_VAR + sum(
            np.outer(j[0], j[0]) / cc[0, 0] for j, cc in zip(Jt, c)))
        lam_v = np.linalg.inv(np.eye(2) / PRIOR_VAR + sum(
            np.outer(j[0], j[0]) / (cc[0, 0] + est.variance) for j, cc in zip(Jt, c)))
        dv.append(np.mean([j[0] @ (lam_v - lam) @ j[0] for j in Jq]))
    assert np.mean(dv) == pytest.approx(DELTA_H2, rel=0.01)
    # and that virtual noise makes the fit converge near the best linear fit
    q, y = rollouts(100, seed=5)
    d_v = np.mean(distance2(*fit(q, y, noise_var(q) + est.variance)))
    d_t = np.mean(distance2(*fit(q, y, noise_var(q))))
    assert d_v < d_t


def test_ensemble_target_outside_bracket():
    with pytest.raises(ValueError, match="lo, hi"):
        ensemble_virtual_variance([_member(50, 0)], hi=1e-6)


def test_validation_set_choice():
    q, y = rollouts(300, r=400, seed=6)
    qv = np.linspace(-1, 1, 101)

    def val_err(v):
        a, b = fit(q, y, noise_var(q) + v)
        return float(np.mean((qv[None] ** 3 - a[:, None] - b[:, None] * qv[None]) ** 2))

    cands = [0.0, 0.01, 0.1, 1.0, 10.0]
    best, errs = validation_virtual_variance(cands, val_err)
    assert best > 0.0 and errs[0] > min(errs)
    with pytest.raises(ValueError, match="candidates"):
        validation_virtual_variance([-1.0], val_err)


def test_add_and_approximate():
    C = np.eye(2)[None].repeat(3, 0)
    out = add_virtual_noise(C, [0.1, 0.2])
    np.testing.assert_allclose(out[1], np.diag([1.01, 1.04]))
    assert approximate_virtual_variance(0.1, 100) == pytest.approx(0.1)
    with pytest.raises(ValueError, match="delta_h"):
        approximate_virtual_variance(-1.0, 10)
    with pytest.raises(ValueError, match="n_samples"):
        approximate_virtual_variance(0.1, 0)
    with pytest.raises(ValueError, match="covariance"):
        add_virtual_noise(np.ones(3), 0.1)
    assert predicted_variance(np.ones((4, 1, 1)), np.ones((4, 1, 1)), np.ones((2, 1, 1))) == \
        pytest.approx(0.25)
