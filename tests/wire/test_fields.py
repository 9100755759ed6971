"""Tests for fleetlog.wire.fields: the one rule for what a logged field may hold."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from fleetlog.wire.fields import EMPTY_NAME, clean_name, clean_origin, clean_value, time_ok


@pytest.mark.parametrize(
    ("name", "logged", "changed"),
    [
        ("NAV_X", "NAV_X", False),
        ("a%20b", "a%20b", False),  # '%' itself is never escaped: a good name never changes
        ("x\udcff", "x\udcff", False),  # a byte that was not UTF-8 is written as that byte
        ("é:@", "é:@", False),  # ':' and '@' are only separators in the source column
        ("", EMPTY_NAME, True),
        ("NAV X", "NAV%20X", True),
        ("A\tB", "A%09B", True),
        ("A\nB", "A%0AB", True),
        ("A\u2028B", "A%E2%80%A8B", True),
        ("A\xa0B", "A%C2%A0B", True),
        ("\x00", "%00", True),
        ("A\u200bB", "A%E2%80%8BB", True),
    ],
)
def test_clean_name(name: str, logged: str, changed: bool) -> None:
    assert clean_name(name) == (logged, changed)


def test_clean_origin_escapes_the_source_column_separators() -> None:
    assert clean_origin("pHelm", "BHV:1", "shore") == ("pHelm", "BHV:1", "shore", False)
    assert clean_origin("a:b", "", "") == ("a%3Ab", "", "", True)
    assert clean_origin("a@b", "", "") == ("a%40b", "", "", True)
    assert clean_origin("a", "x@y", "") == ("a", "x%40y", "", True)
    assert clean_origin("a", "", "c@d") == ("a", "", "c%40d", True)
    assert clean_origin("a", "", "c:d") == ("a", "", "c:d", False)
    assert clean_origin("", "", "") == ("", "", "", False)


@pytest.mark.parametrize(
    ("when", "ok"),
    [
        (1.8e9, True),
        (0.0, True),
        (1e10, True),
        (1e10 + 1, False),
        (-1.0, False),
        (math.nan, False),
        (math.inf, False),
        (-math.inf, False),
        (1e300, False),
    ],
)
def test_time_ok(when: float, ok: bool) -> None:
    assert time_ok(when) is ok


@pytest.mark.parametrize(
    ("value", "logged", "changed"),
    [
        ("plain", "plain", False),
        ("line1\nline2", "line1\nline2", False),  # pLogger's multi-line values stay
        ("a\n b", "a\n b", False),
        ("a\nx1", "a\nx1", False),
        ("a\n1.0 X Y 2", "a\\n1.0 X Y 2", True),
        ("a\n-1 X Y 2", "a\\n-1 X Y 2", True),
        ("a\n-x", "a\n-x", False),
        ("a\n%comment", "a\\n%comment", True),
        ("a\n\n5", "a\n\\n5", True),
        ("a\r\n5", "a\r\\n5", True),
        ("a\n٣", "a\n٣", False),  # only ASCII digits start an entry
    ],
)
def test_clean_value(value: str, logged: str, changed: bool) -> None:
    assert clean_value(value) == (logged, changed)


@given(st.text())
def test_cleaning_is_idempotent(text: str) -> None:
    name, _ = clean_name(text)
    assert clean_name(name) == (name, False)
    source, aux, community, _ = clean_origin(text, text, text)
    assert clean_origin(source, aux, community)[3] is False
    value, _ = clean_value(text)
    assert clean_value(value) == (value, False)
