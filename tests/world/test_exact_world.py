"""Exact world objects (jwarp.kernels.geometry, jwarp.world.shapes) and the continuous path
check (jwarp.world.motion), on every device, against independent references: the numpy
closed forms of jwarp.world.primitives, coal's distances, trimesh's closest points and
winding-free inside tests, finite differences, and densely sampled paths."""

import numpy as np
import pytest
import trimesh

import jwarp
from jwarp.solvers.planning import plan
from jwarp.world import World, exact_world
from jwarp.world.device_world import world_query
from jwarp.world.motion import MotionCheck, check_paths, reach_front, sphere_reach, travel_bound
from jwarp.world.primitives import Shape, pose_matrix, rpy_matrix, signed_distance
from jwarp.world.scene_file import Scene
from jwarp.world.shapes import ShapeSet

PRIMS = [("box", [0.3, 0.2, 0.1]), ("sphere", [0.1]), ("cylinder", [0.3, 0.1]),
         ("capsule", [0.2, 0.05]), ("cone", [0.3, 0.15])]


def _shape(kind, dims, rng, oid="o"):
    return Shape(kind, np.array(dims, float), pose_matrix(rng.normal(size=3) * 0.2,
                                                          rpy_matrix(rng.normal(size=3))), oid)


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
@pytest.mark.parametrize("kind,dims", PRIMS)
def test_primitive_distance_matches_closed_form(device, dtype, kind, dims):
    rng = np.random.default_rng(1)
    s = _shape(kind, dims, rng)
    w = World.of_shapes(ShapeSet.from_shapes([s]))
    pts = s.pose[:3, 3] + rng.normal(size=(2000, 3)) * 0.2
    d, g, obj = world_query(w, pts, device=device, dtype=dtype)
    ref = signed_distance(s, pts)
    tol = 1e-12 if dtype == np.float64 else 2e-6
    np.testing.assert_allclose(d, ref, atol=tol)
    assert (ref < 0).sum() > 20 and (ref > 0).sum() > 50  # both sides sampled
    assert (obj == 0).all()


@pytest.mark.parametrize("kind,dims", PRIMS)
def test_primitive_distance_matches_coal_outside(kind, dims):
    coal = pytest.importorskip("coal")
    rng = np.random.default_rng(2)
    s = _shape(kind, dims, rng)
    length_radius = {"cylinder": lambda: coal.Cylinder(dims[1], dims[0]),
                     "capsule": lambda: coal.Capsule(dims[1], dims[0]),
                     "cone": lambda: coal.Cone(dims[1], dims[0])}
    geom = {"box": lambda: coal.Box(*dims), "sphere": lambda: coal.Sphere(dims[0]),
            **length_radius}[kind]()
    w = World.of_shapes(ShapeSet.from_shapes([s]))
    pts = s.pose[:3, 3] + rng.normal(size=(300, 3)) * 0.3
    d, _, _ = world_query(w, pts)
    pts, d = pts[d > 1e-3], d[d > 1e-3]
    tf = coal.Transform3s(s.pose[:3, :3], s.pose[:3, 3])
    point = coal.Sphere(1e-9)
    ref = []
    for p in pts:
        req, res = coal.DistanceRequest(), coal.DistanceResult()
        coal.distance(geom, tf, point, coal.Transform3s(np.eye(3), p), req, res)
        ref.append(res.min_distance + 1e-9)
    np.testing.assert_allclose(d, ref, atol=2e-6)


def test_mesh_distance_closed_and_open(device):
    pytest.importorskip("rtree")  # trimesh's closest points
    rng = np.random.default_rng(3)
    closed = trimesh.creation.icosphere(subdivisions=3, radius=0.2)
    box = trimesh.creation.box(extents=[1.0, 1.0, 0.5])
    box.apply_translation([0, 0, 0.25])
    top = box.triangles_center[:, 2] > 0.49                          # drop the lid: open
    cup = trimesh.Trimesh(box.vertices, box.faces[~top], process=False)
    assert not cup.is_watertight
    for mesh, inside_ref in ((closed, lambda p: closed.contains(p)),
                             (cup, lambda p: (np.abs(p[:, :2]) < 0.5).all(1) & (p[:, 2] > 0)
                              & (p[:, 2] < 0.5))):
        s = Shape("mesh", np.zeros(0), np.eye(4), "m", mesh=mesh)
        w = World.of_shapes(ShapeSet.from_shapes([s]))
        pts = rng.uniform(-0.8, 0.8, size=(1500, 3))
        d, g, _ = world_query(w, pts, device=device)
        _, dist, _ = trimesh.proximity.closest_point(mesh, pts)
        np.testing.assert_allclose(np.abs(d), dist, atol=1e-5)
        # the sign: inside for the closed sphere's contains; for the open cup, points
        # well inside its walls count as inside (winding number ~5/6)
        far = dist > 0.02
        assert ((d < 0) == inside_ref(pts))[far].all()


