"""Task-oriented weighting (TOW, thesis 2.3.3, eqs. 2.9-2.16 and 2.22).

The calibration measures ``y_a = h_a(q, Theta)`` (the *actual* measurement, e.g. image
pixels) but should be accurate in ``y_t = h_t(q, Theta)`` (the *task*, e.g. cartesian
marker positions). Linearized at one sample, actual, task and any shared upstream
quantities are nodes of a linear Gaussian graph (eq. 2.12)::

    x_i ~ N(sum_{j in pa_i} W_ij x_j + b_i, Lambda_i)

:class:`MeasurementGraph` builds the joint mean and covariance (eq. 2.13) in topological
order, gives marginals, cross covariances and conditionals (eq. 2.14), and
:func:`adjusted_covariance` the covariance of the actual measurement with the task's virtual
noise ``V`` (``bar Lambda_t^e``) propagated into it (eq. 2.11)::

    hat Lambda_a = Lambda_a + Lambda_at Lambda_t^-1 V Lambda_t^-1 Lambda_ta

(:func:`task_space_covariance` is the alternative form 2.22). All arrays may carry leading
batch dimensions (one graph per sample: ``W`` (S, d_i, d_j), ``Lambda`` (S, d_i, d_i)).
The closed forms of the special cases are :func:`sequential_covariance` (2.15, the actual
follows the task) and :func:`reverse_covariance` (2.16, the task follows the actual).

Plugins (:func:`frame_twist_jacobians`, :func:`tow_covariance`): both measurements see the
robot through the twists ``xi`` of their frames (``measurement.jacobians``:
``dy = J_f xi``). For the frames ``F`` of the task plugin, ``dy_t = Jt_F xi_F`` and
``dy_a = Ja_F xi_F + (terms of frames the task does not see)``. When the actual observes
the task's points (image pixels of the marker the cartesian task measures), a twist of
``F`` reaches ``y_a`` only through ``y_t``: ``Ja_F = tJa Jt_F`` and, ``Jt_F`` having full
row rank, ``tJa = Ja_F Jt_F^+`` (Moore-Penrose). For the cartesian task (tracker rotation
``R``) and the image (``du/dx_w = B``): ``Jt_F = R^T G``, ``Ja_F = B G`` with ``G = [I |
-[x_w - p_F]x]`` of full row rank, so ``tJa = B G G^+ R = B R``; at the image centre
``B = f / z [I_2 | 0] R_c^T``: the virtual variance added to a pixel is ``(f/z)^2 v^2``,
the weight of far markers grows as ``z^2`` (the thesis' 1/z^2 factor on the covariance).
The graphs built per sample (``graph`` of :class:`TowSpec`):

* ``sequential`` (default, Fig. 2.7 1a): ``y_t ~ N(., Lambda_t)``, ``y_a = tJa y_t +
  N(0, Lambda_a)`` with ``tJa = Ja_F Jt_F^+``; the fit ``Ja_F ~= tJa Jt_F`` is checked
  (relative residual above ``tolerance`` -> ValueError naming the sample: the actual does
  not follow the task, use ``shared``).
* ``reverse`` (Fig. 2.7 2): ``y_a ~ N(., Lambda_a)``, ``y_t = aJt^T y_a + N(0, Lambda_t)``
  with ``aJt^T = Jt_F Ja_F^+``.
* ``shared`` (Fig. 2.7 3): an upstream node ``xi_F ~ N(0, diag(twist_sigma^2))`` (the
  frame twists) with ``y_a = Ja_F xi_F + N(0, Lambda_a)`` and ``y_t = Jt_F xi_F +
  N(0, Lambda_t)``.

``Lambda_a`` and ``Lambda_t`` are the plugins' ``noise^2`` (diagonal); the graph's marginal
of ``y_a`` (which includes what flows in from upstream nodes) is the ``Lambda_a`` of
eq. 2.11. The result, one (m_a, m_a) block per sample, is what
:class:`~jwarp.calibration.estimate.map.CalibrationProblem` takes as ``covariance``.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, cast

import numpy as np

from jwarp.model import RobotModel
from jwarp.model.measurement import Measurement

#: graphs :func:`tow_covariance` builds per sample
GRAPHS = ("sequential", "reverse", "shared")


# ------------------------------------------------------------------- the graph
@dataclass
class GaussianNode:
    """A linear Gaussian node (eq. 2.12): ``x ~ N(sum_j W[j] x_j + b, cov)``.

    name: unique node name; dim: its size d; cov: (..., d, d) own covariance Lambda_i;
    parents: {parent name: W (..., d, d_parent)}; b: (..., d) offset (default 0).
    """

    name: str
    dim: int
    cov: Any
    parents: Mapping[str, Any] = field(default_factory=dict)
    b: Any = None


class MeasurementGraph:
    """A DAG of :class:`GaussianNode` with the joint distribution of eq. 2.13.

    Raises ValueError naming the node for: duplicate names, an unknown parent, a cycle,
    a block of the wrong size (``W`` not (d, d_parent), ``cov`` not (d, d), ``b`` not
    (d,)), a covariance that is not symmetric or has NaN/inf.
    """

    def __init__(self, nodes: Iterable[GaussianNode]) -> None:
        nodes = list(nodes)
        self.nodes: dict[str, GaussianNode] = {}
        for n in nodes:
            if not isinstance(n, GaussianNode):
                raise TypeError(f"nodes: expected GaussianNode, got {type(n).__name__}")
            if n.name in self.nodes:
                raise ValueError(f"node '{n.name}': duplicate name")
            if isinstance(n.dim, bool) or not isinstance(n.dim, (int, np.integer)) or n.dim < 1:
                raise ValueError(f"node '{n.name}': dim must be an integer >= 1, got {n.dim!r}")
            self.nodes[n.name] = n
        for n in nodes:
            for p in n.parents:
                if p not in self.nodes:
                    raise ValueError(f"node '{n.name}': unknown parent '{p}' (nodes: "
                                     f"{', '.join(self.nodes)})")
        self.order = self._topological()
        self._W: dict[str, dict[str, np.ndarray]] = {}
        self._cov: dict[str, np.ndarray] = {}
        self._b: dict[str, np.ndarray] = {}
        batch: tuple[int, ...] = ()
        for name in self.order:
            n = self.nodes[name]
            c = np.asarray(n.cov, np.float64)
            if c.ndim < 2 or c.shape[-2:] != (n.dim, n.dim):
                raise ValueError(f"node '{name}': cov must be (..., {n.dim}, {n.dim}), got "
                                 f"{c.shape}")
            if not np.all(np.isfinite(c)):
                raise ValueError(f"node '{name}': cov has NaN or inf")
            if np.abs(c - np.swapaxes(c, -1, -2)).max(initial=0) > 1e-9 * max(
                    np.abs(c).max(initial=0), 1e-300):
                raise ValueError(f"node '{name}': cov is not symmetric")
            self._cov[name] = c
            batch = np.broadcast_shapes(batch, c.shape[:-2])
            self._W[name] = {}
            for p, w in n.parents.items():
                w = np.asarray(w, np.float64)
                dp = self.nodes[p].dim
                if w.ndim < 2 or w.shape[-2:] != (n.dim, dp):
                    raise ValueError(f"node '{name}': W from parent '{p}' must be (..., "
                                     f"{n.dim}, {dp}), got {w.shape}")
                if not np.all(np.isfinite(w)):
                    raise ValueError(f"node '{name}': W from parent '{p}' has NaN or inf")
                self._W[name][p] = w
                batch = np.broadcast_shapes(batch, w.shape[:-2])
            b = np.zeros(n.dim) if n.b is None else np.asarray(n.b, np.float64)
            if b.ndim < 1 or b.shape[-1] != n.dim:
                raise ValueError(f"node '{name}': b must be (..., {n.dim}), got {b.shape}")
            self._b[name] = b
        self.batch = batch
        self.slices: dict[str, slice] = {}
        k = 0
        for name in self.order:
            self.slices[name] = slice(k, k + self.nodes[name].dim)
            k += self.nodes[name].dim
        self.size = k
        self._joint: tuple[np.ndarray, np.ndarray] | None = None

    def _topological(self) -> list[str]:
        """Depth-first topological order; a cycle -> ValueError naming its nodes."""
        state: dict[str, int] = {}
        order: list[str] = []

        def visit(name: str, path: list[str]) -> None:
            s = state.get(name, 0)
            if s == 2:
                return
            if s == 1:
                cyc = path[path.index(name):] + [name]
                raise ValueError(f"node '{name}': the graph has a cycle "
                                 f"{' -> '.join(reversed(cyc))}")
            state[name] = 1
            for p in self.nodes[name].parents:
                visit(p, path + [name])
            state[name] = 2
            order.append(name)

        for name in self.nodes:
            visit(name, [])
        return order

    def joint(self) -> tuple[np.ndarray, np.ndarray]:
        """Joint mean (..., D) and covariance (..., D, D) of all nodes in :attr:`order`
        (blocks at :attr:`slices`), eq. 2.13: ``E[x_i] = sum W_ij E[x_j] + b_i``,
        ``Cov[x_k, x_i] = sum_{j in pa_i} Cov[x_k, x_j] W_ij^T`` for the nodes k before
        i, ``Cov[x_i, x_i] = sum_j W_ij Cov[x_j, x_i] + Lambda_i``."""
        if self._joint is not None:
            return self._joint
        D = self.size
        mu = np.zeros(self.batch + (D,))
        C = np.zeros(self.batch + (D, D))
        for name in self.order:
            si = self.slices[name]
            m = np.broadcast_to(self._b[name], self.batch + (self.nodes[name].dim,)).copy()
            upto = slice(0, si.start)
            cross = np.zeros(self.batch + (si.start, self.nodes[name].dim))
            for p, w in self._W[name].items():
                sp = self.slices[p]
                m = m + np.einsum("...ij,...j->...i", w, mu[..., sp])
                cross = cross + C[..., upto, sp] @ np.swapaxes(w, -1, -2)
            mu[..., si] = m
            C[..., upto, si] = cross
            C[..., si, upto] = np.swapaxes(cross, -1, -2)
            own = np.broadcast_to(self._cov[name], self.batch + (self.nodes[name].dim,) * 2)
            blk = own.copy()
            for p, w in self._W[name].items():
                blk = blk + w @ cross[..., self.slices[p], :]
            C[..., si, si] = 0.5 * (blk + np.swapaxes(blk, -1, -2))
        self._joint = (mu, C)
        return self._joint

    def index(self, names: str | Sequence[str]) -> np.ndarray:
        """Joint indices of the nodes ``names`` (one name or several, in that order)."""
        names = [names] if isinstance(names, str) else list(names)
        out: list[int] = []
        for n in names:
            if n not in self.slices:
                raise ValueError(f"node '{n}': not in the graph (nodes: {', '.join(self.order)})")
            s = self.slices[n]
            out.extend(range(s.start, s.stop))
        return np.asarray(out, np.int64)

    def covariance(self, k: str | Sequence[str], l: str | Sequence[str] | None = None
                   ) -> np.ndarray:
        """Marginal covariance of ``k`` (l None) or the cross covariance Cov[x_k, x_l]."""
        C = self.joint()[1]
        ik = self.index(k)
        il = ik if l is None else self.index(l)
        return C[..., ik[:, None], il[None, :]]

    def mean(self, k: str | Sequence[str]) -> np.ndarray:
        return self.joint()[0][..., self.index(k)]

    def conditional(self, k: str | Sequence[str], l: str | Sequence[str], x_l: Any
                    ) -> tuple[np.ndarray, np.ndarray]:
        """p(x_k | x_l) = N(mu_k|l, Lambda_k|l) (eq. 2.14); Lambda_l by pseudo-inverse."""
        Ckl = self.covariance(k, l)
        Cl_inv = np.linalg.pinv(self.covariance(l), hermitian=True)
        d = np.asarray(x_l, np.float64) - self.mean(l)
        mu = self.mean(k) + np.einsum("...ij,...j->...i", Ckl @ Cl_inv, d)
        cov = self.covariance(k) - Ckl @ Cl_inv @ np.swapaxes(Ckl, -1, -2)
        return mu, cov


#: the largest virtual noise standard deviation (its square must stay a finite covariance)
MAX_STD = 1e150


def virtual_covariance(virtual: Any, dim: int, name: str = "virtual") -> np.ndarray:
    """(dim, dim) virtual noise covariance from a std (scalar or (dim,)) or a (dim, dim)
    (or (..., dim, dim)) covariance."""
    v = np.asarray(virtual, np.float64)
    if not np.all(np.isfinite(v)):
        raise ValueError(f"{name}: NaN or inf")
    if v.ndim == 0 or v.shape == (dim,):
        if np.any(v < 0):
            raise ValueError(f"{name}: a standard deviation must be >= 0, got {virtual!r}")
        if np.any(v > MAX_STD):  # its square (a covariance) would overflow
            raise ValueError(f"{name}: a standard deviation of at most {MAX_STD:g}, got "
                             f"{float(v.max()):g}")
        return np.diag(np.broadcast_to(v, (dim,)) ** 2)
    if v.ndim >= 2 and v.shape[-2:] == (dim, dim):
        return v
    raise ValueError(f"{name}: expected a std (scalar or {dim} values) or a ({dim}, {dim}) "
                     f"covariance, got shape {v.shape}")


def adjusted_covariance(graph: MeasurementGraph, actual: str | Sequence[str],
                        task: str | Sequence[str], virtual: Any) -> np.ndarray:
    """Eq. 2.11: ``Lambda_a + Lambda_at Lambda_t^-1 V Lambda_t^-1 Lambda_ta`` with the
    marginals and cross covariance of the graph; ``V`` (``virtual``) in task units: std
    (scalar / per task value) or covariance. ``Lambda_t^-1`` is the pseudo-inverse
    (a task the graph determines only partly, eq. 2.16's general form)."""
    Ca = graph.covariance(actual)
    Cat = graph.covariance(actual, task)
    Ct = graph.covariance(task)
    V = virtual_covariance(virtual, Ct.shape[-1])
    G = Cat @ np.linalg.pinv(Ct, hermitian=True)
    out = Ca + G @ V @ np.swapaxes(G, -1, -2)
    return 0.5 * (out + np.swapaxes(out, -1, -2))


def task_space_covariance(graph: MeasurementGraph, actual: str | Sequence[str],
                          task: str | Sequence[str], virtual: Any) -> np.ndarray:
    """Eq. 2.22 (MAP in the task space mapped back): ``(Lambda_a^-1 Lambda_at (Lambda_t +
    V)^-1 Lambda_ta Lambda_a^-1)^-1``; equal to eq. 2.11 when the actual-task mapping is
    invertible (sequential without own noise, or reverse)."""
    Ca = graph.covariance(actual)
    Cat = graph.covariance(actual, task)
    Ct = graph.covariance(task)
    V = virtual_covariance(virtual, Ct.shape[-1])
    Ca_inv = np.linalg.inv(Ca)
    M = Ca_inv @ Cat @ np.linalg.inv(Ct + V) @ np.swapaxes(Cat, -1, -2) @ Ca_inv
    out = np.linalg.inv(M)
    return 0.5 * (out + np.swapaxes(out, -1, -2))


# --------------------------------------------------------------- closed forms
def sequential_covariance(cov_a: Any, tJa: Any, virtual: Any) -> np.ndarray:
    """Eq. 2.15 (the actual follows the task): ``Lambda_a + tJa V tJa^T``; tJa (..., m_a,
    m_t) = dy_a/dy_t."""
    J = np.asarray(tJa, np.float64)
    V = virtual_covariance(virtual, J.shape[-1])
    return np.asarray(cov_a, np.float64) + J @ V @ np.swapaxes(J, -1, -2)


def reverse_covariance(cov_a: Any, aJt: Any, virtual: Any, invertible: bool = False
                       ) -> np.ndarray:
    """Eq. 2.16 (the task follows the actual, ``y_t = aJt^T y_a``; aJt (..., m_a, m_t)):
    general ``Lambda_a + (Lambda_a aJt) M^-1 V M^-1 (aJt^T Lambda_a)`` with ``M = aJt^T
    Lambda_a aJt``, or ``Lambda_a + aJt^-T V aJt^-1`` (``invertible``, square aJt)."""
    Ca = np.asarray(cov_a, np.float64)
    J = np.asarray(aJt, np.float64)
    V = virtual_covariance(virtual, J.shape[-1])
    if invertible:
        Ji = np.linalg.inv(J)
        return Ca + np.swapaxes(Ji, -1, -2) @ V @ Ji
    JT = np.swapaxes(J, -1, -2)
    A = Ca @ J @ np.linalg.inv(JT @ Ca @ J)
    return Ca + A @ V @ np.swapaxes(A, -1, -2)


# ----------------------------------------------------------------- the plugins
@dataclass
class TowSpec:
    """Task-oriented weighting of a calibration (the setup file's ``tow`` section).

    task: the task measurement plugin instance (cartesian, relative, ...).
    virtual_noise: task virtual noise ``V`` as std [task unit] (scalar or one per task
        value) or (m_t, m_t) covariance; or None with ``delta_h`` given.
    delta_h: systematic error [task unit]; ``V = delta_h^2 sqrt(N) I`` (eq. 2.8's
        approximation, N calibration samples) when ``virtual_noise`` is None.
    graph: ``sequential`` | ``reverse`` | ``shared`` (module docstring).
    twist_sigma: (position [m], rotation [rad]) std of the frame twists of ``shared``.
    tolerance: largest relative residual of ``Ja_F ~= tJa Jt_F`` (``sequential``).
    """

    task: Measurement
    virtual_noise: Any = None
    delta_h: float | None = None
    graph: str = "sequential"
    twist_sigma: tuple[float, float] = (0.01, 0.01)
    tolerance: float = 0.05

    def validate(self) -> None:
        if not isinstance(self.task, Measurement):
            raise TypeError(f"task: expected a measurement plugin instance, got "
                            f"{type(self.task).__name__}")
        if self.graph not in GRAPHS:
            raise ValueError(f"graph: expected one of {', '.join(GRAPHS)}, got {self.graph!r}")
        if self.virtual_noise is None and self.delta_h is None:
            raise ValueError("virtual_noise: give the task virtual noise or delta_h")
        if self.virtual_noise is not None:
            virtual_covariance(self.virtual_noise, self.task.n_obs, "virtual_noise")
        if self.delta_h is not None and not (isinstance(self.delta_h, (int, float))
                                             and math.isfinite(self.delta_h)
                                             and self.delta_h >= 0):
            raise ValueError(f"delta_h: expected a number >= 0, got {self.delta_h!r}")
        ts = np.asarray(self.twist_sigma, np.float64)
        if ts.shape != (2,) or not np.all(np.isfinite(ts)) or np.any(ts <= 0):
            raise ValueError(f"twist_sigma: expected [position m, rotation rad] > 0, got "
                             f"{self.twist_sigma!r}")
        if not (isinstance(self.tolerance, (int, float)) and self.tolerance > 0):
            raise ValueError(f"tolerance: expected a number > 0, got {self.tolerance!r}")

    def virtual(self, n_samples: int) -> np.ndarray:
        """(m_t, m_t) task virtual noise covariance for ``n_samples`` calibration rows."""
        m = self.task.n_obs
        if self.virtual_noise is not None:
            return virtual_covariance(self.virtual_noise, m, "virtual_noise")
        return np.eye(m) * float(cast(float, self.delta_h)) ** 2 * math.sqrt(n_samples)


TOW_KEYS = {"task", "virtual_noise", "delta_h", "graph", "twist_sigma", "tolerance"}


def tow_from_dict(doc: Any, robot: RobotModel, where: str = "setup.tow") -> TowSpec:
    """Parse a setup file's ``tow`` section::

        "tow": {"task": {"plugin": "cartesian", "tracker": {...}, "markers": [...],
                         "noise": 1e-4},
                "virtual_noise": 0.002,          # std [task unit], or
                "delta_h": 0.003,                # V = delta_h^2 sqrt(N)
                "graph": "sequential",           # | "reverse" | "shared"
                "twist_sigma": [0.01, 0.01]}     # shared only [m, rad]

    The task plugin is built on ``robot``: unknown frames (a task plugin whose frames the
    robot lacks) and other bad keys raise ValueError naming ``<where>.task...``."""
    from jwarp.plugins.registry import measurement as plugin_class

    if not isinstance(doc, dict):
        raise ValueError(f"{where}: expected a JSON object, got {type(doc).__name__}")
    bad = sorted(set(doc) - TOW_KEYS)
    if bad:
        raise ValueError(f"{where}: unknown key(s) {bad}; known: {sorted(TOW_KEYS)}")
    task = doc.get("task")
    if not isinstance(task, dict) or not isinstance(task.get("plugin"), str):
        raise ValueError(f"{where}.task: expected the task measurement's section with its "
                         f"\"plugin\" (e.g. \"cartesian\", \"relative\")")
    try:
        cls = plugin_class(task["plugin"])
        meas = cls(robot, dict(task))
    except ValueError as e:
        msg = str(e)
        msg = msg[len("setup"):] if msg.startswith("setup") else ": " + msg
        raise ValueError(f"{where}.task{msg}") from None
    spec = TowSpec(task=meas, virtual_noise=doc.get("virtual_noise"),
                   delta_h=doc.get("delta_h"), graph=doc.get("graph", "sequential"),
                   twist_sigma=tuple(doc.get("twist_sigma", (0.01, 0.01))),
                   tolerance=doc.get("tolerance", 0.05))
    try:
        spec.validate()
    except (ValueError, TypeError) as e:
        raise ValueError(f"{where}.{e}") from None
    return spec


def frame_twist_jacobians(actual: Measurement, task: Measurement, frames: np.ndarray,
                          p_actual: Any, p_task: Any, meta: Mapping[str, Any] | None = None,
                          task_meta: Mapping[str, Any] | None = None
                          ) -> tuple[np.ndarray, np.ndarray, list[int]]:
    """(Ja_F (S, m_a, 6 |F|), Jt_F (S, m_t, 6 |F|), F): both measurements' derivatives by
    the twists of the task's frames F (``measurement.jacobians``, base coordinates);
    ``frames`` (S, n_frames, 4, 4). A task sharing no frame with the actual -> ValueError."""
    F = list(task.frames)
    shared = [f for f in F if f in actual.frames]
    if not shared:
        names = [actual.robot.frames[f].name for f in F]
        raise ValueError(f"task: its frames {names} are none of the actual measurement's "
                         f"frames; the task cannot be linked to the actual measurement")
    _, ja, _ = actual.jacobians(frames, p_actual, meta)
    _, jt, _ = task.jacobians(frames, p_task, task_meta)
    S = ja.shape[0]
    Ja = np.zeros((S, ja.shape[1], len(F), 6))
    for k, f in enumerate(F):
        if f in actual.frames:
            Ja[:, :, k] = ja[:, :, actual.frames.index(f)]
    return Ja.reshape(S, ja.shape[1], -1), jt.reshape(S, jt.shape[1], -1), F


def tow_graph(spec: TowSpec, Ja: np.ndarray, Jt: np.ndarray, cov_a: np.ndarray,
              cov_t: np.ndarray) -> MeasurementGraph:
    """The per-sample graph (batched over S) of ``spec.graph`` from the frame-twist
    Jacobians Ja (S, m_a, 6F), Jt (S, m_t, 6F) and the own covariances (m_a, m_a),
    (m_t, m_t); nodes ``actual``, ``task`` (and ``twist`` for ``shared``)."""
    ma, mt = Ja.shape[1], Jt.shape[1]
    if spec.graph == "sequential":
        tJa = Ja @ np.linalg.pinv(Jt)
        fit = np.linalg.norm(Ja - tJa @ Jt, axis=(1, 2))
        rel = fit / np.maximum(np.linalg.norm(Ja, axis=(1, 2)), 1e-300)
        if np.any(rel > spec.tolerance):
            s = int(np.argmax(rel))
            raise ValueError(f"graph: the actual measurement does not follow the task through "
                             f"the task's frames at sample {s} (relative residual "
                             f"{rel[s]:.2g} > tolerance {spec.tolerance:g}); use graph "
                             f"'shared' or 'reverse'")
        return MeasurementGraph([GaussianNode("task", mt, cov_t),
                                 GaussianNode("actual", ma, cov_a, {"task": tJa})])
    if spec.graph == "reverse":
        aJtT = Jt @ np.linalg.pinv(Ja)
        return MeasurementGraph([GaussianNode("actual", ma, cov_a),
                                 GaussianNode("task", mt, cov_t, {"actual": aJtT})])
    nF = Ja.shape[2] // 6
    sp, sr = spec.twist_sigma
    tw = np.diag(np.tile([sp ** 2] * 3 + [sr ** 2] * 3, nF))
    return MeasurementGraph([GaussianNode("twist", 6 * nF, tw),
                             GaussianNode("actual", ma, cov_a, {"twist": Ja}),
                             GaussianNode("task", mt, cov_t, {"twist": Jt})])


def tow_covariance(actual: Measurement, spec: TowSpec, frames: np.ndarray, p_actual: Any,
                   p_task: Any = None, meta: Mapping[str, Any] | None = None,
                   task_meta: Mapping[str, Any] | None = None,
                   n_samples: int | None = None) -> np.ndarray:
    """Per-sample adjusted covariance (S, m_a, m_a) [actual unit^2] of eq. 2.11 for the
    model frames (S, n_frames, 4, 4) (e.g. the nominal or a first fit), the actual's
    parameters ``p_actual`` and the task's (default its nominal). ``n_samples`` (default
    S) is the N of the ``delta_h`` approximation."""
    spec.validate()
    task = spec.task
    if task.robot.frame_names != actual.robot.frame_names:
        raise ValueError(f"task: built for robot '{task.robot.name}', the actual measurement "
                         f"for '{actual.robot.name}'")
    pt = task.params.nominal if p_task is None else p_task
    Ja, Jt, _ = frame_twist_jacobians(actual, task, frames, p_actual, pt, meta, task_meta)
    S = Ja.shape[0]
    cov_a = np.diag(np.broadcast_to(np.asarray(actual.noise, np.float64) ** 2, (actual.n_obs,)))
    cov_t = np.diag(np.broadcast_to(np.asarray(task.noise, np.float64) ** 2, (task.n_obs,)))
    g = tow_graph(spec, Ja, Jt, cov_a, cov_t)
    return adjusted_covariance(g, "actual", "task", spec.virtual(S if n_samples is None
                                                                 else n_samples))
