"""Target poses of ``jwarp ik`` from the command line (pure functions, no solver).

A target is a pose of the end-effector frame in the robot's base frame, a 4x4 matrix
``[[R, p], [0, 0, 0, 1]]`` (p [m], R a rotation matrix). Ways to give it:

* ``--target X,Y,Z`` [m]: the position, identity orientation (unless ``--quat``/``--rpy``).
* ``--target X,Y,Z,RX,RY,RZ``: position and a rotation vector (axis x angle) [rad].
* ``--target X,Y,Z --quat QX,QY,QZ,QW``: a quaternion in ROS/MoveIt order (x, y, z, w),
  normalised (a zero quaternion is an error).
* ``--target X,Y,Z --rpy R,P,Y`` [rad, also with ``--deg``, which is about joint values
  only]: roll, pitch, yaw about the fixed x, y, z axes, the ROS/URDF convention
  ``R = Rz(yaw) Ry(pitch) Rx(roll)`` (scipy ``Rotation.from_euler("xyz", ...)``).
* ``--target-matrix FILE_OR_16_NUMBERS``: the 4x4 matrix row by row, as 16 numbers
  (separated by commas and/or spaces; brackets ignored, so a numpy or JSON print works) or
  a text file holding them (``#`` comments). Its rotation block must be orthonormal with
  determinant +1 within :data:`RIGID_TOL` and its last row ``0 0 0 1``; the rotation is
  then replaced by the nearest rotation matrix (below the solver's tolerances).

Every error is a :class:`~jwarp.cli.common.CLIError` naming the option (two options when
they cannot be combined).
"""

from __future__ import annotations

import math
import os
import re
from collections.abc import Sequence

import numpy as np

from jwarp.cli.common import CLIError, read_small_text

#: the largest target coordinate [m] or rotation component [rad] (squares of larger ones
#: overflow; no robot reaches 1000 km)
MAX_TARGET = 1e6
#: tolerance of ``--target-matrix``'s rigid-transform check (orthonormality, det, last row)
RIGID_TOL = 1e-6

_SEP = re.compile(r"[\s,;]+")


def numbers(text: str, option: str, counts: Sequence[int], what: str) -> np.ndarray:
    """The finite numbers of ``text`` (comma separated, a trailing comma tolerated) as a
    float64 array; their count must be one of ``counts``; ``what`` names the expected
    format in the error (a CLIError naming ``option``)."""
    parts = [p.strip() for p in str(text).split(",")]
    if parts and parts[-1] == "":
        parts = parts[:-1]
    try:
        vals = [float(p) for p in parts]
    except ValueError:
        raise CLIError(f"{option}: expected {what} (numbers), got {text!r}") from None
    if len(vals) not in counts:
        n = " or ".join(str(c) for c in counts)
        raise CLIError(f"{option}: expected {n} numbers {what}, got {len(vals)} in {text!r}")
    if not all(math.isfinite(v) for v in vals):
        raise CLIError(f"{option}: expected finite numbers {what}, got {text!r}")
    if not all(abs(v) <= MAX_TARGET for v in vals):
        raise CLIError(f"{option}: expected values within +-{MAX_TARGET:g}, got {text!r}")
    return np.array(vals, np.float64)


def parse_target(text: str) -> tuple[np.ndarray, np.ndarray | None]:
    """``--target X,Y,Z[,RX,RY,RZ]`` -> (position (3,) [m], rotation vector (3,) [rad] or
    None when only the position is given)."""
    v = numbers(text, "--target", (3, 6), "x,y,z[,rx,ry,rz] (m, rad)")
    return v[:3], (v[3:] if len(v) == 6 else None)


