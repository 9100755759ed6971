"""Bad input to every command: one sentence on stderr and a non-zero exit, never a traceback.

Each test runs the installed CLI as a user would (a subprocess, loopback only) and holds in
place one thing found wrong by trying the commands by hand.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from helpers import free_port, run_cli
from replay_support import Line, Proc, write_session

from fleetlog.moos.alog import format_banner, format_entry

ISOLATED = ["--no-multicast-scouting"]


def loopback() -> str:
    """A fresh loopback endpoint."""
    return f"tcp/127.0.0.1:{free_port()}"


def one_error(result: subprocess.CompletedProcess[str], *needles: str) -> str:
    """Check a run ended in one ``fleetlog: error:`` line holding every needle; return it."""
    assert result.returncode == 1, result.stderr
    assert "Traceback" not in result.stderr, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("fleetlog: error: "), result.stderr
    for needle in needles:
        assert needle in lines[0], result.stderr
    return lines[0]


@pytest.fixture
def procs() -> Iterator[list[Proc]]:
    """Long-running fleetlog processes of one test, killed at its end whatever happened."""
    started: list[Proc] = []
    yield started
    for proc in started:
        proc.close()


# -- numbers that are not durations ---------------------------------------------------------


@pytest.mark.parametrize(
    ("args", "needles"),
    [
        (["poke", "X=1", "--wait", "-1"], ["--wait", "0 or more", "-1"]),
        (["poke", "X=1", "--wait", "nan"], ["--wait", "nan"]),
        (["sessions", "alpha", "--timeout", "-1"], ["--timeout", "more than 0", "-1"]),
        (["sessions", "alpha", "--timeout", "0"], ["--timeout", "more than 0"]),
        (["query", "alpha", "--timeout", "nan"], ["--timeout", "nan"]),
        (["query", "alpha", "--timeout", "-5"], ["--timeout", "-5"]),
        (["fetch", "alpha", "--rate", "nan"], ["--rate", "positive", "nan"]),
        (["fetch", "alpha", "--rate", "inf"], ["--rate", "inf"]),
        (["fetch", "alpha", "--retry-for", "-5"], ["--retry-for", "-5"]),
        (["replay", "x.alog", "--wait", "nan"], ["--wait", "nan"]),
        (["replay", "x.alog", "--wait", "inf"], ["--wait", "inf"]),
        (["replay", "x.alog", "--seek-step", "nan"], ["--seek-step", "nan"]),
    ],
)
def test_a_duration_must_be_a_finite_number_of_seconds(
    args: list[str], needles: list[str], tmp_path: Path, cli_env: dict[str, str]
) -> None:
    # Before: a negative --timeout or --wait reached zenoh ("ValueError: negative timeout",
    # a traceback, after poke had already published); NaN passed every check.
    result = run_cli(*args, *ISOLATED, cwd=tmp_path, env=cli_env)
    one_error(result, *needles)


def test_from_after_to_names_the_options(cli_env: dict[str, str]) -> None:
    # Before: "parameter 'from' (5.0) is after 'to' (1.0)", the protocol's names.
    result = run_cli("query", "alpha", "--from", "5", "--to", "1", *ISOLATED, env=cli_env)
    one_error(result, "--from 5 is after --to 1")


# -- vehicle names ---------------------------------------------------------------------------


@pytest.mark.parametrize(
    "args",
    [
        ["record", "--vehicle", ""],
        ["serve", ".", "--vehicle", " "],
        ["poke", "X=1", "--vehicle", ""],
        ["replay", "x.alog", "--as", ""],
        ["sessions", ""],
        ["query", " "],
        ["fetch", "", "--latest"],
    ],
)
def test_an_empty_vehicle_name_is_refused(
    args: list[str], tmp_path: Path, cli_env: dict[str, str]
) -> None:
    # Before: record and serve silently used the host name, poke and replay the key %00.
    result = run_cli(*args, *ISOLATED, cwd=tmp_path, env=cli_env)
    option = next((o for o in ("--as", "--vehicle") if o in args), "VEHICLE")
    one_error(result, f"{option} needs a vehicle name")


# -- mission files and Zenoh configuration files ----------------------------------------------


def test_a_binary_mission_file_is_named_as_binary(tmp_path: Path, cli_env: dict[str, str]) -> None:
    # Before: the parser read it as text and complained about a '${...}' full of escapes.
    mission = tmp_path / "bin.moos"
    mission.write_bytes(b"\x7fELF\x02\x01\x01\x00\x00${\xb7Q}\x00\xff" * 50)
    result = run_cli("record", str(mission), *ISOLATED, env=cli_env)
    one_error(result, f"mission file {mission} is binary")


@pytest.mark.parametrize(
    ("text", "needle"),
    [
        ("not json {{{", "line 1, column 1: expected array"),
        ("{mode: 1", "line 1, column 8: expected boolean"),
        ("", "Empty config file"),
        ('{mode: "bogus"}', "unknown variant `bogus`"),
    ],
)
def test_a_bad_zenoh_config_file_is_named_with_where(
    text: str, needle: str, tmp_path: Path, cli_env: dict[str, str]
) -> None:
    # Before: "Zenoh configuration failed: --> 1:1", neither the file nor what was wrong.
    config = tmp_path / "zenoh.json5"
    config.write_text(text)
    result = run_cli("fleet", "-c", str(config), *ISOLATED, env=cli_env)
    one_error(result, f"Zenoh configuration file {config} is not usable: {needle}")


def test_a_directory_as_zenoh_config_is_not_a_file(tmp_path: Path, cli_env: dict[str, str]) -> None:
    result = run_cli("fleet", "-c", str(tmp_path), *ISOLATED, env=cli_env)
    one_error(result, f"Zenoh configuration file {tmp_path} is not a file")


def test_a_directory_as_hint_file_is_not_a_file(tmp_path: Path, cli_env: dict[str, str]) -> None:
    result = run_cli("serve", str(tmp_path), "--hint", str(tmp_path), *ISOLATED, env=cli_env)
    one_error(result, f"hint file {tmp_path} is not a file")


# -- Ctrl-C while the commands load ------------------------------------------------------------


def test_the_entry_point_loads_nothing_before_its_ctrl_c_guard() -> None:
    # A Ctrl-C while typer, rich and zenoh load printed a KeyboardInterrupt traceback: they
    # were imported before main() set up its guard. Now importing the entry point is cheap.
    code = "import sys, fleetlog.cli; print(sorted({'typer', 'zenoh', 'rich'} & set(sys.modules)))"
    result = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=30, check=False
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "[]"


# -- what a user must be told ------------------------------------------------------------------


def test_record_says_when_it_falls_back_and_when_the_block_is_missing(
    tmp_path: Path, cli_env: dict[str, str], procs: list[Proc]
) -> None:
    # Before: both were posted on MOOS_DEBUG only; the terminal said "recording into ./…" as
    # if all were well, and a misspelt block silently logged every variable.
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    mission = tmp_path / "m.moos"
    mission.write_text(f"ProcessConfig = pLoger\n{{\n}}\nGlobalLogPath = {blocker}/logs\n")
    rec = Proc(
        ["record", str(mission), "--vehicle", "v", "--no-serve", "-l", loopback(), *ISOLATED],
        cwd=tmp_path,
        env=cli_env,
    )
    procs.append(rec)
    rec.wait_for("recording vehicle 'v'")
    assert rec.stop() == 0
    err = rec.stderr
    assert "Traceback" not in err
    assert f"warning: {mission} has no 'ProcessConfig = pLogger' block" in err
    assert f"warning: cannot create a session under {blocker}/logs: logging to the fallback" in err


def test_serving_a_session_directory_says_to_serve_its_parent(
    tmp_path: Path, cli_env: dict[str, str], procs: list[Proc]
) -> None:
    session = write_session(tmp_path, [Line(1.0, "A", "p", 1.0)])
    server = Proc(
        ["serve", str(session), "--vehicle", "v", "-l", loopback(), *ISOLATED],
        cwd=tmp_path,
        env=cli_env,
    )
    procs.append(server)
    line = server.wait_for("holds no session directory")
    assert f"it is a session itself: serve {tmp_path.resolve()}" in line
    assert server.stop() == 0


def test_query_says_when_lines_were_skipped_or_cut(
    tmp_path: Path, cli_env: dict[str, str], procs: list[Proc]
) -> None:
    # Before: an alog the vehicle could not read printed its banner and nothing else, exit 0,
    # exactly like a query that matched nothing.
    root = "LOG_V_1_1_2027_____00_00_00"
    session = tmp_path / "logs" / root
    session.mkdir(parents=True)
    banner = format_banner(f"./{root}/{root}.alog", 1_800_000_000.0, "Thu Jan  1 00:00:00 1970")
    good = format_entry(1.0, "A", "p", "1.00000     ")
    cut = format_entry(2.0, "B", "p", "two ")[:-4]  # no terminator, no newline
    (session / f"{root}.alog").write_text(banner + "garbage here\nmore\n" + good + cut)
    endpoint = loopback()
    server = Proc(
        ["serve", str(tmp_path / "logs"), "--vehicle", "v", "-l", endpoint, *ISOLATED],
        cwd=tmp_path,
        env=cli_env,
    )
    procs.append(server)
    server.wait_for("serving")
    result = run_cli("query", "v", "-e", endpoint, *ISOLATED, env=cli_env)
    assert result.returncode == 0, result.stderr
    assert "Traceback" not in result.stderr
    assert result.stdout.endswith(good)
    assert f"warning: 2 line(s) of {root}'s alog are not alog entries" in result.stderr
    assert f"warning: {root}'s alog ends inside an entry" in result.stderr
    assert server.stop() == 0


def test_replaying_an_alog_with_non_utf8_bytes_does_not_crash(
    tmp_path: Path, cli_env: dict[str, str]
) -> None:
    # Before: UnicodeEncodeError in the attachment's encoder, a traceback, for a Latin-1
    # source, community or value (a real pLogger writes MOOS's bytes as they are).
    root = "LOG_V_1_1_2027_____00_00_00"
    session = tmp_path / root
    session.mkdir()
    banner = format_banner(f"./{root}/{root}.alog", 1_800_000_000.0, "Thu Jan  1 00:00:00 1970")
    lines = [
        format_entry(0.5, "X", "p\udcffNav", "hello "),
        format_entry(0.6, "Y", "pNav@c\udcfc", "x "),
        format_entry(0.7, "Z", "pNav", "h\udcfdllo "),
    ]
    data = (banner + "".join(lines)).encode("utf-8", "surrogateescape")
    (session / f"{root}.alog").write_bytes(data)
    result = run_cli(
        "replay", str(session), "--as", "v", "--fast", "--wait", "0", "--no-keys",
        "-l", loopback(), *ISOLATED,
        env=cli_env,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert "Traceback" not in result.stderr
    assert "published 3 entries" in result.stderr


def test_fetch_rides_out_a_dropped_link_after_a_transfer_longer_than_retry_for(
    tmp_path: Path, cli_env: dict[str, str], procs: list[Proc]
) -> None:
    # Before: --retry-for counted from the start of the file, so a download that had run
    # longer than it gave up at the first unanswered range ("vehicle is not up").
    root = "LOG_V_1_1_2027_____00_00_00"
    session = tmp_path / "logs" / root
    session.mkdir(parents=True)
    banner = format_banner(f"./{root}/{root}.alog", 1_800_000_000.0, "Thu Jan  1 00:00:00 1970")
    entry = format_entry(1.0, "A", "p", "x" * 200 + " ")
    alog = session / f"{root}.alog"
    alog.write_text(banner + entry * (24_000_000 // len(entry)))
    os.utime(alog, (1_700_000_000, 1_700_000_000))  # complete: unchanged for long
    endpoint = loopback()
    serve = ["serve", str(tmp_path / "logs"), "--vehicle", "v", "-l", endpoint, *ISOLATED]
    server = Proc(serve, cwd=tmp_path, env=cli_env)
    procs.append(server)
    server.wait_for("serving")
    out = str(tmp_path / "out")
    slow = ["--rate", "2", "--retry-for", "5"]
    fetch = Proc(
        ["fetch", "v", "--latest", "-o", out, *slow, "-e", endpoint, *ISOLATED], tmp_path, cli_env
    )
    procs.append(fetch)
    time.sleep(7.0)  # beyond --retry-for, well before the 12 s the transfer takes
    assert fetch.proc.poll() is None, fetch.stderr
    assert server.stop() == 0
    again = Proc(serve, cwd=tmp_path, env=cli_env)
    procs.append(again)
    again.wait_for("serving")
    assert fetch.wait(60) == 0, fetch.stderr
    assert (tmp_path / "out" / root / f"{root}.alog").read_bytes() == alog.read_bytes()
    assert again.stop() == 0


def test_sessions_lists_a_session_whose_alog_is_corrupt(
    tmp_path: Path, cli_env: dict[str, str], procs: list[Proc]
) -> None:
    # Before: a session with a corrupt .alog.gz vanished from `sessions`, while `fleet` named
    # it as the vehicle's latest session.
    logs = tmp_path / "logs"
    write_session(logs, [Line(1.0, "A", "p", 1.0)], root="LOG_V_1_1_2027_____00_00_00")
    bad = logs / "LOG_V_2_1_2027_____00_00_00"
    bad.mkdir()
    (bad / f"{bad.name}.alog.gz").write_bytes(b"\x1f\x8b\x08\x00 not really gzip" * 20)
    endpoint = loopback()
    server = Proc(
        ["serve", str(logs), "--vehicle", "v", "-l", endpoint, *ISOLATED], tmp_path, cli_env
    )
    procs.append(server)
    server.wait_for("serving")
    result = run_cli("sessions", "v", "--json", "-e", endpoint, *ISOLATED, env=cli_env)
    assert result.returncode == 0, result.stderr
    listed = [json.loads(line) for line in result.stdout.splitlines()]
    assert [s["name"] for s in listed] == ["LOG_V_1_1_2027_____00_00_00", bad.name]
    assert listed[1]["latest"] is True
    assert listed[1]["files"][0]["name"] == f"{bad.name}.alog.gz"
    assert server.stop() == 0


@pytest.mark.parametrize("window", [["--from", "100"], ["--to", "0.5"]])
def test_replay_says_when_its_window_holds_no_entry(
    window: list[str], tmp_path: Path, cli_env: dict[str, str]
) -> None:
    # Before: "finished: published 0 entries" and nothing else, like an empty log.
    lines = [Line(1.0, "A", "p", 1.0), Line(2.0, "B", "p", 2.0)]
    session = write_session(tmp_path, lines, vehicle=None)
    result = run_cli(
        "replay", str(session), "--as", "v", *window, "--fast", "--wait", "0", "--no-keys",
        "-l", loopback(), *ISOLATED,
        env=cli_env,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert "note: no entry lies between --from and --to; nothing was played" in result.stderr


def test_errors_from_the_vehicle_do_not_show_its_paths(
    tmp_path: Path, cli_env: dict[str, str], procs: list[Proc]
) -> None:
    # Before: a grep of a corrupt alog answered with the vehicle's absolute file path.
    logs = tmp_path / "logs"
    bad = logs / "LOG_V_2_1_2027_____00_00_00"
    bad.mkdir(parents=True)
    (bad / f"{bad.name}.alog.gz").write_bytes(b"\x1f\x8b\x08\x00 not really gzip" * 20)
    endpoint = loopback()
    server = Proc(
        ["serve", str(logs), "--vehicle", "v", "-l", endpoint, *ISOLATED], tmp_path, cli_env
    )
    procs.append(server)
    server.wait_for("serving")
    result = run_cli("query", "v", "-s", bad.name, "-e", endpoint, *ISOLATED, env=cli_env)
    assert result.returncode == 1
    (line,) = result.stderr.strip().splitlines()
    assert f"{bad.name}.alog.gz" in line
    assert str(logs.resolve()) not in line
    assert str(tmp_path) not in line
    assert server.stop() == 0
