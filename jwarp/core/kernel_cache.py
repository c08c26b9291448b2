"""Warp's kernel cache as jwarp sees it: where it is, and a notice when jwarp's kernels
have to be compiled.

Warp compiles each kernel from source on its first launch (10-30 s a kernel family on a
small CPU) and keeps the binary in its kernel cache: ``wp.config.kernel_cache_dir``, by
default ``~/.cache/warp/<warp version>`` (Linux), or ``$WARP_CACHE_PATH/<warp version>``
when the environment variable ``WARP_CACHE_PATH`` is set. A binary is found again by the
hash of its kernel's source and options, so a cache stays valid until jwarp or Warp
changes.

:func:`install_compile_notice` (called by :func:`jwarp.core.arrays.init_warp`) makes every
compilation of a jwarp kernel module print one line on stderr, naming the module, its
kernels, the device and why it compiles::

    jwarp: compiling kernel module motion_f64 (prep, segment, ...) for cpu: first use (not in the kernel cache /root/.cache/warp/1.19.0 yet; kept there for later runs)

The reasons (:func:`compile_reason`): ``first use`` (no variant of these kernels in the
cache), ``new specialisation`` (the cache holds other variants of the same kernels: they
are built per dtype, robot size or constant, and a changed jwarp source is a new variant
too) or ``changed`` (the cache holds this module for other build options or another
Warp). On a terminal a progress bar (tqdm) shows while a compilation takes more than 1 s.
``JWARP_COMPILE_NOTICE=0`` silences both. Loads from the cache print nothing. The notice
wraps Warp's ``Module._compile`` (which Warp calls for every module load not yet in
memory, cached or not) and decides "compile" the way Warp does: the module's binary is
not in the cache. Should a later Warp rename that method, the notice silently does
nothing; the kernels work as before. :func:`loaded_modules` lists the cache folders of
the jwarp modules a process loaded (compiled or from the cache).

:func:`compile_progress` shows one bar over a known number of module loads
(``jwarp warmup``).
"""

from __future__ import annotations

import contextlib
import inspect
import os
import sys
import threading
import time
from collections.abc import Callable, Iterator
from typing import Any

import warp as wp

from jwarp.core.types import DeviceLike
from jwarp.utils.warp_init import init_quietly

__all__ = ["CACHE_ENV", "NOTICE_ENV", "KernelCacheWarning", "cache_dir", "compile_progress",
           "compile_reason", "compiled_modules", "ensure_cache_dir", "install_compile_notice",
           "loaded_modules", "notice_enabled"]

#: Warp's environment variable for the kernel cache's parent folder
CACHE_ENV = "WARP_CACHE_PATH"
#: ``JWARP_COMPILE_NOTICE=0`` silences the compile notice and its progress bar
NOTICE_ENV = "JWARP_COMPILE_NOTICE"
#: seconds a compilation runs before its progress bar appears
BAR_DELAY = 1.0

_NO_BAR = object()  # the bar could not be made (no tqdm): the line suffices

_LOCK = threading.RLock()
_STATE: dict[str, Any] = {"installed": False, "compiled": [], "loaded": [],
                          "active": 0, "bar": None, "progress": None, "ticker": None}


class KernelCacheWarning(UserWarning):
    """Warp's kernel cache folder cannot be used; a temporary one is used instead
    (:func:`ensure_cache_dir`)."""


def _unusable(folder: str) -> str | None:
    """Why ``folder`` cannot hold the kernel cache (it is made if missing and a file is
    written and removed there), or None if it can."""
    import tempfile

    try:
        os.makedirs(folder, exist_ok=True)
        fd, probe = tempfile.mkstemp(dir=folder, prefix=".jwarp-probe-")
        os.close(fd)
        os.unlink(probe)
    except OSError as e:
        return e.strerror or str(e)
    return None


def ensure_cache_dir() -> str | None:
    """Before ``wp.init()``: check the kernel cache folder chosen by ``WARP_CACHE_PATH`` (or
    ``wp.config.kernel_cache_dir``). When it cannot be used (not a folder, not writable:
    Warp would fail every command with a bare OS error), warn (:class:`KernelCacheWarning`,
    naming the folder and the variable) and point Warp at a new temporary folder (kernels
    then compile again in every process); returns that folder, else None."""
    import tempfile
    import warnings

    if wp.config.kernel_cache_dir is not None:
        base, where = str(wp.config.kernel_cache_dir), "wp.config.kernel_cache_dir"
    elif os.environ.get(CACHE_ENV):
        base, where = os.environ[CACHE_ENV], CACHE_ENV
    else:
        return None
    folder = os.path.join(os.path.realpath(base), wp.config.version)
    why = _unusable(folder)
    if why is None:
        return None
    tmp = tempfile.mkdtemp(prefix="jwarp-warp-cache-")
    warnings.warn(f"{where}={base}: Warp's kernel cache {folder} cannot be used ({why}); "
                  f"using the temporary cache {tmp} instead (kernels compile again in every "
                  f"process): set {CACHE_ENV} to a writable folder", KernelCacheWarning,
                  stacklevel=3)
    wp.config.kernel_cache_dir = tmp
    return tmp


