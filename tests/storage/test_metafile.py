"""Session metadata on disk: atomic replacement, the live recorder's lock, cut sessions, acks.

The lock is held by a real second process, killed with SIGKILL as a crashing recorder is.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fleetlog.errors import FormatError, StorageError
from fleetlog.moos.alog import LineFormatter, format_banner
from fleetlog.storage.metafile import (
    DirLock,
    append_ack,
    boot_id,
    host_name,
    last_status,
    mark_cut_sessions,
    read_meta,
    recorder_alive,
    write_meta,
)
from fleetlog.wire.session_meta import ACKS_NAME, META_NAME, SessionMeta

DIGEST = "0123456789abcdef" * 4


def meta(name: str, state: str = "open") -> SessionMeta:
    return SessionMeta(
        state=state,
        vehicle="alpha",
        session=name,
        recorder="z",
        fleetlog="0",
        opened=1.0,
        logstart=1.0,
        updated=2.0,
        host=host_name(),
        pid=os.getpid(),
        boot=boot_id(),
    )


HOLDER = """
import sys, time
from pathlib import Path
from fleetlog.storage.metafile import DirLock
lock = DirLock(Path(sys.argv[1]))
print("locked", flush=True)
time.sleep(60)
"""


@pytest.fixture
def holder(tmp_path: Path) -> Iterator[subprocess.Popen[str]]:
    """A process holding the lock of ``tmp_path/LIVE`` until killed."""
    live = tmp_path / "LIVE"
    live.mkdir()
    proc = subprocess.Popen(
        [sys.executable, "-c", HOLDER, str(live)], stdout=subprocess.PIPE, text=True
    )
    assert proc.stdout is not None
    assert proc.stdout.readline().strip() == "locked"
    yield proc
    proc.kill()
    proc.wait()
    proc.stdout.close()


def test_write_is_atomic_and_read_back(tmp_path: Path) -> None:
    m = meta("S")
    write_meta(tmp_path, m)
    assert read_meta(tmp_path) == m
    assert sorted(p.name for p in tmp_path.iterdir()) == [META_NAME]  # no temporary left
    write_meta(tmp_path, replace(m, notes={"a": "b"}))
    assert read_meta(tmp_path).notes == {"a": "b"}  # type: ignore[union-attr]
    assert read_meta(tmp_path / "nothing") is None
    (tmp_path / META_NAME).write_text("{")
    with pytest.raises(FormatError, match=META_NAME):
        read_meta(tmp_path)


def test_write_into_a_removed_directory_fails_with_a_storage_error(tmp_path: Path) -> None:
    with pytest.raises(StorageError, match="cannot write"):
        write_meta(tmp_path / "gone", meta("S"))


def test_a_live_lock_is_seen_and_kept_and_a_killed_one_is_cut(
    tmp_path: Path, holder: subprocess.Popen[str]
) -> None:
    live = tmp_path / "LIVE"
    write_meta(live, meta("LIVE"))
    dead = tmp_path / "DEAD"
    dead.mkdir()
    write_meta(dead, meta("DEAD"))
    done = tmp_path / "DONE"
    done.mkdir()
    write_meta(done, meta("DONE", "closed"))
    (tmp_path / "plain").mkdir()  # no metadata: real pLogger's

    assert recorder_alive(live)
    assert not recorder_alive(dead)
    with pytest.raises(StorageError, match="being written by another live recorder"):
        DirLock(live)

    marked = mark_cut_sessions(tmp_path, now=50.0)
    assert [m.session for m in marked] == ["DEAD"]
    assert read_meta(dead) == marked[0]
    assert (marked[0].state, marked[0].closed) == ("cut", 50.0)
    assert read_meta(live).state == "open"  # type: ignore[union-attr]
    assert read_meta(done).state == "closed"  # type: ignore[union-attr]
    before = (dead / META_NAME).read_bytes()

    holder.send_signal(signal.SIGKILL)
    holder.wait()
    assert not recorder_alive(live)
    marked = mark_cut_sessions(tmp_path, now=60.0)
    assert [m.session for m in marked] == ["LIVE"]
    # once cut, never changed again
    assert mark_cut_sessions(tmp_path, now=70.0) == []
    assert (dead / META_NAME).read_bytes() == before


def test_the_lock_is_released_with_its_descriptor(tmp_path: Path) -> None:
    lock = DirLock(tmp_path)
    assert lock.held
    assert recorder_alive(tmp_path)
    lock.release()
    assert not recorder_alive(tmp_path)
    DirLock(tmp_path).release()


def test_without_flock_a_dead_pid_decides(tmp_path: Path) -> None:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    from fleetlog.storage import metafile

    gone = replace(meta("S"), pid=proc.pid)
    assert not metafile._alive_by_process(gone)
    assert metafile._alive_by_process(meta("S"))
    assert not metafile._alive_by_process(replace(meta("S"), boot="another boot"))
    assert metafile._alive_by_process(replace(gone, host="another-host"))


def test_acks_are_appended_after_checking_session_and_files(tmp_path: Path) -> None:
    session = tmp_path / "S1"
    session.mkdir()
    (session / "S1.alog").write_text("x")
    (session / "sub").mkdir()
    append_ack(tmp_path, "S1", {"S1.alog": DIGEST}, now=5.0, source="shore")
    append_ack(tmp_path, "S1", {"S1.alog": DIGEST}, now=6.0)
    lines = (tmp_path / ACKS_NAME).read_text().splitlines()
    assert [json.loads(line) for line in lines] == [
        {"time": 5.0, "session": "S1", "files": {"S1.alog": DIGEST}, "source": "shore"},
        {"time": 6.0, "session": "S1", "files": {"S1.alog": DIGEST}, "source": ""},
    ]
    with pytest.raises(StorageError, match="no session 'S2'"):
        append_ack(tmp_path, "S2", {"S1.alog": DIGEST}, now=7.0)
    with pytest.raises(StorageError, match="has no file 'nope'"):
        append_ack(tmp_path, "S1", {"nope": DIGEST}, now=7.0)
    with pytest.raises(StorageError, match="has no file 'sub'"):
        append_ack(tmp_path, "S1", {"sub": DIGEST}, now=7.0)
    (tmp_path / "link").symlink_to(session)
    with pytest.raises(StorageError, match="no session 'link'"):
        append_ack(tmp_path, "link", {"S1.alog": DIGEST}, now=7.0)
    assert len((tmp_path / ACKS_NAME).read_text().splitlines()) == 2


def test_a_session_of_another_host_is_never_cut_here(tmp_path: Path) -> None:
    fetched = tmp_path / "FETCHED"
    fetched.mkdir()
    write_meta(fetched, replace(meta("FETCHED"), host="another-vehicle"))
    assert recorder_alive(fetched, read_meta(fetched))
    assert mark_cut_sessions(tmp_path, now=5.0) == []
    assert read_meta(fetched).state == "open"  # type: ignore[union-attr]


_STATUS = "PLOGGER_STATUS  "


def _dead_session(root: Path, alog: bytes) -> tuple[Path, SessionMeta]:
    directory = root / "D"
    directory.mkdir(exist_ok=True)
    (directory / "D.alog").write_bytes(alog)
    return directory, replace(meta("D"), logstart=1000.0, updated=1040.0)


def test_last_status_reads_the_plain_alogs_tail_within_its_window(tmp_path: Path) -> None:
    fmt = LineFormatter()
    lines = [format_banner("./D/D.alog", 1000.0, "then")]
    lines += [fmt.string(t, "PLOGGER_STATUS", "pLogger", "Uptime=1") for t in (38.0, 44.0, 48.5)]
    lines.append(fmt.double(49.0, "NAV_X", "pNav", 1.0))  # not a sign of the recorder's life
    directory, dead = _dead_session(tmp_path, "".join(lines).encode())
    assert last_status(directory, dead, now=2000.0) == 1048.5
    # never after ``now``, never beyond ``updated`` + 12 s
    assert last_status(directory, dead, now=1046.0) == 1044.0
    assert last_status(directory, replace(dead, updated=1030.0), now=2000.0) == 1038.0
    assert last_status(directory, replace(dead, updated=1049.0), now=2000.0) is None
    assert last_status(directory, replace(dead, logstart=None), now=2000.0) is None
    # compressed, missing or not a regular file: not read
    (directory / "D.alog").rename(directory / "D.alog.gz")
    assert last_status(directory, dead, now=2000.0) is None
    (directory / "D.alog").symlink_to(directory / "D.alog.gz")
    assert last_status(directory, dead, now=2000.0) is None


@settings(
    max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    body=st.binary(max_size=3000)
    | st.lists(
        st.tuples(st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=20)),
        max_size=20,
    ).map(
        lambda rows: "".join(
            f"{t!s:<15} {_STATUS}     pLogger         {v}\n" for t, v in rows
        ).encode(errors="surrogatepass")
    ),
)
def test_last_status_of_a_hostile_tail_is_none_or_in_its_window(
    tmp_path: Path, body: bytes
) -> None:
    banner = format_banner("./D/D.alog", 1000.0, "then").encode()
    directory, dead = _dead_session(tmp_path, banner + body)
    got = last_status(directory, dead, now=1045.0)
    assert got is None or 1040.0 < got <= 1045.0
