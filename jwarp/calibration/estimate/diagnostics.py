"""Residual diagnostics: where does a calibrated model still err? (issue 29,
``docs/calibration.md``, "Finding a missing effect").

After a fit whose test error stays above the noise, the residuals ``r_s = y_s - h(q_s)``
carry the signature of what the model lacks. :func:`residual_diagnostics` measures:

* **correlation between end-effectors**: per coordinate, the Pearson correlation of the
  residuals of two observation groups (two markers, e.g. both hands). A large positive
  correlation says the error sits upstream of both (torso, base, tracker), not in one arm.
* **per-sample joint errors**: for every joint-driven DH frame (coupled frames
  included), the joint-angle error that best explains each sample's residual alone,
  ``dq_s = g_s . r_s / |g_s|^2`` with ``g_s`` the model's derivative of the sample's
  observations w.r.t. that frame's joint value, and the share of the squared residual
  these per-sample rotations remove, ``sum_s (g_s . r_s)^2 / |g_s|^2 / sum_s |r_s|^2``
  (by chance about ``1 / m`` for m observed values per sample:
  :attr:`Diagnostics.chance`). A frame whose share stands out is where the error acts;
  then
* **against its joint value**: the means of ``dq_s`` in ``bins`` equal-count bins of the
  frame's joint value (a harmonic error: a sine over the bins; a constant: an offset the
  model should have had), and
* **against the gravity torque**: the correlation of ``dq_s`` with the rigid gravity
  torque about the frame's joint axis (an elastic effect grows with the torque, a
  geometric one does not).

:func:`format_diagnostics` prints them as a short table.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from jwarp import kinematics as K
from jwarp.calibration.estimate.result import observation_groups
from jwarp.core.types import ArrayLike
from jwarp.model.robot import RobotModel
from jwarp.utils.checks import check_int

if TYPE_CHECKING:
    from jwarp.model.measurement import Measurement


@dataclass
class JointDiagnostics:
    """The per-sample joint errors of one DH frame (:func:`residual_diagnostics`).

    frame: its name; share: the share of the squared residual that per-sample rotations
    about it remove; bin_means (bins,): means of ``dq_s`` per bin of its joint value [rad
    or m]; bin_centres (bins,): the bins' median joint values; torque_corr: correlation of
    ``dq_s`` with the gravity torque about its axis (nan without a mass model or torque);
    direction_corr: correlation of ``dq_s`` with the direction its joint last moved in
    (``s @ C_i``, +-1; nan without ``directions`` or motion): large for backlash, the
    ``backlash`` group's effect.
    """

    frame: str
    share: float
    bin_means: np.ndarray
    bin_centres: np.ndarray
    torque_corr: float
    direction_corr: float = float("nan")


@dataclass
class Diagnostics:
    """Residual diagnostics of one robot / measurement-parameter pair on some samples.

    Attributes:
        n_samples: S; rms: root mean square residual per observed value [unit].
        correlations: [(group a, group b, (d,) Pearson correlation per coordinate)] for
            every pair of observation groups of the same dimension d.
        joints: :class:`JointDiagnostics` per joint-driven DH frame, largest share first.
        chance: the share one frame removes by chance, 1 / m.
    """

    n_samples: int
    rms: float
    correlations: list[tuple[str, str, np.ndarray]] = field(default_factory=list)
    joints: list[JointDiagnostics] = field(default_factory=list)
    chance: float = 0.0

    def to_dict(self, scale: float = 1.0) -> dict[str, Any]:
        """JSON-serializable; the rms times ``scale`` (1000: m -> mm)."""
        def num(v: float) -> float | None:
            return float(v) if np.isfinite(v) else None

        return {
            "n_samples": self.n_samples, "rms": self.rms * scale, "chance": self.chance,
            "correlations": [{"a": a, "b": b, "r": [float(v) for v in r]}
                             for a, b, r in self.correlations],
            "joints": [{"frame": j.frame, "share": j.share,
                        "bin_means": j.bin_means.tolist(),
                        "bin_centres": j.bin_centres.tolist(),
                        "torque_corr": num(j.torque_corr),
                        "direction_corr": num(j.direction_corr)} for j in self.joints],
        }


def residual_diagnostics(robot: RobotModel, measurement: Measurement, p: Any, q: ArrayLike, y: Any,
                         meta: Mapping[str, Any] | None = None, *, bins: int = 5,
                         directions: Any = None) -> Diagnostics:
    """Diagnostics of the residuals ``y - predict(robot, q)`` (module docstring).

    Args:
        robot: the calibrated RobotModel (e.g. ``result.robot``).
        measurement: the measurement plugin; p: (P_meas,) its parameters.
        q: (S, n_dof) joint values; y: (S, m) observations; meta: per-sample inputs.
        bins: equal-count bins of each joint value (>= 2, at most S).
        directions: (S, n_dof) the direction (+1, -1, 0) each joint last moved in before
            each sample (:func:`~jwarp.calibration.estimate.backlash.motion_directions` of
            the samples in measurement order): adds the direction correlation, and applies
            a backlash the robot records; None: neither.

    Returns:
        :class:`Diagnostics`.
    """
    from jwarp.calibration.estimate.map import CalibrationProblem, problem_options

    if not isinstance(robot, RobotModel):   # resolved where it entered (jwarp.robot)
        raise TypeError(f"robot: expected a RobotModel (jwarp.robot(name) resolves a name), "
                        f"got {type(robot).__name__}")
    model = robot
    qa = np.asarray(q, np.float64)
    if qa.ndim != 2 or qa.shape[1] != model.n_dof:
        raise ValueError(f"q: expected shape (S, {model.n_dof}), got {qa.shape}")
    S = qa.shape[0]
    check_int(bins, "bins", 2, S)
    pa = np.asarray(p, np.float64)
    frames = [i for i in np.nonzero(model.is_dh)[0] if model.frames[i].coupling]
    prob = CalibrationProblem(model, measurement, qa, y,
                              problem_options(free="theta", frames=frames, p_nominal=pa,
                                              noise_sigma=1.0, directions=directions),
                              meta=meta)
    sdir = None
    if directions is not None:
        from jwarp.calibration.estimate.backlash import check_directions

        sdir = check_directions(directions, S, model.n_dof)
    sp = prob.space
    x0 = sp.nominal
    r = prob.y - prob.predict(x0)                                      # (S, m)
    m = r.shape[1]
    J = prob.jacobian(x0)[:prob.n_data].reshape(S, m, sp.size)         # noise 1: raw
    out = Diagnostics(n_samples=S, rms=float(np.sqrt(np.mean(r * r))), chance=1.0 / m)
    groups = observation_groups(measurement)
    for a in range(len(groups)):
        for b in range(a + 1, len(groups)):
            (na, ia), (nb, ib) = groups[a], groups[b]
            if ia.size != ib.size:
                continue
            ra, rb = r[:, ia] - r[:, ia].mean(0), r[:, ib] - r[:, ib].mean(0)
            den = np.sqrt(np.sum(ra * ra, 0) * np.sum(rb * rb, 0))
            out.correlations.append((na, nb, np.where(den > 0, np.sum(ra * rb, 0)
                                                      / np.where(den > 0, den, 1.0), 0.0)))
    total = float(np.sum(r * r))
    tau = (np.asarray(K.gravity_torques(model, qa, device="cpu", dtype=np.float64))[..., 2]
           if model.masses else None)
    C = model.coupling_matrix
    for k in range(sp.size):
        i = int(sp.frame[k])
        g = J[:, :, k]                                                 # (S, m)
        gg = np.sum(g * g, axis=1)
        ok = gg > 1e-18 * max(float(gg.max()), 1e-300)
        if not ok.any() or total == 0:
            continue
        gr = np.sum(g * r, axis=1)
        dq = np.where(ok, gr / np.where(ok, gg, 1.0), 0.0)
        share = float(np.sum(np.where(ok, gr * gr / np.where(ok, gg, 1.0), 0.0))) / total
        v = qa @ C[i]
        order = np.argsort(v, kind="stable")
        parts = np.array_split(order, bins)
        means = np.array([float(dq[pp].mean()) for pp in parts])
        centres = np.array([float(np.median(v[pp])) for pp in parts])
        corr = float("nan")
        if tau is not None:
            t = tau[:, i] - tau[:, i].mean()
            d = dq - dq.mean()
            den = float(np.sqrt((t @ t) * (d @ d)))
            if den > 0 and float(np.abs(tau[:, i]).max()) > 1e-9:
                corr = float(t @ d) / den
        dcorr = float("nan")
        if sdir is not None:
            sv = np.sign(sdir @ C[i])
            mv = sv != 0
            if mv.sum() > 2:
                a_, b_ = sv[mv] - sv[mv].mean(), dq[mv] - dq[mv].mean()
                den = float(np.sqrt((a_ @ a_) * (b_ @ b_)))
                if den > 0:
                    dcorr = float(a_ @ b_) / den
        out.joints.append(JointDiagnostics(model.frames[i].name, share, means, centres, corr,
                                           dcorr))
    out.joints.sort(key=lambda j: -j.share)
    return out


def format_diagnostics(diag: Diagnostics, scale: float = 1.0, unit: str = "",
                       top: int = 6) -> str:
    """A short text report of :func:`residual_diagnostics` (the rms times ``scale``;
    joint errors in mrad)."""
    lines = [f"residual diagnostics on {diag.n_samples} samples (rms {diag.rms * scale:.3f} "
             f"{unit} per value)"]
    if diag.correlations:
        lines.append("  correlation of residuals between observation groups (per coordinate):")
        for a, b, rr in diag.correlations:
            lines.append(f"    {a} ~ {b}: " + " ".join(f"{v:+.2f}" for v in rr))
    lines.append(f"  per-sample joint errors: share of the squared residual removed (chance "
                 f"{diag.chance:.3f}), mean error per bin of the joint value [mrad], "
                 f"correlation with the gravity torque"
                 + (" and with the direction of motion" if any(
                     np.isfinite(j.direction_corr) for j in diag.joints) else ""))
    for j in diag.joints[:top]:
        tc = "  n/a" if not np.isfinite(j.torque_corr) else f"{j.torque_corr:+.2f}"
        dc = "" if not np.isfinite(j.direction_corr) else f"   {j.direction_corr:+.2f}"
        lines.append(f"    {j.frame:<14}{j.share:7.3f}   "
                     + " ".join(f"{1e3 * b:+6.2f}" for b in j.bin_means) + f"   {tc}{dc}")
    return "\n".join(lines)
