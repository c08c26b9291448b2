"""Every ```python block of docs/*.md and examples/README.md is executed (issue 27 item 4).

The blocks are fragments: they use names the text around them defines (``robot``, ``setup``,
``q``, ``panda.urdf`` ...). Each runs in a fresh namespace, in its own temporary working
folder, with stdout captured, after its curated prelude of :data:`PRELUDES` (what the text
assumes, with the reason); :data:`SUBSTITUTIONS` lists the text replaced in a block (smaller
sizes where the block as written takes minutes, each with its reason; the old text must be
in the block, so a changed doc fails here); :data:`CHECKS` checks something real after a
block (the names it defines have the type and shape the text says, the files it writes
exist and load). A block that cannot run on a CPU CI machine is in :data:`NOT_RUN_SNIPPETS`
with the reason; :func:`test_every_snippet_is_run_or_listed` keeps the tables in step with
the docs (README.md's Python blocks run in tests/test_docs_commands.py).
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import warnings
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from test_docs_commands import MJCF_ARM, ROOT, _python_blocks

#: ``file:line`` -> code of every Python block of docs/*.md and examples/README.md
BLOCKS = {where: code for where, code in _python_blocks() if not where.startswith("README.md")}

# ------------------------------------------------------------------ shared prelude parts
_JUSTIN = "import jwarp\nrobot = jwarp.robot('justin19')\n"

#: a small simulated image campaign of justin19 (the scenario of examples/README.md): the
#: ``robot, meas, q, y`` (and ``meta``, ``setup``) of calibration.md and measurements.md
_IMAGE_CAMPAIGN = _JUSTIN + """\
from jwarp import calibrate
from jwarp.calibration.simulate.campaign import simulate_campaign
from jwarp.calibration.files import make_measurement
from jwarp.calibration.simulate.scenarios import scenario
_setup, _sampler, _accept = scenario("justin19", "image")
_camp = simulate_campaign(robot, _setup, 40, seed=1, sampler=_sampler, accept=_accept)
meas = make_measurement(robot, _camp.setup)
q, y, meta = _camp.samples.q, _camp.samples.y, _camp.samples.meta
"""

#: hand4's contact (all six fingertip pairs) vs the relative-position task, as
#: examples/sensitivity_hand4.py and examples/oed_hand4.py build them
_HAND4 = """\
import jwarp
from jwarp.calibration.simulate.campaign import uniform_configurations
from jwarp.calibration.files import Setup, make_measurement
from jwarp.calibration.pool import draw_configurations
from jwarp.calibration.simulate.scenarios import HAND_FINGERS, hand_contact_setup
robot = jwarp.robot("hand4")
_pairs = tuple((a, b) for i, a in enumerate(HAND_FINGERS) for b in HAND_FINGERS[i + 1:])
setup = hand_contact_setup(pairs=_pairs)
contact = actual = make_measurement(robot, setup)
relative = task = make_measurement(robot, Setup(plugin="relative", robot="hand4", section={
    "end_effectors": [f"{f}_tip" for f in HAND_FINGERS]}))
"""


#: out.sqlite of docs/datasets.md's recipe, without the labeller: 4 justin19 simplex worlds
#: of :func:`jwarp.learn.plan_data.world_for`, 3 straight-line paths of 20 waypoints each,
#: all hard and feasible
_PATH_DB = """\
import numpy as np
from types import SimpleNamespace
import jwarp
from jwarp.learn.dataset import PathDB, world_record
from jwarp.learn.plan_data import world_for
from jwarp.calibration.simulate.campaign import uniform_configurations
_robot = jwarp.robot("justin19")
with PathDB("out.sqlite", _robot, create=True) as _db:
    for _s in range(4):
        _rng = np.random.default_rng(_s)
        _a, _b = (uniform_configurations(_robot, _rng, 3).astype(np.float32) for _ in "ab")
        _db.add_world(world_record(_s, world_for(_robot, _s), SimpleNamespace(
            starts=_a, goals=_b, paths=np.linspace(_a, _b, 20, axis=1).astype(np.float32),
            cost=_rng.random(3), feasible=np.ones(3, bool), hard=np.ones(3, bool),
            settings={"labeler": "straight lines (tests/test_docs_snippets.py)"})))
