"""Real pLogger alogs (tests/data/reference) replayed: continuation lines, duplicates, order.

Every reference alog is played as fast as possible into a list, and what comes out is checked
against an independent reading of the same file: the entries in time order (file order for
equal times), without negative times (uPlayBack's rule) and without exact re-deliveries (same
time, variable, source and value, binary compared by its bytes), every value exactly as the
§12 reader reads it. One of them also goes through ``fleetlog replay`` over Zenoh.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import zenoh
from helpers import REFERENCE
from replay_support import Proc

from fleetlog.errors import StorageError
from fleetlog.moos.alog import BinaryRef
from fleetlog.replayer.clock import FakeClock
from fleetlog.replayer.engine import Player
from fleetlog.replayer.inputs import open_input
from fleetlog.replayer.options import PlayOptions
from fleetlog.storage.readers import AlogReader
from fleetlog.transport.session import SessionOptions, open_session
from fleetlog.wire.message import MoosMessage, decode_attachment

CAPTURED = REFERENCE / "captured"
RUN_A = CAPTURED / "runA_themoos_wildcard_restart/logs/TEST_22_11_2026_____11_06_44"
SESSIONS = {
    "themoos": (REFERENCE / "themoos_session/MOOSLog_3_2_2025_____09_05_07", "auv", "._moos"),
    "ivp": (REFERENCE / "ivp_session/LOG_ALPHA_19_6_2025_____12_04_50", "alpha", "DB_TIME"),
    "runA-1": (RUN_A, "test", "DB_TIME"),
    "runA-2": (RUN_A.parent / "TEST_22_11_2026_____11_06_52", "test", "DB_TIME"),
    "runB1-gz": (
        CAPTURED / "runB1_ivp_compressed_markdatatype/LOG_ALPHA_22_11_2026_____11_07_42",
        "ivp",
        "._moos",
    ),
    "runB2-fixed": (CAPTURED / "runB2_nofiletimestamp/FIXED", "nb", "._moos"),
    "runB2-glogs": (
        CAPTURED / "runB2_nofiletimestamp/glogs/MOOSLog_22_11_2026_____11_08_11",
        "nb",
        "DB_TIME",
    ),
}


def expected_of(session: Path) -> tuple[list[tuple[object, ...]], int, int]:
    """Read the alog independently: (played entries, negatives dropped, duplicates dropped)."""
    alog = next(p for p in session.iterdir() if p.name.endswith((".alog", ".alog.gz")))
    with AlogReader(alog) as reader:
        rows: list[tuple[float, int, tuple[object, ...]]] = []
        negatives = duplicates = 0
        seen: set[tuple[object, ...]] = set()
        for index, entry in enumerate(reader.entries()):
            if entry.offset < 0:
                negatives += 1
                continue
            value: object = entry.value
            if isinstance(value, BinaryRef):
                try:
                    value = reader.read_binary(entry)
                except StorageError:  # Offset=-1 after a restart: unplayable
                    value = entry.text
            sig = (entry.offset, entry.key, entry.source, value)
            if sig in seen:
                duplicates += 1
                continue
            seen.add(sig)
            rows.append((entry.offset, index, (entry.key, entry.source, value)))
        assert reader.logstart is not None
    rows.sort(key=lambda row: (row[0], row[1]))
    return [row[2] for row in rows], negatives, duplicates


def source_field(message: MoosMessage) -> str:
    field = message.source
    if message.aux:
        field += ":" + message.aux
    if message.community:
        field += "@" + message.community
    return field


@pytest.mark.parametrize("name", SESSIONS)
def test_reference_alogs_replay_in_order_without_duplicates(name: str) -> None:
    session, vehicle, how = SESSIONS[name]
    source = open_input(session)
    try:
        assert (source.vehicle, source.vehicle_from) == (vehicle, how)
        sent: list[MoosMessage] = []
        player = Player(
            [source],
            lambda _v, m: sent.append(m),
            FakeClock(),
            PlayOptions(rate=None, db_time=False),
        )
        summary = player.run()
    finally:
        source.close()
    expected, negatives, duplicates = expected_of(session)
    got = [(m.name, source_field(m), m.value) for m in sent]
    unplayable = [row for row in expected if isinstance(row[2], str) and row[2].startswith("<MOOS")]
    assert got == [row for row in expected if row not in unplayable]
    assert (summary.before_logstart, summary.duplicates) == (negatives, duplicates)
    assert summary.unplayable == len(unplayable)
    times = [m.original_time for m in sent]
    assert times == sorted(times)  # type: ignore[type-var]


def test_reference_specifics() -> None:
    """What the captured runs hold, spelled out: multi-line values, binary, negatives, dups."""
    _, negatives, _ = expected_of(SESSIONS["runB2-fixed"][0])
    assert negatives > 0  # stale re-deliveries with negative times (runB2, §10)
    run_a, _, duplicates = expected_of(RUN_A)
    assert duplicates > 0  # re-registration blocks (§2.2)
    values = {key: value for key, _, value in run_a}
    assert values["MULTI"] == "line1\nline2"
    assert values["EMPTY"] == ""
    assert isinstance(values["BIN"], bytes)
    assert len(values["BIN"]) == 16
    assert "\n" in str(values["DB_VARSUMMARY"])
    gz, _, gz_dups = expected_of(SESSIONS["runB1-gz"][0])
    gz_values = {key: value for key, _, value in gz}
    assert gz_values["MOOS_DEBUG"] == "hello\ndebug"  # MarkDataType's S: removed
    assert next(v for k, _, v in gz if k == "NAV_X") == 1.5
    assert gz_dups > 0


# -- over Zenoh


@pytest.fixture
def collected(endpoint: str) -> Iterator[list[tuple[str, object, float | None]]]:
    samples: list[tuple[str, object, float | None]] = []
    lock = threading.Lock()

    def on(sample: zenoh.Sample) -> None:
        name = str(sample.key_expr).rsplit("/", 1)[1]
        encoding = str(sample.encoding)
        raw = sample.payload.to_bytes()
        value: object = raw
        if encoding.endswith("moos-double"):
            value = float(raw)
        elif encoding.endswith("moos-string"):
            value = raw.decode()
        meta = decode_attachment(sample.attachment.to_bytes()) if sample.attachment else None
        with lock:
            samples.append((name, value, meta.original_time if meta else None))

    session = open_session(SessionOptions(listen=(endpoint,), multicast_scouting=False))
    sub = session.declare_subscriber("fleet/sim_test/var/*", on)
    yield samples
    sub.undeclare()
    session.close()


def test_captured_run_over_zenoh(
    collected: list[tuple[str, object, float | None]],
    endpoint: str,
    cli_env: dict[str, str],
    tmp_path: Path,
) -> None:
    expected, _, _ = expected_of(RUN_A)
    args = ["replay", str(RUN_A), "--fast", "--prefix", "sim_", "--no-keys", "--wait", "10"]
    proc = Proc(
        [*args, "--no-db-time", "-e", endpoint, "--no-multicast-scouting"], tmp_path, cli_env
    )
    try:
        assert proc.wait(30) == 0, proc.stderr
    finally:
        proc.close()
    deadline = time.monotonic() + 5
    while len(collected) < len(expected) and time.monotonic() < deadline:
        time.sleep(0.01)
    assert [(name, value) for name, value, _ in collected] == [(k, v) for k, _, v in expected]
    originals = [t for _, _, t in collected]
    assert originals == sorted(originals)  # type: ignore[type-var]
    assert f"finished: published {len(expected)} entries" in proc.stderr
