"""Task-oriented weighting (thesis 2.3.3): the measurement graph (eqs. 2.12-2.14), the
adjusted covariance (2.11) against the closed forms of the special cases (2.15, 2.16 both
forms, the pinhole's 1/z^2) and against 2.22 where they coincide; the plugin linearization
and the setup's tow section."""

from __future__ import annotations

import numpy as np
import pytest

import jwarp
from jwarp.calibration.design.tow import (
    GaussianNode,
    MeasurementGraph,
    adjusted_covariance,
    reverse_covariance,
    sequential_covariance,
    task_space_covariance,
    tow_covariance,
    tow_from_dict,
)
from jwarp.calibration.estimate.result import model_frames
from jwarp.calibration.files import make_measurement
from jwarp.calibration.simulate.scenarios import HEAD_CAMERA_INTRINSICS, justin_camera_setup
from jwarp.model.geometry import pose_matrix


def spd(rng, d, batch=()):
    a = rng.normal(size=batch + (d, d))
    return a @ np.swapaxes(a, -1, -2) + 0.1 * np.eye(d)


def test_joint_matches_linear_map():
    """x = (I - W)^-1 (e + b) with W strictly lower block-triangular: Cov = M L M^T."""
    rng = np.random.default_rng(0)
    dims = {"u": 2, "a": 3, "t": 2, "z": 1}
    W = {("a", "u"): rng.normal(size=(3, 2)), ("t", "u"): rng.normal(size=(2, 2)),
         ("t", "a"): rng.normal(size=(2, 3)), ("z", "t"): rng.normal(size=(1, 2))}
    L = {k: spd(rng, d) for k, d in dims.items()}
    b = {k: rng.normal(size=d) for k, d in dims.items()}
    nodes = [GaussianNode(k, d, L[k], {p: w for (c, p), w in W.items() if c == k}, b[k])
             for k, d in reversed(dims.items())]           # given out of order
    g = MeasurementGraph(nodes)
    order = list(dims)
    off = np.cumsum([0] + [dims[k] for k in order])
    sl = {k: slice(off[i], off[i + 1]) for i, k in enumerate(order)}
    D = off[-1]
    Wm = np.zeros((D, D))
    for (c, p), w in W.items():
        Wm[sl[c], sl[p]] = w
    M = np.linalg.inv(np.eye(D) - Wm)
    Lm = np.zeros((D, D))
    for k in order:
        Lm[sl[k], sl[k]] = L[k]
    C = M @ Lm @ M.T
    mu = M @ np.concatenate([b[k] for k in order])
    for k in order:
        np.testing.assert_allclose(g.mean(k), mu[sl[k]], atol=1e-12)
        for l in order:
            np.testing.assert_allclose(g.covariance(k, l), C[sl[k], sl[l]], atol=1e-10)
    # conditional (2.14) against the precision-matrix form
    x_t = rng.normal(size=2)
    m, c = g.conditional("a", "t", x_t)
    ia = np.r_[sl["a"]]
    it = np.r_[sl["t"]]
    Cat, Ctt = C[np.ix_(ia, it)], C[np.ix_(it, it)]
    np.testing.assert_allclose(m, mu[ia] + Cat @ np.linalg.solve(Ctt, x_t - mu[it]), atol=1e-10)
    P = np.linalg.inv(C[np.ix_(np.r_[ia, it], np.r_[ia, it])])
    np.testing.assert_allclose(c, np.linalg.inv(P[:3, :3]), atol=1e-9)


def test_sequential_2_15():
    rng = np.random.default_rng(1)
    S = 5
    Ct, Ca_own = spd(rng, 3, (S,)), spd(rng, 2, (S,))
    J = rng.normal(size=(S, 2, 3))                          # tJa = dy_a / dy_t
    V = spd(rng, 3)
    g = MeasurementGraph([GaussianNode("t", 3, Ct), GaussianNode("a", 2, Ca_own, {"t": J})])
    Ca = g.covariance("a")
    np.testing.assert_allclose(Ca, J @ Ct @ np.swapaxes(J, 1, 2) + Ca_own, atol=1e-10)
    np.testing.assert_allclose(adjusted_covariance(g, "a", "t", V),
                               sequential_covariance(Ca, J, V), atol=1e-9)


