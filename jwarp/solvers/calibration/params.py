"""The calibration parameter vector: chosen free groups of robot and measurement parameters.

Robot groups (per DH frame on the chains the measurement observes):

* ``theta``, ``d``, ``r``, ``alpha``, ``beta``: geometric DH entries of rho0 [rad, m]
  (``theta`` holds the joint offsets);
* ``kappa_alpha``, ``kappa_beta``, ``kappa_theta``: compliances [rad/(N m)] (bounded >= 0).

Measurement groups come from the measurement's :class:`ParamBlock` (``tracker``,
``markers``, ``intrinsics``, ...). Parameters of groups that are not free stay at their
nominal values. Every free parameter has a Gaussian prior ``N(nominal, sigma^2)``; it enters
the least squares as the residual row ``(x - nominal) / sigma`` (thesis eq. 2.5); a sigma of
``inf`` means no prior row.

Names: robot entries are ``"<frame>.<group>"`` (``"right_3.theta"``,
``"torso_2.kappa_alpha"``), measurement entries keep their ParamBlock names.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Iterable, Mapping

import numpy as np

from jwarp.model import RobotModel

DH_GROUPS = ("d", "theta", "r", "alpha", "beta")          # = DH columns 0..4
KAPPA_GROUPS = ("kappa_alpha", "kappa_beta", "kappa_theta")  # = kappa axes 0..2
#: robot parameter groups, in the order they appear in the parameter vector
ROBOT_GROUPS = ("theta", "d", "r", "alpha", "beta", "kappa_theta", "kappa_alpha", "kappa_beta")

#: default prior standard deviations of the robot groups [m, rad, rad/(N m)]
DEFAULT_SIGMA: dict[str, float] = {
    "d": 0.005, "r": 0.005,
    "theta": math.radians(5.0), "alpha": math.radians(5.0), "beta": math.radians(5.0),
    # the paper's prior on Agile Justin's compliances: 0.1 rad/kNm
    "kappa_theta": 1e-4, "kappa_alpha": 1e-4, "kappa_beta": 1e-4,
}

KIND_DH, KIND_KAPPA, KIND_MEAS = 0, 1, 2


def parse_groups(free: str | Iterable[str]) -> list[str]:
    """``"theta,d,tracker"`` or an iterable of names -> list of group names (stripped,
    deduplicated, order kept)."""
    if isinstance(free, str):
        items = [s.strip() for s in free.split(",")]
    else:
        try:
            items = [str(s).strip() for s in free]
        except TypeError:
            raise TypeError(f"free: expected a comma-separated string or a list of group "
                            f"names, got {type(free).__name__}") from None
    items = [s for s in items if s]
    if not items:
        raise ValueError("free: no parameter group given")
    return list(dict.fromkeys(items))


def influencing_frames(robot: RobotModel, measured: Iterable[int] | None, elastic: bool
                       ) -> list[int]:
    """DH frames whose parameters can change the observations of frames ``measured``.

    Rigid: the DH frames on the paths from the root to the measured frames. Elastic: also
    every DH frame hanging off those paths with mass in its subtree (e.g. the head of a
    humanoid measured at the hands: its pose moves a mass that loads the torso joints).
    ``measured`` None or empty: all DH frames.
    """
    dh = robot.is_dh
    if not measured:
        return [int(i) for i in np.nonzero(dh)[0]]
    chain: set[int] = set()
    for f in measured:
        chain.update(robot.ancestors(int(f)))
    use = np.array([i in chain for i in range(robot.n_frames)])
    if elastic:
        fm = np.zeros(robot.n_frames)
        for m in robot.masses:
            fm[m.frame] += m.mass
        loaded = robot.subtree_mask.astype(float) @ fm > 0   # mass in the subtree
        for i in range(robot.n_frames):
            if not use[i] and loaded[i] and any(a in chain for a in robot.ancestors(i)):
                use[i] = True
    return [int(i) for i in np.nonzero(use & dh)[0]]


@dataclass
class ParameterSpace:
    """Map between the free-parameter vector ``x`` (P,) and robot/measurement parameters.

    Attributes (all (P,) unless noted):
        robot: the nominal RobotModel (its DH rows and kappa are the prior means).
        p_nominal: (P_meas,) all measurement parameters at nominal (fixed ones stay there).
        names, groups: parameter names and groups.
        nominal, sigma: prior means and standard deviations (sigma inf = no prior).
        kind: 0 DH entry, 1 compliance, 2 measurement parameter.
        frame, column: robot frame and DH column (kind 0) / kappa axis (kind 1); for kind 2
            column is the index into the measurement's ParamBlock and frame is -1.
        lower, upper: bounds (compliances >= 0 with ``bound_kappa``, else unbounded).
        free_groups: the groups that were freed, in the order given.
    """

    robot: RobotModel
    p_nominal: np.ndarray
    names: list[str]
    groups: list[str]
    nominal: np.ndarray
    sigma: np.ndarray
    kind: np.ndarray
    frame: np.ndarray
    column: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    free_groups: list[str]

    # ----------------------------------------------------------------- build
    @classmethod
    def build(cls, robot: RobotModel, measurement: Any, free: str | Iterable[str], *,
              sigma: Mapping[str, float] | None = None, frames: Iterable[int | str] | None = None,
              p_nominal: np.ndarray | None = None, bound_kappa: bool = False) -> "ParameterSpace":
        """Parameter space of the free groups.

        Args:
            robot: nominal robot (prior means of DH rows and compliances).
            measurement: a Measurement (needs ``frames`` and ``params``), or None for
                robot groups only.
            free: group names (see :data:`ROBOT_GROUPS` and the measurement's
                ``params.groups``), as a list or comma-separated string.
            sigma: per-group prior sigma overrides {group: sigma}; a measurement group given
                here replaces its ParamBlock sigmas; ``inf`` removes the prior.
            frames: DH frames whose rows may be calibrated (default
                :func:`influencing_frames`: the DH frames on the paths from the root to the
                frames the measurement uses, plus, for an elastic model, the mass-carrying
                DH frames branching off those paths, whose geometry and compliance load the
                measured chains through their weight).
            p_nominal: (P_meas,) measurement parameter prior means (default ParamBlock
                nominal).
            bound_kappa: give the compliances the bound kappa >= 0 (default off: bounds
                make dogbox truncate its steps and stall; the optimizer may cross zero
                and the calibrated robot clips negative compliances).
        """
        if not isinstance(robot, RobotModel):
            raise TypeError(f"robot: expected a RobotModel, got {type(robot).__name__}")
        groups = parse_groups(free)
        block = getattr(measurement, "params", None) if measurement is not None else None
        meas_groups = block.group_names() if block is not None else []
        valid = list(ROBOT_GROUPS) + [g for g in meas_groups if g not in ROBOT_GROUPS]
        bad = [g for g in groups if g not in valid]
        if bad:
            raise ValueError(f"free: unknown parameter group(s) {bad}; valid groups: "
                             f"{', '.join(valid)}")
        sig = dict(DEFAULT_SIGMA)
        if sigma is not None:
            if not isinstance(sigma, Mapping):
                raise TypeError(f"sigma: expected a mapping {{group: sigma}}, got "
                                f"{type(sigma).__name__}")
            for g, v in sigma.items():
                if g not in valid:
                    raise ValueError(f"sigma: unknown parameter group '{g}'; valid groups: "
                                     f"{', '.join(valid)}")
                try:
                    fv = float(v)
                except (TypeError, ValueError):
                    raise ValueError(f"sigma['{g}']: expected a number, got {v!r}") from None
                if not (fv > 0) or math.isnan(fv):
                    raise ValueError(f"sigma['{g}']: must be > 0 (inf = no prior), got {v!r}")
                sig[g] = fv
        # which DH frames
        if frames is None:
            elastic = any(g in KAPPA_GROUPS for g in groups) or bool(np.any(robot.kappa != 0))
            dh_frames = influencing_frames(robot, getattr(measurement, "frames", None)
                                           if measurement is not None else None, elastic)
        else:
            dh_frames = []
            for f in frames:
                i = robot.frame_index(f, "frames")
                if not robot.is_dh[i]:
                    raise ValueError(f"frames: frame '{robot.frames[i].name}' is static; "
                                     f"only DH frames have calibratable rows")
                if i not in dh_frames:
                    dh_frames.append(i)
            dh_frames.sort()
        if block is not None:
            pn = block.nominal.copy() if p_nominal is None else np.asarray(p_nominal, np.float64)
            if pn.shape != (block.size,):
                raise ValueError(f"p_nominal: expected shape ({block.size},), got {pn.shape}")
            if not np.all(np.isfinite(pn)):
                raise ValueError("p_nominal: contains NaN or inf")
        else:
            pn = np.zeros(0)
        names: list[str] = []
        grp: list[str] = []
        nom: list[float] = []
        sg: list[float] = []
        kind: list[int] = []
        frm: list[int] = []
        col: list[int] = []
        for g in groups:
            if g in DH_GROUPS or g in KAPPA_GROUPS:
                is_k = g in KAPPA_GROUPS
                c = KAPPA_GROUPS.index(g) if is_k else DH_GROUPS.index(g)
                for i in dh_frames:
                    names.append(f"{robot.frames[i].name}.{g}")
                    grp.append(g)
                    nom.append(float(robot.kappa[i, c] if is_k else robot.dh_table[i, c]))
                    sg.append(sig[g])
                    kind.append(KIND_KAPPA if is_k else KIND_DH)
                    frm.append(i)
                    col.append(c)
            else:
                for k in block.indices(g):
                    names.append(block.names[k])
                    grp.append(g)
                    nom.append(float(pn[k]))
                    sg.append(sig[g] if g in (sigma or {}) else float(block.sigma[k]))
                    kind.append(KIND_MEAS)
                    frm.append(-1)
                    col.append(int(k))
        if not names:
            raise ValueError(f"free: the groups {groups} select no parameters (no DH frames "
                             f"on the measured chains?)")
        kind_a = np.array(kind, np.int64)
        lower = np.where((kind_a == KIND_KAPPA) & bool(bound_kappa), 0.0, -np.inf)
        return cls(robot=robot, p_nominal=pn, names=names, groups=grp,
                   nominal=np.array(nom), sigma=np.array(sg), kind=kind_a,
                   frame=np.array(frm, np.int64), column=np.array(col, np.int64),
                   lower=lower, upper=np.full(len(names), np.inf), free_groups=groups)

    # ------------------------------------------------------------- queries
    @property
    def size(self) -> int:
        return len(self.names)

    def mask(self, kind: int) -> np.ndarray:
        return self.kind == kind

    @property
    def has_prior(self) -> np.ndarray:
        """(P,) bool: parameters with a finite prior sigma."""
        return np.isfinite(self.sigma)

    @property
    def scale(self) -> np.ndarray:
        """(P,) typical scale per parameter: its prior sigma, 1 where there is none."""
        return np.where(self.has_prior, self.sigma, 1.0)

    def index(self, name: str) -> int:
        try:
            return self.names.index(name)
        except ValueError:
            raise ValueError(f"name: unknown parameter '{name}'") from None

    def check(self, x: Any, name: str = "x") -> np.ndarray:
        a = np.asarray(x, np.float64)
        if a.shape != (self.size,):
            raise ValueError(f"{name}: expected shape ({self.size},), got {a.shape}")
        if not np.all(np.isfinite(a)):
            raise ValueError(f"{name}: contains NaN or inf")
        return a

    # ---------------------------------------------------------- x -> model
    def unpack(self, x: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """x (P,) -> (DH rows rho0 (n_frames, 5), kappa (n_frames, 3), measurement p (P_meas,))."""
        x = self.check(x)
        dh = self.robot.dh_table.copy()
        kap = self.robot.kappa.copy()
        p = self.p_nominal.copy()
        m = self.kind == KIND_DH
        dh[self.frame[m], self.column[m]] = x[m]
        m = self.kind == KIND_KAPPA
        kap[self.frame[m], self.column[m]] = x[m]
        m = self.kind == KIND_MEAS
        p[self.column[m]] = x[m]
        return dh, kap, p

    def pack(self, dh: np.ndarray | None = None, kappa: np.ndarray | None = None,
             p: np.ndarray | None = None) -> np.ndarray:
        """Inverse of :meth:`unpack` (missing parts at nominal)."""
        x = self.nominal.copy()
        if dh is not None:
            m = self.kind == KIND_DH
            x[m] = np.asarray(dh, np.float64)[self.frame[m], self.column[m]]
        if kappa is not None:
            m = self.kind == KIND_KAPPA
            x[m] = np.asarray(kappa, np.float64)[self.frame[m], self.column[m]]
        if p is not None:
            m = self.kind == KIND_MEAS
            x[m] = np.asarray(p, np.float64)[self.column[m]]
        return x

    def robot_at(self, x: Any) -> RobotModel:
        """A calibrated copy of the robot: DH rows and compliances from ``x``."""
        dh, kap, _ = self.unpack(x)
        return self.robot.with_dh(dh, kappa=np.maximum(kap, 0.0))

    def measurement_params(self, x: Any) -> np.ndarray:
        """(P_meas,) all measurement parameters (fixed ones at nominal)."""
        return self.unpack(x)[2]

    def prior_residuals(self, x: Any) -> np.ndarray:
        """((x - nominal) / sigma) for the parameters with a prior, (P_prior,)."""
        x = np.asarray(x, np.float64)
        h = self.has_prior
        return (x[h] - self.nominal[h]) / self.sigma[h]

    def sample_prior(self, rng: np.random.Generator) -> np.ndarray:
        """A random x from the prior (parameters without prior stay at nominal), clipped to
        the bounds; compliances are drawn on the physical side (nominal + |N(0, sigma)|)."""
        dev = np.where(self.has_prior, self.sigma, 0.0) * rng.standard_normal(self.size)
        dev = np.where(self.kind == KIND_KAPPA, np.abs(dev), dev)
        return np.clip(self.nominal + dev, self.lower, self.upper)

    @property
    def kappa_free(self) -> np.ndarray:
        """(n_frames, 3) bool: compliance entries that are free."""
        out = np.zeros((self.robot.n_frames, 3), bool)
        m = self.kind == KIND_KAPPA
        out[self.frame[m], self.column[m]] = True
        return out


def perturb_robot(robot: RobotModel, rng: np.random.Generator, *,
                  groups: Iterable[str] = ("theta", "d", "r", "alpha"),
                  length_error: float = 0.005, angle_error: float = math.radians(5.0),
                  kappa: tuple[float, float] | None = None,
                  kappa_groups: Iterable[str] = ("kappa_theta", "kappa_alpha"),
                  frames: Iterable[int | str] | None = None) -> RobotModel:
    """A "true" robot for simulated campaigns (thesis 2.6.1): the nominal DH entries of
    ``groups`` plus uniform errors in [-length_error, length_error] [m] (d, r) or
    [-angle_error, angle_error] [rad] (theta, alpha, beta) on the DH frames ``frames``
    (default all), and compliances drawn uniformly from ``kappa`` = (low, high)
    [rad/(N m)] on the axes of ``kappa_groups`` (None: keep the robot's kappa)."""
    groups = parse_groups(groups)
    bad = [g for g in groups if g not in DH_GROUPS]
    if bad:
        raise ValueError(f"groups: unknown DH group(s) {bad}; valid: {', '.join(DH_GROUPS)}")
    if frames is None:
        idx = np.nonzero(robot.is_dh)[0]
    else:
        idx = np.array([robot.frame_index(f, "frames") for f in frames], np.int64)
        if not np.all(robot.is_dh[idx]):
            raise ValueError("frames: only DH frames can be perturbed")
    dh = robot.dh_table.copy()
    for g in groups:
        c = DH_GROUPS.index(g)
        err = length_error if g in ("d", "r") else angle_error
        dh[idx, c] += rng.uniform(-err, err, idx.size)
    kap = robot.kappa.copy()
    if kappa is not None:
        lo, hi = map(float, kappa)
        if not (0 <= lo <= hi):
            raise ValueError(f"kappa: expected 0 <= low <= high, got {kappa!r}")
        for g in parse_groups(kappa_groups):
            if g not in KAPPA_GROUPS:
                raise ValueError(f"kappa_groups: unknown group '{g}'; valid: {', '.join(KAPPA_GROUPS)}")
            c = KAPPA_GROUPS.index(g)
            kap[idx, c] = rng.uniform(lo, hi, idx.size)
    return robot.with_dh(dh, kappa=kap)
