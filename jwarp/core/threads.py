"""The BLAS thread pool around jwarp's small dense solves.

numpy's OpenBLAS starts one thread per core by default. The dense problems of calibration
(a least-squares Jacobian of a few thousand rows by a few hundred columns), experiment
design and sensitivity analysis are too small to gain from threads, and on a loaded machine
the spinning pool threads steal the cores from each other: ``examples/calibrate_justin_tracker.py``
took 325.7 s with the default pool and 28.3 s with one thread on a loaded 2-core machine
(issue 27), with the same numbers. The solvers therefore run inside
:func:`blas_threads` (or are decorated with :func:`limit_blas`), which caps the BLAS pool
for the duration of the call and restores it afterwards (``threadpoolctl``).

``JWARP_BLAS_THREADS`` (environment variable) overrides the cap: a positive integer is
the number of BLAS threads inside the solvers; ``0`` (or ``none``) leaves the pool as the
user configured it (``OPENBLAS_NUM_THREADS``, ``OMP_NUM_THREADS``, ...). Anything else is a
ValueError naming the variable. Unset: :data:`DEFAULT_BLAS_THREADS`.

The pool is process-wide: two solves running in threads of one process share one cap.

CPU threads of jwarp's other parallel CPU work (torch's intra-op pool while training,
``jwarp warmup``'s compile jobs): :func:`cpu_threads`. On a loaded machine a pool of one
thread per core oversubscribes the cores (issue 39: a torch training epoch took 70-81 s
beside another job against 0.7 s quiet, 3-4x the CPU time). ``JWARP_THREADS`` (a positive
integer) fixes the count; unset, it is the CPUs this process may run on
(:func:`available_cpus`: the affinity mask, a cgroup CPU quota) less those other processes
keep busy (the 1-minute load average less this process's own share, or the threads
runnable right now where more (:func:`runnable_others`: a job started seconds ago has not
raised the average yet; this process's own threads are not counted)), at least 1.

torch's pool while training: :func:`torch_thread_count`, which also leaves one CPU spare
(unless ``JWARP_THREADS`` says otherwise). torch's CPU pool is OpenMP (libgomp), whose
threads spin at every barrier: as soon as any other thread wants one of the pool's CPUs, a
parallel op waits for a thread that is not running. On the 2-core VM (2026-12-02) the
README's ``train ik`` smoke run took 3.3 s of training at one thread, 3.3-4.3 s (twice the
CPU time) at two on an idle machine, and 147 s at two beside the test suite; the networks
of :mod:`jwarp.learn` are too small to gain from a second thread. :func:`torch_threads`
holds the pool at that count inside a block; the training loops ask again every epoch
and, within an epoch, at most every second (:class:`ThreadFollower`), so a job started
beside a long training takes its threads down within a second.
"""

from __future__ import annotations

import contextlib
import functools
import math
import os
from collections.abc import Callable, Iterator
from typing import Any, TypeVar

__all__ = ["BLAS_THREADS_ENV", "DEFAULT_BLAS_THREADS", "THREADS_ENV", "available_cpus",
           "blas_thread_limit", "blas_threads", "cpu_threads", "limit_blas",
           "own_runnable", "refresh_torch_threads", "runnable_others", "ThreadFollower",
           "torch_thread_count", "torch_threads"]

#: environment variable overriding the BLAS threads inside jwarp's solvers
BLAS_THREADS_ENV = "JWARP_BLAS_THREADS"
#: environment variable fixing the threads of jwarp's CPU-parallel work (:func:`cpu_threads`)
THREADS_ENV = "JWARP_THREADS"
#: the kernel's load figures (its 4th field: threads runnable now / all threads)
LOADAVG = "/proc/loadavg"
#: BLAS threads inside jwarp's solvers when ``JWARP_BLAS_THREADS`` is unset
DEFAULT_BLAS_THREADS = 1

_F = TypeVar("_F", bound=Callable[..., Any])


