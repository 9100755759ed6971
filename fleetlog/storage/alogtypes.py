"""Entries' fields become typed columns: double, string or binary, by MOOS's rules.

Under ``%% DATATYPE MARKING ON`` the ``D:``/``S:`` marker says the type; without it, a value
that is exactly a double as pLogger pads it is a double; a ``<MOOS_BINARY>...</MOOS_BINARY>``
tag without terminator space is binary. :func:`typed` computes only the columns asked for.
"""

from __future__ import annotations

from types import ModuleType
from typing import TYPE_CHECKING, Any

from fleetlog.moos.alog import split_source
from fleetlog.storage.columns import ALWAYS, TYPES

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
) -> pl.DataFrame:
    """Turn entry heads (fields of the first line, continuation text) into typed columns.

    ``mark`` is a bool when the whole block has one DATATYPE MARKING state (nearly always:
    the expressions are then simpler), else an expression; ``continued`` says whether any
    entry has continuation lines.
    """
    col = pl.col
    text0 = col("text0")
    value = (
        pl.when(col("c").is_not_null()).then(col("v") + "\n" + col("c")).otherwise(col("v"))
        if continued
        else col("v")
    )
    frame = heads.lazy().with_columns(value=value)
    frame = frame.with_columns(
        term=col("value").str.ends_with(" "), text0=col("value").str.strip_suffix(" ")
    )
    if mark is False:
        frame = frame.with_columns(
            binary=~col("term") & text0.str.contains(_BINARY),
            dmark=pl.lit(False),
            smark=pl.lit(False),
            body=text0.str.strip_chars_end(" "),
        ).with_columns(
            double=~col("binary")
            & col("body").str.contains(_DOUBLE)
            & (
                text0.str.len_bytes()
                == pl.max_horizontal(pl.lit(12, pl.UInt32), col("body").str.len_bytes())
            )
        )
    else:
        frame = frame.with_columns(
            mk=pl.lit(True) if mark is True else mark,
        ).with_columns(
            binary=~col("term") & text0.str.contains(_BINARY),
            dmark=col("mk") & text0.str.starts_with("D:"),
            smark=col("mk") & text0.str.starts_with("S:"),
            body=text0.str.strip_chars_end(" "),
        )
        body = (
            pl.when(col("dmark"))
            .then(text0.str.slice(2).str.strip_chars_end(" "))
            .otherwise("body")
        )
        frame = frame.with_columns(body=body).with_columns(
            double=~col("binary")
            & col("body").str.contains(_DOUBLE)
            & pl.when(col("mk"))
            .then(col("dmark"))
            .otherwise(
                text0.str.len_bytes()
                == pl.max_horizontal(pl.lit(12, pl.UInt32), col("body").str.len_bytes())
            )
        )
    exprs: dict[str, Any] = {
        "line": (col("idx") + first_line).cast(pl.Int64),
        "offset": col("offset"),
        "time": col("offset") + logstart if logstart is not None else pl.lit(None, pl.Float64),
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
    names = [name for name in exprs if name in want or name in ALWAYS]
    extra = [name for name in ("kpos", "spos", "vpos") if name in heads.columns]
    result = frame.select(*(exprs[name].alias(name) for name in names), *extra).collect()
    if "src" in want or "aux" in want:
        result = _with_source_parts(pl, result)
    return result


def _with_source_parts(pl: ModuleType, frame: pl.DataFrame) -> pl.DataFrame:
    """Add ``src`` and ``aux``, computed once per distinct source."""
    if not frame.height:
        return frame.with_columns(src=pl.col("source"), aux=pl.col("source"))
    sources = frame["source"].unique().to_list()
    parts = [split_source(s) for s in sources]
    src = pl.Series([p[0] for p in parts], dtype=pl.String)
    aux = pl.Series([p[1] for p in parts], dtype=pl.String)
    old = pl.Series(sources, dtype=pl.String)
    return frame.with_columns(
        src=pl.col("source").replace_strict(old, src, return_dtype=pl.String),
        aux=pl.col("source").replace_strict(old, aux, return_dtype=pl.String),
    )


def exact_raw(pl: ModuleType, frame: pl.DataFrame, block: bytes, first_line: int) -> pl.DataFrame:
    """Fill ``raw`` with the exact bytes of each entry (a block that is not all UTF-8)."""
    lines = block.split(b"\n")
    raw = []
    for line, count in zip(frame["line"].to_list(), frame["nlines"].to_list(), strict=True):
        start = line - first_line
        raw.append(b"\n".join(lines[start : start + count]))
    return frame.with_columns(raw=pl.Series(raw, dtype=pl.Binary))
