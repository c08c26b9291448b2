"""Measurement plugins (cartesian, image, contact, relative): predictions against plain numpy
references written here, J_frames / J_params against central finite differences, the
twist convention end to end against jwarp.jacobian, initial guesses, registry, validation."""

from __future__ import annotations

import copy

import numpy as np
import pytest
from devices import requires_cpu
from reference import sample_q
from scipy.spatial.transform import Rotation

import jwarp
from jwarp.plugins.registry import measurement

EPS = 1e-6


# ----------------------------------------------------------------- helpers
def fk64(robot, q, device):
    return np.asarray(jwarp.fk(robot, q, device=device, dtype="float64"))


def pose(pos, rv):
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(rv).as_matrix()
    T[:3, 3] = pos
    return T


def perturb(frames, fi, twist):
    """Frame fi (all samples) moved by the base-frame twist (v, w): origin p + v,
    rotation exp([w]x) R."""
    out = frames.copy()
    out[:, fi, :3, :3] = Rotation.from_rotvec(twist[3:]).as_matrix() @ frames[:, fi, :3, :3]
    out[:, fi, :3, 3] = frames[:, fi, :3, 3] + twist[:3]
    return out


def fd_frames(m, frames, p, meta=None, eps=EPS):
    S = frames.shape[0]
    J = np.zeros((S, m.n_obs, len(m.frames), 6))
    for k, fi in enumerate(m.frames):
        for j in range(6):
            tw = np.zeros(6)
            tw[j] = eps
            yp = m.predict(perturb(frames, fi, tw), p, meta)
            ym = m.predict(perturb(frames, fi, -tw), p, meta)
            J[:, :, k, j] = (yp - ym) / (2 * eps)
    return J


def fd_params(m, frames, p, meta=None, eps=EPS):
    J = np.zeros((frames.shape[0], m.n_obs, p.size))
    for i in range(p.size):
        dp = np.zeros(p.size)
        dp[i] = eps
        J[:, :, i] = (m.predict(frames, p + dp, meta) - m.predict(frames, p - dp, meta)) / (2 * eps)
    return J


def check_jacobians(m, frames, p, meta=None, tol=1e-6):
    y, jf, jp = m.jacobians(frames, p, meta)
    np.testing.assert_allclose(y, m.predict(frames, p, meta), atol=1e-12)
    assert jf.shape == (frames.shape[0], m.n_obs, len(m.frames), 6)
    assert jp.shape == (frames.shape[0], m.n_obs, m.params.size)
    scale = max(1.0, np.abs(jf).max(initial=0.0), np.abs(jp).max(initial=0.0))
    np.testing.assert_allclose(jf, fd_frames(m, frames, p, meta), atol=tol * scale)
    np.testing.assert_allclose(jp, fd_params(m, frames, p, meta), atol=tol * scale)


def check_chain_rule(m, robot, q, p, meta=None, tol=1e-6, *, device):
    """dy/dq = sum_f J_frames[f] @ jacobian(robot, q, frame f) equals FD of predict(fk(q))."""
    _, jf, _ = m.jacobians(fk64(robot, q, device), p, meta)
    dydq = np.zeros((q.shape[0], m.n_obs, robot.n_dof))
    for k, fi in enumerate(m.frames):
        Jq = np.asarray(jwarp.jacobian(robot, q, fi, device=device, dtype="float64"))
        dydq += jf[:, :, k, :] @ Jq
    fd = np.zeros_like(dydq)
    for j in range(robot.n_dof):
        dq = np.zeros(robot.n_dof)
        dq[j] = EPS
        fd[:, :, j] = (m.predict(fk64(robot, q + dq, device), p, meta)
                       - m.predict(fk64(robot, q - dq, device), p, meta)) / (2 * EPS)
    np.testing.assert_allclose(dydq, fd, atol=tol * max(1.0, np.abs(fd).max()))


@pytest.fixture(scope="module")
def justin():
    return jwarp.robot("justin19")


@pytest.fixture(scope="module")
def hand():
    return jwarp.robot("hand4")


def justin_q(robot, n, seed):
    q = sample_q(robot, n, seed=seed)
    q[:, 2] = np.clip(q[:, 2], np.maximum(0, -q[:, 1]), np.deg2rad(135) - np.maximum(q[:, 1], 0))
    return q


