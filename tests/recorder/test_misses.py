"""Samples that DROP publishers lose on the way are counted by the recorder (docs/wire.md).

``MoosPublisher(drop=True)`` numbers its samples (zenoh-ext's sample-miss detection, with a
heartbeat); the recorder's drain thread finds the gaps (:class:`MissCounter`) and the engine
counts them as ``missed`` and ``lost``, in PLOGGER_STATUS and on MOOS_DEBUG. The first tests
feed the counter and the engine by hand; the last ones run a real recorder service on loopback
Zenoh, stall its drain thread so that a DROP publisher really drops, and compare what was
logged with what was published.
"""

from __future__ import annotations

import dataclasses
import re
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest
from alog_oracle import iter_entries
from helpers import free_port

from fleetlog.moos.mission import LoggerConfig
from fleetlog.recorder import service as service_module
from fleetlog.recorder.engine import Recorder
from fleetlog.recorder.service import RecorderService, ServiceOptions
from fleetlog.transport.bus import MISS_HEARTBEAT, MissCounter
from fleetlog.transport.publisher import MoosPublisher
from fleetlog.transport.session import SessionOptions, open_session
from fleetlog.wire.keys import var_key
from fleetlog.wire.message import MoosMessage

VEHICLE = "misses"
ROOT = "fleet"
MISSED_STATUS = re.compile(r"PLOGGER_STATUS .*Lost=[1-9]\d*,Missed=[1-9]")
LOST_TEXT = re.compile(
    r"(\d+) samples from (\S+) were lost before reaching the recorder \(DROP congestion control\)"
)

# ------------------------------------------------------------------------------------------
# The counter, fed with stand-ins for zenoh samples


@dataclass(frozen=True)
class _Id:
    zid: str
    eid: int


@dataclass(frozen=True)
class _Info:
    source_id: _Id
    source_sn: int


@dataclass
class _Payload:
    data: bytes

    def to_bytes(self) -> bytes:
        return self.data


@dataclass
class _Sample:
    key_expr: str
    payload: _Payload = field(default_factory=lambda: _Payload(b""))


class Clock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def feed(counter: MissCounter, key: str, zid: str, eid: int, *sns: int) -> None:
    for sn in sns:
        counter.seen(_Info(_Id(zid, eid), sn), _Sample(key))  # type: ignore[arg-type]


def beat(counter: MissCounter, key: str, zid: str, eid: int, last: int) -> None:
    sample = _Sample(f"{key}/@adv/pub/{zid}/{eid}/_", _Payload(last.to_bytes(4, "little")))
    counter.heartbeat(sample)  # type: ignore[arg-type]


def test_gaps_in_a_publishers_numbers_are_counted() -> None:
    counter = MissCounter()
    # Counting starts at the first sample that arrives, whatever its number.
    feed(counter, "k/A", "z1", 1, 7, 8, 9, 12, 13, 20)
    assert counter.take() == [("k/A", "z1", 2 + 6)]
    assert counter.take() == []
    # Late or repeated numbers are not losses, and do not move the expectation back.
    feed(counter, "k/A", "z1", 1, 15, 21)
    assert counter.take() == []


def test_publishers_are_told_apart_by_session_and_entity() -> None:
    counter = MissCounter()
    feed(counter, "k/A", "z1", 1, 0)
    feed(counter, "k/A", "z2", 1, 0)  # another process, same key
    feed(counter, "k/B", "z1", 2, 0)  # same process, another publisher
    feed(counter, "k/A", "z1", 1, 1)
    feed(counter, "k/A", "z2", 1, 3)
    feed(counter, "k/B", "z1", 2, 1)
    assert counter.take() == [("k/A", "z2", 2)]


