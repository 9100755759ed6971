"""The .slog: golden files rebuilt byte for byte, layout rules, SlogTable state, parser errors."""

from __future__ import annotations

import ctypes
import ctypes.util
import math
import random
import struct
from pathlib import Path

import pytest
from helpers import REFERENCE
from hypothesis import given, settings
from hypothesis import strategies as st

from fleetlog.errors import FormatError
from fleetlog.moos.alog import Banner, Variant, format_banner, format_logstart
from fleetlog.moos.slog import (
    HEADER_RULE,
    SlogTable,
    claim_slot,
    dynamic_names,
    format_label_block,
    format_row,
    format_slog_header,
    format_slog_value,
    slot_offsets,
)
from fleetlog.moos.slog_read import SlogLabels, SlogRow, parse_row, parse_slog

SLOGS = sorted(REFERENCE.rglob("*.slog"))
RUN_A = REFERENCE / "captured" / "runA_themoos_wildcard_restart" / "logs"
RUN_A_1 = RUN_A / "TEST_22_11_2026_____11_06_44" / "TEST_22_11_2026_____11_06_44.slog"
RUN_A_2 = RUN_A / "TEST_22_11_2026_____11_06_52" / "TEST_22_11_2026_____11_06_52.slog"
THEMOOS = (
    REFERENCE
    / "themoos_session"
    / "MOOSLog_3_2_2025_____09_05_07"
    / "MOOSLog_3_2_2025_____09_05_07.slog"
)

BANNER = format_banner("./X/X.slog", 100.0, "Thu Jan  1 00:00:00 1970", variant=Variant.EM)


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


def patch(buffer: bytearray, offset: int, data: bytes) -> None:
    buffer[offset : offset + len(data)] = data


# --------------------------------------------------------------------------------------------
# Golden files


def test_reference_slogs_exist() -> None:
    assert len(SLOGS) >= 3
    assert RUN_A_1 in SLOGS
    assert RUN_A_2 in SLOGS
    assert THEMOOS in SLOGS


@pytest.mark.parametrize("path", SLOGS, ids=lambda p: p.name)
def test_golden_rebuilt_with_writer_functions(path: Path) -> None:
    raw = path.read_bytes()
    text = raw.decode()
    slog = parse_slog(text, str(path))
    assert slog.truncated == ""
    banner = rebuild_banner(text, slog.banner)

    # The header as first written: the slots still held their placeholder names, which the
    # label block written right after the header lists last.
    slots = [c for c in slog.columns if c.slot]
    static = [c.name for c in slog.columns if not c.slot]
    first = slog.records[0]
    assert isinstance(first, SlogLabels)
    placeholders = list(first.names[len(first.names) - len(slots) :])
    assert all(name.startswith("DYNAMIC_") for name in placeholders)
    out = bytearray((banner + format_slog_header(static, placeholders)).encode())
    assert len(banner.encode()) == slog.header_offset

    base = len(banner.encode())
    for column, offset in zip(slots, slot_offsets(static, placeholders), strict=True):
        assert base + offset == column.offset
        if column.claimed:
            claim = claim_slot(base + offset, column.name)
            patch(out, claim.offset, claim.data)

    for record in slog.records:
        if isinstance(record, SlogRow):
            out += format_row(record.offset, record.values).encode()
        else:
            assert record.offset is not None
            out += format_label_block(record.names, record.offset).encode()
    assert bytes(out) == raw