@pytest.mark.parametrize("dtype", [np.float64])
def test_gradients_match_finite_differences(device, dtype):
    rng = np.random.default_rng(4)
    shapes = [_shape(k, d, rng, f"o{i}") for i, (k, d) in enumerate(PRIMS)]
    shapes.append(Shape("mesh", np.zeros(0), pose_matrix([0.3, 0, 0]), "m",
                        mesh=trimesh.creation.icosphere(subdivisions=2, radius=0.1)))
    w = World.of_shapes(ShapeSet.from_shapes(shapes))
    pts = rng.normal(size=(400, 3)) * 0.4
    pts = np.concatenate([pts] + [s.pose[:3, 3] + rng.normal(size=(40, 3)) * 0.03
                                  for s in shapes])  # and points inside
    d, g, obj = world_query(w, pts, device=device, dtype=dtype)

    def fd(h):
        return np.stack([(world_query(w, pts + h * e, device=device)[0]
                          - world_query(w, pts - h * e, device=device)[0]) / (2 * h)
                         for e in np.eye(3)], axis=1)

    mesh = obj == len(shapes) - 1   # float32 vertices: a wider step, looser tolerance
    agree = np.where(mesh, np.linalg.norm(fd(1e-4) - g, axis=1) < 1e-3,
                     np.linalg.norm(fd(1e-6) - g, axis=1) < 1e-5)
    assert (d < 0).sum() > 100
    # the distance is not differentiable on the medial axes and where two objects tie:
    # those are a few points at most, and everywhere the gradient has unit length
    assert agree.mean() > 0.97, agree.mean()
    np.testing.assert_allclose(np.linalg.norm(g, axis=1), 1.0, atol=1e-6)
    outside = d > 0.01
    assert agree[outside].mean() > 0.99  # outside a convex shape the distance is C1


def test_union_of_many_objects_matches_brute_force(device):
    rng = np.random.default_rng(5)
    shapes = [Shape(PRIMS[i % 5][0], np.array(PRIMS[i % 5][1]) * 0.3,
                    pose_matrix(rng.uniform(-1, 1, 3), rpy_matrix(rng.normal(size=3))), f"o{i}")
              for i in range(60)]
    w = World.of_shapes(ShapeSet.from_shapes(shapes))
    w.add("floor", "plane", pose=pose_matrix([0, 0, -1.2]))
    pts = rng.uniform(-1.2, 1.2, size=(3000, 3))
    ref = np.min([signed_distance(s, pts) for s in shapes], axis=0)
    ref = np.minimum(ref, pts[:, 2] + 1.2)
    d, _, obj = world_query(w, pts, device=device)
    np.testing.assert_allclose(d, ref, atol=1e-9)
    # with a cutoff only objects within it count; beyond, the cutoff is returned
    dc, _, oc = world_query(w, pts, cutoff=0.05, device=device)
    near = ref < 0.05
    np.testing.assert_allclose(dc[near], ref[near], atol=1e-9)
    assert (dc[~near] == 0.05).all() and (oc[~near] == -1).all()


def test_add_move_remove_in_place(device):
    robot = jwarp.robot("arm7")
    w = World.of_shapes()
    w.add("box", "box", [0.1, 0.1, 0.1], [5.0, 0.0, 0.0])
    q = np.zeros((1, robot.n_dof))
    from jwarp.world.collision import collision_model, min_distances
    far = min_distances(robot, q, w, device=device, dtype=np.float64)[0, 0]
    # move the box onto the arm: the cached collision model sees it
    x = jwarp.fk(robot, q)[0, robot.frame_index(list(robot.end_effectors)[0]), :3, 3]
    w.move("box", x)
    near = min_distances(robot, q, w, device=device, dtype=np.float64)[0, 0]
    assert far > 3.0 and near < 0
    cm = collision_model(robot, w, device=device, dtype=np.float64)
    import warp as wp
    c1, _ = cm.cost(wp.array(q, dtype=wp.float64, device=cm.device), grad=False)
    assert c1.numpy()[0] > 0
    w.add("ball", "sphere", [0.05], [0.0, 0.0, 5.0])
    w.remove("box")
    assert w.object_ids == ["ball"]
    assert min_distances(robot, q, w, device=device, dtype=np.float64)[0, 0] > 3.0
    with pytest.raises(KeyError, match="object 'box'"):
        w.move("box", [0, 0, 0])


@pytest.mark.parametrize("bad,match", [
    (dict(kind="box", dims=[0.1, -0.1, 0.1]), "object 'x': box dimensions must be finite and > 0"),
    (dict(kind="box", dims=[0.1, np.nan, 0.1]), "object 'x': box dimensions"),
    (dict(kind="box", dims=[1e6, 1, 1]), "object 'x': box dimensions .* exceed"),
    (dict(kind="torus", dims=[0.1]), "object 'x': unknown shape type"),
    (dict(kind="sphere", dims=[0.1], pose=[np.nan, 0, 0]), "object 'x': pose contains NaN"),
    (dict(kind="sphere", dims=[0.1], pose=[1e9, 0, 0]), "object 'x': position .* beyond"),
    (dict(kind="mesh", mesh=trimesh.Trimesh(np.zeros((0, 3)), np.zeros((0, 3), int))),
     "object 'x': empty mesh"),
    # face indices past the vertices (or negative) made the first query read outside Warp's
    # vertex array (a segfault); any mesh-like object is checked, not only a Trimesh
    (dict(kind="mesh", mesh=trimesh.Trimesh(np.eye(3), [[0, 1, 100000000]], process=False)),
     r"object 'x': mesh face 0 has vertex indices \[0, 1, 100000000\] outside \[0, 3\)"),
    (dict(kind="mesh", mesh=trimesh.Trimesh(np.eye(3), [[0, 1, 2], [0, -1, 2]], process=False)),
     r"object 'x': mesh face 1 has vertex indices \[0, -1, 2\]"),
    (dict(kind="mesh", mesh=(np.eye(3), np.array([[0, 1, 7]]))), "object 'x': mesh face 0"),
    (dict(kind="mesh", mesh=(np.eye(3), np.array([[0, 1, 2, 0]]))), "object 'x': mesh faces must be triangles"),
    (dict(kind="mesh", mesh=(np.array([[0, 0, 0], [1, 0, 0], [0, 1, np.nan]]), [[0, 1, 2]])),
     "object 'x': mesh vertices contain NaN"),
])
def test_bad_objects_name_the_object(bad, match):
    s = ShapeSet()
    with pytest.raises(ValueError, match=match):
        s.add("x", bad["kind"], bad.get("dims", ()), bad.get("pose"), mesh=bad.get("mesh"))
    assert len(s) == 0
    s.add("x", "sphere", [0.1])
    with pytest.raises(ValueError, match="object 'x': an object of that id exists"):
        s.add("x", "sphere", [0.1])
    with pytest.raises(ValueError, match="object 'x': pose contains NaN"):
        s.move(["x"], [[np.nan, 0, 0]])


