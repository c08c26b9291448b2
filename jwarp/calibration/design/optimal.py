"""Optimal experimental design of a calibration campaign (thesis 2.4.2, eqs. 2.25-2.26).

Choose N configurations out of a candidate pool so that the calibrated parameters predict
the *task* measurement best (task D-optimality, after Carrillo et al.).

Reading of the thesis (documented choices):

* **Information form.** Eq. 2.26 writes ``Cov(Theta) = J_a^T Lambda_a J_a +
  Diag(sigma^2)``; as a covariance this is the inverse of the Gauss-Newton information
  of the MAP problem (eq. 2.5), which is what we use:
  ``A(S) = sum_{s in S} J_s^T Lambda^{-1} J_s + Diag(1 / sigma_Theta^2)`` and
  ``Cov(Theta) = A(S)^{-1}``, with ``J_s`` the actual measurement's Jacobian at candidate
  ``s`` (the rows of :meth:`CalibrationProblem.jacobian`, i.e. whitened by the noise sigma;
  ``Lambda`` diagonal) and ``sigma_Theta`` the free parameters' prior sigmas (every free
  parameter needs a finite prior: it makes ``A`` invertible for any set).
* **Task criterion.** Eq. 2.25, ``det(Cov T) / N_t`` with ``T = sum_i J_t^(i)T J_t^(i)``,
  factors into ``det(Cov) det(T)`` when T is regular (the task would not matter) and is 0
  for every set when T has a kernel (every task blind to some parameter: hand4's relative
  positions). We therefore evaluate the determinant on the range of the task: with
  ``T / N_t = L L^T`` (``L`` (P, r), r the numerical rank of T, relative tolerance
  ``rank_rtol``), the criterion to **maximize** is

      c(S) = -log det(L^T A(S)^{-1} L)

  (the D_A-optimality of the task's parameter combinations; equal to ``-log`` of eq. 2.25
  up to a constant when T is regular). Without a task, ``L = I``: plain D-optimality,
  ``c = log det A``.
* **Updates in log-det.** Adding (eps = +1) or removing (eps = -1) the rows ``U`` (m, P)
  of a candidate changes ``log det K`` (``K = L^T C L``, ``C = A^{-1}``) by
  ``log det(S - eps G K^{-1} G^T) - log det(S)`` with ``S = I_m + eps U C U^T`` and
  ``G = U C L`` (matrix determinant lemma + Woodbury), evaluated for every candidate at
  once; ``C`` follows by Woodbury and is recomputed from ``A`` every ``refresh`` updates.
  With a regular square ``L`` (no task, or a full-rank one) ``G K^{-1} G^T = U C U^T`` and
  the change is ``-log det S`` alone (half the work).

Methods: ``greedy`` adds, from the prior alone, the candidate that raises ``c`` most, N
times. ``detmax`` (Mitchell 1974) starts from the greedy design (or a random one) and
makes excursions: add the ``k`` best candidates one by one, then remove the ``k`` worst
points one by one (k = 1, then up to ``max_excursion`` when k = 1 fails); an excursion is
kept only when it raises ``c`` by more than ``tol``, so ``c`` never decreases; it stops
when no excursion improves or after ``iterations`` accepted ones. Candidates are chosen
without repetition.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from jwarp.calibration.estimate.params import ParameterSpace, parse_groups
from jwarp.core.threads import limit_blas
from jwarp.core.types import ArrayLike, RobotLike
from jwarp.model.robot import RobotModel
from jwarp.plugins.registry import robot as get_robot
from jwarp.solvers.overrides import renamed_options
from jwarp.utils.checks import check_int

if TYPE_CHECKING:
    from jwarp.model.measurement import Measurement

METHODS = ("greedy", "detmax")


@renamed_options(max_iter="iterations")
@dataclass
class DesignOptions:
    """Options of :func:`select`.

    n: configurations to select; method: ``greedy`` or ``detmax``; start (detmax):
    ``greedy`` or ``random``; max_excursion: deepest detmax excursion; iterations: most
    accepted detmax excursions; tol: least improvement of c that counts; refresh: Woodbury
    updates between exact inverses; seed: of the random start; rank_rtol: relative
    eigenvalue tolerance of the task's rank.
    """

    n: int
    method: str = "detmax"
    start: str = "greedy"
    max_excursion: int = 2
    iterations: int = 10000
    tol: float = 1e-9
    refresh: int = 32
    seed: int | None = 0
    rank_rtol: float = 1e-10

    def validate(self) -> None:
        for name, lo in (("n", 1), ("max_excursion", 1), ("iterations", 0), ("refresh", 1)):
            v = getattr(self, name)
            check_int(v, name, lo)
        if self.method not in METHODS:
            raise ValueError(f"method: expected one of {', '.join(METHODS)}, got {self.method!r}")
        if self.start not in ("greedy", "random"):
            raise ValueError(f"start: expected 'greedy' or 'random', got {self.start!r}")
        for name in ("tol", "rank_rtol"):
            v = getattr(self, name)
            if not isinstance(v, (int, float)) or not np.isfinite(v) or v < 0:
                raise ValueError(f"{name}: expected a finite number >= 0, got {v!r}")


@dataclass
class DesignResult:
    """Selected candidates and the criterion.

    indices (N,): into the pool (greedy: in the order added); criterion: c of the selection
    (module docstring; larger is better); history: c after every greedy step / accepted
    detmax excursion (never decreasing within detmax); prior_criterion: c of the prior
    alone; method, iterations (accepted excursions), rank (r of the task), n_candidates,
    time_s.
    """

    indices: np.ndarray
    criterion: float
    history: list[float]
    prior_criterion: float
    method: str
    iterations: int
    rank: int
    n_candidates: int
    time_s: float
    notes: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {"method": self.method, "n": int(self.indices.size),
                "indices": [int(i) for i in self.indices], "criterion": float(self.criterion),
                "prior_criterion": float(self.prior_criterion),
                "history": [float(v) for v in self.history], "iterations": int(self.iterations),
                "rank": int(self.rank), "n_candidates": int(self.n_candidates),
                "time_s": float(self.time_s), **({"notes": self.notes} if self.notes else {})}


# ------------------------------------------------------------------ inputs
def task_factor(Jt: Any, rank_rtol: float = 1e-10) -> np.ndarray:
    """``L`` (P, r) with ``L L^T = Jt^T Jt / rows`` restricted to its numerical range
    (eigenvalues above ``rank_rtol`` times the largest)."""
    a = np.asarray(Jt, np.float64)
    if a.ndim != 2 or a.shape[0] == 0 or a.shape[1] == 0:
        raise ValueError(f"Jt: expected shape (rows >= 1, P >= 1), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError("Jt: contains NaN or inf")
    _, s, Vt = np.linalg.svd(a / np.sqrt(a.shape[0]), full_matrices=False)
    if s.size == 0 or s[0] == 0:
        raise ValueError("Jt: the task does not depend on any free parameter")
    keep = s ** 2 > rank_rtol * s[0] ** 2
    return Vt[keep].T * s[keep]


def _check_inputs(U: Any, prior: Any, L: Any | None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    u = np.asarray(U, np.float64)
    if u.ndim == 2:
        u = u[:, None, :]
    if u.ndim != 3 or u.shape[0] == 0 or u.shape[2] == 0:
        raise ValueError(f"U: expected candidate Jacobians (n, m, P) or (n, P), got {np.shape(U)}")
    if not np.all(np.isfinite(u)):
        bad = np.flatnonzero(~np.all(np.isfinite(u.reshape(u.shape[0], -1)), axis=1))
        raise ValueError(f"U: NaN or inf in candidate(s) {bad[:10].tolist()}")
    P = u.shape[2]
    p = np.asarray(prior, np.float64)
    if p.shape != (P,) or not np.all(np.isfinite(p)) or np.any(p <= 0):
        raise ValueError(f"prior: expected ({P},) finite prior informations 1/sigma^2 > 0, "
                         f"got shape {p.shape}")
    ell = np.eye(P) if L is None else np.asarray(L, np.float64)
    if ell.ndim != 2 or ell.shape[0] != P or ell.shape[1] == 0 or not np.all(np.isfinite(ell)):
        raise ValueError(f"L: expected a finite task factor ({P}, r >= 1), got {ell.shape}")
    return u, p, ell


def _logdet_pd(M: np.ndarray) -> float:
    sign, v = np.linalg.slogdet(M)
    if sign <= 0:
        raise np.linalg.LinAlgError("matrix is not positive definite")
    return float(v)


def criterion(U: Any, prior: Any, L: Any | None, indices: Iterable[int]) -> float:
    """c(S) = -log det(L^T A(S)^{-1} L) computed directly (reference; see module
    docstring); ``indices`` may repeat."""
    u, p, ell = _check_inputs(U, prior, L)
    idx = np.asarray(list(indices), np.int64)
    R = u[idx].reshape(-1, u.shape[2])
    A = np.diag(p) + R.T @ R
    return -_logdet_pd(ell.T @ np.linalg.solve(A, ell))


class _State:
    """A design with its information A, C = A^{-1} and the task's K^{-1}."""

    def __init__(self, u: np.ndarray, prior: np.ndarray, ell: np.ndarray, refresh: int):
        self.u, self.ell, self.refresh = u, ell, refresh
        self.m = u.shape[1]
        #: the task factor is square and regular (no task, or a full-rank one)
        self.full = ell.shape[1] == ell.shape[0]
        self.A = np.diag(prior)
        self.C = np.diag(1.0 / prior)
        self.count = np.zeros(u.shape[0], np.int64)
        self.updates = 0
        self._task()

    def copy(self) -> _State:
        s = object.__new__(_State)
        s.__dict__.update(self.__dict__)
        s.A, s.C, s.count = self.A.copy(), self.C.copy(), self.count.copy()
        return s

    def _task(self) -> None:
        """log det K, and the factors Rc (C = Rc Rc^T) and M = C L chol(K^{-1}) that turn
        the candidates' U C U^T and G K^{-1} G^T into row norms of U Rc and U M."""
        C = self.C
        K = self.ell.T @ C @ self.ell
        K = 0.5 * (K + K.T)
        cho = np.linalg.cholesky(K)
        self.logdetK = 2.0 * float(np.sum(np.log(np.diag(cho))))
        inv = np.linalg.inv(cho)                     # K^{-1} = inv^T inv
        self.M = C @ self.ell @ inv.T
        self.Rc = np.linalg.cholesky(C)

    @property
    def value(self) -> float:
        return -self.logdetK

    def deltas(self, idx: np.ndarray, eps: int) -> np.ndarray:
        """Change of c = -log det K when adding (eps 1) / removing (eps -1) each of the
        candidates ``idx`` alone (a numerically failed evaluation: -inf for an addition,
        +inf for a removal, so that it is never chosen)."""
        m = self.m
        Ui = self.u[idx].reshape(-1, self.u.shape[2])               # (k*m, P)
        Z1 = Ui @ self.Rc                                          # U C U^T = Z1 Z1^T
        if self.full:   # L invertible: G K^-1 G^T = U C U^T, the change is -log det S
            if m == 1:
                with np.errstate(invalid="ignore", divide="ignore"):
                    d = -np.log(1.0 + eps * np.einsum("kp,kp->k", Z1, Z1))
            else:
                Z1 = Z1.reshape(len(idx), m, -1)
                sg, ld = np.linalg.slogdet(np.eye(m) + eps * (Z1 @ Z1.transpose(0, 2, 1)))
                d = np.where(sg > 0, -ld, np.nan)
            return -np.where(np.isfinite(d), d, np.inf if eps < 0 else -np.inf)
        Z2 = Ui @ self.M                                           # G K^-1 G^T = Z2 Z2^T
        if m == 1:
            s = 1.0 + eps * np.einsum("kp,kp->k", Z1, Z1)
            h = np.einsum("kr,kr->k", Z2, Z2)
            with np.errstate(invalid="ignore", divide="ignore"):
                d = np.log(s - eps * h) - np.log(s)
        else:
            Z1 = Z1.reshape(len(idx), m, -1)
            Z2 = Z2.reshape(len(idx), m, -1)
            S = np.eye(m) + eps * (Z1 @ Z1.transpose(0, 2, 1))
            H = Z2 @ Z2.transpose(0, 2, 1)
            s1, l1 = np.linalg.slogdet(S - eps * H)
            s0, l0 = np.linalg.slogdet(S)
            d = np.where((s1 > 0) & (s0 > 0), l1 - l0, np.nan)
        return -np.where(np.isfinite(d), d, np.inf if eps < 0 else -np.inf)

    def apply(self, i: int, eps: int) -> None:
        Ui = self.u[i]                                             # (m, P)
        self.A += eps * (Ui.T @ Ui)
        self.count[i] += eps
        self.updates += 1
        if self.updates % self.refresh == 0:
            self.C = np.linalg.inv(self.A)
        else:
            CU = self.C @ Ui.T                                     # (P, m)
            S = np.eye(self.m) + eps * (Ui @ CU)
            self.C = self.C - eps * CU @ np.linalg.solve(S, CU.T)
        self.C = 0.5 * (self.C + self.C.T)
        self._task()

    def selected(self) -> np.ndarray:
        return np.flatnonzero(self.count > 0)