def replay(table: SlogTable, path: Path, *, restart: bool = False) -> bytes:
    """Drive a SlogTable with the events a reference slog records; return the file it writes.

    Rows become updates (one per non-NaN value) and a row; a label block that the row cadence
    does not explain is a claim (the new name is the one the block adds).
    """
    text = path.read_text()
    slog = parse_slog(text)
    records = list(slog.records)
    first = records[0]
    assert isinstance(first, SlogLabels)
    assert first.offset is not None
    banner = rebuild_banner(text, slog.banner)
    start = table.restart(banner, first.offset) if restart else table.start(banner, first.offset)
    buffer = bytearray(start.encode())
    index = 1
    while index < len(records):
        record = records[index]
        if isinstance(record, SlogRow):
            for name, value in zip(table.names, record.values, strict=True):
                if value is not None:
                    table.update(name, value)
            label_offset = None
            if table.rows % 30 == 0:
                label = records[index + 1]
                assert isinstance(label, SlogLabels)
                label_offset = label.offset
                index += 1
            buffer += table.row(record.offset, label_offset).encode()
        else:
            new = [name for name in record.names if name not in table.names]
            assert len(new) == 1
            assert record.offset is not None
            claim = table.claim(new[0], record.offset)
            assert claim is not None
            assert claim.patch is not None
            patch(buffer, claim.patch.offset, claim.patch.data)
            buffer += claim.text.encode()
        index += 1
    return bytes(buffer)


def test_golden_table_replays_run_a_across_the_restart() -> None:
    first = parse_slog(RUN_A_1.read_text())
    static = [c.name for c in first.columns if not c.slot]
    table = SlogTable(static, dynamic_slots=sum(c.slot for c in first.columns))
    assert replay(table, RUN_A_1) == RUN_A_1.read_bytes()
    assert table.rows == 16
    # LOGGER_RESTART: the claimed NAV_SPEED becomes a static header line, DYNAMIC_1 stays a
    # slot, and the row counter carries on (the label block after row 31 is in session 2).
    assert replay(table, RUN_A_2, restart=True) == RUN_A_2.read_bytes()
    assert table.columns[-1] == "NAV_SPEED"
    assert table.placeholders == ("DYNAMIC_1",)


def test_golden_table_replays_themoos_session() -> None:
    table = SlogTable(["NAV_X", "NAV_Y", "NAV_HEADING"], dynamic_slots=2)
    assert replay(table, THEMOOS) == THEMOOS.read_bytes()


def test_parsed_reference_content() -> None:
    slog = parse_slog(RUN_A_1.read_text(), str(RUN_A_1))
    assert [c.name for c in slog.columns] == [
        "NAV_X",
        "NAV_Y",
        "NAV_HEADING",
        "TINY",
        "NEG",
        "NAV_SPEED",
        "DYNAMIC_1",
    ]
    assert [c.number for c in slog.columns] == [2, 3, 4, 5, 6, 7, 8]
    assert [(c.slot, c.claimed) for c in slog.columns[-2:]] == [(True, True), (True, False)]
    raw = RUN_A_1.read_bytes()
    assert raw[slog.columns[-1].offset :].startswith(b"DYNAMIC_1 ")
    assert raw[slog.columns[-2].offset :].startswith(b"NAV_SPEED ")
    labels = slog.labels
    assert [label.time_text for label in labels] == ["   0.65", "   0.76", "   5.16"]
    assert labels[2].names[-2:] == ("NAV_SPEED", "DYNAMIC_1")
    row = slog.rows[6]
    assert row.offset == 3.836231
    assert row.values[:5] == (1.5, -20.0, 123457000.0, 1e-07, -0.0)
    negative_zero = row.values[4]
    assert negative_zero is not None
    assert math.copysign(1.0, negative_zero) == -1.0
    assert row.values[5:] == (None, None)
    second = parse_slog(RUN_A_2.read_text())
    assert [(c.name, c.slot) for c in second.columns[-2:]] == [
        ("NAV_SPEED", False),
        ("DYNAMIC_1", True),
    ]


# --------------------------------------------------------------------------------------------
# Layout


def test_header_layout() -> None:
    header = format_slog_header(["NAV_X", "NAV_Y"], 2)
    lines = header.split("\n")
    assert lines[0] == "%%   (1) TIME "
    assert lines[1] == "%%   (2) NAV_X"
    assert lines[2] == "%%   (3) NAV_Y"
    assert lines[3] == "%%   (4) " + "DYNAMIC_0".ljust(64)
    assert lines[4] == "%%   (5) " + "DYNAMIC_1".ljust(64)
    assert lines[5] == "%" * 56 == HEADER_RULE
    assert lines[6] == ""
    assert format_slog_header(["A"], ["DYNAMIC_3"]) == (
        "%%   (1) TIME \n%%   (2) A\n%%   (3) " + "DYNAMIC_3".ljust(64) + "\n" + "%" * 56 + "\n"
    )
    assert dynamic_names(2, start=3) == ["DYNAMIC_3", "DYNAMIC_4"]


