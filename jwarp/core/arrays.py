"""Array plumbing shared by the public API: numpy / warp / torch in, the same kind out.

Inputs are flattened to a batch ``(B, n)``; outputs are reshaped back to the caller's
leading batch dimensions. Torch tensors and Warp arrays are shared zero-copy. Outputs:
:func:`empty`/:func:`zeros` (large CPU arrays on numpy memory), :func:`first_touch` (their
pages faulted in on a second core while the kernel runs), :func:`out_view` (a caller's
``out=`` checked and shared with the kernel), :func:`to_output`.
"""

from __future__ import annotations

import ctypes
import errno
import math
import mmap
import sys
import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, cast

import numpy as np
import warp as wp

from jwarp.core.device import numpy_dtype, scalar_type
from jwarp.core.kernel_cache import ensure_cache_dir, install_compile_notice
from jwarp.core.types import ArrayLike, DeviceLike, DTypeLike
from jwarp.utils.checks import (
    real_number as real_number,  # its home; imported from here too
)
from jwarp.utils.warp_init import init_quietly

_INITIALISED = False


def init_warp() -> None:
    """Initialise Warp once, quietly."""
    global _INITIALISED
    if not _INITIALISED:
        wp.config.quiet = True
        if hasattr(wp, "LOG_WARNING"):  # Warp >= 1.1x logs through log_level
            wp.config.log_level = max(wp.config.log_level, wp.LOG_WARNING)
        ensure_cache_dir()  # an unusable WARP_CACHE_PATH: a warning and a temporary cache
        init_quietly()  # wp.init() without the "CUDA driver not found" line (no CUDA)
        install_compile_notice()  # one stderr line when jwarp's kernels compile (issue 27)
        _INITIALISED = True


def is_torch(x: ArrayLike) -> bool:
    mod = type(x).__module__
    return mod.startswith("torch") and hasattr(x, "detach")


def resolve_device(device: DeviceLike, *inputs: Any, like: Any = None) -> wp.Device:
    """THE device rule of every public jwarp function and solver (docs/api.md, "Devices").

    ``device`` given ("cpu", "cuda:0", a ``wp.Device`` or a torch device): that device.
    ``device=None``: the device of the first of ``like`` and ``inputs`` that has one, a
    Warp array or a torch tensor (its memory's device), or a device object of jwarp (a
    :class:`~jwarp.core.device.DeviceModel`, a data, a solver: anything whose ``device``
    attribute is a ``wp.Device``); else Warp's default device (``wp.get_device()``: CUDA
    when present, else the CPU, unless ``wp.set_device``/``wp.ScopedDevice`` chose
    another), as in Newton, MuJoCo Warp and :func:`~jwarp.core.device.put_model`.

    Why the default device and not always "cpu" for host inputs: a Warp or cuRobo user
    expects the GPU when there is one, the CPU results are those of the CPU (a machine
    without CUDA computes exactly what it computed before), and the same call of a solver
    function and of its solver class (``ik``/``IKSolver``, ``plan``/``Planner``) runs on the
    same device. Pass ``device="cpu"`` for small problems on a CUDA machine.

    Resolved devices of a name are cached ("cpu", "cuda:0": no string parsing per call;
    a bare "cuda" follows the current CUDA device and is looked up each time).

    Raises:
        ValueError: naming ``device`` for an unknown or unavailable device.
    """
    if not _INITIALISED:
        init_warp()
    if device is None:
        for x in (like, *inputs):
            if x is None:
                continue
            d = getattr(x, "device", None)
            if isinstance(d, wp.Device):
                return d
            if d is not None and is_torch(x):
                if d.type == "cpu":
                    return _cpu()
                return wp.device_from_torch(d)
        return wp.get_device()
    if isinstance(device, wp.Device):
        return device
    try:
        dev = _DEVICES.get(device)
    except TypeError:   # unhashable: reported below
        dev = None
    if dev is not None:
        return dev
    try:
        dev = wp.get_device(str(device))
    except Exception as e:  # warp raises RuntimeError/ValueError for unknown devices
        raise ValueError(f"device: unknown or unavailable device {device!r}: {e}") from e
    if str(device) == dev.alias:   # "cpu", "cuda:0": always the same device
        _DEVICES[device] = dev
    return dev


def device_name(device: DeviceLike, *inputs: Any) -> str:
    """The device of :func:`resolve_device` by name ("cpu", "cuda:0"): for torch
    (``torch.device(name)``, ``module.to(name)``) and for cache keys."""
    return resolve_device(device, *inputs).alias


