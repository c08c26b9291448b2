"""Sensitivity analysis of a calibration setup (thesis 2.4.1, eqs. 2.23-2.24).

For a measurement ``h`` at configurations ``q_1..q_S`` the stacked Jacobian
``J = [dh(q_s)/dTheta]_s`` (S*m, P) with respect to the free parameters ``Theta`` (the
:class:`~jwarp.calibration.estimate.params.ParameterSpace` of the free groups) tells which
parameters the data can identify: the kernel of ``J^T J``. For an *actual* measurement
``h_a`` (what the lab can measure, e.g. fingertip contacts) and a *task* measurement
``h_t`` (what the application needs, e.g. fingertip positions relative to the thumb), the
necessary condition for calibrating the task with ``h_a`` is (eq. 2.24)

    Kernel(J_a^T J_a)  within  Kernel(J_t^T J_t).

Conventions (documented choices):

* **Unwhitened by default.** ``J`` is the derivative of the observations in the
  measurement's unit (m, px) per parameter unit (rad, m), as eq. 2.23; ``whiten=True``
  divides each row by the measurement's noise sigma (the rows of the MAP problem). The
  rows come from :meth:`CalibrationProblem.jacobian` (analytic, elastic when the robot is)
  at the nominal parameters (``x`` overrides), without its prior rows.
* **Identifiable** means an eigenvalue of ``J^T J`` above
  ``max(rtol * lambda_max, atol)``. The default ``rtol = 1e-12`` (a singular-value ratio of
  1e-6) is a numerical rank: exact kernels sit at ~1e-16 relative in float64, while weakly
  identifiable directions of real setups are far above it (hand4's weakest contact direction
  is ~4e-10). ``atol`` reproduces the thesis' absolute threshold (``atol=1e-6``, Fig. 2.8),
  which depends on units and the number of samples.
* **Kernel inclusion.** With ``N_a`` an orthonormal basis of the actual kernel, the
  directions of ``N_a`` the task sees are the right singular vectors of ``J_t N_a``
  whose squared singular value exceeds the task's threshold
  ``max(rtol * lambda_max(J_t^T J_t), atol)``; each such direction (a unit vector in
  parameter space) breaks eq. 2.24. Its largest-weight parameters name it.
* **Parameter sets.** Robot groups of ``free`` apply to both measurements; a measurement
  group applies to the measurement that has it (a group neither has is an error). The
  two Jacobians are aligned by parameter name on the union of both spaces; a parameter a
  measurement does not depend on is a zero column there (so a task without a parameter
  has it in its kernel).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from jwarp.calibration.estimate.params import ROBOT_GROUPS, ParameterSpace, parse_groups
from jwarp.core.threads import limit_blas
from jwarp.core.types import RobotLike
from jwarp.model.robot import RobotModel
from jwarp.plugins.registry import robot as get_robot

if TYPE_CHECKING:
    from jwarp.model.measurement import Measurement

#: default relative tolerance of :func:`spectrum` (numerical rank of J^T J)
DEFAULT_RTOL = 1e-12


@dataclass
class Spectrum:
    """Eigenvalues of ``J^T J`` (descending) and the identifiable count.

    eigenvalues (P,) [unit^2 / parameter unit^2] (clipped at 0); threshold: the value
    above which an eigenvalue counts as identifiable; n_identifiable, n_params.
    """

    eigenvalues: np.ndarray
    threshold: float
    n_identifiable: int
    n_params: int

    def to_dict(self) -> dict[str, Any]:
        return {"eigenvalues": [float(v) for v in self.eigenvalues],
                "threshold": float(self.threshold), "n_identifiable": int(self.n_identifiable),
                "n_params": int(self.n_params)}


@dataclass
class Direction:
    """A parameter direction (unit vector) of the actual kernel that the task sees.

    vector (P,); task_gain: ``|J_t v|^2`` relative to the task's largest eigenvalue;
    top: the largest-weight parameters [(name, weight)], by |weight| descending.
    """

    vector: np.ndarray
    task_gain: float
    top: list[tuple[str, float]]

    def to_dict(self) -> dict[str, Any]:
        return {"task_gain": float(self.task_gain),
                "top": [{"name": n, "weight": float(w)} for n, w in self.top]}


@dataclass
class SensitivityResult:
    """Result of :func:`sensitivity` (see the module docstring for the conventions).

    names (P,): the parameters (union of both spaces); actual, task: :class:`Spectrum` of
    each measurement; kernel_included: eq. 2.24 holds; breaking: the directions that break
    it; rtol, atol: the tolerances; whitened: rows divided by the noise sigma;
    n_rows: (actual, task) rows of the stacked Jacobians.
    """

    names: list[str]
    actual: Spectrum
    task: Spectrum
    kernel_included: bool
    breaking: list[Direction]
    rtol: float
    atol: float
    whitened: bool
    n_rows: tuple[int, int] = (0, 0)
    labels: tuple[str, str] = ("actual", "task")
    notes: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {"names": list(self.names), "labels": list(self.labels),
                "actual": self.actual.to_dict(), "task": self.task.to_dict(),
                "kernel_included": bool(self.kernel_included),
                "breaking": [d.to_dict() for d in self.breaking],
                "rtol": float(self.rtol), "atol": float(self.atol),
                "whitened": bool(self.whitened), "n_rows": [int(v) for v in self.n_rows],
                **({"notes": self.notes} if self.notes else {})}


# ------------------------------------------------------------------ matrices
def _tolerances(rtol: float, atol: float) -> tuple[float, float]:
    for name, v in (("rtol", rtol), ("atol", atol)):
        if not isinstance(v, (int, float)) or isinstance(v, bool) or not np.isfinite(v) or v < 0:
            raise ValueError(f"{name}: expected a finite number >= 0, got {v!r}")
    if rtol == 0 and atol == 0:
        raise ValueError("rtol, atol: at least one tolerance must be > 0")
    return float(rtol), float(atol)


def _matrix(J: Any, name: str) -> np.ndarray:
    try:
        a = np.asarray(J, np.float64)
    except (TypeError, ValueError):
        raise TypeError(f"{name}: expected a 2-D array of numbers") from None
    if a.ndim != 2 or a.shape[1] == 0:
        raise ValueError(f"{name}: expected shape (rows, P) with P >= 1, got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name}: contains NaN or inf")
    return a


def _eig(J: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eigenvalues (descending, >= 0) and eigenvectors of J^T J, from the SVD of J (more
    accurate near zero than eigh of J^T J)."""
    P = J.shape[1]
    if J.shape[0] == 0:
        return np.zeros(P), np.eye(P)
    # a full V only when it is not square already (rows < P); never the big U
    _, s, Vt = np.linalg.svd(J, full_matrices=J.shape[0] < P)
    ev = np.zeros(P)
    ev[:s.size] = s ** 2
    return ev, Vt.T


