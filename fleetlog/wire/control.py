"""The control service's requests and replies (docs/wire.md, "Control").

Pure: a request (a JSON object in the query's payload, or selector parameters for hand-typed
queries) is checked here, field by field, before any command runs; a reply and each entry of
the recorder's command ring (``commands`` in its status) have one shape for every path a
command may come by (the control queryable, ``PLOGGER_CMD``, ``LOGGER_RESTART``).
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from fleetlog.errors import FormatError
from fleetlog.wire.json_fields import parse_json
from fleetlog.wire.keys import check_component
from fleetlog.wire.parameters import parse_parameters

__all__ = [
    "CONTROL",
    "MAX_REQUEST",
    "PRUNE",
    "RECORDER_COMMANDS",
    "CommandRecord",
    "ControlRequest",
    "Outcome",
    "check_command_key",
    "parse_control_request",
]

#: the recorder's control service: ``<root>/V/@fleetlog/control``
CONTROL = "control"
#: the largest request payload (or parameter string) read
MAX_REQUEST = 64 << 10
#: what one ring entry's ``text`` keeps of a command (the rest is cut, with an ellipsis)
MAX_TEXT = 256
#: every recorder command and the arguments it takes (all strings, except ``ack``'s files)
RECORDER_COMMANDS: Mapping[str, tuple[str, ...]] = {
    "restart": (),
    "pause": (),
    "resume": (),
    "split": (),
    "snapshot": (),
    "note": ("key", "value"),
    "log_request": ("spec",),
    "copy_file": ("path",),
    "ack": ("session", "files"),
    "prune": (),
    "status": (),
}
#: the key (under the control key) that alone takes ``prune``, so access control can grant
#: deleting apart from the other commands: ``<root>/V/@fleetlog/control/prune``
PRUNE = "prune"
#: fields any request may carry: who sent it and its own time stamp (for the ring)
_COMMON = ("cmd", "source", "time")
_LIMITS = {"key": 64, "value": 1024, "spec": 1024, "path": 4096, "session": 255, "source": 64}
_SHA256 = re.compile(r"[0-9a-f]{64}")
#: an ``ack`` names at most this many files
MAX_ACK_FILES = 4096


def _clip(text: str) -> str:
    return text if len(text) <= MAX_TEXT else text[: MAX_TEXT - 1] + "…"


@dataclass(frozen=True)
class ControlRequest:
    """A checked request.

    Attributes:
        cmd: the command, one of :data:`RECORDER_COMMANDS`.
        args: its arguments, checked (strings; ``files`` a name → sha256 mapping).
        source: who sent it, as the sender says (for the ring), or empty.
        time: the sender's time stamp, if it gave a finite one.
        text: the request as received, cut to 256 characters (for the ring).
    """

    cmd: str
    args: Mapping[str, Any] = field(default_factory=dict)
    source: str = ""
    time: float | None = None
    text: str = ""


def parse_control_request(
    payload: bytes | None,
    parameters: str,
    *,
    commands: Mapping[str, tuple[str, ...]] | None = None,
    optional: bool = False,
    numbers: frozenset[str] = frozenset(),
) -> ControlRequest:
    """Check a control query: its JSON payload, or else its selector parameters.

    Args:
        payload: the query's payload (None or empty when it has none).
        parameters: the selector's parameters (``cmd=note;key=site;value=bay``).
        commands: the commands the service takes, with their arguments (the recorder's by
            default).
        optional: the arguments may be left out (the service checks which it needs; a
            replay's ``seek`` takes ``t`` or ``dt``).
        numbers: arguments that may also be JSON numbers, passed on as their decimal text
            (as a selector parameter would give them).

    Raises:
        FormatError: the request is too large, not a JSON object, names no or an unknown
            command, lacks an argument, has one it does not take, or one of the wrong type
            or size. The message names what was wrong.
    """
    known = RECORDER_COMMANDS if commands is None else commands
    if payload:
        if len(payload) > MAX_REQUEST:
            msg = f"the request is {len(payload)} bytes long; at most {MAX_REQUEST}"
            raise FormatError(msg)
        if parameters:
            msg = "give the request as a JSON payload or as parameters, not both"
            raise FormatError(msg)
        try:
            obj = parse_json(payload)
        except (ValueError, RecursionError) as err:
            msg = f"the request is not JSON: {str(err)[:80]}"
            raise FormatError(msg) from None
        if not isinstance(obj, dict):
            msg = "the request is not a JSON object"
            raise FormatError(msg)
        text = payload.decode("utf-8", "replace")
    else:
        if len(parameters) > MAX_REQUEST:
            msg = f"the parameters are {len(parameters)} characters long; at most {MAX_REQUEST}"
            raise FormatError(msg)
        names = {*_COMMON, *(a for args in known.values() for a in args if a != "files")}
        obj = dict(parse_parameters(parameters, names))
        if "time" in obj:
            try:
                obj["time"] = float(obj["time"])
            except ValueError:
                msg = "'time' is not a number"
                raise FormatError(msg) from None
        text = parameters
    cmd = obj.get("cmd")
    if not isinstance(cmd, str) or not cmd:
        msg = "the request names no command ('cmd')"
        raise FormatError(msg)
    if cmd not in known:
        msg = f"unknown command {cmd[:40]!r}; this service takes {', '.join(known)}"
        raise FormatError(msg)
    takes = known[cmd]
    args: dict[str, Any] = {}
    for name, value in obj.items():
        if name in _COMMON:
            continue
        if name not in takes:
            msg = f"command {cmd!r} takes no argument {name[:40]!r}"
            raise FormatError(msg)
        if name in numbers and _is_number(value):
            value = repr(value)
        args[name] = _files(value) if name == "files" else _string(name, value)
    missing = [] if optional else [name for name in takes if name not in args]
    if missing:
        msg = f"command {cmd!r} needs {', '.join(repr(m) for m in missing)}"
        raise FormatError(msg)
    if "session" in args:
        check_component(args["session"], "session")
    source = obj.get("source", "")
    if not isinstance(source, str):
        msg = "'source' is not a string"
        raise FormatError(msg)
    when = obj.get("time")
    if not (isinstance(when, int | float) and not isinstance(when, bool) and math.isfinite(when)):
        when = None
    return ControlRequest(cmd, args, _string("source", source), when, _clip(text))


def check_command_key(request: ControlRequest, *, pruning: bool) -> ControlRequest:
    """Check that ``prune`` came on ``…/control/prune`` and every other command on ``…/control``.

    Args:
        request: the checked request.
        pruning: it came on the ``prune`` key.

    Raises:
        FormatError: it came on the other key.
    """
    if (request.cmd == PRUNE) != pruning:
        where = f"@fleetlog/{CONTROL}/{PRUNE}" if request.cmd == PRUNE else f"@fleetlog/{CONTROL}"
        msg = f"command {request.cmd!r} is taken only on {where}"
        raise FormatError(msg)
    return request


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def _string(name: str, value: Any) -> str:
    if not isinstance(value, str):
        msg = f"argument {name!r} is not a string"
        raise FormatError(msg)
    limit = _LIMITS.get(name, 1024)
    if len(value) > limit:
        msg = f"argument {name!r} is {len(value)} characters long; at most {limit}"
        raise FormatError(msg)
    if "\x00" in value:
        msg = f"argument {name!r} holds a NUL character"
        raise FormatError(msg)
    return value


def _files(value: Any) -> dict[str, str]:
    if not isinstance(value, dict) or not value:
        msg = "argument 'files' is not a non-empty object of file name → sha256"
        raise FormatError(msg)
    if len(value) > MAX_ACK_FILES:
        msg = f"argument 'files' names {len(value)} files; at most {MAX_ACK_FILES}"
        raise FormatError(msg)
    for name, digest in value.items():
        check_component(name, "file")
        if not isinstance(digest, str) or not _SHA256.fullmatch(digest):
            msg = f"the sha256 of {name[:80]!r} is not 64 lowercase hex digits"
            raise FormatError(msg)
    return dict(value)


@dataclass(frozen=True)
class Outcome:
    """What a command did (``ok``), or why it was refused.

    Attributes:
        ok: it was done.
        cmd: the command.
        did: one sentence saying what was done (empty when refused).
        why: why it was refused (None when done).
        extra: fields the reply carries besides these (they depend on the command).
    """

    ok: bool
    cmd: str
    did: str = ""
    why: str | None = None
    extra: Mapping[str, Any] = field(default_factory=dict)

    @classmethod
    def done(cls, cmd: str, did: str, **extra: Any) -> Outcome:
        """Return the outcome of a command that was done."""
        return cls(True, cmd, did, None, extra)

    @classmethod
    def refused(cls, cmd: str, why: str) -> Outcome:
        """Return the outcome of a command that was refused."""
        return cls(False, cmd, "", why)

    def reply(self) -> bytes:
        """Return the reply's JSON."""
        body = {"ok": self.ok, "cmd": self.cmd, "did": self.did, "why": self.why}
        body.update({k: v for k, v in self.extra.items() if k not in body})
        return json.dumps(body, allow_nan=False, default=str).encode()


@dataclass(frozen=True)
class CommandRecord:
    """One entry of the recorder's ring of recent commands (``commands`` in its status).

    Attributes:
        time: the command message's own time (the request's ``time``, else when it came).
        via: ``PLOGGER_CMD``, ``LOGGER_RESTART`` (or their names under another app name)
            or ``control``.
        source: the sender (the MOOS source; the request's ``source``).
        cmd: the command (``?`` when it could not be read).
        text: the command as received, cut to 256 characters.
        ok: it was done.
        did: what was done.
        why: why it was refused.
    """

    time: float
    via: str
    source: str
    cmd: str
    text: str
    ok: bool
    did: str
    why: str | None

    @classmethod
    def of(
        cls, outcome: Outcome, *, time: float, via: str, source: str, text: str
    ) -> CommandRecord:
        """Return the ring entry of an outcome."""
        return cls(
            time, via, source, outcome.cmd, _clip(text), outcome.ok, outcome.did, outcome.why
        )

    def as_json(self) -> dict[str, Any]:
        """Return the JSON object."""
        return {
            "time": self.time,
            "via": self.via,
            "source": self.source,
            "cmd": self.cmd,
            "text": self.text,
            "ok": self.ok,
            "did": self.did,
            "why": self.why,
        }

    @classmethod
    def from_json(cls, obj: Any) -> CommandRecord:
        """Read one entry (as the shore does from a status reply).

        Raises:
            FormatError: not the shape above.
        """
        if not isinstance(obj, dict):
            msg = "a command record is not an object"
            raise FormatError(msg)
        try:
            time = float(obj["time"])
            why = obj.get("why")
            record = cls(
                time,
                str(obj["via"]),
                str(obj["source"]),
                str(obj["cmd"]),
                str(obj["text"]),
                bool(obj["ok"]),
                str(obj["did"]),
                None if why is None else str(why),
            )
        except (KeyError, TypeError, ValueError) as err:
            msg = f"a command record lacks or garbles {err}"
            raise FormatError(msg) from None
        return record
