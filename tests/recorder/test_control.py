"""The one command handler and the session metadata, in the engine (fake clock, real files).

The same handler serves PLOGGER_CMD, LOGGER_RESTART and the control service; each outcome
lands in the ring the status reply lists. The metadata file follows the session: ``open``
when it opens, rewritten while it is, ``closed`` at a clean close and never touched again.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import pytest
from alog_oracle import iter_entries
from recorder_support import DIGEST, T0, Rig, rigs

from fleetlog.moos.alog import Entry, LineFormatter, format_banner
from fleetlog.recorder.control import QUEUE_LIMIT, RING_SIZE
from fleetlog.storage.metafile import boot_id, host_name, recorder_alive, write_meta
from fleetlog.wire.control import MAX_TEXT, ControlRequest, Outcome
from fleetlog.wire.session_meta import ACKS_NAME, META_NAME, SessionMeta

__all__ = ["rigs"]  # the fixture, imported


def test_moos_commands_keep_their_debug_text_and_land_in_the_ring(
    tmp_path: Path, rigs: Callable[..., Rig]
) -> None:
    rig = rigs()
    rig.rec.start()
    (tmp_path / "mission" / "a.txt").write_text("hi")
    rig.debugs()
    rig.send("PLOGGER_CMD", "LOG_REQUEST = B @ 0", at=1.0)
    rig.send("PLOGGER_CMD", "LOG_REQUEST = B @ 0", at=1.5)
    rig.send("PLOGGER_CMD", "COPY_FILE_REQUEST = /etc/hostname", at=2.0)
    rig.send("PLOGGER_CMD", "COPY_FILE_REQUEST = mission/a.txt", at=2.5)
    rig.send("PLOGGER_CMD", 3.0, at=3.0)
    rig.send("PLOGGER_CMD", "FROB = 1", at=3.5)
    assert rig.debugs() == [
        "failed to process dynamic log request  - see pLogger output\n",
        "refused COPY_FILE_REQUEST for /etc/hostname: outside the directories the recorder "
        "may copy from",
        "PLOGGER_CMD must be a string, got a double: ignored",
        "Dynamic command FROB is not supported",
    ]
    rig.send("LOGGER_RESTART", "true", at=4.0)
    ring = rig.rec.status()["commands"]
    assert [(r["via"], r["cmd"], r["ok"]) for r in ring] == [
        ("PLOGGER_CMD", "log_request", True),
        ("PLOGGER_CMD", "log_request", False),
        ("PLOGGER_CMD", "copy_file", False),
        ("PLOGGER_CMD", "copy_file", True),
        ("PLOGGER_CMD", "?", False),
        ("PLOGGER_CMD", "frob", False),
        ("LOGGER_RESTART", "restart", True),
    ]
    assert ring[0] == {
        "time": T0 + 1.0,
        "via": "PLOGGER_CMD",
        "source": "iOps",
        "cmd": "log_request",
        "text": "LOG_REQUEST = B @ 0",
        "ok": True,
        "did": "now logging B",
        "why": None,
    }
    assert ring[1]["why"] == "B is logged already"
    assert ring[3]["did"] == "copying mission/a.txt to a._txt"
    assert ring[4]["text"] == "3.0"
    assert ring[6]["did"] == f"started session {rig.rec.session.root}"  # type: ignore[union-attr]
    stats = rig.rec.stats
    assert (stats.commands, stats.refused_commands) == (7, 4)


def test_a_restart_inside_half_a_second_of_the_last_is_refused_in_the_ring(
    rigs: Callable[..., Rig],
) -> None:
    """pLogger registers LOGGER_RESTART at 0.5 s: a second one that soon is not run, as its
    MOOSDB would not deliver it, but the ring says so (poke reports it) and it is counted."""
    rig = rigs()
    rig.rec.start()
    rig.send("LOGGER_RESTART", "true", at=1.0)
    second = rig.dir
    rig.debugs()
    rig.send("LOGGER_RESTART", "true", at=1.3, source="uPoke")
    assert rig.dir == second  # not run
    assert rig.debugs() == []  # no MOOS_DEBUG per throttled command (a flood stays one)
    last = rig.rec.status()["commands"][-1]
    assert (last["via"], last["cmd"], last["ok"], last["source"]) == (
        "LOGGER_RESTART",
        "restart",
        False,
        "uPoke",
    )
    assert (
        last["why"] == "LOGGER_RESTART is taken at most once every 0.5 s (as pLogger registers it)"
    )
    stats = rig.rec.stats
    assert (stats.throttled, stats.commands, stats.refused_commands) == (1, 2, 1)
    rig.send("LOGGER_RESTART", "true", at=1.6)  # 0.6 s after the one that ran
    assert rig.dir != second


@pytest.mark.parametrize("size", [10, 256, 257, 1 << 20])
def test_a_binary_commands_ring_text_is_its_repr_cut_to_the_records_size(
    rigs: Callable[..., Rig], size: int
) -> None:
    """Run or throttled, a binary LOGGER_RESTART shows in the ring as ``repr`` of its bytes,
    cut to what a record holds (the cut made before the whole value is written out)."""
    rig = rigs()
    rig.rec.start()
    value = bytes(range(256)) * (size // 256) + bytes(range(size % 256))
    rig.send("LOGGER_RESTART", value, at=1.0)
    rig.send("LOGGER_RESTART", value, at=1.2)  # throttled
    whole = repr(value)
    expected = whole if len(whole) <= MAX_TEXT else whole[: MAX_TEXT - 1] + "…"
    ran, throttled = rig.rec.status()["commands"][-2:]
    assert (ran["ok"], throttled["ok"]) == (True, False)
    assert ran["text"] == throttled["text"] == expected


def test_the_ring_keeps_the_last_64(tmp_path: Path, rigs: Callable[..., Rig]) -> None:
    rig = rigs()
    rig.rec.start()
    for i in range(RING_SIZE + 10):
        rig.send("PLOGGER_CMD", f"X{i} = 1", at=1.0)
    ring = rig.rec.status()["commands"]
    assert len(ring) == RING_SIZE
    assert ring[0]["cmd"] == "x10"
    assert ring[-1]["cmd"] == f"x{RING_SIZE + 9}"


def test_control_requests_go_through_the_same_handler(
    tmp_path: Path, rigs: Callable[..., Rig]
) -> None:
    rig = rigs()
    rig.rec.start()
    (tmp_path / "mission" / "notes.txt").write_text("n")
    rig.debugs()
    first = rig.rec.session
    assert rig.control({"cmd": "log_request", "spec": "NAV_X @ 0", "source": "ops"}).ok
    again = rig.control({"cmd": "log_request", "spec": "NAV_X @ 0"})
    assert (again.ok, again.why) == (False, "NAV_X is logged already")
    # the same MOOS_DEBUG as the PLOGGER_CMD path
    assert rig.debugs() == ["failed to process dynamic log request  - see pLogger output\n"]
    copied = rig.control({"cmd": "copy_file", "path": "mission/notes.txt"})
    assert (copied.ok, copied.did) == (True, "copying mission/notes.txt to notes._txt")
    assert (rig.dir / "notes._txt").read_text() == "n"
    noted = rig.control({"cmd": "note", "key": "site", "value": "bay"})
    assert noted.ok
    assert rig.meta().notes == {"site": "bay"}
    assert rig.control({"cmd": "pause"}).extra["paused"] is True
    assert rig.control({"cmd": "resume"}).extra["paused"] is False
    rig.clock.t += 2.0
    split = rig.control({"cmd": "split"})
    assert (split.ok, split.extra["part"]) == (True, 2)
    out = rig.control({"cmd": "snapshot"})
    assert (out.ok, out.why) == (
        False,
        "the recorder is not in snapshot mode (SnapshotSeconds is not set)",
    )
    status = rig.control({"cmd": "status"})
    assert status.ok
    assert status.extra["vehicle"] == "alpha"
    restarted = rig.control({"cmd": "restart", "time": 12.0})
    assert restarted.ok
    assert rig.rec.session is not first
    assert restarted.extra["session"] == rig.rec.session.root  # type: ignore[union-attr]
    ring = rig.rec.status()["commands"]
    # status polls do not fill the ring; the request's own time is kept
    assert [r["cmd"] for r in ring] == [
        "log_request",
        "log_request",
        "copy_file",
        "note",
        "pause",
        "resume",
        "split",
        "snapshot",
        "restart",
    ]
    assert ring[0]["source"] == "ops"
    assert ring[-1]["time"] == 12.0
    assert json.loads(ring[-1]["text"]) == {"cmd": "restart", "time": 12.0}


def test_malformed_requests_are_counted_and_a_full_queue_refuses_at_once(
    tmp_path: Path, rigs: Callable[..., Rig]
) -> None:
    rig = rigs()
    rig.rec.start()
    rig.rec.commands.refuse_request('{"cmd": 1}', "the request names no command ('cmd')")
    got: list[Outcome] = []
    for _ in range(QUEUE_LIMIT + 3):
        rig.rec.commands.submit(ControlRequest("note", {"key": "k", "value": "v"}), got.append)
    # the first QUEUE_LIMIT wait for the drain thread; the others are refused now
    assert [o.ok for o in got] == [False] * 3
    assert got[0].why is not None
    assert "busy" in got[0].why
    while rig.rec.commands.pending:
        rig.rec.commands.run_queued()
    assert [o.ok for o in got[3:]] == [True] * QUEUE_LIMIT
    stats = rig.rec.stats
    assert (stats.commands, stats.refused_commands) == (QUEUE_LIMIT + 4, 4)


def test_the_recorder_tells_when_its_session_opens_or_closes(rigs: Callable[..., Rig]) -> None:
    """What a log server's warmer waits on (instead of looking every 2 s)."""
    rig = rigs()
    changes = rig.rec.session_changes
    assert not changes.is_set()
    rig.rec.start()
    assert changes.is_set()
    changes.clear()
    rig.send("A", 1.0, at=0.5)
    rig.clock.t = T0 + 2.5
    rig.rec.tick()
    assert not changes.is_set()  # writing is no change
    rig.send("LOGGER_RESTART", "now", at=3.0)
    assert changes.is_set()
    changes.clear()
    rig.rec.stop()
    assert changes.is_set()


