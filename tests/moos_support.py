"""A real MOOSDB and real MOOS clients (``umm``) for the tests that need them.

They are built by hand from the public core-moos sources, outside the repository, and found
through ``MOOS_BIN`` (the folder holding ``MOOSDB`` and ``umm``). Without it every test that
needs them is skipped with a reason that says so; the session's summary repeats it loudly
(``tests/bridge/conftest.py``). No fake stands in for the real MOOSDB.

The programs run on loopback only: clients connect to 127.0.0.1, the DB's suicide channel
(UDP multicast) is disabled, its web server stays off (the default), and each runs in its own
temporary directory so that no ``mission.moos`` lying around is read.
"""

from __future__ import annotations

import os
import re
import signal
import socket
import subprocess
import time
from pathlib import Path

import pytest
from helpers import free_port

#: what the skip reason and the summary say
MISSING = (
    "MOOS_BIN is not set to a folder holding MOOSDB and umm (built by hand from the public "
    "core-moos sources): the tests against a real MOOSDB are SKIPPED"
)


def moos_bin() -> Path | None:
    """The folder holding MOOSDB and umm, or None."""
    folder = os.environ.get("MOOS_BIN", "")
    if not folder:
        return None
    path = Path(folder)
    if not (path / "MOOSDB").is_file() or not (path / "umm").is_file():
        return None
    return path


def _reason() -> str:
    folder = os.environ.get("MOOS_BIN", "")
    if folder and moos_bin() is None:
        return f"MOOS_BIN={folder} does not hold both MOOSDB and umm: tests SKIPPED"
    return MISSING


#: mark for every test that needs a real MOOSDB
needs_moos = pytest.mark.skipif(moos_bin() is None, reason=_reason())


def _wait_port(port: int, proc: subprocess.Popen[bytes], timeout: float = 10.0) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            msg = f"MOOSDB exited with {proc.returncode} before listening on {port}"
            raise AssertionError(msg)
        with socket.socket() as s:
            s.settimeout(0.2)
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return  # closed at once: the DB drops a client that sends no handshake
        time.sleep(0.05)
    msg = f"MOOSDB did not listen on {port} within {timeout} s"
    raise AssertionError(msg)


class MoosDB:
    """A real MOOSDB on 127.0.0.1, in its own directory."""

    def __init__(self, folder: Path, workdir: Path, community: str, port: int | None = None):
        self.folder = folder
        self.workdir = workdir
        self.community = community
        self.port = port or free_port()
        self.proc: subprocess.Popen[bytes] | None = None
        self.starts = 0
        workdir.mkdir(parents=True, exist_ok=True)

    def start(self) -> MoosDB:
        self.starts += 1
        out = (self.workdir / f"moosdb.{self.starts}.out").open("wb")
        self.proc = subprocess.Popen(
            [
                str(self.folder / "MOOSDB"),
                f"--moos_port={self.port}",
                f"--moos_community={self.community}",
                "--moos_suicide_disable",
            ],
            cwd=self.workdir,
            stdin=subprocess.DEVNULL,
            stdout=out,
            stderr=subprocess.STDOUT,
        )
        out.close()
        _wait_port(self.port, self.proc)
        return self

    def stop(self, sig: int = signal.SIGTERM) -> None:
        proc = self.proc
        if proc is None:
            return
        if proc.poll() is None:
            proc.send_signal(sig)
            try:
                proc.wait(5)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(5)
        self.proc = None

    def output(self) -> str:
        text = "".join(
            p.read_text(errors="replace") for p in sorted(self.workdir.glob("moosdb.*.out"))
        )
        return re.sub(r"\x1b\[[0-9;]*m", "", text)


class Umm:
    """A real ``umm`` MOOS client (core-moos' universal MOOS messenger)."""

    def __init__(self, folder: Path, workdir: Path, db: MoosDB, name: str, *args: str):
        self.workdir = workdir / name
        self.workdir.mkdir(parents=True, exist_ok=True)
        self.log = self.workdir / "received.log"
        self.out = self.workdir / "umm.out"
        with self.out.open("wb") as out:
            self.proc = subprocess.Popen(
                [
                    str(folder / "umm"),
                    f"--moos_name={name}",
                    "--moos_host=127.0.0.1",
                    f"--moos_port={db.port}",
                    "--moos_suicide_disable",
                    f"--log={self.log}",
                    *args,
                ],
                cwd=self.workdir,
                stdin=subprocess.DEVNULL,
                stdout=out,
                stderr=subprocess.STDOUT,
            )

    def wait(self, timeout: float = 30.0) -> int:
        return self.proc.wait(timeout)

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(5)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(5)

    def received(self) -> list[tuple[str, str, float, str]]:
        """What it received: (name, source, MOOS time, value text), in order."""
        rows = []
        if not self.log.exists():
            return rows
        for line in self.log.read_text(errors="replace").splitlines():
            # key, source and times are padded to 20 columns; the value follows the last
            name, source, when, _rx = (line[i : i + 20].strip() for i in (0, 20, 40, 60))
            if name:
                rows.append((name, source, float(when), line[80:]))
        return rows

    def connected(self) -> bool:
        text = self.out.read_text(errors="replace") if self.out.exists() else ""
        return "Handshaking as" in text and "[ok]" in text


def wait_until(check: object, timeout: float = 10.0, what: str = "condition") -> None:
    """Wait until ``check()`` is true; fail after ``timeout`` seconds."""
    assert callable(check)
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if check():
            return
        time.sleep(0.05)
    msg = f"timed out after {timeout} s waiting for {what}"
    raise AssertionError(msg)
