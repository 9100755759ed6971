"""Registers every command on the app (each lives in its own module)."""

from fleetlog.cli import (
    bridge,
    demo,
    deploy,
    export,
    fetch,
    fleet,
    poke,
    query,
    record,
    replay,
    replay_ctl,
    router,
    serve,
    sessions,
    status,
    tools,
)

__all__ = [
    "bridge",
    "demo",
    "deploy",
    "export",
    "fetch",
    "fleet",
    "poke",
    "query",
    "record",
    "replay",
    "replay_ctl",
    "router",
    "serve",
    "sessions",
    "status",
    "tools",
]
