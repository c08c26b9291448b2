"""Small rigid-body helpers shared by the measurement plugins (numpy float64, vectorized).

Rotation vectors use scipy's convention (:meth:`Rotation.from_rotvec`). The derivative of
``R(r)`` w.r.t. its rotation vector is expressed with the left Jacobian of SO(3):
``R(r + dr) = (I + [J_l(r) dr]x) R(r)`` to first order, i.e. a change ``dr`` rotates the
frame by the base-frame angle ``J_l(r) dr``.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from jwarp.model import RobotModel

# scipy.spatial.transform is imported inside the functions: importing it costs 0.3 s, and
# every plugin load (any `jwarp` command) imports this module (issue 27: CLI start-up).


def skew(v: np.ndarray) -> np.ndarray:
    """Cross-product matrices: v (..., 3) -> [v]x (..., 3, 3) with [v]x a = v x a."""
    v = np.asarray(v, dtype=np.float64)
    out = np.zeros(v.shape + (3,))
    out[..., 0, 1] = -v[..., 2]
    out[..., 0, 2] = v[..., 1]
    out[..., 1, 0] = v[..., 2]
    out[..., 1, 2] = -v[..., 0]
    out[..., 2, 0] = -v[..., 1]
    out[..., 2, 1] = v[..., 0]
    return out


def rotvec_matrix(r: np.ndarray) -> np.ndarray:
    """Rotation matrix (3, 3) of a rotation vector r (3,) [rad]."""
    from scipy.spatial.transform import Rotation

    return Rotation.from_rotvec(np.asarray(r, dtype=np.float64)).as_matrix()


def left_jacobian(r: np.ndarray) -> np.ndarray:
    """Left Jacobian J_l(r) (3, 3) of SO(3): ``dR = [J_l(r) dr]x R`` (r (3,) [rad])."""
    r = np.asarray(r, dtype=np.float64)
    th2 = float(r @ r)
    k = skew(r)
    if th2 < 1e-8:  # Taylor series, error O(th^4)
        a = 0.5 - th2 / 24.0
        b = 1.0 / 6.0 - th2 / 120.0
    else:
        th = math.sqrt(th2)
        a = (1.0 - math.cos(th)) / th2
        b = (th - math.sin(th)) / (th2 * th)
    return np.eye(3) + a * k + b * (k @ k)


def nearest_rotvec(R: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """Rotation vector of R (3, 3) closest to ``ref`` (3,) [rad] among its equivalent
    representations ``(angle + 2 pi k) axis`` (a rotation near pi has two nearly opposite
    ones). Keeps a fitted pose next to its prior mean, so the Gaussian prior on the rotation
    vector measures the actual change."""
    from scipy.spatial.transform import Rotation

    r = Rotation.from_matrix(np.asarray(R, dtype=np.float64)).as_rotvec()
    ref = np.asarray(ref, dtype=np.float64)
    th = float(np.linalg.norm(r))
    if th < 1e-12:
        nr = float(np.linalg.norm(ref))
        if nr < 1e-12:
            return r
        axis, th = ref / nr, 0.0
    else:
        axis = r / th
    cands = (th + 2.0 * math.pi * np.arange(-2, 3))[:, None] * axis
    return cands[int(np.argmin(np.linalg.norm(cands - ref, axis=1)))]


def pose_matrix(position: np.ndarray, rotvec: np.ndarray) -> np.ndarray:
    """4x4 homogeneous transform from position (3,) [m] and rotation vector (3,) [rad]."""
    T = np.eye(4)
    T[:3, :3] = rotvec_matrix(rotvec)
    T[:3, 3] = position
    return T


def point_twist_rows(n: np.ndarray, x: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """d(n . x) / d twist for a point x fixed in a frame with origin ``origin``.

    A twist (v, w) in base coordinates moves x by ``v + w x (x - origin)``, so the row is
    ``[n, (x - origin) x n]``. n, x, origin (..., 3) (n may be (..., k, 3) with x, origin
    broadcasting) -> (..., 6).
    """
    n, x, origin = np.broadcast_arrays(n, x, origin)
    return np.concatenate([n, np.cross(x - origin, n)], axis=-1)


def rigid_align(src: np.ndarray, dst: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares rigid transform (Kabsch): ``dst ~ R src + t``.

    src, dst (N, 3). Returns (R (3, 3), t (3,)). Raises ValueError when the points do not
    span at least a plane (the rotation is then not determined).
    """
    src = np.asarray(src, dtype=np.float64).reshape(-1, 3)
    dst = np.asarray(dst, dtype=np.float64).reshape(-1, 3)
    if src.shape != dst.shape or src.shape[0] < 3:
        raise ValueError(f"rigid_align: need >= 3 matching points, got {src.shape} and {dst.shape}")
    ms, md = src.mean(axis=0), dst.mean(axis=0)
    a, b = src - ms, dst - md
    sv = np.linalg.svd(a, compute_uv=False)
    if sv[1] <= 1e-9 * max(sv[0], 1e-300):
        raise ValueError("rigid_align: the points are collinear; the rotation is not determined")
    from scipy.spatial.transform import Rotation

    rot, _ = Rotation.align_vectors(b, a)
    R = rot.as_matrix()
    return R, md - R @ ms


