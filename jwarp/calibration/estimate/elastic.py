"""Derivatives of the elastic equilibrium (implicit function theorem), numpy float64.

The elastic model (thesis eq. 2.31-2.33) defines the DH rows in the torque equilibrium
implicitly::

    rho* = rho0 + E^T (kappa o tau(F(q, rho*)) + kappa_nl o tau_theta^3)

with ``tau`` the gravity torques (n_frames, 3) about the [alpha, beta, theta] axes of every
DH frame (see :mod:`jwarp.kernels.elastic`) and ``E^T`` placing the three elastic
components into the DH columns [alpha -> 3, beta -> 4, theta -> 1]. With ``w = kappa o tau``
restricted to the K active elastic components, the implicit function theorem gives

    (I - diag(kappa) dtau/drho E^T) dw = diag(tau) dkappa + diag(kappa) dtau/drho drho0
                                         + diag(kappa) dtau/dm dm,
    drho* = drho0 + E^T dw,

one K x K linear solve per sample. With the torque-dependent joint compliance
``kappa_nonlinear`` the ``diag(kappa)`` above is the local compliance
``kappa + 3 kappa_nl tau^2`` (:func:`effective_kappa`) and ``d w / d kappa_nl = tau^3``. This module provides ``tau`` and ``dtau/drho`` in
closed form from the frames at ``rho*``:

* A DH parameter ``(j, c)`` moves the whole subtree of frame j (j included) rigidly by a
  spatial twist ``(a, w)``: a point ``x`` moves by ``a + w x x`` (base coordinates)
  (:func:`dh_twists`).
* Torques of frames inside that subtree rotate with it against the fixed gravity:
  ``d tau = (g x w) . (axis x c)``; torques of frame j's own lateral axes (whose parent
  does not move) see only the moved masses; torques of ancestors of j see the moved first
  moment ``ds = m_j a + w x s_j`` (:func:`torque_jacobian`).
* The point masses ``m`` enter only through the torques, linearly at fixed frames: a mass
  loads every frame whose subtree carries it as a unit mass at its world position would
  (:func:`mass_torque_jacobian`).

Everything is vectorized over samples S; shapes are documented per function.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from jwarp.core.device import frame_mass_model
from jwarp.model import RobotModel

#: DH column of each elastic axis [alpha, beta, theta] (order of ``kappa`` / ``tau``)
AXIS_COLUMN = np.array([3, 4, 1])


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product over the last axis (faster than np.cross for small arrays)."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


def frame_masses(robot: RobotModel, values: np.ndarray | None = None
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Total point mass per frame (n_frames,) [kg] and its centre of mass (n_frames, 3) [m]
    in frame coordinates (several masses on one frame are merged); ``values``
    (len(robot.masses),) [kg] replaces the entries' masses (the ``mass`` group)."""
    return frame_mass_model(robot, values)


@dataclass
class TorqueState:
    """Gravity-torque quantities at one set of frames (all float64, base coordinates).

    tau (S, n, 3) [N m] about [alpha, beta, theta]; s (S, n, 3) subtree first moments
    sum m x [kg m]; m (n,) subtree masses [kg]; origin (S, n, 3); z (S, n, 3) z-axes;
    p_par (S, n, 3) parent origins; ax_a, ax_b (S, n, 3) alpha / beta torque axes;
    c_p = s - m p_par, c_t = s - m origin (S, n, 3).
    """

    tau: np.ndarray
    s: np.ndarray
    m: np.ndarray
    origin: np.ndarray
    z: np.ndarray
    p_par: np.ndarray
    ax_a: np.ndarray
    ax_b: np.ndarray
    c_p: np.ndarray
    c_t: np.ndarray


