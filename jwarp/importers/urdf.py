"""URDF -> jwarp robot document (schema ``jwarp.robot``, docs/robot_schema.md).

The kinematic tree, limits, mimic joints and inertials are read with ``yourdfpy``
(without loading meshes); the ``<collision>`` elements are read here from the XML (so that
``<capsule>``, which URDF parsers differ on, is accepted and a missing mesh file does not
stop the import). Mapping (docs/urdf.md):

* every URDF link is a frame of the same name; the root link is a static identity frame;
* a ``fixed`` joint is one ``static`` frame (its origin) named after the child link;
* a moving joint with origin ``T`` and unit axis ``a`` is ``T @ R_align`` (``R_align``
  turns z onto ``a``; identity for ``a = z``; for ``a = -z`` the joint is driven with
  coefficient -1 instead) followed by a ``dh`` frame ``[d, theta, 0, 0, 0]`` that turns
  about (revolute, continuous: theta) or slides along (prismatic: d) its z-axis, followed,
  when ``R_align != I``, by a static ``R_align^T`` so that the child frame is URDF's
  link frame. ``T @ R_align`` is folded into the DH row when it is one exactly
  (``Rot_y(beta) Rot_x(alpha) Trans_x(r) Rot_z(theta) Trans_z(d)``, to 4e-15), else it is
  a static frame ``<joint>_origin``. The dh frame is the child link's frame (named after
  the link) when ``R_align = I``, else it is jwarp's axis frame ``<joint>_axis``;
* every URDF joint name (fixed ones too) is a frame alias (``frame_aliases``) of its child
  link's frame: the URDF joint frame after the joint's motion, pinocchio's ``oMf[joint]``;
* ``mimic`` joints are coupled frames: ``q_frame = multiplier * q[joint]``, the offset
  added to theta (or d); mimics of mimics are resolved;
* ``continuous`` joints become revolute joints with limits ``[-continuous_limit,
  continuous_limit]`` (default pi: every angle once);
* inertials become point masses (mass, centre of mass in the link frame; the rotational
  inertia is not used by jwarp's point-mass model);
* ``<collision><sphere>`` elements become the robot's collision spheres; every collision
  element is also returned as a :class:`CollisionGeometry`.

This module does not import :mod:`jwarp.model` (and the model imports no importer);
:mod:`jwarp.importers.robot` builds the model.
"""

from __future__ import annotations

import io
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

#: joint types jwarp imports; ``planar`` and ``floating`` are reported as unsupported
SUPPORTED_JOINTS = ("revolute", "continuous", "prismatic", "fixed")
UNSUPPORTED_JOINTS = ("planar", "floating")
GEOMETRY_KINDS = ("sphere", "box", "cylinder", "capsule", "mesh")
#: tolerance of the "axis is +-x, +-y, +-z" tests
EXACT = 1e-12
#: a joint origin is folded into a DH row only if the row reproduces it to this (times
#: max(1, |translation| / m)): a few roundoffs, so folding never changes the kinematics
FOLD_TOL = 4e-15


class UrdfError(ValueError):
    """A malformed or unsupported URDF; the message names the file and the element."""


@dataclass
class UrdfOptions:
    """Options of the URDF import.

    end_effectors: ``{alias: link or frame name}``; None: one per arm, at its tool
        (:func:`jwarp.importers.tips.default_tips`: the tool frame after the last moving
        joint of each branch, gripper fingers not counted), under its own name.
    package_dirs: folders searched for ``package://NAME/...`` mesh files: a folder that is
        the package ``NAME`` or that contains a folder ``NAME``; the URDF's own ancestors
        are searched last.
    continuous_limit: limits ``[-x, x]`` [rad] of continuous joints (> 0).
    merge_static: fold a joint's origin into its DH row when exact (fewer frames).
    require_meshes: raise if a collision mesh file cannot be found (else its
        ``mesh_path`` is None and :meth:`CollisionGeometry.mesh_file` raises when used).
    name: robot name (default: the URDF's ``<robot name>``).
    """

    end_effectors: Mapping[str, str] | None = None
    package_dirs: Sequence[str | os.PathLike] = ()
    continuous_limit: float = math.pi
    merge_static: bool = True
    require_meshes: bool = False
    name: str | None = None

    def validate(self) -> None:
        check_import_options(self, "link")
        if isinstance(self.package_dirs, (str, os.PathLike)):
            self.package_dirs = [self.package_dirs]
        for d in self.package_dirs:
            if not isinstance(d, (str, os.PathLike)):
                raise TypeError(f"package_dirs: expected folder paths, got {type(d).__name__}")
            if not os.path.isdir(d):
                raise ValueError(f"package_dirs: not a folder: '{os.fspath(d)}'")


