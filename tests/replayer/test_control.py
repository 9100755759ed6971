"""Steering a running ``fleetlog replay`` over Zenoh: the control queryable, the status, the choke.

The replay runs as a subprocess connected to a session of the test, which collects what it
publishes, queries ``<root>/V/@fleetlog/replay/control`` and ``.../status``, and posts
PLAYBACK_CHOKE heartbeats as a client would.
"""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import zenoh
from replay_support import Line, MakeSession, Proc

from fleetlog.transport.publisher import MoosPublisher
from fleetlog.transport.session import SessionOptions, open_session
from fleetlog.wire.keys import service_key

CONTROL = service_key("fleet", "alpha", "replay", "control")
STATUS = service_key("fleet", "alpha", "replay", "status")


class Client:
    """The test's side: a listening session that collects, queries and posts heartbeats."""

    def __init__(self, endpoint: str) -> None:
        options = SessionOptions(listen=(endpoint,), multicast_scouting=False)
        self.session = open_session(options)
        self.names: list[str] = []
        self.statuses: list[dict[str, Any]] = []
        self._lock = threading.Lock()
        self._subs = [
            self.session.declare_subscriber("fleet/alpha/var/*", self._on_var),
            self.session.declare_subscriber(STATUS, self._on_status),
        ]
        self.publisher = MoosPublisher(self.session, "fleet", "alpha", "uClient")

    def _on_var(self, sample: zenoh.Sample) -> None:
        with self._lock:
            self.names.append(str(sample.key_expr).rsplit("/", 1)[1])

    def _on_status(self, sample: zenoh.Sample) -> None:
        with self._lock:
            self.statuses.append(json.loads(sample.payload.to_bytes()))

    def data(self) -> list[str]:
        with self._lock:
            return [n for n in self.names if n not in ("PLAYBACK_DB_TIME", "PLAYBACK_CHOKE")]

    def query(self, selector: str, timeout: float = 5.0) -> tuple[dict[str, Any] | None, str]:
        """Return ``(document, "")`` for a good reply or ``(None, error text)``."""
        for reply in self.session.get(selector, timeout=timeout):
            if reply.ok is not None:
                return json.loads(reply.ok.payload.to_bytes()), ""
            return None, reply.err.payload.to_string() if reply.err is not None else "?"
        return None, "no reply"

    def command(self, params: str) -> dict[str, Any]:
        doc, err = self.query(f"{CONTROL}?{params}")
        assert doc is not None, err
        return doc

    def wait_ready(self, timeout: float = 15.0) -> dict[str, Any]:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            doc, _ = self.query(STATUS, timeout=1.0)
            if doc is not None:
                return doc
            time.sleep(0.05)
        raise AssertionError("the replay's status queryable never answered")

    def wait_until(self, predicate: Any, timeout: float = 10.0) -> None:
        deadline = time.monotonic() + timeout
        while not predicate():
            assert time.monotonic() < deadline, "timed out"
            time.sleep(0.01)

    def close(self) -> None:
        self.publisher.close()
        for sub in self._subs:
            sub.undeclare()
        self.session.close()


@pytest.fixture
def client(endpoint: str) -> Iterator[Client]:
    made = Client(endpoint)
    yield made
    made.close()


@pytest.fixture
def replay() -> Iterator[list[Proc]]:
    procs: list[Proc] = []
    yield procs
    for proc in procs:
        proc.close()


def start_replay(
    procs: list[Proc], session: Path, endpoint: str, env: dict[str, str], *args: str
) -> Proc:
    argv = ["replay", str(session), "--no-keys", "--wait", "10", "-e", endpoint]
    proc = Proc([*argv, "--no-multicast-scouting", *args], session.parent, env)
    procs.append(proc)
    return proc


