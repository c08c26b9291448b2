"""Independent plain-numpy reference for kinematics, gravity torques and elastic FK.

Written from the conventions in SPEC.md only; it deliberately imports nothing from
``jwarp``. A model is read duck-typed through these attributes alone:
``frames`` (``name``, ``parent``, ``kind``, ``dh``, ``coupling``, ``transform``),
``joints`` (``type``, ``lower``, ``upper``), ``masses`` (``frame``, ``mass``, ``com``),
``gravity``, ``kappa``, ``n_frames``, ``n_dof``.

Conventions
-----------
* DH row ``[d, theta, r, alpha, beta]``::

      parent_T_child = Rot_y(beta) @ Rot_x(alpha) @ Trans_x(r) @ Rot_z(theta + qi) @ Trans_z(d)

  with ``qi = sum(coef * q[j])`` over ``frame.coupling``; a prismatic joint adds ``qi``
  to ``d`` instead of ``theta``.
* Gravity torques of the subtree of frame ``i`` (i and all descendants):
  ``tau_beta`` about ``R_par @ e_y`` through the parent origin, ``tau_alpha`` about
  ``R_par @ Rot_y(beta_i) @ e_x`` through the parent origin, ``tau_theta`` about the
  z-axis of frame ``i`` through its origin. Output column order ``[alpha, beta, theta]``.
* Elastic FK: ``rho_n = (1 - lam) rho_{n-1} + lam (rho_0 + K tau(F(q, rho_{n-1})))``.

Everything is float64 and vectorised over the batch.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "rot_x", "rot_y", "rot_z", "trans",
    "parent_first_order", "subtree_matrix", "nominal_dh", "coupling_matrix",
    "prismatic_mask", "ref_local_transforms", "ref_fk", "ref_torques",
    "ref_fk_elastic", "ref_jacobian_fd", "sample_q", "frame_id", "kappa_uniform",
]

# DH column indices
D, THETA, R, ALPHA, BETA = range(5)


# ----------------------------------------------------------------- elementary
def rot_x(a):
    """(..., 4, 4) homogeneous rotation about x by angle(s) ``a``."""
    a = np.asarray(a, np.float64)
    c, s = np.cos(a), np.sin(a)
    T = np.zeros(a.shape + (4, 4))
    T[..., 0, 0] = 1.0
    T[..., 1, 1], T[..., 1, 2] = c, -s
    T[..., 2, 1], T[..., 2, 2] = s, c
    T[..., 3, 3] = 1.0
    return T


def rot_y(a):
    a = np.asarray(a, np.float64)
    c, s = np.cos(a), np.sin(a)
    T = np.zeros(a.shape + (4, 4))
    T[..., 0, 0], T[..., 0, 2] = c, s
    T[..., 1, 1] = 1.0
    T[..., 2, 0], T[..., 2, 2] = -s, c
    T[..., 3, 3] = 1.0
    return T


def rot_z(a):
    a = np.asarray(a, np.float64)
    c, s = np.cos(a), np.sin(a)
    T = np.zeros(a.shape + (4, 4))
    T[..., 0, 0], T[..., 0, 1] = c, -s
    T[..., 1, 0], T[..., 1, 1] = s, c
    T[..., 2, 2] = 1.0
    T[..., 3, 3] = 1.0
    return T


def trans(x=0.0, y=0.0, z=0.0):
    """(..., 4, 4) homogeneous translation; arguments broadcast."""
    x, y, z = np.broadcast_arrays(*(np.asarray(v, np.float64) for v in (x, y, z)))
    T = np.zeros(x.shape + (4, 4))
    T[..., 0, 0] = T[..., 1, 1] = T[..., 2, 2] = T[..., 3, 3] = 1.0
    T[..., 0, 3], T[..., 1, 3], T[..., 2, 3] = x, y, z
    return T


# ----------------------------------------------------------- model reading
def _parent(model, i):
    p = model.frames[i].parent
    return -1 if p is None else int(p)


def parent_first_order(model):
    """Frame indices with every parent before its children (computed from scratch)."""
    n = len(model.frames)
    depth = np.full(n, -1)
    for i in range(n):
        # walk up to a frame of known depth (or the root), then fill back down
        chain, j = [], i
        while j >= 0 and depth[j] < 0:
            chain.append(j)
            j = _parent(model, j)
            if len(chain) > n:
                raise ValueError("reference: cycle in the frame tree")
        base = -1 if j < 0 else depth[j]
        for k in reversed(chain):
            base += 1
            depth[k] = base
    return [int(i) for i in np.argsort(depth, kind="stable")]


def subtree_matrix(model):
    """(n_frames, n_frames) float: ``S[i, j] = 1`` if j is i or a descendant of i."""
    n = len(model.frames)
    S = np.zeros((n, n))
    for j in range(n):
        i = j
        while i >= 0:
            S[i, j] = 1.0
            i = _parent(model, i)
    return S


def nominal_dh(model):
    """(n_frames, 5) nominal DH rows (zeros for static frames)."""
    out = np.zeros((len(model.frames), 5))
    for i, f in enumerate(model.frames):
        if f.kind == "dh":
            row = np.asarray(f.dh, np.float64).ravel()
            out[i, : row.size] = row
    return out


def coupling_matrix(model):
    """(n_frames, n_dof) matrix C with ``qi = C[i] @ q``."""
    C = np.zeros((len(model.frames), len(model.joints)))
    for i, f in enumerate(model.frames):
        if f.kind == "dh":
            for j, c in f.coupling:
                C[i, int(j)] += float(c)
    return C


def prismatic_mask(model):
    """(n_frames,) bool: the frame's joint value goes into d (prismatic)."""
    return np.array([f.kind == "dh" and any(model.joints[int(j)].type == "prismatic"
                                             for j, _ in f.coupling)
                     for f in model.frames], bool)


