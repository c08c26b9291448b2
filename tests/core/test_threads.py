"""The BLAS pool around jwarp's small dense solves (jwarp.core.threads): the limit is
applied inside the solve and restored after it, JWARP_BLAS_THREADS overrides it, and a
bad value is a ValueError naming the variable. Thread counts are read back through
threadpoolctl's own report of the loaded BLAS library, not through jwarp."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from threadpoolctl import threadpool_info, threadpool_limits

import jwarp
from jwarp.core.threads import BLAS_THREADS_ENV, blas_thread_limit, blas_threads


def blas_counts() -> list[int]:
    return [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]


@pytest.fixture
def two_threads():
    """The BLAS pool at 2 threads outside the solve (as numpy's default on 2 cores)."""
    if not blas_counts():
        pytest.skip("threadpoolctl finds no BLAS library in this numpy")
    with threadpool_limits(limits=2, user_api="blas"):
        yield


def test_parse_values_and_errors(monkeypatch):
    monkeypatch.delenv(BLAS_THREADS_ENV, raising=False)
    assert blas_thread_limit() == 1
    for text, want in [("3", 3), (" 2 ", 2), ("0", None), ("none", None), ("NONE", None),
                       ("", 1)]:
        assert blas_thread_limit(text) == want, text
    for bad in ["-1", "two", "1.5", "2,3"]:
        with pytest.raises(ValueError, match=f"^{BLAS_THREADS_ENV}: expected an integer >= 0"):
            blas_thread_limit(bad)
    monkeypatch.setenv(BLAS_THREADS_ENV, "x")
    with pytest.raises(ValueError, match=BLAS_THREADS_ENV), blas_threads():
        pass
    for bad in [0, -2, 1.5, True]:
        with pytest.raises(ValueError, match="^n: expected a positive integer"), \
                blas_threads(bad):
            pass


def test_context_limits_and_restores(monkeypatch, two_threads):
    monkeypatch.delenv(BLAS_THREADS_ENV, raising=False)
    assert set(blas_counts()) == {2}
    with blas_threads() as n:
        assert n == 1 and set(blas_counts()) == {1}
    assert set(blas_counts()) == {2}
    monkeypatch.setenv(BLAS_THREADS_ENV, "0")          # leave the pool alone
    with blas_threads() as n:
        assert n is None and set(blas_counts()) == {2}
    # restored after an exception too
    with pytest.raises(RuntimeError), blas_threads(1):
        raise RuntimeError("boom")
    assert set(blas_counts()) == {2}


def _arm7_campaign():
    from jwarp.plugins.measurements.cartesian import CartesianMeasurement

    robot = jwarp.robot("arm7")
    meas = CartesianMeasurement(robot, {"plugin": "cartesian", "tracker": {
        "position": [2.0, 0.0, 1.0], "rotvec": [0.0, 0.0, 2.6]}, "markers": [
        {"name": "tcp", "frame": "tcp", "position": [0.0, 0.0, 0.05]}], "noise": 1e-4})
    rng = np.random.default_rng(1)
    lim = robot.joint_limits
    q = rng.uniform(lim[:, 0], lim[:, 1], (30, robot.n_dof))
    y = meas.predict(jwarp.fk(robot, q, device="cpu", dtype=np.float64),
                     meas.params.nominal) + rng.normal(0, 1e-4, (30, 3))
    return robot, meas, q, y


@pytest.mark.parametrize("env, inside", [(None, {1}), ("2", {2}), ("0", {2})])
def test_calibration_solve_runs_with_the_limit(monkeypatch, two_threads, env, inside):
    """The pool seen from the solver's iteration callback: 1 thread by default, the
    variable's value when set, untouched with 0; 2 again after the solve. Same result."""
    from jwarp.calibration import CalibrationWarning, calibrate

    if env is None:
        monkeypatch.delenv(BLAS_THREADS_ENV, raising=False)
    else:
        monkeypatch.setenv(BLAS_THREADS_ENV, env)
    robot, meas, q, y = _arm7_campaign()
    seen: list[int] = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", CalibrationWarning)
        res = calibrate(robot, meas, q, y, free="theta,tracker", max_nfev=5, warn=False,
                        callback=lambda p: seen.extend(blas_counts()))
    assert seen and set(seen) == inside
    assert set(blas_counts()) == {2}
    assert np.all(np.isfinite(res.x))


def test_bad_variable_stops_the_solve(monkeypatch):
    from jwarp.calibration import calibrate

    monkeypatch.setenv(BLAS_THREADS_ENV, "many")
    robot, meas, q, y = _arm7_campaign()
    with pytest.raises(ValueError, match=f"^{BLAS_THREADS_ENV}: "):
        calibrate(robot, meas, q, y, free="theta", max_nfev=2, warn=False)
