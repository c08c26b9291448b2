"""Threads of jwarp's CPU-parallel work (issue 39, item 6; jwarp.core.threads): the count
follows JWARP_THREADS, else the CPUs this process may run on (its affinity mask) less the
load of other processes; torch training runs inside that count and the previous pool size
comes back after it; a bad JWARP_THREADS is a ValueError naming it."""

from __future__ import annotations

import os

import pytest

from jwarp.core import threads as T


def test_env_wins_and_bad_values_name_it(monkeypatch):
    monkeypatch.setenv(T.THREADS_ENV, "3")
    assert T.cpu_threads(load=50.0) == 3  # the user's count, whatever the load
    assert T.cpu_threads(" 5 ") == 5
    for bad in ["0", "-2", "two", "1.5"]:
        monkeypatch.setenv(T.THREADS_ENV, bad)
        with pytest.raises(ValueError, match=f"^{T.THREADS_ENV}: expected a positive integer"):
            T.cpu_threads()
    monkeypatch.setenv(T.THREADS_ENV, "")  # empty: as unset
    assert 1 <= T.cpu_threads() <= T.available_cpus()


def test_affinity_and_load(monkeypatch):
    monkeypatch.delenv(T.THREADS_ENV, raising=False)
    monkeypatch.setattr(T.os, "sched_getaffinity", lambda pid: {0, 1, 2, 3}, raising=False)
    monkeypatch.setattr(T.os, "cpu_count", lambda: 64)  # the machine's: not ours to use
    cpus = T.available_cpus()
    assert cpus <= 4
    # quiet (this process's own thread only): every CPU it may use
    assert T.cpu_threads(load=0.0) == cpus
    assert T.cpu_threads(load=1.0) == cpus
    # another process keeps one CPU busy: one fewer; a loaded machine: one
    assert T.cpu_threads(load=2.0) == max(1, cpus - 1)
    assert T.cpu_threads(load=40.0) == 1
    # the load average is read when not given (the threads runnable now: none here)
    monkeypatch.setattr(T, "runnable_others", lambda samples=3: 0)
    monkeypatch.setattr(T.os, "getloadavg", lambda: (30.0, 30.0, 30.0))
    assert T.cpu_threads() == 1
    monkeypatch.setattr(T.os, "getloadavg", lambda: (0.0, 0.0, 0.0))
    assert T.cpu_threads() == cpus


def test_available_cpus_is_the_affinity_mask():
    if not hasattr(os, "sched_getaffinity"):
        pytest.skip("no affinity mask on this platform")
    assert 1 <= T.available_cpus() <= len(os.sched_getaffinity(0))


def test_torch_threads_sets_and_restores():
    torch = pytest.importorskip("torch")
    before = torch.get_num_threads()
    with T.torch_threads(1) as n:
        assert n == 1 and torch.get_num_threads() == 1
    assert torch.get_num_threads() == before
    with pytest.raises(RuntimeError), T.torch_threads(1):
        raise RuntimeError("boom")
    assert torch.get_num_threads() == before
    with pytest.raises(ValueError, match="^n: expected a positive integer"), T.torch_threads(0):
        pass


def test_training_runs_at_jwarp_threads(monkeypatch):
    """train_ik's epochs and train_plan run with torch at JWARP_THREADS threads (read back
    from torch inside the training), and the caller's pool size comes back after."""
    torch = pytest.importorskip("torch")
    import importlib

    TI = importlib.import_module("jwarp.learn.train_ik")  # the modules (the package
    TP = importlib.import_module("jwarp.learn.train_plan")  # exports functions of the names)

    before = torch.get_num_threads()
    want = 1 if before != 1 else 2
    monkeypatch.setenv(T.THREADS_ENV, str(want))
    seen = []
    monkeypatch.setattr(TI, "_epochs", lambda *a: seen.append(torch.get_num_threads()) or
                        ("net", []))
    assert TI._run(object(), False, None) == ("net", [])
    monkeypatch.setattr(TP, "_train_plan", lambda *a: seen.append(torch.get_num_threads()) or
                        ("net", []))
    assert TP.train_plan(object(), object()) == ("net", [])
    assert seen == [want, want]
    assert torch.get_num_threads() == before


