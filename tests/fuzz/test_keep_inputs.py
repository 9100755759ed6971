"""Fuzz the inputs of snapshot mode and the disk's bounds (issue 17).

* mission settings (``SnapshotSeconds``... ``MaxLogSize``) and the command-line options: a
  one-line error naming the file and line (or the option), or values in range;
* ``SnapshotTrigger`` text: a :class:`FormatError`, or a trigger that reads back the same;
* a long-lived snapshot-mode recorder fed hostile samples, trigger writes, PLOGGER_CMD
  (``SNAPSHOT`` among garbage) and control requests: no exception, every command answered
  with a why when refused, the ring under its memory bound, every sample held, written or
  counted, and nothing in the sessions but what was sent.
"""

from __future__ import annotations

import json
import math
import shutil
import tempfile
from pathlib import Path
from typing import Any

from alog_oracle import iter_entries
from fuzzer import Fuzzer
from hostile import keep_missions, snapshot_events, triggers
from hypothesis import strategies as st

from fleetlog.errors import FormatError, MissionError
from fleetlog.moos.keep_settings import (
    MAX_SNAPSHOT_SECONDS,
    MIN_SNAPSHOT_MEMORY,
    DiskSettings,
    parse_trigger,
    with_disk_options,
    with_snapshot_options,
)
from fleetlog.moos.mission import parse_mission
from fleetlog.recorder.engine import Recorder
from fleetlog.wire.control import Outcome, parse_control_request
from fleetlog.wire.fields import clean_name
from fleetlog.wire.message import MoosMessage

T0 = 1_800_000_000.25
MEMORY = 200_000


def check_keep_mission(text: str) -> None:
    try:
        cfg = parse_mission(text, "m.moos").logger_config()
    except MissionError as err:
        error = str(err)
    else:
        error = None
    if error is not None:
        assert "\n" not in error
        assert error.startswith("m.moos:")
        return
    snap = cfg.snapshot
    if snap is not None:
        assert 0.1 <= snap.seconds <= MAX_SNAPSHOT_SECONDS
        assert 0.0 <= snap.after <= MAX_SNAPSHOT_SECONDS
        assert snap.memory >= MIN_SNAPSHOT_MEMORY
        for trigger in snap.triggers:
            assert parse_trigger(trigger.text()) == trigger
    disk = cfg.disk
    assert disk.min_free >= 0
    assert disk.keep_sessions is None or disk.keep_sessions >= 1
    assert disk.max_log_size is None or disk.max_log_size >= 10**6


def test_fuzz_keep_mission(fuzz: Fuzzer) -> None:
    fuzz.run(keep_missions(), check_keep_mission)


def check_trigger(text: str) -> None:
    try:
        trigger = parse_trigger(text)
    except FormatError as err:
        error = str(err)
    else:
        error = None
    if error is not None:
        assert "\n" not in error
        return
    assert trigger.var
    assert trigger.var.isascii()
    if isinstance(trigger.value, float):
        assert math.isfinite(trigger.value)
    else:
        assert trigger.value.isprintable()
    assert parse_trigger(trigger.text()) == trigger


def test_fuzz_trigger(fuzz: Fuzzer) -> None:
    fuzz.run(triggers, check_trigger)


_OPTION_TEXT = st.sampled_from(
    ["0", "1", "30s", "2min", "256MB", "1e400", "-1", "x", ""]
) | st.text(max_size=12)


def check_keep_options(case: tuple[Any, ...]) -> None:
    seconds, memory, after, trigger, free, keep, size = case
    try:
        snap = with_snapshot_options(
            None, seconds=seconds, memory=memory, after=after, triggers=[trigger] if trigger else []
        )
        disk = with_disk_options(
            DiskSettings(), min_free=free, keep_sessions=keep, max_log_size=size
        )
    except FormatError as err:
        error = str(err)
    else:
        error = None
    if error is not None:
        assert "\n" not in error
        assert "--" in error  # names the option
        return
    if snap is not None:
        assert 0.1 <= snap.seconds <= MAX_SNAPSHOT_SECONDS
        assert snap.memory >= MIN_SNAPSHOT_MEMORY
    assert disk.keep_sessions is None or disk.keep_sessions >= 1


