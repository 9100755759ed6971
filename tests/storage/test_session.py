"""The session writer against real pLogger sessions: mission backups and the file set."""

from __future__ import annotations

from pathlib import Path

import pytest
from helpers import REFERENCE

from fleetlog.moos.alog import Variant, format_banner, format_logstart, parse_banner
from fleetlog.storage.session import SessionLayout, SessionWriter, copy_mission

#: (session directory, the mission file pLogger was given), relative to reference/
BACKUPS = [
    ("themoos_session/MOOSLog_3_2_2025_____09_05_07", "themoos_session/mission.moos"),
    ("ivp_session/LOG_ALPHA_19_6_2025_____12_04_50", "ivp_session/alpha.moos"),
    (
        "captured/runA_themoos_wildcard_restart/logs/TEST_22_11_2026_____11_06_44",
        "captured/runA_themoos_wildcard_restart/test.moos",
    ),
    (
        "captured/runA_themoos_wildcard_restart/logs/TEST_22_11_2026_____11_06_52",
        "captured/runA_themoos_wildcard_restart/test.moos",
    ),
    (
        "captured/runB1_ivp_compressed_markdatatype/LOG_ALPHA_22_11_2026_____11_07_42",
        "captured/runB1_ivp_compressed_markdatatype/test.moos",
    ),
    ("captured/runB2_nofiletimestamp/FIXED", "captured/runB2_nofiletimestamp/fixed.moos"),
    (
        "captured/runB2_nofiletimestamp/glogs/MOOSLog_22_11_2026_____11_08_11",
        "captured/runB2_nofiletimestamp/noblock.moos",
    ),
]


def _variant(logstart: float, text: str) -> Variant:
    for variant in Variant:
        if format_logstart(logstart, variant) == text:
            return variant
    raise AssertionError(f"LOGSTART {text!r} is neither variant's")


@pytest.mark.parametrize(
    ("session", "mission"), BACKUPS, ids=[b[0].split("/")[-1] for b in BACKUPS]
)
def test_mission_backup_is_byte_identical(session: str, mission: str) -> None:
    directory = REFERENCE / session
    (backup,) = directory.glob("*._moos")
    real = backup.read_bytes()
    lines = real.decode("utf-8").split("\n")
    banner = parse_banner(lines[:7], str(backup))
    text = format_banner(
        banner.log_file,
        banner.logstart,
        banner.opened,
        variant=_variant(banner.logstart, banner.logstart_text),
        mark_data_type=banner.mark_data_type,
    )
    # pLogger copies line by line, each line plus "\n": a final "\n" gains an empty line
    assert copy_mission((REFERENCE / mission).read_bytes(), text) == real


def test_mission_backup_keeps_carriage_returns_and_a_missing_final_newline() -> None:
    assert copy_mission(b"A = 1\r\nB = 2", "") == b"A = 1\r\nB = 2\n"
    assert copy_mission(b"A = 1\n", "") == b"A = 1\n\n"
    assert copy_mission(b"", "%%\n") == b"%%\n\n"


@pytest.mark.parametrize(
    ("layout", "expected"),
    [
        (SessionLayout(), {".alog", ".ylog", ".blog"}),
        (
            SessionLayout(sync_log=True, exclusion_log=True),
            {".alog", ".ylog", ".blog", ".slog", ".xlog"},
        ),
        # pLogger opens the compressed xlog even without the exclusion log (an empty stream)
        (SessionLayout(compression="gzip"), {".alog.gz", ".xlog.gz", ".ylog", ".blog"}),
        (SessionLayout(compression="zstd"), {".alog.zst", ".xlog.zst", ".ylog", ".blog"}),
    ],
)
def test_file_set(tmp_path: Path, layout: SessionLayout, expected: set[str]) -> None:
    writer = SessionWriter.open(layout, 1_800_000_000.0, when=1_800_000_000.0, cwd=tmp_path)
    writer.close()
    root = writer.root
    assert {p.name.removeprefix(root) for p in writer.dir_path.iterdir()} == expected
    assert (tmp_path / ".LastOpenedMOOSLogDirectory").read_text() == (
        f"LastOpenedLoggingDirectory=./{root}\n"
    )
    assert writer.directory == f"./{root}"


def test_copies_are_byte_for_byte(tmp_path: Path) -> None:
    writer = SessionWriter.open(
        SessionLayout(), 1_800_000_000.0, when=1_800_000_000.0, cwd=tmp_path
    )
    source = REFERENCE / "ivp_session" / "alpha.bhv"
    target = writer.copy_file(source, "alpha.bhv")
    writer.close()
    assert target.name == "alpha._bhv"
    assert (
        target.read_bytes()
        == (REFERENCE / "ivp_session/LOG_ALPHA_19_6_2025_____12_04_50/alpha._bhv").read_bytes()
    )