def test_slot_offsets_point_at_placeholder_names() -> None:
    static = [f"V{i}" for i in range(12)]  # pushes the slot numbers to two digits
    header = format_slog_header(static, 3).encode()
    offsets = slot_offsets(static, 3)
    assert len(offsets) == 3
    for i, offset in enumerate(offsets):
        assert header[offset : offset + 64] == f"DYNAMIC_{i}".ljust(64).encode()
        assert header[offset - 5 : offset] == f"({14 + i}) ".encode()
    assert slot_offsets(["A"], 0) == ()


def test_claim_keeps_the_64th_byte_and_newline() -> None:
    header = bytearray(format_slog_header(["A"], 2).encode())
    size = len(header)
    first, second = slot_offsets(["A"], 2)
    claim = claim_slot(first, "NAV_SPEED")
    assert claim.offset == first
    assert claim.data == b"NAV_SPEED".ljust(63)
    patch(header, claim.offset, claim.data)
    assert len(header) == size
    lines = header.decode().split("\n")
    assert lines[2] == "%%   (3) " + "NAV_SPEED".ljust(64)
    assert lines[3] == "%%   (4) " + "DYNAMIC_1".ljust(64)
    exact = claim_slot(second, "N" * 63)
    patch(header, exact.offset, exact.data)
    assert header.decode().split("\n")[3] == "%%   (4) " + "N" * 63 + " "


def test_claim_with_long_name_overwrites_following_bytes() -> None:
    header = bytearray(format_slog_header(["A"], 2).encode())
    first, _ = slot_offsets(["A"], 2)
    name = "L" * 70
    claim = claim_slot(first, name)
    assert claim.data == name.encode()  # not truncated
    patch(header, claim.offset, claim.data)
    lines = header.decode().split("\n")
    # The slot's space and newline and the next line's first 5 bytes are gone, as in pLogger.
    assert lines[2] == "%%   (3) " + name + "(4) " + "DYNAMIC_1".ljust(64)


def test_label_block_layout() -> None:
    block = format_label_block(["NAV_X", "DYNAMIC_0"], 0.654)
    assert block == (
        "%% TIME            NAV_X              DYNAMIC_0          \n"
        "%% TIME            [   0.65]          [   0.65]          \n"
    )
    wide = format_label_block(["A" * 20], 1234.5)
    assert wide == f"%% TIME            {'A' * 20} \n%% TIME            [1234.50]          \n"
    assert format_label_block([], 1.0) == "%% TIME            \n%% TIME            \n"


def test_row_layout() -> None:
    row = format_row(0.8137105, [10.0, -5.25, None])
    assert row == (
        "0.8137105".ljust(18)
        + " "
        + "10".ljust(18)
        + " "
        + "-5.25".ljust(18)
        + " "
        + "NaN".ljust(18)
        + " \n"
    )
    assert format_row(10.83372, []) == "10.83372           \n"
    assert format_row(1234567.89, [])[:8] == "1234568 "


@pytest.mark.parametrize(
    ("value", "text"),
    [
        (-0.0, "-0"),
        (0.0, "0"),
        (1e-07, "1e-07"),
        (123456789.0, "1.23457e+08"),
        (11.99994, "11.9999"),
        (0.0001, "0.0001"),
        (1e-05, "1e-05"),
        (1e16, "1e+16"),
        (float("inf"), "inf"),
        (float("-inf"), "-inf"),
        (float("nan"), "nan"),
        (-float("nan"), "-nan"),
    ],
)
def test_value_format_matches_cpp(value: float, text: str) -> None:
    assert format_slog_value(value) == text
    assert format_row(0.0, [value]) == "0".ljust(18) + " " + text.ljust(18) + " \n"


