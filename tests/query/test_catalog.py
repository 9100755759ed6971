"""The vehicle side's storage: session catalog, confinement with real symlinks, digests, .part.

Copies of the real pLogger runs in ``reference/`` are the oracle: what the catalog says about
a session is checked against reading its alog whole with :class:`AlogReader`.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import time
from pathlib import Path

import pytest

from fleetlog.errors import FormatError, StorageError
from fleetlog.moos.alog import LineFormatter, format_banner
from fleetlog.storage.alogscan import VariableScan, read_head, tail_offset
from fleetlog.storage.catalog import LogCatalog
from fleetlog.storage.confined import ConfinedRoot, DigestCache
from fleetlog.storage.download import PartFile
from fleetlog.storage.readers import AlogReader

RUN_A = "captured/runA_themoos_wildcard_restart"
RUN_B1 = "captured/runB1_ivp_compressed_markdatatype"
RUN_B2 = "captured/runB2_nofiletimestamp"
A44 = "TEST_22_11_2026_____11_06_44"
A52 = "TEST_22_11_2026_____11_06_52"


def copy_tree(reference: Path, rel: str, dest: Path) -> Path:
    """Copy a reference directory (keeping mtimes) and make it writable."""
    target = dest / Path(rel).name
    shutil.copytree(reference / rel, target)
    for path in [target, *target.rglob("*")]:
        path.chmod(0o755 if path.is_dir() else 0o644)
    return target


def test_sessions_match_a_full_read(reference: Path, tmp_path: Path) -> None:
    run = copy_tree(reference, RUN_A, tmp_path)
    catalog = LogCatalog(run / "logs", vehicle="fallback")
    assert catalog.session_names() == [A44, A52]
    for info in catalog.sessions():
        alog = run / "logs" / info.name / f"{info.name}.alog"
        with AlogReader(alog) as reader:
            entries = list(reader.entries())
            assert info.start == reader.logstart
        assert info.variables == len({e.key for e in entries})
        assert info.duration == entries[-1].offset
        assert info.vehicle == "test"  # DB_TIME's source is MOOSDB_test
        assert info.complete  # copies keep the old mtimes
        assert info.stamp == "2026-11-22T11:06:" + info.name[-2:]
        listed = {f.name: f.size for f in info.files}
        on_disk = {p.name: p.stat().st_size for p in (run / "logs" / info.name).iterdir()}
        assert listed == on_disk
    brief = catalog.session(A44, brief=True)
    assert brief.start is None
    assert brief.variables is None
    assert brief.alog == f"{A44}.alog"


def test_latest_from_the_hint_in_the_parent(reference: Path, tmp_path: Path) -> None:
    run = copy_tree(reference, RUN_A, tmp_path)
    # pLogger's hint names an absolute path from another machine: matched by its last part.
    latest = LogCatalog(run / "logs", vehicle="v").latest()
    assert (latest.session, latest.how, latest.writing) == (A52, "hint", False)
    assert latest.hint == f"/home/alpha/mission/logs/{A52}"
    (run / ".LastOpenedMOOSLogDirectory").write_text(f"LastOpenedLoggingDirectory=./logs/{A44}\n")
    assert LogCatalog(run / "logs", vehicle="v").latest().session == A44
    (run / ".LastOpenedMOOSLogDirectory").unlink()
    latest = LogCatalog(run / "logs", vehicle="v").latest()
    assert (latest.session, latest.how, latest.hint) == (A52, "newest", None)


def test_compressed_run_with_a_named_hint(reference: Path, tmp_path: Path) -> None:
    run = copy_tree(reference, RUN_B1, tmp_path)
    catalog = LogCatalog(run, vehicle="v", hint=run / "summary.txt")
    latest = catalog.latest()
    assert (latest.session, latest.how) == ("LOG_ALPHA_22_11_2026_____11_07_42", "hint")
    info = catalog.session(latest.session or "")
    assert info.alog == "LOG_ALPHA_22_11_2026_____11_07_42.alog.gz"
    with AlogReader(run / info.name / info.alog) as reader:
        entries = list(reader.entries())
    assert info.variables == len({e.key for e in entries})
    assert info.duration == entries[-1].offset
    assert info.vehicle == "ivp"  # no DB_TIME in the head: the ._moos Community
    assert catalog.guess_vehicle() == "ivp"


def test_a_session_without_time_stamp(reference: Path, tmp_path: Path) -> None:
    run = copy_tree(reference, RUN_B2, tmp_path)
    catalog = LogCatalog(run, vehicle="v")
    assert catalog.session_names() == ["FIXED"]  # glogs/ holds sessions, not an alog
    latest = catalog.latest()
    assert (latest.session, latest.how) == ("FIXED", "hint")
    assert catalog.session("FIXED").duration == pytest.approx(-3.71)


def test_completeness_by_quiet_time_and_by_the_recorder(tmp_path: Path) -> None:
    session = tmp_path / "MOOSLog_1_2_2025_____10_00_00"
    session.mkdir()
    (session / f"{session.name}.alog").write_text(format_banner("x", 1.0, "now"))
    now = time.time()
    assert not LogCatalog(tmp_path, vehicle="v", clock=lambda: now).session(session.name).complete
    later = LogCatalog(tmp_path, vehicle="v", clock=lambda: now + 6)
    assert later.session(session.name).complete
    active = LogCatalog(tmp_path, vehicle="v", active=lambda: session, clock=lambda: now + 60)
    assert not active.session(session.name).complete
    latest = active.latest()
    assert (latest.session, latest.how, latest.writing) == (session.name, "recorder", True)
    idle = LogCatalog(tmp_path, vehicle="v", active=lambda: None)
    assert idle.session(session.name).complete


def test_symlinks_that_leave_the_root_are_refused(tmp_path: Path) -> None:
    root = tmp_path / "logs"
    session = root / "S"
    session.mkdir(parents=True)
    (session / "S.alog").write_text(format_banner("x", 1.0, "now"))
    secret = tmp_path / "secret.txt"
    secret.write_text("private")
    outside = tmp_path / "elsewhere"
    outside.mkdir()
    (outside / "E.alog").write_text("x")
    (session / "leak.txt").symlink_to(secret)
    (session / "inside.alog").symlink_to(session / "S.alog")
    (root / "E").symlink_to(outside)
    (session / "up").symlink_to(root)
    os.mkfifo(session / "pipe")
    (session / "S.alog.part").write_text("half a download")
    (session / "S.alog.part.json").write_text("{}")
    catalog = LogCatalog(root, vehicle="v")
    assert catalog.session_names() == ["S"]  # E leads outside
    names = {f.name for f in catalog.session("S", brief=True).files}
    assert names == {"S.alog", "inside.alog"}  # no leak.txt, no pipe, no directory
    with pytest.raises(StorageError, match="leads outside the log root"):
        catalog.read_range("S", "leak.txt", 0, 10)
    with pytest.raises(StorageError, match="no session 'E'"):
        catalog.read_range("E", "E.alog", 0, 10)
    with pytest.raises(StorageError, match="not a regular file"):
        catalog.read_range("S", "pipe", 0, 10)  # O_NONBLOCK: a FIFO cannot hang the server
    with pytest.raises(StorageError, match="does not exist"):
        catalog.read_range("S", "missing", 0, 10)
    with pytest.raises(FormatError, match="relative directory"):
        catalog.read_range("S", "..", 0, 10)
    data, meta = catalog.read_range("S", "inside.alog", 0, 10)
    assert data == (session / "S.alog").read_bytes()[:10]
    assert meta.size == (session / "S.alog").stat().st_size
    with pytest.raises(StorageError, match="past the end"):
        catalog.read_range("S", "S.alog", meta.size + 1, 10)
    confined = ConfinedRoot(root)
    with pytest.raises(StorageError, match="leads outside"):
        confined.resolve("S", "up")  # resolves to the root itself


def test_digest_cache_hashes_once(tmp_path: Path) -> None:
    session = tmp_path / "S"
    session.mkdir()
    data = os.urandom(3 << 20)
    (session / "f").write_bytes(data)
    root = ConfinedRoot(tmp_path)
    cache = DigestCache()
    digest, _ = cache.sha256(root, ("S", "f"))
    assert digest == hashlib.sha256(data).hexdigest()
    (session / "f").write_bytes(data + b"x")  # size and mtime change: hashed again
    assert cache.sha256(root, ("S", "f"))[0] == hashlib.sha256(data + b"x").hexdigest()


def _ranges(
    root: ConfinedRoot, names: tuple[str, str], size: int, step: int
) -> list[tuple[int, bytes, os.stat_result]]:
    out = []
    for offset in range(0, size, step):
        data, st, steady = root.read_steady(names, offset, step)
        assert steady
        out.append((offset, data, st))
    return out


def test_served_ranges_make_the_digest(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    (tmp_path / "S").mkdir()
    data = os.urandom((5 << 20) + 123)
    (tmp_path / "S" / "f").write_bytes(data)
    root = ConfinedRoot(tmp_path)
    want = hashlib.sha256(data).hexdigest()
    ranges = _ranges(root, ("S", "f"), len(data), 1 << 20)
    cache = DigestCache()
    # Out of order, as a few workers send them: later ranges wait for their turn.
    order = [0, 2, 1, 4, 3, 5]
    for index in order[:-1]:
        offset, chunk, st = ranges[index]
        cache.feed(st, offset, chunk)
        assert cache.known(st) is None
    offset, chunk, st = ranges[order[-1]]
    cache.feed(st, offset, chunk)
    assert cache.known(st) == want
    cache.feed(st, 0, ranges[0][1])  # a range sent again (another client) changes nothing

    def no_disk(*_: object) -> bytes:
        raise AssertionError("the digest was read from the disk again")

    monkeypatch.setattr("fleetlog.storage.confined._pread_all", no_disk)
    assert cache.sha256(root, ("S", "f")) == (want, st)


def test_a_digest_continues_where_the_ranges_stopped(tmp_path: Path) -> None:
    (tmp_path / "S").mkdir()
    data = os.urandom(3 << 20)
    (tmp_path / "S" / "f").write_bytes(data)
    root = ConfinedRoot(tmp_path)
    ranges = _ranges(root, ("S", "f"), len(data), 1 << 19)
    cache = DigestCache(max_pending=1 << 19)
    offset, chunk, st = ranges[1]
    cache.feed(st, offset, chunk)  # no digest begun at offset 0: ignored
    for offset, chunk, st in (ranges[0], ranges[3], ranges[4], ranges[2]):
        cache.feed(st, offset, chunk)  # ranges[4] does not fit in memory: read again later
    assert cache.known(st) is None
    assert cache.sha256(root, ("S", "f"))[0] == hashlib.sha256(data).hexdigest()
    # Ranges of an older version of the file never enter the new version's digest.
    (tmp_path / "S" / "f").write_bytes(data[::-1])
    cache.feed(st, 0, chunk)
    assert cache.sha256(root, ("S", "f"))[0] == hashlib.sha256(data[::-1]).hexdigest()


def test_served_ranges_of_a_catalog_make_the_digest(tmp_path: Path) -> None:
    logs = tmp_path / "logs"
    session = logs / "S"
    session.mkdir(parents=True)
    data = os.urandom(2 << 20)
    (session / "S.alog").write_bytes(data)
    old = time.time() - 60
    os.utime(session / "S.alog", (old, old))
    catalog = LogCatalog(logs, vehicle="v", quiet=5.0)
    for offset in range(0, len(data), 1 << 20):
        chunk, meta, sent = catalog.serve_range("S", "S.alog", offset, 1 << 20)
        assert chunk == data[offset : offset + len(chunk)]
        assert meta.complete
        sent()
    assert catalog.digests.known(os.stat(session / "S.alog")) == hashlib.sha256(data).hexdigest()
    # A session still being written is not hashed as it is served.
    (session / "S.alog").write_bytes(data)
    _, meta, sent = catalog.serve_range("S", "S.alog", 0, 1 << 20)
    sent()
    assert not meta.complete
    assert catalog.digests.known(os.stat(session / "S.alog")) is None


def test_variable_scan_is_incremental(tmp_path: Path) -> None:
    fmt = LineFormatter()
    path = tmp_path / "x.alog"
    text = format_banner("x", 1.0, "now") + "".join(
        fmt.double(i * 0.5, f"VAR_{i % 7}", "p", float(i)) for i in range(1000)
    )
    text += fmt.string(600.0, "A_VERY_LONG_VARIABLE_NAME_OVERFLOWING", "src", "v")
    text += fmt.string(601.0, "MULTI", "src", "12 is a continuation\n3 x y z")
    cut = len(text) // 2 + 7
    path.write_text(text[:cut])
    scan = VariableScan(path)
    scan.update()
    first = scan.count
    with path.open("a") as file:
        file.write(text[cut:])
    scan.update()
    fresh = VariableScan(path)
    fresh.update()
    with AlogReader(path) as reader:
        keys = {e.key for e in reader.entries()}
    assert first <= scan.count == fresh.count == len(keys) == 9
    assert scan.last_offset == fresh.last_offset == tail_offset(path) == 601.0
    assert read_head(path).time_decimals == 5


def test_part_file_resumes_and_commits(tmp_path: Path) -> None:
    final = tmp_path / "out" / "S" / "f.alog"
    source = {"vehicle": "v", "session": "S", "file": "f.alog"}
    data = os.urandom(100_000)
    sha = hashlib.sha256(data).hexdigest()
    part = PartFile(final, source)
    assert part.open() == 0
    part.append(data[:30_000])
    part.remember(size=len(data), mtime=1.0, complete=True, sha256=sha)
    part.close()  # a killed client leaves the .part and its state
    assert not final.exists()
    again = PartFile(final, source)
    assert again.open() == 30_000
    assert again.tail(10) == data[29_990:30_000]
    assert not again.remember(size=len(data), mtime=2.0, complete=True, sha256="0" * 64)
    again.append(data[30_000:])
    with pytest.raises(StorageError, match="sha256 of the 100000 bytes"):
        again.commit("0" * 64)
    assert not final.exists()
    assert again.part.exists()
    assert again.commit(sha) == final
    assert final.read_bytes() == data
    assert not again.part.exists()
    assert not again.state_path.exists()
    other = PartFile(final.with_name("g"), {**source, "file": "g"})
    other.open()
    other.append(b"abc")
    other.close()
    # The same .part claimed for another file starts over.
    stranger = PartFile(final.with_name("g"), {**source, "file": "g", "session": "T"})
    assert stranger.open() == 0
    stranger.close()


def test_a_directory_named_like_an_alog_makes_no_session(tmp_path: Path) -> None:
    # A session is a directory holding an alog *file*; one holding only a directory named
    # X.alog (or a copied tree) is not listed, fetched or pruned as a session.
    root = tmp_path / "logs"
    fake = root / "MOOSLog_1_2_2025_____10_00_00"
    (fake / "inner.alog").mkdir(parents=True)
    (fake / "x.alog.zst").mkdir()
    real = root / "MOOSLog_1_2_2025_____10_00_05"
    real.mkdir()
    (real / f"{real.name}.alog").write_bytes(b"")
    catalog = LogCatalog(root, vehicle="v")
    assert catalog.session_names() == [real.name]
    assert not catalog.has_session(fake.name)
    assert catalog.has_session(real.name)
