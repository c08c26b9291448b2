"""Sensitivity analysis (eqs. 2.23-2.24) and optimal experimental design (eqs. 2.25-2.26):
closed forms, numpy references, brute force, finite differences, bad input."""

import itertools

import numpy as np
import pytest

from jwarp.calibration.design.optimal import (
    DesignOptions,
    _State,
    candidate_jacobians,
    criterion,
    design,
    detmax,
    greedy,
    select,
    task_factor,
)
from jwarp.calibration.design.sensitivity import (
    kernel_basis,
    kernel_inclusion,
    sensitivity,
    spectrum,
    stacked_jacobian,
)
from jwarp.calibration.estimate.params import ParameterSpace
from jwarp.calibration.estimate.result import model_frames
from jwarp.calibration.files import Setup, make_measurement
from jwarp.calibration.pool import configurations_text, draw_configurations, parse_configurations
from jwarp.calibration.simulate.campaign import uniform_configurations
from jwarp.calibration.simulate.scenarios import hand_contact_setup
from jwarp.plugins.registry import robot as get_robot


@pytest.fixture(scope="module")
def hand():
    return get_robot("hand4")


def relative(hand, fingers=("thumb", "index")):
    return make_measurement(hand, Setup(plugin="relative", robot="hand4", section={
        "end_effectors": [f"{f}_tip" for f in fingers], "noise": 0.001}))


def with_kernel(rng, rows, P, kernel):
    """A random (rows, P) matrix whose kernel is exactly span(kernel columns)."""
    K = np.linalg.qr(np.asarray(kernel, float))[0]
    return rng.normal(size=(rows, P)) @ (np.eye(P) - K @ K.T)


# ----------------------------------------------------------------- matrices
def test_spectrum_matches_numpy_and_rank():
    rng = np.random.default_rng(0)
    J = with_kernel(rng, 12, 6, np.eye(6)[:, [1, 4]])
    sp = spectrum(J)
    ref = np.sort(np.linalg.eigvalsh(J.T @ J))[::-1]
    assert np.allclose(sp.eigenvalues, np.maximum(ref, 0), atol=1e-12)
    assert sp.n_identifiable == np.linalg.matrix_rank(J) == 4
    assert sp.n_params == 6
    # an absolute threshold above the smallest real eigenvalue removes it
    assert spectrum(J, atol=0.5 * (ref[3] + ref[2])).n_identifiable == 3
    K = kernel_basis(J)
    assert K.shape == (6, 2) and np.allclose(J @ K, 0, atol=1e-10)


def test_kernel_inclusion_true_and_false():
    rng = np.random.default_rng(1)
    e = np.eye(5)
    Ja = with_kernel(rng, 20, 5, e[:, [0]])
    Jt = with_kernel(rng, 20, 5, e[:, [0, 1]])
    ok, dirs = kernel_inclusion(Ja, Jt)
    assert ok and dirs == []
    # reversed: the actual misses p1, which the task sees
    ok, dirs = kernel_inclusion(Jt, Ja, names=list("abcde"))
    assert not ok and len(dirs) == 1
    assert abs(abs(dirs[0].vector[1]) - 1) < 1e-9
    assert dirs[0].top[0][0] == "b" and dirs[0].top[0][1] > 0
    assert np.isclose(dirs[0].task_gain,
                      np.linalg.norm(Ja @ dirs[0].vector) ** 2 / np.linalg.eigvalsh(Ja.T @ Ja)[-1])
    # a mixed direction: kernel of the actual (p0 + p1), the task sees p0 - p1 only
    Ja = with_kernel(rng, 20, 5, (e[:, 0] + e[:, 1])[:, None])
    Jt = with_kernel(rng, 20, 5, e[:, [2, 3, 4]])
    ok, dirs = kernel_inclusion(Ja, Jt, names=list("abcde"))
    assert not ok and {n for n, _ in dirs[0].top} == {"a", "b"}


