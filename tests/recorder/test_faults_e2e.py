"""Faults tried on a real ``fleetlog record`` (loopback Zenoh, real files, real mounts).

* **SIGKILL** at a random moment while samples flow (plain, gzip, zstd): every sample
  published a second or more before the kill is on disk afterwards; the worst loss window
  is printed. (The campaign at full rate, and above it, is ``bench/faults.py``.)
* **A full disk** (a small tmpfs the test mounts): counted, said in the status, marked, and
  left by itself when space returns, in a new session whose first entry is the gap.
* **A read-only file system** (a read-only tmpfs mounted over the recorder's directory; a
  restart meets it): the same.
* **The session directory removed** while recording.
* **A backlog**: samples stamped on an offered schedule far ahead of what the recorder can
  take keep their own times (skew rule), every one checked.

The mount tests need root (mount); without it they skip and say so, and the RLIMIT_FSIZE
variant of the full disk in ``test_faults.py`` runs everywhere.
"""

from __future__ import annotations

import json
import random
import shutil
import signal
import subprocess
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

import pytest
from helpers import Proc
from recorder_support import mount_tmpfs, mounts

from fleetlog.api import Vehicle
from fleetlog.storage.readers import AlogReader
from fleetlog.transport.queries import ZenohSession, start_query
from fleetlog.transport.session import SessionOptions, open_session
from fleetlog.wire.session_meta import META_NAME, SessionMeta

__all__ = ["mounts"]  # the fixture, imported

STATUS = "fleet/alpha/@fleetlog/status"
MISSION = """\
ProcessConfig = pLogger
{{
  Path = {path}
  WildcardLogging = true
  CompressAlogs = {compress}
}}
"""


class Recorder(Proc):
    def __init__(self, args: Sequence[str], cwd: Path, env: dict[str, str]) -> None:
        super().__init__(["record", *args], cwd, env)


@pytest.fixture
def record(endpoint: str, cli_env: dict[str, str]) -> Iterator[Callable[..., Recorder]]:
    started: list[Recorder] = []

    def start(cwd: Path, *args: str) -> Recorder:
        rec = Recorder(
            [*args, "--vehicle", "alpha", "--no-serve", "-l", endpoint, "--no-multicast-scouting"],
            cwd,
            cli_env,
        )
        started.append(rec)
        rec.wait_for("recording")
        return rec

    yield start
    for rec in started:
        rec.close()


@pytest.fixture
def zenoh_session(endpoint: str) -> Iterator[ZenohSession]:
    session = open_session(SessionOptions(connect=(endpoint,), multicast_scouting=False))
    yield session
    session.close()


def vehicle(endpoint: str) -> Vehicle:
    return Vehicle(
        "alpha",
        source="iTest",
        options=SessionOptions(connect=(endpoint,), multicast_scouting=False),
    )


def status(session: ZenohSession) -> dict[str, Any]:
    for _ in range(50):
        replies = list(start_query(session, STATUS, timeout=10.0))
        if replies:
            return json.loads(replies[0].payload)  # type: ignore[no-any-return]
        time.sleep(0.1)
    msg = "the recorder's status never answered"
    raise AssertionError(msg)


def wait_status(
    session: ZenohSession, check: Callable[[dict[str, Any]], bool], timeout: float = 20.0
) -> dict[str, Any]:
    deadline = time.monotonic() + timeout
    while True:
        body = status(session)
        if check(body):
            return body
        assert time.monotonic() < deadline, f"status never matched: {body}"
        time.sleep(0.05)


def alogs(where: Path) -> list[Path]:
    return sorted(p for p in where.rglob("*.alog*") if ".xlog" not in p.name)


def records(alog: Path) -> list[tuple[float, str, Any]]:
    with AlogReader(alog, errors="skip") as reader:
        return [(r.time, r.entry.key, r.entry.value) for r in reader.records()]


# -------------------------------------------------------------------------------------------
# SIGKILL


class Paced(threading.Thread):
    """Publishes NAV_SEQ = 0, 1, 2… at ``rate`` per second, keeping each one's own time."""

    def __init__(self, v: Vehicle, rate: float) -> None:
        super().__init__(daemon=True)
        self.v = v
        self.rate = rate
        self.stamps: list[float] = []
        self.halt = threading.Event()

    def run(self) -> None:
        start = time.time()
        i = 0
        while not self.halt.is_set():
            due = start + i / self.rate
            now = time.time()
            if now < due:
                time.sleep(min(due - now, 0.002))
                continue
            self.v.publish("NAV_SEQ", float(i), time=now)
            self.stamps.append(now)
            i += 1


