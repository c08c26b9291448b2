"""RobotModel: loading, validation (clear errors naming the field), saving, look-ups."""

from __future__ import annotations

import copy
import json
import os
from pathlib import Path

import numpy as np
import pytest

import jwarp.model.robot as model_mod
from jwarp.model import RobotModel, RobotModelError

ROOT = Path(__file__).resolve().parents[2]
JUSTIN = ROOT / "jwarp" / "plugins" / "robots" / "justin19.json"


def tiny() -> dict:
    """A valid 2-DoF robot with every section filled in."""
    tip = np.eye(4)
    tip[0, 3] = 0.3
    return {
        "schema": "jwarp.robot", "version": 1, "name": "tiny",
        "description": "two links", "gravity": [0, 0, -9.81],
        "joints": [{"name": "j0", "type": "revolute", "limits": [-1, 1]},
                   {"name": "j1", "type": "revolute", "limits": [-2, 2]}],
        "frames": [
            {"name": "base", "parent": None, "kind": "static", "transform": np.eye(4).tolist()},
            {"name": "l1", "parent": "base", "kind": "dh", "dh": [0.1, 0, 0, 0, 0], "joint": "j0"},
            {"name": "l2", "parent": "l1", "kind": "dh", "dh": [0, 0, 0.5, 0.2, 0.01],
             "joint": "j1"},
            {"name": "tip", "parent": "l2", "kind": "static", "transform": tip.tolist()},
        ],
        "masses": [{"frame": "l2", "mass": 1.5, "com": [0.2, 0, 0]}],
        "spheres": [{"frame": "l2", "position": [0.1, 0, 0], "radius": 0.05}],
        "capsules": [{"frame": "l1", "p0": [0, 0, 0], "p1": [0.5, 0, 0], "radius": 0.04}],
        "self_collision": {"groups": {"arm": ["l1", "l2"]}, "include_pairs": [],
                           "exclude_pairs": [["base", "tip"]]},
        "end_effectors": {"tcp": "tip"},
        "linear_limits": [{"joints": ["j0", "j1"], "coefficients": [1, 1], "limits": [-1, 1]}],
        "kappa": [[0, 0, 0], [1e-4, 1e-4, 2e-4], [1e-4, 0, 0], [0, 0, 0]],
        "notes": {"who": "test"},
    }


def test_tiny_is_valid():
    m = RobotModel.from_dict(tiny())
    assert (m.n_dof, m.n_frames) == (2, 4)
    assert list(m.parents) == [-1, 0, 1, 2]
    assert m.frames[2].coupling == [(1, 1.0)]
    np.testing.assert_allclose(m.kappa[1], [1e-4, 1e-4, 2e-4])


# ------------------------------------------------------------ negative tests
def _raises(doc, match):
    with pytest.raises(ValueError, match=match) as info:
        RobotModel.from_dict(doc)
    assert isinstance(info.value, RobotModelError)
    return info.value


def test_cycle_in_tree():
    doc = tiny()
    doc["frames"][1]["parent"] = "l2"  # l1 <- l2 <- l1
    err = _raises(doc, r"frames: cycle in the tree")
    assert "1" in str(err) and "2" in str(err)


def test_cycle_with_indices():
    doc = tiny()
    doc["frames"][0]["parent"] = 3  # base -> tip -> l2 -> l1 -> base
    _raises(doc, r"frames: cycle")


def test_self_parent():
    doc = tiny()
    doc["frames"][2]["parent"] = 2
    _raises(doc, r"frames\[2\]\.parent: a frame cannot be its own parent")


@pytest.mark.parametrize("parent", [4, 17, -1])
def test_parent_index_out_of_range(parent):
    doc = tiny()
    doc["frames"][2]["parent"] = parent
    _raises(doc, rf"frames\[2\]\.parent: index {parent} out of range")


@pytest.mark.parametrize("row", [[0, 0, 0], [0, 0, 0, 0, 0, 0], [], [[0, 0, 0, 0]]])
def test_dh_row_wrong_length(row):
    doc = tiny()
    doc["frames"][1]["dh"] = row
    _raises(doc, r"frames\[1\]\.dh: expected \[d, theta, r, alpha\(, beta\)\]")


