"""Fetch throughput of ``fleetlog fetch`` against a raw Python TCP copy, same run, loopback.

A generated session of about 200 MB (an alog of generated pLogger lines, a blog, a ylog) is
served by ``fleetlog serve`` in a subprocess, a fresh one per round. The shore side fetches
it with fleetlog's Python API (:func:`fleetlog.shore.fetch.fetch_session`: 1 MiB ranges,
8 in flight, written to ``.part``, sha256 verified, fsynced, renamed) three times a round:

* **first**: right after ``fleetlog serve`` started, or ``--settle`` seconds after (it
  hashes the latest session ahead of time, which takes it a fraction of a second here; a
  fetch that starts before that, or a server without it, hashes while it serves);
* **again**: the same server, the digests cached;
* **cold**: the same server after the files were touched (a new mtime: no digest of this
  version exists, so the vehicle hashes the ranges as it serves them) — the first fetch of a
  file nobody hashed before.

The baseline sends the same files over one plain TCP connection from a subprocess
(``sock.sendall`` of 1 MiB reads) to this process, which writes them to disk: the best a
Python program can expect here.

Both read the files from the page cache and write to the same file system; rounds
alternate the two so load from other users of the machine hits both; figures are the median
[min–max] over rounds, the ratio is taken within each round.

Every timed transfer starts with memory in the same state: just before it, a scratch file as
large as the session is written and deleted where the transfer writes (``--no-prime`` skips
this). On this VM, memory left free for a few seconds is handed back to the host, and writing
into it again runs at 0.6-0.9 GB/s instead of about 4 GB/s; without priming, whichever
transfer follows a pause (the first fetch, after the server starts) writes into that cold
memory and the others into pages just freed by the previous round.

    python bench/fetch_throughput.py               # 200 MB, 5 rounds
    python bench/fetch_throughput.py --mb 500 --rounds 5
"""

from __future__ import annotations

import argparse
import os
import shutil
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

from fleetlog.moos.alog import LineFormatter, format_banner
from fleetlog.shore.client import FleetClient
from fleetlog.shore.fetch import fetch_session
from fleetlog.transport.session import SessionOptions

SESSION = "BENCH_1_1_2025_____00_00_00"
VEHICLE = "bench"
BLOCK = 1 << 20

_SENDER = """
import socket, sys
port, paths = int(sys.argv[1]), sys.argv[2:]
server = socket.create_server(("127.0.0.1", port))
print("ready", flush=True)
conn, _ = server.accept()
with conn:
    for path in paths:
        with open(path, "rb") as file:
            while block := file.read(1 << 20):
                conn.sendall(block)
"""


def free_port() -> int:
    """Return a TCP port that is free on loopback right now."""
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def loadavg() -> str:
    """Return the 1-minute load average (other engineers share the machine)."""
    return f"{os.getloadavg()[0]:.2f}"


def spread(values: list[float]) -> str:
    """Return ``median [min–max]`` of figures."""
    return f"{statistics.median(values):,.0f} [{min(values):,.0f}–{max(values):,.0f}]"


def make_session(root: Path, megabytes: int) -> Path:
    """Write the session: the alog is a 4 MB block of pLogger lines, repeated."""
    session = root / SESSION
    session.mkdir(parents=True)
    fmt = LineFormatter()
    lines = []
    for i in range(40_000):
        key = f"VAR_{i % 50}"
        if i % 3:
            lines.append(fmt.double(i * 0.01, key, "pBench", i * 1.25))
        else:
            lines.append(fmt.string(i * 0.01, key, "pBench:aux", f"value {i}"))
    block = "".join(lines).encode()
    with (session / f"{SESSION}.alog").open("wb") as alog:
        alog.write(format_banner(f"./{SESSION}/{SESSION}.alog", 1.7e9, "now").encode())
        written = 0
        while written < megabytes * 1_000_000 - 2_000_000:
            alog.write(block)
            written += len(block)
    (session / f"{SESSION}.blog").write_bytes(os.urandom(2_000_000))
    (session / f"{SESSION}.ylog").write_text(format_banner("y", 1.7e9, "now"))
    old = time.time() - 3600  # complete for `serve`: not modified for a while
    for path in session.iterdir():
        os.utime(path, (old, old))
    return session


class Served:
    """``fleetlog serve`` of the log root in a subprocess; entering gives its endpoint."""

    def __init__(self, log_root: Path) -> None:
        self.log_root = log_root
        self.endpoint = f"tcp/127.0.0.1:{free_port()}"
        self.proc: subprocess.Popen[str] | None = None

    def __enter__(self) -> str:
        command = ["serve", str(self.log_root), "--vehicle", VEHICLE, "-l", self.endpoint]
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "fleetlog", *command, "--no-multicast-scouting"],
            stderr=subprocess.PIPE,
            text=True,
        )
        assert self.proc.stderr is not None
        line = self.proc.stderr.readline()
        if "serving" not in line:
            self.proc.kill()
            raise RuntimeError(f"fleetlog serve did not start: {line}")
        return self.endpoint

    def __exit__(self, *exc: object) -> None:
        assert self.proc is not None
        self.proc.terminate()
        self.proc.wait(15)
        if self.proc.stderr is not None:
            self.proc.stderr.close()


