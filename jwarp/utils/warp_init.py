"""Warp's initialisation without its "CUDA driver not found" line on machines without CUDA.

Warp's native library prints ``Warp CUDA warning: Could not find or load the NVIDIA CUDA
driver. GPU execution will not be available.`` on stderr (from C, not through Python's
warnings or logging) whenever it initialises on a machine without an NVIDIA driver: every
jwarp command on a CPU machine printed it (issue 39). :func:`init_quietly` initialises Warp
with that one line filtered out of the process's stderr when no driver library can be
loaded (anything else Warp prints is passed on); :func:`cuda_driver_found` tells whether
there is one, for ``jwarp info``'s device line. On a machine with a driver nothing is
filtered: a driver that fails to load is Warp's to report.
"""

from __future__ import annotations

import ctypes
import os
import sys
import tempfile

import warp as wp

__all__ = ["CUDA_DRIVER_WARNING", "cuda_driver_found", "init_quietly"]

#: the start of the line Warp prints when it finds no CUDA driver
CUDA_DRIVER_WARNING = "Warp CUDA warning: Could not find or load the NVIDIA CUDA driver"

_FOUND: bool | None = None


def cuda_driver_found() -> bool:
    """Whether the NVIDIA CUDA driver library (``libcuda.so``/``libcuda.so.1``,
    ``nvcuda.dll`` on Windows) can be loaded, as Warp loads it (cached; no CUDA context is
    made). False on macOS."""
    global _FOUND
    if _FOUND is None:
        if sys.platform == "darwin":
            names: tuple[str, ...] = ()
        elif sys.platform == "win32":
            names = ("nvcuda.dll",)
        else:
            names = ("libcuda.so", "libcuda.so.1")
        found = False
        for name in names:
            try:
                ctypes.CDLL(name)
            except OSError:
                continue
            found = True
            break
        _FOUND = found
    return _FOUND


def init_quietly() -> None:
    """``wp.init()``; without a CUDA driver (:func:`cuda_driver_found`) the native stderr
    (file descriptor 2) is caught while Warp initialises and written back without the
    :data:`CUDA_DRIVER_WARNING` line. Where file descriptor 2 cannot be redirected,
    plain ``wp.init()``."""
    if cuda_driver_found():
        wp.init()
        return
    try:
        sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, ValueError, AttributeError):
        wp.init()
        return
    with tempfile.TemporaryFile() as tmp:
        try:
            os.dup2(tmp.fileno(), 2)
            wp.init()
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            tmp.seek(0)
            text = tmp.read().decode("utf-8", "replace")
    rest = "".join(line for line in text.splitlines(keepends=True)
                   if not line.startswith(CUDA_DRIVER_WARNING))
    if rest:
        try:
            sys.stderr.write(rest)
            sys.stderr.flush()
        except (OSError, ValueError):  # pragma: no cover - stderr closed
            pass