def spectrum(J: Any, rtol: float = DEFAULT_RTOL, atol: float = 0.0) -> Spectrum:
    """The eigenvalue spectrum of ``J^T J`` for a stacked Jacobian J (rows, P) and the
    number of eigenvalues above ``max(rtol * lambda_max, atol)``."""
    rtol, atol = _tolerances(rtol, atol)
    a = _matrix(J, "J")
    ev, _ = _eig(a)
    thr = max(rtol * float(ev[0]), atol)
    return Spectrum(ev, thr, int(np.sum(ev > thr)), a.shape[1])


def kernel_basis(J: Any, rtol: float = DEFAULT_RTOL, atol: float = 0.0) -> np.ndarray:
    """Orthonormal basis (P, k) of the kernel of ``J^T J`` (eigenvalues at or below
    ``max(rtol * lambda_max, atol)``)."""
    rtol, atol = _tolerances(rtol, atol)
    a = _matrix(J, "J")
    ev, V = _eig(a)
    return V[:, ev <= max(rtol * float(ev[0]), atol)]


def top_parameters(v: np.ndarray, names: list[str], k: int = 6,
                   min_weight: float = 0.05) -> list[tuple[str, float]]:
    """The ``k`` largest-|weight| entries of a direction ``v`` (at least one; others only
    when |weight| >= ``min_weight``), sign fixed so that the largest weight is positive."""
    v = np.asarray(v, np.float64)
    order = np.argsort(-np.abs(v), kind="stable")
    sign = 1.0 if v[order[0]] >= 0 else -1.0
    out = [(names[i], float(sign * v[i])) for i in order[:k]
           if i == order[0] or abs(v[i]) >= min_weight]
    return out


