"""Calibration options (CalibrationOptions, calibrate_with) and the problem's joint values
uploaded once (CalibrationProblem.q_device)."""

from __future__ import annotations

import warnings
from dataclasses import replace

import numpy as np
import pytest
import warp as wp

import jwarp
from jwarp.calibration import (
    CalibrationOptions,
    CalibrationProblem,
    CalibrationWarning,
    calibrate,
    calibrate_with,
)
from jwarp.calibration.estimate import map as M
from jwarp.calibration.estimate.map import problem_options


def _cartesian(robot):
    from jwarp.plugins.measurements.cartesian import CartesianMeasurement

    setup = {"plugin": "cartesian",
             "tracker": {"position": [3.0, 0.2, 1.0], "rotvec": [0.0, 0.0, 2.6]},
             "markers": [{"name": "right", "frame": "right_tcp", "position": [0.0, 0.02, 0.05]},
                         {"name": "left", "frame": "left_tcp", "position": [0.0, 0.02, 0.05]}],
             "noise": 1e-4}
    return CartesianMeasurement(robot, setup)


def _data(robot, n, seed):
    rng = np.random.default_rng(seed)
    lim = robot.joint_limits
    q = rng.uniform(lim[:, 0], lim[:, 1], (n, robot.n_dof))
    return q, rng


@pytest.mark.parametrize("free", ["theta,d,kappa_theta,tracker,markers", "theta,d,tracker"])
def test_problem_uploads_the_joint_values_once(monkeypatch, free):
    """Every model and Jacobian evaluation (at different x) launches on one device array of
    the joint values: none is uploaded again per evaluation (elastic and rigid model)."""
    robot = jwarp.robot("justin19")
    meas = _cartesian(robot)
    q, rng = _data(robot, 20, 0)
    y = rng.normal(0, 0.3, (20, 6))
    prob = CalibrationProblem(robot, meas, q, y, problem_options(free=free, noise_sigma=1e-4))
    assert prob.elastic == ("kappa" in free)
    seen = []

    def spy(fn, at):   # records the joint values, positional argument ``at``
        def wrapped(*a, **k):
            seen.append(a[at])
            return fn(*a, **k)
        return wrapped

    # the problem's kinematics calls: (m, q, ...), (m, d, q, ...), (m, d, frame, q, ...)
    for name, at in (("solve_equilibrium", 1), ("forward_kinematics", 2),
                     ("frame_dh_jacobian", 3)):
        monkeypatch.setattr(M.K, name, spy(getattr(M.K, name), at))
    sp = prob.space
    for k in range(3):
        x = sp.nominal + 0.1 * k * sp.scale
        prob.residuals(x)
        prob.jacobian(x)
    assert prob.n_evaluations == 3 and len(seen) >= 3 * 3  # model + one Jacobian per marker
    assert all(isinstance(a, wp.array) for a in seen), {type(a).__name__ for a in seen}
    assert len({id(a) for a in seen}) == 1 and seen[0] is prob.q_device
    assert prob.q_device.device.is_cpu and prob.q_device.dtype == wp.float64
    np.testing.assert_array_equal(prob.q_device.numpy(), q)


def test_calibrate_with_options_is_calibrate():
    robot = jwarp.robot("arm7")
    from jwarp.plugins.measurements.cartesian import CartesianMeasurement

    meas = CartesianMeasurement(robot, {"plugin": "cartesian", "tracker": {
        "position": [2.0, 0.0, 1.0], "rotvec": [0.0, 0.0, 2.6]}, "markers": [
        {"name": "tcp", "frame": "tcp", "position": [0.0, 0.0, 0.05]}], "noise": 1e-4})
    q, rng = _data(robot, 40, 1)
    y = meas.predict(jwarp.fk(robot, q, device="cpu", dtype=np.float64),
                     meas.params.nominal) + rng.normal(0, 1e-4, (40, 3))
    progress = []
    opts = CalibrationOptions(free="theta,d,tracker", n_starts=2, seed=3, max_nfev=20,
                              callback=progress.append, warn=False)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", CalibrationWarning)
        a = calibrate_with(robot, meas, q, y, opts)
        b = calibrate(robot, meas, q, y, free="theta,d,tracker", n_starts=2, seed=3,
                      max_nfev=20, warn=False)
    np.testing.assert_array_equal(a.x, b.x)
    assert a.iterations == b.iterations and a.nfev == b.nfev and len(progress) >= a.iterations
    prob = CalibrationProblem.from_options(robot, meas, q, y, opts)
    # the measurement's pose and marker groups are freed by default, as the CLI does
    assert prob.space.free_groups == ["theta", "d", "tracker", "markers"]
    prob = CalibrationProblem.from_options(robot, meas, q, y, replace(opts, fix="markers"))
    assert prob.space.free_groups == ["theta", "d", "tracker"]
    prob = CalibrationProblem.from_options(robot, meas, q, y, replace(opts, free_poses=False))
    assert prob.space.free_groups == ["theta", "d", "tracker"]


