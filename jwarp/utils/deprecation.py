"""Forwarding of deprecated module paths (issue 28: packages by job).

A module that moved leaves a small module at its old path::

    __getattr__, __dir__ = moved(__name__, ("jwarp.new.place",))

Importing the old path warns once (``DeprecationWarning``, naming the new path); its
attributes are read from the new module(s), in order, on first use.
"""

from __future__ import annotations

import importlib
import warnings
from typing import Any, Callable


def moved(old: str, targets: tuple[str, ...]) -> tuple[Callable[[str], Any],
                                                       Callable[[], list[str]]]:
    """Warn that ``old`` moved to ``targets[0]``; return the module ``__getattr__`` and
    ``__dir__`` that read names from ``targets`` (first hit wins)."""
    warnings.warn(f"{old} moved to {targets[0]}; the old path goes away in the next release",
                  DeprecationWarning, stacklevel=3)

    def getattr_(name: str) -> Any:
        for t in targets:
            mod = importlib.import_module(t)
            if hasattr(mod, name):
                return getattr(mod, name)
        raise AttributeError(f"module {old!r} (moved to {targets[0]}) has no attribute "
                             f"{name!r}")

    def dir_() -> list[str]:
        return sorted({n for t in targets for n in dir(importlib.import_module(t))})

    return getattr_, dir_
