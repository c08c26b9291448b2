"""MJCF (MuJoCo XML) -> jwarp robot document (schema ``jwarp.robot``, docs/urdf.md "MJCF").

The file is compiled by MuJoCo's own parser (``mujoco.MjModel.from_xml_path``; the optional
extra ``jwarp[mjcf]``), so includes, defaults, ``<compiler angle>``, ``<frame>`` elements,
``childclass`` and mesh compilation are MuJoCo's; jwarp reads the compiled ``MjModel``:

* every body is a frame of the same name (unnamed bodies: ``body<id>``); the world body is a
  static identity frame, the robot's root;
* a body without joints is one ``static`` frame ``B = (body_pos, body_quat)``;
* a body with joints ``j1..jn`` (``hinge`` or ``slide``, in the order of the file) moves as
  MuJoCo's ``mj_kinematics`` does: ``B @ prod_k Trans(p_k) M_k(q_k - ref_k) Trans(-p_k)``
  (``p_k`` = ``jnt_pos``, ``M_k`` the rotation about / translation along ``jnt_axis``, both
  in the body frame). Each joint is a static ``Trans(p_k) @ R_align`` (folded into the joint's
  DH row when it is one exactly, as the URDF importer does, with ``B`` or the previous
  joint's ``R_align^T Trans(-p)`` in front), then a ``dh`` frame ``[d, theta, 0, 0, 0]``
  named after the joint, with ``-ref`` added to theta (or d); the body frame is the static
  ``R_align^T Trans(-p_n)`` after the last joint;
* ``free`` and ``ball`` joints are unsupported (ValueError naming the joint);
* joint limits: ``jnt_range`` of limited joints; unlimited hinges get ``[-continuous_limit,
  continuous_limit]``; an unlimited slide joint is an error;
* active ``<equality><joint>`` constraints ``q1 - ref1 = c0 + c1 (q2 - ref2)`` (polycoef
  with ``c2 = c3 = c4 = 0``) make ``joint1`` a coupled joint driven by ``joint2`` (chains
  resolved); a nonlinear polynomial or a joint fixed to a constant (no ``joint2``) is
  unsupported (an error naming it);
* the other active equality constraints (``<connect>``, ``<weld>``, ``<tendon>``, ``<flex>``,
  ...: the loop closures of linkages such as the Robotiq 2F-85's) cannot be imported: they
  are dropped with an :class:`MjcfWarning` naming each of them (and listed in the robot's
  ``notes["dropped_equalities"]``); the joints they would tie move independently;
* sites become static frames (named after the site) on their body;
* body mass and ``ipos`` become point masses;
* geoms with ``contype | conaffinity != 0`` on bodies other than the world body are the
  collision geometry (:class:`~jwarp.importers.urdf.CollisionGeometry`, sizes converted from
  MuJoCo's half sizes); mesh geoms carry MuJoCo's compiled mesh as ``mesh`` (a
  ``trimesh.Trimesh`` in the geom frame), ellipsoids a scaled icosphere; spheres become the
  robot's collision spheres.

The configuration vector ``q`` of the jwarp robot holds MuJoCo's ``qpos`` of the actuated
(not equality-coupled) joints, in MuJoCo's joint order.
"""

from __future__ import annotations

import math
import os
import warnings
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from jwarp.importers.urdf import (
    EXACT,
    CollisionGeometry,
    UrdfImport,
    align_z,
    check_import_options,
    dh_of,
)

#: MuJoCo's joint and geom type numbers (mjtJoint, mjtGeom)
JOINT_TYPES = {0: "free", 1: "ball", 2: "slide", 3: "hinge"}
GEOM_TYPES = {0: "plane", 1: "hfield", 2: "sphere", 3: "capsule", 4: "ellipsoid",
              5: "cylinder", 6: "box", 7: "mesh", 8: "sdf"}
EQ_JOINT = 2
INSTALL = "pip install jwarp[mjcf] (or pip install mujoco)"


