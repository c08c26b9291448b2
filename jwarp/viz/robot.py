"""Streaming robots to rerun (https://rerun.io): frames, skeleton, collision bodies.

``rerun`` is imported lazily inside the functions, so jwarp imports (and computes) on
machines without ``rerun-sdk``; only these functions need it.

Entity layout written by :func:`log_robot` under ``path`` (default ``"robot"``)::

    robot/frames/<frame>   Transform3D (world pose of the frame) + TransformAxes3D
    robot/skeleton         LineStrips3D from every frame's origin to its parent's
    robot/spheres          Points3D with radii: the collision spheres in world coordinates
    robot/capsules         Capsules3D: the collision capsules in world coordinates

:func:`save_robot_rrd` logs one time step per configuration on the timeline ``config``
and, with ``elastic_kappa``, the elastic frames under ``elastic/`` plus the sag of every
end-effector (``elastic/sag_mm/<end_effector>``, scalar in mm).
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from jwarp.core.types import ArrayLike, RobotLike
from jwarp.model import RobotModel
from jwarp.plugins.registry import robot as get_robot
from jwarp.utils.atomic import AtomicFile
from jwarp.viz.recording import atomic_recording, rerun_module

if TYPE_CHECKING:
    from jwarp.model.measurement import Measurement
    from jwarp.world.sdf import World

#: timeline on which :func:`save_robot_rrd` logs the configurations
TIMELINE = "config"

_RIGID_COLOR = (150, 160, 175)
_ELASTIC_COLOR = (240, 140, 40)
_SPHERE_COLOR = (80, 140, 220, 110)
_CAPSULE_COLOR = (90, 190, 120, 140)


def _frames_array(robot: RobotModel, frames: Any) -> np.ndarray:
    if hasattr(frames, "detach"):  # torch
        frames = frames.detach().cpu().numpy()
    elif hasattr(frames, "numpy") and not isinstance(frames, np.ndarray):  # warp
        frames = frames.numpy()
    f = np.asarray(frames, dtype=np.float64)
    if f.shape != (robot.n_frames, 4, 4):
        raise ValueError(f"frames: expected shape (n_frames={robot.n_frames}, 4, 4) for robot "
                         f"'{robot.name}', got {f.shape}")
    if not np.all(np.isfinite(f)):
        raise ValueError("frames: contains NaN or inf")
    return f


def object_meshes(world: World) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """The exact objects of ``world`` as triangle meshes in the world frame, for display:
    ``[(id, vertices (V, 3), faces (F, 3))]`` (a plane as a 4 x 4 m tile)."""
    import trimesh

    shapes = getattr(world, "shapes", None)
    out: list[tuple[str, np.ndarray, np.ndarray]] = []
    if shapes is None:
        return out
    for oid in shapes.ids:
        kind, dims, mesh = shapes.spec(oid)
        if kind == "box":
            m = trimesh.creation.box(extents=dims)
        elif kind == "sphere":
            m = trimesh.creation.icosphere(subdivisions=2, radius=dims[0])
        elif kind == "cylinder":
            m = trimesh.creation.cylinder(radius=dims[1], height=dims[0])
        elif kind == "capsule":
            m = trimesh.creation.capsule(height=dims[0], radius=dims[1])
        elif kind == "cone":
            m = trimesh.creation.cone(radius=dims[1], height=dims[0])
            m.apply_translation([0.0, 0.0, -0.5 * dims[0]])   # base at -length/2
        elif kind == "plane":
            m = trimesh.creation.box(extents=[4.0, 4.0, 1e-3])
            m.apply_translation([0.0, 0.0, -5e-4])
        else:
            m = trimesh.Trimesh(np.asarray(mesh.vertices), np.asarray(mesh.faces), process=False)
        m.apply_transform(shapes.pose(oid))
        out.append((oid, np.asarray(m.vertices, np.float32), np.asarray(m.faces, np.int32)))
    return out


def world_spheres(robot: RobotModel, frames: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Collision spheres in world coordinates: centres (n, 3) [m] and radii (n,) [m]."""
    f = _frames_array(robot, frames)
    idx, pos, rad = robot.sphere_arrays()
    if len(idx) == 0:
        return np.zeros((0, 3)), np.zeros(0)
    centres = np.einsum("nij,nj->ni", f[idx, :3, :3], pos) + f[idx, :3, 3]
    return centres, rad


