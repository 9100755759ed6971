"""What a pass learns of a log's entry-only ranges, and a later selective pass that uses it.

A selective pass over a block its memo knows to hold entry lines only skips the per-line
tests (fleetlog.storage.purity): it must give exactly what a pass without the memo gives,
cold and warm, whatever the first pass was; a log that changed since is another version.
"""

from __future__ import annotations

import os
import threading
from pathlib import Path
from typing import Any

import polars as pl
import pytest
from alog_cases import BANNER, alog_bytes
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fleetlog.errors import FleetlogError
from fleetlog.moos.alog import LineFormatter
from fleetlog.storage import alogheads, alogpass, purity
from fleetlog.storage.columnar import AlogReader
from fleetlog.storage.purity import FileVersion, PurityMemo
from fleetlog.storage.select import Selection

_COLUMNS = ("line", "offset", "var", "source", "type", "double", "text", "raw")


def _read(path: Path, where: Any, memo: PurityMemo | None, block: int = 1024) -> tuple[Any, ...]:
    """Everything a skip-errors read gives: rows, counts, or the error it raised."""
    rows: list[tuple[object, ...]] = []
    try:
        with AlogReader(path, errors="skip", block_size=block, purity=memo) as reader:
            for batch in reader.frames(_COLUMNS, where=where):
                rows += batch.frame.with_columns(pl.col("double").fill_nan(None)).rows()
            return (rows, reader.scanned, reader.skipped, reader.truncated)
    except FleetlogError as err:
        return ("error", str(err), rows)


def _version(path: Path) -> FileVersion:
    with path.open("rb") as f:
        return FileVersion.of(f.fileno())


class _Counted:
    """Counts the blocks read by the known-pure path (the real function is still called)."""

    def __init__(self, monkeypatch: pytest.MonkeyPatch) -> None:
        self.calls = 0
        real = alogheads._known_pure

        def counted(*args: Any) -> Any:
            self.calls += 1
            return real(*args)

        monkeypatch.setattr(alogheads, "_known_pure", counted)


def _mission(n: int, continued_at: int | None = None) -> str:
    """A banner and ``n`` entries (one with a continuation line at ``continued_at``)."""
    fmt = LineFormatter()
    lines = [BANNER]
    for i in range(n):
        name = ("NAV_X", "NAV_Y", "DEPLOY")[i % 3]
        if name == "DEPLOY":
            value = "line one\nline two" if i == continued_at else "true"
            lines.append(fmt.string(1.0 + i / 100, name, "pHelmIvP", value))
        else:
            lines.append(fmt.double(1.0 + i / 100, name, "pNav", float(i)))
    return "".join(lines)


@settings(
    max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    data=st.booleans().flatmap(alog_bytes),
    learn_with=st.sampled_from(["selective", "whole"]),
    workers=st.sampled_from([1, 2]),
    variables=st.sampled_from([["NAV_X"], ["A*"], ["*_Y", "B"], ["?"]]),
)
def test_a_warm_selective_read_gives_what_a_read_without_the_memo_gives(
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    data: bytes,
    learn_with: str,
    workers: int,
    variables: list[str],
) -> None:
    monkeypatch.setattr(alogpass, "_WORKERS", workers)
    path = tmp_path / "p.alog"
    path.write_bytes(data)
    selection = Selection(variables)
    want = _read(path, selection, None)
    memo = PurityMemo()
    # learn from a selective pass (a first grep) or a whole one (a read of every line)
    first = _read(path, selection if learn_with == "selective" else None, memo)
    if learn_with == "selective":
        assert first == want
    assert _read(path, selection, memo) == want  # warm
    assert _read(path, selection, memo, block=2048) == want  # other block boundaries