class MjcfError(ValueError):
    """A malformed or unsupported MJCF file; the message names the file and the element."""


class MjcfWarning(UserWarning):
    """Something of an MJCF file the import leaves out (equality constraints other than
    linear joint couplings); the message names the file and the elements."""


@dataclass
class MjcfOptions:
    """Options of the MJCF import.

    end_effectors: ``{alias: body, site or frame name}``; None: every tip body (a body
        without child bodies) and every site, under its own name.
    continuous_limit: limits ``[-x, x]`` [rad] of hinge joints without a range (> 0).
    merge_static: fold a joint's origin into its DH row when exact (fewer frames).
    sites: add every site as a static frame.
    name: robot name (default: ``<mujoco model>``, else the file's stem).
    """

    end_effectors: Mapping[str, str] | None = None
    continuous_limit: float = math.pi
    merge_static: bool = True
    sites: bool = True
    name: str | None = None

    def validate(self) -> None:
        check_import_options(self, "body")


def import_mujoco() -> Any:
    """The ``mujoco`` module; ImportError telling how to install it when missing."""
    try:
        import mujoco
    except ImportError as e:
        raise ImportError(f"MJCF import needs the 'mujoco' package: {INSTALL} ({e})") from None
    return mujoco


def is_mjcf(path: str | os.PathLike) -> bool:
    """True when ``path`` is a file ending in ``.xml`` whose root element is ``<mujoco>``
    (read with a streaming parser: only the root element is read)."""
    p = os.fspath(path)
    if not (isinstance(p, str) and p.lower().endswith(".xml") and os.path.isfile(p)):
        return False
    from xml.etree import ElementTree

    try:
        for _, el in ElementTree.iterparse(p, events=("start",)):
            return el.tag == "mujoco"
    except (ElementTree.ParseError, OSError):
        return False
    return False


def quat_matrix(q: Any) -> np.ndarray:
    """(3, 3) rotation of MuJoCo's quaternion ``(w, x, y, z)`` (normalised first)."""
    w, x, y, z = np.asarray(q, np.float64) / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def pose(pos: Any, quat: Any) -> np.ndarray:
    """(4, 4) transform of a MuJoCo ``pos`` (3,) and ``quat`` (w, x, y, z)."""
    out = np.eye(4)
    out[:3, :3] = quat_matrix(quat)
    out[:3, 3] = pos
    return out


def _trans(p: Any) -> np.ndarray:
    out = np.eye(4)
    out[:3, 3] = p
    return out


def _rot(R: np.ndarray) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3] = R
    return out


def _name(mujoco: Any, m: Any, objtype: Any, i: int, prefix: str) -> str:
    n = mujoco.mj_id2name(m, objtype, i)
    return n if n else f"{prefix}{i}"


def read_mjcf(path: str | os.PathLike, options: MjcfOptions | None = None) -> UrdfImport:
    """Read an MJCF file into a ``jwarp.robot`` document and the bodies' collision geometry
    (module docstring). ``link_frames`` maps bodies (and sites) to frames, ``joint_frames``
    MuJoCo joints to their dh frames. Raises :class:`MjcfError` (a ValueError) naming the
    file and the element: MuJoCo's own parse/compile errors (with element and line), free and
    ball joints, nonlinear or constant joint equalities, unlimited slide joints, unsupported
    collision geoms (plane, hfield, sdf) on robot bodies; ImportError without ``mujoco``."""
    opt = options or MjcfOptions()
    opt.validate()
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise MjcfError(f"path: MJCF file not found: '{path}'")
    warn_outside_includes(path)
    mujoco = import_mujoco()
    try:
        m = mujoco.MjModel.from_xml_path(path)
    except ValueError as e:
        raise MjcfError(f"{path}: MuJoCo could not load it: {' '.join(str(e).split())}") from None
    return build(m, path, opt)


