"""Where an alog line's columns are: the writer's column rule, vectorised over lines.

pLogger left-justifies the time, the variable and the source to 15, 20 and 15 characters
(or wider), each followed by one space; the value is the rest. :func:`standard_layout`
recognises the lines whose fields all fit their columns (nearly all), so their fields are
cut at fixed places; :func:`overflow_fields` splits the others by the rule itself.
:func:`entry_start` and :func:`line_start` find where to cut a block of bytes so that it
ends with whole entries.
"""

from __future__ import annotations

import functools
from types import ModuleType
from typing import TYPE_CHECKING, Any

from fleetlog.storage.columns import in_memory

if TYPE_CHECKING:
    import polars as pl

__all__ = [
    "entry_line",
    "entry_start",
    "line_start",
    "overflow_fields",
    "standard_layout",
    "starts_entry",
]

#: Lines looked at, from the end of a block, for an entry to cut the block before.
_CUT_LOOKBACK = 64

#: The line's first field (up to its first space) is a time.
_TIME_FIELD = r"^-?[0-9]+(?:\.[0-9]*)?(?:[eE][-+]?[0-9]+)? "
_TIME = r"^-?[0-9]+(?:\.[0-9]*)?(?:[eE][-+]?[0-9]+)?$"


def starts_entry(line: bytes) -> bool:
    """Whether a line starts like an entry: a digit, or ``-`` and a digit."""
    # ASCII digits only: a time column never starts otherwise.
    if not line:
        return False
    c = line[0]
    if 0x30 <= c <= 0x39:
        return True
    return c == 0x2D and len(line) > 1 and 0x30 <= line[1] <= 0x39


def entry_start(pl: ModuleType, buf: bytes, end: int) -> int | None:
    """Return where the last entry line of ``buf[:end]`` starts (not at 0), or None.

    Looks at the last :data:`_CUT_LOOKBACK` whole lines only, with the reader's own rule
    for an entry line (so a block cut there ends with whole entries).
    """
    starts: list[int] = []
    pos = end
    while len(starts) < _CUT_LOOKBACK and pos > 0:
        start = buf.rfind(b"\n", 0, pos) + 1
        if start == 0:
            break
        starts.append(start)
        pos = start - 1
    if not starts:
        return None
    ends = [end, *(start - 1 for start in starts[:-1])]
    texts = [
        buf[a:b].decode("utf-8", "fleetlog.byte-per-char")
        for a, b in zip(starts, ends, strict=True)
    ]
    lines = pl.DataFrame({"l": texts}).with_row_index("idx")
    entries = lines.filter(standard_layout(pl))["idx"].to_list()
    others = lines.filter(~standard_layout(pl) & pl.col("l").str.contains(r"^-?[0-9]"))
    if others.height:
        entries += overflow_fields(pl, others)["idx"].to_list()
    return starts[min(entries)] if entries else None


def line_start(buf: bytes, end: int, lines: int) -> int:
    """Return where the last ``lines`` lines of ``buf[:end]`` start (``end`` if none)."""
    if lines <= 0:
        return end + 1
    pos = end
    for _ in range(lines):
        pos = buf.rfind(b"\n", 0, pos)
        if pos < 0:
            return 0
    return pos + 1


def _all_spaces(pl: ModuleType, expr: Any, width: Any) -> Any:
    """An expression: ``expr`` holds at least ``width`` characters, the first ``width`` spaces."""
    return (expr.str.len_chars() >= width) & (
        expr.str.slice(0, width).str.strip_chars_start(" ").str.len_bytes() == 0
    )


def _field_rule(chars: str, width: int, shortest: int, wider: bool = True) -> str:
    """A regex: a field of ``chars`` left-justified to ``width`` (or wider), one space after."""
    longest = width if wider else width + 1
    padded = "|".join(f"{chars}{{{n}}} {{{width + 1 - n}}}" for n in range(shortest, longest))
    return f"(?:{padded}|{chars}{{{width},}} )" if wider else f"(?:{padded})"


#: The standard layout as one regex on a whole line: a time left-justified to 15, a variable
#: (at least one character) to 20, a source (maybe none) to 15, each followed by one space,
#: so the value starts at character 53. With _TIME_FIELD (the time is a time), without
#: cutting the line: its first 16 characters are a time and spaces, the next 21 a variable
#: and spaces, the next 16 a source (maybe none) and spaces.
_STD_LINE = (
    "^"
    + _field_rule("[-+.0-9eE]", 15, 1, wider=False)
    + _field_rule("[^ ]", 20, 1, wider=False)
    + _field_rule("[^ ]", 15, 0, wider=False)
)


