"""The calibration parameter vector: chosen free groups of robot and measurement parameters.

Robot groups (per DH frame on the chains the measurement observes):

* ``theta``, ``d``, ``r``, ``alpha``, ``beta``: geometric DH entries of rho0 [rad, m]
  (``theta`` holds the joint offsets);
* ``kappa_alpha``, ``kappa_beta``, ``kappa_theta``: compliances [rad/(N m)] (bounded >= 0
  with ``bound_kappa``);
* ``origin``: a 6-parameter pose error ``(x, y, z [m], rx, ry, rz [rad])`` per static frame
  that precedes a joint frame on those chains (the joint origins of an imported URDF; any
  static frame with ``frames=``), applied as ``T <- T @ Trans(v) @ Rot(w)``
  (:mod:`.origin`); names ``"<frame>.origin_x"`` ... ``"<frame>.origin_rz"``; also on a
  compliant robot and with free compliance groups (the elastic equilibrium follows the
  moved origins, issue 29).

non-geometric extras (``docs/nongeometric.md``):

* ``harmonic``: joint transmission errors, per joint j driving a DH frame on those chains
  and per harmonic k = 1..K (K = max(:data:`HARMONIC_ORDER`, the robot's own K)) the
  coefficients a_jk, b_jk of ``dq_j = sum_k a_jk sin(k q_j) + b_jk cos(k q_j)`` [rad, m
  for a prismatic joint]; names ``"<joint>.harmonic_a<k>"``, ``"<joint>.harmonic_b<k>"``;
* ``kappa_nonlinear``: torque-dependent joint compliance [rad/(N m)^3] per DH frame (the
  theta axis bends by ``kappa_theta tau + kappa_nonlinear tau^3``), unbounded (negative =
  stiffening);
* ``coupling``: per coupled DH frame i on those chains (a frame driven by several joints
  or by one with a coefficient other than 1, e.g. justin19's passive ``torso_4`` =
  -(q1 + q2)): its coupling coefficients c_ij (``"<frame>.coupling_<joint>"``, prior
  mean the robot's), an offset (``"<frame>.coupling_offset"`` [rad, m], left out when
  the ``theta`` (``d`` for a prismatic frame) group is free: the same entry) and K
  harmonics of the coupled angle ``u_i = sum_j c_ij q_j`` (raw q):
  ``dtheta_i = sum_k a_ik sin(k u_i) + b_ik cos(k u_i)`` (``"<frame>.coupling_a<k>"``,
  ``"<frame>.coupling_b<k>"``, K = :data:`COUPLING_ORDER` or ``orders``; prior mean the
  robot's ``coupling_harmonic``); one sigma for all of them (rad, or 1 for the
  dimensionless coefficients);

and per point mass of the robot's mass model (``robot.masses``):

* ``mass``: the mass [kg] of every entry whose frame lies in the subtree of a compliant DH
  frame (nonzero or free kappa) on the measured chains -- the masses that load the
  measured chains' elastic joints, the only way they change a prediction (bounded >= 0).
  Its prior sigma is **relative**: ``sigma["mass"] = 0.1`` means 10 % of each entry's
  nominal mass (entries of nominal mass 0 are left out unless the prior is ``inf``).
  Masses and compliances only act through ``kappa * tau``: freeing both without priors
  leaves a flat direction (all masses x c, all compliances / c), reported as not
  identifiable.

Measurement groups come from the measurement's :class:`ParamBlock` (``tracker``,
``markers``, ``intrinsics``, ...). Parameters of groups that are not free stay at their
nominal values. Every free parameter has a Gaussian prior ``N(nominal, sigma^2)``; it enters
the least squares as the residual row ``(x - nominal) / sigma`` (thesis eq. 2.5); a sigma of
``inf`` means no prior row.

Names: robot entries are ``"<frame>.<group>"`` (``"right_3.theta"``,
``"torso_2.kappa_alpha"``, ``"right_7.mass"``; ``"<frame>.mass<k>"`` for the k-th of several
mass entries on one frame), measurement entries keep their ParamBlock names.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from enum import IntEnum
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from jwarp.calibration.estimate.origin import (
    ORIGIN_AXES,
    ORIGIN_GROUP,
    delta_transform,
    origin_frames,
    with_static_transforms,
)
from jwarp.core.types import ArrayLike
from jwarp.model import RobotModel

if TYPE_CHECKING:
    from jwarp.model.measurement import Measurement

DH_GROUPS = ("d", "theta", "r", "alpha", "beta")          # = DH columns 0..4
KAPPA_GROUPS = ("kappa_alpha", "kappa_beta", "kappa_theta")  # = kappa axes 0..2
MASS_GROUP = "mass"                                        # = robot.masses entries
HARMONIC_GROUP = "harmonic"                                # = robot.harmonic entries
KAPPA_NL_GROUP = "kappa_nonlinear"                         # = robot.kappa_nonlinear
#: the number of harmonics the ``harmonic`` group frees (at least; more if the robot has)
HARMONIC_ORDER = 2
COUPLING_GROUP = "coupling"                                # = coupled frames
#: direction-dependent joint errors (backlash): ``q'_j += b_j s_j``, s_j = +-1 the
#: direction joint j last moved in (:mod:`jwarp.calibration.estimate.backlash`)
BACKLASH_GROUP = "backlash"
#: the number of harmonics of the coupled angle the ``coupling`` group frees
COUPLING_ORDER = 2
#: robot parameter groups
ROBOT_GROUPS = ("theta", "d", "r", "alpha", "beta", "kappa_theta", "kappa_alpha", "kappa_beta",
                MASS_GROUP, HARMONIC_GROUP, KAPPA_NL_GROUP, ORIGIN_GROUP, COUPLING_GROUP,
                BACKLASH_GROUP)
#: groups whose harmonic order ``orders`` may set (per group or per joint/frame pattern)
ORDER_GROUPS = (HARMONIC_GROUP, COUPLING_GROUP)
#: ``column`` of the ``coupling`` group: 0 the offset, COUPLING_COEF + t the t-th entry of
#: the frame's coupling list, COUPLING_HARM + 2 (k - 1) + (0 a, 1 b) the k-th harmonic
COUPLING_COEF, COUPLING_HARM = 1, 1000

#: default prior standard deviations of the robot groups [m, rad, rad/(N m)]; ``mass`` is
#: relative to each entry's nominal mass [1] (0.1 = 10 %)
DEFAULT_SIGMA: dict[str, float] = {
    "d": 0.005, "r": 0.005,
    "theta": math.radians(5.0), "alpha": math.radians(5.0), "beta": math.radians(5.0),
    # the paper's prior on Agile Justin's compliances: 0.1 rad/kNm
    "kappa_theta": 1e-4, "kappa_alpha": 1e-4, "kappa_beta": 1e-4,
    MASS_GROUP: 0.1,
    # transmission errors of harmonic drives are a few arcmin: 1e-3 rad = 3.4 arcmin
    HARMONIC_GROUP: 1e-3,
    # 1e-9 rad/(N m)^3 bends a joint by 1e-3 rad more at 100 N m (kappa_theta 1e-4: 1 %)
    KAPPA_NL_GROUP: 1e-9,
    # joint origin errors: 1 mm and 1 mrad (one sigma for the six entries of a frame)
    ORIGIN_GROUP: 1e-3,
    # coupled frames: 1 % of each coefficient, 10 mrad of offset and harmonic terms (a
    # passive coupling is looser than a drive: Agile Justin's torso shows ~10 mrad)
    COUPLING_GROUP: 1e-2,
    # backlash / hysteresis of a joint: half the dead band, a few arcmin (1e-3 rad)
    BACKLASH_GROUP: 1e-3,
}

class ParamKind(IntEnum):
    """What a parameter of :class:`ParameterSpace` is (``ParameterSpace.kind``, stored as
    int64 codes): a DH entry, a compliance, a measurement parameter, a mass, a harmonic
    (non-geometric) term, a nonlinear compliance, a joint-origin error or a coupling
    term."""

    DH = 0
    KAPPA = 1
    MEAS = 2
    MASS = 3
    HARMONIC = 4
    KAPPA_NL = 5
    ORIGIN = 6
    COUPLING = 7
    BACKLASH = 8


#: the kinds by their module-level names (``np.int64`` codes compare equal to them)
KIND_DH, KIND_KAPPA, KIND_MEAS, KIND_MASS = (ParamKind.DH, ParamKind.KAPPA, ParamKind.MEAS,
                                             ParamKind.MASS)
KIND_HARMONIC, KIND_KAPPA_NL = ParamKind.HARMONIC, ParamKind.KAPPA_NL
KIND_ORIGIN, KIND_COUPLING = ParamKind.ORIGIN, ParamKind.COUPLING
KIND_BACKLASH = ParamKind.BACKLASH


def coupled_frames(robot: RobotModel, dh_frames: Iterable[int]) -> list[int]:
    """The DH frames of ``dh_frames`` that are coupled: driven by several joints, or by one
    joint with a coefficient other than 1 (sorted indices)."""
    out = []
    for i in sorted(set(int(i) for i in dh_frames)):
        c = robot.frames[i].coupling
        if len(c) > 1 or (len(c) == 1 and c[0][1] != 1.0):
            out.append(i)
    return out


def split_keyed(mapping: Mapping[str, Any] | None, name: str, valid: Iterable[str]
                ) -> tuple[dict[str, Any], list[tuple[str, str, Any]]]:
    """Split {key: value} into per-group entries {group: value} and per-parameter entries
    [(group, pattern, value)] from keys ``"group:pattern"`` (pattern: fnmatch on the
    joint/frame part of a parameter name, or on the whole name), in the order given.
    ValueError naming ``name`` for an unknown group."""
    whole: dict[str, Any] = {}
    keyed: list[tuple[str, str, Any]] = []
    valid = list(valid)
    for key, v in (mapping or {}).items():
        g, colon, pat = str(key).partition(":")
        g, pat = g.strip(), pat.strip()
        if g not in valid:
            raise ValueError(f"{name}: unknown parameter group '{g}' (in '{key}'); valid "
                             f"groups: {', '.join(valid)}")
        if colon:
            if not pat:
                raise ValueError(f"{name}: empty pattern in '{key}' (expected "
                                 f"'group:joint_or_frame_pattern', e.g. 'harmonic:torso_*')")
            keyed.append((g, pat, v))
        else:
            whole[g] = v
    return whole, keyed


def _matches(param_name: str, pattern: str) -> bool:
    import fnmatch

    return (fnmatch.fnmatchcase(param_name.split(".", 1)[0], pattern)
            or fnmatch.fnmatchcase(param_name, pattern))


def _check_sigma(v: Any, where: str) -> float:
    try:
        fv = float(v)
    except (TypeError, ValueError):
        raise ValueError(f"{where}: expected a number, got {v!r}") from None
    if not (fv > 0) or math.isnan(fv):
        raise ValueError(f"{where}: must be > 0 (inf = no prior), got {v!r}")
    return fv


def _check_order(v: Any, where: str) -> int:
    if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or not 0 <= v <= 20:
        raise ValueError(f"{where}: expected an integer harmonic order in [0, 20], got {v!r}")
    return int(v)

#: measurement groups that hold the poses of the sensors and markers (the calibration
#: frames ``c`` of the paper): freed by default (:func:`with_pose_groups`), as the
#: measurement loop is not closed without them
POSE_GROUPS = ("tracker", "camera", "markers", "fixtures")


def parse_groups(free: str | Iterable[str]) -> list[str]:
    """``"theta,d,tracker"`` or an iterable of names -> list of group names (stripped,
    deduplicated, order kept)."""
    if isinstance(free, str):
        items = [s.strip() for s in free.split(",")]
    else:
        try:
            items = [str(s).strip() for s in free]
        except TypeError:
            raise TypeError(f"free: expected a comma-separated string or a list of group "
                            f"names, got {type(free).__name__}") from None
    items = [s for s in items if s]
    if not items:
        raise ValueError("free: no parameter group given")
    return list(dict.fromkeys(items))


def with_pose_groups(measurement: Measurement, free: str | Iterable[str],
                     fix: str | Iterable[str] | None = None) -> list[str]:
    """The groups ``free`` plus the measurement's pose and marker groups
    (:data:`POSE_GROUPS` it has: tracker, camera, markers, fixtures) not named in ``fix``.

    This is what ``jwarp calibrate`` frees (its ``--fix`` is ``fix``), and what
    :func:`~jwarp.calibration.calibrate` frees by default: without them the
    measurement loop is closed by the rough setup, and every robot parameter bends to
    absorb the setup's error (e.g. 35 mm instead of 3.8 mm on Agile Justin's tracker data).

    Args:
        measurement: a measurement plugin (its ``params.group_names()``), or None (robot
            groups only: ``free`` is returned parsed).
        free: group names, a list or comma-separated (may be empty when the measurement has
            pose groups to free).
        fix: measurement groups kept at their nominal values (a list or comma-separated);
            each must be a group of the measurement (ValueError naming ``fix``).

    Returns:
        the group names, ``free`` first in its order, then the added pose groups.
    """
    groups = [] if isinstance(free, str) and not free.strip() else parse_groups(free)
    block = getattr(measurement, "params", None) if measurement is not None else None
    meas_groups = block.group_names() if block is not None else []
    fixed: list[str] = []
    if fix is not None and not (isinstance(fix, str) and not fix.strip()):
        try:
            fixed = parse_groups(fix)
        except (TypeError, ValueError) as e:
            raise type(e)(str(e).replace("free:", "fix:", 1)) from None
    unknown = [g for g in fixed if g not in meas_groups]
    if unknown:
        name = getattr(measurement, "name", type(measurement).__name__)
        raise ValueError(f"fix: {unknown} are not groups of the '{name}' measurement (its "
                         f"groups: {', '.join(meas_groups) or 'none'})")
    clash = [g for g in fixed if g in groups]
    if clash:
        raise ValueError(f"fix: {clash} are also named in free; a group is either free or fixed")
    for g in meas_groups:
        if g in POSE_GROUPS and g not in fixed and g not in groups:
            groups.append(g)
    if not groups:
        raise ValueError("free: no parameter group given (and the measurement has no pose "
                         "groups to free)")
    return groups


def measured_chain(robot: RobotModel, measured: Iterable[int] | None) -> set[int]:
    """Frames on the paths from the root to the frames ``measured`` (all frames when None
    or empty)."""
    if not measured:
        return set(range(robot.n_frames))
    chain: set[int] = set()
    for f in measured:
        chain.update(robot.ancestors(int(f)))
    return chain


def influencing_masses(robot: RobotModel, measured: Iterable[int] | None,
                       compliant: np.ndarray) -> list[int]:
    """Entries of ``robot.masses`` (indices) whose value can change the observations of the
    frames ``measured``: those in the subtree of a compliant DH frame on the measured chains.

    A mass acts only through gravity torques, i.e. through ``kappa * tau`` of the frames
    whose subtree carries it; a compliant frame off the measured chains bends only its own
    subtree, which loads the chains only through a compliant frame on them, whose subtree
    holds the mass as well.

    Args:
        robot: the robot.
        measured: frames the measurement observes (None or empty: all frames).
        compliant: (n_frames,) bool, DH frames with a nonzero or free compliance.
    """
    compliant = np.asarray(compliant, bool) & robot.is_dh
    chain = measured_chain(robot, measured)
    roots = [i for i in sorted(chain) if compliant[i]]
    if not roots or not robot.masses:
        return []
    loaded = cast(np.ndarray, robot.subtree_mask[roots].any(axis=0))  # (n,): in a compliant subtree
    return [e for e, m in enumerate(robot.masses) if loaded[m.frame]]


def mass_names(robot: RobotModel) -> list[str]:
    """Parameter names of all entries of ``robot.masses``: ``"<frame>.mass"``, or
    ``"<frame>.mass<k>"`` (k = 0, 1, ... in file order) on frames with several entries."""
    per_frame: dict[int, int] = {}
    for m in robot.masses:
        per_frame[m.frame] = per_frame.get(m.frame, 0) + 1
    seen: dict[int, int] = {}
    out = []
    for m in robot.masses:
        name = robot.frames[m.frame].name
        if per_frame[m.frame] == 1:
            out.append(f"{name}.{MASS_GROUP}")
        else:
            k = seen.get(m.frame, 0)
            seen[m.frame] = k + 1
            out.append(f"{name}.{MASS_GROUP}{k}")
    return out


def influencing_frames(robot: RobotModel, measured: Iterable[int] | None, elastic: bool
                       ) -> list[int]:
    """DH frames whose parameters can change the observations of frames ``measured``.

    Rigid: the DH frames on the paths from the root to the measured frames. Elastic: also
    every DH frame hanging off those paths with mass in its subtree (e.g. the head of a
    humanoid measured at the hands: its pose moves a mass that loads the torso joints).
    ``measured`` None or empty: all DH frames.
    """
    dh = robot.is_dh
    if not measured:
        return [int(i) for i in np.nonzero(dh)[0]]
    chain: set[int] = set()
    for f in measured:
        chain.update(robot.ancestors(int(f)))
    use = np.array([i in chain for i in range(robot.n_frames)])
    if elastic:
        fm = np.zeros(robot.n_frames)
        for m in robot.masses:
            fm[m.frame] += m.mass
        loaded = robot.subtree_mask.astype(float) @ fm > 0   # mass in the subtree
        for i in range(robot.n_frames):
            if not use[i] and loaded[i] and any(a in chain for a in robot.ancestors(i)):
                use[i] = True
    return [int(i) for i in np.nonzero(use & dh)[0]]


#: the ``RobotModel.notes`` key of a robot's backlash: JSON ``{joint: b}`` [rad or m]
BACKLASH_NOTE = "backlash"


def robot_backlash(robot: RobotModel) -> np.ndarray:
    """(n_dof,) the backlash b_j recorded in ``robot.notes['backlash']`` (0 where none;
    ValueError naming the note when it is not a JSON object of numbers)."""
    import json

    out = np.zeros(robot.n_dof)
    text = robot.notes.get(BACKLASH_NOTE)
    if not text:
        return out
    try:
        doc = json.loads(text)
        names = robot.joint_names
        for k, v in doc.items():
            if k in names:
                out[names.index(k)] = float(v)
    except (ValueError, TypeError, AttributeError):
        raise ValueError(f"notes.{BACKLASH_NOTE}: expected a JSON object {{joint: backlash}}"
                         ) from None
    if not np.all(np.isfinite(out)):
        raise ValueError(f"notes.{BACKLASH_NOTE}: not finite")
    return out


def with_backlash(robot: RobotModel, b: np.ndarray) -> RobotModel:
    """A copy of ``robot`` recording the backlash b (n_dof,) [rad or m] in
    ``notes['backlash']`` (its nonzero entries; none: the note removed). The kinematics
    kernels do not apply it (it needs the direction of motion):
    :func:`~jwarp.calibration.estimate.result.model_frames` does, given ``directions``."""
    import json

    notes = dict(robot.notes)
    nz = {robot.joints[j].name: float(v) for j, v in enumerate(np.asarray(b, np.float64))
          if v != 0.0}
    if nz:
        notes[BACKLASH_NOTE] = json.dumps(nz)
    else:
        notes.pop(BACKLASH_NOTE, None)
    return robot.copy(notes=notes)


def harmonic_joints(robot: RobotModel, dh_frames: Iterable[int]) -> list[int]:
    """Joints (sorted indices) that drive at least one of the DH frames ``dh_frames``."""
    out: set[int] = set()
    for i in dh_frames:
        out.update(int(j) for j, _ in robot.frames[int(i)].coupling)
    return sorted(out)


def _free_masses(robot: RobotModel, measurement: Measurement, groups: list[str], dh_frames: list[int],
                 rel_sigma: float) -> list[int]:
    """Entries of ``robot.masses`` of the ``mass`` group (see :func:`influencing_masses`);
    a ValueError naming ``free`` when there are none."""
    if not robot.masses:
        raise ValueError(f"free: group '{MASS_GROUP}' selects nothing: robot '{robot.name}' "
                         f"has no point masses ('masses' in its robot file)")
    compliant = np.any(robot.kappa != 0, axis=1)
    free_axes = [KAPPA_GROUPS.index(g) for g in groups if g in KAPPA_GROUPS]
    if free_axes:
        compliant[dh_frames] = True
    measured = getattr(measurement, "frames", None) if measurement is not None else None
    entries = influencing_masses(robot, measured, compliant)
    if not entries:
        raise ValueError(f"free: group '{MASS_GROUP}' selects no masses: masses act only through "
                         f"the gravity torques of compliant joints, and no DH frame on the "
                         f"measured chains of robot '{robot.name}' is compliant; free a kappa "
                         f"group (kappa_theta, kappa_alpha, kappa_beta) or use a robot with "
                         f"nonzero kappa")
    if math.isfinite(rel_sigma):
        kept = [e for e in entries if robot.masses[e].mass > 0]
        if not kept:
            raise ValueError(f"free: group '{MASS_GROUP}' selects no masses: the candidate "
                             f"entries have nominal mass 0, where a relative prior has zero "
                             f"width; give sigma={{'{MASS_GROUP}': inf}} to free them without prior")
        entries = kept
    return entries


@dataclass
class ParameterSpace:
    """Map between the free-parameter vector ``x`` (P,) and robot/measurement parameters.

    Attributes (all (P,) unless noted):
        robot: the nominal RobotModel (its DH rows and kappa are the prior means).
        p_nominal: (P_meas,) all measurement parameters at nominal (fixed ones stay there).
        names, groups: parameter names and groups.
        nominal, sigma: prior means and standard deviations (sigma inf = no prior).
        kind: 0 DH entry, 1 compliance, 2 measurement parameter, 3 point mass, 4 joint
            transmission coefficient (``harmonic``), 5 nonlinear compliance, 6 joint
            origin pose error (``origin``).
        frame, column: robot frame and DH column (kind 0) / kappa axis (kind 1) / index
            into ``robot.masses`` (kind 3, frame = the mass's frame); for kind 2 column is
            the index into the measurement's ParamBlock and frame is -1; kind 4: frame is
            the *joint* index and column ``2 (k - 1) + (0 for a, 1 for b)``; kind 5: the DH
            frame and column 2 (the theta axis); kind 6: the static frame and column
            0..5 (:data:`~.origin.ORIGIN_AXES`).
        lower, upper: bounds (masses >= 0; compliances >= 0 with ``bound_kappa``; else
            unbounded).
        free_groups: the groups that were freed, in the order given.
        typical: (P,) the solver's scale of each parameter: its prior sigma, or without a
            prior the group's default sigma (None: 1); the MAP solver replaces the latter
            by the data Jacobian's column scale at the start
            (:meth:`~.map.CalibrationProblem.scale_unpriored`), so that switching priors
            off does not make the solver's steps absurd (a 1 rad/(N m) compliance step).
    """

    robot: RobotModel
    p_nominal: np.ndarray
    names: list[str]
    groups: list[str]
    nominal: np.ndarray
    sigma: np.ndarray
    kind: np.ndarray  # (P,) int64 ParamKind codes
    frame: np.ndarray
    column: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    free_groups: list[str]
    typical: np.ndarray | None = None

    # ----------------------------------------------------------------- build
    @classmethod
    def build(cls, robot: RobotModel, measurement: Measurement, free: str | Iterable[str], *,
              sigma: Mapping[str, float] | None = None, frames: Iterable[int | str] | None = None,
              p_nominal: np.ndarray | None = None, bound_kappa: bool = False,
              orders: Mapping[str, int] | None = None) -> ParameterSpace:
        """Parameter space of the free groups.

        Args:
            robot: nominal robot (prior means of DH rows, compliances and the non-geometric
            extras ``harmonic`` and ``kappa_nonlinear``).
            measurement: a Measurement (needs ``frames`` and ``params``), or None for
                robot groups only.
            free: group names (see :data:`ROBOT_GROUPS` and the measurement's
                ``params.groups``), as a list or comma-separated string.
            sigma: per-group prior sigma overrides {group: sigma}; a measurement group given
                here replaces its ParamBlock sigmas; ``mass`` is relative to each nominal
                mass (0.1 = 10 %); ``inf`` removes the prior. Keys ``"group:pattern"``
                set the sigma of the group's parameters whose joint/frame part (before
                the ``.``) or whole name matches the fnmatch ``pattern``
                (``{"harmonic:torso_*": 5e-3}``); applied after the group's own, in the
                order given; a pattern that matches nothing is a ValueError.
            orders: harmonic orders {group: K} of ``harmonic`` and ``coupling`` (defaults
                :data:`HARMONIC_ORDER` (at least the robot's own K) and
                :data:`COUPLING_ORDER`), or per joint/frame ``{"harmonic:torso_*": 4}``
                (0: none for those).
            frames: DH frames whose rows may be calibrated, and static frames whose pose
                the ``origin`` group frees (default for ``origin``: the static frames
                preceding a joint frame on the measured chains; default for the DH groups
                :func:`influencing_frames`: the DH frames on the paths from the root to the
                frames the measurement uses, plus, for an elastic model, the mass-carrying
                DH frames branching off those paths, whose geometry and compliance load the
                measured chains through their weight).
            p_nominal: (P_meas,) measurement parameter prior means (default ParamBlock
                nominal).
            bound_kappa: give the compliances the bound kappa >= 0 (``lower``). The MAP
                solver keeps it by an active set around unbounded solves (scipy's box
                bounds make dogbox/trf stall at a start on the bound, see
                docs/calibration_robustness.md); without it the optimizer may cross
                zero and the calibrated robot clips negative compliances.

        The ``mass`` group takes the entries of :func:`influencing_masses` (compliant =
        nonzero kappa, or a kappa group freed here on the frame); a ValueError naming
        ``free`` says why when it selects none.
        """
        if not isinstance(robot, RobotModel):
            raise TypeError(f"robot: expected a RobotModel, got {type(robot).__name__}")
        groups = parse_groups(free)
        block = getattr(measurement, "params", None) if measurement is not None else None
        meas_groups = block.group_names() if block is not None else []
        valid = list(ROBOT_GROUPS) + [g for g in meas_groups if g not in ROBOT_GROUPS]
        bad = [g for g in groups if g not in valid]
        if bad:
            raise ValueError(f"free: unknown parameter group(s) {bad}; valid groups: "
                             f"{', '.join(valid)}")
        sig = dict(DEFAULT_SIGMA)
        if sigma is not None and not isinstance(sigma, Mapping):
            raise TypeError(f"sigma: expected a mapping {{group: sigma}}, got "
                            f"{type(sigma).__name__}")
        sig_whole, sig_keyed = split_keyed(sigma, "sigma", valid)
        for g, v in sig_whole.items():
            sig[g] = _check_sigma(v, f"sigma['{g}']")
        sig_keyed = [(g, pat, _check_sigma(v, f"sigma['{g}:{pat}']")) for g, pat, v in sig_keyed]
        if orders is not None and not isinstance(orders, Mapping):
            raise TypeError(f"orders: expected a mapping {{group: order}}, got "
                            f"{type(orders).__name__}")
        ord_whole, ord_keyed = split_keyed(orders, "orders", ORDER_GROUPS)
        ord_whole = {g: _check_order(v, f"orders['{g}']") for g, v in ord_whole.items()}
        ord_keyed = [(g, pat, _check_order(v, f"orders['{g}:{pat}']")) for g, pat, v in ord_keyed]
        ord_used = [False] * len(ord_keyed)

        def order_of(g: str, owner: str, default: int) -> int:
            k = ord_whole.get(g, default)
            for n, (gg, pat, v) in enumerate(ord_keyed):
                if gg == g and _matches(owner, pat):
                    k, ord_used[n] = v, True
            return k
        # which DH frames (and static frames of the origin group)
        static_frames: list[int] | None = None
        if frames is None:
            elastic = (any(g in KAPPA_GROUPS or g == KAPPA_NL_GROUP for g in groups)
                       or bool(np.any(robot.kappa != 0)) or bool(np.any(robot.kappa_nonlinear)))
            dh_frames = influencing_frames(robot, getattr(measurement, "frames", None)
                                           if measurement is not None else None, elastic)
        else:
            dh_frames, static_frames = [], []
            for f in frames:
                i = robot.frame_index(f, "frames")
                if not robot.is_dh[i]:
                    if ORIGIN_GROUP not in groups:
                        raise ValueError(f"frames: frame '{robot.frames[i].name}' is static; "
                                         f"only DH frames have calibratable rows (static "
                                         f"frames: free the '{ORIGIN_GROUP}' group)")
                    if i not in static_frames:
                        static_frames.append(i)
                elif i not in dh_frames:
                    dh_frames.append(i)
            dh_frames.sort()
            static_frames.sort()
        if block is not None:
            pn = block.nominal.copy() if p_nominal is None else np.asarray(p_nominal, np.float64)
            if pn.shape != (block.size,):
                raise ValueError(f"p_nominal: expected shape ({block.size},), got {pn.shape}")
            if not np.all(np.isfinite(pn)):
                raise ValueError("p_nominal: contains NaN or inf")
        else:
            pn = np.zeros(0)
        names: list[str] = []
        grp: list[str] = []
        nom: list[float] = []
        sg: list[float] = []
        kind: list[int] = []
        frm: list[int] = []
        col: list[int] = []
        for g in groups:
            if g in DH_GROUPS or g in KAPPA_GROUPS:
                is_k = g in KAPPA_GROUPS
                c = KAPPA_GROUPS.index(g) if is_k else DH_GROUPS.index(g)
                for i in dh_frames:
                    names.append(f"{robot.frames[i].name}.{g}")
                    grp.append(g)
                    nom.append(float(robot.kappa[i, c] if is_k else robot.dh_table[i, c]))
                    sg.append(sig[g])
                    kind.append(KIND_KAPPA if is_k else KIND_DH)
                    frm.append(i)
                    col.append(c)
            elif g == MASS_GROUP:
                entries = _free_masses(robot, measurement, groups, dh_frames, sig[g])
                all_names = mass_names(robot)
                for e in entries:
                    m0 = float(robot.masses[e].mass)
                    names.append(all_names[e])
                    grp.append(g)
                    nom.append(m0)
                    sg.append(sig[g] * m0 if math.isfinite(sig[g]) else math.inf)
                    kind.append(KIND_MASS)
                    frm.append(int(robot.masses[e].frame))
                    col.append(int(e))
            elif g == HARMONIC_GROUP:
                K0 = max(ord_whole.get(g, HARMONIC_ORDER), robot.harmonic.shape[1])
                for j in harmonic_joints(robot, dh_frames):
                    K = order_of(g, robot.joints[j].name, K0)
                    for k in range(K):
                        for ab in range(2):
                            names.append(f"{robot.joints[j].name}.harmonic_{'ab'[ab]}{k + 1}")
                            grp.append(g)
                            nom.append(float(robot.harmonic[j, k, ab])
                                       if k < robot.harmonic.shape[1] else 0.0)
                            sg.append(sig[g])
                            kind.append(KIND_HARMONIC)
                            frm.append(j)
                            col.append(2 * k + ab)
            elif g == BACKLASH_GROUP:
                bl0 = robot_backlash(robot)
                for j in harmonic_joints(robot, dh_frames):
                    names.append(f"{robot.joints[j].name}.backlash")
                    grp.append(g)
                    nom.append(float(bl0[j]))
                    sg.append(sig[g])
                    kind.append(KIND_BACKLASH)
                    frm.append(j)
                    col.append(0)
            elif g == ORIGIN_GROUP:
                if static_frames is None:
                    measured = (getattr(measurement, "frames", None)
                                if measurement is not None else None)
                    static_frames = origin_frames(robot, measured_chain(robot, measured))
                if not static_frames:
                    raise ValueError(f"free: group '{ORIGIN_GROUP}' selects no frames: robot "
                                     f"'{robot.name}' has no static frame preceding a joint "
                                     f"frame on the measured chains (name static frames "
                                     f"with frames=)")
                for i in static_frames:
                    for c, ax in enumerate(ORIGIN_AXES):
                        names.append(f"{robot.frames[i].name}.{g}_{ax}")
                        grp.append(g)
                        nom.append(0.0)
                        sg.append(sig[g])
                        kind.append(KIND_ORIGIN)
                        frm.append(i)
                        col.append(c)
            elif g == COUPLING_GROUP:
                cfr = coupled_frames(robot, dh_frames)
                if not cfr:
                    raise ValueError(f"free: group '{COUPLING_GROUP}' selects no frames: no DH "
                                     f"frame on the measured chains of robot '{robot.name}' is "
                                     f"coupled (driven by several joints or by a coefficient "
                                     f"other than 1)")
                ch = robot.coupling_harmonic
                for i in cfr:
                    fname = robot.frames[i].name
                    offset_group = "d" if robot.frame_is_prismatic[i] else "theta"
                    centries: list[tuple[str, int, float]] = []
                    if offset_group not in groups:
                        centries.append((f"{fname}.{g}_offset", 0, 0.0))
                    for t, (j, coef) in enumerate(robot.frames[i].coupling):
                        centries.append((f"{fname}.{g}_{robot.joints[j].name}",
                                         COUPLING_COEF + t, float(coef)))
                    K = order_of(g, fname, ord_whole.get(g, COUPLING_ORDER))
                    for k in range(K):
                        for ab in range(2):
                            centries.append((f"{fname}.{g}_{'ab'[ab]}{k + 1}",
                                             COUPLING_HARM + 2 * k + ab,
                                             float(ch[i, k, ab]) if k < ch.shape[1] else 0.0))
                    for nm, cc, v in centries:
                        names.append(nm)
                        grp.append(g)
                        nom.append(v)
                        sg.append(sig[g])
                        kind.append(KIND_COUPLING)
                        frm.append(i)
                        col.append(cc)
            elif g == KAPPA_NL_GROUP:
                for i in dh_frames:
                    names.append(f"{robot.frames[i].name}.{g}")
                    grp.append(g)
                    nom.append(float(robot.kappa_nonlinear[i]))
                    sg.append(sig[g])
                    kind.append(KIND_KAPPA_NL)
                    frm.append(i)
                    col.append(2)
            else:
                assert block is not None  # g is one of the measurement's groups
                for k in block.indices(g):
                    names.append(block.names[k])
                    grp.append(g)
                    nom.append(float(pn[k]))
                    sg.append(sig[g] if g in (sigma or {}) else float(block.sigma[k]))
                    kind.append(KIND_MEAS)
                    frm.append(-1)
                    col.append(int(k))
        if not names:
            raise ValueError(f"free: the groups {groups} select no parameters (no DH frames "
                             f"on the measured chains?)")
        for n, (g, pat, _) in enumerate(ord_keyed):
            if not ord_used[n] and g in groups:
                raise ValueError(f"orders['{g}:{pat}']: the pattern matches no "
                                 f"{'joint' if g == HARMONIC_GROUP else 'coupled frame'} of "
                                 f"the '{g}' group")
        # the typical scale of a parameter without prior: the group's default sigma
        typical = [s_ if math.isfinite(s_) else math.inf for s_ in sg]
        for k, g in enumerate(grp):
            if not math.isfinite(typical[k]):
                if g == MASS_GROUP:
                    typical[k] = DEFAULT_SIGMA[MASS_GROUP] * max(nom[k], 1.0)
                elif g in DEFAULT_SIGMA:
                    typical[k] = DEFAULT_SIGMA[g]
                elif kind[k] == KIND_MEAS and math.isfinite(
                        float(cast(Any, block).sigma[col[k]])):  # a measurement parameter
                    typical[k] = float(cast(Any, block).sigma[col[k]])
                else:
                    typical[k] = 1.0
        for g, pat, v in sig_keyed:
            hit = [k for k, (gg, nm) in enumerate(zip(grp, names)) if gg == g and _matches(nm, pat)]
            if not hit:
                raise ValueError(f"sigma['{g}:{pat}']: the pattern matches no parameter of the "
                                 f"'{g}' group (is the group free?)")
            for k in hit:
                sg[k] = v * nom[k] if (g == MASS_GROUP and math.isfinite(v)) else v
                if math.isfinite(sg[k]):
                    typical[k] = sg[k]
        kind_a = np.array(kind, np.int64)
        lower = np.where((kind_a == KIND_KAPPA) & bool(bound_kappa), 0.0, -np.inf)
        lower[kind_a == KIND_MASS] = 0.0
        return cls(robot=robot, p_nominal=pn, names=names, groups=grp,
                   nominal=np.array(nom), sigma=np.array(sg), kind=kind_a,
                   frame=np.array(frm, np.int64), column=np.array(col, np.int64),
                   lower=lower, upper=np.full(len(names), np.inf), free_groups=groups,
                   typical=np.array(typical, np.float64))

    # ------------------------------------------------------------- queries
    @property
    def size(self) -> int:
        return len(self.names)

    def mask(self, kind: int) -> np.ndarray:
        return self.kind == kind

    @property
    def has_prior(self) -> np.ndarray:
        """(P,) bool: parameters with a finite prior sigma."""
        return np.isfinite(self.sigma)

    @property
    def scale(self) -> np.ndarray:
        """(P,) typical scale per parameter: its prior sigma; where there is none the
        group's default sigma (:attr:`typical`), else 1."""
        fallback = 1.0 if self.typical is None else self.typical
        return np.where(self.has_prior, self.sigma, fallback)

    def index(self, name: str) -> int:
        try:
            return self.names.index(name)
        except ValueError:
            raise ValueError(f"name: unknown parameter '{name}'") from None

    def check(self, x: ArrayLike, name: str = "x") -> np.ndarray:
        a = np.asarray(x, np.float64)
        if a.shape != (self.size,):
            raise ValueError(f"{name}: expected shape ({self.size},), got {a.shape}")
        if not np.all(np.isfinite(a)):
            raise ValueError(f"{name}: contains NaN or inf")
        return a

    # ---------------------------------------------------------- x -> model
    def unpack(self, x: ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """x (P,) -> (DH rows rho0 (n_frames, 5), kappa (n_frames, 3), measurement p
        (P_meas,), point masses (len(robot.masses),) [kg]); fixed parts at nominal."""
        x = self.check(x)
        dh = self.robot.dh_table.copy()
        kap = self.robot.kappa.copy()
        p = self.p_nominal.copy()
        mass = self.nominal_masses
        m = self.kind == KIND_DH
        dh[self.frame[m], self.column[m]] = x[m]
        m = self.kind == KIND_KAPPA
        kap[self.frame[m], self.column[m]] = x[m]
        m = self.kind == KIND_MEAS
        p[self.column[m]] = x[m]
        m = self.kind == KIND_MASS
        mass[self.column[m]] = x[m]
        return dh, kap, p, mass

    def pack(self, dh: np.ndarray | None = None, kappa: np.ndarray | None = None,
             p: np.ndarray | None = None, masses: np.ndarray | None = None) -> np.ndarray:
        """Inverse of :meth:`unpack` (missing parts at nominal); ``masses``
        (len(robot.masses),) [kg] as :meth:`RobotModel.mass_arrays` gives them."""
        x = self.nominal.copy()
        if dh is not None:
            m = self.kind == KIND_DH
            x[m] = np.asarray(dh, np.float64)[self.frame[m], self.column[m]]
        if kappa is not None:
            m = self.kind == KIND_KAPPA
            x[m] = np.asarray(kappa, np.float64)[self.frame[m], self.column[m]]
        if p is not None:
            m = self.kind == KIND_MEAS
            x[m] = np.asarray(p, np.float64)[self.column[m]]
        if masses is not None:
            a = np.asarray(masses, np.float64)
            if a.shape != (len(self.robot.masses),):
                raise ValueError(f"masses: expected shape ({len(self.robot.masses)},), "
                                 f"got {a.shape}")
            m = self.kind == KIND_MASS
            x[m] = a[self.column[m]]
        return x

    def robot_at(self, x: ArrayLike) -> RobotModel:
        """A calibrated copy of the robot: DH rows, compliances and (when the ``mass``
        group is free) point masses from ``x``; negative compliances / masses clipped to 0."""
        dh, kap, _, mass = self.unpack(x)
        out = self.robot.with_dh(dh, kappa=np.maximum(kap, 0.0))
        if self.mass_entries.size:
            out = out.with_masses(np.maximum(mass, 0.0))
        if np.any(self.kind == KIND_HARMONIC) or np.any(self.kind == KIND_KAPPA_NL):
            out = out.copy(harmonic=self.harmonic_at(x),
                           kappa_nonlinear=self.kappa_nonlinear_at(x))
        if np.any(self.kind == KIND_ORIGIN):
            out = with_static_transforms(out, self.static_transforms_at(x))
        if np.any(self.kind == KIND_COUPLING):
            out = self.with_coupling(out, x)
        if np.any(self.kind == KIND_BACKLASH):
            out = with_backlash(out, self.backlash_at(x))
        return out

    def coupling_at(self, x: ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The coupled frames at ``x``: (coupling matrix (n_frames, n_dof) with the
        calibrated coefficients, offsets (n_frames,) [rad or m] added to theta (d for a
        prismatic frame), coupling harmonics (n_frames, K, 2); the robot's where not
        free)."""
        x = self.check(x)
        rb = self.robot
        C = rb.coupling_matrix.copy()
        off = np.zeros(rb.n_frames)
        m = self.kind == KIND_COUPLING
        h0 = rb.coupling_harmonic
        hm = m & (self.column >= COUPLING_HARM)
        K = max(h0.shape[1], int((self.column[hm] - COUPLING_HARM).max()) // 2 + 1
                if hm.any() else 0)
        h = np.zeros((rb.n_frames, K, 2))
        h[:, :h0.shape[1]] = h0
        for p in np.nonzero(m)[0]:
            i, c = int(self.frame[p]), int(self.column[p])
            if c == 0:
                off[i] = x[p]
            elif c < COUPLING_HARM:
                j = rb.frames[i].coupling[c - COUPLING_COEF][0]
                C[i, j] = x[p]
            else:
                h[i, (c - COUPLING_HARM) // 2, (c - COUPLING_HARM) % 2] = x[p]
        return C, off, h

    def with_coupling(self, robot: RobotModel, x: ArrayLike) -> RobotModel:
        """``robot`` (a copy of :attr:`robot` with other groups applied) with the
        ``coupling`` group at ``x``: coefficients in the frames' couplings, offsets in
        their DH rows, harmonics in ``coupling_harmonic``."""
        C, off, h = self.coupling_at(x)
        doc = robot.to_dict()
        for i in np.unique(self.frame[self.kind == KIND_COUPLING]):
            fd = doc["frames"][int(i)]
            joints = [j for j, _ in self.robot.frames[int(i)].coupling]
            coef = [float(C[i, j]) for j in joints]
            fd.pop("joint", None)
            if len(joints) == 1 and coef[0] == 1.0:
                fd["joint"] = joints[0]
                fd.pop("coupled", None)
            else:
                fd["coupled"] = {"joints": joints, "coefficients": coef}
            fd["dh"][0 if self.robot.frame_is_prismatic[i] else 1] += float(off[i])
        doc.pop("coupling_harmonic", None)
        if h.shape[1] and np.any(h):
            doc["coupling_harmonic"] = {self.robot.frames[i].name: h[i].tolist()
                                        for i in range(self.robot.n_frames) if np.any(h[i])}
        return RobotModel.from_dict(doc)

    def static_transforms_at(self, x: ArrayLike) -> dict[int, np.ndarray]:
        """{static frame: (4, 4) transform ``T0 @ Trans(v) @ Rot(w)``} of the frames of
        the ``origin`` group at ``x`` (empty when the group is not free)."""
        x = self.check(x)
        m = self.kind == KIND_ORIGIN
        out = {}
        for i in np.unique(self.frame[m]):
            delta = np.zeros(6)
            sel = m & (self.frame == i)
            delta[self.column[sel]] = x[sel]
            out[int(i)] = self.robot.frames[int(i)].transform @ delta_transform(delta)
        return out

    def harmonic_at(self, x: ArrayLike) -> np.ndarray:
        """(n_dof, K, 2) joint transmission coefficients at ``x`` (fixed ones at the
        robot's; K as the ``harmonic`` group frees, or the robot's own)."""
        x = self.check(x)
        m = self.kind == KIND_HARMONIC
        h0 = self.robot.harmonic
        K = max(h0.shape[1], int(self.column[m].max()) // 2 + 1 if m.any() else 0)
        h = np.zeros((self.robot.n_dof, K, 2))
        h[:, :h0.shape[1]] = h0
        h[self.frame[m], self.column[m] // 2, self.column[m] % 2] = x[m]
        return h

    def backlash_at(self, x: ArrayLike) -> np.ndarray:
        """(n_dof,) backlash b_j [rad or m] at ``x`` (the robot's recorded one,
        :func:`robot_backlash`, where not free)."""
        x = self.check(x)
        out = robot_backlash(self.robot)
        m = self.kind == KIND_BACKLASH
        out[self.frame[m]] = x[m]
        return out

    def kappa_nonlinear_at(self, x: ArrayLike) -> np.ndarray:
        """(n_frames,) nonlinear joint compliances [rad/(N m)^3] at ``x``."""
        x = self.check(x)
        out = self.robot.kappa_nonlinear.copy()
        m = self.kind == KIND_KAPPA_NL
        out[self.frame[m]] = x[m]
        return out

    @property
    def kappa_nonlinear_free(self) -> np.ndarray:
        """(n_frames,) bool: frames whose nonlinear compliance is free."""
        out = np.zeros(self.robot.n_frames, bool)
        out[self.frame[self.kind == KIND_KAPPA_NL]] = True
        return out

    def measurement_params(self, x: ArrayLike) -> np.ndarray:
        """(P_meas,) all measurement parameters (fixed ones at nominal)."""
        return self.unpack(x)[2]

    @property
    def nominal_masses(self) -> np.ndarray:
        """(len(robot.masses),) the robot's point masses [kg] (a fresh copy)."""
        return np.array([m.mass for m in self.robot.masses], np.float64)

    @property
    def mass_entries(self) -> np.ndarray:
        """(P_m,) indices into ``robot.masses`` of the free masses, in parameter order."""
        return self.column[self.kind == KIND_MASS]

    def prior_residuals(self, x: ArrayLike) -> np.ndarray:
        """((x - nominal) / sigma) for the parameters with a prior, (P_prior,)."""
        x = np.asarray(x, np.float64)
        h = self.has_prior
        return (x[h] - self.nominal[h]) / self.sigma[h]

    def sample_prior(self, rng: np.random.Generator) -> np.ndarray:
        """A random x from the prior (parameters without prior stay at nominal), clipped to
        the bounds; compliances are drawn on the physical side (nominal + |N(0, sigma)|)."""
        dev = np.where(self.has_prior, self.sigma, 0.0) * rng.standard_normal(self.size)
        dev = np.where(self.kind == KIND_KAPPA, np.abs(dev), dev)
        return np.clip(self.nominal + dev, self.lower, self.upper)

    @property
    def kappa_free(self) -> np.ndarray:
        """(n_frames, 3) bool: compliance entries that are free."""
        out = np.zeros((self.robot.n_frames, 3), bool)
        m = self.kind == KIND_KAPPA
        out[self.frame[m], self.column[m]] = True
        return out


def perturb_robot(robot: RobotModel, rng: np.random.Generator, *,
                  groups: Iterable[str] = ("theta", "d", "r", "alpha"),
                  length_error: float = 0.005, angle_error: float = math.radians(5.0),
                  kappa: tuple[float, float] | Mapping[str, tuple[float, float]] | None = None,
                  kappa_groups: Iterable[str] = ("kappa_theta", "kappa_alpha"),
                  frames: Iterable[int | str] | None = None,
                  mass_error: float | None = None) -> RobotModel:
    """A "true" robot for simulated campaigns (thesis 2.6.1): the nominal DH entries of
    ``groups`` plus uniform errors in [-length_error, length_error] [m] (d, r) or
    [-angle_error, angle_error] [rad] (theta, alpha, beta) on the DH frames ``frames``
    (default all), compliances drawn uniformly from ``kappa`` = (low, high)
    [rad/(N m)] on the axes of ``kappa_groups``, or from per-group ranges ``kappa`` =
    {group: (low, high)} (then ``kappa_groups`` is ignored; drawn in the order given;
    None: keep the robot's kappa), and, with
    ``mass_error`` (relative, e.g. 0.15), every point mass on those frames times
    ``1 + U(-mass_error, mass_error)`` (None: nominal masses; drawn after everything else,
    so the other draws do not depend on it)."""
    groups = parse_groups(groups)
    bad = [g for g in groups if g not in DH_GROUPS]
    if bad:
        raise ValueError(f"groups: unknown DH group(s) {bad}; valid: {', '.join(DH_GROUPS)}")
    if frames is None:
        idx = np.nonzero(robot.is_dh)[0]
    else:
        idx = np.array([robot.frame_index(f, "frames") for f in frames], np.int64)
        if not np.all(robot.is_dh[idx]):
            raise ValueError("frames: only DH frames can be perturbed")
    if mass_error is not None:
        try:
            me = float(mass_error)
        except (TypeError, ValueError):
            raise ValueError(f"mass_error: expected a number in [0, 1), got {mass_error!r}") from None
        if not (0.0 <= me < 1.0):
            raise ValueError(f"mass_error: expected a relative error in [0, 1), got {mass_error!r}")
    dh = robot.dh_table.copy()
    for g in groups:
        c = DH_GROUPS.index(g)
        err = length_error if g in ("d", "r") else angle_error
        dh[idx, c] += rng.uniform(-err, err, idx.size)
    kap = robot.kappa.copy()
    if kappa is not None:
        if isinstance(kappa, Mapping):
            ranges = dict(kappa)
            where = "kappa"
        else:
            ranges = {g: kappa for g in parse_groups(kappa_groups)}
            where = "kappa_groups"
        for g, rg in ranges.items():
            try:
                lo, hi = map(float, rg)
            except (TypeError, ValueError):
                raise ValueError(f"kappa: expected (low, high), got {rg!r}") from None
            if not (0 <= lo <= hi):
                raise ValueError(f"kappa: expected 0 <= low <= high, got {rg!r}")
            if g not in KAPPA_GROUPS:
                raise ValueError(f"{where}: unknown group '{g}'; valid: {', '.join(KAPPA_GROUPS)}")
            c = KAPPA_GROUPS.index(g)
            kap[idx, c] = rng.uniform(lo, hi, idx.size)
    out = robot.with_dh(dh, kappa=kap)
    if mass_error is not None and robot.masses:
        values = np.array([m.mass for m in robot.masses], np.float64)
        on = np.isin([m.frame for m in robot.masses], idx) if frames is not None \
            else np.ones(values.size, bool)
        factor = 1.0 + rng.uniform(-me, me, values.size)
        out = out.with_masses(np.where(on, values * factor, values))
    return out