def cache_dir() -> str:
    """The folder of Warp's kernel cache (``wp.config.kernel_cache_dir``; Warp is
    initialised if it was not)."""
    if wp.config.kernel_cache_dir is None:  # as jwarp.core.arrays.init_warp: quietly
        if hasattr(wp, "LOG_WARNING"):
            wp.config.log_level = max(wp.config.log_level, wp.LOG_WARNING)
        init_quietly()
    return str(wp.config.kernel_cache_dir)


def notice_enabled() -> bool:
    """False when ``JWARP_COMPILE_NOTICE`` is ``0``/``false``/``no``/``off``."""
    return os.environ.get(NOTICE_ENV, "1").strip().lower() not in ("0", "false", "no", "off")


def compiled_modules() -> list[str]:
    """Names of the jwarp kernel modules this process compiled (not loaded from the
    cache), in order."""
    with _LOCK:
        return list(_STATE["compiled"])


def loaded_modules() -> list[str]:
    """The kernel-cache folders (``wp_<module>_<hash>``) of the jwarp modules this process
    loaded, compiled or from the cache, in order (a module once per folder)."""
    with _LOCK:
        return list(_STATE["loaded"])


def compile_reason(output_dir: str) -> str:
    """Why the module of the cache folder ``output_dir`` (``<cache>/wp_<name>_<hash>``,
    not there yet) compiles, judged from the cache's other folders: ``changed`` (the
    module is there under another hash: other build options or another Warp), ``new
    specialisation`` (other variants of its kernels are there: jwarp builds them per
    dtype, robot size or constant; a changed source is a new variant too) or ``first
    use``."""
    cache, folder = os.path.split(os.path.normpath(os.fspath(output_dir)))
    stem = folder.rsplit("_", 1)[0] if "_" in folder else folder  # wp_<name>
    # a kernel's module name ends with the hash of its specialisation: wp_<key>_<hash8>
    head, _, tail = stem.rpartition("_")
    key = head if len(tail) == 8 and all(c in "0123456789abcdef" for c in tail) else stem
    try:
        others = [f for f in os.listdir(cache) if f != folder]
    except OSError:
        others = []
    if any(f.startswith(stem + "_") for f in others):
        return ("changed (the kernel cache holds this module for other build options or "
                "another Warp)")
    variants = sum(1 for f in others if f.startswith(key + "_"))
    if variants:
        return (f"new specialisation (the kernel cache holds {variants} other variant"
                f"{'s' if variants > 1 else ''} of these kernels: another dtype, robot size "
                f"or constant, or a changed jwarp)")
    return "first use"


def _is_jwarp(module: Any) -> bool:
    kernels = getattr(module, "kernels", None) or {}
    try:
        return any(str(getattr(getattr(k, "func", None), "__module__", "")).startswith("jwarp.")
                   for k in list(kernels.values()))
    except Exception:  # noqa: BLE001 - an unexpected Warp internals change: no notice
        return False


def _kernel_names(module: Any) -> str:
    names = [str(getattr(k, "key", "?")).rsplit("__locals__", 1)[-1].strip("_")
             for k in list((getattr(module, "kernels", None) or {}).values())]
    return ", ".join(names[:2]) + (", ..." if len(names) > 2 else "")


def _device_name(device: DeviceLike) -> str:
    return str(getattr(device, "alias", None) or device or "the compile target")


def _new_bar(total: int | None, desc: str) -> Any:
    import shutil

    from tqdm import tqdm

    fmt = ("{desc}: {n_fmt}/{total_fmt} modules |{bar}| [{elapsed}<{remaining}]{postfix}"
           if total else "{desc} [{elapsed}]{postfix}")
    # a terminal that reports no size (e.g. a pty without one) gets 80 x 24, not no bar
    size = shutil.get_terminal_size((80, 24))
    return tqdm(total=total, desc=desc, file=sys.stderr, leave=total is not None,
                ncols=min(size.columns or 80, 120), nrows=size.lines or 24, bar_format=fmt,
                disable=None, mininterval=0.2)


def _ticker() -> None:
    """Shows (after :data:`BAR_DELAY` s) and refreshes the bar of a running compilation."""
    while True:
        time.sleep(0.25)
        with _LOCK:
            if _STATE["active"] == 0:
                _STATE["ticker"] = None
                return
            if _STATE["progress"] is not None:
                continue
            bar = _STATE["bar"]
            if bar is None and time.perf_counter() - _STATE["since"] >= BAR_DELAY:
                try:
                    bar = _STATE["bar"] = _new_bar(None, "jwarp: compiling")
                    bar.start_t = time.time() - (time.perf_counter() - _STATE["since"])
                except Exception:  # noqa: BLE001 - no tqdm or no terminal: the line suffices
                    _STATE["bar"] = _NO_BAR
                    continue
            if bar is not None and bar is not _NO_BAR:
                bar.set_description_str(f"jwarp: compiling {_STATE['what']}", refresh=False)
                bar.refresh()