def warn_outside_includes(path: str) -> None:
    """An :class:`~jwarp.utils.roots.OutsideFolderWarning` for each ``<include file>`` of
    the MJCF ``path`` (and of the files it includes) outside the model's folder (MuJoCo
    resolves them against it), once per file. A file that does not parse is left to
    MuJoCo's error."""
    from jwarp.utils.roots import one_warning_per_file

    with one_warning_per_file():
        _warn_includes([Path(path)], set(), Path(path).resolve().parent, path)


def _warn_includes(todo: list, seen: set, folder: Path, path: str) -> None:
    from lxml import etree

    from jwarp.utils.roots import warn_if_outside

    while todo:
        f = todo.pop()
        key = f.resolve()
        if key in seen:
            continue
        seen.add(key)
        try:
            root = etree.parse(str(f), etree.XMLParser(remove_comments=True)).getroot()
        except (etree.XMLSyntaxError, OSError):
            continue
        for el in root.iter("include"):
            name = el.get("file")
            if not name:
                continue
            inc = Path(name) if Path(name).is_absolute() else folder / name
            warn_if_outside(inc, folder, f"{path}: <include> (line {el.sourceline}) file",
                            stacklevel=5)
            if inc.is_file():
                todo.append(inc)


def build(m: Any, path: str, opt: MjcfOptions) -> UrdfImport:
    """The robot document of a compiled ``mujoco.MjModel`` ``m`` (``path`` for messages)."""
    mujoco = import_mujoco()
    OB, OJ, OG, OS, OM = (mujoco.mjtObj.mjOBJ_BODY, mujoco.mjtObj.mjOBJ_JOINT,
                          mujoco.mjtObj.mjOBJ_GEOM, mujoco.mjtObj.mjOBJ_SITE,
                          mujoco.mjtObj.mjOBJ_MESH)
    bodies = [_name(mujoco, m, OB, b, "body") for b in range(m.nbody)]
    joints = [_name(mujoco, m, OJ, j, "joint") for j in range(m.njnt)]
    for j in range(m.njnt):
        t = JOINT_TYPES.get(int(m.jnt_type[j]), str(int(m.jnt_type[j])))
        if t in ("free", "ball"):
            raise MjcfError(f"{path}: joint '{joints[j]}' (body '{bodies[m.jnt_bodyid[j]]}'): "
                            f"type '{t}' is not supported (supported: hinge, slide)")
    jtype = {j: "prismatic" if m.jnt_type[j] == 2 else "revolute" for j in range(m.njnt)}
    ref = {j: float(m.qpos0[m.jnt_qposadr[j]]) for j in range(m.njnt)}

    # ---- joint equalities -> couplings: drive[j] = (source joint, coefficient, offset)
    coupled: dict[int, tuple[int, float, float]] = {}
    dropped = [_equality_text(mujoco, m, e) for e in range(m.neq)
               if int(m.eq_type[e]) != EQ_JOINT and bool(m.eq_active0[e])]
    if dropped:
        warnings.warn(f"{path}: {len(dropped)} equality constraint"
                      f"{'s' if len(dropped) > 1 else ''} cannot be imported and "
                      f"{'are' if len(dropped) > 1 else 'is'} dropped: {'; '.join(dropped)} "
                      f"(jwarp imports only linear <joint> couplings; the loops these close "
                      f"are not enforced, their joints move independently)", MjcfWarning,
                      stacklevel=4)
    for e in range(m.neq):
        if int(m.eq_type[e]) != EQ_JOINT or not bool(m.eq_active0[e]):
            continue
        j1, j2 = int(m.eq_obj1id[e]), int(m.eq_obj2id[e])
        c = np.asarray(m.eq_data[e][:5], np.float64)
        ename = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_EQUALITY, e) or f"equality {e}"
        where = f"{path}: <equality><joint> '{ename}' (joint1 '{joints[j1]}')"
        if j2 < 0:
            raise MjcfError(f"{where}: a joint fixed to a constant (no joint2) is not supported")
        if np.any(c[2:] != 0.0):
            raise MjcfError(f"{where}: polycoef {c.tolist()} is not linear; only "
                            f"q1 = c0 + c1 q2 is supported")
        if jtype[j1] != jtype[j2]:
            raise MjcfError(f"{where}: couples a {jtype[j1]} joint to the {jtype[j2]} joint "
                            f"'{joints[j2]}'")
        if j1 in coupled:
            raise MjcfError(f"{where}: joint '{joints[j1]}' is constrained twice")
        # q1 - ref1 = c0 + c1 (q2 - ref2)  ->  q1 = c1 q2 + (ref1 + c0 - c1 ref2)
        coupled[j1] = (j2, float(c[1]), ref[j1] + float(c[0]) - float(c[1]) * ref[j2])

    drive: dict[int, tuple[int, float, float]] = {j: (j, 1.0, 0.0) for j in range(m.njnt)
                                                  if j not in coupled}

    def resolve(j: int, seen: tuple[int, ...] = ()) -> tuple[int, float, float]:
        if j in drive:
            return drive[j]
        if j in seen:
            raise MjcfError(f"{path}: joint equalities form a cycle: "
                            f"{' -> '.join(joints[k] for k in seen + (j,))}")
        src, c1, off = coupled[j]
        s, m0, o0 = resolve(src, seen + (j,))
        drive[j] = (s, c1 * m0, c1 * o0 + off)
        return drive[j]

    for j in range(m.njnt):
        resolve(j)

    jdocs = []
    for j in range(m.njnt):
        if j in coupled:
            continue
        if bool(m.jnt_limited[j]):
            lim = [float(m.jnt_range[j][0]), float(m.jnt_range[j][1])]
        elif jtype[j] == "revolute":
            lim = [-float(opt.continuous_limit), float(opt.continuous_limit)]
        else:
            raise MjcfError(f"{path}: joint '{joints[j]}': a slide joint needs a range "
                            f"(range=\"lower upper\", limited)")
        jdocs.append({"name": joints[j], "type": jtype[j], "limits": lim})

    # ---- frames
    frames: list[dict[str, Any]] = []
    used = set(bodies)
    link_frames: dict[str, str] = {bodies[0]: bodies[0]}
    joint_frames: dict[str, str] = {}

    def unique(name: str) -> str:
        base, k = name, 1
        while name in used:
            name = f"{base}_{k}" if k > 1 else f"{base}_joint"
            k += 1
        used.add(name)
        return name

    def static(name: str, parent: str, T: np.ndarray) -> None:
        frames.append({"name": name, "parent": parent, "kind": "static",
                       "transform": T.tolist()})

    frames.append({"name": bodies[0], "parent": None, "kind": "static",
                   "transform": np.eye(4).tolist()})
    for b in range(1, m.nbody):   # MuJoCo orders bodies parents first
        parent = bodies[int(m.body_parentid[b])]
        pending = pose(m.body_pos[b], m.body_quat[b])   # transform not yet in a frame
        adr, n = int(m.body_jntadr[b]), int(m.body_jntnum[b])
        for j in range(adr, adr + n):
            axis = np.asarray(m.jnt_axis[j], np.float64)
            norm = float(np.linalg.norm(axis))
            if not np.isfinite(norm) or norm < 1e-9:
                raise MjcfError(f"{path}: joint '{joints[j]}': axis is zero or not finite")
            axis = axis / norm
            sign, R = 1.0, None
            if np.all(np.abs(axis - [0, 0, 1]) <= EXACT):
                pass
            elif np.all(np.abs(axis - [0, 0, -1]) <= EXACT):
                sign = -1.0
            else:
                R = align_z(axis)
            p = np.asarray(m.jnt_pos[j], np.float64)
            pre = pending @ _trans(p)
            if R is not None:
                pre = pre @ _rot(R)
            row = dh_of(pre) if opt.merge_static else None
            if row is None:
                row = np.zeros(5)
                if np.max(np.abs(pre - np.eye(4))) > 0.0:
                    oname = unique(f"{joints[j]}_origin")
                    static(oname, parent, pre)
                    parent = oname
            src, mult, offset = drive[j]
            col = 0 if jtype[j] == "prismatic" else 1
            # MuJoCo moves by (q - ref): q_frame = mult q_src + offset - ref
            row[col] += sign * (offset - ref[j])
            name = unique(joints[j])
            fd: dict[str, Any] = {"name": name, "parent": parent, "kind": "dh",
                                  "dh": row.tolist()}
            if sign * mult == 1.0:
                fd["joint"] = joints[src]
            else:
                fd["coupled"] = {"joints": [joints[src]], "coefficients": [sign * mult]}
            frames.append(fd)
            joint_frames[joints[j]] = name
            parent = name
            pending = _trans(-p) if R is None else _rot(R.T) @ _trans(-p)
        static(bodies[b], parent, pending)
        link_frames[bodies[b]] = bodies[b]

    sites = []
    if opt.sites:
        for s in range(m.nsite):
            sname = unique(_name(mujoco, m, OS, s, "site"))
            static(sname, bodies[int(m.site_bodyid[s])], pose(m.site_pos[s], m.site_quat[s]))
            link_frames[sname] = sname
            sites.append(sname)

    # ---- masses, collision geometry, end-effectors
    masses = []
    for b in range(1, m.nbody):
        mass = float(m.body_mass[b])
        if mass > 0.0:
            masses.append({"frame": bodies[b], "mass": mass,
                           "com": np.asarray(m.body_ipos[b], np.float64).tolist()})
    geometries = _geoms(mujoco, m, path, bodies, OG, OM)
    spheres = [{"frame": g.link, "position": g.origin[:3, 3].tolist(), "radius": float(g.size[0])}
               for g in geometries if g.kind == "sphere"]
    has_child = {int(p) for p in m.body_parentid[1:]}
    names = [f["name"] for f in frames]
    if opt.end_effectors is None:
        eff = {bodies[b]: bodies[b] for b in range(1, m.nbody) if b not in has_child}
        eff.update({s: s for s in sites})
    else:
        eff = {}
        for alias, target in opt.end_effectors.items():
            if target not in names:
                raise MjcfError(f"end_effectors.{alias}: unknown body, site or frame "
                                f"'{target}' (bodies: {', '.join(bodies)})")
            eff[alias] = target
    excluded = _contact_excludes(m, bodies, set(names))
    model_name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_MODEL, 0) if hasattr(
        mujoco.mjtObj, "mjOBJ_MODEL") else None
    name = opt.name or model_name or os.path.splitext(os.path.basename(path))[0] or "mjcf"
    doc = {
        "schema": "jwarp.robot", "version": 1, "name": name,
        "description": (f"imported from MJCF {os.path.basename(path)}: {m.nbody - 1} bodies, "
                        f"{len(jdocs)} actuated joints, {len(coupled)} coupled joints. "
                        f"Units: m, rad, kg."),
        "joints": jdocs, "frames": frames, "masses": masses, "spheres": spheres,
        "end_effectors": eff,
        **({"self_collision": {"exclude_pairs": excluded}} if excluded else {}),
        "notes": {"source": os.path.abspath(path),
                  "importer": "jwarp.importers.mjcf (docs/urdf.md, MJCF)",
                  **({"dropped_equalities": "; ".join(dropped)} if dropped else {})},
    }
    return UrdfImport(document=doc, geometries=geometries, link_frames=link_frames,
                      joint_frames=joint_frames, path=path)


