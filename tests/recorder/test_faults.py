"""Faults in the engine (fake clock, real files): nothing lost without a count and a mark.

A session directory removed while recording, a disk that refuses every write (RLIMIT_FSIZE,
a real OS limit, for root too) and comes back, losses on the way: each is counted, posted on
MOOS_DEBUG, said in the status, and marked by a ``PLOGGER_GAP`` entry where it happened; a
new session opens by itself as soon as writing works again.
"""

from __future__ import annotations

import resource
import shutil
import signal
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from recorder_support import T0, Clock, Rig, config, rigs

from fleetlog.recorder.engine import Recorder
from fleetlog.wire.message import MoosMessage

__all__ = ["rigs"]  # the fixture, imported


@pytest.fixture
def file_size_limit() -> Iterator[Callable[[int], None]]:
    """Limit the size any file of this process may grow to; restore it afterwards."""
    soft, hard = resource.getrlimit(resource.RLIMIT_FSIZE)
    previous = signal.signal(signal.SIGXFSZ, signal.SIG_IGN)

    def limit(size: int) -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (size, hard))

    try:
        yield limit
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, (soft, hard))
        signal.signal(signal.SIGXFSZ, previous)


def gaps(rig: Rig, directory: Path | None = None) -> list[str]:
    return [str(e.value) for e in rig.entries(directory) if e.key == "PLOGGER_GAP"]


def test_a_removed_session_directory_is_noticed_and_its_pending_lines_move_on(
    rigs: Callable[..., Rig],
) -> None:
    rig = rigs("File = R\nPath = logs\nLog = A @ 0\nLog = BIN @ 0")
    rig.rec.start()
    first = rig.dir
    rig.send("A", 1.0, at=0.5)
    rig.rec.flush()
    shutil.rmtree(first)
    rig.posted.clear()
    for i in range(3):
        rig.send("A", float(i), at=1.0)  # written, not yet handed to the OS
    rig.send("BIN", b"\x00\x01", at=1.0)  # its record went to the removed blog
    rig.rec.flush()  # noticed here, before the lines would go to unlinked files
    assert rig.rec.session is not None
    second = rig.dir
    assert second != first
    assert not first.exists()
    stats = rig.rec.stats
    assert (stats.lost, stats.write_errors, stats.sessions) == (1, 1, 2)
    assert stats.last_error == f"the session directory logs/{first.name} was removed"
    assert rig.debugs()[-1] == (
        f"the session directory logs/{first.name} was removed while recording: "
        f"now logging to logs/{second.name} (1 samples lost)"
    )
    # the new session keeps LOGSTART: the lines moved unchanged, after the mark
    assert rig.rec.logstart == T0
    rig.send("A", 7.0, at=1.5)
    entries = rig.entries()
    assert entries[0].key == "PLOGGER_GAP"
    assert entries[0].value == (
        f"reason=removed,lost=1,from={T0 + 1.0:.3f},to={T0 + 1.0:.3f},session={first.name},"
        "vars=BIN:1"
    )
    assert [(e.offset, e.value) for e in entries if e.key == "A"] == [
        (1.0, 0.0),
        (1.0, 1.0),
        (1.0, 2.0),
        (1.5, 7.0),
    ]
    assert rig.meta().gaps[0].reason == "removed"


def test_a_session_directory_removed_while_idle_is_replaced_within_a_tick(
    rigs: Callable[..., Rig],
) -> None:
    rig = rigs()
    rig.rec.start()
    first = rig.dir
    shutil.rmtree(first)
    rig.clock.t = T0 + 0.02
    rig.rec.tick()
    assert rig.rec.stats.sessions == 2  # (named as the first: it is gone, the name is free)
    assert rig.dir.exists()
    (mark,) = [e for e in rig.entries() if e.key == "PLOGGER_GAP"]
    assert str(mark.value).startswith("reason=removed,lost=0,")


