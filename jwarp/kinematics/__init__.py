"""Kinematics: batched FK of all frames, Jacobians, the elastic equilibrium, compensation
rows for optimizers, torch autograd and Warp-tape differentiation.

Modules (each with one job): :mod:`~jwarp.kinematics.fk` (forward kinematics),
:mod:`~jwarp.kinematics.jacobians` (joint and DH Jacobians),
:mod:`~jwarp.kinematics.equilibrium` (elastic FK, one torque update, gravity torques),
:mod:`~jwarp.kinematics.data` (:class:`KinematicsData`, the reusable workspace of one batch
size, with :func:`forward_kinematics`, :func:`frame_jacobian` and :func:`frame_dh_jacobian`),
:mod:`~jwarp.kinematics.launch` (the validated batch, device tables and kernel launches they
share), :mod:`~jwarp.kinematics.compensation` (DH rows kept across optimizer iterations),
:mod:`~jwarp.kinematics.torch_ops` (torch autograd), :mod:`~jwarp.kinematics.autodiff`
(Warp tape Jacobians).
"""

from jwarp.kinematics.data import (
                                  KinematicsData,
                                  forward_kinematics,
                                  frame_dh_jacobian,
                                  frame_jacobian,
)
from jwarp.kinematics.equilibrium import (
                                  elastic_step,
                                  fk_elastic,
                                  gravity_torques,
                                  solve_equilibrium,
)
from jwarp.kinematics.fk import fk
from jwarp.kinematics.jacobians import jacobian, jacobian_dh
from jwarp.kinematics.launch import (
                                  ELASTIC_TOL,
                                  ElasticFK,
                                  ElasticLaunch,
                                  ElasticStep,
                                  default_tol,
                                  elastic_args,
                                  equilibrium,
                                  frame_rows,
                                  host_out,
                                  kappa_array,
                                  launch_fk,
                                  rho0_full,
                                  setup,
)
from jwarp.kinematics.transmission import (
                                  transmitted,
                                  without_coupling_harmonic,
                                  without_transmission,
)

__all__ = [
    "ElasticFK", "ElasticStep", "KinematicsData", "elastic_step", "fk_elastic",
    "forward_kinematics", "frame_dh_jacobian", "frame_jacobian", "gravity_torques",
    "jacobian_dh", "kappa_array", "solve_equilibrium", "transmitted",
    "without_coupling_harmonic", "without_transmission",
]
