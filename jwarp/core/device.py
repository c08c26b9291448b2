"""Device tables of a robot (the *Model* the kernels read), per device and scalar type.

:func:`tables` turns a :class:`~jwarp.model.RobotModel` into Warp arrays once and
caches them (keyed by the model object, device and dtype).
"""

from __future__ import annotations

import dataclasses
import weakref
from dataclasses import dataclass
from typing import Any

import numpy as np
import warp as wp

from jwarp.kernels.fk import kernels as fk_kernels
from jwarp.model import RobotModel

#: the fields of ``kernels.fk.FrameTables`` (attributes of :class:`KinematicsTables`)
_FRAME_FIELDS = ("order", "parent", "is_dh", "prismatic", "fixed_rot", "fixed_pos", "dh0",
                 "trig", "cpl_start", "cpl_joint", "cpl_coef")

_SCALARS = {np.dtype(np.float32): wp.float32, np.dtype(np.float64): wp.float64}


def scalar_type(dtype: object) -> type:
    """Warp scalar for ``dtype`` (numpy dtype, 'float32'/'float64', or a Warp scalar)."""
    if dtype is wp.float32 or dtype is wp.float64:
        return dtype  # type: ignore[return-value]
    try:
        key = np.dtype(dtype)
    except TypeError as e:
        raise TypeError(f"dtype: expected float32 or float64, got {dtype!r}") from e
    if key not in _SCALARS:
        raise TypeError(f"dtype: expected float32 or float64, got {key}")
    return _SCALARS[key]


def numpy_dtype(scalar: type) -> np.dtype:
    return np.dtype(np.float32) if scalar == wp.float32 else np.dtype(np.float64)


@dataclass
class KinematicsTables:
    """Frame, coupling and mass tables of one robot on one device (see kernels/fk.py)."""

    robot: RobotModel
    device: wp.Device
    scalar: type
    order: wp.array
    parent: wp.array
    is_dh: wp.array
    prismatic: wp.array
    fixed_rot: wp.array
    fixed_pos: wp.array
    dh0: wp.array
    dh0_3d: wp.array  # (1, n_frames, 5) view used as the shared rho0
    trig: wp.array  # (n_frames,) vec4 [cos alpha, sin alpha, cos beta, sin beta]
    cpl_start: wp.array
    cpl_joint: wp.array
    cpl_coef: wp.array
    mass: wp.array
    mass_com: wp.array
    dh_info: wp.array  # (n_dh,) vec4i [position in order, frame, subtree end, parent] of DH frames
    static_idx: wp.array  # (n_static,) int32 static frame indices

    @property
    def frame_struct(self) -> Any:
        """The frame tables as one kernel argument (``kernels.fk.FrameTables``; cached)."""
        st = self.__dict__.get("_frame_struct")
        if st is None:
            st = fk_kernels(self.scalar).FrameTables()
            for name in _FRAME_FIELDS:
                setattr(st, name, getattr(self, name))
            self.__dict__["_frame_struct"] = st
        return st

    def chain(self, frame: int) -> wp.array:
        """Frames from the root to ``frame`` as an int32 device array (cached)."""
        cache = self.__dict__.setdefault("_chains", {})
        if frame not in cache:
            cache[frame] = wp.array(np.asarray(self.robot.ancestors(frame), np.int32),
                                    dtype=wp.int32, device=self.device)
        return cache[frame]


_CACHE: "weakref.WeakKeyDictionary[RobotModel, dict]" = weakref.WeakKeyDictionary()


def fixed_parts(robot: RobotModel) -> tuple[np.ndarray, np.ndarray]:
    """Nominal ``Rot_y(beta) Rot_x(alpha)`` (n, 3, 3) and ``r Rot_y(beta) e_x`` (n, 3) of DH
    frames; rotation/translation of static frames."""
    n = robot.n_frames
    rot = np.zeros((n, 3, 3))
    pos = np.zeros((n, 3))
    dh = robot.dh_table
    static = robot.static_transforms
    for i, f in enumerate(robot.frames):
        if f.kind == "dh":
            _, _, r, a, b = dh[i]
            ca, sa, cb, sb = np.cos(a), np.sin(a), np.cos(b), np.sin(b)
            rot[i] = [[cb, sb * sa, sb * ca], [0.0, ca, -sa], [-sb, cb * sa, cb * ca]]
            pos[i] = r * rot[i][:, 0]
        else:
            rot[i] = static[i, :3, :3]
            pos[i] = static[i, :3, 3]
    return rot, pos


