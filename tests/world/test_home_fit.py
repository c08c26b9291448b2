"""The home free of self-collision at import (jwarp.world.home_fit): a given home where the
URDF geometry of a checked pair touches is refused (naming the pairs and distances), a
default one replaced (SRDF state, mid-limits, random free), never freed by unchecking a
pair (boxes at known distances: analytic); spheres tightened where the geometry is apart
(never below their clearance, analytic for a cube; a link whose surface would be uncovered
beyond the tolerance is left as it was), the mesh distance against coal (pinocchio) on
the Kinova, the SRDF home against pinocchio's FK, and ``jwarp import-urdf --home``."""

from __future__ import annotations

import json
import math
import warnings

import numpy as np
import pytest

import jwarp
from jwarp.importers.robot import example_robot_urdf, load_urdf
from jwarp.importers.srdf import read_srdf
from jwarp.model import SelfCollision, Sphere
from jwarp.world.home_fit import (
    HomeFitOptions,
    HomeFitWarning,
    fit_home,
    link_mesh,
    mesh_distance,
    resolve_home,
)

H = 0.05   # half edge of the boxes [m]


def _joint(name, parent, child, axis):
    return (f'<joint name="{name}" type="prismatic"><parent link="{parent}"/>'
            f'<child link="{child}"/><axis xyz="{axis}"/>'
            f'<limit lower="-0.5" upper="0.5" effort="1" velocity="1"/></joint>')


def _box(name, x):
    return (f'<link name="{name}"><collision><origin xyz="{x} 0 0"/><geometry>'
            f'<box size="{2 * H} {2 * H} {2 * H}"/></geometry></collision></link>')


@pytest.fixture()
def boxes(tmp_path):
    """Three cubes: 'a' overlaps 'base' by 2 mm at q = 0, 'b' is 4 mm from it; each pair
    joined through a link without geometry (not adjacent)."""
    text = ('<robot name="boxes">' + _box("base", 0.0) + '<link name="m1"/>'
            + _box("a", 2 * H - 0.002) + '<link name="m2"/>' + _box("b", -2 * H - 0.004)
            + _joint("j1", "base", "m1", "0 0 1") + _joint("j2", "m1", "a", "0 1 0")
            + _joint("j3", "base", "m2", "0 0 1") + _joint("j4", "m2", "b", "0 1 0")
            + "</robot>")
    path = tmp_path / "boxes.urdf"
    path.write_text(text)
    return str(path)


def _with_spheres(imp, protrusion=0.003):
    """The imported boxes, every frame pair checked, one sphere at each cube's centre
    reaching ``protrusion`` past its faces."""
    m = imp.model
    spheres = [Sphere(frame=m.frame_index(n), position=np.array([x, 0.0, 0.0]),
                      radius=H + protrusion)
               for n, x in (("base", 0.0), ("a", 2 * H - 0.002), ("b", -2 * H - 0.004))]
    return m.copy(spheres=spheres, self_collision=SelfCollision())


def _overlaps(m, q):
    """{(frame a, frame b) names: deepest sphere overlap [m]} of the checked pairs (numpy)."""
    f, p, r = m.sphere_arrays()
    T = np.asarray(jwarp.fk(m, np.asarray(q, float)[None], device="cpu", dtype=np.float64))[0]
    x = np.einsum("sij,sj->si", T[f, :3, :3], p) + T[f, :3, 3]
    d = np.linalg.norm(x[:, None] - x[None], axis=-1) - r[:, None] - r[None]
    A = m.allowed_collision_pairs
    n = m.frame_names
    return {(n[f[i]], n[f[j]]): float(d[i, j]) for i, j in zip(*np.nonzero(d < 0))
            if f[i] < f[j] and A[f[i], f[j]]}


def test_mesh_distance_of_boxes(boxes):
    imp = load_urdf(boxes)
    m = imp.model
    T = np.asarray(jwarp.fk(m, np.zeros((1, m.n_dof)), device="cpu", dtype=np.float64))[0]
    base, a, b = (link_mesh(imp, n) for n in ("base", "a", "b"))
    i = m.frame_index
    assert mesh_distance(base, T[i("base")], a, T[i("a")]) == pytest.approx(-0.002, abs=1e-5)
    assert mesh_distance(base, T[i("base")], b, T[i("b")]) == pytest.approx(0.004, abs=1e-5)
    assert mesh_distance(a, T[i("a")], b, T[i("b")]) == pytest.approx(0.102, abs=1e-5)
    assert link_mesh(imp, "m1") is None