@pytest.mark.parametrize("bad, match", [
    (lambda: spectrum(np.zeros(3)), "J: "),
    (lambda: spectrum(np.array([[np.nan, 1.0]])), "J: contains NaN"),
    (lambda: spectrum(np.eye(2), rtol=-1.0), "rtol: "),
    (lambda: spectrum(np.eye(2), rtol=0.0, atol=0.0), "rtol, atol: "),
    (lambda: kernel_inclusion(np.eye(3), np.eye(4)), "Ja, Jt: "),
    (lambda: kernel_inclusion(np.eye(3), np.eye(3), names=["a"]), "names: "),
])
def test_matrix_errors(bad, match):
    with pytest.raises(ValueError, match=match):
        bad()


# ------------------------------------------------------------ measurements
def test_stacked_jacobian_finite_differences(hand):
    """Unwhitened rows against central differences of the prediction; one configuration
    (fewer rows than parameters: the repeated-sample path)."""
    meas = relative(hand)
    q = uniform_configurations(hand, np.random.default_rng(2), 1)
    J, names = stacked_jacobian(hand, meas, q, "theta,d,alpha")
    space = ParameterSpace.build(hand, meas, "theta,d,alpha")
    assert names == space.names and J.shape == (3, space.size)
    h = 1e-6
    for i in range(space.size):
        x = space.nominal.copy()
        x[i] += h
        yp = meas.predict(model_frames(space.robot_at(x), q), meas.params.nominal)
        x[i] -= 2 * h
        ym = meas.predict(model_frames(space.robot_at(x), q), meas.params.nominal)
        assert np.allclose(J[:, i], ((yp - ym) / (2 * h))[0], atol=1e-7)
    Jw, _ = stacked_jacobian(hand, meas, q, "theta,d,alpha", whiten=True)
    assert np.allclose(Jw, J / 0.001)


def test_parallel_axes_give_the_known_kernel(hand):
    """Fingertip positions with only the d offsets free: each finger's three parallel
    flexion axes leave two combinations of their d's (a shift along the common axis)
    unidentifiable, nothing else."""
    meas = relative(hand)
    q = uniform_configurations(hand, np.random.default_rng(3), 40)
    J, names = stacked_jacobian(hand, meas, q, "d")
    K = kernel_basis(J)
    assert K.shape[1] == 4
    expect = []
    for f in ("thumb", "index"):
        a, b, c = (names.index(f"{f}_{p}.d") for p in ("proximal", "intermediate", "distal"))
        for i, j in ((a, b), (b, c)):
            v = np.zeros(len(names))
            v[i], v[j] = 1.0, -1.0
            expect.append(v)
    E = np.array(expect).T
    assert np.allclose(J @ E, 0, atol=1e-12)
    # the numerical kernel is exactly their span
    assert np.linalg.matrix_rank(np.hstack([K, E]), tol=1e-8) == 4


def test_hand_one_pair_as_the_thesis(hand):
    """One contact pair vs its relative task (Fig. 2.8, leftmost mode): 26 vs 27 of 32, and
    the contact kernel is not inside the task's (one direction)."""
    setup = hand_contact_setup(pairs=(("thumb", "index"),))
    q, meta = draw_configurations(hand, setup, 120, seed=0)
    qt = uniform_configurations(hand, np.random.default_rng(4), 60)
    res = sensitivity(hand, make_measurement(hand, setup), q, relative(hand), qt,
                      "theta,d,r,alpha", meta_actual=meta)
    assert (res.actual.n_identifiable, res.task.n_identifiable, res.actual.n_params) == (26, 27, 32)
    assert not res.kernel_included and len(res.breaking) == 1
    d = res.breaking[0].to_dict()
    assert d["top"] and all(t["name"] in res.names for t in d["top"])
    doc = res.to_dict()
    assert doc["kernel_included"] is False and len(doc["actual"]["eigenvalues"]) == 32


