"""``fleetlog record`` and ``fleetlog poke`` as real processes on loopback Zenoh.

Each test starts the recorder as a subprocess (``-l <endpoint> --no-multicast-scouting``),
waits for its "recording" line, publishes with ``fleetlog poke`` and with the Python API,
stops it with a signal and compares the session directory with what MOOS_FORMAT.md says
pLogger writes, and with the real pLogger run of ``reference/captured/runA_*``. Every wait
has a timeout and every process is killed in teardown.
"""

from __future__ import annotations

import gzip
import io
import math
import os
import re
import shutil
import signal
import subprocess
import time
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path

import pytest
import zstandard
from alog_oracle import iter_entries
from helpers import Proc, free_port, run_cli

from fleetlog.api import Vehicle
from fleetlog.moos.alog import BANNER_RULE, BinaryRef, Entry
from fleetlog.moos.blog import payload_at
from fleetlog.moos.slog_read import SlogFile, parse_slog
from fleetlog.moos.ylog import YlogFile, parse_ylog
from fleetlog.transport.services import live_vehicles
from fleetlog.transport.session import SessionOptions, open_session

RUN_A = "runA_themoos_wildcard_restart"
PAYLOAD = bytes.fromhex("00112233445566778899aabbccddeeff")
CTIME = re.compile(r"[A-Z][a-z]{2} [A-Z][a-z]{2} [ 123]\d \d\d:\d\d:\d\d \d{4}")
#: how long a recorder may take to stop on this 2-core machine (Proc.wait_for allows 15 s to start)
STOP_TIMEOUT = 5.0
#: the session metadata file beside pLogger's files (docs/wire.md)
META = ".fleetlog-session.json"


class Recorder(Proc):
    """A ``fleetlog record`` subprocess whose stderr is read by a thread."""

    def __init__(self, args: Sequence[str], cwd: Path, env: dict[str, str]) -> None:
        self.started = time.time()
        super().__init__(["record", *args], cwd, env)

    def stop(self, sig: int = signal.SIGINT, timeout: float = STOP_TIMEOUT) -> int:
        """Send ``sig`` and return the exit code; fail if it takes longer than ``timeout``."""
        return super().stop(sig, timeout)


@pytest.fixture
def record(
    tmp_path: Path, endpoint: str, cli_env: dict[str, str]
) -> Iterator[Callable[..., Recorder]]:
    """Start recorders in ``tmp_path`` listening on ``endpoint``; kill leftovers at the end."""
    started: list[Recorder] = []

    def start(*args: str, listen: str | None = None, cwd: Path | None = None) -> Recorder:
        rec = Recorder(
            [*args, "-l", listen or endpoint, "--no-multicast-scouting"],
            cwd or tmp_path,
            cli_env,
        )
        started.append(rec)
        rec.wait_for("recording")
        return rec

    yield start
    for rec in started:
        rec.close()


def poke(
    endpoint: str | Sequence[str], cwd: Path, env: dict[str, str], *args: str
) -> subprocess.CompletedProcess[str]:
    endpoints = [endpoint] if isinstance(endpoint, str) else list(endpoint)
    connect = [arg for e in endpoints for arg in ("-e", e)]
    return run_cli("poke", *args, *connect, "--no-multicast-scouting", cwd=cwd, env=env)


def vehicle(name: str, endpoint: str, source: str = "iTest") -> Vehicle:
    return Vehicle(
        name,
        source=source,
        options=SessionOptions(connect=(endpoint,), multicast_scouting=False),
    )


def publish_all(v: Vehicle, items: Sequence[tuple[str, float | str | bytes, str]]) -> None:
    """Publish ``(name, value, aux)`` items once the recorder's subscription is known."""
    for name, value, aux in items:
        assert v.wait_for_subscriber(name, timeout=10.0), name
        v.publish(name, value, aux=aux)


def session_dirs(where: Path) -> list[Path]:
    return sorted(p for p in where.iterdir() if p.is_dir() and p.name != "mission")


def entries(path: Path) -> list[Entry]:
    with open(path, encoding="utf-8", newline="") as f:
        return list(iter_entries(f))


def read(path: Path) -> str:
    return path.read_bytes().decode("utf-8")


def check_banner(text: str, name: str, logstart: tuple[float, float]) -> float:
    """Check the 5-line banner of a bannered file; return its LOGSTART."""
    lines = text.split("\n")
    assert lines[0] == BANNER_RULE
    assert lines[1] == f"%% LOG FILE:       {name}"
    assert lines[2].startswith("%% FILE OPENED ON  ")
    assert CTIME.fullmatch(lines[2][len("%% FILE OPENED ON  ") :])
    assert lines[3].startswith("%% LOGSTART        ")
    value = lines[3][len("%% LOGSTART        ") :]
    assert len(value) == 20
    assert value == value.strip().rjust(20)
    assert lines[4] == BANNER_RULE
    start = float(value)
    assert logstart[0] <= start <= logstart[1]
    return start


def alog_line_shapes(text: str) -> None:
    """Every entry line: a 5-decimal time padded to 15, key to 20, source to 15, one space."""
    for raw in text.split("\n")[5:]:
        if raw and raw[0].isdigit():
            assert re.match(r"\d+\.\d{5} +\S", raw), raw
            assert raw[15] == " "
            assert raw[16:36].rstrip(" ")
            assert raw[36] == " "


# --------------------------------------------------------------------------------------------


