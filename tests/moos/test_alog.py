"""The alog format: golden round trips of the reference logs, §2.2 rules, parse-back, truncation.

The reference sessions live in ``tests/data/reference`` (copied from ../shared/reference;
MOOS_FORMAT.md §10): real pLogger output under ``captured/`` and two synthetic sessions. The
golden tests parse every alog and xlog there and write it back with the same configuration; the
bytes must be identical.
"""

from __future__ import annotations

import bisect
import gzip
import math
import re
from pathlib import Path

import pytest
from alog_oracle import EntryParser, classify_value, iter_entries
from helpers import REFERENCE
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from fleetlog.errors import FormatError
from fleetlog.moos.alog import (
    BANNER_RULE,
    Banner,
    BinaryRef,
    Entry,
    LineFormatter,
    Variant,
    format_banner,
    format_binary_ref,
    format_double,
    format_entry,
    format_logstart,
    format_time,
    parse_banner,
    parse_binary_ref,
    source_field,
    split_source,
)

LOG_SUFFIXES = (".alog", ".alog.gz", ".xlog", ".xlog.gz")
GOLDEN = (
    sorted(p for p in REFERENCE.rglob("*") if p.name.endswith(LOG_SUFFIXES) and p.is_file())
    if REFERENCE.is_dir()
    else []
)

RUN_A1 = "captured/runA_themoos_wildcard_restart/logs/TEST_22_11_2026_____11_06_44"
RUN_A2 = "captured/runA_themoos_wildcard_restart/logs/TEST_22_11_2026_____11_06_52"
RUN_B1 = "captured/runB1_ivp_compressed_markdatatype/LOG_ALPHA_22_11_2026_____11_07_42"
RUN_B2 = "captured/runB2_nofiletimestamp"
THEMOOS = "themoos_session/MOOSLog_3_2_2025_____09_05_07"
IVP = "ivp_session/LOG_ALPHA_19_6_2025_____12_04_50"

# What the golden test infers, stated here for the files whose pLogger configuration is known
# from their missions (MOOS_FORMAT.md §10): (variant, DoublePrecision, MarkDataType).
KNOWN_CONFIG = {
    f"{THEMOOS}/MOOSLog_3_2_2025_____09_05_07.alog": (Variant.EM, 3, False),
    f"{IVP}/LOG_ALPHA_19_6_2025_____12_04_50.alog": (Variant.IVP, 5, False),
    f"{RUN_A1}/TEST_22_11_2026_____11_06_44.alog": (Variant.EM, 5, False),
    f"{RUN_A2}/TEST_22_11_2026_____11_06_52.alog": (Variant.EM, 5, False),
    f"{RUN_B1}/LOG_ALPHA_22_11_2026_____11_07_42.alog.gz": (Variant.IVP, 5, True),
    f"{RUN_B2}/FIXED/FIXED.alog": (Variant.EM, 5, False),
}


def ref(relative: str) -> Path:
    return REFERENCE / relative


def read_bytes(path: Path) -> bytes:
    data = path.read_bytes()
    return gzip.decompress(data) if path.name.endswith(".gz") else data


def decode(data: bytes) -> str:
    return data.decode("utf-8", "surrogateescape")


def split_lines(text: str) -> list[str]:
    """Split at ``\\n`` only, keeping it; a last piece without ``\\n`` is kept if not empty."""
    parts = text.split("\n")
    lines = [part + "\n" for part in parts[:-1]]
    if parts[-1]:
        lines.append(parts[-1])
    return lines


def head_lines(text: str, count: int) -> list[str]:
    return [line.removesuffix("\n") for line in split_lines(text)[:count]]


_TIME_COLUMN = re.compile(r"^-?[0-9]+\.([0-9]+) ", re.M)


