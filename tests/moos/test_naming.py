"""Tests for fleetlog.moos.naming: session roots, directories, copy names, hint file, ctime."""

from __future__ import annotations

import calendar
import time
from datetime import datetime

import pytest
from helpers import REFERENCE
from hypothesis import given, settings
from hypothesis import strategies as st

from fleetlog.errors import FormatError
from fleetlog.moos.naming import (
    HINT_FILE_NAME,
    copy_file_name,
    ctime_text,
    hint_file_content,
    normalize_log_path,
    parse_hint_file,
    parse_session_root,
    session_dir,
    session_root,
    unique_root,
)

file_names = st.text(alphabet="ABC_019-.", max_size=12)
datetimes = st.datetimes(min_value=datetime(1000, 1, 1), max_value=datetime(9999, 12, 31))


def utc(text: str) -> time.struct_time:
    """A struct_time in UTC from ``YYYY-MM-DD hh:mm:ss``."""
    return time.gmtime(calendar.timegm(time.strptime(text, "%Y-%m-%d %H:%M:%S")))


# --------------------------------------------------------------------------------------------
# Session roots


@pytest.mark.parametrize(
    ("file", "when", "root"),
    [
        ("MOOSLog", "2025-02-03 09:05:07", "MOOSLog_3_2_2025_____09_05_07"),
        ("LOG_ALPHA", "2025-06-19 12:04:50", "LOG_ALPHA_19_6_2025_____12_04_50"),
        ("TEST", "2026-11-22 11:06:44", "TEST_22_11_2026_____11_06_44"),
        ("TEST", "2026-11-22 11:06:52", "TEST_22_11_2026_____11_06_52"),
        ("MOOSLog", "2026-11-22 11:08:11", "MOOSLog_22_11_2026_____11_08_11"),
        ("X", "2030-12-31 00:00:00", "X_31_12_2030_____00_00_00"),
        ("", "2025-01-01 01:02:03", "_1_1_2025_____01_02_03"),
    ],
)
def test_session_root_reference_names(file: str, when: str, root: str) -> None:
    as_struct = utc(when)
    as_datetime = datetime.strptime(when, "%Y-%m-%d %H:%M:%S")
    assert session_root(file, as_struct, True) == root
    assert session_root(file, as_datetime, True) == root
    parsed = parse_session_root(root)
    assert parsed == (file, as_datetime)


def test_session_root_reference_directories() -> None:
    """Every time-stamped directory in the reference tree parses and rebuilds to itself."""
    if not REFERENCE.is_dir():
        pytest.skip("no reference tree")
    seen = 0
    for directory in REFERENCE.rglob("*"):
        if not directory.is_dir():
            continue
        parsed = parse_session_root(directory.name)
        if parsed is None:
            continue
        file, when = parsed
        assert session_root(file, when, True) == directory.name
        assert session_root(file, when.timetuple(), True) == directory.name
        seen += 1
    assert seen >= 5  # MOOSLog_3_2_2025…, LOG_ALPHA_19_6_2025…, TEST_…44, TEST_…52, …


def test_session_root_without_time_stamp() -> None:
    assert session_root("FIXED", None, False) == "FIXED"
    assert session_root("FIXED", utc("2025-02-03 09:05:07"), False) == "FIXED"
    assert parse_session_root("FIXED") is None


def test_session_root_needs_a_time() -> None:
    with pytest.raises(FormatError, match="needs the opening time"):
        session_root("MOOSLog", None, True)


@settings(max_examples=300)
@given(file_names, datetimes)
def test_session_root_round_trip(file: str, when: datetime) -> None:
    when = when.replace(microsecond=0)
    root = session_root(file, when, True)
    assert session_root(file, when.timetuple(), True) == root
    assert parse_session_root(root) == (file, when)
    assert " " not in root


