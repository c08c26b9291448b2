"""Array plumbing shared by the public API: numpy / warp / torch in, the same kind out.

Inputs are flattened to a batch ``(B, n)``; outputs are reshaped back to the caller's
leading batch dimensions. Torch tensors and Warp arrays are shared zero-copy.
"""

from __future__ import annotations

import numbers
from dataclasses import dataclass
from typing import Any

import numpy as np
import warp as wp

from jwarp.core.device import numpy_dtype, scalar_type

_INITIALISED = False


def init_warp() -> None:
    """Initialise Warp once, quietly."""
    global _INITIALISED
    if not _INITIALISED:
        wp.config.quiet = True
        if hasattr(wp, "LOG_WARNING"):  # Warp >= 1.1x logs through log_level
            wp.config.log_level = max(wp.config.log_level, wp.LOG_WARNING)
        wp.init()
        _INITIALISED = True


def is_torch(x: Any) -> bool:
    mod = type(x).__module__
    return mod.startswith("torch") and hasattr(x, "detach")


def resolve_device(device: Any, like: Any = None) -> wp.Device:
    """The Warp device: ``device`` if given, else that of ``like`` (warp/torch), else the
    preferred device (CUDA if present, else CPU)."""
    init_warp()
    if device is None:
        if isinstance(like, wp.array):
            return like.device
        if like is not None and is_torch(like):
            return wp.device_from_torch(like.device)
        return wp.get_preferred_device()
    try:
        return wp.get_device(str(device) if not isinstance(device, wp.Device) else device)
    except Exception as e:  # warp raises RuntimeError/ValueError for unknown devices
        raise ValueError(f"device: unknown or unavailable device {device!r}: {e}") from e


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


def as_batch(x: Any, n: int, name: str, *, device: wp.Device, dtype: Any,
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
        return Batch(arr.reshape((-1, n)), shape[:-1], "warp")
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
        arr = wp.from_torch(t, dtype=scalar)
        if arr.device != device:
            arr = arr.to(device)
        return Batch(arr, shape[:-1], "torch", torch_tensor=x)
    a = real_array(x, name, float64=False)
    _check_shape(a.shape, n, name, what)
    with np.errstate(over="ignore", invalid="ignore"):  # overflow is reported below
        a2 = np.ascontiguousarray(a.reshape(-1, n), dtype=npdt)
    if validate:  # after the cast: 1e39 is finite in float64, inf in float32
        _check_finite(a2, name, a)
    return Batch(wp.array(a2, dtype=scalar, device=device), a.shape[:-1], "numpy")


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


def finite_as(a: np.ndarray, dtype: Any, name: str) -> np.ndarray:
    """``a`` cast to the computing ``dtype`` (float32/float64), contiguous; ValueError
    naming ``name`` if it has NaN/inf after the cast (1e39 is finite in float64, inf in
    float32)."""
    npdt = np.dtype(dtype)
    with np.errstate(over="ignore", invalid="ignore"):
        c = np.ascontiguousarray(a, dtype=npdt)
    if c.size and not np.isfinite(c).all():
        raise ValueError(f"{name}: {_not_finite(bool(np.isfinite(a).all()), npdt)}")
    return c


def real_number(v: Any, name: str, dtype: Any = None) -> float:
    """A real scalar argument (int, float, numpy scalar or 0-d array) as a float. TypeError
    naming ``name`` for bool, complex, strings and other non-numbers; with ``dtype``,
    ValueError unless it is finite in that computing dtype. Range checks are the
    caller's."""
    if type(v) is not float:  # the common case first (optimizer loops call this)
        if isinstance(v, np.ndarray) and v.ndim == 0:
            v = v[()]
        if isinstance(v, (bool, np.bool_)) or not isinstance(v, numbers.Real):
            raise TypeError(f"{name}: expected a real number, got {type(v).__name__} {v!r}")
    f = float(v)
    if dtype is not None:
        fmax = _FMAX.get(dtype)
        if fmax is None:
            fmax = _FMAX.setdefault(dtype, float(np.finfo(dtype).max))
        if not abs(f) <= fmax:
            raise ValueError(f"{name}: expected a finite number in {np.dtype(dtype).name}, "
                             f"got {v!r}")
    return f


_FMAX: dict = {}


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


def to_output(arr: wp.array, batch: Batch, tail: tuple = ()) -> Any:
    """Return ``arr`` (B, *tail) in the caller's kind with the caller's leading dims.

    Warp callers get Warp arrays (matrix dtypes kept, e.g. ``mat44`` of shape (..., n)),
    numpy/torch callers get plain arrays with the matrix dims appended, e.g. (..., n, 4, 4).
    """
    shape = tuple(batch.lead_shape) + tuple(tail)
    if not arr.is_contiguous:
        arr = arr.contiguous()
    if batch.kind == "warp":
        return arr.reshape(shape) if shape else arr
    inner = tuple(getattr(arr.dtype, "_shape_", ()))
    if batch.kind == "torch":
        t = wp.to_torch(arr)
        src = batch.torch_tensor
        if t.device != src.device:
            t = t.to(src.device)
        return t.reshape(shape + inner)
    return arr.numpy().reshape(shape + inner)
