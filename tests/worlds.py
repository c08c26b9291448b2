"""Worlds shared by tests of several modules."""

import numpy as np


def block_world():
    """A 30 cm thick block in front of justin19, 5 cm voxels."""
    from jwarp.world import world_from_occupancy

    h = 0.05
    lim = np.array([[-0.5, 1.5], [-1.0, 1.0], [0.0, 1.6]])
    n = np.round((lim[:, 1] - lim[:, 0]) / h).astype(int) + 1
    X, Y, Z = np.meshgrid(*[lim[d, 0] + h * np.arange(n[d]) for d in range(3)], indexing="ij")
    return world_from_occupancy((np.abs(X - 0.6) < 0.15) & (Z < 1.0), lim, h)


def block_world_2d():
    """README's 2D block world for planar4: a block at x 0.5..0.75 m, |y| < 0.12 m, on a
    64 x 64 grid over [-1, 1]^2 m."""
    from jwarp.world import world_from_occupancy

    lim = np.array([[-1.0, 1.0], [-1.0, 1.0]])
    h = 2.0 / 63
    X, Y = np.meshgrid(*[lim[d, 0] + h * np.arange(64) for d in range(2)], indexing="ij")
    return world_from_occupancy((X > 0.5) & (X < 0.75) & (np.abs(Y) < 0.12), lim, h)


def grazing_paths(robot, n, delta, margin=0.0, W=3, seed=0, N=3000):
    """``n`` paths of W waypoints (self-free) and per path a ball that they pass at
    ``margin + delta`` [m] (the smallest clearance of any sphere over N samples a segment;
    the ball's radius is set to it): grazing for 0 < delta <~ 1 mm, a collision for
    delta < 0. Returns (paths (n, W, n_dof), the smallest clearance (n,) of a denser
    sampling, balls [(centre, radius)])."""
    from jwarp.core.limits import within_limits
    from jwarp.world.collision import min_distances
    from jwarp.world.path_feasibility import sphere_centres

    rng = np.random.default_rng(seed)
    lim = np.array(robot.joint_limits)
    mid = lim.mean(1)
    _, _, rad = robot.sphere_arrays()
    paths, balls, dense = [], [], []
    while len(paths) < n:
        q = mid + 0.7 * (rng.uniform(lim[:, 0], lim[:, 1], size=(2, robot.n_dof)) - mid)
        path = q[:1] + np.linspace(0, 1, W)[:, None] * (q[1:] - q[:1])
        if not within_limits(robot, q).all():  # (linear limits: convex, the ends suffice)
            continue
        u = np.linspace(0, 1, N * (W - 1) + 1)
        qs = path[0] + u[:, None] * (path[-1] - path[0])
        if min_distances(robot, qs[::25], None, dtype=np.float64)[:, 1].min() < 0.01:
            continue
        x = sphere_centres(robot, qs)                      # (samples, S, 3)
        i = int(rng.integers(len(u) // 4, 3 * len(u) // 4))
        s = int(rng.integers(len(rad)))
        v = x[i + 1, s] - x[i - 1, s]
        if np.linalg.norm(v) < 1e-6:
            continue
        nrm = np.cross(v, rng.normal(size=3))              # across the sphere's motion
        c = x[i, s] + nrm / np.linalg.norm(nrm) * (rad[s] + 0.15)
        R = (np.linalg.norm(x - c, axis=-1) - rad).min() - margin - delta
        if R < 0.03 or c[2] - R < 0.0:
            continue
        fine = np.linspace(0, 1, 8 * N * (W - 1) + 1)
        xf = sphere_centres(robot, path[0] + fine[:, None] * (path[-1] - path[0]))
        paths.append(path)
        balls.append((c, R))
        dense.append((np.linalg.norm(xf - c, axis=-1) - rad).min() - R)
    return np.array(paths), np.array(dense), balls


def ball_worlds(balls):
    """A batch of worlds (:meth:`World.batch`), world i the ball ``balls[i]`` alone."""
    from jwarp.world import World

    ws = []
    for c, R in balls:
        w = World.of_shapes()
        w.add("ball", "sphere", [R], c)
        ws.append(w)
    return World.batch(ws)


def box_pole_scene(floor: bool = False):
    """arm7's exact test scene: a 20 cm box in front, a pole to the side (and, with
    ``floor``, a plane 5 cm below the base)."""
    from jwarp.world import World
    from jwarp.world.primitives import pose_matrix

    w = World.of_shapes()
    w.add("box", "box", [0.2, 0.2, 0.2], [0.45, 0.0, 0.5])
    w.add("pole", "cylinder", [0.6, 0.03], pose_matrix([0.0, 0.45, 0.5]))
    if floor:
        w.add("floor", "plane", pose=pose_matrix([0, 0, -0.05]))
    return w
