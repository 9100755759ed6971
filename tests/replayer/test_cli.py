"""``fleetlog replay``'s arguments: one clear line for every bad input, before any Zenoh."""

from __future__ import annotations

import re
import time
from pathlib import Path

import pytest
from helpers import run_cli
from replay_support import Line, MakeSession, Proc
from typer.testing import CliRunner

from fleetlog.cli.app import app
from fleetlog.cli.replay import parse_when
from fleetlog.errors import FleetlogError, UsageError
from fleetlog.storage.metafile import write_meta
from fleetlog.wire.session_meta import SessionMeta

ISOLATED = ["--no-keys", "--wait", "0", "--no-multicast-scouting"]


def invoke(*args: str) -> BaseException | None:
    """Run the command in-process; return the FleetlogError it ended with (the CLI prints it)."""
    from fleetlog.cli import commands

    commands.load(["replay"])  # registers it
    result = CliRunner().invoke(app, ["replay", *args, *ISOLATED])
    return result.exception


def test_missing_input_is_one_line(tmp_path: Path, cli_env: dict[str, str]) -> None:
    result = run_cli("replay", str(tmp_path / "nope.alog"), *ISOLATED, env=cli_env)
    assert result.returncode == 1
    assert (
        result.stderr.strip()
        == f"fleetlog: error: {tmp_path / 'nope.alog'}: no such file or session directory"
    )


def test_corrupt_alog_names_the_file_and_line(
    make_session: MakeSession, tmp_path: Path, cli_env: dict[str, str]
) -> None:
    session = make_session([Line(1.0, "A", "p", 1.0)])
    alog = next(session.glob("*.alog"))
    text = alog.read_text().splitlines(keepends=True)
    # Lines that are neither entries nor comments, before the first entry (line 6).
    alog.write_text("".join([*text[:5], "garbage here\n", "more\n", *text[5:]]))
    result = run_cli("replay", str(session), "--fast", *ISOLATED, env=cli_env)
    assert result.returncode == 1
    lines = result.stderr.strip().splitlines()
    assert lines[-1].startswith(f"fleetlog: error: {alog}:8: 2 line(s) before line 8")
    bad = tmp_path / "bad.alog"
    bad.write_text("not an alog\n")
    result = run_cli("replay", str(bad), "--as", "x", *ISOLATED, env=cli_env)
    assert result.returncode == 1
    assert result.stderr.strip().startswith(f"fleetlog: error: {bad}:1: expected a banner line")


def test_unknown_vehicle_asks_for_as(make_session: MakeSession) -> None:
    session = make_session([Line(1.0, "A", "p", 1.0)], vehicle=None)
    err = invoke(str(session))
    assert isinstance(err, FleetlogError)
    assert "cannot tell which vehicle" in str(err)
    assert "--as V" in str(err)


def test_remote_input_of_a_vehicle_that_is_not_up() -> None:
    err = invoke("alpha:latest")
    assert isinstance(err, FleetlogError)
    assert str(err).startswith("vehicle 'alpha' is not up")


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--rate", "500"], "rate 500 is outside 0.1 ... 100"),
        (["--rate", "0.01"], "rate 0.01 is outside"),
        (["--from", "soon"], "--from 'soon': give seconds"),
        (["--from", "10", "--to", "5"], "--to 5 is before --from 10"),
        (["--as", "a", "--as", "b", "--as", "c"], "--as was given 3 times for 1 inputs"),
        (["--sort-window", "-1"], "sort window must be 0 or more"),
        (["--root", "a/*"], "key root"),
    ],
)
def test_bad_options(make_session: MakeSession, args: list[str], message: str) -> None:
    err = invoke(str(make_session([Line(1.0, "A", "p", 1.0)])), *args)
    assert isinstance(err, FleetlogError), err
    assert message in str(err)


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("12.5", (12.5, False)),
        ("0", (0.0, False)),
        ("1:02", (62.0, False)),
        ("1:02:03.5", (3723.5, False)),
        ("@1795345603.4", (1795345603.4, True)),
    ],
)
def test_parse_when(text: str, expected: tuple[float, bool]) -> None:
    assert parse_when(text, "--from") == expected


@pytest.mark.parametrize("text", ["", "soon", "nan", "inf", "@", "1:xx"])
def test_parse_when_refuses(text: str) -> None:
    with pytest.raises(UsageError, match="--from"):
        parse_when(text, "--from")


def test_sigint_stops_with_a_summary(
    make_session: MakeSession, tmp_path: Path, cli_env: dict[str, str]
) -> None:
    session = make_session([Line(1.0 + i, f"V{i}", "p", float(i)) for i in range(30)])
    proc = Proc(["replay", str(session), *ISOLATED], tmp_path, cli_env)
    try:
        proc.wait_for("replaying 1 input(s) as alpha")
        time.sleep(1.2)  # about two entries are out (DB_TIME at 0, V0 at 1.0)
        assert proc.stop() == 0
        found = re.search(r"fleetlog: stopped: published (\d+) entries", proc.stderr)
        assert found is not None, proc.stderr
        assert 1 <= int(found.group(1)) < 10
    finally:
        proc.close()


def _clock(session: Path, vehicle: str, synchronized: bool | None) -> None:
    """Give a session fleetlog's metadata, with the clock state its recorder saw."""
    clock = {} if synchronized is None else {"synchronized": synchronized}
    meta = SessionMeta("closed", vehicle, session.name, "1", "0", 1.0, 1.0, 2.0, clock=clock)
    write_meta(session, meta)


def test_a_fleet_replay_warns_of_an_unsynchronised_clock(
    make_session: MakeSession, cli_env: dict[str, str]
) -> None:
    alpha = make_session([Line(1.0, "A", "p", 1.0)], vehicle="alpha")
    bravo = make_session([Line(1.0, "B", "p", 2.0)], vehicle="bravo")
    charlie = make_session([Line(1.0, "C", "p", 3.0)], vehicle="charlie")
    _clock(alpha, "alpha", True)
    _clock(bravo, "bravo", False)  # charlie: written by pLogger, no metadata: not known
    fleet = run_cli(
        "replay", str(alpha), str(bravo), str(charlie), "--fast", *ISOLATED, env=cli_env
    )
    assert fleet.returncode == 0, fleet.stderr
    warnings = [line for line in fleet.stderr.splitlines() if "warning" in line]
    assert warnings == [
        f"fleetlog: warning: bravo's clock was not synchronised when {bravo} was recorded: on"
        " one clock with the other vehicles, its entries may be out of place by as much as its"
        " clock was off"
    ]
    # One vehicle plays right whatever its clock: nothing to warn of.
    alone = run_cli("replay", str(bravo), "--fast", *ISOLATED, env=cli_env)
    assert alone.returncode == 0, alone.stderr
    assert "warning" not in alone.stderr
