"""The recorder engine with a fake clock and real files: pLogger's behaviour, §12's fixes.

No Zenoh here. Each test builds a :class:`Recorder` from a real mission block, feeds it
:class:`MoosMessage` objects as the service would, and reads back what it wrote in
``tmp_path``. What the recorder posts itself (MOOS_DEBUG, LOGGER_DIRECTORY, PLOGGER_STATUS)
lands in a list; :meth:`Rig.loop_back` feeds it back in, as the Zenoh subscription (or the
MOOSDB, for pLogger) does.
"""

from __future__ import annotations

import gzip
import math
import os
import re
import resource
import shutil
import signal
import time
import zlib
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
import zstandard
from alog_oracle import iter_entries

from fleetlog.errors import TransportError
from fleetlog.moos.alog import BinaryRef, Entry, Variant, format_banner
from fleetlog.moos.blog import payload_at
from fleetlog.moos.mission import LoggerConfig, parse_mission
from fleetlog.moos.naming import ctime_text, session_root
from fleetlog.moos.patterns import NAMES_CACHED
from fleetlog.moos.slog import SLOT_WIDTH, format_label_block, format_row
from fleetlog.moos.slog_read import parse_slog
from fleetlog.moos.ylog import format_ylog_line, parse_ylog
from fleetlog.recorder.engine import Recorder
from fleetlog.wire.message import MoosMessage

#: LOGSTART of every rig: exactly representable, so offsets like 0.75 stay exact
T0 = 1_800_000_000.25
DUP = "failed to process dynamic log request  - see pLogger output\n"
#: the session metadata file beside pLogger's files (docs/wire.md)
META = ".fleetlog-session.json"


class FakeClock:
    """A wall clock the test moves by hand."""

    def __init__(self, t: float = T0) -> None:
        self.t = t

    def __call__(self) -> float:
        return self.t

    def at(self, offset: float) -> None:
        """Jump to ``T0 + offset`` (absolute, so no rounding accumulates)."""
        self.t = T0 + offset


def mission_text(body: str, *, head: str = "", app: str = "pLogger") -> str:
    lines = "\n".join(f"  {line.strip()}" for line in body.strip().splitlines())
    return f"Community = alpha\n{head}\nProcessConfig = {app}\n{{\n{lines}\n}}\n"


def config(body: str, *, head: str = "", app: str = "pLogger") -> LoggerConfig:
    return parse_mission(mission_text(body, head=head, app=app), "test.moos").logger_config(app)


#: one ``Name=value`` of a status text; CMOOSApp quotes its lists, which hold commas
STATUS_FIELD = r'(?:^|,)([A-Za-z_]+)=("[^"]*"|[^,]*)'


def status_fields(text: str) -> dict[str, str]:
    return dict(re.findall(STATUS_FIELD, text))


def root_at(file: str, when: float = T0) -> str:
    return session_root(file, time.localtime(when), True)


class Rig:
    """A recorder, its clock, what it posted, and readers for its files."""

    def __init__(
        self,
        tmp: Path,
        cfg: LoggerConfig,
        *,
        mission: Path | None = None,
        subscribe: Callable[[str], None] | None = None,
        start: bool = True,
    ) -> None:
        self.tmp = tmp
        self.clock = FakeClock()
        self.posted: list[MoosMessage] = []
        self.rec = Recorder(
            cfg,
            vehicle="alpha",
            publish=self.posted.append,
            mission_path=mission,
            cwd=tmp,
            copy_dirs=[tmp / "mission"],
            clock=self.clock,
            subscribe=subscribe,
        )
        if start:
            self.rec.start()

    def send(
        self,
        name: str,
        value: float | str | bytes,
        *,
        at: float | None = None,
        stamp: float | None = None,
        source: str = "iTest",
        aux: str = "",
        community: str = "alpha",
        garbled: bool = False,
    ) -> None:
        """Deliver one message at ``T0 + at`` (now by default), stamped ``stamp`` (now)."""
        if at is not None:
            self.clock.at(at)
        when = self.clock.t if stamp is None else stamp
        self.rec.handle(MoosMessage(name, value, when, source, aux, community), garbled=garbled)

    def cmd(self, text: str, *, at: float | None = None) -> None:
        self.send("PLOGGER_CMD", text, at=at)

    def loop_back(self) -> list[MoosMessage]:
        """Feed the recorder's own posts back to it; return them."""
        seen: list[MoosMessage] = []
        for _ in range(10):
            if not self.posted:
                break
            batch = list(self.posted)
            self.posted.clear()
            for message in batch:
                self.rec.handle(message)
            seen.extend(batch)
        return seen

    def debugs(self) -> list[str]:
        """Take the MOOS_DEBUG texts posted so far (the others stay posted)."""
        texts = [str(m.value) for m in self.posted if m.name == "MOOS_DEBUG"]
        self.posted[:] = [m for m in self.posted if m.name != "MOOS_DEBUG"]
        return texts

    def take(self, name: str) -> list[MoosMessage]:
        found = [m for m in self.posted if m.name == name]
        self.posted[:] = [m for m in self.posted if m.name != name]
        return found

    @property
    def dir(self) -> Path:
        assert self.rec.session is not None
        return self.rec.session.dir_path

    @property
    def root(self) -> str:
        assert self.rec.session is not None
        return self.rec.session.root

    def file(self, ext: str) -> Path:
        return self.dir / f"{self.root}{ext}"

    def read(self, ext: str) -> str:
        self.rec.flush()
        return self.file(ext).read_bytes().decode("utf-8")

    def entries(self, ext: str = ".alog", path: Path | None = None) -> list[Entry]:
        if path is None:
            self.rec.flush()
            path = self.file(ext)
        with open(path, encoding="utf-8", newline="") as f:
            return list(iter_entries(f))

    def keys(self, ext: str = ".alog") -> list[str]:
        return [e.key for e in self.entries(ext)]


@pytest.fixture
def rigs(tmp_path: Path) -> Iterator[Callable[..., Rig]]:
    """Make rigs in tmp_path (one directory per rig); stop them all at the end."""
    made: list[Rig] = []
    (tmp_path / "mission").mkdir()

    def make(body: str, **kwargs: object) -> Rig:
        head = str(kwargs.pop("head", ""))
        app = str(kwargs.pop("app", "pLogger"))
        rig = Rig(tmp_path, config(body, head=head, app=app), **kwargs)  # type: ignore[arg-type]
        made.append(rig)
        return rig

    yield make
    for rig in made:
        rig.rec.stop()


def line(offset: str, key: str, src: str, value: str) -> str:
    """An alog line as pLogger writes it (value already formatted)."""
    return f"{offset:<15} {key:<20} {src:<15} {value} \n"


# --------------------------------------------------------------------------------------------
# Log = ... periods and flags


def test_log_period_throttles_with_default_of_two_seconds(rigs: Callable[..., Rig]) -> None:
    rig = rigs("""
        Log = NAV_X
        Log = NAV_Y @ 0.5
        Log = NAV_Z @ 0
    """)
    for at in (1.0, 1.5, 2.75, 3.0, 4.0, 5.0):
        rig.send("NAV_X", at, at=at)
    for at in (1.0, 1.25, 1.5, 1.75):
        rig.send("NAV_Y", at, at=at)
    for at in (1.0, 1.0, 1.125):
        rig.send("NAV_Z", at, at=at)
    got = [(e.key, e.offset) for e in rig.entries() if e.key.startswith("NAV_")]
    assert [o for k, o in got if k == "NAV_X"] == [1.0, 3.0, 5.0]  # no '@': 2.0 s
    assert [o for k, o in got if k == "NAV_Y"] == [1.0, 1.5]
    assert [o for k, o in got if k == "NAV_Z"] == [1.0, 1.0, 1.125]
    assert rig.rec.stats.throttled == 3 + 2
    # a throttled sample is dropped, not averaged: the values are those of the logged posts
    assert [e.value for e in rig.entries() if e.key == "NAV_X"] == [1.0, 3.0, 5.0]


