"""The kinematics *Data*: :class:`KinematicsData`, a workspace of one batch size that holds
every buffer of FK and of frame Jacobians and their recorded kernel launches, reused across
calls (pinocchio / MuJoCo Warp style: the Model is the
:class:`~jwarp.core.device.DeviceModel` of :func:`~jwarp.core.device.put_model`).

    m = put_model(jwarp.robot("justin19"), "cuda:0", np.float32)
    d = KinematicsData(m, batch=1024)
    frames = forward_kinematics(m, d, q)          # d.frames, (1024, n_frames) mat44
    J = frame_jacobian(m, d, "right_tcp", q)      # d.jacobian, (1024, 6, n_dof)

A second call with new q allocates nothing and returns the same buffer, overwritten: copy
a result you want to keep before the next call. One data must not be used from two threads
at once.

This module also builds the argument lists of the FK and Jacobian kernels
(:func:`fk_inputs`, :func:`jacobian_inputs`, :func:`point_vec`, :data:`POINT_ARG`), shared
by every launch of them (:mod:`~jwarp.kinematics.launch` re-exports them)."""

from __future__ import annotations

import math
import numbers
from typing import Any, cast

import numpy as np
import warp as wp

from jwarp.core.arrays import finite_as, real_array
from jwarp.core.device import DeviceModel, numpy_dtype
from jwarp.core.types import ArrayLike
from jwarp.kernels import fk as fk_kernels

__all__ = ["KinematicsData", "forward_kinematics", "frame_jacobian", "frame_dh_jacobian",
           "fk_inputs", "jacobian_inputs", "point_vec", "POINT_ARG", "ORIGIN"]

#: the point of a Jacobian when none is given: the frame's origin [m]
ORIGIN = (0.0, 0.0, 0.0)


# ------------------------------------------------------------ kernel arguments
def fk_inputs(t: DeviceModel, q: wp.array, dh: tuple[wp.array, int] | None) -> list:
    """Inputs of the FK kernels: the frame tables, q (B, n_dof), DH rows and their batch
    stride (None: the nominal tables)."""
    rho, stride = dh if dh is not None else (t.dh0_3d, 0)
    return [t.frame_struct, q, rho, stride, int(dh is not None)]


def point_vec(point: Any, t: DeviceModel) -> Any:
    """A point (3,) [m] in a frame's coordinates as the kernels' vec3 (None: the origin);
    ValueError naming ``point`` unless 3 finite numbers (in the computing dtype)."""
    vec3 = fk_kernels.kernels(t.scalar).vec3
    if point is None:
        return vec3(0.0, 0.0, 0.0)
    p = real_array(point, "point")
    if p.shape != (3,) or not np.all(np.isfinite(p)):
        raise ValueError(f"point: expected 3 finite numbers [m], got {point!r}")
    return vec3(*finite_as(p, numpy_dtype(t.scalar), "point").tolist())


#: position of the point among the arguments of the Jacobian kernels (:func:`jacobian_inputs`)
POINT_ARG = 6


def jacobian_inputs(t: DeviceModel, q: wp.array, dh: tuple[wp.array, int] | None,
                    point: Any, frame: int) -> list:
    """Inputs of the ``jacobian``/``jacobian_dh`` kernels: the frame tables and the chain of
    the frame index, q (B, n_dof), DH rows (None: the nominal ones), the point as
    :func:`point_vec` makes it."""
    rho, stride = dh if dh is not None else (t.dh0_3d, 0)
    return [t.frame_struct, t.chain(frame), q, rho, stride, int(dh is not None), point]


