"""Why an IK answer is not feasible (:func:`jwarp.solvers.ik.explain.explain_ik`), on
closed-form cases: a joint outside its limit by a known amount, a pose off by a known
translation and rotation, a collision sphere at the centre of a box (distance known in
closed form), a self-collision whose pair is found independently with numpy, and the
position-only / free-axis modes."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import jwarp
from jwarp.core.device import host_frames
from jwarp.solvers.ik.explain import explain_ik, limit_reasons, pose_errors
from jwarp.viz import world_spheres
from jwarp.world import World

ARM = jwarp.robot("arm7")
FRAME = "right_tcp"
Q0 = np.array([0.3, 1.0, 0.2, 1.0, -0.4, 0.5, 0.1])


def pose(q, frame=FRAME, robot=ARM):
    """The frame's pose (4, 4) at q from the host FK (numpy, not the Warp kernels)."""
    return host_frames(robot, np.asarray(q)[None])[0, robot.frame_index(frame)]


def number(pattern, text):
    m = re.search(pattern, text)
    assert m, (pattern, text)
    return float(m.group(1))


def test_feasible_at_the_fk_pose():
    assert explain_ik(ARM, FRAME, Q0, pose(Q0)) == "feasible"


def test_joint_outside_its_limit_by_a_known_amount():
    q = Q0.copy()
    hi = ARM.joint_limits[3, 1]
    q[3] = hi + 0.25
    why = explain_ik(ARM, FRAME, q, pose(q))
    assert "joint 'right_4'" in why and "above its upper limit" in why
    assert number(r"is ([0-9.e-]+) rad above", why) == pytest.approx(0.25, abs=1e-9)
    assert "pose not reached" not in why           # the pose is that of q itself
    q[3] = ARM.joint_limits[3, 0] - 0.125
    assert number(r"is ([0-9.e-]+) rad below", explain_ik(ARM, FRAME, q, pose(q))) == \
        pytest.approx(0.125, abs=1e-9)
    assert limit_reasons(ARM, Q0) == []


def test_pose_off_by_a_known_translation_and_rotation():
    T = pose(Q0)
    off = T.copy()
    off[:3, 3] += [0.003, -0.004, 0.0]                      # 5 mm
    off[:3, :3] = Rotation.from_rotvec([0, 0, math.radians(2.0)]).as_matrix() @ T[:3, :3]
    why = explain_ik(ARM, FRAME, Q0, off)
    assert why.startswith("pose not reached")
    assert number(r"position error ([0-9.e-]+) mm", why) == pytest.approx(5.0, rel=1e-6)
    assert number(r"rotation error ([0-9.e-]+) deg", why) == pytest.approx(2.0, rel=1e-6)
    pos, rot = pose_errors(ARM, FRAME, Q0, off)
    assert pos == pytest.approx(0.005, rel=1e-9) and rot == pytest.approx(math.radians(2), rel=1e-9)
    # within looser tolerances it is feasible; the tolerances are quoted in the reason
    assert explain_ik(ARM, FRAME, Q0, off, tol_pos=0.006, tol_rot=0.04) == "feasible"
    why = explain_ik(ARM, FRAME, Q0, off, tol_pos=0.006, tol_rot=0.01)
    assert "(< tol 6 mm)" in why and "(>= tol 0.573 deg)" in why


def test_position_only_and_free_axis():
    T = pose(Q0)
    spun = T.copy()     # turned by 1 rad about the tool's own z axis
    spun[:3, :3] = T[:3, :3] @ Rotation.from_rotvec([0, 0, 1.0]).as_matrix()
    assert "rotation error" in explain_ik(ARM, FRAME, Q0, spun)
    assert explain_ik(ARM, FRAME, Q0, spun, orientation="none") == "feasible"
    assert explain_ik(ARM, FRAME, Q0, spun, orientation="axis", free_axis=(0, 0, 1)) == \
        "feasible"
    # about the tool's x axis the free z axis tilts by the same angle
    tilt = T.copy()
    tilt[:3, :3] = T[:3, :3] @ Rotation.from_rotvec([0.3, 0, 0]).as_matrix()
    why = explain_ik(ARM, FRAME, Q0, tilt, orientation="axis", free_axis=(0, 0, 2))
    assert number(r"free-axis direction error ([0-9.e-]+) deg", why) == \
        pytest.approx(math.degrees(0.3), rel=1e-5)        # printed to 6 digits
    assert pose_errors(ARM, FRAME, Q0, tilt, orientation="axis")[1] == pytest.approx(0.3, rel=1e-9)
    # position only ignores any rotation but not the position
    far = spun.copy()
    far[2, 3] += 0.01
    why = explain_ik(ARM, FRAME, Q0, far, orientation="none")
    assert number(r"position error ([0-9.e-]+) mm", why) == pytest.approx(10.0, rel=1e-6)
    assert "rotation" not in why


