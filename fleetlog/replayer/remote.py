"""Remote inputs: ``V:latest`` and ``V:SESSION``, fetched from the vehicle into a cache first.

The session is downloaded with the query service's resumable fetch
(:func:`fleetlog.shore.fetch.fetch_session`) into ``<cache>/<V>/<SESSION>/``, so replaying
the same session again costs only a check that the files are up to date. A session still
being written is replayed as far as it has arrived: its files stay ``.part`` (the fetch
resumes them next time), and the replay reads them through hard links under their real
names in ``<SESSION>.partial/``, so a compressed alog is still recognised by its suffix.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path

from fleetlog.errors import ReplayError, StorageError
from fleetlog.moos.patterns import name_to_chunk
from fleetlog.replayer.inputs import RemoteSpec
from fleetlog.shore.client import FleetClient
from fleetlog.shore.fetch import fetch_session
from fleetlog.transport.session import SessionOptions

__all__ = ["default_cache", "fetch_remote"]

_PART = ".part"


def default_cache() -> Path:
    """Return ``$XDG_CACHE_HOME/fleetlog/replay`` (``~/.cache/fleetlog/replay`` by default)."""
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "fleetlog" / "replay"


def _partial_view(directory: Path) -> Path:
    """Link a partly fetched session's files, ``.part`` ones under their real names."""
    view = directory.with_name(directory.name + ".partial")
    try:
        view.mkdir(parents=True, exist_ok=True)
        for old in view.iterdir():
            old.unlink()
        for item in directory.iterdir():
            if item.name.endswith(_PART + ".json") or not item.is_file():
                continue
            name = item.name.removesuffix(_PART)
            os.link(item, view / name)
    except OSError as err:
        msg = f"cannot prepare the partly fetched session {directory}: {err.strerror or err}"
        raise StorageError(msg) from err
    return view


def fetch_remote(
    spec: RemoteSpec,
    options: SessionOptions,
    root: str,
    cache: Path,
    announce: Callable[[str], None] | None = None,
) -> Path:
    """Fetch a remote session into the cache; return its local directory.

    Args:
        spec: the vehicle and the session (``latest`` for its latest).
        options: how to reach the fleet over Zenoh.
        root: the key root.
        cache: the cache directory.
        announce: told, in a sentence, what is being fetched.

    Raises:
        ReplayError: the vehicle has no session.
        QueryError: the vehicle does not answer or refuses.
        StorageError: the cache cannot be written.
        TransportError: the session cannot be opened.
    """
    with FleetClient.open(options, root=root) as client:
        client.require(spec.vehicle)
        session = spec.session
        if session == "latest":
            info = client.latest(spec.vehicle)
            if info.session is None:
                msg = f"{spec.vehicle}:latest: vehicle {spec.vehicle} has no session"
                raise ReplayError(msg)
            session = info.session
        target = cache / name_to_chunk(spec.vehicle)
        if announce is not None:
            announce(f"fetching {spec.vehicle}:{session} into {target / session}")
        outcome = fetch_session(client, spec.vehicle, session, target)
    if outcome.complete:
        return outcome.directory
    if announce is not None:
        announce(f"{spec.vehicle}:{session} is still being written: replaying what arrived")
    return _partial_view(outcome.directory)
