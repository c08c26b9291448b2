"""Collision costs, gradients and distances against an independent numpy implementation
(tests/reference.py ``ref_fk`` for the frames, scipy for the SDF interpolation) and
central finite differences (float64)."""

import numpy as np
import pytest
import warp as wp
from devices import requires_cpu, requires_cuda
from reference import ref_fk, sample_q
from test_world import ref_lookup

import jwarp
from jwarp.world import random_configurations, simplex_world, world_from_occupancy
from jwarp.world.collision import (
    CollisionModel,
    collision_cost,
    collision_pairs,
    is_collision_free,
    min_distances,
    rigid_pairs,
    self_distances,
    sphere_distances,
)

EPS = 0.05


# ================================================================ reference
def ref_clip(d, eps):
    """Smooth clip c(d) of thesis eq. 3.10."""
    return np.where(d < 0, -d + eps / 2, np.where(d <= eps, (d - eps) ** 2 / (2 * eps), 0.0))


def ref_spheres(model, q, rho=None):
    f, p, r = model.sphere_arrays()
    F = ref_fk(model, q, dh=rho)[:, f]
    return np.einsum("bsij,sj->bsi", F[..., :3, :3], p) + F[..., :3, 3], r


def ref_allowed_pairs(model):
    """Sphere pairs (a < b) on frames allowed to collide, from the model alone."""
    f, _, _ = model.sphere_arrays()
    allowed = model.allowed_collision_pairs
    return {(a, b) for a in range(len(f)) for b in range(a + 1, len(f)) if allowed[f[a], f[b]]}


def ref_rigid(model, pairs):
    """Mask of pairs whose surface distance is the same (and positive) in 200 random
    configurations."""
    d = ref_self_dist(model, sample_q(model, 200, seed=21), sorted(pairs))
    return (d.max(0) - d.min(0) < 1e-9) & (d.min(0) > 0), d.min(0)


def ref_pairs(model):
    """The pairs the self-collision cost sums over: allowed, minus the rigid ones."""
    pairs = sorted(ref_allowed_pairs(model))
    if not pairs:
        return set()
    rigid, _ = ref_rigid(model, pairs)
    return {pr for pr, r in zip(pairs, rigid) if not r}


def ref_world_dist(model, q, world, rho=None):
    x, r = ref_spheres(model, q, rho)
    d = ref_lookup(world, x[..., :world.dim].reshape(-1, world.dim)).reshape(x.shape[:2])
    return d - r


def ref_self_dist(model, q, pairs, rho=None):
    x, r = ref_spheres(model, q, rho)
    a, b = np.array(pairs, int).reshape(-1, 2).T
    return np.linalg.norm(x[:, a] - x[:, b], axis=-1) - r[a] - r[b]


def ref_cost(model, q, world, w_world=1.0, w_self=1.0, eps=EPS, rho=None):
    cost = np.zeros(len(q))
    if world is not None:
        cost += w_world * ref_clip(ref_world_dist(model, q, world, rho), eps).sum(1)
    pairs = sorted(ref_pairs(model))
    if pairs:
        cost += w_self * ref_clip(ref_self_dist(model, q, pairs, rho), eps).sum(1)
    return cost


# ================================================================== fixtures
ROBOTS = ["justin19", "arm7", "planar4", "planar5", "sphere2d"]


def dense_world(model, seed=3):
    """A cluttered world over the robot's reach (many spheres in contact)."""
    dim = model.workspace_dim
    lim = np.array([[-1.6, 1.6], [-1.6, 1.6], [-0.8, 2.4]])[:dim] if model.name != "sphere2d" \
        else np.array([[-0.9, 0.9], [-0.9, 0.9]])  # sphere2d also leaves the grid
    return simplex_world(dim, seed=seed, shape=(24,) * dim, limits=lim, threshold=0.1,
                         frequency=3.0)


def sample(model, n, seed):
    return random_configurations(model, n, seed)


def perturbed_rho(model, n, seed):
    rng = np.random.default_rng(seed)
    rho = np.broadcast_to(model.dh_table, (n,) + model.dh_table.shape).copy()
    rho[..., [1, 3, 4]] += rng.normal(0, 0.02, (n, model.n_frames, 3)) * model.is_dh[:, None]
    return rho