def test_warmup_jobs_follow_jwarp_threads(monkeypatch):
    import warp

    from jwarp.cli import warmup as W

    monkeypatch.setenv(T.THREADS_ENV, "1")
    seen = {}

    def force_load(device=None, modules=None, max_workers=None):
        seen["workers"] = max_workers

    monkeypatch.setattr(warp, "force_load", force_load)
    monkeypatch.setattr(W, "kernel_modules", lambda *a: [])
    W.warmup("cpu", robots=[], families=["fk"], progress=False)
    assert seen["workers"] == 0  # one job: no pool


def test_runnable_now_counts_a_job_the_average_has_not_seen(monkeypatch, tmp_path):
    """A job started seconds ago: the 1-minute average is still low, the threads runnable
    right now (/proc/loadavg's 4th field, the reader included) are not; the least of a
    few reads counts (a thread that ran for an instant is no load)."""
    monkeypatch.delenv(T.THREADS_ENV, raising=False)
    monkeypatch.setattr(T.os, "sched_getaffinity", lambda pid: set(range(8)), raising=False)
    monkeypatch.setattr(T, "available_cpus", lambda: 8)
    monkeypatch.setattr(T.os, "getloadavg", lambda: (0.2, 0.1, 0.1))
    f = tmp_path / "loadavg"
    monkeypatch.setattr(T, "LOADAVG", str(f))
    monkeypatch.setattr(T, "own_runnable", lambda: 1)  # the reader alone
    f.write_text("0.20 0.10 0.10 4/300 12345\n")  # this reader and 3 threads of a new job
    assert T.runnable_others() == 3
    assert T.cpu_threads() == 5
    f.write_text("0.20 0.10 0.10 1/300 12345\n")  # quiet: every CPU
    assert T.runnable_others() == 0 and T.cpu_threads() == 8
    monkeypatch.setattr(T.os, "getloadavg", lambda: (6.0, 6.0, 6.0))  # the average wins
    assert T.cpu_threads() == 3
    f.write_text("garbage")
    assert T.runnable_others() is None
    monkeypatch.setattr(T.os, "getloadavg", lambda: (0.0, 0.0, 0.0))
    assert T.cpu_threads() == 8


def test_refresh_follows_the_load_inside_a_training(monkeypatch):
    """refresh_torch_threads (every epoch of train_ik / train_plan) sets torch's pool to
    cpu_threads() of now; the pool of before the block comes back after it."""
    torch = pytest.importorskip("torch")
    before = torch.get_num_threads()
    monkeypatch.setenv(T.THREADS_ENV, "2")
    with T.torch_threads() as n:
        assert n == 2 == torch.get_num_threads()
        monkeypatch.setenv(T.THREADS_ENV, "1")  # the machine got busy
        assert T.refresh_torch_threads() == 1 == torch.get_num_threads()
    assert torch.get_num_threads() == before


def test_own_threads_are_no_load(monkeypatch, tmp_path):
    """This process's runnable threads (a torch pool spinning at a barrier) are not other
    processes' load, now or in the load average (the pool's size passed as ``own``)."""
    monkeypatch.delenv(T.THREADS_ENV, raising=False)
    assert T.own_runnable() >= 1  # the caller runs
    monkeypatch.setattr(T, "available_cpus", lambda: 8)
    f = tmp_path / "loadavg"
    monkeypatch.setattr(T, "LOADAVG", str(f))
    f.write_text("3.00 3.00 3.00 4/300 12345\n")
    monkeypatch.setattr(T, "own_runnable", lambda: 3)  # the reader and 2 pool threads
    assert T.runnable_others() == 1
    monkeypatch.setattr(T, "own_runnable", lambda: 4)
    assert T.runnable_others() == 0
    # a training at 3 threads made the load of 3: no other load
    assert T.cpu_threads(load=3.0, own=3) == 8
    assert T.cpu_threads(load=3.0) == 6  # counted as one thread: 2 CPUs taken
    monkeypatch.setattr(T.os, "getloadavg", lambda: (3.0, 3.0, 3.0))
    assert T.cpu_threads(own=3) == 8


