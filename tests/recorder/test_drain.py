"""The drain thread sleeps when idle, and loses, reorders or delays nothing for it.

A real RecorderService on loopback Zenoh (a thread of this process), real files.
"""

from __future__ import annotations

import json
import signal
import threading
import time
from collections import deque
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
from alog_oracle import iter_entries
from helpers import free_port
from lane_support import PREFIX, sample_tap
from recorder_support import T0, config, rigs  # noqa: F401  (rigs: a fixture)

from fleetlog.moos.mission import LoggerConfig
from fleetlog.recorder.drain import Drain, Wake
from fleetlog.recorder.service import RecorderService, ServiceOptions
from fleetlog.transport.publisher import MoosPublisher
from fleetlog.transport.queries import start_query
from fleetlog.transport.session import SessionOptions, open_session
from fleetlog.wire.control import CONTROL
from fleetlog.wire.keys import service_key, var_key
from fleetlog.wire.message import MoosMessage, encode_attachment

ROOT = "fleet"
VEHICLE = "drainer"
DOUBLE = "text/plain;moos-double"


def test_a_wake_given_before_the_wait_is_kept_once() -> None:
    wake = Wake()
    assert not wake.wait(0.0)
    wake.set()
    wake.set()  # coalesces
    assert wake.wait(0.0)
    assert not wake.wait(0.01)


def test_a_signal_handler_in_the_sleeping_thread_wakes_it() -> None:
    """SIGINT stops the CLI's recorder from the main thread, which is the one asleep."""
    wake = Wake()
    previous = signal.signal(signal.SIGALRM, lambda signum, frame: wake.set())
    try:
        signal.setitimer(signal.ITIMER_REAL, 0.05)
        began = time.monotonic()
        assert wake.wait(10.0)
        assert time.monotonic() - began < 5.0
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


def test_a_signal_another_thread_receives_wakes_the_main_thread() -> None:
    """Linux gives a process's signal to any thread; Python runs the handler in the main one."""
    wake = Wake()
    handled: list[int] = []
    previous = signal.signal(signal.SIGUSR1, lambda signum, frame: handled.append(signum))
    try:
        with wake.signals():
            other = threading.Thread(
                target=lambda: (
                    time.sleep(0.05),
                    signal.pthread_kill(threading.get_ident(), signal.SIGUSR1),
                )
            )
            other.start()
            began = time.monotonic()
            assert wake.wait(10.0)
            assert time.monotonic() - began < 5.0
            other.join()
    finally:
        signal.signal(signal.SIGUSR1, previous)
        wake.close()
    time.sleep(0.01)  # the handler runs at the main thread's next bytecode
    assert handled == [signal.SIGUSR1]


def test_the_engine_says_how_long_it_has_nothing_to_do(rigs: Callable[..., Any]) -> None:  # noqa: F811
    rig = rigs()
    rig.rec.start()
    rig.rec.tick()
    idle = rig.rec.due_in()
    assert 0.0 < idle <= 2.0  # the next status post at the latest
    rig.rec.handle(MoosMessage("A", 1.0, rig.clock.t, "iX", "", "alpha"))
    assert rig.rec.due_in() == 0.0  # a line waits for its flush
    rig.rec.flush()
    assert rig.rec.due_in() > 0.0


@pytest.mark.parametrize(
    ("body", "at", "idle"),
    [
        ("", 0.25, 1.75),  # the next PLOGGER_STATUS
        ("MinFreeDisk = 1MB", 0.25, 1.0),  # the guard's check, once a second
        ("SplitDuration = 1s", 0.25, 0.75),  # the next part
        ("KeepSessions = 5", 0.25, 0.0),  # retention's first pass is due at the first tick
    ],
    ids=["status", "disk-guard", "split", "retention"],
)
def test_every_timed_duty_bounds_the_idle_sleep(
    rigs: Callable[..., Any],  # noqa: F811
    body: str,
    at: float,
    idle: float,
) -> None:
    """The drain thread sleeps until the engine's next timer: none may wait for another."""
    rig = rigs(f"File = R\nPath = logs\nLog = A @ 0\nFsyncInterval = 0\n{body}")
    rig.rec.start()
    rig.clock.t = T0 + at
    if idle:
        rig.rec.tick()
    assert rig.rec.due_in() == pytest.approx(idle, abs=1e-6)


