"""Zenoh's samples handed from the receiving thread to the bridge's event loop.

The receiving thread decodes samples and hands over batches through a bounded queue; the loop
is woken once per run of batches, not once per sample. When the MOOSDB's socket cannot take
more, or the queue is full, the thread waits: its FIFO channel fills and Zenoh pushes back on
the (BLOCK) publishers instead of anything being dropped.
"""

from __future__ import annotations

import asyncio
import contextlib
import queue
import threading
from collections.abc import Callable, Sequence

from fleetlog.moos.protocol import Message

__all__ = ["Intake"]

Items = Sequence[tuple[Message | None, bool]]


class Intake:
    """A bounded hand-over of decoded samples from one thread to an event loop.

    Args:
        loop: the event loop that consumes.
        consume: called in the loop with each batch, in order.
        writable: set while the MOOSDB's socket accepts more (the producer waits otherwise).
        stopping: set when the producer must stop waiting.
        batches: the most batches held at once.
    """

    def __init__(
        self,
        loop: asyncio.AbstractEventLoop,
        consume: Callable[[Items], None],
        writable: Callable[[], threading.Event | None],
        stopping: threading.Event,
        batches: int = 64,
    ) -> None:
        self._loop = loop
        self._consume = consume
        self._writable = writable
        self._stopping = stopping
        self._queue: queue.Queue[Items] = queue.Queue(maxsize=batches)
        self._wake_pending = False

    def put(self, items: Items) -> None:
        """Hand over a batch (in the producing thread): wait for room, then wake the loop."""
        stopping = self._stopping
        while not stopping.is_set():
            writable = self._writable()
            if writable is None or writable.wait(0.5):
                break
        while not stopping.is_set():
            try:
                self._queue.put(items, timeout=0.5)
                break
            except queue.Full:
                continue
        # A put seen before the flag is cleared is drained by the wake already scheduled.
        if not self._wake_pending:
            self._wake_pending = True
            with contextlib.suppress(RuntimeError):  # the loop is closed: shutting down
                self._loop.call_soon_threadsafe(self._drain)

    def _drain(self) -> None:
        self._wake_pending = False
        get = self._queue.get_nowait
        while True:
            try:
                items = get()
            except queue.Empty:
                return
            self._consume(items)
