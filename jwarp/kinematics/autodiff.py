"""Jacobians through Warp's autodiff (``wp.Tape``): w.r.t. q, DH rows and compliances.

The hand-written kernels (:func:`jwarp.kinematics.jacobian`, :func:`jacobian_dh`) are the
fast path for rigid kinematics. This module differentiates the *elastic* model, where the
frames depend on the compliances through the torque-equilibrium iteration: the tape
records every torque update, so the result is the exact derivative of the iterated
model (the implicit derivative once the iteration has converged).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import warp as wp

from jwarp.core.arrays import finite_as, real_array, real_number
from jwarp.core.types import ArrayLike, DeviceLike, DTypeLike
from jwarp.kernels import fk as fk_kernels
from jwarp.kinematics.launch import ElasticLaunch, kappa_array, launch_fk, setup
from jwarp.model import RobotModel
from jwarp.utils.checks import check_int

WRT = ("q", "dh", "kappa")


def _rows_batched(a: np.ndarray, B: int, n: int, width: int, name: str) -> np.ndarray:
    a = real_array(a, name)
    if a.shape == (n, width):
        a = np.broadcast_to(a, (B, n, width))
    if a.shape != (B, n, width):
        raise ValueError(f"{name}: expected shape ({n}, {width}) or ({B}, {n}, {width}), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name}: contains NaN or inf")
    return np.ascontiguousarray(a)


def record_frames(t: Any, q: wp.array, dh: wp.array, kappa: wp.array | None, lam: float,
                  iterations: int) -> wp.array:
    """Launch (rigid or elastic) FK with per-configuration ``dh`` (B, n, 5) and ``kappa``
    (B, n, 3); call inside a ``wp.Tape``. ``iterations`` fixed torque updates."""
    if kappa is None or iterations == 0:
        out = wp.empty(q.shape[0:1] + (t.robot.n_frames,), dtype=fk_kernels.kernels(t.scalar).mat44,
                       device=t.device, requires_grad=True)
        return launch_fk(t, q, dh=(dh, 1), frames=out)
    run = ElasticLaunch(t, q, (kappa, 1), (dh, 1), lam, requires_grad=True)
    rho = None
    for _ in range(iterations):
        _, rho_new, _ = run.step(rho)
        rho = (rho_new, 1)
    return run.frames_at(rho)


def tape_jacobian(robot: RobotModel, q: ArrayLike, frame: int | str, *, point: Any = None,
                  kappa: ArrayLike | None = None, iterations: int = 0, lam: float = 1.0, dh: Any = None,
                  wrt: tuple[str, ...] = WRT, device: DeviceLike = None,
                  dtype: DTypeLike = np.float64) -> dict[str, np.ndarray]:
    """Jacobians of a frame's pose (or a point in it) by reverse-mode autodiff.

    Args:
        robot, q: robot and joint values (B, n_dof) (numpy).
        frame: target frame name or index; ``point`` (3,) [m] in its coordinates.
        kappa: compliances (see :func:`jwarp.kinematics.kappa_array`); used when
            ``iterations`` > 0 (elastic FK with that many torque updates).
        dh: geometric DH rows (n_frames, 5) or (B, n_frames, 5); default nominal.
        wrt: any of "q", "dh", "kappa".

    Returns:
        ``{"q": (B, 6, n_dof), "dh": (B, 6, n_frames, 5), "kappa": (B, 6, n_frames, 3)}``
        (only the requested keys); rows [linear; angular] in the base frame, the angular
        rows being ``vee(dR R^T)``.
    """
    bad = set(wrt) - set(WRT)
    if bad:
        raise ValueError(f"wrt: unknown {sorted(bad)}; choose from {WRT}")
    check_int(iterations, "iterations", 0)
    lam = real_number(lam, "lam")
    if not 0.0 < lam <= 1.0:
        raise ValueError(f"lam: damping must be in (0, 1], got {lam!r}")
    model, batch, t = setup(robot, q, device, dtype)
    fi = model.frame_index(frame)
    B, n = batch.size, model.n_frames
    npdt = np.float32 if t.scalar == wp.float32 else np.float64
    pt = np.zeros(3) if point is None else real_array(point, "point")
    if pt.shape != (3,) or not np.all(np.isfinite(pt)):
        raise ValueError(f"point: expected 3 finite numbers [m], got {point!r}")
    pt = finite_as(pt, npdt, "point").astype(np.float64)
    q_w: wp.array = wp.array(batch.array.numpy(), dtype=t.scalar, device=t.device,
                             requires_grad=True)
    dh_np = _rows_batched(model.dh_table if dh is None else dh, B, n, 5, "dh")
    dh_w: wp.array = wp.array(finite_as(dh_np, npdt, "dh"), dtype=t.scalar, device=t.device,
                              requires_grad=True)
    kap_np = _rows_batched(kappa_array(model, kappa), B, n, 3, "kappa")
    kap_w: wp.array = wp.array(finite_as(kap_np, npdt, "kappa"), dtype=t.scalar,
                               device=t.device, requires_grad=True)
    tape = wp.Tape()
    with tape:
        frames = record_frames(t, q_w, dh_w, kap_w, float(lam), int(iterations))
    R = frames.numpy()[:, fi, :3, :3]
    mat44 = fk_kernels.kernels(t.scalar).mat44
    params = {"q": q_w, "dh": dh_w, "kappa": kap_w}
    # d(entry)/d(param) for the 3 point coordinates and the 9 rotation entries
    grads: dict[str, list] = {k: [] for k in wrt}
    seeds = []
    for r in range(3):
        s = np.zeros((B, n, 4, 4))
        s[:, fi, r, 3] = 1.0
        s[:, fi, r, :3] = pt
        seeds.append(s)
    for r in range(3):
        for c in range(3):
            s = np.zeros((B, n, 4, 4))
            s[:, fi, r, c] = 1.0
            seeds.append(s)
    for s in seeds:
        tape.backward(grads={frames: wp.array(s.astype(npdt), dtype=mat44, device=t.device)})
        for k in wrt:
            grads[k].append(params[k].grad.numpy().reshape(B, -1).astype(np.float64).copy())
        tape.zero()
    out = {}
    shapes = {"q": (model.n_dof,), "dh": (n, 5), "kappa": (n, 3)}
    for k in wrt:
        g = np.stack(grads[k], axis=1)  # (B, 12, P)
        lin = g[:, :3]
        dR = g[:, 3:].reshape(B, 3, 3, -1)  # dR[b, r, c, p]
        A = np.einsum("brcp,bjc->brjp", dR, R)  # dR R^T
        ang = np.stack([A[:, 2, 1] - A[:, 1, 2], A[:, 0, 2] - A[:, 2, 0],
                        A[:, 1, 0] - A[:, 0, 1]], axis=1) * 0.5
        out[k] = np.concatenate([lin, ang], axis=1).reshape((B, 6) + shapes[k])
    return out