def test_sensitivity_errors(hand):
    meas = relative(hand)
    q = uniform_configurations(hand, np.random.default_rng(5), 5)
    with pytest.raises(ValueError, match="free: unknown parameter group"):
        sensitivity(hand, meas, q, meas, q, "theta,bogus")
    with pytest.raises(ValueError, match=r"q: expected shape"):
        sensitivity(hand, meas, q[:, :3], meas, q, "theta")
    with pytest.raises(ValueError, match="free: unknown parameter group"):
        stacked_jacobian(hand, meas, q, "theta,radii")    # a group of another plugin
    with pytest.raises(ValueError, match="q: contains NaN"):
        stacked_jacobian(hand, meas, np.full((2, hand.n_dof), np.nan), "theta")


# -------------------------------------------------------------------- design
def random_problem(rng, n=8, m=1, P=5, r=3):
    U = rng.normal(size=(n, m, P))
    prior = rng.uniform(0.5, 2.0, P)
    L = task_factor(rng.normal(size=(r, P)))
    return U, prior, L


def test_task_factor():
    rng = np.random.default_rng(6)
    Jt = rng.normal(size=(7, 5)) @ np.diag([1, 1, 1, 0, 0]) @ np.linalg.qr(rng.normal(size=(5, 5)))[0]
    L = task_factor(Jt)
    assert L.shape == (5, 3)
    assert np.allclose(L @ L.T, Jt.T @ Jt / 7)


@pytest.mark.parametrize("m", [1, 2])
def test_logdet_updates_match_slogdet(m):
    rng = np.random.default_rng(7 + m)
    U, prior, L = random_problem(rng, n=10, m=m)
    st = _State(U, prior, L, refresh=1000)
    chosen = [0, 3, 5]
    for i in chosen:
        st.apply(i, +1)
    base = criterion(U, prior, L, chosen)
    assert np.isclose(st.value, base)
    rest = np.array([i for i in range(10) if i not in chosen])
    add = st.deltas(rest, +1)
    for i, d in zip(rest, add):
        assert np.isclose(d, criterion(U, prior, L, chosen + [int(i)]) - base, atol=1e-10)
    rem = st.deltas(np.array(chosen), -1)
    for i, d in zip(chosen, rem):
        assert np.isclose(d, criterion(U, prior, L, [j for j in chosen if j != i]) - base,
                          atol=1e-10)
    # plain D-optimality (L = None, the square-L shortcut): c = log det A
    full = _State(U, prior, np.eye(5), refresh=1000)
    for i in chosen:
        full.apply(i, +1)
    for eps, idx in ((+1, rest), (-1, np.array(chosen))):
        for i, d in zip(idx, full.deltas(idx, eps)):
            after = chosen + [int(i)] if eps > 0 else [j for j in chosen if j != i]
            assert np.isclose(d, criterion(U, prior, None, after)
                              - criterion(U, prior, None, chosen), atol=1e-10)
    A = np.diag(prior) + sum(U[i].T @ U[i] for i in chosen)
    assert np.isclose(criterion(U, prior, None, chosen), np.linalg.slogdet(A)[1])


def test_greedy_and_detmax_vs_brute_force():
    """DETMAX is a local search: never worse than its greedy start, never above the
    exhaustive optimum, and on these tiny pools (N = 2 of 8) it finds the optimum in most
    cases where greedy does not."""
    rng = np.random.default_rng(8)
    hits = greedy_hits = 0
    for trial in range(12):
        U, prior, L = random_problem(rng, m=1 + trial % 2)
        best = max(criterion(U, prior, L, c) for c in itertools.combinations(range(8), 2))
        g, d = greedy(U, prior, L, 2), detmax(U, prior, L, 2)
        assert np.isclose(g.criterion, criterion(U, prior, L, g.indices))
        assert np.isclose(d.criterion, criterion(U, prior, L, d.indices))
        assert g.criterion <= d.criterion + 1e-12 <= best + 1e-9
        hits += bool(np.isclose(d.criterion, best))
        greedy_hits += bool(np.isclose(g.criterion, best))
        assert len(set(d.indices.tolist())) == 2
    assert hits >= 10 and hits > greedy_hits, (hits, greedy_hits)


