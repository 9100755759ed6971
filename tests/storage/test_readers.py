"""Reading logs from disk: compression, truncated tails, memory, binary payloads, merging."""

from __future__ import annotations

import gzip
import io
import shutil
import tracemalloc
import zlib
from collections.abc import Iterator
from pathlib import Path

import pytest
import zstandard
from alog_oracle import iter_entries
from helpers import REFERENCE

from fleetlog.errors import FormatError, StorageError, UsageError
from fleetlog.moos.alog import (
    BinaryRef,
    Entry,
    LineFormatter,
    Variant,
    format_banner,
)
from fleetlog.storage.readers import (
    AlogReader,
    IndexedRecord,
    Record,
    find_alog,
    merge_records,
    open_text,
    sorted_window,
)

RUN_A1 = REFERENCE / "captured/runA_themoos_wildcard_restart/logs/TEST_22_11_2026_____11_06_44"
RUN_A2 = REFERENCE / "captured/runA_themoos_wildcard_restart/logs/TEST_22_11_2026_____11_06_52"
RUN_B1 = REFERENCE / "captured/runB1_ivp_compressed_markdatatype/LOG_ALPHA_22_11_2026_____11_07_42"
RUN_B2 = REFERENCE / "captured/runB2_nofiletimestamp/glogs/MOOSLog_22_11_2026_____11_08_11"
THEMOOS = REFERENCE / "themoos_session/MOOSLog_3_2_2025_____09_05_07"
IVP = REFERENCE / "ivp_session/LOG_ALPHA_19_6_2025_____12_04_50"

RUN_A1_ALOG = RUN_A1 / f"{RUN_A1.name}.alog"
THEMOOS_ALOG = THEMOOS / f"{THEMOOS.name}.alog"
RUN_B1_ALOG_GZ = RUN_B1 / f"{RUN_B1.name}.alog.gz"


def reference_text(path: Path) -> bytes:
    data = path.read_bytes()
    return gzip.decompress(data) if path.suffix == ".gz" else data


def split_lines(text: str) -> list[str]:
    parts = text.split("\n")
    lines = [part + "\n" for part in parts[:-1]]
    if parts[-1]:
        lines.append(parts[-1])
    return lines


def pure_entries(data: bytes) -> list[Entry]:
    return list(iter_entries(split_lines(data.decode("utf-8", "surrogateescape"))))


def read_all(path: Path, **kwargs: str) -> tuple[AlogReader, list[Entry]]:
    with AlogReader(path, **kwargs) as reader:  # type: ignore[arg-type]
        return reader, list(reader.entries())


def plogger_gzip(
    data: bytes, piece: int = 300, flush_every: int = 2048
) -> tuple[bytes, list[tuple[int, int]]]:
    """Compress like pLogger's Zipper: one member, Z_SYNC_FLUSH after each 2048 bytes.

    The small reference files are shorter than 2048 bytes; their tests flush more often.

    Returns the stream and its sync points as (compressed size, text size) pairs.
    """
    compressor = zlib.compressobj(6, zlib.DEFLATED, 16 + zlib.MAX_WBITS)
    out = bytearray()
    points: list[tuple[int, int]] = []
    since_flush = 0
    for start in range(0, len(data), piece):
        chunk = data[start : start + piece]
        out += compressor.compress(chunk)
        since_flush += len(chunk)
        if since_flush >= flush_every:
            out += compressor.flush(zlib.Z_SYNC_FLUSH)
            points.append((len(out), start + len(chunk)))
            since_flush = 0
    out += compressor.flush()
    return bytes(out), points


def zstd_frames(data: bytes, lines_per_frame: int) -> tuple[bytes, list[tuple[int, int]]]:
    """Compress as a sequence of frames at line boundaries, as fleetlog's recorder will.

    Returns the stream and the frame ends as (compressed size, text size) pairs.
    """
    compressor = zstandard.ZstdCompressor()
    lines = data.splitlines(keepends=True)
    out = bytearray()
    ends: list[tuple[int, int]] = []
    text_size = 0
    for start in range(0, len(lines), lines_per_frame):
        chunk = b"".join(lines[start : start + lines_per_frame])
        out += compressor.compress(chunk)
        text_size += len(chunk)
        ends.append((len(out), text_size))
    return bytes(out), ends


