"""One block of alog text becomes entries: continuation lines, stray lines, cut tails.

:func:`parse_block` splits a block into lines and finds the entry lines' fields
(:mod:`fleetlog.storage.alogheads`), joins continuation lines to the entry before them
(before any entry, or after a comment, they are stray lines), follows the DATATYPE MARKING
state, applies the cut-tail rules to a file's last entry (MOOS_FORMAT.md §12), runs the
caller's ``where`` and types what it keeps (:mod:`fleetlog.storage.alogtypes`). The state a
pass carries from block to block is a :class:`PassState`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from types import ModuleType
from typing import TYPE_CHECKING, Any

from fleetlog.moos.alog import DATATYPE_MARKING
from fleetlog.storage.alogheads import find_heads
from fleetlog.storage.alogtypes import exact_raw, typed

if TYPE_CHECKING:
    import polars as pl

__all__ = ["Parsed", "PassState", "parse_block"]

_BINARY_OPEN = "<MOOS_BINARY>"
_BINARY_CLOSE = "</MOOS_BINARY>"


@dataclass
class PassState:
    """The state one pass carries from block to block."""

    lineno: int = 1  # the line number of the first line of the next block
    mark: bool = False  # DATATYPE MARKING seen
    entries: int = 0  # entries read so far (before ``where``)
    where: Callable[[pl.DataFrame], pl.Series] | None = None
    orphans: int = 0  # stray lines seen so far
    reported: int = 0  # stray lines already reported (raise) or counted (skip)
    literals: tuple[str, ...] | None = None  # every line ``where`` keeps holds one of them


@dataclass
class Parsed:
    """What parsing one block gave."""

    frame: pl.DataFrame  # the entries, with internal columns
    consumed: int  # lines of the block that are done (the rest is carried)
    mark: bool  # the DATATYPE MARKING state after the consumed lines
    orphans: list[int]  # line numbers of stray lines
    exact: bool  # the block was valid UTF-8
    scanned: int = 0  # entries read (before ``where``)
    lines: int = 0  # lines in the block
    pure: bool = False  # every line of the block is an entry


def parse_block(
    pl: ModuleType,
    text: str,
    block: bytes | None,
    state: PassState,
    logstart: float | None,
    want: frozenset[str],
    *,
    final: bool,
    complete: bool,
    mark_at_end: bool,
    on_drop: Any,
    at_head: bool = False,
    pure: bool = False,
) -> Parsed:
    """Parse the lines of ``text``; ``block`` is its bytes when they were not all UTF-8.

    ``final``: the file ends here (the cut-tail rules apply to the last entry). ``at_head``:
    the next line, not in ``text``, starts an entry, so every entry here is finished.
    Otherwise the last entry may go on in the next block: it is left out (``consumed``).
    ``pure``: every line of ``text`` is known to be an entry (:func:`find_heads`).
    """
    col = pl.col
    line = col("l")
    found = find_heads(pl, text, state.literals, pure=pure)
    heads, comments = found.heads, found.comments
    n = found.n
    comment_idx = comments["idx"]
    entries = found.entries

    # Continuation lines join the entry before them; before any entry, or after a comment,
    # they are stray lines.
    orphans: list[int] = []
    continued = False
    if found.is_head is not None and found.is_entry is not None and found.lines is not None:
        is_head = found.is_head
        tagged = found.lines.with_columns(
            gid=is_head.cast(pl.Int32).cum_sum(), head=is_head, entry=found.is_entry
        )
        owner = tagged.filter(col("head")).select("gid", "entry")
        conts = tagged.filter(~col("head")).drop("entry").join(owner, on="gid", how="left")
        conts = conts.with_columns(col("entry").fill_null(False))
        stray = conts.filter(~col("entry"))
        orphans = [int(i) + state.lineno for i in stray["idx"]]
        attached = conts.filter(col("entry"))
        if attached.height:
            joined = attached.group_by("gid", maintain_order=True).agg(
                col("l").str.join("\n").alias("c")
            )
            # the entry that owns group g is the head line at the g-th head
            head_idx = tagged.filter(col("head"))["idx"]
            joined = joined.with_columns(idx=head_idx.gather(joined["gid"] - 1)).drop("gid")
            heads = heads.join(joined, on="idx", how="left", maintain_order="left")
            continued = True
    if not continued:
        heads = heads.with_columns(c=pl.lit(None, pl.String))

    # The DATATYPE MARKING state where each entry was finished (at the next head, or at the
    # end of the file): the line parser classified an entry then.
    end_mark = state.mark
    mark_lines = comments.filter(line == DATATYPE_MARKING)["idx"] if comments.height else None
    mark: Any = state.mark
    if not state.mark and mark_lines is not None and mark_lines.len():
        end_mark = True
        first = int(mark_lines[0])
        # entries after the marking line, and the one it finished (no comment in between)
        entry_idx = found.entry_idx()
        before = entry_idx.filter(entry_idx < first)
        finisher = -1
        if before.len():
            last = int(before[-1])
            if not comment_idx.filter((comment_idx > last) & (comment_idx < first)).len():
                finisher = last
        mark = (col("idx") > first) | (col("idx") == finisher)

    # What is done: in a non-final block, the last entry may go on in the next block.
    consumed = n
    last_head = max(
        int(heads["idx"][-1]) if heads.height else -1,
        int(comment_idx[-1]) if comments.height else -1,
    )
    last_is_entry = heads.height > 0 and int(heads["idx"][-1]) == last_head
    dropped = False
    if last_is_entry and not final and not at_head:
        consumed = last_head
        heads = heads.slice(0, heads.height - 1)
        entries -= 1
    elif last_is_entry and final:
        # the last entry: whole only if the file was, and if it ends with its terminator
        value = heads["v"][-1]
        more = heads["c"][-1]
        last_part = more.rsplit("\n", 1)[-1] if more is not None else value
        terminated = last_part.endswith(" ") or (
            value.startswith(_BINARY_OPEN) and last_part.endswith(_BINARY_CLOSE)
        )
        if not complete or not terminated:
            heads = heads.slice(0, heads.height - 1)
            entries -= 1
            dropped = True
        elif mark_at_end and not end_mark:
            mark = pl.when(col("idx") == last_head).then(True).otherwise(pl.lit(mark))
    if dropped:
        on_drop()
    scanned = entries
    if state.where is not None and heads.height:
        keep = state.where(
            heads.select(
                line=(col("idx") + state.lineno).cast(pl.Int64),
                offset="offset",
                var="var",
                source="source",
            )
        )
        heads = heads.filter(keep)
    frame = typed(
        pl,
        heads,
        mark,
        state.lineno,
        logstart,
        want,
        continued,
        # a binary reference is a whole one-line value: only values that start with the tag
        heads.height > 0 and bool(heads["v"].str.starts_with(_BINARY_OPEN).any()),
    )
    if block is not None:
        frame = exact_raw(pl, frame, block, state.lineno)
    return Parsed(frame, consumed, end_mark, orphans, block is None, scanned, n, found.pure)
