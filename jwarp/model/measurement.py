"""Measurement plugin interface: ``h(frames(q, Theta), p) -> y``, vectorized over samples.

A measurement plugin sees the robot only through the world transforms of its frames (the
output of :func:`jwarp.fk` / :func:`jwarp.fk_elastic`, float64) and owns its parameters
``p`` (tracker pose, marker positions, camera intrinsics, ...) as a :class:`ParamBlock`
with nominal values, prior sigmas and groups.

Derivatives (the contract with the calibration solver)
------------------------------------------------------
``jacobians(frames, p, meta)`` returns ``(y, J_frames, J_params)``:

* ``y`` (S, m): the predicted observations.
* ``J_frames`` (S, m, len(self.frames), 6): ``dy_k / d twist`` of frame ``self.frames[f]``
  with the twist ``(v, w)`` in BASE coordinates: the perturbed frame has origin ``p + v``
  and rotation ``(I + [w]x) R``, so a point ``x`` fixed in that frame moves by
  ``dx = v + w x (x - p)``. This matches the rows ``[d origin; d omega]`` of
  :func:`jwarp.jacobian` / :func:`jwarp.jacobian_dh` with ``point=0`` (the frame origin),
  so ``dy/dq = sum_f J_frames[:, :, f, :] @ jacobian(robot, q, self.frames[f])``.
* ``J_params`` (S, m, P): ``dy / dp``.

Rigid poses (tracker frame, camera mount) are parameterized by position (3) and rotation
vector (3) (:meth:`scipy.spatial.transform.Rotation.from_rotvec`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from jwarp.model import RobotModel


@dataclass
class ParamBlock:
    """A measurement's own parameters (float64).

    ``names`` (P,) parameter names, e.g. ``tracker_px``, ``marker_right_x``;
    ``nominal`` (P,) initial / prior-mean values [m, rad, px];
    ``sigma`` (P,) prior standard deviations in the same units (``np.inf`` = no prior);
    ``groups`` (P,) the group of each parameter (``"tracker"``, ``"markers"``, ``"camera"``,
    ``"intrinsics"``, ...), the unit in which a solver frees or fixes parameters.
    """

    names: list[str] = field(default_factory=list)
    nominal: np.ndarray = field(default_factory=lambda: np.zeros(0))
    sigma: np.ndarray = field(default_factory=lambda: np.zeros(0))
    groups: list[str] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.names = [str(n) for n in self.names]
        self.groups = [str(g) for g in self.groups]
        self.nominal = np.asarray(self.nominal, dtype=np.float64).reshape(-1)
        self.sigma = np.asarray(self.sigma, dtype=np.float64).reshape(-1)
        n = len(self.names)
        for what, size in (("nominal", self.nominal.size), ("sigma", self.sigma.size),
                           ("groups", len(self.groups))):
            if size != n:
                raise ValueError(f"ParamBlock: {what} has {size} entries, names has {n}")
        if len(set(self.names)) != n:
            dup = sorted({x for x in self.names if self.names.count(x) > 1})
            raise ValueError(f"ParamBlock: duplicate parameter names {dup}")
        if not np.all(np.isfinite(self.nominal)):
            raise ValueError("ParamBlock: nominal contains NaN or inf")
        if np.any(np.isnan(self.sigma)) or np.any(self.sigma <= 0):
            raise ValueError("ParamBlock: sigma must be > 0 (np.inf = no prior)")

    @property
    def size(self) -> int:
        """Number of parameters P."""
        return len(self.names)

    def indices(self, group: str) -> np.ndarray:
        """Indices (int array) of the parameters in ``group`` (empty if none)."""
        return np.array([i for i, g in enumerate(self.groups) if g == group], dtype=np.int64)

    def index(self, name: str) -> int:
        """Index of the parameter called ``name``."""
        try:
            return self.names.index(name)
        except ValueError:
            raise ValueError(f"ParamBlock: unknown parameter '{name}'") from None

    def group_names(self) -> list[str]:
        """The distinct groups, in order of first appearance."""
        return list(dict.fromkeys(self.groups))


class Measurement:
    """Base class of measurement plugins: ``h(q, Theta) -> y``, vectorized over samples S.

    Subclasses set in ``__init__``: ``frames`` (robot frame indices the prediction depends
    on), ``obs_names`` (the m observed values per sample = CSV column names), ``meta_names``
    (extra per-sample CSV input columns, e.g. contact ``["pair"]``), ``params``
    (:class:`ParamBlock`) and ``noise`` (measurement noise standard deviation per observed
    value, in ``unit``; setup key ``"noise"``), and implement :meth:`jacobians` (and,
    for speed, :meth:`predict`).
    """

    name: str = ""
    unit: str = "m"

    def __init__(self, robot: RobotModel, setup: dict) -> None:
        if not isinstance(robot, RobotModel):
            raise TypeError(f"robot: expected a RobotModel, got {type(robot).__name__}")
        if not isinstance(setup, dict):
            raise TypeError(f"setup: expected a dict (the plugin's JSON section), got "
                            f"{type(setup).__name__}")
        plugin = setup.get("plugin", self.name)
        if plugin != self.name:
            raise ValueError(f"setup.plugin: '{plugin}' given to the '{self.name}' measurement")
        self.robot = robot
        self.setup = setup
        self.frames: list[int] = []
        self.obs_names: list[str] = []
        self.meta_names: list[str] = []
        self.params = ParamBlock()
        self.noise: float = 1.0

    # ---------------------------------------------------------------- sizes
    @property
    def n_obs(self) -> int:
        """m, the number of observed values per sample."""
        return len(self.obs_names)

    # ------------------------------------------------------------ interface
    def predict(self, frames: np.ndarray, p: np.ndarray, meta: dict | None = None) -> np.ndarray:
        """frames (S, n_frames, 4, 4) float64 world transforms of ALL robot frames [m];
        p (P,); meta {name: (S,) array} -> y (S, m)."""
        return self.jacobians(frames, p, meta)[0]

    def jacobians(self, frames: np.ndarray, p: np.ndarray, meta: dict | None = None
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(y (S, m), J_frames (S, m, len(self.frames), 6), J_params (S, m, P)); see the
        module docstring for the twist convention."""
        raise NotImplementedError(f"measurement '{self.name}' does not implement jacobians()")

    def initial_guess(self, frames: np.ndarray, y: np.ndarray, p: np.ndarray,
                      meta: dict | None = None) -> np.ndarray:
        """A robust start for the parameters from data (default: ``p`` unchanged)."""
        self.check_inputs(frames, p, meta)
        self.check_obs(y, frames.shape[0])
        return np.array(p, dtype=np.float64, copy=True)

    def simulate(self, frames: np.ndarray, p: np.ndarray, noise_sigma: float,
                 rng: np.random.Generator, meta: dict | None = None) -> np.ndarray:
        """Predicted y (S, m) plus Gaussian noise of std ``noise_sigma`` (unit of y)."""
        if not (isinstance(noise_sigma, (int, float, np.floating, np.integer))
                and math.isfinite(noise_sigma) and noise_sigma >= 0):
            raise ValueError(f"noise_sigma: expected a finite number >= 0, got {noise_sigma!r}")
        y = self.predict(frames, p, meta)
        return y + rng.normal(0.0, float(noise_sigma), size=y.shape)

    # ----------------------------------------------------------- validation
    def check_inputs(self, frames: Any, p: Any, meta: dict | None = None
                     ) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
        """Validate and convert ``frames`` (S, n_frames, 4, 4), ``p`` (P,), ``meta``."""
        f = np.asarray(frames, dtype=np.float64)
        nf = self.robot.n_frames
        if f.ndim != 4 or f.shape[1:] != (nf, 4, 4):
            raise ValueError(f"frames: expected shape (S, {nf}, 4, 4) for robot "
                             f"'{self.robot.name}', got {f.shape}")
        if not np.all(np.isfinite(f[:, self.frames])):
            raise ValueError("frames: contains NaN or inf")
        pp = np.asarray(p, dtype=np.float64)
        if pp.shape != (self.params.size,):
            raise ValueError(f"p: expected shape ({self.params.size},) for measurement "
                             f"'{self.name}', got {pp.shape}")
        if not np.all(np.isfinite(pp)):
            raise ValueError("p: contains NaN or inf")
        m: dict[str, np.ndarray] = {}
        for key in self.meta_names:
            if meta is None or key not in meta:
                raise ValueError(f"meta: measurement '{self.name}' needs the per-sample "
                                 f"column '{key}'")
            a = np.asarray(meta[key])
            if a.shape != (f.shape[0],):
                raise ValueError(f"meta['{key}']: expected shape ({f.shape[0]},), got {a.shape}")
            m[key] = a
        return f, pp, m

    def check_obs(self, y: Any, n_samples: int) -> np.ndarray:
        """Validate measured ``y`` (S, m)."""
        a = np.asarray(y, dtype=np.float64)
        if a.shape != (n_samples, self.n_obs):
            raise ValueError(f"y: expected shape ({n_samples}, {self.n_obs}), got {a.shape}")
        if not np.all(np.isfinite(a)):
            raise ValueError("y: contains NaN or inf")
        return a
