"""Control replies as the shore reads them (docs/wire.md, "Control").

A recorder (``<root>/V/@fleetlog/control``) and a running replay
(``<root>/V/@fleetlog/replay/control``) answer one schema: ``{"ok", "cmd", "did", "why",
...}``. The reply comes from the network: it is read defensively, bounded in size, and its
texts are cut short.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from fleetlog.errors import FormatError
from fleetlog.wire.json_fields import parse_json

__all__ = ["ControlReply"]

#: a control reply larger than this is refused unread
MAX_REPLY = 1 << 20
_MAX_TEXT = 1024


def _text(value: Any) -> str:
    if not isinstance(value, str):
        return ""
    return value if len(value) <= _MAX_TEXT else value[: _MAX_TEXT - 1] + "…"


@dataclass(frozen=True)
class ControlReply:
    """One process's answer to a control request.

    Attributes:
        ok: the command was done.
        cmd: the command, as the process names it.
        did: what was done, one sentence.
        why: why it was refused (when not ``ok``).
        extra: the reply's other fields (a replay's status: ``state``, ``offset``, ...).
        server: the Zenoh id of the process that answered, if known.
    """

    ok: bool
    cmd: str
    did: str
    why: str | None
    extra: Mapping[str, Any] = field(default_factory=dict)
    server: str | None = None

    @classmethod
    def from_json(cls, data: bytes, server: str | None = None) -> ControlReply:
        """Read a reply.

        Raises:
            FormatError: not a JSON object with a boolean ``ok``, or too large.
        """
        if len(data) > MAX_REPLY:
            msg = f"the control reply is {len(data)} bytes long; at most {MAX_REPLY}"
            raise FormatError(msg)
        try:
            obj = parse_json(data)
        except (ValueError, RecursionError) as err:
            msg = f"the control reply is not JSON: {str(err)[:80]}"
            raise FormatError(msg) from None
        if not isinstance(obj, dict) or not isinstance(obj.get("ok"), bool):
            msg = "the control reply is not an object with a boolean 'ok'"
            raise FormatError(msg)
        why = obj.get("why")
        extra = {k: v for k, v in obj.items() if k not in ("ok", "cmd", "did", "why")}
        return cls(
            obj["ok"],
            _text(obj.get("cmd")),
            _text(obj.get("did")),
            _text(why) if why is not None else None,
            extra,
            server,
        )

    def describe(self) -> str:
        """One line: what was done, or why it was refused."""
        if self.ok:
            return self.did or f"{self.cmd}: done"
        return f"{self.cmd} refused: {self.why or 'no reason given'}"
