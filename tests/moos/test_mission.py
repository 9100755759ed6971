"""Tests for fleetlog.moos.mission: MOOS mission-file syntax and pLogger's configuration."""

from __future__ import annotations

import contextlib
import dataclasses
import re
import string
from collections.abc import Callable

import pytest
from helpers import REFERENCE
from hypothesis import given, settings
from hypothesis import strategies as st

from fleetlog.errors import MissionError
from fleetlog.moos.mission import (
    LoggerConfig,
    LogSpec,
    Mission,
    Param,
    parse_log_spec,
    parse_mission,
)


def mission(text: str, env: dict[str, str] | None = None) -> Mission:
    return parse_mission(text, "m.moos", env)


def config(block_body: str, head: str = "", app: str = "pLogger") -> LoggerConfig:
    """Return the LoggerConfig of a mission with one pLogger block holding ``block_body``."""
    text = f"{head}\nProcessConfig = {app}\n{{\n{block_body}\n}}\n"
    return mission(text).logger_config(app)


def assert_error(text: str, expected: str, env: dict[str, str] | None = None) -> None:
    with pytest.raises(MissionError, match=re.escape(expected)) as info:
        mission(text, env)
    assert str(info.value) == expected


def assert_config_error(body: str, expected: str, head: str = "") -> None:
    text = f"{head}\nProcessConfig = pLogger\n{{\n{body}\n}}\n"
    parsed = mission(text)
    with pytest.raises(MissionError, match=re.escape(expected)) as info:
        parsed.logger_config()
    assert str(info.value) == expected


# --------------------------------------------------------------------------------------------
# The real missions in tests/data/reference


def read_reference(relative: str) -> Mission:
    path = REFERENCE / relative
    return parse_mission(path.read_text(), str(path))


BASE = LoggerConfig()

REAL_MISSIONS = {
    "ivp_session/alpha.moos": dataclasses.replace(
        BASE,
        file="LOG_ALPHA",
        path=".",
        log_aux_src=True,
        wildcard_logging=True,
        wildcard_omit_patterns=("MISSION_FILE", "*_STATUS", "DB_VARSUMMARY"),
        wildcard_exclusion_log=True,
        log_specs=(LogSpec("IVPHELM_LIFE_EVENT", 0.0, sync=False, monitor=False),),
        community="alpha",
    ),
    "themoos_session/mission.moos": dataclasses.replace(
        BASE,
        path=".",
        sync_log=True,
        sync_period=1.0,
        double_precision=3,
        dynamic_sync_log_columns=2,
        mark_external_community_messages=True,
        log_specs=(
            LogSpec("NAV_X", 0.0, sync=True, monitor=False),
            LogSpec("NAV_Y", 0.0, sync=True, monitor=False),
            LogSpec("NAV_HEADING", 0.5, sync=True, monitor=False),
            LogSpec("MISSION_STATE", 0.0, sync=False, monitor=False),
            LogSpec("CAMERA_FRAME", 0.0, sync=False, monitor=False),
            LogSpec("GPS_FIX", 0.0, sync=False, monitor=True),
        ),
        community="auv",
    ),
    "captured/runA_themoos_wildcard_restart/test.moos": dataclasses.replace(
        BASE,
        file="TEST",
        path="/home/alpha/mission/logs",
        sync_log=True,
        sync_period=0.5,
        log_aux_src=True,
        dynamic_sync_log_columns=2,
        wildcard_logging=True,
        wildcard_omit_patterns=("MISSION_FILE", "*_STATUS"),
        wildcard_exclusion_log=True,
        log_specs=(
            LogSpec("NAV_X", 0.0, sync=True, monitor=False),
            LogSpec("NAV_Y", 0.0, sync=True, monitor=False),
            LogSpec("DEPLOY", 0.0, sync=False, monitor=False),
            LogSpec("EMPTY", 0.0, sync=False, monitor=False),
            LogSpec("MULTI", 0.0, sync=False, monitor=False),
            LogSpec("BIN", 0.0, sync=False, monitor=False),
            LogSpec("NAV_HEADING", 0.0, sync=True, monitor=False),
            LogSpec("TINY", 0.0, sync=True, monitor=False),
            LogSpec("NEG", 0.0, sync=True, monitor=False),
            LogSpec("GPS_FIX", 0.0, sync=False, monitor=True),
        ),
        community="test",
        moos_time_warp=1.0,
    ),
    "captured/runB1_ivp_compressed_markdatatype/test.moos": dataclasses.replace(
        BASE,
        file="LOG_ALPHA",
        path="/nonexistent/dir",
        compress_alogs="gzip",
        mark_data_type=True,
        utc_log_directories=True,
        log_aux_src=True,
        logging_directory_summary_file="./summary.txt",
        log_specs=(
            LogSpec("NAV_X", 0.0, sync=True, monitor=False),
            LogSpec("NAV_Y", 0.0, sync=False, monitor=False),
            LogSpec("DEPLOY", 0.0, sync=True, monitor=False),
            LogSpec("EMPTY", 0.0, sync=True, monitor=False),
            LogSpec("BIN", 0.0, sync=True, monitor=False),
            LogSpec("NAV_HEADING", 0.0, sync=True, monitor=False),
        ),
        community="ivp",
    ),
    "captured/runB2_nofiletimestamp/fixed.moos": dataclasses.replace(
        BASE,
        file="FIXED",
        path=".",
        file_timestamp=False,
        log_specs=(LogSpec("NAV_X", 0.0, sync=True, monitor=False),),
        community="nb",
    ),
    "captured/runB2_nofiletimestamp/noblock.moos": dataclasses.replace(
        BASE,
        path="./glogs",
        wildcard_logging=True,
        community="nb",
    ),
}


