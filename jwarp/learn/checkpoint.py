"""IK network checkpoints ("jwarp-ik-net" files, version 1; docs/learning.md,
"Checkpoint format").

A checkpoint is a ``torch.save`` of a plain dict (loadable with
``torch.load(weights_only=True)``: only dicts, lists, strings, numbers, bools, None and
tensors)::

    format            "jwarp-ik-net"
    version           1
    config            IKNetConfig as a dict
    state_dict        the network's weights and buffers
    robot             robot name
    kinematics_hash   jwarp.core.device.content_key(robot) (a hash of the robot's content)
    bps               BasisPointSet.to_dict() (world-aware networks) or None
    world_distribution  str or dict: what worlds the network was trained on
    training          TrainIKOptions as a dict (or {})
    jwarp_version, torch_version
    metrics           dict (last validation numbers, history)
    epoch             last finished epoch (0: untrained)
    optimizer_state   optimizer.state_dict() or None (for resuming)
    training_state    dict or None (the trainer's state besides the optimizer: hard set)

Files are written atomically (:class:`jwarp.utils.atomic.AtomicFile`).

Motion-planning networks (:class:`jwarp.learn.plan_net.PlanNet`) are written by the same
:func:`save_checkpoint` with ``format`` ``"jwarp-plan-net"`` (``config``: PlanNetConfig)
and read by :func:`load_plan_checkpoint`; each loader refuses the other's files.
"""

from __future__ import annotations

import os
import pickle
from pathlib import Path
from typing import TYPE_CHECKING, Any

import torch

from jwarp.core.arrays import device_name
from jwarp.core.device import content_key
from jwarp.core.types import DeviceLike
from jwarp.learn.ik_net import IKNet, IKNetConfig
from jwarp.learn.plan_net import PlanNet, PlanNetConfig
from jwarp.plugins.registry import robot as get_robot
from jwarp.utils.atomic import AtomicFile

if TYPE_CHECKING:
    from jwarp.model import RobotModel

__all__ = ["FORMAT", "PLAN_FORMAT", "VERSION", "save_checkpoint", "load_checkpoint",
           "load_plan_checkpoint", "read_checkpoint", "check_weights", "network_bytes"]

FORMAT = "jwarp-ik-net"
#: the format of motion-planning network checkpoints
PLAN_FORMAT = "jwarp-plan-net"
VERSION = 1
#: what each format holds, in the loaders' errors
_WHAT = {FORMAT: "jwarp IK network", PLAN_FORMAT: "jwarp motion-planning network"}


def _plain(x: Any) -> Any:
    """``x`` with numpy values turned into lists/floats (weights_only-loadable)."""
    import numpy as np

    if isinstance(x, dict):
        return {str(k): _plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_plain(v) for v in x]
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, torch.Tensor):
        return x.detach().cpu()
    if x is None or isinstance(x, (str, int, float, bool)):
        return x
    return str(x)


def save_checkpoint(path: str | os.PathLike, net: IKNet | PlanNet, *, world_distribution: Any = "",
                    training: dict | None = None, metrics: dict | None = None,
                    epoch: int = 0, optimizer_state: dict | None = None,
                    training_state: dict | None = None) -> Path:
    """Write ``net`` (an IKNet or a PlanNet) and what it is valid for to ``path``
    (atomically); returns the path."""
    from jwarp import __version__ as jwarp_version

    doc = {
        "format": PLAN_FORMAT if isinstance(net, PlanNet) else FORMAT, "version": VERSION,
        "config": _plain(net.config.to_dict()),
        "state_dict": {k: v.detach().cpu() for k, v in net.state_dict().items()},
        "robot": net.robot.name,
        "kinematics_hash": content_key(net.robot),
        "bps": _plain(net.bps.to_dict()) if net.bps is not None else None,
        "world_distribution": _plain(world_distribution),
        "training": _plain(training or {}),
        "jwarp_version": str(jwarp_version),
        "torch_version": str(torch.__version__),
        "metrics": _plain(metrics or {}),
        "epoch": int(epoch),
        "optimizer_state": optimizer_state,
        "training_state": _plain(training_state) if training_state is not None else None,
    }
    with AtomicFile(path) as f:
        torch.save(doc, f.tmp)
    return Path(path)


