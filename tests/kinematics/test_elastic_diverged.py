"""Reliability round 3, item 2: a diverged elastic iteration (non-finite frames) is never
called converged, in the API and on the CLI (it failed before: kappa 1e10 in float32 gave
NaN frames with converged=[True], iterations=[2])."""

import numpy as np
import pytest
from cli_helpers import run

import jwarp


@pytest.mark.parametrize("dtype,kappa", [("float32", 1e10), ("float64", 1e308)])
def test_nan_frames_are_not_converged(dtype, kappa):
    r = jwarp.fk_elastic("justin19", np.zeros((2, 19)), kappa=kappa, dtype=dtype)
    assert not np.isfinite(np.asarray(r.frames)).all()
    assert not np.asarray(r.converged).any()
    assert np.asarray(r.diverged).all()
    ok = jwarp.fk_elastic("justin19", np.zeros((1, 19)), kappa=1e-4, dtype=dtype)
    assert np.asarray(ok.converged).all() and not np.asarray(ok.diverged).any()


def test_cli_says_it_diverged(capsys):
    code, out, err = run(capsys, ["fk", "justin19", "--elastic", "--kappa", "1e10",
                                  "--dtype", "float32", "--q", "0"])
    assert "converged = NO" in out
    assert "diverged" in err


def test_kappa_that_requires_grad_is_refused_not_dropped():
    """Reliability round 3, item 7: a kappa tensor with requires_grad was accepted and its
    grad stayed None (finite differences give a real derivative): refused, naming kappa."""
    torch = pytest.importorskip("torch")
    kappa = torch.tensor(1e-4, dtype=torch.float64, requires_grad=True)
    q = torch.zeros((1, 19), dtype=torch.float64, requires_grad=True)
    with pytest.raises(TypeError, match="kappa: a torch tensor that requires grad"):
        jwarp.fk_elastic("justin19", q, kappa=kappa)
    r = jwarp.fk_elastic("justin19", q, kappa=kappa.detach())   # detached: fine
    r.frames[..., 2, 3].sum().backward()
    assert q.grad is not None and kappa.grad is None


@pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning")  # the point
def test_a_model_whose_lengths_overflow_float32_is_refused_at_load(tmp_path):
    """Reliability round 3, item 8: a URDF joint origin of 1e300 imported and float32 FK then
    returned NaN frames: refused at load, naming the file and the frame."""
    from jwarp.model import RobotModelError
    urdf = tmp_path / "big.urdf"
    urdf.write_text("""<robot name="big"><link name="base"/><link name="l1"/>
      <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>
      <origin xyz="1e300 0 0"/><axis xyz="0 0 1"/>
      <limit lower="-1" upper="1" effort="1" velocity="1"/></joint></robot>""")
    with pytest.raises((RobotModelError, ValueError), match=r"big.urdf.*frames\[1\].*exceeds"):
        jwarp.robot(str(urdf))
    ok = tmp_path / "ok.urdf"
    ok.write_text(urdf.read_text().replace("1e300", "0.3"))
    assert np.isfinite(jwarp.fk(jwarp.robot(str(ok)), np.zeros(1), dtype="float32")).all()
