"""Every stage respects the call's deadline (issue 45): the shortening is skipped when too
little of the time limit is left, its check calls go in chunks with the deadline asked
before each (a step overruns it by at most one chunk), a path shortened only partly is
still certified (re-checked here by the independent verifier), and explain() gives the
cheap "out of time" reason once the deadline has passed (no diagnosis check)."""

from __future__ import annotations

import time

import numpy as np
import pytest
from test_plan_shorten import independent_feasible
from worlds import block_world_2d

from jwarp.solvers import planning as PL
from jwarp.solvers.planning import planner as PM
from jwarp.solvers.planning import shorten as SH
from jwarp.world.motion import MotionCheck

S4 = np.array([1.2, 0.0, 0.0, 0.0])
G4 = np.array([-1.2, 0.0, 0.0, 0.0])
#: three problems: 0 a detour of the multi-starts, 1 the straight line, 2 the fallback's
STARTS = np.stack([S4, np.array([2.0, 1.0, 0.0, 0.0]), S4 * 0.95])
GOALS = np.stack([G4, np.array([2.0, -1.0, 0.0, 0.0]), G4 * 0.95])
OPTS = dict(n_starts=8, iterations=300, step=0.05, seed=0, n_substeps=8,
            weights=PL.PathWeights(length=0.05), fallback="rrt")


@pytest.fixture(scope="module")
def world():
    return block_world_2d()


class Clock:
    """A fake ``time.perf_counter``: it moves only by ``tick`` seconds per check call."""

    def __init__(self, monkeypatch, tick: float = 1.0) -> None:
        self.now, self.tick, self.calls = 1000.0, tick, 0
        monkeypatch.setattr(time, "perf_counter", lambda: self.now)

    def advance(self) -> None:
        self.calls += 1
        self.now += self.tick


def _detours(k: int) -> np.ndarray:
    """k copies of a detour over a wall at x in (1.5, 2.5) below y 0.25."""
    path = np.array([[0.0, 0.0], [1.0, 1.0], [2.0, 1.0], [3.0, 1.0], [4.0, 0.0]])
    return np.repeat(path[None], k, axis=0)


def _wall(segs):
    u = np.linspace(0, 1, 201)[None, :, None]
    q = segs[:, :1] + u * (segs[:, 1:] - segs[:, :1])
    hit = (np.abs(q[..., 0] - 2.0) < 0.5) & (q[..., 1] < 0.25)
    return ~hit.any(axis=1)


def _length(p):
    return float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum())


# ------------------------------------------------------------------ shortcut_paths
def test_chunks_stop_before_the_deadline(monkeypatch):
    """chunk=1 path per call, each call 1 s of a fake clock, deadline 2.5 s away: two
    calls (the third would end after it at the pace so far); those two paths take their
    proven jumps, the others stay as they were; every segment proven by the check."""
    clock = Clock(monkeypatch)
    rows_seen = []

    def check(segs, per, rows):
        clock.advance()
        rows_seen.append((np.array(rows), per))
        return _wall(segs[rows])

    paths = _detours(5)
    out = SH.shortcut_paths(paths, check, rounds=4, deadline=clock.now + 2.5, chunk=1)
    assert clock.calls == 2
    assert clock.now <= 1000.0 + 2.5  # not overrun
    # each call one path's list (chunk 1), the first path's, then the second's
    assert [np.unique(r // per).tolist() for r, per in rows_seen] == [[0], [1]]
    shortened = [k for k in range(5) if _length(out[k]) < _length(paths[k]) - 1e-9]
    assert shortened == [0, 1]
    for k in range(2, 5):
        np.testing.assert_allclose(out[k], SH.corners(paths[k]))
    for p in out:  # start and goal kept; every segment proven
        np.testing.assert_allclose(p[[0, -1]], paths[0][[0, -1]])
        assert _wall(np.stack([p[:-1], p[1:]], 1)).all()


def test_chunks_without_a_deadline_are_one_call():
    """No deadline: the two-argument call over every path at once (as before)."""
    calls = []

    def check(segs, per):
        calls.append(len(segs))
        return _wall(segs)

    paths = _detours(3)
    a = SH.shortcut_paths(paths, check, rounds=1, chunk=1)
    b = SH.shortcut_paths(paths, lambda s, p: _wall(s), rounds=1)
    assert len(calls) >= 1
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x, y)


def test_chunked_result_is_the_one_calls_with_time_left(monkeypatch):
    """With time to spare the chunked calls shorten exactly as the single call."""
    def check3(segs, per, rows):
        return _wall(segs[rows])

    paths = _detours(4)
    a = SH.shortcut_paths(paths, check3, rounds=3, deadline=time.perf_counter() + 100.0,
                          chunk=3)
    b = SH.shortcut_paths(paths, lambda s, p: _wall(s), rounds=3)
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x, y)


