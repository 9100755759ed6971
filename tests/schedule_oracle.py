"""The replay schedule as it was, one record at a time: the oracle of the one in runs.

:mod:`fleetlog.replayer.schedule` makes its items in runs straight from the reader's columns
and lets a sorted run pass the re-sort window in one step. This is the schedule it
replaced (``fleetlog.replayer.schedule`` at 7165918), kept for the tests alone: property
tests hold the two to the same order, the same values and the same counts.

What it does (MOOS_FORMAT.md §2.2, §8.1): each input through a bounded re-sort window, the
inputs merged by absolute time, entries before LOGSTART dropped, re-delivered duplicates
dropped (a bounded memory of recent entries), entries out of order by more than the window
played late and counted.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Generator, Iterator, Sequence
from typing import NamedTuple

from fleetlog.errors import StorageError
from fleetlog.moos.alog import BinaryRef, Entry
from fleetlog.replayer.inputs import ReplayInput
from fleetlog.storage.ordering import IndexedRecord, merge_indexed

__all__ = ["DEDUPE_MEMORY", "DEFAULT_WINDOW", "Item", "Schedule"]

#: Records each input's re-sort window holds back (alogsort holds 1000).
DEFAULT_WINDOW = 10_000
#: How many recent entries the duplicate check remembers.
DEDUPE_MEMORY = 65_536
#: Entries read ahead of the one being played, so the player can prepare their publishers.
LOOKAHEAD = 32


class Item(NamedTuple):
    """One entry on the replay schedule.

    Attributes:
        time: absolute log time (LOGSTART + offset).
        origin: the index of the input it came from.
        entry: the entry as read.
        late: True when a later entry was already scheduled (out of order by more than the
            re-sort window).
        payload: a binary value's bytes, once read from the blog (the duplicate check
            reads them).
    """

    time: float
    origin: int
    entry: Entry
    late: bool
    payload: bytes | None = None


class Schedule:
    """Iterates the inputs' entries in time order, once; see the module docstring.

    Args:
        inputs: the open inputs (a new pass is started on each).
        window: each input's re-sort window, in records.
        dedupe: drop re-delivered duplicates.
        memory: how many recent entries the duplicate check remembers.

    Attributes:
        before_logstart: entries dropped for a negative offset.
        duplicates: entries dropped as duplicates.
        late: entries scheduled after a later one.
    """

    def __init__(
        self,
        inputs: Sequence[ReplayInput],
        *,
        window: int = DEFAULT_WINDOW,
        dedupe: bool = True,
        memory: int = DEDUPE_MEMORY,
    ) -> None:
        self.inputs = inputs
        self.before_logstart = 0
        self.duplicates = 0
        self.late = 0
        self._dedupe = dedupe
        self._memory = memory
        self._seen: set[int] = set()
        self._order: deque[int] = deque()
        self._passes = [self._records(item, index) for index, item in enumerate(inputs)]
        self._merge = merge_indexed(self._passes, window=window)
        self._run = self._items()
        self._ahead: deque[Item] = deque()

    def _records(self, source: ReplayInput, index: int) -> Generator[IndexedRecord, None, None]:
        logstart = source.logstart
        entries = source.reader.entries()
        try:
            for entry in entries:
                if entry.offset < 0:
                    self.before_logstart += 1
                    continue
                yield IndexedRecord(logstart + entry.offset, index, entry)
        finally:
            # Closing the pass closes its file now, not when the garbage collector runs.
            close = getattr(entries, "close", None)
            if close is not None:
                close()

    def _with_payload(self, item: Item) -> Item:
        try:
            return item._replace(payload=self.inputs[item.origin].reader.read_binary(item.entry))
        except StorageError:
            return item  # publishing reports it, with the reason

    def _is_duplicate(self, item: Item) -> bool:
        entry = item.entry
        # A binary re-delivery gets a new blog record, so its reference differs: compare
        # the bytes instead.
        value = entry.text if item.payload is None else item.payload
        sig = hash((self.inputs[item.origin].vehicle, item.time, entry.key, entry.source, value))
        if sig in self._seen:
            return True
        self._seen.add(sig)
        self._order.append(sig)
        if len(self._order) > self._memory:
            self._seen.discard(self._order.popleft())
        return False

    def _items(self) -> Generator[Item, None, None]:
        newest = -float("inf")
        for time, origin, entry in self._merge:
            late = time < newest
            item = Item(time, origin, entry, late)
            if self._dedupe:
                if isinstance(entry.value, BinaryRef):
                    item = self._with_payload(item)
                if self._is_duplicate(item):
                    self.duplicates += 1
                    continue
            if late:
                self.late += 1
            else:
                newest = time
            yield item

    def __iter__(self) -> Iterator[Item]:
        return self

    def __next__(self) -> Item:
        ahead = self._ahead
        # One read per entry played (all of them at the start), so reading stays smooth.
        while len(ahead) < LOOKAHEAD:
            item = next(self._run, None)
            if item is None:
                break
            ahead.append(item)
        if not ahead:
            raise StopIteration
        return ahead.popleft()

    @property
    def ahead(self) -> deque[Item]:
        """The entries already read that come next (up to :data:`LOOKAHEAD`); do not modify."""
        return self._ahead

    def payload(self, item: Item) -> float | str | bytes:
        """Return the value to publish: the double, the string, or the bytes from the blog.

        Raises:
            StorageError: a binary value's bytes cannot be read (the message names the log
                line, the blog and the offset).
        """
        value = item.entry.value
        if isinstance(value, BinaryRef):
            if item.payload is not None:
                return item.payload
            return self.inputs[item.origin].reader.read_binary(item.entry)
        return value

    def close(self) -> None:
        """Stop the pass: close the files it holds open."""
        self._run.close()
        for records in self._passes:
            records.close()