# ---------------------------------------------------------------- continuous check
@pytest.fixture(scope="module")
def arm_scene():
    robot = jwarp.robot("arm7")
    w = World.of_shapes()
    w.add("box", "box", [0.2, 0.2, 0.2], [0.45, 0.0, 0.5])
    w.add("pole", "cylinder", [0.6, 0.03], pose_matrix([0.0, 0.45, 0.5]))
    w.add("floor", "plane", pose=pose_matrix([0, 0, -0.05]))
    return robot, w


def _dense_clearance(robot, world, paths, n=1500):
    from jwarp.world.collision import min_distances
    P, W, nd = paths.shape
    u = np.linspace(0, 1, n)
    seg = paths[:, :-1, None] + u[None, None, :, None] * np.diff(paths, axis=1)[:, :, None]
    md = min_distances(jwarp.robot(robot), seg.reshape(-1, nd), world, dtype=np.float64)
    return md.reshape(P, -1, 2).min(axis=(1, 2))


@pytest.mark.parametrize("points,method", [(0, "advance"), (8, "advance"), (None, "levels")])
def test_motion_check_agrees_with_dense_sampling(device, arm_scene, points, method):
    """Every scheme: the advancement alone (the CPU's default), parallel evaluations
    first (8 points per segment), and the interval refinement (the GPU's default)."""
    from jwarp.world.motion import MotionOptions
    robot, w = arm_scene
    rng = np.random.default_rng(6)
    lim = np.array(robot.joint_limits)
    q = rng.uniform(lim[:, 0], lim[:, 1], size=(120, 2, robot.n_dof)) * 0.6
    paths = q[:, :1] + np.linspace(0, 1, 6)[None, :, None] * (q[:, 1:] - q[:, :1])
    res = MotionCheck(robot, w, device=device,
                      options=MotionOptions(points=points, method=method)).check(paths)
    dense = _dense_clearance(robot, w, paths)
    assert not (res.ok & (dense < 0)).any()          # never feasible through an object
    clear = dense > 2e-3                               # clearly free: certified
    assert res.ok[clear].all()
    assert 10 < (~res.ok).sum() < 110                  # both kinds present
    bad = np.nonzero(~res.ok)[0]
    assert set(res.code[bad]) <= {1, 2, 3}
    assert all(("box" in r or "pole" in r or "floor" in r or "self" in r)
               for r in res.reasons() if r != "feasible")


def test_motion_check_margin_and_endpoint_margin(device, arm_scene):
    robot, w = arm_scene
    rng = np.random.default_rng(7)
    lim = np.array(robot.joint_limits)
    q = rng.uniform(lim[:, 0], lim[:, 1], size=(150, 2, robot.n_dof)) * 0.6
    paths = q[:, :1] + np.linspace(0, 1, 5)[None, :, None] * (q[:, 1:] - q[:, :1])
    chk = MotionCheck(robot, w, device=device)
    dense = _dense_clearance(robot, w, paths)
    for m in (0.0, 0.01, 0.03):
        ok = chk.check(paths, margin=m).ok
        assert not (ok & (dense < m)).any()
        assert ok[dense > m + 3e-3].all()
    # a grasp-like goal 4 mm from a ball: refused at margin 1 cm, planned with
    # endpoint_margin 0 (the last segment may come closer than the margin, never below 0)
    from jwarp.world.path_feasibility import sphere_centres
    goal = np.array([0.0, 0.8, 0.0, -1.0, 0.0, 0.5, 0.0])
    c = sphere_centres(robot, goal[None])[0]
    _, _, rad = robot.sphere_arrays()
    k = int(np.argmax(np.linalg.norm(c[:, :2], axis=1)))   # the farthest out
    u = np.r_[c[k, :2], 0.0] / np.linalg.norm(c[k, :2])
    ball = World.of_shapes()
    ball.add("ball", "sphere", [0.05], c[k] + u * (rad[k] + 0.004 + 0.05))
    start = goal + np.r_[1.2, 0, 0, 0, 0, 0, 0]
    path = np.linspace(start, goal, 8)
    chk = MotionCheck(robot, ball, device=device)
    r0 = chk.check(path, margin=0.01)
    assert not r0.ok[0] and "ball" in r0.reason(0) and r0.where[0] > 6.0
    r1 = chk.check(path, margin=0.01, endpoint_margin=0.0)
    assert r1.ok[0], r1.reason(0)
    dense = _dense_clearance(robot, ball, path[None])
    assert 0.0 < dense[0] <= 0.004 + 1e-6
    assert _dense_clearance(robot, ball, path[None, :7])[0] >= 0.01


