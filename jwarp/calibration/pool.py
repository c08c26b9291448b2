"""Configuration files of experimental design: candidate pools and measurement plans (CSV).

A pool or plan is a samples file without observations: one header row, one row per
configuration, the robot's joint columns (rad or m) and the measurement's per-sample
columns (contact: ``pair``), exactly as in a samples CSV
(:func:`~jwarp.calibration.files.columns`). The measurement's observed columns may
be present and are ignored (a samples file or a ``simulate-campaign`` output is a valid
pool); any other column is an error, as is a missing one. Errors name the file's option
(``what``, e.g. ``--candidates``), the column and, for values, the line.

Feasible pools (:func:`draw_pool`, :func:`check_configurations`): every drawn pool keeps
only configurations inside the joint limits (box and linear) whose collision spheres keep
more than ``margin`` [m] from each other (the robot's self-collision pairs, checked as
``jwarp sample-poses`` checks them: :class:`~jwarp.calibration.design.poses.PoseSampler`;
contact setups leave the contact bodies' own frame pairs out) and, with a ``world``, from
the world (:func:`jwarp.world.collision.min_distances`). Rejected draws are replaced by
more draws until the pool has its size or ``max_draws`` are spent; the result says how
many were dropped and why. A robot without collision spheres (or without self-collision
sphere pairs) cannot be checked: the result carries a warning saying so.
"""

from __future__ import annotations

import csv
import dataclasses
import io
import math
import os
import time
import warnings
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from jwarp.calibration.files import Samples, numeric_rows, read_header, read_text
from jwarp.core.types import ArrayLike
from jwarp.model import RobotModel
from jwarp.model.measurement import Measurement
from jwarp.utils.atomic import atomic_write_text
from jwarp.utils.checks import ArgumentError, check_int

if TYPE_CHECKING:
    from jwarp.world.sdf import World


def pool_columns(robot: RobotModel, meas: Measurement) -> list[str]:
    """The columns of a pool / plan: joints, then the measurement's per-sample columns."""
    return [j.name for j in robot.joints] + list(meas.meta_names)


def read_configurations(path: str | os.PathLike, robot: RobotModel, meas: Measurement,
                        what: str = "--candidates") -> Samples:
    """Read a pool / plan CSV (module docstring) -> Samples with q (S, n_dof), meta and an
    empty y (S, 0); ``lines`` holds each row's line number."""
    text, _ = read_text(path, what)
    return parse_configurations(text, robot, meas, what, os.fspath(path))


def parse_configurations(text: str, robot: RobotModel, meas: Measurement,
                         what: str = "--candidates", where: str = "") -> Samples:
    """Parse the text of a pool / plan CSV (see :func:`read_configurations`)."""
    label = f"{what}: {where}" if where else what
    if text.startswith("\ufeff"):
        text = text[1:]
    reader = csv.reader(io.StringIO(text, newline=""))
    header, header_line = read_header(reader, label, f"expected a header row with the columns "
                                                    f"{pool_columns(robot, meas)}")
    need = pool_columns(robot, meas)
    dup = sorted({h for h in header if header.count(h) > 1})
    if dup:
        raise ValueError(f"{label}: duplicate column '{dup[0]}'")
    missing = [c for c in need if c not in header]
    if missing:
        raise ValueError(f"{label}: missing column '{missing[0]}' (robot '{robot.name}' with "
                         f"the '{meas.name}' measurement needs {need})")
    ignored = set(meas.obs_names)
    extra = [c for c in header if c not in need and c not in ignored]
    if extra:
        raise ValueError(f"{label}: unknown column '{extra[0]}' (expected {need}, "
                         f"optionally the observed columns {list(meas.obs_names)})")
    col = [header.index(c) for c in need]
    values, lines = numeric_rows(reader, header, col, label, header_line)
    if not values:
        raise ValueError(f"{label}: no configuration rows after the header")
    a = np.asarray(values, np.float64)
    n = robot.n_dof
    meta = {}
    for k, name in enumerate(meas.meta_names):
        v = a[:, n + k]
        if name == "pair":
            bad = np.flatnonzero((v != np.round(v)) | (v < 0) | (v >= len(meas.pairs)))
            if bad.size:
                raise ValueError(f"{label}: line {lines[bad[0]]}, column 'pair': expected a pair "
                                 f"index in [0, {len(meas.pairs)}), got {v[bad[0]]:g}")
            v = v.astype(np.int64)
        meta[name] = v
    return Samples(q=a[:, :n].copy(), y=np.zeros((a.shape[0], 0)), meta=meta,
                   lines=np.asarray(lines, np.int64))