def test_the_second_grep_of_a_log_skips_the_line_tests(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = tmp_path / "m.alog"
    path.write_text(_mission(400, continued_at=200))
    counted = _Counted(monkeypatch)
    memo = PurityMemo()
    selection = Selection(["NAV_X"])
    cold = _read(path, selection, memo)
    assert counted.calls == 0
    warm = _read(path, selection, memo)
    assert warm == cold == _read(path, selection, None)
    assert warm[1] == 400  # every entry scanned, the continued one too
    # every block but the banner's and the continuation line's was read the quick way
    blocks = len(path.read_bytes()) // 1024
    assert blocks - 3 <= counted.calls <= blocks


@pytest.mark.parametrize("change", ["rewritten", "appended", "replaced", "recreated"])
def test_a_changed_log_is_not_read_with_what_was_learnt_before(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, change: str
) -> None:
    path = tmp_path / "c.alog"
    text = _mission(300)
    path.write_text(text)
    memo = PurityMemo()
    selection = Selection(["DEPLOY"])
    _read(path, selection, memo)
    before = _version(path)
    # the same entries, a DEPLOY in the middle now has a continuation line in place
    fmt = LineFormatter()
    plain = fmt.string(1.0 + 152 / 100, "DEPLOY", "pHelmIvP", "true")
    odd = fmt.string(1.0 + 152 / 100, "DEPLOY", "pHelmIvP", "tr\ne")
    assert plain in text
    assert len(odd) == len(plain)
    changed = text.replace(plain, odd)
    if change == "rewritten":
        with path.open("r+") as f:  # in place: same inode and size, a new mtime
            f.write(changed)
        os.utime(path, ns=(before.mtime_ns + 1_000_000, before.mtime_ns + 1_000_000))
    elif change == "appended":  # (what was learnt still holds: but it is another version)
        with path.open("a") as f:
            f.write("x\n")
    elif change == "recreated":  # (often with the inode the deleted file had)
        path.unlink()
        path.write_text(changed)
        os.utime(path, ns=(before.mtime_ns, before.mtime_ns))
    else:
        other = tmp_path / "new.alog"
        other.write_text(changed)
        os.utime(other, ns=(before.mtime_ns, before.mtime_ns))  # even the same mtime
        other.replace(path)
    assert _version(path) != before
    counted = _Counted(monkeypatch)
    got = _read(path, selection, memo)
    assert counted.calls == 0
    assert got == _read(path, selection, None)
    if change != "appended":
        assert [r for r in got[0] if r[2] == "DEPLOY" and r[6] == "tr\ne"]  # read as changed


def test_ranges_merge_and_cover() -> None:
    memo = PurityMemo()
    v = FileVersion(1, 2, 1000, 3)
    memo.learn(v, 100, 200)
    memo.learn(v, 300, 400)
    assert memo.covers(v, 100, 200)
    assert memo.covers(v, 150, 160)
    assert not memo.covers(v, 150, 250)
    assert not memo.covers(v, 50, 150)
    memo.learn(v, 200, 300)  # touching both: one range
    assert memo.covers(v, 100, 400)
    memo.learn(v, 50, 120)
    assert memo.covers(v, 50, 400)
    assert not memo.covers(v, 49, 60)
    memo.learn(v, 900, 1001)  # past the size the version had: not learnt
    memo.learn(v, 500, 500)  # empty
    assert not memo.covers(v, 900, 1000)
    assert not memo.covers(v, 500, 501)
    assert not memo.covers(FileVersion(1, 2, 1000, 4), 100, 200)  # another version
    memo.clear()
    assert not memo.covers(v, 100, 200)


def test_a_file_holds_one_version() -> None:
    memo = PurityMemo()
    for size in range(1000, 1100):  # a log that grows between greps
        memo.learn(FileVersion(1, 7, size, size), 0, 500)
    assert len(memo) == 1
    assert memo.covers(FileVersion(1, 7, 1099, 1099), 0, 500)
    assert not memo.covers(FileVersion(1, 7, 1098, 1098), 0, 500)  # an older version
    memo.learn(FileVersion(1, 8, 1000, 0), 0, 500)
    assert len(memo) == 2


def test_the_memo_is_bounded(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(purity, "MAX_FILES", 3)
    monkeypatch.setattr(purity, "MAX_RANGES", 4)
    memo = PurityMemo()
    versions = [FileVersion(1, i, 10_000, 0) for i in range(5)]
    for v in versions[:3]:
        memo.learn(v, 0, 10)
    assert memo.covers(versions[0], 0, 10)  # used: the least recently used is now 1
    memo.learn(versions[3], 0, 10)
    assert not memo.covers(versions[1], 0, 10)
    assert memo.covers(versions[0], 0, 10)
    assert memo.covers(versions[3], 0, 10)
    v = versions[4]
    for i in range(6):
        memo.learn(v, 100 * i, 100 * i + 10)
    assert [memo.covers(v, 100 * i, 100 * i + 10) for i in range(6)] == [True] * 4 + [False] * 2
    memo.learn(v, 5, 105)  # a merge still happens at the cap
    assert memo.covers(v, 0, 110)


def test_threads_learn_and_look_up_together() -> None:
    memo = PurityMemo()
    v = FileVersion(1, 1, 1 << 40, 0)
    errors: list[BaseException] = []

    def work(k: int) -> None:
        try:
            for i in range(k, 4000, 4):
                memo.learn(v, 10 * i, 10 * i + 10)
                assert memo.covers(v, 10 * i, 10 * i + 10)
        except BaseException as err:  # (reported below)
            errors.append(err)

    threads = [threading.Thread(target=work, args=(k,)) for k in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors
    assert memo.covers(v, 0, 40_000)