@pytest.mark.parametrize("relative", sorted(REAL_MISSIONS))
def test_real_mission_logger_config(relative: str) -> None:
    assert read_reference(relative).logger_config() == REAL_MISSIONS[relative]


def test_real_mission_slog_columns_match_the_captured_slog() -> None:
    cfg = read_reference("captured/runA_themoos_wildcard_restart/test.moos").logger_config()
    slog = next((REFERENCE / "captured/runA_themoos_wildcard_restart/logs").glob("*/*.slog"))
    header = [
        line.split(") ", 1)[1].strip()
        for line in slog.read_text().splitlines()
        if line.startswith("%%   (")
    ]
    assert header[0] == "TIME"
    columns = header[1 : 1 + len(cfg.sync_columns)]
    assert cfg.sync_columns == tuple(columns) == ("NAV_X", "NAV_Y", "NAV_HEADING", "TINY", "NEG")
    assert len(header) - 1 - len(columns) == cfg.dynamic_sync_log_columns
    assert cfg.monitored == ("GPS_FIX",)


def test_real_mission_structure() -> None:
    parsed = read_reference("ivp_session/alpha.moos")
    assert list(parsed.blocks) == ["pLogger"]
    block = parsed.block("pLogger")
    assert block is not None
    assert block.lineno == 5
    assert block.params[0] == Param("AppTick", "8", 7)
    assert block.get("path") == "./"
    assert parsed.global_value("ServerHost") == "localhost"
    assert parsed.global_value("serverport") == "9000"
    assert parsed.community == "alpha"
    assert parsed.text == (REFERENCE / "ivp_session/alpha.moos").read_text()


def test_real_mission_every_prefix_parses_or_raises_mission_error() -> None:
    text = (REFERENCE / "captured/runA_themoos_wildcard_restart/test.moos").read_text()
    for end in range(len(text) + 1):
        with contextlib.suppress(MissionError):
            parse_mission(text[:end])


# --------------------------------------------------------------------------------------------
# §9 syntax: lines, comments, quotes


def test_whole_line_and_end_of_line_comments() -> None:
    parsed = mission(
        "// header\n"
        "   // indented comment\n"
        "Community = alpha // the community\n"
        "ProcessConfig = pLogger // the logger\n"
        "{ // opens\n"
        "  // File = COMMENTED\n"
        "  File = LOG // trailing\n"
        "} // closes\n"
    )
    block = parsed.block("pLogger")
    assert block is not None
    assert block.params == (Param("File", "LOG", 7),)
    assert parsed.community == "alpha"


def test_first_quoted_pair_is_unwrapped_and_protects_comment_marker() -> None:
    parsed = mission(
        "ProcessConfig = pLogger\n"
        "{\n"
        '  Path = "http://host/x"\n'
        '  File = "a // b" // comment\n'
        '  Note = "one" "two//three"\n'
        '  Early = x // "y"\n'
        "}\n"
    )
    block = parsed.block("pLogger")
    assert block is not None
    assert block.get("Path") == "http://host/x"
    assert block.get("File") == "a // b"
    # only the first pair is unwrapped; the second pair's // still starts a comment
    assert block.get("Note") == 'one "two'
    assert block.get("Early") == "x"


def test_leading_whitespace_blank_lines_and_crlf() -> None:
    text = (
        "\r\n \t Community = c\r\n\r\n  ProcessConfig = pLogger\r\n\t{\r\n   File = X Y \r\n  }\r\n"
    )
    parsed = mission(text)
    block = parsed.block("pLogger")
    assert block is not None
    assert block.params == (Param("File", "X Y", 6),)
    assert block.raw == (Param("File", "XY", 6),)
    assert parsed.community == "c"


def test_only_newline_separates_lines() -> None:
    # a lone CR is not a line break for MOOS (getline splits at \n only)
    parsed = mission("ProcessConfig = pLogger\n{\nFile = A\rB\n}\n")
    block = parsed.block("pLogger")
    assert block is not None
    assert block.get("File") == "A\rB"
    assert block.raw_values("File") == (Param("File", "AB", 3),)


# --------------------------------------------------------------------------------------------
# §9 syntax: blocks


@pytest.mark.parametrize(
    "line",
    [
        "ProcessConfig = pLogger",
        "processconfig=PLOGGER",
        "PROCESSCONFIG   =   pLogger   ",
        "\tProcessConfig\t=\tp Logger",
    ],
)
def test_process_config_line_is_case_insensitive_without_blanks(line: str) -> None:
    parsed = mission(f"{line}\n{{\nFile = X\n}}\n")
    for name in ("pLogger", "PLOGGER", "plogger", "p logger"):
        block = parsed.block(name)
        assert block is not None
        assert block.get("file") == "X"
    assert parsed.logger_config().file == "X"


