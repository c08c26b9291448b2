"""MAP calibration (thesis eq. 2.5, paper sec. IV-B): whitened least squares with a prior.

The residual vector of :class:`CalibrationProblem` is

    r(x) = [ (h(q_n, x) - y_n) / sigma_noise  for every sample n and observation;
             (x - x_prior) / sigma_prior      for every free parameter with a prior ]

with ``h`` the measurement applied to the (elastic) forward kinematics: the frames are those
of the torque equilibrium ``rho* = rho0 + kappa tau(F(q, rho*))`` (float64, CPU) when a
compliance is free or nonzero, else the rigid FK. The torques ``tau`` use the point masses
of ``x`` when the ``mass`` group is free (the device tables are shared, only the per-frame
mass arrays are replaced). Its Jacobian is analytic: the measurement's frame twists chained
with :func:`jwarp.jacobian_dh` at rho*, and through the equilibrium by the implicit
function theorem (:mod:`.elastic`).

:func:`calibrate` (:func:`calibrate_with` given :class:`CalibrationOptions`) minimizes
``|r|^2 / 2`` with :func:`scipy.optimize.least_squares`
(``dogbox``: trf stalls on the flat directions of this problem) from the measurement's
robust initial guess, optionally from more starts drawn from the prior, and returns a
:class:`~jwarp.calibration.estimate.result.CalibrationResult`. Each start runs
:func:`solve_start`: compliances kept >= 0 by an active set around unbounded runs (the
calibrated robot cannot hold a negative one), a run stopped when its cost stalls, and the
lowest-cost feasible point returned, never one above the start (see
docs/calibration_robustness.md).
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any, NamedTuple, cast

import numpy as np
import warp as wp
from scipy.optimize import OptimizeResult, least_squares

from jwarp import kinematics as K
from jwarp.calibration.estimate.backlash import check_directions, motion_directions
from jwarp.calibration.estimate.elastic import (
    ElasticComponents,
    effective_kappa,
    equilibrium_jacobian,
    frame_masses,
    mass_torque_jacobian,
    nonlinear_b,
    torque_jacobian,
    torque_state,
)
from jwarp.calibration.estimate.options import CalibrationOptions
from jwarp.calibration.estimate.origin import origin_twists, with_static_transforms
from jwarp.calibration.estimate.params import (
    COUPLING_HARM,
    KIND_BACKLASH,
    KIND_COUPLING,
    KIND_DH,
    KIND_HARMONIC,
    KIND_KAPPA,
    KIND_KAPPA_NL,
    KIND_MASS,
    KIND_MEAS,
    KIND_ORIGIN,
    MASS_GROUP,
    ParameterSpace,
    parse_groups,
    robot_backlash,
    with_pose_groups,
)
from jwarp.calibration.estimate.result import CalibrationResult, build_result
from jwarp.calibration.estimate.robust import LOSSES, robust_weights
from jwarp.calibration.estimate.samples import check_samples
from jwarp.core.arrays import finite_as, init_warp, resolve_device
from jwarp.core.device import put_model, with_frame_masses, with_kappa_nonlinear
from jwarp.core.threads import limit_blas
from jwarp.core.types import ArrayLike, DeviceLike, RobotLike
from jwarp.model import RobotModel
from jwarp.plugins.registry import robot as get_robot

if TYPE_CHECKING:
    from jwarp.model.measurement import Measurement

#: the largest robust-loss scale in noise sigmas (beyond it the loss is linear on any data,
#: and its square overflows near 1e154)
MAX_LOSS_SIGMAS = 1e6


class ModelState(NamedTuple):
    """The model at one x (:meth:`CalibrationProblem.state`).

    frames (S, n, 4, 4) world frames; rho (S, n, 5) equilibrium DH rows (rho0 when rigid);
    dh (n, 5) geometric rows rho0; kappa (n, 3) [rad/(N m)]; p (P_meas,) measurement
    parameters; converged (S,) bool; masses (len(robot.masses),) point masses [kg].
    """

    frames: np.ndarray
    rho: np.ndarray
    dh: np.ndarray
    kappa: np.ndarray
    p: np.ndarray
    converged: np.ndarray
    masses: np.ndarray


class Progress(NamedTuple):
    """Passed to the ``callback`` of :func:`calibrate` after every solver iteration."""

    start: int        # 0-based index of the current start
    n_starts: int
    iteration: int    # 1-based iteration of this start
    cost: float       # 0.5 |r|^2 of the whitened problem


def signed_equilibrium(robot: RobotModel, q: np.ndarray, dh: np.ndarray, kappa: np.ndarray,
                       lam: float, max_iter: int, tol: float,
                       masses: tuple[np.ndarray, np.ndarray] | None = None,
                       kappa_nl: np.ndarray | None = None, device: DeviceLike = None
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Elastic FK (float64) as :func:`jwarp.fk_elastic`, but accepting compliances of
    either sign: the optimizer may cross kappa = 0 on its way (the fixed point is just as
    well defined; only the final model must be physical). q (S, n_dof) (numpy, or a
    float64 Warp array on ``device``, used as is: no upload), dh (n, 5), kappa (n, 3),
    optional mass model ``masses`` = (per-frame mass (n,) [kg], centre of mass (n, 3) [m],
    see :func:`.elastic.frame_masses`) replacing the robot's, optional nonlinear joint
    compliances ``kappa_nl`` (n,) [rad/(N m)^3] replacing the robot's -> numpy frames
    (S, n, 4, 4), rho* (S, n, 5), converged (S,). ``q`` are the joint values the links
    see (transmission errors already applied). ``device``: where the kernels run (None: the
    one device rule, :func:`~jwarp.core.arrays.resolve_device`)."""
    m = put_model(robot, resolve_device(device, like=q), np.float64)
    if masses is not None:
        m = with_frame_masses(m, *masses)
    if kappa_nl is not None:
        m = with_kappa_nonlinear(m, kappa_nl)
    eq = K.solve_equilibrium(m, q, dh, kappa, lam=lam, max_iter=max_iter, tol=tol,
                             validate=False)
    return eq.frames, eq.rho, eq.converged


def _whitener(covariance: Any, S: int, m: int) -> np.ndarray | None:
    """(S, m, m) inverse Cholesky factors ``L_s^-1`` of a per-sample covariance
    ``Lambda_s = L_s L_s^T`` (S, m, m) or one (m, m) for every sample [unit^2]; None -> None.
    Raises ValueError naming ``covariance`` (and the first bad sample)."""
    if covariance is None:
        return None
    try:
        c = np.asarray(covariance, np.float64)
    except (TypeError, ValueError):
        raise TypeError(f"covariance: expected an array (S, m, m), got {type(covariance).__name__}") from None
    if c.shape == (m, m):
        c = np.broadcast_to(c, (S, m, m))
    if c.shape != (S, m, m):
        raise ValueError(f"covariance: expected shape ({S}, {m}, {m}) (one m x m block per "
                         f"sample) or ({m}, {m}), got {c.shape}")
    bad = ~np.all(np.isfinite(c), axis=(1, 2))
    if bad.any():
        raise ValueError(f"covariance: NaN or inf in sample {int(np.flatnonzero(bad)[0])}")
    asym = np.abs(c - np.swapaxes(c, 1, 2)).max(axis=(1, 2)) > 1e-9 * np.abs(c).max(axis=(1, 2))
    if asym.any():
        raise ValueError(f"covariance: block of sample {int(np.flatnonzero(asym)[0])} is not "
                         f"symmetric")
    try:
        L = np.linalg.cholesky(c)
    except np.linalg.LinAlgError:
        ev = np.linalg.eigvalsh(c).min(axis=1)
        raise ValueError(f"covariance: block of sample {int(np.argmin(ev))} is not positive "
                         f"definite (smallest eigenvalue {ev.min():.3g})") from None
    eye = np.broadcast_to(np.eye(m), (S, m, m))
    return np.linalg.solve(L, eye)   # L^-1, lower triangular


