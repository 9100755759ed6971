"""Safe replay: a replay into the keys of a vehicle whose recorder runs now is refused.

A real recorder of ``alpha`` listens on loopback; the replay (the CLI as a subprocess) is told
where it is. Without ``--into-live`` nothing of the replay may reach alpha's live log.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
from helpers import Proc, run_cli
from replay_support import Line, MakeSession

ZENOH = ["--no-multicast-scouting"]


@pytest.fixture
def alpha(tmp_path: Path, cli_env: dict[str, str], endpoint: str) -> Iterator[tuple[Proc, Path]]:
    """A recorder of vehicle alpha, listening on ``endpoint``; its log root."""
    logs = tmp_path / "alpha_logs"
    logs.mkdir()
    proc = Proc(["record", "--vehicle", "alpha", "-l", endpoint, *ZENOH], logs, cli_env)
    try:
        proc.wait_for("recording vehicle")
        yield proc, logs
    finally:
        proc.close()


def _alog_text(logs: Path) -> str:
    return "".join(p.read_text() for p in logs.glob("*/*.alog"))


def _variable_lines(text: str, name: str) -> int:
    return sum(1 for line in text.splitlines() if line.split(None, 2)[1:2] == [name])


def test_a_replay_into_a_live_vehicle_is_refused_and_suggests_prefix(
    alpha: tuple[Proc, Path], make_session: MakeSession, endpoint: str, cli_env: dict[str, str]
) -> None:
    recorder, logs = alpha
    session = make_session([Line(0.1 * i, "REPLAYED_X", "pNav", float(i)) for i in range(5)])
    args = ["replay", str(session), "--fast", "--no-keys", "-e", endpoint, *ZENOH]
    refused = run_cli(*args, env=cli_env)
    assert refused.returncode == 1, refused.stderr
    error = refused.stderr.strip().splitlines()[-1]
    assert error.startswith("fleetlog: error: vehicle alpha is live now"), error
    assert "--prefix" in error
    assert "--into-live" in error
    assert "published" not in refused.stderr

    beside = run_cli(*args, "--prefix", "sim_", env=cli_env)
    assert beside.returncode == 0, beside.stderr
    assert "as sim_alpha" in beside.stderr

    into = run_cli(*args, "--into-live", env=cli_env)
    assert into.returncode == 0, into.stderr
    assert recorder.stop() == 0
    # Only the replay asked for with --into-live reached alpha's live log: five entries.
    # (entries of REPLAYED_X: the recorder's PLOGGER_STATUS lists it among its subscriptions)
    assert _variable_lines(_alog_text(logs), "REPLAYED_X") == 5
