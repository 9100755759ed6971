"""Fuzz targets for the recording modes' inputs (issue 17): what a peer or a mission may send.

Sizes and durations (``SplitSize``, ``--split-duration``), notes (``NOTE=key:value`` from any
MOOS app or Zenoh peer, ``Note =``, ``--note``), a flood of PAUSE/RESUME/SPLIT/NOTE commands,
mission blocks full of unknown or misspelt parameters, and the notes a hostile vehicle puts in
its sessions reply. Each must be taken within its bounds or refused in one sentence; the
recording carries on and its metadata stays valid and bounded.
"""

from __future__ import annotations

import json
import math
import shutil
import tempfile
from pathlib import Path
from typing import Any

from fuzzer import Fuzzer
from hostile import hostile_text, mission_texts, note_texts, plogger_cmds, sizes_and_durations
from hypothesis import strategies as st

from fleetlog.errors import FormatError, MissionError
from fleetlog.moos.mission import parse_mission
from fleetlog.moos.param_check import MAX_WARNINGS, check_logger_block
from fleetlog.moos.recording_modes import MAX_NOTES, check_note, parse_note
from fleetlog.moos.units import MAX_DURATION, MAX_SIZE, parse_duration, parse_size
from fleetlog.recorder.engine import Recorder
from fleetlog.storage.metafile import read_meta
from fleetlog.wire.control import MAX_TEXT
from fleetlog.wire.message import MoosMessage
from fleetlog.wire.replies import SessionInfo


def check_size_or_duration(text: str) -> None:
    for parse, high in ((parse_size, MAX_SIZE), (parse_duration, MAX_DURATION)):
        error: FormatError | None = None
        try:
            value = parse(text)
        except FormatError as err:
            error = err
        if error is not None:
            assert "\n" not in str(error)
            assert len(str(error)) < 300
            continue
        assert math.isfinite(value)
        assert 0 <= value <= high


def test_fuzz_size_and_duration(fuzz: Fuzzer) -> None:
    fuzz.run(sizes_and_durations, check_size_or_duration)


def check_note_text(text: str) -> None:
    error: FormatError | None = None
    try:
        key, value = parse_note(text)
    except FormatError as err:
        error = err
    if error is not None:
        assert "\n" not in str(error)
        return
    assert check_note(key, value) is None
    assert key.strip()
    assert len(key) <= 64
    assert len(value) <= 1024


def test_fuzz_note_text(fuzz: Fuzzer) -> None:
    fuzz.run(note_texts(), check_note_text)


class _Clock:
    def __init__(self) -> None:
        self.t = 1_800_000_000.0

    def __call__(self) -> float:
        return self.t


class _ModeRig:
    """A recorder taking a flood of mode commands, reused by every case of a run."""

    def __init__(self) -> None:
        self.where = Path(tempfile.mkdtemp(prefix="fleetlog-fuzz-"))
        (self.where / "logs").mkdir()
        self.clock = _Clock()
        cfg = parse_mission(
            f"ProcessConfig = pLogger\n{{\n  Path = {self.where / 'logs'}\n  SyncLog = true\n"
            "  Log = NAV_X @ 0\n  Note = site:bay\n}\n",
            "f.moos",
        ).logger_config()
        self.rec = Recorder(
            cfg, vehicle="V", publish=lambda msg: None, clock=self.clock, cwd=self.where
        )
        self.rec.start()
        self.began = self.clock.t
        self.sent = 0

    def probe(self) -> None:
        """A plain sample is logged unless paused; either way it is counted, never lost."""
        stats = self.rec.stats
        before = (stats.logged, stats.paused, stats.lost)
        self.rec.handle(MoosMessage("NAV_X", 1.0, self.clock.t, "iOk", "", "V"))
        self.sent += 1
        after = (stats.logged, stats.paused, stats.lost)
        if self.rec.status()["paused"]:
            assert after == (before[0], before[1] + 1, before[2])
        else:
            assert after == (before[0] + 1, before[1], before[2])
        self.rec.tick()

    def finish(self) -> tuple[int, int]:
        """Stop; check every part's metadata; return (parts, notes at most)."""
        self.rec.stop()
        dirs = [d for d in (self.where / "logs").iterdir() if d.is_dir()]
        most = 0
        for directory in dirs:
            meta = read_meta(directory)
            assert meta is not None
            assert meta.state == "closed"
            assert len(meta.notes) <= MAX_NOTES
            assert all(check_note(k, v) is None for k, v in meta.notes.items())
            most = max(most, len(meta.notes))
        # splits by command: at most one a second (plus the first session)
        assert len(dirs) <= int(self.clock.t - self.began) + 2
        assert self.rec.stats.lost == 0
        shutil.rmtree(self.where, ignore_errors=True)
        return len(dirs), most


