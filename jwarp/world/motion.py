"""Continuous feasibility of paths, checked on the device (host side of
:mod:`jwarp.kernels.motion`).

"Feasible" means: every waypoint within the joint limits, and along the whole continuous
motion between the waypoints (linear in joint space) every collision sphere keeps
``margin`` [m] from the world and from every sphere it may collide with; on the first and
the last segment the clearance required is ``min(margin, endpoint_margin)`` (so a grasp
pose closer to an object than the path margin can be reached). Distances are exact for
the world's objects; a grid counts with its declared ``grid_error`` subtracted.

One call checks a batch of paths on the device, in a few launches: on the CPU by
conservative advancement (one thread per segment, :attr:`MotionOptions.method`
"advance"), on a GPU by interval refinement (every segment split into intervals, each
proven from its midpoint or cut to what it leaves unproven, level by level, every
interval of a level a thread: "levels"; a fixed number of launches, no host read), both
with the same travel bound; a last launch reduces them: per path a flag, and for an infeasible one the first
offending place (in waypoint units), the sphere (its link) and the object or the other
sphere. Only these few numbers per path are read back.

Example::

    chk = MotionCheck("panda.urdf", world, device="cpu")
    res = chk.check(paths)                 # paths (P, W, n_dof)
    res.ok                                 # (P,) bool
    print(res.reason(0))                   # "sphere 12 of link 'panda_hand' vs object ..."
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import warp as wp

from jwarp.core.arrays import init_warp, real_array, real_number, resolve_device
from jwarp.core.caches import IdentityCache
from jwarp.core.device import put_model
from jwarp.core.limits import LIMIT_TOL
from jwarp.core.types import DeviceLike
from jwarp.kernels import motion as mk
from jwarp.model import RobotModel
from jwarp.utils.checks import check_int
from jwarp.world.collision import check_world, mm_text
from jwarp.world.device_world import DeviceWorld
from jwarp.world.reach import point_reach
from jwarp.world.sdf import World

__all__ = ["MotionCheck", "MotionOptions", "PathCheck", "check_paths", "motion_check",
           "pair_travel_tables",
           "sphere_reach", "travel_bound"]


@dataclass
class MotionOptions:
    """Options of the continuous check (conservative advancement or interval refinement,
    :mod:`jwarp.kernels.motion`).

    Attributes:
        min_step: the smallest proven step, as a fraction of a segment, in (0, 1): a
            segment whose motion can only be proven in smaller steps (it grazes the
            margin) is reported uncertified.
        max_evals: most evaluations per segment of the advancement (then uncertified),
            >= 1 (the levels have none: ``levels`` and ``capacity`` bound them).
        probe_len: ``"advance"``: a coarse pass probes each segment every ``probe_len``
            [m] of sphere travel (at most 16 probes) for a clearance below the margin
            before the advancement, > 0 (colliding paths are found in a few evaluations).
        points: ``"advance"``: evaluations of every segment in parallel before the
            advancement (each proves an interval around it; the advancement goes on from
            the first gap), >= 1, or 0 for none; None: 16 on a GPU (a thread per
            evaluation), 0 on the CPU.
        rounds: ``"advance"``: rounds of parallel evaluations (>= 1): each evaluates
            ``points`` points of every segment's part not proven yet (denser near its
            start after the first), so a segment that grazes an obstacle is proven in
            parallel steps.
        method: ``"levels"`` (interval refinement: every segment split into
            ``intervals`` intervals, each proven from its midpoint or cut to the two parts
            that evaluation leaves unproven (each at most half of it), level by level, all
            intervals of a level in parallel), ``"advance"`` (conservative
            advancement from the start of each segment, one thread per segment, after
            ``points`` x ``rounds`` parallel evaluations), or None: "levels" on a GPU,
            "advance" on the CPU. Both use the same travel bound and evaluation.
        intervals: ``"levels"``: intervals per segment at level 0, in [1, 4096].
        levels: ``"levels"``: the most levels (>= 1; level l has ``intervals * 2**l``
            per segment), or None: down to ``min_step`` (an interval not proven whose step
            is below ``min_step`` makes its segment uncertified, as in the advancement;
            one narrower than ``min_step`` is proven or that).
            A segment still unresolved after the last level goes to ``fallback``.
        capacity: ``"levels"``: intervals the work list holds (>= 1), or None: twice the
            level-0 intervals of the launch (at least 1024). On a GPU each holds a row of
            evaluation scratch (configuration, frames, sphere centres). An interval that
            does not fit is left unresolved (``fallback``).
        fallback: ``"levels"``: a segment left unresolved by the levels (capacity, level
            cap) goes on with the conservative advancement from its proven prefix (True,
            bounded by ``max_evals`` and ``min_step``), or is reported uncertified (False).
        meshes: a path the spheres do not prove (a collision less deep than the spheres'
            protrusion past the meshes, or a segment left uncertified) is proven by the
            mesh certificate where the robot records its collision pieces
            (:meth:`MotionCheck.mesh_recheck`, :mod:`jwarp.world.mesh_check`); False:
            the spheres decide alone.
    """

    min_step: float = 1e-5
    max_evals: int = 4000
    probe_len: float = 0.1
    points: int | None = None
    rounds: int = 4
    method: str | None = None
    intervals: int = 16
    levels: int | None = None
    capacity: int | None = None
    fallback: bool = True
    meshes: bool = True

    def validate(self) -> None:
        if not isinstance(self.meshes, (bool, np.bool_)):
            raise TypeError(f"meshes: expected True or False, got {self.meshes!r}")
        d = real_number(self.min_step, "min_step")
        if not (np.isfinite(d) and 0 < d < 1):
            raise ValueError(f"min_step: expected a fraction in (0, 1), got {self.min_step!r}")
        check_int(self.rounds, "rounds", 1)
        if self.points is not None and (isinstance(self.points, bool) or not isinstance(
                self.points, (int, np.integer)) or self.points < 0):
            raise ValueError(f"points: expected an integer >= 0 or None, got {self.points!r}")
        pl = real_number(self.probe_len, "probe_len")
        if not (np.isfinite(pl) and pl > 0):
            raise ValueError(f"probe_len: expected a length > 0 [m], got {self.probe_len!r}")
        v = self.max_evals
        check_int(v, "max_evals", 1)
        if self.method not in (None, "levels", "advance"):
            raise ValueError(f"method: expected 'levels', 'advance' or None, got "
                             f"{self.method!r}")
        v = self.intervals
        check_int(v, "intervals", 1, 4096)
        for name, lo in (("levels", 1), ("capacity", 1)):
            v = getattr(self, name)
            check_int(v, name, lo, none=True)
        if not isinstance(self.fallback, (bool, np.bool_)):
            raise ValueError(f"fallback: expected True or False, got {self.fallback!r}")

    def n_levels(self) -> int:
        """The levels of ``"levels"``: :attr:`levels`, at most down to the first level of
        intervals narrower than ``min_step`` (each is proven or uncertified there), and
        at most ``intervals * 2**(levels - 1) <= 2**29`` intervals per segment."""
        n = 1
        while (1.0 / (2.0 * self.intervals * 2 ** (n - 1)) >= self.min_step
               and self.intervals * 2 ** n <= 2 ** 29):
            n += 1
        return n if self.levels is None else min(n, int(self.levels))

    def resolved_method(self, device: wp.Device) -> str:
        """:attr:`method` on ``device`` (None: "levels" on a GPU, "advance" on the CPU)."""
        if self.method is not None:
            return self.method
        return "levels" if device.is_cuda else "advance"


_TABLES: OrderedDict[tuple, Any] = OrderedDict()


def _cached(kind: str, model: RobotModel, build: Any) -> Any:
    """Robot tables cached by the robot's content (a few robots at a time)."""
    from jwarp.core.device import content_key

    key = (kind, content_key(model))
    hit = _TABLES.get(key)
    if hit is None:
        hit = _TABLES[key] = build(model)
        while len(_TABLES) > 16:
            _TABLES.popitem(last=False)
    return hit


