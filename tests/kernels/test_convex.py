"""GJK lower bounds of jwarp.kernels.convex against coal's exact convex distances."""

import numpy as np
import pytest
import warp as wp
from scipy.spatial.transform import Rotation

from jwarp.kernels import convex as ck

try:
    import coal
except ImportError:  # the device machine: the closed-form tests still run
    coal = None


def _cloud(rng, n, centre, size):
    p = rng.normal(size=(n, 3))
    p *= size * rng.uniform(0.2, 1.0, (n, 1)) / np.linalg.norm(p, axis=1, keepdims=True)
    return p + centre


def _tables(pieces, rads):
    verts = np.concatenate(pieces)
    start = np.cumsum([0] + [len(p) for p in pieces]).astype(np.int32)
    centre = np.array([(p.max(0) + p.min(0)) / 2 for p in pieces])
    bound = np.array([np.linalg.norm(p - c, axis=1).max() + r
                      for p, c, r in zip(pieces, centre, rads)])
    return verts, start, centre, bound


def _boxes(pieces, scalar=wp.float64):
    """The broad phase's object boxes of world_lower: axis-aligned about the centre of
    :func:`_tables` (rot (O, 3, 3) identities, half extents (O, 3))."""
    half = np.array([(p.max(0) - p.min(0)) / 2 for p in pieces])
    return np.tile(np.eye(3), (len(pieces), 1, 1)), half


def _coal_convex(points):
    v = coal.StdVec_Vec3s()
    for p in points:
        v.append(np.asarray(p, np.float64))
    if len(points) < 4:  # coal needs a solid: a tiny tetrahedron-free set -> spheres
        return None
    return coal.Convex.convexHull(v, False, "")


def _coal_distance(a, Ta, b, Tb):
    req, res = coal.DistanceRequest(), coal.DistanceResult()
    return coal.distance(a, coal.Transform3s(Ta[:3, :3], Ta[:3, 3]), b,
                         coal.Transform3s(Tb[:3, :3], Tb[:3, 3]), req, res)


