"""A hostile peer against a real ``fleetlog record`` process (issue 10).

Each test starts the recorder as a subprocess on a loopback endpoint, attacks it through a
raw Zenoh session (forged attachments, keys, values), stops it with a signal and reads what
reached the disk with fleetlog's reader.
"""

from __future__ import annotations

import itertools
import json
import math
import re
import signal
import struct
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import zenoh
from alog_oracle import iter_entries
from helpers import Proc, run_cli

from fleetlog.moos.alog import Entry, split_source
from fleetlog.storage.readers import AlogReader
from fleetlog.transport.session import SessionOptions, open_session
from fleetlog.wire.message import ENCODINGS, Kind, encode_attachment
from fleetlog.wire.session_meta import META_NAME

STOP_TIMEOUT = 5.0
MISSION = """\
Community = V
ProcessConfig = pLogger
{
  File = H
  LogAuxSrc = true
  MarkExternalCommunityMessages = true
  WildcardLogging = true
}
"""


class Recorder(Proc):
    def __init__(self, tmp_path: Path, endpoint: str, env: dict[str, str]) -> None:
        (tmp_path / "h.moos").write_text(MISSION)
        super().__init__(
            ["record", "h.moos", "-l", endpoint, "--no-multicast-scouting", "--no-serve"],
            tmp_path,
            env,
        )
        self.wait_for("recording")

    def summary(self) -> dict[str, int]:
        line = self.wait_for("stopped:")
        return {k: int(v) for k, v in re.findall(r"(\w+) (\d+)", line)}


@pytest.fixture
def recorder(tmp_path: Path, endpoint: str, cli_env: dict[str, str]) -> Iterator[Recorder]:
    rec = Recorder(tmp_path, endpoint, cli_env)
    yield rec
    rec.close()


@pytest.fixture
def peer(endpoint: str) -> Iterator[zenoh.Session]:
    session = open_session(SessionOptions(connect=(endpoint,), multicast_scouting=False))
    yield session
    session.close()


def raw_attachment(when: float, *strings: bytes) -> bytes:
    """An attachment built by hand: f64 then LEB128-prefixed strings (may be invalid)."""
    out = struct.pack("<d", when)
    for s in strings:
        assert len(s) < 128
        out += bytes([len(s)]) + s
    return out


def put_all(session: zenoh.Session, items: list[tuple[str, bytes, str, bytes | None]]) -> None:
    """Put each ``(key chunk, payload, encoding, attachment)`` under fleet/V/var/."""
    for chunk, payload, encoding, attachment in items:
        key = f"fleet/V/var/{chunk}"
        deadline = time.monotonic() + 10
        pub = session.declare_publisher(
            key, congestion_control=zenoh.CongestionControl.BLOCK, encoding=encoding
        )
        while not pub.matching_status.matching and time.monotonic() < deadline:
            time.sleep(0.01)
        assert pub.matching_status.matching, key
        pub.put(payload, attachment=attachment)
        pub.undeclare()


def alog_entries(where: Path) -> list[Entry]:
    (alog,) = where.glob("*/*.alog")
    with open(alog, encoding="utf-8", errors="surrogateescape", newline="") as f:
        return list(iter_entries(f))


DOUBLE = ENCODINGS[Kind.DOUBLE]
STRING = ENCODINGS[Kind.STRING]