def blas_thread_limit(value: str | None = None) -> int | None:
    """The BLAS threads inside the solvers: ``value`` (default: ``$JWARP_BLAS_THREADS``)
    parsed; None means "leave the pool alone" (``0`` or ``none``); unset or empty gives
    :data:`DEFAULT_BLAS_THREADS`.

    Raises:
        ValueError: naming ``JWARP_BLAS_THREADS`` for anything but an integer >= 0 or
            ``none``.
    """
    text = os.environ.get(BLAS_THREADS_ENV) if value is None else value
    if text is None or not str(text).strip():
        return DEFAULT_BLAS_THREADS
    text = str(text).strip()
    if text.lower() == "none":
        return None
    try:
        n = int(text)
    except ValueError:
        n = -1
    if n < 0:
        raise ValueError(f"{BLAS_THREADS_ENV}: expected an integer >= 0 (BLAS threads inside "
                         f"jwarp's solvers; 0 or 'none': leave the pool as configured), "
                         f"got {text!r}")
    return None if n == 0 else n


def _controller() -> Any:
    """A fresh ``threadpoolctl.ThreadpoolController``: the BLAS libraries loaded *now*
    (numpy's and scipy's are separate OpenBLAS builds, and scipy's may be loaded after a
    first solve; a scan costs about 2 ms)."""
    from threadpoolctl import ThreadpoolController

    return ThreadpoolController()


@contextlib.contextmanager
def blas_threads(n: int | None | str = "env") -> Iterator[int | None]:
    """Context manager: at most ``n`` BLAS threads inside the block (default: from
    ``JWARP_BLAS_THREADS``, see :func:`blas_thread_limit`; None: no limit). Yields the
    limit applied (None: the pool was left alone). The previous pool sizes are restored
    on exit, also after an exception."""
    limit = blas_thread_limit() if n == "env" else n
    if limit is not None and (isinstance(limit, bool) or not isinstance(limit, int) or limit < 1):
        raise ValueError(f"n: expected a positive integer, None or 'env', got {limit!r}")
    if limit is None:
        yield None
        return
    ctl = _controller()
    with ctl.limit(limits=limit, user_api="blas"):
        yield limit


def limit_blas(func: _F) -> _F:
    """Decorator: run ``func`` inside :func:`blas_threads` (the limit read from
    ``JWARP_BLAS_THREADS`` at each call)."""

    @functools.wraps(func)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        with blas_threads():
            return func(*args, **kwargs)

    return wrapper  # type: ignore[return-value]