def test_metadata_follows_the_session_and_never_changes_once_closed(
    tmp_path: Path, rigs: Callable[..., Rig]
) -> None:
    rig = rigs()
    rig.rec.start()
    first = rig.dir
    meta = rig.meta()
    assert (meta.state, meta.vehicle, meta.session, meta.recorder) == (
        "open",
        "alpha",
        first.name,
        "zid-1",
    )
    assert (meta.opened, meta.logstart, meta.closed, meta.part) == (T0, T0, None, 1)
    assert (meta.host, meta.pid, meta.boot) == (host_name(), os.getpid(), boot_id())
    assert len(meta.mission_id) == 32
    for i in range(5):
        rig.send("A", float(i), at=0.5)
    rig.clock.t = T0 + 2.5
    rig.rec.tick()  # counters changed: rewritten
    assert rig.meta().counters["logged"] == 5
    assert rig.meta().updated == T0 + 2.5
    rig.send("LOGGER_RESTART", "now", at=3.0)
    closed = rig.meta(first)
    assert (closed.state, closed.closed) == ("closed", T0 + 3.0)
    assert closed.counters["logged"] == 5
    assert closed.counters["received"] == 6  # the restart itself came in this session
    frozen = (first / META_NAME).read_bytes()
    second = rig.dir
    assert rig.meta().state == "open"
    assert rig.meta().mission_id != closed.mission_id
    rig.send("A", 9.0, at=4.0)
    rig.clock.t = T0 + 9.0
    rig.rec.tick()
    rig.rec.stop()
    assert rig.meta(second).state == "closed"
    assert rig.meta(second).counters["logged"] == 1
    assert (first / META_NAME).read_bytes() == frozen
    assert sorted(p.name for p in first.iterdir() if p.name.startswith(".")) == [META_NAME]


