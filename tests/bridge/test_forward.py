"""The bridge's rules (fleetlog/bridge/forward.py), without sockets: a fake clock, lists."""

from __future__ import annotations

import math

import pytest

from fleetlog.bridge.echo import EchoFilter
from fleetlog.bridge.forward import Forwarder
from fleetlog.errors import TransportError
from fleetlog.moos.protocol import Message
from fleetlog.moos.requests import notify


class Rig:
    def __init__(self, *, to: tuple[str, ...] = ("*",), frm: tuple[str, ...] = ("*",)) -> None:
        self.now = 1000.0
        self.published: list[Message] = []
        self.posted: list[Message] = []
        self.subscribed: list[str] = []
        self.said: list[str] = []
        self.fail_publish = False
        self.fw = Forwarder(
            name="fleetlog_bridge",
            vehicle="alpha",
            to_zenoh=to,
            from_zenoh=frm,
            publish=self.publish,
            post=self.post,
            subscribe=self.subscribed.append,
            clock=lambda: self.now,
            max_post=1000,
            on_say=self.said.append,
        )
        self.fw.moos_connected()

    def publish(self, message: Message) -> None:
        if self.fail_publish:
            raise TransportError("router gone")
        self.published.append(message)

    def post(self, messages: list[Message]) -> bool:
        if not self.fw.moos_up:
            return False
        self.posted.extend(messages)
        return True

    def echo_back(self) -> None:
        """The MOOSDB delivers the bridge's posts back to it (it is subscribed)."""
        posts = [m._replace(community=m.community or "alpha") for m in self.posted]
        self.posted.clear()
        self.fw.from_moos(posts)


def test_moos_mail_goes_to_zenoh_unchanged() -> None:
    rig = Rig()
    mail = [
        notify("NAV_X", 1.5, 10.0, "iGPS", "aux", "alpha"),
        notify("IMG", b"\x00\xff", 10.1, "cam", "", "alpha"),
        notify("DB_TIME", 10.2, 10.2, "MOOSDB_alpha", "", "alpha"),
        Message("T", "D", "_async_timing", 10.3),  # not a notification: not forwarded
    ]
    rig.fw.from_moos(mail)
    assert rig.published == mail[:3]
    assert rig.fw.stats.from_moos == 3
    assert rig.fw.stats.to_zenoh == 3


def test_zenoh_samples_are_posted_under_their_source_and_echoes_dropped() -> None:
    rig = Rig()
    sample = notify("DEPLOY", "true", 5.0, "uPokeDB", "", "alpha")
    rig.fw.from_zenoh([(sample, False)])
    assert rig.posted == [sample]
    rig.echo_back()
    assert rig.published == []  # nothing comes back around
    assert rig.fw.stats.echoes == 1
    assert rig.fw.stats.to_moos == 1


def test_an_echo_is_told_from_a_real_post_by_value_and_source() -> None:
    rig = Rig()
    rig.fw.from_zenoh([(notify("X", 1.0, 5.0, "replay"), False)])
    rig.posted.clear()
    # Same name and time, but another value, then another source: real MOOS posts.
    other_value = notify("X", 2.0, 5.0, "replay", community="alpha")
    other_source = notify("X", 1.0, 5.0, "pHelm", community="alpha")
    echo = notify("X", 1.0, 5.0, "replay", community="alpha")
    rig.fw.from_moos([other_value, other_source, echo])
    assert rig.published == [other_value, other_source]
    assert rig.fw.stats.echoes == 1


def test_equal_posts_each_drop_one_echo() -> None:
    rig = Rig()
    same = notify("X", 1.0, 5.0, "a")
    rig.fw.from_zenoh([(same, False), (same, False)])
    rig.echo_back()
    rig.fw.from_moos([same._replace(community="alpha")])  # a third: a real post
    assert rig.fw.stats.echoes == 2
    assert len(rig.published) == 1


def test_nan_values_and_binary_echoes_match() -> None:
    rig = Rig()
    rig.fw.from_zenoh(
        [(notify("N", -math.nan, 5.0, "a"), False), (notify("B", b"\x01" * 50, 5.0, "a"), False)]
    )
    rig.echo_back()
    assert rig.fw.stats.echoes == 2
    assert rig.published == []


def test_a_redelivered_value_is_not_forwarded_twice() -> None:
    rig = Rig()
    value = notify("DEPLOY", "true", 5.0, "pHelm", "", "alpha")
    rig.fw.from_moos([value])
    rig.fw.moos_lost()
    rig.fw.moos_connected()  # re-registration: the DB sends the current value again
    rig.fw.from_moos([value, value._replace(time=6.0)])
    assert [m.time for m in rig.published] == [5.0, 6.0]
    assert rig.fw.stats.redelivered == 1


def test_moos_type_rule() -> None:
    rig = Rig()
    rig.fw.from_moos([notify("SPEED", 1.0, 1.0, "pHelm", "", "alpha")])
    clash = notify("SPEED", "fast", 2.0, "uPokeDB")
    rig.fw.from_zenoh([(clash, False), (clash._replace(time=3.0), False)])
    rig.fw.from_zenoh([(notify("SPEED", 2.0, 4.0, "uPokeDB"), False)])
    assert [m.value for m in rig.posted if m.key == "SPEED"] == [2.0]
    assert rig.fw.stats.type_clashes == 2
    said = [t for t in rig.said if "SPEED" in t]
    assert said == [
        "SPEED is a double in the MOOSDB: a string from uPokeDB was not posted (MOOS keeps a "
        "variable's first type); further ones are counted"
    ]
    # said on MOOS_DEBUG too, in the MOOSDB and on Zenoh
    assert any(m.key == "MOOS_DEBUG" and b"SPEED" in m.string for m in rig.posted)
    assert any(m.key == "MOOS_DEBUG" and b"SPEED" in m.string for m in rig.published)


