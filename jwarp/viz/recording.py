"""rerun recordings written to a temporary file and renamed into place at the end.

:class:`Recording` opens ``path`` through :class:`jwarp.utils.atomic.AtomicFile`: the
recording streams into a temporary file beside ``path``; :meth:`Recording.close` renames it
to ``path``, :meth:`Recording.abort` (or a failure while opening) removes it, so ``path`` is
either the old file or the whole new recording. As a context manager it closes on success
and aborts on an error; :func:`atomic_recording` yields just its stream. ``rerun`` is
imported on first use (:func:`rerun_module`).
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from jwarp.utils.atomic import AtomicFile


def rerun_module() -> Any:
    """The ``rerun`` module; ImportError naming the package when rerun-sdk is missing."""
    try:
        import rerun as rr
    except ImportError as e:  # pragma: no cover - depends on the machine
        raise ImportError("jwarp.viz needs rerun-sdk: pip install rerun-sdk") from e
    return rr


def open_recording(path: str | os.PathLike, application_id: str = "jwarp") -> Any:
    """A rerun RecordingStream saving to ``path`` (z up, right-handed); flush and
    disconnect it when done."""
    rr = rerun_module()
    rec = rr.RecordingStream(application_id)
    rec.save(str(path))
    rec.log("/", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    return rec


class Recording:
    """A rerun recording of application ``app`` bound for ``path``.

    ``rr`` is the rerun module, ``rec`` the recording stream. ``option`` names the
    argument or CLI option in errors. Raises ``ImportError`` without rerun-sdk (before any
    file is made) and ``ValueError`` for a path that cannot be written."""

    def __init__(self, path: str | os.PathLike, app: str, option: str = "path"):
        self.rr = rerun_module()
        self.file = AtomicFile(path, option=option)
        try:
            self.rec = open_recording(self.file.tmp, app)
        except BaseException:
            self.file.discard()
            raise

    def close(self) -> Path:
        """Flush, close and rename the recording to its path; return the path."""
        self.rec.flush()
        self.rec.disconnect()
        return self.file.commit()

    def abort(self) -> None:
        """Close the recording and remove its temporary file (the path keeps its old
        content)."""
        try:
            self.rec.disconnect()  # no writer left on the temporary file
        finally:
            self.file.discard()

    def __enter__(self) -> Recording:
        return self

    def __exit__(self, exc_type: Any, exc: Any, tb: Any) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()


@contextlib.contextmanager
def atomic_recording(path: str | os.PathLike, application_id: str = "jwarp",
                     option: str = "path") -> Iterator[Any]:
    """A rerun RecordingStream saving to a temporary file beside ``path``, renamed to
    ``path`` when the block ends without error (readers never see a partial file). On an
    error or interrupt the stream is closed and the temporary file removed; ``path``
    stays as it was. ``option`` names the path in errors (e.g. ``--save``)."""
    with Recording(path, application_id, option) as recording:
        yield recording.rec
