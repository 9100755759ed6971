"""The control service and session metadata of a real ``fleetlog record`` on loopback Zenoh.

A recorder subprocess listens on a fresh loopback endpoint; the test's own Zenoh session asks
its control queryable (JSON payloads and hand-typed parameters), publishes PLOGGER_CMD as a
MOOS app would, and reads the status ring, the metadata files and the ``sessions`` service.
A recorder killed with SIGKILL leaves its session ``open``; the next start marks it ``cut``
and opens its own session with the crash's PLOGGER_GAP as the first entry.
"""

from __future__ import annotations

import hashlib
import json
import signal
import time
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

import pytest
from alog_oracle import iter_entries
from helpers import Proc

from fleetlog.api import Vehicle
from fleetlog.transport.queries import ZenohSession, start_query
from fleetlog.transport.session import SessionOptions, open_session
from fleetlog.wire.query import sessions_from_json
from fleetlog.wire.session_meta import ACKS_NAME, META_NAME, SessionMeta

CONTROL = "fleet/alpha/@fleetlog/control"
STATUS = "fleet/alpha/@fleetlog/status"


class Recorder(Proc):
    def __init__(self, args: Sequence[str], cwd: Path, env: dict[str, str]) -> None:
        super().__init__(["record", *args], cwd, env)


@pytest.fixture
def record(
    tmp_path: Path, endpoint: str, cli_env: dict[str, str]
) -> Iterator[Callable[..., Recorder]]:
    started: list[Recorder] = []

    def start(*args: str) -> Recorder:
        rec = Recorder(
            ["--vehicle", "alpha", *args, "-l", endpoint, "--no-multicast-scouting"],
            tmp_path,
            cli_env,
        )
        started.append(rec)
        rec.wait_for("recording")
        return rec

    yield start
    for rec in started:
        rec.close()


@pytest.fixture
def zenoh_session(endpoint: str) -> Iterator[ZenohSession]:
    session = open_session(SessionOptions(connect=(endpoint,), multicast_scouting=False))
    yield session
    session.close()


def ask(
    session: ZenohSession, request: dict[str, Any] | None = None, params: str = ""
) -> dict[str, Any] | str:
    """Send one control request; return the reply's JSON, or the error reply's text."""
    payload = json.dumps(request).encode() if request is not None else None
    selector = f"{CONTROL}?{params}" if params else CONTROL
    for _ in range(50):
        replies = list(start_query(session, selector, timeout=10.0, payload=payload))
        if replies:
            (reply,) = replies
            if reply.error is not None:
                return reply.error
            return json.loads(reply.payload)  # type: ignore[no-any-return]
        time.sleep(0.1)  # the queryable is not known to this session yet
    msg = "the control queryable never answered"
    raise AssertionError(msg)


def status(session: ZenohSession) -> dict[str, Any]:
    (reply,) = list(start_query(session, STATUS, timeout=10.0))
    return json.loads(reply.payload)  # type: ignore[no-any-return]


def sessions(session: ZenohSession) -> dict[str, Any]:
    for _ in range(50):
        replies = list(start_query(session, "fleet/alpha/@fleetlog/sessions", timeout=10.0))
        if replies:
            return {s.name: s for s in sessions_from_json([r.payload for r in replies])}
        time.sleep(0.1)  # the queryable is not known to this session yet
    msg = "the sessions service never answered"
    raise AssertionError(msg)


def eventually(check: Callable[[], bool], timeout: float = 10.0) -> None:
    """Wait until ``check()`` holds (metadata is written off the recording thread)."""
    deadline = time.monotonic() + timeout
    while not check():
        assert time.monotonic() < deadline, "never happened"
        time.sleep(0.02)


def meta_of(directory: Path) -> SessionMeta:
    return SessionMeta.from_bytes((directory / META_NAME).read_bytes())


def session_dirs(where: Path) -> list[Path]:
    return sorted(p for p in where.iterdir() if p.is_dir())


