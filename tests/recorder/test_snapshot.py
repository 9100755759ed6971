"""Snapshot mode with a fake clock and real files: what a snapshot holds, triggers, memory."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest
from recorder_support import T0, Rig, config, rigs

from fleetlog.errors import MissionError
from fleetlog.moos.keep_settings import DiskSettings, Trigger, parse_trigger
from fleetlog.moos.mission import parse_mission
from fleetlog.recorder.snapshot import SnapshotRing, sample_size
from fleetlog.wire.message import MoosMessage

__all__ = ["rigs"]  # the fixture, imported

STEP = 0.125  # exact in binary: window edges are exact too


def sessions(rig: Rig) -> list[Path]:
    return sorted(p for p in (rig.rec.log_root).iterdir() if p.is_dir())


def absolute(rig: Rig, directory: Path) -> list[tuple[str, float, object]]:
    """(name, absolute time, value) of a closed session's alog entries."""
    logstart = rig.meta(directory).logstart
    return [(e.key, round(logstart + e.offset, 3), e.value) for e in rig.entries(directory)]


def finish(rig: Rig, at: float) -> None:
    """Let the drain loop's ticks write what is due (as the service's loop does)."""
    rig.clock.t = T0 + at
    for _ in range(100):
        rig.rec.tick()


def test_a_snapshot_holds_exactly_the_window_plus_each_latest_older_value(
    rigs: Callable[..., Rig],
) -> None:
    rig = rigs("File = R\nPath = logs\nLog = A @ 0\nLog = B @ 0\nLog = C @ 0\nSnapshotSeconds = 10")
    rig.rec.start()
    assert rig.rec.session is None
    assert any("snapshot mode" in d for d in rig.debugs())
    rig.send("B", "first", at=1.0)
    rig.send("B", "second", at=2.0)
    rig.send("C", 3.5, at=30.0)
    for k in range(1, 481):  # A at 8 Hz for 60 s
        rig.send("A", float(k), at=k * STEP)
        if k % 8 == 0:
            rig.rec.tick()
    assert sessions(rig) == []  # nothing written before a SNAPSHOT
    rig.send("PLOGGER_CMD", "SNAPSHOT", at=60.0, source="uOps")
    finish(rig, 60.0)
    (snap,) = sessions(rig)
    got = absolute(rig, snap)
    window = [("A", round(T0 + k * STEP, 3), float(k)) for k in range(400, 481)]
    older = [
        ("B", round(T0 + 2.0, 3), "second"),
        ("C", round(T0 + 30.0, 3), 3.5),
        ("A", round(T0 + 399 * STEP, 3), 399.0),
    ]
    assert got == older + window
    meta = rig.meta(snap)
    assert meta.state == "closed"
    assert meta.notes["snapshot"] == "PLOGGER_CMD from uOps"
    assert meta.logstart == pytest.approx(T0 + 2.0)
    status = rig.rec.status()["snapshot"]
    assert status["state"] == "armed"
    assert (status["snapshots"], status["written"], status["evicted"]) == (1, 84, 0)
    assert rig.rec.stats.logged == 84


def test_a_snapshot_that_records_on_is_closed_on_time_by_an_idle_recorder(
    rigs: Callable[..., Rig],
) -> None:
    """Nothing arrives after the trigger: the drain thread sleeps until the snapshot's end."""
    rig = rigs("File = R\nPath = logs\nLog = A @ 0\nSnapshotSeconds = 2\nSnapshotAfter = 0.5")
    rig.rec.start()
    for k in range(1, 17):  # 2 s at 8 Hz
        rig.send("A", float(k), at=k * STEP)
    assert rig.control({"cmd": "snapshot", "source": "shore"}).ok
    finish(rig, 2.0)  # the window is written; the snapshot records on until 2.5 s
    assert rig.rec.session is not None
    assert rig.rec.due_in() == pytest.approx(0.5, abs=1e-6)
    rig.clock.t = T0 + 2.5
    rig.rec.tick()
    assert rig.rec.session is None


def test_snapshot_after_records_on_and_a_second_trigger_extends_it(
    rigs: Callable[..., Rig],
) -> None:
    rig = rigs("File = R\nPath = logs\nLog = A @ 0\nSnapshotSeconds = 2\nSnapshotAfter = 3")
    rig.rec.start()
    for k in range(1, 81):  # 10 s at 8 Hz
        rig.send("A", float(k), at=k * STEP)
    first = rig.control({"cmd": "snapshot", "source": "shore"})
    assert first.ok
    assert first.did is not None
    assert first.did.startswith("started snapshot")
    for k in range(81, 105):  # 3 s more; a second SNAPSHOT at 12 s extends to 15 s
        rig.send("A", float(k), at=k * STEP)
        rig.rec.tick()
        if k == 96:
            again = rig.control({"cmd": "snapshot"})
            assert again.ok
            assert again.did is not None
            assert again.did.startswith("extended snapshot")
    assert rig.rec.session is not None  # still writing at 13 s
    for k in range(105, 161):  # to 20 s
        rig.send("A", float(k), at=k * STEP)
        rig.rec.tick()
    finish(rig, 20.0)
    (one,) = sessions(rig)
    values = [v for _, _, v in absolute(rig, one)]
    # the older value (k=63), the window 8..10 s, and on to 15 s: each once, in order
    assert values == [63.0, *[float(k) for k in range(64, 121)]]
    # a trigger after it closed: a session of its own, whole on its own
    rig.send("PLOGGER_CMD", "snapshot", at=20.0)
    finish(rig, 30.0)
    assert len(sessions(rig)) == 2
    second = absolute(rig, sessions(rig)[1])
    assert [v for _, _, v in second] == [float(k) for k in range(143, 161)]


