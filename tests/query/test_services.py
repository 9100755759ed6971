"""The query services end to end: ``fleetlog serve`` vehicles and the shore CLI as processes.

Three vehicles serve copies of the real pLogger runs (one with the hint in the parent
directory, one compressed with a named hint) and generated sessions; the shore lists them,
fetches sessions byte for byte, greps remotely and is compared with reading the files
locally; hostile requests are refused and the vehicles keep serving.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from query_support import Fleet, copy_reference, make_session, same_tree

from fleetlog.moos.alog import BinaryRef, Entry
from fleetlog.moos.patterns import MoosGlob
from fleetlog.storage.readers import AlogReader
from fleetlog.transport.queries import start_query
from fleetlog.transport.session import SessionOptions, open_session

RUN_A = "captured/runA_themoos_wildcard_restart"
RUN_B1 = "captured/runB1_ivp_compressed_markdatatype"
A44 = "TEST_22_11_2026_____11_06_44"
A52 = "TEST_22_11_2026_____11_06_52"
B1 = "LOG_ALPHA_22_11_2026_____11_07_42"
IVP = "LOG_ALPHA_19_6_2025_____12_04_50"


@pytest.fixture
def three(fleet: Fleet, reference: Path, tmp_path: Path) -> dict[str, Path]:
    """alpha (the synthetic IVP session), test (runA, hint in the parent), ivp (runB1)."""
    src = tmp_path / "vehicles"
    src.mkdir()
    ivp = copy_reference(reference, "ivp_session", src)
    run_a = copy_reference(reference, RUN_A, src)
    run_b1 = copy_reference(reference, RUN_B1, src)
    fleet.serve(ivp, "alpha")
    fleet.serve(run_a / "logs")  # the vehicle's name comes from its logs: "test"
    fleet.serve(run_b1, extra=["--hint", str(run_b1 / "summary.txt")])  # "ivp", from ._moos
    return {"alpha": ivp, "test": run_a / "logs", "ivp": run_b1}


def test_fleet_sessions_and_fetch(fleet: Fleet, three: dict[str, Path], tmp_path: Path) -> None:
    listing = fleet.cli("fleet", "--json")
    assert listing.returncode == 0, listing.stderr
    rows = {row["vehicle"]: row for row in map(json.loads, listing.stdout.splitlines())}
    assert sorted(rows) == ["alpha", "ivp", "test"]
    assert {v: (r["latest"]["session"], r["latest"]["how"]) for v, r in rows.items()} == {
        "alpha": (IVP, "hint"),
        "test": (A52, "hint"),  # pLogger's hint in the parent of the log root
        "ivp": (B1, "hint"),  # --hint summary.txt
    }
    assert all(r["up"] == ["serve"] and not r["latest"]["writing"] for r in rows.values())
    table = fleet.cli("fleet")
    assert table.returncode == 0
    assert all(name in table.stdout for name in ("alpha", "ivp", "test", A52, "complete"))

    sessions = fleet.cli("sessions", "test", "--json")
    assert sessions.returncode == 0, sessions.stderr
    infos = [json.loads(line) for line in sessions.stdout.splitlines()]
    assert [(i["name"], i["latest"], i["variables"]) for i in infos] == [
        (A44, False, 23),
        (A52, True, 11),
    ]
    assert fleet.cli("sessions", "test").stdout.count("complete") == 2

    nobody = fleet.cli("sessions", "nobody")
    assert nobody.returncode == 1
    assert "vehicle 'nobody' is not up; vehicles up: alpha, ivp, test" in nobody.stderr

    out = tmp_path / "shore"
    fetched = fleet.cli("fetch", "--all", "--latest", "-o", str(out))
    assert fetched.returncode == 0, fetched.stderr
    same_tree(three["alpha"] / IVP, out / "alpha" / IVP)
    same_tree(three["test"] / A52, out / "test" / A52)
    same_tree(three["ivp"] / B1, out / "ivp" / B1)  # .alog.gz, .xlog.gz and .blog included

    one = fleet.cli("fetch", "test", A44, "-o", str(out / "one"))
    assert one.returncode == 0, one.stderr
    same_tree(three["test"] / A44, out / "one" / A44)
    again = fleet.cli("fetch", "test", A44, "-o", str(out / "one"))
    assert again.returncode == 0
    assert "7 up to date" in again.stdout
    assert "0 B received" in again.stdout

    missing = fleet.cli("fetch", "test", "NOPE", "-o", str(out))
    assert missing.returncode == 1
    assert "vehicle test: no session 'NOPE' in this log root" in missing.stderr
    gone = fleet.cli("fetch", "zulu", "--latest")
    assert gone.returncode == 1
    assert "vehicles up: alpha, ivp, test" in gone.stderr


def _local(path: Path, keep: dict[str, object]) -> list[tuple[float, str, str, str]]:
    """What the grep should return, from reading the alog locally."""
    globs = [MoosGlob(p) for p in keep.get("vars", [])]  # type: ignore[attr-defined]
    sources = [MoosGlob(p) for p in keep.get("sources", [])]  # type: ignore[attr-defined]
    low, high = keep.get("low"), keep.get("high")
    out = []
    with AlogReader(path, errors="skip") as reader:
        for entry in reader.entries():
            process = entry.source.split(":")[0].split("@")[0]
            if globs and not any(g.matches(entry.key) for g in globs):
                continue
            if sources and not any(g.matches(entry.source) or g.matches(process) for g in sources):
                continue
            if low is not None and entry.offset < low:  # type: ignore[operator]
                continue
            if high is not None and entry.offset > high:  # type: ignore[operator]
                continue
            out.append((entry.offset, entry.key, entry.source, entry.text))
    return out


@pytest.mark.parametrize(
    ("args", "keep"),
    [
        (["NAV_*"], {"vars": ["NAV_*"]}),
        (["DB_?IME", "DEPLOY"], {"vars": ["DB_?IME", "DEPLOY"]}),
        (["--source", "iTest"], {"sources": ["iTest"]}),
        (["--source", "pLog*", "--source", "MOOSDB_test"], {"sources": ["pLog*", "MOOSDB_test"]}),
        (["--from", "2.5", "--to", "4"], {"low": 2.5, "high": 4.0}),
        (["NAV_X", "--from", "@1795345608.4"], {"vars": ["NAV_X"], "low": 5.0}),
        (["*", "--to", "2026-11-22T11:06:45.4Z"], {"high": 2.0}),
    ],
)
def test_query_filters_match_a_local_read(
    fleet: Fleet, reference: Path, tmp_path: Path, args: list[str], keep: dict[str, object]
) -> None:
    logs = copy_reference(reference, RUN_A, tmp_path) / "logs"
    fleet.serve(logs, "test")
    alog = logs / A44 / f"{A44}.alog"
    result = fleet.cli("query", "test", *args, "-s", A44, "--format", "json")
    assert result.returncode == 0, result.stderr
    got = [json.loads(line) for line in result.stdout.splitlines()]
    expected = _local(alog, keep)
    assert expected, "the filter should keep something"
    assert [(g["time"], g["var"], g["source"], g["value"]) for g in got] == [
        (t, k, s, float(v) if g["type"] == "double" else v)
        for (t, k, s, v), g in zip(expected, got, strict=True)
    ]
    assert all(g["abs_time"] == pytest.approx(1795345603.4 + g["time"]) for g in got)
    # As alog text the entries are the file's own lines (multi-line values included).
    text = fleet.cli("query", "test", *args, "-s", A44).stdout
    file_text = alog.read_text()
    assert text.startswith(file_text[: file_text.index("\n0")])  # the banner
    for line in text.splitlines(keepends=True):
        assert line in file_text


def test_query_limit_csv_and_latest(fleet: Fleet, reference: Path, tmp_path: Path) -> None:
    logs = copy_reference(reference, RUN_A, tmp_path) / "logs"
    fleet.serve(logs, "test")
    result = fleet.cli("query", "test", "DB_*", "--limit", "3", "--format", "csv")
    assert result.returncode == 0, result.stderr
    rows = result.stdout.splitlines()
    assert rows[0] == "time,abs_time,var,source,type,value"
    assert len(rows) == 4
    assert "stopped after 3 entries (--limit)" in result.stderr
    latest = _local(logs / A52 / f"{A52}.alog", {"vars": ["DB_*"]})[:3]
    assert [r.split(",")[2] for r in rows[1:]] == [k for _, k, _, _ in latest]
    bad = fleet.cli("query", "test", "--from", "soon")
    assert bad.returncode == 1
    assert "--from 'soon' is neither" in bad.stderr
    blank = fleet.cli("query", "test", "A B")
    assert blank.returncode == 1
    assert "without blanks" in blank.stderr


def test_hostile_requests_are_refused_and_serving_goes_on(
    fleet: Fleet, reference: Path, tmp_path: Path
) -> None:
    logs = tmp_path / "logs"
    logs.mkdir()
    secret = tmp_path / "secret.txt"
    secret.write_text("the vehicle's private key")
    session = copy_reference(reference, f"ivp_session/{IVP}", logs)
    (session / "leak.txt").symlink_to(secret)
    outside = tmp_path / "outside_session"
    outside.mkdir()
    (outside / "x.alog").write_text("not served")
    (logs / "ESCAPE").symlink_to(outside)
    served = fleet.serve(logs, "alpha")
    file_key = f"fleet/alpha/@fleetlog/file/{IVP}"
    alog = f"{file_key}/{IVP}.alog"
    attempts = {
        "fleet/alpha/@fleetlog/file/../secret.txt": "session name '..' is a relative directory",
        f"{file_key}/..%2F..%2Fsecret.txt": "holds '/'",
        "fleet/alpha/@fleetlog/file/%2Ftmp/secret.txt": "session name '/tmp' holds '/'",
        f"{file_key}/leak.txt": "leak.txt leads outside the log root (a symlink?); refused",
        "fleet/alpha/@fleetlog/file/ESCAPE/x.alog": "no session 'ESCAPE' in this log root",
        f"{file_key}/a\x00b": "holds a NUL character",
        f"{file_key}/%2e%2e": "is not an escaped name",
        f"{alog}?length=4194305": "a range holds at most 4194304",
        f"{alog}?offset=99999999": "offset 99999999 is past the end",
        f"{alog}?offset=-5": "parameter 'offset' must be a whole number",
        f"{alog}?garbage": "unknown parameter 'garbage'",
        f"{alog}?length=1;length=2": "parameter 'length' is given twice",
        "fleet/alpha/@fleetlog/file/**": "not with the wildcard '**'",
        f"fleet/alpha/@fleetlog/grep/{IVP}?var=%zz": "not followed by two hex digits",
        f"fleet/alpha/@fleetlog/grep/{IVP}?limit=0": "parameter 'limit' must be between 1",
        "fleet/alpha/@fleetlog/sessions?session=../..": "holds '/'",
        "fleet/alpha/@fleetlog/latest?x=1": "the latest service takes no parameters",
        f"fleet/alpha/@fleetlog/sessions?{'x' * 9000}=1": "characters long",
    }
    zopts = SessionOptions(connect=(served.endpoint,), multicast_scouting=False)
    session_ = open_session(zopts)
    try:
        for selector, expected in attempts.items():
            replies = list(start_query(session_, selector, timeout=10))
            assert len(replies) == 1, selector
            assert replies[0].error is not None, selector
            assert expected in replies[0].error, (selector, replies[0].error)
        good = list(start_query(session_, f"{alog}?offset=0;length=59", timeout=10))
        assert good[0].payload == b"%" * 59
    finally:
        session_.close()
    assert served.proc is not None
    assert served.proc.poll() is None
    out = tmp_path / "shore"
    fetched = fleet.cli("fetch", "alpha", IVP, "-o", str(out))
    assert fetched.returncode == 0, fetched.stderr
    assert not (out / IVP / "leak.txt").exists()
    (session / "leak.txt").unlink()
    same_tree(session, out / IVP)


def test_generated_session_grep_counts(fleet: Fleet, tmp_path: Path) -> None:
    logs = tmp_path / "logs"
    make_session(logs, "GEN_1_1_2025_____00_00_00", 3)
    fleet.serve(logs, "gen")
    result = fleet.cli("query", "gen", "NAV_?", "--source", "pGen", "--format", "json")
    assert result.returncode == 0, result.stderr
    got = [json.loads(line) for line in result.stdout.splitlines()]
    alog = logs / "GEN_1_1_2025_____00_00_00" / "GEN_1_1_2025_____00_00_00.alog"
    expected = _local(alog, {"vars": ["NAV_?"], "sources": ["pGen"]})
    assert len(got) == len(expected) > 1000
    sessions = json.loads(fleet.cli("sessions", "gen", "--json").stdout)
    assert sessions["variables"] == 44
    assert sessions["vehicle"] == "gen"


def test_remote_entries_equal_local_entries(fleet: Fleet, reference: Path, tmp_path: Path) -> None:
    from fleetlog.shore.client import FleetClient
    from fleetlog.wire.query import GrepRequest

    run = copy_reference(reference, RUN_B1, tmp_path)
    served = fleet.serve(run, "ivp")
    alog = run / B1 / f"{B1}.alog.gz"
    with AlogReader(alog) as reader:
        local: list[Entry] = list(reader.entries())
    with FleetClient.open(
        SessionOptions(connect=(served.endpoint,), multicast_scouting=False)
    ) as client:
        stream = client.grep("ivp", B1, GrepRequest())
        remote = list(stream.entries())
        assert stream.header is not None
        assert stream.header.mark_data_type
        assert stream.end is not None
        assert stream.end.matched == len(local)
    assert remote == local
    assert any(isinstance(e.value, BinaryRef) for e in remote)


def test_fetch_leaves_the_disk_reserve_free(fleet: Fleet, reference: Path, tmp_path: Path) -> None:
    # The shore's disk is real: a reserve above what it has free refuses every file before
    # a byte is written; the same fetch with the reserve off then completes.
    src = tmp_path / "vehicles"
    src.mkdir()
    fleet.serve(copy_reference(reference, "ivp_session", src), "alpha")
    out = tmp_path / "shore"
    beyond = shutil.disk_usage(tmp_path).free + (1 << 30)
    refused = fleet.cli("fetch", "alpha", IVP, "-o", str(out), "--min-free-disk", str(beyond))
    assert refused.returncode == 1
    assert "kept free (--min-free-disk)" in refused.stderr, refused.stderr
    assert "Traceback" not in refused.stderr
    assert not [p for p in out.rglob("*") if p.is_file() and ".part" not in p.name]
    bad = fleet.cli("fetch", "alpha", IVP, "-o", str(out), "--min-free-disk", "lots")
    assert bad.returncode != 0
    assert "--min-free-disk" in bad.stderr
    done = fleet.cli("fetch", "alpha", IVP, "-o", str(out), "--min-free-disk", "0")
    assert done.returncode == 0, done.stderr
    same_tree(src / "ivp_session" / IVP, out / IVP)