def test_motion_check_reports_limits_and_uses_grid_error(device):
    robot = jwarp.robot("sphere2d")
    occ = np.zeros((64, 64), bool)
    occ[31:33, :] = True
    from jwarp.world import world_from_occupancy
    grid = world_from_occupancy(occ, [[-1, 1], [-1, 1]])
    path = np.array([[-0.5, 0.0], [-0.2, 0.0]])
    base = check_paths(robot, grid, path, device=device)
    assert base.ok[0]
    from dataclasses import replace
    g2 = replace(grid, grid_error=0.5)   # a grid that declares 0.5 m of error
    bad = check_paths(robot, g2, path, device=device)
    assert not bad.ok[0] and "grid" in bad.reason(0)
    over = np.array([[-0.5, 0.0], [-1.5, 0.0]])
    r = check_paths(robot, grid, over, device=device)
    assert r.code[0] == 4 and "joint limits" in r.reason(0)


def test_travel_bound_keeps_only_the_reach_front():
    """The travel bound's largest sphere travel from the reach front equals numpy's over
    every sphere (justin19: the front is a few of its spheres), and the front of random
    tables keeps the max of every non-negative direction."""
    robot = jwarp.robot("justin19")
    R = sphere_reach(robot)
    front = reach_front(R)
    assert 1 <= len(front) < len(R) // 4
    rng = np.random.default_rng(3)
    lim = np.array(robot.joint_limits)
    paths = rng.uniform(lim[:, 0], lim[:, 1], size=(40, 6, robot.n_dof))
    C = np.zeros((robot.n_frames, robot.n_dof))
    for i, f in enumerate(robot.frames):
        for j, c in f.coupling:
            C[i, j] += c
    ref = (np.abs(np.diff(paths, axis=1) @ C.T)[..., None, :] * R).sum(-1).max(-1)
    np.testing.assert_allclose(travel_bound(robot, paths), ref, rtol=1e-12)
    np.testing.assert_allclose(travel_bound(robot, paths), ref, rtol=1e-12)  # cached tables
    np.testing.assert_allclose(travel_bound(robot, paths, R), ref, rtol=1e-12)  # given reach
    for _ in range(200):
        T = rng.integers(0, 3, size=(rng.integers(1, 9), rng.integers(1, 4))).astype(float)
        x = rng.uniform(0, 1, size=(30, T.shape[1]))
        f = reach_front(T)
        assert len(f) <= len(np.unique(T, axis=0))
        np.testing.assert_array_equal((x @ T.T).max(1), (x @ f.T).max(1))
    for bad in (np.zeros(3), -np.ones((2, 2))):
        with pytest.raises(ValueError, match="^reach: expected a table"):
            reach_front(bad)


def test_sphere_reach_bounds_the_motion():
    """Finite differences of the sphere centres never exceed the reach bound."""
    robot = jwarp.robot("justin19")
    R = sphere_reach(robot)
    rng = np.random.default_rng(8)
    lim = np.array(robot.joint_limits)
    q = rng.uniform(lim[:, 0], lim[:, 1], size=(200, robot.n_dof))
    from jwarp.world.path_feasibility import sphere_centres
    x0 = sphere_centres(robot, q)
    h = 1e-6
    for j in range(robot.n_dof):
        dq = np.zeros(robot.n_dof)
        dq[j] = h
        speed = np.linalg.norm(sphere_centres(robot, q + dq) - x0, axis=-1) / h  # (200, S)
        # frame angles that joint j drives (couplings)
        coef = np.zeros(robot.n_frames)
        for i, f in enumerate(robot.frames):
            for jj, c in f.coupling:
                if jj == j:
                    coef[i] += abs(c)
        bound = R @ coef
        assert (speed <= bound[None] * (1 + 1e-4) + 1e-6).all(), j


def test_exact_world_of_a_scene_and_planner_feasible_means_feasible(device, arm_scene):
    robot, w = arm_scene
    from jwarp.world.collision import min_distances
    rng = np.random.default_rng(9)
    lim = np.array(robot.joint_limits)
    q = rng.uniform(lim[:, 0], lim[:, 1], size=(400, 2, robot.n_dof)) * 0.6
    free = (min_distances(robot, q.reshape(-1, robot.n_dof), w, dtype=np.float64)
            .reshape(400, 2, 2).min(axis=(1, 2)) > 0.02)
    lines = q[:, :1] + np.linspace(0, 1, 20)[None, :, None] * (q[:, 1:] - q[:, :1])
    through = _dense_clearance(robot, w, lines, n=50) < 0
    k = np.nonzero(free & through)[0][:3]       # straight lines through an object
    assert len(k) == 3
    res = plan(robot, w, q[k, 0], q[k, 1], n_starts=4, iterations=80,
                                      device=device)
    assert res.feasible.all()
    assert (_dense_clearance(robot, w, res.path, n=400) >= 0).all()
    scene = Scene([Shape("box", np.array([0.2, 0.2, 0.2]), pose_matrix([0.45, 0, 0.5]), "b")])
    ew = exact_world(scene)
    assert ew.object_ids == ["b"] and not ew.has_grid and ew.dim == 3


def test_infeasible_plan_says_why(device, arm_scene, tmp_path, capsys):
    robot, w = arm_scene
    from jwarp.world.collision import min_distances
    # a free goal whose straight line hits the box, no iterations and no fallback
    rng = np.random.default_rng(10)
    lim = np.array(robot.joint_limits)
    q = rng.uniform(lim[:, 0], lim[:, 1], size=(300, 2, robot.n_dof)) * 0.6
    free = (min_distances(robot, q.reshape(-1, robot.n_dof), w, dtype=np.float64)
            .reshape(300, 2, 2).min(axis=(1, 2)) > 0.02)
    lines = q[:, :1] + np.linspace(0, 1, 20)[None, :, None] * (q[:, 1:] - q[:, :1])
    i = int(np.nonzero(free & (_dense_clearance(robot, w, lines, n=50) < 0))[0][0])
    start, goal = q[i, 0], q[i, 1]
    res = plan(robot, w, start, goal, start_kind="straight", iterations=0,
                                      device=device, fallback=None)
    assert not res.feasible[0]
    assert res.reasons[0].startswith("collision: sphere") and "vs object '" in res.reasons[0]
    assert res.to_dict(0)["reason"] == res.reasons[0]


