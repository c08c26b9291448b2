"""Export a jwarp robot as URDF (and a side file for what URDF cannot hold).

Mapping (see ``docs/urdf_export.md``):

* Every jwarp frame becomes a URDF link of the same name; a root link (``jwarp_base``,
  made unique against the frame names) is added as the parent of the root frames (URDF has
  exactly one root link; jwarp's world frame).
* A ``dh`` frame ``[d, theta, r, alpha, beta]``: jwarp's transform
  ``Ry(beta) Rx(alpha) Tx(r) Rz(theta + q) Tz(d)`` equals ``A Rz(q)`` with the fixed
  ``A = Ry(beta) Rx(alpha) Tx(r) Rz(theta) Tz(d)`` (``Rz(q)`` commutes with ``Tz(d)``); a
  prismatic joint gives ``A Tz(q)``. So the frame is one URDF joint with ``origin = A`` and
  ``axis = 0 0 1``, revolute or prismatic; a DH frame driven by no joint is a ``fixed``
  joint with ``origin = A``.
* Joint ``j`` of jwarp is the URDF joint named ``j``: the joint of the first frame driven by
  ``1.0 * q_j`` alone, or else a driver joint of a massless leaf link ``<j>_driver`` under
  the root link. Every other frame driven by ``c * q_j`` is a ``mimic`` joint
  (``multiplier = c``, ``offset = 0``). A frame driven by several joints
  ``sum_k c_k q_k`` is a chain of mimic joints about the same z axis through massless links
  ``<frame>__mimic<k>`` (rotations, or translations, about one axis add up), so every
  jwarp coupling is exact.
* ``static`` frames are ``fixed`` joints with their transform as the origin.
* Masses of a frame: one ``<inertial>`` with their total mass, their centre of mass and the
  inertia of the point masses about it plus ``INERTIA_FLOOR`` on the diagonal (a point
  mass has none; simulators reject a zero inertia).
* Collision spheres are ``<collision>`` spheres (a "spherized" URDF); a capsule is a
  cylinder and two spheres.
* Joint limits are the jwarp limits; URDF's required ``effort`` and ``velocity`` are
  ``options.effort`` / ``options.velocity`` (jwarp holds neither; 0 = unknown).

URDF cannot hold the elastic and non-geometric fields (``kappa``, ``kappa_nonlinear``,
``harmonic``) nor ``linear_limits``: when any is present the whole jwarp robot is written
to the side file ``<out>.jwarp.json`` (readable with ``jwarp.robot(path)``) and a warning
names the fields. End-effector names and gravity are not written into URDF either; they
are in the side file when it is written. The frame pairs the robot never checks for
self-collision (its ``self_collision`` groups and exclude pairs) are written as MoveIt's
``<disable_collisions>`` to the SRDF ``<out stem>.srdf`` beside the URDF
(:mod:`jwarp.importers.srdf`; ``options.srdf=False``: none), so that ``jwarp import-urdf
OUT.urdf --srdf OUT.srdf`` gets them back.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast
from xml.sax.saxutils import quoteattr

import numpy as np

from jwarp.model import RobotModel
from jwarp.utils.atomic import AtomicFile, commit_all

#: diagonal inertia [kg m^2] added to every exported inertial (point masses have none)
INERTIA_FLOOR = 1e-6
#: suffix of the side file beside the URDF
SIDE_SUFFIX = ".jwarp.json"


@dataclass
class UrdfExportOptions:
    """Options of :func:`export_urdf`.

    Attributes:
        effort: URDF ``<limit effort>`` of every joint [N m or N] (jwarp holds none; 0).
        velocity: URDF ``<limit velocity>`` [rad/s or m/s] (jwarp holds none; 0).
        side_file: write ``<out>.jwarp.json``: ``None`` when the robot has fields URDF
            cannot hold, ``True`` always, ``False`` never (the warning then says the
            fields are dropped).
        root_link: name of the added root link (made unique against the frame names).
        srdf: write the SRDF :func:`jwarp.importers.srdf.srdf_path` (``robot.urdf`` ->
            ``robot.srdf``) with the robot's self-collision exclusions (default True).
    """

    effort: float = 0.0
    velocity: float = 0.0
    side_file: bool | None = None
    root_link: str = "jwarp_base"
    srdf: bool = True

    def validate(self) -> None:
        for key in ("effort", "velocity"):
            v = getattr(self, key)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) \
                    or v < 0:
                raise ValueError(f"options.{key}: must be a finite number >= 0, got {v!r}")
        if not isinstance(self.srdf, bool):
            raise TypeError(f"options.srdf: expected True or False, got {self.srdf!r}")
        if self.side_file not in (None, True, False):
            raise TypeError(f"options.side_file: expected None, True or False, "
                            f"got {self.side_file!r}")
        if not isinstance(self.root_link, str) or not self.root_link.strip():
            raise ValueError(f"options.root_link: expected a non-empty name, "
                             f"got {self.root_link!r}")


def side_file_path(path: str | os.PathLike) -> Path:
    """The side file written beside the URDF ``path``: ``<path>.jwarp.json``."""
    p = Path(path)
    return p.with_name(p.name + SIDE_SUFFIX)


# ------------------------------------------------------------------ geometry helpers
def dh_origin(row: np.ndarray) -> np.ndarray:
    """(4, 4) fixed part ``A = Ry(beta) Rx(alpha) Tx(r) Rz(theta) Tz(d)`` of a DH row
    ``[d, theta, r, alpha, beta]``: jwarp's frame transform is ``A Rz(q)`` (revolute) or
    ``A Tz(q)`` (prismatic)."""
    d, theta, r, alpha, beta = (float(v) for v in row)
    cb, sb = math.cos(beta), math.sin(beta)
    ca, sa = math.cos(alpha), math.sin(alpha)
    ct, st = math.cos(theta), math.sin(theta)
    ry = np.array([[cb, 0, sb], [0, 1, 0], [-sb, 0, cb]])
    rx = np.array([[1, 0, 0], [0, ca, -sa], [0, sa, ca]])
    rz = np.array([[ct, -st, 0], [st, ct, 0], [0, 0, 1]])
    rot_ab = ry @ rx
    T = np.eye(4)
    T[:3, :3] = rot_ab @ rz
    T[:3, 3] = rot_ab @ np.array([r, 0.0, 0.0]) + T[:3, :3] @ np.array([0.0, 0.0, d])
    return T


def rpy_of(R: np.ndarray) -> tuple[float, float, float]:
    """URDF roll, pitch, yaw [rad] of a rotation matrix ``R = Rz(yaw) Ry(pitch) Rx(roll)``.

    Stable at gimbal lock (pitch = +-pi/2): yaw is taken first and roll from the entries
    left well-conditioned by it (the method of Eigen's ``eulerAngles(2, 1, 0)``)."""
    R = np.asarray(R, np.float64)
    yaw = math.atan2(R[1, 0], R[0, 0])
    pitch = math.atan2(-R[2, 0], math.hypot(R[0, 0], R[1, 0]))
    s, c = math.sin(yaw), math.cos(yaw)
    roll = math.atan2(s * R[0, 2] - c * R[1, 2], c * R[1, 1] - s * R[0, 1])
    return roll, pitch, yaw


def _num(v: float) -> str:
    return repr(float(v) + 0.0)  # shortest string that reads back exactly; no "-0.0"


def _vec(v: Any) -> str:
    return " ".join(_num(x) for x in v)


def _origin(T: np.ndarray, indent: str) -> str:
    return (f'{indent}<origin xyz="{_vec(T[:3, 3])}" rpy="{_vec(rpy_of(T[:3, :3]))}"/>\n')


def _unique(name: str, taken: set[str]) -> str:
    out, k = name, 1
    while out in taken:
        k += 1
        out = f"{name}_{k}"
    taken.add(out)
    return out


# ------------------------------------------------------------------ the document
def _unsupported(robot: RobotModel) -> list[str]:
    """Fields of ``robot`` that URDF cannot hold and that are not empty."""
    out = []
    if np.any(robot.kappa):
        out.append("kappa")
    if np.any(robot.kappa_nonlinear):
        out.append("kappa_nonlinear")
    if robot.has_harmonic:
        out.append("harmonic")
    if robot.linear_limits:
        out.append("linear_limits")
    return out


def _inertial(robot: RobotModel, frame: int, indent: str) -> str:
    ms = [m for m in robot.masses if m.frame == frame and m.mass > 0]
    if not ms:
        return ""
    total = sum(m.mass for m in ms)
    com = sum(m.mass * np.asarray(m.com) for m in ms) / total
    inertia = INERTIA_FLOOR * np.eye(3)
    for m in ms:
        r = np.asarray(m.com) - com
        inertia += m.mass * (np.dot(r, r) * np.eye(3) - np.outer(r, r))
    i = indent
    return (f"{i}<inertial>\n{i}  <origin xyz=\"{_vec(com)}\" rpy=\"0 0 0\"/>\n"
            f"{i}  <mass value=\"{_num(total)}\"/>\n"
            f"{i}  <inertia ixx=\"{_num(inertia[0, 0])}\" ixy=\"{_num(inertia[0, 1])}\" "
            f"ixz=\"{_num(inertia[0, 2])}\" iyy=\"{_num(inertia[1, 1])}\" "
            f"iyz=\"{_num(inertia[1, 2])}\" izz=\"{_num(inertia[2, 2])}\"/>\n{i}</inertial>\n")


def _sphere(pos: Any, radius: float, i: str) -> str:
    return (f"{i}<collision>\n{i}  <origin xyz=\"{_vec(pos)}\" rpy=\"0 0 0\"/>\n"
            f"{i}  <geometry><sphere radius=\"{_num(radius)}\"/></geometry>\n{i}</collision>\n")


def _capsule(p0: np.ndarray, p1: np.ndarray, radius: float, i: str) -> str:
    axis = np.asarray(p1, np.float64) - np.asarray(p0, np.float64)
    length = float(np.linalg.norm(axis))
    out = _sphere(p0, radius, i) + _sphere(p1, radius, i)
    if length > 0:
        z = axis / length
        helper = np.array([1.0, 0, 0]) if abs(z[0]) < 0.9 else np.array([0, 1.0, 0])
        x = np.cross(helper, z)
        x /= np.linalg.norm(x)
        T = np.eye(4)
        T[:3, :3] = np.column_stack([x, np.cross(z, x), z])
        T[:3, 3] = (np.asarray(p0) + np.asarray(p1)) / 2
        out += (f"{i}<collision>\n{_origin(T, i + '  ')}"
                f"{i}  <geometry><cylinder radius=\"{_num(radius)}\" length=\"{_num(length)}\"/>"
                f"</geometry>\n{i}</collision>\n")
    return out


def _link(name: str, body: str) -> str:
    if not body:
        return f"  <link name={quoteattr(name)}/>\n"
    return f"  <link name={quoteattr(name)}>\n{body}  </link>\n"


def _joint(name: str, kind: str, parent: str, child: str, T: np.ndarray | None,
           limit: tuple[float, float] | None = None, mimic: tuple[str, float] | None = None,
           options: UrdfExportOptions | None = None) -> str:
    s = (f"  <joint name={quoteattr(name)} type=\"{kind}\">\n"
         f"    <parent link={quoteattr(parent)}/>\n    <child link={quoteattr(child)}/>\n")
    s += _origin(T if T is not None else np.eye(4), "    ")
    if kind != "fixed":
        s += "    <axis xyz=\"0 0 1\"/>\n"
        lo, hi = limit if limit is not None else (-math.pi, math.pi)
        s += (f"    <limit lower=\"{_num(lo)}\" upper=\"{_num(hi)}\" "
              f"effort=\"{_num(options.effort)}\" velocity=\"{_num(options.velocity)}\"/>\n")
    if mimic is not None:
        s += f"    <mimic joint={quoteattr(mimic[0])} multiplier=\"{_num(mimic[1])}\" offset=\"0\"/>\n"
    return s + "  </joint>\n"


def urdf_text(robot: RobotModel, *, name: str | None = None,
              options: UrdfExportOptions | None = None) -> str:
    """The URDF document of ``robot`` (see the module docstring for the mapping)."""
    options = options or UrdfExportOptions()
    options.validate()
    links = set(robot.frame_names)
    root = _unique(options.root_link, links)
    joint_names: set[str] = set(robot.joint_names)
    # the frame whose URDF joint is jwarp joint j itself
    driver: dict[int, int] = {}
    for i in robot.topological_order:
        f = robot.frames[int(i)]
        if f.kind == "dh" and len(f.coupling) == 1 and f.coupling[0][1] == 1.0:
            driver.setdefault(f.coupling[0][0], int(i))
    fname = robot.frame_names
    out = [f"<?xml version=\"1.0\"?>\n<!-- written by jwarp export_urdf from robot "
           f"{robot.name!r}; see docs/urdf_export.md -->\n"
           f"<robot name={quoteattr(name or robot.name)}>\n", _link(root, "")]
    for j, jt in enumerate(robot.joints):
        if j not in driver:
            dummy = _unique(f"{jt.name}_driver", links)
            out.append(_link(dummy, ""))
            out.append(_joint(jt.name, jt.type, root, dummy, None, (jt.lower, jt.upper),
                              options=options))
    for i in robot.topological_order:
        i = int(i)
        f = robot.frames[i]
        parent = root if f.parent is None else fname[f.parent]
        body = _inertial(robot, i, "    ")
        for s in robot.spheres:
            if s.frame == i:
                body += _sphere(s.position, s.radius, "    ")
        for c in robot.capsules:
            if c.frame == i:
                body += _capsule(c.p0, c.p1, c.radius, "    ")
        out.append(_link(f.name, body))
        if f.kind == "static":
            out.append(_joint(_unique(f"{f.name}_joint", joint_names), "fixed", parent, f.name,
                              f.transform))
            continue
        A = dh_origin(cast(np.ndarray, f.dh))  # a DH frame
        if not f.coupling:
            out.append(_joint(_unique(f"{f.name}_joint", joint_names), "fixed", parent, f.name, A))
            continue
        kind = "prismatic" if robot.frame_is_prismatic[i] else "revolute"
        if driver.get(f.coupling[0][0]) == i:
            jt = robot.joints[f.coupling[0][0]]
            out.append(_joint(jt.name, kind, parent, f.name, A, (jt.lower, jt.upper),
                              options=options))
            continue
        # mimic chain: one joint per coupling term, about the same axis
        prev = parent
        T: np.ndarray | None = A
        for k, (j, coef) in enumerate(f.coupling):
            last = k == len(f.coupling) - 1
            child = f.name if last else _unique(f"{f.name}__mimic{k + 1}", links)
            if not last:
                out.append(_link(child, ""))
            jt = robot.joints[j]
            lim = sorted((coef * jt.lower, coef * jt.upper))
            jname = _unique(f"{f.name}_joint" + ("" if k == 0 else f"_{k + 1}"), joint_names)
            out.append(_joint(jname, kind, prev, child, T, (lim[0], lim[1]),
                              mimic=(jt.name, float(coef)), options=options))
            prev, T = child, None
    out.append("</robot>\n")
    return "".join(out)


def export_urdf(robot: RobotModel, path: str | os.PathLike, *, name: str | None = None,
                options: UrdfExportOptions | None = None) -> list[str]:
    """Write ``robot`` as a URDF file ``path`` (and, if needed, the side file
    ``<path>.jwarp.json``; and the SRDF ``<stem>.srdf`` unless ``options.srdf`` is False);
    returns the warnings (one line each).

    Args:
        robot: the jwarp robot (e.g. a calibrated one, ``result.robot``).
        path: the URDF file to write (its folder must exist).
        name: the URDF ``<robot name>`` (default: the robot's name).
        options: :class:`UrdfExportOptions`.

    Returns:
        Warnings: the fields URDF cannot hold and where they went (the side file), or that
        they were dropped (``options.side_file=False``).

    Raises:
        TypeError: ``robot`` is not a :class:`~jwarp.model.RobotModel`, ``name`` not a str.
        ValueError: ``path`` is a folder or its folder does not exist (checked before work).

    All files are written to temporary files first and renamed at the end
    (:func:`jwarp.utils.atomic.commit_all`): an error leaves none. The side file's
    ``notes.urdf_sha256`` is the SHA-256 of the URDF text written with it. A side file left
    from an earlier export of ``path`` is removed when no side file is written now (it would
    describe another robot); a file of that name that no export wrote (its notes do not
    name this URDF) is left alone, with a warning. The same for the SRDF: one an earlier
    export of ``path`` wrote is replaced (or, with ``options.srdf`` False, removed); any
    other file of that name is never overwritten (ValueError before any work,
    :func:`check_srdf_target`). The renames go side file, SRDF, URDF; the SRDF records the
    URDF's name and SHA-256 like the side file, so a kill between renames leaves a set that
    :func:`export_set_problems` reports.
    """
    if not isinstance(robot, RobotModel):
        raise TypeError(f"robot: expected a jwarp RobotModel (load a name or file with "
                        f"jwarp.robot(...)), got {type(robot).__name__}")
    if name is not None and (not isinstance(name, str) or not name.strip()):
        raise TypeError(f"name: expected a non-empty str, got {name!r}")
    options = options or UrdfExportOptions()
    if not isinstance(options, UrdfExportOptions):
        raise TypeError(f"options: expected UrdfExportOptions, got {type(options).__name__}")
    options.validate()
    if not isinstance(path, (str, os.PathLike)) or not str(path).strip():
        raise TypeError(f"path: expected a file name, got {path!r}")
    side = side_file_path(path)
    check_srdf_target(path, options)
    urdf_file = AtomicFile(path, option="path")       # checks the path before any work
    files = [urdf_file]
    try:
        text = urdf_text(robot, name=name, options=options)
        digest = hashlib.sha256(text.encode("utf-8")).hexdigest()
        if options.srdf:
            from jwarp.importers.srdf import srdf_path, srdf_text

            srdf_file = AtomicFile(srdf_path(path), option="path")
            files.insert(0, srdf_file)
            _write(srdf_file.tmp, srdf_text(robot, name=name, urdf_file=Path(path).name,
                                            urdf_sha256=digest))
        missing = _unsupported(robot)
        write_side = bool(missing) if options.side_file is None else options.side_file
        side_file = AtomicFile(side, option="path") if write_side else None
        if side_file is not None:
            files.insert(0, side_file)
        _write(urdf_file.tmp, text)
        warnings = []
        if side_file is not None:
            doc = robot.to_dict()
            doc.setdefault("notes", {})["urdf_sha256"] = digest
            doc["notes"]["urdf_file"] = Path(path).name
            _write(side_file.tmp, json.dumps(doc, indent=1) + "\n")
            if missing:
                warnings.append(f"URDF cannot hold {', '.join(missing)} of robot "
                                f"'{robot.name}': the full jwarp robot is in {side}")
        elif missing:
            warnings.append(f"URDF cannot hold {', '.join(missing)} of robot '{robot.name}': "
                            f"dropped (no side file written)")
    except BaseException:
        for f in files:
            f.discard()
        raise
    # the URDF last: a kill between two renames leaves a side file or SRDF whose recorded
    # urdf_sha256 is not the URDF's (export_set_problems reports it)
    commit_all(files)
    if side_file is None and side.is_file():
        if _written_by_export(side, path):
            side.unlink()
            warnings.append(f"removed the side file {side} of an earlier export (this robot "
                            f"needs none)")
        else:  # a file of that name jwarp did not write: not ours to delete
            warnings.append(f"left {side} alone: it is not a side file jwarp's export wrote "
                            f"for {Path(path).name} (it no longer belongs to this URDF)")
    if not options.srdf:
        from jwarp.importers.srdf import export_mark, srdf_path

        old = srdf_path(path)
        if old.is_file():
            mark = export_mark(old)
            if mark is not None and mark[0] in ("", Path(path).name):
                old.unlink()
                warnings.append(f"removed the SRDF {old} of an earlier export (no SRDF "
                                f"written now; it described another robot)")
            else:
                warnings.append(f"left {old} alone: no SRDF written now, and it is not one "
                                f"jwarp's export wrote for {Path(path).name}, so it may not "
                                f"describe this URDF's links")
    return warnings


def check_srdf_target(path: str | os.PathLike, options: UrdfExportOptions | None = None,
                      option: str = "path") -> None:
    """ValueError naming ``option`` if :func:`export_urdf` would overwrite an SRDF it did not
    write: the file :func:`jwarp.importers.srdf.srdf_path` of ``path`` exists and is not an
    SRDF of an export of ``path`` (e.g. the user's MoveIt SRDF of the robot, the natural
    ``import-urdf robot.urdf --srdf robot.srdf`` -> ``export-urdf --out robot.urdf`` round
    trip). Nothing to check with ``options.srdf`` False."""
    from jwarp.importers.srdf import export_mark, srdf_path

    if options is not None and not options.srdf:
        return
    target = srdf_path(path)
    if not target.exists():
        return
    mark = export_mark(target) if target.is_file() else None
    if mark is None or mark[0] not in ("", Path(path).name):
        raise ValueError(f"{option}: {target} exists and is not an SRDF that export-urdf wrote "
                         f"for {Path(path).name} (your own SRDF?); it is not overwritten: "
                         f"give another {option}, or write no SRDF (--no-srdf, "
                         f"UrdfExportOptions(srdf=False))")


def export_set_problems(path: str | os.PathLike) -> list[str]:
    """What does not belong together in the files an export of the URDF ``path`` wrote:
    the side file (``notes``) and the SRDF (:func:`jwarp.importers.srdf.export_mark`) record
    the URDF file name and the SHA-256 of its text; one that names ``path`` but records
    another hash (an export killed between its renames, or a URDF changed since), or whose
    URDF is missing, is one line each. Empty when the set is whole (or holds no record)."""
    from jwarp.importers.srdf import export_mark, srdf_path

    p = Path(path)
    try:
        digest = hashlib.sha256(p.read_bytes()).hexdigest() if p.is_file() else None
    except OSError:
        digest = None
    out = []
    records = []
    side = side_file_path(p)
    if side.is_file() and _written_by_export(side, p):
        notes = json.loads(side.read_text(encoding="utf-8"))["notes"]
        records.append(("side file", side, notes["urdf_sha256"]))
    srdf = srdf_path(p)
    mark = export_mark(srdf) if srdf.is_file() else None
    if mark is not None and mark[0] == p.name:
        records.append(("SRDF", srdf, mark[1]))
    for what, f, sha in records:
        if digest is None:
            out.append(f"{what} {f} was written by export-urdf with {p}, which does not "
                       f"exist (an interrupted export?)")
        elif sha != digest:
            out.append(f"{what} {f} was written by export-urdf with another version of {p} "
                       f"(URDF sha256 {sha[:12]}..., the file's is {digest[:12]}...): an "
                       f"interrupted export, or the URDF changed since; export again")
    return out


def _written_by_export(side: Path, urdf_path: Any) -> bool:
    """Whether ``side`` is a side file an export of ``urdf_path`` wrote: JSON whose notes
    name that URDF file and carry the SHA-256 of its text."""
    try:
        doc = json.loads(side.read_text(encoding="utf-8"))
    except (OSError, ValueError, UnicodeDecodeError):
        return False
    notes = doc.get("notes") if isinstance(doc, dict) else None
    return (isinstance(notes, dict) and notes.get("urdf_file") == Path(urdf_path).name
            and isinstance(notes.get("urdf_sha256"), str))


def _write(tmp: Path, text: str) -> None:
    with os.fdopen(os.open(tmp, os.O_WRONLY | os.O_TRUNC), "w", encoding="utf-8") as fh:
        fh.write(text)
        fh.flush()
        os.fsync(fh.fileno())
