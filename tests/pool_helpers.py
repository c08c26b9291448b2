"""Independent feasibility checks of design pools in tests: numpy sphere distances from
jwarp's FK output (brute force over every allowed sphere pair)."""

import numpy as np

from jwarp.kinematics.fk import fk


def sphere_centres(robot, q):
    """(N, S, 3) sphere centres [m] and (S,) radii, frames from jwarp's FK (float64)."""
    frame, pos, rad = robot.sphere_arrays()
    T = np.asarray(fk(robot, np.asarray(q, np.float64), dtype=np.float64, device="cpu"))
    Tf = T[:, frame]
    x = np.einsum("nsij,sj->nsi", Tf[..., :3, :3], pos) + Tf[..., :3, 3]
    return x, rad


def self_colliding(robot, q, margin=0.0, skip_frames=()):
    """(N,) bool: some allowed sphere pair keeps <= margin between its surfaces (pairs of
    frames both in ``skip_frames`` left out), by brute force in numpy. Pairs whose
    distance is the same positive value in every configuration of q (rigidly connected;
    no configuration can change them) are left out, as the collision tables do."""
    frame = robot.sphere_arrays()[0]
    allowed = robot.allowed_collision_pairs.copy()
    for a in skip_frames:
        for b in skip_frames:
            allowed[a, b] = False
    a, b = np.triu_indices(len(frame), 1)
    use = allowed[frame[a], frame[b]]
    a, b = a[use], b[use]
    x, r = sphere_centres(robot, q)
    d = np.linalg.norm(x[:, a] - x[:, b], axis=-1) - r[a] - r[b]
    rigid = (np.ptp(d, axis=0) < 1e-9) & (d.min(axis=0) > 0)
    assert len(q) >= 10 or not margin, "rigid pairs need a few configurations to be told"
    return (d[:, ~rigid] <= margin).any(axis=1)


def ball_colliding(robot, q, centre, radius, margin=0.0):
    """(N,) bool: some robot sphere keeps <= margin from a ball obstacle."""
    x, r = sphere_centres(robot, q)
    d = np.linalg.norm(x - np.asarray(centre), axis=-1) - r - radius
    return (d <= margin).any(axis=1)


def in_limits(robot, q):
    lim = np.asarray(robot.joint_limits)
    ok = np.all((q >= lim[:, 0]) & (q <= lim[:, 1]), axis=1)
    for ll in robot.linear_limits:
        v = q[:, ll.joints] @ np.asarray(ll.coefficients)
        ok &= (v >= ll.lower) & (v <= ll.upper)
    return ok
