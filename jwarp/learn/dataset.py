"""Motion-planning datasets in SQLite ("jwarp-path-db", schema version 1; docs/datasets.md).

One database file holds the worlds and the labelled paths of ONE robot (and optionally one
basis point set), written by :func:`jwarp.learn.generate.generate` and read by
:class:`PathDataset` (``torch.utils.data``) or :func:`export_npz`.

Schema::

    meta     (key TEXT PRIMARY KEY, value TEXT)        format, schema_version, robot,
                                                       kinematics_hash, bps (JSON or ""),
                                                       jwarp_version, created
    worlds   (world_id INTEGER PRIMARY KEY,            the world seed
              dim, shape TEXT (JSON), limits BLOB (float64 (dim, 2)), voxel_size REAL,
              occupancy BLOB  zlib(np.packbits(bool grid, C order)) or NULL,
              sdf BLOB        zlib(float32 grid), only when there is no occupancy,
              sdf_dtype TEXT, meta TEXT (JSON), n_paths INTEGER, settings_id INTEGER)
    settings (settings_id INTEGER PRIMARY KEY, json TEXT UNIQUE)   the labeller's settings
    paths    (world_id INTEGER, task INTEGER,  PRIMARY KEY (world_id, task),
              start BLOB, goal BLOB (float32 (n_dof,)), waypoints BLOB (float32 (W, n_dof)),
              n_waypoints INTEGER, cost REAL, feasible INTEGER, hard INTEGER, settings_id)
    index paths_by_world ON paths(world_id)

Writes are append-only: one world and all its paths go in ONE transaction
(:meth:`PathDB.add_world`), so a world is either complete in the file or absent; an
interrupted writer (exception, SIGKILL, power loss) loses at most the world it was
writing, and SQLite's journal rolls that back on the next open. Rows are inserted with
``INSERT OR IGNORE`` on the unique keys, so writing a world twice changes nothing: a rerun
resumes without duplicates (:meth:`PathDB.complete_worlds`).

Errors (:class:`PathDBError`, a ValueError; the message names the file): a file that is
not an SQLite database or not a jwarp path database, a database of another robot
(name or kinematics hash) or of another BPS, another schema version, and a database
locked by another writer for longer than ``timeout`` seconds. Nothing already committed
is touched by any of them.
"""

from __future__ import annotations

import json
import os
import sqlite3
import time
import zlib
from collections import OrderedDict
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import numpy as np
from torch.utils.data import IterableDataset

if TYPE_CHECKING:
    from jwarp.model import RobotModel
    from jwarp.world.sdf import World

__all__ = ["DamagedRowError", "DuplicateWorldError", "FORMAT", "SCHEMA_VERSION", "PathDB", "PathDBError", "PathDataset", "WorldRecord",
           "export_npz", "record_hash", "world_from_record", "world_record"]

FORMAT = "jwarp-path-db"
SCHEMA_VERSION = 1

SCHEMA = """
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS settings (settings_id INTEGER PRIMARY KEY, json TEXT NOT NULL UNIQUE);
CREATE TABLE IF NOT EXISTS worlds (
    world_id INTEGER PRIMARY KEY, dim INTEGER NOT NULL, shape TEXT NOT NULL,
    limits BLOB NOT NULL, voxel_size REAL NOT NULL, occupancy BLOB, sdf BLOB,
    sdf_dtype TEXT NOT NULL, meta TEXT NOT NULL, n_paths INTEGER NOT NULL,
    settings_id INTEGER REFERENCES settings(settings_id));
CREATE TABLE IF NOT EXISTS paths (
    world_id INTEGER NOT NULL REFERENCES worlds(world_id), task INTEGER NOT NULL,
    start BLOB NOT NULL, goal BLOB NOT NULL, waypoints BLOB NOT NULL,
    n_waypoints INTEGER NOT NULL, cost REAL NOT NULL, feasible INTEGER NOT NULL,
    hard INTEGER NOT NULL, settings_id INTEGER REFERENCES settings(settings_id),
    PRIMARY KEY (world_id, task));
CREATE INDEX IF NOT EXISTS paths_by_world ON paths(world_id);
CREATE TABLE IF NOT EXISTS world_hashes (
    hash TEXT PRIMARY KEY, world_id INTEGER NOT NULL UNIQUE REFERENCES worlds(world_id));
"""

#: the table of world content hashes (also added to databases written before it existed)
HASH_TABLE = ("CREATE TABLE IF NOT EXISTS world_hashes (hash TEXT PRIMARY KEY, "
              "world_id INTEGER NOT NULL UNIQUE REFERENCES worlds(world_id))")