def configurations_text(robot: RobotModel, meas: Measurement, q: np.ndarray,
                        meta: dict | None = None) -> str:
    """CSV text of configurations q (S, n_dof) with the measurement's per-sample columns."""
    qa = np.asarray(q, np.float64)
    if qa.ndim != 2 or qa.shape[1] != robot.n_dof:
        raise ValueError(f"q: expected shape (S, {robot.n_dof}), got {qa.shape}")
    cols = [np.asarray((meta or {})[k]) for k in meas.meta_names]
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(pool_columns(robot, meas))
    for s in range(qa.shape[0]):
        w.writerow([repr(float(v)) for v in qa[s]]
                   + [str(int(c[s])) if c.dtype.kind in "iu" else repr(float(c[s]))
                      for c in cols])
    return buf.getvalue()


def write_configurations(path: str | os.PathLike, robot: RobotModel, meas: Measurement,
                         q: np.ndarray, meta: dict | None = None) -> None:
    """Write a pool / plan CSV atomically."""
    atomic_write_text(os.fspath(path), configurations_text(robot, meas, q, meta))


#: why a configuration was dropped from a pool (index = code of :attr:`PoolCheck.reason`)
REASONS = ("ok", "limits", "self_collision", "world_collision")


@dataclass
class PoolCheck:
    """Verdicts of configurations for a pool: ``keep`` (N,) bool, ``reason`` (N,) int8
    code of :data:`REASONS` (the first failed check: limits, then self-, then world
    collision), ``self_checked`` / ``world_checked`` whether those checks ran,
    ``margin`` [m], ``warnings`` (unchecked collisions), ``time_s`` of the check."""

    keep: np.ndarray
    reason: np.ndarray
    self_checked: bool
    world_checked: bool
    margin: float
    warnings: list[str] = field(default_factory=list)
    time_s: float = 0.0

    @property
    def dropped(self) -> dict[str, int]:
        """{reason: configurations dropped} for every reason but ``ok``."""
        c = np.bincount(self.reason, minlength=len(REASONS))
        return {k: int(c[i]) for i, k in enumerate(REASONS) if i > 0}


class PoolChecker:
    """The feasibility check of pool configurations for one robot, setup and world
    (module docstring); build once, call on batches: ``checker(q) -> PoolCheck``.

    Args:
        robot: the nominal robot.
        setup: the measurement setup (contact setups leave the contact bodies' frame
            pairs out of the self-collision check; cameras are ignored) or None.
        world: a :class:`jwarp.world.World` of the robot's workspace dimension, or None
            (no world check).
        margin: least distance [m] between sphere surfaces (self and world), in [0, 1].
    """

    def __init__(self, robot: RobotModel, setup: Any = None, *, world: World | None = None,
                 margin: float = 0.0) -> None:
        from jwarp.calibration.design.poses import PoseOptions, PoseSampler
        from jwarp.world.collision import check_world

        if isinstance(margin, bool) or not isinstance(margin, (int, float, np.integer,
                                                               np.floating)):
            raise TypeError(f"margin: expected a distance [m], got {margin!r}")
        if not math.isfinite(float(margin)) or not 0.0 <= float(margin) <= 1.0:
            raise ValueError(f"margin: expected a distance in [0, 1] m, got {margin!r}")
        check_world(robot, world)
        self.robot, self.world, self.margin = robot, world, float(margin)
        setup_nc = None if setup is None else dataclasses.replace(setup, cameras=None)
        self.sampler = PoseSampler(robot, setup_nc, PoseOptions(
            margin=self.margin, max_angle=None, dtype="float64", device="cpu"))
        self.self_checked = bool(self.sampler.checks.check_self)
        has_spheres = len(robot.spheres) > 0
        self.world_checked = world is not None and has_spheres
        self.warnings: list[str] = []
        if not has_spheres:
            self.warnings.append(f"robot '{robot.name}' has no collision spheres: the pool is "
                                 f"NOT checked for self-collision"
                                 f"{' or collision with the world' if world is not None else ''}"
                                 f" (only the joint limits are)")
        elif not self.self_checked:
            self.warnings.append(f"robot '{robot.name}' has no self-collision sphere pairs: "
                                 f"the pool is NOT checked for self-collision")

    def __call__(self, q: ArrayLike) -> PoolCheck:
        """Verdicts of ``q`` (N, n_dof) [rad or m]."""
        from jwarp.world.collision import min_distances

        t0 = time.perf_counter()
        q = np.asarray(q, np.float64)
        code, _ = self.sampler.check(q)
        reason = np.zeros(len(q), np.int8)
        reason[code == 1] = 1                       # limits
        reason[code == 4] = 2                       # self_collision
        if self.world_checked and np.any(reason == 0):
            idx = np.flatnonzero(reason == 0)
            md = np.asarray(min_distances(self.robot, q[idx], self.world, device="cpu",
                                          dtype=np.float64))
            reason[idx[md[:, 0] <= self.margin]] = 3
        return PoolCheck(keep=reason == 0, reason=reason, self_checked=self.self_checked,
                         world_checked=self.world_checked, margin=self.margin,
                         warnings=list(self.warnings), time_s=time.perf_counter() - t0)


