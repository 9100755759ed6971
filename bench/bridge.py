"""``fleetlog bridge`` against a C++ MOOS client on the same real MOOSDB, in one run.

Needs ``MOOS_BIN``: the folder holding ``MOOSDB`` and ``umm`` built by hand from core-moos
(docs/bench.md §11 says which programs and how they were built). Everything runs on loopback.

Each round, in this order:

1. **Rate, C++ client.** A publisher (fleetlog's asyncio MOOS client, in a helper process)
   posts N doubles ``BENCH_X = 0..N-1`` into the MOOSDB as fast as it can. The C++ receiver
   (``umm -s=BENCH_X --log=FILE``, core-moos' own client) logs each one with its receive
   time. Rate = N / (last receive − first post).
2. **Rate, bridge.** The same publisher and N; ``fleetlog bridge`` forwards to a bare counting
   Zenoh subscriber (a helper process: one FIFO, ``try_recv() or recv()``, checks that the
   values arrive as 0..N-1). Rate = N / (last sample − first post). Loss-free: the count and
   the order are checked, and the bridge's summary must say ``not forwarded 0``.
3. **Latency at 1,000 msg/s.** ``umm -p=BENCH_L@1000`` (C++) publishes; a C++ ``umm``
   receiver and the bridge → Zenoh subscriber receive the same messages at the same time.
   Latency = receive time − the message's MOOS time. Added p99 = bridge − C++.
4. **Zenoh → MOOS.** fleetlog's Python API publishes N doubles (BLOCK); the bridge posts them
   into the MOOSDB, where fleetlog's asyncio MOOS client counts them in order.
5. **Into the recorder.** The same N-message burst, bridge → ``fleetlog record``; every value
   must be in the alog once (loss-free at the recorder's own rate, which paces the bridge
   through BLOCK back-pressure).

    python bench/bridge.py --rounds 3 -n 100000
"""

from __future__ import annotations

import argparse
import asyncio
import os
import re
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
from benchlib import (
    CpuMeter,
    Helper,
    _emit,
    _wait_for,
    free_port,
    loadavg,
    percentile,
    spread,
)

HERE = Path(__file__).resolve()
VEHICLE = "bench"
KEY = f"fleet/{VEHICLE}/var/BENCH_X"
LAT_KEY = f"fleet/{VEHICLE}/var/BENCH_L"


# --------------------------------------------------------------------------------------------
# Helper roles (run as ``python bench/bridge.py ROLE ...``)


def role_moospub(args: argparse.Namespace) -> None:
    """Post N doubles into the MOOSDB as fast as our asyncio client can."""
    from fleetlog.moos.requests import notify
    from fleetlog.transport.moos_client import MoosClient

    async def main() -> None:
        client = MoosClient(args.name, "127.0.0.1", args.port, on_mail=lambda m: None)
        await client.connect()
        _emit(event="ready")
        await asyncio.to_thread(_wait_for, sys.stdin, "go")
        first = time.time()
        # --rate: chunks of a hundredth of a second's messages, each sent on its schedule
        step = max(1, int(args.rate / 100)) if args.rate > 0 else 1000
        began = time.perf_counter()
        for start in range(0, args.n, step):
            if args.rate > 0:
                delay = began + start / args.rate - time.perf_counter()
                if delay > 0:
                    await asyncio.sleep(delay)
            now = time.time()
            client.send(
                [
                    notify(args.var, float(i), now, args.name)
                    for i in range(start, min(start + step, args.n))
                ]
            )
            await asyncio.sleep(0)
            while client.buffered() > 1 << 20:
                await asyncio.sleep(0.001)
        while client.buffered():
            await asyncio.sleep(0.001)
        _emit(event="done", first=first, last=time.time())
        await asyncio.to_thread(_wait_for, sys.stdin, "exit")
        client.close()

    asyncio.run(main())


def role_moosrx(args: argparse.Namespace) -> None:
    """Count N BENCH_Z notifications from the MOOSDB (fleetlog's asyncio client)."""
    from fleetlog.transport.moos_client import MoosClient

    async def main() -> None:
        done = asyncio.Event()
        state = {"count": 0, "first": 0.0, "last": 0.0, "in_order": True}

        def mail(messages: list[Any]) -> None:
            for m in messages:
                if m.key != "BENCH_Z":
                    continue
                if state["count"] == 0:
                    state["first"] = time.time()
                if m.double != state["count"]:
                    state["in_order"] = False
                state["count"] += 1
                if state["count"] >= args.n:
                    state["last"] = time.time()
                    done.set()

        client = MoosClient(args.name, "127.0.0.1", args.port, on_mail=mail)
        client.subscribe("BENCH_Z")
        await client.connect()
        _emit(event="ready")
        await done.wait()
        _emit(event="done", **state)
        await asyncio.to_thread(_wait_for, sys.stdin, "exit")
        client.close()

    asyncio.run(main())


