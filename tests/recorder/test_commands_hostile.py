"""Commands from a hostile peer, in the engine (fake clock, real files): issue 10, items 1, 3, 5.

Every refused command gives a MOOS_DEBUG message, a counter and an outcome that says why;
nothing a peer sends stops the recorder or leaks a file; what a peer can add (variables,
subscriptions, copies) is bounded, and the bound is a clear refusal.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from fleetlog.errors import RecorderError
from fleetlog.moos.mission import LoggerConfig, parse_mission
from fleetlog.recorder.control import MAX_COPIES, MAX_COPY_BYTES, MAX_LOG_REQUESTS
from fleetlog.recorder.engine import Recorder
from fleetlog.wire.control import ControlRequest, Outcome
from fleetlog.wire.message import MoosMessage

T0 = 1_800_000_000.25


class Clock:
    def __init__(self) -> None:
        self.t = T0

    def __call__(self) -> float:
        return self.t


def config(logs: Path, body: str = "") -> LoggerConfig:
    lines = "\n".join(f"  {line.strip()}" for line in body.strip().splitlines())
    text = f"ProcessConfig = pLogger\n{{\n  File = R\n  Path = {logs}\n{lines}\n}}\n"
    return parse_mission(text, "t.moos").logger_config("pLogger")


class Rig:
    """A recorder over ``tmp``: a mission directory with secrets in it, a log directory."""

    def __init__(self, tmp: Path, body: str = "", subscribe_limit: int | None = None) -> None:
        self.tmp = tmp
        mission = tmp / "mission"
        (mission / ".ssh").mkdir(parents=True)
        (mission / ".ssh" / "id_rsa").write_text("SECRET KEY\n")
        (mission / ".hidden").write_text("hidden\n")
        (mission / "sub" / ".git").mkdir(parents=True)
        (mission / "sub" / ".git" / "config").write_text("hidden\n")
        (mission / "m.moos").write_text("// the mission\n")
        (mission / "alpha.bhv").write_text("// behaviours\n")
        os.mkfifo(mission / "fifo")
        (tmp / "outside.txt").write_text("outside\n")
        (mission / "link_out").symlink_to(tmp / "outside.txt")
        (mission / "link_dev").symlink_to("/dev/zero")
        (mission / "link_in").symlink_to(mission / "alpha.bhv")
        (mission / "link_hidden").symlink_to(mission / ".ssh" / "id_rsa")
        (mission / ".visible_link").symlink_to(mission / "alpha.bhv")
        with open(mission / "big.bin", "wb") as f:
            f.truncate(MAX_COPY_BYTES + 1)
        (tmp / "logs").mkdir()
        self.clock = Clock()
        self.posted: list[MoosMessage] = []
        self.subscribed: list[str] = []
        self.subscribe_limit = subscribe_limit
        self.rec = Recorder(
            config(tmp / "logs", body),
            vehicle="alpha",
            publish=self.posted.append,
            cwd=mission,
            copy_dirs=[mission],
            clock=self.clock,
            subscribe=self.subscribe,
        )
        self.rec.start()

    def subscribe(self, name: str) -> None:
        if self.subscribe_limit is not None and len(self.subscribed) >= self.subscribe_limit:
            raise RecorderError(f"at most {self.subscribe_limit} subscriptions")
        self.subscribed.append(name)

    def cmd(self, value: str | float | bytes) -> Outcome:
        self.clock.t += 0.001
        self.posted.clear()
        self.rec.handle(MoosMessage("PLOGGER_CMD", value, self.clock.t, "iEvil", "", "alpha"))
        return self.outcome()

    def outcome(self) -> Outcome:
        last = self.rec.commands.recent()[-1]
        return Outcome(last["ok"], last["cmd"], last["did"], last["why"])

    def debugs(self) -> list[str]:
        return [str(m.value) for m in self.posted if m.name == "MOOS_DEBUG"]

    def copies(self) -> list[str]:
        """The copies in the session (``stem._ext``)."""
        assert self.rec.session is not None
        return sorted(p.name for p in self.rec.session.dir_path.iterdir() if "._" in p.name)

    def logs_still(self) -> None:
        """A sample after the attack is logged: the recorder is alive and writing."""
        before = self.rec.stats.logged
        self.rec.handle(MoosMessage("PROBE", 1.0, self.clock.t, "iOk", "", "alpha"))
        assert self.rec.stats.logged == before + 1

    def close(self) -> None:
        self.rec.stop()


@pytest.fixture
def rig(tmp_path: Path) -> Rig:
    return Rig(tmp_path, "WildcardLogging = true")


def assert_refused(rig: Rig, outcome: Outcome, why: str) -> None:
    assert not outcome.ok
    assert outcome.why is not None
    assert why in outcome.why, outcome.why
    assert rig.debugs(), "a refused command is reported on MOOS_DEBUG"


# --------------------------------------------------------------------------------------------
# Item 1: nothing a peer sends stops the recorder


@pytest.mark.parametrize(
    "value",
    [
        "COPY_FILE_REQUEST=a\x00b",
        "COPY_FILE_REQUEST=" + "x" * 300,
        "COPY_FILE_REQUEST=" + ("d" * 200 + "/") * 30 + "f",
        "COPY_FILE_REQUEST=sub/" + "y" * 300 + "/z",
        "LOG_REQUEST=A\x00B@0",
        "LOG_REQUEST=" + "V" * 100_000,
        "COPY_FILE_REQUEST=\udcff",
        "LOG_REQUEST=X@1e999",
        "=" * 10_000,
    ],
    ids=[
        "nul",
        "long-name",
        "long-path",
        "long-component",
        "nul-var",
        "huge-var",
        "surrogate",
        "inf-period",
        "equals",
    ],
)
def test_no_command_stops_the_recorder(rig: Rig, value: str) -> None:
    before = rig.rec.stats.refused_commands
    outcome = rig.cmd(value)
    assert not outcome.ok
    assert outcome.why
    assert rig.rec.stats.refused_commands == before + 1
    debugs = rig.debugs()
    assert debugs
    assert all(len(text) < 1024 for text in debugs), "a MOOS_DEBUG never echoes a huge command"
    rig.logs_still()
    rig.close()


def test_a_command_that_raises_is_refused_not_fatal(
    rig: Rig, monkeypatch: pytest.MonkeyPatch
) -> None:
    def boom(argument: str) -> Outcome:
        raise OSError(36, "File name too long")

    monkeypatch.setattr(rig.rec, "copy_file", boom)
    outcome = rig.cmd("COPY_FILE_REQUEST=x")
    assert_refused(rig, outcome, "File name too long")
    rig.logs_still()
    rig.close()


# --------------------------------------------------------------------------------------------
# Item 5: COPY_FILE_REQUEST leaks nothing


@pytest.mark.parametrize(
    ("path", "why"),
    [
        (".ssh/id_rsa", "hidden"),
        (".hidden", "hidden"),
        ("sub/.git/config", "hidden"),
        ("link_hidden", "hidden"),
        (".visible_link", "hidden"),
        ("link_out", "outside the directories"),
        ("link_dev", "outside the directories"),
        ("../outside.txt", "outside the directories"),
        ("/etc/passwd", "outside the directories"),
        ("fifo", "not a regular file"),
        ("sub", "a directory"),
        ("big.bin", f"larger than {MAX_COPY_BYTES}"),
        ("nothing.here", "cannot read"),
    ],
)
def test_copy_file_request_refuses_what_must_not_leave(rig: Rig, path: str, why: str) -> None:
    before = rig.rec.stats.refused_copies
    outcome = rig.cmd("COPY_FILE_REQUEST=" + path)
    assert_refused(rig, outcome, why)
    assert rig.rec.stats.refused_copies == before + 1
    assert not rig.copies()
    rig.close()
    files = [p for p in rig.tmp.joinpath("logs").rglob("*") if p.is_file()]
    assert any(p.suffix == ".alog" for p in files)
    for found in files:
        assert b"SECRET" not in found.read_bytes()


def test_copy_file_request_still_copies_what_it_may(rig: Rig) -> None:
    assert rig.cmd("COPY_FILE_REQUEST=alpha.bhv").ok
    assert rig.cmd("COPY_FILE_REQUEST=link_in").ok
    rig.close()
    (session,) = rig.tmp.joinpath("logs").iterdir()
    assert (session / "alpha._bhv").read_text() == "// behaviours\n"
    assert (session / "link_in._bak").read_text() == "// behaviours\n"


def test_copies_per_session_are_bounded(rig: Rig) -> None:
    for _ in range(MAX_COPIES):
        assert rig.cmd("COPY_FILE_REQUEST=alpha.bhv").ok
    assert_refused(rig, rig.cmd("COPY_FILE_REQUEST=alpha.bhv"), f"at most {MAX_COPIES}")
    rig.close()


# --------------------------------------------------------------------------------------------
# Item 3: what a peer can add is bounded, each request costs the same


def test_log_requests_are_bounded_with_a_clear_refusal(rig: Rig) -> None:
    for i in range(MAX_LOG_REQUESTS):
        assert rig.cmd(f"LOG_REQUEST=V_{i}@0").ok
    outcome = rig.cmd("LOG_REQUEST=ONE_TOO_MANY@0")
    assert_refused(rig, outcome, f"at most {MAX_LOG_REQUESTS}")
    assert len(rig.subscribed) == MAX_LOG_REQUESTS
    assert rig.rec.stats.refused_commands == 1
    rig.logs_still()
    rig.close()


def test_a_subscription_the_transport_refuses_refuses_the_request(tmp_path: Path) -> None:
    rig = Rig(tmp_path, "WildcardLogging = false", subscribe_limit=2)
    assert rig.cmd("LOG_REQUEST=A@0").ok
    assert rig.cmd("LOG_REQUEST=B@0").ok
    outcome = rig.cmd("LOG_REQUEST=C@0")
    assert_refused(rig, outcome, "at most 2 subscriptions")
    # refused means not added: a later request for it is not "logged already"
    rig.subscribe_limit = None
    assert rig.cmd("LOG_REQUEST=C@0").ok
    rig.close()


def test_control_refusals_are_reported_on_moos_debug(rig: Rig) -> None:
    replies: list[Outcome] = []
    rig.posted.clear()
    rig.rec.commands.submit(ControlRequest("snapshot", text='{"cmd": "snapshot"}'), replies.append)
    rig.rec.commands.run_queued()  # snapshot runs in the recording thread
    (reply,) = replies
    assert not reply.ok
    assert any("snapshot" in text and "refused" in text for text in rig.debugs())
    rig.close()
