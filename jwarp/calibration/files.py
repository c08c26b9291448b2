"""Calibration data files: the JSON *setup file* and the CSV of measured *samples*.

Setup file (JSON object)::

    {
      "schema": "jwarp.calibration_setup",   # optional; checked when given
      "version": 1,                          # optional; checked when given
      "robot": "justin19",                   # optional: default robot of the campaign
      "description": "...",                  # optional free text
      "campaign_id": "...",                  # optional: simulated campaign (see below)
      "samples_sha256": "...",               # optional: SHA-256 of its samples.csv
      "cameras": [...],                      # optional: tracker cameras for pose sampling
      "marker_normals": {...},               # optional: marker normals (docs/pose_sampling.md)
      "plugin": "cartesian",                 # the measurement plugin
      ...                                    # the plugin's own keys (docs/measurements.md)
      "tow": {...}                           # optional: task-oriented weighting
    }                                        # (docs/task_weighting.md)

Samples file (CSV, comma separated, one header row, one row per sample)::

    <joint 1>,...,<joint n>,<meta columns>,<observed columns>

The joint columns are named as the robot's joints (rad or m), the meta columns are the
plugin's per-sample inputs (contact: ``pair``) and the observed columns are the plugin's
``obs_names`` (cartesian: ``<marker>_x,<marker>_y,<marker>_z`` in m; image:
``<marker>_u,<marker>_v`` in px; contact: ``distance`` in m). Column order is free; every
column must be present; extra columns are an error. A row with a missing value, NaN/inf or
the wrong number of fields is rejected with its line number; nothing is dropped silently.
A joint value far outside the robot's limits (by more than :data:`FAR_OUTSIDE` of the
joint's range, e.g. degrees written for radians) gives a :class:`DataWarning` naming the
line. Both files are UTF-8 (a byte order mark, as spreadsheet programs write it, is
accepted); other bytes are an error naming the file and line.

A simulated campaign (:meth:`~jwarp.calibration.simulate.campaign.Campaign.write`) records
a ``campaign_id`` and the SHA-256 of its ``samples.csv`` in ``setup.json`` (and in the
``notes`` of ``truth.json``), so readers can tell files of different campaigns apart.
"""

from __future__ import annotations

import csv
import hashlib
import io
import json
import math
import os
import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from jwarp.model import RobotModel
from jwarp.model.measurement import Measurement
from jwarp.utils.atomic import atomic_write_text

SETUP_SCHEMA = "jwarp.calibration_setup"
SETUP_VERSION = 1
_FILE_KEYS = ("schema", "version", "robot", "description", "campaign_id", "samples_sha256",
              "tow", "cameras", "marker_normals")
#: a joint value beyond a limit by more than this fraction of the joint's range warns
FAR_OUTSIDE = 0.1


class DataWarning(UserWarning):
    """A suspicious but readable value in a data file (e.g. a joint far outside its limits)."""


@dataclass
class Setup:
    """A parsed setup file: the plugin section handed to the measurement plugin."""

    plugin: str
    section: dict[str, Any]
    robot: str | None = None
    description: str = ""
    path: str | None = None
    campaign_id: str | None = None     # simulated campaign this setup belongs to
    samples_sha256: str | None = None  # SHA-256 of that campaign's samples.csv
    tow: dict[str, Any] | None = None  # task-oriented weighting section (calibration.tow)
    cameras: list | None = None        # tracker cameras of the pose sampler (poses.py)
    marker_normals: dict | None = None  # {marker: normal in its frame} (poses.py)


@dataclass
class Samples:
    """Measured samples: joint values (S, n_dof), observations (S, m), meta columns."""

    q: np.ndarray
    y: np.ndarray
    meta: dict[str, np.ndarray] = field(default_factory=dict)
    lines: np.ndarray | None = None  # (S,) line number of each row in the file
    #: (S, n_dof) the direction (+1, -1, 0) each joint last moved in, from the optional
    #: ``dir_<joint>`` columns (NaN for joints without one); None: no such column
    directions: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.q.shape[0])

    def select(self, rows: slice | np.ndarray) -> Samples:
        """The samples of ``rows`` (a slice or index array)."""
        return Samples(self.q[rows], self.y[rows], {k: v[rows] for k, v in self.meta.items()},
                       None if self.lines is None else self.lines[rows],
                       None if self.directions is None else self.directions[rows])