@pytest.mark.parametrize("mt", [2, 3])
def test_reverse_2_16(mt):
    rng = np.random.default_rng(2)
    Ca = spd(rng, 3, (4,))
    J = rng.normal(size=(4, 3, mt))                         # aJt: y_t = aJt^T y_a
    V = np.diag(rng.uniform(0.1, 1, mt))
    g = MeasurementGraph([GaussianNode("a", 3, Ca),
                          GaussianNode("t", mt, np.zeros((mt, mt)), {"a": np.swapaxes(J, 1, 2)})])
    out = adjusted_covariance(g, "a", "t", V)
    np.testing.assert_allclose(out, reverse_covariance(Ca, J, V), atol=1e-8)
    if mt == 3:   # invertible: the familiar form, and eq. 2.22 coincides
        np.testing.assert_allclose(out, reverse_covariance(Ca, J, V, invertible=True), atol=1e-8)
        np.testing.assert_allclose(task_space_covariance(g, "a", "t", V), out, atol=1e-7)


def test_2_22_sequential_deterministic():
    rng = np.random.default_rng(3)
    Ct = spd(rng, 2)
    J = rng.normal(size=(2, 2))
    V = 0.3 * np.eye(2)
    g = MeasurementGraph([GaussianNode("t", 2, Ct),
                          GaussianNode("a", 2, np.zeros((2, 2)), {"t": J})])
    a = adjusted_covariance(g, "a", "t", V)
    np.testing.assert_allclose(a, g.covariance("a") + J @ V @ J.T, atol=1e-10)
    np.testing.assert_allclose(task_space_covariance(g, "a", "t", V), a, atol=1e-9)


def test_graph_errors_name_the_node():
    c = np.eye(2)
    with pytest.raises(ValueError, match="node 'a'.*cycle"):
        MeasurementGraph([GaussianNode("a", 2, c, {"b": c}), GaussianNode("b", 2, c, {"a": c})])
    with pytest.raises(ValueError, match="node 'a': unknown parent 'x'"):
        MeasurementGraph([GaussianNode("a", 2, c, {"x": c})])
    with pytest.raises(ValueError, match="node 'b': W from parent 'a'"):
        MeasurementGraph([GaussianNode("a", 2, c), GaussianNode("b", 2, c, {"a": np.eye(3)})])
    with pytest.raises(ValueError, match="node 'a': cov"):
        MeasurementGraph([GaussianNode("a", 2, np.eye(3))])
    with pytest.raises(ValueError, match="node 'a': cov is not symmetric"):
        MeasurementGraph([GaussianNode("a", 2, np.array([[1.0, 0.5], [0.0, 1.0]]))])
    with pytest.raises(ValueError, match="node 'a': duplicate"):
        MeasurementGraph([GaussianNode("a", 2, c), GaussianNode("a", 2, c)])


TASK = {"plugin": "cartesian", "tracker": {"position": [0.3, -0.2, 0.1], "rotvec": [0.1, 0.2, 0.3]},
        "markers": [{"name": "right", "frame": "right_tcp", "position": [0, 0, 0.05]},
                    {"name": "left", "frame": "left_tcp", "position": [0, 0, 0.05]}],
        "noise": 1e-4}


@pytest.fixture(scope="module")
def camera():
    robot = jwarp.robot("justin19")
    setup = justin_camera_setup(noise=1.0)
    setup.section["intrinsics"] = dict(setup.section["intrinsics"], xi=0.0)
    meas = make_measurement(robot, setup)
    rng = np.random.default_rng(4)
    lim = robot.joint_limits
    q = lim[:, 0] + (lim[:, 1] - lim[:, 0]) * rng.random((6, robot.n_dof))
    return robot, meas, model_frames(robot, q)