def test_block_name_is_kept_as_written_and_other_blocks_are_separate() -> None:
    parsed = mission(
        "ProcessConfig = pHelmIvP\n{\n  Behaviors = a.bhv\n}\n"
        "ProcessConfig = PLOGGER\n{\n  File = L\n}\n"
    )
    assert list(parsed.blocks) == ["pHelmIvP", "PLOGGER"]
    assert parsed.blocks["PLOGGER"].lineno == 5
    assert parsed.block("pLogger") is parsed.blocks["PLOGGER"]
    assert parsed.block("pMarineViewer") is None


def test_duplicate_block_first_wins() -> None:
    parsed = mission(
        "ProcessConfig = pLogger\n{\n  File = FIRST\n}\nProcessConfig = PLOGGER\n{\n  File = X\n}\n"
    )
    assert list(parsed.blocks) == ["pLogger"]
    assert parsed.logger_config().file == "FIRST"


def test_text_after_brace_lines_is_ignored_as_moos_does() -> None:
    parsed = mission("ProcessConfig = pLogger\n{ ignored\n  File = A\n}x\n")
    block = parsed.block("pLogger")
    assert block is not None
    assert block.params == (Param("File", "A", 3),)


def test_empty_block_exists() -> None:
    parsed = mission("ProcessConfig = pLogger\n{\n}\n")
    block = parsed.block("pLogger")
    assert block is not None
    assert block.params == ()
    assert parsed.logger_config().wildcard_logging is False


# --------------------------------------------------------------------------------------------
# §9 syntax: parameters


def test_parameter_names_case_insensitive_first_wins_trimmed_inner_kept() -> None:
    parsed = mission(
        "ProcessConfig = pLogger\n"
        "{\n"
        "  FILE   =   My  Log   \n"
        "  file = SECOND\n"
        "  Path =\n"
        "  Path = \t \n"
        "  Path = /data/a b/\n"
        "  Eq = a=b = c\n"
        "}\n"
    )
    block = parsed.block("pLogger")
    assert block is not None
    assert block.get("File") == "My  Log"
    assert block.param("file") == Param("FILE", "My  Log", 3)
    assert block.get("PATH") == "/data/a b/"
    assert block.param("path") == Param("Path", "/data/a b/", 7)
    assert block.get("eq") == "a=b = c"
    assert block.get("missing") is None
    assert [p.lineno for p in block.params] == [3, 4, 7, 8]


def test_raw_list_removes_spaces_tabs_and_crs() -> None:
    parsed = mission(
        "ProcessConfig = pLogger\n{\n  Log = NAV_X @ 0 NOSYNC\r\n  Wild Card Pattern =\tA_*, B\n}\n"
    )
    block = parsed.block("pLogger")
    assert block is not None
    assert block.raw == (
        Param("Log", "NAV_X@0NOSYNC", 3),
        Param("WildCardPattern", "A_*,B", 4),
    )
    assert block.raw_values("log") == (Param("Log", "NAV_X@0NOSYNC", 3),)
    assert block.params[1] == Param("Wild Card Pattern", "A_*, B", 4)


# --------------------------------------------------------------------------------------------
# §9 syntax: define and ${NAME}


def test_define_expansion_in_values_names_and_process_config() -> None:
    parsed = mission(
        "define: APP = pLogger\n"
        "define: STEM=LOG_ALPHA\n"
        "ProcessConfig = ${APP}\n"
        "{\n"
        "  File = ${STEM}_x\n"
        "  ${KEY} = v\n"
        "}\n"
        "define: KEY = Path\n",
    )
    block = parsed.block("pLogger")
    assert block is not None
    assert block.get("File") == "LOG_ALPHA_x"
    assert block.get("Path") == "v"  # a define applies before its line too
    assert parsed.defines == {"APP": "pLogger", "STEM": "LOG_ALPHA", "KEY": "Path"}


def test_define_removes_all_whitespace_and_last_wins() -> None:
    parsed = mission(
        "define: A = one\ndefine: A = t w o\nProcessConfig = pLogger\n{\n  File = ${A}\n}\n"
    )
    assert parsed.logger_config().file == "two"


def test_define_lines_are_neither_params_nor_expanded() -> None:
    parsed = mission(
        "ProcessConfig = pLogger\n{\n  define: X = ${Y}\n  File = [${X}]\n}\n",
        env={"Y": "env-y"},
    )
    block = parsed.block("pLogger")
    assert block is not None
    assert block.params == (Param("File", "[${Y}]", 4),)  # one pass, no recursion


def test_environment_is_the_fallback_and_defines_win() -> None:
    text = "define: A = from_define\nProcessConfig = pLogger\n{\n  File = ${A}-${HOME}\n}\n"
    parsed = mission(text, env={"A": "from_env", "HOME": "/home/x"})
    assert parsed.logger_config().file == "from_define-/home/x"


def test_variables_in_comments_are_not_expanded() -> None:
    parsed = mission("// ${NOPE}\nCommunity = c // ${NOPE}\n")
    assert parsed.community == "c"


def test_env_none_means_empty_environment() -> None:
    with pytest.raises(MissionError, match=re.escape("${HOME} is not defined")):
        parse_mission("Community = ${HOME}\n")


