"""A small recorder rig for the engine's control and fault tests (fake clock, real files)."""

from __future__ import annotations

import json
import subprocess
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
from alog_oracle import iter_entries

from fleetlog.moos.alog import Entry
from fleetlog.moos.mission import LoggerConfig, parse_mission
from fleetlog.recorder.background import Background, inline
from fleetlog.recorder.engine import Recorder
from fleetlog.storage.metafile import read_meta
from fleetlog.wire.control import Outcome, parse_control_request
from fleetlog.wire.message import MoosMessage
from fleetlog.wire.session_meta import SessionMeta

T0 = 1_800_000_000.25
DIGEST = "ab" * 32


class Clock:
    def __init__(self) -> None:
        self.t = T0

    def __call__(self) -> float:
        return self.t


def config(body: str) -> LoggerConfig:
    """A pLogger block for vehicle ``alpha``."""
    lines = "\n".join(f"  {line.strip()}" for line in body.strip().splitlines())
    text = f"Community = alpha\nProcessConfig = pLogger\n{{\n{lines}\n}}\n"
    return parse_mission(text, "t.moos").logger_config("pLogger")


class Rig:
    """A recorder in ``tmp/logs`` with a fake clock; what it posts lands in ``posted``."""

    def __init__(
        self,
        tmp: Path,
        body: str = "File = R\nPath = logs\nLog = A @ 0",
        background: Background = inline,
    ) -> None:
        (tmp / "logs").mkdir(exist_ok=True)
        (tmp / "mission").mkdir(exist_ok=True)
        self.clock = Clock()
        self.posted: list[MoosMessage] = []
        self.rec = Recorder(
            config(body),
            vehicle="alpha",
            publish=self.posted.append,
            cwd=tmp,
            copy_dirs=[tmp / "mission"],
            clock=self.clock,
            recorder_id="zid-1",
            background=background,
        )

    def send(self, name: str, value: float | str | bytes, at: float, source: str = "iOps") -> None:
        self.clock.t = T0 + at
        self.rec.handle(MoosMessage(name, value, self.clock.t, source, "", "alpha"))

    @property
    def dir(self) -> Path:
        assert self.rec.session is not None
        return self.rec.session.dir_path

    def meta(self, directory: Path | None = None) -> SessionMeta:
        found = read_meta(directory or self.dir)
        assert found is not None
        return found

    def debugs(self) -> list[str]:
        texts = [str(m.value) for m in self.posted if m.name == "MOOS_DEBUG"]
        self.posted.clear()
        return texts

    def close(self) -> None:
        self.rec.stop()

    def entries(self, directory: Path | None = None) -> list[Entry]:
        """The alog entries of a session (the open one by default), flushed first."""
        self.rec.flush()
        d = directory or self.dir
        with open(d / f"{d.name}.alog", encoding="utf-8", newline="") as f:
            return list(iter_entries(f))

    def control(self, obj: dict[str, object]) -> Outcome:
        """Submit a control request and run it as the drain thread would."""
        got: list[Outcome] = []
        self.rec.commands.submit(parse_control_request(json.dumps(obj).encode(), ""), got.append)
        self.rec.commands.run_queued()
        (outcome,) = got
        return outcome


@pytest.fixture
def rigs(tmp_path: Path) -> Iterator[Callable[..., Rig]]:
    """Make rigs in ``tmp_path``; every recorder is stopped at the end."""
    made: list[Rig] = []

    def make(body: str = "File = R\nPath = logs\nLog = A @ 0", **kwargs: Any) -> Rig:
        rig = Rig(tmp_path, body, **kwargs)
        made.append(rig)
        return rig

    yield make
    for rig in made:
        rig.close()


def mount_tmpfs(where: Path, size: str, *options: str) -> None:
    """Mount a tmpfs of ``size`` at ``where`` (root only: otherwise skip, and say so loudly)."""
    where.mkdir(parents=True, exist_ok=True)
    opts = ",".join([f"size={size}", *options])
    done = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", opts, "tmpfs", str(where)], capture_output=True, check=False
    )
    if done.returncode != 0:
        pytest.skip(
            f"SKIPPED LOUDLY: mounting a tmpfs needs root ({done.stderr.decode().strip()}); "
            "the RLIMIT_FSIZE full-disk test in test_faults.py covers the engine"
        )


@pytest.fixture
def mounts() -> Iterator[list[Path]]:
    """Mount points to unmount at the end (lazily, whatever is still using them)."""
    made: list[Path] = []
    yield made
    for where in reversed(made):
        subprocess.run(["umount", "-l", str(where)], capture_output=True, check=False)