def infer_config(
    text: str, banner: Banner | None, entries: list[Entry]
) -> tuple[Variant, int, bool]:
    """Infer pLogger's configuration from a file: time decimals, double decimals, banner."""
    match = _TIME_COLUMN.search(text)
    if match is not None:
        variant = Variant.EM if len(match.group(1)) == 3 else Variant.IVP
        assert len(match.group(1)) == variant.time_decimals
    elif banner is not None:
        digits = len(banner.logstart_text.replace(".", "").lstrip("0"))
        variant = Variant.IVP if digits > 12 else Variant.EM
    else:
        variant = Variant.IVP  # nothing in the file depends on it
    decimals = {
        len(entry.text.partition(".")[2])
        for entry in entries
        if isinstance(entry.value, float) and math.isfinite(entry.value)
    }
    assert len(decimals) <= 1, f"doubles with different precisions: {decimals}"
    precision = decimals.pop() if decimals else 5
    mark = banner.mark_data_type if banner is not None else False
    return variant, precision, mark


def write_back(
    banner: Banner | None,
    entries: list[Entry],
    variant: Variant,
    precision: int,
    mark: bool,
) -> str:
    out: list[str] = []
    if banner is not None:
        out.append(
            format_banner(
                banner.log_file,
                banner.logstart,
                banner.opened,
                variant=variant,
                mark_data_type=mark,
            )
        )
    formatter = LineFormatter(variant, precision, mark_data_type=mark)
    for entry in entries:
        value = entry.value
        if isinstance(value, float):
            out.append(formatter.double(entry.offset, entry.key, entry.source, value))
        elif isinstance(value, str):
            out.append(formatter.string(entry.offset, entry.key, entry.source, value))
        else:
            out.append(formatter.binary(entry.offset, entry.key, entry.source, value))
    return "".join(out)


def parse_file(path: Path) -> tuple[str, Banner | None, list[Entry]]:
    text = decode(read_bytes(path))
    lines = split_lines(text)
    banner = None
    if lines and lines[0] == BANNER_RULE + "\n":
        banner = parse_banner(head_lines(text, 8), str(path))
    return text, banner, list(iter_entries(lines))


def entries_of(relative: str) -> list[Entry]:
    return parse_file(ref(relative))[2]


def first_by_key(entries: list[Entry]) -> dict[str, Entry]:
    """Each key's first entry."""
    return {e.key: e for e in reversed(entries)}


# --------------------------------------------------------------------------------------------
# Golden round trips


def test_reference_corpus_is_present() -> None:
    names = {p.relative_to(REFERENCE).as_posix() for p in GOLDEN}
    assert set(KNOWN_CONFIG) <= names
    assert {p.name.partition(".")[2] for p in GOLDEN} == {"alog", "alog.gz", "xlog", "xlog.gz"}
    assert len(GOLDEN) == 10


@pytest.mark.parametrize("path", GOLDEN, ids=lambda p: p.relative_to(REFERENCE).as_posix())
def test_golden_round_trip(path: Path) -> None:
    raw = read_bytes(path)
    text, banner, entries = parse_file(path)
    variant, precision, mark = infer_config(text, banner, entries)
    known = KNOWN_CONFIG.get(path.relative_to(REFERENCE).as_posix())
    if known is not None:
        assert (variant, precision, mark) == known
    if path.name.endswith(".xlog"):
        assert banner is None  # no banner on an uncompressed xlog (§2.5, §4.2)
    if banner is not None:
        # The LOGSTART text is the variant's %g of the value, right-justified to 20.
        assert format_logstart(banner.logstart, variant) == banner.logstart_text
    rewritten = write_back(banner, entries, variant, precision, mark)
    assert rewritten.encode("utf-8", "surrogateescape") == raw


def test_compressed_xlog_of_run_b1_is_an_empty_gzip_stream() -> None:
    path = ref(f"{RUN_B1}/LOG_ALPHA_22_11_2026_____11_07_42.xlog.gz")
    assert path.stat().st_size == 25
    assert read_bytes(path) == b""
    assert list(iter_entries([])) == []


def test_negative_times_are_read_and_written_back() -> None:
    entries = entries_of(f"{RUN_B2}/FIXED/FIXED.alog")
    assert [(e.offset, e.key, e.value) for e in entries] == [
        (-7.479, "MOOS_DEBUG", "hello\ndebug"),
        (-7.479, "MOOS_SYSTEM", 3.25),
        (-3.71, "NAV_X", 3.0),
    ]
    assert format_time(-7.479, Variant.EM) == "-7.479"


