"""Building blocks of the kinematics functions: the validated batch and device tables of a
call (:func:`setup`), per-frame rows (:func:`frame_rows`), the FK launch, the small-call
path of fk/jacobian (:func:`small_call`: a cached :class:`Workspace` around a
:class:`~jwarp.kinematics.data.KinematicsData`), and the elastic fixed-point iteration
(:class:`ElasticLaunch`, :func:`equilibrium`). Shared by the public functions
(:mod:`~jwarp.kinematics.fk`, :mod:`~jwarp.kinematics.equilibrium`), torch ops, autodiff
and the calibration. The kernel argument lists (``fk_inputs``, ``jacobian_inputs``,
``point_vec``, ``POINT_ARG``) live in :mod:`~jwarp.kinematics.data` and are re-exported
here."""

from __future__ import annotations

import math
import sys
import threading
from typing import Any, NamedTuple, cast

import numpy as np
import warp as wp

from jwarp.core.arrays import (
    Batch,
    HostWrap,
    as_batch,
    default_dtype,
    empty,
    finite_as,
    first_touch,
    init_warp,
    is_torch,
    real_array,
    real_number,
    resolve_device,
)
from jwarp.core.device import DeviceModel, numpy_dtype, put_model, scalar_type
from jwarp.core.types import ArrayLike, DeviceLike, DTypeLike
from jwarp.kernels import elastic as elastic_kernels
from jwarp.kernels import fk as fk_kernels
from jwarp.kinematics.data import (  # noqa: F401  (POINT_ARG, jacobian_inputs: re-exported)
    ORIGIN,
    POINT_ARG,
    KinematicsData,
    fk_inputs,
    jacobian_inputs,
    point_vec,
)
from jwarp.model import RobotModel
from jwarp.utils.checks import check_int


def setup(robot: RobotModel, q: ArrayLike, device: DeviceLike, dtype: DTypeLike, validate: bool = True
           ) -> tuple[RobotModel, Batch, DeviceModel]:
    init_warp()
    model = robot
    dev = resolve_device(device, like=q)
    dt = default_dtype(q) if dtype is None else dtype
    batch = as_batch(q, model.n_dof, "q", device=dev, dtype=dt,
                     what=f"robot '{model.name}' has {model.n_dof} joints", validate=validate)
    return model, batch, put_model(model, dev, dt)


def frame_rows(x: ArrayLike, model: RobotModel, batch: Batch, t: DeviceModel, name: str,
               width: int) -> tuple[wp.array, int]:
    """Per-frame rows (n_frames, width) shared, or (..., n_frames, width) per configuration,
    as a (B or 1, n_frames, width) device array and its batch stride (0: shared). Internal
    building block of the elastic kinematics, shared with torch_ops, autodiff and the
    calibration; ValueError/TypeError name ``name``."""
    npdt = numpy_dtype(t.scalar)
    a = real_array(x, name)
    if a.shape[-2:] != (model.n_frames, width):
        raise ValueError(f"{name}: expected shape (n_frames={model.n_frames}, {width}) or "
                         f"(batch..., {model.n_frames}, {width}), got {a.shape}")
    if a.ndim == 2:
        return wp.array(finite_as(a[None], npdt, name), dtype=t.scalar, device=t.device), 0
    if a.shape[:-2] != tuple(batch.lead_shape):
        raise ValueError(f"{name}: batch dims {a.shape[:-2]} do not match q's {tuple(batch.lead_shape)}")
    a = finite_as(a.reshape(-1, model.n_frames, width), npdt, name)
    return wp.array(a, dtype=t.scalar, device=t.device), 1