def test_nosync_and_monitor_flags_in_any_case(rigs: Callable[..., Rig]) -> None:
    rig = rigs("""
        SyncLog = true @ 0.5
        Log = A @ 0
        Log = B @ 0 NOSYNC
        Log = C @ 0 MONITOR
        Log = D @ 0 nosync monitor
    """)
    assert rig.rec.synclog is not None
    assert rig.rec.synclog.columns == ("A", "C")
    assert rig.rec.monitored == ["C", "D"]
    slog = parse_slog(rig.read(".slog"))
    assert [c.name for c in slog.columns] == ["A", "C"]


def test_monitor_every_ten_seconds_with_plogger_text(rigs: Callable[..., Rig]) -> None:
    rig = rigs("""
        Log = C @ 0 MONITOR
        Log = D @ 0 NOSYNC MONITOR
        Log = E @ 0
    """)
    rig.take("LOGGER_DIRECTORY")
    rig.send("C", 1.0, at=5.0)
    rig.send("D", 1.0, at=5.0)
    rig.clock.at(9.9)
    rig.rec.tick()
    assert rig.debugs() == []
    rig.send("C", 2.0, at=9.95)
    rig.clock.at(10.0)
    rig.rec.tick()
    assert rig.debugs() == []  # both seen within 10 s
    rig.send("C", 3.0, at=16.0)
    rig.clock.at(20.0)
    rig.rec.tick()
    assert rig.debugs() == [
        "1 monitored variable is not being logged\n",
        'Monitored Variable "D" is not appearing',
    ]
    rig.clock.at(30.0)
    rig.rec.tick()
    posts = list(rig.posted)
    assert rig.debugs() == [
        "2 monitored variables are not being logged\n",
        'Monitored Variable "C" is not appearing',
        'Monitored Variable "D" is not appearing',
    ]
    assert all(m.source == "pLogger" and m.community == "alpha" for m in posts)
    # the trailing newline of pLogger's text shows in the alog as a line holding one space
    rig.posted.extend(posts)
    rig.loop_back()
    text = rig.read(".alog")
    assert (
        "MOOS_DEBUG           pLogger         2 monitored variables are not being logged\n \n"
        in (text)
    )
    ylog = parse_ylog(rig.read(".ylog"))
    assert [y.text for y in ylog.entries][:1] == ["2 monitored variables are not being logged"]


def test_a_flood_of_new_names_is_bounded_and_changes_no_throttle_nor_monitor(
    rigs: Callable[..., Rig],
) -> None:
    # A peer spraying new names makes the per-name caches start again, many times: memory
    # stays bounded, and the state of throttled and monitored variables survives it.
    rig = rigs("""
        WildcardLogging = true
        Log = SLOW @ 1.0
        Log = WATCHED @ 0 MONITOR
    """)
    rig.take("LOGGER_DIRECTORY")
    rig.send("SLOW", 1.0, at=1.0)
    rig.send("WATCHED", 1.0, at=1.0)
    flood = 3 * NAMES_CACHED + 17
    for i in range(flood):
        rig.send(f"JUNK_{i}", float(i), at=1.0 + 0.5 * i / flood)
        assert len(rig.rec._vars) <= NAMES_CACHED + 3
    rig.send("SLOW", 2.0, at=1.75)  # inside SLOW's second: throttled, as without the flood
    rig.send("SLOW", 3.0, at=2.0)
    rig.clock.at(10.5)
    rig.rec.tick()
    assert rig.debugs() == []  # WATCHED was seen 9.5 s ago: not missing
    assert [e.value for e in rig.entries() if e.key == "SLOW"] == [1.0, 3.0]
    assert sum(1 for e in rig.entries() if e.key.startswith("JUNK_")) == flood
    assert rig.rec.stats.throttled == 1
    assert len(rig.rec._classifier._cache) <= NAMES_CACHED


def test_logger_directory_at_start_and_every_ten_seconds(rigs: Callable[..., Rig]) -> None:
    rig = rigs("Log = A @ 0")
    first = rig.take("LOGGER_DIRECTORY")
    assert [m.value for m in first] == [f"./{root_at('MOOSLog')}"]
    assert first[0].time == T0
    assert first[0].source == "pLogger"
    for at in (2.0, 4.0, 6.0, 8.0, 9.75):
        rig.clock.at(at)
        rig.rec.tick()
    assert rig.take("LOGGER_DIRECTORY") == []
    rig.clock.at(10.0)
    rig.rec.tick()
    assert [m.value for m in rig.take("LOGGER_DIRECTORY")] == [f"./{root_at('MOOSLog')}"]
    rig.clock.at(20.0)
    rig.rec.tick()
    assert len(rig.take("LOGGER_DIRECTORY")) == 1


def test_status_counters(rigs: Callable[..., Rig]) -> None:
    rig = rigs("""
        Log = A @ 1
        LogAuxSrc = true
        WildcardLogging = true
        WildcardOmitPattern = *_STATUS
        WildcardExclusionLog = true
    """)
    rig.send("A", 1.0, at=0.5)
    rig.send("A", 2.0, at=0.75)  # throttled
    rig.send("B", "x", at=1.0)
    rig.send("FOO_STATUS", "y", at=1.0)  # excluded
    rig.send("C", 1.0, at=1.0, stamp=T0 - 100)  # skewed
    rig.send("D", b"\xff", at=1.0, garbled=True)
    rig.clock.at(2.0)
    rig.rec.tick()
    first, status = rig.take("PLOGGER_STATUS")  # one at session start, one 2 s later
    assert "Received=0," in str(first.value)
    fields = status_fields(str(status.value))
    assert fields["AppErrorFlag"] == "false"
    assert fields["MOOSName"] == "pLogger"
    assert fields["Community"] == rig.rec.vehicle
    assert fields["LogAuxSrc"] == "true"
    assert fields["Received"] == "6"
    assert fields["Logged"] == "4"
    assert fields["Excluded"] == "1"
    assert fields["Throttled"] == "1"
    assert fields["Skewed"] == "1"
    assert fields["Garbled"] == "1"
    assert fields["Lost"] == "0"
    assert fields["Sessions"] == "1"
    assert fields["Directory"] == f"./{root_at('MOOSLog')}"
    assert float(fields["Uptime"]) == 2.0
    rig.clock.at(3.0)
    rig.rec.tick()
    assert rig.take("PLOGGER_STATUS") == []  # every 2 s


# --------------------------------------------------------------------------------------------
# The wildcard truth table (§6.4)

NAMES = ["NAV_X", "NAV_SPEED", "NAV_XY", "WILD_ONE", "FOO_STATUS", "MISSION_FILE", "MOOS_DEBUG"]


