"""Fixtures of the bridge tests: a real MOOSDB (``MOOS_BIN``), umm clients, the CLI.

Without ``MOOS_BIN`` the tests that need a real MOOSDB are skipped, each with the reason,
and the session's summary ends with a loud line saying how many and why.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from helpers import Proc
from moos_support import MISSING, MoosDB, Umm, moos_bin


@pytest.fixture
def moos_folder() -> Path:
    folder = moos_bin()
    if folder is None:
        pytest.skip(MISSING)
    return folder


@pytest.fixture
def moosdbs(moos_folder: Path, tmp_path: Path) -> Iterator[Callable[..., MoosDB]]:
    """Start real MOOSDBs (``make(community)``); stop them at the end."""
    made: list[MoosDB] = []

    def make(community: str = "alpha", *, start: bool = True, port: int | None = None) -> MoosDB:
        db = MoosDB(moos_folder, tmp_path / f"moosdb-{community}-{len(made)}", community, port)
        made.append(db)
        return db.start() if start else db

    yield make
    for db in made:
        db.stop()


@pytest.fixture
def umms(moos_folder: Path, tmp_path: Path) -> Iterator[Callable[..., Umm]]:
    """Start umm clients (``make(db, name, *args)``); stop them at the end."""
    made: list[Umm] = []

    def make(db: MoosDB, name: str, *args: str) -> Umm:
        client = Umm(moos_folder, tmp_path / "umm", db, name, *args)
        made.append(client)
        return client

    yield make
    for client in made:
        client.stop()


@pytest.fixture
def procs(tmp_path: Path, cli_env: dict[str, str]) -> Iterator[Callable[..., Proc]]:
    """Start ``fleetlog`` subprocesses in ``tmp_path``; kill leftovers at the end."""
    made: list[Proc] = []

    def make(*args: str, cwd: Path | None = None) -> Proc:
        proc = Proc(list(args), cwd or tmp_path, cli_env)
        made.append(proc)
        return proc

    yield make
    for proc in made:
        proc.close()


def pytest_terminal_summary(terminalreporter: pytest.TerminalReporter) -> None:
    skipped = [
        r
        for r in terminalreporter.stats.get("skipped", [])
        if "MOOS_BIN" in str(getattr(r, "longrepr", ""))
    ]
    if skipped:
        terminalreporter.write_sep(
            "!", f"{len(skipped)} tests against a real MOOSDB SKIPPED", red=True, bold=True
        )
        terminalreporter.write_line(MISSING, red=True, bold=True)
