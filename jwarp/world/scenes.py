"""Hand-made test scenes (occupancy boxes turned into signed distance worlds)."""

from __future__ import annotations

import numpy as np

from jwarp.utils.checks import check_int
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


#: the region of :func:`shelf_grasp_poses`: tool positions [m] (x, y, z ranges) in front of
#: the lower compartment of :func:`shelf_world`, and the spread of the hand's orientation
SHELF_GRASP_REGION = ((0.5, 0.62), (-0.5, 0.1), (0.72, 0.88))
SHELF_GRASP_SPREAD = 0.15


def shelf_grasp_poses(n: int, seed: int | np.random.Generator = 1) -> np.ndarray:
    """``n`` grasp poses (n, 4, 4) [m] for :func:`shelf_world`: the tool's position uniform
    in :data:`SHELF_GRASP_REGION` (between the boards, in front of the shelf), the hand
    pointing into the shelf (+x: a rotation of 90 deg about y) turned by a random rotation
    vector of standard deviation :data:`SHELF_GRASP_SPREAD` [rad] per axis. Not every pose
    is reachable. The task distribution of the shelf benchmarks and of the shelf IK
    networks' training targets; ``seed``: an int or a numpy Generator."""
    from scipy.spatial.transform import Rotation

    check_int(n, "n", 0)
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    base = Rotation.from_euler("y", 90, degrees=True)
    out = np.tile(np.eye(4), (int(n), 1, 1))
    for i in range(int(n)):
        out[i, :3, 3] = [rng.uniform(*SHELF_GRASP_REGION[d]) for d in range(3)]
        r = (base * Rotation.from_rotvec(rng.normal(scale=SHELF_GRASP_SPREAD, size=3))).as_rotvec()
        out[i, :3, :3] = Rotation.from_rotvec(r).as_matrix()
    return out