def check_import_options(options: Any, element: str) -> None:
    """Check the fields every importer's options share: ``end_effectors`` ({alias:
    ``element`` name} or None), ``continuous_limit`` (> 0 [rad]) and ``name`` (None or a
    non-empty string); TypeError/ValueError naming the field."""
    eff = options.end_effectors
    if eff is not None:
        if not isinstance(eff, Mapping):
            raise TypeError(f"end_effectors: expected a mapping {{alias: {element} name}}")
        for k, v in eff.items():
            if not isinstance(k, str) or not k or not isinstance(v, str) or not v:
                raise TypeError(f"end_effectors: expected non-empty names, got {k!r}: {v!r}")
    c = options.continuous_limit
    if isinstance(c, bool) or not isinstance(c, (int, float)) or not (0 < c < math.inf):
        raise ValueError(f"continuous_limit: expected a finite number > 0 [rad], got {c!r}")
    if options.name is not None and (not isinstance(options.name, str) or not options.name):
        raise TypeError("name: expected a non-empty string")


@dataclass
class CollisionGeometry:
    """One ``<collision>`` element of a link.

    kind: ``sphere | box | cylinder | capsule | mesh``.
    size: sphere ``[radius]``, box ``[x, y, z]`` (full edge lengths), cylinder and capsule
        ``[radius, length]`` (length of the axis segment along z, capsule without its caps),
        mesh ``[]`` [m].
    origin: (4, 4) pose of the geometry in the link frame.
    mesh_uri: the ``filename`` as written in the URDF (mesh only).
    mesh_path: the resolved file (None if not found or not a mesh).
    scale: (3,) mesh scale (ones for primitives).
    mesh: an in-memory mesh (``trimesh.Trimesh``, vertices in the geometry frame, scale
        applied) when the geometry has no file: the MJCF importer stores MuJoCo's compiled
        mesh here (``mesh_uri`` then names the MuJoCo mesh, ``mesh_path`` is None). The
        sphere fitting uses it before :meth:`mesh_file`.
    """

    link: str
    kind: str
    size: np.ndarray
    origin: np.ndarray
    mesh_uri: str | None = None
    mesh_path: str | None = None
    scale: np.ndarray = field(default_factory=lambda: np.ones(3))
    name: str | None = None
    mesh: Any = None

    def mesh_file(self) -> str:
        """The resolved mesh file; ValueError naming the link and the file if missing."""
        if self.kind != "mesh":
            raise ValueError(f"link '{self.link}': collision geometry is a {self.kind}, "
                             f"not a mesh")
        if self.mesh_path is None:
            raise ValueError(f"link '{self.link}': collision mesh file not found: "
                             f"'{self.mesh_uri}' (give package_dirs / --package-dir for "
                             f"package:// paths)")
        return self.mesh_path


@dataclass
class UrdfJoint:
    """One URDF joint as written: ``type`` (``revolute``, ``continuous``, ``prismatic``,
    ``fixed``), ``parent`` and ``child`` links, and ``actuated``: the jwarp joint that
    drives it (itself, or the joint it mimics, through mimics of mimics; None if fixed)."""

    name: str
    type: str
    parent: str
    child: str
    actuated: str | None


