"""The inverse-kinematics solver: a persistent :class:`IKSolver` holding its device buffers,
the one-call :func:`ik`, seeds and learned warm starts."""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np
import warp as wp

from jwarp.core.arrays import finite_as, init_warp, real_array, resolve_device
from jwarp.core.device import numpy_dtype, put_model, scalar_type
from jwarp.core.limits import LIMIT_TOL, sample_within_limits, within_limits
from jwarp.core.types import ArrayLike, DeviceLike, DTypeLike, RobotLike
from jwarp.kernels import fk as fk_kernels
from jwarp.kernels import ik_step as step_kernels
from jwarp.kinematics.transmission import transmitted, untransmitted
from jwarp.model import RobotModel
from jwarp.model.valid_range import check_valid_range
from jwarp.plugins.registry import robot as get_robot
from jwarp.solvers.ik.objective import (
    IKObjective,
    batch_array,
    check_single_world,
    target_poses,
)
from jwarp.solvers.ik.options import IKOptions, IKWeights
from jwarp.solvers.ik.result import IKResult
from jwarp.solvers.overrides import renamed_argument, with_overrides
from jwarp.utils.checks import check_int
from jwarp.world import collision
from jwarp.world.model_check import check_collision_model, mesh_margin_model

if TYPE_CHECKING:
    from jwarp.world.sdf import World


