"""``fleetlog replay-ctl``: pause, resume, seek, step, re-rate or stop a running replay."""

from __future__ import annotations

import json
from typing import Annotated, Any

import typer

from fleetlog.cli.app import app
from fleetlog.cli.options import Config, Connect, Listen, Mode, NoScouting, Root, checked_vehicle
from fleetlog.cli.replay import parse_when
from fleetlog.cli.shore import WAIT, Wait, open_client
from fleetlog.errors import FleetlogError, QueryError, UsageError
from fleetlog.shore.client import FleetClient
from fleetlog.shore.discovery import REPLAY_TOKEN, Discovery

__all__ = ["replay_ctl"]

_SIMPLE = ("pause", "resume", "toggle", "stop", "status")
_COMMANDS = ", ".join([*_SIMPLE, "rate X", "seek T", "step [N]"])


def build_request(command: str, value: str | None) -> dict[str, Any]:
    """Turn ``COMMAND [VALUE]`` into a control request (docs/wire.md, "Control").

    Raises:
        UsageError: an unknown command, or a value that does not fit it.
    """
    cmd = command.strip().lower()
    if cmd in _SIMPLE:
        if value is not None:
            msg = f"{cmd} takes no value, got {value!r}"
            raise UsageError(msg)
        return {"cmd": cmd}
    if cmd == "rate":
        if value is None:
            msg = "rate needs a value: 0.1 ... 100, fast, + or -"
            raise UsageError(msg)
        if value in ("fast", "+", "-"):
            return {"cmd": "rate", "x": value}
        try:
            return {"cmd": "rate", "x": float(value)}
        except ValueError:
            msg = f"rate {value!r} is not 0.1 ... 100, fast, + or -"
            raise UsageError(msg) from None
    if cmd == "seek":
        if value is None:
            msg = "seek needs a time: SECONDS or [H:]MM:SS from the start, or +S / -S"
            raise UsageError(msg)
        if value[:1] in ("+", "-"):
            seconds, _ = parse_when(value[1:], "seek")
            return {"cmd": "seek", "dt": seconds if value[0] == "+" else -seconds}
        seconds, absolute = parse_when(value, "seek")
        if absolute:
            msg = "seek takes a time from the replay's start, not an absolute @EPOCH"
            raise UsageError(msg)
        return {"cmd": "seek", "t": seconds}
    if cmd == "step":
        if value is None:
            return {"cmd": "step"}
        if value.endswith("s"):
            seconds, _ = parse_when(value[:-1], "step")
            return {"cmd": "step", "dt": seconds}
        if not value.isdigit() or int(value) < 1:
            msg = f"step takes a number of entries (1 or more) or seconds (2s), not {value!r}"
            raise UsageError(msg)
        return {"cmd": "step", "n": int(value)}
    msg = f"unknown replay command {command!r}; known: {_COMMANDS}"
    raise UsageError(msg)


def _find_replay(client: FleetClient, wait: float, vehicle: str | None) -> str:
    """The vehicle to steer: ``vehicle`` once its replay is seen, else the one replay running.

    Replays are found by their tokens, as vehicles are (no fixed sleep).
    """
    discovery = Discovery(client.zenoh, client.root, services=(REPLAY_TOKEN,))
    try:
        view = discovery.wait(expect=() if vehicle is None else (vehicle,), wait=wait)
    finally:
        discovery.close()
    if vehicle is not None:
        return vehicle  # not seen: the control query says so
    if not view.vehicles:
        msg = f"no replay is running (none answered under --root {client.root} in {wait:g} s)"
        raise QueryError(msg)
    if len(view.vehicles) == 1:
        return view.names[0]
    # One replay plays every vehicle it publishes to: several names may be one replay.
    players: dict[str | None, list[str]] = {}
    for vehicle in view.names:
        for reply in client.control(vehicle, {"cmd": "status"}, replay=True):
            players.setdefault(reply.server, []).append(vehicle)
    if len(players) == 1:
        return view.names[0]
    names = "; ".join(", ".join(v) for v in players.values())
    msg = f"{len(players)} replays are running ({names}); name one with --vehicle"
    raise QueryError(msg)


@app.command("replay-ctl", context_settings={"ignore_unknown_options": True})
def replay_ctl(
    command: Annotated[
        str,
        typer.Argument(metavar="COMMAND", help=f"One of: {_COMMANDS}.", show_default=False),
    ],
    value: Annotated[
        str | None,
        typer.Argument(
            metavar="VALUE",
            help="rate: 0.1 ... 100, fast, + or -; seek: SECONDS or [H:]MM:SS from the start,"
            " +S or -S from here; step: N entries or Ns seconds of log.",
            show_default=False,
        ),
    ] = None,
    vehicle: Annotated[
        str | None,
        typer.Option(
            "--vehicle",
            "-v",
            metavar="V",
            help="A vehicle the replay plays (after --prefix) [default: the one replay running].",
        ),
    ] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print the reply as JSON.")] = False,
    wait: Wait = WAIT,
    root: Root = "fleet",
    mode: Mode = None,
    connect: Connect = None,
    listen: Listen = None,
    config: Config = None,
    no_multicast_scouting: NoScouting = False,
) -> None:
    """Steer a running fleetlog replay: pause, resume, seek, step, change its rate, stop it.

    Prints what the replay did (where it is now); exits non-zero if it refused or no replay
    answered. The replay is found by its liveliness token, as vehicles are.
    """
    request = build_request(command, value)
    if vehicle is not None:
        checked_vehicle(vehicle, "--vehicle")
    with open_client(
        root, mode, connect, listen, config, no_multicast_scouting, wait=wait
    ) as client:
        target = _find_replay(client, wait, vehicle)
        replies = client.control(target, request, replay=True)
    refused: list[str] = []
    for reply in replies:
        if as_json:
            body = {"ok": reply.ok, "cmd": reply.cmd, "did": reply.did, "why": reply.why}
            print(json.dumps({**body, **reply.extra}))
        else:
            print(f"replay of {target}: {reply.describe()}")
        if not reply.ok:
            refused.append(reply.describe())
    if refused:
        raise FleetlogError(refused[0])