def world_capsules(robot: RobotModel, frames: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Collision capsules in world coordinates: p0 (n, 3), p1 (n, 3), radii (n,) [m]."""
    f = _frames_array(robot, frames)
    if not robot.capsules:
        return np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0)
    idx = np.array([c.frame for c in robot.capsules])
    p0 = np.array([c.p0 for c in robot.capsules], np.float64)
    p1 = np.array([c.p1 for c in robot.capsules], np.float64)
    rad = np.array([c.radius for c in robot.capsules], np.float64)
    rot, trans = f[idx, :3, :3], f[idx, :3, 3]
    return (np.einsum("nij,nj->ni", rot, p0) + trans,
            np.einsum("nij,nj->ni", rot, p1) + trans, rad)


def _z_to(d: np.ndarray) -> np.ndarray:
    """Quaternions (x, y, z, w) rotating +z onto the unit vectors ``d`` (n, 3)."""
    q = np.zeros((len(d), 4))
    q[:, 0] = -d[:, 1]          # cross((0, 0, 1), d)
    q[:, 1] = d[:, 0]
    q[:, 3] = 1.0 + d[:, 2]
    flip = q[:, 3] < 1e-9       # d == -z: half turn about x
    q[flip] = (1.0, 0.0, 0.0, 0.0)
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def log_robot(rec: Any, robot: RobotLike, frames: Any, path: str = "robot", spheres: bool = True,
              *, axis_length: float = 0.08, color: Iterable[int] = _RIGID_COLOR) -> None:
    """Log one configuration of a robot to the rerun recording stream ``rec``.

    Args:
        rec: a ``rerun.RecordingStream`` (set its time before calling).
        robot: robot name or RobotModel.
        frames: world transforms (n_frames, 4, 4) [m], e.g. ``jwarp.kinematics.fk(...)``.
        path: entity path prefix.
        spheres: also log the collision spheres and capsules.
        axis_length: length of the drawn frame axes [m].
        color: RGB of the skeleton lines.
    """
    rr = rerun_module()
    model = get_robot(robot)
    f = _frames_array(model, frames)
    path = path.strip("/") or "robot"
    for i, name in enumerate(model.frame_names):
        rec.log(f"{path}/frames/{name}",
                rr.Transform3D(translation=f[i, :3, 3], mat3x3=f[i, :3, :3]),
                rr.TransformAxes3D(axis_length))
    strips = [[f[int(p), :3, 3], f[i, :3, 3]] for i, p in enumerate(model.parents) if p >= 0]
    if strips:
        rec.log(f"{path}/skeleton",
                rr.LineStrips3D(strips, radii=0.006, colors=[tuple(color)] * len(strips)))
    if not spheres:
        return
    centres, radii = world_spheres(model, f)
    if len(radii):
        sphere_frames = [model.frame_names[s.frame] for s in model.spheres]
        rec.log(f"{path}/spheres",
                rr.Points3D(centres, radii=radii, colors=[_SPHERE_COLOR] * len(radii),
                            labels=sphere_frames, show_labels=False))
    p0, p1, rad = world_capsules(model, f)
    if len(rad):
        d = p1 - p0
        length = np.linalg.norm(d, axis=1)
        unit = np.where(length[:, None] > 0, d / np.maximum(length, 1e-12)[:, None], [0, 0, 1])
        rec.log(f"{path}/capsules",
                rr.Capsules3D(lengths=length, radii=rad, translations=p0,
                              quaternions=[rr.Quaternion(xyzw=q) for q in _z_to(unit)],
                              colors=[_CAPSULE_COLOR] * len(rad)))


def _q_batch(model: RobotModel, q_list: Any) -> np.ndarray:
    try:
        q = np.asarray(q_list, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise ValueError("q_list: expected a list of joint vectors (numbers)") from e
    if q.ndim == 1:
        q = q[None]
    if q.ndim != 2 or q.shape[1] != model.n_dof or q.shape[0] == 0:
        raise ValueError(f"q_list: expected shape (n_configs, {model.n_dof}) for robot "
                         f"'{model.name}', got {np.shape(q_list)}")
    if not np.all(np.isfinite(q)):
        raise ValueError("q_list: contains NaN or inf")
    return q


def save_robot_rrd(robot: RobotLike, q_list: Any, path: str | os.PathLike,
                   elastic_kappa: Any = None, *, lam: float = 1.0, max_iter: int = 10,
                   application_id: str = "jwarp", option: str = "path") -> Path:
    """Compute FK for every configuration and write a rerun recording (.rrd) atomically.

    Args:
        robot: robot name or RobotModel.
        q_list: joint vectors (n_configs, n_dof) [rad or m]; one rerun time step
            (timeline ``config``) per configuration.
        path: the .rrd file to write (its folder must exist). Written to a temporary file
            in the same folder, then renamed, so readers never see a partial file.
        elastic_kappa: if given, also log the elastic frames (``fk_elastic`` with this
            kappa [rad/(N m)]: scalar, [alpha, beta, theta] or (n_frames, 3)) under
            ``elastic/`` and each end-effector's sag under ``elastic/sag_mm/``.
        lam, max_iter: passed to :func:`jwarp.kinematics.fk_elastic`.
        option: the name errors give ``path`` (e.g. the CLI's ``--save``).

    Returns:
        The path written. FK runs in float64 on the CPU.
    """
    from jwarp import kinematics

    rr = rerun_module()
    model = get_robot(robot)
    q = _q_batch(model, q_list)
    target = Path(path)
    AtomicFile(target, option=option).discard()  # folder missing/unwritable: before the work
    frames = np.asarray(kinematics.fk(model, q, device="cpu", dtype=np.float64))
    elastic = None
    if elastic_kappa is not None:
        elastic = kinematics.fk_elastic(model, q, elastic_kappa, lam=lam, max_iter=max_iter,
                                        device="cpu", dtype=np.float64)

    with atomic_recording(target, application_id, option=option) as rec:
        rec.log("robot/description", rr.TextDocument(model.summary()), static=True)
        for k in range(len(q)):
            rec.set_time(TIMELINE, sequence=k)
            log_robot(rec, model, frames[k], path="robot")
            if elastic is not None:
                ef = np.asarray(elastic.frames[k])
                log_robot(rec, model, ef, path="elastic", spheres=False, color=_ELASTIC_COLOR)
                for ee, fi in model.end_effectors.items():
                    sag = 1e3 * np.linalg.norm(ef[fi, :3, 3] - frames[k, fi, :3, 3])
                    rec.log(f"elastic/sag_mm/{ee}", rr.Scalars(sag))
    return target


#: timeline on which :func:`save_calibration_rrd` logs the samples
SAMPLE_TIMELINE = "sample"


def _pose(params: Any, p: np.ndarray, prefix: str) -> np.ndarray | None:
    """4x4 pose of the measurement parameters ``<prefix>_px .. _rz`` (None if absent)."""
    from scipy.spatial.transform import Rotation

    names = list(params.names)
    keys = [f"{prefix}_{k}" for k in ("px", "py", "pz", "rx", "ry", "rz")]
    if not all(k in names for k in keys):
        return None
    v = np.array([p[names.index(k)] for k in keys])
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(v[3:]).as_matrix()
    T[:3, 3] = v[:3]
    return T


def save_calibration_rrd(path: str | os.PathLike, robot: RobotLike, measurement: Measurement, p: Any,
                         q: ArrayLike, y: Any, meta: Mapping[str, Any] | None = None, *,
                         p_before: Any = None, robot_before: Any = None,
                         application_id: str = "jwarp-calibration") -> Path:
    """Write a rerun recording of a calibration: one time step per sample (timeline
    ``sample``) with the calibrated robot, the measured and predicted observations and the
    per-sample errors after (and before) calibration.

    Args:
        robot, p: calibrated robot and measurement parameters (P,).
        q (S, n_dof), y (S, m), meta: the samples.
        p_before, robot_before: the start (nominal robot, initial parameters) for the
            ``error/before`` series.

    Cartesian markers are drawn in the robot base frame (measured ones mapped through the
    calibrated tracker pose), image points in an ``image`` 2D view, relative positions from
    the first end-effector; every plugin gets ``error/after/<group>`` scalars [mm or px].
    """
    from jwarp.calibration.estimate.result import (
        group_norms,
        model_frames,
        observation_groups,
    )

    rr = rerun_module()
    model = get_robot(robot)
    qa = np.asarray(q, np.float64)
    ya = np.asarray(y, np.float64)
    if qa.ndim != 2 or qa.shape[1] != model.n_dof:
        raise ValueError(f"q: expected shape (S, {model.n_dof}), got {qa.shape}")
    if ya.shape != (qa.shape[0], measurement.n_obs):
        raise ValueError(f"y: expected shape ({qa.shape[0]}, {measurement.n_obs}), got {ya.shape}")
    p = np.asarray(p, np.float64)
    md = None if not meta else {k: np.asarray(v) for k, v in meta.items()}
    frames = model_frames(model, qa)
    pred = np.asarray(measurement.predict(frames, p, md))
    groups = observation_groups(measurement)
    scale = 1000.0 if measurement.unit == "m" else 1.0
    unit = "mm" if measurement.unit == "m" else measurement.unit
    err_after = group_norms(pred - ya, groups) * scale
    err_before = None
    if p_before is not None:
        mb = get_robot(robot_before) if robot_before is not None else model
        fb = model_frames(mb, qa)
        pb = np.asarray(measurement.predict(fb, np.asarray(p_before, np.float64), md))
        err_before = group_norms(pb - ya, groups) * scale
    T_tracker = _pose(measurement.params, p, "tracker") if measurement.name == "cartesian" else None
    with atomic_recording(path, application_id) as rec:
        rec.log("description", rr.TextDocument(
            f"calibration of '{model.name}' with '{measurement.name}': {len(qa)} samples; "
            f"errors in {unit}"), static=True)
        for s in range(len(qa)):
            rec.set_time(SAMPLE_TIMELINE, sequence=s)
            log_robot(rec, model, frames[s], path="robot", spheres=False)
            if measurement.name == "cartesian" and T_tracker is not None:
                meas_pts = ya[s].reshape(-1, 3) @ T_tracker[:3, :3].T + T_tracker[:3, 3]
                pred_pts = pred[s].reshape(-1, 3) @ T_tracker[:3, :3].T + T_tracker[:3, 3]
            elif measurement.name == "relative":
                base = frames[s, measurement.frames[0], :3, 3]
                meas_pts = ya[s].reshape(-1, 3) + base
                pred_pts = pred[s].reshape(-1, 3) + base
            else:
                meas_pts = pred_pts = None
            if meas_pts is not None:
                rec.log("markers/measured", rr.Points3D(meas_pts, radii=0.01,
                                                        colors=[(230, 60, 60)] * len(meas_pts)))
                rec.log("markers/predicted", rr.Points3D(pred_pts, radii=0.01,
                                                         colors=[(60, 200, 90)] * len(pred_pts)))
                rec.log("markers/residual", rr.Arrows3D(origins=pred_pts,
                                                        vectors=meas_pts - pred_pts))
            if measurement.unit == "px":
                rec.log("image/measured", rr.Points2D(ya[s].reshape(-1, 2), radii=3.0,
                                                      colors=[(230, 60, 60)] * (ya.shape[1] // 2)))
                rec.log("image/predicted", rr.Points2D(pred[s].reshape(-1, 2), radii=3.0,
                                                       colors=[(60, 200, 90)] * (ya.shape[1] // 2)))
            for g, (name, _) in enumerate(groups):
                rec.log(f"error/after/{name}", rr.Scalars(float(err_after[s, g])))
                if err_before is not None:
                    rec.log(f"error/before/{name}", rr.Scalars(float(err_before[s, g])))
    return Path(path)
