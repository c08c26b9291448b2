"""Process-wide caches of objects made for other objects (issue 40 item 5: caches are
explicit objects, not ``id()`` keys).

:class:`IdentityCache` is a small least-recently-used cache whose key has two parts: a
tuple of plain, hashable values (a robot's content key, a device name, options), compared
by value, and the objects the entry was made for (a world, a robot model), compared by
identity and held weakly. An entry whose object has died never matches, even where a new
object has been given its ``id()``; ``None`` stands for itself (no world).
"""

from __future__ import annotations

import threading
import weakref
from collections import OrderedDict
from collections.abc import Callable, Hashable
from typing import Any, Generic, TypeVar

V = TypeVar("V")


def _none() -> None:
    return None


def _ref(obj: Any) -> Callable[[], Any]:
    """A weak reference to ``obj``; ``None`` gets a stand-in that always returns None."""
    return _none if obj is None else weakref.ref(obj)


#: the attribute of an object under which the caches keep the values made for it
OWNER_ATTRIBUTE = "_jwarp_cached"


class IdentityCache(Generic[V]):
    """At most ``maxsize`` values, each kept for (``key``, ``objects``): ``key`` a hashable
    tuple compared by value, ``objects`` a tuple compared by identity (held weakly, so the
    cache keeps none of them alive; each must accept a weak reference, or be None). The
    least recently used entry goes first. Thread safe (one lock per cache).

    ``owner``: the index in ``objects`` of the object whose lifetime the values follow (a
    world): a value is stored on that object (an attribute), so a value that refers to it
    (a collision model holding its world and device buffers) does not keep it alive
    through the cache, and both go together (with Python's cycle collector) once the
    caller drops the object. None, or that object None: the cache holds the value."""

    def __init__(self, maxsize: int, owner: int | None = None) -> None:
        if maxsize < 1:
            raise ValueError(f"maxsize: expected an integer >= 1, got {maxsize!r}")
        self.maxsize = int(maxsize)
        if owner is not None and (isinstance(owner, bool) or not isinstance(owner, int)
                                  or owner < 0):
            raise ValueError(f"owner: expected an index >= 0 into the objects, or None, got "
                             f"{owner!r}")
        self.owner = owner
        # slot -> (weak refs of the objects, the value held here, or a weak ref of its owner)
        self._entries: OrderedDict[tuple, tuple[tuple, Any, bool]] = OrderedDict()
        self._lock = threading.Lock()

    @staticmethod
    def _slot(key: Hashable, objects: tuple) -> tuple:
        return (key, tuple(id(o) for o in objects))

    @staticmethod
    def _store(owner: Any) -> dict:
        """The values the caches keep on ``owner`` (made on first use)."""
        return owner.__dict__.setdefault(OWNER_ATTRIBUTE, {})

    def get(self, key: Hashable, objects: tuple = ()) -> V | None:
        """The value kept for ``key`` and these very ``objects`` (marked recently used), or
        None."""
        slot = self._slot(key, objects)
        with self._lock:
            hit = self._entries.get(slot)
            if hit is None or any(r() is not o for r, o in zip(hit[0], objects)):
                return None
            refs, held, owned = hit
            if owned:
                owner = held()
                value = None if owner is None else self._store(owner).get((id(self), slot))
                if value is None:
                    return None
            else:
                value = held
            self._entries.move_to_end(slot)
            return value

    def put(self, key: Hashable, objects: tuple, value: V) -> V:
        """Keep ``value`` for ``key`` and ``objects`` (replacing what was kept there), the
        least recently used entries leaving beyond :attr:`maxsize`; returns ``value``."""
        slot = self._slot(key, objects)
        refs = tuple(_ref(o) for o in objects)
        owner = None if self.owner is None else objects[self.owner]
        with self._lock:
            self._drop(slot)
            if owner is None:
                self._entries[slot] = (refs, value, False)
            else:
                self._store(owner)[(id(self), slot)] = value
                self._entries[slot] = (refs, weakref.ref(owner), True)
            self._entries.move_to_end(slot)
            while len(self._entries) > self.maxsize:
                self._drop(next(iter(self._entries)))
        return value

    def _drop(self, slot: tuple) -> None:
        """Forget ``slot`` here and on its owner (lock held)."""
        hit = self._entries.pop(slot, None)
        if hit is not None and hit[2]:
            owner = hit[1]()
            if owner is not None:
                self._store(owner).pop((id(self), slot), None)

    def clear(self) -> None:
        """Forget every entry."""
        with self._lock:
            for slot in list(self._entries):
                self._drop(slot)

    def __len__(self) -> int:
        return len(self._entries)