def test_dh_row_of_four_gets_zero_beta():
    doc = tiny()
    doc["frames"][1]["dh"] = [0.1, 0.2, 0.3, 0.4]
    m = RobotModel.from_dict(doc)
    np.testing.assert_array_equal(m.frames[1].dh, [0.1, 0.2, 0.3, 0.4, 0.0])


def test_dh_missing():
    doc = tiny()
    del doc["frames"][1]["dh"]
    _raises(doc, r"frames\[1\]\.dh: missing")


@pytest.mark.parametrize("bad", [float("nan"), float("inf"), -float("inf")])
def test_nan_in_dh_row(bad):
    doc = tiny()
    doc["frames"][2]["dh"][3] = bad
    _raises(doc, r"frames\[2\]\.dh: contains NaN or inf")


def test_nan_in_dh_row_from_file(tmp_path):
    text = json.dumps(tiny()).replace('"dh": [0.1, 0, 0, 0, 0]', '"dh": [0.1, NaN, 0, 0, 0]')
    assert "NaN" in text
    p = tmp_path / "nan.json"
    p.write_text(text)
    with pytest.raises(ValueError, match=r"nan\.json: frames\[1\]\.dh: contains NaN"):
        RobotModel.load(p)


def test_nan_in_dh_row_programmatic():
    m = RobotModel.from_dict(tiny())
    m.frames[1].dh = np.array([0.1, np.nan, 0, 0, 0])
    with pytest.raises(ValueError, match=r"frames\[1\]\.dh: contains NaN"):
        model_mod.validate(m)


def test_negative_sphere_radius():
    doc = tiny()
    doc["spheres"][0]["radius"] = -0.01
    _raises(doc, r"spheres\[0\]\.radius: must be finite and >= 0")


def test_negative_capsule_radius():
    doc = tiny()
    doc["capsules"][0]["radius"] = -1
    _raises(doc, r"capsules\[0\]\.radius")


def test_unknown_joint_name():
    doc = tiny()
    doc["frames"][2]["joint"] = "elbow"
    _raises(doc, r"frames\[2\]\.joint: unknown joint 'elbow'")


def test_unknown_joint_in_coupling_and_linear_limit():
    doc = tiny()
    doc["frames"][2].pop("joint")
    doc["frames"][2]["coupled"] = {"joints": ["j1", "jx"], "coefficients": [1, -1]}
    _raises(doc, r"frames\[2\]\.coupled\.joints: unknown joint 'jx'")
    doc = tiny()
    doc["linear_limits"][0]["joints"] = ["j0", "wrist"]
    _raises(doc, r"linear_limits\[0\]\.joints: unknown joint 'wrist'")


def test_unknown_frame_name():
    doc = tiny()
    doc["frames"][2]["parent"] = "forearm"
    _raises(doc, r"frames\[2\]\.parent: unknown frame 'forearm'")


@pytest.mark.parametrize("section,where", [
    ("masses", r"masses\[0\]\.frame"), ("spheres", r"spheres\[0\]\.frame"),
    ("capsules", r"capsules\[0\]\.frame")])
def test_unknown_frame_name_in_bodies(section, where):
    doc = tiny()
    doc[section][0]["frame"] = "nowhere"
    _raises(doc, rf"{where}: unknown frame 'nowhere'")


def test_unknown_frame_name_in_end_effectors_and_groups():
    doc = tiny()
    doc["end_effectors"]["tcp"] = "hand"
    _raises(doc, r"end_effectors\.tcp: unknown frame 'hand'")
    doc = tiny()
    doc["self_collision"]["groups"]["arm"].append("hand")
    _raises(doc, r"self_collision\.groups\.arm: unknown frame 'hand'")
    doc = tiny()
    doc["self_collision"]["exclude_pairs"].append(["l1", "hand"])
    _raises(doc, r"self_collision\.exclude_pairs\[1\]: unknown frame 'hand'")


