"""Our asyncio MOOS client against a real MOOSDB (MOOS_BIN): what the bridge relies on."""

from __future__ import annotations

import asyncio
import contextlib
import time
from collections.abc import Callable, Coroutine
from typing import Any

import pytest
from moos_support import MoosDB, needs_moos

from fleetlog.errors import TransportError
from fleetlog.moos.protocol import Message
from fleetlog.moos.requests import notify
from fleetlog.transport.moos_client import MoosClient, MoosRefusedError

pytestmark = needs_moos


def run(coro: Coroutine[Any, Any, None]) -> None:
    asyncio.run(asyncio.wait_for(coro, 30))


class Inbox:
    def __init__(self) -> None:
        self.messages: list[Message] = []
        self.event = asyncio.Event()

    def __call__(self, messages: list[Message]) -> None:
        self.messages.extend(messages)
        self.event.set()

    def notes(self, key: str) -> list[Message]:
        return [m for m in self.messages if m.msg_type == "N" and m.key == key]

    async def until(self, check: Callable[[], bool], timeout: float = 5.0) -> None:
        deadline = time.monotonic() + timeout
        while not check():
            left = deadline - time.monotonic()
            assert left > 0, "timed out"
            self.event.clear()
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self.event.wait(), left)


def client(db: MoosDB, name: str, inbox: Inbox | None = None) -> MoosClient:
    return MoosClient(name, "127.0.0.1", db.port, on_mail=inbox or (lambda m: None))


def test_handshake_and_a_refused_name(moosdbs: Callable[..., MoosDB]) -> None:
    db = moosdbs("alpha")

    async def main() -> None:
        a = client(db, "probe")
        welcome = await a.connect()
        assert welcome.community == "alpha"
        assert welcome.asynchronous
        assert 0.05 < welcome.skew < 0.5  # the DB's pause before reading the handshake
        with pytest.raises(MoosRefusedError, match='A client of this name \\("probe"\\)'):
            await client(db, "probe").connect()
        a.close()

    run(main())


def test_values_metadata_and_bytes_survive_the_moosdb(moosdbs: Callable[..., MoosDB]) -> None:
    db = moosdbs("alpha")

    async def main() -> None:
        inbox = Inbox()
        sub = client(db, "sub", inbox)
        pub = client(db, "pub")
        sub.subscribe_wildcard("T_*")
        await sub.connect()
        await pub.connect()
        sent = [
            notify("T_D", -0.0, 1700000000.125, "pHelmIvP", "bhv_waypoint", "bravo"),
            notify("T_S", "h\u00e9llo\x00 \udcff", 1700000000.25, "src", "", ""),
            notify("T_B", bytes(range(256)) * 4, 1700000000.5, "cam", "", "alpha"),
        ]
        pub.send(sent)
        await inbox.until(lambda: len(inbox.notes("T_B")) == 1)
        for original in sent:
            (got,) = inbox.notes(original.key)
            # kept: time (an hour-old stamp would be too), source, aux, bytes; the DB
            # fills an empty community with its own
            expected = original._replace(community=original.community or "alpha")
            assert got._replace(id=-1) == expected
        sub.close()
        pub.close()

    run(main())


def test_a_subscriber_gets_its_own_posts_back(moosdbs: Callable[..., MoosDB]) -> None:
    db = moosdbs("alpha")

    async def main() -> None:
        inbox = Inbox()
        me = client(db, "me", inbox)
        me.subscribe_wildcard("*")
        await me.connect()
        me.send([notify("MINE", 1.0, time.time(), "someone_else")])
        await inbox.until(lambda: bool(inbox.notes("MINE")))
        assert inbox.notes("MINE")[0].source == "someone_else"
        me.close()

    run(main())