@pytest.mark.parametrize("kind,dims", PRIMS + [("mesh", None)])
def test_covering_spheres_contain_the_object(kind, dims):
    from jwarp.world.attach import covering_spheres
    rng = np.random.default_rng(11)
    mesh = trimesh.creation.icosphere(radius=0.07) if kind == "mesh" else None
    c, r = covering_spheres(kind, dims if dims else (), mesh=mesh, max_spheres=16)
    assert 1 <= len(c) <= 18
    s = Shape(kind, np.zeros(0) if kind == "mesh" else np.array(dims), np.eye(4), "o",
              mesh=mesh)
    half = 0.1 if kind == "mesh" else 0.3      # the mesh: 4000 points around its 7 cm ball
    pts = rng.uniform(-half, half, (4000 if kind == "mesh" else 20000, 3))
    inside = signed_distance(s, pts) < 0
    covered = (np.linalg.norm(pts[:, None] - c[None], axis=-1) <= r[None]).any(1)
    assert inside.sum() > 100 and covered[inside].all()


def test_attach_moves_the_object_with_the_hand_and_detach_puts_it_back(device):
    robot = jwarp.robot("arm7")
    tcp = list(robot.end_effectors)[0]
    q0 = np.array([0.0, 0.8, 0.0, -1.0, 0.0, 0.5, 0.0])
    T = jwarp.fk(robot, q0[None], dtype=np.float64)[0, robot.frame_index(tcp)]
    w = World.of_shapes()
    part = T.copy()                          # a bar along the hand's x axis
    part[:3, 3] = T[:3, 3] + T[:3, 0] * 0.15
    w.add("part", "box", [0.2, 0.04, 0.04], part)
    w.add("ball", "sphere", [0.02], T[:3, 3] + T[:3, 0] * 0.30)   # 3 cm beyond its tip
    carried = w.attach("part", robot, tcp, q0)
    assert w.object_ids == ["ball"] and len(carried.spheres) > len(robot.spheres)
    from jwarp.world.collision import min_distances
    q = np.repeat(q0[None], 60, 0)
    q[:, 0] += np.linspace(0, 0.5, 60)
    bare = min_distances(robot, q, w, device=device, dtype=np.float64)[:, 0]
    held = min_distances(carried, q, w, device=device, dtype=np.float64)[:, 0]
    assert (held <= bare + 1e-12).all()
    # at q0 the bar's tip is 3 cm from the ball; the covering spheres bulge < 2.5 cm
    assert 0.03 - 0.025 <= held[0] <= 0.03 + 1e-9 and bare[0] > held[0] + 0.05
    # the part goes back where the hand left it
    back = w.detach("part", carried, q[30])
    assert len(back.spheres) == len(robot.spheres) and "part" in w.object_ids
    T30 = jwarp.fk(robot, q[30:31], dtype=np.float64)[0, robot.frame_index(tcp)]
    np.testing.assert_allclose(w.shapes.pose("part")[:3, 3], T30[:3, 3] + T30[:3, 0] * 0.15,
                               atol=1e-12)


def test_self_margin_is_separate_from_the_world_margin(device):
    """The world margin does not apply between the robot's own links (MoveIt's default):
    a path whose links pass 5 mm apart is feasible at margin 1 cm, not at self_margin 1 cm."""
    robot = jwarp.robot("arm7")
    from jwarp.world.collision import min_distances
    rng = np.random.default_rng(12)
    lim = np.array(robot.joint_limits)
    q = rng.uniform(lim[:, 0], lim[:, 1], (4000, robot.n_dof))
    md = min_distances(robot, q, None, dtype=np.float64)[:, 1]
    i = int(np.nonzero((md > 0.004) & (md < 0.008))[0][0])    # links 4-8 mm apart
    path = np.stack([q[i], q[i]])                                  # stand still there
    empty = World.of_shapes()
    chk = MotionCheck(robot, empty, device=device)
    assert chk.check(path, margin=0.01).ok[0]
    r = chk.check(path, margin=0.0, self_margin=0.01, endpoint_margin=0.01)
    assert not r.ok[0] and r.reason(0).startswith("self collision")