def test_pace():
    pace = SH.Pace()
    assert pace.fits(10**9, None) and pace.fits(10**9, time.perf_counter() + 1.0)
    assert not pace.fits(1, time.perf_counter() - 1.0)
    pace.seconds, pace.rows = 1.0, 10  # 0.1 s per row
    assert pace.fits(5, time.perf_counter() + 1.0)
    assert not pace.fits(50, time.perf_counter() + 1.0)


# ------------------------------------------------------------------ the planner
@pytest.fixture()
def solved(world):
    pl = PL.Planner("planar4", world, 3, PL.PlanOptions(shorten=0, **OPTS))
    res = pl.plan(STARTS, GOALS)
    assert res.feasible.all() and (res.length_cost[[0, 2]] > PM.NEAR_STRAIGHT).all()
    pl.options.shorten = 4
    pl.options.shorten_budget = None
    return pl, res


def _count_checks(monkeypatch, clock=None):
    """The MotionCheck.check calls: per call "shortcut" (a call of shortcut lists,
    ``group``) or "certify", and its rows."""
    calls = []
    original = MotionCheck.check

    def counting(self, *args, **kwargs):
        calls.append(("shortcut" if kwargs.get("group") else "certify", kwargs.get("rows")))
        r = original(self, *args, **kwargs)
        if clock is not None:
            clock.advance()
        return r

    monkeypatch.setattr(MotionCheck, "check", counting)
    return calls


def test_shortening_skipped_with_little_time_left(solved, monkeypatch):
    pl, res = solved
    path = res.path.copy()
    calls = _count_checks(monkeypatch)
    pl.options.time_limit = 10.0
    left = 0.9 * PM.SHORTEN_MIN_LEFT * 10.0
    pl._shorten(pl._buffers.objective.n_sub, res, deadline=time.perf_counter() + left)
    assert not calls
    np.testing.assert_array_equal(res.path, path)
    # enough left: it shortens
    pl._shorten(pl._buffers.objective.n_sub, res, deadline=time.perf_counter() + 9.0)
    assert calls and (res.length_cost[[0, 2]] < res.length_before[[0, 2]]).all()


def test_shortened_paths_proven_as_built(solved, monkeypatch, world):
    """The endpoint margins equal to the others: the shortcut calls' proofs are the whole
    shortened path's (every corner a waypoint), so no certification call is made; every
    path passes the independent check. With a lower endpoint margin, it is certified."""
    pl, res = solved
    assert pl._shortcuts_prove()
    calls = _count_checks(monkeypatch)
    pl._shorten(pl._buffers.objective.n_sub, res, deadline=None)
    assert calls and all(k == "shortcut" for k, _ in calls)
    assert (res.length_cost[[0, 2]] < res.length_before[[0, 2]]).all()
    for p in res.path:
        assert independent_feasible(pl.robot, world, p)
    for o, want in ((dict(margin=0.01, endpoint_margin=0.005), False),
                    (dict(margin=0.01, endpoint_margin=0.01), True),
                    (dict(margin=0.01, self_margin=0.02), False),
                    (dict(margin=0.01, self_margin=0.01), True)):
        assert PL.Planner("planar4", world, 1, PL.PlanOptions(**o))._shortcuts_prove() is want


def test_shortening_cut_short_keeps_certified_paths(solved, monkeypatch, world):
    """A fake clock, 1 s per check call, SHORTEN_CHUNK 1 path, the deadline 3.3 s away
    (the shortcut rounds end at 80 % of it, 2.64 s): three shortcut calls (the next would
    end after 2.64 s at their pace), then the certification of the first path; the
    second's would end after the deadline: not made, so that path stays as it was
    (with time left it is shortened); every path passes the independent check."""
    pl, res = solved
    path = res.path.copy()
    length = res.length_cost.copy()
    full = PL.Planner("planar4", world, 3, PL.PlanOptions(shorten=0, **OPTS))
    ref = full.plan(STARTS, GOALS)
    full.options.shorten, full.options.shorten_budget = 4, None
    monkeypatch.setattr(PM, "SHORTEN_CHUNK", 1)
    # the shortened paths certified again (as where the endpoint margins are lower)
    monkeypatch.setattr(PM.Planner, "_shortcuts_prove", lambda self: False)
    clock = Clock(monkeypatch)
    calls = _count_checks(monkeypatch, clock)
    deadline = clock.now + 3.3
    pl._shorten(pl._buffers.objective.n_sub, res, deadline=deadline)
    assert [k for k, _ in calls] == ["shortcut"] * 3 + ["certify"]
    assert all(r is not None for _, r in calls)  # chunks: rows of the step's lists
    assert clock.now <= deadline + 1.0  # overrun by at most one call
    assert res.length_cost[0] < length[0]  # certified in time
    np.testing.assert_array_equal(res.path[1:], path[1:])  # the line; not certified in time
    for p in res.path:
        assert independent_feasible(pl.robot, world, p)
    # the same with time to spare: the third problem's path is shortened too
    full._shorten(full._buffers.objective.n_sub, ref, deadline=clock.now + 1000.0)
    assert ref.length_cost[2] < length[2]
    for p in ref.path:
        assert independent_feasible(pl.robot, world, p)