def test_a_removal_is_one_write_error_whatever_metadata_write_was_in_flight(
    rigs: Callable[..., Rig],
) -> None:
    # The background writer runs when told here: a metadata rewrite is queued, the operator
    # removes the directory, then the rewrite runs (and fails) before the drain notices.
    queued: list[Callable[[], None]] = []
    rig = rigs(background=queued.append)
    rig.rec.start()
    for job in queued:
        job()
    queued.clear()
    first = rig.dir
    rig.send("A", 1.0, at=0.5)
    rig.clock.t = T0 + 3.0  # the metadata is stale (a sample came) and due (2 s)
    rig.rec.tick()
    assert queued, "no metadata rewrite was queued"
    shutil.rmtree(first)
    for job in queued:
        job()  # fails: the directory is gone
    queued.clear()
    rig.rec.tick()  # the drain notices the removal
    assert rig.rec.stats.sessions == 2
    assert rig.rec.stats.write_errors == 1
    assert rig.rec.stats.last_error == f"the session directory logs/{first.name} was removed"


def test_a_disk_that_refuses_writes_is_survived_and_left_as_soon_as_it_works(
    rigs: Callable[..., Rig], file_size_limit: Callable[[int], None]
) -> None:
    rig = rigs("File = R\nPath = logs\nLog = A @ 0\nLog = B @ 0")
    rig.rec.start()
    first = rig.dir
    rig.send("A", 0.0, at=0.5)
    rig.rec.flush()
    file_size_limit(64)  # not even a banner fits: the fallback fails too
    try:
        rig.send("A", 1.0, at=1.0)
        rig.rec.flush()  # fails: this sample is lost, the session dropped
        assert rig.rec.session is None
        assert rig.rec.broken == "file-too-large"
        status = rig.rec.status()
        assert (status["writing"], status["problem"]) == (False, "file-too-large")
        for i in range(5):
            rig.send("A", float(i), at=1.2)
            rig.send("B", float(i), at=1.4)
        rig.clock.t = T0 + 2.5
        rig.rec.tick()  # a retry while writes still fail: still lost, no empty directory left
        assert rig.rec.session is None
        rig.send("B", 9.0, at=2.6)
    finally:
        file_size_limit(resource.RLIM_INFINITY)
    debugs = rig.debugs()
    assert debugs[:1] == [
        f"write error, samples are being lost: cannot write {first}/{first.name}.alog: "
        "File too large"
    ]
    assert (
        "no session is open (file-too-large): samples are being lost until writing works again"
        in debugs
    )
    rig.clock.t = T0 + 10.0
    rig.rec.tick()  # the disk takes writes again: a new session, by itself
    assert rig.rec.session is not None
    assert rig.debugs()[-1] == f"writing works again: now logging to logs/{rig.dir.name}"
    stats = rig.rec.stats
    assert stats.lost == 1 + 10 + 1
    dirs = sorted(p.name for p in (rig.dir.parent).iterdir())
    assert dirs == sorted([first.name, rig.dir.name])  # failed attempts left nothing
    (mark,) = gaps(rig)
    assert mark == (
        f"reason=file-too-large,lost=12,from={T0 + 1.0:.3f},to={T0 + 2.6:.3f},"
        f"session={first.name},vars=A:6;B:6"
    )
    assert rig.entries()[0].key == "PLOGGER_GAP"
    assert rig.rec.status()["problem"] is None


def test_losses_on_the_way_are_marked_at_most_once_a_second(rigs: Callable[..., Rig]) -> None:
    rig = rigs()
    rig.rec.start()
    rig.clock.t = T0 + 0.5
    rig.rec.missed("A", "zid-9", 4)
    rig.rec.missed(None, "zid-9", 2)
    rig.rec.unreadable("fleet/alpha/var/BAD%ZZ")
    rig.rec.missed("A", "zid-9", 1)
    rig.rec.tick()  # within a second of the session's start (its last marks): not yet
    assert gaps(rig) == []
    rig.clock.t = T0 + 1.0
    rig.rec.tick()
    assert gaps(rig) == [
        f"reason=dropped,lost=7,from={T0 + 0.5:.3f},to={T0 + 0.5:.3f},vars=A:5",
        f"reason=unreadable,lost=1,from={T0 + 0.5:.3f},to={T0 + 0.5:.3f}",
    ]
    rig.clock.t = T0 + 1.2
    rig.rec.missed("A", "zid-9", 1)
    rig.clock.t = T0 + 1.5
    rig.rec.tick()
    assert len(gaps(rig)) == 2
    rig.clock.t = T0 + 2.0
    rig.rec.tick()
    assert gaps(rig)[2:] == [
        f"reason=dropped,lost=1,from={T0 + 1.2:.3f},to={T0 + 1.2:.3f},vars=A:1"
    ]
    assert len(rig.meta().gaps) == 3