"""


def _panda(*names: str) -> str:
    """Prelude lines linking example-robot-data's Panda files into the working folder under
    the doc's names (``panda.urdf``, ``panda.srdf``, ``link3.stl``)."""
    src = {"panda.urdf": "panda_description/urdf/panda.urdf",
           "panda.srdf": "panda_description/srdf/panda.srdf",
           "link3.stl": "panda_description/meshes/collision/link3.stl",
           "finger.stl": "panda_description/meshes/collision/finger.stl"}
    return "from robot_data import erd\n" + "".join(
        f"_link({src[n]!r}, {n!r})\n" for n in names)


def _link(relative: str, name: str) -> None:
    """Symlink example-robot-data's ``relative`` as ``name`` (the URDF's mesh paths are
    package:// URIs, resolved from the installed package, not from the link's folder)."""
    from robot_data import erd

    os.symlink(erd(relative), name)


#: "file:line" of a block -> (prelude code, reason)
PRELUDES: dict[str, tuple[str, str]] = {
    "docs/calibration.md:80": (
        _IMAGE_CAMPAIGN + "_calibrate, _results = calibrate, []\n"
        "def calibrate(*args, **kwargs):\n"
        "    _results.append(_calibrate(*args, **kwargs))\n"
        "    return _results[-1]\n",
        "the text's `calibrate(robot, meas, q, y)`: justin19 and a 40-sample simulated image "
        "campaign (the free harmonic/coupling groups need justin19's coupled torso); "
        "`calibrate` keeps its result for the check (the block drops it)"),
    "docs/calibration.md:148": (
        _IMAGE_CAMPAIGN + "res = calibrate(robot, meas, q, y, free='theta,d,r,alpha')\n",
        "`res` is a calibration result of the text (the image campaign above, DH free)"),
    "docs/calibration.md:287": (
        _IMAGE_CAMPAIGN,
        "`robot, meas, q, y` of the text: justin19's 40-sample simulated image campaign"),
    "docs/calibration.md:337": (
        _IMAGE_CAMPAIGN + "_camp.write('run')\n",
        "`run/setup.json` and `run/samples.csv`: the 40-sample image campaign above, "
        "written as `jwarp simulate-campaign` writes it"),
    "docs/design.md:9": (
        _HAND4 + "q_actual, _meta = draw_configurations(robot, setup, 30, 0)\n"
        "pairs = _meta['pair']\n"
        "q_task = uniform_configurations(robot, __import__('numpy').random.default_rng(1), 30)\n",
        "examples/sensitivity_hand4.py's all-pairs mode: `actual` the hand4 contact "
        "measurement at 30 configurations in contact, `task` the fingertips relative to "
        "the thumb tip at 30 uniform ones"),
    "docs/design.md:40": (
        _HAND4 + "q_pool, _meta = draw_configurations(robot, setup, 300, 0)\n"
        "pairs = _meta['pair']\n"
        "q_uniform = uniform_configurations(robot, __import__('numpy').random.default_rng(1),"
        " 30)\n",
        "examples/oed_hand4.py's setting: a pool of 300 contact configurations, the task "
        "at 30 uniform ones"),
    "docs/design.md:100": (
        _HAND4 + "import numpy as np\nfrom jwarp.world import World\n"
        "world = World.of_shapes()\n"
        "q = uniform_configurations(robot, np.random.default_rng(2), 20)\n",
        "`setup` the hand4 contact setup, `world` an empty exact world, `q` 20 uniform "
        "configurations to check"),
    "docs/ik.md:167": (
        "import jwarp\nimport numpy as np\n"
        "from jwarp.world import load_scene, exact_world\n"
        "robot = jwarp.robot('justin19')\n"
        f"world = exact_world(load_scene({str(ROOT / 'examples/scenes/table_shelf.yaml')!r}))\n"
        "T = np.eye(4); T[:3, 3] = (0.6, -0.3, 0.75)\n",
        "ik.md's scene: justin19 and examples/scenes/table_shelf.yaml's exact world, a target "
        "pose T near the table"),
    "docs/measurements.md:8": (
        _IMAGE_CAMPAIGN + "setup = {'plugin': _camp.setup.plugin, **_camp.setup.section}\n"
        "p = meas.params.nominal\n",
        "`setup` the JSON section of the image scenario's setup, `q`/`meta` its 40 simulated "
        "samples, `p` the nominal parameters"),
    "docs/measurements.md:192": (
        "from jwarp.model.measurement import Measurement\n"
        "class LaserMeasurement(Measurement):\n    pass\n",
        "`LaserMeasurement` is the plugin class the text writes"),
    "docs/robot_schema.md:314": (
        "import jwarp\nfactory = lambda: jwarp.robot('planar4')\n",
        "`factory` is any callable returning a RobotModel"),
    "docs/robot_schema.md:334": ("", "self-contained (the factory is not called: my_arm.json "
                                     "is the reader's file)"),
    "docs/robot_schema.md:355": (
        "import jwarp\nfrom pathlib import Path as _P\n"
        "_P('my_package').mkdir()\n"
        "jwarp.robot('planar4').save('my_package/my_arm.json')\n"
        "__file__ = str(_P('my_package/robots.py').resolve())\n",
        "the block is my_package/robots.py: `__file__` names it, my_arm.json (planar4) "
        "lies beside it"),
    "docs/scenes.md:13": ("", "self-contained (examples/ is linked into the folder)"),
    "docs/scenes.md:238": (
        "import numpy as np\npose = np.eye(4); pose[:3, 3] = (0.6, 0.0, 0.8)\n"
        "new_pose = pose.copy(); new_pose[0, 3] = 0.5\n",
        "`pose`/`new_pose`: 4x4 poses of the cup [m]"),
    "docs/spheres.md:10": (
        _panda("link3.stl") + "import numpy as np\n"
        "from jwarp.importers.spheres import load_mesh\n"
        "mesh = load_mesh('link3.stl')\norigin_4x4 = np.eye(4)\n"
        "from jwarp.importers.robot import load_urdf\n"
        "urdf_link_geometries = load_urdf(erd('panda_description/urdf/panda.urdf'))"
        ".geometries_of('panda_link3')\n",
        "`link3.stl`, `mesh` and `urdf_link_geometries`: example-robot-data's Panda link 3 "
        "and the importer's own CollisionGeometry objects of that link"),
    "docs/spheres.md:204": (
        _JUSTIN, "`robot` is justin19 (the text's robot with spheres)"),
    "docs/spheres.md:267": (
        _panda("finger.stl"), "`finger.stl`: example-robot-data's Panda finger mesh"),
    "docs/urdf.md:6": (
        _panda("panda.urdf") + "import jwarp, numpy as np\n"
        "q = np.zeros((3, jwarp.robot('panda.urdf').n_dof))\n"
        "__import__('os').mkdir('ros_share')\n",
        "panda.urdf: example-robot-data's Panda; `q` 3 configurations of it; ros_share: "
        "the folder of the package_dirs substitution"),
    "docs/urdf.md:43": ("", "self-contained (example-robot-data of the test extra)"),
    "docs/urdf.md:198": (_panda("panda.urdf", "panda.srdf"),
                         "panda.urdf/panda.srdf: example-robot-data's Panda and its SRDF"),
    "docs/urdf.md:281": (_panda("panda.urdf"), "panda.urdf: example-robot-data's Panda"),
    "docs/urdf.md:416": (
        f"import jwarp\nopen('panda.xml', 'w').write({MJCF_ARM!r})\n",
        "panda.xml: tests/test_docs_commands.py's small MJCF arm (a Panda MJCF such as "
        "MuJoCo Menagerie's is not installed here), which has the attachment_site"),
    "docs/urdf_export.md:75": (
        _panda("panda.urdf") + "import jwarp\n"
        "from jwarp.importers.urdf_export import export_urdf\n"
        "from jwarp.calibration.simulate.campaign import simulate_campaign\n"
        "from jwarp.calibration.files import Setup, make_measurement\n"
        "robot = jwarp.robot('panda.urdf')\n"
        "_setup = Setup(plugin='cartesian', robot='panda', section={\n"
        "    'tracker': {'position': [2.0, 0.3, 0.8], 'rotvec': [0.1, -0.2, 2.4]},\n"
        "    'markers': [{'name': 'm', 'frame': 'panda_hand_tcp',\n"
        "                 'position': [0.02, 0.01, 0.05]}],\n"
        "    'noise': 1e-4})\n"
        "_camp = simulate_campaign(robot, _setup, 30, seed=0, collision_margin=None)\n"
        "measurement = make_measurement(robot, _camp.setup)\n"
        "q, y = _camp.samples.q, _camp.samples.y\n",
        "an imported URDF robot (example-robot-data's Panda) and a 30-sample simulated "
        "cartesian campaign of its hand TCP"),
    "examples/README.md:90": ("import jwarp\n", "the block uses `jwarp`"),
    "docs/datasets.md:45": ("", "self-contained (sizes: SUBSTITUTIONS)"),
    "docs/datasets.md:136": (
        _PATH_DB, "out.sqlite of the recipe above: 4 justin19 simplex worlds (world_for) "
                  "with straight-line paths as labels (real labels take minutes per world "
                  "on a CPU; the reader sees the same format)"),
    "docs/datasets.md:178": (
        _PATH_DB, "out.sqlite of the recipe above: 4 justin19 simplex worlds (world_for) "
                  "with straight-line paths labelled hard and feasible (real hard labels "
                  "take minutes per world on a CPU)"),
}

