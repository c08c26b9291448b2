"""Batched forward kinematics of all frames (rigid, or at given DH rows).

Every public function takes a robot (name or :class:`~jwarp.model.RobotModel`) and joint values
``q`` of shape ``(..., n_dof)`` as numpy, Warp or torch arrays, and returns the same kind
with the same leading batch dimensions. ``device`` None is the device rule of docs/api.md
("Devices": q's device for Warp/torch q, else Warp's default device); ``dtype`` defaults
to float64 for float64 input, else float32.
"""

from __future__ import annotations

from typing import Any

from jwarp.core.arrays import out_view, to_output
from jwarp.core.types import ArrayLike, DeviceLike, DTypeLike, RobotLike
from jwarp.kernels import fk as fk_kernels
from jwarp.kinematics.launch import frame_rows, launch_fk, setup, small_call
from jwarp.kinematics.transmission import transmitted
from jwarp.plugins.registry import robot as get_robot


def fk(robot: RobotLike, q: ArrayLike, *, dh: ArrayLike | None = None,
       device: DeviceLike = None, dtype: DTypeLike = None, validate: bool = True,
       out: ArrayLike | None = None) -> Any:
    """Forward kinematics of all frames.

    Args:
        robot: robot name or RobotModel.
        q: joint values (..., n_dof) [rad or m].
        dh: optional DH rows (n_frames, 5) or per configuration (..., n_frames, 5)
            [d, theta, r, alpha, beta] replacing the nominal ones (calibration).
        device: "cpu", "cuda:0", ... (None: q's device for Warp/torch q, else Warp's
            default device: docs/api.md "Devices").
        dtype: float32 or float64 (default: float64 for float64 input, else float32).
        validate: check q for NaN/inf (costs a pass over q).
        out: optional array the frames are written to, and returned: a numpy array or
            torch tensor (..., n_frames, 4, 4), or a Warp ``mat44`` array (..., n_frames),
            in the computing dtype, C-contiguous, torch/Warp on the computing device (not
            with torch autograd). Reusing ``out`` saves the allocation and the first touch
            of fresh memory (a large new CPU output is faulted in on a second core while the
            kernel runs, see :func:`jwarp.core.arrays.first_touch`).

    A robot with joint transmission errors (``harmonic``) is evaluated at
    ``q + dq(q)`` (:mod:`jwarp.kinematics.transmission`).

    Returns:
        World transforms (..., n_frames, 4, 4) of every frame in the base frame
        (Warp input: a Warp ``mat44`` array of shape (..., n_frames)); ``out`` if given.

    Small calls (a few configurations of numpy float32/float64 q, or a CPU torch tensor
    without grad; no ``dh``) reuse buffers and a recorded kernel launch kept per process
    for each (robot tables, device, dtype, batch size): one configuration costs about
    10 us on the CPU instead of about 65 us. The returned array is always a new one (or
    ``out``), never overwritten by a later call. The buffers serve one call at a time; a
    concurrent call from another thread takes the general path (correct, just slower).
    """
    model = get_robot(robot)
    q = transmitted(model, q)   # joint transmission errors (host side, exact)
    if dh is None:
        res = small_call("fk", model, q, device, dtype, validate, out)
        if res is not None:
            return res
    model, batch, t = setup(model, q, device, dtype, validate)
    if batch.kind == "torch" and batch.torch_tensor.requires_grad:
        if out is not None:
            raise ValueError("out: not supported when q requires grad (torch autograd)")
        from jwarp.kinematics.torch_ops import fk_torch

        return fk_torch(model, batch.torch_tensor, dh=dh, device=t.device, dtype=t.scalar)
    dh_rows = None if dh is None else frame_rows(dh, model, batch, t, "dh", 5)
    view = None if out is None else out_view(out, batch, (model.n_frames,),
                                             fk_kernels.kernels(t.scalar).mat44, t.device)
    frames = launch_fk(t, batch.array, dh=dh_rows, frames=view)
    return to_output(frames, batch, (model.n_frames,), out=out)