def test_control_commands_and_the_ring_over_zenoh(
    record: Callable[..., Recorder],
    zenoh_session: ZenohSession,
    endpoint: str,
    tmp_path: Path,
) -> None:
    (tmp_path / "notes.txt").write_text("dock 4\n")
    rec = record("--copy-dir", str(tmp_path))
    (first,) = session_dirs(tmp_path)
    assert meta_of(first).state == "open"

    noted = ask(zenoh_session, {"cmd": "note", "key": "site", "value": "bay", "source": "ops"})
    assert noted == {
        "ok": True,
        "cmd": "note",
        "did": f"noted site on session {first.name}",
        "why": None,
    }
    eventually(lambda: meta_of(first).notes == {"site": "bay"})
    typed = ask(zenoh_session, params="cmd=note;key=tide;value=low")
    assert isinstance(typed, dict)
    assert typed["ok"]
    copied = ask(zenoh_session, {"cmd": "copy_file", "path": str(tmp_path / "notes.txt")})
    assert isinstance(copied, dict)
    assert copied["did"] == f"copying {tmp_path / 'notes.txt'} to notes._txt"
    snapshot = ask(zenoh_session, {"cmd": "snapshot"})
    assert isinstance(snapshot, dict)
    assert (snapshot["ok"], snapshot["did"]) == (False, "")
    assert "not in snapshot mode" in snapshot["why"]
    bad = ask(zenoh_session, {"cmd": "frobnicate"})
    assert isinstance(bad, str)
    assert bad.startswith("unknown command 'frobnicate'")
    oversized = ask(zenoh_session, {"cmd": "note", "key": "k", "value": "x" * 70_000})
    assert isinstance(oversized, str)
    assert "at most 65536" in oversized

    # A MOOS app's PLOGGER_CMD goes through the same handler and lands in the same ring.
    with Vehicle(
        "alpha",
        source="iOps",
        options=SessionOptions(connect=(endpoint,), multicast_scouting=False),
    ) as v:
        assert v.wait_for_subscriber("PLOGGER_CMD", timeout=10.0)
        v.publish("PLOGGER_CMD", "LOG_REQUEST = NAV_SPEED @ 0")
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:
            ring = status(zenoh_session)["commands"]
            if any(r["via"] == "PLOGGER_CMD" for r in ring):
                break
            time.sleep(0.05)
    ring = status(zenoh_session)["commands"]
    assert [(r["via"], r["cmd"], r["ok"]) for r in ring] == [
        ("control", "note", True),
        ("control", "note", True),
        ("control", "copy_file", True),
        ("control", "snapshot", False),
        ("control", "?", False),
        ("control", "?", False),
        ("PLOGGER_CMD", "log_request", True),
    ]
    assert ring[0]["source"] == "ops"
    assert ring[-1]["source"] == "iOps"
    assert ring[-1]["did"] == "now logging NAV_SPEED"

    restarted = ask(zenoh_session, {"cmd": "restart"})
    assert isinstance(restarted, dict)
    assert restarted["ok"]
    second = tmp_path / restarted["session"]
    assert meta_of(second).state == "open"
    eventually(lambda: meta_of(first).state == "closed")
    closed = meta_of(first)
    assert closed.state == "closed"
    assert closed.notes == {"site": "bay", "tide": "low"}

    # The shore collector acknowledges the closed session's files.
    files = {
        p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in first.iterdir() if p.is_file()
    }
    acked = ask(zenoh_session, {"cmd": "ack", "session": first.name, "files": files})
    assert isinstance(acked, dict)
    assert acked["ok"], acked
    refused = ask(zenoh_session, {"cmd": "ack", "session": second.name, "files": files})
    assert isinstance(refused, dict)
    assert "still being recorded" in refused["why"]
    (line,) = (tmp_path / ACKS_NAME).read_text().splitlines()
    assert json.loads(line)["files"] == files

    listed = sessions(zenoh_session)
    assert (listed[first.name].state, listed[second.name].state) == ("closed", "open")
    assert rec.stop(signal.SIGINT) == 0
    assert meta_of(second).state == "closed"


def test_a_killed_recorder_leaves_a_cut_session_marked_by_the_next(
    record: Callable[..., Recorder], zenoh_session: ZenohSession, tmp_path: Path
) -> None:
    rec = record()
    (first,) = session_dirs(tmp_path)
    rec.proc.send_signal(signal.SIGKILL)
    rec.wait()
    assert meta_of(first).state == "open"  # nobody could close it
    rec = record()
    cut = meta_of(first)
    assert cut.state == "cut"
    (second,) = [d for d in session_dirs(tmp_path) if d != first]
    with open(second / f"{second.name}.alog", encoding="utf-8") as f:
        gap = next(iter_entries(f))
    assert gap.key == "PLOGGER_GAP"
    assert str(gap.value).startswith("reason=crash,lost=?,from=")
    assert str(gap.value).endswith(f",session={first.name}")
    listed = sessions(zenoh_session)
    assert listed[first.name].state == "cut"
    assert listed[first.name].complete
    assert listed[second.name].state == "open"
    rec.stop(signal.SIGTERM)
    assert meta_of(first) == cut  # a cut session's file never changes again
