"""The query protocol (fleetlog.wire.query): keys, parameters, refusals, reply round trips."""

from __future__ import annotations

import pytest

from fleetlog.errors import FormatError
from fleetlog.wire.query import (
    MAX_RANGE,
    FileInfo,
    FileMeta,
    FileRequest,
    GrepEnd,
    GrepHeader,
    GrepRecord,
    GrepRequest,
    LatestInfo,
    SessionInfo,
    SessionsRequest,
    TimeBound,
    check_component,
    decode_grep_lines,
    encode_grep_line,
    file_key,
    grep_key,
    parse_file_request,
    parse_grep_request,
    parse_parameters,
    parse_service_parts,
    parse_sessions_request,
    sessions_from_json,
    sessions_to_json,
)

SESSION = "MOOSLog_3_2_2025_____09_05_07"


@pytest.mark.parametrize(
    ("name", "match"),
    [
        ("", "is empty"),
        (".", "relative directory"),
        ("..", "relative directory"),
        ("../etc", "holds '/'"),
        ("/etc/passwd", "holds '/'"),
        ("a\\b", "holds '\\\\'"),
        ("a\x00b", "NUL"),
        ("x" * 256, "longer than 255 bytes"),
    ],
)
def test_component_refusals(name: str, match: str) -> None:
    with pytest.raises(FormatError, match=match):
        check_component(name, "session")


def test_component_accepts_plain_names() -> None:
    for name in (SESSION, "FIXED", "a b", "x.alog.gz", "...", ".hidden", "é"):
        assert check_component(name, "file") == name


def test_keys_escape_and_parse_back() -> None:
    key = file_key("fleet", "#1", "S*1", "a?b")
    assert key == "fleet/%231/@fleetlog/file/S%2A1/a%3Fb"
    assert parse_service_parts(key) == ("file", ("S*1", "a?b"))
    assert parse_service_parts(grep_key("fleet", "alpha", SESSION)) == ("grep", (SESSION,))
    assert parse_service_parts("fleet/*/@fleetlog/latest") == ("latest", ())
    with pytest.raises(FormatError, match="holds '/'"):
        file_key("fleet", "alpha", "../x", "y")


@pytest.mark.parametrize(
    ("key", "match"),
    [
        ("fleet/alpha/var/X", "names no @fleetlog service"),
        ("fleet/alpha/@fleetlog", "names no service"),
        ("fleet/alpha/@fleetlog/status2", "unknown service"),
        ("fleet/alpha/@fleetlog/file/S", "takes session and file"),
        ("fleet/alpha/@fleetlog/file/**", "wildcard '\\*\\*'"),
        ("fleet/alpha/@fleetlog/grep/$*x", "wildcard"),
        ("fleet/alpha/@fleetlog/file/../x", "relative directory"),
        ("fleet/alpha/@fleetlog/file/S/..%2Fetc", "holds '/'"),
        ("fleet/alpha/@fleetlog/file/%2Fetc/passwd", "holds '/'"),
        ("fleet/alpha/@fleetlog/file/S/%2e%2e", "not an escaped name"),
        ("fleet/alpha/@fleetlog/file/S/a\x00b", "NUL"),
    ],
)
def test_service_key_refusals(key: str, match: str) -> None:
    with pytest.raises(FormatError, match=match):
        parse_service_parts(key)


def test_parameters_percent_decode_and_refuse() -> None:
    assert parse_parameters("var=A%7CB|C;source=%3B", ("var", "source")) == {
        "var": "A|B|C",
        "source": ";",
    }
    assert parse_parameters("", ("x",)) == {}
    with pytest.raises(FormatError, match="unknown parameter 'bogus'"):
        parse_parameters("bogus=1", ("var",))
    with pytest.raises(FormatError, match="given twice"):
        parse_parameters("var=a;var=b", ("var",))
    with pytest.raises(FormatError, match="not followed by two hex digits"):
        parse_parameters("var=%zz", ("var",))
    with pytest.raises(FormatError, match="NUL"):
        parse_parameters("var=a%00", ("var",))
    with pytest.raises(FormatError, match="characters long"):
        parse_parameters("var=" + "x" * 9000, ("var",))


