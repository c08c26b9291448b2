"""Geometric Jacobians of a frame (or a point in it) w.r.t. the joints and w.r.t. every DH
parameter (calibration)."""

from __future__ import annotations

from typing import Any

import warp as wp

from jwarp.core.arrays import empty, first_touch, out_view, to_output, zeros
from jwarp.kernels import fk as fk_kernels
from jwarp.kinematics.launch import frame_rows, jacobian_inputs, point_vec, setup, small_call


def jacobian(robot: Any, q: Any, frame: int | str, *, point: Any = None, dh: Any = None,
             device: Any = None, dtype: Any = None, validate: bool = True,
             out: Any = None) -> Any:
    """Geometric Jacobian of a frame (or of a point fixed in it) w.r.t. the joints.

    Returns (..., 6, n_dof): rows [linear velocity; angular velocity] in the base frame.
    Coupled passive joints are folded into the columns of the joints that drive them.
    ``point`` (3,) [m] is in the frame's coordinates (default: its origin).
    ``out``: optional array (..., 6, n_dof) (numpy, torch or Warp) in the computing dtype
    the Jacobians are written to, and returned (as for :func:`~jwarp.kinematics.fk.fk`).
    Small calls reuse per-process buffers and a recorded launch, as
    :func:`~jwarp.kinematics.fk.fk` describes (same thread-safety).
    """
    if dh is None:
        res = small_call("jacobian", robot, q, device, dtype, validate, out, frame, point)
        if res is not None:
            return res
    model, batch, t = setup(robot, q, device, dtype, validate)
    fi = model.frame_index(frame)
    pt = point_vec(point, t)
    k = fk_kernels.kernels(t.scalar)
    rows = None if dh is None else frame_rows(dh, model, batch, t, "dh", 5)
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


def jacobian_dh(robot: Any, q: Any, frame: int | str, *, point: Any = None, dh: Any = None,
                device: Any = None, dtype: Any = None, validate: bool = True) -> Any:
    """Jacobian of a frame's pose (or a point in it) w.r.t. every DH parameter.

    Returns (..., 6, n_frames, 5): rows [linear; angular] in the base frame, columns the
    DH rows [d, theta, r, alpha, beta] of each frame (zero for frames off the chain and
    for static frames).
    """
    model, batch, t = setup(robot, q, device, dtype, validate)
    fi = model.frame_index(frame)
    pt = point_vec(point, t)
    k = fk_kernels.kernels(t.scalar)
    rows = None if dh is None else frame_rows(dh, model, batch, t, "dh", 5)
    jac = zeros((batch.size, 6, model.n_frames, 5), t.scalar, t.device)
    done = first_touch(jac)
    wp.launch(k.jacobian_dh, dim=batch.size, inputs=jacobian_inputs(t, batch.array, rows, pt, fi),
              outputs=[jac], device=t.device)
    if done is not None:
        done()
    return to_output(jac, batch, (6, model.n_frames, 5))


# ------------------------------------------------------------------ elastic