def _add_best(st: _State, free: np.ndarray | None = None) -> int:
    cand = np.flatnonzero(st.count == 0) if free is None else free
    d = st.deltas(cand, +1)
    i = int(cand[int(np.argmax(d))])
    st.apply(i, +1)
    return i


def _remove_worst(st: _State) -> int:
    sel = st.selected()
    d = st.deltas(sel, -1)
    i = int(sel[int(np.argmax(d))])
    st.apply(i, -1)
    return i


def greedy(U: Any, prior: Any, L: Any | None, n: int, *, refresh: int = 32,
           progress: Callable[[int, int], Any] | None = None) -> DesignResult:
    """Greedy selection of ``n`` candidates (module docstring); U (n_c, m, P) whitened
    candidate Jacobians, prior (P,) = 1/sigma^2, L (P, r) task factor (None: D-optimal)."""
    return select(U, prior, L, DesignOptions(n=n, method="greedy", refresh=refresh),
                  progress=progress)


def detmax(U: Any, prior: Any, L: Any | None, n: int, **options: Any) -> DesignResult:
    """DETMAX selection of ``n`` candidates (module docstring); options: the fields of
    :class:`DesignOptions`."""
    return select(U, prior, L, DesignOptions(n=n, method="detmax", **options))


def select(U: Any, prior: Any, L: Any | None, options: DesignOptions,
           progress: Callable[[int, int], Any] | None = None) -> DesignResult:
    """Select ``options.n`` of the candidates U (n_c, m, P) (whitened Jacobians) with
    prior information ``prior`` (P,) and task factor ``L`` (P, r) (None: plain D-optimality).

    ``progress(done, total)`` is called after every greedy step and detmax excursion.
    """
    t0 = time.perf_counter()
    if not isinstance(options, DesignOptions):
        raise TypeError(f"options: expected a DesignOptions, got {type(options).__name__}")
    options.validate()
    u, p, ell = _check_inputs(U, prior, L)
    n_c = u.shape[0]
    if options.n > n_c:
        raise ValueError(f"n: {options.n} configurations asked from a pool of {n_c} candidates")
    st = _State(u, p, ell, options.refresh)
    c0 = st.value
    history: list[float] = []
    order: list[int] = []
    if options.method == "greedy" or options.start == "greedy":
        for k in range(options.n):
            order.append(_add_best(st))
            history.append(st.value)
            if progress is not None:
                progress(k + 1, options.n)
    else:
        rng = np.random.default_rng(options.seed)
        for i in rng.choice(n_c, options.n, replace=False):
            st.apply(int(i), +1)
        history.append(st.value)
    iterations = 0
    if options.method == "detmax":
        k_max = min(options.max_excursion, n_c - options.n) if n_c > options.n else 0
        k = 1
        while k <= k_max and iterations < options.iterations:
            trial = st.copy()
            for _ in range(k):
                _add_best(trial)
            for _ in range(k):
                _remove_worst(trial)
            trial.C = np.linalg.inv(trial.A)     # exact before comparing
            trial._task()
            if trial.value > st.value + options.tol:
                st = trial
                iterations += 1
                history.append(st.value)
                k = 1
                if progress is not None:
                    progress(iterations, 0)
            else:
                k += 1
        order = [i for i in order if st.count[i] > 0] + \
            [int(i) for i in st.selected() if i not in set(order)]
    st.C = np.linalg.inv(st.A)
    st._task()
    return DesignResult(indices=np.array(order, np.int64), criterion=st.value, history=history,
                        prior_criterion=c0, method=options.method, iterations=iterations,
                        rank=ell.shape[1], n_candidates=n_c, time_s=time.perf_counter() - t0)


