"""Built-in simulated calibration campaigns (thesis 2.6.1-2.6.3, paper VI-A).

:func:`scenario` ``(robot_name, plugin) -> (Setup, sampler or None, accept or None)`` gives
the exact ("true") measurement setup of a campaign and how its configurations are drawn;
:func:`~jwarp.calibration.simulate.campaign.simulate_campaign` turns it into samples of a
perturbed robot (``jwarp simulate-campaign --robot R --plugin P`` uses it):

================  =========  ===========================================================
robot             plugin     campaign
================  =========  ===========================================================
``justin19``      cartesian  external tracker ~2.5 m in front, a marker 5 cm off each TCP;
                             configurations uniform in the joint limits
``justin19``      image      head camera (on ``head_tcp``) seeing a marker on each hand and
                             three markers on a fixed pole; the sampler places both hands
                             in front of the head and points the head at hands + pole;
                             ``accept`` keeps samples where every marker is in the image
``justin19``      relative   right TCP relative to the left TCP (task function, eq. 2.46)
``hand4``         contact    signed distance between the fingertip capsules of the thumb
                             and each finger; samples are in contact on the NOMINAL model
================  =========  ===========================================================

The samplers see only the nominal robot (the truth is unknown when a campaign is planned);
``accept`` is evaluated by ``simulate_campaign`` on the true robot's frames and the true
measurement parameters (a marker the real camera does not see is not measured).

Contact campaign: on the real hand a sample is a configuration where the fingertips touch
and the measured distance is 0. The truth is not known when the sampler runs, so the
sampler finds configurations where the two capsules touch on the *nominal* model (a 1-D
root find on the segment between a penetrating and a separated configuration), and the
observation ``simulate_campaign`` records is the *true* model's signed distance there plus
noise -- the same information (one scalar distance per pair and configuration), just not
at distance 0.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from jwarp.calibration.files import Setup, make_measurement
from jwarp.calibration.simulate.campaign import (
    Sampler,
    justin_tracker_setup,
    uniform_configurations,
)
from jwarp.model import RobotModel
from jwarp.model.measurement import Measurement
from jwarp.plugins.registry import robot as get_robot

#: ``accept(measurement, frames (S, n_frames, 4, 4), p (P,), meta) -> (S,) bool``
Accept = Callable[[Measurement, np.ndarray, np.ndarray, dict], np.ndarray]

# ----------------------------------------------------------------- justin19 image
#: camera mount in ``head_tcp`` (x forward, y left, z up at q = 0): 8 cm forward, 5 cm up,
#: optical axis (camera z) = head x, image right (camera x) = head -y, image down = head -z
HEAD_CAMERA_POSITION = [0.08, 0.0, 0.05]
HEAD_CAMERA_ROTVEC = [-1.2091995761561452, 1.2091995761561452, -1.2091995761561452]
#: "true" intrinsics of the simulated head camera (1280 x 960 px); a datasheet would say
#: focal 600, centre (640, 480), xi 0 (see examples/calibrate_justin_camera.py)
HEAD_CAMERA_INTRINSICS = {"focal": [612.0, 607.0], "center": [646.0, 474.0], "xi": 0.03,
                          "size": [1280, 960]}
#: pole markers in the base frame [m]: a vertical pole 1.1 m in front of the robot
POLE_MARKERS = [[1.1, 0.0, 0.85], [1.1, 0.0, 1.05], [1.1, 0.0, 1.25]]


def justin_camera_setup(noise: float = 1.0) -> Setup:
    """Agile Justin's head camera (thesis 2.6.3, Fig. 2.18): pinhole with radial
    distortion on ``head_tcp``, a marker 5 cm off each TCP and three on a fixed pole.

    Args:
        noise: pixel noise sigma [px].
    """
    section: dict[str, Any] = {
        "camera": {"frame": "head_tcp", "position": list(HEAD_CAMERA_POSITION),
                   "rotvec": list(HEAD_CAMERA_ROTVEC), "sigma_position": 0.05,
                   "sigma_rotation": 0.2},
        "intrinsics": {**{k: list(v) if isinstance(v, list) else v
                          for k, v in HEAD_CAMERA_INTRINSICS.items()},
                       "sigma_focal": 10.0, "sigma_center": 10.0, "sigma_xi": 0.1},
        "markers": ([{"name": "right", "frame": "right_tcp", "position": [0.0, 0.0, 0.05],
                      "sigma": 0.02},
                     {"name": "left", "frame": "left_tcp", "position": [0.0, 0.0, 0.05],
                      "sigma": 0.02}]
                    + [{"name": f"pole{k + 1}", "frame": None, "position": list(x),
                        "sigma": 0.02} for k, x in enumerate(POLE_MARKERS)]),
        "noise": float(noise),
    }
    return Setup(plugin="image", section=section, robot="justin19",
                 description="Agile Justin's head camera seeing markers on both hands and a "
                             "pole (thesis 2.6.3)")


def look_at_head_joints(robot: RobotModel, q: np.ndarray, target: np.ndarray,
                        clip: bool = True) -> np.ndarray:
    """Head pan/tilt that point the x axis of ``head_tcp`` (the camera's optical axis in
    :func:`justin_camera_setup`) at world points, on the model ``robot``.

    justin19's head is ``head_tcp = head_base . Rot_z(pan) . Rot_y(tilt)`` (nominal DH), so
    with ``v`` the target direction in ``head_base`` coordinates, pan = atan2(v_y, v_x)
    and tilt = atan2(-v_z, |v_xy|) (positive tilt looks down).

    Args:
        robot: justin19-like model with frames ``head_base`` and ``head_tcp``.
        q: (S, n_dof) configurations (head joints ignored).
        target: (S, 3) world points [m].

    Returns:
        (S, 2) [pan, tilt] [rad], clipped to the head joint limits when ``clip``.
    """
    from jwarp.kinematics.fk import fk

    hb = robot.frame_index("head_base")
    ht = robot.frame_index("head_tcp")
    F = fk(robot, q, device="cpu", dtype="float64")
    R, o = F[:, hb, :3, :3], F[:, ht, :3, 3]
    v = np.einsum("sji,sj->si", R, np.asarray(target, np.float64) - o)
    pan = np.arctan2(v[:, 1], v[:, 0])
    tilt = np.arctan2(-v[:, 2], np.hypot(v[:, 0], v[:, 1]))
    if not clip:
        return np.stack([pan, tilt], axis=1)
    lim = robot.joint_limits
    jp, jt = robot.joint_index("head_pan"), robot.joint_index("head_tilt")
    return np.stack([np.clip(pan, lim[jp, 0], lim[jp, 1]),
                     np.clip(tilt, lim[jt, 0], lim[jt, 1])], axis=1)


def justin_camera_sampler(robot: RobotModel, setup: Setup, *, candidates: int = 48,
                          cone: float = math.radians(32.0), distance: tuple[float, float]
                          = (0.35, 1.1), margin: float = math.radians(10.0)) -> Sampler:
    """Sampler of the head-camera campaign on the nominal ``robot``.

    Per sample: torso joints uniform in their limits; per arm, ``candidates`` uniform arm
    configurations of which the first whose TCP marker is ``distance`` [m] from the head
    and within ``cone`` [rad] of the pole's direction is kept (without fixed markers: the
    first hand 0.2 m in front of and below the head, the next ones within ``cone`` of it;
    samples where an arm finds none are dropped); torso poses from which the head cannot
    look at the pole (pan/tilt within ``margin`` [rad] of their limits) are dropped; the
    head looks at the mean
    direction of the hand and pole markers. The rest (markers inside the image on the true
    robot) is ``accept``'s job. Returns up to k samples per call, no meta."""
    meas = make_measurement(robot, setup)
    p = meas.params.nominal
    names = meas.params.names
    mk = {}
    for m in meas.setup["markers"]:
        i = names.index(f"marker_{m['name']}_x")
        mk[m["name"]] = (m["frame"], p[i:i + 3])
    arm_markers = [(n, robot.frame_index(f), x) for n, (f, x) in mk.items() if f is not None]
    fixed = np.array([x for f, x in mk.values() if f is None], np.float64).reshape(-1, 3)
    pole = fixed.mean(axis=0) if len(fixed) else None
    ht = robot.frame_index("head_tcp")
    lim = robot.joint_limits
    head = np.array([robot.joint_index("head_pan"), robot.joint_index("head_tilt")])
    cos_cone = math.cos(cone)

    def arm_joints(frame: int) -> np.ndarray:
        chain = set(robot.ancestors(frame)) | {frame}
        cols = set()
        for i in chain:
            for j, _ in robot.frames[i].coupling or []:
                cols.add(int(j))
        torso = {robot.joint_index(n) for n in robot.joint_names if n.startswith("torso")}
        return np.array(sorted(cols - torso), np.int64)

    def sampler(rng: np.random.Generator, k: int) -> tuple[np.ndarray, dict]:
        from jwarp.kinematics.fk import fk

        q = uniform_configurations(robot, rng, k if pole is None else 4 * k)
        q[:, head] = 0.0
        if pole is not None:   # torso poses from which the head can look at the pole
            hj = look_at_head_joints(robot, q, np.broadcast_to(pole, (len(q), 3)), clip=False)
            inside = np.all((hj > lim[head, 0] + margin) & (hj < lim[head, 1] - margin), axis=1)
            q = q[inside][:k]
            k = len(q)
            if k == 0:
                return q, {}
        F = fk(robot, q, device="cpu", dtype="float64")
        eye = F[:, ht, :3, 3]                                   # (k, 3) head origin
        ref = (np.broadcast_to(pole, eye.shape) - eye) if pole is not None else None
        keep = np.ones(k, bool)
        dirs = []
        for _name, frame, x in arm_markers:
            cols = arm_joints(frame)
            qq = np.repeat(q, candidates, axis=0)
            qq[:, cols] = uniform_configurations(robot, rng, k * candidates)[:, cols]
            Fa = fk(robot, qq, device="cpu", dtype="float64")
            xw = (np.einsum("sij,j->si", Fa[:, frame, :3, :3], x)
                  + Fa[:, frame, :3, 3]).reshape(k, candidates, 3)
            d = xw - eye[:, None]
            dist = np.linalg.norm(d, axis=-1)
            ok = (dist > distance[0]) & (dist < distance[1])
            if ref is not None:
                cosang = (np.einsum("skc,sc->sk", d, ref)
                          / (dist * np.linalg.norm(ref, axis=-1)[:, None]))
                ok &= cosang > cos_cone
            else:   # no fixed marker: in front of the head (base x) and below it
                ok &= (d[..., 0] > 0.2) & (d[..., 2] < 0.1)
            has = ok.any(axis=1)
            first = np.argmax(ok, axis=1)
            sel = qq.reshape(k, candidates, -1)[np.arange(k), first]
            q[:, cols] = sel[:, cols]
            keep &= has
            dd = d[np.arange(k), first]
            dirs.append(dd / np.linalg.norm(dd, axis=-1, keepdims=True))
            if ref is None:   # no pole: the next hand near this one
                ref = dd
        if pole is not None:
            dirs.append(ref / np.linalg.norm(ref, axis=-1, keepdims=True))
        look = eye + np.mean(dirs, axis=0)
        q[:, head] = look_at_head_joints(robot, q, look)
        return q[keep], {}

    return sampler