def _without(m, *pairs):
    """``m`` with the frame pairs (names) excluded, as an SRDF's disable_collisions would."""
    return m.copy(self_collision=SelfCollision(exclude_pairs=[
        tuple(sorted((m.frame_index(a), m.frame_index(b)))) for a, b in pairs]))


def test_given_home_in_collision_is_refused(boxes):
    """base/a: the cubes overlap by 2 mm at q = 0: a given home there is refused, naming the
    pair, the geometry's overlap and the spheres' depth; nothing is unchecked."""
    imp = load_urdf(boxes)
    m = _with_spheres(imp)
    with pytest.raises(ValueError) as e:
        fit_home(imp, m, [0.0] * 4)
    msg = str(e.value)
    assert msg.startswith("home: given joint values is a self-collision of robot 'boxes'")
    assert "base/a (URDF collision geometry overlapping by 2.0 mm, spheres 8.0 mm deep)" in msg
    assert "base/b" not in msg                      # 4 mm apart: a fit to tighten, not a hit
    assert m.allowed_collision_pairs[m.frame_index("base"), m.frame_index("a")]


def test_default_home_in_collision_is_replaced(boxes, tmp_path):
    """The default home (zeros) is a self-collision: replaced by the first free candidate
    (an SRDF state in collision is passed over, the middle of the limits is zeros again,
    then a random configuration); the pair stays checked and is free at the new home."""
    from jwarp.importers.srdf import parse_srdf
    imp = load_urdf(boxes)
    m = _with_spheres(imp)
    # 'ready' lifts a by 9 cm: the cubes still overlap by 1 cm in z, the spheres (one per
    # cube, 33 mm short of its corners: the tolerance passed) are 27 mm apart
    srdf = parse_srdf("<robot name='boxes'><group name='g'><joint name='j1'/></group>"
                      "<group_state name='ready' group='g'><joint name='j1' value='0.09'/>"
                      "</group_state><group_state name='up' group='g'><joint name='j2' "
                      "value='0.4'/></group_state></robot>")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        out, rep = fit_home(imp, m, None, HomeFitOptions(tolerance=0.035), srdf=srdf)
    assert [r["home_from"] for r in rep.rejected] == [
        "zeros projected into the limits", "SRDF group_state 'ready'"]
    assert rep.rejected[0]["pairs"][0]["links"] == ["base", "a"]
    assert rep.rejected[0]["pairs"][0]["mesh_distance_m"] == pytest.approx(-0.002, abs=1e-5)
    assert rep.home_from == "SRDF group_state 'up'" and rep.home == [0.0, 0.4, 0.0, 0.0]
    assert rep.home_free and rep.default_pairs == []
    assert np.array_equal(out.allowed_collision_pairs, m.allowed_collision_pairs)
    assert json.loads(out.notes["home"]) == rep.home
    text = " ".join(str(w.message) for w in caught if w.category is HomeFitWarning)
    assert "the default home (zeros projected into the limits) is a self-collision: base/a" \
        in text and "SRDF group_state 'up' instead" in text
    assert "replaced zeros projected into the limits (self-collision: base/a)" in rep.summary()
    # without the SRDF: the middle of the limits is zeros too: a random free configuration
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", HomeFitWarning)
        out, rep = fit_home(imp, m, None, HomeFitOptions(tolerance=0.035))
    assert rep.home_from.startswith("a random configuration free of self-collision")
    assert [r["home_from"] for r in rep.rejected] == [
        "zeros projected into the limits", "the middle of the joint limits"]
    assert _overlaps(out, rep.home) == {} and rep.home_free
    # nothing free anywhere (n_random 0): refused, naming what was tried
    with pytest.raises(ValueError, match=r"home: no home free of self-collision found .*"
                                         r"zeros projected into the limits: base/a .*"
                                         r"nor among 0 random configurations"):
        fit_home(imp, m, None, HomeFitOptions(n_random=0))