def spaced(count: int, gap: float) -> list[Line]:
    # A stale PLAYBACK_CHOKE in the log: replaying it must not choke the replay itself.
    return [Line(0.5, "PLAYBACK_CHOKE", "uOldClient", 5.0)] + [
        Line(1.0 + gap * i, f"V{i}", "p", float(i)) for i in range(count)
    ]


def test_pause_step_seek_rate_resume(
    make_session: MakeSession,
    client: Client,
    replay: list[Proc],
    endpoint: str,
    cli_env: dict[str, str],
) -> None:
    session = make_session(spaced(20, 0.1))  # DB_TIME at 0, V0..V19 at 1.0 ... 2.9
    proc = start_replay(replay, session, endpoint, cli_env, "--paused")
    first = client.wait_ready()
    assert first["state"] == "paused"
    assert first["vehicles"] == ["alpha"]
    assert first["end"] == pytest.approx(2.9)

    doc = client.command("cmd=step")
    assert (doc["state"], doc["published"]) == ("paused", 1)  # DB_TIME
    doc = client.command("cmd=step;n=2")
    assert doc["published"] == 3  # PLAYBACK_CHOKE, V0
    doc = client.command("cmd=step&dt=0.25")  # '&' works too: V1, V2 (1.1, 1.2)
    assert doc["published"] == 5
    assert doc["offset"] == pytest.approx(1.25)
    doc = client.command("cmd=seek;t=2.0")
    assert doc["offset"] == pytest.approx(2.0)
    assert doc["state"] == "paused"
    doc = client.command("cmd=rate;x=50")
    assert doc["rate"] == 50
    bad, err = client.query(f"{CONTROL}?cmd=fly")
    assert bad is None
    assert "unknown command 'fly'" in err
    bad, err = client.query(f"{CONTROL}?cmd=rate;x=1000")
    assert "outside" in err
    client.command("cmd=resume")
    assert proc.wait(20) == 0, proc.stderr
    client.wait_until(lambda: len(client.data()) >= 13)
    assert client.data() == ["DB_TIME", "V0", "V1", "V2", *[f"V{i}" for i in range(10, 20)]]
    assert "finished: published 15 entries" in proc.stderr
    states = {s["state"] for s in client.statuses}
    assert {"paused", "playing"} <= states


def test_stop_command_ends_the_replay(
    make_session: MakeSession,
    client: Client,
    replay: list[Proc],
    endpoint: str,
    cli_env: dict[str, str],
) -> None:
    proc = start_replay(replay, make_session(spaced(5, 0.1)), endpoint, cli_env, "--paused")
    client.wait_ready()
    client.command("cmd=stop")
    assert proc.wait(20) == 0, proc.stderr
    assert "stopped: published 0 entries" in proc.stderr


def test_choke_waits_for_the_client(
    make_session: MakeSession,
    client: Client,
    replay: list[Proc],
    endpoint: str,
    cli_env: dict[str, str],
) -> None:
    session = make_session(spaced(40, 0.05), vehicle=None, moos_community="alpha")
    proc = start_replay(replay, session, endpoint, cli_env, "--paused", "--rate", "4")
    client.wait_ready()
    # A heartbeat 1.9 s old: playback may run for 0.1 s more, then waits for the client.
    client.publisher.publish("PLAYBACK_CHOKE", time.time() - 1.9)
    client.command("cmd=resume")
    client.wait_until(lambda: client.query(STATUS)[0]["state"] == "waiting for client")  # type: ignore[index]
    held = client.query(STATUS)[0]
    assert held is not None
    time.sleep(0.3)
    still = client.query(STATUS)[0]
    assert still is not None
    assert still["published"] == held["published"] < 41
    assert still["offset"] == pytest.approx(held["offset"])
    # The client catches up (a heartbeat well in its future keeps it fresh to the end).
    client.publisher.publish("PLAYBACK_CHOKE", time.time() + 60)
    assert proc.wait(20) == 0, proc.stderr
    assert "finished: published 41 entries" in proc.stderr