def touch(files: list[Path], round_: int) -> None:
    """Give the files a new mtime (still an hour old): their digests are no longer known."""
    stamp = time.time() - 3600 - round_
    for path in files:
        os.utime(path, (stamp, stamp))


def prime(directory: Path, size: int) -> None:
    """Write and delete ``size`` bytes in ``directory``: the next writes find warm pages."""
    directory.mkdir(parents=True, exist_ok=True)
    scratch = directory / "prime.tmp"
    block = bytes(BLOCK)
    with scratch.open("wb") as file:
        for _ in range(0, size, BLOCK):
            file.write(block)
    scratch.unlink()


def fetch_round(
    endpoint: str, out: Path, before: Callable[[], None] = lambda: None
) -> tuple[float, int]:
    """Fetch the session with the Python API; return (seconds, bytes).

    ``before`` runs once the vehicle is known to be up, just before the clock starts.
    """
    options = SessionOptions(connect=(endpoint,), multicast_scouting=False)
    with FleetClient.open(options) as client:
        client.require(VEHICLE)
        before()
        started = time.perf_counter()
        outcome = fetch_session(client, VEHICLE, SESSION, out)
        seconds = time.perf_counter() - started
    if not outcome.complete or any(f.status != "fetched" for f in outcome.files):
        raise RuntimeError(f"the fetch did not complete: {outcome}")
    return seconds, outcome.received


def tcp_round(
    files: list[Path], out: Path, before: Callable[[], None] = lambda: None
) -> tuple[float, int]:
    """Copy the files over one TCP connection from a subprocess; return (seconds, bytes)."""
    port = free_port()
    sender = subprocess.Popen(
        [sys.executable, "-c", _SENDER, str(port), *map(str, files)],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert sender.stdout is not None
        if sender.stdout.readline().strip() != "ready":
            raise RuntimeError("the TCP sender did not start")
        out.mkdir(parents=True)
        buffer = bytearray(BLOCK)
        view = memoryview(buffer)
        total = 0
        before()
        started = time.perf_counter()
        with socket.create_connection(("127.0.0.1", port)) as conn:
            for path in files:
                remaining = path.stat().st_size
                with (out / path.name).open("wb") as target:
                    while remaining:
                        got = conn.recv_into(view[: min(BLOCK, remaining)])
                        if not got:
                            raise RuntimeError("the sender closed early")
                        target.write(view[:got])
                        remaining -= got
                        total += got
        seconds = time.perf_counter() - started
    finally:
        sender.wait(30)
    return seconds, total


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mb", type=int, default=200, help="session size in MB")
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument(
        "--settle",
        type=float,
        default=0.0,
        help="seconds between the server's start and the first fetch [default: 0]",
    )
    parser.add_argument(
        "--no-prime",
        action="store_true",
        help="do not warm the pages each transfer writes into (see the docstring)",
    )
    args = parser.parse_args()
    kinds = ("first", "again", "cold")
    rates: dict[str, list[float]] = {kind: [] for kind in (*kinds, "tcp")}
    ratios: dict[str, list[float]] = {kind: [] for kind in kinds}
    with tempfile.TemporaryDirectory(prefix="fleetlog-bench-") as tmp:
        work = Path(tmp)
        session = make_session(work / "logs", args.mb)
        files = sorted(p for p in session.iterdir())
        size = sum(p.stat().st_size for p in files)
        print(f"session: {size / 1e6:.0f} MB in {len(files)} files; load {loadavg()}")

        def before() -> None:
            if not args.no_prime:
                prime(work, size)

        for round_ in range(args.rounds):
            out = work / f"out{round_}"
            figures: dict[str, float] = {}
            with Served(work / "logs") as endpoint:
                time.sleep(args.settle)
                for kind in kinds:
                    if kind == "cold":
                        touch(files, round_)
                    seconds, got = fetch_round(endpoint, out, before)
                    figures[kind] = got / seconds / 1e6
                    shutil.rmtree(out)
            seconds, got = tcp_round(files, out, before)
            figures["tcp"] = got / seconds / 1e6
            shutil.rmtree(out)
            for kind, rate in figures.items():
                rates[kind].append(rate)
            for kind in ratios:
                ratios[kind].append(figures[kind] / figures["tcp"])
            print(
                f"round {round_ + 1}: fetch first {figures['first']:,.0f} MB/s, again"
                f" {figures['again']:,.0f}, cold {figures['cold']:,.0f};"
                f" raw TCP {figures['tcp']:,.0f} MB/s; load {loadavg()}",
                flush=True,
            )
    print(f"fleetlog fetch, first after serve starts: {spread(rates['first'])} MB/s")
    print(f"fleetlog fetch, again (digests cached):   {spread(rates['again'])} MB/s")
    print(f"fleetlog fetch, cold (files never hashed): {spread(rates['cold'])} MB/s")
    print(f"raw Python TCP copy (1 MiB blocks):       {spread(rates['tcp'])} MB/s")
    for kind, values in ratios.items():
        print(
            f"ratio fetch {kind}/TCP: {statistics.median(values):.2f}"
            f" [{min(values):.2f}–{max(values):.2f}] (aim ≥ 0.25)"
        )
    print(f"load {loadavg()} (other users of this 2-core machine count)")


if __name__ == "__main__":
    main()
