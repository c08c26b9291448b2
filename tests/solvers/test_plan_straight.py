"""The straight line first (PlanOptions.straight_first, issue 45 items 3 and 4): a problem
whose straight line the planner's continuous check proves is returned before any other
start is drawn or the optimiser is set up (stage "straight"), certified as the
optimiser's start 0 would be; every other problem is planned as before."""

import os
import sys

import numpy as np
import pytest

import jwarp
from jwarp.solvers import planning as PL
from jwarp.world import World
from jwarp.world.collision import min_distances
from jwarp.world.motion import check_paths

sys.path.insert(0, os.path.dirname(os.path.dirname(__file__)))

from worlds import block_world_2d  # noqa: E402

S4 = np.array([1.2, 0.0, 0.0, 0.0])
G4 = np.array([-1.2, 0.0, 0.0, 0.0])
#: the straight line is free
S_EASY = np.array([2.0, 1.0, 0.0, 0.0])
G_EASY = np.array([2.0, -1.0, 0.0, 0.0])


@pytest.fixture(scope="module")
def grid():
    return block_world_2d()


def _boxes(seed=3, n=6):
    rng = np.random.default_rng(seed)
    w = World.of_shapes()
    for j in range(n):
        w.add(f"b{j}", "box", rng.uniform(0.05, 0.2, 3),
              rng.uniform([-0.7, -0.7, 0.0], [0.7, 0.7, 1.0]))
    return w


def _dense_clearance(robot, world, path, per_segment=400):
    """The smallest world and self clearance [m] of ``path`` (W, n_dof) sampled densely
    (float64 spheres; independent of the continuous check's proof)."""
    u = np.linspace(0.0, 1.0, per_segment)[:, None]
    q = np.concatenate([a + u * (b - a) for a, b in zip(path[:-1], path[1:])])
    md = np.asarray(min_distances(jwarp.robot(robot), q, world, device="cpu", dtype=np.float64))
    return md[:, 0].min(), md[:, 1].min()


@pytest.fixture(scope="module")
def arm7_problems():
    """arm7 in six boxes: pairs whose straight line is free, and pairs whose line hits a
    box (both endpoints 2 cm clear), found by dense sampling."""
    robot = jwarp.robot("arm7")
    world = _boxes()
    rng = np.random.default_rng(5)
    lim = np.array(robot.joint_limits)
    free, hit = [], []
    while len(free) < 2 or len(hit) < 2:
        c = rng.uniform(lim[:, 0], lim[:, 1], (2, robot.n_dof)) * 0.6
        md = np.asarray(min_distances(robot, c, world, device="cpu", dtype=np.float64))
        if not (md > 0.02).all():
            continue
        w, s = _dense_clearance(robot, world, np.stack([c[0], c[1]]), 200)
        if w > 0.01 and s > 0.01 and len(free) < 2:
            free.append(c)
        elif w < -0.02 and len(hit) < 2:
            hit.append(c)
    return robot, world, np.array(free), np.array(hit)


def test_a_free_line_is_returned_by_the_straight_stage_and_is_certified(arm7_problems):
    robot, world, free, _ = arm7_problems
    q0, q1 = free[0]
    pl = PL.Planner(robot, world, 1, PL.PlanOptions(margin=0.005), device="cpu")
    res = pl.plan(q0, q1)
    assert res.feasible[0] and list(res.stage) == ["straight"]
    assert res.stop_reason == "solved" and res.iterations[0] == 0 and res.start_index[0] == 0
    # nothing else was set up: no initial paths, no objective, no endpoint checks
    assert pl.objective is None
    assert set(res.timings) == {"straight"}
    assert res.all_feasible.shape == (1, 1) and res.all_paths.shape == (1, 1, 20, 7)
    # the path is the line of 20 waypoints, in the planner's float32 (as the optimiser holds it)
    line = (q0 + np.linspace(0.0, 1.0, 20)[:, None] * (q1 - q0)).astype(np.float32)
    np.testing.assert_array_equal(res.path[0], line.astype(np.float64))
    # certified: the continuous check with its full budget, and a dense independent sampling
    assert check_paths(robot, world, res.path, margin=0.005, device="cpu").ok[0]
    w, s = _dense_clearance(robot, world, res.path[0])
    assert w >= 0.005 and s >= 0.0


