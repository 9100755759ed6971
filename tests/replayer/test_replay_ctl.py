"""``fleetlog replay-ctl`` steers a running replay; both are CLI subprocesses on loopback."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from helpers import Proc, run_cli
from replay_support import Line, MakeSession

from fleetlog.cli.replay_ctl import build_request
from fleetlog.errors import UsageError

ZENOH = ["--no-multicast-scouting"]


def ctl(endpoint: str, env: dict[str, str], *args: str) -> tuple[int, dict[str, object], str]:
    done = run_cli("replay-ctl", *args, "--json", "-e", endpoint, *ZENOH, env=env)
    lines = done.stdout.splitlines()
    return done.returncode, json.loads(lines[0]) if lines else {}, done.stderr


def test_replay_ctl_pauses_resumes_seeks_and_stops_a_replay(
    make_session: MakeSession, tmp_path: Path, endpoint: str, cli_env: dict[str, str]
) -> None:
    session = make_session([Line(1.0 * i, f"V{i}", "p", float(i)) for i in range(1, 60)])
    args = ["replay", str(session), "--paused", "--no-keys", "--wait", "0", "-l", endpoint]
    replay = Proc([*args, *ZENOH], tmp_path, cli_env)
    try:
        replay.wait_for("replaying 1 input(s) as alpha")
        code, reply, err = ctl(endpoint, cli_env, "status")
        assert code == 0, err
        assert (reply["ok"], reply["state"], reply["vehicles"]) == (True, "paused", ["alpha"])

        code, reply, err = ctl(endpoint, cli_env, "resume")
        assert code == 0, err
        assert (reply["cmd"], reply["state"]) == ("resume", "playing")
        assert str(reply["did"]).startswith("playing from")

        code, reply, err = ctl(endpoint, cli_env, "pause")
        assert code == 0, err
        assert reply["state"] == "paused"
        assert str(reply["did"]).startswith("paused at")

        code, reply, err = ctl(endpoint, cli_env, "seek", "0:30")
        assert code == 0, err
        assert reply["offset"] == pytest.approx(30.0)
        code, reply, err = ctl(endpoint, cli_env, "seek", "-10")  # a negative value, no "--"
        assert reply["offset"] == pytest.approx(20.0)
        before = reply["published"]
        assert isinstance(before, int)
        code, reply, err = ctl(endpoint, cli_env, "step", "2")
        assert code == 0, err
        assert reply["published"] == before + 2
        code, reply, err = ctl(endpoint, cli_env, "rate", "5")
        assert reply["rate"] == 5

        bad = run_cli("replay-ctl", "rate", "1000", "-e", endpoint, *ZENOH, env=cli_env)
        assert bad.returncode == 1
        assert "outside 0.1 ... 100" in bad.stderr

        # Without --json: one sentence a person reads.
        said = run_cli("replay-ctl", "-v", "alpha", "status", "-e", endpoint, *ZENOH, env=cli_env)
        assert said.returncode == 0, said.stderr
        assert said.stdout.startswith("replay of alpha: paused at 0:2")

        code, reply, err = ctl(endpoint, cli_env, "stop")
        assert code == 0, err
        assert replay.wait(20) == 0, replay.stderr
        assert f"stopped: published {before + 2} entries" in replay.stderr
    finally:
        replay.close()

    gone = run_cli("replay-ctl", "pause", "--wait", "0.5", "-e", endpoint, *ZENOH, env=cli_env)
    assert gone.returncode == 1
    assert "no replay is running" in gone.stderr


@pytest.mark.parametrize(
    ("args", "expected"),
    [
        (("pause", None), {"cmd": "pause"}),
        (("rate", "fast"), {"cmd": "rate", "x": "fast"}),
        (("rate", "0.5"), {"cmd": "rate", "x": 0.5}),
        (("seek", "1:30"), {"cmd": "seek", "t": 90.0}),
        (("seek", "+5"), {"cmd": "seek", "dt": 5.0}),
        (("seek", "-1:00"), {"cmd": "seek", "dt": -60.0}),
        (("step", None), {"cmd": "step"}),
        (("step", "3"), {"cmd": "step", "n": 3}),
        (("step", "2.5s"), {"cmd": "step", "dt": 2.5}),
    ],
)
def test_requests(args: tuple[str, str | None], expected: dict[str, object]) -> None:
    assert build_request(*args) == expected


@pytest.mark.parametrize(
    ("args", "match"),
    [
        (("fly", None), "unknown replay command 'fly'"),
        (("pause", "3"), "takes no value"),
        (("rate", None), "needs a value"),
        (("rate", "quick"), "is not 0.1"),
        (("seek", "@1700000000"), "not an absolute"),
        (("step", "0"), "1 or more"),
    ],
)
def test_request_refusals(args: tuple[str, str | None], match: str) -> None:
    with pytest.raises(UsageError, match=match):
        build_request(*args)
