"""Time order for records of one or several logs: a bounded re-sort window and a merge.

alogs are not globally time-sorted (MOOS_FORMAT.md §2.2): mail batches are sorted, the file
is in arrival order, and re-delivered values re-appear with their old times.
:func:`sorted_window` puts one stream in order with a bounded buffer (what alogsort does with
1000 lines) and :func:`merge_records` merges several vehicles' streams by absolute time.
"""

from __future__ import annotations

import heapq
import operator
from collections import deque
from collections.abc import Callable, Iterable, Iterator, Sequence
from typing import TYPE_CHECKING, Any, Generic, NamedTuple, Protocol, TypeVar, runtime_checkable

from fleetlog.errors import UsageError
from fleetlog.moos.alog import Entry

if TYPE_CHECKING:
    from typing import Self

__all__ = [
    "IndexedRecord",
    "Record",
    "RecordMerge",
    "SortedWindow",
    "merge_indexed",
    "merge_records",
    "sorted_window",
]

# --------------------------------------------------------------------------------------------
# Records


class Record(NamedTuple):
    """An entry with its absolute time (``LOGSTART + offset``)."""

    time: float
    entry: Entry


class IndexedRecord(NamedTuple):
    """A record from a merge, tagged with the index of the input it came from (``origin``)."""

    time: float
    origin: int
    entry: Entry


@runtime_checkable
class _RecordSource(Protocol):
    """A reader: :class:`fleetlog.storage.columnar.AlogReader`."""

    def records(self) -> Iterator[Record]: ...


class _Timed(Protocol):
    @property
    def time(self) -> float: ...


R = TypeVar("R", bound=_Timed)


#: a record's time (C code: called once per record held back)
_time_of: Callable[[Any], float] = operator.attrgetter("time")


# --------------------------------------------------------------------------------------------
# Time order


class SortedWindow(Generic[R]):
    """A streaming re-sort by time with a bounded buffer (what alogsort does with 1000 lines).

    Records are held in a heap of at most ``window`` records; once it is full, each new record
    pushes out the earliest one. A record that arrives after a later one has already left the
    window (it is out of place by more than ``window`` records) cannot be put back: it is
    yielded late, as soon as possible, and counted in :attr:`late`. Records with equal times
    keep their input order.

    Attributes:
        window: the buffer size.
        late: records yielded after a record with a later time.

    Raises:
        UsageError: ``window`` is negative.
    """

    def __init__(
        self, records: Iterable[R], window: int = 1000, *, key: Callable[[R], float] | None = None
    ) -> None:
        if window < 0:
            msg = f"the sort window must be 0 or more records, not {window}"
            raise UsageError(msg)
        self.window = window
        self.late = 0
        self._key: Callable[[R], float] = key if key is not None else _time_of
        self._run = self._sort(records)

    def __iter__(self) -> Self:
        return self

    def __next__(self) -> R:
        return next(self._run)

    def _sort(self, records: Iterable[R]) -> Iterator[R]:
        # The records held are in two parts: ``run``, those that came in time order (each no
        # earlier than the one before it), in a FIFO, and ``heap``, those that came early.
        # The earliest held record is the earlier of their heads: the same order as one heap
        # (time, then input order), but a mostly sorted log costs a deque append and pop per
        # record instead of two sifts through a heap of ``window`` records.
        run: deque[tuple[float, int, R]] = deque()
        heap: list[tuple[float, int, R]] = []
        key = self._key
        window = self.window
        last = -float("inf")
        for seq, record in enumerate(records):
            item = (key(record), seq, record)
            if not run or item[0] >= run[-1][0]:
                run.append(item)
            else:
                heapq.heappush(heap, item)
            if len(run) + len(heap) > window:
                # seq differs between any two items, so the records are never compared
                when, _, out = (
                    heapq.heappop(heap) if heap and (not run or heap[0] < run[0]) else run.popleft()
                )
                if when < last:
                    self.late += 1
                else:
                    last = when
                yield out
        while run or heap:
            when, _, out = (
                heapq.heappop(heap) if heap and (not run or heap[0] < run[0]) else run.popleft()
            )
            if when < last:
                self.late += 1
            else:
                last = when
            yield out