def test_a_heartbeat_reveals_losses_at_the_end_of_a_burst() -> None:
    clock = Clock()
    counter = MissCounter(clock=clock, settle_delay=0.5)
    feed(counter, "k/A", "z1", 1, 0, 1, 2)
    beat(counter, "k/A", "z1", 1, 9)  # 3..9 were sent after 2
    # Not trusted before the subscribers were seen empty after it, nor too soon.
    counter.settle(drained_at=clock.t - 0.1)
    clock.t += 0.1
    counter.settle(drained_at=clock.t)
    assert counter.take() == []
    clock.t += 0.5
    counter.settle(drained_at=clock.t)
    assert counter.take() == [("k/A", "z1", 7)]
    # The next sample continues from the heartbeat: 10 is no gap, and 3..9 arriving late
    # (which the settle delay makes as good as impossible) would not count again.
    feed(counter, "k/A", "z1", 1, 10, 4)
    beat(counter, "k/A", "z1", 1, 10)
    counter.settle(drained_at=clock.t + 1, min_age=0.0)
    assert counter.take() == []


def test_a_waiting_heartbeat_says_when_it_may_be_trusted() -> None:
    """The drain thread reads heartbeats at its ticks, and sleeps until one may be trusted."""
    clock = Clock()
    counter = MissCounter(clock=clock, settle_delay=0.5)
    assert counter.due_in() == float("inf")
    feed(counter, "k/A", "z1", 1, 0, 1)
    beat(counter, "k/A", "z1", 1, 4)
    clock.t += 0.2
    assert counter.due_in() == pytest.approx(0.3)
    clock.t += 0.3
    assert counter.due_in() == 0.0
    counter.settle(drained_at=clock.t)
    assert counter.take() == [("k/A", "z1", 3)]
    assert counter.due_in() == float("inf")


def test_heartbeats_of_unknown_publishers_or_malformed_are_ignored() -> None:
    clock = Clock()
    counter = MissCounter(clock=clock)
    beat(counter, "k/A", "z9", 1, 50)  # never seen a sample of it: counting has not started
    feed(counter, "k/A", "z1", 1, 0)
    counter.heartbeat(_Sample("k/A/@adv/pub/z1/1/_", _Payload(b"\x05")))  # type: ignore[arg-type]
    counter.heartbeat(_Sample("k/A/@adv/pub/z1/x/_", _Payload(b"\x05\0\0\0")))  # type: ignore[arg-type]
    counter.heartbeat(_Sample("k/A/other/z1/1/_", _Payload(b"\x05\0\0\0")))  # type: ignore[arg-type]
    counter.settle(drained_at=clock.t + 10, min_age=0.0)
    assert counter.take() == []


# ------------------------------------------------------------------------------------------
# The engine: counters, status, MOOS_DEBUG


class FakeClock:
    def __init__(self) -> None:
        self.t = 1_800_000_000.0

    def __call__(self) -> float:
        return self.t


Engine = tuple[Recorder, list[MoosMessage], FakeClock]


@pytest.fixture
def engines(tmp_path: Path) -> Iterator[Callable[[LoggerConfig], Engine]]:
    made: list[Recorder] = []

    def make(config: LoggerConfig) -> Engine:
        posts: list[MoosMessage] = []
        clock = FakeClock()
        recorder = Recorder(
            config, vehicle=VEHICLE, publish=posts.append, cwd=tmp_path, clock=clock
        )
        made.append(recorder)
        recorder.start()
        return recorder, posts, clock

    yield make
    for recorder in made:
        recorder.stop()


def debugs(posts: list[MoosMessage]) -> list[str]:
    return [str(m.value) for m in posts if m.name == "MOOS_DEBUG"]


