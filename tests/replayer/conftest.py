"""Fixtures for the replayer tests."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import pytest
from replay_support import Line, MakeSession, write_session


@pytest.fixture
def make_session(tmp_path: Path) -> MakeSession:
    """Return ``make(lines, name=..., **write_session options)`` writing under tmp_path."""
    counter = iter(range(1000))

    def make(lines: Sequence[Line], name: str | None = None, **kwargs: object) -> Path:
        base = tmp_path / (name or f"s{next(counter)}")
        return write_session(base, lines, **kwargs)  # type: ignore[arg-type]

    return make