def test_sphere_inside_a_box_names_link_and_object():
    """A box of half size h centred at a sphere's centre: the signed distance of that
    sphere's surface is -(h + r), the deepest of every sphere."""
    F = host_frames(ARM, Q0[None])[0]
    c, r = world_spheres(ARM, F)
    s = 6                                                    # a sphere of right_4
    h = 0.1
    world = World(None)
    world.add("crate", "box", [2 * h] * 3, c[s])
    why = explain_ik(ARM, FRAME, Q0, pose(Q0), world=world)
    link = ARM.frames[ARM.spheres[s].frame].name
    first = why.split("; ")[0]
    assert first.startswith(f"collision: link '{link}' vs object 'crate'"), why
    assert number(r"distance (-?[0-9.e-]+) mm", first) == pytest.approx(-(h + r[s]) * 1e3,
                                                                         abs=0.0051)
    # a margin is quoted; far from the box it is feasible
    world2 = World(None)
    world2.add("crate", "box", [0.1] * 3, [5.0, 5.0, 5.0])
    assert explain_ik(ARM, FRAME, Q0, pose(Q0), world=world2, margin=0.01) == "feasible"


def test_self_collision_pair_found_independently():
    from jwarp.world.collision import collision_pairs

    pairs = collision_pairs(ARM)
    rng = np.random.default_rng(0)
    lo, hi = ARM.joint_limits.T
    qs = rng.uniform(lo, hi, size=(4000, 7))
    F = host_frames(ARM, qs)
    found = None
    for q, f in zip(qs, F):
        c, r = world_spheres(ARM, f)
        d = np.linalg.norm(c[pairs[:, 0]] - c[pairs[:, 1]], axis=1) - r[pairs[:, 0]] - r[pairs[:, 1]]
        if d.min() < -0.02:
            found = q, d, c
            break
    assert found is not None
    q, d, _ = found
    k = int(np.argmin(d))
    a, b = (ARM.frames[ARM.spheres[int(s)].frame].name for s in pairs[k])
    why = explain_ik(ARM, FRAME, q, pose(q))
    assert f"self-collision: link '{a}' vs link '{b}'" in why, why
    line = next(p for p in why.split("; ") if p.startswith(f"self-collision: link '{a}' vs "
                                                            f"link '{b}'"))
    assert number(r"distance (-?[0-9.e-]+) mm", line) == pytest.approx(d[k] * 1e3, abs=0.0051)  # 0.01 mm


def test_planar_robot():
    p4 = jwarp.robot("planar4")
    q = np.array([0.3, -0.2, 0.4, 0.1])
    T = pose(q, "tcp", p4)
    off = T.copy()
    off[0, 3] += 0.002
    off[:3, :3] = Rotation.from_rotvec([0, 0, 0.01]).as_matrix() @ T[:3, :3]
    pos, rot = pose_errors(p4, "tcp", q, off)
    assert pos == pytest.approx(0.002, rel=1e-9) and rot == pytest.approx(0.01, rel=1e-9)


@pytest.mark.parametrize("kw, name", [
    (dict(q=np.zeros(3)), "q"), (dict(q=np.full(7, np.nan)), "q"),
    (dict(target=np.eye(3)), "target"), (dict(orientation="roll"), "orientation"),
    (dict(free_axis=(0, 0, 0)), "free_axis"), (dict(tol_pos=0.0), "tol_pos"),
    (dict(tol_rot=-1.0), "tol_rot"), (dict(margin=-0.1), "margin"),
])
def test_bad_input_names_the_argument(kw, name):
    args = dict(q=Q0, target=pose(Q0))
    args.update({k: kw.pop(k) for k in list(kw) if k in args})
    with pytest.raises(ValueError, match=f"^{name}: "):
        explain_ik(ARM, FRAME, args["q"], args["target"], **kw)


def test_world_of_the_wrong_dimension():
    from jwarp.world import simplex_world

    w2 = simplex_world(2, seed=0, shape=(16, 16), limits=[[-1, 1], [-1, 1]])
    with pytest.raises(ValueError, match="^world: "):
        explain_ik(ARM, FRAME, Q0, pose(Q0), world=w2)


def test_elastic_pose_is_the_deflected_one():
    """With kappa the answer's pose is the elastic equilibrium's (fk_elastic, converged):
    feasible at the deflected pose, and off by the deflection at the rigid one."""
    from jwarp.kinematics.equilibrium import fk_elastic

    kappa = 1e-3
    res = fk_elastic(ARM, Q0[None], kappa, lam=0.7, max_iter=100, dtype=np.float64)
    assert bool(np.all(res.converged))
    Te = np.asarray(res.frames)[0, ARM.frame_index(FRAME)]
    Tr = pose(Q0)
    defl = float(np.linalg.norm(Te[:3, 3] - Tr[:3, 3]))
    assert defl > 0.01                                   # a visible deflection
    assert explain_ik(ARM, FRAME, Q0, Te, kappa=kappa, tol_pos=1e-6) == "feasible"
    pos, _ = pose_errors(ARM, FRAME, Q0, Tr, kappa=kappa)
    assert pos == pytest.approx(defl, abs=1e-6)
    assert "pose not reached" in explain_ik(ARM, FRAME, Q0, Tr, kappa=kappa)
