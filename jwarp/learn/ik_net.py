"""The IK network (thesis 3.4.4, eq. 3.28; IK paper III-D): target frame (+ the world's
basis point set) -> one or two joint configurations (twin heads), used as the solver's
warm start.

Architecture: blocks of fully connected layers joined DenseNet-style (thesis Fig. 3.11):
block ``b`` sees the concatenation of the input and every earlier block's output; a last
linear layer maps the concatenation to ``n_heads x JointCodec.size`` outputs, decoded by
:class:`jwarp.learn.encoding.JointCodec` into the joint limits.

Input: :func:`jwarp.learn.encoding.frame_features` of the target, shifted and scaled by the
robot's reach box (buffers ``in_shift``/``in_scale``, saved with the weights), followed by
the world's BPS values (:mod:`jwarp.learn.bps`, scaled by ``bps_scale``) for a
world-aware network (``n_bps > 0``).
"""

from __future__ import annotations

import dataclasses
import hashlib
import weakref
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np
import torch
from torch import nn

from jwarp.learn.encoding import (
    JointCodec,
    feature_size,
    frame_features,
    frame_features_numpy,
)
from jwarp.plugins.registry import robot as get_robot
from jwarp.utils.checks import check_int
from jwarp.world.feasibility import robot_reach

if TYPE_CHECKING:
    from jwarp.model import RobotModel
    from jwarp.world.sdf import World

__all__ = ["IKNetConfig", "IKNet", "DenseBlock", "NetConfig", "network_bps", "world_key"]


class NetConfig:
    """Shared behaviour of the network configurations (dataclasses): ``to_dict``,
    ``from_dict`` (ValueError naming unknown fields) and ``validate``, which checks that
    ``robot`` is a name and that each field of :attr:`INT_FIELDS` ((name, lower bound))
    is an integer at or above its bound (errors name the field)."""

    INT_FIELDS: tuple = ()
    # declared for the type checker (the subclasses are dataclasses with a ``robot`` field)
    __dataclass_fields__: ClassVar[dict[str, dataclasses.Field[Any]]]
    robot: str

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> Any:
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = set(d) - names
        if unknown:
            raise ValueError(f"config: unknown fields {sorted(unknown)}")
        return cls(**d)

    def validate(self) -> None:
        if not isinstance(self.robot, str):
            raise TypeError(f"robot: expected a robot name, got {type(self.robot).__name__}")
        for name, lo in self.INT_FIELDS:
            v = getattr(self, name)
            check_int(v, name, lo)


@dataclass
class IKNetConfig(NetConfig):
    """What an :class:`IKNet` is: robot name, end-effector frame, BPS size (0: the
    world-unaware network), hidden width, number of dense blocks (2 layers each), twin
    heads, unit-vector output."""

    INT_FIELDS = (("n_bps", 0), ("hidden", 1), ("n_blocks", 1))

    robot: str = "planar5"
    frame: str | int = "tcp"
    n_bps: int = 0
    hidden: int = 128
    n_blocks: int = 3
    twin: bool = True
    unit_vectors: bool = True


def network_bps(model: RobotModel, n_bps: int, bps: Any = None) -> Any:
    """The basis point set of a network with ``n_bps`` points (0: None, world-unaware):
    ``bps`` if given (ValueError naming ``bps`` unless it has ``n_bps`` points), else
    ``basis_points(model, n_bps)``."""
    n_bps = int(n_bps)
    if n_bps <= 0:
        return None
    if bps is None:
        from jwarp.learn.bps import basis_points
        bps = basis_points(model, n_bps)
    if int(bps.size) != n_bps:
        raise ValueError(f"bps: has {bps.size} points, config.n_bps is {n_bps}")
    return bps


def world_key(world: World) -> str:
    """Content hash of a world (SDF bytes, grid limits, voxel size)."""
    h = hashlib.blake2b(digest_size=16)
    sdf = np.ascontiguousarray(world.sdf)
    h.update(str((sdf.shape, sdf.dtype.str)).encode())
    h.update(sdf.tobytes())
    h.update(np.asarray(world.limits, np.float64).tobytes())
    h.update(np.float64(world.voxel_size).tobytes())
    return h.hexdigest()


class DenseBlock(nn.Module):
    def __init__(self, n_in: int, width: int):
        super().__init__()
        self.l1 = nn.Linear(n_in, width)
        self.l2 = nn.Linear(width, width)
        self.act = nn.SiLU()

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.act(self.l2(self.act(self.l1(x))))


