"""MCAP that Foxglove opens as it is: a channel per ``/<vehicle>/<VAR>``, JSON messages.

Each entry becomes one message on its variable's channel (``json`` encoding, schema
``fleetlog.MoosValue``: ``{value, source, aux, community}``; a double's value is a JSON
number, null for NaN and infinities, which JSON cannot hold; a binary's is its bytes in
base64). ``log_time`` and ``publish_time`` are the entry's absolute time in nanoseconds,
LOGSTART (exactly as the banner wrote it) plus the offset rounded to the nanosecond. The
channel's metadata names the vehicle, variable and session(s). Positions get Foxglove's own
channels (:mod:`fleetlog.export.foxglove`).

Entries without an absolute time (a log with no usable banner) or with one before 1970
cannot be MCAP messages: they are counted (:attr:`McapResult.untimed`), not written.
The JSON text of a whole batch is built by polars expressions, never per message in Python.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from decimal import Decimal
from functools import partial
from typing import TYPE_CHECKING, BinaryIO

from fleetlog import __version__
from fleetlog.export.entries import Select, Tally, entry_frames
from fleetlog.export.foxglove import (
    LOCATION_FIX,
    NAV_VARS,
    POSE_IN_FRAME,
    VALUE_SCHEMA,
    locations,
    poses,
    schema_bytes,
)
from fleetlog.export.mcapfile import McapWriter
from fleetlog.moos.alog import split_source
from fleetlog.storage.columnar import Errors

if TYPE_CHECKING:
    import polars as pl

    from fleetlog.export.sources import Source

__all__ = ["McapResult", "export_mcap", "logstart_ns"]

#: Derived messages written per batch (about as many as a 4 MiB block of the log holds).
_SLICE = 50_000


@dataclass
class McapResult:
    """What an MCAP export wrote.

    Attributes:
        messages: messages written (derived positions included).
        channels: channels declared.
        untimed: entries not written: no absolute time, or one before 1970.
        derived: topics of the derived position channels.
    """

    messages: int = 0
    channels: int = 0
    untimed: int = 0
    derived: list[str] = field(default_factory=list)


def logstart_ns(logstart: float) -> int:
    """LOGSTART in nanoseconds, exactly as its shortest decimal form reads."""
    return int((Decimal(repr(logstart)) * 1_000_000_000).to_integral_value())


def _timed(frame: pl.DataFrame) -> pl.DataFrame:
    """The rows whose ``log_time`` is known and not before 1970."""
    import polars as pl

    times = frame["log_time"]
    if not times.null_count() and times.min() >= 0:  # type: ignore[operator]
        return frame  # the usual case: nothing to drop, no copy
    return frame.filter(pl.col("log_time").is_not_null() & (pl.col("log_time") >= 0))


def _channel_ids(ids: dict[str, int]) -> pl.Expr:
    """Each row's channel id from its variable (every variable of the frame is in ``ids``)."""
    import polars as pl

    # An Enum cast finds the name's index in one hash lookup, 4x a string replace_strict.
    index = pl.col("variable").cast(pl.Enum(list(ids))).to_physical()
    cids = list(ids.values())
    if cids == list(range(cids[0], cids[0] + len(cids))):  # one vehicle, or the first
        return (index.cast(pl.UInt32) + cids[0]).cast(pl.UInt16)
    return index.replace_strict(list(range(len(cids))), cids, return_dtype=pl.UInt16)


def _rests(sources: pl.Series) -> pl.Series:
    """The text after the value, ``,"source":…,"aux":…,"community":…}``, of each source column."""
    import polars as pl

    parts = [split_source(text) for text in sources.to_list()]
    names = pl.DataFrame(
        parts, schema={"source": pl.String, "aux": pl.String, "community": pl.String}, orient="row"
    )
    encoded = pl.struct("source", "aux", "community").struct.json_encode().str.slice(1)
    return names.select(pl.concat_str(pl.lit(","), encoded)).to_series()


