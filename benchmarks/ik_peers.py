"""Peers of ``bench_ik.py --peers``: jwarp's IKSolver beside Newton's ``newton.ik`` (its
IKSolver, Levenberg-Marquardt) and pytorch_kinematics' ``PseudoInverseIK``, on one URDF (the
Panda of example-robot-data, TCP frame ``panda_hand_tcp``), the same targets and seeds, and
one common float64 check of every returned configuration.

* :func:`problem`: P reachable targets (float64 FK of uniform random configurations inside
  the limits) and S seeds per target (uniform inside the limits), both drawn once by numpy.
* :class:`PoseCheck`: the common check, float64 and independent of every solver: pinocchio's
  FK of the TCP frame where pinocchio is installed (else jwarp's float64 FK), the position
  error [m], the rotation error [rad] (the angle of R_target^T R) and the joint limits
  (within 1e-9); solved = all three within the tolerances. :func:`pick_best` picks per target
  the seed that passes, else the one with the smallest error (for the peers that return every
  seed).
* Runners (``Jwarp``, :class:`Newton`, :class:`PytorchKinematics`): ``solve(targets (P, 4, 4),
  seeds (P, S, 7)) -> q`` host numpy float64, (P, 7) for a library that returns its choice
  (jwarp) or (P, S, 7) for one that returns every seed. Each call takes host inputs and
  returns host outputs (the upload and the read-back are part of the timed call).

The peers are optional: :func:`import_newton` / :func:`import_pytorch_kinematics` return
None (the section prints "not installed") when they are missing. Install them outside the
project's environment, e.g. ``pip install --no-deps --target /tmp/peers newton
pytorch-kinematics arm-pytorch-utilities pytorch-seed`` and run with ``PYTHONPATH=/tmp/peers``
(see benchmarks/README.md). pytorch_kinematics imports matplotlib (debug plots only), lxml
(its URDF parser), yaml and scipy (unused by IK): where those are missing,
:func:`import_pytorch_kinematics` stands in for them while importing it (a no-op matplotlib,
a minimal ``lxml.etree`` on ``xml.etree.ElementTree``, empty yaml and scipy).
"""

from __future__ import annotations

import importlib
import os
import shutil
import sys
import types
import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np

import jwarp
from jwarp.core.limits import sample_within_limits

URDF = "panda_description/urdf/panda.urdf"
TCP = "panda_hand_tcp"
ARM = tuple(f"panda_joint{i}" for i in range(1, 8))  # the joints on the chain to the TCP
LIMIT_SLACK = 1e-9  # [rad] a joint counts as within its limits up to this


def panda(urdf: str | None = None, model_path: str | None = None) -> tuple[str, Any]:
    """(URDF path, jwarp RobotModel with end effector ``tcp`` = ``panda_hand_tcp``): the URDF
    of example-robot-data (or ``urdf``) and jwarp's import of it (or the robot JSON
    ``model_path``, e.g. written by this module's ``__main__`` for a machine without
    example-robot-data and lxml). ValueError naming ``--peer-urdf`` / ``--peer-model`` when
    the file is missing or the model lacks the TCP frame or an arm joint."""
    from jwarp.model import RobotModel

    if urdf is None:
        from jwarp.importers.robot import example_robot_urdf

        urdf = example_robot_urdf(URDF)
    if not os.path.isfile(urdf):
        raise ValueError(f"--peer-urdf: no file {urdf}")
    if model_path is not None:
        model = RobotModel.load(model_path)
    else:
        from jwarp.importers.robot import load_urdf

        model = load_urdf(urdf, end_effectors={"tcp": TCP}).model
    missing = [n for n in ARM if n not in list(model.joint_names)]
    if TCP not in list(model.frame_names) or missing:
        raise ValueError(f"--peer-model: {model.name} lacks frame {TCP} or joints {missing}")
    return str(urdf), model


def arm_columns(model: Any) -> np.ndarray:
    """Indices of :data:`ARM` in the jwarp model's joints (7,)."""
    return np.array([list(model.joint_names).index(n) for n in ARM])