def frame_mass_model(robot: RobotModel, values: np.ndarray | None = None
                     ) -> tuple[np.ndarray, np.ndarray]:
    """The mass model the elastic kernel reads: total point mass per frame (n_frames,) [kg]
    and its centre of mass (n_frames, 3) [m] in frame coordinates (several entries on one
    frame are merged). ``values`` (len(robot.masses),) [kg] replaces the entries' masses
    (calibration); default the robot's own."""
    n = robot.n_frames
    if values is None:
        values = np.array([m.mass for m in robot.masses], np.float64)
    values = np.asarray(values, np.float64)
    if values.shape != (len(robot.masses),):
        raise ValueError(f"values: expected shape ({len(robot.masses)},), got {values.shape}")
    mass = np.zeros(n)
    first_moment = np.zeros((n, 3))
    for m, v in zip(robot.masses, values):
        mass[m.frame] += v
        first_moment[m.frame] += v * np.asarray(m.com, np.float64)
    com = np.divide(first_moment, mass[:, None], out=np.zeros_like(first_moment),
                    where=mass[:, None] != 0)
    return mass, com


def with_frame_masses(t: KinematicsTables, mass: np.ndarray, com: np.ndarray) -> KinematicsTables:
    """A copy of the tables ``t`` with another mass model: per-frame mass (n_frames,) [kg]
    and centre of mass (n_frames, 3) [m] (see :func:`frame_mass_model`). Only these two
    small arrays are uploaded; every other table is shared with ``t``. The copy is not
    cached (e.g. one per calibration step)."""
    n = t.robot.n_frames
    mass = np.asarray(mass, np.float64)
    com = np.asarray(com, np.float64)
    if mass.shape != (n,) or com.shape != (n, 3):
        raise ValueError(f"mass, com: expected shapes ({n},) and ({n}, 3), got {mass.shape} "
                         f"and {com.shape}")
    npdt = numpy_dtype(t.scalar)
    return dataclasses.replace(
        t, mass=wp.array(mass.astype(npdt), dtype=t.scalar, device=t.device),
        mass_com=wp.array(com.astype(npdt), dtype=t.mass_com.dtype, device=t.device))


def _dh_info(robot: RobotModel) -> np.ndarray:
    """(n_dh, 4) int32 rows [k, i, subtree_end[k], parent[i]] of the DH frames i at positions
    k of the topological order (one table load per frame in the elastic torque pass)."""
    order = robot.topological_order
    ks = np.nonzero(robot.is_dh[order])[0]
    i = order[ks]
    return np.stack([ks, i, robot.subtree_end[ks], robot.parents[i]], 1).astype(np.int32).reshape(-1, 4)


def tables(robot: RobotModel, device: object = None, dtype: object = np.float32) -> KinematicsTables:
    """Device tables of ``robot`` on ``device`` in ``dtype`` (cached)."""
    scalar = scalar_type(dtype)
    dev = wp.get_device(device)
    per_robot = _CACHE.setdefault(robot, {})
    key = (str(dev), scalar.__name__)
    if key in per_robot:
        return per_robot[key]
    npdt = numpy_dtype(scalar)
    n = robot.n_frames
    vec3 = wp.types.vector(3, scalar)
    mat33 = wp.types.matrix((3, 3), scalar)

    def arr(a: np.ndarray, dt: object) -> wp.array:
        return wp.array(a, dtype=dt, device=dev)

    cpl_start = np.zeros(n + 1, np.int32)
    cpl_joint: list[int] = []
    cpl_coef: list[float] = []
    for i, f in enumerate(robot.frames):
        for j, c in f.coupling:
            cpl_joint.append(j)
            cpl_coef.append(c)
        cpl_start[i + 1] = len(cpl_joint)
    mass, com = frame_mass_model(robot)
    rot, pos = fixed_parts(robot)
    dh0 = robot.dh_table.astype(npdt)
    t = KinematicsTables(
        robot=robot, device=dev, scalar=scalar,
        order=arr(robot.topological_order, wp.int32),
        parent=arr(robot.parents, wp.int32),
        is_dh=arr(robot.is_dh.astype(np.int32), wp.int32),
        prismatic=arr(robot.frame_is_prismatic.astype(np.int32), wp.int32),
        fixed_rot=arr(rot.astype(npdt), mat33),
        fixed_pos=arr(pos.astype(npdt), vec3),
        dh0=arr(dh0, scalar),
        dh0_3d=arr(dh0[None], scalar),
        trig=arr(np.stack([np.cos(robot.dh_table[:, 3]), np.sin(robot.dh_table[:, 3]),
                           np.cos(robot.dh_table[:, 4]), np.sin(robot.dh_table[:, 4])], 1).astype(npdt),
                 wp.types.vector(4, scalar)),
        cpl_start=arr(cpl_start, wp.int32),
        cpl_joint=arr(np.array(cpl_joint or [0], np.int32), wp.int32),
        cpl_coef=arr(np.array(cpl_coef or [0.0], npdt), scalar),
        mass=arr(mass.astype(npdt), scalar),
        mass_com=arr(com.astype(npdt), vec3),
        dh_info=arr(_dh_info(robot), wp.vec4i),
        static_idx=arr(np.nonzero(~robot.is_dh.astype(bool))[0].astype(np.int32), wp.int32),
    )
    per_robot[key] = t
    return t
