"""Geometric Jacobians of a frame (or a point in it) w.r.t. the joints and w.r.t. every DH
parameter (calibration)."""

from __future__ import annotations

from typing import Any

import numpy as np
import warp as wp

from jwarp.core.arrays import (finite_as, real_array,
                               to_output)
from jwarp.core.device import KinematicsTables, numpy_dtype
from jwarp.kernels import fk as fk_kernels
from jwarp.kinematics.launch import frame_rows, setup


def jacobian(robot: Any, q: Any, frame: int | str, *, point: Any = None, dh: Any = None,
             device: Any = None, dtype: Any = None, validate: bool = True) -> Any:
    """Geometric Jacobian of a frame (or of a point fixed in it) w.r.t. the joints.

    Returns (..., 6, n_dof): rows [linear velocity; angular velocity] in the base frame.
    Coupled passive joints are folded into the columns of the joints that drive them.
    ``point`` (3,) [m] is in the frame's coordinates (default: its origin).
    """
    model, batch, t = setup(robot, q, device, dtype, validate)
    fi = model.frame_index(frame)
    pt = _point(point, t)
    k = fk_kernels.kernels(t.scalar)
    rho, stride = (t.dh0_3d, 0) if dh is None else frame_rows(dh, model, batch, t, "dh", 5)
    jac = wp.empty((batch.size, 6, model.n_dof), dtype=t.scalar, device=t.device)
    wp.launch(k.jacobian, dim=batch.size,
              inputs=[batch.array, rho, stride, int(dh is not None), pt, t.frame_struct,
                      t.chain(fi)], outputs=[jac], device=t.device)
    return to_output(jac, batch, (6, model.n_dof))


def jacobian_dh(robot: Any, q: Any, frame: int | str, *, point: Any = None, dh: Any = None,
                device: Any = None, dtype: Any = None, validate: bool = True) -> Any:
    """Jacobian of a frame's pose (or a point in it) w.r.t. every DH parameter.

    Returns (..., 6, n_frames, 5): rows [linear; angular] in the base frame, columns the
    DH rows [d, theta, r, alpha, beta] of each frame (zero for frames off the chain and
    for static frames).
    """
    model, batch, t = setup(robot, q, device, dtype, validate)
    fi = model.frame_index(frame)
    pt = _point(point, t)
    k = fk_kernels.kernels(t.scalar)
    rho, stride = (t.dh0_3d, 0) if dh is None else frame_rows(dh, model, batch, t, "dh", 5)
    jac = wp.zeros((batch.size, 6, model.n_frames, 5), dtype=t.scalar, device=t.device)
    wp.launch(k.jacobian_dh, dim=batch.size,
              inputs=[batch.array, rho, stride, int(dh is not None), pt, t.frame_struct,
                      t.chain(fi)], outputs=[jac], device=t.device)
    return to_output(jac, batch, (6, model.n_frames, 5))


def _point(point: Any, t: KinematicsTables) -> Any:
    vec3 = fk_kernels.kernels(t.scalar).vec3
    if point is None:
        return vec3(0.0, 0.0, 0.0)
    p = real_array(point, "point")
    if p.shape != (3,) or not np.all(np.isfinite(p)):
        raise ValueError(f"point: expected 3 finite numbers [m], got {point!r}")
    return vec3(*finite_as(p, numpy_dtype(t.scalar), "point").tolist())


# ------------------------------------------------------------------ elastic
