"""The .ylog: golden files rebuilt byte for byte, the line rules, parsing and round trips."""

from __future__ import annotations

from pathlib import Path

import pytest
from helpers import REFERENCE
from hypothesis import given, settings
from hypothesis import strategies as st

from fleetlog.errors import FormatError
from fleetlog.moos.alog import Banner, Variant, format_banner, format_logstart
from fleetlog.moos.ylog import (
    YlogEntry,
    format_ylog_line,
    format_ylog_value,
    parse_ylog,
    parse_ylog_line,
)

YLOGS = sorted(REFERENCE.rglob("*.ylog"))
BANNER = format_banner("./X/X.ylog", 100.0, "Thu Jan  1 00:00:00 1970", variant=Variant.EM)


def rebuild_banner(text: str, banner: Banner) -> str:
    """The banner as format_banner writes it, with the reference's variant and alignment."""
    variant = Variant.IVP
    if format_logstart(banner.logstart, Variant.EM) == banner.logstart_text:
        variant = Variant.EM
    left = text.split("\n")[3].endswith(" ")  # the LOGSTART line after a restart
    return format_banner(
        banner.log_file,
        banner.logstart,
        banner.opened,
        variant=variant,
        mark_data_type=banner.mark_data_type,
        left_logstart=left,
    )


def test_reference_ylogs_exist() -> None:
    assert len(YLOGS) >= 7


@pytest.mark.parametrize("path", YLOGS, ids=lambda p: p.name)
def test_golden_rebuilt_with_writer_functions(path: Path) -> None:
    raw = path.read_bytes()
    text = raw.decode()
    ylog = parse_ylog(text, str(path))
    assert ylog.truncated == ""
    out = rebuild_banner(text, ylog.banner)
    out += "".join(format_ylog_line(e.offset, e.key, e.source, e.text) for e in ylog.entries)
    assert out.encode() == raw


def test_parsed_reference_content() -> None:
    path = next(p for p in YLOGS if p.name == "TEST_22_11_2026_____11_06_44.ylog")
    entries = parse_ylog(path.read_text()).entries
    assert entries[0] == YlogEntry(3.747175, "MOOS_DEBUG", "iTest", "hellodebug")
    assert entries[1] == YlogEntry(3.747177, "MOOS_SYSTEM", "iTest", "3.25")
    assert entries[-1].text == "failed to process dynamic log request  - see pLogger output"


# --------------------------------------------------------------------------------------------
# Writing


def test_line_layout() -> None:
    line = format_ylog_line(1.5081412, "MOOS_DEBUG", "pHelmIvP", "pHelmIvP AllStop: clear")
    assert line == (
        "1.508141   MOOS_DEBUG           pHelmIvP             pHelmIvP AllStop: clear \n"
    )
    short = format_ylog_line(10.113441, "MOOS_DEBUG", "iTest", "after restart")
    assert short == "10.11344   MOOS_DEBUG           iTest                after restart        \n"


def test_newlines_are_removed_and_carriage_returns_kept() -> None:
    line = format_ylog_line(3.75, "MOOS_DEBUG", "iTest", "hello\ndebug\r\n")
    assert (
        line
        == "3.75       MOOS_DEBUG           iTest                hellodebug\r" + " " * 9 + " \n"
    )
    assert parse_ylog_line(line).text == "hellodebug\r"


@pytest.mark.parametrize(
    ("value", "text"),
    [
        (3.25, "3.25"),
        (1e-07, "1e-07"),
        (-0.0, "-0"),
        (123456789.0, "1.234568e+08"),
        (float("inf"), "inf"),
        (float("nan"), "nan"),
        (-float("nan"), "-nan"),
        ("a\nb", "ab"),
        ("", ""),
    ],
)
def test_values(value: float | str, text: str) -> None:
    assert format_ylog_value(value) == text
    assert format_ylog_line(0.0, "MOOS_SYSTEM", "x", value).endswith(text.ljust(20) + " \n")


def test_long_fields_push_the_next_ones() -> None:
    line = format_ylog_line(-1.234567e-05, "MOOS_DEBUG_LONGER_KEY_", "a_source_longer_than_20", "v")
    assert line == (
        "-1.234567e-05 MOOS_DEBUG_LONGER_KEY_ a_source_longer_than_20 " + "v".ljust(20) + " \n"
    )
    assert parse_ylog_line(line) == YlogEntry(
        -1.234567e-05, "MOOS_DEBUG_LONGER_KEY_", "a_source_longer_than_20", "v"
    )


def test_padding_counts_bytes_like_cpp() -> None:
    line = format_ylog_line(1.0, "MOOS_DEBUG", "src", "été")  # 5 bytes of UTF-8
    assert line.encode().endswith("été".encode() + b" " * 15 + b" \n")
    assert parse_ylog_line(line).text == "été"