E2E_MISSION = """\
// an end-to-end mission
Community = alpha

ProcessConfig = pLogger
{
  File = E2E
  SyncLog = true @ 0.2
  DynamicSyncLogColumns = 1
  LogAuxSrc = true
  Log = NAV_X @ 0
  Log = NAV_Y @ 0 NOSYNC
  WildcardLogging = true
  WildcardOmitPattern = *_STATUS
  WildcardExclusionLog = true
}
"""


def test_record_poke_and_api_into_a_plogger_session(
    record: Callable[..., Recorder], tmp_path: Path, endpoint: str, cli_env: dict[str, str]
) -> None:
    mission = tmp_path / "mission"
    mission.mkdir()
    (mission / "e2e.moos").write_text(E2E_MISSION)
    (mission / "notes.txt").write_bytes(b"copied\r\nbyte for byte\n")
    before = time.time()
    rec = record("mission/e2e.moos")
    after = time.time()
    assert "vehicle 'alpha'" in rec.stderr

    done = poke(
        endpoint,
        tmp_path,
        cli_env,
        "NAV_X=1.5",
        "MSG:=hello, world = yes",
        "EMPTY:=",
        "NUM_STR:=42",
        "SPACES:=  two  spaces ",
        "NL:=line1\nline2",
        "NAV_Y=-20",
        "WORD=true",
        "EXP=1e-7",
        "NOT_A_NUMBER=nan",
        "FOO_STATUS=omitted",
        "--source",
        "uPokeDB",
    )
    assert done.returncode == 0, done.stderr
    with vehicle("alpha", endpoint) as v:
        publish_all(
            v,
            [
                ("NAV_X", 2.25, ""),
                ("DEPLOY", "true", "HELM_VAR_INIT"),
                ("CSV", "a,b,,c", ""),
                ("EQ", "x=1,y=2", ""),
                ("EMPTY", "", ""),
                ("BIN", PAYLOAD, ""),
                ("BIN", b"line\nbreak\x00", ""),
                ("MOOS_DEBUG", "hello\ndebug", ""),
                ("MOOS_SYSTEM", 3.25, ""),
                ("BIG", 123456789.123456, ""),
                ("NEG", -0.0, ""),
                ("PLOGGER_CMD", "LOG_REQUEST = NAV_SPEED @ 0", ""),
                ("PLOGGER_CMD", "COPY_FILE_REQUEST = mission/notes.txt", ""),
            ],
        )
        assert v.confirm(timeout=10.0)
        time.sleep(0.3)  # a slog row after the claim
        publish_all(v, [("NAV_SPEED", 1.25, ""), ("NAV_X", 3.0, "")])
        assert v.confirm(timeout=10.0)
        time.sleep(0.5)  # rows every 0.2 s: NAV_SPEED shows in one
    assert rec.stop(signal.SIGINT) == 0
    assert "fleetlog: stopped: received" in rec.stderr
    assert "Traceback" not in rec.stderr

    (directory,) = session_dirs(tmp_path)
    root = directory.name
    assert re.fullmatch(r"E2E_\d{1,2}_\d{1,2}_\d{4}_____\d\d_\d\d_\d\d", root)
    assert sorted(p.name for p in directory.iterdir()) == sorted(
        [f"{root}{ext}" for ext in (".alog", ".xlog", ".ylog", ".slog", ".blog", "._moos")]
        + ["notes._txt", META]
    )
    assert (tmp_path / ".LastOpenedMOOSLogDirectory").read_text() == (
        f"LastOpenedLoggingDirectory=./{root}\n"
    )
    assert (directory / "notes._txt").read_bytes() == b"copied\r\nbyte for byte\n"

    window = (before - 1.0, after)
    alog = read(directory / f"{root}.alog")
    logstart = check_banner(alog, f"./{root}/{root}.alog", window)
    for ext in (".ylog", ".slog", "._moos"):
        assert check_banner(read(directory / f"{root}{ext}"), f"./{root}/{root}{ext}", window) == (
            logstart
        )
    moos = read(directory / f"{root}._moos")
    assert moos.split(BANNER_RULE + "\n", 2)[2] == E2E_MISSION + "\n"
    alog_line_shapes(alog)

    # the alog, read back: values and their types exactly
    logged = entries(directory / f"{root}.alog")
    assert all(e.offset >= 0 for e in logged)
    mine = [(e.key, e.source, e.value) for e in logged if e.source.startswith(("uPokeDB", "iTest"))]
    ref = BinaryRef(f"{root}.blog", 53, 16)
    ref2 = BinaryRef(f"{root}.blog", 53 + 16 + 1 + 53, 11)
    assert mine == [
        ("NAV_X", "uPokeDB", 1.5),
        ("MSG", "uPokeDB", "hello, world = yes"),
        ("EMPTY", "uPokeDB", ""),
        ("NUM_STR", "uPokeDB", "42"),
        ("SPACES", "uPokeDB", "  two  spaces "),
        ("NL", "uPokeDB", "line1\nline2"),
        ("NAV_Y", "uPokeDB", -20.0),
        ("WORD", "uPokeDB", "true"),
        ("EXP", "uPokeDB", 0.0),  # 1e-7 is a double, written %.5f
        ("NOT_A_NUMBER", "uPokeDB", "nan"),
        ("NAV_X", "iTest", 2.25),
        ("DEPLOY", "iTest:HELM_VAR_INIT", "true"),
        ("CSV", "iTest", "a,b,,c"),
        ("EQ", "iTest", "x=1,y=2"),
        ("EMPTY", "iTest", ""),
        ("BIN", "iTest", ref),
        ("BIN", "iTest", ref2),
        ("MOOS_DEBUG", "iTest", "hello\ndebug"),
        ("MOOS_SYSTEM", "iTest", 3.25),
        ("BIG", "iTest", 123456789.12346),
        ("NEG", "iTest", -0.0),
        ("PLOGGER_CMD", "iTest", "LOG_REQUEST = NAV_SPEED @ 0"),
        ("PLOGGER_CMD", "iTest", "COPY_FILE_REQUEST = mission/notes.txt"),
        ("NAV_SPEED", "iTest", 1.25),
        ("NAV_X", "iTest", 3.0),
    ]
    assert math.copysign(1.0, next(e.value for e in logged if e.key == "NEG")) == -1.0  # type: ignore[arg-type]
    # exact columns, padding and the terminator space
    assert f" {'MSG':<20} {'uPokeDB':<15} hello, world = yes \n" in alog
    assert f" {'EMPTY':<20} {'uPokeDB':<15}  \n" in alog
    assert f" {'NAV_Y':<20} {'uPokeDB':<15} {'-20.00000':<12} \n" in alog
    assert f" {'BIG':<20} {'iTest':<15} 123456789.12346 \n" in alog
    assert f" {'NL':<20} {'uPokeDB':<15} line1\nline2 \n" in alog
    assert (
        f" {'BIN':<20} {'iTest':<15} <MOOS_BINARY>File={root}.blog,Offset=53,Bytes=16"
        "</MOOS_BINARY>\n"
    ) in alog
    blog = (directory / f"{root}.blog").read_bytes()
    assert payload_at(blog, ref) == PAYLOAD
    assert payload_at(blog, ref2) == b"line\nbreak\x00"
    own = {(e.key, str(e.value)) for e in logged if e.source == "pLogger"}
    assert ("LOGGER_DIRECTORY", f"./{root}") in own

    # xlog: the omitted variables, alog-formatted, no banner
    xlog = read(directory / f"{root}.xlog")
    assert xlog
    assert not xlog.startswith("%")
    assert f" {'FOO_STATUS':<20} {'uPokeDB':<15} omitted \n" in xlog
    assert {e.key for e in entries(directory / f"{root}.xlog")} <= {"FOO_STATUS", "PLOGGER_STATUS"}

    # ylog: MOOS_DEBUG and MOOS_SYSTEM, newlines removed
    ylog: YlogFile = parse_ylog(read(directory / f"{root}.ylog"))
    assert [(y.key, y.source, y.text) for y in ylog.entries if y.source == "iTest"] == [
        ("MOOS_DEBUG", "iTest", "hellodebug"),
        ("MOOS_SYSTEM", "iTest", "3.25"),
    ]

    # slog: NAV_X and the claimed column; NAV_Y is NOSYNC
    slog: SlogFile = parse_slog(read(directory / f"{root}.slog"))
    assert [(c.name, c.slot) for c in slog.columns] == [("NAV_X", False), ("NAV_SPEED", True)]
    assert slog.truncated == ""
    values = [r.values for r in slog.rows]
    assert any(row[0] == 2.25 for row in values)
    assert (3.0, 1.25) in values
    assert all(line.endswith(" ") for line in read(directory / f"{root}.slog").split("\n")[12:-1])


