"""collect over a thin radio link: its throughput against a raw TCP copy, and a poke's round trip.

A vehicle and the shore in network namespaces of their own, joined by an emulated radio
(``fleetlog/deploy/netlink.py``: 1 Mbit/s each way, 200 ms each way, 0.8 s (100 kB) of
modem buffer; needs root). The vehicle runs ``fleetlog record`` over a log root holding one
finished session (``--mb`` MB). From the shore, all the while, a probe does what ``fleetlog
poke`` does every 0.5 s: it publishes a variable and waits until the recorder confirms it
(a status query that travels behind the sample), and prints the round trip. Three phases,
in one run:

* **idle**: nothing else on the link;
* **collect**: ``fleetlog collect --once`` of the session (its time is from the collector's
  "up; collecting" to the session's "complete" line);
* **raw TCP**: the baseline, a plain TCP copy of as many bytes between the two namespaces
  (a Python socket, ``sendall`` of 64 KiB blocks), what any unpaced bulk transfer does.

    sudo python bench/collect_link.py            # a 4 MB session
    sudo python bench/collect_link.py --mb 3 --rate 2e6 --delay 0.1
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

TESTS = Path(__file__).resolve().parents[1] / "tests"
sys.path.insert(0, str(TESTS))

from query_support import make_session  # noqa: E402

from fleetlog.deploy.netlink import LinkShape, Namespace, RadioLink, namespaces_possible  # noqa: E402

VEHICLE_ADDR, SHORE_ADDR = "10.202.0.1", "10.202.0.2"
SESSION = "MOOSLog_1_1_2026_____10_00_00"

PROBE = """
import sys, time
from fleetlog.api import Vehicle
from fleetlog.transport.session import SessionOptions
opts = SessionOptions(connect=(sys.argv[1],), multicast_scouting=False)
with Vehicle("alpha", source="uPoke", options=opts) as v:
    v.wait_for_subscriber("PROBE", 60)
    print("ready", flush=True)
    n = 0
    while True:
        t = time.monotonic()
        v.publish("PROBE", float(n))
        ok = v.confirm(timeout=20)
        print(t, time.monotonic() - t if ok else "none", flush=True)
        n += 1
        time.sleep(max(0.0, t + 0.5 - time.monotonic()))
"""

SERVER = """
import socket, sys
size = int(sys.argv[2])
s = socket.socket(); s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
s.bind((sys.argv[1], 9009)); s.listen(1)
print("listening", flush=True)
c, _ = s.accept()
block = b"x" * 65536
sent = 0
while sent < size:
    c.sendall(block[: min(len(block), size - sent)]); sent += min(len(block), size - sent)
c.close()
"""

CLIENT = """
import socket, sys, time
s = socket.create_connection((sys.argv[1], 9009))
t = time.monotonic(); n = 0
while (b := s.recv(65536)):
    n += len(b)