def test_undecodable_bytes_count_as_one_byte() -> None:
    raw = b"bad\xff".decode("utf-8", "surrogateescape")  # as a reader would carry it
    line = format_ylog_line(1.0, "MOOS_DEBUG", "src", raw)
    assert line.encode("utf-8", "surrogateescape").endswith(b"bad\xff" + b" " * 16 + b" \n")
    assert parse_ylog_line(line).text == raw
    odd = format_ylog_line(1.0, "MOOS_DEBUG", "src", "\ud800")  # never crashes
    assert parse_ylog_line(odd).text == "\ud800"


def test_empty_source_and_value() -> None:
    line = format_ylog_line(2.0, "MOOS_DEBUG", "", "")
    assert line == "2          MOOS_DEBUG           " + " " * 20 + " " + " " * 20 + " \n"
    assert parse_ylog_line(line) == YlogEntry(2.0, "MOOS_DEBUG", "", "")


# --------------------------------------------------------------------------------------------
# Reading


def test_value_keeps_inner_and_leading_spaces() -> None:
    line = format_ylog_line(1.0, "MOOS_DEBUG", "a", "  two  spaces")
    assert parse_ylog_line(line).text == "  two  spaces"
    long = "  trailing spaces past twenty bytes   "
    assert parse_ylog_line(format_ylog_line(1.0, "MOOS_DEBUG", "a", long)).text == long


@pytest.mark.parametrize(
    ("line", "match"),
    [
        ("", "does not start with a time"),
        ("abc MOOS_DEBUG", "does not start with a time"),
        ("1.0  MOOS_DEBUG           iTest                x" + " " * 20, "time field is not padded"),
        ("1.0        MOOS_DEBUG", "ends inside its key"),
        ("1.0        MOOS_DEBUG  iTest", "key field is not padded"),
        ("1.0        " + " " * 20 + " iTest" + " " * 16 + "x" * 20 + " ", "empty key"),
        ("1.0        MOOS_DEBUG           iTest                " + "x" * 20, "terminator"),
        ("1.0        MOOS_DEBUG           iTest                short ", "5 bytes"),
    ],
)
def test_malformed_lines(line: str, match: str) -> None:
    with pytest.raises(FormatError, match=match) as info:
        parse_ylog_line(line, path="x.ylog", lineno=7)
    assert info.value.lineno == 7
    assert info.value.path == "x.ylog"


def test_file_errors_name_the_line() -> None:
    text = BANNER + format_ylog_line(1.0, "MOOS_DEBUG", "a", "ok") + "garbage\n"
    with pytest.raises(FormatError, match="time") as info:
        parse_ylog(text, "x.ylog")
    assert info.value.lineno == 7
    with pytest.raises(FormatError, match="banner"):
        parse_ylog("1.0 MOOS_DEBUG\n")


def test_truncated_last_line_is_set_aside() -> None:
    text = BANNER + format_ylog_line(1.0, "MOOS_DEBUG", "a", "ok") + "2.0        MOOS_DE"
    ylog = parse_ylog(text)
    assert ylog.entries == (YlogEntry(1.0, "MOOS_DEBUG", "a", "ok"),)
    assert ylog.truncated == "2.0        MOOS_DE"


def test_every_prefix_after_the_banner_parses() -> None:
    path = next(p for p in YLOGS if p.name == "TEST_22_11_2026_____11_06_52.ylog")
    raw = path.read_bytes()
    full = parse_ylog(raw.decode())
    banner_end = len(rebuild_banner(raw.decode(), full.banner).encode())
    for size in range(len(raw) + 1):
        text = raw[:size].decode()
        if size < banner_end:
            with pytest.raises(FormatError):
                parse_ylog(text)
            continue
        ylog = parse_ylog(text)
        assert full.entries[: len(ylog.entries)] == ylog.entries
        assert "\n" not in ylog.truncated
        assert text.endswith(ylog.truncated)
        assert len(ylog.entries) == text.count("\n") - full.banner.lines


# --------------------------------------------------------------------------------------------
# Round trips

_word = st.text(alphabet=st.characters(codec="ascii", exclude_characters=" \n\r\t"), max_size=30)


@settings(max_examples=200)
@given(
    offset=st.floats(min_value=-1e6, max_value=1e9, allow_nan=False),
    key=_word.filter(bool),
    src=_word,
    value=st.text(
        alphabet=st.characters(exclude_characters="\n", exclude_categories=["Cs"]), max_size=40
    ),
)
def test_line_round_trip(offset: float, key: str, src: str, value: str) -> None:
    line = format_ylog_line(offset, key, src, value)
    entry = parse_ylog_line(line)
    assert format_ylog_line(*entry) == line
    assert entry.offset == float(format(offset, ".7g"))
    assert entry.key == key
    assert entry.source == src
    size = len(value.encode())
    assert entry.text == (value if size > 20 else value.rstrip(" "))


@settings(max_examples=100)
@given(value=st.floats(allow_nan=False))
def test_double_value_round_trip(value: float) -> None:
    entry = parse_ylog_line(format_ylog_line(0.5, "MOOS_SYSTEM", "iTest", value))
    assert float(entry.text) == float(format(value, ".7g"))