def setup_from_dict(doc: Any, where: str = "setup") -> Setup:
    """Check the file-level keys of a setup document and split off the plugin section."""
    if not isinstance(doc, dict):
        raise ValueError(f"{where}: expected a JSON object, got {type(doc).__name__}")
    if "schema" in doc and doc["schema"] != SETUP_SCHEMA:
        raise ValueError(f"{where}: schema: expected '{SETUP_SCHEMA}', got {doc['schema']!r}")
    if "version" in doc and doc["version"] != SETUP_VERSION:
        raise ValueError(f"{where}: version: {doc['version']!r} not supported "
                         f"(this jwarp reads version {SETUP_VERSION})")
    plugin = doc.get("plugin")
    if not isinstance(plugin, str) or not plugin:
        raise ValueError(f"{where}: plugin: missing; name the measurement plugin "
                         f"(e.g. \"cartesian\", \"image\", \"contact\", \"relative\")")
    robot = doc.get("robot")
    if robot is not None and not isinstance(robot, str):
        raise ValueError(f"{where}: robot: expected a robot name, got {robot!r}")
    for key in ("campaign_id", "samples_sha256"):
        if doc.get(key) is not None and not isinstance(doc[key], str):
            raise ValueError(f"{where}: {key}: expected a string, got {doc[key]!r}")
    tow = doc.get("tow")
    if tow is not None and not isinstance(tow, dict):
        raise ValueError(f"{where}: tow: expected a JSON object (task, virtual_noise, ...), "
                         f"got {type(tow).__name__}")
    if doc.get("cameras") is not None and not isinstance(doc["cameras"], list):
        raise ValueError(f"{where}: cameras: expected a list of cameras, got {doc['cameras']!r}")
    if doc.get("marker_normals") is not None and not isinstance(doc["marker_normals"], dict):
        raise ValueError(f"{where}: marker_normals: expected an object {{marker: [x, y, z]}}, "
                         f"got {doc['marker_normals']!r}")
    section = {k: v for k, v in doc.items() if k not in _FILE_KEYS}
    return Setup(plugin=plugin, section=section, robot=robot,
                 description=str(doc.get("description", "")),
                 campaign_id=doc.get("campaign_id"), samples_sha256=doc.get("samples_sha256"),
                 tow=tow, cameras=doc.get("cameras"), marker_normals=doc.get("marker_normals"))


def read_text(path: str | os.PathLike, what: str) -> tuple[str, bytes]:
    """The text of a UTF-8 file (a leading byte order mark dropped) and its bytes.

    Raises:
        ValueError: the file is missing, unreadable or not a regular file (named as
            ``what``: e.g. ``data``), or not UTF-8 (naming the file, line and column of the
            first bad byte).
    """
    import stat

    path = os.fspath(path)
    try:
        mode = os.stat(path).st_mode
        if not stat.S_ISREG(mode):  # a folder, /dev/zero, a pipe: never read without end
            kind = "a folder" if stat.S_ISDIR(mode) else "a device, pipe or socket"
            raise ValueError(f"{what}: {path} is {kind}, not a regular file")
        with open(path, "rb") as f:
            raw = f.read()
    except FileNotFoundError:
        raise ValueError(f"{what}: file not found: {path}") from None
    except OSError as e:
        raise ValueError(f"{what}: cannot read {path}: {e.strerror or e}") from None
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        line = raw.count(b"\n", 0, e.start) + 1
        start = raw.rfind(b"\n", 0, e.start) + 1
        col = len(raw[start:e.start].decode("utf-8", "replace")) + 1  # in characters
        raise ValueError(f"{path}: line {line}, column {col}: not UTF-8 text (byte "
                         f"0x{raw[e.start]:02x}); save the file as UTF-8") from None
    return text, raw


def read_setup(path: str | os.PathLike) -> Setup:
    """Read a setup file; malformed JSON or missing keys -> ValueError naming the file."""
    path = os.fspath(path)
    text, _ = read_text(path, "setup")
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as e:
        raise ValueError(f"{path}: malformed JSON at line {e.lineno} column {e.colno}: "
                         f"{e.msg}") from None
    setup = setup_from_dict(doc, where=path)
    setup.path = path
    return setup


def write_setup(path: str | os.PathLike, setup: Setup) -> None:
    """Write a setup file atomically."""
    doc: dict[str, Any] = {"schema": SETUP_SCHEMA, "version": SETUP_VERSION}
    if setup.robot:
        doc["robot"] = setup.robot
    if setup.description:
        doc["description"] = setup.description
    if setup.campaign_id:
        doc["campaign_id"] = setup.campaign_id
    if setup.samples_sha256:
        doc["samples_sha256"] = setup.samples_sha256
    if setup.cameras is not None:
        doc["cameras"] = setup.cameras
    if setup.marker_normals is not None:
        doc["marker_normals"] = setup.marker_normals
    doc.update(setup.section)
    doc["plugin"] = setup.plugin
    if setup.tow is not None:
        doc["tow"] = setup.tow
    atomic_write_text(os.fspath(path), json.dumps(_jsonable(doc), indent=1) + "\n")