@dataclass
class UrdfImport:
    """What :func:`read_urdf` found: the robot ``document`` (schema ``jwarp.robot``; frames
    and joints referenced by name), the collision ``geometries`` of every link, the
    ``link_frames`` ``{link: frame name}`` (the same names), ``joint_frames``
    ``{URDF joint: dh frame name}`` of the moving joints (the child link's frame, or the axis
    frame ``<joint>_axis``; the joint's name itself is an alias of the child link's frame)
    and ``urdf_joints`` ``{name: UrdfJoint}`` of every joint, fixed ones included (what an
    SRDF may name)."""

    document: dict[str, Any]
    geometries: list[CollisionGeometry]
    link_frames: dict[str, str]
    joint_frames: dict[str, str]
    path: str
    urdf_joints: dict[str, UrdfJoint] = field(default_factory=dict)


# ------------------------------------------------------------------ small geometry
def rpy_matrix(rpy: Sequence[float]) -> np.ndarray:
    """URDF's roll-pitch-yaw: ``Rot_z(yaw) Rot_y(pitch) Rot_x(roll)`` (3, 3)."""
    r, p, y = (float(v) for v in rpy)
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


def align_z(axis: np.ndarray) -> np.ndarray:
    """A rotation (3, 3) taking z onto the unit vector ``axis`` (exact permutations for
    +-x, +-y; Rodrigues otherwise). Not used for +-z (identity and a sign flip)."""
    a = np.asarray(axis, np.float64)
    for k, cols in ((0, [[0, 0, 1], [0, 1, 0], [-1, 0, 0]]), (1, [[1, 0, 0], [0, 0, 1], [0, -1, 0]])):
        for s in (1.0, -1.0):
            e = np.zeros(3)
            e[k] = s
            if np.all(np.abs(a - e) <= EXACT):
                m = np.array(cols, np.float64)   # Rot_y(+-pi/2) / Rot_x(-+pi/2)
                return m if s > 0 else m.T
    z = np.array([0.0, 0.0, 1.0])
    v = np.cross(z, a)
    c = float(a[2])
    vx = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + vx + vx @ vx / (1.0 + c)


def dh_of(T: np.ndarray) -> np.ndarray | None:
    """``[d, theta, r, alpha, beta]`` with ``Rot_y(beta) Rot_x(alpha) Trans_x(r) Rot_z(theta)
    Trans_z(d) == T`` (to :data:`FOLD_TOL`), or None when T is not of that form."""
    R, t = T[:3, :3], T[:3, 3]
    zc = R[:, 2]
    sa = -zc[1]
    ca = math.hypot(zc[0], zc[2])
    alpha = math.atan2(sa, ca)
    if ca > 1e-9:
        beta = math.atan2(zc[0], zc[2])
    else:   # z along +-y: beta is free, choose it so that the translation fits
        beta = math.atan2(-t[2], t[0]) if math.hypot(t[0], t[2]) > 0 else 0.0
    ryx = _rot_y(beta) @ _rot_x(alpha)
    m = ryx.T @ R
    theta = math.atan2(m[1, 0], m[0, 0])
    u = _rot_y(beta).T @ t
    r = u[0]
    d = -u[1] * math.sin(alpha) + u[2] * math.cos(alpha)
    row = np.array([d, theta, r, alpha, beta])
    tol = FOLD_TOL * max(1.0, float(np.linalg.norm(t)))
    return row if np.max(np.abs(dh_matrix(row) - T)) <= tol else None


def dh_matrix(row: np.ndarray) -> np.ndarray:
    """(4, 4) ``Rot_y(beta) Rot_x(alpha) Trans_x(r) Rot_z(theta) Trans_z(d)`` of a DH row."""
    d, theta, r, alpha, beta = row
    out = np.eye(4)
    out[:3, :3] = _rot_y(beta) @ _rot_x(alpha) @ _rot_z(theta)
    out[:3, 3] = _rot_y(beta) @ _rot_x(alpha) @ (np.array([r, 0.0, 0.0]) + np.array([0, 0, d]))
    return out


def _rot_x(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0, 0], [0, c, -s], [0, s, c]])


def _rot_y(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s], [0, 1.0, 0], [-s, 0, c]])


def _rot_z(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


def _hom(R: np.ndarray, t: Any = (0.0, 0.0, 0.0)) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3] = R
    out[:3, 3] = t
    return out