@pytest.mark.parametrize(
    ("block", "alog", "xlog"),
    [
        pytest.param(
            "Log = NAV_X @ 0",
            {"NAV_X", "MOOS_DEBUG"},
            None,
            id="wildcard-off",
        ),
        pytest.param(
            "Log = NAV_X @ 0\nWildcardLogging = true\nWildcardOmitPattern = *_STATUS",
            {"NAV_X", "NAV_SPEED", "NAV_XY", "WILD_ONE", "MOOS_DEBUG"},
            None,
            id="no-patterns",
        ),
        pytest.param(
            "Log = NAV_X @ 0\nWildcardLogging = true\nWildcardOmitPattern = *_STATUS\n"
            "WildcardExclusionLog = true",
            {"NAV_X", "NAV_SPEED", "NAV_XY", "WILD_ONE", "MOOS_DEBUG"},
            {"FOO_STATUS", "MISSION_FILE"},
            id="no-patterns-xlog",
        ),
        pytest.param(
            "Log = NAV_X @ 0\nWildcardLogging = true\nWildcardPattern = NAV_*\n"
            "WildcardOmitPattern = *_SPEED",
            {"NAV_X", "NAV_XY", "MOOS_DEBUG"},
            None,
            id="patterns",
        ),
        pytest.param(
            "Log = NAV_X @ 0\nWildcardLogging = true\nWildcardPattern = NAV_*\n"
            "WildcardOmitPattern = *_SPEED\nWildcardExclusionLog = true",
            {"NAV_X", "NAV_XY", "MOOS_DEBUG"},
            {"NAV_SPEED", "WILD_ONE", "FOO_STATUS", "MISSION_FILE"},
            id="patterns-xlog",
        ),
        pytest.param(
            "Log = FOO_STATUS @ 0\nWildCardLogging = true\nWildCardPattern = NAV_?, WILD*\n"
            "WildCardOmitPattern = *_STATUS, MOOS_*\nWildCardExclusionLog = true",
            {"FOO_STATUS", "NAV_X", "WILD_ONE", "MOOS_DEBUG"},
            {"NAV_SPEED", "NAV_XY", "MISSION_FILE"},
            id="explicit-beats-omit",
        ),
    ],
)
def test_wildcard_truth_table(
    rigs: Callable[..., Rig], block: str, alog: set[str], xlog: set[str] | None
) -> None:
    rig = rigs(block)
    rig.take("LOGGER_DIRECTORY")
    for name in NAMES:
        rig.send(name, "v", at=1.0)
    assert set(rig.keys()) == alog
    if xlog is None:
        assert not rig.file(".xlog").exists()
        assert rig.rec.stats.excluded == 0
    else:
        text = rig.read(".xlog")
        assert not text.startswith("%")  # the uncompressed xlog has no banner (§4.2)
        assert set(rig.keys(".xlog")) == xlog
        assert rig.rec.stats.excluded == len(xlog)
    ignored = set(NAMES) - alog - (xlog or set())
    assert rig.rec.stats.ignored == len(ignored)
    assert rig.rec.stats.logged == len(alog)


# --------------------------------------------------------------------------------------------
# Time stamps


def test_skewed_samples_are_logged_at_receive_time_and_counted(rigs: Callable[..., Rig]) -> None:
    rig = rigs("Log = A @ 0\nLog = B @ 0\nLog = C @ 0\nLog = D @ 0\nLog = E @ 0\nLog = F @ 0")
    rig.send("A", 1.0, at=3.0, stamp=T0 + 0.5)  # 2.5 s old, after LOGSTART: its own time
    rig.send("B", 2.0, at=3.0, stamp=T0 - 1.0)  # before LOGSTART
    rig.send("C", 3.0, at=3.0, stamp=T0 + 9.5)  # 6.5 s in the future
    # 6 s old, after LOGSTART: a backlog never changes a time (issue 11; pLogger §2.2)
    rig.send("D", 4.0, at=10.0, stamp=T0 + 4.0)
    rig.send("E", 5.0, at=10.0, stamp=T0 + 15.0)  # exactly 5 s ahead: still its own
    rig.send("F", 6.0, at=10.0, stamp=math.nan)
    rig.send("MOOS_DEBUG", "late", at=10.0, stamp=T0 - 50.0)
    got = {e.key: e.offset for e in rig.entries()}
    assert got == {
        "A": 0.5,
        "B": 3.0,
        "C": 3.0,
        "D": 4.0,
        "E": 15.0,
        "F": 10.0,
        "MOOS_DEBUG": 10.0,
    }
    assert rig.rec.stats.skewed == 4
    assert rig.read(".ylog").endswith(format_ylog_line(10.0, "MOOS_DEBUG", "iTest", "late"))
    # no negative time anywhere: every entry line starts with a digit (§12)
    body = rig.read(".alog").split("\n")[5:-1]
    assert body
    assert all(text[0].isdigit() for text in body)


# --------------------------------------------------------------------------------------------
# ylog and blog


def test_ylog_for_moos_debug_and_moos_system(rigs: Callable[..., Rig]) -> None:
    rig = rigs("Log = A @ 0\nLogAuxSrc = true")
    rig.send("MOOS_DEBUG", "hello\ndebug", at=1.5, aux="BHV")
    rig.send("MOOS_SYSTEM", 3.25, at=2.0)
    rig.send("A", "not a system message", at=2.0)
    rig.send("MOOS_DEBUG", "x" * 30 + "\r\n", at=2.5)
    rig.send("MOOS_DEBUG", b"\x00binary", at=2.5)  # alog (binary), not ylog
    ylog = rig.read(".ylog")
    body = ylog.split("\n", 5)[5]
    assert body == (
        f"{'1.5':<10} {'MOOS_DEBUG':<20} {'iTest':<20} {'hellodebug':<20} \n"
        f"{'2':<10} {'MOOS_SYSTEM':<20} {'iTest':<20} {'3.25':<20} \n"
        f"{'2.5':<10} {'MOOS_DEBUG':<20} {'iTest':<20} {'x' * 30}\r \n"
    )
    assert ylog.startswith(rig.rec.session.banner(".ylog", T0))  # type: ignore[union-attr]
    alog = rig.read(".alog")
    # the alog keeps the newline raw and the aux source
    assert line("1.50000", "MOOS_DEBUG", "iTest:BHV", "hello\ndebug") in alog
    assert line("2.00000", "MOOS_SYSTEM", "iTest", "3.25000     ") in alog


def test_binary_values_go_to_the_blog(rigs: Callable[..., Rig]) -> None:
    rig = rigs("""
        Log = BIN @ 0 NOSYNC
        WildcardLogging = true
        WildcardOmitPattern = X*
        WildcardExclusionLog = true
    """)
    payloads = [bytes(range(16)), b"\xff" * 16, b"line\nbreak\n\x00"]
    for i, data in enumerate(payloads):
        rig.send("BIN", data, at=3.75 + i)
    rig.send("XBIN", b"excluded", at=7.0)  # xlog lines point into the same blog
    alog = rig.read(".alog")
    blog_name = f"{rig.root}.blog"
    assert (
        f"{'3.75000':<15} {'BIN':<20} {'iTest':<15} "
        f"<MOOS_BINARY>File={blog_name},Offset=53,Bytes=16</MOOS_BINARY>\n"
    ) in alog
    refs = [e.value for e in rig.entries()]
    assert refs == [
        BinaryRef(blog_name, 53, 16),
        BinaryRef(blog_name, 123, 16),  # runA's offsets: 53, 123, 193
        BinaryRef(blog_name, 193, 12),
    ]
    (xref,) = [e.value for e in rig.entries(".xlog")]
    assert isinstance(xref, BinaryRef)
    blog = rig.file(".blog").read_bytes()
    assert [payload_at(blog, r) for r in refs] == payloads  # type: ignore[arg-type]
    assert payload_at(blog, xref) == b"excluded"
    # each record is the alog prefix, the payload and a newline
    assert blog.startswith(f"{'3.75000':<15} {'BIN':<20} {'iTest':<15} ".encode() + payloads[0])
    assert len(blog) == 4 * 53 + sum(map(len, payloads)) + len(b"excluded") + 4


# --------------------------------------------------------------------------------------------
# slog


