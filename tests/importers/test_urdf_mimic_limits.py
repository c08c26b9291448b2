"""Reliability round 3, item 10 (URDF mimics): a NaN mimic multiplier is named as such (it
was reported as ``frames[2].dh``), and a 1500-joint mimic chain listed child-first imports
like the same chain in document order (it hit a RecursionError)."""

import numpy as np
import pytest

import jwarp

LIMIT = '<axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/>'


def chain(n: int, reverse: bool) -> str:
    links = "".join(f'<link name="l{i}"/>' for i in range(n + 2))
    js = [f'<joint name="j0" type="revolute"><parent link="l0"/><child link="l1"/>{LIMIT}'
          f'</joint>']
    for i in range(1, n + 1):
        js.append(f'<joint name="j{i}" type="revolute"><parent link="l{i}"/>'
                  f'<child link="l{i + 1}"/>{LIMIT}<mimic joint="j{i - 1}" multiplier="1.0"/>'
                  f'</joint>')
    return f'<robot name="c">{links}{"".join(reversed(js) if reverse else js)}</robot>'


def test_nan_mimic_multiplier_is_named(tmp_path):
    p = tmp_path / "m.urdf"
    p.write_text(chain(1, False).replace('multiplier="1.0"', 'multiplier="nan"'))
    with pytest.raises(ValueError, match=r"joint 'j1': <mimic multiplier=\"nan\".*finite"):
        jwarp.robot(str(p))


def test_long_mimic_chain_in_any_order(tmp_path):
    a, b = tmp_path / "a.urdf", tmp_path / "b.urdf"
    a.write_text(chain(1500, False))
    b.write_text(chain(1500, True))
    ra, rb = jwarp.robot(str(a)), jwarp.robot(str(b))
    assert ra.n_dof == rb.n_dof == 1
    q = np.array([[0.001]])
    np.testing.assert_allclose(jwarp.fk(ra, q, dtype=np.float64)[0, -1],
                               jwarp.fk(rb, q, dtype=np.float64)[0, -1], atol=1e-9)
