"""Zenoh session options shared by every command, and ZError translation.

The options mirror zenoh-python's examples: ``-m/--mode``, ``-e/--connect`` (repeatable),
``-l/--listen`` (repeatable), ``-c/--config FILE`` and ``--no-multicast-scouting``. With none
of them the session is an embedded peer that finds its neighbours by multicast scouting: no
router and no configuration needed.
"""

from __future__ import annotations

import json
import re
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import zenoh

from fleetlog.errors import TransportError

__all__ = ["SessionOptions", "open_session", "translate_zerror"]

_MODES = ("peer", "client", "router")


@dataclass(frozen=True)
class SessionOptions:
    """How to open a Zenoh session.

    Attributes:
        mode: ``peer`` (default), ``client`` (behind a router) or ``router``.
        connect: endpoints to connect to, e.g. ``tcp/192.168.1.10:7447``.
        listen: endpoints to listen on.
        config: a Zenoh JSON5 configuration file; the other options override it.
        multicast_scouting: False turns multicast scouting off (tests, isolated networks).
    """

    mode: str | None = None
    connect: tuple[str, ...] = field(default_factory=tuple)
    listen: tuple[str, ...] = field(default_factory=tuple)
    config: Path | None = None
    multicast_scouting: bool = True

    def to_config(self) -> zenoh.Config:
        """Build the zenoh.Config these options describe.

        Raises:
            TransportError: an option or the configuration file is not usable.
        """
        if self.mode is not None and self.mode not in _MODES:
            msg = f"--mode must be one of {', '.join(_MODES)}, not {self.mode!r}"
            raise TransportError(msg)
        if self.config is not None:
            if not self.config.is_file():
                msg = f"Zenoh configuration file {self.config} does not exist"
                raise TransportError(msg)
            try:
                conf = zenoh.Config.from_file(str(self.config))
            except zenoh.ZError as err:
                msg = f"Zenoh configuration file {self.config} is not usable: {_clean(str(err))}"
                raise TransportError(msg) from err
        else:
            conf = zenoh.Config()
        with translate_zerror("configuration"):
            if self.mode is not None:
                conf.insert_json5("mode", json.dumps(self.mode))
            if self.connect:
                conf.insert_json5("connect/endpoints", json.dumps(list(self.connect)))
            if self.listen:
                conf.insert_json5("listen/endpoints", json.dumps(list(self.listen)))
            if not self.multicast_scouting:
                conf.insert_json5("scouting/multicast/enabled", "false")
        return conf


@contextmanager
def translate_zerror(what: str) -> Iterator[None]:
    """Turn ``zenoh.ZError`` raised inside the block into a TransportError about ``what``."""
    try:
        yield
    except zenoh.ZError as err:
        msg = f"Zenoh {what} failed: {_clean(str(err))}"
        raise TransportError(msg) from err


_MSG_RE = re.compile(r'msg: "(.*?)(?: at /[^"]*)?"')
_AT_RE = re.compile(r"\s+at /\S+\.rs:\d+\.?")
_PARSE_RE = re.compile(r"-->\s*(\d+):(\d+).*?\n\s*=\s*([^\n]*)", re.DOTALL)


def _clean(text: str) -> str:
    """Keep the human part of a ZError: its inner message, without Rust source locations."""
    parse = _PARSE_RE.search(text)
    if parse is not None:
        # A JSON5 syntax error: " --> 1:5 | <the line> | ^--- = expected ...".
        line, column, expected = parse.groups()
        return f"line {line}, column {column}: {_AT_RE.sub('', expected).strip()}"
    match = _MSG_RE.search(text)
    if match:
        text = match.group(1)
    text = _AT_RE.sub("", text).strip().strip("'\"")
    if text.startswith("ZError("):
        text = text[len("ZError(") :].rstrip(")").strip("'\"")
    return text.splitlines()[0] if text else "unknown Zenoh error"


def open_session(options: SessionOptions) -> zenoh.Session:
    """Open a Zenoh session.

    Raises:
        TransportError: the options are unusable or the session cannot be opened (for
            example a listen endpoint already in use).
    """
    conf = options.to_config()
    with translate_zerror("session open"):
        return zenoh.open(conf)
