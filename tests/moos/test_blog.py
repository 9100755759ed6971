"""The .blog: reference blogs rebuilt from their alogs' binary references, and payload checks."""

from __future__ import annotations

import gzip
from pathlib import Path

import pytest
from alog_oracle import iter_entries
from helpers import REFERENCE
from hypothesis import given, settings
from hypothesis import strategies as st

from fleetlog.errors import FormatError
from fleetlog.moos.alog import BinaryRef, Entry, LineFormatter, Variant
from fleetlog.moos.blog import LOST_OFFSET, BlogRecord, format_blog_record, payload_at

BLOGS = sorted(REFERENCE.rglob("*.blog"))
RUN_A = REFERENCE / "captured" / "runA_themoos_wildcard_restart" / "logs"


def read_text(path: Path) -> str:
    data = path.read_bytes()
    if path.suffix == ".gz":
        data = gzip.decompress(data)
    return data.decode("utf-8", "surrogateescape")


def sibling_logs(blog: Path) -> list[Path]:
    """The alog (plain or gzip) and xlog next to a blog: both send binary values to it."""
    stem = blog.with_suffix("")
    names = [".alog", ".alog.gz", ".xlog", ".xlog.gz"]
    return [p for p in (Path(f"{stem}{n}") for n in names) if p.exists()]


def variant_of(text: str) -> Variant:
    """The variant that wrote an alog, from the decimals of its first entry's time."""
    for line in text.split("\n"):
        if line[:1].isdigit():
            decimals = len(line.split(" ", 1)[0].partition(".")[2])
            return Variant.IVP if decimals == 5 else Variant.EM
    return Variant.IVP


def binary_entries(blog: Path) -> tuple[list[Entry], Variant]:
    entries: list[Entry] = []
    variant = Variant.IVP
    for log in sibling_logs(blog):
        text = read_text(log)
        if log.name.split(".")[-2 if log.suffix == ".gz" else -1] == "alog":
            variant = variant_of(text)
        lines = text.splitlines(keepends=True)
        entries += [e for e in iter_entries(lines) if isinstance(e.value, BinaryRef)]
    return entries, variant


def test_reference_blogs_exist() -> None:
    names = [p.parent.parent.name for p in BLOGS if p.stat().st_size]
    assert "themoos_session" in names
    assert "logs" in names  # runA
    assert len([p for p in BLOGS if p.stat().st_size]) >= 4


@pytest.mark.parametrize("path", BLOGS, ids=lambda p: p.name)
def test_golden_blog_rebuilt_from_alog_references(path: Path) -> None:
    blog = path.read_bytes()
    assert sibling_logs(path)
    entries, variant = binary_entries(path)
    entries.sort(key=lambda e: e.value.offset if isinstance(e.value, BinaryRef) else 0)
    formatter = LineFormatter(variant)
    out = b""
    for entry in entries:
        ref = entry.value
        assert isinstance(ref, BinaryRef)
        assert ref.file == path.name
        assert ref.size == 16
        payload = payload_at(blog, ref, path=str(path))
        assert len(payload) == 16
        record = format_blog_record(
            formatter.prefix(entry.offset, entry.key, entry.source), payload, len(out), path.name
        )
        assert record.ref == ref
        out += record.data
    assert out == blog
    if blog:
        assert [e.value.offset for e in entries if isinstance(e.value, BinaryRef)][:2] == [53, 123]


def test_run_a_restart_lost_the_payload() -> None:
    alog = RUN_A / "TEST_22_11_2026_____11_06_52" / "TEST_22_11_2026_____11_06_52.alog"
    refs = [
        e.value
        for e in iter_entries(read_text(alog).splitlines(keepends=True))
        if isinstance(e.value, BinaryRef)
    ]
    assert refs == [BinaryRef("TEST_22_11_2026_____11_06_52.blog", LOST_OFFSET, 16)]
    assert not alog.with_suffix(".blog").exists()
    with pytest.raises(FormatError, match=r"lost: Offset=-1"):
        payload_at(b"", refs[0], path="x.blog")


def test_record_layout() -> None:
    prefix = LineFormatter(Variant.EM).prefix(1.5, "CAMERA_FRAME", "iCamera")
    assert len(prefix) == 53
    payload = b"\x00\x01\x02\xff\nABC\r\n\x7f\x80\x10 0@"
    record = format_blog_record(prefix, payload, 0, "root.blog")
    assert record == BlogRecord(prefix.encode() + payload + b"\n", BinaryRef("root.blog", 53, 16))
    second = format_blog_record(prefix, payload, len(record.data), "root.blog")
    assert second.ref.offset == 123
    assert format_blog_record(prefix, b"", 10, "r.blog").ref == BinaryRef("r.blog", 63, 0)


def test_negative_size_is_refused() -> None:
    with pytest.raises(ValueError, match="negative"):
        format_blog_record("x ", b"", -1, "r.blog")


def test_payload_checks() -> None:
    blog = b"head " + b"abc" + b"\n" + b"next " + b"de"
    assert payload_at(blog, BinaryRef("r.blog", 5, 3)) == b"abc"
    assert payload_at(bytearray(blog), BinaryRef("r.blog", 5, 3)) == b"abc"
    assert payload_at(memoryview(blog), BinaryRef("r.blog", 5, 3)) == b"abc"
    assert payload_at(blog, BinaryRef("r.blog", 14, 2)) == b"de"  # cut before its newline
    with pytest.raises(FormatError, match="runs past the end of the blog") as info:
        payload_at(blog, BinaryRef("r.blog", 14, 3), path="r.blog")
    assert info.value.path == "r.blog"
    with pytest.raises(FormatError, match="not followed by a newline"):
        payload_at(blog, BinaryRef("r.blog", 5, 2))
    with pytest.raises(FormatError, match="invalid"):
        payload_at(blog, BinaryRef("r.blog", -5, 2))
    with pytest.raises(FormatError, match="invalid"):
        payload_at(blog, BinaryRef("r.blog", 5, -2))


@settings(max_examples=100)
@given(
    records=st.lists(
        st.tuples(
            st.floats(min_value=0, max_value=1e6, allow_nan=False),
            st.text(alphabet="ABCDEFGHIJKLMNOPQRSTUVWXYZ_", min_size=1, max_size=25),
            st.binary(max_size=64),
        ),
        max_size=8,
    )
)
def test_records_round_trip(records: list[tuple[float, str, bytes]]) -> None:
    formatter = LineFormatter()
    blog = b""
    refs = []
    for offset, key, payload in records:
        record = format_blog_record(formatter.prefix(offset, key, "src"), payload, len(blog), "b")
        blog += record.data
        refs.append(record.ref)
    assert [payload_at(blog, ref) for ref in refs] == [payload for _, _, payload in records]