def test_a_batch_of_worlds_plans_each_problem_in_its_own_world(device):
    """World.batch: problem b sees only world b's objects (cost, checks, reasons), the same
    verdicts as planning each world alone; distances per world equal those of select(b)."""
    robot = jwarp.robot("arm7")
    from jwarp.world.collision import min_distances
    rng = np.random.default_rng(13)
    worlds = []
    for _ in range(4):
        w = World.of_shapes()
        for j in range(3):
            w.add(f"b{j}", "box", rng.uniform(0.05, 0.2, 3),
                  rng.uniform([-0.7, -0.7, 0.0], [0.7, 0.7, 1.0]))
        worlds.append(w)
    worlds.append(World.of_shapes())                       # a world without objects
    batch = World.batch(worlds)
    assert batch.n_worlds == 5 and batch.select(4).object_ids == []
    lim = np.array(robot.joint_limits)
    q = rng.uniform(lim[:, 0], lim[:, 1], (5, robot.n_dof)) * 0.6
    per = min_distances(robot, q, batch, device=device, dtype=np.float64, per_world=1)
    alone = np.stack([min_distances(robot, q[i:i + 1], worlds[i], device=device,
                                    dtype=np.float64)[0] for i in range(5)])
    np.testing.assert_allclose(per[:4], alone[:4], atol=1e-12)
    assert np.isinf(per[4, 0]) and per[4, 1] == alone[4, 1]
    # plan: every problem in its own world; feasible paths verified densely in their world
    free = []
    while len(free) < 10:
        c = rng.uniform(lim[:, 0], lim[:, 1], (64, robot.n_dof)) * 0.6
        ok = np.ones(64, bool)
        for w in worlds:
            ok &= min_distances(robot, c, w, dtype=np.float64).min(axis=1) > 0.02
        free.extend(c[ok])
    starts, goals = np.array(free[:5]), np.array(free[5:10])
    res = plan(robot, batch, starts, goals, n_starts=4, iterations=60, device=device)
    for b in range(5):
        if res.feasible[b]:
            assert _dense_clearance(robot, worlds[b], res.path[b:b + 1], n=300)[0] >= 0
    assert res.feasible.sum() >= 4
    with pytest.raises(ValueError, match="a batch of 5 worlds needs as many problems"):
        plan(robot, batch, starts[:2], goals[:2], device=device)


def test_ik_solver_sees_objects_added_after_it_was_built(device):
    """An IKSolver keeps its world: an object added (or moved) later is in its next solve
    (its check refuses a pose inside the new object)."""
    from jwarp.solvers.ik import IKOptions, IKSolver
    robot = jwarp.robot("arm7")
    tcp = list(robot.end_effectors)[0]
    q = np.array([0.0, 0.8, 0.0, -1.0, 0.0, 0.5, 0.0])
    T = jwarp.fk(robot, q[None], dtype=np.float64)[0, robot.frame_index(tcp)]
    w = World.of_shapes()
    w.add("far", "sphere", [0.05], [3.0, 0.0, 0.0])
    solver = IKSolver(robot, tcp, 1, IKOptions(n_starts=8), world=w, device=device)
    assert solver.solve(T).feasible
    w.add("block", "sphere", [0.08], T[:3, 3])           # the target is now inside it
    res = solver.solve(T)
    assert not res.feasible
    w.move("block", T[:3, 3] + np.array([2.0, 0.0, 0.0]))  # and out of the way again
    assert solver.solve(T).feasible


