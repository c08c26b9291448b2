#!/usr/bin/env python
"""Planning-problem sets in the MotionBenchMaker style (the Panda, or another arm of
:data:`ARMS`): MoveIt planning-scene YAML files, one per problem, each with randomised
object poses, a collision-free start and a collision-free goal found by jwarp's
collision-aware IK, and an index.

    python benchmarks/scene_problems.py --out DIR --per-family N --seed S
        [--families table_pick,box,...] [--margin 0.0] [--robot panda.json]
    python benchmarks/scene_problems.py --arm ur5 --robot ur5.json --out DIR ...

Other arms (``--arm ur5``, ``kinova``, ``xarm7``; :class:`ArmSpec`): the same families and
targets; ``--robot`` is the arm's model as ``jwarp import-urdf URDF --srdf SRDF [--home
STATE]`` writes it (the default import); an arm without a gripper (UR5 ``tool0``, xArm7
``link_eef``, both flanges) holds its frame 10 cm behind the pre-grasp point along the
approach, as if a 10 cm gripper were mounted; the Kinova's ``j2s6s200_end_effector``
(its gripper's, x the approach) is at it. Everything said of the fingers below is the
Panda's.

Families (robot base at the world origin, x forward; every structure is placed at a
random distance and bearing in front of the robot, turned to face it):

* ``table_pick``: a table (top 0.20-0.45 m high) with 3-5 cans; goal: the hand above a can,
  pointing down (pre-grasp, 2-6 cm above its top);
* ``table_under_pick``: a higher table (top 0.40-0.55 m) with cans on a low board beneath
  it; goal: a horizontal pre-grasp of a can under the table top;
* ``bookshelf_small``: a shelf of 3 compartments; goal: a horizontal pre-grasp of a can
  in one of them;
* ``bookshelf_tall``: a shelf of 5 compartments (1.5-1.8 m tall), cans on every board;
* ``bookshelf_thin``: a shelf of narrow compartments (vertical dividers 18-25 cm apart);
* ``box``: an open box on a pedestal with small objects inside; goal: the hand inside the
  box above an object, pointing down;
* ``cage``: a cage of posts, bars and a roof on a pedestal, open at the front; goal: a
  horizontal pre-grasp of a can inside through the front.

Starts: the hand pointing down at a random point in front of the robot (0.30-0.45 m
forward, 0.45-0.65 m high). Targets are for the frame ``panda_hand_tcp``; the fingers are
set to 3.5 cm open in both states. IK: :class:`jwarp.solvers.ik.IKSolver` on the CPU, all
goal and start candidates of one problem in one batch (8 seeds each: the ready pose, then
uniform ones), on the scene's 2 cm SDF with the
fitted sphere model (``SpherizeOptions()``, the default of ``jwarp import-urdf``: spheres that
contain the meshes, issue 42; before: ``tolerance=0.02``, a one-sided error of up to
2 cm; cached). A candidate is accepted
only if, with the fingers set, jwarp finds it collision-free (world and self, sphere model,
``--margin``) **and** the independent checker ``tests/verifier.py`` (pinocchio + coal)
finds the URDF collision meshes clear of the exact scene geometry by ``--margin`` and the
robot spheres by ``max(--clearance, --margin)`` (default 0). jwarp's own check runs on the
exact objects (``exact_world``; a ``Generator(voxel=...)`` grid world lowers the SDF by its
declared error, about 0.87 voxel, and may then refuse a start or goal). A scene whose start or goal cannot be found is redrawn.

Files: ``DIR/<family>_<k>.yaml`` (MoveIt planning scene: ``robot_state.joint_state`` with
the 7 arm joints and both finger joints, ``world.collision_objects`` of boxes and
cylinders in frame ``world`` = the robot base, ``goal_constraints[0].joint_constraints``
of the 7 arm joints) and ``DIR/index.json`` (per problem: file, family, seed, target
object, the TCP goal pose, the checker's clearances, and the generation settings). Load
one with ``jwarp.world.load_scene`` (``--start moveit --goal moveit`` on the CLI).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from typing import TYPE_CHECKING  # noqa: E402

if TYPE_CHECKING:  # the checker needs pinocchio and coal: imported where a problem set is made
    from verifier import PathVerifier

ARM = [f"panda_joint{i}" for i in range(1, 8)]
FINGER = 0.035
READY = np.array([0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785, FINGER])
TCP = "panda_hand_tcp"
URDF = "panda_description/urdf/panda.urdf"


@dataclass(frozen=True)
class ArmSpec:
    """What the generator needs to know of an arm (``--arm``).

    Attributes:
        name: the arm's name in the index and the YAML files (``robot_model_name``).
        urdf: its URDF under example-robot-data's ``robots`` folder.
        srdf: its SRDF there ("" none): passed to the fit as ``jwarp import-urdf --srdf``
            would (its disabled pairs, its home state).
        home: the SRDF group_state the import takes as home ("" the import's default).
        tcp: the frame the targets are for.
        joints: the arm joints (the goal constraints; the joints OMPL plans in).
        approach: the TCP frame's axis that points from the wrist to the object
            (``tcp_pose`` builds targets with z along the approach).
        standoff: metres the TCP frame stays behind the pre-grasp point along the approach
            (an arm without a gripper: the frame is its flange, the object no gripper's
            length away from it).
        ready: the seed of every IK (natural solutions near it; the fixed joints' values
            included, e.g. the fingers), by joint name; joints it does not name take the
            middle of their limits.
        fixed: joints held at a value in start and goal (the Panda's fingers), and
            ``mimic``: joints the YAML state sets equal to another (its second finger).
    """

    name: str
    urdf: str
    tcp: str
    joints: tuple[str, ...]
    ready: dict
    srdf: str = ""
    home: str = ""
    approach: str = "z"
    standoff: float = 0.0
    fixed: dict = field(default_factory=dict)
    mimic: dict = field(default_factory=dict)

    def frame_offset(self) -> np.ndarray:
        """4x4: the TCP frame in the convention of :func:`tcp_pose` (z the approach, at the
        pre-grasp point) -> the arm's own ``tcp`` frame (``approach`` axis, ``standoff``)."""
        T = np.eye(4)
        T[2, 3] = -self.standoff
        if self.approach == "x":    # the frame's x is tcp_pose's z, its z tcp_pose's -x
            T[:3, :3] = np.array([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])
        elif self.approach != "z":
            raise ValueError(f"approach: expected 'x' or 'z', got {self.approach!r}")
        return T


ARMS: dict[str, ArmSpec] = {
    "panda": ArmSpec("panda", URDF, TCP, tuple(ARM),
                     dict(zip(ARM + ["panda_finger_joint1"], READY.tolist())),
                     fixed={"panda_finger_joint1": FINGER},
                     mimic={"panda_finger_joint2": "panda_finger_joint1"}),
    # UR5 (no gripper): the flange tool0 10 cm behind the pre-grasp point
    "ur5": ArmSpec("ur5", "ur_description/urdf/ur5_robot.urdf", "tool0",
                   ("shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint",
                    "wrist_1_joint", "wrist_2_joint", "wrist_3_joint"),
                   {"shoulder_pan_joint": 0.0, "shoulder_lift_joint": -1.571,
                    "elbow_joint": 1.571, "wrist_1_joint": -1.571, "wrist_2_joint": -1.571,
                    "wrist_3_joint": 0.0},
                   srdf="ur_description/srdf/ur5.srdf", standoff=0.10),
    # Kinova Jaco2 j2s6s200 (its gripper's end-effector frame: x is the approach)
    "kinova": ArmSpec("kinova", "kinova_description/robots/kinova.urdf",
                      "j2s6s200_end_effector",
                      tuple(f"j2s6s200_joint_{i}" for i in range(1, 7)),
                      {"j2s6s200_joint_1": -1.55, "j2s6s200_joint_2": 3.39,
                       "j2s6s200_joint_3": 2.12, "j2s6s200_joint_4": -3.14,
                       "j2s6s200_joint_5": 1.27, "j2s6s200_joint_6": 0.69},
                      srdf="kinova_description/srdf/kinova.srdf", home="arm_up",
                      approach="x"),
    # xArm7 (no gripper): the flange link_eef 10 cm behind the pre-grasp point
    "xarm7": ArmSpec("xarm7", "xarm_description/urdf/xarm7.urdf", "link_eef",
                     tuple(f"joint{i}" for i in range(1, 8)),
                     {"joint1": 0.0, "joint2": 0.0, "joint3": 0.0, "joint4": 1.0,
                      "joint5": 0.0, "joint6": 1.0, "joint7": 0.0},
                     srdf="xarm_description/srdf/xarm7.srdf", home="home", standoff=0.10),
}


# ------------------------------------------------------------------ geometry helpers
def rot_z(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def quat(R: np.ndarray) -> list[float]:
    """(x, y, z, w) of a rotation matrix."""
    m = R
    t = np.trace(m)
    if t > 0:
        s = 2.0 * math.sqrt(1.0 + t)
        q = [(m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s, 0.25 * s]
    else:
        i = int(np.argmax(np.diag(m)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * math.sqrt(1.0 + m[i, i] - m[j, j] - m[k, k])
        v = [0.0, 0.0, 0.0]
        v[i] = 0.25 * s
        v[j] = (m[j, i] + m[i, j]) / s
        v[k] = (m[k, i] + m[i, k]) / s
        q = v + [(m[k, j] - m[j, k]) / s]
    q = np.array(q) / np.linalg.norm(q)
    return [float(x) for x in q]


class Site:
    """A structure's frame: on the floor at distance ``dist`` and bearing ``bearing`` from
    the robot, x pointing away from it (plus a yaw jitter), z up."""

    def __init__(self, dist: float, bearing: float, yaw_jitter: float = 0.0, z: float = 0.0):
        self.R = rot_z(bearing + yaw_jitter)
        self.t = np.array([dist * math.cos(bearing), dist * math.sin(bearing), z])

    def point(self, p: Any) -> np.ndarray:
        return self.R @ np.asarray(p, float) + self.t

    def frame(self, p: Any, R_local: np.ndarray | None = None) -> np.ndarray:
        T = np.eye(4)
        T[:3, :3] = self.R @ (np.eye(3) if R_local is None else R_local)
        T[:3, 3] = self.point(p)
        return T


class SceneBuilder:
    """Collision objects (boxes, cylinders) in world coordinates, as MoveIt YAML data."""

    def __init__(self) -> None:
        self.objects: list[dict] = []

    def add(self, oid: str, prims: list[tuple[str, list, np.ndarray]]) -> str:
        self.objects.append({
            "id": oid, "header": {"frame_id": "world"}, "operation": "add",
            "primitives": [{"type": t, "dimensions": [round(float(v), 6) for v in d]}
                           for t, d, _ in prims],
            "primitive_poses": [{"position": [round(float(v), 6) for v in T[:3, 3]],
                                 "orientation": [round(v, 9) for v in quat(T[:3, :3])]}
                                for _, _, T in prims]})
        return oid

    def box(self, site: Site, size: Any, centre: Any) -> tuple:
        return ("box", list(size), site.frame(centre))

    def cyl(self, site: Site, length: float, radius: float, centre: Any,
            R_local: np.ndarray | None = None) -> tuple:
        return ("cylinder", [length, radius], site.frame(centre, R_local))


def tcp_pose(site: Site, p_local: Any, approach_local: Any, up_local: Any) -> np.ndarray:
    """TCP pose: z along ``approach_local``, the fingers' axis y along ``up_local`` x z
    (so ``up_local`` is the hand's x axis), both in the site frame."""
    z = np.asarray(approach_local, float)
    z = z / np.linalg.norm(z)
    x = np.asarray(up_local, float)
    x = x - (x @ z) * z
    x = x / np.linalg.norm(x)
    y = np.cross(z, x)
    return site.frame(p_local, np.stack([x, y, z], axis=1))


def side_grasp(site: Site, rng: np.random.Generator, centre: np.ndarray, radius: float) -> np.ndarray:
    """Horizontal pre-grasp of an upright can at ``centre`` (site frame), approaching along
    site +x from 3-6 cm in front of its surface, fingers closing horizontally."""
    off = rng.uniform(0.03, 0.06)
    p = centre - np.array([radius + off, 0.0, 0.0])
    up = np.array([0.0, 0.0, 1.0 if rng.random() < 0.5 else -1.0])
    tilt = rng.uniform(-0.15, 0.15)
    a = np.array([math.cos(tilt), math.sin(tilt), 0.0])
    return tcp_pose(site, p, a, up)


def top_grasp(site: Site, rng: np.random.Generator, top: np.ndarray, lo: float = 0.02,
              hi: float = 0.06) -> np.ndarray:
    """Pre-grasp from above: the TCP ``lo..hi`` above ``top`` (site frame), pointing down,
    random yaw."""
    yaw = rng.uniform(-math.pi, math.pi)
    p = top + np.array([0.0, 0.0, rng.uniform(lo, hi)])
    return tcp_pose(site, p, [0.0, 0.0, -1.0], [math.cos(yaw), math.sin(yaw), 0.0])


def cans(rng: np.random.Generator, n: int, x: tuple, y: tuple, gap: float = 0.12,
         r: tuple = (0.02, 0.03), h: tuple = (0.08, 0.18)) -> list[tuple]:
    """Up to n non-overlapping upright cans ``(x, y, radius, height)`` in the rectangle."""
    out: list[tuple] = []
    for _ in range(50 * n):
        if len(out) == n:
            break
        c = (rng.uniform(*x), rng.uniform(*y))
        if all(math.hypot(c[0] - o[0], c[1] - o[1]) > gap for o in out):
            out.append((c[0], c[1], rng.uniform(*r), rng.uniform(*h)))
    return out


Family = Callable[[np.random.Generator], tuple[list, list, list]]


# ------------------------------------------------------------------ families
def _table(sb: SceneBuilder, site: Site, depth: float, width: float, top: float,
           th: float = 0.04, legs: bool = True) -> None:
    prims = [sb.box(site, [depth, width, th], [0.5 * depth, 0.0, top - 0.5 * th])]
    if legs:
        for sx in (0.04, depth - 0.04):
            for sy in (-0.5 * width + 0.04, 0.5 * width - 0.04):
                prims.append(sb.box(site, [0.04, 0.04, top - th], [sx, sy, 0.5 * (top - th)]))
    sb.add("table", prims)


def table_pick(rng: np.random.Generator) -> tuple[list, list, list]:
    sb = SceneBuilder()
    site = Site(rng.uniform(0.30, 0.45), rng.uniform(-0.5, 0.5), rng.uniform(-0.2, 0.2))
    depth, width, top = rng.uniform(0.6, 0.8), rng.uniform(0.9, 1.3), rng.uniform(0.20, 0.45)
    _table(sb, site, depth, width, top)
    goals = []
    for k, (x, y, r, h) in enumerate(cans(rng, int(rng.integers(3, 6)), (0.1, 0.45),
                                          (-0.35, 0.35))):
        oid = sb.add(f"can{k}", [sb.cyl(site, h, r, [x, y, top + 0.5 * h])])
        goals += [(oid, top_grasp(site, rng, np.array([x, y, top + h]))) for _ in range(2)]
    return sb.objects, goals, []


def table_under_pick(rng: np.random.Generator) -> tuple[list, list, list]:
    sb = SceneBuilder()
    site = Site(rng.uniform(0.30, 0.40), rng.uniform(-0.5, 0.5), rng.uniform(-0.2, 0.2))
    depth, width, top = rng.uniform(0.6, 0.8), rng.uniform(0.9, 1.3), rng.uniform(0.40, 0.55)
    _table(sb, site, depth, width, top)
    board = rng.uniform(0.05, 0.12)    # a low board between the legs
    sb.add("low_board", [sb.box(site, [depth - 0.1, width - 0.1, 0.02], [0.5 * depth, 0.0, board - 0.01])])
    goals = []
    for k, (x, y, r, h) in enumerate(cans(rng, int(rng.integers(2, 4)), (0.15, 0.35),
                                          (-0.3, 0.3), h=(0.08, 0.14))):
        oid = sb.add(f"can{k}", [sb.cyl(site, h, r, [x, y, board + 0.5 * h])])
        c = np.array([x, y, board + rng.uniform(0.5, 0.8) * h])
        goals += [(oid, side_grasp(site, rng, c, r)) for _ in range(3)]
    return sb.objects, goals, []


def _shelf(sb: SceneBuilder, site: Site, depth: float, width: float, boards: list[float],
           height: float, dividers: list[float] = (), t: float = 0.02) -> None:
    prims = [sb.box(site, [depth, width, t], [0.5 * depth, 0.0, z - 0.5 * t]) for z in boards]
    for y in (-0.5 * width - 0.5 * t, 0.5 * width + 0.5 * t):
        prims.append(sb.box(site, [depth, t, height], [0.5 * depth, y, 0.5 * height]))
    prims.append(sb.box(site, [t, width + 2 * t, height], [depth + 0.5 * t, 0.0, 0.5 * height]))
    for y in dividers:
        prims.append(sb.box(site, [depth, t, height - boards[0]], [0.5 * depth, y, 0.5 * (height + boards[0])]))
    sb.add("shelf", prims)


def _bookshelf(rng: np.random.Generator, n_levels: int, spacing: tuple, thin: bool,
               dist: tuple = (0.55, 0.75)) -> tuple[list, list, list]:
    sb = SceneBuilder()
    site = Site(rng.uniform(*dist), rng.uniform(-0.6, 0.6), rng.uniform(-0.15, 0.15))
    depth, width = rng.uniform(0.30, 0.40), rng.uniform(0.6, 0.9)
    z0 = rng.uniform(0.0, 0.25)
    boards = [z0]
    for _ in range(n_levels):
        boards.append(boards[-1] + rng.uniform(*spacing))
    height = boards[-1] + 0.01
    cells = [(-0.5 * width, 0.5 * width)]
    dividers: list[float] = []
    if thin:
        y, cells = -0.5 * width, []
        while True:
            w = rng.uniform(0.18, 0.25)
            if y + w > 0.5 * width - 0.12:
                cells.append((y, 0.5 * width))
                break
            cells.append((y, y + w))
            dividers.append(y + w + 0.01)
            y += w + 0.02
    _shelf(sb, site, depth, width, boards, height, dividers)
    goals, k = [], 0
    for lvl in range(n_levels):
        zb, zt = boards[lvl], boards[lvl + 1] - 0.02
        for y0, y1 in cells:
            gap = 0.12
            n = 1 if thin else int(rng.integers(1, 3))
            hmax = min(0.18, zt - zb - 0.06)
            for x, y, r, h in cans(rng, n, (0.08, depth - 0.08), (y0 + 0.05, y1 - 0.05),
                                   gap=gap, h=(0.07, max(0.08, hmax))):
                oid = sb.add(f"can{k}", [sb.cyl(site, h, r, [x, y, zb + 0.5 * h])])
                k += 1
                c = np.array([x, y, zb + rng.uniform(0.5, 0.8) * h])
                goals += [(oid, side_grasp(site, rng, c, r)) for _ in range(2)]
    return sb.objects, goals, []


def bookshelf_small(rng: np.random.Generator) -> tuple[list, list, list]:
    return _bookshelf(rng, 3, (0.28, 0.36), thin=False)


def bookshelf_tall(rng: np.random.Generator) -> tuple[list, list, list]:
    return _bookshelf(rng, 5, (0.30, 0.36), thin=False)


def bookshelf_thin(rng: np.random.Generator) -> tuple[list, list, list]:
    return _bookshelf(rng, 3, (0.28, 0.34), thin=True)


def box(rng: np.random.Generator) -> tuple[list, list, list]:
    sb = SceneBuilder()
    site = Site(rng.uniform(0.38, 0.52), rng.uniform(-0.6, 0.6), rng.uniform(-0.4, 0.4))
    base = rng.uniform(0.05, 0.25)
    sx, sy, wall, t = rng.uniform(0.30, 0.40), rng.uniform(0.30, 0.45), rng.uniform(0.12, 0.22), 0.015
    sb.add("pedestal", [sb.box(site, [sx + 2 * t, sy + 2 * t, base - t], [0.5 * sx, 0.0, 0.5 * (base - t)])])
    walls = [sb.box(site, [sx + 2 * t, sy + 2 * t, t], [0.5 * sx, 0.0, base - 0.5 * t])]
    for x in (-0.5 * t, sx + 0.5 * t):
        walls.append(sb.box(site, [t, sy + 2 * t, wall], [x, 0.0, base + 0.5 * wall]))
    for y in (-0.5 * sy - 0.5 * t, 0.5 * sy + 0.5 * t):
        walls.append(sb.box(site, [sx, t, wall], [0.5 * sx, y, base + 0.5 * wall]))
    sb.add("box", walls)
    goals = []
    for k, (x, y, r, h) in enumerate(cans(rng, int(rng.integers(1, 4)), (0.09, sx - 0.09),
                                          (-0.5 * sy + 0.09, 0.5 * sy - 0.09), gap=0.13,
                                          r=(0.02, 0.03), h=(0.05, 0.10))):
        oid = sb.add(f"item{k}", [sb.cyl(site, h, r, [x, y, base + 0.5 * h])])
        goals += [(oid, top_grasp(site, rng, np.array([x, y, base + h]), 0.01, 0.04))
                  for _ in range(3)]
    return sb.objects, goals, []


def cage(rng: np.random.Generator) -> tuple[list, list, list]:
    sb = SceneBuilder()
    site = Site(rng.uniform(0.45, 0.60), rng.uniform(-0.5, 0.5), rng.uniform(-0.2, 0.2))
    base = rng.uniform(0.10, 0.30)
    d, w, h = rng.uniform(0.35, 0.45), rng.uniform(0.40, 0.50), rng.uniform(0.35, 0.45)
    sb.add("pedestal", [sb.box(site, [d, w, base], [0.5 * d, 0.0, 0.5 * base])])
    r = 0.012
    prims = [sb.cyl(site, h, r, [x, y, base + 0.5 * h]) for x in (0.0, d) for y in (-0.5 * w, 0.5 * w)]
    prims.append(sb.box(site, [d + 0.04, w + 0.04, 0.02], [0.5 * d, 0.0, base + h + 0.01]))
    Rx = np.array([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]])     # cylinder axis along y
    Ry = np.array([[0, 0, 1.0], [0, 1.0, 0], [-1.0, 0, 0]])     # along x
    for zf in rng.uniform(0.3, 0.7, 2):
        prims.append(sb.cyl(site, w, r, [d, 0.0, base + zf * h], Rx))            # back
        for y in (-0.5 * w, 0.5 * w):
            prims.append(sb.cyl(site, d, r, [0.5 * d, y, base + zf * h], Ry))  # sides
    if rng.random() < 0.5:   # a low bar across the front
        prims.append(sb.cyl(site, w, r, [0.0, 0.0, base + rng.uniform(0.05, 0.12)], Rx))
    sb.add("cage", prims)
    goals = []
    for k, (x, y, rc, hc) in enumerate(cans(rng, int(rng.integers(1, 3)), (0.15, d - 0.08),
                                            (-0.5 * w + 0.1, 0.5 * w - 0.1), gap=0.13,
                                            h=(0.08, 0.15))):
        oid = sb.add(f"can{k}", [sb.cyl(site, hc, rc, [x, y, base + 0.5 * hc])])
        c = np.array([x, y, base + rng.uniform(0.5, 0.8) * hc])
        goals += [(oid, side_grasp(site, rng, c, rc)) for _ in range(3)]
    return sb.objects, goals, []


FAMILIES: dict[str, Family] = {
    "table_pick": table_pick, "table_under_pick": table_under_pick,
    "bookshelf_small": bookshelf_small, "bookshelf_tall": bookshelf_tall,
    "bookshelf_thin": bookshelf_thin, "box": box, "cage": cage,
}


def start_targets(rng: np.random.Generator, n: int) -> list[np.ndarray]:
    """The hand pointing down at random points in front of the robot."""
    site = Site(0.0, 0.0)
    out = []
    for _ in range(n):
        p = np.array([rng.uniform(0.30, 0.45), rng.uniform(-0.2, 0.2), rng.uniform(0.45, 0.65)])
        out.append(top_grasp(site, rng, p, 0.0, 0.0))
    return out


# ------------------------------------------------------------------ the generator
class Generator:
    """Makes problems for one robot model (spheres + self pairs) and URDF."""

    def __init__(self, robot: Any, urdf: str, margin: float = 0.0, n_seeds: int = 8,
                 voxel: float | None = None, clearance: float = 0.0, arm: str = "panda"):
        self.robot, self.urdf, self.margin = robot, urdf, margin
        self.clearance = max(clearance, margin)
        self.n_seeds, self.voxel = n_seeds, voxel
        from verifier import robot_spheres

        self.spec = arm_spec(arm)
        self.spheres = robot_spheres(robot)
        self.names = robot.joint_names
        missing = [n for n in (*self.spec.joints, *self.spec.fixed, *self.spec.ready)
                   if n not in self.names]
        if missing:
            raise ValueError(f"arm: {arm!r} names joints the robot lacks: {missing}")
        lim = np.asarray(robot.joint_limits, float)
        self.ready = np.array([self.spec.ready.get(n, 0.5 * (lo + hi))
                               for n, (lo, hi) in zip(self.names, lim)])
        self.arm = np.array([self.names.index(n) for n in self.spec.joints])
        self.fixed = [(self.names.index(n), v) for n, v in self.spec.fixed.items()]
        off = self.spec.frame_offset()
        self.offset = None if np.array_equal(off, np.eye(4)) else off
        self.stats = {"scenes": 0, "ik_feasible": 0, "jwarp_rejected": 0, "verifier_rejected": 0,
                      "ik_s": 0.0, "sdf_s": 0.0, "verify_s": 0.0}

    def _pick(self, q: np.ndarray, ok: np.ndarray, world: Any, verifier: PathVerifier
              ) -> tuple[np.ndarray, Any, int] | None:
        from jwarp.world.path_feasibility import collision_free

        cand = np.nonzero(ok)[0]
        # the candidate nearest the ready pose first (natural problems)
        near = np.abs(q[cand][:, self.arm] - self.ready[self.arm]).sum(1)
        for i in cand[np.argsort(near)]:
            c = q[i].copy()
            for j, v in self.fixed:
                c[j] = v
            if not collision_free(self.robot, world, c[None], self.margin, device="cpu")[0]:
                self.stats["jwarp_rejected"] += 1
                continue
            t = time.perf_counter()
            v = verifier.check_path(c[None], margin=self.margin)
            self.stats["verify_s"] += time.perf_counter() - t
            if not v.ok or (v.sphere is not None and v.sphere.distance < self.clearance):
                self.stats["verifier_rejected"] += 1
                continue
            return c, v, int(i)
        return None

    def problem(self, family: str, seed: int, max_tries: int = 20) -> dict | None:
        """One problem of ``family`` (a dict: scene data, start, goal, meta) or None."""
        from jwarp.solvers.ik import IKOptions, IKSolver
        from jwarp.world.scene_file import SceneOptions, exact_world, scene_from_dict, scene_world

        rng = np.random.default_rng(seed)
        for attempt in range(max_tries):
            objects, goals, _ = FAMILIES[family](rng)
            if not goals:
                continue
            order = rng.permutation(len(goals))[:16]
            goals = [goals[i] for i in order]
            starts = start_targets(rng, 8)
            data = {"world": {"collision_objects": objects}}
            scene = scene_from_dict(data, source=f"{family}/{seed}")
            self.stats["scenes"] += 1
            t = time.perf_counter()
            world = exact_world(scene) if self.voxel is None else \
                scene_world(scene, SceneOptions(voxel_size=self.voxel, pad=0.3))
            self.stats["sdf_s"] += time.perf_counter() - t
            targets = np.stack([g for _, g in goals] + starts)
            if self.offset is not None:     # the arm's own frame behind the pre-grasp point
                targets = targets @ self.offset
            # seeds: the ready pose first (natural solutions near it), then uniform ones
            lim = self.robot.joint_limits
            seeds = rng.uniform(lim[:, 0], lim[:, 1], (len(targets), self.n_seeds, len(lim)))
            seeds[:, 0] = self.ready
            t = time.perf_counter()
            ik = IKSolver(self.robot, self.spec.tcp, len(targets),
                          IKOptions(n_starts=self.n_seeds, seed=int(rng.integers(2**31)),
                                    margin=self.margin, q_default=self.ready),
                          world=world, device="cpu", dtype=np.float64).solve(targets, seeds)
            self.stats["ik_s"] += time.perf_counter() - t
            self.stats["ik_feasible"] += int(ik.feasible.sum())
            from verifier import PathVerifier

            verifier = PathVerifier(self.urdf, None, scene.shapes, spheres=self.spheres,
                                    joint_names=self.names)
            G = len(goals)
            goal = self._pick(ik.q[:G], ik.feasible[:G], world, verifier)
            if goal is None:
                continue
            start = self._pick(ik.q[G:], ik.feasible[G:], world, verifier)
            if start is None:
                continue
            gi = goal[2]
            return {"objects": objects, "start": start[0], "goal": goal[0],
                    "target_object": goals[gi][0], "goal_tcp": targets[gi],
                    "clearance": {"start_mesh": start[1].mesh.distance,
                                  "start_spheres": start[1].sphere.distance,
                                  "goal_mesh": goal[1].mesh.distance,
                                  "goal_spheres": goal[1].sphere.distance},
                    "attempts": attempt + 1}
        return None


def arm_spec(arm: str) -> ArmSpec:
    """The :class:`ArmSpec` of ``arm`` (ValueError naming the known ones)."""
    if arm not in ARMS:
        raise ValueError(f"arm: unknown {arm!r}; known: {', '.join(ARMS)}")
    return ARMS[arm]


def scene_yaml(name: str, p: dict, names: list[str], arm: str = "panda") -> dict:
    spec = arm_spec(arm)
    start = {n: float(v) for n, v in zip(names, p["start"])}
    for n, src in spec.mimic.items():
        start[n] = start[src]
    return {
        "name": name, "robot_model_name": spec.name,
        "robot_state": {"joint_state": {"name": list(start), "position": list(start.values())}},
        "world": {"collision_objects": p["objects"]}, "is_diff": True,
        "goal_constraints": [{"joint_constraints": [
            {"joint_name": n, "position": float(v), "tolerance_above": 1e-4,
             "tolerance_below": 1e-4, "weight": 1.0}
            for n, v in zip(names, p["goal"]) if n in spec.joints]}],
    }


def load_robot(path: str | None = None, arm: str = "panda") -> tuple[Any, str | None]:
    """(the arm's sphere model: ``path`` or the Panda fitted from its URDF; the URDF path,
    None where ``path`` is given and example-robot-data is not installed). Arms other than
    the Panda need ``path``: the model ``jwarp import-urdf URDF --srdf SRDF`` writes."""
    import jwarp
    from jwarp.importers.robot import example_robot_urdf
    from jwarp.world.spherize import SpherizeOptions, spherized_robot

    spec = arm_spec(arm)
    if path:  # the URDF only where example-robot-data is installed (a GPU machine may lack it)
        try:
            urdf = example_robot_urdf(spec.urdf)
        except (ImportError, FileNotFoundError, ValueError):
            urdf = None
        return jwarp.robot(path), urdf
    if arm != "panda":
        raise ValueError(f"robot: the {arm} needs its imported model (jwarp import-urdf "
                         f"<erd>/{spec.urdf}"
                         + (f" --srdf <erd>/{spec.srdf}" if spec.srdf else "")
                         + (f" --home {spec.home}" if spec.home else "") + " --out X.json)")
    urdf = example_robot_urdf(URDF)
    # the default fit (containment): at tolerance 0.02 a contained fit's spheres would
    # reach 4 cm past the thick links (the protrusion scales with the tolerance)
    return spherized_robot(urdf, SpherizeOptions())[0], urdf


def generate(out: str | os.PathLike, per_family: int, seed: int = 0,
             families: list[str] | None = None, margin: float = 0.0,
             robot: str | None = None, log: Callable[[str], None] = print,
             clearance: float = 0.0, arm: str = "panda") -> dict:
    """Write ``per_family`` problems of each family into ``out``; returns the index."""
    import yaml

    from jwarp.core.arrays import init_warp

    init_warp()
    fams = list(FAMILIES) if families is None else families
    unknown = [f for f in fams if f not in FAMILIES]
    if unknown:
        raise ValueError(f"families: unknown {unknown}; known: {', '.join(FAMILIES)}")
    t0 = time.perf_counter()
    spec = arm_spec(arm)
    model, urdf = load_robot(robot, arm)
    if urdf is None:
        raise ValueError(f"robot: example-robot-data is needed (the {arm}'s URDF, "
                         "for the checker)")
    gen = Generator(model, urdf, margin, clearance=clearance, arm=arm)
    folder = Path(out)
    folder.mkdir(parents=True, exist_ok=True)
    index = {"format": "jwarp.scene_problems", "version": 1, "robot": spec.name,
             "urdf": spec.urdf, "tcp": spec.tcp, "standoff": spec.standoff, "seed": seed, "per_family": per_family,
             "margin": margin, "sphere_clearance": max(clearance, margin), "spheres": len(model.spheres), "problems": [], "failed": []}
    for fi, fam in enumerate(fams):
        for k in range(per_family):
            s = seed * 1_000_003 + fi * 10_007 + k
            t = time.perf_counter()
            p = gen.problem(fam, s)
            if p is None:
                index["failed"].append({"family": fam, "seed": s})
                log(f"{fam} {k}: no start/goal found (seed {s})")
                continue
            name = f"{fam}_{k}"
            file = folder / f"{name}.yaml"
            file.write_text(yaml.safe_dump(scene_yaml(name, p, gen.names, arm),
                                           sort_keys=False))
            index["problems"].append({
                "file": file.name, "family": fam, "seed": s, "target_object": p["target_object"],
                "goal_tcp": np.round(p["goal_tcp"], 9).tolist(),
                "start": p["start"].tolist(), "goal": p["goal"].tolist(),
                "clearance_m": p["clearance"], "scene_attempts": p["attempts"]})
            log(f"{name}: {len(p['objects'])} objects, {p['attempts']} scene(s), "
                f"goal clearance mesh {p['clearance']['goal_mesh'] * 100:.1f} cm, "
                f"{time.perf_counter() - t:.1f} s")
    index["stats"] = {k: (round(v, 3) if isinstance(v, float) else v) for k, v in gen.stats.items()}
    index["stats"]["total_s"] = round(time.perf_counter() - t0, 2)
    (folder / "index.json").write_text(json.dumps(index, indent=1))
    return index


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", required=True, help="output folder")
    ap.add_argument("--per-family", type=int, default=10, help="problems per family (10)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--families", default=None, help=f"comma-separated ({','.join(FAMILIES)})")
    ap.add_argument("--margin", type=float, default=0.0,
                    help="clearance [m] of start and goal (jwarp spheres and the checker)")
    ap.add_argument("--clearance", type=float, default=0.0,
                    help="least exact clearance [m] of the robot spheres at start and goal "
                         "(0; e.g. 0.02 keeps them clear of a 2 cm grid's declared error, "
                         "for worlds coarser than the generator's; fewer problems succeed)")
    ap.add_argument("--robot", default=None, metavar="JSON",
                    help="a saved sphere model of the arm (default, Panda only: fitted "
                         "from example-robot-data's URDF)")
    ap.add_argument("--arm", default="panda", choices=list(ARMS),
                    help="the arm (panda; ur5, kinova, xarm7 need --robot)")
    a = ap.parse_args(argv)
    if a.per_family < 1:
        ap.error("--per-family: expected >= 1")
    fams = a.families.split(",") if a.families else None
    try:
        index = generate(a.out, a.per_family, a.seed, fams, a.margin, a.robot,
                         clearance=a.clearance, arm=a.arm)
    except ValueError as e:
        print(f"scene_problems: error: {e}", file=sys.stderr)
        return 2
    st = index["stats"]
    print(f"{len(index['problems'])} problems, {len(index['failed'])} failed, in "
          f"{st['total_s']} s (IK {st['ik_s']} s, SDF {st['sdf_s']} s, checker "
          f"{st['verify_s']} s; {st['scenes']} scenes drawn; rejected after IK: jwarp "
          f"{st['jwarp_rejected']}, checker {st['verifier_rejected']})")
    return 0 if not index["failed"] else 1


if __name__ == "__main__":
    sys.exit(main())
