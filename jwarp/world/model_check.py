"""Checks of a robot's collision model before planning or IK: no silent empty models.

A planner or IK solver that checks collisions with a robot that has no collision spheres
would call every path or solution collision-free; a robot whose spheres overlap at its home
configuration (a collision model that is wrong: spheres fitted to open meshes, a missing
exclusion) would make every configuration near it infeasible with no reason given. Both are
errors at construction (:func:`check_collision_model`, used by
:class:`jwarp.solvers.planning.Planner` and :class:`jwarp.solvers.ik.IKSolver`), unless the
caller opts out (``allow_no_collision=True``; CLI ``--no-collision``).

A robot imported with ``jwarp import-urdf`` carries its home (``notes['home']``, JSON joint
values: the SRDF state or values of ``--home``, made free of self-collision at import,
:mod:`jwarp.world.home_fit`); it is the first of :func:`home_configurations`. Two
more stand in for a home: the zero configuration projected into the joint limits, and
the middle of the limits. The self-collision check fails when the robot collides with itself
at both (the Panda's zero configuration projected into its limits is folded, hand against
link 5, while the middle of its limits is free, as for every robot shipped with jwarp).
"""

from __future__ import annotations

from collections import OrderedDict
from typing import Any

import numpy as np

from jwarp.core.limits import project_numpy
from jwarp.core.types import DeviceLike
from jwarp.kinematics.fk import fk
from jwarp.model import RobotModel
from jwarp.world.collision import collision_pairs

__all__ = ["NO_SPHERES_HINT", "HOME_NOTE", "noted_home", "home_configuration",
           "MeshMarginWarning", "mesh_margin_model",
           "home_configurations",
           "home_self_collisions", "check_collision_model"]

#: how to get a collision model (the end of the error messages)
NO_SPHERES_HINT = ("fit spheres to the robot's collision geometry with `jwarp import-urdf "
                   "ROBOT.urdf --spheres fit` or `jwarp import-mjcf ROBOT.xml --spheres fit` "
                   "(API: jwarp.world.spherize)")


def home_configuration(robot: RobotModel) -> np.ndarray:
    """(n_dof,) the robot's home configuration [rad or m]: zero projected into the joint
    limits (and linear limits, where the robot has them)."""
    model = robot
    return project_numpy(model, np.zeros(model.n_dof))


#: ``RobotModel.notes`` key of the home an import chose (JSON list of joint values)
HOME_NOTE = "home"


def noted_home(robot: RobotModel) -> np.ndarray | None:
    """(n_dof,) the home in ``notes['home']`` [rad or m], projected into the limits; None
    when there is none or it does not fit the robot (another joint count, not numbers)."""
    import json

    model = robot
    text = model.notes.get(HOME_NOTE)
    if not text:
        return None
    try:
        q = np.asarray(json.loads(text), np.float64).reshape(-1)
    except (ValueError, TypeError):
        return None
    if q.shape != (model.n_dof,) or not np.all(np.isfinite(q)):
        return None
    return project_numpy(model, q)


def home_configurations(robot: RobotModel) -> list[tuple[str, np.ndarray]]:
    """``[(label, q (n_dof,))]``: the imported home (:func:`noted_home`) where the robot
    has one, :func:`home_configuration` and the middle of the joint limits (projected into
    linear limits), the configurations of the self-collision check."""
    model = robot
    mid = project_numpy(model, model.joint_limits.mean(axis=1))
    noted = noted_home(model)
    return ([("its home (notes.home)", noted)] if noted is not None else []) + [
        ("the zero configuration projected into the limits", home_configuration(model)),
        ("the middle of the joint limits", mid)]


def home_self_collisions(robot: RobotModel, q: Any = None, *, device: DeviceLike = None
                         ) -> list[tuple[str, str, float]]:
    """Frame pairs whose spheres overlap at ``q`` (None: :func:`home_configuration`) among
    the self-collision pairs the robot checks (``RobotModel.allowed_collision_pairs``):
    ``[(frame_a, frame_b, distance [m] < 0)]``, deepest first (one FK in float64 on
    ``device``: the caller's, so a solver on a GPU runs no CPU kernel)."""
    model = robot
    q = home_configuration(model) if q is None else np.asarray(q, np.float64)
    pairs = collision_pairs(model)
    if len(pairs) == 0:
        return []
    sf, sp, sr = model.sphere_arrays()
    T = fk(model, q[None], device=device, dtype=np.float64)[0]
    x = np.einsum("sij,sj->si", T[sf, :3, :3], sp) + T[sf, :3, 3]
    i, j = pairs[:, 0], pairs[:, 1]
    d = np.linalg.norm(x[i] - x[j], axis=1) - sr[i] - sr[j]
    worst: dict[tuple[int, int], float] = {}
    for k in np.flatnonzero(d < 0.0):
        key = (int(min(sf[i[k]], sf[j[k]])), int(max(sf[i[k]], sf[j[k]])))
        worst[key] = min(worst.get(key, 0.0), float(d[k]))
    names = [f.name for f in model.frames]
    return [(names[a], names[b], v) for (a, b), v in sorted(worst.items(), key=lambda t: t[1])]


#: (robot content, device) whose collision model passed :func:`check_collision_model`
_PASSED: set = set()


