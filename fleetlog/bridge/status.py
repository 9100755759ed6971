"""The bridge's ``<NAME>_STATUS`` text: CMOOSApp's fields, then the bridge's counters."""

from __future__ import annotations

from collections.abc import Iterable

from fleetlog.bridge.forward import BridgeStats

__all__ = ["status_text"]


def _camel(name: str) -> str:
    return "".join(part.capitalize() for part in name.split("_"))


def status_text(
    *,
    name: str,
    vehicle: str | None,
    uptime: float,
    process: str,
    published: Iterable[str],
    subscribing: Iterable[str],
    stats: BridgeStats,
) -> str:
    """Return the status as CMOOSApp writes an app's, with ``Community`` and the counters.

    Args:
        name: the bridge's MOOS name.
        vehicle: the vehicle bridged.
        uptime: seconds since the bridge started.
        process: the ``cpuload=…,memory_kb=…,memory_max_kb=…`` fields.
        published: the variables it posts itself.
        subscribing: its registrations.
        stats: its counters, written ``FromMoos=…,ToZenoh=…`` in their order.
    """
    error = stats.unforwarded_to_moos or stats.unforwarded_to_zenoh or stats.unconfirmed
    counters = ",".join(f"{_camel(key)}={value}" for key, value in stats.as_dict().items())
    return (
        f"AppErrorFlag={'true' if error else 'false'},Uptime={uptime:.6g},{process},"
        f"MOOSName={name},Community={vehicle},"
        f'Publishing="{"".join(n + "," for n in sorted(published))}",'
        f'Subscribing="{"".join(n + "," for n in sorted(subscribing))}",{counters}'
    )