@pytest.mark.parametrize("compress", ["false", "gzip", "zstd"])
def test_sigkill_loses_nothing_published_a_second_before(
    record: Callable[..., Recorder], endpoint: str, tmp_path: Path, compress: str
) -> None:
    (tmp_path / "m.moos").write_text(MISSION.format(path="./", compress=compress))
    rec = record(tmp_path, "m.moos")
    with vehicle(endpoint) as v:
        assert v.wait_for_subscriber("NAV_SEQ", timeout=10.0)
        pub = Paced(v, rate=5000.0)
        pub.start()
        time.sleep(random.uniform(1.5, 2.5))
        killed = time.time()
        rec.proc.send_signal(signal.SIGKILL)
        rec.wait()
        pub.halt.set()
        pub.join()
    (alog,) = alogs(tmp_path)
    on_disk = {int(value) for _, key, value in records(alog) if key == "NAV_SEQ"}
    missing = [i for i, stamp in enumerate(pub.stamps) if i not in on_disk]
    first_missing = pub.stamps[missing[0]] if missing else killed
    window = killed - first_missing
    print(
        f"\n{compress}: {len(pub.stamps)} published, {len(on_disk)} on disk, "
        f"worst loss window {window * 1000:.0f} ms before the kill"
    )
    assert window < 1.0
    assert len(on_disk) > 5000  # it was really recording
    meta = SessionMeta.from_bytes((alog.parent / META_NAME).read_bytes())
    assert meta.state == "open"  # cut: the next start marks it (test_control_e2e.py)


# -------------------------------------------------------------------------------------------
# Full disk, read-only file system, removed directory


def publish_until(v: Vehicle, n: int, payload: str, start: int = 0) -> int:
    for i in range(start, start + n):
        v.publish("BULK", f"{i}:{payload}")
    assert v.confirm(timeout=10.0)
    return start + n


def gap_marks(where: Path) -> list[dict[str, str]]:
    """Every PLOGGER_GAP entry under ``where``, as its key=value pairs."""
    marks = []
    for alog in alogs(where):
        for _, key, value in records(alog):
            if key == "PLOGGER_GAP":
                marks.append(dict(pair.split("=", 1) for pair in str(value).split(",")))
    return marks


def lost_of(marks: list[dict[str, str]], name: str) -> int:
    """Samples of ``name`` the marks say were lost."""
    total = 0
    for mark in marks:
        for item in mark.get("vars", "").split(";"):
            var, _, count = item.partition(":")
            if var == name:
                total += int(count)
    return total


def bulk_values(where: Path) -> list[int]:
    out = []
    for alog in alogs(where):
        out.extend(
            int(str(value).split(":", 1)[0]) for _, key, value in records(alog) if key == "BULK"
        )
    return out


def test_a_full_disk_is_counted_marked_and_left_when_space_returns(
    record: Callable[..., Recorder],
    endpoint: str,
    zenoh_session: ZenohSession,
    tmp_path: Path,
    mounts: list[Path],
) -> None:
    fs = tmp_path / "fs"
    mount_tmpfs(fs, "4m")
    mounts.append(fs)
    filler = fs / "filler.bin"
    filler.write_bytes(b"\0" * (3 << 20))  # leaves about 1 MB
    (fs / "m.moos").write_text(MISSION.format(path="./logs", compress="false"))
    (fs / "logs").mkdir()
    record(fs, "m.moos")  # its working directory (the fallback) is on the same full disk
    payload = "x" * 1000
    with vehicle(endpoint) as v:
        assert v.wait_for_subscriber("BULK", timeout=10.0)
        sent = publish_until(v, 500, payload)
        body = wait_status(zenoh_session, lambda b: b["received"] >= 500)
        assert body["writing"]
        sent = publish_until(v, 1500, payload, sent)  # more than the disk holds
        full = wait_status(zenoh_session, lambda b: b["problem"] is not None)
        assert (full["writing"], full["problem"]) == (False, "disk-full")
        assert full["lost"] > 0
        sent = publish_until(v, 200, payload, sent)  # while full: counted as lost
        filler.unlink()  # space returns: a new session opens by itself
        back = wait_status(zenoh_session, lambda b: b["writing"])
        assert back["sessions"] == 2
        sent = publish_until(v, 100, payload, sent)
        final = wait_status(zenoh_session, lambda b: b["received"] >= sent)
    logged = bulk_values(fs / "logs")
    assert len(logged) == len(set(logged))
    # nothing silent: what is not on disk was counted, and marked by variable
    marks = gap_marks(fs / "logs")
    assert [m["reason"] for m in marks] == ["disk-full"]
    assert int(marks[0]["lost"]) == final["lost"]  # the recorder's own posts are in it too
    assert len(logged) + lost_of(marks, "BULK") == sent
    second = alogs(fs / "logs")[-1]
    assert records(second)[0][1] == "PLOGGER_GAP"