def test_slog_rows_label_blocks_and_dynamic_columns(rigs: Callable[..., Rig]) -> None:
    subscribed: list[str] = []
    rig = rigs(
        """
        SyncLog = true @ 0.5
        DynamicSyncLogColumns = 2
        Log = NAV_X @ 0
        Log = NAV_Y @ 0
        Log = DEPLOY @ 0 NOSYNC
        """,
        subscribe=subscribed.append,
    )
    path = rig.file(".slog")
    rig.rec.flush()
    header_size = path.stat().st_size
    rig.clock.at(0.125)
    rig.rec.tick()  # row 1 at once, then a label block
    rig.send("NAV_X", 1.5, at=0.25)
    rig.send("NAV_X", 2.25, at=0.375)  # the newest value since the last row is shown
    rig.send("NAV_Y", "a string", at=0.375)
    rig.send("DEPLOY", 7.0, at=0.375)  # NOSYNC: no column
    for at in (0.5, 0.625):  # 0.5 after the last row is not "more than" the period
        rig.clock.at(at)
        rig.rec.tick()
    rig.clock.at(0.75)
    rig.rec.tick()
    row2 = format_row(0.75, [2.25, None, None, None])
    assert rig.read(".slog").endswith(row2)

    rig.cmd("LOG_REQUEST = NAV_SPEED @ 0", at=1.0)
    rig.cmd("LOG_REQUEST = NAV_HEADING @ 0 NOSYNC", at=1.0)  # takes no column (§12)
    rig.cmd("LOG_REQUEST = SPEED2 @ 0", at=1.0)
    rig.cmd("LOG_REQUEST = SPEED3 @ 0", at=1.0)  # no column left: alog only
    assert subscribed == ["NAV_SPEED", "NAV_HEADING", "SPEED2", "SPEED3"]
    assert rig.debugs() == ["no free slog column for SPEED3: logged to the alog only"]
    rig.send("NAV_SPEED", 1.25, at=1.125)
    rig.send("NAV_HEADING", 90.0, at=1.125)
    rig.send("SPEED3", 3.0, at=1.125)
    rig.clock.at(1.375)
    rig.rec.tick()
    for i in range(31):
        rig.clock.at(2.0 + i)
        rig.rec.tick()

    text = rig.read(".slog")
    slog = parse_slog(text)
    # the header kept its length: the claims overwrote DYNAMIC_0 and DYNAMIC_1 in place
    assert [c.name for c in slog.columns] == ["NAV_X", "NAV_Y", "NAV_SPEED", "SPEED2"]
    assert [c.claimed for c in slog.columns] == [False, False, True, True]
    header = text.encode()[:header_size].decode()
    assert f"%%   (4) {'NAV_SPEED':<{SLOT_WIDTH}}\n%%   (5) {'SPEED2':<{SLOT_WIDTH}}\n" in header
    assert len(rig.file(".slog").read_bytes()) == len(text.encode())
    rows = slog.rows
    assert len(rows) == 3 + 31
    assert rows[0].values == (None, None, None, None)
    assert rows[1].values == (2.25, None, None, None)
    assert rows[2].offset == 1.375
    assert rows[2].values == (None, None, 1.25, None)
    # label blocks: at the start, after row 1, after each accepted LOG_REQUEST (4), and
    # after row 31
    labels = slog.labels
    assert [lab.offset for lab in labels] == [0.0, 0.12, 1.0, 1.0, 1.0, 1.0, 29.0]
    assert labels[0].names == ("NAV_X", "NAV_Y", "DYNAMIC_0", "DYNAMIC_1")
    assert labels[2].names == ("NAV_X", "NAV_Y", "NAV_SPEED", "DYNAMIC_1")
    assert labels[3].names == labels[2].names  # the NOSYNC request kept DYNAMIC_1 free
    assert labels[4].names == ("NAV_X", "NAV_Y", "NAV_SPEED", "SPEED2")
    assert text.endswith(format_row(32.0, [None] * 4))
    assert format_label_block(labels[-1].names, 29.0) in text
    # every row ends with a trailing space
    assert all(r.endswith(" ") for r in text.split("\n") if r and r[0].isdigit())


# --------------------------------------------------------------------------------------------
# LOGGER_RESTART


RESTART_BLOCK = """
    File = TEST
    SyncLog = true @ 0.5
    DynamicSyncLogColumns = 2
    Log = NAV_X @ 0
    Log = BIN @ 0 NOSYNC
    WildcardLogging = true
    WildcardOmitPattern = *_STATUS
    WildcardExclusionLog = true
"""


def test_logger_restart_opens_a_complete_new_session(
    rigs: Callable[..., Rig], tmp_path: Path
) -> None:
    moos = tmp_path / "mission" / "test.moos"
    moos.write_text(mission_text(RESTART_BLOCK))
    rig = rigs(RESTART_BLOCK, mission=moos)
    old_dir, old_root = rig.dir, rig.root
    assert old_root == root_at("TEST")
    rig.send("NAV_X", 1.5, at=0.125)
    rig.send("BIN", b"0123456789abcdef", at=0.125)
    rig.send("FOO_STATUS", "excluded", at=0.125)
    rig.cmd("LOG_REQUEST = NAV_SPEED @ 0", at=0.125)
    rig.loop_back()
    skewed = rig.rec.stats.skewed

    rig.send("LOGGER_RESTART", "true", at=0.5)  # the same second as the first session
    assert [str(m.value) for m in rig.posted if m.name != "PLOGGER_STATUS"] == [
        f"Closing : {old_root}",
        f"./{old_root}-2",
        f"Now Logging to : {old_root}-2",
    ]
    rig.loop_back()
    assert rig.rec.stats.skewed == skewed  # the recorder's own notices are not skewed
    assert rig.rec.stats.sessions == 2
    new_root = rig.root
    assert new_root == f"{old_root}-2"
    assert rig.dir == tmp_path / new_root != old_dir

    # the restart request is logged in the session it closes, as its last line
    old = rig.entries(path=old_dir / f"{old_root}.alog")
    assert (old[-1].key, old[-1].value) == ("LOGGER_RESTART", "true")
    assert "Closing" not in (old_dir / f"{old_root}.alog").read_text()
    excluded = [e.key for e in rig.entries(path=old_dir / f"{old_root}.xlog")]
    # the recorder's own status (posted at session start) is omitted by *_STATUS too
    assert [k for k in excluded if k != "PLOGGER_STATUS"] == ["FOO_STATUS"]

    # every file reopened: the xlog and blog too (pLogger lost them), plus the mission copy
    rig.send("BIN", b"fedcba9876543210", at=0.75)
    rig.send("FOO_STATUS", "again", at=0.75)
    rig.send("NAV_SPEED", 2.0, at=0.75)
    rig.clock.at(1.0)
    rig.rec.tick()
    names = sorted(p.name for p in rig.dir.iterdir())
    assert names == sorted(
        [f"{new_root}{ext}" for ext in (".alog", ".xlog", ".ylog", ".slog", ".blog", "._moos")]
        + [META]
    )
    new = rig.entries()
    assert [(e.key, e.offset) for e in new[:3]] == [
        ("MOOS_DEBUG", 0.0),
        ("LOGGER_DIRECTORY", 0.0),
        ("MOOS_DEBUG", 0.0),
    ]
    ref = next(e.value for e in new if e.key == "BIN")
    assert ref == BinaryRef(f"{new_root}.blog", 53, 16)
    assert isinstance(ref, BinaryRef)
    assert payload_at(rig.file(".blog").read_bytes(), ref) == b"fedcba9876543210"
    assert next(e.offset for e in new if e.key == "BIN") == 0.25  # relative to the new LOGSTART
    assert [e.key for e in rig.entries(".xlog") if e.key != "PLOGGER_STATUS"] == ["FOO_STATUS"]

    # a fresh LOGSTART, right-aligned in every banner
    banner = format_banner(
        f"./{new_root}/{new_root}.alog", T0 + 0.5, ctime_text(time.localtime(T0 + 0.5))
    )
    assert rig.read(".alog").startswith(banner)
    assert rig.read(".ylog").startswith(banner.replace(".alog", ".ylog"))
    assert (
        rig.read("._moos") == banner.replace(".alog", "._moos") + mission_text(RESTART_BLOCK) + "\n"
    )
    # the slog keeps its columns: the claimed one is now a plain column
    slog = parse_slog(rig.read(".slog"))
    assert [(c.name, c.slot) for c in slog.columns] == [
        ("NAV_X", False),
        ("NAV_SPEED", False),
        ("DYNAMIC_1", True),
    ]
    # values and freshness carry over, as in pLogger: NAV_X was not shown before the restart
    assert slog.rows[-1].values == (1.5, 2.0, None)
    assert (tmp_path / ".LastOpenedMOOSLogDirectory").read_text() == (
        f"LastOpenedLoggingDirectory=./{new_root}\n"
    )
    # the old session's files were closed complete
    assert parse_slog((old_dir / f"{old_root}.slog").read_text()).truncated == ""


