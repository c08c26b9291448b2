"""A rerun recording written to a temporary file and renamed into place at the end.

:class:`Recording` opens ``path`` through :class:`jwarp.utils.atomic.AtomicFile`: the
recording streams into a temporary file beside ``path``; :meth:`Recording.close` renames it
to ``path``, :meth:`Recording.abort` (or a failure while opening) removes it, so ``path`` is
either the old file or the whole new recording. ``rerun`` is imported on first use.
"""

from __future__ import annotations

from pathlib import Path

from jwarp.utils.atomic import AtomicFile
from jwarp.viz.robot import open_recording, rerun_module


class Recording:
    """A rerun recording of application ``app`` bound for ``path``.

    ``rr`` is the rerun module, ``rec`` the recording stream. ``option`` names the
    argument or CLI option in errors. Raises ``ImportError`` without rerun-sdk and
    ``ValueError`` for a path that cannot be written."""

    def __init__(self, path: str, app: str, option: str = "path"):
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
