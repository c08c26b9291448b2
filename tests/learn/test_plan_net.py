"""The motion-planning network (jwarp/learn/plan_net.py, train_plan.py, evaluate_plan.py)
and the planner's warm start: path encoding round trip, augmentation (time reversal and
the declared axis symmetries against FK and a mirrored world), gradients, a short planar4
training lowering the validation MSE, Algorithm 1's clean/extend, the evaluation table,
checkpoints, and ``Planner(..., warm_start=net)``."""

from __future__ import annotations

import numpy as np
import pytest
import torch

import jwarp
from jwarp.kinematics.fk import fk
from jwarp.learn.checkpoint import load_checkpoint, load_plan_checkpoint, save_checkpoint
from jwarp.learn.evaluate_plan import evaluate_plan, format_plan_table
from jwarp.learn.plan_net import (
    AXIS_SYMMETRIES,
    PlanNet,
    PlanNetConfig,
    axis_symmetries,
    decode_paths,
    encode_paths,
    straight_paths,
    symmetric_bps,
)
from jwarp.learn.train_plan import (
    TrainPlanOptions,
    augment,
    boost_weights,
    clean,
    extend,
    make_plan_data,
    path_costs,
    plan_loss,
    train_plan,
    validation_mse,
)
from jwarp.solvers.planning import Planner, PlanOptions
from jwarp.world.feasibility import feasible_simplex_world, random_configurations
from jwarp.world.path_feasibility import path_feasible
from jwarp.world.sdf import World

ROBOT = "planar4"


@pytest.fixture(scope="module")
def worlds():
    return [feasible_simplex_world(ROBOT, seed=s) for s in (3, 11)]


@pytest.fixture(scope="module")
def samples(worlds):
    """Planner-labelled tasks: 40 in the first world (training), 16 more there (validation)."""
    data = make_plan_data(ROBOT, worlds[:1], 40, seed=0, n_starts=4, iterations=60)
    val = make_plan_data(ROBOT, worlds[:1], 16, seed=1, n_starts=4, iterations=60)
    assert len(data) >= 20 and len(val) >= 8
    return data, val


def small_net(n_bps=32, **kw):
    torch.manual_seed(0)
    return PlanNet(PlanNetConfig(robot=ROBOT, n_bps=n_bps, hidden=32, n_blocks=2, **kw))


def mirrored_world(world):
    """The world mirrored about the x axis (y -> -y)."""
    lim = world.limits.copy()
    lim[1] = [-world.limits[1, 1], -world.limits[1, 0]]
    return World(np.ascontiguousarray(world.sdf[:, ::-1]), lim, world.voxel_size)


# ------------------------------------------------------------------ encoding
def test_path_encoding_round_trip():
    rng = np.random.default_rng(0)
    lo, hi = np.full(4, -2.9), np.full(4, 2.9)
    paths = rng.uniform(-2.5, 2.5, (6, 20, 4))
    dev = encode_paths(paths, lo, hi)
    assert dev.shape == (6, 18, 4)
    back = decode_paths(dev, paths[:, 0], paths[:, -1], lo, hi)
    np.testing.assert_allclose(back, paths, atol=1e-12)
    line = straight_paths(paths[:, 0], paths[:, -1], 20)
    np.testing.assert_allclose(encode_paths(line, lo, hi), 0.0, atol=1e-12)
    # heads and clipping into the limits
    big = decode_paths(np.full((6, 2, 18, 4), 5.0), paths[:, 0], paths[:, -1], lo, hi)
    assert big.shape == (6, 2, 20, 4) and np.all(big <= hi) and np.all(big >= lo)


def test_paths_endpoints_limits_and_world_forms(worlds):
    net = small_net(n_heads=2)
    q = random_configurations(ROBOT, 6, seed=1)
    P = net.paths(q[:3], q[3:], worlds[0])
    assert P.shape == (3, 2, 20, 4) and P.dtype == np.float64
    np.testing.assert_array_equal(P[:, :, 0], np.repeat(q[:3, None], 2, 1))
    np.testing.assert_array_equal(P[:, :, -1], np.repeat(q[3:, None], 2, 1))
    assert np.all(net.lower <= P) and np.all(net.upper >= P)
    per_task = net.paths(q[:3], q[3:], [worlds[0]] * 3)
    np.testing.assert_allclose(per_task, P)
    with pytest.raises(ValueError, match="world"):
        net.paths(q[:3], q[3:])


