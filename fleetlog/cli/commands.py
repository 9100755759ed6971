"""Registers every command on the app (each lives in its own module)."""

from fleetlog.cli import fetch, fleet, poke, query, record, replay, serve, sessions

__all__ = ["fetch", "fleet", "poke", "query", "record", "replay", "serve", "sessions"]