def make_measurement(robot: RobotModel, setup: Setup) -> Measurement:
    """Instantiate the setup's plugin (unknown plugin -> ValueError listing the known)."""
    from jwarp.plugins.registry import measurement

    cls = measurement(setup.plugin)
    return cls(robot, dict(setup.section, plugin=setup.plugin))


def columns(robot: RobotModel, meas: Measurement) -> list[str]:
    """The CSV header: joints, then meta columns, then observed values."""
    return [j.name for j in robot.joints] + list(meas.meta_names) + list(meas.obs_names)


def read_samples(path: str | os.PathLike, robot: RobotModel, meas: Measurement) -> Samples:
    """Read a samples CSV for ``robot`` and ``meas`` (see the module docstring)."""
    path = os.fspath(path)
    text, _ = read_text(path, "data")
    return parse_samples(text, robot, meas, where=path)



def read_header(reader: Any, where: str, expect: str) -> tuple[list[str], int]:
    """The first non-blank row of a ``csv.reader`` (stripped names) and its line number;
    an empty file is a ValueError ``<where>: empty file (<expect>)``."""
    header = None
    for header in reader:
        if header and any(h.strip() for h in header):
            break
    if not header:
        raise ValueError(f"{where}: empty file ({expect})")
    return [h.strip() for h in header], reader.line_num


def numeric_rows(reader: Any, header: list[str], col: list[int], where: str,
                 header_line: int) -> tuple[list[list[float]], list[int]]:
    """The columns ``col`` of every further non-blank row as finite floats, and the rows'
    line numbers. A row with another field count than the header, a field that is not a
    number, or NaN/inf is a ValueError naming ``where``, the line and the column."""
    values, lines = [], []
    for fields in reader:
        line = reader.line_num
        if not fields or (len(fields) == 1 and not fields[0].strip()):
            continue  # blank line
        if len(fields) != len(header):
            raise ValueError(f"{where}: line {line}: {len(fields)} fields, the header "
                             f"(line {header_line}) has {len(header)}")
        row = []
        for k in col:
            s = fields[k].strip()
            try:
                v = float(s)
            except ValueError:
                raise ValueError(f"{where}: line {line}, column '{header[k]}': not a "
                                 f"number: {s!r}") from None
            if not math.isfinite(v):
                raise ValueError(f"{where}: line {line}, column '{header[k]}': {s} "
                                 f"(NaN/inf rows are rejected, not dropped)")
            row.append(v)
        values.append(row)
        lines.append(line)
    return values, lines

#: prefix of the optional samples-CSV columns of the direction each joint last moved in
#: (``dir_<joint>``: -1, 0, 1), read by the ``backlash`` calibration group
DIRECTION_PREFIX = "dir_"


def parse_samples(text: str, robot: RobotModel, meas: Measurement, where: str = "data"
                  ) -> Samples:
    """Parse CSV text (the content of a samples file)."""
    if text.startswith("\ufeff"):  # byte order mark
        text = text[1:]
    reader = csv.reader(io.StringIO(text, newline=""))
    header, header_line = read_header(reader, where, "expected a header row")
    expected = columns(robot, meas)
    dup = sorted({h for h in header if header.count(h) > 1})
    if dup:
        raise ValueError(f"{where}: duplicate column(s) {dup}")
    missing = [c for c in expected if c not in header]
    if missing:
        raise ValueError(f"{where}: missing column(s) {missing}; expected {expected}")
    dir_cols = [f"{DIRECTION_PREFIX}{j}" for j in robot.joint_names]
    extra = [c for c in header if c not in expected and c not in dir_cols]
    if extra:
        raise ValueError(f"{where}: unknown column(s) {extra}; expected {expected} (and "
                         f"optionally direction columns {DIRECTION_PREFIX}<joint>)")
    dirs_given = [c for c in dir_cols if c in header]
    col = [header.index(c) for c in expected + dirs_given]
    values, lines = numeric_rows(reader, header, col, where, header_line)
    if not values:
        raise ValueError(f"{where}: no sample rows after the header")
    a = np.asarray(values, dtype=np.float64)
    n, nm = robot.n_dof, len(meas.meta_names)
    meta = {}
    for k, name in enumerate(meas.meta_names):
        v = a[:, n + k]
        if name == "pair":
            if np.any(v != np.round(v)) or np.any(v < 0):
                bad = int(np.flatnonzero((v != np.round(v)) | (v < 0))[0])
                raise ValueError(f"{where}: line {lines[bad]}, column 'pair': expected a "
                                 f"pair index >= 0, got {v[bad]}")
            v = v.astype(np.int64)
        meta[name] = v
    lines_a = np.asarray(lines, dtype=np.int64)
    _warn_far_outside(robot, a[:, :n], lines_a, where)
    ne = len(expected)
    directions = None
    if dirs_given:
        directions = np.full((a.shape[0], n), np.nan)
        for k, c in enumerate(dirs_given):
            v = a[:, ne + k]
            wrong = np.flatnonzero((v != 1) & (v != -1) & (v != 0))
            if wrong.size:
                raise ValueError(f"{where}: line {lines_a[wrong[0]]}, column '{c}': expected "
                                 f"the direction the joint last moved in, -1, 0 or 1, got "
                                 f"{v[wrong[0]]:g}")
            directions[:, dir_cols.index(c)] = v
    return Samples(q=a[:, :n].copy(), y=a[:, n + nm:ne].copy(), meta=meta, lines=lines_a,
                   directions=directions)


