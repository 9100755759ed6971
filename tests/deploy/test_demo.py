"""The demo a new user runs first, end to end (fleetlog demo, as a subprocess)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from helpers import run_cli

from fleetlog.deploy.netlink import namespaces_possible


@pytest.mark.parametrize(
    "args",
    [
        pytest.param([], id="radios-where-possible"),
        pytest.param(["--no-netns"], id="loopback", marks=pytest.mark.slow),
    ],
)
def test_the_demo_runs_end_to_end(tmp_path: Path, cli_env: dict[str, str], args: list[str]) -> None:
    done = run_cli(
        "demo", str(tmp_path / "demo"), "--seconds", "4", *args, env=cli_env, timeout=600
    )
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    out = done.stdout
    if not args and namespaces_possible() is None:
        assert "bravo: 200 ms, 5% loss, 1 Mbit/s" in out
    else:
        assert "everything on loopback" in out
    for vehicle in ("alpha", "bravo", "charlie"):
        assert re.search(rf"^{vehicle}\s+recorder", out, re.M), out
        fetched = list((tmp_path / "demo" / "shore-logs" / vehicle).glob("*/*.alog"))
        assert len(fetched) == 1
        assert "NAV_X" in fetched[0].read_text()
        assert re.search(rf"{vehicle}: [1-9]\d* NAV_HEADING entries", out), out
    assert "fleetlog:operator:ops may not publish NAV_X" in out
    replayed = re.search(r"the shore received: (\{.*\})", out)
    assert replayed is not None, out
    for vehicle in ("sim_alpha", "sim_bravo", "sim_charlie"):
        assert f"'{vehicle}': " in replayed.group(1)