def test_its_costs_are_evaluated_when_read_and_equal_the_optimisers(arm7_problems):
    """The costs are those the optimiser gives the same line (start_kind "straight", the
    straight stage off: the same substeps), evaluated on first read."""
    robot, world, free, _ = arm7_problems
    q0, q1 = free[1]
    o = dict(start_kind="straight", device="cpu")
    res = PL.plan(robot, world, q0, q1, **o)
    old = PL.plan(robot, world, q0, q1, straight_first=False, **o)
    assert list(res.stage) == ["straight"] and list(old.stage) == ["optimizer"]
    assert res.__dict__["_cost"] is None  # not evaluated yet
    np.testing.assert_array_equal(res.path, old.path)
    assert res.n_substeps == old.n_substeps
    np.testing.assert_array_equal(res.length_cost, old.length_cost)
    np.testing.assert_array_equal(res.collision_cost, old.collision_cost)
    np.testing.assert_array_equal(res.cost, old.cost)
    np.testing.assert_array_equal(res.length_before, old.length_before)
    assert abs(res.length_cost[0] - 1.0) < 1e-5
    d = res.to_dict(0)
    assert d["stage"] == "straight" and d["costs"]["total"] == float(old.cost[0])


def test_a_colliding_line_is_planned_as_before(arm7_problems, grid):
    """Where the line is not proven the endpoints are checked and the multi-starts run on
    the same initial paths: the same result as without the straight stage."""
    robot, world, _, hit = arm7_problems
    o = dict(seed=0, fallback=None, iterations=60, device="cpu")
    for q0, q1 in hit:
        res = PL.plan(robot, world, q0, q1, **o)
        old = PL.plan(robot, world, q0, q1, straight_first=False, **o)
        assert list(res.stage) == list(old.stage) != ["straight"]
        np.testing.assert_array_equal(res.path, old.path)
        np.testing.assert_array_equal(res.cost, old.cost)
        assert {"straight", "endpoints", "starts"} <= set(res.timings)
        # a start proven as drawn ends the search before the optimiser is set up
        assert ("optimizer" in res.timings) == (res.iterations[0] > 0 or not res.feasible[0])
    # planar4 in the block world (a grid): the line collides; the fallback solves it
    res = PL.plan("planar4", grid, S4, G4, n_starts=2, iterations=3, seed=0, device="cpu")
    assert res.feasible[0] and list(res.stage) == ["fallback"]


def test_a_batch_mixes_the_line_and_the_optimiser(arm7_problems):
    """Two problems, one free line, one not: the first is the straight stage's, the
    second the optimiser's; both as without the straight stage."""
    robot, world, free, hit = arm7_problems
    starts = np.stack([free[0, 0], hit[0, 0]])
    goals = np.stack([free[0, 1], hit[0, 1]])
    o = PL.PlanOptions(seed=0, fallback=None, iterations=60)
    res = PL.Planner(robot, world, 2, o, device="cpu").plan(starts, goals)
    old = PL.Planner(robot, world, 2, PL.PlanOptions(seed=0, fallback=None, iterations=60,
                                                     straight_first=False),
                     device="cpu").plan(starts, goals)
    assert res.stage[0] == "straight" and res.stage[1] != "straight"
    assert old.stage[0] == "optimizer"
    np.testing.assert_array_equal(res.path, old.path)
    np.testing.assert_array_equal(res.feasible, old.feasible)
    np.testing.assert_array_equal(res.iterations, old.iterations)
    np.testing.assert_array_equal(res.start_index, old.start_index)
    np.testing.assert_array_equal(res.cost, old.cost)


def test_a_batch_of_worlds(arm7_problems):
    """World.batch: each line proven in its own world (problem 1's line hits a box of
    world 0 and is free in its own)."""
    robot, world, free, hit = arm7_problems
    empty = World.of_shapes()
    empty.add("far", "box", [0.1, 0.1, 0.1], [5.0, 5.0, 5.0])
    batch = World.batch([world, empty])
    starts, goals = np.stack([free[1, 0], hit[0, 0]]), np.stack([free[1, 1], hit[0, 1]])
    res = PL.plan(robot, batch, starts, goals, device="cpu")
    assert list(res.stage) == ["straight", "straight"] and res.feasible.all()
    for b, w in enumerate((world, empty)):
        assert check_paths(robot, w, res.path[b:b + 1], device="cpu").ok[0]
    assert not check_paths(robot, world, res.path[1:2], device="cpu").ok[0]


