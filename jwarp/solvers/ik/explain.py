"""Why an IK answer is not feasible, in words: :func:`explain_ik`.

An IK answer ``q`` is feasible (:mod:`jwarp.solvers.ik`) when it is within the joint
limits (up to :data:`jwarp.core.limits.LIMIT_TOL`), on the target (position error below
``tol_pos``, rotation error below ``tol_rot``) and collision-free: every collision sphere
more than ``margin`` from the world and from every sphere it may collide with. This module
re-checks one answer on the host in float64 with the library's own checks
(:func:`jwarp.fk`, :func:`jwarp.world.collision.sphere_distances`,
:func:`jwarp.world.collision.self_distances`, :func:`jwarp.world.device_world.world_query`
for the nearest object's name) and says which of the three fails:

* limits: each joint outside its range, with its value, the range and by how much; each
  linear (coupled) limit likewise;
* pose: position error [mm] and rotation error [deg] against the tolerances (with the
  joints sitting exactly at a limit, a frequent cause of a seed that stopped short);
* collision: the colliding pairs, link vs object or link vs link, with their signed
  surface distance [mm] (negative: penetration) against the margin.

Orientation modes (the solver's ``IKOptions.orientation``): ``"full"`` (the whole
rotation), ``"none"`` (position only: no rotation error), ``"axis"`` (the rotation about
``free_axis``, a unit vector in the end-effector frame, is free: the rotation error is the
angle between the axis as the frame holds it and as the target holds it).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from jwarp.core.arrays import real_array
from jwarp.core.device import host_device
from jwarp.core.limits import LIMIT_TOL
from jwarp.core.types import ArrayLike
from jwarp.model import RobotModel
from jwarp.solvers.ik.objective import as_poses
from jwarp.solvers.ik.options import ORIENTATIONS, orientation_args

if TYPE_CHECKING:
    from jwarp.world.sdf import World

__all__ = ["explain_ik", "pose_errors", "limit_reasons", "collision_reasons",
           "ORIENTATIONS"]

#: colliding pairs listed per kind (world, self); the rest are counted
MAX_PAIRS = 3


def _frames(model: RobotModel, q: np.ndarray, kappa: ArrayLike | None = None) -> tuple[np.ndarray, Any, bool]:
    """Frames (n_frames, 4, 4) at q (n_dof,) in float64, the DH rows used (None: rigid)
    and whether the elastic equilibrium converged (True when rigid)."""
    from jwarp.kinematics.fk import fk

    if kappa is None:
        return np.asarray(fk(model, q[None], dtype=np.float64, device=host_device()))[0], None, True
    from jwarp.world.path_feasibility import elastic_equilibrium

    rho, conv = elastic_equilibrium(model, q[None], kappa, device=host_device())
    F = np.asarray(fk(model, q[None], dh=rho, dtype=np.float64, device=host_device()))[0]
    return F, rho, bool(np.all(conv))


def pose_errors(robot: RobotModel, frame: int | str, q: ArrayLike, target: Any, *, orientation: str = "full",
                free_axis: Any = (0.0, 0.0, 1.0), kappa: ArrayLike | None = None) -> tuple[float, float]:
    """(position error [m], rotation error [rad]) of ``frame`` at q (n_dof,) against the
    target pose (4, 4), as :func:`explain_ik` measures them (planar robots: x, y and the
    rotation about z; ``orientation`` "none": rotation error 0; "axis": the angle between
    ``free_axis`` (end-effector frame) carried by the frame and by the target)."""
    model = robot
    qv, T, fi, axis = _inputs(model, frame, q, target, orientation, free_axis)
    F, _, _ = _frames(model, qv, kappa)
    return _pose_errors(model, F[fi], T, orientation, axis)


def _pose_errors(model: RobotModel, X: np.ndarray, T: np.ndarray, orientation: str,
                 axis: np.ndarray) -> tuple[float, float]:
    planar = model.workspace_dim == 2
    dp = T[:3, 3] - X[:3, 3]
    pos = float(np.linalg.norm(dp[:2] if planar else dp))
    if orientation == "none":
        return pos, 0.0
    if orientation == "axis":
        a, b = X[:3, :3] @ axis, T[:3, :3] @ axis
        # atan2 of |a x b| and a.b: accurate at small and large angles
        return pos, float(math.atan2(np.linalg.norm(np.cross(a, b)), float(a @ b)))
    Rerr = T[:3, :3] @ X[:3, :3].T
    if planar:
        return pos, abs(math.atan2(Rerr[1, 0], Rerr[0, 0]))
    c = (np.trace(Rerr) - 1.0) / 2.0
    s = np.linalg.norm([Rerr[2, 1] - Rerr[1, 2], Rerr[0, 2] - Rerr[2, 0],
                        Rerr[1, 0] - Rerr[0, 1]]) / 2.0
    return pos, float(math.atan2(s, c))


def _unit(model: RobotModel, j: int) -> str:
    return "m" if model.joints[j].type == "prismatic" else "rad"


def limit_reasons(robot: RobotModel, q: ArrayLike, tol: float = LIMIT_TOL) -> list[str]:
    """One line per violated limit of q (n_dof,): the joint, its value, its range and by
    how much it is outside (box limits), or the linear combination likewise."""
    model = robot
    q = np.asarray(q, np.float64).reshape(model.n_dof)
    out = []
    for j, (lo, hi) in enumerate(model.joint_limits):
        u = _unit(model, j)
        if q[j] < lo - tol:
            out.append(f"joint '{model.joint_names[j]}' = {q[j]:+.6g} {u} is {lo - q[j]:.4g} {u} "
                       f"below its lower limit {lo:+.6g}")
        elif q[j] > hi + tol:
            out.append(f"joint '{model.joint_names[j]}' = {q[j]:+.6g} {u} is {q[j] - hi:.4g} {u} "
                       f"above its upper limit {hi:+.6g}")
    for lim in model.linear_limits:
        s = float(q[list(lim.joints)] @ np.asarray(lim.coefficients, np.float64))
        terms = " + ".join(f"{c:g}*{model.joint_names[j]}"
                           for j, c in zip(lim.joints, lim.coefficients))
        if s < lim.lower - tol:
            out.append(f"linear limit {terms} = {s:+.6g} is {lim.lower - s:.4g} below "
                       f"{lim.lower:+.6g}")
        elif s > lim.upper + tol:
            out.append(f"linear limit {terms} = {s:+.6g} is {s - lim.upper:.4g} above "
                       f"{lim.upper:+.6g}")
    return out


def _at_limits(model: RobotModel, q: np.ndarray, tol: float = 1e-6) -> list[str]:
    """The joints of q sitting at (within ``tol`` of) a box limit, as 'name = value (lower)'."""
    out = []
    for j, (lo, hi) in enumerate(model.joint_limits):
        if abs(q[j] - lo) <= tol or abs(q[j] - hi) <= tol:
            side = "lower" if abs(q[j] - lo) <= tol else "upper"
            out.append(f"'{model.joint_names[j]}' = {q[j]:+.6g} ({side})")
    return out


def _link(model: RobotModel, s: int) -> str:
    from jwarp.world.collision import sphere_link

    return sphere_link(model, s)


def collision_reasons(robot: RobotModel, q: ArrayLike, world: World | None = None, margin: float = 0.0, *,
                      kappa: ArrayLike | None = None) -> list[str]:
    """The colliding pairs of q (n_dof,): link vs object (closer than ``margin`` [m] to the
    world) and link vs link (closer than ``margin`` to each other), the worst first, one
    line per pair of a link and an object/link (its closest spheres' signed surface
    distance [mm], negative = penetration), at most :data:`MAX_PAIRS` per kind and a count
    of the others. The robot's collision spheres; rigid model unless ``kappa``."""
    from jwarp.world.collision import self_distances, sphere_distances

    model = robot
    q = np.asarray(q, np.float64).reshape(model.n_dof)
    if not model.spheres:
        return []
    _, rho, _ = _frames(model, q, kappa)
    rho1 = None if rho is None else np.asarray(rho)[0]
    out: list[str] = []
    if world is not None:
        d = np.asarray(sphere_distances(model, q[None], world, rho=None if rho1 is None
                                        else rho1[None], device=host_device(), dtype=np.float64))[0]
        bad = np.nonzero(d <= margin)[0]
        if len(bad):
            names = _objects(model, q, world, bad, rho1)
            worst: dict[tuple[str, str], float] = {}
            for s, obj in zip(bad, names):
                key = (_link(model, int(s)), obj)
                worst[key] = min(worst.get(key, math.inf), float(d[s]))
            out += _pair_lines(worst, margin, "object")
    pairs = np.asarray(_pairs(model))
    if len(pairs):
        d = np.asarray(self_distances(model, q[None], rho=None if rho1 is None else rho1[None],
                                      device=host_device(), dtype=np.float64))[0]
        bad = np.nonzero(d <= margin)[0]
        worst = {}
        for p in bad:
            a, b = (_link(model, int(s)) for s in pairs[p])
            key = (a, b)
            worst[key] = min(worst.get(key, math.inf), float(d[p]))
        out += _pair_lines(worst, margin, "link")
    return out