# --------------------------------------------------------------------------------------------
# §9 file scope


def test_file_scope_scans_whole_file_first_wins_whitespace_removed() -> None:
    parsed = mission(
        "ProcessConfig = pHelm\n{\n  GlobalLogPath = /in side/block\n}\n"
        "GLOBALLOGPATH = /later\n"
        "Community =\n"
        "community = alpha\n"
    )
    assert parsed.global_value("globallogpath") == "/inside/block"
    assert parsed.global_param("GlobalLogPath") == Param("GlobalLogPath", "/inside/block", 3)
    assert parsed.global_value("Community") == ""
    assert parsed.community is None  # the first Community line is empty
    assert parsed.global_value("ServerHost") is None
    assert parsed.global_value("ProcessConfig") == "pHelm"


def test_community_defaults_to_none() -> None:
    assert mission("ServerPort = 9000\n").community is None


# --------------------------------------------------------------------------------------------
# Errors: exact messages


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        pytest.param(
            "Community = a\nProcessConfig = pLogger\n{\n  File = X\n",
            "m.moos:2: the block of ProcessConfig = pLogger is never closed by a line "
            "beginning with '}'",
            id="unterminated-block",
        ),
        pytest.param(
            "ProcessConfig = pLogger\n  File = X\n{\n}\n",
            "m.moos:1: ProcessConfig = pLogger must be followed by a line beginning with '{', "
            "not 'File = X' on line 2",
            id="no-brace-after-process-config",
        ),
        pytest.param(
            "\nProcessConfig = pLogger\n// nothing else\n",
            "m.moos:2: ProcessConfig = pLogger must be followed by a line beginning with '{', "
            "not the end of the file",
            id="no-brace-at-end-of-file",
        ),
        pytest.param(
            "ProcessConfig = pLogger\ndefine: A = 1\n{\n}\n",
            "m.moos:1: ProcessConfig = pLogger must be followed by a line beginning with '{', "
            "not 'define: A = 1' on line 2",
            id="define-before-brace",
        ),
        pytest.param(
            "ProcessConfig = pLogger\n{\n}\n  }\n",
            "m.moos:4: '}' closes no open ProcessConfig block",
            id="stray-close",
        ),
        pytest.param(
            "Community = a\n{\n}\n",
            "m.moos:2: '{' does not follow a ProcessConfig line",
            id="stray-open",
        ),
        pytest.param(
            "ProcessConfig = pLogger\n{\n  File = ${STEM}\n}\n",
            "m.moos:3: ${STEM} is not defined by a 'define:' line or in the environment",
            id="undefined-variable",
        ),
        pytest.param(
            "Community = ${OPEN\n",
            "m.moos:1: '${' in 'Community = ${OPEN' has no closing '}'",
            id="unclosed-variable",
        ),
        pytest.param(
            "Community = ${}x\n",
            "m.moos:1: '${}' in 'Community = ${}x' names no variable",
            id="empty-variable",
        ),
        pytest.param(
            "ProcessConfig = pLogger\n{\n  AppTick 4\n}\n",
            "m.moos:3: line 'AppTick 4' in the block of ProcessConfig = pLogger has no '='",
            id="param-without-equals",
        ),
        pytest.param(
            "ProcessConfig = pLogger\n{\n  = 4\n}\n",
            "m.moos:3: line '= 4' in the block of ProcessConfig = pLogger has no parameter "
            "name before '='",
            id="param-without-name",
        ),
        pytest.param(
            "ProcessConfig = pLogger\n{\n  File = X\nProcessConfig = pHelmIvP\n{\n}\n",
            "m.moos:4: ProcessConfig = pHelmIvP appears inside the block of "
            "ProcessConfig = pLogger opened on line 1, which is not closed",
            id="nested-process-config",
        ),
        pytest.param(
            "ProcessConfig = pLogger\n{\n  {\n}\n",
            "m.moos:3: '{' cannot open a block inside the block of ProcessConfig = pLogger "
            "opened on line 1",
            id="nested-brace",
        ),
        pytest.param(
            "ProcessConfig = pLogger {\n  File = X\n}\n",
            "m.moos:1: '{' must be on its own line after ProcessConfig = pLogger",
            id="brace-on-process-config-line",
        ),
        pytest.param(
            "ProcessConfig =\n{\n}\n",
            "m.moos:1: ProcessConfig line names no application",
            id="process-config-without-name",
        ),
        pytest.param(
            "define: NAME\n",
            "m.moos:1: define line 'define: NAME' has no '='",
            id="define-without-equals",
        ),
        pytest.param(
            "define: = 3\n",
            "m.moos:1: define line 'define: = 3' has no name before '='",
            id="define-without-name",
        ),
    ],
)
def test_bad_mission_messages(text: str, expected: str) -> None:
    assert_error(text, expected)


def test_error_uses_given_path() -> None:
    with pytest.raises(MissionError) as info:
        parse_mission("}\n", "/missions/alpha.moos")
    assert str(info.value) == "/missions/alpha.moos:1: '}' closes no open ProcessConfig block"
    assert info.value.path == "/missions/alpha.moos"
    assert info.value.lineno == 1
    with pytest.raises(MissionError, match=re.escape("<mission>:1: ")):
        parse_mission("}\n")