def _contact_excludes(m: Any, bodies: list[str], frames: set[str]) -> list[list[str]]:
    """The body pairs of the model's ``<contact><exclude body1 body2>`` elements (MuJoCo's
    ``exclude_signature`` = body1 << 16 | body2) as frame-name pairs for
    ``self_collision.exclude_pairs`` (pairs naming the world body or a body that is not a
    frame are left out)."""
    out: set[tuple[str, str]] = set()
    for sig in np.asarray(getattr(m, "exclude_signature", []), np.int64).reshape(-1):
        a, b = int(sig) >> 16, int(sig) & 0xFFFF
        if 0 < a < len(bodies) and 0 < b < len(bodies) and a != b \
                and bodies[a] in frames and bodies[b] in frames:
            out.add((min(bodies[a], bodies[b]), max(bodies[a], bodies[b])))
    return [list(p) for p in sorted(out)]


def _equality_text(mujoco: Any, m: Any, e: int) -> str:
    """``<connect> 'name' (body1 'a', body2 'b')`` of equality constraint ``e``."""
    t = int(m.eq_type[e])
    try:
        kind = mujoco.mjtEq(t).name.removeprefix("mjEQ_").lower()
    except ValueError:
        kind = f"type {t}"
    name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_EQUALITY, e)
    objtype = int(m.eq_objtype[e]) if hasattr(m, "eq_objtype") else int(mujoco.mjtObj.mjOBJ_BODY)
    what = {int(mujoco.mjtObj.mjOBJ_BODY): "body", int(mujoco.mjtObj.mjOBJ_XBODY): "body",
            int(mujoco.mjtObj.mjOBJ_SITE): "site", int(mujoco.mjtObj.mjOBJ_TENDON): "tendon",
            int(mujoco.mjtObj.mjOBJ_JOINT): "joint"}.get(objtype)
    objs = []
    for k, obj in enumerate((int(m.eq_obj1id[e]), int(m.eq_obj2id[e])), 1):
        if what is not None and obj >= 0:
            objs.append(f"{what}{k} '{mujoco.mj_id2name(m, objtype, obj) or obj}'")
    label = f"'{name}'" if name else f"#{e}"
    return f"<{kind}> {label}" + (f" ({', '.join(objs)})" if objs else "")


