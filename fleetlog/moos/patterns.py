"""MOOS names and wildcard patterns, mapped onto Zenoh key chunks (MOOS_FORMAT.md §6.4).

Pure code: strings in, strings, booleans and verdicts out. Nothing here imports zenoh; the
tests check every rule below against ``zenoh.KeyExpr``.

**Escaping a name into one key chunk.** Any MOOS name (a variable or a community) becomes one
Zenoh key chunk by a documented, reversible rule; a name is never dropped or merged with
another:

* ``%`` → ``%25``, ``/`` → ``%2F``, ``*`` → ``%2A``, ``$`` → ``%24``, ``?`` → ``%3F``,
  ``#`` → ``%23``, wherever they occur. (Zenoh splits keys at ``/``, reads ``*`` and ``$*`` as
  wildcards, and refuses ``?``, ``#`` and any other ``$``; ``%`` is the escape character.)
* an ``@`` at position 0 → ``%40`` (a chunk starting with ``@`` is a *verbatim* chunk, which no
  wildcard matches); an ``@`` anywhere else stays as it is;
* the empty name → the chunk ``%00`` (Zenoh forbids empty chunks; no other name produces it,
  because NUL is never escaped and ``%`` always is);
* a lone surrogate ``U+DC80``–``U+DCFF`` (how Python's ``surrogateescape`` carries a byte
  ``0x80``–``0xFF`` that is not UTF-8) → ``%80``–``%FF``, so names read as raw bytes survive
  too; any other surrogate cannot be sent at all and raises :class:`FormatError`;
* every other character, spaces, control characters and non-ASCII letters included, stays as
  it is: Zenoh accepts it, and the key stays readable (``NAV_X`` is ``NAV_X``, the default
  community ``#1`` is ``%231``).

Hex digits are upper case. :func:`chunk_to_name` accepts exactly the chunks
:func:`name_to_chunk` produces (lower-case hex, a ``%40`` after position 0, a raw ``*`` and so
on raise :class:`FormatError`), so the mapping is a bijection between names and valid chunks:
two names never share a key, and a key always names one variable.

**Globs.** MOOS matches names with ``MOOSWildCmp``: case-sensitive, ``*`` matches any run of
characters (also none), ``?`` exactly one, everything else itself. :class:`MoosGlob` does the
same, in time linear in the name and without backtracking, so a hostile pattern cannot stall
the process that matches it. :func:`glob_to_chunk` returns the narrowest chunk expression
that admits *at least* every escaped name the glob matches (Zenoh has no single-character
wildcard, so ``?`` widens to ``$*``); subscribers filter exactly on arrival with
:class:`MoosGlob`. :class:`WildcardClassifier` implements pLogger's wildcard truth table.
"""

from __future__ import annotations

import enum
import re
from collections.abc import Iterable

from fleetlog.errors import FormatError

__all__ = [
    "ALWAYS_LOGGED",
    "ALWAYS_OMITTED",
    "EMPTY_NAME_CHUNK",
    "NAMES_CACHED",
    "MoosGlob",
    "Verdict",
    "WildcardClassifier",
    "chunk_includes",
    "chunk_to_name",
    "glob_match",
    "glob_to_chunk",
    "globs_to_key_suffixes",
    "name_to_chunk",
    "reduce_chunks",
]

#: How many names (variables, keys, key and source pairs) each of a recorder's per-name
#: caches holds before it starts again. A vehicle posts hundreds to a few thousand variables;
#: a peer that sprays new names makes each cache start again every few thousand names
#: instead of pinning tens of MB (each entry is rebuilt on its next use).
NAMES_CACHED = 8192

#: The chunk that stands for the empty name.
EMPTY_NAME_CHUNK = "%00"
#: Variables pLogger always subscribes to and logs, whatever the patterns say (§2.2, §6.4).
ALWAYS_LOGGED = frozenset({"MOOS_DEBUG", "MOOS_SYSTEM"})
#: Names pLogger always adds to the omit patterns (EM:402).
ALWAYS_OMITTED = ("MISSION_FILE",)

