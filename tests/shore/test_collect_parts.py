"""The collector's parts without a network: the pacer on a simulated link, rate caps, the
order of a round's fetches, the archive's records and the fleet view read from them."""

from __future__ import annotations

import heapq
import json
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from fleetlog.cli.collect import parse_rate
from fleetlog.errors import FormatError, StorageError, UsageError
from fleetlog.shore.collect_rounds import plan_fetches
from fleetlog.shore.holdings import holdings
from fleetlog.shore.pacing import LinkPacer, RateLimit
from fleetlog.storage.archive import (
    ArchivedFile,
    ArchiveLock,
    VehicleRecord,
    collector_running,
    load_record,
    save_record,
)
from fleetlog.wire.query import FileInfo, SessionInfo


def simulate(rate: float, rtt: float, seconds: float) -> tuple[float, float, LinkPacer]:
    """Run a LinkPacer against a link of ``rate`` bytes/s, ``rtt`` s and an unbounded queue.

    Returns the throughput and the largest queueing delay of the second half of the run.
    """
    now = [0.0]
    pacer = LinkPacer(clock=lambda: now[0])
    link_free = 0.0
    inflight: list[tuple[float, int, float]] = []  # (arrival, size, sent)
    asked = 0
    delivered = 0
    worst = 0.0
    while now[0] < seconds:
        while pacer.room(asked, len(inflight)):
            size = pacer.chunk()
            start = max(now[0] + rtt / 2, link_free)
            link_free = start + size / rate
            heapq.heappush(inflight, (link_free + rtt / 2, size, now[0]))
            asked += size
        arrival, size, sent = heapq.heappop(inflight)
        now[0] = arrival
        asked -= size
        pacer.arrived(size, arrival - sent)
        if arrival > seconds / 2:
            delivered += size
            worst = max(worst, arrival - sent - rtt - size / rate)
    return delivered / (seconds / 2), worst, pacer


def test_link_pacer_fills_a_radio_link_and_keeps_its_queue_short() -> None:
    rate = 125_000.0  # 1 Mbit/s
    throughput, worst, pacer = simulate(rate, rtt=0.4, seconds=120)
    assert throughput > 0.85 * rate
    assert worst < 0.25  # the target is 0.1 s: a command waits about that behind ranges
    assert pacer.chunk() <= 16 << 10


def test_link_pacer_reaches_full_speed_on_a_lan() -> None:
    rate = 400e6
    throughput, _, pacer = simulate(rate, rtt=0.001, seconds=10)
    assert throughput > 0.8 * rate
    assert pacer.chunk() == 1 << 20


def test_a_fixed_window_would_queue_for_a_minute() -> None:
    # The baseline: 8 ranges of 1 MiB in flight on the same radio link.
    queued = 8 * (1 << 20) / 125_000.0
    assert queued > 60


def test_rate_limit_is_shared() -> None:
    now = [0.0]
    slept: list[float] = []

    def sleep(seconds: float) -> None:
        slept.append(seconds)
        now[0] += seconds

    cap = RateLimit(1000.0, burst=0.0, clock=lambda: now[0], sleep=sleep)
    for _ in range(10):
        cap.wait(500)  # two transfers taking turns through one cap
    assert now[0] == pytest.approx(4.5)
    RateLimit(None).wait(1 << 30)  # no cap: no wait


@pytest.mark.parametrize(
    ("text", "rate"),
    [("1Mbit", 125_000.0), ("125kB", 125_000.0), ("0.5", 500_000.0), ("2 MB", 2e6),
     ("800kbps", 100_000.0), ("64k", 64_000.0)],
)  # fmt: skip
def test_parse_rate(text: str, rate: float) -> None:
    assert parse_rate(text, "--max-rate") == pytest.approx(rate)


@pytest.mark.parametrize("text", ["", "0", "-1Mbit", "fast", "1e999", "nan", "1 Tbit"])
def test_parse_rate_refuses(text: str) -> None:
    with pytest.raises(UsageError, match="--max-rate must be a positive rate"):
        parse_rate(text, "--max-rate")


