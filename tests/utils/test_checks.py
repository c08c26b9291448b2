"""The one integer/real checker and its one exception (issue 40 item 4), and the options
base the IK and the planner share."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from jwarp.utils.checks import ArgumentError, check_int, check_real, real_number


def test_argument_error_is_a_type_and_a_value_error():
    assert issubclass(ArgumentError, TypeError) and issubclass(ArgumentError, ValueError)


@pytest.mark.parametrize("v", [True, np.bool_(True), 1.0, "1", None, [1]])
def test_check_int_refuses_non_integers(v):
    with pytest.raises(ArgumentError, match=r"^n: expected an integer >= 0, got "):
        check_int(v, "n", 0)


def test_check_int_bounds_and_none():
    assert check_int(np.int64(3), "n", 1) == 3 and type(check_int(np.int64(3), "n")) is int
    with pytest.raises(ValueError, match=r"^n: expected an integer >= 1, got 0$"):
        check_int(0, "n", 1)
    with pytest.raises(TypeError, match=r"^n: expected an integer in \[1, 8\], got 9$"):
        check_int(9, "n", 1, 8)
    assert check_int(None, "n", 1, none=True) is None
    with pytest.raises(ArgumentError, match=r"or None, got 0"):
        check_int(0, "n", 1, none=True)


def test_check_real():
    assert check_real(np.float32(0.5), "x", 0, 1) == 0.5
    assert check_real(np.array(2.0), "x") == 2.0
    for bad, msg in ((0.0, r"x: expected a finite number > 0, got 0.0"),
                     (float("nan"), r"x: expected a finite number > 0"),
                     (float("inf"), r"x: expected a finite number > 0")):
        with pytest.raises(ArgumentError, match=msg):
            check_real(bad, "x", 0, open_lo=True)
    assert check_real(float("inf"), "x", 0, finite=False) == float("inf")
    with pytest.raises(TypeError, match=r"x: expected a real number, got bool"):
        check_real(True, "x")
    with pytest.raises(ValueError, match=r"x: expected a finite number in float32"):
        real_number(1e39, "x", np.float32)


def test_ik_and_plan_options_share_one_base_with_their_own_defaults():
    from jwarp.solvers.ik import IKOptions
    from jwarp.solvers.options import SolverOptions
    from jwarp.solvers.planning import PlanOptions

    shared = [f.name for f in dataclasses.fields(SolverOptions)]
    assert len(shared) == 11 and "n_starts" not in shared  # each declares its own
    for cls, own in ((IKOptions, dict(n_starts=16, iterations=200, step=1.0, max_step=0.5)),
                     (PlanOptions, dict(n_starts=None, iterations=100, step=0.01,
                                        max_step=0.1))):
        assert issubclass(cls, SolverOptions)
        o = cls()
        assert [f.name for f in dataclasses.fields(cls)][:11] == shared
        assert {k: getattr(o, k) for k in own} == own
        assert (o.margin, o.eps, o.kappa, o.lam, o.seed) == (0.0, None, None, 0.7, 0)
        assert o.stop_when_solved and o.mesh_margin and not o.allow_no_collision
