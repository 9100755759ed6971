"""The offline tools: output re-read by the line parser (the oracle) and compared with it."""

from __future__ import annotations

import io
import json
from pathlib import Path

import pytest
from alog_oracle import AlogReader as OracleReader
from helpers import REFERENCE, run_cli

from fleetlog.errors import UsageError
from fleetlog.moos.alog import Entry, LineFormatter, format_banner
from fleetlog.storage.select import Selection
from fleetlog.tools import grep_log, merge_logs, open_log, scan_log, sort_log

IVP = REFERENCE / "ivp_session/LOG_ALPHA_19_6_2025_____12_04_50"
RUN_A1 = REFERENCE / "captured/runA_themoos_wildcard_restart/logs/TEST_22_11_2026_____11_06_44"
THEMOOS = REFERENCE / "themoos_session/MOOSLog_3_2_2025_____09_05_07"


def oracle(path: Path) -> list[Entry]:
    with OracleReader(path, errors="skip") as reader:
        return list(reader.entries())


def reread(data: bytes, tmp_path: Path, name: str = "out.alog") -> tuple[OracleReader, list[Entry]]:
    path = tmp_path / name
    path.write_bytes(data)
    reader = OracleReader(path)
    return reader, list(reader.entries())


def strip_lineno(entries: list[Entry]) -> list[tuple[object, ...]]:
    return [(e.offset, e.key, e.source, e.text) for e in entries]


@pytest.mark.parametrize("session", [IVP, RUN_A1, THEMOOS], ids=lambda p: p.name)
def test_grep_keeps_the_banner_and_the_matching_lines_byte_for_byte(
    session: Path, tmp_path: Path
) -> None:
    log = open_log(session)
    out = io.BytesIO()
    result = grep_log(log, out, Selection(keys=("NAV_*", "pHelmIvP")))
    expected = [
        e
        for e in oracle(log.path)
        if e.key.startswith("NAV_") or e.source.split(":")[0] == "pHelmIvP"
    ]
    reader, got = reread(out.getvalue(), tmp_path)
    assert strip_lineno(got) == strip_lineno(expected)
    assert result.matched == len(expected) > 0
    if log.path.suffix == ".alog":
        original = log.path.read_bytes()
        lines = out.getvalue().split(b"\n")
        banner = reader.banner.lines if reader.banner else 0
        assert lines[:banner] == original.split(b"\n")[:banner]
        for line in lines[banner:]:
            assert line == b"" or line in original


def test_clip_first_and_final(tmp_path: Path) -> None:
    log = open_log(IVP)
    out = io.BytesIO()
    grep_log(log, out, Selection(low=1.2, high=1.9))
    _, got = reread(out.getvalue(), tmp_path)
    assert got
    assert all(1.2 <= e.offset <= 1.9 for e in got)
    assert len(got) == sum(1 for e in oracle(log.path) if 1.2 <= e.offset <= 1.9)
    first, final = io.BytesIO(), io.BytesIO()
    grep_log(log, first, Selection(keys=("NAV_*",)), first=True)
    grep_log(log, final, Selection(keys=("NAV_*",)), final=True)
    nav = [e for e in oracle(log.path) if e.key.startswith("NAV_")]
    assert strip_lineno(reread(first.getvalue(), tmp_path, "f.alog")[1]) == strip_lineno(nav[:1])
    assert strip_lineno(reread(final.getvalue(), tmp_path, "l.alog")[1]) == strip_lineno(nav[-1:])
    with pytest.raises(UsageError, match="exclude"):
        grep_log(log, io.BytesIO(), Selection(), first=True, final=True)


def _shuffled_log(path: Path) -> list[float]:
    fmt = LineFormatter()
    offsets = [5.0, 1.0, 3.0, 2.0, 4.0, 0.5]
    text = format_banner("./s/s.alog", 1000.0, "Thu Jan  1 00:00:00 1970")
    text += "".join(fmt.double(o, "X", "p", o) for o in offsets)
    path.write_text(text)
    return offsets


def test_sort_orders_within_the_window_and_counts_the_rest(tmp_path: Path) -> None:
    path = tmp_path / "s.alog"
    offsets = _shuffled_log(path)
    out = io.BytesIO()
    result = sort_log(open_log(path), out, window=10)
    _, got = reread(out.getvalue(), tmp_path)
    assert [e.offset for e in got] == sorted(offsets)
    assert result.late == 0
    small = sort_log(open_log(path), io.BytesIO(), window=1)
    assert small.late > 0


def test_merge_puts_vehicles_on_one_clock(tmp_path: Path) -> None:
    a, b = open_log(IVP), open_log(THEMOOS, "bravo")
    out = io.BytesIO()
    result = merge_logs([a, b], out)
    reader, got = reread(out.getvalue(), tmp_path)
    starts = {}
    for log in (a, b):
        with OracleReader(log.path) as r:
            starts[log.vehicle] = r.logstart
    assert reader.logstart == pytest.approx(min(starts.values()), abs=0.01)
    assert result.entries == len(got) == len(oracle(a.path)) + len(oracle(b.path))
    times = [reader.logstart + e.offset for e in got]
    assert times == sorted(times)
    assert {e.source.rsplit("@", 1)[-1] for e in got} == {"alpha", "bravo"}
    bravo = [
        (round(reader.logstart + e.offset, 2), e.key) for e in got if e.source.endswith("@bravo")
    ]
    expected = [(round(starts["bravo"] + e.offset, 2), e.key) for e in oracle(b.path)]
    assert sorted(bravo) == sorted(expected)


def test_info_counts_what_the_oracle_reads() -> None:
    log = open_log(RUN_A1)
    info = scan_log(log)
    entries = oracle(log.path)
    assert info.entries == len(entries)
    for name, var in info.variables.items():
        mine = [e for e in entries if e.key == name]
        assert var.count == len(mine)
        assert var.first == min(e.offset for e in mine)
        assert var.sources == sorted({e.source for e in mine})
    assert json.loads(json.dumps(info.to_json()))["entries"] == len(entries)


def test_cli_tools_as_subprocesses(tmp_path: Path) -> None:
    out = tmp_path / "g.alog"
    done = run_cli("grep", str(IVP), "NAV_X", "-o", str(out))
    assert done.returncode == 0, done.stderr
    assert [e.key for e in reread(out.read_bytes(), tmp_path, "r.alog")[1]] == ["NAV_X", "NAV_X"]
    info = run_cli("info", str(IVP), "--json")
    assert info.returncode == 0, info.stderr
    assert json.loads(info.stdout)["vehicle"] == "alpha"
    bad = run_cli("clip", str(tmp_path / "missing.alog"), "0", "1")
    assert bad.returncode != 0
    assert "no such alog" in bad.stderr
    assert "Traceback" not in bad.stderr