# ------------------------------------------------------------------ XML checks
def _xml_root(path: str) -> Any:
    from lxml import etree

    try:
        tree = etree.parse(path, etree.XMLParser(remove_blank_text=True))
    except etree.XMLSyntaxError as e:
        raise UrdfError(f"{path}: not valid XML: {e}") from None
    except OSError as e:
        raise UrdfError(f"{path}: cannot read: {e}") from None
    root = tree.getroot()
    if root.tag != "robot":
        raise UrdfError(f"{path}: the root element is <{root.tag}>, expected <robot>")
    if not root.get("name"):
        raise UrdfError(f"{path}: <robot> has no 'name' attribute")
    return root


def _check_elements(path: str, root: Any) -> None:
    """What yourdfpy would trip over with an unhelpful KeyError/AttributeError."""
    for k, el in enumerate(root.findall("link")):
        if not el.get("name"):
            raise UrdfError(f"{path}: <link> number {k + 1} (line {el.sourceline}) has no "
                            f"'name' attribute")
    for k, el in enumerate(root.findall("joint")):
        name = el.get("name")
        if not name:
            raise UrdfError(f"{path}: <joint> number {k + 1} (line {el.sourceline}) has no "
                            f"'name' attribute")
        if not el.get("type"):
            raise UrdfError(f"{path}: joint '{name}': no 'type' attribute")
        for tag in ("parent", "child"):
            sub = el.find(tag)
            if sub is None or not sub.get("link"):
                raise UrdfError(f"{path}: joint '{name}': missing <{tag} link=\"...\"/>")
        _origin(el.find("origin"), f"{path}: joint '{name}'")
        axis = el.find("axis")
        if axis is not None:
            _numbers(axis.get("xyz"), 3, f"{path}: joint '{name}' <axis xyz>", (1.0, 0.0, 0.0))
        mimic = el.find("mimic")
        if mimic is not None and not mimic.get("joint"):
            raise UrdfError(f"{path}: joint '{name}': <mimic> has no 'joint' attribute")


def _numbers(text: str | None, n: int, where: str, default: Sequence[float] | None = None
             ) -> np.ndarray:
    if text is None:
        if default is None:
            raise UrdfError(f"{where}: missing")
        return np.asarray(default, np.float64)
    try:
        v = np.array([float(x) for x in text.split()], np.float64)
    except ValueError:
        raise UrdfError(f"{where}: expected {n} numbers, got '{text}'") from None
    if v.shape != (n,) or not np.all(np.isfinite(v)):
        raise UrdfError(f"{where}: expected {n} finite numbers, got '{text}'")
    return v


def _origin(el: Any, where: str) -> np.ndarray:
    if el is None:
        return np.eye(4)
    xyz = _numbers(el.get("xyz"), 3, f"{where} <origin xyz>", (0.0, 0.0, 0.0))
    rpy = _numbers(el.get("rpy"), 3, f"{where} <origin rpy>", (0.0, 0.0, 0.0))
    return _hom(rpy_matrix(rpy), xyz)


# ------------------------------------------------------------------ mesh paths
def resolve_mesh(uri: str, urdf_path: str, package_dirs: Sequence[str | os.PathLike]
                 ) -> str | None:
    """The file of a mesh ``filename``: ``package://NAME/rest`` searched in ``package_dirs``
    (a folder named NAME, or one containing NAME), then in the URDF's ancestor folders;
    ``file://`` and absolute paths as they are; other paths relative to the URDF's folder.
    None if no such file exists."""
    here = Path(urdf_path).resolve().parent
    if uri.startswith("package://"):
        pkg, _, rest = uri[len("package://"):].partition("/")
        candidates = []
        for d in list(package_dirs) + list(here.parents) + [here]:
            d = Path(d)
            candidates += [d / pkg / rest] + ([d / rest] if d.name == pkg else [])
        for c in candidates:
            if c.is_file():
                return str(c)
        return None
    uri = uri.removeprefix("file://")
    p = Path(uri)
    p = p if p.is_absolute() else here / p
    return str(p) if p.is_file() else None