_ESCAPES = {"%": "%25", "/": "%2F", "*": "%2A", "$": "%24", "?": "%3F", "#": "%23"}
_ESCAPE_TABLE: dict[int, str] = {ord(c): e for c, e in _ESCAPES.items()}
_ESCAPE_TABLE.update({0xDC00 + b: f"%{b:02X}" for b in range(0x80, 0x100)})
_UNESCAPES: dict[str, str] = {e[1:]: c for c, e in _ESCAPES.items()}
_UNESCAPES.update({f"{b:02X}": chr(0xDC00 + b) for b in range(0x80, 0x100)})
_SURROGATE = re.compile("[\ud800-\udfff]")
# What a canonical chunk never holds raw: the escaped characters and any surrogate.
_RAW_FORBIDDEN = re.compile("[/*$?#\ud800-\udfff]")
_ESCAPE_SEQ = re.compile("%(.{0,2})", re.DOTALL)

_WILD = "$*"


# --------------------------------------------------------------------------------------------
# Names <-> chunks


def name_to_chunk(name: str) -> str:
    """Return the Zenoh key chunk for a MOOS name (the rule is in the module docstring).

    Args:
        name: a MOOS variable or community name, any string.

    Returns:
        A non-empty string that is a valid, wildcard-free Zenoh key chunk.

    Raises:
        FormatError: if the name holds a surrogate that stands for no byte (only possible for
            a string that was not decoded from text or bytes).
    """
    if not name:
        return EMPTY_NAME_CHUNK
    chunk = name.translate(_ESCAPE_TABLE)
    if _SURROGATE.search(chunk) is not None:
        msg = f"name {name!r} holds a surrogate that stands for no byte"
        raise FormatError(msg)
    if chunk[0] == "@":
        chunk = "%40" + chunk[1:]
    return chunk


def chunk_to_name(chunk: str) -> str:
    """Return the MOOS name a key chunk stands for; the inverse of :func:`name_to_chunk`.

    Args:
        chunk: one key chunk, as :func:`name_to_chunk` produced it.

    Returns:
        The name.

    Raises:
        FormatError: if the chunk is not exactly what :func:`name_to_chunk` produces for some
            name (an unknown or lower-case escape, ``%40`` after position 0, a raw ``/``,
            ``*``, ``$``, ``?``, ``#`` or leading ``@``, or an empty chunk).
    """
    if chunk == EMPTY_NAME_CHUNK:
        return ""
    if not chunk:
        msg = "empty key chunk (the empty name is written %00)"
        raise FormatError(msg)
    if chunk[0] == "@":
        msg = f"key chunk {chunk!r} starts with a raw '@' (written %40)"
        raise FormatError(msg)
    bad = _RAW_FORBIDDEN.search(chunk)
    if bad is not None:
        msg = f"key chunk {chunk!r} holds a raw {bad.group()!r} at {bad.start()}"
        raise FormatError(msg)
    if "%" not in chunk:
        return chunk

    def unescape(m: re.Match[str]) -> str:
        code = m.group(1)
        char = _UNESCAPES.get(code)
        if char is None and code == "40" and m.start() == 0:
            char = "@"
        if char is None:
            msg = f"key chunk {chunk!r} holds a malformed escape {m.group()!r} at {m.start()}"
            raise FormatError(msg)
        return char

    return _ESCAPE_SEQ.sub(unescape, chunk)


# --------------------------------------------------------------------------------------------
# Globs


class _Segment:
    """A run of a glob between stars: literal pieces at fixed offsets, ``?`` between them.

    ``at`` checks one position; ``find`` returns the leftmost position at or after ``start``
    where the segment fits before ``end``. When a piece does not fit, ``find`` jumps to that
    piece's next occurrence (``str.find``), so the candidate position only moves forward:
    O(len(text) * pieces) at worst, no backtracking, whatever the text.
    """

    __slots__ = ("_pieces", "length")

    def __init__(self, segment: str) -> None:
        self.length = len(segment)
        pieces: list[tuple[int, str]] = []
        offset = 0
        for literal in segment.split("?"):
            if literal:
                pieces.append((offset, literal))
            offset += len(literal) + 1
        # The longest piece first: it is the likeliest to rule a position out.
        pieces.sort(key=lambda piece: -len(piece[1]))
        self._pieces = tuple(pieces)

    def at(self, text: str, pos: int) -> bool:
        if pos < 0 or pos + self.length > len(text):
            return False
        return all(text.startswith(literal, pos + offset) for offset, literal in self._pieces)

    def find(self, text: str, start: int, end: int) -> int:
        last = end - self.length  # the last position where the segment still fits
        pos = start
        while pos <= last:
            for offset, literal in self._pieces:
                if not text.startswith(literal, pos + offset):
                    hit = text.find(literal, pos + offset + 1, last + offset + len(literal))
                    if hit < 0:
                        return -1
                    pos = hit - offset
                    break
            else:
                return pos
        return -1