def test_tightened_where_the_geometry_is_apart(boxes):
    imp = load_urdf(boxes)
    m = _without(_with_spheres(imp), ("base", "a"))    # as an SRDF disabling base/a
    q = np.zeros(m.n_dof)
    before = _overlaps(m, q)
    assert before == pytest.approx({("base", "b"): -0.002}, abs=1e-9)
    with pytest.warns(HomeFitWarning) as caught:
        out, rep = fit_home(imp, m, [0.0] * 4)
    text = " ".join(str(w.message) for w in caught)
    assert "'b'" in text and "shrunk" in text and "Default" not in text
    assert rep.default_pairs == [] and rep.rejected == []
    # base/b: the cubes are 4 mm apart -> still checked, its two spheres shrunk just enough
    assert out.allowed_collision_pairs[out.frame_index("base"), out.frame_index("b")]
    assert np.array_equal(out.allowed_collision_pairs, m.allowed_collision_pairs)
    assert {r["link"] for r in rep.tightened} == {"base", "b"}
    f, _, r = out.sphere_arrays()
    rb, rbb = r[f == out.frame_index("base")][0], r[f == out.frame_index("b")][0]
    assert H <= rb < H + 0.003 and H <= rbb < H + 0.003          # never below the clearance
    assert 2 * H + 0.004 - rb - rbb == pytest.approx(HomeFitOptions().gap, abs=1e-9)
    assert r[f == out.frame_index("a")][0] == H + 0.003          # 'a' untouched
    assert _overlaps(out, q) == {} and rep.home_free and rep.remaining == []
    # the one-sided error reported is the cube corner's distance outside the sphere
    row = next(x for x in rep.tightened if x["link"] == "b")
    assert row["one_sided_error_m"] == pytest.approx(
        [math.sqrt(3) * H - H - 0.003, math.sqrt(3) * H - rbb], abs=1e-9)
    assert "home (given joint values): free" in rep.summary()


def test_tightening_beyond_tolerance_is_left_as_it_was(boxes):
    imp = load_urdf(boxes)
    m = _without(_with_spheres(imp), ("base", "a"))
    corner = math.sqrt(3) * H - H - 0.003        # the cubes' one-sided error as fitted
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", HomeFitWarning)
        out, rep = fit_home(imp, m, None, HomeFitOptions(tolerance=corner + 0.0005,
                                                         refit=False))
    assert rep.home_from == "zeros projected into the limits"
    assert all(x.get("reverted") for x in rep.tightened) and rep.tightened
    assert [p["links"] for p in rep.remaining] == [["base", "b"]]
    assert "uncover" in rep.remaining[0]["why"] and not rep.home_free
    assert "IN COLLISION: base/b" in rep.summary()
    f, _, r = out.sphere_arrays()
    assert np.all(r == H + 0.003)
    assert set(_overlaps(out, np.zeros(4))) == {("base", "b")}    # not hidden


def test_refit_where_shrinking_would_uncover(boxes):
    """The cubes' spheres shrunk to free the home would leave the corners 35 mm outside:
    the two links are fitted again with a protrusion of half their 4 mm gap (analytic
    clearance of a cube: every sphere within it; the fresh one-sided error on the cubes'
    corners and faces within the tolerance)."""
    imp = load_urdf(boxes)
    m = _without(_with_spheres(imp), ("base", "a"))
    tol = math.sqrt(3) * H - H - 0.003 + 0.0005
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", HomeFitWarning)
        out, rep = fit_home(imp, m, None, HomeFitOptions(tolerance=tol))
    assert rep.home_free and _overlaps(out, np.zeros(4)) == {}
    rows = {r["link"]: r for r in rep.tightened}
    assert set(rows) == {"base", "b"} and all(r["refit"] for r in rows.values())
    p = rows["b"]["protrusion_m"]
    assert p == pytest.approx((0.004 - HomeFitOptions().gap) / 2)
    f, c, r = out.sphere_arrays()
    rng = np.random.default_rng(0)
    for name, x0 in (("base", 0.0), ("b", -2 * H - 0.004)):
        k = f == out.frame_index(name)
        local = c[k] - [x0, 0.0, 0.0]
        clear = H - np.abs(local).max(axis=1)               # distance to the cube's faces
        assert np.all(clear >= -1e-6) and np.all(r[k] - clear <= p + 1e-6)
        pts = rng.uniform(-H, H, (20000, 3))
        pts[np.arange(20000), rng.integers(0, 3, 20000)] = rng.choice([-H, H], 20000)
        pts = np.concatenate([pts, np.array(np.meshgrid(*[[-H, H]] * 3)).reshape(3, -1).T])
        err = np.linalg.norm(pts[:, None] - local[None], axis=-1) - r[k][None]
        assert err.min(axis=1).max() <= tol + 1e-6
    assert "fitted again" in rep.summary()


