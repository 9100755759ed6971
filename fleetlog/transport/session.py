"""Zenoh session options shared by every command, and ZError translation.

The options mirror zenoh-python's examples: ``-m/--mode``, ``-e/--connect`` (repeatable),
``-l/--listen`` (repeatable), ``-c/--config FILE`` and ``--no-multicast-scouting``. With none
of them the session is an embedded peer that finds its neighbours by multicast scouting: no
router and no configuration needed.

**Where the configuration comes from** (first found): ``-c FILE``; the file named by the
``ZENOH_CONFIG`` environment variable (as zenoh's own tools read it); the machine-wide
``/etc/fleetlog/zenoh.json5`` that an installed fleet machine carries (``FLEETLOG_ETC`` moves
that directory: tests, the demo). The other options then override what the file says.
:func:`resolve_config` says which was used, for ``--verbose`` and ``status``.
"""

from __future__ import annotations

import json
import os
import re
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import zenoh

from fleetlog.errors import TransportError

__all__ = [
    "RECORDER_RUNTIME",
    "ConfigSource",
    "ConfigSummary",
    "SessionOptions",
    "etc_dir",
    "open_session",
    "prefer_runtime",
    "resolve_config",
    "summarize",
    "tls_problem",
    "translate_zerror",
]

#: the machine-wide configuration directory of an installed fleet machine
ETC = Path("/etc/fleetlog")
#: the machine-wide Zenoh configuration's name in it
MACHINE_ZENOH = "zenoh.json5"


#: the Zenoh runtime a recording process asks for: the links it accepts (``acc``) and those it
#: opens (``net``) are watched by its two receiving threads (``rx``) themselves. By default a
#: thread of their own watches them and wakes a receiving thread for every message that comes
#: alone (a steady rate): a thread switch per message, 10-23 % of the recorder's CPU at 10,000
#: to 40,000 msg/s, for the same loss-free rate (docs/bench.md §15, stop 22). One receiving
#: thread (``rx: (worker_threads: 1)``) would save as much but lowered the loss-free rate.
RECORDER_RUNTIME = "(acc: (handover: rx), net: (handover: rx))"


def prefer_runtime(setting: str = RECORDER_RUNTIME) -> bool:
    """Ask Zenoh for ``setting`` as this process's runtime, unless ``ZENOH_RUNTIME`` says one.

    Zenoh reads ``ZENOH_RUNTIME`` (RON) when its first session opens: call this before. An
    operator's own ``ZENOH_RUNTIME`` wins. Returns whether ``setting`` was taken.
    """
    if os.environ.get("ZENOH_RUNTIME"):
        return False
    os.environ["ZENOH_RUNTIME"] = setting
    return True


def etc_dir() -> Path:
    """Return the machine-wide configuration directory (``FLEETLOG_ETC`` or /etc/fleetlog)."""
    moved = os.environ.get("FLEETLOG_ETC")
    return Path(moved) if moved else ETC


@dataclass(frozen=True, slots=True)
class ConfigSource:
    """Which Zenoh configuration file a session uses, and why.

    Attributes:
        path: the file, or None (Zenoh's defaults: an embedded peer).
        how: ``--config``, ``ZENOH_CONFIG``, ``machine-wide`` or ``none``.
    """

    path: Path | None
    how: str

    def describe(self) -> str:
        """One phrase for --verbose and status."""
        if self.path is None:
            return "no configuration file (an embedded peer with Zenoh's defaults)"
        why = {
            "--config": "given by -c/--config",
            "ZENOH_CONFIG": "named by ZENOH_CONFIG",
            "machine-wide": "this machine's configuration",
        }[self.how]
        return f"{self.path} ({why})"


