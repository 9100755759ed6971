"""Discovery: when to stop waiting (a fake clock), and tokens seen over real Zenoh sessions."""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Iterator

import pytest
import zenoh

from fleetlog.shore.discovery import Discovery, FleetView, Settle
from fleetlog.shore.report import FleetReport, PartialError
from fleetlog.transport.queries import declare_token

ROOT = "disco"

# -- the decision alone


def test_expected_vehicles_end_the_wait_at_once() -> None:
    settle = Settle(100.0, frozenset({"a", "b"}), quiet=0.3, wait=5.0)
    assert settle.verdict(100.0, ["a"]) is None
    assert settle.verdict(100.01, ["a", "b", "c"]) == "expected"


def test_expected_vehicles_missing_wait_for_the_cap_not_the_quiet_period() -> None:
    settle = Settle(0.0, frozenset({"a"}), quiet=0.3, wait=2.0)
    assert settle.verdict(1.0, ["b"]) is None  # quiet long past: still waiting for a
    assert settle.remaining(1.0) == pytest.approx(1.0)
    assert settle.verdict(2.0, ["b"]) == "wait"


def test_without_expectations_the_fleet_is_known_once_quiet() -> None:
    settle = Settle(0.0, quiet=0.3, wait=5.0)
    settle.news(0.05)
    assert settle.verdict(0.2, ["a"]) is None
    settle.news(0.3)  # another vehicle (or a peer) appeared: the quiet period starts again
    assert settle.verdict(0.5, ["a", "b"]) is None
    assert settle.remaining(0.5) == pytest.approx(0.1)
    assert settle.verdict(0.6, ["a", "b"]) == "quiet"


def test_with_nothing_in_sight_it_waits_for_the_cap() -> None:
    settle = Settle(0.0, quiet=0.3, wait=3.0)
    assert settle.verdict(1.0, []) is None
    assert settle.verdict(3.0, []) == "wait"


def test_view_describes_who_answered_and_who_is_missing() -> None:
    view = FleetView({"a": frozenset({"recorder"})}, ("a", "b"), "wait", 3.0)
    assert view.missing == ["b"]
    text = view.describe()
    assert "1 vehicle(s) up: a" in text
    assert "not up after 3.0 s: b" in text


def test_report_names_what_was_not_done() -> None:
    report = FleetReport("fetched", done={"a": "ok"}, missing=["c"], failed={"b": "it broke"})
    assert report.summary() == "fetched 1 of 3 vehicle(s); not up: c; failed: b: it broke"
    with pytest.raises(PartialError, match="not up: c"):
        report.check()
    FleetReport("fetched", done={"a": "ok"}).check()


# -- over Zenoh


def _config(endpoint: str, listen: bool) -> zenoh.Config:
    conf = zenoh.Config()
    conf.insert_json5("scouting/multicast/enabled", "false")
    key = "listen/endpoints" if listen else "connect/endpoints"
    conf.insert_json5(key, json.dumps([endpoint]))
    return conf


@pytest.fixture
def pair(endpoint: str) -> Iterator[tuple[zenoh.Session, zenoh.Session]]:
    """A vehicle-side session listening on loopback and a shore session connected to it."""
    vehicle = zenoh.open(_config(endpoint, listen=True))
    shore = zenoh.open(_config(endpoint, listen=False))
    try:
        yield vehicle, shore
    finally:
        shore.close()
        vehicle.close()


def test_tokens_declared_before_and_after_the_watch_are_seen(
    pair: tuple[zenoh.Session, zenoh.Session],
) -> None:
    vehicle, shore = pair
    early = declare_token(vehicle, f"{ROOT}/alpha/@fleetlog/recorder")
    discovery = Discovery(shore, ROOT)
    try:
        late: list[object] = []
        timer = threading.Timer(
            0.4, lambda: late.append(declare_token(vehicle, f"{ROOT}/bravo/@fleetlog/serve"))
        )
        timer.start()
        started = time.monotonic()
        view = discovery.wait(expect=("alpha", "bravo"), wait=10.0)
        took = time.monotonic() - started
        timer.join()
        assert view.reason == "expected"
        assert view.vehicles == {
            "alpha": frozenset({"recorder"}),
            "bravo": frozenset({"serve"}),
        }
        assert 0.35 < took < 5.0  # it waited for bravo, and no longer
        early.undeclare()
        deadline = time.monotonic() + 5
        while "alpha" in discovery.current():
            assert time.monotonic() < deadline, "alpha's token never went away"
            time.sleep(0.01)
        assert set(discovery.current()) == {"bravo"}
    finally:
        discovery.close()


def test_other_keys_under_the_root_are_not_vehicles(
    pair: tuple[zenoh.Session, zenoh.Session],
) -> None:
    vehicle, shore = pair
    tokens = [
        declare_token(vehicle, f"{ROOT}/alpha/@fleetlog/recorder"),
        declare_token(vehicle, f"{ROOT}/ghost/@fleetlog/something"),
        declare_token(vehicle, "other/zulu/@fleetlog/recorder"),
    ]
    discovery = Discovery(shore, ROOT, quiet=0.2)
    try:
        view = discovery.wait(wait=5.0)
        assert view.reason == "quiet"
        assert view.names == ["alpha"]
    finally:
        discovery.close()
        for token in tokens:
            token.undeclare()


def test_nothing_up_waits_for_the_cap(pair: tuple[zenoh.Session, zenoh.Session]) -> None:
    _, shore = pair
    discovery = Discovery(shore, ROOT)
    try:
        started = time.monotonic()
        view = discovery.wait(expect=("alpha",), wait=0.5)
        assert view.reason == "wait"
        assert view.missing == ["alpha"]
        assert time.monotonic() - started >= 0.45
    finally:
        discovery.close()