#: "file:line" -> [(old text, new text, reason)]: replacements in the block before it runs
SUBSTITUTIONS: dict[str, list[tuple[str, str, str]]] = {
    "docs/calibration.md:337": [
        ('test_rows="300:500"', 'test_rows="30:40"', "the prelude's campaign has 40 rows"),
        ("cv_folds=5", "cv_folds=2", "2 folds of 30 rows (5 folds of 300: minutes on a CPU)"),
        ('free="theta,d,r,alpha,kappa_theta,kappa_alpha"', 'free="theta,d"',
         "the joint offsets and lengths only: 30 rows of one image campaign cannot "
         "identify the elastic groups in seconds")],
    "docs/datasets.md:45": [
        ("10000, 100,", "3, 1,", "3 worlds of 1 path instead of 10000 x 100 (hours)"),
        ("PlanDataOptions(n_waypoints=20)",
         "PlanDataOptions(n_waypoints=20, max_starts=4, iterations=50)",
         "4 multi-starts of 50 steps per task (the default 100 x 300 takes ~30 s a world "
         "on a CPU)"),
        ("ray=True, num_gpus=0.25", "ray=False, progress=False",
         "CI has no GPU (num_gpus); in-process instead of Ray (starting Ray takes ~10 s; "
         "the Ray path of generate runs in tests/test_docs_commands.py's datasets recipe)")],
    "docs/datasets.md:136": [
        ("num_workers=4", "num_workers=0",
         "no worker processes (each would import torch and jwarp: seconds on 2 shared "
         "cores); the same batches in the main process"),
        ("range(10)", "range(2)", "2 epochs instead of 10 (each reads the same 12 paths)")],
    "docs/datasets.md:178": [
        ('checkpoint="plan19.pt")', 'checkpoint="plan19.pt", epochs=1, steps_per_epoch=2)',
         "1 epoch of 2 steps instead of 10 x 100 (~2.5 min on a CPU): the same network, "
         "split and checkpoint")],
    "docs/urdf.md:6": [
        ('"/opt/ros/humble/share"', '"ros_share"',
         "CI has no ROS install; package_dirs must name existing folders (an empty one "
         "here: example-robot-data's package:// meshes resolve without it)")],
    "docs/robot_schema.md:314": [
        (", ...}", "}", "`...` stands for more entries (not Python in a dict display)")],
    "docs/design.md:40": [
        ("DesignOptions(n=100,", "DesignOptions(n=20,",
         "a plan of 20 from the 300-configuration pool (100 of 10000 takes minutes)")],
    "docs/design.md:100": [
        ("setup, 10000,", "setup, 200,", "200 draws instead of 10000 (seconds, not minutes)")],
    "docs/spheres.md:204": [
        ("n_samples=10000", "n_samples=200", "200 sampled configurations instead of 10000")],
    "docs/urdf.md:281": [
        ("SpherizeOptions()", "SpherizeOptions(pair_samples=500)",
         "500 self-pair samples instead of 10000 (the contained fit's 125 spheres)")],
    "examples/README.md:90": [
        ("setup, 500,", "setup, 20,", "20 samples instead of 500 (each needs visible markers)")],
}

