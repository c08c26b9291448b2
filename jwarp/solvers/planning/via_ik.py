"""Initial paths through via points found by collision-free batched IK
(:attr:`PlanOptions.via_ik`): for problems whose straight line is not proven, some of the
random multi-starts are replaced by paths through

* *pre-goal* points: the goal's tool pose pulled back along its approach axis (the tool
  frame's z axis: out of a shelf, a cage or a box) by :data:`BACK_OFF` metres, solved
  from the goal configuration, so the last segment is a short move along the approach;
* *detour* points: the tool at the straight line's first colliding waypoint lifted
  against gravity (:data:`LIFT`) or moved sideways (perpendicular to the tool's
  start-goal chord, :data:`SIDE`), solved from that waypoint (around the object the line
  hits);

all of one problem set in one :class:`jwarp.solvers.ik.IKSolver` call (:data:`IK_SEEDS`
seeds per via point: the configuration it is near, then that one jittered). The IK
solves the pose without a world (its solver is made once per robot and reused by every
planner, of any world), and a via point is the first of its IK seeds that is on target
and collision-free at the planner's margins in the problem's world (in a batch of worlds,
:meth:`jwarp.world.sdf.World.batch`, its own; the anchor is found in that world too). The paths are
start -> detour -> pre-goal -> goal, start -> pre-goal -> goal and start -> detour -> goal
(in this order of preference; the W waypoints spread along the polyline as every
via-point start). The same problems and seed give the same paths.

Measured on the Panda scene problems (``benchmarks/bench_scenes.py --versus via_ik=0``,
benchmarks/README.md, issue 45): the pre-goal points solve most shelf and cage problems
the random starts leave to the RRT fallback; one call costs about 5-10 ms on one CPU core.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from jwarp.core.caches import IdentityCache
from jwarp.core.limits import project_numpy
from jwarp.model import RobotModel
from jwarp.world.path_feasibility import collision_free, polyline_path

#: distances [m] the goal's tool pose is pulled back along its approach axis (-z)
BACK_OFF = (0.15, 0.3, 0.45)
#: heights [m] the tool at the first colliding waypoint of the line is lifted
LIFT = (0.25,)
#: sideways offsets [m] of that tool position (both sides)
SIDE = (0.2,)
#: iterations of the IK (the via points need not be exact: :data:`TOL_POS`)
IK_ITERATIONS = 20
#: IK seeds per via point: the configuration it is near (the goal, the line's waypoint),
#: then that one with every joint moved by a normal deviate of :data:`JITTER` [rad or m]
IK_SEEDS = 3
JITTER = 0.3
#: position / rotation tolerance of a via point [m], [rad]
TOL_POS, TOL_ROT = 0.01, 0.05


def via_frame(model: RobotModel, frame: Any) -> int:
    """The frame of the via points: ``frame`` (a name or index), None: the robot's first
    end effector, else its last frame."""
    if frame is not None:
        return model.frame_index(frame, "via_frame")
    if model.end_effectors:
        return int(next(iter(model.end_effectors.values())))
    return model.n_frames - 1


def _up(model: RobotModel) -> np.ndarray:
    g = np.asarray(model.gravity, np.float64)
    n = float(np.linalg.norm(g))
    return np.array([0.0, 0.0, 1.0]) if n == 0 else -g / n


def ik_via_paths(model: RobotModel, world: Any, q0: np.ndarray, q1: np.ndarray,
                 lines: np.ndarray, k: int, W: int, **kw: Any) -> tuple[np.ndarray, np.ndarray]:
    """Up to ``k`` paths (B, k, W, n_dof) per problem through the via points of
    :func:`ik_via_points` (the keywords are its), and how many of them each problem has
    (B,) (the rest of its rows are zeros)."""
    B, n = q0.shape
    out = np.zeros((B, k, W, n))
    count = np.zeros(B, np.int64)
    if k <= 0:
        return out, count
    for b, vias in enumerate(ik_via_points(model, world, q0, q1, lines, k, **kw)):
        for i, v in enumerate(vias):
            out[b, i] = polyline_path(q0[b], v, q1[b], W)
        count[b] = len(vias)
    return project_numpy(model, out), count


def ik_via_points(model: RobotModel, world: Any, q0: np.ndarray, q1: np.ndarray,
                  lines: np.ndarray, k: int, *, frame: Any = None, margin: float = 0.0,
                  self_margin: float = 0.0, device: Any = None, dtype: Any = np.float32,
                  seed: Any = 0, worlds: Any = None) -> list[list[np.ndarray]]:
    """Per problem up to ``k`` via-point sequences (each (m, n_dof), m = 1 or 2), in the
    order of preference (module docstring), every point collision-free in ``world`` at
    ``margin`` and ``self_margin``; one IK call for all problems.

    ``model``: the robot as the planner plans on it (its mesh margin already applied;
    its collision model is not checked again: the planner checked it, or its options
    waived the check); ``q0``, ``q1`` (B, n_dof): start and goal; ``lines`` (B, W', n_dof): each problem's
    straight line (its first colliding waypoint is the detour's anchor); ``frame``: the
    tool frame (:func:`via_frame`); ``seed``: of the IK seeds' jitter (an integer, a
    numpy Generator, None: fresh entropy); ``worlds`` (B,) ints: with a batch of worlds,
    problem b is in world ``worlds[b]`` (None: world b)."""
    from jwarp.kinematics import fk

    B, n = q0.shape
    out: list[list[np.ndarray]] = [[] for _ in range(B)]
    if B == 0 or k <= 0 or model.workspace_dim != 3:
        return out
    f = via_frame(model, frame)
    up = _up(model)
    batched = world is not None and world.n_worlds > 1
    own = None  # a batch of worlds: the world of each problem
    if batched:
        own = np.arange(B) if worlds is None else np.asarray(worlds, np.int64).reshape(-1)
        if own.shape != (B,) or own.min() < 0 or own.max() >= world.n_worlds:
            raise ValueError(f"worlds: expected ({B},) worlds of the batch in "
                             f"[0, {world.n_worlds}), got {worlds!r}")
    T1 = np.asarray(fk(model, q1.astype(np.float64), device=device, dtype=np.float64))[:, f]
    T0 = np.asarray(fk(model, q0.astype(np.float64), device=device, dtype=np.float64))[:, f]
    # the first colliding waypoint of each line (its middle if none collides: a swept
    # collision between waypoints)
    Wl = lines.shape[1]
    inner = lines[:, 1:-1].reshape(-1, n)
    if own is None:
        free = collision_free(model, world, inner, margin, device=device,
                              self_margin=self_margin, meshes=False)
    else:
        free = free_in_worlds(model, world, inner, np.repeat(own, Wl - 2), margin,
                              self_margin, device, meshes=False)
    free = free.reshape(B, Wl - 2)
    hit = np.where(free.all(1), Wl // 2, 1 + np.argmax(~free, axis=1))
    anchor = lines[np.arange(B), hit]
    Ta = np.asarray(fk(model, anchor.astype(np.float64), device=device, dtype=np.float64))[:, f]
    targets, seeds, kind, owner = [], [], [], []
    for b in range(B):
        approach = T1[b, :3, 2]
        for d in BACK_OFF:
            T = T1[b].copy()
            T[:3, 3] -= d * approach
            targets.append(T)
            seeds.append(q1[b])
            kind.append("pre")
            owner.append(b)
        chord = T1[b, :3, 3] - T0[b, :3, 3]
        side = np.cross(up, chord)
        ns = float(np.linalg.norm(side))
        side = side / ns if ns > 1e-9 else np.cross(up, [1.0, 0.0, 0.0])
        offsets = [h * up for h in LIFT] + [s * sgn * side for s in SIDE for sgn in (1, -1)]
        for off in offsets:
            T = Ta[b].copy()
            T[:3, 3] += off
            targets.append(T)
            seeds.append(anchor[b])
            kind.append("detour")
            owner.append(b)
    T = np.stack(targets)
    # IK seeds per target: the configuration it is near, then that one jittered
    S = np.repeat(np.stack(seeds)[:, None], IK_SEEDS, 1)
    rng = np.random.default_rng(seed)
    S[:, 1:] += rng.normal(0.0, JITTER, S[:, 1:].shape)
    S = project_numpy(model, S)
    ik = _solver(model, f, len(T), margin, device, dtype, S.reshape(-1, n)).solve(T, S)
    kind_a, owner_a = np.array(kind), np.array(owner)
    # every seed on target, checked in its problem's world at the planner's margins by
    # the spheres (an inner waypoint the spheres touch keeps its paths from the fast
    # proofs): the first free one
    qa = np.asarray(ik.all_q, np.float64)  # (targets, IK_SEEDS, n)
    oka = np.asarray(ik.all_feasible, bool).copy()
    if oka.any():
        if own is None:
            oka[oka] = collision_free(model, world, qa[oka], margin, device=device,
                                      self_margin=self_margin, meshes=False)
        else:
            seed_world = np.repeat(own[owner_a], qa.shape[1]).reshape(oka.shape)
            oka[oka] = free_in_worlds(model, world, qa[oka], seed_world[oka], margin,
                                      self_margin, device, meshes=False)
    ok = oka.any(1)
    q = qa[np.arange(len(qa)), np.argmax(oka, axis=1)]
    for b in range(B):
        mine = (owner_a == b) & ok
        pre = q[mine & (kind_a == "pre")]
        det = q[mine & (kind_a == "detour")]
        vias: list[np.ndarray] = []
        if len(det) and len(pre):
            vias.append(np.stack([det[0], pre[-1]]))
        vias += [p[None] for p in pre[::-1]]
        vias += [d[None] for d in det]
        out[b] = vias[:k]
    return out


#: the via points' IK solvers, kept on their robot (one per frame, target count, margin,
#: device and dtype): they hold no world, so a planner of any world reuses them
_SOLVERS: IdentityCache = IdentityCache(32, owner=0)


def _solver(model: RobotModel, frame: int, n_targets: int, margin: float, device: Any,
            dtype: Any, q_default: np.ndarray) -> Any:
    """The IK solver of ``n_targets`` via points (:data:`IK_SEEDS` seeds each, pose and
    self-collision only: the world is checked afterwards), made once per robot and
    shape and reused: its closeness pose per seed set to ``q_default`` and its
    generator reseeded (the same targets and seeds give the same points)."""
    from jwarp.core.arrays import resolve_device
    from jwarp.solvers.ik import IKOptions, IKSolver

    dev = resolve_device(device)
    key = (int(frame), int(n_targets), float(margin), str(dev), np.dtype(dtype).str)
    s = _SOLVERS.get(key, (model,))
    if s is None:
        opts = IKOptions(n_starts=IK_SEEDS, iterations=IK_ITERATIONS, margin=margin, seed=0,
                         tol_pos=TOL_POS, tol_rot=TOL_ROT, restart_after=None,
                         q_default=q_default,
                         # the planner's robot as it plans on it (its mesh margin applied,
                         # its collision model checked or waived by the planner's options)
                         mesh_margin=False, allow_no_collision=True)
        s = _SOLVERS.put(key, (model,), IKSolver(model, frame, n_targets, opts, world=None,
                                                 device=dev, dtype=dtype))
    else:
        s.objective.q_default.assign(np.asarray(q_default, s.npdt).reshape(
            s.objective.q_default.shape))
        s.reseed(0)
    return s


def free_in_worlds(model: RobotModel, world: Any, q: np.ndarray, worlds: np.ndarray,
                   margin: float, self_margin: float, device: Any = None,
                   meshes: bool = True) -> np.ndarray:
    """(N,) bool: configuration i of q (N, n_dof) collision-free in world ``worlds[i]`` of
    the batch ``world`` (:meth:`jwarp.world.sdf.World.batch`): the planner's check
    (:func:`jwarp.world.path_feasibility.collision_free` with ``per_world``) on the rows
    of each world padded to the most any world has (with the first configuration; the
    padding's verdicts are dropped)."""
    q = np.asarray(q, np.float64).reshape(len(worlds), -1)
    N = q.shape[0]
    if N == 0:
        return np.zeros(0, bool)
    worlds = np.asarray(worlds, np.int64)
    nw = int(world.n_worlds)
    counts = np.bincount(worlds, minlength=nw)
    per = int(counts.max())
    order = np.argsort(worlds, kind="stable")
    first = np.concatenate([[0], np.cumsum(counts)[:-1]])
    rank = np.empty(N, np.int64)
    rank[order] = np.arange(N) - first[worlds[order]]
    slot = worlds * per + rank
    qp = np.repeat(q[:1], nw * per, axis=0)  # the padding: some configuration in the limits
    qp[slot] = q
    return collision_free(model, world, qp, margin, device=device, self_margin=self_margin,
                          per_world=per, meshes=meshes)[slot]