# ------------------------------------------------------------------------ Data
class KinematicsData:
    """Device buffers and recorded launches of FK and frame Jacobians for ``batch``
    configurations of the robot of ``model`` (its device and dtype), reused by every call
    of :func:`forward_kinematics` and :func:`frame_jacobian`.

    Buffers (on ``model.device``, in ``model``'s dtype):

    * ``q`` (batch, n_dof) scalar: joint values [rad or m], the input of every launch;
    * ``frames`` (batch, n_frames) mat44: base_T_frame of every frame [m];
    * ``jacobian`` (batch, 6, n_dof) scalar: rows [linear [m/rad]; angular [rad/rad]] in the
      base frame (made on first use);
    * ``jacobian_dh`` (batch, 6, n_frames, 5) scalar: the same rows w.r.t. every DH
      parameter [d, theta, r, alpha, beta] (made on first use).

    Launches are recorded once (``wp.launch(..., record_cmd=True)``) and replayed: the FK
    launch, and one Jacobian launch per frame whose point is set in place when it changes.

    Raises:
        TypeError: ``model`` is not a :class:`~jwarp.core.device.DeviceModel`, or ``batch``
            is not an integer.
        ValueError: ``batch`` < 1.
    """

    def __init__(self, model: DeviceModel, batch: int) -> None:
        if not isinstance(model, DeviceModel):
            raise TypeError(f"model: expected a DeviceModel (jwarp.core.device.put_model(robot, "
                            f"device, dtype)), got {type(model).__name__}")
        if isinstance(batch, (bool, np.bool_)) or not isinstance(batch, numbers.Integral):
            raise TypeError(f"batch: expected an integer number of configurations, got "
                            f"{type(batch).__name__} {batch!r}")
        if batch < 1:
            raise ValueError(f"batch: expected >= 1 configurations, got {batch}")
        B = int(batch)
        dev, sc = model.device, model.scalar
        self.model: DeviceModel = model
        self.batch: int = B
        self.device: wp.Device = dev
        self.q: wp.array = wp.zeros((B, model.n_dof), dtype=sc, device=dev)
        self.frames: wp.array = wp.zeros((B, model.n_frames),
                                         dtype=fk_kernels.kernels(sc).mat44, device=dev)
        self._jacobian: wp.array | None = None
        self._jacobian_dh: wp.array | None = None
        self._fk_cmd: Any = None
        self._jac_cmds: dict[int, list] = {}   # frame -> [recorded launch, its point tuple]
        self._stage: np.ndarray | None = None  # host side of q (CPU: q's own memory)
        self._stage_arr: wp.array | None = None  # CUDA: the pinned buffer behind _stage
        self._uploaded: Any = None             # CUDA: event after the last upload_q

    def __repr__(self) -> str:
        m = self.model
        return (f"KinematicsData(robot={m.robot.name!r}, batch={self.batch}, "
                f"device={str(self.device)!r}, dtype={m.dtype.name})")

    @property
    def jacobian(self) -> wp.array:
        """(batch, 6, n_dof) scalar: the last Jacobian of :func:`frame_jacobian`."""
        if self._jacobian is None:
            self._jacobian = wp.zeros((self.batch, 6, self.model.n_dof), dtype=self.model.scalar,
                                      device=self.device)
        return self._jacobian

    @property
    def jacobian_dh(self) -> wp.array:
        """(batch, 6, n_frames, 5) scalar: the last DH Jacobian of
        :func:`frame_dh_jacobian` (made on first use)."""
        if self._jacobian_dh is None:
            m = self.model
            self._jacobian_dh = wp.zeros((self.batch, 6, m.n_frames, 5), dtype=m.scalar,
                                         device=self.device)
        return self._jacobian_dh

    # -------------------------------------------------------- recorded launches
    def fk_launch(self) -> Any:
        """The recorded FK launch q -> frames (a ``wp.Launch``; made on first use)."""
        cmd = self._fk_cmd
        if cmd is None:
            m = self.model
            cmd = self._fk_cmd = wp.launch(
                fk_kernels.kernels(m.scalar).fk, dim=self.batch,
                inputs=fk_inputs(m, self.q, None), outputs=[self.frames], device=self.device,
                record_cmd=True)
        return cmd

    def jacobian_launch(self, frame: int, point: Any = None) -> Any:
        """The recorded Jacobian launch q -> jacobian of frame index ``frame`` at ``point``
        (3,) [m] in the frame's coordinates (None: its origin; a tuple of 3 floats that
        :func:`point_vec` made is taken as is), made on first use; the point is set in
        place (``set_param_at_index(POINT_ARG, ...)``) when it differs from the last one."""
        entry = self._jac_cmds.get(frame)
        if entry is not None:
            if type(point) is tuple:
                if point == entry[1]:
                    return entry[0]
            elif point is None and entry[1] == ORIGIN:
                return entry[0]
        m = self.model
        vec = point_vec(point, m)
        key = tuple(vec)
        if entry is None:
            cmd = wp.launch(fk_kernels.kernels(m.scalar).jacobian, dim=self.batch,
                            inputs=jacobian_inputs(m, self.q, None, vec, frame),
                            outputs=[self.jacobian], device=self.device, record_cmd=True)
            self._jac_cmds[frame] = [cmd, key]
            return cmd
        if key != entry[1]:
            entry[0].set_param_at_index(POINT_ARG, vec)
            entry[1] = key
        return entry[0]

    # ------------------------------------------------------------- q upload
    def q_staging(self) -> np.ndarray:
        """The host array (batch, n_dof) a host q is written to before :meth:`upload_q`:
        on the CPU the memory of ``q`` itself (nothing to upload), on CUDA a pinned buffer
        (made on first use). Waits until the previous :meth:`upload_q` has read it."""
        if self._stage is None:
            if self.device.is_cuda:
                self._stage_arr = wp.empty(self.q.shape, dtype=self.model.scalar,
                                           device="cpu", pinned=True)
                self._stage = self._stage_arr.numpy()
            else:
                self._stage = self.q.numpy()
        if self._uploaded is not None:
            wp.synchronize_event(self._uploaded)
            self._uploaded = None
        return self._stage

    def upload_q(self, stream: Any = None, fence: bool = True) -> None:
        """Copy :meth:`q_staging` to ``q`` (CUDA: asynchronously on ``stream``, default the
        device's current stream; CPU: nothing to do). ``fence``: record an event that the
        next :meth:`q_staging` waits on (a caller that synchronizes the stream itself before
        writing the staging again may leave it out)."""
        if not self.device.is_cuda:
            return
        if self._stage_arr is None:
            self.q_staging()
        stream = self.device.stream if stream is None else stream
        wp.copy(self.q, cast(wp.array, self._stage_arr), stream=stream)  # staged above
        if fence:
            self._uploaded = stream.record_event()