def test_restart_session_keeps_offset_minus_one_reference() -> None:
    entries = entries_of(f"{RUN_A2}/TEST_22_11_2026_____11_06_52.alog")
    refs = [e.value for e in entries if isinstance(e.value, BinaryRef)]
    assert refs == [BinaryRef("TEST_22_11_2026_____11_06_52.blog", -1, 16)]


def test_monitor_newline_artefact() -> None:
    monitor = "1 monitored variable is not being logged\n"
    for relative in (
        f"{THEMOOS}/MOOSLog_3_2_2025_____09_05_07.alog",
        f"{RUN_A2}/TEST_22_11_2026_____11_06_52.alog",
    ):
        texts = [e.text for e in entries_of(relative) if e.key == "MOOS_DEBUG"]
        assert monitor in texts
    line = LineFormatter(Variant.EM).string(10.032, "MOOS_DEBUG", "pLogger", monitor)
    assert line.endswith("not being logged\n \n")


def test_real_files_hold_duplicates_and_out_of_order_entries() -> None:
    entries = entries_of(f"{RUN_A1}/TEST_22_11_2026_____11_06_44.alog")
    keys = [(e.offset, e.key, e.source, e.text) for e in entries]
    assert len(set(keys)) < len(keys)  # re-delivered values (§2.2)
    offsets = [e.offset for e in entries]
    assert offsets != sorted(offsets)
    by_key = first_by_key(entries)
    assert by_key["MULTI"].value == "line1\nline2"
    assert by_key["EMPTY"].value == ""
    assert by_key["NEG"].value == 0.0
    assert math.copysign(1.0, by_key["NEG"].value) == -1.0
    assert by_key["NAV_HEADING"].text == "123456789.12346"
    assert by_key["DEPLOY"].source == "iTest:HELM_VAR_INIT"
    assert split_source(by_key["DEPLOY"].source) == ("iTest", "HELM_VAR_INIT", "")
    summary = next(e for e in entries if e.key == "DB_VARSUMMARY")
    assert isinstance(summary.value, str)
    assert summary.value.endswith("~  \n")  # the multi-line value ends in a newline


def test_mark_data_type_file() -> None:
    entries = entries_of(f"{RUN_B1}/LOG_ALPHA_22_11_2026_____11_07_42.alog.gz")
    by_key = first_by_key(entries)
    assert by_key["NAV_X"].value == 1.5
    assert by_key["NAV_Y"].text == "-20.00000"
    assert by_key["DEPLOY"].value == "true"
    assert by_key["EMPTY"].value == ""
    assert by_key["MOOS_DEBUG"].value == "hello\ndebug"
    assert by_key["BIN"].value == BinaryRef("LOG_ALPHA_22_11_2026_____11_07_42.blog", 53, 16)


def test_synthetic_sessions() -> None:
    themoos = first_by_key(entries_of(f"{THEMOOS}/MOOSLog_3_2_2025_____09_05_07.alog"))
    assert themoos["MISSION_STATE"].source == "pMarineViewer@shoreside"
    assert split_source("pMarineViewer@shoreside") == ("pMarineViewer", "", "shoreside")
    assert themoos["NAV_Y"].text == "-5.250"
    ivp = first_by_key(entries_of(f"{IVP}/LOG_ALPHA_19_6_2025_____12_04_50.alog"))
    assert ivp["IVPHELM_MODESET"].value == ""
    assert ivp["NAV_Z"].text == "-0.00000"
    assert ivp["DB_TIME"].value == 1750334691.85246


# --------------------------------------------------------------------------------------------
# §2.2 rules, one by one


def test_entry_columns_are_padded_on_the_right() -> None:
    line = format_entry(1.10113, "DESIRED_RUDDER", "pMarinePIDV22", format_double(0.0))
    assert line == "1.10113         DESIRED_RUDDER       pMarinePIDV22   0.00000      \n"
    assert line.index("0.00000") == 53  # 15 + 1 + 20 + 1 + 15 + 1
    assert LineFormatter().double(1.10113, "DESIRED_RUDDER", "pMarinePIDV22", 0.0) == line
    em = LineFormatter(Variant.EM, 3).double(0.702, "NAV_X", "iNav", 10.0)
    assert em == "0.702           NAV_X                iNav            10.000       \n"