class IKSolver:
    """Batched collision-free IK of one frame, resident on one device.

    Holds ``n_problems`` targets x ``n_seeds`` seeds (``options.n_starts`` unless the seeds
    given to :meth:`solve` say otherwise): the cost buffers (:class:`IKObjective`), the
    per-seed state and result rows, and the recorded kernel launches. :meth:`solve` reuses
    all of them while the number of seeds stays the same (a different count reallocates).
    Options are read once, at construction.

    Per iteration (:mod:`jwarp.kernels.ik_step`): the pose error and Jacobian (rigid robot:
    one kernel walking the frame's chain; elastic: FK at the compensation rows), the list
    of active seeds whose pose is on target, U_A of those only (their collision costs in a
    gathered batch), the exact check of the candidates, and the projected DLS step of the
    active seeds. The host reads three counters (done seeds, solved problems, seeds on
    target) every iteration on the CPU (a view, free) and every ``check_every`` iterations
    on CUDA (a small copy and a sync): between two reads the rigid robot's gathered U_A
    launch keeps the size of the last read count with headroom (seeds beyond it wait an
    iteration), the elastic model evaluates U_A of every seed. The result rows are copied
    once at the end.

    Args:
        robot: robot name or RobotModel.
        frame: end-effector frame (name, end-effector alias or index).
        n_problems: targets per :meth:`solve` (>= 1).
        options: :class:`IKOptions` (None: the defaults).
        world: optional :class:`jwarp.world.World` (None: self-collision only).
        device: Warp device (None: Warp's default device, docs/api.md "Devices"); every
            kernel and check of the solve runs there.
        dtype: float type of the iteration (None: float64); the step's linear algebra and
            the feasibility check are float64 either way.
        warm_start: optional learned warm start (thesis 3.4): any object with a callable
            ``seeds(targets (P, 4, 4) numpy, world) -> (P, H, n_dof)`` (e.g. a loaded
            ``jwarp.learn`` IK network: H = 2 for twin heads). :meth:`solve` without
            ``seeds`` then starts from its H seeds per target followed by
            ``options.n_random_with_warm_start`` random ones (from :attr:`rng`); seeds given
            to :meth:`solve` win. A TypeError (no callable ``seeds``) or ValueError (its
            output is not (P, H, n_dof) finite values) names ``warm_start``.
    """

    def __init__(self, robot: RobotLike, frame: int | str, n_problems: int,
                 options: IKOptions | None = None, world: World | None = None, device: DeviceLike = None,
                 dtype: DTypeLike = None, warm_start: Any = None):
        init_warp()
        #: the warm start (None: random seeds); see the class docstring
        self.warm_start = check_warm_start(warm_start)
        self.robot = get_robot(robot)
        self.frame = self.robot.frame_index(frame)
        collision.check_world(self.robot, world)
        check_single_world(world)
        self.world = world
        self.n_problems = check_int(n_problems, "n_problems", 1)
        if options is None:
            options = IKOptions()
        elif not isinstance(options, IKOptions):
            raise TypeError(f"options: expected IKOptions, got {type(options).__name__}")
        options = dataclasses.replace(options)  # a copy (validated): later edits do not leak
        self.device = resolve_device(device)
        # approximate spheres: the meshes' poke-out as extra margin per link (or a warning)
        self.robot = mesh_margin_model(self.robot, options.mesh_margin, what="IK")
        if not options.allow_no_collision:
            check_collision_model(self.robot, need_spheres=world is not None,
                                  what="IK in a world", device=self.device)
        self.options = options
        self.scalar = scalar_type(np.float64 if dtype is None else dtype)
        self.npdt = numpy_dtype(self.scalar)
        self.eps = options.eps_for(world)
        #: random generator of the seeds (from ``options.seed``); :meth:`reseed` resets it
        self.rng = np.random.default_rng(options.seed)
        self.planar = self.robot.workspace_dim == 2
        self.dk = step_kernels.dls_kernels(self.scalar, self.planar, self.robot.n_dof)
        self.ck = step_kernels.check_kernels(self.scalar, self.planar)
        self.limits = put_model(self.robot, self.device, self.scalar).limits
        self.limits64 = put_model(self.robot, self.device, np.float64).limits
        self.cm64 = collision.collision_model(self.robot, world, device=self.device,
                                              dtype=np.float64)
        w = options.weights or IKWeights()
        self.weights = w
        w_min = min([v for v in (w.world, w.self) if v > 0] or [0.0])
        # screen: a collision cost below w_min c(margin) means no sphere is within margin
        # (every term is >= 0); those get the exact check at once, the others every
        # check_every iterations
        self.screen = w_min * (self.eps - options.margin) ** 2 / (2.0 * self.eps)
        dev = self.device
        mat44 = fk_kernels.kernels(self.scalar).mat44
        self.targets = wp.zeros(self.n_problems, dtype=mat44, device=dev)
        self.best = wp.zeros((self.n_problems, 2), dtype=wp.int32, device=dev)
        self.solved = wp.zeros(self.n_problems, dtype=wp.int32, device=dev)
        #: [done, frozen or given-up seeds, solved problems, seeds on target this
        #: iteration, problems whose seeds all gave up]
        self.counts = wp.zeros(4, dtype=wp.int32, device=dev)
        self._counts_host = (self.counts if dev.is_cpu else
                             wp.zeros(4, dtype=wp.int32, device="cpu", pinned=True))
        self.halt = wp.zeros(1, dtype=wp.int32, device=dev)
        self.n_seeds = 0
        self._allocate(options.n_starts)

    # ------------------------------------------------------------------ buffers
    def _allocate(self, n_seeds: int) -> None:
        """Buffers and recorded launches for ``n_seeds`` seeds per problem."""
        o, dev = self.options, self.device
        P, S, n = self.n_problems, int(n_seeds), self.robot.n_dof
        B = P * S
        self.n_seeds, self.B = S, B
        fast = dev.is_cuda  # configuration index fastest in memory (coalesced)
        obj = IKObjective(self.robot, self.frame, B, world=self.world, weights=o.weights,
                          eps=self.eps, q_default=o.q_default, kappa=o.kappa, lam=o.lam,
                          device=dev, dtype=self.scalar, batch_fastest=fast,
                          orientation=o.orientation, free_axis=o.free_axis)
        #: the batch's objective (allocated with the buffers)
        self.objective: IKObjective = obj
        i32 = wp.int32
        self.on = wp.zeros(B, dtype=i32, device=dev)
        #: per seed: 0 active, 1 done (feasible), 2 frozen (``freeze_solved``)
        self.done = wp.zeros(B, dtype=i32, device=dev)
        self.iterations = wp.zeros(B, dtype=i32, device=dev)
        rs = step_kernels.RestartArgs()
        rs.after = int(o.restart_after or 0)
        rs.max_restarts = int(o.max_restarts)
        rs.progress = wp.float64(RESTART_PROGRESS)
        rs.on_cost = wp.float64(o.tol_pos ** 2 + step_kernels.W_ROT * o.tol_rot ** 2)
        rs.seed = wp.zeros(1, dtype=i32, device=dev)
        # the solve's seed is staged here (CUDA: pinned, copied without a sync)
        self._seed_host = (rs.seed if dev.is_cpu else
                           wp.zeros(1, dtype=i32, device="cpu", pinned=True))
        rs.best = wp.zeros(B, dtype=wp.float64, device=dev)
        rs.stall = wp.zeros(B, dtype=i32, device=dev)
        rs.count = wp.zeros(B, dtype=i32, device=dev)
        rs.gave = wp.zeros(P, dtype=i32, device=dev)
        #: the re-seeding state (:class:`jwarp.kernels.ik_step.RestartArgs`)
        self.restart = rs
        self.out = batch_array(B, (n + step_kernels.N_EXTRA,), wp.float64, dev, fast)
        # the seeds whose pose is on target, gathered for their collision costs
        self.idx = wp.zeros(B, dtype=i32, device=dev)
        self.q_near = batch_array(B, (n,), self.scalar, dev, fast)
        self.near_cost = wp.zeros(B, dtype=self.scalar, device=dev)
        self.near_grad = batch_array(B, (n,), self.scalar, dev, fast)
        self._near_views: dict = {}
        comp = obj.compensation
        nf = self.robot.n_frames
        self._rows = comp.rows if comp is not None else wp.zeros((1, nf, 9), dtype=self.scalar,
                                                                  device=dev)
        self._delta = obj.delta if comp is not None else wp.zeros(1, dtype=self.scalar,
                                                                  device=dev)
        ck, cm = self.ck, self.cm64
        tab = ck.CheckTables()
        tab.model, tab.spheres = cm.model_args
        tab.world = cm.world_struct
        tab.use_world = int(self.world is not None and cm.n_spheres > 0)
        tab.use_self = int(cm.n_pairs > 0)
        tab.limits = self.limits64
        tab.limit_tol = wp.float64(LIMIT_TOL)
        self._check_tables = tab
        sc = ck.CheckScratch()
        k64 = fk_kernels.kernels(wp.float64)
        sc.q64 = batch_array(B, (n,), wp.float64, dev, fast)
        sc.rho64 = (batch_array(B, (nf, 5), wp.float64, dev, fast) if comp is not None else
                    wp.zeros((1, nf, 5), dtype=wp.float64, device=dev))
        self._scratch_owner: list = []
        sc.frames = self._scratch(B, nf, k64.mat44)
        sc.xs = self._scratch(B, max(cm.n_spheres, 1), k64.vec3)
        self._check_scratch = sc
        self._launches: dict = {}
        self._cost_data: dict = {}  # CollisionData per gathered U_A batch size

    def _scratch(self, B: int, m: int, dtype: type) -> wp.array:
        """(B, m) scratch of the check: on CUDA frame-major (coalesced); on the CPU, whose
        threads run one after another, one row seen by every configuration (stride 0)."""
        if self.device.is_cuda:
            return wp.zeros((m, B), dtype=dtype, device=self.device).transpose()
        row = wp.zeros((1, m), dtype=dtype, device=self.device)
        self._scratch_owner.append(row)  # owns the memory of the view
        return wp.array(ptr=row.ptr, shape=(B, m), strides=(0, row.strides[1]), dtype=dtype,
                        device=self.device)

    def _sync_world(self) -> None:
        """Objects added to or removed from the world since the last solve: the new world
        struct in the check tables and the cost (recorded launches re-recorded); moved
        objects need nothing (updated in place)."""
        ws = self.cm64.world_struct
        if self._check_tables.world is not ws:
            self._check_tables.world = ws
            self._launches.clear()

    def _launch(self, key: Any, kernel: Any, dim: int, inputs: list) -> None:
        launch = self._launches.get(key)
        if launch is None:
            launch = wp.launch(kernel, dim=dim, inputs=inputs, device=self.device,
                               record_cmd=True)
            self._launches[key] = launch
        launch.launch()

    def _read_counts(self) -> np.ndarray:
        """The counters on the host (CPU: a view; CUDA: a copy, which waits for the
        device)."""
        if self.device.is_cpu:
            return self._counts_host.numpy()
        wp.copy(self._counts_host, self.counts)
        wp.synchronize_device(self.device)
        return self._counts_host.numpy()

    def _pose(self) -> None:
        """Rigid robot: error and Jacobian of every active seed (one kernel)."""
        obj = self.objective
        t = obj.t
        self._launch("pose", self.ck.pose, self.B, [
            t.frame_struct, t.chain(self.frame), t.dh0_3d, obj.orient, obj.axis,
            obj.q, obj.target, self.halt, self.done, obj.jac, obj.err])

    def _near(self, cap: int) -> None:
        """List the on-target seeds, at most ``cap`` of them (the others wait)."""
        o, obj = self.options, self.objective
        self._launch(("near", cap), self.ck.near, self.B, [
            obj.err, o.tol_pos, o.tol_rot, cap, self.halt, self.done, self.on, self.counts,
            self.idx, obj.coll_cost, obj.cost_a, obj.grad_a])

    def _gather_size(self, n_near: int) -> int:
        """Size of the gathered U_A launch for ``n_near`` seeds: a power of two above 32
        seeds (so a few recorded launches serve every count), at most B."""
        n_near = max(int(n_near), 1)
        return min(self.B, n_near if self.B <= 32 else 1 << (n_near - 1).bit_length())

    def _near_aux(self, n_near: int) -> None:
        """U_A and its gradient of the ``n_near`` listed seeds (at most :meth:`_gather_size`
        of them): their collision costs in a gathered batch."""
        obj, w = self.objective, self.weights
        K = self._gather_size(n_near)
        views = self._near_views.get(K)
        if views is None:
            views = self._near_views[K] = (self.q_near[:K], self.near_cost[:K],
                                           self.near_grad[:K])
        qk, ck, gk = views
        use = int(obj.collides)
        if use:
            self._launch(("gather", K), self.ck.gather, K, [obj.q, self.idx, self.counts, qk])
            data = self._cost_data.get(K)  # the solver's own scratch (graphs hold it)
            if data is None:
                data = self._cost_data[K] = obj.cm.make_data(K)
            obj.cm.cost(qk, w_world=w.world, w_self=w.self, eps=obj.eps, grad=True,
                        out_cost=ck, out_grad=gk, data=data)
        self._launch(("scatter", K), self.ck.scatter_aux, K, [
            obj.q, obj.q_default, obj.default_stride, self.idx, self.counts, ck, gk, use,
            self.scalar(w.default), obj.coll_cost, obj.cost_a, obj.grad_a])

    def _check(self, full: bool) -> None:
        o, obj = self.options, self.objective
        self._launch(("check", bool(full)), self.ck.check, self.B, [
            self._check_tables,
            obj.q, obj.err, obj.cost_a, obj.coll_cost, self._delta, self._rows,
            int(obj.compensation is not None), o.tol_pos, o.tol_rot, o.tol_rho, self.screen,
            int(full), o.margin, self.n_seeds, self.halt, self.iterations,
            self._check_scratch,
            self.on, self.done, self.solved, self.counts, self.out])

    def _iteration_graph(self, cap: int, full: bool) -> None:
        """One rigid iteration between two host reads (error and Jacobian, the on-target
        list of at most ``cap`` seeds, their U_A, the check, the step) as a CUDA graph,
        captured on first use for (``cap``, ``full``) and replayed after (the recorded
        launches hold fixed buffers; a world that gains or loses objects drops the
        graphs with the launches)."""
        key = ("graph", cap, bool(full))
        graph = self._launches.get(key)
        if graph is None:
            # what the capture may not do itself: load the kernels' modules, size the
            # cost's scratch (only these modules load, not every one Warp knows)
            obj = self.objective
            K = self._gather_size(cap)
            kernels = [self.ck.pose, self.ck.near, self.ck.gather, self.ck.scatter_aux,
                       self.ck.check, self.dk.step]
            if obj.collides:
                kernels += obj.cm.cost_kernels(K)
                if K not in self._cost_data:
                    self._cost_data[K] = obj.cm.make_data(K)
            wp.force_load(device=self.device, modules=list({k.module: None for k in kernels}))
            with wp.ScopedCapture(device=self.device, force_module_load=False) as capture:
                self._pose()
                self._near(cap)
                self._near_aux(cap)
                self._check(full)
                self._step()
            graph = self._launches[key] = capture.graph
        wp.capture_launch(graph)

    def _step(self) -> None:
        o, obj = self.options, self.objective
        self._launch("step", self.dk.step, self.B, [
            self.limits, obj.jac, obj.err, obj.grad_a, self.on, self.solved, self.n_seeds,
            int(o.freeze_solved), int(o.stop_when_solved), self.n_problems, o.damping ** 2,
            o.step, o.max_step, obj.q, self.done, self.counts,
            self.iterations, self.halt, self.restart])

    # ------------------------------------------------------------------ solve
    def _mesh_rescue(self, out: np.ndarray, best: np.ndarray, P: int, S: int) -> None:
        """The problems without a feasible seed: seeds on target whose spheres touch but
        whose URDF geometry the mesh certificate proves free (``margin`` from the world and
        between the pieces; :mod:`jwarp.world.mesh_check`) become feasible, and the choice
        (``best`` (P, 2)) is made again; ``out`` (P S, n_dof + 5) updated in place. A grasp
        pose whose fingers clear the object by millimetres is then a solution, as it is a
        start or goal for the planner."""
        _rescue_rows(self, out, best, P, S)

    def reseed(self, seed: int | None) -> None:
        """Restart the random seeds' generator from ``seed`` (an integer >= 0 or None)."""
        check_int(seed, "seed", 0, none=True)
        self.rng = np.random.default_rng(seed)

    def solve(self, targets: ArrayLike, seeds: Any = None, *,
              callback: Callable[[int, np.ndarray], None] | None = None) -> IKResult:
        """Solve the ``n_problems`` targets.

        Args:
            targets: poses (n_problems, 4, 4) in the base frame [m], or one pose (4, 4)
                for every problem, or a tuple ``(positions (n_problems, 3), quaternions
                (n_problems, 4))`` with quaternions ``(x, y, z, w)`` (ROS/scipy order,
                normalised); planar robots use x, y and the rotation about z.
            seeds: initial configurations (n_problems, n_seeds, n_dof) or the same for every
                problem (n_seeds, n_dof) or (n_dof,); None: with a ``warm_start``, its H
                seeds per problem and ``options.n_random_with_warm_start`` random ones
                (numpy, from :attr:`rng`); without, ``options.n_starts`` random seeds per
                problem, drawn on the device (uniform in the box, redrawn for the linear
                limits; Warp's random stream, seeded from :attr:`rng`). Every seed is
                projected onto the joint limits first.
            callback: ``callback(iteration, q (B, n_dof))`` after every evaluation (reads q
                back every iteration).

        Returns:
            :class:`IKResult` with the leading dims of ``targets`` (a (4, 4) target with
            ``n_problems == 1``: no leading dim).
        """
        t0 = time.perf_counter()
        self._sync_world()
        T, lead = target_poses(targets)
        P, model = self.n_problems, self.robot
        if len(T) != P:
            if len(T) != 1:
                raise ValueError(f"target: expected {P} poses (the solver's n_problems) or "
                                 f"one, got {len(T)}")
            T = np.broadcast_to(T, (P, 4, 4))
            lead = (P,)
        T = finite_as(T, self.npdt, "target")  # finite in the solver's dtype
        q0 = None
        S = self.options.n_starts
        if seeds is not None:
            q0 = finite_as(_seeds(model, seeds, P, "seeds"), self.npdt, "seeds")
            S = q0.shape[1]
        elif self.warm_start is not None:
            q0 = finite_as(warm_start_seeds(model, self.warm_start, T, self.world,
                                            self.options.n_random_with_warm_start, self.rng),
                           self.npdt, "warm_start")
            S = q0.shape[1]
        if q0 is not None and model.has_harmonic:  # the kernels work in the links' joint space
            q0 = transmitted(model, q0)
        if self.n_seeds != S:
            self._allocate(S)
        obj, dev, B = self.objective, self.device, self.B
        if q0 is None:  # random seeds, drawn on the device
            obj.reset_rows()
            wp.launch(self.dk.sample, dim=B, inputs=[self.limits,
                                                     int(self.rng.integers(1 << 31))],
                      outputs=[obj.q], device=dev)
        else:
            obj.set_q(q0.reshape(B, -1))
        obj.project_limits()
        if dev.is_cpu:
            self.targets.numpy()[...] = T  # CPU arrays share memory with numpy
        else:
            wp.copy(self.targets, wp.array(T, dtype=self.targets.dtype, device=dev))
        self._launch("repeat", self.ck.repeat_targets, B, [self.targets, S, obj.target])
        self._seed_host.numpy()[0] = int(self.rng.integers(1 << 31))  # this solve's re-seeds
        if not dev.is_cpu:
            wp.copy(self.restart.seed, self._seed_host)
        self._launch("reset", self.ck.reset, B, [P, self.done, self.on, self.iterations,
                                                self.solved, self.counts, self.halt,
                                                self.restart])
        o = self.options
        rigid = obj.compensation is None
        # the counters are read every iteration on the CPU (a view: free) and on CUDA every
        # check_every iterations (a copy that waits for the device). Between two reads the
        # rigid robot gathers the on-target seeds into a launch sized from the last read
        # count with headroom (seeds beyond it wait an iteration); the elastic robot
        # evaluates U_A of every seed
        k_read = o.read_every or (1 if dev.is_cpu else o.check_every)
        every = k_read == 1 or (rigid and callback is not None)
        cap = self.B if every else self._gather_size(2 * 32)

        def over(c: np.ndarray) -> bool:
            return bool(c[0] >= B or (o.stop_when_solved and c[1] + c[3] >= P))

        graphs = o.cuda_graphs and rigid and not every and callback is None and dev.is_cuda
        for it in range(o.iterations + 1):
            last = it == o.iterations
            read = every or it % k_read == 0
            if graphs and not read and not last:
                # an iteration between two reads: its launches depend on nothing the host
                # learns in between, so they replay as one CUDA graph
                self._iteration_graph(cap, it % o.check_every == 0)
                continue
            if rigid:
                self._pose()
            else:
                obj.evaluate_pose()
            near = True
            if last:  # U_A of every seed: the result rows of the unsolved ones carry it
                obj.evaluate_aux()
            elif rigid:
                self._near(self.B if read else cap)
                if read:
                    c = self._read_counts()
                    if not every and over(c):  # solved at the last check (device halted)
                        break
                    near = c[2] > 0
                    if near:
                        self._near_aux(int(c[2]))
                    cap = self._gather_size(2 * max(int(c[2]), 32))
                else:
                    self._near_aux(cap)
            elif every:
                self._near(self.B)
                c = self._read_counts()
                near = c[2] > 0
                if near:
                    obj.evaluate_aux()
                else:
                    obj.update_rows()
            else:
                obj.evaluate_aux()
            if callback is not None:
                callback(it, obj.q.numpy().astype(np.float64))
            if near:
                self._check(it % o.check_every == 0 or last)
            if last:
                break
            if (every or callback is not None or (not rigid and read)) \
                    and over(self._read_counts()):
                break
            self._step()
        self._launch("finalize", self.ck.finalize, B, [obj.q, obj.err, obj.cost_a, self.done,
                                                       self.iterations, o.iterations,
                                                       self.out])
        self._launch("select", self.ck.select, P, [self.out, S, model.n_dof, self.best])
        out = self.out.numpy().copy() if dev.is_cpu else self.out.numpy()
        if self.npdt != np.float64:  # a float32 value clamped to a limit may lie outside
            lo, hi = model.joint_limits[:, 0], model.joint_limits[:, 1]  # the float64 one
            np.clip(out[:, :model.n_dof], lo, hi, out=out[:, :model.n_dof])
        best = self.best.numpy().copy() if dev.is_cpu else self.best.numpy()
        if rigid and (best[:, 1] == 0).any():
            self._mesh_rescue(out, best, P, S)
        res = IKResult.from_rows(out, best, model.n_dof, P, S, time.perf_counter() - t0)
        if model.has_harmonic:  # back to the commanded joint values
            res = dataclasses.replace(res, q=untransmitted(model, res.q),
                                      all_q=untransmitted(model, res.all_q))
        # a calibrated robot: warn once when the solutions leave its calibration's range
        check_valid_range(model, res.q, "ik")
        return res.reshaped(lead)


