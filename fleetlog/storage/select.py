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
from fleetlog.moos.patterns import MoosGlob
from fleetlog.wire.query import TimeBound

if TYPE_CHECKING:
    import polars as pl

__all__ = ["Selection"]

#: Distinct names whose verdict is remembered; past that the memory starts over.
_MAX_VERDICTS = 65536


class Selection:
    """Decides which entries are kept; a ``where`` for the columnar reader.

    Args:
        variables: MOOS globs of the variables to keep (none: every variable).
        sources: MOOS globs of the sources to keep (none: every source).
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
        self._keys = Selection(keys, ()) if keys else None
        self._key_sources = Selection((), keys) if keys else None
        self._vars = [MoosGlob(p) for p in variables]
        self._sources = [MoosGlob(p) for p in sources]
        self.low = low
        self.high = high
        self._var_verdicts: dict[str, bool] = {}
        self._source_verdicts: dict[str, bool] = {}

    @classmethod
    def of(
        cls,
        variables: Sequence[str],
        sources: Sequence[str],
        start: TimeBound | None,
        end: TimeBound | None,
        logstart: float | None,
    ) -> Selection:
        """Build a selection whose time bounds may be absolute (converted with LOGSTART).

        Raises:
            FormatError: an absolute time bound on a log without LOGSTART.
        """
        low = start.offset(logstart) if start else None
        high = end.offset(logstart) if end else None
        return cls(variables, sources, low, high)

    @property
    def everything(self) -> bool:
        """True when nothing is filtered out."""
        return (
            not self._vars
            and not self._sources
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

    def var_ok(self, key: str) -> bool:
        """Return True if a variable name is wanted."""
        verdict = self._var_verdicts.get(key)
        if verdict is None:
            verdict = not self._vars or any(g.matches(key) for g in self._vars)
            if len(self._var_verdicts) >= _MAX_VERDICTS:
                self._var_verdicts.clear()
            self._var_verdicts[key] = verdict
        return verdict

    def source_ok(self, source: str) -> bool:
        """Return True if a source column is wanted (whole, or its process name)."""
        verdict = self._source_verdicts.get(source)
        if verdict is None:
            process = split_source(source)[0]
            verdict = not self._sources or any(
                g.matches(source) or g.matches(process) for g in self._sources
            )
            if len(self._source_verdicts) >= _MAX_VERDICTS:
                self._source_verdicts.clear()
            self._source_verdicts[source] = verdict
        return verdict

    def time_ok(self, offset: float) -> bool:
        """Return True if an offset lies in the window."""
        return (self.low is None or offset >= self.low) and (
            self.high is None or offset <= self.high
        )

    def __call__(self, heads: pl.DataFrame) -> pl.Series:
        """Return which of a block's entries are wanted (``var``, ``source``, ``offset``)."""
        offset = heads["offset"]
        keep = offset.is_not_null()
        if self.low is not None:
            keep = keep & (offset >= self.low)
        if self.high is not None:
            keep = keep & (offset <= self.high)
        if self._vars:
            names = [k for k in heads["var"].unique().to_list() if self.var_ok(k)]
            keep = keep & heads["var"].is_in(names)
        if self._sources:
            names = [s for s in heads["source"].unique().to_list() if self.source_ok(s)]
            keep = keep & heads["source"].is_in(names)
        if self._keys is not None and self._key_sources is not None:
            by_var = [k for k in heads["var"].unique().to_list() if self._keys.var_ok(k)]
            by_src = [
                s for s in heads["source"].unique().to_list() if self._key_sources.source_ok(s)
            ]
            keep = keep & (heads["var"].is_in(by_var) | heads["source"].is_in(by_src))
        return keep