def _pairs(model: RobotModel) -> np.ndarray:
    from jwarp.world.collision import collision_pairs

    return collision_pairs(model)


def _objects(model: RobotModel, q: np.ndarray, world: World, spheres: np.ndarray,
             rho: Any) -> list[str]:
    """The name of the object nearest to each sphere's centre (``world.object_name``)."""
    from jwarp.world.collision import nearest_objects

    return nearest_objects(model, q, world, spheres, rho)


def _pair_lines(worst: dict, margin: float, kind: str) -> list[str]:
    from jwarp.world.collision import mm_text

    items = sorted(worst.items(), key=lambda kv: kv[1])
    lines = []
    for (a, b), d in items[:MAX_PAIRS]:
        other = b if kind == "object" else f"link '{b}'"
        what = "collision" if kind == "object" else "self-collision"
        lines.append(f"{what}: link '{a}' vs {other}, distance {mm_text(d)} mm "
                     f"(margin {margin * 1e3:g} mm)")
    if len(items) > MAX_PAIRS:
        lines.append(f"and {len(items) - MAX_PAIRS} more {'link-object' if kind == 'object' else 'link-link'} "
                     f"pair(s) closer than the margin")
    return lines


def _inputs(model: RobotModel, frame: int | str, q: ArrayLike, target: Any, orientation: str,
            free_axis: Any) -> tuple[np.ndarray, np.ndarray, int, np.ndarray]:
    qv = real_array(q, "q")
    if qv.shape != (model.n_dof,):
        raise ValueError(f"q: expected ({model.n_dof},) joint values of '{model.name}', got "
                         f"shape {qv.shape}")
    if not np.all(np.isfinite(qv)):
        raise ValueError("q: contains NaN or inf")
    T = real_array(as_poses(target), "target")
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise ValueError(f"target: expected one finite pose (4, 4), got shape {T.shape}")
    fi = model.frame_index(frame)
    _, axis = orientation_args(orientation, free_axis)   # the solver's own check
    return np.asarray(qv, np.float64), np.asarray(T, np.float64), fi, np.asarray(axis)