def test_fuzz_keep_options(fuzz: Fuzzer) -> None:
    texts = st.none() | _OPTION_TEXT
    fuzz.run(
        st.tuples(
            texts, texts, texts, st.none() | triggers, texts, st.none() | st.integers(), texts
        ),
        check_keep_options,
    )


class _Clock:
    def __init__(self) -> None:
        self.t = T0

    def __call__(self) -> float:
        return self.t


#: the entries the recorder writes of its own: losses, pauses (a PAUSE command), parameters
_OWN_MARKS = ("PLOGGER_GAP", "PLOGGER_PAUSE", "PLOGGER_PARAMETERS")


class _SnapshotRig:
    """A snapshot-mode recorder reused by every case of a run (its ring wraps, as in a flood)."""

    def __init__(self) -> None:
        self.where = Path(tempfile.mkdtemp(prefix="fleetlog-fuzz-"))
        self.clock = _Clock()
        (self.where / "logs").mkdir()
        cfg = parse_mission(
            f"ProcessConfig = pLogger\n{{\n  Path = {self.where / 'logs'}\n  SyncLog = true\n"
            f"  SnapshotSeconds = 1\n  SnapshotMemory = {MEMORY}\n  SnapshotAfter = 0.5\n"
            "  SnapshotTrigger = ALARM == 1\n  MinFreeDisk = 0\n}\n",
            "f.moos",
        ).logger_config()
        self.rec = Recorder(
            cfg, vehicle="V", publish=lambda msg: None, clock=self.clock, cwd=self.where
        )
        self.rec.start()
        self.names: set[str] = set()

    def run(self, events: list[tuple[str, Any, Any]]) -> None:
        rec = self.rec
        for kind, name, value in events:
            if kind == "tick":
                self.clock.t += value
                rec.tick()
            elif kind == "control":
                try:
                    request = parse_control_request(value, "")
                except FormatError:
                    continue
                replies: list[Outcome] = []
                rec.commands.submit(request, replies.append)
                while rec.commands.pending:
                    rec.commands.run_queued()
                (reply,) = replies
                assert reply.ok or reply.why
            else:
                self.clock.t += 0.001
                if kind == "sample":
                    name, _ = clean_name(name)
                    value, stamp = value
                else:
                    stamp = self.clock.t
                self.names.add(name)
                before = rec.stats.commands
                rec.handle(MoosMessage(name, value, stamp, "iEvil", "", "V"))
                if kind == "cmd":
                    assert rec.stats.commands == before + 1
                    last = rec.commands.recent()[-1]
                    assert last["ok"] or last["why"]
            ring = rec._snap.ring  # type: ignore[union-attr]
            assert ring.bytes <= MEMORY
        status = rec.status()
        json.dumps(status)  # the status reply is always JSON
        snap = status["snapshot"]
        assert snap["held"] >= snap["samples"]
        assert snap["evicted"] <= snap["held"]

    def check_sessions(self) -> None:
        rec = self.rec
        rec.stop()
        found = sorted(p for p in (self.where / "logs").iterdir() if p.is_dir())
        assert not [p for p in self.where.iterdir() if p.is_dir() and p.name != "logs"]
        assert len(found) == rec.status()["snapshot"]["snapshots"]
        for directory in found:
            alog = directory / f"{directory.name}.alog"
            with open(alog, encoding="utf-8", errors="surrogateescape", newline="") as f:
                for entry in iter_entries(f):
                    # only what was sent, and the recorder's own marks: nothing forged
                    assert entry.key in self.names or entry.key in _OWN_MARKS, entry
        shutil.rmtree(self.where, ignore_errors=True)


def test_fuzz_snapshot_recorder(fuzz: Fuzzer) -> None:
    rig = _SnapshotRig()
    try:
        fuzz.run(snapshot_events(), rig.run)
    finally:
        rig.check_sessions()
    snap = rig.rec.status()["snapshot"]
    fuzz.note(
        f"{snap['snapshots']:,} snapshots, {snap['evicted']:,} evicted, {snap['lost']:,} lost"
    )