#: a record of one world as the generator's workers return it (plain, picklable)
WorldRecord = dict


class PathDBError(ValueError):
    """A path database that cannot be used: not one, another robot/BPS/schema, locked,
    corrupt. The message names the file."""


def _json(obj: Any) -> str:
    def default(o: Any) -> Any:
        if hasattr(o, "tolist"):
            return o.tolist()
        return str(o)

    return json.dumps(obj, sort_keys=True, separators=(",", ":"), default=default)


def _robot_identity(model: RobotModel) -> tuple[str, str]:
    """(name, kinematics hash) of the robot."""
    from jwarp.core.device import content_key

    return model.name, content_key(model)


def _bps_text(bps: Any) -> str:
    if bps is None:
        return ""
    if hasattr(bps, "to_dict"):
        bps = bps.to_dict()
    return _json(bps)


# ====================================================================== records
def world_record(world_id: int, world: World, labels: Any) -> WorldRecord:
    """The plain record (numpy arrays, dicts) of one world (a
    :class:`jwarp.world.sdf.World`) and its labels (an object with ``starts``, ``goals``,
    ``paths``, ``cost``, ``feasible``, ``hard``, ``settings``: e.g.
    ``jwarp.learn.plan_data.WorldLabels``), checked for consistent shapes."""
    starts = np.asarray(labels.starts, np.float32)
    goals = np.asarray(labels.goals, np.float32)
    paths = np.asarray(labels.paths, np.float32)
    n = starts.shape[0]
    if starts.ndim != 2 or goals.shape != starts.shape or paths.ndim != 3 \
            or paths.shape[0] != n or paths.shape[2] != starts.shape[1]:
        raise ValueError(f"labels of world {world_id}: inconsistent shapes starts "
                         f"{starts.shape}, goals {goals.shape}, paths {paths.shape}")
    cost = np.asarray(labels.cost, np.float64).reshape(n)
    feasible = np.asarray(labels.feasible, bool).reshape(n)
    hard = np.asarray(getattr(labels, "hard", np.zeros(n, bool)), bool).reshape(n)
    occ = None if world.occupancy is None else np.asarray(world.occupancy, bool)
    return {
        "world_id": int(world_id),
        "shape": [int(s) for s in cast(np.ndarray, world.sdf).shape],
        "limits": np.asarray(world.limits, np.float64),
        "voxel_size": float(cast(float, world.voxel_size)),
        "occupancy": occ,
        "sdf": None if occ is not None else np.asarray(world.sdf, np.float32),
        "sdf_dtype": str(np.asarray(world.sdf).dtype),
        "meta": dict(world.meta),
        "starts": starts, "goals": goals, "paths": paths, "cost": cost,
        "feasible": feasible, "hard": hard,
        "settings": dict(getattr(labels, "settings", {}) or {}),
    }


def record_hash(rec: dict) -> str:
    """The content hash of a world record or stored world row (``shape``, ``limits``,
    ``voxel_size``, ``occupancy`` or ``sdf``): equal to
    :meth:`jwarp.world.sdf.World.content_hash` of the world it holds."""
    import hashlib

    h = hashlib.sha256()
    h.update(json.dumps([[int(x) for x in rec["shape"]], float(rec["voxel_size"])]).encode())
    h.update(np.ascontiguousarray(np.asarray(rec["limits"], np.float64)).tobytes())
    if rec.get("occupancy") is not None:
        h.update(b"occ")
        h.update(np.packbits(np.asarray(rec["occupancy"], bool).ravel()).tobytes())
    else:
        h.update(b"sdf")
        h.update(np.ascontiguousarray(np.asarray(rec["sdf"]), np.float32).tobytes())
    return h.hexdigest()


class DuplicateWorldError(ValueError):
    """A world whose content (grid) equals a world already in the database."""


def world_from_record(row: dict) -> Any:
    """The :class:`jwarp.world.sdf.World` of a stored world (the SDF recomputed from the
    occupancy, as the simplex worlds make it)."""
    from jwarp.world.sdf import World, world_from_occupancy

    dtype = np.dtype(row["sdf_dtype"])
    if row["occupancy"] is not None:
        w = world_from_occupancy(row["occupancy"], row["limits"], row["voxel_size"], dtype=dtype)
        w.meta = dict(row["meta"])
        return w
    return World(row["sdf"].astype(dtype), row["limits"], row["voxel_size"], None,
                 dict(row["meta"]))


def _pack_occ(occ: np.ndarray) -> bytes:
    return zlib.compress(np.packbits(occ.reshape(-1)).tobytes(), 6)


