"""Warm starts in the IK solver (jwarp/solvers/ik/solver.py: IKSolver(warm_start=), ik(warm_start=),
IKOptions.n_random_with_warm_start): a duck-typed object with ``seeds(targets, world)``.
Fakes stand in for a learned network: one returning known solutions (solved in a couple of
iterations), one returning garbage (solved by the random extra seeds), bad ones (clear
errors naming ``warm_start``)."""

import numpy as np
import pytest

import jwarp
from jwarp.core.limits import sample_within_limits
from jwarp.solvers import ik as IK
from jwarp.world import collision

ROBOT, FRAME = "planar5", "tcp"


def _problems(n, seed=0):
    model = jwarp.robot(ROBOT)
    rng = np.random.default_rng(seed)
    q = sample_within_limits(model, 8 * n, rng)
    q = q[collision.is_collision_free(model, q, None, 0.0, device="cpu",
                                      dtype=np.float64)][:n]
    T = jwarp.fk(model, q, device="cpu", dtype=np.float64)[:, model.frame_index(FRAME)]
    return model, q, T


class Known:
    """Twin heads: head 1 the known solution, head 2 a configuration far from it."""

    def __init__(self, q):
        self.q = np.asarray(q, np.float64)
        self.calls = []

    def seeds(self, targets, world=None):
        self.calls.append((np.array(targets), world))
        far = np.clip(-self.q, -2.0, 2.0)
        return np.stack([self.q[:len(targets)], far[:len(targets)]], axis=1)


class Garbage:
    """One head at a joint-limit corner (a poor guess, still finite)."""

    def __init__(self, n_dof, value=50.0):
        self.n, self.value = n_dof, value

    def seeds(self, targets, world=None):
        return np.full((len(targets), 1, self.n), self.value)


class Returns:
    def __init__(self, out):
        self.out = out

    def seeds(self, targets, world=None):
        return self.out


def test_known_solutions_solve_in_few_iterations():
    model, q, T = _problems(6)
    ws = Known(q)
    solver = IK.IKSolver(ROBOT, FRAME, len(T), world=None, device="cpu", warm_start=ws)
    res = solver.solve(T)
    assert res.feasible.all()
    assert res.all_q.shape == (6, 2, model.n_dof)  # two heads, no random seeds
    assert res.iterations.max() <= 2, res.iterations
    assert np.all(res.start_index == 0)  # the known solution is chosen (lowest U_A or first)
    np.testing.assert_allclose(ws.calls[0][0], T)  # the net saw the targets
    assert ws.calls[0][1] is None  # and the solver's world


def test_warm_start_gets_the_world():
    from jwarp.world import simplex_world

    world = simplex_world(2, seed=1)
    model = jwarp.robot(ROBOT)
    ws = Known(np.zeros((1, model.n_dof)))
    T = jwarp.fk(model, np.zeros(model.n_dof), device="cpu", dtype=np.float64)[6]
    IK.IKSolver(ROBOT, FRAME, 1, world=world, device="cpu", warm_start=ws).solve(T)
    assert ws.calls[0][1] is world


def test_garbage_is_rescued_by_random_seeds():
    model, q, T = _problems(5, seed=1)
    opts = IK.IKOptions(n_random_with_warm_start=12)
    solver = IK.IKSolver(ROBOT, FRAME, len(T), opts, device="cpu",
                         warm_start=Garbage(model.n_dof))
    res = solver.solve(T)
    assert res.all_q.shape == (5, 13, model.n_dof)
    assert res.feasible.all()
    # without the random extra seeds the corner guess alone is (at best) worse
    res1 = IK.IKSolver(ROBOT, FRAME, len(T), IK.IKOptions(iterations=3), device="cpu",
                       warm_start=Garbage(model.n_dof)).solve(T)
    assert res1.all_q.shape == (5, 1, model.n_dof)
    assert res1.feasible.sum() <= res.feasible.sum()


def test_random_extra_seeds_come_from_the_solver_rng():
    model, q, T = _problems(3, seed=2)
    opts = IK.IKOptions(n_random_with_warm_start=4, iterations=0, seed=7)
    a = IK.IKSolver(ROBOT, FRAME, 3, opts, device="cpu", warm_start=Known(q))
    b = IK.IKSolver(ROBOT, FRAME, 3, opts, device="cpu", warm_start=Known(q))
    ra, rb = a.solve(T), b.solve(T)
    np.testing.assert_array_equal(ra.all_q, rb.all_q)
    assert not np.allclose(a.solve(T).all_q[:, 2:], ra.all_q[:, 2:])  # the stream moves on
    a.reseed(7)
    np.testing.assert_array_equal(a.solve(T).all_q, ra.all_q)


def test_explicit_seeds_win_over_the_warm_start():
    model, q, T = _problems(2, seed=3)
    ws = Known(q)
    solver = IK.IKSolver(ROBOT, FRAME, 2, device="cpu", warm_start=ws)
    res = solver.solve(T, seeds=np.zeros((3, model.n_dof)))
    assert res.all_q.shape == (2, 3, model.n_dof)
    assert ws.calls == []


