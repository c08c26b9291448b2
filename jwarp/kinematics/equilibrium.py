"""Elastic kinematics: the frames in the static equilibrium of gravity torques and joint
compliances (rho = rho0 + kappa tau, a damped fixed-point iteration), one torque update
(:func:`elastic_step`) and the gravity torques; :func:`solve_equilibrium` ``(m, q, dh,
kappa)`` is the equilibrium on a given device model (its masses, nonlinear compliances)."""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from jwarp.core.arrays import as_batch, out_view, real_number, to_output
from jwarp.core.device import DeviceModel
from jwarp.core.types import ArrayLike, DeviceLike, DTypeLike, RobotLike
from jwarp.kernels import fk as fk_kernels
from jwarp.kinematics.launch import (
    ElasticFK,
    ElasticLaunch,
    ElasticStep,
    check_max_iter,
    elastic_args,
    equilibrium,
    frame_rows,
    host_out,
    lam_tol,
    rho0_full,
    setup,
)
from jwarp.kinematics.transmission import transmitted
from jwarp.plugins.registry import robot as get_robot


def fk_elastic(robot: RobotLike, q: ArrayLike, kappa: ArrayLike | None = None, *,
               lam: float = 1.0, max_iter: int = 10, tol: float | None = None,
               dh: ArrayLike | None = None, device: DeviceLike = None, dtype: DTypeLike = None,
               validate: bool = True, out: ArrayLike | None = None) -> ElasticFK:
    """Elastic forward kinematics: frames in the static torque equilibrium.

    Solves ``rho = rho0 + kappa * tau(F(q, rho))`` (thesis eq. 2.33) by the damped
    fixed-point iteration (eq. 2.35) started at the geometric rows ``rho0``.

    Args:
        robot, q, device, dtype, validate: as for :func:`fk`.
        kappa: compliances [rad/(N m)]: scalar, [alpha, beta, theta], (n_frames, 3) or per
            configuration (..., n_frames, 3); None uses the robot's ``kappa``.
        lam: damping lambda in (0, 1]; use < 1 for very soft robots.
        max_iter: most torque updates (0 gives the rigid FK; ``converged`` then says
            whether the rigid frames already are the equilibrium to ``tol``).
        tol: stop once no DH angle changes by more than ``tol`` [rad] in an update;
            default :func:`default_tol`: 1e-9 rad in float64, 4.8e-7 rad (the rows'
            resolution) in float32.
        dh: geometric DH rows rho0 (n_frames, 5) or (..., n_frames, 5); default nominal.
        out: optional array the frames are written to (as ``out`` of :func:`fk`); the
            result's ``frames`` is then ``out``.

    The robot's non-geometric extras act too: ``kappa_nonlinear`` (the joint axis bends
    by ``kappa tau + kappa_nonlinear tau^3``, in the kernel) and the joint transmission
    errors ``harmonic`` (the kernel runs at ``q + dq(q)``, exact; host side).

    Returns:
        :class:`ElasticFK` (frames, rho, iterations, converged).
    """
    robot = get_robot(robot)
    q = transmitted(robot, q)
    model, batch, t, kap, rho0 = elastic_args(robot, q, kappa, lam, max_iter, tol, dh,
                                               device, dtype, validate)
    lam, tol = lam_tol(lam, tol, t)
    if batch.kind == "torch" and batch.torch_tensor.requires_grad:
        if out is not None:
            raise ValueError("out: not supported when q requires grad (torch autograd)")
        from jwarp.kinematics.torch_ops import fk_elastic_torch

        return fk_elastic_torch(model, batch, t, kap, rho0, lam, max_iter, tol)
    view = None if out is None else out_view(out, batch, (model.n_frames,),
                                             fk_kernels.kernels(t.scalar).mat44, t.device)
    run = ElasticLaunch(t, batch.array, kap, rho0, float(lam))
    rho, frames, iterations, converged = equilibrium(run, max_iter, tol, view)
    rho_arr = rho[0] if rho is not None else rho0_full(run)
    return ElasticFK(to_output(frames, batch, (model.n_frames,), out=out),
                     to_output(rho_arr, batch, (model.n_frames, 5)),
                     host_out(iterations, batch), host_out(converged, batch))