def quaternion_matrix(text: str, option: str = "--quat") -> np.ndarray:
    """``--quat QX,QY,QZ,QW`` (ROS/MoveIt order, scalar last) -> rotation (3, 3); the
    quaternion is normalised, a zero one is an error."""
    q = numbers(text, option, (4,), "qx,qy,qz,qw (a quaternion, scalar last)")
    norm = float(np.linalg.norm(q))
    if not norm > 1e-12:
        raise CLIError(f"{option}: the quaternion {text!r} has zero norm")
    x, y, z, w = q / norm
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def rpy_matrix(text: str, option: str = "--rpy") -> np.ndarray:
    """``--rpy R,P,Y`` [rad] -> rotation (3, 3) = Rz(yaw) Ry(pitch) Rx(roll) (ROS/URDF:
    roll, pitch, yaw about the fixed x, y, z axes)."""
    r, p, y = numbers(text, option, (3,), "roll,pitch,yaw [rad]")
    cr, sr, cp, sp, cy, sy = (math.cos(r), math.sin(r), math.cos(p), math.sin(p),
                              math.cos(y), math.sin(y))
    rx = np.array([[1.0, 0.0, 0.0], [0.0, cr, -sr], [0.0, sr, cr]])
    ry = np.array([[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]])
    rz = np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]])
    return rz @ ry @ rx


def rotvec_matrix(rotvec: np.ndarray) -> np.ndarray:
    """Rotation (3, 3) of a rotation vector (3,) [rad] (Rodrigues' formula)."""
    w = np.asarray(rotvec, np.float64).reshape(3)
    a = float(np.linalg.norm(w))
    if a < 1e-300:
        return np.eye(3)
    k = w / a
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(a) * K + (1.0 - math.cos(a)) * (K @ K)


def nearest_rotation(R: np.ndarray) -> np.ndarray:
    """The rotation matrix nearest to R (3, 3) in the Frobenius norm (SVD polar factor)."""
    u, _, vt = np.linalg.svd(R)
    d = np.sign(np.linalg.det(u @ vt))
    return u @ np.diag([1.0, 1.0, d]) @ vt


def matrix_target(text: str, option: str = "--target-matrix") -> np.ndarray:
    """``--target-matrix FILE_OR_16_NUMBERS`` -> pose (4, 4): 16 numbers row by row
    (separated by commas, spaces or semicolons; brackets ignored) or a text file holding
    them (``#`` starts a comment). The rotation block must be orthonormal within
    :data:`RIGID_TOL` with determinant +1 and the last row ``0 0 0 1``; it is replaced by
    the nearest rotation."""
    raw = str(text)
    flat = _SEP.split(raw.replace("[", " ").replace("]", " ").strip())
    source = "the value"
    try:
        vals = [float(p) for p in flat if p]
    except ValueError:
        vals = None
    if vals is None or len(vals) != 16:
        looks_numeric = vals is not None
        if not looks_numeric and os.path.exists(raw):
            if os.path.isdir(raw):
                raise CLIError(f"{option}: {raw} is a folder, not a file of 16 numbers")
            body = "\n".join(line.split("#", 1)[0]
                             for line in read_small_text(raw, option).splitlines())
            try:
                vals = [float(p) for p in _SEP.split(
                    body.replace("[", " ").replace("]", " ").strip()) if p]
            except ValueError:
                raise CLIError(f"{option}: {raw} holds something other than numbers") from None
            source = raw
        elif not looks_numeric:
            raise CLIError(f"{option}: expected 16 numbers (a 4x4 matrix row by row) or a "
                           f"file of them; {raw!r} is neither (no such file)")
        if len(vals) != 16:
            raise CLIError(f"{option}: expected 16 numbers (a 4x4 matrix row by row), got "
                           f"{len(vals)} in {source if source != 'the value' else repr(raw)}")
    return rigid_pose(np.array(vals, np.float64).reshape(4, 4), option)