def test_a_trigger_variable_fires_once_per_change_to_its_value(rigs: Callable[..., Rig]) -> None:
    rig = rigs(
        "File = R\nPath = logs\nLog = A @ 0\nSnapshotSeconds = 5\n"
        "SnapshotTrigger = ALARM == 1\nSnapshotTrigger = MODE == FAULT"
    )
    rig.rec.start()
    t = 0.0
    for value in (0.0, 1.0, 1.0, 1.0, 0.0, 1.0, 1.0):
        t += 1.0
        rig.send("ALARM", value, at=t)
        rig.send("A", t, at=t)
        finish(rig, t)
    for text in ("OK", "FAULT", "FAULT ", "OK", "FAULT"):
        t += 1.0
        rig.send("MODE", text, at=t)
        finish(rig, t)
    status = rig.rec.status()["snapshot"]
    assert status["triggered"] == 4
    assert status["snapshots"] == 4
    assert len(sessions(rig)) == 4
    assert status["triggers"] == ["ALARM == 1", "MODE == FAULT"]
    assert rig.meta(sessions(rig)[0]).notes["snapshot"] == "ALARM == 1"
    assert rig.rec.stats.commands == 0  # a trigger's writes are not commands


def test_the_memory_bound_evicts_counts_and_says_so_in_the_session(
    rigs: Callable[..., Rig],
) -> None:
    rig = rigs("File = R\nPath = logs\nLog = A @ 0\nSnapshotSeconds = 60\nSnapshotMemory = 100kB")
    rig.rec.start()
    ring = rig.rec._snap.ring  # type: ignore[union-attr]
    for k in range(1, 401):
        rig.send("A", "x" * 1000, at=k * STEP)
        assert ring.bytes <= 100_000
    status = rig.rec.status()["snapshot"]
    assert status["evicted"] > 300
    assert status["evicted"] + status["samples"] == 400
    assert rig.rec.snapshot().ok
    finish(rig, 51.0)
    (snap,) = sessions(rig)
    note = rig.meta(snap).notes["snapshot_held"]
    assert "of 60 s (SnapshotMemory 100000 bytes" in note
    assert len(rig.entries(snap)) == status["samples"] + 1  # and A's latest older value
    assert "Snapshot=armed" in rig.rec.status_text(T0 + 51.0)


def test_samples_evicted_before_a_snapshot_wrote_them_are_lost_and_marked(
    rigs: Callable[..., Rig],
) -> None:
    rig = rigs(
        "File = R\nPath = logs\nLog = A @ 0\nSnapshotSeconds = 600\nSnapshotMemory = 100kB\n"
        "SnapshotAfter = 60"
    )
    rig.rec.start()
    for k in range(1, 90):
        rig.send("A", "x" * 1000, at=k * STEP)
    before = rig.rec.status()["snapshot"]["evicted"]
    assert before > 0
    assert rig.rec.snapshot().ok
    for k in range(90, 400):  # no tick: nothing is written meanwhile, the ring wraps
        rig.send("A", "x" * 1000, at=k * STEP)
    finish(rig, 120.0)
    status = rig.rec.status()["snapshot"]
    assert status["lost"] > 0
    assert rig.rec.stats.lost == status["lost"]
    (snap,) = sessions(rig)
    gaps = rig.meta(snap).gaps
    assert [g.reason for g in gaps] == ["snapshot-memory"]
    assert gaps[0].lost == status["lost"]
    written = [e for e in rig.entries(snap) if e.key == "A"]
    # every sample is written or counted: evicted before the trigger (one of them written
    # as the latest older value), or lost after it
    assert len(written) - 1 + status["lost"] + before == 399


def test_restart_is_refused_and_snapshot_refused_outside_snapshot_mode(
    rigs: Callable[..., Rig],
) -> None:
    rig = rigs("File = R\nPath = logs\nLog = A @ 0\nSnapshotSeconds = 5")
    rig.rec.start()
    rig.send("LOGGER_RESTART", "true", at=1.0)
    (record,) = rig.rec.status()["commands"]
    assert record["ok"] is False
    assert "snapshot mode" in record["why"]
    assert sessions(rig) == []
    plain = rigs("File = P\nPath = logs\nLog = A @ 0")
    plain.rec.start()
    plain.send("PLOGGER_CMD", "SNAPSHOT", at=1.0)
    record = plain.rec.status()["commands"][-1]
    assert record["ok"] is False
    assert "not in snapshot mode" in record["why"]


