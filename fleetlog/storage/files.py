"""Small whole files written atomically: configuration, certificates, keys, manifests."""

from __future__ import annotations

import contextlib
import os
from pathlib import Path

from fleetlog.errors import StorageError

__all__ = ["fsync_dir", "read_small", "write_atomic"]

#: a configuration or certificate file is never larger than this
SMALL = 4 * 1024 * 1024


def fsync_dir(directory: Path) -> None:
    """Make a rename or a new entry in ``directory`` durable.

    Best effort: some file systems cannot fsync a directory, and the data is on disk already.
    """
    try:
        fd = os.open(directory, os.O_RDONLY | os.O_DIRECTORY | os.O_CLOEXEC)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def write_atomic(path: Path, data: bytes, mode: int = 0o644) -> None:
    """Write ``data`` to ``path``: a temporary file beside it, fsync, rename, fsync its directory.

    A reader sees the old file or the new one, never a part; a key written with mode 0o600
    is never readable by others, not even for a moment.

    Raises:
        StorageError: the directory cannot be created or the file written.
    """
    tmp = path.with_name(f".{path.name}.tmp")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        flags = os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_NOFOLLOW | os.O_CLOEXEC
        fd = os.open(tmp, flags, mode)
        try:
            os.fchmod(fd, mode)
            view = memoryview(data)
            while view:
                view = view[os.write(fd, view) :]
            os.fsync(fd)
        finally:
            os.close(fd)
        os.replace(tmp, path)
        fsync_dir(path.parent)
    except OSError as err:
        with contextlib.suppress(OSError):
            tmp.unlink()
        msg = f"cannot write {path}: {err.strerror or err}"
        raise StorageError(msg) from None


def read_small(path: Path, what: str) -> bytes:
    """Read a small file whole.

    Raises:
        StorageError: it is missing, unreadable or over 4 MiB.
    """
    try:
        with path.open("rb") as f:
            data = f.read(SMALL + 1)
    except FileNotFoundError:
        msg = f"{what} {path} does not exist"
        raise StorageError(msg) from None
    except OSError as err:
        msg = f"cannot read {what} {path}: {err.strerror or err}"
        raise StorageError(msg) from None
    if len(data) > SMALL:
        msg = f"{what} {path} is over {SMALL // (1024 * 1024)} MiB: not a configuration file"
        raise StorageError(msg)
    return data