def test_duplicate_frame_names():
    doc = tiny()
    doc["frames"][3]["name"] = "l1"
    doc["end_effectors"] = {"tcp": 3}
    doc["self_collision"]["exclude_pairs"] = [[0, 3]]
    _raises(doc, r"frames\[3\]\.name: duplicate frame name 'l1'")


def test_duplicate_joint_names():
    doc = tiny()
    doc["joints"][1]["name"] = "j0"
    doc["frames"][2]["joint"] = 1
    doc["linear_limits"][0]["joints"] = [0, 1]
    _raises(doc, r"joints\[1\]\.name: duplicate joint name 'j0'")


def test_static_frame_with_joint():
    doc = tiny()
    doc["frames"][3]["joint"] = "j1"
    _raises(doc, r"frames\[3\]\.joint: a 'static' frame cannot be driven by a joint")


def test_static_frame_with_coupled_joints():
    doc = tiny()
    doc["frames"][3]["coupled"] = {"joints": ["j0", "j1"], "coefficients": [1, 1]}
    _raises(doc, r"frames\[3\]\.coupled: a 'static' frame cannot be driven by a joint")


def test_static_frame_with_joint_programmatic():
    m = RobotModel.from_dict(tiny())
    m.frames[3].coupling = [(0, 1.0)]
    with pytest.raises(ValueError, match=r"frames\[3\]\.joint: a 'static' frame"):
        model_mod.validate(m)


def test_bad_static_transform():
    doc = tiny()
    doc["frames"][3]["transform"][3] = [0, 0, 1, 1]
    _raises(doc, r"frames\[3\]\.transform: last row")
    doc = tiny()
    doc["frames"][3]["transform"][0][0] = 2.0
    _raises(doc, r"frames\[3\]\.transform: rotation part is not orthonormal")
    doc = tiny()
    doc["frames"][3]["transform"] = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]
    _raises(doc, r"frames\[3\]\.transform: expected shape \(4, 4\)")


def test_joint_driving_no_frame():
    doc = tiny()
    doc["joints"].append({"name": "j2"})
    _raises(doc, r"joints\[2\]: joint 'j2' drives no frame")