def sphere_reach(robot: RobotModel) -> np.ndarray:
    """(n_spheres, n_frames) float64: for each sphere s and frame i, a bound [m] of the
    distance of the sphere's centre from frame i's joint axis over every configuration
    (0 where frame i is not an ancestor of the sphere's frame; 1 for a prismatic frame,
    whose joint moves the centre by exactly its change). The bound is the sum of the
    frames' translation lengths along the chain below i (|d| + |r| of a DH frame, plus the
    largest joint offset of a prismatic one) plus the centre's offset in its frame."""
    return _cached("reach", robot, _sphere_reach).copy()


def _sphere_reach(model: RobotModel) -> np.ndarray:
    sf, sp, _ = model.sphere_arrays()
    return point_reach(model, sf, sp)


def pair_travel_tables(robot: RobotModel) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per self-collision frame pair (the order of the collision tables) the joints that
    change the distance between its spheres, as CSR ``(start (P_f + 1,), frame (E,),
    weight (E,))``: the frames on both branches below the pair's common ancestor (the
    ancestor's own joint and those above it move both frames rigidly) with the largest
    reach (:func:`sphere_reach`) of the pair's spheres on that branch. A segment moving the
    frame angles by ``dtheta`` changes a pair's distance by at most
    ``sum weight |dtheta[frame]|``."""
    return _cached("pairs", robot, _pair_travel_tables)


def _pair_travel_tables(model: RobotModel) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    from jwarp.core.device import collision_tables

    rt = collision_tables(model)
    R = sphere_reach(model) if len(model.spheres) else np.zeros((0, model.n_frames))
    sf = np.asarray(model.sphere_arrays()[0], int)
    nf = model.n_frames
    Rf = np.zeros((nf, nf))
    for s, f in enumerate(sf):
        Rf[f] = np.maximum(Rf[f], R[s])
    parents = model.parents

    def chain(f: int) -> list[int]:
        out = []
        while f >= 0:
            out.append(f)
            f = int(parents[f])
        return out

    start, frames, weights = [0], [], []
    for fa, fb in zip(rt["fpair_a"], rt["fpair_b"]):
        ca, cb = chain(int(fa)), chain(int(fb))
        common = set(ca) & set(cb)
        for f, c in ((int(fa), ca), (int(fb), cb)):
            for i in c:
                if i in common:
                    break
                frames.append(i)
                weights.append(Rf[f, i])
        start.append(len(frames))
    return (np.array(start, np.int32), np.array(frames or [0], np.int32),
            np.array(weights or [0.0], np.float64))


def travel_bound(robot: RobotModel, paths: np.ndarray, reach: np.ndarray | None = None
                 ) -> np.ndarray:
    """(P, W - 1) [m]: a bound of the largest travel of any sphere centre along each
    segment of ``paths`` (P, W, n_dof) (numpy; :func:`sphere_reach` ``reach`` may be
    passed to reuse it)."""
    model = robot
    if reach is None:  # the robot's own reach: its front and coupling cached with it
        front, C = _cached("travel", model, _travel_tables)
    else:
        front, C = reach_front(reach) if reach.size else reach, _coupling(model)
    if front.size == 0:
        return np.zeros(paths.shape[:-2] + (paths.shape[-2] - 1,))
    dth = np.abs(np.diff(np.asarray(paths, np.float64), axis=-2) @ C.T)   # (..., W-1, nf)
    # the largest over the spheres needs only those no other sphere's reach bounds in
    # every frame (the travel is dth @ reach with dth >= 0: a dominated row never wins);
    # on a serial arm that is a few of its spheres (the Panda: 2 of 125)
    return (dth @ front.T).max(axis=-1)


def _coupling(model: RobotModel) -> np.ndarray:
    """(n_frames, n_dof): each frame's joint angle per joint (the couplings)."""
    C = np.zeros((model.n_frames, model.n_dof))
    for i, f in enumerate(model.frames):
        for j, c in f.coupling:
            C[i, j] += c
    return C


