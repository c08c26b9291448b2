"""The Table 3.5 / 3.4 evaluation (jwarp/learn/evaluate.py) on planar5 with fake warm
starts (known solutions, a poor guess) and random seeds: the columns against a brute-force
run of every seed, the length cost against the solver's default pose, the printed tables
and the input errors."""

import numpy as np
import pytest

import jwarp
from jwarp.core.limits import sample_within_limits
from jwarp.learn.evaluate import (
    TABLE_34_COLUMNS,
    TABLE_35_COLUMNS,
    ablation_table,
    evaluate_ik,
    format_table_34,
    format_table_35,
)
from jwarp.solvers.ik import IKObjective, IKOptions, IKSolver
from jwarp.world import collision, simplex_world

ROBOT, FRAME = "planar5", "tcp"


@pytest.fixture(scope="module")
def problems():
    model = jwarp.robot(ROBOT)
    rng = np.random.default_rng(0)
    worlds = [simplex_world(2, seed=s) for s in (0, 1)]
    qs, Ts = [], []
    for w in worlds:
        q = sample_within_limits(model, 400, rng)
        q = q[collision.is_collision_free(model, q, w, 0.0, device="cpu",
                                          dtype=np.float64)][:10]
        qs.append(q)
        Ts.append(jwarp.fk(model, q, device="cpu", dtype=np.float64)[:, 6])
    return model, worlds, qs, Ts


class Twin:
    """Head 1 near the known solution, head 2 a mirrored (poor) guess."""

    config = {"twin": True, "boosting": True, "unit_vectors": False}

    def __init__(self, worlds, qs, noise=0.02):
        self.by_world = {id(w): q for w, q in zip(worlds, qs)}
        self.noise = noise

    def seeds(self, targets, world):
        q = self.by_world[id(world)]
        assert len(q) == len(targets)
        d = np.random.default_rng(1).normal(0.0, self.noise, q.shape)
        return np.stack([q + d, -q], axis=1)


class Corner:
    class config:  # attributes, like a dataclass
        twin, boosting, unit_vectors = False, False, False

    def __init__(self, n):
        self.n = n

    def seeds(self, targets, world):
        return np.full((len(targets), 1, self.n), 3.0)


def test_known_solutions_against_random(problems):
    model, worlds, qs, Ts = problems
    rnd = evaluate_ik(jwarp.robot(ROBOT), FRAME, worlds, Ts, n_random=12)
    net = evaluate_ik(jwarp.robot(ROBOT), FRAME, worlds, Ts, warm_start=Twin(worlds, qs), n_random=12,
                      name="Known")
    assert rnd["name"] == "Random" and rnd["heads"] == 0 and rnd["feasibility_heads"] is None
    assert rnd["n_targets"] == net["n_targets"] == 20 and rnd["n_worlds"] == 2
    assert net["heads"] == 2 and net["multi_starts"]["cap"] == 14
    assert rnd["multi_starts"]["cap"] == 12
    assert net["feasibility_1"] == 1.0 and net["feasibility_heads"] == 1.0
    assert net["multi_starts"]["mean"] == 1.0 and net["multi_starts"]["std"] == 0.0
    assert net["iterations"]["mean"] <= 5 and net["iterations"]["n"] == 20
    assert rnd["multi_starts"]["mean"] >= 1.0
    assert net["iterations"]["mean"] < rnd["iterations"]["mean"]
    assert 0.0 <= rnd["feasibility_1"] <= 1.0
    assert rnd["solved_rate"] == 1 - rnd["multi_starts"]["n_capped"] / 20


def _brute_force(model, worlds, Ts, seeds_of, max_iterations):
    """Every seed of every target at once: (first feasible index + 1 or cap, its its, q)."""
    counts, its, qsol = [], [], []
    for w, T in zip(worlds, Ts):
        seeds = seeds_of(w, T)
        opts = IKOptions(iterations=max_iterations, stop_when_solved=False,
                         restart_after=None, freeze_solved=False)
        res = IKSolver(model, FRAME, len(T), opts, world=w, device="cpu").solve(T, seeds)
        for p in range(len(T)):
            k = np.flatnonzero(res.all_feasible[p])
            counts.append(k[0] + 1 if len(k) else seeds.shape[1])
            if len(k):
                its.append(res.all_iterations[p, k[0]])
                qsol.append(res.all_q[p, k[0]])
    return np.array(counts), np.array(its), np.array(qsol)


def test_columns_equal_a_brute_force_run(problems):
    """Blocks of seeds (a target stops once solved) give the figures of running every seed;
    U_1^q uses the solver's own default pose."""
    model, worlds, qs, Ts = problems
    net = Corner(model.n_dof)
    r = evaluate_ik(jwarp.robot(ROBOT), FRAME, worlds, Ts, warm_start=net, n_random=19, seed=4,
                    iterations=40)
    rng = np.random.default_rng(4)

    def seeds_of(w, T):
        rand = sample_within_limits(model, len(T) * 19, rng).reshape(len(T), 19, -1)
        return np.concatenate([net.seeds(T, w), rand], axis=1)

    counts, its, qsol = _brute_force(model, worlds, Ts, seeds_of, 40)
    assert r["multi_starts"]["mean"] == pytest.approx(counts.mean())
    assert r["multi_starts"]["std"] == pytest.approx(counts.std())
    assert r["multi_starts"]["n_capped"] == len(counts) - len(its)
    assert r["iterations"]["mean"] == pytest.approx(its.mean())
    qd = IKObjective(model, FRAME, 1).q_default.numpy()[0]
    assert r["length_cost"]["mean"] == pytest.approx(np.mean(0.5 * np.sum((qsol - qd) ** 2, 1)))
    assert r["feasibility_heads"] is None and r["heads"] == 1


