"""Sanity checks of the plain-numpy reference (tests/reference.py) against closed forms.

The reference is what the Warp kernels are tested against, so it is checked here
against results derived by hand: planar chains, pendulums, a cantilever, the coupled
torso joint of Agile Justin, and energy derivatives for the torque axes.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import reference as ref

from jwarp.model import RobotModel

ROOT = Path(__file__).resolve().parents[1]
JUSTIN = ROOT / "jwarp" / "plugins" / "robots" / "justin19.json"
G = 9.81
EYE = np.eye(4).tolist()


def _tx(x):
    T = np.eye(4)
    T[0, 3] = x
    return T.tolist()


def _rx(a):
    c, s = math.cos(a), math.sin(a)
    return [[1, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1]]


@pytest.fixture(scope="module")
def justin():
    return RobotModel.load(JUSTIN)


def planar2(l1=0.7, l2=0.4, tip="static"):
    """2-link planar chain in the world xy plane; ``tip`` as static or fixed dh frame."""
    frames = [
        {"name": "link1", "parent": None, "kind": "dh", "dh": [0, 0, 0, 0, 0], "joint": "q1"},
        {"name": "link2", "parent": "link1", "kind": "dh", "dh": [0, 0, l1, 0, 0], "joint": "q2"},
    ]
    if tip == "static":
        frames.append({"name": "tip", "parent": "link2", "kind": "static", "transform": _tx(l2)})
    else:
        frames.append({"name": "tip", "parent": "link2", "kind": "dh", "dh": [0, 0, l2, 0, 0]})
    return RobotModel.from_dict({
        "name": "planar2", "joints": [{"name": "q1"}, {"name": "q2"}], "frames": frames})


def pendulum(m=2.0, L=0.8):
    """Joint axis horizontal (world -y); the link points along world x at q = 0."""
    return RobotModel.from_dict({
        "name": "pendulum", "joints": [{"name": "q"}],
        "frames": [
            {"name": "base", "parent": None, "kind": "static", "transform": _rx(math.pi / 2)},
            {"name": "link", "parent": "base", "kind": "dh", "dh": [0, 0, 0, 0, 0], "joint": "q"},
        ],
        "masses": [{"frame": "link", "mass": m, "com": [L, 0, 0]}]})


def cantilever(m=3.0, L=0.6):
    """Vertical pan joint, then a fixed horizontal beam of length L carrying m at its end."""
    return RobotModel.from_dict({
        "name": "cantilever", "joints": [{"name": "pan"}],
        "frames": [
            {"name": "pan", "parent": None, "kind": "dh", "dh": [0, 0, 0, 0, 0], "joint": "pan"},
            {"name": "beam", "parent": "pan", "kind": "dh", "dh": [0, 0, L, 0, 0]},
        ],
        "masses": [{"frame": "beam", "mass": m, "com": [0, 0, 0]}]})


# ----------------------------------------------------------------------- FK
def test_planar_chain_tip_closed_form():
    l1, l2 = 0.7, 0.4
    q = ref.sample_q(planar2(), 50, seed=3)
    for tip in ("static", "dh"):
        F = ref.ref_fk(planar2(l1, l2, tip), q)
        assert F.shape == (50, 3, 4, 4)
        q1, q2 = q[:, 0], q[:, 1]
        expect = np.stack([l1 * np.cos(q1) + l2 * np.cos(q1 + q2),
                           l1 * np.sin(q1) + l2 * np.sin(q1 + q2), 0 * q1], -1)
        np.testing.assert_allclose(F[:, 2, :3, 3], expect, atol=1e-12)
        # orientation: rotation by q1 + q2 about z
        a = q1 + q2
        np.testing.assert_allclose(F[:, 2, :2, 0], np.stack([np.cos(a), np.sin(a)], -1), atol=1e-12)
        np.testing.assert_allclose(F[:, 2, :3, 2], np.tile([0, 0, 1.0], (50, 1)), atol=1e-12)
        # elbow at (l1 cos q1, l1 sin q1)
        np.testing.assert_allclose(F[:, 1, :2, 3], l1 * np.stack([np.cos(q1), np.sin(q1)], -1),
                                   atol=1e-12)


def test_single_dh_row_closed_form():
    """One root dh frame with all five parameters, compared with a hand expansion."""
    rng = np.random.default_rng(0)
    model = RobotModel.from_dict({
        "name": "one", "joints": [{"name": "j"}],
        "frames": [{"name": "f", "parent": None, "kind": "dh", "dh": [0, 0, 0, 0, 0], "joint": "j"}]})
    dh = rng.uniform(-1.5, 1.5, (20, 1, 5))
    q = rng.uniform(-1, 1, (20, 1))
    F = ref.ref_fk(model, q, dh)[:, 0]
    d, th, r, a, b = (dh[:, 0, k] for k in range(5))
    th = th + q[:, 0]
    # p = Ry(b) [r, -d sin a, d cos a]
    x, y, z = r, -d * np.sin(a), d * np.cos(a)
    p = np.stack([x * np.cos(b) + z * np.sin(b), y, -x * np.sin(b) + z * np.cos(b)], -1)
    np.testing.assert_allclose(F[:, :3, 3], p, atol=1e-12)
    # z-axis = Ry(b) Rx(a) e_z (Rot_z does not move it)
    ez = np.stack([np.cos(a) * np.sin(b), -np.sin(a), np.cos(a) * np.cos(b)], -1)
    np.testing.assert_allclose(F[:, :3, 2], ez, atol=1e-12)
    # x-axis = Ry(b) Rx(a) [cos th, sin th, 0] = Ry(b) [cos th, cos a sin th, sin a sin th]
    x, y, z = np.cos(th), np.cos(a) * np.sin(th), np.sin(a) * np.sin(th)
    ex = np.stack([x * np.cos(b) + z * np.sin(b), y, -x * np.sin(b) + z * np.cos(b)], -1)
    np.testing.assert_allclose(F[:, :3, 0], ex, atol=1e-12)
    # shared (n_frames, 5) dh gives the same as a broadcast batch
    F1 = ref.ref_fk(model, q[:1], dh[0])
    np.testing.assert_allclose(F1[0, 0], F[0], atol=1e-14)


def test_prismatic_joint_adds_to_d():
    model = RobotModel.from_dict({
        "name": "slide", "joints": [{"name": "s", "type": "prismatic", "limits": [0, 0.5]}],
        "frames": [{"name": "f", "parent": None, "kind": "dh", "dh": [0.1, 0.3, 0.2, 0, 0],
                    "joint": "s"}]})
    q = np.array([[0.0], [0.25], [0.5]])
    F = ref.ref_fk(model, q)
    np.testing.assert_allclose(F[:, 0, 0, 3], 0.2)
    np.testing.assert_allclose(F[:, 0, 2, 3], 0.1 + q[:, 0])
    # orientation does not depend on q: theta stays 0.3
    np.testing.assert_allclose(F[:, 0, 0, 0], math.cos(0.3))


def test_parent_first_order_handles_unsorted_frames():
    """Children listed before their parents must still be computed after them."""
    model = RobotModel.from_dict({
        "name": "unsorted", "joints": [{"name": "q1"}, {"name": "q2"}],
        "frames": [
            {"name": "tip", "parent": "link2", "kind": "static", "transform": _tx(0.4)},
            {"name": "link2", "parent": "link1", "kind": "dh", "dh": [0, 0, 0.7, 0, 0], "joint": "q2"},
            {"name": "link1", "parent": None, "kind": "dh", "dh": [0, 0, 0, 0, 0], "joint": "q1"},
        ]})
    order = ref.parent_first_order(model)
    assert order.index(2) < order.index(1) < order.index(0)
    q = ref.sample_q(model, 10, seed=1)
    np.testing.assert_allclose(ref.ref_fk(model, q)[:, 0], ref.ref_fk(planar2(), q)[:, 2],
                               atol=1e-12)


# ------------------------------------------------------------------ Jacobian
def test_fd_jacobian_planar_equals_analytic():
    l1, l2 = 0.7, 0.4
    model = planar2(l1, l2)
    q = ref.sample_q(model, 20, seed=5)
    J = ref.ref_jacobian_fd(model, q, "tip")
    q1, q12 = q[:, 0], q[:, 0] + q[:, 1]
    Ja = np.zeros((20, 6, 2))
    Ja[:, 0, 0] = -l1 * np.sin(q1) - l2 * np.sin(q12)
    Ja[:, 1, 0] = l1 * np.cos(q1) + l2 * np.cos(q12)
    Ja[:, 0, 1] = -l2 * np.sin(q12)
    Ja[:, 1, 1] = l2 * np.cos(q12)
    Ja[:, 5, :] = 1.0
    np.testing.assert_allclose(J, Ja, atol=1e-8)
    np.testing.assert_allclose(ref.ref_jacobian_fd(model, q, 2), J)


def test_fd_jacobian_justin_structure(justin):
    q = ref.sample_q(justin, 4, seed=2)
    J = ref.ref_jacobian_fd(justin, q, "right_tcp")
    assert J.shape == (4, 6, 19)
    # left arm and head joints do not move the right hand
    np.testing.assert_allclose(J[:, :, 10:19], 0.0, atol=1e-9)
    # torso_pan rotates about world z
    np.testing.assert_allclose(J[:, 3:, 0], np.tile([0, 0, 1.0], (4, 1)), atol=1e-8)
    # angular columns of revolute joints are unit vectors
    np.testing.assert_allclose(np.linalg.norm(J[:, 3:, 3:10], axis=1), 1.0, atol=1e-8)
    # linear velocity = omega x (p_tcp - p_axis): check right_1 (frame 6)
    F = ref.ref_fk(justin, q)
    w = F[:, 6, :3, 2]
    np.testing.assert_allclose(J[:, :3, 3], np.cross(w, F[:, 13, :3, 3] - F[:, 6, :3, 3]),
                               atol=1e-8)
    assert justin.joint_names[3] == "right_1" and justin.frames[6].coupling == [(3, 1.0)]


# ----------------------------------------------------------- coupled torso
def test_justin_coupled_torso_frame(justin):
    q = ref.sample_q(justin, 30, seed=7)
    F = ref.ref_fk(justin, q)
    rel = np.linalg.inv(F[:, 3]) @ F[:, 4]
    a = -(q[:, 1] + q[:, 2])
    expect = np.tile(np.eye(4), (30, 1, 1))
    expect[:, 0, 0], expect[:, 0, 1] = np.cos(a), -np.sin(a)
    expect[:, 1, 0], expect[:, 1, 1] = np.sin(a), np.cos(a)
    expect[:, 0, 3] = 0.3
    np.testing.assert_allclose(rel, expect, atol=1e-12)
    # with the coupling, torso_4's orientation depends only on torso_pan: the upper
    # body stays upright whatever torso_tilt_1/2 are
    F0 = ref.ref_fk(justin, np.where(np.arange(19) == 0, q, 0.0))
    np.testing.assert_allclose(F[:, 4, :3, :3], F0[:, 4, :3, :3], atol=1e-12)


def test_justin_frames_are_rigid_transforms(justin):
    F = ref.ref_fk(justin, ref.sample_q(justin, 10, seed=11))
    R = F[..., :3, :3]
    np.testing.assert_allclose(R @ np.swapaxes(R, -1, -2), np.broadcast_to(np.eye(3), R.shape),
                               atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-12)
    np.testing.assert_allclose(F[..., 3, :], np.broadcast_to([0, 0, 0, 1.0], F.shape[:-1]))


# ----------------------------------------------------------------- torques
def test_pendulum_torque_closed_form():
    m, L = 2.0, 0.8
    model = pendulum(m, L)
    q = np.linspace(-3, 3, 13)[:, None]
    F = ref.ref_fk(model, q)
    # the link's x-axis is (cos q, 0, sin q) in the world: q > 0 raises the mass
    np.testing.assert_allclose(F[:, 1, :3, 3], 0.0, atol=1e-15)
    tau = ref.ref_torques(model, F)
    np.testing.assert_allclose(tau[:, 1, 2], -m * G * L * np.cos(q[:, 0]), atol=1e-12)
    # the parent axes x (world x) and y (world z) see no gravity torque
    np.testing.assert_allclose(tau[:, 1, :2], 0.0, atol=1e-12)
    np.testing.assert_allclose(tau[:, 0], 0.0)  # static frame


def test_pendulum_elastic_fixed_point():
    m, L, k = 2.0, 0.8, 0.02
    model = pendulum(m, L)
    q = np.array([[0.0], [0.7], [-1.2], [2.5]])
    kappa = np.zeros((2, 3))
    kappa[1, 2] = k
    F, rho = ref.ref_fk_elastic(model, q, kappa, n_iter=60)
    # closed form: delta = -k m g L cos(q + delta), solved by Newton
    delta = np.zeros(len(q))
    for _ in range(50):
        f = delta + k * m * G * L * np.cos(q[:, 0] + delta)
        delta -= f / (1 - k * m * G * L * np.sin(q[:, 0] + delta))
    np.testing.assert_allclose(rho[:, 1, 1], delta, atol=1e-12)
    np.testing.assert_allclose(rho[:, 1, [0, 2, 3, 4]], 0.0, atol=1e-15)
    mass_z = F[:, 1, 2, 0] * L  # z of the mass = L sin(q + delta)
    np.testing.assert_allclose(mass_z, L * np.sin(q[:, 0] + delta), atol=1e-12)


def test_cantilever_torques_and_beta_sag():
    m, L = 3.0, 0.6
    model = cantilever(m, L)
    q = np.array([[0.0], [0.4], [2.0]])
    F = ref.ref_fk(model, q)
    tau = ref.ref_torques(model, F)
    s, c = np.sin(q[:, 0]), np.cos(q[:, 0])
    # frame "pan" (root: axes are world x and y through the origin; vertical z axis)
    np.testing.assert_allclose(tau[:, 0, 0], -m * G * L * s, atol=1e-12)
    np.testing.assert_allclose(tau[:, 0, 1], m * G * L * c, atol=1e-12)
    np.testing.assert_allclose(tau[:, 0, 2], 0.0, atol=1e-12)
    # frame "beam": beta axis is the pan frame's y axis, alpha axis along the beam
    np.testing.assert_allclose(tau[:, 1], np.tile([0.0, m * G * L, 0.0], (3, 1)), atol=1e-12)
    # elastic: only beam.beta compliant -> b = k m g L cos b, tip drops by L sin b
    k = 0.05
    kappa = np.zeros((2, 3))
    kappa[1, 1] = k
    Fe, rho = ref.ref_fk_elastic(model, q, kappa, n_iter=80)
    b = 0.0
    for _ in range(80):
        b = b - (b - k * m * G * L * math.cos(b)) / (1 + k * m * G * L * math.sin(b))
    np.testing.assert_allclose(rho[:, 1, 4], b, atol=1e-12)
    np.testing.assert_allclose(Fe[:, 1, 2, 3], -L * math.sin(b), atol=1e-12)
    np.testing.assert_allclose(np.hypot(Fe[:, 1, 0, 3], Fe[:, 1, 1, 3]), L * math.cos(b),
                               atol=1e-12)
    # damped iteration reaches the same fixed point
    _, rho_d = ref.ref_fk_elastic(model, q, kappa, n_iter=200, lam=0.5)
    np.testing.assert_allclose(rho_d, rho, atol=1e-12)


def _gravity_work(model, F):
    """sum_j m_j g . w_j: its derivative w.r.t. a rotation angle is the gravity torque."""
    g = np.asarray(model.gravity)
    out = np.zeros(F.shape[0])
    for mass in model.masses:
        w = F[:, mass.frame, :3, :3] @ mass.com + F[:, mass.frame, :3, 3]
        out += mass.mass * (w @ g)
    return out


def test_torques_are_derivatives_of_gravity_work(justin):
    """tau_alpha/beta/theta = d(sum m g.w)/d(alpha/beta/theta): an independent check of
    the axes and points used in ref_torques (virtual work)."""
    rng = np.random.default_rng(4)
    q = ref.sample_q(justin, 3, seed=9)
    dh = ref.nominal_dh(justin)[None].repeat(3, 0)
    dh[:, :, [3, 4]] += rng.uniform(-0.05, 0.05, (3, justin.n_frames, 2))  # non-zero beta too
    tau = ref.ref_torques(justin, ref.ref_fk(justin, q, dh), dh)
    eps = 1e-6
    for col, k in ((3, 0), (4, 1), (1, 2)):
        for i in range(justin.n_frames):
            dp, dm = dh.copy(), dh.copy()
            dp[:, i, col] += eps
            dm[:, i, col] -= eps
            num = (_gravity_work(justin, ref.ref_fk(justin, q, dp))
                   - _gravity_work(justin, ref.ref_fk(justin, q, dm))) / (2 * eps)
            if justin.frames[i].kind == "dh":
                np.testing.assert_allclose(tau[:, i, k], num, atol=1e-6, err_msg=f"{i} {k}")
            else:
                np.testing.assert_allclose(tau[:, i, k], 0.0)


def test_torques_match_subtree_of_model(justin):
    np.testing.assert_array_equal(ref.subtree_matrix(justin) > 0, justin.subtree_mask)
    order = ref.parent_first_order(justin)
    pos = {f: k for k, f in enumerate(order)}
    assert all(pos[p] < pos[i] for i, p in enumerate(justin.parents) if p >= 0)


# -------------------------------------------------------- justin elastic sag
def test_justin_elastic_converges_to_mm_cm_sag(justin):
    q = np.concatenate([np.zeros((1, 19)), ref.sample_q(justin, 7, seed=1)])
    q[1:, 2] = np.minimum(q[1:, 2], np.deg2rad(135) - np.maximum(q[1:, 1], 0))  # q1+q2 <= 135 deg
    q[1:, 2] = np.maximum(q[1:, 2], -np.minimum(q[1:, 1], 0))
    kappa = ref.kappa_uniform(justin, 1e-4)
    F0 = ref.ref_fk(justin, q)
    F, rho, hist = ref.ref_fk_elastic(justin, q, kappa, n_iter=25, history=True)
    steps = np.array([np.abs(hist[k + 1] - hist[k]).max() for k in range(25)])
    print("\nreference elastic FK, justin19, kappa=1e-4 rad/(N m): max |rho_n - rho_n-1|")
    print("  " + " ".join(f"{s:.1e}" for s in steps[:10]))
    assert np.all(steps[1:] < 0.3 * steps[:-1] + 1e-15), steps  # contracts every step
    assert steps[-1] < 1e-13
    sag = {e: np.linalg.norm(F[:, i, :3, 3] - F0[:, i, :3, 3], axis=-1)
           for e, i in (("right_tcp", 13), ("left_tcp", 22), ("head_tcp", 26))}
    for e, s in sag.items():
        print(f"  {e:<10} sag [mm]: " + " ".join(f"{1e3 * v:6.1f}" for v in s))
    # zero configuration: a few mm to a few cm
    for e, s in sag.items():
        assert 2e-3 < s[0] < 6e-2, (e, s[0])
    allsag = np.concatenate(list(sag.values()))
    assert np.all(allsag > 1e-3) and np.all(allsag < 0.2), allsag
    # sag is a downward motion on the whole: the TCPs drop on average
    dz = np.stack([F[:, i, 2, 3] - F0[:, i, 2, 3] for i in (13, 22, 26)])
    assert dz.mean() < 0
    # static frames keep their nominal rows; joints stay at q
    is_static = np.array([f.kind == "static" for f in justin.frames])
    np.testing.assert_array_equal(rho[:, is_static], 0.0)