print(n, time.monotonic() - t)
"""


class Lines:
    """A subprocess whose output lines are kept with the time they arrived."""

    def __init__(self, argv: list[str], cwd: Path) -> None:
        self.proc = subprocess.Popen(
            argv, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
        )
        self.lines: list[tuple[float, str]] = []
        self._thread = threading.Thread(target=self._read, daemon=True)
        self._thread.start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        with self.proc.stdout:
            for line in self.proc.stdout:
                self.lines.append((time.monotonic(), line.rstrip("\n")))

    def wait_for(self, needle: str, timeout: float = 120.0) -> float:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            for when, line in list(self.lines):
                if needle in line:
                    return when
            if self.proc.poll() is not None and not self._thread.is_alive():
                break
            time.sleep(0.05)
        text = "\n".join(line for _, line in self.lines[-20:])
        msg = f"never printed {needle!r}:\n{text}"
        raise RuntimeError(msg)

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(10)
        self._thread.join(5)


def netns(ns: str, argv: list[str]) -> list[str]:
    return ["ip", "netns", "exec", ns, *argv]


def fleetlog(*args: str) -> list[str]:
    return [sys.executable, "-m", "fleetlog", *args]


def round_trips(probe: Lines, start: float, end: float) -> list[float | None]:
    out: list[float | None] = []
    for _, line in list(probe.lines):
        parts = line.split()
        if len(parts) == 2 and parts[0][0].isdigit() and start <= float(parts[0]) < end:
            out.append(None if parts[1] == "none" else float(parts[1]))
    return out


def describe(trips: list[float | None]) -> str:
    got = [t for t in trips if t is not None]
    lost = len(trips) - len(got)
    if not got:
        return f"no answer in {len(trips)}"
    text = f"median {statistics.median(got):.2f} s, max {max(got):.2f} s ({len(got)} pokes)"
    return text + (f", {lost} unanswered" if lost else "")


def run(mb: float, rate: float, delay: float, queue: float, work: Path) -> dict[str, object]:
    """One run of the three phases (``queue``: seconds of buffer); returns the figures."""
    tag = f"{os.getpid() % 10000}"
    vehicle, shore = Namespace(f"clv{tag}"), Namespace(f"cls{tag}")
    vehicle_ns, shore_ns = vehicle.name, shore.name
    shape = LinkShape(delay=delay, rate=rate, queue=queue)
    link = RadioLink(vehicle, VEHICLE_ADDR, shore, SHORE_ADDR, shape)
    started: list[Lines] = []
    figures: dict[str, object] = {}
    # Every byte through the radio: Zenoh would hand payloads over 3 kB between processes of
    # one host through shared memory, past the link (namespaces share /dev/shm).
    config = work / "zenoh.json5"
    config.write_text('{"transport": {"shared_memory": {"enabled": false}}}\n')
    os.environ["ZENOH_CONFIG"] = str(config)
    try:
        logs = work / "logs"
        session = make_session(logs, SESSION, mb)
        size = sum(p.stat().st_size for p in session.iterdir())
        figures["bytes"] = size
        endpoint = f"tcp/{VEHICLE_ADDR}:7447"
        recorder = Lines(
            netns(vehicle_ns, fleetlog("record", "--vehicle", "alpha", "-l", endpoint,
                                       "--no-multicast-scouting")), logs)  # fmt: skip
        started.append(recorder)
        recorder.wait_for("recording")
        probe = Lines(netns(shore_ns, [sys.executable, "-c", PROBE, endpoint]), work)
        started.append(probe)
        probe.wait_for("ready")
        idle_start = time.monotonic()
        time.sleep(6.0)
        idle_end = time.monotonic()

        collect = Lines(
            netns(shore_ns, fleetlog("collect", str(work / "archive"), "--once", "--expect",
                                     "alpha", "-e", endpoint, "--no-multicast-scouting")),
            work,
        )  # fmt: skip
        started.append(collect)
        began = collect.wait_for("alpha: up; collecting")
        ended = collect.wait_for(f"{SESSION} complete", timeout=600)
        collect.proc.wait(120)
        figures["collect_s"] = ended - began
        figures["collect_rate"] = size * 8 / (ended - began)
        time.sleep(2.0)

        server = Lines(netns(vehicle_ns, [sys.executable, "-c", SERVER, VEHICLE_ADDR,
                                          str(size)]), work)  # fmt: skip
        started.append(server)
        server.wait_for("listening")
        raw_start = time.monotonic()
        done = subprocess.run(
            netns(shore_ns, [sys.executable, "-c", CLIENT, VEHICLE_ADDR]),
            capture_output=True, text=True, timeout=600, check=True,
        )  # fmt: skip
        raw_end = time.monotonic()
        received, seconds = done.stdout.split()
        figures["raw_s"] = float(seconds)
        figures["raw_rate"] = int(received) * 8 / float(seconds)
        time.sleep(1.0)
        figures["idle"] = round_trips(probe, idle_start, idle_end)
        figures["during_collect"] = round_trips(probe, began, ended)
        figures["during_raw"] = round_trips(probe, raw_start, raw_end)
        figures["link"] = {"carried": link.bytes_carried, "dropped": link.counters[1]}
    finally:
        for proc in reversed(started):
            proc.stop()
        link.close()
        vehicle.close()
        shore.close()
    return figures


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--mb", type=float, default=4.0, help="session size (MB of alog)")
    parser.add_argument("--rate", type=float, default=1e6, help="bits/s each way")
    parser.add_argument("--delay", type=float, default=0.2, help="seconds each way")
    parser.add_argument("--queue", type=float, default=0.8, help="modem buffer, seconds")
    args = parser.parse_args()
    why = namespaces_possible()
    if why is not None:
        sys.exit(f"cannot run: {why}")
    with tempfile.TemporaryDirectory() as tmp:
        figures = run(args.mb, args.rate, args.delay, args.queue, Path(tmp))
    load = os.getloadavg()
    print(f"link: {args.rate / 1e6:g} Mbit/s, {args.delay * 1e3:.0f} ms each way, "
          f"{args.queue:g} s buffer; session {figures['bytes']} B; load {load[0]:.1f}")  # fmt: skip
    collect_rate, raw_rate = float(figures["collect_rate"]), float(figures["raw_rate"])  # type: ignore[arg-type]
    print(f"collect: {figures['collect_s']:.1f} s, {collect_rate / 1e6:.3f} Mbit/s")
    print(f"raw TCP: {figures['raw_s']:.1f} s, {raw_rate / 1e6:.3f} Mbit/s")
    print(f"collect / raw TCP throughput: {collect_rate / raw_rate:.2f}")
    for phase in ("idle", "during_collect", "during_raw"):
        print(f"poke round trip, {phase.replace('_', ' ')}: {describe(figures[phase])}")  # type: ignore[arg-type]
    print(f"link counters: {figures['link']}")


if __name__ == "__main__":
    main()