def solve_equilibrium(m: DeviceModel, q: ArrayLike, dh: Any, kappa: ArrayLike, *, lam: float = 1.0,
                      max_iter: int = 10, tol: float | None = None,
                      validate: bool = True) -> ElasticFK:
    """The elastic equilibrium (as :func:`fk_elastic`) on the device model ``m``
    (:func:`~jwarp.core.device.put_model`, or a copy with other masses or nonlinear
    compliances: :func:`~jwarp.core.device.with_frame_masses`,
    :func:`~jwarp.core.device.with_kappa_nonlinear`), with compliances of either sign (an
    optimizer may cross kappa = 0; the fixed point is just as well defined). No
    transmission errors are applied: ``q`` are the joint values the links see.

    Args:
        m: the device model; the kernels run on its device in its dtype.
        q: (..., n_dof) joint values [rad or m]: numpy, or a Warp array of the model's
            dtype (used as is on the model's device: no copy).
        dh: geometric DH rows rho0 (n_frames, 5) or (..., n_frames, 5).
        kappa: compliances (n_frames, 3) or (..., n_frames, 3) [rad/(N m)], any sign.
        lam, max_iter, tol: as for :func:`fk_elastic`.
        validate: check ``q`` for NaN/inf.

    Returns:
        :class:`ElasticFK` of numpy arrays (for a Warp ``q`` too): frames
        (..., n_frames, 4, 4), rho (..., n_frames, 5), iterations and converged (...,).
    """
    if not isinstance(m, DeviceModel):
        raise TypeError(f"m: expected a DeviceModel (jwarp.core.device.put_model), got "
                        f"{type(m).__name__}")
    robot = m.robot
    batch = as_batch(q, robot.n_dof, "q", device=m.device, dtype=m.scalar,
                     what=f"robot '{robot.name}' has {robot.n_dof} joints", validate=validate)
    lam, tol = lam_tol(lam, tol, m)
    max_iter = check_max_iter(max_iter)
    kap = frame_rows(kappa, robot, batch, m, "kappa", 3)
    rho0 = frame_rows(dh, robot, batch, m, "dh", 5)
    run = ElasticLaunch(m, batch.array, kap, rho0, float(lam))
    rho, frames, iterations, converged = equilibrium(run, max_iter, float(tol))
    rho_arr = rho[0] if rho is not None else rho0_full(run)
    host = replace(batch, kind="numpy")  # numpy out for a Warp q too
    n = robot.n_frames
    return ElasticFK(to_output(frames, host, (n,)), to_output(rho_arr, host, (n, 5)),
                     host_out(iterations, host), host_out(np.asarray(converged, bool), host))


def elastic_step(robot: RobotLike, q: ArrayLike, rho: ArrayLike | None = None,
                 kappa: ArrayLike | None = None, *, lam: float = 1.0, dh: ArrayLike | None = None,
                 device: DeviceLike = None, dtype: DTypeLike = None,
                 validate: bool = True) -> ElasticStep:
    """One torque update, as used for compensation inside an optimizer (Fig. 2.11).

    Computes the frames at ``rho`` (None: the geometric rows), the gravity torques of
    those frames and ``rho_new = (1 - lam) rho + lam (rho0 + kappa tau)``. Planners keep
    ``rho`` between their iterations and take gradients with ``rho`` fixed.

    Returns :class:`ElasticStep` (frames (..., n_frames, 4, 4), rho (..., n_frames, 5),
    delta (...,) [rad]). Transmission errors as in :func:`fk_elastic`.
    """
    robot = get_robot(robot)
    q = transmitted(robot, q)
    model, batch, t, kap, rho0 = elastic_args(robot, q, kappa, lam, 1, 0.0, dh,
                                               device, dtype, validate)
    run = ElasticLaunch(t, batch.array, kap, rho0, real_number(lam, "lam"))
    rho_in = None if rho is None else frame_rows(rho, model, batch, t, "rho", 5)
    frames, rho_new, delta = run.step(rho_in)
    return ElasticStep(to_output(frames, batch, (model.n_frames,)),
                       to_output(rho_new, batch, (model.n_frames, 5)),
                       to_output(delta, batch, ()))


def gravity_torques(robot: RobotLike, q: ArrayLike, *, dh: ArrayLike | None = None,
                    device: DeviceLike = None, dtype: DTypeLike = None) -> Any:
    """Gravity torques (..., n_frames, 3) [N m] about the [alpha, beta, theta] axes of
    every DH frame at the frames F(q, dh) (rigid; zero rows for static frames)."""
    robot = get_robot(robot)
    model, batch, t = setup(robot, transmitted(robot, q), device, dtype)
    rho = None if dh is None else frame_rows(dh, model, batch, t, "dh", 5)
    kap = frame_rows(np.zeros((model.n_frames, 3)), model, batch, t, "kappa", 3)
    run = ElasticLaunch(t, batch.array, kap, None, 1.0, write_tau=True)
    run.step(rho)
    return to_output(run.tau, batch, (model.n_frames, 3))
