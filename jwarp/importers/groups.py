"""Planning groups, frozen joints and SRDF collision pairs of an imported URDF robot.

:func:`plan_group` turns an imported robot (:class:`~jwarp.importers.robot.UrdfRobot`) into
the robot jwarp plans with (docs/urdf.md, "Planning groups, grippers, SRDF"):

* ``srdf``: MoveIt's SRDF; the pairs its allowed-collision matrix leaves unchecked
  (``disable_collisions``, ``disable_default_collisions`` less ``enable_collisions``:
  :func:`~jwarp.importers.srdf.disabled_link_pairs`) become self-collision exclude
  pairs: ``srdf_collisions="srdf"`` (default) the SRDF's pairs plus the adjacent and
  always-colliding pairs found so far, without the sampled never-colliding ones (the
  SRDF's own "Never" decided those, on the meshes: what MoveIt checks, jwarp checks,
  adjacent links apart); ``"add"``: every pair found so far (the sampled never-colliding
  ones too) plus the SRDF's; ``"replace"``: the SRDF's only. The reason of every pair is
  recorded (:func:`jwarp.world.self_pairs.skipped_pairs`);
* ``group`` (an SRDF group) or ``joints`` (joint names): the joints to plan with; every
  other joint is frozen (:func:`jwarp.model.freeze_joints`) at its ``lock`` value, else
  its value in the SRDF ``state`` (a ``<group_state>``), else 0 clipped into its limits;
* ``freeze``: joints frozen at a value (``None``: the same default), e.g. gripper
  fingers; the mimic joints of a frozen joint follow it;
* end-effectors: ``end_effectors`` when given; else the group's SRDF
  ``<end_effector>`` parent links, else the tip links of the group's chains; without a
  group the SRDF's end-effectors; else the default rule of :mod:`jwarp.importers.tips`
  applied to the reduced robot.

Errors are ValueError/TypeError naming the option (``group:``, ``joints:``, ``lock:``,
``state:``, ``freeze:``, ``srdf:``, ``end_effectors.NAME:``); the CLI shows them as
``--group:`` etc.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from jwarp.importers.robot import UrdfRobot
from jwarp.importers.srdf import (
    Srdf,
    SrdfError,
    check_srdf,
    group_chain_tips,
    group_end_effectors,
    group_joints,
    read_srdf,
)
from jwarp.importers.tips import default_tips
from jwarp.model import RobotModel, SelfCollision, freeze_joints, frozen_joint_values

#: values of ``GroupOptions.srdf_collisions``
SRDF_COLLISIONS = ("srdf", "add", "replace")


@dataclass
class GroupOptions:
    """Options of :func:`plan_group` (module docstring).

    Attributes:
        srdf: SRDF file or parsed :class:`~jwarp.importers.srdf.Srdf` (None: none).
        group: SRDF group to plan with (needs ``srdf``).
        joints: joint names to plan with (instead of ``group``).
        lock: ``{joint: value}`` [rad or m] of joints outside the group or ``joints``.
        state: SRDF ``<group_state>`` giving the default values of frozen joints.
        freeze: ``{joint: value or None}`` joints frozen (None: the default value).
        srdf_collisions: ``"srdf"`` (SRDF pairs + adjacent and always-colliding pairs so
            far), ``"add"`` (every exclude pair so far + SRDF pairs) or ``"replace"``.
        end_effectors: ``{alias: link or frame}``; None: the defaults (module docstring).
    """

    srdf: str | os.PathLike | Srdf | None = None
    group: str | None = None
    joints: Sequence[str] | None = None
    lock: Mapping[str, float] | None = None
    state: str | None = None
    freeze: Mapping[str, float | None] | None = None
    srdf_collisions: str = "srdf"
    end_effectors: Mapping[str, str] | None = None

    def validate(self) -> None:
        if self.srdf is not None and not isinstance(self.srdf, (str, os.PathLike, Srdf)):
            raise TypeError(f"srdf: expected a file name or Srdf, got {type(self.srdf).__name__}")
        for key in ("group", "state"):
            v = getattr(self, key)
            if v is not None and (not isinstance(v, str) or not v.strip()):
                raise TypeError(f"{key}: expected a non-empty name, got {v!r}")
        if self.group is not None and self.joints is not None:
            raise ValueError("group: give either a group or joints, not both")
        if (self.group is not None or self.state is not None) and self.srdf is None:
            key = "group" if self.group is not None else "state"
            raise ValueError(f"{key}: needs an SRDF (srdf / --srdf)"
                             + ("; or give the joints (joints / --joints)" if key == "group"
                                else ""))
        if self.joints is not None:
            if isinstance(self.joints, str) or not all(
                    isinstance(j, str) and j for j in self.joints):
                raise TypeError("joints: expected a list of joint names")
            if not self.joints:
                raise ValueError("joints: empty list of joints")
        for key in ("lock", "freeze"):
            v = getattr(self, key)
            if v is None:
                continue
            if not isinstance(v, Mapping):
                raise TypeError(f"{key}: expected a mapping {{joint: value}}")
            for name, x in v.items():
                if x is None and key == "freeze":
                    continue
                if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x):
                    raise ValueError(f"{key}: {name}: expected a finite number, got {x!r}")
        if self.state is not None and self.group is None and self.joints is None \
                and not self.freeze:
            raise ValueError("state: only with a group, joints or freeze (it gives the values "
                             "of the locked and frozen joints)")
        if self.lock and self.group is None and self.joints is None:
            raise ValueError("lock: only with a group or joints (the joints outside them are "
                             "locked); to fix a joint without a group use freeze")
        if self.srdf_collisions not in SRDF_COLLISIONS:
            raise ValueError(f"srdf_collisions: expected one of {', '.join(SRDF_COLLISIONS)}, "
                             f"got {self.srdf_collisions!r}")
        if self.srdf_collisions != "srdf" and self.srdf is None:
            raise ValueError(f"srdf_collisions: '{self.srdf_collisions}' only with an SRDF "
                             f"(srdf), whose disable_collisions it is about; without one it "
                             f"would be ignored")


@dataclass
class GroupResult:
    """What :func:`plan_group` made: the reduced ``model``; the ``planned`` joints; the
    ``frozen`` joints and values [rad or m] with where each value came from (``source``:
    lock, freeze, state, default); ``end_effectors_from`` (``given``, ``srdf
    end_effector``, ``group chain tips``, ``default rule``); ``srdf_pairs`` (the SRDF's
    disable_collisions) and ``pairs_added`` (exclude pairs the SRDF added)."""

    model: RobotModel
    planned: list[str]
    frozen: dict[str, float] = field(default_factory=dict)
    source: dict[str, str] = field(default_factory=dict)
    end_effectors_from: str = "default rule"
    srdf: Srdf | None = None
    srdf_pairs: int = 0
    pairs_added: int = 0
    srdf_collisions: str = "srdf"
    #: sampled never-colliding pairs checked again because the SRDF keeps them checked
    pairs_dropped: int = 0


def default_end_effectors(model: RobotModel, links: Any = None) -> dict[str, int]:
    """``{frame name: frame index}`` of the default end-effectors of ``model``
    (:func:`jwarp.importers.tips.default_tips`: one per arm, at its tool); ``links``: the
    frame names that may be tools (an imported URDF's links; None: every frame)."""
    tips = default_tips(model.frame_names, model.parents.tolist(),
                        [f.coupling for f in model.frames], model.joint_names,
                        [j.type for j in model.joints],
                        [f.kind == "dh" and not f.coupling for f in model.frames],
                        None if links is None else [n in links for n in model.frame_names])
    return {model.frame_names[i]: i for i in tips}


def load_srdf(srdf: str | os.PathLike | Srdf, robot: UrdfRobot, states: Any = None,
              groups: Any = None) -> Srdf:
    """The SRDF (read if a path) for the URDF of ``robot``: entries naming links or joints
    the URDF lacks are skipped as MoveIt does (:func:`~jwarp.importers.srdf.prune_srdf`,
    one :class:`~jwarp.importers.srdf.SrdfWarning` naming how many and the first few;
    the returned Srdf lists them in ``skipped``), the rest checked
    (:func:`~jwarp.importers.srdf.check_srdf`; of the group states, those named in
    ``states``, None: all). SrdfError naming the file and the element for a group of
    ``groups`` (the ones the user asked for) that lost a member or was dropped: planning
    with part of a group would be planning with other joints than asked."""
    import warnings

    from jwarp.importers.srdf import SrdfWarning, prune_srdf, skipped_summary

    s = srdf if isinstance(srdf, Srdf) else read_srdf(srdf)
    links, joints = set(robot.source.link_frames), set(robot.source.urdf_joints)
    pruned = prune_srdf(s, links, joints)
    for name in groups or []:
        if name not in s.groups:
            continue   # group_joints names the known groups
        members = set(_members(s, name))
        bad = [k for k in pruned.skipped if k.element == "group" and k.owner in members]
        if bad:
            raise SrdfError(f"group: {s.path}: <group name=\"{name}\"> (line "
                            f"{s.groups[name].line}) names what the URDF lacks: "
                            + "; ".join(str(k) for k in bad[:4])
                            + (f" and {len(bad) - 4} more" if len(bad) > 4 else ""))
    check_srdf(pruned, links, joints, [st for st in (states or [])
                                       if any(g.name == st for g in pruned.group_states)]
               if states is not None else None)
    if pruned.skipped:
        warnings.warn(skipped_summary(pruned), SrdfWarning, stacklevel=3)  # plan_group's caller
    return pruned


def _members(srdf: Srdf, name: str, seen: tuple = ()) -> list[str]:
    """``name`` and its subgroups, recursively (no error on a cycle: check_srdf's)."""
    if name in seen or name not in srdf.groups:
        return []
    out = [name]
    for g in srdf.groups[name].subgroups:
        out += _members(srdf, g, seen + (name,))
    return out


def plan_group(robot: UrdfRobot, options: GroupOptions | None = None, *,
               model: RobotModel | None = None) -> GroupResult:
    """The robot to plan with: ``model`` (default ``robot.model``; e.g. the sphere-fitted
    one, same frames) reduced to the group's joints, with SRDF pairs and end-effectors
    (module docstring). ValueError/TypeError naming the option."""
    o = GroupOptions() if options is None else options
    if not isinstance(o, GroupOptions):
        raise TypeError(f"options: expected GroupOptions, got {type(o).__name__}")
    o.validate()
    if not isinstance(robot, UrdfRobot):
        raise TypeError(f"robot: expected an imported URDF robot (load_urdf), got "
                        f"{type(robot).__name__}")
    model = robot.model if model is None else model
    if not isinstance(model, RobotModel):
        raise TypeError(f"model: expected a RobotModel, got {type(model).__name__}")
    if model.frame_names[:len(robot.model.frame_names)] != robot.model.frame_names:
        raise ValueError("model: its frames are not those of the imported robot")
    urdf_joints = robot.source.urdf_joints
    names = model.joint_names
    srdf = None if o.srdf is None else load_srdf(o.srdf, robot,
                                                  [] if o.state is None else [o.state],
                                                  [] if o.group is None else [o.group])

    def actuated(name: str, key: str) -> str:
        """The model joint a URDF joint name stands for (ValueError naming ``key``)."""
        if name in names:
            return name
        j = urdf_joints.get(name)
        if j is None:
            raise ValueError(f"{key}: unknown joint '{name}' for robot '{model.name}'; its "
                             f"joints: {', '.join(names)}")
        if j.actuated is None:
            raise ValueError(f"{key}: '{name}' is a fixed joint")
        if j.actuated not in names:
            raise ValueError(f"{key}: joint '{name}' is already frozen")
        if key in ("freeze", "lock"):
            raise ValueError(f"{key}: '{name}' mimics '{j.actuated}'; give '{j.actuated}' "
                             f"(its mimic joints follow it)")
        return j.actuated

    # ---- the planned joints
    if o.group is not None:
        group = [urdf_joints[j] for j in group_joints(srdf, o.group, urdf_joints)
                 if j in urdf_joints]          # not the SRDF's virtual joints
        planned = list(dict.fromkeys(j.actuated for j in group if j.actuated is not None))
        planned = [j for j in planned if j in names]
        if not planned:
            raise ValueError(f"group: SRDF group '{o.group}' has no moving joint of robot "
                             f"'{model.name}'")
    elif o.joints is not None:
        planned = list(dict.fromkeys(actuated(j, "joints") for j in o.joints))
    else:
        planned = list(names)

    # ---- default values of frozen joints
    def default(name: str) -> tuple[float, str]:
        j = model.joints[model.joint_index(name)]
        if o.state is not None:
            st = srdf.state(o.state)
            if name in st:
                return st[name], "state"
        return min(max(0.0, j.lower), j.upper), "default"

    frozen: dict[str, float] = {}
    source: dict[str, str] = {}
    if o.group is not None or o.joints is not None:
        for n in names:
            if n not in planned:
                frozen[n], source[n] = default(n)
    for key, table in (("lock", o.lock or {}), ("freeze", o.freeze or {})):
        for name, v in table.items():
            a = actuated(name, key)
            if key == "lock" and a in planned:
                raise ValueError(f"lock: joint '{a}' is one of the planned joints (lock only "
                                 f"the others; to remove it from planning use freeze)")
            if v is None:
                v, src = default(a)
            else:
                src = key
            frozen[a], source[a] = float(v), src
    for name, v in frozen.items():
        j = model.joints[model.joint_index(name)]
        tol = 1e-12 * max(1.0, abs(j.lower), abs(j.upper))
        if not j.lower - tol <= v <= j.upper + tol:
            unit = "m" if j.type == "prismatic" else "rad"
            where = {"state": f"state: <group_state name=\"{o.state}\">",
                     "default": "freeze"}.get(source[name], source[name])
            raise ValueError(f"{where}: {name}={v:g} {unit} is outside the joint's limits "
                             f"[{j.lower:g}, {j.upper:g}]")
    planned = [n for n in planned if n not in frozen]
    if not planned:
        raise ValueError(f"freeze: freezes every joint to plan with of robot '{model.name}'")

    # ---- SRDF collision pairs (frame indices are kept by freezing)
    res = GroupResult(model=model, planned=planned, frozen=frozen, source=source, srdf=srdf,
                      srdf_collisions=o.srdf_collisions)
    if srdf is not None:
        from jwarp.importers.srdf import disabled_link_pairs
        from jwarp.model.pair_reasons import pair_reasons, with_pair_reasons

        def pair_key(a: str, b: str) -> tuple[int, int]:
            i, j = model.frame_index(a), model.frame_index(b)
            return (min(i, j), max(i, j))

        dis = disabled_link_pairs(srdf, robot.source.link_frames)
        pairs = {pair_key(*sorted(p)): ("SRDF", why) for p, why in dis.items()}
        enabled = {pair_key(d.link1, d.link2) for d in srdf.enable_collisions
                   if d.link1 != d.link2}
        res.srdf_pairs = len(srdf.disable_collisions)
        sc = model.self_collision
        why = pair_reasons(model)
        if o.srdf_collisions == "replace":
            new = SelfCollision(exclude_pairs=sorted(pairs))
            res.pairs_added = len(pairs)
            reasons = dict(pairs)
        else:
            have = {tuple(sorted(p)) for p in sc.exclude_pairs}
            drop = {p for p in have if why.get(p, ("",))[0] == "Never"} \
                if o.srdf_collisions == "srdf" else set()
            res.pairs_dropped = len(drop - set(pairs))
            kept = [p for p in sc.exclude_pairs
                    if tuple(sorted(p)) not in drop and tuple(sorted(p)) not in enabled]
            added = sorted(set(pairs) - have)
            res.pairs_added = len(added)
            new = SelfCollision(groups={k: list(v) for k, v in sc.groups.items()},
                                include_pairs=list(sc.include_pairs),
                                exclude_pairs=[*kept, *added])
            left = {tuple(sorted(p)) for p in kept}
            reasons = {p: r for p, r in why.items() if p in left}
            reasons.update(pairs)     # the SRDF's reason first
        notes = dict(model.notes)
        notes["srdf"] = srdf.path
        model = with_pair_reasons(model.copy(self_collision=new, notes=notes), reasons)
    if frozen:
        model = freeze_joints(model, frozen)
    if o.group is not None or o.joints is not None:
        notes = dict(model.notes)
        notes["planning_group"] = o.group if o.group is not None else ",".join(planned)
        model = model.copy(notes=notes)

    # ---- end-effectors
    eff: dict[str, str]
    if o.end_effectors is not None:
        eff, res.end_effectors_from = dict(o.end_effectors), "given"
    else:
        eff = {}
        if srdf is not None:
            ees = (group_end_effectors(srdf, o.group) if o.group is not None
                   else srdf.end_effectors)
            eff = {e.name: e.parent_link for e in ees}
            res.end_effectors_from = "srdf end_effector"
            if not eff and o.group is not None:
                eff = {t: t for t in group_chain_tips(srdf, o.group)}
                res.end_effectors_from = "group chain tips"
        if not eff:
            eff = {n: n for n in default_end_effectors(model, robot.source.link_frames)}
            res.end_effectors_from = "default rule"
    fnames = model.frame_names
    table = {}
    for alias, target in eff.items():
        if target not in fnames and target not in model.frame_aliases:
            raise ValueError(f"end_effectors.{alias}: unknown link or frame '{target}'")
        # a URDF joint's name is its child link's frame (a frame alias, docs/urdf.md)
        idx = fnames.index(target) if target in fnames else model.frame_aliases[target]
        if alias in fnames and fnames.index(alias) != idx:
            raise ValueError(f"end_effectors.{alias}: the name of another frame (than "
                             f"'{target}'); choose another name")
        table[alias] = idx
    res.model = model.copy(end_effectors=table)
    return res


def frozen_summary(model: RobotModel) -> str:
    """``name=value, ...`` of the frozen joints of ``model`` ('' when none)."""
    return ", ".join(f"{k}={v:g}" for k, v in frozen_joint_values(model).items())


__all__ = ["GroupOptions", "GroupResult", "SrdfError", "default_end_effectors", "load_srdf",
           "plan_group", "frozen_summary"]