def check_collision_model(robot: RobotModel, *, need_spheres: bool, what: str,
                          option: str = "allow_no_collision=True",
                          device: DeviceLike = None) -> None:
    """ValueError naming the robot when ``need_spheres`` and it has no collision spheres,
    or when it is in self-collision at every one of :func:`home_configurations` (naming the
    frame pairs and how deep they overlap).
    ``what``: the work refused (e.g. "planning"); ``option``: the opt-out to name;
    ``device``: where the FK of the check runs."""
    from jwarp.core.device import content_key

    model = robot
    key = (content_key(model), str(device))
    if key in _PASSED:  # the same robot content passed before (a planner per problem)
        return
    if need_spheres and len(model.spheres) == 0:
        raise ValueError(f"robot: '{model.name}' has no collision spheres, so {what} would "
                         f"call everything collision-free; {NO_SPHERES_HINT}, or pass "
                         f"{option} to work without a collision model")
    if len(model.spheres) == 0:
        return
    found = []
    for label, q in home_configurations(model):
        hits = home_self_collisions(model, q, device=device)
        if not hits:
            _PASSED.add(key)
            return
        listed = ", ".join(f"'{a}'-'{b}' ({-d * 1e3:.1f} mm deep)" for a, b, d in hits[:4])
        more = f" and {len(hits) - 4} more pairs" if len(hits) > 4 else ""
        found.append(f"at {label} {np.round(q, 4).tolist()}: {listed}{more}")
    rel = model.sphere_relation
    grown = (" (its spheres were grown by the meshes' poke-out, issue 42: mesh_margin=False "
             "works on them as fitted, or import with containment)"
             if rel is not None and rel.inflated else "")
    raise ValueError(
        f"robot: '{model.name}'{grown} is in self-collision at "
        f"{'both' if len(found) == 2 else f'all {len(found)}'} of its home configurations, "
        f"{'; '.join(found)}; its collision model is wrong (spheres reaching outside the "
        f"links: fit again with a smaller tolerance, or exclude the pairs in "
        f"self_collision.exclude_pairs), or pass {option} to skip this check")


#: how a contained fit names itself in ``SphereRelation.method``
#: (:func:`jwarp.importers.spheres.contain_fit`)
CONTAIN_METHOD = "jwarp.importers.spheres.contain_fit"


class MeshMarginWarning(UserWarning):
    """Planning or IK with a robot whose spheres only approximate its collision meshes
    (``RobotModel.sphere_relation`` "approximate"): said once per robot and choice."""


#: (robot content, mesh_margin) pairs already warned about (:func:`mesh_margin_model`)
_WARNED: set = set()
#: robot content -> its inflated copy (the last few; a planner built per problem reuses it,
#: and with it the device tables, instead of copying the robot each time)
_INFLATED: OrderedDict[str, Any] = OrderedDict()


def mesh_margin_model(robot: RobotModel, mesh_margin: bool = True, *, what: str = "planning") -> Any:
    """The robot a planner or IK solver works with (a :class:`~jwarp.model.RobotModel`):
    when its ``sphere_relation`` is ``"approximate"`` (the meshes poke out of the spheres
    by a measured, certified amount per link) and ``mesh_margin``, a copy whose every
    sphere is grown by its link's poke-out [m] (:func:`jwarp.model.sphere_relation.
    inflated`: the grown spheres contain the meshes, so the poke-out acts as extra margin
    per link); with ``mesh_margin`` False the robot as it is. Either way a
    :class:`MeshMarginWarning` says so, once per robot content and choice (``what``: the
    work, e.g. "planning"). Contained robots and robots of unknown relation (no
    ``sphere_relation``, e.g. files written before it existed: nothing is added) are
    returned as they are, without a warning."""
    import warnings

    from jwarp.core.device import content_key
    from jwarp.model.sphere_relation import inflated

    if not isinstance(mesh_margin, (bool, np.bool_)):
        raise TypeError(f"mesh_margin: expected True or False, got {mesh_margin!r}")
    model = robot
    rel = model.sphere_relation
    if rel is None or rel.kind != "approximate" or not model.spheres:
        return model
    key = (content_key(model), bool(mesh_margin))
    worst = sorted(rel.poke_out.items(), key=lambda kv: -kv[1])[:3]
    listed = ", ".join(f"{k} {v * 1e3:.1f} mm" for k, v in worst)
    # a contained fit whose spheres were edited afterwards (the import's home fit shrinks
    # spheres that overlap at the home): growing them by their recorded margin contains
    # the meshes again, as imported with the defaults; nothing to warn about
    edited_contained = rel.method.startswith(CONTAIN_METHOD)
    if key not in _WARNED and not (mesh_margin and edited_contained):
        _WARNED.add(key)
        if mesh_margin:
            msg = (f"robot '{model.name}': its spheres approximate the collision meshes "
                   f"(the meshes poke out by up to {rel.bound * 1e3:.1f} mm: {listed}); "
                   f"{what} grows each link's spheres by its poke-out (extra margin per "
                   f"link; mesh_margin=False to plan on the spheres as they are, or import "
                   f"with containment, the default of `jwarp import-urdf`)")
        else:
            msg = (f"robot '{model.name}': its spheres approximate the collision meshes and "
                   f"mesh_margin is off: {what} keeps the spheres free, but the meshes may "
                   f"enter objects by up to {rel.bound * 1e3:.1f} mm ({listed})")
        warnings.warn(msg, MeshMarginWarning, stacklevel=3)
    if not mesh_margin:
        return model
    got = _INFLATED.get(key[0])
    if got is None:
        got = _INFLATED[key[0]] = inflated(model)
        while len(_INFLATED) > 8:
            _INFLATED.popitem(last=False)
    return got
