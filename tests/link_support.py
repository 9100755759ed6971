"""A secured vehicle and shore in network namespaces the test creates, joined by a radio link.

Used by tests/deploy/test_link.py and bench/link_fetch.py. The vehicle's namespace runs its
router, recorder and an app publishing a counter; the shore's runs its router; shore commands
run in the shore's namespace as subprocesses. Everything uses the fleet's real certificates
and configurations (``FleetKit``), with the vehicle dialling the shore across the link.
"""

from __future__ import annotations

import datetime as dt
import json
import os
import subprocess
import sys
import time
from pathlib import Path

from helpers import fleetlog_cmd

from fleetlog.deploy.fleet import Fleet, Machine
from fleetlog.deploy.kit import FleetKit
from fleetlog.deploy.netlink import LinkShape, Namespace, RadioLink

VEHICLE_ADDR, SHORE_ADDR = "10.77.0.1", "10.77.0.2"

#: the vehicle app: a counter at 20 Hz, through the vehicle's router, until killed
COUNTER_APP = """
import sys, time
from fleetlog.api import Vehicle
with Vehicle("alpha", source="iCounter") as v:
    v.wait_for_subscriber("COUNTER", 30)
    n = 0
    print("publishing", flush=True)
    while True:
        v.publish("COUNTER", float(n))
        n += 1
        time.sleep(0.05)
"""

#: command round trips from the shore: a control query every 0.25 s, each printed as
#: "SENT_AT ROUND_TRIP" (time.monotonic(), shared by every process of the machine)
RTT_PROBE = """
import json, sys, time
from fleetlog.transport.services import get_replies
from fleetlog.transport.session import SessionOptions, open_session
s = open_session(SessionOptions())
print("ready", flush=True)
while True:
    t = time.monotonic()
    try:
        ok = bool(get_replies(s, "fleet/alpha/@fleetlog/control", timeout=10,
                              payload=json.dumps({"cmd": "status"}).encode()))
    except Exception:
        ok = False
    print(t, time.monotonic() - t if ok else "none", flush=True)
    time.sleep(0.25)
"""


def round_trips(text: str, start: float, end: float) -> list[float | None]:
    """The probe's round trips of commands sent between ``start`` and ``end``."""
    out: list[float | None] = []
    for line in text.splitlines():
        parts = line.split()
        if len(parts) == 2 and parts[0][0].isdigit() and start <= float(parts[0]) < end:
            out.append(None if parts[1] == "none" else float(parts[1]))
    return out


def big_session(log_root: Path, size: int) -> tuple[str, Path]:
    """A finished session of ``size`` bytes of alog in the vehicle's log root."""
    name = "MOOSLog_1_1_2026_____00_00_00"
    directory = log_root / name
    directory.mkdir(parents=True)
    lines = ["%% LOGFILE:  " + name, "%% FILETIME: 1767225600.0", "%% LOGSTART   1767225600.0"]
    n = 0
    body = []
    total = sum(len(x) + 1 for x in lines)
    while total < size:
        line = f"{n * 0.01:.3f}   BIG_DATA   iBig   {n:09d} {'x' * 60}"
        body.append(line)
        total += len(line) + 1
        n += 1
    alog = directory / f"{name}.alog"
    alog.write_text("\n".join(lines + body) + "\n")
    old = time.time() - 3600
    os.utime(alog, (old, old))
    os.utime(directory, (old, old))
    return name, alog


