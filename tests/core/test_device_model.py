"""The device Model (jwarp/core/device.py put_model), the typed DH rows (jwarp/core/rows.py)
and the Data workspaces (CollisionData): one cache keyed by robot content, every
table against the RobotModel (numpy), workspaces reused by identity, rows validated."""

import dataclasses

import numpy as np
import pytest
import warp as wp
from reference import coupling_matrix, nominal_dh, parent_first_order, prismatic_mask, ref_fk
from worlds import block_world

import jwarp
from jwarp.core import device as D
from jwarp.core.device import collision_tables, content_key, put_model
from jwarp.core.limits import sample_within_limits
from jwarp.core.rows import PER_CONFIG_LAYOUT, DHRows, RowsKind
from jwarp.kernels import fk as fk_kernels
from jwarp.kinematics.compensation import CompensationRows
from jwarp.model import RobotModel
from jwarp.world import collision
from jwarp.world.collision import CollisionData, CollisionModel

ROBOTS = ["justin19", "arm7", "planar4", "hand4", "sphere2d"]


# ================================================================ the cache
def test_equal_robots_share_one_model_and_edited_copies_do_not():
    r = jwarp.robot("arm7")
    m = put_model(r, "cpu", np.float32)
    twin = RobotModel.from_dict(r.to_dict())  # another object, equal content
    assert twin is not r and content_key(twin) == content_key(r)
    assert put_model(twin, "cpu", np.float32) is m
    assert put_model(jwarp.robot("arm7"), "cpu", "float32") is m
    assert put_model(twin, "cpu", wp.float32).limits is m.limits
    # another dtype: another model
    m64 = put_model(r, "cpu", np.float64)
    assert m64 is not m and m64.scalar == wp.float64 and m.scalar == wp.float32
    assert m64.key == m.key
    # changed DH rows: new tables with the new rows (no stale cache)
    dh = r.dh_table.copy()
    dh[2, 2] += 0.125
    edited = r.with_dh(dh)
    me = put_model(edited, "cpu", np.float32)
    assert me is not m and me.key != m.key
    np.testing.assert_allclose(me.dh0.numpy()[2, 2], dh[2, 2], rtol=1e-7)
    np.testing.assert_allclose(m.dh0.numpy()[2, 2], r.dh_table[2, 2], rtol=1e-7)
    # gravity, masses and compliances are content too
    g = dataclasses.replace(r, gravity=np.array([0.0, 0.0, -3.7]))
    assert put_model(g, "cpu", np.float32) is not m
    assert put_model(g, "cpu", np.float32).gravity[2] == np.float32(-3.7)
    heavy = r.with_masses([2.0 * x.mass for x in r.masses])
    assert put_model(heavy, "cpu", np.float32).key != m.key
    soft = r.copy(kappa=np.full((r.n_frames, 3), 1e-3) * r.is_dh[:, None])
    assert content_key(soft) != content_key(r)


def test_a_model_in_use_stays_the_one_model_of_its_content():
    """Past the recently-used list a model is kept while anything holds it."""
    base = jwarp.robot("planar4")
    held = put_model(base, "cpu", np.float64)
    for k in range(D._RECENT_MAX + 3):  # push it out of the recently-used list
        put_model(base.with_dh(base.dh_table + 1e-3 * (k + 1) * base.is_dh[:, None]), "cpu",
                  np.float64)
    assert put_model(RobotModel.from_dict(base.to_dict()), "cpu", np.float64) is held


def test_collision_models_share_the_device_model_of_equal_robots():
    r = jwarp.robot("arm7")
    twin = RobotModel.from_dict(r.to_dict())
    a = collision.collision_model(r, None, device="cpu", dtype=np.float64)
    b = collision.collision_model(twin, None, device="cpu", dtype=np.float64)
    assert a is b and a.model is put_model(r, "cpu", np.float64)
    c = CollisionModel(twin, None, device="cpu", dtype=np.float64)
    assert c.model is a.model and c.model_args[1] is a.model_args[1]