def _unpack_occ(blob: bytes, shape: tuple[int, ...]) -> np.ndarray:
    bits = np.frombuffer(zlib.decompress(blob), np.uint8)
    return np.unpackbits(bits, count=int(np.prod(shape))).astype(bool).reshape(shape)


class DamagedRowError(PathDBError):
    """A stored world or path row whose data cannot be decoded (a blob that does not
    decompress, or of the wrong size); the message names the file, the world and the row.
    ``world_id`` and ``task`` (None for a world row) say which."""

    def __init__(self, message: str, world_id: int, task: int | None = None):
        super().__init__(message)
        self.world_id, self.task = int(world_id), task


# ====================================================================== database
class PathDB:
    """An SQLite path database (module docstring).

    Args:
        path: the file.
        robot: RobotModel; required to create, checked (name and kinematics hash)
            when given for an existing file; None: read whatever robot it holds.
        bps: a BasisPointSet (or its dict) the data is meant for; stored on creation,
            checked when given for an existing file.
        create: make the file if it does not exist (else PathDBError).
        timeout: seconds to wait for another writer's lock before PathDBError.
    """

    def __init__(self, path: str | os.PathLike, robot: RobotModel | None = None, *, bps: Any = None,
                 create: bool = False, timeout: float = 5.0):
        self.path = Path(path)
        self.timeout = float(timeout)
        if self.path.is_dir():
            raise PathDBError(f"database: '{self.path}' is a folder")
        exists = self.path.is_file() and self.path.stat().st_size > 0
        if not exists and not create:
            if self.path.is_file():
                raise PathDBError(f"database: '{self.path}' is empty (0 bytes): not a path "
                                  f"database (jwarp data generate makes one)")
            raise PathDBError(f"database: '{self.path}' does not exist")
        if not exists and robot is None:
            raise PathDBError(f"database: a robot is needed to create '{self.path}'")
        try:
            self.con = sqlite3.connect(str(self.path), timeout=self.timeout,
                                       isolation_level=None)  # explicit transactions
        except sqlite3.Error as e:
            raise self._error(e) from None
        try:
            try:
                self.con.execute("PRAGMA foreign_keys=ON")
                self.con.execute("PRAGMA synchronous=FULL")
            except sqlite3.Error as e:
                raise self._error(e, "opening it") from None
            if exists:
                self.meta = self._read_meta()
                self._check(robot, bps)
                try:  # a database of before the hash table: add it (read-only: later)
                    self.con.execute(HASH_TABLE)
                except sqlite3.Error:
                    pass
            else:
                self.meta = self._create(cast("RobotModel", robot), bps)  # not None: checked above
        except BaseException:
            self.con.close()
            raise
        self._settings: dict[str, int] = {}

    # ------------------------------------------------------------------ open/create
    def _error(self, e: BaseException, doing: str = "") -> PathDBError:
        msg = str(e)
        what = f" while {doing}" if doing else ""
        if "locked" in msg or "busy" in msg:
            return PathDBError(f"database: '{self.path}' is locked by another process{what} "
                               f"(waited {self.timeout:g} s); nothing already written is "
                               f"lost; retry once the other writer has finished")
        if "not a database" in msg or "malformed" in msg or "corrupt" in msg:
            return PathDBError(f"database: '{self.path}' is not a readable SQLite database "
                               f"({msg}){what}")
        return PathDBError(f"database: '{self.path}': {type(e).__name__}: {msg}{what}")

    def _create(self, robot: RobotModel, bps: Any) -> dict:
        from jwarp import __version__

        name, key = _robot_identity(robot)
        meta = {"format": FORMAT, "schema_version": str(SCHEMA_VERSION), "robot": name,
                "kinematics_hash": key, "bps": _bps_text(bps), "jwarp_version": __version__,
                "created": time.strftime("%Y-%m-%dT%H:%M:%S%z")}
        try:
            self.con.execute("BEGIN IMMEDIATE")
            for stmt in SCHEMA.strip().split(";"):
                if stmt.strip():
                    self.con.execute(stmt)
            self.con.executemany("INSERT OR IGNORE INTO meta(key, value) VALUES (?, ?)",
                                 list(meta.items()))
            self.con.execute("COMMIT")
        except sqlite3.Error as e:
            self._rollback()
            raise self._error(e, "creating it") from None
        return self._read_meta()  # another process may have created it first

    def _read_meta(self) -> dict:
        try:
            tables = {r[0] for r in self.con.execute(
                "SELECT name FROM sqlite_master WHERE type='table'")}
            if "meta" not in tables:
                raise PathDBError(f"database: '{self.path}' is an SQLite database but not a "
                                  f"jwarp path database (no meta table)")
            meta = dict(self.con.execute("SELECT key, value FROM meta").fetchall())
        except sqlite3.Error as e:
            raise self._error(e, "reading it") from None
        if meta.get("format") != FORMAT:
            raise PathDBError(f"database: '{self.path}' is not a jwarp path database (format "
                              f"{meta.get('format')!r}, expected {FORMAT!r})")
        if meta.get("schema_version") != str(SCHEMA_VERSION):
            raise PathDBError(f"database: '{self.path}' has schema version "
                              f"{meta.get('schema_version')}; this jwarp reads version "
                              f"{SCHEMA_VERSION}")
        return meta

    def _check(self, robot: RobotModel | None, bps: Any) -> None:
        if robot is not None:
            name, key = _robot_identity(robot)
            if name != self.meta["robot"] or key != self.meta["kinematics_hash"]:
                raise PathDBError(f"database: '{self.path}' holds paths of robot "
                                  f"'{self.meta['robot']}' (kinematics hash "
                                  f"{self.meta['kinematics_hash']}), not of robot '{name}' "
                                  f"(kinematics hash {key})")
        if bps is not None:
            mine = _bps_text(bps)
            if mine != self.meta.get("bps", ""):
                stored = "no BPS" if not self.meta.get("bps") else "another BPS"
                raise PathDBError(f"database: '{self.path}' was made for {stored} than the "
                                  f"one given (basis point sets differ); use a new database")

    def _rollback(self) -> None:
        try:
            if self.con.in_transaction:
                self.con.execute("ROLLBACK")
        except sqlite3.Error:
            pass

    # ------------------------------------------------------------------ properties
    @property
    def robot(self) -> str:
        return self.meta["robot"]

    @property
    def kinematics_hash(self) -> str:
        return self.meta["kinematics_hash"]

    @property
    def bps(self) -> dict | None:
        text = self.meta.get("bps", "")
        return json.loads(text) if text else None

    def close(self) -> None:
        self.con.close()

    def __enter__(self) -> PathDB:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ writing
    def _settings_id(self, settings: dict) -> int:
        text = _json(settings)
        sid = self._settings.get(text)
        if sid is None:
            self.con.execute("INSERT OR IGNORE INTO settings(json) VALUES (?)", (text,))
            sid = self.con.execute("SELECT settings_id FROM settings WHERE json = ?",
                                   (text,)).fetchone()[0]
        return sid

    def add_world(self, rec: WorldRecord) -> bool:
        """Write one world record (:func:`world_record`) and its paths in one transaction;
        False (nothing written) if the world is already there."""
        wid = int(rec["world_id"])
        n = int(rec["starts"].shape[0])
        occ = rec["occupancy"]
        try:
            self.con.execute("BEGIN IMMEDIATE")
            try:
                if self.con.execute("SELECT 1 FROM worlds WHERE world_id = ?",
                                    (wid,)).fetchone():
                    self.con.execute("ROLLBACK")
                    return False
                digest = record_hash(rec)
                self._hash_old_worlds()
                dup = self.con.execute("SELECT world_id FROM world_hashes WHERE hash = ?",
                                       (digest,)).fetchone()
                if dup:
                    raise DuplicateWorldError(
                        f"database: '{self.path}': world {wid} has the same grid as world "
                        f"{int(dup[0])} (content hash {digest[:12]}): nothing written; "
                        f"distinct world seeds must give distinct worlds")
                sid = self._settings_id(rec["settings"])
                self.con.execute(
                    "INSERT OR IGNORE INTO worlds(world_id, dim, shape, limits, voxel_size, "
                    "occupancy, sdf, sdf_dtype, meta, n_paths, settings_id) "
                    "VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                    (wid, len(rec["shape"]), json.dumps(rec["shape"]),
                     np.asarray(rec["limits"], np.float64).tobytes(), rec["voxel_size"],
                     None if occ is None else _pack_occ(occ),
                     None if rec["sdf"] is None else zlib.compress(
                         np.asarray(rec["sdf"], np.float32).tobytes(), 6),
                     rec["sdf_dtype"], _json(rec["meta"]), n, sid))
                self.con.execute("INSERT INTO world_hashes(hash, world_id) VALUES (?, ?)",
                                 (digest, wid))
                w = int(rec["paths"].shape[1])
                self.con.executemany(
                    "INSERT OR IGNORE INTO paths(world_id, task, start, goal, waypoints, "
                    "n_waypoints, cost, feasible, hard, settings_id) "
                    "VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                    [(wid, i, rec["starts"][i].tobytes(), rec["goals"][i].tobytes(),
                      np.ascontiguousarray(rec["paths"][i]).tobytes(), w,
                      float(rec["cost"][i]), int(rec["feasible"][i]), int(rec["hard"][i]), sid)
                     for i in range(n)])
                self.con.execute("COMMIT")
            except BaseException:
                self._rollback()
                raise
        except sqlite3.Error as e:
            self._settings.clear()  # ids of a rolled-back transaction
            raise self._error(e, f"writing world {wid}") from None
        return True

    # ------------------------------------------------------------------ reading
    def _query(self, sql: str, args: Iterable = ()) -> list:
        try:
            return self.con.execute(sql, tuple(args)).fetchall()
        except sqlite3.Error as e:
            raise self._error(e, "reading it") from None

    def complete_worlds(self) -> set[int]:
        """The world ids (seeds) written completely (with all their paths)."""
        return {r[0] for r in self._query("SELECT world_id FROM worlds")}

    def world_ids(self) -> list[int]:
        return [r[0] for r in self._query("SELECT world_id FROM worlds ORDER BY world_id")]

    def n_paths(self) -> int:
        return int(self._query("SELECT COUNT(*) FROM paths")[0][0])

    def n_dof(self) -> int | None:
        r = self._query("SELECT length(start) FROM paths LIMIT 1")
        return None if not r else r[0][0] // 4

    def world_row(self, world_id: int) -> dict:
        """A stored world as a dict (shape, limits, voxel_size, occupancy or sdf, meta)."""
        r = self._query("SELECT shape, limits, voxel_size, occupancy, sdf, sdf_dtype, meta, "
                        "n_paths FROM worlds WHERE world_id = ?", (int(world_id),))
        if not r:
            raise KeyError(f"database: '{self.path}' has no world {world_id}")
        shape, lim, h, occ, sdf, dt, meta, n = r[0]
        field = "shape"
        try:
            shape = tuple(json.loads(shape))
            field = "limits"
            limits = np.frombuffer(lim, np.float64).reshape(len(shape), 2).copy()
            field = "occupancy"
            occupancy = None if occ is None else _unpack_occ(occ, shape)
            field = "sdf"
            grid = None if sdf is None else np.frombuffer(
                zlib.decompress(sdf), np.float32).reshape(shape).copy()
            field = "meta"
            meta = json.loads(meta)
        except (zlib.error, ValueError, TypeError) as e:
            raise DamagedRowError(
                f"database: '{self.path}': world {int(world_id)} is damaged (table worlds, "
                f"row world_id={int(world_id)}, column {field}: "
                f"{type(e).__name__}: {' '.join(str(e).split())})", world_id) from None
        return {"world_id": int(world_id), "shape": shape, "limits": limits,
                "voxel_size": float(h), "occupancy": occupancy, "sdf": grid,
                "sdf_dtype": dt, "meta": meta, "n_paths": int(n)}

    def world(self, world_id: int) -> Any:
        """The :class:`jwarp.world.sdf.World` of ``world_id``."""
        return world_from_record(self.world_row(world_id))

    def settings(self) -> list[dict]:
        return [json.loads(r[0]) for r in self._query(
            "SELECT json FROM settings ORDER BY settings_id")]

    def paths_of(self, world_ids: Iterable[int], *, skip_damaged: bool = False,
                 skipped: list | None = None) -> dict[str, np.ndarray]:
        """All paths of the worlds ``world_ids`` (in that order, tasks in order) as arrays
        world_id, task, start, goal, path (N, W, n_dof) float32, cost, feasible, hard.

        A row whose blobs have the wrong size (start/goal not n_dof float32 values,
        waypoints not n_waypoints x n_dof) is a :class:`DamagedRowError` naming the file,
        the world and the task; ``skip_damaged``: left out instead, and described in
        ``skipped`` (a list; dicts with ``what``, ``world_id``, ``task``, ``paths``)."""
        rows: list = []
        n_dof = self.n_dof()
        for wid in world_ids:
            for r in self._query("SELECT world_id, task, start, goal, waypoints, n_waypoints, "
                                 "cost, feasible, hard FROM paths WHERE world_id = ? "
                                 "ORDER BY task", (int(wid),)):
                bad = _bad_path_row(r, n_dof)
                if bad is None:
                    rows.append(r)
                    continue
                what = (f"path row (world_id={r[0]}, task={r[1]}) of world {r[0]} in "
                        f"'{self.path}': {bad}")
                if not skip_damaged:
                    raise DamagedRowError(f"database: '{self.path}': world {r[0]} is damaged "
                                          f"(table paths, row world_id={r[0]}, task={r[1]}: "
                                          f"{bad})", r[0], r[1])
                if skipped is not None:
                    skipped.append({"what": what, "world_id": int(r[0]), "task": int(r[1]),
                                    "paths": 1})
        return rows_to_arrays(rows)

    def rows(self) -> list[tuple]:
        """Every path row as (world_id, task, start bytes, goal bytes, waypoints bytes,
        cost, feasible, hard), ordered: for comparing databases."""
        return self._query("SELECT world_id, task, start, goal, waypoints, cost, feasible, "
                           "hard FROM paths ORDER BY world_id, task")

    def _hash_old_worlds(self) -> None:
        """Hashes of stored worlds that have none (a database of before the hash table),
        inside the caller's transaction; a duplicate among them keeps the first."""
        rows = self.con.execute(
            "SELECT world_id FROM worlds WHERE world_id NOT IN "
            "(SELECT world_id FROM world_hashes)").fetchall()
        for (wid,) in rows:
            self.con.execute("INSERT OR IGNORE INTO world_hashes(hash, world_id) VALUES (?, ?)",
                             (record_hash(self.world_row(int(wid))), int(wid)))

    def world_hashes(self) -> dict[int, str]:
        """``{world_id: content hash}`` of every stored world (:func:`record_hash`),
        computed from the rows (also for a database without the hash table)."""
        return {wid: record_hash(self.world_row(wid)) for wid in self.world_ids()}

    def info(self) -> dict:
        """A summary: meta, counts, feasible/hard fractions, the settings used."""
        n = self.n_paths()
        f, h = self._query("SELECT COALESCE(SUM(feasible), 0), COALESCE(SUM(hard), 0) "
                           "FROM paths")[0]
        ids = self.world_ids()
        # worlds whose stored paths are fewer than the world row says it has
        short = self._query("SELECT w.world_id, w.n_paths, COUNT(p.world_id) FROM worlds w "
                            "LEFT JOIN paths p ON p.world_id = w.world_id "
                            "GROUP BY w.world_id HAVING COUNT(p.world_id) < w.n_paths")
        by_hash: dict[str, list[int]] = {}
        for wid, digest in self.world_hashes().items():
            by_hash.setdefault(digest, []).append(wid)
        dups = [sorted(v) for v in by_hash.values() if len(v) > 1]
        return {"path": str(self.path), **{k: v for k, v in self.meta.items() if k != "bps"},
                "bps": self.bps is not None, "worlds": len(ids),
                "distinct_worlds": len(by_hash), "duplicate_worlds": dups,
                "world_ids": [ids[0], ids[-1]] if ids else [], "paths": n,
                "n_dof": self.n_dof(), "feasible": (f / n) if n else None,
                "hard": (h / n) if n else None, "settings": self.settings(),
                "worlds_missing_paths": [{"world_id": int(w), "expected": int(e),
                                          "stored": int(c)} for w, e, c in short]}