def kernel_inclusion(Ja: Any, Jt: Any, names: Iterable[str] | None = None, *,
                     rtol: float = DEFAULT_RTOL, atol: float = 0.0, top: int = 6
                     ) -> tuple[bool, list[Direction]]:
    """Test eq. 2.24, Kernel(Ja^T Ja) within Kernel(Jt^T Jt), for stacked Jacobians
    Ja (rows_a, P) and Jt (rows_t, P) on the same P parameters.

    Returns:
        (included, directions): the directions of the actual kernel the task sees
        (module docstring), largest task gain first, each with its ``top`` parameters.
    """
    rtol, atol = _tolerances(rtol, atol)
    a, t = _matrix(Ja, "Ja"), _matrix(Jt, "Jt")
    if a.shape[1] != t.shape[1]:
        raise ValueError(f"Ja, Jt: different parameter counts {a.shape[1]} and {t.shape[1]}")
    P = a.shape[1]
    nm = [f"p{i}" for i in range(P)] if names is None else [str(n) for n in names]
    if len(nm) != P:
        raise ValueError(f"names: expected {P} names, got {len(nm)}")
    Na = kernel_basis(a, rtol, atol)
    ev_t, _ = _eig(t)
    thr_t = max(rtol * float(ev_t[0]), atol)
    if Na.shape[1] == 0:
        return True, []
    M = t @ Na
    if M.shape[0] == 0:
        return True, []
    _, s, Vt = np.linalg.svd(M, full_matrices=False)
    out = []
    scale = float(ev_t[0]) if ev_t[0] > 0 else 1.0
    for k in range(s.size):
        if s[k] ** 2 > thr_t:
            v = Na @ Vt[k]
            v = v / np.linalg.norm(v)
            out.append(Direction(v, float(s[k] ** 2 / scale), top_parameters(v, nm, top)))
    return not out, out


# ---------------------------------------------------------- measurements
def _groups_for(measurement: Measurement, groups: list[str]) -> list[str]:
    own = measurement.params.group_names() if getattr(measurement, "params", None) else []
    return [g for g in groups if g in ROBOT_GROUPS or g in own]


