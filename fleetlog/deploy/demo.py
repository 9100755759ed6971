"""``fleetlog demo``: a whole secured fleet on one machine, the first thing a new user runs.

Routers (the shore's and each vehicle's), three vehicles with their own missions, apps and
recorders, and a shore, with the security profile on (mutual TLS, access control). Where
network namespaces can be made (root), each vehicle sits in one of its own behind a radio
link with delay, loss and a bandwidth cap (:mod:`fleetlog.deploy.netlink`); elsewhere
everything runs on loopback. The demo records, closes each vehicle's session with an
operator's LOGGER_RESTART, fetches every vehicle's finished session, greps remotely, and
replays the fleet together under the replay prefix while the shore watches.

Every step is a ``fleetlog`` command, printed as it runs, so the demo is also a recipe.
"""

from __future__ import annotations

import datetime as dt
import json
import os
import shlex
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from fleetlog.deploy.fleet import DEFAULT_PORT, Fleet, Machine
from fleetlog.deploy.kit import FleetKit
from fleetlog.deploy.netlink import LinkShape, Namespace, RadioLink, namespaces_possible
from fleetlog.errors import FleetlogError

__all__ = ["DemoFleet", "DemoResult", "run_demo"]

SHORE_ADDR = "10.77.0.2"
VEHICLES = ("alpha", "bravo", "charlie")
#: each vehicle's radio, from the vehicle (as netem and tbf on its side) and back
RADIOS: dict[str, tuple[LinkShape, LinkShape]] = {
    "alpha": (LinkShape(delay=0.05, loss=0.01, rate=5e6), LinkShape(rate=5e6)),
    "bravo": (LinkShape(delay=0.2, loss=0.05, rate=1e6), LinkShape(rate=1e6)),
    "charlie": (LinkShape(delay=0.1, loss=0.02, rate=2e6), LinkShape(rate=2e6)),
}

MISSION = """// {vehicle}'s mission (the pLogger block is what fleetlog record reads)
ServerHost = localhost
ServerPort = {port}
Community  = {vehicle}

ProcessConfig = pLogger
{{
  AsyncLog = true
  WildCardLogging = true
  Log = NAV_X @ 0
  Log = NAV_Y @ 0
  Log = NAV_HEADING @ 0.5
  LoggingDirectorySummaryFile = ~/.LastOpenedMOOSLogDirectory
}}
"""


class DemoError(FleetlogError):
    """A step of the demo failed."""


