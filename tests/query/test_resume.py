"""Fetches that are cut: a killed client, a stopped vehicle, a session still being written.

Each ends with a session directory byte-identical to the vehicle's, and the resumed run
receives less than the whole session (it continued, it did not start over). Transfers are
slowed with ``--rate`` so the cut lands mid-file.
"""

from __future__ import annotations

import re
import subprocess
import threading
import time
from pathlib import Path

import pytest
from helpers import fleetlog_cmd, free_port, run_cli
from query_support import Fleet, make_session, same_tree, wait_for

from fleetlog.moos.alog import LineFormatter, format_banner
from fleetlog.query.server import LogServer
from fleetlog.storage.catalog import LogCatalog
from fleetlog.transport.session import SessionOptions, open_session

NAME = "GEN_1_1_2025_____00_00_00"
MB = 1 << 20


def received_bytes(stdout: str) -> float:
    """The bytes a fetch says it received (from its summary line)."""
    match = re.search(r"([0-9.]+) (B|KiB|MiB|GiB) received", stdout)
    assert match, stdout
    unit = {"B": 1, "KiB": 1 << 10, "MiB": 1 << 20, "GiB": 1 << 30}[match.group(2)]
    return float(match.group(1)) * unit


@pytest.fixture
def generated(tmp_path: Path) -> tuple[Path, Path]:
    """A 40 MB session: the log root and the session directory."""
    logs = tmp_path / "logs"
    return logs, make_session(logs, NAME, 40)


