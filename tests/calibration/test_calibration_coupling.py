"""Issue 29: the ``coupling`` group of coupled frames (justin19's passive torso_4 =
-(q1 + q2)), per-joint priors and orders, robust losses, groups fixed at calibrated
values, the start without priors, and the robot file of a calibrated coupling.

Jacobian columns are checked against central differences; the coupled frames' FK against
an independent numpy evaluation (tests/reference.py) with the extra joint value added by
hand."""

from __future__ import annotations

import json

import numpy as np
import pytest
from calibration.test_calibration import KAPPA, _cartesian, _fd_jacobian, _q
from devices import requires_cpu
from reference import THETA, nominal_dh, ref_fk
from scipy.optimize import OptimizeResult

import jwarp
from jwarp.calibration import CalibrationProblem, ParameterSpace, calibrate
from jwarp.calibration.estimate.map import problem_options, solve_start
from jwarp.calibration.estimate.options import CalibrationOptions
from jwarp.calibration.estimate.params import KIND_COUPLING, KIND_HARMONIC, KIND_KAPPA
from jwarp.calibration.estimate.result import fixed_params, model_frames
from jwarp.calibration.estimate.robust import robust_weights
from jwarp.model import RobotModel, RobotModelError

pytestmark = requires_cpu

TORSO_4 = 4


def _problem(free, S=30, seed=2, **kw):
    robot = jwarp.robot("justin19")
    rng = np.random.default_rng(seed)
    q = _q(robot, S, rng)
    y = rng.normal(0, 0.3, (S, 6))
    return CalibrationProblem(robot, _cartesian(robot), q, y,
                              problem_options(noise_sigma=1e-3, tol=1e-15, max_iter=300, free=free,
                                              **kw)), rng


def _check_columns(prob, rng, groups, rtol=1e-6):
    """Analytic columns of the parameters of ``groups`` vs central differences at a random
    point (compliances in [0.5, 1.5] KAPPA): per column relative error < rtol."""
    sp = prob.space
    x = sp.nominal + 0.5 * sp.scale * rng.standard_normal(sp.size)
    x[sp.kind == KIND_KAPPA] = rng.uniform(0.5, 1.5, int((sp.kind == KIND_KAPPA).sum())) * KAPPA
    J = prob.jacobian(x)
    Jfd = _fd_jacobian(prob, x)
    n = prob.n_data
    sel = np.array([g in groups for g in sp.groups])
    assert sel.any()
    norms = np.linalg.norm(Jfd[:n, sel], axis=0)
    new = np.array([g in ("coupling", "harmonic") for g in np.array(sp.groups)[sel]])
    assert np.all(norms[new] > 0), "a parameter has no effect"
    # a compliance of a joint that carries no torque (the torso pan) has none
    rel = np.linalg.norm(J[:n, sel] - Jfd[:n, sel], axis=0) / np.maximum(
        norms, 1e-6 * np.median(norms))
    assert rel.max() < rtol, (rel.max(), np.array(sp.names)[sel][int(rel.argmax())])
    return x


def test_coupling_group_parameters_and_rigid_columns():
    prob, rng = _problem("coupling,tracker,markers", elastic=False)
    sp = prob.space
    names = [n for n, k in zip(sp.names, sp.kind) if k == KIND_COUPLING]
    assert names == ["torso_4.coupling_offset", "torso_4.coupling_torso_tilt_1",
                     "torso_4.coupling_torso_tilt_2", "torso_4.coupling_a1",
                     "torso_4.coupling_b1", "torso_4.coupling_a2", "torso_4.coupling_b2"]
    cp = sp.kind == KIND_COUPLING
    np.testing.assert_array_equal(sp.nominal[cp], [0, -1, -1, 0, 0, 0, 0])
    _check_columns(prob, rng, ("coupling",))
    # with theta free the offset is theta's entry: not twice
    prob2, _ = _problem("theta,coupling", elastic=False)
    assert "torso_4.coupling_offset" not in prob2.space.names
    assert "torso_4.theta" in prob2.space.names


def test_coupling_with_harmonic_and_per_joint_orders_rigid_columns():
    prob, rng = _problem("coupling,harmonic,theta,tracker", elastic=False,
                         orders={"coupling": 3, "harmonic:torso_*": 3, "harmonic:right_*": 0,
                                 "harmonic:left_*": 1})
    sp = prob.space
    harm = [n for n, k in zip(sp.names, sp.kind) if k == KIND_HARMONIC]
    assert "torso_tilt_1.harmonic_b3" in harm and "left_2.harmonic_b1" in harm
    assert not any(n.startswith("right_") for n in harm)
    assert not any(n.startswith("left_") and n.endswith("2") for n in harm)
    assert "torso_4.coupling_b3" in sp.names
    _check_columns(prob, rng, ("coupling", "harmonic"))