def test_restart_with_file_timestamp_false_reuses_the_directory(
    rigs: Callable[..., Rig], tmp_path: Path
) -> None:
    (tmp_path / "logs").mkdir()
    (tmp_path / "mission" / "alpha.bhv").write_text("behaviour\n")
    rig = rigs("File = LOG\nFileTimeStamp = false\nPath = logs/\nLog = A @ 0")
    assert rig.dir == tmp_path / "logs" / "LOG"
    rig.send("A", 1.0, at=1.0)
    rig.cmd("COPY_FILE_REQUEST = mission/alpha.bhv", at=1.0)
    rig.send("LOGGER_RESTART", 1.0, at=2.0)  # any type, any value
    rig.send("A", 2.0, at=3.0)
    rig.loop_back()
    assert rig.dir == tmp_path / "logs" / "LOG"
    assert [(e.key, e.value) for e in rig.entries() if e.key == "A"] == [("A", 2.0)]  # truncated
    assert (rig.dir / "alpha._bhv").read_text() == "behaviour\n"  # copies survive
    assert rig.read(".alog").startswith(
        format_banner("logs/LOG/LOG.alog", T0 + 2.0, ctime_text(time.localtime(T0 + 2.0)))
    )
    assert (tmp_path / ".LastOpenedMOOSLogDirectory").read_text() == (
        "LastOpenedLoggingDirectory=logs/LOG\n"
    )
    # a second run reuses (and truncates) it too
    first = rig.dir
    rig.rec.stop()
    again = rigs("File = LOG\nFileTimeStamp = false\nPath = logs\nLog = A @ 0")
    assert again.dir == first
    assert again.entries() == []


# --------------------------------------------------------------------------------------------
# PLOGGER_CMD


def test_plogger_cmd_rejections_are_posted(rigs: Callable[..., Rig]) -> None:
    rig = rigs("Log = A @ 0")
    rig.debugs()
    rig.send("PLOGGER_CMD", 3.0, at=1.0)
    rig.send("PLOGGER_CMD", b"\x01", at=1.0)
    rig.cmd("garbage without equals", at=1.0)
    rig.cmd("FROBNICATE = 1", at=1.0)
    rig.cmd("LOG_REQUEST = @ 1", at=1.0)
    assert rig.debugs() == [
        "PLOGGER_CMD must be a string, got a double: ignored",
        "PLOGGER_CMD must be a string, got a binary value: ignored",
        "PLOGGER_CMD 'garbage without equals' is not TASK=VALUE: ignored",
        "Dynamic command FROBNICATE is not supported",
        "failed to process dynamic log request '@1': log entry '@1' names no variable before '@'",
    ]
    rig.cmd("log_request = B @ 0", at=1.0)  # the task name in any case
    assert rig.debugs() == []
    rig.send("B", 4.0, at=1.5)
    assert [e.key for e in rig.entries()] == ["B"]


def test_command_variable_follows_the_app_name(rigs: Callable[..., Rig]) -> None:
    rig = rigs("Log = A @ 0", app="pLogger_B")
    rig.send("PLOGGER_CMD", "LOG_REQUEST = X @ 0", at=1.0)  # not this logger's
    rig.send("PLOGGER_B_CMD", "LOG_REQUEST = Y @ 0", at=1.0)
    rig.send("X", 1.0, at=2.0)
    rig.send("Y", 2.0, at=2.0)
    assert [e.key for e in rig.entries()] == ["Y"]
    assert rig.take("PLOGGER_STATUS") == []
    (status,) = rig.take("PLOGGER_B_STATUS")  # the one posted when the session opened
    assert "MOOSName=pLogger_B," in str(status.value)


def test_log_request_duplicate_posts_plogger_text(rigs: Callable[..., Rig]) -> None:
    rig = rigs("Log = NAV_X @ 0")
    rig.debugs()
    rig.cmd("LOG_REQUEST = NAV_X @ 0", at=1.0)  # in the mission already
    rig.cmd("LOG_REQUEST = MOOS_DEBUG", at=1.0)  # always logged
    rig.cmd("LOG_REQUEST = NAV_SPEED @ 1", at=1.0)
    rig.cmd("LOG_REQUEST = NAV_SPEED @ 0", at=1.0)  # requested already
    posts = list(rig.posted)
    assert rig.debugs() == [DUP, DUP, DUP]
    rig.posted.extend(posts)
    rig.loop_back()
    alog = rig.read(".alog")
    assert alog.count(line("1.00000", "MOOS_DEBUG", "pLogger", DUP)) == 3
    # the request's period holds
    for at in (2.0, 2.5, 3.0):
        rig.send("NAV_SPEED", at, at=at)
    assert [e.offset for e in rig.entries() if e.key == "NAV_SPEED"] == [2.0, 3.0]


def test_copy_file_request(rigs: Callable[..., Rig], tmp_path: Path) -> None:
    mission = tmp_path / "mission"
    (mission / "alpha.bhv").write_bytes(b"Behavior = BHV_Waypoint\r\n{ }\n")
    (mission / "sub").mkdir()
    (mission / "sub" / "b.c.d").write_bytes(b"\x00\x01\x02")
    (mission / "README").write_text("no extension\n")
    (tmp_path / "secret.txt").write_text("outside\n")
    (mission / "link").symlink_to("/etc/hostname")
    rig = rigs("Log = A @ 0")
    rig.debugs()

    rig.cmd("COPY_FILE_REQUEST = mission/alpha.bhv", at=1.0)  # relative to the cwd
    rig.cmd(f"COPY_FILE_REQUEST = {mission}/sub/b.c.d", at=1.0)
    rig.cmd("COPY_FILE_REQUEST = mission / READ ME", at=1.0)  # spaces are stripped
    assert rig.debugs() == []
    assert (rig.dir / "alpha._bhv").read_bytes() == b"Behavior = BHV_Waypoint\r\n{ }\n"
    assert (rig.dir / "b.c._d").read_bytes() == b"\x00\x01\x02"
    assert (rig.dir / "README._bak").read_text() == "no extension\n"

    refused = ["/etc/hostname", "mission/../secret.txt", "mission/link", "/etc/no-such-file"]
    for path in refused:
        rig.cmd(f"COPY_FILE_REQUEST = {path}", at=2.0)
    assert rig.debugs() == [
        f"refused COPY_FILE_REQUEST for {path}: outside the directories the recorder may copy from"
        for path in refused
    ]
    assert rig.rec.stats.refused_copies == len(refused)

    for path in ("mission/nothere.bhv", "mission/alpha.bhv/", "mission/sub"):
        rig.cmd(f"COPY_FILE_REQUEST = {path}", at=3.0)
    assert rig.debugs() == ["failed to open file for reading"] * 3
    assert sorted(p.name for p in rig.dir.iterdir() if "._" in p.name) == [
        "README._bak",
        "alpha._bhv",
        "b.c._d",
    ]


def test_lines_reach_the_os_before_a_copy_starts(rigs: Callable[..., Rig], tmp_path: Path) -> None:
    (tmp_path / "mission" / "big.bin").write_bytes(b"x" * 1000)
    rig = rigs("Log = A @ 0")
    rig.send("A", 1.0, at=0.5)
    alog = rig.file(".alog")
    assert b" A " not in alog.read_bytes()  # written, not flushed yet
    rig.cmd("COPY_FILE_REQUEST = mission/big.bin", at=0.5)
    assert b" A " in alog.read_bytes()  # a long copy does not hold it back
    assert (rig.dir / "big._bin").stat().st_size == 1000


