r"""What a received sample's fields may hold, and what is done with what they may not.

The recorder writes every field of a sample into a line of text that other programs split
again: pLogger's columns (time, variable, source) are separated by runs of spaces, lines by
``\n``, and the source column is split once more at ``:`` (aux) and at its last ``@``
(community). A peer can put anything into a key chunk or an attachment, so every field is
checked where samples enter (``transport.bus.SampleDecoder``), by one rule (docs/wire.md,
"What a field may hold"):

* **name, source, aux, community**: a character is *unsafe* if it is a space or is not
  printable (``str.isprintable``: control characters, tabs, every line or paragraph
  separator, every other whitespace, format characters, unassigned code points), except a
  lone surrogate ``U+DC80``–``U+DCFF``, which stands for a byte that was not UTF-8 and is
  written as that byte. In the source, ``:`` and ``@`` are unsafe too (they would start an
  aux or a community); in the aux and the community, ``@``. Each unsafe character is
  replaced by ``%XX`` for each byte of its UTF-8 form (upper-case hex). An empty name becomes
  ``%00`` (as its key chunk is spelled). An empty source stays empty (the recorder logs
  it as ``?``, docs/wire.md).
* **times**: a time must be finite and within ``[0, MAX_TIME]``; another is dropped (the
  message time then comes from the Zenoh timestamp or the arrival time; an original time is
  dropped).
* **string values**: a ``\n`` followed by what would start an entry or a comment in the
  next line (an ASCII digit, ``-`` and a digit, or ``%``) is written as the two characters
  ``\n``; every other multi-line value is written verbatim, as pLogger writes it.

Anything replaced is counted as *garbled*: nothing is written that a reader would split
differently, and nothing is changed silently. The replacement is one-way: ``%`` itself is
not escaped, so a well-formed name or source is never changed.
"""

from __future__ import annotations

import re

__all__ = [
    "EMPTY_NAME",
    "MAX_TIME",
    "clean_name",
    "clean_origin",
    "clean_value",
    "time_ok",
]

#: the latest time a sample may carry: 2286-11-20, far past any clock, far below where a
#: float's text would grow absurd
MAX_TIME = 1e10
#: what an empty variable name is logged as (its key chunk's spelling)
EMPTY_NAME = "%00"

_BYTE_SURROGATES = frozenset(chr(0xDC00 + b) for b in range(0x80, 0x100))
_SOURCE_EXTRA = frozenset(":@")
_AUX_EXTRA = frozenset("@")
# A newline that would let the next line pass for an entry or a comment.
_FORGING_NEWLINE = re.compile(r"\n(?=[0-9%]|-[0-9])")


def _unsafe(char: str, extra: frozenset[str]) -> bool:
    if char in extra or char == " ":
        return True
    return not char.isprintable() and char not in _BYTE_SURROGATES


def _escape(text: str, extra: frozenset[str]) -> tuple[str, bool]:
    if text.isprintable() and " " not in text and not (extra and any(c in extra for c in text)):
        return text, False  # the common case, decided in C
    out: list[str] = []
    changed = False
    for char in text:
        if _unsafe(char, extra):
            out.extend(f"%{b:02X}" for b in char.encode("utf-8", "surrogatepass"))
            changed = True
        else:
            out.append(char)
    return "".join(out), changed


def clean_name(name: str) -> tuple[str, bool]:
    """Return the variable name as it may be logged, and whether it had to change.

    Args:
        name: the name a key chunk spells (any string).

    Returns:
        ``(name, changed)``: ``changed`` is True when an unsafe character was escaped or the
        name was empty.
    """
    if not name:
        return EMPTY_NAME, True
    return _escape(name, frozenset())


def clean_origin(source: str, aux: str, community: str) -> tuple[str, str, str, bool]:
    """Return an attachment's source, aux and community as they may be logged.

    Returns:
        ``(source, aux, community, changed)``; ``changed`` is True when any of them had an
        unsafe character escaped.
    """
    source, s_changed = _escape(source, _SOURCE_EXTRA)
    aux, a_changed = _escape(aux, _AUX_EXTRA)
    community, c_changed = _escape(community, _AUX_EXTRA)
    return source, aux, community, s_changed or a_changed or c_changed


def time_ok(when: float) -> bool:
    """Return True if a sample's time may be used: finite and within ``[0, MAX_TIME]``."""
    return 0.0 <= when <= MAX_TIME  # False for NaN too


def clean_value(value: str) -> tuple[str, bool]:
    r"""Return a string value as it may be logged, and whether it had to change.

    A ``\n`` that a reader would take for the end of the entry (the next line would start
    with a digit, ``-`` and a digit, or ``%``) becomes the two characters ``\n``.
    """
    if "\n" not in value:
        return value, False
    cleaned = _FORGING_NEWLINE.sub(r"\\n", value)
    return cleaned, cleaned != value