def test_coupling_elastic_columns():
    prob, rng = _problem("coupling,kappa_theta,tracker", S=25, seed=4)
    assert prob.elastic
    _check_columns(prob, rng, ("coupling",))


def test_calibrated_coupling_robot_file_and_reference_fk(tmp_path):
    """robot_at writes the coefficients, the offset and the harmonics into the robot file;
    model_frames of the loaded robot equals the problem's frames, and both equal a numpy
    FK whose torso_4 row gets C q + offset + sum a sin(k u) + b cos(k u) by hand."""
    prob, rng = _problem("coupling,tracker", S=8, elastic=False)
    sp = prob.space
    x = sp.nominal + 2 * sp.scale * rng.standard_normal(sp.size)
    robot = sp.robot_at(x)
    path = tmp_path / "cal.json"
    robot.save(path)
    back = RobotModel.load(path)
    doc = json.loads(path.read_text())
    assert set(doc["coupling_harmonic"]) == {"torso_4"}
    assert doc["frames"][TORSO_4]["coupled"]["joints"] == [1, 2]
    v = dict(zip(sp.names, x))
    np.testing.assert_allclose(doc["frames"][TORSO_4]["coupled"]["coefficients"],
                               [v["torso_4.coupling_torso_tilt_1"],
                                v["torso_4.coupling_torso_tilt_2"]], rtol=0, atol=0)
    q = prob.q
    u = v["torso_4.coupling_torso_tilt_1"] * q[:, 1] + v["torso_4.coupling_torso_tilt_2"] * q[:, 2]
    extra = (v["torso_4.coupling_offset"] + (v["torso_4.coupling_torso_tilt_1"] + 1) * q[:, 1]
             + (v["torso_4.coupling_torso_tilt_2"] + 1) * q[:, 2])
    for k in (1, 2):
        extra = extra + v[f"torso_4.coupling_a{k}"] * np.sin(k * u) \
            + v[f"torso_4.coupling_b{k}"] * np.cos(k * u)
    nominal = jwarp.robot("justin19")
    rho = np.broadcast_to(nominal_dh(nominal), (len(q), nominal.n_frames, 5)).copy()
    rho[:, TORSO_4, THETA] += extra
    ref = ref_fk(nominal, q, rho)
    np.testing.assert_allclose(model_frames(back, q), ref, atol=1e-12)
    np.testing.assert_allclose(prob.frames(x), ref, atol=1e-12)
    # a robot without the term writes no key (files of today unchanged)
    assert "coupling_harmonic" not in nominal.to_dict()
    bad = nominal.to_dict()
    bad["coupling_harmonic"] = {"torso_base": [[1e-3, 0.0]]}
    with pytest.raises(RobotModelError, match="coupling_harmonic.torso_base"):
        RobotModel.from_dict(bad)


def test_per_joint_priors_orders_and_their_errors():
    robot = jwarp.robot("justin19")
    meas = _cartesian(robot)
    sp = ParameterSpace.build(robot, meas, "harmonic,coupling",
                              sigma={"harmonic": 1e-3, "harmonic:torso_*": 5e-3,
                                     "coupling:torso_4": 2e-2},
                              orders={"harmonic:torso_tilt_?": 4})
    sig = dict(zip(sp.names, sp.sigma))
    assert sig["torso_tilt_1.harmonic_a4"] == 5e-3 and sig["torso_pan.harmonic_b2"] == 5e-3
    assert "torso_pan.harmonic_a3" not in sig
    assert sig["right_3.harmonic_a1"] == 1e-3 and sig["torso_4.coupling_b2"] == 2e-2
    with pytest.raises(ValueError, match=r"sigma\['harmonic:nope\*'\]: the pattern matches no"):
        ParameterSpace.build(robot, meas, "harmonic", sigma={"harmonic:nope*": 1e-3})
    with pytest.raises(ValueError, match="sigma: unknown parameter group 'harmonics'"):
        ParameterSpace.build(robot, meas, "harmonic", sigma={"harmonics:torso_*": 1e-3})
    with pytest.raises(ValueError, match=r"orders\['harmonic'\]: expected an integer"):
        ParameterSpace.build(robot, meas, "harmonic", orders={"harmonic": 1.5})
    with pytest.raises(ValueError, match="orders: unknown parameter group 'theta'"):
        ParameterSpace.build(robot, meas, "harmonic", orders={"theta": 2})
    with pytest.raises(ValueError, match="group 'coupling' selects no frames"):
        ParameterSpace.build(jwarp.robot("arm7"), None, "coupling")
    # a prior-less parameter gets its group's default sigma as the solver's scale
    sp = ParameterSpace.build(robot, meas, "kappa_theta,theta", sigma={"kappa_theta": np.inf})
    k = np.array(sp.groups) == "kappa_theta"
    assert np.all(~sp.has_prior[k]) and np.all(sp.scale[k] == 1e-4)


