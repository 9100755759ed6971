"""The demo's stand-ins for a vehicle's apps, and a shore-side watcher.

``python -m fleetlog.deploy.demoapp app VEHICLE`` publishes a vehicle's navigation and a few
other variables at 10 Hz, as iGPS, pNav and pHelm would, through the machine's Zenoh
configuration, until it is stopped. ``watch PATTERN SECONDS`` counts the samples per vehicle
it receives on ``<root>/PATTERN/var/**`` and prints them as JSON.
"""

from __future__ import annotations

import json
import math
import signal
import sys
import time
from collections import Counter

from fleetlog.transport.bus import declare_fifo_subscriber, wait_for_subscriber
from fleetlog.transport.publisher import MoosPublisher
from fleetlog.transport.session import SessionOptions, open_session
from fleetlog.wire.keys import parse_var_key, var_key

__all__ = ["main"]

ROOT = "fleet"


def app(vehicle: str) -> None:
    """Publish a vehicle's variables at 10 Hz until SIGTERM."""
    running = True

    def stop(signum: int, frame: object) -> None:
        nonlocal running
        running = False

    signal.signal(signal.SIGTERM, stop)
    signal.signal(signal.SIGINT, stop)
    session = open_session(SessionOptions())
    gps = MoosPublisher(session, ROOT, vehicle, "iGPS")
    helm = MoosPublisher(session, ROOT, vehicle, "pHelmIvP")
    try:
        wait_for_subscriber(session, var_key(ROOT, vehicle, "NAV_X"), 30)
        print(f"{vehicle}: publishing", flush=True)
        phase = sum(map(ord, vehicle)) % 360
        n = 0
        start = time.monotonic()
        while running:
            t = n / 10
            heading = (phase + 6 * t) % 360
            gps.publish("NAV_X", round(100 * math.cos(math.radians(heading)), 3))
            gps.publish("NAV_Y", round(100 * math.sin(math.radians(heading)), 3))
            gps.publish("NAV_HEADING", round(heading, 2))
            gps.publish("NAV_SPEED", 1.5)
            if n % 50 == 0:
                helm.publish("IVPHELM_STATE", "DRIVE" if n else "PARK")
                helm.publish("DEPLOY", "true")
            n += 1
            time.sleep(max(0.0, start + n / 10 - time.monotonic()))
    finally:
        helm.close()
        gps.close()
        time.sleep(0.2)  # let the last samples leave before the session closes
        session.close()


def watch(pattern: str, seconds: float) -> None:
    """Count the samples per vehicle on ``<root>/PATTERN/var/**`` for ``seconds`` (or SIGTERM)."""
    stopped = False

    def stop(signum: int, frame: object) -> None:
        nonlocal stopped
        stopped = True

    signal.signal(signal.SIGTERM, stop)
    session = open_session(SessionOptions())
    sub = declare_fifo_subscriber(session, f"{ROOT}/{pattern}/var/**")
    counts: Counter[str] = Counter()
    print("watching", flush=True)
    deadline = time.monotonic() + seconds
    try:
        while time.monotonic() < deadline and not stopped:
            sample = sub.try_recv()
            if sample is None:
                time.sleep(0.01)
                continue
            try:
                counts[parse_var_key(ROOT, str(sample.key_expr)).vehicle] += 1
            except Exception:  # a key that is not a variable's: not counted
                continue
    finally:
        sub.undeclare()
        session.close()
    print(json.dumps(dict(counts)), flush=True)


def main(argv: list[str] | None = None) -> None:
    """``app VEHICLE`` or ``watch PATTERN SECONDS``."""
    args = sys.argv[1:] if argv is None else argv
    if len(args) == 2 and args[0] == "app":
        app(args[1])
    elif len(args) == 3 and args[0] == "watch":
        watch(args[1], float(args[2]))
    else:
        print("usage: demoapp app VEHICLE | watch PATTERN SECONDS", file=sys.stderr)
        sys.exit(2)


if __name__ == "__main__":
    main()
