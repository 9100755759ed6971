"""Two recorders, one vehicle: what the shore sees once a partition between them heals.

Two real recorders of ``alpha`` run on their own loopback endpoints, unaware of each other
(each started on its side of the partition); the shore connects to both, as it would once
the link is back. Both stay reachable: every command says there are two, ``fetch`` takes
each one's session into ``DIR/alpha@ZID/``, and ``--server ZID`` asks one of them.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

import pytest
from helpers import Proc, free_port, run_cli

ZENOH = ["--no-multicast-scouting"]


@pytest.fixture
def twins(tmp_path: Path, cli_env: dict[str, str]) -> Iterator[list[str]]:
    """Two recorders of alpha; the shore's Zenoh options to reach both."""
    procs: list[Proc] = []
    shore: list[str] = []
    try:
        for side in ("left", "right"):
            endpoint = f"tcp/127.0.0.1:{free_port()}"
            logs = tmp_path / side
            logs.mkdir()
            proc = Proc(["record", "--vehicle", "alpha", "-l", endpoint, *ZENOH], logs, cli_env)
            procs.append(proc)
            proc.wait_for("recording vehicle")
            shore += ["-e", endpoint]
        yield [*shore, *ZENOH]
    finally:
        for proc in procs:
            proc.close()


def test_both_recorders_stay_reachable_and_the_conflict_is_reported(
    twins: list[str], tmp_path: Path, cli_env: dict[str, str]
) -> None:
    fleet = run_cli("fleet", "--json", "--expect", "alpha", *twins, env=cli_env)
    assert fleet.returncode == 0, fleet.stderr
    (row,) = [json.loads(line) for line in fleet.stdout.splitlines()]
    assert row["vehicle"] == "alpha"
    servers = sorted(row["conflict"])
    assert len(servers) == 2
    assert len(set(servers)) == 2
    assert all(a["recorder"] == a["server"] for a in row["answers"])
    assert "2 processes answer" in fleet.stderr

    status = run_cli("status", "alpha", "--json", *twins, env=cli_env)
    assert status.returncode == 0, status.stderr
    rows = [json.loads(line) for line in status.stdout.splitlines()]
    assert sorted(r["server"] for r in rows) == servers
    assert all(r["conflict"] for r in rows)
    assert "2 recorders answer" in status.stderr
    table = run_cli("status", *twins, env=cli_env)
    assert table.returncode == 0, table.stderr
    assert "CONFLICT" in table.stdout

    out = tmp_path / "shore"
    fetched = run_cli("fetch", "alpha", "--latest", "-o", str(out), *twins, env=cli_env)
    assert fetched.returncode == 0, fetched.stderr
    assert sorted(p.name for p in out.iterdir()) == [f"alpha@{s}" for s in servers]
    for server in servers:
        (session,) = (out / f"alpha@{server}").iterdir()
        assert session.name.startswith("MOOSLog_")

    one = tmp_path / "one"
    pinned = run_cli(
        "fetch", "alpha", "--latest", "--server", servers[0], "-o", str(one), *twins, env=cli_env
    )
    assert pinned.returncode == 0, pinned.stderr
    assert next(p.name for p in one.iterdir()).startswith("MOOSLog_")

    query = run_cli("query", "alpha", *twins, env=cli_env)
    assert query.returncode == 1
    error = query.stderr.strip().splitlines()[-1]
    assert "2 processes answer for vehicle 'alpha'" in error
    assert servers[0] in error
    assert "--server" in error
    grep = run_cli("query", "alpha", "--server", servers[1], *twins, env=cli_env)
    assert grep.returncode == 0, grep.stderr
