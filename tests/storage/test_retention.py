"""Retention: the one module that deletes sessions, and the file leases that stop it.

Real directories, real files, real flocks; no deletion is faked.
"""

from __future__ import annotations

import fcntl
import hashlib
import json
import os
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

from fleetlog.storage import retention
from fleetlog.storage.leases import FileLeases, exclusive_files
from fleetlog.storage.metafile import DirLock, append_ack, write_meta
from fleetlog.storage.retention import RetentionView, StoredSession
from fleetlog.wire.session_meta import ACKS_NAME, SessionMeta


def _session(root: Path, name: str, body: bytes = b"x" * 1000) -> Path:
    directory = root / name
    directory.mkdir()
    (directory / f"{name}.alog").write_bytes(b"%% LOGFILE\n" + body)
    (directory / f"{name}.ylog").write_bytes(b"ylog " + name.encode())
    return directory


def _digests(directory: Path) -> dict[str, str]:
    return {
        p.name: hashlib.sha256(p.read_bytes()).hexdigest()
        for p in directory.iterdir()
        if p.is_file()
    }


def _ack(root: Path, name: str) -> None:
    append_ack(root, name, _digests(root / name), now=1.0, source="test")


NAMES = [f"MOOSLog_{d}_1_2026_____10_00_00" for d in (1, 2, 3, 4)]


def test_prune_removes_acknowledged_sessions_only(tmp_path: Path) -> None:
    for name in NAMES:
        _session(tmp_path, name)
    _ack(tmp_path, NAMES[0])
    _ack(tmp_path, NAMES[2])
    result = retention.run(tmp_path, [retention.PruneAcknowledged()])
    assert [r.session.name for r in result.removed] == [NAMES[0], NAMES[2]]
    assert sorted(p.name for p in tmp_path.iterdir() if p.is_dir()) == [NAMES[1], NAMES[3]]
    assert result.kept == {n: "the shore has not acknowledged it" for n in (NAMES[1], NAMES[3])}
    assert result.freed == sum(
        len(b"%% LOGFILE\n") + 1000 + len(b"ylog " + n.encode()) for n in (NAMES[0], NAMES[2])
    )
    assert (tmp_path / ACKS_NAME).is_file()  # the acks file is not a session


def test_never_the_current_session(tmp_path: Path) -> None:
    for name in NAMES[:2]:
        _session(tmp_path, name)
        _ack(tmp_path, name)
    result = retention.run(tmp_path, [retention.PruneAcknowledged()], current=lambda: NAMES[1])
    assert [r.session.name for r in result.removed] == [NAMES[0]]
    assert result.kept[NAMES[1]] == retention.CURRENT
    assert (tmp_path / NAMES[1]).is_dir()


def test_an_ack_of_other_bytes_or_a_new_file_is_no_ack(tmp_path: Path) -> None:
    changed, added, partial, odd = (_session(tmp_path, n) for n in NAMES)
    for directory in (changed, added, partial, odd):
        _ack(tmp_path, directory.name)
    (changed / f"{changed.name}.alog").write_bytes(b"other bytes")
    (added / "late.txt").write_text("added after the ack")
    append_ack(
        tmp_path,
        partial.name,
        {f"{partial.name}.alog": _digests(partial)[f"{partial.name}.alog"]},
        now=1.0,
    )
    (partial / "extra").write_text("never acknowledged")
    (odd / "sub").mkdir()  # something that is not a regular file
    result = retention.run(tmp_path, [retention.PruneAcknowledged()])
    assert result.removed == []
    assert all(d.is_dir() for d in (changed, added, partial, odd))


def test_acks_file_with_garbage_lines(tmp_path: Path) -> None:
    first = _session(tmp_path, NAMES[0])
    with (tmp_path / ACKS_NAME).open("w") as acks:
        acks.write('not json\n[1,2]\n{"session": 5}\n')
        acks.write(json.dumps({"session": first.name, "files": _digests(first)})[:-3] + "\n")
    assert retention.read_acks(tmp_path) == {}
    _ack(tmp_path, first.name)
    assert set(retention.read_acks(tmp_path)[first.name]) == set(_digests(first))


def test_a_session_being_fetched_is_left(tmp_path: Path) -> None:
    one, two = _session(tmp_path, NAMES[0]), _session(tmp_path, NAMES[1])
    _ack(tmp_path, one.name)
    _ack(tmp_path, two.name)
    leases = FileLeases()
    alog = one / f"{one.name}.alog"
    leases.served(alog, alog.stat(), finished=False)  # a range in the middle was sent
    try:
        result = retention.run(tmp_path, [retention.PruneAcknowledged()])
        assert [r.session.name for r in result.removed] == [two.name]
        assert result.skipped == {one.name: retention.FETCHING}
        assert leases.sessions(tmp_path) == {one.name}
        # The fetch reaches the end of the file: the lease ends, the session may go.
        leases.served(alog, alog.stat(), finished=True)
        assert leases.sessions(tmp_path) == set()
        result = retention.run(tmp_path, [retention.PruneAcknowledged()])
        assert [r.session.name for r in result.removed] == [one.name]
    finally:
        leases.close()


def test_a_lease_expires(tmp_path: Path) -> None:
    one = _session(tmp_path, NAMES[0])
    now = [0.0]
    leases = FileLeases(lease=10.0, clock=lambda: now[0])
    alog = one / f"{one.name}.alog"
    leases.served(alog, alog.stat(), finished=False)
    with exclusive_files([alog]) as free:
        assert not free
    now[0] = 11.0
    assert leases.paths() == []
    with exclusive_files([alog]) as free:
        assert free
    leases.close()