def test_overflowing_fields_push_the_next_columns() -> None:
    formatter = LineFormatter()
    line = formatter.string(1.25772, "DEPLOY", "pHelmIvP:HELM_VAR_INIT", "false")
    assert line == "1.25772         DEPLOY               pHelmIvP:HELM_VAR_INIT false \n"
    long_key = "USIMMARINEV22_STATUS_LONGER"
    line = formatter.string(1234567890123.5, long_key, "uSim", "x")
    assert line == f"1234567890123.50000 {long_key} uSim            x \n"
    [entry] = iter_entries([line])
    assert (entry.offset, entry.key, entry.source, entry.value) == (
        1234567890123.5,
        long_key,
        "uSim",
        "x",
    )
    assert format_double(123456789.123456) == "123456789.12346"  # wider than 12, no padding


def test_doubles_negative_zero_tiny_and_precision() -> None:
    assert format_double(0.0) == "0.00000     "
    assert format_double(-20.0) == "-20.00000   "
    assert format_double(-0.0) == "-0.00000    "
    assert format_double(1e-7) == "0.00000     "
    assert format_double(-1e-7) == "-0.00000    "
    assert format_double(1.5, 3) == "1.500       "
    assert format_double(2.5, 0) == "2           "  # round half to even, as printf
    value, text = classify_value("-0.00000    ")
    assert text == "-0.00000"
    assert isinstance(value, float)
    assert math.copysign(1.0, value) == -1.0


def test_nan_and_infinities() -> None:
    assert format_double(math.nan) == "nan         "
    assert format_double(-math.nan) == "-nan        "
    assert format_double(math.inf) == "inf         "
    assert format_double(-math.inf) == "-inf        "
    for text in ("nan", "-nan", "inf", "-inf"):
        value, clean = classify_value(text.ljust(12))
        assert isinstance(value, float)
        assert clean == text
        assert str(value) == text.removeprefix("-") or value == -math.inf
    # Unpadded, they are strings: pLogger pads every double to 12.
    assert classify_value("nan") == ("nan", "nan")


def test_empty_string_ends_with_the_source_field_and_two_spaces() -> None:
    line = LineFormatter().string(1.25798, "IVPHELM_MODESET", "pHelmIvP", "")
    assert line == "1.25798         IVPHELM_MODESET      pHelmIvP         \n"
    assert line.endswith("pHelmIvP".ljust(15) + "  \n")
    [entry] = iter_entries([line])
    assert entry.value == ""
    assert entry.text == ""


def test_strings_are_verbatim() -> None:
    formatter = LineFormatter()
    value = "  two leading,  inner  runs, a tab\tand\r a CR  "
    line = formatter.string(0.5, "NOTE", "app", value)
    assert line.endswith(value + " \n")
    [entry] = iter_entries([line])
    assert entry.value == value
    lines = split_lines(formatter.string(0.5, "MULTI", "iTest", "line1\nline2"))
    assert lines == ["0.50000         MULTI                iTest           line1\n", "line2 \n"]
    [entry] = iter_entries(lines)
    assert entry.value == "line1\nline2"


def test_binary_has_no_trailing_space() -> None:
    ref = BinaryRef("LOG.blog", 53, 16)
    tag = format_binary_ref(ref.file, ref.offset, ref.size)
    assert tag == "<MOOS_BINARY>File=LOG.blog,Offset=53,Bytes=16</MOOS_BINARY>"
    line = LineFormatter().binary(3.74691, "BIN", "iTest", ref)
    assert line.endswith("</MOOS_BINARY>\n")
    assert format_entry(3.74691, "BIN", "iTest", tag, binary=True) == line
    assert LineFormatter().prefix(3.74691, "BIN", "iTest") == line[:53]
    [entry] = iter_entries([line])
    assert entry.value == ref
    assert parse_binary_ref(tag) == ref
    assert parse_binary_ref(tag.replace("53", "-1")) == BinaryRef("LOG.blog", -1, 16)
    assert parse_binary_ref(tag + " ") is None


