"""Split and pause in ``fleetlog record`` as a real process, at full rate on loopback Zenoh.

The parts of a split recording hold every published sample exactly once, in order; a pause
writes nothing and counts what it did not write.
"""

from __future__ import annotations

import json
import subprocess
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from alog_oracle import iter_entries
from helpers import Proc, run_cli

from fleetlog.api import Vehicle
from fleetlog.storage.metafile import read_meta
from fleetlog.transport.session import SessionOptions, open_session

MISSION = "Community = alpha\nProcessConfig = pLogger\n{{\n  Log = N @ 0\n{extra}}}\n"


@pytest.fixture
def record(tmp_path: Path, endpoint: str, cli_env: dict[str, str]) -> Iterator[Callable[..., Proc]]:
    started: list[Proc] = []

    def start(*args: str, extra: str = "") -> Proc:
        (tmp_path / "m.moos").write_text(MISSION.format(extra=extra))
        rec = Proc(
            ["record", "m.moos", *args, "-l", endpoint, "--no-multicast-scouting"],
            tmp_path,
            cli_env,
        )
        started.append(rec)
        rec.wait_for("recording")
        return rec

    yield start
    for rec in started:
        rec.close()


def vehicle(endpoint: str) -> Vehicle:
    return Vehicle(
        "alpha",
        source="iTest",
        options=SessionOptions(connect=(endpoint,), multicast_scouting=False),
    )


def parts_in_order(where: Path) -> list[Path]:
    dirs = [d for d in where.iterdir() if d.is_dir()]
    metas = {d: read_meta(d) for d in dirs}
    ids = {m.mission_id for m in metas.values() if m is not None}
    assert len(ids) == 1  # one mission
    ordered = sorted(dirs, key=lambda d: metas[d].part)  # type: ignore[union-attr]
    assert [metas[d].part for d in ordered] == list(range(1, len(dirs) + 1))  # type: ignore[union-attr]
    return ordered


def logged(directory: Path) -> list[float | str | bytes]:
    with open(directory / f"{directory.name}.alog", encoding="utf-8", newline="") as f:
        return [e.value for e in iter_entries(f) if e.key == "N"]


def test_split_by_size_at_full_rate_loses_nothing(
    record: Callable[..., Proc], tmp_path: Path, endpoint: str
) -> None:
    rec = record(extra="  SplitSize = 1MB\n")
    count = 30_000
    pad = "x" * 80
    with vehicle(endpoint) as v:
        assert v.wait_for_subscriber("N", timeout=10.0)
        for i in range(count):
            v.publish("N", f"{i} {pad}")
        assert v.confirm(timeout=30.0)
    assert rec.stop(timeout=10.0) == 0
    parts = parts_in_order(tmp_path)
    assert len(parts) >= 3
    got = [value for part in parts for value in logged(part)]
    assert got == [f"{i} {pad}" for i in range(count)]
    assert "lost 0 in" in rec.stderr
    hint = (tmp_path / ".LastOpenedMOOSLogDirectory").read_text()
    assert parts[-1].name in hint
    for part in parts:
        meta = read_meta(part)
        assert meta is not None
        assert meta.state == "closed"
        assert meta.counters["lost"] == 0


def test_split_by_duration_at_full_rate_loses_nothing(
    record: Callable[..., Proc], tmp_path: Path, endpoint: str
) -> None:
    rec = record("--split-duration", "1s")
    sent = 0
    with vehicle(endpoint) as v:
        assert v.wait_for_subscriber("N", timeout=10.0)
        until = time.monotonic() + 2.6
        while time.monotonic() < until:
            for _ in range(500):
                v.publish("N", float(sent))
                sent += 1
        assert v.confirm(timeout=30.0)
    assert rec.stop(timeout=10.0) == 0
    parts = parts_in_order(tmp_path)
    assert len(parts) >= 3
    got = [value for part in parts for value in logged(part)]
    assert got == [float(i) for i in range(sent)]
    assert all(logged(part) for part in parts[:2])


