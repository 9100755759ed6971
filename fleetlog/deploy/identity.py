"""This machine's fleet identity, and what the security profile lets it do.

Zenoh's routers drop a refused put without a word: a publisher cannot see the refusal on the
wire. A command that publishes (``fleetlog poke``) therefore asks first what the profile
grants the certificate it connects with, and refuses what the routers would drop.
"""

from __future__ import annotations

from pathlib import Path

from fleetlog.errors import FleetlogError, FormatError
from fleetlog.moos.patterns import name_to_chunk
from fleetlog.storage.files import read_small
from fleetlog.transport.certs import read_certificate
from fleetlog.transport.session import SessionOptions, summarize
from fleetlog.wire.access import Action, Role, grants_of
from fleetlog.wire.access_profile import Identity, parse_common_name

__all__ = ["publish_refusal", "this_identity"]


def this_identity(options: SessionOptions) -> Identity | None:
    """The fleet identity of the certificate these options connect with, if any."""
    try:
        path = summarize(options).tls_files.get("connect_certificate")
        if path is None:
            return None
        cert = read_certificate(read_small(Path(path), "certificate"), path)
        return parse_common_name(cert.common_name)
    except FleetlogError:
        return None  # no usable identity: the session's own open reports why


def publish_refusal(who: Identity, vehicle: str, name: str, replay_prefix: str = "") -> str | None:
    """Why the profile refuses ``who`` publishing variable ``name`` of ``vehicle``, or None.

    Args:
        who: the publishing identity.
        vehicle: the vehicle.
        name: the MOOS variable.
        replay_prefix: a replay host's prefix, if known (without it, a replay host's puts are
            left to the routers, which may grant replays into live vehicles).
    """
    try:
        key = f"var/{name_to_chunk(name)}"
    except FormatError:
        return None
    allowed = Action.PUBLISH in grants_of(who.role, key)
    if who.role is Role.VEHICLE and vehicle != who.name:
        return (
            f"access control: vehicle {who.name}'s certificate ({who.common_name}) may publish"
            f" only vehicle {who.name}'s variables, not {vehicle}'s; the routers drop it"
        )
    if who.role is Role.REPLAY and replay_prefix and not vehicle.startswith(replay_prefix):
        return None
    if not allowed:
        what = {
            Role.OPERATOR: "an operator publishes only PLOGGER_CMD and LOGGER_RESTART",
            Role.REPLAY: "a replay host publishes only replayed vehicles' variables",
        }.get(who.role, "its role may not")
        return (
            f"access control: {who.common_name} may not publish {name} of vehicle {vehicle}"
            f" ({what}); the routers drop it"
        )
    return None
