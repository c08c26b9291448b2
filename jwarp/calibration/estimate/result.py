"""Calibration results: calibrated model, posterior sigmas, identifiability, error tables.

* :class:`CalibrationResult` — what :func:`~jwarp.calibration.calibrate` returns.
* :func:`predict`, :func:`errors`, :func:`error_stats` — per-sample errors of any robot /
  measurement-parameter pair on any rows (train/test, before/after tables).
* :func:`observation_groups` — which observed values form one marker / image point.
"""

from __future__ import annotations

import math
import types
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from jwarp import kinematics as K
from jwarp.calibration.estimate.backlash import check_directions
from jwarp.calibration.estimate.params import (
    KIND_KAPPA,
    KIND_MASS,
    ParameterSpace,
    robot_backlash,
)
from jwarp.core.types import ArrayLike, RobotLike
from jwarp.model import RobotModel
from jwarp.model.valid_range import ValidRange, record_valid_range, valid_range_of
from jwarp.plugins.registry import robot as get_robot

if TYPE_CHECKING:
    from jwarp.model.measurement import Measurement


class CalibrationWarning(UserWarning):
    """The data cannot identify some parameters, a parameter moved far from its prior, the
    solver or the elastic equilibrium did not converge."""


# ---------------------------------------------------------------- errors
_COORD_SUFFIXES = ("x", "y", "z", "u", "v")


def observation_groups(measurement: Measurement) -> list[tuple[str, np.ndarray]]:
    """Groups of observed values whose Euclidean norm is one error (a marker's x, y, z; an
    image point's u, v; a scalar distance alone).

    Uses ``measurement.error_groups`` (list of (name, indices)) when the plugin defines it,
    else groups ``obs_names`` ``<name>_x/_y/_z`` (or ``_u/_v``) by ``<name>``.
    """
    custom = getattr(measurement, "error_groups", None)
    if custom is not None:
        return [(str(n), np.asarray(ix, np.int64)) for n, ix in custom]
    order: dict[str, list[int]] = {}
    for k, name in enumerate(measurement.obs_names):
        head, sep, tail = name.rpartition("_")
        key = head if sep and tail in _COORD_SUFFIXES and head else name
        order.setdefault(key, []).append(k)
    return [(n, np.asarray(ix, np.int64)) for n, ix in order.items()]


def group_norms(diff: np.ndarray, groups: list[tuple[str, np.ndarray]]) -> np.ndarray:
    """Per-sample error norms (S, G) of differences ``diff`` (S, m)."""
    return np.stack([np.linalg.norm(diff[:, ix], axis=1) for _, ix in groups], axis=1)


def model_frames(robot: RobotModel, q: np.ndarray, *, kappa: ArrayLike | None = None,
                 elastic: bool | None = None, lam: float = 1.0, max_iter: int = 100,
                 tol: float = 1e-12, directions: Any = None) -> np.ndarray:
    """World frames (S, n_frames, 4, 4) float64 on CPU: elastic equilibrium with ``kappa``
    (default the robot's) when elastic (default: iff kappa or the robot's
    ``kappa_nonlinear`` is nonzero), else rigid FK (both with the robot's joint
    transmission errors, if any, and the angle-dependent errors of coupled frames,
    ``coupling_harmonic``, as per-sample DH rows). ``directions`` (S, n_dof): the
    direction each joint last moved in (:mod:`~jwarp.calibration.estimate.backlash`),
    with which the robot's recorded backlash (``notes['backlash']``) is applied; None: no
    backlash."""
    kap = K.kappa_array(robot, kappa)
    model = get_robot(robot)
    dh = None
    q_kin = q
    if directions is not None:
        b = robot_backlash(model)
        if np.any(b):
            qa = np.asarray(q, np.float64)
            if qa.ndim != 2:
                raise ValueError(f"q: expected (S, n_dof) with directions, got {qa.shape}")
            q_kin = model.joint_transmission(qa) + check_directions(directions, *qa.shape) * b
    if model.has_coupling_harmonic:
        qa = np.asarray(q, np.float64)
        delta = model.coupled_frame_delta(qa)                        # (..., n)
        dh = np.broadcast_to(model.dh_table, qa.shape[:-1] + model.dh_table.shape).copy()
        pris = model.frame_is_prismatic
        dh[..., 1] += delta * ~pris
        dh[..., 0] += delta * pris
        model = K.without_coupling_harmonic(model)   # the rows carry them (not the kernels)
    if q_kin is not q:   # the links' values carry the transmission errors and the backlash
        model = K.without_transmission(model)
    q = q_kin
    if elastic is None:
        elastic = bool(np.any(kap != 0) or np.any(model.kappa_nonlinear))
    if elastic:
        return K.fk_elastic(model, q, kap, lam=lam, max_iter=max_iter, tol=tol, dh=dh,
                            device="cpu", dtype=np.float64).frames
    return K.fk(model, q, dh=dh, device="cpu", dtype=np.float64)


