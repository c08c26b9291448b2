"""RobotModel.collision_pieces (jwarp.model.collision_pieces): the JSON round trip, the
sphere digest (spheres appended later are extra, edited ones make the pieces untrusted),
the flat arrays, stamping, and validation errors naming the key and the index."""

from __future__ import annotations

import json

import numpy as np
import pytest

from jwarp.model import CollisionPieces, ConvexPiece, RobotModel, RobotModelError, Sphere
from jwarp.model.collision_pieces import (
    pieces_from_dict,
    pieces_to_dict,
    sphere_digest,
    stamp_pieces,
)

DOC = {
    "schema": "jwarp.robot", "version": 1, "name": "two",
    "joints": [{"name": "j0", "limits": [-1, 1]}, {"name": "j1", "limits": [-2, 2]}],
    "frames": [
        {"name": "base", "parent": None, "kind": "static", "transform": np.eye(4).tolist()},
        {"name": "l1", "parent": "base", "kind": "dh", "dh": [0.1, 0, 0, 0, 0], "joint": "j0"},
        {"name": "l2", "parent": "l1", "kind": "dh", "dh": [0, 0, 0.5, 0.2, 0], "joint": "j1"},
    ],
    "spheres": [{"frame": "l1", "position": [0.0, 0.0, 0.05], "radius": 0.06},
                {"frame": "l2", "position": [0.1, 0.0, 0.0], "radius": 0.05},
                {"frame": "l2", "position": [0.3, 0.0, 0.0], "radius": 0.04}],
}


def pieces_doc() -> dict:
    """The JSON object of three pieces: a box of l1, a capsule and a sphere of l2."""
    corners = [[x, y, z] for x in (-0.05, 0.05) for y in (-0.04, 0.04) for z in (0.0, 0.1)]
    return {"pieces": [{"frame": "l1", "vertices": corners, "radius": 0.0,
                        "source": "l1 <collision> 1 box"},
                       {"frame": "l2", "vertices": [[0.0, 0, 0], [0.4, 0, 0]], "radius": 0.03,
                        "source": "l2 <collision> 1 capsule"},
                       {"frame": "l2", "vertices": [[0.1 / 3, 1e-10, -2.5e-7]],
                        "radius": 0.02}],
            "sphere_count": 3, "sphere_digest": "", "method": "by hand"}


def model() -> RobotModel:
    """The robot with its pieces stamped for its three spheres."""
    m = RobotModel.from_dict(DOC)
    return stamp_pieces(m.copy(collision_pieces=pieces_from_dict(pieces_doc(),
                                                                 m.frame_names)))


def same_pieces(a: CollisionPieces, b: CollisionPieces) -> bool:
    return (len(a.pieces) == len(b.pieces)
            and all(p.frame == q.frame and np.array_equal(p.vertices, q.vertices)
                    and p.radius == q.radius and p.source == q.source
                    for p, q in zip(a.pieces, b.pieces))
            and (a.sphere_count, a.sphere_digest, a.method)
            == (b.sphere_count, b.sphere_digest, b.method))


def test_json_round_trip_keeps_the_pieces_exactly(tmp_path):
    m = model()
    cp = m.collision_pieces
    assert cp is not None and cp.sphere_count == 3 and len(cp.sphere_digest) == 64
    assert cp.pieces[0].vertices.shape == (8, 3) and cp.pieces[0].vertices.dtype == np.float64
    doc = m.to_dict()["collision_pieces"]
    assert doc["pieces"][1]["frame"] == "l2"             # frames by name
    assert set(doc) == {"pieces", "sphere_count", "sphere_digest", "method"}
    path = tmp_path / "two.json"
    m.save(path)
    back = RobotModel.load(path)
    assert back.collision_pieces is not None and same_pieces(back.collision_pieces, cp)
    assert same_pieces(m.copy().collision_pieces, cp)    # copy() keeps them
    assert back.collision_pieces.extra_spheres(back) == []   # the digest survives the file
    # a model without pieces writes no key and reads None
    plain = RobotModel.from_dict(DOC)
    assert plain.collision_pieces is None and "collision_pieces" not in plain.to_dict()
    # frames may be given by index too (docs/robot_schema.md)
    d = pieces_doc()
    d["pieces"][0]["frame"] = 1
    assert pieces_from_dict(d, plain.frame_names).pieces[0].frame == 1


