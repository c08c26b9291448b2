"""The robot JSON schema (``jwarp.robot`` version 1, ``docs/robot_schema.md``) and the
checks of a robot model: the document's fields (:func:`document_fields`, :func:`to_document`),
:func:`validate` (every invariant of a :class:`~jwarp.model.robot.RobotModel`, run on
construction and after every edit) and the value checks they share, which raise
:class:`RobotModelError` naming the offending field."""

from __future__ import annotations

import math
import numbers
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from jwarp.model.collision_pieces import (
    CollisionPieces,
    check_pieces,
    pieces_from_dict,
    pieces_to_dict,
)
from jwarp.model.parts import Capsule, Frame, Joint, LinearLimit, Mass, SelfCollision, Sphere
from jwarp.model.sphere_relation import SphereRelation, relation_from_dict, relation_to_dict

if TYPE_CHECKING:
    from jwarp.model.robot import RobotModel

__all__ = ["DH_PARAMS", "FRAME_KINDS", "JOINT_TYPES", "KAPPA_AXES", "MAX_LENGTH", "SCHEMA_NAME",
           "SCHEMA_VERSION", "RobotModelError", "document_fields", "to_document", "validate"]

SCHEMA_NAME = "jwarp.robot"
SCHEMA_VERSION = 1
FRAME_KINDS = ("dh", "static")
JOINT_TYPES = ("revolute", "prismatic")
#: column order of the DH parameters in every ``(..., 5)`` array
DH_PARAMS = ("d", "theta", "r", "alpha", "beta")
#: column order of the compliance array ``kappa (n_frames, 3)``
KAPPA_AXES = ("alpha", "beta", "theta")


class RobotModelError(ValueError):
    """A robot description is malformed; the message names the offending field."""



def _topological_order(parents: np.ndarray) -> list[int]:
    """Depth-first preorder of the frame tree (roots and children by index): every parent
    precedes its children and every subtree is one contiguous run of the order (the
    elastic kernel sums subtree masses by prefix sums over it). Raises on a cycle."""
    n = len(parents)
    state = np.zeros(n, np.int8)  # 0 new, 1 on stack, 2 done
    for start in range(n):
        chain = []
        i = start
        while i >= 0 and state[i] == 0:
            state[i] = 1
            chain.append(i)
            i = int(parents[i])
        if i >= 0 and state[i] == 1:
            cyc = chain[chain.index(i):] if i in chain else [i]
            raise RobotModelError(f"frames: cycle in the tree through frames {cyc}")
        for j in chain:
            state[j] = 2
    children: list[list[int]] = [[] for _ in range(n)]
    for j in range(n):
        if parents[j] >= 0:
            children[int(parents[j])].append(j)
    order: list[int] = []
    stack = [j for j in range(n) if parents[j] < 0][::-1]
    while stack:
        j = stack.pop()
        order.append(j)
        stack.extend(reversed(children[j]))
    return order


def _has_bool(x: Any) -> bool:
    """Whether ``x`` is a bool or a (nested) list/tuple/array holding one."""
    if isinstance(x, (bool, np.bool_)):
        return True
    if isinstance(x, np.ndarray):
        return x.dtype == np.bool_ or (x.dtype == object and any(_has_bool(v) for v in x.flat))
    if isinstance(x, (list, tuple)):
        return any(_has_bool(v) for v in x)
    return False


#: the largest length [m] a frame may be from its parent: beyond it float32 kernels lose all
#: precision (and overflow in products); no robot is that large
MAX_LENGTH = 1e5


def _within_reach(lengths: np.ndarray, where: str) -> None:
    """RobotModelError naming ``where`` if a length exceeds :data:`MAX_LENGTH` [m] (the
    kernels run in float32 by default: a value that imports may still give NaN frames)."""
    big = np.abs(np.asarray(lengths, np.float64)).max(initial=0.0)
    if big > MAX_LENGTH:
        raise RobotModelError(f"{where}: {big:g} m exceeds {MAX_LENGTH:g} m; the kinematics "
                              f"would overflow or lose all precision in float32")


