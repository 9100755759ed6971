"""A secured fleet on loopback for tests: real certificates, real routers, real recorders.

``SecureFleet`` makes a fleet directory with ``FleetKit`` (the code ``fleetlog deploy init``
runs), starts the shore's and each vehicle's router as ``fleetlog router`` subprocesses, and
recorders as ``fleetlog record`` subprocesses that find their configuration as an installed
machine does (``FLEETLOG_ETC`` pointing at the vehicle's directory).
"""

from __future__ import annotations

import datetime as dt
import json
import os
import time
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from pathlib import Path

import zenoh
from helpers import Proc, free_port, run_cli

from fleetlog.deploy.fleet import Fleet, Machine
from fleetlog.deploy.kit import FleetKit
from fleetlog.transport.session import SessionOptions, open_session

#: machine directories of a test fleet
SHORE = "shore"
OPS = "operators/ops"
REPLAY = "replays/sim"


def vehicle_dir(name: str) -> str:
    return f"vehicles/{name}"


def make_fleet(
    directory: Path, vehicles: tuple[str, ...] = ("alpha", "bravo"), *, days: int = 365
) -> FleetKit:
    """A fleet on 127.0.0.1 whose files stay where they are made."""
    fleet = Fleet(
        name=directory.name,
        root="fleet",
        shore=Machine("shore", ["127.0.0.1"], free_port()),
        vehicles={v: Machine(v, ["127.0.0.1"], free_port()) for v in vehicles},
        operators=["ops"],
        replays=["sim"],
        etc="",
    )
    kit = FleetKit(directory)
    kit.init(fleet, dt.datetime.now(dt.UTC), days)
    return kit


class SecureFleet:
    """Routers and recorders of a secured fleet, stopped by :meth:`close`."""

    def __init__(self, directory: Path, env: dict[str, str], vehicles: tuple[str, ...]) -> None:
        self.directory = directory
        self.kit = make_fleet(directory, vehicles)
        self.fleet = self.kit.load()
        self.base_env = env
        self.procs: dict[str, Proc] = {}
        #: what the last ``fleet --json`` of :meth:`wait_vehicles` said
        self.last_fleet = ""

    # -- environment of a machine

    def env(self, machine: str) -> dict[str, str]:
        """The environment of a process on ``machine`` (its /etc/fleetlog)."""
        env = dict(self.base_env)
        env["FLEETLOG_ETC"] = str(self.directory / machine)
        env.pop("ZENOH_CONFIG", None)
        return env

    def config(self, machine: str) -> Path:
        return self.directory / machine / "zenoh.json5"

    def cli(self, machine: str, *args: str, timeout: float = 60.0) -> tuple[int, str, str]:
        """Run ``fleetlog ARGS`` on ``machine``: (exit code, stdout, stderr)."""
        done = run_cli(*args, cwd=self.directory, env=self.env(machine), timeout=timeout)
        return done.returncode, done.stdout, done.stderr

    # -- processes

    def start_router(self, name: str, zenohd: str | None = None) -> Proc:
        """Start the shore's ("shore") or a vehicle's router (``zenohd``: the stock one)."""
        where = SHORE if name == "shore" else vehicle_dir(name)
        config = str(self.directory / where / "router.json5")
        if zenohd is None:
            proc = Proc(["router", "-c", config], self.directory, self.env(where))
            self.procs[f"router:{name}"] = proc
            proc.wait_for("listening on", timeout=60)
        else:
            proc = Proc([zenohd, "-c", config], self.directory, self.env(where), program=True)
            self.procs[f"router:{name}"] = proc
            time.sleep(2.0)  # zenohd says nothing we could wait for
        return proc

    def start_recorder(self, vehicle: str, *, wait: bool = True) -> Proc:
        """Start a vehicle's recorder, as its service does (no -c: the machine's config)."""
        cwd = self.directory / "logs" / vehicle
        cwd.mkdir(parents=True, exist_ok=True)
        proc = Proc(["record"], cwd, self.env(vehicle_dir(vehicle)))
        self.procs[f"record:{vehicle}"] = proc
        if wait:
            proc.wait_for("recording vehicle", timeout=60)
        return proc

    def start_all(self) -> None:
        self.start_router("shore")
        for vehicle in self.fleet.vehicles:
            self.start_router(vehicle)
        for vehicle in self.fleet.vehicles:
            self.start_recorder(vehicle)

    def stop(self, key: str) -> int:
        proc = self.procs.pop(key)
        try:
            return proc.stop()
        finally:
            proc.close()

    def close(self) -> None:
        for key in list(self.procs):
            proc = self.procs.pop(key)
            if proc.proc.poll() is None:
                with suppress(AssertionError):
                    proc.stop(timeout=10)
            proc.close()

    # -- sessions in this process

    @contextmanager
    def session(self, machine: str, **overrides: object) -> Iterator[zenoh.Session]:
        """A Zenoh session with ``machine``'s configuration (TLS settings overridable)."""
        path = self.config(machine)
        if overrides:
            path = self.tweaked_config(machine, **overrides)
        session = open_session(SessionOptions(config=path, machine_config=False))
        try:
            yield session
        finally:
            session.close()

    def tweaked_config(self, machine: str, **tls: object) -> Path:
        """A copy of a machine's client configuration with some TLS settings changed.

        ``None`` removes a setting (``connect_certificate=None``: no certificate at all).
        """
        conf = zenoh.Config.from_file(str(self.config(machine)))
        for key, value in tls.items():
            text = "null" if value is None else json.dumps(str(value))
            conf.insert_json5(f"transport/link/tls/{key}", text)
        path = self.directory / f"tweaked-{time.monotonic_ns()}.json5"
        path.write_text(str(conf))
        return path

    def wait_vehicles(self, machine: str, want: set[str], timeout: float = 60.0) -> set[str]:
        """Wait until ``machine`` sees ``want`` among the vehicles up (via ``fleetlog fleet``)."""
        deadline = time.monotonic() + timeout
        seen: set[str] = set()
        while time.monotonic() < deadline:
            code, out, err = self.cli(machine, "fleet", "--json")
            self.last_fleet = f"exit {code}; stdout {out[-800:]!r}; stderr {err[-800:]!r}"
            if code == 0:
                seen = {json.loads(line)["vehicle"] for line in out.splitlines() if line}
                if want <= seen:
                    return seen
            time.sleep(0.5)
        return seen

    def diagnosis(self) -> str:
        """What every process of the fleet said, and the last ``fleet`` listing: for a
        failure's message (a fleet that did not come up on a busy machine)."""
        parts = [
            f"ports: shore {self.fleet.shore.port}, "
            + ", ".join(f"{v} {m.port}" for v, m in self.fleet.vehicles.items())
        ]
        for key, proc in self.procs.items():
            state = "running" if proc.proc.poll() is None else f"exited {proc.proc.returncode}"
            parts.append(f"{key} ({state}): {proc.stderr[-1500:]!r}")
        parts.append(f"last fleet listing: {self.last_fleet}")
        return "\n".join(parts)


def recorder_env_free(env: dict[str, str]) -> dict[str, str]:
    out = dict(env)
    for key in ("FLEETLOG_ETC", "ZENOH_CONFIG", "FLEETLOG_SETTINGS"):
        out.pop(key, None)
    return out


def alog_text(directory: Path) -> str:
    """The text of every alog under ``directory`` (a recorder's log root)."""
    out = []
    for path in sorted(directory.rglob("*.alog")):
        out.append(path.read_text(encoding="utf-8", errors="replace"))
    return "".join(out)


def pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except OSError:
        return False
    return True