def test_detmax_never_decreases():
    rng = np.random.default_rng(9)
    U, prior, L = random_problem(rng, n=300, m=1, P=12, r=8)
    res = detmax(U, prior, L, 20, start="random", seed=3)
    assert res.iterations > 3
    assert np.all(np.diff(res.history) > 0)
    assert res.criterion >= res.history[0]
    g = greedy(U, prior, L, 20)
    assert np.all(np.diff(g.history) > 0) and g.criterion > g.prior_criterion


@pytest.mark.parametrize("call, match", [
    (lambda U, p, L: select(U, p, L, DesignOptions(n=20)), "n: 20 configurations asked"),
    (lambda U, p, L: select(U, p, L, DesignOptions(n=2, method="best")), "method: "),
    (lambda U, p, L: select(U, -p, L, DesignOptions(n=2)), "prior: "),
    (lambda U, p, L: select(np.where(np.arange(8)[:, None, None] == 5, np.nan, U), p, L,
                            DesignOptions(n=2)), r"U: NaN or inf in candidate\(s\) \[5\]"),
    (lambda U, p, L: select(U, p, L[:2], DesignOptions(n=2)), "L: "),
    (lambda U, p, L: select(U, p, L, DesignOptions(n=0)), "n: expected an integer"),
])
def test_design_errors(call, match):
    U, prior, L = random_problem(np.random.default_rng(10))
    with pytest.raises(ValueError, match=match):
        call(U, prior, L)


def test_candidate_jacobians_batches(hand):
    setup = hand_contact_setup()
    meas = make_measurement(hand, setup)
    q, meta = draw_configurations(hand, setup, 7, seed=1)
    U, space = candidate_jacobians(hand, meas, q, "theta,r", meta=meta, chunk=3)
    J, names = stacked_jacobian(hand, meas, q, "theta,r", meta=meta, whiten=True)
    assert names == space.names and np.allclose(U[:, 0], J)


def test_the_robot_is_resolved_at_the_entry(hand, monkeypatch):
    """The Jacobian helpers take the RobotModel (a name is a TypeError naming robot);
    design and sensitivity take a name too and resolve it once, at their entry (issue 40
    item 2): the same result as with the model."""
    import importlib

    opt = importlib.import_module("jwarp.calibration.design.optimal")
    sens = importlib.import_module("jwarp.calibration.design.sensitivity")
    from jwarp.calibration.estimate.diagnostics import residual_diagnostics

    setup = hand_contact_setup()
    meas = make_measurement(hand, setup)
    q, meta = draw_configurations(hand, setup, 12, seed=4)
    for call in (lambda r: stacked_jacobian(r, meas, q, "theta", meta=meta),
                 lambda r: candidate_jacobians(r, meas, q, "theta", meta=meta),
                 lambda r: opt.task_information(r, relative(hand), q, ["x"], "theta"),
                 lambda r: residual_diagnostics(r, meas, meas.params.nominal, q,
                                                np.zeros((12, meas.n_obs)), meta)):
        with pytest.raises(TypeError, match="robot: expected a RobotModel"):
            call("hand4")
    resolved = []
    for mod in (opt, sens):
        real = mod.get_robot
        monkeypatch.setattr(mod, "get_robot", lambda r, real=real: resolved.append(r) or real(r))
    opts = DesignOptions(n=4)
    by_name = design("hand4", meas, q, opts, free="theta", meta_pool=meta)
    assert resolved == ["hand4"]
    by_model = design(hand, meas, q, opts, free="theta", meta_pool=meta)
    np.testing.assert_array_equal(by_name.indices, by_model.indices)
    assert by_name.criterion == by_model.criterion
    task = relative(hand)
    qt = uniform_configurations(hand, np.random.default_rng(3), 6)
    a = sensitivity("hand4", meas, q, task, qt, "theta", meta_actual=meta)
    b = sensitivity(hand, meas, q, task, qt, "theta", meta_actual=meta)
    assert resolved == ["hand4", hand, "hand4", hand]
    assert a.to_dict() == b.to_dict()


