"""Fixtures of the fuzz suite: each target runs short (normal suite) and full (``slow``).

``python -m pytest -m slow tests/fuzz`` is the full campaign; with
``FLEETLOG_FUZZ_REPORT=path`` the session writes a Markdown table of its figures there.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
from fuzzer import FIGURES, Fuzzer


@pytest.fixture(
    params=[
        pytest.param("short"),
        pytest.param("full", marks=pytest.mark.slow),
    ]
)
def budget(request: pytest.FixtureRequest) -> str:
    return str(request.param)


@pytest.fixture
def fuzz(request: pytest.FixtureRequest, budget: str) -> Iterator[Fuzzer]:
    target = request.node.originalname.removeprefix("test_fuzz_")
    yield Fuzzer(target, budget)
    _write_report()  # after every target, so a long campaign cut short keeps its figures


def _write_report() -> None:
    path = os.environ.get("FLEETLOG_FUZZ_REPORT")
    if not path or not FIGURES:
        return
    rows = [
        "| input | run | cases | outcome | slowest case | time | notes |",
        "|---|---|---:|---|---:|---:|---|",
    ]
    for f in FIGURES:
        rows.append(
            f"| {f.target} | {f.budget} | {f.cases:,} | {f.outcome} | {f.slowest * 1000:.1f} ms "
            f"| {f.seconds:.1f} s | {'; '.join(f.notes)} |"
        )
    Path(path).write_text("\n".join(rows) + "\n", encoding="utf-8")


def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    path = os.environ.get("FLEETLOG_FUZZ_REPORT")
    if path and FIGURES:
        _write_report()
        print(f"\nfuzz figures written to {path}", file=sys.stderr)