def rigid_pose(T: np.ndarray, where: str) -> np.ndarray:
    """The pose (4, 4) ``T`` with its rotation replaced by the nearest rotation, after the
    checks of ``--target-matrix`` (finite, within :data:`MAX_TARGET`, last row ``0 0 0 1``,
    rotation block orthonormal within :data:`RIGID_TOL` with determinant +1); a CLIError
    starting with ``where`` otherwise."""
    if not np.all(np.isfinite(T)):
        raise CLIError(f"{where}: the matrix holds NaN or inf")
    if np.abs(T).max() > MAX_TARGET:
        raise CLIError(f"{where}: expected values within +-{MAX_TARGET:g}")
    last = np.abs(T[3] - [0.0, 0.0, 0.0, 1.0]).max()
    if last > RIGID_TOL:
        raise CLIError(f"{where}: not a rigid transform: the last row is "
                       f"{' '.join(f'{v:g}' for v in T[3])}, expected 0 0 0 1")
    R = T[:3, :3]
    ortho = float(np.abs(R @ R.T - np.eye(3)).max())
    if ortho > RIGID_TOL:
        raise CLIError(f"{where}: not a rigid transform: the rotation block is not "
                       f"orthonormal (largest |R R^T - I| entry {ortho:.3g} > {RIGID_TOL:g})")
    det = float(np.linalg.det(R))
    if det < 0:
        raise CLIError(f"{where}: not a rigid transform: the rotation block is a reflection "
                       f"(determinant {det:.6g})")
    out = np.eye(4)
    out[:3, :3] = nearest_rotation(R)
    out[:3, 3] = T[:3, 3]
    return out


def unit_axis(text: str, option: str = "--free-axis") -> np.ndarray:
    """``--free-axis X,Y,Z`` -> unit vector (3,) (normalised; zero is an error)."""
    v = numbers(text, option, (3,), "x,y,z (an axis of the end-effector frame)")
    n = float(np.linalg.norm(v))
    if not n > 1e-12:
        raise CLIError(f"{option}: the axis {text!r} has zero length")
    return v / n


def target_pose(target: str | None = None, quat: str | None = None, rpy: str | None = None,
                matrix: str | None = None) -> tuple[np.ndarray, bool]:
    """The pose (4, 4) of ``--target`` [+ ``--quat`` | ``--rpy``] or ``--target-matrix``,
    and whether an orientation was given (False: ``--target X,Y,Z`` alone, identity).

    Errors (naming the options): none or both of ``--target``/``--target-matrix``,
    ``--quat`` with ``--rpy``, either with a 6-number ``--target`` or with
    ``--target-matrix``, and each value's own format."""
    if matrix is not None:
        for opt, val in (("--target", target), ("--quat", quat), ("--rpy", rpy)):
            if val is not None:
                raise CLIError(f"--target-matrix: not allowed with {opt} (the matrix holds "
                               f"the whole pose)")
        return matrix_target(matrix), True
    if target is None:
        raise CLIError("--target: give the target as --target X,Y,Z[,RX,RY,RZ] (optionally "
                       "with --quat or --rpy) or --target-matrix")
    if quat is not None and rpy is not None:
        raise CLIError("--quat: not allowed with --rpy (give one orientation)")
    p, rv = parse_target(target)
    T = np.eye(4)
    T[:3, 3] = p
    if quat is not None or rpy is not None:
        opt = "--quat" if quat is not None else "--rpy"
        if rv is not None:
            raise CLIError(f"{opt}: not allowed with a 6-number --target (its rx,ry,rz are "
                           f"an orientation already); give --target X,Y,Z {opt} ...")
        T[:3, :3] = quaternion_matrix(quat) if quat is not None else rpy_matrix(rpy)
        return T, True
    if rv is not None:
        T[:3, :3] = rotvec_matrix(rv)
        return T, True
    return T, False


