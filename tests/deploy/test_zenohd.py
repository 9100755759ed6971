"""The shipped router configurations run in the stock zenohd 1.10.2, where it is installed.

zenohd is not part of the repository (it builds from crates.io: `cargo install zenohd
--version 1.10.2`); without it on PATH (or ZENOHD naming it) this test is skipped, loudly.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import time
from pathlib import Path

import pytest
from deploy_support import OPS, SecureFleet, alog_text

ZENOHD = os.environ.get("ZENOHD") or shutil.which("zenohd")


def test_stock_zenohd_runs_the_profile(tmp_path: Path) -> None:
    if ZENOHD is None:
        pytest.skip(
            "SKIPPED LOUDLY: zenohd is not installed (cargo install zenohd --version 1.10.2)"
        )
    version = subprocess.run([ZENOHD, "--version"], capture_output=True, text=True, check=False)
    assert "1.10.2" in version.stdout + version.stderr, "the configurations were tested with 1.10.2"
    env = dict(os.environ, TZ="UTC", NO_COLOR="1")
    secure = SecureFleet(tmp_path / "fleet", env, ("alpha",))
    try:
        secure.start_router("shore", zenohd=ZENOHD)
        secure.start_router("alpha", zenohd=ZENOHD)
        secure.start_recorder("alpha")
        assert "alpha" in secure.wait_vehicles(OPS, {"alpha"}, timeout=30)
        code, _, err = secure.cli(OPS, "poke", "--vehicle", "alpha", "PLOGGER_CMD:=via-zenohd")
        assert code == 0, err
        code, _, err = secure.cli(OPS, "poke", "--vehicle", "alpha", "NAV_X=1")
        assert code == 1
        time.sleep(0.5)
        assert "via-zenohd" in alog_text(secure.directory / "logs" / "alpha")
        code, _, err = secure.cli("vehicles/alpha", "fleet")
        assert code == 1
        assert "access control may have refused" in err
    finally:
        secure.close()
