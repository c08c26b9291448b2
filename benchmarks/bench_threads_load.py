#!/usr/bin/env python
"""Training beside a second process (issue 39 item 6): the README's ``jwarp train ik``
smoke run, alone and beside one CPU-bound process, side by side.

    python benchmarks/bench_threads_load.py                 # 3 rounds, the default threads
    python benchmarks/bench_threads_load.py --threads 2     # JWARP_THREADS=2 (torch's own count here)
    python benchmarks/bench_threads_load.py --rounds 5 --epochs 3 --burners 1

Each round runs the training once alone and once beside ``--burners`` processes of
``while True: pass`` (started 2 s before, killed after), the order alternating round by
round (alone first in even rounds). Every run is a fresh process (``python -m jwarp.cli
train ik --robot planar5 --world random --n-bps 256 --n-worlds 2 --epochs E``, kernels
cached), timed from outside: wall time, and CPU time (user + system, all its threads,
``os.wait4``). Inside, the threads torch's pool had at every epoch (read from torch in the
training's callback) and the training rate of the epochs. Right after each training, as
the reference of the CPU share one thread gets in that condition, a pure-Python loop of
``--loop`` additions (one thread, the same burners running): its wall time.

Printed per run, then min / median per condition and the ratios loaded / alone of the
medians: wall, CPU time, the one-thread loop. The machine's 1-minute load average and the
threads runnable (``/proc/loadavg``) before each run are printed: on a shared machine other
jobs take their share too, say so beside the figures.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)

CHILD = r"""
import json, sys, time
t0 = time.perf_counter()
import importlib
import torch
import jwarp.core.threads as JT
TI = importlib.import_module("jwarp.learn.train_ik")  # the package exports a function of the name
from jwarp.cli.main import main
seen = []
orig = JT.refresh_torch_threads
def refresh():
    n = orig()
    seen.append((n, torch.get_num_threads(), torch.get_num_interop_threads()))
    return n
JT.refresh_torch_threads = refresh  # what ThreadFollower calls, every epoch and second
rates = []
orig_line = TI._line
def line(rec, epochs, supervised):
    if rec.get("samples_per_s"):
        rates.append(rec["samples_per_s"])
    return orig_line(rec, epochs, supervised)
TI._line = line
rc = main(sys.argv[2:])
blas = []
try:
    from threadpoolctl import threadpool_info
    blas = [(i["internal_api"], i["num_threads"]) for i in threadpool_info()]
except Exception:
    pass
with open(sys.argv[1], "w") as f:
    json.dump({"rc": rc, "threads": seen, "rates": rates, "pools_after": blas,
               "inside_s": time.perf_counter() - t0}, f)
"""

BURN = "while True: pass"


def loadavg() -> str:
    try:
        with open("/proc/loadavg") as f:
            a = f.read().split()
        return f"load {a[0]} runnable {a[3]}"
    except OSError:
        return "load ?"


def one_loop(n: int) -> float:
    t = time.perf_counter()
    s = 0
    for i in range(n):
        s += i
    return time.perf_counter() - t


def run_training(epochs: int, env: dict, out: str) -> dict:
    cmd = [sys.executable, "-c", CHILD, out, "train", "ik", "--robot", "planar5", "--world",
           "random", "--n-bps", "256", "--n-worlds", "2", "--epochs", str(epochs), "--out",
           os.path.join(os.path.dirname(out), "p5.pt")]
    t = time.perf_counter()
    p = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    _, status, ru = os.wait4(p.pid, 0)
    wall = time.perf_counter() - t
    p.returncode = os.waitstatus_to_exitcode(status)
    if p.returncode != 0:
        raise RuntimeError(f"training failed (exit {p.returncode}): {' '.join(cmd[3:])}")
    with open(out) as f:
        info = json.load(f)
    info.update(wall=wall, cpu=ru.ru_utime + ru.ru_stime, nivcsw=ru.ru_nivcsw)
    return info


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--epochs", type=int, default=3)
    ap.add_argument("--burners", type=int, default=1, help="CPU-bound processes beside it")
    ap.add_argument("--threads", default=None, help="JWARP_THREADS for the training (default unset)")
    ap.add_argument("--loop", type=int, default=20_000_000, help="additions of the one-thread loop")
    a = ap.parse_args(argv)
    env = dict(os.environ)
    env["PYTHONPATH"] = ROOT + os.pathsep + env.get("PYTHONPATH", "")
    env.pop("JWARP_THREADS", None)
    if a.threads is not None:
        env["JWARP_THREADS"] = str(a.threads)
    print(f"cpus {os.cpu_count()}, affinity {len(os.sched_getaffinity(0))}, JWARP_THREADS "
          f"{a.threads or 'unset'}, {a.burners} burner(s), {a.epochs} epochs, {a.rounds} rounds")
    res: dict[str, list[dict]] = {"alone": [], "loaded": []}
    with tempfile.TemporaryDirectory() as tmp:
        run_training(1, env, os.path.join(tmp, "warm.json"))  # kernels compiled, files cached
        for r in range(a.rounds):
            order = ["alone", "loaded"] if r % 2 == 0 else ["loaded", "alone"]
            for cond in order:
                burners = []
                if cond == "loaded":
                    burners = [subprocess.Popen([sys.executable, "-c", BURN])
                               for _ in range(a.burners)]
                    time.sleep(2.0)
                before = loadavg()
                try:
                    info = run_training(a.epochs, env, os.path.join(tmp, f"{cond}{r}.json"))
                    info["loop"] = one_loop(a.loop)
                finally:
                    for b in burners:
                        b.kill()
                        b.wait()
                info["before"] = before
                res[cond].append(info)
                thr = sorted({t[0] for t in info["threads"]})
                rates = ", ".join(f"{x / 1000:.1f}k" for x in info["rates"])
                print(f"round {r + 1} {cond:6s} {before}: wall {info['wall']:.2f} s, cpu "
                      f"{info['cpu']:.2f} s, torch threads {thr} (interop "
                      f"{info['threads'][0][2] if info['threads'] else '?'}), samples/s "
                      f"[{rates}], involuntary switches {info['nivcsw']}, one-thread loop "
                      f"{info['loop']:.2f} s", flush=True)
                time.sleep(1.0)
    med = {}
    for cond, runs in res.items():
        for key in ("wall", "cpu", "loop"):
            v = [x[key] for x in runs]
            med[cond, key] = statistics.median(v)
            print(f"{cond:6s} {key:4s} min {min(v):.2f} median {statistics.median(v):.2f} s")
    for key in ("wall", "cpu", "loop"):
        print(f"loaded / alone ({key}, medians): {med['loaded', key] / med['alone', key]:.2f}x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
