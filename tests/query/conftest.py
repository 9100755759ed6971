"""Fixtures of the query tests: a fleet of ``fleetlog serve`` vehicles, killed at the end."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from query_support import Fleet


@pytest.fixture
def fleet(cli_env: dict[str, str]) -> Iterator[Fleet]:
    """Start vehicles with ``fleet.serve(...)``; all are killed at the end."""
    vehicles = Fleet(cli_env)
    try:
        yield vehicles
    finally:
        vehicles.close()
