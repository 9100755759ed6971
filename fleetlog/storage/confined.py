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
that resumes or verifies again does not make the vehicle hash the file again. A file being
served is hashed *as its ranges are read* (:meth:`DigestCache.feed`): the bytes a range
request reads from disk are hashed once the reply is sent, in file order, so a client that
fetches a file from its start and then asks for the digest gets it without the vehicle
reading the file a second time. A digest asked for before the ranges reached the end is
finished from the disk, continuing where the ranges stopped.
"""

from __future__ import annotations

import hashlib
import os
import stat
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

from fleetlog.errors import FormatError, StorageError
from fleetlog.wire.query import check_component

__all__ = ["ConfinedRoot", "DigestCache", "FileStat"]

_OPEN_FLAGS = (
    os.O_RDONLY
    | getattr(os, "O_NOFOLLOW", 0)
    | getattr(os, "O_NONBLOCK", 0)
    | getattr(os, "O_CLOEXEC", 0)
)
_HASH_BLOCK = 1 << 20
#: blocks of :meth:`DigestCache.warm`: small, so a request never waits long for it
_WARM_BLOCK = 256 << 10

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
        data, st, _ = self.read_steady(names, offset, length)
        return data, st

    def read_steady(
        self, names: tuple[str, ...], offset: int, length: int
    ) -> tuple[bytes, FileStat, bool]:
        """As :meth:`read_range`; also say whether the file stayed the same during the read.

        The third value is True when the file's identity (device, inode, size, mtime) after
        the read is the one it had when opened: the bytes are then the file's bytes in
        ``st``'s version, fit to be hashed as part of its digest (:meth:`DigestCache.feed`).

        Raises:
            FormatError: a name is not a single path component.
            StorageError: as :meth:`open`, or ``offset`` lies past the end of the file.
        """
        with self.open(*names) as (fd, st):
            if offset > st.st_size:
                msg = f"offset {offset} is past the end of {'/'.join(names)} ({st.st_size} bytes)"
                raise StorageError(msg)
            want = min(length, st.st_size - offset)
            data = _pread_all(fd, want, offset, "/".join(names))
            steady = len(data) == want and _identity(os.fstat(fd)) == _identity(st)
            return data, st, steady


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


class _Running:
    """A sha256 being computed from a file's start, and the ranges waiting for their turn.

    ``offset`` is how much of the file is hashed, or being hashed by the thread that set
    ``busy``; ``pending`` holds ranges read ahead of it, by offset.
    """

    __slots__ = ("busy", "hash", "offset", "pending", "size", "touched")

    def __init__(self, size: int, now: float) -> None:
        self.hash = hashlib.sha256()
        self.size = size
        self.offset = 0
        self.busy = False
        self.pending: dict[int, bytes] = {}
        self.touched = now

    def take(self) -> memoryview | None:
        """Remove and return the pending bytes that continue the hash (None if none do).

        Ranges wholly behind ``offset`` are dropped; the one that covers it is cut to start
        there and ``offset`` is moved past it.
        """
        for start in list(self.pending):
            data = self.pending[start]
            if start + len(data) <= self.offset:
                del self.pending[start]
            elif start <= self.offset:
                del self.pending[start]
                piece = memoryview(data)[self.offset - start :]
                self.offset += len(piece)
                return piece
        return None

    def pending_bytes(self) -> int:
        """Return the bytes held in ``pending``."""
        return sum(len(data) for data in self.pending.values())


class DigestCache:
    """sha256 of files, computed once per (device, inode, size, mtime).

    A digest is computed from the ranges served (:meth:`feed`), in file order, as they are
    read; :meth:`sha256` returns it, finishing it from the disk if the ranges did not reach
    the end. Two requests for the same file hash it once: the second waits for the first.
    The cache keeps the newest ``max_entries`` digests and at most ``max_running`` digests in
    progress, which hold at most ``max_pending`` bytes of ranges read ahead of their turn
    (beyond that, a range is left for :meth:`sha256` to read again). A digest in progress is
    let go as soon as its file changes (a newer version of the same inode starts one: the
    old can never finish), and the ranges waiting in one that nobody fed for ``idle``
    seconds (a fetch abandoned) give way to those of others.
    """

    def __init__(
        self,
        max_entries: int = 4096,
        *,
        max_running: int = 8,
        max_pending: int = 16 << 20,
        idle: float = 30.0,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self._max = max_entries
        self._max_running = max_running
        self._max_pending = max_pending
        self._idle = idle
        self._clock = clock
        self._digests: dict[tuple[int, int, int, int], str] = {}
        self._running: dict[tuple[int, int, int, int], _Running] = {}
        self._lock = threading.Lock()
        self._changed = threading.Condition(self._lock)

    def known(self, st: FileStat) -> str | None:
        """Return the digest of the file version ``st`` if it is already computed."""
        with self._lock:
            return self._digests.get(_identity(st))

    def held(self) -> dict[str, int]:
        """Return what the cache holds: ``digests``, ``running`` and ``pending`` (bytes)."""
        with self._lock:
            pending = sum(run.pending_bytes() for run in self._running.values())
            return {
                "digests": len(self._digests),
                "running": len(self._running),
                "pending": pending,
            }

    def _start(self, key: tuple[int, int, int, int], size: int) -> _Running | None:
        # Under the lock: a digest of this file version begins; older versions of the same
        # file (device, inode) can never finish, so what they hold is let go now.
        for other in [k for k, r in self._running.items() if k[:2] == key[:2] and not r.busy]:
            del self._running[other]
        if not self._make_room():
            return None
        run = self._running[key] = _Running(size, self._clock())
        return run

    def _room_for(self, size: int) -> bool:
        # Under the lock: whether ``size`` more pending bytes fit, after dropping the pending
        # ranges of digests nobody fed for ``idle`` seconds (their fetch was abandoned; what
        # they held is read from the disk again if the digest is ever asked for).
        held = sum(run.pending_bytes() for run in self._running.values())
        if held + size <= self._max_pending:
            return True
        stale = self._clock() - self._idle
        for run in self._running.values():
            if run.touched < stale and run.pending and not run.busy:
                held -= run.pending_bytes()
                run.pending.clear()
        return held + size <= self._max_pending

    def feed(self, st: FileStat, offset: int, data: bytes) -> None:
        """Hash the bytes at ``offset`` of the file version ``st``, if they continue its digest.

        Call it with bytes read from the file while its identity stayed ``st``'s
        (:meth:`ConfinedRoot.read_steady`), of a file that is complete. A range at offset 0
        starts a digest; a later one continues it, or waits in memory until the ranges before
        it arrive; a range whose turn is past, or that does not fit in memory, is ignored. The
        hashing happens in the calling thread (outside the GIL), one thread at a time per file.
        """
        key = _identity(st)
        with self._lock:
            if not data or key in self._digests:
                return
            run = self._running.get(key)
            if run is None and offset == 0:
                run = self._start(key, st.st_size)
            if run is None:
                return
            run.touched = self._clock()
            end = offset + len(data)
            if end <= run.offset:
                return
            if run.busy or offset > run.offset:
                if offset not in run.pending and self._room_for(len(data)):
                    run.pending[offset] = data
                return
            run.busy = True
            piece: memoryview | None = memoryview(data)[run.offset - offset :]
            run.offset = end
        try:
            while piece is not None:
                run.hash.update(piece)
                with self._lock:
                    piece = run.take()
        finally:
            with self._lock:
                run.busy = False
                if run.offset >= run.size:
                    self._finish(key, run)
                self._changed.notify_all()

    def _make_room(self) -> bool:
        # Under the lock: drop the oldest digest in progress that nobody is hashing.
        if len(self._running) < self._max_running:
            return True
        for key, run in self._running.items():
            if not run.busy:
                del self._running[key]
                return True
        return False

    def _finish(self, key: tuple[int, int, int, int], run: _Running) -> str:
        # Under the lock: the digest of the whole file is known.
        digest = run.hash.hexdigest()
        self._running.pop(key, None)
        if len(self._digests) >= self._max:
            self._digests.pop(next(iter(self._digests)))
        self._digests[key] = digest
        return digest

    def sha256(
        self, root: ConfinedRoot, names: tuple[str, ...], cancel: threading.Event | None = None
    ) -> tuple[str, FileStat]:
        """Return the hex sha256 of a file under ``root`` and the stat it belongs to.

        Continues the digest the ranges served so far began (see :meth:`feed`), reading the
        rest of the file from the disk; or hashes the whole file.

        Raises:
            FormatError: a name is not a single path component.
            StorageError: as :meth:`ConfinedRoot.open`; the file changed while it was being
                hashed; or ``cancel`` was set.
        """
        shown = "/".join(names)
        with root.open(*names) as (fd, st):
            key = _identity(st)
            with self._lock:
                while True:
                    found = self._digests.get(key)
                    if found is not None:
                        return found, st
                    run = self._running.get(key)
                    if run is None or not run.busy:
                        break
                    if cancel is not None and cancel.is_set():
                        raise _cancelled(shown)
                    self._changed.wait(0.5)
                if run is None:
                    # without room, hashed all the same (it is asked for), kept only meanwhile
                    run = self._start(key, st.st_size) or _Running(st.st_size, self._clock())
                    self._running[key] = run
                run.busy = True
            digest = ""
            complete = False
            try:
                self._catch_up(fd, run, shown, cancel)
                complete = run.offset == st.st_size and _identity(os.fstat(fd)) == key
            finally:
                with self._lock:
                    run.busy = False
                    if complete:
                        digest = self._finish(key, run)
                    else:  # its state is unknown: the next request starts over
                        self._running.pop(key, None)
                    self._changed.notify_all()
            if not complete:
                msg = f"{shown} changed while it was being hashed; it is still being written"
                raise StorageError(msg)
            return digest, st

    def warm(
        self,
        root: ConfinedRoot,
        names: tuple[str, ...],
        cancel: threading.Event | None = None,
        pause: Callable[[float], None] | None = None,
    ) -> None:
        """Compute a file's digest ahead of any request for it, politely.

        The file is read in blocks and fed as served ranges are (:meth:`feed`), so a fetch
        that starts meanwhile shares the work: the blocks its ranges already hashed are
        skipped, and while another thread hashes the file this one waits. After each block
        ``pause(seconds it took)`` is called (the caller sleeps, or waits for an idle moment).
        Stops quietly when the file changes, cannot be read, or ``cancel`` is set.
        """
        try:
            with root.open(*names) as (fd, st):
                key = _identity(st)
                while cancel is None or not cancel.is_set():
                    with self._lock:
                        if key in self._digests:
                            return
                        run = self._running.get(key)
                        if run is not None and run.busy:
                            self._changed.wait(0.05)
                            continue
                        offset = 0 if run is None else run.offset
                    if offset >= st.st_size:
                        return
                    started = time.monotonic()
                    want = min(_WARM_BLOCK, st.st_size - offset)
                    block = _pread_all(fd, want, offset, "/".join(names))
                    if len(block) != want or _identity(os.fstat(fd)) != key:
                        return  # changed: being written after all
                    self.feed(st, offset, block)
                    with self._lock:
                        run = self._running.get(key)
                        if key not in self._digests and (run is None or run.offset <= offset):
                            return  # no room for another digest in progress: left for later
                    if pause is not None:
                        pause(time.monotonic() - started)
        except (StorageError, FormatError, OSError):
            return

    def _catch_up(self, fd: int, run: _Running, shown: str, cancel: threading.Event | None) -> None:
        # The calling thread owns ``run`` (busy): hash what is pending, else read the disk.
        while True:
            with self._lock:
                piece = run.take()
            if piece is None:
                if run.offset >= run.size:
                    return
                if cancel is not None and cancel.is_set():
                    raise _cancelled(shown)
                block = _pread_all(fd, min(_HASH_BLOCK, run.size - run.offset), run.offset, shown)
                if not block:
                    return  # truncated: the caller sees the offset short of the size
                with self._lock:
                    run.offset += len(block)
                piece = memoryview(block)
            run.hash.update(piece)


def _cancelled(shown: str) -> StorageError:
    return StorageError(f"hashing {shown} was cancelled (the server is closing)")
