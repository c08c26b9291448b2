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


def test_world_caches_are_identity_caches():
    from jwarp.world import collision, mesh_check, motion

    for cache in (collision._MODELS, motion._CHECKS, mesh_check._CACHE,
                  mesh_check._ROBOT_PARTS):
        assert isinstance(cache, IdentityCache)