def test_home_arguments(boxes):
    imp = load_urdf(boxes)
    m = imp.model
    with pytest.raises(ValueError, match="home: expected 4 finite joint values"):
        resolve_home(m, [0.0, 0.0])
    with pytest.raises(ValueError, match=r"home: j2=0.7 is outside the joint's limits"):
        resolve_home(m, [0.0, 0.7, 0.0, 0.0])
    with pytest.raises(ValueError, match="home: state 'x' needs an SRDF"):
        resolve_home(m, "x")
    with pytest.raises(TypeError, match="home: expected a state name or joint values"):
        resolve_home(m, 3.0)
    with pytest.raises(ValueError, match="contact_margin: expected a finite distance"):
        fit_home(imp, m, None, HomeFitOptions(contact_margin=-1.0))


def _erd(path):
    try:
        return example_robot_urdf(path)
    except ValueError as e:
        pytest.skip(str(e))


def test_kinova_home_and_mesh_distance_against_pinocchio_coal():
    """The Kinova's SRDF 'arm_up' writes joint_3 = -pi/2 for a range [0.33, 5.95]: the home
    is the same angle + 2 pi (pinocchio's FK at the raw values agrees); at the value
    clipped into the limits the meshes of link_1 and link_6 are apart, and jwarp's mesh
    distance is coal's within the sampling."""
    pin = pytest.importorskip("pinocchio")
    urdf = _erd("kinova_description/robots/kinova.urdf")
    srdf = read_srdf(_erd("kinova_description/srdf/kinova.srdf"))
    imp = load_urdf(urdf)
    m = imp.model
    q, where = resolve_home(m, "arm_up", srdf)
    raw = srdf.state("arm_up")
    pm = pin.buildModelFromUrdf(urdf)
    pd = pm.createData()
    qp = pin.neutral(pm)
    for name, v in raw.items():
        jp = pm.joints[pm.getJointId(name)]
        if jp.nq == 1:
            qp[jp.idx_q] = v
        else:
            qp[jp.idx_q], qp[jp.idx_q + 1] = math.cos(v), math.sin(v)
    pin.framesForwardKinematics(pm, pd, qp)
    T = np.asarray(jwarp.fk(m, q[None], device="cpu", dtype=np.float64))[0]
    for name in ("j2s6s200_link_6", "j2s6s200_end_effector"):
        ref = pd.oMf[pm.getFrameId(name)].homogeneous
        assert np.allclose(T[m.frame_index(name)], ref, atol=1e-9)
    j3 = m.joint_index("j2s6s200_joint_3")
    assert q[j3] == pytest.approx(raw["j2s6s200_joint_3"] + 2 * math.pi)
    # clipped instead: link_1 and link_6 close, coal's distance as the reference
    qc = q.copy()
    qc[j3] = m.joint_limits[j3, 0]
    qp[pm.joints[pm.getJointId("j2s6s200_joint_3")].idx_q] = qc[j3]
    share = str(__import__("pathlib").Path(urdf).parents[4])
    gm = pin.buildGeomFromUrdf(pm, urdf, pin.GeometryType.COLLISION, package_dirs=[share])
    names = [pm.frames[g.parentFrame].name for g in gm.geometryObjects]
    ia, ib = names.index("j2s6s200_link_1"), names.index("j2s6s200_link_6")
    gm.addCollisionPair(pin.CollisionPair(ia, ib))
    gd = pin.GeometryData(gm)
    pin.computeDistances(pm, pd, gm, gd, qp)
    ref = gd.distanceResults[0].min_distance
    T = np.asarray(jwarp.fk(m, qc[None], device="cpu", dtype=np.float64))[0]
    d = mesh_distance(link_mesh(imp, "j2s6s200_link_1"), T[m.frame_index("j2s6s200_link_1")],
                      link_mesh(imp, "j2s6s200_link_6"), T[m.frame_index("j2s6s200_link_6")])
    assert 0.002 < ref < 0.01
    assert ref - 1e-4 <= d <= ref + 0.0015, (d, ref)


