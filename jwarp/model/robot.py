"""Robot model: a tree of frames with DH rows, joints, masses, collision bodies.

`RobotModel` is the single description every kernel and solver reads. It is plain
Python/numpy (no Warp); :mod:`jwarp.core.device` turns it into device tables.

Conventions (see ``docs/robot_schema.md``):

* DH row ``[d, theta, r, alpha, beta]`` (beta optional, default 0)::

      parent_T_child = Rot_y(beta) Rot_x(alpha) Trans_x(r) Rot_z(theta + q) Trans_z(d)

  A revolute joint adds its value to ``theta``, a prismatic one to ``d``.
* A ``dh`` frame is driven by one joint, by a linear combination of joints (coupled
  passive joint) or by none (a fixed DH frame that may still bend elastically).
* A ``static`` frame has a fixed 4x4 transform relative to its parent.
* Elastic compliance ``kappa``: array ``(n_frames, 3)`` in rad/(N m) for the axes of
  ``[alpha, beta, theta]`` of each ``dh`` frame (zero rows for static frames).
* Non-geometric extras (both optional, absent = zero; see ``docs/nongeometric.md``):
  ``harmonic`` ``(n_dof, K, 2)`` joint transmission errors: joint j acts as
  ``q_j + sum_k a_jk sin(k q_j) + b_jk cos(k q_j)`` (k = 1..K, ``[..., 0]`` = a,
  ``[..., 1]`` = b) [rad, or m for a prismatic joint]; ``kappa_nonlinear`` ``(n_frames,)``
  [rad/(N m)^3] torque-dependent joint compliance: the theta axis of a DH frame bends by
  ``(kappa_theta + kappa_nonlinear tau^2) tau`` (negative = stiffening, as harmonic drives).
  ``coupling_harmonic`` ``(n_frames, K, 2)`` angle-dependent errors of coupled frames: a
  DH frame driven by ``u = sum_j c_j q_j`` (raw joint values) moves by
  ``sum_k a_ik sin(k u) + b_ik cos(k u)`` more (the calibration's ``coupling`` group,
  ``docs/calibration.md``; applied by the calibration's model evaluation, not yet by the
  kinematics kernels).
* SI units: m, rad, kg, N m.
"""

from __future__ import annotations

import json
import math
import numbers
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from jwarp.model.collision_pieces import (
    CollisionPieces,
    check_pieces,
    pieces_from_dict,
    pieces_to_dict,
)
from jwarp.model.sphere_relation import (
    SphereRelation,
    relation_after_edit,
    relation_from_dict,
    relation_to_dict,
)
from jwarp.utils.atomic import atomic_write_text

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


@dataclass
class Joint:
    """One actuated joint. ``lower``/``upper`` in rad (revolute) or m (prismatic)."""

    name: str
    type: str = "revolute"
    lower: float = -math.pi
    upper: float = math.pi


@dataclass
class Frame:
    """One frame of the kinematic tree.

    ``coupling`` lists ``(joint_index, coefficient)``: the frame's joint value is
    ``sum(c * q[j])``. Empty for static frames and fixed DH frames.
    """

    name: str
    parent: int | None
    kind: str
    dh: np.ndarray | None = None  # (5,) [d, theta, r, alpha, beta]
    coupling: list[tuple[int, float]] = field(default_factory=list)
    transform: np.ndarray | None = None  # (4, 4) for static frames


@dataclass
class Mass:
    """Point mass ``mass`` [kg] at ``com`` [m] in the coordinates of ``frame``."""

    frame: int
    mass: float
    com: np.ndarray


@dataclass
class Sphere:
    """Collision sphere: centre ``position`` [m] in ``frame``, ``radius`` [m]."""

    frame: int
    position: np.ndarray
    radius: float


@dataclass
class Capsule:
    """Collision capsule: segment ``p0``-``p1`` [m] in ``frame``, ``radius`` [m]."""

    frame: int
    p0: np.ndarray
    p1: np.ndarray
    radius: float


@dataclass
class LinearLimit:
    """Limit on a linear combination of joints: ``lower <= sum(c_j q_j) <= upper``."""

    joints: list[int]
    coefficients: list[float]
    lower: float
    upper: float


@dataclass
class SelfCollision:
    """Which frame pairs may collide.

    Frames inside one group never collide with each other, except ``include_pairs``;
    ``exclude_pairs`` never collide. Everything else may.
    """

    groups: dict[str, list[int]] = field(default_factory=dict)
    include_pairs: list[tuple[int, int]] = field(default_factory=list)
    exclude_pairs: list[tuple[int, int]] = field(default_factory=list)


