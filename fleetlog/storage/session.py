"""One pLogger session directory on disk: its files, banners, copies and the hint file.

MOOS_FORMAT.md §1 is the layout: ``<path>/<root>/<root>.{alog,ylog,blog,_moos}``, ``.slog``
with SyncLog, ``.xlog`` with the exclusion log, ``.alog.zst``/``.alog.gz`` when compressing,
``<root>._hoof`` for a pHelm TaskFile, copies from COPY_FILE_REQUEST, and the
``.LastOpenedMOOSLogDirectory`` hint in the working directory. The directory string
(``path + "/" + root``) is built exactly as pLogger builds it, because it appears in the
banners, the hint file and LOGGER_DIRECTORY.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import stat
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

from fleetlog.errors import StorageError
from fleetlog.moos.alog import BinaryRef, Variant, format_banner
from fleetlog.moos.naming import (
    copy_file_name,
    ctime_text,
    hint_file_content,
    session_dir,
    session_root,
    unique_root,
)
from fleetlog.storage.metafile import DirLock, write_meta
from fleetlog.storage.streams import OutStream, PlainStream, open_stream
from fleetlog.wire.session_meta import SessionMeta

__all__ = ["SessionLayout", "SessionWriter", "copy_mission"]

_EXT = {"none": "", "zstd": ".zst", "gzip": ".gz"}


@dataclass(frozen=True)
class SessionLayout:
    """What to open: everything the configuration decides about a session's files.

    Attributes:
        file: pLogger's ``File`` (the root name's stem).
        path: the log path, one trailing ``/`` already removed (``.`` by default).
        timestamp: FileTimeStamp.
        utc: UTCLogDirectories.
        variant: the on-disk variant (banner LOGSTART precision).
        compression: ``none``, ``zstd`` or ``gzip``.
        sync_log: write a ``.slog``.
        exclusion_log: write an ``.xlog``.
        mark_data_type: the banner's DATATYPE MARKING line.
        summary_file: the hint file's path (relative to ``cwd``).
        mission_path: the mission file to back up as ``._moos`` (None without one).
        helm_task_file: a pHelm TaskFile to back up as ``._hoof``.
    """

    file: str = "MOOSLog"
    path: str = "."
    timestamp: bool = True
    utc: bool = False
    variant: Variant = Variant.IVP
    compression: str = "none"
    sync_log: bool = False
    exclusion_log: bool = False
    mark_data_type: bool = False
    summary_file: str = ".LastOpenedMOOSLogDirectory"
    mission_path: Path | None = None
    helm_task_file: str | None = None


def copy_mission(source: bytes, banner: str) -> bytes:
    r"""Return a ``._moos`` backup: banner then the mission copied line by line.

    pLogger writes every line back followed by ``\n`` and stops only after a failed read, so
    a file that ends in ``\n`` gains one extra empty line (§1.5); ``\r`` survives.
    """
    lines = source.split(b"\n")
    body = b"".join(line + b"\n" for line in lines)
    return banner.encode("utf-8", "surrogateescape") + body


class SessionWriter:
    """The open files of one session.

    Use :meth:`open`; then append with the ``write_*`` methods, :meth:`flush` regularly and
    :meth:`close` at the end. Every OS failure is raised as :class:`StorageError` naming the
    file, so the recorder can count what it lost and carry on.
    """

    def __init__(
        self,
        layout: SessionLayout,
        directory: str,
        root: str,
        logstart: float,
        cwd: Path,
        fallback: bool,
    ) -> None:
        self.layout = layout
        #: the directory string as pLogger builds it (``path/root``, relative if path was)
        self.directory = directory
        self.root = root
        self.logstart = logstart
        self.fallback = fallback
        self._cwd = cwd
        self.dir_path = (cwd / directory) if not os.path.isabs(directory) else Path(directory)
        self.alog: OutStream
        self.xlog: OutStream | None = None
        self.ylog: PlainStream
        self.slog: PlainStream | None = None
        self.blog: PlainStream
        self._streams: list[OutStream] = []
        self.closed = False
        #: problems that did not stop the session (the hint file could not be written)
        self.warnings: list[str] = []
        #: held from open until :meth:`finish`: this recorder is alive
        self.lock: DirLock | None = None
        #: files copied in by COPY_FILE_REQUEST (fsynced at the end like the logs)
        self.copies: list[Path] = []
        #: taken by :meth:`sync` and :meth:`close`, so a descriptor is never fsynced closed
        self._sync_lock = threading.Lock()

    # ----------------------------------------------------------------------------------------
    @classmethod
    def open(
        cls,
        layout: SessionLayout,
        logstart: float,
        *,
        when: float | None = None,
        cwd: Path | None = None,
    ) -> SessionWriter:
        """Create the session directory and its files, write banners, backups and the hint.

        Args:
            layout: what the configuration says to open.
            logstart: the session's LOGSTART (seconds since the epoch).
            when: the wall-clock time naming the directory (now by default).
            cwd: the directory relative paths start from (the process's cwd by default).

        Raises:
            StorageError: neither the configured directory nor the ``./<root>`` fallback
                could be created.
        """
        base = Path.cwd() if cwd is None else cwd
        now = time.time() if when is None else when
        stamp = time.gmtime(now) if layout.utc else time.localtime(now)
        root = session_root(layout.file, stamp, layout.timestamp)

        def resolve(d: str) -> Path:
            return Path(d) if os.path.isabs(d) else base / d

        if layout.timestamp:
            # §12: never reuse (and truncate) an existing time-stamped directory.
            root = unique_root(
                root,
                lambda r: (
                    resolve(session_dir(layout.path, r)).exists()
                    or resolve(session_dir(".", r)).exists()
                ),
            )
        directory = session_dir(layout.path, root)
        fallback = False
        created = False
        try:
            created = _mkdir(resolve(directory))
        except OSError as first:
            # pLogger's fallback: the working directory (§1.2).
            directory = session_dir(".", root)
            fallback = True
            try:
                created = _mkdir(resolve(directory))
            except OSError as err:
                msg = (
                    f"cannot create log directory {session_dir(layout.path, root)} "
                    f"({first.strerror}) nor the fallback {directory} ({err.strerror})"
                )
                raise StorageError(msg) from err
        writer = cls(layout, directory, root, logstart, base, fallback)
        # Locked before anything says "open": a recorder starting meanwhile never takes a
        # session being created for a cut one.
        writer.lock = DirLock(writer.dir_path)
        try:
            writer._open_files(now)
        except StorageError:
            # Closing flushes the same broken file again; the first error is the one to report.
            with contextlib.suppress(StorageError):
                writer.close()
            if created:
                # Never a session: what it created goes, so that retrying on a full disk
                # does not leave a trail of empty directories.
                writer._remove_created()
            writer.lock.release()
            raise
        return writer

    def _remove_created(self) -> None:
        for stream in self._streams:
            with contextlib.suppress(OSError):
                stream.path.unlink()
        for ext in ("._moos", "._hoof"):
            with contextlib.suppress(OSError):
                self._file(ext).unlink()
        with contextlib.suppress(OSError):
            self.dir_path.rmdir()

    def _name(self, ext: str) -> str:
        """The file name pLogger puts in banners: ``dir/root.ext``."""
        return f"{self.directory}/{self.root}{ext}"

    def _file(self, ext: str) -> Path:
        return self.dir_path / f"{self.root}{ext}"

    def banner(self, ext: str, opened: float, *, left: bool = False) -> str:
        """Return the banner of the file with extension ``ext``."""
        return format_banner(
            self._name(ext),
            self.logstart,
            ctime_text(time.localtime(opened)),
            variant=self.layout.variant,
            mark_data_type=self.layout.mark_data_type,
            left_logstart=left,
        )

    def _open_files(self, now: float) -> None:
        layout = self.layout
        zext = _EXT[layout.compression]
        self.alog = self._track(open_stream(self._file(".alog" + zext), layout.compression))
        self.alog.write(self.banner(".alog", now))
        if layout.compression != "none":
            # pLogger always opens the compressed xlog; with the exclusion log off it stays
            # an empty stream, with it on it starts with the alog's banner (§1.3).
            self.xlog = self._track(open_stream(self._file(".xlog" + zext), layout.compression))
            if layout.exclusion_log:
                self.xlog.write(self.banner(".alog", now))
        elif layout.exclusion_log:
            self.xlog = self._track(PlainStream(self._file(".xlog")))  # no banner (§4.2)
        self.ylog = PlainStream(self._file(".ylog"))
        self._track(self.ylog).write(self.banner(".ylog", now))
        if layout.sync_log:
            # The recorder writes the slog's banner with its header (SlogTable.start).
            self.slog = PlainStream(self._file(".slog"))
            self._track(self.slog)
        self.blog = PlainStream(self._file(".blog"))
        self._track(self.blog)
        if layout.mission_path is not None:
            self._backup(layout.mission_path, "._moos", self.banner("._moos", now))
        if layout.helm_task_file:
            task = Path(layout.helm_task_file)
            if not task.is_absolute():
                # Relative to the working directory, as pLogger reads it; else beside the mission.
                near = (layout.mission_path.parent if layout.mission_path else self._cwd) / task
                task = self._cwd / task if (self._cwd / task).exists() else near
            self._backup(task, "._hoof", None)
        try:
            self.write_hint()
        except StorageError as err:
            # pLogger ignores a summary file it cannot write; a read-only working directory
            # (a service started in /) must not stop logging into a writable Path.
            self.warnings.append(str(err))
        self.flush(now)

    def _track(self, stream: OutStream) -> OutStream:
        self._streams.append(stream)
        return stream

    def _backup(self, source: Path, ext: str, banner: str | None) -> None:
        try:
            data = source.read_bytes()
        except OSError:
            return  # pLogger skips a backup it cannot read
        out = copy_mission(data, banner) if banner is not None else data
        target = self._file(ext)
        try:
            target.write_bytes(out)
        except OSError as err:
            msg = f"cannot write {target}: {err.strerror}"
            raise StorageError(msg) from err

    def write_hint(self) -> None:
        """(Re)write the ``.LastOpenedMOOSLogDirectory`` hint file.

        Raises:
            StorageError: the hint file cannot be written.
        """
        hint = Path(self.layout.summary_file)
        if not hint.is_absolute():
            hint = self._cwd / hint
        try:
            hint.write_text(hint_file_content(self.directory), encoding="utf-8")
        except OSError as err:
            msg = f"cannot write the session hint file {hint}: {err.strerror}"
            raise StorageError(msg) from err

    # ----------------------------------------------------------------------------------------
    def write_blog(self, prefix: str, payload: bytes) -> BinaryRef:
        """Append a binary record (alog prefix, payload, newline) and return its reference."""
        head = prefix.encode("utf-8", "surrogateescape")
        start = self.blog.tell()
        self.blog.write_bytes(head + payload + b"\n")
        return BinaryRef(f"{self.root}.blog", start + len(head), len(payload))

    def copy_file(self, source: Path, requested: str) -> Path:
        """Copy a file into the session as COPY_FILE_REQUEST does (``stem._ext``).

        Raises:
            StorageError: the file cannot be read or the copy written.
        """
        target = self.dir_path / copy_file_name(requested)
        try:
            shutil.copyfile(source, target)
        except OSError as err:
            msg = f"cannot copy {source} to {target}: {err.strerror}"
            raise StorageError(msg) from err
        if target not in self.copies:
            self.copies.append(target)
        return target

    def copy_from(self, source: BinaryIO, requested: str, limit: int) -> Path:
        """Copy an open file into the session as COPY_FILE_REQUEST does (``stem._ext``).

        The caller opened and checked the file; at most ``limit`` bytes are copied (a file
        that grew past it while being copied is removed, not cut).

        Raises:
            StorageError: the copy could not be written, or the file grew past ``limit``.
        """
        target = self.dir_path / copy_file_name(requested)
        try:
            with open(target, "wb") as out:
                copied = 0
                while chunk := source.read(1 << 20):
                    copied += len(chunk)
                    if copied > limit:
                        break
                    out.write(chunk)
        except OSError as err:
            msg = f"cannot copy {requested} to {target}: {err.strerror}"
            raise StorageError(msg) from err
        if copied > limit:
            target.unlink(missing_ok=True)
            msg = f"{requested} grew past {limit} bytes while it was copied"
            raise StorageError(msg)
        if target not in self.copies:
            self.copies.append(target)
        return target

    def write_meta(self, meta: SessionMeta | bytes, *, durable: bool = True) -> None:
        """Replace the session's metadata file atomically (write, fsync, rename, fsync).

        Raises:
            StorageError: it could not be written.
        """
        write_meta(self.dir_path, meta, durable=durable)

    def flush(self, now: float) -> None:
        """Hand every stream's buffer to the OS (compressed ones per their interval)."""
        for stream in self._streams:
            stream.flush(now)

    def unit_due(self) -> float | None:
        """Return when a compressed stream's pending text is next due in a unit (or None)."""
        dues = [due for stream in self._streams if (due := stream.unit_due()) is not None]
        return min(dues, default=None)

    def sync(self) -> None:
        """Sync every open stream to the disk (what was flushed to the OS survives a power cut).

        Safe from another thread while the recorder writes; does nothing once closed.

        Raises:
            StorageError: a file could not be synced (names it and why).
        """
        with self._sync_lock:
            if self.closed:
                return
            for stream in self._streams:
                try:
                    os.fsync(stream.fileno())
                except (OSError, ValueError) as err:
                    reason = err.strerror if isinstance(err, OSError) else str(err)
                    msg = f"cannot sync {stream.path}: {reason}"
                    raise StorageError(msg) from err

    def removed(self) -> bool:
        """Return True if the alog was unlinked (its directory removed): writes would vanish."""
        try:
            return os.fstat(self.alog.fileno()).st_nlink == 0
        except (OSError, ValueError):
            return False

    def files_removed(self) -> bool:
        """Whether the session's files are gone: its alog unlinked, or its own directory.

        Unlike :meth:`removed`, also once the session is closed (its streams with it).
        """
        return self.removed() or (self.layout.timestamp and not self.dir_path.is_dir())

    def take_unwritten(self) -> dict[str, int]:
        """Return the samples whose lines never became readable (a failed write), and forget.

        Per variable; only alog and xlog lines count (one per sample).
        """
        names: dict[str, int] = {}
        for stream in (self.alog, self.xlog):
            if stream is None:
                continue
            for name, count in stream.unwritten_names.items():
                names[name] = names.get(name, 0) + count
            # Lines whose name was not kept (past 1024 names) are counted without one.
            rest = stream.unwritten - sum(stream.unwritten_names.values())
            if rest:
                names["?"] = names.get("?", 0) + rest
            stream.unwritten = 0
            stream.unwritten_names.clear()
        return names

    def take_pending(self) -> dict[str, list[str]]:
        """Return the text lines not yet flushed, per stream (alog, xlog, ylog), and forget them."""
        pending: dict[str, list[str]] = {}
        for kind, stream in (("alog", self.alog), ("xlog", self.xlog), ("ylog", self.ylog)):
            if stream is not None:
                pending[kind] = stream.take_text()
        return pending

    def take_wait(self) -> float:
        """Return the longest flushed text waited to become readable (compressed), and reset."""
        return max((s.take_wait() for s in self._streams), default=0.0)

    def disk_bytes(self) -> int:
        """Return the bytes the session's log files hold on disk (what reached the OS)."""
        total = 0
        for stream in self._streams:
            with contextlib.suppress(OSError, ValueError):
                total += os.fstat(stream.fileno()).st_size
        return total

    def paths(self) -> list[Path]:
        """Return the session's files: its logs and the copies made into it."""
        return (
            [s.path for s in self._streams]
            + [self._file(ext) for ext in ("._moos", "._hoof") if self._file(ext).exists()]
            + list(self.copies)
        )

    def close(self) -> None:
        """Close every stream; the first failure is raised after all were tried.

        The directory stays locked until :meth:`finish`.
        """
        with self._sync_lock:
            if self.closed:
                return
            self.closed = True
        first: StorageError | None = None
        for stream in self._streams:
            try:
                stream.close()
            except (StorageError, OSError) as err:
                if first is None:
                    first = err if isinstance(err, StorageError) else StorageError(str(err))
        if first is not None:
            raise first

    def finish(self, meta: SessionMeta | bytes | None) -> None:
        """After :meth:`close`: fsync the files, write the last metadata, unlock.

        The files are synced through new descriptors (fsync applies to the file, whichever
        descriptor asks), so this may run in another thread while the recorder goes on.
        Nothing is written into the session afterwards.

        Raises:
            StorageError: a file or the metadata could not be synced or written; the lock
                is released either way.
        """
        try:
            first: StorageError | None = None
            for path in self.paths():
                try:
                    fd = os.open(path, os.O_RDONLY | os.O_CLOEXEC | os.O_NONBLOCK)
                    try:
                        if stat.S_ISREG(os.fstat(fd).st_mode):
                            os.fsync(fd)
                    finally:
                        os.close(fd)
                except FileNotFoundError:
                    continue  # the directory was removed: nothing left to sync
                except OSError as err:
                    if first is None:
                        msg = f"cannot sync {path}: {err.strerror}"
                        first = StorageError(msg)
            if meta is not None:
                self.write_meta(meta)
            if first is not None:
                raise first
        finally:
            if self.lock is not None:
                self.lock.release()


def _mkdir(path: Path) -> bool:
    """mkdir, not recursive, as pLogger does; an existing directory is reused.

    Returns:
        True if it was created.
    """
    try:
        path.mkdir(mode=0o755)
    except FileExistsError:
        if not path.is_dir():
            raise
        return False
    return True