def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@dataclass
class DemoFleet:
    """The fleet's processes, in namespaces joined by radios or on loopback.

    Args:
        directory: where everything goes (the fleet directory, logs, fetched copies).
        vehicles: the vehicles.
        netns: put each vehicle and the shore in a namespace of its own.
        radios: each vehicle's link (vehicle to shore, shore to vehicle), with ``netns``.
    """

    directory: Path
    vehicles: tuple[str, ...] = VEHICLES
    netns: bool = False
    radios: dict[str, tuple[LinkShape, LinkShape]] = field(default_factory=lambda: RADIOS)
    env: dict[str, str] = field(default_factory=lambda: dict(os.environ))
    say: Callable[[str], None] = print

    def __post_init__(self) -> None:
        self.namespaces: dict[str, Namespace] = {}
        self.links: dict[str, RadioLink] = {}
        self.procs: list[subprocess.Popen[str]] = []
        self.directory.mkdir(parents=True, exist_ok=True)
        if self.netns:
            shore = Machine("shore", [SHORE_ADDR], DEFAULT_PORT)
            machines = {v: Machine(v) for v in self.vehicles}
        else:
            shore = Machine("shore", ["127.0.0.1"], _free_port())
            machines = {v: Machine(v, ["127.0.0.1"], _free_port()) for v in self.vehicles}
        fleet = Fleet(
            name="demo",
            root="fleet",
            shore=shore,
            vehicles=machines,
            operators=["ops"],
            replays=["sim"],
            etc="",
        )
        self.kit = FleetKit(self.directory / "fleet")
        self.kit.init(fleet, dt.datetime.now(dt.UTC), 30)
        if self.netns:
            try:
                self._make_radios()
            except BaseException:
                self.close()
                raise

    def _make_radios(self) -> None:
        tag = os.getpid() % 10000
        self.namespaces["shore"] = Namespace(f"fldemo{tag}shore")
        for i, vehicle in enumerate(self.vehicles, start=1):
            ns = self.namespaces[vehicle] = Namespace(f"fldemo{tag}{vehicle[:6]}")
            out, back = self.radios.get(vehicle, (LinkShape(), LinkShape()))
            self.links[vehicle] = RadioLink(
                ns, f"10.77.{i}.1", self.namespaces["shore"], SHORE_ADDR, out, back, seed=i
            )

    # -- machines

    def where(self, machine: str) -> str:
        """The namespace a machine directory runs in (operators, replays: the shore's)."""
        if machine.startswith("vehicles/"):
            return machine.split("/", 1)[1]
        return "shore"

    def command(self, machine: str, argv: list[str]) -> list[str]:
        """``argv`` as run on ``machine`` (in its namespace, if any)."""
        ns = self.namespaces.get(self.where(machine))
        return ns.command(argv) if ns is not None else argv

    def machine_env(self, machine: str) -> dict[str, str]:
        """The environment of a process on ``machine``: its /etc/fleetlog, nothing else."""
        env = dict(self.env)
        env["FLEETLOG_ETC"] = str(self.kit.directory / machine)
        for name in ("ZENOH_CONFIG", "FLEETLOG_SETTINGS", "NOTIFY_SOCKET", "WATCHDOG_USEC"):
            env.pop(name, None)
        return env

    def spawn(self, machine: str, name: str, argv: list[str], cwd: Path) -> subprocess.Popen[str]:
        """Start a long-running process on a machine; its output goes to logs/NAME.log."""
        logs = self.directory / "process-logs"
        logs.mkdir(exist_ok=True)
        with (logs / f"{name}.log").open("w") as out:
            proc = subprocess.Popen(
                self.command(machine, argv),
                cwd=cwd,
                env=self.machine_env(machine),
                stdin=subprocess.DEVNULL,
                stdout=out,
                stderr=subprocess.STDOUT,
                text=True,
            )
        self.procs.append(proc)
        return proc

    def output(self, name: str) -> str:
        """What a process started by :meth:`spawn` printed so far."""
        path = self.directory / "process-logs" / f"{name}.log"
        return path.read_text(errors="replace") if path.exists() else ""

    def wait_output(self, name: str, needle: str, timeout: float = 60) -> None:
        """Wait until a process printed ``needle``.

        Raises:
            DemoError: it did not within ``timeout`` seconds.
        """
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if needle in self.output(name):
                return
            time.sleep(0.1)
        msg = f"{name} did not start: {self.output(name)[-600:]}"
        raise DemoError(msg)

    def fleetlog(
        self, machine: str, *args: str, timeout: float = 300, show: bool = True
    ) -> subprocess.CompletedProcess[str]:
        """Run ``fleetlog ARGS`` on a machine (printing the command line)."""
        if show:
            self.say(f"  [{machine}] $ fleetlog {shlex.join(args)}")
        return subprocess.run(
            self.command(machine, [sys.executable, "-m", "fleetlog", *args]),
            cwd=self.directory,
            env=self.machine_env(machine),
            capture_output=True,
            text=True,
            timeout=timeout,
            check=False,
        )

    def must(self, machine: str, *args: str, timeout: float = 300) -> str:
        """Run ``fleetlog ARGS`` on a machine; return its output.

        Raises:
            DemoError: it failed (with what it said).
        """
        done = self.fleetlog(machine, *args, timeout=timeout)
        if done.returncode != 0:
            msg = f"fleetlog {' '.join(args)} failed: {done.stderr.strip()[-800:]}"
            raise DemoError(msg)
        return done.stdout

    # -- the fleet

    def start(self, apps: bool = True) -> None:
        """Routers, then each vehicle's recorder (with its mission) and, with ``apps``, apps."""
        fleet_dir = self.kit.directory
        me = [sys.executable, "-m", "fleetlog"]
        self.spawn("shore", "router-shore",
                   [*me, "router", "-c", str(fleet_dir / "shore" / "router.json5")],
                   self.directory)  # fmt: skip
        self.wait_output("router-shore", "listening on")
        for vehicle in self.vehicles:
            machine = f"vehicles/{vehicle}"
            self.spawn(machine, f"router-{vehicle}",
                       [*me, "router", "-c", str(fleet_dir / machine / "router.json5")],
                       self.directory)  # fmt: skip
        for vehicle in self.vehicles:
            self.wait_output(f"router-{vehicle}", "listening on")
            machine = f"vehicles/{vehicle}"
            home = self.directory / "vehicles" / vehicle
            home.mkdir(parents=True, exist_ok=True)
            mission = home / f"{vehicle}.moos"
            mission.write_text(MISSION.format(vehicle=vehicle, port=9000))
            self.spawn(machine, f"record-{vehicle}", [*me, "record", str(mission)], home)
        for vehicle in self.vehicles:
            self.wait_output(f"record-{vehicle}", "recording vehicle")
            if not apps:
                continue
            self.spawn(f"vehicles/{vehicle}", f"app-{vehicle}",
                       [sys.executable, "-m", "fleetlog.deploy.demoapp", "app", vehicle],
                       self.directory)  # fmt: skip
        for vehicle in self.vehicles if apps else ():
            self.wait_output(f"app-{vehicle}", "publishing")

    def close(self) -> None:
        """Stop every process, then remove the links and namespaces."""
        for proc in reversed(self.procs):
            if proc.poll() is None:
                proc.terminate()
                try:
                    proc.wait(20)
                except subprocess.TimeoutExpired:
                    proc.kill()
                    proc.wait(5)
        for link in self.links.values():
            link.close()
        for ns in self.namespaces.values():
            ns.close()


