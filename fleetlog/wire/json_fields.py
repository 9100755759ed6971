"""Reading a peer's JSON field by field, as every reply decoder of the wire layer does.

Pure code. :func:`parse_json` parses a peer's JSON (huge integers refused, nesting
bounded), :func:`load_object` parses a JSON object,
:func:`required_field` and :func:`optional_field` take one field and check its type (a bool
is never taken for a number), :func:`dump_json` writes compact ASCII JSON. Each refusal is a
:class:`~fleetlog.errors.FormatError` that names what was read and the field, so a reply
from a peer that lies is refused, never half-read.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from typing import Any

from fleetlog.errors import FormatError

__all__ = ["dump_json", "load_object", "optional_field", "parse_json", "required_field"]

#: integers a peer's JSON may hold: every count, size and time fleetlog writes fits in 64 bits;
#: a larger one (10**400 is valid JSON) would overflow the first float() it meets
_INT_LIMIT = 1 << 64


def _number_int(text: str) -> int:
    number = int(text)
    if not -_INT_LIMIT < number < _INT_LIMIT:
        msg = f"an integer of {len(text)} digits is beyond 64 bits"
        raise ValueError(msg)
    return number


def parse_json(data: bytes | str) -> Any:
    """Parse a peer's JSON, refusing what has crashed readers that trusted the parse.

    Python's parser takes integers of thousands of digits (the first ``float()`` of one
    raises OverflowError) and recurses once per nesting level (RecursionError): both are
    refused here like any other bad JSON. NaN and Infinity are kept (a double may be one;
    ``1e400`` reads as inf): a reader that needs a finite number checks for one.

    Raises:
        ValueError: not JSON, an integer beyond 64 bits, or nested deeper than the
            interpreter can follow.
    """
    try:
        return json.loads(data, parse_int=_number_int)
    except RecursionError:
        msg = "nested too deeply"
        raise ValueError(msg) from None


def required_field(
    obj: Mapping[str, Any], name: str, kind: type | tuple[type, ...], what: str
) -> Any:
    """Return ``obj[name]``, checked to be of ``kind``.

    Raises:
        FormatError: the field is missing or of another type.
    """
    value = obj.get(name)
    if not isinstance(value, kind) or (isinstance(value, bool) and kind in (int, float)):
        msg = f"{what}: field {name!r} is missing or has the wrong type"
        raise FormatError(msg)
    return value


def optional_field(
    obj: Mapping[str, Any], name: str, kind: type | tuple[type, ...], what: str
) -> Any:
    """Return ``obj[name]`` checked as :func:`required_field` does, or None if absent or null."""
    return None if obj.get(name) is None else required_field(obj, name, kind, what)


def load_object(data: bytes | str, what: str) -> dict[str, Any]:
    """Parse ``data`` as a JSON object.

    Raises:
        FormatError: not JSON, or not an object.
    """
    try:
        obj = parse_json(data)
    except ValueError as err:
        msg = f"{what} is not JSON: {str(err)[:80]}"
        raise FormatError(msg) from None
    if not isinstance(obj, dict):
        msg = f"{what} is not a JSON object"
        raise FormatError(msg)
    return obj


def dump_json(obj: object) -> bytes:
    """Return ``obj`` as compact ASCII JSON."""
    # ensure_ascii keeps surrogate-escaped bytes as \udcXX, which json.loads gives back.
    return json.dumps(obj, separators=(",", ":")).encode("ascii")