def test_design_on_hand_contacts(hand):
    """Task D-optimal contacts beat the same number of random ones on the criterion."""
    setup = hand_contact_setup()
    meas = make_measurement(hand, setup)
    q, meta = draw_configurations(hand, setup, 400, seed=2)
    qt = uniform_configurations(hand, np.random.default_rng(11), 100)
    task = relative(hand, ("thumb", "index", "middle", "ring"))
    res = design(hand, meas, q, DesignOptions(n=30), free="theta,d,r,alpha", meta_pool=meta,
                 task=task, q_task=qt)
    U, space = candidate_jacobians(hand, meas, q, "theta,d,r,alpha", meta=meta)
    from jwarp.calibration.design.optimal import prior_information, task_information

    L, _ = task_information(hand, task, qt, space.names, "theta,d,r,alpha")
    prior = prior_information(space)
    assert np.isclose(res.criterion, criterion(U, prior, L, res.indices))
    rand = [criterion(U, prior, L, np.random.default_rng(s).choice(400, 30, replace=False))
            for s in range(5)]
    assert res.criterion > max(rand)


# ---------------------------------------------------------------- pool files
def test_pool_roundtrip_and_errors(hand):
    meas = make_measurement(hand, hand_contact_setup())
    q = uniform_configurations(hand, np.random.default_rng(12), 4)
    text = configurations_text(hand, meas, q, {"pair": np.array([0, 1, 2, 0])})
    s = parse_configurations(text, hand, meas)
    assert np.array_equal(s.q, q) and s.meta["pair"].tolist() == [0, 1, 2, 0]
    # observed columns are allowed (a samples file is a pool) and ignored
    lines = text.splitlines()
    with_obs = "\n".join([lines[0] + ",distance"] + [ln + ",0.0" for ln in lines[1:]])
    assert np.array_equal(parse_configurations(with_obs, hand, meas).q, q)
    with pytest.raises(ValueError, match="--candidates: missing column 'thumb_abd'"):
        parse_configurations(text.replace("thumb_abd", "thumb_x", 1), hand, meas)
    with pytest.raises(ValueError, match="--candidates: unknown column 'extra'"):
        parse_configurations("\n".join([lines[0] + ",extra"] + [ln + ",1" for ln in lines[1:]]),
                             hand, meas)
    bad = text.rsplit(",", 1)[0] + ",7\n"
    with pytest.raises(ValueError, match="line 5, column 'pair'"):
        parse_configurations(bad, hand, meas)


def test_candidate_jacobians_on_every_device(device):
    """The candidates' Jacobians on ``device`` (rigid hand4 contacts, and the elastic
    justin19 tracker through the torque equilibrium) equal finite differences of the
    predictions on the CPU; CPU and CUDA agree to round-off."""
    from jwarp.calibration.estimate.map import CalibrationProblem, problem_options
    from jwarp.calibration.simulate.campaign import justin_tracker_setup

    robot = get_robot("justin19")
    meas = make_measurement(robot, justin_tracker_setup())
    q = uniform_configurations(robot, np.random.default_rng(4), 16)
    free = "theta,kappa_theta,tracker,markers"
    U, space = candidate_jacobians(robot, meas, q, free, device=device, elastic=True)
    prob = CalibrationProblem(robot, meas, q, np.zeros((len(q), len(meas.obs_names))),
                              problem_options(free=free, elastic=True), device=device)
    x0 = prob.initial_x(guess=False)
    J = prob.jacobian(x0)[:prob.n_data].reshape(U.shape)
    np.testing.assert_allclose(U, J, rtol=1e-12, atol=1e-12)
    # central differences of the whitened predictions for a few columns
    for k in (0, space.size // 2, space.size - 1):
        h = 1e-6 * max(1.0, abs(x0[k]))
        xp, xm = x0.copy(), x0.copy()
        xp[k] += h
        xm[k] -= h
        d = (prob.predict(xp) - prob.predict(xm)) / (2 * h) / prob.noise
        np.testing.assert_allclose(U[:, :, k], d, rtol=1e-5, atol=1e-6 * np.abs(d).max())