def _dead_session(tmp_path: Path, alog: str, updated: float) -> tuple[Path, SessionMeta]:
    """R_OLD, left open by a recorder that died (nobody holds its lock), opened at T0 - 100."""
    dead = tmp_path / "logs" / "R_OLD"
    dead.mkdir(parents=True)
    (dead / "R_OLD.alog").write_text(alog)
    crashed = SessionMeta(
        state="open",
        vehicle="alpha",
        session="R_OLD",
        recorder="zid-0",
        fleetlog="0",
        opened=T0 - 100,
        logstart=T0 - 100,
        updated=updated,
        host=host_name(),
        pid=os.getpid(),
        boot=boot_id(),
    )
    write_meta(dead, crashed)
    return dead, crashed


def _first_entry_of_the_next_session(tmp_path: Path) -> Entry:
    (session,) = [d for d in (tmp_path / "logs").iterdir() if d.name != "R_OLD"]
    with open(session / f"{session.name}.alog", encoding="utf-8") as f:
        return next(iter_entries(f))


def test_a_session_left_open_by_a_dead_recorder_is_cut_and_marked_in_the_next(
    tmp_path: Path, rigs: Callable[..., Rig]
) -> None:
    rig = rigs()
    dead, crashed = _dead_session(tmp_path, "", updated=T0 - 50)
    rig.rec.start()
    cut = rig.meta(dead)
    assert (cut.state, cut.closed) == ("cut", T0)
    # ``updated`` stays the last sign of life of its own recorder
    assert cut == replace(crashed, state="cut", closed=T0)
    rig.rec.stop()
    assert (dead / "R_OLD.alog").read_text() == ""  # only its metadata is touched
    first = _first_entry_of_the_next_session(tmp_path)
    assert (first.key, first.source) == ("PLOGGER_GAP", "pLogger")
    assert first.value == f"reason=crash,lost=?,from={T0 - 50:.3f},to={T0:.3f},session=R_OLD"
    (session,) = [d for d in (tmp_path / "logs").iterdir() if d.name != "R_OLD"]
    assert rig.meta(session).gaps[0].reason == "crash"


