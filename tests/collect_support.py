"""A small fleet for the collect tests: vehicles and a shore, in namespaces or on loopback.

With root and ``ip``, each vehicle runs in a network namespace of its own, joined to the
shore's namespace by a veth pair (``10.201.N.1`` the vehicle, ``10.201.N.2`` the shore): a
link cut is the shore's end of the pair set down, a real cut that TCP and Zenoh must ride
out. Without (CI machines without root), every process runs on loopback with its own port,
and a "cut" freezes the vehicle's processes (SIGSTOP) for as long: from the shore the
vehicle goes silent mid-transfer the same way, though no packet is lost.

Each vehicle runs a real ``fleetlog record`` (without a mission: pLogger's defaults, every
variable, sessions in its log root) and an app publishing strings at a steady rate through
the recorder's Zenoh endpoint, in the vehicle's namespace. Shore commands (collect, poke, a
script) run in the shore's namespace as subprocesses. Everything started is killed and every
namespace deleted at the end.
"""

from __future__ import annotations

import contextlib
import itertools
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Sequence
from pathlib import Path

from helpers import fleetlog_cmd

__all__ = ["Fleet", "Vehicle", "namespaces_unavailable"]

#: the app a vehicle runs: strings of SIZE characters at RATE per second until killed
APP = """
import sys, time
from fleetlog.api import Vehicle
from fleetlog.transport.session import SessionOptions
name, endpoint, rate, size = sys.argv[1], sys.argv[2], float(sys.argv[3]), int(sys.argv[4])
opts = SessionOptions(connect=(endpoint,), multicast_scouting=False)
with Vehicle(name, source="pApp", options=opts) as v:
    v.wait_for_subscriber("PAYLOAD", 30)
    print("publishing", flush=True)
    n = 0
    start = time.monotonic()
    while True:
        v.publish("PAYLOAD", f"{n:08d} " + "x" * size)
        v.publish("NAV_X", float(n))
        n += 1
        time.sleep(max(0.0, start + n / rate - time.monotonic()))
"""

_serial = itertools.count()


def namespaces_unavailable() -> str | None:
    """Why vehicles cannot run in namespaces here (then they run on loopback), or None."""
    if shutil.which("ip") is None:
        return "the ip command is not installed"
    if os.geteuid() != 0:
        return "network namespaces need root"
    name = f"flcprobe{os.getpid() % 100000}"
    made = subprocess.run(["ip", "netns", "add", name], capture_output=True, check=False)
    if made.returncode != 0:
        return f"ip netns add failed: {made.stderr.decode().strip()}"
    subprocess.run(["ip", "netns", "del", name], capture_output=True, check=False)
    return None


def _ip(*args: str) -> None:
    done = subprocess.run(["ip", *args], capture_output=True, text=True, check=False)
    if done.returncode != 0:
        msg = f"ip {' '.join(args)}: {done.stderr.strip()}"
        raise RuntimeError(msg)


class Spawned:
    """A subprocess whose output is read by a thread (lines kept)."""

    def __init__(self, argv: Sequence[str], cwd: Path, env: dict[str, str]) -> None:
        self.argv = list(argv)
        self.proc = subprocess.Popen(
            self.argv,
            cwd=cwd,
            env=env,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            start_new_session=True,
        )
        self.lines: list[str] = []
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        with self.proc.stdout:
            for line in self.proc.stdout:
                self.lines.append(line)

    @property
    def output(self) -> str:
        return "".join(self.lines)

    def wait_for(self, needle: str, timeout: float = 30.0) -> None:
        deadline = time.monotonic() + timeout
        while not any(needle in line for line in list(self.lines)):
            if self.proc.poll() is not None or time.monotonic() > deadline:
                msg = f"{self.argv[-3:]} never printed {needle!r}: {self.output[-2000:]}"
                raise AssertionError(msg)
            time.sleep(0.05)

    def send(self, sig: int) -> None:
        if self.proc.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(self.proc.pid, sig)

    def stop(self, sig: int = signal.SIGINT, timeout: float = 30.0) -> int:
        self.send(sig)
        try:
            code = self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            self.kill()
            msg = f"{self.argv[-3:]} did not stop within {timeout} s: {self.output[-2000:]}"
            raise AssertionError(msg) from None
        self._reader.join(5)
        return code

    def kill(self) -> None:
        self.send(signal.SIGKILL)
        with contextlib.suppress(subprocess.TimeoutExpired):
            self.proc.wait(10)
        self._reader.join(5)


