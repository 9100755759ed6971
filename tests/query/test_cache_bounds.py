"""What the log server keeps per file and per session stays bounded, whatever is asked.

A recorder restarted every minute for months, files that grow while they are fetched and
fetches abandoned half way must not make the server's own bookkeeping grow.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import pytest

from fleetlog.moos.alog import LineFormatter, format_banner
from fleetlog.storage import catalog as catalog_module
from fleetlog.storage.catalog import LogCatalog
from fleetlog.storage.confined import ConfinedRoot, DigestCache

MiB = 1 << 20


def _alog(path: Path, names: range, start: float = 0.0) -> None:
    fmt = LineFormatter()
    text = "".join(fmt.double(start + i, f"VAR_{i}", "src", float(i)) for i in names)
    if not path.exists():
        text = format_banner("x", 1.0, "now") + text
    with path.open("a") as file:
        file.write(text)


def test_listing_many_sessions_keeps_bounded_details(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(catalog_module, "_MAX_DETAILS", 8)
    old = time.time() - 600
    for n in range(24):
        session = tmp_path / f"MOOSLog_1_2_2025_____10_00_{n:02d}"
        session.mkdir()
        _alog(session / f"{session.name}.alog", range(n * 100, n * 100 + 100))
        os.utime(session / f"{session.name}.alog", (old, old))
    catalog = LogCatalog(tmp_path, vehicle="v")
    infos = catalog.sessions()
    assert [info.variables for info in infos] == [100] * 24
    # Complete sessions' scans (their sets of names) are let go once their details are known.
    assert catalog.cached() == {"details": 8, "scans": 0, "names": 0}
    assert [info.variables for info in catalog.sessions()] == [100] * 24
    assert catalog.cached()["details"] == 8


def test_a_growing_alog_keeps_one_scan(tmp_path: Path) -> None:
    session = tmp_path / "MOOSLog_1_2_2025_____10_00_00"
    session.mkdir()
    alog = session / f"{session.name}.alog"
    catalog = LogCatalog(tmp_path, vehicle="v", active=lambda: session)
    for step in range(20):
        _alog(alog, range(step * 10, step * 10 + 10), start=step * 10.0)
        info = catalog.session(session.name)
        assert info.variables == (step + 1) * 10
        assert catalog.cached() == {"details": 1, "scans": 1, "names": (step + 1) * 10}
    # Closed: the next listing lets its scan go.
    closed = LogCatalog(tmp_path, vehicle="v", active=lambda: None)
    closed._details, closed._scans = catalog._details, catalog._scans
    _alog(alog, range(200, 201), start=200.0)
    assert closed.session(session.name).variables == 201
    assert closed.cached() == {"details": 1, "scans": 0, "names": 0}


def test_digests_of_a_file_that_grows_while_fetched_are_let_go(tmp_path: Path) -> None:
    # A file of a session taken for complete grows while clients fetch it, over and over:
    # each version's digest in progress, and the ranges it holds ahead of their turn, can
    # never finish, and must not stay.
    (tmp_path / "S").mkdir()
    path = tmp_path / "S" / "f"
    root = ConfinedRoot(tmp_path)
    cache = DigestCache(max_running=8, max_pending=64 * MiB)
    for version in range(6):
        with path.open("ab") as file:
            file.write(os.urandom(3 * MiB))
        for offset in (0, 2 * MiB):  # the second range arrives ahead of the one before it
            data, st, steady = root.read_steady(("S", "f"), offset, MiB)
            assert steady
            cache.feed(st, offset, data)
        held = cache.held()
        assert held["running"] == 1, version
        assert held["pending"] == MiB, version


def test_ranges_of_an_abandoned_fetch_give_way(tmp_path: Path) -> None:
    now = [0.0]
    (tmp_path / "S").mkdir()
    root = ConfinedRoot(tmp_path)
    for name in ("a", "b"):
        (tmp_path / "S" / name).write_bytes(os.urandom(4 * MiB))
    cache = DigestCache(max_pending=2 * MiB, idle=30.0, clock=lambda: now[0])

    def feed(name: str, offset: int) -> None:
        data, st, _ = root.read_steady(("S", name), offset, MiB)
        cache.feed(st, offset, data)

    feed("a", 0)
    feed("a", 2 * MiB)
    feed("a", 3 * MiB)  # "a" holds 2 MiB ahead of their turn: all there is room for
    feed("b", 0)
    feed("b", 2 * MiB)  # no room while "a" may still continue
    assert cache.held()["pending"] == 2 * MiB
    now[0] = 31.0  # nobody fed "a" since: its ranges give way to "b"'s
    feed("b", 2 * MiB)
    assert cache.held() == {"digests": 0, "running": 2, "pending": MiB}