#: "file:line" -> reason the block is not run
NOT_RUN_SNIPPETS: dict[str, str] = {}


def _check_priors_and_orders(ns: dict, folder: Path, out: str) -> None:
    """calibration.md:80: each joint's harmonic order and prior sigma are the ones asked."""
    import re

    (res,) = ns["_results"]
    orders: dict[str, int] = {}
    for name, sigma in zip(res.names, res.sigma):
        m = re.match(r"(\w+)\.harmonic_[ab](\d+)$", name)
        if m:
            orders[m.group(1)] = max(orders.get(m.group(1), 0), int(m.group(2)))
            assert sigma == pytest.approx(5e-3 if m.group(1).startswith("torso_") else 1e-3), \
                (name, sigma)
    assert orders and all(k == (3 if j.startswith("torso_") else 1 if j.startswith("right_")
                                else 2) for j, k in orders.items()), orders


def _check_diagnostics(ns: dict, folder: Path, out: str) -> None:
    assert "mm" in out and len(out.splitlines()) >= 2, out


def _check_cross_validation(ns: dict, folder: Path, out: str) -> None:
    """calibration.md "Choosing settings": the table printed, the choice recorded in the
    provenance, the valid range of the 40 rows in the result."""
    res, cv = ns["res"], ns["cv"]
    assert "cross-validation: 4 folds of 40 calibration rows, 3 settings" in out, out
    prov = res.provenance["cv"]
    assert prov["chosen"] == cv.chosen.to_dict() and len(prov["table"]) == 3
    np.testing.assert_array_equal(res.valid_range.upper, ns["q"][:40].max(axis=0))