def sorted_window(
    records: Iterable[R], window: int = 1000, *, key: Callable[[R], float] | None = None
) -> SortedWindow[R]:
    """Re-sort ``records`` by time in a bounded window; see :class:`SortedWindow`.

    alogs are not globally time-sorted (§2.2: mail batches are sorted, the file is in arrival
    order, and re-delivered values re-appear with their old times). A window of 1000 records
    puts ordinary files in order; a record displaced by more than that is yielded late and
    counted in the returned iterator's ``late``.

    Args:
        records: the records, usually :meth:`AlogReader.records`.
        window: how many records to hold back at most.
        key: the time of a record; ``record.time`` by default.

    Returns:
        An iterator over the records, with a ``late`` count.

    Raises:
        UsageError: ``window`` is negative.
    """
    return SortedWindow(records, window, key=key)


class RecordMerge:
    """The iterator :func:`merge_records` returns.

    Attributes:
        windows: each input's re-sort window, in input order (empty without windows).
    """

    def __init__(
        self,
        inputs: Sequence[Iterable[Record]],
        key: Callable[[IndexedRecord], float],
        window: int | None,
    ) -> None:
        tagged = [_tag(records, index) for index, records in enumerate(inputs)]
        self._start(tagged, key, window)

    @classmethod
    def of_indexed(
        cls,
        streams: Sequence[Iterable[IndexedRecord]],
        key: Callable[[IndexedRecord], float],
        window: int | None,
    ) -> RecordMerge:
        """Merge streams whose records are tagged with their input's index already."""
        merge = cls.__new__(cls)
        merge._start(list(streams), key, window)
        return merge

    def _start(
        self,
        tagged: Sequence[Iterable[IndexedRecord]],
        key: Callable[[IndexedRecord], float],
        window: int | None,
    ) -> None:
        self.windows: list[SortedWindow[IndexedRecord]] = []
        streams: list[Iterable[IndexedRecord]] = list(tagged)
        if window is not None:
            self.windows = [SortedWindow(stream, window, key=key) for stream in tagged]
            streams = list(self.windows)
        # One input needs no merge: its records pass as they come.
        self._merged: Iterator[IndexedRecord] = (
            iter(streams[0]) if len(streams) == 1 else heapq.merge(*streams, key=key)
        )

    @property
    def late(self) -> int:
        """Records that left their input's window out of order (see :class:`SortedWindow`)."""
        return sum(window.late for window in self.windows)

    def __iter__(self) -> Self:
        return self

    def __next__(self) -> IndexedRecord:
        return next(self._merged)


def _tag(records: Iterable[Record], index: int) -> Iterator[IndexedRecord]:
    for time, entry in records:
        yield IndexedRecord(time, index, entry)


def merge_records(
    sources: Sequence[_RecordSource | Iterable[Record]],
    *,
    key: Callable[[IndexedRecord], float] | None = None,
    window: int | None = 1000,
) -> RecordMerge:
    """Merge several logs' records into one stream by absolute time (multi-vehicle replay).

    Each input is first re-sorted in a bounded window (:func:`sorted_window`), because a
    single alog is not time-sorted; then the inputs are merged with :func:`heapq.merge`.
    Each record is tagged with the index of its input. Records with equal times come in
    input order, and within an input in file order.

    Args:
        sources: readers (their ``records()`` are used) or record iterables.
        key: the time to order by; the absolute time by default.
        window: each input's re-sort window in records; None merges the inputs as they come
            (only right for inputs that are already sorted).

    Returns:
        An iterator of :class:`IndexedRecord`, with a ``late`` count of records that were out
        of order by more than the window.

    Raises:
        StorageError: a reader has no LOGSTART, or as :meth:`AlogReader.records`.
        UsageError: ``window`` is negative.
    """
    inputs = [src.records() if isinstance(src, _RecordSource) else src for src in sources]
    return RecordMerge(inputs, key if key is not None else _time_of, window)


def merge_indexed(
    streams: Sequence[Iterable[IndexedRecord]],
    *,
    key: Callable[[IndexedRecord], float] | None = None,
    window: int | None = 1000,
) -> RecordMerge:
    """:func:`merge_records` for streams of :class:`IndexedRecord` tagged by their producer.

    What a player uses: it makes each record once, with its input's index, instead of a
    record and then a tagged copy of it.
    """
    return RecordMerge.of_indexed(streams, key if key is not None else _time_of, window)
