"""U_path (eq. 3.16) and U_ik (eq. 3.19) as torch autograd functions, for training networks
through the planning objectives (thesis 3.4.4, eq. 3.28).

Tensors are shared with Warp through ``wp.from_torch`` / ``wp.to_torch`` (no host copies;
the inputs are copied device-to-device into the objective's persistent buffers so its
recorded launches are reused). The forward pass evaluates the cost and its gradient in one
go; the backward pass scales the stored gradient by the incoming one. CPU and CUDA.
"""

from __future__ import annotations

import weakref
from typing import TYPE_CHECKING, Any, cast

import numpy as np
import torch
import warp as wp

from jwarp.core.arrays import device_name
from jwarp.core.device import content_key
from jwarp.core.types import DeviceLike, DTypeLike, RobotLike
from jwarp.model import RobotModel
from jwarp.plugins.registry import robot as get_robot
from jwarp.solvers.ik import IKObjective, IKWeights
from jwarp.solvers.planning import PathObjective, PathWeights

if TYPE_CHECKING:
    from jwarp.world.sdf import World

#: objectives by (kind, robot content key (:func:`jwarp.core.device.content_key`: equal
#: robots share one, an edited copy gets its own), id of the world (the objective holds
#: its world, so that id is not reused while the entry lives), sizes, weights, device,
#: dtype); an entry lives as long as its objective
_OBJECTIVES: weakref.WeakValueDictionary[tuple, Any] = weakref.WeakValueDictionary()
_KEEP: list = []  # the last few objectives stay alive between calls


def _remember(key: tuple, obj: Any) -> Any:
    _OBJECTIVES[key] = obj
    _KEEP.append(obj)
    del _KEEP[:-8]
    return obj


def _scalar_np(t: torch.Tensor) -> Any:
    if t.dtype == torch.float64:
        return np.float64
    if t.dtype == torch.float32:
        return np.float32
    raise TypeError(f"expected a float32 or float64 tensor, got {t.dtype}")


def _check(t: Any, name: str, tail: tuple) -> None:
    if not isinstance(t, torch.Tensor):
        raise TypeError(f"{name}: expected a torch tensor, got {type(t).__name__}")
    if t.ndim != len(tail) + 1 or tuple(t.shape[1:]) != tail or t.shape[0] == 0:
        raise ValueError(f"{name}: expected shape (batch, {', '.join(map(str, tail))}), "
                         f"got {tuple(t.shape)}")
    if not bool(torch.isfinite(t).all()):
        raise ValueError(f"{name}: contains NaN or inf")


def path_objective(robot: RobotModel, world: World, n_paths: int, n_waypoints: int, n_substeps: int,
                   *, weights: PathWeights | None = None, eps: float | None = None,
                   device: DeviceLike = None, dtype: DTypeLike = np.float32) -> PathObjective:
    """A cached :class:`PathObjective` for these sizes (rebuilt when anything differs:
    robots count as equal by content). ``robot``: the RobotModel (:func:`u_path` resolves a
    name)."""
    model = robot
    w = weights or PathWeights()
    key = ("path", content_key(model), id(world), n_paths, n_waypoints, n_substeps,
           (w.world, w.self, w.length), eps, device_name(device), np.dtype(dtype).name)
    obj = _OBJECTIVES.get(key)
    if obj is None:
        obj = _remember(key, PathObjective(model, world, n_paths, n_waypoints, n_substeps,
                                           weights=w, eps=eps, device=device, dtype=dtype))
    return obj


class UPathFunction(torch.autograd.Function):
    """U_path(paths) (P,) with dU/dpaths (P, W, n_dof) (zero at start and goal)."""

    @staticmethod
    def forward(ctx: Any, paths: torch.Tensor, obj: PathObjective) -> torch.Tensor:
        src = wp.from_torch(paths.detach().contiguous(), dtype=obj.scalar)
        wp.copy(obj.paths, cast(wp.array, src))
        obj.evaluate(grad=True)
        ctx.save_for_backward(wp.to_torch(obj.gradient()).clone())
        return wp.to_torch(obj.total).clone()

    @staticmethod
    def backward(ctx: Any, grad_out: torch.Tensor) -> tuple:
        (g,) = ctx.saved_tensors
        return grad_out[:, None, None] * g, None


