"""Which file is a session directory's alog, and whether a directory holds one."""

from __future__ import annotations

import os
from pathlib import Path

from fleetlog.errors import StorageError

__all__ = ["ALOG_SUFFIXES", "find_alog", "holds_alog"]

#: an alog as pLogger writes it, or compressed by fleetlog
ALOG_SUFFIXES = (".alog", ".alog.zst", ".alog.gz")


def holds_alog(directory: str | os.PathLike[str]) -> bool:
    """Whether ``directory`` holds an alog file: what makes a directory a session.

    A directory that only *holds a directory* named ``X.alog`` is not one.

    Raises:
        OSError: the directory cannot be listed.
    """
    with os.scandir(directory) as it:
        return any(e.name.endswith(ALOG_SUFFIXES) and e.is_file() for e in it)


def find_alog(session_dir: str | os.PathLike[str]) -> Path:
    """Return the alog of a session directory: ``.alog``, ``.alog.zst`` or ``.alog.gz``.

    The one named after the directory (``root/root.alog``) is preferred, in that suffix
    order; otherwise the directory must hold exactly one alog.

    Raises:
        StorageError: the directory cannot be listed, holds no alog, or holds several and
            none is named after it.
    """
    directory = Path(session_dir)
    for suffix in ALOG_SUFFIXES:
        named = directory / (directory.name + suffix)
        if named.is_file():
            return named
    try:
        found = sorted(
            child
            for child in directory.iterdir()
            if child.name.endswith(ALOG_SUFFIXES) and child.is_file()
        )
    except OSError as err:
        msg = f"cannot list session directory {directory}: {err.strerror or err}"
        raise StorageError(msg) from err
    if not found:
        msg = f"{directory} holds no .alog, .alog.zst or .alog.gz"
        raise StorageError(msg)
    if len(found) > 1:
        names = ", ".join(child.name for child in found)
        msg = f"{directory} holds several alogs and none is named after it: {names}"
        raise StorageError(msg)
    return found[0]
