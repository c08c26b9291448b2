"""Collision model of imported URDFs (jwarp.world.spherize): fitted spheres cover every
link's collision geometry (checked on fresh surface points by numpy), URDF spheres are
kept, adjacent links are excluded from self-collision, the disk cache returns the same
model; the fitted Panda plans and solves IK in the MoveIt table-and-shelf scene."""

import json

import numpy as np
import pytest
from cli_helpers import run

import jwarp
from jwarp.importers.robot import example_robot_urdf, load_urdf
from jwarp.solvers.ik import IKOptions, IKSolver
from jwarp.solvers.planning import Planner, PlanOptions
from jwarp.world.path_feasibility import collision_free, path_feasible
from jwarp.world.scene_file import SceneOptions, load_scene, robot_frames, scene_world
from jwarp.world.spherize import SpherizeOptions, spherize, spherized_robot

TOL = 0.01
URDF = """<?xml version="1.0"?>
<robot name="two_box">
  <link name="base"><collision><geometry><sphere radius="0.05"/></geometry></collision></link>
  <link name="arm"><collision><origin xyz="0.15 0 0" rpy="0 0 0.3"/>
    <geometry><box size="0.3 0.04 0.02"/></geometry></collision></link>
  <link name="tip"><collision><origin xyz="0.05 0 0" rpy="0 1.5707963 0"/>
    <geometry><cylinder radius="0.02" length="0.1"/></geometry></collision></link>
  <joint name="j1" type="revolute"><parent link="base"/><child link="arm"/>
    <origin xyz="0 0 0.1"/><axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="j2" type="revolute"><parent link="arm"/><child link="tip"/>
    <origin xyz="0.3 0 0"/><axis xyz="0 1 0"/><limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
</robot>
"""


@pytest.fixture
def urdf(tmp_path, monkeypatch):
    monkeypatch.setenv("JWARP_CACHE", str(tmp_path / "cache"))
    p = tmp_path / "two_box.urdf"
    p.write_text(URDF)
    return p


def box_surface(size, n, rng):
    """n points on the surface of a box of edge lengths ``size`` centred at 0 (numpy)."""
    size = np.asarray(size, float)
    pts = rng.uniform(-0.5, 0.5, (n, 3)) * size
    axis = rng.integers(0, 3, n)
    pts[np.arange(n), axis] = np.sign(rng.uniform(-1, 1, n)) * size[axis] / 2
    return pts


def test_spheres_cover_the_geometry_and_urdf_spheres_are_kept(urdf):
    imported = load_urdf(urdf)
    model, rep = spherize(imported, SpherizeOptions(tolerance=TOL, pair_samples=200))
    base, arm = model.frame_index("base"), model.frame_index("arm")
    kept = [s for s in model.spheres if s.frame == base]
    assert len(kept) == 1 and kept[0].radius == pytest.approx(0.05)
    rows = {r["link"]: r for r in rep.links}
    assert rows["base"]["kept"] and not rows["arm"]["kept"]
    # fresh box surface points (in the link frame: origin xyz 0.15, yaw 0.3) within TOL
    rng = np.random.default_rng(7)
    c, s = np.cos(0.3), np.sin(0.3)
    R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    pts = box_surface([0.3, 0.04, 0.02], 5000, rng) @ R.T + [0.15, 0, 0]
    sph = [(np.asarray(x.position), x.radius) for x in model.spheres if x.frame == arm]
    C = np.array([p for p, _ in sph])
    r = np.array([q for _, q in sph])
    outside = (np.linalg.norm(pts[:, None] - C[None], axis=-1) - r).min(axis=1)
    assert outside.max() <= TOL
    assert rows["arm"]["one_sided_error"] <= TOL and rows["arm"]["meets_tolerance"]
    # adjacent links never checked against each other
    allowed = model.allowed_collision_pairs
    assert not allowed[base, arm] and not allowed[arm, model.frame_index("tip")]


def test_cache_returns_the_same_model_and_recovers_from_damage(urdf, tmp_path):
    o = SpherizeOptions(tolerance=0.02, pair_samples=200)
    a, ra = spherized_robot(urdf, o)
    b, rb = spherized_robot(urdf, o)
    assert not ra.cached and rb.cached
    assert json.dumps(a.to_dict(), sort_keys=True) == json.dumps(b.to_dict(), sort_keys=True)
    files = list((tmp_path / "cache" / "urdf").glob("*.json"))
    assert len(files) == 1
    files[0].write_text("{not json")
    c, rc = spherized_robot(urdf, o)
    assert not rc.cached and len(c.spheres) == len(a.spheres)
    # other options: another cache entry
    spherized_robot(urdf, SpherizeOptions(tolerance=0.03, pair_samples=200))
    assert len(list((tmp_path / "cache" / "urdf").glob("*.json"))) == 2