def test_string_that_looks_like_a_binary_reference_stays_a_string() -> None:
    # A string keeps its terminator space; pLogger writes a binary reference without one.
    tag = format_binary_ref("x.blog", 1, 2)
    [entry] = iter_entries([LineFormatter().string(1.0, "FAKE", "app", tag)])
    assert entry.value == tag
    assert classify_value(tag, binary=False) == (tag, tag)


def test_mark_data_type_prefixes() -> None:
    formatter = LineFormatter(mark_data_type=True)
    assert formatter.double(3.74687, "NAV_X", "iTest", 1.5).endswith(" D:1.50000      \n")
    assert formatter.string(3.7469, "DEPLOY", "iTest", "true").endswith(" S:true \n")
    assert formatter.string(3.7469, "EMPTY", "iTest", "").endswith("iTest           S: \n")
    binary = formatter.binary(3.74691, "BIN", "iTest", BinaryRef("a.blog", 53, 16))
    assert binary.endswith(
        "iTest           <MOOS_BINARY>File=a.blog,Offset=53,Bytes=16</MOOS_BINARY>\n"
    )
    assert classify_value("D:1.50000     ", mark_data_type=True) == (1.5, "1.50000")
    assert classify_value("S:1.50000     ", mark_data_type=True) == ("1.50000     ",) * 2
    assert classify_value("S:", mark_data_type=True) == ("", "")


def test_log_aux_src_and_community_marking() -> None:
    assert source_field("pHelmIvP", "HELM_VAR_INIT", log_aux=True) == "pHelmIvP:HELM_VAR_INIT"
    assert source_field("pHelmIvP", "HELM_VAR_INIT") == "pHelmIvP"  # LogAuxSrc=false
    assert source_field("pHelmIvP", "", log_aux=True) == "pHelmIvP"  # empty aux: no colon
    assert (
        source_field("pMarineViewer", community="shoreside", mark_external=True, own_community="a")
        == "pMarineViewer@shoreside"
    )
    # Local traffic carries the DB's own community and is never marked.
    assert (
        source_field("pNav", community="alpha", mark_external=True, own_community="alpha") == "pNav"
    )
    assert source_field("pNav", community="shoreside", own_community="alpha") == "pNav"
    both = source_field(
        "pHelm", "AUX", "shore", log_aux=True, mark_external=True, own_community="alpha"
    )
    assert both == "pHelm:AUX@shore"
    assert split_source(both) == ("pHelm", "AUX", "shore")
    assert split_source("iTest") == ("iTest", "", "")
    # The aux is split at the first ':' (as the IvP tools do), the community at the last '@'.
    assert split_source("a:b:c@x@y") == ("a", "b:c@x", "y")


def test_banner_em_variant_matches_real_file() -> None:
    path = ref(f"{RUN_A1}/TEST_22_11_2026_____11_06_44.alog")
    head = decode(path.read_bytes())[: len(format_banner("", 0.0, ""))]
    expected = format_banner(
        "/home/alpha/mission/logs/TEST_22_11_2026_____11_06_44/TEST_22_11_2026_____11_06_44.alog",
        1795345603.40,
        "Thu Jan  1 00:00:00 1970",
        variant=Variant.EM,
    )
    assert format_logstart(1795345603.40, Variant.EM) == "1795345603.4"
    assert format_logstart(1738573507.264815, Variant.EM) == "1738573507.26"
    assert "%% LOGSTART                1795345603.4\n" in expected
    assert decode(path.read_bytes()).startswith(expected)
    assert len(head) < len(expected)  # the real paths are longer than the empty one
    banner = parse_banner(head_lines(expected, 5))
    assert banner == Banner(
        "/home/alpha/mission/logs/TEST_22_11_2026_____11_06_44/TEST_22_11_2026_____11_06_44.alog",
        "Thu Jan  1 00:00:00 1970",
        1795345603.4,
        "1795345603.4",
        False,
        5,
    )