def frame_id(model, frame):
    """Frame index from an int or a frame name (looked up in ``model.frames``)."""
    if isinstance(frame, str):
        names = [f.name for f in model.frames]
        return names.index(frame)
    return int(frame)


def _batch_dh(model, dh, B):
    if dh is None:
        dh = nominal_dh(model)
    dh = np.asarray(dh, np.float64)
    if dh.ndim == 2:
        dh = np.broadcast_to(dh, (B,) + dh.shape)
    assert dh.shape == (B, len(model.frames), 5), dh.shape
    return dh


# ------------------------------------------------------------------ FK
def ref_local_transforms(model, q, dh=None):
    """(B, n_frames, 4, 4) parent_T_child of every frame."""
    q = np.atleast_2d(np.asarray(q, np.float64))
    B = q.shape[0]
    dh = _batch_dh(model, dh, B)
    qi = q @ coupling_matrix(model).T  # (B, nf)
    pris = prismatic_mask(model)
    d = dh[..., D] + np.where(pris, qi, 0.0)
    th = dh[..., THETA] + np.where(pris, 0.0, qi)
    local = (rot_y(dh[..., BETA]) @ rot_x(dh[..., ALPHA]) @ trans(x=dh[..., R])
             @ rot_z(th) @ trans(z=d))
    for i, f in enumerate(model.frames):
        if f.kind == "static":
            local[:, i] = np.asarray(f.transform, np.float64)
    return local


def ref_fk(model, q, dh=None):
    """World transforms of all frames, (B, n_frames, 4, 4).

    ``q`` (B, n_dof); ``dh`` None, (n_frames, 5) or (B, n_frames, 5).
    """
    local = ref_local_transforms(model, q, dh)
    F = np.empty_like(local)
    for i in parent_first_order(model):
        p = _parent(model, i)
        F[:, i] = local[:, i] if p < 0 else F[:, p] @ local[:, i]
    return F


# ------------------------------------------------------------- torques
def ref_torques(model, frames, dh=None):
    """Gravity torques ``[tau_alpha, tau_beta, tau_theta]`` (B, n_frames, 3) [N m].

    Sum over all masses in the subtree of each dh frame; zero rows for static frames.
    """
    F = np.asarray(frames, np.float64)
    B, nf = F.shape[:2]
    dh = _batch_dh(model, dh, B)
    g = np.asarray(model.gravity, np.float64).reshape(3)
    tau = np.zeros((B, nf, 3))
    if not model.masses:
        return tau
    mf = np.array([int(m.frame) for m in model.masses])
    mm = np.array([float(m.mass) for m in model.masses])
    mc = np.array([np.asarray(m.com, np.float64) for m in model.masses])  # (nm, 3)
    # world positions of the masses, (B, nm, 3)
    Fm = F[:, mf]  # (B, nm, 4, 4)
    w = np.einsum("bmij,mj->bmi", Fm[..., :3, :3], mc) + Fm[..., :3, 3]
    force = mm[:, None] * g[None, :]  # (nm, 3)
    # membership: M[i, m] = 1 if mass m sits in the subtree of frame i
    M = subtree_matrix(model)[:, mf]  # (nf, nm)
    moment_origin = np.einsum("im,bmk->bik", M, np.cross(w, force[None]))  # about world origin
    fsum = M @ force  # (nf, 3)

    def moment_about(p):  # p (B, nf, 3): sum (w - p) x f = sum w x f - p x sum f
        return moment_origin - np.cross(p, fsum[None])

    # parent transforms (identity for roots)
    par = np.array([_parent(model, i) for i in range(nf)])
    P = np.broadcast_to(np.eye(4), (B, nf, 4, 4)).copy()
    has = par >= 0
    P[:, has] = F[:, par[has]]
    R_par, p_par = P[..., :3, :3], P[..., :3, 3]
    b = dh[..., BETA]
    e_beta = R_par[..., :, 1]
    e_alpha_local = np.stack([np.cos(b), np.zeros_like(b), -np.sin(b)], axis=-1)
    e_alpha = np.einsum("bnij,bnj->bni", R_par, e_alpha_local)
    e_theta = F[..., :3, 2]
    m_par = moment_about(p_par)
    m_own = moment_about(F[..., :3, 3])
    tau[..., 0] = np.einsum("bni,bni->bn", m_par, e_alpha)
    tau[..., 1] = np.einsum("bni,bni->bn", m_par, e_beta)
    tau[..., 2] = np.einsum("bni,bni->bn", m_own, e_theta)
    is_dh = np.array([f.kind == "dh" for f in model.frames])
    tau[:, ~is_dh] = 0.0
    return tau