def test_torch_pool_leaves_a_cpu_spare(monkeypatch):
    """Unset JWARP_THREADS: torch's training pool is cpu_threads() but at most the CPUs
    less one (an OpenMP pool on every CPU stalls as soon as another thread wants one);
    at least 1; JWARP_THREADS wins, also on every CPU."""
    monkeypatch.delenv(T.THREADS_ENV, raising=False)
    for cpus, load, want in [(2, 0.0, 1), (2, 1.0, 1), (8, 0.0, 7), (8, 1.0, 7), (8, 3.0, 6),
                             (8, 30.0, 1), (1, 0.0, 1)]:
        monkeypatch.setattr(T, "available_cpus", lambda c=cpus: c)
        assert T.torch_thread_count(load=load) == want, (cpus, load)
    monkeypatch.setattr(T, "available_cpus", lambda: 2)
    monkeypatch.setenv(T.THREADS_ENV, "2")
    assert T.torch_thread_count(load=30.0) == 2
    monkeypatch.setenv(T.THREADS_ENV, "all")
    with pytest.raises(ValueError, match=f"^{T.THREADS_ENV}: expected a positive integer"):
        T.torch_thread_count()


def test_simulated_load_sets_the_training_pool(monkeypatch):
    """A monkeypatched load reading (no JWARP_THREADS): the pool train_ik's epochs run
    at: one thread on a busy 2-CPU machine, 7 on a quiet 8-CPU one, 6 beside a job of
    2 runnable threads that the 1-minute average has not seen yet."""
    torch = pytest.importorskip("torch")
    import importlib

    TI = importlib.import_module("jwarp.learn.train_ik")
    monkeypatch.delenv(T.THREADS_ENV, raising=False)
    seen = []
    monkeypatch.setattr(TI, "_epochs", lambda *a: seen.append(torch.get_num_threads()) or
                        ("net", []))
    before = torch.get_num_threads()
    for cpus, avg, now, want in [(2, 3.0, 0, 1), (8, 0.0, 0, 7), (8, 0.1, 2, 6),
                                 (2, 0.0, 1, 1)]:
        monkeypatch.setattr(T, "available_cpus", lambda c=cpus: c)
        monkeypatch.setattr(T.os, "getloadavg", lambda a=avg: (a, a, a))
        monkeypatch.setattr(T, "runnable_others", lambda samples=3, n=now: n)
        TI._run(object(), False, None)
        assert seen[-1] == want, (cpus, avg, now)
    assert torch.get_num_threads() == before


def test_follower_refreshes_at_most_every_interval(monkeypatch):
    """ThreadFollower (every training step): refreshes on the first call, when forced
    (an epoch's start) and once ``interval`` seconds passed, not in between; inside a
    training the pool follows a load that came mid-epoch."""
    import time

    torch = pytest.importorskip("torch")
    clock = [100.0]
    monkeypatch.setattr(time, "monotonic", lambda: clock[0])
    calls = []
    real = T.refresh_torch_threads
    monkeypatch.setattr(T, "refresh_torch_threads", lambda: calls.append(clock[0]) or real())
    monkeypatch.setenv(T.THREADS_ENV, "2")
    before = torch.get_num_threads()
    with T.torch_threads():
        follow = T.ThreadFollower(1.0)
        assert follow() == 2 and len(calls) == 1
        monkeypatch.setenv(T.THREADS_ENV, "1")  # a job started mid-epoch
        clock[0] += 0.5
        assert follow() == 2 and torch.get_num_threads() == 2 and len(calls) == 1
        clock[0] += 0.6
        assert follow() == 1 == torch.get_num_threads() and len(calls) == 2
        assert follow(force=True) == 1 and len(calls) == 3
    assert torch.get_num_threads() == before
    with pytest.raises(ValueError, match="^interval"):
        T.ThreadFollower(-1.0)