def check_configurations(robot: RobotModel, q: ArrayLike, setup: Any = None, *, world: World | None = None,
                         margin: float = 0.0) -> PoolCheck:
    """Which configurations ``q`` (N, n_dof) a pool may keep: ``PoolChecker(robot, setup,
    world=world, margin=margin)(q)`` (a pool read from a file is checked this way by
    ``jwarp design --candidates``)."""
    q = np.asarray(q, np.float64)
    if q.ndim != 2 or q.shape[1] != robot.n_dof:
        raise ValueError(f"q: expected shape (N, {robot.n_dof}), got {q.shape}")
    if not np.all(np.isfinite(q)):
        raise ValueError("q: contains NaN or inf")
    return PoolChecker(robot, setup, world=world, margin=margin)(q)


@dataclass
class CandidatePool:
    """A drawn candidate pool (:func:`draw_pool`).

    q (n, n_dof) kept configurations in draw order and ``meta`` their per-sample columns;
    ``requested`` the size asked for; ``drawn`` the raw draws consumed (= n + dropped; draws
    after the last kept one are not counted); ``dropped`` {reason: count} (:data:`REASONS`);
    ``rejected_q`` (R, n_dof), ``rejected_meta`` and ``rejected_reason`` (R,) int8 the
    dropped draws; ``self_checked`` / ``world_checked``; ``margin`` [m]; ``warnings``
    (unchecked collisions, a pool short of its size); ``time_s`` in all and ``check_s`` of
    the collision checks.
    """

    q: np.ndarray
    meta: dict[str, np.ndarray]
    requested: int
    drawn: int
    dropped: dict[str, int]
    rejected_q: np.ndarray
    rejected_meta: dict[str, np.ndarray]
    rejected_reason: np.ndarray
    self_checked: bool
    world_checked: bool
    margin: float
    warnings: list[str] = field(default_factory=list)
    time_s: float = 0.0
    check_s: float = 0.0

    def __len__(self) -> int:
        return int(self.q.shape[0])

    @property
    def complete(self) -> bool:
        """The pool has the size asked for."""
        return len(self) == self.requested

    def summary(self) -> str:
        """One line: what was checked, how many draws were dropped and why."""
        what = [w for w, on in (("self", self.self_checked), ("world", self.world_checked))
                if on]
        if not what:
            return (f"collision check: NONE (no collision spheres); {len(self)} of "
                    f"{self.drawn} draws kept (joint limits only)")
        d = sum(self.dropped.values())
        parts = ", ".join(f"{k.replace('_', ' ')} {v}" for k, v in self.dropped.items() if v)
        return (f"collision check ({' + '.join(what)}, margin {self.margin:g} m): dropped "
                f"{d} of {self.drawn} draws ({100.0 * d / max(self.drawn, 1):.1f}%"
                f"{'; ' + parts if parts else ''}) in {self.check_s:.2f} s")

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (no arrays)."""
        return {"requested": self.requested, "kept": len(self), "drawn": self.drawn,
                "dropped": dict(self.dropped), "self_checked": self.self_checked,
                "world_checked": self.world_checked, "margin": self.margin,
                "complete": self.complete, "warnings": list(self.warnings),
                "time_s": self.time_s, "check_s": self.check_s}


def _raw_draw(robot: RobotModel, setup: object, rng: np.random.Generator) -> Any:
    """``k -> (q (<= k, n_dof), meta)``: the setup's raw candidate draws."""
    from jwarp.calibration.files import make_measurement
    from jwarp.calibration.simulate.campaign import uniform_configurations

    meas = make_measurement(robot, setup)
    if meas.name == "contact":
        from jwarp.calibration.simulate.scenarios import contact_sampler

        sampler = contact_sampler(robot, setup)
        return lambda k: sampler(rng, k)
    if meas.meta_names:
        raise ValueError(f"setup: the '{meas.name}' measurement needs per-sample columns "
                         f"{list(meas.meta_names)}; give the configurations as a file")
    return lambda k: (uniform_configurations(robot, rng, k), {})