# ================================================================ tables vs the RobotModel
def _rot_y_rot_x(a, b):
    ca, sa, cb, sb = np.cos(a), np.sin(a), np.cos(b), np.sin(b)
    Ry = np.array([[cb, 0, sb], [0, 1, 0], [-sb, 0, cb]])
    Rx = np.array([[1, 0, 0], [0, ca, -sa], [0, sa, ca]])
    return Ry @ Rx


@pytest.mark.parametrize("name", ROBOTS)
def test_every_table_matches_the_robot(name):
    r = jwarp.robot(name)
    m = put_model(r, "cpu", np.float64)
    n = r.n_frames
    parents = np.array([-1 if f.parent is None else f.parent for f in r.frames])
    # frames
    order = m.order.numpy()
    assert sorted(order.tolist()) == list(range(n))
    pos = np.empty(n, int)
    pos[order] = np.arange(n)
    assert all(pos[parents[i]] < pos[i] for i in range(n) if parents[i] >= 0)
    assert order.tolist() == r.topological_order.tolist()
    assert set(order.tolist()) == set(parent_first_order(r))
    np.testing.assert_array_equal(m.parent.numpy(), parents)
    is_dh = np.array([f.kind == "dh" for f in r.frames])
    np.testing.assert_array_equal(m.is_dh.numpy(), is_dh.astype(np.int32))
    np.testing.assert_array_equal(m.prismatic.numpy(), prismatic_mask(r).astype(np.int32))
    dh = nominal_dh(r)
    np.testing.assert_array_equal(m.dh0.numpy(), dh)
    np.testing.assert_array_equal(m.dh0_3d.numpy(), dh[None])
    np.testing.assert_allclose(m.trig.numpy(), np.stack(
        [np.cos(dh[:, 3]), np.sin(dh[:, 3]), np.cos(dh[:, 4]), np.sin(dh[:, 4])], 1), atol=1e-15)
    rot, p = m.fixed_rot.numpy(), m.fixed_pos.numpy()
    for i, f in enumerate(r.frames):
        if f.kind == "dh":
            R = _rot_y_rot_x(dh[i, 3], dh[i, 4])
            np.testing.assert_allclose(rot[i], R, atol=1e-15)
            np.testing.assert_allclose(p[i], dh[i, 2] * R[:, 0], atol=1e-15)
        else:
            np.testing.assert_allclose(rot[i], f.transform[:3, :3], atol=1e-15)
            np.testing.assert_allclose(p[i], f.transform[:3, 3], atol=1e-15)
    # coupling CSR == the coupling matrix
    start, joint, coef = m.cpl_start.numpy(), m.cpl_joint.numpy(), m.cpl_coef.numpy()
    C = np.zeros((n, r.n_dof))
    for i in range(n):
        for k in range(start[i], start[i + 1]):
            C[i, joint[k]] += coef[k]
    np.testing.assert_allclose(C, coupling_matrix(r), atol=0)
    # masses merged per frame, centre of mass weighted
    mass = np.zeros(n)
    mom = np.zeros((n, 3))
    for x in r.masses:
        mass[x.frame] += x.mass
        mom[x.frame] += x.mass * np.asarray(x.com)
    np.testing.assert_allclose(m.mass.numpy(), mass, rtol=1e-15)
    com = m.mass_com.numpy()
    on = mass > 0
    np.testing.assert_allclose(com[on], mom[on] / mass[on, None], rtol=1e-12, atol=1e-15)
    assert np.all(com[~on] == 0)
    info = m.dh_info.numpy()
    assert info[:, 1].tolist() == [i for i in order if is_dh[i]]
    for k, i, end, par in info:
        assert order[k] == i and par == parents[i]
        sub = {int(j) for j in order[k:end]}
        desc = {j for j in range(n) if i in r.ancestors(j)}
        assert sub == desc
    np.testing.assert_array_equal(m.static_idx.numpy(), np.nonzero(~is_dh)[0])
    # gravity, default compliances
    np.testing.assert_array_equal(np.array(m.gravity), r.gravity)
    np.testing.assert_array_equal(m.kappa.numpy(), r.kappa[None])
    # limits: box and linear CSR
    np.testing.assert_array_equal(m.limits.box.numpy(),
                                  [[j.lower, j.upper] for j in r.joints])
    ls, lj, lc, lb = (getattr(m.limits, k).numpy() for k in ("lin_start", "lin_joint", "lin_coef",
                                                           "lin_bounds"))
    assert len(ls) == len(r.linear_limits) + 1
    for k, lim in enumerate(r.linear_limits):
        assert lj[ls[k]:ls[k + 1]].tolist() == list(lim.joints)
        np.testing.assert_array_equal(lc[ls[k]:ls[k + 1]], lim.coefficients)
        np.testing.assert_array_equal(lb[k], [lim.lower, lim.upper])
    # the nominal rows
    assert m.nominal_rows.kind == RowsKind.NOMINAL and m.nominal_rows.array is m.dh0_3d
    assert m.nominal_rows is m.nominal_rows


