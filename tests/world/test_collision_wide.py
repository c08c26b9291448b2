"""The wide collision cost (jwarp/kernels/collision_wide.py) against the fused kernel, the
numpy reference and finite differences, on every device (the wide launches run on the CPU
too when asked for)."""

import numpy as np
import pytest
import warp as wp
from test_collision import ROBOTS, dense_world, fd_grad, off_kinks, perturbed_rho, ref_cost, sample

import jwarp
from jwarp.core.device import put_model
from jwarp.kinematics.compensation import CompensationRows
from jwarp.world import World
from jwarp.world.collision import CollisionModel, default_wide


def both(model, world, q, device, dtype=np.float64, **kw):
    """(cost, grad) of the fused and of the wide launches, numpy."""
    scalar = wp.float64 if dtype == np.float64 else wp.float32
    qa = wp.array(q.astype(dtype), dtype=scalar, device=device)
    out = []
    for wide in (False, True):
        cm = CollisionModel(model, world, device=device, dtype=dtype, wide=wide)
        assert cm.wide is wide
        c, g = cm.cost(qa, **kw)
        out.append((c.numpy().copy(), None if g is None else g.numpy().copy()))
    return out


@pytest.mark.parametrize("name", ROBOTS)
def test_wide_equals_fused_and_reference(device, name):
    model = jwarp.robot(name)
    world = dense_world(model)
    q = sample(model, 48, seed=11)
    rho = perturbed_rho(model, 48, seed=12)
    for kw in (dict(), dict(w_world=2.5, w_self=0.3, eps=0.08), dict(rho=rho),
               dict(rho=model.dh_table), dict(w_self=0.0), dict(w_world=0.0)):
        (c0, g0), (c1, g1) = both(model, world, q, device, **kw)
        ref = ref_cost(model, q, world, **{k: v for k, v in kw.items()})
        np.testing.assert_allclose(c1, ref, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(c1, c0, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(g1, g0, rtol=1e-10, atol=1e-10 * max(1.0, np.abs(g0).max()))
        if not kw:
            assert (c0 > 0).sum() >= 8 and np.abs(g0).max() > 0.1  # the cases do touch
    # no world: self-collision only
    (c0, g0), (c1, g1) = both(model, None, q, device)
    np.testing.assert_allclose(c1, c0, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(g1, g0, atol=1e-10 * max(1.0, np.abs(g0).max()))
    # float32: the same terms in another summation order
    (c0, g0), (c1, g1) = both(model, world.astype(np.float32), q, device, dtype=np.float32)
    np.testing.assert_allclose(c1, c0, rtol=2e-5, atol=2e-5 * max(1.0, c0.max()))
    np.testing.assert_allclose(g1, g0, atol=2e-5 * max(1.0, np.abs(g0).max()))
    # cost only
    (c0, g0), (c1, g1) = both(model, world, q, device, grad=False)
    assert g0 is None and g1 is None
    np.testing.assert_allclose(c1, c0, rtol=1e-12, atol=1e-12)


def test_wide_recorded_launches_replay_on_new_values(device):
    """A planner's loop (preallocated outputs and data): the wide launches are recorded on
    the first call and replayed after; a replay reads the new configurations."""
    model = jwarp.robot("justin19")
    world = dense_world(model)
    q1, q2 = sample(model, 32, seed=13), sample(model, 32, seed=14)
    cm = CollisionModel(model, world, device=device, dtype=np.float64, wide=True)
    ref = CollisionModel(model, world, device=device, dtype=np.float64, wide=False)
    d = cm.make_data(32)
    qa = wp.array(q1, dtype=wp.float64, device=device)
    for q in (q1, q2, q1):
        wp.copy(qa, wp.array(q, dtype=wp.float64, device=device))
        c, g = cm.cost(qa, data=d, out_cost=d.cost, out_grad=d.grad)
        c0, g0 = ref.cost(wp.array(q, dtype=wp.float64, device=device))
        np.testing.assert_allclose(c.numpy(), c0.numpy(), rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(g.numpy(), g0.numpy(),
                                   atol=1e-10 * max(1.0, np.abs(g0.numpy()).max()))
    assert not np.allclose(cm.cost(wp.array(q2, dtype=wp.float64, device=device))[0].numpy(),
                           c.numpy())  # the two batches differ: the replay did read q


def test_wide_gradient_matches_finite_differences(device):
    """justin19's coupled torso: the wide gradient spreads the frame moments through the
    couplings as the fused one does; both against central differences."""
    model = jwarp.robot("justin19")
    world = dense_world(model, seed=8)
    q = sample(model, 24, seed=9)
    q = q[off_kinks(model, q, world)]
    cm = CollisionModel(model, world, device=device, dtype=np.float64, wide=True)
    c, g = cm.cost(wp.array(q, dtype=wp.float64, device=device))
    fd = fd_grad(model, q, world, device)
    assert np.abs(fd).max() > 0.1
    np.testing.assert_allclose(g.numpy(), fd, atol=1e-6 * np.abs(fd).max())


def test_wide_exact_objects_batches_of_worlds_and_frozen_rows(device):
    """Exact objects, a batch of worlds (``group_div``) and frozen rows (``active``): the
    wide launches give the fused kernel's values, frozen rows cost 0 with a zero gradient."""
    robot = jwarp.robot("arm7")
    rng = np.random.default_rng(3)
    worlds = []
    for _ in range(3):
        w = World.of_shapes()
        for j in range(4):
            w.add(f"b{j}", "box", rng.uniform(0.1, 0.3, 3),
                  rng.uniform([-0.5, -0.5, 0.1], [0.5, 0.5, 0.9]))
        w.add("ball", "sphere", 0.15, rng.uniform([-0.4, -0.4, 0.3], [0.4, 0.4, 0.8]))
        worlds.append(w)
    batch = World.batch(worlds)
    q = sample(robot, 30, seed=4)
    active = wp.array(np.array([1, 0, 1, 1, 0, 1], np.int32), dtype=wp.int32, device=device)
    for world, kw in ((worlds[0], {}), (batch, dict(group_div=10)),
                      (batch, dict(group_div=10, active=active, active_div=5))):
        (c0, g0), (c1, g1) = both(robot, world, q, device, **kw)
        np.testing.assert_allclose(c1, c0, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(g1, g0, atol=1e-10 * max(1.0, np.abs(g0).max()))
        assert (c0 > 0).sum() >= 5
        if "active" in kw:
            frozen = np.repeat(active.numpy() == 0, 5)
            assert np.all(c1[frozen] == 0) and np.all(g1[frozen] == 0)
            assert np.any(c1[~frozen] > 0)


def test_wide_with_compensation_rows_and_their_update(device):
    """Rows kept per waypoint (the elastic compensation of a planner): the wide launches
    read each substep's row as the fused kernel does, and the torque update made in the
    FK launch equals the fused kernel's."""
    model = jwarp.robot("justin19")
    world = dense_world(model, seed=2)
    P, W, n_sub = 3, 4, 3
    S = (W - 1) * n_sub + 1
    q = sample(model, P * S, seed=21)
    qa = wp.array(q, dtype=wp.float64, device=device)
    dm = put_model(model, device, np.float64)
    res = []
    for wide in (False, True):
        rows = CompensationRows(dm, P, W, n_sub, 3e-3, 0.5)
        cm = CollisionModel(model, world, device=device, dtype=np.float64, wide=wide)
        c, g = cm.cost(qa, rho=rows, eps=0.05)
        c, g = c.numpy().copy(), g.numpy().copy()
        cm.cost(qa, rho=rows, eps=0.05, update_rows=True)
        res.append((c, g, rows.rows.numpy().copy(), rows.delta.numpy().copy()))
    (c0, g0, r0, d0), (c1, g1, r1, d1) = res
    assert np.any(c0 > 0) and np.any(d0 > 0)
    np.testing.assert_allclose(c1, c0, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(g1, g0, atol=1e-10 * max(1.0, np.abs(g0).max()))
    np.testing.assert_allclose(r1, r0, rtol=0, atol=1e-14)
    np.testing.assert_allclose(d1, d0, rtol=0, atol=1e-14)


def test_wide_choice_and_bad_values(monkeypatch):
    from jwarp.world.collision import WIDE_MAX_CONFIGS

    with pytest.raises(TypeError, match="wide"):
        CollisionModel(jwarp.robot("arm7"), None, device="cpu", wide="yes")
    assert CollisionModel(jwarp.robot("arm7"), None, device="cpu").wide is None  # by the batch size
    monkeypatch.setenv("JWARP_COST_KERNEL", "fast")
    with pytest.raises(ValueError, match="JWARP_COST_KERNEL"):
        default_wide("cpu", 10)
    monkeypatch.setenv("JWARP_COST_KERNEL", "wide")
    assert default_wide("cpu", 10) and default_wide("cpu", 10 * WIDE_MAX_CONFIGS)
    monkeypatch.setenv("JWARP_COST_KERNEL", "fused")
    assert not default_wide("cpu", 10)
    monkeypatch.delenv("JWARP_COST_KERNEL")
    assert not default_wide("cpu", 10)  # auto: the fused kernel on the CPU
    if wp.is_cuda_available():
        assert default_wide("cuda:0", WIDE_MAX_CONFIGS)
        assert not default_wide("cuda:0", WIDE_MAX_CONFIGS + 1)


def primitive_scene(rng, n_objects=8, extent=1.0, clear=0.7, top=1.2):
    """Exact objects of every primitive kind (no mesh) within ``extent`` [m] of the base,
    ``clear`` [m] from its vertical axis, up to ``top`` [m], and a floor far below."""
    w = World.of_shapes()
    kinds = [("sphere", (0.12,)), ("box", (0.2, 0.1, 0.3)), ("cylinder", (0.08, 0.3)),
             ("capsule", (0.06, 0.2)), ("cone", (0.15, 0.25))]
    for j in range(n_objects):
        kind, dims = kinds[j % len(kinds)]
        T = np.eye(4)
        a = rng.normal(size=3)
        a *= rng.uniform(0, np.pi) / np.linalg.norm(a)
        from scipy.spatial.transform import Rotation
        T[:3, :3] = Rotation.from_rotvec(a).as_matrix()
        lo, hi = [-extent, -extent, 0.0], [extent, extent, top]
        T[:3, 3] = rng.uniform(lo, hi)
        while np.linalg.norm(T[:2, 3]) < clear:  # clear of the base column
            T[:3, 3] = rng.uniform(lo, hi)
        w.add(f"o{j}", kind, dims, T)
    T = np.eye(4)
    T[2, 3] = -1.0
    w.add("floor", "plane", (), T)
    return w


@pytest.mark.parametrize("name", ["arm7", "justin19"])
def test_bounding_sphere_skip_changes_no_bit(device, name, monkeypatch):
    """The fused kernel skips the object queries of a frame whose bounding sphere keeps eps
    from every object (worlds of primitives): cost and gradient are bit for bit those of
    the kernel that queries every sphere."""
    from jwarp.world.device_world import DeviceWorld

    robot = jwarp.robot(name)
    rng = np.random.default_rng(5)
    world = primitive_scene(rng) if name == "arm7" else primitive_scene(rng, 16, 1.4, 0.9, 1.8)
    q = sample(robot, 200, seed=6)
    for dtype, scalar in ((np.float64, wp.float64), (np.float32, wp.float32)):
        qa = wp.array(q.astype(dtype), dtype=scalar, device=device)
        cm = CollisionModel(robot, world, device=device, dtype=dtype, wide=False)
        assert cm.device_world.bound_skip
        c1, g1 = (a.numpy().copy() for a in cm.cost(qa, w_self=0.0))
        with monkeypatch.context() as m:
            m.setattr(DeviceWorld, "bound_skip", property(lambda self: False))
            cm2 = CollisionModel(robot, world, device=device, dtype=dtype, wide=False)
            c0, g0 = (a.numpy().copy() for a in cm2.cost(qa, w_self=0.0))
        assert (c0 > 0).sum() >= 20 and (c0 == 0).sum() >= 5  # touching and free ones
        np.testing.assert_array_equal(c1, c0)
        np.testing.assert_array_equal(g1, g0)
    # a mesh in the world: no skip (a winding-number sign need not be 1-Lipschitz)
    from types import SimpleNamespace

    v = 0.05 * np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
    f = np.array([[0, 2, 1], [1, 2, 3], [4, 5, 6], [5, 7, 6], [0, 1, 4], [1, 5, 4],
                  [2, 6, 3], [3, 6, 7], [0, 4, 2], [2, 4, 6], [1, 3, 5], [3, 7, 5]])
    world.add("m", "mesh", mesh=SimpleNamespace(vertices=v, faces=f))  # a closed cube
    assert not CollisionModel(robot, world, device=device, wide=False).device_world.bound_skip


def clustered_scene(robot, rng, device, n_clusters=3, per_cluster=24):
    """Tight clusters of many small boxes where the robot's last frame reaches (a link
    near one sees more objects than a candidate list holds), a few far objects, and a
    floor plane just below the base (a plane is no BVH object)."""
    from jwarp.kinematics import fk

    w = primitive_scene(rng, 4)
    tips = np.asarray(fk(robot, sample(robot, n_clusters, seed=21), device=device))[:, -1, :3, 3]
    for c, tip in enumerate(tips):
        for j in range(per_cluster):
            T = np.eye(4)
            T[:3, 3] = tip + rng.uniform(-0.04, 0.04, 3)
            w.add(f"c{c}_{j}", "box", (0.005, 0.005, 0.005), T)
    T = np.eye(4)
    T[2, 3] = -0.05
    w.add("floor_near", "plane", (), T)
    return w


def test_near_lists_change_no_bit(device, monkeypatch):
    """One BVH query per frame (its candidate list, or every sphere's own query where more
    objects than the list holds are near, or none at all): the cost, its gradient and the
    continuous check (verdicts, places, evaluations) are bit for bit those of the kernels
    that query every sphere, in a world of clusters, far objects and a near plane."""
    from jwarp.kernels.geometry import NEAR_MAX
    from jwarp.world.device_world import DeviceWorld
    from jwarp.world.motion import MotionCheck

    robot = jwarp.robot("arm7")
    rng = np.random.default_rng(8)
    world = clustered_scene(robot, rng, device)
    assert NEAR_MAX < 24  # a cluster overflows a list
    q = sample(robot, 300, seed=6)
    qa = wp.array(q, dtype=wp.float64, device=device)
    paths = np.stack([q[:-1:2], q[1::2]], axis=1)[:, [0, 0, 1, 1]]
    paths[:, 1] = 0.7 * paths[:, 0] + 0.3 * paths[:, 3]
    paths[:, 2] = 0.3 * paths[:, 0] + 0.7 * paths[:, 3]

    def run():
        cm = CollisionModel(robot, world, device=device, dtype=np.float64, wide=False)
        c, g = (a.numpy().copy() for a in cm.cost(qa, w_self=0.0, eps=0.05))
        chk = MotionCheck(robot, world, device=device).check(paths, margin=0.01, meshes=False)
        return cm.device_world.bound_skip, c, g, chk

    skip, c1, g1, k1 = run()
    assert skip
    with monkeypatch.context() as m:
        m.setattr(DeviceWorld, "bound_skip", property(lambda self: False))
        skip0, c0, g0, k0 = run()
    assert not skip0
    assert (c0 > 0).sum() >= 20 and (c0 == 0).sum() >= 20
    np.testing.assert_array_equal(c1, c0)
    np.testing.assert_array_equal(g1, g0)
    assert k0.ok.any() and not k0.ok.all()
    for name in ("ok", "code", "where", "what", "clearance"):
        np.testing.assert_array_equal(getattr(k1, name), getattr(k0, name))
    assert k1.evaluations == k0.evaluations
