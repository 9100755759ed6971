"""One streaming pass of the columnar reader over a log's blocks.

A pass reads the (decompressed) bytes a block at a time, cuts each block where its last
whole line ends (or, with two workers, where an entry starts, so that blocks can be parsed
side by side while the next is read), parses it (:mod:`fleetlog.storage.alogblocks`),
carries the unfinished end to the next block (a plain file's by seeking back to it),
accounts for stray lines under the error policy, and applies the cut-tail rules to the
last block. A pass with a purity memo (:mod:`fleetlog.storage.purity`) learns which blocks
held entry lines only and lets a selective pass skip their per-line tests.

:class:`BlockPasses` is a base of :class:`~fleetlog.storage.columnar.AlogReader`, which
opens the file, reads the banner and starts the passes.
"""

from __future__ import annotations

import io
from collections import deque
from collections.abc import Callable, Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING

from fleetlog.errors import FormatError, StorageError
from fleetlog.moos.alog import DATATYPE_MARKING
from fleetlog.storage.alogblocks import Parsed, PassState, parse_block
from fleetlog.storage.alogfields import entry_start, line_start, starts_entry
from fleetlog.storage.columns import Errors, decode_block, polars_module
from fleetlog.storage.decompress import LogBytes
from fleetlog.storage.purity import BlockSpan, FileVersion, PassPurity, PurityMemo
from fleetlog.storage.select import Selection

if TYPE_CHECKING:
    import polars as pl

__all__ = ["BlockPasses"]

#: Blocks parsed at once (never more than polars' thread pool: one in a recorder).
_WORKERS = 2
_MARKING = DATATYPE_MARKING.encode()