def _string_text(value: pl.Expr) -> pl.Expr:
    """A string as JSON text (``null`` for a null), as polars' ``json_encode`` writes it."""
    import polars as pl

    return pl.struct(value.alias("v")).struct.json_encode().str.slice(5).str.head(-1)


def _json(
    sources: pl.Series,
    *,
    binary: bool = True,
    finite: bool = False,
    text: pl.Expr | None = None,
) -> pl.Expr:
    """The message text of each row (``{value, source, aux, community}``).

    ``source`` is the column as written; ``sources`` its distinct values (a log has a few),
    each split and written once, then looked up by row. ``binary``: the rows may hold binary
    values (written in base64). ``finite``: every double is finite (no NaN or infinity to
    write as null), so a double's text is its cast alone. ``text``: the column ``string`` as
    JSON text, if it was made already.
    """
    import polars as pl

    col = pl.col
    if text is None:
        text = _string_text(col("string"))
    # Each branch is null where it does not apply: a double's text where it is finite, a
    # binary's base64 (or null); then a string's text, which is "null" for a double (its
    # ``string`` is null) and a binary's reference (its branch comes first).
    double = col("double").cast(pl.String)
    branches = [double if finite else pl.when(col("double").is_finite()).then(double)]
    if binary:
        encoded = pl.concat_str(pl.lit('"'), col("binary").bin.encode("base64"), pl.lit('"'))
        branches.append(
            pl.when(col("type") == "binary").then(
                pl.when(col("binary").is_not_null()).then(encoded).otherwise(pl.lit("null"))
            )
        )
    # Each row's index among the distinct sources (an Enum cast: one hash lookup, half the
    # cost of a string replace_strict), then its text by that index.
    index = col("source").cast(pl.Enum(sources)).to_physical()
    rest = pl.lit(_rests(sources)).gather(index)
    return pl.concat_str(pl.lit('{"value":'), pl.coalesce(*branches, text), rest)


def _messages(frame: pl.DataFrame) -> pl.DataFrame:
    """The batch of messages of a frame of entries with their ``channel`` (made by a worker)."""
    import polars as pl

    # The strings' JSON text, made for the rows that have one only (most rows are doubles,
    # whose ``string`` is null: their text is "null", which only a NaN or infinity uses).
    strings = frame["string"]
    if strings.null_count():
        has = strings.is_not_null()
        encoded = frame.select(_string_text(pl.col("string").filter(has))).to_series()
        text = pl.repeat("null", frame.height, dtype=pl.String, eager=True)
        frame = frame.with_columns(text.scatter(has.arg_true(), encoded).alias("string_json"))
    else:
        frame = frame.with_columns(_string_text(pl.col("string")).alias("string_json"))
    data = _json(
        frame["source"].unique(),
        binary=bool(frame["type"].eq("binary").any()),
        finite=bool(frame["double"].is_finite().all()),  # nulls (not doubles) are ignored
        text=pl.col("string_json"),
    )
    return frame.select("channel", pl.col("log_time"), data.alias("data"))


class _Channels:
    """The channel of each (vehicle, variable), declared on first use."""

    def __init__(self, writer: McapWriter) -> None:
        self.writer = writer
        self.value_schema = writer.add_schema(
            "fleetlog.MoosValue", "jsonschema", schema_bytes(VALUE_SCHEMA)
        )
        self.ids: dict[str, dict[str, int]] = {}

    def of(self, vehicle: str, session: str, variables: list[str]) -> dict[str, int]:
        known = self.ids.setdefault(vehicle, {})
        for name in variables:
            if name not in known:
                known[name] = self.writer.add_channel(
                    f"/{vehicle}/{name}",
                    "json",
                    self.value_schema,
                    {"vehicle": vehicle, "variable": name, "session": session},
                )
        return known


