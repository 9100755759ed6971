"""Registers every command on the app (each lives in its own module)."""

from fleetlog.cli import bridge, fetch, fleet, poke, query, record, replay, serve, sessions

__all__ = ["bridge", "fetch", "fleet", "poke", "query", "record", "replay", "serve", "sessions"]