def torque_state(robot: RobotModel, frames: np.ndarray, rho: np.ndarray,
                 masses: tuple[np.ndarray, np.ndarray] | None = None) -> TorqueState:
    """Gravity torques of every DH frame at ``frames`` (S, n, 4, 4) with DH rows
    ``rho`` (S, n, 5) (only beta is read: it tilts the alpha axis). Same model as the
    elastic kernel; rows of static frames are zero. ``masses`` overrides
    :func:`frame_masses` (per frame mass (n,), com (n, 3))."""
    mass, com = frame_masses(robot) if masses is None else masses
    R = frames[..., :3, :3]
    o = frames[..., :3, 3]
    w = np.einsum("snij,nj->sni", R, com) + o
    sub = robot.subtree_mask.astype(np.float64)  # [i, j]: j in subtree of i
    s = np.einsum("ij,sjk->sik", sub, mass[None, :, None] * w)
    mt = sub @ mass
    S, n = frames.shape[:2]
    par = robot.parents
    Rp = np.broadcast_to(np.eye(3), (S, n, 3, 3)).copy()
    pp = np.zeros((S, n, 3))
    has = par >= 0
    Rp[:, has] = R[:, par[has]]
    pp[:, has] = o[:, par[has]]
    beta = rho[..., 4]
    ax_a = np.einsum("snij,snj->sni", Rp,
                     np.stack([np.cos(beta), np.zeros_like(beta), -np.sin(beta)], -1))
    ax_b = Rp[..., :, 1]
    z = R[..., :, 2]
    g = robot.gravity
    c_p = s - mt[:, None] * pp
    c_t = s - mt[:, None] * o
    arm_p = _cross(c_p, np.broadcast_to(g, c_p.shape))
    tau = np.stack([np.sum(arm_p * ax_a, -1), np.sum(arm_p * ax_b, -1),
                    np.sum(_cross(c_t, np.broadcast_to(g, c_t.shape)) * z, -1)], -1)
    tau *= robot.is_dh[None, :, None]
    return TorqueState(tau, s, mt, o, z, pp, ax_a, ax_b, c_p, c_t)


def dh_twists(robot: RobotModel, st: TorqueState) -> tuple[np.ndarray, np.ndarray]:
    """Spatial twists of every DH parameter: a change of DH entry ``(j, c)`` moves every
    point ``x`` of the subtree of frame j by ``a[:, j, c] + w[:, j, c] x x``.

    Returns a, w (S, n, 5, 3) (zero for static frames); columns [d, theta, r, alpha, beta].
    """
    S, n = st.z.shape[:2]
    a = np.zeros((S, n, 5, 3))
    w = np.zeros((S, n, 5, 3))
    a[:, :, 0] = st.z                              # d: along z_j
    w[:, :, 1] = st.z                              # theta: about z_j through o_j
    a[:, :, 1] = _cross(st.origin, st.z)
    a[:, :, 2] = st.ax_a                           # r: along Rp Rot_y(beta) e_x
    w[:, :, 3] = st.ax_a                           # alpha: about that axis through p_par
    a[:, :, 3] = _cross(st.p_par, st.ax_a)
    w[:, :, 4] = st.ax_b                           # beta: about Rp e_y through p_par
    a[:, :, 4] = _cross(st.p_par, st.ax_b)
    dh = robot.is_dh[None, :, None, None]
    return a * dh, w * dh


