"""What a MOOS client sends, and the MOOSDB's answer to its handshake (MOOS_WIRE.md §4-7).

Pure code: builders of the messages a client sends (the handshake, registrations, timing,
notifications) and the reading of the DB's welcome or poison message. The codec that puts
them on the wire is :mod:`fleetlog.moos.protocol`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from fleetlog.errors import FormatError
from fleetlog.moos.protocol import DataType, Message, MsgType

__all__ = [
    "ASYNC_KEY",
    "HANDSHAKE",
    "Welcome",
    "handshake_message",
    "notify",
    "parse_welcome",
    "register",
    "timing_message",
    "unregister",
    "wildcard_register",
]

#: What a client sends first: the protocol's 23-character magic, NUL-padded to 32 bytes.
HANDSHAKE = b"ELKS CAN'T DANCE 2/8/10".ljust(32, b"\0")
#: The key of the handshake message of an asynchronous (full-duplex) client.
ASYNC_KEY = "asynchronous"

_new_message = Message.__new__


def _text(text: str) -> bytes:
    return text.encode("utf-8", "surrogateescape")


# --------------------------------------------------------------------------------------------
# Messages a client sends


def handshake_message(name: str, time: float, *, asynchronous: bool = True) -> Message:
    """The ``i`` message after :data:`HANDSHAKE`: the client's name, async or not."""
    return Message(
        MsgType.DATA,
        DataType.STRING,
        ASYNC_KEY if asynchronous else "",
        time,
        string=_text(name),
    )


def timing_message(time: float) -> Message:
    """The ``T`` message an async client sends at least once a second (keep-alive, skew)."""
    return Message(MsgType.TIMING, DataType.DOUBLE, "_async_timing", time, double=0.0)


def register(client: str, key: str, interval: float, time: float) -> Message:
    """Subscribe ``client`` to ``key``, at most one message every ``interval`` seconds."""
    return Message(MsgType.REGISTER, DataType.DOUBLE, key, time, double=interval, source=client)


def unregister(client: str, key: str, time: float) -> Message:
    """Unsubscribe ``client`` from ``key``."""
    return Message(MsgType.UNREGISTER, DataType.DOUBLE, key, time, double=0.0, source=client)


def wildcard_register(
    client: str, var_pattern: str, app_pattern: str, interval: float, time: float
) -> Message:
    """Subscribe ``client`` to the variables matching ``var_pattern`` (MOOS globs).

    ``app_pattern`` must match the writer of a variable's first write; the DB parses the
    text as ``MOOSAddValToString``'s comma list.

    Raises:
        ValueError: a pattern holds ``,`` or ``=``, which the DB's parser cannot carry.
    """
    for pattern in (var_pattern, app_pattern):
        if "," in pattern or "=" in pattern:
            msg = f"a MOOS wildcard pattern cannot hold ',' or '=': {pattern!r}"
            raise ValueError(msg)
    text = f"AppPattern={app_pattern},VarPattern={var_pattern},Interval={interval:.6f}"
    return Message(
        MsgType.WILDCARD_REGISTER,
        DataType.STRING,
        client,
        time,
        string=_text(text),
        source=client,
    )


def notify(
    key: str,
    value: float | str | bytes,
    time: float,
    source: str,
    aux: str = "",
    community: str = "",
) -> Message:
    """A notification (``N``): a double, a string or binary data, as given."""
    if isinstance(value, bytes):
        return _new_message(
            Message, "N", "B", key, time, -1.0, value, source, aux, community, -1.0, -1
        )
    if isinstance(value, str):
        return _new_message(
            Message, "N", "S", key, time, -1.0, _text(value), source, aux, community, -1.0, -1
        )
    return _new_message(
        Message, "N", "D", key, time, float(value), b"", source, aux, community, -1.0, -1
    )


# --------------------------------------------------------------------------------------------
# The DB's answer to the handshake


@dataclass(frozen=True, slots=True)
class Welcome:
    """What the DB's welcome says.

    Attributes:
        community: the DB's community.
        host: the DB's host name (``hostname=`` in the aux source), if given.
        skew: the DB's time minus the client's handshake time. On the same host this is the
            DB's 100 ms pause before reading the handshake, not a clock offset.
        asynchronous: whether the DB accepts asynchronous clients.
    """

    community: str
    host: str
    skew: float
    asynchronous: bool


def parse_welcome(messages: Sequence[Message]) -> Welcome:
    """Read the DB's answer to the handshake.

    Raises:
        FormatError: the answer is a poison message (for example: a client of that name is
            already connected), or neither a welcome nor a poison message.
    """
    if not messages:
        msg = "the MOOSDB answered the handshake with an empty packet"
        raise FormatError(msg)
    first = messages[0]
    text = first.string.decode("utf-8", "replace")
    if first.msg_type == MsgType.POISON:
        msg = f"the MOOSDB refused the connection: {text or 'no reason given'}"
        raise FormatError(msg)
    if first.msg_type != MsgType.WELCOME:
        msg = f"the MOOSDB answered the handshake with a {first.msg_type!r} message"
        raise FormatError(msg)
    host = first.aux.partition("hostname=")[2] if "hostname=" in first.aux else ""
    return Welcome(first.community, host, first.double, text == ASYNC_KEY)