class Vehicle:
    """One vehicle: its log root, recorder and app (in its namespace, if any)."""

    def __init__(self, fleet: Fleet, name: str, index: int) -> None:
        self.fleet = fleet
        self.name = name
        self.log_root = fleet.base / name
        self.log_root.mkdir()
        self.ns: str | None = None
        if fleet.netns:
            self.ns = f"{fleet.prefix}{name[:3]}"
            self.address = f"10.201.{index}.1"
            shore_if, vehicle_if = f"{fleet.prefix}s{index}", f"{fleet.prefix}v{index}"
            _ip("netns", "add", self.ns)
            _ip("-n", self.ns, "link", "set", "lo", "up")
            _ip(
                "link", "add", shore_if, "netns", fleet.shore_ns, "type", "veth",
                "peer", "name", vehicle_if, "netns", self.ns,
            )  # fmt: skip
            _ip("-n", self.ns, "addr", "add", f"{self.address}/24", "dev", vehicle_if)
            _ip("-n", fleet.shore_ns, "addr", "add", f"10.201.{index}.2/24", "dev", shore_if)
            _ip("-n", self.ns, "link", "set", vehicle_if, "up")
            _ip("-n", fleet.shore_ns, "link", "set", shore_if, "up")
            self.shore_if = shore_if
            self.endpoint = f"tcp/{self.address}:7447"
            self.local = "tcp/127.0.0.1:7447"  # the app's way in, inside the namespace
        else:
            from helpers import free_port

            self.endpoint = f"tcp/127.0.0.1:{free_port()}"
            self.local = self.endpoint
        self.recorder: Spawned | None = None
        self.app: Spawned | None = None
        self.frozen = False

    def argv(self, argv: Sequence[str]) -> list[str]:
        return ["ip", "netns", "exec", self.ns, *argv] if self.ns else list(argv)

    def start_recorder(self) -> Spawned:
        listen = ["-l", self.endpoint] + (["-l", self.local] if self.local != self.endpoint else [])
        args = ["record", "--vehicle", self.name, *listen, "--no-multicast-scouting"]
        self.recorder = Spawned(self.argv(fleetlog_cmd(*args)), self.log_root, self.fleet.env)
        self.recorder.wait_for("recording")
        return self.recorder

    def start_app(self, rate: float, size: int) -> Spawned:
        argv = [sys.executable, "-c", APP, self.name, self.local, str(rate), str(size)]
        self.app = Spawned(self.argv(argv), self.log_root.parent, self.fleet.env)
        self.app.wait_for("publishing")
        return self.app

    def sessions(self) -> list[Path]:
        return sorted(p for p in self.log_root.iterdir() if p.is_dir())

    def cut(self) -> None:
        """Cut the vehicle's link to the shore (or freeze it, on loopback)."""
        if self.ns:
            _ip("-n", self.fleet.shore_ns, "link", "set", self.shore_if, "down")
        else:
            for proc in (self.recorder, self.app):
                if proc is not None:
                    proc.send(signal.SIGSTOP)
        self.frozen = True

    def restore(self) -> None:
        if self.ns:
            _ip("-n", self.fleet.shore_ns, "link", "set", self.shore_if, "up")
        else:
            for proc in (self.recorder, self.app):
                if proc is not None:
                    proc.send(signal.SIGCONT)
        self.frozen = False

    def close(self) -> None:
        if self.frozen:
            with contextlib.suppress(RuntimeError):
                self.restore()
        for proc in (self.app, self.recorder):
            if proc is not None:
                proc.kill()
        if self.ns:
            with contextlib.suppress(RuntimeError):
                _ip("netns", "del", self.ns)


class Fleet:
    """Vehicles and a shore; :meth:`shore` runs a command on the shore's side."""

    def __init__(self, base: Path, env: dict[str, str], *, netns: bool) -> None:
        self.base = base
        # Every byte through the link: Zenoh would hand payloads over 3 kB between processes
        # of one host through shared memory, past the link (namespaces share /dev/shm).
        config = base / "zenoh.json5"
        config.write_text('{"transport": {"shared_memory": {"enabled": false}}}\n')
        self.env = {**env, "ZENOH_CONFIG": str(config)}
        self.netns = netns
        self.prefix = f"flc{os.getpid() % 10000}{next(_serial)}"
        self.shore_ns = f"{self.prefix}sh"
        if netns:
            _ip("netns", "add", self.shore_ns)
            _ip("-n", self.shore_ns, "link", "set", "lo", "up")
        self.vehicles: dict[str, Vehicle] = {}
        self.spawned: list[Spawned] = []

    def add(self, name: str) -> Vehicle:
        vehicle = Vehicle(self, name, len(self.vehicles) + 1)
        self.vehicles[name] = vehicle
        return vehicle

    def zenoh_args(self) -> list[str]:
        args: list[str] = []
        for vehicle in self.vehicles.values():
            args += ["-e", vehicle.endpoint]
        return [*args, "--no-multicast-scouting"]

    def shore_argv(self, argv: Sequence[str]) -> list[str]:
        return ["ip", "netns", "exec", self.shore_ns, *argv] if self.netns else list(argv)

    def spawn(self, *args: str) -> Spawned:
        """A shore ``fleetlog`` command, left running."""
        argv = self.shore_argv(fleetlog_cmd(*args, *self.zenoh_args()))
        proc = Spawned(argv, self.base, self.env)
        self.spawned.append(proc)
        return proc

    def run(self, *args: str, timeout: float = 120.0) -> subprocess.CompletedProcess[str]:
        """A shore ``fleetlog`` command, to completion."""
        return subprocess.run(
            self.shore_argv(fleetlog_cmd(*args, *self.zenoh_args())),
            cwd=self.base,
            env=self.env,
            capture_output=True,
            text=True,
            timeout=timeout,
            check=False,
        )

    def python(self, script: str, *argv: str, timeout: float = 120.0) -> str:
        """Run a Python script on the shore's side; return its stdout (fail on an error)."""
        done = subprocess.run(
            self.shore_argv([sys.executable, "-c", script, *argv]),
            cwd=self.base,
            env=self.env,
            capture_output=True,
            text=True,
            timeout=timeout,
            check=False,
        )
        assert done.returncode == 0, done.stderr[-3000:]
        return done.stdout

    def close(self) -> None:
        for proc in self.spawned:
            proc.kill()
        for vehicle in self.vehicles.values():
            vehicle.close()
        if self.netns:
            with contextlib.suppress(RuntimeError):
                _ip("netns", "del", self.shore_ns)
