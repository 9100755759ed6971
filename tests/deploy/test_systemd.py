"""The systemd units, and the services' side of the notify protocol and the watchdog."""

from __future__ import annotations

import configparser
import itertools
import os
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from helpers import Proc, free_port

from fleetlog.moos.mission import LoggerConfig
from fleetlog.recorder.service import RecorderService, ServiceOptions
from fleetlog.transport.notify import Notifier, Watchdog
from fleetlog.transport.session import SessionOptions

UNITS = Path(__file__).resolve().parents[2] / "deploy" / "systemd"
SERVICES = ("fleetlog-record@.service", "fleetlog-router.service", "fleetlog-collect.service")


def unit(name: str) -> configparser.ConfigParser:
    parser = configparser.ConfigParser(strict=False, interpolation=None)
    parser.optionxform = str  # type: ignore[assignment,method-assign]
    parser.read_string((UNITS / name).read_text())
    return parser


def test_units_pass_systemd_analyze_verify(tmp_path: Path) -> None:
    analyze = shutil.which("systemd-analyze")
    if analyze is None:
        pytest.skip("SKIPPED LOUDLY: systemd-analyze is not installed (apt-get install systemd)")
    # verify checks that ExecStart's program exists: point it at this installation's.
    fleetlog = shutil.which("fleetlog") or str(Path(sys.executable).parent / "fleetlog")
    assert Path(fleetlog).exists(), "the fleetlog entry point is not installed"
    names = []
    for name in SERVICES:
        text = (UNITS / name).read_text().replace("/usr/local/bin/fleetlog", fleetlog)
        target = tmp_path / name.replace("@.", "@alpha.")
        target.write_text(text)
        names.append(str(target))
    done = subprocess.run(
        [analyze, "verify", *names], capture_output=True, text=True, timeout=60, check=False
    )
    assert done.returncode == 0, done.stderr
    assert done.stderr.strip() == "", done.stderr


@pytest.mark.parametrize("name", SERVICES)
def test_units_restart_and_are_hardened(name: str) -> None:
    service = unit(name)["Service"]
    assert service["User"] == "fleetlog"
    assert service["Restart"] in ("always", "on-failure")
    assert service["NoNewPrivileges"] == "yes"
    assert service["ProtectSystem"] == "strict"
    assert service["CapabilityBoundingSet"] == ""
    assert service["StandardError"] == "journal"
    assert service["Type"] == "notify"
    assert float(service["WatchdogSec"]) > 0
    if name.startswith("fleetlog-record"):
        assert service["ReadWritePaths"] == "/var/lib/fleetlog/%i"
        assert service["KillSignal"] == "SIGTERM"
    if name == "fleetlog-collect.service":
        assert service["ExecStart"].endswith("fleetlog collect /var/lib/fleetlog/archive")