def _collisions(path: str, root: Any, package_dirs: Sequence[str | os.PathLike],
                require_meshes: bool) -> list[CollisionGeometry]:
    out = []
    for link in root.findall("link"):
        lname = link.get("name")
        for k, col in enumerate(link.findall("collision")):
            where = f"{path}: link '{lname}' <collision> {k + 1}"
            geom = col.find("geometry")
            if geom is None or len(geom) != 1:
                raise UrdfError(f"{where}: expected one element in <geometry>")
            g = geom[0]
            kind = g.tag
            origin = _origin(col.find("origin"), where)
            item = CollisionGeometry(link=lname, kind=kind, size=np.zeros(0), origin=origin,
                                     name=col.get("name"))
            if kind == "sphere":
                item.size = _numbers(g.get("radius"), 1, f"{where} <sphere radius>")
            elif kind == "box":
                item.size = _numbers(g.get("size"), 3, f"{where} <box size>")
            elif kind in ("cylinder", "capsule"):
                item.size = np.concatenate([_numbers(g.get("radius"), 1, f"{where} <{kind} radius>"),
                                            _numbers(g.get("length"), 1, f"{where} <{kind} length>")])
            elif kind == "mesh":
                uri = g.get("filename")
                if not uri:
                    raise UrdfError(f"{where}: <mesh> has no 'filename'")
                item.mesh_uri = uri
                item.mesh_path = resolve_mesh(uri, path, package_dirs)
                scale = g.get("scale")
                item.scale = (np.ones(3) if scale is None
                              else _numbers(scale, 3, f"{where} <mesh scale>"))
                if require_meshes and item.mesh_path is None:
                    raise UrdfError(f"{where}: mesh file not found: '{uri}' (give package_dirs "
                                    f"/ --package-dir for package:// paths)")
            else:
                raise UrdfError(f"{where}: unknown geometry <{kind}> (expected one of "
                                f"{', '.join(GEOMETRY_KINDS)})")
            if np.any(item.size < 0):
                raise UrdfError(f"{where}: negative size {item.size.tolist()}")
            out.append(item)
    return out


# ------------------------------------------------------------------ the import
def read_urdf(path: str | os.PathLike, options: UrdfOptions | None = None) -> UrdfImport:
    """Read a URDF file into a ``jwarp.robot`` document and the links' collision geometry.

    Raises :class:`UrdfError` (a ValueError) naming the file and the element: bad XML, a
    joint without parent/child, a link that is not defined, a link with two parents, a
    cycle, an unsupported (planar, floating) or unknown joint type, a mimic of an unknown
    or fixed joint, a zero axis, a missing ``<limit>`` of a revolute/prismatic joint, a
    missing mesh file (only with ``require_meshes``)."""
    opt = options or UrdfOptions()
    opt.validate()
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise UrdfError(f"path: URDF file not found: '{path}'")
    root = _xml_root(path)
    _check_elements(path, root)
    geometries = _collisions(path, root, opt.package_dirs, opt.require_meshes)
    import yourdfpy
    from lxml import etree

    # visuals and collisions are not needed from yourdfpy (collisions are read above);
    # dropping them keeps unknown geometry tags (capsule) from failing its parser
    for tag in ("visual", "collision"):
        for el in root.findall(f"link/{tag}"):
            el.getparent().remove(el)
    try:
        urdf = yourdfpy.URDF.load(io.BytesIO(etree.tostring(root)), build_scene_graph=False,
                                  load_meshes=False, build_collision_scene_graph=False,
                                  load_collision_meshes=False)
    except (KeyError, AttributeError, ValueError, TypeError, IndexError) as e:
        raise UrdfError(f"{path}: yourdfpy could not parse it: {type(e).__name__}: {e}") from None
    return _build(path, urdf.robot, geometries, opt)