# --------------------------------------------------------------- cartesian
CART = {"plugin": "cartesian",
        "tracker": {"position": [2.5, 0.3, 1.2], "rotvec": [0.1, -0.2, 2.8],
                    "sigma_position": 1.0, "sigma_rotation": 1.0},
        "markers": [{"name": "right", "frame": "right_tcp", "position": [0.01, -0.02, 0.05],
                     "sigma": 0.05},
                    {"name": "left", "frame": "left_tcp", "position": [0.0, 0.03, 0.04]},
                    {"name": "right2", "frame": "right_tcp", "position": [0.05, 0.0, 0.0]}],
        "noise": 0.001}


def test_cartesian_predict_matches_numpy(device, justin):
    m = measurement("cartesian")(justin, CART)
    assert m.obs_names == ["right_x", "right_y", "right_z", "left_x", "left_y", "left_z",
                           "right2_x", "right2_y", "right2_z"]
    assert m.params.names[:6] == ["tracker_px", "tracker_py", "tracker_pz",
                                  "tracker_rx", "tracker_ry", "tracker_rz"]
    assert m.params.groups.count("tracker") == 6 and m.params.groups.count("markers") == 9
    q = justin_q(justin, 5, seed=0)
    F = fk64(justin, q, device)
    y = m.predict(F, m.params.nominal)
    Tinv = np.linalg.inv(pose(CART["tracker"]["position"], CART["tracker"]["rotvec"]))
    for s in range(5):
        for k, mk in enumerate(CART["markers"]):
            x = Tinv @ F[s, justin.frame_index(mk["frame"])] @ np.r_[mk["position"], 1.0]
            np.testing.assert_allclose(y[s, 3 * k:3 * k + 3], x[:3], atol=1e-12)


def test_cartesian_jacobians_fd_and_chain_rule(device, justin):
    m = measurement("cartesian")(justin, CART)
    q = justin_q(justin, 4, seed=1)
    p = m.params.nominal + np.random.default_rng(0).normal(0, 0.01, m.params.size)
    check_jacobians(m, fk64(justin, q, device), p)
    check_chain_rule(m, justin, q, p, device=device)


def test_cartesian_initial_guess_recovers_tracker(device, justin):
    m = measurement("cartesian")(justin, CART)
    q = justin_q(justin, 30, seed=2)
    F = fk64(justin, q, device)
    p_true = m.params.nominal.copy()
    y = m.simulate(F, p_true, 0.0005, np.random.default_rng(1))
    p0 = p_true.copy()
    p0[:3] += np.array([0.3, -0.2, 0.1]) / np.linalg.norm([0.3, -0.2, 0.1]) * 0.3
    p0[3:6] = (Rotation.from_rotvec([0.0, 0.0, np.deg2rad(30)])
               * Rotation.from_rotvec(p_true[3:6])).as_rotvec()
    err0 = np.abs(m.predict(F, p0) - y).mean()
    p1 = m.initial_guess(F, y, p0)
    assert np.linalg.norm(p1[:3] - p_true[:3]) < 2e-3
    ang = (Rotation.from_rotvec(p1[3:6]).inv() * Rotation.from_rotvec(p_true[3:6])).magnitude()
    assert ang < np.deg2rad(0.2)
    np.testing.assert_array_equal(p1[6:], p0[6:])
    assert np.abs(m.predict(F, p1) - y).mean() < 0.002 < err0


def test_cartesian_simulate_noise(device, justin):
    m = measurement("cartesian")(justin, CART)
    F = fk64(justin, justin_q(justin, 400, seed=3), device)
    y = m.simulate(F, m.params.nominal, 0.002, np.random.default_rng(5))
    r = y - m.predict(F, m.params.nominal)
    assert abs(r.std() - 0.002) < 2e-4
    with pytest.raises(ValueError, match="noise_sigma"):
        m.simulate(F, m.params.nominal, -1.0, np.random.default_rng(0))


# ------------------------------------------------------------------- image
R_FIXED = np.array([[0.0, 0.0, -1.0], [1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])  # looks along -x
R_HEAD = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])   # looks along head x
INTR = {"focal": [600.0, 610.0], "center": [640.0, 480.0], "xi": 0.08, "size": [1280, 960]}


