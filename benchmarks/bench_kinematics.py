#!/usr/bin/env python
"""Throughput of the jwarp kinematics kernels (configurations per second).

Times the Warp kernel launches of FK, the geometric Jacobian of one TCP and the elastic
(torque-equilibrium) FK on preallocated Warp arrays, beside a plain vectorized numpy FK
and (if installed) pinocchio, and prints one fixed-width table. See benchmarks/README.md.

    python benchmarks/bench_kinematics.py                  # CPU, and CUDA if present
    python benchmarks/bench_kinematics.py --device cpu --dtype float64 --json out.json
    python benchmarks/bench_kinematics.py --quick --device cpu    # smoke test sizes

How a jwarp row is timed: the library call is made once with its launches recorded
(``wp.launch`` is wrapped while it runs); the recorded launches, with the very arrays the
library allocated, are then replayed with ``wp.launch``. Compile time and allocations are
therefore excluded, while the per-launch Python cost of ``wp.launch`` is included (it is
what every library call pays). Each measurement repeats the replay until it takes at
least ``--min-time`` seconds, ends with ``wp.synchronize_device``, runs ``--repeats``
times, and reports the median (the best is kept in the JSON output).
"""

from __future__ import annotations

import argparse
import concurrent.futures
import contextlib
import gc
import inspect
import json
import math
import os
import platform
import statistics
import sys
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
import warp as wp

if hasattr(wp.config, "quiet"):  # older Warp
    wp.config.quiet = True
if hasattr(wp, "LOG_WARNING") and hasattr(wp.config, "log_level"):
    wp.config.log_level = max(wp.config.log_level, wp.LOG_WARNING)

import timing  # noqa: E402  (benchmarks/timing.py, beside this script)
from timing import Timing, measure  # noqa: E402,F401

from jwarp.core.arrays import init_warp  # noqa: E402
from jwarp.core.device import put_model  # noqa: E402
from jwarp.kinematics import (  # noqa: E402
    ElasticLaunch,
    KinematicsData,
    elastic_args,
    fk,
    fk_elastic,
    forward_kinematics,
    frame_jacobian,
    jacobian,
    launch_fk,
)
from jwarp.model import RobotModel  # noqa: E402
from jwarp.plugins.registry import robot as get_robot  # noqa: E402

KAPPA = 1e-4            # rad/(N m) on the alpha, beta and theta axes of every DH frame
ELASTIC_ITERS = (1, 3, 10)
FULL = dict(cpu=(1, 1_000, 100_000), cuda=(1, 1_000, 100_000, 1_000_000),
            thread_batch=100_000, pin_batch=1_000, min_time=0.2, repeats=5,
            small_repeats=20_000)
QUICK = dict(cpu=(1, 100), cuda=(1, 10_000), thread_batch=2_000, pin_batch=20,
             min_time=0.005, repeats=2, small_repeats=200)


# ====================================================================== timing
# Timing and measure come from benchmarks/timing.py (the one timing helper of every
# benchmark script): median/best of repeated runs, each closed by a device sync.


# ============================================================ launch recording
_LAUNCH_SIG = inspect.signature(wp.launch)


@contextlib.contextmanager
def record_launches():
    """Record every ``wp.launch`` made inside the block (and still perform it)."""
    original = wp.launch
    recorded: list[dict] = []

    def spy(*args: Any, **kwargs: Any) -> Any:
        recorded.append(dict(_LAUNCH_SIG.bind(*args, **kwargs).arguments))
        return original(*args, **kwargs)

    wp.launch = spy
    try:
        yield recorded
    finally:
        wp.launch = original


def replay(launches: list[dict]) -> Callable[[], None]:
    """A function that re-issues the recorded launches, on the same arrays, in order."""
    calls = [dict(l) for l in launches]

    def run() -> None:
        for c in calls:
            wp.launch(**c)
    return run


def slice_launches(launches: list[dict], B: int, lo: int, hi: int) -> list[dict]:
    """The launches restricted to configurations [lo, hi): dim and every array whose first
    dimension is the batch are sliced (views, no copies); shared input tables are kept.
    An output that is not batch-sized is per-launch scratch (the elastic step's CPU
    scratch column): each slice gets its own copy, or concurrent slices would race on it."""
    own: dict[int, wp.array] = {}

    def cut(x: Any, output: bool = False) -> Any:
        if isinstance(x, wp.array) and x.ndim >= 1 and x.shape[0] == B:
            return x[lo:hi]
        if output and isinstance(x, wp.array):
            return own.setdefault(id(x), wp.empty_like(x))
        return x

    out = []
    for l in launches:
        dim = l["dim"]
        if (dim if isinstance(dim, int) else tuple(dim)[0]) != B:
            raise ValueError("launch is not over the batch")
        c = dict(l)
        c["dim"] = hi - lo
        c["inputs"] = [cut(x) for x in l.get("inputs", [])]
        c["outputs"] = [cut(x, output=True) for x in l.get("outputs", [])]
        out.append(c)
    return out


