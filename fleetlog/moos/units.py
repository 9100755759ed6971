"""Sizes and durations as operators write them: ``500MB``, ``2 GiB``, ``10min``, ``90``.

Pure helpers for the recording-mode settings (``SplitSize``, ``SplitDuration``, and the disk
and snapshot bounds), shared by the mission reader and the command line so that both accept
exactly the same text and say the same thing about text they refuse.

* A size is a number of bytes, or a number with a unit: ``B``, ``kB``, ``MB``, ``GB``,
  ``TB`` (powers of 1000, as disks are sold) or ``KiB``, ``MiB``, ``GiB``, ``TiB`` (powers of
  1024). Units are read in any case (MOOS reads names in any case; nobody means megabits).
* A duration is a number of seconds, or a number with a unit: ``s``, ``min``, ``h`` (also
  ``sec``, ``m``, ``hr``, ``d`` for days).
"""

from __future__ import annotations

import math
import re

from fleetlog.errors import FormatError

__all__ = ["MAX_DURATION", "MAX_SIZE", "human_size", "parse_duration", "parse_size"]

#: the largest size read: 1 PB (a larger value is a typo, not a plan)
MAX_SIZE = 10**15
#: the longest duration read: a year
MAX_DURATION = 366 * 86400.0
#: the longest text read (a value is a number and a unit)
_MAX_TEXT = 64

_NUMBER = re.compile(
    r"\s*([0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE]([+-]?[0-9]{1,3}))?\s*([A-Za-z]*)\s*"
)
_SIZE_UNITS = {
    "": 1,
    "b": 1,
    "kb": 10**3,
    "mb": 10**6,
    "gb": 10**9,
    "tb": 10**12,
    "kib": 1 << 10,
    "mib": 1 << 20,
    "gib": 1 << 30,
    "tib": 1 << 40,
}
_DURATION_UNITS = {
    "": 1.0,
    "s": 1.0,
    "sec": 1.0,
    "m": 60.0,
    "min": 60.0,
    "h": 3600.0,
    "hr": 3600.0,
    "d": 86400.0,
}


def _split(text: str, what: str) -> tuple[float, str]:
    if len(text) > _MAX_TEXT:
        msg = f"{what} is {len(text)} characters long; at most {_MAX_TEXT}"
        raise FormatError(msg)
    match = _NUMBER.fullmatch(text)
    if match is None:
        msg = f"{what} {text.strip()!r} is not a number with an optional unit"
        raise FormatError(msg)
    number = float(match.group(1) + (f"e{match.group(2)}" if match.group(2) else ""))
    return number, match.group(3).lower()


def parse_size(text: str, *, name: str = "size") -> int:
    """Return the number of bytes ``text`` says (``500MB``, ``2GiB``, ``1048576``).

    Args:
        text: the value.
        name: what the value is, for the message (``SplitSize``).

    Raises:
        FormatError: not a non-negative number with one of the units above, or larger
            than :data:`MAX_SIZE`.
    """
    number, unit = _split(text, name)
    scale = _SIZE_UNITS.get(unit)
    if scale is None:
        msg = (
            f"{name} {text.strip()!r} has an unknown unit {unit!r}; "
            "use B, kB, MB, GB, TB or KiB, MiB, GiB, TiB"
        )
        raise FormatError(msg)
    value = number * scale
    if not math.isfinite(value) or value > MAX_SIZE:
        msg = f"{name} {text.strip()!r} is too large: at most 1 PB"
        raise FormatError(msg)
    return int(value)


def parse_duration(text: str, *, name: str = "duration") -> float:
    """Return the number of seconds ``text`` says (``10min``, ``1.5h``, ``90``).

    Args:
        text: the value.
        name: what the value is, for the message (``SplitDuration``).

    Raises:
        FormatError: not a non-negative number with one of the units above, or longer
            than :data:`MAX_DURATION`.
    """
    number, unit = _split(text, name)
    scale = _DURATION_UNITS.get(unit)
    if scale is None:
        msg = f"{name} {text.strip()!r} has an unknown unit {unit!r}; use s, min or h"
        raise FormatError(msg)
    value = number * scale
    if not math.isfinite(value) or value > MAX_DURATION:
        msg = f"{name} {text.strip()!r} is too long: at most a year"
        raise FormatError(msg)
    return value


def human_size(size: int) -> str:
    """``1536`` → ``1.5 KiB`` (binary units, one decimal)."""
    value = float(size)
    for unit in ("B", "KiB", "MiB", "GiB"):
        if value < 1024 or unit == "GiB":
            return f"{value:.0f} {unit}" if unit == "B" else f"{value:.1f} {unit}"
        value /= 1024
    return f"{value:.1f} TiB"  # pragma: no cover - the loop returns