def launch_fk(t: DeviceModel, q: wp.array, dh: tuple[wp.array, int] | None = None,
              frames: wp.array | None = None, frame_major: bool = False,
              component_major: bool = False) -> wp.array:
    """Launch the FK kernel on a (B, n_dof) device array; returns frames (B, n_frames) mat44.

    ``frame_major`` stores the output frame-major in memory (a transposed view), which
    coalesces the stores on CUDA; the returned array is indexed [b, i] either way.
    ``component_major`` returns a scalar (B, n_frames, 4, 4) view of memory laid out
    (n_frames, 4, 4, B) (the batch index fastest: every warp store is one coalesced line on
    CUDA); ``wp.to_torch`` gives a strided (B, n_frames, 4, 4) tensor without a copy.
    """
    k = fk_kernels.kernels(t.scalar)
    B = q.shape[0]
    n = t.robot.n_frames
    inputs = fk_inputs(t, q, dh)
    if component_major:
        if frames is not None and (frames.ndim != 4 or frames.dtype != t.scalar
                                   or tuple(frames.shape) != (B, n, 4, 4)):
            raise ValueError(f"frames: component_major needs a scalar ({B}, {n}, 4, 4) array "
                             f"of {t.scalar.__name__}, got shape {tuple(frames.shape)} of "
                             f"{getattr(frames.dtype, '__name__', frames.dtype)}")
        done = None
        if frames is None:
            frames = empty((n, 4, 4, B), t.scalar, t.device).transpose((3, 0, 1, 2))
            done = first_touch(frames)
        wp.launch(k.fk_components, dim=B, inputs=inputs, outputs=[frames], device=t.device)
        if done is not None:
            done()
        return frames
    done = None
    if frames is None:
        if frame_major:
            frames = empty((n, B), k.mat44, t.device).transpose()
        else:
            frames = empty((B, n), k.mat44, t.device, requires_grad=q.requires_grad)
        done = first_touch(frames)
    wp.launch(k.fk, dim=B, inputs=inputs, outputs=[frames], device=t.device)
    if done is not None:
        done()
    return frames


# ----------------------------------------------------------------- small calls
#: a call whose result has at most this many bytes may use a :class:`Workspace`
SMALL_CALL_BYTES = 1 << 18
#: most workspaces kept per process (the oldest is dropped first)
SMALL_CALL_WORKSPACES = 32
_SMALL_DTYPES = (np.dtype(np.float32), np.dtype(np.float64))


class Workspace:
    """A :class:`~jwarp.kinematics.data.KinematicsData` (device buffers and recorded
    launches) of one (device tables of a robot, batch size) serving repeated small calls:
    a call copies q into the data's input buffer, replays its recorded launch (FK, or the
    Jacobian of a frame: no argument packing, no allocation) and copies the result out:
    the caller's array never aliases the workspace. On CUDA the host side goes through
    pinned staging buffers.

    One call at a time: a call that finds the workspace busy (another thread) returns None
    and the caller takes the general path, so concurrent calls stay correct."""

    def __init__(self, t: DeviceModel, B: int):
        self.t = t
        self.data = KinematicsData(t, B)
        self.cuda = t.device.is_cuda
        self.q_host = self.data.q_staging()   # CUDA: pinned; CPU: the data's q itself
        # op -> (device output, its host side, CUDA: the pinned staging of it)
        self.outs: dict[str, tuple[wp.array, np.ndarray, wp.array | None]] = {}
        self.lock = threading.Lock()

    def _out(self, op: str) -> tuple[wp.array, np.ndarray, wp.array | None]:
        """The device output of ``op``, its host side and staging (made on first use)."""
        dev_out = self.data.frames if op == "fk" else self.data.jacobian
        stage = None
        if self.cuda:
            stage = wp.empty(dev_out.shape, dtype=dev_out.dtype, device="cpu", pinned=True)
            host = stage.numpy()
        else:
            host = dev_out.numpy()
        res = self.outs[op] = (dev_out, host, stage)
        return res

    def run(self, op: str, q: np.ndarray, validate: bool, out: np.ndarray | None = None,
            frame: int = -1, point: tuple | None = None) -> np.ndarray | None:
        """The result of ``op`` ("fk", or "jacobian" of frame index ``frame`` at ``point``,
        3 floats from :func:`point_vec`, None: the origin) for q (B, n_dof) as a new array
        (or copied into ``out``); None when busy or (``validate``) q is not finite after
        the cast: the general path then reports it."""
        if not self.lock.acquire(blocking=False):
            return None
        try:
            d = self.data
            cmd = d.fk_launch() if op == "fk" else d.jacobian_launch(frame, point)
            dev_out, out_host, stage = self.outs.get(op) or self._out(op)
            np.copyto(self.q_host, q, casting="unsafe")
            # a finite sum means every value is finite; an overflowing sum of finite
            # values takes the general path, which checks value by value
            if validate and not math.isfinite(self.q_host.sum()):
                return None
            if self.cuda:
                stream = self.t.device.stream
                d.upload_q(stream, fence=False)   # synchronized below
                cmd.launch(stream)
                wp.copy(stage, dev_out, stream=stream)
                wp.synchronize_stream(stream)
            else:
                cmd.launch()
            if out is None:
                return out_host.copy()
            np.copyto(out, out_host.reshape(out.shape))
            return out
        finally:
            self.lock.release()