def available_cpus() -> int:
    """The CPUs this process may run on: its affinity mask (``os.sched_getaffinity``;
    ``os.cpu_count()`` where the platform has none), capped by a cgroup v2 CPU quota
    (``/sys/fs/cgroup/cpu.max``, rounded up) where one is set; at least 1."""
    try:
        n = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):  # macOS, Windows
        n = os.cpu_count() or 1
    try:
        with open("/sys/fs/cgroup/cpu.max") as f:
            quota, period = f.read().split()[:2]
        if quota != "max" and float(period) > 0:
            n = min(n, max(1, -(-int(quota) // int(period))))
    except (OSError, ValueError):
        pass
    return max(1, n)


def own_runnable() -> int:
    """Threads of this process runnable right now (state ``R`` in
    ``/proc/self/task/*/stat``; the caller among them), at least 1."""
    n = 0
    try:
        tasks = os.listdir("/proc/self/task")
    except OSError:
        return 1
    for t in tasks:
        try:
            with open(f"/proc/self/task/{t}/stat") as f:
                state = f.read().rsplit(")", 1)[1].split()[0]
        except (OSError, IndexError):
            continue
        n += state == "R"
    return max(1, n)


def runnable_others(samples: int = 3) -> int | None:
    """Threads of other processes runnable right now: the running count of
    ``/proc/loadavg`` less this process's runnable threads (:func:`own_runnable`: the
    reader, and a torch pool's threads spinning at a barrier), the least of ``samples``
    reads 1 ms apart (a thread that ran for an instant is not a load); None where there is
    no ``/proc/loadavg``."""
    import time

    best: int | None = None
    for k in range(max(1, samples)):
        try:
            with open(LOADAVG) as f:
                running = int(f.read().split()[3].split("/")[0])
        except (OSError, ValueError, IndexError):
            return None
        others = running - own_runnable()
        best = others if best is None else min(best, others)
        if k + 1 < samples:
            time.sleep(0.001)
    return max(0, best or 0)


def _env_threads(value: str | None) -> int | None:
    """``value`` (default ``$JWARP_THREADS``) parsed; None when unset or empty."""
    text = os.environ.get(THREADS_ENV) if value is None else value
    if text is None or not str(text).strip():
        return None
    try:
        n = int(str(text).strip())
    except ValueError:
        n = 0
    if n < 1:
        raise ValueError(f"{THREADS_ENV}: expected a positive integer (threads of "
                         f"jwarp's CPU-parallel work), got {text!r}")
    return n


def cpu_threads(value: str | None = None, load: float | None = None, own: float = 1.0) -> int:
    """Threads of jwarp's CPU-parallel work: ``value`` (default ``$JWARP_THREADS``), a
    positive integer, wins; unset or empty: :func:`available_cpus` less the CPUs other
    processes keep busy: ``load`` beyond this process's own ``own`` threads (1: the caller;
    a training loop passes its pool's size, which the load average has counted), rounded;
    ``load`` None: the 1-minute load average, or :func:`runnable_others` + ``own`` where
    that is more (a job started seconds ago); at least 1, at most :func:`available_cpus`.

    Raises:
        ValueError: naming ``JWARP_THREADS`` for anything but a positive integer.
    """
    n = _env_threads(value)
    if n is not None:
        return n
    cpus = available_cpus()
    if load is None:
        try:
            load = os.getloadavg()[0]
        except (AttributeError, OSError):  # Windows
            load = 0.0
        now = runnable_others()
        if now is not None:
            load = max(float(load), now + float(own))
    others = max(0.0, float(load) - float(own))
    return int(min(cpus, max(1, math.floor(cpus - others + 0.5))))


def torch_thread_count(value: str | None = None, load: float | None = None,
                       own: float = 1.0) -> int:
    """torch's intra-op threads while training: ``value`` / ``$JWARP_THREADS`` wins;
    unset: :func:`cpu_threads` but at most :func:`available_cpus` - 1 (at least 1): one
    CPU left spare, since an OpenMP pool on every CPU stalls at each barrier as soon as
    any other thread wants a CPU (module docstring)."""
    n = _env_threads(value)
    if n is not None:
        return n
    spare = max(1, available_cpus() - 1)
    return min(spare, cpu_threads(value, load, own))


def refresh_torch_threads() -> int:
    """Inside :func:`torch_threads` (a training loop, every epoch): torch's pool at
    :func:`torch_thread_count` again, which follows the load of now (the pool's own
    threads not counted as load). Returns the count."""
    import torch

    current = torch.get_num_threads()
    count = torch_thread_count(own=current)
    if current != count:
        torch.set_num_threads(count)
    return count


class ThreadFollower:
    """Calls :func:`refresh_torch_threads` at most every ``interval`` seconds: a training
    loop calls it every step (a read of ``/proc/loadavg`` costs about 3 ms, so not every
    step of a few ms), so a job started mid-epoch takes the pool down within ``interval``.
    The first call refreshes."""

    def __init__(self, interval: float = 1.0) -> None:
        if not interval >= 0:
            raise ValueError(f"interval: expected seconds >= 0, got {interval!r}")
        self.interval = float(interval)
        self.last = -math.inf
        self.count: int | None = None

    def __call__(self, force: bool = False) -> int | None:
        """Refresh when due (or ``force``: at an epoch's start); returns the count set by
        the last refresh."""
        import time

        now = time.monotonic()
        if force or now - self.last >= self.interval:
            self.count = refresh_torch_threads()
            self.last = time.monotonic()
        return self.count


@contextlib.contextmanager
def torch_threads(n: int | None = None) -> Iterator[int]:
    """Context manager: torch's intra-op thread pool at ``n`` threads (None:
    :func:`torch_thread_count`) inside the block, the previous count restored after (also after
    an exception). Yields the count. Training loops of :mod:`jwarp.learn` run inside it."""
    import torch

    count = torch_thread_count() if n is None else n
    if isinstance(count, bool) or not isinstance(count, int) or count < 1:
        raise ValueError(f"n: expected a positive integer or None, got {n!r}")
    before = torch.get_num_threads()
    torch.set_num_threads(count)
    try:
        yield count
    finally:
        torch.set_num_threads(before)