def test_malformed_json(tmp_path):
    p = tmp_path / "broken.json"
    good = json.dumps(tiny(), indent=1)
    p.write_text(good[: len(good) // 2])
    with pytest.raises(ValueError, match=r"broken\.json: not valid JSON"):
        RobotModel.load(p)
    p.write_text("{'name': 'single quotes'}")
    with pytest.raises(ValueError, match=r"broken\.json: not valid JSON"):
        RobotModel.load(p)


def test_missing_file(tmp_path):
    with pytest.raises(ValueError, match=r"path: cannot read robot file .*absent\.json"):
        RobotModel.load(tmp_path / "absent.json")


def test_json_not_an_object(tmp_path):
    p = tmp_path / "list.json"
    p.write_text("[1, 2, 3]")
    with pytest.raises(ValueError, match=r"list\.json: document: expected a JSON object"):
        RobotModel.load(p)


@pytest.mark.parametrize("version", [0, 2, "1", "v1"])
def test_wrong_schema_version(version):
    doc = tiny()
    doc["version"] = version
    _raises(doc, r"version: schema version .* not supported")


def test_wrong_schema_name():
    doc = tiny()
    doc["schema"] = "urdf"
    _raises(doc, r"schema: expected 'jwarp.robot', got 'urdf'")


def test_wrong_version_from_file_names_file(tmp_path):
    doc = tiny()
    doc["version"] = 3
    p = tmp_path / "v3.json"
    p.write_text(json.dumps(doc))
    with pytest.raises(ValueError, match=r"v3\.json: version: schema version 3"):
        RobotModel.load(p)


@pytest.mark.parametrize("kappa", [[[0, 0, 0]] * 3, [[0, 0]] * 4, [0, 0, 0], [[0, 0, 0, 0]] * 4])
def test_kappa_wrong_shape(kappa):
    doc = tiny()
    doc["kappa"] = kappa
    _raises(doc, r"kappa: expected shape \(4, 3\)")


def test_kappa_wrong_shape_programmatic():
    m = RobotModel.from_dict(tiny())
    with pytest.raises(ValueError, match=r"kappa: expected shape \(4, 3\)"):
        m.copy(kappa=np.zeros((3, 3)))
    with pytest.raises(ValueError, match=r"kappa: compliances must be >= 0"):
        m.copy(kappa=-np.ones((4, 3)))


def test_missing_required_fields():
    for key in ("name", "joints", "frames"):
        doc = tiny()
        del doc[key]
        _raises(doc, rf"document\.{key}: missing")
    doc = tiny()
    del doc["frames"][1]["kind"]
    _raises(doc, r"frames\[1\]\.kind: missing")


def test_bad_kind_and_joint_type():
    doc = tiny()
    doc["frames"][3]["kind"] = "fixed"
    _raises(doc, r"frames\[3\]\.kind: 'fixed' is not one of")
    doc = tiny()
    doc["joints"][0]["type"] = "spherical"
    _raises(doc, r"joints\[0\]\.type: 'spherical' is not one of")


def test_joint_limits_reversed():
    doc = tiny()
    doc["joints"][0]["limits"] = [1, -1]
    _raises(doc, r"joints\[0\]\.limits: lower 1.0 > upper -1.0")


def test_negative_mass():
    doc = tiny()
    doc["masses"][0]["mass"] = -2
    _raises(doc, r"masses\[0\]\.mass: must be finite and >= 0")


def test_mixed_coupling_types():
    doc = tiny()
    doc["joints"][1]["type"] = "prismatic"
    doc["frames"][2].pop("joint")
    doc["frames"][2]["coupled"] = {"joints": ["j0", "j1"], "coefficients": [1, 1]}
    doc["frames"][1]["joint"] = "j0"
    _raises(doc, r"frames\[2\]\.coupled: mixes revolute and prismatic")


# ------------------------------------------------------------------- saving
def test_round_trip_tiny(tmp_path):
    m = RobotModel.from_dict(tiny())
    p = tmp_path / "tiny.json"
    m.save(p)
    m2 = RobotModel.load(p)
    assert m2.to_dict() == m.to_dict()
    # saving the loaded model again gives the identical text
    p2 = tmp_path / "tiny2.json"
    m2.save(p2)
    assert p2.read_text() == p.read_text()


def test_round_trip_justin(tmp_path):
    m = RobotModel.load(JUSTIN)
    p = tmp_path / "justin.json"
    m.save(p)
    m2 = RobotModel.load(p)
    assert m2.to_dict() == m.to_dict()
    np.testing.assert_array_equal(m2.dh_table, m.dh_table)
    np.testing.assert_array_equal(m2.coupling_matrix, m.coupling_matrix)
    np.testing.assert_array_equal(m2.allowed_collision_pairs, m.allowed_collision_pairs)
    # to_dict -> from_dict round trip without a file, and copy()
    assert RobotModel.from_dict(m.to_dict()).to_dict() == m.to_dict()
    assert m.copy().to_dict() == m.to_dict()


def test_round_trip_with_kappa_and_coupling(tmp_path):
    doc = tiny()
    doc["frames"][2].pop("joint")
    doc["frames"][2]["coupled"] = {"joints": ["j1", "j0"], "coefficients": [-1.0, 0.5]}
    m = RobotModel.from_dict(doc)
    p = tmp_path / "c.json"
    m.save(p)
    m2 = RobotModel.load(p)
    assert m2.to_dict() == m.to_dict()
    assert m2.frames[2].coupling == [(1, -1.0), (0, 0.5)]
    np.testing.assert_array_equal(m2.kappa, m.kappa)


def _tmp_leftovers(folder: Path, name: str) -> list[str]:
    return [f.name for f in folder.iterdir() if f.name != name]


def test_save_is_atomic_when_rename_fails(tmp_path, monkeypatch):
    p = tmp_path / "robot.json"
    old = RobotModel.from_dict(tiny())
    old.save(p)
    before = p.read_text()
    doc = tiny()
    doc["name"] = "tiny_v2"
    new = RobotModel.from_dict(doc)

    def boom(src, dst):
        raise OSError("disk on fire")

    monkeypatch.setattr(model_mod.os, "replace", boom)
    with pytest.raises(OSError, match="disk on fire"):
        new.save(p)
    assert p.read_text() == before
    assert _tmp_leftovers(tmp_path, "robot.json") == []


def test_save_is_atomic_when_write_fails_halfway(tmp_path, monkeypatch):
    p = tmp_path / "robot.json"
    RobotModel.from_dict(tiny()).save(p)
    before = p.read_text()
    real_fdopen = os.fdopen

    class HalfWriter:
        """Writes half of the text to the real file, then fails."""

        def __init__(self, fh):
            self.fh = fh

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.fh.close()
            return False

        def write(self, text):
            self.fh.write(text[: len(text) // 2])
            self.fh.flush()
            raise OSError("no space left on device")

        def __getattr__(self, k):
            return getattr(self.fh, k)

    monkeypatch.setattr(model_mod.os, "fdopen", lambda fd, mode="r", *a, **k:
                        HalfWriter(real_fdopen(fd, mode, *a, **k)))
    doc = tiny()
    doc["name"] = "tiny_v2"
    with pytest.raises(OSError, match="no space left"):
        RobotModel.from_dict(doc).save(p)
    assert p.read_text() == before
    assert RobotModel.load(p).name == "tiny"
    assert _tmp_leftovers(tmp_path, "robot.json") == []


def test_save_is_atomic_when_serialisation_fails(tmp_path, monkeypatch):
    p = tmp_path / "robot.json"
    RobotModel.from_dict(tiny()).save(p)
    before = p.read_text()

    def bad_dumps(*a, **k):
        raise TypeError("not serialisable")

    monkeypatch.setattr(model_mod.json, "dumps", bad_dumps)
    with pytest.raises(TypeError):
        RobotModel.from_dict(tiny()).save(p)
    assert p.read_text() == before
    assert _tmp_leftovers(tmp_path, "robot.json") == []


def test_save_into_missing_folder(tmp_path):
    with pytest.raises(ValueError, match=r"path: folder .* does not exist"):
        RobotModel.from_dict(tiny()).save(tmp_path / "nope" / "r.json")


# ----------------------------------------------------------- self-collision
@pytest.fixture(scope="module")
def justin():
    return RobotModel.load(JUSTIN)


def test_justin_allowed_collision_pairs(justin):
    A = justin.allowed_collision_pairs
    n = justin.n_frames
    assert A.shape == (n, n) and A.dtype == bool
    np.testing.assert_array_equal(A, A.T)
    assert not A.diagonal().any()
    sc = justin.self_collision
    include = {frozenset(p) for p in sc.include_pairs}
    exclude = {frozenset(p) for p in sc.exclude_pairs}
    assert include and exclude and not include & exclude
    group_of = {}
    for g, members in sc.groups.items():
        for m in members:
            group_of[m] = g
    for i in range(n):
        for j in range(n):
            if i == j:
                continue
            pair = frozenset((i, j))
            if pair in exclude:
                expect = False
            elif pair in include:
                expect = True
            elif group_of.get(i) is not None and group_of.get(i) == group_of.get(j):
                expect = False
            else:
                expect = True
            assert A[i, j] == expect, (justin.frames[i].name, justin.frames[j].name)
    # spot checks: the hands may touch each other, the right hand may touch the right
    # shoulder (include pair), the head never checks against the torso
    r_tcp, l_tcp = justin.frame_index("right_tcp"), justin.frame_index("left_tcp")
    assert A[r_tcp, l_tcp]
    assert A[justin.frame_index("right_base"), justin.frame_index("right_7")]
    assert not A[justin.frame_index("right_1"), justin.frame_index("right_2")]
    assert not A[justin.frame_index("torso_4"), justin.frame_index("head_1")]


def test_allowed_pairs_tiny():
    A = RobotModel.from_dict(tiny()).allowed_collision_pairs
    expect = ~np.eye(4, dtype=bool)
    expect[1, 2] = expect[2, 1] = False  # group "arm"
    expect[0, 3] = expect[3, 0] = False  # excluded
    np.testing.assert_array_equal(A, expect)


# ------------------------------------------------------------- frame_index
def test_frame_index(justin):
    assert justin.frame_index("torso_4") == 4
    assert justin.frame_index("right_tcp") == 13
    assert justin.frame_index(0) == 0
    assert justin.frame_index(np.int64(26)) == 26
    assert isinstance(justin.frame_index(np.int32(5)), int)


def test_frame_index_end_effector_alias():
    doc = tiny()
    doc["end_effectors"] = {"gripper": "tip", "elbow": 2}
    m = RobotModel.from_dict(doc)
    assert m.frame_index("gripper") == 3
    assert m.frame_index("elbow") == 2
    assert m.frame_index("tip") == 3


def test_frame_index_rejects_unknown(justin):
    with pytest.raises(ValueError, match=r"target: unknown frame 'right_hand' for robot 'justin19'"):
        justin.frame_index("right_hand", argname="target")
    with pytest.raises(ValueError, match=r"frame: unknown frame 'nose'"):
        justin.frame_index("nose")
    with pytest.raises(ValueError, match=r"frame: frame index 27 out of range \[0, 27\)"):
        justin.frame_index(27)
    with pytest.raises(ValueError, match=r"frame index -1 out of range"):
        justin.frame_index(-1)
    with pytest.raises(TypeError, match="frame"):
        justin.frame_index(True)
    with pytest.raises(TypeError, match="frame"):
        justin.frame_index(1.5)


def test_justin_loads_with_expected_sizes(justin):
    assert (justin.n_dof, justin.n_frames) == (19, 27)
    assert len(justin.spheres) == 53
    assert justin.frames[4].coupling == [(1, -1.0), (2, -1.0)]
    order = list(justin.topological_order)
    assert sorted(order) == list(range(27))
    assert all(order.index(p) < order.index(i) for i, p in enumerate(justin.parents) if p >= 0)


def test_from_dict_does_not_mutate_input():
    doc = tiny()
    snapshot = copy.deepcopy(doc)
    RobotModel.from_dict(doc)
    assert doc == snapshot


@pytest.mark.parametrize("bad", [1, 4, True, "2"])
def test_workspace_dim_must_be_2_or_3(bad):
    doc = tiny()
    doc["workspace_dim"] = bad
    _raises(doc, r"workspace_dim: must be 2")


def test_workspace_dim_round_trip(tmp_path):
    doc = tiny()
    doc["workspace_dim"] = 2
    m = RobotModel.from_dict(doc)
    m.save(tmp_path / "r.json")
    assert RobotModel.load(tmp_path / "r.json").workspace_dim == 2
    assert RobotModel.from_dict(tiny()).workspace_dim == 3


@pytest.mark.parametrize("name", ["justin19", "arm7", "hand4", "planar4", "sphere2d"])
def test_topological_order_is_a_preorder_with_contiguous_subtrees(name):
    import jwarp
    robot = jwarp.robot(name)
    order, end, parents = robot.topological_order, robot.subtree_end, robot.parents
    assert sorted(order.tolist()) == list(range(robot.n_frames))
    pos = {int(i): k for k, i in enumerate(order)}
    for k, i in enumerate(order):
        if parents[i] >= 0:
            assert pos[int(parents[i])] < k                      # parents first
        # the run order[k:end[k]] is exactly frame i and its descendants
        below = {int(j) for j in np.nonzero(robot.subtree_mask[i])[0]}
        assert set(order[k:end[k]].tolist()) == below


def test_topological_order_of_a_branching_tree_listed_out_of_order():
    # parents listed after children and two branches interleaved by index
    parents = np.array([3, 4, 0, -1, 3, 2, 1])
    order = model_mod._topological_order(parents)
    assert order == [3, 0, 2, 5, 4, 1, 6]
    with pytest.raises(RobotModelError, match="cycle"):
        model_mod._topological_order(np.array([1, 2, 0]))
