"""Fetch over a radio: ``fleetlog fetch`` against a raw TCP copy over the same emulated link.

A vehicle and the shore sit in network namespaces joined by fleetlog's radio link
(fleetlog/deploy/netlink.py): from the vehicle 200 ms delay, 5 % loss, 1 Mbit/s (as netem and
tbf on the vehicle's side), 1 Mbit/s back. The vehicle runs its router and recorder with the
security profile (mutual TLS, access control, the two-link radio configuration); the shore
its router. A finished session of --mb MB of incompressible text sits in the vehicle's log
root.

* **fetch**: ``fleetlog fetch alpha SESSION`` run on the shore as the operator, to a fresh
  directory (ranges through both routers, sha256 verified);
* **raw TCP**: the same bytes sent by a Python ``sock.sendall`` in the vehicle's namespace
  to a Python receiver in the shore's, one plain TCP connection on the same link.

Rounds alternate the two; the figure is each one's median rate and the ratio of the medians.
Needs root (namespaces). The machine is shared: run it short, and note ``uptime`` beside it.

    sudo python bench/link_fetch.py --mb 2 --rounds 3
"""

from __future__ import annotations

import argparse
import base64
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from fleetlog.deploy.demo import DemoFleet
from fleetlog.deploy.netlink import LinkShape, namespaces_possible

SESSION = "MOOSLog_1_1_2026_____00_00_00"
RADIO = (LinkShape(delay=0.2, loss=0.05, rate=1e6, queue=0.1), LinkShape(rate=1e6, queue=0.1))

RECEIVER = """
import socket, sys, time
s = socket.socket(); s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
s.bind(("0.0.0.0", int(sys.argv[1]))); s.listen(1); print("ready", flush=True)
c, _ = s.accept(); t = time.monotonic(); n = 0
while True:
    d = c.recv(1 << 16)
    if not d: break
    n += len(d)
print(n, time.monotonic() - t, flush=True)
"""
SENDER = """
import socket, sys
s = socket.create_connection((sys.argv[1], int(sys.argv[2])))
with open(sys.argv[3], "rb") as f:
    while chunk := f.read(1 << 20):
        s.sendall(chunk)
s.close()
"""


def make_session(home: Path, size: int) -> Path:
    """A finished session whose alog is ``size`` bytes of incompressible text."""
    directory = home / SESSION
    directory.mkdir(parents=True)
    alog = directory / f"{SESSION}.alog"
    with alog.open("w") as f:
        f.write(f"%% LOGFILE:  {SESSION}\n%% LOGSTART   1767225600.0\n")
        n = 0
        while f.tell() < size:
            text = base64.b64encode(os.urandom(45)).decode()
            f.write(f"{n * 0.01:.3f}   BIG_DATA   iBig   {text}\n")
            n += 1
    old = time.time() - 3600
    os.utime(alog, (old, old))
    return alog


def raw_tcp(demo: DemoFleet, alog: Path, port: int) -> float:
    receiver = subprocess.Popen(
        demo.command("shore", [sys.executable, "-c", RECEIVER, str(port)]),
        stdout=subprocess.PIPE,
        text=True,
    )
    assert receiver.stdout is not None
    assert receiver.stdout.readline().strip() == "ready"
    subprocess.run(
        demo.command("vehicles/alpha", [sys.executable, "-c", SENDER, "10.77.0.2", str(port),
                                        str(alog)]),
        check=True,
        timeout=900,
    )  # fmt: skip
    nbytes, seconds = receiver.communicate(timeout=900)[0].split()
    return int(nbytes) / float(seconds)


def fetch(demo: DemoFleet, alog: Path, out: Path) -> float:
    started = time.monotonic()
    done = demo.fleetlog(
        "operators/ops", "fetch", "alpha", SESSION, "-o", str(out), show=False, timeout=1800
    )
    seconds = time.monotonic() - started
    if done.returncode != 0:
        raise SystemExit(f"fetch failed: {done.stderr[-500:]}")
    assert (out / SESSION / alog.name).stat().st_size == alog.stat().st_size
    return alog.stat().st_size / seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--mb", type=float, default=2.0)
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args()
    why = namespaces_possible()
    if why is not None:
        raise SystemExit(f"cannot run here: {why}")
    work = Path(tempfile.mkdtemp(prefix="link-fetch-"))
    demo = DemoFleet(work, ("alpha",), netns=True, radios={"alpha": RADIO}, say=lambda _: None)
    try:
        alog = make_session(work / "vehicles" / "alpha", int(args.mb * 1e6))
        demo.start(apps=False)
        time.sleep(3)
        rates: dict[str, list[float]] = {"fetch": [], "raw TCP": []}
        for i in range(args.rounds):
            rates["raw TCP"].append(raw_tcp(demo, alog, 9100 + i))
            rates["fetch"].append(fetch(demo, alog, work / f"out{i}"))
            print(
                f"round {i + 1}: raw TCP {rates['raw TCP'][-1] / 1e3:.1f} kB/s,"
                f" fetch {rates['fetch'][-1] / 1e3:.1f} kB/s",
                flush=True,
            )
    finally:
        demo.close()
        shutil.rmtree(work, ignore_errors=True)
    raw, got = statistics.median(rates["raw TCP"]), statistics.median(rates["fetch"])
    load = os.getloadavg()
    print(f"{args.mb:g} MB over 200 ms / 5 % loss / 1 Mbit/s, {args.rounds} rounds:")
    print(f"  raw TCP  {raw / 1e3:.1f} kB/s (median)")
    print(f"  fetch    {got / 1e3:.1f} kB/s (median): {got / raw:.2f} of raw TCP")
    print(f"  load average {load[0]:.1f} {load[1]:.1f} {load[2]:.1f} (2 cores, shared)")


if __name__ == "__main__":
    main()
