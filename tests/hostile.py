r"""Hypothesis strategies for every input a network peer or an operator controls (issue 10).

One place for hostile data, shared by the fuzz suite (``tests/fuzz/``) and any test that
wants it: a new reader or parser gets fuzzed by adding a target in
``tests/fuzz/test_inputs.py`` that draws from these.

The text strategies lean on what breaks line formats and parsers: spaces, tabs, every
line separator ``str.splitlines`` knows, a newline followed by a digit or ``%`` (the start
of a forged entry or a comment), the separators of the source column (``:``, ``@``), ``%``
escapes, NUL, bytes that are not UTF-8 (as ``surrogateescape`` surrogates), long runs, and
plain MOOS-looking names so that the interesting cases sit next to ordinary ones.
"""

from __future__ import annotations

import gzip
import json
import math
import struct
from typing import Any

import zstandard
from hypothesis import strategies as st

from fleetlog.moos.alog import LineFormatter, Variant, format_banner
from fleetlog.wire.message import ENCODINGS, encode_attachment

__all__ = [
    "alog_files",
    "attachments",
    "control_requests",
    "encodings",
    "hostile_text",
    "keep_missions",
    "key_chunks",
    "message_times",
    "mission_texts",
    "moos_names",
    "note_texts",
    "payloads",
    "plogger_cmds",
    "query_parameters",
    "selector_keys",
    "sizes_and_durations",
    "snapshot_events",
    "triggers",
]

#: characters that break line formats, column splitting or escaping
NASTY = (
    " \t\n\r\x0b\x0c\x1c\x1d\x1e\x85\u2028\u2029\xa0\u200b\ufeff\x00\x7f:@%/*$?#=,;|&<>\\\"'{}[]"
)
SURROGATES = "".join(chr(0xDC80 + i) for i in (0, 1, 0x7F))
_ALPHA = "ABXYZ_abc019."

hostile_chars = st.sampled_from(NASTY + SURROGATES + _ALPHA)
#: short strings where almost every character is hostile
nasty_text = st.text(alphabet=hostile_chars, max_size=24)
#: forged-entry material: a newline, then a line that would pass for an entry or a comment
forged_tails = st.sampled_from(
    [
        "\n0.00000 FORGED iEvil 1 ",
        "\n1 X Y Z",
        "\n-2.5 NEG src v",
        "\n%% comment",
        "\n%",
        "\n\n3",
        "\r\n4 A B C",
    ]
)


@st.composite
def _spliced(draw: st.DrawFn, base: st.SearchStrategy[str]) -> str:
    text = draw(base)
    if draw(st.booleans()):
        at = draw(st.integers(0, len(text)))
        text = text[:at] + draw(forged_tails) + text[at:]
    return text


#: any text a peer may send as a name, a source, a value or a command argument
hostile_text = st.one_of(
    st.text(alphabet=_ALPHA, max_size=16),
    _spliced(nasty_text),
    st.text(max_size=24),
    st.text(alphabet=hostile_chars, min_size=200, max_size=600),
)
moos_names = st.one_of(
    st.sampled_from(["NAV_X", "DEPLOY", "MOOS_DEBUG", "PLOGGER_CMD", "LOGGER_RESTART", ""]),
    hostile_text,
)


def _finite_or_not() -> st.SearchStrategy[float]:
    return st.one_of(
        st.floats(allow_nan=True, allow_infinity=True),
        st.sampled_from([math.nan, -math.nan, math.inf, -math.inf, 1e300, -1e300, 0.0, -0.0]),
        st.sampled_from([5e-324, 1e10, 1e10 + 1, 2.0**63, -1.0]),
        st.floats(1.7e9, 1.9e9),
    )


#: message times as a peer may put them in an attachment
message_times = _finite_or_not()


@st.composite
def _valid_attachment(draw: st.DrawFn) -> bytes:
    original = draw(st.none() | message_times)
    return encode_attachment(
        draw(message_times),
        draw(hostile_text),
        draw(hostile_text),
        draw(hostile_text),
        original,
    )


def _leb(n: int) -> bytes:
    out = bytearray()
    while True:
        byte, n = n & 0x7F, n >> 7
        out.append(byte | (0x80 if n else 0))
        if not n:
            return bytes(out)