def fixed_params(measurement: Measurement, fix_at: Mapping[str, Any], p_nominal: Any = None
                 ) -> np.ndarray:
    """Measurement parameters (P_meas,) with the groups of ``fix_at`` at values calibrated
    before (``--fix tracker=cal.json``).

    Args:
        measurement: the measurement plugin (its ``params``).
        fix_at: {group: source}; a source is a :class:`CalibrationResult`, its
            ``to_dict()`` (the ``--params-out`` JSON: its ``measurement_params``), or the
            path of such a JSON file.
        p_nominal: (P_meas,) the other values (default: the ParamBlock's nominal).

    Raises:
        ValueError naming ``fix_at`` (unknown group, unreadable file, a parameter of the
        group missing from the source).
    """
    import json
    import os

    block = getattr(measurement, "params", None)
    if block is None:
        raise ValueError("fix_at: the measurement has no parameters")
    p = block.nominal.copy() if p_nominal is None else np.array(p_nominal, np.float64)
    if p.shape != (block.size,):
        raise ValueError(f"p_nominal: expected shape ({block.size},), got {p.shape}")
    for g, src in fix_at.items():
        if g not in block.group_names():
            raise ValueError(f"fix_at: '{g}' is not a group of the measurement (its groups: "
                             f"{', '.join(block.group_names())})")
        where = f"fix_at['{g}']"
        if isinstance(src, CalibrationResult):
            values = dict(zip(src.param_names, map(float, src.params)))
        else:
            doc = src
            if isinstance(src, (str, os.PathLike)):
                try:
                    with open(src, encoding="utf-8") as fh:
                        doc = json.load(fh)
                except (OSError, ValueError) as e:
                    raise ValueError(f"{where}: cannot read {src}: {e}") from None
            if not isinstance(doc, Mapping) or not isinstance(
                    doc.get("measurement_params"), Mapping):
                raise ValueError(f"{where}: expected a calibration result (its "
                                 f"'measurement_params'), got {type(doc).__name__}")
            values = doc["measurement_params"]
        origin = f"{os.fspath(src)}: " if isinstance(src, (str, os.PathLike)) else ""
        for k in block.indices(g):
            name = block.names[k]
            if name not in values:
                raise ValueError(f"{where}: {origin}the source has no value of '{name}'")
            raw = values[name]
            if isinstance(raw, (bool, np.bool_)) or not isinstance(
                    raw, (int, float, np.integer, np.floating)):
                raise ValueError(f"{where}: {origin}'{name}' is {raw!r}, not a number")
            v = float(raw)
            if not math.isfinite(v):
                raise ValueError(f"{where}: {origin}'{name}' is not finite")
            p[k] = v
    return p