def test_time_format_is_seven_digits() -> None:
    assert format_slog_value(0.75562291, 7) == "0.7556229"
    assert format_slog_value(19.82450001, 7) == "19.8245"
    assert format_slog_value(1e-07, 7) == "1e-07"


def _libc_snprintf() -> ctypes.CDLL | None:
    name = ctypes.util.find_library("c")
    if name is None:
        return None
    try:
        return ctypes.CDLL(name)
    except OSError:
        return None


def test_g_formats_match_libc_printf() -> None:
    libc = _libc_snprintf()
    if libc is None:
        pytest.skip("no C library to compare with")
    buffer = ctypes.create_string_buffer(64)
    rng = random.Random(20250203)
    values = [0.0, -0.0, 1e-7, 123456789.0, 5e-324, 1.7976931348623157e308, 9.9999995, 999999.5]
    values += [float("inf"), float("-inf"), float("nan"), -float("nan")]
    for _ in range(2000):
        values.append(struct.unpack("<d", rng.getrandbits(64).to_bytes(8, "little"))[0])
        values.append(round(rng.uniform(-1e4, 1e4), rng.randint(0, 8)))
    for value in values:
        for digits in (6, 7):
            libc.snprintf(buffer, 64, f"%.{digits}g".encode(), ctypes.c_double(value))
            assert format_slog_value(value, digits) == buffer.value.decode(), value
        if math.isfinite(value) and abs(value) < 1e12:
            libc.snprintf(buffer, 64, b"[%7.2f]", ctypes.c_double(value))
            assert format_label_block(["X"], value).split("\n")[1][19:].rstrip() == (
                buffer.value.decode()
            )


# --------------------------------------------------------------------------------------------
# SlogTable


def test_start_writes_banner_header_and_label_block() -> None:
    table = SlogTable(["NAV_X"], dynamic_slots=1)
    text = table.start(BANNER, 0.61)
    assert text == (
        BANNER + format_slog_header(["NAV_X"], 1) + format_label_block(["NAV_X", "DYNAMIC_0"], 0.61)
    )
    assert table.names == ("NAV_X", "DYNAMIC_0")


def test_label_block_after_rows_1_31_61() -> None:
    table = SlogTable(["A"])
    table.start(BANNER, 0.0)
    labelled = []
    for n in range(1, 92):
        text = table.row(float(n))
        assert text.startswith(format_row(float(n), [None]))
        if "%% TIME" in text:
            assert text == format_row(float(n), [None]) + format_label_block(["A"], float(n))
            labelled.append(n)
    assert labelled == [1, 31, 61, 91]
    assert table.rows == 91


def test_label_offset_can_differ_from_row_time() -> None:
    table = SlogTable(["A"])
    text = table.row(0.7556229, label_offset=0.7649)
    assert text.endswith(format_label_block(["A"], 0.7649))


def test_values_are_shown_once_then_stale() -> None:
    table = SlogTable(["A", "B"])
    table.row(0.0)
    table.update("A", 1.5)
    assert table.row(1.0) == format_row(1.0, [1.5, None])
    assert table.row(2.0) == format_row(2.0, [None, None])


def test_strings_make_nan() -> None:
    table = SlogTable(["A", "B"])
    table.row(0.0)
    table.update("A", "hello")
    table.update("B", 2.0)
    assert table.row(1.0) == format_row(1.0, [None, 2.0])


def test_newest_value_since_last_row_is_shown() -> None:
    table = SlogTable(["A"])
    table.row(0.0)
    table.update("A", 1.0)
    table.update("A", 2.0)
    assert table.row(1.0) == format_row(1.0, [2.0])
    table.update("A", 3.0)
    table.update("A", "text")  # the newest sample is a string
    assert table.row(2.0) == format_row(2.0, [None])
    table.update("A", "text")
    table.update("A", 4)  # an int is a double
    assert table.row(3.0) == format_row(3.0, [4.0])


