"""Run a command in a network namespace of its own, where multicast works on loopback.

fleetlog's default mode (embedded peers finding each other by multicast scouting) cannot be
tested on the machine's own interfaces: tests touch only loopback, and other engineers' tests
run at the same time. So such a test runs its whole process tree in a fresh user and network
namespace (``unshare -rn``, no root needed where user namespaces are allowed) whose only
interface is ``lo``, with multicast switched on and a route for 224.0.0.0/4 (without them
Zenoh's scouting finds nobody on ``lo``).
"""

from __future__ import annotations

import shutil
import subprocess
from collections.abc import Sequence

__all__ = ["netns_argv", "netns_unavailable"]

_SETUP = (
    "ip link set lo up && ip link set lo multicast on"
    ' && ip route add 224.0.0.0/4 dev lo && exec "$@"'
)
_why: str | None = None
_checked = False


def netns_argv(argv: Sequence[str]) -> list[str]:
    """The command line that runs ``argv`` in a fresh namespace with multicast on ``lo``."""
    return ["unshare", "-rn", "sh", "-c", _SETUP, "sh", *argv]


def netns_unavailable() -> str | None:
    """Why a namespace cannot be made here (no unshare or ip, user namespaces off), or None."""
    global _why, _checked
    if _checked:
        return _why
    _checked = True
    for tool in ("unshare", "ip"):
        if shutil.which(tool) is None:
            _why = f"{tool} is not installed"
            return _why
    probe = subprocess.run(
        netns_argv(["ip", "-o", "link", "show", "lo"]),
        capture_output=True,
        text=True,
        timeout=10,
        check=False,
    )
    if probe.returncode != 0 or "MULTICAST" not in probe.stdout:
        _why = f"cannot make a network namespace: {probe.stderr.strip() or probe.stdout.strip()}"
    return _why