def _warn_far_outside(robot: RobotModel, q: np.ndarray, lines: np.ndarray, where: str) -> None:
    """A :class:`DataWarning` per joint with values beyond a limit by more than
    :data:`FAR_OUTSIDE` of its range, naming the first such line."""
    lim = np.asarray(robot.joint_limits, np.float64)
    for j, joint in enumerate(robot.joints):
        lo, hi = lim[j]
        if not (math.isfinite(lo) and math.isfinite(hi)):
            continue
        margin = FAR_OUTSIDE * (hi - lo)
        bad = np.flatnonzero((q[:, j] < lo - margin) | (q[:, j] > hi + margin))
        if not len(bad):
            continue
        k = int(bad[0])
        v = q[k, j]
        hint = (" (degrees instead of radians?)"
                if joint.type == "revolute" and abs(v) > 2 * math.pi else "")
        more = f"; {len(bad)} rows in all" if len(bad) > 1 else ""
        warnings.warn(f"{where}: line {lines[k]} (sample {k}): joint '{joint.name}' = {v:.6g} "
                      f"is far outside its limits [{lo:.6g}, {hi:.6g}]{hint}{more}",
                      DataWarning, stacklevel=3)


def write_samples(path: str | os.PathLike, robot: RobotModel, meas: Measurement,
                  samples: Samples) -> None:
    """Write ``samples`` as CSV atomically (full float precision)."""
    atomic_write_text(os.fspath(path), samples_text(robot, meas, samples))


def samples_text(robot: RobotModel, meas: Measurement, samples: Samples) -> str:
    """The CSV text of ``samples`` (what :func:`write_samples` writes)."""
    S = len(samples)
    if samples.y.shape != (S, meas.n_obs):
        raise ValueError(f"samples.y: expected shape ({S}, {meas.n_obs}), got {samples.y.shape}")
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(columns(robot, meas))
    meta = [np.asarray(samples.meta[name]) for name in meas.meta_names]
    for s in range(S):
        row = [repr(float(v)) for v in samples.q[s]]
        row += [str(int(m[s])) if m.dtype.kind in "iu" else repr(float(m[s])) for m in meta]
        row += [repr(float(v)) for v in samples.y[s]]
        w.writerow(row)
    return buf.getvalue()


def sha256_hex(data: bytes | str) -> str:
    """The SHA-256 of ``data`` (str: its UTF-8 bytes) in hex, as campaigns record it."""
    return hashlib.sha256(data.encode("utf-8") if isinstance(data, str) else data).hexdigest()


def parse_rows(spec: str | None, n: int, argname: str = "rows") -> slice:
    """``"0:300"`` -> slice(0, 300) checked against ``n`` rows (None: all rows)."""
    if spec is None or spec == "" or spec == ":":
        return slice(0, n)
    parts = str(spec).split(":")
    if len(parts) != 2:
        raise ValueError(f"{argname}: expected START:STOP (e.g. 0:300), got {spec!r}")
    try:
        start = int(parts[0]) if parts[0].strip() else 0
        stop = int(parts[1]) if parts[1].strip() else n
    except ValueError:
        raise ValueError(f"{argname}: expected integers START:STOP, got {spec!r}") from None
    if not 0 <= start < stop <= n:
        raise ValueError(f"{argname}: {spec!r} is not a non-empty range inside the "
                         f"{n} rows of the data")
    return slice(start, stop)


def _jsonable(x: Any) -> Any:
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return _jsonable(x.tolist())
    if isinstance(x, (np.floating, np.integer)):
        return x.item()
    return x
