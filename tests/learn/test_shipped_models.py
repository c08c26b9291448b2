"""The warm-start networks shipped in jwarp/learn/models/ load for their robot (the
kinematics hash matches today's robot) and give seeds inside the joint limits."""

from pathlib import Path

import numpy as np
import pytest

import jwarp
from jwarp.learn.checkpoint import load_checkpoint

MODELS = Path(jwarp.__file__).resolve().parent / "learn" / "models"


@pytest.mark.parametrize("name, robot", [("planar5_random", "planar5"),
                                         ("justin19_shelf", "justin19")])
def test_shipped_model_loads_and_seeds_within_limits(name, robot):
    net = load_checkpoint(MODELS / f"{name}.pt", robot=robot)
    r = jwarp.robot(robot)
    q = jwarp.fk(r, np.zeros((1, r.n_dof)))
    T = q[:, r.frame_index(net.config.frame)]
    world = None
    if net.config.n_bps:
        from jwarp.learn.ik_data import make_worlds
        world = make_worlds(r, "random", 1, seed=123)[0]
    s = net.seeds(T, world)
    assert s.shape == (1, net.n_heads, r.n_dof) and np.isfinite(s).all()
    lim = r.joint_limits
    assert np.all(s >= lim[:, 0] - 1e-6) and np.all(s <= lim[:, 1] + 1e-6)
    with pytest.raises(ValueError):
        load_checkpoint(MODELS / f"{name}.pt", robot="arm7")