def read_checkpoint(path: str | os.PathLike, fmt: str = FORMAT) -> dict:
    """The checkpoint dict of ``path`` (checked to be a file of format ``fmt``: a
    jwarp-ik-net file by default); ValueError for anything else."""
    what = _WHAT[fmt]
    p = Path(path)
    if not p.is_file():
        raise ValueError(f"checkpoint: '{p}' does not exist or is not a file")
    try:
        doc = torch.load(p, map_location="cpu", weights_only=True)
    except (pickle.UnpicklingError, RuntimeError, EOFError, OSError, ValueError,
            AttributeError, ImportError, IndexError, KeyError, TypeError) as e:
        raise ValueError(f"checkpoint: '{p}' is not a {what} checkpoint "
                         f"(cannot be read by torch.load: {type(e).__name__}: "
                         f"{str(e).splitlines()[0] if str(e) else ''})") from None
    if not isinstance(doc, dict) or doc.get("format") != fmt:
        raise ValueError(f"checkpoint: '{p}' is not a {what} checkpoint "
                         f"(format field {doc.get('format') if isinstance(doc, dict) else None!r}, "
                         f"expected {fmt!r})")
    if doc.get("version") != VERSION:
        raise ValueError(f"checkpoint: '{p}' has format version {doc.get('version')!r}; this "
                         f"jwarp reads version {VERSION}")
    for k in ("config", "state_dict", "robot", "kinematics_hash"):
        if k not in doc:
            raise ValueError(f"checkpoint: '{p}' lacks the field '{k}'")
    return doc


def load_checkpoint(path: str | os.PathLike, robot: RobotModel | None = None, device: DeviceLike = None) -> IKNet:
    """The :class:`IKNet` of a checkpoint, on ``device`` (None: Warp's default device,
    docs/api.md "Devices") in eval mode, with ``.meta`` (every field but the weights and
    the optimizer state).

    ``robot`` (name or RobotModel; None: the checkpoint's robot from the registry): the
    robot the network is meant for; a different name or kinematics hash raises ValueError
    naming both.
    """
    doc = read_checkpoint(path)
    model, bps = _robot_and_bps(doc, path, get_robot(doc["robot"] if robot is None else robot))
    config = _config(IKNetConfig, doc, path)
    check_weights(IKNet, config, bps, doc, path)   # before any weight is allocated
    net = IKNet(config, bps=bps)
    return _finish(net, model, doc, path, device)


def load_plan_checkpoint(path: str | os.PathLike, robot: RobotModel | None = None, device: DeviceLike = None
                         ) -> PlanNet:
    """The :class:`PlanNet` of a ``"jwarp-plan-net"`` checkpoint, as :func:`load_checkpoint`
    (ValueError for another robot or kinematics hash, or a file of another format)."""
    doc = read_checkpoint(path, PLAN_FORMAT)
    model, bps = _robot_and_bps(doc, path, get_robot(doc["robot"] if robot is None else robot))
    config = _config(PlanNetConfig, doc, path)
    check_weights(PlanNet, config, bps, doc, path)  # before any weight is allocated
    net = PlanNet(config, bps=bps)
    return _finish(net, model, doc, path, device)


def _config(cls: Any, doc: dict, path: Any) -> Any:
    """The network config of the checkpoint (ValueError naming the file when it is not
    a valid config)."""
    try:
        return cls.from_dict(doc["config"])
    except (ValueError, TypeError, KeyError, AttributeError) as e:
        raise ValueError(f"checkpoint: '{path}' has an invalid config ({type(e).__name__}: "
                         f"{' '.join(str(e).split())})") from None


def _shape_text(shape: tuple) -> str:
    return "(" + ", ".join(str(d) for d in shape) + ")"