#: devices resolved from their names (see :func:`resolve_device`)
_DEVICES: dict = {}


def _cpu() -> wp.Device:
    dev = _DEVICES.get("cpu")
    if dev is None:
        dev = _DEVICES["cpu"] = wp.get_device("cpu")
    return dev


@dataclass
class Batch:
    """A validated input flattened to (B, n) on the compute device."""

    array: wp.array            # (B, n) on the compute device, compute dtype
    lead_shape: tuple          # caller's leading batch dims
    kind: str                  # "numpy" | "warp" | "torch"
    torch_tensor: Any = None   # original torch tensor (for autograd)

    @property
    def size(self) -> int:
        return self.array.shape[0]


def as_batch(x: Any, n: int, name: str, *, device: wp.Device, dtype: DTypeLike,
             what: str, validate: bool = True) -> Batch:
    """Validate ``x`` (shape (..., n)) and bring it to ``device``/``dtype`` as (B, n)."""
    scalar = scalar_type(dtype)
    npdt = numpy_dtype(scalar)
    if isinstance(x, wp.array):
        shape = tuple(x.shape)
        _check_shape(shape, n, name, what)
        if x.dtype != scalar:
            raise TypeError(f"{name}: warp array dtype {x.dtype.__name__} does not match "
                            f"dtype {np.dtype(npdt).name}")
        if validate:
            _check_finite(x.numpy(), name)
        arr = x if x.device == device else x.to(device)
        if not arr.is_contiguous:
            arr = arr.contiguous()
        if arr.ndim != 2:  # a Warp reshape makes a new array object (microseconds)
            arr = arr.reshape((-1, n))
        return Batch(arr, shape[:-1], "warp")
    if is_torch(x):
        import torch

        shape = tuple(x.shape)
        _check_shape(shape, n, name, what)
        if not x.is_floating_point():
            raise TypeError(f"{name}: expected a floating point tensor, got {x.dtype}")
        t = x.detach().reshape(-1, n).to(dtype=getattr(torch, np.dtype(npdt).name)).contiguous()
        if validate and not bool(torch.isfinite(t).all()):  # after the cast (overflow)
            bad = torch.nonzero(~torch.isfinite(t).all(dim=1))[:5].flatten().tolist()
            raise ValueError(f"{name}: {_not_finite(bool(torch.isfinite(x).all()), npdt)} "
                             f"(batch rows {bad})")
        arr = cast(wp.array, wp.from_torch(t, dtype=scalar))
        if arr.device != device:
            arr = arr.to(device)
        return Batch(arr, shape[:-1], "torch", torch_tensor=x)
    a = real_array(x, name, float64=False)
    _check_shape(a.shape, n, name, what)
    with np.errstate(over="ignore", invalid="ignore"):  # overflow is reported below
        if device.is_cpu:  # one copy, by numpy (never the caller's q), shared with Warp
            a2 = np.array(a.reshape(-1, n), dtype=npdt, order="C")
        else:  # the upload copies
            a2 = np.ascontiguousarray(a.reshape(-1, n), dtype=npdt)
    if validate:  # after the cast: 1e39 is finite in float64, inf in float32
        _check_finite(a2, name, a)
    return Batch(wp.array(a2, dtype=scalar, device=device, copy=not device.is_cpu),
                 a.shape[:-1], "numpy")


def _check_shape(shape: tuple, n: int, name: str, what: str) -> None:
    if len(shape) == 0 or shape[-1] != n:
        raise ValueError(f"{name}: expected shape (..., {n}) ({what}), got {shape}")
    if int(np.prod(shape[:-1])) == 0:
        raise ValueError(f"{name}: empty batch, shape {shape}")


def _not_finite(source_finite: bool, npdt: Any) -> str:
    if source_finite:
        return (f"values overflow {np.dtype(npdt).name} (largest magnitude "
                f"{float(np.finfo(npdt).max):.3g}), the computing dtype")
    return "contains NaN or inf"


def _check_finite(a: np.ndarray, name: str, source: np.ndarray | None = None) -> None:
    """ValueError naming ``name`` and the first bad batch rows unless ``a`` (..., n) is
    finite. ``source``: the array ``a`` was cast from (tells overflow from NaN/inf)."""
    finite = np.isfinite(a)
    if not finite.all():
        rows = np.nonzero(~finite.reshape(-1, a.shape[-1]).all(axis=1))[0][:5].tolist()
        what = _not_finite(source is not None and bool(np.isfinite(source).all()), a.dtype)
        raise ValueError(f"{name}: {what} (batch rows {rows})")