@st.composite
def _crafted_attachment(draw: st.DrawFn) -> bytes:
    """Field by field, with lengths that lie, strings that are not UTF-8, odd tails."""
    out = struct.pack("<d", draw(message_times))
    for _ in range(draw(st.integers(0, 5))):
        raw = draw(st.binary(max_size=12))
        length = draw(st.sampled_from([len(raw), len(raw) + 1, 0, 2**35, 2**63]))
        out += _leb(length) + raw
    if draw(st.booleans()):
        out += draw(st.binary(max_size=9))
    return out


#: attachments: valid ones with hostile fields, cut ones, crafted ones, noise
attachments = st.one_of(
    _valid_attachment(),
    _valid_attachment().flatmap(lambda a: st.integers(0, len(a)).map(lambda n: a[:n])),
    _crafted_attachment(),
    st.binary(max_size=64),
    st.just(b"\xff" * 40),
)

#: encodings a publisher may declare
encodings = st.one_of(
    st.sampled_from(
        [
            *ENCODINGS.values(),
            "text/plain",
            "zenoh/string",
            "zenoh/bytes",
            "application/octet-stream",
            "application/json",
            "",
        ]
    ),
    st.text(max_size=30),
)


def _number_texts() -> st.SearchStrategy[bytes]:
    return st.one_of(
        st.floats(allow_nan=True, allow_infinity=True).map(lambda f: repr(f).encode()),
        st.sampled_from([b"nan", b"inf", b"-inf", b"1e999", b"1" * 400, b"0x10", b"1_0", b" 1"]),
        st.from_regex(rb"[-+]?[0-9]{0,30}(\.[0-9]{0,30})?([eE][-+]?[0-9]{1,4})?", fullmatch=True),
    )


#: payloads of every kind: numbers, hostile text, bytes that are not UTF-8, big ones
payloads = st.one_of(
    _number_texts(),
    hostile_text.map(lambda t: t.encode("utf-8", "surrogateescape")),
    st.binary(max_size=64),
    st.binary(min_size=4096, max_size=20000),
)

# --------------------------------------------------------------------------------------------
# Keys and queries

#: one key chunk after ``<root>/V/var/``: escapes well and badly formed, raw wildcards
key_chunks = st.one_of(
    st.from_regex(r"[A-Za-z0-9_ %$*@#?.:-]{0,20}", fullmatch=True),
    st.sampled_from(["%00", "%2A", "%2a", "%40x", "x%40", "%", "%G0", "%FF", "$*", "**", "@a"]),
    hostile_text,
)

SERVICES = ["sessions", "latest", "file", "grep", "control", "status", "replay/control"]


@st.composite
def selector_keys(draw: st.DrawFn) -> str:
    """Key expressions a shore peer may query under a vehicle's ``@fleetlog``."""
    parts = draw(
        st.lists(
            st.one_of(st.sampled_from(SERVICES), key_chunks, st.just(".."), st.just("")),
            max_size=5,
        )
    )
    return "/".join(parts)


PARAMETER_NAMES = [
    "since",
    "limit",
    "offset",
    "length",
    "sha256",
    "var",
    "src",
    "start",
    "end",
    "cmd",
    "all",
    "latest",
    "x",
]


@st.composite
def query_parameters(draw: st.DrawFn) -> str:
    """Selector parameters: known and unknown names, repeated ones, bad escapes, huge values."""
    items = []
    for _ in range(draw(st.integers(0, 6))):
        name = draw(st.sampled_from(PARAMETER_NAMES) | st.text(max_size=6))
        value = draw(
            st.one_of(
                st.integers(-(2**70), 2**70).map(str),
                st.floats().map(repr),
                st.from_regex(r"[*?a-zA-Z_|]{0,40}", fullmatch=True),
                hostile_text,
                st.just("*a" * 200 + "b"),
            )
        )
        items.append(name if draw(st.booleans()) and not value else f"{name}={value}")
    return ";".join(items)


# --------------------------------------------------------------------------------------------
# Commands

_TASKS = ["LOG_REQUEST", "COPY_FILE_REQUEST", "log_request", "Copy_File_Request", "NOPE", ""]
#: the recording-mode words of PLOGGER_CMD (issue 17), and near misses
_MODE_WORDS = ["PAUSE", "RESUME", "SPLIT", "pause", " Resume ", "SPLIT=1", "PAUSED", "NOTE"]
_PATHS = [
    "m.moos",
    ".ssh/id_rsa",
    ".hidden",
    "sub/.hidden/x",
    "../outside",
    "/etc/passwd",
    "/dev/zero",
    "/proc/self/environ",
    "fifo",
    "link_out",
    "link_in",
    "big.bin",
    "a\x00b",
    "x" * 300,
    ("d" * 200 + "/") * 3,
    "sub/",
    "",
]