@pytest.mark.parametrize("name", ROBOTS)
def test_sphere_tables_match_the_robot(name):
    r = jwarp.robot(name)
    m = put_model(r, "cpu", np.float64)
    sp = m.spheres
    assert sp is m.spheres  # built once
    f, p, rad = r.sphere_arrays()
    assert sp.n_spheres == len(f) and sp.sph_frame.shape[0] == len(f)
    if len(f):
        np.testing.assert_array_equal(sp.sph_frame.numpy(), f)
        np.testing.assert_array_equal(sp.sph_pos.numpy(), p)
        np.testing.assert_array_equal(sp.sph_rad.numpy(), rad)
        # every frame's bounding sphere encloses its spheres
        bp, br = sp.bound_pos.numpy(), sp.bound_rad.numpy()
        for i in range(r.n_frames):
            on = f == i
            if on.any():
                assert np.all(np.linalg.norm(p[on] - bp[i], axis=1) + rad[on] <= br[i] + 1e-12)
            else:
                assert br[i] < 0
    # pairs: the allowed sphere pairs, less the rigid ones, each once, lower frame first
    allowed = r.allowed_collision_pairs
    cand = {(a, b) for a in range(len(f)) for b in range(len(f))
            if f[a] < f[b] and allowed[f[a], f[b]]}
    rigid = {tuple(x) for x in sp.rigid_pairs.tolist()}
    assert {tuple(x) for x in sp.pairs.tolist()} == cand - rigid and len(sp.pairs) == sp.n_pairs
    np.testing.assert_array_equal(collision.collision_pairs(r), sp.pairs)
    # the kernel's CSR walks exactly these pairs
    if sp.n_pairs:
        fa, fb, fs = sp.fpair_a.numpy(), sp.fpair_b.numpy(), sp.fpair_start.numpy()
        es, est, pb = sp.ent_sphere.numpy(), sp.ent_start.numpy(), sp.pair_b.numpy()
        walked = []
        for k in range(len(fa)):
            for e in range(fs[k], fs[k + 1]):
                assert f[es[e]] == fa[k]
                for q in range(est[e], est[e + 1]):
                    assert f[pb[q]] == fb[k]
                    walked.append((int(es[e]), int(pb[q])))
        assert walked == [tuple(x) for x in sp.pairs.tolist()]
    # rigid pairs: their distance is the same at random configurations (numpy FK)
    if len(sp.rigid_pairs):
        q = sample_within_limits(r, 8, np.random.default_rng(0))
        F = ref_fk(r, q)[:, f]
        x = np.einsum("bsij,sj->bsi", F[..., :3, :3], p) + F[..., :3, 3]
        a, b = sp.rigid_pairs[:, 0], sp.rigid_pairs[:, 1]
        d = np.linalg.norm(x[:, a] - x[:, b], axis=-1) - rad[a] - rad[b]
        np.testing.assert_allclose(d, np.broadcast_to(sp.rigid_distance, d.shape), atol=1e-9)
        assert np.all(sp.rigid_distance > 0)
    # float32 tables on the same device come from the same host tables
    m32 = put_model(r, "cpu", np.float32)
    np.testing.assert_array_equal(m32.spheres.pairs, sp.pairs)
    assert collision_tables(r) is collision_tables(RobotModel.from_dict(r.to_dict()))