# --------------------------------------------------------------------------------------------
# The reference mission, unchanged


def _itest_set(path: Path) -> set[tuple[str, str, str]]:
    """(key, source, value text) of iTest's entries, binary ones left out."""
    return {
        (e.key, e.source, e.text)
        for e in entries(path)
        if e.source.startswith("iTest") and not isinstance(e.value, BinaryRef)
    }


def test_reference_mission_runs_unchanged(
    record: Callable[..., Recorder], tmp_path: Path, endpoint: str, reference: Path
) -> None:
    captured = reference / "captured" / RUN_A
    for name in ("test.moos", "alpha.bhv"):
        shutil.copyfile(captured / name, tmp_path / name)
    rec = record("test.moos")
    assert "vehicle 'test'" in rec.stderr  # the mission's Community
    with vehicle("test", endpoint) as v:
        publish_all(
            v,
            [
                ("NAV_X", 1.5, ""),
                ("NAV_Y", -20.0, ""),
                ("DEPLOY", "true", "HELM_VAR_INIT"),
                ("EMPTY", "", ""),
                ("MULTI", "line1\nline2", ""),
                ("BIN", PAYLOAD, ""),
                ("MOOS_DEBUG", "hello\ndebug", ""),
                ("MOOS_SYSTEM", 3.25, ""),
                ("NAV_HEADING", 123456789.123456, ""),
                ("TINY", 1e-7, ""),
                ("NEG", -0.0, ""),
                ("FOO_STATUS", "omitted one", ""),
                ("WILD_ONE", 7.0, ""),
            ],
        )
        assert v.confirm(timeout=10.0)
        time.sleep(0.7)  # slog rows every 0.5 s
        publish_all(
            v,
            [
                ("NAV_X", 2.25, ""),
                ("WILD_ONE", 8.0, ""),
                ("PLOGGER_CMD", "LOG_REQUEST = NAV_SPEED @ 0", ""),
            ],
        )
        assert v.confirm(timeout=10.0)
        publish_all(
            v,
            [
                ("NAV_SPEED", 1.2, ""),
                ("PLOGGER_CMD", "COPY_FILE_REQUEST = alpha.bhv", ""),
                ("PLOGGER_CMD", "FROBNICATE = 1", ""),
            ],
        )
        assert v.confirm(timeout=10.0)
        time.sleep(0.7)
        publish_all(v, [("NAV_SPEED", 1.3, ""), ("NAV_X", 3.0, "")])
        assert v.confirm(timeout=10.0)
        time.sleep(0.7)
        publish_all(v, [("LOGGER_RESTART", "true", "")])
        assert v.confirm(timeout=10.0)
        time.sleep(0.3)
        publish_all(
            v, [("NAV_X", 4.0, ""), ("BIN", PAYLOAD, ""), ("MOOS_DEBUG", "after restart", "")]
        )
        assert v.confirm(timeout=10.0)
    # MONITOR runs every 10 s from the recorder's start, as in the reference run: wait for
    # its notice in the second session (lines reach the file within 20 ms)
    deadline = rec.started + 18.0
    while time.time() < deadline:
        second_alogs = [d / f"{d.name}.alog" for d in session_dirs(tmp_path)[1:]]
        if second_alogs and 'Variable "GPS_FIX" is not appearing' in read(second_alogs[0]):
            break
        time.sleep(0.1)
    assert rec.stop() == 0

    ref_dirs = sorted((captured / "logs").iterdir())
    mine = session_dirs(tmp_path)
    assert len(mine) == len(ref_dirs) == 2
    # Path = /home/alpha/mission/logs does not exist: pLogger's fallback to ./
    assert all(d.parent == tmp_path for d in mine)
    roots = [d.name for d in mine]
    ref_roots = [d.name for d in ref_dirs]
    assert all(
        re.fullmatch(r"TEST_\d{1,2}_\d{1,2}_\d{4}_____\d\d_\d\d_\d\d(-2)?", r) for r in roots
    )
    assert (tmp_path / ".LastOpenedMOOSLogDirectory").read_text() == (
        f"LastOpenedLoggingDirectory=./{roots[1]}\n"
    )

    def names(d: Path, root: str) -> set[str]:
        return {p.name.replace(root, "ROOT") for p in d.iterdir()}

    # the same file set plus the metadata; after the restart the xlog and blog exist too (§12)
    assert names(mine[0], roots[0]) == names(ref_dirs[0], ref_roots[0]) | {META}
    assert names(mine[1], roots[1]) == names(ref_dirs[1], ref_roots[1]) | {
        "ROOT.xlog",
        "ROOT.blog",
        META,
    }
    assert (mine[0] / "alpha._bhv").read_bytes() == (ref_dirs[0] / "alpha._bhv").read_bytes()
    for mine_dir, ref_dir, root, ref_root in zip(mine, ref_dirs, roots, ref_roots, strict=True):
        body = read(mine_dir / f"{root}._moos").split(BANNER_RULE + "\n", 2)[2]
        assert body == read(ref_dir / f"{ref_root}._moos").split(BANNER_RULE + "\n", 2)[2]
        for ext in (".alog", ".ylog", ".slog", "._moos"):
            text = read(mine_dir / f"{root}{ext}")
            assert text.split("\n")[1] == f"%% LOG FILE:       ./{root}/{root}{ext}"
            assert text.split("\n")[4] == BANNER_RULE
        alog_line_shapes(read(mine_dir / f"{root}.alog"))

    # session 1: iTest's lines are the reference's, value for value and byte for byte
    first = mine[0] / f"{roots[0]}.alog"
    assert _itest_set(first) == _itest_set(ref_dirs[0] / f"{ref_roots[0]}.alog")
    (bin1,) = [e.value for e in entries(first) if e.key == "BIN"]
    assert bin1 == BinaryRef(f"{roots[0]}.blog", 53, 16)  # the reference's first offset
    assert payload_at((mine[0] / f"{roots[0]}.blog").read_bytes(), bin1) == PAYLOAD
    last = entries(first)[-1]
    assert (last.key, last.source, last.value) == ("LOGGER_RESTART", "iTest", "true")
    own = [(e.key, str(e.value)) for e in entries(first) if e.source == "pLogger"]
    fell_back = (
        f"could not create /home/alpha/mission/logs/{roots[0]}: "
        f"logging to the fallback ./{roots[0]}"
    )
    # pLogger printed the fallback on stdout; fleetlog posts it too
    assert own[:2] == [("MOOS_DEBUG", fell_back), ("LOGGER_DIRECTORY", f"./{roots[0]}")]
    assert ("MOOS_DEBUG", "Dynamic command FROBNICATE is not supported") in own
    xlog = {(e.key, e.source) for e in entries(mine[0] / f"{roots[0]}.xlog")}
    ref_xlog = {(e.key, e.source) for e in entries(ref_dirs[0] / f"{ref_roots[0]}.xlog")}
    assert xlog == ref_xlog == {("FOO_STATUS", "iTest"), ("PLOGGER_STATUS", "pLogger")}
    assert not read(mine[0] / f"{roots[0]}.xlog").startswith("%")

    def ylog_set(path: Path) -> set[tuple[str, str, str]]:
        return {(y.key, y.source, y.text) for y in parse_ylog(read(path)).entries}

    assert ylog_set(mine[0] / f"{roots[0]}.ylog") == (
        ylog_set(ref_dirs[0] / f"{ref_roots[0]}.ylog")
        - {("MOOS_DEBUG", "pLogger", "failed to process dynamic log request  - see pLogger output")}
        | {
            ("MOOS_DEBUG", "pLogger", "Dynamic command FROBNICATE is not supported"),
            ("MOOS_DEBUG", "pLogger", fell_back),
        }
    )
    slog = parse_slog(read(mine[0] / f"{roots[0]}.slog"))
    ref_slog = parse_slog(read(ref_dirs[0] / f"{ref_roots[0]}.slog"))
    assert [(c.name, c.slot) for c in slog.columns] == [(c.name, c.slot) for c in ref_slog.columns]
    assert [c.name for c in slog.columns] == [
        "NAV_X", "NAV_Y", "NAV_HEADING", "TINY", "NEG", "NAV_SPEED", "DYNAMIC_1"
    ]  # fmt: skip
    assert next(lab.names for lab in slog.labels) == ref_slog.labels[0].names
    columns = list(zip(*(r.values for r in slog.rows), strict=True))
    assert 1.5 in columns[0]
    assert -20.0 in columns[1]
    assert 123457000.0 in columns[2]
    assert 1e-07 in columns[3]
    assert any(v == 0.0 and math.copysign(1.0, v) < 0 for v in columns[4] if v is not None)
    assert {1.2, 1.3} & set(columns[5])

    # session 2: the restart notices first, then the traffic; the blog works (pLogger: -1)
    second = entries(mine[1] / f"{roots[1]}.alog")
    ref_second = entries(ref_dirs[1] / f"{ref_roots[1]}.alog")

    def notices(items: list[Entry], root_a: str, root_b: str) -> list[tuple[str, str]]:
        out = [(e.key, str(e.value)) for e in items[:4]]
        return [(k, v.replace(root_a, "A").replace(root_b, "B")) for k, v in out]

    assert notices(second, roots[0], roots[1]) == [
        ("MOOS_DEBUG", "Closing : A"),
        ("MOOS_DEBUG", "could not create /home/alpha/mission/logs/B: logging to the fallback ./B"),
        ("LOGGER_DIRECTORY", "./B"),
        ("MOOS_DEBUG", "Now Logging to : B"),
    ]
    assert [
        n for n in notices(ref_second, ref_roots[0], ref_roots[1])[:3] if n[0] == "MOOS_DEBUG"
    ] == [
        ("MOOS_DEBUG", "Closing : A"),
        ("MOOS_DEBUG", "Now Logging to : B"),
    ]
    assert _itest_set(mine[1] / f"{roots[1]}.alog") == _itest_set(
        ref_dirs[1] / f"{ref_roots[1]}.alog"
    )
    (bin2,) = [e.value for e in second if e.key == "BIN"]
    assert bin2 == BinaryRef(f"{roots[1]}.blog", 53, 16)
    assert payload_at((mine[1] / f"{roots[1]}.blog").read_bytes(), bin2) == PAYLOAD
    assert ("MOOS_DEBUG", "1 monitored variable is not being logged\n") in [
        (e.key, e.value) for e in second
    ]
    assert ylog_set(mine[1] / f"{roots[1]}.ylog") >= {
        ("MOOS_DEBUG", "pLogger", f"Closing : {roots[0]}"),
        ("MOOS_DEBUG", "pLogger", f"Now Logging to : {roots[1]}"),
        ("MOOS_DEBUG", "iTest", "after restart"),
        ("MOOS_DEBUG", "pLogger", "1 monitored variable is not being logged"),
        ("MOOS_DEBUG", "pLogger", 'Monitored Variable "GPS_FIX" is not appearing'),
    }
    slog2 = parse_slog(read(mine[1] / f"{roots[1]}.slog"))
    ref_slog2 = parse_slog(read(ref_dirs[1] / f"{ref_roots[1]}.slog"))
    assert [(c.name, c.slot) for c in slog2.columns] == [
        (c.name, c.slot) for c in ref_slog2.columns
    ]
    # a fresh LOGSTART for the new session (pLogger kept the old one), right-aligned
    starts = [
        float(read(d / f"{r}.alog").split("\n")[3][19:]) for d, r in zip(mine, roots, strict=True)
    ]
    assert starts[0] < starts[1]
    assert read(mine[1] / f"{roots[1]}.slog").split("\n")[3].endswith(f"{starts[1]:.16g}")
    assert (mine[1] / f"{roots[1]}.xlog").stat().st_size > 0  # PLOGGER_STATUS after restart