@pytest.mark.parametrize(
    ("body", "expected"),
    [
        ("  DoublePrecision = abc", "m.moos:4: DoublePrecision value 'abc' is not an integer"),
        ("  doubleprecision = 3.5", "m.moos:4: doubleprecision value '3.5' is not an integer"),
        ("  DoublePrecision = -1", "m.moos:4: DoublePrecision value '-1' is negative"),
        (
            "  DynamicSyncLogColumns = two",
            "m.moos:4: DynamicSyncLogColumns value 'two' is not an integer",
        ),
        ("  SyncLog = true @ fast", "m.moos:4: SyncLog period 'fast' is not a number"),
        ("  LogFormat = moos", "m.moos:4: LogFormat value 'moos' is neither 'ivp' nor 'em'"),
        ("  Log = @ 0", "m.moos:4: log entry '@0' names no variable before '@'"),
        ("\n  Log = X @ -1", "m.moos:5: log entry 'X@-1' has a negative period"),
    ],
)
def test_bad_parameter_messages(body: str, expected: str) -> None:
    assert_config_error(body, expected)


@pytest.mark.parametrize(
    ("head", "expected"),
    [
        ("MOOSTimeWarp = fast", "m.moos:1: MOOSTimeWarp value 'fast' is not a number"),
        ("MOOSTimeWarp = 0", "m.moos:1: MOOSTimeWarp value '0' is not greater than 0"),
    ],
)
def test_bad_file_scope_messages(head: str, expected: str) -> None:
    assert_config_error("", expected, head=head)


# --------------------------------------------------------------------------------------------
# Log = VAR @ period [NOSYNC] [MONITOR] (§6.5, §12)


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("NAV_X @ 0", LogSpec("NAV_X", 0.0, sync=True, monitor=False)),
        ("NAV_X@0.2", LogSpec("NAV_X", 0.2, sync=True, monitor=False)),
        ("DESIRED_SPEED @ 0.5 NOSYNC", LogSpec("DESIRED_SPEED", 0.5, sync=False, monitor=False)),
        ("X @ NOSYNC", LogSpec("X", 0.0, sync=False, monitor=False)),
        ("X @ 0 NOSYNC MONITOR", LogSpec("X", 0.0, sync=False, monitor=True)),
        ("X @ 3 monitor", LogSpec("X", 3.0, sync=True, monitor=True)),
        ("X @ 1 nosync", LogSpec("X", 1.0, sync=False, monitor=False)),
        ("X @ 1 NoSync MoNiToR", LogSpec("X", 1.0, sync=False, monitor=True)),
        ("X", LogSpec("X", 2.0, sync=True, monitor=False)),
        ("X NOSYNC", LogSpec("XNOSYNC", 2.0, sync=True, monitor=False)),
        ("X MONITOR", LogSpec("XMONITOR", 2.0, sync=True, monitor=False)),
        ("X @", LogSpec("X", 2.0, sync=True, monitor=False)),
        ("X @ ,0.3", LogSpec("X", 2.0, sync=True, monitor=False)),
        ("X @ 0.5, NOSYNC", LogSpec("X", 0.5, sync=False, monitor=False)),
        ("X @ 1.5abc", LogSpec("X", 1.5, sync=True, monitor=False)),
        ("X @ .25", LogSpec("X", 0.25, sync=True, monitor=False)),
        ("X @ 1e-3", LogSpec("X", 0.001, sync=True, monitor=False)),
        ("X @ 2e", LogSpec("X", 2.0, sync=True, monitor=False)),
        ("X @ +4", LogSpec("X", 4.0, sync=True, monitor=False)),
        ("X @ 0x10", LogSpec("X", 16.0, sync=True, monitor=False)),
        ("X @ abc", LogSpec("X", 0.0, sync=True, monitor=False)),
        ("X @ 1 @ 2", LogSpec("X", 1.0, sync=True, monitor=False)),
        ("  A B\t@\t1 ", LogSpec("AB", 1.0, sync=True, monitor=False)),
        ("X @ 1\nNOSYNC", LogSpec("X", 1.0, sync=False, monitor=False)),
    ],
)
def test_parse_log_spec(text: str, expected: LogSpec) -> None:
    assert parse_log_spec(text) == expected


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("@ 0", "log entry '@ 0' names no variable before '@'"),
        ("", "log entry '' names no variable before '@'"),
        ("   ", "log entry '' names no variable before '@'"),
        ("X @ -0.5", "log entry 'X @ -0.5' has a negative period"),
        ("X @ inf", "log entry 'X @ inf' has a period that is not a finite number"),
        ("X @ nan", "log entry 'X @ nan' has a period that is not a finite number"),
    ],
)
def test_parse_log_spec_errors(text: str, expected: str) -> None:
    with pytest.raises(MissionError, match=re.escape(expected)) as info:
        parse_log_spec(text)
    assert str(info.value) == expected


def test_parse_log_spec_error_location() -> None:
    with pytest.raises(MissionError) as info:
        parse_log_spec("@1", lineno=12, path="a.moos")
    assert str(info.value) == "a.moos:12: log entry '@1' names no variable before '@'"
    with pytest.raises(MissionError) as info:
        parse_log_spec("@1", lineno=3)
    assert str(info.value) == "line 3: log entry '@1' names no variable before '@'"


