"""The range a calibration is valid in (issue 38 item 3).

A calibrated robot (:func:`jwarp.calibration.calibrate`, ``jwarp calibrate --out``)
records the range of its calibration poses in ``notes['valid_range']``: per joint
``[min, max]`` of the joint values, and per coupled frame (a frame driven by several
joints, or by one with a coefficient other than 1, as justin19's ``torso_4``) ``[min,
max]`` of its coupled angle ``u_i = sum_j c_ij q_j``. A calibrated model extrapolates
outside that range (a joint offset, harmonic or compliance fitted on 0..100 deg says
little about 110 deg), so the users of a robot check their configurations against it:

* :func:`range_excess` / :meth:`ValidRange.excess`: how far (S,) configurations lie
  outside, per joint and coupled angle (0 inside), vectorised numpy;
* :func:`check_valid_range`: the check at an API entry (``jwarp fk``, IK, the planner,
  ``calibrate --test-rows``): warns (:class:`ValidRangeWarning`) once per robot and entry
  point, naming the worst joints and how far past their range. A robot without the note
  costs one dict look-up.
"""

from __future__ import annotations

import json
import math
import warnings
import weakref
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from jwarp.model import RobotModel

#: the ``RobotModel.notes`` key of the recorded range (a JSON object)
VALID_RANGE_NOTE = "valid_range"


class ValidRangeWarning(UserWarning):
    """A calibrated robot is used at configurations outside the range of its calibration
    poses (per joint or coupled angle)."""


@dataclass(frozen=True)
class ValidRange:
    """The range of a calibration's poses.

    Attributes:
        joints: (n_dof,) joint names.
        lower, upper: (n_dof,) smallest / largest joint value of the calibration poses
            [rad or m].
        coupled: (n_c,) names of the coupled frames.
        coupling: (n_c, n_dof) their coupling rows (``u = coupling @ q``).
        coupled_lower, coupled_upper: (n_c,) range of the coupled angles [rad or m].
        prismatic: (n_dof + n_c,) bool: a length (m), not an angle (rad).
        samples: number of calibration poses.
    """

    joints: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray
    coupled: tuple[str, ...]
    coupling: np.ndarray
    coupled_lower: np.ndarray
    coupled_upper: np.ndarray
    prismatic: np.ndarray
    samples: int

    @property
    def names(self) -> list[str]:
        """(n_dof + n_c,) names of the checked values: the joints, then the coupled frames
        (``"<frame> (coupled)"``)."""
        return list(self.joints) + [f"{c} (coupled)" for c in self.coupled]

    def values(self, q: Any) -> np.ndarray:
        """(S, n_dof + n_c) joint values and coupled angles of configurations q (S, n_dof)."""
        qa = np.asarray(q, np.float64).reshape(-1, len(self.joints))
        if not len(self.coupled):
            return qa
        return np.concatenate([qa, qa @ self.coupling.T], axis=1)

    def excess(self, q: Any) -> np.ndarray:
        """(S, n_dof + n_c) how far each joint value / coupled angle of q (..., n_dof) lies
        outside the recorded range [rad or m]; 0 inside."""
        v = self.values(q)
        lo = np.concatenate([self.lower, self.coupled_lower])
        hi = np.concatenate([self.upper, self.coupled_upper])
        return np.maximum(np.maximum(lo - v, v - hi), 0.0)

    def outside(self, q: Any, tol: float = 1e-9) -> np.ndarray:
        """(S,) bool: configurations with any value more than ``tol`` outside the range."""
        return np.any(self.excess(q) > tol, axis=1)

    def describe(self, excess: np.ndarray, tol: float = 1e-9, most: int = 4) -> str:
        """Text naming the values furthest outside in ``excess`` (S, n_dof + n_c): e.g.
        ``"torso_4 (coupled) up to 11.40 deg past [-20.00, 104.70] deg"``."""
        worst = excess.max(axis=0) if excess.size else np.zeros(0)
        order = [int(i) for i in np.argsort(-worst) if worst[i] > tol][:most]
        lo = np.concatenate([self.lower, self.coupled_lower])
        hi = np.concatenate([self.upper, self.coupled_upper])
        names = self.names
        parts = []
        for i in order:
            f, u = (1e3, "mm") if self.prismatic[i] else (180.0 / math.pi, "deg")
            parts.append(f"{names[i]} up to {worst[i] * f:.2f} {u} past "
                         f"[{lo[i] * f:.2f}, {hi[i] * f:.2f}] {u}")
        more = int(np.sum(worst > tol)) - len(order)
        return "; ".join(parts) + (f"; and {more} more" if more > 0 else "")

    def to_dict(self) -> dict[str, Any]:
        """The note's JSON document."""
        return {"samples": int(self.samples),
                "joints": {n: [float(a), float(b)]
                           for n, a, b in zip(self.joints, self.lower, self.upper)},
                "coupled": {n: [float(a), float(b)] for n, a, b in
                            zip(self.coupled, self.coupled_lower, self.coupled_upper)}}


