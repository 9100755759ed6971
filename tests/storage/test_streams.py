"""Output streams: text is held until a flush, then written once, with the same bytes."""

from __future__ import annotations

import gzip
import io
import resource
import signal
import zlib
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
import zstandard

from fleetlog.errors import StorageError
from fleetlog.storage.streams import (
    COMPRESSED_FLUSH_INTERVAL,
    GzipStream,
    PlainStream,
    ZstdStream,
)

LINES = [
    "0.100 A proc 1.5 \n",
    "0.200 B proc caf\u00e9 \u2603 \n",
    "0.300 C proc \udcff\udc80 raw bytes \n",  # surrogateescape'd bytes come back as bytes
    "",
    "0.400 D proc value, with = signs\nand a newline \n",
]


def encoded(lines: list[str]) -> bytes:
    """What writing each line on its own gave before (the reference bytes)."""
    return b"".join(line.encode("utf-8", "surrogateescape") for line in lines)


def test_plain_text_reaches_the_file_at_flush_byte_identical(tmp_path: Path) -> None:
    path = tmp_path / "a.alog"
    stream = PlainStream(path)
    for line in LINES:
        stream.write(line)
    assert path.read_bytes() == b""  # held in memory until the flush
    stream.flush(0.0)
    assert path.read_bytes() == encoded(LINES)
    stream.write(LINES[0])
    stream.close()
    assert path.read_bytes() == encoded([*LINES, LINES[0]])


def test_plain_bytes_and_offsets_come_after_the_text_written_before(tmp_path: Path) -> None:
    path = tmp_path / "a.blog"
    stream = PlainStream(path)
    stream.write("text \u00e9\n")
    assert stream.tell() == len("text \u00e9\n".encode())
    stream.write_bytes(b"\x00\xff")
    stream.write("more\n")
    stream.close()
    assert path.read_bytes() == "text \u00e9\n".encode() + b"\x00\xffmore\n"


def test_plain_patch_overwrites_text_not_yet_flushed(tmp_path: Path) -> None:
    path = tmp_path / "a.slog"
    stream = PlainStream(path)
    stream.write("%% header DYNAMIC_1  \n")
    stream.patch(len("%% header "), b"NAV_X    ")
    stream.write("row\n")
    stream.flush(0.0)
    assert path.read_bytes() == b"%% header NAV_X      \nrow\n"
    stream.close()


def test_a_surrogate_standing_for_no_byte_is_written_not_raised(tmp_path: Path) -> None:
    path = tmp_path / "a.alog"
    stream = PlainStream(path)
    stream.write("ok\n")
    stream.write("bad \ud800\n")
    stream.close()
    assert path.read_bytes() == b"ok\nbad \xed\xa0\x80\n"


@pytest.fixture
def file_size_limit() -> Iterator[Callable[[int], None]]:
    """Limit the size files may grow to (RLIMIT_FSIZE: EFBIG, for root too), then restore it."""
    soft, hard = resource.getrlimit(resource.RLIMIT_FSIZE)
    previous = signal.signal(signal.SIGXFSZ, signal.SIG_IGN)

    def limit(size: int) -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (size, hard))

    try:
        yield limit
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, (soft, hard))
        signal.signal(signal.SIGXFSZ, previous)


def test_a_failed_flush_raises_and_does_not_keep_the_text_for_the_next(
    tmp_path: Path, file_size_limit: Callable[[int], None]
) -> None:
    path = tmp_path / "a.alog"
    stream = PlainStream(path)
    stream.write("0123456789abcdef\n")
    stream.write("second line\n")
    file_size_limit(4)
    try:
        with pytest.raises(StorageError, match=f"cannot write {path}: File too large"):
            stream.flush(0.0)
        stream.flush(0.0)  # nothing is kept for a second try: it was counted
    finally:
        file_size_limit(resource.RLIM_INFINITY)
    assert stream.unwritten == 2  # exactly the lines that did not reach the file
    stream.write("after\n")
    stream.close()
    assert path.read_bytes() == b"0123after\n"  # a cut line, as readers expect after a fault


def zstd_text(path: Path) -> tuple[str, int]:
    """Return the text of the complete frames and how many there are."""
    data = path.read_bytes()
    text = b""
    frames = 0
    while data:
        reader = zstandard.ZstdDecompressor().decompressobj()
        chunk = reader.decompress(data)
        if not reader.eof:
            break
        text += chunk
        frames += 1
        data = reader.unused_data
    return text.decode("utf-8", "surrogateescape"), frames


def test_zstd_frames_close_at_most_every_quarter_second_with_every_line(tmp_path: Path) -> None:
    assert COMPRESSED_FLUSH_INTERVAL == 0.25
    path = tmp_path / "a.alog.zst"
    stream = ZstdStream(path)
    stream.write(LINES[0])
    stream.flush(10.0)  # an interval since the (zero) start: a frame
    assert zstd_text(path) == (LINES[0], 1)
    stream.write(LINES[1])
    stream.flush(10.1)  # fed to the compressor, but inside the same interval: no frame
    stream.write(LINES[2])
    stream.flush(10.2)
    assert zstd_text(path) == (LINES[0], 1)
    stream.flush(10.25)
    assert zstd_text(path) == ("".join(LINES[:3]), 2)
    assert stream.take_wait() == pytest.approx(0.15)  # LINES[1] waited from 10.1 to 10.25
    assert stream.take_wait() == 0.0
    stream.flush(13.0)  # nothing new: no empty frame
    assert zstd_text(path)[1] == 2
    stream.write(LINES[4])
    stream.close()
    assert zstd_text(path)[0] == "".join(LINES[:3]) + LINES[4]


def test_gzip_sync_points_at_most_every_quarter_second_with_every_line(tmp_path: Path) -> None:
    path = tmp_path / "a.alog.gz"
    stream = GzipStream(path)

    def readable() -> bytes:
        return zlib.decompressobj(31).decompress(path.read_bytes())

    stream.write(LINES[0])
    stream.flush(10.0)
    assert readable() == encoded(LINES[:1])
    stream.write(LINES[1])
    stream.flush(10.2)
    assert readable() == encoded(LINES[:1])
    stream.flush(10.25)
    assert readable() == encoded(LINES[:2])
    stream.write(LINES[4])
    stream.close()
    with gzip.open(io.BytesIO(path.read_bytes())) as f:
        assert f.read() == encoded([*LINES[:2], LINES[4]])
