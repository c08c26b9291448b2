"""Why a robot's self-collision pairs are not checked: the reasons recorded per excluded
frame pair (``notes['self_collision_pairs']``), MoveIt's adjacency rule, and the list of
every unchecked pair with its reason (docs/urdf.md, "Which self-collision pairs are not
checked").

Reasons: ``SRDF`` (the SRDF's allowed-collision matrix; ``why`` names the element, line and
MoveIt's reason), ``Adjacent`` (:func:`moveit_adjacent_pairs`), ``Always`` / ``Never``
(in collision in >= 95 % / in none of the random configurations sampled by
:func:`jwarp.world.self_pairs.never_colliding_pairs`), ``Frozen`` (joined rigidly by frozen
joints), ``Default`` (an older import's home rule), ``Model`` (the robot file's own
section). Host code only (no FK): the importers record SRDF pairs with it.
"""

from __future__ import annotations

import json
from typing import Any

import numpy as np

from jwarp.model.robot import RobotModel, SelfCollision

__all__ = ["PAIRS_NOTE", "DEFAULT_NOTE", "REASONS", "moveit_adjacent_pairs", "pair_reasons",
           "with_pair_reasons", "skipped_pairs", "skipped_summary"]

#: ``RobotModel.notes`` key: JSON ``[[frame a, frame b, reason, why], ...]`` of the excluded
#: self-collision pairs and why
PAIRS_NOTE = "self_collision_pairs"
#: ``RobotModel.notes`` key of the pairs an older import excluded by MoveIt's "Default" rule
DEFAULT_NOTE = "self_collision_default"
#: the reasons a pair is excluded by (:func:`skipped_pairs`)
REASONS = ("SRDF", "Adjacent", "Always", "Never", "Frozen", "Default", "Model")


def moveit_adjacent_pairs(robot: RobotModel) -> list[tuple[int, int]]:
    """Sorted frame pairs ``(a, b)``, ``a < b``, adjacent by MoveIt's setup assistant rule
    ("Adjacent"): both frames carry collision bodies (spheres or capsules) and the frame
    tree joins them by a path whose frames in between carry none (a parent and its child
    link; or two links joined through links without geometry, e.g. the Panda's link7 and
    hand through the flange panda_link8, or a joint's own ``_axis``/``_origin`` frames).
    Unlike :func:`jwarp.world.self_pairs.adjacent_pairs`, two links that are only rigidly attached (a link and its
    parent's fixed child) are not adjacent: whether they collide is sampled."""
    model = robot
    solid = np.zeros(model.n_frames, bool)
    for sph in model.spheres:
        solid[sph.frame] = True
    for cap in model.capsules:
        solid[cap.frame] = True
    nbr: list[list[int]] = [[] for _ in range(model.n_frames)]
    for f, p in enumerate(model.parents):
        if p >= 0:
            nbr[f].append(int(p))
            nbr[int(p)].append(f)
    out: set[tuple[int, int]] = set()
    for a in np.flatnonzero(solid):
        seen, stack = {int(a)}, [int(a)]
        while stack:   # through frames without bodies only
            for b in nbr[stack.pop()]:
                if b in seen:
                    continue
                seen.add(b)
                if solid[b]:
                    out.add((min(int(a), b), max(int(a), b)))
                else:
                    stack.append(b)
    return sorted(out)




def pair_reasons(robot: RobotModel) -> dict[tuple[int, int], tuple[str, str]]:
    """``{(a, b): (reason, why)}`` (frame indices ``a < b``) recorded for the excluded pairs
    of ``robot`` in ``notes['self_collision_pairs']`` (:data:`PAIRS_NOTE`); pairs no longer
    excluded, or naming frames the robot lacks, are left out."""
    model = robot
    text = model.notes.get(PAIRS_NOTE)
    if not text:
        return {}
    try:
        doc = json.loads(text)
    except ValueError:
        return {}
    index = {n: i for i, n in enumerate(model.frame_names)}
    have = {tuple(sorted(p)) for p in model.self_collision.exclude_pairs}
    out: dict[tuple[int, int], tuple[str, str]] = {}
    for row in doc if isinstance(doc, list) else []:
        if not (isinstance(row, list) and len(row) == 4 and row[0] in index
                and row[1] in index):
            continue
        key = (min(index[row[0]], index[row[1]]), max(index[row[0]], index[row[1]]))
        if key in have:
            out[key] = (str(row[2]), str(row[3]))
    return out


