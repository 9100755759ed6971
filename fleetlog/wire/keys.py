"""Key expressions of fleetlog's Zenoh convention (docs/wire.md).

A MOOS variable ``VAR`` of vehicle ``V`` lives at ``<root>/V/var/VAR``; fleetlog's own services
live under ``<root>/V/@fleetlog/...``. ``@fleetlog`` is a verbatim chunk, so no wildcard
subscription (``fleet/**``, ``fleet/V/*/...``) ever swallows the services. Vehicle and variable
names are escaped into single chunks by :func:`fleetlog.moos.patterns.name_to_chunk`, a
reversible rule, so no MOOS name is ever dropped (MOOS's default community ``#1`` included).
"""

from __future__ import annotations

from dataclasses import dataclass

from fleetlog.errors import FormatError
from fleetlog.moos.patterns import chunk_to_name, glob_to_chunk, name_to_chunk

__all__ = [
    "DEFAULT_ROOT",
    "MAX_NAME_BYTES",
    "SERVICE",
    "VarKey",
    "check_component",
    "check_root",
    "fleet_service_selector",
    "parse_service_key",
    "parse_var_key",
    "service_key",
    "var_key",
    "var_selector",
    "vehicle_chunk",
]

DEFAULT_ROOT = "fleet"
#: the longest session or file name (one path component)
MAX_NAME_BYTES = 255
#: the verbatim chunk under which fleetlog's own services live
SERVICE = "@fleetlog"


def check_root(root: str) -> str:
    """Validate a key root (``fleet`` by default): non-empty chunks, no wildcards.

    Raises:
        FormatError: the root cannot prefix fleetlog's keys.
    """
    chunks = root.split("/")
    for chunk in chunks:
        if not chunk or any(c in chunk for c in "*$?#") or chunk.startswith("@"):
            msg = f"key root {root!r} must be plain Zenoh chunks without wildcards, '$', '?', '#'"
            raise FormatError(msg)
    return root


def vehicle_chunk(vehicle: str) -> str:
    """Return the key chunk of a vehicle (its MOOS community, escaped)."""
    return name_to_chunk(vehicle)


def var_key(root: str, vehicle: str, name: str) -> str:
    """Return the key of a MOOS variable of a vehicle."""
    return f"{root}/{name_to_chunk(vehicle)}/var/{name_to_chunk(name)}"


def var_selector(root: str, vehicle: str, glob: str = "*") -> str:
    """Return the narrowest key expression that holds every variable matching a MOOS glob."""
    return f"{root}/{name_to_chunk(vehicle)}/var/{glob_to_chunk(glob)}"


@dataclass(frozen=True, slots=True)
class VarKey:
    """A variable key taken apart: the vehicle and the MOOS variable name."""

    vehicle: str
    name: str


def parse_var_key(root: str, key: str) -> VarKey:
    """Split ``<root>/V/var/NAME`` into vehicle and name (both unescaped).

    Raises:
        FormatError: the key is not a variable key under ``root``.
    """
    prefix = root + "/"
    if not key.startswith(prefix):
        msg = f"key {key!r} is not under {root!r}"
        raise FormatError(msg)
    parts = key[len(prefix) :].split("/")
    if len(parts) != 3 or parts[1] != "var":
        msg = f"key {key!r} is not of the form {root}/VEHICLE/var/NAME"
        raise FormatError(msg)
    return VarKey(chunk_to_name(parts[0]), chunk_to_name(parts[2]))


def service_key(root: str, vehicle: str, *parts: str) -> str:
    """Return the key of one of a vehicle's fleetlog services (``<root>/V/@fleetlog/...``)."""
    tail = "/".join(parts)
    base = f"{root}/{name_to_chunk(vehicle)}/{SERVICE}"
    return f"{base}/{tail}" if tail else base


def fleet_service_selector(root: str, *parts: str) -> str:
    """Return the selector of a service across every vehicle (``<root>/*/@fleetlog/...``)."""
    return "/".join([root, "*", SERVICE, *parts])


def parse_service_key(root: str, key: str) -> tuple[str, tuple[str, ...]]:
    """Split ``<root>/V/@fleetlog/a/b`` into the vehicle name and ``("a", "b")``.

    Raises:
        FormatError: the key is not a fleetlog service key under ``root``.
    """
    prefix = root + "/"
    parts = key[len(prefix) :].split("/") if key.startswith(prefix) else []
    if len(parts) < 2 or parts[1] != SERVICE:
        msg = f"key {key!r} is not a fleetlog service key under {root!r}"
        raise FormatError(msg)
    return chunk_to_name(parts[0]), tuple(parts[2:])


def check_component(name: str, what: str) -> str:
    r"""Check that a session or file name is one plain path component.

    Args:
        name: the name, already unescaped from its key chunk.
        what: ``"session"`` or ``"file"``, for the message.

    Returns:
        The name unchanged.

    Raises:
        FormatError: the name is empty, ``.`` or ``..``, holds ``/``, ``\`` or NUL, or is
            longer than 255 bytes; each could reach outside the session.
    """
    if not name:
        reason = "is empty"
    elif name in (".", ".."):
        reason = "is a relative directory"
    elif "/" in name:
        reason = "holds '/' (only one path component is allowed)"
    elif "\\" in name:
        reason = "holds '\\' (only one path component is allowed)"
    elif "\x00" in name:
        reason = "holds a NUL character"
    elif len(name.encode("utf-8", "surrogateescape")) > MAX_NAME_BYTES:
        reason = f"is longer than {MAX_NAME_BYTES} bytes"
    else:
        return name
    msg = f"{what} name {name[:80]!r} {reason}"
    raise FormatError(msg)
