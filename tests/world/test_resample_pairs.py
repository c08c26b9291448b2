"""Self-collision pairs sampled again after joints are locked (jwarp.world.spherize.
resample_pairs, used by ``jwarp import-urdf --group/--joints/--lock/--freeze``): the result
equals an independent sampling over the locked model plus the exclusions that did not come
from the first sampling."""

import numpy as np

import jwarp
from jwarp.model import SelfCollision, freeze_joints
from jwarp.world.self_pairs import never_colliding_pairs, with_self_pairs
from jwarp.world.spherize import MOVEIT_RULES, SpherizeOptions, resample_pairs


def test_pairs_resampled_over_the_planned_joints():
    full = jwarp.robot("justin19")
    first = never_colliding_pairs(full, n_samples=300, seed=0)
    fitted = with_self_pairs(full, first)
    # the right arm only: torso bent far forward, left arm and head locked
    lock = {"torso_pan": 0.0, "torso_tilt_1": 1.0, "torso_tilt_2": 1.0, "left_1": 0.3,
            "left_2": -1.5, "left_3": 0.0, "left_4": 1.2, "left_5": 0.0, "left_6": 0.0,
            "left_7": 0.0, "head_pan": 0.0, "head_tilt": 0.5}
    locked = freeze_joints(fitted, lock)
    assert locked.n_dof == 7
    # an exclusion of its own (as an SRDF adds): kept
    extra = (0, locked.n_frames - 1)
    sc = locked.self_collision
    locked = locked.copy(self_collision=SelfCollision(
        groups=sc.groups, include_pairs=sc.include_pairs,
        exclude_pairs=sorted(set(sc.exclude_pairs) | {extra})))
    opts = SpherizeOptions(pair_samples=300, seed=0)
    out, pairs = resample_pairs(locked, fitted.self_collision.exclude_pairs, opts)

    # independent sampling, by the import's rules (MoveIt's adjacency and always >= 95 %)
    ref = never_colliding_pairs(locked, n_samples=300, seed=0, **MOVEIT_RULES)
    own = {tuple(sorted(p)) for p in locked.self_collision.exclude_pairs} \
        - {tuple(sorted(p)) for p in first.exclude_pairs}
    assert extra in own
    want = set(ref.exclude_pairs) | own
    assert set(map(tuple, out.self_collision.exclude_pairs)) == want
    assert pairs.never_colliding == ref.never_colliding
    # locking changed what is excluded (else the test proves nothing)
    assert set(ref.exclude_pairs) != set(first.exclude_pairs)
    assert "planned joints" in out.notes["self_collision"]
    # the locked model's check agrees with the pairs: the excluded pairs are not checked
    allowed = out.allowed_collision_pairs
    for a, b in want:
        assert not allowed[a, b]
    assert np.any(allowed)


def test_cli_import_with_frozen_fingers_resamples(tmp_path, capsys, monkeypatch):
    """``import-urdf --freeze`` with a sphere fit: the pairs of the written robot are those
    of an independent sampling over its 7 planned joints (same samples and seed)."""
    import json

    from cli_helpers import run

    from jwarp.importers.robot import example_robot_urdf

    monkeypatch.setenv("JWARP_CACHE", str(tmp_path / "cache"))
    urdf = example_robot_urdf("panda_description/urdf/panda.urdf")
    out = tmp_path / "panda7.json"
    code, stdout, err = run(capsys, ["import-urdf", urdf, "--out", out, "--freeze",
                                     "panda_finger_joint1=0.04", "--pair-samples", 300,
                                     "--tolerance", 0.03, "--json"])
    assert code == 0, err
    doc = json.loads(stdout)
    model = jwarp.robot(str(out))
    assert model.n_dof == 7
    ref = never_colliding_pairs(model, n_samples=300, seed=0, **MOVEIT_RULES)
    assert doc["pairs_resampled"] == {"never": len(ref.never_colliding),
                                      "always": len(ref.always_colliding)}
    assert set(ref.exclude_pairs) <= set(map(tuple, model.self_collision.exclude_pairs))
