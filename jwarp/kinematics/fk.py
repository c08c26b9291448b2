"""Batched forward kinematics of all frames (rigid, or at given DH rows).

Every public function takes a robot (name or :class:`~jwarp.model.RobotModel`) and joint values
``q`` of shape ``(..., n_dof)`` as numpy, Warp or torch arrays, and returns the same kind
with the same leading batch dimensions. ``device`` defaults to CUDA when present, else
CPU; ``dtype`` defaults to float64 for float64 input, else float32.
"""

from __future__ import annotations

from typing import Any


from jwarp.core.arrays import (to_output)
from jwarp.kinematics.launch import frame_rows, launch_fk, setup


def fk(robot: Any, q: Any, *, dh: Any = None, device: Any = None, dtype: Any = None,
       validate: bool = True) -> Any:
    """Forward kinematics of all frames.

    Args:
        robot: robot name or RobotModel.
        q: joint values (..., n_dof) [rad or m].
        dh: optional DH rows (n_frames, 5) or per configuration (..., n_frames, 5)
            [d, theta, r, alpha, beta] replacing the nominal ones (calibration).
        device: "cpu", "cuda:0", ... (default: CUDA if present, else CPU).
        dtype: float32 or float64 (default: float64 for float64 input, else float32).
        validate: check q for NaN/inf (costs a pass over q).

    Returns:
        World transforms (..., n_frames, 4, 4) of every frame in the base frame
        (Warp input: a Warp ``mat44`` array of shape (..., n_frames)).
    """
    model, batch, t = setup(robot, q, device, dtype, validate)
    if batch.kind == "torch" and batch.torch_tensor.requires_grad:
        from jwarp.kinematics.torch_ops import fk_torch

        return fk_torch(model, batch.torch_tensor, dh=dh, device=t.device, dtype=t.scalar)
    frames = launch_fk(t, batch.array, dh=None if dh is None else frame_rows(dh, model, batch, t, "dh", 5))
    return to_output(frames, batch, (model.n_frames,))


