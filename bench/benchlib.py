"""Shared pieces of the recorder benchmarks: helper processes, the recorder, an alog tailer.

The helper processes run this file with a role::

    python bench/benchlib.py publisher --connect tcp/127.0.0.1:P -n 200000 --keys 4
    python bench/benchlib.py counter --listen tcp/127.0.0.1:P -n 200001
    python bench/benchlib.py stamps --listen tcp/127.0.0.1:P -n 10001

Each prints one JSON line per event on stdout (``{"event": "ready"}`` first) and waits for
``go`` / ``exit`` on stdin where the parent must synchronise. Every process uses fleetlog's
own transport (``open_session``, ``MoosPublisher`` with BLOCK, FIFO subscribers), with
multicast scouting off and explicit loopback endpoints (STYLE.md §5).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import re
import signal
import socket
import statistics
import struct
import subprocess
import sys
import threading
import time
from collections.abc import Sequence
from pathlib import Path
from typing import IO, Any

ROOT = "fleet"
VEHICLE = "bench"
END = "BENCH_END"
HERE = Path(__file__).resolve()

# --------------------------------------------------------------------------------------------
# Small helpers used by the bench scripts


def matching(publisher: Any) -> bool:
    """Whether a subscriber matches a publisher's key (zenoh's stub calls the status a bool)."""
    return bool(publisher.matching_status.matching)


def free_port() -> int:
    """Return a TCP port that is free on loopback right now."""
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def key_names(keys: int) -> list[str]:
    """Return the MOOS names the publisher cycles through."""
    return [f"BENCH_X{k}" for k in range(keys)]


def spread(values: Sequence[float], fmt: str = "{:,.0f}") -> str:
    """Return ``median [min–max]`` of a list of figures, formatted."""
    if not values:
        return "-"
    med = statistics.median(values)
    if len(values) == 1:
        return fmt.format(med)
    return f"{fmt.format(med)} [{fmt.format(min(values))}–{fmt.format(max(values))}]"


def percentile(sorted_values: Sequence[float], q: float) -> float:
    """Return the q-quantile (0..1) of already sorted values (nearest rank)."""
    if not sorted_values:
        return float("nan")
    index = min(len(sorted_values) - 1, max(0, round(q * len(sorted_values) + 0.5) - 1))
    return sorted_values[index]


def parse_env(items: Sequence[str] | None) -> dict[str, str]:
    """Return ``KEY=VALUE`` arguments (``--knob``) as a dict."""
    env: dict[str, str] = {}
    for item in items or ():
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise SystemExit(f"expected KEY=VALUE, got {item!r}")
        env[key] = value
    return env


def loadavg() -> str:
    """Return the 1-minute load average (other engineers share the machine)."""
    try:
        return f"{os.getloadavg()[0]:.2f}"
    except OSError:
        return "?"


class CpuMeter:
    """How busy the machine's CPUs were between two readings of ``/proc/stat``.

    ``busy`` is the share of all CPU time spent running anything (ours and other users'),
    ``steal`` the share the hypervisor gave to other guests: both stall the recorder in ways
    it cannot control.
    """

    def __init__(self) -> None:
        self._start = self._read()

    @staticmethod
    def _read() -> list[int]:
        try:
            with open("/proc/stat") as f:
                return [int(x) for x in f.readline().split()[1:]]
        except (OSError, ValueError):
            return []

    def shares(self) -> tuple[float, float]:
        """Return (busy, steal) as fractions of the time since the meter started."""
        end = self._read()
        if not end or len(end) != len(self._start):
            return float("nan"), float("nan")
        delta = [b - a for a, b in zip(self._start, end, strict=True)]
        total = sum(delta[:8]) or 1  # user nice system idle iowait irq softirq steal
        idle = delta[3] + delta[4]
        steal = delta[7] if len(delta) > 7 else 0
        return (total - idle - steal) / total, steal / total


class Helper:
    """A helper process, talking JSON lines on stdout and commands on stdin.

    It runs ``script`` (this file by default) with the role as its first argument.
    """

    def __init__(self, role: str, args: Sequence[str], script: Path = HERE) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, str(script), role, *args],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
            bufsize=1,
        )

    def read(self, timeout: float = 120.0) -> dict[str, Any]:
        """Return the next event the helper printed (kill it, by pid, after ``timeout``)."""
        assert self.proc.stdout is not None
        watchdog = threading.Timer(timeout, self.proc.kill)
        watchdog.start()
        try:
            line = self.proc.stdout.readline()
        finally:
            watchdog.cancel()
        if not line:
            raise RuntimeError(f"helper exited ({self.proc.poll()}) without its event")
        return dict(json.loads(line))

    def send(self, command: str) -> None:
        """Write a command line to the helper's stdin."""
        assert self.proc.stdin is not None
        try:
            self.proc.stdin.write(command + "\n")
            self.proc.stdin.flush()
        except BrokenPipeError:
            pass

    def finish(self, timeout: float = 15.0) -> None:
        """Tell the helper to exit and wait; kill it (by its pid) if it does not."""
        self.send("exit")
        try:
            self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()


class RecorderProcess:
    """``fleetlog record`` without a mission, as a subprocess in its own directory."""

    def __init__(
        self,
        workdir: Path,
        port: int,
        extra: Sequence[str] = (),
        tree: Path | None = None,
        env: dict[str, str] | None = None,
        nice: int | None = None,
    ) -> None:
        """``tree``: run fleetlog from that source tree (``PYTHONPATH``: a before/after pair).

        ``env``: more environment variables for the recorder alone (a Zenoh setting such as
        ``ZENOH_RUNTIME``, measured against the default in the same round). ``nice``: run it
        at that niceness (``nice -n``; below 0 needs root), as a unit's ``Nice=`` would.
        """
        self.workdir = workdir
        more = dict(env or {})
        if tree is not None:
            more["PYTHONPATH"] = str(tree)
        full = {**os.environ, **more} if more else None
        prefix = ["nice", "-n", str(nice)] if nice is not None else []
        self.proc = subprocess.Popen(
            [
                *prefix,
                sys.executable,
                "-m",
                "fleetlog",
                "record",
                "--vehicle",
                VEHICLE,
                "-l",
                f"tcp/127.0.0.1:{port}",
                "--no-multicast-scouting",
                *extra,
            ],
            cwd=workdir,
            env=full,
            stderr=subprocess.PIPE,
            stdout=subprocess.DEVNULL,
            text=True,
        )
        self.stderr: list[str] = []
        self.alog = self._wait_ready()

    def _wait_ready(self, timeout: float = 30.0) -> Path:
        assert self.proc.stderr is not None
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            line = self.proc.stderr.readline()
            if not line:
                raise RuntimeError("fleetlog record exited: " + "".join(self.stderr))
            self.stderr.append(line)
            match = re.search(r"recording .* into (\S+)", line)
            if match:
                directory = self.workdir / match.group(1)
                return directory / (directory.name + ".alog")
        raise TimeoutError("fleetlog record did not say 'recording'")

    def stop(self, timeout: float = 30.0) -> str:
        """SIGINT the recorder (by its pid) and return its summary line."""
        self.proc.send_signal(signal.SIGINT)
        try:
            _, err = self.proc.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            _, err = self.proc.communicate()
        self.stderr.append(err)
        text = "".join(self.stderr)
        summary = [line for line in text.splitlines() if "stopped:" in line]
        return summary[-1] if summary else text.strip()[-300:]


_MISSION = """\
ServerHost = localhost
ServerPort = {port}
Community  = bench

ProcessConfig = pLogger
{{
  AppTick   = {tick}
  CommsTick = {tick}
  File      = plogger
  PATH      = {path}
  SyncLog   = false
  AsyncLog  = true
  FileTimeStamp = true
  WildCardLogging = true
  Log = BENCH_X @ 0
}}
"""


def cpu_ns(pid: int) -> int:
    """Return the nanoseconds every thread of process ``pid`` has spent on a CPU."""
    total = 0
    for task in Path(f"/proc/{pid}/task").iterdir():
        with contextlib.suppress(OSError, ValueError, IndexError):  # a thread that ended
            total += int((task / "schedstat").read_text().split()[0])
    return total


#: Thread names of Zenoh's own runtimes (zenoh 1.x: rx-N, tx-N, acc-N, net-N, app-N) and of
#: tokio workers; every other thread of a recorder is Python's (or polars', jemalloc's).
_ZENOH_THREAD = re.compile(r"^(?:rx|tx|acc|net|app)-[0-9]+$|^tokio-")


def zenoh_cpu_ns(pid: int) -> int:
    """Return the nanoseconds the Zenoh runtime threads of process ``pid`` spent on a CPU."""
    total = 0
    for task in Path(f"/proc/{pid}/task").iterdir():
        with contextlib.suppress(OSError, ValueError, IndexError):  # a thread that ended
            if _ZENOH_THREAD.match((task / "comm").read_text().strip()):
                total += int((task / "schedstat").read_text().split()[0])
    return total


class PLogger:
    """A real MOOSDB and pLogger (core-moos, ``MOOS_BIN``) in ``work``, on a port of their own.

    pLogger logs every variable (WildCardLogging) into ``work/plogs``; BENCH_X is named
    (``Log``) so that it is registered from the start (a wildcard registers a variable only
    once the MOOSDB's DB_VARSUMMARY shows it).
    """

    def __init__(self, moos_bin: Path, work: Path, app_tick: int = 10) -> None:
        self.port = port = free_port()
        self.logs = work / "plogs"
        self.logs.mkdir()  # pLogger creates no parents
        mission = work / "plogger.moos"
        mission.write_text(_MISSION.format(port=port, path=self.logs, tick=app_tick))
        self.procs: list[subprocess.Popen[bytes]] = []
        self.db = self._spawn(moos_bin / "MOOSDB", str(mission), work / "moosdb.out")
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:
            with socket.socket() as s:
                if s.connect_ex(("127.0.0.1", port)) == 0:
                    break
            time.sleep(0.05)
        self.logger = self._spawn(moos_bin / "pLogger", str(mission), work / "plogger.out")

    def alog(self, timeout: float = 20.0) -> Path:
        """Return pLogger's alog, once it exists."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            found = sorted(self.logs.glob("*/*.alog"))
            if found:
                return found[-1]
            time.sleep(0.1)
        raise TimeoutError("pLogger wrote no alog")

    def _spawn(self, program: Path, mission: str, out: Path) -> subprocess.Popen[bytes]:
        with out.open("wb") as f:
            proc = subprocess.Popen(
                [str(program), mission],
                cwd=out.parent,
                stdin=subprocess.DEVNULL,
                stdout=f,
                stderr=subprocess.STDOUT,
            )
        self.procs.append(proc)
        return proc

    def close(self) -> None:
        for proc in reversed(self.procs):
            proc.terminate()
            try:
                proc.wait(5)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()


def summary_counts(summary: str) -> dict[str, int]:
    """Parse ``received N, logged N, ..., lost N`` from the recorder's summary line."""
    text = summary.split("stopped:", 1)[-1]
    return {name: int(num) for name, num in re.findall(r"([a-z]+) (\d+)", text)}


class Tail:
    """Follows a file being written: reads only what the OS has, splits complete lines."""

    def __init__(self, path: Path) -> None:
        self.fd = os.open(path, os.O_RDONLY)
        self.partial = b""

    def read_lines(self) -> list[bytes]:
        """Return the complete lines that appeared since the last call."""
        chunks = [self.partial]
        while True:
            data = os.read(self.fd, 1 << 20)
            if not data:
                break
            chunks.append(data)
        buf = b"".join(chunks)
        cut = buf.rfind(b"\n") + 1
        self.partial = buf[cut:]
        if not cut:
            return []
        return buf[:cut].split(b"\n")[:-1]

    def close(self) -> None:
        os.close(self.fd)


def count_alog(path: Path, names: Sequence[str]) -> tuple[dict[str, int], dict[str, bool]]:
    """Count the entry lines per name and check each name's values are 0..count-1 exactly."""
    wanted = set(names)
    seen: dict[str, list[float]] = {name: [] for name in names}
    with open(path, "rb") as f:
        for raw in f:
            if raw.startswith(b"%"):
                continue
            fields = raw.split()
            if len(fields) >= 4:
                name = fields[1].decode()
                if name in wanted:
                    seen[name].append(float(fields[3]))
    counts = {name: len(v) for name, v in seen.items()}
    exact = {name: sorted(v) == [float(i) for i in range(len(v))] for name, v in seen.items()}
    return counts, exact


# --------------------------------------------------------------------------------------------
# Helper roles (run in their own processes)


def _emit(**fields: object) -> None:
    print(json.dumps(fields), flush=True)


def _wait_for(stream: IO[str], word: str) -> None:
    for line in stream:
        if line.strip() == word:
            return


def role_publisher(args: argparse.Namespace) -> None:
    """Publish N doubles on a few keys with MoosPublisher (BLOCK), then the END marker."""
    from fleetlog.transport.publisher import MoosPublisher
    from fleetlog.transport.session import SessionOptions, open_session
    from fleetlog.wire.keys import var_key

    session = open_session(SessionOptions(connect=(args.connect,), multicast_scouting=False))
    pub = MoosPublisher(session, ROOT, VEHICLE, "bench")
    names = key_names(args.keys)
    # A put made before the subscription is known goes nowhere: wait for each key's match.
    for name in [*names, END]:
        probe = session.declare_publisher(var_key(ROOT, VEHICLE, name))
        deadline = time.monotonic() + 10.0
        while not matching(probe) and time.monotonic() < deadline:
            time.sleep(0.002)
        probe.undeclare()
    time.sleep(0.05)
    _emit(event="ready")
    _wait_for(sys.stdin, "go")
    publish = pub.publish
    k = args.keys
    n = args.n
    if args.raw:
        t0, t1 = _raw_burst(session, names, n)
    elif args.rate <= 0:
        t0 = time.time()
        for i in range(n):
            publish(names[i % k], float(i // k))
        t1 = time.time()
    else:
        period = 1.0 / args.rate
        perf = time.perf_counter
        start = perf()
        t0 = time.time()
        for i in range(n):
            delay = start + i * period - perf()
            if delay > 0:
                time.sleep(delay)
            publish(names[i % k], float(i // k))
        t1 = time.time()
    publish(END, float(n))
    _emit(event="done", t0=t0, t1=t1, n=n)
    # Closing right after the last put drops what is still in transit: wait for the parent.
    _wait_for(sys.stdin, "exit")
    pub.close()
    session.close()


_raw_publishers: list[Any] = []


def _raw_burst(session: Any, names: list[str], n: int) -> tuple[float, float]:
    """Put the same samples as MoosPublisher would, pre-encoded: zenoh-python's own speed.

    Same keys, encoding, payloads and attachment layout; the payloads are built beforehand
    and the attachment's time is refreshed every 1024 samples, so the loop is little more
    than ``Publisher.put``.
    """
    import zenoh

    from fleetlog.wire.keys import var_key
    from fleetlog.wire.message import ENCODINGS, Kind, encode_attachment

    k = len(names)
    pubs = [
        session.declare_publisher(
            var_key(ROOT, VEHICLE, name),
            encoding=zenoh.Encoding(ENCODINGS[Kind.DOUBLE]),
            congestion_control=zenoh.CongestionControl.BLOCK,
            reliability=zenoh.Reliability.RELIABLE,
        )
        for name in names
    ]
    puts = [p.put for p in pubs]
    payloads = [repr(float(i // k)).encode() for i in range(n)]
    tail = encode_attachment(0.0, "bench", "", VEHICLE)[8:]
    pack = struct.Struct("<d").pack
    clock = time.time
    att = b""
    t0 = clock()
    for i in range(n):
        if not i & 1023:
            att = pack(clock()) + tail
        puts[i % k](payloads[i], attachment=att)
    t1 = clock()
    # The publishers stay declared: the session's close at exit undeclares them.
    _raw_publishers.extend(pubs)
    return t0, t1


def _subscriber(args: argparse.Namespace) -> tuple[Any, Any]:
    import zenoh

    from fleetlog.transport.session import SessionOptions, open_session

    session = open_session(SessionOptions(listen=(args.listen,), multicast_scouting=False))
    sub = session.declare_subscriber(f"{ROOT}/{VEHICLE}/var/*", zenoh.handlers.FifoChannel(65536))
    return session, sub


def role_counter(args: argparse.Namespace) -> None:
    """The bare subscriber: one FIFO, ``try_recv() or recv()``, counts to N and stops."""
    session, sub = _subscriber(args)
    _emit(event="ready")
    try_recv = sub.try_recv
    recv = sub.recv
    n = args.n
    _ = try_recv() or recv()
    first = time.time()
    count = 1
    while count < n:
        _ = try_recv() or recv()
        count += 1
    last = time.time()
    _emit(event="done", first=first, last=last, count=count)
    _wait_for(sys.stdin, "exit")
    sub.undeclare()
    session.close()


def role_stamps(args: argparse.Namespace) -> None:
    """A bare subscriber that records receive time − the attachment's publish time."""
    session, sub = _subscriber(args)
    _emit(event="ready")
    unpack = struct.Struct("<d").unpack_from
    try_recv = sub.try_recv
    recv = sub.recv
    clock = time.time
    lat: list[float] = []
    for _ in range(args.n):
        sample = try_recv() or recv()
        now = clock()
        att = sample.attachment
        if att is not None:
            lat.append(now - unpack(att.to_bytes(), 0)[0])
    _emit(event="done", latencies=lat[:-1])  # the last one is the END marker
    _wait_for(sys.stdin, "exit")
    sub.undeclare()
    session.close()


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    sub = parser.add_subparsers(dest="role", required=True)
    p = sub.add_parser("publisher")
    p.add_argument("--connect", required=True)
    p.add_argument("-n", type=int, required=True)
    p.add_argument("--keys", type=int, default=4)
    p.add_argument("--rate", type=float, default=0.0, help="samples/s; 0: as fast as possible")
    p.add_argument("--raw", action="store_true", help="pre-encoded zenoh puts, full speed")
    for role in ("counter", "stamps"):
        s = sub.add_parser(role)
        s.add_argument("--listen", required=True)
        s.add_argument("-n", type=int, required=True, help="samples to receive, END included")
    args = parser.parse_args(argv)
    {"publisher": role_publisher, "counter": role_counter, "stamps": role_stamps}[args.role](args)


if __name__ == "__main__":
    main()