# --------------------------------------------------------------------------------------------
# Plain, gzip and zstd


@pytest.mark.parametrize(
    "source", [RUN_A1_ALOG, THEMOOS_ALOG, RUN_B1_ALOG_GZ], ids=lambda p: p.name
)
def test_plain_gzip_and_zstd_read_identically(tmp_path: Path, source: Path) -> None:
    data = reference_text(source)
    name = source.name.removesuffix(".gz")
    multi, _ = zstd_frames(data, 7)
    variants = {
        "plain": (name, data),
        "gzip": (name + ".gz", gzip.compress(data)),
        "pLogger gzip": (name + ".gz", plogger_gzip(data)[0]),
        "zstd": (name + ".zst", zstandard.ZstdCompressor().compress(data)),
        "zstd frames": (name + ".zst", multi),
    }
    results = {}
    for label, (filename, content) in variants.items():
        directory = tmp_path / label.replace(" ", "_")
        directory.mkdir()
        (directory / filename).write_bytes(content)
        reader, entries = read_all(directory / filename)
        assert not reader.truncated, label
        assert reader.skipped == 0, label
        assert reader.blog_path == directory / (name.removesuffix(".alog") + ".blog")
        results[label] = (reader.banner, entries)
    assert results["plain"][1] == pure_entries(data)
    assert len(results["plain"][1]) > 0
    for label, result in results.items():
        assert result == results["plain"], label


def test_open_text_keeps_carriage_returns_and_arbitrary_bytes(tmp_path: Path) -> None:
    banner = format_banner("./x/x.alog", 100.0, "Thu Jan  1 00:00:00 1970").encode()
    odd = "cr\r inside, crlf\r\nnext, bytes \udcff\udcfe and é"
    line = LineFormatter().string(1.0, "ODD", "app", odd)
    data = banner + line.encode("utf-8", "surrogateescape")
    assert b"\xff\xfe" in data
    for name, content in (
        ("x.alog", data),
        ("y.alog.gz", gzip.compress(data)),
        ("z.alog.zst", zstandard.ZstdCompressor().compress(data)),
    ):
        path = tmp_path / name
        path.write_bytes(content)
        with open_text(path) as stream:
            lines = list(stream)
            assert not stream.truncated
        assert "".join(lines).encode("utf-8", "surrogateescape") == data
        # Split at \n only: the \r and \r\n inside the value do not end lines.
        assert len(lines) == data.count(b"\n")
        _, [entry] = read_all(path)
        assert entry.value == odd
        assert isinstance(entry.value, str)
        assert entry.value.encode("utf-8", "surrogateescape") == odd.encode(
            "utf-8", "surrogateescape"
        )


def test_open_text_missing_file_names_it(tmp_path: Path) -> None:
    with pytest.raises(StorageError, match=r"cannot open .*missing\.alog\.zst"):
        open_text(tmp_path / "missing.alog.zst")


def test_concatenated_gzip_members_and_nul_padding(tmp_path: Path) -> None:
    data = reference_text(THEMOOS_ALOG)
    half = data.index(b"\n2.250") + 1
    path = tmp_path / "two.alog.gz"
    path.write_bytes(gzip.compress(data[:half]) + gzip.compress(data[half:]) + b"\x00" * 64)
    reader, entries = read_all(path)
    assert not reader.truncated
    assert entries == pure_entries(data)


# --------------------------------------------------------------------------------------------
# Truncated tails