# --------------------------------------------------------------------------------------------
# What goes into a line


def test_mark_data_type_log_aux_src_community_marking_precision(
    rigs: Callable[..., Rig],
) -> None:
    rig = rigs("""
        Log = NAV_X @ 0
        Log = DEPLOY @ 0
        Log = BIN @ 0
        Log = CONTACT @ 0
        MarkDataType = true
        LogAuxSrc = true
        MarkExternalCommunityMessages = true
        DoublePrecision = 3
    """)
    rig.send("NAV_X", 1.5, at=1.0)
    rig.send("DEPLOY", "true", at=1.0, source="pHelmIvP", aux="HELM_VAR_INIT")
    rig.send("DEPLOY", "", at=1.0)
    rig.send("BIN", b"ab", at=1.0)
    rig.send("CONTACT", -20.0, at=1.0, source="pMarineViewer", community="shoreside")
    rig.send("CONTACT", "x", at=1.0, source="pShare", aux="A", community="bravo")
    alog = rig.read(".alog")
    assert "%% DATATYPE MARKING ON\n" in alog.split("\n%%%%")[0] + "\n"
    body = alog.split("%" * 59 + "\n")[2]
    assert body == (
        line("1.00000", "NAV_X", "iTest", "D:1.500       ")
        + line("1.00000", "DEPLOY", "pHelmIvP:HELM_VAR_INIT", "S:true")
        + line("1.00000", "DEPLOY", "iTest", "S:")
        + f"{'1.00000':<15} {'BIN':<20} {'iTest':<15} "
        f"<MOOS_BINARY>File={rig.root}.blog,Offset=53,Bytes=2</MOOS_BINARY>\n"
        + line("1.00000", "CONTACT", "pMarineViewer@shoreside", "D:-20.000     ")
        + line("1.00000", "CONTACT", "pShare:A@bravo", "S:x")
    )
    got = [(e.key, e.value) for e in rig.entries()]
    assert got[:3] == [("NAV_X", 1.5), ("DEPLOY", "true"), ("DEPLOY", "")]
    assert "%% DATATYPE MARKING ON\n" in rig.read(".ylog")


def test_defaults_drop_aux_and_community(rigs: Callable[..., Rig]) -> None:
    rig = rigs("Log = A @ 0")
    rig.send("A", -0.0, at=1.0, source="pHelmIvP", aux="BHV", community="shoreside")
    rig.send("A", 123456789.123456, at=1.0)
    rig.send("A", 1e-7, at=1.0)
    rig.send("A", "", at=1.0)
    body = rig.read(".alog").split("%" * 59 + "\n")[2]
    assert body == (
        line("1.00000", "A", "pHelmIvP", "-0.00000    ")
        + line("1.00000", "A", "iTest", "123456789.12346")
        + line("1.00000", "A", "iTest", "0.00000     ")
        + line("1.00000", "A", "iTest", "")
    )


def test_essential_moos_variant(rigs: Callable[..., Rig]) -> None:
    rig = rigs("Log = A @ 0\nLogFormat = em")
    rig.send("A", 2.0, at=3.746875)
    alog = rig.read(".alog")
    banner = format_banner(
        f"./{rig.root}/{rig.root}.alog",
        T0,
        ctime_text(time.localtime(T0)),
        variant=Variant.EM,
    )
    assert "%% LOGSTART               1800000000.25\n" in banner
    assert alog == banner + line("3.747", "A", "iTest", "2.00000     ")


# --------------------------------------------------------------------------------------------
# Compression


def read_zstd(path: Path) -> bytes:
    with open(path, "rb") as f:
        reader = zstandard.ZstdDecompressor().stream_reader(f, read_across_frames=True)
        return reader.read()


COMPRESS_BLOCK = """
    Log = A @ 0
    WildcardLogging = true
    WildcardOmitPattern = X*
    WildcardExclusionLog = {xlog}
    CompressAlogs = {mode}
"""


def feed_some(rig: Rig) -> None:
    rig.send("A", 1.5, at=0.25)
    rig.send("B", "hello, world = x\nsecond line", at=0.25)
    rig.send("XA", "excluded", at=0.25)
    rig.send("BIN", b"\x00\xff", at=0.25)
    rig.send("MOOS_DEBUG", "dbg", at=0.25)


def test_compress_zstd_flushes_a_frame_within_a_second(
    rigs: Callable[..., Rig], tmp_path: Path
) -> None:
    rig = rigs(COMPRESS_BLOCK.format(mode="zstd", xlog="true"))
    root = rig.root
    assert sorted(p.name for p in rig.dir.iterdir()) == sorted(
        [f"{root}{ext}" for ext in (".alog.zst", ".xlog.zst", ".ylog", ".blog")] + [META]
    )
    feed_some(rig)
    rig.clock.at(0.125)
    rig.rec.tick()
    before = read_zstd(rig.file(".alog.zst")).decode()
    assert "hello, world" not in before  # less than a quarter second since the banner's frame
    assert before.startswith("%" * 59 + f"\n%% LOG FILE:       ./{root}/{root}.alog\n")
    rig.clock.at(1.25)  # no more samples: the tick alone closes the frame
    rig.rec.tick()
    during = read_zstd(rig.file(".alog.zst")).decode()
    assert "hello, world = x\nsecond line \n" in during
    assert "excluded" in read_zstd(rig.file(".xlog.zst")).decode()
    rig.rec.stop()

    # the same traffic uncompressed: the .alog.zst holds exactly the .alog's bytes
    plain_dir = tmp_path / "plain"
    plain_dir.mkdir()
    (plain_dir / "mission").mkdir()
    plain = Rig(plain_dir, config(COMPRESS_BLOCK.format(mode="false", xlog="true")))
    feed_some(plain)
    plain.clock.at(1.25)
    plain.rec.tick()
    plain.rec.stop()
    done = read_zstd(tmp_path / root / f"{root}.alog.zst")
    assert done == (plain_dir / root / f"{root}.alog").read_bytes()
    xlog = read_zstd(tmp_path / root / f"{root}.xlog.zst").decode()
    # compressed, the xlog starts with the alog's banner (§1.3)
    assert xlog.startswith(done.decode().split("\n0.")[0])
    assert xlog.endswith((plain_dir / root / f"{root}.xlog").read_text())


@pytest.mark.parametrize("mode", ["true", "gzip"])
def test_compress_gzip_is_plogger_gz(rigs: Callable[..., Rig], mode: str) -> None:
    rig = rigs(COMPRESS_BLOCK.format(mode=mode, xlog="false"))
    root = rig.root
    assert sorted(p.name for p in rig.dir.iterdir()) == sorted(
        [f"{root}{ext}" for ext in (".alog.gz", ".xlog.gz", ".ylog", ".blog")] + [META]
    )
    feed_some(rig)
    rig.clock.at(1.25)
    rig.rec.tick()
    # mid-session: a sync-flushed, unfinished gzip member decompresses up to the flush point
    partial = zlib.decompressobj(31).decompress(rig.file(".alog.gz").read_bytes()).decode()
    assert "hello, world = x\nsecond line \n" in partial
    directory = rig.dir
    rig.rec.stop()
    whole = gzip.decompress((directory / f"{root}.alog.gz").read_bytes()).decode()
    assert whole == partial
    assert [e.key for e in iter_entries(whole.splitlines(keepends=True))] == [
        "A",
        "B",
        "BIN",
        "MOOS_DEBUG",
    ]
    # without the exclusion log the .xlog.gz is an empty gzip stream, as pLogger's
    assert gzip.decompress((directory / f"{root}.xlog.gz").read_bytes()) == b""


# --------------------------------------------------------------------------------------------
# Where the session goes, and what happens when the disk says no


