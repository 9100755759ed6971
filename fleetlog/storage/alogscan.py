r"""What a session listing says about an alog, read cheaply: head, tail and variable names.

Every part reads through the columnar reader's parser (:mod:`fleetlog.storage.columnar`):

* :func:`read_head` reads the banner and the first entries (at most 256 KiB of text): LOGSTART,
  the time column's decimals, MarkDataType and the community from the MOOSDB's ``DB_TIME``
  source (``MOOSDB_<community>``, as alogsplit finds the vehicle name, MOOS_FORMAT.md §7.2).
* :func:`tail_offset` finds the last entry's time in a plain alog by reading backwards from
  the end in growing steps, so a session's duration costs one small read, not the whole file.
* :class:`VariableScan` counts the distinct variables. There is no index beside pLogger's
  files, so it scans, in 8 MiB blocks of typed columns. A plain file that grew is scanned
  only from where the last scan stopped (same inode), so a live session's count stays
  cheap; a compressed file is read whole.
"""

from __future__ import annotations

import os
import re
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from fleetlog.errors import FormatError, StorageError
from fleetlog.moos.alog import BANNER_RULE, Banner, parse_banner
from fleetlog.storage.columnar import parse_lines, read_tail
from fleetlog.storage.decompress import open_text

__all__ = ["HeadInfo", "VariableScan", "is_compressed", "read_head", "tail_offset"]

_HEAD_BYTES = 256 << 10
_TAIL_STEP = 64 << 10
_TAIL_MAX = 4 << 20
_SCAN_BLOCK = 1 << 20
_STATUS_COMMUNITY = re.compile(r"[ ,]Community=([^,]*)")
_COMMUNITY = re.compile(r"MOOSDB_(\S+)")


def is_compressed(path: Path) -> bool:
    """Return True for a ``.gz`` or ``.zst`` file."""
    return path.suffix.lower() in (".gz", ".zst")


@dataclass(frozen=True, slots=True)
class HeadInfo:
    """What the start of an alog says.

    Attributes:
        banner: the parsed banner, or None if it is missing or garbled.
        banner_lines: the banner's lines as written, without newlines.
        time_decimals: decimals of the first entry's time (3 essential-moos, 5 MOOS-IvP).
        community: the community in the ``DB_TIME`` source ``MOOSDB_<community>``, if the
            head holds one.
    """

    banner: Banner | None
    banner_lines: tuple[str, ...]
    time_decimals: int | None
    community: str | None


def read_head(path: Path) -> HeadInfo:
    """Read an alog's banner and first entries (plain, ``.gz`` or ``.zst``).

    Raises:
        StorageError: the file cannot be opened or its compressed data is corrupt.
    """
    with open_text(path) as text:
        head = text.read(_HEAD_BYTES)
    lines = head.split("\n")
    if not head.endswith("\n"):
        lines.pop()  # cut at the read limit, or the file's own cut tail
    banner_lines: list[str] = []
    if lines and lines[0] == BANNER_RULE:
        for line in lines[:16]:
            banner_lines.append(line)
            if len(banner_lines) > 1 and line == BANNER_RULE:
                break
    banner: Banner | None = None
    try:
        banner = parse_banner(banner_lines, str(path))
    except FormatError:
        banner = None
    decimals: int | None = None
    community: str | None = None
    status: str | None = None
    frame = parse_lines(head.encode("utf-8", "surrogateescape"), final=True)[0]
    if frame.height:
        first = frame.row(0, named=True)
        decimals = _decimals(lines, first["line"])
    for key, source, text in frame.select("var", "source", "text").iter_rows():
        if key == "DB_TIME":
            found = _COMMUNITY.fullmatch(source)
            if found:
                community = found.group(1)
                break
        elif status is None and key.endswith("_STATUS"):
            # A fleetlog recorder's status names the vehicle when no MOOSDB posted DB_TIME.
            named = _STATUS_COMMUNITY.search(text.rstrip(" "))
            if named and named.group(1):
                status = named.group(1)
    return HeadInfo(banner, tuple(banner_lines), decimals, community or status)


def _decimals(lines: list[str], line: int) -> int:
    """Return the decimals of the time column of 1-based ``line``."""
    time_text = lines[line - 1].split(" ", 1)[0]
    return len(time_text.partition(".")[2])


def tail_offset(path: Path) -> float | None:
    """Return the time of the last whole entry of a plain alog, reading from the end.

    A last line without its newline (a file being written) is not an entry yet. Looks back at
    most 4 MiB; returns None if no entry is found there.

    Raises:
        StorageError: the file cannot be read.
    """
    step = _TAIL_STEP
    while True:
        offsets = read_tail(path, step)["offset"]
        if offsets.len():
            return float(offsets[-1])
        try:
            size = path.stat().st_size
        except OSError as err:
            msg = f"cannot read {path}: {err.strerror or err}"
            raise StorageError(msg) from err
        if step >= size or step >= _TAIL_MAX:
            return None
        step *= 4


@dataclass
class VariableScan:
    """The distinct variables of one alog, scanned incrementally.

    Attributes:
        path: the file.
        inode: the inode scanned (a new file under the same name starts over).
        position: bytes of the (decompressed) file scanned, up to the last whole line.
        variables: the names seen.
        last_offset: the time of the last entry seen.
    """

    path: Path
    inode: int = -1
    position: int = 0
    variables: set[str] = field(default_factory=set)
    last_offset: float | None = None

    def update(self) -> None:
        """Scan what was appended since the last call (everything, for a compressed file).

        Raises:
            StorageError: the file cannot be read or its compressed data is corrupt.
        """
        try:
            st = os.stat(self.path)
        except OSError as err:
            msg = f"cannot read {self.path}: {err.strerror or err}"
            raise StorageError(msg) from err
        if is_compressed(self.path) or st.st_ino != self.inode or st.st_size < self.position:
            self.inode = st.st_ino
            self.position = 0
            self.variables = set()
            self.last_offset = None
        if is_compressed(self.path):
            with open_text(self.path) as text:
                buffer = text.buffer
                self._scan(lambda size: bytes(buffer.read(size)))
            return
        try:
            with self.path.open("rb") as file:
                file.seek(self.position)
                self._scan(file.read)
        except OSError as err:
            msg = f"cannot read {self.path}: {err.strerror or err}"
            raise StorageError(msg) from err

    def _scan(self, read: Callable[[int], bytes]) -> None:
        # ``carry`` holds the unfinished last entry (its value may go on in the next block);
        # ``position`` is where it starts, so a scan that resumes reads it again.
        carry = b""
        found = self.variables
        while block := read(_SCAN_BLOCK):
            data = carry + block
            frame, used = parse_lines(data)
            found.update(frame["var"].unique().to_list())
            if frame.height:
                self.last_offset = float(frame["offset"][-1])
            carry = data[used:]
            self.position += used
        if carry:
            # what is left at the end: read it now, but resume from its start next time
            frame = parse_lines(carry, final=True)[0]
            found.update(frame["var"].unique().to_list())
            if frame.height:
                self.last_offset = float(frame["offset"][-1])

    @property
    def count(self) -> int:
        """How many distinct variables were seen."""
        return len(self.variables)