def check_cut(path: Path, text: bytes, full: list[Entry], *, whole: bool) -> list[Entry]:
    """Read a cut file; check it never raises and yields a prefix of the entries.

    ``whole`` says the compressed stream ends cleanly there (an empty file has no member or
    frame at all, which is a whole, empty stream; the alog reader still calls it cut).
    """
    reader, entries = read_all(path)
    assert entries == full[: len(entries)]
    if not whole:
        assert reader.truncated
    with open_text(path) as stream:
        recovered = stream.read().encode("utf-8", "surrogateescape")
        assert stream.truncated is not whole
    assert text.startswith(recovered)
    # Nothing the decoder recovered is lost at the entry layer except the unproven tail.
    assert entries == list(
        iter_entries([*split_lines(recovered.decode()), *([] if whole else [""])])
    )
    return entries


@pytest.mark.parametrize("source", [THEMOOS_ALOG, RUN_B1_ALOG_GZ], ids=lambda p: p.name)
def test_gzip_cut_at_every_prefix(tmp_path: Path, source: Path) -> None:
    text = reference_text(source)
    full = pure_entries(text)
    stream, points = plogger_gzip(text, piece=97, flush_every=256)
    assert points  # at least one Z_SYNC_FLUSH point
    path = tmp_path / "cut.alog.gz"
    seen = 0
    for n in range(len(stream) + 1):
        path.write_bytes(stream[:n])
        entries = check_cut(path, text, full, whole=n in (0, len(stream)))
        with open_text(path) as reader:
            recovered = len(reader.read().encode("utf-8", "surrogateescape"))
        # Everything up to the last sync-flush point before the cut is recovered.
        flushed = max((size for end, size in points if end <= n), default=0)
        assert recovered >= flushed
        assert len(entries) >= seen or n == len(stream)
        seen = len(entries)
    assert seen == len(full)


def test_gzip_cut_dense_sample_of_a_long_real_file(tmp_path: Path) -> None:
    text = reference_text(RUN_A1_ALOG)
    full = pure_entries(text)
    stream, points = plogger_gzip(text)
    cuts = set(range(0, len(stream) + 1, 7))
    for end, _ in points:
        cuts.update(range(end - 2, end + 3))
    path = tmp_path / "cut.alog.gz"
    for n in sorted(c for c in cuts if 0 <= c <= len(stream)):
        path.write_bytes(stream[:n])
        check_cut(path, text, full, whole=n in (0, len(stream)))


def test_gzip_without_trailer_recovers_all_text_but_not_the_unproven_last_entry(
    tmp_path: Path,
) -> None:
    text = reference_text(THEMOOS_ALOG)
    path = tmp_path / "crash.alog.gz"
    path.write_bytes(gzip.compress(text)[:-8])  # the member's CRC and size are missing
    with open_text(path) as stream:
        assert stream.read().encode() == text
        assert stream.truncated
    reader, entries = read_all(path)
    assert reader.truncated
    # The stream ended, but not cleanly: the last entry could have had more lines.
    assert entries == pure_entries(text)[:-1]


def test_zstd_multi_frame_cut_mid_frame(tmp_path: Path) -> None:
    text = reference_text(RUN_B1_ALOG_GZ)
    full = pure_entries(text)
    stream, ends = zstd_frames(text, 3)
    assert len(ends) > 5
    boundaries = {end: size for end, size in ends}
    path = tmp_path / "cut.alog.zst"
    for n in range(len(stream) + 1):
        path.write_bytes(stream[:n])
        at_boundary = n == 0 or n in boundaries
        entries = check_cut(path, text, full, whole=at_boundary)
        if n in boundaries:
            # A stream that ends between frames is whole up to there.
            assert entries == pure_entries(text[: boundaries[n]])


def test_corrupt_compressed_data_raise_or_skip(tmp_path: Path) -> None:
    text = reference_text(RUN_A1_ALOG)
    full = pure_entries(text)
    for name, content in (
        ("bad.alog.gz", bytearray(gzip.compress(text))),
        ("bad.alog.zst", bytearray(zstd_frames(text, 20)[0])),
    ):
        middle = len(content) // 2
        content[middle : middle + 16] = b"\xff" * 16
        path = tmp_path / name
        path.write_bytes(content)
        with pytest.raises(StorageError, match=rf"{name}: corrupt"), AlogReader(path) as reader:
            list(reader.entries())
        reader, entries = read_all(path, errors="skip")
        assert reader.truncated
        assert reader.skipped == 1
        assert entries == full[: len(entries)]


