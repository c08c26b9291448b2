"""Atomic file output: write to a temporary file (or folder) beside the target, then rename.

Readers never see a partial file, and a failed write leaves the old file (if any) as it
was. Every file jwarp writes (robot and calibration JSON, world .npz, rerun recordings,
benchmark figures) goes through :class:`AtomicFile`; a set of files that belong together
(a simulated calibration campaign: ``samples.csv``, ``setup.json``, ``truth.json``) goes
through :class:`AtomicFolder`, which replaces the whole folder at once.

Temporary names carry a token ``<host>-<pid>-<random>`` (``host``: 6 hex digits of the
host name's hash)::

    .<name>.<token>.tmp        AtomicFile's temporary file beside <name>
    .<name>.tmp-<token>        AtomicFolder's temporary folder beside <name>
    .<name>.old-<token>        the old folder, moved aside (only without an atomic exchange)

A process killed at any moment (SIGKILL, power loss) can leave such an entry behind. The
next write of the same target (any :class:`AtomicFile` or :class:`AtomicFolder` on it)
removes the entries whose process has ended (same host, POSIX; entries of other hosts, or
on other systems, once they are older than :data:`STALE_AGE_S`) and first finishes an
interrupted folder swap (:func:`clean_stale`).
"""

from __future__ import annotations

import errno
import hashlib
import os
import re
import secrets
import shutil
import socket
import stat
import sys
import time
from collections.abc import Iterable
from pathlib import Path
from typing import Any

#: temporary entries of another host are removed once older than this [s]
STALE_AGE_S = 24 * 3600.0

_HOST = hashlib.sha1(socket.gethostname().encode("utf-8", "replace")).hexdigest()[:6]
_TOKEN = r"(?P<host>[0-9a-f]{6})-(?P<pid>[0-9]+)-(?P<rand>[0-9a-z_]+)"


def _token() -> str:
    return f"{_HOST}-{os.getpid()}-{secrets.token_hex(4)}"


def _process_ended(host: str, pid: int, path: Path) -> bool:
    """Whether the process that made the temporary entry ``path`` has ended."""
    if host != _HOST or os.name != "posix":  # another machine, or no os.kill(pid, 0): by age
        try:
            return time.time() - path.lstat().st_mtime > STALE_AGE_S
        except OSError:
            return False
    if pid == os.getpid():
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return True
    except OSError:  # PermissionError: alive, another user's
        return False
    return False


def _remove(path: Path) -> None:
    try:
        if path.is_dir() and not path.is_symlink():
            shutil.rmtree(path)
        else:
            path.unlink()
    except FileNotFoundError:
        pass


