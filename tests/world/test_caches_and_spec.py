"""Caches keyed by robot content (jwarp.world.feasibility.robot_reach,
jwarp.learn.torch_costs objectives): equal robots share an entry, an edited copy gets its
own, correct one. And parse_world_spec's ``device``: handed on to every robot computation
that builds a simplex world."""

import importlib

import numpy as np
import pytest
import warp as wp

import jwarp
from jwarp.kinematics.fk import fk as reference_fk  # bound before any test wraps the module's
from jwarp.model import Joint
from jwarp.world import parse_world_spec, random_configurations, robot_reach

# the modules (jwarp.kinematics.fk is also the name of the function the package exports)
kinematics_fk = importlib.import_module("jwarp.kinematics.fk")
world_collision = importlib.import_module("jwarp.world.collision")


def _record_devices(monkeypatch, module, name):
    """Wraps ``module.name`` (its callers import it at call time): each call's ``device``
    argument is recorded in the list returned."""
    calls = []
    fn = getattr(module, name)

    def recording(*args, **kwargs):
        calls.append(kwargs.get("device"))
        return fn(*args, **kwargs)

    monkeypatch.setattr(module, name, recording)
    return calls


def _count_fk(monkeypatch):
    """The FK calls (robot_reach and fixed_spheres)."""
    return _record_devices(monkeypatch, kinematics_fk, "fk")


def _reach_numpy(robot, n, seed):
    """robot_reach computed here: the sphere boxes of the same random configurations."""
    q = random_configurations(robot, n, seed)
    f, pos, rad = robot.sphere_arrays()
    T = reference_fk(robot, q, device="cpu", dtype=np.float64)[:, f]  # not counted
    x = np.einsum("bsij,sj->bsi", T[..., :3, :3], pos) + T[..., :3, 3]
    d = robot.workspace_dim
    return np.stack([(x - rad[:, None]).min(axis=(0, 1))[:d],
                     (x + rad[:, None]).max(axis=(0, 1))[:d]], axis=1)


def _narrower(robot, factor=0.4):
    """A copy whose joint limits are ``factor`` times as wide (about their middle)."""
    joints = []
    for j in robot.joints:
        mid, half = 0.5 * (j.lower + j.upper), 0.5 * (j.upper - j.lower)
        joints.append(Joint(j.name, j.type, mid - factor * half, mid + factor * half))
    return robot.copy(joints=joints)


def test_robot_reach_is_shared_by_equal_robots_and_recomputed_for_an_edited_copy(monkeypatch):
    base = jwarp.robot("arm7").copy(description="reach cache test")  # a content no test had
    a, b = base.copy(), base.copy()
    assert a is not b
    calls = _count_fk(monkeypatch)
    n, seed = 300, 71
    box_a = robot_reach(a, n=n, seed=seed)
    box_b = robot_reach(b, n=n, seed=seed)
    assert len(calls) == 1, "an equal robot (another object) computed the reach again"
    np.testing.assert_array_equal(box_a, box_b)
    np.testing.assert_allclose(box_a, _reach_numpy(a, n, seed), rtol=0, atol=1e-12)
    box_a[:] = 0.0  # the caller's copy: the cached box stays
    np.testing.assert_array_equal(robot_reach(b, n=n, seed=seed), box_b)
    assert len(calls) == 1

    narrow = _narrower(a)   # other limits
    longer = a.with_dh(a.dh_table + np.where(a.is_dh[:, None], [0.05, 0, 0.05, 0, 0], 0.0))
    for edited in (narrow, longer):
        box = robot_reach(edited, n=n, seed=seed)
        np.testing.assert_allclose(box, _reach_numpy(edited, n, seed), rtol=0, atol=1e-12)
        assert not np.allclose(box, box_b)
    assert len(calls) == 3
    robot_reach(_narrower(a), n=n, seed=seed)  # equal to `narrow`: shared
    assert len(calls) == 3