def _travel_tables(model: RobotModel) -> tuple[np.ndarray, np.ndarray]:
    """(:func:`reach_front` of the robot's :func:`sphere_reach`, :func:`_coupling`)."""
    R = _sphere_reach(model)
    return (reach_front(R) if R.size else R), _coupling(model)


def reach_front(reach: np.ndarray) -> np.ndarray:
    """The rows of ``reach`` (S, F) >= 0 that no other row bounds in every column (one of
    equal rows kept): ``max_s x . reach[s]`` over them equals the max over all rows for
    every ``x >= 0``."""
    R = np.asarray(reach, np.float64)
    if R.ndim != 2 or not np.all(R >= 0):
        raise ValueError(f"reach: expected a table (S, F) of bounds >= 0, got shape {R.shape}")
    if len(R) < 2:
        return R
    ge = np.asarray((R[:, None, :] >= R[None, :, :]).all(-1))  # ge[j, i]: row j bounds row i
    np.fill_diagonal(ge, False)
    same = ge & ge.T                                      # equal rows: the first stays
    beaten = (ge & ~same).any(0) | np.triu(same, 1).any(0)
    return R[~beaten]


_DEVICE_TABLES: OrderedDict[tuple, tuple] = OrderedDict()


def _device_tables(model: RobotModel, dev: Any, n_spheres: int) -> tuple:
    """The robot's travel tables on ``dev`` (read only; shared by the checks of one robot
    content and device): ``(reach (n_spheres, n_frames), (fp_start, fp_frame,
    fp_weight))`` (:func:`sphere_reach`, :func:`pair_travel_tables`)."""
    from jwarp.core.device import content_key

    key = (content_key(model), str(dev))
    hit = _DEVICE_TABLES.get(key)
    if hit is None:
        reach = (_cached("reach", model, _sphere_reach) if n_spheres
                 else np.zeros((0, model.n_frames)))
        fs, ff, fw = pair_travel_tables(model)
        hit = _DEVICE_TABLES[key] = (
            wp.array(np.ascontiguousarray(reach, np.float64), dtype=wp.float64, device=dev),
            (wp.array(fs, dtype=wp.int32, device=dev), wp.array(ff, dtype=wp.int32, device=dev),
             wp.array(fw, dtype=wp.float64, device=dev)))
        while len(_DEVICE_TABLES) > 16:
            _DEVICE_TABLES.popitem(last=False)
    else:
        _DEVICE_TABLES.move_to_end(key)
    return hit


@dataclass
class PathCheck:
    """Results of :meth:`MotionCheck.check` for P paths (numpy).

    Attributes:
        ok: (P,) bool, feasible.
        code: (P,) int, :data:`jwarp.kernels.motion.CODE_NAMES` index of the first failure.
        where: (P,) float, its place in waypoint units (segment t + fraction).
        what: (P, 2) int: sphere a and object b (world; -2 = the grid), or spheres a, b
            (self), -1 where not applicable.
        clearance: (P,) float [m] at that place.
        evaluations: the configurations the check evaluated, all paths together (its
            work: a skipped segment costs none).
    """

    ok: np.ndarray
    code: np.ndarray
    where: np.ndarray
    what: np.ndarray
    clearance: np.ndarray
    robot: Any = None
    world: Any = None
    #: the margins [m] the paths were checked with (None: not known)
    margin: float | None = None
    endpoint_margin: float | None = None
    self_margin: float | None = None
    evaluations: int = 0

    def _clearance_text(self, i: int, self_pair: bool) -> str:
        """``clearance 3.00 mm`` and, when positive, the margin it is below."""
        d = float(self.clearance[i])
        mm = f"clearance {mm_text(d)} mm"
        if d <= 0 or self.margin is None:
            return mm
        if self_pair:
            return f"{mm}, below the self margin {mm_text(float(self.self_margin or 0.0))} mm"
        em = self.endpoint_margin
        both = "" if em is None or em == self.margin else \
            f" (endpoint margin {mm_text(em)} mm on the first and last segment)"
        return f"{mm}, below the margin {mm_text(self.margin)} mm{both}"

    def reason(self, i: int) -> str:
        """Why path ``i`` is infeasible, in words ("feasible" if it is not)."""
        c = int(self.code[i])
        if c == 0:
            return "feasible"
        if c == 5:
            return "not checked: another path of its problem was proven first"
        at = f"at waypoint {self.where[i]:.3f}"
        a, b = (int(v) for v in self.what[i])
        if c == 4:
            return f"waypoint {int(round(self.where[i]))} outside the joint limits"
        link = _link(self.robot, a)
        mm = f"clearance {mm_text(self.clearance[i])} mm"
        if c == 2:
            return (f"self collision: {link} vs {_link(self.robot, b)} {at} "
                    f"({self._clearance_text(i, True)})")
        other = self.world.object_name(b) if self.world is not None else str(b)
        if c == 1:
            return (f"collision: {link} vs object '{other}' {at} "
                    f"({self._clearance_text(i, False)})")
        if c == 6:
            return (f"uncertified: {link} grazes {_link(self.robot, b)} {at} ({mm}): the motion "
                    f"cannot be proven to keep the self-collision margin there")
        if a < 0:
            return (f"uncertified {at}: the motion was not proven within the check's work "
                    f"budget (MotionOptions capacity, levels)")
        return (f"uncertified: {link} grazes '{other}' {at} ({mm}): the motion cannot be "
                f"proven to keep the margin there; lower the margin or move the path away")

    def reasons(self) -> list[str]:
        return [self.reason(i) for i in range(len(self.ok))]