def problem(model: Any, n_targets: int, n_seeds: int, seed: int = 0, device: Any = "cpu"
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Targets (P, 4, 4) float64 [m] = jwarp's float64 FK (on ``device``) of the TCP at
    uniform random configurations inside the limits (reachable), those configurations
    (P, n_dof), and seeds (P, S, n_dof) uniform inside the limits; numpy's generator of
    ``seed``."""
    rng = np.random.default_rng(seed)
    q = sample_within_limits(model, n_targets, rng)
    T = np.asarray(jwarp.fk(model, q, device=device, dtype=np.float64))[:, model.frame_index(TCP)]
    seeds = sample_within_limits(model, n_targets * n_seeds, rng).reshape(
        n_targets, n_seeds, model.n_dof)
    return np.ascontiguousarray(T), q, seeds


# ====================================================================== the common check
def rotation_angle(R: np.ndarray) -> np.ndarray:
    """Angle [rad] of rotations (..., 3, 3), robust near 0 and pi (atan2 of sin and cos)."""
    s = 0.5 * np.linalg.norm(np.stack([R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0],
                                       R[..., 1, 0] - R[..., 0, 1]], -1), axis=-1)
    c = 0.5 * (np.trace(R, axis1=-2, axis2=-1) - 1.0)
    return np.arctan2(s, c)


@dataclass
class Check:
    """Per configuration: pos_err [m], rot_err [rad], in_limits, solved (all three ok)."""

    pos_err: np.ndarray
    rot_err: np.ndarray
    in_limits: np.ndarray
    solved: np.ndarray


class PoseCheck:
    """The one float64 check of every library's answers (see the module docstring).

    Args:
        urdf: the URDF path (pinocchio builds its own model from it).
        model: the jwarp model (the fallback FK, and the limits without pinocchio).
        tol_pos, tol_rot: tolerances [m], [rad].
        use_pinocchio: False forces the jwarp float64 FK.
        device: the Warp device of that FK.
    """

    def __init__(self, urdf: str, model: Any, tol_pos: float, tol_rot: float,
                 use_pinocchio: bool = True, device: Any = "cpu") -> None:
        self.model, self.tol_pos, self.tol_rot = model, tol_pos, tol_rot
        self.device = device
        self.pin = None
        if use_pinocchio:
            try:
                import pinocchio
                self.pin = pinocchio
            except ImportError:
                pass
        if self.pin is not None:
            self.pm = self.pin.buildModelFromUrdf(urdf)
            self.pd = self.pm.createData()
            self.fid = self.pm.getFrameId(TCP)
            idx = [self.pm.idx_qs[self.pm.getJointId(n)] for n in ARM]
            self.idx = np.array(idx)
            self.lo = self.pm.lowerPositionLimit[self.idx].copy()
            self.hi = self.pm.upperPositionLimit[self.idx].copy()
            self.reference = f"pinocchio {self.pin.__version__} (float64)"
        else:
            cols = arm_columns(model)
            self.lo, self.hi = model.joint_limits[cols, 0], model.joint_limits[cols, 1]
            self.reference = "jwarp.fk (float64; pinocchio not installed)"

    def fk(self, q7: np.ndarray) -> np.ndarray:
        """TCP poses (N, 4, 4) float64 of arm configurations (N, 7) [rad]."""
        q7 = np.asarray(q7, np.float64).reshape(-1, 7)
        out = np.empty((len(q7), 4, 4))
        if self.pin is not None:
            qp = self.pin.neutral(self.pm)
            for i, q in enumerate(q7):
                qp[self.idx] = q
                self.pin.framesForwardKinematics(self.pm, self.pd, qp)
                out[i] = self.pd.oMf[self.fid].homogeneous
            return out
        m = self.model
        q = np.tile(np.mean(m.joint_limits, axis=1), (len(q7), 1))
        q[:, arm_columns(m)] = q7
        return np.asarray(jwarp.fk(m, q, device=self.device, dtype=np.float64)
                          )[:, m.frame_index(TCP)]

    def __call__(self, q7: np.ndarray, targets: np.ndarray) -> Check:
        """Check configurations (..., 7) against targets (..., 4, 4) (same leading dims, or
        configurations (P, S, 7) against targets (P, 4, 4))."""
        q7 = np.asarray(q7, np.float64)
        T = np.asarray(targets, np.float64)
        if q7.ndim == T.ndim:  # (P, S, 7) vs (P, 4, 4)
            T = np.broadcast_to(T[:, None], q7.shape[:-1] + (4, 4))
        lead = q7.shape[:-1]
        M = self.fk(q7).reshape(lead + (4, 4))
        pe = np.linalg.norm(M[..., :3, 3] - T[..., :3, 3], axis=-1)
        re = rotation_angle(np.swapaxes(T[..., :3, :3], -1, -2) @ M[..., :3, :3])
        finite = np.isfinite(q7).all(-1)
        lim = finite & np.all((q7 >= self.lo - LIMIT_SLACK) & (q7 <= self.hi + LIMIT_SLACK), -1)
        pe = np.where(finite, pe, np.inf)
        re = np.where(finite, re, np.inf)
        return Check(pe, re, lim, (pe <= self.tol_pos) & (re <= self.tol_rot) & lim)


def pick_best(check: PoseCheck, q_all: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """Per target the seed (of (P, S, 7)) to keep: one that passes the check, else the one with
    the smallest error max(pos_err / tol_pos, rot_err / tol_rot); returns (P, 7)."""
    c = check(q_all, targets)
    err = np.maximum(c.pos_err / check.tol_pos, c.rot_err / check.tol_rot)
    key = np.where(c.solved, -1.0, err)  # solved seeds first
    b = np.argmin(key, axis=1)
    return q_all[np.arange(len(q_all)), b]


# ====================================================================== jwarp
class Jwarp:
    """A persistent :class:`jwarp.solvers.ik.IKSolver` of ``n_targets`` targets (given seeds:
    (P, S, n_dof)); returns its chosen configurations' arm joints (P, 7)."""

    name = "jwarp IKSolver"
    returns_all_seeds = False

    def __init__(self, model: Any, n_targets: int, n_seeds: int, iterations: int,
                 tol_pos: float, tol_rot: float, device: Any, dtype: Any) -> None:
        from jwarp.solvers.ik import IKOptions, IKSolver

        self.cols = arm_columns(model)
        self.solver = IKSolver(model, TCP, n_targets, IKOptions(
            n_starts=n_seeds, iterations=iterations, tol_pos=tol_pos, tol_rot=tol_rot,
            seed=0), device=device, dtype=dtype)
        self.last = None

    def solve(self, targets: np.ndarray, seeds: np.ndarray) -> np.ndarray:
        self.last = self.solver.solve(targets, seeds)
        return np.asarray(self.last.q, np.float64)[:, self.cols]


# ====================================================================== Newton
def import_newton() -> Any:
    """``newton`` (with ``newton.ik``) or None where it is not installed."""
    try:
        newton = importlib.import_module("newton")
        importlib.import_module("newton.ik")
        return newton
    except ImportError:
        return None


def matrix_to_quat_xyzw(R: np.ndarray) -> np.ndarray:
    """Unit quaternions (..., 4) in (x, y, z, w) order of rotation matrices (..., 3, 3)
    (Shepperd's method: the largest of w, x, y, z first)."""
    R = np.asarray(R, np.float64)
    m00, m11, m22 = R[..., 0, 0], R[..., 1, 1], R[..., 2, 2]
    tr = m00 + m11 + m22
    cand = np.stack([tr, m00, m11, m22], -1)
    k = np.argmax(cand, -1)
    q = np.empty(R.shape[:-2] + (4,))
    s = np.sqrt(np.maximum(1.0 + 2.0 * np.take_along_axis(cand, k[..., None], -1)[..., 0]
                           - tr, 1e-300)) * 2.0  # 4 * the largest component
    r21, r12 = R[..., 2, 1], R[..., 1, 2]
    r02, r20 = R[..., 0, 2], R[..., 2, 0]
    r10, r01 = R[..., 1, 0], R[..., 0, 1]
    rows = {0: (r21 - r12, r02 - r20, r10 - r01, s * s / 4),   # w largest
            1: (s * s / 4, r01 + r10, r02 + r20, r21 - r12),   # x
            2: (r01 + r10, s * s / 4, r12 + r21, r02 - r20),   # y
            3: (r02 + r20, r12 + r21, s * s / 4, r10 - r01)}   # z
    for j, (x, y, z, w) in rows.items():
        sel = k == j
        q[sel] = np.stack([x, y, z, w], -1)[sel] / s[sel][:, None]
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def quat_xyzw_to_matrix(q: np.ndarray) -> np.ndarray:
    """The rotation matrix (3, 3) of a unit quaternion (x, y, z, w)."""
    x, y, z, w = np.asarray(q, np.float64) / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


class Newton:
    """Newton's ``newton.ik.IKSolver`` (LM, analytic Jacobian; position, rotation and joint-limit
    objectives as in its Franka example: link offset 0 at the ``panda_hand_tcp`` body, limit
    weight 10, lambda_initial 0.1), float32 (Newton's only type). The given seeds are used as
    they are: each (target, seed) pair is one Newton problem (sampler NONE), so Newton returns
    every seed (P, S, 7), and :func:`pick_best` picks per target."""

    name = "Newton ik LM"
    returns_all_seeds = True

    def __init__(self, newton: Any, urdf: str, n_targets: int, n_seeds: int, iterations: int,
                 device: Any) -> None:
        import warp as wp

        ik = newton.ik
        self.wp, self.iterations = wp, iterations
        b = newton.ModelBuilder()
        with warnings.catch_warnings():  # meshes it cannot resolve: IK does not need them
            warnings.simplefilter("ignore")
            b.add_urdf(urdf, floating=False)
        self.model = m = b.finalize(device=device)
        bodies = list(m.body_label)
        self.body = [i for i, n in enumerate(bodies) if n.split("/")[-1] == TCP][0]
        joints = [n.split("/")[-1] for n in m.joint_label]
        qs = m.joint_q_start.numpy()
        self.cols = np.array([qs[joints.index(n)] for n in ARM])
        self.n_coords = m.joint_coord_count
        self.P, self.S = n_targets, n_seeds
        B = n_targets * n_seeds
        self.pos = wp.zeros(B, dtype=wp.vec3, device=m.device)
        self.rot = wp.zeros(B, dtype=wp.vec4, device=m.device)
        objectives = [
            ik.IKObjectivePosition(link_index=self.body, link_offset=wp.vec3(0.0, 0.0, 0.0),
                                   target_positions=self.pos),
            ik.IKObjectiveRotation(link_index=self.body, link_offset_rotation=wp.quat_identity(),
                                   target_rotations=self.rot),
            ik.IKObjectiveJointLimit(joint_limit_lower=m.joint_limit_lower,
                                     joint_limit_upper=m.joint_limit_upper, weight=10.0)]
        self.solver = ik.IKSolver(model=m, n_problems=B, objectives=objectives,
                                  lambda_initial=0.1, jacobian_mode=ik.IKJacobianType.ANALYTIC)
        self.q = wp.zeros((B, self.n_coords), dtype=wp.float32, device=m.device)
        self.q0 = np.zeros((B, self.n_coords), np.float32)  # untouched coordinates: 0 (fingers)
        self.state = m.state()
        self.newton = newton

    def fk(self, q7: np.ndarray) -> np.ndarray:
        """Newton's own FK (float32) of the TCP body at arm configurations (N, 7): (N, 4, 4)."""
        wp, m = self.wp, self.model
        out = []
        for q in np.asarray(q7).reshape(-1, 7):
            jq = np.zeros(self.n_coords, np.float32)
            jq[self.cols] = q
            self.newton.eval_fk(m, wp.array(jq, dtype=wp.float32, device=m.device), m.joint_qd,
                                self.state)
            x = self.state.body_q.numpy()[self.body].astype(np.float64)  # p (3), quat xyzw (4)
            T = np.eye(4)
            T[:3, :3], T[:3, 3] = quat_xyzw_to_matrix(x[3:]), x[:3]
            out.append(T)
        return np.stack(out)

    def solve(self, targets: np.ndarray, seeds: np.ndarray, iterations: int | None = None
              ) -> np.ndarray:
        T = np.repeat(np.asarray(targets, np.float64), self.S, axis=0)
        self.pos.assign(T[:, :3, 3].astype(np.float32))
        self.rot.assign(matrix_to_quat_xyzw(T[:, :3, :3]).astype(np.float32))
        q0 = self.q0.copy()
        q0[:, self.cols] = np.asarray(seeds).reshape(-1, seeds.shape[-1])[:, :7]
        self.q.assign(q0)
        self.solver.step(self.q, self.q, iterations=iterations or self.iterations)
        return self.q.numpy()[:, self.cols].astype(np.float64).reshape(self.P, self.S, 7)


# ====================================================================== pytorch_kinematics
def _stand_in_matplotlib() -> None:
    """A no-op ``matplotlib`` (pytorch_kinematics.ik imports pyplot and cm for debug plots)."""
    mpl = types.ModuleType("matplotlib")
    mpl.__path__ = []  # a package
    plt = types.ModuleType("matplotlib.pyplot")
    cm = types.ModuleType("matplotlib.cm")
    mpl.pyplot, mpl.cm = plt, cm
    sys.modules.update({"matplotlib": mpl, "matplotlib.pyplot": plt, "matplotlib.cm": cm})


def _stand_in_lxml() -> None:
    """A minimal ``lxml.etree`` on the standard library's ElementTree (what the URDF parser
    of pytorch_kinematics calls: fromstring, ElementTree, Element, SubElement, tostring)."""
    import xml.etree.ElementTree as ET

    class Element(ET.Element):
        def getchildren(self) -> list:  # lxml's (removed from ElementTree in Python 3.9)
            return list(self)

    def fromstring(text: Any) -> Any:
        return ET.fromstring(text, ET.XMLParser(target=ET.TreeBuilder(element_factory=Element)))

    etree = types.ModuleType("lxml.etree")
    etree.fromstring = fromstring
    etree.ElementTree = ET.ElementTree
    etree.Element = Element
    etree.SubElement = ET.SubElement
    etree._Element = ET.Element
    etree._Comment = type("_Comment", (), {})  # ElementTree drops comments when parsing

    def tostring(e: Any, pretty_print: bool = False, encoding: Any = None, **kw: Any) -> Any:
        return ET.tostring(e, encoding="unicode" if encoding in ("unicode", str) else "utf-8")

    etree.tostring = tostring
    lxml = types.ModuleType("lxml")
    lxml.__path__ = []
    lxml.etree = etree
    sys.modules.update({"lxml": lxml, "lxml.etree": etree})


def _stand_in_modules(names: dict) -> None:
    """Empty modules ``{name: attributes}`` (a dotted name is also an attribute of its parent)."""
    for name, attrs in names.items():
        mod = types.ModuleType(name)
        mod.__path__ = []
        mod.__dict__.update(attrs)
        sys.modules[name] = mod
        if "." in name:
            parent, _, child = name.rpartition(".")
            setattr(sys.modules[parent], child, mod)


def _no_yaml_dump(*args: Any, **kw: Any) -> Any:
    raise RuntimeError("yaml is not installed (a stand-in of benchmarks/ik_peers.py)")


def import_pytorch_kinematics(stand_ins: bool = True) -> Any:
    """``pytorch_kinematics`` or None where it (or torch) is not installed. With ``stand_ins``,
    modules it imports but IK never calls are stood in where missing, only while it is
    imported (recorded in :data:`STAND_INS`): matplotlib (debug plots), lxml.etree (on
    xml.etree.ElementTree: its URDF parser), yaml (printing a URDF element) and scipy.linalg
    (arm_pytorch_utilities' matrix square root)."""
    try:
        importlib.import_module("torch")
    except ImportError:
        return None
    if importlib.util.find_spec("pytorch_kinematics") is None:
        return None
    added: list[str] = []
    if stand_ins:
        before = set(sys.modules)
        if importlib.util.find_spec("matplotlib") is None:
            _stand_in_matplotlib()
            STAND_INS.append("matplotlib (no-op)")
        if importlib.util.find_spec("lxml") is None:
            _stand_in_lxml()
            STAND_INS.append("lxml.etree (xml.etree)")
        if importlib.util.find_spec("yaml") is None:
            _stand_in_modules({"yaml": {"dump": _no_yaml_dump}})
            STAND_INS.append("yaml (no dump)")
        if importlib.util.find_spec("scipy") is None:
            _stand_in_modules({"scipy": {}, "scipy.linalg": {}, "scipy.io": {}})
            STAND_INS.append("scipy (empty)")
        added = [m for m in sys.modules if m not in before]
    try:
        return importlib.import_module("pytorch_kinematics")
    except ImportError:
        return None
    finally:  # pytorch_kinematics keeps its references; nothing else sees the stand-ins
        for m in added:
            sys.modules.pop(m, None)


STAND_INS: list[str] = []


class PytorchKinematics:
    """pytorch_kinematics' ``PseudoInverseIK`` (damped least squares with its LM damping, its
    defaults otherwise: lr 1, no line search, joint limits enforced at the end by wrapping and
    10 clamped refinement iterations), stopping a target once one of its seeds converged
    (``early_stopping_any_converged``); the given seeds per target as ``initial_config``
    (P, S, 7); the chain of ``panda_hand_tcp`` from the URDF on torch device ``device`` in
    ``dtype``. Returns every seed's solution (P, S, 7)."""

    name = "pytorch_kinematics"
    returns_all_seeds = True

    def __init__(self, pk: Any, urdf: str, n_targets: int, n_seeds: int, iterations: int,
                 tol_pos: float, tol_rot: float, device: Any, dtype: Any) -> None:
        import torch

        self.torch, self.pk = torch, pk
        self.device = torch.device(str(device))
        self.dtype = torch.float64 if np.dtype(dtype) == np.float64 else torch.float32
        with open(urdf, "rb") as f:
            data = f.read()
        chain = pk.build_serial_chain_from_urdf(data, TCP)
        self.chain = chain.to(dtype=self.dtype, device=self.device)
        names = self.chain.get_joint_parameter_names(exclude_fixed=True)
        if tuple(names) != ARM:
            raise RuntimeError(f"pytorch_kinematics chain joints {names}, expected {ARM}")
        lim = torch.tensor(np.asarray(self.chain.get_joint_limits()).T, dtype=self.dtype,
                           device=self.device)
        first = torch.zeros((n_seeds, 7), dtype=self.dtype, device=self.device)
        self.ik = pk.PseudoInverseIK(self.chain, pos_tolerance=tol_pos, rot_tolerance=tol_rot,
                                     retry_configs=first, joint_limits=lim,
                                     max_iterations=iterations,
                                     early_stopping_any_converged=True)
        self.P, self.S = n_targets, n_seeds

    def fk(self, q7: np.ndarray) -> np.ndarray:
        """pytorch_kinematics' FK of the TCP at arm configurations (N, 7): (N, 4, 4)."""
        q = self.torch.as_tensor(np.asarray(q7).reshape(-1, 7), dtype=self.dtype,
                                 device=self.device)
        return self.chain.forward_kinematics(q).get_matrix().cpu().numpy().astype(np.float64)

    def solve(self, targets: np.ndarray, seeds: np.ndarray) -> np.ndarray:
        torch = self.torch
        # (P, S, 7) seeds: the solver's own shape check only allows (S, 7) at construction
        self.ik.initial_config = torch.as_tensor(np.asarray(seeds)[..., :7], dtype=self.dtype,
                                                 device=self.device)
        T = self.pk.Transform3d(matrix=torch.as_tensor(targets, dtype=self.dtype,
                                                       device=self.device),
                                dtype=self.dtype, device=self.device)
        sol = self.ik.solve(T)
        return sol.solutions.cpu().numpy().astype(np.float64).reshape(self.P, self.S, 7)


def main(argv: list[str] | None = None) -> int:
    """``python benchmarks/ik_peers.py DIR``: write the Panda URDF (``DIR/panda.urdf``) and
    jwarp's import of it (``DIR/panda.json``) for a machine without example-robot-data and
    lxml; there: ``bench_ik.py --peers --peer-urdf DIR/panda.urdf --peer-model
    DIR/panda.json``."""
    import argparse

    p = argparse.ArgumentParser(description=main.__doc__.split("\n")[0])
    p.add_argument("dir", help="output folder (created)")
    args = p.parse_args(argv)
    urdf, model = panda()
    os.makedirs(args.dir, exist_ok=True)
    shutil.copyfile(urdf, os.path.join(args.dir, "panda.urdf"))
    model.save(os.path.join(args.dir, "panda.json"))
    print(f"wrote {args.dir}/panda.urdf and {args.dir}/panda.json")
    return 0


if __name__ == "__main__":
    sys.exit(main())