def all_markers_visible(meas: Measurement, frames: np.ndarray, p: np.ndarray,
                        meta: dict | None = None) -> np.ndarray:
    """``accept`` of the image campaign: (S,) True where every marker is in the image
    (:meth:`ImageMeasurement.visible`)."""
    return np.all(meas.visible(frames, p), axis=1)


# ------------------------------------------------------------- justin19 relative
def justin_relative_setup(noise: float = 0.001) -> Setup:
    """Right TCP relative to the left TCP (eq. 2.46), noise [m] per coordinate."""
    return Setup(plugin="relative",
                 section={"end_effectors": ["left_tcp", "right_tcp"], "free_offsets": False,
                          "noise": float(noise)},
                 robot="justin19",
                 description="Agile Justin: right TCP relative to the left TCP (eq. 2.46)")


# ------------------------------------------------------------------- hand4 contact
HAND_FINGERS = ("thumb", "index", "middle", "ring")


def hand_contact_setup(noise: float = 0.0005,
                       pairs: tuple[tuple[str, str], ...] = (("thumb", "index"),
                                                             ("thumb", "middle"),
                                                             ("thumb", "ring"))) -> Setup:
    """Pairwise fingertip contacts of hand4 (thesis 2.6.1, DLR-Hand II contact paper): the
    capsules of the distal links, thumb against each finger by default.

    Args:
        noise: distance noise sigma [m].
        pairs: finger pairs (names of :data:`HAND_FINGERS`).
    """
    for a, b in pairs:
        for f in (a, b):
            if f not in HAND_FINGERS:
                raise ValueError(f"pairs: unknown finger '{f}'; fingers: {', '.join(HAND_FINGERS)}")
    used = [f for f in HAND_FINGERS if any(f in pr for pr in pairs)]
    section = {"bodies": [{"name": f, "robot_capsule": f"{f}_distal", "sigma_radius": 0.001}
                          for f in used],
               "pairs": [list(pr) for pr in pairs], "noise": float(noise)}
    return Setup(plugin="contact", section=section, robot="hand4",
                 description="hand4 fingertip contacts (thesis 2.6.1)")


