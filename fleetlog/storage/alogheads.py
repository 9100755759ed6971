"""Which lines of a block start entries, and their fields; for a selective read, only some.

:func:`find_heads` splits a block's text into lines and sorts them into entry lines (the
standard layout, or fields wider than their columns: :mod:`fleetlog.storage.alogfields`),
comments and the rest (continuation or stray lines, which :mod:`fleetlog.storage.alogblocks`
attaches). Every entry line's fields are cut, unless the caller names texts every line it
keeps must hold (a grep's literals: :attr:`fleetlog.storage.select.Selection.literals`) and
the block proves it has no continuation lines: every line is then an entry or a comment, so
which lines are entries, how many and where is known without their fields, and only the
lines holding one of the texts (and the block's last line, whose value decides a cut tail)
are cut into fields. A block with any other line is read whole, as without the texts.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from types import ModuleType
from typing import TYPE_CHECKING, Any

from fleetlog.storage.alogfields import entry_line, overflow_fields, standard_layout
from fleetlog.storage.columns import in_memory

if TYPE_CHECKING:
    import polars as pl

__all__ = ["Heads", "find_heads"]

#: The fields of an entry line in the standard layout, in this order.
FIELDS = ("offset", "var", "source", "v", "kpos", "spos", "vpos")


@dataclass
class Heads:
    """A block's lines sorted into entry lines, comments and the rest."""

    n: int  # lines in the block
    lines: pl.DataFrame | None  # every line (idx, l); None when ``partial`` (not needed)
    heads: pl.DataFrame  # entry lines with their fields (idx, l, FIELDS), in line order
    comments: pl.DataFrame  # comment lines: idx, l
    entries: int  # entry lines in the block; ``heads`` holds all of them unless ``partial``
    partial: bool  # ``heads`` holds only the lines that may be kept, and the last line
    is_head: pl.Series | None  # per line: entry or comment; None when every line is one
    is_entry: pl.Series | None  # per line: entry; None when every line is a head

    @property
    def pure(self) -> bool:
        """Every line of the block is an entry (no comment, continuation or stray line)."""
        return self.entries == self.n

    def entry_idx(self) -> pl.Series:
        """Return the indices of the block's entry lines (all of them, even when partial)."""
        import polars as pl

        if not self.partial:
            return self.heads["idx"]
        # every line is an entry or a comment
        every = pl.int_range(0, self.n, dtype=pl.UInt32, eager=True).alias("idx")
        if not self.comments.height:
            return every
        return every.filter(~every.is_in(self.comments["idx"].implode()))


@functools.cache
def _field_exprs(pl: ModuleType) -> tuple[Any, ...]:
    """Every line's fields as if it had the standard layout (built once)."""
    line = pl.col("l")
    return (
        line.str.slice(0, 16)
        .str.strip_chars_end(" ")
        .cast(pl.Float64, strict=False)
        .alias("offset"),
        line.str.slice(16, 21).str.strip_chars_end(" ").alias("var"),
        line.str.slice(37, 16).str.strip_chars_end(" ").alias("source"),
        line.str.slice(53).alias("v"),
        pl.lit(16, pl.Int32).alias("kpos"),
        pl.lit(37, pl.Int32).alias("spos"),
        pl.lit(53, pl.Int32).alias("vpos"),
    )


def _lines(pl: ModuleType, text: str) -> Any:
    line = pl.col("l")
    return pl.LazyFrame({"l": [text]}).select(line.str.split("\n").explode()).with_row_index("idx")


def find_heads(
    pl: ModuleType, text: str, literals: tuple[str, ...] | None = None, *, pure: bool = False
) -> Heads:
    """Split ``text`` into lines and find the entry lines, their fields and the comments.

    ``literals``: texts one of which every line the caller keeps holds (None: no such
    texts); with them, a block without continuation or stray lines gets the fields of the
    lines holding one and of its last line only (``partial``). ``pure``: the block is known
    to hold entry lines only (:mod:`fleetlog.storage.purity`), so with ``literals`` its
    lines are not tested one by one.
    """
    if literals and pure:
        return _known_pure(pl, text, literals)
    if literals:
        return _selective(pl, text, literals)
    # Every line as if it had the standard layout, and whether it has: one query.
    parsed = (
        _lines(pl, text)
        .select(pl.col("idx"), pl.col("l"), standard_layout(pl).alias("std"), *_field_exprs(pl))
        .collect(engine=in_memory(pl))
    )
    return _whole(pl, parsed.select("idx", "l"), parsed.drop("std"), parsed["std"])