def test_time_limit_in_plan_ends_on_time(world):
    """The whole plan: wall time near the limit, every returned path certified."""
    o = dict(OPTS, time_limit=0.5)
    res = PL.plan("planar4", world, STARTS, GOALS, **o)
    assert res.wall_time < 0.5 + 0.5
    for b in np.nonzero(res.feasible)[0]:
        assert independent_feasible(PL.Planner("planar4", world, 1).robot, world, res.path[b])


# ------------------------------------------------------------------ explain
def test_explain_after_the_deadline_is_cheap(world, monkeypatch):
    pl = PL.Planner("planar4", world, 3, PL.PlanOptions(
        n_starts=1, iterations=1, step=0.05, seed=0, n_substeps=8, fallback=None))
    res = pl.plan(STARTS, GOALS)
    bad = np.nonzero(~res.feasible)[0]
    assert len(bad) and res.feasible[1]
    calls = _count_checks(monkeypatch)
    diag = pl.explain(res)  # no deadline: a check diagnoses them
    assert calls
    assert all(diag[i] != PM.NOT_DIAGNOSED and "collision" in diag[i] for i in bad)
    assert diag[1] == "feasible"
    calls.clear()
    assert pl.explain(res, deadline=time.perf_counter() + 100.0) == diag
    calls.clear()
    late = pl.explain(res, deadline=time.perf_counter() - 1.0)
    assert not calls
    assert late[1] == "feasible"
    assert all(late[i] == PM.NOT_DIAGNOSED for i in bad)
    # the fallback's notes are still appended
    res.fallback_notes = np.array(["", "", ""], dtype=object)
    res.fallback_notes[bad[0]] = "RRT-Connect not run: no time left"
    late = pl.explain(res, deadline=time.perf_counter() - 1.0)
    assert late[bad[0]] == f"{PM.NOT_DIAGNOSED}; fallback: RRT-Connect not run: no time left"


def test_plan_out_of_time_says_so(world):
    res = PL.plan("planar4", world, S4, G4, time_limit=1e-4, n_starts=8, iterations=300,
                  step=0.05, seed=0, n_substeps=8, fallback=None)
    assert not res.feasible[0] and res.stop_reason == "time_limit"
    assert res.reasons[0] == PM.NOT_DIAGNOSED


def test_round_setup_stops_at_the_deadline(monkeypatch):
    """A round's host set-up (points, lengths, gains) looks at the deadline every
    SETUP_CHUNK paths: with 1 s per path on a fake clock and the deadline 40 s away, 64 of
    70 paths are set up (two chunks), none is checked after it, and every path comes back
    as it was (nothing proven in time)."""
    clock = Clock(monkeypatch)
    monkeypatch.setattr(SH, "SETUP_CHUNK", 32)
    gains = SH._gains
    seen = []

    def slow_gains(p, c):
        seen.append(1)
        clock.now += 1.0
        return gains(p, c)

    monkeypatch.setattr(SH, "_gains", slow_gains)
    checks = []
    paths = _detours(70)
    out = SH.shortcut_paths(paths, lambda segs, per, rows=None: checks.append(1) or
                            _wall(segs), rounds=4, deadline=clock.now + 40.0, chunk=8)
    assert len(seen) == 64 and not checks
    for k in range(70):
        np.testing.assert_allclose(out[k], SH.corners(paths[k]))


def test_last_iteration_paced_to_the_deadline(world):
    """The optimiser treats an iteration that would end after its deadline at the last
    one's pace as past it: with 0.1 s per iteration (a slow callback) and a 0.35 s limit
    its last (check-only) iteration starts by 0.3 s, so the call ends well before
    0.5 s (unpaced: a step at 0.3 s, the last iteration at 0.4 s, the end at 0.5 s)."""
    o = dict(OPTS, fallback=None, shorten=0, n_starts=2, time_limit=0.35,
             straight_first=False, callback=lambda it, paths: time.sleep(0.1))
    PL.plan("planar4", world, S4, G4, **dict(o, time_limit=None, iterations=2))  # warm
    t = time.perf_counter()
    res = PL.plan("planar4", world, S4, G4, **o)
    took = time.perf_counter() - t
    assert res.stop_reason in ("time_limit", "solved")
    assert took < 0.47, took


def test_no_optimiser_when_its_time_is_spent_before_it(world):
    """The optimiser's share spent before its first iteration (the starts proven as
    drawn first): no optimiser (its first check would repeat the starts' checks); the
    unsolved problems come out "none", not feasible, "time_limit"."""
    res = PL.plan("planar4", world, STARTS, GOALS, **dict(OPTS, fallback=None,
                                                         time_limit=1e-4))
    assert "optimizer" not in res.timings and "starts" in res.timings
    assert res.stop_reason == "time_limit"
    assert (res.stage[~res.feasible] == "none").all()
    assert (res.iterations == 0).all() and (res.all_iterations == 0).all()
    assert np.isnan(res.solved_at[~res.feasible]).all()