def test_a_compressed_unit_still_open_is_due_in_a_quarter_second(
    rigs: Callable[..., Any],  # noqa: F811
) -> None:
    rig = rigs("File = R\nPath = logs\nLog = A @ 0\nCompressAlogs = zstd")
    rig.rec.start()
    rig.clock.t = T0 + 1.0
    rig.rec.tick()  # the timers of the start (metadata) have run
    rig.send("A", 1.0, at=1.0)
    rig.rec.flush()  # the last unit ended long ago: this one ends at once
    rig.send("A", 2.0, at=1.1)
    rig.rec.flush()
    session = rig.rec.session
    assert session is not None
    assert session.unit_due() == pytest.approx(T0 + 1.25, abs=1e-6)
    assert rig.rec.due_in() == pytest.approx(0.15, abs=1e-6)
    rig.clock.t = T0 + 1.25
    rig.rec.tick()
    assert session.unit_due() is None


class Queue:
    """A subscriber's FIFO that the test fills between the drain's passes (real samples)."""

    def __init__(self) -> None:
        self.items: deque[Any] = deque()

    @property
    def handler(self) -> Queue:
        return self

    def try_recv(self) -> Any:
        return self.items.popleft() if self.items else None

    def undeclare(self) -> None:
        self.items.clear()


def test_a_line_waits_one_pass_while_the_recorder_keeps_up(
    rigs: Callable[..., Any],  # noqa: F811
) -> None:
    """Passes that take samples and then find every FIFO empty flush within 1 ms, not 5 ms.

    Real Zenoh samples (loopback) are handed to the drain a few at a time, 2 ms of the
    recorder's clock apart (a poll on a busy machine): every pass takes some and finds both
    FIFOs empty. Before, such passes left their lines for a pass that found nothing, or for
    the 5 ms bound, and a reader waited that long for lines the recorder had caught up with.
    """
    rig = rigs("File = R\nPath = logs\nLog = X @ 0\nLog = Y @ 0\nWildcardLogging = false")
    rig.rec.start()
    alog = rig.dir / f"{rig.dir.name}.alog"

    def on_disk() -> list[tuple[str, float]]:
        with alog.open(encoding="utf-8", newline="") as f:
            return [(e.key, float(e.value)) for e in iter_entries(f) if e.key in "XY"]  # type: ignore[arg-type]

    attachment = encode_attachment(T0 + 0.5, "iTest", "", "alpha", None)
    sent = [("XY"[i % 2], float(i)) for i in range(48)]
    parts = [(PREFIX + n, repr(v).encode(), DOUBLE, attachment) for n, v in sent]
    with sample_tap() as tap:
        samples = tap.samples(parts)
    assert len(samples) == len(sent)
    queues = {"X": Queue(), "Y": Queue()}  # a FIFO each: both must be found empty
    drain = Drain(rig.rec, PREFIX, threading.Event())
    for queue in queues.values():
        drain.add(queue)
    taken = 0
    for burst in range(0, len(sent), 6):
        for (name, _), sample in zip(
            sent[burst : burst + 6], samples[burst : burst + 6], strict=True
        ):
            queues[name].items.append(sample)
        assert drain.step() == 6
        assert drain.drained
        # Every line taken by an earlier pass (2 ms ago or more) is readable.
        got = on_disk()
        assert len(got) >= taken
        for name in "XY":  # each variable in the order it was published
            mine = [v for n, v in got if n == name]
            assert mine == [v for n, v in sent if n == name][: len(mine)]
        taken += 6
        rig.clock.t += 0.002
    assert drain.step() == 0  # a pass that finds nothing flushes at once
    assert sorted(on_disk()) == sorted(sent)
    assert drain.lane is not None
    # The common way (each variable's first sample goes the general way, which types it).
    assert drain.lane.fast == len(sent) - 2


