"""``fleetlog status``: a real recorder and a ``fleetlog serve`` vehicle; the CLI run as is."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

import pytest
from helpers import Proc, free_port, run_cli
from query_support import Served, make_session

ZENOH = ["--no-multicast-scouting"]


@pytest.fixture
def mixed_fleet(tmp_path: Path, cli_env: dict[str, str]) -> Iterator[list[str]]:
    """alpha runs a recorder; bravo only serves old logs. The shore's options to reach both."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    logs = tmp_path / "alpha"
    logs.mkdir()
    recorder = Proc(["record", "--vehicle", "alpha", "-l", endpoint, *ZENOH], logs, cli_env)
    old = tmp_path / "bravo"
    make_session(old, "MOOSLog_1_1_2025_____00_00_00", 0.01)
    served: Served | None = None
    try:
        recorder.wait_for("recording vehicle")
        served = Served(old, "bravo", cli_env)
        yield ["-e", endpoint, "-e", served.endpoint, *ZENOH]
    finally:
        recorder.close()
        if served is not None:
            served.kill()


def test_status_of_one_vehicle_and_of_the_fleet(
    mixed_fleet: list[str], cli_env: dict[str, str]
) -> None:
    one = run_cli("status", "alpha", *mixed_fleet, env=cli_env)
    assert one.returncode == 0, one.stderr
    for label in ("state", "session", "counters", "losses", "disk free", "clock", "last error"):
        assert label in one.stdout
    assert "recording" in one.stdout
    disk = next(line for line in one.stdout.splitlines() if line.startswith("disk free"))
    assert "iB" in disk  # the recorder says how much room is left
    assert "MOOSLog_" in one.stdout

    rows = run_cli("status", "--json", *mixed_fleet, env=cli_env)
    assert rows.returncode == 0, rows.stderr
    (row,) = [json.loads(line) for line in rows.stdout.splitlines()]
    assert row["vehicle"] == "alpha"
    assert row["conflict"] is False
    assert row["logged"] >= 1
    assert row["lost"] == 0
    assert row["disk"]["free"] > 0
    assert row["disk"]["total"] >= row["disk"]["free"]
    assert "bravo: runs no recorder" in rows.stderr

    table = run_cli("status", *mixed_fleet, env=cli_env)
    assert table.returncode == 0, table.stderr
    lines = table.stdout.splitlines()
    assert lines[0].split()[:5] == ["VEHICLE", "STATE", "SESSION", "LOGGED", "LOST"]
    alpha = next(line for line in lines if line.startswith("alpha"))
    assert alpha.split()[1] == "recording"
    assert any(line.startswith("bravo") and "no recorder" in line for line in lines)

    serve_only = run_cli("status", "bravo", *mixed_fleet, env=cli_env)
    assert serve_only.returncode == 1
    assert "bravo runs no recorder" in serve_only.stderr

    missing = run_cli("status", "--expect", "charlie", "--wait", "0.5", *mixed_fleet, env=cli_env)
    assert missing.returncode == 1
    assert missing.stderr.strip().splitlines()[-1].endswith("not up: charlie")