def test_plain_file_cut_inside_a_line_or_a_multi_line_value(tmp_path: Path) -> None:
    text = reference_text(RUN_B2 / f"{RUN_B2.name}.alog")
    full = pure_entries(text)
    path = tmp_path / "cut.alog"
    cut_line = text.index(b"3.700           MULTI") + 30
    path.write_bytes(text[:cut_line])
    reader, entries = read_all(path)
    assert reader.truncated
    assert entries == [e for e in full if e.lineno < entries[-1].lineno + 1]
    assert entries[-1].key == "EMPTY"
    # Cut right after "line1\n" of MULTI = "line1\nline2": no terminator, dropped.
    after_line1 = text.index(b"line1\n", cut_line - 30) + len(b"line1\n")
    path.write_bytes(text[:after_line1])
    reader, entries = read_all(path)
    assert reader.truncated
    assert entries[-1].key == "EMPTY"
    path.write_bytes(text)
    reader, entries = read_all(path)
    assert not reader.truncated
    assert entries == full


def test_file_cut_inside_its_banner_is_truncated_not_garbled(tmp_path: Path) -> None:
    text = reference_text(RUN_B1_ALOG_GZ)
    banner_end = text.index(b"\n3.74687")
    path = tmp_path / "short.alog"
    for n in range(banner_end):
        path.write_bytes(text[:n])
        reader, entries = read_all(path)  # errors="raise": not an error
        assert reader.banner is None
        assert reader.logstart is None
        assert reader.truncated
        assert entries == []


# --------------------------------------------------------------------------------------------
# Memory


def write_large_alog(path: Path, lines: int, *, wide: bool = False) -> None:
    """Write a synthetic alog line by line; ``wide`` adds NODE_REPORT-sized string values."""
    formatter = LineFormatter(Variant.IVP)
    banner = format_banner(f"./big/{path.name}", 1750334690.048564, "Thu Jan  1 00:00:00 1970")
    raw = path.open("wb")
    sink: io.RawIOBase | zstandard.ZstdCompressionWriter | gzip.GzipFile = raw  # type: ignore[assignment]
    if path.suffix == ".gz":
        sink = gzip.GzipFile(fileobj=raw, mode="wb")
    elif path.suffix == ".zst":
        sink = zstandard.ZstdCompressor().stream_writer(raw)
    with raw, sink:
        sink.write(banner.encode())
        batch: list[str] = []
        for i in range(lines):
            offset = i * 0.01
            if i % 3 == 0:
                batch.append(formatter.double(offset, "NAV_X", "uSimMarineV22", i * 0.37))
            elif i % 3 == 1:
                report = f"NAME=alpha,X={i},Y={-i},SPD=1.20,HDG=180.00,TYPE=kayak,INDEX={i}"
                if wide:
                    report += ",MODE=SURVEY,ALLSTOP=clear,LOAD_WARNING=none" * 4
                batch.append(formatter.string(offset, "NODE_REPORT", "pNodeReporter", report))
            else:
                batch.append(formatter.string(offset, "MULTI", "iTest", f"a{i}\nb{i}"))
            if len(batch) == 1000:
                sink.write("".join(batch).encode())
                batch.clear()
                if isinstance(sink, zstandard.ZstdCompressionWriter):
                    sink.flush(zstandard.FLUSH_FRAME)  # a frame per batch
        sink.write("".join(batch).encode())


BLOCK = 1 << 18


def entries_peak_memory(path: Path) -> tuple[int, int]:
    tracemalloc.start()
    try:
        count = 0
        # Memory is bounded by the block (8 MiB by default): a small one shows the bound on a
        # small file. tracemalloc sees Python's allocations, not polars' (bench/ measures RSS).
        with AlogReader(path, block_size=BLOCK) as reader:
            for _ in reader.entries():
                count += 1
            assert not reader.truncated
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    return count, peak