_WORKSPACES: dict = {}
_WORKSPACES_LOCK = threading.Lock()


def workspace(t: DeviceModel, B: int) -> Workspace:
    """The cached :class:`Workspace` for batch size ``B`` on the tables ``t`` (made on
    first use; per process)."""
    key = (id(t), B)
    ws = _WORKSPACES.get(key)
    if ws is not None and ws.t is t:
        return ws
    ws = Workspace(t, B)
    with _WORKSPACES_LOCK:
        _WORKSPACES[key] = ws   # holds t: its id is not reused while the entry lives
        while len(_WORKSPACES) > SMALL_CALL_WORKSPACES:
            del _WORKSPACES[next(iter(_WORKSPACES))]
    return ws


def clear_workspaces() -> int:
    """Drop every cached :class:`Workspace` (their memory is freed once no call uses them);
    returns how many there were. Later small calls make new ones."""
    with _WORKSPACES_LOCK:
        n = len(_WORKSPACES)
        _WORKSPACES.clear()
        _CALLS.clear()
    return n


class SmallCall(NamedTuple):
    """What a small call of one signature resolved once (see :func:`small_call`): the
    robot, the workspace, the batch, the result's shape and dtype, the frame and point of
    a Jacobian, whether q is cast to a narrower dtype, and (Warp input) the wrapper of the
    results as Warp arrays."""

    model: RobotModel
    ws: Workspace
    B: int
    want: tuple
    npdt: np.dtype
    frame: int
    point: tuple | None
    narrowing: bool
    wrap: HostWrap | None


#: (op, robot id, device alias, dtype argument, input kind, q dtype, q shape, frame, point)
#: -> :class:`SmallCall`; cleared with the workspaces
_CALLS: dict = {}


def _resolve_small(op: str, model: RobotModel, q: Any, qa: np.ndarray, warp_in: bool,
                   dev: wp.Device, dtype: DTypeLike, frame: Any, point: Any) -> SmallCall | None:
    """The :class:`SmallCall` of a signature, or None where the general path must run."""
    if qa.dtype not in _SMALL_DTYPES or qa.ndim == 0:
        return None
    n = model.n_dof
    shape = qa.shape
    if shape[-1] != n or qa.size == 0:
        return None
    B = qa.size // n
    npdt = qa.dtype if dtype is None else numpy_dtype(scalar_type(dtype))
    if warp_in and (npdt != qa.dtype or dev != q.device):
        return None   # the general path raises / moves q
    tail = (model.n_frames, 4, 4) if op == "fk" else (6, n)
    if B * (tail[0] * 16 if op == "fk" else 6 * n) * npdt.itemsize > SMALL_CALL_BYTES:
        return None
    t = put_model(model, dev, npdt)
    if op == "fk":
        fi, pt = -1, None
    else:
        fi = model.frame_index(frame)
        pt = ORIGIN if point is None else tuple(point_vec(point, t))
    ws = workspace(t, B)
    want = shape[:-1] + tail
    wrap = None
    if warp_in:
        wdt = fk_kernels.kernels(t.scalar).mat44 if op == "fk" else t.scalar
        lead = shape[:-1] + ((model.n_frames,) if op == "fk" else (6, n))
        wrap = HostWrap(lead + ((4, 4) if op == "fk" else ()), npdt, wdt)
    return SmallCall(model, ws, B, want, npdt, fi, pt, npdt.itemsize < qa.itemsize, wrap)


