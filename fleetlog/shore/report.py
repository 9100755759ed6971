"""What a command that works on several vehicles did with each, and how to say it.

A shore command over the fleet (``fetch --all``, ``status``, and the collector) records each
vehicle's outcome in a :class:`FleetReport`: done, missing (expected but never seen) or
failed (with the one-sentence reason). :meth:`FleetReport.summary` says which part of the
work was not done; a command whose report is not :attr:`~FleetReport.ok` exits non-zero
with it. Every shore command reports its failures through this one place.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from fleetlog.errors import QueryError

__all__ = ["FleetReport", "PartialError"]


class PartialError(QueryError):
    """A command over several vehicles did only part of its work.

    Attributes:
        report: what it did with each vehicle.
    """

    def __init__(self, report: FleetReport) -> None:
        self.report = report
        super().__init__(report.summary())


@dataclass
class FleetReport:
    """Each vehicle's outcome.

    Attributes:
        verb: what was done, in the past tense (``fetched``), for the summary.
        done: vehicle (or ``vehicle@zid``) → one line on what was done.
        missing: vehicles expected but not up.
        failed: vehicle → why it failed, one sentence.
        skipped: vehicle → why there was nothing to do (not a failure: a vehicle with no
            session yet).
    """

    verb: str
    done: dict[str, str] = field(default_factory=dict)
    missing: list[str] = field(default_factory=list)
    failed: dict[str, str] = field(default_factory=dict)
    skipped: dict[str, str] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        """Nothing is missing and nothing failed."""
        return not self.missing and not self.failed

    @property
    def vehicles(self) -> int:
        """How many vehicles the command meant to cover."""
        return len({*self.done, *self.missing, *self.failed, *self.skipped})

    def summary(self) -> str:
        """One sentence: how many were done, which were missing or failed, and why."""
        parts = [f"{self.verb} {len(self.done)} of {self.vehicles} vehicle(s)"]
        if self.missing:
            parts.append(f"not up: {', '.join(self.missing)}")
        if self.failed:
            reasons = "; ".join(f"{v}: {why}" for v, why in sorted(self.failed.items()))
            parts.append(f"failed: {reasons}")
        return "; ".join(parts)

    def check(self) -> None:
        """Raise if the work was only partly done.

        Raises:
            PartialError: a vehicle is missing or failed.
        """
        if not self.ok:
            raise PartialError(self)
