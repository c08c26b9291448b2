"""The one checker of integer and real arguments (issue 40 item 4), and its one exception.

:func:`check_int` and :func:`real_number` / :func:`check_real` raise :class:`ArgumentError`,
whose message names the argument (``"n_starts: expected an integer >= 1, got 0"``). It is
both a ``TypeError`` and a ``ValueError``: code that catches either one (as jwarp's own
callers and tests did before there was one checker) still catches it, whether the type or
the value was wrong. Host only: numpy, no Warp (layer 0, usable by every package).
"""

from __future__ import annotations

import math
import numbers
from typing import Any

import numpy as np

__all__ = ["ArgumentError", "check_int", "check_real", "real_number"]


class ArgumentError(TypeError, ValueError):
    """A bad argument, named in the message: a wrong type (bool, str, float where an integer
    is expected, ...) or a value out of range. A ``TypeError`` and a ``ValueError`` both."""


def _bounds(lo: Any, hi: Any, open_lo: bool = False, open_hi: bool = False) -> str:
    g = "{:g}".format if not isinstance(lo, numbers.Integral) else str
    h = "{:g}".format if not isinstance(hi, numbers.Integral) else str
    if lo is not None and hi is not None:
        if not open_lo and not open_hi:
            return f" in [{g(lo)}, {h(hi)}]"
        return f" {'>' if open_lo else '>='} {g(lo)} and {'<' if open_hi else '<='} {h(hi)}"
    if lo is not None:
        return f" {'>' if open_lo else '>='} {g(lo)}"
    if hi is not None:
        return f" {'<' if open_hi else '<='} {h(hi)}"
    return ""


def check_int(v: Any, name: str, lo: int | None = None, hi: int | None = None, *,
              none: bool = False) -> Any:
    """``v`` as a Python int when it is an integer (Python or numpy; bools refused) in
    ``[lo, hi]`` (None: unbounded), else :class:`ArgumentError` naming ``name``. With
    ``none``, None passes (and is returned)."""
    if v is None and none:
        return None
    if not isinstance(v, (bool, np.bool_)) and isinstance(v, numbers.Integral):
        i = int(v)
        if (lo is None or i >= lo) and (hi is None or i <= hi):
            return i
    raise ArgumentError(f"{name}: expected an integer{_bounds(lo, hi)}"
                        f"{' or None' if none else ''}, got {v!r}")


def real_number(v: Any, name: str, dtype: Any = None) -> float:
    """A real scalar argument (int, float, numpy scalar or 0-d array) as a float.
    :class:`ArgumentError` naming ``name`` for bool, complex, strings and other non-numbers;
    with ``dtype``, also unless it is finite in that computing dtype. Range checks:
    :func:`check_real`."""
    if type(v) is not float:  # the common case first (optimizer loops call this)
        if isinstance(v, np.ndarray) and v.ndim == 0:
            v = v[()]
        if isinstance(v, (bool, np.bool_)) or not isinstance(v, numbers.Real):
            raise ArgumentError(f"{name}: expected a real number, got {type(v).__name__} "
                                f"{v!r}")
    f = float(v)
    if dtype is not None:
        fmax = _FMAX.get(dtype)
        if fmax is None:
            fmax = _FMAX.setdefault(dtype, float(np.finfo(dtype).max))
        if not abs(f) <= fmax:
            raise ArgumentError(f"{name}: expected a finite number in {np.dtype(dtype).name}, "
                                f"got {v!r}")
    return f


_FMAX: dict = {}


def check_real(v: Any, name: str, lo: float | None = None, hi: float | None = None, *,
               open_lo: bool = False, open_hi: bool = False, finite: bool = True,
               none: bool = False) -> Any:
    """``v`` as a float when it is a real number (:func:`real_number`), finite (unless
    ``finite=False``; NaN never passes) and within the bounds (``open_lo``/``open_hi``:
    strict), else :class:`ArgumentError` naming ``name``. With ``none``, None passes (and
    is returned)."""
    if v is None and none:
        return None
    f = real_number(v, name)
    ok = not math.isnan(f) and (not finite or math.isfinite(f))
    if ok and lo is not None:
        ok = f > lo if open_lo else f >= lo
    if ok and hi is not None:
        ok = f < hi if open_hi else f <= hi
    if not ok:
        raise ArgumentError(f"{name}: expected a {'finite ' if finite else ''}number"
                            f"{_bounds(lo, hi, open_lo, open_hi)}"
                            f"{' or None' if none else ''}, got {v!r}")
    return f
