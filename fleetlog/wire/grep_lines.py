"""The remote grep's reply stream: JSON lines, a header first, an end record last (docs/wire.md).

Pure code. A grep answer is a run of replies of about
:data:`~fleetlog.wire.replies.REPLY_TARGET` bytes, each holding whole lines: one
:class:`GrepHeader` (how to read and print the entries), then one compact
:class:`GrepRecord` per matching entry, then one :class:`GrepEnd` (what was scanned, whether
the limit or a cut file stopped it). :func:`encode_grep_line` writes a line,
:func:`decode_grep_lines` reads a reply's lines and refuses any field of the wrong type. The
request is :class:`~fleetlog.wire.query.GrepRequest`; :mod:`fleetlog.wire.query` re-exports
every name here.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass
from typing import Any

from fleetlog.errors import FormatError
from fleetlog.wire.json_fields import dump_json, optional_field, parse_json, required_field

__all__ = ["GrepEnd", "GrepHeader", "GrepRecord", "decode_grep_lines", "encode_grep_line"]


@dataclass(frozen=True, slots=True)
class GrepHeader:
    """The first line of a grep stream: how to read and print the entries.

    Attributes:
        session: the session.
        alog: the alog's file name.
        logstart: LOGSTART, or None when the banner is unusable.
        banner: the alog's banner lines, without newlines (aloggrep keeps them).
        time_decimals: decimals of the file's time column (3 essential-moos, 5 MOOS-IvP).
        mark_data_type: the file marks values ``D:``/``S:``.
    """

    session: str
    alog: str
    logstart: float | None
    banner: tuple[str, ...] = ()
    time_decimals: int = 5
    mark_data_type: bool = False


@dataclass(frozen=True, slots=True)
class GrepRecord:
    """One matching entry: time since LOGSTART, variable, source, type and value text.

    ``kind`` is ``d`` (double), ``s`` (string) or ``b`` (binary: ``text`` is the
    ``<MOOS_BINARY>`` reference); ``text`` is the value as written, without padding or
    MarkDataType marker; ``lineno`` is where the entry starts in the file.
    """

    offset: float
    key: str
    source: str
    kind: str
    text: str
    lineno: int


@dataclass(frozen=True, slots=True)
class GrepEnd:
    """The last line of a grep stream.

    Attributes:
        matched: entries sent.
        scanned: entries read.
        truncated: the limit stopped the scan before the end of the file.
        skipped: lines the reader could not use (see ``AlogReader.skipped``).
        cut: the file ended inside an entry (being written, or a crash).
    """

    matched: int
    scanned: int
    truncated: bool
    skipped: int = 0
    cut: bool = False


_KINDS = frozenset("dsb")


def encode_grep_line(item: GrepHeader | GrepRecord | GrepEnd) -> bytes:
    """Return one line of a grep stream, newline included."""
    obj: object
    if isinstance(item, GrepRecord):
        obj = [item.offset, item.key, item.source, item.kind, item.text, item.lineno]
    elif isinstance(item, GrepHeader):
        obj = {
            "header": True,
            "session": item.session,
            "alog": item.alog,
            "logstart": item.logstart,
            "banner": list(item.banner),
            "time_decimals": item.time_decimals,
            "mark_data_type": item.mark_data_type,
        }
    else:
        obj = {
            "end": True,
            "matched": item.matched,
            "scanned": item.scanned,
            "truncated": item.truncated,
            "skipped": item.skipped,
            "cut": item.cut,
        }
    return dump_json(obj) + b"\n"


_new = object.__new__
_RECORD_SETTERS = tuple(
    GrepRecord.__dict__[name].__set__
    for name in ("offset", "key", "source", "kind", "text", "lineno")
)


def _grep_record(obj: list[Any]) -> GrepRecord:
    if len(obj) != 6:
        msg = "grep reply: an entry is not [time, var, source, kind, text, line]"
        raise FormatError(msg)
    offset, key, source, kind, text, lineno = obj
    if (
        type(key) is not str
        or type(source) is not str
        or type(text) is not str
        or type(lineno) is not int
        or type(kind) is not str
        or kind not in _KINDS
        or type(offset) not in (float, int)
    ) and not _loose_record(offset, key, source, kind, text, lineno):
        msg = "grep reply: an entry is not [time, var, source, kind, text, line]"
        raise FormatError(msg)
    return _new_record(offset, key, source, kind, text, lineno)


def _new_record(
    offset: float, key: str, source: str, kind: str, text: str, lineno: int
) -> GrepRecord:
    """Build a checked record's :class:`GrepRecord`.

    A shore reads a record per matching line: the frozen slots are set directly, as
    wire.message.new_message does, instead of the dataclass's six object.__setattr__.
    """
    record = _new(GrepRecord)
    s_offset, s_key, s_source, s_kind, s_text, s_lineno = _RECORD_SETTERS
    s_offset(record, float(offset))
    s_key(record, key)
    s_source(record, source)
    s_kind(record, kind)
    s_text(record, text)
    s_lineno(record, lineno)
    return record


def _loose_record(offset: Any, key: Any, source: Any, kind: Any, text: Any, lineno: Any) -> bool:
    """The isinstance form of the record check (json gives exact types; bool is an int)."""
    return (
        isinstance(offset, int | float)
        and all(isinstance(x, str) for x in (key, source, kind, text))
        and kind in _KINDS
        and isinstance(lineno, int)
    )


# A record line exactly as a vehicle writes it (compact JSON, ASCII or not; the time an
# integer of at most 18 digits or a JSON float, the line an integer of at most 18 digits: no
# integer near 64 bits), matched without backtracking (possessive): a line this accepts is
# one JSON array that _grep_record would take, so such lines can be parsed in one call.
_STRING = rb'"(?:[^"\\\x00-\x1f]++|\\["\\/bfnrt]|\\u[0-9a-fA-F]{4})*+"'
_INT = rb"-?(?:0|[1-9][0-9]{0,17})"
_NUMBER = _INT + rb"(?:\.[0-9]+)?(?:[eE][-+]?[0-9]+)?"
_RECORD = (
    rb"\[" + _NUMBER + (rb"," + _STRING) * 2 + rb',"[dsb]",' + _STRING + rb"," + _INT + rb"\]\n"
)
_RECORDS = re.compile(rb"(?:" + _RECORD + rb")*+")


def decode_grep_lines(data: bytes) -> list[GrepHeader | GrepRecord | GrepEnd]:
    """Read one grep reply (several lines).

    The record lines between a header and an end record, when every one of them is exactly
    what a vehicle writes, are parsed in one ``json.loads``; any other reply line by line,
    as before (what each line gives, or the first refusal, is the same either way).

    Raises:
        FormatError: a line is not a header, an entry or an end record.
    """
    start, end = 0, len(data)
    if data.startswith(b"{"):  # the header, in a stream's first reply
        start = data.find(b"\n") + 1 or end
    if data.endswith(b"}\n"):  # the end record, in its last
        end = data.rfind(b"\n", start, end - 1) + 1 or start
    records = _records(data[start:end])
    if records is None:
        return _decode_lines(data)
    return [*_decode_lines(data[:start]), *records, *_decode_lines(data[end:])]


def _records(body: bytes) -> list[GrepHeader | GrepRecord | GrepEnd] | None:
    """Parse record lines in one call; None unless every line is exactly a vehicle's record."""
    if _RECORDS.fullmatch(body) is None:
        return None
    try:
        rows = json.loads(b"[" + body[:-1].replace(b"\n", b",") + b"]")
    except ValueError:  # bytes that are not UTF-8 inside a string
        return None
    return [_new_record(*row) for row in rows]