def threaded(launches: list[dict], B: int, pool: concurrent.futures.ThreadPoolExecutor,
             n_threads: int) -> Callable[[], None]:
    """Run the launches on ``n_threads`` contiguous slices of the batch, one thread each
    (Warp's CPU kernels are called through ctypes, which releases the GIL)."""
    bounds = [B * k // n_threads for k in range(n_threads + 1)]
    parts = [replay(slice_launches(launches, B, bounds[k], bounds[k + 1]))
             for k in range(n_threads)]

    def run() -> None:
        for f in [pool.submit(p) for p in parts]:
            f.result()
    return run


# ================================================================ numpy FK
class NumpyFK:
    """Plain vectorized numpy FK: frames in topological order, each composed with its
    parent by an einsum over the batch. Same DH convention as jwarp::

        parent_T_child = Rot_y(beta) Rot_x(alpha) Trans_x(r) Rot_z(theta + q) Trans_z(d)
    """

    def __init__(self, model: RobotModel, dtype: Any):
        self.dtype = np.dtype(dtype)
        self.order = [int(i) for i in model.topological_order]
        self.parents = model.parents.astype(int)
        self.coupling_t = model.coupling_matrix.T.astype(self.dtype)   # (n_dof, n_frames)
        self.prismatic = model.frame_is_prismatic
        self.driven = np.abs(model.coupling_matrix).sum(axis=1) > 0
        self.is_dh = model.is_dh
        self.n = model.n_frames
        dh = model.dh_table
        self.theta0 = dh[:, 1].astype(self.dtype)
        self.d0 = dh[:, 0].astype(self.dtype)
        # Rot_y(beta) Rot_x(alpha) Trans_x(r) (DH) or the fixed local transform (static,
        # fixed DH frames): columns of the first used below.
        self.pre = np.zeros((self.n, 4, 4))
        self.const = np.zeros((self.n, 4, 4))
        for i in range(self.n):
            if self.is_dh[i]:
                d, th, r, a, b = dh[i]
                self.pre[i] = rot_y(b) @ rot_x(a) @ trans(r, 0, 0)
                self.const[i] = self.pre[i] @ rot_z(th) @ trans(0, 0, d)
            else:
                self.const[i] = model.static_transforms[i]
        self.pre = self.pre.astype(self.dtype)
        self.const = self.const.astype(self.dtype)

    def alloc(self, B: int) -> tuple[np.ndarray, np.ndarray]:
        return (np.empty((B, self.n, 4, 4), self.dtype), np.empty((B, 4, 4), self.dtype))

    def __call__(self, q: np.ndarray, out: np.ndarray, local: np.ndarray) -> np.ndarray:
        qf = q @ self.coupling_t                                         # (B, n_frames)
        for i in self.order:
            p = self.parents[i]
            if self.is_dh[i] and self.driven[i]:
                A = self.pre[i]
                if self.prismatic[i]:
                    th = np.full(q.shape[0], self.theta0[i], self.dtype)
                    d = self.d0[i] + qf[:, i]
                else:
                    th = self.theta0[i] + qf[:, i]
                    d = np.full(q.shape[0], self.d0[i], self.dtype)
                c, s = np.cos(th), np.sin(th)
                # A Rot_z(th) Trans_z(d): columns c*a0 + s*a1, -s*a0 + c*a1, a2, d*a2 + a3
                local[:, :, 0] = c[:, None] * A[:, 0] + s[:, None] * A[:, 1]
                local[:, :, 1] = c[:, None] * A[:, 1] - s[:, None] * A[:, 0]
                local[:, :, 2] = A[:, 2]
                local[:, :, 3] = d[:, None] * A[:, 2] + A[:, 3]
                if p < 0:
                    out[:, i] = local
                else:
                    np.einsum("bij,bjk->bik", out[:, p], local, out=out[:, i])
            else:
                if p < 0:
                    out[:, i] = self.const[i]
                else:
                    np.einsum("bij,jk->bik", out[:, p], self.const[i], out=out[:, i])
        return out


def rot_x(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1.0]])