def test_unknown_variables_are_ignored() -> None:
    table = SlogTable(["A"], dynamic_slots=1)
    table.start(BANNER, 0.0)
    table.update("DYNAMIC_0", 1.0)
    table.update("OTHER", 1.0)
    table.row(0.5)
    table.update("LATER", 5.0)  # before its claim: not a column yet
    claim = table.claim("LATER", 0.6)
    assert claim is not None
    assert table.row(1.0) == format_row(1.0, [None, None])


def test_claim_renames_the_first_placeholder_in_place() -> None:
    table = SlogTable(["NAV_X"], dynamic_slots=2)
    file = bytearray(table.start(BANNER, 0.61).encode())
    size = len(file)
    claim = table.claim("NAV_SPEED", 2.42)
    assert claim is not None
    assert claim.patch is not None
    assert file[claim.patch.offset : claim.patch.offset + 64] == b"DYNAMIC_0".ljust(64)
    patch(file, claim.patch.offset, claim.patch.data)
    assert len(file) == size
    assert claim.text == format_label_block(["NAV_X", "NAV_SPEED", "DYNAMIC_1"], 2.42)
    assert table.columns == ("NAV_X", "NAV_SPEED")
    assert table.placeholders == ("DYNAMIC_1",)
    header = file.decode().split("\n")
    assert header[7] == "%%   (3) " + "NAV_SPEED".ljust(64)
    table.update("NAV_SPEED", 1.5)
    assert table.row(2.8) == format_row(2.8, [None, 1.5, None]) + format_label_block(
        ["NAV_X", "NAV_SPEED", "DYNAMIC_1"], 2.8
    )
    second = table.claim("DEPTH", 3.0)
    assert second is not None
    assert second.patch is not None
    assert file[second.patch.offset : second.patch.offset + 64] == b"DYNAMIC_1".ljust(64)


def test_nosync_request_does_not_consume_a_placeholder() -> None:
    table = SlogTable(["NAV_X"], dynamic_slots=1)
    table.start(BANNER, 0.0)
    claim = table.claim("QUIET", 1.0, nosync=True)
    assert claim is not None
    assert claim.patch is None
    assert claim.text == format_label_block(["NAV_X", "DYNAMIC_0"], 1.0)
    assert table.placeholders == ("DYNAMIC_0",)
    table.update("QUIET", 3.0)
    assert table.row(1.5) == format_row(1.5, [None, None]) + format_label_block(
        ["NAV_X", "DYNAMIC_0"], 1.5
    )
    loud = table.claim("LOUD", 2.0)
    assert loud is not None
    assert loud.patch is not None
    assert table.columns == ("NAV_X", "LOUD")


def test_claim_without_free_placeholder_adds_only_a_label_block() -> None:
    table = SlogTable(["A"])
    table.start(BANNER, 0.0)
    claim = table.claim("B", 1.0)
    assert claim is not None
    assert claim.patch is None
    assert claim.text == format_label_block(["A"], 1.0)
    assert table.columns == ("A",)


def test_claim_of_an_existing_column_changes_nothing() -> None:
    table = SlogTable(["A"], dynamic_slots=1)
    table.start(BANNER, 0.0)
    assert table.claim("A", 1.0) is None
    assert table.placeholders == ("DYNAMIC_0",)


def test_claim_before_start_is_an_error() -> None:
    table = SlogTable(["A"], dynamic_slots=1)
    with pytest.raises(RuntimeError, match="start"):
        table.claim("B", 1.0)


def test_long_claimed_name_overwrites_like_plogger() -> None:
    table = SlogTable([], dynamic_slots=2)
    table.start(BANNER, 0.0)
    claim = table.claim("X" * 70, 1.0)
    assert claim is not None
    assert claim.patch is not None
    assert claim.patch.data == b"X" * 70