def coupled_frames(model: RobotModel) -> list[int]:
    """Indices of the coupled frames of ``model``: driven by several joints, or by one
    with a coefficient other than 1."""
    return [i for i, f in enumerate(model.frames)
            if f.coupling and (len(f.coupling) > 1 or float(f.coupling[0][1]) != 1.0)]


def valid_range_of(model: RobotModel, q: Any) -> ValidRange:
    """The :class:`ValidRange` of configurations ``q`` (S, n_dof) on ``model`` (S >= 1,
    finite; ValueError naming ``q`` otherwise)."""
    qa = np.asarray(q, np.float64)
    if qa.ndim != 2 or qa.shape[1] != model.n_dof or qa.shape[0] == 0:
        raise ValueError(f"q: expected (S >= 1, {model.n_dof}) joint values, got shape "
                         f"{qa.shape}")
    if not np.all(np.isfinite(qa)):
        raise ValueError("q: contains NaN or inf")
    cf = coupled_frames(model)
    C = np.asarray(model.coupling_matrix, np.float64)[cf].reshape(len(cf), model.n_dof)
    u = qa @ C.T
    pris = np.array([j.type == "prismatic" for j in model.joints]
                    + [bool(model.frame_is_prismatic[i]) for i in cf], bool)
    return ValidRange(tuple(model.joint_names), qa.min(axis=0), qa.max(axis=0),
                      tuple(model.frames[i].name for i in cf), C,
                      u.min(axis=0) if len(cf) else np.zeros(0),
                      u.max(axis=0) if len(cf) else np.zeros(0), pris, int(qa.shape[0]))


def record_valid_range(model: RobotModel, q: Any) -> Any:
    """A copy of ``model`` with the range of configurations ``q`` (S, n_dof) in
    ``notes['valid_range']`` (JSON; replacing an earlier one)."""
    vr = valid_range_of(model, q)
    notes = dict(model.notes)
    notes[VALID_RANGE_NOTE] = json.dumps(vr.to_dict())
    return model.copy(notes=notes)


#: parsed notes, per model (models are treated as immutable once used): (text, range)
_PARSED: weakref.WeakKeyDictionary[Any, tuple[str, ValidRange | None]] = \
    weakref.WeakKeyDictionary()
#: the entry points that warned already, per model
_WARNED: weakref.WeakKeyDictionary[Any, set[str]] = weakref.WeakKeyDictionary()


