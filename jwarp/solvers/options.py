"""The fields the IK and the planning options share, declared once (issue 40 item 4):
:class:`SolverOptions`, the base of :class:`jwarp.solvers.ik.IKOptions` and
:class:`jwarp.solvers.planning.PlanOptions`.

Each subclass keeps its own defaults where the solvers differ (``iterations``, ``step``,
``max_step``: redeclared there; ``n_starts``, whose default the planner sizes to the
device, is declared in each), its own validation
(``validate``: the IK options become floats, the planning options are checked in the
computing dtype) and documents every field in its own docstring.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any


@dataclass
class SolverOptions:
    """The options an IK solve and a plan share.

    Attributes:
        iterations: optimizer iterations, >= 0.
        step: the optimizer's step size, > 0.
        max_step: the largest change of one joint per iteration, > 0.
        eps: smoothing width of the collision clip [m], > 0 and >= margin (None: from the
            world's voxel size).
        margin: required clearance [m] (world and self), >= 0.
        kappa, lam: elastic compensation (compliances [rad/(N m)] or None for the rigid
            robot, and the damping of the torque update in (0, 1]).
        stop_when_solved: end once every problem has a feasible solution.
        seed: the random seeds' generator seed, an integer >= 0 (or None).
        allow_no_collision: accept a robot without collision spheres.
        mesh_margin: for a robot whose spheres approximate its meshes, grow each sphere by
            its recorded poke-out.
    """

    iterations: int = 100
    step: float = 1.0
    max_step: float = 0.1
    eps: float | None = None
    margin: float = 0.0
    kappa: Any = None
    lam: float = 0.7
    stop_when_solved: bool = True
    seed: Any = 0
    allow_no_collision: bool = False
    mesh_margin: bool = True
