"""Hardening of the numerics: no silent NaN after a cast to the computing dtype, honest
elastic convergence in every check, numpy scalars accepted and bool/complex refused, and a
float32 tolerance of the elastic iteration that float32 can reach."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest
import torch
import warp as wp

import jwarp
from jwarp import kinematics as K
from jwarp.cli import main
from jwarp.core.device import put_model
from jwarp.kinematics.autodiff import tape_jacobian
from jwarp.kinematics.compensation import CompensationRows
from jwarp.solvers import planning as PL
from jwarp.solvers.ik import ik
from jwarp.world import path_feasibility, world_from_occupancy
from jwarp.world.collision import collision_cost, is_collision_free, min_distances
from jwarp.world.feasibility import random_configurations

BIG = 1e39  # finite in float64, inf in float32
Z19 = np.zeros(19)
F32 = dict(device="cpu", dtype=np.float32)


@pytest.fixture(scope="module")
def block_world():
    """planar4's workspace (README): a block in front of the base at x in (0.5, 0.75)."""
    lim = np.array([[-1.0, 1.0], [-1.0, 1.0]])
    h = 2.0 / 63
    X, Y = np.meshgrid(*[lim[d, 0] + h * np.arange(64) for d in range(2)], indexing="ij")
    return world_from_occupancy((X > 0.5) & (X < 0.75) & (np.abs(Y) < 0.12), lim, h)


def _big(n=19):
    q = np.zeros(n)
    q[3] = BIG
    return q