def torque_jacobian(robot: RobotModel, st: TorqueState,
                    twists: tuple[np.ndarray, np.ndarray] | None = None,
                    rows: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """d tau / d rho (S, n, 3, n, 5): derivative of the gravity torques [alpha, beta, theta]
    of frame i (axes 1-2) w.r.t. DH entry (j, c) (axes 3-4), frames held at F(q, rho).

    ``rows`` = (frame (K,), axis (K,)): only those torque components, returned as
    (S, K, n, 5) (= the full result's ``[:, frame, axis]``; e.g. the active elastic
    components of :class:`ElasticComponents`, all :func:`equilibrium_jacobian` reads:
    a fraction of the work and memory of the full array)."""
    a, w = dh_twists(robot, st) if twists is None else twists
    S, n = st.z.shape[:2]
    g = np.broadcast_to(robot.gravity, (S, n, 5, 3))
    gw = _cross(g, w)                                          # (S, j, c, 3)
    axes = (st.ax_a, st.ax_b, st.z)
    arms = (st.c_p, st.c_p, st.c_t)
    sub = robot.subtree_mask                                    # [j, i]: i in subtree(j)
    eye = np.eye(n, dtype=bool)
    rigid = [sub.T & ~eye, sub.T & ~eye, sub.T]                 # [i, j] masks per axis
    below = (sub & ~eye)                                       # [i, j]: j strictly below i
    ds = st.m[None, :, None, None] * a + _cross(w, st.s[:, :, None, :])   # (S, j, c, 3)
    g3 = np.broadcast_to(robot.gravity, st.z.shape)
    if rows is None:
        r_frame = np.tile(np.arange(n), 3)
        r_axis = np.repeat(np.arange(3), n)
    else:
        r_frame = np.asarray(rows[0], np.int64)
        r_axis = np.asarray(rows[1], np.int64)
    K = r_frame.size
    out = np.zeros((S, K, n, 5))
    # contiguous (S, 3, j*c): numpy's batched matmul is 2x faster than on the transposed view
    gw_t = np.ascontiguousarray(gw.reshape(S, n * 5, 3).transpose(0, 2, 1))
    ds_t = np.ascontiguousarray(ds.reshape(S, n * 5, 3).transpose(0, 2, 1))
    for k in range(3):
        sel = np.nonzero(r_axis == k)[0]
        if sel.size == 0:
            continue
        fi = r_frame[sel]
        ax_k, arm_k = axes[k][:, fi], arms[k][:, fi]
        # subtree of j moves rigidly with frame i's axis: (g x w) . (axis_i x c_i)
        h = _cross(ax_k, arm_k)                                 # (S, i, 3)
        rig = (h @ gw_t).reshape(S, sel.size, n, 5)
        rig *= rigid[k][fi][None, :, :, None]
        # j strictly below i: only the moved masses count: ds . (g x axis_i)
        ga = _cross(g3[:, fi], ax_k)                            # (S, i, 3)
        blw = (ga @ ds_t).reshape(S, sel.size, n, 5)
        blw *= below[fi][None, :, :, None]
        rig += blw
        out[:, sel] = rig
    # i == j, lateral axes: the parent (and so the axis, except for beta) stays put
    lat = np.nonzero(r_axis < 2)[0]
    if lat.size:
        fl = r_frame[lat]
        a_l, w_l = a[:, fl], w[:, fl]                           # (S, L, 5, 3)
        v_par = a_l + _cross(w_l, st.p_par[:, fl, None, :])     # velocity of p_par
        dc = _cross(w_l, st.c_p[:, fl, None, :]) + st.m[None, fl, None, None] * v_par
        gdc = _cross(dc, np.broadcast_to(robot.gravity, dc.shape))  # (S, L, c, 3)
        is_a = r_axis[lat] == 0
        axis_l = np.where(is_a[None, :, None], st.ax_a[:, fl], st.ax_b[:, fl])
        own = np.sum(gdc * axis_l[:, :, None, :], axis=-1)    # (S, L, c)
        extra = np.sum(_cross(st.c_p[:, fl], g3[:, fl]) * _cross(w_l[:, :, 4], st.ax_a[:, fl]),
                       axis=-1)
        own[:, :, 4] += np.where(is_a[None, :], extra, 0.0)
        out[:, lat, fl, :] = own
    if not np.all(robot.is_dh[r_frame]):
        out *= robot.is_dh[r_frame][None, :, None, None]
    if rows is None:
        return out.reshape(S, 3, n, n, 5).transpose(0, 2, 1, 3, 4)
    return out


def mass_torque_jacobian(robot: RobotModel, frames: np.ndarray, st: TorqueState,
                         entries: np.ndarray) -> np.ndarray:
    """d tau / d m (S, n, 3, P_m): derivative of the gravity torques [alpha, beta, theta] of
    every frame i w.r.t. the point masses ``entries`` (P_m,) (indices into
    ``robot.masses``) [N m / kg], frames held at ``frames`` (S, n, 4, 4).

    The torques are linear in each mass: entry e at world position ``w_e = R_f c_e + o_f``
    adds, to every DH frame i with f in the subtree of i, the torque of a unit mass at
    ``w_e``: ``((w_e - p_par_i) x g) . axis`` for the lateral axes and
    ``((w_e - o_i) x g) . z_i`` for the joint axis (the formula of :func:`torque_state`).
    """
    entries = np.asarray(entries, np.int64)
    S, n = st.z.shape[:2]
    out = np.zeros((S, n, 3, entries.size))
    if entries.size == 0:
        return out
    fr = np.array([robot.masses[e].frame for e in entries], np.int64)
    com = np.array([robot.masses[e].com for e in entries], np.float64).reshape(-1, 3)
    T = frames[:, fr]                                               # (S, P_m, 4, 4)
    w = np.einsum("spij,pj->spi", T[..., :3, :3], com) + T[..., :3, 3]   # (S, P_m, 3)
    g = np.broadcast_to(robot.gravity, w.shape)
    wg = _cross(w, g)                                               # w x g (S, P_m, 3)
    # (x - p) x g = x x g - p x g
    pg = _cross(st.p_par, np.broadcast_to(robot.gravity, st.p_par.shape))    # (S, n, 3)
    og = _cross(st.origin, np.broadcast_to(robot.gravity, st.origin.shape))
    for k, (axis, base) in enumerate(((st.ax_a, pg), (st.ax_b, pg), (st.z, og))):
        out[:, :, k, :] = (np.einsum("sik,spk->sip", axis, wg)
                           - np.sum(axis * base, -1)[:, :, None])
    # only frames whose subtree holds the mass's frame, only DH frames
    mask = robot.subtree_mask[:, fr] & robot.is_dh[:, None]         # (n, P_m)
    return out * mask[None, :, None, :]


@dataclass
class ElasticComponents:
    """The K elastic components (frame, axis) that can be nonzero: DH frames whose
    compliance on that axis is nonzero or free. frame (K,), axis (K,) in [alpha, beta,
    theta] order, column (K,) the DH column they displace."""

    frame: np.ndarray
    axis: np.ndarray

    @property
    def column(self) -> np.ndarray:
        return AXIS_COLUMN[self.axis]

    @property
    def size(self) -> int:
        return int(self.frame.size)

    @classmethod
    def select(cls, robot: RobotModel, kappa: np.ndarray, free: np.ndarray | None = None
               ) -> ElasticComponents:
        """Components with ``kappa != 0`` or ``free`` (bool (n, 3)) on DH frames."""
        act = (np.asarray(kappa) != 0)
        if free is not None:
            act = act | free
        act &= robot.is_dh[:, None]
        fr, ax = np.nonzero(act)
        return cls(fr.astype(np.int64), ax.astype(np.int64))


def effective_kappa(kappa: np.ndarray, kappa_nl: np.ndarray | None, tau: np.ndarray
                    ) -> np.ndarray:
    """The local compliance d(kappa o tau + kappa_nl tau_theta^3)/d tau per sample
    (S, n, 3): ``kappa`` (n, 3), on the theta axis plus ``3 kappa_nl tau_theta^2``
    (``kappa_nl`` (n,) [rad/(N m)^3], None: ``kappa`` broadcast); tau (S, n, 3)."""
    out = np.broadcast_to(np.asarray(kappa, np.float64), tau.shape).copy()
    if kappa_nl is not None:
        out[..., 2] += 3.0 * np.asarray(kappa_nl, np.float64) * tau[..., 2] ** 2
    return out


def nonlinear_b(comps: ElasticComponents, tau: np.ndarray, frames: np.ndarray) -> np.ndarray:
    """(S, K, P) right-hand sides of the nonlinear compliances of DH ``frames`` (P,):
    d w / d kappa_nl_i = tau_theta_i^3 on the theta component of frame i (which must be
    active in ``comps``)."""
    frames = np.asarray(frames, np.int64)
    S = tau.shape[0]
    out = np.zeros((S, comps.size, frames.size))
    pos = {(int(f), int(a)): k for k, (f, a) in enumerate(zip(comps.frame, comps.axis))}
    for p, i in enumerate(frames):
        k = pos.get((int(i), 2))
        if k is None:
            raise ValueError(f"comps: the theta component of frame {int(i)} is not active")
        out[:, k, p] = tau[:, i, 2] ** 3
    return out


def equilibrium_jacobian(jy_rho: np.ndarray, dtau: np.ndarray, tau: np.ndarray,
                         kappa: np.ndarray, comps: ElasticComponents,
                         dh_frame: np.ndarray, dh_col: np.ndarray,
                         kap_frame: np.ndarray, kap_axis: np.ndarray,
                         dtau_mass: np.ndarray | None = None,
                         extra_b: np.ndarray | None = None
                         ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Total derivative of observations through the equilibrium (adjoint form).

    With ``A = I - diag(kappa) dtau/drho E^T`` (K x K) one adjoint solve
    ``A^T lam = (dy/drho E^T)^T`` per sample serves every parameter: a parameter whose
    change moves the elastic components by ``A^-1 b`` contributes ``lam^T b`` with
    ``b = diag(kappa) dtau/drho0`` (DH entries), ``diag(tau)`` (compliances) or
    ``diag(kappa) dtau/dm`` (masses, which enter only through the torques).

    Args:
        jy_rho: (S, m, n, 5) dy/drho at the equilibrium rows rho* (frames fixed).
        dtau: (S, n, 3, n, 5) torque Jacobian at rho* (:func:`torque_jacobian`), or its
            rows of the components ``comps`` only, (S, K, n, 5) (``rows=`` there).
        tau: (S, n, 3) torques at rho*; kappa (n, 3) compliances [rad/(N m)], or the
            local compliances (S, n, 3) of a torque-dependent model
            (:func:`effective_kappa`).
        comps: active elastic components (must include every free kappa entry).
        dh_frame, dh_col: (P_dh,) free geometric DH entries (of rho0).
        kap_frame, kap_axis: (P_k,) free compliance entries.
        dtau_mass: (S, n, 3, P_m) torque derivatives w.r.t. free point masses
            (:func:`mass_torque_jacobian`) [N m / kg]; None: no free masses.
        extra_b: (S, K, P_x) right-hand sides ``d w / d x`` of further parameters that
            enter only through the elastic components (e.g. :func:`nonlinear_b`); their
            derivatives ``lam^T b`` are appended to the third output after the masses.

    Returns:
        (dy/d rho0[free] (S, m, P_dh), dy/d kappa[free] (S, m, P_k),
        dy/d m[free] (S, m, P_m) [unit / kg], followed by the P_x columns of ``extra_b``).
    """
    S, m = jy_rho.shape[:2]
    direct = jy_rho[:, :, dh_frame, dh_col]
    P_m = 0 if dtau_mass is None else dtau_mass.shape[-1]
    P_m += 0 if extra_b is None else extra_b.shape[-1]
    K = comps.size
    if K == 0:
        return direct, np.zeros((S, m, kap_frame.size)), np.zeros((S, m, P_m))
    fr, ax, col = comps.frame, comps.axis, comps.column
    kc = np.asarray(kappa)[..., fr, ax]                       # (K,) or (S, K)
    kc = np.broadcast_to(kc, (S, K))[:, :, None]              # (S, K, 1)
    t_rows = dtau if dtau.ndim == 4 else dtau[:, fr, ax]      # (S, K, n, 5)
    # gathers along the flattened (frame, column) axis: np.take of one contiguous axis is
    # several times faster than 2-D fancy indexing on these (S, K, n * 5) arrays
    t_flat = t_rows.reshape(S, K, -1)
    n5 = t_flat.shape[-1] // 5
    A = np.eye(K)[None] - kc * np.take(t_flat, fr * 5 + col, axis=2)  # (S, K, K)
    jy_e = np.take(jy_rho.reshape(S, m, n5 * 5), fr * 5 + col, axis=2)  # (S, m, K)
    lam = np.linalg.solve(np.swapaxes(A, 1, 2), np.swapaxes(jy_e, 1, 2))  # (S, K, m)
    lam_t = np.swapaxes(lam, 1, 2)                            # (S, m, K)
    b_dh = kc * np.take(t_flat, np.asarray(dh_frame) * 5 + np.asarray(dh_col), axis=2)  # (S, K, P_dh)
    d_dh = direct + lam_t @ b_dh
    pos = {(int(f), int(a)): k for k, (f, a) in enumerate(zip(fr, ax))}
    try:
        rows = np.array([pos[(int(f), int(a))] for f, a in zip(kap_frame, kap_axis)], np.int64)
    except KeyError as e:
        raise ValueError(f"comps: free compliance {e.args[0]} is not an active component") from None
    # b_kap[s, rows[p], p] = tau[s, frame_p, axis_p]
    t_free = tau[:, kap_frame, kap_axis]                      # (S, P_k)
    d_kap = lam[:, rows, :].transpose(0, 2, 1) * t_free[:, None, :]      # (S, m, P_k)
    b_m = np.zeros((S, K, 0)) if dtau_mass is None else kc * dtau_mass[:, fr, ax]
    if extra_b is not None:
        b_m = np.concatenate([b_m, extra_b], axis=2)
    return d_dh, d_kap, lam_t @ b_m