def small_call(op: str, robot: RobotModel, q: Any, device: DeviceLike, dtype: DTypeLike, validate: bool,
               out: Any = None, frame: int | str | None = None, point: Any = None) -> Any:
    """The fast path of :func:`~jwarp.kinematics.fk.fk` (``op`` "fk") and
    :func:`~jwarp.kinematics.jacobians.jacobian` ("jacobian") for a small batch of float32/
    float64 q: a numpy array, a CPU torch tensor without grad or a contiguous Warp CPU array
    without grad, through a cached :class:`Workspace`. What a call signature needs (robot
    tables, workspace, shapes) is resolved once and kept (:class:`SmallCall`), so a repeated
    call costs a copy of q, the recorded launch and a copy of the result. Returns None
    wherever the general path must run instead: other inputs, large results, a busy
    workspace, a non-finite q, an ``out`` that is not a fitting numpy array (the general
    path then raises its usual errors)."""
    tq = type(q)
    warp_in = False
    if tq is np.ndarray:
        qa = q
    elif tq is wp.array:
        if out is not None or q.requires_grad or not q.is_contiguous or not q.device.is_cpu:
            return None
        try:
            qa = np.asarray(q)
        except (TypeError, ValueError, AttributeError):
            return None
        warp_in = True
    elif is_torch(q):
        try:   # raises for a tensor that requires grad or is not on the CPU
            qa = q.numpy()
        except (RuntimeError, TypeError):
            return None
        if device is None:   # q's device (resolve_device), here the CPU: no torch lookup
            device = "cpu"
    else:
        return None
    model = robot
    try:   # any error: the general path raises it, in its order
        dev = resolve_device(device, like=q)
        key = None
        if point is None or type(point) is tuple:   # else: resolved per call
            try:
                key = (op, id(model), dev.alias, dtype, warp_in, qa.dtype, qa.shape, frame,
                       point)
                call = _CALLS.get(key)
            except TypeError:   # an unhashable argument: resolved per call
                key = call = None
        else:
            call = None
        if call is None or call.model is not model:
            call = _resolve_small(op, model, q, qa, warp_in, dev, dtype, frame, point)
            if call is None:
                return None
            if key is not None:
                with _WORKSPACES_LOCK:
                    _CALLS[key] = call   # holds the model: its id is not reused meanwhile
                    while len(_CALLS) > 4 * SMALL_CALL_WORKSPACES:
                        del _CALLS[next(iter(_CALLS))]
        if out is not None and not (type(out) is np.ndarray and out.shape == call.want
                                    and out.dtype == call.npdt and out.flags.c_contiguous
                                    and out.flags.writeable):
            return None
    except (ValueError, TypeError):
        return None
    q2 = qa.reshape(call.B, model.n_dof)
    wrap = cast(HostWrap, call.wrap)   # set for Warp input
    if warp_in:   # the result is written to a new Warp array's memory
        out, ptr = wrap.take()
    if call.narrowing:   # float64 q computed in float32: overflow -> inf
        with np.errstate(over="ignore", invalid="ignore"):
            res = call.ws.run(op, q2, validate, out, call.frame, call.point)
    else:
        res = call.ws.run(op, q2, validate, out, call.frame, call.point)
    if warp_in:
        return None if res is None else wrap.wrap(res, ptr)
    if res is None or out is not None:
        return res
    if tq is not np.ndarray:
        return sys.modules["torch"].from_numpy(res.reshape(call.want))
    return res.reshape(call.want)


