"""Which byte ranges of a log hold entry lines only: learnt by one pass, used by the next.

Whether a line is an entry is a property of the line alone (its text too: blocks end at
newlines, and a byte that is not UTF-8 decodes to one U+FFFD in any block), so a range of
whole lines that held entries only when one pass read it holds entries only for any later
pass over the same file, whatever that pass's block boundaries. A selective pass (a grep)
that knows a block is such a range need not test each of its lines (the two per-line
regexes, about a quarter of a remote grep's CPU): it cuts only the lines that hold its
literals.

The memo is kept in memory, per file version: device, inode, size, and the modification
and status-change times in nanoseconds, taken when a pass opens the file (an appended,
rewritten or replaced log is another version and starts unknown; the status-change time,
which no one can set, tells a new file that took a deleted one's inode, size and forged
modification time from it). It is bounded (:data:`MAX_FILES` files, LRU, and
:data:`MAX_RANGES` ranges a file) and shared by threads. Only plain (uncompressed) logs are
remembered: their byte offsets are the file's own.
"""

from __future__ import annotations

import bisect
import os
import threading
from collections import OrderedDict
from dataclasses import dataclass

__all__ = ["MAX_FILES", "MAX_RANGES", "BlockSpan", "FileVersion", "PassPurity", "PurityMemo"]

#: Files remembered at once (the least recently used is forgotten first).
MAX_FILES = 128
#: Separate ranges remembered per file; a file whose entry-only ranges are more scattered
#: than this (a stray or continuation line every few blocks) learns nothing more. With
#: MAX_FILES, the memo holds at most ~10 MB (a recorder's log is usually one range).
MAX_RANGES = 1024


@dataclass(frozen=True)
class FileVersion:
    """A file as it was when a pass opened it."""

    device: int
    inode: int
    size: int
    mtime_ns: int
    ctime_ns: int = 0

    @classmethod
    def of(cls, fd: int) -> FileVersion:
        """The version of the open file ``fd``."""
        st = os.fstat(fd)
        return cls(st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns, st.st_ctime_ns)


class _Ranges:
    """Disjoint, sorted, non-adjacent byte ranges ``[start, end)``."""

    def __init__(self) -> None:
        self.starts: list[int] = []
        self.ends: list[int] = []

    def covers(self, start: int, end: int) -> bool:
        i = bisect.bisect_right(self.starts, start) - 1
        return i >= 0 and self.ends[i] >= end

    def add(self, start: int, end: int) -> None:
        lo = bisect.bisect_left(self.ends, start)  # the first range that ends at or after start
        hi = bisect.bisect_right(self.starts, end)  # past the last that starts at or before end
        if lo < hi:  # overlapping or touching ranges merge into one
            start = min(start, self.starts[lo])
            end = max(end, self.ends[hi - 1])
        elif len(self.starts) >= MAX_RANGES:
            return
        self.starts[lo:hi] = [start]
        self.ends[lo:hi] = [end]


class PurityMemo:
    """The entry-only ranges of recently read files (thread-safe, bounded).

    One version per file (device and inode): a newer version learnt replaces an older one, so
    a log that grows while it is grepped again and again (the open session) holds one entry,
    not one per grep.
    """

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._files: OrderedDict[tuple[int, int], tuple[FileVersion, _Ranges]] = OrderedDict()

    def covers(self, version: FileVersion, start: int, end: int) -> bool:
        """Whether ``[start, end)`` of that version is known to hold entry lines only."""
        key = (version.device, version.inode)
        with self._lock:
            known = self._files.get(key)
            if known is None or known[0] != version:
                return False
            self._files.move_to_end(key)
            return known[1].covers(start, end)

    def learn(self, version: FileVersion, start: int, end: int) -> None:
        """Remember that ``[start, end)`` of that version holds entry lines only."""
        if not 0 <= start < end <= version.size:
            return  # (read past the size the pass began with: the file grew meanwhile)
        key = (version.device, version.inode)
        with self._lock:
            known = self._files.get(key)
            if known is None or known[0] != version:
                known = self._files[key] = (version, _Ranges())
                while len(self._files) > MAX_FILES:
                    self._files.popitem(last=False)
            self._files.move_to_end(key)
            known[1].add(start, end)

    def __len__(self) -> int:
        """Files remembered."""
        with self._lock:
            return len(self._files)

    def clear(self) -> None:
        """Forget every file."""
        with self._lock:
            self._files.clear()


@dataclass(frozen=True)
class PassPurity:
    """One pass's view of the memo: its file's version."""

    memo: PurityMemo
    version: FileVersion

    def covers(self, start: int, end: int) -> bool:
        """Whether ``[start, end)`` of the pass's file is known to hold entry lines only."""
        return self.memo.covers(self.version, start, end)

    def learn(self, start: int, end: int) -> None:
        """Remember that ``[start, end)`` of the pass's file holds entry lines only."""
        self.memo.learn(self.version, start, end)


class BlockSpan:
    """Where a block (and the newline after it) is in its file, for a pass's purity."""

    __slots__ = ("end", "purity", "start")

    def __init__(self, purity: PassPurity | None, start: int, end: int) -> None:
        self.purity = purity
        self.start = start
        self.end = end

    def known_pure(self) -> bool:
        """Whether the block is known to hold entry lines only."""
        return self.purity is not None and self.purity.covers(self.start, self.end)

    def learn(self) -> None:
        """Remember that the block holds entry lines only."""
        if self.purity is not None:
            self.purity.learn(self.start, self.end)
