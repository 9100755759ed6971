"""Entries' fields become typed columns: double, string or binary, by MOOS's rules.

Under ``%% DATATYPE MARKING ON`` the ``D:``/``S:`` marker says the type; without it, a value
that is exactly a double as pLogger pads it is a double; a ``<MOOS_BINARY>...</MOOS_BINARY>``
tag without terminator space is binary. :func:`typed` computes only the columns asked for.
"""

from __future__ import annotations

import functools
from types import ModuleType
from typing import TYPE_CHECKING, Any

from fleetlog.moos.alog import split_source
from fleetlog.storage.columns import TYPES, in_memory

if TYPE_CHECKING:
    import polars as pl

__all__ = ["exact_raw", "typed"]

_DOUBLE = r"^(?:-?[0-9]+(?:\.[0-9]+)?|-?nan|-?inf)$"
_BINARY = r"^<MOOS_BINARY>File=.*,Offset=-?[0-9]+,Bytes=[0-9]+</MOOS_BINARY>$"


def typed(
    pl: ModuleType,
    heads: pl.DataFrame,
    mark: Any,
    first_line: int,
    logstart: float | None,
    want: frozenset[str],
    continued: bool = True,
    binary: bool = True,
) -> pl.DataFrame:
    """Turn entry heads (fields of the first line, continuation text) into typed columns.

    ``mark`` is a bool when the whole block has one DATATYPE MARKING state (nearly always:
    the expressions are then simpler), else an expression; ``continued`` says whether any
    entry has continuation lines; ``binary`` whether any value may be a binary reference
    (a value starts with ``<MOOS_BINARY>``: without one, the tag's regex is not run at all).
    """
    names = [name for name in _OUTPUTS if name in want]
    extra = [name for name in ("kpos", "spos", "vpos") if name in heads.columns]
    frame = heads.lazy()
    if isinstance(mark, bool):
        steps = _steps(pl, mark, continued, binary)
    else:  # the marking starts inside this block (once a file): not worth a cache entry
        steps = _build_steps(pl, mark, continued, binary)
    for step in steps:
        frame = frame.with_columns(**step)
    outputs = _outputs(pl)
    first = pl.lit(first_line, pl.Int64)
    per_block = {
        "line": (pl.col("idx").cast(pl.Int64) + first).alias("line"),
        "time": (
            (pl.col("offset") + logstart) if logstart is not None else pl.lit(None, pl.Float64)
        ).alias("time"),
    }
    exprs = [per_block[name] if name in per_block else outputs[name] for name in names]
    result = frame.select(*exprs, *extra).collect(engine=in_memory(pl))
    if "src" in want or "aux" in want:
        result = _with_source_parts(pl, result)
    return result


#: The columns typed() can compute, in this order.
_OUTPUTS = ("line", "offset", "time", "var", "source", "type", "double", "text", "raw", "nlines")


@functools.cache
def _steps(pl: ModuleType, mark: bool, continued: bool, binary: bool) -> tuple[dict[str, Any], ...]:
    """Return the intermediate columns of :func:`typed`, built once per case.

    Expressions are immutable, and building them costs more Python than applying them.
    """
    return _build_steps(pl, mark, continued, binary)


def _build_steps(
    pl: ModuleType, mark: Any, continued: bool, binary: bool
) -> tuple[dict[str, Any], ...]:
    col = pl.col
    text0 = col("text0")
    value = (
        pl.when(col("c").is_not_null()).then(col("v") + "\n" + col("c")).otherwise(col("v"))
        if continued
        else col("v")
    )
    steps: list[dict[str, Any]] = [
        {"value": value},
        {"term": col("value").str.ends_with(" "), "text0": col("value").str.strip_suffix(" ")},
    ]
    is_binary = ~col("term") & text0.str.contains(_BINARY) if binary else pl.lit(False)
    padded = text0.str.len_bytes() == pl.max_horizontal(
        pl.lit(12, pl.UInt32), col("body").str.len_bytes()
    )
    if mark is False:
        steps += [
            {
                "binary": is_binary,
                "dmark": pl.lit(False),
                "smark": pl.lit(False),
                "body": text0.str.strip_chars_end(" "),
            },
            {"double": ~col("binary") & col("body").str.contains(_DOUBLE) & padded},
        ]
    else:
        steps += [
            {"mk": pl.lit(True) if mark is True else mark},
            {
                "binary": is_binary,
                "dmark": col("mk") & text0.str.starts_with("D:"),
                "smark": col("mk") & text0.str.starts_with("S:"),
                "body": text0.str.strip_chars_end(" "),
            },
            {
                "body": pl.when(col("dmark"))
                .then(text0.str.slice(2).str.strip_chars_end(" "))
                .otherwise("body")
            },
            {
                "double": ~col("binary")
                & col("body").str.contains(_DOUBLE)
                & pl.when(col("mk")).then(col("dmark")).otherwise(padded)
            },
        ]
    return tuple(steps)


@functools.cache
def _outputs(pl: ModuleType) -> dict[str, Any]:
    """The output columns of :func:`typed` but ``line`` and ``time`` (per block)."""
    col = pl.col
    text0 = col("text0")
    exprs: dict[str, Any] = {
        "offset": col("offset"),
        "var": col("var"),
        "source": col("source"),
        "type": pl.when(col("binary"))
        .then(pl.lit("binary"))
        .when(col("double"))
        .then(pl.lit("double"))
        .otherwise(pl.lit("string"))
        .cast(pl.Enum(TYPES)),
        "double": pl.when(col("double")).then(col("body").cast(pl.Float64, strict=False)),
        "text": pl.when(col("double"))
        .then(col("body"))
        .when(col("smark") & ~col("binary"))
        .then(text0.str.slice(2))
        .otherwise(text0),
        "raw": pl.when(col("c").is_not_null())
        .then(col("l") + "\n" + col("c"))
        .otherwise(col("l"))
        .cast(pl.Binary),
        "nlines": pl.when(col("c").is_not_null())
        .then(col("c").str.count_matches("\n") + 2)
        .otherwise(1),
    }
    return {name: expr.alias(name) for name, expr in exprs.items()}


def _with_source_parts(pl: ModuleType, frame: pl.DataFrame) -> pl.DataFrame:
    """Add ``src`` and ``aux``, computed once per distinct source (joined back on it)."""
    if not frame.height:
        return frame.with_columns(src=pl.col("source"), aux=pl.col("source"))
    sources = frame["source"].unique().to_list()
    parts = [split_source(s) for s in sources]
    table = pl.DataFrame(
        {"source": sources, "src": [p[0] for p in parts], "aux": [p[1] for p in parts]},
        schema={"source": pl.String, "src": pl.String, "aux": pl.String},
    )
    return frame.join(table, on="source", how="left", maintain_order="left")


def exact_raw(pl: ModuleType, frame: pl.DataFrame, block: bytes, first_line: int) -> pl.DataFrame:
    """Fill ``raw`` with the exact bytes of each entry (a block that is not all UTF-8)."""
    lines = block.split(b"\n")
    raw = []
    for line, count in zip(frame["line"].to_list(), frame["nlines"].to_list(), strict=True):
        start = line - first_line
        raw.append(b"\n".join(lines[start : start + count]))
    return frame.with_columns(raw=pl.Series(raw, dtype=pl.Binary))
