"""``fleetlog recorder-ctl``: pause, resume, split, note or restart vehicles' recorders."""

from __future__ import annotations

import json
import sys
from typing import Annotated, Any

import typer

from fleetlog.cli.app import app
from fleetlog.cli.options import Config, Connect, Listen, Mode, NoScouting, Root, checked_vehicle
from fleetlog.cli.shore import WAIT, Wait, open_client
from fleetlog.errors import FleetlogError, FormatError, QueryError, UsageError
from fleetlog.moos.recording_modes import parse_note

__all__ = ["build_recorder_request", "recorder_ctl"]

_SIMPLE = ("pause", "resume", "split", "snapshot", "restart")
_COMMANDS = ", ".join([*_SIMPLE, "note KEY:VALUE"])


def build_recorder_request(command: str, value: str | None, source: str) -> dict[str, Any]:
    """Turn ``COMMAND [VALUE]`` into a recorder control request (docs/wire.md, "Control").

    Raises:
        UsageError: an unknown command, or a value that does not fit it.
    """
    cmd = command.strip().lower()
    if cmd in _SIMPLE:
        if value is not None:
            msg = f"{cmd} takes no value, got {value!r}"
            raise UsageError(msg)
        return {"cmd": cmd, "source": source}
    if cmd == "note":
        if value is None:
            msg = "note needs KEY:VALUE (fleetlog recorder-ctl note site:bay -v alpha)"
            raise UsageError(msg)
        try:
            key, text = parse_note(value)
        except FormatError as err:
            raise UsageError(err.reason) from None
        return {"cmd": "note", "key": key, "value": text, "source": source}
    msg = f"unknown recorder command {command!r}; known: {_COMMANDS}"
    raise UsageError(msg)


@app.command("recorder-ctl")
def recorder_ctl(
    command: Annotated[
        str,
        typer.Argument(metavar="COMMAND", help=f"One of: {_COMMANDS}.", show_default=False),
    ],
    value: Annotated[
        str | None,
        typer.Argument(metavar="VALUE", help="note: KEY:VALUE.", show_default=False),
    ] = None,
    vehicle: Annotated[
        list[str] | None,
        typer.Option(
            "--vehicle",
            "-v",
            metavar="V",
            help="A vehicle whose recorder to command (repeatable; required).",
            show_default=False,
        ),
    ] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print each reply as JSON.")] = False,
    wait: Wait = WAIT,
    root: Root = "fleet",
    mode: Mode = None,
    connect: Connect = None,
    listen: Listen = None,
    config: Config = None,
    no_multicast_scouting: NoScouting = False,
) -> None:
    """Command vehicles' recorders: pause, resume, split, note, snapshot, restart.

    pause stops writing (the session stays open; what is not written is counted as paused),
    resume writes again, split starts the next part of the session now, note KEY:VALUE sets a
    note on the open session, restart starts a new session (LOGGER_RESTART). The same
    commands reach a recorder from MOOS apps as PLOGGER_CMD = PAUSE, RESUME, SPLIT,
    NOTE=key:value. Prints what each recorder did; exits non-zero if one refused or did not
    answer.
    """
    names = list(vehicle or [])
    if not names:
        msg = "name the recorders to command with --vehicle (repeatable)"
        raise UsageError(msg)
    for name in names:
        checked_vehicle(name, "--vehicle")
    request = build_recorder_request(command, value, source="fleetlog recorder-ctl")
    failed: dict[str, str] = {}
    with open_client(
        root, mode, connect, listen, config, no_multicast_scouting, wait=wait
    ) as client:
        for name in names:
            try:
                replies = client.control(name, request)
            except QueryError as err:
                print(f"fleetlog: {name}: {err}", file=sys.stderr)
                failed.setdefault(name, str(err))
                continue
            for reply in replies:
                if as_json:
                    body = {"ok": reply.ok, "cmd": reply.cmd, "did": reply.did, "why": reply.why}
                    print(json.dumps({"vehicle": name, **body, **reply.extra}))
                else:
                    print(f"{name}: {reply.describe()}")
                if not reply.ok:
                    failed.setdefault(name, reply.describe())
    if failed:
        first, why = next(iter(failed.items()))
        msg = (
            f"{len(failed)} of {len(names)} recorder(s) refused or did not answer ({first}: {why})"
        )
        raise FleetlogError(msg)
