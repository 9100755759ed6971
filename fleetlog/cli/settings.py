"""fleetlog's own settings and the global options (``--settings``, ``--verbose``).

Settings file, first found: ``--settings FILE``; the file named by ``FLEETLOG_SETTINGS``; the
machine-wide ``/etc/fleetlog/fleetlog.toml`` (``FLEETLOG_ETC`` moves the directory). It holds
defaults an installed machine shares across commands, so that an operator types
``fleetlog fetch alpha`` instead of repeating them::

    root = "fleet"          # --root
    vehicle = "alpha"       # fleetlog record's --vehicle, on a vehicle

A command-line option always wins over the file.
"""

from __future__ import annotations

import os
import sys
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from fleetlog.errors import UsageError
from fleetlog.transport.session import etc_dir

__all__ = ["MACHINE_SETTINGS", "Settings", "load_settings", "say", "settings", "verbose"]

MACHINE_SETTINGS = "fleetlog.toml"
_KNOWN = {"root": str, "vehicle": str}


@dataclass(frozen=True)
class Settings:
    """The settings in force and where they came from."""

    path: Path | None = None
    how: str = "none"
    values: dict[str, str] = field(default_factory=dict)

    def get(self, name: str) -> str | None:
        """A setting's value, or None."""
        return self.values.get(name)

    def describe(self) -> str:
        """One phrase for --verbose and status."""
        if self.path is None:
            return "no settings file (built-in defaults)"
        why = {
            "--settings": "given by --settings",
            "FLEETLOG_SETTINGS": "named by FLEETLOG_SETTINGS",
            "machine-wide": "this machine's settings",
        }[self.how]
        shown = ", ".join(f"{k}={v!r}" for k, v in sorted(self.values.items())) or "empty"
        return f"{self.path} ({why}): {shown}"


def load_settings(explicit: Path | None) -> Settings:
    """Find and read the settings file.

    Raises:
        UsageError: the file named by --settings or FLEETLOG_SETTINGS is missing, or a
            settings file is not TOML or holds an unknown or mistyped setting.
    """
    path: Path | None = None
    how = "none"
    if explicit is not None:
        path, how = explicit, "--settings"
    elif os.environ.get("FLEETLOG_SETTINGS"):
        path, how = Path(os.environ["FLEETLOG_SETTINGS"]), "FLEETLOG_SETTINGS"
    else:
        machine = etc_dir() / MACHINE_SETTINGS
        if machine.is_file():
            path, how = machine, "machine-wide"
    if path is None:
        return Settings()
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        msg = f"settings file {path} does not exist"
        raise UsageError(msg) from None
    except (OSError, UnicodeDecodeError) as err:
        msg = f"cannot read settings file {path}: {err}"
        raise UsageError(msg) from None
    except tomllib.TOMLDecodeError as err:
        msg = f"settings file {path} is not TOML: {err}"
        raise UsageError(msg) from None
    values: dict[str, str] = {}
    for key, value in data.items():
        kind = _KNOWN.get(key)
        if kind is None:
            msg = f"settings file {path}: unknown setting {key!r} (known: {', '.join(_KNOWN)})"
            raise UsageError(msg)
        if not isinstance(value, kind) or not value.strip():
            msg = f"settings file {path}: {key} must be a non-empty string"
            raise UsageError(msg)
        values[key] = value
    return Settings(path, how, values)


class _State:
    settings_path: Path | None = None
    verbose = False
    loaded: Settings | None = None


def configure(settings_path: Path | None, is_verbose: bool) -> None:
    """Record the global options (the app's callback calls this)."""
    _State.settings_path = settings_path
    _State.verbose = is_verbose
    _State.loaded = None


def settings() -> Settings:
    """The settings in force (read once).

    Raises:
        UsageError: the settings file is unusable.
    """
    if _State.loaded is None:
        _State.loaded = load_settings(_State.settings_path)
    return _State.loaded


def verbose() -> bool:
    """Whether --verbose was given."""
    return _State.verbose


def say(text: str) -> None:
    """Print a --verbose line on stderr."""
    if _State.verbose:
        print(f"fleetlog: {text}", file=sys.stderr)