def rot_y(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s, 0], [0, 1, 0, 0], [-s, 0, c, 0], [0, 0, 0, 1.0]])


def rot_z(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])


def trans(x: float, y: float, z: float) -> np.ndarray:
    t = np.eye(4)
    t[:3, 3] = (x, y, z)
    return t


# ================================================================ pinocchio
class PinocchioModel:
    """A pinocchio model of the same frame tree: every driven DH frame is a revolute-Z (or
    prismatic-Z) joint after a fixed placement ``Rot_y Rot_x Trans_x(r) Rot_z(theta)
    Trans_z(d)`` (Trans_z and Rot_z commute with a Z joint); static and fixed DH frames
    are operational frames. A coupled frame (justin19's torso_4 = -q1 - q2) becomes an
    independent joint: pinocchio gets q_pin = C q (C: the coupling rows of the driven
    frames), so its FK is exact and its Jacobian has one column per driven frame
    (folding J_pin @ C gives jwarp's columns; the fold is not timed)."""

    def __init__(self, model: RobotModel, tcp: str):
        import pinocchio as pin

        self.pin = pin
        pm = pin.Model()
        pm.name = model.name
        where: dict[int, tuple[int, np.ndarray, int]] = {}  # frame -> (joint, placement, pin frame)
        rows: list[tuple[int, np.ndarray]] = []
        self.frame_ids = [0] * model.n_frames
        for i in (int(k) for k in model.topological_order):
            f = model.frames[i]
            p = int(model.parents[i])
            joint, placement, parent_frame = (0, np.eye(4), 0) if p < 0 else where[p]
            if f.kind == "dh":
                d, th, r, a, b = model.dh_table[i]
                local = rot_y(b) @ rot_x(a) @ trans(r, 0, 0) @ rot_z(th) @ trans(0, 0, d)
            else:
                local = model.static_transforms[i]
            placement = placement @ local
            if f.coupling:
                jm = pin.JointModelPZ() if model.frame_is_prismatic[i] else pin.JointModelRZ()
                joint = pm.addJoint(joint, jm, pin.SE3(placement), f.name + "_joint")
                rows.append((joint, model.coupling_matrix[i]))
                placement = np.eye(4)
            fid = pm.addFrame(pin.Frame(f.name, joint, parent_frame, pin.SE3(placement),
                                        pin.FrameType.OP_FRAME), False)
            self.frame_ids[i] = int(fid)
            where[i] = (joint, placement, fid)
        self.coupling = np.zeros((pm.nq, model.n_dof))
        for joint, row in rows:
            self.coupling[pm.joints[joint].idx_q] = row
        self.model, self.data = pm, pm.createData()
        self.tcp = self.frame_ids[model.frame_index(tcp)]
        self.n_coupled = sum(1 for f in model.frames if len(f.coupling) > 1)

    def q(self, q: np.ndarray) -> list[np.ndarray]:
        return [np.ascontiguousarray(r) for r in np.asarray(q, np.float64) @ self.coupling.T]

    def fk_loop(self, qs: list[np.ndarray]) -> Callable[[], None]:
        pin, m, d = self.pin, self.model, self.data

        def run() -> None:
            for qi in qs:
                pin.forwardKinematics(m, d, qi)
                pin.updateFramePlacements(m, d)
        return run

    def jac_loop(self, qs: list[np.ndarray]) -> Callable[[], None]:
        pin, m, d, f = self.pin, self.model, self.data, self.tcp
        ref = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED

        def run() -> None:
            for qi in qs:
                pin.computeJointJacobians(m, d, qi)
                pin.getFrameJacobian(m, d, f, ref)
        return run

    def frame_jac_loop(self, qs: list[np.ndarray]) -> Callable[[], None]:
        pin, m, d, f = self.pin, self.model, self.data, self.tcp
        ref = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED

        def run() -> None:
            for qi in qs:
                pin.computeFrameJacobian(m, d, qi, f, ref)
        return run

    def check(self, model: RobotModel, q: np.ndarray, tcp: str) -> tuple[float, float]:
        """Max |difference| to jwarp (float64, CPU) of all frames and of the folded TCP
        Jacobian over the configurations ``q``."""
        pin = self.pin
        ref_frames = fk(model, q.astype(np.float64), device="cpu", dtype=np.float64)
        ref_jac = jacobian(model, q.astype(np.float64), tcp, device="cpu", dtype=np.float64)
        ef = ej = 0.0
        for b, qi in enumerate(self.q(q)):
            pin.forwardKinematics(self.model, self.data, qi)
            pin.updateFramePlacements(self.model, self.data)
            for i, fid in enumerate(self.frame_ids):
                ef = max(ef, float(np.abs(self.data.oMf[fid].homogeneous - ref_frames[b, i]).max()))
            pin.computeJointJacobians(self.model, self.data, qi)
            J = pin.getFrameJacobian(self.model, self.data, self.tcp,
                                     pin.ReferenceFrame.LOCAL_WORLD_ALIGNED) @ self.coupling
            ej = max(ej, float(np.abs(J - ref_jac[b]).max()))
        return ef, ej