# ===================================================================== tests
def test_pairs_match_allowed_matrix(device):
    for name in ROBOTS:
        model = jwarp.robot(name)
        got = collision_pairs(model)
        f, _, _ = model.sphere_arrays()
        assert {tuple(sorted(p)) for p in got.tolist()} == ref_pairs(model)
        assert len(got) == len(ref_pairs(model))
        assert np.all(f[got[:, 0]] < f[got[:, 1]])
        rp, rd = rigid_pairs(model)
        assert {tuple(p) for p in rp.tolist()} | {tuple(p) for p in got.tolist()} == ref_allowed_pairs(model)
    # justin19: the torso_3 sphere on the shoulder axis keeps 1.5 cm from both shoulder
    # bases in every configuration; those pairs would add a constant c(0.015) to the cost
    model = jwarp.robot("justin19")
    rp, rd = rigid_pairs(model)
    pairs = sorted(ref_allowed_pairs(model))
    rigid, dist = ref_rigid(model, pairs)
    assert {tuple(p) for p in rp.tolist()} == {pr for pr, r in zip(pairs, rigid) if r}
    np.testing.assert_allclose(np.sort(rd), np.sort(dist[rigid]), atol=1e-9)
    assert len(rp) >= 2 and rd.min() < EPS and len(collision_pairs(model)) == 906 - len(rp)
    q = sample(model, 500, seed=3)
    c, _ = collision_cost(model, q, None, device=device, dtype=np.float64, grad=False)
    assert (c == 0).sum() > 20  # free configurations cost exactly 0


@pytest.mark.parametrize("name", ROBOTS)
def test_cost_matches_numpy_reference(device, name):
    model = jwarp.robot(name)
    world = dense_world(model)
    q = sample(model, 64, seed=1)
    rho = perturbed_rho(model, 64, seed=2)
    for kw in (dict(), dict(w_world=2.5, w_self=0.3, eps=0.08), dict(rho=rho)):
        ref = ref_cost(model, q, world, **kw)
        cost, grad = collision_cost(model, q, world, device=device, dtype=np.float64, grad=False, **kw)
        assert grad is None
        np.testing.assert_allclose(cost, ref, rtol=1e-10, atol=1e-12)
    assert (ref > 0).sum() >= 8  # the dense world does collide
    c32, _ = collision_cost(model, q.astype(np.float32), world, device=device, grad=False)
    assert c32.dtype == np.float32
    np.testing.assert_allclose(c32, ref_cost(model, q, world), rtol=2e-4, atol=2e-4)
    # self-collision only (no world)
    np.testing.assert_allclose(collision_cost(model, q, None, device=device, dtype=np.float64,
                                              grad=False)[0], ref_cost(model, q, None), atol=1e-12)


def off_kinks(model, q, world, rho=None):
    """Mask of configurations whose sphere centres all lie off the cell planes of the
    piecewise-linear field (finite differences straddling a plane see a kink)."""
    x, _ = ref_spheres(model, q, rho)
    u = (x[..., :world.dim] - world.limits[:, 0]) / world.voxel_size
    return np.abs(u - np.round(u)).min(axis=(1, 2)) > 1e-3


def fd_grad(model, q, world, device, h=1e-6, **kw):
    g = np.zeros_like(q)
    for j in range(model.n_dof):
        dq = np.zeros(model.n_dof)
        dq[j] = h
        cp = collision_cost(model, q + dq, world, device=device, dtype=np.float64, grad=False, **kw)[0]
        cm = collision_cost(model, q - dq, world, device=device, dtype=np.float64, grad=False, **kw)[0]
        g[:, j] = (cp - cm) / (2 * h)
    return g


@pytest.mark.parametrize("name", ROBOTS)
def test_gradients_hand_and_tape_match_finite_differences(device, name):
    model = jwarp.robot(name)
    world = dense_world(model)
    q = sample(model, 12, seed=5)
    rho = perturbed_rho(model, 12, seed=6)
    keep = off_kinks(model, q, world) & off_kinks(model, q, world, rho)
    q, rho = q[keep], rho[keep]
    assert len(q) >= 8
    for kw in (dict(w_world=1.5, w_self=0.7), dict(rho=rho)):
        fd = fd_grad(model, q, world, device, **kw)
        assert np.abs(fd).max() > 0.1  # the configurations do touch something
        for tape in (False, True):
            cost, grad = collision_cost(model, q, world, device=device, dtype=np.float64,
                                        tape=tape, **kw)
            np.testing.assert_allclose(cost, ref_cost(model, q, world, **kw), atol=1e-12)
            np.testing.assert_allclose(grad, fd, rtol=0, atol=1e-6 * max(1.0, np.abs(fd).max()))