def test_torch_objectives_are_shared_by_equal_robots_and_rebuilt_for_an_edited_copy():
    torch = pytest.importorskip("torch")
    from jwarp.learn.torch_costs import ik_objective, path_objective, u_ik
    from jwarp.solvers.ik import IKObjective

    base = jwarp.robot("arm7").copy(description="objective cache test")
    a, b = base.copy(), base.copy()
    oa = ik_objective(a, "tcp", 5, dtype=np.float64)
    assert ik_objective(b, "tcp", 5, dtype=np.float64) is oa
    edited = a.with_dh(a.dh_table + np.where(a.is_dh[:, None], [0.03, 0.1, 0.02, 0, 0], 0.0))
    oe = ik_objective(edited, "tcp", 5, dtype=np.float64)
    assert oe is not oa
    np.testing.assert_array_equal(oe.robot.dh_table, edited.dh_table)

    rng = np.random.default_rng(4)
    lim = a.joint_limits
    q = rng.uniform(lim[:, 0], lim[:, 1], (5, a.n_dof))
    target = jwarp.fk(a, rng.uniform(lim[:, 0], lim[:, 1], (5, a.n_dof)), device="cpu",
                      dtype=np.float64)[:, a.frame_index("tcp")]
    qt, tt = torch.tensor(q), torch.tensor(target)
    got = {name: u_ik(qt, tt, robot, "tcp").numpy() for name, robot in
           (("a", a), ("b", b), ("edited", edited))}
    np.testing.assert_array_equal(got["a"], got["b"])
    fresh = IKObjective(edited, "tcp", 5, dtype=np.float64)  # built here, not from the cache
    wp.copy(fresh.q, wp.array(q, dtype=wp.float64, device="cpu"))
    wp.copy(fresh.target, wp.array(target, dtype=fresh.fk.mat44, device="cpu"))
    fresh.evaluate_pose()
    fresh.evaluate_aux()
    np.testing.assert_allclose(got["edited"], fresh.cost_f.numpy() + fresh.cost_a.numpy(),
                               rtol=1e-12, atol=0)
    assert not np.allclose(got["edited"], got["a"])

    world = parse_world_spec("simplex:seed=1,cells=16", jwarp.robot("planar4"))
    p4 = jwarp.robot("planar4").copy(description="objective cache test")
    po = path_objective(p4, world, 2, 4, 3, dtype=np.float64)
    assert path_objective(p4.copy(), world, 2, 4, 3, dtype=np.float64) is po
    assert path_objective(_narrower(p4), world, 2, 4, 3, dtype=np.float64) is not po


def test_parse_world_spec_hands_its_device_to_the_robot_computations(monkeypatch):
    robot = jwarp.robot("planar4").copy(description="world spec device test")
    spec = "simplex:seed=3,cells=24,feasible=5,samples=50,tries=3"
    default = parse_world_spec(spec, robot)  # as before: no device
    fk_devices = _count_fk(monkeypatch)
    checks = _record_devices(monkeypatch, world_collision, "is_collision_free")
    dev = wp.get_device("cpu")
    robot = robot.copy(description="world spec device test, again")  # reach not cached
    world = parse_world_spec(spec, robot, device=dev)
    assert fk_devices and all(d is dev for d in fk_devices), fk_devices  # reach, base spheres
    assert checks and all(d is dev for d in checks), checks              # feasible search
    if wp.get_preferred_device().is_cpu:  # the default device: the same world
        np.testing.assert_array_equal(world.sdf, default.sdf)
        assert world.meta["seed"] == default.meta["seed"]

    fk_devices.clear()
    checks.clear()
    parse_world_spec(spec, robot.copy(description="third"))  # the default is still None
    assert fk_devices and checks and all(d is None for d in fk_devices + checks)
    parse_world_spec("simplex:seed=2,cells=8,dim=2", device="cpu")  # no robot: no device use
