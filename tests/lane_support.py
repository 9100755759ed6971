"""The recorder's two ways for one sample, side by side: the fast lane and the general way.

:class:`SampleTap` turns sample parts into real ``zenoh.Sample`` objects (put by one session
and received by another over loopback TCP); :func:`both_ways` logs the same samples with
two recorders (same configuration, same fake clock), one through the general way
(``SampleDecoder.decode`` + ``Recorder.handle``) and one through ``Lane.pump``, and returns
what each wrote and counted.
"""

from __future__ import annotations

import contextlib
import re
import shutil
import tempfile
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import zenoh
from helpers import free_port

from fleetlog.moos.mission import LoggerConfig, parse_mission
from fleetlog.recorder.engine import Recorder
from fleetlog.recorder.lane import Lane
from fleetlog.transport.bus import SampleDecoder, declare_fifo_subscriber
from fleetlog.transport.session import SessionOptions, open_session
from fleetlog.wire.message import MoosMessage

PREFIX = "fleet/V/var/"
T0 = 1_800_000_000.25
_END = "fleet/V/end"
_PROCESS = re.compile(r"cpuload=[^,]*,memory_kb=[^,]*,memory_max_kb=[^,]*,")

#: (key, payload, encoding, attachment)
Part = tuple[str, bytes, str, bytes | None]


class SampleTap:
    """Two Zenoh sessions on loopback: parts put into one come out of the other as samples."""

    def __init__(self) -> None:
        endpoint = f"tcp/127.0.0.1:{free_port()}"
        self._rx = open_session(SessionOptions(listen=(endpoint,), multicast_scouting=False))
        self._tx = open_session(SessionOptions(connect=(endpoint,), multicast_scouting=False))
        self._sub = declare_fifo_subscriber(self._rx, "fleet/V/**")
        self._round = 0
        deadline = time.monotonic() + 10
        while not self.samples([]) and time.monotonic() < deadline:
            pass  # the first rounds go nowhere until the subscription is known

    def samples(self, parts: Sequence[Part], timeout: float = 10.0) -> list[Any]:
        """Put ``parts`` and return the samples received (an invalid key is not put)."""
        self._round += 1
        end = f"{_END}/{self._round}"
        for key, payload, encoding, attachment in parts:
            # A key or encoding Zenoh refuses (or cannot encode) never arrives from a peer.
            with contextlib.suppress(zenoh.ZError, UnicodeEncodeError):
                self._tx.put(key, payload, encoding=zenoh.Encoding(encoding), attachment=attachment)
        self._tx.put(end, b"")
        got: list[Any] = []
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            sample = self._sub.try_recv()
            if sample is None:
                time.sleep(0.001)
                continue
            key = str(sample.key_expr)
            if key == end:
                return got
            if not key.startswith(_END):
                got.append(sample)
        return []

    def close(self) -> None:
        self._sub.undeclare()
        self._tx.close()
        self._rx.close()


@contextlib.contextmanager
def sample_tap() -> Iterator[SampleTap]:
    tap = SampleTap()
    try:
        yield tap
    finally:
        tap.close()


class _Clock:
    def __init__(self) -> None:
        self.t = T0

    def __call__(self) -> float:
        return self.t


def mission(body: str = "WildcardLogging = true") -> LoggerConfig:
    """A pLogger block for vehicle ``V`` (File = F)."""
    lines = "\n".join(f"  {line.strip()}" for line in body.strip().splitlines())
    text = f"Community = V\nProcessConfig = pLogger\n{{\n  File = F\n{lines}\n}}\n"
    return parse_mission(text, "f.moos").logger_config()


@dataclass
class Written:
    """What one recorder wrote and counted."""

    files: dict[str, bytes]
    stats: dict[str, Any]
    #: what it posted: (name, value, time)
    posted: list[tuple[str, float | str | bytes, float]]
    fast: int


def _run(config: LoggerConfig, samples: list[Any], now: float, lane: bool) -> Written:
    where = Path(tempfile.mkdtemp(prefix="fleetlog-lane-"))
    try:
        clock = _Clock()
        posted: list[MoosMessage] = []
        rec = Recorder(config, vehicle="V", publish=posted.append, cwd=where, clock=clock)
        session = rec.start()
        assert session is not None
        clock.t = now
        decoder = SampleDecoder(PREFIX, clock=clock)
        fast = 0
        if lane:
            way = Lane(rec, decoder, lambda info, sample: None)
            rest = iter(samples[1:])
            if samples:
                done = way.pump(samples[0], lambda: next(rest, None), len(samples) + 1)
                assert done == len(samples)
            fast = way.fast
        else:
            for sample in samples:
                incoming = decoder.decode(sample)
                if incoming is None:
                    rec.unreadable(str(sample.key_expr))
                else:
                    rec.handle(incoming.message, garbled=incoming.garbled)
        directory = session.dir_path
        rec.stop()
        files = {
            p.name.split(".", 1)[-1]: p.read_bytes()
            for p in sorted(directory.iterdir())
            if p.suffix in (".alog", ".xlog", ".ylog", ".blog", ".slog")
        }
        stats = rec.stats.as_dict()
        # The process's own CPU and memory in PLOGGER_STATUS differ from run to run.
        posts = [
            (m.name, _PROCESS.sub("", m.value) if isinstance(m.value, str) else m.value, m.time)
            for m in posted
        ]
        return Written(files, stats, posts, fast)
    finally:
        shutil.rmtree(where, ignore_errors=True)


def both_ways(config: LoggerConfig, samples: list[Any], now: float) -> tuple[Written, Written]:
    """Log ``samples`` the general way and through the lane: return both (general first).

    The clock reads T0 at the recorders' start (LOGSTART) and ``now`` afterwards.
    """
    return _run(config, samples, now, lane=False), _run(config, samples, now, lane=True)