def check_mode_command(rig: _ModeRig, value: str | float | bytes) -> None:
    rig.clock.t += 0.05
    before = rig.rec.stats.commands
    rig.rec.handle(MoosMessage("PLOGGER_CMD", value, rig.clock.t, "iEvil", "", "V"))
    assert rig.rec.stats.commands == before + 1
    last = rig.rec.commands.recent()[-1]
    assert last["ok"] or last["why"]
    rig.probe()


def test_fuzz_mode_commands(fuzz: Fuzzer) -> None:
    rig = _ModeRig()
    modes = st.sampled_from(["PAUSE", "RESUME", "SPLIT", " resume"])
    try:
        fuzz.run(
            modes | plogger_cmds() | note_texts().map(lambda t: "NOTE=" + t),
            lambda value: check_mode_command(rig, value),
        )
    finally:
        parts, notes = rig.finish()
    fuzz.note(f"{parts} parts, at most {notes} notes on one")


def check_restart_value(rig: _ModeRig, value: str | float | bytes) -> None:
    """Any LOGGER_RESTART value: run or throttled (0.5 s), counted, one bounded ring line."""
    rig.clock.t += 0.3  # every other one inside the 0.5 s of the last that ran
    before = rig.rec.stats.commands
    rig.rec.handle(MoosMessage("LOGGER_RESTART", value, rig.clock.t, "iEvil", "", "V"))
    assert rig.rec.stats.commands == before + 1
    last = rig.rec.commands.recent()[-1]
    assert last["ok"] or last["why"]
    assert len(last["text"]) <= MAX_TEXT
    rig.probe()


def test_fuzz_restart_values(fuzz: Fuzzer) -> None:
    rig = _ModeRig()
    values = st.text(max_size=300) | st.floats() | st.binary(max_size=1 << 16)
    try:
        fuzz.run(values, lambda value: check_restart_value(rig, value))
    finally:
        rig.rec.stop()
        parts = [d for d in (rig.where / "logs").iterdir() if d.is_dir()]
        assert len(parts) <= 2 * (rig.clock.t - rig.began) + 2  # one restart per 0.5 s
        assert rig.rec.stats.lost == 0
        shutil.rmtree(rig.where, ignore_errors=True)
    fuzz.note(f"{len(parts)} sessions, {rig.rec.stats.throttled} restarts throttled")


def check_mission_warnings(text: str) -> None:
    error: MissionError | None = None
    try:
        mission = parse_mission(text, "m.moos")
        mission.logger_config()
    except MissionError as err:
        error = err
    if error is not None:
        assert "\n" not in str(error)
        assert str(error).startswith("m.moos")
        return
    warnings = check_logger_block(mission.block("pLogger"), "m.moos")
    assert len(warnings) <= MAX_WARNINGS
    for warning in warnings:
        assert str(warning).startswith("m.moos")
        assert "\n" not in str(warning)
        assert len(str(warning)) < 400


def test_fuzz_mission_warnings(fuzz: Fuzzer) -> None:
    fuzz.run(mission_texts(), check_mission_warnings)


_hostile_notes: st.SearchStrategy[Any] = st.one_of(
    st.dictionaries(hostile_text, hostile_text | st.integers() | st.none(), max_size=80),
    st.lists(hostile_text, max_size=5),
    hostile_text,
    st.none(),
)


def check_session_reply(case: tuple[Any, Any]) -> None:
    notes, tags = case
    obj = {"name": "S", "files": [], "complete": True, "notes": notes, "tags": tags}
    info = SessionInfo.from_json(json.loads(json.dumps(obj)))
    assert len(info.notes) <= MAX_NOTES
    assert all(check_note(k, v) is None for k, v in info.notes.items())
    assert len(info.tags) <= 64
    assert all(t.isprintable() and len(t) <= 64 for t in info.tags)


def test_fuzz_session_notes_reply(fuzz: Fuzzer) -> None:
    fuzz.run(
        st.tuples(_hostile_notes, _hostile_notes | st.lists(hostile_text)), check_session_reply
    )