@functools.cache
def standard_layout(pl: ModuleType) -> Any:
    """An expression: the line ``l`` is an entry with no field wider than its column."""
    line = pl.col("l")
    return line.str.contains(_TIME_FIELD) & line.str.contains(_STD_LINE)


#: The writer's column rule as one regex on a whole line, for lines whose fields may be
#: wider than their columns: a time left-justified to 15 or wider, a variable (at least
#: one character) to 20, a source (maybe none) to 15, each followed by one space. Each
#: field is cut at its first space (no field holds one), so a line matches exactly when
#: :func:`overflow_fields` finds its fields, given that its time is a time (_TIME_FIELD).
_ENTRY_LINE = (
    "^" + _field_rule("[-+.0-9eE]", 15, 1) + _field_rule("[^ ]", 20, 1) + _field_rule("[^ ]", 15, 0)
)


@functools.cache
def entry_line(pl: ModuleType) -> Any:
    """An expression: the line ``l`` is an entry, whatever its fields' widths.

    True exactly where :func:`standard_layout` is or :func:`overflow_fields` finds fields,
    in two regex tests of the whole line (no field cut out): for reads that need to know
    which lines are entries but not the fields of most of them.
    """
    line = pl.col("l")
    return line.str.contains(_TIME_FIELD) & line.str.contains(_ENTRY_LINE)


def overflow_fields(pl: ModuleType, lines: pl.DataFrame) -> pl.DataFrame:
    """Split lines whose columns overflow (or are not entries) by the writer's column rule.

    Follows the columns: each field is left-justified to its width (15, 20, 15) or wider,
    then one separator space. Returns the lines that are entries, with their fields and
    the character positions of the key, source and value.
    """
    frame = lines.lazy()
    for method, args, kwargs in _overflow_plan(pl):
        frame = getattr(frame, method)(*args, **kwargs)
    return frame.collect(engine=in_memory(pl))


@functools.cache
def _overflow_plan(pl: ModuleType) -> tuple[tuple[str, tuple[Any, ...], dict[str, Any]], ...]:
    """The steps of :func:`overflow_fields`, as (LazyFrame method, args, kwargs), built once."""
    col = pl.col
    zero = pl.lit(0)
    plan: list[tuple[str, tuple[Any, ...], dict[str, Any]]] = []

    def step(method: str, *args: Any, **kwargs: Any) -> None:
        plan.append((method, args, kwargs))

    step("with_columns", col("l").str.splitn(" ", 2).struct.rename_fields(["t", "r1"]).alias("p"))
    step("unnest", "p")
    step("with_columns", lt=col("t").str.len_chars().cast(pl.Int64))
    step("with_columns", pad1=pl.max_horizontal(15 - col("lt"), zero))
    step(
        "filter",
        col("r1").is_not_null()
        & col("t").str.contains(_TIME)
        & _all_spaces(pl, col("r1"), col("pad1")),
    )
    step("with_columns", r1k=col("r1").str.slice(col("pad1")))
    step("filter", (col("r1k").str.len_bytes() > 0) & ~col("r1k").str.starts_with(" "))
    step("with_columns", col("r1k").str.splitn(" ", 2).struct.rename_fields(["k", "r2"]).alias("p"))
    step("unnest", "p")
    step("with_columns", lk=col("k").str.len_chars().cast(pl.Int64))
    step("with_columns", pad2=pl.max_horizontal(20 - col("lk"), zero))
    step("filter", col("r2").is_not_null() & _all_spaces(pl, col("r2"), col("pad2")))
    step("with_columns", r3=col("r2").str.slice(col("pad2")))
    step("with_columns", col("r3").str.splitn(" ", 2).struct.rename_fields(["s", "r4"]).alias("p"))
    step("unnest", "p")
    step("with_columns", ls=col("s").str.len_chars().cast(pl.Int64))
    step("with_columns", pad3=pl.max_horizontal(15 - col("ls"), zero))
    step("filter", col("r4").is_not_null() & _all_spaces(pl, col("r4"), col("pad3")))
    step(
        "with_columns",
        kpos=pl.max_horizontal(col("lt"), pl.lit(15)) + 1,
    )
    step("with_columns", spos=col("kpos") + pl.max_horizontal(col("lk"), pl.lit(20)) + 1)
    step("with_columns", vpos=col("spos") + pl.max_horizontal(col("ls"), pl.lit(15)) + 1)
    step(
        "select",
        "idx",
        "l",
        offset=col("t").cast(pl.Float64, strict=False),
        var="k",
        source="s",
        v=col("r4").str.slice(col("pad3")),
        kpos=col("kpos").cast(pl.Int32),
        spos=col("spos").cast(pl.Int32),
        vpos=col("vpos").cast(pl.Int32),
    )
    return tuple(plan)
