"""Objects attached to a robot frame (a grasped part moves with the hand).

An attached object becomes part of the robot: it is covered by collision spheres fixed to
the frame it is attached to (:func:`covering_spheres`: every point of the object lies
inside a sphere, so the robot with the object is checked conservatively, never less than
the object itself), which then collide with the world and with every frame the attach
frame may collide with. :meth:`jwarp.world.sdf.World.attach` removes the object from the
world and returns the robot carrying it; :meth:`~jwarp.world.sdf.World.detach` puts it
back where the robot left it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from jwarp.model import RobotModel, Sphere

__all__ = ["Attachment", "attach_object", "covering_spheres", "sphere_table"]


def _grid_cells(half: np.ndarray, n_max: int) -> np.ndarray:
    """Cells per axis (3,) splitting a box of half extents ``half`` into about cubes, at
    most ``n_max`` cells."""
    side = max(float(np.prod(2 * half)) / n_max, 1e-30) ** (1 / 3)
    n = np.maximum(1, np.ceil(2 * half / max(side, 1e-12)).astype(int))
    while np.prod(n) > n_max:
        n[np.argmax(2 * half / n)] -= 1
        n = np.maximum(n, 1)
        if np.prod(n) <= n_max or (n == 1).all():
            break
    return n


def covering_spheres(kind: str, dims: Any = (), *, mesh: Any = None,
                     max_spheres: int = 32) -> tuple[np.ndarray, np.ndarray]:
    """Spheres (centres (k, 3) [m] in the object's frame, radii (k,) [m]) whose union
    contains the object (the conventions of :mod:`jwarp.world.shapes`); at most
    ``max_spheres``. Boxes and meshes (their bounding box) are split into near-cubes, each
    covered by the sphere through its corners; cylinders, capsules and cones into slices
    along z, each covered by a sphere on the axis."""
    if max_spheres < 1:
        raise ValueError(f"max_spheres: expected >= 1, got {max_spheres}")
    d = np.asarray(dims, np.float64).reshape(-1)
    if kind == "sphere":
        return np.zeros((1, 3)), np.array([d[0]])
    if kind in ("box", "mesh"):
        if kind == "box":
            centre, half = np.zeros(3), 0.5 * d
        else:
            v = np.asarray(mesh.vertices, np.float64)
            centre, half = 0.5 * (v.max(0) + v.min(0)), 0.5 * (v.max(0) - v.min(0))
        n = _grid_cells(half, max_spheres)
        cell = 2 * half / n
        axes = [centre[i] - half[i] + cell[i] * (np.arange(n[i]) + 0.5) for i in range(3)]
        c = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
        return c, np.full(len(c), 0.5 * float(np.linalg.norm(cell)))
    if kind in ("cylinder", "capsule", "cone"):
        length, radius = d
        m = max(1, min(max_spheres, int(np.ceil(length / max(radius, 1e-12)))))
        h = length / m
        z = -0.5 * length + h * (np.arange(m) + 0.5)
        c = np.stack([np.zeros(m), np.zeros(m), z], 1)
        if kind == "capsule":   # the segment's slice swept by a ball: radius + h / 2
            r = np.full(m, radius + 0.5 * h)
            c = np.concatenate([c, [[0, 0, -0.5 * length], [0, 0, 0.5 * length]]])
            r = np.concatenate([r, [radius, radius]])
            return c, r
        return c, np.full(m, float(np.hypot(radius, 0.5 * h)))
    raise ValueError(f"kind: an attached object must be a sphere, box, cylinder, capsule, "
                     f"cone or mesh, got {kind!r}")


@dataclass
class Attachment:
    """What :meth:`World.attach` took out of the world: the object (``kind``, ``dims``,
    ``mesh``), its ``frame`` (index) and its pose in that frame ``frame_T_object`` (4x4),
    and the indices of the spheres it added to the robot."""

    id: str
    kind: str
    dims: np.ndarray
    mesh: Any
    frame: int
    frame_T_object: np.ndarray
    spheres: tuple[int, int]
    #: the covering spheres as added: (n, 5) frame, centre (3,), radius (None: unchecked)
    added: np.ndarray | None = None

    def carried_by(self, robot: RobotModel) -> bool:
        """Whether ``robot`` carries this object: its spheres :attr:`spheres` are the
        covering spheres attach added (a robot of another attach, or the bare robot, is
        not; detach would strip other spheres)."""
        s0, s1 = self.spheres
        if len(robot.spheres) < s1 or self.frame >= robot.n_frames:
            return False
        if self.added is None:
            return True
        return bool(np.array_equal(sphere_table(robot.spheres[s0:s1]), self.added))


def sphere_table(spheres: Any) -> np.ndarray:
    """(n, 5) float64 rows ``frame, x, y, z, radius`` of ``spheres``."""
    return np.array([[s.frame, *np.asarray(s.position, np.float64), s.radius]
                     for s in spheres], np.float64).reshape(-1, 5)


def attach_object(robot: RobotModel, frame: int, frame_T_object: np.ndarray, kind: str,
                  dims: Any, mesh: Any = None, max_spheres: int = 32) -> tuple[RobotModel,
                                                                                tuple[int, int]]:
    """A copy of ``robot`` whose frame ``frame`` carries spheres covering the object (pose
    ``frame_T_object`` in the frame); returns it and the range of the new sphere indices."""
    c, r = covering_spheres(kind, dims, mesh=mesh, max_spheres=max_spheres)
    c = c @ frame_T_object[:3, :3].T + frame_T_object[:3, 3]
    start = len(robot.spheres)
    new = list(robot.spheres) + [Sphere(int(frame), ci.copy(), float(ri)) for ci, ri in zip(c, r)]
    name = robot.name if robot.name.endswith("+attached") else f"{robot.name}+attached"
    return robot.copy(spheres=new, name=name), (start, len(new))