def image_setup(fixed: bool, xi: float = 0.08) -> dict:
    intr = dict(INTR, xi=xi)
    if fixed:
        cam = {"frame": None, "position": [2.2, 0.1, 1.3],
               "rotvec": Rotation.from_matrix(R_FIXED).as_rotvec().tolist(),
               "sigma_position": 1.0, "sigma_rotation": 1.0}
        markers = [{"name": "right", "frame": "right_tcp", "position": [0.0, 0.0, 0.05]},
                   {"name": "left", "frame": "left_tcp", "position": [0.02, 0.0, 0.04]},
                   {"name": "pole", "frame": None, "position": [1.2, 0.3, 1.0]},
                   {"name": "pole2", "frame": None, "position": [1.0, -0.2, 1.4]}]
    else:
        cam = {"frame": "head_tcp", "position": [0.05, 0.0, 0.08],
               "rotvec": Rotation.from_matrix(R_HEAD).as_rotvec().tolist()}
        markers = [{"name": "right", "frame": "right_tcp", "position": [0.0, 0.0, 0.05]},
                   {"name": "left", "frame": "left_tcp", "position": [0.02, 0.0, 0.04]},
                   # a marker on the camera's own frame: its pixels do not depend on q
                   {"name": "visor", "frame": "head_tcp", "position": [0.4, 0.05, 0.1]}]
    return {"plugin": "image", "camera": cam, "intrinsics": intr, "markers": markers,
            "noise": 1.0}


def visible_q(robot, m, n, seed, device):
    q = justin_q(robot, 100 * n, seed=seed)
    ok = m.visible(fk64(robot, q, device), m.params.nominal).all(axis=1)
    assert ok.sum() >= n, "too few configurations with all markers in view"
    return q[ok][:n]


def camera_pose(m, F, p):
    Tm = pose(p[:3], p[3:6])
    return Tm[None] if m.camera_frame is None else F[:, m.camera_frame] @ Tm


@pytest.mark.parametrize("fixed", [True, False])
def test_image_predict_matches_numpy(device, justin, fixed):
    setup = image_setup(fixed)
    m = measurement("image")(justin, setup)
    assert m.unit == "px" and m.obs_names[:4] == ["right_u", "right_v", "left_u", "left_v"]
    assert m.params.names[-5:] == [f"intrinsics_{k}" for k in ("fx", "fy", "cx", "cy", "xi")]
    assert m.params.groups.count("intrinsics") == 5 and m.params.groups.count("camera") == 6
    q = visible_q(justin, m, 6, seed=10, device=device)
    F = fk64(justin, q, device)
    y = m.predict(F, m.params.nominal)
    Tc = camera_pose(m, F, m.params.nominal)
    fx, fy = INTR["focal"]
    cx, cy = INTR["center"]
    for s in range(q.shape[0]):
        for k, mk in enumerate(setup["markers"]):
            Tf = np.eye(4) if mk["frame"] is None else F[s, justin.frame_index(mk["frame"])]
            xc = np.linalg.inv(Tc[min(s, len(Tc) - 1)]) @ Tf @ np.r_[mk["position"], 1.0]
            a, b = xc[0] / xc[2], xc[1] / xc[2]
            den = 1 + 0.08 * (a * a + b * b)
            np.testing.assert_allclose(y[s, 2 * k:2 * k + 2], [cx + fx * a / den, cy + fy * b / den],
                                       atol=1e-9)


def test_image_matches_opencv_without_distortion(device, justin):
    cv2 = pytest.importorskip("cv2")
    m = measurement("image")(justin, image_setup(True, xi=0.0))
    q = visible_q(justin, m, 5, seed=11, device=device)
    F = fk64(justin, q, device)
    p = m.params.nominal
    y = m.predict(F, p).reshape(5, -1, 2)
    Rc = Rotation.from_rotvec(p[3:6]).as_matrix()
    K = np.array([[600.0, 0, 640.0], [0, 610.0, 480.0], [0, 0, 1]])
    rvec = Rotation.from_matrix(Rc.T).as_rotvec()
    tvec = -Rc.T @ p[:3]
    for k, mk in enumerate(image_setup(True)["markers"]):
        Tf = (np.broadcast_to(np.eye(4), (5, 4, 4)) if mk["frame"] is None
              else F[:, justin.frame_index(mk["frame"])])
        xw = (Tf @ np.r_[mk["position"], 1.0])[:, :3]
        uv, _ = cv2.projectPoints(np.ascontiguousarray(xw).reshape(-1, 1, 3), rvec, tvec, K, None)
        np.testing.assert_allclose(y[:, k], uv.reshape(-1, 2), atol=1e-8)


