"""The bridge process: one MOOS client, one Zenoh session, the forwarding rules between them.

The MOOS side runs on an asyncio event loop (:class:`~fleetlog.transport.moos_client.MoosClient`):
the DB's mail is forwarded to Zenoh as each packet arrives. The Zenoh side's samples arrive
in a receiving thread (:class:`~fleetlog.transport.bridging.RemoteSubscriber`), are decoded
there and handed to the loop in batches; when the MOOSDB cannot take more, that thread waits,
its FIFO fills and Zenoh pushes back on the (BLOCK) publishers instead of dropping.

Both sides reconnect by themselves: the MOOS client retries every second while the DB is
down, restarting or unreachable, and re-registers; Zenoh re-opens its links, which the
bridge follows through transport events. Every change is reported on the terminal and on
MOOS_DEBUG (on whichever side is up), and what could not be forwarded meanwhile is counted.
"""

from __future__ import annotations

import asyncio
import contextlib
import gc
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from fleetlog.bridge.forward import BridgeStats, Forwarder
from fleetlog.bridge.intake import Intake
from fleetlog.bridge.status import status_text
from fleetlog.errors import FleetlogError, TransportError
from fleetlog.moos.bridge_config import BRIDGE_APP, DEFAULT_COMMUNITY, BridgeConfig
from fleetlog.moos.patterns import glob_to_chunk, reduce_chunks
from fleetlog.moos.protocol import DEFAULT_MAX_PACKET, MESSAGE_OVERHEAD, Message
from fleetlog.moos.requests import Welcome
from fleetlog.storage.procinfo import ProcessMonitor
from fleetlog.transport.bridging import (
    ExactPublisher,
    LinkWatch,
    RemoteSubscriber,
    sample_to_message,
)
from fleetlog.transport.moos_client import MoosClient, MoosRefusedError
from fleetlog.transport.session import SessionOptions, open_session
from fleetlog.wire.keys import vehicle_chunk

__all__ = ["BridgeOptions", "BridgeService"]

#: seconds between the bridge's status posts (CMOOSApp's period)
STATUS_INTERVAL = 2.0
#: while the MOOSDB stays away, the wait is reported again this often (seconds)
RETRY_REPORT_INTERVAL = 30.0


@dataclass
class BridgeOptions:
    """How the bridge runs (beyond the mission's configuration).

    Attributes:
        vehicle: the vehicle (community) whose keys are bridged; None: the mission's
            ``Community``, else the MOOSDB's.
        root: the key root.
        zenoh: the Zenoh session options.
        name: the bridge's MOOS client name.
        max_packet: the largest MOOS packet accepted (and message posted), in bytes.
        retry: seconds between attempts to reach the MOOSDB.
        wait_first: keep retrying when the MOOSDB is not up at the start (False: fail).
        freeze_gc: once started, move the start-up objects out of the cyclic GC's reach
            (``gc.freeze``), as the recorder does: a full collection then does not walk
            them in the middle of forwarding. Process-wide: leave it off when embedding.
    """

    vehicle: str | None = None
    root: str = "fleet"
    zenoh: SessionOptions = field(default_factory=SessionOptions)
    name: str = BRIDGE_APP
    max_packet: int = DEFAULT_MAX_PACKET
    retry: float = 1.0
    wait_first: bool = True
    freeze_gc: bool = True