@dataclass(eq=False)
class RobotModel:
    """A robot: frames, joints, masses, collision bodies, end-effectors, gravity."""

    name: str
    joints: list[Joint]
    frames: list[Frame]
    description: str = ""
    gravity: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, -9.81]))
    workspace_dim: int = 3  # 2: a planar robot moving in the x-y plane (2D worlds), else 3
    masses: list[Mass] = field(default_factory=list)
    spheres: list[Sphere] = field(default_factory=list)
    capsules: list[Capsule] = field(default_factory=list)
    self_collision: SelfCollision = field(default_factory=SelfCollision)
    end_effectors: dict[str, int] = field(default_factory=dict)
    #: ``{name: frame index}``: other names of frames (an imported URDF's joint names, each
    #: naming its child link's frame, as pinocchio's joint frames; docs/urdf.md)
    frame_aliases: dict[str, int] = field(default_factory=dict)
    linear_limits: list[LinearLimit] = field(default_factory=list)
    kappa: np.ndarray | None = None  # (n_frames, 3) rad/(N m)
    notes: dict[str, str] = field(default_factory=dict)
    harmonic: np.ndarray | None = None  # (n_dof, K, 2) [rad or m]; None: K = 0
    kappa_nonlinear: np.ndarray | None = None  # (n_frames,) rad/(N m)^3
    coupling_harmonic: np.ndarray | None = None  # (n_frames, K, 2) [rad or m]; None: K = 0
    #: how the spheres relate to the collision meshes they model (contained, or
    #: approximate with the per-link poke-out); None: unknown (jwarp.model.sphere_relation)
    sphere_relation: SphereRelation | None = None
    #: the convex pieces of the collision geometry (meshes' hulls, primitives) and the
    #: spheres they stand for; None: not recorded (jwarp.model.collision_pieces)
    collision_pieces: CollisionPieces | None = None

    def __post_init__(self) -> None:
        self.gravity = _finite(self.gravity, "gravity")
        if self.kappa is None:
            self.kappa = np.zeros((len(self.frames), 3))
        self.kappa = _finite(self.kappa, "kappa")
        if self.harmonic is None:
            self.harmonic = np.zeros((len(self.joints), 0, 2))
        self.harmonic = _finite(self.harmonic, "harmonic")
        if self.kappa_nonlinear is None:
            self.kappa_nonlinear = np.zeros(len(self.frames))
        self.kappa_nonlinear = _finite(self.kappa_nonlinear, "kappa_nonlinear")
        if self.coupling_harmonic is None:
            self.coupling_harmonic = np.zeros((len(self.frames), 0, 2))
        self.coupling_harmonic = _finite(self.coupling_harmonic, "coupling_harmonic")
        validate(self)

    # ----------------------------------------------------------------- sizes
    @property
    def n_dof(self) -> int:
        return len(self.joints)

    @property
    def n_frames(self) -> int:
        return len(self.frames)

    @property
    def joint_names(self) -> list[str]:
        return [j.name for j in self.joints]

    @property
    def frame_names(self) -> list[str]:
        return [f.name for f in self.frames]

    # ------------------------------------------------------------- look-ups
    def frame_index(self, frame: int | str, argname: str = "frame") -> int:
        """Index of a frame given by index, end-effector name, frame name or frame alias
        (:attr:`frame_aliases`), looked up in that order."""
        if isinstance(frame, (bool, np.bool_)):
            raise TypeError(f"{argname}: expected a frame name or index, got {frame!r}")
        if isinstance(frame, (int, np.integer)):
            if not 0 <= int(frame) < self.n_frames:
                raise ValueError(
                    f"{argname}: frame index {frame} out of range [0, {self.n_frames}) "
                    f"for robot '{self.name}'")
            return int(frame)
        if isinstance(frame, str):
            if frame in self.end_effectors:
                return self.end_effectors[frame]
            names = self.frame_names
            if frame in names:
                return names.index(frame)
            if frame in self.frame_aliases:
                return self.frame_aliases[frame]
            raise ValueError(
                f"{argname}: unknown frame '{frame}' for robot '{self.name}'; "
                f"known: {', '.join(names)}")
        raise TypeError(f"{argname}: expected a frame name or index, got {type(frame).__name__}")

    def joint_index(self, joint: int | str, argname: str = "joint") -> int:
        if isinstance(joint, (int, np.integer)) and not isinstance(joint, bool):
            if not 0 <= int(joint) < self.n_dof:
                raise ValueError(f"{argname}: joint index {joint} out of range [0, {self.n_dof})")
            return int(joint)
        if isinstance(joint, str):
            if joint in self.joint_names:
                return self.joint_names.index(joint)
            raise ValueError(f"{argname}: unknown joint '{joint}' for robot '{self.name}'; "
                             f"known: {', '.join(self.joint_names)}")
        raise TypeError(f"{argname}: expected a joint name or index, got {type(joint).__name__}")

    # --------------------------------------------------------- derived data
    @cached_property
    def parents(self) -> np.ndarray:
        """(n_frames,) int32 parent index, -1 for roots."""
        return np.array([-1 if f.parent is None else f.parent for f in self.frames], np.int32)

    @cached_property
    def topological_order(self) -> np.ndarray:
        """(n_frames,) frame indices ordered so that every parent precedes its children:
        a depth-first preorder, so every subtree is a contiguous run (see :attr:`subtree_end`)."""
        return np.asarray(_topological_order(self.parents), np.int32)

    @cached_property
    def subtree_end(self) -> np.ndarray:
        """(n_frames,) int32: for position k of :attr:`topological_order`, the position one past
        the last descendant of frame ``topological_order[k]`` (its subtree is ``order[k:end]``)."""
        order = self.topological_order
        pos = np.empty(self.n_frames, np.int64)
        pos[order] = np.arange(self.n_frames)
        end = np.arange(1, self.n_frames + 1)
        for k in range(self.n_frames - 1, -1, -1):   # children come after their parent
            p = self.parents[order[k]]
            if p >= 0:
                end[pos[p]] = max(end[pos[p]], end[k])
        return end.astype(np.int32)

    @cached_property
    def depth(self) -> np.ndarray:
        """(n_frames,) number of ancestors of each frame."""
        depth = np.zeros(self.n_frames, np.int32)
        for i in self.topological_order:
            p = self.parents[i]
            depth[i] = 0 if p < 0 else depth[p] + 1
        return depth

    def ancestors(self, frame: int | str) -> list[int]:
        """Path from the root to ``frame`` (both included), root first."""
        i = self.frame_index(frame)
        path = []
        while i >= 0:
            path.append(i)
            i = int(self.parents[i])
        return path[::-1]

    @cached_property
    def subtree_mask(self) -> np.ndarray:
        """(n_frames, n_frames) bool: ``[i, j]`` is True if j is i or a descendant of i."""
        m = np.eye(self.n_frames, dtype=bool)
        for j in range(self.n_frames):
            for i in self.ancestors(j):
                m[i, j] = True
        return m

    @cached_property
    def dh_table(self) -> np.ndarray:
        """(n_frames, 5) nominal DH rows ``[d, theta, r, alpha, beta]`` (zeros for static)."""
        t = np.zeros((self.n_frames, 5))
        for i, f in enumerate(self.frames):
            if f.kind == "dh":
                t[i] = f.dh
        return t

    @cached_property
    def static_transforms(self) -> np.ndarray:
        """(n_frames, 4, 4) fixed transforms of static frames (identity for dh frames)."""
        t = np.tile(np.eye(4), (self.n_frames, 1, 1))
        for i, f in enumerate(self.frames):
            if f.kind == "static":
                t[i] = f.transform
        return t

    @cached_property
    def is_dh(self) -> np.ndarray:
        return np.array([f.kind == "dh" for f in self.frames])

    @cached_property
    def coupling_matrix(self) -> np.ndarray:
        """(n_frames, n_dof): the joint value of frame i is ``coupling_matrix[i] @ q``."""
        c = np.zeros((self.n_frames, self.n_dof))
        for i, f in enumerate(self.frames):
            for j, coef in f.coupling:
                c[i, j] += coef
        return c

    @cached_property
    def frame_is_prismatic(self) -> np.ndarray:
        out = np.zeros(self.n_frames, bool)
        for i, f in enumerate(self.frames):
            if f.coupling:
                out[i] = self.joints[f.coupling[0][0]].type == "prismatic"
        return out

    @property
    def has_harmonic(self) -> bool:
        """Whether any joint transmission error (``harmonic``) is nonzero."""
        h = self.harmonic
        return h.shape[1] != 0 and bool(np.any(h))   # shape first: the common K = 0 is cheap

    @property
    def has_coupling_harmonic(self) -> bool:
        """Whether any angle-dependent coupled-frame error (``coupling_harmonic``) is nonzero."""
        h = self.coupling_harmonic
        return h.shape[1] != 0 and bool(np.any(h))

    def coupled_frame_delta(self, q: np.ndarray, coupling_harmonic: np.ndarray | None = None
                            ) -> np.ndarray:
        """(..., n_frames) the extra joint value of every frame from ``coupling_harmonic``
        (or the given (n_frames, K, 2)): ``sum_k a_ik sin(k u_i) + b_ik cos(k u_i)`` with
        ``u = coupling_matrix @ q`` of the raw joint values q (..., n_dof) [rad or m]; it is
        added to theta (d for a prismatic frame)."""
        h = self.coupling_harmonic if coupling_harmonic is None else np.asarray(
            coupling_harmonic, np.float64)
        q = np.asarray(q, np.float64)
        if h.shape[1] == 0:
            return np.zeros(q.shape[:-1] + (self.n_frames,))
        u = q @ self.coupling_matrix.T                      # (..., n_frames)
        k = np.arange(1, h.shape[1] + 1)
        ku = u[..., :, None] * k
        return np.sum(h[:, :, 0] * np.sin(ku) + h[:, :, 1] * np.cos(ku), axis=-1)

    def joint_transmission(self, q: np.ndarray, harmonic: np.ndarray | None = None
                           ) -> np.ndarray:
        """The joint values the links see, ``q + dq(q)`` (..., n_dof) (numpy float64),
        ``dq_j = sum_k a_jk sin(k q_j) + b_jk cos(k q_j)``; ``harmonic`` (n_dof, K, 2)
        replaces the robot's own."""
        h = self.harmonic if harmonic is None else np.asarray(harmonic, np.float64)
        q = np.asarray(q, np.float64)
        if h.shape[1] == 0:
            return q.copy()
        k = np.arange(1, h.shape[1] + 1)
        kq = q[..., :, None] * k                      # (..., n_dof, K)
        return q + np.sum(h[:, :, 0] * np.sin(kq) + h[:, :, 1] * np.cos(kq), axis=-1)

    def joint_transmission_slope(self, q: np.ndarray) -> np.ndarray:
        """d(q + dq(q))/dq (..., n_dof): the diagonal chain-rule factor of
        :meth:`joint_transmission` (1 without transmission errors)."""
        h = self.harmonic
        q = np.asarray(q, np.float64)
        if h.shape[1] == 0:
            return np.ones_like(q)
        k = np.arange(1, h.shape[1] + 1)
        kq = q[..., :, None] * k
        return 1.0 + np.sum(k * (h[:, :, 0] * np.cos(kq) - h[:, :, 1] * np.sin(kq)), axis=-1)

    @cached_property
    def joint_limits(self) -> np.ndarray:
        """(n_dof, 2) [lower, upper]."""
        return np.array([[j.lower, j.upper] for j in self.joints], np.float64).reshape(-1, 2)

    @cached_property
    def allowed_collision_pairs(self) -> np.ndarray:
        """(n_frames, n_frames) symmetric bool: frames i and j are checked for collision."""
        n = self.n_frames
        allowed = ~np.eye(n, dtype=bool)
        for members in self.self_collision.groups.values():
            for a in members:
                for b in members:
                    allowed[a, b] = False
        for a, b in self.self_collision.include_pairs:
            allowed[a, b] = allowed[b, a] = True
        for a, b in self.self_collision.exclude_pairs:
            allowed[a, b] = allowed[b, a] = False
        return allowed

    def sphere_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Spheres as arrays: frame (n,), position (n, 3) [m], radius (n,) [m]."""
        f = np.array([s.frame for s in self.spheres], np.int32)
        p = np.array([s.position for s in self.spheres], np.float64).reshape(-1, 3)
        r = np.array([s.radius for s in self.spheres], np.float64)
        return f, p, r

    def mass_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Masses as arrays: frame (n,), mass (n,) [kg], com (n, 3) [m]."""
        f = np.array([m.frame for m in self.masses], np.int32)
        m = np.array([m.mass for m in self.masses], np.float64)
        c = np.array([m.com for m in self.masses], np.float64).reshape(-1, 3)
        return f, m, c

    # ------------------------------------------------------------ I/O
    def to_dict(self) -> dict[str, Any]:
        """The JSON document of this robot (schema ``jwarp.robot`` version 1)."""
        return _to_dict(self)

    @classmethod
    def from_dict(cls, doc: dict[str, Any]) -> RobotModel:
        return _from_dict(doc)

    @classmethod
    def load(cls, path: str | os.PathLike) -> RobotModel:
        """Read a robot JSON file; errors name the file and the offending field."""
        path = Path(path)
        try:
            text = path.read_text(encoding="utf-8")
        except OSError as e:
            raise ValueError(f"path: cannot read robot file '{path}': {e}") from e
        except UnicodeDecodeError as e:
            raise RobotModelError(f"{path}: not a UTF-8 text file (byte {e.start}: "
                                  f"{e.reason}); a robot file is JSON in UTF-8") from None
        try:
            doc = json.loads(text)
        except json.JSONDecodeError as e:
            if path.suffix.lower() == ".xml":
                raise RobotModelError(f"{path}: an .xml robot must be MJCF (a <mujoco> root) "
                                      f"or be named .urdf; this one is neither") from None
            raise RobotModelError(f"{path}: not valid JSON: {e}") from e
        try:
            return _from_dict(doc)
        except RobotModelError as e:
            raise RobotModelError(f"{path}: {e}") from e

    @classmethod
    def from_urdf(cls, path: str | os.PathLike, *, end_effectors: dict[str, str] | None = None,
                  package_dirs: Sequence[str | os.PathLike] = (), **options: Any
                  ) -> RobotModel:
        """Import a URDF file (docs/urdf.md): links are frames of the same names, moving
        joints are ``dh`` frames (mimic joints coupled), inertials point masses, sphere
        collision geometry the robot's spheres. ``end_effectors`` ``{alias: link}``
        (default: the tip links), ``package_dirs`` (folders for ``package://`` paths) and
        ``options`` (``continuous_limit``, ``merge_static``, ``require_meshes``, ``name``)
        are the fields of :class:`jwarp.importers.urdf.UrdfOptions`. For the collision
        geometry use :func:`jwarp.importers.robot.load_urdf`. ValueError naming the file
        and the element for a malformed URDF."""
        from jwarp.importers.urdf import UrdfOptions, read_urdf

        opt = UrdfOptions(end_effectors=end_effectors, package_dirs=package_dirs, **options)
        doc = read_urdf(path, opt).document
        try:
            return _from_dict(doc)
        except RobotModelError as e:
            raise RobotModelError(f"{os.fspath(path)}: imported robot is invalid: {e}") from None

    def save(self, path: str | os.PathLike) -> None:
        """Write the robot as JSON atomically (temporary file + rename)."""
        atomic_write_text(path, json.dumps(self.to_dict(), indent=1) + "\n")

    def copy(self, **changes: Any) -> RobotModel:
        """A deep copy with some top-level fields replaced (validated again)."""
        doc = self.to_dict()
        model = _from_dict(doc)
        if "spheres" in changes and "sphere_relation" not in changes:
            # edited spheres: the relation follows what it can still promise
            changes = {**changes, "sphere_relation": relation_after_edit(
                model.sphere_relation, [f.name for f in model.frames], model.spheres,
                list(changes["spheres"]))}
        for k, v in changes.items():
            if not hasattr(model, k):
                raise TypeError(f"copy: unknown field '{k}'")
            setattr(model, k, v)
        for k in list(vars(model)):  # drop cached derived data
            if k in type(model).__dict__ and isinstance(type(model).__dict__[k], cached_property):
                del model.__dict__[k]
        model.__post_init__()
        return model

    def with_dh(self, dh_table: np.ndarray, kappa: np.ndarray | None = None) -> RobotModel:
        """Copy with new DH rows ``(n_frames, 5)`` (static rows ignored) and optionally kappa."""
        dh_table = np.asarray(dh_table, np.float64)
        if dh_table.shape != (self.n_frames, 5):
            raise ValueError(f"dh_table: expected shape ({self.n_frames}, 5), got {dh_table.shape}")
        m = self.copy()
        for i, f in enumerate(m.frames):
            if f.kind == "dh":
                f.dh = dh_table[i].copy()
        if kappa is not None:
            m.kappa = _finite(kappa, "kappa", (self.n_frames, 3))
        for k in ("dh_table",):
            m.__dict__.pop(k, None)
        validate(m)
        return m

    def with_masses(self, masses: Any) -> RobotModel:
        """Copy with new values of the point masses: ``masses`` (len(self.masses),) [kg],
        one per entry of ``self.masses`` in that order (frames and centres of mass kept).
        Values must be finite and >= 0."""
        try:
            a = np.asarray(masses, np.float64)
        except (TypeError, ValueError):
            raise TypeError("masses: expected an array of numbers [kg]") from None
        if a.shape != (len(self.masses),):
            raise ValueError(f"masses: expected shape ({len(self.masses)},) (one value per "
                             f"mass entry of robot '{self.name}'), got {a.shape}")
        bad = ~np.isfinite(a) | (a < 0)
        if bad.any():
            k = int(np.nonzero(bad)[0][0])
            raise ValueError(f"masses[{k}]: must be finite and >= 0 kg, got {a[k]}")
        m = self.copy()
        for entry, v in zip(m.masses, a):
            entry.mass = float(v)
        validate(m)
        return m

    def freeze(self, values: dict[str | int, float], **options: Any) -> RobotModel:
        """A copy without the joints in ``values`` ``{joint: value}`` [rad or m], each fixed
        at its value (a gripper's fingers; mimic joints follow): :func:`freeze_joints`."""
        return freeze_joints(self, values, **options)

    def summary(self) -> str:
        """Human-readable multi-line description (used by ``jwarp info``)."""
        lines = [f"robot {self.name}: {self.n_dof} DoF, {self.n_frames} frames, "
                 f"{len(self.masses)} masses ({sum(m.mass for m in self.masses):.3f} kg), "
                 f"{len(self.spheres)} spheres, {len(self.capsules)} capsules"]
        if self.description:
            lines.append(f"  {self.description}")
        lines.append(f"  gravity {self.gravity.tolist()} m/s^2")
        lines.append("  joints:")
        for j in self.joints:
            lines.append(f"    {j.name:<16} {j.type:<9} [{j.lower:+.4f}, {j.upper:+.4f}]")
        lines.append("  frames:")
        for i, f in enumerate(self.frames):
            parent = "-" if f.parent is None else self.frames[f.parent].name
            if f.kind == "dh":
                drive = " + ".join(f"{c:g}*{self.joints[j].name}" for j, c in f.coupling) or "fixed"
                extra = f"dh={np.round(f.dh, 5).tolist()} q={drive}"
            else:
                extra = f"static p={np.round(f.transform[:3, 3], 5).tolist()}"
            lines.append(f"    {i:3d} {f.name:<14} parent={parent:<14} {extra}")
        if self.end_effectors:
            eff = ", ".join(f"{k}={self.frames[v].name}" for k, v in self.end_effectors.items())
            lines.append(f"  end-effectors: {eff}")
        lines.append(f"  self-collision frame pairs: {int(self.allowed_collision_pairs.sum()) // 2}")
        return "\n".join(lines)