# ------------------------------------------------------------ measurements
def candidate_jacobians(robot: RobotModel, measurement: Measurement, q: ArrayLike, free: str | Iterable[str], *,
                        meta: Mapping[str, Any] | None = None, chunk: int = 4096,
                        **problem: Any) -> tuple[np.ndarray, ParameterSpace]:
    """Whitened Jacobians (n, m, P) of ``measurement`` at the candidate configurations q
    (n, n_dof) at the nominal parameters, evaluated in batches of ``chunk`` candidates
    (one :class:`CalibrationProblem` each: the Warp kernels run once per batch), and the
    parameter space (its ``sigma`` gives the prior).

    Args:
        robot: the RobotModel (a name is resolved by the caller, e.g. :func:`design`).
        free: robot groups and the measurement's own groups.
        meta: the measurement's per-sample columns of the candidates.
        problem: further CalibrationProblem arguments (noise_sigma, sigma, frames, ...).
    """
    from jwarp.calibration.design.sensitivity import stacked_jacobian

    if not isinstance(robot, RobotModel):   # resolved where it entered (jwarp.robot)
        raise TypeError(f"robot: expected a RobotModel (jwarp.robot(name) resolves a name), "
                        f"got {type(robot).__name__}")
    model = robot
    qa = np.asarray(q, np.float64)
    if qa.ndim != 2 or qa.shape[1] != model.n_dof or qa.shape[0] == 0:
        raise ValueError(f"q: expected candidate configurations (n >= 1, {model.n_dof}) for "
                         f"robot '{model.name}', got {qa.shape}")
    check_int(chunk, "chunk", 1)
    m = len(measurement.obs_names)
    space_args = {k: problem[k] for k in ("sigma", "frames", "p_nominal", "bound_kappa")
                  if k in problem}
    space = ParameterSpace.build(model, measurement, free, **space_args)
    out = np.empty((qa.shape[0], m, space.size))
    for a in range(0, qa.shape[0], chunk):
        b = min(a + chunk, qa.shape[0])
        mm = None if meta is None else {k: np.asarray(v)[a:b] for k, v in meta.items()}
        J, _ = stacked_jacobian(model, measurement, qa[a:b], free, meta=mm, whiten=True,
                                **problem)
        out[a:b] = J.reshape(b - a, m, space.size)
    return out, space