def _decode_lines(data: bytes) -> list[GrepHeader | GrepRecord | GrepEnd]:
    """Read a reply's lines one by one, each checked."""
    out: list[GrepHeader | GrepRecord | GrepEnd] = []
    for line in data.splitlines():
        if not line:
            continue
        try:
            obj = parse_json(line)
        except ValueError as err:
            msg = f"grep reply: a line is not JSON: {err}"
            raise FormatError(msg) from None
        if isinstance(obj, list):
            out.append(_grep_record(obj))
        elif isinstance(obj, dict) and obj.get("header") is True:
            what = "grep header"
            logstart = optional_field(obj, "logstart", (int, float), what)
            banner = required_field(obj, "banner", list, what)
            out.append(
                GrepHeader(
                    required_field(obj, "session", str, what),
                    required_field(obj, "alog", str, what),
                    None if logstart is None else float(logstart),
                    tuple(str(x) for x in banner),
                    required_field(obj, "time_decimals", int, what),
                    required_field(obj, "mark_data_type", bool, what),
                )
            )
        elif isinstance(obj, dict) and obj.get("end") is True:
            what = "grep end"
            out.append(
                GrepEnd(
                    required_field(obj, "matched", int, what),
                    required_field(obj, "scanned", int, what),
                    required_field(obj, "truncated", bool, what),
                    required_field(obj, "skipped", int, what),
                    required_field(obj, "cut", bool, what),
                )
            )
        else:
            msg = "grep reply: a line is neither a header, an entry nor an end record"
            raise FormatError(msg)
    return out