def test_robust_loss_weights_jacobian_and_cost():
    e = np.array([[0.0, 0.0, 0.0], [1e-5, 0.0, 0.0], [0.3, 0.1, -0.2], [3.0, -4.0, 0.0]])
    f = 0.5
    z = np.sum(e * e, axis=1) / f ** 2
    for loss, rho in (("soft_l1", 2 * (np.sqrt(1 + z) - 1)),
                      ("huber", np.where(z <= 1, z, 2 * np.sqrt(z) - 1))):
        w, dw = robust_weights(e, loss, f)
        np.testing.assert_allclose(w ** 2 * z, rho, rtol=1e-6)   # (rho cancels for small z)
        h = 1e-6
        zz = np.array([0.05, 2.0, 25.0])
        ee = np.sqrt(zz)[:, None] * f * np.array([[1.0, 0.0, 0.0]])
        wp = robust_weights(ee * np.sqrt(1 + h / zz)[:, None], loss, f)[0]
        wm = robust_weights(ee * np.sqrt(1 - h / zz)[:, None], loss, f)[0]
        np.testing.assert_allclose(robust_weights(ee, loss, f)[1], (wp - wm) / (2 * h), rtol=1e-5)
    prob, rng = _problem("theta,tracker,markers", S=20, elastic=False, loss="soft_l1",
                         loss_scale=2e-3)
    _check_columns(prob, rng, ("theta", "tracker", "markers"))
    x = prob.space.nominal
    lin, _ = _problem("theta,tracker,markers", S=20, elastic=False)
    e = lin.whiten(lin.predict(x) - lin.y)
    fw = 2e-3 / 1e-3
    zz = np.sum(e * e, axis=1) / fw ** 2
    data_cost = 0.5 * np.sum(fw ** 2 * 2 * (np.sqrt(1 + zz) - 1))
    assert prob.cost(x) == pytest.approx(data_cost + 0.5 * float(np.sum(
        prob.space.prior_residuals(x) ** 2)), rel=1e-10)
    with pytest.raises(ValueError, match="loss_scale: required"):
        CalibrationOptions(free="theta", loss="huber").validate()
    with pytest.raises(ValueError, match="loss: expected one of"):
        CalibrationOptions(free="theta", loss="cauchy").validate()


def test_fix_at_keeps_a_group_at_a_previous_result(tmp_path):
    robot = jwarp.robot("justin19")
    meas = _cartesian(robot)
    rng = np.random.default_rng(7)
    q = _q(robot, 40, rng)
    y = meas.predict(model_frames(robot, q), meas.params.nominal) + rng.normal(0, 1e-4, (40, 6))
    first = calibrate(robot, meas, q, y, free="theta", noise_sigma=1e-4, warn=False)
    path = tmp_path / "cal.json"
    path.write_text(json.dumps(first.to_dict()))
    tr = meas.params.indices("tracker")
    p = fixed_params(meas, {"tracker": str(path)})
    np.testing.assert_array_equal(p[tr], first.params[tr])
    np.testing.assert_array_equal(fixed_params(meas, {"tracker": first})[tr], first.params[tr])
    second = calibrate(robot, meas, q, y, free="theta", noise_sigma=1e-4, warn=False,
                       fix_at={"tracker": path})
    assert "tracker" not in second.groups and "markers" in second.groups
    np.testing.assert_array_equal(second.params[tr], first.params[tr])
    with pytest.raises(ValueError, match="fix_at: 'nope' is not a group"):
        fixed_params(meas, {"nope": first})
    with pytest.raises(ValueError, match=r"fix_at\['tracker'\]: cannot read"):
        fixed_params(meas, {"tracker": str(tmp_path / "missing.json")})