@pytest.mark.parametrize("fixed", [True, False])
def test_image_jacobians_fd_and_chain_rule(device, justin, fixed):
    m = measurement("image")(justin, image_setup(fixed))
    q = visible_q(justin, m, 4, seed=12, device=device)
    p = m.params.nominal + np.random.default_rng(1).normal(0, 1e-3, m.params.size)
    check_jacobians(m, fk64(justin, q, device), p, tol=1e-6)
    check_chain_rule(m, justin, q, p, tol=1e-6, device=device)
    if not fixed:  # closed loop: both the camera frame and the hand frames appear
        assert set(m.frames) == {justin.frame_index(f) for f in ("head_tcp", "right_tcp", "left_tcp")}
        # the visor marker rides on the camera frame: its pixels do not depend on that frame
        _, jf, _ = m.jacobians(fk64(justin, q, device), p)
        np.testing.assert_allclose(jf[:, 4:6], 0.0, atol=1e-9)


@pytest.mark.parametrize("fixed", [True, False])
def test_image_initial_guess_recovers_camera(device, justin, fixed):
    m = measurement("image")(justin, image_setup(fixed))
    q = visible_q(justin, m, 20, seed=13, device=device)
    F = fk64(justin, q, device)
    p_true = m.params.nominal.copy()
    y = m.simulate(F, p_true, 0.5, np.random.default_rng(2))
    p0 = p_true.copy()
    p0[:3] += np.array([0.2, 0.2, -0.1])  # 0.3 m
    p0[3:6] = (Rotation.from_rotvec(p_true[3:6]) * Rotation.from_rotvec([0.3, -0.3, 0.3])
               ).as_rotvec()  # about 30 deg
    p1 = m.initial_guess(F, y, p0)
    assert np.linalg.norm(p1[:3] - p_true[:3]) < 5e-3
    ang = (Rotation.from_rotvec(p1[3:6]).inv() * Rotation.from_rotvec(p_true[3:6])).magnitude()
    assert ang < np.deg2rad(0.5)
    assert np.abs(m.predict(F, p1) - y).mean() < 2.0 < np.abs(m.predict(F, p0) - y).mean()


# ----------------------------------------------------------------- contact
from scipy.optimize import minimize  # noqa: E402

from jwarp.plugins.measurements.contact import closest_segments  # noqa: E402

TIPS = ["thumb", "index", "middle", "ring"]
HAND_PAIRS = [[a, b] for i, a in enumerate(TIPS) for b in TIPS[i + 1:]]


def seg_dist_ref(a0, a1, b0, b1):
    """Brute force: grid over (s, t), then a bounded quasi-Newton polish."""
    grid = np.linspace(0, 1, 41)
    P = a0 + grid[:, None] * (a1 - a0)
    Q = b0 + grid[:, None] * (b1 - b0)
    D = np.linalg.norm(P[:, None] - Q[None], axis=-1)
    i, j = np.unravel_index(np.argmin(D), D.shape)
    fun = lambda st: np.linalg.norm(a0 + st[0] * (a1 - a0) - b0 - st[1] * (b1 - b0))  # noqa: E731
    res = minimize(fun, [grid[i], grid[j]], bounds=[(0, 1), (0, 1)], method="L-BFGS-B",
                   options={"ftol": 1e-15, "gtol": 1e-12})
    return min(res.fun, D[i, j])