class BridgeService:
    """Runs the bridge until :meth:`stop`.

    Args:
        config: where the MOOSDB is and what crosses.
        options: how the process runs.
        on_say: receives each line the bridge reports (the CLI prints them on stderr).
    """

    def __init__(
        self,
        config: BridgeConfig,
        options: BridgeOptions,
        on_say: Callable[[str], None] = lambda text: None,
    ) -> None:
        self.config = config
        self.options = options
        self._on_say = on_say
        self.forwarder: Forwarder | None = None
        self.vehicle: str | None = options.vehicle or config.community
        self.ready = threading.Event()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stop: asyncio.Event | None = None
        self._client: MoosClient | None = None
        self._session: Any = None
        self._publisher: ExactPublisher | None = None
        self._rx: RemoteSubscriber | None = None
        self._links: LinkWatch | None = None
        #: set once the bridge stops: the receiving thread stops waiting for room
        self._stopping = threading.Event()
        self._fatal: FleetlogError | None = None
        self._monitor = ProcessMonitor()
        self._started = time.time()
        self._moos_down_since: float | None = None
        self._moos_ever_up = False
        self._unforwarded_at_loss = 0
        self._retry_said = -1e300
        self._zenoh_down_since: float | None = None
        self._zenoh_ever_up = False
        self._unforwarded_zenoh_at_loss = 0
        #: what the bridge last said while the MOOSDB is away (repeated when Zenoh links)
        self._waiting = ""

    # ---------------------------------------------------------------------------------------
    # Control

    def stop(self) -> None:
        """Ask the bridge to finish (safe from a signal handler or another thread)."""
        self._stopping.set()
        loop, stop = self._loop, self._stop
        if loop is not None and stop is not None:
            with contextlib.suppress(RuntimeError):
                loop.call_soon_threadsafe(stop.set)

    @property
    def stats(self) -> BridgeStats:
        """The counters so far."""
        return self.forwarder.stats if self.forwarder is not None else BridgeStats()

    def say(self, text: str) -> None:
        """Report a line: terminal, and MOOS_DEBUG on whichever side is up."""
        if self.forwarder is not None:
            self.forwarder.say(text)
        else:
            self._on_say(text)

    # ---------------------------------------------------------------------------------------
    # Running

    def run(self) -> BridgeStats:
        """Bridge until stopped; return the final counters.

        Raises:
            TransportError: Zenoh could not be opened, or the MOOSDB refused the bridge's
                name (another client of that name is connected).
        """
        self._session = open_session(self.options.zenoh)
        try:
            asyncio.run(self._main())
        finally:
            self._close_zenoh()
        if self._fatal is not None:
            raise self._fatal
        return self.stats

    async def _main(self) -> None:
        self._loop = asyncio.get_running_loop()
        self._stop = asyncio.Event()
        if self._stopping.is_set():
            return
        cfg = self.config
        client = MoosClient(
            self.options.name,
            cfg.host,
            cfg.port,
            on_mail=self._mail,
            max_packet=self.options.max_packet,
        )
        self._client = client
        for pattern in ("*",) if "*" in cfg.to_zenoh else cfg.to_zenoh:
            client.subscribe_wildcard(pattern)
        if self.vehicle is not None:
            # Known already: Zenoh hears at once that the bridge waits for its MOOSDB.
            self._start_zenoh(self.vehicle)
        keeper = asyncio.create_task(
            client.maintain(self._moos_up, self._moos_down, self._moos_retry, self.options.retry)
        )
        ticker = asyncio.create_task(self._ticker())
        if self.options.freeze_gc:
            gc.collect()
            gc.freeze()
        try:
            await self._stop.wait()
        finally:
            self._stopping.set()
            client.close()
            for task in (keeper, ticker):
                task.cancel()
                with contextlib.suppress(asyncio.CancelledError):
                    await task
            # Posts queued by the last batches reach the socket before it closes.
            await asyncio.sleep(0)

    def _fail(self, error: FleetlogError) -> None:
        self._fatal = error
        if self._stop is not None:
            self._stop.set()

    # ---------------------------------------------------------------------------------------
    # The MOOS side

    def _moos_up(self, welcome: Welcome) -> None:
        client = self._client
        assert client is not None
        where = f"{client.host}:{client.port}"
        if self.forwarder is None:
            try:
                self._start_zenoh(welcome.community or DEFAULT_COMMUNITY)
            except FleetlogError as err:
                self._fail(err)
                return
        forwarder = self.forwarder
        assert forwarder is not None
        forwarder.moos_connected()
        self._moos_ever_up = True
        self._retry_said = -1e300
        self._waiting = ""
        if self._moos_down_since is None:
            forwarder.say(f"connected to the MOOSDB at {where} (community {welcome.community})")
        else:
            away = time.monotonic() - self._moos_down_since
            lost = forwarder.stats.unforwarded_to_moos - self._unforwarded_at_loss
            forwarder.say(
                f"reconnected to the MOOSDB at {where} after {away:.1f} s; {lost} samples "
                "from Zenoh could not be posted meanwhile"
            )
        self._moos_down_since = None
        if welcome.community != self.vehicle:
            forwarder.say(
                f"the MOOSDB's community is {welcome.community!r}, the bridge's vehicle is "
                f"{self.vehicle!r}: bridging the keys of {self.vehicle!r}"
            )
        self.ready.set()

    def _moos_down(self, reason: str) -> None:
        self._moos_down_since = time.monotonic()
        forwarder = self.forwarder
        if forwarder is None:
            return
        forwarder.moos_lost()
        self._unforwarded_at_loss = forwarder.stats.unforwarded_to_moos
        client = self._client
        where = f"{client.host}:{client.port}" if client else "?"
        forwarder.say(f"lost the MOOSDB at {where} ({reason}); reconnecting")

    def _moos_retry(self, error: TransportError) -> None:
        client = self._client
        reason = str(error)
        if isinstance(error, MoosRefusedError) and not self._moos_ever_up:
            self._fail(MoosRefusedError(f"{reason}; is another bridge running?"))
            return
        if not self._moos_ever_up and not self.options.wait_first:
            self._fail(error)
            return
        where = f"{client.host}:{client.port}" if client else "?"
        self._waiting = f"waiting for the MOOSDB at {where}: {reason}"
        now = time.monotonic()
        if now - self._retry_said >= RETRY_REPORT_INTERVAL:
            self._retry_said = now
            self.say(self._waiting)

    def _mail(self, messages: list[Message]) -> None:
        forwarder = self.forwarder
        if forwarder is not None:
            forwarder.from_moos(messages)

    def _post(self, messages: list[Message]) -> bool:
        client = self._client
        return client is not None and client.send(messages)

    def _writable(self) -> threading.Event | None:
        return self._client.writable if self._client is not None else None

    def _subscribe(self, name: str) -> None:
        if self._client is not None:
            self._client.subscribe(name)

    # ---------------------------------------------------------------------------------------
    # The Zenoh side

    def _start_zenoh(self, vehicle: str) -> None:
        """Set up publishing and subscribing once the vehicle is known.

        Raises:
            TransportError: a declaration failed.
        """
        self.vehicle = vehicle
        opts = self.options
        publisher = ExactPublisher(self._session, opts.root, vehicle, opts.name)
        self._publisher = publisher
        forwarder = Forwarder(
            name=opts.name,
            vehicle=vehicle,
            to_zenoh=self.config.to_zenoh,
            from_zenoh=self.config.from_zenoh,
            publish=publisher.put_message,
            post=self._post,
            subscribe=self._subscribe,
            clock=time.time,
            max_post=max(opts.max_packet - 9, MESSAGE_OVERHEAD),
            on_say=self._on_say,
        )
        forwarder.zenoh_up = False
        self.forwarder = forwarder
        loop = self._loop
        assert loop is not None

        def links(count: int) -> None:
            with contextlib.suppress(RuntimeError):
                loop.call_soon_threadsafe(self._links_changed, count)

        self._links = LinkWatch(self._session, links)
        forwarder.zenoh_up = self._links.count > 0
        self._zenoh_ever_up = forwarder.zenoh_up
        if not forwarder.zenoh_up:
            self._zenoh_down_since = time.monotonic()
        if self.config.from_zenoh:
            prefix = f"{opts.root}/{vehicle_chunk(vehicle)}/var/"
            chunks = reduce_chunks(glob_to_chunk(p) for p in self.config.from_zenoh)
            chunk = chunks[0] if len(chunks) == 1 else "*"
            names: dict[str, str | None] = {}
            source = opts.name

            intake = Intake(loop, forwarder.from_zenoh, self._writable, self._stopping)

            def samples(batch: list[Any]) -> None:
                now = time.time()
                intake.put([sample_to_message(s, prefix, names, now, source) for s in batch])

            self._rx = RemoteSubscriber(self._session, prefix + chunk, samples)

    def _links_changed(self, count: int) -> None:
        forwarder = self.forwarder
        if forwarder is None:
            return
        up = count > 0
        if up == forwarder.zenoh_up:
            return
        forwarder.zenoh_up = up
        stats = forwarder.stats
        if not up:
            stats.zenoh_losses += 1
            self._zenoh_down_since = time.monotonic()
            self._unforwarded_zenoh_at_loss = stats.unforwarded_to_zenoh
            forwarder.say(
                "lost every Zenoh link (router or peers): messages from the MOOSDB are "
                "counted as not forwarded until it comes back"
            )
            return
        since = self._zenoh_down_since
        self._zenoh_down_since = None
        if self._waiting and not forwarder.moos_up:
            forwarder.own("MOOS_DEBUG", self._waiting)  # Zenoh could not hear it before
        if not self._zenoh_ever_up:
            self._zenoh_ever_up = True
            if stats.unforwarded_to_zenoh:
                forwarder.say(
                    f"Zenoh linked: {stats.unforwarded_to_zenoh} messages from the MOOSDB "
                    "found no Zenoh link before"
                )
            return
        away = time.monotonic() - since if since is not None else 0.0
        lost = stats.unforwarded_to_zenoh - self._unforwarded_zenoh_at_loss
        forwarder.say(
            f"Zenoh link back after {away:.1f} s; {lost} messages from the MOOSDB could not "
            "be forwarded meanwhile"
        )

    def _close_zenoh(self) -> None:
        if self._rx is not None:
            self._rx.close()
            self._rx = None
        if self._links is not None:
            self._links.close()
            self._links = None
        if self._publisher is not None:
            self._publisher.close()
            self._publisher = None
        if self._session is not None:
            with contextlib.suppress(Exception):
                self._session.close()
            self._session = None

    # ---------------------------------------------------------------------------------------
    # Timers

    async def _ticker(self) -> None:
        next_status = time.monotonic() + STATUS_INTERVAL
        while True:
            await asyncio.sleep(1.0)
            forwarder = self.forwarder
            if forwarder is None:
                continue
            forwarder.tick()
            if self._client is not None:
                forwarder.stats.oversized = self._client.oversized_packets
            rx = self._rx
            if rx is not None and rx.errors != forwarder.stats.rx_errors:
                forwarder.stats.rx_errors = rx.errors
                forwarder.say(f"{rx.errors} samples from Zenoh lost to an error: {rx.last_error}")
            if time.monotonic() >= next_status:
                next_status += STATUS_INTERVAL
                forwarder.own(self.options.name.upper() + "_STATUS", self.status_text())

    def status_text(self) -> str:
        """The bridge's ``<NAME>_STATUS``: CMOOSApp's fields, then its counters."""
        forwarder = self.forwarder
        client = self._client
        return status_text(
            name=self.options.name,
            vehicle=self.vehicle,
            uptime=time.time() - self._started,
            process=self._monitor.fields(),
            published=forwarder.published if forwarder is not None else (),
            subscribing=[s.var for s in client.subscriptions] if client else (),
            stats=self.stats,
        )