def test_forged_fields_never_write_a_line_that_reads_back_differently(
    recorder: Recorder, peer: zenoh.Session, tmp_path: Path
) -> None:
    now = time.time()
    forged = "0.00000         FORGED          iEvil           666 "

    def att(source: str = "iX", aux: str = "", community: str = "", when: float = now) -> bytes:
        return encode_attachment(when, source, aux, community)

    # (key chunk, payload, encoding, attachment, name and source as they must be logged)
    cases: list[tuple[str, bytes, str, bytes | None, str, str]] = [
        ("SRC_NL", b"1", DOUBLE, att("iX\n" + forged), "SRC_NL", "iX%0A0.00000%20%20%20"),
        ("SRC_SPACE", b"2", DOUBLE, att("i X"), "SRC_SPACE", "i%20X"),
        ("SRC_EMPTY", b"3", DOUBLE, att(""), "SRC_EMPTY", "?"),
        ("SRC_SEPS", b"4", DOUBLE, att("a:b@c"), "SRC_SEPS", "a%3Ab%40c"),
        ("AUX_NL", b"5", DOUBLE, att("iX", "h\n" + forged), "AUX_NL", "iX:h%0A0.00000"),
        ("AUX_AT", b"6", DOUBLE, att("iX", "h@x"), "AUX_AT", "iX:h%40x"),
        ("COMM_TAB", b"7", DOUBLE, att("iX", "", "sh\tore"), "COMM_TAB", "iX@sh%09ore"),
        ("TIME_NAN", b"8", DOUBLE, att(when=math.nan), "TIME_NAN", "iX"),
        ("TIME_INF", b"9", DOUBLE, att(when=math.inf), "TIME_INF", "iX"),
        ("TIME_HUGE", b"10", DOUBLE, att(when=1e300), "TIME_HUGE", "iX"),
        ("TIME_NEG", b"11", DOUBLE, att(when=-1e300), "TIME_NEG", "iX"),
        ("NAME SPACE", b"12", DOUBLE, att(), "NAME%20SPACE", "iX"),
        ("NAME\tTAB", b"13", DOUBLE, att(), "NAME%09TAB", "iX"),
        ("NAME\nNL", b"14", DOUBLE, att(), "NAME%0ANL", "iX"),
        ("%00", b"15", DOUBLE, att(), "%00", "iX"),
        ("BAD_ATT", b"16", DOUBLE, raw_attachment(now, b"iX", b"\xff\xfe", b""), "BAD_ATT", "?"),
        ("SHORT_ATT", b"17", DOUBLE, b"\x00\x01", "SHORT_ATT", "?"),
        ("VAL_FORGE", ("x\n" + forged).encode(), STRING, att(), "VAL_FORGE", "iX"),
    ]
    # Source column prefixes: an escaped source is compared up to its first padding run.
    put_all(peer, [(c, p, e, a) for c, p, e, a, _, _ in cases])
    put_all(peer, [("END", b"0", DOUBLE, att())])
    time.sleep(0.5)
    assert recorder.stop(timeout=STOP_TIMEOUT) == 0
    summary = recorder.summary()
    entries = alog_entries(tmp_path)
    by_key = {e.key: e for e in entries}
    assert not [e for e in entries if "FORGED" in e.key or e.source == "iEvil"]
    for _, payload, _, _, name, source in cases:
        entry = by_key[name]
        assert entry.source.startswith(source), (name, entry.source)
        assert " " not in entry.source
        assert math.isfinite(entry.offset)
        assert 0 <= entry.offset < 60
        if name == "VAL_FORGE":
            assert entry.value == "x\\n" + forged
        else:
            assert entry.value == float(payload)
    # every line that was logged reads back as one entry
    assert len(entries) == summary["logged"]
    # every case but the empty source, whose "?" is the documented rule, is garbled
    assert summary["garbled"] == len(cases) - 1
    for entry in entries:
        src, _aux, _community = split_source(entry.source)
        assert src
        assert " " not in entry.source
        assert "\n" not in entry.source


@pytest.mark.parametrize(
    ("setting", "message"),
    [
        (b"Path = " + b"p" * 300, "bad.moos:3: Path value has a component of 300 bytes"),
        (b"File = caf\xe9", "bad.moos:3: File value 'caf\\udce9' is not UTF-8 text"),
        (b"DoublePrecision = 99999999999", "bad.moos:3: DoublePrecision value '99999999999'"),
        (b"SyncLog = true\n DynamicSyncLogColumns = 99999999999", "bad.moos:4: DynamicSync"),
    ],
)
def test_bad_mission_is_one_line_before_anything_starts(
    tmp_path: Path, cli_env: dict[str, str], setting: bytes, message: str
) -> None:
    (tmp_path / "bad.moos").write_bytes(b"ProcessConfig = pLogger\n{\n " + setting + b"\n}\n")
    done = run_cli("record", "bad.moos", "--no-multicast-scouting", cwd=tmp_path, env=cli_env)
    assert done.returncode == 1
    assert done.stderr.startswith(f"fleetlog: error: {message}")
    assert done.stderr.count("\n") == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.moos"]


FLOOD_MISSION = """\
Community = V
ProcessConfig = pLogger
{
  File = F
  SyncLog = true @ 0.2
  DynamicSyncLogColumns = 4
  Log = HEART @ 0
}
"""


class Heart(threading.Thread):
    """Publishes HEART at 1 kHz, each sample stamped with its own time, until stopped."""

    def __init__(self, session: zenoh.Session) -> None:
        super().__init__(daemon=True)
        self.pub = session.declare_publisher(
            "fleet/V/var/HEART",
            congestion_control=zenoh.CongestionControl.BLOCK,
            encoding=DOUBLE,
        )
        self.sent: list[tuple[int, float]] = []
        self.halt = threading.Event()

    def run(self) -> None:
        start = time.monotonic()
        i = 0
        while not self.halt.is_set():
            when = time.time()
            self.pub.put(str(i).encode(), attachment=encode_attachment(when, "iHeart"))
            self.sent.append((i, when))
            i += 1
            pause = start + i / 1000 - time.monotonic()
            if pause > 0:
                time.sleep(pause)
        self.pub.undeclare()


class Tail(threading.Thread):
    """Watches an alog grow: when each HEART sample and the last command reached the disk."""

    def __init__(self, where: Path) -> None:
        super().__init__(daemon=True)
        self.where = where
        self.seen: dict[int, float] = {}
        self.last_command = 0.0
        self.halt = threading.Event()

    def run(self) -> None:
        alog: Path | None = None
        while alog is None and not self.halt.is_set():
            alog = next(self.where.glob("*/*.alog"), None)
            time.sleep(0.005)
        if alog is None:
            return
        with open(alog, "rb") as f:
            rest = b""
            while not self.halt.is_set():
                chunk = f.read()
                now = time.time()
                if not chunk:
                    time.sleep(0.002)
                    continue
                lines = (rest + chunk).split(b"\n")
                rest = lines.pop()
                for line in lines:
                    fields = line.split()
                    if len(fields) >= 4 and fields[1] == b"HEART":
                        self.seen.setdefault(int(float(fields[3])), now)
                    elif len(fields) >= 2 and fields[1] in (b"PLOGGER_CMD", b"MOOS_DEBUG"):
                        self.last_command = now