def test_closest_segments_against_brute_force():
    rng = np.random.default_rng(3)
    a0, a1, b0, b1 = (rng.normal(size=(60, 3)) for _ in range(4))
    a1[:5] = a0[:5]                                  # point vs segment
    b1[5:10] = b0[5:10]                              # segment vs point
    a1[10:12], b1[10:12] = a0[10:12], b0[10:12]      # point vs point
    b1[12:18] = b0[12:18] + 0.7 * (a1[12:18] - a0[12:18])   # parallel segments
    ca, cb = closest_segments(a0, a1, b0, b1)
    got = np.linalg.norm(ca - cb, axis=1)
    ref = np.array([seg_dist_ref(*x) for x in zip(a0, a1, b0, b1)])
    np.testing.assert_allclose(got, ref, atol=1e-7)


def hand_contact(extra_bodies=(), extra_pairs=()):
    bodies = [{"name": t, "robot_capsule": f"{t}_distal"} for t in TIPS]
    return {"plugin": "contact", "bodies": bodies + list(extra_bodies),
            "pairs": HAND_PAIRS + list(extra_pairs), "noise": 0.0005}


def test_contact_capsules_match_relative_frame_reference(device, hand):
    m = measurement("contact")(hand, hand_contact())
    assert m.obs_names == ["distance"] and m.meta_names == ["pair"]
    assert m.params.names == [f"{t}_radius" for t in TIPS]
    np.testing.assert_allclose(m.params.nominal, 0.009)
    q = sample_q(hand, 12, seed=4)
    F = fk64(hand, q, device)
    meta = {"pair": np.arange(12) % len(HAND_PAIRS)}
    y = m.predict(F, m.params.nominal, meta)
    caps = {hand.frames[c.frame].name: c for c in hand.capsules}
    for s in range(12):
        a, b = HAND_PAIRS[meta["pair"][s]]
        ca, cb = caps[f"{a}_distal"], caps[f"{b}_distal"]
        # eq. 2.43: the distance depends on the relative frame inv(T_A) T_B only
        T_ab = np.linalg.inv(F[s, ca.frame]) @ F[s, cb.frame]
        b0 = (T_ab @ np.r_[cb.p0, 1])[:3]
        b1 = (T_ab @ np.r_[cb.p1, 1])[:3]
        ref = seg_dist_ref(ca.p0, ca.p1, b0, b1) - ca.radius - cb.radius
        assert abs(y[s, 0] - ref) < 1e-7


def test_contact_capsules_jacobians_fd_and_chain_rule(device, hand):
    m = measurement("contact")(hand, hand_contact())
    q = sample_q(hand, 12, seed=5)
    meta = {"pair": (np.arange(12) * 5) % len(HAND_PAIRS)}
    p = m.params.nominal + np.array([0.001, -0.0005, 0.0, 0.0007])
    check_jacobians(m, fk64(hand, q, device), p, meta)
    check_chain_rule(m, hand, q, p, meta, device=device)


BOX = {"name": "block", "type": "mesh", "frame": None, "box": [0.04, 0.06, 0.03],
       "position": [0.11, 0.01, 0.05], "rotvec": [0.2, -0.1, 0.3]}
BALL = {"name": "ball", "type": "sphere", "frame": "index_distal", "center": [0.015, 0.0, 0.0],
        "radius": 0.006}


def box_sd(x, half):
    """Outside-positive signed distance of points x (..., 3) to a centred box."""
    d = np.abs(x) - half
    return np.linalg.norm(np.maximum(d, 0), axis=-1) + np.minimum(d.max(axis=-1), 0)