@pytest.mark.parametrize(
    "name",
    [
        "MOOSLog",
        "MOOSLog_03_2_2025_____09_05_07",  # day is never zero-padded
        "MOOSLog_3_02_2025_____09_05_07",
        "MOOSLog_3_2_2025____09_05_07",  # four underscores
        "MOOSLog_3_2_2025_____9_05_07",  # hour is always two digits
        "MOOSLog_31_2_2025_____09_05_07",  # no 31 February
        "MOOSLog_3_13_2025_____09_05_07",
        "MOOSLog_3_2_2025_____24_05_07",
        "MOOSLog_3_2_2025_____09_05_61",
        "MOOSLog_3_2_2025_____09_05_07-1",  # the first session has no suffix
        "MOOSLog_3_2_2025_____09_05_07-02",
        "MOOSLog_3_2_2025_____09_05_07_2",
        "MOOSLog_3_2_2025_____09_05_07 2",
    ],
)
def test_parse_session_root_rejects(name: str) -> None:
    assert parse_session_root(name) is None


def test_parse_session_root_leap_second() -> None:
    assert parse_session_root("X_31_12_2016_____23_59_60") == ("X", datetime(2017, 1, 1))


# --------------------------------------------------------------------------------------------
# Directories and unique roots


@pytest.mark.parametrize(
    ("path", "normalized"),
    [
        ("./", "."),
        (".", "."),
        ("/data/logs/", "/data/logs"),
        ("/data/logs", "/data/logs"),
        ("logs//", "logs/"),  # exactly one slash goes
        ("/", ""),
        ("", ""),
    ],
)
def test_normalize_log_path(path: str, normalized: str) -> None:
    assert normalize_log_path(path) == normalized


def test_session_dir() -> None:
    root = "MOOSLog_3_2_2025_____09_05_07"
    assert session_dir(normalize_log_path("./"), root) == "./" + root
    assert session_dir(normalize_log_path("/data/logs/"), root) == "/data/logs/" + root
    assert session_dir("/home/alpha/mission/logs", "TEST_22_11_2026_____11_06_52") == (
        "/home/alpha/mission/logs/TEST_22_11_2026_____11_06_52"
    )
    assert session_dir(normalize_log_path("/"), "R") == "/R"


def test_unique_root() -> None:
    root = "TEST_22_11_2026_____11_06_44"
    taken: set[str] = set()
    assert unique_root(root, taken.__contains__) == root
    names = []
    for _ in range(12):
        name = unique_root(root, taken.__contains__)
        taken.add(name)
        names.append(name)
    assert names[:3] == [root, root + "-2", root + "-3"]
    assert len(set(names)) == 12
    # Every name still reads as the same second, in the order the sessions were opened.
    parsed = [parse_session_root(n) for n in names]
    assert all(p is not None and p[0] == "TEST" for p in parsed)
    times = [p[1] for p in parsed if p is not None]
    assert all(t.replace(microsecond=0) == datetime(2026, 11, 22, 11, 6, 44) for t in times)
    assert times == sorted(times)
    assert sorted(names, key=lambda n: parse_session_root(n) or ("", datetime.min)) == names
    for name in names:
        assert " " not in name
        assert "." not in name


def test_unique_root_gives_up() -> None:
    with pytest.raises(FormatError, match="already in that second"):
        unique_root("R", lambda _: True)


def test_sessions_sort_by_time_stamp() -> None:
    names = [
        "TEST_22_11_2026_____11_06_52",
        "TEST_22_11_2026_____11_06_44-2",
        "TEST_9_11_2026_____23_00_00",
        "TEST_22_11_2026_____11_06_44",
    ]
    ordered = sorted(names, key=lambda n: parse_session_root(n) or ("", datetime.min))
    assert ordered == [
        "TEST_9_11_2026_____23_00_00",
        "TEST_22_11_2026_____11_06_44",
        "TEST_22_11_2026_____11_06_44-2",
        "TEST_22_11_2026_____11_06_52",
    ]


# --------------------------------------------------------------------------------------------
# Copy names