def test_a_read_only_file_system_is_counted_marked_and_left_when_writable(
    record: Callable[..., Recorder],
    endpoint: str,
    zenoh_session: ZenohSession,
    tmp_path: Path,
    mounts: list[Path],
) -> None:
    work = tmp_path / "work"
    work.mkdir()
    (work / "m.moos").write_text(MISSION.format(path="./logs", compress="false"))
    (work / "logs").mkdir()
    record(work, "m.moos")
    with vehicle(endpoint) as v:
        assert v.wait_for_subscriber("BULK", timeout=10.0)
        sent = publish_until(v, 100, "a")
        # The directory becomes a read-only file system: the next session cannot open.
        mount_tmpfs(work, "1m", "ro")
        mounts.append(work)
        v.publish("LOGGER_RESTART", "true")
        ro = wait_status(zenoh_session, lambda b: b["problem"] is not None)
        assert (ro["writing"], ro["problem"]) == (False, "read-only")
        sent = publish_until(v, 300, "b", sent)
        wait_status(zenoh_session, lambda b: b["received"] >= sent + 1)
        subprocess.run(["umount", str(work)], check=True)
        mounts.remove(work)
        wait_status(zenoh_session, lambda b: b["writing"])
        sent = publish_until(v, 50, "c", sent)
        wait_status(zenoh_session, lambda b: b["received"] >= sent + 1)
    logged = bulk_values(work / "logs")
    marks = gap_marks(work / "logs")
    assert [m["reason"] for m in marks] == ["read-only"]
    assert lost_of(marks, "BULK") == 300
    assert len(logged) + 300 == sent
    last = alogs(work / "logs")[-1]
    assert records(last)[0][1] == "PLOGGER_GAP"


def test_a_removed_session_directory_starts_a_new_session(
    record: Callable[..., Recorder], endpoint: str, zenoh_session: ZenohSession, tmp_path: Path
) -> None:
    (tmp_path / "m.moos").write_text(MISSION.format(path="./logs", compress="false"))
    (tmp_path / "logs").mkdir()
    record(tmp_path, "m.moos")
    with vehicle(endpoint) as v:
        assert v.wait_for_subscriber("BULK", timeout=10.0)
        sent = publish_until(v, 100, "a")
        (first,) = (tmp_path / "logs").iterdir()
        shutil.rmtree(first)
        sent = publish_until(v, 100, "b", sent)
        body = wait_status(zenoh_session, lambda b: b["sessions"] == 2 and b["received"] >= sent)
    assert body["write_errors"] == 1
    (second,) = (tmp_path / "logs").iterdir()
    meta = SessionMeta.from_bytes((second / META_NAME).read_bytes())
    entries = records(alogs(second)[0])
    assert entries[0][1] == "PLOGGER_GAP"
    assert str(entries[0][2]).startswith(f"reason=removed,lost={body['lost']},")
    # Whenever it was noticed, what was not yet written moved into the new session, so
    # every sample after the removal is there (what was written before went with it).
    after = [int(str(val).split(":")[0]) for _, key, val in entries if key == "BULK"]
    assert body["lost"] == 0
    assert after[-100:] == list(range(100, 200))
    assert meta.logstart > 0


# -------------------------------------------------------------------------------------------
# Backlog: times are never changed by it


def test_a_backlog_never_changes_a_time(
    record: Callable[..., Recorder], endpoint: str, zenoh_session: ZenohSession, tmp_path: Path
) -> None:
    (tmp_path / "m.moos").write_text(MISSION.format(path="./", compress="zstd"))
    rec = record(tmp_path, "m.moos")
    offered = 400_000.0  # per second: several times what any recorder here takes in
    n = 60_000
    with vehicle(endpoint) as v:
        assert v.wait_for_subscriber("NAV_SEQ", timeout=10.0)
        time.sleep(6.0)  # LOGSTART now lies 6 s back: stamps may fall 5 s behind
        t0 = time.time() - 5.5  # the first ones are already 5.5 s old when published
        for i in range(n):
            v.publish("NAV_SEQ", float(i), time=t0 + i / offered)
        assert v.confirm(timeout=30.0)
        body = wait_status(zenoh_session, lambda b: b["received"] >= n)
    assert (body["skewed"], body["lost"]) == (0, 0)
    assert body["max_lag"] < 1.0
    assert rec.stop(signal.SIGINT) == 0  # the last zstd frame closes
    (alog,) = alogs(tmp_path)
    got = [(when, int(value)) for when, key, value in records(alog) if key == "NAV_SEQ"]
    assert [i for _, i in got] == list(range(n))
    # every written time is the published one (to the alog's 5 decimals)
    worst = max(abs(when - (t0 + i / offered)) for when, i in got)
    assert worst < 1e-5 + 1e-6
