"""The parts of a robot model: joints, frames, point masses, collision bodies, linear
joint limits and the self-collision rules (plain dataclasses, checked by
:func:`jwarp.model.schema.validate` when a :class:`~jwarp.model.robot.RobotModel` holds them).
Conventions: :mod:`jwarp.model.robot`."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

__all__ = ["Capsule", "Frame", "Joint", "LinearLimit", "Mass", "SelfCollision", "Sphere"]


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
    include_pairs: list[tuple[int, ...]] = field(default_factory=list)  # frame pairs
    exclude_pairs: list[tuple[int, ...]] = field(default_factory=list)
