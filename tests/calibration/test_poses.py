"""Measurement-pose sampling (jwarp.calibration.design.poses) and TSP ordering (tour.py)
against an independent numpy reference: FK frames (float64), sphere centres, the view cone,
the facing angle, segment-sphere occlusion and sphere-pair distances written out here."""

import itertools
import math

import numpy as np
import pytest
from reference import ref_fk

from jwarp.calibration.design.poses import (
    CONTAIN_TOL,
    PoseOptions,
    PoseSampler,
    parse_cameras,
    plan_text,
    write_plan,
)
from jwarp.calibration.design.tour import order_poses, path_length
from jwarp.calibration.files import read_setup, write_setup
from jwarp.calibration.simulate.campaign import justin_tracker_setup, simulate_campaign
from jwarp.core.limits import within_limits
from jwarp.kinematics.fk import fk
from jwarp.plugins.registry import robot as get_robot
from jwarp.world.collision import collision_pairs


@pytest.fixture(scope="module")
def justin():
    return get_robot("justin19")


def ring_cameras(n=6, radius=2.5, height=2.2, fov=70.0, rng=(0.5, 6.0)):
    return [{"name": f"c{i}", "pose": {"position": [radius * math.cos(a), radius * math.sin(a),
                                                    height], "look_at": [0.3, 0.0, 1.0]},
             "fov": fov, "range": list(rng)} for i, a in enumerate(np.linspace(-1.2, 1.2, n))]


def tracker_setup(cameras, normals=None):
    s = justin_tracker_setup()
    s.cameras = cameras
    s.marker_normals = normals
    return s


# ------------------------------------------------------------------ numpy reference
def ref_check(robot, setup, q, opt):
    """(code (N,), seen (N, M)) by plain numpy, the kernel's rules (module docstring of
    jwarp.kernels.visibility) re-derived: 0 ok, 1 limits, 2 not seen, 3 many, 4 self."""
    cams = parse_cameras(setup.cameras) if setup.cameras else []
    F = ref_fk(robot, q)                                                # (N, nf, 4, 4)
    sf, sp, sr = (np.asarray(a) for a in robot.sphere_arrays())
    Fs = F[:, sf]                                                       # (N, S, 4, 4)
    xs = np.einsum("nsij,sj->nsi", Fs[..., :3, :3], sp) + Fs[..., :3, 3]
    markers = setup.section["markers"] if cams else []
    names = [m["name"] for m in markers]
    normals = setup.marker_normals or {}
    N, M = len(q), len(names)
    seen = np.zeros((N, M), np.int64)
    code = np.zeros(N, np.int64)
    inside = within_limits(robot, q, tol=0.0)
    cos_max = -2.0 if opt.max_angle is None else math.cos(math.radians(opt.max_angle))
    for m, mk in enumerate(markers):
        fi = robot.frame_index(mk["frame"])
        n_loc = np.asarray(normals.get(mk["name"], [0, 0, 1.0]), float)
        n_loc = n_loc / np.linalg.norm(n_loc)
        x = F[:, fi, :3, :3] @ np.asarray(mk["position"], float) + F[:, fi, :3, 3]
        nw = F[:, fi, :3, :3] @ n_loc
        for c in cams:
            v = x - c.position
            dist = np.linalg.norm(v, axis=1)
            ok = (dist >= c.near) & (dist <= c.far)
            ok &= v @ c.axis >= math.cos(math.radians(c.fov) / 2) * dist
            ok &= -np.einsum("ni,ni->n", nw, v) >= cos_max * dist
            # occlusion: segment camera -> marker against every sphere not holding the marker
            d = x - c.position                                               # (N, 3)
            t = np.clip(np.einsum("nsi,ni->ns", xs - c.position, d)
                        / np.einsum("ni,ni->n", d, d)[:, None], 0.0, 1.0)
            closest = c.position + t[..., None] * d[:, None, :]
            hit = np.linalg.norm(closest - xs, axis=-1) < sr
            holds = np.linalg.norm(x[:, None, :] - xs, axis=-1) < sr + CONTAIN_TOL
            ok &= ~np.any(hit & ~holds, axis=1)
            seen[:, m] += ok
    if cams:
        n_seen = (seen >= opt.k_of_n).sum(1)
        not_seen = (n_seen == 0) if opt.require == "any" else (n_seen < M)
        many = (seen > 0).sum(1) > 1 if opt.single_marker else np.zeros(N, bool)
    else:
        not_seen = many = np.zeros(N, bool)
    pairs = collision_pairs(robot)
    dmin = (np.linalg.norm(xs[:, pairs[:, 0]] - xs[:, pairs[:, 1]], axis=-1)
            - sr[pairs[:, 0]] - sr[pairs[:, 1]]).min(axis=1)
    selfc = dmin < opt.margin if opt.self_collision else np.zeros(N, bool)
    code[:] = np.select([~inside, not_seen, many, selfc], [1, 2, 3, 4], 0)
    seen[~inside] = 0
    return code, seen