def predict(robot: RobotLike, measurement: Measurement, p: Any, q: ArrayLike, meta: Mapping[str, Any] | None = None,
            *, kappa: ArrayLike | None = None, elastic: bool | None = None, lam: float = 1.0,
            max_iter: int = 100, tol: float = 1e-12, directions: Any = None) -> np.ndarray:
    """Predicted observations (S, m) of ``measurement`` with parameters ``p`` (P_meas,) for
    joint values ``q`` (S, n_dof) on ``robot`` (elastic as in :func:`model_frames`)."""
    from jwarp.calibration.estimate.samples import check_samples

    model = get_robot(robot)
    m = len(measurement.obs_names)
    qa = np.asarray(q, np.float64)
    S = qa.shape[0] if qa.ndim == 2 else 0
    qa, _, md = check_samples(model, measurement, q, np.zeros((S, m)), meta)
    fr = model_frames(model, qa, kappa=kappa, elastic=elastic, lam=lam, max_iter=max_iter,
                      tol=tol, directions=directions)
    return np.asarray(measurement.predict(fr, np.asarray(p, np.float64), md), np.float64)


def errors(robot: RobotLike, measurement: Measurement, p: Any, q: ArrayLike, y: Any,
           meta: Mapping[str, Any] | None = None, *, kappa: ArrayLike | None = None,
           elastic: bool | None = None, lam: float = 1.0, max_iter: int = 100,
           tol: float = 1e-12, directions: Any = None) -> np.ndarray:
    """Per-sample errors (S, G) = norm of (prediction - y) per observation group (marker,
    image point, distance) in the measurement's unit, for rows q (S, n_dof), y (S, m).

    ``robot`` is e.g. the nominal or the calibrated model (``result.robot``); ``p`` the
    measurement parameters (``result.params``); elastic and ``directions`` (backlash) as
    in :func:`model_frames`.
    """
    from jwarp.calibration.estimate.samples import check_samples

    model = get_robot(robot)
    qa, ya, md = check_samples(model, measurement, q, y, meta)
    fr = model_frames(model, qa, kappa=kappa, elastic=elastic, lam=lam, max_iter=max_iter,
                      tol=tol, directions=directions)
    yp = np.asarray(measurement.predict(fr, np.asarray(p, np.float64), md), np.float64)
    return group_norms(yp - ya, observation_groups(measurement))


def error_stats(errors: Any) -> dict[str, float]:
    """``{"mean", "std", "max"}`` over all entries of an error array (e.g. (S, G))."""
    e = np.asarray(errors, np.float64).reshape(-1)
    if e.size == 0:
        raise ValueError("errors: empty")
    if not np.all(np.isfinite(e)):
        raise ValueError("errors: contains NaN or inf")
    return {"mean": float(e.mean()), "std": float(e.std()), "max": float(e.max())}


# ---------------------------------------------------------------- result
@dataclass
class Direction:
    """A weakly determined parameter direction: eigenvalue of the prior-whitened data
    information and the parameters dominating its eigenvector (name, component)."""

    eigenvalue: float
    parameters: list[tuple[str, float]]

    def describe(self) -> str:
        comp = ", ".join(f"{w:+.2g} {n}" for n, w in self.parameters)
        return f"eigenvalue {self.eigenvalue:.2e}: [{comp}]"


