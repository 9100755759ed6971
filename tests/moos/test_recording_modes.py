"""Recording-mode settings: sizes, durations, notes, and the warnings pLogger never gives."""

from __future__ import annotations

import pytest

from fleetlog.errors import FormatError
from fleetlog.moos.mission import parse_mission
from fleetlog.moos.param_check import MAX_WARNINGS, check_logger_block
from fleetlog.moos.units import parse_duration, parse_size


@pytest.mark.parametrize(
    ("text", "size"),
    [
        ("500MB", 500_000_000),
        ("500 mb", 500_000_000),
        ("2GiB", 2 << 30),
        ("1.5kB", 1500),
        ("1048576", 1 << 20),
        ("1e3 B", 1000),
        ("0", 0),
    ],
)
def test_sizes(text: str, size: int) -> None:
    assert parse_size(text) == size


@pytest.mark.parametrize(
    ("text", "seconds"),
    [("10min", 600.0), ("90", 90.0), ("1.5h", 5400.0), ("2 s", 2.0), ("1d", 86400.0)],
)
def test_durations(text: str, seconds: float) -> None:
    assert parse_duration(text) == seconds


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("", "is not a number with an optional unit"),
        ("-5MB", "is not a number with an optional unit"),
        ("5 parsecs", "unknown unit 'parsecs'"),
        ("1e999", "too large"),
        ("2PB", "unknown unit 'pb'"),
        ("9" * 70, "at most 64"),
        ("nan", "is not a number"),
    ],
)
def test_bad_sizes_say_why(text: str, message: str) -> None:
    with pytest.raises(FormatError, match="SplitSize") as err:
        parse_size(text, name="SplitSize")
    assert message in str(err.value)


def block(body: str) -> object:
    text = "ProcessConfig = pLogger\n{\n" + body + "}\n"
    return parse_mission(text, "m.moos").block("pLogger")


def warnings_of(body: str) -> list[str]:
    return [str(w) for w in check_logger_block(block(body), "m.moos")]  # type: ignore[arg-type]


def test_unknown_parameters_name_the_closest_known_one() -> None:
    got = warnings_of(
        "  WildcardLoging = true\n  Pth = /data\n  AppTick = 4\n  CommsTick = 4\n"
        "  splitsize = 1GB\n  Xyzzy = 1\n  LOG = A @ 0\n"
    )
    assert got == [
        "m.moos:3: unknown pLogger parameter 'WildcardLoging' is ignored"
        " (did you mean 'WildcardLogging'?)",
        "m.moos:4: unknown pLogger parameter 'Pth' is ignored (did you mean 'Path'?)",
        "m.moos:8: unknown pLogger parameter 'Xyzzy' is ignored (no known parameter is close)",
    ]


def test_log_periods_that_are_not_numbers() -> None:
    got = warnings_of(
        "  Log = A @ fast\n  Log = B @ 2s NOSYNC\n  Log = C @ 0.5 nosync monitor\n"
        "  Log = D @ NOSYNC\n  Log = E\n  Log = F @ 1e-1\n"
    )
    assert got == [
        "m.moos:3: Log = A @ fast: the period 'fast' is not a number;"
        " pLogger reads it as 0 s (every post)",
        "m.moos:4: Log = B @ 2s NOSYNC: the period '2s' is not a number; pLogger reads it as 2 s",
    ]


def test_warnings_are_bounded() -> None:
    got = warnings_of("".join(f"  Bogus{i} = 1\n" for i in range(200)))
    assert len(got) == MAX_WARNINGS
    assert got[-1] == "m.moos: and 151 more warnings like these"