def test_file_request_bounds() -> None:
    assert parse_file_request("") == FileRequest(0, 1 << 20, False)
    assert parse_file_request("offset=5;length=0;sha256=1") == FileRequest(5, 0, True)
    assert parse_file_request(FileRequest(7, MAX_RANGE, True).parameters()) == FileRequest(
        7, MAX_RANGE, True
    )
    with pytest.raises(FormatError, match="a range holds at most 4194304"):
        parse_file_request(f"length={MAX_RANGE + 1}")
    with pytest.raises(FormatError, match="'offset' must be a whole number"):
        parse_file_request("offset=-1")
    with pytest.raises(FormatError, match="'offset' must be a whole number"):
        parse_file_request("offset=1e9")
    with pytest.raises(FormatError, match="'sha256' must be 1 or 0"):
        parse_file_request("sha256=yes")


def test_grep_request_round_trip() -> None:
    request = GrepRequest(
        ("NAV_*", "A|B;C%"), ("pHelm*",), TimeBound(1.5), TimeBound(1750334690.5, True), 10
    )
    assert parse_grep_request(request.parameters()) == GrepRequest(
        ("NAV_*", "A", "B;C%"), ("pHelm*",), TimeBound(1.5), TimeBound(1750334690.5, True), 10
    )
    assert parse_grep_request("") == GrepRequest()


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("from=abc", "'from' must be seconds"),
        ("to=@", "'to' must be seconds"),
        ("from=nan", "'from' must be seconds"),
        ("from=5;to=1", "'from' \\(5.0\\) is after 'to'"),
        ("limit=0", "'limit' must be between 1"),
        ("var=a b", "without blanks"),
        ("var=A||B", "non-empty"),
        ("var=" + "|".join("x" * 65), "at most 64"),
        ("where=1", "unknown parameter 'where'"),
    ],
)
def test_grep_request_refusals(text: str, match: str) -> None:
    with pytest.raises(FormatError, match=match):
        parse_grep_request(text)


def test_sessions_request() -> None:
    assert parse_sessions_request("") == SessionsRequest()
    request = SessionsRequest(SESSION, True)
    assert parse_sessions_request(request.parameters()) == request
    with pytest.raises(FormatError, match="relative directory"):
        parse_sessions_request("session=..")


def test_time_bound_offsets() -> None:
    assert TimeBound(3.0).offset(None) == 3.0
    assert TimeBound(110.0, True).offset(100.0) == 10.0
    with pytest.raises(FormatError, match="LOGSTART"):
        TimeBound(1.0, True).offset(None)


def test_reply_shapes_round_trip() -> None:
    meta = FileMeta(0, 10, 20, 1.5, True, "ab" * 32)
    assert FileMeta.from_json(meta.to_json()) == meta
    latest = LatestInfo("alpha", SESSION, True, "hint", "./x", 12.0)
    assert LatestInfo.from_json(latest.to_json()) == latest
    sessions = [
        SessionInfo(f"S{i}", (FileInfo("a.alog", i, 2.0),), True, None, "a.alog", 1.0, 2.0, "v", 3)
        for i in range(3000)
    ]
    replies = sessions_to_json("alpha", sessions)
    assert len(replies) > 1
    assert all(len(r) < 400_000 for r in replies)
    assert sessions_from_json(replies) == sessions
    with pytest.raises(FormatError, match="ended before the last one"):
        sessions_from_json(replies[:-1])
    with pytest.raises(FormatError, match="not JSON"):
        FileMeta.from_json(b"{")
    with pytest.raises(FormatError, match="field 'size'"):
        FileMeta.from_json(b'{"offset":0,"length":0,"size":"x","mtime":0,"complete":true}')


def test_grep_lines_round_trip() -> None:
    items: list[GrepHeader | GrepRecord | GrepEnd] = [
        GrepHeader("S", "S.alog", 100.0, ("%%%",), 3, True),
        GrepRecord(1.25, "NAV_X", "iGPS", "d", "1.50000", 7),
        GrepRecord(2.0, "TEXT", "p:aux@shore", "s", " spaced \r\nmulti \udcff", 8),
        GrepEnd(2, 10, False, 1, True),
    ]
    data = b"".join(encode_grep_line(item) for item in items)
    assert decode_grep_lines(data) == items
    with pytest.raises(FormatError, match="neither a header"):
        decode_grep_lines(b'{"x": 1}\n')
    with pytest.raises(FormatError, match="an entry is not"):
        decode_grep_lines(b'[1, "a", "b", "q", "t", 1]\n')
