"""Travel bounds of points fixed to a robot's frames (the continuous checks' reach).

:func:`point_reach`: for points on the robot (sphere centres, the enclosing spheres of the
mesh certificate's convex pieces), a bound of their distance from every ancestor joint's
axis over all configurations, so a segment moving the frame angles by ``dtheta`` moves a
point by at most ``sum_i reach_i |dtheta_i|`` (:mod:`jwarp.world.motion`,
:mod:`jwarp.world.mesh_check`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from jwarp.model import RobotModel

__all__ = ["point_reach"]


def point_reach(robot: RobotModel, frames: Any, positions: Any, extent: Any = None) -> np.ndarray:
    """(K, n_frames) float64: :func:`sphere_reach` of K points (``frames`` (K,) int,
    ``positions`` (K, 3) [m] in their frames), each grown by ``extent`` (K,) [m] (None: 0):
    a bound of the distance from frame i's joint axis of any point within ``extent`` of
    point k (a convex piece inside its enclosing sphere: :mod:`jwarp.world.mesh_check`)."""
    from jwarp.core.device import fixed_parts

    model = robot
    sf = np.asarray(frames, np.int64).reshape(-1)
    sp = np.asarray(positions, np.float64).reshape(-1, 3)
    ext = np.zeros(len(sf)) if extent is None else np.asarray(extent, np.float64).reshape(-1)
    nf = model.n_frames
    _, fixed_pos = fixed_parts(model)
    dh = model.dh_table
    prism = model.frame_is_prismatic
    lim = np.asarray(model.joint_limits, np.float64).reshape(-1, 2)
    step = np.zeros(nf)  # translation bound from the parent's origin to frame i's
    for i, f in enumerate(model.frames):
        if model.is_dh[i]:
            step[i] = abs(dh[i, 0]) + abs(dh[i, 2])
            if prism[i]:
                step[i] += sum(abs(c) * np.abs(lim[j]).max() for j, c in f.coupling)
        else:
            step[i] = float(np.linalg.norm(fixed_pos[i]))
    parents = model.parents
    out = np.zeros((len(sf), nf))
    for s, (fs, p) in enumerate(zip(sf, sp)):
        acc = float(np.linalg.norm(p)) + float(ext[s])
        i = int(fs)
        while i >= 0:
            out[s, i] = 1.0 if prism[i] else acc
            acc += step[i]
            i = int(parents[i])
    return out * (1.0 + 1e-9) + 1e-12


