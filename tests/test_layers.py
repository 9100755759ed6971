"""The layering of shared/STYLE.md §4, enforced.

Imports flow one way: cli -> engines (recorder, query, shore, replayer, tools, bridge) ->
storage | transport -> wire -> moos -> errors. Only transport/ imports zenoh, only cli/ imports
typer, and the pure layers (moos/, wire/) never touch files, sockets or clocks. The shore side
(shore/) and the vehicle-side services (query/, recorder/) never import each other: they meet
only in the wire protocol.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import fleetlog

PACKAGE = Path(fleetlog.__file__).parent

#: what each layer may import from fleetlog (besides itself and errors)
ALLOWED: dict[str, set[str]] = {
    "moos": set(),
    "wire": {"moos"},
    "storage": {"moos", "wire"},
    "transport": {"moos", "wire"},
    "recorder": {"moos", "wire", "storage", "transport"},
    "query": {"moos", "wire", "storage", "transport"},
    "shore": {"moos", "wire", "storage", "transport"},
    "replayer": {"moos", "wire", "storage", "transport", "shore"},
    "tools": {"moos", "wire", "storage"},
    "export": {"moos", "wire", "storage", "tools"},
    "bridge": {"moos", "wire", "storage", "transport"},
    "api": {"moos", "wire", "transport"},
    "deploy": {"moos", "wire", "storage", "transport"},
    "cli": {
        *("moos", "wire", "storage", "transport"),
        *("recorder", "query", "shore", "replayer", "tools", "api", "bridge", "deploy", "export"),
    },
}
PURE_FORBIDDEN = {"socket", "zenoh", "typer", "threading", "subprocess", "shutil"}


def _modules() -> list[Path]:
    return sorted(p for p in PACKAGE.rglob("*.py"))


def _layer(path: Path) -> str:
    rel = path.relative_to(PACKAGE)
    return rel.parts[0].removesuffix(".py")


def _imports(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
    return names


@pytest.mark.parametrize("path", _modules(), ids=lambda p: str(p.relative_to(PACKAGE)))
def test_imports_flow_one_way(path: Path) -> None:
    layer = _layer(path)
    if layer not in ALLOWED:
        return  # __init__, __main__, errors
    for name in _imports(path):
        top = name.split(".")[0]
        if top == "zenoh":
            assert layer == "transport", f"{path.name} imports zenoh outside transport/"
        if top == "typer":
            assert layer == "cli", f"{path.name} imports typer outside cli/"
        if top != "fleetlog" or name in ("fleetlog", "fleetlog.errors"):
            continue
        target = name.split(".")[1]
        if target in ("errors", "__init__") or target == layer:
            continue
        assert target in ALLOWED[layer], f"{path.name} ({layer}) imports {name}"


@pytest.mark.parametrize(
    "path",
    [p for p in _modules() if _layer(p) in ("moos", "wire")],
    ids=lambda p: str(p.relative_to(PACKAGE)),
)
def test_pure_layers_stay_pure(path: Path) -> None:
    for name in _imports(path):
        assert name.split(".")[0] not in PURE_FORBIDDEN, f"{path.name} imports {name}"
    source = path.read_text(encoding="utf-8")
    for call in ("open(", "time.time(", "time.localtime(", "datetime.now("):
        assert call not in source.replace("def open(", ""), f"{path.name} calls {call}"
