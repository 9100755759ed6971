"""Shared fixtures: the reference sessions, loopback endpoints, the CLI environment."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from helpers import REFERENCE, free_port


@pytest.fixture(autouse=True, scope="session")
def _no_machine_configuration(tmp_path_factory: pytest.TempPathFactory) -> None:
    """Tests never read this machine's /etc/fleetlog, ZENOH_CONFIG or FLEETLOG_SETTINGS."""
    os.environ["FLEETLOG_ETC"] = str(tmp_path_factory.mktemp("etc") / "none")
    os.environ.pop("ZENOH_CONFIG", None)
    os.environ.pop("FLEETLOG_SETTINGS", None)


@pytest.fixture
def endpoint() -> str:
    """A fresh loopback endpoint for one test's Zenoh sessions."""
    return f"tcp/127.0.0.1:{free_port()}"


@pytest.fixture
def reference() -> Path:
    """The real pLogger sessions (the oracle)."""
    if not REFERENCE.is_dir():
        pytest.fail(f"the reference sessions are missing: {REFERENCE}")
    return REFERENCE


@pytest.fixture
def cli_env() -> dict[str, str]:
    """Environment for CLI subprocesses: UTC, no colour."""
    env = dict(os.environ)
    env["TZ"] = "UTC"
    env["NO_COLOR"] = "1"
    env.pop("FORCE_COLOR", None)
    return env