def _others(
    pl: ModuleType, rest: pl.DataFrame, comments: bool = True
) -> tuple[pl.DataFrame, pl.DataFrame]:
    """Of the lines not in the standard layout: the entries (with fields) and the comments.

    ``comments``: look for the comments (else the second frame is empty).
    """
    if not rest.height:
        return rest, rest
    line = pl.col("l")
    candidates = rest.filter(line.str.contains(r"^-?[0-9]"))
    general = overflow_fields(pl, candidates) if candidates.height else candidates
    return general, rest.filter(line.str.starts_with("%") if comments else pl.lit(False))


def _whole(
    pl: ModuleType,
    lines: pl.DataFrame,
    parsed: pl.DataFrame,
    std_mask: pl.Series,
    comments: pl.DataFrame | None = None,
) -> Heads:
    """Every entry line with its fields: ``parsed`` has every line's standard fields.

    ``comments``: the comment lines, when already found.
    """
    general, found = _others(pl, lines.filter(~std_mask), comments is None)
    comments = found if comments is None else comments
    entry_mask = std_mask
    if general.height:
        # the overflowing lines' fields replace the standard layout's, in place
        general_idx = general["idx"]
        parsed = parsed.with_columns(
            parsed[name].scatter(general_idx, general[name]) for name in FIELDS
        )
        entry_mask = std_mask.clone().scatter(general_idx, True)
    heads = parsed.filter(entry_mask)
    is_head = is_entry = None
    if heads.height + comments.height < lines.height:
        is_entry = entry_mask
        is_head = entry_mask.clone().scatter(comments["idx"], True) if comments.height else None
        is_head = is_entry if is_head is None else is_head
    return Heads(lines.height, lines, heads, comments, heads.height, False, is_head, is_entry)


def _selective(pl: ModuleType, text: str, literals: tuple[str, ...]) -> Heads:
    col = pl.col
    line = col("l")
    # One pass over the lines (polars computes the shared part once): how many lines are
    # entries and comments, the comments, and the fields of the entries that may be kept
    # (those holding a literal) and of the last line. The lines themselves are not kept
    # (a copy of the block's text, ~0.5 ms a 2 MiB block): only a block with continuation
    # lines needs them, and splits its text again.
    base = _lines(pl, text).with_columns(
        entry=entry_line(pl),
        comment=line.str.starts_with("%"),
        maybe=line.str.contains_any(list(literals)),
    )
    counts, comments, picked = pl.collect_all(
        [
            base.select(n=pl.len(), entries=col("entry").sum(), comments=col("comment").sum()),
            base.filter(col("comment")).select("idx", "l"),
            base.filter(col("entry") & (col("maybe") | (col("idx") == pl.len() - 1))).select(
                col("idx"), line, standard_layout(pl).alias("std"), *_field_exprs(pl)
            ),
        ],
        engine=in_memory(pl),
    )
    n, entries, _ = counts.row(0)
    if entries + comments.height < n:
        # continuation or stray lines: which entry owns a line needs every entry
        lines = _lines(pl, text).collect(engine=in_memory(pl))
        parsed = lines.select(col("idx"), line, standard_layout(pl).alias("std"), *_field_exprs(pl))
        return _whole(pl, lines, parsed.drop("std"), parsed["std"], comments)
    # Every line is an entry or a comment: the entries not picked cannot be kept.
    return Heads(n, None, _picked_fields(pl, picked), comments, entries, True, None, None)


def _known_pure(pl: ModuleType, text: str, literals: tuple[str, ...]) -> Heads:
    """:func:`_selective` for a block known to hold entry lines only: no per-line tests."""
    col = pl.col
    line = col("l")
    base = _lines(pl, text).with_columns(maybe=line.str.contains_any(list(literals)))
    counts, picked = pl.collect_all(
        [
            base.select(n=pl.len()),
            base.filter(col("maybe") | (col("idx") == pl.len() - 1)).select(
                col("idx"), line, standard_layout(pl).alias("std"), *_field_exprs(pl)
            ),
        ],
        engine=in_memory(pl),
    )
    n = int(counts.item())
    comments = pl.DataFrame(schema={"idx": pl.UInt32, "l": pl.String})
    return Heads(n, None, _picked_fields(pl, picked), comments, n, True, None, None)


def _picked_fields(pl: ModuleType, picked: pl.DataFrame) -> pl.DataFrame:
    """The picked entry lines with their fields: the standard layout's, or the rule's."""
    std_mask = picked["std"]
    heads = picked.drop("std")
    if not std_mask.all():
        wide = overflow_fields(pl, heads.filter(~std_mask).select("idx", "l"))
        heads = pl.concat([heads.filter(std_mask), wide.select(heads.columns)]).sort("idx")
    return heads