def test_the_endpoints_are_still_checked(arm7_problems):
    """A start in collision or outside the limits is refused with the same messages."""
    robot, world, free, _ = arm7_problems
    lim = np.array(robot.joint_limits)
    bad = free[0, 0].copy()
    bad[0] = lim[0, 1] + 0.1
    with pytest.raises(ValueError, match="start: outside the joint limits"):
        PL.plan(robot, world, bad, free[0, 1], device="cpu")
    bad = free[0, 1].copy()
    bad[1] = lim[1, 0] - 0.1
    with pytest.raises(ValueError, match="goal: outside the joint limits"):
        PL.plan(robot, world, free[0, 0], bad, device="cpu")
    # the start inside a box
    box = World.of_shapes()
    box.add("all", "box", [4.0, 4.0, 4.0], [0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="start: configuration is in collision"):
        PL.plan(robot, box, free[0, 0], free[0, 1], device="cpu")


def test_not_taken_where_the_line_is_not_a_start(grid):
    base = dict(device="cpu", fallback=None, iterations=5)
    taken = PL.plan("planar4", grid, S_EASY, G_EASY, **base)
    assert list(taken.stage) == ["straight"]
    for extra in (dict(straight_first=False), dict(start_kind="random"),
                  dict(stop_when_solved=False), dict(converge=True, stop_when_solved=False),
                  dict(callback=lambda it, p: None), dict(freeze_feasible=False)):
        res = PL.plan("planar4", grid, S_EASY, G_EASY, **base, **extra)
        assert "straight" not in list(res.stage), extra
        assert "straight" not in res.timings, extra
    # seeds given: they are the starts
    seeds = np.stack([S_EASY, [2.0, 0.0, 0.5, 0.0], G_EASY])
    res = PL.plan("planar4", grid, S_EASY, G_EASY, seeds=seeds, **base)
    assert list(res.stage) == ["optimizer"]
    with pytest.raises(TypeError, match="straight_first"):
        PL.plan("planar4", grid, S_EASY, G_EASY, straight_first="yes", **base)


def test_panda_grasp_pose_line_certified_by_the_meshes(tmp_path_factory):
    """A hand 3 mm from a box (the contained spheres touch it, the meshes do not): the
    line away from it is proven with the mesh certificate (the start needs it) and
    returned by the straight stage; the independent verifier (pinocchio + coal, URDF
    meshes) finds every configuration of it free."""
    pytest.importorskip("pinocchio")
    pytest.importorskip("coal")
    from panda_graze import coarse_panda, grasp_q, graze_box
    from verifier import PathVerifier, checked_link_pairs

    from jwarp.world.collision import is_collision_free
    from jwarp.world.scene_file import Scene, exact_world

    path, model = coarse_panda(tmp_path_factory)
    q0 = grasp_q(model)
    box = graze_box(model, q0, 0.003)
    scene = Scene(shapes=[box], source="graze")
    world = exact_world(scene)
    assert not is_collision_free(model, q0[None], world, meshes=False, device="cpu")[0]
    q1 = q0.copy()
    q1[0] -= 0.6
    res = jwarp.plan(model, world, q0, q1, options=PL.PlanOptions(time_limit=20.0),
                     device="cpu")
    assert res.feasible[0] and list(res.stage) == ["straight"], res.reasons
    assert "endpoints" in res.timings  # the spheres alone did not prove the line
    v = PathVerifier(path, None, scene.shapes)
    v = PathVerifier(path, None, scene.shapes, self_pairs=checked_link_pairs(model, v))
    verdict = v.check_path(res.path[0])
    assert verdict.ok, str(verdict)


def test_last_check_of_one_problem_certifies_one_start(tmp_path_factory, monkeypatch):
    """The last check gives the mesh certificate only the unproven start the spheres miss
    by least (MESH_FINAL_PER_PROBLEM), for one problem as for a batch: a grasp start the
    spheres refuse leaves every start unproven by them; 8 starts go to the check, 1 to
    the certificate (it took 120-210 ms per unsolved CPU problem for all 8)."""
    pytest.importorskip("pinocchio")
    from panda_graze import coarse_panda, grasp_q, graze_box

    from jwarp.solvers.planning.planner import MESH_FINAL_PER_PROBLEM
    from jwarp.world.motion import MotionCheck
    from jwarp.world.scene_file import Scene, exact_world

    _, model = coarse_panda(tmp_path_factory)
    q0 = grasp_q(model)
    world = exact_world(Scene(shapes=[graze_box(model, q0, 0.003)], source="graze"))
    q1 = q0.copy()
    q1[0] -= 0.6
    rows = []
    orig = MotionCheck.mesh_recheck

    def recheck(self, paths, r, *a, **kw):
        rows.append(len(r))
        return orig(self, paths, r, *a, **kw)

    monkeypatch.setattr(MotionCheck, "mesh_recheck", recheck)
    o = PL.PlanOptions(straight_first=False, iterations=0, n_starts=8, fallback=None,
                       shorten=0)
    res = jwarp.plan(model, world, q0, q1, options=o, device="cpu")
    assert rows and max(rows) <= MESH_FINAL_PER_PROBLEM < 8, rows
    assert res.feasible[0], res.reasons  # the start the spheres miss by least is certified


def test_optimiser_checks_the_clearest_candidates_first(arm7_problems, monkeypatch):
    """On the CPU every check of the optimiser gets each problem's candidates clearest
    first (the lowest largest substep cost; its first proven path ends the problem's
    check), and the problems in order: the order the CPU's threads take them; before the
    last check only the clearest (CPU_CHECK_PER_PROBLEM)."""
    robot, world, _, hit = arm7_problems
    seen = []
    original = PL.Planner._confirm

    def recording(self, buf, cand):
        smax = buf.objective.sub_max.numpy().astype(np.float64)
        seen.append((np.array(cand), smax[cand], buf.objective.P // self.n_problems,
                     self._final))
        return original(self, buf, cand)

    monkeypatch.setattr(PL.Planner, "_confirm", recording)
    q0 = np.stack([h[0] for h in hit])
    q1 = np.stack([h[1] for h in hit])
    PL.plan(robot, world, q0, q1, seed=0, fallback=None, iterations=60, device="cpu",
            straight_first=False)
    assert seen and any(len(c) > 1 for c, _, _, _ in seen)
    cap = PL.planner.CPU_CHECK_PER_PROBLEM
    assert cap == 1
    for cand, smax, per, final in seen:
        prob = cand // per
        assert (np.diff(prob) >= 0).all()
        same = np.diff(prob) == 0
        assert (np.diff(smax)[same] >= 0).all()
        # before the last check: the clearest candidate of each problem only
        if not final:
            assert np.bincount(prob).max() <= cap


def _points_asked(monkeypatch, cls, name):
    """The ``points`` argument of every call of ``cls.name`` from now on (a list)."""
    asked = []
    original = getattr(cls, name)

    def recording(self, *args, **kwargs):
        asked.append(kwargs.get("points"))
        return original(self, *args, **kwargs)

    monkeypatch.setattr(cls, name, recording)
    return asked


def test_cpu_line_check_evaluates_points_first(arm7_problems, monkeypatch):
    """On the CPU the straight stage's check evaluates LINE_CHECK_POINTS points of every
    segment before the advancement (MotionCheck.launch(points=...)): the same verdicts as
    the planner's own check on free and colliding lines."""
    import warp as wp

    from jwarp.world.motion import MotionCheck

    robot, world, free, hit = arm7_problems
    assert PL.planner.LINE_CHECK_POINTS == 2
    asked = _points_asked(monkeypatch, MotionCheck, "launch")
    PL.plan(robot, world, free[0][0], free[0][1], device="cpu")
    assert asked[0] == (2, 1)
    chk = PL.Planner(robot, world, 1, device="cpu").motion_check()
    pairs = list(free) + list(hit)
    paths = np.stack([q0 + np.linspace(0, 1, 20)[:, None] * (q1 - q0) for q0, q1 in pairs])
    P = wp.array(paths, dtype=wp.float64, device="cpu")
    idx = wp.array(np.arange(len(paths), dtype=np.int32), device="cpu")
    a = chk.launch(P, idx, len(paths), points=(2, 1))["ok"].numpy()[:len(paths)].copy()
    b = chk.launch(P, idx, len(paths))["ok"].numpy()[:len(paths)].copy()
    np.testing.assert_array_equal(a, b)
    assert a[:len(free)].all() and not a[len(free):].any()
    with pytest.raises(ValueError, match="rounds"):
        chk.launch(P, idx, len(paths), points=(2, 0))


def test_cpu_start_check_evaluates_points_first(arm7_problems, monkeypatch):
    """On the CPU the check of the starts as drawn evaluates START_CHECK_POINTS points of
    every segment first (MotionCheck.check(points=...)); in groups (one proven path per
    problem) it proves the same first feasible path of each group as without them."""
    robot, world, free, hit = arm7_problems
    assert PL.planner.START_CHECK_POINTS == 1
    from jwarp.world.motion import MotionCheck

    original = MotionCheck.check
    asked = _points_asked(monkeypatch, MotionCheck, "check")
    # a colliding line: its random starts are checked as drawn
    PL.plan(robot, world, hit[0][0], hit[0][1], device="cpu", fallback=None, iterations=0)
    assert (1, 1) in asked
    monkeypatch.setattr(MotionCheck, "check", original)
    chk = PL.Planner(robot, world, 1, device="cpu").motion_check()
    line = lambda q0, q1: q0 + np.linspace(0, 1, 20)[:, None] * (q1 - q0)  # noqa: E731
    F = [line(*p) for p in free]
    H = [line(*p) for p in hit]
    groups = [[H[0], F[0], F[1]], [F[1], H[1], F[0]], [H[1], H[0], H[0]]]
    paths = np.stack([p for g in groups for p in g])
    a = chk.check(paths, group=3, meshes=False, points=(1, 1)).ok
    b = chk.check(paths, group=3, meshes=False).ok
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(a, [False, True, False, True, False, False,
                                      False, False, False])
