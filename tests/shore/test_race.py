"""Discovery right the first time, in fleetlog's default mode (embedded peers, multicast).

The whole process tree runs in a network namespace of its own with multicast on loopback
(``tests/netns.py``), so the recorders find each other and the shore by multicast scouting,
as on a vehicle LAN, and nothing of another test can be seen. The counts here are small; the
issue's (50 fleet runs, 20 fetch runs, 3 and 10 recorders) are run by hand with
``python tests/fleet_race.py`` and reported in docs/shore.md.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from netns import netns_unavailable

DRIVER = Path(__file__).resolve().parents[1] / "fleet_race.py"


def _race(*args: str) -> dict[str, object]:
    why = netns_unavailable()
    if why is not None:
        pytest.skip(f"NEEDS A NETWORK NAMESPACE (unshare -rn): {why}")
    done = subprocess.run(
        [sys.executable, str(DRIVER), *args],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    result: dict[str, object] = json.loads(done.stdout)
    return result


def test_three_recorders_in_default_mode_are_all_found_every_time() -> None:
    result = _race("--vehicles", "3", "--fleet-runs", "6", "--fetch-runs", "3", "--naive-runs", "0")
    assert result["fleet"] == [6, 6], result["fleet_failures"]
    assert result["fetch"] == [3, 3], result["fetch_failures"]
    stopped = result["stopped"]
    assert isinstance(stopped, dict)
    assert stopped["exit"] != 0, stopped
    assert stopped["named"], stopped["stderr"]
    assert stopped["fetched_others"], stopped["stderr"]