@dataclass
class DemoResult:
    """What the demo did, for its summary and for tests."""

    vehicles_up: list[str] = field(default_factory=list)
    fetched: dict[str, Path] = field(default_factory=dict)
    grep_lines: dict[str, int] = field(default_factory=dict)
    replayed: dict[str, int] = field(default_factory=dict)
    refused: str = ""


def run_demo(
    directory: Path,
    seconds: float = 15.0,
    netns: bool | None = None,
    say: Callable[[str], None] = print,
) -> DemoResult:
    """Run the whole demo; return what it did.

    Args:
        directory: where everything goes (kept afterwards, to look at).
        seconds: how long the vehicles record.
        netns: namespaces and radios (None: when this machine can make them).
        say: where the narration goes.

    Raises:
        DemoError: a step failed (the message names the command and what it said).
    """
    why_not = namespaces_possible()
    use_netns = why_not is None if netns is None else netns
    if use_netns and why_not is not None:
        msg = f"network namespaces cannot be made here: {why_not}"
        raise DemoError(msg)
    result = DemoResult()
    ops = "operators/ops"
    say(f"fleetlog demo in {directory}")
    if use_netns:
        say("  each vehicle sits in its own network namespace behind a radio:")
        for vehicle in VEHICLES:
            radio, _ = RADIOS[vehicle]
            say(
                f"    {vehicle}: {radio.delay * 1000:.0f} ms, {radio.loss:.0%} loss,"
                f" {radio.rate / 1e6:g} Mbit/s"
            )
    else:
        say(f"  everything on loopback ({why_not or 'namespaces off'})")
    say("1. the fleet: a CA, certificates and configurations (fleetlog deploy init)")
    demo = DemoFleet(directory, netns=use_netns, say=say)
    try:
        say("2. routers, recorders with their missions, vehicle apps; security profile on")
        demo.start()
        say(f"3. recording {seconds:g} s; the shore sees the fleet:")
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            done = demo.fleetlog(ops, "fleet", "--json", show=False, timeout=60)
            rows = [json.loads(x) for x in done.stdout.splitlines() if x.strip()]
            result.vehicles_up = sorted(r["vehicle"] for r in rows)
            if set(result.vehicles_up) >= set(demo.vehicles):
                break
            time.sleep(1)
        else:
            msg = f"the shore sees only {result.vehicles_up}"
            raise DemoError(msg)
        time.sleep(seconds)
        say(demo.must(ops, "fleet").rstrip())
        say("4. an operator closes each session (LOGGER_RESTART), then fetches it:")
        for vehicle in demo.vehicles:
            demo.must(ops, "poke", "--vehicle", vehicle, "LOGGER_RESTART=true")
        time.sleep(2)
        shore_logs = directory / "shore-logs"
        for vehicle in demo.vehicles:
            rows = [
                json.loads(x)
                for x in demo.must(ops, "sessions", vehicle, "--json").splitlines()
                if x.strip()
            ]
            finished = [r for r in rows if r.get("complete")]
            if not finished:
                msg = f"vehicle {vehicle} has no finished session"
                raise DemoError(msg)
            session = finished[-1]["name"]
            demo.must(ops, "fetch", vehicle, session, "-o", str(shore_logs / vehicle))
            result.fetched[vehicle] = shore_logs / vehicle / session
        say("5. a remote grep on each vehicle (the log stays on the vehicle):")
        for vehicle in demo.vehicles:
            session = result.fetched[vehicle].name
            out = demo.must(ops, "query", vehicle, "NAV_HEADING", "--session", session)
            result.grep_lines[vehicle] = sum(1 for x in out.splitlines() if "NAV_HEADING" in x)
            say(f"    {vehicle}: {result.grep_lines[vehicle]} NAV_HEADING entries")
        say("6. what the profile refuses: the operator may not publish a vehicle's variables:")
        refused = demo.fleetlog(ops, "poke", "--vehicle", "alpha", "NAV_X=0")
        result.refused = refused.stderr.strip()
        say(f"    {result.refused}")
        say("7. the replay host replays the fleet together, under the replay prefix sim_:")
        watch = [sys.executable, "-m", "fleetlog.deploy.demoapp", "watch", "sim_$*", "600"]
        watcher = demo.spawn(ops, "watch", watch, directory)
        demo.wait_output("watch", "watching")
        demo.must(
            "replays/sim", "replay", *map(str, result.fetched.values()), "--prefix", "sim_",
            "--rate", "4", "--no-keys", "--wait", "10", timeout=seconds + 120,
        )  # fmt: skip
        watcher.terminate()
        watcher.wait(20)
        last = [x for x in demo.output("watch").splitlines() if x.startswith("{")]
        result.replayed = json.loads(last[-1]) if last else {}
        say(f"    the shore received: {result.replayed}")
    finally:
        demo.close()
    say(f"done: the fleet's files, logs and each process's output are under {directory}")
    return result