@pytest.mark.parametrize("field,value,exc", [("tolerance", 0.0, ValueError),
                                             ("tolerance", "1", TypeError),
                                             ("max_spheres", 0, ValueError),
                                             ("pair_samples", 0, ValueError),
                                             ("pair_margin", -1.0, ValueError)])
def test_options_validate(field, value, exc):
    with pytest.raises(exc, match=field):
        SpherizeOptions(**{field: value}).validate()


def test_import_urdf_cli_fits_spheres(urdf, tmp_path, capsys):
    out = tmp_path / "r.json"
    code, stdout, err = run(capsys, ["import-urdf", urdf, "--out", out, "--tolerance", "0.02",
                                     "--pair-samples", "200"])
    assert code == 0, err
    assert "spheres fitted to 3 links" in stdout
    assert len(jwarp.robot(str(out)).spheres) > 3
    code, _, err = run(capsys, ["import-urdf", urdf, "--out", out, "--tolerance", "0"])
    assert code == 2 and "--tolerance" in err
    code, _, err = run(capsys, ["import-urdf", urdf, "--out", out, "--spheres", "none"])
    assert code == 0 and len(jwarp.robot(str(out)).spheres) == 0


@pytest.fixture(scope="module")
def panda(tmp_path_factory):
    try:
        path = example_robot_urdf("panda_description/urdf/panda.urdf")
    except ValueError as e:
        pytest.skip(str(e))
    mp = pytest.MonkeyPatch()
    mp.setenv("JWARP_CACHE", str(tmp_path_factory.mktemp("cache")))
    try:
        model, rep = spherized_robot(path, SpherizeOptions(tolerance=0.02, pair_samples=2000))
    finally:
        mp.undo()
    return model, rep


@pytest.fixture(scope="module")
def table_shelf(panda):
    from pathlib import Path

    scene = load_scene(Path(__file__).parents[2] / "examples" / "scenes" / "table_shelf.yaml",
                       robot_frames(panda[0]))
    return scene_world(scene, SceneOptions(voxel_size=0.03))


def test_fitted_panda_plans_and_solves_ik_in_the_scene(panda, table_shelf):
    model, rep = panda
    assert len(model.spheres) > 20
    assert all(r["meets_tolerance"] for r in rep.links)
    rng = np.random.default_rng(0)
    lim = model.joint_limits
    q = rng.uniform(lim[:, 0], lim[:, 1], (2000, model.n_dof))
    q = q[collision_free(model, table_shelf, q, 0.0, device="cpu")]
    assert len(q) > 50   # the self pairs leave free configurations
    # plan between free configurations: feasible, and the path passes the exact check
    opts = PlanOptions(n_starts=4, iterations=100, n_waypoints=16)
    res = Planner(model, table_shelf, 6, opts, device="cpu").plan(q[0:6], q[6:12])
    assert res.feasible.sum() >= 5
    ok = path_feasible(model, table_shelf, res.path[res.feasible], 32, device="cpu")
    assert ok.all()
    # IK to the hand pose of free configurations: on target and collision-free
    frame = model.frame_index("panda_hand")
    T = np.asarray(jwarp.fk(model, q[12:20], device="cpu", dtype="float64"))[:, frame]
    ik = IKSolver(model, frame, 8, IKOptions(n_starts=8), world=table_shelf, device="cpu",
                  dtype=np.float64).solve(T)
    assert ik.feasible.sum() >= 7
    F = np.asarray(jwarp.fk(model, ik.q[ik.feasible], device="cpu", dtype="float64"))[:, frame]
    assert np.abs(F[:, :3, 3] - T[ik.feasible, :3, 3]).max() < 1e-3
    assert collision_free(model, table_shelf, ik.q[ik.feasible], 0.0, device="cpu").all()
    # and the independent verifier (pinocchio FK, coal: the URDF's collision meshes and the
    # fitted spheres against the scene's exact primitives) finds every IK answer clear
    from pathlib import Path

    from verifier import PathVerifier, robot_spheres

    scene = load_scene(Path(__file__).parents[2] / "examples" / "scenes" / "table_shelf.yaml",
                       robot_frames(model))
    v = PathVerifier(example_robot_urdf("panda_description/urdf/panda.urdf"), None,
                     scene.shapes, spheres=robot_spheres(model), joint_names=model.joint_names)
    for qs in ik.q[ik.feasible]:
        verdict = v.check_path(qs[None], margin=0.0)
        assert verdict.ok, verdict