def u_path(paths: torch.Tensor, robot: RobotLike, world: World, n_substeps: int, *,
           weights: PathWeights | None = None, eps: float | None = None) -> torch.Tensor:
    """Differentiable U_path of a batch of paths (P, W, n_dof) -> (P,) on the tensor's
    device and dtype. Start and goal are the first and last waypoints (no gradient)."""
    model = get_robot(robot)
    if not isinstance(paths, torch.Tensor) or paths.ndim != 3:
        raise ValueError(f"paths: expected a tensor (P, W, {model.n_dof}), got "
                         f"{getattr(paths, 'shape', type(paths).__name__)}")
    _check(paths, "paths", (paths.shape[1], model.n_dof))
    dev = wp.device_from_torch(paths.device)
    obj = path_objective(model, world, paths.shape[0], paths.shape[1], n_substeps,
                         weights=weights, eps=eps, device=dev, dtype=_scalar_np(paths))
    return UPathFunction.apply(paths, obj)


def ik_objective(robot: RobotModel, frame: int | str, n: int, *, world: World | None = None,
                 weights: IKWeights | None = None, eps: float | None = None,
                 q_default: Any = None, device: DeviceLike = None, dtype: DTypeLike = np.float32
                 ) -> IKObjective:
    """A cached :class:`IKObjective` for this batch size (q_default is (re)set each call;
    robots count as equal by content). ``robot``: the RobotModel (:func:`u_ik` resolves a
    name)."""
    model = robot
    w = weights or IKWeights()
    key = ("ik", content_key(model), model.frame_index(frame), id(world), n,
           (w.position, w.rotation, w.world, w.self, w.default), eps, device_name(device),
           np.dtype(dtype).name)
    obj = _OBJECTIVES.get(key)
    if obj is None:
        obj = _remember(key, IKObjective(model, frame, n, world=world, weights=w, eps=eps,
                                         device=device, dtype=dtype))
    obj.set_default(q_default)
    return obj


class UIKFunction(torch.autograd.Function):
    """U_ik(q; target) = U_f + U_A (B,) with dU/dq (B, n_dof) (targets get no gradient)."""

    @staticmethod
    def forward(ctx: Any, q: torch.Tensor, target: torch.Tensor, obj: IKObjective) -> torch.Tensor:
        wp.copy(obj.q, cast(wp.array, wp.from_torch(q.detach().contiguous(), dtype=obj.scalar)))
        tgt = target.detach().to(dtype=q.dtype).contiguous()
        wp.copy(obj.target, cast(wp.array, wp.from_torch(tgt, dtype=obj.fk.mat44)))
        obj.evaluate_pose()
        obj.evaluate_aux()
        g = wp.to_torch(obj.grad_f) + wp.to_torch(obj.grad_a)
        ctx.save_for_backward(g)
        return wp.to_torch(obj.cost_f) + wp.to_torch(obj.cost_a)

    @staticmethod
    def backward(ctx: Any, grad_out: torch.Tensor) -> tuple:
        (g,) = ctx.saved_tensors
        return grad_out[:, None] * g, None, None


def u_ik(q: torch.Tensor, target: torch.Tensor, robot: RobotLike, frame: int | str, *, world: World | None = None,
         weights: IKWeights | None = None, eps: float | None = None,
         q_default: Any = None) -> torch.Tensor:
    """Differentiable U_ik (eq. 3.19) of configurations q (B, n_dof) for target poses
    (B, 4, 4) of ``frame`` -> (B,), on q's device and dtype (the unsupervised IK loss)."""
    model = get_robot(robot)
    _check(q, "q", (model.n_dof,))
    _check(target, "target", (4, 4))
    if target.shape[0] != q.shape[0]:
        raise ValueError(f"target: batch {target.shape[0]} does not match q's {q.shape[0]}")
    if target.device != q.device:
        raise ValueError(f"target: on {target.device}, q on {q.device}")
    dev = wp.device_from_torch(q.device)
    obj = ik_objective(model, frame, q.shape[0], world=world, weights=weights, eps=eps,
                       q_default=q_default, device=dev, dtype=_scalar_np(q))
    return UIKFunction.apply(q, target, obj)