# ------------------------------------------------------------------ --targets FILE
#: the column layouts of ``--targets`` (CSV header names; docs/ik.md "Many targets")
TARGET_LAYOUTS: dict[str, tuple[str, ...]] = {
    "position": ("x", "y", "z"),
    "quaternion": ("x", "y", "z", "qx", "qy", "qz", "qw"),
    "rpy": ("x", "y", "z", "roll", "pitch", "yaw"),
    "rotvec": ("x", "y", "z", "rx", "ry", "rz"),
    "matrix": tuple(f"m{i}{j}" for i in range(4) for j in range(4)),
}
#: the layout of a file without names, by its number of columns (6 is ambiguous: rpy or
#: a rotation vector, so it needs a header)
_BY_COUNT = {3: "position", 7: "quaternion", 16: "matrix"}


def _layout_of(header: list[str], where: str) -> str:
    names = tuple(h.strip().lower() for h in header)
    for layout, cols in TARGET_LAYOUTS.items():
        if names == cols:
            return layout
    known = "; ".join(",".join(c) if k != "matrix" else "m00,m01,...,m33"
                      for k, c in TARGET_LAYOUTS.items())
    raise CLIError(f"{where}: unknown column names {','.join(header)!r}; expected one of: "
                   f"{known}")


def _count_layout(n: int, where: str) -> str:
    if n in _BY_COUNT:
        return _BY_COUNT[n]
    if n == 6:
        raise CLIError(f"{where}: 6 columns are either x,y,z,roll,pitch,yaw or x,y,z,rx,ry,rz "
                       f"(a rotation vector); name them in a CSV header line")
    raise CLIError(f"{where}: expected 3 (x,y,z), 7 (x,y,z,qx,qy,qz,qw) or 16 (a 4x4 matrix "
                   f"row by row) columns, or a CSV header naming 6, got {n}")


def _split(line: str) -> list[str]:
    return [p.strip() for p in (line.split(",") if "," in line else line.split())]