class BlockPasses:
    """The passes of a reader over its file (the reader sets these attributes)."""

    path: Path
    errors: Errors
    block_size: int
    purity: PurityMemo | None
    truncated: bool
    skipped: int
    scanned: int
    _open: set[LogBytes]

    @property
    def logstart(self) -> float | None:
        """The banner's LOGSTART (the reader's)."""
        raise NotImplementedError

    def _read(self, stream: LogBytes, size: int) -> tuple[bytes, bool]:
        """Read up to ``size`` bytes; return them and whether the stream was corrupt there."""
        try:
            return stream.read(size) or b"", False
        except StorageError:
            if self.errors == "raise":
                raise
            self.skipped += 1
            return b"", True
        except OSError as err:
            msg = f"cannot read {self.path}: {err.strerror or err}"
            raise StorageError(msg) from err
        except ValueError as err:  # I/O on the closed file
            if not stream.closed:
                raise
            msg = f"{self.path}: the reader was closed during a pass"
            raise StorageError(msg) from err

    def _pass(
        self,
        stream: LogBytes,
        head: bytes,
        want: frozenset[str],
        where: Callable[[pl.DataFrame], pl.Series] | None,
    ) -> Iterator[tuple[pl.DataFrame, bool]]:
        pl = polars_module()
        literals = where.literals if isinstance(where, Selection) else None
        state = PassState(where=where, literals=literals)
        workers = min(_WORKERS, int(pl.thread_pool_size()))
        pool = ThreadPoolExecutor(workers, "fleetlog-read") if workers > 1 else None
        purity = self._pass_purity(stream)
        pos = 0  # where ``buf`` starts in the file (a pass starts at its beginning)
        pending: deque[Future[Parsed]] = deque()
        # A plain file's unfinished end of a block is read again with the next block (sought
        # back to, from the page cache) rather than copied in front of it: a copy of the
        # whole block per block, under the GIL, at half the cost of its decoding.
        seekable: bool | None = None  # known after the first read (the stream may be closed)
        try:
            carry = head
            size = self.block_size
            while True:
                data, corrupt = self._read(stream, size)
                if not data:
                    while pending:
                        yield from self._account(pending.popleft().result(), state)
                    yield from self._finish(pl, state, carry, want, cut=corrupt or stream.truncated)
                    return
                buf = carry + data if carry else data
                if seekable is None:
                    seekable = not stream.compression and stream.seekable()
                rewind = seekable and len(data) == size  # (a short read: the end of the file)
                end = buf.rfind(b"\n")
                if end < 0:
                    carry = buf
                    size *= 2  # one line longer than a block
                    continue
                cut = entry_start(pl, buf, end) if pool is not None else None
                if cut is not None:
                    # The block ends where an entry starts, so it is whole: parse it while
                    # the next one is read (polars releases the GIL), in order.
                    block = memoryview(buf)[: cut - 1]
                    carry = _rest(stream, buf, cut, rewind)
                    job = PassState(state.lineno, state.mark, where=where, literals=literals)
                    state.lineno += buf.count(b"\n", 0, cut - 1) + 1
                    state.mark = state.mark or _has_line(buf, _MARKING, cut - 1)
                    assert pool is not None
                    span = BlockSpan(purity, pos, pos + cut)
                    pending.append(pool.submit(self._parse_job, pl, block, job, want, span))
                    pos += cut
                    while len(pending) > workers or (pending and pending[0].done()):
                        yield from self._account(pending.popleft().result(), state)
                    size = self.block_size
                    continue
                # No entry starts near the end of the block: find the unfinished entry by
                # parsing it, after the blocks before it.
                while pending:
                    yield from self._account(pending.popleft().result(), state)
                # (a view: the block is decoded, not copied first)
                span = BlockSpan(purity, pos, pos + end + 1)
                parsed = self._parse(pl, memoryview(buf)[:end], state, want, final=False, span=span)
                kept = parsed.lines - parsed.consumed
                at = line_start(buf, end, kept)
                carry = _rest(stream, buf, at, rewind)
                pos += at
                yield from self._account(parsed, state)
                state.lineno += parsed.consumed
                state.mark = parsed.mark
                size = self.block_size if parsed.consumed else size * 2
        finally:
            for future in pending:
                future.cancel()
            if pool is not None:
                pool.shutdown(wait=True, cancel_futures=True)
            stream.close()
            self._open.discard(stream)

    def _parse_job(
        self,
        pl: ModuleType,
        block: memoryview,
        job: PassState,
        want: frozenset[str],
        span: BlockSpan,
    ) -> Parsed:
        return self._parse(pl, block, job, want, final=False, at_head=True, span=span)

    def _pass_purity(self, stream: LogBytes) -> PassPurity | None:
        """The purity memo for a pass over ``stream`` (plain files only), or None."""
        if self.purity is None or stream.compression:
            return None
        try:
            return PassPurity(self.purity, FileVersion.of(stream.fileno()))
        except (OSError, ValueError):  # (closed by another thread: the first read says so)
            return None

    def _finish(
        self, pl: ModuleType, state: PassState, carry: bytes, want: frozenset[str], *, cut: bool
    ) -> Iterator[tuple[pl.DataFrame, bool]]:
        """Parse the last block: apply the cut-tail rules (MOOS_FORMAT.md §12)."""
        end = carry.rfind(b"\n")
        tail = carry[end + 1 :]
        complete = True
        mark_at_end = False
        if tail:
            # A cut line that starts a new entry (or a comment) proves the entry before it
            # was whole; a cut continuation line leaves that entry's value unknown.
            self.truncated = True
            complete = tail.startswith(b"%") or starts_entry(tail)
            mark_at_end = tail == _MARKING
        elif cut:
            self.truncated = True
            complete = False
        if end >= 0:
            parsed = self._parse(
                pl,
                carry[:end],
                state,
                want,
                final=True,
                complete=complete,
                mark_at_end=mark_at_end,
            )
            yield from self._account(parsed, state)
        if state.orphans > state.reported:
            if self.errors == "raise":
                raise _stray_error(self.path, state.orphans - state.reported, None)
            self.skipped += state.orphans - state.reported
            state.reported = state.orphans

    def _account(self, parsed: Parsed, state: PassState) -> Iterator[tuple[pl.DataFrame, bool]]:
        """Yield a block's entries, counting or raising on its stray lines.

        The line parser raised at the first entry after a stray line, having yielded the
        entries before it; under ``"skip"`` it counted them.
        """
        frame = parsed.frame
        state.orphans += len(parsed.orphans)
        if self.errors == "skip":
            self.skipped += state.orphans - state.reported
            state.reported = state.orphans
        elif state.orphans > state.reported:
            pending = state.orphans - state.reported - len(parsed.orphans)
            first = parsed.orphans[0] if not pending else 0
            later = frame["line"].filter(frame["line"] > first)
            if later.len():
                line = int(later[0])
                count = pending + sum(1 for n in parsed.orphans if n < line)
                before = frame.filter(frame["line"] < line)
                if before.height:
                    yield before, parsed.exact
                raise _stray_error(self.path, count, line)
        state.entries += parsed.scanned
        self.scanned = state.entries
        if frame.height:
            yield frame, parsed.exact

    def _parse(
        self,
        pl: ModuleType,
        block: bytes | memoryview,
        state: PassState,
        want: frozenset[str],
        *,
        final: bool,
        complete: bool = True,
        mark_at_end: bool = False,
        at_head: bool = False,
        span: BlockSpan | None = None,
    ) -> Parsed:
        """Parse the whole lines of ``block`` (no trailing newline) into entries.

        ``span``: where the block and its newline are in the file, to look up and learn
        whether its lines are all entries (a pass with a purity memo).
        """
        text, exact = decode_block(block)
        pure = bool(state.literals) and span is not None and span.known_pure()
        parsed = parse_block(
            pl,
            text,
            bytes(block) if not exact else None,
            state,
            self.logstart,
            want,
            final=final,
            complete=complete,
            mark_at_end=mark_at_end,
            on_drop=self._dropped,
            at_head=at_head,
            pure=pure,
        )
        if span is not None and parsed.pure and not pure:
            span.learn()
        return parsed

    def _dropped(self) -> None:
        self.truncated = True


def _has_line(buf: bytes, line: bytes, end: int) -> bool:
    """Whether ``line`` is one of the lines of ``buf[:end]`` (without copying them)."""
    return (
        buf.startswith(line + b"\n", 0, end)
        or buf.endswith(b"\n" + line, 0, end)
        or (end == len(line) and buf.startswith(line))
        or buf.find(b"\n" + line + b"\n", 0, end) >= 0
    )


def _rest(stream: LogBytes, buf: bytes, at: int, rewind: bool) -> bytes:
    """The bytes of ``buf`` from ``at`` on, for the next block: b"" if sought back to.

    ``rewind``: ``buf`` ends where the stream is, and the stream is a plain file.
    """
    rest = len(buf) - at
    if not rewind or rest <= 0:
        return buf[at:]
    try:
        stream.seek(-rest, io.SEEK_CUR)
    except (OSError, ValueError):  # (closed by another thread: the next read says so)
        return buf[at:]
    return b""


def _stray_error(path: Path, count: int, line: int | None) -> FormatError:
    where = f"before line {line}" if line is not None else "after the banner"
    msg = f"{count} line(s) {where} are neither entries nor comments"
    return FormatError(msg, str(path), line)