def _check_campaign_run(ns: dict, folder: Path, out: str) -> None:
    """calibration.md "From Python": the calibrated robot written with its provenance, the
    fit lowering the training error, the CV's choice among the grid's 3 settings."""
    import json

    import jwarp

    run = ns["run"]
    saved = jwarp.robot(str(folder / "run" / "calibrated.json"))
    assert saved.name.endswith("-calibrated"), saved.name
    prov = json.loads(saved.notes["calibration"]) if isinstance(
        saved.notes.get("calibration"), str) else saved.notes["calibration"]
    assert prov, saved.notes
    assert run.after["train"]["mean"] < run.before["train"]["mean"], (run.before, run.after)


def _check_generate(ns: dict, folder: Path, out: str) -> None:
    from jwarp.learn.dataset import PathDB

    r = ns["report"]
    assert (r.worlds_written, r.paths_written) == (3, 3), r
    assert out.split()[:2] == ["3", "3"], out
    with PathDB(folder / "out.sqlite") as db:
        assert db.robot == "justin19" and db.n_paths() == 3 and db.n_dof() == 19


def _check_loader(ns: dict, folder: Path, out: str) -> None:
    b = ns["b"]
    B = len(b["start"])
    assert B == 12 and b["start"].shape == (B, 19) and b["path"].shape == (B, 20, 19)
    assert b["start"].dtype == b["path"].dtype == __import__("torch").float32
    assert b["occupancy"].dtype == __import__("torch").bool
    assert b["occupancy"].shape[0] == len(set(b["world_id"].tolist())) == 4
    assert b["world_index"].shape == (B,)


