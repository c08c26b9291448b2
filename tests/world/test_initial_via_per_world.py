"""Random initial paths in a batch of worlds (``initial_paths(..., per_world=k)``): each
row's via points are free in its own world (checked independently by the spheres' exact
distances in that world alone), not in the union of all worlds."""

import numpy as np

import jwarp
from jwarp.world import World
from jwarp.world.collision import min_distances
from jwarp.world.path_feasibility import initial_paths


def test_via_points_free_in_their_own_world():
    robot = jwarp.robot("arm7")
    a = World.of_shapes()
    a.add("left", "box", [1.0, 0.8, 1.6], [0.3, 0.75, 0.6])
    b = World.of_shapes()
    b.add("right", "box", [1.0, 0.8, 1.6], [0.3, -0.75, 0.6])
    worlds = [a, b]
    k = 24
    lim = np.array(robot.joint_limits)
    q = np.repeat(np.mean(lim, axis=1)[None], 2 * k, 0)
    # start == goal, one via point, 3 waypoints: the middle waypoint is the via point
    paths = initial_paths(q, q, 3, "random", robot=robot, n_via=(1, 1),
                          rng=np.random.default_rng(3), world=World.batch(worlds),
                          device="cpu", per_world=k)
    via = paths[:, 1]
    assert paths.shape == (2 * k, 3, robot.n_dof)
    assert np.abs(via - q).max() > 0.1                       # drawn, not the start
    crossed = 0
    for w in range(2):
        mine = via[w * k:(w + 1) * k]
        d_own = min_distances(robot, mine, worlds[w], dtype=np.float64)[:, 0]
        assert (d_own > 0).all(), (w, d_own)
        d_other = min_distances(robot, mine, worlds[1 - w], dtype=np.float64)[:, 0]
        crossed += int((d_other <= 0).sum())
    # the worlds differ enough that some via points are free only in their own world
    # (sampling in the union of the worlds would refuse them)
    assert crossed > 0
    # deterministic with the generator
    again = initial_paths(q, q, 3, "random", robot=robot, n_via=(1, 1),
                          rng=np.random.default_rng(3), world=World.batch(worlds),
                          device="cpu", per_world=k)
    np.testing.assert_array_equal(paths, again)


def test_polyline_paths_match_the_one_row_function():
    """The vectorised polylines equal ``polyline_path`` row by row (numpy's interp),
    degenerate rows (a zero-length segment, all points equal) included."""
    from jwarp.world.path_feasibility import polyline_path, polyline_paths

    rng = np.random.default_rng(0)
    for k in (1, 2, 3):
        s, g = rng.normal(size=(40, 7)), rng.normal(size=(40, 7))
        v = rng.normal(size=(40, k, 7))
        v[0, 0] = s[0]                    # a zero-length first segment
        g[1], v[1] = s[1], s[1]           # every point the same
        got = polyline_paths(s, v, g, 17)
        want = np.stack([polyline_path(s[i], v[i], g[i], 17) for i in range(40)])
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
        np.testing.assert_array_equal(got[:, 0], s)
        np.testing.assert_array_equal(got[:, -1], g)