def real_array(x: Any, name: str, float64: bool = True) -> np.ndarray:
    """``x`` as a float64 numpy array (no copy for float64 input; ``float64=False`` keeps
    any integer or float dtype). TypeError naming ``name`` for booleans, complex numbers,
    strings or anything else that is not real numbers (numpy would silently turn True
    into 1.0 or drop an imaginary part)."""
    if is_torch(x):
        x = x.detach().cpu().numpy()
    elif isinstance(x, wp.array):
        x = x.numpy()
    try:
        a = np.asarray(x)
    except (TypeError, ValueError) as e:
        raise TypeError(f"{name}: expected an array of numbers, got {type(x).__name__}") from e
    kind = a.dtype.kind
    if kind == "f" and (a.dtype.itemsize == 8 or not float64):
        return a
    if kind == "b":
        raise TypeError(f"{name}: expected numbers, got booleans")
    if kind == "c":
        raise TypeError(f"{name}: expected real numbers, got complex values")
    if kind not in "iuf":
        if kind == "O" and any(isinstance(v, (bool, np.bool_, complex, np.complexfloating))
                               for v in a.flat):
            raise TypeError(f"{name}: expected real numbers, got booleans or complex values")
        if kind != "O":
            raise TypeError(f"{name}: expected an array of numbers, got {a.dtype} values")
    if kind in "iu" and not float64:
        return a
    try:
        return a.astype(np.float64)
    except (TypeError, ValueError, OverflowError) as e:
        raise TypeError(f"{name}: expected an array of numbers, got {type(x).__name__}") from e


def finite_as(a: np.ndarray, dtype: DTypeLike, name: str) -> np.ndarray:
    """``a`` cast to the computing ``dtype`` (float32/float64), contiguous; ValueError
    naming ``name`` if it has NaN/inf after the cast (1e39 is finite in float64, inf in
    float32)."""
    npdt = np.dtype(dtype)
    with np.errstate(over="ignore", invalid="ignore"):
        c = np.ascontiguousarray(a, dtype=npdt)
    if c.size and not np.isfinite(c).all():
        raise ValueError(f"{name}: {_not_finite(bool(np.isfinite(a).all()), npdt)}")
    return c


def default_dtype(x: Any) -> Any:
    """float64 for float64 numpy/torch/warp input, else float32."""
    if isinstance(x, wp.array):
        return np.float64 if x.dtype == wp.float64 else np.float32
    if is_torch(x):
        import torch

        return np.float64 if x.dtype == torch.float64 else np.float32
    if isinstance(x, np.ndarray) and x.dtype == np.float64:
        return np.float64
    return np.float32


#: CPU arrays of at least this many bytes are allocated by numpy (see :func:`empty`)
NUMPY_ALLOC_BYTES = 1 << 20
_HOST_DTYPES: dict[Any, np.dtype] = {
    wp.float32: np.dtype(np.float32), wp.float64: np.dtype(np.float64), wp.int32: np.dtype(np.int32)}
_ITEM_BYTES: dict = {}


def _numpy_backed(shape: tuple, dtype: type, device: wp.Device, fill: bool) -> wp.array | None:
    """A CPU Warp array on numpy memory (``np.empty``/``np.zeros``), or None where Warp
    should allocate (CUDA, small arrays)."""
    if not device.is_cpu:
        return None
    item = _ITEM_BYTES.get(dtype)
    if item is None:
        item = _ITEM_BYTES.setdefault(dtype, wp.types.type_size_in_bytes(dtype))
    if math.prod(shape) * item < NUMPY_ALLOC_BYTES:
        return None
    inner = tuple(getattr(dtype, "_shape_", ()))
    npdt = _HOST_DTYPES.get(getattr(dtype, "_wp_scalar_type_", dtype))
    if npdt is None:
        return None
    # numpy's buffers start 16 bytes past a cache line; Warp's (and the kernels' 64-byte
    # mat44 stores) are 64-byte aligned: over-allocate and start at the next cache line
    nbytes = math.prod(shape) * item
    raw = (np.zeros if fill else np.empty)(nbytes + 64, np.uint8)
    skip = -raw.ctypes.data % 64
    host = raw[skip:skip + nbytes].view(npdt).reshape(tuple(shape) + inner)
    return wp.array(host, dtype=dtype, device=device, copy=False)