@pytest.mark.parametrize("scalar", [wp.float32, wp.float64])
def test_world_and_self_bounds_match_coal(device, scalar):
    if coal is None:
        pytest.skip("coal is not installed")
    rng = np.random.default_rng(3)
    npdt = np.float32 if scalar == wp.float32 else np.float64
    K_, O_ = 12, 10
    pieces = [_cloud(rng, int(rng.integers(4, 80)), rng.uniform(-0.3, 0.3, 3),
                     rng.uniform(0.02, 0.15)) for _ in range(K_)]
    objs = [_cloud(rng, int(rng.integers(4, 80)), rng.uniform(-0.4, 0.4, 3),
                   rng.uniform(0.02, 0.2)) for _ in range(O_)]
    rads = rng.choice([0.0, 0.01], K_)
    orads = rng.choice([0.0, 0.02], O_)
    v, s, c, b = _tables(pieces, rads)
    ov, os_, oc, ob = _tables(objs, orads)
    N, n_frames = 4, 2
    frame = rng.integers(0, n_frames, K_).astype(np.int32)
    X = np.tile(np.eye(4), (N, n_frames, 1, 1))
    for i in range(N):
        for f in range(n_frames):
            X[i, f, :3, :3] = Rotation.random(random_state=10 * i + f).as_matrix()
            X[i, f, :3, 3] = rng.uniform(-0.1, 0.1, 3)
    K = ck.kernels(scalar)

    def arr(x, dt):
        return wp.array(np.ascontiguousarray(x), dtype=dt, device=device)

    tab = [arr(frame, wp.int32), arr(s, wp.int32), arr(v.astype(npdt), K.vec3),
           arr(rads.astype(npdt), scalar), arr(c.astype(npdt), K.vec3),
           arr(b.astype(npdt), scalar)]
    Xw = wp.array(X.astype(npdt), dtype=K.mat44, device=device)
    slack = 2e-5 if scalar == wp.float32 else 1e-9
    out = wp.full((N, K_), 1e9, dtype=scalar, device=device)
    wp.launch(K.world_lower, dim=(N, K_, O_),
              inputs=[*tab, arr(np.zeros(O_, np.int32), wp.int32), arr(os_, wp.int32),
                      arr(ov.astype(npdt), K.vec3), arr(orads.astype(npdt), scalar),
                      arr(oc.astype(npdt), K.vec3), arr(ob.astype(npdt), scalar),
                      arr(np.zeros(O_, np.int32), wp.int32),
                      arr(_boxes(objs)[0].astype(npdt), wp.types.matrix((3, 3), scalar)),
                      arr(_boxes(objs)[1].astype(npdt), K.vec3),
                      arr(np.zeros(1, np.int32), wp.int32), Xw,
                      arr(np.zeros(N, np.int32), wp.int32), 0, arr(np.full(N, 1e9, npdt), scalar),
                      scalar(1e-7),
                      scalar(slack)], outputs=[out], device=device)
    got = out.numpy().astype(np.float64)
    qa = rng.integers(0, K_, 30).astype(np.int32)
    qb = rng.integers(0, K_, 30).astype(np.int32)
    out2 = wp.empty((N, 30), dtype=scalar, device=device)
    wp.launch(K.self_lower, dim=(N, 30),
              inputs=[*tab, arr(qa, wp.int32), arr(qb, wp.int32), Xw, arr(np.full(N, 1e9, npdt), scalar),
                      scalar(1e-7), scalar(slack)], outputs=[out2], device=device)
    got2 = out2.numpy().astype(np.float64)
    cp = [_coal_convex(p) for p in pieces]
    co = [_coal_convex(p) for p in objs]
    eye = np.eye(4)
    tol = 5e-5 if scalar == wp.float32 else 1e-6
    n_sep = 0
    for i in range(N):
        for k in range(K_):
            ref = min(_coal_distance(cp[k], X[i, frame[k]], co[o], eye) - rads[k] - orads[o]
                      for o in range(O_))
            assert got[i, k] <= max(ref, 0.0) + 1e-9 + (slack if ref > 0 else 0), (i, k)
            if ref > 1e-4:
                n_sep += 1
                assert got[i, k] >= ref - tol, (i, k, got[i, k], ref)
        for q in range(30):
            a, bb = qa[q], qb[q]
            ref = _coal_distance(cp[a], X[i, frame[a]], cp[bb], X[i, frame[bb]]) - rads[a] - rads[bb]
            assert got2[i, q] <= max(ref, 0.0) + 1e-9, (i, q)
            if ref > 1e-4:
                assert got2[i, q] >= ref - tol, (i, q, got2[i, q], ref)
    assert n_sep > 10  # the test saw separated pieces, not only overlaps


def test_halfspace_is_exact(device):
    """A box's corners against the plane z <= 0.1: the lowest corner's height."""
    K = ck.kernels(wp.float64)
    h = np.array([0.1, 0.2, 0.3])
    corners = np.array([[x, y, z] for x in (-h[0], h[0]) for y in (-h[1], h[1])
                        for z in (-h[2], h[2])])
    R = Rotation.from_rotvec([0.4, -0.2, 0.3]).as_matrix()
    X = np.eye(4)[None, None].copy()
    X[0, 0, :3, :3], X[0, 0, :3, 3] = R, [0.0, 0.0, 0.8]

    def arr(x, dt):
        return wp.array(np.ascontiguousarray(x), dtype=dt, device=device)

    out = wp.full((1, 1), 1e9, dtype=wp.float64, device=device)
    wp.launch(K.world_lower, dim=(1, 1, 1),
              inputs=[arr(np.zeros(1, np.int32), wp.int32), arr([0, 8], wp.int32),
                      arr(corners, K.vec3), arr([0.0], wp.float64), arr(np.zeros((1, 3)), K.vec3),
                      arr([np.linalg.norm(h)], wp.float64), arr([int(ck.HALFSPACE)], wp.int32),
                      arr([0, 1], wp.int32), arr(np.zeros((1, 3)), K.vec3), arr([0.0], wp.float64),
                      arr([[0.0, 0.0, 1.0]], K.vec3), arr([0.1], wp.float64),
                      arr([0], wp.int32), arr(np.eye(3)[None], wp.types.matrix((3, 3), wp.float64)),
                      arr(np.zeros((1, 3)), K.vec3), arr(np.zeros(1, np.int32), wp.int32),
                      wp.array(X, dtype=K.mat44, device=device),
                      arr([0], wp.int32), 0, arr([1.0], wp.float64), wp.float64(1e-9),
                      wp.float64(0.0)], outputs=[out], device=device)
    want = (corners @ R.T)[:, 2].min() + 0.8 - 0.1
    assert abs(out.numpy()[0, 0] - want) < 1e-12