# ================================================================== table
@dataclass
class Row:
    robot: str
    op: str
    device: str
    batch: int
    configs_per_s: float
    time_per_batch_s: float          # median
    best_time_per_batch_s: float
    ratio: float | None = None
    ratio_meaning: str = ""
    extra: dict = field(default_factory=dict)


COLUMNS = (("robot", 9, "<"), ("op", 24, "<"), ("device", 7, "<"), ("batch", 9, ">"),
           ("configs/s", 10, ">"), ("time/batch", 11, ">"), ("ratio", 8, ">"),
           ("ratio meaning", 24, "<"))


def si(x: float) -> str:
    for div, suffix in ((1e9, " G"), (1e6, " M"), (1e3, " k")):
        if x >= div:
            return f"{x / div:.3g}{suffix}"
    return f"{x:.3g}"


def duration(t: float) -> str:
    for div, unit in ((1.0, "s"), (1e-3, "ms"), (1e-6, "us")):
        if t >= div:
            return f"{t / div:.3g} {unit}"
    return f"{t / 1e-9:.3g} ns"


def header() -> str:
    head = " ".join(f"{name:{align}{w}}" for name, w, align in COLUMNS)
    return head + "\n" + " ".join("-" * w for _, w, _ in COLUMNS)


def fmt(r: Row) -> str:
    cells = (r.robot, r.op, r.device, f"{r.batch:,}".replace(",", "_"), si(r.configs_per_s),
             duration(r.time_per_batch_s), "" if r.ratio is None else f"{r.ratio:.3g}",
             r.ratio_meaning)
    return " ".join(f"{c:{align}{w}}" for c, (_, w, align) in zip(cells, COLUMNS))


