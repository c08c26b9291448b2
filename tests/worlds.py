"""Worlds shared by tests of several modules."""

import numpy as np


def block_world():
    """A 30 cm thick block in front of justin19, 5 cm voxels."""
    from jwarp.world import world_from_occupancy

    h = 0.05
    lim = np.array([[-0.5, 1.5], [-1.0, 1.0], [0.0, 1.6]])
    n = np.round((lim[:, 1] - lim[:, 0]) / h).astype(int) + 1
    X, Y, Z = np.meshgrid(*[lim[d, 0] + h * np.arange(n[d]) for d in range(3)], indexing="ij")
    return world_from_occupancy((np.abs(X - 0.6) < 0.15) & (Z < 1.0), lim, h)


def block_world_2d():
    """README's 2D block world for planar4: a block at x 0.5..0.75 m, |y| < 0.12 m, on a
    64 x 64 grid over [-1, 1]^2 m."""
    from jwarp.world import world_from_occupancy

    lim = np.array([[-1.0, 1.0], [-1.0, 1.0]])
    h = 2.0 / 63
    X, Y = np.meshgrid(*[lim[d, 0] + h * np.arange(64) for d in range(2)], indexing="ij")
    return world_from_occupancy((X > 0.5) & (X < 0.75) & (np.abs(Y) < 0.12), lim, h)