@pytest.fixture
def service(tmp_path: Path) -> Iterator[Callable[[LoggerConfig], tuple[RecorderService, str]]]:
    running: list[tuple[RecorderService, threading.Thread]] = []

    def start(cfg: LoggerConfig) -> tuple[RecorderService, str]:
        endpoint = f"tcp/127.0.0.1:{free_port()}"
        options = ServiceOptions(
            vehicle=VEHICLE,
            root=ROOT,
            zenoh=SessionOptions(listen=(endpoint,), multicast_scouting=False),
            cwd=tmp_path,
            freeze_gc=False,
        )
        svc = RecorderService(cfg, options)
        thread = threading.Thread(target=svc.run, name="recorder", daemon=True)
        thread.start()
        assert svc.ready.wait(30), "the recorder did not start"
        running.append((svc, thread))
        return svc, endpoint

    yield start
    for svc, thread in running:
        svc.stop()
        thread.join(30)


def logged(tmp_path: Path) -> list[tuple[str, float]]:
    alogs = list(tmp_path.glob("*/*.alog"))
    assert len(alogs) == 1, alogs
    with alogs[0].open() as f:
        return [(e.key, float(e.value)) for e in iter_entries(f) if e.key in ("X", "Y")]  # type: ignore[arg-type]


def wait_sleeping(svc: RecorderService, more_than: int, timeout: float = 10.0) -> bool:
    drain = svc._drain
    assert drain is not None
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if drain.sleeps > more_than:
            return True
        time.sleep(0.005)
    return False


@pytest.mark.parametrize(
    "body",
    [
        "Log = X @ 0\nLog = Y @ 0\nWildcardLogging = false",  # a FIFO per variable
        "WildcardLogging = true",  # one FIFO for every variable
    ],
    ids=["fifo-per-variable", "one-fifo"],
)
def test_bursts_after_idle_times_are_logged_whole_and_in_order(
    service: Callable[[LoggerConfig], tuple[RecorderService, str]], tmp_path: Path, body: str
) -> None:
    svc, endpoint = service(config(f"File = R\nPath = .\n{body}"))
    session = open_session(SessionOptions(connect=(endpoint,), multicast_scouting=False))
    try:
        pub = MoosPublisher(session, ROOT, VEHICLE, "iTest")
        for name in ("X", "Y"):
            probe = session.declare_publisher(var_key(ROOT, VEHICLE, name))
            deadline = time.monotonic() + 10
            while not probe.matching_status.matching and time.monotonic() < deadline:
                time.sleep(0.01)
            probe.undeclare()
        sent: list[tuple[str, float]] = []
        for burst in range(8):
            drain = svc._drain
            assert drain is not None
            assert wait_sleeping(svc, drain.sleeps), "the drain thread never went to sleep"
            for i in range(40):
                name = "XY"[i % 2]
                value = float(burst * 40 + i)
                pub.publish(name, value)
                sent.append((name, value))
        # Every sample reaches the file soon after it was published, without a stop.
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline and len(logged(tmp_path)) < len(sent):
            time.sleep(0.02)
        got = logged(tmp_path)
        for name in ("X", "Y"):
            assert [v for n, v in got if n == name] == [v for n, v in sent if n == name]
    finally:
        session.close()


def test_a_control_command_wakes_a_sleeping_recorder(
    service: Callable[[LoggerConfig], tuple[RecorderService, str]],
) -> None:
    svc, endpoint = service(config("File = R\nPath = .\nWildcardLogging = true"))
    session = open_session(SessionOptions(connect=(endpoint,), multicast_scouting=False))
    try:
        request = {"cmd": "note", "key": "site", "value": "bay", "source": "ops"}
        payload = json.dumps(request).encode()
        selector = service_key(ROOT, VEHICLE, CONTROL)
        for _ in range(50):
            assert wait_sleeping(svc, 0)
            replies = list(start_query(session, selector, timeout=10.0, payload=payload))
            if replies:
                break
            time.sleep(0.1)  # the queryable is not known to this session yet
        (reply,) = replies
        assert json.loads(reply.payload)["ok"] is True
    finally:
        session.close()