def _noise(measurement: Measurement, noise_sigma: Any) -> np.ndarray:
    m = len(measurement.obs_names)
    v = getattr(measurement, "noise", None) if noise_sigma is None else noise_sigma
    if v is None:
        raise ValueError("noise_sigma: not given and the measurement has no 'noise'")
    try:
        a = np.asarray(v, np.float64)
    except (TypeError, ValueError):
        raise TypeError(f"noise_sigma: expected a number or {m} numbers, got {v!r}") from None
    if a.ndim == 0:
        a = np.full(m, float(a))
    if a.shape != (m,) or not np.all(np.isfinite(a)) or np.any(a <= 0):
        raise ValueError(f"noise_sigma: expected a finite number > 0 or {m} of them "
                         f"(one per observation), got {v!r}")
    return a


def _problem_groups(measurement: Measurement, o: CalibrationOptions) -> tuple[list[str], Any]:
    """(the free groups, the measurement's prior means) of the problem of ``o``: ``free``
    with the pose groups when ``free_poses`` (less ``fix`` and the ``fix_at`` groups, whose
    values replace ``p_nominal``)."""
    p_nominal = o.p_nominal
    fix = o.fix
    if o.fix_at:
        from jwarp.calibration.estimate.result import fixed_params

        p_nominal = fixed_params(measurement, o.fix_at, p_nominal)
        named = [] if fix is None or (isinstance(fix, str) and not fix.strip()) \
            else parse_groups(fix)
        fix = named + [g for g in o.fix_at if g not in named]
    if o.free_poses:
        free = with_pose_groups(measurement, o.free, fix)
    else:
        free = [g for g in parse_groups(o.free) if g not in (o.fix_at or {})]
    return free, p_nominal


#: the keywords :class:`CalibrationProblem` took before ``options`` (issue 40; deprecated,
#: for one release) and the :class:`CalibrationOptions` field each sets
PROBLEM_KEYWORDS = {
    "free": "free", "noise_sigma": "noise_sigma", "sigma": "sigma", "frames": "frames",
    "p_nominal": "p_nominal", "elastic": "elastic", "lam": "lam",
    "max_iter": "equilibrium_iterations", "tol": "tol", "bound_kappa": "bound_kappa",
    "covariance": "covariance", "orders": "orders", "loss": "loss",
    "loss_scale": "loss_scale", "directions": "directions",
}


def problem_options(**keywords: Any) -> CalibrationOptions:
    """The :class:`CalibrationOptions` of the problem that :class:`CalibrationProblem`'s
    former keywords (:data:`PROBLEM_KEYWORDS`: ``free``, ``noise_sigma``, ``sigma``, ...,
    ``max_iter``) described: exactly the groups ``free`` (``free_poses=False``) and, unless
    ``bound_kappa`` is given, compliances unbounded (``bound_kappa=False``, the problem's
    default then). TypeError naming an unknown keyword or a missing ``free``."""
    unknown = sorted(set(keywords) - set(PROBLEM_KEYWORDS))
    if unknown:
        raise TypeError(f"CalibrationProblem: unexpected keyword {unknown[0]!r} (the problem's "
                        f"settings are the fields of options=CalibrationOptions(...))")
    if "free" not in keywords:
        raise TypeError("CalibrationProblem: missing options=CalibrationOptions(free=...)")
    fields = {PROBLEM_KEYWORDS[k]: v for k, v in keywords.items()}
    fields.setdefault("bound_kappa", False)
    return CalibrationOptions(free_poses=False, **fields)