# ------------------------------------------------------------------ augmentation
def test_time_reversal_is_a_label_of_the_reversed_task(samples):
    data, _ = samples
    world = data.worlds[0]
    rev = data.paths[:, ::-1]
    assert path_feasible(jwarp.robot(ROBOT), world, rev, 4).all()
    model = jwarp.robot(ROBOT)   # path_costs takes the RobotModel (issue 40 item 2)
    np.testing.assert_allclose(path_costs(model, world, rev), path_costs(model, world, data.paths),
                               rtol=1e-4, atol=1e-6)
    net = small_net()
    arr = augment(net, data, time_reversal=True, axis_symmetry=False)
    r = arr["kind"] == 1
    np.testing.assert_array_equal(arr["starts"][r], data.goals[arr["source"][r]])
    np.testing.assert_array_equal(arr["goals"][r], data.starts[arr["source"][r]])
    np.testing.assert_allclose(arr["labels"][r], encode_paths(rev, net.lower, net.upper)[arr["source"][r]])


def test_axis_symmetry_mirrors_fk_positions():
    (sym,) = axis_symmetries(ROBOT)
    q = random_configurations(ROBOT, 50, seed=2)
    T = fk(ROBOT, q, dtype=np.float64)
    Tm = fk(ROBOT, sym.map_q(q), dtype=np.float64)
    np.testing.assert_allclose(Tm[..., :2, 3], T[..., :2, 3] @ sym.matrix.T, atol=1e-9)
    assert AXIS_SYMMETRIES["planar5"] and axis_symmetries("arm7") == ()


def test_axis_symmetry_bps_and_labels_match_the_mirrored_world(samples):
    data, _ = samples
    world = data.worlds[0]
    (sym,) = axis_symmetries(ROBOT)
    net = small_net(n_bps=64)
    mw = mirrored_world(world)
    np.testing.assert_allclose(symmetric_bps(net.bps, [world], sym)[0], net.world_bps(mw),
                               atol=1e-5)
    mp = sym.map_q(data.paths)
    assert path_feasible(jwarp.robot(ROBOT), mw, mp, 4).all()
    assert not path_feasible(jwarp.robot(ROBOT), mw, data.paths, 4).all()  # the mirror matters
    arr = augment(net, data, time_reversal=True, axis_symmetry=True)
    assert sorted(np.unique(arr["kind"]).tolist()) == [0, 1, 2, 3]
    m = arr["kind"] == 2
    np.testing.assert_allclose(arr["bps"][m][0], net.world_bps(mw), atol=1e-5)
    np.testing.assert_allclose(arr["starts"][m], -data.starts[arr["source"][m]])


# ------------------------------------------------------------------ training
def test_gradients_reach_every_weight(samples):
    data, _ = samples
    net = small_net()
    arr = augment(net, data)
    t = [None if arr[k] is None else torch.as_tensor(arr[k][:16], dtype=torch.float32)
         for k in ("starts", "goals", "bps", "labels")]
    plan_loss(net, *t).backward()
    for name, p in net.named_parameters():
        assert p.grad is not None and torch.isfinite(p.grad).all(), name
        assert p.grad.abs().sum() > 0, name


def test_short_training_lowers_validation_mse(samples, tmp_path):
    data, val = samples
    o = TrainPlanOptions(robot=ROBOT, n_bps=32, hidden=64, n_blocks=2, epochs=4,
                         steps_per_epoch=40, batch_size=64, lr=2e-3, boosting=True,
                         checkpoint=str(tmp_path / "p.pt"))
    torch.manual_seed(o.seed)  # the initialisation train_plan starts from
    before = validation_mse(PlanNet(o.net_config()), data)
    net, hist = train_plan(o, data, val)
    # held-out tasks: lower than the untrained network (at this size the gain over the
    # straight line is small); the training tasks: fitted
    assert hist[-1]["val_mse"] < 0.97 * hist[0]["val_mse"], hist
    assert validation_mse(net, data) < 0.5 * before
    assert hist[-1]["boost_hard"] > 0
    loaded = load_plan_checkpoint(tmp_path / "p.pt")
    assert loaded.meta["epoch"] == 4
    assert validation_mse(loaded, val) == pytest.approx(hist[-1]["val_mse"], rel=1e-5)


