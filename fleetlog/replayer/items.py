"""What the replay schedule holds: an entry as one tuple, made in runs from the reader's columns.

A replay as fast as possible publishes ~100k entries a second, so an entry costs as little as
can be: the columnar reader's batch is turned into items a run at a time (:data:`RUN`), each
an :data:`Item` tuple made by ``zip`` from its columns, with what the schedule needs ready:
the absolute time, whether the run is in time order, and the duplicate signature, computed
for the whole batch in one polars query. A batch that held bytes that are not UTF-8 is made
from its exact :class:`~fleetlog.moos.alog.Entry` rows instead, to the same items.
"""

from __future__ import annotations

import operator
from collections.abc import Generator, Iterable, Iterator
from itertools import islice, repeat
from types import ModuleType
from typing import TYPE_CHECKING, Any, Final

from fleetlog.errors import StorageError
from fleetlog.moos.alog import BinaryRef, Entry, parse_binary_ref
from fleetlog.replayer.inputs import ReplayInput

if TYPE_CHECKING:
    import polars as pl

__all__ = [
    "KEY",
    "LATE",
    "LINE",
    "ORIGIN",
    "PAYLOAD",
    "RUN",
    "SEQ",
    "SIG",
    "SOURCE",
    "TEXT",
    "TIME",
    "VALUE",
    "InputPass",
    "Item",
    "entry_of",
    "late",
    "payload_expr",
    "with_payload",
]

#: One entry on the replay schedule: a plain tuple, whose fields are at the indexes below.
#: Made a thousand at a time by ``zip`` from the reader's columns (a NamedTuple costs four
#: times as much to make, which a replay as fast as possible feels).
Item = tuple[
    float, int, int, str, str, "float | str | BinaryRef", str, int, int, bool, "bytes | None"
]
#: absolute log time (LOGSTART + offset)
TIME: Final = 0
#: the entry's place in its input's pass (equal times keep file order in the window)
SEQ: Final = 1
#: the index of the input it came from
ORIGIN: Final = 2
#: the MOOS variable
KEY: Final = 3
#: the source column as written (``src[:aux][@community]``)
SOURCE: Final = 4
#: a float, a str, or a :class:`BinaryRef` to the bytes in the blog
VALUE: Final = 5
#: the value as written (for a binary value, its ``<MOOS_BINARY>`` tag)
TEXT: Final = 6
#: the line the entry starts at (for messages)
LINE: Final = 7
#: the duplicate signature (0 when duplicates are played)
SIG: Final = 8
#: True when a later entry was already scheduled (out of order by more than the window)
LATE: Final = 9
#: the bytes to publish, when known before publishing: a string's, a double's text as
#: :func:`~fleetlog.wire.message.encode_value` writes it (made with the batch's columns),
#: a binary value's once read from the blog; None: made when published
PAYLOAD: Final = 10

#: Entries made from the reader's columns at a time: ~1 ms of work, so a 1x replay is never
#: held back longer than that by reading, and per-run costs vanish per entry.
RUN = 1024
#: The reader's columns a replay needs.
_COLUMNS = ("line", "offset", "var", "source", "type", "double", "text")
#: the columns a signature holds besides the vehicle and the time
_SIGNED = ("var", "source", "text")
#: the seed of the duplicate signatures (any fixed one: they are compared within a pass)
_SEED = 0x5EED


def late(item: Item) -> Item:
    """The item marked late."""
    return (*item[:LATE], True, item[PAYLOAD])


def entry_of(item: Item) -> Entry:
    """The entry an item was made of, as the reader's binary lookup takes it.

    Its offset is only known through the item's time, so it is not rebuilt (0.0).
    """
    return Entry(0.0, item[KEY], item[SOURCE], item[VALUE], item[TEXT], item[LINE])