def _begin(module: Any, device: DeviceLike, output_dir: Any) -> None:
    with _LOCK:
        if _STATE["progress"] is None:  # warmup: its own header and bar
            why = compile_reason(os.fspath(output_dir)) if output_dir is not None else "first use"
            name = str(getattr(module, "name", "?"))
            print(f"jwarp: compiling kernel module {name} ({_kernel_names(module)}) for "
                  f"{_device_name(device)}: {why} (kept in the kernel cache "
                  f"{wp.config.kernel_cache_dir} for later runs)", file=sys.stderr, flush=True)
        _STATE["active"] += 1
        _STATE["what"] = _kernel_names(module)
        if _STATE["active"] == 1:
            _STATE["since"] = time.perf_counter()
        if _STATE["ticker"] is None and _STATE["progress"] is None:
            t = threading.Thread(target=_ticker, name="jwarp-compile-bar", daemon=True)
            _STATE["ticker"] = t
            t.start()


def _end(module: Any, compiled: bool) -> None:
    with _LOCK:
        _STATE["active"] -= 1
        if compiled:
            _STATE["compiled"].append(str(getattr(module, "name", "?")))
        if _STATE["active"] == 0 and _STATE["bar"] is not None:
            if _STATE["bar"] is not _NO_BAR:
                _STATE["bar"].close()
            _STATE["bar"] = None


def _wrap(original: Callable[..., bool]) -> Callable[..., bool]:
    signature = inspect.signature(original)

    def _compile(self: Any, *args: Any, **kwargs: Any) -> bool:
        progress = _STATE["progress"]
        try:
            ours = _is_jwarp(self)
            bound = signature.bind(self, *args, **kwargs).arguments if ours else {}
            out_dir, out_name = bound.get("output_dir"), bound.get("output_name")
            cached = (bool(wp.config.cache_kernels) and out_dir is not None
                      and out_name is not None
                      and os.path.exists(os.path.join(os.fspath(out_dir), out_name)))
        except Exception:  # noqa: BLE001 - Warp internals changed: compile without notice
            ours = False
        if not ours:
            return original(self, *args, **kwargs)
        if out_dir is not None:
            with _LOCK:
                folder = os.path.basename(os.path.normpath(os.fspath(out_dir)))
                if folder not in _STATE["loaded"]:
                    _STATE["loaded"].append(folder)
        if cached:
            result = original(self, *args, **kwargs)
            if progress is not None:
                progress.update(1)
            return result
        if notice_enabled():
            _begin(self, bound.get("device"), out_dir)
        else:
            with _LOCK:
                _STATE["active"] += 1
        compiled = False
        try:
            compiled = bool(original(self, *args, **kwargs))
            return compiled
        finally:
            _end(self, compiled)
            if progress is not None:
                progress.update(1)

    _compile.__wrapped__ = original  # type: ignore[attr-defined]
    _compile._jwarp_notice = True  # type: ignore[attr-defined]
    return _compile


def install_compile_notice() -> bool:
    """Wrap Warp's module compilation once per process so that compiling jwarp's kernels
    prints the notice (see the module docstring). Returns False where this Warp has no
    ``Module._compile`` (no notice then)."""
    with _LOCK:
        if _STATE["installed"]:
            return True
        module_cls: Any  # Warp's Module class (its _compile is wrapped)
        try:
            from warp._src.context import Module as module_cls
        except ImportError:  # pragma: no cover - an older Warp layout
            module_cls = getattr(getattr(wp, "context", None), "Module", None)
        original = getattr(module_cls, "_compile", None) if module_cls is not None else None
        if original is None or not callable(original):
            return False
        if not getattr(original, "_jwarp_notice", False):
            module_cls._compile = _wrap(original)
        _STATE["installed"] = True
        return True


class _Progress:
    """A thread-safe counter over a known number of module loads, drawn as a tqdm bar."""

    def __init__(self, total: int, desc: str, enabled: bool):
        self.bar = _new_bar(total, desc) if enabled else None
        self.n = 0
        self.lock = threading.Lock()

    def update(self, k: int) -> None:
        with self.lock:
            self.n += k
            if self.bar is not None:
                self.bar.update(k)


@contextlib.contextmanager
def compile_progress(total: int, desc: str = "jwarp warmup",
                     bar: bool = True) -> Iterator[_Progress]:
    """Inside the block, every jwarp module load (compiled or from the cache) advances one
    progress bar of ``total`` steps (on a terminal; ``bar=False``: none); the per-compile
    bar of the notice is off meanwhile. Yields the counter (``.n`` loads so far)."""
    install_compile_notice()
    p = _Progress(int(total), desc, bar)
    with _LOCK:
        _STATE["progress"] = p
    try:
        yield p
    finally:
        with _LOCK:
            _STATE["progress"] = None
        if p.bar is not None:
            p.bar.close()
