"""``fleetlog poke`` says what the recorder did with a command, from its status ring."""

from __future__ import annotations

import json
from pathlib import Path

import zenoh
from helpers import Proc, run_cli

ZENOH = ["--no-multicast-scouting"]


def test_poke_prints_the_new_directory_and_refusals(
    tmp_path: Path, endpoint: str, cli_env: dict[str, str]
) -> None:
    logs = tmp_path / "logs"
    logs.mkdir()
    recorder = Proc(["record", "--vehicle", "alpha", "-l", endpoint, *ZENOH], logs, cli_env)
    shore = ["-e", endpoint, *ZENOH]
    try:
        recorder.wait_for("recording vehicle")
        first = {p.name for p in logs.iterdir() if p.is_dir()}

        restart = run_cli("poke", "LOGGER_RESTART=true", *shore, env=cli_env)
        assert restart.returncode == 0, restart.stderr
        (line,) = restart.stdout.splitlines()
        assert line.startswith("recorder of alpha: true: started session MOOSLog_"), line
        new = {p.name for p in logs.iterdir() if p.is_dir()} - first
        assert len(new) == 1
        assert line.endswith(f"started session {new.pop()}")

        refused = run_cli("poke", "PLOGGER_CMD:=BOGUS=1", "-v", "alpha", *shore, env=cli_env)
        assert refused.returncode == 1
        assert "refused: dynamic command BOGUS is not supported" in refused.stdout
        assert refused.stderr.strip().splitlines()[-1] == (
            "fleetlog: error: the recorder refused PLOGGER_CMD: dynamic command BOGUS is not"
            " supported"
        )

        plain = run_cli("poke", "DEPTH=3", *shore, env=cli_env)
        assert plain.returncode == 0, plain.stderr
        assert plain.stdout == ""  # not a command: receipt confirmed, nothing to say

        status = run_cli("status", "alpha", "--json", *shore, env=cli_env)
        ring = json.loads(status.stdout)["commands"]
        assert [(c["via"], c["source"], c["ok"]) for c in ring[-2:]] == [
            ("LOGGER_RESTART", "uPokeDB", True),
            ("PLOGGER_CMD", "uPokeDB", False),
        ]
    finally:
        recorder.close()


def test_a_poke_no_recorder_confirmed_exits_non_zero(
    endpoint: str, cli_env: dict[str, str]
) -> None:
    conf = zenoh.Config()
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("listen/endpoints", json.dumps([endpoint]))
    session = zenoh.open(conf)
    got: list[str] = []
    sub = session.declare_subscriber("fleet/ghost/var/*", lambda s: got.append(str(s.key_expr)))
    try:
        done = run_cli(
            "poke", "X=1", "-v", "ghost", "--wait", "1", "-e", endpoint, *ZENOH, env=cli_env
        )
        assert done.returncode == 1
        assert "no recorder of vehicle 'ghost' confirmed receipt" in done.stderr
        assert got == ["fleet/ghost/var/X"]  # delivered to the plain subscriber all the same
    finally:
        sub.undeclare()
        session.close()