def _bad_path_row(r: tuple, n_dof: int | None) -> str | None:
    """Why the path row r (world_id, task, start, goal, waypoints, n_waypoints, ...) cannot
    be decoded, or None."""
    try:
        W = int(r[5])
    except (TypeError, ValueError):
        return f"n_waypoints is {r[5]!r}"
    for k, name in ((2, "start"), (3, "goal"), (4, "waypoints")):
        if not isinstance(r[k], (bytes, bytearray, memoryview)):
            return f"{name} is not a blob"
    n = len(r[2]) // 4 if n_dof is None else n_dof
    for k, name, size in ((2, "start", 4 * n), (3, "goal", 4 * n), (4, "waypoints", 4 * n * W)):
        if len(r[k]) != size:
            return f"{name} has {len(r[k])} bytes, expected {size} ({n} joints, {W} waypoints)"
    return None


def rows_to_arrays(rows: list) -> dict[str, np.ndarray]:
    if not rows:
        return {"world_id": np.zeros(0, np.int64), "task": np.zeros(0, np.int64),
                "start": np.zeros((0, 0), np.float32), "goal": np.zeros((0, 0), np.float32),
                "path": np.zeros((0, 0, 0), np.float32), "cost": np.zeros(0),
                "feasible": np.zeros(0, bool), "hard": np.zeros(0, bool)}
    n_dof = len(rows[0][2]) // 4
    w = rows[0][5]
    if any(r[5] != w for r in rows):
        raise ValueError("paths: rows with different numbers of waypoints cannot be stacked")
    return {
        "world_id": np.array([r[0] for r in rows], np.int64),
        "task": np.array([r[1] for r in rows], np.int64),
        "start": np.frombuffer(b"".join(r[2] for r in rows), np.float32).reshape(-1, n_dof),
        "goal": np.frombuffer(b"".join(r[3] for r in rows), np.float32).reshape(-1, n_dof),
        "path": np.frombuffer(b"".join(r[4] for r in rows), np.float32).reshape(-1, w, n_dof),
        "cost": np.array([r[6] for r in rows], np.float64),
        "feasible": np.array([bool(r[7]) for r in rows]),
        "hard": np.array([bool(r[8]) for r in rows]),
    }


