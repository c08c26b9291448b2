"""Optimization-based motion planning (OMP): batched gradient descent on U_path.

Thesis 3.3.1-3.3.3 and the IROS'22 paper, section II. A path is ``W`` waypoints
``Q = [q_1 .. q_W]`` with fixed start ``q_1`` and goal ``q_W``; linear substeps (eq. 3.3)
between the waypoints make the swept volume explicit. The objective (eq. 3.16)

    U_path(Q) = lam_w U_w(Q) + lam_s U_s(Q) + lam_l U_l(Q)

sums the world and self-collision costs (eq. 3.8-3.12, :mod:`jwarp.world.collision`) over all
substeps and adds the normalised length cost (eq. 3.5). Gradient descent with a fixed
step (eq. 3.18), a per-joint step clamp and a projection onto the joint limits (box plus
linear limits such as justin19's coupled torso) runs for many paths in one launch per
stage: substeps -> collision cost + gradient -> path cost -> step.

A path is *feasible* when every substep is collision-free with ``margin`` (world and self)
and every waypoint is within the limits. Each path stops on its own as soon as it is
feasible (early stop); :class:`Planner` (a persistent solver: device buffers reused across
calls, options in :class:`PlanOptions`, seeds from the caller) and its one-call wrapper
:func:`plan` return per problem the best (lowest U_path) feasible path of its multi-starts,
chosen on the device, or the lowest-cost infeasible one with ``feasible = False``.

With ``kappa`` (elastic compensation, elastic paper section V, Fig. 2.11) the robot is the
elastic model (:mod:`jwarp.kinematics.compensation`): the collision kernel computes the frames
at the DH rows kept from the previous iteration, one torque update at every waypoint from
those frames gives the rows of the next iteration (substeps take their nearest
waypoint's), and the collision gradient is taken with the rows fixed."""

from jwarp.solvers.planning.objective import NORM_FLOOR, PathObjective
from jwarp.solvers.planning.options import (
                                            FALLBACKS,
                                            INITIAL_KINDS,
                                            STAGES,
                                            STOP_REASONS,
                                            PathWeights,
                                            PlanOptions,
                                            ViaPoints,
)
from jwarp.solvers.planning.planner import (
                                            EXACT_SUBSTEP,
                                            PLANNER_CHECK_EVALS,
                                            PLANNER_CHECK_EVALS_GPU,
                                            Planner,
                                            plan,
)
from jwarp.solvers.planning.result import PlanResult

__all__ = [
    "PathObjective", "PathWeights", "PlanOptions", "ViaPoints", "PlanResult",
]