class MoosGlob:
    """A MOOS wildcard pattern, matched exactly as ``MOOSWildCmp`` does, in linear time.

    Case-sensitive; ``*`` matches any run of characters (also none), ``?`` exactly one
    character, every other character itself. There are no escapes and no character classes.

    The matcher never backtracks (and uses no regular expression): the pattern is cut at its
    stars into segments; the first must match at the start, the last at the end, and each one
    between is placed at its leftmost fit after the previous one, which is always right
    because a later placement can only leave less room for the segments that follow. A check
    costs O(len(name) * len(pattern)) at worst, whatever the name holds (the remote grep's
    ``*a*a*a*a*a*a*a*b`` over long values included), and runs mostly inside ``str.find`` and
    ``str.startswith``. It holds no lock and calls no C code that runs for long, so a thread
    matching a huge name still lets the others run.

    Args:
        pattern: the pattern, e.g. ``*_STATUS`` or ``NAV_?``.
    """

    __slots__ = ("_head", "_middle", "_min_length", "_starred", "_tail", "pattern")

    def __init__(self, pattern: str) -> None:
        self.pattern = pattern
        segments = pattern.split("*")
        self._starred = len(segments) > 1
        self._head = _Segment(segments[0])
        self._tail = _Segment(segments[-1]) if self._starred else self._head
        self._middle = tuple(_Segment(s) for s in segments[1:-1] if s)
        lengths = [self._head.length, *(s.length for s in self._middle)]
        self._min_length = sum(lengths) + (self._tail.length if self._starred else 0)

    def matches(self, name: str) -> bool:
        """Return True if the name matches the pattern."""
        size = len(name)
        if not self._starred:
            return size == self._min_length and self._head.at(name, 0)
        if size < self._min_length:
            return False
        if not self._head.at(name, 0):
            return False
        end = size - self._tail.length
        if not self._tail.at(name, end):
            return False
        pos = self._head.length
        for segment in self._middle:
            found = segment.find(name, pos, end)
            if found < 0:
                return False
            pos = found + segment.length
        return True

    @property
    def has_wildcards(self) -> bool:
        """True if the pattern holds ``*`` or ``?``; otherwise it matches only itself."""
        return "*" in self.pattern or "?" in self.pattern

    @property
    def chunk(self) -> str:
        """The key chunk expression for this pattern (see :func:`glob_to_chunk`)."""
        return glob_to_chunk(self.pattern)

    def __repr__(self) -> str:
        return f"MoosGlob({self.pattern!r})"

    def __eq__(self, other: object) -> bool:
        return isinstance(other, MoosGlob) and other.pattern == self.pattern

    def __hash__(self) -> int:
        return hash(self.pattern)


def glob_match(pattern: str, name: str) -> bool:
    """Return True if ``name`` matches the MOOS glob ``pattern`` (see :class:`MoosGlob`).

    Compile the pattern once with :class:`MoosGlob` when it is checked against many names.
    """
    return MoosGlob(pattern).matches(name)


def _escape_char(char: str) -> str:
    """Escape one character away from position 0 (so ``@`` stays ``@``)."""
    escaped = char.translate(_ESCAPE_TABLE)
    if _SURROGATE.match(escaped) is not None:
        msg = f"pattern character {char!r} is a surrogate that stands for no byte"
        raise FormatError(msg)
    return escaped


