"""Finding vehicles and asking their services: liveliness and queries, ZError translated."""

from __future__ import annotations

import contextlib
import queue
from collections.abc import Sequence
from typing import Any

import zenoh

from fleetlog.errors import FormatError, QueryError
from fleetlog.transport.session import translate_zerror
from fleetlog.wire.json_fields import parse_json
from fleetlog.wire.keys import fleet_service_selector, parse_service_key, service_key

__all__ = [
    "TokenWatch",
    "get_json",
    "get_replies",
    "live_vehicles",
    "refusal_hint",
    "routers_connected",
]


class TokenWatch:
    """The liveliness tokens matching key expressions, as they come and go, with history.

    One subscriber per expression, each declared with history, so tokens declared before it
    arrive as well; :meth:`next_change` hands them over one at a time, and :meth:`neighbours`
    tells which Zenoh peers and routers the session is connected to right now (a newly
    connected peer may be about to deliver tokens). One subscriber per kind of token rather
    than one on ``@fleetlog/*``: a router's access control allows a subscription only on a
    key its rule includes, and each kind of token has a rule of its own.

    Args:
        session: an open session (not closed here).
        selectors: the tokens' key expressions.

    Raises:
        TransportError: Zenoh refused a subscription.
    """

    def __init__(self, session: zenoh.Session, selectors: Sequence[str]) -> None:
        self._session = session
        self._changes: queue.SimpleQueue[tuple[str, bool]] = queue.SimpleQueue()
        self._subs: list[Any] = []

        def receive(sample: zenoh.Sample) -> None:
            alive = sample.kind == zenoh.SampleKind.PUT
            self._changes.put((str(sample.key_expr), alive))

        try:
            for selector in selectors:
                with translate_zerror(f"liveliness subscription {selector!r}"):
                    liveliness = session.liveliness()
                    self._subs.append(
                        liveliness.declare_subscriber(selector, receive, history=True)
                    )
        except BaseException:
            self.close()
            raise

    def next_change(self, timeout: float) -> tuple[str, bool] | None:
        """Return the next ``(key, alive)`` change, waiting up to ``timeout``; None if none."""
        try:
            if timeout <= 0:
                return self._changes.get_nowait()
            return self._changes.get(timeout=timeout)
        except queue.Empty:
            return None

    def neighbours(self) -> frozenset[str]:
        """Return the Zenoh ids of the peers and routers connected now."""
        with translate_zerror("session info"):
            info = self._session.info
            return frozenset(str(z) for z in (*info.peers_zid(), *info.routers_zid()))

    def close(self) -> None:
        """Undeclare the subscribers (before the session closes: a live callback hangs it)."""
        for sub in self._subs:
            with contextlib.suppress(zenoh.ZError, RuntimeError):
                sub.undeclare()
        self._subs.clear()


def live_vehicles(
    session: zenoh.Session,
    root: str,
    services: tuple[str, ...] = ("recorder",),
    timeout: float = 2.0,
    vehicle: str | None = None,
) -> dict[str, set[str]]:
    """Return the vehicles whose liveliness tokens are up: ``{vehicle: {service, ...}}``.

    Args:
        session: an open session.
        root: the key root.
        services: which tokens count (``recorder``, ``serve``).
        timeout: how long to wait for the liveliness answers.
        vehicle: ask about this vehicle only.
    """
    found: dict[str, set[str]] = {}
    for service in services:
        if vehicle is None:
            selector = fleet_service_selector(root, service)
        else:
            selector = service_key(root, vehicle, service)
        with translate_zerror(f"liveliness query {selector!r}"):
            replies = session.liveliness().get(selector, timeout=timeout)
            for reply in replies:
                sample = reply.ok
                if sample is None:
                    continue
                try:
                    vehicle, parts = parse_service_key(root, str(sample.key_expr))
                except FormatError:
                    continue
                if parts == (service,):
                    found.setdefault(vehicle, set()).add(service)
    return found


def get_replies(
    session: zenoh.Session,
    selector: str,
    *,
    timeout: float = 5.0,
    payload: bytes | None = None,
) -> list[zenoh.Sample]:
    """Run a query and return its good samples.

    Raises:
        QueryError: a queryable answered with an error (its text is the message), or the
            query could not be sent.
    """
    samples: list[zenoh.Sample] = []
    errors: list[str] = []
    with translate_zerror(f"query {selector!r}"):
        # Status and control: ahead of any bulk transfer on the same link.
        replies = session.get(
            selector,
            timeout=timeout,
            payload=payload,
            consolidation=zenoh.ConsolidationMode.NONE,
            priority=zenoh.Priority.INTERACTIVE_HIGH,
        )
        for reply in replies:
            sample = reply.ok
            if sample is not None:
                samples.append(sample)
            elif reply.err is not None:
                errors.append(reply.err.payload.to_string())
    if errors and not samples:
        raise QueryError(errors[0])
    return samples


def get_json(session: zenoh.Session, selector: str, *, timeout: float = 5.0) -> list[Any]:
    """Run a query whose replies are JSON documents; return them decoded.

    Raises:
        QueryError: an error reply, or a reply that is not JSON.
    """
    out: list[Any] = []
    for sample in get_replies(session, selector, timeout=timeout):
        try:
            out.append(parse_json(sample.payload.to_bytes()))
        except ValueError as err:
            msg = f"reply on {sample.key_expr} is not JSON: {err}"
            raise QueryError(msg) from err
    return out


def routers_connected(session: zenoh.Session) -> int:
    """How many routers the session is connected to now (0 for a peer on its own)."""
    try:
        return len(session.info.routers_zid())
    except (zenoh.ZError, RuntimeError):
        return 0


def refusal_hint(session: zenoh.Session, action: str, key: str) -> str:
    """The clause that says a silence may be an access-control refusal, if a router is there.

    Zenoh's routers drop what access control refuses without a word, so "nothing answered"
    through a router may mean "not allowed": say which key and which action.
    """
    if not routers_connected(session):
        return ""
    return (
        f"; a router is connected, so its access control may have refused the {action} on"
        f" {key!r} (check that this machine's certificate has a role that may)"
    )