def test_leases_are_bounded(tmp_path: Path) -> None:
    leases = FileLeases(limit=3)
    paths = []
    for i in range(5):
        path = tmp_path / f"f{i}"
        path.write_text("x")
        paths.append(path)
        leases.served(path, path.stat(), finished=False)
    assert leases.paths() == paths[2:]
    leases.close()


def test_a_live_recorder_holds_its_session(tmp_path: Path) -> None:
    live = _session(tmp_path, NAMES[0])
    meta = SessionMeta("open", "v", live.name, "1", "0", opened=1.0, logstart=1.0)
    lock = DirLock(live)
    try:
        write_meta(live, meta)
        _ack(tmp_path, live.name)  # acknowledged, yet its recorder is alive
        result = retention.run(tmp_path, [retention.PruneAcknowledged()])
        assert result.removed == []
        assert result.kept[live.name] == retention.LIVE
    finally:
        lock.release()


def test_the_directory_lock_is_checked_again_before_deleting(tmp_path: Path) -> None:
    one = _session(tmp_path, NAMES[0])
    _ack(tmp_path, one.name)
    chosen = retention.plan(
        retention.survey(tmp_path, current=None), [retention.PruneAcknowledged()]
    )
    fd = os.open(one, os.O_RDONLY | os.O_DIRECTORY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)  # a recorder took it meanwhile
        result = retention.apply(chosen)
    finally:
        os.close(fd)
    assert result.skipped == {one.name: retention.LIVE}
    assert one.is_dir()


def test_became_current_or_fetched_meanwhile(tmp_path: Path) -> None:
    one, two = _session(tmp_path, NAMES[0]), _session(tmp_path, NAMES[1])
    _ack(tmp_path, one.name)
    _ack(tmp_path, two.name)
    chosen = retention.plan(
        retention.survey(tmp_path, current=None), [retention.PruneAcknowledged()]
    )
    result = retention.apply(chosen, current=lambda: one.name, fetching=lambda: {two.name})
    assert result.skipped == {one.name: retention.CURRENT, two.name: retention.FETCHING}
    assert one.is_dir()
    assert two.is_dir()


def test_symlinks_are_not_followed(tmp_path: Path) -> None:
    outside = tmp_path / "outside"
    outside.mkdir()
    (outside / "precious").write_text("keep me")
    root = tmp_path / "logs"
    root.mkdir()
    one = _session(root, NAMES[0])
    _ack(root, one.name)
    (root / NAMES[1]).symlink_to(outside, target_is_directory=True)
    (outside / f"{NAMES[1]}.alog").write_text("an alog behind a link")
    result = retention.run(root, [retention.PruneAcknowledged()])
    assert [r.session.name for r in result.removed] == [one.name]
    assert (outside / "precious").read_text() == "keep me"
    assert (root / NAMES[1]).is_symlink()


@dataclass(frozen=True)
class _KeepNewest:
    """A policy as the recording modes will add them: keep the newest ``n`` sessions."""

    n: int
    name: str = "keep_sessions"

    def choose(self, view: RetentionView) -> Iterable[tuple[StoredSession, str]]:
        newest = {s.name for s in view.sessions[-self.n :]}
        return [(s, f"more than {self.n}") for s in view.candidates if s.name not in newest]


def test_a_policy_is_an_input_and_acknowledged_sessions_go_first(tmp_path: Path) -> None:
    for name in NAMES:
        _session(tmp_path, name)
    _ack(tmp_path, NAMES[1])
    view = retention.survey(tmp_path, current=NAMES[3])
    assert [s.name for s in view.sessions] == NAMES
    # acknowledged first, then oldest first; the current one never
    assert [s.name for s in view.candidates] == [NAMES[1], NAMES[0], NAMES[2]]
    chosen = retention.plan(view, [_KeepNewest(2)])
    assert [(r.session.name, r.policy) for r in chosen.remove] == [
        (NAMES[1], "keep_sessions"),
        (NAMES[0], "keep_sessions"),
    ]
    retention.apply(chosen)
    assert sorted(p.name for p in tmp_path.iterdir() if p.is_dir()) == NAMES[2:]
    assert view.free is not None
    assert view.total is not None


def test_digest_is_asked_only_for_fully_acknowledged_sessions(tmp_path: Path) -> None:
    for name in NAMES:
        _session(tmp_path, name)
    _ack(tmp_path, NAMES[2])
    asked: list[str] = []

    def digest(path: Path) -> str:
        asked.append(path.parent.name)
        return hashlib.sha256(path.read_bytes()).hexdigest()

    retention.survey(tmp_path, current=None, digest=digest)
    assert set(asked) == {NAMES[2]}


def test_a_replaced_file_moves_its_lease(tmp_path: Path) -> None:
    # The session metadata is replaced (rename) while its session is open: the lease follows
    # the name, and the old file's lease does not pin the session for ever.
    one = _session(tmp_path, NAMES[0])
    meta = one / ".fleetlog-session.json"
    meta.write_text("v1")
    leases = FileLeases()
    try:
        leases.served(meta, meta.stat(), finished=False)
        (one / "tmp").write_text("v2")
        os.replace(one / "tmp", meta)
        leases.served(meta, meta.stat(), finished=True)
        assert leases.paths() == []
        with exclusive_files([meta]) as free:
            assert free
    finally:
        leases.close()