def test_one_world_and_no_world(problems):
    model, worlds, qs, Ts = problems
    r = evaluate_ik(model, FRAME, worlds[0], Ts[0], n_random=4, iterations=30)
    assert r["n_targets"] == 10 and r["n_worlds"] == 1
    r = evaluate_ik(model, FRAME, None, np.concatenate(Ts), n_random=4)
    assert r["n_targets"] == 20 and r["solved_rate"] > 0.5
    # (W, P, 4, 4) for W worlds
    r = evaluate_ik(model, FRAME, worlds, np.stack(Ts), n_random=2, iterations=5)
    assert r["n_targets"] == 20


def test_positions_and_quaternions_as_targets(problems):
    """Issue 39 item 3: targets as (positions, quaternions xyzw), as jwarp.ik takes them:
    the same row as their poses."""
    from scipy.spatial.transform import Rotation

    from jwarp.solvers.ik.objective import pose_from_quaternions

    model, worlds, qs, Ts = problems
    p, quat = Ts[0][:, :3, 3], Rotation.from_matrix(Ts[0][:, :3, :3]).as_quat()
    a = evaluate_ik(model, FRAME, worlds[0], (p, quat), n_random=4, iterations=30)
    b = evaluate_ik(model, FRAME, worlds[0], pose_from_quaternions(p, quat), n_random=4,
                    iterations=30)
    a.pop("wall_s"), b.pop("wall_s")
    assert a == b and a["n_targets"] == 10


def test_ablation_table_and_printing(problems):
    model, worlds, qs, Ts = problems
    rows = ablation_table(jwarp.robot(ROBOT), FRAME, worlds, Ts,
                          {"full": Twin(worlds, qs), "none": Corner(model.n_dof)})
    assert [r["name"] for r in rows] == ["full", "none"]
    assert rows[0]["twin"] is True and rows[0]["boosting"] is True
    assert rows[0]["unit_vectors"] is False and rows[1]["twin"] is False
    assert rows[0]["feasibility"] == 1.0 and rows[0]["iterations"] == 10
    assert rows[1]["feasibility"] <= rows[0]["feasibility"]
    t34 = format_table_34(rows, "Table 3.4")
    for c in TABLE_34_COLUMNS:
        assert c in t34
    assert "Yes" in t34 and "No" in t34 and "after 10 solver iterations" in t34
    r0 = evaluate_ik(jwarp.robot(ROBOT), FRAME, worlds, Ts, n_random=3, iterations=5)
    r1 = evaluate_ik(jwarp.robot(ROBOT), FRAME, worlds, Ts, warm_start=Twin(worlds, qs), n_random=3,
                     name="Unsupervised")
    t35 = format_table_35([r0, r1], "Table 3.5")
    for c in TABLE_35_COLUMNS:
        assert c in t35
    lines = t35.splitlines()
    assert lines[0] == "Table 3.5"
    assert lines[3].startswith("planar5") and lines[4].lstrip().startswith("Unsupervised")
    assert "±" in lines[4] and "100.0" in lines[4]
    if r0["multi_starts"]["n_capped"]:
        assert ">=" in lines[3] and "cap of 3 seeds" in t35


def test_input_errors(problems):
    model, worlds, qs, Ts = problems
    with pytest.raises(ValueError, match="n_random"):
        evaluate_ik(jwarp.robot(ROBOT), FRAME, worlds, Ts, n_random=0)
    with pytest.raises(ValueError, match="iterations"):
        evaluate_ik(jwarp.robot(ROBOT), FRAME, worlds, Ts, iterations=-1)
    with pytest.raises(ValueError, match="targets"):
        evaluate_ik(jwarp.robot(ROBOT), FRAME, worlds, Ts[:1])
    with pytest.raises(ValueError, match="targets"):
        evaluate_ik(jwarp.robot(ROBOT), FRAME, None, np.zeros((3, 3, 3)))
    with pytest.raises(TypeError, match="warm_start"):
        evaluate_ik(jwarp.robot(ROBOT), FRAME, None, Ts[0], warm_start="model.pt")
    with pytest.raises(ValueError, match="warm_start"):
        evaluate_ik(jwarp.robot(ROBOT), FRAME, None, Ts[0], warm_start=Corner(3))
    with pytest.raises(ValueError, match="nets"):
        ablation_table(jwarp.robot(ROBOT), FRAME, None, Ts[0], {})
    with pytest.raises(TypeError, match="nets"):
        ablation_table(jwarp.robot(ROBOT), FRAME, None, Ts[0], [("x", object())])


def test_evaluate_ik_old_iterations_name_warns(problems):
    """``max_iterations`` (the name before issue 28's one vocabulary) still works for one
    release, with a DeprecationWarning, and gives the row of ``iterations``."""
    model, worlds, qs, Ts = problems
    new = evaluate_ik(model, FRAME, worlds[0], Ts[0], n_random=2, iterations=5)
    with pytest.warns(DeprecationWarning, match="'max_iterations' is renamed 'iterations'"):
        old = evaluate_ik(model, FRAME, worlds[0], Ts[0], n_random=2, max_iterations=5)
    for k in ("multi_starts", "solved_rate", "iterations", "length_cost", "max_iterations"):
        assert old[k] == new[k], k
    for it in (7, 200):   # the default value given explicitly counts too
        with pytest.raises(TypeError, match="both"):
            evaluate_ik(model, FRAME, worlds[0], Ts[0], iterations=it, max_iterations=5)
    with pytest.raises(TypeError, match="unexpected keyword argument 'max_iter'"):
        evaluate_ik(model, FRAME, worlds[0], Ts[0], max_iter=5)