# ---------------------------------------------------------------- 3. no silent NaN
@pytest.mark.parametrize("call,name", [
    (lambda: jwarp.fk("justin19", [BIG] * 19), "q"),  # list -> float32
    (lambda: K.fk("justin19", _big(), **F32), "q"),
    (lambda: K.jacobian("justin19", _big(), "right_tcp", **F32), "q"),
    (lambda: K.jacobian_dh("justin19", _big(), "right_tcp", **F32), "q"),
    (lambda: K.fk_elastic("justin19", _big(), 1e-4, **F32), "q"),
    (lambda: K.gravity_torques("justin19", _big(), **F32), "q"),
    (lambda: K.elastic_step("justin19", _big(), None, 1e-4, **F32), "q"),
    (lambda: K.fk("justin19", torch.tensor(_big()), **F32), "q"),
    (lambda: K.fk("justin19", torch.tensor(_big(), requires_grad=True), **F32), "q"),
    (lambda: K.fk_elastic("justin19", Z19, BIG, **F32), "kappa"),
    (lambda: K.fk_elastic("justin19", Z19, [1e-4, BIG, 1e-4], **F32), "kappa"),
    (lambda: K.fk("justin19", Z19, dh=np.full((27, 5), BIG), **F32), "dh"),
    (lambda: K.fk_elastic("justin19", Z19, 1e-4, dh=np.full((27, 5), BIG), **F32), "dh"),
    (lambda: K.elastic_step("justin19", Z19, np.full((27, 5), BIG), 1e-4, **F32), "rho"),
    (lambda: K.jacobian("justin19", Z19, "right_tcp", point=[BIG, 0, 0], **F32), "point"),
    (lambda: tape_jacobian(jwarp.robot("arm7"), np.zeros((1, 7)), "tcp", kappa=BIG, iterations=1, **F32),
     "kappa"),
    (lambda: collision_cost(jwarp.robot("planar4"), _big(4)[None], None, **F32), "q"),
    (lambda: min_distances(jwarp.robot("planar4"), np.zeros((1, 4)), rho=np.full((6, 5), BIG), **F32), "rho"),
    (lambda: collision_cost(jwarp.robot("planar4"), np.zeros((1, 4)), None, eps=BIG, **F32), "eps"),
    (lambda: CompensationRows(put_model(jwarp.robot("arm7"), "cpu", np.float32), 1, 2, 1, BIG, 0.5),
     "kappa"),
])
def test_overflow_in_the_computing_dtype_is_a_value_error(call, name):
    """1e39 is finite in float64 and inf in float32: the check runs after the cast."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with pytest.raises(ValueError, match=rf"^{name}: .*float32"):
            call()
    assert not [w for w in caught if issubclass(w.category, RuntimeWarning)]  # no numpy noise


def test_overflow_names_the_batch_row_and_float64_still_computes():
    q = np.zeros((3, 19))
    q[2, 5] = BIG
    with pytest.raises(ValueError, match=r"q: values overflow float32 .*batch rows \[2\]"):
        K.fk("justin19", q, **F32)
    with pytest.raises(ValueError, match=r"q: values overflow float32 .*batch rows \[2\]"):
        K.fk("justin19", torch.tensor(q), **F32)
    # NaN keeps its own message
    with pytest.raises(ValueError, match=r"q: contains NaN or inf \(batch rows \[1\]\)"):
        K.fk("justin19", np.array([Z19, np.full(19, np.nan)], np.float32))
    # the same input computes in float64 (finite there)
    assert np.isfinite(K.jacobian("justin19", q[:2], 13, device="cpu")).all()


def test_planner_and_ik_check_their_inputs_in_the_solver_dtype(block_world):
    T = jwarp.fk("arm7", np.full(7, 0.3))[jwarp.robot("arm7").frame_index("tcp")]
    far = T.copy()
    far[0, 3] = BIG
    with pytest.raises(ValueError, match="^target: values overflow float32"):
        ik("arm7", "tcp", far, n_starts=2, iterations=2, dtype=np.float32)
    with pytest.raises(ValueError, match="^seeds: values overflow float32"):
        ik("arm7", "tcp", T, seeds=_big(7), iterations=2, dtype=np.float32)
    obj = PL.PathObjective("planar4", block_world, 1, 3, 2, device="cpu", dtype=np.float32)
    paths = np.zeros((1, 3, 4))
    paths[0, 1, 1] = BIG
    with pytest.raises(ValueError, match="^paths: values overflow float32"):
        obj.set_paths(paths)
    with pytest.raises(ValueError, match="^paths: values overflow float32"):
        path_feasibility.substeps(paths, 2, dtype=np.float32)


# ------------------------------------------------------- 4. honest elastic answers
def test_fk_elastic_max_iter_0_converged_only_if_rigid_is_the_equilibrium():
    model = jwarp.robot("justin19")
    q = random_configurations(model, 8, seed=3)
    rigid = K.fk(model, q, device="cpu")
    soft = K.fk_elastic(model, q, 1e-4, max_iter=0, device="cpu")
    np.testing.assert_array_equal(soft.frames, rigid)  # still the rigid FK
    assert (soft.iterations == 0).all() and not soft.converged.any()
    stiff = K.fk_elastic(model, q, 0.0, max_iter=0, device="cpu")  # rigid = equilibrium
    assert stiff.converged.all() and (stiff.iterations == 0).all()
    # a loose tolerance that the first update meets counts as converged (per configuration)
    d = np.asarray(K.elastic_step(model, q, None, 1e-4, device="cpu").delta)
    tol = float(np.median(d))
    res = K.fk_elastic(model, q, 1e-4, max_iter=0, tol=tol, device="cpu")
    np.testing.assert_array_equal(res.converged, d <= tol)
    assert 0 < res.converged.sum() < len(q)
    tq = K.fk_elastic(model, torch.tensor(q, requires_grad=True), 1e-4, max_iter=0, device="cpu")
    assert not bool(tq.converged.any())


def test_cli_fk_elastic_max_iter_0_is_not_converged(capsys):
    code = main(["fk", "justin19", "--elastic", "--max-iter", "0", "--json"])
    out, _ = capsys.readouterr()
    d = json.loads(out)
    assert code == 0 and d["iterations"] == 0 and d["converged"] is False
    code = main(["fk", "justin19", "--elastic", "--kappa", "0", "--max-iter", "0", "--json"])
    out, _ = capsys.readouterr()
    assert json.loads(out)["converged"] is True


def test_collision_checks_use_only_converged_equilibria(block_world):
    """planar4 with kappa = 0.1 rad/(N m): the damped iteration of the checks does not
    converge (its rows are finite but not an equilibrium): not collision-free, and a
    start/goal on it is an error that says so."""
    model = jwarp.robot("planar4")
    q = np.array([[1.2, 0.0, 0.0, 0.0], [-1.2, 0.0, 0.0, 0.0]])
    eq = K.fk_elastic(model, q, 0.1, lam=0.7, max_iter=30, tol=1e-7, device="cpu",
                      dtype=np.float64)  # what the checks solve
    rho = np.asarray(eq.rho)
    assert not eq.converged.any() and np.isfinite(rho).all()
    assert path_feasibility.collision_free(model, block_world, q, 0.0).all()  # rigid: free
    assert path_feasibility.collision_free(model, block_world, q, 0.0, kappa=1e-3).all()  # converges: free
    assert not path_feasibility.collision_free(model, block_world, q, 0.0, kappa=0.1).any()
    # the same rows handed in as rho are free: only convergence makes the difference
    assert path_feasibility.collision_free(model, block_world, q, 0.0, rho=rho).all()
    with pytest.raises(ValueError, match=r"^kappa: the elastic equilibrium at start .*does not converge"):
        PL.plan(model, block_world, q[0], q[1], kappa=0.1, iterations=2, n_starts=1)
    # per-configuration compliances: the error names the row that does not converge
    mask = model.is_dh.astype(float)[:, None]
    kap = np.stack([np.full((model.n_frames, 3), 1e-3), np.full((model.n_frames, 3), 0.1)])
    with pytest.raises(ValueError, match=r"^kappa: the elastic equilibrium at goal\[1\]"):
        path_feasibility.check_endpoints(model, block_world, q, "goal", 0.0, kap * mask)
    path_feasibility.check_endpoints(model, block_world, q, "goal", 0.0, kap[0] * mask)  # both converge
    path = path_feasibility.initial_paths(q[:1], np.array([[1.0, 0.0, 0.0, 0.0]]), 4)[0]
    assert path_feasibility.path_feasible(model, block_world, path, 4)
    assert path_feasibility.path_feasible(model, block_world, path, 4, kappa=1e-3)
    assert not path_feasibility.path_feasible(model, block_world, path, 4, kappa=0.1)


def test_elastic_ik_is_infeasible_where_the_rows_do_not_converge():
    """arm7 with kappa = 0.1: the compensation rows never settle, so no start reaches the
    target with a converged equilibrium; with kappa = 1e-3 the same problem is solved."""
    model = jwarp.robot("arm7")
    T = jwarp.fk(model, np.full(7, 0.3))[model.frame_index("tcp")]
    soft = ik(model, "tcp", T, n_starts=4, iterations=40, kappa=0.1, seed=1)
    assert not soft.feasible and soft.n_feasible == 0
    ok = ik(model, "tcp", T, n_starts=4, iterations=40, kappa=1e-3, seed=1)
    assert ok.feasible


# ------------------------------------------------------------ 7. small API mends
def test_numpy_scalars_are_accepted_where_floats_are(block_world):
    q = random_configurations("justin19", 4, seed=5)
    k, lam, tol = np.float32(1e-4), np.float32(0.7), np.float32(1e-8)
    ref = K.fk_elastic("justin19", q, float(k), lam=float(lam), tol=float(tol), device="cpu")
    got = K.fk_elastic("justin19", q, k, lam=lam, tol=tol, device="cpu")
    np.testing.assert_array_equal(got.frames, ref.frames)
    np.testing.assert_array_equal(got.iterations, ref.iterations)
    step = K.elastic_step("justin19", q, None, 1e-4, lam=np.float64(0.5), device="cpu")
    assert np.isfinite(step.rho).all()
    t = put_model(jwarp.robot("arm7"), "cpu", np.float64)
    rows = CompensationRows(t, 1, 2, 1, np.float32(1e-4), np.float32(0.5))
    assert rows.kappa.numpy().max() == pytest.approx(1e-4)
    qp = np.zeros((2, 4))
    assert (is_collision_free(jwarp.robot("planar4"), qp, block_world, np.float32(0.01)) ==
            is_collision_free(jwarp.robot("planar4"), qp, block_world, 0.01)).all()
    c32, _ = collision_cost(jwarp.robot("planar4"), qp, block_world, eps=np.float32(0.05),
                            w_world=np.float16(1.0), device="cpu")
    c, _ = collision_cost(jwarp.robot("planar4"), qp, block_world, eps=0.05, device="cpu")
    np.testing.assert_allclose(c32, c, rtol=1e-7)
    res = PL.plan("planar4", block_world, [1.2, 0, 0, 0], [-1.2, 0, 0, 0], n_starts=2,
                  iterations=np.int64(3), step=np.float32(0.05), max_step=np.float32(0.1),
                  margin=np.float32(0.0), weights=PL.PathWeights(np.float32(1.0)),
                  n_substeps=2)
    assert res.path.shape == (1, 20, 4)
    arm = jwarp.robot("arm7")
    sol = ik(arm, "tcp", jwarp.fk(arm, np.full(7, 0.3))[arm.frame_index("tcp")], n_starts=2,
             iterations=3, tol_pos=np.float32(1e-4), step=np.float64(1.0),
             damping=np.float32(1e-3))
    assert sol.q.shape == (7,)


@pytest.mark.parametrize("call,name", [
    (lambda: K.fk("justin19", True), "q"),
    (lambda: K.fk("justin19", [True] * 19), "q"),
    (lambda: K.fk("justin19", np.ones(19, bool)), "q"),
    (lambda: K.fk_elastic("justin19", Z19, True), "kappa"),
    (lambda: K.fk_elastic("justin19", Z19, [True, False, True]), "kappa"),
    (lambda: K.fk_elastic("justin19", Z19, 1e-4, lam=True), "lam"),
    (lambda: K.fk_elastic("justin19", Z19, 1e-4, tol=False), "tol"),
    (lambda: K.fk_elastic("justin19", Z19, 1e-4, max_iter=True), "max_iter"),
    (lambda: K.elastic_step("justin19", Z19, None, 1e-4, lam=np.bool_(True)), "lam"),
    (lambda: is_collision_free(jwarp.robot("planar4"), np.zeros(4), None, True), "margin"),
    (lambda: collision_cost(jwarp.robot("planar4"), np.zeros(4), None, eps=True), "eps"),
    (lambda: ik("arm7", "tcp", np.eye(4), tol_pos=True), "tol_pos"),
    (lambda: ik("arm7", "tcp", np.eye(4), margin=True), "margin"),
    (lambda: CompensationRows(put_model(jwarp.robot("arm7"), "cpu", np.float64), 1, 2, 1, 1e-4,
                              True), "lam"),
])
def test_bool_is_refused_where_a_number_is_meant(call, name):
    with pytest.raises((TypeError, ValueError), match=rf"^{name}"):
        call()


def test_bool_lam_and_kappa_are_type_errors(block_world):
    with pytest.raises(TypeError, match="^lam: expected a real number, got bool"):
        K.fk_elastic("justin19", Z19, 1e-4, lam=True)
    with pytest.raises(TypeError, match="^kappa: expected numbers, got booleans"):
        K.fk_elastic("justin19", Z19, True)
    with pytest.raises(TypeError, match="^q: expected numbers, got booleans"):
        K.fk("justin19", True)
    with pytest.raises(TypeError, match="^step: expected a real number"):
        PL.plan("planar4", block_world, [1.2, 0, 0, 0], [-1.2, 0, 0, 0], step=True)


@pytest.mark.parametrize("q", [np.zeros(19, complex), np.zeros(19, np.complex64) + 0.5j,
                               [0.1 + 0j] * 19])
def test_complex_q_is_a_type_error(q):
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # numpy's ComplexWarning would be a silent drop
        with pytest.raises(TypeError, match="^q: expected real numbers, got complex"):
            K.fk("justin19", q)
        with pytest.raises(TypeError, match="^q: expected real numbers"):
            path_feasibility.collision_free(jwarp.robot("justin19"), None, np.asarray(q)[None], 0.0)


def test_complex_arguments_are_type_errors():
    with pytest.raises(TypeError, match="^kappa"):
        K.fk_elastic("justin19", Z19, 1e-4 + 0j)
    with pytest.raises(TypeError, match="^dh"):
        K.fk("justin19", Z19, dh=jwarp.robot("justin19").dh_table.astype(complex))
    with pytest.raises(TypeError, match="^target"):
        ik("arm7", "tcp", np.eye(4, dtype=complex))
    with pytest.raises(TypeError, match="^lam"):
        K.fk_elastic("justin19", Z19, 1e-4, lam=0.5 + 0j)
    with pytest.raises(TypeError, match="^q"):
        K.fk("justin19", torch.zeros(19, dtype=torch.complex64))


# ----------------------------------------------------- 8. float32 elastic tolerance
def test_float32_default_tolerance_reports_converged_configurations(capsys):
    model = jwarp.robot("justin19")
    q = random_configurations(model, 1000, seed=0)
    f64 = K.fk_elastic(model, q, 1e-4, device="cpu")
    f32 = K.fk_elastic(model, q.astype(np.float32), 1e-4, device="cpu")
    strict = K.fk_elastic(model, q.astype(np.float32), 1e-4, tol=1e-9, device="cpu")
    print(f"\njustin19, 1000 random q, kappa 1e-4, max_iter 10: converged float32 "
          f"default tol {f32.converged.mean():.1%} (tol 1e-9: {strict.converged.mean():.1%}),"
          f" float64 {f64.converged.mean():.1%}; median updates float32 "
          f"{np.median(f32.iterations):.0f}, float64 {np.median(f64.iterations):.0f}")
    assert f64.converged.all()
    assert f32.converged.all()
    assert strict.converged.mean() < 0.99  # float32 rows cannot resolve 1e-9 rad
    # converged to float32 resolution: the frames agree with the float64 equilibrium
    np.testing.assert_allclose(f32.frames[..., :3, 3], f64.frames[..., :3, 3], atol=5e-6)
    # ... and the tolerance is not so loose that a short iteration passes for converged
    assert not K.fk_elastic(model, q[:100].astype(np.float32), 1e-4, max_iter=3,
                            device="cpu").converged.any()


def test_float64_keeps_its_tolerance_1e_9():
    model = jwarp.robot("justin19")
    q = random_configurations(model, 200, seed=4)
    default = K.fk_elastic(model, q, 1e-4, device="cpu")
    explicit = K.fk_elastic(model, q, 1e-4, tol=1e-9, device="cpu")
    looser = K.fk_elastic(model, q, 1e-4, tol=2e-9, device="cpu")
    tighter = K.fk_elastic(model, q, 1e-4, tol=5e-10, device="cpu")
    np.testing.assert_array_equal(default.iterations, explicit.iterations)
    np.testing.assert_array_equal(default.rho, explicit.rho)
    assert (looser.iterations != default.iterations).any()
    assert (tighter.iterations != default.iterations).any()
    assert K.default_tol(np.float64) == 1e-9
    # torch and warp float32 input get the float32 default too
    wq = wp.array(q.astype(np.float32), dtype=wp.float32, device="cpu")
    tq = torch.tensor(q, dtype=torch.float32)
    ref = K.fk_elastic(model, q.astype(np.float32), 1e-4, device="cpu")
    np.testing.assert_array_equal(K.fk_elastic(model, wq, 1e-4).iterations, ref.iterations)
    np.testing.assert_array_equal(K.fk_elastic(model, tq, 1e-4).iterations.numpy(),
                                  ref.iterations)
