"""Freezing joints: a robot without some of its joints, each fixed at a value (a gripper's
fingers; mimic joints follow), and the values a frozen robot records in its ``notes``."""

from __future__ import annotations

import json
from functools import cached_property
from typing import TYPE_CHECKING, cast

import numpy as np

from jwarp.model.parts import LinearLimit
from jwarp.model.schema import RobotModelError, _number, validate

if TYPE_CHECKING:
    from jwarp.model.robot import RobotModel

__all__ = ["FROZEN_NOTE", "freeze_joints", "frozen_joint_values"]


#: ``notes`` key of a robot with frozen joints: JSON ``{joint name: value}`` [rad or m]
FROZEN_NOTE = "frozen_joints"


def frozen_joint_values(model: RobotModel) -> dict[str, float]:
    """``{joint name: value}`` [rad or m] of the joints :func:`freeze_joints` removed from
    ``model`` (its ``notes['frozen_joints']``; empty when none). A MoveIt start or goal
    state may still name them: :func:`jwarp.world.moveit.joint_vector` ignores them."""
    text = model.notes.get(FROZEN_NOTE)
    if not text:
        return {}
    try:
        doc = json.loads(text)
    except ValueError:
        raise RobotModelError(f"notes.{FROZEN_NOTE}: not a JSON object of joint values") from None
    if not isinstance(doc, dict):
        raise RobotModelError(f"notes.{FROZEN_NOTE}: not a JSON object of joint values")
    return {str(k): float(v) for k, v in doc.items()}


def _rigid_roots(model: RobotModel) -> np.ndarray:
    """(n_frames,) the root frame of each frame's rigid group (frames joined by static
    frames and DH frames driven by no joint)."""
    group = np.arange(model.n_frames)
    for f in model.topological_order:
        fr = model.frames[f]
        if fr.parent is not None and (fr.kind == "static" or not fr.coupling):
            group[f] = group[fr.parent]
    return group


def freeze_joints(model: RobotModel, values: dict[str | int, float], *,
                  exclude_rigid_pairs: bool = True) -> RobotModel:
    """A copy of ``model`` without the joints in ``values``, each fixed at its value.

    Args:
        model: the robot.
        values: ``{joint name or index: value}`` [rad, or m for a prismatic joint], each
            within the joint's limits. Every frame the joint drives (its own and those of
            its mimic joints, with their coefficients) keeps its DH row with
            ``c * (value + transmission error)`` added to theta (revolute) or d
            (prismatic); a frame left driven by no joint is a fixed DH frame (its elastic
            compliance kept). A linear limit over a frozen joint moves ``c * value`` into
            its bounds (ValueError naming it if the value breaks it).
        exclude_rigid_pairs: frames that the freezing joins rigidly (a frozen finger and
            its hand) and that carry spheres or capsules are added to
            ``self_collision.exclude_pairs`` (their distance can no longer change).

    Returns:
        A new :class:`RobotModel` with ``n_dof - len(values)`` joints (frames, masses,
        collision bodies, end-effectors and frame indices unchanged) whose FK at the
        remaining joints equals ``model``'s FK with the frozen joints at their values.
        ``notes['frozen_joints']`` lists every frozen joint and value (with earlier ones).

    Raises:
        TypeError: ``values`` is not a mapping.
        ValueError: unknown joint, value not finite or outside the limits, or every joint
            frozen (a robot needs one joint).
    """
    if not isinstance(values, dict):
        try:
            values = dict(values)
        except (TypeError, ValueError):
            raise TypeError(f"values: expected a mapping {{joint: value}}, "
                            f"got {type(values).__name__}") from None
    frozen: dict[int, float] = {}
    for key, v in values.items():
        j = model.joint_index(key, "values")
        name = model.joints[j].name
        if j in frozen:
            raise ValueError(f"values: joint '{name}' given twice")
        try:
            v = _number(v, f"values['{name}']")
        except RobotModelError as e:
            raise ValueError(str(e)) from None
        lo, hi = model.joints[j].lower, model.joints[j].upper
        tol = 1e-12 * max(1.0, abs(lo), abs(hi))
        if not lo - tol <= v <= hi + tol:
            unit = "m" if model.joints[j].type == "prismatic" else "rad"
            raise ValueError(f"values['{name}']: {v:g} {unit} is outside the joint's limits "
                             f"[{lo:g}, {hi:g}]")
        frozen[j] = v
    if len(frozen) == model.n_dof:
        raise ValueError(f"values: freezes every joint of robot '{model.name}' (a robot needs "
                         f"at least one joint)")
    if not frozen:
        return model.copy()
    q = np.zeros(model.n_dof)
    for j, v in frozen.items():
        q[j] = v
    seen = model.joint_transmission(q)          # the value the links see (transmission errors)
    keep = [j for j in range(model.n_dof) if j not in frozen]
    new_index = {j: k for k, j in enumerate(keep)}
    before = _rigid_roots(model)
    m = model.copy()
    for f in m.frames:
        if f.kind != "dh" or not f.coupling:
            continue
        col = 0 if model.joints[f.coupling[0][0]].type == "prismatic" else 1
        f.dh = cast(np.ndarray, f.dh).copy()  # a DH frame
        for j, c in f.coupling:
            if j in frozen:
                f.dh[col] += c * seen[j]
        f.coupling = [(new_index[j], c) for j, c in f.coupling if j not in frozen]
    lin = []
    for k, lim in enumerate(m.linear_limits):
        shift = sum(c * frozen[j] for j, c in zip(lim.joints, lim.coefficients) if j in frozen)
        js = [(new_index[j], c) for j, c in zip(lim.joints, lim.coefficients) if j not in frozen]
        if not js:
            if not lim.lower - 1e-12 <= shift <= lim.upper + 1e-12:
                raise ValueError(f"values: the frozen values break linear_limits[{k}] "
                                 f"({shift:g} outside [{lim.lower:g}, {lim.upper:g}])")
            continue
        lin.append(LinearLimit(joints=[j for j, _ in js], coefficients=[c for _, c in js],
                               lower=lim.lower - shift, upper=lim.upper - shift))
    m.linear_limits = lin
    m.joints = [m.joints[j] for j in keep]
    m.harmonic = model.harmonic[keep]
    notes = dict(m.notes)
    old = frozen_joint_values(model)
    old.update({model.joints[j].name: v for j, v in frozen.items()})
    notes[FROZEN_NOTE] = json.dumps(old)
    m.notes = notes
    for attr in list(vars(m)):  # drop cached derived data
        if isinstance(type(m).__dict__.get(attr), cached_property):
            del m.__dict__[attr]
    m.__post_init__()
    if exclude_rigid_pairs:
        after = _rigid_roots(m)
        solid = sorted({s.frame for s in m.spheres} | {c.frame for c in m.capsules})
        sc = m.self_collision
        have = {tuple(sorted(p)) for p in sc.exclude_pairs}
        for a_i, a in enumerate(solid):
            for b in solid[a_i + 1:]:
                if after[a] == after[b] and before[a] != before[b] and (a, b) not in have:
                    sc.exclude_pairs.append((a, b))
                    have.add((a, b))
        m.__dict__.pop("allowed_collision_pairs", None)
        validate(m)
    return m