def test_log_spec_to_text() -> None:
    assert LogSpec("A", 0.5, sync=False, monitor=True).to_text() == "A @ 0.5 NOSYNC MONITOR"
    assert LogSpec("B").to_text() == "B @ 2.0"


# --------------------------------------------------------------------------------------------
# LoggerConfig (§1, §3.1, §5, §6.4-6.7, §12)


def test_default_without_mission_file() -> None:
    cfg = LoggerConfig.default()
    assert cfg == dataclasses.replace(BASE, wildcard_logging=True, dynamic_sync_log_columns=10)
    assert (cfg.file, cfg.path, cfg.file_timestamp, cfg.async_log) == ("MOOSLog", ".", True, True)
    assert cfg.wildcard_omit_patterns == ("MISSION_FILE",)
    assert cfg.variant == "ivp"
    assert cfg.compress_alogs == "none"
    assert LoggerConfig.default("pLogger_B").app_name == "pLogger_B"


def test_empty_block_gives_plogger_defaults() -> None:
    assert config("") == BASE
    assert BASE.logging_directory_summary_file == ".LastOpenedMOOSLogDirectory"
    assert BASE.dynamic_sync_log_columns == 0
    assert BASE.double_precision == 5
    assert BASE.sync_period == 1.0


def test_no_block_turns_wildcard_on_and_keeps_file_scope() -> None:
    parsed = mission(
        "Community = nb\nGlobalLogPath = ./glogs/\nMOOSTimeWarp = 10\n"
        "ProcessConfig = pLogger\n{\n  File = OTHER\n}\n"
    )
    cfg = parsed.logger_config("pLogger_B")
    assert cfg == dataclasses.replace(
        BASE,
        app_name="pLogger_B",
        path="./glogs",
        wildcard_logging=True,
        community="nb",
        moos_time_warp=10.0,
    )
    assert parsed.logger_config("PLOGGER").file == "OTHER"


@pytest.mark.parametrize(
    ("head", "body", "expected"),
    [
        ("", "", "."),
        ("", "  Path = ./", "."),
        ("", "  Path = /data/logs/", "/data/logs"),
        ("", '  Path = "/data/logs//"', "/data/logs/"),
        ("", "  Path = /data/logs//", "/data/logs"),  # an unquoted // starts a comment
        ("", "  Path = logs", "logs"),
        ("", "  Path = /", ""),
        ("", "  Path = /my logs/", "/my logs"),
        ("GlobalLogPath = /global/", "  Path = /block/", "/global"),
        ("GlobalLogPath = / glo bal", "  Path = /block/", "/global"),
        ("GlobalLogPath =", "  Path = /block/", "/block"),
    ],
)
def test_path(head: str, body: str, expected: str) -> None:
    assert config(body, head).path == expected


def test_global_log_path_inside_another_block_still_wins() -> None:
    text = (
        "ProcessConfig = pLogger\n{\n  Path = /block\n}\n"
        "ProcessConfig = pShare\n{\n  GlobalLogPath = /shared\n}\n"
    )
    assert mission(text).logger_config().path == "/shared"


@pytest.mark.parametrize(
    ("value", "sync_log", "period"),
    [
        ("true", True, 1.0),
        ("TRUE", True, 1.0),
        ("true @ 0.5", True, 0.5),
        ("True@2", True, 2.0),
        ("t r u e @ 0 . 5", True, 0.5),
        ("true @ 0.01", True, 0.1),
        ("true @ -3", True, 0.1),
        ("true @", True, 1.0),
        ("1", False, 1.0),
        ("1 @ 0.5", False, 0.5),
        ("false @ 2", False, 2.0),
        ("yes", False, 1.0),
    ],
)
def test_sync_log(value: str, sync_log: bool, period: float) -> None:
    cfg = config(f"  SyncLog = {value}")
    assert (cfg.sync_log, cfg.sync_period) == (sync_log, period)


@pytest.mark.parametrize(
    ("value", "expected"),
    [
        ("true", True),
        ("TRUE", True),
        ("tRuE", True),
        ("1", True),
        ("0.5", True),
        ("2e0", True),
        ("+3", True),
        ("false", False),
        ("0", False),
        ("0.0", False),
        ("-1", False),
        ("yes", False),
        ("on", False),
        ("1 true", False),
        ("1x", False),
    ],
)
def test_booleans(value: str, expected: bool) -> None:
    cfg = config(
        f"  LogAuxSrc = {value}\n  FileTimeStamp = {value}\n  MarkDataType = {value}\n"
        f"  UTCLogDirectories = {value}\n  MarkExternalCommunityMessages = {value}\n"
        f"  WildcardExclusionLog = {value}\n  WildcardLogging = {value}"
    )
    assert cfg.log_aux_src is expected
    assert cfg.file_timestamp is expected
    assert cfg.mark_data_type is expected
    assert cfg.utc_log_directories is expected
    assert cfg.mark_external_community_messages is expected
    assert cfg.wildcard_exclusion_log is expected
    assert cfg.wildcard_logging is expected


