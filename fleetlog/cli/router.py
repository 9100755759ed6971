"""``fleetlog router``: a Zenoh router on zenoh-python, for sites without zenohd."""

from __future__ import annotations

import dataclasses
import os
import signal
import sys
import threading
import time
from pathlib import Path

from fleetlog.cli.app import app
from fleetlog.cli.options import Config, Connect, Listen, NoScouting, session_options
from fleetlog.cli.settings import say
from fleetlog.errors import TransportError, UsageError
from fleetlog.transport.notify import Notifier, Watchdog
from fleetlog.transport.router import Router
from fleetlog.transport.session import etc_dir

__all__ = ["router"]

#: the machine-wide router configuration ``fleetlog deploy`` installs
MACHINE_ROUTER = "router.json5"


def _router_config(config: Path | None) -> Path | None:
    """``-c FILE`` > ``ZENOH_CONFIG`` > the machine's router.json5 > Zenoh's defaults."""
    if config is not None:
        return config
    named = os.environ.get("ZENOH_CONFIG")
    if named:
        return Path(named)
    machine = etc_dir() / MACHINE_ROUTER
    return machine if machine.is_file() else None


@app.command()
def router(
    config: Config = None,
    listen: Listen = None,
    connect: Connect = None,
    no_multicast_scouting: NoScouting = False,
) -> None:
    """Run a Zenoh router, as zenohd does, from the same JSON5 configuration.

    Each vehicle runs one (its apps, bridge and recorder reach it on loopback) and the shore
    runs one; `fleetlog deploy init` writes their configurations (router.json5). Without -c it
    reads $ZENOH_CONFIG, else /etc/fleetlog/router.json5, else Zenoh's defaults (listening on
    tcp/[::]:7447). Under systemd (Type=notify) it reports ready and feeds the watchdog while
    the router answers. SIGTERM or Ctrl-C stop it.
    """
    chosen = _router_config(config)
    if chosen is not None and not chosen.is_file():
        msg = f"router configuration {chosen} does not exist"
        raise UsageError(msg)
    opts = session_options(None, connect, listen, chosen, no_multicast_scouting)
    opts = dataclasses.replace(opts, machine_config=False)
    say(f"router configuration: {chosen or 'none (Zenoh defaults)'}")
    stop = threading.Event()

    def on_signal(signum: int, frame: object) -> None:
        stop.set()
        signal.signal(signum, signal.SIG_DFL)

    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGTERM, on_signal)

    def event(line: str) -> None:
        print(f"fleetlog router: {line}", file=sys.stderr, flush=True)

    running = Router(opts, event)
    notifier = Notifier()
    watchdog = Watchdog(notifier)
    info = running.info
    acl = (
        f"access control on ({info.subjects} identities)"
        if info.access_control
        else "no access control"
    )
    print(
        f"fleetlog router: {info.zid} listening on {', '.join(info.listen)}"
        + (f", connecting to {', '.join(info.connect)}" if info.connect else "")
        + f"; {acl}",
        file=sys.stderr,
        flush=True,
    )
    notifier.ready(f"router {info.zid} on {', '.join(info.listen)}")
    failed = False
    try:
        last_status = 0.0
        while not stop.wait(0.5):
            if not running.alive():
                failed = True
                break
            watchdog.kick()
            now = time.monotonic()
            if now - last_status >= 10.0:
                last_status = now
                routers, others = running.neighbours()
                notifier.status(f"{routers} router(s), {others} peer(s)/client(s) connected")
    finally:
        notifier.stopping()
        running.close()
        notifier.close()
    if failed:
        msg = "the router stopped answering"
        raise TransportError(msg)
    print("fleetlog router: stopped", file=sys.stderr)