def random_q(robot, rng, n, spill=0.05):
    lim = robot.joint_limits
    span = lim[:, 1] - lim[:, 0]
    return lim[:, 0] - spill * span + (1 + 2 * spill) * span * rng.random((n, robot.n_dof))


# --------------------------------------------------------------- hand-built cases
def single_camera_case(justin, offset_dir, normal, fov=10.0, rng=(0.1, 5.0), look=True,
                       max_angle=60.0):
    """A camera 1 m from the right marker along ``offset_dir`` (right_tcp coordinates) at
    q = 0 (arms stretched), looking at the marker (or away)."""
    q = np.zeros((1, justin.n_dof))
    q[0, 2] = 0.5          # inside the coupled torso limit
    F = fk(justin, q, device="cpu", dtype="float64")[0]
    T = F[justin.frame_index("right_tcp")]
    x = T[:3, :3] @ [0, 0, 0.05] + T[:3, 3]
    o = x + T[:3, :3] @ np.asarray(offset_dir, float)
    target = x if look else 2 * o - x
    cams = [{"name": "c", "pose": {"position": o.tolist(), "look_at": target.tolist()},
             "fov": fov, "range": list(rng)}]
    s = tracker_setup(cams, {"right": list(normal), "left": [0, 0, 1]})
    opt = PoseOptions(k_of_n=1, max_angle=max_angle, self_collision=False, dtype="float64")
    return PoseSampler(justin, s, opt).check(q)[1][0, 0], ref_check(justin, s, q, opt)[1][0, 0]


def test_hand_built_visibility_known_answers(justin):
    # along the tcp's x axis, marker normal +x: in view, facing, no sphere on the ray
    assert single_camera_case(justin, [1, 0, 0], [1, 0, 0]) == (1, 1)
    # looking the other way: outside the 10 deg cone
    assert single_camera_case(justin, [1, 0, 0], [1, 0, 0], look=False) == (0, 0)
    # out of range (far 0.5 m < 1 m)
    assert single_camera_case(justin, [1, 0, 0], [1, 0, 0], rng=(0.1, 0.5)) == (0, 0)
    # normal 70 deg off the ray, limit 60 deg: not facing; limit 80 deg: facing
    n70 = [math.cos(math.radians(70)), math.sin(math.radians(70)), 0]
    assert single_camera_case(justin, [1, 0, 0], n70) == (0, 0)
    assert single_camera_case(justin, [1, 0, 0], n70, max_angle=80.0) == (1, 1)
    # along +z the ray leaves through the hand sphere at z = 0.25 (r 0.07): occluded
    assert single_camera_case(justin, [0, 0, 1], [0, 0, 1]) == (0, 0)


def test_occlusion_by_torso_known_answer(justin):
    """A camera behind the torso, the marker in front: the ray crosses the torso spheres."""
    q = np.zeros((1, justin.n_dof))
    q[0, 2] = 0.5
    F = fk(justin, q, device="cpu", dtype="float64")[0]
    x = F[justin.frame_index("right_tcp")][:3, :3] @ [0, 0, 0.05] \
        + F[justin.frame_index("right_tcp"), :3, 3]
    torso = F[justin.frame_index("torso_2"), :3, 3]
    o = x + 3.0 * (torso - x)              # beyond the torso on the line marker -> torso
    n = (o - x) / np.linalg.norm(o - x)    # facing the camera exactly
    cams = [{"pose": {"position": o.tolist(), "look_at": x.tolist()}, "fov": 20.0}]
    R = F[justin.frame_index("right_tcp"), :3, :3]
    s = tracker_setup(cams, {"right": (R.T @ n).tolist()})
    opt = PoseOptions(self_collision=False, dtype="float64")
    seen = PoseSampler(justin, s, opt).check(q)[1]
    assert seen[0, 0] == 0 and ref_check(justin, s, q, opt)[1][0, 0] == 0
    # the known blocker: the torso_2 sphere at the frame origin (r 0.14) lies on the segment
    c = torso
    t = np.clip(np.dot(c - o, x - o) / np.dot(x - o, x - o), 0, 1)
    assert np.linalg.norm(o + t * (x - o) - c) < 0.14
    # the same camera moved to the other side of the marker (away from the robot): seen
    cams[0]["pose"]["position"] = (x - 1.0 * n).tolist()
    s = tracker_setup(cams, {"right": (R.T @ -n).tolist()})
    assert PoseSampler(justin, s, opt).check(q)[1][0, 0] == ref_check(justin, s, q, opt)[1][0, 0]