def _check_args(m: DeviceModel, d: KinematicsData) -> None:
    if not isinstance(d, KinematicsData):
        raise TypeError(f"d: expected a KinematicsData, got {type(d).__name__}")
    dm = d.model
    if dm is not m:
        if not isinstance(m, DeviceModel):
            raise TypeError(f"m: expected a DeviceModel (jwarp.core.device.put_model), got "
                            f"{type(m).__name__}")
        if (dm.key, dm.device, dm.scalar) != (m.key, m.device, m.scalar):
            raise ValueError(f"d: made for robot '{dm.robot.name}' on {dm.device} in "
                             f"{dm.dtype.name}, not for this model (robot '{m.robot.name}' on "
                             f"{m.device} in {m.dtype.name})")


def _not_finite(a: np.ndarray, source: np.ndarray | None) -> ValueError:
    """The ValueError naming q for a (B, n) array with NaN/inf (``source``: the array it
    was cast from, which tells an overflow of the cast from NaN/inf)."""
    rows = np.nonzero(~np.isfinite(a).all(axis=1))[0][:5].tolist()
    if source is not None and np.isfinite(source).all():
        what = (f"values overflow {a.dtype.name} (largest magnitude "
                f"{float(np.finfo(a.dtype).max):.3g}), the computing dtype")
    else:
        what = "contains NaN or inf"
    return ValueError(f"q: {what} (batch rows {rows})")