def task_information(robot: RobotModel, task: Any, q_task: Any, names: list[str],
                     free: str | Iterable[str], *, meta: Mapping[str, Any] | None = None,
                     rank_rtol: float = 1e-10, **problem: Any) -> tuple[np.ndarray, list[str]]:
    """The task factor ``L`` (P, r) on the parameters ``names`` (the actual measurement's
    space) from the task measurement at q_task, and the task parameters left out (not in
    ``names``: the design cannot calibrate them). Robot groups of ``free`` only.
    ``robot``: the RobotModel (:func:`stacked_jacobian`'s)."""
    from jwarp.calibration.design.sensitivity import align, stacked_jacobian
    from jwarp.calibration.estimate.params import ROBOT_GROUPS

    groups = [g for g in parse_groups(free) if g in ROBOT_GROUPS]
    if not groups:
        raise ValueError(f"free: no robot group in {parse_groups(free)}; the task needs one")
    problem = {k: v for k, v in problem.items() if k not in ("noise_sigma", "p_nominal")}
    Jt, nt = stacked_jacobian(robot, task, q_task, groups, meta=meta, **problem)
    kept = [n for n in nt if n in names]
    dropped = [n for n in nt if n not in names]
    cols = [nt.index(n) for n in kept]
    Jt = align(Jt[:, cols], kept, names)
    return task_factor(Jt, rank_rtol), dropped