# ====================================================================== export
def export_npz(db: str | os.PathLike | PathDB, out: str | os.PathLike, *,
               world_ids: Iterable[int] | None = None, skip_damaged: bool = False,
               skipped: list | None = None) -> Path:
    """Write the database (or the worlds ``world_ids``) to one ``.npz`` file, atomically
    (a temporary file renamed at the end). Arrays: ``world_id``, ``task``, ``start``,
    ``goal``, ``path`` (N, W, n_dof) float32, ``cost``, ``feasible``, ``hard``;
    ``worlds`` (M,) ids, ``world_limits`` (M, dim, 2), ``world_voxel_size`` (M,),
    ``world_occupancy`` (M, *shape) bool when every world has one of the same shape;
    ``meta`` (JSON string of the database's meta and settings).

    A damaged world or path row is a :class:`DamagedRowError` (file, world, row) before
    anything is written; ``skip_damaged``: damaged worlds (with their paths) and rows are
    left out and described in the list ``skipped`` (``what``, ``world_id``, ``task``,
    ``paths``)."""
    from jwarp.utils.atomic import AtomicFile

    own = not isinstance(db, PathDB)
    d = db if isinstance(db, PathDB) else PathDB(db)  # own: made here, closed here
    try:
        ids = d.world_ids() if world_ids is None else [int(i) for i in world_ids]
        rows, good = [], []
        for i in ids:
            try:
                rows.append(d.world_row(i))
                good.append(i)
            except DamagedRowError as e:
                if not skip_damaged:
                    raise
                if skipped is not None:
                    n = int(d._query("SELECT COUNT(*) FROM paths WHERE world_id = ?",
                                     (i,))[0][0])
                    skipped.append({"what": f"world {i} and its {n} paths: {e}",
                                    "world_id": i, "task": None, "paths": n})
        ids = good
        arrays: dict[str, Any] = d.paths_of(ids, skip_damaged=skip_damaged, skipped=skipped)
        arrays["worlds"] = np.array(ids, np.int64)
        if rows:
            arrays["world_limits"] = np.stack([r["limits"] for r in rows])
            arrays["world_voxel_size"] = np.array([r["voxel_size"] for r in rows])
            if all(r["occupancy"] is not None and r["shape"] == rows[0]["shape"] for r in rows):
                arrays["world_occupancy"] = np.stack([r["occupancy"] for r in rows])
        arrays["meta"] = np.array(_json({**d.meta, "settings": d.settings()}))
    finally:
        if own:
            d.close()
    with AtomicFile(out) as f, open(f.tmp, "wb") as fh:
        np.savez_compressed(fh, **arrays)
    return Path(out)


