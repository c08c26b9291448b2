"""MoveIt's SRDF (semantic robot description) in and out of jwarp (docs/urdf.md, SRDF).

Read (:func:`read_srdf`): what MoveIt's setup assistant writes. Used: ``<group>``
(``<joint>``, ``<link>``, ``<chain base_link tip_link>``, ``<group>`` subgroups),
``<group_state>``, ``<end_effector>``, ``<disable_collisions link1 link2 reason>``,
``<enable_collisions link1 link2>`` and ``<disable_default_collisions link>`` (the pairs
MoveIt's allowed-collision matrix leaves unchecked: :func:`disabled_link_pairs`);
``<virtual_joint>`` names (a floating base) are accepted where a joint is named (and are
no joint of the robot). Not used, and ignored with ONE :class:`SrdfIgnoredWarning` per
file listing them (``Srdf.ignored``): ``<passive_joint>`` (at the top or inside a group,
as MoveIt's panda.srdf writes it), ``<link_sphere_approximation>`` (jwarp fits its own
spheres), ``<joint_property>`` and any other element. :func:`check_srdf`
checks every name against the URDF (strict); :func:`prune_srdf` drops the entries naming
links or joints the URDF lacks, as MoveIt's loader does (one SRDF often serves several
URDFs: a whole robot and its arm, or joints renamed by a prefix), and lists them;
:func:`group_joints` resolves a group to the URDF's
joints as MoveIt does (a ``<link>`` adds the joint whose child it is; a chain the joints
from ``base_link`` down to ``tip_link``; subgroups recursively).

Write (:func:`srdf_text`, :func:`write_srdf`): the robot's frame pairs that are never
checked for self-collision as ``<disable_collisions>`` (reason ``Adjacent`` for a frame
and its parent, ``Default`` for the pairs in contact at the home configuration that the
import excluded (``notes['self_collision_default']``, :mod:`jwarp.world.home_fit`),
else ``Never``); :func:`jwarp.importers.urdf_export.export_urdf` writes
it beside the URDF.

Errors are :class:`SrdfError` (a ValueError) naming the file, the element and its line.
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any
from urllib.parse import quote, unquote
from xml.sax.saxutils import quoteattr

if TYPE_CHECKING:
    from jwarp.model import RobotModel

#: the word that starts the comment of an exported SRDF naming its URDF (:func:`export_mark`)
EXPORT_MARK = "jwarp-export"
#: reasons :func:`srdf_text` writes
REASON_ADJACENT = "Adjacent"
REASON_NEVER = "Never"
REASON_DEFAULT = "Default"
#: ``RobotModel.notes`` key: JSON ``[[frame a, frame b], ...]`` of the pairs excluded by
#: MoveIt's "Default" rule (in contact at the home configuration; written with that reason)
DEFAULT_NOTE = "self_collision_default"


class SrdfError(ValueError):
    """A malformed SRDF or one naming links/joints the URDF lacks; the message names the
    file and the element."""


class SrdfWarning(UserWarning):
    """SRDF entries skipped because they name links or joints the URDF lacks."""


class SrdfIgnoredWarning(UserWarning):
    """SRDF elements jwarp does not use (``passive_joint``, ``link_sphere_approximation``,
    ...): one warning per file, listing them."""


#: elements of an SRDF root that jwarp reads
USED_ELEMENTS = ("group", "group_state", "end_effector", "virtual_joint",
                 "disable_collisions", "enable_collisions", "disable_default_collisions")


@dataclass
class SrdfSkipped:
    """One entry :func:`prune_srdf` dropped: ``element`` (``group``, ``group_state``,
    ``end_effector``, ``disable_collisions``), ``owner`` (the group/state/end-effector
    name; '' for disable_collisions), ``what`` (e.g. "joint 'baxter/head_pan'"),
    ``line`` in the file; ``whole``: a consequence of other skips, no unknown name of its
    own (a group left empty, a state with no joint left, a subgroup or group that is
    gone)."""

    element: str
    owner: str
    what: str
    line: int = 0
    whole: bool = False

    def __str__(self) -> str:
        where = (f"<{self.element} name=\"{self.owner}\">" if self.owner
                 else f"<{self.element}>")
        return f"{where} (line {self.line}): {self.what}"


@dataclass
class SrdfGroup:
    """One ``<group>``: its ``joints``, ``links``, ``chains`` ``[(base_link, tip_link)]``
    and ``subgroups`` (names of other groups), in document order; ``line`` in the file."""

    name: str
    joints: list[str] = field(default_factory=list)
    links: list[str] = field(default_factory=list)
    chains: list[tuple[str, str]] = field(default_factory=list)
    subgroups: list[str] = field(default_factory=list)
    line: int = 0


@dataclass
class SrdfEndEffector:
    """One ``<end_effector>``: ``parent_link`` is where the tool attaches (jwarp's
    end-effector frame); ``group`` the gripper's group, ``parent_group`` the arm's."""

    name: str
    parent_link: str
    group: str | None = None
    parent_group: str | None = None
    line: int = 0


@dataclass
class SrdfGroupState:
    """One ``<group_state name group>``: ``values`` ``{joint: value}`` [rad or m]; a
    multi-DOF joint (a floating ``virtual_joint``) has a tuple of numbers. ``group`` may be
    None (pinocchio's SRDFs leave it out)."""

    name: str
    group: str | None
    values: dict[str, float | tuple[float, ...]] = field(default_factory=dict)
    line: int = 0


@dataclass
class SrdfDisabled:
    """One ``<disable_collisions link1 link2 reason>``."""

    link1: str
    link2: str
    reason: str = ""
    line: int = 0


@dataclass
class Srdf:
    """The parts of an SRDF jwarp reads (module docstring); ``path`` names the source."""

    name: str
    groups: dict[str, SrdfGroup] = field(default_factory=dict)
    group_states: list[SrdfGroupState] = field(default_factory=list)
    end_effectors: list[SrdfEndEffector] = field(default_factory=list)
    disable_collisions: list[SrdfDisabled] = field(default_factory=list)
    virtual_joints: list[str] = field(default_factory=list)
    path: str = "<srdf>"
    #: entries :func:`prune_srdf` dropped (empty for a file read as it is)
    skipped: list[SrdfSkipped] = field(default_factory=list)
    #: ``<enable_collisions link1 link2>``: pairs checked whatever else disables them
    enable_collisions: list[SrdfDisabled] = field(default_factory=list)
    #: ``<disable_default_collisions link>``: links whose pairs are unchecked unless enabled
    no_default_links: list[tuple[str, int]] = field(default_factory=list)
    #: elements not used by jwarp: ``(element, line)``, e.g. ``("group/passive_joint", 52)``
    ignored: list[tuple[str, int]] = field(default_factory=list)

    @property
    def state_names(self) -> list[str]:
        """The names of the ``<group_state>`` elements, without repeats."""
        return list(dict.fromkeys(st.name for st in self.group_states))

    def state(self, name: str) -> dict[str, float]:
        """``{joint: value}`` of every ``<group_state>`` called ``name`` (MoveIt names states
        per group: ``home`` of the arm and ``home`` of the hand are merged); joints of
        several values (a floating base) are left out. SrdfError listing the known states,
        or naming a joint two states of that name give different values."""
        found = [st for st in self.group_states if st.name == name]
        dropped = [k for k in self.skipped if k.element == "group_state" and k.owner == name]
        if not found and dropped:
            raise SrdfError(f"state: {self.path}: <group_state name=\"{name}\"> (line "
                            f"{dropped[0].line}): "
                            + "; ".join(f"unknown {k.what}" for k in dropped[:4]
                                        if not k.whole)
                            + (f" and {len(dropped) - 5} more" if len(dropped) > 5 else "")
                            + " (nothing of the state is in the URDF)")
        if not found:
            raise SrdfError(f"state: {self.path} has no <group_state name=\"{name}\"> (its "
                            f"states: {', '.join(self.state_names) or 'none'})")
        out: dict[str, float] = {}
        line: dict[str, int] = {}
        for st in found:
            for j, v in st.values.items():
                if isinstance(v, tuple):
                    continue
                if j in out and out[j] != v:
                    raise SrdfError(f"state: {self.path}: <group_state name=\"{name}\"> lines "
                                    f"{line[j]} and {st.line} give joint '{j}' different values")
                out[j], line[j] = v, st.line
        return out


# ------------------------------------------------------------------ reading
def read_srdf(path: str | os.PathLike) -> Srdf:
    """Parse the SRDF file ``path`` (no check against a URDF: :func:`check_srdf`).
    SrdfError naming the file and element for bad XML, a root other than ``<robot>``, a
    missing attribute, a value that is not a finite number, a name defined twice."""
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise SrdfError(f"{path}: SRDF file not found")
    from lxml import etree

    try:
        root = etree.parse(path, etree.XMLParser(remove_comments=True)).getroot()
    except etree.XMLSyntaxError as e:
        raise SrdfError(f"{path}: not valid XML: {e}") from None
    except OSError as e:
        raise SrdfError(f"{path}: cannot read: {e}") from None
    return _parse(root, path)


def parse_srdf(text: str | bytes, source: str = "<srdf>") -> Srdf:
    """:func:`read_srdf` of a document given as text; ``source`` names it in errors."""
    from lxml import etree

    try:
        root = etree.fromstring(text.encode() if isinstance(text, str) else text,
                                etree.XMLParser(remove_comments=True))
    except etree.XMLSyntaxError as e:
        raise SrdfError(f"{source}: not valid XML: {e}") from None
    return _parse(root, source)


def _attr(el: Any, key: str, path: str) -> str:
    v = el.get(key)
    if v is None or not v.strip():
        name = el.get("name")
        what = f"<{el.tag}{f' name={quoteattr(name)}' if name and key != 'name' else ''}>"
        raise SrdfError(f"{path}: {what} (line {el.sourceline}) has no '{key}' attribute")
    return v.strip()


def _parse(root: Any, path: str) -> Srdf:
    if root.tag != "robot":
        raise SrdfError(f"{path}: the root element is <{root.tag}>, expected <robot>")
    out = Srdf(name=root.get("name") or "", path=path)
    for el in root:
        if not isinstance(el.tag, str):
            continue
        if el.tag == "group":
            name = _attr(el, "name", path)
            if name in out.groups:
                raise SrdfError(f"{path}: <group name=\"{name}\"> (line {el.sourceline}) is "
                                f"defined twice (also line {out.groups[name].line})")
            g = SrdfGroup(name=name, line=el.sourceline)
            for sub in el:
                if not isinstance(sub.tag, str):
                    continue
                if sub.tag == "joint":
                    g.joints.append(_attr(sub, "name", path))
                elif sub.tag == "link":
                    g.links.append(_attr(sub, "name", path))
                elif sub.tag == "chain":
                    g.chains.append((_attr(sub, "base_link", path), _attr(sub, "tip_link", path)))
                elif sub.tag == "group":
                    g.subgroups.append(_attr(sub, "name", path))
                else:   # e.g. <passive_joint>: MoveIt's group parser skips it too
                    out.ignored.append((f"group/{sub.tag}", sub.sourceline))
            out.groups[name] = g
        elif el.tag == "group_state":
            name = _attr(el, "name", path)
            st = SrdfGroupState(name=name, group=el.get("group"), line=el.sourceline)
            for sub in el:
                if not isinstance(sub.tag, str) or sub.tag != "joint":
                    continue
                jn = _attr(sub, "name", path)
                text = _attr(sub, "value", path)
                try:
                    vals = [float(x) for x in text.split()]
                except ValueError:
                    vals = []
                if not vals or not all(math.isfinite(v) for v in vals):
                    raise SrdfError(f"{path}: <group_state name=\"{name}\"> joint '{jn}' "
                                    f"(line {sub.sourceline}): value '{text}' is not finite "
                                    f"numbers")
                st.values[jn] = vals[0] if len(vals) == 1 else tuple(vals)
            out.group_states.append(st)
        elif el.tag == "end_effector":
            out.end_effectors.append(SrdfEndEffector(
                name=_attr(el, "name", path), parent_link=_attr(el, "parent_link", path),
                group=el.get("group"), parent_group=el.get("parent_group"), line=el.sourceline))
        elif el.tag == "virtual_joint":
            out.virtual_joints.append(_attr(el, "name", path))
        elif el.tag in ("disable_collisions", "enable_collisions"):
            pair = SrdfDisabled(link1=_attr(el, "link1", path), link2=_attr(el, "link2", path),
                                reason=el.get("reason") or "", line=el.sourceline)
            (out.disable_collisions if el.tag == "disable_collisions"
             else out.enable_collisions).append(pair)
        elif el.tag == "disable_default_collisions":
            out.no_default_links.append((_attr(el, "link", path), el.sourceline))
        else:
            out.ignored.append((el.tag, el.sourceline))
    names = [e.name for e in out.end_effectors]
    for k, n in enumerate(names):
        if n in names[:k]:
            raise SrdfError(f"{path}: <end_effector name=\"{n}\"> (line "
                            f"{out.end_effectors[k].line}) is defined twice")
    if out.ignored:
        import warnings

        warnings.warn(ignored_summary(out), SrdfIgnoredWarning, stacklevel=3)
    return out


def ignored_summary(srdf: Srdf) -> str:
    """One line naming the elements of ``srdf`` jwarp does not use (``Srdf.ignored``), each
    with how often and its first line ('' when none)."""
    if not srdf.ignored:
        return ""
    first: dict[str, int] = {}
    count: dict[str, int] = {}
    for tag, line in srdf.ignored:
        first.setdefault(tag, line)
        count[tag] = count.get(tag, 0) + 1
    items = ", ".join(f"<{t.split('/')[-1]}>" + (" in a <group>" if "/" in t else "")
                      + (f" x{count[t]}" if count[t] > 1 else "") + f" (line {first[t]})"
                      for t in first)
    n = len(srdf.ignored)
    return (f"{srdf.path}: {n} element{'s' if n != 1 else ''} jwarp does not use "
            f"{'are' if n != 1 else 'is'} ignored (as MoveIt's parser ignores what it does "
            f"not know): {items}")


def check_srdf(srdf: Srdf, links: set[str] | list[str], joints: set[str] | list[str],
               states: Any = None) -> None:
    """SrdfError naming the file, the element and its line for every name of ``srdf`` that
    is not a URDF link (``links``), joint (``joints``, fixed ones included; or a
    ``<virtual_joint>`` of the SRDF) or group, and
    for a group whose subgroups form a cycle. ``states``: the names of the group states
    to check (None: all); a state's joints of several values (a floating base) are not
    checked."""
    links, joints = set(links), set(joints) | set(srdf.virtual_joints)
    p = srdf.path

    def need(name: str, known: set[str], what: str, where: str) -> None:
        if name not in known:
            raise SrdfError(f"{p}: {where}: unknown {what} '{name}' (not in the URDF)")

    for g in srdf.groups.values():
        where = f"<group name=\"{g.name}\"> (line {g.line})"
        for j in g.joints:
            need(j, joints, "joint", where)
        for link in g.links:
            need(link, links, "link", where)
        for base, tip in g.chains:
            need(base, links, "link", f"{where} <chain base_link>")
            need(tip, links, "link", f"{where} <chain tip_link>")
        for s in g.subgroups:
            if s not in srdf.groups:
                raise SrdfError(f"{p}: {where}: unknown subgroup '{s}' (groups: "
                                f"{', '.join(srdf.groups)})")
        _subgroups(srdf, g.name, ())
    for st in srdf.group_states:
        if states is not None and st.name not in states:
            continue
        where = f"<group_state name=\"{st.name}\"> (line {st.line})"
        if st.group is not None and st.group not in srdf.groups:
            raise SrdfError(f"{p}: {where}: unknown group '{st.group}' (groups: "
                            f"{', '.join(srdf.groups) or 'none'})")
        for j, v in st.values.items():
            if not isinstance(v, tuple):
                need(j, joints, "joint", where)
    for e in srdf.end_effectors:
        where = f"<end_effector name=\"{e.name}\"> (line {e.line})"
        need(e.parent_link, links, "link", f"{where} parent_link")
        for key in ("group", "parent_group"):
            g = getattr(e, key)
            if g is not None and g not in srdf.groups:
                raise SrdfError(f"{p}: {where}: unknown {key} '{g}' (groups: "
                                f"{', '.join(srdf.groups) or 'none'})")
    for tag, pairs in (("disable_collisions", srdf.disable_collisions),
                       ("enable_collisions", srdf.enable_collisions)):
        for d in pairs:
            where = f"<{tag}> (line {d.line})"
            need(d.link1, links, "link", f"{where} link1")
            need(d.link2, links, "link", f"{where} link2")
    for link, line in srdf.no_default_links:
        need(link, links, "link", f"<disable_default_collisions> (line {line}) link")


def prune_srdf(srdf: Srdf, links: set[str] | list[str], joints: set[str] | list[str]
               ) -> Srdf:
    """A copy of ``srdf`` without the entries that name links or joints the URDF lacks
    (``links``, ``joints``: its names, fixed joints included; the SRDF's
    ``<virtual_joint>`` names count as joints), as MoveIt's SRDF loader skips them:
    a group's unknown joints, links and chains (a chain with an unknown base or tip) and
    subgroups that are gone; a group left empty; a group state's unknown joints (a state
    left without joints is dropped); an end-effector whose parent link is unknown or whose
    group is gone (an unknown ``parent_group`` is forgotten); a ``disable_collisions`` of
    an unknown link. The dropped entries are listed in the copy's ``skipped``
    (:class:`SrdfSkipped`); nothing is raised (a cycle of subgroups is left for
    :func:`check_srdf`)."""
    links, joints = set(links), set(joints) | set(srdf.virtual_joints)
    out = Srdf(name=srdf.name, virtual_joints=list(srdf.virtual_joints), path=srdf.path,
               skipped=list(srdf.skipped), ignored=list(srdf.ignored))
    skip = out.skipped
    groups: dict[str, SrdfGroup] = {}
    for g in srdf.groups.values():
        ng = SrdfGroup(name=g.name, line=g.line)
        for j in g.joints:
            if j in joints:
                ng.joints.append(j)
            else:
                skip.append(SrdfSkipped("group", g.name, f"joint '{j}'", g.line))
        for link in g.links:
            if link in links:
                ng.links.append(link)
            else:
                skip.append(SrdfSkipped("group", g.name, f"link '{link}'", g.line))
        for base, tip in g.chains:
            bad = [x for x in (base, tip) if x not in links]
            if bad:
                skip.append(SrdfSkipped("group", g.name, f"chain {base} -> {tip} (link "
                                        f"'{bad[0]}')", g.line))
            else:
                ng.chains.append((base, tip))
        ng.subgroups = list(g.subgroups)
        groups[g.name] = ng
    # groups left empty are dropped, then subgroups naming them, until nothing changes
    while True:
        gone = [n for n, g in groups.items()
                if not (g.joints or g.links or g.chains or g.subgroups)]
        for n in gone:
            skip.append(SrdfSkipped("group", n, "every member (the group is dropped)",
                                    groups.pop(n).line, whole=True))
        changed = bool(gone)
        for g in groups.values():
            keep = [s for s in g.subgroups if s in groups]
            for s in g.subgroups:
                if s not in groups and s not in srdf.groups:
                    keep.append(s)   # never defined: check_srdf names it
                elif s not in groups:
                    skip.append(SrdfSkipped("group", g.name, f"subgroup '{s}' (dropped)",
                                            g.line, whole=True))
            if len(keep) != len(g.subgroups):
                changed = True
            g.subgroups = keep
        if not changed:
            break
    out.groups = groups
    for st in srdf.group_states:
        ns = SrdfGroupState(name=st.name, group=st.group, line=st.line)
        for j, v in st.values.items():
            if j in joints or isinstance(v, tuple):   # several values: a floating base
                ns.values[j] = v
            else:
                skip.append(SrdfSkipped("group_state", st.name, f"joint '{j}'", st.line))
        if st.group is not None and st.group in srdf.groups and st.group not in groups:
            skip.append(SrdfSkipped("group_state", st.name, f"group '{st.group}' (dropped; "
                                    f"the state is dropped)", st.line, whole=True))
        elif st.values and not ns.values:
            skip.append(SrdfSkipped("group_state", st.name, "every joint (the state is "
                                    "dropped)", st.line, whole=True))
        else:
            out.group_states.append(ns)
    for e in srdf.end_effectors:
        if e.parent_link not in links:
            skip.append(SrdfSkipped("end_effector", e.name, f"parent_link '{e.parent_link}' "
                                    f"(the end-effector is dropped)", e.line))
            continue
        if e.group is not None and e.group in srdf.groups and e.group not in groups:
            skip.append(SrdfSkipped("end_effector", e.name, f"group '{e.group}' (dropped; the "
                                    f"end-effector is dropped)", e.line, whole=True))
            continue
        pg = e.parent_group
        if pg is not None and pg in srdf.groups and pg not in groups:
            skip.append(SrdfSkipped("end_effector", e.name, f"parent_group '{pg}' (dropped)",
                                    e.line, whole=True))
            pg = None
        out.end_effectors.append(SrdfEndEffector(name=e.name, parent_link=e.parent_link,
                                                 group=e.group, parent_group=pg, line=e.line))
    for tag, pairs, kept in (("disable_collisions", srdf.disable_collisions,
                              out.disable_collisions),
                             ("enable_collisions", srdf.enable_collisions,
                              out.enable_collisions)):
        for d in pairs:
            bad = [x for x in (d.link1, d.link2) if x not in links]
            if bad:
                skip.append(SrdfSkipped(tag, "", f"link '{bad[0]}'", d.line))
            else:
                kept.append(d)
    for link, line in srdf.no_default_links:
        if link in links:
            out.no_default_links.append((link, line))
        else:
            skip.append(SrdfSkipped("disable_default_collisions", "", f"link '{link}'", line))
    return out


def disabled_link_pairs(srdf: Srdf, links: Any) -> dict[frozenset[str], str]:
    """The link pairs MoveIt's allowed-collision matrix leaves unchecked for ``srdf``, among
    ``links`` (the links with collision geometry): ``{frozenset((a, b)): why}``, ``why``
    naming the element, its line and reason, e.g. ``"disable_collisions line 40, reason
    Never"``. As MoveIt builds it: every ``<disable_collisions>`` pair, and every pair of a
    ``<disable_default_collisions>`` link, less the ``<enable_collisions>`` pairs (checked
    whatever else says)."""
    names = list(dict.fromkeys(links))
    out: dict[frozenset[str], str] = {}
    for link, line in srdf.no_default_links:
        for other in names:
            if other != link:
                out.setdefault(frozenset((link, other)),
                               f"disable_default_collisions line {line} (link '{link}')")
    for d in srdf.disable_collisions:
        if d.link1 != d.link2:
            out[frozenset((d.link1, d.link2))] = (f"disable_collisions line {d.line}"
                                                  + (f", reason {d.reason}" if d.reason else ""))
    for d in srdf.enable_collisions:
        out.pop(frozenset((d.link1, d.link2)), None)
    return out


def skipped_summary(srdf: Srdf, most: int = 4) -> str:
    """One line: how many entries of ``srdf`` were skipped (:func:`prune_srdf`), per
    element, and the first ``most`` ('' when none)."""
    if not srdf.skipped:
        return ""
    named = [k for k in srdf.skipped if not k.whole]
    count: dict[str, int] = {}
    for k in named:
        count[k.element] = count.get(k.element, 0) + 1
    names = list(dict.fromkeys(k.what.split("'")[1] for k in named if "'" in k.what))
    dropped = [k for k in srdf.skipped if k.whole]
    first = "; ".join(str(k) for k in srdf.skipped[:most])
    more = f"; and {len(srdf.skipped) - most} more" if len(srdf.skipped) > most else ""
    return (f"{srdf.path}: {len(named)} entries name links or joints the URDF lacks and "
            f"are skipped, as MoveIt does ("
            + ", ".join(f"{v} in {k}" for k, v in count.items())
            + (f"; {len(dropped)} elements left empty or dangling, dropped" if dropped else "")
            + f"; {len(names)} unknown names, e.g. "
            + ", ".join(f"'{n}'" for n in names[:most]) + f"): {first}{more}")


def _subgroups(srdf: Srdf, name: str, seen: tuple[str, ...]) -> list[str]:
    """``name`` and its subgroups, recursively (SrdfError on a cycle)."""
    if name in seen:
        cyc = " -> ".join(seen[seen.index(name):] + (name,))
        raise SrdfError(f"{srdf.path}: <group name=\"{name}\">: subgroups form a cycle: {cyc}")
    out = [name]
    for s in srdf.groups[name].subgroups:
        out += _subgroups(srdf, s, seen + (name,))
    return out


def group_joints(srdf: Srdf, name: str, urdf_joints: dict[str, Any]) -> list[str]:
    """The URDF joints of group ``name`` (MoveIt's meaning; module docstring), in document
    order without repeats, fixed ones included. ``urdf_joints``: ``{name: joint}`` with
    attributes ``parent`` and ``child`` (links), e.g.
    :attr:`jwarp.importers.urdf.UrdfImport.urdf_joints`. SrdfError naming the group for an
    unknown group or a chain whose tip_link is not below its base_link."""
    if name not in srdf.groups:
        raise SrdfError(f"group: {srdf.path} has no <group name=\"{name}\"> (its groups: "
                        f"{', '.join(srdf.groups) or 'none'})")
    by_child = {j.child: j for j in urdf_joints.values()}
    out: list[str] = []
    for gname in _subgroups(srdf, name, ()):
        g = srdf.groups[gname]
        out += g.joints
        out += [by_child[link].name for link in g.links if link in by_child]
        for base, tip in g.chains:
            chain, link = [], tip
            while link != base:
                j = by_child.get(link)
                if j is None:
                    raise SrdfError(f"{srdf.path}: <group name=\"{gname}\"> (line {g.line}) "
                                    f"<chain>: tip_link '{tip}' is not below base_link "
                                    f"'{base}'")
                chain.append(j.name)
                link = j.parent
            out += chain[::-1]
    return list(dict.fromkeys(out))


def group_chain_tips(srdf: Srdf, name: str) -> list[str]:
    """The ``tip_link`` of every chain of group ``name`` and its subgroups."""
    return list(dict.fromkeys(tip for g in _subgroups(srdf, name, ())
                              for _, tip in srdf.groups[g].chains))


def group_end_effectors(srdf: Srdf, name: str) -> list[SrdfEndEffector]:
    """The ``<end_effector>`` elements of group ``name``: those whose ``parent_group`` or
    ``group`` is ``name`` or one of its subgroups."""
    members = set(_subgroups(srdf, name, ()))
    return [e for e in srdf.end_effectors
            if e.parent_group in members or (e.parent_group is None and e.group in members)]


# ------------------------------------------------------------------ writing
def srdf_path(urdf_path: str | os.PathLike) -> Path:
    """The SRDF written beside a URDF: ``robot.urdf`` -> ``robot.srdf`` (another suffix
    is kept and ``.srdf`` appended)."""
    p = Path(urdf_path)
    return p.with_suffix(".srdf") if p.suffix.lower() == ".urdf" else p.with_name(p.name + ".srdf")


def disabled_pairs(robot: RobotModel) -> list[tuple[str, str, str]]:
    """``(frame a, frame b, reason)`` for every frame pair of ``robot`` (a
    :class:`~jwarp.model.RobotModel`) that is never checked for self-collision (its
    ``self_collision`` groups and exclude pairs, less include pairs), ``a < b`` by index;
    reason: the one recorded at import (``notes['self_collision_pairs']``,
    :mod:`jwarp.model.pair_reasons`) in MoveIt's words (``Adjacent``, ``Always``,
    ``Never``; an SRDF pair its own reason, else ``User``; frames joined by frozen joints
    ``Never``), else ``Adjacent`` when one is the other's parent, ``Default`` for the pairs
    listed in ``notes['self_collision_default']`` (an older import's home rule), else
    ``Never``."""
    from jwarp.model.pair_reasons import pair_reasons

    allowed = robot.allowed_collision_pairs
    parents = robot.parents
    names = robot.frame_names
    default = {frozenset(p) for p in default_pair_names(robot)}
    recorded = pair_reasons(robot)
    out = []
    for a in range(robot.n_frames):
        for b in range(a + 1, robot.n_frames):
            if not allowed[a, b]:
                adj = parents[a] == b or parents[b] == a
                reason = (REASON_ADJACENT if adj else REASON_DEFAULT
                          if frozenset((names[a], names[b])) in default else REASON_NEVER)
                if (a, b) in recorded:
                    kind, why = recorded[(a, b)]
                    m = re.search(r"reason (\S+)$", why)
                    reason = ((m.group(1) if m else "User") if kind == "SRDF" else
                              kind if kind in ("Adjacent", "Always", "Never", "Default")
                              else REASON_NEVER if kind == "Frozen" else "User")
                out.append((names[a], names[b], reason))
    return out


def default_pair_names(robot: RobotModel) -> list[tuple[str, str]]:
    """The frame-name pairs of ``robot``'s ``notes['self_collision_default']`` (excluded
    by the "Default" rule at import; empty when none or unreadable)."""
    import json

    text = getattr(robot, "notes", {}).get(DEFAULT_NOTE)
    if not text:
        return []
    try:
        doc = json.loads(text)
        return [(str(a), str(b)) for a, b in doc]
    except (ValueError, TypeError):
        return []


def srdf_text(robot: RobotModel, *, name: str | None = None, urdf_file: str | None = None,
              urdf_sha256: str | None = None) -> str:
    """The SRDF document of ``robot``: its :func:`disabled_pairs` as ``<disable_collisions>``
    (link names = jwarp frame names = the exported URDF's links). With ``urdf_file`` and
    ``urdf_sha256`` (what :func:`jwarp.importers.urdf_export.export_urdf` passes) a first
    comment records the URDF it belongs to (:func:`export_mark`)."""
    lines = ["<?xml version=\"1.0\"?>"]
    if urdf_file is not None and urdf_sha256 is not None:
        if not re.fullmatch(r"[0-9a-f]{64}", urdf_sha256):
            raise ValueError(f"urdf_sha256: expected 64 hex digits, got {urdf_sha256!r}")
        # percent-encoded (and '-' too): a comment may not hold "--"
        enc = quote(urdf_file, safe="").replace("-", "%2D")
        lines.append(f"<!-- {EXPORT_MARK} urdf_file={enc} urdf_sha256={urdf_sha256} -->")
    lines += [f"<!-- written by jwarp export_urdf from robot {robot.name!r}: the frame pairs "
             f"jwarp never checks for self-collision; see docs/urdf.md -->",
             f"<robot name={quoteattr(name or robot.name)}>"]
    for a, b, reason in disabled_pairs(robot):
        lines.append(f"  <disable_collisions link1={quoteattr(a)} link2={quoteattr(b)} "
                     f"reason=\"{reason}\"/>")
    lines.append("</robot>")
    return "\n".join(lines) + "\n"


def export_mark(path: str | os.PathLike) -> tuple[str, str] | None:
    """``(URDF file name, its SHA-256)`` recorded by :func:`srdf_text` in an SRDF that
    ``export_urdf`` wrote (read from the first 4 KiB of ``path``); ``("", "")`` for an SRDF
    of an older export (its comment says so, but names no URDF); None for any other file
    (a user's SRDF), or one that cannot be read."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(4096).decode("utf-8", "replace")
    except OSError:
        return None
    m = re.search(EXPORT_MARK + r" urdf_file=(\S+) urdf_sha256=([0-9a-f]{64}) -->", head)
    if m:
        return unquote(m.group(1)), m.group(2)
    if "<!-- written by jwarp export_urdf from robot" in head:
        return "", ""
    return None


def write_srdf(robot: RobotModel, path: str | os.PathLike, *, name: str | None = None) -> None:
    """Write :func:`srdf_text` to ``path`` atomically."""
    from jwarp.utils.atomic import atomic_write_text

    atomic_write_text(path, srdf_text(robot, name=name))
