"""The log server outlives the recorder: ``fleetlog serve --standby`` beside a real recorder.

A ``fetch --follow`` of the session being recorded is running when the recorder stops: the
standby takes over within moments, the fetch rides out the gap, sees the session end, and
verifies it. Every process is a real CLI subprocess on loopback.
"""

from __future__ import annotations

import filecmp
import json
import signal
from pathlib import Path

import pytest
from helpers import Proc, free_port, run_cli
from query_support import wait_for

ZENOH = ["--no-multicast-scouting"]


@pytest.mark.parametrize("how", ["stopped", "killed"])
def test_the_standby_takes_over_when_the_recorder_stops_and_a_follow_ends_verified(
    how: str, tmp_path: Path, cli_env: dict[str, str]
) -> None:
    rec_end = f"tcp/127.0.0.1:{free_port()}"
    serve_end = f"tcp/127.0.0.1:{free_port()}"
    shore = ["-e", rec_end, "-e", serve_end, *ZENOH]
    logs = tmp_path / "logs"
    logs.mkdir()
    procs: list[Proc] = []
    try:
        recorder = Proc(["record", "--vehicle", "alpha", "-l", rec_end, *ZENOH], logs, cli_env)
        procs.append(recorder)
        recorder.wait_for("recording vehicle")
        serve = ["serve", str(logs), "--vehicle", "alpha", "--standby", "-l", serve_end]
        standby = Proc([*serve, "-e", rec_end, *ZENOH], tmp_path, cli_env)
        procs.append(standby)
        standby.wait_for("standing by for vehicle 'alpha'")

        # While the recorder serves, the standby is silent: one answer, no conflict.
        fleet = run_cli("fleet", "--json", "--expect", "alpha", *shore, env=cli_env)
        assert fleet.returncode == 0, fleet.stderr
        (row,) = [json.loads(line) for line in fleet.stdout.splitlines()]
        assert row["conflict"] is None
        assert row["up"] == ["recorder"]
        session = row["latest"]["session"]
        assert row["latest"]["writing"] is True

        poke = run_cli("poke", "-v", "alpha", "DEPTH=12.5", "MODE:=survey", *shore, env=cli_env)
        assert poke.returncode == 0, poke.stderr
        out = tmp_path / "shore"
        follow = Proc(
            ["fetch", "alpha", "--latest", "--follow", "-o", str(out), *shore], tmp_path, cli_env
        )
        procs.append(follow)
        # The follow is under way (its .part files exist) before the recorder stops.
        wait_for(lambda: any((out / session).glob("*.alog.part")), 20, "the follow to start")
        assert follow.proc.poll() is None, follow.stderr

        if how == "stopped":
            assert recorder.stop() == 0  # the session is closed
        else:
            recorder.proc.send_signal(signal.SIGKILL)  # left open: cut
            recorder.wait(10)
        standby.wait_for("taking over", timeout=15)
        assert follow.wait(timeout=60) == 0, follow.stderr
        meta = json.loads((logs / session / ".fleetlog-session.json").read_text())
        assert meta["state"] == ("closed" if how == "stopped" else "open")
        fetched = out / session
        original = logs / session
        names = sorted(p.name for p in original.iterdir() if p.is_file())
        assert sorted(p.name for p in fetched.iterdir()) == names
        _, mismatch, errors = filecmp.cmpfiles(original, fetched, names, shallow=False)
        assert (mismatch, errors) == ([], [])
        assert "DEPTH" in next(fetched.glob("*.alog")).read_text()

        # The logs stay reachable after the recorder stopped.
        after = run_cli("sessions", "alpha", "--json", *shore, env=cli_env)
        assert after.returncode == 0, after.stderr
        listed = {row["name"]: row for row in map(json.loads, after.stdout.splitlines())}
        assert listed[session]["state"] == ("closed" if how == "stopped" else "cut")
        assert listed[session]["complete"] is True
    finally:
        for proc in procs:
            proc.close()