@dataclass
class CalibrationResult:
    """Outcome of :func:`~jwarp.calibration.calibrate`.

    robot: calibrated RobotModel (``robot.save(path)``; loads as a robot everywhere).
    params: (P_meas,) calibrated measurement parameters (fixed ones at nominal).
    x, x_start, names, groups, nominal, sigma: (P,) free-parameter vector at the optimum,
        the start it came from, names/groups, prior means and sigmas.
    std: (P,) posterior standard deviations, sqrt(diag((J^T J)^-1)) of the whitened problem
        (inf where neither data nor prior constrain).
    cost: 0.5 |r|^2 at the optimum; success/status/message/nfev/iterations of the best start;
    starts: per-start summaries {start, cost, nfev, iterations, status, message}.
    errors, errors_start: (S, G) per-sample errors on the calibration rows at the optimum and
        at the start [measurement unit]; error_names (G,) the observation groups.
    unidentifiable: weakly determined directions (:class:`Direction`).
    moved: [(name, prior sigmas moved)] beyond ``moved_sigmas``.
    warnings: the findings as text (also emitted as CalibrationWarning when warn=True).
    space: the ParameterSpace (to map x again); elastic: whether the equilibrium was used.
    time_s: wall time [s].
    valid_range: the range of the calibration poses, per joint and coupled angle
        (:class:`~jwarp.model.valid_range.ValidRange`), also recorded in
        ``robot.notes['valid_range']``: IK, the planner and ``jwarp fk`` warn outside it.
    provenance: how settings were chosen (e.g. ``{"cv": ...}`` of a cross-validation).
    """

    robot: RobotModel
    params: np.ndarray
    x: np.ndarray
    x_start: np.ndarray
    names: list[str]
    groups: list[str]
    nominal: np.ndarray
    sigma: np.ndarray
    std: np.ndarray
    cost: float
    success: bool
    status: int
    message: str
    nfev: int
    iterations: int
    starts: list[dict]
    errors: np.ndarray
    errors_start: np.ndarray
    error_names: list[str]
    unidentifiable: list[Direction]
    moved: list[tuple[str, float]]
    warnings: list[str]
    space: ParameterSpace
    elastic: bool
    time_s: float
    unit: str = "m"
    param_names: list[str] = field(default_factory=list)
    valid_range: ValidRange | None = None
    provenance: dict[str, Any] = field(default_factory=dict)

    def value(self, name: str) -> float:
        """Calibrated value of the free parameter ``name``."""
        return float(self.x[self.space.index(name)])

    def table(self, scale_lengths: float = 1.0) -> str:
        """Text table of the free parameters: nominal, calibrated, posterior std, moved."""
        rows = [f"{'parameter':<28} {'group':<12} {'nominal':>12} {'calibrated':>12} "
                f"{'std':>10} {'moved/sigma':>11}"]
        for i, n in enumerate(self.names):
            mv = (self.x[i] - self.nominal[i]) / self.sigma[i] if math.isfinite(self.sigma[i]) else float("nan")
            rows.append(f"{n:<28} {self.groups[i]:<12} {self.nominal[i]:>12.6g} "
                        f"{self.x[i]:>12.6g} {self.std[i]:>10.3g} {mv:>11.2f}")
        return "\n".join(rows)

    def to_dict(self) -> dict[str, Any]:
        """JSON-serializable summary (lengths/errors in the measurement unit)."""
        def f(v: float) -> float | None:
            return float(v) if math.isfinite(v) else None

        return {
            "cost": float(self.cost), "success": bool(self.success), "status": int(self.status),
            "message": self.message, "nfev": int(self.nfev), "iterations": int(self.iterations),
            "time_s": float(self.time_s), "elastic": bool(self.elastic), "unit": self.unit,
            "starts": [{**r, "cost": f(r["cost"])} for r in self.starts],
            "errors": error_stats(self.errors), "errors_start": error_stats(self.errors_start),
            "measurement_params": dict(zip(self.param_names, map(float, self.params))),
            "parameters": [{"name": n, "group": g, "nominal": float(a), "value": float(b),
                            "sigma": f(s), "std": f(sd)}
                           for n, g, a, b, s, sd in zip(self.names, self.groups, self.nominal,
                                                        self.x, self.sigma, self.std)],
            "unidentifiable": [{"eigenvalue": d.eigenvalue,
                                "parameters": [[n, w] for n, w in d.parameters]}
                               for d in self.unidentifiable],
            "moved": [[n, v] for n, v in self.moved],
            "warnings": list(self.warnings),
            **({"valid_range": self.valid_range.to_dict()} if self.valid_range is not None
               else {}),
            **({"provenance": self.provenance} if self.provenance else {}),
        }


