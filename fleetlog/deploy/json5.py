"""Render a configuration as JSON5 with comments an operator can read.

Zenoh reads JSON5; the files ``fleetlog deploy`` writes are read by people too, so each
choice that is not Zenoh's default carries a comment saying why.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from typing import Any

__all__ = ["render"]


def render(value: Mapping[str, Any], comments: Mapping[str, str], header: str = "") -> str:
    """Return ``value`` as JSON5 text.

    Args:
        value: the configuration (JSON types only).
        comments: ``"a/b/c"`` key paths → a comment written above that key.
        header: lines written first, as comments.
    """
    lines = [f"// {line}".rstrip() for line in header.splitlines()]
    lines.append(_value(value, "", comments, 0))
    return "\n".join(lines) + "\n"


def _value(value: Any, path: str, comments: Mapping[str, str], depth: int) -> str:
    pad = "  " * (depth + 1)
    if isinstance(value, Mapping):
        if not value:
            return "{}"
        out = ["{"]
        for key, item in value.items():
            sub = f"{path}/{key}" if path else key
            note = comments.get(sub)
            if note:
                out.extend(f"{pad}// {line}".rstrip() for line in note.splitlines())
            out.append(f"{pad}{_key(key)}: {_value(item, sub, comments, depth + 1)},")
        out.append("  " * depth + "}")
        return "\n".join(out)
    if isinstance(value, list) and value and any(isinstance(v, Mapping) for v in value):
        out = ["["]
        for item in value:
            out.append(f"{pad}{_value(item, path, comments, depth + 1)},")
        out.append("  " * depth + "]")
        return "\n".join(out)
    return json.dumps(value)


def _key(key: str) -> str:
    return key if key.isidentifier() else json.dumps(key)