@st.composite
def plogger_cmds(draw: st.DrawFn) -> str | float | bytes:
    """PLOGGER_CMD values: well-formed requests with hostile arguments, and garbage."""
    choice = draw(st.integers(0, 11))
    if choice == 0:
        return draw(st.floats(allow_nan=True) | st.binary(max_size=8))
    if choice == 1:
        return draw(hostile_text)
    if choice == 10:
        return draw(st.sampled_from(_MODE_WORDS))
    if choice == 11:
        return draw(note_texts().map(lambda note: "NOTE=" + note))
    task = draw(st.sampled_from(_TASKS) | st.text(max_size=10))
    if task.upper() == "COPY_FILE_REQUEST":
        argument = draw(st.sampled_from(_PATHS) | hostile_text)
    else:
        var = draw(st.sampled_from(["NAV_X", "V_1", "MOOS_DEBUG"]) | hostile_text)
        tail = draw(
            st.sampled_from(["", "@0", "@ 1.5", "@-1", "@nan", "@inf", "@1e308", " NOSYNC"])
            | hostile_text.map(lambda t: "@" + t)
        )
        argument = var + tail + draw(st.sampled_from(["", " monitor", " NOSYNC monitor"]))
    sep = draw(st.sampled_from(["=", " = ", "==", ""]))
    return task + sep + argument


@st.composite
def note_texts(draw: st.DrawFn) -> str:
    """``key:value`` texts (NOTE=, --note, ``Note =``): fine, huge, colonless, unprintable."""
    key = draw(st.sampled_from(["site", "event", "", " ", "k" * 65]) | hostile_text)
    value = draw(st.sampled_from(["bay", "a: b", "", "v" * 1025]) | hostile_text)
    sep = draw(st.sampled_from([":", " : ", "", "::", "="]))
    return key + sep + value


#: ``SplitSize`` / ``SplitDuration`` / ``--split-*`` values: numbers, units, overflow, garbage
sizes_and_durations = st.one_of(
    st.sampled_from(
        ["500MB", "2 GiB", "10min", "1.5h", "90", "0", "1e999", "1e308GB", ".5kB", "5 5", "-1s"]
    ),
    st.builds(
        lambda n, unit: f"{n}{unit}",
        st.floats(allow_nan=True, allow_infinity=True) | st.integers(-(10**30), 10**30),
        st.sampled_from(["", "B", "kb", "MiB", "GB", "TB", "s", "min", "h", "d", "furlong"]),
    ),
    hostile_text,
)


#: control-request payloads: JSON objects with known and unknown commands and argument types
control_requests = st.one_of(
    st.fixed_dictionaries(
        {
            "cmd": st.sampled_from(
                [
                    "restart",
                    "pause",
                    "resume",
                    "split",
                    "snapshot",
                    "note",
                    "log_request",
                    "copy_file",
                    "ack",
                    "status",
                    "nope",
                ]
            )
            | hostile_text,
        },
        optional={
            "spec": hostile_text | st.integers(),
            "path": st.sampled_from(_PATHS) | hostile_text,
            "key": hostile_text,
            "value": hostile_text | st.floats() | st.none(),
            "session": hostile_text,
            "files": st.dictionaries(hostile_text, hostile_text, max_size=3) | st.integers(),
        },
    ).map(lambda d: json.dumps(d).encode()),
    st.binary(max_size=64),
    st.recursive(
        st.none() | st.booleans() | st.floats() | st.text(max_size=5),
        lambda kids: st.lists(kids, max_size=3) | st.dictionaries(st.text(max_size=4), kids),
        max_leaves=10,
    ).map(lambda v: json.dumps(v).encode()),
    st.just(b"[" * 100_000),
    st.just(b'{"cmd": "note", "value": "' + b"x" * 70_000 + b'"}'),
)

# --------------------------------------------------------------------------------------------
# Mission files