def _build(path: str, robot: Any, geometries: list[CollisionGeometry], opt: UrdfOptions
           ) -> UrdfImport:
    links = {}
    for link in robot.links:
        if link.name in links:
            raise UrdfError(f"{path}: link '{link.name}' is defined twice")
        links[link.name] = link
    joints = {}
    parent_joint: dict[str, Any] = {}
    children: dict[str, list[Any]] = {name: [] for name in links}
    for j in robot.joints:
        if j.name in joints:
            raise UrdfError(f"{path}: joint '{j.name}' is defined twice")
        joints[j.name] = j
        if j.type in UNSUPPORTED_JOINTS:
            raise UrdfError(f"{path}: joint '{j.name}': type '{j.type}' is not supported "
                            f"(supported: {', '.join(SUPPORTED_JOINTS)})")
        if j.type not in SUPPORTED_JOINTS:
            raise UrdfError(f"{path}: joint '{j.name}': unknown joint type '{j.type}' "
                            f"(supported: {', '.join(SUPPORTED_JOINTS)})")
        for role, link in (("parent", j.parent), ("child", j.child)):
            if link not in links:
                raise UrdfError(f"{path}: joint '{j.name}': {role} link '{link}' is not "
                                f"defined (no <link name=\"{link}\">)")
        if j.child in parent_joint:
            raise UrdfError(f"{path}: link '{j.child}' has two parents (joints "
                            f"'{parent_joint[j.child].name}' and '{j.name}')")
        parent_joint[j.child] = j
        children[j.parent].append(j)
    roots = [n for n in links if n not in parent_joint]
    if not roots:
        raise UrdfError(f"{path}: the joints form a cycle (every link has a parent joint)")
    if len(roots) > 1:
        raise UrdfError(f"{path}: several root links ({', '.join(roots)}): a URDF is one "
                        f"tree; connect them with joints")
    reached = _reachable(roots[0], children)
    if len(reached) != len(links):
        rest = [n for n in links if n not in reached]
        cycle = _cycle(rest[0], parent_joint)
        raise UrdfError(f"{path}: the joints form a cycle: {' -> '.join(cycle)}")

    # ---- actuated joints and mimics
    moving = [j for j in robot.joints if j.type != "fixed"]
    actuated = [j for j in moving if j.mimic is None]
    jtype = {j.name: "prismatic" if j.type == "prismatic" else "revolute" for j in moving}
    jdocs = []
    for j in actuated:
        if j.type == "continuous":
            lim = [-float(opt.continuous_limit), float(opt.continuous_limit)]
        else:
            if j.limit is None:
                raise UrdfError(f"{path}: joint '{j.name}': a {j.type} joint needs a <limit> "
                                f"(lower and upper)")
            lim = [float(j.limit.lower or 0.0), float(j.limit.upper or 0.0)]
            if not (np.all(np.isfinite(lim)) and lim[0] <= lim[1]):
                raise UrdfError(f"{path}: joint '{j.name}': <limit> lower {lim[0]} > upper "
                                f"{lim[1]} (or not finite)")
        jdocs.append({"name": j.name, "type": jtype[j.name], "limits": lim})
    drive = {j.name: (j.name, 1.0, 0.0) for j in actuated}   # joint -> (actuated, mult, offset)

    def resolve(j: Any) -> tuple[str, float, float]:
        """(actuated joint, multiplier, offset) of joint j, following mimics of mimics
        iteratively (a chain of any length, in any document order)."""
        chain: list[Any] = []
        cur = j
        while cur.name not in drive:
            if cur in chain:
                names = [c.name for c in chain[chain.index(cur):]] + [cur.name]
                raise UrdfError(f"{path}: joint '{cur.name}': mimic joints form a cycle: "
                                f"{' -> '.join(names)}")
            target = joints.get(cur.mimic.joint)
            if target is None:
                raise UrdfError(f"{path}: joint '{cur.name}': <mimic joint=\"{cur.mimic.joint}\"> "
                                f"names an unknown joint")
            if target.type == "fixed":
                raise UrdfError(f"{path}: joint '{cur.name}': <mimic> of the fixed joint "
                                f"'{target.name}'")
            if jtype[target.name] != jtype[cur.name]:
                raise UrdfError(f"{path}: joint '{cur.name}': a {jtype[cur.name]} joint cannot "
                                f"mimic the {jtype[target.name]} joint '{target.name}'")
            chain.append(cur)
            cur = target
        for c in reversed(chain):  # from the one nearest the actuated joint outwards
            src, m0, o0 = drive[c.mimic.joint]
            m = 1.0 if c.mimic.multiplier is None else float(c.mimic.multiplier)
            o = 0.0 if c.mimic.offset is None else float(c.mimic.offset)
            if not (np.isfinite(m) and np.isfinite(o)):
                raise UrdfError(f"{path}: joint '{c.name}': <mimic multiplier=\"{m:g}\" "
                                f"offset=\"{o:g}\">: expected finite numbers")
            drive[c.name] = (src, m * m0, m * o0 + o)
        return drive[j.name]

    for j in moving:
        resolve(j)

    # ---- frames, depth first from the root
    frames: list[dict[str, Any]] = []
    used: set[str] = set()
    link_frames: dict[str, str] = {}
    joint_frames: dict[str, str] = {}

    def unique(name: str) -> str:
        base, k = name, 1
        while name in used:
            name = f"{base}_{k}" if k > 1 else f"{base}_joint"
            k += 1
        used.add(name)
        return name

    used.update(links)   # link names are kept as they are
    used.update(joints)  # joint names are aliases of their child links' frames (below)
    frames.append({"name": roots[0], "parent": None, "kind": "static",
                   "transform": np.eye(4).tolist()})
    link_frames[roots[0]] = roots[0]
    stack = [roots[0]]
    while stack:
        lname = stack.pop()
        for j in children[lname]:
            parent = link_frames[lname]
            origin = np.eye(4) if j.origin is None else np.asarray(j.origin, np.float64)
            if j.type == "fixed":
                frames.append({"name": j.child, "parent": parent, "kind": "static",
                               "transform": origin.tolist()})
                link_frames[j.child] = j.child
                continue
            axis = np.array([1.0, 0.0, 0.0]) if j.axis is None else np.asarray(j.axis, np.float64)
            norm = float(np.linalg.norm(axis))
            if not np.isfinite(norm) or norm < 1e-9:
                raise UrdfError(f"{path}: joint '{j.name}': <axis xyz> is zero or not finite")
            axis = axis / norm
            sign = 1.0
            R = None
            if np.all(np.abs(axis - [0, 0, 1]) <= EXACT):
                pass
            elif np.all(np.abs(axis - [0, 0, -1]) <= EXACT):
                sign = -1.0
            else:
                R = align_z(axis)
            src, mult, offset = drive[j.name]
            pre = origin if R is None else origin @ _hom(R)
            row = dh_of(pre) if opt.merge_static else None
            if row is None:
                row = np.zeros(5)
                if np.max(np.abs(pre - np.eye(4))) > 0.0:
                    oname = unique(f"{j.name}_origin")
                    frames.append({"name": oname, "parent": parent, "kind": "static",
                                   "transform": pre.tolist()})
                    parent = oname
            col = 0 if jtype[j.name] == "prismatic" else 1
            row[col] += sign * offset
            name = j.child if R is None else unique(f"{j.name}_axis")
            fd: dict[str, Any] = {"name": name, "parent": parent, "kind": "dh",
                                  "dh": row.tolist()}
            if sign * mult == 1.0:
                fd["joint"] = src
            else:
                fd["coupled"] = {"joints": [src], "coefficients": [sign * mult]}
            frames.append(fd)
            joint_frames[j.name] = name
            if R is not None:
                frames.append({"name": j.child, "parent": name, "kind": "static",
                               "transform": _hom(R.T).tolist()})
            link_frames[j.child] = j.child
        stack.extend(reversed([j.child for j in children[lname]]))

    # ---- masses, spheres, end-effectors
    masses = []
    for link in robot.links:
        inert = link.inertial
        if inert is None or inert.mass is None or float(inert.mass) == 0.0:
            continue
        m = float(inert.mass)
        if not (np.isfinite(m) and m > 0):
            raise UrdfError(f"{path}: link '{link.name}': <mass value> must be finite and "
                            f">= 0, got {m}")
        com = np.zeros(3) if inert.origin is None else np.asarray(inert.origin)[:3, 3]
        masses.append({"frame": link.name, "mass": m, "com": np.asarray(com, float).tolist()})
    spheres = [{"frame": g.link, "position": g.origin[:3, 3].tolist(), "radius": float(g.size[0])}
               for g in geometries if g.kind == "sphere"]
    names = [f["name"] for f in frames]
    # a joint's name is its child link's frame (pinocchio's joint frame: the URDF joint
    # frame after the motion); a name that is also a frame's stays that frame's
    aliases = {j.name: j.child for j in robot.joints if j.name not in names}
    if opt.end_effectors is None:
        eff = {names[i]: names[i] for i in document_tips(frames, jdocs, set(links))}
    else:
        eff = {}
        for alias, target in opt.end_effectors.items():
            if target not in names and target not in aliases:
                raise UrdfError(f"end_effectors.{alias}: unknown link or frame '{target}' "
                                f"(links: {', '.join(links)})")
            eff[alias] = target if target in names else aliases[target]
    n_mimic = len(moving) - len(actuated)
    doc = {
        "schema": "jwarp.robot", "version": 1, "name": opt.name or robot.name,
        "description": (f"imported from URDF {os.path.basename(path)}: {len(links)} links, "
                        f"{len(actuated)} actuated joints, {n_mimic} mimic joints. "
                        f"Units: m, rad, kg."),
        "joints": jdocs, "frames": frames, "masses": masses, "spheres": spheres,
        "end_effectors": eff, "frame_aliases": aliases,
        "notes": {"source": os.path.abspath(path),
                  "importer": "jwarp.importers.urdf (docs/urdf.md)"},
    }
    urdf_joints = {j.name: UrdfJoint(name=j.name, type=j.type, parent=j.parent, child=j.child,
                                     actuated=None if j.type == "fixed" else drive[j.name][0])
                   for j in robot.joints}
    return UrdfImport(document=doc, geometries=geometries, link_frames=link_frames,
                      joint_frames=joint_frames, path=path, urdf_joints=urdf_joints)


