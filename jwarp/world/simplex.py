"""Seeded simplex noise (2D and 3D, plain numpy) and occupancy worlds made from it.

The noise is Gustavson's simplex noise ("Simplex noise demystified", 2005; thesis
Fig. 3.21): a gradient noise on a simplex lattice whose values lie in about [-1, 1]
(mean 0). A seed fixes the lattice permutation and a random offset in noise space, so the
same seed always gives the same world on every machine (numpy's PCG64 generator).

An occupancy world thresholds the noise sampled on a regular grid: a cell is occupied
where ``noise > threshold``. The two knobs of Fig. 3.21 are

* ``frequency`` (the "resolution"): noise periods across the longest side of the grid;
  low values give few large blobs, high values many small ones;
* ``threshold`` in [-1, 1]: higher values give fewer obstacles (one octave: 0.4 fills
  about 20 % of the cells, the default 0.6 about 10 %, 0.7 about 5 %).

The defaults (frequency 2, threshold 0.6) give worlds in which typically 10-40 % of
random configurations of planar4, arm7 and justin19 are collision-free, so the
200/1000 filter of :func:`jwarp.world.feasible_simplex_world` passes within a few seeds.

Optional ``octaves`` add finer noise layers (each doubling the frequency, amplitude
times ``persistence``), normalised so the sum stays in about [-1, 1].
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from jwarp.utils.checks import check_int

if TYPE_CHECKING:
    from jwarp.world.sdf import World

__all__ = ["simplex_noise", "noise_grid", "simplex_occupancy", "simplex_world"]

_F2 = 0.5 * (np.sqrt(3.0) - 1.0)
_G2 = (3.0 - np.sqrt(3.0)) / 6.0
_F3 = 1.0 / 3.0
_G3 = 1.0 / 6.0
# the 12 edge midpoints of a cube: gradient directions of 2D (x, y used) and 3D noise
_GRAD3 = np.array([[1, 1, 0], [-1, 1, 0], [1, -1, 0], [-1, -1, 0],
                   [1, 0, 1], [-1, 0, 1], [1, 0, -1], [-1, 0, -1],
                   [0, 1, 1], [0, -1, 1], [0, 1, -1], [0, -1, -1]], np.float64)


def _check_seed(seed: object) -> int:
    return check_int(seed, "seed", 0)


def _permutation(seed: int) -> np.ndarray:
    """(512,) the permutation of 0..255 of ``seed``, repeated twice."""
    p = np.random.default_rng(seed).permutation(256)
    return np.concatenate([p, p]).astype(np.int64)


def _noise2(x: np.ndarray, y: np.ndarray, perm: np.ndarray) -> np.ndarray:
    s = (x + y) * _F2
    i = np.floor(x + s)
    j = np.floor(y + s)
    t = (i + j) * _G2
    x0 = x - (i - t)
    y0 = y - (j - t)
    i1 = (x0 > y0).astype(np.int64)
    j1 = 1 - i1
    corners = ((x0, y0, 0, 0),
               (x0 - i1 + _G2, y0 - j1 + _G2, i1, j1),
               (x0 - 1.0 + 2.0 * _G2, y0 - 1.0 + 2.0 * _G2, 1, 1))
    ii = i.astype(np.int64) & 255
    jj = j.astype(np.int64) & 255
    total = np.zeros(np.shape(x))
    for cx, cy, oi, oj in corners:
        gi = perm[ii + oi + perm[jj + oj]] % 12
        t0 = 0.5 - cx * cx - cy * cy
        g = _GRAD3[gi]
        contrib = t0 ** 4 * (g[..., 0] * cx + g[..., 1] * cy)
        total += np.where(t0 > 0.0, contrib, 0.0)
    return 70.0 * total


def _noise3(x: np.ndarray, y: np.ndarray, z: np.ndarray, perm: np.ndarray) -> np.ndarray:
    s = (x + y + z) * _F3
    i = np.floor(x + s)
    j = np.floor(y + s)
    k = np.floor(z + s)
    t = (i + j + k) * _G3
    x0 = x - (i - t)
    y0 = y - (j - t)
    z0 = z - (k - t)
    # which of the six simplices (Gustavson's case table): corner offsets 1 and 2
    xy, yz, xz = x0 >= y0, y0 >= z0, x0 >= z0
    cases = [xy & yz, xy & ~yz & xz, xy & ~yz & ~xz,
             ~xy & ~yz, ~xy & yz & ~xz, ~xy & yz & xz]
    #          X>=Y>=Z    X>=Z>Y     Z>X>=Y     Z>Y>X      Y>=Z>X     Y>X>=Z
    first = [(1, 0, 0), (1, 0, 0), (0, 0, 1), (0, 0, 1), (0, 1, 0), (0, 1, 0)]
    second = [(1, 1, 0), (1, 0, 1), (1, 0, 1), (0, 1, 1), (0, 1, 1), (1, 1, 0)]
    i1, j1, k1 = (np.select(cases, [f[a] for f in first]).astype(np.int64) for a in range(3))
    i2, j2, k2 = (np.select(cases, [f[a] for f in second]).astype(np.int64) for a in range(3))
    ii = i.astype(np.int64) & 255
    jj = j.astype(np.int64) & 255
    kk = k.astype(np.int64) & 255
    offs = ((0, 0, 0), (i1, j1, k1), (i2, j2, k2), (1, 1, 1))
    total = np.zeros(np.shape(x))
    for c, (oi, oj, ok) in enumerate(offs):
        cx = x0 - oi + c * _G3
        cy = y0 - oj + c * _G3
        cz = z0 - ok + c * _G3
        gi = perm[ii + oi + perm[jj + oj + perm[kk + ok]]] % 12
        t0 = 0.6 - cx * cx - cy * cy - cz * cz
        g = _GRAD3[gi]
        contrib = t0 ** 4 * (g[..., 0] * cx + g[..., 1] * cy + g[..., 2] * cz)
        total += np.where(t0 > 0.0, contrib, 0.0)
    return 32.0 * total


def simplex_noise(points: np.ndarray, seed: int) -> np.ndarray:
    """Simplex noise at ``points`` (..., 2) or (..., 3) in noise coordinates (one lattice
    unit is about one noise feature). Returns (...,) values in about [-1, 1].

    The seed fixes the permutation table only (no offset), so ``simplex_noise`` of one
    seed is a fixed function of the coordinates.
    """
    seed = _check_seed(seed)
    p = np.asarray(points, np.float64)
    if p.ndim < 1 or p.shape[-1] not in (2, 3):
        raise ValueError(f"points: expected shape (..., 2) or (..., 3), got {p.shape}")
    if not np.all(np.isfinite(p)):
        raise ValueError("points: contains NaN or inf")
    perm = _permutation(seed)
    if p.shape[-1] == 2:
        return _noise2(p[..., 0], p[..., 1], perm)
    return _noise3(p[..., 0], p[..., 1], p[..., 2], perm)


def _check_shape(shape: Sequence[int], dim: int | None) -> tuple[int, ...]:
    try:
        s = tuple(int(v) for v in shape)
    except (TypeError, ValueError) as e:
        raise TypeError(f"shape: expected a sequence of integers, got {shape!r}") from e
    if len(s) not in (2, 3) or (dim is not None and len(s) != dim):
        raise ValueError(f"shape: expected {dim or '2 or 3'} grid sizes, got {s}")
    if min(s) < 2:
        raise ValueError(f"shape: every grid size must be >= 2, got {s}")
    return s


def noise_grid(shape: Sequence[int], *, seed: int, frequency: float = 2.0, octaves: int = 1,
               persistence: float = 0.5) -> np.ndarray:
    """Fractal simplex noise sampled on a grid of ``shape`` (2 or 3 sizes).

    Cell ``idx`` samples the noise at ``idx * frequency / max(shape) + offset(seed)``, so
    ``frequency`` is the number of noise periods across the longest side. Returns an
    array of ``shape`` with values in about [-1, 1].
    """
    seed = _check_seed(seed)
    s = _check_shape(shape, None)
    if not np.isfinite(frequency) or frequency <= 0:
        raise ValueError(f"frequency: expected a positive number, got {frequency}")
    check_int(octaves, "octaves", 1, 8)
    if not np.isfinite(persistence) or not 0 < persistence <= 1:
        raise ValueError(f"persistence: expected a number in (0, 1], got {persistence}")
    rng = np.random.default_rng([seed, 1])
    offset = rng.uniform(0.0, 256.0, size=len(s))
    perm = _permutation(seed)
    axes = np.meshgrid(*[np.arange(n, dtype=np.float64) for n in s], indexing="ij")
    base = [a * (float(frequency) / max(s)) for a in axes]
    total = np.zeros(s)
    amp, norm = 1.0, 0.0
    for o in range(int(octaves)):
        f = 2.0 ** o
        coords = [b * f + offset[d] + 17.0 * o for d, b in enumerate(base)]
        total += amp * (_noise2(*coords, perm) if len(s) == 2 else _noise3(*coords, perm))
        norm += amp
        amp *= persistence
    return total / norm


def simplex_occupancy(shape: Sequence[int], *, seed: int, threshold: float = 0.6,
                      frequency: float = 2.0, octaves: int = 1,
                      persistence: float = 0.5) -> np.ndarray:
    """Boolean occupancy grid of ``shape``: True where the noise exceeds ``threshold``."""
    if not np.isfinite(threshold):
        raise ValueError(f"threshold: expected a finite number, got {threshold}")
    return noise_grid(shape, seed=seed, frequency=frequency, octaves=octaves,
                      persistence=persistence) > float(threshold)


def simplex_world(dim: int = 3, *, seed: int, shape: Sequence[int] | None = None,
                  limits: np.ndarray | None = None, voxel_size: float | None = None,
                  threshold: float = 0.6, frequency: float = 2.0, octaves: int = 1,
                  persistence: float = 0.5,
                  keep_free: Sequence[tuple[Sequence[float] | np.ndarray, float]] = ()
                  ) -> World:
    """A random occupancy world from simplex noise, with its signed distance field.

    Args:
        dim: 2 or 3.
        seed: non-negative integer; the same seed gives the same world.
        shape: grid sizes (default 64 per axis, or derived from ``limits`` and ``voxel_size``).
        limits: (dim, 2) [m] first and last cell centre per axis (default: the cube
            [-1, 1]^dim, or the box ``shape`` cells of ``voxel_size`` starting at -1).
        voxel_size: [m] (default: from ``limits`` and ``shape``).
        threshold, frequency, octaves, persistence: noise knobs (module docstring).
        keep_free: balls ``(centre (dim,), radius)`` [m] whose cells are cleared, e.g.
            the fixed base of a robot.

    Returns:
        :class:`jwarp.world.sdf.World` with ``occupancy`` and ``meta`` describing the
        generator (``meta["spec"]`` re-creates it through ``parse_world_spec``).
    """
    from jwarp.world.sdf import grid_geometry, world_from_occupancy

    if dim not in (2, 3) or isinstance(dim, bool):
        raise ValueError(f"dim: expected 2 or 3, got {dim!r}")
    s, lim, h = grid_geometry(dim, shape=shape, limits=limits, voxel_size=voxel_size)
    occ = simplex_occupancy(s, seed=seed, threshold=threshold, frequency=frequency,
                            octaves=octaves, persistence=persistence)
    if keep_free:
        occ = clear_balls(occ, lim, h, keep_free)
    world = world_from_occupancy(occ, lim, h)
    world.meta.update(source="simplex", seed=int(seed), threshold=float(threshold),
                      frequency=float(frequency), octaves=int(octaves),
                      persistence=float(persistence))
    return world


def clear_balls(occ: np.ndarray, limits: np.ndarray, voxel_size: float,
                balls: Sequence[tuple[Sequence[float], float]]) -> np.ndarray:
    """Copy of ``occ`` with every cell whose centre lies within a ball set free.
    ``balls``: ``(centre (dim,) [m], radius [m])`` pairs."""
    occ = np.array(occ, dtype=bool)
    dim = occ.ndim
    axes = np.meshgrid(*[limits[d, 0] + voxel_size * np.arange(occ.shape[d]) for d in range(dim)],
                       indexing="ij")
    for k, ball in enumerate(balls):
        try:
            c, r = ball
            c = np.asarray(c, np.float64).reshape(-1)[:dim]
            r = float(r)
        except (TypeError, ValueError) as e:
            raise ValueError(f"keep_free[{k}]: expected (centre, radius), got {ball!r}") from e
        if c.shape != (dim,) or not np.all(np.isfinite(c)) or not np.isfinite(r) or r < 0:
            raise ValueError(f"keep_free[{k}]: expected a finite centre of {dim} values and "
                             f"a radius >= 0, got {ball!r}")
        d2 = sum((axes[d] - c[d]) ** 2 for d in range(dim))
        occ[d2 <= r * r] = False
    return occ