def info(name: str, *files: tuple[str, int], complete: bool = True) -> SessionInfo:
    return SessionInfo(
        name=name,
        files=tuple(FileInfo(n, s, 0.0) for n, s in files),
        complete=complete,
        state="closed" if complete else "open",
    )


def test_a_round_fetches_small_files_first_newest_first() -> None:
    new = info("S3", ("S3.alog", 900), (".fleetlog-session.json", 9), ("S3.ylog", 5))
    old = info("S1", ("S1.alog", 800), ("S1._moos", 7))
    only = info("S2", ("S2.alog", 10))
    live = info("S4", ("S4.alog", 10), ("S4.ylog", 1), complete=False)
    plan = [(i.name, names) for i, names in plan_fetches([live, new, only, old])]
    assert plan == [
        ("S3", frozenset({".fleetlog-session.json", "S3.ylog"})),
        ("S1", frozenset({"S1._moos"})),
        ("S3", None),
        ("S2", None),
        ("S1", None),
    ]


def test_records_round_trip_and_are_read_defensively(tmp_path: Path) -> None:
    record = VehicleRecord("alpha", seen=5.0, up=True, received=7)
    entry = record.session("S1")
    entry.state = "cut"
    entry.files["S1.alog"] = ArchivedFile(10, "ab" * 32)
    entry.remote = {"S1.alog": 10}
    entry.acked = 6.0
    save_record(tmp_path / "alpha", record)
    back = load_record(tmp_path / "alpha")
    assert back is not None
    assert back.to_bytes() == record.to_bytes()
    assert load_record(tmp_path / "nobody") is None
    (tmp_path / "alpha" / ".fleetlog-archive.json").write_text("{ cut off")
    with pytest.raises(FormatError, match="not JSON"):
        load_record(tmp_path / "alpha")


JSON = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False) | st.text(),
    lambda kids: st.lists(kids) | st.dictionaries(st.text(), kids),
    max_leaves=30,
)


@given(JSON)
def test_a_garbled_record_never_crashes_the_reader(garbage: object) -> None:
    shapes = (
        garbage,
        {"format": 1, "sessions": garbage, "in_flight": garbage},
        {"format": 1, "sessions": {"S": garbage}},
    )
    for obj in shapes:
        try:
            record = VehicleRecord.from_bytes("v", json.dumps(obj).encode())
        except FormatError:
            continue
        record.to_bytes()  # what was read can be written back


def test_one_collector_per_archive(tmp_path: Path) -> None:
    assert not collector_running(tmp_path)
    lock = ArchiveLock(tmp_path)
    try:
        assert collector_running(tmp_path)
        with pytest.raises(StorageError, match="another fleetlog collect is running"):
            ArchiveLock(tmp_path)
    finally:
        lock.release()
    assert not collector_running(tmp_path)


def test_the_fleet_view(tmp_path: Path) -> None:
    record = VehicleRecord("alpha", seen=1.0)
    done = record.session("S1")
    done.state, done.remote = "complete", {"S1.alog": 4}
    done.files["S1.alog"] = ArchivedFile(4, "00" * 32)
    half = record.session("S2")
    half.state, half.remote = "partial", {"S2.alog": 10}
    save_record(tmp_path / "alpha", record)
    (tmp_path / "alpha" / "S1").mkdir()
    (tmp_path / "alpha" / "S1" / "S1.alog").write_bytes(b"abcd")
    (tmp_path / "alpha" / "S2").mkdir()
    (tmp_path / "alpha" / "S2" / "S2.alog.part").write_bytes(b"abc")
    (tmp_path / "ghost").mkdir()  # not a vehicle: no record
    view = holdings(tmp_path).as_json()
    (alpha,) = view["vehicles"]
    assert alpha["on_shore"] == {"sessions": 1, "complete": 1, "cut": 0, "bytes": 4}
    assert alpha["only_on_vehicle"] == {"sessions": 1, "bytes": 7}
    assert view["collector_running"] is False
    with pytest.raises(StorageError, match="not an archive directory"):
        holdings(tmp_path / "nothing")
