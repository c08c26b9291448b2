"""The persistent planner (jwarp.solvers.planning.Planner, PlanOptions): buffers reused across
calls, seeds from the caller, the best start chosen on the device, options validated, and the
planner's device passed to every check."""

import sys

import numpy as np
import pytest
import warp as wp
from devices import requires_cpu

import jwarp
from jwarp.solvers import planning as PL
from jwarp.world import path_feasibility, world_from_occupancy

N_CELLS = 64
LIM2 = np.array([[-1.0, 1.0], [-1.0, 1.0]])
H2 = 2.0 / (N_CELLS - 1)
S4 = np.array([1.2, 0.0, 0.0, 0.0])
G4 = np.array([-1.2, 0.0, 0.0, 0.0])
FIELDS = ("path", "feasible", "cost", "length_cost", "collision_cost", "iterations",
          "start_index", "n_feasible", "all_paths", "all_feasible", "all_iterations")


@pytest.fixture(scope="module")
def block_world():
    """planar4's workspace with a block in front of the base at x in (0.5, 0.75)."""
    xs = LIM2[0, 0] + H2 * np.arange(N_CELLS)
    X, Y = np.meshgrid(xs, xs, indexing="ij")
    return world_from_occupancy((X > 0.5) & (X < 0.75) & (np.abs(Y) < 0.12), LIM2, H2)


def assert_equal_on(device, x, y, err_msg=""):
    """Bit for bit on the CPU; on CUDA the collision costs are sums of atomic adds, whose
    order varies between launches: paths agree to float32 rounding there."""
    if str(device).startswith("cuda") and np.asarray(x).dtype.kind == "f":
        np.testing.assert_allclose(x, y, rtol=1e-5, atol=1e-6, err_msg=err_msg)
    else:
        np.testing.assert_array_equal(x, y, err_msg=err_msg)


def assert_same(a, b, device="cpu"):
    for f in FIELDS:
        x, y = getattr(a, f), getattr(b, f)
        assert x.dtype == y.dtype and x.shape == y.shape, f
        assert_equal_on(device, x, y, err_msg=f)
    assert a.n_substeps == b.n_substeps


def test_planner_reuses_its_buffers_and_matches_plan(device, block_world):
    opts = PL.PlanOptions(n_starts=6, n_substeps=8, iterations=150, step=0.05, seed=2)
    planner = PL.Planner("planar4", block_world, 2, opts, device=device)
    assert planner.objective is None  # allocated by the first call
    starts = np.array([S4, [2.0, 1.0, 0.0, 0.0]])
    goals = np.array([G4, [2.0, -1.0, 0.0, 0.0]])
    first = planner.plan(starts, goals)
    obj = planner.objective
    buffers = (obj.q_sub, obj.sub_cost, obj.sub_grad, obj.total)
    # another problem in between (paths frozen by early stop, other seeds), then the first
    # again: the same buffers, and the same numbers as a fresh planner and as plan()
    planner.plan(np.array([[2.0, 0.0, 0.5, 0.0]] * 2), np.array([[2.5, 0.3, 0.0, 0.0]] * 2),
                 seeds=path_feasibility.initial_paths(np.array([[2.0, 0.0, 0.5, 0.0]] * 2),
                                        np.array([[2.5, 0.3, 0.0, 0.0]] * 2), 20,
                                        "straight")[:, None].repeat(6, axis=1))
    again = planner.plan(starts, goals)
    assert planner.objective is obj
    assert all(a is b for a, b in zip(buffers, (obj.q_sub, obj.sub_cost, obj.sub_grad,
                                                obj.total)))
    assert_same(first, again, device)
    ref = PL.plan("planar4", block_world, starts, goals, n_starts=6, n_substeps=8,
                  iterations=150, step=0.05, seed=2, device=device)
    assert_same(first, ref, device)
    assert first.feasible.all() and first.path.shape == (2, 20, 4)
    # a single start/goal is used for every problem
    one = planner.plan(S4, G4)
    np.testing.assert_allclose(one.path[:, [0, -1]], [[S4, G4]] * 2, atol=1e-6)


@requires_cpu
def test_device_copies_give_the_host_path_numbers(block_world):
    """The kernels that gather the candidates and keep the final paths (used on a GPU)
    give the numbers of the host's in-place reads (used on the CPU). CPU only: the host's
    in-place reads exist only there."""
    opts = PL.PlanOptions(n_starts=8, n_substeps=8, iterations=120, step=0.05,
                          check_all_every=3)
    starts = np.array([S4, [2.0, 1.0, 0.0, 0.0]])
    goals = np.array([G4, [2.0, -1.0, 0.0, 0.0]])
    host = PL.Planner("planar4", block_world, 2, opts, device="cpu")
    kern = PL.Planner("planar4", block_world, 2, opts, device="cpu")
    assert not host._kernel_copies
    kern._kernel_copies = True
    assert_same(host.plan(starts, goals), kern.plan(starts, goals))
    assert kern._buffers.cand_sub is not None and host._buffers.cand_sub is None