def test_the_first_post_fixes_the_type_too() -> None:
    rig = Rig()
    rig.fw.from_zenoh([(notify("NEW", "text", 1.0, "a"), False)])
    rig.fw.from_zenoh([(notify("NEW", 1.0, 2.0, "a"), False)])
    assert rig.fw.stats.type_clashes == 1
    assert [m.key for m in rig.posted if m.key == "NEW"] == ["NEW"]


def test_a_new_moosdb_starts_its_types_afresh() -> None:
    rig = Rig()
    rig.fw.from_moos([notify("X", 1.0, 1.0, "a", "", "alpha")])
    rig.fw.moos_lost()
    rig.fw.moos_connected()
    rig.fw.from_zenoh([(notify("X", "now a string", 2.0, "b"), False)])
    assert rig.fw.stats.type_clashes == 0


def test_what_cannot_cross_is_counted() -> None:
    rig = Rig(frm=("NAV_*",))
    rig.fw.from_zenoh(
        [
            (notify("OTHER", 1.0, 1.0, "a"), False),  # outside FromZenoh
            (None, True),  # a key that names no variable
            (notify("NAV_IMG", b"x" * 2000, 1.0, "a"), False),  # larger than max_post
        ]
    )
    rig.fw.moos_lost()
    rig.fw.from_zenoh([(notify("NAV_X", 1.0, 1.0, "a"), True)])  # no MOOSDB
    s = rig.fw.stats
    assert (s.from_zenoh, s.filtered, s.garbled, s.too_large) == (4, 1, 2, 1)
    assert s.unforwarded_to_moos == 1
    assert rig.posted == []

    rig.fw.zenoh_up = False
    rig.fw.from_moos([notify("Y", 1.0, 1.0, "a", "", "alpha")])
    rig.fw.zenoh_up = True
    rig.fail_publish = True
    rig.fw.from_moos([notify("Y", 2.0, 2.0, "a", "", "alpha")])
    rig.fw.from_moos([notify("Y", 3.0, 3.0, "a", "", "alpha")])
    assert s.unforwarded_to_zenoh == 3
    assert rig.said == ["could not forward to Zenoh: router gone"]  # once, not per message


def test_posts_never_echoed_are_unconfirmed() -> None:
    rig = Rig()
    rig.fw.from_zenoh([(notify("X", 1.0, 1.0, "a"), False)])
    rig.now += 11
    rig.fw.tick()
    assert rig.fw.stats.unconfirmed == 1
    rig.fw.from_zenoh([(notify("X", 2.0, 2.0, "a"), False)])
    rig.fw.moos_lost()
    assert rig.fw.stats.unconfirmed == 2


def test_to_zenoh_patterns_register_what_the_bridge_posts() -> None:
    rig = Rig(to=("NAV_*", "DB_*"))
    rig.fw.from_zenoh([(notify("DEPLOY", "true", 1.0, "a"), False)] * 2)
    assert rig.subscribed == ["DEPLOY"]  # once: the DB's echo and the type reach the bridge
    rig.echo_back()
    assert rig.fw.stats.echoes == 2
    rig.fw.from_moos([notify("DEPLOY", "false", 2.0, "pHelm", "", "alpha")])
    rig.fw.from_moos([notify("NAV_X", 1.0, 2.0, "iGPS", "", "alpha")])
    assert [m.key for m in rig.published] == ["NAV_X"]
    assert rig.fw.stats.not_selected == 1


def test_the_bridges_own_posts_reach_both_sides_once() -> None:
    rig = Rig()
    rig.fw.own("FLEETLOG_BRIDGE_STATUS", "AppErrorFlag=false")
    assert [m.key for m in rig.published] == ["FLEETLOG_BRIDGE_STATUS"]
    assert [m.source for m in rig.posted] == ["fleetlog_bridge"]
    rig.echo_back()
    assert len(rig.published) == 1
    assert rig.fw.published == {"FLEETLOG_BRIDGE_STATUS"}


def test_echo_filter_forgets_the_oldest_beyond_its_capacity() -> None:
    echo = EchoFilter(ttl=5.0, capacity=3)
    posts = [notify("X", float(i), 1.0, "a") for i in range(5)]
    forgotten = sum(echo.expect(p, 0.0) for p in posts)
    assert forgotten == 2
    assert not echo.take(posts[0])
    assert echo.take(posts[4])
    assert echo.expire(10.0) == 2
    assert not echo


@pytest.mark.parametrize("value", [0.0, -0.0])
def test_zero_and_negative_zero_are_different_values(value: float) -> None:
    rig = Rig()
    rig.fw.from_zenoh([(notify("Z", value, 1.0, "a"), False)])
    flipped = math.copysign(0.0, -math.copysign(1.0, value))
    other = notify("Z", flipped, 1.0, "a", community="alpha")
    rig.fw.from_moos([other])
    assert rig.fw.stats.echoes == 0


def test_a_flood_of_new_names_does_not_grow_the_registrations(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    import fleetlog.bridge.forward as forward

    monkeypatch.setattr(forward, "MAX_REGISTERED", 3)
    rig = Rig(to=("NAV_*",))
    rig.fw.from_zenoh([(notify(f"V{i}", 1.0, 1.0, "a"), False) for i in range(10)])
    assert rig.subscribed == ["V0", "V1", "V2"]
    assert len([m for m in rig.posted if m.key.startswith("V")]) == 10
    assert len([t for t in rig.said if "later ones are posted without registering" in t]) == 1