def _zsession(listen: str) -> Any:
    from fleetlog.transport.session import SessionOptions, open_session

    return open_session(SessionOptions(listen=(listen,), multicast_scouting=False))


def role_zcount(args: argparse.Namespace) -> None:
    """Count BENCH_X samples to N, checking their values are 0..N-1 in order."""
    import zenoh

    session = _zsession(args.listen)
    sub = session.declare_subscriber(KEY, zenoh.handlers.FifoChannel(65536))
    _emit(event="ready")
    try_recv, recv = sub.try_recv, sub.recv
    sample = try_recv() or recv()
    first = time.time()
    value = float(sample.payload.to_bytes())
    count, wrong = 1, None if value == 0.0 else (0, value)
    while count < args.n:
        sample = try_recv() or recv()
        if wrong is None and (value := float(sample.payload.to_bytes())) != count:
            wrong = (count, value)
        count += 1
    last = time.time()
    _emit(event="done", first=first, last=last, count=count, in_order=wrong is None, wrong=wrong)
    _wait_for(sys.stdin, "exit")
    sub.undeclare()
    session.close()


def role_zstamps(args: argparse.Namespace) -> None:
    """Receive time − MOOS time of N BENCH_L samples (a blocking receive: no polling)."""
    import struct

    import zenoh

    session = _zsession(args.listen)
    sub = session.declare_subscriber(LAT_KEY, zenoh.handlers.FifoChannel(65536))
    _emit(event="ready")
    unpack = struct.Struct("<d").unpack_from
    recv = sub.handler.recv
    clock = time.time
    got: list[tuple[float, float, float]] = []
    for _ in range(args.n):
        sample = recv()
        now = clock()
        got.append(
            (float(sample.payload.to_bytes()), unpack(sample.attachment.to_bytes(), 0)[0], now)
        )
    _emit(event="done", samples=got)
    _wait_for(sys.stdin, "exit")
    sub.undeclare()
    session.close()


# --------------------------------------------------------------------------------------------
# The MOOS programs and the bridge


def moos_bin() -> Path:
    folder = os.environ.get("MOOS_BIN", "")
    if not folder or not (Path(folder) / "MOOSDB").is_file():
        sys.exit("bench/bridge.py needs MOOS_BIN: the folder holding MOOSDB and umm")
    return Path(folder)


class Moos:
    def __init__(self, work: Path) -> None:
        self.bin = moos_bin()
        self.work = work
        self.port = free_port()
        self.procs: list[subprocess.Popen[bytes]] = []
        self.db = self._spawn(
            "MOOSDB",
            f"--moos_port={self.port}",
            f"--moos_community={VEHICLE}",
            "--moos_suicide_disable",
            out="moosdb.out",
        )
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:
            with socket.socket() as s:
                if s.connect_ex(("127.0.0.1", self.port)) == 0:
                    break
            time.sleep(0.05)
        time.sleep(0.2)

    def _spawn(self, program: str, *args: str, out: str) -> subprocess.Popen[bytes]:
        with (self.work / out).open("wb") as f:
            proc = subprocess.Popen(
                [str(self.bin / program), *args],
                cwd=self.work,
                stdin=subprocess.DEVNULL,
                stdout=f,
                stderr=subprocess.STDOUT,
            )
        self.procs.append(proc)
        return proc

    def umm(self, name: str, *args: str) -> tuple[subprocess.Popen[bytes], Path]:
        log = self.work / f"{name}.log"
        log.unlink(missing_ok=True)
        proc = self._spawn(
            "umm",
            f"--moos_name={name}",
            "--moos_host=127.0.0.1",
            f"--moos_port={self.port}",
            "--moos_suicide_disable",
            f"--log={log}",
            *args,
            out=f"{name}.out",
        )
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:
            if "Handshaking as" in (self.work / f"{name}.out").read_text(errors="replace"):
                break
            time.sleep(0.05)
        time.sleep(0.3)
        return proc, log

    def close(self) -> None:
        for proc in reversed(self.procs):
            if proc.poll() is None:
                proc.send_signal(signal.SIGINT)
                try:
                    proc.wait(5)
                except subprocess.TimeoutExpired:
                    proc.kill()
                    proc.wait()


