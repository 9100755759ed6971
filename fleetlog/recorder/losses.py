"""What the recorder lost and has not marked in a log yet, by reason: the source of its gaps.

Every loss is counted in the recorder's counters as it happens; this ledger also remembers
where and why, so that a ``PLOGGER_GAP`` entry (docs/compat.md) marks it in the alog as soon
as there is a session to write it in: at once for samples lost on the way (``dropped``) or
unreadable, and as the first entries of the next session for losses that broke the
session (a full or read-only disk, a removed directory, a write error).
"""

from __future__ import annotations

import errno
from dataclasses import dataclass, field

from fleetlog.errors import FleetlogError
from fleetlog.wire.session_meta import MAX_GAP_VARS, Gap

__all__ = ["LossLedger", "reason_of"]

#: variables counted by name per reason (a flood of names is counted in the total only)
_MAX_NAMES = 1024
_REASONS = {
    errno.ENOSPC: "disk-full",
    errno.EDQUOT: "disk-full",
    errno.EFBIG: "file-too-large",
    errno.EROFS: "read-only",
    errno.ENOENT: "removed",
    errno.EIO: "io-error",
}


def reason_of(err: FleetlogError) -> str:
    """Return the gap reason of a storage failure, from the OS error behind it."""
    cause = err.__cause__
    code = getattr(cause, "errno", None)
    return _REASONS.get(code, "write-error") if isinstance(code, int) else "write-error"


@dataclass
class _Loss:
    start: float
    end: float
    count: int = 0
    known: bool = True
    names: dict[str, int] = field(default_factory=dict)
    session: str = ""
    #: marked even if no sample was lost (a removed directory: what it held is gone)
    always: bool = False


class LossLedger:
    """Losses by reason, until they are written as gaps."""

    def __init__(self) -> None:
        self._open: dict[str, _Loss] = {}

    def __bool__(self) -> bool:
        return bool(self._open)

    def add(
        self,
        reason: str,
        count: int | None,
        now: float,
        *,
        name: str | None = None,
        session: str = "",
        always: bool = False,
    ) -> None:
        """Count ``count`` samples lost for ``reason`` (None: an unknown number).

        ``always``: mark it even if no sample is lost (else a loss of none leaves no gap).
        """
        loss = self._open.get(reason)
        if loss is None:
            loss = self._open[reason] = _Loss(now, now, session=session, always=always)
        loss.end = now
        if count is None:
            loss.known = False
        else:
            loss.count += count
        if name is not None and count:
            names = loss.names
            if name in names or len(names) < _MAX_NAMES:
                names[name] = names.get(name, 0) + count

    def take(self, now: float) -> list[Gap]:
        """Return every loss as a gap (its 16 most-lost variables named) and forget them.

        A failure that cost no sample leaves no gap (MOOS_DEBUG reported it).
        """
        gaps = []
        for reason, loss in self._open.items():
            if loss.known and not loss.count and not loss.always:
                continue
            top = sorted(loss.names.items(), key=lambda kv: (-kv[1], kv[0]))[:MAX_GAP_VARS]
            gaps.append(
                Gap(
                    now,
                    reason,
                    loss.count if loss.known else None,
                    loss.start,
                    loss.end,
                    dict(top),
                    loss.session,
                )
            )
        self._open.clear()
        return gaps