def _geoms(mujoco: Any, m: Any, path: str, bodies: list[str], OG: Any, OM: Any
           ) -> list[CollisionGeometry]:
    import trimesh

    out = []
    for g in range(m.ngeom):
        b = int(m.geom_bodyid[g])
        if b == 0 or (int(m.geom_contype[g]) | int(m.geom_conaffinity[g])) == 0:
            continue   # the world body's geoms are the scene; visual-only geoms
        kind = GEOM_TYPES.get(int(m.geom_type[g]), str(int(m.geom_type[g])))
        gname = mujoco.mj_id2name(m, OG, g)
        s = np.asarray(m.geom_size[g], np.float64)
        item = CollisionGeometry(link=bodies[b], kind=kind, size=np.zeros(0),
                                 origin=pose(m.geom_pos[g], m.geom_quat[g]), name=gname)
        if kind == "sphere":
            item.size = s[:1].copy()
        elif kind == "box":
            item.size = 2.0 * s[:3]
        elif kind in ("capsule", "cylinder"):
            item.size = np.array([s[0], 2.0 * s[1]])
        elif kind == "ellipsoid":
            item.kind = "mesh"
            mesh = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
            mesh.apply_scale(s[:3])
            item.mesh, item.mesh_uri = mesh, f"ellipsoid {s[:3].tolist()}"
        elif kind == "mesh":
            k = int(m.geom_dataid[g])
            va, vn = int(m.mesh_vertadr[k]), int(m.mesh_vertnum[k])
            fa, fn = int(m.mesh_faceadr[k]), int(m.mesh_facenum[k])
            item.mesh = trimesh.Trimesh(vertices=np.array(m.mesh_vert[va:va + vn], np.float64),
                                        faces=np.array(m.mesh_face[fa:fa + fn], np.int64),
                                        process=False)
            item.mesh_uri = _name(mujoco, m, OM, k, "mesh")
        else:
            raise MjcfError(f"{path}: geom '{gname or g}' (body '{bodies[b]}'): a {kind} is not "
                            f"supported as robot collision geometry (make it visual only: "
                            f"contype=\"0\" conaffinity=\"0\")")
        out.append(item)
    return out
