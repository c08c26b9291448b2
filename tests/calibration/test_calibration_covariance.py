"""Per-sample full-block covariance in the MAP problem: identical to the diagonal path for
sigma^2 I, a finite-difference check of the whitened Jacobian, and bad input."""

from __future__ import annotations

import numpy as np
import pytest

import jwarp
from jwarp.calibration import CalibrationProblem, calibrate
from jwarp.calibration.estimate.map import problem_options
from jwarp.calibration.files import make_measurement
from jwarp.calibration.simulate.campaign import justin_tracker_setup, simulate_campaign

FREE = "theta,d,kappa_theta,tracker,markers"


@pytest.fixture(scope="module")
def data():
    robot = jwarp.robot("justin19")
    camp = simulate_campaign(robot, justin_tracker_setup(), 12, seed=3, kappa=(0.5e-4, 1e-4))
    meas = make_measurement(robot, camp.setup)
    return robot, meas, camp.samples.q, camp.samples.y


def test_diagonal_covariance_identical(data):
    robot, meas, q, y = data
    sig = np.array([1e-3, 2e-3, 1.5e-3] * 2)
    a = CalibrationProblem(robot, meas, q, y, problem_options(free=FREE, noise_sigma=sig))
    b = CalibrationProblem(robot, meas, q, y,
                           problem_options(free=FREE, covariance=np.broadcast_to(
                               np.diag(sig ** 2), (len(q), 6, 6))))
    x = a.initial_x()
    np.testing.assert_allclose(b.residuals(x), a.residuals(x), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(b.jacobian(x), a.jacobian(x), rtol=1e-12, atol=1e-9)
    ra = calibrate(robot, meas, q, y, free=FREE, noise_sigma=sig, max_nfev=20, warn=False)
    rb = calibrate(robot, meas, q, y, free=FREE, covariance=np.diag(sig ** 2), max_nfev=20,
                   warn=False)
    # the same optimum: equal cost; x equal up to the problem's flat directions (the two
    # runs whiten by a division and by a Cholesky solve, which differ in round-off, and the
    # stall stop may end them one iteration apart)
    np.testing.assert_allclose(rb.cost, ra.cost, rtol=1e-9)
    np.testing.assert_allclose(rb.x, ra.x, rtol=1e-4, atol=1e-5)


def test_full_covariance_whitening_and_fd_jacobian(data):
    robot, meas, q, y = data
    rng = np.random.default_rng(0)
    A = rng.normal(size=(len(q), 6, 6)) * 1e-3
    C = A @ np.swapaxes(A, 1, 2) + 1e-6 * np.eye(6)
    prob = CalibrationProblem(robot, meas, q, y, problem_options(free=FREE, covariance=C))
    x = prob.initial_x() + 1e-3 * prob.space.scale * rng.normal(size=prob.space.size)
    r = prob.residuals(x)
    d = prob.predict(x) - y
    # independent: r_s^T r_s = d_s^T C_s^-1 d_s
    np.testing.assert_allclose(np.sum(r[:prob.n_data].reshape(len(q), 6) ** 2, axis=1),
                               np.einsum("si,sij,sj->s", d, np.linalg.inv(C), d), rtol=1e-8)
    J = prob.jacobian(x)
    h = 1e-6 * prob.space.scale
    fd = np.empty_like(J)
    for k in range(prob.space.size):
        e = np.zeros_like(x)
        e[k] = h[k]
        fd[:, k] = (prob.residuals(x + e) - prob.residuals(x - e)) / (2 * h[k])
    np.testing.assert_allclose(J, fd, rtol=1e-4, atol=1e-4 * np.abs(fd).max())


def test_bad_covariance(data):
    robot, meas, q, y = data
    with pytest.raises(ValueError, match="covariance: expected shape"):
        CalibrationProblem(robot, meas, q, y, problem_options(free=FREE, covariance=np.eye(5)))
    C = np.broadcast_to(np.eye(6), (len(q), 6, 6)).copy()
    C[3, 0, 0] = -1.0
    with pytest.raises(ValueError, match="covariance: block of sample 3 is not positive"):
        CalibrationProblem(robot, meas, q, y, problem_options(free=FREE, covariance=C))
    C[3, 0, 0] = 1.0
    C[4, 0, 1] = 0.5
    with pytest.raises(ValueError, match="covariance: block of sample 4 is not symmetric"):
        CalibrationProblem(robot, meas, q, y, problem_options(free=FREE, covariance=C))
