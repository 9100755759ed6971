"""What a vehicle's recorder did with the variables a shore command published to it.

``fleetlog poke LOGGER_RESTART=true`` publishes a MOOS command; the recorder runs it in its own
time and keeps the outcome in the ``commands`` ring of its status (docs/wire.md, "Control").
:func:`await_outcomes` asks the status until the recorder has confirmed receipt (its status
answers: the query travels behind the samples) and every command published has its entry,
matched by variable, source and the message's own time stamp.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field

from fleetlog.errors import QueryError
from fleetlog.shore.client import FleetClient
from fleetlog.wire.control import CommandRecord

__all__ = ["Delivery", "Sent", "await_outcomes", "is_command"]

#: how often the status is asked while a command's outcome is awaited
_POLL = 0.05


def is_command(name: str) -> bool:
    """Whether a variable is one a recorder runs as a command (LOGGER_RESTART, PLOGGER_CMD)."""
    upper = name.upper()
    return upper == "LOGGER_RESTART" or upper.endswith("_CMD")


@dataclass(frozen=True)
class Sent:
    """One variable published: its name and the time stamp it carried."""

    name: str
    time: float


@dataclass
class Delivery:
    """What the recorder said about what was published.

    Attributes:
        confirmed: the recorder's status answered after the samples were sent.
        outcomes: each command published → the recorder's entry for it (None: none came).
    """

    confirmed: bool = False
    outcomes: dict[Sent, CommandRecord | None] = field(default_factory=dict)


def _match(records: Sequence[CommandRecord], sent: Sent, source: str) -> CommandRecord | None:
    for record in reversed(records):
        if record.via == sent.name and record.source == source and record.time == sent.time:
            return record
    return None


def await_outcomes(
    client: FleetClient,
    vehicle: str,
    sent: Sequence[Sent],
    source: str,
    wait: float,
) -> Delivery:
    """Wait (at most ``wait`` seconds) for the recorder's receipt and its commands' outcomes.

    Args:
        client: the fleet client.
        vehicle: the vehicle published to.
        sent: what was published, in order.
        source: the source it was published as.
        wait: seconds at most.
    """
    delivery = Delivery()
    commands = [s for s in sent if is_command(s.name)]
    for item in commands:
        delivery.outcomes[item] = None
    deadline = time.monotonic() + wait
    while True:
        try:
            answers = client.status(vehicle)
        except QueryError:
            answers = []
        if answers:
            delivery.confirmed = True
            records = [r for a in answers for r in a.commands]
            for item in commands:
                if delivery.outcomes[item] is None:
                    delivery.outcomes[item] = _match(records, item, source)
        done = delivery.confirmed and all(v is not None for v in delivery.outcomes.values())
        if done or time.monotonic() + _POLL > deadline:
            return delivery
        time.sleep(_POLL)
