"""Type aliases of the public signatures: what a robot, an array, a device and a dtype argument
may be. For readers and type checkers only; the functions validate their arguments
themselves (TypeError/ValueError naming the argument)."""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import TYPE_CHECKING, Union

import numpy as np

if TYPE_CHECKING:
    import torch
    import warp as wp

    from jwarp.model import RobotModel

#: a robot: a :class:`~jwarp.model.RobotModel`, a registered name (``jwarp.robots()``) or a
#: robot file (jwarp JSON, URDF, MJCF)
RobotLike = Union["RobotModel", str, "os.PathLike[str]"]

#: an array argument: numpy (or anything ``np.asarray`` takes), a torch tensor or a Warp array;
#: results come back as the same kind
ArrayLike = Union[np.ndarray, "torch.Tensor", "wp.array", float, Sequence[float],
                  Sequence[Sequence[float]]]

#: a device: a Warp device, its name (``"cpu"``, ``"cuda:0"``), a torch device, or None (the
#: one rule, :func:`jwarp.core.arrays.resolve_device`: the inputs' device, else Warp's
#: default device)
DeviceLike = Union["wp.Device", str, "torch.device", None]

#: a computing dtype: float32 or float64 as numpy, Warp or a name (``"float32"``); None: that
#: of the input
DTypeLike = Union[type, str, np.dtype, None]  # noqa: UP007 (Union like the aliases above)