def _link(robot: RobotModel | None, s: int) -> str:
    if robot is None or s < 0:
        return f"sphere {s}"
    f = robot.spheres[s].frame
    return f"sphere {s} of link '{robot.frames[f].name}'"


class MotionCheck:
    """A persistent continuous path check of one robot in one world on one device (the
    Model: robot tables, world struct, sphere travel bounds; the Data: scratch and
    outputs, grown on demand and reused).

    Args:
        robot: RobotModel (rigid; transmission errors are handled by the caller).
        world: :class:`World` of the robot's workspace dimension, or None (self only).
        device: Warp device (None: the preferred one).
        options: :class:`MotionOptions`.
    """

    def __init__(self, robot: RobotModel, world: World | None, *, device: DeviceLike = None,
                 options: MotionOptions | None = None) -> None:
        init_warp()
        self.robot = robot
        check_world(self.robot, world)
        self.world = world
        self.device = resolve_device(device)
        self.options = options or MotionOptions()
        if not isinstance(self.options, MotionOptions):
            raise TypeError(f"options: expected a MotionOptions, got "
                            f"{type(self.options).__name__}")
        self.options.validate()
        dev = self.device
        self.model = put_model(self.robot, dev, wp.float64)
        sp = self.model.spheres
        self.n_spheres = sp.n_spheres
        self.device_world = DeviceWorld(world, dev, wp.float64)
        self.k = mk.funcs()  # the structs (the kernels: built per launch, those it uses)
        cm = self.k.CheckModel()
        cm.model = self.model.frame_struct
        cm.rho = self.model.dh0_3d
        cm.spheres = sp.struct
        cm.use_world = int(world is not None and sp.n_spheres > 0)
        cm.use_self = int(sp.n_pairs > 0)
        cm.bound_skip = 0  # set per check (the world's objects may change)
        self._reach, self._fp = _device_tables(self.robot, dev, sp.n_spheres)
        cm.reach = self._reach
        cm.fp_start, cm.fp_frame, cm.fp_weight = self._fp
        self.n_fpairs = self._fp[0].shape[0] - 1
        cm.limits = self.model.limits
        cm.limit_tol = wp.float64(LIMIT_TOL)
        self._cm = cm
        self._scratch: tuple | None = None
        self._lists: tuple = ()  # the levels' work lists (two of (segment row, u0, u1))
        self._levels_count: wp.array | None = None  # per level its list's size
        #: kernel launches of the last check (memsets not counted)
        self.last_launches = 0
        self._cap = 0
        self._cap_eval = 0
        #: the output buffers per number of waypoints W (:meth:`_outputs`), the last used
        #: last: a planner checks its W-waypoint paths and its shortcuts (W = 2) in turn
        self._outs: OrderedDict[int, dict] = OrderedDict()
        self._mesh: Any = None  # the mesh certificate (mesh_check), made on first use

    # ------------------------------------------------------------------ data
    def _rows(self, n: int, m: int, dt: Any) -> wp.array:
        if self.device.is_cuda:
            return wp.empty((n, max(m, 1)), dtype=dt, device=self.device)
        row = wp.empty((1, max(m, 1)), dtype=dt, device=self.device)
        self._keep.append(row)
        return wp.array(ptr=row.ptr, shape=(n, max(m, 1)), strides=(0, row.strides[1]),
                        dtype=dt, device=self.device)

    def _scratch_for(self, n: int, n_eval: int) -> Any:
        """Scratch for ``n`` segments (their travel rows, real rows on every device) and
        ``n_eval`` evaluating threads (q, frames, xs; stride-0 rows on the CPU)."""
        if self._scratch is None or n > self._cap or n_eval > self._cap_eval:
            cap = max(n, int(self._cap * 1.5))
            cap_e = max(n_eval, int(self._cap_eval * 1.5))
            self._scratch = None  # the old rows freed before the new ones are made
            self._keep: list = []
            nd, nf, S = self.robot.n_dof, self.robot.n_frames, self.n_spheres
            k = self.k
            dev = self.device

            def full(m: int, dt: Any) -> wp.array:
                return wp.empty((cap, max(m, 1)), dtype=dt, device=dev)

            sc = k.CheckScratch()
            sc.dq = full(nd, wp.float64)
            sc.dth = full(nf, wp.float64)
            sc.travel = full(S, wp.float64)
            sc.fptravel = full(self.n_fpairs, wp.float64)
            sc.q = self._rows(cap_e, nd, wp.float64)
            sc.frames = self._rows(cap_e, nf, k.fk.mat44)
            sc.xs = self._rows(cap_e, S, k.fk.vec3)
            self._scratch, self._cap, self._cap_eval = sc, cap, cap_e
        return self._scratch

    def _points(self, K: int, W: int, M: int) -> Any:
        """The ``Points`` of the parallel rounds (K, W - 1, M); a dummy set when M = 0."""
        shape = (K, W - 1, M) if M > 0 else (1, 1, 1)
        pts = self.__dict__.get("_pts")
        if pts is None or pts.code.shape != shape:
            dev = self.device
            pts = self.k.Points()
            pts.code = wp.empty(shape, dtype=wp.int32, device=dev)
            pts.h = wp.empty(shape, dtype=wp.float64, device=dev)
            pts.a = wp.empty(shape, dtype=wp.int32, device=dev)
            pts.b = wp.empty(shape, dtype=wp.int32, device=dev)
            pts.d = wp.empty(shape, dtype=wp.float64, device=dev)
            self.__dict__["_pts"] = pts
        return pts

    def _outputs(self, K: int, W: int) -> dict:
        """The outputs for K paths of W waypoints: views of buffers kept for the largest
        K seen with this W (an RRT's varying edge batches reuse them; the buffers of the
        last :data:`_OUT_KEEP` W are kept, so alternating W allocates nothing)."""
        o = self._outs.get(W, {})
        if o.get("cap", 0) < K:
            dev = self.device
            cap = max(K, int(o.get("cap", 0) * 1.5))
            shape = (cap, W - 1)
            seg = self.k.Segments()
            seg.code = wp.empty(shape, dtype=wp.int32, device=dev)
            seg.u = wp.empty(shape, dtype=wp.float64, device=dev)
            seg.a = wp.empty(shape, dtype=wp.int32, device=dev)
            seg.b = wp.empty(shape, dtype=wp.int32, device=dev)
            seg.d = wp.empty(shape, dtype=wp.float64, device=dev)
            seg.n = wp.empty(shape, dtype=wp.int32, device=dev)
            seg.cov = wp.empty(shape, dtype=wp.float64, device=dev)
            seg.left = wp.empty(shape, dtype=wp.int32, device=dev)
            seg.claim = wp.empty(shape, dtype=wp.int32, device=dev)
            o = dict(
                W=W, cap=cap, seg=seg,
                bad=wp.zeros(cap, dtype=wp.int32, device=dev),
                ok_segments=wp.zeros(cap, dtype=wp.int32, device=dev),
                solved=wp.zeros(1, dtype=wp.int32, device=dev),
                ok=wp.empty(cap, dtype=wp.int32, device=dev),
                code=wp.empty(cap, dtype=wp.int32, device=dev),
                where=wp.empty(cap, dtype=wp.float64, device=dev),
                what=wp.empty((cap, 2), dtype=wp.int32, device=dev),
                dist=wp.empty(cap, dtype=wp.float64, device=dev))
        self._outs[W] = o
        self._outs.move_to_end(W)
        while len(self._outs) > _OUT_KEEP:
            self._outs.popitem(last=False)
        return o

    # ------------------------------------------------------------------ check
    def launch(self, paths: wp.array, idx: wp.array, K: int, *, margin: float = 0.0,
               endpoint_margin: float | None = None, group: int = 0,
               self_margin: float = 0.0, world_group: int = 0,
               points: tuple[int, int] | None = None) -> dict:
        """Check the paths ``idx[:K]`` of the device array ``paths`` (P, W, n_dof) (float32
        or float64) without host copies; returns the output arrays (``ok``, ``code``,
        ``where``, ``what``, ``dist`` of length >= K, and the per-segment ones).
        ``group`` > 0: path p belongs to problem ``p // group`` and a problem needs one
        feasible path: once one is proven, the others of its problem are skipped (code
        "skipped", not ok). ``self_margin`` [m]: the clearance required between the
        robot's own spheres (default 0). ``world_group`` > 0 with a batch of worlds
        (:meth:`jwarp.world.sdf.World.batch`): path p is in world ``p // world_group``.
        ``points`` (``"advance"`` only): (points, rounds) of this launch's parallel
        evaluations instead of the options' (e.g. (2, 1): a colliding path is found
        before the advancement proves its segments up to the collision)."""
        W = paths.shape[1]
        self.device_world.sync()  # moved / added objects
        self._cm.world = self.device_world.struct
        self._cm.bound_skip = int(self.device_world.bound_skip)
        out = self._outputs(K, W)
        o = self.options
        levels = o.resolved_method(self.device) == "levels"
        if points is not None and not levels:
            check_int(points[0], "points", 0)
            check_int(points[1], "rounds", 1)
            o = replace(o, points=int(points[0]), rounds=int(points[1]))
        M = 0 if levels else (o.points if o.points is not None
                              else (16 if self.device.is_cuda else 0))
        n_seg = K * (W - 1)
        lo = self._level_options(n_seg) if levels else o
        cap = self._work_lists(n_seg, lo) if levels else 0
        sc = self._scratch_for(n_seg, cap if levels else n_seg * max(M, 1))
        em = margin if endpoint_margin is None else endpoint_margin
        ps = paths.dtype  # the kernels that read the paths: one per path type
        seg = out["seg"]
        pts = self._points(K, W, M) if M > 0 else None  # the rounds' points only
        out["bad"].zero_()
        out["ok_segments"].zero_()
        n_groups = paths.shape[0] // group + 1 if group > 0 else 1
        if out["solved"].shape[0] < n_groups:
            out["solved"] = wp.zeros(n_groups, dtype=wp.int32, device=self.device)
        out["solved"].zero_()
        dev = self.device
        wp.launch(mk.prep(ps), dim=(K, W - 1), inputs=[self._cm, paths, idx, sc, out["bad"]],
                  outputs=[seg], device=dev)
        n_launch = 1
        use_points = int(M > 0)
        run_segments = True
        if levels:
            n_launch += self._launch_levels(paths, idx, K, W, cap, sc, out, margin, em,
                                            self_margin, group, world_group, lo)
            use_points = 2
            # the CPU reads how many segments the levels left (free there); a GPU launches
            # the advancement anyway (its threads return at once where none is left)
            left = self._levels_count
            run_segments = bool(o.fallback) and (dev.is_cuda or left is None
                                                 or int(left.numpy()[-1]) > 0)
        for rnd in range(o.rounds if M > 0 else 0):
            wp.launch(mk.points(ps), dim=(K, W - 1, M),
                      inputs=[self._cm, paths, idx, float(margin), float(em),
                              float(self_margin), int(world_group), seg, int(rnd > 0), sc],
                      outputs=[pts], device=dev)
            wp.launch(mk.cover(), dim=(K, W - 1), inputs=[pts, int(rnd > 0)],
                      outputs=[out["bad"], seg], device=dev)
            n_launch += 2
        if run_segments:
            wp.launch(mk.segment(ps), dim=(K, W - 1),
                      inputs=[self._cm, paths, idx, float(margin), float(em),
                              float(self_margin), float(o.min_step), int(o.max_evals),
                              float(o.probe_len), int(group), int(world_group), use_points,
                              sc, out["bad"], out["ok_segments"], out["solved"]],
                      outputs=[seg], device=dev)
            n_launch += 1
        wp.launch(mk.reduce(), dim=K, inputs=[seg],
                  outputs=[out["ok"], out["code"], out["where"], out["what"], out["dist"]],
                  device=dev)
        self.last_launches = n_launch + 1
        return out

    def _row_bytes(self) -> int:
        """Bytes of one evaluation row of the scratch on a GPU (configuration, frames,
        sphere centres)."""
        size = wp.types.type_size_in_bytes
        return (8 * self.robot.n_dof + self.robot.n_frames * size(self.k.fk.mat44)
                + self.n_spheres * size(self.k.fk.vec3))

    def _level_options(self, n_seg: int) -> MotionOptions:
        """The options of a levels launch of ``n_seg`` segments: :attr:`options`, without
        a set ``capacity`` with ``intervals`` halved (down to 1) until twice the level-0
        intervals fit :data:`LEVELS_SCRATCH_BYTES` of scratch rows (a GPU's memory; the
        CPU's rows take none, the same rule keeps the results alike)."""
        o = self.options
        if o.capacity is not None:
            return o
        rows = LEVELS_SCRATCH_BYTES // self._row_bytes()
        n0 = int(o.intervals)
        while n0 > 1 and 2 * n_seg * n0 > rows:
            n0 //= 2
        return o if n0 == o.intervals else replace(o, intervals=n0)

    def _work_lists(self, n_seg: int, lo: MotionOptions | None = None) -> int:
        """The levels' two work lists (segment row, interval) for ``n_seg`` segments:
        :attr:`MotionOptions.capacity` entries, or (None) at least twice the level-0
        intervals, kept and grown by half (varying batches reuse them); returns their
        length (the capacity of this launch)."""
        o = self.options if lo is None else lo
        if o.capacity is not None:
            cap = int(o.capacity)
            if not self._lists or self._lists[0].shape[0] != cap:
                self._lists = self._new_lists(cap)
            return cap
        need = max(2 * n_seg * int(o.intervals), 1024)
        have = self._lists[0].shape[0] if self._lists else 0
        if have < need:
            cap = max(need, int(have * 1.5))
            # grown by half only within the scratch budget
            cap = max(need, min(cap, LEVELS_SCRATCH_BYTES // self._row_bytes()))
            self._lists = ()  # free the old ones first
            self._lists = self._new_lists(cap)
        return self._lists[0].shape[0]

    def _new_lists(self, cap: int) -> tuple:
        """Two work lists of ``cap`` intervals: (segment row, u0, u1) each."""
        dev = self.device
        return tuple(wp.empty(cap, dtype=dt, device=dev)
                     for _ in range(2) for dt in (wp.int32, wp.float64, wp.float64))

    def _launch_levels(self, paths: wp.array, idx: wp.array, K: int, W: int,
                       cap: int, sc: Any, out: dict, margin: float, em: float,
                       self_margin: float, group: int, world_group: int,
                       lo: MotionOptions | None = None) -> int:
        """The interval refinement (:attr:`MotionOptions.method` "levels"): level 0, the
        levels, their end; returns the number of launches. A GPU launches every level at
        the list's capacity (sizes stay on the device: no host read); the CPU reads each
        level's size (no copy there) and stops at an empty level. ``lo``: the launch's
        options (:meth:`_level_options`; None: :attr:`options`)."""
        o = self.options if lo is None else lo
        dev = self.device
        n0 = int(o.intervals)
        L = o.n_levels()
        lists = self._lists  # (_work_lists: cap entries each)
        count = self._levels_count
        if count is None or count.shape[0] != L + 2:
            count = self._levels_count = wp.zeros(L + 2, dtype=wp.int32, device=dev)
        count.zero_()
        seg = out["seg"]
        wp.launch(mk.level_init(), dim=(K, W - 1), inputs=[n0, out["bad"]],
                  outputs=[count, seg, *lists[:3]], device=dev)
        n = 1
        host = None if dev.is_cuda else count.numpy()  # the CPU: a view, no copy
        for lv in range(L):
            src, dst = (lists[:3], lists[3:]) if lv % 2 == 0 else (lists[3:], lists[:3])
            dim = cap
            if host is not None:
                dim = min(int(host[lv]), cap)
                if dim == 0:
                    break
            wp.launch(mk.level(paths.dtype), dim=dim,
                      inputs=[self._cm, paths, idx, float(margin), float(em),
                              float(self_margin), float(o.min_step), int(group),
                              int(world_group), lv, int(lv == L - 1), *src, sc],
                      outputs=[count, out["bad"], out["ok_segments"], out["solved"], seg,
                               *dst], device=dev)
            n += 1
        wp.launch(mk.level_end(), dim=(K, W - 1),
                  inputs=[int(group), int(o.fallback), idx, out["solved"]],
                  outputs=[out["bad"], count, seg], device=dev)
        return n + 1

    def check(self, paths: Any, *, margin: float = 0.0,
              endpoint_margin: float | None = None, self_margin: float = 0.0,
              world_group: int = 0, group: int = 0,
              meshes: bool | np.ndarray | None = None,
              rows: np.ndarray | None = None,
              points: tuple[int, int] | None = None) -> PathCheck:
        """Check ``paths`` (W, n_dof) or (P, W, n_dof) (numpy or Warp; rad or m) with
        ``margin`` [m] (>= 0) from the world, ``self_margin`` [m] between the robot's own
        spheres and ``endpoint_margin`` (None: = margin) on the first and last segment.
        ``group`` > 0: paths ``p`` of one group ``p // group`` need one proven path: once
        one is, the group's others not yet checked are skipped (not ok; on the CPU the
        paths are checked in order, so the first feasible path of each group is the one
        proven; on a GPU a later one may be). ``world_group``: as :meth:`launch`.
        ``meshes``: what the spheres leave unproven goes to :meth:`mesh_recheck` (None:
        ``options.meshes``; a (P,) bool array: of those paths only). ``rows`` (K,) ints:
        check only the paths ``paths[rows]`` (the others are not read: a batch of worlds'
        blocks of ``world_group`` paths need not be full), their results in that order.
        ``points``: as :meth:`launch` (``"advance"`` only: its points per segment and
        rounds, evaluated first). Returns a :class:`PathCheck` (P results, or K with ``rows``; one for a single
        path)."""
        margin = _check_margin(margin, "margin")
        self_margin = _check_margin(self_margin, "self_margin")
        if endpoint_margin is not None:
            endpoint_margin = _check_margin(endpoint_margin, "endpoint_margin")
        n = self.robot.n_dof
        if isinstance(paths, wp.array):
            if paths.ndim != 3 or paths.shape[2] != n or paths.shape[1] < 2:
                raise ValueError(f"paths: expected shape (P, W >= 2, {n}), got {paths.shape}")
            p = paths
        else:
            a = real_array(paths, "paths")
            if a.ndim == 2:
                a = a[None]
            if a.ndim != 3 or a.shape[2] != n or a.shape[1] < 2:
                raise ValueError(f"paths: expected shape (W >= 2, {n}) or (P, W, {n}) for "
                                 f"robot '{self.robot.name}', got {np.shape(paths)}")
            if not np.all(np.isfinite(a)):
                raise ValueError("paths: contains NaN or inf")
            p = wp.array(np.ascontiguousarray(a, np.float64), dtype=wp.float64,
                         device=self.device)
        if rows is None:
            sel = np.arange(p.shape[0])
        else:
            sel = np.asarray(rows)
            if sel.ndim != 1 or not np.issubdtype(sel.dtype, np.integer) or (
                    len(sel) and (sel.min() < 0 or sel.max() >= p.shape[0])):
                raise ValueError(f"rows: expected (K,) integers in [0, {p.shape[0]}), got "
                                 f"{np.shape(rows)} {sel.dtype}")
        K = len(sel)
        idx: wp.array = wp.array(sel.astype(np.int32), dtype=wp.int32, device=self.device)
        check_int(group, "group", 0)
        out = self.launch(p, idx, K, margin=margin, endpoint_margin=endpoint_margin,
                          self_margin=self_margin, world_group=world_group, group=int(group),
                          points=points)
        ok = out["ok"].numpy()[:K].astype(bool)
        code = out["code"].numpy()[:K]
        dist = out["dist"].numpy()[:K]
        rows = sel
        if meshes is not None and np.ndim(meshes) == 1:
            allow = np.asarray(meshes, bool)
            if allow.shape != (K,):
                raise ValueError(f"meshes: expected a bool or ({K},) bools, one per path, got "
                                 f"shape {allow.shape}")
        else:
            allow = np.full(K, bool(self.options.meshes if meshes is None else meshes))
        if not ok.all() and (allow & ~ok).any():
            ok2 = ok.copy()
            ok2[allow] = self.mesh_recheck(p, rows[allow], ok[allow], code[allow], dist[allow],
                                           margin=margin, endpoint_margin=endpoint_margin,
                                           self_margin=self_margin, world_group=world_group)
            if (ok2 != ok).any():
                code = np.where(ok2, 0, code)
                ok = ok2
        return PathCheck(ok=ok, code=code,
                         where=out["where"].numpy()[:K], what=out["what"].numpy()[:K],
                         clearance=dist, robot=self.robot, world=self.world,
                         margin=margin, endpoint_margin=endpoint_margin,
                         self_margin=self_margin,
                         evaluations=int(out["seg"].n.numpy()[:K].sum()))

    def mesh_check(self) -> Any:
        """The :class:`jwarp.world.mesh_check.MeshCheck` of this robot and world (None
        where there is none, or with ``options.meshes`` False)."""
        return self._mesh_check_any() if self.options.meshes else None

    def _mesh_check_any(self) -> Any:
        """:meth:`mesh_check` whatever ``options.meshes`` says (a caller's ``meshes=True``)."""
        if getattr(self.robot, "collision_pieces", None) is None:
            return None
        if self._mesh is None:
            from jwarp.world.mesh_check import mesh_check

            self._mesh = mesh_check(self.robot, self.world, self.device) or False
        return self._mesh or None

    def mesh_recheck(self, paths: Any, rows: np.ndarray, ok: np.ndarray, code: np.ndarray,
                     dist: np.ndarray, *, margin: float = 0.0,
                     endpoint_margin: float | None = None, self_margin: float = 0.0,
                     world_group: int = 0) -> np.ndarray:
        """``ok`` (K,) with the paths the spheres did not prove but the mesh certificate
        does (:mod:`jwarp.world.mesh_check`): ``paths`` (P, W, n_dof) (numpy or Warp),
        ``rows`` (K,) the checked paths' rows, ``code``/``dist`` (K,) the sphere check's
        results. Tried for world/self collisions whose clearance is above minus the
        spheres' largest protrusion past the meshes (a deeper sphere collision is a mesh
        collision), and for uncertified segments; a proven path must also keep its
        waypoints within the joint limits. Unchanged without a mesh certificate."""
        mc = self._mesh_check_any()
        if mc is None:
            return ok
        from jwarp.world.mesh_check import sphere_reach_past

        depth = sphere_reach_past(self.robot)
        try_ = (~ok & np.isin(code, (1, 2, 3, 6)) & (np.asarray(dist) > -depth))
        if not try_.any():
            return ok
        rows = np.asarray(rows)
        sel = rows[try_]
        if isinstance(paths, wp.array):
            host = paths.numpy() if len(sel) * 4 > paths.shape[0] else None
            if host is None:
                host = np.stack([paths[int(i)].numpy() for i in sel])
            else:
                host = host[sel]
        else:
            host = np.asarray(paths)[sel]
        host = np.asarray(host, np.float64)
        from jwarp.core.limits import within_limits

        lim = within_limits(self.robot, host.reshape(-1, host.shape[-1])).reshape(
            host.shape[:2]).all(axis=1)
        groups = sel // int(world_group) if world_group else None
        good = np.zeros(len(sel), bool)
        if lim.any() and (groups is not None or host.shape[1] == 2):
            # a batch of worlds, or single segments: the certificate on the whole paths
            good[lim] = mc.paths_free(host[lim], margin, self_margin,
                                      endpoint_margin=endpoint_margin,
                                      groups=None if groups is None else groups[lim])
        elif lim.any():
            good[lim] = self._segments_recheck(mc, host[lim], margin, endpoint_margin,
                                               self_margin)
        out = ok.copy()
        out[np.nonzero(try_)[0]] = good
        return out

    def _segments_recheck(self, mc: Any, paths: np.ndarray, margin: float,
                          endpoint_margin: float | None, self_margin: float) -> np.ndarray:
        """(K,) bool: every segment of ``paths`` (K, W > 2, n_dof) proven by the spheres
        (each segment checked alone) or, where they cannot, by the mesh certificate: the
        certificate's work is only the segments the spheres leave (a grasp pose's
        approach), not the whole path. First and last segments at ``endpoint_margin``."""
        K, W, n = paths.shape
        segs = np.stack([paths[:, :-1], paths[:, 1:]], axis=2).reshape(-1, 2, n)
        end = np.zeros((K, W - 1), bool)
        end[:, 0] = end[:, -1] = True
        end = end.reshape(-1)
        seg_ok = np.zeros(len(segs), bool)
        for mask, em in ((end, endpoint_margin), (~end, None)):
            if not mask.any():
                continue
            idx = np.nonzero(mask)[0]
            seg_ok[idx] = self.check(segs[idx], margin=margin, endpoint_margin=em,
                                     self_margin=self_margin, meshes=False).ok
            bad = idx[~seg_ok[idx]]
            # a path with a segment the certificate cannot prove fails: one per path is
            # enough to know, but the segments of a path are few; check them all at once
            if len(bad):
                seg_ok[bad] = mc.paths_free(segs[bad], margin, self_margin,
                                            endpoint_margin=em)
        return np.asarray(seg_ok.reshape(K, W - 1).all(axis=1), bool)


#: numbers of waypoints whose output buffers a MotionCheck keeps (:meth:`MotionCheck._outputs`)
_OUT_KEEP = 4

#: bytes of evaluation scratch (per row a configuration, its frames and its sphere
#: centres) that the levels' work lists of one launch hold (on a GPU) when
#: :attr:`MotionOptions.capacity` is None: a launch of more segments than fit at
#: ``intervals`` per segment starts with fewer level-0 intervals (halved, down to 1; the
#: levels refine them as before, the same proofs). A batch of 700 problems x 32 starts x
#: 19 segments at 16 intervals asked for 30 GB of one array on an H200.
LEVELS_SCRATCH_BYTES = 8 << 30

#: MotionChecks by (robot content key, device, options) and the world (by identity, held
#: weakly), the 8 used last
_CHECKS: IdentityCache[MotionCheck] = IdentityCache(8, owner=0)


def motion_check(robot: RobotModel, world: World | None, *, device: DeviceLike = None,
                 options: MotionOptions | None = None) -> MotionCheck:
    """A cached :class:`MotionCheck` for (robot content, world identity, device, options):
    repeated checks (an RRT's edges, the planners of one world) pay its set-up once.
    Worlds are held weakly. ``options``: :class:`MotionOptions` (None: the defaults); the
    cached check keeps its own copy."""
    from dataclasses import astuple, replace

    from jwarp.core.device import content_key

    model = robot
    dev = resolve_device(device)
    opts = MotionOptions() if options is None else replace(options)
    key = (content_key(model), str(dev), astuple(opts))
    hit = _CHECKS.get(key, (world,))
    if hit is not None:
        return hit
    return _CHECKS.put(key, (world,), MotionCheck(model, world, device=dev, options=opts))


def _check_margin(v: Any, name: str) -> float:
    m = real_number(v, name)
    if not (np.isfinite(m) and m >= 0):
        raise ValueError(f"{name}: expected a finite clearance >= 0 [m], got {v!r}")
    if m > 1e3:
        raise ValueError(f"{name}: {m:g} m is not a clearance a robot can keep")
    return m


def check_paths(robot: RobotModel, world: World | None, paths: Any, *, margin: float = 0.0,
                endpoint_margin: float | None = None, self_margin: float = 0.0,
                device: DeviceLike = None, options: MotionOptions | None = None) -> PathCheck:
    """Continuous feasibility of ``paths`` (W, n_dof) or (P, W, n_dof): a
    :class:`MotionCheck` made for this call (keep one for repeated checks)."""
    return MotionCheck(robot, world, device=device, options=options).check(
        paths, margin=margin, endpoint_margin=endpoint_margin, self_margin=self_margin)
