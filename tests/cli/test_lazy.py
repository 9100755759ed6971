"""The CLI imports only the module of the command it runs (fleetlog/cli/commands.py).

The table of which module registers which command is checked against what the modules
register; then the real CLI, as a subprocess, runs an offline command without importing the
recorder, the bridge, the query server or the deploy kit, and ``--help`` still lists every
command.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
import typer
from helpers import run_cli

from fleetlog.cli import commands
from fleetlog.cli.app import app
from fleetlog.moos.alog import LineFormatter, format_banner


def test_the_table_names_the_module_of_every_registered_command() -> None:
    commands.load_all()
    group = typer.main.get_command(app)
    assert isinstance(group, typer.core.TyperGroup)
    registered: dict[str, str] = {}
    for name, command in group.commands.items():
        subcommands = getattr(command, "commands", None)
        callbacks = (
            [sub.callback for sub in subcommands.values()] if subcommands else [command.callback]
        )
        (module,) = {callback.__module__ for callback in callbacks if callback is not None}
        registered[name] = module.removeprefix("fleetlog.cli.")
    assert registered == commands.MODULES


@pytest.mark.parametrize(
    ("argv", "name"),
    [
        (["grep", "f.alog", "X"], "grep"),
        (["--verbose", "info", "f.alog"], "info"),
        (["--settings", "s.toml", "record"], "record"),
        (["--settings", "info", "sort"], "sort"),  # a settings file named like a command
        (["--help"], None),
        ([], None),
    ],
)
def test_the_command_is_the_first_argument_after_the_apps_options(
    argv: list[str], name: str | None
) -> None:
    assert commands.command_name(argv) == name


_MODULES_AT_EXIT = """
import atexit, json, sys
atexit.register(lambda: print(json.dumps([m for m in sys.modules if m.startswith("fleetlog")]),
                              file=sys.stderr))
sys.argv = ["fleetlog", *sys.argv[1:]]
from fleetlog.cli import main
main()
"""


def _loaded(argv: list[str], cwd: Path) -> tuple[subprocess.CompletedProcess[str], set[str]]:
    """Run the CLI with ``argv``; return its result and the fleetlog modules it imported."""
    done = subprocess.run(
        [sys.executable, "-c", _MODULES_AT_EXIT, *argv],
        capture_output=True,
        text=True,
        cwd=cwd,
        timeout=60,
    )
    last = done.stderr.strip().splitlines()[-1]
    return done, set(json.loads(last))


def test_an_offline_command_does_not_import_the_services(tmp_path: Path) -> None:
    fmt = LineFormatter()
    log = tmp_path / "a.alog"
    log.write_text(format_banner("./a/a.alog", 1.7e9, "now") + fmt.double(0.5, "NAV_X", "p", 1.0))
    done, loaded = _loaded(["grep", str(log), "NAV_X"], tmp_path)
    assert done.returncode == 0, done.stderr
    assert "NAV_X" in done.stdout
    assert "fleetlog.cli.tools" in loaded
    heavy = {"fleetlog.recorder.engine", "fleetlog.bridge.service", "fleetlog.query.server"}
    assert not heavy & loaded
    assert "fleetlog.cli.record" not in loaded
    assert "fleetlog.cli.deploy" not in loaded


def test_version_loads_no_command(tmp_path: Path) -> None:
    done, loaded = _loaded(["--version"], tmp_path)
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith("fleetlog ")
    assert not {m for m in loaded if m.startswith("fleetlog.cli.") and m != "fleetlog.cli.app"} - {
        "fleetlog.cli.commands",
        "fleetlog.cli.settings",
    }


def test_help_lists_every_command(tmp_path: Path, cli_env: dict[str, str]) -> None:
    done = run_cli("--help", env=cli_env)
    assert done.returncode == 0, done.stderr
    for name in commands.MODULES:
        assert name in done.stdout
    unknown = run_cli("gerp", env=cli_env)
    assert unknown.returncode != 0
    assert "gerp" in unknown.stderr