def umm_rows(log: Path) -> list[tuple[float, float, float]]:
    """(value, MOOS time, receive time) of each double an umm logged."""
    rows = []
    for line in log.read_text(errors="replace").splitlines():
        try:
            rows.append((float(line[80:]), float(line[40:60]), float(line[60:80])))
        except ValueError:
            continue
    return rows


def wait_rows(log: Path, n: int, timeout: float = 120.0) -> list[tuple[float, float, float]]:
    """The rows an umm logged, once it has N or its log stopped growing for 2 s.

    A C++ MOOS app purges its inbox above 2,048 unread messages (INBOX_PENDING_LIMIT): under
    a burst umm may never reach N.
    """
    deadline = time.monotonic() + timeout
    rows: list[tuple[float, float, float]] = []
    size, still = -1, time.monotonic()
    while time.monotonic() < deadline:
        now_size = log.stat().st_size if log.exists() else 0
        if now_size != size:
            size, still = now_size, time.monotonic()
        rows = umm_rows(log) if log.exists() else []
        if len(rows) >= n or (size > 0 and time.monotonic() - still > 2.0):
            return rows
        time.sleep(0.25)
    return rows


def cpu_seconds(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


class Bridge:
    def __init__(self, moos: Moos, *zenoh: str) -> None:
        self.err = (moos.work / "bridge.err").open("w+")
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "fleetlog", "bridge", "--host", "127.0.0.1",
             "--port", str(moos.port), "--no-multicast-scouting", *zenoh],
            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=self.err,
        )  # fmt: skip
        deadline = time.monotonic() + 20
        while "connected to the MOOSDB" not in self.text():
            if time.monotonic() > deadline or self.proc.poll() is not None:
                raise RuntimeError(f"the bridge did not connect: {self.text()}")
            time.sleep(0.05)
        time.sleep(1.0)  # its publishers learn the subscriber

    def text(self) -> str:
        self.err.flush()
        return Path(self.err.name).read_text()

    def stop(self) -> str:
        self.proc.send_signal(signal.SIGINT)
        self.proc.wait(30)
        return self.text().splitlines()[-1]


def publish(moos: Moos, n: int, var: str = "BENCH_X", name: str = "tx") -> Helper:
    pub = Helper(
        "moospub", ["--port", str(moos.port), "-n", str(n), "--name", name, "--var", var], HERE
    )
    pub.read()
    return pub


# --------------------------------------------------------------------------------------------
# The measurements


def rate_cpp(moos: Moos, n: int) -> dict[str, float]:
    rx, log = moos.umm("rx_cpp", "-s=BENCH_C")
    pub = publish(moos, n, "BENCH_C")
    pub.send("go")
    sent = pub.read()
    rows = wait_rows(log, n)
    pub.finish()
    rx.send_signal(signal.SIGINT)
    rx.wait(10)
    last_rx = max(r[2] for r in rows) if rows else float("nan")
    return {"rate": len(rows) / (last_rx - sent["first"]), "lost": n - len(rows),
            "put": n / (sent["last"] - sent["first"])}  # fmt: skip


def rate_bridge(moos: Moos, n: int) -> dict[str, float]:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    counter = Helper("zcount", ["--listen", endpoint, "-n", str(n)], HERE)
    counter.read()
    bridge = Bridge(moos, "-e", endpoint)
    cpu0 = cpu_seconds(bridge.proc.pid)
    pub = publish(moos, n)
    pub.send("go")
    sent = pub.read()
    got = counter.read(timeout=300)
    cpu = cpu_seconds(bridge.proc.pid) - cpu0
    pub.finish()
    counter.finish()
    line = bridge.stop()
    assert got["count"] == n, got
    assert got["in_order"], got
    assert "not forwarded 0," in line, line
    return {"rate": n / (got["last"] - sent["first"]), "cpu_us": cpu / n * 1e6}


