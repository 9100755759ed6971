"""The ``fleetlog`` command line: thin typer commands over the engines."""

from __future__ import annotations

from fleetlog.cli.app import app, main

__all__ = ["app", "main"]