class LinkedFleet:
    """Vehicle alpha and the shore in two namespaces, the radio link between them."""

    def __init__(self, directory: Path, env: dict[str, str], big: int = 0) -> None:
        self.directory = directory
        self.env = env
        tag = f"{os.getpid() % 100000}"
        self.veh_ns = Namespace(f"flveh{tag}")
        self.shore_ns = Namespace(f"flshore{tag}")
        self.popens: list[subprocess.Popen[str]] = []
        try:
            self.link = RadioLink(self.veh_ns, VEHICLE_ADDR, self.shore_ns, SHORE_ADDR, LinkShape())
            fleet = Fleet(
                name="linked",
                root="fleet",
                shore=Machine("shore", [SHORE_ADDR]),
                vehicles={"alpha": Machine("alpha")},
                operators=["ops"],
                etc="",
            )
            self.kit = FleetKit(directory / "fleet")
            self.kit.init(fleet, dt.datetime.now(dt.UTC), 30)
            self.logs = directory / "logs"
            self.logs.mkdir()
            self.big = big_session(self.logs, big) if big else None
        except BaseException:
            self.close()
            raise

    def machine_env(self, machine: str) -> dict[str, str]:
        env = dict(self.env)
        env["FLEETLOG_ETC"] = str(self.kit.directory / machine)
        env.pop("ZENOH_CONFIG", None)
        return env

    def spawn(
        self, ns: Namespace, machine: str, name: str, argv: list[str], cwd: Path
    ) -> subprocess.Popen[str]:
        """Start a long-running process; its output goes to ``DIRECTORY/NAME.log``."""
        with (self.directory / f"{name}.log").open("w") as out:
            proc = subprocess.Popen(
                ns.command(argv),
                cwd=cwd,
                env=self.machine_env(machine),
                stdin=subprocess.DEVNULL,
                stdout=out,
                stderr=subprocess.STDOUT,
                text=True,
            )
        self.popens.append(proc)
        return proc

    def output(self, name: str) -> str:
        return (self.directory / f"{name}.log").read_text(errors="replace")

    def wait_output(self, name: str, needle: str, timeout: float = 30) -> None:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if needle in self.output(name):
                return
            time.sleep(0.2)
        msg = f"{name} never printed {needle!r}: {self.output(name)[-2000:]}"
        raise AssertionError(msg)

    def start_fleet(self) -> None:
        """The shore's router, then alpha's router, recorder and counter app."""
        fleet_dir = self.kit.directory
        self.spawn(self.shore_ns, "shore", "router-shore",
                   fleetlog_cmd("router", "-c", str(fleet_dir / "shore" / "router.json5")),
                   self.directory)  # fmt: skip
        self.wait_output("router-shore", "listening on")
        veh = "vehicles/alpha"
        self.spawn(self.veh_ns, veh, "router-alpha",
                   fleetlog_cmd("router", "-c", str(fleet_dir / veh / "router.json5")),
                   self.directory)  # fmt: skip
        self.wait_output("router-alpha", "listening on")
        self.spawn(self.veh_ns, veh, "record", fleetlog_cmd("record"), self.logs)
        self.wait_output("record", "recording vehicle 'alpha'")
        self.spawn(self.veh_ns, veh, "counter", python_cmd(COUNTER_APP), self.directory)
        self.wait_output("counter", "publishing")

    def run(
        self, ns: Namespace, machine: str, argv: list[str], timeout: float = 120
    ) -> subprocess.CompletedProcess[str]:
        return subprocess.run(
            ns.command(argv),
            cwd=self.directory,
            env=self.machine_env(machine),
            capture_output=True,
            text=True,
            timeout=timeout,
            check=False,
        )

    def fleetlog(
        self, ns: Namespace, machine: str, *args: str, timeout: float = 120
    ) -> subprocess.CompletedProcess[str]:
        return self.run(ns, machine, fleetlog_cmd(*args), timeout)

    def shore_sees_alpha(self, timeout: float) -> float | None:
        """Seconds until the shore lists alpha (None if it never did)."""
        start = time.monotonic()
        while time.monotonic() - start < timeout:
            done = self.fleetlog(self.shore_ns, "shore", "fleet", "--json", timeout=30)
            if done.returncode == 0 and any(
                json.loads(line)["vehicle"] == "alpha" for line in done.stdout.splitlines() if line
            ):
                return time.monotonic() - start
            time.sleep(0.5)
        return None

    def close(self) -> None:
        for proc in getattr(self, "popens", []):
            if proc.poll() is None:
                proc.terminate()
                try:
                    proc.wait(15)
                except subprocess.TimeoutExpired:
                    proc.kill()
                    proc.wait(5)
        if hasattr(self, "link"):
            self.link.close()
        self.veh_ns.close()
        self.shore_ns.close()


def python_cmd(code: str, *args: str) -> list[str]:
    return [sys.executable, "-c", code, *args]