def test_async_log_and_wildcard_forcing_it() -> None:
    assert config("  AsyncLog = false").async_log is False
    assert config("  AsyncLog = false\n  WildcardLogging = true").async_log is True
    assert config("  ASYNCLOG = FALSE\n  wildcardlogging = 1").async_log is True


@pytest.mark.parametrize(
    ("value", "expected"),
    [
        (None, "none"),
        ("false", "none"),
        ("0", "none"),
        ("none", "none"),
        ("true", "gzip"),
        ("TRUE", "gzip"),
        ("1", "gzip"),
        ("zstd", "zstd"),
        ("ZSTD", "zstd"),
        ("gzip", "gzip"),
        ("GZip", "gzip"),
    ],
)
def test_compress_alogs(value: str | None, expected: str) -> None:
    body = "" if value is None else f"  CompressAlogs = {value}"
    assert config(body).compress_alogs == expected


def test_integers() -> None:
    cfg = config("  DoublePrecision = 3\n  DynamicSyncLogColumns = 4")
    assert (cfg.double_precision, cfg.dynamic_sync_log_columns) == (3, 4)
    assert config("  doubleprecision = +0").double_precision == 0


def test_wildcard_patterns() -> None:
    cfg = config(
        "  WildcardLogging = true\n"
        "  WildcardPattern = NAV_*, DESIRED_*\n"
        "  WildCardPattern = A B ,, C\n"
        "  wildcardpattern =\n"
        "  WildCardOmitPattern = *_STATUS , APPCAST\n"
        "  WILDCARDOMITPATTERN = DB_VARSUMMARY\n"
    )
    assert cfg.wildcard_patterns == ("NAV_*", "DESIRED_*", "AB", "C")
    assert cfg.wildcard_omit_patterns == ("MISSION_FILE", "*_STATUS", "APPCAST", "DB_VARSUMMARY")


def test_log_specs_first_wins_and_always_logged_left_out() -> None:
    cfg = config(
        "  Log = NAV_X @ 0\n"
        "  log = NAV_Y @ 0.5 NOSYNC\n"
        "  LOG = NAV_X @ 1 MONITOR\n"
        "  Log = nav_x @ 3\n"
        "  Log = MOOS_DEBUG @ 5\n"
        "  Log = MOOS_SYSTEM\n"
        "  Log =\n"
        "  L og = SPACED @ 0\n"
    )
    assert cfg.log_specs == (
        LogSpec("NAV_X", 0.0, sync=True, monitor=False),
        LogSpec("NAV_Y", 0.5, sync=False, monitor=False),
        LogSpec("nav_x", 3.0, sync=True, monitor=False),
        LogSpec("SPACED", 0.0, sync=True, monitor=False),
    )
    assert cfg.sync_columns == ("NAV_X", "nav_x", "SPACED")
    assert cfg.monitored == ()


def test_strings() -> None:
    cfg = config(
        "  File = LOG ALPHA\n  LoggingDirectorySummaryFile = ./summary.txt\n",
        head="Community = alpha",
    )
    assert cfg.file == "LOG ALPHA"
    assert cfg.logging_directory_summary_file == "./summary.txt"
    assert cfg.community == "alpha"
    assert cfg.app_name == "pLogger"


@pytest.mark.parametrize(
    ("helm", "expected"),
    [
        ("ProcessConfig = pHelm\n{\n  TaskFile = alpha.hoof\n}\n", "alpha.hoof"),
        ("ProcessConfig = pHelmIvP\n{\n  TaskFile = a b.hoof\n}\n", "a b.hoof"),
        (
            "ProcessConfig = pHelmIvP\n{\n  TaskFile = ivp.hoof\n}\n"
            "ProcessConfig = pHelm\n{\n  TaskFile = helm.hoof\n}\n",
            "helm.hoof",
        ),
        ("ProcessConfig = pHelmIvP\n{\n  Behaviors = alpha.bhv\n}\n", None),
        ("", None),
    ],
)
def test_helm_task_file(helm: str, expected: str | None) -> None:
    assert config("", head=helm).helm_task_file == expected


@pytest.mark.parametrize(
    ("body", "expected"),
    [
        ("", "ivp"),
        ("  LogFormat = em", "em"),
        ("  logformat = EM", "em"),
        ("  LogFormat=IvP", "ivp"),
    ],
)
def test_variant(body: str, expected: str) -> None:
    assert config(body).variant == expected


def test_copy_file_dirs() -> None:
    assert config("").copy_file_dirs == ()
    cfg = config("  CopyFileDirs = /home/a/mission, ./bhv ,\n  copyfiledirs = /my dir")
    assert cfg.copy_file_dirs == ("/home/a/mission", "./bhv", "/my dir")


@pytest.mark.parametrize(
    ("head", "expected"),
    [("", 1.0), ("MOOSTimeWarp = 10", 10.0), ("moostimewarp = 0.5", 0.5), ("MOOSTimeWarp =", 1.0)],
)
def test_moos_time_warp(head: str, expected: float) -> None:
    assert config("", head=head).moos_time_warp == expected


# --------------------------------------------------------------------------------------------
# Properties


