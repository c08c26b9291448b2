"""Default end-effectors of an imported robot: one per arm, at its tool (docs/urdf.md).

A robot imported without named end-effectors gets one per *branch* of its moving joints,
not one per leaf link (Baxter has 29 leaf links: sonar ring, display, cameras, finger
tips). The rule (:func:`default_tips`), on the frame tree:

1. **Gripper joints do not make branches.** A moving frame is a gripper frame when its
   name or the name of a joint driving it contains ``finger``, ``gripper``, ``knuckle``,
   ``jaw``, ``claw`` or the word ``hand`` (``hand_index_joint``), when it is driven only
   by joints that drive a gripper frame (the mimic joints of a finger), or when it is one of two or more prismatic frames without
   moving frames below them that hang from one rigid body (a parallel-jaw gripper).
   Frozen joints (:func:`jwarp.model.freeze_joints`) are not moving; a frozen joint
   named like a gripper joint still ends the tool's body (rule 3).
2. **Branches.** The *tip* of a branch is a moving, non-gripper frame with no such frame
   below it (the last arm joint). Branches driven by fewer than half the joints of the
   longest one (counted from the root, distinct joints) are dropped: a pan/tilt head or
   a laser tilt beside 7-joint arms is not an end-effector.
3. **The tool of a branch** is a frame of the rigid body after the tip (the tip frame
   and the frames reached from it through fixed frames, fingers excluded): the one
   whose name has the best of the words ``tcp``, ``grasp*``, ``tool<N>``,
   ``ee``/``eef``/``effector``, ``flange``, ``gripper``, ``hand`` (ties: a leaf of the
   body first, then the deepest, then by name); with none of them, the frame reached by
   following the body from the tip while it does not branch. Only links are tools
   (not the ``<joint>_origin`` and ``<joint>_axis`` helper frames of the URDF import).

Panda: ``panda_hand_tcp`` (the fingers are gripper joints, fixed or not). Baxter:
``left_gripper`` and ``right_gripper`` (the 1-joint head is dropped). UR10: ``tool0``.
TIAGo: ``hand_grasping_frame``. PR2: ``l/r_gripper_tool_frame``.
This module imports nothing from jwarp (the URDF importer and the planning groups use it).
"""

from __future__ import annotations

import re
from collections.abc import Sequence

#: joint or frame names of gripper joints (see the module docstring)
GRIPPER_WORDS = re.compile(r"finger|gripper|knuckle|jaw|claw|(^|_)hand(_|$)", re.IGNORECASE)
#: words of tool frame names, best first (each a regex matching one whole word)
TOOL_WORDS = (r"tcp", r"grasp\w*", r"tool\d*", r"ee|eef|effector|endeffector", r"flange",
              r"gripper", r"hand")


def tool_rank(name: str) -> int | None:
    """Index in :data:`TOOL_WORDS` of the best word of ``name`` (words split at anything but
    letters and digits), None when it has none."""
    words = [w for w in re.split(r"[^a-z0-9]+", name.lower()) if w]
    for k, pat in enumerate(TOOL_WORDS):
        if any(re.fullmatch(pat, w) for w in words):
            return k
    return None


def default_tips(names: Sequence[str], parents: Sequence[int],
                 couplings: Sequence[Sequence[tuple[int, float]]],
                 joint_names: Sequence[str], joint_types: Sequence[str],
                 frozen: Sequence[bool] | None = None,
                 tools: Sequence[bool] | None = None) -> list[int]:
    """Frame indices of the default end-effectors (module docstring), in frame order.

    Args:
        names: (n_frames,) frame names.
        parents: (n_frames,) parent frame index, -1 for a root.
        couplings: per frame ``[(joint index, coefficient), ...]``; empty: not moving.
        joint_names, joint_types: per joint (``revolute`` / ``prismatic``).
        frozen: per frame, whether it is a DH frame driven by no joint (a frozen joint);
            a frozen frame named like a gripper joint and the frames below it are not
            part of the tool's body (the fingers of a frozen gripper).
        tools: per frame, whether it may be a tool (an importer passes its links, not
            the helper frames it adds); None: every frame.
    """
    n = len(names)
    children: list[list[int]] = [[] for _ in range(n)]
    for i, p in enumerate(parents):
        if p >= 0:
            children[p].append(i)
    order: list[int] = []
    stack = [i for i in range(n) if parents[i] < 0][::-1]
    while stack:
        i = stack.pop()
        order.append(i)
        stack.extend(reversed(children[i]))
    depth = [0] * n
    root = list(range(n))   # root of each frame's rigid body
    for i in order:
        if parents[i] >= 0:
            depth[i] = depth[parents[i]] + 1
            if not couplings[i]:
                root[i] = root[parents[i]]
    moving = [bool(c) for c in couplings]

    gripper = [moving[i] and (GRIPPER_WORDS.search(names[i]) is not None or any(
        GRIPPER_WORDS.search(joint_names[j]) for j, _ in couplings[i])) for i in range(n)]
    changed = True
    while changed:      # mimics of a finger's joint
        gjoints = {j for i in range(n) if gripper[i] for j, _ in couplings[i]}
        changed = False
        for i in range(n):
            if moving[i] and not gripper[i] and all(j in gjoints for j, _ in couplings[i]):
                gripper[i] = changed = True

    def below(flags: list[bool]) -> list[bool]:
        out = [False] * n
        for i in reversed(order):
            p = parents[i]
            if p >= 0 and (flags[i] or out[i]):
                out[p] = True
        return out

    moving_below = below(moving)
    jaws: dict[int, list[int]] = {}
    for i in range(n):
        if moving[i] and not gripper[i] and not moving_below[i] and parents[i] >= 0 \
                and all(joint_types[j] == "prismatic" for j, _ in couplings[i]):
            jaws.setdefault(root[parents[i]], []).append(i)
    for members in jaws.values():
        if len(members) >= 2:
            for i in members:
                gripper[i] = True
    arm = [moving[i] and not gripper[i] for i in range(n)]
    if not any(arm):        # a gripper alone: its fingers are the branches
        arm, gripper = moving, [False] * n
    arm_below = below(arm)
    tips = [i for i in range(n) if arm[i] and not arm_below[i]]

    def count(i: int) -> int:
        js: set[int] = set()
        while i >= 0:
            if arm[i]:
                js.update(j for j, _ in couplings[i])
            i = parents[i]
        return len(js)

    counts = {t: count(t) for t in tips}
    longest = max(counts.values(), default=0)
    out = []
    for t in tips:
        if 2 * counts[t] < longest:
            continue
        body, stack = [], [t]
        while stack:
            i = stack.pop()
            body.append(i)
            stack.extend(c for c in children[i] if not moving[c] and not (
                frozen is not None and frozen[c] and GRIPPER_WORDS.search(names[c])))
        inside = set(body)
        ok = [tools is None or bool(tools[i]) for i in range(n)]
        ranked = [i for i in body if ok[i] and tool_rank(names[i]) is not None]
        if ranked:
            best = min(ranked, key=lambda i: (tool_rank(names[i]),
                                              any(c in inside for c in children[i]),
                                              -depth[i], names[i]))
        else:
            best = cur = t
            while True:
                nxt = [c for c in children[cur] if c in inside]
                if len(nxt) != 1:
                    break
                cur = nxt[0]
                if ok[cur] or not ok[best]:
                    best = cur
        out.append(best)
    return sorted(set(out))