# ----------------------------------------------------------- random vs reference
@pytest.mark.parametrize("single,require", [(False, "any"), (True, "any"), (False, "all")])
def test_check_matches_numpy_reference(justin, single, require, device):
    rng = np.random.default_rng(3)
    q = random_q(justin, rng, 1500)
    s = tracker_setup(ring_cameras())
    opt = PoseOptions(k_of_n=3, max_angle=70.0, single_marker=single, require=require,
                      margin=0.02, dtype="float64", device=device)
    code, seen = PoseSampler(justin, s, opt).check(q)
    rcode, rseen = ref_check(justin, s, q, opt)
    assert np.array_equal(seen, rseen)
    assert np.array_equal(code, rcode)
    assert len(set(code.tolist())) >= 3   # the cases exercise several verdicts
    # float32 kernels agree except at float32 round-off boundaries
    c32, _ = PoseSampler(justin, s, PoseOptions(**{**opt.__dict__, "dtype": "float32"})).check(q)
    assert np.mean(c32 == rcode) > 0.99


def test_sampled_poses_satisfy_every_constraint(justin, device):
    s = tracker_setup(ring_cameras(), {"right": [1, 0, 0]})
    opt = PoseOptions(k_of_n=4, max_angle=75.0, margin=0.03, single_marker=True,
                      dtype="float64", batch_size=20000, seed=5, device=device)
    res = PoseSampler(justin, s, opt).sample(40)
    assert res.q.shape == (40, justin.n_dof)
    code, seen = ref_check(justin, s, res.q, opt)
    assert np.all(code == 0)
    assert np.all(((seen >= 4).sum(1) == 1) & ((seen > 0).sum(1) == 1))
    assert res.counts["ok"] >= 40 and sum(res.counts.values()) == res.tried
    # reproducible with the seed (on the CPU: on CUDA the accepted rows of a batch are
    # appended in thread order), different with another
    again = PoseSampler(justin, s, opt).sample(40)
    if device == "cpu":
        assert np.array_equal(again.q, res.q)
    other = PoseSampler(justin, s, PoseOptions(**{**opt.__dict__, "seed": 6})).sample(40)
    assert not np.array_equal(other.q, res.q)


def test_no_cameras_limits_and_self_collision_only(justin):
    opt = PoseOptions(margin=0.05, dtype="float64", batch_size=4096)
    res = PoseSampler(justin, None, opt).sample(200)
    code, _ = ref_check(justin, tracker_setup(None), res.q, opt)
    assert np.all(code == 0)


def test_too_strict_reports_counts(justin):
    s = tracker_setup(ring_cameras(fov=1.0))
    with pytest.raises(ValueError, match=r"n: only 0 of 5 poses .*not_seen"):
        PoseSampler(justin, s, PoseOptions(k_of_n=6, max_tries=2000, batch_size=1000)).sample(5)


def test_contact_poses_on_the_manifold():
    from jwarp.calibration.files import make_measurement
    from jwarp.calibration.simulate.scenarios import (
        contact_distance,
        contact_sampler,
        hand_contact_setup,
    )

    hand = get_robot("hand4")
    s = hand_contact_setup()
    opt = PoseOptions(margin=0.0, dtype="float64", seed=1)
    with pytest.raises(ValueError, match="draw: contact setups need a contact search"):
        PoseSampler(hand, s, opt).sample(3)
    res = PoseSampler(hand, s, opt, draw=contact_sampler(hand, s)).sample(12)
    assert res.q.shape == (12, hand.n_dof) and res.meta["pair"].shape == (12,)
    d = contact_distance(hand, make_measurement(hand, s), res.q, res.meta["pair"])
    assert np.max(np.abs(d)) < 1e-6
    code, _ = ref_check(hand, tracker_setup(None), res.q, PoseOptions(margin=0.0))
    assert np.all(code == 0)


# ------------------------------------------------------------------ setup / options
@pytest.mark.parametrize("cams,msg", [
    ([{"fov": 60}], r"cameras\[0\]\.pose: missing"),
    ([{"pose": {"position": [0, 0, 0], "rotvec": [0, 0, 0]}, "fov": 180}],
     r"cameras\[0\]\.fov: expected an angle in \(0, 180\)"),
    ([{"pose": {"position": [0, 0, 0], "rotvec": [0, 0, 0]}}], r"cameras\[0\]\.fov"),
    ([{"pose": {"position": [0, 0, 0], "rotvec": [0, 0, 0]}, "fov": 50, "range": [2, 1]}],
     r"cameras\[0\]\.range"),
    ([{"pose": {"position": [0, 0, 0]}, "fov": 50}], r"cameras\[0\]\.pose: give exactly one"),
    ([{"pose": {"position": [0, 0], "look_at": [1, 0, 0]}, "fov": 50}],
     r"cameras\[0\]\.pose\.position"),
    ([], r"cameras: expected a non-empty list"),
])
def test_bad_cameras(cams, msg):
    with pytest.raises(ValueError, match=msg):
        parse_cameras(cams)