def test_pause_and_resume_over_the_control_service(
    record: Callable[..., Proc], tmp_path: Path, endpoint: str
) -> None:
    rec = record("--paused")
    assert "paused" in rec.stderr

    def ask(request: dict[str, object]) -> dict[str, object]:
        with open_session(SessionOptions(connect=(endpoint,), multicast_scouting=False)) as z:
            (reply,) = list(
                z.get("fleet/alpha/@fleetlog/control", payload=json.dumps(request).encode())
            )
            return json.loads(reply.ok.payload.to_bytes())  # type: ignore[union-attr, no-any-return]

    with vehicle(endpoint) as v:
        assert v.wait_for_subscriber("N", timeout=10.0)
        for i in range(100):
            v.publish("N", float(i))
        assert v.confirm(timeout=10.0)
        time.sleep(0.2)
        status = ask({"cmd": "status"})
        assert status["paused"] is True
        assert status["paused_samples"] >= 100  # type: ignore[operator]
        assert status["lost"] == 0
        assert ask({"cmd": "resume"})["ok"] is True
        for i in range(100, 200):
            v.publish("N", float(i))
        assert v.confirm(timeout=10.0)
        time.sleep(0.2)
        assert ask({"cmd": "pause"})["did"] == "paused recording"
        for i in range(200, 300):
            v.publish("N", float(i))
        assert v.confirm(timeout=10.0)
        time.sleep(0.2)
    assert rec.stop(timeout=10.0) == 0
    (session,) = parts_in_order(tmp_path)
    assert logged(session) == [float(i) for i in range(100, 200)]
    meta = read_meta(session)
    assert meta is not None
    assert meta.counters["paused"] >= 200
    assert meta.counters["lost"] == 0
    summary = rec.wait_for("stopped:")
    assert f"paused {meta.counters['paused']} (not written while paused)" in summary, summary


def test_the_shore_commands_the_recorder_and_sees_its_notes(
    record: Callable[..., Proc], tmp_path: Path, endpoint: str, cli_env: dict[str, str]
) -> None:
    record("--note", "site:the bay", "--tag", "trial", extra="  Note = crew:2\n")
    shore = ("-e", endpoint, "--no-multicast-scouting")

    def ctl(*args: str) -> subprocess.CompletedProcess[str]:
        return run_cli("recorder-ctl", *args, "-v", "alpha", *shore, cwd=tmp_path, env=cli_env)

    noted = ctl("note", "event: hit a buoy")
    assert noted.returncode == 0, noted.stderr
    assert noted.stdout.startswith("alpha: noted event on session")
    split = ctl("split")
    assert split.returncode == 0, split.stderr
    assert "started part 2 of the mission" in split.stdout
    paused = ctl("pause", "--json")
    assert json.loads(paused.stdout)["paused"] is True
    status = run_cli("status", "alpha", *shore, cwd=tmp_path, env=cli_env)
    assert status.returncode == 0, status.stderr
    assert "paused" in status.stdout
    assert "paused_samples" in status.stdout
    refused = ctl("snapshot")
    assert refused.returncode == 1
    assert "not in snapshot mode" in refused.stdout
    assert "1 of 1 recorder(s) refused" in refused.stderr
    bad = ctl("note", "nocolon")
    assert bad.returncode == 1
    assert "is not key:value" in bad.stderr
    listed = run_cli("sessions", "alpha", *shore, cwd=tmp_path, env=cli_env)
    assert listed.returncode == 0, listed.stderr
    assert "PART" in listed.stdout
    assert "event=hit a buoy" in listed.stdout
    assert "#trial" in listed.stdout
    rows = run_cli("sessions", "alpha", "--json", *shore, cwd=tmp_path, env=cli_env)
    found = [json.loads(line) for line in rows.stdout.splitlines()]
    assert [(s["part"], s["notes"]) for s in found] == [
        (1, {"crew": "2", "site": "the bay", "event": "hit a buoy"}),
        (2, {"crew": "2", "site": "the bay", "event": "hit a buoy"}),
    ]
    # part 2 opened after part 1, and both keep the mission's LOGSTART
    assert found[0]["start"] == found[1]["start"]
    assert found[1]["opened"] > found[0]["opened"] >= found[0]["start"] - 1
    first = tmp_path / found[0]["name"]
    info = run_cli("info", str(first), cwd=tmp_path, env=cli_env)
    assert info.returncode == 0, info.stderr
    assert "part 1 of mission" in info.stdout
    assert "event=hit a buoy" in info.stdout


def test_misspelt_parameters_warn_and_strict_refuses(
    tmp_path: Path, endpoint: str, cli_env: dict[str, str], record: Callable[..., Proc]
) -> None:
    extra = "  WildcardLoging = true\n  Log = X @ fast\n"
    (tmp_path / "m.moos").write_text(MISSION.format(extra=extra))
    refused = run_cli("record", "m.moos", "--strict", "-l", endpoint, cwd=tmp_path, env=cli_env)
    assert refused.returncode == 1
    assert refused.stderr == (
        "fleetlog: error: m.moos:5: unknown pLogger parameter 'WildcardLoging' is ignored"
        " (did you mean 'WildcardLogging'?) (and 1 more); --strict refuses it\n"
    )
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.moos"]
    bad = run_cli("record", "m.moos", "--split-size", "10kB", cwd=tmp_path, env=cli_env)
    assert bad.returncode == 1
    assert bad.stderr.endswith(
        "\nfleetlog: error: --split-size '10kB' is below the smallest part, 1MB\n"
    )
    rec = record(extra=extra)
    assert "warning: m.moos:5: unknown pLogger parameter 'WildcardLoging'" in rec.stderr
    assert "warning: m.moos:6: Log = X @ fast: the period 'fast' is not a number" in rec.stderr
