"""Simulated calibration campaigns (thesis 2.6.1): a "true" robot, a rough setup, samples.

The true robot is the nominal one plus uniform DH errors (default +-1 mm on d and r,
+-0.3 deg on theta and alpha) and compliances (:data:`DEFAULT_KAPPA`), sized so that
justin19's nominal model is about as far off as Agile Justin's (~20 mm mean at the TCPs),
optionally with effects outside the calibration model (``unmodeled``:
:mod:`.unmodeled`); the true measurement parameters are the setup's nominal ones. The setup handed to the user (and written to ``setup.json``) is made
*rough*: the tracker / camera pose is moved by ``rough_position`` metres and
``rough_rotation`` radians in random directions and the markers by ``rough_marker`` metres,
as a lab's first guess would be. Observations are the true model's prediction plus Gaussian
noise of the measurement's ``noise``.

:meth:`Campaign.write` writes ``samples.csv``, ``setup.json`` and ``truth.json`` into a
folder as one set (:class:`~jwarp.utils.atomic.AtomicFolder`: all new or all old, also when the
process is killed), with a fresh ``campaign_id`` and the SHA-256 of ``samples.csv`` in
``setup.json`` and in the ``notes`` of ``truth.json``; :func:`read_campaign` reads such a
folder back and refuses one whose files do not belong together.
"""

from __future__ import annotations

import dataclasses
import math
import os
import uuid
import warnings
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from jwarp.calibration.estimate.params import perturb_robot, robot_backlash
from jwarp.calibration.estimate.result import model_frames
from jwarp.calibration.files import (
    Samples,
    Setup,
    make_measurement,
    parse_samples,
    read_setup,
    read_text,
    samples_text,
    sha256_hex,
    write_setup,
)
from jwarp.calibration.simulate.unmodeled import (
    Unmodeled,
    add_unmodeled,
    parse_unmodeled,
)
from jwarp.model import RobotModel
from jwarp.model.measurement import Measurement
from jwarp.utils.atomic import AtomicFolder, atomic_write_text, clean_stale

#: default truth of :func:`simulate_campaign`: uniform DH errors +-1 mm (d, r) and
#: +-0.3 deg (theta, alpha), joint compliances U(3e-5, 9e-5) and lateral (alpha) ones
#: U(1e-5, 3e-5) rad/(N m) -- sized like Agile Justin (paper Table I: the nominal model is
#: 21 mm off on average, 63 mm at most, joint elasticity the largest part). Measured on
#: justin19 with the tracker setup (uniform configurations, tracker and markers fitted on
#: 300, tested on 200, seeds 0-5): 17.4 mm mean / 57.5 mm max TCP error; with
#: ``unmodeled="all"`` 21.7 / 75.3 mm (docs/nongeometric.md).
DEFAULT_LENGTH_ERROR = 0.001
DEFAULT_ANGLE_ERROR = math.radians(0.3)
DEFAULT_KAPPA: Mapping[str, tuple[float, float]] = MappingProxyType(
    {"kappa_theta": (3e-5, 9e-5), "kappa_alpha": (1e-5, 3e-5)})

#: A sampler draws (q (n, n_dof), meta {name: (n,)}) candidates; ``accept`` filters them.
Sampler = Callable[[np.random.Generator, int], tuple[np.ndarray, dict[str, np.ndarray]]]


@dataclass
class Campaign:
    """A simulated campaign: the truth, the rough setup and the measured samples."""

    robot: RobotModel          # nominal model (what the user calibrates)
    true_robot: RobotModel     # nominal + DH errors + compliances
    setup: Setup               # rough setup (as a lab would write it)
    true_setup: Setup          # the exact measurement setup used to simulate
    true_params: np.ndarray    # (P,) true measurement parameters
    samples: Samples
    noise: float               # noise sigma used [unit of the measurement]
    campaign_id: str | None = None  # id of the last write (None: not written yet)

    def write(self, folder: str | os.PathLike, prefix: str = "", option: str = "folder"
              ) -> dict[str, str]:
        """Write ``<prefix>samples.csv``, ``<prefix>setup.json`` (rough) and
        ``<prefix>truth.json`` (the true robot) into ``folder`` as one set: the folder is
        replaced at once (:class:`~jwarp.utils.atomic.AtomicFolder`; its other files are kept),
        so a reader or a killed write never leaves files of two campaigns side by side.
        Each write draws a new :attr:`campaign_id`, recorded with the SHA-256 of the
        samples file in ``setup.json`` and ``truth.json`` (``notes``).

        Args:
            folder: made if missing; its parent folder must exist.
            option: the name errors give ``folder`` (e.g. ``--out``).

        Returns:
            {file name without prefix: path}.

        Raises:
            ValueError: the parent folder is missing or not writable, ``folder`` is a file.
        """
        folder = os.fspath(folder)
        meas = make_measurement(self.robot, self.setup)
        text = samples_text(self.robot, meas, self.samples)
        cid = uuid.uuid4().hex
        record: dict[str, Any] = {"campaign_id": cid, "samples_sha256": sha256_hex(text)}
        setup = dataclasses.replace(self.setup, path=None, **record)
        truth = self.true_robot.copy(notes={**self.true_robot.notes, **record})
        with AtomicFolder(folder, option=option) as out:
            atomic_write_text(out.file(f"{prefix}samples.csv"), text)
            write_setup(out.file(f"{prefix}setup.json"), setup)
            truth.save(out.file(f"{prefix}truth.json"))
        self.campaign_id = cid
        return {k: os.path.join(folder, f"{prefix}{k}") for k in CAMPAIGN_FILES}