@pytest.mark.parametrize(
    ("path", "copy"),
    [
        ("alpha.bhv", "alpha._bhv"),
        ("/etc/hostname", "hostname._bak"),
        ("a/b.c.d", "b.c._d"),
        ("./missions/alpha.bhv", "alpha._bhv"),
        ("dir.x/file", "file._bak"),  # a dot in a directory does not count
        ("file.", "file._bak"),  # an empty extension is no extension
        (".bashrc", "._bashrc"),
        ("/home/u/.bashrc", "._bashrc"),
        ("a/..", ".._bak"),
        ("plain", "plain._bak"),
    ],
)
def test_copy_file_name(path: str, copy: str) -> None:
    assert copy_file_name(path) == copy


@pytest.mark.parametrize("path", ["", "/", "dir/", "a/b/"])
def test_copy_file_name_needs_a_file(path: str) -> None:
    with pytest.raises(FormatError, match="names no file"):
        copy_file_name(path)


def test_copy_file_name_reference() -> None:
    """The ivp_session copied ``alpha.bhv`` to ``alpha._bhv``."""
    session = REFERENCE / "ivp_session" / "LOG_ALPHA_19_6_2025_____12_04_50"
    if not session.is_dir():
        pytest.skip("no reference tree")
    assert (session / copy_file_name(str(REFERENCE / "ivp_session" / "alpha.bhv"))).is_file()


# --------------------------------------------------------------------------------------------
# Hint file


def test_hint_file_content() -> None:
    assert hint_file_content("./MOOSLog_3_2_2025_____09_05_07") == (
        "LastOpenedLoggingDirectory=./MOOSLog_3_2_2025_____09_05_07\n"
    )
    assert HINT_FILE_NAME == ".LastOpenedMOOSLogDirectory"


@pytest.mark.parametrize(
    "directory",
    ["./LOG_ALPHA_19_6_2025_____12_04_50", "/home/alpha/mission/logs/X", "./FIXED", "a=b", " x "],
)
def test_hint_file_round_trip(directory: str) -> None:
    text = hint_file_content(directory)
    assert parse_hint_file(text) == directory
    assert parse_hint_file(text.rstrip("\n")) == directory
    assert parse_hint_file(text.replace("\n", "\r\n")) == directory


def test_hint_file_reference() -> None:
    files = [*REFERENCE.rglob(HINT_FILE_NAME), *REFERENCE.rglob("summary.txt")]
    if not files:
        pytest.skip("no reference tree")
    for path in files:
        text = path.read_text()
        directory = parse_hint_file(text, str(path))
        assert hint_file_content(directory) == text


@pytest.mark.parametrize(
    "text",
    [
        "",
        "\n",
        "LastOpenedLoggingDirectory=\n",
        "LastOpenedMOOSLogDirectory=./x\n",
        "lastopenedloggingdirectory=./x\n",
        "LastOpenedLoggingDirectory=./x\nLastOpenedLoggingDirectory=./y\n",
        "LastOpenedLoggingDirectory=./x\n\n",
        " LastOpenedLoggingDirectory=./x\n",
        "LastOpenedLoggingDirectory=./x\rjunk",
    ],
)
def test_parse_hint_file_rejects(text: str) -> None:
    with pytest.raises(FormatError) as info:
        parse_hint_file(text, "summary.txt")
    assert info.value.path == "summary.txt"
    assert str(info.value).startswith("summary.txt:1: ")


# --------------------------------------------------------------------------------------------
# ctime


def test_ctime_text_epoch() -> None:
    assert ctime_text(time.gmtime(0)) == "Thu Jan  1 00:00:00 1970"
    assert ctime_text(datetime(1970, 1, 1)) == "Thu Jan  1 00:00:00 1970"
    assert ctime_text(datetime(1969, 12, 31, 19)) == "Wed Dec 31 19:00:00 1969"
    assert ctime_text(datetime(2025, 6, 19, 12, 4, 50)) == "Thu Jun 19 12:04:50 2025"


@settings(max_examples=300)
@given(st.integers(min_value=-(2**34), max_value=2**37))
def test_ctime_text_matches_c_asctime(seconds: int) -> None:
    struct = time.gmtime(seconds)
    assert ctime_text(struct) == time.asctime(struct)
    when = datetime(*struct[:6])
    assert ctime_text(when) == time.asctime(struct)
