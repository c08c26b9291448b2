"""The Panda of example-robot-data with a coarse contained fit, and a box a few
millimetres from its hand (tests of the mesh certificate import this module by name)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

#: a Panda pose with the hand forward and level (the fingers open 3.5 cm)
GRASP_Q = np.array([0.0, -0.3, 0.0, -2.2, 0.0, 2.0, 0.8, 0.035, 0.035])


def coarse_panda(tmp_path_factory, **options):
    """(URDF path, model): the Panda fitted with ``SpherizeOptions(tolerance=0.03,
    pair_samples=300, **options)`` into a fresh cache (79 contained spheres reaching up to
    7 cm past the meshes: many poses the spheres refuse are free for the meshes); skips
    where example-robot-data is not installed."""
    from jwarp.importers.robot import example_robot_urdf
    from jwarp.world.spherize import SpherizeOptions, spherized_robot

    try:
        path = example_robot_urdf("panda")
    except ValueError as e:
        pytest.skip(str(e))
    mp = pytest.MonkeyPatch()
    mp.setenv("JWARP_CACHE", str(tmp_path_factory.mktemp("cache")))
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            model, _ = spherized_robot(path, SpherizeOptions(
                **{"tolerance": 0.03, "pair_samples": 300, **options}))
    finally:
        mp.undo()
    return path, model


def grasp_q(model) -> np.ndarray:
    """:data:`GRASP_Q` for ``model``'s joints, within its limits."""
    q = GRASP_Q[:model.n_dof]
    return np.clip(q, model.joint_limits[:, 0], model.joint_limits[:, 1])


def graze_box(model, q, gap):
    """A 10 cm box ``gap`` [m] beyond the robot's collision pieces along +x of the world at
    ``q``, level with the hand."""
    from jwarp.kinematics import fk
    from jwarp.world.primitives import Shape, pose_matrix

    X = np.asarray(fk(model, q[None], dtype=np.float64))[0]
    pts = np.concatenate([p.vertices @ X[p.frame, :3, :3].T + X[p.frame, :3, 3]
                          for p in model.collision_pieces.pieces])
    x = pts[:, 0].max() + gap + 0.05
    c = X[model.frame_index("panda_hand"), :3, 3]
    return Shape("box", np.array([0.1, 0.1, 0.1]), pose_matrix([x, c[1], c[2]]), "graze")
