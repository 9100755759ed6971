"""The ``prune`` command of a real ``fleetlog record``: its own key, acks by sha256."""

from __future__ import annotations

import hashlib
import json
import time
from pathlib import Path
from typing import Any

from helpers import Proc

from fleetlog.transport.queries import start_query
from fleetlog.transport.session import SessionOptions, open_session

CONTROL = "fleet/alpha/@fleetlog/control"


def ask(session: Any, key: str, request: dict[str, Any]) -> dict[str, Any] | str:
    payload = json.dumps(request).encode()
    for _ in range(50):
        replies = list(start_query(session, key, timeout=30.0, payload=payload))
        if replies:
            (reply,) = replies
            if reply.error is not None:
                return reply.error
            return json.loads(reply.payload)  # type: ignore[no-any-return]
        time.sleep(0.1)  # the queryable is not known to this session yet
    msg = f"{key} never answered"
    raise AssertionError(msg)


def digests(directory: Path) -> dict[str, str]:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in directory.iterdir()}


def test_prune_removes_only_what_the_shore_acknowledged(
    tmp_path: Path, endpoint: str, cli_env: dict[str, str]
) -> None:
    recorder = Proc(
        ["record", "--vehicle", "alpha", "-l", endpoint, "--no-multicast-scouting"],
        tmp_path,
        cli_env,
    )
    session = open_session(SessionOptions(connect=(endpoint,), multicast_scouting=False))
    try:
        recorder.wait_for("recording")
        for _ in range(3):
            assert ask(session, CONTROL, {"cmd": "restart"})["ok"]  # type: ignore[index]
        first, second, third, current = sorted(p for p in tmp_path.iterdir() if p.is_dir())
        time.sleep(0.5)  # the closing metadata is written off the recording thread
        # prune is taken on its own key only, and nothing else is taken there
        wrong = ask(session, CONTROL, {"cmd": "prune"})
        assert wrong == "command 'prune' is taken only on @fleetlog/control/prune"
        other = ask(session, CONTROL + "/prune", {"cmd": "status"})
        assert other == "command 'status' is taken only on @fleetlog/control"
        # the shore acknowledges two sessions; one of them then changes on the vehicle
        for directory in (first, second):
            request = {"cmd": "ack", "session": directory.name, "files": digests(directory)}
            assert ask(session, CONTROL, request)["ok"]  # type: ignore[index]
        with (second / f"{second.name}.alog").open("a") as alog:
            alog.write("written after the ack\n")
        reply = ask(session, CONTROL + "/prune", {"cmd": "prune", "source": "test"})
        assert isinstance(reply, dict)
        assert reply["ok"], reply
        assert reply["removed"] == [first.name]
        assert reply["kept"] == {
            second.name: "the shore has not acknowledged it",
            third.name: "the shore has not acknowledged it",
            current.name: "it is the session being recorded",
        }
        assert sorted(p for p in tmp_path.iterdir() if p.is_dir()) == [second, third, current]
        status = ask(session, CONTROL, {"cmd": "status"})
        assert isinstance(status, dict)
        ring = [c for c in status["commands"] if c["cmd"] == "prune"]
        assert [(c["ok"], c["source"]) for c in ring][-1] == (True, "test")
    finally:
        session.close()
        recorder.close()