def _apply_compliance(kappa, tau):
    """(B, nf, 5) DH offsets from torques: K(tau)."""
    delta = np.zeros(tau.shape[:2] + (5,))
    delta[..., ALPHA] = kappa[..., 0] * tau[..., 0]
    delta[..., BETA] = kappa[..., 1] * tau[..., 1]
    delta[..., THETA] = kappa[..., 2] * tau[..., 2]
    return delta


def ref_fk_elastic(model, q, kappa=None, n_iter=20, lam=1.0, history=False):
    """Elastic FK by the damped fixed-point iteration (thesis eq. 2.31/2.35).

    Returns ``(frames (B, nf, 4, 4), rho (B, nf, 5))`` after ``n_iter`` updates, or with
    ``history=True`` also the list ``[rho_0, rho_1, ..., rho_n]``.
    ``kappa`` (n_frames, 3) [rad/(N m)] in column order [alpha, beta, theta]; default
    ``model.kappa``. Static frames never bend (their torques are zero).
    """
    q = np.atleast_2d(np.asarray(q, np.float64))
    B, nf = q.shape[0], len(model.frames)
    kappa = np.asarray(model.kappa if kappa is None else kappa, np.float64)
    kappa = np.broadcast_to(kappa, (nf, 3))
    rho0 = np.broadcast_to(nominal_dh(model), (B, nf, 5)).copy()
    rho = rho0.copy()
    hist = [rho.copy()]
    for _ in range(int(n_iter)):
        F = ref_fk(model, q, rho)
        target = rho0 + _apply_compliance(kappa, ref_torques(model, F, rho))
        rho = (1.0 - lam) * rho + lam * target
        hist.append(rho.copy())
    F = ref_fk(model, q, rho)
    return (F, rho, hist) if history else (F, rho)


def kappa_uniform(model, value):
    """(n_frames, 3) compliance ``value`` on all three axes of every dh frame."""
    k = np.zeros((len(model.frames), 3))
    for i, f in enumerate(model.frames):
        if f.kind == "dh":
            k[i] = value
    return k


# ------------------------------------------------------------- Jacobian
def _vee(A):
    """Axial vector of the skew-symmetric part of (..., 3, 3)."""
    S = 0.5 * (A - np.swapaxes(A, -1, -2))
    return np.stack([S[..., 2, 1], S[..., 0, 2], S[..., 1, 0]], axis=-1)


def ref_jacobian_fd(model, q, frame_index, eps=1e-6, dh=None):
    """Geometric Jacobian of one frame by central differences, (B, 6, n_dof).

    Rows 0-2: d position / d q_j; rows 3-5: angular velocity vee((dR/dq_j) R^T); all in
    the base (world) frame.
    """
    q = np.atleast_2d(np.asarray(q, np.float64))
    B, n = q.shape
    k = frame_id(model, frame_index)
    R0 = ref_fk(model, q, dh)[:, k, :3, :3]
    J = np.zeros((B, 6, n))
    for j in range(n):
        dq = np.zeros(n)
        dq[j] = eps
        Fp = ref_fk(model, q + dq, dh)[:, k]
        Fm = ref_fk(model, q - dq, dh)[:, k]
        J[:, :3, j] = (Fp[:, :3, 3] - Fm[:, :3, 3]) / (2 * eps)
        dR = (Fp[:, :3, :3] - Fm[:, :3, :3]) / (2 * eps)
        J[:, 3:, j] = _vee(dR @ np.swapaxes(R0, -1, -2))
    return J


# ------------------------------------------------------------- sampling
def central_difference_grad(value, q, h=1e-6):
    """(B, n) central differences of ``value(q)`` (B,) w.r.t. each column of ``q`` (B, n),
    step ``h``: the reference for analytic gradients of batched objectives."""
    q = np.asarray(q, np.float64)
    fd = np.zeros_like(q)
    for j in range(q.shape[1]):
        e = np.zeros(q.shape[1])
        e[j] = h
        fd[:, j] = (value(q + e) - value(q - e)) / (2 * h)
    return fd


def sample_q(model, n, seed=0, margin=0.0):
    """(n, n_dof) configurations uniform within the joint limits (shrunk by ``margin``)."""
    rng = np.random.default_rng(seed)
    lo = np.array([j.lower for j in model.joints], np.float64) + margin
    hi = np.array([j.upper for j in model.joints], np.float64) - margin
    return lo + (hi - lo) * rng.random((int(n), len(model.joints)))