def draw_pool(robot: RobotModel, setup: object, n: int, seed: int, *, world: World | None = None,
              margin: float = 0.0, max_draws: int | None = None) -> CandidatePool:
    """A feasible pool of ``n`` candidate configurations of a measurement setup on the
    nominal robot (module docstring), with their per-sample columns.

    Raw draws: contact setups by
    :func:`~jwarp.calibration.simulate.scenarios.contact_sampler` (configurations in
    contact, pairs in turn), other measurements uniformly in the joint limits (a plugin
    with other per-sample columns is an error: give a pool file). Draws that fail
    :class:`PoolChecker` (limits, self-collision with ``margin`` [m], the ``world``) are
    dropped and more are drawn, up to ``max_draws`` (default ``max(50 n, 1000)``); a
    pool that cannot reach ``n`` is returned short with a warning in ``warnings``.
    """
    check_int(n, "n", 1)
    if max_draws is None:
        max_draws = max(50 * int(n), 1000)
    if check_int(max_draws, "max_draws") < n:
        raise ArgumentError(f"max_draws: expected an integer >= n ({n}), got {max_draws!r}")
    t0 = time.perf_counter()
    checker = PoolChecker(robot, setup, world=world, margin=margin)
    raw = _raw_draw(robot, setup, np.random.default_rng(seed))
    keep_q: list[np.ndarray] = []
    keep_m: list[dict] = []
    rej_q: list[np.ndarray] = []
    rej_m: list[dict] = []
    rej_r: list[np.ndarray] = []
    have = drawn = empty = 0
    check_s = 0.0
    while have < n and drawn < max_draws and empty < 100:
        need = n - have
        k = need if drawn == 0 else math.ceil(1.1 * need * drawn / max(have, 1)) + 8
        k = int(min(k, max_draws - drawn, max(4 * n, 4096)))
        q, meta = raw(k)
        q = np.asarray(q, np.float64)[:k]
        meta = {key: np.asarray(v)[:k] for key, v in meta.items()}
        if len(q) == 0:
            empty += 1
            continue
        chk = checker(q)
        check_s += chk.time_s
        ok = chk.keep
        cut = len(q)
        if int(ok.sum()) > need:            # raw draws after the n-th kept one are unused
            cut = int(np.flatnonzero(ok)[need - 1]) + 1
        ok, bad = ok[:cut], ~ok[:cut]
        keep_q.append(q[:cut][ok])
        keep_m.append({key: v[:cut][ok] for key, v in meta.items()})
        rej_q.append(q[:cut][bad])
        rej_m.append({key: v[:cut][bad] for key, v in meta.items()})
        rej_r.append(chk.reason[:cut][bad])
        have += int(ok.sum())
        drawn += cut

    def cat(parts: list[dict], key: str) -> np.ndarray:
        return np.concatenate([p[key] for p in parts])

    keys = list(keep_m[0]) if keep_m else []
    reason = np.concatenate(rej_r) if rej_r else np.zeros(0, np.int8)
    counts = np.bincount(reason, minlength=len(REASONS))
    warn = list(checker.warnings)
    if have < n:
        warn.append(f"only {have} of {n} candidate configurations passed the collision check "
                    f"in {drawn} draws (acceptance {have / max(drawn, 1):.3g}); the pool is "
                    f"short: lower the margin, check the world, or raise max_draws")
    return CandidatePool(
        q=np.concatenate(keep_q) if keep_q else np.zeros((0, robot.n_dof)),
        meta={key: cat(keep_m, key) for key in keys}, requested=int(n), drawn=int(drawn),
        dropped={k: int(counts[i]) for i, k in enumerate(REASONS) if i > 0},
        rejected_q=np.concatenate(rej_q) if rej_q else np.zeros((0, robot.n_dof)),
        rejected_meta={key: cat(rej_m, key) for key in keys}, rejected_reason=reason,
        self_checked=checker.self_checked, world_checked=checker.world_checked,
        margin=checker.margin, warnings=warn, time_s=time.perf_counter() - t0,
        check_s=check_s)


def draw_configurations(robot: RobotModel, setup: object, n: int, seed: int, *,
                        world: World | None = None, margin: float = 0.0) -> tuple[np.ndarray, dict]:
    """``n`` feasible candidate configurations and their per-sample columns:
    :func:`draw_pool` as ``(q, meta)``; its warnings (unchecked collisions, a short pool)
    are issued as :class:`UserWarning` s."""
    pool = draw_pool(robot, setup, n, seed, world=world, margin=margin)
    for w in pool.warnings:
        warnings.warn(w, UserWarning, stacklevel=2)
    return pool.q, pool.meta
