"""A log server that takes over when the vehicle's recorder stops: ``fleetlog serve --standby``.

A recorder serves its own log root while it runs, and stops serving when it stops: a mission
that ends by stopping the recorder would leave its last session out of reach, and a
``fetch --follow`` of it unable to finish. So a vehicle runs ``fleetlog serve LOGROOT
--standby`` beside its recorder (its own service, started with the vehicle): it watches the
recorder's liveliness token and serves the log root exactly while no recorder of the vehicle
serves it. When the recorder stops (or dies), its token vanishes within milliseconds and the
standby declares its queryables and its ``serve`` token; a fetch in flight rides out the gap
with its ordinary retries. When a recorder comes back and answers ``latest`` itself, the
standby withdraws again, so the shore never hears two answers for the vehicle.

A recorder started with ``--no-serve`` holds the token but does not serve: the standby asks
``latest`` and keeps serving while no recorder answers it.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable

from fleetlog.errors import FleetlogError, FormatError
from fleetlog.query.server import LogServer
from fleetlog.storage.catalog import LogCatalog
from fleetlog.transport.queries import ZenohSession, session_zid, start_query
from fleetlog.transport.services import TokenWatch
from fleetlog.wire.keys import service_key
from fleetlog.wire.query import LATEST, RECORDER_TOKEN, LatestInfo

__all__ = ["Standby"]

_log = logging.getLogger("fleetlog.query.standby")
#: how long the standby waits for a recorder's token before it first decides to serve
SETTLE = 0.5
#: how often a recorder that holds its token but does not answer ``latest`` is asked again
RECHECK = 2.0
#: right after a recorder's token appears it is asked this often (its log server starts a
#: moment after its token), for :data:`EAGER` seconds
EAGER_EVERY = 0.1
EAGER = 5.0


class Standby:
    """Serves a log root whenever no recorder of its vehicle serves it.

    Args:
        session: an open Zenoh session (not closed here).
        catalog: the log root (the recorder's).
        root: the key root.
        vehicle: the vehicle.
        on_change: told ``(serving, why)`` each time the standby starts or stops serving.
        settle: seconds to wait for a recorder's token at start before serving.
    """

    def __init__(
        self,
        session: ZenohSession,
        catalog: LogCatalog,
        *,
        root: str,
        vehicle: str,
        on_change: Callable[[bool, str], None] | None = None,
        settle: float = SETTLE,
    ) -> None:
        self.session = session
        self.catalog = catalog
        self.root = root
        self.vehicle = vehicle
        self.settle = settle
        self._on_change = on_change or (lambda serving, why: None)
        self._zid = session_zid(session)
        self._server: LogServer | None = None

    @property
    def serving(self) -> bool:
        """Whether this process serves the log root now."""
        return self._server is not None

    def _recorder_serves(self) -> bool:
        """Whether a recorder (another process) answers the vehicle's ``latest`` now."""
        key = service_key(self.root, self.vehicle, LATEST)
        try:
            for reply in start_query(self.session, key, timeout=2.0):
                if reply.error is not None or reply.replier == self._zid:
                    continue
                try:
                    if LatestInfo.from_json(reply.payload).recorder is not None:
                        return True
                except FormatError:
                    continue
        except FleetlogError as err:
            _log.info("asking the recorder's latest failed: %s", err)
        return False

    def _serve(self, why: str) -> None:
        if self._server is None:
            server = LogServer(
                self.session, self.catalog, root=self.root, vehicle=self.vehicle, announce=True
            )
            self._server = server.start()
            self._on_change(True, why)

    def _withdraw(self, why: str) -> None:
        if self._server is not None:
            self._server.close()
            self._server = None
            self._on_change(False, why)

    def run(self, stop: threading.Event) -> None:
        """Serve or stand by, as the recorder comes and goes, until ``stop`` is set.

        Raises:
            TransportError: the token subscription or a queryable could not be declared.
        """
        watch = TokenWatch(self.session, [service_key(self.root, self.vehicle, RECORDER_TOKEN)])
        recorder_up = False
        started = time.monotonic()
        next_check = 0.0
        eager_until = 0.0
        try:
            while not stop.is_set():
                change = watch.next_change(EAGER_EVERY)
                while change is not None:
                    recorder_up = change[1]
                    next_check = 0.0
                    eager_until = time.monotonic() + EAGER
                    change = watch.next_change(0)
                now = time.monotonic()
                if not recorder_up:
                    if now - started >= self.settle:
                        self._serve("no recorder of the vehicle is up")
                    continue
                if now < next_check:
                    continue
                next_check = now + (EAGER_EVERY if now < eager_until else RECHECK)
                if self._recorder_serves():
                    self._withdraw("the vehicle's recorder serves its logs")
                else:
                    self._serve("the vehicle's recorder does not serve its logs")
        finally:
            if self._server is not None:
                self._server.close()
                self._server = None
            watch.close()
