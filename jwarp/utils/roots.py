"""Files that a document (a scene file, an MJCF model) names outside its own folder.

A scene's mesh given as ``../x.stl``, an absolute path or ``file:///...``, or an MJCF
``<include file="...">`` reaching out of the model's folder, is read, but with one
:class:`OutsideFolderWarning` per file naming the document's folder: a scene shared with
others should not read whatever the names point to without a word. The environment
variable :data:`ROOTS_ENV` (``JWARP_ALLOWED_ROOTS``, folders separated by ``os.pathsep``)
lists further folders whose files are read without a warning (e.g. a shared mesh
library). Symbolic links are resolved before the comparison.
"""

from __future__ import annotations

import contextlib
import os
import warnings
from collections.abc import Iterator
from contextvars import ContextVar
from pathlib import Path

__all__ = ["OutsideFolderWarning", "ROOTS_ENV", "allowed_roots", "is_outside",
           "one_warning_per_file", "warn_if_outside"]

_SEEN: ContextVar[set | None] = ContextVar("jwarp_outside_seen", default=None)

#: folders (``os.pathsep``-separated) whose files documents may name without a warning
ROOTS_ENV = "JWARP_ALLOWED_ROOTS"


class OutsideFolderWarning(UserWarning):
    """A document names a file outside its folder and the allowed roots (:data:`ROOTS_ENV`)."""


def allowed_roots() -> list[Path]:
    """The resolved folders of :data:`ROOTS_ENV` (empty when it is unset)."""
    text = os.environ.get(ROOTS_ENV, "")
    return [Path(p).expanduser().resolve() for p in text.split(os.pathsep) if p.strip()]


def is_outside(path: str | os.PathLike, folder: str | os.PathLike) -> bool:
    """Whether ``path`` lies outside ``folder`` and every allowed root (links resolved)."""
    p = Path(path).resolve()
    for root in [Path(folder).resolve(), *allowed_roots()]:
        if p == root or root in p.parents:
            return False
    return True


@contextlib.contextmanager
def one_warning_per_file() -> Iterator[None]:
    """Within the block (the reading of one document), :func:`warn_if_outside` warns once
    per file, however many times (and however spelt: ``../``, absolute, ``file://``) the
    document names it."""
    token = _SEEN.set(set())
    try:
        yield
    finally:
        _SEEN.reset(token)


def warn_if_outside(path: str | os.PathLike, folder: str | os.PathLike, what: str,
                    stacklevel: int = 2) -> bool:
    """An :class:`OutsideFolderWarning` when ``path`` is outside ``folder`` and the allowed
    roots (within :func:`one_warning_per_file`: the first time only); ``what`` starts the
    message (e.g. ``"object 'cup': mesh file"``). Returns whether it is outside."""
    if not is_outside(path, folder):
        return False
    seen = _SEEN.get()
    if seen is not None:
        key = Path(path).resolve()
        if key in seen:
            return True
        seen.add(key)
    warnings.warn(f"{what} '{path}' is outside {Path(folder).resolve()}, the folder of the "
                  f"file that names it; read anyway ({ROOTS_ENV} lists folders whose files "
                  f"are read without this warning)", OutsideFolderWarning,
                  stacklevel=stacklevel + 1)
    return True
