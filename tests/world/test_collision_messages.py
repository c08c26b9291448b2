"""Messages about collisions (issue 39 item 5): a start or goal in collision names the
link and the object (or the two links) with their distance, and no clearance is printed as
``-0.00 mm``. arm7 in a world of exact objects; the expected link is found independently
(the argmin of :func:`jwarp.world.collision.sphere_distances` / ``self_distances``)."""

from __future__ import annotations

import re

import numpy as np
import pytest

import jwarp
from jwarp.core.limits import sample_within_limits
from jwarp.solvers.planning import plan
from jwarp.world import World
from jwarp.world.collision import (
    collision_pairs,
    min_distances,
    mm_text,
    self_distances,
    sphere_distances,
    sphere_link,
)
from jwarp.world.motion import PathCheck

ROBOT = jwarp.robot("arm7")
Q1 = np.array([0.3, 1.0, 0.2, 1.0, -0.4, 0.5, 0.1])


def table_world(q: np.ndarray) -> World:
    """A 'shelf' far away and a 'table' box around the end-effector at q."""
    w = World.of_shapes()
    w.add("shelf", "box", [0.2, 0.2, 0.2], [5.0, 0.0, 0.0])
    tcp = jwarp.fk(ROBOT, q)[ROBOT.frame_index(list(ROBOT.end_effectors)[0]), :3, 3]
    w.add("table", "box", [0.1, 0.1, 0.1], tcp)
    return w


def test_start_in_collision_names_the_link_and_the_object():
    q0 = np.zeros(ROBOT.n_dof)
    w = table_world(Q1)
    d = np.asarray(sphere_distances(ROBOT, Q1[None], w, dtype=np.float64))[0]
    link = sphere_link(ROBOT, int(np.argmin(d)))
    with pytest.raises(ValueError) as e:
        plan(ROBOT, w, Q1, q0, n_starts=1, iterations=1)
    msg = str(e.value)
    assert msg.startswith("start: configuration is in collision: "), msg
    assert f"link '{link}' vs object 'table', {mm_text(d.min())} mm (margin 0 m)" in msg
    assert d.min() < 0
    # the goal too, named as such
    with pytest.raises(ValueError, match=rf"^goal: configuration is in collision: link "
                                         rf"'{link}' vs object 'table'"):
        plan(ROBOT, w, q0, Q1, n_starts=1, iterations=1)


def test_self_collision_names_the_two_links():
    rng = np.random.default_rng(0)
    q = sample_within_limits(ROBOT, 4000, rng)
    md = np.asarray(min_distances(ROBOT, q, None, dtype=np.float64))
    hit = q[md[:, 1] < -0.005]
    assert len(hit), "no self-colliding configuration drawn"
    qs = hit[0]
    d = np.asarray(self_distances(ROBOT, qs[None], dtype=np.float64))[0]
    a, b = (sphere_link(ROBOT, int(s)) for s in collision_pairs(ROBOT)[int(np.argmin(d))])
    w = World.of_shapes()
    w.add("shelf", "box", [0.2, 0.2, 0.2], [5.0, 0.0, 0.0])
    with pytest.raises(ValueError) as e:
        plan(ROBOT, w, qs, np.zeros(ROBOT.n_dof), n_starts=1, iterations=1)
    assert f"link '{a}' vs link '{b}', {mm_text(d.min())} mm (self margin 0 m)" in str(e.value)


def test_no_minus_zero_clearance():
    assert mm_text(-0.0) == "0.00" and mm_text(0.0) == "0.00"
    assert mm_text(-1e-7) == "-0.0001" and mm_text(3e-6) == "0.003"
    assert mm_text(-0.09327) == "-93.27" and mm_text(0.0012345) == "1.23"
    w = table_world(Q1)
    for c in (-1e-7, -0.0, -4e-6):
        chk = PathCheck(ok=np.array([False]), code=np.array([1]), where=np.array([3.0]),
                          what=np.array([[0, 1]]), clearance=np.array([c]), robot=ROBOT,
                          world=w)
        reason = chk.reason(0)
        assert "collision:" in reason and "-0.00 " not in reason, reason
        assert re.search(r"clearance -?0\.0*\d* mm", reason), reason


def test_messages_use_no_cpu_kernel_without_warp_cpu(monkeypatch):
    """On a GPU-only Warp install (no CPU backend) the object named in a collision message
    is found on Warp's default device: nothing asks for "cpu" (a GPU machine raised an
    AttributeError from Warp's missing CPU compiler instead of the start's ValueError);
    with a device given (the planner's), that device is used."""
    import importlib

    import warp as wp

    from jwarp.world.collision import nearest_objects

    fk_mod = importlib.import_module("jwarp.kinematics.fk")
    dw = importlib.import_module("jwarp.world.device_world")
    asked = []
    real_fk, real_query = fk_mod.fk, dw.world_query

    def fk_spy(*a, **k):
        asked.append(k.get("device"))
        return real_fk(*a, **k)

    def query_spy(*a, **k):
        asked.append(k.get("device"))
        return real_query(*a, **k)

    monkeypatch.setattr(fk_mod, "fk", fk_spy)
    monkeypatch.setattr(dw, "world_query", query_spy)
    w = table_world(Q1)
    d = np.asarray(sphere_distances(ROBOT, Q1[None], w, dtype=np.float64))[0]
    s = int(np.argmin(d))
    monkeypatch.setattr(wp, "is_cpu_available", lambda: False)
    assert nearest_objects(ROBOT, Q1, w, [s]) == ["object 'table'"]
    assert asked == [None, None], asked
    asked.clear()
    monkeypatch.setattr(wp, "is_cpu_available", lambda: True)
    assert nearest_objects(ROBOT, Q1, w, [s], device="cpu") == ["object 'table'"]
    assert asked == ["cpu", "cpu"], asked