def test_elastic_planner_reuse_restarts_the_compensation_rows(device, block_world):
    opts = PL.PlanOptions(n_starts=4, n_substeps=6, iterations=60, step=0.05, kappa=1e-3)
    planner = PL.Planner("planar4", block_world, 1, opts, device=device)
    a = planner.plan(S4, G4)
    b = planner.plan(S4, G4)
    assert_same(a, b, device)
    assert_same(a, PL.plan("planar4", block_world, S4, G4, n_starts=4, n_substeps=6,
                           iterations=60, step=0.05, kappa=1e-3, device=device), device)


def test_caller_seeds_paths_and_via_points(device, block_world):
    robot = jwarp.robot("planar4")
    s = np.array([[2.0, 1.0, 0.0, 0.0], [2.0, 0.0, 0.5, 0.0]])
    g = np.array([[2.0, -1.0, 0.0, 0.0], [2.5, 0.3, 0.0, 0.0]])
    line = path_feasibility.initial_paths(s, g, 8, "straight")
    seeds = np.stack([line, line + 0.05, line - 0.05], axis=1)  # (B, 3 seeds, W, n)
    planner = PL.Planner(robot, block_world, 2, PL.PlanOptions(iterations=30), device=device)
    res = planner.plan(s, g, seeds=seeds)
    assert res.path.shape == (2, 8, 4) and res.all_feasible.shape == (2, 3)
    assert res.feasible.all()
    np.testing.assert_allclose(res.path[:, [0, -1]], np.stack([s, g], axis=1), atol=1e-6)
    # via points: start -> via -> goal, the option's n_waypoints spread along it
    via = PL.ViaPoints(np.array([[[[1.6, 0.0, 0.0, 0.0]]], [[[2.2, 0.2, 0.2, 0.0]]]]))
    res = planner.plan(s, g, seeds=via)  # (B, 1 seed, 1 via point, n)
    assert res.path.shape == (2, 20, 4) and res.all_feasible.shape == (2, 1)
    # (shorten=0: the seed's path as it is, not pulled straight)
    as_is = PL.Planner(robot, block_world, 2,
                       PL.PlanOptions(iterations=0, n_waypoints=9, shorten=0),
                       device=device).plan(s, g, seeds=via)
    expect = path_feasibility.polyline_path(s[0], np.array([[1.6, 0.0, 0.0, 0.0]]), g[0], 9)
    np.testing.assert_allclose(as_is.path[0], expect, atol=1e-6)
    assert np.abs(np.diff(np.linalg.norm(np.diff(expect, axis=0), axis=1))).max() < 1e-9
    with pytest.raises(ValueError, match="seeds: expected paths"):
        planner.plan(s, g, seeds=np.zeros((3, 8, 4, 4)))
    with pytest.raises(ValueError, match="seeds: contains NaN"):
        planner.plan(s, g, seeds=np.full((8, 4), np.nan))
    with pytest.raises(ValueError, match="seeds: expected via points"):
        planner.plan(s, g, seeds=PL.ViaPoints(np.zeros((2, 3))))


def test_best_start_is_chosen_on_the_device_and_all_paths_read_on_demand(device, block_world):
    # (shorten=0: the chosen start's path as it ended, not pulled straight)
    planner = PL.Planner("planar4", block_world, 1,
                         PL.PlanOptions(n_starts=8, n_substeps=8, iterations=200, step=0.05,
                                        shorten=0),
                         device=device)
    res = planner.plan(S4, G4)
    assert isinstance(res.paths_source, wp.array)  # not read yet
    all_paths = res.all_paths
    assert isinstance(res.paths_source, np.ndarray) and res.all_paths is all_paths
    assert all_paths.shape == (1, 8, 20, 4) and all_paths.dtype == np.float64
    # the device's choice is numpy's: feasible first, then the lowest U_path
    obj = PL.PathObjective("planar4", block_world, 1, 20, 8, eps=planner.eps, device=device)
    costs = np.array([obj.value_and_grad(p[None])[0][0] for p in all_paths[0]])
    feas = res.all_feasible[0]
    best = int(np.argmin(np.where(feas, costs, np.inf)) if feas.any() else np.argmin(costs))
    assert res.start_index[0] == best
    np.testing.assert_array_equal(res.path[0], all_paths[0, best])
    # a result keeps its own copy: the next call does not change it
    planner.plan(S4, np.array([-1.0, 0.3, 0.0, 0.0]))
    np.testing.assert_array_equal(res.all_paths, all_paths)
    res2 = planner.plan(S4, G4)
    assert_equal_on(device, res2.all_paths, all_paths)


