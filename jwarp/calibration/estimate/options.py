"""The options of a MAP calibration (:func:`jwarp.calibration.calibrate` and
:func:`jwarp.calibration.calibrate_with`), documented once."""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from jwarp.calibration.estimate.params import parse_groups
from jwarp.calibration.estimate.robust import LOSSES
from jwarp.solvers.overrides import renamed_options
from jwarp.utils.checks import check_int, check_real

#: least-squares methods (scipy.optimize.least_squares) the calibration accepts
METHODS = ("dogbox", "trf")


def _flag(v: Any, name: str, none: bool = False) -> None:
    if v is None and none:
        return
    if not (isinstance(v, (bool, np.bool_)) or (isinstance(v, (int, np.integer)) and v in (0, 1))):
        raise TypeError(f"{name}: expected True or False{' or None' if none else ''}, got {v!r}")


@renamed_options(max_iter="equilibrium_iterations")
@dataclass
class CalibrationOptions:
    """Options of a MAP calibration; :meth:`validate` raises ValueError/TypeError naming
    the field (the values that need the robot, the measurement or the data - group names,
    frames, sigma values, noise, x0 - are checked when the problem is built).

    Attributes:
        free: free parameter groups, a list or comma-separated (required): robot groups
            (``theta``, ``d``, ``r``, ``alpha``, ``beta``, ``kappa_*``, ``mass``) and the
            measurement's own (see :class:`~jwarp.calibration.estimate.params.ParameterSpace`).
        free_poses: also free the measurement's pose and marker groups (``tracker``,
            ``camera``, ``markers``, ``fixtures``: the frames that close the measurement
            loop) that ``fix`` does not name, as ``jwarp calibrate`` does
            (:func:`~jwarp.calibration.estimate.params.with_pose_groups`); False: exactly
            ``free``.
        fix: measurement groups kept at their nominal values although ``free_poses``
            (a list or comma-separated; e.g. ``"markers"`` for markers measured by hand).
        noise_sigma: measurement noise std, scalar or one per observation [unit]; None:
            ``measurement.noise``.
        sigma: prior sigma overrides {group: value} (``inf``: no prior; ``mass``: relative
            to each nominal mass, 0.1 = 10 %); keys ``"group:pattern"`` set the sigma of
            the group's parameters whose joint/frame name matches the fnmatch pattern
            (``{"harmonic:torso_*": 5e-3}``), after the group's own.
        orders: harmonic orders {group: K} of ``harmonic`` and ``coupling``, or per
            joint/frame pattern (``{"harmonic:torso_*": 4, "coupling": 3}``); None: the
            defaults (2 each).
        loss: "linear" (least squares), "soft_l1" or "huber": a robust loss on each
            sample's whitened residual norm (:mod:`~jwarp.calibration.estimate.robust`;
            the prior rows stay Gaussian).
        loss_scale: the robust loss's scale [unit of the measurement] (required with a
            robust loss; e.g. 3 noise sigmas).
        fix_at: {measurement group: value source}: keep these groups fixed at values
            calibrated before: a :class:`~jwarp.calibration.estimate.result.CalibrationResult`,
            its ``to_dict()`` (a ``--params-out`` JSON document) or the path of such a
            file (:func:`~jwarp.calibration.estimate.result.fixed_params`); they replace
            the groups' ``p_nominal`` and are left out of the free groups (with
            ``free_poses`` as with ``fix``).
        frames: the calibratable DH frames (names or indices); None: the measured chains.
        p_nominal: measurement parameter prior means; None: the measurement's nominal.
        x0: (P,) first start (None: the prior mean).
        initial_guess: replace the start's free measurement parameters by
            ``measurement.initial_guess`` (e.g. a closed-form tracker alignment), which makes
            a rough setup converge.
        n_starts: starts (>= 1); those after the first draw the robot parameters from the
            prior (then the initial guess); the lowest cost wins.
        seed: random seed of the prior draws (an integer >= 0, a numpy Generator or None).
        max_nfev, ftol, xtol, gtol, method: of :func:`scipy.optimize.least_squares`
            (``method`` "dogbox" or "trf"; ``x_scale`` is the prior sigma).
        elastic: True/False; None: elastic iff a compliance is free or nonzero.
        lam, equilibrium_iterations, tol: damping in (0, 1], most updates and tolerance
            [rad] of the elastic equilibrium (``fk_elastic``'s ``lam``, ``max_iter``, ``tol``).
        bound_kappa: keep compliances >= 0 (default): every start runs the unbounded
            solver, then holds the compliances that ended negative at 0 and solves again
            (an active set; a held one whose gradient points inside is released), so the
            calibrated robot (which cannot hold a negative compliance) is the optimum the
            result reports. False: the solver may end with negative compliances, which the
            calibrated robot clips to 0 (a finding says how much that costs).
        stall_tol: stop a solver run when its cost (0.5 chi^2 of the whitened residuals)
            fell by less than this (or 1e-5 of the cost) over the last 5 iterations
            (None: off). With systematic error in the data Gauss-Newton converges only
            linearly along weakly determined directions and crawls on for tens of
            iterations, each gaining ~0.1; the default 1.0 (a chi^2 change of 2 in 5
            iterations) ends that crawl, far below what a test error shows. Clean data
            converge by ``ftol`` first.
        covariance: per-sample measurement covariance (S, m, m) with full blocks, or one
            (m, m) for all samples [unit^2] (task-oriented weighting, virtual noise: see
            :mod:`~jwarp.calibration.design.tow`); replaces ``noise_sigma`` in the
            whitening (its shape and positive definiteness are checked with the data).
        callback: called with :class:`~jwarp.calibration.estimate.map.Progress` after every
            solver iteration (progress bars).
        identifiability_tol: a direction of the prior-whitened data information J^T J with
            eigenvalue below this is reported as not identifiable.
        moved_sigmas: report parameters that moved more than this many prior sigmas.
        warn: emit the findings with ``warnings.warn`` (they are always in the result).
        directions: (S, n_dof) the direction (+1, -1; 0 unknown) each joint last moved in
            before each sample, for the ``backlash`` group (direction-dependent joint
            errors, :mod:`~jwarp.calibration.estimate.backlash`); None: from the order of
            the rows (the previous sample in measurement order).
    """

    free: str | Iterable[str]
    noise_sigma: Any = None
    sigma: Mapping[str, float] | None = None
    frames: Iterable[int | str] | None = None
    p_nominal: Any = None
    x0: Any = None
    initial_guess: bool = True
    n_starts: int = 1
    seed: Any = 0
    max_nfev: int | None = 200
    ftol: float | None = 1e-8
    xtol: float | None = 1e-8
    gtol: float | None = 1e-8
    method: str = "dogbox"
    elastic: bool | None = None
    lam: float = 1.0
    equilibrium_iterations: int = 100
    tol: float = 1e-12
    bound_kappa: bool = True
    covariance: Any = None
    free_poses: bool = True
    fix: str | Iterable[str] | None = None
    stall_tol: float | None = 1.0
    callback: Callable[[Any], Any] | None = None
    identifiability_tol: float = 1e-2
    moved_sigmas: float = 3.0
    warn: bool = True
    orders: Mapping[str, int] | None = None
    loss: str = "linear"
    loss_scale: float | None = None
    fix_at: Mapping[str, Any] | None = None
    directions: Any = None

    def validate(self) -> None:
        """ValueError/TypeError naming the first bad field."""
        check_int(self.n_starts, "n_starts", 1)
        if self.method not in METHODS:
            raise ValueError(f"method: expected 'dogbox' or 'trf', got {self.method!r}")
        if self.callback is not None and not callable(self.callback):
            raise TypeError("callback: expected a callable taking a Progress")
        if not (self.free_poses and isinstance(self.free, str) and not self.free.strip()):
            parse_groups(self.free)  # empty is fine when the pose groups are added
        if self.fix is not None and not (isinstance(self.fix, str) and not self.fix.strip()):
            try:
                parse_groups(self.fix)
            except (TypeError, ValueError) as e:
                raise type(e)(str(e).replace("free:", "fix:", 1)) from None
            if not self.free_poses:
                raise ValueError("fix: names groups to keep out of the pose groups that "
                                 "free_poses adds, but free_poses is False")
        if self.sigma is not None and not isinstance(self.sigma, Mapping):
            raise TypeError(f"sigma: expected a mapping {{group: sigma}}, got "
                            f"{type(self.sigma).__name__}")
        if not (self.seed is None
                or isinstance(self.seed, (np.random.Generator, np.random.SeedSequence))):
            check_int(self.seed, "seed", 0)
        check_int(self.max_nfev, "max_nfev", 1, none=True)
        check_real(self.stall_tol, "stall_tol", 0.0, none=True)
        for name in ("ftol", "xtol", "gtol"):
            check_real(getattr(self, name), name, 0.0, none=True)
        _flag(self.elastic, "elastic", none=True)
        if not (isinstance(self.lam, (int, float)) and 0 < self.lam <= 1):
            raise ValueError(f"lam: damping must be in (0, 1], got {self.lam!r}")
        check_int(self.equilibrium_iterations, "equilibrium_iterations", 0)
        check_real(self.tol, "tol", 0.0)
        for name in ("initial_guess", "bound_kappa", "warn", "free_poses"):
            _flag(getattr(self, name), name)
        check_real(self.identifiability_tol, "identifiability_tol", 0.0)
        check_real(self.moved_sigmas, "moved_sigmas", 0.0, open_lo=True)
        if self.orders is not None and not isinstance(self.orders, Mapping):
            raise TypeError(f"orders: expected a mapping {{group: order}}, got "
                            f"{type(self.orders).__name__}")
        if self.loss not in LOSSES:
            raise ValueError(f"loss: expected one of {', '.join(LOSSES)}, got {self.loss!r}")
        check_real(self.loss_scale, "loss_scale", 0.0, open_lo=True, none=True)
        if self.loss != "linear" and self.loss_scale is None:
            raise ValueError(f"loss_scale: required with loss={self.loss!r} (the residual "
                             f"norm where the loss turns robust, unit of the measurement)")
        if self.fix_at is not None and not isinstance(self.fix_at, Mapping):
            raise TypeError(f"fix_at: expected a mapping {{group: result or file}}, got "
                            f"{type(self.fix_at).__name__}")