def flood(session: zenoh.Session, values: Iterator[str], halt: threading.Event) -> int:
    """Publish PLOGGER_CMD values as fast as BLOCK allows; return how many."""
    pub = session.declare_publisher(
        "fleet/V/var/PLOGGER_CMD",
        congestion_control=zenoh.CongestionControl.BLOCK,
        encoding=STRING,
    )
    count = 0
    attachment = encode_attachment(time.time(), "iEvil")
    for value in values:
        if halt.is_set():
            break
        pub.put(value.encode("utf-8", "surrogateescape"), attachment=attachment)
        count += 1
    pub.undeclare()
    return count


def attack() -> Iterator[str]:
    """LOG_REQUESTs for ever new variables, copies of everything, garbage; for ever."""
    i = 0
    while True:
        yield f"LOG_REQUEST = V_{i} @ 0"
        yield f"LOG_REQUEST = W_{i} @ 0 NOSYNC MONITOR"
        yield "COPY_FILE_REQUEST = flood.moos" if i % 50 == 0 else "COPY_FILE_REQUEST = /etc/passwd"
        yield "COPY_FILE_REQUEST = a\x00b" if i % 2 else "COPY_FILE_REQUEST = " + "x" * 300
        yield "=" * 2000
        i += 1


def test_command_flood_neither_stalls_nor_loses_a_1khz_variable_and_sigterm_stops_it(
    tmp_path: Path, endpoint: str, cli_env: dict[str, str], peer: zenoh.Session
) -> None:
    (tmp_path / "flood.moos").write_text(FLOOD_MISSION)
    rec = Proc(
        ["record", "flood.moos", "-l", endpoint, "--no-multicast-scouting", "--no-serve"],
        tmp_path,
        cli_env,
    )
    try:
        rec.wait_for("recording")
        heart = Heart(peer)
        deadline = time.monotonic() + 10
        while not heart.pub.matching_status.matching and time.monotonic() < deadline:
            time.sleep(0.01)
        tail = Tail(tmp_path)
        tail.start()
        heart.start()
        time.sleep(0.3)
        halt = threading.Event()
        commands = attack()
        sent = flood(peer, itertools.islice(commands, 15_000), halt)
        # The flood is queued at once; HEART goes on until the recorder has worked through
        # it (nothing about the flood reaches the disk for half a second).
        quiet_since = time.monotonic() + 30
        while tail.last_command == 0.0 or time.time() - tail.last_command < 0.5:
            assert time.monotonic() < quiet_since, "the flood never finished reaching the disk"
            time.sleep(0.05)
        heart.halt.set()
        heart.join(10)
        assert not heart.is_alive()
        time.sleep(0.5)
        # Then SIGTERM in the middle of a flood that does not stop by itself.
        attacker = threading.Thread(target=flood, args=(peer, commands, halt), daemon=True)
        attacker.start()
        time.sleep(0.5)
        began = time.monotonic()
        assert rec.stop(signal.SIGTERM, timeout=STOP_TIMEOUT) == 0
        stopped_in = time.monotonic() - began
        halt.set()
        attacker.join(10)
    finally:
        rec.close()
    (session,) = [p for p in tmp_path.iterdir() if p.is_dir()]
    (alog,) = session.glob("*.alog")
    with AlogReader(alog) as reader:
        logstart = reader.logstart
        assert logstart is not None
        beats = [e for e in reader.entries() if e.key == "HEART"]
        assert not reader.truncated
    meta = json.loads((session / META_NAME).read_text())
    assert meta["state"] == "closed"
    # every sample on disk, once, with its own time
    assert len(beats) == len(heart.sent), (len(beats), len(heart.sent))
    for entry, (i, when) in zip(beats, heart.sent, strict=True):
        assert entry.value == float(i)
        assert abs(logstart + entry.offset - when) < 2e-5
    # the flood never held HEART back: each sample reached the disk soon after it was sent
    # (the flush bound is 20 ms; 1 s allows for a loaded 2-core machine), and the longest
    # time without a new HEART line on disk stays as short
    tail.halt.set()
    tail.join(5)
    latency = max(tail.seen[i] - when for i, when in heart.sent)
    seen = sorted(tail.seen.values())
    gap = max(b - a for a, b in itertools.pairwise(seen))
    assert latency < 1.0, latency
    assert gap < 1.0, gap
    assert stopped_in < STOP_TIMEOUT
    assert sent == 15_000
    stats = rec.wait_for("stopped:")
    assert "lost 0" in stats