@pytest.mark.parametrize(
    ("name", "lines", "wide"),
    [("big.alog", 50_000, False), ("big.alog.zst", 10_000, True), ("big.alog.gz", 10_000, True)],
)
def test_memory_does_not_grow_with_file_size(
    tmp_path: Path, name: str, lines: int, wide: bool
) -> None:
    small, big = tmp_path / ("small-" + name), tmp_path / name
    write_large_alog(small, lines, wide=wide)
    write_large_alog(big, 4 * lines, wide=wide)
    with open_text(big) as stream:
        text_size = sum(len(line) for line in stream)
    entries_peak_memory(small)  # the first read imports polars, whose modules would count
    count_small, peak_small = entries_peak_memory(small)
    count, peak = entries_peak_memory(big)
    assert (count_small, count) == (lines, 4 * lines)
    # Correctness bounds, not timing ones: four times the file needs no more memory, and a
    # few blocks' worth (two parsed at once, one read ahead) is all it needs (a reader that
    # held the file would need more).
    assert peak < 1.5 * peak_small, (peak, peak_small)
    assert peak < min(16 * BLOCK, text_size / 2), (peak, text_size)


# --------------------------------------------------------------------------------------------
# Binary payloads


@pytest.mark.parametrize(
    ("alog", "payload"),
    [
        (THEMOOS_ALOG, b"\x00\x01\x02\xff\nABC\r\n\x7f\x80\x10 0@"),
        (RUN_A1_ALOG, bytes.fromhex("00112233445566778899aabbccddeeff")),
        (RUN_B1_ALOG_GZ, bytes.fromhex("00112233445566778899aabbccddeeff")),
        (RUN_B2 / f"{RUN_B2.name}.alog", bytes.fromhex("00112233445566778899aabbccddeeff")),
    ],
    ids=lambda value: value.name if isinstance(value, Path) else "",
)
def test_binary_payloads_resolve_against_the_reference_blogs(alog: Path, payload: bytes) -> None:
    with AlogReader(alog) as reader:
        binaries = [e for e in reader.entries() if isinstance(e.value, BinaryRef)]
        assert binaries
        blog = reader.blog_path.read_bytes()
        variant = Variant.IVP if "ALPHA" in alog.name else Variant.EM
        formatter = LineFormatter(variant)
        for entry in binaries:
            assert reader.read_binary(entry) == payload
            ref = entry.value
            assert isinstance(ref, BinaryRef)
            assert ref.file == reader.blog_path.name
            # Each blog record is the alog line's head, the payload and a newline (§2.6).
            head = formatter.prefix(entry.offset, entry.key, entry.source).encode()
            assert blog[ref.offset - len(head) : ref.offset] == head
            assert blog[ref.offset + ref.size] == ord("\n")


def test_offset_minus_one_after_restart_names_file_and_offset() -> None:
    with AlogReader(RUN_A2 / f"{RUN_A2.name}.alog") as reader:
        [entry] = [e for e in reader.entries() if isinstance(e.value, BinaryRef)]
        with pytest.raises(StorageError, match=r"TEST_22_11_2026_____11_06_52\.blog Offset=-1"):
            reader.read_binary(entry)
        assert not reader.blog_path.exists()  # pLogger never reopened it (§6.3)