def glob_to_chunk(pattern: str) -> str:
    """Return the narrowest key chunk expression that admits every name the glob matches.

    The expression is a superset: every escaped name the glob matches is included by it, and
    some names it does not match may be too (subscribers filter with :class:`MoosGlob`).

    * a pattern without wildcards → :func:`name_to_chunk` of it (exact);
    * a pattern made only of ``*`` and ``?`` → ``*`` (any one chunk);
    * otherwise each run of ``*``/``?`` becomes ``$*`` and every literal is escaped as in a
      name. An ``@`` that can land at position 0 of a matching name (it follows nothing but
      ``*``) also becomes ``$*``, since that name's chunk starts ``%40``; an ``@`` first in
      the pattern is ``%40``. Adjacent ``$*`` are merged.

    Args:
        pattern: a MOOS wildcard pattern.

    Returns:
        A valid Zenoh chunk expression (never containing ``/``).

    Raises:
        FormatError: if a literal cannot be escaped (see :func:`name_to_chunk`).
    """
    if "*" not in pattern and "?" not in pattern:
        return name_to_chunk(pattern)
    if not pattern.strip("*?"):
        return "*"
    out: list[str] = []
    only_stars_before = True
    for index, char in enumerate(pattern):
        if char in "*?" or (char == "@" and index > 0 and only_stars_before):
            if not out or out[-1] != _WILD:
                out.append(_WILD)
        elif char == "@" and index == 0:
            out.append("%40")
        else:
            out.append(_escape_char(char))
        if char != "*":
            only_stars_before = False
    chunk = "".join(out)
    return "*" if chunk == _WILD else chunk


def _tokens(chunk: str) -> list[str]:
    return re.findall(r"\$\*|.", chunk, re.DOTALL)


def chunk_includes(outer: str, inner: str) -> bool:
    """Return True if the chunk expression ``outer`` admits every chunk ``inner`` admits.

    Pure string logic over the expressions this module produces (``*``, literals and
    ``$*``). It is sound: True is only returned when the inclusion really holds.

    Args:
        outer: a chunk expression.
        inner: a chunk expression.
    """
    if outer == "*" or outer == inner:
        return True
    if inner == "*":
        return False
    pat = _tokens(outer)
    txt = _tokens(inner)
    # reach[j]: pattern prefix matches the first j inner tokens, where an outer "$*" may absorb
    # any run of inner tokens (inner "$*" included) and a literal matches only itself.
    reach = [True] + [False] * len(txt)
    for tok in pat:
        if tok == _WILD:
            for j in range(1, len(reach)):
                reach[j] = reach[j] or reach[j - 1]
        else:
            for j in range(len(reach) - 1, 0, -1):
                reach[j] = reach[j - 1] and txt[j - 1] == tok
            reach[0] = False
    return reach[-1]


def reduce_chunks(chunks: Iterable[str]) -> list[str]:
    """Drop chunk expressions another one already includes; keep the first of equal ones.

    Args:
        chunks: chunk expressions, e.g. from :func:`glob_to_chunk` and :func:`name_to_chunk`.

    Returns:
        The remaining expressions in their first-seen order (``["*"]`` if any is ``*``).
    """
    unique = list(dict.fromkeys(chunks))
    if "*" in unique:
        return ["*"]
    kept: list[str] = []
    for i, chunk in enumerate(unique):
        covered = False
        for j, other in enumerate(unique):
            if j != i and chunk_includes(other, chunk):
                # A strictly wider expression, or an equal one seen earlier, covers it.
                covered = j < i or not chunk_includes(chunk, other)
                if covered:
                    break
        if not covered:
            kept.append(chunk)
    return kept


def globs_to_key_suffixes(patterns: Iterable[str]) -> list[str]:
    """Return the key chunks to subscribe to for a list of MOOS patterns, without redundancy.

    An empty list gives an empty result: whether "no patterns" means "everything" is the
    caller's rule (pLogger's is, for ``WildcardPattern``).

    Args:
        patterns: MOOS wildcard patterns.

    Returns:
        Chunk expressions (see :func:`glob_to_chunk`); none is included by another.

    Raises:
        FormatError: if a literal cannot be escaped (see :func:`name_to_chunk`).
    """
    return reduce_chunks(glob_to_chunk(p) for p in patterns)


# --------------------------------------------------------------------------------------------
# pLogger's wildcard truth table


class Verdict(enum.Enum):
    """Where a variable's samples go."""

    #: the asynchronous log
    ALOG = "alog"
    #: the exclusion log (``WildcardExclusionLog = true``)
    XLOG = "xlog"
    #: not logged
    IGNORE = "ignore"