_SETTINGS = [
    "File",
    "Path",
    "AsyncLog",
    "SyncLog",
    "WildcardLogging",
    "WildcardPattern",
    "WildcardOmitPattern",
    "WildcardExclusionLog",
    "LogAuxSrc",
    "DoublePrecision",
    "DynamicSyncLogColumns",
    "FileTimeStamp",
    "CompressAlogs",
    "MarkDataType",
    "Log",
    "COPY_FILE_DIRS",
    "AppTick",
    "MOOSTimeWarp",
    "Community",
    "SplitSize",
    "SplitDuration",
    "StartPaused",
    "Note",
    "Tag",
    "WildcardLoging",
]
_VALUES = [
    "true",
    "false",
    "",
    "99999999999",
    "-1",
    "1e308",
    "nan",
    "NAV_X @ 0",
    "NAV_X @ 0 NOSYNC monitor",
    "*_X",
    "x" * 300,
    ("p" * 256 + "/") * 2,
    "\udcff\udcfe",
    "${UNDEFINED}",
    "gzip",
    "zstd",
    "true @ 0.2",
    "true @ -5",
    "500MB",
    "1 GiB",
    "10min",
    "1e999h",
    "0.5",
    "site:bay",
    ":v",
    "a, b,,c",
]


@st.composite
def mission_texts(draw: st.DrawFn) -> str:
    """Mission files: real structure with hostile settings, broken blocks, defines, noise."""
    lines: list[str] = []
    for _ in range(draw(st.integers(0, 4))):
        lines.append(draw(st.sampled_from(["Community = V", "ServerPort = 9000", "define: A = B"])))
    for _ in range(draw(st.integers(0, 2))):
        lines.append("ProcessConfig = " + draw(st.sampled_from(["pLogger", "pOther", ""])))
        if draw(st.integers(0, 9)):
            lines.append("{")
        for _ in range(draw(st.integers(0, 8))):
            name = draw(st.sampled_from(_SETTINGS) | st.text(max_size=8))
            value = draw(st.sampled_from(_VALUES) | hostile_text)
            lines.append(f"  {name} = {value}")
        if draw(st.integers(0, 9)):
            lines.append("}")
    if draw(st.booleans()):
        at = draw(st.integers(0, len(lines)))
        lines.insert(at, draw(hostile_text))
    return "\n".join(lines) + draw(st.sampled_from(["\n", "", "\r\n"]))


# --------------------------------------------------------------------------------------------
# Snapshot mode and the disk's bounds (issue 17)

_KEEP_SETTINGS = [
    "SnapshotSeconds",
    "SnapshotMemory",
    "SnapshotAfter",
    "SnapshotTrigger",
    "MinFreeDisk",
    "KeepSessions",
    "MaxLogSize",
    "snapshotseconds",
]
_KEEP_VALUES = [
    "30",
    "0",
    "0.05",
    "2min",
    "1.5h",
    "1e9",
    "1e400",
    "nan",
    "inf",
    "-1",
    "256MB",
    "2 GiB",
    "100kB",
    "10 potatoes",
    "1.5.3kB",
    "99999999999999999999TB",
    "ALARM == 1",
    "A==",
    "== 1",
    "MODE == FAULT",
    "X == nan",
    "X == 1e999",
    "X == -",
    "X == a == b",
    "\u00b2",
    "\u0663",
    "0x10",
    "",
]
#: trigger texts: well-formed ones with hostile halves, and garbage
triggers = st.one_of(
    st.sampled_from(_KEEP_VALUES),
    st.tuples(
        st.sampled_from(["ALARM", "A_B", "x.y", "", " "]) | hostile_text,
        st.sampled_from(["==", "= =", "===", "=", ""]),
        st.sampled_from(["1", "FAULT", "-2.5", "1e3", " ", "nan"]) | hostile_text,
    ).map("".join),
)


@st.composite
def keep_missions(draw: st.DrawFn) -> str:
    """Missions whose pLogger block sets snapshot and disk settings to hostile values."""
    lines = ["ProcessConfig = pLogger", "{"]
    if draw(st.booleans()):
        lines.append("  SnapshotSeconds = " + draw(st.sampled_from(_KEEP_VALUES[:6])))
    for _ in range(draw(st.integers(1, 6))):
        name = draw(st.sampled_from(_KEEP_SETTINGS))
        value = draw(st.sampled_from(_KEEP_VALUES) | hostile_text | triggers)
        lines.append(f"  {name} = {value}")
    lines.append("}")
    return "\n".join(lines) + "\n"