# --------------------------------------------------------------------------------------------
# Without a mission, liveliness, signals


def test_no_mission_logs_everything_with_liveliness_and_sigterm(
    record: Callable[..., Recorder], tmp_path: Path, endpoint: str, cli_env: dict[str, str]
) -> None:
    watcher_endpoint = f"tcp/127.0.0.1:{free_port()}"
    watcher = open_session(SessionOptions(listen=(watcher_endpoint,), multicast_scouting=False))
    try:
        rec = Recorder(
            [
                "--vehicle",
                "bravo",
                "-l",
                endpoint,
                "-e",
                watcher_endpoint,
                "--no-multicast-scouting",
            ],
            tmp_path,
            cli_env,
        )
        try:
            rec.wait_for("recording")
            deadline = time.monotonic() + 5.0
            while live_vehicles(watcher, "fleet", timeout=0.5) != {"bravo": {"recorder"}}:
                assert time.monotonic() < deadline, "the recorder's liveliness token never showed"
            done = poke(endpoint, tmp_path, cli_env, "ANYTHING=1", "ELSE:=two words")
            assert done.returncode == 0, done.stderr
            assert "-> vehicle bravo" in done.stderr  # the one reachable recorder
            # a plain Zenoh publisher: no fleetlog encoding, no attachment
            with Vehicle("bravo", session=watcher) as v:
                assert v.wait_for_subscriber("RAW_NUM", timeout=10.0)
                watcher.put("fleet/bravo/var/RAW_NUM", "-3.5e2")
                watcher.put("fleet/bravo/var/RAW_TEXT", "free text")
                watcher.put("fleet/bravo/var/RAW_BIN", b"\xff\x00\n")
                watcher.put("fleet/bravo/var/BAD%ZZ", "a key that names no variable")
                assert v.confirm(timeout=10.0)
            time.sleep(0.3)  # the recorder's MOOS_DEBUG about BAD%ZZ comes back through Zenoh
            assert rec.stop(signal.SIGTERM) == 0
        finally:
            rec.close()
        assert "fleetlog: stopped:" in rec.stderr
        deadline = time.monotonic() + 5.0
        while live_vehicles(watcher, "fleet", timeout=0.5):
            assert time.monotonic() < deadline, "the liveliness token outlived the recorder"
    finally:
        watcher.close()
    (directory,) = session_dirs(tmp_path)
    assert directory.name.startswith("MOOSLog_")
    root = directory.name
    assert sorted(p.name for p in directory.iterdir()) == sorted(
        [f"{root}{ext}" for ext in (".alog", ".ylog", ".blog")] + [META]
    )
    logged = entries(directory / f"{root}.alog")
    got = {(e.key, e.value) for e in logged}
    assert {("ANYTHING", 1.0), ("ELSE", "two words"), ("LOGGER_DIRECTORY", f"./{root}")} <= got
    raw = {e.key: (e.source, e.value) for e in logged if e.key.startswith("RAW_")}
    assert raw["RAW_NUM"] == ("?", -350.0)
    assert raw["RAW_TEXT"] == ("?", "free text")
    source, ref = raw["RAW_BIN"]
    assert source == "?"
    assert isinstance(ref, BinaryRef)
    assert payload_at((directory / f"{root}.blog").read_bytes(), ref) == b"\xff\x00\n"
    # nothing silent: the unreadable key is counted and reported
    assert (
        "MOOS_DEBUG",
        "sample on fleet/bravo/var/BAD%ZZ names no MOOS variable: not logged",
    ) in got
    assert "garbled 1, lost 1" in rec.stderr