def test_registering_redelivers_the_current_value_with_its_old_time(
    moosdbs: Callable[..., MoosDB],
) -> None:
    db = moosdbs("alpha")

    async def main() -> None:
        pub = client(db, "pub")
        await pub.connect()
        pub.send([notify("OLD", 7.0, 1600000000.0, "pub")])
        await asyncio.sleep(0.3)
        inbox = Inbox()
        late = client(db, "late", inbox)
        late.subscribe("OLD")
        await late.connect()
        await inbox.until(lambda: bool(inbox.notes("OLD")))
        assert inbox.notes("OLD")[0].time == 1600000000.0
        pub.close()
        late.close()

    run(main())


def test_the_moosdb_drops_a_write_of_another_type_silently(moosdbs: Callable[..., MoosDB]) -> None:
    db = moosdbs("alpha")

    async def main() -> None:
        inbox = Inbox()
        sub = client(db, "sub", inbox)
        sub.subscribe("TYPED")
        await sub.connect()
        pub = client(db, "pub", Inbox())
        await pub.connect()
        now = time.time()
        pub.send([notify("TYPED", 1.0, now, "pub")])
        pub.send([notify("TYPED", "text", now + 0.001, "pub")])
        pub.send([notify("TYPED", 2.0, now + 0.002, "pub")])
        await inbox.until(lambda: len(inbox.notes("TYPED")) >= 2)
        await asyncio.sleep(0.3)
        assert [m.value for m in inbox.notes("TYPED")] == [1.0, 2.0]
        sub.close()
        pub.close()

    run(main())


def test_maintain_reconnects_and_reregisters(moosdbs: Callable[..., MoosDB]) -> None:
    db = moosdbs("alpha", start=False)
    events: list[str] = []

    async def main() -> None:
        inbox = Inbox()
        me = client(db, "me", inbox)
        me.subscribe_wildcard("AFTER_*")
        up = asyncio.Event()

        def on_up(welcome: object) -> None:
            events.append("up")
            up.set()

        keeper = asyncio.create_task(
            me.maintain(
                on_up,
                lambda reason: events.append(f"down: {reason}"),
                lambda err: events.append(f"retry: {err}"),
                retry=0.2,
            )
        )
        await asyncio.sleep(0.5)
        assert any("cannot connect" in e for e in events)  # not up yet: retrying
        await asyncio.to_thread(db.start)
        await asyncio.wait_for(up.wait(), 10)
        up.clear()
        await asyncio.to_thread(db.stop)
        await asyncio.to_thread(db.start)
        await asyncio.wait_for(up.wait(), 10)
        pub = client(db, "pub")
        await pub.connect()
        pub.send([notify("AFTER_RESTART", 1.0, time.time(), "pub")])
        await inbox.until(lambda: bool(inbox.notes("AFTER_RESTART")))
        pub.close()
        me.close()
        await keeper

    run(main())
    assert events.count("up") == 2
    assert any(e.startswith("down: ") for e in events)


def test_a_closed_port_is_a_clear_error(moosdbs: Callable[..., MoosDB]) -> None:
    db = moosdbs("alpha", start=False)

    async def main() -> None:
        with pytest.raises(
            TransportError, match=f"cannot connect to the MOOSDB at 127.0.0.1:{db.port}"
        ):
            await client(db, "x").connect()

    run(main())


def test_a_burst_arrives_whole_and_in_order(moosdbs: Callable[..., MoosDB]) -> None:
    db = moosdbs("alpha")
    count = 20000

    async def main() -> None:
        inbox = Inbox()
        sub = client(db, "sub", inbox)
        sub.subscribe("BURST")
        await sub.connect()
        pub = client(db, "pub")
        await pub.connect()
        now = time.time()
        pub.send([notify("BURST", float(i), now, "pub") for i in range(count)])
        await inbox.until(lambda: len(inbox.notes("BURST")) >= count, timeout=20)
        assert [m.double for m in inbox.notes("BURST")] == [float(i) for i in range(count)]
        sub.close()
        pub.close()

    run(main())
