"""Finding vehicles and asking their services: liveliness and queries, ZError translated."""

from __future__ import annotations

import json
from typing import Any

import zenoh

from fleetlog.errors import FormatError, QueryError
from fleetlog.transport.session import translate_zerror
from fleetlog.wire.keys import fleet_service_selector, parse_service_key

__all__ = ["get_json", "get_replies", "live_vehicles"]


def live_vehicles(
    session: zenoh.Session,
    root: str,
    services: tuple[str, ...] = ("recorder",),
    timeout: float = 2.0,
) -> dict[str, set[str]]:
    """Return the vehicles whose liveliness tokens are up: ``{vehicle: {service, ...}}``.

    Args:
        session: an open session.
        root: the key root.
        services: which tokens count (``recorder``, ``serve``).
        timeout: how long to wait for the liveliness answers.
    """
    found: dict[str, set[str]] = {}
    for service in services:
        selector = fleet_service_selector(root, service)
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
        replies = session.get(
            selector,
            timeout=timeout,
            payload=payload,
            consolidation=zenoh.ConsolidationMode.NONE,
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
            out.append(json.loads(sample.payload.to_bytes()))
        except ValueError as err:
            msg = f"reply on {sample.key_expr} is not JSON: {err}"
            raise QueryError(msg) from err
    return out