def latency(moos: Moos, seconds: float) -> dict[str, list[float]]:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    n = int(seconds * 1000)
    stamps = Helper("zstamps", ["--listen", endpoint, "-n", str(n)], HERE)
    stamps.read()
    bridge = Bridge(moos, "-e", endpoint)
    rx, log = moos.umm("rx_lat", "-s=BENCH_L")
    tx, _ = moos.umm("tx_lat", "-p=BENCH_L@1000", f"--num_tx={n}")
    tx.wait(seconds + 30)
    rows = wait_rows(log, n, timeout=30)
    got = stamps.read(timeout=60)
    stamps.finish()
    bridge.stop()
    rx.send_signal(signal.SIGINT)
    rx.wait(10)
    cpp = {value: (when, rx) for value, when, rx in rows}
    bridged = {value: (when, rx) for value, when, rx in got["samples"]}
    both = sorted(set(cpp) & set(bridged))
    return {
        "cpp": [cpp[v][1] - cpp[v][0] for v in both],
        "bridge": [bridged[v][1] - bridged[v][0] for v in both],
        # the same message, received by each: what the bridge adds to a C++ receiver's time
        "added": [bridged[v][1] - cpp[v][1] for v in both],
        "missing": [n - len(cpp), n - len(bridged)],
    }


def zenoh_to_moos(moos: Moos, n: int) -> dict[str, float]:
    """fleetlog's Python API publishes N doubles; the bridge posts them into the MOOSDB."""
    from fleetlog.api import Vehicle
    from fleetlog.transport.session import SessionOptions

    port = free_port()
    rx = Helper("moosrx", ["--port", str(moos.port), "-n", str(n), "--name", "rx_z"], HERE)
    rx.read()
    opts = SessionOptions(listen=(f"tcp/127.0.0.1:{port}",), multicast_scouting=False)
    with Vehicle(VEHICLE, source="bench", options=opts) as v:
        bridge = Bridge(moos, "-e", f"tcp/127.0.0.1:{port}")
        assert v.wait_for_subscriber("BENCH_Z", 10.0)
        first = time.time()
        for i in range(n):
            v.publish("BENCH_Z", float(i))
        got = rx.read(timeout=300)
        rx.finish()
        bridge.stop()
    assert got["count"] == n, got
    assert got["in_order"], got
    return {"rate": n / (got["last"] - first)}