def ik(robot: RobotLike, frame: int | str, target: Any, *, world: World | None = None, seeds: Any = None,
       device: DeviceLike = None, dtype: DTypeLike = np.float64,
       callback: Callable[[int, np.ndarray], None] | None = None, warm_start: Any = None,
       options: IKOptions | None = None, **overrides: Any) -> IKResult:
    """Collision-free IK of ``frame`` onto ``target`` with random multi-starts: one
    :class:`IKSolver` solve.

    Args:
        robot: robot name or RobotModel.
        frame: end-effector frame (name, end-effector alias or index).
        target: pose(s) (4, 4) or (..., 4, 4) in the base frame [m], or a tuple
            ``(positions (..., 3) [m], quaternions (..., 4))``, the quaternions in
            ROS/MoveIt/scipy order ``(x, y, z, w)`` (normalised; no scipy needed).
        world: optional :class:`jwarp.world.World` (None: self-collision only).
        seeds: start configurations (n_dof,), (n_starts, n_dof) or (T, n_starts, n_dof)
            instead of random ones (the old name ``initial`` warns, for one release).
        device, dtype: Warp device (None: Warp's default device, as :class:`IKSolver`;
            docs/api.md "Devices") and float type.
        callback: ``callback(iteration, q (B, n_dof))`` after every evaluation.
        warm_start: optional learned warm start (:class:`IKSolver`'s ``warm_start``: an
            object with ``seeds(targets (T, 4, 4), world) -> (T, H, n_dof)``): the seeds
            are its H per target followed by ``n_random_with_warm_start`` random ones
            (numpy, from ``seed``) instead of ``n_starts`` random ones; ``seeds`` win.
        options: :class:`IKOptions` (None: its defaults); not modified.
        **overrides: any field of :class:`IKOptions` as a keyword (``n_starts=32``,
            ``tol_pos=1e-5``, ``seed=1``, ...): the options are
            ``dataclasses.replace(options, **overrides)``, so an override wins over the same
            field of ``options``; ``ik(r, f, T, n_starts=8)`` equals
            ``ik(r, f, T, options=IKOptions(n_starts=8))``.

    Raises:
        ValueError: unknown frame, bad target/seed shapes, world dimension mismatch, bad
            options, a warm start's output that is not (T, H, n_dof) finite values.
        TypeError: an override that is not a field of :class:`IKOptions` (named, with the
            list of fields), ``options`` not an :class:`IKOptions`, a ``warm_start``
            without a callable ``seeds``.
    """
    t0 = time.perf_counter()
    seeds = renamed_argument("ik()", "initial", "seeds", overrides, seeds)  # one release
    init_warp()
    check_warm_start(warm_start)
    model = get_robot(robot)
    fi = model.frame_index(frame)
    collision.check_world(model, world)
    check_single_world(world)
    T, lead = target_poses(target)
    opts = with_overrides("ik", IKOptions, options, overrides)
    seed = opts.seed
    finite_as(T, numpy_dtype(scalar_type(dtype)), "target")  # before the seeds' check
    n_seeds = opts.n_starts
    if seeds is not None:
        q0 = _seeds(model, seeds, len(T), "seeds")
        finite_as(q0, numpy_dtype(scalar_type(dtype)), "seeds")
        n_seeds = q0.shape[1]
    elif warm_start is not None:  # its seeds, then random ones from numpy's stream
        q0 = warm_start_seeds(model, warm_start, T, world, opts.n_random_with_warm_start,
                              np.random.default_rng(seed))
        finite_as(q0, numpy_dtype(scalar_type(dtype)), "warm_start")
        n_seeds = q0.shape[1]
    else:  # numpy's random stream (the seeds ik() has always drawn)
        q0 = sample_within_limits(model, len(T) * n_seeds,
                                  np.random.default_rng(seed)).reshape(len(T), n_seeds, -1)
    opts.n_starts = n_seeds
    key = _solver_key(model, fi, len(T), opts, world, device, dtype)
    solver = _SOLVERS.pop(key, None) if key is not None else None  # in use: not shared
    if solver is None:
        solver = IKSolver(model, fi, len(T), opts, world=world, device=device, dtype=dtype)
    solver.reseed(seed)  # a cached solver: the same re-seeds as a new one
    res = solver.solve(T, q0, callback=callback)
    if key is not None:
        _SOLVERS[key] = solver
        while len(_SOLVERS) > SOLVER_CACHE_SIZE:
            _SOLVERS.pop(next(iter(_SOLVERS)))
    return res.reshaped(lead, time.perf_counter() - t0)


