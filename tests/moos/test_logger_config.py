"""Missions an operator (or an attacker who can edit one) gets wrong: one-line errors (issue 10).

Each bad setting gives a :class:`MissionError` naming the file, the line and the setting,
before any session starts, instead of a traceback at start or a recorder that dies at its
first sample.
"""

from __future__ import annotations

import pytest

from fleetlog.errors import MissionError
from fleetlog.moos.logger_config import MAX_DOUBLE_PRECISION, MAX_DYNAMIC_COLUMNS, LoggerConfig
from fleetlog.moos.mission import parse_log_spec, parse_mission


def config_of(body: str, head: str = "") -> LoggerConfig:
    text = f"{head}ProcessConfig = pLogger\n{{\n{body}\n}}\n"
    return parse_mission(text, "bad.moos").logger_config()


@pytest.mark.parametrize(
    ("head", "body", "message"),
    [
        ("", "  Path = " + "p" * 300, r"bad.moos:3: Path value has a component of 300 bytes"),
        ("", "  Path = a/" + "p" * 256 + "/b", r"bad.moos:3: Path value has a component of 256"),
        ("", "  Path = " + "a/" * 2100, r"bad.moos:3: Path value is 4200 bytes long: at most"),
        ("GlobalLogPath = " + "g" * 256 + "\n", "", r"bad.moos:1: GlobalLogPath value has a"),
        ("", "  File = caf\udce9", r"bad.moos:3: File value 'caf\\udce9' is not UTF-8 text"),
        ("", "  Path = \udcff", r"bad.moos:3: Path value '\\udcff' is not UTF-8 text"),
        ("", "  File = " + "f" * 201, r"bad.moos:3: File value has a component of 201 bytes"),
        ("", "  File = d/" + "f" * 201, r"bad.moos:3: File value has a component of 201 bytes"),
        ("", "  LoggingDirectorySummaryFile = " + "s" * 256, r"bad.moos:3: LoggingDirectory"),
        ("", "  CopyFileDirs = " + "c" * 256, r"bad.moos:3: CopyFileDirs value has a component"),
        (
            "",
            "  DoublePrecision = 99999999999",
            r"bad.moos:3: DoublePrecision value '99999999999' is too large: at most 30",
        ),
        (
            "",
            "  DynamicSyncLogColumns = 99999999999",
            r"bad.moos:3: DynamicSyncLogColumns value '99999999999' is too large: at most 1000",
        ),
        ("", "  SyncLog = true @ 1e999", r"bad.moos:3: SyncLog period '1e999' is not a finite"),
        ("MOOSTimeWarp = 1e999\n", "", r"bad.moos:1: MOOSTimeWarp value '1e999' is not a finite"),
        ("", "  Log = A\x1cB @ 0", r"bad.moos:3: log entry .* unprintable characters"),
        ("", "  Log = A\u2028B @ 0", r"bad.moos:3: log entry .* unprintable characters"),
    ],
)
def test_bad_setting_is_one_error_naming_file_line_and_setting(
    head: str, body: str, message: str
) -> None:
    with pytest.raises(MissionError, match=message) as caught:
        config_of(body, head)
    assert "\n" not in str(caught.value)


def test_helm_task_file_path_is_checked() -> None:
    text = "ProcessConfig = pHelmIvP\n{\n  TaskFile = " + "t" * 300 + "\n}\n"
    with pytest.raises(MissionError, match=r"bad.moos:3: TaskFile value has a component"):
        parse_mission(text, "bad.moos").logger_config()


def test_limits_themselves_are_accepted() -> None:
    cfg = config_of(
        f"  DoublePrecision = {MAX_DOUBLE_PRECISION}\n"
        f"  DynamicSyncLogColumns = {MAX_DYNAMIC_COLUMNS}\n"
        "  File = " + "f" * 200 + "\n"
        "  Path = " + "p" * 255 + "/x\n"
        "  Log = café\udcff @ 0"
    )
    assert cfg.double_precision == MAX_DOUBLE_PRECISION
    assert cfg.dynamic_sync_log_columns == MAX_DYNAMIC_COLUMNS
    assert cfg.file == "f" * 200
    assert cfg.log_specs[0].var == "café\udcff"


def test_log_request_with_a_control_character_is_refused() -> None:
    with pytest.raises(MissionError, match="unprintable"):
        parse_log_spec("X\x00Y @ 0")