def test_options_are_validated_naming_the_field():
    C = CalibrationOptions
    bad = [(C(free="theta", n_starts=0), ValueError, "n_starts"),
           (C(free="theta", method="lm"), ValueError, "method"),
           (C(free="theta", callback=1), TypeError, "callback"),
           (C(free=" , "), ValueError, "free"), (C(free=3), TypeError, "free"),
           (C(free="theta", sigma=[1.0]), TypeError, "sigma"),
           (C(free="theta", seed=-2), ValueError, "seed"),
           (C(free="theta", max_nfev=0), ValueError, "max_nfev"),
           (C(free="theta", ftol=-1.0), ValueError, "ftol"),
           (C(free="theta", gtol="x"), TypeError, "gtol"),
           (C(free="theta", elastic="yes"), TypeError, "elastic"),
           (C(free="theta", lam=0.0), ValueError, "lam"),
           (C(free="theta", equilibrium_iterations=-1), ValueError, "equilibrium_iterations"),
           (C(free="theta", tol=np.nan), ValueError, "tol"),
           (C(free="theta", bound_kappa=2), TypeError, "bound_kappa"),
           (C(free="theta", identifiability_tol=-1.0), ValueError, "identifiability_tol"),
           (C(free="theta", moved_sigmas=0.0), ValueError, "moved_sigmas")]
    for opts, err, name in bad:
        with pytest.raises(err, match=f"^{name}"):
            opts.validate()
    C(free=["theta", "d"], ftol=None, max_nfev=None, seed=None, elastic=True).validate()
    robot = jwarp.robot("arm7")
    with pytest.raises(TypeError, match="options"):
        calibrate_with(robot, None, np.zeros((3, 7)), np.zeros((3, 3)), {"free": "theta"})
    with pytest.raises(ValueError, match="^max_nfev"):
        calibrate(robot, None, np.zeros((3, 7)), np.zeros((3, 3)), free="theta", max_nfev=0)


def test_calibrate_takes_options_and_overrides():
    """calibrate(options=..., **overrides): the options are
    dataclasses.replace(options, **overrides); an override wins over the options' field and
    the result equals the keyword call bit for bit; the options object is not modified."""
    robot = jwarp.robot("arm7")
    meas = _tcp_measurement(robot)
    q, rng = _data(robot, 30, 2)
    y = meas.predict(jwarp.fk(robot, q, device="cpu", dtype=np.float64),
                     meas.params.nominal) + rng.normal(0, 1e-4, (30, 3))
    opts = CalibrationOptions(free="theta", n_starts=2, seed=7, max_nfev=10, warn=False)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", CalibrationWarning)
        kw = calibrate(robot, meas, q, y, free="theta,d,tracker", n_starts=2, seed=3,
                       max_nfev=15, warn=False)
        a = calibrate(robot, meas, q, y, options=opts, free="theta,d,tracker", seed=3,
                      max_nfev=15)
        b = calibrate(robot, meas, q, y, options=replace(opts, free="theta,d,tracker",
                                                         seed=3, max_nfev=15))
    for r in (a, b):
        np.testing.assert_array_equal(r.x, kw.x)
        assert r.cost == kw.cost and r.nfev == kw.nfev and r.iterations == kw.iterations
    assert len(kw.starts) == 2
    assert (opts.free, opts.seed, opts.max_nfev) == ("theta", 7, 10)  # not modified


def test_calibrate_rejects_unknown_options_naming_them():
    robot = jwarp.robot("arm7")
    q, y = np.zeros((3, 7)), np.zeros((3, 3))
    with pytest.raises(TypeError, match=r"calibrate\(\) got an unexpected option 'n_seeds'"
                                        r".*CalibrationOptions: free, noise_sigma"):
        calibrate(robot, None, q, y, free="theta", n_seeds=2)
    with pytest.raises(TypeError, match="missing the option 'free'"):
        calibrate(robot, None, q, y, n_starts=2)
    with pytest.raises(TypeError, match="^options: expected CalibrationOptions or None"):
        calibrate(robot, None, q, y, options={"free": "theta"})
    with pytest.raises(ValueError, match="^n_starts"):  # values: validated as before
        calibrate(robot, None, q, y, options=CalibrationOptions(free="theta"), n_starts=0)


def _tcp_measurement(robot):
    from jwarp.plugins.measurements.cartesian import CartesianMeasurement

    return CartesianMeasurement(robot, {"plugin": "cartesian", "tracker": {
        "position": [2.0, 0.0, 1.0], "rotvec": [0.0, 0.0, 2.6]}, "markers": [
        {"name": "tcp", "frame": "tcp", "position": [0.0, 0.0, 0.05]}], "noise": 1e-4})