#: a step counts as progress (resets a start's stall count) when it brings the pose cost
#: below this fraction of the start's best (:attr:`IKOptions.restart_after`)
RESTART_PROGRESS = 0.9


#: :func:`ik` keeps this many small solvers (<= :data:`SOLVER_CACHE_MAX_BATCH` seeds) for
#: calls with the same robot, frame, sizes, world, device, dtype and options (a solver's
#: set-up costs about as much as a small solve on the CPU)
SOLVER_CACHE_SIZE = 8


SOLVER_CACHE_MAX_BATCH = 4096


_SOLVERS: dict[tuple, IKSolver] = {}


def _solver_key(model: RobotModel, frame: int, n_problems: int, opts: IKOptions, world: World | None,
                device: DeviceLike, dtype: DTypeLike) -> tuple | None:
    """Cache key of a solver for these arguments (None: do not cache). The cached solver
    holds the robot and the world, so their ids stay theirs while it is cached."""
    if n_problems * opts.n_starts > SOLVER_CACHE_MAX_BATCH:
        return None

    def arr(a: Any) -> Any:
        if a is None:
            return None
        a = np.asarray(a, np.float64)
        return a.shape, a.tobytes()

    w = opts.weights
    fields = tuple(getattr(opts, f.name) for f in dataclasses.fields(opts)
                   if f.name not in ("seed", "weights", "kappa", "q_default"))
    return (id(model), frame, n_problems, fields, id(world), str(resolve_device(device)),
            scalar_type(dtype).__name__, None if w is None else dataclasses.astuple(w),
            arr(opts.kappa), arr(opts.q_default))