def test_coupled_torso_gradient_and_float32(device):
    """justin19's torso_3 frame follows q1 + q2 (coupling): the hand-written gradient
    spreads its moment on both joints."""
    model = jwarp.robot("justin19")
    world = dense_world(model, seed=8)
    q = sample(model, 40, seed=9)
    q = q[off_kinks(model, q, world)]
    c64, g64 = collision_cost(model, q, world, device=device, dtype=np.float64)
    fd = fd_grad(model, q, world, device)
    np.testing.assert_allclose(g64, fd, atol=1e-6 * np.abs(fd).max())
    c32, g32 = collision_cost(model, q.astype(np.float32), world.astype(np.float32), device=device)
    assert g32.dtype == np.float32
    scale = np.abs(g64).max()
    np.testing.assert_allclose(g32, g64, atol=2e-3 * scale)


def test_zero_cost_when_far_and_outside_grid(device):
    model = jwarp.robot("sphere2d")
    occ = np.zeros((11, 11), bool)
    occ[5, 5] = True
    world = world_from_occupancy(occ, np.array([[-0.25, 0.25], [-0.25, 0.25]]))  # voxel 0.05
    q = np.array([[0.0, 0.0], [0.9, 0.9], [0.0, 0.126], [0.0, 0.2]])
    cost, grad = collision_cost(model, q, world, device=device, dtype=np.float64)
    # centre inside the voxel: D = -0.025 - r; at 0.126: surface 0.101 - 0.05 > eps
    d0 = -0.025 - 0.05
    np.testing.assert_allclose(cost, [-d0 + EPS / 2, 0.0, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(grad[1:], 0.0)


def test_distances_and_collision_free(device):
    model = jwarp.robot("arm7")
    world = dense_world(model)
    q = sample(model, 50, seed=3)
    sd = sphere_distances(model, q, world, device=device, dtype=np.float64)
    np.testing.assert_allclose(sd, ref_world_dist(model, q, world), atol=1e-12)
    pairs = collision_pairs(model)
    pd = self_distances(model, q, device=device, dtype=np.float64)
    np.testing.assert_allclose(pd, ref_self_dist(model, q, pairs), atol=1e-12)
    md = min_distances(model, q, world, device=device, dtype=np.float64)
    np.testing.assert_allclose(md[:, 0], sd.min(1), atol=1e-12)
    np.testing.assert_allclose(md[:, 1], pd.min(1), atol=1e-12)
    for margin in (0.0, 0.05):
        free = is_collision_free(model, q, world, margin, device=device)
        np.testing.assert_array_equal(free, (sd.min(1) > margin) & (pd.min(1) > margin))
    # a robot without self-collision pairs: min self distance is inf
    md2 = min_distances(jwarp.robot("sphere2d"), np.zeros((2, 2)), None, device=device)
    assert np.all(np.isinf(md2))
    # batch dims are kept
    assert sphere_distances(model, q.reshape(5, 10, 7), world, device=device).shape == (5, 10, 14)


def test_warp_in_warp_out_and_preallocated_reuse(device):
    model = jwarp.robot("justin19")
    world = dense_world(model)
    cm = CollisionModel(model, world, device=device, dtype=np.float32)
    q_np = sample(model, 30, seed=4).astype(np.float32)
    q = wp.array(q_np, dtype=wp.float32, device=device)
    cost = wp.empty(30, dtype=wp.float32, device=device)
    grad = wp.empty((30, 19), dtype=wp.float32, device=device)
    c1, g1 = cm.cost(q, out_cost=cost, out_grad=grad)
    assert c1 is cost and g1 is grad
    ref1 = ref_cost(model, q_np.astype(np.float64), world)
    np.testing.assert_allclose(cost.numpy(), ref1, rtol=2e-4, atol=2e-4)
    q_np2 = sample(model, 30, seed=5).astype(np.float32)
    q.assign(q_np2)  # same buffers, new data: the replayed launch must see it
    cm.cost(q, out_cost=cost, out_grad=grad)
    np.testing.assert_allclose(cost.numpy(), ref_cost(model, q_np2.astype(np.float64), world),
                               rtol=2e-4, atol=2e-4)
    # the functional API returns Warp arrays for Warp input
    c, g = collision_cost(model, q, world, device=device)
    assert isinstance(c, wp.array) and isinstance(g, wp.array) and g.shape == (30, 19)
    with pytest.raises(ValueError, match="out_cost"):
        cm.cost(q, out_cost=wp.empty(3, dtype=wp.float32, device=device))
    with pytest.raises(TypeError, match="q"):
        cm.cost(wp.array(q_np.astype(np.float64), dtype=wp.float64, device=device))


def test_bad_inputs():
    world3 = simplex_world(3, seed=0, shape=(8, 8, 8))
    world2 = simplex_world(2, seed=0, shape=(8, 8))
    with pytest.raises(ValueError, match="world: a 3D world"):
        collision_cost(jwarp.robot("planar4"), np.zeros((2, 4)), world3, device="cpu")
    with pytest.raises(ValueError, match="world: a 2D world"):
        collision_cost(jwarp.robot("justin19"), np.zeros((2, 19)), world2, device="cpu")
    with pytest.raises(ValueError, match="world: a 2D world"):
        is_collision_free(jwarp.robot("arm7"), np.zeros((2, 7)), world2)
    with pytest.raises(ValueError, match="q"):
        collision_cost(jwarp.robot("planar4"), np.zeros((2, 5)), world2, device="cpu")
    with pytest.raises(ValueError, match="NaN"):
        collision_cost(jwarp.robot("planar4"), np.full((2, 4), np.nan), world2, device="cpu")
    with pytest.raises(ValueError, match="eps"):
        collision_cost(jwarp.robot("planar4"), np.zeros((2, 4)), world2, eps=0.0, device="cpu")
    with pytest.raises(ValueError, match="rho"):
        collision_cost(jwarp.robot("planar4"), np.zeros((2, 4)), world2, rho=np.zeros((3, 6, 5)), device="cpu")
    with pytest.raises(TypeError, match="world"):
        collision_cost(jwarp.robot("planar4"), np.zeros((2, 4)), np.zeros((8, 8)), device="cpu")
    with pytest.raises(ValueError, match="unknown robot"):
        collision_cost(jwarp.robot("nobody"), np.zeros((2, 4)), world2, device="cpu")
    with pytest.raises(ValueError, match="margin"):
        is_collision_free(jwarp.robot("planar4"), np.zeros((2, 4)), world2, margin=np.nan)


@requires_cuda
def test_cuda_matches_reference_and_cpu():
    model = jwarp.robot("justin19")
    world = dense_world(model)
    q = sample(model, 256, seed=12)
    q = q[off_kinks(model, q, world)]
    rho = perturbed_rho(model, len(q), seed=13)
    for kw in (dict(), dict(rho=rho, w_world=2.0, w_self=0.5)):
        c, g = collision_cost(model, q, world, device="cuda:0", dtype=np.float64, **kw)
        np.testing.assert_allclose(c, ref_cost(model, q, world, **kw), atol=1e-10)
        _, g_tape = collision_cost(model, q, world, device="cuda:0", dtype=np.float64, tape=True, **kw)
        np.testing.assert_allclose(g_tape, g, atol=1e-9)
        fd = np.zeros_like(g)
        for j in range(model.n_dof):
            dq = np.zeros(model.n_dof)
            dq[j] = 1e-6
            fd[:, j] = (collision_cost(model, q + dq, world, device="cuda:0", dtype=np.float64, grad=False, **kw)[0]
                        - collision_cost(model, q - dq, world, device="cuda:0", dtype=np.float64, grad=False, **kw)[0]) / 2e-6
        np.testing.assert_allclose(g, fd, atol=1e-6 * np.abs(fd).max())
    c32, g32 = collision_cost(model, q.astype(np.float32), world, device="cuda:0")
    np.testing.assert_allclose(c32, ref_cost(model, q, world), rtol=2e-4, atol=2e-4)
    md = min_distances(model, q, world, device="cuda:0", dtype=np.float64)
    np.testing.assert_allclose(md[:, 0], ref_world_dist(model, q, world).min(1), atol=1e-10)
    pd_ref = ref_self_dist(model, q, collision_pairs(model))
    np.testing.assert_allclose(md[:, 1], pd_ref.min(1), atol=1e-10)
    np.testing.assert_allclose(self_distances(model, q, device="cuda:0", dtype=np.float64), pd_ref,
                               atol=1e-10)
    np.testing.assert_allclose(sphere_distances(model, q, world, device="cuda:0", dtype=np.float64),
                               ref_world_dist(model, q, world), atol=1e-10)
    for margin in (0.0, 0.05):
        np.testing.assert_array_equal(
            is_collision_free(model, q, world, margin, device="cuda:0"),
            (ref_world_dist(model, q, world).min(1) > margin) & (pd_ref.min(1) > margin))
    # preallocated Warp buffers on the device, replayed launch
    cm = CollisionModel(model, world, device="cuda:0", dtype=np.float32)
    qw = wp.array(q.astype(np.float32), dtype=wp.float32, device="cuda:0")
    cost = wp.empty(len(q), dtype=wp.float32, device="cuda:0")
    grad = wp.empty((len(q), 19), dtype=wp.float32, device="cuda:0")
    for _ in range(2):
        cm.cost(qw, out_cost=cost, out_grad=grad)
    np.testing.assert_allclose(cost.numpy(), c32, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(grad.numpy(), g32, rtol=1e-4, atol=1e-4 * np.abs(g32).max())


@requires_cpu
def test_bench_collision_quick_cpu(tmp_path):
    """Smoke test of benchmarks/bench_collision.py (exit 0, rows and JSON written) on its
    default device, the CPU."""
    import json
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    out = tmp_path / "bench.json"
    proc = subprocess.run([sys.executable, str(root / "benchmarks" / "bench_collision.py"), "--quick",
                           "--robots", "planar4", "--json", str(out)],
                          cwd=root, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, f"stdout:\n{proc.stdout}\nstderr:\n{proc.stderr}"
    rows = json.loads(out.read_text())["rows"]
    ops = {(r["configs"], r["op"]) for r in rows}
    assert {("random", "cost+grad"), ("free", "cost+grad"), ("random", "tape grad")} <= ops
    assert all(r["us_per_config"] > 0 for r in rows)
    assert all(r["colliding"] == 0.0 for r in rows if r["configs"] == "free" and r["colliding"] is not None)


@requires_cpu
def test_one_configuration_check(monkeypatch, capsys):
    """"Is this configuration collision-free" has one implementation (issue 40):
    ``path_feasibility.collision_free`` (rigid and elastic) and ``jwarp free-config`` call
    ``is_collision_free``, with the same verdicts; the IK's mesh rescue calls
    ``mesh_certified`` (no copy of its depth rule elsewhere in the solvers)."""
    import pathlib

    from jwarp.cli import main
    from jwarp.world import collision as col
    from jwarp.world import path_feasibility as fz

    model = jwarp.robot("planar4")
    world = simplex_world(2, seed=3)
    q = random_configurations(model, 64, seed=2)
    calls = []
    real = col.is_collision_free

    def spy(*a, **k):
        calls.append(k.get("rho") is not None)
        return real(*a, **k)

    monkeypatch.setattr(col, "is_collision_free", spy)
    rigid = fz.collision_free(model, world, q, 0.01, self_margin=0.01, device="cpu")
    np.testing.assert_array_equal(rigid, real(model, q, world, 0.01, device="cpu"))
    assert 0 < rigid.sum() < len(q)
    fz.collision_free(model, world, q, 0.01, kappa=1e-3, device="cpu")
    assert calls == [False, True]
    assert main(["free-config", "--robot", "planar4", "--world", "simplex:seed=3", "--n",
                 "2", "--json"]) == 0
    capsys.readouterr()
    assert len(calls) > 2
    solvers = pathlib.Path(jwarp.__file__).parent / "solvers"
    copies = [str(p) for p in solvers.rglob("*.py") if "sphere_reach_past" in p.read_text()]
    assert not copies, copies