def document_tips(frames: list[dict[str, Any]], joints: list[dict[str, Any]],
                  links: set[str] | None = None) -> list[int]:
    """:func:`jwarp.importers.tips.default_tips` of a robot document's ``frames`` and
    ``joints`` (parents, joints referenced by name or index); ``links``: the frame names
    that may be tools (None: all)."""
    from jwarp.importers.tips import default_tips

    fnames = [f["name"] for f in frames]
    jnames = [j["name"] for j in joints]

    def idx(v: Any, names: list[str]) -> int:
        return names.index(v) if isinstance(v, str) else int(v)

    parents = [-1 if f.get("parent") is None else idx(f["parent"], fnames) for f in frames]
    couplings: list[list[tuple[int, float]]] = []
    for f in frames:
        if f.get("kind") != "dh":
            couplings.append([])
        elif f.get("joint") is not None:
            couplings.append([(idx(f["joint"], jnames), 1.0)])
        elif f.get("coupled") is not None:
            couplings.append([(idx(j, jnames), float(c)) for j, c in
                              zip(f["coupled"]["joints"], f["coupled"]["coefficients"])])
        else:
            couplings.append([])
    frozen = [f.get("kind") == "dh" and not c for f, c in zip(frames, couplings)]
    return default_tips(fnames, parents, couplings, jnames,
                        [j.get("type", "revolute") for j in joints], frozen,
                        None if links is None else [n in links for n in fnames])


def _reachable(root: str, children: dict[str, list[Any]]) -> set[str]:
    seen, stack = {root}, [root]
    while stack:
        for j in children[stack.pop()]:
            if j.child not in seen:
                seen.add(j.child)
                stack.append(j.child)
    return seen


def _cycle(start: str, parent_joint: dict[str, Any]) -> list[str]:
    """The links of the cycle reached by following parents from ``start``."""
    path, link = [], start
    while link not in path:
        path.append(link)
        link = parent_joint[link].parent
    cyc = path[path.index(link):] + [link]
    return cyc[::-1]