_NAMES = st.text(alphabet="abXY_7", min_size=1, max_size=3)
_VALUE_CHARS = string.ascii_letters + string.digits + " \t=/.,@*:;{}[]()#$%-+'"
_VALUES = (
    st.text(alphabet=_VALUE_CHARS, min_size=1, max_size=12)
    .map(lambda text: text.strip(" \t"))
    .filter(lambda text: bool(text) and "//" not in text and "${" not in text)
)
_CASINGS: st.SearchStrategy[Callable[[str], str]] = st.sampled_from(
    [str.upper, str.lower, str.swapcase, lambda text: text]
)
_SPACE = st.sampled_from(["", " ", "\t", "   ", " \t "])
_TRAILER = st.sampled_from(["", " ", "\t", "\r", "  // note", "\t// x = y"])
_FILLER = st.sampled_from([None, "", "   ", "// comment", "  \t// ProcessConfig = x"])


@st.composite
def _block_missions(draw: st.DrawFn) -> tuple[str, list[Param]]:
    """Render a random pLogger block; return the text and the params as they should parse."""
    lines = [draw(_FILLER) or "", draw(st.sampled_from(["Community = c", "ServerPort = 1"]))]
    lines.append(
        draw(
            st.sampled_from(
                [
                    "ProcessConfig = pLogger",
                    "processconfig=PLOGGER",
                    "  PROCESSCONFIG  =  pLogger  ",
                    "\tProcessConfig\t=\tp Logger // the logger",
                ]
            )
        )
    )
    lines.append(draw(st.sampled_from(["{", "  {", "\t{  // open"])))
    expected: list[Param] = []
    for name, value in draw(st.lists(st.tuples(_NAMES, _VALUES), max_size=12)):
        filler = draw(_FILLER)
        if filler is not None:
            lines.append(filler)
        written = draw(_CASINGS)(name)
        lines.append(
            f"{draw(_SPACE)}{written}{draw(_SPACE)}={draw(_SPACE)}{value}{draw(_SPACE)}"
            f"{draw(_TRAILER)}"
        )
        expected.append(Param(written, value, len(lines)))
    lines.append(draw(st.sampled_from(["}", "  }", "} // end"])))
    return "\n".join(lines) + draw(st.sampled_from(["", "\n", "\n\n"])), expected


@settings(max_examples=200, deadline=None)
@given(_block_missions())
def test_property_block_parameters_first_wins(case: tuple[str, list[Param]]) -> None:
    text, expected = case
    parsed = parse_mission(text)
    block = parsed.block("pLogger")
    assert block is not None
    assert list(block.params) == expected
    assert list(block.raw) == [
        Param(p.name, p.value.replace(" ", "").replace("\t", ""), p.lineno) for p in expected
    ]
    first: dict[str, str] = {}
    for param in expected:
        first.setdefault(param.name.upper(), param.value)
    for name, value in first.items():
        assert block.get(name.lower()) == value
        assert block.get(name) == value
        assert parsed.global_value(name.swapcase()) == value.replace(" ", "").replace("\t", "")


_VARS = st.from_regex(r"[A-Za-z_][A-Za-z0-9_]{0,15}", fullmatch=True)
_PERIODS = st.floats(min_value=0, max_value=1e9, allow_nan=False, allow_infinity=False)
_FLAG_CASINGS = st.sampled_from([str.upper, str.lower, str.title, str.swapcase])


@st.composite
def _log_spec_texts(draw: st.DrawFn) -> tuple[str, LogSpec]:
    var = draw(_VARS)
    period = draw(_PERIODS)
    period_text = draw(st.sampled_from([repr(period), f"{period:.3f}", f"{period:e}"]))
    nosync = draw(st.booleans())
    monitor = draw(st.booleans())
    flags = []
    if nosync:
        flags.append(draw(_FLAG_CASINGS)("NOSYNC"))
    if monitor:
        flags.append(draw(_FLAG_CASINGS)("MONITOR"))
    flags = draw(st.permutations(flags))
    parts = [var, "@", period_text, *flags]
    text = draw(_SPACE)
    for part in parts:
        text += part + draw(_SPACE)
    return text, LogSpec(var, float(period_text), sync=not nosync, monitor=monitor)


@settings(max_examples=200, deadline=None)
@given(_log_spec_texts())
def test_property_log_spec_round_trip(case: tuple[str, LogSpec]) -> None:
    text, expected = case
    spec = parse_log_spec(text)
    assert spec == expected
    assert parse_log_spec(spec.to_text()) == spec


@settings(max_examples=100, deadline=None)
@given(_VARS, st.lists(st.sampled_from(["NOSYNC", "monitor", "x"]), max_size=3), _SPACE)
def test_property_log_spec_without_at_glues_flags(var: str, extra: list[str], space: str) -> None:
    text = space.join([var, *extra])
    assert parse_log_spec(text) == LogSpec("".join([var, *extra]), 2.0, sync=True, monitor=False)


@settings(max_examples=200, deadline=None)
@given(st.text(alphabet=st.sampled_from(list('ab={}/"$ \t\r\n#@:ProcesCnfig')), max_size=80))
def test_property_any_text_parses_or_raises_mission_error(text: str) -> None:
    try:
        parsed = parse_mission(text)
    except MissionError:
        return
    with contextlib.suppress(MissionError):
        parsed.logger_config()