#: fresh CPU outputs of at least this many bytes are faulted in on a second thread while
#: the kernel runs (see :func:`first_touch`)
FIRST_TOUCH_BYTES = 16 << 20
_MADV_POPULATE_WRITE = 23   # Linux >= 5.14
_MADVISE: list = []         # [libc.madvise] once found to work, [None] where unavailable


def _madvise() -> Any:
    if not _MADVISE:
        fn = None
        from jwarp.core.threads import available_cpus

        if sys.platform.startswith("linux") and available_cpus() > 1:
            try:
                fn = ctypes.CDLL(None, use_errno=True).madvise
                fn.argtypes = [ctypes.c_void_p, ctypes.c_size_t, ctypes.c_int]
                fn.restype = ctypes.c_int
            except (OSError, AttributeError):
                fn = None
        _MADVISE.append(fn)
    return _MADVISE[0]


def first_touch(arr: wp.array) -> Callable[[], None] | None:
    """Start faulting in the pages of a fresh, large CPU array on another thread
    (``madvise(MADV_POPULATE_WRITE)``, Linux >= 5.14), so that the OS zeroes them on a
    second core while the kernel that writes them runs; returns the function that waits
    for it (call it after the launch), or None where nothing was started (small array,
    CUDA, one core, another OS). Populating keeps the contents, so it may race with the
    kernel's writes. Saves most of the first-touch cost of a new output: justin19 frames
    of 100 000 configurations, 1.31x the kernel alone -> 1.03x on a 2-core EPYC VM."""
    if not cast(wp.Device, arr.device).is_cpu:
        return None
    item = _ITEM_BYTES.get(arr.dtype)
    if item is None:
        item = _ITEM_BYTES.setdefault(arr.dtype, wp.types.type_size_in_bytes(arr.dtype))
    nbytes = math.prod(arr.shape) * item
    if nbytes < FIRST_TOUCH_BYTES:
        return None
    madvise = _madvise()
    if madvise is None:
        return None
    start = -(-arr.ptr // _PAGE) * _PAGE           # whole pages inside the array
    length = (arr.ptr + nbytes) // _PAGE * _PAGE - start

    def populate() -> None:
        if madvise(start, length, _MADV_POPULATE_WRITE) != 0 and ctypes.get_errno() in (
                errno.EINVAL, errno.ENOSYS):   # a kernel without it: stop trying
            _MADVISE[0] = None

    thread = threading.Thread(target=populate, name="jwarp-first-touch", daemon=True)
    thread.start()
    return thread.join


_PAGE = mmap.PAGESIZE


def empty(shape: tuple, dtype: type, device: wp.Device, requires_grad: bool = False) -> wp.array:
    """``wp.empty``, but a large CPU array is allocated by numpy and shared (zero-copy):
    numpy asks Linux for transparent huge pages, so the first touch of a fresh output costs
    about a quarter of what it costs in Warp's own allocation (173 MB of justin19 frames:
    about 17 ms instead of 70 ms on a 2-core EPYC VM; :func:`first_touch` hides the rest)."""
    if not requires_grad:
        arr = _numpy_backed(tuple(shape), dtype, device, fill=False)
        if arr is not None:
            return arr
    return wp.empty(shape, dtype=dtype, device=device, requires_grad=requires_grad)


def zeros(shape: tuple, dtype: type, device: wp.Device, requires_grad: bool = False) -> wp.array:
    """``wp.zeros``, large CPU arrays as :func:`empty` (``np.zeros``: pages zeroed lazily
    by the OS, not written twice)."""
    if not requires_grad:
        arr = _numpy_backed(tuple(shape), dtype, device, fill=True)
        if arr is not None:
            return arr
    return wp.zeros(shape, dtype=dtype, device=device, requires_grad=requires_grad)


def out_view(out: Any, batch: Batch, tail: tuple, dtype: type, device: wp.Device,
             name: str = "out") -> wp.array | None:
    """Check a caller's output array ``out`` for a result (B, *tail) of Warp ``dtype``
    (a scalar, or a vector/matrix type such as ``mat44``) on ``device``, and return a Warp
    array of shape (B, *tail) sharing ``out``'s memory for the kernel to write, or None
    where the result must be computed elsewhere and copied in (a numpy ``out`` of a CUDA
    computation; :func:`to_output` copies it).

    ``out`` is a numpy array or torch tensor of the shape the call returns for numpy/torch
    input (the caller's leading dims, then ``tail`` and the matrix dims, e.g.
    (..., n_frames, 4, 4)), or a Warp array of the shape it returns for Warp input
    ((..., n_frames) of ``mat44``); in the computing dtype, C-contiguous and writeable;
    torch and Warp arrays on the computing device. TypeError/ValueError name ``name``."""
    inner = tuple(getattr(dtype, "_shape_", ()))
    scalar = getattr(dtype, "_wp_scalar_type_", dtype)
    npdt = numpy_dtype(scalar)
    lead = tuple(batch.lead_shape)
    B = batch.size
    if isinstance(out, wp.array):
        want = lead + tuple(tail)
        if not wp.types.types_equal(out.dtype, dtype):
            raise TypeError(f"{name}: Warp array of {_wp_name(out.dtype)}, expected "
                            f"{_wp_name(dtype)} (the computing dtype is {npdt.name})")
        if tuple(out.shape) != want:
            raise ValueError(f"{name}: expected shape {want}, got {tuple(out.shape)}")
        if out.device != device:
            raise ValueError(f"{name}: on device {out.device}, the computation runs on {device}")
        if not out.is_contiguous:
            raise ValueError(f"{name}: must be contiguous")
        return out.reshape((B,) + tuple(tail))
    want = lead + tuple(tail) + inner
    if is_torch(out):
        import torch

        if out.dtype != getattr(torch, npdt.name):
            raise TypeError(f"{name}: dtype {out.dtype}, expected torch.{npdt.name} "
                            f"(the computing dtype)")
        if tuple(out.shape) != want:
            raise ValueError(f"{name}: expected shape {want}, got {tuple(out.shape)}")
        if wp.device_from_torch(out.device) != device:
            raise ValueError(f"{name}: on device {out.device}, the computation runs on {device}")
        if not out.is_contiguous():
            raise ValueError(f"{name}: must be contiguous")
        if out.requires_grad:
            raise ValueError(f"{name}: must not require grad (out= is not differentiable)")
        return wp.from_torch(out.detach(), dtype=dtype).reshape((B,) + tuple(tail))
    if not isinstance(out, np.ndarray):
        raise TypeError(f"{name}: expected a numpy array, torch tensor or Warp array, got "
                        f"{type(out).__name__}")
    if out.dtype != npdt:
        raise TypeError(f"{name}: dtype {out.dtype}, expected {npdt.name} (the computing dtype)")
    if out.shape != want:
        raise ValueError(f"{name}: expected shape {want}, got {out.shape}")
    if not out.flags.c_contiguous:
        raise ValueError(f"{name}: must be C-contiguous")
    if not out.flags.writeable:
        raise ValueError(f"{name}: is read-only")
    if not device.is_cpu:
        return None
    return wp.array(out.reshape((B,) + tuple(tail) + inner), dtype=dtype, device=device,
                    copy=False)


def _wp_name(dtype: DTypeLike) -> str:
    inner = getattr(dtype, "_shape_", ())
    scalar = getattr(dtype, "_wp_scalar_type_", dtype)
    base = getattr(scalar, "__name__", str(scalar))
    return f"{'x'.join(map(str, inner))} {base} matrices" if inner else base


def host_copy(arr: wp.array, out: np.ndarray | None = None) -> np.ndarray:
    """A CUDA array copied to host memory allocated by numpy (or into ``out``)."""
    inner = tuple(getattr(arr.dtype, "_shape_", ()))
    scalar = getattr(arr.dtype, "_wp_scalar_type_", arr.dtype)
    fresh = out is None
    if out is None:
        if scalar not in _HOST_DTYPES:
            return arr.numpy()
        out = np.empty(tuple(arr.shape) + inner, _HOST_DTYPES[scalar])
    dst: wp.array = wp.array(out.reshape(tuple(arr.shape) + inner), dtype=arr.dtype,
                             device="cpu", copy=False)
    done = first_touch(dst) if fresh else None
    stream = cast(wp.Device, arr.device).null_stream  # as Warp's .numpy(): in order with every stream
    wp.copy(dst, arr, stream=stream)
    wp.synchronize_stream(stream)
    if done is not None:
        done()
    return out


_new_object = object.__new__


class HostWrap:
    """New Warp CPU arrays of one shape and dtype holding copies of host results, at about
    a third of the cost of ``wp.array(host.copy(), dtype=..., copy=False)`` (the small-call
    path of fk/jacobian returns a new Warp array per call).

    The copies are written to consecutive slots of a numpy pool of about 64 kB (a new pool
    when it is used up; a pool lives while an array of it does), so the pointer of a slot
    is known without asking numpy. The first array is made by ``wp.array``; its attributes
    are kept as a template, and each later array gets a copy of them with its own pointer
    (``ptr``), owner (``_ref``: the slot, which keeps the pool alive) and no cached
    interfaces. Where Warp's array keeps other attributes (another Warp version), every
    call takes ``wp.array``."""

    POOL_BYTES = 1 << 16

    #: the instance attributes of a ``wp.array`` (Warp 1.19) that :meth:`wrap` copies or sets
    KNOWN_ATTRIBUTES = frozenset({
        "_array_interface", "_grad", "_is_read", "_memory_kind", "_ref", "_requires_grad",
        "_retain_grad", "_storage_base_ptr", "_storage_nbytes", "capacity", "ctype",
        "deleter", "device", "dtype", "is_contiguous", "is_transposed", "ndim", "pinned",
        "ptr", "shape", "size", "strides"})

    def __init__(self, shape: tuple, npdt: Any, dtype: DTypeLike) -> None:
        self.shape, self.npdt, self.dtype = tuple(shape), np.dtype(npdt), dtype
        self.nbytes = math.prod(self.shape) * self.npdt.itemsize
        self.slots = max(1, self.POOL_BYTES // max(self.nbytes, 1))
        self.pool: np.ndarray | None = None
        self.base = 0
        self.next = self.slots
        self.lock = threading.Lock()
        first: Any = wp.array(np.zeros(self.shape, self.npdt), dtype=dtype, device="cpu",
                              copy=False)
        state = dict(first.__dict__)
        # only where the array's attributes are exactly those known (Warp 1.19): an
        # attribute a later Warp adds is not copied from the template unseen
        fast = (type(first) is wp.array and state.keys() == self.KNOWN_ATTRIBUTES
                and state["deleter"] is None and state["_storage_base_ptr"] is None)
        if fast:
            state.update(ctype=None, _array_interface=None)
        self.state = state if fast else None

    def take(self) -> tuple[np.ndarray, int]:
        """A fresh slot (of the template's shape and dtype) to write a result to, and its
        address; :meth:`wrap` makes it a Warp array."""
        with self.lock:   # threads never share a slot
            k = self.next
            if k == self.slots:
                self.pool = np.empty((self.slots,) + self.shape, self.npdt)
                self.base = self.pool.ctypes.data
                k = 0
            self.next = k + 1
            pool = cast(np.ndarray, self.pool)   # set at the first take
            return pool[k], self.base + k * self.nbytes

    def wrap(self, slot: np.ndarray, ptr: int) -> wp.array:
        """The slot of :meth:`take` (at address ``ptr``) as a new Warp array."""
        state = self.state
        if state is None:
            return wp.array(slot, dtype=self.dtype, device="cpu", copy=False)
        arr = _new_object(wp.array)   # every attribute comes from the template
        d = arr.__dict__
        d.update(state)
        d["ptr"] = ptr
        d["_ref"] = slot
        return arr


def to_output(arr: wp.array, batch: Batch, tail: tuple = (), out: Any = None) -> Any:
    """Return ``arr`` (B, *tail) in the caller's kind with the caller's leading dims.

    Warp callers get Warp arrays (matrix dtypes kept, e.g. ``mat44`` of shape (..., n)),
    numpy/torch callers get plain arrays with the matrix dims appended, e.g. (..., n, 4, 4).
    With ``out`` (checked by :func:`out_view`), returns ``out``, after copying ``arr``
    into it unless the kernel wrote it already.
    """
    if out is not None:
        if isinstance(out, np.ndarray) and not cast(wp.Device, arr.device).is_cpu:
            host_copy(arr, out)
        return out
    shape = tuple(batch.lead_shape) + tuple(tail)
    if not arr.is_contiguous:
        arr = arr.contiguous()
    if batch.kind == "warp":
        return arr.reshape(shape) if shape and shape != tuple(arr.shape) else arr
    inner = tuple(getattr(arr.dtype, "_shape_", ()))
    if batch.kind == "torch":
        t = wp.to_torch(arr)
        src = batch.torch_tensor
        if t.device != src.device:
            t = t.to(src.device)
        return t.reshape(shape + inner)
    if not cast(wp.Device, arr.device).is_cpu:
        return host_copy(arr).reshape(shape + inner)
    return arr.numpy().reshape(shape + inner)
