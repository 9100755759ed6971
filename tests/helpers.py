"""Helpers the tests import: free loopback ports and the CLI as a subprocess."""

from __future__ import annotations

import queue
import random
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Sequence
from pathlib import Path

#: test data kept in the repository: the tests read nothing outside it
DATA = Path(__file__).resolve().parent / "data"
#: real pLogger sessions and MOOS wire traffic, copied from ../shared/reference
REFERENCE = DATA / "reference"


#: its own generator: hypothesis reseeds the global one inside its tests
_PORTS = random.Random()


def _ephemeral_low() -> int:
    """The first port of the kernel's ephemeral range (what outgoing connections use)."""
    try:
        return int(Path("/proc/sys/net/ipv4/ip_local_port_range").read_text().split()[0])
    except (OSError, ValueError, IndexError):
        return 32768


def free_port() -> int:
    """Return a TCP port on 127.0.0.1 that nothing listens on right now.

    Taken below the kernel's ephemeral range. A port ``bind(0)`` hands out is one the kernel
    also gives outgoing connections: a test's router, started seconds after its port was
    chosen (certificates, the routers before it), once found a Zenoh connection on it
    ("Address already in use"). Below the range only another test's listener can take it.
    """
    low = _ephemeral_low()
    below = range(max(1024, low - 12_000), low)
    for _ in range(100 if len(below) >= 1000 else 0):  # (a range that starts low: bind(0))
        port = _PORTS.choice(below)
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
            try:
                s.bind(("127.0.0.1", port))
            except OSError:
                continue
            return port
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def fleetlog_cmd(*args: str) -> list[str]:
    """The command line that runs the installed CLI with this interpreter."""
    return [sys.executable, "-m", "fleetlog", *args]


def run_cli(
    *args: str, cwd: Path | None = None, env: dict[str, str] | None = None, timeout: float = 30.0
) -> subprocess.CompletedProcess[str]:
    """Run ``fleetlog ARGS`` to completion and return its result."""
    return subprocess.run(
        fleetlog_cmd(*args),
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        timeout=timeout,
        check=False,
    )


class Proc:
    """A ``fleetlog`` subprocess whose stderr is read by a thread, killed on close."""

    def __init__(
        self, args: Sequence[str], cwd: Path, env: dict[str, str], *, program: bool = False
    ) -> None:
        """``fleetlog ARGS``, or with ``program`` the command line ``ARGS`` as it is."""
        self.args = list(args)
        self.proc = subprocess.Popen(
            list(args) if program else fleetlog_cmd(*args),
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

    def stop(self, sig: int = signal.SIGINT, timeout: float = 10.0) -> int:
        """Send ``sig`` (SIGINT) and return the exit code; fail after ``timeout`` seconds."""
        self.proc.send_signal(sig)
        try:
            return self.wait(timeout)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait(5)
            msg = f"{self.args[0]} did not stop within {timeout} s after signal {sig}"
            raise AssertionError(msg) from None

    def close(self) -> None:
        """Kill the process if it still runs."""
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(5)
        self._reader.join(5)
        if self.proc.stderr is not None:
            self.proc.stderr.close()
