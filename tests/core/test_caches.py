"""jwarp.core.caches.IdentityCache (issue 40 item 5: caches are explicit objects, not id()
keys): values by a plain key and objects by identity, held weakly; a dead object never
matches; least recently used out first."""

from __future__ import annotations

import gc

import pytest

from jwarp.core.caches import IdentityCache


class Obj:
    pass


def test_hits_by_key_and_identity():
    c: IdentityCache[str] = IdentityCache(4)
    a, b = Obj(), Obj()
    assert c.put(("k", 1), (a,), "va") == "va"
    assert c.get(("k", 1), (a,)) == "va"
    assert c.get(("k", 2), (a,)) is None      # another key
    assert c.get(("k", 1), (b,)) is None      # another object, however equal
    c.put("n", (None,), "none")               # None stands for itself
    assert c.get("n", (None,)) == "none" and c.get("n", (a,)) is None


def test_holds_objects_weakly_and_a_dead_one_never_matches():
    c: IdentityCache[str] = IdentityCache(4)
    a = Obj()
    c.put("k", (a,), "v")
    ida = id(a)
    del a
    gc.collect()
    for _ in range(1000):       # a new object may get the dead one's id: no match then
        b = Obj()
        if id(b) == ida:
            break
    assert c.get("k", (b,)) is None


def test_least_recently_used_go_first():
    c: IdentityCache[int] = IdentityCache(2)
    a = Obj()
    c.put(1, (a,), 1)
    c.put(2, (a,), 2)
    assert c.get(1, (a,)) == 1       # 1 used last
    c.put(3, (a,), 3)                # 2 goes
    assert len(c) == 2 and c.get(2, (a,)) is None and c.get(1, (a,)) == 1
    c.clear()
    assert len(c) == 0
    with pytest.raises(ValueError):
        IdentityCache(0)
    for bad in (-1, 1.5, True, "0"):
        with pytest.raises(ValueError, match="^owner: expected an index"):
            IdentityCache(2, owner=bad)


def test_world_caches_are_identity_caches():
    from jwarp.world import collision, mesh_check, motion

    for cache in (collision._MODELS, motion._CHECKS, mesh_check._CACHE,
                  mesh_check._ROBOT_PARTS):
        assert isinstance(cache, IdentityCache)


class Holder:
    """A value that refers to its object (as a collision model holds its world)."""

    def __init__(self, obj):
        self.obj = obj


def test_a_value_that_holds_its_owner_dies_with_it():
    import weakref

    c: IdentityCache[Holder] = IdentityCache(4, owner=0)
    a = Obj()
    v = c.put("k", (a,), Holder(a))
    assert c.get("k", (a,)) is v
    ra, rv = weakref.ref(a), weakref.ref(v)
    del a, v
    gc.collect()
    assert ra() is None and rv() is None      # the cache kept neither alive
    # held by the cache itself (no owner): kept
    keep: IdentityCache[Holder] = IdentityCache(4)
    b = Obj()
    keep.put("k", (b,), Holder(b))
    rb = weakref.ref(b)
    del b
    gc.collect()
    assert rb() is not None
    keep.clear()
    gc.collect()
    assert rb() is None


def test_evicted_and_cleared_values_leave_their_owner():
    c: IdentityCache[int] = IdentityCache(1, owner=0)
    a, b = Obj(), Obj()
    c.put(1, (a,), 1)
    c.put(2, (b,), 2)                # 1 goes, from a too
    assert c.get(1, (a,)) is None and not a.__dict__.get("_jwarp_cached")
    c.clear()
    assert len(c) == 0 and not b.__dict__.get("_jwarp_cached")
    assert c.put(3, (None,), 3) == 3 and c.get(3, (None,)) == 3   # None: held here


def test_a_batch_world_and_its_collision_model_are_freed_together():
    """A World.batch planned once and dropped takes its cached collision model (and the
    model's device buffers) with it."""
    import weakref

    import numpy as np

    import jwarp
    from jwarp.world import World, collision
    from jwarp.world.primitives import Shape, pose_matrix
    from jwarp.world.shapes import ShapeSet

    robot = jwarp.robot("arm7")
    w = World.batch([World.of_shapes(ShapeSet.from_shapes([Shape(
        "sphere", np.array([0.1]), pose_matrix(np.array([x, 0.5, 0.4])), "s")]))
        for x in (0.3, -0.3)])
    cm = collision.collision_model(robot, w, device="cpu")
    cm.cost(collision.wp.array(np.zeros((4, robot.n_dof), np.float32), device="cpu"),
            grad=False)
    assert collision.collision_model(robot, w, device="cpu") is cm
    rw, rc = weakref.ref(w), weakref.ref(cm)
    del w, cm
    gc.collect()
    assert rw() is None and rc() is None