def _check_train_plan(ns: dict, folder: Path, out: str) -> None:
    import torch

    assert (folder / "plan19.pt").is_file()
    torch.load(folder / "plan19.pt", map_location="cpu", weights_only=False)
    assert isinstance(ns["net"], torch.nn.Module) and ns["history"]


def _check_sensitivity(ns: dict, folder: Path, out: str) -> None:
    res = ns["res"]
    n = len(res.names)
    assert 0 < res.actual.n_identifiable <= n and 0 < res.task.n_identifiable <= n
    assert isinstance(res.kernel_included, bool) and out.count("\n") == len(res.breaking)
    json.dumps(res.to_dict())


def _check_design(ns: dict, folder: Path, out: str) -> None:
    q_plan, res = ns["q_plan"], ns["res"]
    assert q_plan.shape == (20, ns["robot"].n_dof) and len(set(res.indices.tolist())) == 20


def _check_pool(ns: dict, folder: Path, out: str) -> None:
    pool, chk, n_dof = ns["pool"], ns["chk"], ns["robot"].n_dof
    assert pool.q.shape == (200, n_dof) and set(pool.meta) == {"pair"}
    assert pool.drawn == 200 + sum(pool.dropped.values()) == 200 + len(pool.rejected_q)
    assert chk.keep.shape == (20,) and chk.keep.dtype == bool


def _check_explain_ik(ns: dict, folder: Path, out: str) -> None:
    res = ns["res"]
    assert np.shape(res.q)[-1] == ns["robot"].n_dof
    assert bool(res.feasible) == (out == ""), out


def _check_measurement(ns: dict, folder: Path, out: str) -> None:
    """measurements.md:8: frames (S, n_frames, 4, 4), y (S, m); the y of ``jacobians`` at
    the nominal parameters is ``predict``'s."""
    meas, frames, S = ns["meas"], ns["frames"], len(ns["q"])
    assert np.shape(frames) == (S, len(ns["robot"].frame_names), 4, 4)
    m = len(meas.obs_names)
    assert ns["y"].shape == (S, m) and np.asarray(ns["J_params"]).shape[-1] == len(ns["p"])
    np.testing.assert_allclose(ns["y"], meas.predict(frames, ns["p"], ns["meta"]), atol=1e-12)


def _check_hook(ns: dict, folder: Path, out: str) -> None:
    assert ns["jwarp_measurements"]() == {"laser": ns["LaserMeasurement"]}


def _check_robot_hook(ns: dict, folder: Path, out: str) -> None:
    robots = ns["jwarp_robots"]()
    assert set(robots) == {"robot_name"} and robots["robot_name"]().n_dof == 4


def _check_builtin_hook(ns: dict, folder: Path, out: str) -> None:
    robots = ns["jwarp_robots"]()
    assert set(robots) == {"my_arm"} and callable(robots["my_arm"])


def _check_package_hook(ns: dict, folder: Path, out: str) -> None:
    robot = ns["jwarp_robots"]()["my_arm"]()
    assert robot.joint_names == __import__("jwarp").robot("planar4").joint_names


def _check_scene(ns: dict, folder: Path, out: str) -> None:
    assert "can" in ns["world"].object_ids and not ns["world"].has_grid and ns["grid"].has_grid


def _check_world_edits(ns: dict, folder: Path, out: str) -> None:
    assert "cup" not in ns["world"].object_ids and "can" in ns["world"].object_ids
    assert ns["w2"].object_ids == []


def _check_sphere_fit(ns: dict, folder: Path, out: str) -> None:
    fit = ns["fit"]
    assert fit.k == len(fit.radii) >= 1 and np.shape(fit.centres) == (fit.k, 3)


