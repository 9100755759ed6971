"""Wire-protocol versions: a shore of version N works with vehicles of N-1.

The vehicle of the previous version is its recording (tests/data/wire/v1-alpha.jsonl, made by
tests/data/wire/capture.py with that version's fleetlog serve and shore commands), answered on a
real Zenoh session; today's shore commands run against it as subprocesses.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import pytest
import zenoh
from helpers import REFERENCE, free_port, run_cli
from wire_compat_support import DATA, RecordedVehicle

from fleetlog.wire.query import LatestInfo, sessions_to_json
from fleetlog.wire.version import OLDEST_SUPPORTED, WIRE_VERSION, version_of, version_problem

SESSION = "LOG_ALPHA_19_6_2025_____12_04_50"


@pytest.fixture
def old_vehicle(tmp_path: Path) -> tuple[RecordedVehicle, list[str]]:
    port = free_port()
    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("listen/endpoints", f'["tcp/127.0.0.1:{port}"]')
    conf.insert_json5("scouting/multicast/enabled", "false")
    session = zenoh.open(conf)
    vehicle = RecordedVehicle(session, "fleet", "alpha", DATA / f"v{WIRE_VERSION - 1}-alpha.jsonl")
    try:
        yield vehicle, ["-e", f"tcp/127.0.0.1:{port}", "--no-multicast-scouting"]
    finally:
        vehicle.close()
        session.close()


def test_the_previous_version_is_the_one_recorded() -> None:
    assert OLDEST_SUPPORTED == WIRE_VERSION - 1
    assert (DATA / f"v{OLDEST_SUPPORTED}-alpha.jsonl").is_file(), (
        "record the previous version's vehicle with tests/data/wire/capture.py before bumping"
    )


def test_a_shore_of_today_lists_fetches_and_greps_the_previous_version(
    old_vehicle: tuple[RecordedVehicle, list[str]], tmp_path: Path, cli_env: dict[str, str]
) -> None:
    vehicle, common = old_vehicle
    fleet = run_cli("fleet", "--json", *common, env=cli_env)
    assert fleet.returncode == 0, fleet.stderr
    row = json.loads(fleet.stdout.splitlines()[0])
    assert row["vehicle"] == "alpha"
    assert row["latest"]["session"] == SESSION
    assert row["latest"]["wire"] == 1  # no "wire" field: version 1
    assert "warning" not in fleet.stderr
    sessions = run_cli("sessions", "alpha", *common, env=cli_env)
    assert sessions.returncode == 0, sessions.stderr
    assert SESSION in sessions.stdout
    fetched = run_cli("fetch", "alpha", SESSION, "-o", str(tmp_path), *common, env=cli_env)
    assert fetched.returncode == 0, fetched.stderr
    for original in (REFERENCE / "ivp_session" / SESSION).iterdir():
        copy = tmp_path / SESSION / original.name
        assert (
            hashlib.sha256(copy.read_bytes()).digest()
            == hashlib.sha256(original.read_bytes()).digest()
        ), original.name
    grep = run_cli("query", "alpha", "NAV_*", "--session", SESSION, *common, env=cli_env)
    assert grep.returncode == 0, grep.stderr
    assert "NAV_X" in grep.stdout
    assert vehicle.unknown == [], "today's shore asked what the older one never did"


def test_todays_replies_announce_the_version() -> None:
    info = LatestInfo("alpha", None, False, "newest")
    assert json.loads(info.to_json())["wire"] == WIRE_VERSION
    assert LatestInfo.from_json(info.to_json()).wire == WIRE_VERSION
    for reply in sessions_to_json("alpha", []):
        assert json.loads(reply)["wire"] == WIRE_VERSION


@pytest.mark.parametrize(
    ("obj", "version"),
    [({}, 1), ({"wire": 2}, 2), ({"wire": "2"}, 1), ({"wire": True}, 1), ({"wire": 0}, 1)],
)
def test_version_of(obj: dict[str, object], version: int) -> None:
    assert version_of(obj) == version


def test_version_problems() -> None:
    assert version_problem("a", WIRE_VERSION) is None
    assert version_problem("a", WIRE_VERSION - 1) is None
    assert "upgrade the shore first" in (version_problem("a", WIRE_VERSION + 1) or "")
    if WIRE_VERSION > 2:
        assert "upgrade the vehicle" in (version_problem("a", WIRE_VERSION - 2) or "")