class NotifySocket:
    """The service manager's end of NOTIFY_SOCKET."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        self.sock.bind(str(path))
        self.sock.settimeout(0.2)
        self.messages: list[tuple[float, str]] = []

    def collect(self, seconds: float, until: str | None = None) -> list[str]:
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            try:
                data = self.sock.recv(4096).decode()
            except TimeoutError:
                continue
            self.messages.append((time.monotonic(), data))
            if until is not None and until in data:
                break
        return [m for _, m in self.messages]

    def close(self) -> None:
        self.sock.close()


def service_env(base: dict[str, str], sock: Path, watchdog_usec: int) -> dict[str, str]:
    env = dict(base)
    env["NOTIFY_SOCKET"] = str(sock)
    env["WATCHDOG_USEC"] = str(watchdog_usec)
    env.pop("WATCHDOG_PID", None)
    return env


def test_recorder_notifies_ready_feeds_the_watchdog_and_stops(
    tmp_path: Path, cli_env: dict[str, str]
) -> None:
    manager = NotifySocket(tmp_path / "notify")
    env = service_env(cli_env, manager.path, 300_000)
    proc = Proc(["record", "--vehicle", "wd", "--no-multicast-scouting", "-l",
                 f"tcp/127.0.0.1:{free_port()}"], tmp_path, env)  # fmt: skip
    try:
        seen = manager.collect(20, until="READY=1")
        assert any("READY=1" in m for m in seen), proc.stderr
        manager.collect(1.0)
        beats = [t for t, m in manager.messages if m == "WATCHDOG=1"]
        # a third of 300 ms: about 10 in a second, from the drain loop
        assert len(beats) >= 5, manager.messages
        assert max(b - a for a, b in itertools.pairwise(beats)) < 0.3
        proc.proc.send_signal(signal.SIGTERM)
        manager.collect(10, until="STOPPING=1")
        assert proc.wait(20) == 0
        assert any("STOPPING=1" in m for _, m in manager.messages)
    finally:
        proc.close()
        manager.close()


def test_router_notifies_and_feeds_the_watchdog(tmp_path: Path, cli_env: dict[str, str]) -> None:
    manager = NotifySocket(tmp_path / "notify")
    env = service_env(cli_env, manager.path, 1_500_000)
    proc = Proc(["router", "-l", f"tcp/127.0.0.1:{free_port()}", "--no-multicast-scouting"],
                tmp_path, env)  # fmt: skip
    try:
        assert any("READY=1" in m for m in manager.collect(20, until="READY=1")), proc.stderr
        manager.collect(1.5)
        assert sum(m == "WATCHDOG=1" for _, m in manager.messages) >= 2
        assert proc.stop(signal.SIGTERM) == 0
    finally:
        proc.close()
        manager.close()


def test_collector_notifies_and_feeds_the_watchdog(tmp_path: Path, cli_env: dict[str, str]) -> None:
    manager = NotifySocket(tmp_path / "notify")
    env = service_env(cli_env, manager.path, 1_500_000)
    proc = Proc(["collect", str(tmp_path / "archive"), "-l", f"tcp/127.0.0.1:{free_port()}",
                 "--no-multicast-scouting"], tmp_path, env)  # fmt: skip
    try:
        assert any("READY=1" in m for m in manager.collect(20, until="READY=1")), proc.stderr
        manager.collect(1.5)
        assert sum(m == "WATCHDOG=1" for _, m in manager.messages) >= 2
        assert proc.stop(signal.SIGTERM) == 0
        assert any("STOPPING=1" in m for m in manager.collect(2, until="STOPPING=1"))
    finally:
        proc.close()
        manager.close()


def test_the_watchdog_is_fed_from_the_drain_loop(tmp_path: Path) -> None:
    """A timer thread would keep a hung recorder alive: the kicks come from the drain loop."""
    kicks: list[str] = []
    options = ServiceOptions(
        vehicle="wdloop",
        zenoh=SessionOptions(listen=(f"tcp/127.0.0.1:{free_port()}",), multicast_scouting=False),
        cwd=tmp_path,
        freeze_gc=False,
        watchdog=lambda now: kicks.append(threading.current_thread().name),
    )
    service = RecorderService(LoggerConfig.default("pLogger"), options)
    runner = threading.Thread(target=service.run, name="drain-loop")
    runner.start()
    try:
        assert service.ready.wait(20)
        time.sleep(2.5)  # idle: the loop sleeps, but wakes at least once a second
    finally:
        service.stop()
        runner.join(20)
    assert len(kicks) >= 3
    assert set(kicks) == {"drain-loop"}


def test_watchdog_timing_and_pid() -> None:
    sent: list[str] = []

    class Recording(Notifier):
        def send(self, *fields: str) -> bool:
            sent.extend(fields)
            return True

    notifier = Recording({"NOTIFY_SOCKET": "/run/x"})
    dog = Watchdog(notifier, {"WATCHDOG_USEC": "3000000", "WATCHDOG_PID": str(os.getpid())})
    assert dog.interval == 3.0
    for now in (0.0, 0.5, 0.99, 1.0, 1.5, 2.0, 2.1):
        dog.kick(now)
    assert sent == ["WATCHDOG=1"] * 3
    other = Watchdog(notifier, {"WATCHDOG_USEC": "3000000", "WATCHDOG_PID": "1"})
    assert not other.enabled
    assert not Watchdog(Notifier({}), {"WATCHDOG_USEC": "3000000"}).enabled


def test_notifier_without_a_manager_does_nothing() -> None:
    assert Notifier({}).ready() is False
    assert Notifier({"NOTIFY_SOCKET": "relative"}).ready() is False


def test_notifier_abstract_socket() -> None:
    name = f"fleetlog-test-{os.getpid()}"
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    sock.bind("\0" + name)
    sock.settimeout(2)
    notifier = Notifier({"NOTIFY_SOCKET": "@" + name})
    try:
        assert notifier.ready("hi")
        assert sock.recv(100) == b"READY=1\nSTATUS=hi"
    finally:
        notifier.close()
        sock.close()