def with_pair_reasons(robot: RobotModel, reasons: dict[tuple[int, int], tuple[str, str]], *,
                      replace: bool = False) -> RobotModel:
    """A copy of ``robot`` whose ``notes['self_collision_pairs']`` records ``reasons``
    (``{(a, b): (reason, why)}``); ``replace``: its ``exclude_pairs`` become exactly these
    pairs (groups and include pairs dropped), else they are added to them."""
    model = robot
    nf = model.n_frames
    keys = {}
    for (a, b), r in reasons.items():
        a, b = int(a), int(b)
        if not (0 <= a < nf and 0 <= b < nf) or a == b:
            raise ValueError(f"reasons: frame pair ({a}, {b}) out of range for robot "
                             f"'{model.name}' ({nf} frames)")
        keys[(min(a, b), max(a, b))] = (str(r[0]), str(r[1]))
    sc = model.self_collision
    if replace:
        new_sc = SelfCollision(groups={}, include_pairs=[], exclude_pairs=sorted(keys))
    else:
        have = {tuple(sorted(p)) for p in sc.exclude_pairs}
        new_sc = SelfCollision(groups={k: list(v) for k, v in sc.groups.items()},
                               include_pairs=list(sc.include_pairs),
                               exclude_pairs=list(sc.exclude_pairs)
                               + sorted(set(keys) - have))
    names = model.frame_names
    notes = dict(model.notes)
    notes[PAIRS_NOTE] = json.dumps([[names[a], names[b], r, w]
                                    for (a, b), (r, w) in sorted(keys.items())])
    return model.copy(self_collision=new_sc, notes=notes)


def skipped_pairs(robot: RobotModel) -> list[dict[str, Any]]:
    """Every frame pair of ``robot`` with collision bodies on both frames that is not
    checked for self-collision, and why: ``[{"links": [a, b], "reason", "why"}]`` in frame
    order. The reason is the recorded one (:func:`pair_reasons`), else: ``Frozen`` (frames
    joined rigidly by frozen joints, :func:`jwarp.model.freeze_joints`), ``Adjacent``
    (:func:`moveit_adjacent_pairs`), ``Default`` (listed in ``notes['self_collision_default']``
    by an older import), else ``Model`` (the robot file's own ``self_collision``)."""
    model = robot
    recorded = pair_reasons(model)
    solid = sorted({sph.frame for sph in model.spheres} | {c.frame for c in model.capsules})
    allowed = model.allowed_collision_pairs
    names = model.frame_names
    adj = set(moveit_adjacent_pairs(model))
    rigid = np.arange(model.n_frames)   # frames joined by fixed frames share a root
    for f in model.topological_order:
        fr = model.frames[f]
        if fr.parent is not None and (fr.kind == "static" or not fr.coupling):
            rigid[f] = rigid[fr.parent]
    frozen = bool(model.notes.get("frozen_joints"))
    try:
        default = {frozenset(p) for p in json.loads(model.notes.get(DEFAULT_NOTE) or "[]")}
    except (ValueError, TypeError):
        default = set()
    out = []
    for i, a in enumerate(solid):
        for b in solid[i + 1:]:
            if allowed[a, b]:
                continue
            if (a, b) in recorded:
                reason, why = recorded[(a, b)]
            elif frozen and rigid[a] == rigid[b] and (a, b) not in adj:
                reason, why = "Frozen", "joined rigidly by frozen joints (a fixed distance)"
            elif (a, b) in adj:
                reason, why = "Adjacent", "parent and child, or joined through frames " \
                                          "without collision geometry"
            elif frozenset((names[a], names[b])) in default:
                reason, why = "Default", "in contact at the home of an older import"
            else:
                reason, why = "Model", "excluded by the robot file's self_collision section"
            out.append({"links": [names[a], names[b]], "reason": reason, "why": why})
    return out


def skipped_summary(robot: RobotModel) -> str:
    """One line: how many frame pairs with collision bodies ``robot`` leaves unchecked, per
    reason (:func:`skipped_pairs`)."""
    rows = skipped_pairs(robot)
    count: dict[str, int] = {}
    for r in rows:
        count[r["reason"]] = count.get(r["reason"], 0) + 1
    return (f"self-collision pairs not checked: {len(rows)} ("
            + (", ".join(f"{k} {v}" for k, v in sorted(count.items(), key=lambda t:
                                                     REASONS.index(t[0])
                                                     if t[0] in REASONS else 99))
               or "none") + ")")
