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

The parts of a model are in :mod:`jwarp.model.parts`, its JSON schema and checks in
:mod:`jwarp.model.schema`, the freezing of joints in :mod:`jwarp.model.freeze`; every name
is also importable from here (and from :mod:`jwarp.model`).
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any, cast

import numpy as np

from jwarp.model.collision_pieces import CollisionPieces
from jwarp.model.freeze import FROZEN_NOTE, freeze_joints, frozen_joint_values
from jwarp.model.parts import Capsule, Frame, Joint, LinearLimit, Mass, SelfCollision, Sphere
from jwarp.model.schema import (
    DH_PARAMS,
    FRAME_KINDS,
    JOINT_TYPES,
    KAPPA_AXES,
    MAX_LENGTH,
    SCHEMA_NAME,
    SCHEMA_VERSION,
    RobotModelError,
    _finite,
    _topological_order,
    document_fields,
    to_document,
    validate,
)
from jwarp.model.sphere_relation import SphereRelation, relation_after_edit
from jwarp.utils.atomic import atomic_write_text

__all__ = ["DH_PARAMS", "FRAME_KINDS", "FROZEN_NOTE", "JOINT_TYPES", "KAPPA_AXES", "MAX_LENGTH",
           "SCHEMA_NAME", "SCHEMA_VERSION", "Capsule", "Frame", "Joint", "LinearLimit", "Mass",
           "RobotModel", "RobotModelError", "SelfCollision", "Sphere", "freeze_joints",
           "frozen_joint_values", "validate"]


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
    # kappa (n_frames, 3) rad/(N m); harmonic (n_dof, K, 2) [rad or m]; kappa_nonlinear
    # (n_frames,) rad/(N m)^3; coupling_harmonic (n_frames, K, 2) [rad or m]. None when
    # constructed: the default (zeros; K = 0), which __post_init__ fills in, so they are arrays
    # on every constructed model (hence the ignores of the None defaults)
    kappa: np.ndarray = None  # type: ignore[assignment]
    notes: dict[str, str] = field(default_factory=dict)
    harmonic: np.ndarray = None  # type: ignore[assignment]
    kappa_nonlinear: np.ndarray = None  # type: ignore[assignment]
    coupling_harmonic: np.ndarray = None  # type: ignore[assignment]
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
        return to_document(self)

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
                extra = f"dh={np.round(cast(np.ndarray, f.dh), 5).tolist()} q={drive}"
            else:
                extra = f"static p={np.round(cast(np.ndarray, f.transform)[:3, 3], 5).tolist()}"
            lines.append(f"    {i:3d} {f.name:<14} parent={parent:<14} {extra}")
        if self.end_effectors:
            eff = ", ".join(f"{k}={self.frames[v].name}" for k, v in self.end_effectors.items())
            lines.append(f"  end-effectors: {eff}")
        lines.append(f"  self-collision frame pairs: {int(self.allowed_collision_pairs.sum()) // 2}")
        return "\n".join(lines)



def _from_dict(doc: Any) -> RobotModel:
    """The robot of a JSON document (:func:`~jwarp.model.schema.document_fields`)."""
    return RobotModel(**document_fields(doc))