def test_pinhole_weight(camera):
    """image <- cartesian of the same markers: the added covariance of a hand marker's
    pixel is v^2 diag(f) [I | -n] [I | -n]^T diag(f) / z^2, the pole's stays the noise."""
    robot, meas, F = camera
    v = 0.004
    spec = tow_from_dict({"task": TASK, "virtual_noise": v}, robot)
    C = tow_covariance(meas, spec, F, meas.params.nominal)
    p = meas.params.nominal
    foc = np.asarray(HEAD_CAMERA_INTRINSICS["focal"], float)
    Tc = F[:, robot.frame_index("head_tcp")] @ pose_matrix(p[0:3], p[3:6])
    for k, name in enumerate(("right", "left")):
        T = F[:, robot.frame_index(f"{name}_tcp")]
        xw = T[:, :3, :3] @ np.array([0, 0, 0.05]) + T[:, :3, 3]
        xc = np.einsum("sji,sj->si", Tc[:, :3, :3], xw - Tc[:, :3, 3])
        z = xc[:, 2]
        n = xc[:, :2] / z[:, None]
        A = np.zeros((len(z), 2, 3))
        A[:, 0, 0] = A[:, 1, 1] = 1.0
        A[:, :, 2] = -n
        A = foc[None, :, None] * A / z[:, None, None]
        # tiny task noise 1e-4 m propagates too (marginal Lambda_a of eq. 2.11)
        want = np.eye(2) + (v ** 2 + 1e-8) * A @ np.swapaxes(A, 1, 2)
        np.testing.assert_allclose(C[:, 2 * k:2 * k + 2, 2 * k:2 * k + 2], want, rtol=1e-6)
        # at the image centre the weight is z^2 / (f v)^2: the 1/z^2 law
    np.testing.assert_allclose(C[:, 4:, 4:], np.broadcast_to(np.eye(6), (len(F), 6, 6)),
                               atol=1e-12)
    np.testing.assert_allclose(C[:, :2, 2:4], 0.0, atol=1e-12)


def test_shared_and_reverse_graphs(camera):
    robot, meas, F = camera
    for graph in ("shared", "reverse"):
        spec = tow_from_dict({"task": TASK, "virtual_noise": 0.004, "graph": graph}, robot)
        C = tow_covariance(meas, spec, F, meas.params.nominal)
        assert C.shape == (len(F), 10, 10)
        assert np.all(np.linalg.eigvalsh(C) > 0)
        # the virtual noise only adds: C - C(V = 0) is PSD and nonzero on the hand rows
        spec0 = tow_from_dict({"task": TASK, "virtual_noise": 0.0, "graph": graph}, robot)
        D = C - tow_covariance(meas, spec0, F, meas.params.nominal)
        assert np.linalg.eigvalsh(D).min() > -1e-9 and np.abs(D[:, :4, :4]).max() > 1.0


def test_tow_section_errors(camera):
    robot, meas, F = camera
    bad = dict(TASK, markers=[{"name": "x", "frame": "no_such_frame"}])
    with pytest.raises(ValueError, match=r"setup.tow.task.markers\[0\].frame"):
        tow_from_dict({"task": bad, "virtual_noise": 0.01}, robot)
    with pytest.raises(ValueError, match="setup.tow: unknown key"):
        tow_from_dict({"task": TASK, "virtual_noise": 0.01, "virtual": 1}, robot)
    with pytest.raises(ValueError, match="setup.tow.graph"):
        tow_from_dict({"task": TASK, "virtual_noise": 0.01, "graph": "ring"}, robot)
    with pytest.raises(ValueError, match="setup.tow.virtual_noise"):
        tow_from_dict({"task": TASK}, robot)
    with pytest.raises(ValueError, match="setup.tow.task"):
        tow_from_dict({"task": {"tracker": {}}, "virtual_noise": 0.01}, robot)
    # a task measuring other points than the image: sequential refuses, naming the sample
    other = dict(TASK, markers=[{"name": "right", "frame": "right_tcp", "position": [0.3, 0, 0]}])
    spec = tow_from_dict({"task": other, "virtual_noise": 0.01, "tolerance": 1e-3}, robot)
    with pytest.raises(ValueError, match="graph: the actual measurement does not follow"):
        tow_covariance(meas, spec, F, meas.params.nominal)
    head = dict(TASK, markers=[{"name": "h", "frame": "torso_tcp" if "torso_tcp" in
                                robot.frame_names else robot.frame_names[1]}])
    spec = tow_from_dict({"task": head, "virtual_noise": 0.01}, robot)
    with pytest.raises(ValueError, match="task: its frames"):
        tow_covariance(meas, spec, F, meas.params.nominal)