def test_fallback_to_cwd_when_path_does_not_exist(rigs: Callable[..., Rig], tmp_path: Path) -> None:
    rig = rigs("File = ROOT\nPath = /nonexistent/dir/\nLog = A @ 0")
    root = root_at("ROOT")
    assert rig.dir == tmp_path / root
    assert rig.rec.session is not None
    assert rig.rec.session.directory == f"./{root}"
    assert (tmp_path / ".LastOpenedMOOSLogDirectory").read_text() == (
        f"LastOpenedLoggingDirectory=./{root}\n"
    )
    assert rig.read(".alog").startswith(
        format_banner(f"./{root}/{root}.alog", T0, ctime_text(time.localtime(T0)))
    )
    assert rig.read(".ylog").split("\n")[1] == f"%% LOG FILE:       ./{root}/{root}.ylog"
    assert [m.value for m in rig.take("LOGGER_DIRECTORY")] == [f"./{root}"]
    assert rig.debugs() == [
        f"could not create /nonexistent/dir/{root}: logging to the fallback ./{root}"
    ]


def _chmod_stops_root() -> bool:
    """True when a read-only directory really refuses writes (not when running as root)."""
    return os.geteuid() != 0


@pytest.mark.parametrize("mechanism", ["read-only-dir", "path-is-a-file"])
def test_unusable_log_directory_falls_back(
    rigs: Callable[..., Rig], tmp_path: Path, mechanism: str
) -> None:
    logs = tmp_path / "logs"
    if mechanism == "read-only-dir":
        if not _chmod_stops_root():
            pytest.skip("running as root: chmod does not stop root's writes")
        logs.mkdir(mode=0o555)
    else:
        logs.write_text("a file where the log directory should be\n")
    try:
        rig = rigs("File = R\nPath = logs\nLog = A @ 0")
        root = root_at("R")
        assert rig.rec.session is not None
        assert rig.rec.session.directory == f"./{root}"
        rig.send("A", 1.0, at=1.0)
        assert [e.key for e in rig.entries()] == ["A"]
    finally:
        if logs.is_dir():
            logs.chmod(0o755)


@pytest.fixture
def file_size_limit() -> Iterator[Callable[[int], None]]:
    """Limit the size any file of this process may grow to (RLIMIT_FSIZE), then restore it.

    A real OS mechanism that makes writes fail with EFBIG, for root too (chmod does not stop
    root); SIGXFSZ is ignored meanwhile so the write fails instead of killing the process.
    """
    soft, hard = resource.getrlimit(resource.RLIMIT_FSIZE)
    previous = signal.signal(signal.SIGXFSZ, signal.SIG_IGN)

    def limit(size: int) -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (size, hard))

    try:
        yield limit
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, (soft, hard))
        signal.signal(signal.SIGXFSZ, previous)


def test_write_error_mid_session_is_counted_posted_and_survived(
    rigs: Callable[..., Rig], tmp_path: Path, file_size_limit: Callable[[int], None]
) -> None:
    rig = rigs("File = W\nLog = A @ 0")
    first = rig.dir
    rig.send("A", 0.0, at=0.5)
    rig.rec.flush()
    size = rig.file(".alog").stat().st_size
    # room for the fallback's banners and metadata, not for 200 more lines
    file_size_limit(size + 2000)
    try:
        for i in range(200):
            rig.send("A", float(i), at=1.0)
        rig.rec.flush()  # the buffered lines reach the OS only now, and fail
    finally:
        file_size_limit(resource.RLIM_INFINITY)
    stats = rig.rec.stats
    # exactly the lines that did not reach the file (the last one there may be cut)
    on_disk = rig.entries(path=first / f"{first.name}.alog")
    assert 0 < len(on_disk) - 1 < 200
    assert stats.lost == 200 - (len(on_disk) - 1)
    assert stats.write_errors == 1
    assert "File too large" in stats.last_error
    debugs = [str(m.value) for m in rig.posted if m.name == "MOOS_DEBUG"]
    assert debugs[0] == (
        f"write error, samples are being lost: cannot write {first}/{first.name}.alog: "
        "File too large"
    )
    fallback = root_at("W", T0 + 1.0)
    assert debugs[1] == f"now logging to the fallback ./{fallback}"
    # the recorder carries on in the fallback session
    assert rig.dir == tmp_path / fallback
    rig.send("A", 42.0, at=2.0)
    rig.loop_back()
    assert [e.value for e in rig.entries() if e.key == "A"] == [42.0]
    assert "write error, samples are being lost" in rig.read(".alog")
    assert stats.sessions == 2


def test_restart_into_an_unwritable_place_counts_losses_until_it_recovers(
    rigs: Callable[..., Rig], tmp_path: Path
) -> None:
    (tmp_path / "logs").mkdir()
    rig = rigs("File = LOG\nFileTimeStamp = false\nPath = logs\nLog = A @ 0")
    alog = tmp_path / "logs" / "LOG" / "LOG.alog"
    # the file paths become directories: opening them fails, for root too
    alog.unlink()
    alog.mkdir()
    (tmp_path / "LOG" / "LOG.alog").mkdir(parents=True)  # and the ./LOG fallback
    rig.debugs()
    rig.send("LOGGER_RESTART", "now", at=1.0)
    assert rig.rec.session is None
    debugs = rig.debugs()
    assert debugs[0] == "Closing : LOG"
    assert debugs[1].startswith(f"write error, samples are being lost: cannot create {alog}: ")
    assert debugs[2].startswith("fallback failed too, samples are being lost: cannot create ")
    for i in range(5):
        rig.send("A", float(i), at=2.0)
    rig.send("MOOS_DEBUG", "also lost", at=2.0)
    rig.send("NOT_LOGGED", 1.0, at=2.0)  # ignored, so not lost
    assert rig.rec.stats.lost == 6
    rig.clock.at(2.0)
    rig.rec.tick()
    *_, status = rig.take("PLOGGER_STATUS")
    assert "AppErrorFlag=true" in str(status.value)
    assert "Lost=6" in str(status.value)

    alog.rmdir()
    rig.send("LOGGER_RESTART", "again", at=3.0)  # a restart retries
    assert rig.rec.session is not None
    assert rig.debugs()[-1] == "Now Logging to : LOG"
    rig.send("A", 9.0, at=4.0)
    assert [e.value for e in rig.entries() if e.key == "A"] == [9.0]
    shutil.rmtree(tmp_path / "LOG")


def test_an_unwritable_hint_file_does_not_stop_logging(
    rigs: Callable[..., Rig], tmp_path: Path
) -> None:
    (tmp_path / "hint").mkdir()  # the summary file's path is a directory: writing it fails
    rig = rigs("LoggingDirectorySummaryFile = hint\nLog = A @ 0")
    (debug,) = rig.debugs()
    assert debug == f"cannot write the session hint file {tmp_path / 'hint'}: Is a directory"
    rig.send("A", 1.0, at=1.0)
    assert [e.key for e in rig.entries()] == ["A"]


def test_summary_file_elsewhere(rigs: Callable[..., Rig], tmp_path: Path) -> None:
    rig = rigs("LoggingDirectorySummaryFile = mission/last.txt\nLog = A @ 0")
    assert not (tmp_path / ".LastOpenedMOOSLogDirectory").exists()
    assert (tmp_path / "mission" / "last.txt").read_text() == (
        f"LastOpenedLoggingDirectory=./{rig.root}\n"
    )


@pytest.mark.parametrize("where", ["cwd", "mission"])
def test_helm_task_file_is_backed_up_as_hoof(
    rigs: Callable[..., Rig], tmp_path: Path, where: str
) -> None:
    task = (tmp_path if where == "cwd" else tmp_path / "mission") / "alpha.bhv"
    task.write_bytes(b"Behavior = BHV_Loiter\n{ }\n")
    head = "ProcessConfig = pHelmIvP\n{\n  TaskFile = alpha.bhv\n}\n"
    moos = tmp_path / "mission" / "alpha.moos"
    moos.write_text(mission_text("Log = A @ 0", head=head))
    rig = rigs("Log = A @ 0", head=head, mission=moos)
    assert rig.file("._hoof").read_bytes() == b"Behavior = BHV_Loiter\n{ }\n"  # raw, no banner
    assert rig.read("._moos").endswith(mission_text("Log = A @ 0", head=head) + "\n")