class WildcardClassifier:
    """Decides, once per name, whether a variable goes to the alog, the xlog or nowhere (§6.4).

    * Explicit ``Log =`` variables, ``MOOS_DEBUG``, ``MOOS_SYSTEM`` and variables added by
      LOG_REQUEST (:meth:`add_log_var`) → ALOG, whatever the omit patterns say.
    * With wildcard logging off, everything else → IGNORE.
    * Otherwise ``accept`` = no patterns, or any pattern matches; ``reject`` = any omit
      pattern matches (``MISSION_FILE`` is always omitted). accept and not reject → ALOG;
      anything else → XLOG with the exclusion log, IGNORE without it.

    Verdicts are cached per name; the cache is bounded (the oldest entry is evicted first).

    Args:
        log_vars: the explicit ``Log =`` variable names.
        patterns: ``WildcardPattern`` values.
        omit_patterns: ``WildcardOmitPattern`` values.
        exclusion_log: ``WildcardExclusionLog``.
        wildcard_enabled: ``WildcardLogging`` (pLogger also turns it on for a mission with
            no pLogger block).
        cache_size: the most verdicts kept.
    """

    def __init__(
        self,
        log_vars: Iterable[str] = (),
        patterns: Iterable[str] = (),
        omit_patterns: Iterable[str] = (),
        exclusion_log: bool = False,
        *,
        wildcard_enabled: bool = True,
        cache_size: int = NAMES_CACHED,
    ) -> None:
        self._log_vars: dict[str, None] = dict.fromkeys(log_vars)
        self._patterns = tuple(MoosGlob(p) for p in dict.fromkeys(patterns))
        omits = dict.fromkeys([*omit_patterns, *ALWAYS_OMITTED])
        self._omits = tuple(MoosGlob(p) for p in omits)
        self.exclusion_log = exclusion_log
        self.wildcard_enabled = wildcard_enabled
        self._cache_size = max(1, cache_size)
        self._cache: dict[str, Verdict] = {}

    @property
    def log_vars(self) -> tuple[str, ...]:
        """The explicit variables (``Log =`` and LOG_REQUEST), in the order they were added."""
        return tuple(self._log_vars)

    @property
    def patterns(self) -> tuple[str, ...]:
        """The accept patterns."""
        return tuple(g.pattern for g in self._patterns)

    @property
    def omit_patterns(self) -> tuple[str, ...]:
        """The omit patterns, ``MISSION_FILE`` included."""
        return tuple(g.pattern for g in self._omits)

    def is_explicit(self, name: str) -> bool:
        """Return True for an explicit variable, ``MOOS_DEBUG`` or ``MOOS_SYSTEM``."""
        return name in self._log_vars or name in ALWAYS_LOGGED

    def add_log_var(self, name: str) -> bool:
        """Log a variable explicitly from now on (a LOG_REQUEST).

        Returns:
            False if it was already explicit (pLogger then posts its "failed to process
            dynamic log request" MOOS_DEBUG), True otherwise.
        """
        if self.is_explicit(name):
            return False
        self._log_vars[name] = None
        self._cache.pop(name, None)
        return True

    def classify(self, name: str) -> Verdict:
        """Return where the variable's samples go (cached per name)."""
        verdict = self._cache.get(name)
        if verdict is None:
            verdict = self._decide(name)
            if len(self._cache) >= self._cache_size:
                del self._cache[next(iter(self._cache))]
            self._cache[name] = verdict
        return verdict

    def _decide(self, name: str) -> Verdict:
        if self.is_explicit(name):
            return Verdict.ALOG
        if not self.wildcard_enabled:
            return Verdict.IGNORE
        accept = not self._patterns or any(g.matches(name) for g in self._patterns)
        reject = any(g.matches(name) for g in self._omits)
        if accept and not reject:
            return Verdict.ALOG
        return Verdict.XLOG if self.exclusion_log else Verdict.IGNORE

    def key_suffixes(self) -> list[str]:
        """Return the variable key chunks a subscriber needs to see every non-IGNORE name.

        With the exclusion log every name is logged somewhere, so ``["*"]``; otherwise the
        accept patterns (``*`` when there are none) plus the explicit variables. Omit patterns
        cannot narrow a key expression; :meth:`classify` applies them on arrival.

        Raises:
            FormatError: if a name or pattern cannot be escaped (see :func:`name_to_chunk`).
        """
        explicit = [name_to_chunk(n) for n in (*sorted(ALWAYS_LOGGED), *self._log_vars)]
        if not self.wildcard_enabled:
            return reduce_chunks(explicit)
        if self.exclusion_log or not self._patterns:
            return ["*"]
        return reduce_chunks([*(glob_to_chunk(g.pattern) for g in self._patterns), *explicit])
