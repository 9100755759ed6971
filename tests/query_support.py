"""Query test support: ``fleetlog serve`` vehicles on loopback, and sessions to serve.

Every vehicle listens on its own ``tcp/127.0.0.1:<free port>`` with multicast scouting off;
the shore CLI connects to all of them. Every wait has a timeout, and every process started
here is killed in teardown.
"""

from __future__ import annotations

import filecmp
import os
import random
import shutil
import signal
import subprocess
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import pytest
from helpers import fleetlog_cmd, free_port, run_cli

from fleetlog.moos.alog import LineFormatter, format_banner

START_TIMEOUT = 20.0
OLD = time.time() - 3600  # an mtime that makes a session complete for `serve`


class Served:
    """A ``fleetlog serve`` subprocess; its stderr is read by a thread."""

    def __init__(
        self,
        log_root: Path,
        vehicle: str | None,
        env: dict[str, str],
        port: int | None = None,
        extra: Sequence[str] = (),
    ) -> None:
        self.log_root = log_root
        self.vehicle = vehicle
        self.env = env
        self.port = port or free_port()
        self.extra = tuple(extra)
        self.endpoint = f"tcp/127.0.0.1:{self.port}"
        self.lines: list[str] = []
        self.proc: subprocess.Popen[str] | None = None
        self.start()

    def start(self) -> None:
        args = ["serve", str(self.log_root), "-l", self.endpoint, "--no-multicast-scouting"]
        if self.vehicle is not None:
            args += ["--vehicle", self.vehicle]
        self.lines = []
        self.proc = subprocess.Popen(
            fleetlog_cmd(*args, *self.extra),
            env=self.env,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
        )
        proc = self.proc
        ready = threading.Event()

        def read() -> None:
            assert proc.stderr is not None
            for line in proc.stderr:
                self.lines.append(line)
                if "serving" in line:
                    ready.set()
            ready.set()

        self._reader = threading.Thread(target=read, daemon=True)
        self._reader.start()
        if not ready.wait(START_TIMEOUT) or proc.poll() is not None:
            self.kill()
            pytest.fail(f"fleetlog serve did not start: {''.join(self.lines)}")

    def _reap(self) -> None:
        assert self.proc is not None
        self._reader.join(5)
        if self.proc.stderr is not None:
            self.proc.stderr.close()

    def kill(self) -> None:
        """SIGKILL: a vehicle that loses power."""
        if self.proc is not None and self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(10)
        if self.proc is not None:
            self._reap()

    def stop(self) -> None:
        """SIGTERM, as systemd stops it."""
        if self.proc is not None and self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(10)
        if self.proc is not None:
            self._reap()


class Fleet:
    """The vehicles of one test and the shore's Zenoh options to reach them."""

    def __init__(self, env: dict[str, str]) -> None:
        self.env = env
        self.vehicles: list[Served] = []

    def serve(
        self,
        log_root: Path,
        vehicle: str | None = None,
        *,
        port: int | None = None,
        extra: Sequence[str] = (),
    ) -> Served:
        served = Served(log_root, vehicle, self.env, port, extra)
        self.vehicles.append(served)
        return served

    def zenoh_args(self) -> list[str]:
        args: list[str] = []
        for served in self.vehicles:
            args += ["-e", served.endpoint]
        return [*args, "--no-multicast-scouting"]

    def cli(self, *args: str, timeout: float = 60.0) -> subprocess.CompletedProcess[str]:
        return run_cli(*args, *self.zenoh_args(), env=self.env, timeout=timeout)

    def close(self) -> None:
        for served in self.vehicles:
            served.kill()


def copy_reference(reference: Path, rel: str, dest: Path) -> Path:
    """Copy a reference run (mtimes kept, so its sessions are complete) and make it writable."""
    target = dest / Path(rel).name
    shutil.copytree(reference / rel, target, symlinks=True)
    for path in [target, *target.rglob("*")]:
        path.chmod(0o755 if path.is_dir() else 0o644)
    return target


def make_session(
    root: Path, name: str, megabytes: float, *, seed: int = 1, old: bool = True
) -> Path:
    """Write a generated session: an alog of about ``megabytes``, a blog, a ylog, a ._moos."""
    rng = random.Random(seed)
    session = root / name
    session.mkdir(parents=True)
    fmt = LineFormatter()
    keys = [f"VAR_{i}" for i in range(40)] + ["NAV_X", "NAV_Y", "DEPLOY"]
    target = int(megabytes * 1e6)
    with (
        (session / f"{name}.alog").open("w") as alog,
        (session / f"{name}.blog").open("wb") as blog,
    ):
        alog.write(
            format_banner(f"./{name}/{name}.alog", 1750334690.048564, "Thu Jan  1 00:00:00 1970")
        )
        alog.write(fmt.string(0.5, "DB_TIME", "MOOSDB_gen", "1750334690.5"))
        t = 1.0
        written = 0
        lines: list[str] = []
        while written < target:
            t += 0.001
            key = keys[rng.randrange(len(keys))]
            if rng.random() < 0.7:
                line = fmt.double(t, key, "pGen", rng.uniform(-1e4, 1e4))
            else:
                line = fmt.string(t, key, "pGen:aux", f"text {rng.getrandbits(64):x}")
            lines.append(line)
            written += len(line)
            if len(lines) >= 4096:
                alog.write("".join(lines))
                lines.clear()
        alog.write("".join(lines))
        blog.write(os.urandom(200_000))
    (session / f"{name}.ylog").write_text(format_banner("y", 1.0, "now"))
    (session / f"{name}._moos").write_text("Community = gen\n")
    if old:
        for path in session.iterdir():
            os.utime(path, (OLD, OLD))
    return session


def wait_for(check: Callable[[], bool], timeout: float, what: str) -> None:
    """Poll ``check`` every 10 ms until it holds; fail the test after ``timeout`` seconds."""
    deadline = time.monotonic() + timeout
    while not check():
        if time.monotonic() > deadline:
            pytest.fail(f"timed out after {timeout} s waiting for {what}")
        time.sleep(0.01)


def same_tree(left: Path, right: Path) -> None:
    """Assert two directories hold the same files with the same bytes, nothing else."""
    names = sorted(p.name for p in left.iterdir())
    assert sorted(p.name for p in right.iterdir()) == names
    match, mismatch, errors = filecmp.cmpfiles(left, right, names, shallow=False)
    assert (mismatch, errors) == ([], [])
    assert len(match) == len(names)