def test_banner_ivp_variant_matches_real_files() -> None:
    expected = format_banner(
        "./LOG_ALPHA_19_6_2025_____12_04_50/LOG_ALPHA_19_6_2025_____12_04_50.alog",
        1750334690.048564,
        "Thu Jan  1 00:00:00 1970",
    )
    assert format_logstart(1750334690.048564) == "1750334690.048564"
    assert "%% LOGSTART           1750334690.048564\n" in expected
    path = ref(f"{IVP}/LOG_ALPHA_19_6_2025_____12_04_50.alog")
    assert decode(path.read_bytes()).startswith(expected)
    marked = format_banner(
        "./LOG_ALPHA_22_11_2026_____11_07_42/LOG_ALPHA_22_11_2026_____11_07_42.alog",
        1795345661.900295,
        "Wed Dec 31 19:00:00 1969",
        mark_data_type=True,
    )
    assert marked.splitlines()[4] == "%% DATATYPE MARKING ON"
    gz = ref(f"{RUN_B1}/LOG_ALPHA_22_11_2026_____11_07_42.alog.gz")
    assert decode(read_bytes(gz)).startswith(marked)
    assert parse_banner(head_lines(marked, 6)).mark_data_type


def test_banner_left_justified_logstart_after_restart() -> None:
    # pLogger's slog and ylog streams keep ios::left after a LOGGER_RESTART (§2.1).
    ylog = ref(f"{RUN_A2}/TEST_22_11_2026_____11_06_52.ylog")
    text = decode(ylog.read_bytes())
    banner = parse_banner(head_lines(text, 5), str(ylog))
    expected = format_banner(
        banner.log_file, banner.logstart, banner.opened, variant=Variant.EM, left_logstart=True
    )
    assert "%% LOGSTART        1795345603.4        \n" in expected
    assert text.startswith(expected)


@pytest.mark.parametrize(
    ("lines", "lineno", "match"),
    [
        ([], 1, "empty"),
        (["%%%% short rule"], 1, "banner line of 59"),
        ([BANNER_RULE, "%% LOG FILE:       x", BANNER_RULE], 3, "no LOGSTART"),
        ([BANNER_RULE, "%% LOGSTART        soon", BANNER_RULE], 3, "not a number"),
        ([BANNER_RULE, "%% LOGSTART        1.5", "0.1 X y z "], 3, "ends before its closing"),
        ([BANNER_RULE, "%% LOGSTART        1.5"], 2, "not closed"),
    ],
)
def test_parse_banner_errors_name_file_and_line(lines: list[str], lineno: int, match: str) -> None:
    with pytest.raises(FormatError, match=match) as info:
        parse_banner(lines, "x.alog")
    assert info.value.path == "x.alog"
    assert info.value.lineno == lineno
    assert str(info.value).startswith(f"x.alog:{lineno}: ")


def test_double_looking_values_must_be_padded_like_pLogger() -> None:
    assert classify_value("1.50000     ") == (1.5, "1.50000")  # a padded double
    assert classify_value("123456789.12346") == (123456789.12346, "123456789.12346")
    # pLogger pads doubles to 12, so these unpadded or oddly padded numbers are strings.
    for text in ("0.5", "3", "1.50000      ", " 1.5        ", "1e5         ", "1.5 "):
        assert classify_value(text) == (text, text)


def test_without_mark_data_type_a_padded_number_string_reads_back_as_a_double() -> None:
    # The inherent ambiguity of the format (§12): without MarkDataType nothing tells the
    # string "1.50000" + 5 spaces from the double 1.5. It reads back as a double; the text,
    # and so the bytes written back, are the same. MarkDataType removes the ambiguity.
    text = "1.50000".ljust(12)
    [entry] = iter_entries([LineFormatter().string(1.0, "S", "app", text)])
    assert entry.value == 1.5
    assert LineFormatter().double(1.0, "S", "app", 1.5) == LineFormatter().string(
        1.0, "S", "app", text
    )
    [entry] = iter_entries(
        [LineFormatter(mark_data_type=True).string(1.0, "S", "app", text)], mark_data_type=True
    )
    assert entry.value == text