def test_bad_binary_references(tmp_path: Path) -> None:
    formatter = LineFormatter()
    blog = (b"x" * 53 + b"0123456789" + b"\n") * 2
    (tmp_path / "s.blog").write_bytes(blog)
    refs = [
        BinaryRef("s.blog", 53, 10),  # good
        BinaryRef("../s.blog", 53, 10),
        BinaryRef("s.blog", 53, 11),  # past the payload: not followed by a newline
        BinaryRef("s.blog", 100, 30),  # past the end
        BinaryRef("gone.blog", 53, 10),
    ]
    text = format_banner("./s/s.alog", 10.0, "x")
    for i, ref in enumerate(refs):
        text += formatter.binary(float(i), "BIN", "app", ref)
    text += formatter.string(9.0, "STR", "app", "not binary")
    (tmp_path / "s.alog").write_text(text)
    with AlogReader(tmp_path / "s.alog") as reader:
        good, traversal, unended, beyond, missing, string = list(reader.entries())
        assert reader.read_binary(good) == b"0123456789"
        with pytest.raises(StorageError, match=r"'\.\./s\.blog'.*not a file beside the log"):
            reader.read_binary(traversal)
        with pytest.raises(StorageError, match=r"s\.blog at Offset=53, Bytes=11 is not a blog"):
            reader.read_binary(unended)
        with pytest.raises(StorageError, match=r"s\.blog ends before Offset=100 \+ Bytes=30"):
            reader.read_binary(beyond)
        with pytest.raises(StorageError, match=r"s\.alog:10: BIN: cannot read .*gone\.blog at"):
            reader.read_binary(missing)
        with pytest.raises(StorageError, match=r"s\.alog:11: STR is not a binary value"):
            reader.read_binary(string)


# --------------------------------------------------------------------------------------------
# Records, windows and merging


def make_alog(path: Path, logstart: float, items: list[tuple[float, str, float]]) -> None:
    formatter = LineFormatter(Variant.IVP)
    text = format_banner(f"./{path.stem}/{path.name}", logstart, "Thu Jan  1 00:00:00 1970")
    for offset, key, value in items:
        text += formatter.double(offset, key, "app", value)
    path.write_text(text)


def test_records_carry_absolute_time() -> None:
    with AlogReader(RUN_B1_ALOG_GZ) as reader:
        assert reader.logstart == 1795345661.900295
        records = list(reader.records())
        assert [r.entry for r in records] == list(reader.entries())  # a second pass
    assert records[0] == Record(1795345661.900295 + 3.74687, records[0].entry)
    assert all(r.time == 1795345661.900295 + r.entry.offset for r in records)


def test_merge_two_files_by_absolute_time(tmp_path: Path) -> None:
    make_alog(
        tmp_path / "a.alog",
        1000.0,
        [(0.5, "A", 1), (2.0, "A", 2), (1.0, "A", 3), (3.0, "A", 4), (10.0, "A", 5)],
    )
    make_alog(
        tmp_path / "b.alog", 1001.0, [(0.0, "B", 1), (1.0, "B", 2), (0.25, "B", 3), (5.0, "B", 4)]
    )
    with AlogReader(tmp_path / "a.alog") as a, AlogReader(tmp_path / "b.alog") as b:
        merged = merge_records([a, b])
        records = list(merged)
    assert merged.late == 0
    assert [(r.time, r.origin, r.entry.value) for r in records] == [
        (1000.5, 0, 1.0),
        (1001.0, 0, 3.0),
        (1001.0, 1, 1.0),  # equal times: input order
        (1001.25, 1, 3.0),
        (1002.0, 0, 2.0),
        (1002.0, 1, 2.0),
        (1003.0, 0, 4.0),
        (1006.0, 1, 4.0),
        (1010.0, 0, 5.0),
    ]
    assert all(isinstance(r, IndexedRecord) for r in records)


def test_merge_real_sessions_of_a_restart() -> None:
    with AlogReader(RUN_A1_ALOG) as first, AlogReader(RUN_A2 / f"{RUN_A2.name}.alog") as second:
        assert first.logstart == second.logstart  # LOGSTART survives LOGGER_RESTART (§6.3)
        counts = (len(list(first.entries())), len(list(second.entries())))
        merged = merge_records([first, second])
        records = list(merged)
    assert len(records) == sum(counts)
    assert merged.late == 0
    times = [r.time for r in records]
    assert times == sorted(times)
    assert {r.origin for r in records} == {0, 1}


def test_merge_without_window_and_with_a_custom_key() -> None:
    def entry(offset: float) -> Entry:
        return Entry(offset, "K", "s", offset, str(offset))

    a = [Record(1.0, entry(1.0)), Record(3.0, entry(3.0))]
    b = [Record(2.0, entry(2.0))]
    merged = list(merge_records([a, b], window=None))
    assert [(r.time, r.origin) for r in merged] == [(1.0, 0), (2.0, 1), (3.0, 0)]
    backwards = list(merge_records([a[::-1], b], key=lambda r: -r.time))
    assert [r.time for r in backwards] == [3.0, 2.0, 1.0]