def test_fsync_runs_in_the_background_at_its_interval(tmp_path: Path) -> None:
    (tmp_path / "logs").mkdir()
    jobs: list[Callable[[], None]] = []
    clock = Clock()
    rec = Recorder(
        config("File = R\nPath = logs\nFsyncInterval = 0.5\nLog = A @ 0"),
        vehicle="alpha",
        publish=lambda m: None,
        cwd=tmp_path,
        clock=clock,
        background=jobs.append,
    )
    rec.start()

    def syncs() -> list[Callable[[], None]]:
        for job in [j for j in jobs if "_sync" not in j.__qualname__]:
            jobs.remove(job)
            job()  # metadata writes
        return jobs

    rec.handle(MoosMessage("A", 1.0, clock.t, "iX", "", "alpha"))
    clock.t = T0 + 0.4
    rec.tick()
    assert syncs() == []  # not due yet
    clock.t = T0 + 0.6
    rec.tick()
    assert len(syncs()) == 1
    clock.t = T0 + 1.2
    rec.tick()
    assert len(syncs()) == 1  # the first has not run: never two at once
    jobs.pop()()
    assert rec.synced_at == T0 + 0.6
    assert rec.status()["synced_at"] == T0 + 0.6
    clock.t = T0 + 1.8
    rec.tick()
    assert syncs() == []  # nothing was written since: an idle session is not synced
    rec.handle(MoosMessage("A", 2.0, clock.t, "iX", "", "alpha"))
    rec.flush()
    clock.t = T0 + 1.9
    rec.tick()
    assert len(syncs()) == 1  # overdue: the line written after an idle time is synced now
    rec.stop()
    for job in list(jobs):
        job()


def test_max_lag_is_the_delay_from_arrival_to_the_os(rigs: Callable[..., Rig]) -> None:
    rig = rigs()
    rig.rec.start()
    rig.send("A", 1.0, at=1.0)
    rig.clock.t = T0 + 1.03
    rig.rec.flush()
    assert rig.rec.max_lag() == pytest.approx(0.03)
    rig.send("A", 1.0, at=5.0)
    rig.rec.tick()  # a status period ends: the last period's maximum is still reported
    rig.clock.t = T0 + 8.0
    rig.rec.tick()
    assert rig.rec.max_lag() == 0.0


def test_fsync_interval_must_be_seconds() -> None:
    from fleetlog.errors import MissionError

    with pytest.raises(MissionError, match="FsyncInterval value '-1' is not a number of seconds"):
        config("FsyncInterval = -1")
    assert config("FsyncInterval = 0").fsync_interval == 0.0
    assert config("").fsync_interval == 1.0


def test_the_hot_path_objects_keep_cpython_fast_attributes(rigs: Callable[..., Rig]) -> None:
    """Structure, not timing: CPython 3.11 reads ``self.x`` fast (inline values) only for
    objects with at most 30 attributes whose ``__dict__`` was never read; the counters use
    slots (reading their ``__dict__`` cost ``handle`` 0.2 µs a sample, docs/reliability.md)."""
    rig = rigs()
    rig.rec.start()
    assert not hasattr(rig.rec.stats, "__dict__")
    assert rig.rec.stats.as_dict()["received"] == 0
    assert len(vars(rig.rec)) <= 30