def test_boost_clean_extend(samples, worlds):
    data, _ = samples
    net = small_net()
    w = boost_weights(net, data, percentile=0.75, ratio=0.9)
    assert np.all(np.isclose(w, 1.0) | np.isclose(w, 0.1)) and (w == 1.0).sum() >= len(data) // 5
    cleaned, n = clean(net, data, iterations=30)
    assert len(cleaned) == len(data) and 0 <= n <= len(data)
    assert np.all(cleaned.cost <= data.cost + 1e-9)
    changed = np.any(cleaned.paths != data.paths, axis=(1, 2))
    assert changed.sum() == n
    assert path_feasible(jwarp.robot(ROBOT), data.worlds[0], cleaned.paths[changed], 4).all()
    calls = []

    def labeler(robot, world, q0, q1):
        calls.append(len(q0))
        P = straight_paths(q0, q1, 20)
        return P, np.ones(len(q0), bool), np.zeros(len(q0))

    ext, added = extend(net, cleaned, 3, n_candidates=12, worlds=worlds, labeler=labeler)
    assert added == 3 and sum(calls) == 3 and len(ext) == len(data) + 3
    assert len(ext.worlds) == 2


def test_evaluate_plan_table(samples):
    _, val = samples
    net = small_net()
    rows = evaluate_plan(ROBOT, val.worlds, val.starts[:6], val.goals[:6], val.world_index[:6],
                         nets=[("net", net)], ks=(0, 20), n_random=3)
    assert [r["name"] for r in rows] == ["net", "random (1)", "random (best of 3)",
                                         "straight line"]
    for r in rows:
        assert 0.0 <= r["feasible"][0] <= r["feasible"][20] <= 1.0
    text = format_plan_table(rows, "t")
    assert "k=20" in text and "random (best of 3)" in text


# ------------------------------------------------------------------ checkpoints
def test_checkpoint_round_trip_and_other_robot_refused(tmp_path, worlds):
    net = small_net()
    path = save_checkpoint(tmp_path / "n.pt", net)
    back = load_plan_checkpoint(path, robot=ROBOT)
    q = random_configurations(ROBOT, 4, seed=3)
    np.testing.assert_allclose(back.paths(q[:2], q[2:], worlds[0]),
                               net.paths(q[:2], q[2:], worlds[0]))
    assert back.bps == net.bps
    with pytest.raises(ValueError, match="planar5"):
        load_plan_checkpoint(path, robot="planar5")
    with pytest.raises(ValueError, match="not a jwarp IK network"):
        load_checkpoint(path)


# ------------------------------------------------------------------ planner warm start
class Recorder:
    def __init__(self, net):
        self.net, self.calls = net, 0

    def paths(self, q0, q1, world):
        self.calls += 1
        return self.net.paths(q0, q1, world)


def test_planner_warm_start_uses_the_network(worlds, samples):
    data, _ = samples
    net = Recorder(small_net())
    q0, q1 = data.starts[:4], data.goals[:4]
    opts = PlanOptions(n_starts=1, n_substeps=4, iterations=0)
    res = Planner(ROBOT, worlds[0], 4, opts, device="cpu", warm_start=net).plan(q0, q1)
    assert net.calls == 1
    np.testing.assert_allclose(res.all_paths[:, 0], net.net.paths(q0, q1, worlds[0])[:, 0],
                               atol=1e-5)
    # more starts: the network's paths first, then multi-starts; explicit seeds win
    opts3 = PlanOptions(n_starts=3, n_substeps=4, iterations=0)
    res3 = Planner(ROBOT, worlds[0], 4, opts3, device="cpu", warm_start=net).plan(q0, q1)
    assert res3.all_paths.shape[1] == 3
    np.testing.assert_allclose(res3.all_paths[:, 0], res.all_paths[:, 0], atol=1e-6)
    line = straight_paths(q0, q1, 20)[:, None]
    res4 = Planner(ROBOT, worlds[0], 4, opts3, device="cpu", warm_start=net).plan(q0, q1,
                                                                                  seeds=line)
    assert net.calls == 2 and res4.all_paths.shape[1] == 1
    np.testing.assert_allclose(res4.all_paths[:, 0], line[:, 0], atol=1e-5)


def test_planner_warm_start_type_error(worlds):
    with pytest.raises(TypeError, match="warm_start"):
        Planner(ROBOT, worlds[0], 2, warm_start=object())