class IKNet(nn.Module):
    """Twin- or single-headed IK network (module docstring).

    Args:
        config: :class:`IKNetConfig`.
        bps: the :class:`jwarp.learn.bps.BasisPointSet` of a world-aware network (None:
            ``basis_points(robot, config.n_bps)``); ignored when ``n_bps == 0``.

    Attributes:
        robot, frame (index), codec (:class:`JointCodec`), n_heads, n_dof, bps, meta (what
        :func:`jwarp.learn.checkpoint.load_checkpoint` read besides the weights).
    """

    # buffers (register_buffer), declared for the type checker
    in_shift: torch.Tensor
    in_scale: torch.Tensor
    bps_scale: torch.Tensor

    def __init__(self, config: IKNetConfig, bps: Any = None):
        super().__init__()
        config.validate()
        self.config = config
        model = get_robot(config.robot)
        self.robot = model
        self.frame = model.frame_index(config.frame)
        self.dim = model.workspace_dim
        self.codec = JointCodec(model, unit_vectors=config.unit_vectors)
        self.n_heads = 2 if config.twin else 1
        self.n_dof = model.n_dof
        self.meta: dict = {}
        F = feature_size(self.dim)
        self.bps = network_bps(model, config.n_bps, bps)
        box = robot_reach(model)[:self.dim]
        centre, half = box.mean(axis=1), 0.5 * (box[:, 1] - box[:, 0])
        shift = np.zeros(F, np.float32)
        scale = np.ones(F, np.float32)
        shift[:self.dim] = centre
        scale[:self.dim] = 1.0 / np.maximum(half, 1e-3)
        self.register_buffer("in_shift", torch.as_tensor(shift))
        self.register_buffer("in_scale", torch.as_tensor(scale))
        self.register_buffer("bps_scale", torch.tensor(1.0 / float(max(half.max(), 1e-3))))
        width = F + int(config.n_bps)
        self.blocks = nn.ModuleList()
        for _ in range(int(config.n_blocks)):
            self.blocks.append(DenseBlock(width, int(config.hidden)))
            width += int(config.hidden)
        self.out = nn.Linear(width, self.n_heads * self.codec.size)
        with torch.no_grad():  # start near the middle of the limits (angle 0: sin 0, cos 1)
            self.out.weight.mul_(0.1)
            self.out.bias.zero_()
            if len(self.codec.cos_cols):
                b = self.out.bias.view(self.n_heads, self.codec.size)
                b[:, torch.as_tensor(self.codec.cos_cols)] = 1.0
        self._bps_by_id: dict = {}
        self._bps_by_key: dict = {}
        self._buf: dict = {}

    # ------------------------------------------------------------------ forward
    @property
    def world_aware(self) -> bool:
        return self.bps is not None

    def forward(self, features: torch.Tensor, bps_values: torch.Tensor | None = None
                ) -> torch.Tensor:
        """Raw outputs (B, n_heads, codec.size) of frame features (B, F) (not yet
        normalised) and BPS values (B, n_bps) [m] (world-aware networks)."""
        x = (features - self.in_shift) * self.in_scale
        if self.bps is not None:
            if bps_values is None:
                raise ValueError("bps_values: this network is world-aware (n_bps > 0); "
                                 "give the world's BPS values")
            x = torch.cat([x, bps_values * self.bps_scale], dim=1)
        for blk in self.blocks:
            x = torch.cat([x, blk(x)], dim=1)
        return self.out(x).view(x.shape[0], self.n_heads, self.codec.size)

    def predict(self, targets: torch.Tensor, bps_values: torch.Tensor | None = None
                ) -> torch.Tensor:
        """Joint configurations (B, n_heads, n_dof) for target frames (B, 4, 4) (the
        network's dtype and device; differentiable)."""
        p = self.out.weight
        f = frame_features(targets.to(dtype=p.dtype, device=p.device), self.dim)
        if bps_values is not None:
            bps_values = bps_values.to(dtype=p.dtype, device=p.device)
        return self.codec.decode(self(f, bps_values))

    # ------------------------------------------------------------------ BPS of worlds
    def world_bps(self, world: World) -> torch.Tensor:
        """(1, n_bps) BPS values of ``world`` on the network's device and dtype, cached per
        world object and per world content (:func:`world_key`)."""
        if self.bps is None:
            raise ValueError("world_bps: this network is world-unaware (n_bps == 0)")
        p = self.out.weight
        hit = self._bps_by_id.get(id(world))
        if hit is not None and hit[0]() is world and hit[1].dtype == p.dtype \
                and hit[1].device == p.device:
            return hit[1]
        key = (world_key(world), p.dtype, str(p.device))
        t = self._bps_by_key.get(key)
        if t is None:
            vals = np.asarray(self.bps.encode([world]), np.float32).reshape(1, -1)
            t = torch.as_tensor(vals).to(dtype=p.dtype, device=p.device)
            self._bps_by_key[key] = t
            while len(self._bps_by_key) > 64:
                self._bps_by_key.pop(next(iter(self._bps_by_key)))
        try:
            ref = weakref.ref(world)
            self._bps_by_id[id(world)] = (ref, t)
            while len(self._bps_by_id) > 64:
                self._bps_by_id.pop(next(iter(self._bps_by_id)))
        except TypeError:  # not weak-referenceable: the content key only
            pass
        return t

    # ------------------------------------------------------------------ warm starts
    def seeds(self, targets: np.ndarray, world: World | None = None) -> np.ndarray:
        """Warm starts for the solver: (P, 4, 4) targets (or one (4, 4)) -> (P, n_heads,
        n_dof) float64. A world-aware network needs ``world`` (its BPS is computed with the
        network's basis point set and cached); a world-unaware one ignores it."""
        T = np.asarray(targets)
        if T.shape == (4, 4):
            T = T[None]
        if T.ndim != 3 or T.shape[1:] != (4, 4):
            raise ValueError(f"targets: expected (P, 4, 4), got {T.shape}")
        P = T.shape[0]
        p = self.out.weight
        buf = self._buf.get(P)
        if buf is None or buf[0].dtype != p.dtype:
            np_dt = np.float64 if p.dtype == torch.float64 else np.float32
            arr = np.empty((P, feature_size(self.dim)), np_dt)
            buf = (torch.from_numpy(arr), arr)
            self._buf = {P: buf}
        frame_features_numpy(T, self.dim, out=buf[1])
        with torch.inference_mode():
            x = buf[0] if p.device.type == "cpu" else buf[0].to(p.device)
            b = None
            if self.bps is not None:
                if world is None:
                    raise ValueError("world: this network is world-aware (n_bps > 0); "
                                     "give the world to compute its basis point set")
                b = self.world_bps(world).expand(P, -1)
            q = self.codec.decode(self(x, b))
            return q.to(device="cpu", dtype=torch.float64).numpy().copy()