def _fsync_dir(folder: Path) -> None:
    """Make renames in ``folder`` durable (no-op where folders cannot be opened)."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def clean_stale(target: str | os.PathLike) -> list[Path]:
    """Remove the temporary entries that killed writers left beside ``target`` (a file or
    folder path); returns the entries removed.

    An :class:`AtomicFolder` swap interrupted between its two renames (only where the
    atomic exchange is not available) left ``target`` missing, the old folder at
    ``.<name>.old-<token>`` and the complete new one at ``.<name>.tmp-<token>``: the new
    folder is renamed onto ``target`` (the write is finished), or the old one back where
    the new one is gone. Entries of running writers are left alone.
    """
    target = Path(os.path.abspath(target))
    folder, name = target.parent, target.name
    try:
        entries = os.listdir(folder)
    except OSError:
        return []
    name_re = re.escape(name)
    folder_pat = re.compile(rf"^\.{name_re}\.(?P<kind>tmp|old)-{_TOKEN}$")
    file_pat = re.compile(rf"^\.{name_re}\.{_TOKEN}\.tmp$")
    stale: dict[str, dict[str, Path]] = {}
    for e in entries:
        m = folder_pat.match(e) or file_pat.match(e)
        if not m:
            continue
        d = m.groupdict()
        path = folder / e
        if _process_ended(d["host"], int(d["pid"]), path):
            token = f"{d['host']}-{d['pid']}-{d['rand']}"
            stale.setdefault(token, {})[d.get("kind") or "file"] = path
    removed = []
    for kinds in stale.values():
        if "old" in kinds and not os.path.lexists(target):  # swap cut between its renames
            src = kinds.pop("tmp", None) or kinds.pop("old")
            os.rename(src, target)
            _fsync_dir(folder)
        for p in kinds.values():
            _remove(p)
            removed.append(p)
    return removed


class _CommitOnExit:
    """Context manager of :class:`AtomicFile` and :class:`AtomicFolder`: commits when the
    block ends without error, discards otherwise."""

    def commit(self) -> Any:  # pragma: no cover - overridden
        raise NotImplementedError

    def discard(self) -> None:  # pragma: no cover - overridden
        raise NotImplementedError

    def __enter__(self) -> Any:
        return self

    def __exit__(self, exc_type: Any, exc: Any, tb: Any) -> None:
        if exc_type is None:
            self.commit()
        else:
            self.discard()


class AtomicFile(_CommitOnExit):
    """A temporary file beside ``path`` (same folder, so the rename is atomic; the usual
    file mode, not mkstemp's 0600). Write to :attr:`tmp`, then :meth:`commit` renames it
    onto ``path`` or :meth:`discard` removes it. As a context manager it commits when the
    block ends without error and discards otherwise. Making one first removes the stale
    temporary files of killed writers of ``path`` (:func:`clean_stale`).

    Args:
        path: the file to write.
        option: the name errors give the path (e.g. a CLI option ``--out``).

    Raises:
        ValueError: the folder of ``path`` does not exist or cannot be written to, or
            ``path`` is a folder.
    """

    def __init__(self, path: str | os.PathLike, option: str = "path"):
        self.target = Path(path)
        folder = self.target.parent if str(self.target.parent) else Path(".")
        if not folder.is_dir():
            what = "is not a folder" if folder.exists() else "does not exist"
            raise ValueError(f"{option}: folder '{folder}' {what}")
        if self.target.is_dir():
            raise ValueError(f"{option}: '{self.target}' is a folder; give a file name")
        clean_stale(self.target)
        for _ in range(100):
            tmp = folder / f".{self.target.name}.{_token()}.tmp"
            try:  # mode 0666 & ~umask, as open() would make it
                fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
            except FileExistsError:
                continue
            except OSError as e:
                raise ValueError(f"{option}: cannot write in folder '{folder}': "
                                 f"{e.strerror or e}") from None
            os.close(fd)
            self.tmp = tmp
            break
        else:  # pragma: no cover - 100 collisions of 32 random bits
            raise ValueError(f"{option}: no free temporary name in '{folder}'")

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



def atomic_write_text(path: str | os.PathLike, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically, synced to disk."""
    with AtomicFile(path) as f, \
            os.fdopen(os.open(f.tmp, os.O_WRONLY | os.O_TRUNC), "w", encoding="utf-8") as fh:
        fh.write(text)
        fh.flush()
        os.fsync(fh.fileno())


def commit_all(files: Iterable[AtomicFile]) -> None:
    """Rename several written :class:`AtomicFile` s onto their targets, back to back (the
    last step, after all temporary files are complete). If a rename fails, the files not
    yet renamed are discarded and the error raised. Not one atomic step: a kill between
    two renames leaves the first target new and the next one old, so files that belong
    together should record it (e.g. a hash of the other) for readers to check."""
    files = list(files)
    for k, f in enumerate(files):
        try:
            f.commit()
        except BaseException:
            for g in files[k + 1:]:
                g.discard()
            raise


# ----------------------------------------------------------------------------- folders
_RENAME_EXCHANGE = 2
_renameat2: Any = None


def _exchange(a: Path, b: Path) -> bool:
    """Swap the paths ``a`` and ``b`` in one atomic step (Linux ``renameat2`` with
    ``RENAME_EXCHANGE``); False where the OS or file system has no such call."""
    global _renameat2
    if not sys.platform.startswith("linux"):
        return False
    if _renameat2 is None:
        try:
            import ctypes

            libc = ctypes.CDLL(None, use_errno=True)
            _renameat2 = getattr(libc, "renameat2", False)
            if _renameat2:
                _renameat2.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int,
                                       ctypes.c_char_p, ctypes.c_uint]
        except (OSError, AttributeError):  # pragma: no cover
            _renameat2 = False
    if not _renameat2:
        return False
    import ctypes

    AT_FDCWD = -100
    if _renameat2(AT_FDCWD, os.fsencode(a), AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE) == 0:
        return True
    err = ctypes.get_errno()
    if err in (errno.EINVAL, errno.ENOSYS, errno.ENOTSUP, errno.EOPNOTSUPP):
        return False  # not supported here: the caller renames twice
    raise OSError(err, os.strerror(err), str(b))


def _link_tree(src: Path, dst: Path, skip: Iterable[str] = ()) -> None:
    """Hard-link the tree ``src`` (less its top-level entries ``skip``) into the folder
    ``dst`` (copies where a file cannot be linked); symbolic links are recreated, not
    followed."""
    skip = set(skip)
    for e in os.scandir(src):
        if e.name in skip:
            continue
        s, d = Path(e.path), dst / e.name
        if e.is_symlink():
            os.symlink(os.readlink(s), d)
        elif e.is_dir():
            os.mkdir(d)
            shutil.copystat(s, d)
            _link_tree(s, d)
        else:
            try:
                os.link(s, d)
            except OSError:
                shutil.copy2(s, d)