def prior_information(space: ParameterSpace) -> np.ndarray:
    """(P,) 1/sigma^2 of the free parameters; a parameter without prior is an error."""
    bad = [n for n, s in zip(space.names, space.sigma) if not np.isfinite(s)]
    if bad:
        raise ValueError(f"sigma: the design needs a finite prior for every free parameter "
                         f"(eq. 2.26); none for {bad[:5]}")
    return 1.0 / space.sigma ** 2


@limit_blas  # small dense problems (JWARP_BLAS_THREADS)
def design(robot: RobotLike, actual: Any, q_pool: Any, options: DesignOptions, *,
           free: str | Iterable[str], meta_pool: Mapping[str, Any] | None = None,
           task: Any = None, q_task: Any = None, meta_task: Mapping[str, Any] | None = None,
           progress: Callable[[int, int], Any] | None = None, **problem: Any) -> DesignResult:
    """Task D-optimal selection of ``options.n`` configurations from a pool.

    Args:
        robot: robot name or RobotModel (the nominal model: the truth is not known yet).
        actual: the measurement to be made; q_pool (n_c, n_dof) candidates and their
            per-sample columns ``meta_pool`` (e.g. contact pairs).
        options: :class:`DesignOptions`.
        free: groups to be calibrated (robot groups + the actual measurement's groups).
        task, q_task, meta_task: the task measurement and its configurations (eq. 2.25);
            None: plain D-optimality on all free parameters.
        problem: further CalibrationProblem arguments (noise_sigma, sigma, frames, ...).

    Returns:
        :class:`DesignResult` (``notes``: task parameters the actual space lacks).
    """
    if not isinstance(options, DesignOptions):
        raise TypeError(f"options: expected a DesignOptions, got {type(options).__name__}")
    options.validate()
    model = get_robot(robot)   # resolved once here; the Jacobians take the model
    U, space = candidate_jacobians(model, actual, q_pool, free, meta=meta_pool, **problem)
    prior = prior_information(space)
    dropped: list[Any]
    L, dropped = None, []
    if task is not None:
        if q_task is None:
            raise ValueError("q_task: the task measurement needs its configurations")
        L, dropped = task_information(model, task, q_task, list(space.names), free,
                                      meta=meta_task, rank_rtol=options.rank_rtol, **problem)
    res = select(U, prior, L, options, progress=progress)
    if dropped:
        res.notes["task_parameters_not_in_actual"] = dropped
    return res
