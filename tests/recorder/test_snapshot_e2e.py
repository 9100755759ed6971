"""Snapshot mode and the disk guard in a real ``fleetlog record`` on loopback Zenoh, real files.

A recorder subprocess in snapshot mode listens on a fresh loopback endpoint; the test
publishes a counter at a steady rate as a MOOS app would, asks for a SNAPSHOT through the
control service, and reads the session it wrote: every sample of the window and of the
``--snapshot-after`` period, once and in order, the counter's latest older value first, and
nothing from before; then a trigger variable fires once per change to its value.
"""

from __future__ import annotations

import json
import subprocess
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
from alog_oracle import iter_entries
from helpers import Proc
from recorder_support import mount_tmpfs

from fleetlog.api import Vehicle
from fleetlog.storage.download import sha256_file
from fleetlog.transport.queries import ZenohSession, start_query
from fleetlog.transport.session import SessionOptions, open_session
from fleetlog.wire.session_meta import META_NAME, SessionMeta

RATE = 200.0  # samples a second
WINDOW = 2.0
AFTER = 1.0
#: how far loopback delivery under a loaded machine may move a window's edges
SLACK = 0.4


@pytest.fixture
def zenoh_session(endpoint: str) -> Iterator[ZenohSession]:
    session = open_session(SessionOptions(connect=(endpoint,), multicast_scouting=False))
    yield session
    session.close()


def control(session: ZenohSession, key: str, request: dict[str, Any] | None) -> dict[str, Any]:
    payload = json.dumps(request).encode() if request is not None else None
    for _ in range(100):
        replies = list(
            start_query(session, f"fleet/alpha/@fleetlog/{key}", timeout=10.0, payload=payload)
        )
        if replies:
            return json.loads(replies[0].payload)  # type: ignore[no-any-return]
        time.sleep(0.1)  # the queryable is not known to this session yet
    raise AssertionError(f"{key} never answered")


def eventually(check: Callable[[], bool], timeout: float) -> None:
    deadline = time.monotonic() + timeout
    while not check():
        assert time.monotonic() < deadline, "never happened"
        time.sleep(0.05)


def meta_of(directory: Path) -> SessionMeta:
    return SessionMeta.from_bytes((directory / META_NAME).read_bytes())


def session_dirs(where: Path) -> list[Path]:
    return sorted(p for p in where.iterdir() if p.is_dir())


def entries(directory: Path) -> list[tuple[float, str, object]]:
    logstart = meta_of(directory).logstart
    with open(directory / f"{directory.name}.alog", encoding="utf-8", newline="") as f:
        return [(logstart + e.offset, e.key, e.value) for e in iter_entries(f)]


def publish_for(v: Vehicle, seconds: float, start: int) -> tuple[int, dict[int, float]]:
    """Publish SEQ = start, start+1, ... at RATE for ``seconds``; return the next and times."""
    times: dict[int, float] = {}
    k = start
    began = time.monotonic()
    while time.monotonic() - began < seconds:
        now = time.time()
        v.publish("SEQ", float(k), time=now)
        times[k] = now
        k += 1
        time.sleep(max(0.0, began + (k - start) / RATE - time.monotonic()))
    return k, times


