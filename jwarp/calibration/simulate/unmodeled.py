"""Systematic error in simulated campaigns: effects in the *truth* that the calibration
model does not have (issue 16 item 1; ``docs/nongeometric.md``).

Real robots are never exactly their calibration model; a simulated campaign whose truth is
inside the model lets the calibration reach the noise level, which no lab sees. The
effects, each drawn once per true robot (seeded) and written into the true robot file
(so the saved truth reproduces the data):

* ``harmonic`` -- joint transmission errors: for every joint and harmonic k = 1..``k``,
  ``a_jk, b_jk ~ U(-amp, amp)`` in ``dq_j = sum_k a_jk sin(k q_j) + b_jk cos(k q_j)``
  (default ``amp`` 5e-4 rad = 1.7 arcmin, ``k`` 2: the order of a harmonic drive's
  transmission error and an encoder's eccentricity).
* ``kappa_nonlinear`` -- torque-dependent joint stiffness: the joint compliance becomes
  ``kappa_theta (1 + s (tau / tau_ref)^2)`` with ``s ~ U(-rel, rel)`` per joint (default
  ``rel`` 0.5: +-50 % at ``tau_ref``, the joint's 95th percentile gravity torque over
  uniform configurations), i.e. ``kappa_nonlinear = s kappa_theta / tau_ref^2``
  [rad/(N m)^3]; frames without joint compliance, and joints whose ``tau_ref`` is below
  1 % of the largest (a vertical pan axis), get none.
* ``kappa_beta`` -- lateral compliance about the DH beta axes, U(``min``, ``max``)
  [rad/(N m)] on every DH frame (default 1e-5 .. 3e-5, a third of the default joint
  compliances of :func:`~.campaign.simulate_campaign`; the standard calibration groups
  leave it out).
* ``coupling`` -- angle-dependent error of the coupled frames (a passive joint that does
  not follow its coupling exactly, e.g. justin19's ``torso_4`` = -(q1 + q2); issue 29):
  for every coupled DH frame and harmonic k = 1..``k`` of its coupled angle u, a term of
  amplitude U(``amp``/2, ``amp``) and uniform phase, ``dtheta = sum_k A_k sin(k u +
  phi_k)`` (default ``amp`` 1e-2 rad, ``k`` 2: 5-10 mrad per harmonic, the size that
  Agile Justin's data suggests); stored in the true robot's ``coupling_harmonic``. The
  calibration's ``coupling`` group models it.
* ``backlash`` -- direction-dependent joint errors (backlash, hysteresis; issue 38): every
  joint driving a DH frame gets ``b_j ~ U(min, max)`` (default 1e-3 .. 3e-3 rad), and
  the links see ``q_j + b_j s_j`` with ``s_j`` the direction joint j last moved in, from
  the previous sample in measurement order
  (:func:`~jwarp.calibration.estimate.backlash.motion_directions`); stored in the true
  robot's ``notes['backlash']``. The calibration's ``backlash`` group models it.

Spec strings (``--unmodeled``): comma-separated effects, each optionally followed by
``:key=value`` options; further ``key=value`` items after a comma belong to the effect
before them, e.g. ``harmonic:amp=5e-4,k=3,kappa_nonlinear,kappa_beta:max=5e-5``.
``none`` (or an empty string) means no unmodeled effect, ``all`` harmonic, kappa_nonlinear
and kappa_beta at their defaults (``coupling`` only by name).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from jwarp.model import RobotModel

#: the effects and their options with defaults (units in the module docstring)
EFFECTS: dict[str, dict[str, float]] = {
    "harmonic": {"amp": 5e-4, "k": 2},
    "kappa_nonlinear": {"rel": 0.5},
    "kappa_beta": {"min": 1e-5, "max": 3e-5},
    "coupling": {"amp": 1e-2, "k": 2},
    "backlash": {"min": 1e-3, "max": 3e-3},
}
#: what ``all`` selects: the effects of issue 16 (``coupling`` is named on its own, so
#: that campaigns with ``all`` keep their data)
ALL_EFFECTS = ("harmonic", "kappa_nonlinear", "kappa_beta")


@dataclass
class Unmodeled:
    """Which unmodeled effects a simulated truth gets, with their sizes:
    {effect: {option: value}} (see :data:`EFFECTS`)."""

    effects: dict[str, dict[str, float]] = field(default_factory=dict)

    def validate(self, option: str = "unmodeled") -> Unmodeled:
        """Check names and values; a ValueError names ``option`` and the bad item."""
        for name, opts in self.effects.items():
            if name not in EFFECTS:
                raise ValueError(f"{option}: unknown effect '{name}'; valid: "
                                 f"{', '.join(EFFECTS)} (or none, all)")
            for key, v in opts.items():
                if key not in EFFECTS[name]:
                    raise ValueError(f"{option}: {name}: unknown option '{key}'; valid: "
                                     f"{', '.join(EFFECTS[name])}")
                if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) \
                        or v < 0:
                    raise ValueError(f"{option}: {name}:{key} must be a finite number >= 0, "
                                     f"got {v!r}")
            if name in ("harmonic", "coupling") and (int(opts.get("k", 2)) != opts.get("k", 2)
                                                     or not 1 <= opts.get("k", 2) <= 20):
                raise ValueError(f"{option}: {name}:k must be an integer in [1, 20], "
                                 f"got {opts.get('k')!r}")
            if name == "backlash" and opts.get("min", 1e-3) > opts.get("max", 3e-3):
                raise ValueError(f"{option}: backlash: min > max "
                                 f"({opts.get('min', 1e-3)!r} > {opts.get('max', 3e-3)!r})")
            if name == "kappa_beta" and opts.get("min", 1e-5) > opts.get("max", 3e-5):
                raise ValueError(f"{option}: kappa_beta: min > max "
                                 f"({opts.get('min', 1e-5)!r} > {opts.get('max', 3e-5)!r})")
        return self

    def get(self, effect: str, key: str) -> float:
        return float(self.effects[effect].get(key, EFFECTS[effect][key]))

    def __bool__(self) -> bool:
        return bool(self.effects)


def parse_unmodeled(spec: Any, option: str = "unmodeled") -> Unmodeled:
    """An :class:`Unmodeled` from a spec string (module docstring), a list of effect
    names, a mapping {effect: {option: value}}, an Unmodeled or None (no effect).
    ValueError/TypeError name ``option``."""
    if spec is None:
        return Unmodeled()
    if isinstance(spec, Unmodeled):
        return Unmodeled({k: dict(v) for k, v in spec.effects.items()}).validate(option)
    if isinstance(spec, dict):
        eff = {}
        for k, v in spec.items():
            if v is None:
                v = {}
            if not isinstance(v, dict):
                raise TypeError(f"{option}: {k}: expected a mapping of options, got "
                                f"{type(v).__name__}")
            eff[str(k)] = dict(v)
        return Unmodeled(eff).validate(option)
    if isinstance(spec, (list, tuple)):
        spec = ",".join(str(s) for s in spec)
    if not isinstance(spec, str):
        raise TypeError(f"{option}: expected a spec string such as "
                        f"'harmonic,kappa_nonlinear', got {type(spec).__name__}")
    text = spec.strip()
    if text in ("", "none"):
        return Unmodeled()
    effects: dict[str, dict[str, float]] = {}
    current: str | None = None
    for raw in text.split(","):
        item = raw.strip()
        if not item:
            raise ValueError(f"{option}: empty item in '{spec}'")
        if "=" in item and ":" not in item:          # option of the effect before
            if current is None:
                raise ValueError(f"{option}: option '{item}' before any effect name")
            opts_text = item
        else:
            name, _, opts_text = item.partition(":")
            name = name.strip()
            if name == "all":
                for n in ALL_EFFECTS:
                    effects.setdefault(n, {})
                current = None
                if opts_text:
                    raise ValueError(f"{option}: 'all' takes no options")
                continue
            if name in effects:
                raise ValueError(f"{option}: effect '{name}' given twice")
            effects[name] = {}
            current = name
            if not opts_text:
                continue
        key, eq, val = opts_text.partition("=")
        if not eq:
            raise ValueError(f"{option}: expected key=value after '{current}:', got "
                             f"'{opts_text}'")
        try:
            effects[current][key.strip()] = float(val)
        except ValueError:
            raise ValueError(f"{option}: {current}:{key.strip()}: expected a number, got "
                             f"'{val}'") from None
    return Unmodeled(effects).validate(option)


def reference_torques(robot: RobotModel, q: np.ndarray, percentile: float = 95.0) -> np.ndarray:
    """(n_frames,) the ``percentile`` of |tau_theta| [N m] over configurations ``q``
    (rigid nominal geometry of ``robot``); 0 where a joint carries no torque."""
    from jwarp import kinematics as K

    tau = K.gravity_torques(robot, q, device="cpu", dtype=np.float64)
    return np.percentile(np.abs(tau[..., 2]), percentile, axis=0)


def add_unmodeled(truth: RobotModel, unmodeled: Unmodeled, rng: np.random.Generator,
                  q_ref: np.ndarray) -> RobotModel:
    """A copy of ``truth`` with the effects of ``unmodeled`` drawn from ``rng`` (in the
    fixed order harmonic, kappa_nonlinear, kappa_beta, coupling, backlash); ``q_ref`` (N, n_dof)
    configurations defining the reference torques of ``kappa_nonlinear``."""
    if not unmodeled:
        return truth
    harm = truth.harmonic
    knl = truth.kappa_nonlinear.copy()
    kap = truth.kappa.copy()
    dh = truth.is_dh
    if "harmonic" in unmodeled.effects:
        amp, K = unmodeled.get("harmonic", "amp"), int(unmodeled.get("harmonic", "k"))
        harm = np.zeros((truth.n_dof, max(K, truth.harmonic.shape[1]), 2))
        harm[:, :truth.harmonic.shape[1]] = truth.harmonic
        harm[:, :K] += rng.uniform(-amp, amp, (truth.n_dof, K, 2))
    if "kappa_nonlinear" in unmodeled.effects:
        rel = unmodeled.get("kappa_nonlinear", "rel")
        tau_ref = reference_torques(truth, q_ref)
        s = rng.uniform(-rel, rel, truth.n_frames)
        # joints that carry (numerically) no torque, e.g. a vertical pan axis, get none
        ok = dh & (tau_ref > max(1e-2 * float(tau_ref.max(initial=0.0)), 1e-3)) & (kap[:, 2] > 0)
        knl = knl + np.where(ok, s * kap[:, 2] / np.where(ok, tau_ref, 1.0) ** 2, 0.0)
    if "kappa_beta" in unmodeled.effects:
        lo, hi = unmodeled.get("kappa_beta", "min"), unmodeled.get("kappa_beta", "max")
        kap[:, 1] = np.where(dh, rng.uniform(lo, hi, truth.n_frames), 0.0)
    ch = truth.coupling_harmonic
    if "coupling" in unmodeled.effects:
        from jwarp.calibration.estimate.params import coupled_frames

        amp, K = unmodeled.get("coupling", "amp"), int(unmodeled.get("coupling", "k"))
        ch = np.zeros((truth.n_frames, max(K, truth.coupling_harmonic.shape[1]), 2))
        ch[:, :truth.coupling_harmonic.shape[1]] = truth.coupling_harmonic
        for i in coupled_frames(truth, np.nonzero(dh)[0]):
            A = rng.uniform(amp / 2, amp, K)
            phi = rng.uniform(-np.pi, np.pi, K)
            ch[i, :K, 0] += A * np.cos(phi)          # A sin(k u + phi) = A cos(phi) sin(k u)
            ch[i, :K, 1] += A * np.sin(phi)          #                  + A sin(phi) cos(k u)
    out = truth.copy(harmonic=harm, kappa_nonlinear=knl, kappa=kap, coupling_harmonic=ch)
    if "backlash" in unmodeled.effects:   # drawn last: the other effects keep their draws
        from jwarp.calibration.estimate.params import harmonic_joints, with_backlash

        lo, hi = unmodeled.get("backlash", "min"), unmodeled.get("backlash", "max")
        b = np.zeros(truth.n_dof)
        joints = harmonic_joints(truth, np.nonzero(dh)[0])
        b[joints] = rng.uniform(lo, hi, len(joints))
        out = with_backlash(out, b)
    return out
