"""A vehicle whose router is down at boot records from its first second and joins later."""

from __future__ import annotations

import os
import time
from pathlib import Path

from deploy_support import OPS, SecureFleet, alog_text
from helpers import Proc, free_port

from fleetlog.api import Vehicle
from fleetlog.transport.session import SessionOptions


def wait_logged(root: Path, needle: str, timeout: float = 10.0) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if needle in alog_text(root):
            return True
        time.sleep(0.2)
    return False


def test_secured_recorder_records_before_its_router_and_joins_it(tmp_path: Path) -> None:
    env = dict(os.environ, TZ="UTC", NO_COLOR="1")
    secure = SecureFleet(tmp_path / "fleet", env, ("alpha",))
    try:
        started = time.monotonic()
        rec = secure.start_recorder("alpha", wait=False)
        rec.wait_for("recording vehicle 'alpha'", timeout=10)
        assert time.monotonic() - started < 5, "the recorder waited for its router"
        logs = secure.directory / "logs" / "alpha"
        assert wait_logged(logs, "PLOGGER_STATUS"), rec.stderr  # writing, router or not
        time.sleep(1.0)
        assert rec.proc.poll() is None, rec.stderr
        secure.start_router("shore")
        secure.start_router("alpha")
        assert "alpha" in secure.wait_vehicles(OPS, {"alpha"}, timeout=30), rec.stderr
        with (
            secure.session("vehicles/alpha") as app,
            Vehicle("alpha", session=app, source="iTest") as v,
        ):
            assert v.wait_for_subscriber("AFTER_ROUTER", 10)
            v.publish("AFTER_ROUTER", 1.0)
            assert v.confirm(10)
        assert wait_logged(logs, "AFTER_ROUTER")
        assert secure.stop("record:alpha") == 0
    finally:
        secure.close()


def test_client_mode_recorder_with_its_router_down(tmp_path: Path, cli_env: dict[str, str]) -> None:
    """The issue's case: `record -m client -e ROUTER` exited at once ("Unable to connect")."""
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    rec = Proc(
        ["record", "--vehicle", "boot", "-m", "client", "-e", endpoint, "--no-multicast-scouting"],
        tmp_path,
        cli_env,
    )
    router: Proc | None = None
    try:
        rec.wait_for("recording vehicle 'boot'", timeout=10)
        assert wait_logged(tmp_path, "PLOGGER_STATUS")
        router = Proc(["router", "-l", endpoint, "--no-multicast-scouting"], tmp_path, cli_env)
        router.wait_for("listening on")
        options = SessionOptions(mode="client", connect=(endpoint,), multicast_scouting=False)
        with Vehicle("boot", options=options, source="iTest") as v:
            assert v.wait_for_subscriber("JOINED", 15), rec.stderr
            v.publish("JOINED", "yes")
            assert v.confirm(10)
        assert wait_logged(tmp_path, "JOINED")
        assert rec.stop() == 0
    finally:
        rec.close()
        if router is not None:
            router.close()
