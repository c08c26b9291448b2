"""Atomic file output: write to a temporary file beside the target, then rename.

Readers never see a partial file, and a failed write leaves the old file (if any) as it
was. Every file jwarp writes (robot and calibration JSON, world .npz, rerun recordings,
benchmark figures) goes through :class:`AtomicFile`.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import Any


class AtomicFile:
    """A temporary file beside ``path`` (same folder, so the rename is atomic; the usual
    file mode, not mkstemp's 0600). Write to :attr:`tmp`, then :meth:`commit` renames it
    onto ``path`` or :meth:`discard` removes it. As a context manager it commits when the
    block ends without error and discards otherwise.

    Raises:
        ValueError: the folder of ``path`` does not exist.
    """

    def __init__(self, path: str | os.PathLike):
        self.target = Path(path)
        folder = self.target.parent if str(self.target.parent) else Path(".")
        if not folder.is_dir():
            raise ValueError(f"path: folder '{folder}' does not exist")
        fd, tmp = tempfile.mkstemp(prefix=f".{self.target.name}.", suffix=".tmp", dir=folder)
        os.close(fd)
        self.tmp = Path(tmp)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(self.tmp, 0o666 & ~umask)

    def commit(self) -> Path:
        """Rename the temporary file onto the target; returns the target. If the rename
        fails the temporary file is removed and the error raised."""
        try:
            os.replace(self.tmp, self.target)
        except BaseException:
            self.discard()
            raise
        return self.target

    def discard(self) -> None:
        """Remove the temporary file (the target stays as it was)."""
        if self.tmp.exists():
            self.tmp.unlink()

    def __enter__(self) -> "AtomicFile":
        return self

    def __exit__(self, exc_type: Any, exc: Any, tb: Any) -> None:
        if exc_type is None:
            self.commit()
        else:
            self.discard()


def atomic_write_text(path: str | os.PathLike, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically, synced to disk."""
    with AtomicFile(path) as f:
        with os.fdopen(os.open(f.tmp, os.O_WRONLY | os.O_TRUNC), "w", encoding="utf-8") as fh:
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())