def _seeds(model: RobotModel, initial: Any, nT: int, name: str = "initial") -> np.ndarray:
    a = real_array(initial, name)
    n = model.n_dof
    if a.ndim == 1:
        a = a[None, None]
    elif a.ndim == 2:
        a = a[None]
    if a.ndim != 3 or a.shape[-1] != n or a.shape[0] not in (1, nT) or a.shape[1] == 0:
        raise ValueError(f"{name}: expected seeds ({n},), (n_starts, {n}) or ({nT}, n_starts, "
                         f"{n}), got {np.shape(initial)}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name}: contains NaN or inf")
    return np.array(np.broadcast_to(a, (nT,) + a.shape[1:]))


# ------------------------------------------------------------------ warm starts
def check_warm_start(warm_start: Any, name: str = "warm_start") -> Any:
    """``warm_start`` itself if it is None or has a callable ``seeds``, else a TypeError
    naming ``name``. A warm start (duck-typed; e.g. ``jwarp.learn.ik_net.IKNet``) is any
    object with ``seeds(targets (P, 4, 4) numpy float64, world) -> (P, H, n_dof)``: H
    initial configurations per target (a twin-headed network: 2)."""
    if warm_start is not None and not callable(getattr(warm_start, "seeds", None)):
        raise TypeError(f"{name}: expected an object with a callable seeds(targets, world) "
                        f"(e.g. a loaded IK network), got {type(warm_start).__name__}")
    return warm_start