def into_recorder(moos: Moos, n: int, work: Path) -> dict[str, float]:
    from benchlib import RecorderProcess, count_alog

    port = free_port()
    (work / "rec").mkdir()
    rec = RecorderProcess(work / "rec", port, ["--no-serve"])
    bridge = Bridge(moos, "-e", f"tcp/127.0.0.1:{port}")
    pub = publish(moos, n, "BENCH_R")
    pub.send("go")
    sent = pub.read()
    deadline = time.monotonic() + 300
    counts: dict[str, int] = {}
    exact: dict[str, bool] = {}
    last_seen = time.time()
    while time.monotonic() < deadline:
        counts, exact = count_alog(rec.alog, ["BENCH_R"])
        if counts.get("BENCH_R", 0) >= n:
            last_seen = time.time()
            break
        time.sleep(0.2)
    pub.finish()
    line = bridge.stop()
    summary = rec.stop()
    assert exact.get("BENCH_R"), "the alog's BENCH_R values are not 0..n-1"
    return {"rate": n / (last_seen - sent["first"]), "logged": counts.get("BENCH_R", 0),
            "lost": int(re.search(r"lost (\d+)", summary).group(1)),  # type: ignore[union-attr]
            "not_forwarded": int(re.search(r"not forwarded (\d+),", line).group(1))}  # type: ignore[union-attr]  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("-n", type=int, default=100_000)
    parser.add_argument("--lat-seconds", type=float, default=5.0)
    parser.add_argument("--no-recorder", action="store_true")
    args = parser.parse_args()
    cpp_rates: list[float] = []
    bridge_rates: list[float] = []
    ratios: list[float] = []
    cpu_us: list[float] = []
    lat: dict[str, list[float]] = {
        "cpp50": [], "cpp99": [], "br50": [], "br99": [], "added": [], "added50": []
    }  # fmt: skip
    rec_rates: list[float] = []
    z2m_rates: list[float] = []
    meter = CpuMeter()
    print(f"load average at start: {loadavg()}", flush=True)
    for r in range(args.rounds):
        with tempfile.TemporaryDirectory(prefix="bench-bridge-") as tmp:
            moos = Moos(Path(tmp))
            try:
                cpp = rate_cpp(moos, args.n)
                br = rate_bridge(moos, args.n)
                lt = latency(moos, args.lat_seconds)
                z2m = zenoh_to_moos(moos, args.n)
                rec = None if args.no_recorder else into_recorder(moos, args.n, Path(tmp))
            finally:
                moos.close()
        cpp_rates.append(cpp["rate"])
        bridge_rates.append(br["rate"])
        ratios.append(br["rate"] / cpp["rate"])
        cpu_us.append(br["cpu_us"])
        c, b = sorted(lt["cpp"]), sorted(lt["bridge"])
        lat["cpp50"].append(percentile(c, 0.5) * 1e3)
        lat["cpp99"].append(percentile(c, 0.99) * 1e3)
        lat["br50"].append(percentile(b, 0.5) * 1e3)
        lat["br99"].append(percentile(b, 0.99) * 1e3)
        added = sorted(lt["added"])
        lat["added50"].append(percentile(added, 0.5) * 1e3)
        lat["added"].append(percentile(added, 0.99) * 1e3)
        print(
            f"round {r + 1}: C++ {cpp['rate']:,.0f}/s (lost {cpp['lost']}, put {cpp['put']:,.0f}/s)"
            f" | bridge {br['rate']:,.0f}/s ({br['cpu_us']:.1f} µs CPU/msg)"
            f" | ratio {ratios[-1]:.2f} | 1 kHz p50/p99 C++ {lat['cpp50'][-1]:.2f}/"
            f"{lat['cpp99'][-1]:.2f} ms, bridge {lat['br50'][-1]:.2f}/{lat['br99'][-1]:.2f} ms"
            f" added p50/p99 {lat['added50'][-1]:.2f}/{lat['added'][-1]:.2f} ms"
            f" ({len(c)} msgs, missing C++/bridge {lt['missing']})"
            + (f" | recorder {rec['rate']:,.0f}/s logged {rec['logged']} lost {rec['lost']}"
               f" not forwarded {rec['not_forwarded']}" if rec else "")
            + f" | load {loadavg()}",
            flush=True,
        )  # fmt: skip
        z2m_rates.append(z2m["rate"])
        print(f"round {r + 1}: Zenoh -> MOOS {z2m['rate']:,.0f}/s, loss-free", flush=True)
        if rec:
            rec_rates.append(rec["rate"])
    busy, steal = meter.shares()
    print()
    shares = f"CPU busy {busy:.0%}, steal {steal:.0%}"
    print(f"{args.rounds} rounds, N = {args.n:,}; 2 cores, shared ({shares})")
    print(f"C++ umm receiver            {spread(cpp_rates)} msg/s")
    print(f"bridge -> Zenoh subscriber  {spread(bridge_rates)} msg/s")
    print(f"bridge / C++                {spread(ratios, '{:.2f}')}x")
    print(f"bridge CPU per message      {spread(cpu_us, '{:.1f}')} µs")
    ms = "{:.2f}"
    print(f"1 kHz p50 C++ / bridge      {spread(lat['cpp50'], ms)} / {spread(lat['br50'], ms)} ms")
    print(f"1 kHz p99 C++ / bridge      {spread(lat['cpp99'], ms)} / {spread(lat['br99'], ms)} ms")
    print(f"added, same message p50     {spread(lat['added50'], ms)} ms (bridge rx - C++ rx)")
    print(f"added, same message p99     {spread(lat['added'], ms)} ms")
    print(f"API -> bridge -> MOOSDB     {spread(z2m_rates)} msg/s, loss-free")
    if rec_rates:
        print(f"bridge -> recorder          {spread(rec_rates)} msg/s, loss-free")
    print(f"median C++ rate {statistics.median(cpp_rates):,.0f}")


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] in ("moospub", "moosrx", "zcount", "zstamps"):
        role = sys.argv[1]
        p = argparse.ArgumentParser()
        p.add_argument("--port", type=int)
        p.add_argument("--listen")
        p.add_argument("-n", type=int, default=0)
        p.add_argument("--name", default="tx")
        p.add_argument("--var", default="BENCH_X")
        p.add_argument("--rate", type=float, default=0.0, help="msg/s; 0: as fast as it can")
        ns = p.parse_args(sys.argv[2:])
        roles = {"moospub": role_moospub, "moosrx": role_moosrx, "zcount": role_zcount}
        roles["zstamps"] = role_zstamps
        roles[role](ns)
    else:
        main()
