"""Recording modes in the engine: split, pause and resume, notes (fake clock, real files).

A split closes the open session and opens the next part of its mission between two samples:
each sample is in exactly one part, the parts share the mission id and LOGSTART, and the hint
file names the newest. While paused nothing is written and what is not written is counted as
``paused``, never as lost.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest
from recorder_support import T0, Rig, config, rigs

from fleetlog.errors import MissionError
from fleetlog.storage.metafile import read_meta
from fleetlog.wire.session_meta import META_NAME

__all__ = ["rigs"]  # the fixture, imported


def parts(tmp_path: Path) -> list[Path]:
    """The session directories, in part order (from their metadata)."""
    dirs = [d for d in (tmp_path / "logs").iterdir() if d.is_dir()]
    metas = {d: read_meta(d) for d in dirs}
    return sorted(dirs, key=lambda d: metas[d].part)  # type: ignore[union-attr]


def values(rig: Rig, directory: Path, name: str = "A") -> list[float | str | bytes]:
    return [e.value for e in rig.entries(directory) if e.key == name]


def test_a_split_command_cuts_between_two_samples(tmp_path: Path, rigs: Callable[..., Rig]) -> None:
    rig = rigs("File = R\nPath = logs\nLog = A @ 0\nLog = B @ 0\nSyncLog = true @ 0.2")
    rig.rec.start()
    first = rig.dir
    for i in range(5):
        rig.send("A", float(i), at=1.0 + i * 0.1)
    rig.send("PLOGGER_CMD", "SPLIT", at=2.0)
    second = rig.dir
    assert second != first
    for i in range(5, 10):
        rig.send("A", float(i), at=2.0 + i * 0.1)
    rig.clock.t = T0 + 4.0
    rig.rec.tick()
    assert values(rig, first) == [0.0, 1.0, 2.0, 3.0, 4.0]
    assert values(rig, second) == [5.0, 6.0, 7.0, 8.0, 9.0]
    one, two = rig.meta(first), rig.meta(second)
    assert one.state == "closed"
    assert two.state == "open"
    assert (one.part, two.part) == (1, 2)
    assert one.mission_id == two.mission_id != ""
    assert one.logstart == two.logstart  # the parts read as one log
    # the hint names the new part; its slog repeats the header
    hint = (tmp_path / ".LastOpenedMOOSLogDirectory").read_text()
    assert second.name in hint
    for part in (first, second):
        lines = (part / f"{part.name}.slog").read_text().splitlines()
        assert lines[3].startswith("%% LOGSTART")
        assert lines[3] == (first / f"{first.name}.slog").read_text().splitlines()[3]
        assert any(line.split()[1:4] == ["TIME", "A", "B"] for line in lines if line[:2] == "%%")
    ring = rig.rec.status()["commands"]
    assert (ring[-1]["via"], ring[-1]["cmd"], ring[-1]["ok"]) == ("PLOGGER_CMD", "split", True)
    assert rig.rec.stats.lost == 0


def test_split_commands_are_taken_at_most_once_a_second(rigs: Callable[..., Rig]) -> None:
    rig = rigs()
    rig.rec.start()
    assert rig.control({"cmd": "split"}).ok
    too_soon = rig.control({"cmd": "split"})
    assert not too_soon.ok
    assert "at most one a second" in (too_soon.why or "")
    rig.clock.t += 1.0
    assert rig.control({"cmd": "split"}).extra["part"] == 3


def test_a_restart_begins_a_new_mission(rigs: Callable[..., Rig]) -> None:
    rig = rigs()
    rig.rec.start()
    first = rig.meta()
    rig.send("LOGGER_RESTART", "true", at=1.0)
    second = rig.meta()
    assert second.mission_id != first.mission_id
    assert second.part == 1


def test_split_by_duration(tmp_path: Path, rigs: Callable[..., Rig]) -> None:
    rig = rigs("File = R\nPath = logs\nLog = A @ 0\nSplitDuration = 2s")
    rig.rec.start()
    for i in range(50):
        rig.send("A", float(i), at=i * 0.1)
        rig.rec.tick()
    found = parts(tmp_path)
    assert len(found) == 3  # cut at 2 s and 4 s
    got = [v for d in found for v in values(rig, d)]
    assert got == [float(i) for i in range(50)]
    # each sample, then the tick that sees the duration reached
    assert [len(values(rig, d)) for d in found] == [21, 20, 9]


def test_split_by_size_on_disk(tmp_path: Path, rigs: Callable[..., Rig]) -> None:
    rig = rigs("File = R\nPath = logs\nLog = A @ 0\nSplitSize = 1MB")
    rig.rec.start()
    text = "x" * 100
    count = 25_000  # about 3 MB of lines
    for i in range(count):
        rig.send("A", f"{i} {text}", at=1.0 + i * 1e-4)
        if i % 100 == 0:
            rig.rec.tick()
    rig.rec.tick()
    found = parts(tmp_path)
    assert len(found) >= 3
    for closed in found[:-1]:
        size = sum(f.stat().st_size for f in closed.iterdir() if f.name != META_NAME)
        # cut at the first tick that sees 1 MB on disk: over it by a tick's lines at most
        assert 1_000_000 <= size <= 1_000_000 + 100 * 130 + 4096
    got = [v for d in found for v in values(rig, d)]
    assert got == [f"{i} {text}" for i in range(count)]


def test_pause_writes_nothing_and_counts_what_it_did_not_write(rigs: Callable[..., Rig]) -> None:
    rig = rigs()
    rig.rec.start()
    rig.send("A", 1.0, at=1.0)
    rig.send("PLOGGER_CMD", "PAUSE", at=2.0)
    status = rig.rec.status()
    assert status["paused"] is True
    for i in range(10):
        rig.send("A", float(100 + i), at=3.0 + i * 0.01)
    rig.clock.t = T0 + 5.0
    rig.rec.tick()
    rig.send("PLOGGER_CMD", " resume ", at=6.0)
    rig.send("A", 2.0, at=7.0)
    entries = rig.entries()
    assert [e.value for e in entries if e.key == "A"] == [1.0, 2.0]
    marks = [str(e.value) for e in entries if e.key == "PLOGGER_PAUSE"]
    assert marks[0] == "paused"
    assert marks[1].startswith("resumed,unwritten=")
    stats = rig.rec.stats
    unwritten = int(marks[1].split(",")[1].split("=")[1])
    assert unwritten == stats.paused >= 10  # the samples and the recorder's own posts
    assert stats.lost == 0
    assert rig.rec.status()["paused"] is False
    rig.clock.t = T0 + 9.0
    rig.rec.tick()
    assert rig.meta().counters["paused"] == stats.paused
    assert "Paused=" in rig.rec.status_text(rig.clock.t)


def test_start_paused_and_idempotent_commands(rigs: Callable[..., Rig]) -> None:
    rig = rigs("File = R\nPath = logs\nLog = A @ 0\nStartPaused = true")
    rig.rec.start()
    rig.send("A", 1.0, at=1.0)
    again = rig.control({"cmd": "pause"})
    assert (again.ok, again.did) == (True, "recording was paused already")
    assert rig.control({"cmd": "resume"}).ok
    assert rig.control({"cmd": "resume"}).did == "recording was not paused"
    rig.send("A", 2.0, at=2.0)
    assert [e.value for e in rig.entries() if e.key == "A"] == [2.0]


def test_notes_from_the_mission_and_at_runtime(tmp_path: Path, rigs: Callable[..., Rig]) -> None:
    rig = rigs(
        "File = R\nPath = logs\nLog = A @ 0\nNote = site: the bay\nNote = crew:2\n"
        "Tag = trial, night\nTag = trial"
    )
    rig.rec.start()
    assert rig.meta().notes == {"site": "the bay", "crew": "2"}
    assert rig.meta().tags == ("trial", "night")
    rig.send("PLOGGER_CMD", "NOTE = event : hit a buoy: no damage", at=1.0)
    assert rig.meta().notes["event"] == "hit a buoy: no damage"
    rig.clock.t += 2
    assert rig.control({"cmd": "split"}).ok
    assert rig.meta().notes["event"] == "hit a buoy: no damage"  # the mission's next part
    rig.send("LOGGER_RESTART", "true", at=5.0)
    assert rig.meta().notes == {"site": "the bay", "crew": "2"}  # a new mission
    bad = rig.control({"cmd": "note", "key": "k\x07", "value": "v"})
    assert (bad.ok, bad.why) == (False, "a note's key must be printable text")
    rig.send("PLOGGER_CMD", "NOTE=nokey", at=6.0)
    ring = rig.rec.status()["commands"]
    assert (ring[-1]["cmd"], ring[-1]["ok"]) == ("note", False)
    assert "key:value" in ring[-1]["why"]


def test_split_needs_time_stamped_names(rigs: Callable[..., Rig]) -> None:
    rig = rigs("File = R\nPath = logs\nLog = A @ 0\nFileTimeStamp = false")
    rig.rec.start()
    out = rig.control({"cmd": "split"})
    assert not out.ok
    assert "FileTimeStamp = false" in (out.why or "")


@pytest.mark.parametrize(
    ("line", "message"),
    [
        ("SplitSize = 10", "below the smallest part, 1MB"),
        ("SplitSize = 5 5", "is not a number with an optional unit"),
        ("SplitSize = 5 furlongs", "unknown unit 'furlongs'"),
        ("SplitDuration = 0.5", "below the shortest part, 1s"),
        ("SplitDuration = 1e9h", "is too long"),
        ("Note = nocolon", "is not key:value"),
        ("Note = :v", "a note needs a key"),
    ],
)
def test_bad_mode_settings_name_the_line(line: str, message: str) -> None:
    with pytest.raises(MissionError, match=r"^t\.moos:\d+: ") as err:
        config(f"File = R\n{line}")
    assert message in str(err.value)