#: the files of a campaign folder
CAMPAIGN_FILES = ("samples.csv", "setup.json", "truth.json")


@dataclass
class CampaignFiles:
    """A campaign folder read back by :func:`read_campaign`."""

    setup: Setup               # the rough setup written
    truth: RobotModel          # the true robot
    samples: Samples
    campaign_id: str | None    # None: files of a jwarp without campaign ids
    paths: dict[str, str]


def read_campaign(folder: str | os.PathLike, robot: RobotModel | None = None,
                  prefix: str = "") -> CampaignFiles:
    """Read a folder written by :meth:`Campaign.write` (``jwarp simulate-campaign``) and
    check that its three files belong to one campaign: ``setup.json`` and ``truth.json``
    name the same ``campaign_id`` and the SHA-256 they record is the one of
    ``samples.csv``. Files without any record (older jwarp) are read with a warning.
    A folder write cut by a kill between its two renames (systems without an atomic
    exchange) is finished first (:func:`~jwarp.utils.atomic.clean_stale`).

    Args:
        robot: the robot whose joints name the CSV columns (default: the true robot).

    Raises:
        ValueError: a file is missing or malformed, or the files are of different
            campaigns (naming them).
    """
    folder = os.fspath(folder)
    clean_stale(folder)  # finishes a folder swap cut by a kill (see AtomicFolder)
    paths = {k: os.path.join(folder, f"{prefix}{k}") for k in CAMPAIGN_FILES}
    missing = [f"{prefix}{k}" for k, p in paths.items() if not os.path.isfile(p)]
    if missing:
        raise ValueError(f"{folder}: not a campaign folder: missing {', '.join(missing)}")
    setup = read_setup(paths["setup.json"])
    truth = RobotModel.load(paths["truth.json"])
    text, raw = read_text(paths["samples.csv"], "data")
    ids = {"setup.json": setup.campaign_id, "truth.json": truth.notes.get("campaign_id")}
    shas = {"setup.json": setup.samples_sha256, "truth.json": truth.notes.get("samples_sha256")}
    sha = sha256_hex(raw)
    names = {k: f"{prefix}{k}" for k in CAMPAIGN_FILES}
    if not any(ids.values()) and not any(shas.values()):
        warnings.warn(f"{folder}: no campaign id in {names['setup.json']} and "
                      f"{names['truth.json']} (written by an older jwarp?): cannot check that "
                      f"the files belong together", stacklevel=2)
    else:
        if len(set(ids.values())) != 1:
            raise ValueError(
                f"{folder}: {names['setup.json']} (campaign {ids['setup.json']}) and "
                f"{names['truth.json']} (campaign {ids['truth.json']}) are not of one "
                f"campaign; write the folder again (jwarp simulate-campaign)")
        wrong = [names[k] for k, s in shas.items() if s != sha]
        if wrong:
            raise ValueError(
                f"{folder}: {names['samples.csv']} is not the samples file of campaign "
                f"{ids['setup.json']} (its SHA-256 differs from the one {' and '.join(wrong)} "
                f"record{'s' if len(wrong) == 1 else ''}); write the folder again")
    parse_robot = robot if robot is not None else truth
    samples = parse_samples(text, parse_robot, make_measurement(parse_robot, setup),
                            where=paths["samples.csv"])
    return CampaignFiles(setup=setup, truth=truth, samples=samples,
                         campaign_id=ids["setup.json"], paths=paths)


