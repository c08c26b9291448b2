"""Validation of calibration samples: joint values, observations and per-sample meta
columns, shared by the MAP solver and the result's predictions."""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from jwarp.core.types import ArrayLike
from jwarp.model import RobotModel

if TYPE_CHECKING:
    from jwarp.model.measurement import Measurement


def check_samples(robot: RobotModel, measurement: Measurement, q: ArrayLike, y: Any,
                  meta: Mapping[str, Any] | None = None
                  ) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray] | None]:
    """Validate joint values q (S, n_dof), observations y (S, m) and per-sample meta
    columns {name: (S,)}; returns float64 copies. Errors name the argument."""
    try:
        qa = np.array(q, dtype=np.float64)
    except (TypeError, ValueError):
        raise TypeError("q: expected an array of joint values") from None
    if qa.ndim != 2 or qa.shape[1] != robot.n_dof:
        raise ValueError(f"q: expected shape (S, {robot.n_dof}) for robot '{robot.name}', "
                         f"got {qa.shape}")
    if qa.shape[0] == 0:
        raise ValueError("q: no samples")
    bad = ~np.all(np.isfinite(qa), axis=1)
    if bad.any():
        raise ValueError(f"q: NaN or inf in sample(s) {np.nonzero(bad)[0][:10].tolist()}")
    m = len(measurement.obs_names)
    try:
        ya = np.array(y, dtype=np.float64)
    except (TypeError, ValueError):
        raise TypeError("y: expected an array of observations") from None
    if ya.shape != (qa.shape[0], m):
        raise ValueError(f"y: expected shape ({qa.shape[0]}, {m}) (samples of q x observations "
                         f"{measurement.obs_names}), got {ya.shape}")
    bad = ~np.all(np.isfinite(ya), axis=1)
    if bad.any():
        raise ValueError(f"y: NaN or inf in sample(s) {np.nonzero(bad)[0][:10].tolist()}")
    md = None
    names = list(getattr(measurement, "meta_names", []) or [])
    if names:
        if meta is None:
            raise ValueError(f"meta: measurement '{measurement.name}' needs the per-sample "
                             f"column(s) {names}")
        md = {}
        for k in names:
            if k not in meta:
                raise ValueError(f"meta: missing per-sample column '{k}'")
            a = np.asarray(meta[k])
            if a.shape != (qa.shape[0],):
                raise ValueError(f"meta['{k}']: expected shape ({qa.shape[0]},), got {a.shape}")
            md[k] = a
    elif meta is not None:
        md = dict(meta)
    return qa, ya, md