#: default tolerance of :func:`fk_elastic` [rad] per computing dtype: float64 stops at
#: 1e-9 rad; float32 at 4 float32 epsilons (2^-21 = 4.8e-7 rad, two float32 steps of a DH
#: angle near pi), the resolution its rows can reach (a row of magnitude 2..4 rad moves
#: in steps of 2.4e-7 rad, so the updates of many configurations never fall below 1e-9)
ELASTIC_TOL = {np.dtype(np.float64): 1e-9, np.dtype(np.float32): 4 * float(np.finfo(np.float32).eps)}


def default_tol(dtype: DTypeLike) -> float:
    """The default tolerance of :func:`fk_elastic` [rad] for the computing ``dtype``."""
    return ELASTIC_TOL[numpy_dtype(scalar_type(dtype))]


class ElasticFK(NamedTuple):
    """Result of :func:`fk_elastic`.

    frames (..., n_frames, 4, 4); rho (..., n_frames, 5) equilibrium DH rows
    [d, theta, r, alpha, beta]; iterations (...,) int torque updates used per configuration;
    converged (...,) bool: last update changed rho by less than ``tol`` [rad] and every
    frame and row is finite (a diverged iteration, e.g. an enormous kappa, is never
    converged; :attr:`diverged` says so).
    """

    frames: Any
    rho: Any
    iterations: Any
    converged: Any

    @property
    def diverged(self) -> np.ndarray:
        """(...,) bool numpy: the iteration left finite numbers (NaN or inf frames)."""
        f = self.frames
        if isinstance(f, wp.array):
            f = f.numpy()
        elif hasattr(f, "detach"):
            f = f.detach().cpu().numpy()
        f = np.asarray(f)
        return ~np.isfinite(f).all(axis=(-1, -2, -3))


class ElasticStep(NamedTuple):
    """Result of :func:`elastic_step`: frames at the given rho, the updated rho, and the
    largest change of rho per configuration [rad]."""

    frames: Any
    rho: Any
    delta: Any


def kappa_array(model: RobotModel, kappa: Any) -> np.ndarray:
    """Expand ``kappa`` to (n_frames, 3) or (..., n_frames, 3) [rad/(N m)].

    Accepts a scalar (all three axes of every DH frame), 3 values [alpha, beta, theta]
    for every DH frame, a (n_frames, 3) table or per-configuration tables.
    ``None`` uses the robot's own ``kappa``.
    """
    if kappa is None:
        return model.kappa
    if getattr(kappa, "requires_grad", False):
        raise TypeError("kappa: a torch tensor that requires grad: jwarp differentiates the "
                        "elastic kinematics w.r.t. q only, so its gradient would silently stay "
                        "None; pass kappa.detach() (d/dkappa: jwarp.kinematics.autodiff)")
    k = real_array(kappa, "kappa")
    if not np.all(np.isfinite(k)):
        raise ValueError("kappa: contains NaN or inf")
    if np.any(k < 0):
        raise ValueError("kappa: compliances must be >= 0 rad/(N m)")
    mask = model.is_dh.astype(np.float64)[:, None]
    if k.ndim == 0:
        return np.full((model.n_frames, 3), float(k)) * mask
    if k.shape == (3,):
        return np.tile(k, (model.n_frames, 1)) * mask
    if k.shape[-2:] == (model.n_frames, 3):
        return k
    raise ValueError(f"kappa: expected a scalar, 3 values [alpha, beta, theta], or shape "
                     f"(..., {model.n_frames}, 3); got {k.shape}")