def test_a_hostile_source_cannot_forge_lines_through_the_snapshot_reason(
    rigs: Callable[..., Rig],
) -> None:
    rig = rigs("File = R\nPath = logs\nLog = A @ 0\nSnapshotSeconds = 5")
    rig.rec.start()
    rig.send("A", 1.0, at=1.0)
    rig.send("PLOGGER_CMD", "SNAPSHOT", at=2.0, source="x\n0.0 FORGED y 1")
    finish(rig, 3.0)
    (snap,) = sessions(rig)
    assert "\n" not in rig.meta(snap).notes["snapshot"]
    assert [e.key for e in rig.entries(snap)] == ["A"]


def test_the_ring_counts_bytes_and_keeps_only_the_newest_older_value() -> None:
    ring = SnapshotRing(seconds=1.0, memory=10**6)
    for k in range(10):
        msg = MoosMessage("V", float(k), float(k), "src")
        ring.add(float(k), float(k), msg)
    assert len(ring) == 2  # 8 and 9: the window is closed at its start
    older, first = ring.begin(9.0)
    assert [h[2].value for h in older] == [7.0]
    assert first == 8
    assert ring.bytes == 3 * sample_size(MoosMessage("V", 0.0, 0.0, "src"))
    assert [seq for seq, _ in ring.since(0, 100)] == [8, 9]
    assert [seq for seq, _ in ring.since(9, 100)] == [9]


@pytest.mark.parametrize(
    ("line", "error"),
    [
        ("SnapshotSeconds = soon", "SnapshotSeconds value 'soon'"),
        ("SnapshotSeconds = 0", "must be from 0.1 s to a day"),
        ("SnapshotSeconds = 5\nSnapshotMemory = 10", "must be at least 100000 bytes"),
        ("SnapshotSeconds = 5\nSnapshotMemory = 2 potatoes", "unknown unit"),
        ("SnapshotAfter = 5", "SnapshotAfter needs SnapshotSeconds"),
        ("SnapshotSeconds = 5\nSnapshotTrigger = ALARM", "is not VAR == value"),
        ("SnapshotSeconds = 5\nSnapshotTrigger = == 1", "is not a MOOS variable name"),
        ("SnapshotSeconds = 5\nSnapshotTrigger = A ==", "no printable value"),
        ("KeepSessions = 0", "must be a whole number from 1"),
        ("KeepSessions = ²", "must be a whole number from 1"),
        ("MaxLogSize = 10kB", "must be at least 1000000 bytes"),
        ("MinFreeDisk = -1GB", "MinFreeDisk value '-1GB'"),
    ],
)
def test_bad_settings_are_one_line_errors_naming_the_line(line: str, error: str) -> None:
    with pytest.raises(MissionError, match=r"t\.moos:") as info:
        config(f"File = R\n{line}")
    assert error in str(info.value)
    assert "\n" not in str(info.value)


def test_settings_are_read_with_units() -> None:
    cfg = config(
        "SnapshotSeconds = 2min\nSnapshotMemory = 1GiB\nSnapshotAfter = 10s\n"
        "SnapshotTrigger = ALARM == 1\nsnapshottrigger = MODE==FAULT\n"
        "MinFreeDisk = 2GB\nKeepSessions = 20\nMaxLogSize = 50GB"
    )
    assert cfg.snapshot is not None
    assert (cfg.snapshot.seconds, cfg.snapshot.memory, cfg.snapshot.after) == (120, 1 << 30, 10)
    assert cfg.snapshot.triggers == (Trigger("ALARM", 1.0), Trigger("MODE", "FAULT"))
    assert cfg.disk == DiskSettings(2 * 10**9, 20, 50 * 10**9)
    default = parse_mission("ProcessConfig = pLogger\n{\n}\n", "t.moos").logger_config("pLogger")
    assert default.snapshot is None
    assert default.disk == DiskSettings()
    assert parse_trigger("X == 1e3").value == 1000.0
    assert parse_trigger("X == 1.2.3").value == "1.2.3"


def test_a_flood_of_snapshots_starts_at_most_one_session_a_second(
    rigs: Callable[..., Rig],
) -> None:
    rig = rigs("File = R\nPath = logs\nLog = A @ 0\nSnapshotSeconds = 5")
    rig.rec.start()
    rig.send("A", 1.0, at=1.0)
    outcomes = []
    for k in range(40):  # 40 SNAPSHOTs in 2 s, each written and closed at once (no after)
        rig.send("PLOGGER_CMD", "SNAPSHOT", at=1.0 + k * 0.05)
        finish(rig, 1.0 + k * 0.05)
        outcomes.append(rig.rec.status()["commands"][-1])
    assert len(sessions(rig)) == 2
    refused = [o for o in outcomes if not o["ok"]]
    assert len(refused) == 38
    assert "at most one snapshot session a second" in refused[0]["why"]
    assert rig.rec.stats.refused_commands == 38
