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
import tempfile
from pathlib import Path
from typing import Any, Iterable

import numpy as np

from jwarp.model import RobotModel
from jwarp.registry import robot as get_robot

#: timeline on which :func:`save_robot_rrd` logs the configurations
TIMELINE = "config"

_RIGID_COLOR = (150, 160, 175)
_ELASTIC_COLOR = (240, 140, 40)
_SPHERE_COLOR = (80, 140, 220, 110)
_CAPSULE_COLOR = (90, 190, 120, 140)


def _rerun() -> Any:
    try:
        import rerun as rr
    except ImportError as e:  # pragma: no cover - depends on the machine
        raise ImportError("jwarp.viz needs rerun-sdk: pip install rerun-sdk") from e
    return rr


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


def log_robot(rec: Any, robot: Any, frames: Any, path: str = "robot", spheres: bool = True,
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
    rr = _rerun()
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


def save_robot_rrd(robot: Any, q_list: Any, path: str | os.PathLike,
                   elastic_kappa: Any = None, *, lam: float = 1.0, max_iter: int = 10,
                   application_id: str = "jwarp") -> Path:
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

    Returns:
        The path written. FK runs in float64 on the CPU.
    """
    from jwarp import kinematics

    rr = _rerun()
    model = get_robot(robot)
    q = _q_batch(model, q_list)
    target = Path(path)
    folder = target.parent if str(target.parent) else Path(".")
    if not folder.is_dir():
        raise ValueError(f"path: folder '{folder}' does not exist")
    frames = np.asarray(kinematics.fk(model, q, device="cpu", dtype=np.float64))
    elastic = None
    if elastic_kappa is not None:
        elastic = kinematics.fk_elastic(model, q, elastic_kappa, lam=lam, max_iter=max_iter,
                                        device="cpu", dtype=np.float64)

    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=folder)
    os.close(fd)
    try:
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp creates 0600; give the usual file mode
        rec = rr.RecordingStream(application_id)
        rec.save(tmp)
        rec.log("/", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
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
        rec.flush()
        rec.disconnect()
        os.replace(tmp, target)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return target
