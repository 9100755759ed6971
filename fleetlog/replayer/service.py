"""A replay process: inputs opened, a Zenoh session, the player, its control and its status.

The player runs in the calling thread. Zenoh's callback threads deliver PLAYBACK_CHOKE
heartbeats and control queries to it; the status is published four times a second from the
player's idle time. At the end, the service makes sure the recorders got everything before
the session closes (a short-lived publisher loses its tail otherwise).
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Sequence
from concurrent.futures import TimeoutError as FutureTimeout
from dataclasses import dataclass, field
from pathlib import Path

from fleetlog.errors import ReplayError
from fleetlog.replayer.clock import Clock, RealClock
from fleetlog.replayer.control import describe, parse_request
from fleetlog.replayer.engine import Player
from fleetlog.replayer.inputs import RemoteSpec, ReplayInput, open_inputs
from fleetlog.replayer.options import PlayOptions
from fleetlog.replayer.output import Sender
from fleetlog.replayer.remote import default_cache, fetch_remote
from fleetlog.replayer.report import Summary
from fleetlog.shore.discovery import QUIET, Discovery
from fleetlog.storage.readers import Errors
from fleetlog.transport.replay import ReplayLink
from fleetlog.transport.session import SessionOptions, open_session
from fleetlog.wire.control import Outcome
from fleetlog.wire.message import Kind, MoosMessage
from fleetlog.wire.query import RECORDER_TOKEN

__all__ = ["ReplayConfig", "ReplayService"]

#: Seconds a control query waits for the player to apply its command.
COMMAND_TIMEOUT = 2.0
#: The interpreter's thread switch interval while playing (Python's default is 5 ms).
SWITCH_INTERVAL = 0.001


@dataclass
class ReplayConfig:
    """Everything a replay process needs.

    Attributes:
        inputs: alogs and session directories.
        vehicles: ``--as``: none, one for every input, or one per input.
        options: how to play; ``start``/``stop`` are seconds from the origin.
        root: the key root.
        zenoh: how to open the session.
        wait: seconds to wait for every vehicle's variables to have a subscriber before
            playing (a put before that goes nowhere).
        confirm: seconds to wait, at the end, for each recorder to confirm receipt.
        errors: the readers' policy for malformed lines (``"raise"`` or ``"skip"``).
        cache: where remote inputs (``V:latest``, ``V:SESSION``) are fetched to; None for
            ``~/.cache/fleetlog/replay``.
        announce: told, in a sentence, what is being fetched.
        into_live: publish into the keys of a vehicle whose recorder is running now;
            without it such a replay is refused (``--prefix`` keeps replays apart).
    """

    inputs: Sequence[str]
    vehicles: Sequence[str] = ()
    options: PlayOptions = field(default_factory=PlayOptions)
    root: str = "fleet"
    zenoh: SessionOptions = field(default_factory=SessionOptions)
    wait: float = 1.0
    confirm: float = 5.0
    errors: Errors = "raise"
    cache: Path | None = None
    announce: Callable[[str], None] | None = None
    into_live: bool = False


class ReplayService:
    """Runs one replay over Zenoh; see the module docstring.

    Args:
        config: what to replay and how.
        clock: the clock to pace by (the real one by default).

    Attributes:
        inputs: the opened inputs, after :meth:`open`.
        player: the player, after :meth:`open`.
        missing: vehicles that had no subscriber when playback began.
        unconfirmed: vehicles whose recorder did not confirm receipt at the end.
    """

    def __init__(self, config: ReplayConfig, clock: Clock | None = None) -> None:
        self.config = config
        self.clock = clock or RealClock()
        self.inputs: list[ReplayInput] = []
        self.player: Player | None = None
        self.missing: list[str] = []
        self.unconfirmed: list[str] = []
        self._link: ReplayLink | None = None

    def open_inputs(self) -> list[ReplayInput]:
        """Open the inputs (before any network I/O), once.

        Raises:
            ReplayError: no inputs, a missing input, an unknown vehicle.
            StorageError: an input cannot be read.
            FormatError: an input's banner is garbled (names the file and line).
            QueryError: a remote input could not be fetched.
            TransportError: (remote inputs) the Zenoh session cannot be opened.
        """
        if not self.inputs:
            config = self.config
            self.inputs = open_inputs(
                config.inputs, config.vehicles, errors=config.errors, fetch=self._fetch
            )
        return self.inputs

    def _fetch(self, spec: RemoteSpec) -> Path:
        config = self.config
        cache = config.cache if config.cache is not None else default_cache()
        return fetch_remote(spec, config.zenoh, config.root, cache, config.announce)

    @property
    def origin(self) -> float:
        """The replay's origin: the earliest LOGSTART of the opened inputs."""
        return min(item.logstart for item in self.open_inputs())

    def open(self, options: PlayOptions | None = None) -> Player:
        """Open the inputs and build the player.

        Args:
            options: how to play, instead of the configuration's (for options that depend
                on the inputs, such as an absolute ``--from``).

        Raises:
            ReplayError: as :meth:`open_inputs`, or bad options.
            StorageError: as :meth:`open_inputs`.
            FormatError: as :meth:`open_inputs`.
        """
        inputs = self.open_inputs()
        try:
            self.player = Player(
                inputs,
                self._publish,
                self.clock,
                options or self.config.options,
                self._prepare,
                self._sender,
            )
        except BaseException:
            self.close_inputs()
            raise
        return self.player

    def _publish(self, vehicle: str, message: MoosMessage) -> None:
        assert self._link is not None
        self._link.publish(vehicle, message)

    def _sender(
        self, vehicle: str, name: str, kind: Kind, source: str, aux: str, community: str
    ) -> Sender:
        assert self._link is not None
        return self._link.sender(vehicle, name, kind, source, aux, community)

    def _prepare(self, vehicle: str, name: str, kind: Kind) -> None:
        assert self._link is not None
        self._link.prepare(vehicle, name, kind)

    def close_inputs(self) -> None:
        """Close the input files."""
        for item in self.inputs:
            item.close()

    def run(self, on_ready: Callable[[Player], None] | None = None) -> Summary:
        """Open the session, play, confirm delivery; return the summary.

        Args:
            on_ready: called with the player just before playback starts (to attach a
                keyboard or a display).

        Raises:
            ReplayError: a vehicle replayed into is live now, without ``into_live``.
            TransportError: the session cannot be opened or used.
            StorageError: an input cannot be read.
            FormatError: an input has a malformed line (names the file and line).
        """
        player = self.player or self.open()
        try:
            session = open_session(self.config.zenoh)
            try:
                # Watching the fleet starts now, so the wait for subscribers counts for it.
                live = None if self.config.into_live else Discovery(session, self.config.root)
                try:
                    self._link = ReplayLink(session, self.config.root, player.vehicles)
                    try:
                        return self._play(player, self._link, on_ready, live)
                    finally:
                        self._link.close()
                finally:
                    if live is not None:
                        live.close()
            finally:
                session.close()
        finally:
            self.close_inputs()

    def _refuse_live(self, discovery: Discovery, vehicles: Sequence[str]) -> None:
        """Refuse to publish into the keys of a vehicle whose recorder runs now.

        Its live log would take the replayed entries for its own (and, through a bridge,
        its MOOSDB too). The fleet is watched as every shore command watches it (until no
        new vehicle appeared for a moment, at least 0.3 s), so a vehicle whose token
        arrives a moment late is still seen.

        Raises:
            ReplayError: such a vehicle is up.
        """
        view = discovery.wait(wait=max(self.config.wait, QUIET))
        live = [v for v in dict.fromkeys(vehicles) if RECORDER_TOKEN in view.vehicles.get(v, ())]
        if live:
            names = ", ".join(live)
            example = live[0]
            msg = (
                f"vehicle {names} {'is' if len(live) == 1 else 'are'} live now (a recorder"
                f" records {'it' if len(live) == 1 else 'them'}): the replay would land in its"
                f" live log. Replay beside it with --prefix (--prefix sim_ publishes as"
                f" sim_{example}) or another --root, or give --into-live to replay into it (to"
                " have that recorder record the replay)"
            )
            raise ReplayError(msg)

    def _play(
        self,
        player: Player,
        link: ReplayLink,
        on_ready: Callable[[Player], None] | None,
        live: Discovery | None,
    ) -> Summary:
        self.missing = link.wait_for_subscribers(self.config.wait)
        if live is not None:
            self._refuse_live(live, player.vehicles)
        link.on_choke(player.heartbeat)
        link.serve(self._control, lambda: player.status().to_dict())
        player.idle_hooks.append(lambda: link.publish_status(player.status().to_dict()))
        # The player spins before each entry, holding the GIL; a short switch interval lets
        # the callback and status threads in within a millisecond instead of five.
        interval = sys.getswitchinterval()
        sys.setswitchinterval(SWITCH_INTERVAL)
        try:
            if on_ready is not None:
                on_ready(player)
            link.publish_status(player.status().to_dict())
            summary = player.run()
        finally:
            sys.setswitchinterval(interval)
        link.publish_status(player.status().to_dict())
        self.unconfirmed = link.confirm_delivery(self.config.confirm)
        return summary

    def _control(self, payload: bytes | None, parameters: str) -> bytes:
        """Run one control request (docs/wire.md, "Control"); return the reply's JSON.

        Raises:
            FormatError: the request is malformed (answered with an error reply).
        """
        cmd, command = parse_request(payload, parameters)
        player = self.player
        if player is None:
            return Outcome.refused(cmd, "the replay has not started").reply()
        if command is None:
            doc = player.status().to_dict()
            return Outcome.done(cmd, describe(cmd, doc), **doc).reply()
        future = player.submit(command)
        try:
            doc = future.result(COMMAND_TIMEOUT).to_dict()
        except FutureTimeout:
            return Outcome.refused(cmd, "the player did not take the command in time").reply()
        if self._link is not None:
            self._link.publish_status(doc)  # a UI following the status sees the change now
        return Outcome.done(cmd, describe(cmd, doc), **doc).reply()