# ====================================================================== torch
class PathDataset(IterableDataset):
    """A ``torch.utils.data.IterableDataset`` streaming batches from a path database.

    Each item is a dict of tensors for ``batch_size`` paths: ``start`` (B, n_dof),
    ``goal``, ``path`` (B, W, n_dof) float32, ``cost`` (B,) float32, ``feasible``,
    ``hard`` (B,) bool, ``world_id`` (B,) int64; with ``occupancy=True`` also
    ``occupancy`` (K, *shape) bool, the grids of the K distinct worlds of the batch, and
    ``world_index`` (B,) int64, each path's row in it (``occupancy[world_index]`` is the
    grid per path; grids are read once per world and cached: ``cache_worlds`` of them). Use ``DataLoader(ds, batch_size=None, num_workers=k)``:
    every worker opens its own connection and reads every k-th world.

    ``shuffle``: worlds in a random order (``seed`` + :meth:`set_epoch`), paths shuffled
    within a buffer of ``shuffle_worlds`` worlds. ``feasible_only``: skip infeasible paths.
    ``world_ids``: a subset of the worlds (e.g. a train/validation split).
    ``robot``/``bps``: checked against the database as :class:`PathDB` does.
    """

    def __init__(self, path: str | os.PathLike, batch_size: int = 256, *,
                 shuffle: bool = False, seed: int = 0, feasible_only: bool = False,
                 occupancy: bool = False, world_ids: Iterable[int] | None = None,
                 shuffle_worlds: int = 16, drop_last: bool = False, cache_worlds: int = 64,
                 robot: RobotModel | None = None, bps: Any = None):
        super().__init__()
        if batch_size < 1:
            raise ValueError(f"batch_size: expected >= 1, got {batch_size}")
        self.path = str(path)
        with PathDB(path, robot, bps=bps) as db:  # checks the file now
            self.meta = dict(db.meta)
            self.world_ids = db.world_ids() if world_ids is None else [int(i) for i in world_ids]
            self.n_paths = db.n_paths()
        self.batch_size = int(batch_size)
        self.shuffle, self.seed, self.epoch = bool(shuffle), int(seed), 0
        self.feasible_only, self.occupancy = bool(feasible_only), bool(occupancy)
        self.shuffle_worlds, self.drop_last = max(1, int(shuffle_worlds)), bool(drop_last)
        self.cache_worlds = max(1, int(cache_worlds))
        self._db: PathDB | None = None
        self._cache: OrderedDict[int, dict] = OrderedDict()

    def __getstate__(self) -> dict:  # DataLoader workers started by spawn: no connection
        state = dict(self.__dict__)
        state["_db"], state["_cache"] = None, OrderedDict()
        return state

    def set_epoch(self, epoch: int) -> None:
        """Another shuffled order per epoch (same ``seed``)."""
        self.epoch = int(epoch)

    def _conn(self) -> PathDB:
        if self._db is None or self._db.path != Path(self.path):
            self._db = PathDB(self.path)
        return self._db

    def world(self, world_id: int) -> dict:
        """The stored world ``world_id`` (dict of :meth:`PathDB.world_row`), cached."""
        row = self._cache.get(world_id)
        if row is None:
            row = self._conn().world_row(world_id)
            self._cache[world_id] = row
            while len(self._cache) > self.cache_worlds:
                self._cache.popitem(last=False)
        else:
            self._cache.move_to_end(world_id)
        return row

    def __iter__(self) -> Iterator[dict]:
        import torch
        from torch.utils.data import get_worker_info

        ids = list(self.world_ids)
        rng = np.random.default_rng([self.seed, self.epoch])
        if self.shuffle:
            ids = [ids[i] for i in rng.permutation(len(ids))]
        info = get_worker_info()
        if info is not None:
            ids = ids[info.id::info.num_workers]
        self._db = None  # a fresh connection in this process (DataLoader workers fork)
        db = self._conn()
        group = self.shuffle_worlds if self.shuffle else 1
        carry: dict[str, np.ndarray] | None = None
        for g in range(0, len(ids), group):
            a = db.paths_of(ids[g:g + group])
            if self.feasible_only:
                a = {k: v[a["feasible"]] for k, v in a.items()}
            if self.shuffle and len(a["task"]):
                p = rng.permutation(len(a["task"]))
                a = {k: v[p] for k, v in a.items()}
            if carry is not None and len(carry["task"]):
                a = {k: np.concatenate([carry[k], a[k]]) if len(a[k]) else carry[k]
                     for k in carry}
            n = len(a["task"])
            b = 0
            while n - b >= self.batch_size:
                yield self._batch(a, slice(b, b + self.batch_size), torch)
                b += self.batch_size
            carry = {k: v[b:] for k, v in a.items()}
        if carry is not None and len(carry["task"]) and not self.drop_last:
            yield self._batch(carry, slice(0, len(carry["task"])), torch)

    def _batch(self, a: dict, s: slice, torch: Any) -> dict:
        out = {"start": torch.from_numpy(np.array(a["start"][s])),
               "goal": torch.from_numpy(np.array(a["goal"][s])),
               "path": torch.from_numpy(np.array(a["path"][s])),
               "cost": torch.from_numpy(a["cost"][s].astype(np.float32)),
               "feasible": torch.from_numpy(np.array(a["feasible"][s])),
               "hard": torch.from_numpy(np.array(a["hard"][s])),
               "world_id": torch.from_numpy(np.array(a["world_id"][s]))}
        if self.occupancy:  # each world of the batch once
            uniq, index = np.unique(a["world_id"][s], return_inverse=True)
            grids = [self.world(int(w))["occupancy"] for w in uniq]
            if any(g is None for g in grids):
                raise ValueError(f"database: '{self.path}': a world without occupancy grid "
                                 f"(occupancy=True needs one)")
            out["occupancy"] = torch.from_numpy(np.stack(grids))
            out["world_index"] = torch.from_numpy(index.reshape(-1).astype(np.int64))
        return out
