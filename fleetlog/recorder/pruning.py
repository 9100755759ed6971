"""The ``prune`` control command: the shore asks the vehicle to delete what it acknowledged.

The deleting is retention's (:mod:`fleetlog.storage.retention`, the one module that deletes
sessions); this runs it with :class:`~fleetlog.storage.retention.PruneAcknowledged` in a
thread of its own, because checking the acknowledgements may hash files (seconds on an SD
card) and neither the recording thread nor the control queryable's thread may wait for that.
One prune runs at a time; a second request meanwhile is refused ("busy").
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Collection
from pathlib import Path

from fleetlog.errors import StorageError
from fleetlog.storage import retention
from fleetlog.storage.download import sha256_file
from fleetlog.wire.control import Outcome

__all__ = ["MAX_LISTED", "Pruner"]

#: sessions a reply names at most (a reply stays far under Zenoh's 4 MiB)
MAX_LISTED = 1024


class Pruner:
    """Runs acknowledged prunes of a log root, one at a time, off the recording path.

    Args:
        log_root: the recorder's log root.
        current: returns the session being recorded.

    Attributes:
        digest: returns a file's sha256; the log server replaces it with its cache of the
            digests it computed while serving (so a just-collected session is not read again).
        fetching: returns the sessions the log server knows are being fetched (retention
            also checks the file leases, which any serving process holds).
    """

    def __init__(self, log_root: Path, current: Callable[[], str | None]) -> None:
        self.log_root = log_root
        self.current = current
        self.digest: Callable[[Path], str] = sha256_file
        self.fetching: Callable[[], Collection[str]] = tuple
        self._busy = threading.Lock()

    def submit(self, reply: Callable[[Outcome], None]) -> None:
        """Start a prune; ``reply`` gets its outcome from the prune's thread (or now, if busy)."""
        if not self._busy.acquire(blocking=False):
            reply(Outcome.refused("prune", "a prune is already running; try again shortly"))
            return

        def work() -> None:
            try:
                outcome = self.prune()
            except Exception as err:  # a prune must never take the recorder down
                outcome = Outcome.refused("prune", f"the prune failed: {err}")
            finally:
                self._busy.release()
            reply(outcome)

        threading.Thread(target=work, name="fleetlog-prune", daemon=True).start()

    def prune(self) -> Outcome:
        """Delete the acknowledged sessions (in this thread); return the outcome."""
        try:
            result = retention.run(
                self.log_root,
                [retention.PruneAcknowledged()],
                current=self.current,
                fetching=self.fetching,
                digest=self.digest,
            )
        except StorageError as err:
            return Outcome.refused("prune", str(err))
        removed = [r.session.name for r in result.removed]
        kept = dict(sorted(result.kept.items())[:MAX_LISTED])
        did = f"removed {len(removed)} acknowledged session(s), {result.freed} bytes"
        if result.skipped:
            did += f"; left {len(result.skipped)} (being recorded or fetched)"
        if result.failed:
            did += f"; {len(result.failed)} could not be removed"
        return Outcome.done(
            "prune",
            did,
            removed=removed[:MAX_LISTED],
            freed=result.freed,
            skipped=dict(sorted(result.skipped.items())[:MAX_LISTED]),
            failed=dict(sorted(result.failed.items())[:MAX_LISTED]),
            kept=kept,
        )