def test_contact_mesh_fixture_matches_analytic_box(device, hand):
    pytest.importorskip("trimesh")
    setup = hand_contact([BOX, BALL], [["block", "thumb"], ["ball", "block"], ["index", "ball"]])
    m = measurement("contact")(hand, setup)
    assert m.params.groups.count("fixtures") == 6 and "ball_radius" in m.params.names
    q = sample_q(hand, 9, seed=6)
    F = fk64(hand, q, device)
    meta = {"pair": np.array([6, 7, 8] * 3)}
    p = m.params.nominal
    y = m.predict(F, p, meta)
    Tbox = pose(BOX["position"], BOX["rotvec"])
    half = np.array(BOX["box"]) / 2
    cap = [c for c in hand.capsules if hand.frames[c.frame].name == "thumb_distal"][0]
    idx = [c for c in hand.capsules if hand.frames[c.frame].name == "index_distal"][0]
    for s in range(9):
        pr = meta["pair"][s]
        if pr == 6:   # thumb capsule vs box: minimize the analytic box distance along the axis
            T = np.linalg.inv(Tbox) @ F[s, cap.frame]
            a0, a1 = (T @ np.r_[cap.p0, 1])[:3], (T @ np.r_[cap.p1, 1])[:3]
            ts = np.linspace(0, 1, 20001)
            ref = box_sd(a0 + ts[:, None] * (a1 - a0), half).min() - cap.radius
            assert abs(y[s, 0] - ref) < 1e-7
        elif pr == 7:  # ball vs box
            c = (np.linalg.inv(Tbox) @ F[s, hand.frame_index("index_distal")] @ np.r_[BALL["center"], 1])[:3]
            assert abs(y[s, 0] - (box_sd(c, half) - BALL["radius"])) < 1e-9
        else:          # index capsule vs ball on the same frame: constant
            ref = seg_dist_ref(idx.p0, idx.p1, np.array(BALL["center"]), np.array(BALL["center"]))
            assert abs(y[s, 0] - (ref - idx.radius - BALL["radius"])) < 1e-9


def test_contact_mesh_jacobians_fd_and_chain_rule(device, hand):
    pytest.importorskip("trimesh")
    setup = hand_contact([BOX, BALL], [["block", "thumb"], ["ball", "block"]])
    m = measurement("contact")(hand, setup)
    q = sample_q(hand, 6, seed=7)
    meta = {"pair": np.array([6, 7] * 3)}
    p = m.params.nominal
    check_jacobians(m, fk64(hand, q, device), p, meta, tol=2e-5)
    check_chain_rule(m, hand, q, p, meta, tol=2e-5, device=device)


def test_mesh_signed_distance_box_inside_and_outside():
    trimesh = pytest.importorskip("trimesh")
    from jwarp.plugins.measurements.contact import mesh_signed_distance
    half = np.array([0.02, 0.03, 0.015])
    mesh = trimesh.creation.box(extents=2 * half)
    pts = np.random.default_rng(8).uniform(-0.05, 0.05, size=(300, 3))
    pts[:40] *= 0.3  # some points inside
    d, c, _ = mesh_signed_distance(mesh, pts, chunk=1000)  # several chunks
    np.testing.assert_allclose(d, box_sd(pts, half), atol=1e-12)
    assert (d < 0).sum() >= 30
    np.testing.assert_allclose(np.abs(d), np.linalg.norm(pts - c, axis=1), atol=1e-12)


# ---------------------------------------------------------------- relative
REL = {"plugin": "relative",
       "end_effectors": ["thumb_tip",
                         {"name": "index", "frame": "index_tip", "position": [0.001, 0.0, -0.002]},
                         {"name": "middle", "frame": "middle_tip", "sigma": 0.005},
                         {"frame": "ring_tip", "position": [0.0, 0.003, 0.0]}],
       "noise": 0.001}


@pytest.mark.parametrize("free", [False, True])
def test_relative_predict_and_jacobians(device, hand, free):
    m = measurement("relative")(hand, dict(REL, free_offsets=free))
    assert m.obs_names == ["index_x", "index_y", "index_z", "middle_x", "middle_y", "middle_z",
                           "ring_tip_x", "ring_tip_y", "ring_tip_z"]
    assert m.params.size == (12 if free else 0)
    q = sample_q(hand, 5, seed=9)
    F = fk64(hand, q, device)
    p = m.params.nominal
    y = m.predict(F, p)
    offs = [[0, 0, 0], [0.001, 0.0, -0.002], [0, 0, 0], [0.0, 0.003, 0.0]]
    frames = ["thumb_tip", "index_tip", "middle_tip", "ring_tip"]
    for s in range(5):
        x = [(F[s, hand.frame_index(fr)] @ np.r_[o, 1])[:3] for fr, o in zip(frames, offs)]
        np.testing.assert_allclose(y[s], np.concatenate([x[k] - x[0] for k in (1, 2, 3)]),
                                   atol=1e-12)
    if free:
        p = p + np.random.default_rng(2).normal(0, 0.002, p.size)
    check_jacobians(m, F, p)
    check_chain_rule(m, hand, q, p, device=device)


