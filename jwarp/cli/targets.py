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
from typing import Sequence

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
    T = np.array(vals, np.float64).reshape(4, 4)
    if not np.all(np.isfinite(T)):
        raise CLIError(f"{option}: the matrix holds NaN or inf")
    if np.abs(T).max() > MAX_TARGET:
        raise CLIError(f"{option}: expected values within +-{MAX_TARGET:g}")
    last = np.abs(T[3] - [0.0, 0.0, 0.0, 1.0]).max()
    if last > RIGID_TOL:
        raise CLIError(f"{option}: not a rigid transform: the last row is "
                       f"{' '.join(f'{v:g}' for v in T[3])}, expected 0 0 0 1")
    R = T[:3, :3]
    ortho = float(np.abs(R @ R.T - np.eye(3)).max())
    if ortho > RIGID_TOL:
        raise CLIError(f"{option}: not a rigid transform: the rotation block is not "
                       f"orthonormal (largest |R R^T - I| entry {ortho:.3g} > {RIGID_TOL:g})")
    det = float(np.linalg.det(R))
    if det < 0:
        raise CLIError(f"{option}: not a rigid transform: the rotation block is a reflection "
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