def contact_distance(robot: RobotModel, meas: Measurement, q: np.ndarray, pair: np.ndarray,
                     p: np.ndarray | None = None) -> np.ndarray:
    """Signed distances (S,) [m] of the pairs ``pair`` (S,) at configurations q (S, n_dof)
    on ``robot`` (rigid FK, float64)."""
    from jwarp.kinematics.fk import fk

    F = fk(robot, q, device="cpu", dtype="float64")
    pp = meas.params.nominal if p is None else p
    return np.asarray(meas.predict(F, pp, {"pair": np.asarray(pair)}), np.float64)[:, 0]


def contact_sampler(robot: RobotModel, setup: Setup, *, pool: int = 4096,
                    iterations: int = 40, max_pools: int = 200) -> Sampler:
    """Sampler of configurations in contact on the nominal ``robot``.

    Each call cycles through the setup's pairs (equal counts, random order). For a pair,
    a penetrating configuration ``q_in`` (distance < 0) is taken from a pool of uniform
    configurations and a separated one ``q_out`` (distance > 0) is drawn uniformly; the
    contact configuration is the root of the distance on the segment q_in -> q_out (joint
    limits are a box, so the segment stays inside them), found by ``iterations`` steps of
    vectorized bisection (|t| error 2^-iterations). Returns meta ``{"pair": (k,) int}``.
    """
    meas = make_measurement(robot, setup)
    n_pairs = len(meas.pairs)

    def penetrating(rng: np.random.Generator, k: int, need: int) -> np.ndarray:
        got: list[np.ndarray] = []
        have = 0
        for _ in range(max_pools):
            q = uniform_configurations(robot, rng, pool)
            d = contact_distance(robot, meas, q, np.full(pool, k))
            got.append(q[d < 0])
            have += int((d < 0).sum())
            if have >= need:
                break
        if have == 0:
            raise ValueError(f"setup.pairs[{k}]: no penetrating configuration of "
                             f"{meas.pairs[k]} in {max_pools * pool} uniform draws; the pair "
                             f"cannot touch")
        q = np.concatenate(got)
        return q[rng.integers(0, len(q), need)]

    def sampler(rng: np.random.Generator, k: int) -> tuple[np.ndarray, dict]:
        pair = rng.permutation(np.arange(k) % n_pairs)
        q_in = np.empty((k, robot.n_dof))
        for j in range(n_pairs):
            m = pair == j
            if m.any():
                q_in[m] = penetrating(rng, j, int(m.sum()))
        q_out = uniform_configurations(robot, rng, k)
        d_out = contact_distance(robot, meas, q_out, pair)
        ok = d_out > 0
        lo, hi = np.zeros(k), np.ones(k)            # d(lo) < 0 (q_in), d(hi) > 0 (q_out)
        for _ in range(iterations):
            t = 0.5 * (lo + hi)
            d = contact_distance(robot, meas, q_in + t[:, None] * (q_out - q_in), pair)
            neg = d < 0
            lo = np.where(neg, t, lo)
            hi = np.where(neg, hi, t)
        t = 0.5 * (lo + hi)
        q = q_in + t[:, None] * (q_out - q_in)
        return q[ok], {"pair": pair[ok].astype(np.int64)}

    return sampler


