"""MoveIt's "Default" rule (jwarp.world.self_pairs.default_pairs / with_default_pairs):
pairs in collision at the home are split by a contact test of the robot's own geometry,
checked against sphere distances computed here with numpy; the excluded pairs are written
to the exported SRDF with reason="Default" (read back with xml.etree)."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET

import numpy as np
import pytest

import jwarp
from jwarp.importers.srdf import srdf_text
from jwarp.model import SelfCollision, Sphere
from jwarp.world.model_check import home_configuration
from jwarp.world.self_pairs import DEFAULT_NOTE, default_pairs, with_default_pairs


def _robot():
    """arm7 with every frame pair checked and hand-placed spheres: frames 2/5 overlap by
    30 mm at the home, frames 1/6 by 5 mm, frames 3/7 are 10 mm apart."""
    m = jwarp.robot("arm7").copy(self_collision=SelfCollision())
    q = home_configuration(m)
    T = np.asarray(jwarp.fk(m, q[None], device="cpu", dtype=np.float64))[0]
    spheres = []
    for (a, b), (gap, where) in {(2, 5): (-0.03, [0.0, 0.0, 3.0]),
                                 (1, 6): (-0.005, [3.0, 0.0, 0.0]),
                                 (3, 7): (0.01, [0.0, 3.0, 0.0])}.items():
        p = np.array(where)
        for f, x in ((a, p), (b, p + [0.04 + gap, 0.0, 0.0])):
            local = np.linalg.solve(T[f], np.append(x, 1.0))[:3]
            spheres.append(Sphere(frame=f, position=local, radius=0.02))
    return m.copy(spheres=spheres), q


def _overlaps(m, q) -> dict[tuple[int, int], float]:
    """Deepest sphere overlap per checked frame pair (numpy)."""
    f, p, r = m.sphere_arrays()
    T = np.asarray(jwarp.fk(m, q[None], device="cpu", dtype=np.float64))[0]
    x = np.einsum("sij,sj->si", T[f, :3, :3], p) + T[f, :3, 3]
    d = np.linalg.norm(x[:, None] - x[None], axis=-1) - r[:, None] - r[None]
    A = m.allowed_collision_pairs
    out: dict[tuple[int, int], float] = {}
    for i, j in zip(*np.nonzero(d < 0)):
        if f[i] < f[j] and A[f[i], f[j]]:
            k = (int(f[i]), int(f[j]))
            out[k] = min(out.get(k, 0.0), float(d[i, j]))
    return out


def test_default_pairs_split_by_contact():
    m, q = _robot()
    want = _overlaps(m, q)
    assert set(want) == {(2, 5), (1, 6)}
    asked = []

    def contact(a, b):
        asked.append((a, b))
        return (a, b) == (2, 5)

    default, fit = default_pairs(m, q, contact)
    assert sorted(asked) == sorted(want)
    assert [(a, b) for a, b, _ in default] == [(2, 5)]
    assert [(a, b) for a, b, _ in fit] == [(1, 6)]
    for a, b, depth in default + fit:
        assert depth == pytest.approx(want[a, b], abs=1e-9)
    # excluded by name, the rest checked as before
    m2 = with_default_pairs(m, default)
    A = m2.allowed_collision_pairs
    assert not A[2, 5] and A[1, 6] and A[3, 7]
    assert json.loads(m2.notes[DEFAULT_NOTE]) == [[m.frame_names[2], m.frame_names[5]]]
    assert set(_overlaps(m2, q)) == {(1, 6)}
    assert with_default_pairs(m2, default).self_collision.exclude_pairs == \
        m2.self_collision.exclude_pairs                        # no repeats
    # the SRDF export says why
    root = ET.fromstring(srdf_text(m2))
    reasons = {frozenset((d.get("link1"), d.get("link2"))): d.get("reason")
               for d in root.findall("disable_collisions")}
    assert reasons == {frozenset((m.frame_names[2], m.frame_names[5])): "Default"}


def test_default_pairs_bad_input():
    m, q = _robot()
    with pytest.raises(ValueError, match="home: expected 7 finite joint values"):
        default_pairs(m, q[:3], lambda a, b: True)
    with pytest.raises(TypeError, match="contact: expected a callable"):
        default_pairs(m, q, None)
    with pytest.raises(ValueError, match=r"pairs: frame pair \(2, 99\) out of range"):
        with_default_pairs(m, [(2, 99)])