def explain_ik(robot: RobotModel, frame: int | str, q: ArrayLike, target: Any, *, world: World | None = None,
               margin: float = 0.0, tol_pos: float = 1e-4, tol_rot: float = 1e-3,
               orientation: str = "full", free_axis: Any = (0.0, 0.0, 1.0),
               kappa: ArrayLike | None = None) -> str:
    """Why the IK answer q is not feasible, or ``"feasible"``.

    Args:
        robot: robot name or RobotModel.
        frame: the end-effector frame (name, alias or index).
        q: the answer (n_dof,) [rad or m].
        target: the target pose (4, 4) in the base frame [m].
        world: the :class:`jwarp.world.World` it was solved in (None: self-collision only).
        margin: required clearance [m] to the world and between links (>= 0).
        tol_pos, tol_rot: the tolerances [m], [rad] (> 0; :func:`jwarp.solvers.ik.ik`'s
            defaults).
        orientation, free_axis: ``"full"``, ``"none"`` (position only) or ``"axis"``
            (rotation about ``free_axis`` (3,), end-effector frame, free).
        kappa: compliances of the elastic model (None: rigid): the frames in its torque
            equilibrium, as the solver's check.

    Returns:
        ``"feasible"``, or the reasons joined by ``"; "``: limits (joint, value, range, by
        how much), pose error (position [mm] and rotation [deg] against the tolerances,
        and the joints sitting at a limit), colliding pairs (link vs object or link, signed
        surface distance [mm] against the margin), and a non-converged elastic equilibrium.

    Raises:
        ValueError/TypeError naming the argument: q not (n_dof,) finite, target not one
        finite (4, 4) pose, unknown frame, bad tolerance/margin/orientation/free_axis, a
        world of the wrong dimension.
    """
    from jwarp.world.collision import check_world

    model = robot
    qv, T, fi, axis = _inputs(model, frame, q, target, orientation, free_axis)
    for name, v in (("tol_pos", tol_pos), ("tol_rot", tol_rot)):
        if isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer)) \
                or not (math.isfinite(v) and v > 0):
            raise ValueError(f"{name}: expected a number > 0, got {v!r}")
    if isinstance(margin, bool) or not isinstance(margin, (int, float, np.floating, np.integer)) \
            or not (math.isfinite(margin) and margin >= 0):
        raise ValueError(f"margin: expected a number >= 0 [m], got {margin!r}")
    check_world(model, world)
    reasons = limit_reasons(model, qv)
    F, _, converged = _frames(model, qv, kappa)
    if not converged:
        reasons.append("the elastic torque equilibrium does not converge at q, so its pose "
                       "and collisions are unknown")
    pos, rot = _pose_errors(model, F[fi], T, orientation, axis)
    if not (pos < tol_pos and rot < tol_rot):
        what = {"full": "rotation", "axis": "free-axis direction", "none": "rotation"}
        parts = [f"position error {pos * 1e3:.6g} mm "
                 f"({'>=' if pos >= tol_pos else '<'} tol {tol_pos * 1e3:g} mm)"]
        if orientation != "none":
            parts.append(f"{what[orientation]} error {math.degrees(rot):.6g} deg "
                         f"({'>=' if rot >= tol_rot else '<'} tol {math.degrees(tol_rot):.4g} "
                         f"deg)")
        line = "pose not reached: " + ", ".join(parts)
        stuck = _at_limits(model, qv)
        if stuck:
            line += f"; at a joint limit: {', '.join(stuck)}"
        reasons.append(line)
    reasons += collision_reasons(model, qv, world, float(margin), kappa=kappa)
    return "; ".join(reasons) if reasons else "feasible"
