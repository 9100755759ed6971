"""The columns of a batch of entries, and the columnar library they are computed with.

:data:`SCHEMA` names the columns every consumer of the read path sees. polars is imported
on first use (:func:`polars_module`), so a process that never reads a log never loads it,
and its thread pool is sized then: :func:`limit_threads` caps it beforehand (a recorder: 1).
:func:`decode_block` turns a block of log bytes into text with one character per byte that
is not UTF-8, so character positions match a ``surrogateescape`` decoding.
"""

from __future__ import annotations

import codecs
import functools
import importlib
import os
import sys
from types import ModuleType
from typing import Any, Literal

from fleetlog.errors import StorageError

__all__ = [
    "ALWAYS",
    "SCHEMA",
    "TYPES",
    "Errors",
    "decode_block",
    "in_memory",
    "limit_threads",
    "polars_module",
]

#: The error policy: ``"raise"`` (tests, tools) or ``"skip"`` (field logs, remote grep).
Errors = Literal["raise", "skip"]

#: The columns of a batch and their types, in order (polars type names).
SCHEMA: dict[str, str] = {
    "line": "Int64",
    "offset": "Float64",
    "time": "Float64",
    "var": "String",
    "source": "String",
    "src": "String",
    "aux": "String",
    "type": "Enum(double, string, binary)",
    "double": "Float64",
    "text": "String",
    "raw": "Binary",
}
TYPES = ("double", "string", "binary")
#: Columns every batch has inside the reader (what entries() needs besides SCHEMA's).
ALWAYS = frozenset(("line", "offset", "var", "source", "type", "double", "text", "nlines"))


def _byte_per_char(err: UnicodeError) -> tuple[str, int]:
    # One U+FFFD per undecodable byte, as surrogateescape gives one surrogate per byte: the
    # two decodings have the same characters at the same places, so positions carry over.
    if not isinstance(err, UnicodeDecodeError):  # pragma: no cover - registered for decoding
        raise err
    return "\ufffd" * (err.end - err.start), err.end


codecs.register_error("fleetlog.byte-per-char", _byte_per_char)


def limit_threads(threads: int) -> bool:
    """Cap the columnar library's thread pool in this process (a recorder: 1).

    polars sizes its pool when it is first imported, so this works only before the first
    read; it returns False (and changes nothing) when polars is already loaded.
    """
    if "polars" in sys.modules:
        return False
    os.environ["POLARS_MAX_THREADS"] = str(max(1, threads))
    return True


def polars_module() -> ModuleType:
    """Return the polars module, importing it on first use."""
    try:
        return importlib.import_module("polars")
    except ImportError as err:  # pragma: no cover - a dependency; a broken install only
        msg = "reading logs needs polars (pip install polars); it is not installed"
        raise StorageError(msg) from err


@functools.cache
def in_memory(pl: ModuleType) -> Any:
    """Return the name of polars' in-memory engine, the one the reader's queries run on.

    polars 2 runs a query on its streaming engine unless told otherwise: for the reader's
    queries (one block, a few MB) that cost a third more CPU and more wall time, on a thread
    of its own (measured here, one thread: docs/bench.md §9.3). polars 1 calls it ``cpu``
    before it had the streaming engine's name for it.
    """
    try:
        pl.LazyFrame({"a": [0]}).collect(engine="in-memory")
    except (TypeError, ValueError):  # pragma: no cover - polars before 1.23
        return "cpu"
    return "in-memory"


def decode_block(block: bytes | memoryview) -> tuple[str, bool]:
    """Decode log bytes; return the text and whether they were all UTF-8.

    A byte that is not UTF-8 becomes one U+FFFD, so the text has a character wherever
    ``surrogateescape`` would, and positions found in it carry over to the exact decoding.
    """
    try:
        return str(block, "utf-8"), True
    except UnicodeDecodeError:
        return str(block, "utf-8", "fleetlog.byte-per-char"), False