def resolve_config(explicit: Path | None) -> ConfigSource:
    """Find the Zenoh configuration file: ``-c FILE`` > ``ZENOH_CONFIG`` > machine-wide.

    Raises:
        TransportError: ``ZENOH_CONFIG`` names a file that does not exist (a typo there would
            otherwise silently fall back to another configuration).
    """
    if explicit is not None:
        return ConfigSource(explicit, "--config")
    named = os.environ.get("ZENOH_CONFIG")
    if named:
        path = Path(named)
        if not path.is_file():
            msg = f"ZENOH_CONFIG names {path}, which is not a file"
            raise TransportError(msg)
        return ConfigSource(path, "ZENOH_CONFIG")
    machine = etc_dir() / MACHINE_ZENOH
    if machine.is_file():
        return ConfigSource(machine, "machine-wide")
    return ConfigSource(None, "none")


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
        machine_config: without ``config``, use ``ZENOH_CONFIG`` or the machine-wide file.
        keep_trying: a session behind a router that must open whether or not the router is
            up (the recorder: a vehicle records whatever the network does). A client then
            opens as a peer that listens nowhere, scouts nothing and connects to the same
            endpoints in the background, retrying until they answer; Zenoh's client mode
            refuses to open without its router.
    """

    mode: str | None = None
    connect: tuple[str, ...] = field(default_factory=tuple)
    listen: tuple[str, ...] = field(default_factory=tuple)
    config: Path | None = None
    multicast_scouting: bool = True
    machine_config: bool = True
    keep_trying: bool = False

    def source(self) -> ConfigSource:
        """Which configuration file these options use.

        Raises:
            TransportError: ZENOH_CONFIG names a missing file.
        """
        if self.machine_config:
            return resolve_config(self.config)
        return ConfigSource(self.config, "--config" if self.config else "none")

    def to_config(self) -> zenoh.Config:
        """Build the zenoh.Config these options describe.

        Raises:
            TransportError: an option or the configuration file is not usable.
        """
        if self.mode is not None and self.mode not in _MODES:
            msg = f"--mode must be one of {', '.join(_MODES)}, not {self.mode!r}"
            raise TransportError(msg)
        path = self.source().path
        if path is not None:
            if not path.is_file():
                msg = f"Zenoh configuration file {path} does not exist"
                raise TransportError(msg)
            try:
                conf = zenoh.Config.from_file(str(path))
            except zenoh.ZError as err:
                msg = f"Zenoh configuration file {path} is not usable: {_clean(str(err))}"
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
            if self.keep_trying:
                _keep_trying(conf)
        return conf


def _get(conf: zenoh.Config, key: str) -> Any:
    """A configuration value, decoded (zenoh hands it over as JSON text)."""
    return json.loads(conf.get_json(key))


def _keep_trying(conf: zenoh.Config) -> None:
    """Turn a client into a peer that opens at once and joins its router when it answers."""
    if _get(conf, "mode") != "client":
        return
    endpoints = _get(conf, "connect/endpoints")
    if isinstance(endpoints, dict):
        endpoints = endpoints.get("client") or []
    if not endpoints:
        return  # a client that scouts for its router: nothing to keep trying on
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("connect/endpoints", json.dumps(endpoints))
    listen = _get(conf, "listen/endpoints")
    if isinstance(listen, dict):
        listen = listen.get("client") or []
    conf.insert_json5("listen/endpoints", json.dumps(listen or []))
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("scouting/gossip/enabled", "false")
    conf.insert_json5("scouting/delay", "0")  # nothing to scout: open at once
    conf.insert_json5("connect/timeout_ms", "-1")
    conf.insert_json5("connect/exit_on_failure", "false")


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
    try:
        return zenoh.open(conf)
    except zenoh.ZError as err:
        msg = f"Zenoh session open failed: {_clean(str(err))}"
        hint = tls_problem(conf)
        if hint:
            msg += f"; {hint}"
        raise TransportError(msg) from err


#: the TLS settings that name files
TLS_FILES = (
    "root_ca_certificate",
    "connect_certificate",
    "connect_private_key",
    "listen_certificate",
    "listen_private_key",
)


def tls_settings(conf: zenoh.Config) -> dict[str, Any]:
    """The ``transport/link/tls`` section of a configuration (empty without TLS)."""
    try:
        tls = _get(conf, "transport/link/tls")
    except (zenoh.ZError, ValueError):
        return {}
    return tls if isinstance(tls, dict) else {}


def uses_tls(conf: zenoh.Config) -> bool:
    """Whether the configuration connects or listens on a ``tls/`` endpoint."""
    for key in ("connect/endpoints", "listen/endpoints"):
        try:
            value = _get(conf, key)
        except (zenoh.ZError, ValueError):
            continue
        items = value.values() if isinstance(value, dict) else [value]
        for item in items:
            if isinstance(item, list) and any(str(e).startswith("tls/") for e in item):
                return True
    return False


def tls_problem(conf: zenoh.Config) -> str | None:
    """Say why a TLS session may have failed to open: a missing, expired or foreign file.

    Zenoh says only "Unable to connect"; this names the file and what is wrong with it, or
    lists what the other end may have refused.
    """
    if not uses_tls(conf):
        return None
    from fleetlog.transport.certs import check_tls_files  # cryptography: only when needed

    tls = tls_settings(conf)
    return check_tls_files({k: str(tls[k]) for k in TLS_FILES if tls.get(k)})


@dataclass(frozen=True)
class ConfigSummary:
    """What a configuration makes of a session, for ``status`` and ``deploy check``."""

    source: ConfigSource
    mode: str
    connect: tuple[str, ...]
    listen: tuple[str, ...]
    multicast_scouting: bool
    tls_files: dict[str, str]
    access_control: bool


def summarize(options: SessionOptions) -> ConfigSummary:
    """Read what a session opened with these options would be.

    Raises:
        TransportError: the configuration is unusable.
    """
    conf = options.to_config()
    mode = str(_get(conf, "mode") or "peer")

    def endpoints(key: str) -> tuple[str, ...]:
        value = _get(conf, key)
        if isinstance(value, dict):
            value = value.get(mode) or []
        return tuple(str(v) for v in value) if isinstance(value, list) else ()

    multicast = _get(conf, "scouting/multicast/enabled")
    acl = _get(conf, "access_control")
    tls = tls_settings(conf)
    return ConfigSummary(
        source=options.source(),
        mode=mode,
        connect=endpoints("connect/endpoints"),
        listen=endpoints("listen/endpoints"),
        multicast_scouting=multicast is not False,
        tls_files={k: str(tls[k]) for k in TLS_FILES if tls.get(k)},
        access_control=isinstance(acl, dict) and acl.get("enabled") is True,
    )