def test_setup_file_roundtrip_and_bad_normals(tmp_path, justin):
    s = tracker_setup(ring_cameras(2), {"right": [1, 0, 0]})
    write_setup(tmp_path / "s.json", s)
    back = read_setup(tmp_path / "s.json")
    assert back.cameras == s.cameras and back.marker_normals == {"right": [1, 0, 0]}
    assert "cameras" not in back.section
    with pytest.raises(ValueError, match=r"marker_normals\.wrist: unknown marker"):
        PoseSampler(justin, tracker_setup(ring_cameras(2), {"wrist": [1, 0, 0]}))
    with pytest.raises(ValueError, match="k_of_n: 3 cameras asked"):
        PoseSampler(justin, s, PoseOptions(k_of_n=3))


@pytest.mark.parametrize("field,value,exc", [
    ("margin", -0.1, ValueError), ("margin", math.nan, ValueError), ("k_of_n", 0, ValueError),
    ("k_of_n", 1.5, TypeError), ("max_angle", 0.0, ValueError), ("max_angle", 181.0, ValueError),
    ("require", "some", ValueError), ("batch_size", 0, ValueError), ("seed", -1, ValueError),
    ("dtype", "float16", ValueError), ("single_marker", 1, TypeError),
])
def test_options_validate(field, value, exc):
    with pytest.raises(exc, match=field):
        PoseOptions(**{field: value}).validate()


# ------------------------------------------------------------------------ ordering
def test_tsp_optimal_on_tiny_instances_vs_brute_force():
    rng = np.random.default_rng(0)
    for _ in range(3):
        q = rng.uniform(-2, 2, (7, 4))
        for metric in ("euclidean", "max"):
            o = order_poses(q, metric=metric)
            best = min(path_length(q, p, metric) for p in itertools.permutations(range(7)))
            assert o.after[metric] == pytest.approx(best, rel=1e-5)
            assert sorted(o.order.tolist()) == list(range(7))
        o = order_poses(q, start=4)
        best = min(path_length(q, (4,) + p) for p in itertools.permutations([0, 1, 2, 3, 5, 6]))
        assert o.order[0] == 4 and o.after["euclidean"] == pytest.approx(best, rel=1e-5)


def test_tsp_never_longer_than_input():
    rng = np.random.default_rng(1)
    line = np.linspace(0, 1, 30)[:, None] * np.ones((1, 3))     # input already optimal
    for q in (line, rng.uniform(-3, 3, (60, 19)), rng.uniform(-3, 3, (3, 2))):
        o = order_poses(q)
        assert o.after["euclidean"] <= o.before["euclidean"] + 1e-12
        assert o.before["euclidean"] == pytest.approx(path_length(q))
        assert o.after["max"] == pytest.approx(path_length(q, o.order, "max"))
    assert order_poses(rng.uniform(-3, 3, (60, 19))).after["euclidean"] < \
        0.8 * path_length(rng.uniform(-3, 3, (60, 19)))
    with pytest.raises(ValueError, match="metric"):
        order_poses(line, metric="manhattan")


# ---------------------------------------------------------------- plan and campaign
def test_plan_csv(tmp_path, justin):
    q = np.random.default_rng(0).uniform(-1, 1, (3, justin.n_dof))
    path = tmp_path / "plan.csv"
    write_plan(str(path), justin, q)
    lines = path.read_text().splitlines()
    assert lines[0].split(",") == list(justin.joint_names)
    assert np.array_equal(np.loadtxt(path, delimiter=",", skiprows=1), q)
    assert plan_text(justin, q[:1], {"pair": np.array([2])}).splitlines()[0].endswith(",pair")


def test_campaign_rows_do_not_self_collide(justin):
    s = justin_tracker_setup()
    c = simulate_campaign(justin, s, 150, seed=2)
    opt = PoseOptions(margin=0.02, self_collision=True)
    code, _ = ref_check(justin, tracker_setup(None), c.samples.q, opt)
    assert np.all(code == 0)
    c0 = simulate_campaign(justin, s, 150, seed=2, collision_margin=None)
    code0, _ = ref_check(justin, tracker_setup(None), c0.samples.q, PoseOptions(margin=0.0))
    assert np.mean(code0 == 4) > 0.2   # without the sampler many rows collide
