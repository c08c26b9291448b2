"""Collision-free inverse kinematics: the two-stage solver of thesis 3.3.3 (eq. 3.21-3.24).

Stage 1 (projection, eq. 3.21-3.23): ``q <- q + J^+ e`` with the 6D error
``e = [p_T - p; log(R_T R^T)]`` of the end-effector frame and the damped pseudo-inverse
``J^+ = J^T (J J^T + mu^2 I)^-1`` of the geometric Jacobian (planar robots use the rows
``v_x, v_y, w_z`` only). Stage 2 (eq. 3.24): once a configuration is on the target
(``|e_v| < tol_pos``, ``|e_w| < tol_rot``) it descends ``U_A`` (world + self collision +
closeness to a default pose, eq. 3.19) inside the Jacobian's nullspace,
``q <- q + J^+ e - alpha (I - J^+ J) dU_A/dq``, the ``J^+ e`` term pulling it back onto the
target manifold. Every step is scaled so that no joint moves more than ``max_step`` and
projected onto the joint limits.

Convergence (beyond the thesis): a joint at a box limit that the step would push further
out is held (its Jacobian column removed, the step recomputed), and a start whose pose
error stops falling while off target (``restart_after`` steps without a 10 % gain) is
re-seeded uniformly inside the limits, up to ``max_restarts`` times; then it gives up. A
problem is done when solved or when all its starts gave up; with ``stop_when_solved`` the
batch ends when every problem is done. Panda, 4 starts, 50 iterations, 1 mm / 0.01 rad:
85 % of reachable targets solved before, 99 % with both (benchmarks/README.md). Targets may
constrain the full pose, the position only (``orientation="none"``) or one axis of the
frame (``orientation="axis"``, ``free_axis``: a grasp symmetric about the tool axis).

A configuration is *feasible* when it is on the target, collision-free with ``margin``
(world and self) and within the limits; each multi-start stops when feasible. The batch
holds ``P`` problems (targets) x ``S`` seeds; the solver returns per problem the feasible
seed with the lowest U_A (or the best infeasible one, flagged).

:class:`IKSolver` keeps everything on the device (:mod:`jwarp.kernels.ik_step`): the damped
least-squares step, the exact feasibility check of the candidates (float64: limits, world
and self collision with ``margin``), freezing the solved seeds and the best-seed selection
run in kernels; the host only reads three counters now and then to decide when to stop
(every iteration on the CPU, where that is free; every ``check_every`` iterations on CUDA)
and copies the results once at the end. :func:`ik` is a thin wrapper that builds one.

With ``kappa`` the robot is the elastic model (elastic paper section V): one torque update
per iteration from the DH rows kept from the previous iteration; frames and Jacobians at
those rows, gradients with the rows fixed; "on target" also requires the torque update to
have converged (largest DH change < ``tol_rho``)."""

from jwarp.solvers.ik.objective import IKObjective, pose_matrix
from jwarp.solvers.ik.options import (
                                     ORIENTATIONS,
                                     IKOptions,
                                     IKWeights,
                                     orientation_args,
)
from jwarp.solvers.ik.result import IKResult
from jwarp.solvers.ik.solver import (
                                     RESTART_PROGRESS,
                                     SOLVER_CACHE_MAX_BATCH,
                                     SOLVER_CACHE_SIZE,
                                     IKSolver,
                                     check_warm_start,
                                     ik,
                                     select_best,
                                     warm_start_seeds,
)

__all__ = [
    "pose_matrix", "IKObjective", "IKWeights", "IKOptions", "IKResult", "warm_start_seeds",
]