def test_sorted_window_is_bounded_stable_and_counts_late_records() -> None:
    def entry(offset: float, tag: str) -> Entry:
        return Entry(offset, tag, "s", tag, tag)

    times = [5.0, 1.0, 2.0, 2.0, 0.5, 9.0, 3.0, 8.0, 7.5]
    records = [Record(t, entry(t, f"k{i}")) for i, t in enumerate(times)]
    window = sorted_window(records, 1000)
    out = list(window)
    assert [r.time for r in out] == sorted(times)
    assert [r.entry.key for r in out if r.time == 2.0] == ["k2", "k3"]  # stable
    assert window.late == 0
    narrow = sorted_window(records, 2)
    out = list(narrow)
    assert sorted(r.time for r in out) == sorted(times)
    # 0.5 is 4 records after 5.0: with 2 records held it comes out after 1.0 and 2.0.
    assert narrow.late > 0
    passthrough = sorted_window(records, 0)
    assert list(passthrough) == records
    assert passthrough.late == sum(1 for i, t in enumerate(times) if t < max(times[:i] or [t]))
    with pytest.raises(UsageError, match="window"):
        sorted_window(records, -1)


def test_sorted_window_streams() -> None:
    pulled = 0

    def source() -> Iterator[Record]:
        nonlocal pulled
        for i in range(100_000):
            pulled += 1
            yield Record(float(i), Entry(float(i), "K", "s", "v", "v"))

    window = sorted_window(source(), 10)
    assert next(window).time == 0.0
    assert pulled == 11  # never more than the window ahead


# --------------------------------------------------------------------------------------------
# Banner and stray-line policy


def garbled(tmp_path: Path) -> Path:
    text = reference_text(THEMOOS_ALOG).replace(
        b"%% LOGSTART               1738573507.26", b"%% LOGSTART  soon"
    )
    path = tmp_path / "garbled.alog"
    path.write_bytes(text)
    return path


def test_garbled_banner_raise_or_skip(tmp_path: Path) -> None:
    path = garbled(tmp_path)
    with pytest.raises(FormatError, match=r"garbled\.alog:5: LOGSTART 'soon' is not a number"):
        AlogReader(path)
    reader, entries = read_all(path, errors="skip")
    assert reader.banner is None
    assert reader.logstart is None
    assert reader.skipped == 1
    assert isinstance(reader.banner_error, FormatError)
    assert entries == pure_entries(reference_text(THEMOOS_ALOG))
    with AlogReader(path, errors="skip") as reader, pytest.raises(StorageError, match="LOGSTART"):
        reader.records()


def test_missing_banner_raise_or_skip(tmp_path: Path) -> None:
    text = reference_text(THEMOOS_ALOG)
    path = tmp_path / "headless.alog"
    path.write_bytes(text[text.index(b"0.702") :])
    with pytest.raises(FormatError, match=r"headless\.alog:1: expected a banner line"):
        AlogReader(path)
    reader, entries = read_all(path, errors="skip")
    assert reader.skipped == 1
    assert entries[0].lineno == 1
    assert len(entries) == len(pure_entries(text))


def test_stray_lines_after_the_banner_raise_or_skip(tmp_path: Path) -> None:
    text = reference_text(THEMOOS_ALOG)
    cut = text.index(b"0.702")
    path = tmp_path / "stray.alog"
    path.write_bytes(text[:cut] + b"garbage line\nmore garbage\n" + text[cut:])
    with pytest.raises(FormatError, match=r"stray\.alog:8: 2 line\(s\) before line 8"):
        read_all(path)
    reader, entries = read_all(path, errors="skip")
    assert reader.skipped == 2
    assert len(entries) == len(pure_entries(text))