def test_sphere_fit_shows_a_progress_bar(urdf, capsys):
    """Issue 39 item 5: the fit draws a bar on stderr (a step per fitted link, named, and
    one for the pair sampling; the result does not depend on it); off by default in
    Python, on a terminal only with ``progress=None`` (the CLI's import)."""
    imported = load_urdf(urdf)
    opts = SpherizeOptions(tolerance=TOL, pair_samples=200)
    quiet, _ = spherize(imported, opts)
    assert capsys.readouterr().err == ""
    loud, _ = spherize(imported, opts, progress=True)
    err = capsys.readouterr().err
    last = err.replace("\r", "\n").strip().splitlines()[-1]
    assert last.startswith("sphere fit: 100%") and "3/3 steps" in last, err  # arm, tip, pairs
    assert "self-collision pairs" in last
    assert loud.to_dict() == quiet.to_dict()
    spherize(imported, opts, progress=None)   # stderr is not a terminal here: no bar
    assert capsys.readouterr().err == ""
    model, rep = spherized_robot(urdf, opts, progress=True)
    assert "sphere fit: 100%" in capsys.readouterr().err and not rep.cached
    model, rep = spherized_robot(urdf, opts, progress=True)   # from the cache: nothing to show
    assert capsys.readouterr().err == "" and rep.cached


def test_absurd_protrusion_is_bounded_by_the_robot_and_all_in_contact_refused(urdf, tmp_path,
                                                                              capsys):
    """Reliability round 4, item 6: ``--protrusion 1e308`` wrote spheres of radius 1e308 m,
    every self pair was dropped as always colliding and free-config called configurations
    free. The option is bounded by the robot's size (the box of its collision geometry),
    and a fit whose spheres are in contact in every tested pair is refused."""
    imported = load_urdf(urdf)
    with pytest.raises(ValueError, match=r"protrusion: 1e\+308 m is more than the robot's "
                                         r"size \(its collision geometry spans 0\.4"):
        spherize(imported, SpherizeOptions(tolerance=TOL, protrusion=1e308, pair_samples=50))
    # within the robot's size, but the tip's spheres reach the base in every sample: the
    # only tested pair (base-tip) would be excluded as always colliding
    with pytest.raises(ValueError, match=r"protrusion: the fitted spheres of all 1 link pairs "
                                         r"that are not adjacent are in contact in every one"):
        spherize(imported, SpherizeOptions(tolerance=TOL, protrusion=0.4, pair_samples=50))
    _, rep = spherize(imported, SpherizeOptions(tolerance=TOL, protrusion=0.005,
                                                pair_samples=50))
    assert rep.pairs.always_colliding == []          # a sane protrusion fits as before
    code, out, err = run(capsys, ["import-urdf", urdf, "--out", tmp_path / "r.json",
                                  "--protrusion", "1e308", "--pair-samples", "50"])
    assert code == 2 and err.strip().splitlines()[-1].startswith(
        "jwarp: error: --protrusion: 1e+308 m is more than the robot's size")
    assert not (tmp_path / "r.json").exists()


def test_home_without_a_collision_model_names_the_reason(urdf, tmp_path, capsys):
    """Reliability round 4, item 9: ``--home`` with ``--spheres urdf`` of a URDF without
    sphere geometry said "needs a collision model (--spheres fit or urdf)", after the work;
    now the reason, before any work."""
    boxes = tmp_path / "boxes.urdf"
    boxes.write_text(URDF.replace('<sphere radius="0.05"/>', '<box size="0.1 0.1 0.1"/>'))
    out = tmp_path / "r.json"
    for extra, words in ((["--spheres", "urdf"], "has no sphere geometry, so --spheres urdf "
                                                  "gives none"),
                         (["--spheres", "none"], "--spheres none gives none"),
                         (["--no-home-fit"], "not --no-home-fit")):
        code, _, err = run(capsys, ["import-urdf", boxes, "--out", out, "--home", "0,0",
                                    *extra])
        assert code == 2, err
        last = err.strip().splitlines()[-1]
        assert last.startswith("jwarp: error: --home: ") and words in last, last
    assert not out.exists()
