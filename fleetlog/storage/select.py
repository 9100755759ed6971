"""Which entries a grep, a clip or a merge keeps: variables, sources and a time window.

One filter for the remote grep (:mod:`fleetlog.query.grep`) and the offline tools
(:mod:`fleetlog.tools`): variables by MOOS glob, sources by MOOS glob (on the whole source
column or on the process name before ``:``/``@``, so ``pHelmIvP`` also finds
``pHelmIvP:HELM_VAR_INIT``), and a window of seconds since LOGSTART. It is a ``where`` for
:meth:`~fleetlog.storage.columnar.AlogReader.batches`: it runs on each block's entries before
their values are typed. Globs are matched once per distinct variable and source (a log of
millions of lines has a few hundred) with the MOOS glob matcher, and rows are then kept by
set membership, in Rust.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

from fleetlog.moos.alog import split_source
from fleetlog.wire.query import TimeBound

if TYPE_CHECKING:
    import polars as pl

__all__ = ["Selection"]


def glob_regex(pattern: str) -> str:
    """Return a MOOS glob as a whole-string regular expression for polars (Rust ``regex``).

    ``*`` matches any run of characters (also none), ``?`` one character, anything else
    itself, case-sensitively, as ``MOOSWildCmp`` does. Rust's ``regex`` runs in time linear
    in the text whatever the pattern (no backtracking), so a peer's ``*a*a*a*a*a*a*a*b``
    costs what ``*`` costs.
    """
    parts = []
    for char in pattern:
        if char == "*":
            parts.append(".*")
        elif char == "?":
            parts.append(".")
        elif char.isascii() and not char.isalnum():
            parts.append(f"\\x{{{ord(char):x}}}")
        else:
            parts.append(char)
    return "(?s)^" + "".join(parts) + "$"


def glob_literal(pattern: str) -> str:
    """Return the longest run of a MOOS glob's plain characters: text every match holds."""
    pieces = pattern.replace("?", "*").split("*")
    return max(pieces, key=len)


def _literals(patterns: Sequence[str]) -> tuple[str, ...] | None:
    """Texts one of which every name matching one of ``patterns`` holds (None: no such)."""
    pieces = {glob_literal(p) for p in patterns}
    if not patterns or "" in pieces:
        return None
    try:
        for piece in pieces:
            piece.encode("utf-8")  # a lone surrogate is no text polars can search
    except UnicodeEncodeError:
        return None
    return tuple(sorted(pieces))


def _any_glob(patterns: Sequence[str]) -> str | None:
    if not patterns:
        return None
    return "|".join(f"(?:{glob_regex(p)})" for p in patterns)


class Selection:
    """Decides which entries are kept; a ``where`` for the columnar reader.

    Globs are matched by polars' Rust regular expressions, in linear time, on each block's
    distinct names; nothing here runs a backtracking matcher or holds the GIL for long.
    :attr:`literals` tells the reader which lines can be kept at all: every name a glob
    matches holds the glob's longest run of plain characters (``NAV_X`` for ``NAV_X``,
    ``NAV_`` for ``NAV_*``), so every line it keeps holds one of them.

    Args:
        variables: MOOS globs of the variables to keep (none: every variable).
        sources: MOOS globs of the sources to keep (none: every source), tried on the whole
            source column and on the process name before ``:``/``@``.
        low: the earliest offset (seconds since LOGSTART) kept, or None.
        high: the latest offset kept, or None.
        keys: MOOS globs matched against the variable *or* the process name, as aloggrep's
            keys are (none: no such condition).
    """

    def __init__(
        self,
        variables: Sequence[str] = (),
        sources: Sequence[str] = (),
        low: float | None = None,
        high: float | None = None,
        keys: Sequence[str] = (),
    ) -> None:
        self.variables = tuple(variables)
        self.sources = tuple(sources)
        self.keys = tuple(keys)
        self.low = low
        self.high = high
        self._var_re = _any_glob(self.variables)
        self._source_re = _any_glob(self.sources)
        self._key_re = _any_glob(self.keys)
        #: Texts one of which the line of every kept entry holds (its variable, source or
        #: process name holds it), or None: a reader may leave the other lines unparsed.
        self.literals = _literals(self.variables) or _literals(self.keys) or _literals(self.sources)

    @classmethod
    def of(
        cls,
        variables: Sequence[str],
        sources: Sequence[str],
        start: TimeBound | None,
        end: TimeBound | None,
        logstart: float | None,
        keys: Sequence[str] = (),
    ) -> Selection:
        """Build a selection whose time bounds may be absolute (converted with LOGSTART).

        Raises:
            FormatError: an absolute time bound on a log without LOGSTART.
        """
        low = start.offset(logstart) if start else None
        high = end.offset(logstart) if end else None
        return cls(variables, sources, low, high, keys)

    @property
    def everything(self) -> bool:
        """True when nothing is filtered out."""
        return (
            not self.variables
            and not self.sources
            and not self.keys
            and self.low is None
            and self.high is None
        )

    def shifted(self, delta: float) -> Selection:
        """Return the same selection with its window moved by ``delta`` seconds."""
        return Selection(
            self.variables,
            self.sources,
            None if self.low is None else self.low + delta,
            None if self.high is None else self.high + delta,
            self.keys,
        )

    def __call__(self, heads: pl.DataFrame) -> pl.Series:
        """Return which of a block's entries are wanted (``var``, ``source``, ``offset``)."""
        offset = heads["offset"]
        keep = offset.is_not_null()
        if self.low is not None:
            keep = keep & (offset >= self.low)
        if self.high is not None:
            keep = keep & (offset <= self.high)
        if self._var_re is not None:
            keep = keep & heads["var"].is_in(_matching(heads["var"], self._var_re))
        if self._source_re is not None:
            keep = keep & heads["source"].is_in(_matching_source(heads["source"], self._source_re))
        if self._key_re is not None:
            by_var = _matching(heads["var"], self._key_re)
            by_source = _matching_source(heads["source"], self._key_re)
            keep = keep & (heads["var"].is_in(by_var) | heads["source"].is_in(by_source))
        return keep


def _matching(names: pl.Series, regex: str) -> pl.Series:
    """The distinct names that match (in Rust: linear time, without the GIL)."""
    distinct = names.unique()
    return distinct.filter(distinct.str.contains(regex))


def _matching_source(sources: pl.Series, regex: str) -> pl.Series:
    """The distinct source columns whose whole text or process name matches."""
    import polars as pl

    distinct = sources.unique()
    process = pl.Series([split_source(s)[0] for s in distinct.to_list()], dtype=pl.String)
    return distinct.filter(distinct.str.contains(regex) | process.str.contains(regex))