def test_cli_home(tmp_path, capsys, monkeypatch):
    """``import-urdf --home``: the boxes with geometry on the middle links too (so that base
    and a are not adjacent by MoveIt's rule, which joins links through links without
    geometry): a given home in collision is refused naming --home; the default home is
    replaced and the pair stays checked; a free home tightens base/b."""
    from jwarp.cli.main import main

    text = ('<robot name="boxes">' + _box("base", 0.0)
            + '<link name="m1"><collision><origin xyz="0 0 1"/><geometry><box size="0.01 0.01 '
              '0.01"/></geometry></collision></link>'
            + _box("a", 2 * H - 0.002)
            + '<link name="m2"><collision><origin xyz="0 0 -1"/><geometry><box size="0.01 0.01 '
              '0.01"/></geometry></collision></link>'
            + _box("b", -2 * H - 0.004)
            + _joint("j1", "base", "m1", "0 0 1") + _joint("j2", "m1", "a", "0 1 0")
            + _joint("j3", "base", "m2", "0 0 1") + _joint("j4", "m2", "b", "0 1 0")
            + "</robot>")
    boxes = tmp_path / "boxes.urdf"
    boxes.write_text(text)
    monkeypatch.setenv("JWARP_CACHE", str(tmp_path / "cache"))   # one fit for every call
    out = tmp_path / "boxes.json"
    base = ["import-urdf", str(boxes), "--out", str(out), "--pair-samples", "200",
            "--tolerance", "0.03"]
    assert main(base + ["--home", "0,0,0,0"]) == 2
    err = capsys.readouterr().err
    assert "--home: given joint values is a self-collision of robot 'boxes': base/a (URDF " \
           "collision geometry overlapping by 2.0 mm" in err and not out.exists()
    assert main(base + ["--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    hf = doc["home_fit"]
    assert hf["home_free"] and hf["home"] != [0.0] * 4
    assert ["base", "a"] in [p["links"] for r in hf["rejected"] for p in r["pairs"]]
    m = jwarp.robot(str(out))
    assert m.allowed_collision_pairs[m.frame_index("base"), m.frame_index("a")]
    assert ["base", "a"] not in [r["links"] for r in doc["skipped_pairs"]]
    assert _overlaps(m, hf["home"]) == {}
    # a free home: base/b (4 mm apart) tightened, still checked
    assert main(base + ["--home", "0,0.3,0,0", "--json"]) == 0
    hf = json.loads(capsys.readouterr().out)["home_fit"]
    assert hf["home_free"] and hf["home"] == [0.0, 0.3, 0.0, 0.0] and hf["rejected"] == []
    m = jwarp.robot(str(out))
    assert _overlaps(m, [0.0, 0.3, 0.0, 0.0]) == {}
    from jwarp.world.model_check import home_configurations, noted_home
    assert json.loads(m.notes["home"]) == [0.0, 0.3, 0.0, 0.0]
    assert noted_home(m).tolist() == [0.0, 0.3, 0.0, 0.0]
    assert home_configurations(m)[0][0] == "its home (notes.home)"
    assert noted_home(m.copy(notes={"home": "[1, 2]"})) is None    # not this robot's
    assert m.allowed_collision_pairs[m.frame_index("base"), m.frame_index("b")]
    for extra, match in ((["--home", "0,0"], "--home: expected 4 finite joint values"),
                         (["--home", "arm_up"], "--home: state 'arm_up' needs --srdf"),
                         (["--home", "0,x"], "--home: expected numbers"),
                         (["--home", "0,0,0,0", "--spheres", "none"], "--home: needs a "
                                                                       "collision model")):
        assert main(base + extra) == 2, extra
        assert match in capsys.readouterr().err