def _wildcard_rig(rigs: Callable[..., Rig], more: str) -> Rig:
    """A started wildcard recorder whose metadata was rewritten at T0 + 0.1 (the first time)."""
    rig = rigs(f"File = R\nPath = logs\nWildcardLogging = true\n{more}")
    rig.rec.start()
    rig.clock.t = T0 + 0.1
    rig.rec.tick()
    return rig


def test_an_idle_recorder_rewrites_its_metadata_every_10_s_a_busy_one_every_2_s(
    rigs: Callable[..., Rig],
) -> None:
    """Idle: only the recorder's own status lines (1 every 2 s); busy: more than 8 lines."""
    rig = _wildcard_rig(rigs, "")
    written = []
    for step in range(1, 16):  # 30 s of an idle recorder: a status line every 2 s
        rig.send("PLOGGER_STATUS", f"Uptime={2 * step}", at=2.0 * step, source="pLogger")
        rig.rec.tick()
        written.append(rig.meta().updated - T0)
    assert sorted(set(written)) == [pytest.approx(t) for t in (0.1, 10.0, 20.0, 30.0)]
    for i in range(9):  # a stream starts: the 2 s rewrite again
        rig.send("A", float(i), at=31.0)
    rig.clock.t = T0 + 32.0
    rig.rec.tick()
    assert rig.meta().updated == T0 + 32.0
    assert rig.meta().counters["logged"] == 15 + 9


