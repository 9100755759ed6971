"""Recognising the MOOSDB's echoes of the bridge's own posts.

A MOOS client subscribed to a variable receives its own posts of it back. The bridge posts
messages under their original source and time, so an echo looks exactly like the message it
posted; it is recognised by name, time, source, type and a digest of the value (exact bits of
a double, NaN and -0.0 included; the length and keyed hash of a string or binary value), and
only the first matching message is taken for each post. No field is changed to mark a post.
"""

from __future__ import annotations

import collections
import struct

from fleetlog.moos.protocol import DataType, Message

__all__ = ["EchoFilter"]

_F64 = struct.Struct("<d")


def _digest(message: Message) -> object:
    # The value's identity: exact bits of a double (NaN and -0.0 included), else the bytes'
    # length and keyed hash (Python's SipHash, randomized per process).
    if message.data_type == DataType.DOUBLE:
        return _F64.pack(message.double)
    return (len(message.string), hash(message.string))


class EchoFilter:
    """Remembers the bridge's recent posts to recognise the MOOSDB's echoes of them.

    Args:
        ttl: seconds a post waits for its echo; after that it is counted as unconfirmed.
        capacity: the most posts remembered at once (the oldest are then forgotten and
            counted as unconfirmed).
    """

    def __init__(self, ttl: float = 10.0, capacity: int = 1 << 18) -> None:
        self.ttl = ttl
        self.capacity = capacity
        self._pending: dict[tuple[str, float], list[tuple[str, str, object]]] = {}
        self._order: collections.deque[tuple[float, tuple[str, float], tuple[str, str, object]]]
        self._order = collections.deque()
        self.size = 0

    def __bool__(self) -> bool:
        return self.size > 0

    def expect(self, message: Message, now: float) -> int:
        """Remember a post; return how many old posts had to be forgotten to make room."""
        head = (message.key, message.time)
        tail = (message.source, message.data_type, _digest(message))
        self._pending.setdefault(head, []).append(tail)
        self._order.append((now + self.ttl, head, tail))
        self.size += 1
        forgotten = 0
        while self.size > self.capacity:
            forgotten += self._pop_oldest()
        return forgotten

    def take(self, message: Message) -> bool:
        """Return True (and forget it) if ``message`` is the echo of a remembered post."""
        tails = self._pending.get((message.key, message.time))
        if tails is None:
            return False
        tail = (message.source, message.data_type, _digest(message))
        try:
            tails.remove(tail)
        except ValueError:
            return False
        if not tails:
            del self._pending[(message.key, message.time)]
        self.size -= 1
        return True

    def _pop_oldest(self) -> int:
        _, head, tail = self._order.popleft()
        tails = self._pending.get(head)
        if tails is None or tail not in tails:
            return 0  # already echoed
        tails.remove(tail)
        if not tails:
            del self._pending[head]
        self.size -= 1
        return 1

    def expire(self, now: float) -> int:
        """Forget posts whose echo is overdue; return how many."""
        expired = 0
        order = self._order
        while order and order[0][0] <= now:
            expired += self._pop_oldest()
        if not self._pending:
            order.clear()
        return expired

    def clear(self) -> int:
        """Forget every post (the connection is gone); return how many were waiting."""
        waiting = self.size
        self._pending.clear()
        self._order.clear()
        self.size = 0
        return waiting