def export_mcap(
    sources: Sequence[Source],
    out: BinaryIO,
    tally: Tally,
    *,
    errors: Errors = "skip",
    selection: Select = None,
    positions: bool = True,
) -> McapResult:
    """Write the sources' entries as one MCAP file.

    Args:
        sources: the logs (several vehicles, several sessions each).
        out: the file.
        tally: counts what reading met.
        errors: the reader's error policy.
        selection: keep only these variables, sources and times.
        positions: add ``foxglove.LocationFix``/``PoseInFrame`` channels where possible.

    Raises:
        StorageError: a log cannot be read or the file written.
        FormatError: (``errors="raise"``) a log is corrupt.
    """
    import polars as pl

    result = McapResult()
    writer = McapWriter(out, library=f"fleetlog {__version__}")
    channels = _Channels(writer)
    nav: dict[str, list[pl.DataFrame]] = {}
    try:
        for source in sources:
            if source.logstart is None:
                # Read it anyway: the tally counts its entries as untimed, and its warnings.
                frames = entry_frames(
                    source, tally, errors=errors, selection=selection, split=False
                )
                for frame in frames:
                    result.untimed += frame.height
                continue
            base = logstart_ns(source.logstart)
            log_time = (pl.col("offset") * 1e9).round().cast(pl.Int64, strict=False) + base
            # Sources as written: each distinct one is split once, by the worker (_json).
            frames = entry_frames(source, tally, errors=errors, selection=selection, split=False)
            for frame in frames:
                timed = _timed(frame.with_columns(log_time=log_time))
                result.untimed += frame.height - timed.height
                if not timed.height:
                    continue
                names = timed["variable"].unique().sort().to_list()
                ids = channels.of(source.vehicle, source.session, names)
                # Each row's channel, found once: the position rows are picked by it too.
                timed = timed.with_columns(_channel_ids(ids).alias("channel"))
                # The JSON text is made by the writer's worker while this thread reads on.
                writer.write_lazy(partial(_messages, timed), timed.height)
                navs = [ids[name] for name in names if name in NAV_VARS]
                if positions and navs:
                    wanted = (
                        timed.select("channel", "log_time", "variable", "type", "double")
                        .filter(pl.col("channel").is_in(navs))
                        .filter(pl.col("type") == "double")
                    )
                    if wanted.height:
                        nav.setdefault(source.vehicle, []).append(
                            wanted.select("log_time", "variable", "double")
                        )
        if positions:
            _derived(writer, channels, nav, result)
        result.channels = sum(len(v) for v in channels.ids.values()) + len(result.derived)
        writer.finish()
        result.messages = writer.messages
    except BaseException:
        writer.abort()
        raise
    return result


def _derived(
    writer: McapWriter,
    channels: _Channels,
    nav: dict[str, list[pl.DataFrame]],
    result: McapResult,
) -> None:
    import polars as pl

    schemas: dict[str, int] = {}
    for vehicle, parts in nav.items():
        rows = pl.concat(parts).with_columns(pl.col("log_time").cast(pl.UInt64))
        for kind, schema, derived in (
            ("location", LOCATION_FIX, locations(rows, vehicle)),
            ("pose", POSE_IN_FRAME, poses(rows)),
        ):
            height = derived.rows.height
            if not height:
                continue
            name = str(schema["title"])
            if name not in schemas:
                schemas[name] = writer.add_schema(name, "jsonschema", schema_bytes(schema))
            topic = f"/{vehicle}/{kind}"
            if kind in channels.ids.get(vehicle, {}):
                topic += "_fleetlog"  # a variable of that very name exists: keep both
            cid = writer.add_channel(topic, "json", schemas[name], {"vehicle": vehicle})
            result.derived.append(topic)
            # In slices (the rows are in time order): the workers share a long channel's JSON
            # and chunks instead of one of them writing it alone at the end.
            for at in range(0, height, _SLICE):
                part = derived.rows.lazy().slice(at, _SLICE)
                writer.write_lazy(
                    part.select(
                        pl.lit(cid).alias("channel"), "log_time", derived.data.alias("data")
                    ),
                    min(_SLICE, height - at),
                )
