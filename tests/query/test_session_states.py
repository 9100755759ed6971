"""What the shore sees of session metadata: open, closed, cut, and an unsynchronised clock.

A log root with three generated sessions and metadata written as a recorder writes it (one
closed on a synchronised clock, one closed on an unsynchronised one, one left ``open`` by a
recorder that is gone) is served by ``fleetlog serve``; ``fleetlog sessions`` and ``fleetlog
fleet`` run as subprocesses.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from query_support import Fleet, make_session

from fleetlog.storage.catalog import LogCatalog
from fleetlog.storage.metafile import boot_id, host_name, write_meta
from fleetlog.wire.session_meta import SessionMeta

NAMES = (
    "MOOSLog_1_1_2026_____00_00_00",
    "MOOSLog_1_1_2026_____01_00_00",
    "MOOSLog_1_1_2026_____02_00_00",
)


def meta(name: str, state: str, synced: bool) -> SessionMeta:
    return SessionMeta(
        state=state,
        vehicle="gen",
        session=name,
        recorder="z",
        fleetlog="0",
        opened=1.0,
        logstart=1.0,
        updated=2.0,
        closed=3.0 if state == "closed" else None,
        clock={"source": "adjtimex", "synchronized": synced},
        host=host_name(),
        pid=os.getpid() + 10_000_000,  # not a live process: only the lock would say so
        boot=boot_id(),
    )


def test_states_and_clock_warnings_reach_the_shore(fleet: Fleet, tmp_path: Path) -> None:
    root = tmp_path / "logs"
    for name, (state, synced) in zip(
        NAMES, [("closed", True), ("closed", False), ("open", False)], strict=True
    ):
        write_meta(make_session(root, name, 0.01), meta(name, state, synced))
    fleet.serve(root, "gen")
    listed = fleet.cli("sessions", "gen", "--json")
    assert listed.returncode == 0, listed.stderr
    rows = {row["name"]: row for row in map(json.loads, listed.stdout.splitlines())}
    assert [(rows[n]["state"], rows[n]["synced"], rows[n]["complete"]) for n in NAMES] == [
        ("closed", True, True),
        ("closed", False, True),
        ("cut", False, True),  # open, but no recorder holds it
    ]
    assert (
        f"fleetlog: warning: gen's clock was not synchronised when 2 session(s) opened"
        f" ({NAMES[1]}, {NAMES[2]})" in listed.stderr
    )
    table = fleet.cli("sessions", "gen")
    assert "closed (clock not synced)" in table.stdout
    assert "cut (clock not synced)" in table.stdout
    up = fleet.cli("fleet")
    assert up.returncode == 0, up.stderr
    assert "gen's clock was not synchronised when its latest session" in up.stderr


def test_a_session_closed_between_reading_its_file_and_its_lock_is_closed(
    tmp_path: Path,
) -> None:
    """The listing read ``open``; then the recorder wrote ``closed`` and let its lock go."""
    root = tmp_path / "logs"
    name = NAMES[0]
    directory = make_session(root, name, 0.01)
    write_meta(directory, meta(name, "closed", True))  # on disk now; nobody holds the lock
    catalog = LogCatalog(root, vehicle="gen")
    assert catalog.state(name, meta(name, "open", True)) == "closed"
    # a session whose file still says open when nobody holds it is cut
    write_meta(directory, meta(name, "open", True))
    assert catalog.state(name, meta(name, "open", True)) == "cut"
