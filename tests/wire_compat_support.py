"""A vehicle of an older wire protocol, recorded once and answered from the recording.

``capture.py`` (beside the recordings in tests/data/wire) ran a real vehicle of that version
(``fleetlog serve`` on a reference session) behind a recording proxy while the shore of that
version listed, fetched and grepped it. :class:`RecordedVehicle` answers the same queries from
the recording, on a real Zenoh session with the vehicle's liveliness token, so that the shore
of today is tested against what the older vehicle really sent.

File ranges are answered from the recorded file bytes with the recorded meta's fields (a shore
may ask for other ranges than the old one did); everything else must be asked exactly as it
was recorded, and a question the old shore never asked gets an error reply saying so.
"""

from __future__ import annotations

import base64
import json
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from urllib.parse import unquote

import zenoh

DATA = Path(__file__).resolve().parent / "data" / "wire"


@dataclass
class Exchange:
    """One query and the replies it got."""

    key: str
    parameters: str
    replies: list[dict[str, Any]]

    def to_json(self) -> str:
        return json.dumps(
            {"key": self.key, "parameters": self.parameters, "replies": self.replies},
            sort_keys=True,
        )


def encode_reply(reply: zenoh.Reply) -> dict[str, Any]:
    if reply.ok is not None:
        sample = reply.ok
        attachment = sample.attachment
        return {
            "key": str(sample.key_expr),
            "payload": base64.b64encode(sample.payload.to_bytes()).decode(),
            "encoding": str(sample.encoding),
            "attachment": None
            if attachment is None
            else base64.b64encode(attachment.to_bytes()).decode(),
        }
    return {"error": reply.err.payload.to_string()}


def _params(text: str) -> dict[str, str]:
    out = {}
    for item in text.split(";"):
        if item:
            name, _, value = item.partition("=")
            out[name] = unquote(value)
    return out


class RecordedVehicle:
    """Answers one vehicle's queries from a recording (see the module docstring)."""

    def __init__(self, session: zenoh.Session, root: str, vehicle: str, recording: Path) -> None:
        self.exchanges = [
            Exchange(**json.loads(line)) for line in recording.read_text().splitlines() if line
        ]
        self.files: dict[str, tuple[bytes, dict[str, Any]]] = {}
        for ex in self.exchanges:
            if "/@fleetlog/file/" not in ex.key:
                continue
            for rep in ex.replies:
                if "payload" not in rep or rep["attachment"] is None:
                    continue
                meta = json.loads(base64.b64decode(rep["attachment"]))
                data = base64.b64decode(rep["payload"])
                have, old = self.files.get(ex.key, (b"", {}))
                if meta["offset"] == len(have) and len(have) < meta["size"]:
                    have += data
                merged = {**old, **meta}
                merged["sha256"] = meta.get("sha256") or old.get("sha256")
                self.files[ex.key] = (have, merged)
        self.unknown: list[str] = []
        self._lock = threading.Lock()
        self._queryable = session.declare_queryable(f"{root}/{vehicle}/@fleetlog/**", self._answer)
        self._token = session.liveliness().declare_token(f"{root}/{vehicle}/@fleetlog/serve")

    def _answer(self, query: zenoh.Query) -> None:
        key, parameters = str(query.key_expr), str(query.parameters)
        if key in self.files:
            self._file(query, key, _params(parameters))
            return
        for ex in self.exchanges:
            if ex.key == key and ex.parameters == parameters:
                for rep in ex.replies:
                    if "error" in rep:
                        query.reply_err(rep["error"])
                        continue
                    attachment = rep["attachment"]
                    query.reply(
                        rep["key"],
                        base64.b64decode(rep["payload"]),
                        encoding=zenoh.Encoding(rep["encoding"]),
                        attachment=None if attachment is None else base64.b64decode(attachment),
                    )
                return
        with self._lock:
            self.unknown.append(f"{key}?{parameters}")
        query.reply_err(f"the recorded older vehicle was never asked {key}?{parameters}")

    def _file(self, query: zenoh.Query, key: str, params: dict[str, str]) -> None:
        data, meta = self.files[key]
        offset = int(params.get("offset", "0"))
        length = int(params.get("length", str(1 << 20)))
        if offset > len(data):
            query.reply_err(f"offset {offset} is past the end of the file ({len(data)} bytes)")
            return
        chunk = data[offset : offset + length]
        reply_meta = dict(meta, offset=offset, length=len(chunk))
        if params.get("sha256") != "1":
            reply_meta["sha256"] = None
        query.reply(
            key,
            chunk,
            encoding=zenoh.Encoding("application/octet-stream"),
            attachment=json.dumps(reply_meta).encode(),
        )

    def file_bytes(self) -> dict[str, bytes]:
        """The recorded files: key → bytes."""
        return {k: v[0] for k, v in self.files.items()}

    def close(self) -> None:
        self._token.undeclare()
        self._queryable.undeclare()