@pytest.fixture
def new_york() -> Iterator[None]:
    """Run in US Eastern time (five hours behind UTC in January)."""
    old = os.environ.get("TZ")
    os.environ["TZ"] = "America/New_York"
    time.tzset()
    try:
        yield
    finally:
        if old is None:
            del os.environ["TZ"]
        else:
            os.environ["TZ"] = old
        time.tzset()


@pytest.mark.usefixtures("new_york")
@pytest.mark.parametrize("utc", [False, True])
def test_utc_log_directories(rigs: Callable[..., Rig], utc: bool) -> None:
    rig = rigs(f"File = T\nUTCLogDirectories = {str(utc).lower()}\nLog = A @ 0")
    # T0 is 08:00:00 UTC on 15 Jan 2027, 03:00:00 in New York
    assert rig.root == ("T_15_1_2027_____08_00_00" if utc else "T_15_1_2027_____03_00_00")
    # the opening date is local time either way, in C's ctime layout
    assert rig.read(".alog").split("\n")[2] == "%% FILE OPENED ON  Fri Jan 15 03:00:00 2027"


def test_unreadable_keys_and_failed_subscriptions_are_reported(rigs: Callable[..., Rig]) -> None:
    def refuse(name: str) -> None:
        raise TransportError(f"Zenoh subscription to {name!r} failed: closed")

    rig = rigs("Log = A @ 0", subscribe=refuse)
    rig.debugs()
    rig.rec.unreadable("fleet/alpha/var/BAD%ZZ")
    rig.rec.unreadable("fleet/alpha/var/BAD%ZZ")
    stats = rig.rec.stats
    assert (stats.received, stats.garbled, stats.lost) == (2, 2, 2)
    assert rig.debugs() == ["sample on fleet/alpha/var/BAD%ZZ names no MOOS variable: not logged"]
    for i in range(2000):
        rig.rec.unreadable(f"fleet/alpha/var/BAD%ZZ{i}")
    assert len(rig.debugs()) == 1023  # reported once per key, at most 1024 keys
    assert stats.lost == 2002
    rig.cmd("LOG_REQUEST = B @ 0", at=1.0)  # accepted, but the subscription failed
    assert rig.debugs() == ["could not subscribe to B: Zenoh subscription to 'B' failed: closed"]


@pytest.mark.skipif(not Path("/dev/full").exists(), reason="needs /dev/full")
def test_a_full_disk_on_restart_falls_back_to_the_working_directory(
    rigs: Callable[..., Rig], tmp_path: Path
) -> None:
    (tmp_path / "logs").mkdir()
    rig = rigs("File = LOG\nFileTimeStamp = false\nPath = logs\nLog = A @ 0")
    alog = tmp_path / "logs" / "LOG" / "LOG.alog"
    alog.unlink()
    alog.symlink_to("/dev/full")  # the reopened alog: every write fails with ENOSPC
    rig.debugs()
    rig.send("LOGGER_RESTART", "disk full", at=1.0)
    debugs = rig.debugs()
    assert debugs[0] == "Closing : LOG"
    assert (
        debugs[1]
        == f"write error, samples are being lost: cannot write {alog}: No space left on device"
    )
    assert debugs[2:] == ["now logging to the fallback ./LOG", "Now Logging to : LOG"]
    assert rig.dir == tmp_path / "LOG"
    rig.send("A", 5.0, at=2.0)
    assert [e.value for e in rig.entries()] == [5.0]
    assert rig.rec.stats.write_errors == 1


def test_logger_restart_is_not_logged_without_a_log_entry_or_wildcard(
    rigs: Callable[..., Rig], tmp_path: Path
) -> None:
    rig = rigs("File = R\nLog = A @ 0")
    old = rig.file(".alog")
    rig.send("A", 1.0, at=0.5)
    rig.send("LOGGER_RESTART", "true", at=1.5)
    assert rig.file(".alog") != old
    assert [e.key for e in rig.entries(path=old)] == ["A"]  # the restart itself: not logged
    assert rig.rec.stats.ignored == 1


def test_async_log_false_keeps_only_the_banner(rigs: Callable[..., Rig]) -> None:
    rig = rigs("AsyncLog = false\nSyncLog = true\nLog = A @ 0")
    rig.send("A", 1.5, at=0.25)
    rig.send("MOOS_DEBUG", "still in the ylog", at=0.25)
    rig.clock.at(0.5)
    rig.rec.tick()
    assert rig.read(".alog") == rig.rec.session.banner(".alog", T0)  # type: ignore[union-attr]
    assert [y.text for y in parse_ylog(rig.read(".ylog")).entries] == ["still in the ylog"]
    assert parse_slog(rig.read(".slog")).rows[-1].values == (1.5,)


def test_global_log_path_wins_over_path(rigs: Callable[..., Rig], tmp_path: Path) -> None:
    (tmp_path / "global").mkdir()
    rig = rigs("File = G\nPath = elsewhere\nLog = A @ 0", head="GlobalLogPath = global/")
    assert rig.rec.session is not None
    assert rig.rec.session.directory == f"global/{root_at('G')}"
    assert rig.dir == tmp_path / "global" / root_at("G")


# --------------------------------------------------------------------------------------------
# PLOGGER_STATUS holds CMOOSApp's fields; type clashes are counted (issue 14)


def test_status_holds_cmoosapps_fields_in_its_order(rigs: Callable[..., Rig]) -> None:
    rig = rigs("    Log = NAV_X @ 0\n    WildcardLogging = true\n")
    rig.send("DEPTH", 3.0, at=0.5)
    rig.loop_back()
    rig.clock.at(2.5)
    rig.rec.tick()
    (status,) = rig.take("PLOGGER_STATUS")
    text = str(status.value)
    fields = re.findall(STATUS_FIELD, text)
    names = [name for name, _ in fields]
    # CMOOSApp's order (core-moos MOOSApp.cpp MakeStatusString), Community after MOOSName
    assert names[:10] == [
        "AppErrorFlag",
        "Uptime",
        "cpuload",
        "memory_kb",
        "memory_max_kb",
        "MOOSName",
        "Community",
        "Publishing",
        "Subscribing",
        "LogAuxSrc",
    ]
    values = dict(fields)
    assert float(values["cpuload"]) >= 0
    assert float(values["memory_kb"]) > 1000  # a Python process holds megabytes
    assert float(values["memory_max_kb"]) >= 1000
    assert values["Publishing"] == '"LOGGER_DIRECTORY,PLOGGER_STATUS,"'
    subscribing = values["Subscribing"].strip('"').split(",")
    assert subscribing[-1] == ""  # comma-terminated, as CMOOSApp writes it
    assert {"DEPTH", "NAV_X", "LOGGER_RESTART", "PLOGGER_CMD", "PLOGGER_STATUS"} <= set(subscribing)
    assert subscribing[:-1] == sorted(subscribing[:-1])
    assert "TypeClashes=0" in text


def test_a_type_clash_is_logged_and_counted(rigs: Callable[..., Rig]) -> None:
    rig = rigs("    WildcardLogging = true\n")
    rig.send("X", 1.0, at=0.1)
    rig.send("X", "one", at=0.2)
    rig.send("X", b"\x01", at=0.3)
    rig.send("X", 2.0, at=0.4)
    assert rig.rec.stats.type_clashes == 2
    assert [e.value for e in rig.entries() if e.key == "X"][:2] == [1.0, "one"]
    assert rig.rec.stats.as_dict()["type_clashes"] == 2