def test_exact_world_example_runs_and_passes_its_checks():
    """examples/exact_world.py: a user's first exact world (add, plan, why, move, attach)."""
    import subprocess
    import sys
    from pathlib import Path
    root = Path(__file__).resolve().parents[2]
    proc = subprocess.run([sys.executable, str(root / "examples" / "exact_world.py")],
                          cwd=root, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "checks: 4 of 4 passed" in proc.stdout
    assert "vs object 'box'" in proc.stdout


def test_object_meshes_for_display_lie_on_the_objects():
    """jwarp.viz.object_meshes (rerun display of exact worlds): every vertex on its object's
    surface (the exact distance), for every kind."""
    from jwarp.viz import object_meshes
    rng = np.random.default_rng(15)
    w = World.of_shapes()
    for i, (kind, dims) in enumerate(PRIMS):
        w.add(f"o{i}", kind, dims, pose_matrix(rng.uniform(-1, 1, 3), rpy_matrix(rng.normal(size=3))))
    w.add("ball", "mesh", mesh=trimesh.creation.icosphere(radius=0.1), pose=[2.0, 0, 0])
    meshes = object_meshes(w)
    assert [m[0] for m in meshes] == w.object_ids
    for oid, v, _faces in meshes:
        one = World.of_shapes()
        kind, dims, mesh = w.shapes.spec(oid)
        one.add(oid, kind, [] if dims is None else dims, w.shapes.pose(oid), mesh=mesh)
        d = one.shapes.distance(v.astype(np.float64))
        assert np.abs(d).max() < 0.02 * max(1.0, np.abs(v).max()), (oid, np.abs(d).max())


def test_a_mesh_with_faces_past_its_vertices_is_refused_before_any_query():
    """World.add and world_from_mesh check face indices and dtype: nothing reaches Warp."""
    from jwarp.world import world_from_mesh
    w = World.of_shapes()
    with pytest.raises(ValueError, match=r"object 'm': mesh face 0 has vertex indices"):
        w.add("m", "mesh", mesh=trimesh.Trimesh(np.eye(3), [[0, 1, 100000000]], process=False))
    with pytest.raises(TypeError, match="object 'm': mesh face indices must be integers"):
        w.add("m", "mesh", mesh=(np.eye(3), np.array([[0.0, 1.5, 2.0]])))
    assert w.object_ids == []
    assert np.isinf(w.distance([[0.0, 0.0, 0.0]])).all()
    with pytest.raises(ValueError, match=r"mesh: mesh face 0 has vertex indices \[0, 1, -4\]"):
        world_from_mesh((np.eye(4)[:, :3], np.array([[0, 1, -4]])), [[-1, 1]] * 3, 0.5)


def test_world_distance_of_exact_objects():
    w = World.of_shapes()
    w.add("ball", "sphere", [0.1], [0.0, 0.0, 0.0])
    np.testing.assert_allclose(w.distance([[0.3, 0.0, 0.0], [0.0, 0.0, 0.0]]), [0.2, -0.1],
                               atol=1e-12)
    with pytest.raises(ValueError, match="grad: a world with exact objects"):
        w.distance([[0.3, 0.0, 0.0]], grad=True)


@pytest.mark.parametrize("dtype", [np.float64])
def test_collision_cost_gradient_in_an_exact_world_matches_finite_differences(device, dtype,
                                                                               arm_scene):
    """The fused cost kernel's hand-written gradient, now through exact objects (box,
    cylinder, plane) and the BVH broad phase: central differences of the cost."""
    from jwarp.world.collision import collision_cost
    robot, w = arm_scene
    rng = np.random.default_rng(16)
    lim = np.array(robot.joint_limits)
    q = rng.uniform(lim[:, 0], lim[:, 1], (300, robot.n_dof)) * 0.6
    c, g = collision_cost(robot, q, w, eps=0.05, device=device, dtype=dtype)
    q = q[c > 1e-4][:20]                       # configurations that touch something
    assert len(q) >= 5
    c, g = collision_cost(robot, q, w, eps=0.05, device=device, dtype=dtype)
    h = 1e-6
    fd = np.stack([(collision_cost(robot, q + h * e, w, eps=0.05, grad=False, device=device,
                                   dtype=dtype)[0]
                    - collision_cost(robot, q - h * e, w, eps=0.05, grad=False, device=device,
                                     dtype=dtype)[0]) / (2 * h) for e in np.eye(robot.n_dof)],
                   axis=1)
    err = np.abs(fd - g).max(axis=1) / (1e-3 + np.abs(g).max(axis=1))
    assert (err < 1e-4).mean() >= 0.9, err   # non-smooth only on medial axes / ties


def test_bad_input_to_the_new_world_functions_names_the_argument():
    from jwarp.world.attach import covering_spheres
    from jwarp.world.motion import MotionOptions
    robot = jwarp.robot("arm7")
    w = World.of_shapes()
    w.add("ball", "sphere", [0.1], [2.0, 0.0, 0.0])
    w.add("floor", "plane")
    grid = World(np.ones((4, 4, 4)), [[0, 1]] * 3, 1 / 3)
    with pytest.raises(ValueError, match="worlds: expected at least one"):
        World.batch([])
    with pytest.raises(TypeError, match=r"worlds\[1\]: expected a World"):
        World.batch([w, "x"])
    with pytest.raises(ValueError, match=r"worlds\[0\]: a batch takes worlds of exact objects"):
        World.batch([grid])
    with pytest.raises(ValueError, match="i: expected a world of the batch"):
        World.batch([w, w]).select(5)
    with pytest.raises(KeyError, match="object 'nope'"):
        w.attach("nope", robot, list(robot.end_effectors)[0], np.zeros(robot.n_dof))
    with pytest.raises(ValueError, match="object 'floor': a plane cannot be attached"):
        w.attach("floor", robot, list(robot.end_effectors)[0], np.zeros(robot.n_dof))
    with pytest.raises(KeyError, match="object 'ball': not attached"):
        w.detach("ball", robot, np.zeros(robot.n_dof))
    with pytest.raises(ValueError, match="kind: an attached object must be"):
        covering_spheres("plane")
    with pytest.raises(ValueError, match="save: a world file holds a grid only|save: this world"):
        w.save("/tmp/never.npz")
    chk = MotionCheck(robot, w)
    with pytest.raises(ValueError, match=r"paths: expected shape"):
        chk.check(np.zeros((3, 5)))
    with pytest.raises(ValueError, match="paths: contains NaN"):
        chk.check(np.full((2, robot.n_dof), np.nan))
    for bad, name in ((-1.0, "margin"), (np.inf, "margin")):
        with pytest.raises(ValueError, match=name):
            chk.check(np.zeros((2, robot.n_dof)), margin=bad)
    with pytest.raises(ValueError, match="self_margin"):
        chk.check(np.zeros((2, robot.n_dof)), self_margin=-1)
    for kw, name in ((dict(min_step=0), "min_step"), (dict(max_evals=0), "max_evals"),
                     (dict(probe_len=-1), "probe_len"), (dict(points=-1), "points"),
                     (dict(rounds=0), "rounds")):
        with pytest.raises(ValueError, match=name):
            MotionCheck(robot, w, options=MotionOptions(**kw))
    with pytest.raises(TypeError, match="options: expected a MotionOptions"):
        MotionCheck(robot, w, options={"rounds": 2})
    with pytest.raises(ValueError, match="group: expected an integer >= 0"):
        w.shapes.add("g", "sphere", [0.1], group=-1)
    with pytest.raises(ValueError, match=r"poses: expected \(1, 4, 4\)"):
        w.move(["ball"], np.zeros((1, 2)))


def test_world_poses_indices_and_points_that_are_not_what_the_user_meant(device):
    """Reliability round 4, item 5: a transposed 4x4 pose (last row not [0, 0, 0, 1]) put
    the object at the origin (add and move); move accepted a reflection that add refuses;
    select(1.7) / select('1') returned an empty world; the distance of a NaN point was 1e30
    ("free"); detach took any robot and stripped another object's spheres."""
    T = pose_matrix([0.5, 0.2, 0.3], rpy_matrix([0.3, 0.2, 0.1]))
    w = World.of_shapes()
    with pytest.raises(ValueError, match=r"object 'b': pose's last row is .* not \[0, 0, 0, 1\]"):
        w.add("b", "box", [0.1, 0.1, 0.1], T.T)
    w.add("b", "box", [0.1, 0.1, 0.1], T)
    with pytest.raises(ValueError, match=r"object 'b': pose's last row"):
        w.move("b", T.T)
    flip = T.copy()
    flip[:3, 0] *= -1                                   # det -1: a reflection
    with pytest.raises(ValueError, match="object 'b': pose rotation is not a rotation matrix"):
        w.move("b", flip)
    with pytest.raises(ValueError, match="object 'c': pose rotation is not a rotation matrix"):
        w.add("c", "box", [0.1, 0.1, 0.1], flip)
    np.testing.assert_array_equal(w.shapes.pose("b"), T)   # refused moves changed nothing
    # the distance of a NaN point is an error, not 1e30
    with pytest.raises(ValueError, match=r"points: point \[1\] contains NaN"):
        w.distance([[0.0, 0.0, 0.0], [np.nan, 0.0, 0.0]])
    with pytest.raises(ValueError, match=r"points: expected shape \(\.\.\., 3\)"):
        w.distance([[0.0, 0.0]])
    # select takes an integer index only
    batch = World.batch([w, World.of_shapes()])
    for bad in (1.7, "1", True, None):
        with pytest.raises(TypeError, match="i: expected an integer index"):
            batch.select(bad)
    assert batch.select(np.int64(0)).object_ids == ["b"] and batch.select(1).object_ids == []
    with pytest.raises(TypeError, match="i: expected an integer index"):
        w.select(0.0)
    # detach only with a robot that carries the object
    robot = jwarp.robot("arm7")
    tcp = list(robot.end_effectors)[0]
    q0 = np.array([0.0, 0.8, 0.0, -1.0, 0.0, 0.5, 0.0])
    Th = jwarp.fk(robot, q0[None], dtype=np.float64)[0, robot.frame_index(tcp)]
    w2 = World.of_shapes()
    w2.add("part", "sphere", [0.03], Th[:3, 3])
    w2.add("tool", "box", [0.02, 0.02, 0.1], Th)
    carried = w2.attach("part", robot, tcp, q0)
    both = w2.attach("tool", carried, tcp, q0)
    for wrong in (robot, "arm7"):
        with pytest.raises(ValueError, match="robot: not a robot that carries object 'part'"):
            w2.detach("part", wrong, q0)
    with pytest.raises(ValueError, match="robot: not a robot that carries object 'tool'"):
        w2.detach("tool", carried, q0)    # carries 'part' only: detach would strip its spheres
    assert sorted(w2.attached) == ["part", "tool"] and w2.object_ids == []
    back = w2.detach("part", both, q0)
    assert len(back.spheres) == len(both.spheres) - (len(carried.spheres) - len(robot.spheres))
    back = w2.detach("tool", back, q0)
    assert len(back.spheres) == len(robot.spheres) and sorted(w2.object_ids) == ["part", "tool"]


def test_a_clearance_below_the_margin_names_the_margin(device):
    """Reliability round 4, item 9: a positive clearance below the margin was reported as
    "collision ... (clearance 5.00 mm)" without the margin it is below."""
    from jwarp.world.collision import min_distances
    robot = jwarp.robot("arm7")
    q0 = np.array([0.0, 0.8, 0.0, -1.0, 0.0, 0.5, 0.0])
    T = jwarp.fk(robot, q0[None], dtype=np.float64)[0, robot.frame_index(
        list(robot.end_effectors)[0])]
    w = World.of_shapes()
    w.add("ball", "sphere", [0.02], T[:3, 3] + [0.0, 0.0, 0.25])
    d = float(min_distances(robot, q0[None], w, dtype=np.float64)[0, 0])
    assert d > 0.01
    path = np.stack([q0, q0])
    chk = MotionCheck(robot, w, device=device)
    r = chk.check(path, margin=d + 0.02)
    assert not r.ok[0]
    reason = r.reason(0)
    assert reason.startswith("collision: ") and "vs object 'ball'" in reason
    assert f"below the margin {(d + 0.02) * 1e3:.2f} mm" in reason, reason
    r = chk.check(path, margin=d + 0.02, endpoint_margin=d + 0.01)
    assert "endpoint margin" in r.reason(0)
    # a real collision (clearance <= 0) keeps its words
    w.move("ball", T[:3, 3])
    r = chk.check(path, margin=0.0)
    assert not r.ok[0] and "below the margin" not in r.reason(0)


def test_adding_objects_one_by_one_is_amortised_constant_time():
    """Reliability round 4, item 11: every add copied every pose (10,000 objects took 7 s,
    50,000 took 187 s). The last quarter of 20,000 adds costs about what the first quarter
    does (a copy per add made it several times more), and the poses are all kept."""
    import time
    n = 20000
    w = World.of_shapes()
    marks = []
    t0 = time.perf_counter()
    for i in range(n):
        if i % (n // 4) == 0:
            marks.append(time.perf_counter())
        w.add(f"b{i}", "box", [0.01, 0.01, 0.01], [i * 1e-3, 0.0, 0.0])
    marks.append(time.perf_counter())
    first, last = marks[1] - marks[0], marks[4] - marks[3]
    assert last < 3.0 * first + 0.05, (first, last)
    assert marks[-1] - t0 < 30.0
    assert len(w.shapes) == n and w.shapes.pose(f"b{n - 1}")[0, 3] == pytest.approx(19.999)
    w.remove("b0")
    assert w.shapes.pose("b1")[0, 3] == pytest.approx(1e-3) and len(w.shapes) == n - 1
    w.add("again", "sphere", [0.1], [1.0, 2.0, 3.0])
    np.testing.assert_array_equal(w.shapes.pose("again")[:3, 3], [1.0, 2.0, 3.0])
    assert w.shapes.bounds().shape == (n, 3, 2)