def warm_start_seeds(model: RobotModel, warm_start: Any, targets: np.ndarray, world: World | None,
                     n_random: int = 0, rng: np.random.Generator | None = None,
                     name: str = "warm_start") -> np.ndarray:
    """Seeds (P, H + n_random, n_dof) for the targets (P, 4, 4): the warm start's H per
    target (checked: shape (P, H, n_dof), H >= 1, finite; a ValueError naming ``name``
    otherwise), then ``n_random`` uniform ones inside the limits drawn from ``rng``."""
    check_warm_start(warm_start, name)
    T = np.ascontiguousarray(targets, dtype=np.float64).reshape(-1, 4, 4)
    P, n = len(T), model.n_dof
    raw = warm_start.seeds(T.copy(), world)
    if hasattr(raw, "detach") and hasattr(raw, "cpu"):  # a torch tensor
        raw = raw.detach().cpu().numpy()
    try:
        a = np.asarray(raw, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise ValueError(f"{name}: seeds() returned {type(raw).__name__}, not an array of "
                         f"numbers ({e})") from None
    if a.ndim == 2 and a.shape == (P, n):  # one seed per target
        a = a[:, None]
    if a.ndim != 3 or a.shape[0] != P or a.shape[2] != n or a.shape[1] == 0:
        raise ValueError(f"{name}: seeds() must return ({P}, H, {n}) joint values for {P} "
                         f"targets of '{model.name}', got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name}: seeds() returned NaN or inf")
    if n_random:
        rng = np.random.default_rng() if rng is None else rng
        extra = sample_within_limits(model, P * int(n_random), rng).reshape(P, int(n_random), n)
        a = np.concatenate([a, extra], axis=1)
    return np.ascontiguousarray(a)


def _rescue_rows(solver: Any, out: np.ndarray, best: np.ndarray, P: int, S: int) -> None:
    """:meth:`IKSolver._mesh_rescue` (module function: the solver's host side)."""
    model, o = solver.robot, solver.options
    obj = solver.objective
    if getattr(model, "collision_pieces", None) is None or obj is None or not obj.collides \
            or obj.compensation is not None:
        return
    from jwarp.kernels import ik_step as E
    from jwarp.world.mesh_check import mesh_check

    n = model.n_dof
    rows = out.reshape(P, S, -1)
    on = ((rows[..., n + E.COL_POS] <= o.tol_pos) & (rows[..., n + E.COL_ROT] <= o.tol_rot)
          & (rows[..., n + E.COL_FEASIBLE] == 0) & (best[:, 1] == 0)[:, None])
    cand = np.nonzero(on.reshape(-1))[0]
    if not len(cand):
        return
    if mesh_check(model, solver.world, solver.device) is None:
        return
    q = np.asarray(out[cand, :n], np.float64)
    ok = within_limits(model, q)
    if ok.any():
        from jwarp.world.collision import mesh_certified, min_distances

        # the spheres refuse them all (COL_FEASIBLE 0): the one check of what the mesh
        # certificate proves free (a collision deeper than the spheres reach past the
        # meshes is not tried)
        md = np.asarray(min_distances(model, q[ok], solver.world, device=solver.device,
                                      dtype=np.float64))
        ok[ok] = mesh_certified(model, q[ok], solver.world, np.zeros(int(ok.sum()), bool),
                                o.margin, o.margin, solver.device, md=md)
    if not ok.any():
        return
    out[cand[ok], n + E.COL_FEASIBLE] = 1
    fz = (rows[..., n + E.COL_FEASIBLE] != 0)
    errs = rows[..., n + E.COL_POS:n + E.COL_AUX + 1]
    best[:, 0] = select_best(fz, errs)
    best[:, 1] = fz.sum(1)


def select_best(feasible: np.ndarray, errs: np.ndarray) -> np.ndarray:
    """Host twin of the device selection (:mod:`jwarp.kernels.ik_step` ``select``):
    feasible (P, S) bool, errs (P, S, 3) [|e_v|, |e_w|, U_A] -> (P,) chosen seed: the
    feasible one with the lowest U_A, else the smallest |e_v| + 0.1 |e_w|."""
    key_f = np.where(feasible, errs[..., 2], np.inf)
    key_i = errs[..., 0] + errs[..., 1] * 0.1
    return np.where(feasible.any(1), np.argmin(key_f, axis=1), np.argmin(key_i, axis=1))