def test_the_metadata_of_a_compressed_idle_log_is_rewritten_every_2_s(
    rigs: Callable[..., Rig],
) -> None:
    """A compressed alog's tail is not read after a crash: its file is the sign of life."""
    rig = _wildcard_rig(rigs, "CompressAlogs = true")
    rig.send("PLOGGER_STATUS", "Uptime=2", at=2.0, source="pLogger")
    rig.rec.tick()
    assert rig.meta().updated == T0 + 2.0


def test_a_crash_gap_starts_at_the_dead_recorders_last_status_line(
    tmp_path: Path, rigs: Callable[..., Rig]
) -> None:
    """Its metadata was rewritten 9 s before it died; its status lines went on to the end."""
    rig = rigs()
    start = T0 - 100
    fmt = LineFormatter()
    lines = [format_banner("./R_OLD/R_OLD.alog", start, "then")]
    for t in (40.0, 42.0, 44.0, 46.0, 48.0, 50.0):
        lines.append(fmt.string(t, "PLOGGER_STATUS", "pLogger", f"Uptime={t}"))
    lines.append(fmt.string(99.9, "PLOGGER_STATUS", "pOther", "a forged line: too late"))
    dead, crashed = _dead_session(tmp_path, "".join(lines), updated=start + 41.0)
    rig.rec.start()
    cut = rig.meta(dead)
    assert cut == replace(crashed, state="cut", closed=T0, updated=start + 50.0)
    rig.rec.stop()
    first = _first_entry_of_the_next_session(tmp_path)
    assert first.value == f"reason=crash,lost=?,from={start + 50:.3f},to={T0:.3f},session=R_OLD"


def test_ack_checks_the_session_and_appends_a_line(
    tmp_path: Path, rigs: Callable[..., Rig]
) -> None:
    rig = rigs()
    rig.rec.start()
    first = rig.dir
    rig.send("LOGGER_RESTART", "now", at=1.0)
    alog = f"{first.name}.alog"
    ok = rig.control({"cmd": "ack", "session": first.name, "files": {alog: DIGEST}})
    assert ok.ok, ok.why
    current = rig.control({"cmd": "ack", "session": rig.dir.name, "files": {alog: DIGEST}})
    assert current.why == f"session {rig.dir.name!r} is still being recorded"
    missing = rig.control({"cmd": "ack", "session": first.name, "files": {"x.alog": DIGEST}})
    assert missing.why == f"session {first.name!r} has no file 'x.alog'"
    lines = (tmp_path / "logs" / ACKS_NAME).read_text().splitlines()
    assert len(lines) == 1
    assert json.loads(lines[0])["files"] == {alog: DIGEST}


def test_notes_are_bounded(tmp_path: Path, rigs: Callable[..., Rig]) -> None:
    rig = rigs()
    rig.rec.start()
    for i in range(64):
        assert rig.control({"cmd": "note", "key": f"k{i}", "value": "v"}).ok
    assert rig.control({"cmd": "note", "key": "k0", "value": "changed"}).ok
    refused = rig.control({"cmd": "note", "key": "one-more", "value": "v"})
    assert refused.why == "a session holds at most 64 notes"
    assert rig.control({"cmd": "note", "key": "\x01", "value": "v"}).why is not None
    assert rig.meta().notes["k0"] == "changed"
    assert len(rig.meta().notes) == 64


@pytest.mark.parametrize("timestamp", [True, False])
def test_the_directory_is_locked_while_open_and_released_after_close(
    rigs: Callable[..., Rig], timestamp: bool
) -> None:
    stamp = "true" if timestamp else "false"
    rig = rigs(f"File = R\nPath = logs\nFileTimeStamp = {stamp}\nLog = A @ 0")
    rig.rec.start()
    first = rig.dir
    assert recorder_alive(first)
    rig.send("LOGGER_RESTART", "now", at=1.0)  # FileTimeStamp = false reuses the directory
    assert recorder_alive(rig.dir)
    if timestamp:
        assert not recorder_alive(first)
    last = rig.dir
    rig.rec.stop()
    assert not recorder_alive(last)
    assert rig.meta(last).state == "closed"