def test_entry_parser_counts_orphans_and_dropped() -> None:
    parser = EntryParser()
    assert parser.feed("continuation before any entry", 1) is None
    assert parser.orphans == 1
    assert parser.feed("0.5             K                    s               hello", 2) is None
    assert parser.close() is None  # no terminator: cut inside a multi-line value
    assert parser.dropped == 1
    line = "0.5             K                    s               v \n"
    # A cut line that starts an entry proves the one before whole; it is not counted.
    parser = EntryParser()
    assert [e.value for e in iter_entries([line, "1.0   K2 s cut"], parser=parser)] == ["v"]
    assert parser.dropped == 0
    # A cut continuation line leaves the value unknown: the entry is dropped and counted.
    parser = EntryParser()
    assert list(iter_entries([line, "more"], parser=parser)) == []
    assert parser.dropped == 1


def test_iter_entries_empty_cut_line_marks_a_cut_at_a_line_boundary() -> None:
    lines = split_lines(LineFormatter().string(1.0, "K", "s", "first ") + "")
    assert [e.value for e in iter_entries(lines)] == ["first "]
    assert list(iter_entries([*lines, ""])) == []  # it may have had continuation lines
    two = lines + split_lines(LineFormatter().string(2.0, "K", "s", "second"))
    assert [e.value for e in iter_entries([*two, ""])] == ["first "]


# --------------------------------------------------------------------------------------------
# Parse-back property

_NOT_NEWLINE = st.characters(blacklist_characters="\n")
_CHARS = st.one_of(st.sampled_from(" \r\t0-%.:D<>"), _NOT_NEWLINE)
_NAME = st.text(
    st.characters(blacklist_categories=("Cs", "Zs", "Zl", "Zp", "Cc")), min_size=1, max_size=24
)
_DOUBLE_TEXT = re.compile(r"-?[0-9]+(?:\.[0-9]+)?|-?nan|-?inf")


def _continues(line: str) -> bool:
    """A continuation line cannot start like an entry (a digit, '-') or a comment ('%')."""
    return not line or line[0] not in "0123456789-%"


_STRINGS = (
    st.lists(st.text(_CHARS, max_size=20), min_size=1, max_size=4)
    .filter(lambda parts: all(_continues(part) for part in parts[1:]))
    .map("\n".join)
)
_BINARY = st.builds(
    BinaryRef,
    st.from_regex(r"[A-Za-z0-9_.]{1,30}", fullmatch=True),
    st.integers(-1, 2**40),
    st.integers(0, 2**31),
)
_VALUES = st.one_of(st.floats(), _STRINGS, _BINARY)


def looks_like_padded_double(text: str) -> bool:
    body = text.rstrip(" ")
    return bool(_DOUBLE_TEXT.fullmatch(body)) and len(text) == max(12, len(body))


@settings(max_examples=300, deadline=None)
@given(
    variant=st.sampled_from(Variant),
    precision=st.integers(0, 8),
    mark=st.booleans(),
    items=st.lists(
        st.tuples(
            st.floats(0, 1e9),
            _NAME,
            st.one_of(st.just(""), _NAME),
            _VALUES,
        ),
        min_size=1,
        max_size=8,
    ),
)
def test_formatted_entries_parse_back(
    variant: Variant,
    precision: int,
    mark: bool,
    items: list[tuple[float, str, str, float | str | BinaryRef]],
) -> None:
    formatter = LineFormatter(variant, precision, mark_data_type=mark)
    text = ""
    for offset, key, source, value in items:
        if isinstance(value, float):
            text += formatter.double(offset, key, source, value)
        elif isinstance(value, str):
            # Documented ambiguity, tested on its own above.
            assume(mark or not looks_like_padded_double(value))
            text += formatter.string(offset, key, source, value)
        else:
            text += formatter.binary(offset, key, source, value)
    entries = list(iter_entries(split_lines(text), mark_data_type=mark))
    assert len(entries) == len(items)
    for entry, (offset, key, source, value) in zip(entries, items, strict=True):
        assert entry.offset == float(format_time(offset, variant))
        assert (entry.key, entry.source) == (key, source)
        assert type(entry.value) is type(value)
        if isinstance(value, float):
            written = format_double(value, precision).rstrip(" ")
            assert entry.text == written
            assert isinstance(entry.value, float)
            if math.isnan(value):
                assert math.isnan(entry.value)
            else:
                assert entry.value == float(written)
        elif isinstance(value, str):
            assert entry.value == value
            assert entry.text == value
        else:
            assert entry.value == value
            assert entry.text == format_binary_ref(value.file, value.offset, value.size)