def uniform_configurations(robot: RobotModel, rng: np.random.Generator, n: int,
                           margin: float = 0.0) -> np.ndarray:
    """(n, n_dof) joint values uniform inside the joint limits (shrunk by ``margin``) that
    also satisfy the robot's linear (coupled) limits, e.g. justin19's 0 <= q1+q2 <= 2.356."""
    lim = np.asarray(robot.joint_limits, np.float64)
    lo, hi = lim[:, 0] + margin, lim[:, 1] - margin
    out = np.empty((0, robot.n_dof))
    for _ in range(1000):
        q = lo + (hi - lo) * rng.random((max(2 * n, 16), robot.n_dof))
        ok = np.ones(len(q), bool)
        for ll in robot.linear_limits:
            v = q[:, ll.joints] @ np.asarray(ll.coefficients)
            ok &= (v >= ll.lower + margin) & (v <= ll.upper - margin)
        out = np.concatenate([out, q[ok]])
        if len(out) >= n:
            return out[:n]
    raise ValueError("robot: could not sample configurations inside the linear limits")


def _rough_pose(section: dict, key: str, rng: np.random.Generator, dp: float, dr: float) -> None:
    pose = section.get(key)
    if not isinstance(pose, dict) or dp == 0 and dr == 0:
        return
    u = rng.normal(size=3)
    pose["position"] = (np.asarray(pose.get("position", [0, 0, 0]), float)
                        + dp * u / np.linalg.norm(u)).tolist()
    a = rng.normal(size=3)
    r = Rotation.from_rotvec(dr * a / np.linalg.norm(a)) * Rotation.from_rotvec(
        np.asarray(pose.get("rotvec", [0, 0, 0]), float))
    pose["rotvec"] = r.as_rotvec().tolist()


def rough_setup(setup: Setup, rng: np.random.Generator, *, rough_position: float = 0.2,
                rough_rotation: float = math.radians(20.0), rough_marker: float = 0.01) -> Setup:
    """A copy of ``setup`` with the tracker/camera pose and the markers moved randomly."""
    import copy

    sec = copy.deepcopy(setup.section)
    for key in ("tracker", "camera"):
        _rough_pose(sec, key, rng, rough_position, rough_rotation)
    for mk in sec.get("markers", []) or []:
        if isinstance(mk, dict) and "position" in mk and rough_marker > 0:
            u = rng.normal(size=3)
            mk["position"] = (np.asarray(mk["position"], float)
                              + rough_marker * u / np.linalg.norm(u)).tolist()
    return Setup(plugin=setup.plugin, section=sec, robot=setup.robot,
                 description=setup.description, cameras=setup.cameras,
                 marker_normals=setup.marker_normals)