def test_xlogs_need_no_banner(tmp_path: Path) -> None:
    reader, entries = read_all(RUN_A1 / f"{RUN_A1.name}.xlog")
    assert reader.banner is None
    assert not reader.truncated
    assert [e.key for e in entries][:2] == ["PLOGGER_STATUS", "PLOGGER_STATUS"]
    reader, entries = read_all(RUN_B1 / f"{RUN_B1.name}.xlog.gz")  # an empty gzip stream
    assert (reader.banner, entries, reader.truncated) == (None, [], False)
    (tmp_path / "empty.xlog").write_bytes(b"")
    reader, entries = read_all(tmp_path / "empty.xlog")
    assert (reader.banner, entries, reader.truncated) == (None, [], False)
    (tmp_path / "empty.alog").write_bytes(b"")
    reader, entries = read_all(tmp_path / "empty.alog")  # a crash before the banner
    assert (reader.banner, entries, reader.truncated) == (None, [], True)


def test_a_closed_reader_refuses_new_passes() -> None:
    reader = AlogReader(THEMOOS_ALOG)
    entries = reader.entries()
    reader.close()
    with pytest.raises(StorageError, match=r"MOOSLog_3_2_2025_____09_05_07\.alog: the reader is"):
        reader.entries()
    with pytest.raises(StorageError, match="closed during a pass"):
        next(entries)  # the pass's stream was closed with the reader


@pytest.mark.parametrize("suffix", [".alog", ".alog.gz"])
def test_a_reader_closed_in_the_middle_of_a_pass_says_so(tmp_path: Path, suffix: str) -> None:
    """Closed between two blocks (from another thread, say): the pass ends with the
    reader's own error, whatever step of the block it was at."""
    lines = reference_text(THEMOOS_ALOG).split(b"\n")
    banner = [line for line in lines[:8] if line.startswith(b"%")]
    entries = [line for line in lines[len(banner) :] if line and not line.startswith(b"%")]
    log = b"\n".join(banner + entries * 200) + b"\n"  # ~250 KB
    path = tmp_path / f"big{suffix}"
    path.write_bytes(gzip.compress(log) if suffix.endswith(".gz") else log)
    reader = AlogReader(path, block_size=1024)
    entries = reader.entries()
    next(entries)
    reader.close()
    with pytest.raises(StorageError, match="closed during a pass"):
        for _ in entries:
            pass


def test_reader_rejects_unknown_error_policy() -> None:
    with pytest.raises(UsageError, match="errors"):
        AlogReader(THEMOOS_ALOG, errors="ignore")  # type: ignore[arg-type]


# --------------------------------------------------------------------------------------------
# Sessions


def test_find_alog(tmp_path: Path) -> None:
    assert find_alog(THEMOOS) == THEMOOS_ALOG
    assert find_alog(RUN_B1) == RUN_B1_ALOG_GZ
    session = tmp_path / "LOG_22_11_2026_____11_07_42"
    session.mkdir()
    with pytest.raises(StorageError, match=r"holds no \.alog"):
        find_alog(session)
    (session / "LOG_22_11_2026_____11_07_42.alog.gz").write_bytes(b"")
    assert find_alog(session).name.endswith(".alog.gz")
    (session / "LOG_22_11_2026_____11_07_42.alog.zst").write_bytes(b"")
    assert find_alog(session).name.endswith(".alog.zst")  # .zst before .gz
    (session / "LOG_22_11_2026_____11_07_42.alog").write_bytes(b"")
    assert find_alog(session).suffix == ".alog"
    renamed = tmp_path / "renamed"
    shutil.copytree(session, renamed)
    with pytest.raises(StorageError, match="several alogs"):
        find_alog(renamed)
    for extra in ("LOG_22_11_2026_____11_07_42.alog", "LOG_22_11_2026_____11_07_42.alog.zst"):
        (renamed / extra).unlink()
    assert find_alog(renamed).name == "LOG_22_11_2026_____11_07_42.alog.gz"
    with pytest.raises(StorageError, match="cannot list session directory"):
        find_alog(tmp_path / "nowhere")