def _check_containment(ns: dict, folder: Path, out: str) -> None:
    """The contained fit and the grown one hold every certificate point; the one-sided
    fit pokes out by what its bound says at most."""
    from jwarp.importers.spheres import containment_bound

    mesh, pts = ns["mesh"], ns["points"]
    assert ns["fit"].contained and ns["held"].contained and pts.shape[1] == 3
    for f in (ns["fit"], ns["held"]):
        d = np.linalg.norm(pts[:, None] - f.centres[None], axis=-1) - f.radii[None]
        assert d.min(axis=1).max() <= 0
        assert containment_bound(mesh, f.centres, f.radii) == 0.0
    assert ns["bound"] > 0


def _check_self_pairs(ns: dict, folder: Path, out: str) -> None:
    assert out.strip() and ns["pairs"].samples.shape == (200, ns["robot"].n_dof)
    json.loads((folder / "robot_pairs.json").read_text())


def _check_urdf(ns: dict, folder: Path, out: str) -> None:
    panda, q = ns["panda"], ns["q"]
    assert ns["frames"].shape == (len(q), len(panda.frame_names), 4, 4)
    assert ns["tcp"].shape == (len(q), 4, 4) and ns["imported"].geometries_of("panda_link3")


def _check_robot_names(ns: dict, folder: Path, out: str) -> None:
    """The Panda by name is the Panda of its URDF; ur5_urdf is UR5's file; the names list
    the ones the text names."""
    import jwarp
    from jwarp.importers.robot import example_robot_urdf, load_urdf

    panda = ns["panda"]
    assert panda.n_dof == 8 and list(panda.end_effectors) == ["panda_hand_tcp"]
    ref = load_urdf(example_robot_urdf("panda_description/urdf/panda.urdf")).model
    assert panda.frame_names == ref.frame_names
    assert ns["ur5_urdf"].endswith("ur5_robot.urdf") and jwarp.robot(ns["ur5_urdf"]).n_dof == 6
    assert {"panda", "ur3", "ur5", "ur10", "xarm7", "z1", "baxter"} <= set(ns["names"])


def _check_group(ns: dict, folder: Path, out: str) -> None:
    assert len(ns["res"].model.joint_names) == 7 and ns["arm"].n_dof == 7


def _check_spherized(ns: dict, folder: Path, out: str) -> None:
    assert ns["report"].links and ns["panda"].n_dof == __import__("jwarp").robot(
        str(folder / "panda.urdf")).n_dof


def _check_mjcf(ns: dict, folder: Path, out: str) -> None:
    assert ns["arm"].model.n_dof == ns["panda"].n_dof == 3


def _check_export(ns: dict, folder: Path, out: str) -> None:
    """calibrated.urdf loads, and its FK is the calibrated robot's."""
    import jwarp

    res, q = ns["res"], ns["q"][:5]
    back = jwarp.robot(str(folder / "calibrated.urdf"))
    assert back.joint_names == res.robot.joint_names
    i, j = back.frame_index("panda_hand_tcp"), res.robot.frame_index("panda_hand_tcp")
    np.testing.assert_allclose(
        np.asarray(jwarp.fk(back, q, device="cpu", dtype="float64"))[:, i],
        np.asarray(jwarp.fk(res.robot, q, device="cpu", dtype="float64"))[:, j], atol=1e-9)


def _check_campaign(ns: dict, folder: Path, out: str) -> None:
    assert len(ns["camp"].samples) == 20


