"""One pass over the inputs in absolute-time order: what the player publishes, and when.

An alog is not time-sorted (MOOS_FORMAT.md §2.2): pLogger sorts each mail batch, writes
batches in arrival order, and the MOOSDB re-delivers current values, with their original
time stamps, whenever pLogger re-registers. uPlayBack sorts its whole index (§8.1); a
streaming player cannot, so each input goes through a bounded re-sort window (the rule of
:class:`fleetlog.storage.ordering.SortedWindow`) and the inputs are merged by absolute time
(LOGSTART + offset) onto one clock. What the schedule does with the rest, and counts:

* **before LOGSTART**: entries with a negative offset (values the MOOSDB re-delivered from
  before pLogger started) are dropped, as uPlayBack drops them (its index keeps only lines
  that start with a digit, §8.1);
* **duplicates**: an entry equal to one already played (same vehicle, time, variable, source
  and value text; for a binary value, the same bytes, since a re-delivery gets a new blog
  record) is a re-delivery, not a second publication, and is dropped. A bounded
  memory of recent entries catches them whether the window put them next to the original or
  they came too late for it. ``dedupe=False`` plays them, as uPlayBack does;
* **late**: an entry displaced by more than the window comes after later ones. It is played
  at once (its time has passed) rather than lost, and counted.

The schedule works in runs of entries made straight from the columnar reader's batches
(:mod:`fleetlog.replayer.items`): an entry is one tuple, made once, and a run that continues
the window's time order passes the window in one step. Its order is exactly the one the
per-record rule gives (``tests/schedule_oracle.py`` holds it), and a run is short enough
that making it never holds a 1x replay back by more than about a millisecond.
"""

from __future__ import annotations

import heapq
from collections import deque
from collections.abc import Generator, Iterator, Sequence
from itertools import chain, islice
from operator import itemgetter

from fleetlog.moos.alog import BinaryRef
from fleetlog.replayer.inputs import ReplayInput
from fleetlog.replayer.items import (
    ORIGIN,
    PAYLOAD,
    RUN,
    SIG,
    TIME,
    VALUE,
    InputPass,
    Item,
    entry_of,
    late,
    ordered,
    with_payload,
)

__all__ = ["DEDUPE_MEMORY", "DEFAULT_WINDOW", "LOOKAHEAD", "Schedule"]

#: Records each input's re-sort window holds back (alogsort holds 1000).
DEFAULT_WINDOW = 10_000
#: How many recent entries the duplicate check remembers.
DEDUPE_MEMORY = 65_536
#: Entries the player can prepare the publishers of ahead of the one being played.
LOOKAHEAD = 32
_time_of = itemgetter(TIME)


class _Window:
    """:class:`~fleetlog.storage.ordering.SortedWindow`'s rule, fed and drained in runs.

    The records held are in two parts: ``run``, those that came in time order, in a FIFO,
    and ``heap``, those that came early; the earliest held record is the earlier of their
    heads. A run of records in time order that continues ``run`` while ``heap`` is empty
    (a sorted stretch of log: nearly all of it) leaves exactly as record-by-record pushes
    would let it, so it passes in one step. Items compare by ``(time, seq)``: ``seq`` is
    unique within an input, so nothing past it is ever compared.
    """

    __slots__ = ("heap", "run", "size")

    def __init__(self, size: int) -> None:
        self.size = size
        self.run: deque[Item] = deque()
        self.heap: list[Item] = []

    def push(self, items: list[Item], ordered: bool) -> list[Item]:
        """Take the next records (``ordered``: in time order); return those that leave."""
        run, heap, size = self.run, self.heap, self.size
        if ordered and not heap and (not run or items[0][TIME] >= run[-1][TIME]):
            run.extend(items)
            extra = len(run) - size
            return [run.popleft() for _ in range(extra)] if extra > 0 else []
        out: list[Item] = []
        for item in items:
            if not run or item[TIME] >= run[-1][TIME]:
                run.append(item)
            else:
                heapq.heappush(heap, item)
            if len(run) + len(heap) > size:
                out.append(self._pop())
        return out

    def drain(self) -> list[Item]:
        """Return every record still held, in order (the input ended)."""
        out: list[Item] = []
        while self.run or self.heap:
            out.append(self._pop())
        return out

    def _pop(self) -> Item:
        run, heap = self.run, self.heap
        if heap and (not run or heap[0] < run[0]):
            return heapq.heappop(heap)
        return run.popleft()


