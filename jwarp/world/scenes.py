"""Hand-made test scenes (occupancy boxes turned into signed distance worlds)."""

from __future__ import annotations

import numpy as np

from jwarp.world.sdf import World, world_from_occupancy


def shelf_world(voxel_size: float = 0.04) -> World:
    """A shelf in front of justin19 or arm7: two boards at z = 0.55 m and 1.05 m
    (x 0.7..1.1 m, |y| < 0.6 m, 6 cm thick) and a back wall at x = 1.12 m up to 1.3 m, on
    limits x -0.2..1.4, y -1..1, z 0..1.6 m [m]."""
    h = float(voxel_size)
    if not (np.isfinite(h) and 0.0 < h <= 0.2):
        raise ValueError(f"voxel_size: expected a size in (0, 0.2] m, got {voxel_size!r}")
    lim = np.array([[-0.2, 1.4], [-1.0, 1.0], [0.0, 1.6]])
    n = np.round((lim[:, 1] - lim[:, 0]) / h).astype(int) + 1
    X, Y, Z = np.meshgrid(*[lim[d, 0] + h * np.arange(n[d]) for d in range(3)], indexing="ij")
    inside_x = (X > 0.7) & (X < 1.1)
    boards = inside_x & (np.abs(Y) < 0.6) & ((np.abs(Z - 0.55) < 0.03) | (np.abs(Z - 1.05) < 0.03))
    back = (np.abs(X - 1.12) < 0.03) & (np.abs(Y) < 0.6) & (Z < 1.3)
    return world_from_occupancy(boards | back, lim, h)
