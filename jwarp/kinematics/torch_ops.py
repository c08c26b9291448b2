"""Torch autograd wrappers around the Warp kinematics kernels (zero-copy, CPU and CUDA).

:func:`jwarp.kinematics.fk` and :func:`jwarp.kinematics.fk_elastic` route here when
``q`` is a torch tensor that requires grad. Forward passes share memory with torch
through ``wp.from_torch``/``wp.to_torch``; backward passes replay a ``wp.Tape``.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
import warp as wp

from jwarp.core.types import DeviceLike
from jwarp.kernels import fk as fk_kernels
from jwarp.model import RobotModel


def _torch_dtype(scalar: type) -> torch.dtype:
    return torch.float32 if scalar == wp.float32 else torch.float64


class _TapeFunction(torch.autograd.Function):
    """y = f(q) recorded on a Warp tape by ``record(q_w) -> (frames, extras)``."""

    @staticmethod
    def forward(ctx: Any, q: torch.Tensor, record: Any, scalar: type) -> torch.Tensor:
        q_w = wp.from_torch(q.detach().contiguous(), dtype=scalar, requires_grad=True)
        tape = wp.Tape()
        with tape:
            frames = record(q_w)
        ctx.tape, ctx.q_w, ctx.frames = tape, q_w, frames
        return wp.to_torch(frames)

    @staticmethod
    def backward(ctx: Any, grad: torch.Tensor) -> tuple:
        mat44 = fk_kernels.kernels(ctx.q_w.dtype).mat44
        ctx.tape.backward(grads={ctx.frames: wp.from_torch(grad.contiguous(), dtype=mat44)})
        g = wp.to_torch(ctx.q_w.grad).clone()
        ctx.tape.zero()
        return g, None, None


def _prepare(q: torch.Tensor, model: RobotModel, device: DeviceLike, scalar: type) -> torch.Tensor:
    target = wp.device_to_torch(device)
    return q.reshape(-1, model.n_dof).to(device=target, dtype=_torch_dtype(scalar))


def fk_torch(model: RobotModel, q: torch.Tensor, *, dh: Any, device: DeviceLike, dtype: type) -> torch.Tensor:
    """Differentiable FK of a torch tensor q (..., n_dof) -> (..., n_frames, 4, 4)."""
    from jwarp.core.device import put_model
    from jwarp.kinematics.launch import launch_fk

    t = put_model(model, device, np.float32 if dtype == wp.float32 else np.float64)
    qc = _prepare(q, model, device, t.scalar)
    dh_pair = None
    if dh is not None:
        from jwarp.core.arrays import Batch
        from jwarp.kinematics.launch import frame_rows

        dh_pair = frame_rows(dh, model, Batch(None, tuple(q.shape[:-1]), "torch"), t, "dh", 5)

    def record(q_w: wp.array) -> wp.array:
        out = wp.empty((q_w.shape[0], model.n_frames), dtype=fk_kernels.kernels(t.scalar).mat44,
                       device=t.device, requires_grad=True)
        return launch_fk(t, q_w, dh=dh_pair, frames=out)

    frames = _TapeFunction.apply(qc, record, t.scalar)
    return frames.to(q.device).reshape(tuple(q.shape[:-1]) + (model.n_frames, 4, 4))


def fk_elastic_torch(model: RobotModel, batch: Any, t: Any, kap: Any, rho0: Any, lam: float,
                     max_iter: int, tol: float) -> Any:
    """Differentiable elastic FK of a torch tensor: gradients flow through every torque
    update that the iteration performed (exact derivative of the iterated model)."""
    from jwarp.kinematics.launch import (
        ElasticFK,
        ElasticLaunch,
        equilibrium,
        host_out,
        rho0_full,
    )

    q = batch.torch_tensor
    qc = _prepare(q, model, t.device, t.scalar)
    info: dict[str, Any] = {}

    def record(q_w: wp.array) -> wp.array:
        run = ElasticLaunch(t, q_w, kap, rho0, float(lam), requires_grad=True)
        rho, frames, iterations, converged = equilibrium(run, max_iter, tol)
        info.update(rho=rho[0] if rho is not None else rho0_full(run),
                    iterations=iterations, converged=converged)
        return frames

    frames = _TapeFunction.apply(qc, record, t.scalar)
    lead = tuple(q.shape[:-1])
    rho = wp.to_torch(info["rho"]).to(q.device).reshape(lead + (model.n_frames, 5))
    return ElasticFK(frames.to(q.device).reshape(lead + (model.n_frames, 4, 4)), rho.detach(),
                     host_out(info["iterations"], batch), host_out(info["converged"], batch))
