"""The one timing helper of every benchmark script (a script printing figures, never a
timed test).

:func:`measure` warms ``fn`` up (compiles, first touch), calibrates how many back-to-back
calls make one run of at least ``min_time`` seconds, then times ``repeats`` runs, each
closed by a device sync, and returns the median and the best (min) seconds per call.
:func:`machine` names the machine for the printed figures. This machine is shared and
noisy: compare variants as ratios of runs timed side by side in one process
(:func:`side_by_side`).
"""

from __future__ import annotations

import math
import platform
import statistics
import time
from dataclasses import dataclass
from typing import Any, Callable, Sequence

import warp as wp


@dataclass
class Timing:
    """Seconds per call: ``median`` and ``best`` (min) over ``runs`` runs of ``calls`` calls."""

    median: float
    best: float
    calls: int
    runs: int


def measure(fn: Callable[[], Any], device: Any = None, min_time: float = 0.2, repeats: int = 5,
            max_total: float = 20.0) -> Timing:
    """Median/best wall time of ``fn`` per call (see the module docstring); fewer runs (at
    least ``min(3, repeats)``) where ``repeats`` runs would exceed ``max_total`` seconds.
    ``device``: the Warp device to synchronize after each run (None: no sync)."""
    def sync() -> None:
        if device is not None:
            wp.synchronize_device(device)

    fn()
    sync()
    n, elapsed = 1, 0.0
    while True:  # calibrate: double until a batch of calls takes a tenth of min_time
        t0 = time.perf_counter()
        for _ in range(n):
            fn()
        sync()
        elapsed = time.perf_counter() - t0
        if elapsed >= min_time / 10 or n >= 1 << 20:
            break
        n *= 2
    per_call = max(elapsed / n, 1e-9)
    calls = max(1, math.ceil(min_time / per_call))
    runs = repeats
    if calls * per_call * runs > max_total:
        runs = max(min(3, repeats), int(max_total / (calls * per_call)))
    times = []
    for _ in range(runs):
        t0 = time.perf_counter()
        for _ in range(calls):
            fn()
        sync()
        times.append((time.perf_counter() - t0) / calls)
    return Timing(statistics.median(times), min(times), calls, runs)


def side_by_side(fns: Sequence[Callable[[], Any]], device: Any = None, min_time: float = 0.2,
                 rounds: int = 5) -> list[Timing]:
    """Time several variants interleaved (round k times every variant once), so a noisy
    neighbour slows all of them alike; returns one Timing per variant over the rounds."""
    per: list[list[float]] = [[] for _ in fns]
    for _ in range(rounds):
        for i, fn in enumerate(fns):
            t = measure(fn, device, min_time, repeats=1)
            per[i].append(t.median)
    return [Timing(statistics.median(v), min(v), 0, len(v)) for v in per]


def machine(device: Any = None) -> str:
    """The machine's name for printed figures: CPU model and core count, or the GPU's name."""
    if device is not None and str(device).startswith("cuda"):
        try:
            return wp.get_device(str(device)).name
        except Exception:  # noqa: BLE001 - a name only
            return str(device)
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    import os

    return f"{cpu} ({os.cpu_count()} cores)"