class ElasticLaunch:
    """Buffers and launches of the torque-equilibrium iteration for one batch (internal
    building block of :func:`fk_elastic`, shared with torch_ops, autodiff and the
    calibration's signed equilibrium; optimizers use :mod:`jwarp.kinematics.compensation`)."""

    def __init__(self, t: DeviceModel, q: wp.array, kappa: tuple[wp.array, int],
                 rho0: tuple[wp.array, int] | None, lam: float, write_tau: bool = False,
                 requires_grad: bool = False):
        self.t, self.q, self.kappa, self.lam = t, q, kappa, lam
        self.rho0 = rho0 if rho0 is not None else (t.dh0_3d, 0)
        self.nominal_start = rho0 is None
        self.k = elastic_kernels.kernels(t.scalar)
        self.fk = fk_kernels.kernels(t.scalar)
        B, n = q.shape[0], t.robot.n_frames
        self.B, self.n = B, n
        self.write_tau = write_tau
        self.requires_grad = requires_grad
        self.tau = wp.zeros((B if write_tau else 1, n, 3), dtype=t.scalar, device=t.device)
        g = t.robot.gravity
        self.gravity = self.fk.vec3(float(g[0]), float(g[1]), float(g[2]))

    def _rho_buffer(self, requires_grad: bool = False) -> wp.array:
        """A (B, n, 5) rho buffer whose static-frame rows hold the nominal rows (the step
        kernel writes only the DH rows)."""
        t = self.t
        out = empty((self.B, self.n, 5), t.scalar, t.device, requires_grad=requires_grad)
        if t.static_idx.shape[0]:
            wp.launch(self.k.fill_static_rows, dim=(self.B, t.static_idx.shape[0]),
                      inputs=[t.dh0, t.static_idx], outputs=[out], device=t.device)
        return out

    def step(self, rho: tuple[wp.array, int] | None, frames: wp.array | None = None
             ) -> tuple[wp.array, wp.array, wp.array]:
        """One update from ``rho`` (None: the nominal/rho0 rows). Returns frames at rho,
        the new rho (B, n, 5) and delta (B,)."""
        t, B, n = self.t, self.B, self.n
        rg = self.requires_grad
        if rg:  # the tape needs every intermediate kept
            frames = frames if frames is not None else wp.empty((B, n), dtype=self.fk.mat44,
                                                                device=t.device, requires_grad=True)
            moments = wp.empty((n + 1, B), dtype=self.k.vec4, device=t.device, requires_grad=True)
            axes = wp.empty((n, B), dtype=self.fk.vec3, device=t.device, requires_grad=True)
            rho_out = self._rho_buffer(requires_grad=True)
            delta = wp.empty(B, dtype=t.scalar, device=t.device)
        else:  # reuse scratch; rho ping-pongs between two buffers
            if not hasattr(self, "_scratch"):
                S = 1 if t.device.is_cpu else B  # CPU threads run configurations in turn
                self._scratch = (empty((B, n), self.fk.mat44, t.device),
                                 wp.empty((n + 1, S), dtype=self.k.vec4, device=t.device),
                                 wp.empty((n, S), dtype=self.fk.vec3, device=t.device),
                                 [self._rho_buffer() for _ in range(2)],
                                 wp.empty(B, dtype=t.scalar, device=t.device))
            frames_s, moments, axes, rho_bufs, delta = self._scratch
            frames = frames if frames is not None else frames_s
            rho_out = rho_bufs[0] if rho is None or rho[0] is not rho_bufs[0] else rho_bufs[1]
        if rho is None:
            if self.nominal_start:
                rho_arr, stride, use = t.dh0_3d, 0, 0
            else:
                (rho_arr, stride), use = self.rho0, 1
        else:
            (rho_arr, stride), use = rho, 1
        wp.launch(self.k.elastic_step, dim=B,
                  inputs=[t.frame_struct, t.mass, t.mass_com, t.dh_info, t.kappa_nl,
                          self.q, rho_arr, stride, use, self.rho0[0], self.rho0[1],
                          self.kappa[0], self.kappa[1], self.lam, self.gravity,
                          int(self.write_tau), int(moments.shape[1] > 1)],
                  outputs=[frames, moments, axes, rho_out, self.tau, delta], device=t.device)
        return frames, rho_out, delta

    def frames_at(self, rho: tuple[wp.array, int] | None, out: wp.array | None = None
                  ) -> wp.array:
        """Frames at ``rho`` (None: rho0) into ``out`` (B, n_frames) mat44 (default new)."""
        if rho is None and not self.nominal_start:
            rho = self.rho0
        if out is None and self.requires_grad:
            out = empty((self.B, self.n), self.fk.mat44, self.t.device, requires_grad=True)
        return launch_fk(self.t, self.q, dh=rho, frames=out)