_EVENT_NAMES = ["A", "ALARM", "PLOGGER_CMD", "LOGGER_RESTART", "MOOS_DEBUG"]


@st.composite
def snapshot_events(draw: st.DrawFn) -> list[tuple[str, Any, Any]]:
    """What a snapshot-mode recorder meets: samples with hostile values and times, trigger
    writes, PLOGGER_CMD (SNAPSHOT among garbage), control requests, and time passing."""
    events: list[tuple[str, Any, Any]] = []
    for _ in range(draw(st.integers(1, 30))):
        kind = draw(st.sampled_from(["sample", "sample", "alarm", "cmd", "control", "tick"]))
        if kind == "sample":
            name = draw(st.sampled_from(_EVENT_NAMES) | moos_names)
            value = draw(
                st.floats() | hostile_text | st.binary(max_size=64) | st.text(max_size=3000)
            )
            events.append((kind, name, (value, draw(message_times))))
        elif kind == "alarm":
            value = draw(
                st.sampled_from([0.0, 1.0, 1.0000001, "1", " 1 "]) | st.floats() | hostile_text
            )
            events.append((kind, "ALARM", value))
        elif kind == "cmd":
            value = draw(
                st.sampled_from(["SNAPSHOT", "snapshot", " SNAP SHOT ", "SNAPSHOT="])
                | plogger_cmds()
            )
            events.append((kind, "PLOGGER_CMD", value))
        elif kind == "control":
            extra = draw(
                st.sampled_from(["", ',"source":"x\\n0 FORGED y 1"', ',"x":1', ',"time":1e999'])
            )
            events.append((kind, "", ('{"cmd":"snapshot"' + extra + "}").encode()))
        else:
            events.append((kind, "", draw(st.floats(0.0, 3.0))))
    return events


# --------------------------------------------------------------------------------------------
# Log files


@st.composite
def _alog_text(draw: st.DrawFn) -> str:
    mark = draw(st.booleans())
    variant = draw(st.sampled_from([Variant.IVP, Variant.EM]))
    fmt = LineFormatter(variant, draw(st.integers(0, 12)), mark_data_type=mark)
    text = format_banner("x/x.alog", 1.8e9, "Thu Jan  1 00:00:00 1970", mark_data_type=mark)
    for _ in range(draw(st.integers(0, 12))):
        offset = draw(st.floats(-10, 1e6) | st.sampled_from([0.0, 1e15]))
        key = draw(st.sampled_from(["NAV_X", "S", "A_B"]) | st.text(alphabet=_ALPHA, max_size=30))
        source = draw(st.sampled_from(["iX", "pH:aux", "p@shore"]) | st.text(_ALPHA, max_size=30))
        if draw(st.booleans()):
            text += fmt.double(offset, key or "K", source or "S", draw(st.floats()))
        else:
            text += fmt.string(offset, key or "K", source or "S", draw(hostile_text))
    return text


@st.composite
def _corrupted(draw: st.DrawFn, base: st.SearchStrategy[bytes]) -> bytes:
    data = draw(base)
    for _ in range(draw(st.integers(0, 3))):
        if not data:
            break
        at = draw(st.integers(0, len(data) - 1))
        action = draw(st.integers(0, 2))
        if action == 0:
            data = data[:at]
        elif action == 1:
            data = data[:at] + bytes([draw(st.integers(0, 255))]) + data[at + 1 :]
        else:
            data = data[:at] + draw(st.binary(max_size=16)) + data[at:]
    return data


_plain = _alog_text().map(lambda t: t.encode("utf-8", "surrogateescape"))
_zstd = zstandard.ZstdCompressor()


@st.composite
def alog_files(draw: st.DrawFn) -> tuple[str, bytes]:
    """``(suffix, bytes)`` of a log file: valid, cut, corrupted or noise; plain, gz or zst."""
    suffix = draw(st.sampled_from([".alog", ".alog.gz", ".alog.zst"]))
    plain = draw(_plain)
    if suffix == ".alog.gz":
        data = gzip.compress(plain, mtime=0)
    elif suffix == ".alog.zst":
        data = _zstd.compress(plain)
    else:
        data = plain
    data = draw(_corrupted(st.just(data)) | st.just(data) | st.binary(max_size=200))
    return suffix, data


def as_json(value: Any) -> str:
    """JSON text of a value (helper for targets that log what they were given)."""
    return json.dumps(value, default=repr)
