"""The bridge's mission configuration and its command line (no MOOSDB needed)."""

from __future__ import annotations

from pathlib import Path

import pytest
from helpers import free_port, run_cli

from fleetlog.errors import MissionError
from fleetlog.moos.bridge_config import BridgeConfig, bridge_config
from fleetlog.moos.mission import parse_mission


def config(text: str) -> BridgeConfig:
    return bridge_config(parse_mission(text, "m.moos"))


def test_defaults() -> None:
    assert bridge_config(None) == BridgeConfig("localhost", 9000, None, ("*",), ("*",))
    assert config("Community = alpha\n") == BridgeConfig("localhost", 9000, "alpha")


def test_what_every_moos_app_reads_and_the_block() -> None:
    cfg = config(
        "ServerHost = 10.0.0.2\nServerPort = 9001\nCommunity = bravo\n"
        "ProcessConfig = fleetlog_bridge\n{\n"
        "  ToZenoh = NAV_*, DEPLOY\n  ToZenoh = *_STATUS\n  FromZenoh = NAV_?\n}\n"
    )
    assert (cfg.host, cfg.port, cfg.community) == ("10.0.0.2", 9001, "bravo")
    # DB_* comes along: the recording must name its vehicle in the MOOS-IvP tools
    assert cfg.to_zenoh == ("NAV_*", "DEPLOY", "*_STATUS", "DB_*")
    assert cfg.from_zenoh == ("NAV_?",)


def test_from_zenoh_none_posts_nothing() -> None:
    cfg = config("ProcessConfig = fleetlog_bridge\n{\n  FromZenoh = none\n}\n")
    assert cfg.from_zenoh == ()
    assert cfg.to_zenoh == ("*",)


@pytest.mark.parametrize(
    ("text", "reason"),
    [
        ("ServerPort = 90000\n", r"m.moos:1: ServerPort value '90000' is not a TCP port"),
        ("ServerPort = abc\n", "is not a TCP port"),
        ("ProcessConfig = fleetlog_bridge\n{\n  ToZenoh = A=B\n}\n", r"m.moos:3: .*holds '='"),
    ],
)
def test_bad_configuration_names_the_line(text: str, reason: str) -> None:
    with pytest.raises(MissionError, match=reason):
        config(text)


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--port", "0"], "--port must be a TCP port"),
        (["--moos-name", "a,b"], "--moos-name must be a MOOS name"),
        (["--max-packet", "0"], "--max-packet must be between"),
        (["--vehicle", " "], "--vehicle needs a vehicle name"),
        (["/nonexistent/mission.moos"], "mission file /nonexistent/mission.moos does not exist"),
    ],
)
def test_bad_arguments_are_one_sentence(args: list[str], message: str) -> None:
    result = run_cli("bridge", *args, "--no-multicast-scouting", timeout=30)
    assert result.returncode != 0
    assert message in result.stderr
    assert "Traceback" not in result.stderr


def test_no_moosdb_with_no_wait_fails_clearly(tmp_path: Path) -> None:
    port = free_port()  # nothing listens there
    zport = free_port()
    result = run_cli(
        "bridge", "--host", "127.0.0.1", "--port", str(port), "--no-wait",
        "-l", f"tcp/127.0.0.1:{zport}", "--no-multicast-scouting",
        cwd=tmp_path, timeout=30,
    )  # fmt: skip
    assert result.returncode == 1
    assert f"cannot connect to the MOOSDB at 127.0.0.1:{port}" in result.stderr
    assert "Traceback" not in result.stderr