def test_poke_without_a_recorder_fails_in_one_line(tmp_path: Path, cli_env: dict[str, str]) -> None:
    nobody = f"tcp/127.0.0.1:{free_port()}"
    done = poke(nobody, tmp_path, cli_env, "NAV_X=1")
    assert done.returncode == 1
    assert done.stderr == (
        "fleetlog: error: no fleetlog recorder is reachable; name the vehicle with --vehicle\n"
    )
    # with a vehicle named, poke waits for a subscriber, then says nothing was delivered
    done = poke(nobody, tmp_path, cli_env, "NAV_X=1", "--vehicle", "ghost", "--wait", "0.5")
    assert done.returncode == 1
    assert done.stderr == (
        "fleetlog: error: nobody subscribes to NAV_X of vehicle 'ghost'; nothing was delivered\n"
    )


def test_api_waits_for_a_subscriber(record: Callable[..., Recorder], endpoint: str) -> None:
    options = SessionOptions(listen=(endpoint,), multicast_scouting=False)
    with Vehicle("alpha", source="iTest", options=options) as v:
        assert not v.wait_for_subscriber("NAV_X", timeout=0.2)  # no recorder yet
        rec = record("--vehicle", "alpha", "-e", endpoint, listen=f"tcp/127.0.0.1:{free_port()}")
        assert v.wait_for_subscriber("NAV_X", timeout=10.0)
        v.publish("NAV_X", 1.0)
        assert v.confirm(timeout=10.0)
    assert rec.stop() == 0