# ----------------------------------------------------------------------- registry
def _justin_cartesian(robot: RobotModel) -> tuple[Setup, Sampler | None, Accept | None]:
    return justin_tracker_setup(), None, None


def _justin_image(robot: RobotModel) -> tuple[Setup, Sampler | None, Accept | None]:
    setup = justin_camera_setup()
    return setup, justin_camera_sampler(robot, setup), all_markers_visible


def _justin_relative(robot: RobotModel) -> tuple[Setup, Sampler | None, Accept | None]:
    return justin_relative_setup(), None, None


def _hand_contact(robot: RobotModel) -> tuple[Setup, Sampler | None, Accept | None]:
    setup = hand_contact_setup()
    return setup, contact_sampler(robot, setup), None


SCENARIOS: dict[tuple[str, str], Callable[[RobotModel], tuple[Setup, Sampler | None,
                                                               Accept | None]]] = {
    ("justin19", "cartesian"): _justin_cartesian,
    ("justin19", "image"): _justin_image,
    ("justin19", "relative"): _justin_relative,
    ("hand4", "contact"): _hand_contact,
}


def available() -> list[tuple[str, str]]:
    """The built-in (robot, plugin) combinations."""
    return list(SCENARIOS)


def scenario(robot_name: str, plugin: str) -> tuple[Setup, Sampler | None, Accept | None]:
    """The built-in campaign of ``plugin`` on robot ``robot_name``.

    Returns:
        (setup, sampler, accept): the exact measurement setup (the truth's measurement
        parameters), a sampler ``(rng, k) -> (q (<=k, n_dof), meta)`` of candidate
        configurations on the nominal robot or None (uniform in the limits), and an
        ``accept(meas, frames, p, meta) -> (S,) bool`` filter on the true robot or None;
        pass them to :func:`~jwarp.calibration.simulate.campaign.simulate_campaign`.

    Raises:
        ValueError: an unknown combination (the message lists the available ones).
    """
    key = (str(robot_name), str(plugin))
    if key not in SCENARIOS:
        known = ", ".join(f"{r}/{p}" for r, p in SCENARIOS)
        raise ValueError(f"robot, plugin: no built-in campaign for robot '{robot_name}' with "
                         f"plugin '{plugin}'; available: {known} (or give a setup file)")
    return SCENARIOS[key](get_robot(key[0]))