def test_a_snapshot_over_zenoh_holds_the_window_and_after_and_triggers_fire_once(
    tmp_path: Path, endpoint: str, cli_env: dict[str, str], zenoh_session: ZenohSession
) -> None:
    rec = Proc(
        [
            "record",
            "--vehicle",
            "alpha",
            "--snapshot-seconds",
            f"{WINDOW:g}",
            "--snapshot-after",
            f"{AFTER:g}",
            "--snapshot-trigger",
            "ALARM == 1",
            "-l",
            endpoint,
            "--no-multicast-scouting",
        ],
        tmp_path,
        cli_env,
    )
    try:
        rec.wait_for("snapshot mode")
        options = SessionOptions(connect=(endpoint,), multicast_scouting=False)
        with Vehicle("alpha", source="iTest", options=options) as v:
            assert v.wait_for_subscriber("SEQ", timeout=10.0)
            k, times = publish_for(v, 3.0, 0)
            assert session_dirs(tmp_path) == []  # nothing written before a SNAPSHOT
            asked = time.time()
            reply = control(zenoh_session, "control", {"cmd": "snapshot", "source": "ops"})
            assert reply["ok"], reply
            k, later = publish_for(v, AFTER + 1.0, k)
            times.update(later)
            assert v.confirm()
            (snap,) = session_dirs(tmp_path)
            eventually(lambda: meta_of(snap).state == "closed", timeout=15.0)
            got = [(t, int(value)) for t, key, value in entries(snap) if key == "SEQ"]  # type: ignore[call-overload]
            seqs = [n for _, n in got]
            # the latest older value, then every sample of the window and after, in order
            assert seqs == list(range(seqs[0], seqs[-1] + 1))
            for t, n in got:
                assert t == pytest.approx(times[n], abs=1e-3)  # time stamps as published
            assert times[seqs[1]] == pytest.approx(asked - WINDOW, abs=SLACK)
            assert times[seqs[-1]] == pytest.approx(asked + AFTER, abs=SLACK)
            assert times[seqs[0]] < times[seqs[1]]
            meta = meta_of(snap)
            assert meta.notes["snapshot"] == "control from ops"
            # the trigger: once per change to its value, each its own session
            for value in (0.0, 1.0, 1.0, 1.0, 0.0, 1.0):
                v.publish("ALARM", value)
                time.sleep(0.3 if value == 1.0 else 0.1)
                if value == 0.0:
                    time.sleep(AFTER + 0.5)  # the previous snapshot ends first
            assert v.confirm()
            eventually(lambda: len(session_dirs(tmp_path)) == 3, timeout=15.0)
            body = control(zenoh_session, "status", None)
            assert body["snapshot"]["triggered"] == 2
            assert body["snapshot"]["triggers"] == ["ALARM == 1"]
            assert body["snapshot"]["evicted"] == 0
        # what was received and never written is in the stop summary, not only in status
        assert rec.stop(timeout=30.0) == 0
        summary = rec.wait_for("stopped:")
        assert "snapshot mode: 3 snapshot(s)" in summary, summary
        assert "never written (no SNAPSHOT)" in summary, summary
    finally:
        rec.close()


def test_the_disk_guard_stops_a_real_recorder_and_an_ack_lets_it_resume(
    tmp_path: Path, endpoint: str, cli_env: dict[str, str], zenoh_session: ZenohSession
) -> None:
    where = tmp_path / "disk"
    mount_tmpfs(where, "6m")
    try:
        rec = Proc(
            [
                *("record", "--vehicle", "alpha", "--min-free-disk", "2MB"),
                *("-l", endpoint, "--no-multicast-scouting", "--no-serve"),
            ],
            where,
            cli_env,
        )
        try:
            rec.wait_for("recording")
            (first,) = session_dirs(where)
            options = SessionOptions(connect=(endpoint,), multicast_scouting=False)
            with Vehicle("alpha", source="iTest", options=options) as v:
                assert v.wait_for_subscriber("BIG", timeout=10.0)
                deadline = time.monotonic() + 60.0
                while control(zenoh_session, "status", None)["disk"]["stopped"] is None:
                    assert time.monotonic() < deadline, "the guard never stopped writing"
                    # about 1 MB/s: the guard checks every 20 ms near the bound, so a 2 MB
                    # margin holds what a tick writes (a real MinFreeDisk is GBs)
                    for _ in range(10):
                        v.publish("BIG", "x" * 10_000)
                    assert v.confirm()
                    time.sleep(0.1)
                status = control(zenoh_session, "status", None)
                assert status["problem"] == "low-disk"
                # stopped before the disk was full
                assert status["write_errors"] == 0, status["last_error"]
                assert "below MinFreeDisk 2.0 MB" in status["disk"]["stopped"]
                eventually(lambda: meta_of(first).state == "closed", timeout=15.0)
                # the shore acknowledges the session: the guard removes it, writing resumes
                files = {p.name: sha256_file(p) for p in first.iterdir() if p.is_file()}
                reply = control(
                    zenoh_session, "control", {"cmd": "ack", "session": first.name, "files": files}
                )
                assert reply["ok"], reply
                eventually(lambda: not first.exists(), timeout=20.0)
                eventually(lambda: len(session_dirs(where)) == 1, timeout=20.0)
                body = control(zenoh_session, "status", None)
                assert body["disk"]["removed"] == 1
                eventually(lambda: control(zenoh_session, "status", None)["writing"], 20.0)
        finally:
            rec.close()
    finally:
        subprocess.run(["umount", "-l", str(where)], capture_output=True, check=False)