def _load_q(m: DeviceModel, d: KinematicsData, q: ArrayLike, validate: bool) -> None:
    """Bring ``q`` into ``d.q`` (see :func:`forward_kinematics`)."""
    want = (d.batch, m.n_dof)
    if q is None:
        if validate:
            a = d.q.numpy()
            if not math.isfinite(a.sum()) and not np.isfinite(a).all():
                raise _not_finite(a, None)
        return
    if isinstance(q, wp.array):
        if tuple(q.shape) != want:
            raise ValueError(f"q: expected shape {want} (batch {d.batch}, robot "
                             f"'{m.robot.name}' has {m.n_dof} joints), got {tuple(q.shape)}")
        if q.dtype != m.scalar:
            raise TypeError(f"q: Warp array of {getattr(q.dtype, '__name__', q.dtype)}, "
                            f"expected {m.dtype.name} (the model's dtype)")
        if q.device != d.device:
            raise ValueError(f"q: Warp array on {q.device}, expected one on {d.device}")
        if validate:
            a = q.numpy()
            if not math.isfinite(a.sum()) and not np.isfinite(a).all():
                raise _not_finite(a, None)
        if q.ptr != d.q.ptr:
            wp.copy(d.q, q)
        return
    a = real_array(q, "q", float64=False)
    if a.shape != want:
        raise ValueError(f"q: expected shape {want} (batch {d.batch}, robot "
                         f"'{m.robot.name}' has {m.n_dof} joints), got {a.shape}")
    host = d.q_staging()
    with np.errstate(over="ignore", invalid="ignore"):
        np.copyto(host, a, casting="unsafe")
    # a finite sum means every value is finite (an overflowing sum of finite values is
    # checked value by value); checked after the cast: 1e39 is inf in float32
    if validate and not math.isfinite(host.sum()) and not np.isfinite(host).all():
        raise _not_finite(host, a)
    d.upload_q()


def _load_dh(m: DeviceModel, d: KinematicsData, dh: Any,
             validate: bool) -> tuple[wp.array, int] | None:
    """The ``dh`` argument as (device rows (1 or batch, n_frames, 5), batch stride); None
    for the nominal rows. A contiguous Warp array of the model's dtype on its device is used
    as is (no copy); anything else is checked and uploaded."""
    if dh is None:
        return None
    n = m.n_frames
    shapes = ((n, 5), (d.batch, n, 5))
    if isinstance(dh, wp.array):
        shape = tuple(dh.shape)
        if shape not in shapes:
            raise ValueError(f"dh: expected shape ({n}, 5) or ({d.batch}, {n}, 5) (n_frames, "
                             f"batch {d.batch}), got {shape}")
        if dh.dtype != m.scalar:
            raise TypeError(f"dh: Warp array of {getattr(dh.dtype, '__name__', dh.dtype)}, "
                            f"expected {m.dtype.name} (the model's dtype)")
        if dh.device != d.device or not dh.is_contiguous:
            raise ValueError(f"dh: expected a contiguous Warp array on {d.device}, got one on "
                             f"{dh.device}" + ("" if dh.is_contiguous else " (not contiguous)"))
        if validate:
            finite_as(dh.numpy(), m.dtype, "dh")
        rows = dh
    else:
        a = real_array(dh, "dh")
        if a.shape not in shapes:
            raise ValueError(f"dh: expected shape ({n}, 5) or ({d.batch}, {n}, 5) (n_frames, "
                             f"batch {d.batch}), got {a.shape}")
        rows = wp.array(finite_as(a, m.dtype, "dh"), dtype=m.scalar, device=d.device)
    return (rows.reshape((1, n, 5)), 0) if rows.ndim == 2 else (rows, 1)