def _read_csv(path: str, option: str) -> tuple[np.ndarray, str, list[int]]:
    """(values (N, C), layout, file line of each row) of a CSV/text targets file."""
    try:
        with open(path, encoding="utf-8") as fh:
            lines = fh.read().splitlines()
    except (OSError, UnicodeDecodeError) as e:
        raise CLIError(f"{option}: cannot read {path}: {e}") from None
    rows: list[list[float]] = []
    where_line: list[int] = []
    layout = None
    for k, raw in enumerate(lines, start=1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        parts = _split(line)
        try:
            vals = [float(p) for p in parts]
        except ValueError:
            vals = None
        if vals is None:
            if layout is None and not rows:   # the header
                layout = _layout_of(parts, f"{option}: {path} line {k}")
                continue
            bad = next(p for p in parts if not _is_number(p))
            raise CLIError(f"{option}: {path} row {len(rows) + 1} (line {k}): {bad!r} is not a "
                           f"number")
        if rows and len(vals) != len(rows[0]):
            raise CLIError(f"{option}: {path} row {len(rows) + 1} (line {k}): {len(vals)} "
                           f"columns, the rows before have {len(rows[0])}")
        rows.append(vals)
        where_line.append(k)
    if not rows:
        raise CLIError(f"{option}: {path} holds no targets")
    if layout is None:
        layout = _count_layout(len(rows[0]), f"{option}: {path}")
    elif len(rows[0]) != len(TARGET_LAYOUTS[layout]):
        raise CLIError(f"{option}: {path} row 1 (line {where_line[0]}): {len(rows[0])} columns, "
                       f"the header names {len(TARGET_LAYOUTS[layout])}")
    return np.array(rows, np.float64), layout, where_line


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _read_npy(path: str, option: str) -> tuple[np.ndarray, str]:
    """(values (N, C), layout) of a .npy targets file: (N, 3), (N, 7), (N, 16) or
    (N, 4, 4) (one target: (3,), (7,), (16,) or (4, 4))."""
    try:
        a = np.load(path, allow_pickle=False)
    except (OSError, ValueError, EOFError) as e:
        raise CLIError(f"{option}: cannot read {path} as a .npy array: "
                       f"{' '.join(str(e).split())}") from None
    if a.dtype.kind not in "fiu" or a.dtype == np.bool_:
        raise CLIError(f"{option}: {path} holds {a.dtype} values, not real numbers")
    if a.shape[-2:] == (4, 4) and a.ndim in (2, 3):
        a = a.reshape(-1, 16)
    elif a.ndim == 1:
        a = a[None]
    if a.ndim != 2 or a.shape[0] == 0:
        raise CLIError(f"{option}: {path} has shape {a.shape}; expected (N, 3), (N, 7), "
                       f"(N, 16) or (N, 4, 4)")
    if a.shape[1] == 6:
        raise CLIError(f"{option}: {path} has 6 columns, either x,y,z,roll,pitch,yaw or "
                       f"x,y,z,rx,ry,rz; write a CSV file with a header line naming them")
    return np.asarray(a, np.float64), _count_layout(a.shape[1], f"{option}: {path}")


def read_targets(path: str, option: str = "--targets") -> tuple[np.ndarray, str]:
    """The target poses (N, 4, 4) of a targets file and its layout (a key of
    :data:`TARGET_LAYOUTS`; ``"position"``: identity orientations).

    ``.npy``: (N, 3), (N, 7), (N, 16) or (N, 4, 4) float values. Any other file is CSV
    (commas, or whitespace) with an optional header line naming the columns as in
    :data:`TARGET_LAYOUTS`; without one 3, 7 or 16 columns decide (6 need the header);
    ``#`` starts a comment, blank lines are skipped. Quaternions (x, y, z, w) are
    normalised, matrices checked as ``--target-matrix``'s. Every error is a CLIError
    naming ``option``, the file and the row (1-based; CSV: and the line)."""
    import os

    if not os.path.exists(path):
        raise CLIError(f"{option}: file not found: '{path}'")
    if os.path.isdir(path):
        raise CLIError(f"{option}: {path} is a folder, not a file of targets")
    if path.lower().endswith(".npy"):
        vals, layout = _read_npy(path, option)
        lines: list[int] | None = None
    else:
        vals, layout, lines = _read_csv(path, option)

    def where(i: int) -> str:
        line = f" (line {lines[i]})" if lines is not None else ""
        return f"{option}: {path} row {i + 1}{line}"

    bad = ~np.isfinite(vals).all(axis=1)
    if bad.any():
        raise CLIError(f"{where(int(np.flatnonzero(bad)[0]))}: NaN or inf")
    big = (np.abs(vals) > MAX_TARGET).any(axis=1)
    if big.any():
        raise CLIError(f"{where(int(np.flatnonzero(big)[0]))}: expected values within "
                       f"+-{MAX_TARGET:g}")
    N = len(vals)
    T = np.broadcast_to(np.eye(4), (N, 4, 4)).copy()
    if layout == "matrix":
        for i in range(N):
            T[i] = rigid_pose(vals[i].reshape(4, 4), where(i))
        return T, layout
    T[:, :3, 3] = vals[:, :3]
    rot = vals[:, 3:]
    if layout == "quaternion":
        norm = np.linalg.norm(rot, axis=1)
        zero = ~(norm > 1e-12)
        if zero.any():
            raise CLIError(f"{where(int(np.flatnonzero(zero)[0]))}: the quaternion "
                           f"qx,qy,qz,qw has zero norm")
        from jwarp.solvers.ik.objective import quaternion_matrices

        T[:, :3, :3] = quaternion_matrices(rot)
    elif layout == "rpy":
        r, p, y = rot.T
        cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
        T[:, :3, :3] = np.stack([
            np.stack([cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr], -1),
            np.stack([sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr], -1),
            np.stack([-sp, cp * sr, cp * cr], -1)], -2)
    elif layout == "rotvec":
        for i in range(N):
            T[i, :3, :3] = rotvec_matrix(rot[i])
    return T, layout