def _finite(x: Any, where: str, shape: tuple[int, ...] | None = None) -> np.ndarray:
    """``x`` as a float64 array of finite numbers (numpy scalars welcome, bools refused)."""
    if _has_bool(x):
        raise RobotModelError(f"{where}: expected numbers, got a bool in {x!r}")
    try:
        a = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise RobotModelError(f"{where}: expected numbers, got {x!r}") from e
    if shape is not None and a.shape != shape:
        raise RobotModelError(f"{where}: expected shape {shape}, got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise RobotModelError(f"{where}: contains NaN or inf: {a.tolist()}")
    return a


def _number(x: Any, where: str) -> float:
    """``x`` as a finite Python float (numpy scalars welcome, bools and arrays refused)."""
    if isinstance(x, (bool, np.bool_)):
        raise RobotModelError(f"{where}: expected a number, got a bool ({x!r})")
    if not isinstance(x, numbers.Real):
        if isinstance(x, np.ndarray) and x.ndim == 0 and x.dtype.kind in "iuf":
            x = x[()]
        else:
            raise RobotModelError(f"{where}: expected a number, got {x!r}")
    v = float(x)
    if not math.isfinite(v):
        raise RobotModelError(f"{where}: must be finite, got {v}")
    return v


def _index(x: Any, where: str, what: str) -> int:
    """``x`` as a Python int index (numpy integers welcome, bools refused)."""
    if isinstance(x, (bool, np.bool_)) or not isinstance(x, (int, np.integer)):
        raise RobotModelError(f"{where}: expected a {what} index, got {x!r}")
    return int(x)


def _name(x: Any, where: str) -> str:
    if not isinstance(x, str) or not x:
        raise RobotModelError(f"{where}: expected a non-empty string, got {x!r}")
    return x


def _unique(names: Sequence[str], key: str, what: str) -> None:
    """Duplicate names are reported as such (before anything refers to them by name)."""
    seen: dict[str, int] = {}
    for k, n in enumerate(names):
        if n in seen:
            raise RobotModelError(f"{key}[{k}].name: duplicate {what} name '{n}' "
                                  f"(also {key}[{seen[n]}])")
        seen[n] = k


def validate(model: RobotModel) -> None:
    """Check a model; raise :class:`RobotModelError` naming the offending field.

    Numbers are stored as Python floats/ints (numpy scalars accepted, bools refused), so
    that a validated model always saves as JSON."""
    if model.sphere_relation is not None and not isinstance(model.sphere_relation,
                                                            SphereRelation):
        raise RobotModelError(f"sphere_relation: expected a SphereRelation or None, got "
                              f"{type(model.sphere_relation).__name__}")
    if model.collision_pieces is not None:
        try:
            check_pieces(model.collision_pieces, len(model.frames))
        except (ValueError, TypeError) as e:
            raise RobotModelError(str(e)) from None
    if not isinstance(model.name, str) or not model.name:
        raise RobotModelError("name: must be a non-empty string")
    nf, nj = len(model.frames), len(model.joints)
    if nf == 0:
        raise RobotModelError("frames: a robot needs at least one frame")
    if nj == 0:
        raise RobotModelError("joints: a robot needs at least one joint (a robot of only fixed "
                              "frames, 0 DoF, is not supported)")
    model.gravity = _finite(model.gravity, "gravity", (3,))
    if isinstance(model.workspace_dim, (bool, np.bool_)) or model.workspace_dim not in (2, 3):
        raise RobotModelError(f"workspace_dim: must be 2 (planar, x-y plane) or 3, "
                              f"got {model.workspace_dim!r}")
    model.workspace_dim = int(model.workspace_dim)
    for k, j in enumerate(model.joints):
        _name(j.name, f"joints[{k}].name")
    for i, f in enumerate(model.frames):
        _name(f.name, f"frames[{i}].name")
    _unique([j.name for j in model.joints], "joints", "joint")
    _unique([f.name for f in model.frames], "frames", "frame")
    for k, j in enumerate(model.joints):
        if j.type not in JOINT_TYPES:
            raise RobotModelError(f"joints[{k}].type: '{j.type}' is not one of {JOINT_TYPES}")
        bounds = _finite([j.lower, j.upper], f"joints[{k}].limits")
        if bounds[0] > bounds[1]:
            raise RobotModelError(f"joints[{k}].limits: lower {bounds[0]} > upper {bounds[1]}")
        j.lower, j.upper = float(bounds[0]), float(bounds[1])
    driven = set()
    for i, f in enumerate(model.frames):
        w = f"frames[{i}]"
        if f.kind not in FRAME_KINDS:
            raise RobotModelError(f"{w}.kind: '{f.kind}' is not one of {FRAME_KINDS}")
        if f.parent is not None:
            p = f.parent
            if isinstance(p, (bool, np.bool_)) or not isinstance(p, (int, np.integer)) \
                    or not 0 <= p < nf:
                raise RobotModelError(f"{w}.parent: index {p!r} out of range [0, {nf})")
            f.parent = int(p)
        if f.parent == i:
            raise RobotModelError(f"{w}.parent: a frame cannot be its own parent")
        if f.kind == "dh":
            if f.dh is None:
                raise RobotModelError(f"{w}.dh: missing DH row for a 'dh' frame")
            f.dh = _finite(f.dh, f"{w}.dh", (5,))
            _within_reach(f.dh[[0, 2]], f"{w}.dh (d, r)")
            types = set()
            coupling = []
            for jc, cc in f.coupling:
                if (isinstance(jc, (bool, np.bool_)) or not isinstance(jc, (int, np.integer))
                        or not 0 <= jc < nj):
                    raise RobotModelError(f"{w}.joint: joint index {jc!r} out of range [0, {nj})")
                coupling.append((int(jc), _number(cc, f"{w}.coupled.coefficients")))
                types.add(model.joints[jc].type)
                driven.add(int(jc))
            f.coupling = coupling
            if len(types) > 1:
                raise RobotModelError(f"{w}.coupled: mixes revolute and prismatic joints")
        else:
            if f.coupling:
                raise RobotModelError(f"{w}.joint: a 'static' frame cannot be driven by a joint")
            if f.transform is None:
                raise RobotModelError(f"{w}.transform: missing 4x4 transform for a 'static' frame")
            t = _finite(f.transform, f"{w}.transform", (4, 4))
            _within_reach(t[:3, 3], f"{w}.transform (translation)")
            if not np.allclose(t[3], [0, 0, 0, 1]):
                raise RobotModelError(f"{w}.transform: last row must be [0, 0, 0, 1]")
            if not np.allclose(t[:3, :3] @ t[:3, :3].T, np.eye(3), atol=1e-6):
                raise RobotModelError(f"{w}.transform: rotation part is not orthonormal")
            f.transform = t
    _topological_order(np.array([-1 if f.parent is None else f.parent for f in model.frames]))
    for k in range(nj):
        if k not in driven:
            raise RobotModelError(f"joints[{k}]: joint '{model.joints[k].name}' drives no frame")
    for k, m in enumerate(model.masses):
        m.frame = _check_frame(m.frame, nf, f"masses[{k}].frame")
        m.mass = _number(m.mass, f"masses[{k}].mass")
        if m.mass < 0:
            raise RobotModelError(f"masses[{k}].mass: must be finite and >= 0, got {m.mass}")
        m.com = _finite(m.com, f"masses[{k}].com", (3,))
    for k, s in enumerate(model.spheres):
        s.frame = _check_frame(s.frame, nf, f"spheres[{k}].frame")
        s.position = _finite(s.position, f"spheres[{k}].position", (3,))
        s.radius = _number(s.radius, f"spheres[{k}].radius")
        if s.radius < 0:
            raise RobotModelError(f"spheres[{k}].radius: must be finite and >= 0, got {s.radius}")
    for k, c in enumerate(model.capsules):
        c.frame = _check_frame(c.frame, nf, f"capsules[{k}].frame")
        c.p0 = _finite(c.p0, f"capsules[{k}].p0", (3,))
        c.p1 = _finite(c.p1, f"capsules[{k}].p1", (3,))
        c.radius = _number(c.radius, f"capsules[{k}].radius")
        if c.radius < 0:
            raise RobotModelError(f"capsules[{k}].radius: must be finite and >= 0, got {c.radius}")
    sc = model.self_collision
    for g, members in sc.groups.items():
        sc.groups[g] = [_check_frame(m, nf, f"self_collision.groups.{g}") for m in members]
    for key in ("include_pairs", "exclude_pairs"):
        pairs = []
        for k, pair in enumerate(getattr(sc, key)):
            if len(pair) != 2:
                raise RobotModelError(f"self_collision.{key}[{k}]: a pair needs 2 frames")
            pairs.append(tuple(_check_frame(m, nf, f"self_collision.{key}[{k}]") for m in pair))
        setattr(sc, key, pairs)
    frame_names = [f.name for f in model.frames]
    # other names of frames: each a frame index, none the name of another frame
    for table, named in (("end_effectors", model.end_effectors),
                         ("frame_aliases", model.frame_aliases)):
        for name, idx in named.items():
            if table == "frame_aliases":
                _name(name, table)
            idx = named[name] = _check_frame(idx, nf, f"{table}.{name}")
            if name in frame_names and frame_names.index(name) != idx:
                i = frame_names.index(name)
                raise RobotModelError(f"{table}.{name}: the name of frame {i} '{name}', but "
                                      f"points at frame {idx} '{frame_names[idx]}' (frame "
                                      f"'{name}' would be ambiguous)")
    for k, lim in enumerate(model.linear_limits):
        w = f"linear_limits[{k}]"
        if len(lim.joints) != len(lim.coefficients) or not lim.joints:
            raise RobotModelError(f"{w}: joints and coefficients differ in length")
        lim.joints = [_index(j, f"{w}.joints", "joint") for j in lim.joints]
        for jl in lim.joints:
            if not 0 <= jl < nj:
                raise RobotModelError(f"{w}.joints: index {jl} out of range")
        lim.coefficients = [float(c) for c in _finite(lim.coefficients, f"{w}.coefficients")]
        lim.lower = _number(lim.lower, f"{w}.limits")
        lim.upper = _number(lim.upper, f"{w}.limits")
        if lim.lower > lim.upper:
            raise RobotModelError(f"{w}.limits: lower > upper")
    kappa = _finite(model.kappa, "kappa", (nf, 3))
    if np.any(kappa < 0):
        raise RobotModelError("kappa: compliances must be >= 0")
    model.kappa = kappa
    harm = _finite(model.harmonic, "harmonic")
    if harm.ndim != 3 or harm.shape[0] != nj or harm.shape[2] != 2:
        raise RobotModelError(f"harmonic: expected shape (n_dof={nj}, K, 2) "
                              f"([a_k, b_k] per joint and harmonic k = 1..K), got {harm.shape}")
    model.harmonic = harm
    knl = _finite(model.kappa_nonlinear, "kappa_nonlinear", (nf,))
    if np.any(knl[~model.is_dh]):
        raise RobotModelError("kappa_nonlinear: must be 0 on static frames")
    model.kappa_nonlinear = knl
    ch = _finite(model.coupling_harmonic, "coupling_harmonic")
    if ch.ndim != 3 or ch.shape[0] != nf or ch.shape[2] != 2:
        raise RobotModelError(f"coupling_harmonic: expected shape (n_frames={nf}, K, 2), "
                              f"got {ch.shape}")
    for fi in np.nonzero(np.any(ch != 0, axis=(1, 2)))[0]:
        if not model.frames[fi].coupling:
            raise RobotModelError(f"coupling_harmonic.{model.frames[fi].name}: the frame is "
                                  f"driven by no joint")
    model.coupling_harmonic = ch


def _check_frame(idx: Any, nf: int, where: str) -> int:
    if not (isinstance(idx, (int, np.integer)) and not isinstance(idx, (bool, np.bool_))
            and 0 <= idx < nf):
        raise RobotModelError(f"{where}: frame index {idx!r} out of range [0, {nf})")
    return int(idx)



# ================================================================ JSON mapping
def _resolve(value: Any, names: list[str], where: str, what: str) -> int:
    if isinstance(value, str):
        if value not in names:
            raise RobotModelError(f"{where}: unknown {what} '{value}'")
        return names.index(value)
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise RobotModelError(f"{where}: expected a {what} name or index, got {value!r}")
    return int(value)


def _req(doc: dict, key: str, where: str) -> Any:
    if not isinstance(doc, dict):
        raise RobotModelError(f"{where}: expected an object, got {type(doc).__name__}")
    if key not in doc:
        raise RobotModelError(f"{where}.{key}: missing")
    return doc[key]



def document_fields(doc: Any) -> dict[str, Any]:
    """The fields of a robot JSON document (schema ``jwarp.robot`` version 1), checked and
    resolved (names to indices): the keyword arguments of
    :class:`~jwarp.model.robot.RobotModel`, which validates the whole model again.
    :class:`RobotModelError` naming the offending field."""
    if not isinstance(doc, dict):
        raise RobotModelError("document: expected a JSON object")
    schema = doc.get("schema", SCHEMA_NAME)
    if schema != SCHEMA_NAME:
        raise RobotModelError(f"schema: expected '{SCHEMA_NAME}', got '{schema}'")
    version = doc.get("version", SCHEMA_VERSION)
    if version != SCHEMA_VERSION:
        raise RobotModelError(f"version: schema version {version} not supported "
                              f"(this jwarp reads version {SCHEMA_VERSION})")
    name = _req(doc, "name", "document")
    jdocs = _req(doc, "joints", "document")
    fdocs = _req(doc, "frames", "document")
    if not isinstance(jdocs, list):
        raise RobotModelError("joints: expected a list")
    if not isinstance(fdocs, list):
        raise RobotModelError("frames: expected a list")
    joints = []
    for k, jd in enumerate(jdocs):
        w = f"joints[{k}]"
        lim = _req(jd, "limits", w) if isinstance(jd, dict) and "limits" in jd else [-math.pi, math.pi]
        lim = _finite(lim, f"{w}.limits", (2,))
        joints.append(Joint(name=_name(_req(jd, "name", w), f"{w}.name"),
                            type=jd.get("type", "revolute"),
                            lower=float(lim[0]), upper=float(lim[1])))
    jnames = [j.name for j in joints]
    _unique(jnames, "joints", "joint")
    fnames = [_name(_req(fd, "name", f"frames[{k}]"), f"frames[{k}].name")
              for k, fd in enumerate(fdocs)]
    _unique(fnames, "frames", "frame")
    frames = []
    for k, fd in enumerate(fdocs):
        w = f"frames[{k}]"
        kind = _req(fd, "kind", w)
        parent = fd.get("parent")
        parent = None if parent is None else _resolve(parent, fnames, f"{w}.parent", "frame")
        frame = Frame(name=fnames[k], parent=parent, kind=kind)
        if kind == "dh":
            row = _finite(_req(fd, "dh", w), f"{w}.dh")
            if row.ndim != 1 or row.shape[0] not in (4, 5):
                raise RobotModelError(f"{w}.dh: expected [d, theta, r, alpha(, beta)], "
                                      f"got {row.shape[0] if row.ndim == 1 else row.shape} values")
            frame.dh = np.concatenate([row, np.zeros(5 - row.shape[0])])
            if fd.get("joint") is not None and fd.get("coupled") is not None:
                raise RobotModelError(f"{w}: give either 'joint' or 'coupled', not both")
            if fd.get("joint") is not None:
                frame.coupling = [(_resolve(fd["joint"], jnames, f"{w}.joint", "joint"), 1.0)]
            elif fd.get("coupled") is not None:
                cd = fd["coupled"]
                js = _req(cd, "joints", f"{w}.coupled")
                cs = _req(cd, "coefficients", f"{w}.coupled")
                if not isinstance(js, list) or not isinstance(cs, list) or len(js) != len(cs) or not js:
                    raise RobotModelError(f"{w}.coupled: 'joints' and 'coefficients' must be "
                                          f"non-empty lists of equal length")
                frame.coupling = [(_resolve(j, jnames, f"{w}.coupled.joints", "joint"),
                                   _number(c, f"{w}.coupled.coefficients"))
                                  for j, c in zip(js, cs)]
        elif kind == "static":
            frame.transform = _finite(_req(fd, "transform", w), f"{w}.transform", (4, 4))
            for key in ("joint", "coupled"):
                if fd.get(key) is not None:
                    raise RobotModelError(f"{w}.{key}: a 'static' frame cannot be driven by a joint")
        frames.append(frame)

    def fidx(v: Any, where: str) -> int:
        return _resolve(v, fnames, where, "frame")

    masses = [Mass(frame=fidx(_req(m, "frame", f"masses[{k}]"), f"masses[{k}].frame"),
                   mass=_number(_req(m, "mass", f"masses[{k}]"), f"masses[{k}].mass"),
                   com=_finite(_req(m, "com", f"masses[{k}]"), f"masses[{k}].com", (3,)))
              for k, m in enumerate(doc.get("masses", []))]
    spheres = [Sphere(frame=fidx(_req(s, "frame", f"spheres[{k}]"), f"spheres[{k}].frame"),
                      position=_finite(_req(s, "position", f"spheres[{k}]"), f"spheres[{k}].position", (3,)),
                      radius=_number(_req(s, "radius", f"spheres[{k}]"), f"spheres[{k}].radius"))
               for k, s in enumerate(doc.get("spheres", []))]
    capsules = [Capsule(frame=fidx(_req(c, "frame", f"capsules[{k}]"), f"capsules[{k}].frame"),
                        p0=_finite(_req(c, "p0", f"capsules[{k}]"), f"capsules[{k}].p0", (3,)),
                        p1=_finite(_req(c, "p1", f"capsules[{k}]"), f"capsules[{k}].p1", (3,)),
                        radius=_number(_req(c, "radius", f"capsules[{k}]"),
                                       f"capsules[{k}].radius"))
                for k, c in enumerate(doc.get("capsules", []))]
    scd = doc.get("self_collision", {}) or {}
    sc = SelfCollision(
        groups={g: [fidx(m, f"self_collision.groups.{g}") for m in ms]
                for g, ms in (scd.get("groups") or {}).items()},
        include_pairs=[tuple(fidx(m, f"self_collision.include_pairs[{k}]") for m in p)
                       for k, p in enumerate(scd.get("include_pairs", []))],
        exclude_pairs=[tuple(fidx(m, f"self_collision.exclude_pairs[{k}]") for m in p)
                       for k, p in enumerate(scd.get("exclude_pairs", []))])
    eff = {str(k): fidx(v, f"end_effectors.{k}") for k, v in (doc.get("end_effectors") or {}).items()}
    aliases = doc.get("frame_aliases") or {}
    if not isinstance(aliases, dict):
        raise RobotModelError("frame_aliases: expected an object {name: frame}")
    aliases = {str(k): fidx(v, f"frame_aliases.{k}") for k, v in aliases.items()}
    lin = []
    for k, ld in enumerate(doc.get("linear_limits", [])):
        lim = _finite(_req(ld, "limits", f"linear_limits[{k}]"), f"linear_limits[{k}].limits", (2,))
        lin.append(LinearLimit(
            joints=[_resolve(j, jnames, f"linear_limits[{k}].joints", "joint")
                    for j in _req(ld, "joints", f"linear_limits[{k}]")],
            coefficients=[float(c) for c in _finite(_req(ld, "coefficients", f"linear_limits[{k}]"),
                                                    f"linear_limits[{k}].coefficients").reshape(-1)],
            lower=float(lim[0]), upper=float(lim[1])))
    kappa = doc.get("kappa")
    if kappa is not None:
        kappa = _finite(kappa, "kappa", (len(frames), 3))
    harmonic = doc.get("harmonic")
    if harmonic is not None:
        harmonic = _harmonic_from_doc(harmonic, jnames)
    knl = doc.get("kappa_nonlinear")
    if knl is not None:
        knl = _finite(knl, "kappa_nonlinear", (len(frames),))
    coupled_h = doc.get("coupling_harmonic")
    if coupled_h is not None:
        coupled_h = _harmonic_from_doc(coupled_h, [f.name for f in frames],
                                       "coupling_harmonic", "frame")
    return dict(
        name=name, description=doc.get("description", ""), joints=joints, frames=frames,
        gravity=_finite(doc.get("gravity", [0.0, 0.0, -9.81]), "gravity", (3,)),
        workspace_dim=doc.get("workspace_dim", 3),
        masses=masses, spheres=spheres, capsules=capsules, self_collision=sc,
        end_effectors=eff, frame_aliases=aliases, linear_limits=lin, kappa=kappa, harmonic=harmonic,
        kappa_nonlinear=knl, coupling_harmonic=coupled_h, notes={str(k): str(v) for k, v in (doc.get("notes") or {}).items()},
        sphere_relation=_relation(doc.get("sphere_relation")),
        collision_pieces=_pieces(doc.get("collision_pieces"), [f.name for f in frames]))


def _relation(doc: Any) -> SphereRelation | None:
    try:
        return relation_from_dict(doc)
    except (ValueError, TypeError) as e:
        raise RobotModelError(str(e)) from None


def _pieces(doc: Any, frame_names: list[str]) -> CollisionPieces | None:
    try:
        return pieces_from_dict(doc, frame_names)
    except (ValueError, TypeError) as e:
        raise RobotModelError(str(e)) from None


def _harmonic_from_doc(value: Any, jnames: list[str], key: str = "harmonic",
                       what: str = "joint") -> np.ndarray:
    """``harmonic``: {joint name: [[a_1, b_1], ..., [a_K, b_K]]} (joints left out: zero;
    lists may differ in length, shorter ones are padded with zeros) -> (n_dof, K, 2);
    ``coupling_harmonic`` the same keyed by frame name (``key``/``what``)."""
    if not isinstance(value, dict):
        raise RobotModelError(f"{key}: expected an object {{{what} name: [[a_1, b_1], ...]}}")
    rows = {}
    for name, v in value.items():
        j = _resolve(name, jnames, key, what)
        a = _finite(v, f"{key}.{name}")
        if a.ndim != 2 or a.shape[1] != 2:
            raise RobotModelError(f"{key}.{name}: expected [[a_1, b_1], ..., [a_K, b_K]], "
                                  f"got shape {a.shape}")
        rows[j] = a
    K = max([a.shape[0] for a in rows.values()], default=0)
    out = np.zeros((len(jnames), K, 2))
    for j, a in rows.items():
        out[j, :a.shape[0]] = a
    return out


def to_document(m: RobotModel) -> dict[str, Any]:
    """The JSON document of robot ``m`` (schema ``jwarp.robot`` version 1)."""
    def lst(a: np.ndarray | None) -> list:
        return np.asarray(a, np.float64).tolist()

    frames = []
    for f in m.frames:
        d: dict[str, Any] = {"name": f.name, "parent": f.parent, "kind": f.kind}
        if f.kind == "dh":
            d["dh"] = lst(f.dh)
            if len(f.coupling) == 1 and f.coupling[0][1] == 1.0:
                d["joint"] = f.coupling[0][0]
            elif f.coupling:
                d["coupled"] = {"joints": [j for j, _ in f.coupling],
                                "coefficients": [c for _, c in f.coupling]}
        else:
            d["transform"] = lst(f.transform)
        frames.append(d)
    doc: dict[str, Any] = {
        "schema": SCHEMA_NAME, "version": SCHEMA_VERSION, "name": m.name,
        "description": m.description, "gravity": lst(m.gravity),
        "workspace_dim": m.workspace_dim,
        "joints": [{"name": j.name, "type": j.type, "limits": [j.lower, j.upper]} for j in m.joints],
        "frames": frames,
        "masses": [{"frame": x.frame, "mass": x.mass, "com": lst(x.com)} for x in m.masses],
        "spheres": [{"frame": s.frame, "position": lst(s.position), "radius": s.radius}
                    for s in m.spheres],
        "capsules": [{"frame": c.frame, "p0": lst(c.p0), "p1": lst(c.p1), "radius": c.radius}
                     for c in m.capsules],
        "self_collision": {"groups": m.self_collision.groups,
                           "include_pairs": [list(p) for p in m.self_collision.include_pairs],
                           "exclude_pairs": [list(p) for p in m.self_collision.exclude_pairs]},
        "end_effectors": dict(m.end_effectors),
        "linear_limits": [{"joints": l.joints, "coefficients": l.coefficients,
                           "limits": [l.lower, l.upper]} for l in m.linear_limits],
    }
    if m.frame_aliases:
        doc["frame_aliases"] = dict(m.frame_aliases)
    if np.any(m.kappa):
        doc["kappa"] = lst(m.kappa)
    if m.has_harmonic:
        doc["harmonic"] = {m.joints[j].name: lst(m.harmonic[j])
                           for j in range(m.n_dof) if np.any(m.harmonic[j])}
    if np.any(m.kappa_nonlinear):
        doc["kappa_nonlinear"] = lst(m.kappa_nonlinear)
    if m.has_coupling_harmonic:
        doc["coupling_harmonic"] = {m.frames[i].name: lst(m.coupling_harmonic[i])
                                    for i in range(m.n_frames) if np.any(m.coupling_harmonic[i])}
    if m.notes:
        doc["notes"] = dict(m.notes)
    if m.sphere_relation is not None:
        doc["sphere_relation"] = relation_to_dict(m.sphere_relation)
    if m.collision_pieces is not None:
        doc["collision_pieces"] = pieces_to_dict(m.collision_pieces, m.frame_names)
    return doc