def posterior_std(J: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """sqrt(diag((J^T J)^-1)) computed in the scaled variables x / scale (P,); inf for
    parameters in directions with no information at all."""
    Js = J * scale[None, :]
    lam, V = np.linalg.eigh(Js.T @ Js)
    top = max(float(lam[-1]), 1e-300)
    ok = lam > top * 1e-14
    var = (V[:, ok] ** 2) @ (1.0 / lam[ok])
    blind = (V[:, ~ok] ** 2).sum(axis=1) > 1e-6
    std = scale * np.sqrt(var)
    std[blind] = np.inf
    return std


def weak_directions(J_data: np.ndarray, scale: np.ndarray, names: list[str], tol: float,
                    max_names: int = 4) -> list[Direction]:
    """Eigen-directions of the data information ``(J_data S)^T (J_data S)`` (S = diag of the
    prior sigmas, so 1 = as informative as the prior) with eigenvalue < ``tol``; each named
    by its largest components (the two largest and any >= 0.2, at most ``max_names``)."""
    Js = J_data * scale[None, :]
    lam, V = np.linalg.eigh(Js.T @ Js)
    out = []
    for k in np.nonzero(lam < tol)[0]:
        v = V[:, k]
        v = v * np.sign(v[np.argmax(np.abs(v))])
        order = np.argsort(-np.abs(v))
        idx = [i for k2, i in enumerate(order) if abs(v[i]) >= 0.2 or k2 < 2][:max_names]
        out.append(Direction(float(max(lam[k], 0.0)), [(names[i], float(v[i])) for i in idx]))
    return out


def mass_compliance_scaling(J_data: np.ndarray, sp: ParameterSpace, x: np.ndarray,
                            tol: float) -> str | None:
    """The flat direction of free masses together with free compliances, as a finding.

    Masses act only through ``kappa * tau`` and ``tau`` is linear in them, so scaling every
    free mass by ``c`` and every free compliance by ``1 / c`` changes no prediction when
    these are all the masses and compliances in play. The direction ``dx = (m, -kappa)``
    (zero elsewhere) is tested: if its prior-whitened data information (as in
    :func:`weak_directions`) is below ``tol``, the data cannot separate the two groups.

    Args:
        J_data: (S*m, P) data rows of the whitened Jacobian at ``x`` (P,).
        sp: the parameter space; tol: information threshold.

    Returns:
        the finding's text, or None (one of the groups not free, or the data separate them).
    """
    mass = sp.kind == KIND_MASS
    kap = sp.kind == KIND_KAPPA
    if not (mass.any() and kap.any()):
        return None
    v = np.where(mass, x, 0.0) - np.where(kap, x, 0.0)
    vs = v / sp.scale
    nv = float(np.linalg.norm(vs))
    if nv == 0.0:
        return None
    info = float(np.sum((J_data @ (v / nv)) ** 2))
    if info >= tol:
        return None
    held = bool(np.all(sp.has_prior[mass | kap]))
    return (f"masses and compliances are not separately identifiable from the data "
            f"(information {info:.1e}): scaling every free mass by c and every free compliance "
            f"by 1/c leaves the predictions unchanged; "
            + ("held by the priors of mass and kappa" if held else
               "some of them have no prior (sigma inf), so their calibrated values are one "
               "arbitrary point of that family; give them priors or fix one group"))


def build_result(prob: Any, sol: Any, x_start: np.ndarray, iterations: int, starts: list[dict],
                 time_s: float, *, identifiability_tol: float, moved_sigmas: float,
                 warn: bool) -> CalibrationResult:
    """Assemble a :class:`CalibrationResult` from a solved :class:`CalibrationProblem`."""
    sp: ParameterSpace = prob.space
    x = np.asarray(sol.x, np.float64)
    J = prob.jacobian(x)
    scale = sp.scale
    std = posterior_std(J, scale)
    weak = weak_directions(J[:prob.n_data], scale, sp.names, identifiability_tol)
    moved = []
    for i in np.nonzero(sp.has_prior)[0]:
        ns = abs(x[i] - sp.nominal[i]) / sp.sigma[i]
        if ns > moved_sigmas:
            moved.append((sp.names[i], float(ns)))
    groups = observation_groups(prob.measurement)
    err = group_norms(prob.predict(x) - prob.y, groups)
    conv = prob.state(x).converged
    err0 = group_norms(prob.predict(x_start) - prob.y, groups)
    msgs = []
    if sol.status <= 0:
        msgs.append(f"solver stopped before convergence: {sol.message}")
    if not np.all(conv):
        msgs.append(f"elastic equilibrium not converged for {int((~conv).sum())} of "
                    f"{conv.size} samples at the optimum (raise equilibrium_iterations or lower lam)")
    neg_mask = (sp.kind == KIND_KAPPA) & (x < 0)
    neg = [sp.names[i] for i in np.nonzero(neg_mask)[0]]
    if neg:
        xc = np.where(neg_mask, 0.0, x)
        clip_err = float(np.mean(group_norms(prob.predict(xc) - prob.y, groups)))
        msgs.append(f"{len(neg)} compliance(s) calibrated negative, set to 0 in the calibrated "
                    f"robot, whose mean error on the calibration rows is then {clip_err:.4g} "
                    f"instead of the fit's {float(np.mean(err)):.4g} (bound_kappa=True keeps "
                    f"them >= 0 in the fit): {', '.join(neg[:8])}{' ...' if len(neg) > 8 else ''}")
    held = [sp.names[i] for i in np.nonzero(getattr(sol, "held", np.zeros(sp.size, bool)))[0]]
    if held:
        msgs.append(f"{len(held)} compliance(s) held at their bound 0 (the data pull them "
                    f"negative: an effect the model lacks, or little excitation): "
                    f"{', '.join(held[:8])}{' ...' if len(held) > 8 else ''}")
    scaling = mass_compliance_scaling(J[:prob.n_data], sp, x, identifiability_tol)
    if scaling is not None:
        msgs.append(scaling)
    for d in weak:
        msgs.append(f"parameter direction not identifiable from the data (held by the "
                    f"prior), {d.describe()}")
    for n, ns in moved:
        msgs.append(f"parameter {n} moved {ns:.1f} prior sigmas from its nominal value")
    if warn and msgs:
        head = f"calibration: {len(msgs)} finding(s):\n  " + "\n  ".join(msgs[:20])
        if len(msgs) > 20:
            head += f"\n  ... and {len(msgs) - 20} more (see result.warnings)"
        warnings.warn(head, CalibrationWarning, stacklevel=_caller_stacklevel())
    meas = prob.measurement
    robot = sp.robot_at(x)
    vr = valid_range_of(robot, prob.q)
    return CalibrationResult(
        robot=record_valid_range(robot, prob.q), params=sp.measurement_params(x), x=x,
        x_start=np.asarray(x_start),
        names=list(sp.names), groups=list(sp.groups), nominal=sp.nominal.copy(),
        sigma=sp.sigma.copy(), std=std, cost=float(sol.cost), success=bool(sol.status > 0),
        status=int(sol.status), message=str(sol.message), nfev=int(sol.nfev),
        iterations=int(iterations), starts=starts, errors=err, errors_start=err0,
        error_names=[n for n, _ in groups], unidentifiable=weak, moved=moved, warnings=msgs,
        space=sp, elastic=prob.elastic, time_s=float(time_s),
        unit=str(getattr(meas, "unit", "m")),
        param_names=list(getattr(getattr(meas, "params", None), "names", []) or []),
        valid_range=vr)


def _caller_stacklevel() -> int:
    """The ``warnings.warn`` stacklevel, for the function calling this one, of the first
    frame outside the jwarp package: a finding is attributed to the user's call
    (``calibrate(...)`` in their script), whichever jwarp entry point it went through."""
    import os
    import sys

    # this file is jwarp/calibration/estimate/result.py: the package root is 3 levels up
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))) + os.sep
    level = 1
    frame: types.FrameType | None = sys._getframe(1)
    while frame is not None and os.path.abspath(frame.f_code.co_filename).startswith(root):
        frame, level = frame.f_back, level + 1
    return level
