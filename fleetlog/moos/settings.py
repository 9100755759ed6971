"""How MOOS reads the text of a setting: names, squeezed values, C's atof, MOOS booleans.

Pure helpers shared by the mission-file reader (:mod:`fleetlog.moos.mission`) and the pLogger
block's configuration (:mod:`fleetlog.moos.logger_config`), so that both read values exactly
as MOOS's ``CProcessConfigReader`` and pLogger do (MOOS_FORMAT.md §9).
"""

from __future__ import annotations

import math
import re

__all__ = [
    "CPP_SPACE",
    "FLOAT_RE",
    "INT_RE",
    "SQUEEZE_ALL",
    "TRIM",
    "c_atof",
    "is_moos_numeric",
    "key",
    "moos_bool",
    "squeeze",
]

# ``>> std::ws`` skips every C isspace character; MOOSTrimWhiteSpace trims only these four.
CPP_SPACE = " \t\n\v\f\r"
TRIM = " \t\n\r"
# MOOSRemoveChars(line, " \t\r"): the raw block list and GetTokenValPair.
_SQUEEZE = str.maketrans("", "", " \t\r")
# parse_log_spec removes every ASCII whitespace character (a PLOGGER_CMD string may hold \n).
SQUEEZE_ALL = str.maketrans("", "", CPP_SPACE)
_MOOS_NUMERIC = frozenset("1234567890.eE-+")
INT_RE = re.compile(r"[+-]?[0-9]+")
FLOAT_RE = re.compile(r"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")
# The longest prefix C's strtod/atof accepts (decimal, hexadecimal, inf, nan).
_ATOF_RE = re.compile(
    r"[ \t\n\v\f\r]*(?P<num>[+-]?(?:"
    r"(?P<hex>0x(?:[0-9a-f]+\.?[0-9a-f]*|\.[0-9a-f]+)(?:p[+-]?[0-9]+)?)"
    r"|(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:e[+-]?[0-9]+)?"
    r"|inf(?:inity)?"
    r"|nan(?:\([0-9a-z_]*\))?"
    r"))",
    re.IGNORECASE,
)


def squeeze(text: str) -> str:
    """Return the text without spaces, tabs and CRs (what ``MOOSRemoveChars`` leaves)."""
    return text.translate(_SQUEEZE)


def key(name: str) -> str:
    """Return the form MOOSStrCmp compares: upper case."""
    return name.upper()


def c_atof(text: str) -> float:
    """Return ``atof(text)``: the value of the longest numeric prefix, 0.0 if there is none."""
    match = _ATOF_RE.match(text)
    if match is None:
        return 0.0
    number = match.group("num")
    if match.group("hex") is not None:
        try:
            return float.fromhex(number)
        except OverflowError:
            return -math.inf if number.startswith("-") else math.inf
    lowered = number.lower()
    if "nan" in lowered:
        return math.nan
    return float(lowered)


def is_moos_numeric(text: str) -> bool:
    """Return ``MOOSIsNumeric(text)``: trimmed, only the characters ``0-9 . e E - +``."""
    return all(char in _MOOS_NUMERIC for char in text.strip(TRIM))


def moos_bool(text: str) -> bool:
    """Return a MOOS boolean: ``true`` in any case, or a number greater than 0."""
    return key(text) == "TRUE" or (is_moos_numeric(text) and c_atof(text) > 0)
