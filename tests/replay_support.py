"""Replayer test support: alog sessions written byte for byte as pLogger would."""

from __future__ import annotations

import queue
import signal
import subprocess
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from helpers import fleetlog_cmd

from fleetlog.moos.alog import LineFormatter, format_banner
from fleetlog.moos.blog import format_blog_record


@dataclass(frozen=True)
class Line:
    """One entry to write: offset from LOGSTART, variable, source field, value."""

    offset: float
    key: str
    source: str
    value: float | str | bytes


MakeSession = Callable[..., Path]


def write_session(
    directory: Path,
    lines: Sequence[Line],
    *,
    logstart: float = 1_800_000_000.0,
    vehicle: str | None = "alpha",
    root: str = "LOG_ALPHA_1_1_2027_____00_00_00",
    moos_community: str | None = None,
) -> Path:
    """Write a session directory ``directory/root/`` with an alog (and blog, and ._moos).

    ``vehicle`` adds a leading ``DB_TIME`` line from ``MOOSDB_<vehicle>`` (at offset 0) so the
    vehicle can be found; ``moos_community`` writes a ``._moos`` with that Community.
    """
    session = directory / root
    session.mkdir(parents=True)
    fmt = LineFormatter()
    banner = format_banner(f"./{root}/{root}.alog", logstart, "Thu Jan  1 00:00:00 1970")
    text = [banner]
    blog = bytearray()
    all_lines = list(lines)
    if vehicle is not None:
        all_lines.insert(0, Line(0.0, "DB_TIME", f"MOOSDB_{vehicle}", str(logstart)))
    for line in all_lines:
        if isinstance(line.value, bytes):
            prefix = fmt.prefix(line.offset, line.key, line.source)
            record = format_blog_record(prefix, line.value, len(blog), f"{root}.blog")
            blog += record.data
            text.append(fmt.binary(line.offset, line.key, line.source, record.ref))
        elif isinstance(line.value, str):
            text.append(fmt.string(line.offset, line.key, line.source, line.value))
        else:
            text.append(fmt.double(line.offset, line.key, line.source, line.value))
    (session / f"{root}.alog").write_text("".join(text), encoding="utf-8", newline="\n")
    (session / f"{root}.blog").write_bytes(bytes(blog))
    if moos_community is not None:
        moos = format_banner(f"./{root}/{root}._moos", logstart, "Thu Jan  1 00:00:00 1970")
        mission = f"ServerPort = 9000\nCommunity = {moos_community}\n\n"
        (session / f"{root}._moos").write_text(moos + mission, encoding="utf-8")
    return session


class Proc:
    """A ``fleetlog`` subprocess whose stderr is read by a thread, killed on close."""

    def __init__(self, args: Sequence[str], cwd: Path, env: dict[str, str]) -> None:
        self.proc = subprocess.Popen(
            fleetlog_cmd(*args),
            cwd=cwd,
            env=env,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
        )
        self.lines: list[str] = []
        self._queue: queue.Queue[str | None] = queue.Queue()
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.proc.stderr is not None
        for text in self.proc.stderr:
            self.lines.append(text)
            self._queue.put(text)
        self._queue.put(None)

    @property
    def stderr(self) -> str:
        return "".join(self.lines)

    def wait_for(self, needle: str, timeout: float = 15.0) -> str:
        """Return the first stderr line holding ``needle``; raise after ``timeout``."""
        for text in list(self.lines):
            if needle in text:
                return text
        deadline = time.monotonic() + timeout
        while (left := deadline - time.monotonic()) > 0:
            try:
                text = self._queue.get(timeout=left)
            except queue.Empty:
                break
            if text is None:
                break
            if needle in text:
                return text
        msg = f"never printed {needle!r}; stderr: {self.stderr!r}"
        raise AssertionError(msg)

    def wait(self, timeout: float = 30.0) -> int:
        """Wait for the exit; return the code."""
        code = self.proc.wait(timeout)
        self._reader.join(5)
        return code

    def stop(self, timeout: float = 10.0) -> int:
        """SIGINT, then wait for the exit."""
        self.proc.send_signal(signal.SIGINT)
        return self.wait(timeout)

    def close(self) -> None:
        """Kill the process if it still runs."""
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(5)
        self._reader.join(5)
        if self.proc.stderr is not None:
            self.proc.stderr.close()