def test_relative_same_frame_cancels(device, hand):
    m = measurement("relative")(hand, {"plugin": "relative", "end_effectors": [
        "index_tip", {"name": "b", "frame": "index_tip", "position": [0.01, 0, 0]}]})
    F = fk64(hand, sample_q(hand, 3, seed=1), device)
    _, jf, _ = m.jacobians(F, m.params.nominal)
    np.testing.assert_allclose(jf[..., :3], 0.0, atol=1e-15)   # translation cancels
    check_jacobians(m, F, m.params.nominal)


# ------------------------------------------------------ registry, validation
def test_registry_lists_and_looks_up_plugins(hand):
    from jwarp.model.measurement import Measurement
    assert {"cartesian", "image", "contact", "relative"} <= set(jwarp.measurements())
    for name in ("cartesian", "image", "contact", "relative"):
        cls = measurement(name)
        assert issubclass(cls, Measurement) and cls.name == name
    with pytest.raises(ValueError, match="unknown measurement 'laser'.*cartesian"):
        measurement("laser")


def _bad(setup, path, value):
    s = copy.deepcopy(setup)
    d = s
    for key in path[:-1]:
        d = d[key]
    if value is KeyError:
        del d[path[-1]]
    else:
        d[path[-1]] = value
    return s


@pytest.mark.parametrize("path, value, match", [
    (("markers", 0, "frame"), "right_hand", "setup.markers\\[0\\].frame: unknown frame 'right_hand'"),
    (("markers", 1, "position"), [0.0, 0.1], "setup.markers\\[1\\].position: expected 3"),
    (("markers", 0, "sigma"), -0.1, "setup.markers\\[0\\].sigma: must be > 0"),
    (("markers", 0, "position"), [0.0, float("nan"), 0.0], "position: contains NaN"),
    (("tracker", "rotvec"), [0.0, 0.0], "setup.tracker.rotvec"),
    (("tracker", "sigma_rotation"), 0.0, "sigma_rotation: must be > 0"),
    (("tracker",), KeyError, "setup: missing key 'tracker'"),
    (("markers",), [], "setup.markers"),
    (("noise",), -1.0, "setup.noise"),
    (("extra",), 1, "unknown key"),
    (("markers", 1, "name"), "right", "duplicate marker name 'right'"),
    (("plugin",), "image", "setup.plugin"),
])
def test_cartesian_setup_validation(justin, path, value, match):
    with pytest.raises(ValueError, match=match):
        measurement("cartesian")(justin, _bad(CART, path, value))


@pytest.mark.parametrize("path, value, match", [
    (("camera", "frame"), "eye", "setup.camera.frame: unknown frame 'eye'"),
    (("intrinsics", "focal"), [600.0, -1.0], "focal: must be > 0"),
    (("intrinsics", "center"), [1.0], "center: expected 2"),
    (("intrinsics", "xi"), float("nan"), "intrinsics.xi: contains NaN"),
    (("intrinsics", "sigma_xi"), -1, "sigma_xi"),
    (("markers", 2, "frame"), "pole_base", "unknown frame 'pole_base'"),
    (("camera", "position"), KeyError, "setup.camera: missing key 'position'"),
])
def test_image_setup_validation(justin, path, value, match):
    with pytest.raises(ValueError, match=match):
        measurement("image")(justin, _bad(image_setup(True), path, value))