def test_missed_samples_are_lost_reported_and_in_the_status(
    engines: Callable[[LoggerConfig], Engine],
) -> None:
    recorder, posts, clock = engines(LoggerConfig.default())
    recorder.missed("NAV_X", "zid1", 5)
    recorder.missed(None, "zid1", 2)  # an unreadable key: lost all the same
    recorder.missed("NAV_Y", "zid2", 1)
    s = recorder.stats
    assert (s.missed, s.lost) == (8, 8)
    assert s.as_dict()["missed"] == 8
    clock.t += 2.0  # the status is due again
    recorder.tick()
    assert sorted(debugs(posts)[-2:]) == [
        "1 samples from zid2 were lost before reaching the recorder (DROP congestion control)",
        "7 samples from zid1 were lost before reaching the recorder (DROP congestion control)",
    ]
    status = [str(m.value) for m in posts if m.name == "PLOGGER_STATUS"][-1]
    assert "AppErrorFlag=true" in status
    assert "Lost=8,Missed=8," in status
    # At most one report a second per publisher, with what accumulated meanwhile.
    posts.clear()
    recorder.missed("NAV_X", "zid1", 3)
    clock.t += 0.5
    recorder.tick()
    assert debugs(posts) == []
    recorder.missed("NAV_X", "zid1", 4)
    clock.t += 0.5
    recorder.tick()
    assert [LOST_TEXT.match(d).groups() for d in debugs(posts)] == [("7", "zid1")]  # type: ignore[union-attr]


def test_missed_samples_of_ignored_variables_are_not_lost(
    engines: Callable[[LoggerConfig], Engine],
) -> None:
    config = dataclasses.replace(LoggerConfig.default(), wildcard_omit_patterns=("IGNORED_*",))
    recorder, _, _ = engines(config)
    recorder.missed("IGNORED_X", "zid1", 4)
    recorder.missed("KEPT", "zid1", 1)
    assert (recorder.stats.missed, recorder.stats.lost) == (5, 1)


# ------------------------------------------------------------------------------------------
# A real recorder service on loopback Zenoh


@dataclass
class Running:
    service: RecorderService
    thread: threading.Thread
    endpoint: str
    gate: threading.Event
    held: threading.Event
    stats: dict[str, int | str] = field(default_factory=dict)

    @property
    def recorder(self) -> Recorder:
        assert self.service.recorder is not None
        return self.service.recorder