def finite_array(x: Any, where: str, shape: tuple[int, ...] | None = None) -> np.ndarray:
    """``x`` as a finite float64 array (of ``shape`` if given) or a ValueError naming ``where``."""
    try:
        a = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{where}: expected numbers, got {x!r}") from None
    if shape is not None and a.shape != shape:
        raise ValueError(f"{where}: expected {shape[0] if len(shape) == 1 else shape} "
                         f"numbers, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{where}: contains NaN or inf")
    return a


def positive(x: Any, where: str, *, allow_zero: bool = False, allow_inf: bool = False) -> float:
    """A scalar > 0 (or >= 0), or a ValueError naming ``where``. JSON ``null`` = inf when
    ``allow_inf``."""
    if x is None and allow_inf:
        return math.inf
    if isinstance(x, bool) or not isinstance(x, (int, float, np.integer, np.floating)):
        raise ValueError(f"{where}: expected a number, got {x!r}")
    v = float(x)
    if math.isnan(v) or (math.isinf(v) and not allow_inf):
        raise ValueError(f"{where}: expected a finite number, got {x!r}")
    if v < 0 or (v == 0 and not allow_zero):
        raise ValueError(f"{where}: must be {'>= 0' if allow_zero else '> 0'}, got {x!r}")
    return v


def section(setup: dict, key: str, where: str, default: Any = ...) -> Any:
    """``setup[key]`` or a ValueError naming the missing key (unless a default is given)."""
    if key in setup:
        return setup[key]
    if default is ...:
        raise ValueError(f"{where}: missing key '{key}'")
    return default


def check_keys(d: Any, allowed: set[str], where: str) -> dict:
    """``d`` must be a dict whose keys are all in ``allowed``."""
    if not isinstance(d, dict):
        raise ValueError(f"{where}: expected an object, got {type(d).__name__}")
    extra = sorted(set(d) - allowed)
    if extra:
        raise ValueError(f"{where}: unknown key(s) {extra}; allowed: {sorted(allowed)}")
    return d


def robot_frame(robot: RobotModel, frame: int | str, where: str) -> int:
    """Index of a robot frame given by name (frame or end-effector) or index."""
    if isinstance(frame, bool) or not isinstance(frame, (str, int, np.integer)):
        raise ValueError(f"{where}: expected a frame name, got {frame!r}")
    return robot.frame_index(frame, argname=where)


def valid_name(name: Any, where: str) -> str:
    """A non-empty identifier-like name usable in CSV column names."""
    if not isinstance(name, str) or not name or any(c in name for c in ", \t\n\"'"):
        raise ValueError(f"{where}: expected a non-empty name without spaces or commas, "
                         f"got {name!r}")
    return name