def lam_tol(lam: Any, tol: Any, t: DeviceModel) -> tuple[float, float]:
    """Validated damping and tolerance as floats; ``tol`` None is :func:`default_tol` of
    the tables' dtype."""
    lam = real_number(lam, "lam")
    if not 0.0 < lam <= 1.0:
        raise ValueError(f"lam: damping must be in (0, 1], got {lam!r}")
    tol = default_tol(numpy_dtype(t.scalar)) if tol is None else real_number(tol, "tol")
    if not (tol >= 0 and np.isfinite(tol)):
        raise ValueError(f"tol: expected a finite number >= 0 [rad], got {tol!r}")
    return lam, tol


def check_max_iter(max_iter: Any) -> int:
    """``max_iter`` of the elastic iteration as an int; ValueError unless an integer >= 0."""
    return check_int(max_iter, "max_iter", 0)
    return int(max_iter)


def elastic_args(robot: RobotModel, q: Any, kappa: Any, lam: float, max_iter: int, tol: float | None,
                  dh: Any, device: DeviceLike, dtype: DTypeLike, validate: bool):
    """Validated arguments of the elastic functions: (model, batch, tables, kappa rows,
    rho0 rows or None); lam and tol as :func:`lam_tol` checks them."""
    model, batch, t = setup(robot, q, device, dtype, validate)
    lam_tol(lam, tol, t)
    check_max_iter(max_iter)
    kap = frame_rows(kappa_array(model, kappa), model, batch, t, "kappa", 3)
    rho0 = None if dh is None else frame_rows(dh, model, batch, t, "dh", 5)
    return model, batch, t, kap, rho0


def equilibrium(run: ElasticLaunch, max_iter: int, tol: float, frames: wp.array | None = None):
    """Run the damped iteration; returns (rho or None, frames at rho, iterations, converged).

    ``converged``: an update changed no row by more than ``tol``. With ``max_iter`` 0 the
    frames stay rigid (at rho0) and one update is made only to measure whether rho0 already
    is the equilibrium to ``tol`` (its result is discarded). ``frames``: optional
    (B, n_frames) mat44 array the final frames are written to."""
    iterations = np.zeros(run.B, np.int32)
    converged = np.zeros(run.B, bool)
    rho = None
    for _ in range(max_iter):
        _, rho_new, delta = run.step(rho)
        iterations += ~converged
        rho = (rho_new, 1)
        converged |= delta.numpy() <= tol
        if converged.all():
            break
    if max_iter == 0:
        converged |= run.step(None)[2].numpy() <= tol
    frames = run.frames_at(rho, frames)
    # a non-finite iterate has not converged, however small its last change looked (the
    # iteration diverged: NaN comparisons pass silently in the kernels' max)
    finite = np.isfinite(frames.numpy()).reshape(run.B, -1).all(axis=1)
    if rho is not None:
        finite &= np.isfinite(rho[0].numpy()).reshape(run.B, -1).all(axis=1)
    converged &= finite
    return rho, frames, iterations, converged


def rho0_full(run: ElasticLaunch) -> wp.array:
    arr, stride = run.rho0
    if stride:
        return arr
    a = np.broadcast_to(arr.numpy(), (run.B, run.n, 5)).copy()
    return wp.array(a, dtype=run.t.scalar, device=run.t.device)


def host_out(a: np.ndarray, batch: Batch) -> Any:
    a = a.reshape(tuple(batch.lead_shape))
    if batch.kind == "torch":
        import torch

        return torch.from_numpy(a).to(batch.torch_tensor.device)
    return a


