"""Elastic compensation for planning and IK (elastic paper section V, thesis Fig. 2.11).

The elastic robot's frames are ``F(q, rho*)`` at the torque equilibrium
``rho* = rho0 + kappa tau(F(q, rho*))``. Inside an optimizer loop that equilibrium is not
solved to convergence: every outer iteration makes **one** damped torque update from the
DH rows ``rho`` kept from the previous iteration (the configurations move little between
iterations), and gradients treat ``rho`` as constant (d rho / dq = 0). As the optimizer
converges, so does ``rho``. :func:`jwarp.solvers.planning.plan` and
:func:`jwarp.solvers.ik.ik` implement this when given ``kappa``; this module wraps them
and measures what it costs (:func:`compare_ik`, :func:`iteration_overhead`).
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING, Any

import numpy as np

from jwarp.core.types import ArrayLike, DeviceLike
from jwarp.kinematics.equilibrium import fk_elastic
from jwarp.kinematics.launch import kappa_array
from jwarp.solvers.ik import IKObjective, IKResult, ik
from jwarp.solvers.ik.objective import as_poses
from jwarp.solvers.planning import PathObjective, PlanResult, plan
from jwarp.utils.checks import check_int

if TYPE_CHECKING:
    from jwarp.model import RobotModel
    from jwarp.world.sdf import World

#: compliance of Agile Justin's joints used by the studies [rad/(N m)] (0.1 rad/kNm)
JUSTIN_KAPPA = 1e-4


def _kappa(model: RobotModel, kappa: Any) -> Any:
    if kappa is None:
        if not np.any(model.kappa):
            raise ValueError(f"kappa: robot '{model.name}' has no compliances; pass kappa "
                             f"[rad/(N m)]")
        return model.kappa
    kappa_array(model, kappa)  # validates
    return kappa


def compensated_ik(robot: RobotModel, frame: int | str, target: Any, *, kappa: ArrayLike | None = None,
                   lam: float = 0.7, **kwargs: Any) -> IKResult:
    """:func:`jwarp.solvers.ik.ik` on the elastic model (kappa default: the robot's)."""
    model = robot
    return ik(model, frame, target, kappa=_kappa(model, kappa), lam=lam, **kwargs)


def compensated_plan(robot: RobotModel, world: World, start: Any, goal: Any, *, kappa: ArrayLike | None = None,
                     lam: float = 0.7, **kwargs: Any) -> PlanResult:
    """:func:`jwarp.solvers.planning.plan` on the elastic model (kappa default: the robot's)."""
    model = robot
    return plan(model, world, start, goal, kappa=_kappa(model, kappa), lam=lam, **kwargs)


def equilibrium_pose_error(robot: RobotModel, frame: int | str, q: ArrayLike, target: Any, kappa: ArrayLike,
                           device: DeviceLike = None, lam: float = 0.7
                           ) -> tuple[np.ndarray, np.ndarray]:
    """Pose error of ``frame`` at q (..., n_dof) on the fully converged elastic model
    (``fk_elastic`` with damping ``lam`` to 1e-12 rad) against ``target`` (..., 4, 4):
    (position [m], rotation angle [rad]) per configuration - an independent check of a
    compensated IK. NaN where the iteration does not converge in 400 steps (a robot so
    soft that the damped iteration oscillates: lower ``lam``)."""
    from scipy.spatial.transform import Rotation

    model = robot
    fi = model.frame_index(frame)
    q = np.asarray(q, np.float64)
    res = fk_elastic(model, q, kappa, lam=lam, max_iter=400, tol=1e-12, device=device,
                     dtype=np.float64)
    F = np.where(np.asarray(res.converged)[..., None, None],
                 np.asarray(res.frames)[..., fi, :, :], np.nan)
    T = np.asarray(target, np.float64)
    pos = np.linalg.norm(F[..., :3, 3] - T[..., :3, 3], axis=-1)
    R = (F[..., :3, :3] @ np.swapaxes(T[..., :3, :3], -1, -2)).reshape(-1, 3, 3)
    ok = np.isfinite(R).all(axis=(1, 2))
    ang = np.full(len(R), np.nan)
    if ok.any():
        ang[ok] = Rotation.from_matrix(R[ok]).magnitude()
    return pos, ang.reshape(pos.shape)


def compare_ik(robot: RobotModel, frame: int | str, targets: ArrayLike, kappa: ArrayLike, *, n_starts: int = 8,
               seed: int = 0, lam: float = 0.7, **kwargs: Any) -> dict:
    """Rigid vs compensated IK from the same random seeds (no early stop, so every start
    runs until it is on the target): mean iterations of the starts that succeed in both,
    success counts, and the equilibrium error of the compensated solutions."""
    model = robot
    targets = as_poses(targets)
    common = dict(n_starts=n_starts, seed=seed, stop_when_solved=False, **kwargs)
    rigid = ik(model, frame, targets, **common)
    soft = ik(model, frame, targets, kappa=kappa, lam=lam, **common)
    both = rigid.all_feasible & soft.all_feasible
    pos, ang = equilibrium_pose_error(model, frame, soft.q, targets, kappa,
                                      device=kwargs.get("device"), lam=lam)
    it_r = float(rigid.all_iterations[both].mean()) if both.any() else float("nan")
    it_s = float(soft.all_iterations[both].mean()) if both.any() else float("nan")
    return {"starts_both": int(both.sum()), "rigid_feasible": int(rigid.all_feasible.sum()),
            "elastic_feasible": int(soft.all_feasible.sum()),
            "rigid_iterations": it_r, "elastic_iterations": it_s,
            "iteration_ratio": it_s / it_r if both.any() else float("nan"),
            "elastic_equilibrium_pos_err_max_m": float(np.max(pos[soft.feasible]))
            if np.any(soft.feasible) else float("nan"),
            "elastic_equilibrium_rot_err_max_rad": float(np.max(ang[soft.feasible]))
            if np.any(soft.feasible) else float("nan"),
            # solutions whose full equilibrium the check could not solve (NaN errors)
            "elastic_equilibrium_unsolved": int(np.sum(np.isnan(pos[soft.feasible])))}


def iteration_overhead(objective_rigid: Any, objective_elastic: Any, *, repeats: int = 200,
                       rounds: int = 7) -> dict:
    """Time per evaluation (+ step) of a rigid and an elastic objective of the same size
    (:class:`PathObjective` or :class:`IKObjective`, already filled): seconds per
    iteration (the best of ``rounds`` interleaved runs of ``repeats`` iterations each) and
    the relative overhead of the torque update."""
    def one(obj: Any) -> None:
        if isinstance(obj, PathObjective):
            obj.evaluate()
            obj.step(1e-6, 1e-6)
        else:
            obj.evaluate_pose()
            obj.evaluate_aux()

    import warp as wp

    objs = {"rigid": objective_rigid, "elastic": objective_elastic}
    best = dict.fromkeys(objs, float("inf"))
    for obj in objs.values():
        one(obj)
        wp.synchronize_device(obj.device)
    for _ in range(rounds):  # interleaved, so both see the same machine load
        for name, obj in objs.items():
            t0 = time.perf_counter()
            for _ in range(repeats):
                one(obj)
            wp.synchronize_device(obj.device)  # CUDA launches are asynchronous
            best[name] = min(best[name], (time.perf_counter() - t0) / repeats)
    out = {f"{name}_s": t for name, t in best.items()}
    out["overhead"] = out["elastic_s"] / out["rigid_s"] - 1.0
    return out


def ik_iteration_overhead(robot: RobotModel, frame: int | str, kappa: ArrayLike, *, world: World | None = None,
                          n_starts: int = 64, iterations: int = 60, rounds: int = 9,
                          lam: float = 0.7, **kwargs: Any) -> dict:
    """Wall time per iteration of the whole IK solver (:func:`jwarp.solvers.ik.ik`: kernels,
    host reads and the damped least-squares step), rigid and compensated, interleaved.
    The target lies out of reach, so every start runs all ``iterations`` (no early stop,
    no feasibility checks). Per run, the time per iteration is the median interval between
    the solver's per-iteration callbacks (after the first 5), which leaves out the set-up
    of a call; ``*_s`` is the median over ``rounds`` runs, ``overhead`` their ratio - 1
    and ``overhead_per_round`` the ratios of the runs. ``*_setup_s``: the rest of a call's
    wall time (objective, buffers, seeds; median)."""
    check_int(iterations, "iterations", 2)
    model = robot
    fi = model.frame_index(frame)
    target = np.eye(4)
    target[:3, 3] = [10.0, 0.0, 0.0]  # 10 m away
    common = dict(world=world, n_starts=n_starts, iterations=iterations,
                  stop_when_solved=False, seed=0, **kwargs)
    per_it: dict = {"rigid": [], "elastic": []}
    setup: dict = {"rigid": [], "elastic": []}
    for r in range(rounds + 1):
        for name in per_it:
            stamps: list = []
            res = ik(model, fi, target, kappa=None if name == "rigid" else kappa, lam=lam,
                     callback=lambda it, q: stamps.append(time.perf_counter()),  # noqa: B023
                     **common)  # (called during this round's ik only)
            if r:  # round 0 warms up (kernel compiles)
                dt = np.diff(stamps)
                per_it[name].append(float(np.median(dt[min(5, len(dt) // 2):])))
                setup[name].append(res.wall_time - float(np.sum(dt)))
    out: dict[str, Any] = {f"{name}_s": float(np.median(v)) for name, v in per_it.items()}
    out["overhead"] = out["elastic_s"] / out["rigid_s"] - 1.0
    out["overhead_per_round"] = [e / g - 1.0 for g, e in zip(per_it["rigid"], per_it["elastic"])]
    out.update({f"{name}_setup_s": float(np.median(v)) for name, v in setup.items()})
    return out


__all__ = ["JUSTIN_KAPPA", "compare_ik", "ik_iteration_overhead", "compensated_ik", "compensated_plan",
           "equilibrium_pose_error", "iteration_overhead", "IKObjective", "PathObjective"]