def zenoh_threads(pid: int) -> list[str]:
    """The names of a process's Zenoh runtime threads (``rx-0``, ``acc-0``, ...)."""
    names = []
    for task in Path(f"/proc/{pid}/task").iterdir():
        try:
            name = (task / "comm").read_text().strip()
        except OSError:
            continue  # a thread that ended
        if re.fullmatch(r"(rx|tx|acc|net|app)-\d+", name):
            names.append(name)
    return sorted(names)


def test_the_receiving_threads_watch_the_links_themselves(
    record: Callable[..., Recorder], endpoint: str, cli_env: dict[str, str]
) -> None:
    """No Zenoh thread of its own watches the links a recorder accepts or opens.

    Such a thread wakes a receiving thread for every message that travels alone (docs/
    bench.md §15). An operator's ZENOH_RUNTIME still wins.
    """
    options = SessionOptions(listen=(endpoint,), multicast_scouting=False)
    with Vehicle("alpha", source="iTest", options=options) as v:
        rec = record("--vehicle", "alpha", "-e", endpoint, listen=f"tcp/127.0.0.1:{free_port()}")
        assert v.wait_for_subscriber("NAV_X", timeout=10.0)
        v.publish("NAV_X", 1.0)
        assert v.confirm(timeout=10.0)
        threads = zenoh_threads(rec.proc.pid)
        assert "rx-0" in threads
        assert not [t for t in threads if t.startswith(("acc-", "net-"))], threads
        assert rec.stop() == 0
        cli_env["ZENOH_RUNTIME"] = "(rx: (worker_threads: 1))"
        mine = record("--vehicle", "alpha", "-e", endpoint, listen=f"tcp/127.0.0.1:{free_port()}")
        assert v.wait_for_subscriber("NAV_X", timeout=10.0)
        threads = zenoh_threads(mine.proc.pid)
        assert "acc-0" in threads
        assert "rx-1" not in threads
        assert mine.stop() == 0