def test_options_are_validated_naming_the_field(device, block_world):
    P = PL.PlanOptions
    bad = [(P(n_starts=0), ValueError, "n_starts"),
           (P(iterations=-1), ValueError, "iterations"),
           (P(n_waypoints=1), ValueError, "n_waypoints"),
           (P(n_substeps=0), ValueError, "n_substeps"),
           (P(step=0.0), ValueError, "step"), (P(max_step=np.inf), ValueError, "max_step"),
           (P(margin=-0.1), ValueError, "margin"), (P(eps=0.01, margin=0.02), ValueError, "eps"),
           (P(check_all_every=0), ValueError, "check_all_every"),
           (P(start_kind="zigzag"), ValueError, "start_kind"),
           (P(start_kind=np.zeros((2, 4))), TypeError, "start_kind"),
           (P(weights={"world": 1.0}), TypeError, "weights"),
           (P(weights=PL.PathWeights(length=-1.0)), ValueError, "weights.length"),
           (P(freeze_feasible="yes"), TypeError, "freeze_feasible"),
           (P(seed=-1), ValueError, "seed"),
           (P(kappa=1e-4, lam=1.5), ValueError, "lam"), (P(callback=3), TypeError, "callback"),
           (P(step=1e39), ValueError, "step")]
    for opts, err, name in bad:
        with pytest.raises(err, match=f"^{name}"):
            opts.validate()
        with pytest.raises(err, match=f"^{name}"):
            PL.Planner("planar4", block_world, 1, opts, device=device)
    P(step=1e39).validate(np.float64)  # finite in float64
    with pytest.raises(TypeError, match="options"):
        PL.Planner("planar4", block_world, 1, {"n_starts": 2})
    with pytest.raises(ValueError, match="n_problems"):
        PL.Planner("planar4", block_world, 0)
    with pytest.raises(ValueError, match="kappa"):
        PL.Planner("planar4", block_world, 1, P(kappa=-1.0))
    planner = PL.Planner("planar4", block_world, 2, device=device)
    with pytest.raises(ValueError, match="start: expected 2 configurations"):
        planner.plan(np.zeros((3, 4)), G4)
    with pytest.raises(ValueError, match="goal.*collision"):
        planner.plan(S4, np.zeros(4))  # the collision check runs on the device


@requires_cpu
def test_plan_on_cpu_runs_every_check_on_the_cpu(block_world, monkeypatch):
    """plan(device="cpu") passes its device to every check (collision, limits, elastic
    equilibrium, substep sizing, via-point sampling): none of them falls back to the
    preferred device (CUDA where there is one)."""
    def no_default(*a, **k):
        raise AssertionError("the preferred device was asked for (a device was not passed)")

    seen = []

    def spy(fn):
        def wrapped(*a, **k):
            seen.append((fn.__name__, k.get("device")))
            return fn(*a, **k)
        return wrapped

    from jwarp.world import path_feasibility as FZ
    for name in ("collision_free", "elastic_equilibrium", "path_feasible", "substeps_for_voxel",
                 "sphere_centres"):
        fn = spy(getattr(FZ, name))
        for mod in [m for k, m in list(sys.modules.items())  # every planning module using it
                    if k.startswith("jwarp.solvers.planning") and hasattr(m, name)]:
            monkeypatch.setattr(mod, name, fn)
        monkeypatch.setattr(FZ, name, fn)   # the checks live there (the planner re-exports)
    monkeypatch.setattr(wp, "get_preferred_device", no_default)
    launches = []
    launch = wp.launch

    def launch_spy(kernel, *a, **k):
        launches.append(str(wp.get_device(k.get("device"))))
        return launch(kernel, *a, **k)

    monkeypatch.setattr(wp, "launch", launch_spy)
    res = PL.plan("planar4", block_world, S4, G4, n_starts=4, iterations=40, step=0.05,
                  kappa=1e-3, device="cpu")  # sized substeps, free random via points
    assert res.path.shape == (1, 20, 4)
    names = {n for n, _ in seen}
    assert {"collision_free", "elastic_equilibrium", "substeps_for_voxel"} <= names
    assert all(str(wp.get_device(d)) == "cpu" for _, d in seen if d is not None), seen
    assert all(d is not None for _, d in seen), [n for n, d in seen if d is None]
    assert launches and set(launches) == {"cpu"}


def test_facade_exports_the_planner():
    assert jwarp.Planner is PL.Planner
    assert "Planner" in jwarp.__all__
