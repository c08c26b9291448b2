"""Built-in robots: registration, sizes, JSON round trip and geometry.

Geometry is checked against a small plain-numpy DH chain written here from the convention
(SPEC.md, docs/robot_schema.md), independent of the Warp kernels::

    parent_T_child = Rot_y(beta) Rot_x(alpha) Trans_x(r) Rot_z(theta + q) Trans_z(d)
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

import jwarp
from jwarp.model import RobotModel
from jwarp.plugins.registry import BUILTIN_ROBOT_MODULES
from jwarp.plugins.robots import HERE

# name: (n_dof, n_frames)
SIZES = {
    "justin19": (19, 27),
    "arm7": (7, 9),
    "planar4": (4, 6),
    "planar5": (5, 7),
    "sphere2d": (2, 4),
    "hand4": (12, 25),
}
NEW = ["arm7", "planar4", "planar5", "sphere2d", "hand4"]


# ------------------------------------------------------------------ numpy DH chain
def rot_x(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1.0]])


def rot_y(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s, 0], [0, 1, 0, 0], [-s, 0, c, 0], [0, 0, 0, 1.0]])


def rot_z(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])


def trans(x, y, z):
    t = np.eye(4)
    t[:3, 3] = (x, y, z)
    return t


def fk(model: RobotModel, q) -> np.ndarray:
    """(n_frames, 4, 4) world transforms of all frames for one configuration ``q``."""
    q = np.asarray(q, np.float64)
    assert q.shape == (model.n_dof,)
    out = [None] * model.n_frames
    done = 0
    while done < model.n_frames:  # simple fixed-point over the tree, no model helpers
        for i, f in enumerate(model.frames):
            if out[i] is not None or (f.parent is not None and out[f.parent] is None):
                continue
            if f.kind == "static":
                local = np.asarray(f.transform, np.float64)
            else:
                d, theta, r, alpha, beta = np.asarray(f.dh, np.float64)
                qi = sum(c * q[j] for j, c in f.coupling)
                prismatic = bool(f.coupling) and model.joints[f.coupling[0][0]].type == "prismatic"
                if prismatic:
                    d += qi
                else:
                    theta += qi
                local = rot_y(beta) @ rot_x(alpha) @ trans(r, 0, 0) @ rot_z(theta) @ trans(0, 0, d)
            out[i] = local if f.parent is None else out[f.parent] @ local
            done += 1
    return np.stack(out)


def random_q(model: RobotModel, rng: np.random.Generator) -> np.ndarray:
    lim = np.array([[j.lower, j.upper] for j in model.joints])
    return rng.uniform(lim[:, 0], lim[:, 1])


def point(frames: np.ndarray, frame: int, p) -> np.ndarray:
    return frames[frame, :3, :3] @ np.asarray(p, np.float64) + frames[frame, :3, 3]


def fid(model: RobotModel, name: str) -> int:
    return model.frame_index(name)


# ------------------------------------------------------------------ collision helpers
def collision_bodies(model: RobotModel, frames: np.ndarray):
    """List of (frame, segment start, segment end, radius); a sphere is a 0-length segment."""
    bodies = []
    for s in model.spheres:
        c = point(frames, s.frame, s.position)
        bodies.append((s.frame, c, c, s.radius))
    for c in model.capsules:
        bodies.append((c.frame, point(frames, c.frame, c.p0), point(frames, c.frame, c.p1), c.radius))
    return bodies


def segment_distance(a0, a1, b0, b1, n=101) -> float:
    """Distance of two segments (dense sampling, exact for points)."""
    t = np.linspace(0.0, 1.0, n)[:, None]
    pa = a0 + t * (a1 - a0)
    pb = b0 + t * (b1 - b0)
    return float(np.min(np.linalg.norm(pa[:, None, :] - pb[None, :, :], axis=-1)))


def colliding_pairs(model: RobotModel, q) -> list[tuple[str, str, float]]:
    frames = fk(model, q)
    allowed = model.allowed_collision_pairs
    bodies = collision_bodies(model, frames)
    hits = []
    for i, (fa, a0, a1, ra) in enumerate(bodies):
        for fb, b0, b1, rb in bodies[i + 1:]:
            if fa == fb or not allowed[fa, fb]:
                continue
            gap = segment_distance(a0, a1, b0, b1) - ra - rb
            if gap < 0:
                hits.append((model.frames[fa].name, model.frames[fb].name, gap))
    return hits


# ------------------------------------------------------------------ registry, sizes, I/O
def test_all_builtins_registered():
    assert set(SIZES) <= set(jwarp.robots())
    for name in NEW:
        mod = "jwarp.plugins.robots." + ("planar" if name.startswith("planar") else name)
        assert mod in BUILTIN_ROBOT_MODULES
        assert (HERE / f"{name}.json").is_file()


@pytest.mark.parametrize("name", sorted(SIZES))
def test_sizes(name):
    m = jwarp.robot(name)
    assert isinstance(m, RobotModel)
    assert m.name == name
    assert (m.n_dof, m.n_frames) == SIZES[name]
    assert m.description
    assert m.end_effectors
    lim = m.joint_limits
    assert np.all(lim[:, 0] < lim[:, 1])
    assert all(x.mass > 0 for x in m.masses)
    assert all(s.radius > 0 for s in m.spheres)
    assert m.kappa.shape == (m.n_frames, 3)
    np.testing.assert_array_equal(m.gravity, [0.0, 0.0, -9.81])


@pytest.mark.parametrize("name", sorted(SIZES))
def test_save_load_round_trip(name, tmp_path):
    m = jwarp.robot(name)
    doc = m.to_dict()
    json.dumps(doc)  # plain JSON types only
    path = tmp_path / f"{name}.json"
    m.save(path)
    again = RobotModel.load(path)
    assert again.to_dict() == doc
    # the shipped file (names instead of indices in the new robots) gives the same model
    assert RobotModel.load(HERE / f"{name}.json").to_dict() == doc
    assert RobotModel.from_dict(json.loads(path.read_text())).to_dict() == doc


@pytest.mark.parametrize("name", NEW)
def test_home_pose_free_of_self_collision(name):
    m = jwarp.robot(name)
    q = np.clip(np.zeros(m.n_dof), m.joint_limits[:, 0], m.joint_limits[:, 1])
    assert colliding_pairs(m, q) == []


# ------------------------------------------------------------------ planar arms
@pytest.mark.parametrize("name,n,link", [("planar4", 4, 0.25), ("planar5", 5, 0.2)])
def test_planar_geometry(name, n, link):
    m = jwarp.robot(name)
    tcp = fid(m, "tcp")
    assert m.end_effectors == {"tcp": tcp}
    np.testing.assert_allclose(m.joint_limits, [[-math.radians(170), math.radians(170)]] * n)
    assert all(j.type == "revolute" for j in m.joints)
    f0 = fk(m, np.zeros(n))
    np.testing.assert_allclose(f0[tcp, :3, 3], [1.0, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(f0[fid(m, "base")], np.eye(4), atol=1e-12)
    # first joint at 90 deg: the arm points along +y
    q = np.zeros(n)
    q[0] = math.pi / 2
    np.testing.assert_allclose(fk(m, q)[tcp, :3, 3], [0.0, 1.0, 0.0], atol=1e-12)

    rng = np.random.default_rng(0)
    for _ in range(20):
        q = random_q(m, rng)
        f = fk(m, q)
        # everything stays in the plane z = 0 with z-axes along world z
        np.testing.assert_allclose(f[:, 2, 3], 0.0, atol=1e-12)
        np.testing.assert_allclose(f[:, :3, 2], np.tile([0.0, 0.0, 1.0], (m.n_frames, 1)), atol=1e-12)
        ang = np.cumsum(q)
        tip = link * np.array([np.cos(ang).sum(), np.sin(ang).sum(), 0.0])
        np.testing.assert_allclose(f[tcp, :3, 3], tip, atol=1e-12)
        for s in m.spheres:
            assert abs(point(f, s.frame, s.position)[2]) < 1e-12
            assert 0.04 <= s.radius <= 0.05


@pytest.mark.parametrize("name", ["planar4", "planar5"])
def test_planar_neighbours_never_collide(name):
    m = jwarp.robot(name)
    allowed = m.allowed_collision_pairs
    links = [fid(m, "base")] + [fid(m, f"link_{i + 1}") for i in range(m.n_dof)] + [fid(m, "tcp")]
    for a, b in zip(links[:-1], links[1:]):
        assert not allowed[a, b]
    for i in range(1, m.n_dof - 1):
        assert allowed[links[i], links[i + 2]]
    # fully folded, links two apart do collide
    q = np.zeros(m.n_dof)
    q[1] = q[2] = math.radians(170)
    assert colliding_pairs(m, q)


# ------------------------------------------------------------------ sphere2d
def test_sphere2d_position_is_q():
    m = jwarp.robot("sphere2d")
    assert [j.type for j in m.joints] == ["prismatic", "prismatic"]
    np.testing.assert_array_equal(m.joint_limits, [[-1.0, 1.0], [-1.0, 1.0]])
    p = fid(m, "point")
    assert m.end_effectors == {"point": p}
    (sf,), (sp,), (sr,) = m.sphere_arrays()
    assert sf == p and sr == 0.05
    np.testing.assert_array_equal(sp, [0.0, 0.0, 0.0])
    rng = np.random.default_rng(1)
    for q in [np.zeros(2), np.array([1.0, -1.0])] + [random_q(m, rng) for _ in range(20)]:
        f = fk(m, q)
        np.testing.assert_allclose(f[p, :3, 3], [q[0], q[1], 0.0], atol=1e-12)
        np.testing.assert_allclose(f[p, :3, :3], np.eye(3), atol=1e-12)
        # every frame origin: base at 0, slide_x at (q0, 0, 0), slide_y at (q0, q1, 0)
        np.testing.assert_allclose(f[fid(m, "slide_x"), :3, 3], [q[0], 0.0, 0.0], atol=1e-12)
        np.testing.assert_allclose(f[fid(m, "slide_y"), :3, 3], [q[0], q[1], 0.0], atol=1e-12)


# ------------------------------------------------------------------ hand4
FINGERS = ("thumb", "index", "middle", "ring")


def test_hand4_structure():
    m = jwarp.robot("hand4")
    c = m.coupling_matrix
    assert int(np.count_nonzero(np.any(c != 0, axis=1))) == 16
    assert len(m.capsules) == 4
    assert set(m.end_effectors) == {f"{f}_tip" for f in FINGERS}
    for f in FINGERS:
        distal = fid(m, f"{f}_distal")
        flex2 = m.joint_index(f"{f}_flex_2")
        expect = np.zeros(m.n_dof)
        expect[flex2] = 1.0
        np.testing.assert_array_equal(c[distal], expect)
        abd, f1, f2 = (m.joints[m.joint_index(f"{f}_{s}")] for s in ("abd", "flex_1", "flex_2"))
        assert (abd.lower, abd.upper) == pytest.approx((-math.radians(20), math.radians(20)))
        assert (f1.lower, f1.upper) == pytest.approx((0.0, math.radians(90)))
        assert (f2.lower, f2.upper) == pytest.approx((0.0, math.radians(90)))
        (cap,) = [x for x in m.capsules if x.frame == distal]
        assert 0.008 <= cap.radius <= 0.010
        assert m.frames[fid(m, f"{f}_base")].kind == "static"
        assert m.frames[fid(m, f"{f}_tip")].kind == "static"


def test_hand4_coupled_joint_and_parallel_axes():
    m = jwarp.robot("hand4")
    rng = np.random.default_rng(2)
    for _ in range(20):
        q = random_q(m, rng)
        f = fk(m, q)
        for fi in FINGERS:
            base, knuckle, prox, inter, dist, tip = (
                fid(m, f"{fi}_{s}") for s in ("base", "knuckle", "proximal", "intermediate", "distal", "tip"))
            q_abd, q_f1, q_f2 = (q[m.joint_index(f"{fi}_{s}")] for s in ("abd", "flex_1", "flex_2"))
            # passive joint: distal relative to intermediate is a rotation by q_flex_2
            rel = np.linalg.inv(f[inter]) @ f[dist]
            assert math.atan2(rel[1, 0], rel[0, 0]) == pytest.approx(q_f2, abs=1e-12)
            rel = np.linalg.inv(f[prox]) @ f[inter]
            assert math.atan2(rel[1, 0], rel[0, 0]) == pytest.approx(q_f2, abs=1e-12)
            # the three flexion axes are parallel, and normal to the abduction axis
            z = f[[prox, inter, dist], :3, 2]
            np.testing.assert_allclose(z, np.tile(z[0], (3, 1)), atol=1e-12)
            assert abs(z[0] @ f[knuckle, :3, 2]) < 1e-12
            np.testing.assert_allclose(f[knuckle, :3, 2], f[base, :3, 2], atol=1e-12)
            # abduction angle about the base z-axis
            rel = np.linalg.inv(f[base]) @ f[knuckle]
            assert math.atan2(rel[1, 0], rel[0, 0]) == pytest.approx(q_abd, abs=1e-12)
            # phalanx lengths 45 / 25 / 20 mm; the tip lies in the flexion plane
            assert np.linalg.norm(f[inter, :3, 3] - f[prox, :3, 3]) == pytest.approx(0.045)
            assert np.linalg.norm(f[dist, :3, 3] - f[inter, :3, 3]) == pytest.approx(0.025)
            assert np.linalg.norm(f[tip, :3, 3] - f[dist, :3, 3]) == pytest.approx(0.020)
            # the fingertip capsule ends exactly at the tip frame
            (cap,) = [x for x in m.capsules if x.frame == dist]
            end = point(f, dist, cap.p1) + cap.radius * f[dist, :3, 0]
            np.testing.assert_allclose(end, f[tip, :3, 3], atol=1e-12)


def test_hand4_open_and_flexed():
    m = jwarp.robot("hand4")
    f = fk(m, np.zeros(m.n_dof))
    # open hand: index, middle, ring stretched along palm x, 90 mm beyond their bases
    for fi in ("index", "middle", "ring"):
        base = f[fid(m, f"{fi}_base"), :3, 3]
        np.testing.assert_allclose(f[fid(m, f"{fi}_tip"), :3, 3], base + [0.09, 0.0, 0.0], atol=1e-12)
    # palm about 9 cm wide between the outer finger bases + phalanx radii
    width = f[fid(m, "index_base"), 1, 3] - f[fid(m, "ring_base"), 1, 3]
    assert 0.05 <= width <= 0.09
    # 90 deg at the first flexion joint: the proximal phalanx points out of the palm (+z)
    q = np.zeros(m.n_dof)
    q[m.joint_index("index_flex_1")] = math.pi / 2
    f = fk(m, q)
    np.testing.assert_allclose(f[fid(m, "index_proximal"), :3, 0], [0.0, 0.0, 1.0], atol=1e-12)
    # 90 deg at flex_2 bends intermediate and distal (coupled) by 90 deg each
    q[m.joint_index("index_flex_2")] = math.pi / 2
    f = fk(m, q)
    np.testing.assert_allclose(f[fid(m, "index_intermediate"), :3, 0], [-1.0, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(f[fid(m, "index_distal"), :3, 0], [0.0, 0.0, -1.0], atol=1e-12)


# ------------------------------------------------------------------ arm7 vs justin19
def test_arm7_equals_justin_right_arm():
    arm, justin = jwarp.robot("arm7"), jwarp.robot("justin19")
    arm_joints = [f"right_{i}" for i in range(1, 8)]
    assert arm.joint_names == arm_joints
    jidx = [justin.joint_index(n) for n in arm_joints]
    np.testing.assert_array_equal(arm.joint_limits, justin.joint_limits[jidx])
    assert fid(arm, "tcp") == fid(arm, "right_tcp") == arm.end_effectors["right_tcp"]
    base = fid(arm, "right_base")
    assert arm.frames[base].parent is None and arm.frames[base].kind == "static"
    np.testing.assert_array_equal(arm.frames[base].transform, [[1, 0, 0, 0], [0, 1, 0, 0],
                                                                [0, 0, 1, 0.5], [0, 0, 0, 1]])
    # same DH rows, masses and spheres per frame name
    for f in arm.frames[1:]:
        g = justin.frames[fid(justin, f.name)]
        assert f.kind == g.kind
        if f.kind == "dh":
            np.testing.assert_array_equal(f.dh, g.dh)
        else:
            np.testing.assert_array_equal(f.transform, g.transform)

    def per_frame(model, items, attrs):
        return sorted((model.frames[x.frame].name,) + tuple(np.ravel(getattr(x, a)).tolist() for a in attrs)
                      for x in items)

    names = set(arm.frame_names)
    jm = [x for x in justin.masses if justin.frames[x.frame].name in names]
    js = [x for x in justin.spheres if justin.frames[x.frame].name in names]
    assert per_frame(arm, arm.masses, ["mass", "com"]) == per_frame(justin, jm, ["mass", "com"])
    assert per_frame(arm, arm.spheres, ["position", "radius"]) == per_frame(justin, js, ["position", "radius"])
    assert len(arm.masses) == 8 and len(arm.spheres) == 14
    # self-collision: same allowed pairs among the arm's frames
    jf = [fid(justin, n) for n in arm.frame_names]
    np.testing.assert_array_equal(arm.allowed_collision_pairs,
                                  justin.allowed_collision_pairs[np.ix_(jf, jf)])

    # kinematics: right_base_T_right_tcp identical for the same 7 joint values
    rng = np.random.default_rng(3)
    for _ in range(20):
        qa = random_q(arm, rng)
        qj = random_q(justin, rng)  # any torso / left arm / head values
        qj[jidx] = qa
        fa, fj = fk(arm, qa), fk(justin, qj)
        for name in arm.frame_names:
            rel_a = np.linalg.inv(fa[fid(arm, "right_base")]) @ fa[fid(arm, name)]
            rel_j = np.linalg.inv(fj[fid(justin, "right_base")]) @ fj[fid(justin, name)]
            np.testing.assert_allclose(rel_a, rel_j, atol=1e-12)

    # at q = 0 the arm stands straight up from its base
    f0 = fk(arm, np.zeros(7))
    np.testing.assert_allclose(f0[fid(arm, "tcp"), :3, 3], [0.0, 0.0, 0.5 + 0.4 + 0.39 + 0.118], atol=1e-12)