def test_poke_names_several_recorders(
    record: Callable[..., Recorder], tmp_path: Path, endpoint: str, cli_env: dict[str, str]
) -> None:
    other = f"tcp/127.0.0.1:{free_port()}"
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    alpha = record("--vehicle", "alpha", cwd=tmp_path / "a")
    bravo = record("--vehicle", "bravo", listen=other, cwd=tmp_path / "b")
    done = poke([endpoint, other], tmp_path, cli_env, "NAV_X=1")
    assert done.returncode == 1
    assert done.stderr == (
        "fleetlog: error: several recorders are reachable (alpha, bravo); choose one with "
        "--vehicle\n"
    )
    done = poke([endpoint, other], tmp_path, cli_env, "NAV_X=2", "--vehicle", "bravo")
    assert done.returncode == 0, done.stderr
    assert alpha.stop() == 0
    assert bravo.stop() == 0
    (a_dir,) = session_dirs(tmp_path / "a")
    (b_dir,) = session_dirs(tmp_path / "b")
    assert "NAV_X" not in {e.key for e in entries(a_dir / f"{a_dir.name}.alog")}
    assert ("NAV_X", 2.0) in {(e.key, e.value) for e in entries(b_dir / f"{b_dir.name}.alog")}


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (
            "ProcessConfig = pLogger\n{\n  Log = X @ 0\n  Log = Y @ -1\n}\n",
            "bad.moos:4: log entry 'Y@-1' has a negative period",
        ),
        (
            "Community = alpha\nProcessConfig = pLogger\n{\n  Log = X @ 0\n",
            "bad.moos:2: the block of ProcessConfig = pLogger is never closed by a line "
            "beginning with '}'",
        ),
        (
            "ProcessConfig = pLogger\n{\n  DoublePrecision = many\n}\n",
            "bad.moos:3: DoublePrecision value 'many' is not an integer",
        ),
    ],
)
def test_bad_mission_file_is_one_line_naming_file_and_line(
    tmp_path: Path, cli_env: dict[str, str], text: str, message: str
) -> None:
    (tmp_path / "bad.moos").write_text(text)
    done = run_cli("record", "bad.moos", "--no-multicast-scouting", cwd=tmp_path, env=cli_env)
    assert done.returncode == 1
    assert done.stderr == f"fleetlog: error: {message}\n"
    assert os.listdir(tmp_path) == ["bad.moos"]  # no session was started


def test_kill_9_leaves_every_line_older_than_20_ms_readable(
    record: Callable[..., Recorder], tmp_path: Path, endpoint: str
) -> None:
    rec = record("--vehicle", "alpha")
    count = 2000
    with vehicle("alpha", endpoint) as v:
        assert v.wait_for_subscriber("N", timeout=10.0)
        for i in range(count):
            v.publish("N", float(i))
            if i % 500 == 0:
                v.publish("S", f"multi\nline {i}")
        assert v.confirm(timeout=10.0)
        time.sleep(0.1)
        rec.proc.kill()  # SIGKILL: no shutdown at all
        rec.proc.wait(5)
    (directory,) = session_dirs(tmp_path)
    text = read(directory / f"{directory.name}.alog")
    assert text.endswith("\n")
    got = entries(directory / f"{directory.name}.alog")
    assert [e.value for e in got if e.key == "N"] == [float(i) for i in range(count)]
    assert [e.value for e in got if e.key == "S"] == [
        f"multi\nline {i}" for i in range(0, count, 500)
    ]


@pytest.mark.parametrize("compression", ["gzip", "zstd"])
def test_log_request_subscribes_once_and_compressed_streams_finish(
    record: Callable[..., Recorder], tmp_path: Path, endpoint: str, compression: str
) -> None:
    (tmp_path / "m.moos").write_text(
        "Community = alpha\n"
        "ProcessConfig = pLogger\n{\n"
        "  Log = NAV_X @ 0\n"
        "  WildcardLogging = true\n"
        "  WildcardPattern = NAV_*\n"
        f"  CompressAlogs = {compression}\n"
        "}\n"
    )
    rec = record("m.moos")
    with vehicle("alpha", endpoint) as v:
        # NAV_SPEED comes in through the NAV_* subscription already; OTHER through none
        publish_all(
            v,
            [
                ("PLOGGER_CMD", "LOG_REQUEST = NAV_SPEED @ 0", ""),
                ("PLOGGER_CMD", "LOG_REQUEST = OTHER @ 0", ""),
            ],
        )
        assert v.confirm(timeout=10.0)
        time.sleep(0.3)  # the requests are handled
        publish_all(v, [("NAV_SPEED", 1.5, ""), ("OTHER", "x", ""), ("NAV_X", 2.0, "")])
        assert v.confirm(timeout=10.0)
    assert rec.stop() == 0
    (directory,) = session_dirs(tmp_path)
    root = directory.name
    ext = ".gz" if compression == "gzip" else ".zst"
    assert sorted(p.name for p in directory.iterdir()) == sorted(
        [
            f"{root}.alog{ext}",
            f"{root}.xlog{ext}",
            f"{root}.ylog",
            f"{root}.blog",
            f"{root}._moos",
            META,
        ]
    )
    data = (directory / f"{root}.alog{ext}").read_bytes()
    xdata = (directory / f"{root}.xlog{ext}").read_bytes()
    if compression == "gzip":
        # a finished gzip member: gzip.decompress refuses a cut one
        text, xtext = gzip.decompress(data).decode(), gzip.decompress(xdata)
    else:
        reader = zstandard.ZstdDecompressor()
        text = reader.stream_reader(io.BytesIO(data), read_across_frames=True).read().decode()
        xtext = reader.stream_reader(io.BytesIO(xdata), read_across_frames=True).read()
    assert xtext == b""
    assert text.split("\n")[1] == f"%% LOG FILE:       ./{root}/{root}.alog"
    got = [(e.key, e.value) for e in iter_entries(text.splitlines(keepends=True))]
    logged = [item for item in got if item[0] in ("NAV_SPEED", "OTHER", "NAV_X")]
    # each once (two subscribers: no order between them)
    assert sorted(logged, key=str) == [("NAV_SPEED", 1.5), ("NAV_X", 2.0), ("OTHER", "x")]