class _Space:
    """The two attributes of a ParameterSpace that solve_start reads, for a 1-D problem."""

    def __init__(self):
        self.kind = np.array([KIND_KAPPA, 0])
        self.lower = np.array([0.0, -np.inf])
        self.upper = np.full(2, np.inf)
        self.scale = np.array([1e-4, 1.0])
        self.size = 2


class _NoEquilibriumAtZero:
    """A problem whose unbounded minimum lies at a negative compliance and whose
    residuals are not finite at kappa = 0 with the other parameter where the run left
    it: the active set's projected start (what scipy refused: "Residuals are not finite
    in the initial point" with all priors off)."""

    def __init__(self):
        self.space = _Space()

    def residuals(self, x):
        if x[0] == 0.0 and abs(x[1] - 1.0) > 1e-3:
            return np.full(2, np.inf)
        return np.array([(x[0] + 2e-4) / 1e-4, x[1] - 3.0])

    def jacobian(self, x):
        return np.diag([1e4, 1.0])

    def cost(self, x):
        r = self.residuals(x)
        return 0.5 * float(r @ r)


def test_active_set_does_not_start_from_a_point_without_equilibrium():
    prob = _NoEquilibriumAtZero()
    xs = np.array([1e-4, 1.0])
    o = CalibrationOptions(free="x", stall_tol=None)
    sol = solve_start(prob, xs, o)
    assert np.isfinite(sol.cost) and sol.cost <= prob.cost(xs)
    assert sol.x[0] >= 0.0
    assert isinstance(sol, OptimizeResult)


class _FiniteOnlyAtStart(_NoEquilibriumAtZero):
    """Every point but the start has no equilibrium: scipy 1.17's dogbox then ends its
    first iteration without a finite trial, and its callback read an unset cost
    (UnboundLocalError 'cost_new')."""

    def residuals(self, x):
        if not np.array_equal(x, [1e-4, 1.0]):
            return np.full(2, np.inf)
        return np.array([3.0, -2.0])


def test_a_run_without_any_finite_trial_ends_at_its_start():
    prob = _FiniteOnlyAtStart()
    xs = np.array([1e-4, 1.0])
    sol = solve_start(prob, xs, CalibrationOptions(free="x", max_nfev=3, stall_tol=None))
    np.testing.assert_array_equal(sol.x, xs)
    assert sol.cost == prob.cost(xs)


def test_all_priors_off_starts_scales_by_the_data_and_holds_what_has_no_effect():
    """Issue 29 item 5 on a small elastic campaign: every prior off. The prior-less
    parameters get the scale 1 / |column| of the data Jacobian at the start; those without
    effect there (the head's rows, which load the torso only through compliances that are
    still 0) are held; the fit ends far below the start."""
    from jwarp.calibration.files import make_measurement
    from jwarp.calibration.simulate.campaign import justin_tracker_setup, simulate_campaign

    robot = jwarp.robot("justin19")
    camp = simulate_campaign(robot, justin_tracker_setup(), 40, seed=1)
    meas = make_measurement(robot, camp.setup)
    groups = "theta,kappa_theta,harmonic"
    sigma = {g: np.inf for g in groups.split(",") + ["tracker", "markers"]}
    q, y = camp.samples.q, camp.samples.y
    prob = CalibrationProblem(robot, meas, q, y,
                              problem_options(free=groups + ",tracker,markers", sigma=sigma))
    x0 = prob.initial_x()
    hold = prob.scale_unpriored(x0)
    J = prob.jacobian(x0)[:prob.n_data]
    norms = np.linalg.norm(J, axis=0)
    held = {prob.space.names[i] for i in np.nonzero(hold)[0]}
    assert held == {prob.space.names[i] for i in np.nonzero(norms == 0)[0]}
    assert "head_1.theta" in held and "right_3.theta" not in held
    ok = ~hold
    np.testing.assert_allclose(prob.space.scale[ok], 1.0 / norms[ok], rtol=1e-12)
    res = calibrate(robot, meas, q, y, free=groups, sigma=sigma, warn=False)
    assert np.isfinite(res.cost) and "without effect at the start held" in res.message
    assert res.errors.mean() < 0.25 * res.errors_start.mean()
    v = dict(zip(res.names, res.x))
    assert v["head_1.theta"] == dict(zip(res.names, res.nominal))["head_1.theta"]
