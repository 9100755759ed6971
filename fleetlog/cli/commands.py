"""Registers the commands on the app: only the one being run, or every one for help.

Each command lives in its own module, and importing them all (the recorder, the bridge, the
query server, the deploy kit, the shore client…) took 0.33–0.39 s before any command ran:
most of a ``fleetlog info`` or ``fleetlog grep`` of a small log, and several times that on a
vehicle's ARM board. :func:`load` imports the module of the command the arguments name, and
every module when they name none (``fleetlog``, ``fleetlog --help``) or one it does not know
(typer then says so, with the known names). ``tests/cli/test_lazy.py`` holds
:data:`MODULES` to what the modules register.
"""

from __future__ import annotations

import importlib
from collections.abc import Sequence

__all__ = ["MODULES", "command_name", "load", "load_all"]

#: The module (in ``fleetlog.cli``) that registers each command.
MODULES: dict[str, str] = {
    "bridge": "bridge",
    "clip": "tools",
    "collect": "collect",
    "demo": "demo",
    "deploy": "deploy",
    "export": "export",
    "fetch": "fetch",
    "fleet": "fleet",
    "grep": "tools",
    "info": "tools",
    "merge": "tools",
    "plot": "export",
    "poke": "poke",
    "query": "query",
    "record": "record",
    "recorder-ctl": "recorder_ctl",
    "replay": "replay",
    "replay-ctl": "replay_ctl",
    "router": "router",
    "serve": "serve",
    "sessions": "sessions",
    "sort": "tools",
    "status": "status",
}

#: The app's own options that take a value (the next argument is not the command).
_VALUED = frozenset(("--settings",))


def command_name(argv: Sequence[str]) -> str | None:
    """The command the arguments run (after the app's own options), or None."""
    args = iter(argv)
    for arg in args:
        if arg in _VALUED:
            next(args, None)
        elif not arg.startswith("-"):
            return arg
    return None


def load_all() -> None:
    """Import every command's module (the full list, for help)."""
    for module in sorted(set(MODULES.values())):
        importlib.import_module(f"fleetlog.cli.{module}")


def load(argv: Sequence[str]) -> None:
    """Import the module of the command ``argv`` runs, or every module."""
    name = command_name(argv)
    module = MODULES.get(name or "")
    if name is None and "--version" in argv:
        return  # the app's own option answers it: no command is needed
    if module is None:
        load_all()
    else:
        importlib.import_module(f"fleetlog.cli.{module}")
