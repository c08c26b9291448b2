"""The calibration's residual Jacobian uploads the DH rows once per call (not once per
measured frame), with the same numbers; jacobian/jacobian_dh take DH rows that already are
a Warp array on the device without a copy."""

import numpy as np
import pytest
import warp as wp

import jwarp
from jwarp.calibration import CalibrationProblem
from jwarp.calibration.estimate.map import problem_options
from jwarp.calibration.files import make_measurement
from jwarp.calibration.simulate.campaign import justin_tracker_setup
from jwarp.kinematics import jacobian, jacobian_dh


def _uploads(monkeypatch, shape):
    """Counts host arrays of ``shape`` copied into new Warp arrays."""
    seen = []
    init = wp.array.__init__

    def counting(self, data=None, *args, **kwargs):
        if isinstance(data, np.ndarray) and data.shape == shape:
            seen.append(data)
        init(self, data, *args, **kwargs)

    monkeypatch.setattr(wp.array, "__init__", counting)
    return seen


@pytest.mark.parametrize("free", ["theta,d,r,alpha,beta,tracker,markers",
                                  "theta,d,alpha,kappa_theta,kappa_alpha,tracker,markers"])
def test_residual_jacobian_uploads_the_dh_rows_once(monkeypatch, free):
    robot = jwarp.robot("justin19")
    meas = make_measurement(robot, justin_tracker_setup(noise=1e-4))  # a marker on each hand
    assert len(meas.frames) == 2
    rng = np.random.default_rng(5)
    S = 30
    lim = robot.joint_limits
    q = rng.uniform(lim[:, 0], lim[:, 1], (S, robot.n_dof))
    prob = CalibrationProblem(robot, meas, q, rng.normal(0, 0.3, (S, 6)),
                              problem_options(free=free, noise_sigma=1e-4, tol=1e-14, max_iter=200))
    sp = prob.space
    x = sp.nominal + 0.3 * sp.scale * rng.standard_normal(sp.size)
    x[sp.kind == 1] = rng.uniform(0.5, 1.5, int((sp.kind == 1).sum())) * 1e-4
    st = prob.state(x)  # the model at x, cached: the Jacobian reuses it
    seen = _uploads(monkeypatch, (S, robot.n_frames, 5))
    J = prob.jacobian(x)
    uploads = len(seen)
    assert uploads == 1, f"DH rows uploaded {uploads} times for {len(meas.frames)} frames"
    monkeypatch.undo()

    # the same numbers as DH Jacobians from numpy rows, one call per frame
    rho = np.ascontiguousarray(np.broadcast_to(st.rho, (S, robot.n_frames, 5)))
    _, jf, _ = meas.jacobians(st.frames, st.p, prob.meta)
    jy = np.zeros((S, jf.shape[1], robot.n_frames, 5))
    for k, f in enumerate(meas.frames):
        jdh = jacobian_dh(robot, q, int(f), dh=rho, device="cpu", dtype=np.float64)
        jy += (jf[:, :, k, :] @ jdh.reshape(S, 6, -1)).reshape(jy.shape)
    got, _ = prob.data_jacobian_rho(st.frames, rho, st.p)
    np.testing.assert_array_equal(got, jy)
    assert np.all(np.isfinite(J))


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_dh_rows_on_the_device_are_used_as_they_are(monkeypatch, dtype):
    robot = jwarp.robot("justin19")
    rng = np.random.default_rng(6)
    S, n = 9, robot.n_frames
    lim = robot.joint_limits
    q = rng.uniform(lim[:, 0], lim[:, 1], (S, robot.n_dof))
    rows = (robot.dh_table + rng.normal(0, 1e-2, (S, n, 5))).astype(dtype)
    shared = rows[0]
    scalar = wp.float32 if dtype == np.float32 else wp.float64
    q_dev = wp.array(q.astype(dtype), dtype=scalar, device="cpu")
    for dh in (rows, shared):
        dh_dev = wp.array(dh, dtype=scalar, device="cpu")
        seen = _uploads(monkeypatch, (1,) + dh.shape if dh.ndim == 2 else dh.shape)
        got_dh = jacobian_dh(robot, q_dev, "right_tcp", point=(0.1, 0, 0.2), dh=dh_dev).numpy()
        got = jacobian(robot, q_dev, "left_tcp", dh=dh_dev).numpy()
        copies = len(seen)
        assert copies == 0, f"the rows were copied {copies} times"
        monkeypatch.undo()
        np.testing.assert_array_equal(
            got_dh, jacobian_dh(robot, q, "right_tcp", point=(0.1, 0, 0.2), dh=dh,
                                device="cpu", dtype=dtype))
        np.testing.assert_array_equal(got, jacobian(robot, q, "left_tcp", dh=dh, device="cpu",
                                                    dtype=dtype))

    bad = rows.copy()
    bad[2, 3, 1] = np.nan
    with pytest.raises(ValueError, match="dh"):
        jacobian_dh(robot, q_dev, "right_tcp", dh=wp.array(bad, dtype=scalar, device="cpu"))
    with pytest.raises(ValueError, match="dh"):
        jacobian(robot, q_dev, "right_tcp", dh=wp.array(rows[:4], dtype=scalar, device="cpu"))