class AtomicFolder(_CommitOnExit):
    """A set of files that replaces the folder ``path`` as one: write the files into
    :attr:`tmp` (a new folder ``.<name>.tmp-<token>`` beside ``path``, e.g. with
    :meth:`file` and :func:`atomic_write_text`), then :meth:`commit` swaps it in; readers
    see all the old files or all the new ones, never a mix. As a context manager it
    commits when the block ends without error and discards otherwise.

    Entries of the old folder that the new set does not write (e.g. a calibrated robot
    saved next to a campaign) are kept: they are hard-linked into the new folder (copied
    where linking fails) before the swap. The swap:

    * no folder at ``path`` yet: one rename;
    * Linux (``renameat2(RENAME_EXCHANGE)``, ext4, xfs, btrfs, tmpfs, ...): one atomic
      exchange of the two folders, then the old one (now at the temporary name) is removed;
    * elsewhere: two renames, ``path`` -> ``.<name>.old-<token>`` and the new folder ->
      ``path``. A kill between them leaves no folder at ``path`` for that instant; the
      next :class:`AtomicFolder` on ``path`` (or :func:`clean_stale`) renames the complete
      new folder into place.

    A kill at any other moment leaves the old or the new folder at ``path`` and a stale
    temporary folder that the next write removes.

    Args:
        path: the folder to (re)place; its parent folder must exist.
        option: the name errors give the path (e.g. ``--out``).

    Raises:
        ValueError: the parent folder does not exist or cannot be written to, ``path``
            is a file, or it holds the current working folder (which would be left in
            the replaced, removed folder).
    """

    def __init__(self, path: str | os.PathLike, option: str = "path"):
        p = Path(path)
        if p.is_symlink() and p.is_dir():  # replace the folder the link points to
            p = Path(os.path.realpath(p))
        self.target = Path(os.path.abspath(p))
        parent = self.target.parent
        if not self.target.name or self.target == parent:
            raise ValueError(f"{option}: '{path}' cannot be replaced as a folder")
        if not parent.is_dir():
            what = "is not a folder" if parent.exists() else "does not exist"
            raise ValueError(f"{option}: folder '{parent}' {what}")
        if self.target.exists() and not self.target.is_dir():
            raise ValueError(f"{option}: '{path}' is a file; give a folder")
        if self.target.is_dir():
            cwd = os.path.realpath(os.getcwd())
            real = os.path.realpath(self.target)
            if cwd == real or cwd.startswith(real.rstrip(os.sep) + os.sep):
                raise ValueError(f"{option}: '{path}' holds the current folder, which the "
                                 f"write replaces; give a subfolder (e.g. run/)")
        clean_stale(self.target)
        self.token = _token()
        self.tmp = parent / f".{self.target.name}.tmp-{self.token}"
        try:
            os.mkdir(self.tmp)
        except OSError as e:
            raise ValueError(f"{option}: cannot write in folder '{parent}': "
                             f"{e.strerror or e}") from None

    def file(self, name: str) -> Path:
        """The path to write the set's file ``name`` to (inside :attr:`tmp`)."""
        if not name or os.sep in name or name in (".", ".."):
            raise ValueError(f"name: expected a file name, got {name!r}")
        return self.tmp / name

    def commit(self) -> Path:
        """Swap the new folder in (see the class docstring); returns the target. On an
        error before the swap the new folder is removed and the old one kept."""
        target, tmp = self.target, self.tmp
        try:
            if target.is_dir():
                new = set(os.listdir(tmp))
                for n in new:  # killed direct writers' temporary files of the members
                    clean_stale(target / n)
                _link_tree(target, tmp, skip=new)  # keep the entries of others
                os.chmod(tmp, stat.S_IMODE(os.stat(target).st_mode))
            _fsync_dir(tmp)
        except BaseException:
            self.discard()
            raise
        parent = target.parent
        if not os.path.lexists(target):
            os.rename(tmp, target)
            _fsync_dir(parent)
        elif _exchange(tmp, target):
            _fsync_dir(parent)
            _remove(tmp)  # the old folder, now at the temporary name
        else:
            aside = parent / f".{target.name}.old-{self.token}"
            os.rename(target, aside)
            os.rename(tmp, target)
            _fsync_dir(parent)
            _remove(aside)
        return target

    def discard(self) -> None:
        """Remove the temporary folder (the target stays as it was)."""
        _remove(self.tmp)