@pytest.fixture
def recorder_service(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> Iterator[Callable[[], Running]]:
    """A RecorderService in a thread whose drain stops at the first ``STALL`` sample until
    ``gate`` is set; its FIFOs are small, so that a stalled drain backs up to the publisher
    quickly."""
    started: list[Running] = []
    declare = service_module.declare_fifo_subscriber

    def small_fifo(session: Any, key_expr: str, capacity: int = 65536) -> Any:
        return declare(session, key_expr, 256)

    monkeypatch.setattr(service_module, "declare_fifo_subscriber", small_fifo)

    def start() -> Running:
        endpoint = f"tcp/127.0.0.1:{free_port()}"
        options = ServiceOptions(
            vehicle=VEHICLE,
            root=ROOT,
            zenoh=SessionOptions(listen=(endpoint,), multicast_scouting=False),
            cwd=tmp_path,
        )
        service = RecorderService(LoggerConfig.default(), options)
        gate = threading.Event()
        held = threading.Event()

        def on_ready(recorder: Recorder) -> None:
            handle = recorder.handle

            def stalling(msg: MoosMessage, *, garbled: bool = False) -> None:
                if msg.name == "STALL" and not gate.is_set():
                    held.set()
                    gate.wait(60)
                handle(msg, garbled=garbled)

            recorder.handle = stalling  # type: ignore[method-assign]

        running = Running(service, threading.Thread(target=lambda: None), endpoint, gate, held)

        def target() -> None:
            running.stats = service.run(on_ready).stats

        running.thread = threading.Thread(target=target, name="recorder", daemon=True)
        running.thread.start()
        assert service.ready.wait(30), "the recorder did not start"
        started.append(running)
        return running

    yield start
    for running in started:
        running.gate.set()
        running.service.stop()
        running.thread.join(30)


def logged_values(tmp_path: Path, name: str) -> list[float]:
    alogs = list(tmp_path.glob("*/*.alog"))
    assert len(alogs) == 1, alogs
    with alogs[0].open() as f:
        return [float(e.value) for e in iter_entries(f) if e.key == name]  # type: ignore[arg-type]


def all_lines(tmp_path: Path) -> str:
    return "".join(p.read_text(errors="replace") for p in tmp_path.glob("*/*.alog"))


def wait_until(check: Callable[[], bool], timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if check():
            return True
        time.sleep(0.02)
    return check()


def publish_burst(running: Running, session: Any, pub: MoosPublisher, n: int) -> float:
    """Stall the recorder, put ``n`` doubles on X with ``pub`` as fast as possible, release
    the recorder; return how long the puts took."""
    block = MoosPublisher(session, ROOT, VEHICLE, "burst")
    probe = session.declare_publisher(var_key(ROOT, VEHICLE, "X"))
    assert wait_until(lambda: bool(probe.matching_status.matching), 10)
    probe.undeclare()
    block.publish("STALL", 1.0)
    assert running.held.wait(10), "the recorder did not stall"
    # With BLOCK the puts wait for the recorder, so something must release it meanwhile.
    release = threading.Timer(1.0, running.gate.set)
    release.start()
    t0 = time.monotonic()
    for i in range(n):
        pub.publish("X", float(i))
    took = time.monotonic() - t0
    running.gate.set()
    release.cancel()
    block.close()
    return took


def open_publisher_session(running: Running) -> Any:
    return open_session(SessionOptions(connect=(running.endpoint,), multicast_scouting=False))


def test_a_drop_publisher_forced_to_lose_samples_gets_them_counted(
    recorder_service: Callable[[], Running], tmp_path: Path
) -> None:
    running = recorder_service()
    n = 60_000
    session = open_publisher_session(running)
    # Kept until the end: a DROP publisher's heartbeat stops when it is closed.
    pub = MoosPublisher(session, ROOT, VEHICLE, "burst", drop=True)
    try:
        zid = str(session.zid())
        publish_burst(running, session, pub, n)
        recorder = running.recorder
        # Every sample is logged or counted: the gaps at once, the losses at the very end of
        # the burst once a heartbeat (every MISS_HEARTBEAT s) has been trusted.
        assert wait_until(
            lambda: len(logged_values(tmp_path, "X")) + recorder.stats.missed >= n,
            30 + 3 * MISS_HEARTBEAT,
        ), (len(logged_values(tmp_path, "X")), recorder.stats.missed)
        # A MOOS_DEBUG names the publisher (posted at the next tick, logged when it returns),
        # and PLOGGER_STATUS (every 2 s) has the counter.
        assert wait_until(lambda: LOST_TEXT.search(all_lines(tmp_path)) is not None, 10)
        assert wait_until(lambda: MISSED_STATUS.search(all_lines(tmp_path)) is not None, 10)
    finally:
        pub.close()
        session.close()
    running.service.stop()
    running.thread.join(30)
    values = logged_values(tmp_path, "X")
    stats = running.stats
    assert stats["missed"] > 0, "nothing was dropped: the test did not congest the link"
    assert len(values) + int(stats["missed"]) == n, (len(values), stats)
    assert values == sorted(set(values)), "a sample was logged twice or out of order"
    assert int(stats["lost"]) >= int(stats["missed"])
    reported = [(int(m.group(1)), m.group(2)) for m in LOST_TEXT.finditer(all_lines(tmp_path))]
    assert {source for _, source in reported} == {zid}
    assert sum(count for count, _ in reported) <= int(stats["missed"])


def test_a_block_publisher_loses_nothing_and_reports_nothing(
    recorder_service: Callable[[], Running], tmp_path: Path
) -> None:
    running = recorder_service()
    n = 60_000  # as many as the DROP test, which congests the link
    session = open_publisher_session(running)
    pub = MoosPublisher(session, ROOT, VEHICLE, "burst")
    try:
        # The same burst into the same stalled recorder makes DROP drop (the test above).
        publish_burst(running, session, pub, n)
        assert wait_until(lambda: len(logged_values(tmp_path, "X")) >= n, 30)
        time.sleep(2 * MISS_HEARTBEAT)
    finally:
        pub.close()
        session.close()
    running.service.stop()
    running.thread.join(30)
    stats = running.stats
    assert logged_values(tmp_path, "X") == [float(i) for i in range(n)]
    assert (stats["missed"], stats["lost"]) == (0, 0)
    assert LOST_TEXT.search(all_lines(tmp_path)) is None
