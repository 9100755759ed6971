"""Export outputs that appear whole or not at all: a file, or a directory of files.

An export can take minutes and be interrupted (Ctrl-C, a full disk, a bad input half way).
What it leaves must never look like a finished export: each output is written beside its
final name, hidden (``.NAME.tmp``), fsynced, and renamed into place only when complete. A
directory (one session of a fleet dataset) is renamed whole, so a dataset reader sees a
session's files all or none. An output that already exists is never overwritten unless
asked, and a directory never is.
"""

from __future__ import annotations

import contextlib
import os
import shutil
from collections.abc import Iterator
from pathlib import Path
from typing import BinaryIO

from fleetlog.errors import StorageError
from fleetlog.storage.files import fsync_dir

__all__ = ["atomic_output", "staged_directory"]


def _why(err: OSError) -> str:
    return err.strerror or str(err)


@contextlib.contextmanager
def atomic_output(path: Path, *, overwrite: bool = True) -> Iterator[BinaryIO]:
    """Yield a binary file that becomes ``path`` when the block ends without an error.

    Raises:
        StorageError: the file cannot be created or written, or it exists and ``overwrite``
            is False.
    """
    if not overwrite and path.exists():
        msg = f"{path} exists; it is not overwritten"
        raise StorageError(msg)
    tmp = path.with_name(f".{path.name}.tmp")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        out = tmp.open("wb")
    except OSError as err:
        msg = f"cannot write {path}: {_why(err)}"
        raise StorageError(msg) from None
    try:
        with out:
            yield out
            out.flush()
            os.fsync(out.fileno())
        os.replace(tmp, path)
        fsync_dir(path.parent)
    except OSError as err:
        with contextlib.suppress(OSError):
            tmp.unlink()
        msg = f"cannot write {path}: {_why(err)}"
        raise StorageError(msg) from None
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise


@contextlib.contextmanager
def staged_directory(final: Path, staging: Path) -> Iterator[Path]:
    """Yield an empty directory that is renamed to ``final`` when the block succeeds.

    ``staging`` is where the directory is built (on the same file system as ``final``, and
    hidden from readers of the tree); it is removed if the block fails. Every file written in
    it is fsynced before the rename.

    Raises:
        StorageError: ``final`` exists already, or the directories cannot be made or renamed.
    """
    if final.exists():
        msg = f"{final} exists; it is never rewritten"
        raise StorageError(msg)
    try:
        if staging.exists():
            shutil.rmtree(staging)  # left by an interrupted run: never part of the output
        staging.mkdir(parents=True)
    except OSError as err:
        msg = f"cannot make {staging}: {_why(err)}"
        raise StorageError(msg) from None
    try:
        yield staging
        for child in staging.iterdir():
            fd = os.open(child, os.O_RDONLY)
            try:
                os.fsync(fd)
            finally:
                os.close(fd)
        final.parent.mkdir(parents=True, exist_ok=True)
        os.rename(staging, final)
        fsync_dir(final.parent)
    except OSError as err:
        shutil.rmtree(staging, ignore_errors=True)
        msg = f"cannot write {final}: {_why(err)}"
        raise StorageError(msg) from None
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