@pytest.mark.parametrize("name", ["justin19", "hand4"])
def test_fk_from_the_model_tables_matches_numpy(device, name):
    r = jwarp.robot(name)
    m = put_model(r, device, np.float64)
    q = sample_within_limits(r, 16, np.random.default_rng(1))
    k = fk_kernels.kernels(wp.float64)
    frames = wp.empty((16, r.n_frames), dtype=k.mat44, device=device)
    wp.launch(k.fk, dim=16, inputs=[m.frame_struct, wp.array(q, dtype=wp.float64, device=device),
                                    *m.nominal_rows.args],
              outputs=[frames], device=device)
    np.testing.assert_allclose(frames.numpy(), ref_fk(r, q), atol=1e-12)


@pytest.mark.parametrize("name", sorted(jwarp.robots()))
def test_host_frames_match_numpy(name):
    """The host FK that builds the sphere tables (no Warp CPU compiler needed)."""
    r = jwarp.robot(name)
    q = sample_within_limits(r, 8, np.random.default_rng(2))
    np.testing.assert_allclose(D.host_frames(r, q), ref_fk(r, q), atol=1e-12)


def test_frame_masses_copy_shares_every_other_table():
    m = put_model(jwarp.robot("justin19"), "cpu", np.float64)
    _ = m.frame_struct, m.spheres
    mass, com = D.frame_mass_model(m.robot)
    c = D.with_frame_masses(m, 2 * mass, com)
    np.testing.assert_array_equal(c.mass.numpy(), 2 * mass)
    assert c.dh0 is m.dh0 and c.limits is m.limits and c.frame_struct is m.frame_struct
    assert c.spheres is m.spheres and c.mass is not m.mass
    assert put_model(jwarp.robot("justin19"), "cpu", np.float64) is m  # the copy is not cached


# ================================================================ Data workspaces
def test_collision_data_is_reused_and_gives_the_same_numbers():
    r = jwarp.robot("justin19")
    cm = collision.collision_model(r, block_world(), device="cpu", dtype=np.float64)
    q = sample_within_limits(r, 40, np.random.default_rng(2))
    qw = wp.array(q, dtype=wp.float64, device="cpu")
    c_ref, g_ref = (a.numpy() for a in cm.cost(qw))
    _, _, md_ref = cm.distances(qw)
    assert np.any(c_ref > 0)
    d = cm.make_data(40)
    assert isinstance(d, CollisionData)
    c1, g1 = cm.cost(qw, data=d)
    scratch = d.scratch
    c2, g2 = cm.cost(qw, data=d)
    assert c1 is c2 is d.cost and g1 is g2 is d.grad  # no new allocation
    assert all(a is b for a, b in zip(scratch, d.scratch))
    np.testing.assert_array_equal(c2.numpy(), c_ref)
    np.testing.assert_array_equal(g2.numpy(), g_ref)
    sd1, pd1, md1 = cm.distances(qw, spheres=True, pairs=True, data=d)
    sd2, pd2, md2 = cm.distances(qw, spheres=True, pairs=True, data=d)
    assert sd1 is sd2 is d.sphere_dist and pd1 is pd2 is d.pair_dist and md1 is md2 is d.min_dist
    np.testing.assert_array_equal(md2.numpy(), md_ref.numpy())
    # without a data the model's own scratch is reused too
    s1 = cm.scratch(40)
    s2 = cm.scratch(40)
    assert all(a is b for a, b in zip(s1, s2))
    # a data of another size, dtype or model is refused
    with pytest.raises(ValueError, match="data"):
        cm.cost(qw[:10], data=d)
    with pytest.raises(TypeError, match="data"):
        cm.cost(qw, data=object())
    other = collision.collision_model(r, None, device="cpu", dtype=np.float32)
    with pytest.raises(ValueError, match="data"):
        other.cost(wp.array(q, dtype=wp.float32, device="cpu"), data=d)