def forward_kinematics(m: DeviceModel, d: KinematicsData, q: Any = None, *, dh: Any = None,
                       validate: bool = True) -> wp.array:
    """Forward kinematics of all frames of the ``batch`` configurations of ``d``.

    Args:
        m: the device model (:func:`~jwarp.core.device.put_model`) ``d`` was made for.
        d: the :class:`KinematicsData` whose buffers and recorded launch are used.
        q: joint values (batch, n_dof) [rad or m]: a numpy array (or anything numpy turns
            into real numbers; cast to the model's dtype), or a Warp array of the model's
            dtype on its device (copied on the device); None: ``d.q`` as already filled.
        dh: DH rows [d, theta, r, alpha, beta] [m, rad] instead of the nominal ones:
            (n_frames, 5) for every configuration or (batch, n_frames, 5) per
            configuration; a contiguous Warp array of the model's dtype on its device is
            used without a copy (the launch is then not the recorded one).
        validate: check q (and dh) for NaN/inf (after the cast; a Warp q or ``d.q`` is
            read back to the host for it).

    Returns:
        ``d.frames``: (batch, n_frames) mat44 base_T_frame [m] of every frame, on the
        model's device. The same array every call, overwritten by the next call.

    Raises:
        ValueError: q or dh of another shape or (``validate``) with NaN/inf, naming the
            argument (a rejected host q may be left in ``d.q``; ``d.frames`` is not
            written); a Warp q or dh on another device; ``d`` made for another model.
        TypeError: a Warp q or dh of another dtype; q or dh not real numbers; ``d`` not a
            :class:`KinematicsData`.
    """
    _check_args(m, d)
    rows = _load_dh(m, d, dh, validate)
    _load_q(m, d, q, validate)
    if rows is None:
        d.fk_launch().launch()
    else:
        wp.launch(fk_kernels.kernels(m.scalar).fk, dim=d.batch, inputs=fk_inputs(m, d.q, rows),
                  outputs=[d.frames], device=d.device)
    return d.frames


def frame_jacobian(m: DeviceModel, d: KinematicsData, frame: int | str, q: Any = None,
                   point: Any = None, *, validate: bool = True) -> wp.array:
    """Geometric Jacobian of ``frame`` (or of a point fixed in it) w.r.t. the joints, for
    the ``batch`` configurations of ``d``.

    Args:
        m, d: as for :func:`forward_kinematics`.
        frame: frame name or index (``m.robot.frame_index``).
        q: joint values (batch, n_dof) [rad or m] as for :func:`forward_kinematics`
            (None: ``d.q`` as already filled).
        point: (3,) [m] in the frame's coordinates (default: its origin).
        validate: check q for NaN/inf.

    Returns:
        ``d.jacobian``: (batch, 6, n_dof) rows [linear velocity; angular velocity] in the
        base frame, on the model's device (coupled passive joints folded into the columns
        of the joints that drive them). The same array every call, overwritten by the next.

    Raises:
        ValueError: an unknown ``frame``, a ``point`` that is not 3 finite numbers, and the
            errors of :func:`forward_kinematics`.
    """
    _check_args(m, d)
    cmd = d.jacobian_launch(m.robot.frame_index(frame), point)
    _load_q(m, d, q, validate)
    cmd.launch()
    return d.jacobian


def frame_dh_jacobian(m: DeviceModel, d: KinematicsData, frame: int | str, q: Any = None,
                      point: Any = None, *, dh: Any = None, validate: bool = True) -> wp.array:
    """Jacobian of ``frame``'s pose (or of a point fixed in it) w.r.t. every DH parameter,
    for the ``batch`` configurations of ``d`` (the calibration's model Jacobian).

    Args:
        m, d: as for :func:`forward_kinematics`.
        frame: frame name or index (``m.robot.frame_index``).
        q: joint values (batch, n_dof) [rad or m] as for :func:`forward_kinematics`.
        point: (3,) [m] in the frame's coordinates (default: its origin).
        dh: DH rows as for :func:`forward_kinematics` (None: the nominal rows).
        validate: check q and dh for NaN/inf.

    Returns:
        ``d.jacobian_dh``: (batch, 6, n_frames, 5) rows [linear; angular] in the base frame,
        columns the DH rows [d, theta, r, alpha, beta] of each frame (zero for frames off
        the chain and for static frames). The same array every call, overwritten by the
        next.

    Raises:
        ValueError / TypeError: as for :func:`forward_kinematics` and :func:`frame_jacobian`.
    """
    _check_args(m, d)
    fi = m.robot.frame_index(frame)
    vec = point_vec(point, m)
    rows = _load_dh(m, d, dh, validate)
    _load_q(m, d, q, validate)
    out = d.jacobian_dh
    out.zero_()
    wp.launch(fk_kernels.kernels(m.scalar).jacobian_dh, dim=d.batch,
              inputs=jacobian_inputs(m, d.q, rows, vec, fi), outputs=[out], device=d.device)
    return out
