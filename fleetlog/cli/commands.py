"""Registers every command on the app (each lives in its own module)."""

from fleetlog.cli import poke, record

__all__ = ["poke", "record"]