def test_appended_spheres_are_extra_and_edited_ones_untrusted():
    m = model()
    cp = m.collision_pieces
    added = m.copy(spheres=list(m.spheres) + [Sphere(2, np.array([0.5, 0, 0]), 0.03)])
    assert added.collision_pieces.extra_spheres(added) == [3]
    assert cp.extra_spheres(added) == [3]
    saved = RobotModel.from_dict(json.loads(json.dumps(added.to_dict())))
    assert saved.collision_pieces.extra_spheres(saved) == [3]
    spheres = [Sphere(s.frame, s.position.copy(), s.radius) for s in m.spheres]
    spheres[1].radius = 0.049
    edited = m.copy(spheres=spheres)
    assert edited.collision_pieces.extra_spheres(edited) is None
    moved = m.copy(spheres=[Sphere(s.frame, s.position + [0, 0, 1e-12], s.radius)
                            for s in m.spheres])
    assert moved.collision_pieces.extra_spheres(moved) is None
    fewer = m.copy(spheres=list(m.spheres[:2]))
    assert fewer.collision_pieces.extra_spheres(fewer) is None
    # stamped again: the pieces stand for the edited spheres
    again = stamp_pieces(edited)
    assert again.collision_pieces.extra_spheres(again) == []
    assert again.collision_pieces.sphere_digest == sphere_digest(edited.spheres)
    assert same_pieces(CollisionPieces(again.collision_pieces.pieces, 3, cp.sphere_digest,
                                       cp.method), cp)
    assert stamp_pieces(RobotModel.from_dict(DOC)).collision_pieces is None


def test_sphere_digest_is_sha256_of_frames_positions_radii():
    import hashlib

    m = RobotModel.from_dict(DOC)
    f, p, r = m.sphere_arrays()
    h = hashlib.sha256(f.astype(np.int64).tobytes() + p.astype(np.float64).tobytes()
                       + r.astype(np.float64).tobytes()).hexdigest()
    assert sphere_digest(m.spheres) == h
    assert sphere_digest([]) == hashlib.sha256(b"").hexdigest()


def test_arrays_flatten_the_pieces_with_enclosing_spheres():
    cp = model().collision_pieces
    frame, vstart, vertices, radius, centre, bound = cp.arrays()
    assert frame.dtype == np.int32 and frame.tolist() == [1, 2, 2]
    assert vstart.dtype == np.int32 and vstart.tolist() == [0, 8, 10, 11]
    assert vertices.shape == (11, 3) and vertices.dtype == np.float64
    np.testing.assert_array_equal(vertices[8:10], cp.pieces[1].vertices)
    assert radius.tolist() == [0.0, 0.03, 0.02]
    np.testing.assert_allclose(centre[0], [0, 0, 0.05])
    np.testing.assert_allclose(centre[1], [0.2, 0, 0])
    np.testing.assert_allclose(bound, [np.linalg.norm([0.05, 0.04, 0.05]), 0.23, 0.02])
    for k in range(3):   # every vertex plus the radius lies within the bound
        v = vertices[vstart[k]:vstart[k + 1]]
        assert np.linalg.norm(v - centre[k], axis=1).max() + radius[k] <= bound[k] + 1e-15
    empty = CollisionPieces([], 0, sphere_digest([])).arrays()
    assert [a.shape for a in empty] == [(0,), (1,), (0, 3), (0,), (0, 3), (0,)]


