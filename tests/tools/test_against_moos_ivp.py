"""fleetlog grep and info against the real MOOS-IvP aloggrep and alogscan.

The tools are built by hand from the public moos-ivp sources, outside the repository, and
found through ``MOOSIVP_BIN`` (the folder holding ``aloggrep`` and ``alogscan``). Without it
these tests are SKIPPED, and say so. On the reference sessions recorded by the real pLogger
the answers must be the same, except where docs/reading.md says they differ: aloggrep and
alogscan drop entries whose time is negative (their parser wants a digit first, §7.1), and
alogscan drops entries with an empty value.
"""

from __future__ import annotations

import math
import os
import subprocess
from pathlib import Path

import pytest
from helpers import REFERENCE, run_cli

from fleetlog.storage.columnar import AlogReader
from fleetlog.tools import open_log, scan_log

FOLDER = Path(os.environ.get("MOOSIVP_BIN", "/nonexistent"))
MISSING = (
    "MOOSIVP_BIN is not set to a folder holding aloggrep and alogscan (built by hand from the"
    " public moos-ivp sources): the comparisons with the MOOS-IvP tools are SKIPPED"
)
needs_tools = pytest.mark.skipif(
    not (FOLDER / "aloggrep").is_file() or not (FOLDER / "alogscan").is_file(), reason=MISSING
)
LOGS = sorted(p for p in REFERENCE.rglob("*.alog") if p.is_file())


def _entries(text: str) -> list[str]:
    return [line for line in text.splitlines() if line and not line.startswith("%")]


def _whole_and_positive(line: str) -> bool:
    return line[:1].isdigit()


@needs_tools
@pytest.mark.parametrize("path", LOGS, ids=lambda p: p.name)
@pytest.mark.parametrize("keys", [["NAV_X"], ["pHelmIvP", "NAV_*"], ["DB_TIME", "iTest"]])
def test_grep_gives_what_aloggrep_gives(path: Path, keys: list[str]) -> None:
    theirs = subprocess.run(
        [str(FOLDER / "aloggrep"), str(path), *keys, "-q"],
        capture_output=True,
        text=True,
        check=True,
        timeout=60,
    ).stdout
    ours = run_cli("grep", str(path), *keys)
    assert ours.returncode == 0, ours.stderr
    # aloggrep drops negative times and keeps no continuation lines (docs/reading.md)
    mine = [line for line in _entries(ours.stdout) if _whole_and_positive(line)]
    assert mine == _entries(theirs)


@needs_tools
@pytest.mark.parametrize("path", LOGS, ids=lambda p: p.name)
def test_info_counts_what_alogscan_counts(path: Path) -> None:
    theirs = subprocess.run(
        [str(FOLDER / "alogscan"), str(path), "--nocolors"],
        capture_output=True,
        text=True,
        check=False,
        timeout=60,
    ).stdout
    info = scan_log(open_log(path))
    if "Empty log file" in theirs:
        # every entry has a negative time (re-delivered before pLogger started): alogscan
        # reads none of them
        assert info.first is not None
        assert info.last is not None
        assert info.last < 0
        return
    counts: dict[str, int] = {}
    table = theirs.split("-------------", 1)[-1]
    for line in table.splitlines():
        fields = line.split()
        if len(fields) >= 5 and fields[1].replace(",", "").isdigit():
            counts[fields[0]] = int(fields[1].replace(",", ""))
    assert counts, theirs
    with AlogReader(path) as reader:
        entries = list(reader.entries())
    for name, count in counts.items():
        # alogscan leaves out negative times and empty values (§7.1); fleetlog counts them
        valid = [e for e in entries if e.key == name and math.copysign(1, e.offset) > 0]
        assert count == sum(1 for e in valid if e.text != ""), name
        assert info.variables[name].count == sum(1 for e in entries if e.key == name)
