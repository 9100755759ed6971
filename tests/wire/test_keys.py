"""Key convention: variable keys, service keys, escaping."""

from __future__ import annotations

import pytest
import zenoh
from hypothesis import given
from hypothesis import strategies as st

from fleetlog.errors import FormatError
from fleetlog.wire.keys import (
    check_root,
    fleet_service_selector,
    parse_service_key,
    parse_var_key,
    service_key,
    var_key,
    var_selector,
)


def test_var_key_plain() -> None:
    assert var_key("fleet", "alpha", "NAV_X") == "fleet/alpha/var/NAV_X"


def test_default_community_is_escaped_not_dropped() -> None:
    key = var_key("fleet", "#1", "A/B")
    assert key == "fleet/%231/var/A%2FB"
    zenoh.KeyExpr(key)
    parsed = parse_var_key("fleet", key)
    assert (parsed.vehicle, parsed.name) == ("#1", "A/B")


@given(st.text(min_size=0, max_size=40), st.text(min_size=0, max_size=40))
def test_var_key_round_trip(vehicle: str, name: str) -> None:
    key = var_key("fleet", vehicle, name)
    zenoh.KeyExpr(key)  # always a valid key expression
    parsed = parse_var_key("fleet", key)
    assert (parsed.vehicle, parsed.name) == (vehicle, name)


def test_services_are_never_matched_by_wildcards() -> None:
    status = zenoh.KeyExpr(service_key("fleet", "alpha", "status"))
    for wild in ("fleet/**", "fleet/alpha/**", "fleet/*/*/status", "fleet/alpha/*/*"):
        assert not zenoh.KeyExpr(wild).intersects(status), wild
    assert zenoh.KeyExpr(fleet_service_selector("fleet", "status")).intersects(status)


def test_parse_service_key() -> None:
    key = service_key("fleet", "@boat", "file", "x")
    assert parse_service_key("fleet", key) == ("@boat", ("file", "x"))
    with pytest.raises(FormatError, match="not a fleetlog service key"):
        parse_service_key("fleet", "fleet/alpha/var/X")


def test_var_selector_is_superset_of_glob() -> None:
    sel = zenoh.KeyExpr(var_selector("fleet", "alpha", "NAV_*"))
    assert sel.intersects(zenoh.KeyExpr(var_key("fleet", "alpha", "NAV_X")))
    assert not sel.intersects(zenoh.KeyExpr(var_key("fleet", "beta", "NAV_X")))


@pytest.mark.parametrize("root", ["", "a//b", "fleet/*", "@x", "a$b", "x?"])
def test_bad_roots(root: str) -> None:
    with pytest.raises(FormatError, match="key root"):
        check_root(root)


@pytest.mark.parametrize("key", ["other/alpha/var/X", "fleet/alpha/x/X", "fleet/alpha/var"])
def test_not_a_var_key(key: str) -> None:
    with pytest.raises(FormatError):
        parse_var_key("fleet", key)
