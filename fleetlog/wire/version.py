"""The wire protocol's version: what a vehicle announces, and what a shore accepts.

Fleets upgrade one vehicle at a time, so a shore of version N works with vehicles of N and
N-1. The version is an integer in the JSON replies a shore reads first (``status``,
``latest``, ``sessions``: ``"wire": N``); a reply without it comes from version 1, which
predates the field. docs/wire.md ("Versions") lists what each version changed.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

__all__ = ["OLDEST_SUPPORTED", "WIRE_VERSION", "version_of", "version_problem"]

#: 1: the protocol before versions were announced; 2: "wire" in the replies, the control
#: service, session metadata, the access-control key table
WIRE_VERSION = 2
#: the oldest vehicle protocol this shore works with
OLDEST_SUPPORTED = WIRE_VERSION - 1


def version_of(obj: Mapping[str, Any]) -> int:
    """The wire version a reply announces (1 without the field, or with a bad one)."""
    value = obj.get("wire", 1)
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        return 1
    return value


def version_problem(vehicle: str, version: int) -> str | None:
    """A sentence when a vehicle's protocol is outside what this shore supports, else None."""
    if version > WIRE_VERSION:
        return (
            f"vehicle {vehicle} speaks wire protocol {version}, newer than this fleetlog's"
            f" {WIRE_VERSION}: upgrade the shore first (fleets upgrade the shore, then vehicles)"
        )
    if version < OLDEST_SUPPORTED:
        return (
            f"vehicle {vehicle} speaks wire protocol {version}; this fleetlog supports"
            f" {OLDEST_SUPPORTED} and {WIRE_VERSION}: upgrade the vehicle"
        )
    return None