def check_weights(cls: Any, config: Any, bps: Any, doc: dict, path: Any) -> None:
    """Check the stored weights against the network the config declares, before any
    weight is allocated: the network is built on torch's ``meta`` device (shapes only, no
    memory), its parameter shapes compared with the file's ``state_dict``, and its size
    against the available memory (:mod:`jwarp.utils.memory`). A mismatch (a damaged or edited
    file: e.g. a 9 kB file whose config says hidden=40000) is a ValueError naming the
    file, the config fields and the first differing tensors; too large a network a
    MemoryError with the figure."""
    from jwarp.utils.memory import check_memory, format_bytes

    stored = doc["state_dict"]
    if not isinstance(stored, dict) or not all(isinstance(v, torch.Tensor)
                                               for v in stored.values()):
        raise ValueError(f"checkpoint: '{path}': its state_dict is not a dict of tensors")
    try:
        with torch.device("meta"):
            ref = cls(config, bps=bps)
    except (ValueError, TypeError, RuntimeError) as e:
        raise ValueError(f"checkpoint: '{path}' has an invalid config ({type(e).__name__}: "
                         f"{' '.join(str(e).split())})") from None
    want = {k: tuple(v.shape) for k, v in ref.state_dict().items()}
    have = {k: tuple(v.shape) for k, v in stored.items()}
    fields = ", ".join(f"{k}={v}" for k, v in config.to_dict().items()
                       if k in ("hidden", "n_blocks", "n_bps", "n_heads", "n_waypoints",
                                "twin", "unit_vectors"))
    missing = [k for k in want if k not in have]
    extra = [k for k in have if k not in want]
    other = [k for k in want if k in have and want[k] != have[k]]
    if missing or extra or other:
        parts = []
        if other:
            parts.append(f"{len(other)} tensor(s) of another shape (e.g. '{other[0]}': the "
                         f"config makes {_shape_text(want[other[0]])}, the file holds "
                         f"{_shape_text(have[other[0]])})")
        if missing:
            parts.append(f"{len(missing)} missing (e.g. '{missing[0]}')")
        if extra:
            parts.append(f"{len(extra)} unexpected (e.g. '{extra[0]}')")
        raise ValueError(f"checkpoint: '{path}': its config ({fields}) does not match its "
                         f"weights: {'; '.join(parts)}; the file is damaged or was edited "
                         f"(nothing was allocated)")
    need = 4.0 * sum(int(torch.Size(s).numel()) for s in want.values())
    check_memory(need, f"the network of '{path}' ({fields}; {format_bytes(need)} of float32 "
                       f"weights)", "this checkpoint cannot be loaded here")


def _robot_and_bps(doc: dict, path: Any, model: RobotModel) -> tuple[Any, Any]:
    key = content_key(model)
    if model.name != doc["robot"] or key != doc["kinematics_hash"]:
        raise ValueError(f"checkpoint: '{path}' is for robot '{doc['robot']}' (kinematics "
                         f"hash {doc['kinematics_hash']}), not for robot '{model.name}' "
                         f"(kinematics hash {key})")
    bps = None
    if doc.get("bps") is not None:
        from jwarp.learn.bps import BasisPointSet
        bps = BasisPointSet.from_dict(doc["bps"])
    return model, bps


def _finish(net: Any, model: RobotModel, doc: dict, path: Any, device: DeviceLike) -> Any:
    net.robot = model
    net.load_state_dict(doc["state_dict"])
    net.to(device_name(device))
    net.eval()
    net.meta = {k: v for k, v in doc.items() if k not in ("state_dict", "optimizer_state")}
    net.meta["path"] = str(path)
    return net


#: bytes per float32 parameter while training with Adam: weights, gradients, 2 moments
TRAIN_BYTES_PER_PARAM = 16


def network_bytes(cls: Any, config: Any, *, training: bool = False) -> float:
    """The memory [bytes] of the network ``cls(config)`` (float32 weights; ``training``:
    with gradients and Adam's moments, :data:`TRAIN_BYTES_PER_PARAM`), counted on
    torch's ``meta`` device: nothing is allocated. A world-aware network's basis point set
    is left out (small)."""
    with torch.device("meta"):
        try:
            net = cls(config)
        except TypeError:
            net = cls(config, bps=None)
    n = sum(int(p.numel()) for p in net.parameters())
    return float(n) * (TRAIN_BYTES_PER_PARAM if training else 4)
