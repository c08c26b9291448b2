"""Direction-dependent joint errors (the ``backlash`` group, issue 38 item 2).

A joint with backlash or hysteresis stops on one side of its dead band or the other,
depending on the direction it last moved in: the links see ``q'_j = q_j + dq_j(q_j) + b_j
s_j`` with ``s_j = +1`` after a positive move, ``-1`` after a negative one (``dq``: the
``harmonic`` transmission errors). The direction of a sample comes from the previous
sample in measurement order (:func:`motion_directions`) or is given
(``CalibrationOptions.directions``); 0 where unknown (the first sample, a joint that has
not moved yet), so that sample sees no backlash. The calibrated robot records b in
``notes['backlash']``; :func:`~jwarp.calibration.estimate.result.model_frames`,
``predict`` and ``errors`` apply it when given ``directions``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from jwarp.core.types import ArrayLike


def motion_directions(q: ArrayLike) -> np.ndarray:
    """(S, n_dof) the direction (+1, -1; 0 unknown) each joint last moved in, for samples
    q (S, n_dof) in measurement order: ``sign(q_i - q_{i-1})``, the previous sample's
    direction where a joint did not move, 0 before its first move."""
    qa = np.asarray(q, np.float64)
    if qa.ndim != 2:
        raise ValueError(f"q: expected (S, n_dof) joint values, got shape {qa.shape}")
    d = np.zeros_like(qa)
    if len(qa) > 1:
        d[1:] = np.sign(np.diff(qa, axis=0))
    # forward fill: where a joint did not move, the direction it last moved in
    idx = np.where(d != 0, np.arange(len(qa))[:, None], 0)
    np.maximum.accumulate(idx, axis=0, out=idx)
    return np.take_along_axis(d, idx, axis=0)


def check_directions(directions: Any, S: int, n_dof: int, name: str = "directions"
                     ) -> np.ndarray:
    """``directions`` as a float64 (S, n_dof) array of -1, 0, +1 (ValueError naming
    ``name`` otherwise)."""
    d = np.asarray(directions, np.float64)
    if d.shape != (S, n_dof):
        raise ValueError(f"{name}: expected shape ({S}, {n_dof}) (one direction per sample "
                         f"and joint), got {d.shape}")
    if not np.all((d == 1) | (d == -1) | (d == 0)):
        raise ValueError(f"{name}: expected -1, 0 or +1 (the direction each joint last "
                         f"moved in)")
    return d
