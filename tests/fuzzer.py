"""The fuzz campaign's runner: budgets, a hang watchdog, and the figures it reports.

Every target in ``test_inputs.py`` runs twice: a short run in the normal suite and a full run
(``FULL_CASES`` cases, marked ``slow``, so ``python -m pytest -m slow tests/fuzz`` is the
campaign). Each case runs under a watchdog: one that takes longer than ``HANG_SECONDS``
dumps every thread's stack and ends the process, so a hang is a loud failure, never a
stalled run. With ``FLEETLOG_FUZZ_REPORT=path`` the session writes a Markdown table of
what ran (cases, failures, slowest case, time) to that path, for ``docs/reliability.md``.
"""

from __future__ import annotations

import faulthandler
import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

SHORT_CASES = 60
FULL_CASES = int(os.environ.get("FLEETLOG_FUZZ_CASES", "100000"))
HANG_SECONDS = 60.0


@dataclass
class Figures:
    target: str
    budget: str
    cases: int = 0
    slowest: float = 0.0
    seconds: float = 0.0
    outcome: str = "running"
    notes: list[str] = field(default_factory=list)


#: every run of this process, for the report
FIGURES: list[Figures] = []


class Fuzzer:
    """Runs one target's check over many cases drawn from a strategy, and counts them."""

    def __init__(self, target: str, budget: str) -> None:
        self.figures = Figures(target, budget)
        FIGURES.append(self.figures)
        self.cases = SHORT_CASES if budget == "short" else FULL_CASES

    def run(self, strategy: st.SearchStrategy[Any], check: Callable[[Any], None]) -> None:
        figures = self.figures

        @settings(
            max_examples=self.cases,
            deadline=None,
            database=None,
            suppress_health_check=list(HealthCheck),
        )
        @given(strategy)
        def case(data: Any) -> None:
            figures.cases += 1
            faulthandler.dump_traceback_later(HANG_SECONDS, exit=True)
            began = time.perf_counter()
            try:
                check(data)
            finally:
                faulthandler.cancel_dump_traceback_later()
                figures.slowest = max(figures.slowest, time.perf_counter() - began)

        began = time.perf_counter()
        try:
            case()
        except BaseException as err:
            figures.outcome = f"FAILED: {type(err).__name__}: {str(err)[:120]}"
            raise
        finally:
            figures.seconds = time.perf_counter() - began
        figures.outcome = "ok"

    def note(self, text: str) -> None:
        """Add a remark to the report row (what was lost, refused, …)."""
        if text not in self.figures.notes:
            self.figures.notes.append(text)