def valid_range(model: RobotModel) -> ValidRange | None:
    """The recorded :class:`ValidRange` of ``model`` (None: none recorded). Joints or
    coupled frames the note names but the robot lacks are left out; those it lacks
    get an unbounded range. ValueError when the note is not valid JSON of that form."""
    text = model.notes.get(VALID_RANGE_NOTE)
    if text is None:
        return None
    hit = _PARSED.get(model)
    if hit is not None and hit[0] == text:
        return hit[1]
    try:
        doc = json.loads(text)
        jr, cr = doc.get("joints") or {}, doc.get("coupled") or {}
        n = model.n_dof
        lo, hi = np.full(n, -np.inf), np.full(n, np.inf)
        for k, name in enumerate(model.joint_names):
            if name in jr:
                lo[k], hi[k] = float(jr[name][0]), float(jr[name][1])
        cf = [i for i in coupled_frames(model) if model.frames[i].name in cr]
        clo = np.array([float(cr[model.frames[i].name][0]) for i in cf])
        chi = np.array([float(cr[model.frames[i].name][1]) for i in cf])
        samples = int(doc.get("samples", 0))
    except (ValueError, TypeError, KeyError, IndexError, AttributeError) as e:
        raise ValueError(f"notes.{VALID_RANGE_NOTE}: not a valid range document ({e})") from None
    C = np.asarray(model.coupling_matrix, np.float64)[cf].reshape(len(cf), n)
    pris = np.array([j.type == "prismatic" for j in model.joints]
                    + [bool(model.frame_is_prismatic[i]) for i in cf], bool)
    vr = ValidRange(tuple(model.joint_names), lo, hi, tuple(model.frames[i].name for i in cf),
                    C, clo.reshape(-1), chi.reshape(-1), pris, samples)
    _PARSED[model] = (text, vr)
    return vr


def range_excess(model: RobotModel, q: Any) -> np.ndarray | None:
    """(S, n_dof + n_c) how far configurations ``q`` (..., n_dof) lie outside the
    recorded range of ``model`` [rad or m] (:meth:`ValidRange.excess`); None when the
    robot records none."""
    vr = valid_range(model)
    return None if vr is None else vr.excess(q)


def outside_message(model: RobotModel, q: Any, where: str, tol: float = 1e-9) -> str | None:
    """The text of :func:`check_valid_range` (without warning): which configurations of q
    (..., n_dof) leave the range recorded in ``model`` and how far; None when all lie
    inside or none is recorded."""
    if VALID_RANGE_NOTE not in model.notes:
        return None
    vr = valid_range(model)
    if vr is None:
        return None
    ex = vr.excess(q)
    bad = np.any(ex > tol, axis=1)
    if not bad.any():
        return None
    return (f"{where}: {int(bad.sum())} of {len(bad)} configuration(s) lie outside the range "
            f"of the {vr.samples} calibration poses of robot '{model.name}' (the calibration "
            f"extrapolates there): {vr.describe(ex[bad], tol)}")


def check_valid_range(model: RobotModel, q: Any, where: str, *, tol: float = 1e-9) -> str | None:
    """Warn (:class:`ValidRangeWarning`) once per robot and ``where`` (an entry point,
    e.g. ``"ik"``) when configurations ``q`` (..., n_dof) leave the range recorded in
    ``model`` (a calibrated robot), with how far (:func:`outside_message`). Returns the
    message when outside (also after the first warning), else None. Without a recorded
    range: one dict look-up. The warning is attributed to the first caller outside the
    jwarp package (the user's line)."""
    if VALID_RANGE_NOTE not in model.notes:
        return None
    msg = outside_message(model, q, where, tol)
    if msg is None:
        return None
    seen = _WARNED.setdefault(model, set())
    if where not in seen:
        seen.add(where)
        warnings.warn(msg, ValidRangeWarning, stacklevel=_user_stacklevel())
    return msg


def _user_stacklevel() -> int:
    """The ``warnings.warn`` stacklevel (called from :func:`check_valid_range`) of the
    first frame outside the jwarp package."""
    import os
    import sys

    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__))) + os.sep
    level = 1
    frame = sys._getframe(1)
    while frame is not None and os.path.abspath(frame.f_code.co_filename).startswith(root):
        nxt = frame.f_back
        if nxt is None:
            break
        frame, level = nxt, level + 1
    return level