def with_payload(source: ReplayInput, item: Item) -> Item:
    """The item with its binary value's bytes from the blog, and signed by them.

    A re-delivery gets a new blog record, so its reference differs: the bytes repeat. An
    item whose bytes cannot be read comes back as it was (publishing reports why).
    """
    import polars as pl

    try:
        payload = source.reader.read_binary(entry_of(item))
    except StorageError:
        return item
    sig = _signatures(
        _utf8(source.vehicle),
        pl.Series([item[TIME]], dtype=pl.Float64),
        pl.Series([_utf8(item[KEY])], dtype=pl.Binary),
        pl.Series([_utf8(item[SOURCE])], dtype=pl.Binary),
        pl.Series([payload], dtype=pl.Binary),
    )
    return (*item[:SIG], int(sig[0]), item[LATE], payload)


def ordered(times: list[float]) -> bool:
    """Whether ``times`` never decreases."""
    return all(map(operator.le, times, islice(times, 1, None)))


class InputPass:
    """One pass over one input: its entries as runs of items, in file order.

    Args:
        source: the open input.
        index: its index among the replay's inputs (the items' :data:`ORIGIN`).
        run: items made at a time.
        signed: compute the duplicate signatures (else :data:`SIG` is 0).

    Attributes:
        before_logstart: entries dropped for a negative offset.
    """

    def __init__(self, source: ReplayInput, index: int, *, run: int = RUN, signed: bool) -> None:
        self.source = source
        self.index = index
        self.before_logstart = 0
        self._size = run
        self._signed = signed
        self._seq = 0

    def runs(self) -> Generator[tuple[list[Item], bool], None, None]:
        """Yield the entries in runs, each with whether it is in time order."""
        import polars as pl

        logstart = self.source.logstart
        vehicle = _utf8(self.source.vehicle)
        size = self._size
        batches = self.source.reader.frames(_COLUMNS)
        try:
            for batch in batches:
                if batch.exact:
                    frame = batch.frame
                    negative = frame["offset"] < 0
                    if negative.any():
                        self.before_logstart += int(negative.sum())
                        frame = frame.filter(~negative)
                    frame = self._columns(pl, frame, logstart, vehicle)
                    parts: Iterator[list[Item]] = (
                        self._exact_items(frame.slice(start, size))
                        for start in range(0, frame.height, size)
                    )
                else:
                    entries = [entry for entry in batch.entries() if not entry.offset < 0]
                    self.before_logstart += batch.height - len(entries)
                    parts = (
                        self._entry_items(pl, entries[start : start + size], logstart, vehicle)
                        for start in range(0, len(entries), size)
                    )
                for items in parts:
                    yield items, ordered([item[TIME] for item in items])
        finally:
            # Closing the pass closes its file now, not when the garbage collector runs.
            close = getattr(batches, "close", None)
            if close is not None:
                close()

    def _columns(
        self, pl: ModuleType, frame: pl.DataFrame, logstart: float, vehicle: bytes
    ) -> pl.DataFrame:
        """A batch's columns for its items, in one query: times, signatures, binary rows."""
        time = pl.col("offset") + logstart
        sig = (
            _signature(pl, vehicle, time, *(pl.col(c).cast(pl.Binary) for c in _SIGNED))
            if self._signed
            else pl.lit(0, pl.UInt64)
        )
        return frame.select(
            time.alias("time"),
            "var",
            "source",
            "double",
            "text",
            "line",
            sig.alias("sig"),
            (pl.col("type") == "binary").alias("binary"),
            payload_expr(pl).alias("payload"),
        )

    def _exact_items(self, frame: pl.DataFrame) -> list[Item]:
        """Rows of an all-UTF-8 batch (its strings are the file's text) as items."""
        texts = frame["text"].to_list()
        values: list[float | str | BinaryRef] = [
            text if double is None else double
            for double, text in zip(frame["double"].to_list(), texts, strict=True)
        ]
        binary = frame["binary"]
        for row in binary.arg_true().to_list() if binary.any() else ():
            text = texts[row]
            values[row] = parse_binary_ref(text) or text
        return self._make(
            frame["time"].to_list(),
            frame["var"].to_list(),
            frame["source"].to_list(),
            values,
            texts,
            frame["line"].to_list(),
            frame["sig"].to_list(),
            frame["payload"].to_list(),
        )

    def _entry_items(
        self, pl: ModuleType, entries: list[Entry], logstart: float, vehicle: bytes
    ) -> list[Item]:
        """Entries of a batch that held bytes that are not UTF-8 (made exact) as items."""
        times = [logstart + entry.offset for entry in entries]
        sigs: Iterable[int] = repeat(0)
        if self._signed:
            binary = [
                pl.Series([_utf8(getattr(e, name)) for e in entries], dtype=pl.Binary)
                for name in ("key", "source", "text")
            ]
            sigs = _signatures(vehicle, pl.Series(times, dtype=pl.Float64), *binary).to_list()
        return self._make(
            times,
            [entry.key for entry in entries],
            [entry.source for entry in entries],
            [entry.value for entry in entries],
            [entry.text for entry in entries],
            [entry.lineno for entry in entries],
            sigs,
            repeat(None),
        )

    def _make(
        self,
        times: list[float],
        keys: list[str],
        sources: list[str],
        values: list[float | str | BinaryRef],
        texts: list[str],
        lines: list[int],
        sigs: Iterable[int],
        payloads: Iterable[bytes | None],
    ) -> list[Item]:
        n = len(times)
        seq = self._seq
        self._seq = seq + n
        return list(
            zip(
                times,
                range(seq, seq + n),
                repeat(self.index, n),
                keys,
                sources,
                values,
                texts,
                lines,
                sigs,
                repeat(False, n),
                payloads,
                strict=False,  # sigs and payloads may be endless (repeat)
            )
        )