def _launch_world(device, pieces, rads, objs, orads, X, frame, cap=1e9, boxes=None,
                  o_group=None, cfg_group=None, mode=0):
    K = ck.kernels(wp.float64)
    v, s, c, b = _tables(pieces, rads)
    ov, os_, oc, ob = _tables(objs, orads)
    rot, half = _boxes(objs) if boxes is None else boxes[1:]
    if boxes is not None:
        oc = boxes[0]

    def arr(x, dt):
        return wp.array(np.ascontiguousarray(x), dtype=dt, device=device)

    N, K_, O_ = len(X), len(pieces), len(objs)
    og = np.zeros(O_, np.int32) if o_group is None else np.asarray(o_group, np.int32)
    cg = np.zeros(N, np.int32) if cfg_group is None else np.asarray(cfg_group, np.int32)
    first = np.searchsorted(og, np.arange(og.max() + 2)).astype(np.int32)
    span = O_ if mode != 2 else int(np.diff(first).max())
    out = wp.full((N, K_), 1e9, dtype=wp.float64, device=device)
    wp.launch(K.world_lower, dim=(N, K_, span),
              inputs=[arr(frame, wp.int32), arr(s, wp.int32), arr(v, K.vec3),
                      arr(np.asarray(rads, np.float64), wp.float64), arr(c, K.vec3),
                      arr(b, wp.float64), arr(np.zeros(O_, np.int32), wp.int32),
                      arr(os_, wp.int32), arr(ov, K.vec3),
                      arr(np.asarray(orads, np.float64), wp.float64), arr(oc, K.vec3),
                      arr(ob, wp.float64), arr(og, wp.int32),
                      arr(rot, wp.types.matrix((3, 3), wp.float64)),
                      arr(half, K.vec3), arr(first, wp.int32),
                      wp.array(X, dtype=K.mat44, device=device),
                      arr(cg, wp.int32), mode, arr(np.full(N, float(cap)), wp.float64),
                      wp.float64(1e-9), wp.float64(0.0)], outputs=[out], device=device)
    return out.numpy()


def test_closed_forms_spheres_and_boxes(device):
    """Spheres (one vertex + radius): |c1 - c2| - r1 - r2; a unit cube against cubes
    beside it along x, y, z and at a corner: the gaps, the corner distance sqrt(3) gap."""
    rng = np.random.default_rng(5)
    X = np.tile(np.eye(4), (3, 1, 1, 1))
    X[1, 0, :3, 3] = [0.2, -0.1, 0.05]
    X[2, 0, :3, :3] = Rotation.from_rotvec([0.0, 0.0, 0.7]).as_matrix()
    centres = rng.uniform(-1, 1, (5, 3))
    radii = rng.uniform(0.05, 0.2, 5)
    oc = rng.uniform(-1, 1, (4, 3))
    orad = rng.uniform(0.05, 0.2, 4)
    got = _launch_world(device, [c[None] for c in centres], radii, [c[None] for c in oc],
                        orad, X, np.zeros(5, np.int32))
    for i in range(3):
        w = centres @ X[i, 0, :3, :3].T + X[i, 0, :3, 3]
        ref = (np.linalg.norm(w[:, None] - oc[None], axis=2) - radii[:, None] - orad[None]).min(1)
        assert np.allclose(got[i], ref, atol=1e-12)
    cube = np.array([[x, y, z] for x in (-.5, .5) for y in (-.5, .5) for z in (-.5, .5)])
    gap = 0.0123
    objs = [cube + [1 + gap, 0, 0], cube + [0, -1 - gap, 0], cube + [0, 0, 1 + gap],
            cube + [1 + gap, 1 + gap, 1 + gap]]
    Xi = np.eye(4)[None, None]
    for o, want in zip(objs, [gap, gap, gap, np.sqrt(3) * gap]):
        got = _launch_world(device, [cube], [0.0], [o], [0.0], Xi, np.zeros(1, np.int32))
        assert abs(got[0, 0] - want) < 1e-9, (got, want)
    # overlapping cubes: a bound <= 0
    got = _launch_world(device, [cube], [0.0], [cube + 0.3], [0.0], Xi, np.zeros(1, np.int32))
    assert got[0, 0] <= 0.0


