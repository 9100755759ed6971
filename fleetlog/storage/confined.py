"""Files served from a log root, and nothing else: path confinement, ranges and digests.

A remote request names a session and a file; this module turns those names into an open
regular file *inside* the log root or refuses:

* each name must be one path component (:func:`fleetlog.wire.query.check_component`);
* the path is resolved (every symlink followed) and must stay under the resolved root, so a
  symlink that leaves the root is refused even though its name looks harmless;
* the file is opened with ``O_NOFOLLOW`` (a symlink swapped in after the check is refused)
  and ``O_NONBLOCK`` (a FIFO planted in a session cannot hang a server thread), then must be
  a regular file.

sha256 digests of complete files are cached by (device, inode, size, mtime), so a client
that resumes or verifies again does not make the vehicle hash the file again.
"""

from __future__ import annotations

import hashlib
import os
import stat
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from fleetlog.errors import StorageError
from fleetlog.wire.query import check_component

__all__ = ["ConfinedRoot", "DigestCache", "FileStat"]

_OPEN_FLAGS = (
    os.O_RDONLY
    | getattr(os, "O_NOFOLLOW", 0)
    | getattr(os, "O_NONBLOCK", 0)
    | getattr(os, "O_CLOEXEC", 0)
)
_HASH_BLOCK = 1 << 20

FileStat = os.stat_result


class ConfinedRoot:
    """A directory whose regular files may be read by name, and nothing outside it.

    Args:
        root: the log root.

    Raises:
        StorageError: the root does not exist or is not a directory.
    """

    def __init__(self, root: str | os.PathLike[str]) -> None:
        real = Path(os.path.realpath(root))
        if not real.is_dir():
            msg = f"log root {root} is not a directory"
            raise StorageError(msg)
        self.path = real

    def resolve(self, *names: str) -> Path:
        """Return the real path of ``root/names...``, refusing anything outside the root.

        Raises:
            FormatError: a name is not a single path component.
            StorageError: the path (after following symlinks) leaves the root.
        """
        for index, name in enumerate(names):
            check_component(name, "session" if index == 0 else "file")
        real = Path(os.path.realpath(self.path.joinpath(*names)))
        if real == self.path or not real.is_relative_to(self.path):
            msg = f"{'/'.join(names)} leads outside the log root (a symlink?); refused"
            raise StorageError(msg)
        return real

    def contains(self, path: str | os.PathLike[str]) -> bool:
        """Return True if ``path``, resolved, lies strictly under the root."""
        real = Path(os.path.realpath(path))
        return real != self.path and real.is_relative_to(self.path)

    @contextmanager
    def open(self, *names: str) -> Iterator[tuple[int, FileStat]]:
        """Open a regular file under the root for reading; yield its descriptor and stat.

        Raises:
            FormatError: a name is not a single path component.
            StorageError: the file is outside the root, missing, not a regular file, or
                cannot be opened.
        """
        real = self.resolve(*names)
        shown = "/".join(names)
        try:
            fd = os.open(real, _OPEN_FLAGS)
        except FileNotFoundError:
            msg = f"{shown} does not exist"
            raise StorageError(msg) from None
        except OSError as err:
            msg = f"cannot open {shown}: {err.strerror or err}"
            raise StorageError(msg) from None
        try:
            st = os.fstat(fd)
            if not stat.S_ISREG(st.st_mode):
                msg = f"{shown} is not a regular file"
                raise StorageError(msg)
            yield fd, st
        finally:
            os.close(fd)

    def read_range(
        self, names: tuple[str, ...], offset: int, length: int
    ) -> tuple[bytes, FileStat]:
        """Read up to ``length`` bytes at ``offset`` of a file under the root.

        The bytes returned never go past the size the file had when it was opened, so the
        size and the data a reply carries agree even while the file grows.

        Raises:
            FormatError: a name is not a single path component.
            StorageError: as :meth:`open`, or ``offset`` lies past the end of the file.
        """
        with self.open(*names) as (fd, st):
            if offset > st.st_size:
                msg = f"offset {offset} is past the end of {'/'.join(names)} ({st.st_size} bytes)"
                raise StorageError(msg)
            want = min(length, st.st_size - offset)
            return _pread_all(fd, want, offset, "/".join(names)), st


def _pread_all(fd: int, length: int, offset: int, shown: str) -> bytes:
    parts: list[bytes] = []
    got = 0
    while got < length:
        try:
            piece = os.pread(fd, length - got, offset + got)
        except OSError as err:
            msg = f"cannot read {shown}: {err.strerror or err}"
            raise StorageError(msg) from None
        if not piece:
            break  # truncated meanwhile: send what is there
        parts.append(piece)
        got += len(piece)
    return parts[0] if len(parts) == 1 else b"".join(parts)


def _identity(st: FileStat) -> tuple[int, int, int, int]:
    return (st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns)


class DigestCache:
    """sha256 of files, computed once per (device, inode, size, mtime).

    Two requests for the same file hash it once: the second waits for the first. The cache
    keeps the newest ``max_entries`` digests.
    """

    def __init__(self, max_entries: int = 4096) -> None:
        self._max = max_entries
        self._digests: dict[tuple[int, int, int, int], str] = {}
        self._lock = threading.Lock()
        self._busy: dict[tuple[int, int, int, int], threading.Lock] = {}

    def sha256(
        self, root: ConfinedRoot, names: tuple[str, ...], cancel: threading.Event | None = None
    ) -> tuple[str, FileStat]:
        """Return the hex sha256 of a file under ``root`` and the stat it belongs to.

        Raises:
            FormatError: a name is not a single path component.
            StorageError: as :meth:`ConfinedRoot.open`; the file changed while it was being
                hashed; or ``cancel`` was set.
        """
        with root.open(*names) as (fd, st):
            key = _identity(st)
            with self._lock:
                found = self._digests.get(key)
                if found is not None:
                    return found, st
                busy = self._busy.setdefault(key, threading.Lock())
            with busy:
                with self._lock:
                    found = self._digests.get(key)
                if found is None:
                    found = _hash_fd(fd, st, "/".join(names), cancel)
                    with self._lock:
                        if len(self._digests) >= self._max:
                            self._digests.pop(next(iter(self._digests)))
                        self._digests[key] = found
            with self._lock:
                self._busy.pop(key, None)
            return found, st


def _hash_fd(fd: int, st: FileStat, shown: str, cancel: threading.Event | None) -> str:
    digest = hashlib.sha256()
    offset = 0
    while offset < st.st_size:
        if cancel is not None and cancel.is_set():
            msg = f"hashing {shown} was cancelled (the server is closing)"
            raise StorageError(msg)
        block = _pread_all(fd, min(_HASH_BLOCK, st.st_size - offset), offset, shown)
        if not block:
            break
        digest.update(block)
        offset += len(block)
    after = os.fstat(fd)
    if offset != st.st_size or _identity(after) != _identity(st):
        msg = f"{shown} changed while it was being hashed; it is still being written"
        raise StorageError(msg)
    return digest.hexdigest()