def stacked_jacobian(robot: RobotModel, measurement: Measurement, q: Any, free: str | Iterable[str], *,
                     meta: Mapping[str, Any] | None = None, x: Any = None,
                     whiten: bool = False, **problem: Any) -> tuple[np.ndarray, list[str]]:
    """Stacked Jacobian (S*m, P) of ``measurement`` at configurations q (S, n_dof) with
    respect to the free parameters (eq. 2.23), and the parameter names (P,).

    Args:
        robot: the RobotModel (nominal: the point of linearization; a name is resolved
            by the caller, e.g. :func:`sensitivity`).
        measurement: measurement plugin instance; meta: its per-sample columns.
        free: groups (robot groups and the measurement's own groups; others are an error).
        x: (P,) parameters to linearize at (default the nominal / prior mean).
        whiten: divide the rows by the measurement's noise sigma (default: unwhitened, in
            the measurement's unit per parameter unit).
        problem: further :class:`CalibrationProblem` arguments (sigma, frames, elastic, ...).
    """
    from jwarp.calibration.estimate.map import CalibrationProblem, problem_options

    if not isinstance(robot, RobotModel):   # resolved where it entered (jwarp.robot)
        raise TypeError(f"robot: expected a RobotModel (jwarp.robot(name) resolves a name), "
                        f"got {type(robot).__name__}")
    model = robot
    qa = np.asarray(q, np.float64)
    if qa.ndim != 2 or qa.shape[1] != model.n_dof:
        raise ValueError(f"q: expected shape (S, {model.n_dof}) for robot '{model.name}', "
                         f"got {qa.shape}")
    if qa.shape[0] == 0:
        raise ValueError("q: no configurations")
    if not np.all(np.isfinite(qa)):
        raise ValueError("q: contains NaN or inf")
    groups = parse_groups(free)   # unknown groups: ParameterSpace.build names them
    # the Jacobian does not depend on the observations: y = 0 only builds the problem
    y = np.zeros((qa.shape[0], len(measurement.obs_names)))
    space_args = {k: problem[k] for k in ("sigma", "frames", "p_nominal", "bound_kappa")
                  if k in problem}
    P = ParameterSpace.build(model, measurement, groups, **space_args).size
    S, m = y.shape
    # the problem refuses fewer values than parameters (a fit); the rows of a sample do not
    # depend on the others, so build it on repeated samples and keep the first S
    reps = max(1, -(-P // (S * m)))
    mm = None if meta is None else {k: np.tile(np.asarray(v), reps) for k, v in meta.items()}
    if not whiten:   # unit rows: the Jacobian in the measurement's unit
        problem = dict(problem, noise_sigma=1.0)
    settings = {k: v for k, v in problem.items() if k != "device"}
    prob = CalibrationProblem(model, measurement, np.tile(qa, (reps, 1)), np.tile(y, (reps, 1)),
                              problem_options(free=groups, **settings), meta=mm,
                              device=problem.get("device"))
    xx = prob.space.nominal if x is None else prob.space.check(x, "x")
    J = prob.jacobian(xx)[:S * m]
    return J, list(prob.space.names)


def align(J: np.ndarray, names: list[str], union: list[str]) -> np.ndarray:
    """The columns of J (rows, len(names)) placed on the parameters ``union`` (zeros for
    parameters J does not have)."""
    out = np.zeros((J.shape[0], len(union)))
    pos = {n: i for i, n in enumerate(union)}
    out[:, [pos[n] for n in names]] = J
    return out


@limit_blas  # small dense problems (JWARP_BLAS_THREADS)
def sensitivity(robot: RobotLike, actual: Any, q_actual: Any, task: Any, q_task: Any,
                free: str | Iterable[str], *, meta_actual: Mapping[str, Any] | None = None,
                meta_task: Mapping[str, Any] | None = None, whiten: bool = False,
                rtol: float = DEFAULT_RTOL, atol: float = 0.0, top: int = 6,
                labels: tuple[str, str] | None = None, **problem: Any) -> SensitivityResult:
    """Sensitivity of an actual vs a task measurement (eqs. 2.23-2.24).

    Args:
        robot: robot name or RobotModel (linearized at its nominal parameters).
        actual, task: measurement plugin instances (e.g. ``contact`` and ``relative``).
        q_actual (S_a, n_dof), q_task (S_t, n_dof): configurations of each (the actual
            measurement's meta columns in ``meta_actual``, e.g. ``{"pair": (S_a,)}``).
        free: parameter groups (module docstring: which applies to which measurement).
        whiten, rtol, atol: see the module docstring; top: parameters named per direction.
        problem: further CalibrationProblem arguments (sigma, frames, elastic, ...).

    Returns:
        :class:`SensitivityResult`.
    """
    rtol, atol = _tolerances(rtol, atol)
    groups = parse_groups(free)
    own_a = actual.params.group_names() if getattr(actual, "params", None) else []
    own_t = task.params.group_names() if getattr(task, "params", None) else []
    bad = [g for g in groups if g not in ROBOT_GROUPS and g not in own_a and g not in own_t]
    if bad:
        raise ValueError(f"free: unknown parameter group(s) {bad}; robot groups: "
                         f"{', '.join(ROBOT_GROUPS)}; '{actual.name}': {', '.join(own_a) or '-'}; "
                         f"'{task.name}': {', '.join(own_t) or '-'}")
    model = get_robot(robot)   # resolved once here; the Jacobians take the model
    Ja, na = stacked_jacobian(model, actual, q_actual, _groups_for(actual, groups),
                              meta=meta_actual, whiten=whiten, **problem)
    Jt, nt = stacked_jacobian(model, task, q_task, _groups_for(task, groups), meta=meta_task,
                              whiten=whiten, **problem)
    union = list(dict.fromkeys(na + nt))
    Ja, Jt = align(Ja, na, union), align(Jt, nt, union)
    included, breaking = kernel_inclusion(Ja, Jt, union, rtol=rtol, atol=atol, top=top)
    return SensitivityResult(
        names=union, actual=spectrum(Ja, rtol, atol), task=spectrum(Jt, rtol, atol),
        kernel_included=included, breaking=breaking, rtol=rtol, atol=atol,
        whitened=bool(whiten), n_rows=(Ja.shape[0], Jt.shape[0]),
        labels=labels or (str(actual.name), str(task.name)))