def test_compensation_rows_as_typed_rows():
    r = jwarp.robot("justin19")
    t = put_model(r, "cpu", np.float64)
    rows = CompensationRows(t, 2, 3, 4, 1e-3, 0.5)
    a = rows.dh_rows
    assert a.kind == RowsKind.COMPENSATION and a.array is rows.rows and a.layout == rows.layout
    assert rows.dh_rows is a  # one value per buffer
    # the model's default compliances and gravity are used as they are
    own = CompensationRows(t, 1, 2, 1, None, 0.5)
    assert own.kappa is t.kappa and own.gravity == t.gravity
    # rows of an equal robot object are accepted by the collision model (content key)
    twin_t = put_model(RobotModel.from_dict(r.to_dict()), "cpu", np.float64)
    assert twin_t is t
    cm = collision.collision_model(RobotModel.from_dict(r.to_dict()), None, device="cpu",
                                   dtype=np.float64)
    q = wp.array(sample_within_limits(r, rows.N, np.random.default_rng(3)), dtype=wp.float64,
                 device="cpu")
    c, _ = cm.cost(q, rho=rows)
    c_dh, _ = cm.cost(q, rho=a)  # the typed value itself
    np.testing.assert_array_equal(c.numpy(), c_dh.numpy())
    with pytest.raises(ValueError, match="rho"):
        cm.cost(q[:3], rho=rows)


# ================================================================ DHRows
def _arr(shape, dt=wp.float64):
    return wp.zeros(shape, dtype=dt, device="cpu")


def test_rows_kind_values_are_the_kernels_constants():
    assert int(RowsKind.NOMINAL) == fk_kernels.ROWS_NOMINAL == 0
    assert int(RowsKind.DH) == fk_kernels.ROWS_DH == 1
    assert int(RowsKind.COMPENSATION) == fk_kernels.ROWS_COMPENSATION == 2


def test_dh_rows_constructors():
    n = put_model(jwarp.robot("arm7"), "cpu", np.float64)
    nom = DHRows.nominal(n.dh0_3d)
    assert nom.args == (n.dh0_3d, 0, 0) and nom.layout == PER_CONFIG_LAYOUT and nom.is_nominal
    sh = DHRows.shared(_arr((n.n_frames, 5)))
    assert sh.kind == RowsKind.DH and sh.stride == 0 and sh.count == 1 and sh.array.ndim == 3
    pc = DHRows.per_config(_arr((6, n.n_frames, 5)), n=6)
    assert pc.args[1:] == (1, 1) and pc.count == 6 and pc.n_frames == n.n_frames
    cp = DHRows.compensation(_arr((2 * 3, n.n_frames, 9)), (9, 4, 3, 2))
    assert cp.args[1:] == (1, 2) and cp.layout == (9, 4, 3, 2)
    v = cp.layout_vec
    assert tuple(v) == (9, 4, 3, 2) and cp.layout_vec is v
    assert DHRows.compensation(_arr((6, n.n_frames, 9)), (9, 4, 3, 0)).layout[3] == 0
    assert DHRows(1, _arr((1, 4, 5)), 0).kind is RowsKind.DH  # plain ints are read as kinds
    assert pc.check(n.n_frames, 6, wp.float64, "cpu") is pc