@pytest.mark.parametrize("mutate, match", [
    (lambda s: s["pairs"].append(["thumb", "pinky"]), "pairs\\[6\\]: unknown body 'pinky'"),
    (lambda s: s["pairs"].append(["thumb", "thumb"]), "cannot touch itself"),
    (lambda s: s["bodies"].append({"name": "x", "type": "sphere", "frame": "nail",
                                   "center": [0, 0, 0], "radius": 0.01}), "unknown frame 'nail'"),
    (lambda s: s["bodies"].append({"name": "x", "type": "sphere", "frame": "palm",
                                   "center": [0, 0, 0], "radius": -0.01}), "radius: must be >= 0"),
    (lambda s: s["bodies"].append({"name": "x", "type": "cone", "frame": "palm"}), "unknown body type"),
    (lambda s: s["bodies"].append({"name": "x", "type": "mesh", "frame": None,
                                   "vertices": [[0, 0, 0], [1, 0, 0], [0, 1, 0]],
                                   "faces": [[0, 1, 2]]}), "watertight"),
    (lambda s: s["bodies"].append({"name": "x", "robot_capsule": "palm"}), "0 capsules on frame 'palm'"),
    (lambda s: s["bodies"].append({"name": "x", "robot_capsule": 9}), "out of range"),
    (lambda s: s["bodies"].extend([dict(BOX), dict(BOX, name="b2")]) or s["pairs"].append(["block", "b2"]),
     "mesh-mesh"),
    (lambda s: s.pop("pairs"), "missing key 'pairs'"),
])
def test_contact_setup_validation(hand, mutate, match):
    s = hand_contact()
    mutate(s)
    with pytest.raises(ValueError, match=match):
        measurement("contact")(hand, s)


def test_input_validation(device, hand):
    m = measurement("contact")(hand, hand_contact())
    F = fk64(hand, sample_q(hand, 3, seed=0), device)
    p = m.params.nominal
    with pytest.raises(ValueError, match="needs the per-sample column 'pair'"):
        m.predict(F, p)
    with pytest.raises(ValueError, match="meta\\['pair'\\]: index 6 out of range"):
        m.predict(F, p, {"pair": np.array([0, 6, 1])})
    with pytest.raises(ValueError, match="meta\\['pair'\\]: expected integer"):
        m.predict(F, p, {"pair": np.array([0, 0.5, 1])})
    with pytest.raises(ValueError, match="meta\\['pair'\\]: expected shape"):
        m.predict(F, p, {"pair": np.array([0, 1])})
    with pytest.raises(ValueError, match="p: expected shape \\(4,\\)"):
        m.predict(F, p[:3], {"pair": np.zeros(3)})
    with pytest.raises(ValueError, match="frames: expected shape"):
        m.predict(F[:, :5], p, {"pair": np.zeros(3)})
    bad = F.copy()
    bad[0, m.frames[0], 0, 3] = np.nan
    with pytest.raises(ValueError, match="frames: contains NaN"):
        m.predict(bad, p, {"pair": np.zeros(3)})
    r = measurement("relative")(hand, REL)
    with pytest.raises(ValueError, match="y: expected shape"):
        r.initial_guess(F, np.zeros((3, 2)), r.params.nominal)
    with pytest.raises(ValueError, match="at least two"):
        measurement("relative")(hand, {"plugin": "relative", "end_effectors": ["thumb_tip"]})
    with pytest.raises(ValueError, match="free_offsets"):
        measurement("relative")(hand, dict(REL, free_offsets="yes"))
    with pytest.raises(TypeError, match="setup"):
        measurement("relative")(hand, ["thumb_tip"])


def test_docs_setup_examples_build():
    """The JSON setup sections in docs/measurements.md are valid setups."""
    import json
    import re
    from pathlib import Path
    text = (Path(__file__).resolve().parents[2] / "docs" / "measurements.md").read_text()
    blocks = re.findall(r"```json\n(.*?)```", text, re.S)
    assert len(blocks) == 4
    built = set()
    for block in blocks:
        setup = json.loads(block)
        robot = jwarp.robot("hand4" if setup["plugin"] in ("contact", "relative") else "justin19")
        m = measurement(setup["plugin"])(robot, setup)
        assert m.params.size == len(m.params.names) and m.n_obs > 0
        built.add(m.name)
    assert built == {"cartesian", "image", "contact", "relative"}


@requires_cpu
def test_bench_measurements_quick(tmp_path):
    """The benchmark on its default device, the CPU."""
    import json
    import subprocess
    import sys
    from pathlib import Path
    root = Path(__file__).resolve().parents[2]
    out = tmp_path / "bench.json"
    proc = subprocess.run([sys.executable, str(root / "benchmarks" / "bench_measurements.py"),
                           "--quick", "--json", str(out)], cwd=root, capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    rows = json.loads(out.read_text())["rows"]
    assert {r["plugin"] for r in rows} == {"cartesian", "image", "contact capsules",
                                           "contact mesh", "relative"}
    assert all(r["samples_per_s"] > 0 for r in rows)
