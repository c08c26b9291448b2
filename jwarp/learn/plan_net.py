"""The motion-planning network (thesis 3.4.3, Fig. 3.11; Table 3.2): a motion task (start,
goal, the world's basis point set) -> the path's N_t waypoints, used as the planner's
warm start (``Planner(..., warm_start=net)``).

Input: start and goal in the unit-vector joint encoding (:class:`JointCodec`
``(sin, cos)`` pairs of revolute joints, ``encode``), followed by the world's BPS values
(:mod:`jwarp.learn.bps`, scaled by ``bps_scale``) for a world-aware network
(``n_bps > 0``).

Output: the path as its *deviation from the straight line* (thesis 3.5.2): for the
interior waypoints ``k = 1 .. W-2`` (start and goal are the task's)
``y_k = (q_k - line_k) / (upper - lower)`` with ``line_k = q_start + k/(W-1) (q_goal -
q_start)``; an untrained network (outputs near 0) predicts the straight line.
:func:`decode_paths` maps outputs back and clips them into the box limits.

Architecture: the DenseNet-like blocks of :class:`jwarp.learn.ik_net.IKNet` (two fully
connected layers each, SiLU; block ``b`` sees the input and every earlier block's output),
a last linear layer to ``n_heads x (W - 2) x n_dof`` outputs.

Axis symmetries (thesis 3.4.3, "Symmetries of Motion Planning"): :data:`AXIS_SYMMETRIES`
declares per robot name the symmetries ``q -> joint_sign * q`` that, with the world mapped
by the orthogonal ``workspace`` matrix M, turn every feasible (optimal) path into one of
the mapped task: FK positions of ``joint_sign * q`` are ``M`` times those of ``q``
(checked in the tests against :func:`jwarp.fk`). The BPS of the mapped world ``M(world)``
at the basis points b is the world's SDF at ``M^-1 b`` (:func:`symmetric_bps`), so no
mapped world is built.
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import torch
from torch import nn

from jwarp.core.types import RobotLike
from jwarp.learn.encoding import JointCodec
from jwarp.learn.ik_net import DenseBlock, NetConfig, network_bps, world_key
from jwarp.plugins.registry import robot as get_robot
from jwarp.world.feasibility import robot_reach

if TYPE_CHECKING:
    from jwarp.world.sdf import World

__all__ = ["PlanNetConfig", "PlanNet", "AxisSymmetry", "AXIS_SYMMETRIES", "axis_symmetries",
           "symmetric_bps", "straight_paths", "encode_paths", "decode_paths"]


# ====================================================================== symmetries
@dataclass(frozen=True)
class AxisSymmetry:
    """A spatial symmetry of a robot: ``q -> joint_sign * q`` moves every collision sphere
    by the orthogonal map ``workspace`` (dim x dim) of the base frame (a mirror or a
    rotation about the base)."""

    name: str
    joint_sign: tuple
    workspace: tuple

    def map_q(self, q: np.ndarray) -> np.ndarray:
        return np.asarray(q) * np.asarray(self.joint_sign, dtype=np.float64)

    @property
    def matrix(self) -> np.ndarray:
        return np.asarray(self.workspace, dtype=np.float64)


_MIRROR_Y_2D = ((1.0, 0.0), (0.0, -1.0))
_MIRROR_X_2D = ((-1.0, 0.0), (0.0, 1.0))

#: declared axis symmetries per robot name (planar arms: all joints about z, base at the
#: origin: q -> -q mirrors the arm about the x axis; the point robot: each coordinate axis)
AXIS_SYMMETRIES: dict[str, tuple[AxisSymmetry, ...]] = {
    "planar4": (AxisSymmetry("mirror about the x axis", (-1.0,) * 4, _MIRROR_Y_2D),),
    "planar5": (AxisSymmetry("mirror about the x axis", (-1.0,) * 5, _MIRROR_Y_2D),),
    "sphere2d": (AxisSymmetry("mirror about the x axis", (1.0, -1.0), _MIRROR_Y_2D),
                 AxisSymmetry("mirror about the y axis", (-1.0, 1.0), _MIRROR_X_2D)),
}


def axis_symmetries(robot: RobotLike) -> tuple[AxisSymmetry, ...]:
    """The declared symmetries of ``robot`` (:data:`AXIS_SYMMETRIES`; none for an
    undeclared robot). ValueError if the robot's joint limits are not mapped onto
    themselves (an edited robot of a declared name)."""
    model = get_robot(robot)
    syms = AXIS_SYMMETRIES.get(model.name, ())
    lim = np.asarray(model.joint_limits, np.float64)
    for s in syms:
        sign = np.asarray(s.joint_sign, np.float64)
        if sign.shape != (model.n_dof,) or s.matrix.shape != (model.workspace_dim,) * 2:
            raise ValueError(f"axis symmetry '{s.name}' of '{model.name}': shapes do not fit "
                             f"the robot ({model.n_dof} joints, {model.workspace_dim}D)")
        mapped = np.sort(lim * sign[:, None], axis=1)
        if not np.allclose(mapped, lim, atol=1e-9):
            raise ValueError(f"axis symmetry '{s.name}' of '{model.name}': the joint limits "
                             f"are not symmetric under it")
    return syms


def symmetric_bps(bps: Any, worlds: Any, symmetry: AxisSymmetry) -> np.ndarray:
    """BPS values (n_worlds, N) of the worlds mapped by ``symmetry.workspace`` M: the SDF
    of each world at ``M^-1 b`` (rows ``b @ M`` for orthogonal M)."""
    from jwarp.learn.bps import bps_encode

    pts = np.asarray(bps.points, np.float64) @ symmetry.matrix
    return np.asarray(bps_encode(worlds, pts), np.float32)


# ====================================================================== path encoding
def straight_paths(starts: np.ndarray, goals: np.ndarray, n_waypoints: int) -> np.ndarray:
    """(N, W, n_dof) straight lines in joint space."""
    s = np.linspace(0.0, 1.0, n_waypoints)[None, :, None]
    starts = np.asarray(starts, np.float64)
    return starts[:, None] + s * (np.asarray(goals, np.float64) - starts)[:, None]


def encode_paths(paths: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """(N, W, n_dof) paths -> (N, W - 2, n_dof) deviations of the interior waypoints from
    the straight line between their first and last waypoint, per joint range."""
    paths = np.asarray(paths, np.float64)
    line = straight_paths(paths[:, 0], paths[:, -1], paths.shape[1])
    return (paths[:, 1:-1] - line[:, 1:-1]) / (np.asarray(upper) - np.asarray(lower))


def decode_paths(dev: np.ndarray, starts: np.ndarray, goals: np.ndarray, lower: np.ndarray,
                 upper: np.ndarray) -> np.ndarray:
    """Deviations (N, [H,] W - 2, n_dof) -> paths (N, [H,] W, n_dof) from start to goal,
    clipped into the box limits."""
    dev = np.asarray(dev, np.float64)
    heads = dev.ndim == 4
    d = dev if heads else dev[:, None]
    H, Wi = d.shape[1:3]
    line = straight_paths(starts, goals, Wi + 2)[:, None]
    out = np.repeat(line, H, axis=1)
    out[:, :, 1:-1] += d * (np.asarray(upper) - np.asarray(lower))
    out[:, :, 1:-1] = np.clip(out[:, :, 1:-1], lower, upper)
    out[:, :, 0] = np.asarray(starts)[:, None]  # exact endpoints
    out[:, :, -1] = np.asarray(goals)[:, None]
    return out if heads else out[:, 0]


# ====================================================================== network
@dataclass
class PlanNetConfig(NetConfig):
    """What a :class:`PlanNet` is: robot name, BPS size (0: world-unaware), waypoints N_t
    of the predicted paths (start and goal included), hidden width, dense blocks (2 layers
    each), heads (paths per task)."""

    INT_FIELDS = (("n_bps", 0), ("n_waypoints", 3), ("hidden", 1), ("n_blocks", 1),
                  ("n_heads", 1))

    robot: str = "planar4"
    n_bps: int = 128
    n_waypoints: int = 20
    hidden: int = 256
    n_blocks: int = 3
    n_heads: int = 1


class PlanNet(nn.Module):
    """Motion-planning network (module docstring).

    Args:
        config: :class:`PlanNetConfig`.
        bps: the :class:`jwarp.learn.bps.BasisPointSet` (None: ``basis_points(robot,
            config.n_bps)``); ignored when ``n_bps == 0``.

    Attributes:
        robot, codec (unit-vector :class:`JointCodec` of the inputs), n_dof, n_heads,
        n_waypoints, lower/upper (n_dof,) numpy, bps, meta.
    """

    #: the checkpoint format of this network (:mod:`jwarp.learn.checkpoint`)
    checkpoint_format = "jwarp-plan-net"

    # a buffer (register_buffer), declared for the type checker
    bps_scale: torch.Tensor

    def __init__(self, config: PlanNetConfig, bps: Any = None):
        super().__init__()
        config.validate()
        self.config = config
        model = get_robot(config.robot)
        self.robot = model
        self.codec = JointCodec(model, unit_vectors=True)
        self.n_dof = model.n_dof
        self.n_heads = int(config.n_heads)
        self.n_waypoints = int(config.n_waypoints)
        self.lower, self.upper = self.codec.lower, self.codec.upper
        self.meta: dict = {}
        self.bps = network_bps(model, config.n_bps, bps)
        box = robot_reach(model)[:model.workspace_dim]
        half = 0.5 * (box[:, 1] - box[:, 0])
        self.register_buffer("bps_scale", torch.tensor(1.0 / float(max(half.max(), 1e-3))))
        self.n_out = (self.n_waypoints - 2) * self.n_dof
        width = 2 * self.codec.size + int(config.n_bps)
        self.blocks = nn.ModuleList()
        for _ in range(int(config.n_blocks)):
            self.blocks.append(DenseBlock(width, int(config.hidden)))
            width += int(config.hidden)
        self.out = nn.Linear(width, self.n_heads * self.n_out)
        with torch.no_grad():  # start near the straight line
            self.out.weight.mul_(0.1)
            self.out.bias.zero_()
        self._bps_by_id: dict = {}
        self._bps_by_key: dict = {}

    @property
    def world_aware(self) -> bool:
        return self.bps is not None

    # ------------------------------------------------------------------ forward
    def forward(self, starts: torch.Tensor, goals: torch.Tensor,
                bps_values: torch.Tensor | None = None) -> torch.Tensor:
        """Deviation outputs (B, n_heads, W - 2, n_dof) of starts/goals (B, n_dof) (joint
        values inside the limits) and BPS values (B, n_bps) [m] (world-aware networks)."""
        parts = [self.codec.encode(starts), self.codec.encode(goals)]
        if self.bps is not None:
            if bps_values is None:
                raise ValueError("bps_values: this network is world-aware (n_bps > 0); "
                                 "give the world's BPS values")
            parts.append(bps_values * self.bps_scale)
        x = torch.cat(parts, dim=1)
        for blk in self.blocks:
            x = torch.cat([x, blk(x)], dim=1)
        return self.out(x).view(x.shape[0], self.n_heads, self.n_waypoints - 2, self.n_dof)

    # ------------------------------------------------------------------ BPS of worlds
    def world_bps(self, world: World) -> np.ndarray:
        """(n_bps,) float32 BPS values of ``world``, cached per world object and content."""
        if self.bps is None:
            raise ValueError("world_bps: this network is world-unaware (n_bps == 0)")
        hit = self._bps_by_id.get(id(world))
        if hit is not None and hit[0]() is world:
            return hit[1]
        key = world_key(world)
        v = self._bps_by_key.get(key)
        if v is None:
            v = np.asarray(self.bps.encode([world]), np.float32).reshape(-1)
            self._bps_by_key[key] = v
            while len(self._bps_by_key) > 256:
                self._bps_by_key.pop(next(iter(self._bps_by_key)))
        try:
            self._bps_by_id[id(world)] = (weakref.ref(world), v)
            while len(self._bps_by_id) > 256:
                self._bps_by_id.pop(next(iter(self._bps_by_id)))
        except TypeError:
            pass
        return v

    def _bps_rows(self, world: World | None, P: int) -> np.ndarray | None:
        if self.bps is None:
            return None
        if world is None:
            raise ValueError("world: this network is world-aware (n_bps > 0); give the world "
                             "(or one world per task)")
        if isinstance(world, (list, tuple)):
            if len(world) != P:
                raise ValueError(f"world: expected one world or {P} (one per task), got "
                                 f"{len(world)}")
            return np.stack([self.world_bps(w) for w in world])
        return np.repeat(self.world_bps(world)[None], P, axis=0)

    # ------------------------------------------------------------------ warm starts
    def deviations(self, starts: Any, goals: Any, world: World | None = None) -> np.ndarray:
        """Raw outputs (P, H, W - 2, n_dof) float64 (inference mode)."""
        q0, q1 = self._tasks(starts, goals)
        p = self.out.weight
        b = self._bps_rows(world, len(q0))
        with torch.inference_mode():
            t0 = torch.as_tensor(q0, dtype=p.dtype, device=p.device)
            t1 = torch.as_tensor(q1, dtype=p.dtype, device=p.device)
            tb = None if b is None else torch.as_tensor(np.asarray(b), dtype=p.dtype,
                                                        device=p.device)
            y = self(t0, t1, tb)
            return y.to(device="cpu", dtype=torch.float64).numpy().copy()

    def paths(self, starts: Any, goals: Any, world: World | None = None) -> np.ndarray:
        """The planner's warm-start protocol: starts/goals (P, n_dof) (or one (n_dof,)) and
        the world (one for all tasks, or a list of P) -> (P, n_heads, W, n_dof) float64
        paths from start to goal inside the box limits."""
        q0, q1 = self._tasks(starts, goals)
        return decode_paths(self.deviations(q0, q1, world), q0, q1, self.lower, self.upper)

    def _tasks(self, starts: Any, goals: Any) -> tuple[np.ndarray, np.ndarray]:
        q0 = np.atleast_2d(np.asarray(starts, np.float64))
        q1 = np.atleast_2d(np.asarray(goals, np.float64))
        if len(q0) == 1 and len(q1) > 1:
            q0 = np.repeat(q0, len(q1), 0)
        if len(q1) == 1 and len(q0) > 1:
            q1 = np.repeat(q1, len(q0), 0)
        for name, q in (("starts", q0), ("goals", q1)):
            if q.ndim != 2 or q.shape[1] != self.n_dof:
                raise ValueError(f"{name}: expected (P, {self.n_dof}), got {q.shape}")
            if not np.all(np.isfinite(q)):
                raise ValueError(f"{name}: contains NaN or inf")
        if len(q0) != len(q1):
            raise ValueError(f"starts, goals: batch sizes differ ({len(q0)} vs {len(q1)})")
        return np.clip(q0, self.lower, self.upper), np.clip(q1, self.lower, self.upper)