def simulate_campaign(robot: RobotModel, setup: Setup, n: int, *, seed: int = 0,
                      noise: float | None = None, true_robot: RobotModel | None = None,
                      dh_groups: tuple[str, ...] = ("theta", "d", "r", "alpha"),
                      length_error: float = DEFAULT_LENGTH_ERROR,
                      angle_error: float = DEFAULT_ANGLE_ERROR,
                      kappa: tuple[float, float] | Mapping[str, tuple[float, float]] | None
                      = DEFAULT_KAPPA,
                      kappa_groups: tuple[str, ...] = ("kappa_theta", "kappa_alpha"),
                      rough_position: float = 0.2, rough_rotation: float = math.radians(20.0),
                      rough_marker: float = 0.01, sampler: Sampler | None = None,
                      accept: Callable[[Measurement, np.ndarray, np.ndarray, dict], np.ndarray]
                      | None = None, max_draws: int = 200,
                      collision_margin: float | None = 0.02,
                      unmodeled: Unmodeled | str | None = None) -> Campaign:
    """Simulate ``n`` samples of the measurement ``setup`` on a perturbed ``robot``.

    Args:
        robot: nominal model; ``setup``: the exact measurement setup of the truth.
        noise: observation noise sigma [unit of y] (default: the setup's ``noise``).
        true_robot: use this truth instead of drawing one with :func:`perturb_robot`
            (``dh_groups``, ``length_error`` [m], ``angle_error`` [rad], ``kappa``
            (low, high) [rad/(N m)] on ``kappa_groups`` or per group {group: (low,
            high)}; None keeps the nominal kappa). The defaults (:data:`DEFAULT_KAPPA`
            and above) put justin19's nominal model 17 mm (mean) / 58 mm (max) off at the
            TCPs, 22 / 75 mm with ``unmodeled="all"``; the former +-5 mm / +-5 deg gave
            ~130 mm.
        rough_*: how far the written setup is from the truth (see :func:`rough_setup`).
        sampler: draws candidate (q, meta) (default: uniform in the limits, no meta).
        accept: (meas, frames, p, meta) -> (k,) bool keeps candidates (e.g. markers visible).
        collision_margin: candidates pass the pose sampler's checks on the nominal robot
            (:class:`~jwarp.calibration.design.poses.PoseSampler`: joint limits,
            self-collision with this margin [m], and the setup's ``cameras`` if any) before
            ``accept``; None draws without these checks (then about 34-40 % of the
            tracker rows and 54 % of the camera rows self-collide). Contact setups use
            margin 0 (the fingers touch by design; 2 cm would reject almost every contact).
        unmodeled: effects added to the truth that the calibration model lacks (joint
            transmission errors, torque-dependent stiffness, lateral compliance;
            :mod:`.unmodeled`, e.g. ``"harmonic,kappa_nonlinear,kappa_beta"`` or ``"all"``),
            drawn from their own stream of ``seed`` (the other draws do not change) and
            stored in the true robot (``harmonic``, ``kappa_nonlinear``, ``kappa``), so
            the written truth reproduces the data. Default None: no systematic error.
    """
    unmodeled = parse_unmodeled(unmodeled)
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise ValueError(f"n: expected a number of samples >= 1, got {n!r}")
    rng = np.random.default_rng(seed)
    if true_robot is None:
        true_robot = perturb_robot(robot, rng, groups=dh_groups, length_error=length_error,
                                   angle_error=angle_error, kappa=kappa, kappa_groups=kappa_groups)
    if unmodeled:
        urng = np.random.default_rng([int(seed), 0x756e6d])   # own stream ("unm")
        q_ref = uniform_configurations(robot, urng, 500)
        true_robot = add_unmodeled(true_robot, unmodeled, urng, q_ref)
    meas = make_measurement(true_robot, setup)
    p_true = meas.params.nominal.copy()
    sigma = float(meas.noise if noise is None else noise)
    if not (math.isfinite(sigma) and sigma >= 0):
        raise ValueError(f"noise: expected a finite sigma >= 0, got {noise!r}")
    if sampler is None:
        if meas.meta_names:
            raise ValueError(f"sampler: the '{meas.name}' measurement needs per-sample "
                             f"{meas.meta_names}; pass a sampler")

        def sampler(r: np.random.Generator, k: int) -> tuple[np.ndarray, dict]:
            return uniform_configurations(robot, r, k), {}

    poses = None
    if collision_margin is not None:
        from jwarp.calibration.design.poses import PoseOptions, PoseSampler

        margin = 0.0 if setup.plugin == "contact" else float(collision_margin)
        poses = PoseSampler(robot, setup, PoseOptions(margin=margin, dtype="float64"))
    qs, metas, frames_kept = [], [], []
    have = 0
    for _ in range(max_draws):
        q, meta = sampler(rng, max(n - have, 8))
        keep = np.ones(len(q), bool) if poses is None or len(q) == 0 else poses.ok(q)
        q, meta = q[keep], {k: np.asarray(v)[keep] for k, v in meta.items()}
        if len(q) == 0:
            continue
        fr = model_frames(true_robot, q)
        ok = np.ones(len(q), bool) if accept is None else np.asarray(accept(meas, fr, p_true, meta))
        if ok.any():
            qs.append(q[ok])
            metas.append({k: np.asarray(v)[ok] for k, v in meta.items()})
            frames_kept.append(fr[ok])
            have += int(ok.sum())
        if have >= n:
            break
    if have < n:
        raise ValueError(f"accept: only {have} of {n} samples accepted after {max_draws} draws")
    q = np.concatenate(qs)[:n]
    meta = {k: np.concatenate([m[k] for m in metas])[:n] for k in metas[0]}
    fr = np.concatenate(frames_kept)[:n]
    if np.any(robot_backlash(true_robot)):   # the direction of motion: the samples' order
        from jwarp.calibration.estimate.backlash import motion_directions

        fr = model_frames(true_robot, q, directions=motion_directions(q))
    y = meas.simulate(fr, p_true, sigma, rng, meta or None)
    rough = rough_setup(setup, rng, rough_position=rough_position,
                        rough_rotation=rough_rotation, rough_marker=rough_marker)
    return Campaign(robot=robot, true_robot=true_robot, setup=rough, true_setup=setup,
                    true_params=p_true, samples=Samples(q=q, y=np.asarray(y), meta=meta),
                    noise=sigma)


def justin_tracker_setup(noise: float = 0.001) -> Setup:
    """The external-tracker setup of the paper (Table I): a tracker about 2.5 m in front of
    Agile Justin looking back at it, one marker on each TCP."""
    section: dict[str, Any] = {
        "tracker": {"position": [2.5, 0.2, 1.3], "rotvec": [0.0, 0.0, math.pi],
                    "sigma_position": 1.0, "sigma_rotation": 1.0},
        "markers": [{"name": "right", "frame": "right_tcp", "position": [0.0, 0.0, 0.05],
                     "sigma": 0.05},
                    {"name": "left", "frame": "left_tcp", "position": [0.0, 0.0, 0.05],
                     "sigma": 0.05}],
        "noise": noise,
    }
    return Setup(plugin="cartesian", section=section, robot="justin19",
                 description="Agile Justin with an external tracker, markers on both TCPs")