def test_restart_lists_claimed_columns_as_static_and_keeps_the_counter() -> None:
    table = SlogTable(["A"], dynamic_slots=2)
    table.start(BANNER, 0.0)
    for n in range(20):
        table.row(float(n))
    table.claim("B", 20.5)
    longer = format_banner("./LONGER_NAME/LONGER_NAME.slog", 100.0, "Thu Jan  1 00:00:00 1970")
    text = table.restart(longer, 21.0)
    assert text == (
        longer
        + format_slog_header(["A", "B"], ["DYNAMIC_1"])
        + format_label_block(["A", "B", "DYNAMIC_1"], 21.0)
    )
    rows = [table.row(float(n)) for n in range(21, 32)]
    assert "%% TIME" not in "".join(rows[:-1])
    assert rows[-1].endswith(format_label_block(["A", "B", "DYNAMIC_1"], 31.0))  # row 31
    claim = table.claim("C", 32.0)
    assert claim is not None
    assert claim.patch is not None
    data = text.encode()
    assert data[claim.patch.offset : claim.patch.offset + 64] == b"DYNAMIC_1".ljust(64)


def test_columns_must_be_distinct() -> None:
    with pytest.raises(ValueError, match="distinct"):
        SlogTable(["A", "A"])
    with pytest.raises(ValueError, match="distinct"):
        SlogTable([""])


# --------------------------------------------------------------------------------------------
# Parser


def _slog(body: str, columns: tuple[list[str], int] = (["A"], 1)) -> str:
    static, slots = columns
    names = [*static, *dynamic_names(slots)]
    return BANNER + format_slog_header(static, slots) + format_label_block(names, 0.5) + body


def test_parse_minimal() -> None:
    text = _slog(format_row(1.0, [2.0, None]))
    slog = parse_slog(text)
    assert slog.banner.logstart == 100.0
    assert slog.header_offset == len(BANNER)
    assert slog.records == (
        SlogLabels(("A", "DYNAMIC_0"), "   0.50", 10),
        SlogRow(1.0, (2.0, None), 12),
    )


def test_parse_no_columns() -> None:
    text = _slog(format_row(1.0, []), ([], 0))
    slog = parse_slog(text)
    assert slog.columns == ()
    label = slog.records[0]
    assert isinstance(label, SlogLabels)
    assert label.offset is None
    assert slog.rows == (SlogRow(1.0, (), 10),)


def test_parse_row_values() -> None:
    row = parse_row("1e-05  nan -nan inf -inf NaN -0 1.23457e+08 \n", lineno=4)
    assert row.offset == 1e-05
    assert row.lineno == 4
    values = row.values
    nan, minus_nan = values[0], values[1]
    assert nan is not None
    assert math.isnan(nan)
    assert minus_nan is not None
    assert math.isnan(minus_nan)
    assert math.copysign(1.0, minus_nan) == -1.0
    assert values[2:] == (math.inf, -math.inf, None, -0.0, 123457000.0)


@pytest.mark.parametrize(
    ("text", "lineno", "match"),
    [
        ("", 1, "empty"),
        (BANNER + "%%   (2) A\n", 6, "TIME"),
        (BANNER + "%%   (1) TIME \n%%   (3) A\n" + HEADER_RULE + "\n", 7, r"\(2\) NAME"),
        (BANNER + "%%   (1) TIME \n%%   (2) A\n", 7, "56"),
        (BANNER + "%%   (1) TIME \n%%   (2) \n" + HEADER_RULE + "\n", 7, "no name"),
        (_slog("1.0 2 NaN\nbad line\n"), 13, "row"),
        (_slog("1.0 2\n"), 12, "1 values, the columns are 2"),
        (_slog("1.0 2 x1\n"), 12, "'x1' is not a number"),
        (_slog("1.0 1_000 NaN\n"), 12, "not a number"),
        (_slog("abc 2 NaN\n"), 12, "row"),
        (_slog("%% TIME A B\n1.0 2 3\n"), 13, "missing its line of times"),
        (_slog("%% TIME A\n%% TIME [   1.00] [   2.00]\n"), 13, "names 1 columns but has 2"),
        (_slog("%% TIME A B\n%% TIME [   1.00] [   2.00]\n"), 13, "differ"),
        (_slog("%% TIME A\n%% TIME [  x]\n"), 13, "not a number"),
        (_slog("%% TIME A\n%% TIME 1.00\n"), 13, "'\\[%7.2f\\]' fields"),
    ],
)
def test_parse_errors_name_the_line(text: str, lineno: int, match: str) -> None:
    with pytest.raises(FormatError, match=match) as info:
        parse_slog(text, "x.slog")
    assert info.value.lineno == lineno
    assert info.value.path == "x.slog"


