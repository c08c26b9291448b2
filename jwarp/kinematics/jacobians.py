"""Geometric Jacobians of a frame (or a point in it) w.r.t. the joints and w.r.t. every DH
parameter (calibration)."""

from __future__ import annotations

from typing import Any

import numpy as np
import warp as wp

from jwarp.core.arrays import (
    Batch,
    empty,
    finite_as,
    first_touch,
    is_torch,
    out_view,
    to_output,
    zeros,
)
from jwarp.core.device import DeviceModel
from jwarp.core.types import ArrayLike, DeviceLike, DTypeLike, RobotLike
from jwarp.kernels import fk as fk_kernels
from jwarp.kinematics.launch import (
    frame_rows,
    jacobian_inputs,
    point_vec,
    setup,
    small_call,
)
from jwarp.kinematics.transmission import transmission_slope, transmitted
from jwarp.model import RobotModel
from jwarp.plugins.registry import robot as get_robot


def _dh_rows(dh: Any, model: RobotModel, batch: Batch, t: DeviceModel,
             validate: bool) -> tuple[wp.array, int] | None:
    """The ``dh`` argument as (device rows (B or 1, n_frames, 5), batch stride): None for
    the nominal rows; a contiguous Warp array of the computing dtype on the computing device
    is used as is (no upload: a caller evaluating several frames at the same rows uploads
    them once), checked finite when ``validate``; anything else is uploaded
    (:func:`~jwarp.kinematics.launch.frame_rows`)."""
    if dh is None:
        return None
    if not (isinstance(dh, wp.array) and dh.dtype == t.scalar and dh.device == t.device
            and dh.is_contiguous):
        return frame_rows(dh, model, batch, t, "dh", 5)
    n = model.n_frames
    shape = tuple(dh.shape)
    if shape[-2:] != (n, 5) or (len(shape) > 2 and shape[:-2] != tuple(batch.lead_shape)):
        raise ValueError(f"dh: expected shape (n_frames={n}, 5) or (batch..., {n}, 5) with "
                         f"q's batch dims {tuple(batch.lead_shape)}, got {shape}")
    if validate:
        a = dh.numpy()
        finite_as(a, a.dtype, "dh")
    if len(shape) == 2:
        return dh.reshape((1, n, 5)), 0
    return (dh if len(shape) == 3 else dh.reshape((-1, n, 5))), 1


def _scaled(jac: Any, slope: np.ndarray) -> Any:
    """Joint Jacobian (..., 6, n_dof) with its columns times ``slope`` (..., n_dof), in
    place where possible, in the kind of ``jac``."""
    if is_torch(jac):
        import torch

        jac.mul_(torch.as_tensor(slope[..., None, :], dtype=jac.dtype, device=jac.device))
        return jac
    if isinstance(jac, wp.array):
        a = jac.numpy()
        jac.assign((a * slope.reshape(a.shape[:-2] + a.shape[-1:])[..., None, :]).astype(a.dtype))
        return jac
    jac *= slope[..., None, :]
    return jac


def jacobian(robot: RobotLike, q: ArrayLike, frame: int | str, *,
             point: ArrayLike | None = None, dh: ArrayLike | None = None,
             device: DeviceLike = None, dtype: DTypeLike = None, validate: bool = True,
             out: ArrayLike | None = None) -> Any:
    """Geometric Jacobian of a frame (or of a point fixed in it) w.r.t. the joints.

    Returns (..., 6, n_dof): rows [linear velocity; angular velocity] in the base frame.
    Coupled passive joints are folded into the columns of the joints that drive them.
    ``point`` (3,) [m] is in the frame's coordinates (default: its origin).
    ``dh``: DH rows (n_frames, 5) or (..., n_frames, 5) instead of the nominal ones; a
    contiguous Warp array of the computing dtype on the device is used without a copy.
    ``out``: optional array (..., 6, n_dof) (numpy, torch or Warp) in the computing dtype
    the Jacobians are written to, and returned (as for :func:`~jwarp.kinematics.fk.fk`).
    Small calls reuse per-process buffers and a recorded launch, as
    :func:`~jwarp.kinematics.fk.fk` describes (same thread-safety). A robot with joint
    transmission errors (``harmonic``) is evaluated at ``q + dq(q)`` and its columns are
    scaled by ``dq'/dq`` (:mod:`jwarp.kinematics.transmission`).
    """
    model = get_robot(robot)
    if model.has_harmonic:   # the kernels at the links' values, with the robot's own tables
        return _scaled(link_jacobian(model, transmitted(model, q), frame, point=point, dh=dh,
                                     device=device, dtype=dtype, validate=validate, out=out),
                       transmission_slope(model, q))
    return link_jacobian(model, q, frame, point=point, dh=dh, device=device, dtype=dtype,
                         validate=validate, out=out)


def link_jacobian(robot: RobotModel, q_link: Any, frame: int | str, *, point: Any = None,
                  dh: Any = None, device: DeviceLike = None, dtype: DTypeLike = None,
                  validate: bool = True, out: Any = None) -> Any:
    """:func:`jacobian` w.r.t. the joint values the links see, ``q_link`` (transmission
    errors already applied; no ``dq'/dq`` factor): the same as :func:`jacobian` for a
    robot without transmission errors."""
    q = q_link
    if dh is None:
        res = small_call("jacobian", robot, q, device, dtype, validate, out, frame, point)
        if res is not None:
            return res
    model, batch, t = setup(robot, q, device, dtype, validate)
    fi = model.frame_index(frame)
    pt = point_vec(point, t)
    k = fk_kernels.kernels(t.scalar)
    rows = _dh_rows(dh, model, batch, t, validate)
    tail = (6, model.n_dof)
    jac = None if out is None else out_view(out, batch, tail, t.scalar, t.device)
    done = None
    if jac is None:
        jac = empty((batch.size,) + tail, t.scalar, t.device)
        done = first_touch(jac)
    wp.launch(k.jacobian, dim=batch.size, inputs=jacobian_inputs(t, batch.array, rows, pt, fi),
              outputs=[jac], device=t.device)
    if done is not None:
        done()
    return to_output(jac, batch, tail, out=out)


def jacobian_dh(robot: RobotLike, q: ArrayLike, frame: int | str, *,
                point: ArrayLike | None = None, dh: ArrayLike | None = None,
                device: DeviceLike = None, dtype: DTypeLike = None, validate: bool = True) -> Any:
    """Jacobian of a frame's pose (or a point in it) w.r.t. every DH parameter.

    Returns (..., 6, n_frames, 5): rows [linear; angular] in the base frame, columns the
    DH rows [d, theta, r, alpha, beta] of each frame (zero for frames off the chain and
    for static frames). ``dh`` as for :func:`jacobian` (a Warp array on the device is used
    without a copy: evaluating several frames at the same rows uploads them once).
    Transmission errors as in :func:`jacobian` (at ``q + dq(q)``; DH columns need no factor).
    """
    model = get_robot(robot)
    model, batch, t = setup(model, transmitted(model, q), device, dtype, validate)
    fi = model.frame_index(frame)
    pt = point_vec(point, t)
    k = fk_kernels.kernels(t.scalar)
    rows = _dh_rows(dh, model, batch, t, validate)
    jac = zeros((batch.size, 6, model.n_frames, 5), t.scalar, t.device)
    done = first_touch(jac)
    wp.launch(k.jacobian_dh, dim=batch.size, inputs=jacobian_inputs(t, batch.array, rows, pt, fi),
              outputs=[jac], device=t.device)
    if done is not None:
        done()
    return to_output(jac, batch, (6, model.n_frames, 5))


# ------------------------------------------------------------------ elastic