class CalibrationProblem:
    """The whitened MAP least-squares problem of one data set.

    Args:
        robot: nominal robot (name or RobotModel); its DH rows and kappa are the prior means.
        measurement: a measurement plugin instance (see jwarp.model.measurement).
        q: (S, n_dof) joint values [rad, m]; y: (S, m) observations [measurement.unit].
        options: :class:`CalibrationOptions`; the problem's fields of it:

            * ``free`` (with the measurement's pose and marker groups when ``free_poses``,
              less ``fix`` and ``fix_at``: :func:`~.params.with_pose_groups`), see
              :class:`ParameterSpace`; ``fix_at`` also replaces the groups' prior means;
            * ``noise_sigma``: measurement noise std, scalar or (m,) [unit]; None:
              ``measurement.noise``;
            * ``sigma``: prior sigma overrides {group: value} (``mass``: relative to each
              nominal mass, 0.1 = 10 %); ``frames``: calibratable DH frames; ``p_nominal``:
              measurement parameter prior means (None: ParamBlock nominal);
            * ``elastic``: True/False; None: elastic iff a compliance is free or nonzero (a
              free ``mass`` group needs the elastic model: masses act only through its
              torques); ``lam``, ``equilibrium_iterations``, ``tol``: damping, most updates
              and tolerance [rad] of the equilibrium;
            * ``bound_kappa``: constrain compliances to >= 0 in the solver (see
              ParameterSpace.build);
            * ``covariance``: per-sample measurement covariance (S, m, m) with full blocks
              (or one (m, m) for all samples) [unit^2], e.g. with task-oriented weighting or
              virtual noise (:mod:`.tow`, :mod:`.virtual_noise`); the data residuals and their
              Jacobian are whitened by ``L_s^-1`` (``Lambda_s = L_s L_s^T``, Cholesky)
              instead of ``1 / noise_sigma``, which it replaces. None: the diagonal
              ``noise_sigma``;
            * ``orders``: harmonic orders of the ``harmonic`` and ``coupling`` groups, per
              group or per joint/frame pattern (see :meth:`ParameterSpace.build`);
            * ``loss``: "linear" (least squares), "soft_l1" or "huber": a robust loss on
              each sample's whitened residual norm (:mod:`.robust`); the prior rows stay
              Gaussian. ``loss_scale``: where it turns robust [unit of the measurement]
              (divided by the mean noise sigma into whitened units);
            * ``directions``: (S, n_dof) the direction (+1, -1, 0 unknown) each joint last
              moved in before each sample, for the ``backlash`` group and a robot with
              recorded backlash; None: from the order of q (:func:`.backlash.motion_directions`).

            The solver's fields (starts, tolerances, callback, ...) are
            :func:`calibrate_with`'s. Not validated here (:meth:`CalibrationOptions.validate`
            is); the problem checks what it uses.
        meta: per-sample inputs {name: (S,)} the measurement needs (``meta_names``).
        device: Warp device of the FK, equilibrium and DH-Jacobian kernels (float64;
            None: Warp's default device, docs/api.md "Devices"; "cpu" for small problems on
            a CUDA machine, "cuda:0" for large batches such as the candidate Jacobians of
            :func:`.design.candidate_jacobians`); the rest of the problem is numpy.
        keywords: the former keywords (:data:`PROBLEM_KEYWORDS`: ``free=``, ``sigma=``,
            ..., ``max_iter=``), deprecated: they work for one release with a
            DeprecationWarning, as ``options=problem_options(**keywords)`` (exactly
            ``free``, compliances unbounded unless ``bound_kappa``).
    """

    def __init__(self, robot: RobotLike, measurement: Measurement, q: ArrayLike, y: Any,
                 options: CalibrationOptions | None = None, *,
                 meta: Mapping[str, Any] | None = None, device: DeviceLike = None,
                 **keywords: Any) -> None:
        if keywords:
            if options is not None:
                raise TypeError(f"CalibrationProblem: got options and the keywords "
                                f"{', '.join(sorted(keywords))}; give the settings in options")
            o = problem_options(**keywords)
            warnings.warn(f"CalibrationProblem: the keywords {', '.join(sorted(keywords))} are "
                          f"deprecated and removed in the next release: pass "
                          f"options=CalibrationOptions(...) (problem_options() gives the "
                          f"same problem)", DeprecationWarning, stacklevel=2)
        elif options is None:
            raise TypeError("CalibrationProblem: missing options=CalibrationOptions(free=...)")
        elif not isinstance(options, CalibrationOptions):
            raise TypeError(f"options: expected CalibrationOptions, got "
                            f"{type(options).__name__}")
        else:
            o = options
        self.robot = get_robot(robot)
        self.measurement = measurement
        if not hasattr(measurement, "jacobians") or not hasattr(measurement, "obs_names"):
            raise TypeError(f"measurement: expected a measurement plugin instance, got "
                            f"{type(measurement).__name__}")
        if getattr(measurement, "robot", self.robot) is not self.robot:
            mr = measurement.robot
            if mr.n_frames != self.robot.n_frames or mr.frame_names != self.robot.frame_names:
                raise ValueError(f"measurement: built for robot '{mr.name}', not '{self.robot.name}'")
        self.q, self.y, self.meta = check_samples(self.robot, measurement, q, y, meta)
        init_warp()
        #: the Warp device of the model and Jacobian kernels (None: Warp's default device;
        #: "cuda:0" for large batches, e.g. the candidate Jacobians of an experimental design)
        self.device = resolve_device(device)
        #: the joint values on ``device`` (float64), uploaded once: every evaluation of
        #: the model and its Jacobian launches on this array (the data do not change)
        self.q_device: wp.array = wp.array(np.ascontiguousarray(self.q, np.float64),
                                           dtype=wp.float64, device=self.device)
        free, p_nominal = _problem_groups(measurement, o)
        elastic, loss, loss_scale, lam = o.elastic, o.loss, o.loss_scale, o.lam
        if elastic is False and MASS_GROUP in parse_groups(free):
            raise ValueError(f"free: the '{MASS_GROUP}' group acts only through the elastic "
                             f"model, but elastic=False was given")
        self.space = ParameterSpace.build(self.robot, measurement, free, sigma=o.sigma,
                                          frames=o.frames, p_nominal=p_nominal,
                                          bound_kappa=o.bound_kappa, orders=o.orders)
        self.noise = _noise(measurement, o.noise_sigma)
        if loss not in LOSSES:
            raise ValueError(f"loss: expected one of {', '.join(LOSSES)}, got {loss!r}")
        self.loss = loss
        #: the robust loss's scale in whitened units (None for the linear loss)
        self.loss_f: float | None = None
        if loss != "linear":
            if loss_scale is None or isinstance(loss_scale, bool) or not (
                    isinstance(loss_scale, (int, float, np.floating)) and
                    np.isfinite(loss_scale) and loss_scale > 0):
                raise ValueError(f"loss_scale: expected a finite number > 0 [unit of the "
                                 f"measurement] with loss={loss!r}, got {loss_scale!r}")
            self.loss_f = float(loss_scale) / float(np.mean(self.noise))
            if not self.loss_f <= MAX_LOSS_SIGMAS:  # its square overflows long before inf
                raise ValueError(f"loss_scale: {self.loss_f:.3g} times the mean noise sigma; at "
                                 f"most {MAX_LOSS_SIGMAS:g} times (the loss would be linear "
                                 f"wherever data are: use the linear loss)")
        S, m = self.y.shape
        #: (S, m, m) inverse Cholesky factors of ``covariance`` (None: diagonal noise)
        self.whitener = _whitener(o.covariance, S, m)
        P = self.space.size
        if S * m < P:
            raise ValueError(f"q, y: {S} samples x {m} observations = {S * m} values is fewer "
                             f"than the {P} free parameters of groups {self.space.free_groups}; "
                             f"give more samples or free fewer groups")
        if not (isinstance(lam, (int, float)) and 0 < lam <= 1):
            raise ValueError(f"lam: damping must be in (0, 1], got {lam!r}")
        self.lam, self.max_iter, self.tol = float(lam), int(o.equilibrium_iterations), float(o.tol)
        kf = self.space.kappa_free
        sp = self.space
        self._harm_idx = np.nonzero(sp.kind == KIND_HARMONIC)[0]
        self._bl_idx = np.nonzero(sp.kind == KIND_BACKLASH)[0]
        #: backlash in play (the group free or recorded in the robot) and the directions
        self.backlash = bool(self._bl_idx.size or np.any(robot_backlash(self.robot)))
        self.directions = (None if not self.backlash else motion_directions(self.q)
                           if o.directions is None else
                           check_directions(o.directions, *self.q.shape))
        self._knl_idx = np.nonzero(sp.kind == KIND_KAPPA_NL)[0]
        if elastic is None:
            elastic = bool(kf.any() or np.any(self.robot.kappa != 0) or self._knl_idx.size
                           or np.any(self.robot.kappa_nonlinear))
        self.elastic = bool(elastic)
        self._org_idx = np.nonzero(sp.kind == KIND_ORIGIN)[0]
        self._cpl_idx = np.nonzero(sp.kind == KIND_COUPLING)[0]
        #: whether the coupled frames get per-sample rows (``coupling`` group free, or
        #: the robot has ``coupling_harmonic``)
        self.coupled = bool(self._cpl_idx.size or self.robot.has_coupling_harmonic)
        self._kin_cache: tuple[bytes, RobotModel] | None = None
        self._kin_data: Any = None   # KinematicsData of the samples (:meth:`kinematics`)
        #: the raw joint values and whether the links see other ones (transmission errors)
        self.q_device_raw = self.q_device
        self.transmission = bool(self._harm_idx.size or self.robot.has_harmonic
                                 or self.backlash)
        #: the robot the kinematics launches see: transmission errors are applied here
        #: (``q_device``), not again by the public kinematics functions; the coupled frames'
        #: harmonic terms go into the per-sample rows (:meth:`coupled_rows`), not the kernels
        self.kin_robot = K.without_coupling_harmonic(K.without_transmission(self.robot))
        self._dh_idx = np.nonzero(sp.kind == KIND_DH)[0]
        self._kap_idx = np.nonzero(sp.kind == KIND_KAPPA)[0]
        self._meas_idx = np.nonzero(sp.kind == KIND_MEAS)[0]
        self._mass_idx = np.nonzero(sp.kind == KIND_MASS)[0]
        self._prior_idx = np.nonzero(sp.has_prior)[0]
        self._cache: tuple[bytes, Any] | None = None
        self.n_data = S * m
        self.n_evaluations = 0

    @classmethod
    def from_options(cls, robot: RobotLike, measurement: Measurement, q: ArrayLike, y: Any,
                     options: CalibrationOptions, meta: Mapping[str, Any] | None = None
                     ) -> CalibrationProblem:
        """``CalibrationProblem(robot, measurement, q, y, options, meta=meta)`` (kept for
        the callers of before issue 40)."""
        return cls(robot, measurement, q, y, options, meta=meta)

    # ------------------------------------------------------------------ sizes
    @property
    def n_samples(self) -> int:
        return self.y.shape[0]

    @property
    def n_residuals(self) -> int:
        return self.n_data + self._prior_idx.size

    # ------------------------------------------------------------- forward
    def state(self, x: np.ndarray) -> ModelState:
        """Model at x (:class:`ModelState`). Cached for the last x."""
        x = self.space.check(x)
        key = x.tobytes()
        if self._cache is not None and self._cache[0] == key:
            return self._cache[1]
        dh, kap, p, mass = self.space.unpack(x)
        S = self.n_samples
        if self.transmission:   # the links see q + dq(q): every launch below uses it
            q_eff = self.q_links(x)
            self.q_device = wp.array(q_eff, dtype=wp.float64, device=self.device)
        rows = self.coupled_rows(x, dh) if self.coupled else dh
        if self.elastic:
            fm = frame_masses(self.robot, mass) if self._mass_idx.size else None
            knl = self.space.kappa_nonlinear_at(x) if self._knl_idx.size else None
            eq_robot = self.kin_robot_at(x)   # without coupling_harmonic: in the rows
            frames, rho, conv = signed_equilibrium(eq_robot, self.q_device, rows, kap,
                                                   self.lam, self.max_iter, self.tol, masses=fm,
                                                   kappa_nl=knl, device=self.device)
        else:
            m, d = self.kinematics(self.kin_robot_at(x))
            frames = K.forward_kinematics(m, d, self.q_device, dh=rows,
                                          validate=False).numpy().copy()
            rho = np.broadcast_to(rows, (S,) + dh.shape)
            conv = np.ones(S, bool)
        out = ModelState(frames, rho, dh, kap, p, conv, mass)
        self._cache = (key, out)
        self.n_evaluations += 1
        return out

    def q_links(self, x: ArrayLike) -> np.ndarray:
        """(S, n_dof) the joint values the links see at x (transmission errors applied)."""
        if not self.transmission:
            return self.q
        out = self.robot.joint_transmission(self.q, self.space.harmonic_at(x))
        if self.directions is not None:   # backlash, direction-dependent: q'_j += b_j s_j
            out = out + self.directions * self.space.backlash_at(x)
        return out

    def coupling_terms(self, x: ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(coupling matrix C (n, n_dof), offsets (n,), harmonics h (n, K, 2), coupled
        angles u = q C^T (S, n)) at x (the robot's where the ``coupling`` group is not free)."""
        if self._cpl_idx.size:
            C, off, h = self.space.coupling_at(x)
        else:
            C, off, h = (self.robot.coupling_matrix, np.zeros(self.robot.n_frames),
                         self.robot.coupling_harmonic)
        return C, off, h, self.q @ C.T

    def coupled_rows(self, x: ArrayLike, dh: np.ndarray) -> np.ndarray:
        """(S, n, 5) per-sample DH rows: ``dh`` with the coupled frames' extra joint value
        ``(C - C0) q' + offset + sum_k a_k sin(k u) + b_k cos(k u)`` on theta (d for a
        prismatic frame); the kinematics add ``C0 q'`` themselves."""
        C, off, h, u = self.coupling_terms(x)
        delta = self.q_links(x) @ (C - self.robot.coupling_matrix).T + off
        if h.shape[1]:
            k = np.arange(1, h.shape[1] + 1)
            ku = u[..., None] * k
            delta = delta + np.sum(h[:, :, 0] * np.sin(ku) + h[:, :, 1] * np.cos(ku), axis=-1)
        rows = np.broadcast_to(dh, (self.n_samples,) + dh.shape).copy()
        pris = self.robot.frame_is_prismatic
        rows[:, :, 1] += delta * ~pris
        rows[:, :, 0] += delta * pris
        return rows

    def kinematics(self, robot: RobotModel) -> tuple[Any, Any]:
        """The float64 device model of ``robot`` (the kinematics robot, or
        :meth:`kin_robot_at` with free origins) and the :class:`~jwarp.kinematics.KinematicsData`
        of the samples on it (kept while the model stays the same)."""
        m = put_model(robot, self.device, np.float64)
        if self._kin_data is None or self._kin_data.model is not m:
            self._kin_data = K.KinematicsData(m, self.n_samples)
        return m, self._kin_data

    def kin_robot_at(self, x: ArrayLike) -> RobotModel:
        """The robot the kinematics launches see at x: :attr:`kin_robot` with the static
        transforms of the ``origin`` group at x (cached for the last x)."""
        if not self._org_idx.size:
            return self.kin_robot
        x = self.space.check(x)
        key = x[self._org_idx].tobytes()
        if self._kin_cache is None or self._kin_cache[0] != key:
            self._kin_cache = (key, with_static_transforms(
                self.kin_robot, self.space.static_transforms_at(x)))
        return self._kin_cache[1]

    def frames(self, x: Any) -> np.ndarray:
        """World frames (S, n_frames, 4, 4) of the data's configurations at x."""
        return self.state(x)[0]

    def predict(self, x: Any) -> np.ndarray:
        """Predicted observations (S, m) at x."""
        st = self.state(x)
        return np.asarray(self.measurement.predict(st.frames, st.p, self.meta), np.float64)

    def residuals(self, x: Any) -> np.ndarray:
        """Whitened residual vector (S*m + P_prior,) at x (see module docstring). All inf
        where the elastic equilibrium did not converge for some sample (a trial step with
        too soft a robot: the solver then shrinks its step)."""
        st = self.state(x)
        if not (np.all(st.converged) and np.all(np.isfinite(st.frames))):
            return np.full(self.n_residuals, np.inf)
        r = self.whiten(self.predict(x) - self.y)
        if self.loss_f is not None:
            r = r * robust_weights(r, self.loss, self.loss_f)[0][:, None]
        return np.concatenate([r.reshape(-1), self.space.prior_residuals(x)])

    def whiten(self, d: np.ndarray) -> np.ndarray:
        """Whitened data residuals or Jacobian blocks: d (S, m) or (S, m, k) -> the same
        shape, divided by ``noise`` or multiplied by the per-sample ``L_s^-1``."""
        if self.whitener is None:
            return d / self.noise if d.ndim == 2 else d * (1.0 / self.noise)[None, :, None]
        if d.ndim == 2:
            return np.einsum("sij,sj->si", self.whitener, d)
        return self.whitener @ d

    def cost(self, x: Any) -> float:
        """0.5 |r(x)|^2."""
        r = self.residuals(x)
        return 0.5 * float(r @ r)

    # ------------------------------------------------------------ Jacobian
    def data_jacobian_rho(self, frames: np.ndarray, rho: np.ndarray, p: np.ndarray,
                          robot: RobotModel | None = None
                          ) -> tuple[np.ndarray, np.ndarray]:
        """(dy/drho (S, m, n, 5) at fixed frames, dy/dp (S, m, P_meas)) at rows rho
        (S, n, 5), uploaded once for the DH Jacobians of all the measurement's frames;
        ``robot``: the kinematics robot (default :attr:`kin_robot`; :meth:`kin_robot_at`
        with free origins)."""
        meas = self.measurement
        robot = self.kin_robot if robot is None else robot
        _, jf, jp = meas.jacobians(frames, p, self.meta)
        S, m = jf.shape[:2]
        jy = np.zeros((S, m, self.robot.n_frames, 5))
        rows: wp.array = wp.array(finite_as(rho, np.float64, "dh"), dtype=wp.float64,
                                  device=self.device)
        m, d = self.kinematics(robot)
        for k, f in enumerate(meas.frames):
            jdh = K.frame_dh_jacobian(m, d, int(f), self.q_device, dh=rows,
                                      validate=False).numpy()  # (S, 6, n, 5), d's buffer
            jy += (jf[:, :, k, :] @ jdh.reshape(S, 6, -1)).reshape(jy.shape)
        return jy, np.asarray(jp, np.float64)

    def jacobian(self, x: Any) -> np.ndarray:
        """Analytic Jacobian dr/dx (S*m + P_prior, P) of :meth:`residuals`."""
        frames, rho, dh, kap, p, _, mass = self.state(x)
        sp = self.space
        rho_full = np.ascontiguousarray(np.broadcast_to(rho, (self.n_samples,) + dh.shape))
        jy, jp = self.data_jacobian_rho(frames, rho_full, p, self.kin_robot_at(x))
        S, m = jy.shape[:2]
        dh_f, dh_c = sp.frame[self._dh_idx], sp.column[self._dh_idx]
        kp_f, kp_c = sp.frame[self._kap_idx], sp.column[self._kap_idx]
        # transmission errors act as offsets of the driven frames' joint columns
        n_dh = dh_f.size
        C_x = self.coupling_terms(x)[0] if self._cpl_idx.size else None
        hq_f, hq_c, hq_w = self._joint_columns(C_x)
        cf_f = np.unique(sp.frame[self._cpl_idx])
        cf_c = np.where(self.robot.frame_is_prismatic[cf_f], 0, 1).astype(np.int64)
        dh_f = np.concatenate([dh_f, hq_f, cf_f])
        dh_c = np.concatenate([dh_c, hq_c, cf_c])
        knl_f = sp.frame[self._knl_idx]
        if self.elastic:
            st = torque_state(self.robot, frames, rho_full, frame_masses(self.robot, mass))
            free = np.array(sp.kappa_free, copy=True)
            knl = sp.kappa_nonlinear_at(x)
            free[:, 2] |= sp.kappa_nonlinear_free | (knl != 0)
            comps = ElasticComponents.select(self.robot, kap, free)
            dtau = torque_jacobian(self.robot, st, rows=(comps.frame, comps.axis))
            dtau_m = (mass_torque_jacobian(self.robot, frames, st, sp.mass_entries)
                      if self._mass_idx.size else None)
            kap_eff = effective_kappa(kap, knl, st.tau) if np.any(knl) \
                else kap
            b_nl = nonlinear_b(comps, st.tau, knl_f) if knl_f.size else None
            b_org = (self._origin_b(x, frames, st, comps, kap_eff) if self._org_idx.size
                     else None)
            extra = [b for b in (b_nl, b_org) if b is not None]
            d_dh, d_kap, d_mass = equilibrium_jacobian(
                jy, dtau, st.tau, kap_eff, comps, dh_f, dh_c, kp_f, kp_c, dtau_m,
                np.concatenate(extra, axis=2) if extra else None)
            n_m, n_k = self._mass_idx.size, self._knl_idx.size
            d_org_eq = d_mass[:, :, n_m + n_k:]
            d_mass, d_knl = d_mass[:, :, :n_m], d_mass[:, :, n_m:n_m + n_k]
        else:
            d_dh = jy[:, :, dh_f, dh_c]
            d_kap = np.zeros((S, m, kp_f.size))
            d_mass = np.zeros((S, m, self._mass_idx.size))
            d_knl = np.zeros((S, m, 0))
            d_org_eq = None
        n_hq = hq_f.size
        d_cf = d_dh[:, :, n_dh + n_hq:]                                # (S, m, F_c)
        d_dh, d_joint = d_dh[:, :, :n_dh], d_dh[:, :, n_dh:n_dh + n_hq] @ hq_w
        d_harm = self._harmonic_columns(d_joint)
        d_bl = self._backlash_columns(d_joint)
        J = np.zeros((self.n_residuals, sp.size))
        wh = self.whiten
        J[:self.n_data, self._dh_idx] = wh(d_dh).reshape(S * m, -1)
        J[:self.n_data, self._kap_idx] = wh(d_kap).reshape(S * m, -1)
        J[:self.n_data, self._mass_idx] = wh(d_mass).reshape(S * m, -1)
        J[:self.n_data, self._knl_idx] = wh(d_knl).reshape(S * m, -1)
        J[:self.n_data, self._harm_idx] = wh(d_harm).reshape(S * m, -1)
        J[:self.n_data, self._bl_idx] = wh(d_bl).reshape(S * m, -1)
        J[:self.n_data, self._meas_idx] = wh(jp[:, :, sp.column[self._meas_idx]]).reshape(S * m, -1)
        if self._org_idx.size:
            d_org = self._origin_columns(x, frames, p)
            if d_org_eq is not None:
                d_org = d_org + d_org_eq
            J[:self.n_data, self._org_idx] = wh(d_org).reshape(S * m, -1)
        if self._cpl_idx.size:
            J[:self.n_data, self._cpl_idx] = wh(self._coupling_columns(x, d_cf, cf_f)).reshape(
                S * m, -1)
        if self.loss_f is not None:
            e = self.whiten(self.predict(x) - self.y)                  # (S, m)
            w, dw = robust_weights(e, self.loss, self.loss_f)
            Jd = J[:self.n_data].reshape(S, m, -1)
            eJ = np.einsum("sm,smp->sp", e, Jd)                         # e^T J per sample
            Jd = w[:, None, None] * Jd + (dw * 2.0 / self.loss_f ** 2)[:, None, None] \
                * e[:, :, None] * eJ[:, None, :]
            J[:self.n_data] = Jd.reshape(S * m, -1)
        J[self.n_data + np.arange(self._prior_idx.size), self._prior_idx] = 1.0 / sp.sigma[self._prior_idx]
        return J

    def scale_unpriored(self, x: ArrayLike) -> np.ndarray:
        """Set the solver's scale (``space.typical``) of the parameters without a prior to
        ``1 / |dr/dx_i|`` of the data rows at ``x`` (scipy's ``x_scale="jac"``, fixed at the
        start). Without this the trust region of a prior-less run is measured in SI units
        (1 rad/(N m) of compliance next to 1 m of length) and the run crawls or keeps its
        start.

        Returns:
            (P,) bool: the parameters without a prior that have no effect on the data at
            ``x`` (e.g. the pose of a head that loads the torso only once compliances are
            nonzero); :func:`calibrate_with` holds them at the start (free, they make
            prior-less runs wander off; measured in docs/calibration.md).
        """
        sp = self.space
        free = ~sp.has_prior
        none = np.zeros(sp.size, bool)
        if not free.any():
            return none
        J = self.jacobian(x)[:self.n_data]
        norms = np.linalg.norm(J[:, free], axis=0)
        ok = np.isfinite(norms) & (norms > 0)
        typ = np.array(sp.scale, np.float64) if sp.typical is None else sp.typical.copy()
        idx = np.nonzero(free)[0]
        typ[idx[ok]] = 1.0 / norms[ok]
        sp.typical = typ
        none[idx[~ok]] = True
        return none

    def _coupling_columns(self, x: np.ndarray, d_cf: np.ndarray, cf_f: np.ndarray
                          ) -> np.ndarray:
        """(S, m, P_c) dy/d(coupling parameters) from dy/d(joint value) of the coupled
        frames ``d_cf`` (S, m, F_c) (frames ``cf_f``): the offset 1, a coefficient
        ``q'_j + h'(u) q_j``, a harmonic ``sin(k u)`` / ``cos(k u)``."""
        sp = self.space
        idx = self._cpl_idx
        C, _, h, u = self.coupling_terms(x)
        ql = self.q_links(x)
        S = self.n_samples
        K = h.shape[1]
        kk = np.arange(1, K + 1)
        basis = np.zeros((S, idx.size))
        for n, pidx in enumerate(idx):
            i, c = int(sp.frame[pidx]), int(sp.column[pidx])
            ui = u[:, i]
            if c == 0:
                basis[:, n] = 1.0
            elif c < COUPLING_HARM:
                j = self.robot.frames[i].coupling[c - 1][0]
                hp = (np.sum(kk * (h[i, :, 0] * np.cos(np.outer(ui, kk))
                                   - h[i, :, 1] * np.sin(np.outer(ui, kk))), axis=1)
                      if K else 0.0)
                basis[:, n] = ql[:, j] + hp * self.q[:, j]
            else:
                k = (c - COUPLING_HARM) // 2 + 1
                basis[:, n] = np.sin(k * ui) if (c - COUPLING_HARM) % 2 == 0 else np.cos(k * ui)
        pos = np.searchsorted(cf_f, sp.frame[idx])
        return d_cf[:, :, pos] * basis[:, None, :]

    def _origin_b(self, x: np.ndarray, frames: np.ndarray, st: Any, comps: Any,
                  kap_eff: np.ndarray) -> np.ndarray:
        """(S, K, P_o) ``d w / d origin`` right-hand sides of the elastic equilibrium:
        an origin parameter of a static frame moves its subtree rigidly by a twist
        (:func:`.origin.origin_twists`), which changes the torques like a DH entry's
        twist does (:func:`.elastic.torque_jacobian` with those twists), times the local
        compliance."""
        sp = self.space
        idx = self._org_idx
        S, n = frames.shape[:2]
        out = np.zeros((S, comps.size, idx.size))
        if comps.size == 0:
            return out
        kc = np.broadcast_to(np.asarray(kap_eff)[..., comps.frame, comps.axis], (S, comps.size))
        tw = {}
        for s in np.unique(sp.frame[idx]):
            cols = np.nonzero(sp.frame[idx] == s)[0]
            delta = np.zeros(6)
            delta[sp.column[idx[cols]]] = x[idx[cols]]
            par = self.robot.frames[int(s)].parent
            pf = np.broadcast_to(np.eye(4), (S, 4, 4)) if par is None else frames[:, par]
            p_s = frames[:, s, :3, 3]
            t6 = origin_twists(frames[:, s], pf, cast(np.ndarray, self.robot.frames[int(s)].transform), delta,
                               p_s[:, None, :])[:, 0]                 # (S, 6 (v, w), 6 c)
            v, w = t6[:, :3, :], t6[:, 3:, :]                          # (S, 3, 6)
            a = v - np.cross(w, p_s[:, :, None], axis=1)               # a = v - w x p_s
            tw[int(s)] = (a, w)
        for lo, hi in ((0, 5), (5, 6)):
            a_all = np.zeros((S, n, 5, 3))
            w_all = np.zeros((S, n, 5, 3))
            for s_, (a, w) in tw.items():
                a_all[:, s_, :hi - lo] = np.swapaxes(a[:, :, lo:hi], 1, 2)
                w_all[:, s_, :hi - lo] = np.swapaxes(w[:, :, lo:hi], 1, 2)
            dt = torque_jacobian(self.robot, st, twists=(a_all, w_all),
                                 rows=(comps.frame, comps.axis))       # (S, K, n, 5)
            for n_, pidx in enumerate(idx):
                c = int(sp.column[pidx])
                if lo <= c < hi:
                    out[:, :, n_] = kc * dt[:, :, int(sp.frame[pidx]), c - lo]
        return out

    def _origin_columns(self, x: np.ndarray, frames: np.ndarray, p: np.ndarray) -> np.ndarray:
        """(S, m, P_o) dy/d(origin parameters): the twists of the measured frames below
        each freed static frame (:func:`.origin.origin_twists`) through the measurement's
        frame Jacobian."""
        sp = self.space
        meas = self.measurement
        _, jf, _ = meas.jacobians(frames, p, self.meta)         # (S, m, K, 6)
        mframes = np.array([int(f) for f in meas.frames], np.int64)
        sub = self.robot.subtree_mask
        S, m = jf.shape[:2]
        out = np.zeros((S, m, self._org_idx.size))
        idx = self._org_idx
        x = sp.check(x)
        for s in np.unique(sp.frame[idx]):
            cols = np.nonzero(sp.frame[idx] == s)[0]            # positions in _org_idx
            below = np.nonzero(sub[s, mframes])[0]              # measured slots below s
            if not below.size:
                continue
            delta = np.zeros(6)
            delta[sp.column[idx[cols]]] = x[idx[cols]]
            par = self.robot.frames[int(s)].parent
            pf = (np.broadcast_to(np.eye(4), (S, 4, 4)) if par is None else frames[:, par])
            tw = origin_twists(frames[:, s], pf, cast(np.ndarray, self.robot.frames[int(s)].transform), delta,
                               frames[:, mframes[below]][:, :, :3, 3])   # (S, k, 6, 6)
            dy = np.einsum("smkt,sktc->smc", jf[:, :, below, :], tw)  # (S, m, 6)
            out[:, :, cols] = dy[:, :, sp.column[idx[cols]]]
        return out

    def _joint_columns(self, coupling: np.ndarray | None = None
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The DH entries a joint of the ``harmonic`` group drives: frames (E,), columns
        (E,) (theta, or d for a prismatic frame) and the coupling weights (E, J_h) that sum
        their derivatives into d/dq of the J_h joints (``self._harm_joints``);
        ``coupling`` (n_frames, n_dof) replaces the robot's coefficients (the ``coupling``
        group at x)."""
        sp = self.space
        joints = np.unique(np.concatenate([sp.frame[self._harm_idx], sp.frame[self._bl_idx]]))
        self._harm_joints = joints
        fr, co, wt = [], [], []
        pris = self.robot.frame_is_prismatic
        for i, f in enumerate(self.robot.frames):
            for j, c in f.coupling:
                hit = np.nonzero(joints == j)[0]
                if hit.size:
                    fr.append(i)
                    co.append(0 if pris[i] else 1)
                    row = np.zeros(joints.size)
                    row[hit[0]] = c if coupling is None else coupling[i, j]
                    wt.append(row)
        return (np.array(fr, np.int64), np.array(co, np.int64),
                np.array(wt, np.float64).reshape(len(fr), joints.size))

    def _harmonic_columns(self, d_joint: np.ndarray) -> np.ndarray:
        """(S, m, P_h) dy/d(a_jk, b_jk) = dy/dq'_j sin(k q_j) or cos(k q_j) (raw q) from
        dy/dq'_j ``d_joint`` (S, m, J_h)."""
        sp = self.space
        idx = self._harm_idx
        if idx.size == 0:
            return np.zeros(d_joint.shape[:2] + (0,))
        pos = np.searchsorted(self._harm_joints, sp.frame[idx])
        k = (sp.column[idx] // 2 + 1).astype(np.float64)
        kq = self.q[:, sp.frame[idx]] * k                       # (S, P_h)
        basis = np.where(sp.column[idx] % 2 == 0, np.sin(kq), np.cos(kq))
        return d_joint[:, :, pos] * basis[:, None, :]

    def _backlash_columns(self, d_joint: np.ndarray) -> np.ndarray:
        """(S, m, P_b) dy/db_j = dy/dq'_j s_j (the direction of the sample) from dy/dq'_j
        ``d_joint`` (S, m, J_h)."""
        idx = self._bl_idx
        if idx.size == 0:
            return np.zeros(d_joint.shape[:2] + (0,))
        j = self.space.frame[idx]
        pos = np.searchsorted(self._harm_joints, j)
        assert self.directions is not None   # set whenever the group is free
        return d_joint[:, :, pos] * self.directions[:, j][:, None, :]

    # ------------------------------------------------------------- starts
    def initial_x(self, x: np.ndarray | None = None, guess: bool = True) -> np.ndarray:
        """A start: ``x`` (default the prior mean) with the free measurement parameters
        replaced by ``measurement.initial_guess`` at the robot of ``x``."""
        sp = self.space
        x = sp.nominal.copy() if x is None else np.clip(sp.check(x).copy(), sp.lower, sp.upper)
        if guess and self._meas_idx.size and hasattr(self.measurement, "initial_guess"):
            st = self.state(x)
            if not np.all(np.isfinite(st.frames)):
                return x
            p_new = np.asarray(self.measurement.initial_guess(st.frames, self.y, st.p,
                                                              self.meta), np.float64)
            if p_new.shape == st.p.shape and np.all(np.isfinite(p_new)):
                x[self._meas_idx] = p_new[sp.column[self._meas_idx]]
        return x


def _iteration_callback(start: int, n_starts: int, counter: list[int],
                        callback: Callable[[Progress], Any] | None) -> Callable[[Any], None]:
    """least_squares callback (scipy picks the signature by the parameter name)."""

    def cb(intermediate_result: Any) -> None:
        counter[0] += 1
        if callback is not None:
            callback(Progress(start, n_starts, counter[0], _accepted_cost(intermediate_result)))

    return cb


#: most unbounded solves of one start in the compliance active set (:func:`solve_start`)
MAX_ACTIVE_SET_ROUNDS = 6
#: iterations over which ``stall_tol`` measures the cost decrease
STALL_WINDOW = 5
#: ... and the relative decrease over them below which a run has stalled as well
STALL_RTOL = 1e-5


def _accepted_cost(intermediate_result: Any) -> float:
    """0.5 |r|^2 at the solver's current (accepted) x: scipy's ``cost`` field is that of
    the last *trial* step, rejected ones included (dogbox 1.17), so it can go up."""
    f = np.asarray(intermediate_result.fun, np.float64)
    return 0.5 * float(f @ f)


def _least_squares(prob: CalibrationProblem, x: np.ndarray, moving: np.ndarray,
                   lower: np.ndarray, o: CalibrationOptions, max_nfev: int | None,
                   cb: Callable[[Any], None]) -> Any:
    """scipy's least_squares over the entries ``moving`` (bool (P,)) of x, the others held;
    stopped (status 2) when the cost fell by less than ``o.stall_tol`` (or
    :data:`STALL_RTOL` of itself) over the last :data:`STALL_WINDOW` iterations."""
    sp = prob.space
    idx = np.nonzero(moving)[0]
    fun: Callable[[np.ndarray], np.ndarray]
    jac: Callable[[np.ndarray], np.ndarray]
    if idx.size == sp.size:
        fun, jac = prob.residuals, prob.jacobian
    else:
        def full(z: np.ndarray) -> np.ndarray:
            xx = x.copy()
            xx[idx] = z
            return xx

        def fun_sub(z: np.ndarray) -> np.ndarray:
            return prob.residuals(full(z))

        def jac_sub(z: np.ndarray) -> np.ndarray:
            return prob.jacobian(full(z))[:, idx]

        fun, jac = fun_sub, jac_sub
    costs: list[float] = []

    def callback(intermediate_result: Any) -> None:
        cb(intermediate_result)
        costs.append(_accepted_cost(intermediate_result))
        if (o.stall_tol is not None and len(costs) > STALL_WINDOW and costs[-1 - STALL_WINDOW]
                - costs[-1] < max(o.stall_tol, STALL_RTOL * costs[-1])):
            raise StopIteration

    try:
        sol = least_squares(fun, x[idx], jac=jac, bounds=(lower[idx], sp.upper[idx]),
                            method=o.method, x_scale=sp.scale[idx], ftol=o.ftol, xtol=o.xtol,
                            gtol=o.gtol, max_nfev=max_nfev, callback=callback)
    except UnboundLocalError as e:
        if "cost_new" not in str(e):
            raise
        # scipy 1.17 dogbox with a callback: max_nfev reached while every trial step so
        # far had non-finite residuals (no equilibrium) -> its callback reads an unset
        # cost. No step was accepted: the run ends at its start.
        return OptimizeResult(x=x[idx].copy(), cost=0.5 * float(fun(x[idx]) @ fun(x[idx])),
                              nfev=int(max_nfev or 1), status=0, success=False,
                              message="no trial step had finite residuals before max_nfev")
    if sol.status == -2:  # our StopIteration: converged for all practical purposes
        sol.status, sol.success = 2, True
        sol.message = (f"the cost fell by less than stall_tol={o.stall_tol:g} (or "
                       f"{STALL_RTOL:g} of itself) over the last {STALL_WINDOW} iterations")
    return sol


def solve_start(prob: CalibrationProblem, xs: np.ndarray, o: CalibrationOptions,
                cb: Callable[[Any], None] | None = None,
                hold: np.ndarray | None = None) -> OptimizeResult:
    """Minimize ``prob.cost`` from the start ``xs`` (P,) with the solver options of ``o``.

    Without ``o.bound_kappa`` (or no free compliance): one
    :func:`scipy.optimize.least_squares` run with the space's bounds. With it, the
    compliances' bound kappa >= 0 is kept by an active set around *unbounded* runs
    (scipy's box bounds make dogbox truncate every step at a start on the bound kappa = 0
    and stall there, and trf crawl; docs/calibration_robustness.md): after each run the
    compliances that ended negative are set to 0 and held, and the others solved again
    from there; a held one whose cost gradient points inside (d cost / d kappa < 0) is
    released. At most :data:`MAX_ACTIVE_SET_ROUNDS` runs share ``o.max_nfev``.

    ``hold`` (bool (P,)): parameters kept at their start values throughout (the
    prior-less ones without effect at the start, :meth:`CalibrationProblem.scale_unpriored`).

    Guard: the returned x is the lowest-cost feasible point seen, the start included, so
    the cost never ends above the start's (``xs`` must be feasible: compliances >= 0 with
    ``bound_kappa``, finite residuals).

    Returns:
        an OptimizeResult with x, cost, nfev (all runs), status and message (of the last
        run; a note when the guard kept an earlier point), rounds (runs made) and held
        (bool (P,), the compliances held at 0 at the end).
    """
    sp = prob.space
    cb = cb if cb is not None else (lambda _r: None)
    kap = sp.kind == KIND_KAPPA
    bounded = bool(o.bound_kappa) and bool(kap.any())
    lower = np.where(kap, -np.inf, sp.lower) if bounded else sp.lower
    best_x, best_cost = xs.copy(), prob.cost(xs)
    x = xs.copy()
    held = np.zeros(sp.size, bool)
    pinned = np.zeros(sp.size, bool) if hold is None else np.asarray(hold, bool)
    rejected = False     # a run's end point had no equilibrium and was not kept
    nfev, rounds, status, message = 0, 0, 0, "no solver run"
    for rounds in range(1, (MAX_ACTIVE_SET_ROUNDS if bounded else 1) + 1):  # noqa: B007
        left = None if o.max_nfev is None else o.max_nfev - nfev
        if left is not None and left < 1:
            break
        sol = _least_squares(prob, x, ~(held | pinned), lower, o, left, cb)
        nfev += int(sol.nfev)
        status, message = int(sol.status), str(sol.message)
        x[~(held | pinned)] = sol.x
        if not bounded:
            break
        neg = kap & (x < 0)
        x[neg] = 0.0                        # hold the negative ones at the bound
        held |= neg
        c = prob.cost(x)                    # x is feasible now
        if not np.isfinite(c):
            rejected = True
            # the projected point has no equilibrium (e.g. without priors the unbounded
            # run went far, and zeroing compliances leaves the rest unstable): go on from
            # the best point with the held ones at 0, or stop; scipy refuses a start with
            # non-finite residuals ("Residuals are not finite in the initial point")
            x = best_x.copy()
            x[held] = 0.0
            c = prob.cost(x)
            if not np.isfinite(c):
                message += " (the active set stopped: no equilibrium with the compliances " \
                           "that ended negative held at 0)"
                break
        if np.isfinite(c) and c <= best_cost:
            best_x, best_cost = x.copy(), c
        if neg.any():
            continue
        if not held.any():
            break
        r = prob.residuals(x)
        g = prob.jacobian(x).T @ r          # d cost / dx
        release = held & kap & (g * sp.scale < -max(o.gtol or 0.0, 1e-10) * max(float(r @ r), 1.0))
        if not release.any():
            break
        held &= ~release
    if not bounded:
        c_end = prob.cost(x)
        if np.isfinite(c_end) and c_end <= best_cost:
            best_x, best_cost = x.copy(), c_end
    if rejected or best_cost < prob.cost(x):
        message += " (the guard kept the best feasible point seen)"
    if pinned.any():
        message += (f" ({int(pinned.sum())} parameter(s) without prior and without effect at "
                    f"the start held there)")
    return OptimizeResult(x=best_x, cost=float(best_cost), nfev=nfev, status=status,
                          message=message, rounds=rounds, held=held & (best_x == 0.0))


def calibrate(robot: RobotLike, measurement: Measurement, q: ArrayLike, y: Any, *,
              meta: Mapping[str, Any] | None = None, options: CalibrationOptions | None = None,
              **overrides: Any) -> CalibrationResult:
    """MAP calibration of a robot (and the measurement's own parameters) from samples:
    :func:`calibrate_with` with these :class:`CalibrationOptions`.

    Args:
        robot: nominal robot (name or RobotModel); its DH rows and kappa are the prior means.
        measurement: a measurement plugin instance (see jwarp.model.measurement).
        q: (S, n_dof) joint values [rad, m]; y: (S, m) observations [measurement.unit].
        meta: per-sample inputs {name: (S,)} the measurement needs (``meta_names``).
        options: :class:`CalibrationOptions` (None: built from the overrides, which must
            then name ``free``); not modified.
        **overrides: any field of :class:`CalibrationOptions` as a keyword (``free=``,
            ``noise_sigma=``, ``n_starts=``, ``max_nfev=``, ...): the options are
            ``dataclasses.replace(options, **overrides)``, so an override wins over the same
            field of ``options``. By default the measurement's pose and marker groups
            (tracker, camera, markers, fixtures) are freed as well (``free_poses=False`` or
            ``fix`` to keep them), and compliances stay >= 0 (``bound_kappa``).

    Returns:
        :class:`~jwarp.calibration.estimate.result.CalibrationResult`.

    Raises:
        TypeError: an override that is not a field of :class:`CalibrationOptions` (named,
            with the list of fields), ``options`` not a :class:`CalibrationOptions`, no
            ``free`` (neither in ``options`` nor as an override).
        ValueError: bad options or data (:func:`calibrate_with`).
    """
    from jwarp.solvers.overrides import with_overrides

    t0 = time.perf_counter()
    options = with_overrides("calibrate", CalibrationOptions, options, overrides)
    return calibrate_with(robot, measurement, q, y, options, meta=meta, t0=t0)


@limit_blas  # small dense solves: a threaded BLAS only oversubscribes (JWARP_BLAS_THREADS)
def calibrate_with(robot: RobotLike, measurement: Measurement, q: ArrayLike, y: Any, options: CalibrationOptions,
                   *, meta: Mapping[str, Any] | None = None, t0: float | None = None
                   ) -> CalibrationResult:
    """MAP calibration of a robot (and the measurement's own parameters) from samples.

    Args:
        robot, measurement, q (S, n_dof), y (S, m), meta: see :func:`calibrate`.
        options: :class:`CalibrationOptions` (validated here, naming the bad field).
        t0: ``time.perf_counter()`` at which the result's wall time starts (default: now).

    Starts: the first from ``options.x0`` (default: the prior mean), whose free measurement
    parameters ``options.initial_guess`` replaces by ``measurement.initial_guess``; the
    others draw the robot parameters from the prior. Each runs
    :func:`scipy.optimize.least_squares` on one :class:`CalibrationProblem` (the joint
    values uploaded once); the lowest cost wins.

    Returns:
        :class:`~jwarp.calibration.estimate.result.CalibrationResult`.
    """
    t0 = time.perf_counter() if t0 is None else t0
    if not isinstance(options, CalibrationOptions):
        raise TypeError(f"options: expected a CalibrationOptions, got {type(options).__name__}")
    options.validate()
    o = options
    callback = o.callback
    prob = CalibrationProblem(robot, measurement, q, y, o, meta=meta)
    sp = prob.space
    rng = np.random.default_rng(o.seed)
    start0 = prob.initial_x(None if o.x0 is None else sp.check(o.x0, "x0"), guess=o.initial_guess)
    if not np.all(np.isfinite(prob.residuals(start0))):
        raise ValueError(f"x0: the elastic equilibrium does not converge at the start for "
                         f"{int((~prob.state(start0).converged).sum())} sample(s) "
                         f"(equilibrium_iterations={o.equilibrium_iterations}, tol={o.tol}); "
                         f"lower lam or raise equilibrium_iterations")
    hold = prob.scale_unpriored(start0)
    robot_kinds = ((sp.kind == KIND_DH) | (sp.kind == KIND_KAPPA) | (sp.kind == KIND_MASS)
                   | (sp.kind == KIND_ORIGIN))
    n_starts = int(o.n_starts)
    best = None
    runs = []
    for k in range(n_starts):
        if k == 0:
            xs = start0
        else:
            xs = start0.copy()
            xs[robot_kinds] = sp.sample_prior(rng)[robot_kinds]
            xs = prob.initial_x(xs, guess=o.initial_guess)
            if not np.all(np.isfinite(prob.residuals(xs))):
                runs.append({"start": k, "cost": float("inf"), "nfev": 0, "iterations": 0,
                             "status": -1, "message": "no elastic equilibrium at this start"})
                continue
        it = [0]
        cb = _iteration_callback(k, n_starts, it, callback)
        sol = solve_start(prob, xs, o, cb, hold=hold)
        runs.append({"start": k, "cost": float(sol.cost), "nfev": int(sol.nfev),
                     "iterations": it[0], "status": int(sol.status), "message": str(sol.message),
                     "held_at_bound": int(sol.held.sum())})
        if best is None or sol.cost < best[0].cost:
            best = (sol, xs, it[0])
    assert best is not None  # at least one start ran
    sol, xs, iters = best
    return build_result(prob, sol, xs, iters, runs, time.perf_counter() - t0,
                        identifiability_tol=o.identifiability_tol, moved_sigmas=o.moved_sigmas,
                        warn=o.warn)