class Schedule:
    """Iterates the inputs' entries in time order, once; see the module docstring.

    Args:
        inputs: the open inputs (a new pass is started on each).
        window: each input's re-sort window, in records.
        dedupe: drop re-delivered duplicates.
        memory: how many recent entries the duplicate check remembers.
        run: entries made from the reader's columns at a time (:data:`RUN`).

    Attributes:
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
        run: int = RUN,
    ) -> None:
        self.inputs = inputs
        self._size = run
        self.duplicates = 0
        self.late = 0
        self._window = window
        self._dedupe = dedupe
        self._memory = memory
        self._seen: set[int] = set()
        self._order: deque[int] = deque()
        self._newest = -float("inf")
        self._readers = [
            InputPass(item, index, run=run, signed=dedupe) for index, item in enumerate(inputs)
        ]
        self._passes = [self._windowed(reader) for reader in self._readers]
        self._runs = self._merged()
        self._run: list[Item] = []
        self._at = 0

    # -- reading

    @property
    def before_logstart(self) -> int:
        """Entries dropped for a negative offset."""
        return sum(reader.before_logstart for reader in self._readers)

    def _windowed(self, reader: InputPass) -> Generator[list[Item], None, None]:
        """Yield an input's entries re-sorted in its window, in runs."""
        window = _Window(self._window)
        runs = reader.runs()
        try:
            for items, ordered in runs:
                out = window.push(items, ordered)
                if out:
                    yield out
            rest = window.drain()
            if rest:
                yield rest
        finally:
            runs.close()

    def _merged(self) -> Iterator[list[Item]]:
        """The inputs' runs merged by time (equal times in input order)."""
        if len(self._passes) == 1:
            return self._passes[0]  # one input needs no merge: its runs pass as they come
        merged = heapq.merge(*(chain.from_iterable(p) for p in self._passes), key=_time_of)
        return iter(lambda: list(islice(merged, self._size)), [])

    # -- duplicates and lateness

    def _finish(self, run: list[Item]) -> list[Item]:
        """Drop duplicates and mark late entries, in play order."""
        if not self._dedupe:
            return self._mark_late(run)
        seen, order = self._seen, self._order
        sigs = [item[SIG] for item in run]
        if (
            seen.isdisjoint(sigs)
            and len(set(sigs)) == len(sigs)
            and not any(type(item[VALUE]) is BinaryRef for item in run)
        ):
            # No duplicate (even against entries the memory would forget during the run,
            # which the exact way below then sees): remember the run at once.
            order.extend(sigs)
            seen.update(sigs)
            excess = len(order) - self._memory
            if excess > 0:
                seen.difference_update([order.popleft() for _ in range(excess)])
            return self._mark_late(run)
        out: list[Item] = []
        memory = self._memory
        for item in run:
            if type(item[VALUE]) is BinaryRef:
                item = with_payload(self.inputs[item[ORIGIN]], item)
            sig = item[SIG]
            if sig in seen:
                self.duplicates += 1
                continue
            seen.add(sig)
            order.append(sig)
            if len(order) > memory:
                seen.discard(order.popleft())
            out.append(item)
        return self._mark_late(out)

    def _mark_late(self, run: list[Item]) -> list[Item]:
        """Mark the entries that come after a later one (in play order)."""
        if not run:
            return run
        newest = self._newest
        if run[0][TIME] >= newest and ordered([item[TIME] for item in run]):
            self._newest = run[-1][TIME]
            return run
        out: list[Item] = []
        for item in run:
            if item[TIME] < newest:
                out.append(late(item))
                self.late += 1
            else:
                newest = item[TIME]
                out.append(item)
        self._newest = newest
        return out

    # -- iteration

    def __iter__(self) -> Iterator[Item]:
        return self

    def __next__(self) -> Item:
        at = self._at
        run = self._run
        if at >= len(run):
            run = self._refill()
            at = 0
        self._at = at + 1
        return run[at]

    def _refill(self) -> list[Item]:
        for run in self._runs:
            out = self._finish(run)
            if out:
                self._run = out
                return out
        self._run = []
        raise StopIteration

    def take(self) -> list[Item]:
        """Take every entry already read (the rest of the current run; [] if none is left).

        For a player that publishes back to back: :meth:`give_back` returns what it did not
        publish, so the order is kept.
        """
        run = self._run[self._at :] if self._at else self._run
        self._run = []
        self._at = 0
        return run

    def give_back(self, items: list[Item]) -> None:
        """Put entries taken with :meth:`take` back, to come next (in their order)."""
        if items:
            self._run = items + self._run[self._at :]
            self._at = 0

    @property
    def ahead(self) -> list[Item]:
        """The next entries (up to :data:`LOOKAHEAD`), as far as they are read."""
        return self._run[self._at : self._at + LOOKAHEAD]

    def payload(self, item: Item) -> float | str | bytes:
        """Return the value to publish: the double, the string, or the bytes from the blog.

        Raises:
            StorageError: a binary value's bytes cannot be read (the message names the log
                line, the blog and the offset).
        """
        value = item[VALUE]
        if isinstance(value, BinaryRef):
            payload = item[PAYLOAD]
            if payload is not None:
                return payload
            return self.inputs[item[ORIGIN]].reader.read_binary(entry_of(item))
        return value

    def close(self) -> None:
        """Stop the pass: close the files it holds open."""
        close = getattr(self._runs, "close", None)
        if close is not None:
            close()
        for records in self._passes:
            records.close()