# ====================================================================== helpers


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
        lim = _finite([j.lower, j.upper], f"joints[{k}].limits")
        if lim[0] > lim[1]:
            raise RobotModelError(f"joints[{k}].limits: lower {lim[0]} > upper {lim[1]}")
        j.lower, j.upper = float(lim[0]), float(lim[1])
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
            for j, c in f.coupling:
                if (isinstance(j, (bool, np.bool_)) or not isinstance(j, (int, np.integer))
                        or not 0 <= j < nj):
                    raise RobotModelError(f"{w}.joint: joint index {j!r} out of range [0, {nj})")
                coupling.append((int(j), _number(c, f"{w}.coupled.coefficients")))
                types.add(model.joints[j].type)
                driven.add(int(j))
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
        for j in lim.joints:
            if not 0 <= j < nj:
                raise RobotModelError(f"{w}.joints: index {j} out of range")
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
    for i in np.nonzero(np.any(ch != 0, axis=(1, 2)))[0]:
        if not model.frames[i].coupling:
            raise RobotModelError(f"coupling_harmonic.{model.frames[i].name}: the frame is "
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


def _from_dict(doc: Any) -> RobotModel:
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
    return RobotModel(
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


def _to_dict(m: RobotModel) -> dict[str, Any]:
    def lst(a: np.ndarray) -> list:
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



# ================================================================ frozen joints
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
        f.dh = f.dh.copy()
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
    for k in list(vars(m)):  # drop cached derived data
        if isinstance(type(m).__dict__.get(k), cached_property):
            del m.__dict__[k]
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