def payload_expr(pl: ModuleType) -> Any:
    """The expression of the bytes an entry is published as, where polars writes them alike.

    A string's UTF-8 bytes; a double's shortest round-trip text (what ``repr`` and so
    :func:`~fleetlog.wire.message.encode_value` write) where Python writes it without an
    exponent, 0 and 1e-4 <= |x| < 1e16 (polars writes the same digits there; its exponent
    form differs); null for the other doubles (``encode_value`` makes theirs when they are
    published) and for binary values.
    """
    double = pl.col("double")
    kind = pl.col("type")
    plain = double.abs().is_between(1e-4, 1e16, closed="left") | (double == 0)
    text = pl.when((kind == "double") & plain).then(double.cast(pl.String))
    return text.when(kind == "string").then(pl.col("text")).otherwise(None).cast(pl.Binary)


def _utf8(text: str) -> bytes:
    """A string's bytes as the log had them (``surrogateescape`` gives other bytes back)."""
    return text.encode("utf-8", "surrogateescape")


def _signature(pl: ModuleType, vehicle: bytes, time: Any, *fields: Any) -> Any:
    """The expression of an entry's duplicate signature: a hash of its vehicle and fields.

    Over bytes (the name, source and value as Binary), so that an entry and its
    re-delivery get the same signature whichever batch (all UTF-8 or not) and whichever path
    (columns, or a binary payload read later) made it.
    """
    return pl.struct(pl.lit(vehicle).alias("vehicle"), time.alias("t"), *fields).hash(_SEED)


def _signatures(
    vehicle: bytes,
    times: pl.Series,
    keys: pl.Series,
    sources: pl.Series,
    values: pl.Series,
) -> pl.Series:
    """The duplicate signatures of entries given as Series (:func:`_signature`)."""
    import polars as pl

    frame = pl.DataFrame({"t": times, "var": keys, "source": sources, "text": values})
    sig = _signature(pl, vehicle, pl.col("t"), *(pl.col(c) for c in _SIGNED))
    return frame.select(sig).to_series()