@pytest.mark.parametrize("edit, match", [
    (lambda d: d["pieces"][3 - 3].update(vertices=[[0, 0]]),
     r"collision_pieces\.pieces\[0\]\.vertices: expected a list of \[x, y, z\]"),
    (lambda d: d["pieces"][1].update(vertices=[]),
     r"collision_pieces\.pieces\[1\]\.vertices: empty"),
    (lambda d: d["pieces"][1].update(vertices="abc"),
     r"collision_pieces\.pieces\[1\]\.vertices: expected a list of \[x, y, z\]"),
    (lambda d: d["pieces"][1].update(vertices=[[0, 0, 0], [1, "x", 2]]),
     r"collision_pieces\.pieces\[1\]\.vertices: expected a list of \[x, y, z\]"),
    (lambda d: d["pieces"][2].update(vertices=[[0, float("nan"), 0]]),
     r"collision_pieces\.pieces\[2\]\.vertices\[0\]: not finite"),
    (lambda d: d["pieces"][1].update(radius=-0.01),
     r"collision_pieces\.pieces\[1\]\.radius: expected a finite distance >= 0"),
    (lambda d: d["pieces"][1].update(radius=float("inf")),
     r"collision_pieces\.pieces\[1\]\.radius: expected a finite distance"),
    (lambda d: d["pieces"][1].update(radius=True),
     r"collision_pieces\.pieces\[1\]\.radius: expected a number"),
    (lambda d: d["pieces"][2].update(frame="l9"),
     r"collision_pieces\.pieces\[2\]\.frame: unknown frame 'l9'"),
    (lambda d: d["pieces"][2].update(frame=7),
     r"collision_pieces\.pieces\[2\]\.frame: frame index 7 out of range"),
    (lambda d: d["pieces"][0].pop("vertices"), r"collision_pieces\.pieces\[0\]\.vertices: missing"),
    (lambda d: d["pieces"][0].update(color="red"),
     r"collision_pieces\.pieces\[0\]: unknown keys \['color'\]"),
    (lambda d: d["pieces"][0].update(source=3), r"collision_pieces\.pieces\[0\]\.source"),
    (lambda d: d.update(pieces={"a": 1}), r"collision_pieces\.pieces: expected a list"),
    (lambda d: d["pieces"].append(5), r"collision_pieces\.pieces\[3\]: expected an object"),
    (lambda d: d.update(sphere_count=-1), r"collision_pieces\.sphere_count: expected an integer"),
    (lambda d: d.update(sphere_count=2.5), r"collision_pieces\.sphere_count: expected an integer"),
    (lambda d: d.pop("sphere_digest"), r"collision_pieces\.sphere_digest: missing"),
    (lambda d: d.update(extra=1), r"collision_pieces: unknown keys \['extra'\]"),
])
def test_json_errors_name_the_key_and_index(edit, match):
    doc = dict(DOC)
    d = pieces_doc()
    edit(d)
    doc["collision_pieces"] = d
    with pytest.raises(RobotModelError, match=match):
        RobotModel.from_dict(doc)


def test_model_validation_names_the_piece():
    m = RobotModel.from_dict(DOC)
    bad = CollisionPieces([ConvexPiece(1, np.zeros((1, 3))), ConvexPiece(5, np.zeros((1, 3)))],
                          0, "")
    with pytest.raises(RobotModelError, match=r"collision_pieces\.pieces\[1\]\.frame: frame "
                                              r"index 5 out of range \[0, 3\)"):
        m.copy(collision_pieces=bad)
    with pytest.raises(RobotModelError, match=r"collision_pieces\.pieces\[0\]\.radius"):
        m.copy(collision_pieces=CollisionPieces([ConvexPiece(1, np.zeros((1, 3)), -1.0)], 0, ""))
    with pytest.raises(RobotModelError, match=r"collision_pieces: expected a CollisionPieces"):
        m.copy(collision_pieces={"pieces": []})
    # numbers are stored as plain Python/numpy float64 types
    ok = m.copy(collision_pieces=CollisionPieces(
        [ConvexPiece(np.int64(2), [[0, 0, 1]], np.float32(0.5))], np.int64(0), ""))
    p = ok.collision_pieces.pieces[0]
    assert type(p.frame) is int and type(p.radius) is float
    assert p.vertices.dtype == np.float64 and p.vertices.shape == (1, 3)
    assert type(ok.collision_pieces.sphere_count) is int


def test_pieces_to_dict_writes_frame_names_and_exact_numbers():
    m = model()
    d = pieces_to_dict(m.collision_pieces, m.frame_names)
    assert [p["frame"] for p in d["pieces"]] == ["l1", "l2", "l2"]
    assert d["pieces"][2]["vertices"] == [[0.1 / 3, 1e-10, -2.5e-7]]
    assert d["pieces"][2]["source"] == "" and d["method"] == "by hand"