@pytest.mark.parametrize("make, error, match", [
    (lambda: DHRows.nominal(_arr((2, 7, 5))), ValueError, "nominal"),
    (lambda: DHRows(RowsKind.NOMINAL, _arr((1, 7, 5)), 1), ValueError, "nominal"),
    (lambda: DHRows.shared(_arr((3, 7, 5))), ValueError, "shared"),
    (lambda: DHRows.shared(_arr((7, 9))), ValueError, "5\\)"),
    (lambda: DHRows.per_config(_arr((4, 7, 9))), ValueError, "DH rows need"),
    (lambda: DHRows.per_config(_arr((4, 7, 5)), n=5), ValueError, "5 configurations"),
    (lambda: DHRows.per_config(_arr((4, 7, 5), wp.int32)), TypeError, "float"),
    (lambda: DHRows.per_config(np.zeros((4, 7, 5))), TypeError, "warp array"),
    (lambda: DHRows.compensation(_arr((6, 7, 5)), (9, 4, 3, 2)), ValueError, "9\\)"),
    (lambda: DHRows.compensation(_arr((6, 7, 9)), (8, 4, 3, 2)), ValueError, "S = 8"),
    (lambda: DHRows.compensation(_arr((5, 7, 9)), (9, 4, 3, 2)), ValueError, "6 rows"),
    (lambda: DHRows.compensation(_arr((6, 7, 9)), (9, 4, 3)), ValueError, "layout"),
    (lambda: DHRows.compensation(_arr((6, 7, 9)), (9, 0, 3, 2)), ValueError, "layout"),
    (lambda: DHRows(RowsKind.DH, _arr((4, 7, 5)), 1, (9, 4, 3, 0)), ValueError, "waypoint"),
    (lambda: DHRows(RowsKind.DH, _arr((4, 7, 5)), 2), ValueError, "stride"),
    (lambda: DHRows(RowsKind.DH, _arr((4, 7, 5)), True), ValueError, "stride"),
    (lambda: DHRows(3, _arr((4, 7, 5)), 1), ValueError, "RowsKind"),
    (lambda: DHRows.per_config(_arr((4, 7, 5))).check(8, 4, wp.float64, "cpu"), ValueError,
     "frames"),
    (lambda: DHRows.per_config(_arr((4, 7, 5))).check(7, 5, wp.float64, "cpu"), ValueError,
     "4 configurations"),
    (lambda: DHRows.per_config(_arr((4, 7, 5))).check(7, 4, wp.float32, "cpu"), TypeError,
     "float32"),
])
def test_dh_rows_are_validated(make, error, match):
    with pytest.raises(error, match=match):
        make()


def test_collision_model_takes_every_kind_of_rows():
    """None, a numpy table, shared/per-configuration Warp rows and DHRows give the frames
    of those rows (costs equal to the expanded per-configuration rows)."""
    r = jwarp.robot("justin19")
    cm = collision.collision_model(r, block_world(), device="cpu", dtype=np.float64)
    q = sample_within_limits(r, 12, np.random.default_rng(4))
    qw = wp.array(q, dtype=wp.float64, device="cpu")
    dh = r.dh_table.copy()
    dh[r.is_dh.astype(bool), 3] += 0.01
    per = np.broadcast_to(dh, (12, r.n_frames, 5)).copy()
    c_per = cm.cost(qw, rho=per)[0].numpy()
    for rho in (dh, wp.array(dh, dtype=wp.float64, device="cpu"),
                DHRows.shared(wp.array(dh, dtype=wp.float64, device="cpu")),
                DHRows.per_config(wp.array(per, dtype=wp.float64, device="cpu"))):
        rows = cm.dh_rows(rho, 12)
        assert rows.kind == RowsKind.DH
        np.testing.assert_allclose(cm.cost(qw, rho=rho)[0].numpy(), c_per, rtol=1e-12, atol=1e-14)
    assert cm.dh_rows(None, 12) is cm.model.nominal_rows
    assert not np.allclose(cm.cost(qw)[0].numpy(), c_per)


def test_make_struct_names_unknown_and_missing_fields():
    """make_struct: a value that is no field of the struct (a typo) and a field neither the
    values nor the source give are TypeErrors naming them; a given value wins over the
    source's."""
    from jwarp.kernels import path as path_kernels

    m = put_model(jwarp.robot("justin19"), "cpu", np.float64)
    LT = path_kernels.kernels(m.scalar).LimitTables
    with pytest.raises(TypeError, match=r"bx: not a field .*box, lin_start"):
        D.make_struct(LT, m.limits, bx=None)
    with pytest.raises(TypeError, match="box: no value"):
        D.make_struct(LT)
    box = wp.zeros_like(m.limits.box)
    st = D.make_struct(LT, m.limits, box=box)
    assert st.box.ptr == box.ptr and st.lin_coef.ptr == m.limits.lin_coef.ptr
    assert D.struct_fields(LT) == ("box", "lin_start", "lin_joint", "lin_coef", "lin_bounds")
