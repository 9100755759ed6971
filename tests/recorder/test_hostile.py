"""A hostile peer against a real ``fleetlog record`` process (issue 10).

Each test starts the recorder as a subprocess on a loopback endpoint, attacks it through a
raw Zenoh session (forged attachments, keys, values), stops it with a signal and reads what
reached the disk with fleetlog's reader.
"""

from __future__ import annotations

import math
import re
import struct
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import zenoh
from alog_oracle import iter_entries
from helpers import Proc, run_cli

from fleetlog.moos.alog import Entry, split_source
from fleetlog.transport.session import SessionOptions, open_session
from fleetlog.wire.message import ENCODINGS, Kind, encode_attachment

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
