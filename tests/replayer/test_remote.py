"""Remote inputs: ``V:SESSION`` and ``V:latest`` fetched from ``fleetlog serve``, then replayed.

A finished session is fetched whole into the cache (and a second replay finds it up to date);
the latest one, still being written (its files changed in the last seconds), is replayed as
far as it has arrived.
"""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import zenoh
from helpers import free_port
from replay_support import Line, Proc, write_session

from fleetlog.replayer.remote import _partial_view
from fleetlog.transport.session import SessionOptions, open_session


@pytest.fixture
def collected(endpoint: str) -> Iterator[list[str]]:
    names: list[str] = []
    lock = threading.Lock()

    def on(sample: zenoh.Sample) -> None:
        with lock:
            names.append(str(sample.key_expr))

    session = open_session(SessionOptions(listen=(endpoint,), multicast_scouting=False))
    sub = session.declare_subscriber("fleet/*/var/*", on)
    yield names
    sub.undeclare()
    session.close()


def test_remote_sessions_are_fetched_then_replayed(
    tmp_path: Path, endpoint: str, collected: list[str], cli_env: dict[str, str]
) -> None:
    logs = tmp_path / "logs"
    old = write_session(
        logs, [Line(1.0, "OLD_X", "p", 1.0)], root="LOG_A_1_1_2027_____00_00_00", vehicle="alpha"
    )
    for item in [old, *old.iterdir()]:
        os.utime(item, (time.time() - 3600, time.time() - 3600))  # finished an hour ago
    new = write_session(
        logs, [Line(1.0, "NEW_X", "p", 2.0)], root="LOG_A_1_1_2027_____01_00_00", vehicle="alpha"
    )
    serve_at = f"tcp/127.0.0.1:{free_port()}"
    zargs = ["--no-multicast-scouting"]
    server = Proc(["serve", str(logs), "-v", "alpha", "-l", serve_at, *zargs], tmp_path, cli_env)
    procs = [server]
    try:
        server.wait_for("serving")
        cache = tmp_path / "cache"
        common = ["--fast", "--no-keys", "--wait", "10", "--cache-dir", str(cache)]
        links = ["-e", serve_at, "-e", endpoint, *zargs]
        for spec in ("alpha:LOG_A_1_1_2027_____00_00_00", "alpha:latest"):
            for item in [new, *new.iterdir()]:
                os.utime(item)  # still being written, as far as the server can tell
            player = Proc(["replay", spec, "--prefix", "r_", *common, *links], tmp_path, cli_env)
            procs.append(player)
            assert player.wait(60) == 0, player.stderr
            assert "(from remote)" in player.stderr
        # The server calls a session complete 5 s after its last change; on a busy machine
        # the fetch may come later than that (the partial path is tested on its own too).
        assert "fetching alpha:LOG_A_1_1_2027_____01_00_00" in player.stderr
        deadline = time.monotonic() + 5
        while len([k for k in collected if "_X" in k]) < 2 and time.monotonic() < deadline:
            time.sleep(0.01)
        assert "fleet/r_alpha/var/OLD_X" in collected
        assert "fleet/r_alpha/var/NEW_X" in collected
        fetched = cache / "alpha" / "LOG_A_1_1_2027_____00_00_00"
        assert (fetched / "LOG_A_1_1_2027_____00_00_00.alog").read_bytes() == next(
            old.glob("*.alog")
        ).read_bytes()
    finally:
        for proc in procs:
            proc.close()


def test_a_partly_fetched_session_is_read_under_its_real_names(tmp_path: Path) -> None:
    session = write_session(tmp_path / "cache", [Line(1.0, "X", "p", 1.0)], root="S")
    for item in list(session.iterdir()):
        item.rename(item.with_name(item.name + ".part"))
    (session / "S.alog.part.json").write_text("{}")
    view = _partial_view(session)
    assert view.name == "S.partial"
    assert sorted(p.name for p in view.iterdir()) == ["S.alog", "S.blog"]
    assert (view / "S.alog").samefile(session / "S.alog.part")
    assert _partial_view(session) == view  # again: the old links are replaced