def test_box_broad_phase_and_cap(device):
    """A thin rotated plank (1 m x 0.3 m x 2 cm) against spheres around it, with a cap of
    5 cm: every bound is at most the exact sphere-to-box distance, and at least the
    distance or the cap, whichever is less (a piece the object's box keeps beyond the cap
    is not refined; GJK stops at the cap). Closed form: the point-box distance in the
    plank's frame."""
    rng = np.random.default_rng(11)
    h = np.array([0.5, 0.15, 0.01])
    R = Rotation.from_rotvec([0.3, -0.5, 0.9]).as_matrix()
    c0 = np.array([0.1, -0.2, 0.4])
    corners = np.array([[x, y, z] for x in (-h[0], h[0]) for y in (-h[1], h[1])
                        for z in (-h[2], h[2])]) @ R.T + c0
    n = 200
    local = rng.uniform(-1, 1, (n, 3)) * (h + 0.12)
    centres = local @ R.T + c0
    radii = rng.uniform(0.005, 0.05, n)
    frame = np.zeros(n, np.int32)
    X = np.eye(4)[None, None].copy()
    cap = 0.05
    got = _launch_world(device, [p[None] for p in centres], radii, [corners], [0.0], X,
                        frame, cap=cap, boxes=(c0[None], R[None], h[None]))[0]
    box_d = np.linalg.norm(np.maximum(np.abs(local) - h, 0.0), axis=1)
    inside = (np.abs(local) <= h).all(axis=1)
    true = np.where(inside, 0.0, box_d) - radii
    assert (got <= np.maximum(true, 0.0) + 1e-9).all()
    assert (got >= np.minimum(true, cap) - 1e-7).all()
    far, near = true > cap + 1e-3, (true > 0) & (true < cap - 1e-3)
    assert far.sum() > 20 and near.sum() > 10
    # the enclosing spheres alone would not cull: the plank's sphere holds every piece
    assert (np.linalg.norm(centres - c0, axis=1) - radii < np.linalg.norm(h)).sum() > 0.5 * n


def test_groups_sorted_span_equals_group_filter(device):
    """A batch of worlds: objects sorted by world (group), each configuration in one world.
    The ranged launch (use_groups 2: o_first, the largest world's object count) gives the
    bounds of the filtering launch (1: every object, foreign ones skipped), and both equal
    the bounds against the configuration's own objects alone (closed form: spheres)."""
    rng = np.random.default_rng(11)
    pieces = [np.zeros((1, 3)), np.zeros((1, 3))]
    rads = [0.05, 0.08]
    objs = [rng.uniform(-1, 1, (1, 3)) for _ in range(7)]
    orads = list(rng.uniform(0.02, 0.1, 7))
    o_group = [0, 0, 0, 1, 2, 2, 2]          # world 1 has one object, world 2 three
    X = np.tile(np.eye(4), (5, 2, 1, 1))
    X[:, :, :3, 3] = rng.uniform(-0.5, 0.5, (5, 2, 3))
    cfg_group = [2, 0, 1, 2, 0]
    frame = [0, 1]
    got1 = _launch_world(device, pieces, rads, objs, orads, X, frame, o_group=o_group,
                         cfg_group=cfg_group, mode=1)
    got2 = _launch_world(device, pieces, rads, objs, orads, X, frame, o_group=o_group,
                         cfg_group=cfg_group, mode=2)
    np.testing.assert_array_equal(got1, got2)
    for c, g in enumerate(cfg_group):
        own = [i for i, gi in enumerate(o_group) if gi == g]
        for k in range(2):
            want = min(np.linalg.norm(X[c, k, :3, 3] - objs[i][0]) - rads[k] - orads[i]
                       for i in own)
            assert abs(got2[c, k] - want) < 1e-9