# ================================================================== bench
class Bench:
    def __init__(self, args: argparse.Namespace):
        self.args = args
        self.sizes = QUICK if args.quick else FULL
        self.min_time = args.min_time if args.min_time is not None else self.sizes["min_time"]
        self.repeats = args.repeats if args.repeats is not None else self.sizes["repeats"]
        self.dtype = np.dtype(args.dtype)
        # the scalar *type* (np.float32), not the dtype instance: device_model.scalar_type
        # maps np.dtype('float32') to itself (np.dtype('float32') == wp.float32 is True)
        self.ftype = self.dtype.type
        self.wtype = wp.float32 if self.dtype == np.float32 else wp.float64
        self.rows: list[Row] = []
        self.notes: list[str] = []
        self.checks: dict[str, float] = {}
        self.summary: list[str] = []
        self.ratios: dict[str, float] = {}
        self.rng = np.random.default_rng(0)

    # -------------------------------------------------------------- helpers
    def emit(self, row: Row) -> Row:
        self.rows.append(row)
        print(fmt(row), flush=True)
        return row

    def time_row(self, robot: str, op: str, device: Any, batch: int, fn: Callable[[], Any],
                 sync_device: Any = None, ratio: float | None = None,
                 ratio_meaning: str = "", **extra: Any) -> Row:
        t = measure(fn, sync_device, self.min_time, self.repeats)
        row = Row(robot, op, str(device), batch, batch / t.median, t.median, t.best,
                  ratio, ratio_meaning, dict(calls=t.calls, runs=t.runs, **extra))
        return row

    def configs(self, model: RobotModel, B: int) -> np.ndarray:
        lo, hi = model.joint_limits.T
        return (lo + (hi - lo) * self.rng.random((B, model.n_dof))).astype(self.dtype)

    # ------------------------------------------------------------ jwarp ops
    def jwarp_launches(self, model: RobotModel, q: wp.array, dev: Any) -> dict[str, list[dict]]:
        """Record the launches of every timed op on batch ``q`` (runs each once)."""
        t = put_model(model, dev, self.ftype)
        ops: dict[str, list[dict]] = {}
        with record_launches() as rec:
            launch_fk(t, q)
        ops["fk"] = rec
        if dev.is_cuda:
            with record_launches() as rec:
                launch_fk(t, q, frame_major=True)
            ops["fk (frame-major out)"] = rec
        with record_launches() as rec:
            launch_fk(t, q, component_major=True)
        ops["fk (component-major out)"] = rec
        with record_launches() as rec:
            jacobian(model, q, self.args.tcp, device=dev, dtype=self.ftype, validate=False)
        ops["jacobian"] = rec
        ops["fk+jacobian"] = ops["fk"] + ops["jacobian"]
        _, batch, tt, kap, rho0 = elastic_args(model, q, KAPPA, 1.0, 1, 0.0, None, dev,
                                                self.ftype, False)
        for n_iter in ELASTIC_ITERS:
            run = ElasticLaunch(tt, batch.array, kap, rho0, 1.0)
            with record_launches() as rec:
                rho = None
                for _ in range(n_iter):   # fixed count: no convergence test
                    _, rho_new, _ = run.step(rho)
                    rho = (rho_new, 1)
                run.frames_at(rho)
            ops[f"elastic_fk({n_iter})"] = rec
        # one torque update from per-configuration rows rho (compensation inside an
        # optimizer keeps rho between its iterations)
        run = ElasticLaunch(tt, batch.array, kap, rho0, 1.0)
        _, rho1, _ = run.step(None)
        with record_launches() as rec:
            run.step((rho1, 1))
        ops["elastic_step"] = rec
        # the FK part of that step alone: FK at per-configuration DH rows
        with record_launches() as rec:
            launch_fk(t, q, dh=(rho1, 1))
        ops["fk (per-config rho)"] = rec
        return ops

    def run_device(self, model: RobotModel, dev: Any, batches: tuple[int, ...]) -> dict:
        """jwarp rows of one robot on one device; returns {batch: {op: Row}}."""
        name = model.name
        result: dict[int, dict[str, Row]] = {}
        for B in batches:
            q = wp.array(self.configs(model, B), dtype=self.wtype, device=dev)
            ops = self.jwarp_launches(model, q, dev)
            rows: dict[str, Row] = {}
            fns = {op: replay(launches) for op, launches in ops.items()}
            # the FK launch pre-packed by Warp (wp.launch(..., record_cmd=True)): what is
            # left when the Python argument packing of wp.launch is taken out
            fns["fk (wp.Launch replay)"] = wp.launch(**ops["fk"][0], record_cmd=True).launch
            for op, fn in fns.items():
                rows[op] = self.time_row(name, op, dev, B, fn, dev,
                                         launches=len(ops.get(op, [None])))
                if op != "fk":
                    rows[op].ratio = rows[op].time_per_batch_s / rows["fk"].time_per_batch_s
                    rows[op].ratio_meaning = "x fk time"
                self.emit(rows[op])
            kernels = {"fk": fns["fk"], "jacobian": fns["jacobian"]}
            del fns
            del ops
            # the public API, allocations and host sync included: Warp in, a new Warp
            # array out; then with the output reused (out=); then numpy in, numpy out
            # (validation on, as a user calls it), fresh and with out=; then the
            # KinematicsData path: Warp q copied into a reused data, its recorded launch
            # replayed, the data's own buffer returned (pinocchio-style Model/Data)
            tcp = self.args.tcp
            m_dev = put_model(model, dev, self.ftype)
            kdata = KinematicsData(m_dev, B)
            fk_out = fk(model, q, device=dev, dtype=self.ftype, validate=False)
            q_np = np.array(q.numpy())
            fk_out_np = np.empty((B, model.n_frames, 4, 4), self.dtype)
            jac_out = jacobian(model, q, tcp, device=dev, dtype=self.ftype, validate=False)
            kw = dict(device=dev, dtype=self.ftype)
            api = {
                "fk api": lambda: fk(model, q, validate=False, **kw),
                "fk api out=": lambda: fk(model, q, validate=False, out=fk_out, **kw),
                "fk api numpy": lambda: fk(model, q_np, **kw),
                "fk api numpy out=": lambda: fk(model, q_np, out=fk_out_np, **kw),
                "jacobian api": lambda: jacobian(model, q, tcp, validate=False, **kw),
                "jacobian api out=": lambda: jacobian(model, q, tcp, validate=False, out=jac_out,
                                                      **kw),
                "fk KinematicsData": lambda: forward_kinematics(m_dev, kdata, q, validate=False),
                "jacobian KinematicsData": lambda: frame_jacobian(m_dev, kdata, tcp, q,
                                                                  validate=False),
            }
            for op, fn in api.items():
                rows[op] = self.time_row(name, op, dev, B, fn, dev)
            if max(batches) == B:
                self.side_by_side(name, dev, B, kernels, api)
            # max_iter=10, tol=0: the library still stops early once every configuration's
            # update changed nothing (delta == 0, common in float32); the op name gives the
            # number of torque updates it actually made
            it = ELASTIC_ITERS[-1]

            def elastic_api() -> Any:
                return fk_elastic(model, q, KAPPA, max_iter=it, tol=0.0, device=dev,
                                  dtype=self.ftype, validate=False)
            done = int(np.max(elastic_api().iterations))
            api_op = f"elastic_fk({done}) api"
            rows[api_op] = self.time_row(name, api_op, dev, B, elastic_api, dev,
                                         max_iter=it, updates=done)
            for op in (*api, api_op):
                kernel = "jacobian" if op.startswith("jacobian") else "fk"
                rows[op].ratio = rows[op].time_per_batch_s / rows[kernel].time_per_batch_s
                rows[op].ratio_meaning = f"x {kernel} time"
                self.emit(rows[op])
            result[B] = rows
            # free this batch's arrays before the next batch allocates (rebound, not del:
            # the closures above read them, and ruff's F821 reads a del as undefined)
            q = fk_out = fk_out_np = jac_out = q_np = api = kernels = kdata = None
            gc.collect()
        return result

    def side_by_side(self, name: str, dev: Any, B: int, kernels: dict, api: dict) -> None:
        """Each public call over its kernel alone (the recorded launches replayed), timed
        interleaved (:func:`timing.side_by_side`: a noisy neighbour slows all alike); the
        ratios go to the summary under the table and to the JSON."""
        names = list(kernels) + list(api)
        fns = list(kernels.values()) + list(api.values())
        ts = dict(zip(names, timing.side_by_side(fns, dev, self.min_time, rounds=self.repeats)))
        for op in api:
            k = ts[op.split()[0]]
            t = ts[op]
            self.ratios[f"{name} {dev} batch {B}: {op} / kernel"] = t.median / k.median
            self.summary.append(
                f"{name} {dev} batch {B}: {op} / {op.split()[0]} kernel = "
                f"{t.median / k.median:.3g} (median {duration(t.median)} vs "
                f"{duration(k.median)}; best {t.best / k.best:.3g}), side by side, "
                f"{t.runs} rounds")

    # ------------------------------------------------------- small calls
    def run_small(self, model: RobotModel, dev: Any, rows: dict) -> None:
        """The public fk/jacobian of ONE configuration (numpy (n_dof,) in, numpy out, as a
        control loop or an interactive user calls them), every call timed on its own:
        min and median of ``--small-repeats`` calls after a warm-up."""
        n = self.sizes["small_repeats"] if self.args.small_repeats is None else self.args.small_repeats
        q = self.configs(model, 1)[0]
        tcp = self.args.tcp
        calls = {
            "fk api 1 config": lambda: fk(model, q, device=dev, dtype=self.ftype),
            "jacobian api 1 config": lambda: jacobian(model, q, tcp, device=dev, dtype=self.ftype),
        }
        for op, fn in calls.items():
            for _ in range(max(10, n // 20)):
                fn()
            times = []
            for _ in range(n):
                t0 = time.perf_counter()
                fn()
                times.append(time.perf_counter() - t0)
            med, best = statistics.median(times), min(times)
            row = Row(model.name, op, str(dev), 1, 1 / med, med, best,
                      extra=dict(calls=n, runs=1, min_s=best, median_s=med))
            kernel = rows.get(1, {}).get("fk (wp.Launch replay)")
            if kernel is not None:
                row.ratio = med / kernel.time_per_batch_s
                row.ratio_meaning = "x fk wp.Launch replay"
            self.emit(row)
            self.summary.append(f"{model.name} {dev} {op}: min {duration(best)}, median "
                                f"{duration(med)} over {n} calls")

    # ------------------------------------------------------------- numpy
    def run_numpy(self, model: RobotModel, cpu_rows: dict, batches: tuple[int, ...]) -> dict:
        nfk = NumpyFK(model, self.dtype)
        q = self.configs(model, 64)
        out, local = nfk.alloc(64)
        ref = fk(model, q, device="cpu", dtype=self.ftype)
        err = float(np.abs(nfk(q, out, local) - ref).max())
        self.checks[f"{model.name}: |numpy fk - jwarp fk| max"] = err
        tol = 1e-3 if self.dtype == np.float32 else 1e-9
        if not err <= tol:
            raise SystemExit(f"numpy FK disagrees with jwarp FK on {model.name}: {err:.3g}")
        result = {}
        for B in batches:
            q = self.configs(model, B)
            out, local = nfk.alloc(B)
            row = self.time_row(model.name, "fk numpy", "cpu", B, lambda: nfk(q, out, local))
            if B in cpu_rows:
                row.ratio = row.time_per_batch_s / cpu_rows[B]["fk"].time_per_batch_s
                row.ratio_meaning = "jwarp fk speedup"
            self.emit(row)
            result[B] = row
            out = local = None  # freed before the next batch (rebound, not del: see run_device)
        return result

    # ----------------------------------------------------------- threads
    def run_threads(self, model: RobotModel, n_threads: int) -> None:
        B = self.sizes["thread_batch"]
        dev = wp.get_device("cpu")
        q = wp.array(self.configs(model, B), dtype=self.wtype, device=dev)
        ops = self.jwarp_launches(model, q, dev)
        with concurrent.futures.ThreadPoolExecutor(n_threads) as pool:
            # same result either way
            fk_out = ops["fk"][0]["outputs"][0]
            replay(ops["fk"])()
            single = fk_out.numpy().copy()
            fk_out.zero_()
            threaded(ops["fk"], B, pool, n_threads)()
            self.checks[f"{model.name}: |threaded fk - fk| max"] = float(
                np.abs(fk_out.numpy() - single).max())
            rho_out = ops["elastic_step"][0]["outputs"][3]      # the step's new rows
            replay(ops["elastic_step"])()
            single = rho_out.numpy().copy()
            rho_out.zero_()
            threaded(ops["elastic_step"], B, pool, n_threads)()
            self.checks[f"{model.name}: |threaded elastic_step rho - rho| max"] = float(
                np.abs(rho_out.numpy() - single).max())
            for op in ("fk", "jacobian", "elastic_step", "elastic_fk(3)"):
                one = self.time_row(model.name, op, "cpu", B, replay(ops[op]))
                many = self.time_row(model.name, f"{op} {n_threads} threads", "cpu", B,
                                     threaded(ops[op], B, pool, n_threads))
                many.ratio = one.time_per_batch_s / many.time_per_batch_s
                many.ratio_meaning = "speedup vs 1 thread"
                many.extra["single_thread_s"] = one.time_per_batch_s
                self.emit(many)

    # --------------------------------------------------------- pinocchio
    def run_pinocchio(self, model: RobotModel, cpu_rows: dict) -> None:
        try:
            import pinocchio  # noqa: F401
        except ImportError:
            if not any("pinocchio not installed" in n for n in self.notes):
                self.notes.append("pinocchio not installed (pip install pin): no pinocchio rows")
                print("pinocchio not installed", flush=True)
            return
        pm = PinocchioModel(model, self.args.tcp)
        ef, ej = pm.check(model, self.configs(model, 16), self.args.tcp)
        self.checks[f"{model.name}: |pinocchio - jwarp| frames max"] = ef
        self.checks[f"{model.name}: |pinocchio - jwarp| jacobian max"] = ej
        if pm.n_coupled:
            self.notes.append(
                f"pinocchio {model.name}: {pm.n_coupled} coupled frame(s) modelled as "
                f"independent joints (nq={pm.model.nq} vs {model.n_dof} DoF), fed q_pin = C q")
        B = self.sizes["pin_batch"]
        qs = pm.q(self.configs(model, B))
        # jwarp reference at the same batch (CPU), if measured
        ref = cpu_rows.get(B) or cpu_rows[min(cpu_rows, key=lambda b: abs(b - B))]
        for op, fn, jop in (("fk pinocchio", pm.fk_loop(qs), "fk"),
                            ("jacobian pinocchio", pm.jac_loop(qs), "jacobian"),
                            ("jacobian pin frameJac", pm.frame_jac_loop(qs), "jacobian")):
            row = self.time_row(model.name, op, "cpu", B, fn)
            row.ratio = ref[jop].configs_per_s / row.configs_per_s
            row.ratio_meaning = f"jwarp {jop} speedup@{ref[jop].batch:g}"
            self.emit(row)

    # -------------------------------------------------------------- main
    def run(self) -> None:
        init_warp()
        devices = []
        has_cuda = wp.get_cuda_device_count() > 0
        if self.args.device in ("all", "cpu"):
            devices.append(wp.get_device("cpu"))
        if self.args.device in ("all", "cuda"):
            if has_cuda:
                devices.append(wp.get_device("cuda"))
            elif self.args.device == "cuda":
                raise SystemExit("--device cuda: no CUDA device available")
            else:
                self.notes.append("no CUDA device: CPU rows only")
        dev_names = ", ".join(f"{d} ({d.name})" for d in devices)
        print(f"jwarp kinematics benchmark: warp {wp.config.version}, numpy {np.__version__}, "
              f"{self.dtype.name}, {timing.machine()}, "
              f"devices: {dev_names}; median of {self.repeats} runs of >= {self.min_time:g} s; "
              f"load average {_loadavg() or 'n/a'}", flush=True)
        print(header(), flush=True)
        for name in self.args.robots.split(","):
            model = get_robot(name)
            cpu_rows: dict = {}
            numpy_rows: dict = {}
            for dev in devices:
                batches = self.sizes["cuda" if dev.is_cuda else "cpu"]
                if self.args.batches:
                    batches = tuple(int(float(b)) for b in self.args.batches.split(","))
                rows = self.run_device(model, dev, batches)
                self.run_small(model, dev, rows)
                if dev.is_cpu:
                    cpu_rows = rows
                    if not self.args.no_numpy:
                        numpy_rows = self.run_numpy(model, cpu_rows, batches)
                elif numpy_rows:
                    big = max(numpy_rows)
                    for r in rows.values():
                        r["fk"].ratio = r["fk"].configs_per_s / numpy_rows[big].configs_per_s
                        r["fk"].ratio_meaning = f"speed / numpy@{big:g}"
            if cpu_rows and self.args.threads > 1:
                self.run_threads(model, self.args.threads)
            if cpu_rows and not self.args.no_pinocchio:
                self.run_pinocchio(model, cpu_rows)
        self.finish(devices)

    def finish(self, devices: list) -> None:
        print()
        if self.summary:
            print("public API overhead (small calls; big calls against their kernel):")
            for line in self.summary:
                print(f"  {line}")
        if self.checks:
            print("checks:")
            for k, v in self.checks.items():
                print(f"  {k}: {v:.3g}")
        load = _loadavg()
        if load:
            print(f"load average at the end: {load} (other processes skew CPU rows)")
        for n in self.notes:
            print(f"note: {n}")
        if self.args.json:
            doc = dict(
                meta=dict(warp=wp.config.version, numpy=np.__version__, python=sys.version.split()[0],
                          dtype=self.dtype.name, cpu_count=os.cpu_count(),
                          processor=timing.machine(), host=platform.node(),
                          devices=[f"{d} ({d.name})" for d in devices],
                          min_time_s=self.min_time, repeats=self.repeats, quick=self.args.quick,
                          kappa=KAPPA, tcp=self.args.tcp, threads=self.args.threads,
                          load_average_end=_loadavg()),
                rows=[asdict(r) for r in self.rows], checks=self.checks, notes=self.notes,
                summary=self.summary, api_over_kernel=self.ratios)
            with open(self.args.json, "w") as f:
                json.dump(doc, f, indent=1)
            print(f"wrote {self.args.json}")


def _loadavg() -> str:
    try:
        return " ".join(f"{x:.2f}" for x in os.getloadavg())
    except (AttributeError, OSError):
        return ""


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--device", choices=("all", "cpu", "cuda"), default="all",
                   help="devices to time (default: CPU, and CUDA when present)")
    p.add_argument("--dtype", choices=("float32", "float64"), default="float32")
    p.add_argument("--robots", default="justin19,arm7", help="comma-separated robot names")
    p.add_argument("--tcp", default="right_tcp", help="frame of the Jacobian rows")
    p.add_argument("--batches", default=None,
                   help="comma-separated batch sizes overriding the defaults of every device")
    p.add_argument("--threads", type=int, default=2,
                   help="split the big CPU batch over N Python threads (1: skip)")
    p.add_argument("--min-time", type=float, default=None,
                   help="seconds of work per timed run (default 0.2; --quick 0.005)")
    p.add_argument("--repeats", type=int, default=None, help="timed runs per row (default 5)")
    p.add_argument("--small-repeats", type=int, default=None,
                   help="calls timed one by one for the 1-configuration API rows "
                        "(default 20000; --quick 200)")
    p.add_argument("--quick", action="store_true", help="small sizes and short runs (smoke test)")
    p.add_argument("--no-numpy", action="store_true", help="skip the numpy FK rows")
    p.add_argument("--no-pinocchio", action="store_true", help="skip the pinocchio rows")
    p.add_argument("--json", default=None, metavar="PATH", help="also write the rows as JSON")
    return p.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    Bench(parse_args(argv)).run()
    return 0


if __name__ == "__main__":
    sys.exit(main())
