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


class IdentityCache(Generic[V]):
    """At most ``maxsize`` values, each kept for (``key``, ``objects``): ``key`` a hashable
    tuple compared by value, ``objects`` a tuple compared by identity (held weakly, so the
    cache keeps none of them alive; each must accept a weak reference, or be None). The
    least recently used entry goes first. Thread safe (one lock per cache)."""

    def __init__(self, maxsize: int) -> None:
        if maxsize < 1:
            raise ValueError(f"maxsize: expected an integer >= 1, got {maxsize!r}")
        self.maxsize = int(maxsize)
        self._entries: OrderedDict[tuple, tuple[tuple, V]] = OrderedDict()
        self._lock = threading.Lock()

    @staticmethod
    def _slot(key: Hashable, objects: tuple) -> tuple:
        return (key, tuple(id(o) for o in objects))

    def get(self, key: Hashable, objects: tuple = ()) -> V | None:
        """The value kept for ``key`` and these very ``objects`` (marked recently used), or
        None."""
        slot = self._slot(key, objects)
        with self._lock:
            hit = self._entries.get(slot)
            if hit is None or any(r() is not o for r, o in zip(hit[0], objects)):
                return None
            self._entries.move_to_end(slot)
            return hit[1]

    def put(self, key: Hashable, objects: tuple, value: V) -> V:
        """Keep ``value`` for ``key`` and ``objects`` (replacing what was kept there), the
        least recently used entries leaving beyond :attr:`maxsize`; returns ``value``."""
        slot = self._slot(key, objects)
        refs = tuple(_ref(o) for o in objects)
        with self._lock:
            self._entries[slot] = (refs, value)
            self._entries.move_to_end(slot)
            while len(self._entries) > self.maxsize:
                self._entries.popitem(last=False)
        return value

    def clear(self) -> None:
        """Forget every entry."""
        with self._lock:
            self._entries.clear()

    def __len__(self) -> int:
        return len(self._entries)