def start_fetch(fleet: Fleet, out: Path, *extra: str) -> subprocess.Popen[str]:
    return subprocess.Popen(
        fleetlog_cmd("fetch", "gen", NAME, "-o", str(out), *extra, *fleet.zenoh_args()),
        env=fleet.env,
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def half_way(out: Path) -> Path:
    part = out / NAME / f"{NAME}.alog.part"
    wait_for(lambda: part.exists() and part.stat().st_size > 8 * MB, 60, "8 MB of the alog")
    return part


def test_a_killed_client_resumes(
    fleet: Fleet, generated: tuple[Path, Path], tmp_path: Path
) -> None:
    logs, session = generated
    fleet.serve(logs, "gen")
    out = tmp_path / "shore"
    proc = start_fetch(fleet, out, "--rate", "10")
    part = half_way(out)
    proc.kill()
    proc.communicate(timeout=10)
    final = out / NAME / f"{NAME}.alog"
    assert not final.exists()  # never a half file under the real name
    assert (out / NAME / f"{NAME}.alog.part.json").exists()
    cut = part.stat().st_size
    assert 8 * MB < cut < (session / f"{NAME}.alog").stat().st_size
    again = fleet.cli("fetch", "gen", NAME, "-o", str(out))
    assert again.returncode == 0, again.stderr
    same_tree(session, out / NAME)
    total = sum(p.stat().st_size for p in session.iterdir())
    alog = (session / f"{NAME}.alog").stat().st_size
    # Files go smallest first: every other file was here before the alog was cut.
    done_before = cut + sum(p.stat().st_size for p in session.iterdir() if p.stat().st_size < alog)
    # The resumed run fetched the rest (plus a 4 KiB overlap check), not the whole session.
    assert received_bytes(again.stdout) == pytest.approx(total - done_before, abs=0.1 * MB)


def test_a_stopped_vehicle_fails_cleanly_then_resumes(
    fleet: Fleet, generated: tuple[Path, Path], tmp_path: Path
) -> None:
    logs, session = generated
    served = fleet.serve(logs, "gen")
    out = tmp_path / "shore"
    proc = start_fetch(fleet, out, "--rate", "10", "--retry-for", "1")
    half_way(out)
    served.kill()  # the link is cut mid-transfer
    stdout, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 1, stdout
    assert "the same command resumes" in stderr
    assert not (out / NAME / f"{NAME}.alog").exists()
    served.start()
    again = fleet.cli("fetch", "gen", NAME, "-o", str(out))
    assert again.returncode == 0, again.stderr
    same_tree(session, out / NAME)
    total = sum(p.stat().st_size for p in session.iterdir())
    assert received_bytes(again.stdout) < total - 4 * MB


def test_a_vehicle_back_within_the_retry_time_is_waited_for(
    fleet: Fleet, generated: tuple[Path, Path], tmp_path: Path
) -> None:
    logs, session = generated
    served = fleet.serve(logs, "gen")
    out = tmp_path / "shore"
    proc = start_fetch(fleet, out, "--rate", "10")
    half_way(out)
    served.kill()
    time.sleep(1.0)
    served.start()
    _, stderr = proc.communicate(timeout=90)
    assert proc.returncode == 0, stderr
    same_tree(session, out / NAME)


class _Writer:
    """Appends to a live session's alog and blog from a thread, as a recorder would."""

    def __init__(self, session: Path) -> None:
        self.alog = session / f"{session.name}.alog"
        self.blog = session / f"{session.name}.blog"
        self.alog.write_text(format_banner("x", 1750334690.0, "now"))
        self.blog.write_bytes(b"")
        self.stop = threading.Event()
        self.rewrite_at: float | None = None
        self.thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        fmt = LineFormatter()
        t = 0.0
        started = time.monotonic()
        while not self.stop.is_set():
            if self.rewrite_at is not None and time.monotonic() - started > self.rewrite_at:
                self.rewrite_at = None
                # FileTimeStamp = false: pLogger truncates and writes the same name again.
                self.alog.write_text(format_banner("y", 1750334999.0, "later"))
            t += 0.01
            with self.alog.open("a") as file:
                file.write("".join(fmt.double(t, f"X_{i}", "pW", t) for i in range(200)))
            with self.blog.open("ab") as file:
                file.write(bytes(range(256)) * 8)
            time.sleep(0.01)


@pytest.mark.parametrize("rewrite", [False, True], ids=["growing", "rewritten"])
def test_follow_a_session_being_written(
    tmp_path: Path, cli_env: dict[str, str], rewrite: bool
) -> None:
    logs = tmp_path / "logs"
    session = logs / "LIVE_1_1_2025_____00_00_00"
    session.mkdir(parents=True)
    writer = _Writer(session)
    state: dict[str, Path | None] = {"active": session}  # what a recorder tells the server
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    zargs = ["-e", endpoint, "--no-multicast-scouting"]
    zenoh_session = open_session(SessionOptions(listen=(endpoint,), multicast_scouting=False))
    catalog = LogCatalog(logs, vehicle="live", active=lambda: state["active"])
    try:
        with LogServer(zenoh_session, catalog, announce=True):
            writer.thread.start()
            time.sleep(0.3)
            snapshot = run_cli("fetch", "live", "-o", str(tmp_path / "now"), *zargs, env=cli_env)
            assert snapshot.returncode == 0, snapshot.stderr
            assert "still being written" in snapshot.stdout
            kept = tmp_path / "now" / session.name / f"{session.name}.alog"
            assert not kept.exists()
            assert kept.with_name(kept.name + ".part").stat().st_size > 0
            writer.rewrite_at = 1.5 if rewrite else None
            follow = subprocess.Popen(
                fleetlog_cmd("fetch", "live", "--follow", "-o", str(tmp_path / "all"), *zargs),
                env=cli_env,
                stdin=subprocess.DEVNULL,
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
                text=True,
            )
            try:
                time.sleep(3.0)
                writer.stop.set()
                writer.thread.join(5)
                state["active"] = None  # the recorder closed the session
                _, stderr = follow.communicate(timeout=60)
            finally:
                if follow.poll() is None:
                    follow.kill()
                    follow.communicate()
            assert follow.returncode == 0, stderr
            same_tree(session, tmp_path / "all" / session.name)
            # The snapshot's .part resumes into the finished file too.
            again = run_cli("fetch", "live", "-o", str(tmp_path / "now"), *zargs, env=cli_env)
            assert again.returncode == 0, again.stderr
            same_tree(session, tmp_path / "now" / session.name)
    finally:
        zenoh_session.close()
