"""Selector parameters: the ``a=1;b=x|y`` strings every fleetlog service reads (docs/wire.md).

Pure code: :func:`parse_parameters` splits and percent-decodes a request's parameters
against the names a service takes, :func:`format_parameters` writes them, and
:func:`int_parameter` / :func:`flag_parameter` read one bounded value. :func:`split_server`
and :func:`with_server` take out and add the ``server=ZID`` every service accepts. Every
parser is bounded (:data:`MAX_PARAMETERS`), so a garbled request costs nothing to refuse.
The services' keys and requests are in :mod:`fleetlog.wire.query`, control's in
:mod:`fleetlog.wire.control`.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Mapping, Sequence
from urllib.parse import quote, unquote_to_bytes

from fleetlog.errors import FormatError
from fleetlog.wire.replies import (
    SERVER,
)

__all__ = [
    "MAX_PARAMETERS",
    "flag_parameter",
    "format_parameters",
    "int_parameter",
    "parse_parameters",
    "split_server",
    "with_server",
]

#: bounds on what a request may carry, so a garbled one costs nothing to refuse
MAX_PARAMETERS = 8192
_PERCENT = re.compile(r"%(?![0-9A-Fa-f]{2})")
_INT = re.compile(r"[0-9]{1,16}")
_ZID = re.compile(r"[0-9a-f]{1,32}")


def parse_parameters(text: str, known: Iterable[str]) -> dict[str, str]:
    """Split selector parameters ``a=1;b=x|y`` into a dict, percent-decoding the values.

    Args:
        text: the selector's parameters, as received.
        known: the parameter names the service accepts.

    Returns:
        name → decoded value (a flag written without ``=`` has the value ``""``).

    Raises:
        FormatError: the text is too long, a parameter is unknown or given twice, or a value
            holds a ``%`` that is not followed by two hex digits.
    """
    if len(text) > MAX_PARAMETERS:
        msg = f"the parameters are {len(text)} characters long; at most {MAX_PARAMETERS}"
        raise FormatError(msg)
    allowed = frozenset(known)
    out: dict[str, str] = {}
    for item in text.split(";") if text else ():
        if not item:
            continue
        name, _, raw = item.partition("=")
        if name not in allowed:
            expected = ", ".join(sorted(allowed)) or "none"
            msg = f"unknown parameter {name[:40]!r}; this service takes {expected}"
            raise FormatError(msg)
        if name in out:
            msg = f"parameter {name!r} is given twice"
            raise FormatError(msg)
        out[name] = _unquote(name, raw)
    return out


def _unquote(name: str, raw: str) -> str:
    if _PERCENT.search(raw):
        msg = f"parameter {name!r} holds a '%' that is not followed by two hex digits"
        raise FormatError(msg)
    # Percent escapes spell UTF-8 bytes; undecodable ones survive as surrogate escapes (and
    # so does a raw one, which only a local caller can pass: Zenoh's selectors are UTF-8).
    value = unquote_to_bytes(raw.encode("utf-8", "surrogateescape")).decode(
        "utf-8", "surrogateescape"
    )
    if "\x00" in value:
        msg = f"parameter {name!r} holds a NUL character"
        raise FormatError(msg)
    return value


def _quote(value: str) -> str:
    return quote(value.encode("utf-8", "surrogateescape"), safe="*?@:,.-_+~")


def format_parameters(values: Mapping[str, str | int | float | bool | Sequence[str] | None]) -> str:
    """Return selector parameters for a request; the inverse of :func:`parse_parameters`.

    None and False are left out, True becomes ``name=1``, a sequence joins its quoted items
    with ``|``.
    """
    items: list[str] = []
    for name, value in values.items():
        if value is None or value is False:
            continue
        if value is True:
            items.append(f"{name}=1")
        elif isinstance(value, str):
            items.append(f"{name}={_quote(value)}")
        elif isinstance(value, int | float):
            items.append(f"{name}={value!r}")
        else:
            items.append(f"{name}=" + "|".join(_quote(v) for v in value))
    return ";".join(items)


def int_parameter(params: Mapping[str, str], name: str, default: int, low: int, high: int) -> int:
    """Return parameter ``name`` as a whole number in ``[low, high]`` (``default`` if absent).

    Raises:
        FormatError: the value is not a number of at most 16 digits, or out of bounds.
    """
    text = params.get(name)
    if text is None:
        return default
    if not _INT.fullmatch(text):
        msg = f"parameter {name!r} must be a whole number of at most 16 digits, not {text[:40]!r}"
        raise FormatError(msg)
    value = int(text)
    if not low <= value <= high:
        msg = f"parameter {name!r} must be between {low} and {high}, not {value}"
        raise FormatError(msg)
    return value


def flag_parameter(params: Mapping[str, str], name: str) -> bool:
    """Return parameter ``name`` as a flag (absent, ``0`` or ``false`` is False).

    Raises:
        FormatError: the value is not one of ``1``, ``0``, ``true``, ``false`` or empty.
    """
    text = params.get(name)
    if text is None or text in ("0", "false"):
        return False
    if text in ("", "1", "true"):
        return True
    msg = f"parameter {name!r} must be 1 or 0, not {text[:40]!r}"
    raise FormatError(msg)


def split_server(text: str) -> tuple[str | None, str]:
    """Take the ``server=ZID`` parameter out of a request's parameters.

    Returns:
        The Zenoh id asked for (None if the request names none) and the other parameters,
        for the service's own parser.

    Raises:
        FormatError: the parameters are too long, or the id is not 1-32 lower-case hex
            digits.
    """
    if len(text) > MAX_PARAMETERS:
        msg = f"the parameters are {len(text)} characters long; at most {MAX_PARAMETERS}"
        raise FormatError(msg)
    if SERVER not in text:
        return None, text
    server: str | None = None
    rest: list[str] = []
    for item in text.split(";"):
        name, _, value = item.partition("=")
        if name != SERVER:
            rest.append(item)
            continue
        if server is not None:
            msg = f"parameter {SERVER!r} is given twice"
            raise FormatError(msg)
        if not _ZID.fullmatch(value):
            msg = f"parameter {SERVER!r} must be a Zenoh id (hex), not {value[:40]!r}"
            raise FormatError(msg)
        server = value
    return server, ";".join(rest)


def with_server(parameters: str, server: str | None) -> str:
    """Return ``parameters`` with ``server=ZID`` added (unchanged for None)."""
    if server is None:
        return parameters
    return f"{parameters};{SERVER}={server}" if parameters else f"{SERVER}={server}"