def parse_pose(d: Any, where: str, *, default_sigma_position: float,
               default_sigma_rotation: float, required: bool = True
               ) -> tuple[np.ndarray, np.ndarray, float, float]:
    """A pose section ``{"position": [3] m, "rotvec": [3] rad, "sigma_position": m,
    "sigma_rotation": rad}`` (extra keys are left to the caller) ->
    (position, rotvec, sigma_position, sigma_rotation). Missing position/rotvec are zero
    unless ``required``."""
    if not isinstance(d, dict):
        raise ValueError(f"{where}: expected an object, got {type(d).__name__}")
    zero = [0.0, 0.0, 0.0]
    pos = finite_array(section(d, "position", where, ... if required else zero),
                       f"{where}.position", (3,))
    rv = finite_array(section(d, "rotvec", where, zero), f"{where}.rotvec", (3,))
    sp = positive(d.get("sigma_position", default_sigma_position), f"{where}.sigma_position",
                  allow_inf=True)
    sr = positive(d.get("sigma_rotation", default_sigma_rotation), f"{where}.sigma_rotation",
                  allow_inf=True)
    return pos, rv, sp, sr


def pose_param_entries(prefix: str, position: np.ndarray, rotvec: np.ndarray,
                       sigma_position: float, sigma_rotation: float, group: str
                       ) -> tuple[list[str], list[float], list[float], list[str]]:
    """Names ``<prefix>_px.._pz, <prefix>_rx.._rz``, nominal values, sigmas, groups."""
    names = [f"{prefix}_p{a}" for a in "xyz"] + [f"{prefix}_r{a}" for a in "xyz"]
    nominal = list(map(float, position)) + list(map(float, rotvec))
    sigma = [sigma_position] * 3 + [sigma_rotation] * 3
    return names, nominal, sigma, [group] * 6


def parse_markers(setup: dict, robot: RobotModel, *, default_sigma: float, frame_optional: bool,
                  position_required: bool
                  ) -> tuple[list[str], list[int | None], tuple[list[str], list[float],
                                                                list[float], list[str]]]:
    """``setup["markers"]``: a non-empty list of ``{"name", "frame", "position" [3] m,
    "sigma" m}``. Returns (names, frame indices (None for a world-fixed marker where
    ``frame_optional`` and the frame is null), parameter entries: names
    ``marker_<name>_x..z``, nominal positions, sigmas, groups ``"markers"``). A missing
    position is zero unless ``position_required``."""
    markers = section(setup, "markers", "setup")
    if not isinstance(markers, list) or not markers:
        raise ValueError("setup.markers: expected a non-empty list of markers")
    marker_names: list[str] = []
    frames: list[int | None] = []
    names: list[str] = []
    nominal: list[float] = []
    sigma: list[float] = []
    for k, mk in enumerate(markers):
        where = f"setup.markers[{k}]"
        check_keys(mk, {"name", "frame", "position", "sigma"}, where)
        nm = valid_name(section(mk, "name", where), f"{where}.name")
        if nm in marker_names:
            raise ValueError(f"{where}.name: duplicate marker name '{nm}'")
        fr = section(mk, "frame", where)
        frames.append(None if fr is None and frame_optional
                      else robot_frame(robot, fr, f"{where}.frame"))
        x = finite_array(section(mk, "position", where,
                                 ... if position_required else [0.0, 0.0, 0.0]),
                         f"{where}.position", (3,))
        s = positive(mk.get("sigma", default_sigma), f"{where}.sigma", allow_inf=True)
        marker_names.append(nm)
        names += [f"marker_{nm}_{a}" for a in "xyz"]
        nominal += list(map(float, x))
        sigma += [s] * 3
    return marker_names, frames, (names, nominal, sigma, ["markers"] * len(names))

