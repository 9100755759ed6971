"""The disk guard and retention on a small disk the test mounts (a tmpfs), with real files.

The recorder runs with a fake clock (so its once-a-second checks are stepped), on a real
file system whose free space really runs out; retention's deletions are real too.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from recorder_support import T0, Rig, mount_tmpfs, mounts, rigs

from fleetlog.storage.download import sha256_file
from fleetlog.storage.leases import FileLeases

__all__ = ["mounts", "rigs"]  # the fixtures, imported

BIG = "x" * 10_000


def sessions(rig: Rig) -> list[str]:
    return sorted(p.name for p in rig.rec.log_root.iterdir() if p.is_dir())


def step(rig: Rig, seconds: float) -> None:
    """Advance the clock and run the drain loop's tick, then wait for retention."""
    rig.clock.t += seconds
    rig.rec.tick()
    assert rig.rec.retention_idle()


def ack(rig: Rig, name: str) -> None:
    directory = rig.rec.log_root / name
    files = {p.name: sha256_file(p) for p in directory.iterdir() if p.is_file()}
    assert rig.control({"cmd": "ack", "session": name, "files": files}).ok


def session_with_data(rig: Rig, samples: int) -> str:
    """Write ``samples`` big samples a second apart into the open session; return its name."""
    for _ in range(samples):
        rig.send("A", BIG, at=rig.clock.t - T0 + 1.0)
    rig.rec.flush()
    assert rig.rec.session is not None
    return rig.rec.session.root


def test_the_guard_stops_before_the_disk_is_full_counts_and_resumes(
    tmp_path: Path, mounts: list[Path], rigs: Callable[..., Rig]
) -> None:
    mount_tmpfs(tmp_path / "logs", "8m")
    mounts.append(tmp_path / "logs")
    rig = rigs("File = R\nPath = logs\nLog = A @ 0\nMinFreeDisk = 2MB")
    rig.rec.start()
    first = rig.rec.session
    assert first is not None
    sent = 0
    while rig.rec.session is not None and sent < 2000:
        rig.send("A", BIG, at=rig.clock.t - T0 + 0.1)
        sent += 1
        if sent % 10 == 0:
            rig.rec.flush()
            step(rig, 0.0)
    assert rig.rec.session is None, "the guard never stopped writing"
    disk = rig.rec.status()["disk"]
    assert disk["stopped"] is not None
    assert "below MinFreeDisk 2.0 MB" in disk["stopped"]
    assert disk["stops"] == 1
    assert any("disk guard:" in d for d in rig.debugs())
    assert rig.rec.stats.write_errors == 0  # stopped before the disk was full
    assert disk["free"] >= 1_000_000
    # Meanwhile: counted lost, never written; the unacknowledged session is not removed.
    lost = rig.rec.stats.lost
    for _ in range(50):
        rig.send("A", BIG, at=rig.clock.t - T0 + 0.1)
    step(rig, 1.0)
    step(rig, 1.0)
    assert rig.rec.stats.lost == lost + 50
    assert rig.rec.session is None
    assert sessions(rig) == [first.root]
    # The shore acknowledges it: the guard frees the space, and writing resumes by itself.
    ack(rig, first.root)
    for _ in range(4):
        step(rig, 1.0)
    assert sessions(rig) != [first.root]
    assert first.root not in sessions(rig)
    assert rig.rec.session is not None
    disk = rig.rec.status()["disk"]
    assert (disk["stopped"], disk["removed"]) == (None, 1)
    assert disk["freed"] > 4_000_000
    gaps = [e for e in rig.entries() if e.key == "PLOGGER_GAP"]
    assert len(gaps) == 1
    assert "reason=low-disk" in str(gaps[0].value)
    assert "lost=50" in str(gaps[0].value)


def test_keep_sessions_removes_acknowledged_first_then_the_oldest_never_the_current(
    tmp_path: Path, mounts: list[Path], rigs: Callable[..., Rig]
) -> None:
    mount_tmpfs(tmp_path / "logs", "16m")
    mounts.append(tmp_path / "logs")
    rig = rigs("File = R\nPath = logs\nLog = A @ 0\nKeepSessions = 3\nMinFreeDisk = 0")
    rig.rec.start()
    names = [session_with_data(rig, 3)]
    for _ in range(4):
        rig.clock.t += 2.0
        assert rig.rec.restart().ok
        names.append(session_with_data(rig, 3))
    assert len(set(names)) == 5
    ack(rig, names[2])
    ack(rig, names[3])
    step(rig, 0.5)
    # Five sessions, three kept: the two acknowledged ones go, though two are older.
    assert sessions(rig) == sorted([names[0], names[1], names[4]])
    rig.clock.t += 2.0
    assert rig.rec.restart().ok
    current = session_with_data(rig, 1)
    step(rig, 0.5)
    # No acknowledged one left: the oldest goes; the current one never.
    assert sessions(rig) == sorted([names[1], names[4], current])
    disk = rig.rec.status()["disk"]
    assert disk["removed"] == 3
    assert disk["last_removed"] == [names[0]]


def test_max_log_size_and_the_guard_spare_a_session_being_fetched(
    tmp_path: Path, mounts: list[Path], rigs: Callable[..., Rig]
) -> None:
    mount_tmpfs(tmp_path / "logs", "16m")
    mounts.append(tmp_path / "logs")
    rig = rigs("File = R\nPath = logs\nLog = A @ 0\nMaxLogSize = 1MB\nMinFreeDisk = 0")
    rig.rec.start()
    names = []
    for _ in range(4):
        names.append(session_with_data(rig, 40))  # about 400 kB each
        rig.clock.t += 2.0
        assert rig.rec.restart().ok
    leases = FileLeases()
    try:
        fetched = rig.rec.log_root / names[0]
        alog = fetched / f"{names[0]}.alog"
        leases.served(alog, alog.stat(), finished=False)
        step(rig, 0.5)
        left = sessions(rig)
        # the fetched one stays, whatever it costs; the others go oldest first until it fits
        assert names[0] in left
        held = sum(p.stat().st_size for p in rig.rec.log_root.rglob("*") if p.is_file())
        assert names[1] not in left
        assert held <= 1_000_000 + alog.stat().st_size + 20_000
    finally:
        leases.close()
    step(rig, 61.0)  # the next pass, the lease gone
    assert names[0] not in sessions(rig)
