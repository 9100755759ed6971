"""Which entries the player publishes: source and variable filters.

Source filtering is uPlayBack's check-list (MOOS_FORMAT.md §8.3) with globs: the typical use
is to leave out the processes that will run live again, so only the others are "faked". A
source pattern is matched against the source field exactly as written (``pHelmIvP:HELM_VAR_INIT``,
``pMarineViewer@shoreside``, as uPlayBack matches) and against the bare process name
(``pHelmIvP``), so ``--exclude-source pHelmIvP`` removes the helm whatever aux or community
its lines carry. Variable patterns are MOOS globs on the variable name. Patterns are
case-sensitive, like every MOOS name.

Verdicts are cached per source field and per variable: the same few values repeat on every
line.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

from fleetlog.moos.alog import split_source
from fleetlog.moos.patterns import MoosGlob

__all__ = ["EntryFilter", "FilterSpec"]

_CACHE_LIMIT = 65536


@dataclass(frozen=True)
class FilterSpec:
    """The filter options, as patterns (MOOS globs: ``*`` any run, ``?`` one character).

    Attributes:
        include_sources: if any, only sources matching one of them are published.
        exclude_sources: sources matching any of them are not published (wins over include).
        include_vars: if any, only variables matching one of them are published.
        exclude_vars: variables matching any of them are not published (wins over include).
    """

    include_sources: tuple[str, ...] = ()
    exclude_sources: tuple[str, ...] = ()
    include_vars: tuple[str, ...] = ()
    exclude_vars: tuple[str, ...] = ()


def _globs(patterns: Iterable[str]) -> tuple[MoosGlob, ...]:
    return tuple(MoosGlob(p) for p in patterns)


def _any(globs: Sequence[MoosGlob], names: Sequence[str]) -> bool:
    return any(glob.matches(name) for glob in globs for name in names)


class EntryFilter:
    """Decides, per entry, whether the player publishes it.

    Args:
        spec: the patterns.
    """

    def __init__(self, spec: FilterSpec | None = None) -> None:
        self.spec = spec or FilterSpec()
        self._inc_src = _globs(self.spec.include_sources)
        self._exc_src = _globs(self.spec.exclude_sources)
        self._inc_var = _globs(self.spec.include_vars)
        self._exc_var = _globs(self.spec.exclude_vars)
        self._sources: dict[str, bool] = {}
        self._vars: dict[str, bool] = {}
        self.active = bool(self._inc_src or self._exc_src or self._inc_var or self._exc_var)

    def source_allowed(self, source: str) -> bool:
        """Return whether a source field (as written in the alog) passes."""
        verdict = self._sources.get(source)
        if verdict is None:
            names = (source, split_source(source)[0])
            verdict = not _any(self._exc_src, names) and (
                not self._inc_src or _any(self._inc_src, names)
            )
            if len(self._sources) >= _CACHE_LIMIT:
                self._sources.clear()
            self._sources[source] = verdict
        return verdict

    def var_allowed(self, name: str) -> bool:
        """Return whether a variable name passes."""
        verdict = self._vars.get(name)
        if verdict is None:
            verdict = not _any(self._exc_var, (name,)) and (
                not self._inc_var or _any(self._inc_var, (name,))
            )
            if len(self._vars) >= _CACHE_LIMIT:
                self._vars.clear()
            self._vars[name] = verdict
        return verdict

    def allows(self, key: str, source: str) -> bool:
        """Return whether an entry of variable ``key`` from ``source`` is published."""
        if not self.active:
            return True
        return self.var_allowed(key) and self.source_allowed(source)