#: "file:line" -> check(namespace, folder, stdout) after the block ran
CHECKS: dict[str, Callable[[dict, Path, str], None]] = {
    "docs/calibration.md:80": _check_priors_and_orders,
    "docs/calibration.md:148": _check_diagnostics,
    "docs/calibration.md:287": _check_cross_validation,
    "docs/calibration.md:337": _check_campaign_run,
    "docs/datasets.md:45": _check_generate,
    "docs/datasets.md:136": _check_loader,
    "docs/datasets.md:178": _check_train_plan,
    "docs/design.md:9": _check_sensitivity,
    "docs/design.md:40": _check_design,
    "docs/design.md:100": _check_pool,
    "docs/ik.md:167": _check_explain_ik,
    "docs/measurements.md:8": _check_measurement,
    "docs/measurements.md:192": _check_hook,
    "docs/robot_schema.md:314": _check_robot_hook,
    "docs/robot_schema.md:334": _check_builtin_hook,
    "docs/robot_schema.md:355": _check_package_hook,
    "docs/scenes.md:13": _check_scene,
    "docs/scenes.md:238": _check_world_edits,
    "docs/spheres.md:10": _check_sphere_fit,
    "docs/spheres.md:204": _check_self_pairs,
    "docs/spheres.md:267": _check_containment,
    "docs/urdf.md:6": _check_urdf,
    "docs/urdf.md:43": _check_robot_names,
    "docs/urdf.md:198": _check_group,
    "docs/urdf.md:281": _check_spherized,
    "docs/urdf.md:416": _check_mjcf,
    "docs/urdf_export.md:75": _check_export,
    "examples/README.md:90": _check_campaign,
}


def _substituted(where: str) -> str:
    code = BLOCKS[where]
    for old, new, _reason in SUBSTITUTIONS.get(where, []):
        assert old in code, f"{where}: SUBSTITUTIONS text {old!r} is not in the block"
        code = code.replace(old, new)
    return code


def test_every_snippet_is_run_or_listed():
    """Every block has a prelude or a NOT_RUN_SNIPPETS reason (not both), and every table
    key names a block (a moved block fails here, naming it)."""
    assert len(BLOCKS) >= 20, sorted(BLOCKS)
    missing = [w for w in BLOCKS if w not in PRELUDES and w not in NOT_RUN_SNIPPETS]
    assert not missing, f"Python blocks without a PRELUDES or NOT_RUN_SNIPPETS entry: {missing}"
    both = set(PRELUDES) & set(NOT_RUN_SNIPPETS)
    assert not both, f"both run and not run: {sorted(both)}"
    unchecked = [w for w in PRELUDES if w not in CHECKS]
    assert not unchecked, f"run blocks without a CHECKS entry: {unchecked}"
    for table in (PRELUDES, NOT_RUN_SNIPPETS, SUBSTITUTIONS, CHECKS):
        stale = set(table) - set(BLOCKS)
        assert not stale, f"table entries naming no block: {sorted(stale)}"
    assert all(reason for _p, reason in PRELUDES.values())
    assert all(NOT_RUN_SNIPPETS.values())
    assert all(r for subs in SUBSTITUTIONS.values() for _o, _n, r in subs)


@pytest.mark.parametrize("where", [w for w in BLOCKS if w not in NOT_RUN_SNIPPETS])
def test_doc_python_snippet_runs(where, tmp_path, monkeypatch):
    """The block runs after its prelude, in a fresh namespace and an empty folder (with a
    link to the repository's examples/ for blocks reading examples/...), stdout captured,
    then its CHECKS entry."""
    assert where in PRELUDES, f"{where}: no PRELUDES entry (or NOT_RUN_SNIPPETS reason)"
    prelude, _reason = PRELUDES[where]
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("JWARP_CACHE", str(tmp_path / "cache"))  # cold, as on CI (spherize)
    if "examples/" in BLOCKS[where]:
        os.symlink(ROOT / "examples", "examples")  # the repository's, read only
    ns: dict = {"__name__": "doc_snippet", "_link": _link}
    out = io.StringIO()
    with contextlib.redirect_stdout(out), warnings.catch_warnings(record=True):
        warnings.simplefilter("always")  # kept out of the summary (calibration findings)
        exec(compile(prelude, f"{where} (prelude)", "exec"), ns)
        exec(compile(_substituted(where), where, "exec"), ns)
    assert where in CHECKS, f"{where}: no CHECKS entry"
    CHECKS[where](ns, tmp_path, out.getvalue())