def test_one_target_for_every_problem_is_broadcast_to_the_warm_start():
    model, q, T = _problems(1, seed=4)
    ws = Known(np.repeat(q, 3, axis=0))
    res = IK.IKSolver(ROBOT, FRAME, 3, device="cpu", warm_start=ws).solve(T[0])
    assert ws.calls[0][0].shape == (3, 4, 4)
    assert res.feasible.all()


def test_one_seed_per_target_as_2d_output():
    model, q, T = _problems(3, seed=5)
    res = IK.IKSolver(ROBOT, FRAME, 3, device="cpu", warm_start=Returns(q)).solve(T)
    assert res.all_q.shape == (3, 1, model.n_dof) and res.feasible.all()


@pytest.mark.parametrize("bad", [object(), 3, "model.pt", type("NoCall", (), {"seeds": 1})()])
def test_warm_start_without_callable_seeds_is_a_type_error(bad):
    with pytest.raises(TypeError, match="warm_start"):
        IK.IKSolver(ROBOT, FRAME, 1, device="cpu", warm_start=bad)
    with pytest.raises(TypeError, match="warm_start"):
        jwarp.ik(ROBOT, FRAME, np.eye(4), warm_start=bad)


@pytest.mark.parametrize("out, what", [
    (np.zeros((2, 1, 5)), "shape"),          # 2 problems, the solver has 3
    (np.zeros((3, 2, 4)), "shape"),          # 4 joints, planar5 has 5
    (np.zeros((3, 0, 5)), "shape"),          # no seed
    (np.zeros((3,)), "shape"),
    (np.full((3, 1, 5), np.nan), "NaN"),
    (np.full((3, 1, 5), np.inf), "NaN"),
    ("abc", "array|shape"),
    (None, "shape|array"),
])
def test_bad_warm_start_output_is_a_value_error(out, what):
    _, _, T = _problems(3, seed=6)
    solver = IK.IKSolver(ROBOT, FRAME, 3, device="cpu", warm_start=Returns(out))
    with pytest.raises(ValueError, match=f"warm_start.*({what})"):
        solver.solve(T)


def test_n_random_with_warm_start_is_validated():
    assert IK.IKOptions().n_random_with_warm_start == 0
    for bad in (-1, 1.5, True, "2"):
        with pytest.raises(ValueError, match="n_random_with_warm_start"):
            IK.IKOptions(n_random_with_warm_start=bad)
    with pytest.raises(ValueError, match="n_random_with_warm_start"):
        jwarp.ik(ROBOT, FRAME, np.eye(4), n_random_with_warm_start=-2)


def test_ik_with_warm_start():
    model, q, T = _problems(4, seed=8)
    ws = Known(q)
    res = jwarp.ik(ROBOT, FRAME, T, warm_start=ws, device="cpu")
    assert res.feasible.all() and res.iterations.max() <= 2
    assert res.all_q.shape == (4, 2, model.n_dof)
    # random extras from numpy's stream of `seed`: the same call gives the same seeds
    r1 = jwarp.ik(ROBOT, FRAME, T, warm_start=Garbage(model.n_dof), n_random_with_warm_start=10,
                  seed=3, device="cpu")
    r2 = jwarp.ik(ROBOT, FRAME, T, warm_start=Garbage(model.n_dof), n_random_with_warm_start=10,
                  seed=3, device="cpu")
    assert r1.all_q.shape == (4, 11, model.n_dof) and r1.feasible.all()
    np.testing.assert_array_equal(r1.q, r2.q)
    # seeds= win
    ws.calls.clear()
    r3 = jwarp.ik(ROBOT, FRAME, T, warm_start=ws, seeds=np.zeros(model.n_dof), device="cpu")
    assert r3.all_q.shape == (4, 1, model.n_dof) and ws.calls == []
    with pytest.raises(ValueError, match="warm_start"):
        jwarp.ik(ROBOT, FRAME, T, warm_start=Returns(np.zeros((1, 1, 5))))


def test_ik_one_target_keeps_no_leading_dim():
    model, q, T = _problems(1, seed=9)
    res = jwarp.ik(ROBOT, FRAME, T[0], warm_start=Known(q), device="cpu")
    assert res.q.shape == (model.n_dof,) and bool(res.feasible)


def test_without_warm_start_unchanged():
    """warm_start=None: the same seeds and results as before (the random stream is not
    touched by the new option)."""
    _, _, T = _problems(3, seed=10)
    a = IK.IKSolver(ROBOT, FRAME, 3, IK.IKOptions(seed=5), device="cpu").solve(T)
    b = IK.IKSolver(ROBOT, FRAME, 3, IK.IKOptions(seed=5, n_random_with_warm_start=7),
                    device="cpu").solve(T)
    np.testing.assert_array_equal(a.all_q, b.all_q)