def test_rows_follow_the_latest_label_block() -> None:
    # pLogger's NOSYNC bug: a label block with one column fewer than the header, rows to match.
    text = _slog(format_label_block(["A"], 1.0) + format_row(1.5, [3.0]))
    slog = parse_slog(text)
    assert slog.rows == (SlogRow(1.5, (3.0,), 14),)


def test_truncated_tail_is_set_aside() -> None:
    full = _slog(format_row(1.0, [2.0, None]))
    cut = full + "2.0   3"
    slog = parse_slog(cut)
    assert slog.truncated == "2.0   3"
    assert slog.rows == (SlogRow(1.0, (2.0, None), 12),)
    half_label = full + "%% TIME            A                  DYNAMIC_0          \n%% TI"
    slog = parse_slog(half_label)
    assert slog.truncated.startswith("%% TIME            A")
    assert slog.truncated.endswith("\n%% TI")
    assert len(slog.records) == 2


def test_every_prefix_parses_or_fails_cleanly() -> None:
    raw = THEMOOS.read_bytes()
    full = parse_slog(raw.decode())
    header_end = raw.index(b"\n" + b"%" * 56 + b"\n") + 58
    for size in range(len(raw) + 1):
        text = raw[:size].decode()
        if size < header_end:
            with pytest.raises(FormatError):
                parse_slog(text)
            continue
        slog = parse_slog(text)
        assert full.records[: len(slog.records)] == slog.records
        whole = text[: len(text) - len(slog.truncated)]
        assert whole.endswith("\n")
        assert text == whole + slog.truncated
        assert "\n" not in slog.truncated or slog.truncated.startswith("%% TIME")
        rest = full.records[len(slog.records) :]
        if rest:
            assert rest[0].lineno >= whole.count("\n") + 1


# --------------------------------------------------------------------------------------------
# Round trips

_values = st.one_of(st.none(), st.floats(allow_nan=True, allow_infinity=True))


@settings(max_examples=200)
@given(
    offset=st.floats(min_value=-1e9, max_value=1e12, allow_nan=False),
    values=st.lists(_values, max_size=12),
)
def test_row_round_trip(offset: float, values: list[float | None]) -> None:
    text = format_row(offset, values)
    row = parse_row(text)
    assert format_row(row.offset, row.values) == text
    assert row.offset == float(format_slog_value(offset, 7))
    for got, want in zip(row.values, values, strict=True):
        if want is None:
            assert got is None
        elif math.isnan(want):
            assert got is not None
            assert math.isnan(got)
        else:
            assert got == float(format_slog_value(want))


@settings(max_examples=100)
@given(
    names=st.lists(
        st.text(alphabet="ABCDEFGHIJKLMNOPQRSTUVWXYZ_0123456789", min_size=1, max_size=40),
        unique=True,
        max_size=6,
    ),
    slots=st.integers(min_value=0, max_value=3),
    rows=st.lists(st.floats(min_value=0, max_value=1e6, allow_nan=False), max_size=5),
)
def test_table_output_parses_back(names: list[str], slots: int, rows: list[float]) -> None:
    table = SlogTable(names, dynamic_slots=slots)
    text = table.start(BANNER, 0.25)
    for n, offset in enumerate(rows):
        for name in names:
            table.update(name, float(n))
        text += table.row(offset)
    slog = parse_slog(text)
    assert [c.name for c in slog.columns] == [*names, *dynamic_names(slots)]
    assert [row.values for row in slog.rows] == [
        (*([float(n)] * len(names)), *([None] * slots)) for n in range(len(rows))
    ]
