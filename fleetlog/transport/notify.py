"""systemd's service notifications (``sd_notify``), written by hand: a datagram to a socket.

A unit with ``Type=notify`` gives the service ``NOTIFY_SOCKET`` (a path, or ``@name`` in the
abstract namespace); the service sends ``READY=1`` once it works, ``STATUS=...`` lines, and,
with ``WatchdogSec=``, ``WATCHDOG=1`` more often than ``WATCHDOG_USEC`` microseconds or
systemd kills and restarts it. Without ``NOTIFY_SOCKET`` (a terminal, a test) every call does
nothing. The protocol is a few lines of text on a ``SOCK_DGRAM`` Unix socket, so fleetlog
speaks it itself rather than add a dependency.
"""

from __future__ import annotations

import contextlib
import os
import socket
import time
from collections.abc import Mapping

__all__ = ["Notifier", "Watchdog"]


class Notifier:
    """Sends notifications to the service manager, if there is one.

    Args:
        environ: where to read ``NOTIFY_SOCKET`` (the process environment by default).
    """

    def __init__(self, environ: Mapping[str, str] | None = None) -> None:
        env = os.environ if environ is None else environ
        address = env.get("NOTIFY_SOCKET", "")
        self._address: str | bytes | None = None
        if address.startswith("@"):
            self._address = b"\0" + address[1:].encode()
        elif address.startswith("/"):
            self._address = address
        self._sock: socket.socket | None = None

    @property
    def enabled(self) -> bool:
        """Whether a service manager listens."""
        return self._address is not None

    def send(self, *fields: str) -> bool:
        """Send ``KEY=VALUE`` fields in one datagram; False if nobody listens or it failed."""
        if self._address is None:
            return False
        try:
            if self._sock is None:
                self._sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM | socket.SOCK_CLOEXEC)
            self._sock.sendto("\n".join(fields).encode("utf-8", "replace"), self._address)
        except OSError:
            return False  # a service manager that went away must not stop the service
        return True

    def ready(self, status: str = "") -> bool:
        """Tell the manager the service is up."""
        return self.send("READY=1", *([f"STATUS={status}"] if status else []))

    def status(self, text: str) -> bool:
        """Set the one-line status ``systemctl status`` shows."""
        return self.send(f"STATUS={text}")

    def stopping(self, status: str = "") -> bool:
        """Tell the manager the service is stopping on purpose."""
        return self.send("STOPPING=1", *([f"STATUS={status}"] if status else []))

    def close(self) -> None:
        """Close the socket."""
        if self._sock is not None:
            with contextlib.suppress(OSError):
                self._sock.close()
            self._sock = None


class Watchdog:
    """Feeds systemd's watchdog from a loop that must keep running.

    ``kick(now)`` costs one comparison unless a keep-alive is due: call it from the loop
    whose hanging should get the service restarted (the recorder's drain loop), never from a
    timer thread of its own, which would keep a hung service alive.

    Args:
        notifier: where to send.
        environ: where to read ``WATCHDOG_USEC`` and ``WATCHDOG_PID``.
    """

    def __init__(self, notifier: Notifier, environ: Mapping[str, str] | None = None) -> None:
        env = os.environ if environ is None else environ
        self._notifier = notifier
        self.interval: float | None = None
        usec = env.get("WATCHDOG_USEC", "")
        pid = env.get("WATCHDOG_PID", "")
        ours = not pid or (pid.isdigit() and int(pid) == os.getpid())
        if notifier.enabled and usec.isdigit() and int(usec) > 0 and ours:
            self.interval = int(usec) / 1e6
        # Keep-alives at a third of the interval: two may be late before systemd acts.
        self._every = self.interval / 3 if self.interval else float("inf")
        self._next = 0.0

    @property
    def enabled(self) -> bool:
        """Whether systemd expects keep-alives."""
        return self.interval is not None

    def kick(self, now: float | None = None) -> None:
        """Send a keep-alive if one is due (``now``: ``time.monotonic()``)."""
        if now is None:
            now = time.monotonic()
        if now < self._next:
            return
        self._next = now + self._every
        if self.interval is not None:
            self._notifier.send("WATCHDOG=1")
