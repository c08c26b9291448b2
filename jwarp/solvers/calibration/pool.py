"""Configuration files of experimental design: candidate pools and measurement plans (CSV).

A pool or plan is a samples file without observations: one header row, one row per
configuration, the robot's joint columns (rad or m) and the measurement's per-sample
columns (contact: ``pair``), exactly as in a samples CSV
(:func:`~jwarp.solvers.calibration.files.columns`). The measurement's observed columns may
be present and are ignored (a samples file or a ``simulate-campaign`` output is a valid
pool); any other column is an error, as is a missing one. Errors name the file's option
(``what``, e.g. ``--candidates``), the column and, for values, the line.
"""

from __future__ import annotations

import csv
import io
import os

import numpy as np

from jwarp.atomic import atomic_write_text
from jwarp.measurement import Measurement
from jwarp.model import RobotModel
from jwarp.solvers.calibration.files import Samples, numeric_rows, read_header, read_text


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


def draw_configurations(robot: RobotModel, setup: object, n: int, seed: int
                        ) -> tuple[np.ndarray, dict]:
    """``n`` candidate configurations of a measurement setup on the nominal robot, with
    their per-sample columns: contact setups by
    :func:`~jwarp.solvers.calibration.scenarios.contact_sampler` (configurations in
    contact, pairs in turn), other measurements uniformly in the joint limits (a plugin
    with other per-sample columns is an error: give a pool file)."""
    from jwarp.solvers.calibration.campaign import uniform_configurations
    from jwarp.solvers.calibration.files import make_measurement

    if not isinstance(n, int) or n < 1:
        raise ValueError(f"n: expected an integer >= 1, got {n!r}")
    meas = make_measurement(robot, setup)
    rng = np.random.default_rng(seed)
    if meas.name == "contact":
        from jwarp.solvers.calibration.scenarios import contact_sampler

        sampler = contact_sampler(robot, setup)
        qs, pairs, have = [], [], 0
        for _ in range(1000):
            q, meta = sampler(rng, n - have)
            qs.append(q)
            pairs.append(meta["pair"])
            have += len(q)
            if have >= n:
                break
        return np.concatenate(qs)[:n], {"pair": np.concatenate(pairs)[:n]}
    if meas.meta_names:
        raise ValueError(f"setup: the '{meas.name}' measurement needs per-sample columns "
                         f"{list(meas.meta_names)}; give the configurations as a file")
    return uniform_configurations(robot, rng, n), {}