# --------------------------------------------------------------------------------------------
# Every-prefix truncation


def prefix_lines(text: str, lines: list[str], starts: list[int], n: int) -> list[str]:
    """The lines of ``text[:n]``, built from the whole text's lines (ASCII text)."""
    index = bisect.bisect_right(starts, n) - 1
    out = lines[:index]
    if n > starts[index]:
        out.append(text[starts[index] : n])
    return out


def check_prefix(full: list[Entry], lines: list[str], cut_at_newline: bool) -> bool:
    """Check one prefix; return whether it hit the line-boundary ambiguity."""
    got = list(iter_entries(lines))
    count = len(got)
    assert count <= len(full)
    assert got[: max(count - 1, 0)] == full[: max(count - 1, 0)]
    ambiguous = False
    if got and got[-1] != full[count - 1]:
        # The one thing a reader cannot know: text cut right after a newline inside a
        # multi-line value whose line happened to end in a space (DB_VARSUMMARY's lines end
        # in "~  " or "S  ") reads like a whole file whose last value is shorter.
        last, whole = got[-1], full[count - 1]
        assert cut_at_newline
        assert (last.offset, last.key, last.source, last.lineno) == (
            whole.offset,
            whole.key,
            whole.source,
            whole.lineno,
        )
        assert whole.text.startswith(last.text + " \n")
        ambiguous = True
    # Told that the text was cut (an empty cut line, what the storage reader passes for a
    # truncated stream), the parser never yields a value cut short.
    marked = list(iter_entries([*lines, ""]))
    assert marked == full[: len(marked)]
    return ambiguous


def run_prefixes(path: Path, cuts: list[int]) -> int:
    text = decode(read_bytes(path))
    assert text.isascii()
    lines = split_lines(text)
    starts = [0]
    for line in lines:
        starts.append(starts[-1] + len(line))
    full = list(iter_entries(lines))
    ambiguous = 0
    for n in cuts:
        ambiguous += check_prefix(
            full, prefix_lines(text, lines, starts, n), n > 0 and text[n - 1] == "\n"
        )
    return ambiguous


@pytest.mark.parametrize(
    "relative",
    [
        f"{RUN_B1}/LOG_ALPHA_22_11_2026_____11_07_42.alog.gz",
        f"{RUN_B2}/FIXED/FIXED.alog",
        f"{THEMOOS}/MOOSLog_3_2_2025_____09_05_07.alog",
    ],
)
def test_every_byte_prefix_yields_a_prefix_of_the_entries(relative: str) -> None:
    path = ref(relative)
    size = len(read_bytes(path))
    # These files' multi-line values have no line ending in a space: no ambiguity at all.
    assert run_prefixes(path, list(range(size + 1))) == 0


def test_prefixes_of_a_long_real_file_and_the_line_boundary_ambiguity() -> None:
    path = ref(f"{RUN_A1}/TEST_22_11_2026_____11_06_44.alog")
    text = decode(read_bytes(path))
    # Every byte of the first 7000 (banner, DB_VARSUMMARY blocks, MULTI, EMPTY, BIN, NEG),
    # then every line boundary with its neighbours and every 11th byte.
    newlines = [i + 1 for i, c in enumerate(text) if c == "\n"]
    cuts = set(range(7001))
    cuts.update(range(7001, len(text) + 1, 11))
    for n in newlines:
        cuts.update((n - 1, n, n + 1))
    cuts = {n for n in cuts if n <= len(text)}
    ambiguous = run_prefixes(path, sorted(cuts))
    # The ambiguity is real in this file: each DB_VARSUMMARY line ending in spaces.
    assert ambiguous > 0
