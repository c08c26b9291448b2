"""The one timing helper of every benchmark script (a script printing figures, never a
timed test).

:func:`measure` warms ``fn`` up (compiles, first touch), calibrates how many back-to-back
calls make one run of at least ``min_time`` seconds, then times ``repeats`` runs, each
closed by a device sync, and returns the median and the best (min) seconds per call.
:func:`machine` names the machine for the printed figures. This machine is shared and
noisy: compare variants as ratios of runs timed side by side in one process
(:func:`side_by_side`).

Calls too slow or too stateful to repeat back to back (a whole IK solve, a calibration)
are timed one call per run with :func:`each_run` (interleaved like :func:`side_by_side`,
each call prepared untimed and closed by a device sync); :func:`summarize` and
:func:`speedup` turn such per-run seconds into median/min and ratios. :func:`stopwatch`
is for the duration of a whole study or section run once (progress, not a figure), and
:func:`run_sections` runs the sections of a script that prints its figures as JSON
(its options added by :func:`section_options`).
"""

from __future__ import annotations

import json
import math
import platform
import statistics
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import warp as wp


@dataclass
class Timing:
    """Seconds per call: ``median`` and ``best`` (min) over ``runs`` runs of ``calls`` calls."""

    median: float
    best: float
    calls: int
    runs: int

    def figures(self, scale: float = 1.0) -> dict:
        """``{"min": best, "median": median}`` times ``scale`` (1e3: milliseconds), for JSON."""
        return {"min": self.best * scale, "median": self.median * scale}


def _sync(device: Any) -> None:
    if device is not None:
        wp.synchronize_device(device)


def measure(fn: Callable[[], Any], device: Any = None, min_time: float = 0.2, repeats: int = 5,
            max_total: float = 20.0) -> Timing:
    """Median/best wall time of ``fn`` per call (see the module docstring); fewer runs (at
    least ``min(3, repeats)``) where ``repeats`` runs would exceed ``max_total`` seconds.
    ``device``: the Warp device to synchronize after each run (None: no sync)."""
    fn()
    _sync(device)
    n, elapsed = 1, 0.0
    while True:  # calibrate: double until a batch of calls takes a tenth of min_time
        t0 = time.perf_counter()
        for _ in range(n):
            fn()
        _sync(device)
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
        _sync(device)
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


def summarize(seconds: Sequence[float]) -> Timing:
    """The Timing (median, best = min) of per-run seconds, one call per run."""
    return Timing(statistics.median(seconds), min(seconds), 1, len(seconds))


@dataclass
class Runs:
    """One variant's calls timed by :func:`each_run`: ``seconds[k]`` and ``results[k]`` of
    round k + 1."""

    seconds: list[float]
    results: list[Any]

    @property
    def timing(self) -> Timing:
        return summarize(self.seconds)


def each_run(variants: Sequence[Callable[[int], Callable[[], Any]]], rounds: int,
             device: Any = None) -> list[Runs]:
    """Time single calls, interleaved: in round r every variant's ``make(r)`` prepares one
    call untimed (reseed, pick the input: r is the round, 1..``rounds``) and returns it;
    that call alone is timed, between two syncs of ``device`` (None: no sync), and its
    result kept. Round 0 is an untimed warm-up (compiles, first touch). One Runs per
    variant."""
    out = [Runs([], []) for _ in variants]
    for r in range(rounds + 1):
        for make, runs in zip(variants, out):
            call = make(r)
            _sync(device)
            t0 = time.perf_counter()
            result = call()
            _sync(device)
            if r:
                runs.seconds.append(time.perf_counter() - t0)
                runs.results.append(result)
    return out


def speedup(base: Sequence[float], new: Sequence[float]) -> dict:
    """How many times faster ``new`` is than ``base``, from seconds (per call or per unit of
    work) of runs timed side by side: ``per_run`` (base[k] / new[k]), ``of_medians`` and
    ``of_bests``."""
    def div(a: float, b: float) -> float:
        return a / b if b else math.inf

    return {"per_run": [div(b, n) for b, n in zip(base, new)],
            "of_medians": div(statistics.median(base), statistics.median(new)),
            "of_bests": div(min(base), min(new))}


def stopwatch() -> Callable[[], float]:
    """Seconds since this call, read by calling the result: the duration of something run
    once (a whole study, a section), not a benchmark figure."""
    t0 = time.perf_counter()
    return lambda: time.perf_counter() - t0


def section_options(parser: Any, sections: str) -> None:
    """Add the options :func:`run_sections` reads to a script's ``parser``: ``--only``
    (comma-separated sections, default ``sections``), ``--quick`` (tiny sizes: the smoke
    test; the script applies them) and ``--json FILE``."""
    parser.add_argument("--only", default=sections)
    parser.add_argument("--quick", action="store_true", help="tiny sizes (smoke test)")
    parser.add_argument("--json", default=None, metavar="FILE",
                        help="also write the figures as JSON")


def run_sections(parser: Any, sections: dict, args: Any, note: str, **fields: Any) -> dict:
    """Run a script's sections and print their figures: first the line ``machine: <the
    machine of args.device>; CPU <the CPU>; warp <version>; <note>``, then each of the
    comma-separated ``args.only`` of ``sections`` (name -> function of ``args``), in order,
    as JSON under ``== name (its wall time)``; an unknown name is a ``parser`` error.
    Returns the figures (device, machine, cpu, warp, ``fields``, then one key a section),
    also written to ``args.json`` (atomically) where that is set."""
    result: dict = {"device": str(args.device), "machine": machine(args.device),
                    "cpu": machine("cpu"), "warp": wp.config.version, **fields}
    print(f"machine: {result['machine']}; CPU {result['cpu']}; warp {result['warp']}; {note}",
          flush=True)
    for name in [s.strip() for s in args.only.split(",") if s.strip()]:
        if name not in sections:
            parser.error(f"--only: unknown section '{name}' (known: {', '.join(sections)})")
        elapsed = stopwatch()
        result[name] = sections[name](args)
        print(f"== {name} ({elapsed():.1f} s)")
        print(json.dumps(result[name], indent=1, default=float), flush=True)
    if args.json:
        from jwarp.utils.atomic import atomic_write_text

        atomic_write_text(args.json, json.dumps(result, indent=1, default=float) + "\n")
    return result


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