def test_sigint_under_load_logs_everything_received(
    record: Callable[..., Recorder], tmp_path: Path, endpoint: str
) -> None:
    rec = record("--vehicle", "alpha")
    count = 20000
    with vehicle("alpha", endpoint) as v:
        assert v.wait_for_subscriber("N", timeout=10.0)
        for i in range(count):
            v.publish("N", float(i))
        assert v.confirm(timeout=20.0)  # all of them reached the recorder's session
        assert rec.stop() == 0  # at once: the backlog is drained before the files close
    (directory,) = session_dirs(tmp_path)
    got = [e.value for e in entries(directory / f"{directory.name}.alog") if e.key == "N"]
    assert got == [float(i) for i in range(count)]
    assert "lost 0 in 1 session(s)" in rec.stderr


def test_no_session_directory_at_all_is_one_line_and_exit_1(
    tmp_path: Path, endpoint: str, cli_env: dict[str, str]
) -> None:
    # neither Path nor the ./ fallback can be created (File names a missing subdirectory)
    (tmp_path / "m.moos").write_text(
        "ProcessConfig = pLogger\n{\n  Path = /nonexistent\n  File = no/such\n}\n"
    )
    done = run_cli(
        "record", "m.moos", "-l", endpoint, "--no-multicast-scouting", cwd=tmp_path, env=cli_env
    )
    assert done.returncode == 1
    assert re.fullmatch(
        r"fleetlog: error: cannot create log directory /nonexistent/no/such_\S+ \(No such file "
        r"or directory\) nor the fallback \./no/such_\S+ \(No such file or directory\)\n",
        done.stderr,
    )


def test_running_recorder_serves_its_sessions_to_shore(
    record: Callable[..., Recorder], tmp_path: Path, endpoint: str, cli_env: dict[str, str]
) -> None:
    rec = record("--vehicle", "delta")
    done = poke(endpoint, tmp_path, cli_env, "NAV_X=4.25", "NOTE:=served live")
    assert done.returncode == 0, done.stderr
    connect = ("-e", endpoint, "--no-multicast-scouting")
    listing = run_cli("sessions", "delta", "--json", *connect, cwd=tmp_path, env=cli_env)
    assert listing.returncode == 0, listing.stderr
    (directory,) = session_dirs(tmp_path)
    assert directory.name in listing.stdout
    assert '"complete": false' in listing.stdout  # the recorder says it is still writing
    found = run_cli("query", "delta", "NAV_*", *connect, cwd=tmp_path, env=cli_env)
    assert found.returncode == 0, found.stderr
    lines = [line for line in found.stdout.splitlines() if line[:1].isdigit()]
    assert len(lines) == 1
    assert lines[0].split()[1:4] == ["NAV_X", "uPokeDB", "4.25000"]
    assert rec.stop(signal.SIGINT) == 0
    # stopped: nothing serves the vehicle any more, and shore says so in one line
    gone = run_cli("sessions", "delta", *connect, "--timeout", "1", cwd=tmp_path, env=cli_env)
    assert gone.returncode != 0
    assert len(gone.stderr.strip().splitlines()) == 1, gone.stderr


def test_a_second_recorder_of_the_same_vehicle_is_refused(
    record: Callable[..., Recorder], tmp_path: Path, endpoint: str, cli_env: dict[str, str]
) -> None:
    first = record("--vehicle", "echo")
    other = tmp_path / "other"
    other.mkdir()
    second = run_cli(
        "record",
        "--vehicle",
        "echo",
        "-e",
        endpoint,
        "--no-multicast-scouting",
        cwd=other,
        env=cli_env,
    )
    assert second.returncode == 1
    (line,) = second.stderr.strip().splitlines()
    assert line.startswith("fleetlog: error: a recorder of vehicle 'echo' is already running")
    assert list(other.iterdir()) == []  # refused before any session was opened
    # another vehicle on the same network is fine
    third = record("--vehicle", "foxtrot", "-e", endpoint, listen=f"tcp/127.0.0.1:{free_port()}")
    assert third.proc.poll() is None
    assert first.stop(signal.SIGINT) == 0
