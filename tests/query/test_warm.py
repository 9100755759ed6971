"""Digests computed before anyone asks: at start, when the recorder closes a session, and
cooperatively with the ranges a fetch is being served."""

from __future__ import annotations

import hashlib
import os
import threading
import time
from pathlib import Path

import pytest
from helpers import free_port
from query_support import wait_for

from fleetlog.query import server as server_module
from fleetlog.query.server import LogServer
from fleetlog.storage import confined
from fleetlog.storage.catalog import LogCatalog
from fleetlog.storage.confined import ConfinedRoot, DigestCache
from fleetlog.transport.session import SessionOptions, open_session


def old_session(logs: Path, name: str, size: int) -> bytes:
    """A session directory with one alog of random bytes, not modified for a minute."""
    (logs / name).mkdir(parents=True)
    data = os.urandom(size)
    alog = logs / name / f"{name}.alog"
    alog.write_bytes(data)
    then = time.time() - 60
    os.utime(alog, (then, then))
    return data


def test_warming_continues_what_the_ranges_hashed(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    data = old_session(tmp_path, "S", 3 << 20)
    root = ConfinedRoot(tmp_path)
    names = ("S", "S.alog")
    cache = DigestCache()
    for offset in (0, 1 << 20):  # a fetch was served the first 2 MiB
        chunk, st, steady = root.read_steady(names, offset, 1 << 20)
        assert steady
        cache.feed(st, offset, chunk)
    read: list[int] = []
    real = confined._pread_all

    def spy(fd: int, length: int, offset: int, shown: str) -> bytes:
        read.append(offset)
        return real(fd, length, offset, shown)

    monkeypatch.setattr(confined, "_pread_all", spy)
    pauses: list[float] = []
    cache.warm(root, names, pause=pauses.append)
    assert cache.known(st) == hashlib.sha256(data).hexdigest()
    assert read[0] == 2 << 20  # not read again from the start
    assert len(pauses) == len(read) == 4  # 1 MiB in 256 KiB blocks, a pause after each


def test_the_server_warms_the_latest_session_and_each_closed_one(tmp_path: Path) -> None:
    logs = tmp_path / "logs"
    old_session(logs, "A_1_1_2025_____00_00_00", 1 << 20)
    second = old_session(logs, "B_2_1_2025_____00_00_00", 1 << 20)
    state: dict[str, Path | None] = {"active": logs / "B_2_1_2025_____00_00_00"}
    catalog = LogCatalog(logs, vehicle="v", active=lambda: state["active"])

    def known(name: str) -> str | None:
        return catalog.digests.known(os.stat(logs / name / f"{name}.alog"))

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    session = open_session(SessionOptions(listen=(endpoint,), multicast_scouting=False))
    try:
        with LogServer(session, catalog):
            # The latest session is being recorded: nothing to hash yet, and A is not latest.
            time.sleep(0.5)
            assert known("A_1_1_2025_____00_00_00") is None
            assert known("B_2_1_2025_____00_00_00") is None
            state["active"] = None  # the recorder closed B
            wait_for(lambda: known("B_2_1_2025_____00_00_00") is not None, 10, "B hashed")
            assert known("B_2_1_2025_____00_00_00") == hashlib.sha256(second).hexdigest()
            assert known("A_1_1_2025_____00_00_00") is None
        with LogServer(session, LogCatalog(logs, vehicle="v")) as server:
            # Started without a recorder: the latest complete session is hashed at once.
            latest = logs / "B_2_1_2025_____00_00_00" / "B_2_1_2025_____00_00_00.alog"
            wait_for(lambda: server.catalog.digests.known(os.stat(latest)) is not None, 10, "B")
    finally:
        session.close()


def test_a_recorder_that_tells_its_server_of_session_changes_is_not_polled(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The recorder's own server: the warmer sleeps until the recorder closes a session."""
    monkeypatch.setattr(server_module, "_WARM_POLL", 3600.0)  # a poll would never come
    logs = tmp_path / "logs"
    second = old_session(logs, "B_2_1_2025_____00_00_00", 1 << 20)
    state: dict[str, Path | None] = {"active": logs / "B_2_1_2025_____00_00_00"}
    catalog = LogCatalog(logs, vehicle="v", active=lambda: state["active"])
    changes = threading.Event()
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    session = open_session(SessionOptions(listen=(endpoint,), multicast_scouting=False))
    try:
        server = LogServer(session, catalog, session_changes=changes)
        with server:
            time.sleep(0.2)
            state["active"] = None  # the recorder closed B, and says so
            changes.set()
            wait_for(
                lambda: (
                    catalog.digests.known(
                        os.stat(logs / "B_2_1_2025_____00_00_00" / "B_2_1_2025_____00_00_00.alog")
                    )
                    == hashlib.sha256(second).hexdigest()
                ),
                10,
                "B hashed",
            )
            began = time.monotonic()
        assert time.monotonic() - began < 5.0  # closing wakes the waiting warmer
    finally:
        session.close()
